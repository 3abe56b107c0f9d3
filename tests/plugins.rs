//! Dynamic plugins end to end: the example `zigzag` crate and two fixtures are built as
//! shared libraries, loaded by the `lamina` binary, and run, refused or contained.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// Builds the plugin libraries once per test run and returns their folder.
fn libraries() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let target = std::env::var_os("CARGO_TARGET_DIR")
            .map(PathBuf::from)
            .unwrap_or_else(|| root().join("target"));
        let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
        let status = Command::new(cargo)
            .current_dir(root())
            // The whole workspace's libraries: the same feature set as `cargo test
            // --workspace` built, so nothing but the plugins is compiled again.
            .args(["build", "--quiet", "--workspace", "--lib", "--target-dir"])
            .arg(&target)
            .status()
            .expect("cargo runs");
        assert!(status.success(), "building the plugin libraries failed");
        target.join("debug")
    })
}

fn library(crate_name: &str) -> PathBuf {
    libraries().join(format!(
        "{}{}{}",
        std::env::consts::DLL_PREFIX,
        crate_name.replace('-', "_"),
        std::env::consts::DLL_SUFFIX
    ))
}

fn lamina(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_lamina"))
        .args(args)
        .output()
        .expect("lamina runs")
}

fn write_pipeline(dir: &Path, extra: &str) -> PathBuf {
    let path = dir.join("p.toml");
    std::fs::write(
        &path,
        format!(
            "[model]\nuse = \"tube\"\nheight = 2.0\n\n[materials.a]\ncolour = [255, 0, 0]\n\n[slice]\nuse = \"uniform\"\nthickness = 0.5\n\n[[output]]\nuse = \"json\"\npath = \"plan.json\"\n\n{extra}"
        ),
    )
    .expect("write pipeline");
    path
}

#[test]
fn example_plugin_is_loaded_and_plans_toolpaths() {
    let lib = library("lamina-zigzag");
    let dir = tempfile::tempdir().expect("tempdir");
    // Named from the pipeline, relative to its folder.
    std::fs::copy(&lib, dir.path().join("zigzag.so")).expect("copy library");
    let pipeline = write_pipeline(dir.path(), "[plan]\nuse = \"zigzag\"\nwidth = 0.5\n");
    let text = std::fs::read_to_string(&pipeline).expect("read");
    std::fs::write(&pipeline, format!("plugins = [\"zigzag.so\"]\n{text}")).expect("write");
    let out_dir = dir.path().join("out");
    let out = lamina(&[
        "run",
        pipeline.to_str().expect("utf-8"),
        "--out",
        out_dir.to_str().expect("utf-8"),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let plan: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out_dir.join("plan.json")).expect("written")).expect("json");
    let layers = plan["layers"].as_array().expect("layers");
    assert_eq!(layers.len(), 4);
    for layer in layers {
        let paths = layer["toolpaths"].as_array().expect("toolpaths planned");
        let extruded: f64 = paths
            .iter()
            .filter(|p| p["kind"] == "extrude")
            .map(|p| {
                let pts = p["points"].as_array().expect("points");
                let a = &pts[0]["p"];
                let b = &pts[1]["p"];
                let dx = b[0].as_f64().unwrap_or(0.0) - a[0].as_f64().unwrap_or(0.0);
                let dy = b[1].as_f64().unwrap_or(0.0) - a[1].as_f64().unwrap_or(0.0);
                dx.hypot(dy)
            })
            .sum();
        // Lines 0.5 mm apart cover the tube's ring (pi (10² - 7²) = 160 mm²).
        let area = std::f64::consts::PI * (100.0 - 49.0);
        assert!((extruded * 0.5 - area).abs() < 0.05 * area, "{extruded}");
        assert!(layer["build_time"].as_f64().unwrap_or(0.0) > 0.0);
    }

    // `lamina plugins --plugin` lists it with its origin.
    let out = lamina(&["plugins", "plan", "--plugin", lib.to_str().expect("utf-8")]);
    assert!(out.status.success());
    let listing = String::from_utf8_lossy(&out.stdout);
    assert!(
        listing.contains("zigzag") && listing.contains("plugin zigzag"),
        "{listing}"
    );
}

