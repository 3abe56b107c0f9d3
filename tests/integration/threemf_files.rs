//! 3MF packages with the materials extension: read back by Lamina's own 3MF reader
//! (every region a closed prism, the volumes add up), and by lib3mf when its Python
//! package is installed (skipped with a note when it is not).

use crate::support::{run_text, skip};
use std::path::{Path, PathBuf};
use std::process::Command;

fn run(dir: &Path) -> (PathBuf, serde_json::Value) {
    let pipeline = "name = \"graded tube\"\n[model]\nuse = \"tube\"\nouter_radius = 10.0\ninner_radius = 5.0\nheight = 1.5\n\
        [materials.ceramic]\ncolour = [240, 240, 230]\n[materials.metal]\ncolour = [90, 90, 100]\n\
        [discretise]\nuse = \"offset\"\ncount = 4\nfrom = \"outer\"\n\
        [grade]\nuse = \"xy\"\n\
        [slice]\nuse = \"uniform\"\nthickness = 0.5\n\
        [[output]]\nuse = \"json\"\npath = \"plan.json\"\n\
        [[output]]\nuse = \"3mf\"\npath = \"plan.3mf\"\n";
    let plan = run_text(dir, pipeline, "plan.json");
    (dir.join("out/plan.3mf"), plan)
}

#[test]
fn regions_are_closed_prisms_with_the_plans_volume() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (file, plan) = run(dir.path());
    let bytes = std::fs::read(&file).expect("3mf written");
    let meshes = lamina_model::threemf::read(&file, &bytes).expect("our reader opens it");
    let layers = plan["layers"].as_array().expect("layers");
    assert_eq!(meshes.len(), layers.len(), "one object per layer of the one part");
    let mut want = 0.0;
    for l in layers {
        let t = l["thickness"].as_f64().expect("thickness");
        for f in l["parts"][0]["families"].as_array().expect("families") {
            want += f["area"].as_f64().expect("area") * t;
        }
    }
    let mut got = 0.0;
    for m in &meshes {
        assert_eq!(lamina_model::extrude::edge_defect(m), None, "{}", m.name);
        got += m.signed_volume();
    }
    assert!((got - want).abs() < 1e-3 * want, "{got} vs {want}");
}

#[test]
fn lib3mf_opens_the_package() {
    let probe = Command::new("python3").args(["-c", "import lib3mf"]).output();
    if !probe.map(|o| o.status.success()).unwrap_or(false) {
        skip("the lib3mf Python package is not installed (pip install lib3mf)");
        return;
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let (file, plan) = run(dir.path());
    let script = r#"
import sys, lib3mf
w = lib3mf.get_wrapper()
m = w.CreateModel()
m.QueryReader("3mf").ReadFromFile(sys.argv[1])
objects = m.GetMeshObjects()
n = 0
triangles = 0
while objects.MoveNext():
    o = objects.GetCurrentMeshObject()
    n += 1
    triangles += o.GetTriangleCount()
composites = m.GetCompositeMaterials()
groups = 0
while composites.MoveNext():
    groups += 1
print(n, triangles, groups)
"#;
    let out = Command::new("python3")
        .args(["-c", script])
        .arg(&file)
        .output()
        .expect("python runs");
    assert!(
        out.status.success(),
        "lib3mf refused the package: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    let v: Vec<usize> = text
        .split_whitespace()
        .map(|s| s.parse().expect("number"))
        .collect();
    let layers = plan["layers"].as_array().expect("layers").len();
    assert_eq!(v[0], layers, "objects");
    assert!(v[1] > 0, "triangles");
    assert_eq!(v[2], layers, "one composite group per layer");
}
