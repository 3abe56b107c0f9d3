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
