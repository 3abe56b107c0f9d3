//! Plugin boundary benchmark: whole jobs run with the linked stages and with every stage
//! reached through the plugin boundary (each call a MessagePack request and reply,
//! stages behind handles, scripts and files served by the host), as a dynamic plugin's
//! stages are. The report gives the wall time of each and the boundary's share.
//!
//! Run: `cargo bench --bench boundary` (median of 5 after a warm-up; `--quick`: one
//! run). The Benchy job is skipped with a note when `../shared/models/3DBenchy.stl` is
//! absent (or `LAMINA_MODELS` names another folder holding it).

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use lamina_core::Registry;
use lamina_core::pipeline::{Override, Pipeline};
use lamina_core::runtime::{Engine, RunOptions, Silent};

#[path = "common/mod.rs"]
mod common;
use common::{benchy_dir, median, registry};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// One run of a pipeline of `pipelines/` with `registry`; its wall time.
fn time(registry: &Registry, name: &str, overrides: &[Override], out: &Path) -> Duration {
    // The Benchy pipeline reads its model beside the repository.
    let models = [root().join("../shared/models")];
    let pipeline =
        Pipeline::load_allowing(&root().join("pipelines").join(name), overrides, &models).expect("pipeline");
    let start = Instant::now();
    let engine = Engine::build(pipeline, registry.clone(), &RunOptions::default()).expect("engine");
    engine.run(out, &Silent).expect("runs");
    start.elapsed()
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let runs = if quick { 1 } else { 5 };
    let linked = registry();
    let mut remote = Registry::new();
    lamina_core::plugin::add_linked_through_boundary(&mut remote, "bench")
        .expect("the linked stages as a plugin");
    let out = tempfile::tempdir().expect("tempdir");
    let mut jobs: Vec<(&str, Vec<Override>)> = vec![("tube-gradient.toml", Vec::new())];
    match benchy_dir() {
        Some(dir) => jobs.push((
            "benchy-two-tools.toml",
            vec![
                format!("model.file={:?}", dir.join("3DBenchy.stl").display().to_string())
                    .parse()
                    .expect("override"),
            ],
        )),
        None => println!("note: 3DBenchy.stl not found; the Benchy job is skipped"),
    }
    println!(
        "{:<24} {:>12} {:>16} {:>8}",
        "job", "linked (s)", "boundary (s)", "ratio"
    );
    for (name, overrides) in jobs {
        let measure = |registry: &Registry| {
            time(registry, name, &overrides, &out.path().join("warm-up"));
            median(
                (0..runs)
                    .map(|i| time(registry, name, &overrides, &out.path().join(i.to_string())))
                    .collect(),
            )
        };
        let a = measure(&linked);
        let b = measure(&remote);
        println!(
            "{name:<24} {:>12.3} {:>16.3} {:>8.2}",
            a.as_secs_f64(),
            b.as_secs_f64(),
            b.as_secs_f64() / a.as_secs_f64()
        );
    }
}