#[test]
fn plugin_of_another_abi_is_refused_naming_both_versions() {
    let lib = library("lamina-fixture-bad-abi");
    let dir = tempfile::tempdir().expect("tempdir");
    let pipeline = write_pipeline(dir.path(), "");
    let marker = dir.path().join("initialiser-ran");
    let out = Command::new(env!("CARGO_BIN_EXE_lamina"))
        .args([
            "check",
            pipeline.to_str().expect("utf-8"),
            "--plugin",
            lib.to_str().expect("utf-8"),
        ])
        .env("LAMINA_FIXTURE_MARKER", &marker)
        .output()
        .expect("lamina runs");
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("ABI 99.0"), "{err}");
    // Refused from the file: the library was never handed to the loader.
    if cfg!(target_os = "linux") {
        assert!(!marker.exists(), "the refused library's initialiser ran");
    }
    assert!(
        err.contains(&format!("supports ABI {}.", lamina_core::plugin::ABI_MAJOR)),
        "{err}"
    );
}

#[test]
fn panicking_plugin_is_an_error_not_an_abort() {
    let lib = library("lamina-fixture-panic");
    let dir = tempfile::tempdir().expect("tempdir");
    let pipeline = write_pipeline(dir.path(), "[grade]\nuse = \"panics\"\n");
    let out_dir = dir.path().join("out");
    let out = lamina(&[
        "run",
        pipeline.to_str().expect("utf-8"),
        "--plugin",
        lib.to_str().expect("utf-8"),
        "--out",
        out_dir.to_str().expect("utf-8"),
    ]);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("panicked") && err.contains("this grader always panics"),
        "{err}"
    );
    assert!(err.contains("panicking/grade:panics"), "{err}");
    assert!(!out_dir.join("plan.json").exists());
}

#[test]
fn a_file_that_is_not_a_plugin_is_refused() {
    let dir = tempfile::tempdir().expect("tempdir");
    let fake = dir.path().join("fake.so");
    std::fs::write(&fake, b"not a library").expect("write");
    let pipeline = write_pipeline(dir.path(), "");
    let out = lamina(&[
        "check",
        pipeline.to_str().expect("utf-8"),
        "--plugin",
        fake.to_str().expect("utf-8"),
    ]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("fake.so"));
}

#[test]
fn truncated_and_foreign_files_are_refused_with_the_reason_before_loading() {
    let lib = std::fs::read(library("lamina-zigzag")).expect("the zigzag library");
    let dir = tempfile::tempdir().expect("tempdir");
    let pipeline = write_pipeline(dir.path(), "");
    let cases: [(&str, &[u8], &str); 4] = [
        ("header-only.so", &lib[..64], "truncated"),
        ("third.so", &lib[..lib.len() / 3], "truncated"),
        ("text.so", b"not a library\n", "not a complete shared library"),
        ("empty.so", b"", "not a complete shared library"),
    ];
    for (name, bytes, expected) in cases {
        let path = dir.path().join(name);
        std::fs::write(&path, bytes).expect("write");
        let out = lamina(&[
            "check",
            pipeline.to_str().expect("utf-8"),
            "--plugin",
            path.to_str().expect("utf-8"),
        ]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{name}: {err}");
        assert!(err.contains(expected) && err.contains(name), "{name}: {err}");
    }
    // A real library that is not a Lamina plugin: refused by its exports.
    let other = dir.path().join("plain.so");
    let mut plain = lib.clone();
    let at = plain
        .windows(b"lamina_plugin_entry_v1".len())
        .position(|w| w == b"lamina_plugin_entry_v1")
        .expect("the entry symbol's name");
    plain[at] = b'X';
    std::fs::write(&other, &plain).expect("write");
    let out = lamina(&[
        "check",
        pipeline.to_str().expect("utf-8"),
        "--plugin",
        other.to_str().expect("utf-8"),
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("exports no `lamina_plugin_entry_v1`"), "{err}");
}
