//! Our CLI writer read back: a generated part of arbitrary size, layers and rings is
//! planned and written as ASCII or modified CLI, then read by a reader written here
//! from the format's description. Every layer the header declares is there, every
//! polyline has the points its count says, closed, finite, and layers go up.
#![no_main]

#[path = "common.rs"]
mod common;

use arbitrary::Arbitrary;
use libfuzzer_sys::fuzz_target;

#[derive(Debug, Arbitrary)]
struct Case {
    model: u8,
    size: u8,
    thickness: u8,
    rings: u8,
    modified: bool,
}

/// Reads an ASCII CLI file and checks its structure; panics on a violation.
fn check(text: &str) {
    let (header, body) = text.split_once("$$HEADEREND").expect("$$HEADEREND");
    assert!(header.contains("$$HEADERSTART"), "no $$HEADERSTART");
    let declared: usize = header
        .lines()
        .find_map(|l| l.trim().strip_prefix("$$LAYERS/"))
        .expect("$$LAYERS")
        .trim()
        .parse()
        .expect("a layer count");
    let mut layers = 0;
    let mut last_z = f64::NEG_INFINITY;
    for line in body.lines().map(str::trim) {
        if let Some(z) = line.strip_prefix("$$LAYER/") {
            let z: f64 = z.parse().expect("a layer height");
            assert!(z > last_z, "layer at {z} after {last_z}");
            last_z = z;
            layers += 1;
        } else if let Some(p) = line.strip_prefix("$$POLYLINE/") {
            let v: Vec<f64> = p
                .split(',')
                .map(|s| s.trim().parse().expect("a number"))
                .collect();
            assert!(v.len() >= 3, "{line}");
            let (dir, n) = (v[1], v[2] as usize);
            assert!([0.0, 1.0, 2.0].contains(&dir), "direction {dir}");
            assert_eq!(v.len(), 3 + 2 * n, "{line}");
            assert!(v.iter().all(|c| c.is_finite()));
            assert!(n >= 4, "a closed polyline needs 4 points: {line}");
            assert_eq!(v[3..5], v[v.len() - 2..], "not closed: {line}");
        }
    }
    assert_eq!(layers, declared, "$$LAYERS/{declared} but {layers} layers");
}

fuzz_target!(|case: Case| {
    let size = 2.0 + f64::from(case.size) / 8.0;
    let model = match case.model % 3 {
        0 => format!("use = \"box\"\nsize = [{size}, {}, 2.0]", size * 0.7),
        1 => format!(
            "use = \"tube\"\nouter_radius = {size}\ninner_radius = {}\nheight = 2.0",
            size / 3.0
        ),
        _ => format!("use = \"gear\"\nteeth = {}\nheight = 2.0", 8 + case.size % 16),
    };
    let thickness = 0.1 + f64::from(case.thickness % 20) / 10.0;
    let rings = 1 + case.rings % 6;
    let format = if case.modified { "modified" } else { "ascii" };
    let text = format!(
        "name = \"cli\"\n[model]\n{model}\n[materials.a]\ncolour = [255, 0, 0]\n[materials.b]\ncolour = [0, 0, 255]\n\
         [slice]\nuse = \"uniform\"\nthickness = {thickness}\n[discretise]\nuse = \"offset\"\ncount = {rings}\n\
         [grade]\nuse = \"xy\"\nf = \"linear\"\nmu = 1.0\nlambda = 0.0\n\
         [[output]]\nuse = \"cli\"\npath = \"l.cli\"\nformat = \"{format}\"\n"
    );
    let dir = tempfile::tempdir().expect("tempdir");
    if let Err(e) = common::run(&text, dir.path(), &[]) {
        panic!("a valid pipeline failed: {e}\n{text}");
    }
    let written = std::fs::read_to_string(dir.path().join("out/l.cli")).expect("the CLI file");
    check(&written);
});
