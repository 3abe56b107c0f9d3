//! The plugin's own tests, as a third-party crate writes them with
//! `lamina-test-support`: its declared example runs, and a pipeline using it fills the
//! part.

use lamina_zigzag as _;

#[test]
fn the_declared_example_runs() {
    lamina_test_support::assert_examples_run(&["zigzag"]);
}

#[test]
fn a_pipeline_with_the_planner_fills_every_layer() {
    let run = lamina_test_support::run_pipeline(
        "[model]\nuse = \"box\"\nsize = [10.0, 6.0, 1.0]\n\n[materials.a]\ncolour = [255, 0, 0]\n\n\
         [slice]\nuse = \"uniform\"\nthickness = 0.5\n\n[plan]\nuse = \"zigzag\"\nwidth = 0.5\n\n\
         [[output]]\nuse = \"json\"\npath = \"plan.json\"\n",
    );
    assert_eq!(run.report.layers, 2);
    let plan = run.json("plan.json");
    for layer in plan["layers"].as_array().expect("layers") {
        // Bead length times width covers the 60 mm² section.
        let covered: f64 = layer["toolpaths"]
            .as_array()
            .expect("toolpaths")
            .iter()
            .filter(|p| p["kind"] == "extrude")
            .map(|p| {
                let points = p["points"].as_array().expect("points");
                let length: f64 = points
                    .windows(2)
                    .map(|w| {
                        let (a, b) = (&w[0]["p"], &w[1]["p"]);
                        let dx = b[0].as_f64().unwrap_or(0.0) - a[0].as_f64().unwrap_or(0.0);
                        let dy = b[1].as_f64().unwrap_or(0.0) - a[1].as_f64().unwrap_or(0.0);
                        dx.hypot(dy)
                    })
                    .sum();
                length * p["width"].as_f64().unwrap_or(0.0)
            })
            .sum();
        assert!((covered - 60.0).abs() < 0.05 * 60.0, "{covered} mm²");
    }
}
