//! Golden outputs: every example pipeline runs, and every file it writes is compared
//! with its reviewed snapshot in `golden/snapshots/` (insta). Large files are kept as a
//! digest and a summary read from the format (layers, beads, filament per tool, areas
//! per material, first and last lines), so a changed output shows *what* changed.
//!
//! A change is accepted with `cargo insta review` (or `INSTA_UPDATE=always cargo test
//! --test integration golden::` and `git diff`); CONTRIBUTING.md says what a commit
//! that changes a snapshot must tell. Numbers are compared after [`normalise`].

mod cli;
mod files;
mod gcode;
mod nc;
pub mod normalise;
mod plan;

use std::collections::BTreeSet;
use std::fmt::Write;
use std::path::{Path, PathBuf};

use sha2::{Digest, Sha256};

use crate::support::{model, pipelines, root, text, try_run};

/// The digest of `bytes` as written: the first 16 hex digits of their SHA-256.
pub fn digest_bytes(bytes: &[u8]) -> String {
    let hash = Sha256::digest(bytes);
    let hex: String = hash[..8].iter().map(|b| format!("{b:02x}")).collect();
    format!("sha256:{hex}")
}

/// The digest of `text` once [`normalise::text`] has rounded what may move.
pub fn digest_text(text: &str) -> String {
    digest_bytes(normalise::text(text).as_bytes())
}

/// Lines longer than this are cut, with the count of what was cut.
const LINE: usize = 160;

fn clip(line: &str) -> String {
    if line.len() <= LINE {
        return line.to_string();
    }
    let mut end = LINE;
    while !line.is_char_boundary(end) {
        end -= 1;
    }
    format!("{}… [+{} bytes]", &line[..end], line.len() - end)
}

/// The first and last `n` lines of `text`, normalised and clipped (all of it, once,
/// when it has no more than `2 n` lines).
pub fn clipped_ends(text: &str, n: usize) -> String {
    let lines: Vec<&str> = text.lines().collect();
    let mut s = String::new();
    let mut put = |title: &str, lines: &[&str]| {
        writeln!(s, "{title}").ok();
        for line in lines {
            writeln!(s, "| {}", clip(&normalise::text(line))).ok();
        }
    };
    if lines.len() <= 2 * n {
        put(&format!("all {} lines:", lines.len()), &lines);
    } else {
        put(&format!("first {n} lines:"), &lines[..n]);
        put(&format!("last {n} lines:"), &lines[lines.len() - n..]);
    }
    s
}

/// The summary of one output file, by its kind.
fn summarise(path: &Path) -> String {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let extension = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    let as_text = || String::from_utf8_lossy(&bytes).into_owned();
    match extension.as_str() {
        "gcode" => gcode::summary(&as_text()),
        "nc" => nc::summary(&as_text()),
        "cli" => cli::summary(&bytes),
        "json" => plan::summary(&as_text()),
        "3mf" => files::threemf(&bytes),
        "png" => files::png(&bytes),
        "dat" => files::bitmap_data(&bytes, path),
        "svg" => files::svg(&as_text()),
        _ if std::str::from_utf8(&bytes).is_ok() => files::text(&as_text()),
        _ => files::binary(&bytes),
    }
}

/// Every file under `dir`, as paths relative to it, in order.
fn written(dir: &Path) -> Vec<PathBuf> {
    fn walk(dir: &Path, base: &Path, out: &mut Vec<PathBuf>) {
        let Ok(entries) = std::fs::read_dir(dir) else {
            return;
        };
        for entry in entries.flatten() {
            let path = entry.path();
            if path.is_dir() {
                walk(&path, base, out);
            } else if let Ok(relative) = path.strip_prefix(base) {
                out.push(relative.to_path_buf());
            }
        }
    }
    let mut out = Vec::new();
    walk(dir, dir, &mut out);
    out.sort();
    out
}

fn snapshots() -> PathBuf {
    root().join("tests/integration/golden/snapshots")
}

