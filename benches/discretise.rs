//! Discretising benchmark on 3DBenchy at 0.2 mm (from ../shared/models or
//! $LAMINA_MODELS): the `offset` discretiser with N_R = 10 at 0.4 mm steps on every
//! family of every layer (all threads), and a 512 x 512 signed distance field with 10
//! iso-levels per layer (one thread), timed apart. Slicing is done beforehand and not timed.
//!
//! Run: `cargo bench --bench discretise` (the median of 5 runs; `--quick` runs once).

use std::path::Path;
use std::sync::Arc;
use std::time::{Duration, Instant};

use lamina_core::Contour;
use lamina_core::stage::{Discretiser, FamilyContext, MeshSlicer};
use lamina_core::{AnyStage, ContourTree, Layer, RunInfo, StageKind};
use lamina_discretise::distance_field::Levels;
use lamina_geom::field::Field;
use lamina_geom::iso::iso_levels;
use rayon::prelude::*;

#[path = "common/mod.rs"]
mod common;
use common::{load, median, slicer_and_sorter, stage};

/// Every layer of the model at 0.2 mm with its contour tree.
fn layers(dir: &Path, file: &str) -> (RunInfo, Vec<(Layer, ContourTree)>) {
    let mesh = Arc::new(load(dir, file));
    let (slicer, sorter) = slicer_and_sorter(dir, 0.2);
    let info = lamina_test_support::mesh_info(dir, &mesh);
    let slots = slicer
        .layers(std::slice::from_ref(&mesh), &info, None)
        .expect("slots");
    let prepared: Box<dyn MeshSlicer> = slicer.prepare(mesh).expect("prepare");
    let layers = slots
        .par_iter()
        .map(|s| {
            let layer = prepared.slice(s).expect("slice");
            let tree = sorter.sort(&layer).expect("sort");
            (layer, tree)
        })
        .collect();
    (info, layers)
}

/// Time this thread has spent on a CPU (from the scheduler's statistics, in ns), so
/// that one-thread figures hold on a machine shared with other work; wall-clock time
/// where the statistics are missing.
fn cpu_time() -> Duration {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()
        .and_then(|s| s.split_whitespace().next()?.parse::<u64>().ok())
        .map(Duration::from_nanos)
        .unwrap_or_else(|| {
            static START: std::sync::OnceLock<Instant> = std::sync::OnceLock::new();
            START.get_or_init(Instant::now).elapsed()
        })
}

/// CPU time of the whole process (all threads, user and system), in clock ticks of
/// 10 ms; `None` where /proc is missing.
fn process_cpu() -> Option<Duration> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    let fields: Vec<&str> = stat.rsplit_once(')')?.1.split_whitespace().collect();
    let ticks: u64 = fields.get(11)?.parse::<u64>().ok()? + fields.get(12)?.parse::<u64>().ok()?;
    Some(Duration::from_millis(ticks * 10))
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let dir = common::models_dir();
    if !dir.join("3DBenchy.stl").exists() {
        println!(
            "note: 3DBenchy.stl not found in {}; benchmark skipped",
            dir.display()
        );
        return;
    }
    let runs = if quick { 1 } else { 5 };
    let (info, layers) = layers(&dir, "3DBenchy.stl");
    let vertices: usize = layers
        .iter()
        .flat_map(|(l, _)| &l.contours)
        .map(|c| c.len())
        .sum();
    let families: usize = layers.iter().map(|(_, t)| t.families.len()).sum();
    println!(
        "3DBenchy.stl at 0.2 mm: {} layers, {families} families, {vertices} contour vertices",
        layers.len()
    );

    // `--only offset` or `--only field` runs one part (for profiling).
    let args: Vec<String> = std::env::args().collect();
    let only = args
        .iter()
        .position(|a| a == "--only")
        .and_then(|i| args.get(i + 1))
        .cloned();
    let part = |name: &str| only.as_deref().is_none_or(|o| o == name);
    if part("offset") {
        offset_part(&info, &layers, &dir, runs);
    }
    if part("field") {
        field_part(&layers, runs);
    }
}

