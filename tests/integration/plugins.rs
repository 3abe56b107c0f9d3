//! Dynamic plugins end to end: the example `zigzag` crate and the fixtures are built as
//! shared libraries, loaded by the `lamina` binary, and run, refused or contained.
//!
//! `LAMINA_PLUGIN_HOST` names another `lamina` binary to load them with (continuous
//! integration uses the release build).

use crate::support::{cargo, cargo_outside, copy_dir, profile_dir, root, target_dir, write};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

/// Builds the plugin libraries once per test run and returns their folder.
fn libraries() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        // The whole workspace's libraries, with the targets `cargo test --workspace`
        // built: the same features resolve (dev-dependencies included), so after it
        // nothing is compiled again.
        let status = cargo(root(), &["build", "--quiet", "--workspace", "--lib", "--tests"])
            .status()
            .expect("cargo runs");
        assert!(status.success(), "building the plugin libraries failed");
        target_dir().join(profile_dir())
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

/// The host that loads the plugins.
fn host() -> PathBuf {
    std::env::var_os("LAMINA_PLUGIN_HOST")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_BIN_EXE_lamina")))
}

fn lamina(args: &[&str]) -> std::process::Output {
    Command::new(host()).args(args).output().expect("lamina runs")
}

/// `lamina run <pipeline> --plugin <lib> --out <out_dir>`.
fn run_with_plugin(pipeline: &Path, lib: &Path, out_dir: &Path) -> std::process::Output {
    lamina(&[
        "run",
        pipeline.to_str().expect("utf-8"),
        "--plugin",
        lib.to_str().expect("utf-8"),
        "--out",
        out_dir.to_str().expect("utf-8"),
    ])
}

/// `lamina check <pipeline> --plugin <lib>`.
fn check_with_plugin(pipeline: &Path, lib: &Path) -> std::process::Output {
    lamina(&[
        "check",
        pipeline.to_str().expect("utf-8"),
        "--plugin",
        lib.to_str().expect("utf-8"),
    ])
}

/// The layers of the JSON plan (`plan.json` in `out_dir`) of a run that must have
/// succeeded.
fn plan_layers(out: &std::process::Output, out_dir: &Path) -> Vec<serde_json::Value> {
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let plan: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out_dir.join("plan.json")).expect("written")).expect("json");
    plan["layers"].as_array().expect("layers").clone()
}

fn write_pipeline(dir: &Path, extra: &str) -> PathBuf {
    write(
        dir,
        "p.toml",
        &format!(
            "[model]\nuse = \"tube\"\nheight = 2.0\n\n[materials.a]\ncolour = [255, 0, 0]\n\n[slice]\nuse = \"uniform\"\nthickness = 0.5\n\n[[output]]\nuse = \"json\"\npath = \"plan.json\"\n\n{extra}"
        ),
    )
}

