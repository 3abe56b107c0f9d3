//! Test support for Lamina stages, built-in or third-party: runs every stage's declared
//! example in a small pipeline on a generated model, and runs whole pipelines
//! in-process, with every built-in stage linked. It also holds what the workspace's own
//! tests and benchmarks share: a seeded generator ([`Rng`]), the run of one mesh
//! ([`mesh_info`]) and the boundary distance field ([`boundary_field`]).
//!
//! A plugin crate's tests link the crate itself (`use my_plugin as _;`), so its stages
//! register with the same registry as the built-in ones:
//!
//! ```no_run
//! // tests/examples.rs of a plugin crate named `my_plugin`
//! use my_plugin as _;
//!
//! #[test]
//! fn my_stages_examples_run() {
//!     lamina_test_support::assert_examples_run(&["my-grader"]);
//! }
//!
//! #[test]
//! fn a_pipeline_with_my_stage_runs() {
//!     let run = lamina_test_support::run_pipeline(include_str!("../pipeline.toml"));
//!     assert!(run.report.layers > 0);
//! }
//! # mod my_plugin {}
//! ```

use std::path::{Path, PathBuf};

use lamina_core::pipeline::Pipeline;
use lamina_core::pipeline::TableRef;
use lamina_core::registry::{Origin, Registered};
use lamina_core::runtime::{Engine, RunOptions, RunReport, Silent};
use lamina_core::{AnyStage, Registry, SourceFile, StageKind};

// Linked for their registrations.
use lamina_discretise as _;
use lamina_export as _;
use lamina_gcode as _;
use lamina_grade as _;
use lamina_orient as _;
use lamina_plan as _;
use lamina_preview as _;
use lamina_process as _;
use lamina_sequence as _;
use lamina_slice as _;
use lamina_sort as _;
use lamina_sources as _;

/// Every stage linked into the test program: the built-in ones and those of the crates
/// the test links.
pub fn registry() -> Registry {
    Registry::linked().unwrap_or_else(|e| panic!("the linked stages: {e}"))
}

/// Builds the `kind` stage a table names (`use = "..."` and its options, as a pipeline
/// table holds them without its header), with scripts and files relative to `dir`.
pub fn try_stage(kind: StageKind, table: &str, dir: &Path) -> lamina_core::Result<AnyStage> {
    let table = TableRef::parse_snippet(kind.name(), table)?;
    let scripts = lamina_core::script::local(dir, Default::default());
    registry().build_any(kind, &table, &scripts, dir)
}

/// [`try_stage`], which must build.
pub fn stage(kind: StageKind, table: &str, dir: &Path) -> AnyStage {
    try_stage(kind, table, dir).unwrap_or_else(|e| panic!("[{kind}] {table:?}: {e}"))
}

