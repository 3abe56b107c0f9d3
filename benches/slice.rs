//! Slicing benchmark: load + weld, index, cut every layer, resolve loops and build the
//! hierarchy at 0.2 mm on the real meshes of ../shared/models (or $LAMINA_MODELS), and
//! on a >= 1M-triangle mesh made by subdividing one of them.
//!
//! Run: `cargo bench --bench slice` (prints a table; the median of 5 runs after a
//! warm-up). `--quick` runs each model once.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use lamina_core::stage::{MeshSlicer, Slicer, Sorter};
use lamina_core::{AnyStage, Mesh, Point3, Registry, RunInfo, StageKind};
use rayon::prelude::*;

fn stage(kind: StageKind, text: &str, dir: &Path) -> AnyStage {
    use lamina_model as _;
    use lamina_slice as _;
    use lamina_sort as _;
    let table = lamina_core::pipeline::TableRef::parse_snippet(kind.name(), text).expect("snippet");
    let scripts = lamina_core::script::ScriptHost::new(dir, Default::default());
    Registry::linked()
        .expect("registry")
        .build(kind, &table, &scripts, dir)
        .expect("stage builds")
}

fn load(dir: &Path, file: &str) -> Mesh {
    let AnyStage::Model(source) = stage(
        StageKind::Model,
        &format!("use = \"stl\"\nfile = \"{file}\""),
        dir,
    ) else {
        unreachable!()
    };
    let mut meshes = source.load(dir).expect("loads");
    lamina_core::runtime::place(&mut meshes, 1.0, lamina_core::pipeline::Placement::Bed);
    meshes.remove(0)
}

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
    slice: Duration,
    layers: usize,
    contours: usize,
}

fn run(dir: &Path, file: &str, mesh: Option<&Mesh>, thickness: f64) -> Times {
    let start = Instant::now();
    let mesh = Arc::new(match mesh {
        Some(m) => m.clone(),
        None => load(dir, file),
    });
    let load_time = start.elapsed();
    let start = Instant::now();
    let AnyStage::Slice(slicer) = stage(
        StageKind::Slice,
        &format!("use = \"uniform\"\nthickness = {thickness}"),
        dir,
    ) else {
        unreachable!()
    };
    let AnyStage::Sort(sorter) = stage(StageKind::Sort, "use = \"hierarchy\"", dir) else {
        unreachable!()
    };
    let bb = mesh.bbox();
    let info = RunInfo {
        base_dir: dir.to_path_buf(),
        materials: Vec::new(),
        parts: Vec::new(),
        z_min: bb.min.z,
        z_max: bb.max.z,
    };
    let slots = slicer
        .layers(std::slice::from_ref(&mesh), &info, None)
        .expect("slots");
    let prepared: Box<dyn MeshSlicer> = slicer.prepare(mesh.clone()).expect("prepare");
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
        slice: start.elapsed(),
        layers: slots.len(),
        contours,
    }
}

fn median(mut v: Vec<Duration>) -> Duration {
    v.sort();
    v[v.len() / 2]
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let dir = std::env::var_os("LAMINA_MODELS")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/models"));
    if !dir.is_dir() {
        println!("note: {} not found; slicing benchmark skipped", dir.display());
        return;
    }
    let runs = if quick { 1 } else { 5 };
    println!("threads: {}", rayon::current_num_threads());
    println!(
        "{:<40} {:>9} {:>7} {:>9} {:>10} {:>10} {:>10}",
        "model (0.2 mm)", "triangles", "layers", "contours", "load ms", "slice ms", "total ms"
    );
    let big = load(&dir, "3DBenchy.stl");
    let big = subdivide(&subdivide(&big));
    for (file, mesh) in [
        ("3DBenchy.stl", None),
        ("turbine_blade_vtk.stl", None),
        ("openfoam_buildings_400k.stl", None),
        ("3DBenchy.stl subdivided x16", Some(&big)),
    ] {
        if mesh.is_none() && !dir.join(file).exists() {
            continue;
        }
        let _warm = run(&dir, file, mesh, 0.2);
        let mut loads = Vec::new();
        let mut slices = Vec::new();
        let mut last = None;
        for _ in 0..runs {
            let t = run(&dir, file, mesh, 0.2);
            loads.push(t.load);
            slices.push(t.slice);
            last = Some(t);
        }
        let t = last.expect("ran");
        let (l, s) = (median(loads), median(slices));
        let triangles = mesh.map_or_else(|| load(&dir, file).triangles.len(), |m| m.triangles.len());
        println!(
            "{:<40} {:>9} {:>7} {:>9} {:>10.1} {:>10.1} {:>10.1}",
            file,
            triangles,
            t.layers,
            t.contours,
            l.as_secs_f64() * 1e3,
            s.as_secs_f64() * 1e3,
            (l + s).as_secs_f64() * 1e3
        );
    }
}