#[test]
fn example_plugin_is_loaded_and_plans_toolpaths() {
    let lib = library("lamina-zigzag");
    let dir = tempfile::tempdir().expect("tempdir");
    // Listed by the pipeline, relative to its folder.
    std::fs::copy(&lib, dir.path().join("zigzag.so")).expect("copy library");
    let pipeline = write_pipeline(dir.path(), "[plan]\nuse = \"zigzag\"\nwidth = 0.5\n");
    let text = std::fs::read_to_string(&pipeline).expect("read");
    std::fs::write(&pipeline, format!("plugins = [\"zigzag.so\"]\n{text}")).expect("write");
    let out_dir = dir.path().join("out");
    let run = |extra: &[&str]| {
        let mut args = vec![
            "run",
            pipeline.to_str().expect("utf-8"),
            "--out",
            out_dir.to_str().expect("utf-8"),
        ];
        args.extend(extra);
        lamina(&args)
    };
    // The pipeline says it needs the library; it runs only when the command line loads
    // it (a pipeline is data, and cannot make code run).
    let refused = run(&[]);
    assert_eq!(refused.status.code(), Some(2));
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(
        err.contains("cannot load code by itself") && err.contains("--plugin"),
        "{err}"
    );
    assert!(!out_dir.exists(), "a refused run wrote {}", out_dir.display());
    let loaded = dir.path().join("zigzag.so");
    let out = run(&["--plugin", loaded.to_str().expect("utf-8")]);
    let layers = plan_layers(&out, &out_dir);
    assert_eq!(layers.len(), 4);
    for layer in &layers {
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

/// `lamina check` with a fixture library that must be refused from its file: returns
/// the error output, after checking the exit code and (on Linux, where the fixtures
/// carry an initialiser that leaves a marker) that the loader never ran the library.
fn refused_before_loading(crate_name: &str) -> String {
    let lib = library(crate_name);
    let dir = tempfile::tempdir().expect("tempdir");
    let pipeline = write_pipeline(dir.path(), "");
    let marker = dir.path().join("initialiser-ran");
    let out = Command::new(host())
        .args([
            "check",
            pipeline.to_str().expect("utf-8"),
            "--plugin",
            lib.to_str().expect("utf-8"),
        ])
        .env("LAMINA_FIXTURE_MARKER", &marker)
        .output()
        .expect("lamina runs");
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(2), "{err}");
    if cfg!(target_os = "linux") {
        assert!(!marker.exists(), "the refused library's initialiser ran");
    }
    err
}

#[test]
fn plugin_of_another_abi_is_refused_naming_both_versions() {
    let err = refused_before_loading("lamina-fixture-bad-abi");
    assert!(err.contains("plugin ABI 99.0"), "{err}");
    let major = lamina_core::plugin::ABI_MAJOR;
    assert!(
        err.contains("rebuild it against this lamina's lamina-api")
            && err.contains(&format!("(plugin ABI {major}.0 to {major}.")),
        "{err}"
    );
}

#[test]
fn panicking_plugin_is_an_error_not_an_abort() {
    let lib = library("lamina-fixture-panic");
    let dir = tempfile::tempdir().expect("tempdir");
    let pipeline = write_pipeline(dir.path(), "[grade]\nuse = \"panics\"\n");
    let out_dir = dir.path().join("out");
    let out = run_with_plugin(&pipeline, &lib, &out_dir);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("panicked") && err.contains("this grader always panics"),
        "{err}"
    );
    assert!(err.contains("panicking/grade:panics"), "{err}");
    assert!(!out_dir.join("plan.json").exists());
}

/// `lamina run` with the fixture's `grader`, each plugin in a process of its own.
fn run_apart(dir: &Path, grader: &str, extra: &[&str]) -> (std::process::Output, PathBuf) {
    let lib = library("lamina-fixture-panic");
    let pipeline = write_pipeline(dir, &format!("[grade]\nuse = \"{grader}\"\n"));
    let out_dir = dir.join("out");
    let mut args = vec![
        "run",
        pipeline.to_str().expect("utf-8"),
        "--plugin",
        lib.to_str().expect("utf-8"),
        "--isolate-plugins",
        "--out",
        out_dir.to_str().expect("utf-8"),
    ];
    args.extend(extra);
    (lamina(&args), out_dir)
}

#[test]
fn a_plugin_that_crashes_apart_fails_the_run_with_its_name() {
    for (grader, signal) in [("crashes", "SIGSEGV"), ("aborts", "SIGABRT"), ("panics", "")] {
        let dir = tempfile::tempdir().expect("tempdir");
        let (out, out_dir) = run_apart(dir.path(), grader, &[]);
        let err = String::from_utf8_lossy(&out.stderr);
        // Exit 1, not a signal: lamina itself did not crash.
        assert_eq!(out.status.code(), Some(1), "{grader}: {err}");
        assert!(err.contains(&format!("panicking/grade:{grader}")), "{err}");
        if signal.is_empty() {
            assert!(err.contains("this grader always panics"), "{err}");
        } else {
            assert!(
                err.contains("plugin `panicking`") && err.contains("crashed") && err.contains(signal),
                "{err}"
            );
        }
        assert!(!out_dir.join("plan.json").exists(), "{grader}");
        let left: Vec<_> = std::fs::read_dir(dir.path())
            .expect("dir")
            .map(|e| e.expect("entry").file_name())
            .collect();
        assert_eq!(left, ["p.toml"], "{grader}: no core file, no partial output");
    }
}

#[test]
fn a_plugin_that_hangs_apart_is_stopped_after_the_timeout() {
    let dir = tempfile::tempdir().expect("tempdir");
    let start = std::time::Instant::now();
    let (out, out_dir) = run_apart(dir.path(), "hangs", &["--plugin-timeout", "1"]);
    let took = start.elapsed();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("plugin `panicking`") && err.contains("did not answer within 1 s"),
        "{err}"
    );
    assert!(took < std::time::Duration::from_secs(30), "{took:?}");
    assert!(!out_dir.join("plan.json").exists());
    let pipeline = dir.path().join("p.toml");
    let pipeline = pipeline.to_str().expect("utf-8");
    let zero = lamina(&["check", pipeline, "--plugin-timeout", "0"]);
    assert_eq!(zero.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&zero.stderr).contains("--plugin-timeout"));
}

