//! What the integration tests share: the `lamina` binary, the repository's folders,
//! the real models of `../shared/models`, and the rule for what a test needs but may
//! not find (skip with a note; fail under `LAMINA_REQUIRE`, as `.ci/run` sets it).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The repository's root.
pub fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// The example pipelines.
pub fn pipelines() -> PathBuf {
    root().join("pipelines")
}

/// `cargo <args>` in `dir` for the workspace's own crates (the plugin libraries the
/// tests load): into the workspace's target folder, in the profile the tests were
/// built with (`cargo test` builds in `test`, `cargo test --release` in `release`), so
/// that the artifacts `cargo test` made are found fresh instead of the tree being
/// compiled again (with the compiler driver they were made with: .ci/run compiles the
/// workspace with clippy's).
pub fn cargo(dir: &Path, args: &[&str]) -> Command {
    let profile = if profile_dir() == "debug" {
        "test"
    } else {
        profile_dir()
    };
    let mut command = cargo_in(dir, args);
    command.args(["--profile", profile]);
    command
}

/// `cargo <args>` in `dir`, into the workspace's target folder. `RUSTC_BOOTSTRAP` is
/// not passed on: a runner may set it for libtest's per-test times (.ci/timed), and
/// cargo rebuilds everything when it changes.
fn cargo_in(dir: &Path, args: &[&str]) -> Command {
    let mut command = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()));
    command
        .current_dir(dir)
        .env_remove("RUSTC_BOOTSTRAP")
        .args(args)
        .arg("--target-dir")
        .arg(target_dir());
    command
}

/// `cargo <args>` in `dir` for a crate outside the workspace (a scaffolded plugin, the
/// skewed fixture): its own workspace and profiles, so nothing of the workspace's
/// build is reused, and the quickest to compile (the default `dev` profile, in
/// `target/debug`) serves best. Clippy's driver is not passed on (.ci/run compiles the
/// workspace with it): the crate is built as its author's cargo builds it.
pub fn cargo_outside(dir: &Path, args: &[&str]) -> Command {
    let mut command = cargo_in(dir, args);
    command
        .env_remove("RUSTC_WORKSPACE_WRAPPER")
        .env_remove("CLIPPY_ARGS");
    command
}

/// The folder under the target folder that holds the artifacts of the tests' profile.
pub fn profile_dir() -> &'static str {
    Path::new(env!("CARGO_BIN_EXE_lamina"))
        .parent()
        .and_then(Path::file_name)
        .and_then(|d| d.to_str())
        .unwrap_or("debug")
}

/// The folder every build the tests start shares with the workspace's.
pub fn target_dir() -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| root().join("target"))
}

/// Runs the `lamina` binary with `args` in the current folder.
pub fn lamina(args: &[&str]) -> Output {
    lamina_in(Path::new("."), args)
}

/// Runs the `lamina` binary with `args` in `dir`.
pub fn lamina_in(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_lamina"))
        .current_dir(dir)
        .args(args)
        .output()
        .expect("lamina runs")
}

/// A process's output as text.
pub fn text(out: &[u8]) -> String {
    String::from_utf8_lossy(out).into_owned()
}

/// `lamina run --quiet --out <out> <pipeline> --allow <models> [extra]`, whatever its
/// outcome: the pipeline may read the real models (`../shared/models`) too.
pub fn try_run(pipeline: &Path, out: &Path, extra: &[&str]) -> Output {
    let mut args = vec!["run", "--quiet", "--out"];
    let out_str = out.to_str().expect("utf-8 path");
    let pipeline_str = pipeline.to_str().expect("utf-8 path");
    args.extend([out_str, pipeline_str]);
    let allow = allow_models();
    args.extend(allow.iter().map(String::as_str));
    args.extend(extra);
    lamina(&args)
}

/// [`try_run`], which must succeed, and the JSON plan it wrote as `json` (a path under
/// `out`).
pub fn run_plan(pipeline: &Path, out: &Path, extra: &[&str], json: &str) -> serde_json::Value {
    let o = try_run(pipeline, out, extra);
    assert!(
        o.status.success(),
        "lamina run {}: {}",
        pipeline.display(),
        text(&o.stderr)
    );
    read_json(&out.join(json))
}

