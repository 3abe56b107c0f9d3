//! Slicing benchmark: load + weld, index, cut every layer, resolve loops and build the
//! hierarchy at 0.2 mm on the real meshes of ../shared/models (or $LAMINA_MODELS), and
//! on 3DBenchy subdivided into 4x and 16x the triangles (written as STL files first, so
//! the growth with size covers the whole path, load included).
//!
//! Run: `cargo bench --bench slice` (prints a table; the median of 5 runs after a
//! warm-up, and the time ratio of each 4x step). `--quick` runs each model once; other
//! words select models by a part of their name (`cargo bench --bench slice -- Benchy`).

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use lamina_core::stage::{MeshSlicer, Slicer, Sorter};
use lamina_core::{Mesh, Point3};
use rayon::prelude::*;

#[path = "common/mod.rs"]
mod common;
use common::{load, median, slicer_and_sorter};

/// Splits every triangle into four (midpoints shared through an edge map).
fn subdivide(mesh: &Mesh) -> Mesh {
    let mut vertices = mesh.vertices.clone();
    let mut mid = std::collections::HashMap::new();
    let mut midpoint = |a: u32, b: u32, vertices: &mut Vec<Point3>| {
        *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
            let p = Point3::from((vertices[a as usize].coords + vertices[b as usize].coords) * 0.5);
            vertices.push(p);
            (vertices.len() - 1) as u32
        })
    };
    let mut triangles = Vec::with_capacity(mesh.triangles.len() * 4);
    for &[a, b, c] in &mesh.triangles {
        let ab = midpoint(a, b, &mut vertices);
        let bc = midpoint(b, c, &mut vertices);
        let ca = midpoint(c, a, &mut vertices);
        triangles.extend([[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]);
    }
    Mesh::new(format!("{} x4", mesh.name), vertices, triangles)
}

struct Times {
    load: Duration,
    /// Preparing the mesh for cutting (the height index), part of `slice`.
    index: Duration,
    slice: Duration,
    triangles: usize,
    layers: usize,
    contours: usize,
}

fn run(dir: &Path, file: &str, thickness: f64) -> Times {
    let start = Instant::now();
    let mesh = Arc::new(load(dir, file));
    let load_time = start.elapsed();
    let start = Instant::now();
    let (slicer, sorter) = slicer_and_sorter(dir, thickness);
    let info = lamina_test_support::mesh_info(dir, &mesh);
    let slots = slicer
        .layers(std::slice::from_ref(&mesh), &info, None)
        .expect("slots");
    let prepared: Box<dyn MeshSlicer> = slicer.prepare(mesh.clone()).expect("prepare");
    let index = start.elapsed();
    let sorter: &dyn Sorter = sorter.as_ref();
    let contours: usize = slots
        .par_iter()
        .map(|s| {
            let layer = prepared.slice(s).expect("slice");
            let tree = sorter.sort(&layer).expect("sort");
            tree.nodes.len()
        })
        .sum();
    let _: &dyn Slicer = slicer.as_ref();
    Times {
        load: load_time,
        index,
        slice: start.elapsed(),
        triangles: mesh.triangles.len(),
        layers: slots.len(),
        contours,
    }
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

/// Writes Benchy subdivided once and twice (4x and 16x the triangles) as binary STL
/// files, so that the growth with mesh size is measured on the whole path, load included.
fn write_subdivided(dir: &Path, out: &Path) -> Vec<(String, PathBuf)> {
    let mut files = Vec::new();
    if !dir.join("3DBenchy.stl").exists() {
        return files;
    }
    let mut mesh = load(dir, "3DBenchy.stl");
    for factor in [4, 16] {
        mesh = subdivide(&mesh);
        let path = out.join(format!("3DBenchy_x{factor}.stl"));
        let file = std::fs::File::create(&path).expect("create");
        let mut w = std::io::BufWriter::new(file);
        lamina_model::stl::write_binary(&mesh, &mut w).expect("write");
        std::io::Write::flush(&mut w).expect("flush");
        files.push((format!("3DBenchy.stl subdivided x{factor}"), path));
    }
    files
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let quick = args.iter().any(|a| a == "--quick");
    // Words that are not options select models by a part of their name.
    let filters: Vec<&String> = args.iter().filter(|a| !a.starts_with('-')).collect();
    let dir = common::models_dir();
    if !dir.is_dir() {
        println!("note: {} not found; slicing benchmark skipped", dir.display());
        return;
    }
    let runs = if quick { 1 } else { 5 };
    let scratch = tempfile::tempdir().expect("temporary directory");
    let mut models: Vec<(String, PathBuf)> = [
        "3DBenchy.stl",
        "turbine_blade_vtk.stl",
        "openfoam_buildings_400k.stl",
    ]
    .iter()
    .map(|f| (f.to_string(), dir.join(f)))
    .filter(|(_, p)| p.exists())
    .collect();
    models.extend(write_subdivided(&dir, scratch.path()));
    models.retain(|(name, _)| filters.is_empty() || filters.iter().any(|f| name.contains(f.as_str())));
    println!("threads: {}, runs: {runs} (median)", rayon::current_num_threads());
    println!(
        "{:<34} {:>9} {:>6} {:>8} {:>8} {:>8} {:>8} {:>8}",
        "model (0.2 mm)", "triangles", "layers", "contours", "load ms", "index ms", "slice ms", "total ms"
    );
    let mut totals: Vec<(String, usize, f64)> = Vec::new();
    for (name, path) in &models {
        let (dir, file) = (
            path.parent().expect("in a directory"),
            path.file_name().expect("a file").to_string_lossy(),
        );
        let _warm = run(dir, &file, 0.2);
        let mut loads = Vec::new();
        let mut indexes = Vec::new();
        let mut slices = Vec::new();
        let mut totals_run = Vec::new();
        let mut last = None;
        for _ in 0..runs {
            let t = run(dir, &file, 0.2);
            loads.push(t.load);
            indexes.push(t.index);
            slices.push(t.slice);
            totals_run.push(t.load + t.slice);
            last = Some(t);
        }
        let t = last.expect("ran");
        let total = median(totals_run);
        println!(
            "{:<34} {:>9} {:>6} {:>8} {:>8.1} {:>8.1} {:>8.1} {:>8.1}",
            name,
            t.triangles,
            t.layers,
            t.contours,
            ms(median(loads)),
            ms(median(indexes)),
            ms(median(slices)),
            ms(total)
        );
        totals.push((name.clone(), t.triangles, ms(total)));
    }
    // Growth with size: each subdivision has 4x the triangles of the one before.
    let chain: Vec<&(String, usize, f64)> = totals
        .iter()
        .filter(|(n, _, _)| n.starts_with("3DBenchy"))
        .collect();
    for pair in chain.windows(2) {
        let (a, b) = (pair[0], pair[1]);
        println!(
            "growth {} -> {}: {:.2}x triangles, {:.2}x total time (target <= 4.4x for 4x)",
            a.0,
            b.0,
            b.1 as f64 / a.1 as f64,
            b.2 / a.2
        );
    }
}