#[test]
fn a_plugin_apart_gives_what_it_gives_in_process_and_its_prints_stay_out_of_the_messages() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (apart, out_dir) = run_apart(dir.path(), "prints", &[]);
    let apart_plan = std::fs::read(out_dir.join("plan.json"));
    let err = String::from_utf8_lossy(&apart.stderr);
    assert!(apart.status.success(), "{err}");
    assert!(err.contains("from the plugin's stdout"), "{err}");
    assert!(!String::from_utf8_lossy(&apart.stdout).contains("from the plugin's stdout"));
    let lib = library("lamina-fixture-panic");
    let here = run_with_plugin(&dir.path().join("p.toml"), &lib, &dir.path().join("here"));
    assert!(here.status.success(), "{}", String::from_utf8_lossy(&here.stderr));
    let here_plan = std::fs::read(dir.path().join("here/plan.json"));
    assert_eq!(
        apart_plan.expect("written apart"),
        here_plan.expect("written in process")
    );
}

/// The ids of the processes that loaded the fixture while `args` ran, and lamina's.
#[cfg(target_os = "linux")]
fn loaded_by(args: &[&str]) -> (Vec<u32>, u32) {
    let dir = tempfile::tempdir().expect("tempdir");
    let record = dir.path().join("loaded-by");
    let child = Command::new(host())
        .args(args)
        .env("LAMINA_FIXTURE_LOADED_BY", &record)
        .stdout(std::process::Stdio::null())
        .spawn()
        .expect("lamina runs");
    let pid = child.id();
    let out = child.wait_with_output().expect("lamina ends");
    assert!(out.status.success(), "{args:?}");
    let pids = std::fs::read_to_string(&record)
        .unwrap_or_default()
        .lines()
        .map(|l| l.parse().expect("a process id"))
        .collect();
    (pids, pid)
}

#[cfg(target_os = "linux")]
#[test]
fn check_and_plugins_run_no_plugin_code_in_lamina() {
    let lib = library("lamina-fixture-panic");
    let lib = lib.to_str().expect("utf-8");
    let dir = tempfile::tempdir().expect("tempdir");
    let pipeline = write_pipeline(dir.path(), "[grade]\nuse = \"prints\"\n");
    let pipeline = pipeline.to_str().expect("utf-8");
    let out_dir = dir.path().join("out");
    // A run in process loads it in lamina itself, and the record shows it.
    let (pids, lamina_pid) = loaded_by(&[
        "run",
        pipeline,
        "--plugin",
        lib,
        "--out",
        out_dir.to_str().expect("utf-8"),
    ]);
    assert_eq!(pids, [lamina_pid]);
    for args in [
        vec!["check", pipeline, "--plugin", lib],
        vec!["plugins", "grade", "--plugin", lib],
    ] {
        let (pids, lamina_pid) = loaded_by(&args);
        assert!(!pids.is_empty(), "{args:?}: the plugin was loaded somewhere");
        assert!(
            !pids.contains(&lamina_pid),
            "{args:?}: loaded by lamina itself ({pids:?})"
        );
    }
}

#[test]
fn a_file_that_is_not_a_plugin_is_refused() {
    let dir = tempfile::tempdir().expect("tempdir");
    let fake = dir.path().join("fake.so");
    std::fs::write(&fake, b"not a library").expect("write");
    let pipeline = write_pipeline(dir.path(), "");
    let out = check_with_plugin(&pipeline, &fake);
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
        let out = check_with_plugin(&pipeline, &path);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{name}: {err}");
        assert!(err.contains(expected) && err.contains(name), "{name}: {err}");
    }
    // A real library that is not a Lamina plugin: refused by its exports.
    let other = dir.path().join("plain.so");
    let mut plain = lib.clone();
    for at in plain
        .windows(b"lamina_plugin_zigzag".len())
        .enumerate()
        .filter(|(_, w)| *w == b"lamina_plugin_zigzag")
        .map(|(i, _)| i)
        .collect::<Vec<_>>()
    {
        plain[at] = b'X';
    }
    std::fs::write(&other, &plain).expect("write");
    let out = check_with_plugin(&pipeline, &other);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("exports no `lamina_plugin_<name>`"), "{err}");
}

