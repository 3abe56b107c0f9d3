//! Planning benchmark: the whole job on 3DBenchy at 0.2 mm (load, slice, sort, `offset`
//! into 10 graded sub-regions per family, contour-parallel toolpaths for two concurrent
//! tools, tool-change G-code), as `pipelines/benchy-two-tools.toml` runs it, in process.
//! The report gives the wall time, each stage's time summed over threads, and the
//! concurrent/sequential build-time ratio of the two-tool assembly and Benchy pipelines
//! (the targets: <= 1.9 s wall, ratio <= 0.7).
//!
//! Run: `cargo bench --bench plan` (median of 5 after a warm-up; `--quick`: one run).
//! Benchy is skipped with a note when `../shared/models/3DBenchy.stl` is absent (or
//! `LAMINA_MODELS` names another folder holding it).

use std::path::{Path, PathBuf};
use std::time::Duration;

use lamina_core::StageKind;
use lamina_core::pipeline::{Override, Pipeline};
use lamina_core::runtime::{Engine, RunOptions, RunReport, Silent};

#[path = "common/mod.rs"]
mod common;
use common::{median, registry};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn set(s: &str) -> Override {
    s.parse().expect("override")
}

/// Runs a pipeline of `pipelines/` with overrides, writing under `out`.
fn run(name: &str, overrides: &[Override], out: &Path) -> RunReport {
    // The Benchy pipeline reads its model beside the repository.
    let models = [root().join("../shared/models")];
    let pipeline =
        Pipeline::load_allowing(&root().join("pipelines").join(name), overrides, &models).expect("pipeline");
    let engine = Engine::build(pipeline, registry(), &RunOptions::default()).expect("engine");
    engine.run(out, &Silent).expect("runs")
}

/// Concurrent and sequential planned build times (s) of one pipeline.
fn ratio(name: &str, overrides: &[Override], out: &Path) -> (f64, f64) {
    let conc = run(name, overrides, out).build_time.unwrap_or(0.0);
    let mut seq_overrides = overrides.to_vec();
    seq_overrides.push(set("plan.use=\"sequential\""));
    let seq = run(name, &seq_overrides, out).build_time.unwrap_or(0.0);
    (conc, seq)
}

fn print_ratio(label: &str, (conc, seq): (f64, f64)) {
    let r = if seq > 0.0 { conc / seq } else { 1.0 };
    println!("{label:<22} {conc:>12.1} {seq:>12.1} {r:>8.3}");
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let runs = if quick { 1 } else { 5 };
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("out");
    let model = common::benchy_dir().map(|d| d.join("3DBenchy.stl"));
    let benchy_overrides: Vec<Override> = model
        .iter()
        .map(|f| set(&format!("model.file={:?}", f.display().to_string())))
        .collect();

    match &model {
        None => {
            println!("note: ../shared/models/3DBenchy.stl not found (set LAMINA_MODELS); Benchy job skipped")
        }
        Some(_) => {
            println!("3DBenchy at 0.2 mm, 10 graded sub-regions per family, two concurrent tools, G-code");
            println!("{runs} run(s) after a warm-up");
            run("benchy-two-tools.toml", &benchy_overrides, &out);
            let mut walls = Vec::new();
            let mut stages: Vec<(StageKind, Vec<Duration>)> = Vec::new();
            for _ in 0..runs {
                let r = run("benchy-two-tools.toml", &benchy_overrides, &out);
                walls.push(r.timings.wall());
                for (kind, d) in r.timings.entries() {
                    match stages.iter_mut().find(|(k, _)| *k == kind) {
                        Some((_, v)) => v.push(d),
                        None => stages.push((kind, vec![d])),
                    }
                }
            }
            println!("{:<12} {:>9}", "stage", "s (summed over threads)");
            for (kind, v) in stages {
                println!("{:<12} {:>9.3}", kind.name(), median(v).as_secs_f64());
            }
            println!(
                "{:<12} {:>9.3}   (target <= 1.9)",
                "wall",
                median(walls).as_secs_f64()
            );
        }
    }

    println!();
    println!(
        "{:<22} {:>12} {:>12} {:>8}",
        "build time", "concurrent s", "sequential s", "ratio"
    );
    print_ratio("assembly-two-tools", ratio("assembly-two-tools.toml", &[], &out));
    if model.is_some() {
        print_ratio(
            "benchy-two-tools",
            ratio("benchy-two-tools.toml", &benchy_overrides, &out),
        );
    }
    println!("(target: ratio <= 0.7)");
}
