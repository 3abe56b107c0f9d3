//! The generators and `lamina generate`: every generated mesh is closed and consistently
//! wound with the volume it should have, and the files the command writes read back
//! through the model stages with the same triangles.

use std::path::Path;
use std::process::Output;

use crate::support::lamina;
use lamina_core::{Mesh, StageKind};

fn model(text: &str) -> Vec<Mesh> {
    lamina_test_support::meshes(text, Path::new("."))
}

fn closed(m: &Mesh) {
    assert_eq!(lamina_model::edge_defect(m), None, "{}", m.name);
}

fn close(a: f64, b: f64, rel: f64) -> bool {
    (a - b).abs() <= rel * b.abs()
}

/// Area of a regular n-gon of circumradius r.
fn ngon(n: f64, r: f64) -> f64 {
    0.5 * n * r * r * (std::f64::consts::TAU / n).sin()
}

#[test]
fn every_generator_is_closed_with_its_volume() {
    let cube = model("use = \"cube\"\nsize = 3.0");
    closed(&cube[0]);
    assert!(close(cube[0].signed_volume(), 27.0, 1e-12));

    let boxed = model("use = \"box\"\nsize = [3.0, 2.0, 1.5]");
    closed(&boxed[0]);
    assert!(close(boxed[0].signed_volume(), 9.0, 1e-12));

    let tube = model("use = \"tube\"\nouter_radius = 10.0\ninner_radius = 7.0\nheight = 5.0\nsegments = 64");
    closed(&tube[0]);
    let expected = (ngon(64.0, 10.0) - ngon(64.0, 7.0)) * 5.0;
    assert!(close(tube[0].signed_volume(), expected, 1e-9));

    // Gear: the profile area (outline less bore) times the height.
    let gear = model("use = \"gear\"\nteeth = 12\nheight = 4.0\nbore = 5.0\narc_segments = 3");
    closed(&gear[0]);
    let profile = lamina_model::profile::GearProfile {
        teeth: 12,
        tip_radius: 20.0,
        root_radius: 16.0,
        tip_share: 0.3,
        root_share: 0.55,
        arc_segments: 3,
    };
    let bore_segments = (12.0 * 8.0f64).clamp(32.0, 512.0);
    let expected = (profile.outline().area() - ngon(bore_segments, 5.0)) * 4.0;
    assert!(
        close(gear[0].signed_volume(), expected, 1e-9),
        "{} vs {expected}",
        gear[0].signed_volume()
    );

    let assembly = model("use = \"gear-shaft\"\nteeth = 12\nheight = 4.0\nshaft_length = 9.0");
    assert_eq!(assembly.len(), 2);
    assembly.iter().for_each(closed);
    assert!(close(assembly[1].signed_volume(), ngon(120.0, 4.8) * 9.0, 1e-9));

    for cavities in 0..=2 {
        let blade = model(&format!("use = \"blade\"\ncavities = {cavities}"));
        closed(&blade[0]);
        let v = blade[0].signed_volume();
        let b = blade[0].bbox().size();
        println!(
            "blade, {cavities} cavities: {} triangles, {} vertices, volume {v:.1} mm3, {:.2} x {:.2} x {:.2} mm",
            blade[0].triangles.len(),
            blade[0].vertices.len(),
            b.x,
            b.y,
            b.z
        );
        assert!(v > 0.0);
        assert!((b.z - 70.0).abs() < 1e-9, "root 10 + span 60");
    }
}

#[test]
fn blade_options_are_checked_and_named() {
    for (text, option) in [
        ("cavities = 3", "cavities"),
        ("naca = \"24x2\"", "naca"),
        ("naca = \"2412\"\nwall = 4.0\ncavities = 1", "wall"),
        ("twist = 85.0\nsections = 2\ncavities = 2", "sections"),
        ("root_size = [10.0, 10.0]", "root_size"),
        ("thickness = 0.6", "thickness"),
        ("chord = -1.0", "chord"),
    ] {
        let blade = format!("use = \"blade\"\n{text}");
        let e = match lamina_test_support::try_stage(StageKind::Model, &blade, Path::new(".")) {
            Ok(_) => panic!("{text} accepted"),
            Err(e) => e,
        };
        assert!(e.is_usage(), "{text}: {e}");
        // The stage's own checks name the key (`key: ...`), the declared ranges quote it.
        let e = e.to_string();
        assert!(
            e.contains(&format!("{option}:")) || e.contains(&format!("`{option}` = ")),
            "{text}: {e}"
        );
    }
    // A code as a TOML integer and a symmetric section given by its numbers.
    assert!(!model("use = \"blade\"\nnaca = 4415").is_empty());
    assert!(
        !model("use = \"blade\"\nnaca = \"0012\"\nmax_camber = 0.0\nthickness = 0.15\ncavities = 2")
            .is_empty()
    );
}