#[test]
fn plugin_whose_boundary_struct_changed_is_refused_before_loading() {
    let err = refused_before_loading("lamina-fixture-changed-layout");
    assert!(
        err.contains("plugin `changed_layout`")
            && err.contains("lays out the boundary's C types differently"),
        "{err}"
    );
    assert!(
        err.contains("rebuild it against this lamina's lamina-api"),
        "{err}"
    );
}

/// Runs a two-material tube graded by `grade` (with the dynamic script fixture loaded)
/// and returns the exit code, the error output, the plan and the run's wall time.
fn graded_run(dir: &Path, grade: &str) -> (Option<i32>, String, Option<String>, std::time::Duration) {
    std::fs::write(
        dir.join("grading.rhai"),
        "fn smooth(z) { let t = clamp01(z / 2.0); 1.0 - t * t * (3.0 - 2.0 * t) }\n\
         fn by_array(r, x, y, layer, part) { let a = []; a.push(lerp(0.0, 1.0, clamp01(r))); a.push(1.0 - a[0]); if a.len() != 2 { throw \"len\"; } a }\n\
         fn clock(z) { let t = timestamp(); clamp01(sin(z * PI / 4.0).abs()) }\n\
         fn forever(z) { loop { } }\n\
         fn too_much(z) { 2.0 }\n",
    )
    .expect("script");
    let path = write(
        dir,
        "g.toml",
        &format!(
            "[model]\nuse = \"tube\"\nheight = 2.0\n\n[materials.a]\ncolour = [255, 0, 0]\n[materials.b]\ncolour = [0, 0, 255]\n\n[slice]\nuse = \"uniform\"\nthickness = 0.5\n\n[discretise]\nuse = \"offset\"\ncount = 3\n\n[grade]\n{grade}\n\n[[output]]\nuse = \"json\"\npath = \"plan.json\"\n"
        ),
    );
    let out_dir = dir.join("out");
    let _ = std::fs::remove_dir_all(&out_dir);
    let lib = library("lamina-fixture-script");
    let start = std::time::Instant::now();
    let out = run_with_plugin(&path, &lib, &out_dir);
    let took = start.elapsed();
    let plan = std::fs::read_to_string(out_dir.join("plan.json")).ok();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
        plan,
        took,
    )
}

#[test]
fn a_dynamic_plugins_scripts_run_in_the_hosts_sandbox_as_the_built_in_graders_do() {
    let dir = tempfile::tempdir().expect("tempdir");
    let cases = [
        "f = \"sin(r * PI) * 0.5 + 0.25\"",
        "f = \"clamp01(z / 2.0)\"",
        "f = \"grading.rhai#smooth\"",
        "f = \"grading.rhai#by_array\"",
        "f = \"lerp(0.2, 0.8, r) + power(1.0, 0.0, 1.0) * 0.0 + linear(0.0, 0.1, r) * 0.0\"",
    ];
    for case in cases {
        let (code, err, plan, _) = graded_run(dir.path(), &format!("use = \"script\"\n{case}"));
        assert_eq!(code, Some(0), "built in, {case}: {err}");
        let (dyn_code, dyn_err, dyn_plan, _) =
            graded_run(dir.path(), &format!("use = \"dyn-script\"\n{case}"));
        assert_eq!(dyn_code, Some(0), "dynamic, {case}: {dyn_err}");
        assert_eq!(plan, dyn_plan, "{case}: the dynamic grader's plan differs");
    }
    // Failures: the same error, pointing at the same place, and an endless script is
    // stopped by the host's clock.
    let failures = [
        ("f = \"grading.rhai#forever\"", "stopped"),
        ("f = \"grading.rhai#too_much\"", "outside [0, 1]"),
        ("f = \"undefined_function(r)\"", "Function not found"),
        ("f = \"grading.rhai#missing\"", "has no function `missing`"),
        // The host's scripts read no clock, and neither do the plugin's.
        ("f = \"grading.rhai#clock\"", "timestamp"),
    ];
    for (case, expected) in failures {
        let (code, err, plan, took) = graded_run(dir.path(), &format!("use = \"script\"\n{case}"));
        let (dyn_code, dyn_err, dyn_plan, dyn_took) =
            graded_run(dir.path(), &format!("use = \"dyn-script\"\n{case}"));
        assert!(
            code.is_some_and(|c| c != 0) && plan.is_none(),
            "built in, {case}: {err}"
        );
        assert_eq!(dyn_code, code, "dynamic, {case}: {dyn_err}");
        assert!(dyn_plan.is_none());
        assert!(err.contains(expected), "built in, {case}: {err}");
        // The messages differ only in the stage's name.
        assert_eq!(
            dyn_err
                .replace("script_fixture/grade:dyn-script", "grade:script")
                .replace("use = \"dyn-script\"", "use = \"script\""),
            err,
            "{case}"
        );
        if expected == "stopped" {
            assert!(
                took.as_secs_f64() < 2.0 && dyn_took.as_secs_f64() < 2.0,
                "{took:?} {dyn_took:?}"
            );
        }
    }
}