macro_rules! typed_stage {
    ($(#[$doc:meta])* $name:ident, $kind:ident, $trait:ident) => {
        $(#[$doc])*
        pub fn $name(table: &str) -> Box<dyn lamina_core::stage::$trait> {
            stage(StageKind::$kind, table, Path::new("."))
                .into_type()
                .unwrap_or_else(|e| panic!("[{}] {table:?}: {e}", StageKind::$kind))
        }
    };
}

typed_stage!(
    /// The slicer a `[slice]` table names.
    slicer, Slice, Slicer
);
typed_stage!(
    /// The sorter a `[sort]` table names.
    sorter, Sort, Sorter
);
typed_stage!(
    /// The discretiser a `[discretise]` table names.
    discretiser, Discretise, Discretiser
);
typed_stage!(
    /// The grader a `[grade]` table names.
    grader, Grade, Grader
);
typed_stage!(
    /// The planner a `[plan]` table names.
    planner, Plan, Planner
);
typed_stage!(
    /// The process stage a `[[process]]` table names.
    process, Process, Process
);

/// The meshes of the model a `[model]` table names, read relative to `dir`.
pub fn meshes(table: &str, dir: &Path) -> Vec<lamina_core::Mesh> {
    match stage(StageKind::Model, table, dir) {
        AnyStage::Model(source) => source
            .load(dir)
            .unwrap_or_else(|e| panic!("[model] {table:?}: {e}")),
        other => panic!("[model] {table:?} built a {} stage", other.kind()),
    }
}

/// The model every example runs on: a tube 2 mm high (20 mm across, 14 mm bore).
pub const MODEL: &str = "use = \"tube\"\nheight = 2.0";

/// Writes the tube as `part.stl`, `part.obj` and `part.3mf` in `dir`, for examples that
/// read a file.
pub fn write_models(dir: &Path) {
    let table =
        lamina_core::pipeline::TableRef::parse_snippet("model", MODEL).unwrap_or_else(|e| panic!("{e}"));
    let scripts = lamina_core::script::local(dir, Default::default());
    let mesh = match registry().build::<dyn lamina_core::ModelSource>(&table, &scripts, dir) {
        Ok(m) => m.load(dir).unwrap_or_else(|e| panic!("{e}")).remove(0),
        Err(e) => panic!("the tube generator: {e}"),
    };
    let mut stl = Vec::new();
    lamina_model::stl::write_binary(&mesh, &mut stl).unwrap_or_else(|e| panic!("{e}"));
    write(&dir.join("part.stl"), &stl);
    let mut obj = String::new();
    for v in &mesh.vertices {
        obj.push_str(&format!("v {} {} {}\n", v.x, v.y, v.z));
    }
    for t in &mesh.triangles {
        obj.push_str(&format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1));
    }
    write(&dir.join("part.obj"), obj.as_bytes());
    let package = lamina_model::threemf::write(std::slice::from_ref(&mesh)).unwrap_or_else(|e| panic!("{e}"));
    write(&dir.join("part.3mf"), &package);
}

fn write(path: &Path, bytes: &[u8]) {
    std::fs::write(path, bytes).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
}

/// A pipeline around one stage's table: the tube, uniform 0.5 mm layers, two materials
/// mixed by a constant grader (unless the stage is the grader) and a JSON plan (unless
/// the stage is the output).
pub fn pipeline_for(kind: StageKind, table: &str) -> String {
    let mut tables = vec![
        ("model", MODEL.to_string()),
        ("slice", "use = \"uniform\"\nthickness = 0.5".to_string()),
    ];
    let mut outputs = vec!["use = \"json\"\npath = \"plan.json\"".to_string()];
    let mut process = Vec::new();
    match kind {
        StageKind::Export => outputs = vec![table.to_string()],
        StageKind::Process => process.push(table.to_string()),
        k => {
            if let Some(t) = tables.iter_mut().find(|(n, _)| *n == k.name()) {
                t.1 = table.to_string();
            } else {
                tables.push((k.name(), table.to_string()));
            }
        }
    }
    let mut text =
        String::from("[materials.red]\ncolour = [255, 0, 0]\n[materials.green]\ncolour = [0, 255, 0]\n\n");
    if kind != StageKind::Grade {
        // Both materials stay on the part (a discretiser may name them) and a constant
        // grader says how they mix.
        text.push_str("[grade]\nuse = \"constant\"\nmaterial = \"red\"\n\n");
    }
    for (name, body) in tables {
        text.push_str(&format!("[{name}]\n{body}\n\n"));
    }
    for p in process {
        text.push_str(&format!("[[process]]\n{p}\n\n"));
    }
    for o in outputs {
        text.push_str(&format!("[[output]]\n{o}\n\n"));
    }
    text
}

/// Checks what a stage says about itself (one-line doc, every option documented, an
/// example that names the stage) and runs its example in [`pipeline_for`] inside
/// `dir`, which must hold [`write_models`]'s files. Returns the run's report.
pub fn check_example(registry: &Registry, entry: &Registered, dir: &Path) -> Result<RunReport, String> {
    let info = entry.info();
    let label = entry.label();
    if info.doc.is_empty() || info.doc.contains('\n') {
        return Err(format!("{label}: its doc must be one line"));
    }
    if !info.example.contains(&format!("use = \"{}\"", info.name)) {
        return Err(format!(
            "{label}: its example must name the stage (use = \"{}\")",
            info.name
        ));
    }
    if let Some(o) = info.options.iter().find(|o| o.doc.is_empty()) {
        return Err(format!("{label}: option `{}` is undocumented", o.name));
    }
    let text = pipeline_for(info.kind, info.example);
    let file = SourceFile::new(
        dir.join(format!("{}-{}.toml", info.kind, info.name)),
        text.clone(),
    );
    let pipeline =
        Pipeline::parse(file, dir.to_path_buf(), &[]).map_err(|e| format!("{label}: {e}\n{text}"))?;
    let engine = Engine::build(pipeline, registry.clone(), &RunOptions::default())
        .map_err(|e| format!("{label}: its example does not build: {e}\n{text}"))?;
    let out = dir.join("out").join(label.replace(':', "-"));
    let report = engine
        .run(&out, &Silent)
        .map_err(|e| format!("{label}: its example does not run: {e}\n{text}"))?;
    if report.layers == 0 || report.regions == 0 {
        return Err(format!("{label}: its example produced nothing\n{text}"));
    }
    if report.files.is_empty() {
        return Err(format!("{label}: its example wrote nothing\n{text}"));
    }
    Ok(report)
}

/// Runs the examples of the linked stages named in `names` (every linked stage when
/// `names` is empty) and panics with every failure. Each name must be registered.
pub fn assert_examples_run(names: &[&str]) {
    let registry = registry();
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("a temporary folder: {e}"));
    write_models(dir.path());
    for name in names {
        assert!(
            registry.list(None).iter().any(|e| e.info().name == *name),
            "no stage named `{name}` is linked: does the test link the crate (`use my_crate as _;`)?"
        );
    }
    let failures: Vec<String> = registry
        .list(None)
        .into_iter()
        .filter(|e| names.is_empty() || names.contains(&e.info().name))
        .filter_map(|e| check_example(&registry, e, dir.path()).err())
        .collect();
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
}