fn generated(dir: &Path, args: &[&str], file: &str) -> (Output, std::path::PathBuf) {
    let path = dir.join(file);
    let mut all: Vec<&str> = vec!["generate"];
    all.extend_from_slice(args);
    let p = path.to_str().expect("utf-8 path").to_string();
    all.extend_from_slice(&["-o", &p]);
    (lamina(&all), path)
}

#[test]
fn generate_writes_files_the_readers_take_back() {
    let dir = tempfile::tempdir().expect("tempdir");
    for (args, expected_meshes) in [
        (&["blade", "--cavities", "2", "--twist=30"][..], 1),
        (&["gear", "teeth=12"][..], 1),
        (&["gear-shaft", "--set", "teeth=12"][..], 2),
        (&["tube"][..], 1),
        (&["cube", "--size", "5"][..], 1),
    ] {
        let direct = model(&format!(
            "use = \"{}\"\n{}",
            args[0],
            match args[0] {
                "blade" => "cavities = 2\ntwist = 30.0",
                "gear" | "gear-shaft" => "teeth = 12",
                "cube" => "size = 5.0",
                _ => "",
            }
        ));
        assert_eq!(direct.len(), expected_meshes);
        let triangles: usize = direct.iter().map(|m| m.triangles.len()).sum();
        for ext in ["stl", "obj", "3mf"] {
            let (out, path) = generated(dir.path(), args, &format!("{}.{ext}", args[0]));
            assert!(
                out.status.success(),
                "{args:?}: {}",
                String::from_utf8_lossy(&out.stderr)
            );
            assert!(String::from_utf8_lossy(&out.stdout).contains("closed"));
            let back = lamina_test_support::meshes(
                &format!(
                    "use = \"{ext}\"\nfile = \"{}\"",
                    path.display().to_string().replace('\\', "/")
                ),
                dir.path(),
            );
            // An STL holds one solid; OBJ and 3MF keep the parts apart.
            assert_eq!(
                back.len(),
                if ext == "stl" { 1 } else { expected_meshes },
                "{ext}"
            );
            assert_eq!(
                back.iter().map(|m| m.triangles.len()).sum::<usize>(),
                triangles,
                "{args:?} as {ext}"
            );
            if ext != "stl" || expected_meshes == 1 {
                back.iter().for_each(closed);
            }
            let volume: f64 = direct.iter().map(Mesh::signed_volume).sum();
            let read: f64 = back.iter().map(Mesh::signed_volume).sum();
            // STL stores single precision.
            assert!(close(read, volume, 1e-5), "{args:?} {ext}: {read} vs {volume}");
        }
    }
}

#[test]
fn bad_requests_exit_2_and_leave_no_file() {
    let dir = tempfile::tempdir().expect("tempdir");
    for (args, needle) in [
        (&["blade", "--cavities", "3"][..], "cavities"),
        (&["blade", "--cavitys", "1"][..], "cavitys"),
        (&["gear", "teeth=2"][..], "teeth"),
        (&["teapot"][..], "teapot"),
        (&["cube", "size"][..], "size"),
        (&["tube", "--height", "-1"][..], "height"),
    ] {
        let (out, path) = generated(dir.path(), args, "x.stl");
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(needle), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{err}");
        assert!(!path.exists());
    }
    let (out, _) = generated(dir.path(), &["cube"], "x.step");
    assert_eq!(out.status.code(), Some(2));
    let out = lamina(&["generate", "cube"]);
    assert_eq!(out.status.code(), Some(2), "no output file");
    assert_eq!(
        std::fs::read_dir(dir.path()).expect("list").count(),
        0,
        "no temporary files left"
    );
    // A folder that cannot be created is a run failure (1), not a usage error.
    let blocked = dir.path().join("file");
    std::fs::write(&blocked, b"x").expect("write");
    let (out, _) = generated(&blocked, &["cube"], "x.stl");
    assert_eq!(out.status.code(), Some(1));
}
