//! Grading benchmark: what a Rhai grading function costs in a whole pipeline on
//! 3DBenchy at 0.2 mm (load, slice, sort, `offset` into 10 sub-regions per family,
//! grade, JSON). The same pipeline runs with the Rhai `script` grader and with the
//! built-in `xy` grader; the report gives the grade stage's share of the summed stage
//! time and the difference in wall time. Scripts are called once per region, never per
//! point, so the share stays small.
//!
//! Run: `cargo bench --bench grading` (median of 5 after a warm-up; `--quick`: one run).

use std::path::Path;
use std::time::Duration;

use lamina_core::pipeline::Pipeline;
use lamina_core::runtime::{Engine, RunOptions, RunReport, Silent};
use lamina_core::{SourceFile, StageKind};

#[path = "common/mod.rs"]
mod common;
use common::{median, registry};

fn pipeline(models: &Path, grade: &str) -> String {
    format!(
        "name = \"grading-bench\"\n[model]\nuse = \"stl\"\nfile = \"{}\"\n\
         [materials.ceramic]\ncolour = [240, 240, 230]\n[materials.metal]\ncolour = [90, 90, 100]\n\
         [slice]\nuse = \"uniform\"\nthickness = 0.2\n\
         [discretise]\nuse = \"offset\"\ncount = 10\nspacing = 0.4\n\
         [grade]\n{grade}\n\
         [[output]]\nuse = \"json\"\npath = \"plan.jsonl\"\nform = \"lines\"\n",
        models.join("3DBenchy.stl").display()
    )
}

fn run(text: &str, out: &Path) -> RunReport {
    let file = SourceFile::new(out.join("bench.toml"), text.to_string());
    let pipeline = Pipeline::parse(file, out.to_path_buf(), &[]).expect("pipeline");
    let engine = Engine::build(pipeline, registry(), &RunOptions::default()).expect("engine");
    engine.run(&out.join("out"), &Silent).expect("runs")
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let Some(models) = common::benchy_dir() else {
        println!(
            "note: ../shared/models/3DBenchy.stl not found (set LAMINA_MODELS); grading benchmark skipped"
        );
        return;
    };
    let dir = tempfile::tempdir().expect("tempdir");
    let runs = if quick { 1 } else { 5 };
    let cases = [
        (
            "Rhai script",
            "use = \"script\"\nf = \"let s = sin(r * PI); clamp01(0.5 * (1.0 - r) + 0.5 * s * s)\"",
        ),
        ("built-in xy", "use = \"xy\"\nf = \"wave\""),
    ];
    println!("3DBenchy at 0.2 mm, offset into 10 sub-regions per family, {runs} run(s) after a warm-up");
    println!(
        "{:<14} {:>9} {:>9} {:>10} {:>12} {:>8}",
        "grader", "wall s", "grade s", "regions", "grade share", "µs/region"
    );
    let mut walls = Vec::new();
    for (name, grade) in cases {
        let text = pipeline(&models, grade);
        run(&text, dir.path());
        let mut wall = Vec::new();
        let mut grade_time = Vec::new();
        let mut share = Vec::new();
        let mut regions = 0;
        for _ in 0..runs {
            let r = run(&text, dir.path());
            let total: Duration = r.timings.entries().iter().map(|(_, d)| *d).sum();
            let g = r.timings.get(StageKind::Grade);
            wall.push(r.timings.wall());
            grade_time.push(g);
            share.push(Duration::from_secs_f64(g.as_secs_f64() / total.as_secs_f64()));
            regions = r.regions;
        }
        let (w, g, s) = (median(wall), median(grade_time), median(share));
        println!(
            "{name:<14} {:>9.3} {:>9.3} {regions:>10} {:>11.1}% {:>8.2}",
            w.as_secs_f64(),
            g.as_secs_f64(),
            s.as_secs_f64() * 100.0,
            g.as_secs_f64() * 1e6 / regions.max(1) as f64
        );
        walls.push(w);
    }
    let extra = walls[0].as_secs_f64() - walls[1].as_secs_f64();
    println!(
        "the Rhai function adds {:.3} s of wall time ({:.1}% of the Rhai pipeline's wall time)",
        extra,
        100.0 * extra / walls[0].as_secs_f64()
    );
}