/// A finished run of [`run_pipeline`]: its folder (removed when dropped), report and
/// output folder.
#[derive(Debug)]
pub struct Run {
    pub dir: tempfile::TempDir,
    pub report: RunReport,
    pub out: PathBuf,
}

impl Run {
    /// An output file's bytes.
    pub fn file(&self, name: &str) -> Vec<u8> {
        let path = self.out.join(name);
        std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
    }

    /// A JSON output, parsed.
    pub fn json(&self, name: &str) -> serde_json::Value {
        serde_json::from_slice(&self.file(name)).unwrap_or_else(|e| panic!("{name}: {e}"))
    }
}

/// Runs a pipeline given as text, in a temporary folder holding [`write_models`]'s
/// files; panics with the error if it fails.
pub fn run_pipeline(text: &str) -> Run {
    try_run_pipeline(text).unwrap_or_else(|e| panic!("{e}"))
}

/// [`run_pipeline`], returning the error instead (for tests of refusals).
pub fn try_run_pipeline(text: &str) -> Result<Run, lamina_core::Error> {
    let dir = tempfile::tempdir().map_err(|e| lamina_core::Error::io(std::env::temp_dir(), e))?;
    write_models(dir.path());
    let file = SourceFile::new(dir.path().join("pipeline.toml"), text);
    let pipeline = Pipeline::parse(file, dir.path().to_path_buf(), &[])?;
    let engine = Engine::build(pipeline, registry(), &RunOptions::default())?;
    let out = dir.path().join("out");
    let report = engine.run(&out, &Silent)?;
    Ok(Run { dir, report, out })
}

/// Whether what the tests need must be there (`LAMINA_REQUIRE` set and not `0`, as
/// the workspace's CI sets it).
pub fn required() -> bool {
    std::env::var_os("LAMINA_REQUIRE").is_some_and(|v| !v.is_empty() && v != "0")
}

/// A test that cannot run here (a checker or a model missing): a note, or under
/// `LAMINA_REQUIRE` a failure.
pub fn skip(what: &str) {
    assert!(!required(), "LAMINA_REQUIRE is set, but {what}");
    println!("note: {what}; skipped");
}

/// The run of one mesh alone (no materials, no parts): its heights, and files relative
/// to `dir`.
pub fn mesh_info(dir: &Path, mesh: &lamina_core::Mesh) -> lamina_core::RunInfo {
    let bb = mesh.bbox();
    lamina_core::RunInfo {
        base_dir: dir.to_path_buf(),
        materials: Vec::new(),
        parts: Vec::new(),
        z_min: bb.min.z,
        z_max: bb.max.z,
        xy_bounds: lamina_core::BBox2::EMPTY,
        machine: None,
        model_frame: None,
    }
}