/// Runs `pipeline` (with `extra` arguments) and compares every file it writes with the
/// snapshots named `<name>__<file>`; a snapshot of that name whose file the run no
/// longer writes fails too.
fn check(name: &str, pipeline: &Path, extra: &[&str]) {
    let out = tempfile::tempdir().expect("tempdir");
    let result = try_run(pipeline, out.path(), extra);
    assert!(
        result.status.success(),
        "{}: {}",
        pipeline.display(),
        text(&result.stderr)
    );
    let files = written(out.path());
    assert!(!files.is_empty(), "{}: wrote nothing", pipeline.display());
    let mut settings = insta::Settings::clone_current();
    settings.set_prepend_module_to_snapshot(false);
    settings.set_omit_expression(true);
    let mut names = BTreeSet::new();
    for file in &files {
        let shown = file.to_string_lossy().replace(['/', '\\'], "_");
        let snapshot = format!("{name}__{shown}");
        // Where the checkout and the models are is no part of the output.
        let mut run = vec![
            pipeline
                .strip_prefix(root())
                .unwrap_or(pipeline)
                .display()
                .to_string(),
        ];
        run.extend(extra.iter().map(|a| match Path::new(a).file_name() {
            Some(name) if Path::new(a).is_absolute() => name.to_string_lossy().into_owned(),
            _ => a.to_string(),
        }));
        settings.set_description(format!("lamina run {}: {}", run.join(" "), file.display()));
        let summary = summarise(&out.path().join(file));
        settings.bind(|| insta::assert_snapshot!(snapshot.clone(), summary));
        names.insert(format!("{snapshot}.snap"));
    }
    let prefix = format!("{name}__");
    let stale: Vec<String> = std::fs::read_dir(snapshots())
        .into_iter()
        .flatten()
        .flatten()
        .filter_map(|e| e.file_name().into_string().ok())
        .filter(|f| f.starts_with(&prefix) && f.ends_with(".snap") && !names.contains(f))
        .collect();
    assert!(
        stale.is_empty(),
        "{name}: snapshots of files the run no longer writes: {stale:?} (remove them)"
    );
}

/// The examples, each with its golden test below; those that read `../shared/models`
/// have their own, with the acceptance suite.
const EXAMPLES: &[&str] = &[
    "assembly",
    "assembly-two-tools",
    "blade-idw",
    "blade-skin",
    "blade-zxy",
    "distance-field-power",
    "gear-mixing-gcode",
    "gear-z-gradient",
    "gear-z-wave",
    "grading-sources",
    "pipe-work-cycles",
    "tube-gradient",
];

#[test]
fn every_example_pipeline_has_a_golden_test() {
    let mut found: Vec<String> = std::fs::read_dir(pipelines())
        .expect("pipelines/")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .filter(|p| {
            let text = std::fs::read_to_string(p).expect("read");
            !text.contains("shared/models")
        })
        .filter_map(|p| Some(p.file_stem()?.to_str()?.to_string()))
        .collect();
    found.sort();
    assert_eq!(found, EXAMPLES, "pipelines/ against golden::EXAMPLES");
}

macro_rules! golden {
    ($($test:ident: $name:literal,)*) => {$(
        #[test]
        fn $test() {
            check($name, &pipelines().join(concat!($name, ".toml")), &[]);
        }
    )*};
}

golden! {
    assembly: "assembly",
    assembly_two_tools: "assembly-two-tools",
    blade_idw: "blade-idw",
    blade_skin: "blade-skin",
    blade_zxy: "blade-zxy",
    distance_field_power: "distance-field-power",
    gear_mixing_gcode: "gear-mixing-gcode",
    gear_z_gradient: "gear-z-gradient",
    gear_z_wave: "gear-z-wave",
    grading_sources: "grading-sources",
    pipe_work_cycles: "pipe-work-cycles",
    tube_gradient: "tube-gradient",
}

/// The two-tool 3DBenchy on one shipped machine profile (needs `../shared/models`).
fn benchy_on(machine: &str) {
    let Some(benchy) = model("3DBenchy.stl") else {
        return;
    };
    let benchy = benchy.to_str().expect("utf-8 path").to_string();
    let set = format!("machine=\"{machine}\"");
    check(
        &format!("benchy-two-tools-{machine}"),
        &pipelines().join("benchy-two-tools.toml"),
        &["--model", &benchy, "--set", &set],
    );
}

macro_rules! benchy {
    ($($test:ident: $machine:literal,)*) => {$(
        #[test]
        #[ignore = "needs ../shared/models (acceptance)"]
        fn $test() {
            benchy_on($machine);
        }
    )*};
}

benchy! {
    benchy_two_tools_marlin_mixing_2in1: "marlin-mixing-2in1",
    benchy_two_tools_marlin_toolchanger_2: "marlin-toolchanger-2",
    benchy_two_tools_rrf_dual_gantry_2: "rrf-dual-gantry-2",
    benchy_two_tools_rrf_idex_2: "rrf-idex-2",
    benchy_two_tools_rrf_two_systems_2: "rrf-two-systems-2",
}

#[test]
fn every_shipped_machine_profile_has_a_benchy_golden_test() {
    let mut profiles: Vec<String> = std::fs::read_dir(root().join("machine/profiles"))
        .expect("machine/profiles/")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .filter_map(|p| Some(p.file_stem()?.to_str()?.to_string()))
        .collect();
    profiles.sort();
    let tested = [
        "marlin-mixing-2in1",
        "marlin-toolchanger-2",
        "rrf-dual-gantry-2",
        "rrf-idex-2",
        "rrf-two-systems-2",
    ];
    assert_eq!(
        profiles, tested,
        "machine/profiles/ against the benchy golden tests"
    );
}