/// Writes `text` as `dir/p.toml` and runs it into `dir/out` (which must succeed);
/// returns the JSON plan the pipeline writes as `json`.
pub fn run_text(dir: &Path, text: &str, json: &str) -> serde_json::Value {
    let path = write(dir, "p.toml", text);
    run_plan(&path, &dir.join("out"), &[], json)
}

/// Writes `text` as `dir/p.toml` and runs it into `dir/out`, whatever the outcome.
pub fn try_run_text(dir: &Path, text: &str) -> Output {
    let path = write(dir, "p.toml", text);
    try_run(&path, &dir.join("out"), &[])
}

/// Writes `text` as `dir/name`; returns its path.
pub fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    path
}

/// A JSON file, parsed.
pub fn read_json(path: &Path) -> serde_json::Value {
    let s = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&s).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

pub use lamina_test_support::skip;

/// `../shared/models` (or `LAMINA_MODELS`), when it exists; otherwise the test skips
/// (or fails under `LAMINA_REQUIRE`).
pub fn models_dir() -> Option<PathBuf> {
    let dir = models_path();
    if dir.is_dir() {
        Some(dir.canonicalize().unwrap_or(dir))
    } else {
        skip(&format!("{} not found", dir.display()));
        None
    }
}

/// `--allow <models folder>`: a pipeline reads a model outside its own folder only where
/// the command line allows (the folder need not exist).
pub fn allow_models() -> [String; 2] {
    ["--allow".into(), models_path().to_string_lossy().into_owned()]
}

/// `LAMINA_MODELS`, or `../shared/models` beside the repository, whether it exists.
fn models_path() -> PathBuf {
    std::env::var_os("LAMINA_MODELS")
        .map(PathBuf::from)
        .unwrap_or_else(|| root().join("../shared/models"))
}

/// A model of `models_dir()`, when it is there; otherwise the test skips (or fails).
pub fn model(name: &str) -> Option<PathBuf> {
    let path = models_dir()?.join(name);
    if path.is_file() {
        Some(path)
    } else {
        skip(&format!("{} not found", path.display()));
        None
    }
}

/// An ASCII STL of the axis-aligned box from `min` to `max`, outward winding: two
/// triangles a face, each face's corners counter-clockwise seen from outside.
pub fn box_stl(min: [f64; 3], max: [f64; 3]) -> String {
    let v = |i: usize| [0, 1, 2].map(|a| if i & (1 << a) != 0 { max[a] } else { min[a] });
    let faces = [
        [0, 2, 3, 1],
        [4, 5, 7, 6],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 4, 6, 2],
        [1, 3, 7, 5],
    ];
    let mut stl = String::from("solid box\n");
    for q in faces {
        for t in [[q[0], q[1], q[2]], [q[0], q[2], q[3]]] {
            stl.push_str("facet normal 0 0 0\nouter loop\n");
            for i in t {
                let [x, y, z] = v(i);
                stl.push_str(&format!("vertex {x} {y} {z}\n"));
            }
            stl.push_str("endloop\nendfacet\n");
        }
    }
    stl + "endsolid box\n"
}

/// Makes the folder `to` a copy of `from`, leaving out `target` folders and writing
/// only the files that differ (so that a build of the copy stays incremental). What
/// `to` holds that `from` no longer does goes: a source file moved since the last copy
/// (`offset.rs` to `offset/mod.rs`) would otherwise stay and break the copy's build.
pub fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).expect("folder");
    for entry in std::fs::read_dir(to).expect("read folder") {
        let entry = entry.expect("entry");
        if entry.file_name() != "target" && !from.join(entry.file_name()).exists() {
            let path = entry.path();
            if entry.file_type().expect("file type").is_dir() {
                std::fs::remove_dir_all(&path).expect("remove folder");
            } else {
                std::fs::remove_file(&path).expect("remove file");
            }
        }
    }
    for entry in std::fs::read_dir(from).expect("read folder") {
        let entry = entry.expect("entry");
        let (src, dst) = (entry.path(), to.join(entry.file_name()));
        if entry.file_type().expect("file type").is_dir() {
            if entry.file_name() != "target" {
                copy_dir(&src, &dst);
            }
        } else {
            let bytes = std::fs::read(&src).expect("read");
            if std::fs::read(&dst).ok().as_ref() != Some(&bytes) {
                std::fs::write(&dst, bytes).expect("write");
            }
        }
    }
}