/// The `distance-field` discretiser from the family's boundary (the paper's field), at
/// `levels`, on `samples` samples along the longer side; every other option its default.
pub fn boundary_field(
    levels: lamina_discretise::distance_field::Levels,
    samples: usize,
) -> lamina_discretise::distance_field::DistanceField {
    lamina_discretise::distance_field::DistanceField {
        feature: lamina_discretise::distance_field::Feature::Boundary,
        point: None,
        points: Vec::new(),
        faces: Default::default(),
        surfaces: Default::default(),
        width: None,
        levels,
        samples,
        sample_spacing: None,
        around: Default::default(),
        limits: Default::default(),
    }
}

/// The dynamic library `cargo test` built for the plugin crate whose library is named
/// `lib` (the crate's name with `_` for `-`), beside the test program: what
/// `lamina --plugin` loads.
pub fn plugin_library(lib: &str) -> PathBuf {
    let exe = std::env::current_exe().unwrap_or_else(|e| panic!("the test program: {e}"));
    // target/<profile>/deps/<test> -> target/<profile>/<library>
    let profile = exe
        .parent()
        .and_then(Path::parent)
        .unwrap_or_else(|| panic!("{} lies in no build folder", exe.display()));
    profile.join(format!(
        "{}{}{}",
        std::env::consts::DLL_PREFIX,
        lib.replace('-', "_"),
        std::env::consts::DLL_SUFFIX
    ))
}

/// The linked stages twice, for a test that must hold on both sides of the plugin
/// boundary: as linked (`"linked"`), and behind a loopback plugin (`"remote"`).
pub fn linked_and_remote() -> [(&'static str, Registry); 2] {
    [
        ("linked", registry()),
        ("remote", registry_through_boundary("loopback")),
    ]
}

/// Every linked stage behind the plugin boundary, as if a plugin library named `name`
/// held them (each call a message, stages behind handles), with the program's
/// defaults: what a pipeline run with it must give as the linked stages do.
pub fn registry_through_boundary(name: &'static str) -> Registry {
    let mut remote = Registry::new();
    lamina_core::plugin::add_linked_through_boundary(&mut remote, name)
        .unwrap_or_else(|e| panic!("the linked stages as a plugin: {e}"));
    remote
        .adopt_defaults(&registry())
        .unwrap_or_else(|e| panic!("the default stages: {e}"));
    remote
}

/// Runs the examples of the stages named in `names`, loaded from the plugin library
/// `library` through Lamina's own loader (the file inspected, its ABI and messages'
/// schema checked, every call a message across the boundary), with the built-in
/// stages linked for the rest of each pipeline: a stage that runs linked but not as a
/// plugin fails here. Panics with every failure.
pub fn assert_examples_run_through_boundary(library: &Path, names: &[&str]) {
    // The plugin's stages from its library only, then the built-in ones it does not
    // hold (the test program links the plugin crate as well).
    let mut registry = Registry::new();
    lamina_core::plugin::load(&mut registry, library)
        .unwrap_or_else(|e| panic!("{} does not load: {e}", library.display()));
    let linked = self::registry();
    for e in linked.list(None) {
        if registry.get(e.info().kind, e.info().name).is_none() {
            registry
                .add(e.factory, e.origin.clone())
                .unwrap_or_else(|err| panic!("{}: {err}", e.label()));
        }
    }
    registry
        .adopt_defaults(&linked)
        .unwrap_or_else(|e| panic!("the default stages: {e}"));
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("a temporary folder: {e}"));
    write_models(dir.path());
    let mut failures = Vec::new();
    for name in names {
        let Some(entry) = registry
            .list(None)
            .into_iter()
            .find(|e| e.info().name == *name && matches!(e.origin, Origin::Dynamic { .. }))
        else {
            failures.push(format!("{} holds no stage named `{name}`", library.display()));
            continue;
        };
        if let Err(e) = check_example(&registry, entry, dir.path()) {
            failures.push(e);
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
}
