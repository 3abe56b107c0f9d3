//! Helpers the benchmark binaries share (each includes this file with `#[path]`): where
//! the real models are, the registry of every linked plugin, single stages built from
//! a snippet, an STL model loaded as a pipeline would load it, the slicer and sorter
//! of the slicing runs, and medians.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::time::Duration;

use lamina_core::stage::{Slicer, Sorter};
use lamina_core::{AnyStage, Mesh, Registry, StageKind};

/// `$LAMINA_MODELS`, else ../shared/models beside the repository; it may not exist.
pub fn models_dir() -> PathBuf {
    std::env::var_os("LAMINA_MODELS")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/models"))
}

/// The models folder when it holds 3DBenchy.stl.
pub fn benchy_dir() -> Option<PathBuf> {
    let dir = models_dir();
    dir.join("3DBenchy.stl").exists().then_some(dir)
}

/// The registry of every plugin crate the benchmarks link.
pub fn registry() -> Registry {
    use lamina_discretise as _;
    use lamina_export as _;
    use lamina_gcode as _;
    use lamina_grade as _;
    use lamina_model as _;
    use lamina_plan as _;
    use lamina_slice as _;
    use lamina_sort as _;
    Registry::linked().expect("registry")
}

/// One stage of `kind` from a TOML snippet, paths relative to `dir`.
pub fn stage(kind: StageKind, text: &str, dir: &Path) -> AnyStage {
    let table = lamina_core::pipeline::TableRef::parse_snippet(kind.name(), text).expect("snippet");
    let scripts = lamina_core::script::local(dir, Default::default());
    registry()
        .build_any(kind, &table, &scripts, dir)
        .expect("stage builds")
}

/// The STL `file` of `dir`, welded and dropped to the bed as a pipeline loads it.
pub fn load(dir: &Path, file: &str) -> Mesh {
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

/// The uniform slicer at `thickness` and the hierarchy sorter, paths relative to `dir`.
pub fn slicer_and_sorter(dir: &Path, thickness: f64) -> (Box<dyn Slicer>, Box<dyn Sorter>) {
    let slice = format!("use = \"uniform\"\nthickness = {thickness}");
    match (
        stage(StageKind::Slice, &slice, dir),
        stage(StageKind::Sort, "use = \"hierarchy\"", dir),
    ) {
        (AnyStage::Slice(slicer), AnyStage::Sort(sorter)) => (slicer, sorter),
        _ => unreachable!(),
    }
}

pub fn median(mut v: Vec<Duration>) -> Duration {
    v.sort();
    v[v.len() / 2]
}
