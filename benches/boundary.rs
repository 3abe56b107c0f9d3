//! Plugin boundary benchmark: whole jobs run with the linked stages and with every stage
//! reached through the plugin boundary (each call a MessagePack request and reply,
//! stages behind handles, scripts and files served by the host), as a dynamic plugin's
//! stages are. The report gives the wall time of each and the boundary's share.
//!
//! A second table times one stage on its own: the `z` grader on the 881 families of
//! the buildings mesh at 1 mm layers, on one thread, linked and through the boundary
//! (the grade stage's own time, from the run's timings): what a grader costs as a
//! dynamic plugin, whose families of a layer travel in one call.
//!
//! Run: `cargo bench --bench boundary` (median of 5 after a warm-up; `--quick`: one
//! run; `--grader`: the second table only). The Benchy and buildings jobs are skipped
//! with a note when their models are absent from `../shared/models` (or the folder
//! `LAMINA_MODELS` names).

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use lamina_core::pipeline::{Override, Pipeline};
use lamina_core::runtime::{Engine, RunOptions, Silent};
use lamina_core::{Registry, SourceFile, StageKind};

#[path = "common/mod.rs"]
mod common;
use common::{benchy_dir, median, models_dir, registry};

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

/// The grade stage's time in one single-threaded run of the buildings mesh.
fn grade_time(registry: &Registry, models: &Path, out: &Path) -> Duration {
    let text = format!(
        "[model]\nuse = \"stl\"\nfile = {:?}\n\n[materials.a]\ncolour = [255, 0, 0]\n[materials.b]\ncolour = [0, 0, 255]\n\n\
         [slice]\nuse = \"uniform\"\nthickness = 1.0\n\n[discretise]\nuse = \"offset\"\ncount = 3\n\n\
         [grade]\nuse = \"z\"\n\n[[output]]\nuse = \"json\"\npath = \"plan.json\"\n",
        models.join("openfoam_buildings_400k.stl").display().to_string()
    );
    let file = SourceFile::new(out.join("buildings.toml"), text);
    let reach = lamina_core::reach::Reach::folder(out).with(&[models.to_path_buf()]);
    let pipeline = Pipeline::parse_within(file, out.to_path_buf(), reach, &[]).expect("pipeline");
    let options = RunOptions {
        threads: Some(1),
        ..RunOptions::default()
    };
    let engine = Engine::build(pipeline, registry.clone(), &options).expect("engine");
    let report = engine.run(&out.join("out"), &Silent).expect("runs");
    report.timings.get(StageKind::Grade)
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let grader_only = std::env::args().any(|a| a == "--grader");
    let runs = if quick { 1 } else { 5 };
    let linked = registry();
    let mut remote = Registry::new();
    lamina_core::plugin::add_linked_through_boundary(&mut remote, "bench")
        .expect("the linked stages as a plugin");
    remote.adopt_defaults(&linked).expect("one default a kind");
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
    if grader_only {
        jobs.clear();
    } else {
        println!(
            "{:<24} {:>12} {:>16} {:>8}",
            "job", "linked (s)", "boundary (s)", "ratio"
        );
    }
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
    let models = models_dir();
    if !models.join("openfoam_buildings_400k.stl").exists() {
        println!("note: openfoam_buildings_400k.stl not found; the grader job is skipped");
        return;
    }
    println!(
        "\n{:<24} {:>12} {:>16} {:>8}",
        "grade stage", "linked (s)", "boundary (s)", "ratio"
    );
    let measure = |registry: &Registry| {
        grade_time(registry, &models, out.path());
        median(
            (0..runs)
                .map(|_| grade_time(registry, &models, out.path()))
                .collect(),
        )
    };
    let (a, b) = (measure(&linked), measure(&remote));
    println!(
        "{:<24} {:>12.4} {:>16.4} {:>8.2}",
        "buildings, z grader",
        a.as_secs_f64(),
        b.as_secs_f64(),
        b.as_secs_f64() / a.as_secs_f64()
    );
}