fn offset_part(info: &RunInfo, layers: &[(Layer, ContourTree)], dir: &Path, runs: usize) {
    let AnyStage::Discretise(offset) = stage(
        StageKind::Discretise,
        "use = \"offset\"\ncount = 10\nspacing = 0.4",
        dir,
    ) else {
        unreachable!()
    };
    let run_offset = |d: &dyn Discretiser| -> (Duration, usize) {
        let start = Instant::now();
        let regions: usize = layers
            .par_iter()
            .map(|(layer, tree)| {
                let polygons = tree.family_polygons(&layer.contours);
                (0..tree.families.len())
                    .map(|family| {
                        let ctx = FamilyContext {
                            info,
                            layer,
                            tree,
                            polygons: &polygons,
                            mesh: None,
                            part: 0,
                            family,
                        };
                        d.discretise(&ctx).expect("discretises").len()
                    })
                    .sum::<usize>()
            })
            .sum();
        (start.elapsed(), regions)
    };
    let _ = run_offset(offset.as_ref());
    let mut times = Vec::new();
    let mut regions = 0;
    let cpu0 = process_cpu();
    for _ in 0..runs {
        let (t, n) = run_offset(offset.as_ref());
        times.push(t);
        regions = n;
    }
    let cpu = process_cpu().zip(cpu0).map(|(b, a)| (b - a) / runs as u32);
    println!(
        "offset N_R = 10, 0.4 mm: {:>8.1} ms for the whole job on {} threads, {} ms of CPU ({regions} regions; target <= 2000 ms)",
        median(times).as_secs_f64() * 1e3,
        rayon::current_num_threads(),
        cpu.map_or("?".to_string(), |c| format!("{:.0}", c.as_secs_f64() * 1e3)),
    );
}

fn field_part(layers: &[(Layer, ContourTree)], runs: usize) {
    // As the peers measured it: one 512 x 512 field over each layer (all its contours,
    // signed by the inside) and 10 iso-levels of it.
    let mut field_ms = Vec::new();
    let mut iso_ms = Vec::new();
    for _ in 0..runs {
        let (mut t_field, mut t_iso) = (Duration::ZERO, Duration::ZERO);
        let mut loops = 0;
        for (layer, _) in layers {
            let start = cpu_time();
            let contours: Vec<&Contour> = layer.contours.iter().collect();
            let Some(bbox) = layer
                .contours
                .iter()
                .map(Contour::bbox)
                .reduce(|a, b| a.union(&b))
            else {
                continue;
            };
            let mut field = Field::over(&bbox, 512);
            field.distance_to(&contours);
            let inside = field.inside(&contours);
            let max = field.values.iter().copied().fold(0.0f64, f64::max);
            for (v, &i) in field.values.iter_mut().zip(&inside) {
                *v = if i { *v / max } else { -*v / max };
            }
            let mid = cpu_time();
            let levels: Vec<f64> = (1..=10).map(|k| k as f64 / 11.0).collect();
            let sets = iso_levels(&field, &field.values, &levels);
            loops += sets.iter().map(Vec::len).sum::<usize>();
            t_iso += cpu_time() - mid;
            t_field += mid - start;
        }
        std::hint::black_box(loops);
        field_ms.push(t_field / layers.len() as u32);
        iso_ms.push(t_iso / layers.len() as u32);
    }
    let (f, i) = (median(field_ms), median(iso_ms));
    println!(
        "distance field 512 x 512 + 10 iso-levels: {:>6.2} ms on one core per layer ({:.2} field + {:.2} iso-contours; target <= 5 ms)",
        (f + i).as_secs_f64() * 1e3,
        f.as_secs_f64() * 1e3,
        i.as_secs_f64() * 1e3
    );

    // The discretiser itself: a field per family, clipped into bands.
    let df = lamina_test_support::boundary_field(Levels::Equal(11), 512);
    let start = Instant::now();
    let mut loops = 0;
    for (layer, tree) in layers {
        for f in 0..tree.families.len() {
            let polygon = tree.family_polygon(&layer.contours, f);
            if let Some(iso) = df.iso_sets(&polygon, None) {
                loops += iso.sets.iter().map(Vec::len).sum::<usize>();
            }
        }
    }
    std::hint::black_box(loops);
    println!(
        "distance-field iso-sets, 512 cells per family: {:>6.2} ms per layer on one thread",
        start.elapsed().as_secs_f64() * 1e3 / layers.len() as f64
    );
}