#[test]
fn an_endless_script_in_a_dynamic_plugin_is_stopped_within_a_second() {
    let dir = tempfile::tempdir().expect("tempdir");
    for f in ["loop { }", "let a = [3, 1, 2]; a.sort(|x, y| { loop { } }); 0.5"] {
        let (code, err, plan, took) = graded_run(dir.path(), &format!("use = \"dyn-script\"\nf = '{f}'"));
        assert_eq!(code, Some(1), "{f}: {err}");
        assert!(plan.is_none());
        assert!(err.contains("stopped"), "{f}: {err}");
        // One script call is stopped after 0.5 s; the whole run takes little more.
        assert!(took.as_secs_f64() < 1.5, "{f}: {took:?}");
    }
}

/// Lamina's stage API (and geometry) as a later commit of it: a comment and a test
/// changed, the messages not. What a plugin built against it must not notice.
fn later_commit_of_the_api() -> PathBuf {
    let copy = target_dir().join("outside-commit");
    for dir in ["api", "geom", "tests/outside/skewed-plugin"] {
        copy_dir(&root().join(dir), &copy.join(dir));
    }
    // The workspace the two crates name their versions and dependencies from.
    let manifest: toml::Table = std::fs::read_to_string(root().join("Cargo.toml"))
        .expect("Cargo.toml")
        .parse()
        .expect("TOML");
    let mut workspace = manifest["workspace"].as_table().expect("[workspace]").clone();
    workspace.insert("members".into(), toml::Value::from(vec!["api", "geom"]));
    if let Some(deps) = workspace
        .get_mut("dependencies")
        .and_then(toml::Value::as_table_mut)
    {
        deps.retain(|name, _| name != "lamina-core" && name != "lamina-machine");
    }
    let mut root_manifest = toml::Table::new();
    root_manifest.insert("workspace".into(), toml::Value::Table(workspace));
    let text = toml::to_string(&root_manifest).expect("manifest");
    if std::fs::read_to_string(copy.join("Cargo.toml")).ok().as_deref() != Some(text.as_str()) {
        std::fs::write(copy.join("Cargo.toml"), text).expect("write manifest");
    }
    let model = copy.join("api/src/model.rs");
    let text = std::fs::read_to_string(&model).expect("model.rs");
    let later = "\n// A later commit's comment.\n#[cfg(test)]\nmod a_later_commits_test {\n    #[test]\n    \
                 fn holds() {\n        assert!(super::COMPOSITION_TOLERANCE < 1.0);\n    }\n}\n";
    if !text.ends_with(later) {
        std::fs::write(&model, text + later).expect("write model.rs");
    }
    copy
}

/// Builds the plugin crate outside the workspace, with its own lock file, against a
/// later commit of the stage API than the one the host was built from.
fn outside_library() -> PathBuf {
    let copy = later_commit_of_the_api();
    let status = cargo_outside(
        root(),
        &[
            "build",
            "--quiet",
            "--locked",
            "--manifest-path",
            copy.join("tests/outside/skewed-plugin/Cargo.toml")
                .to_str()
                .expect("UTF-8 path"),
        ],
    )
    .status()
    .expect("cargo runs");
    assert!(status.success(), "building the outside plugin failed");
    target_dir().join("debug").join(format!(
        "{}lamina_fixture_skewed{}",
        std::env::consts::DLL_PREFIX,
        std::env::consts::DLL_SUFFIX
    ))
}

/// The lock file of a crate, as `name -> version`.
fn locked_versions(lock: &Path) -> std::collections::BTreeMap<String, String> {
    let text = std::fs::read_to_string(lock).expect("lock file");
    let doc: toml::Table = text.parse().expect("lock file is TOML");
    doc["package"]
        .as_array()
        .expect("packages")
        .iter()
        .filter_map(|p| {
            Some((
                p.get("name")?.as_str()?.to_string(),
                p.get("version")?.as_str()?.to_string(),
            ))
        })
        .collect()
}

