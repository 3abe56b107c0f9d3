//! Build orientation end to end: the `[orient]` stage turns the object before it is
//! sliced, and the plan records the direction and the alternatives weighed.

use std::path::Path;
use std::process::Command;

fn run(dir: &Path, orient: &str) -> (serde_json::Value, String) {
    let path = dir.join("p.toml");
    std::fs::write(
        &path,
        format!(
            "name = \"plate\"\n[model]\nuse = \"box\"\nsize = [10.0, 2.0, 1.0]\n\
             [materials.a]\ncolour = [1, 2, 3]\n[orient]\n{orient}\n\
             [slice]\nuse = \"uniform\"\nthickness = 0.5\n\
             [[output]]\nuse = \"json\"\npath = \"plan.json\"\n"
        ),
    )
    .expect("write");
    let out_dir = dir.join("out");
    let out = Command::new(env!("CARGO_BIN_EXE_lamina"))
        .args(["run", "--out"])
        .arg(&out_dir)
        .arg(&path)
        .output()
        .expect("lamina runs");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = std::fs::read_to_string(out_dir.join("plan.json")).expect("json");
    (
        serde_json::from_str(&text).expect("valid json"),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn least_surface_angle_stands_a_plate_on_its_end() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (plan, stderr) = run(dir.path(), "use = \"candidates\"");
    let o = &plan["orientation"];
    assert_eq!(o["criterion"], "surface-angle");
    assert!(o["direction"][0].as_f64().expect("x").abs() > 1.0 - 1e-9, "{o}");
    // 10 mm tall now: 20 layers of 0.5 mm, each a 2 x 1 mm section.
    assert_eq!(plan["layer_count"], 20);
    let area = plan["layers"][5]["parts"][0]["families"][0]["area"]
        .as_f64()
        .expect("area");
    assert!((area - 2.0).abs() < 1e-9, "{area}");
    let parts = &plan["parts"][0];
    assert!(
        parts["z_min"].as_f64().expect("z_min").abs() < 1e-9,
        "back on the bed"
    );
    assert!((parts["z_max"].as_f64().expect("z_max") - 10.0).abs() < 1e-9);
    let candidates = o["candidates"].as_array().expect("candidates");
    assert!(candidates.len() > 10);
    assert!(
        stderr.contains("build direction"),
        "the summary reports it: {stderr}"
    );
}

#[test]
fn least_height_keeps_the_plate_flat() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (plan, _) = run(dir.path(), "use = \"candidates\"\ncriterion = \"height\"");
    assert_eq!(plan["orientation"]["candidates"][0]["label"], "+z");
    assert_eq!(plan["layer_count"], 2);
}

#[test]
fn the_base_cells_main_surfaces_choose_the_direction_not_the_objects() {
    // Plate-like cells, half-edges s x 3s x 0.2s: their largest faces face z and the
    // next face x, so sum A_i alpha_i over the cells is least building along y (both
    // large faces then stand parallel to the build direction). Over the plate's own
    // surfaces the least is along x, its length.
    let dir = tempfile::tempdir().expect("tempdir");
    let cell = "base_cell = { shape = \"box\", size = 0.1, aspect = [1.0, 3.0, 0.2], period = [1.0, 1.0, 1.0], origin = [0.5, 0.5, 0.5] }";
    let (plan, _) = run(
        dir.path(),
        &format!("use = \"candidates\"\ncriterion = \"base-cell\"\n{cell}"),
    );
    let o = &plan["orientation"];
    assert_eq!(o["criterion"], "base-cell");
    assert!(o["direction"][1].as_f64().expect("y").abs() > 1.0 - 1e-9, "{o}");
    // 2 mm tall now: 4 layers.
    assert_eq!(plan["layer_count"], 4);
    // The cost along x is three times that along y (faces of 2.4 s² against 0.8 s²).
    let cost = |label: &str| {
        o["candidates"]
            .as_array()
            .expect("candidates")
            .iter()
            .find(|c| c["label"] == label)
            .map(|c| c["cost"].as_f64().expect("cost"))
            .expect("candidate")
    };
    assert!(
        (cost("+x") / cost("+y") - 3.0).abs() < 1e-9,
        "{} {}",
        cost("+x"),
        cost("+y")
    );
    // A sphere has no main surfaces to weigh.
    let path = dir.path().join("q.toml");
    std::fs::write(
        &path,
        "[model]\nuse = \"box\"\n[materials.a]\ncolour = [1, 2, 3]\n[orient]\nuse = \"candidates\"\n\
         criterion = \"base-cell\"\nbase_cell = { size = 0.1, period = [1.0, 1.0, 1.0] }\n",
    )
    .expect("write");
    let out = Command::new(env!("CARGO_BIN_EXE_lamina"))
        .args(["check"])
        .arg(&path)
        .output()
        .expect("lamina runs");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("a sphere weighs every build direction the same"),
        "{err}"
    );
}