/// Also: the plugin is built against a later commit of lamina-api than the host's (a
/// comment and a test changed, not the messages), and loads all the same.
#[test]
fn a_plugin_resolving_other_releases_of_the_boundarys_dependencies_runs_correctly() {
    let lib = outside_library();
    // The premise: its lock file and the host's disagree on crates whose types cross.
    let ours = locked_versions(&root().join("Cargo.lock"));
    let theirs = locked_versions(&root().join("tests/outside/skewed-plugin/Cargo.lock"));
    for name in ["serde", "toml", "rmp-serde"] {
        assert_ne!(
            ours.get(name),
            theirs.get(name),
            "{name} resolves the same release in both"
        );
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("s.toml");
    std::fs::write(
        &path,
        "[model]\nuse = \"skewed-box\"\nsize = [10.0, 8.0, 2.0]\n\n[materials.a]\ncolour = [255, 0, 0]\n[materials.b]\ncolour = [0, 0, 255]\n\n\
         [slice]\nuse = \"uniform\"\nthickness = 0.5\n\n[discretise]\nuse = \"offset\"\ncount = 2\n\n\
         [grade]\nuse = \"skewed-z\"\nf = \"clamp01(z / 2.0)\"\n\n[[output]]\nuse = \"json\"\npath = \"plan.json\"\n",
    )
    .expect("pipeline");
    let out_dir = dir.path().join("out");
    let out = run_with_plugin(&path, &lib, &out_dir);
    let layers = plan_layers(&out, &out_dir);
    assert_eq!(layers.len(), 4);
    for layer in &layers {
        let z = layer["z"].as_f64().expect("z");
        let regions = layer["parts"][0]["families"][0]["sub_regions"]
            .as_array()
            .expect("regions");
        let area: f64 = regions.iter().map(|r| r["area"].as_f64().expect("area")).sum();
        assert!((area - 80.0).abs() < 1e-9, "z = {z}: {area}");
        for r in regions {
            let a = r["composition"]["a"].as_f64().expect("graded");
            assert!((a - (z / 2.0).clamp(0.0, 1.0)).abs() < 1e-12, "z = {z}: {a}");
        }
    }
    // An option the plugin's own serde refuses is reported at its place in the file.
    let text = std::fs::read_to_string(&path).expect("read");
    std::fs::write(
        &path,
        text.replace("size = [10.0, 8.0, 2.0]", "size = [10.0, 8.0]"),
    )
    .expect("write");
    let out = check_with_plugin(&path, &lib);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("s.toml:3:") && err.contains("size"), "{err}");
}

#[test]
fn a_plugins_own_process_operation_runs_across_the_boundary() {
    // The example plugin's `cure` step: a UV lamp over each layer's outline, the last
    // layer's pass marked `final` from what the host told it (ProcessContext::last).
    let lib = library("lamina-zigzag");
    let dir = tempfile::tempdir().expect("tempdir");
    let pipeline = write_pipeline(dir.path(), "[[process]]\nuse = \"cure\"\npower = 80.0\n");
    let out_dir = dir.path().join("out");
    let out = run_with_plugin(&pipeline, &lib, &out_dir);
    let layers = plan_layers(&out, &out_dir);
    assert_eq!(layers.len(), 4);
    for (i, layer) in layers.iter().enumerate() {
        let ops = layer["operations"].as_array().expect("operations");
        assert_eq!(ops.len(), 1);
        let op = &ops[0];
        assert_eq!(op["kind"], "cure");
        assert_eq!(
            op["pass"].as_str().unwrap_or(""),
            if i == 3 { "final" } else { "" }
        );
        assert_eq!(op["values"]["dose"], 4.0);
        // The tube's outer contour, radius 10, a closed pass 5 mm above the layer.
        let path = &op["paths"][0];
        assert_eq!(path["closed"], true);
        let z = layer["z"].as_f64().expect("z");
        assert!((path["z"].as_f64().expect("z") - z - 5.0).abs() < 1e-9);
        for p in path["points"].as_array().expect("points") {
            let r = p[0].as_f64().expect("x").hypot(p[1].as_f64().expect("y"));
            assert!((r - 10.0).abs() < 1e-6, "{r}");
        }
    }
}
