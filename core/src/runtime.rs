//! The runtime: builds the stages a pipeline names, loads the model, and drives the
//! layers through slice → sort → discretise → grade → plan in parallel, handing the
//! finished layers to the exporters in build order.
//!
//! Layers are independent, so they are processed in windows of a few layers per thread
//! on a rayon pool; each window is collected in order and streamed to the exporters
//! before the next one starts. Memory therefore stays bounded by a window plus the
//! meshes, and the output does not depend on the number of threads.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::geom::{Point2, Vector2};
use crate::mesh::{BBox3, Mesh, Vector3};
use crate::model::{
    Composition, Layer, LayerPlan, LayerSlot, Orientation, PartInfo, PartLayer, Region, Sequence,
};
use crate::output::AtomicOutputs;
use crate::pipeline::{ModelSpec, Pipeline, Placement, TableRef};
use crate::registry::Registry;
use crate::script::{ScriptHost, ScriptLimits};
use crate::stage::*;

/// How a run is carried out (as opposed to what it makes, which the pipeline says).
/// Stack of each worker thread (bytes).
const WORKER_STACK: usize = 64 << 20;

#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// Worker threads; `None` uses every core.
    pub threads: Option<usize>,
    /// Replaces the model file of a single-part pipeline.
    pub model: Option<PathBuf>,
    /// Dynamic plugins to load in addition to the pipeline's `plugins`.
    pub plugins: Vec<PathBuf>,
    /// Limits applied to every Rhai script.
    pub script_limits: ScriptLimits,
}

/// Receives progress from a run. Only the CLI knows the terminal: the runtime reports
/// here and never prints.
pub trait Observer: Send + Sync {
    /// The run is about to process `layers` layers.
    fn started(&self, _layers: usize) {}
    /// Layer `index` was handed to the exporters.
    fn layer_done(&self, _index: usize) {}
    /// Something was repaired or ignored; the run goes on.
    fn warning(&self, _message: &str) {}
}

/// An observer that ignores everything.
#[derive(Debug, Default, Clone, Copy)]
pub struct Silent;

impl Observer for Silent {}

/// Time spent in each stage kind, summed over all threads.
#[derive(Debug, Default)]
pub struct Timings {
    nanos: [AtomicU64; StageKind::ALL.len()],
    wall: AtomicU64,
}

impl Timings {
    fn add(&self, kind: StageKind, d: Duration) {
        let i = StageKind::ALL.iter().position(|k| *k == kind).unwrap_or(0);
        self.nanos[i].fetch_add(d.as_nanos() as u64, Ordering::Relaxed);
    }

    fn time<T>(&self, kind: StageKind, f: impl FnOnce() -> T) -> T {
        let start = Instant::now();
        let out = f();
        self.add(kind, start.elapsed());
        out
    }

    /// Time spent in `kind`, summed over threads.
    pub fn get(&self, kind: StageKind) -> Duration {
        let i = StageKind::ALL.iter().position(|k| *k == kind).unwrap_or(0);
        Duration::from_nanos(self.nanos[i].load(Ordering::Relaxed))
    }

    /// Wall-clock time of the whole run.
    pub fn wall(&self) -> Duration {
        Duration::from_nanos(self.wall.load(Ordering::Relaxed))
    }

    /// `(stage, time)` for every stage kind that took any time.
    pub fn entries(&self) -> Vec<(StageKind, Duration)> {
        StageKind::ALL
            .into_iter()
            .map(|k| (k, self.get(k)))
            .filter(|(_, d)| !d.is_zero())
            .collect()
    }
}

/// What a finished run produced.
#[derive(Debug)]
pub struct RunReport {
    pub layers: usize,
    pub regions: usize,
    /// Files written, under their final names.
    pub files: Vec<PathBuf>,
    pub warnings: usize,
    pub timings: Timings,
    /// Sum of the planned layer build times (s), when a planner ran.
    pub build_time: Option<f64>,
    /// Sum of the layers' one-tool-at-a-time build times (s), when the planner timed
    /// that baseline (a concurrent planner).
    pub sequential_time: Option<f64>,
    /// Volume the planned beads deposit and volume of the sub-regions they fill (mm³),
    /// when a planner reported its fill.
    pub fill: Option<(f64, f64)>,
    /// The build direction chosen by an `[orient]` stage and the alternatives weighed.
    pub orientation: Option<Orientation>,
}

struct ModelStage {
    source: Box<dyn ModelSource>,
    spec: ModelSpec,
    /// What the model is, for messages: the generator or the file.
    label: String,
}

struct PartStages {
    name: String,
    family_at: Option<[f64; 3]>,
    /// Where `family_at` is written, for errors.
    family_at_location: Option<crate::source::Location>,
    materials: Vec<usize>,
    /// Index into `Engine::models`.
    model: usize,
    mesh: Option<usize>,
    discretiser: Option<Box<dyn Discretiser>>,
    grader: Option<Box<dyn Grader>>,
}

/// A pipeline with every stage built, ready to run.
pub struct Engine {
    pipeline: Pipeline,
    threads: Option<usize>,
    models: Vec<ModelStage>,
    parts: Vec<PartStages>,
    slicer: Box<dyn Slicer>,
    sorter: Box<dyn Sorter>,
    orienter: Option<Box<dyn Orienter>>,
    sequencer: Option<Box<dyn Sequencer>>,
    planner: Option<Box<dyn Planner>>,
    exporters: Vec<Box<dyn Exporter>>,
}

impl std::fmt::Debug for Engine {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Engine")
            .field("pipeline", &self.pipeline.name)
            .field("parts", &self.parts.len())
            .field("exporters", &self.exporters.len())
            .finish()
    }
}

/// Default stage used when a pipeline has no table for a required kind.
const DEFAULT_SLICER: &str = "uniform";
const DEFAULT_SORTER: &str = "hierarchy";

fn build_default(
    registry: &Registry,
    kind: StageKind,
    pipeline: &Pipeline,
    scripts: &ScriptHost,
    default: &str,
) -> Result<AnyStage> {
    match pipeline.stages.get(&kind) {
        Some(t) => registry.build_for(kind, t, scripts, &pipeline.base_dir, pipeline.context()),
        None => {
            let mut table = toml::Table::new();
            table.insert("use".into(), toml::Value::String(default.into()));
            let t = TableRef::detached(kind.name(), table);
            registry
                .build_for(kind, &t, scripts, &pipeline.base_dir, pipeline.context())
                .map_err(|e| {
                    Error::config(format!(
                        "the pipeline has no [{kind}] table and the default {kind} stage \
                         `{default}` could not be built: {e}"
                    ))
                })
        }
    }
}

fn build_optional(
    registry: &Registry,
    kind: StageKind,
    table: Option<&TableRef>,
    scripts: &ScriptHost,
    pipeline: &Pipeline,
) -> Result<Option<AnyStage>> {
    table
        .map(|t| registry.build_for(kind, t, scripts, &pipeline.base_dir, pipeline.context()))
        .transpose()
}

macro_rules! expect_kind {
    ($stage:expr, $variant:ident) => {
        match $stage {
            AnyStage::$variant(s) => s,
            other => {
                return Err(Error::stage(
                    stringify!($variant),
                    format!("expected a {} stage, got {}", stringify!($variant), other.kind()),
                ));
            }
        }
    };
}

/// Builds the model source a model table names: `use = "..."`, or a reader chosen by
/// the extension of `file`.
fn build_model(
    registry: &Registry,
    spec: &ModelSpec,
    scripts: &ScriptHost,
    base_dir: &Path,
    context: PipelineContext<'_>,
) -> Result<Box<dyn ModelSource>> {
    let table = &spec.table;
    let stage = if table.get("use").is_some() {
        registry.build_for(StageKind::Model, table, scripts, base_dir, context)?
    } else {
        let file = table.get("file").and_then(|v| v.as_str()).ok_or_else(|| {
            table
                .error_at("use", "a model table needs `use = \"...\"` or `file = \"...\"`")
                .with_help("e.g. file = \"part.stl\", or use = \"gear\" for a generated model")
        })?;
        let ext = Path::new(file)
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        let entry = registry.get(StageKind::Model, &ext).ok_or_else(|| {
            table
                .error_at("file", format!("no model reader for `.{ext}` files"))
                .with_help("name the reader with `use = \"...\"`; see `lamina plugins model`")
        })?;
        registry.build_entry_for(entry, table, scripts, base_dir, context)?
    };
    Ok(expect_kind!(stage, Model))
}

/// A model spec whose file is replaced by `path` (the `--model` option).
fn replace_model_file(spec: &ModelSpec, path: &Path) -> Result<ModelSpec> {
    let abs = std::path::absolute(path).map_err(|e| Error::io(path, e))?;
    let mut table = toml::Table::new();
    table.insert(
        "file".into(),
        toml::Value::String(abs.to_string_lossy().into_owned()),
    );
    Ok(ModelSpec {
        table: TableRef::detached("--model", table).with_host_keys(crate::pipeline::MODEL_HOST_KEYS),
        scale: spec.scale,
        units: spec.units,
        place: spec.place,
    })
}

impl Engine {
    /// Loads plugins and builds every stage of `pipeline`. Scripts are compiled here, so
    /// a pipeline that builds is a pipeline whose configuration is valid.
    pub fn build(pipeline: Pipeline, mut registry: Registry, options: &RunOptions) -> Result<Engine> {
        for path in pipeline.plugins.iter().chain(&options.plugins) {
            crate::plugin::load(&mut registry, path)?;
        }
        let scripts = ScriptHost::new(&pipeline.base_dir, options.script_limits)
            .with_script_dirs(pipeline.script_dirs.clone());
        let base = pipeline.base_dir.clone();

        if options.model.is_some() && pipeline.parts.len() > 1 {
            return Err(Error::config(format!(
                "--model replaces the model of a single-part pipeline, and `{}` has {} parts",
                pipeline.file.path.display(),
                pipeline.parts.len()
            )));
        }

        let mut models = Vec::new();
        let global_model = match &pipeline.model {
            Some(spec) => {
                let spec = match &options.model {
                    Some(p) => replace_model_file(spec, p)?,
                    None => spec.clone(),
                };
                models.push(ModelStage {
                    source: build_model(&registry, &spec, &scripts, &base, pipeline.context())?,
                    label: describe_model(&spec),
                    spec,
                });
                Some(0)
            }
            None => None,
        };

        let mut parts = Vec::new();
        for part in &pipeline.parts {
            let model = match &part.model {
                Some(spec) => {
                    let spec = match &options.model {
                        Some(p) => replace_model_file(spec, p)?,
                        None => spec.clone(),
                    };
                    models.push(ModelStage {
                        source: build_model(&registry, &spec, &scripts, &base, pipeline.context())?,
                        label: describe_model(&spec),
                        spec,
                    });
                    models.len() - 1
                }
                None => {
                    global_model.ok_or_else(|| Error::config(format!("part `{}` has no model", part.name)))?
                }
            };
            let discretiser = build_optional(
                &registry,
                StageKind::Discretise,
                part.discretise
                    .as_ref()
                    .or(pipeline.stages.get(&StageKind::Discretise)),
                &scripts,
                &pipeline,
            )?
            .map(|s| -> Result<_> { Ok(expect_kind!(s, Discretise)) })
            .transpose()?;
            let grade_table = part.grade.as_ref().or(pipeline.stages.get(&StageKind::Grade));
            let grader = build_optional(&registry, StageKind::Grade, grade_table, &scripts, &pipeline)?
                .map(|s| -> Result<_> { Ok(expect_kind!(s, Grade)) })
                .transpose()?;
            let discretiser_grades = discretiser.as_ref().is_some_and(|d| d.grades());
            if grader.is_none() && !discretiser_grades && part.materials.len() > 1 {
                let names: Vec<_> = part
                    .materials
                    .iter()
                    .map(|&m| pipeline.materials[m].name.as_str())
                    .collect();
                let err = Error::config(format!(
                    "part `{}` has {} materials ({}) but no [grade] table says how to mix them",
                    part.name,
                    names.len(),
                    names.join(", ")
                ))
                .with_help(
                    "add a [grade] table, or give the part a single material with `materials = [\"...\"]`",
                );
                return Err(
                    match part.table.as_ref().and_then(|t| t.location_of(Some("materials"))) {
                        Some(loc) => Error::Config {
                            location: Some(loc),
                            message: err.to_string(),
                            help: err.help().map(str::to_string),
                        },
                        None => err,
                    },
                );
            }
            parts.push(PartStages {
                name: part.name.clone(),
                family_at: part.family_at,
                family_at_location: part.table.as_ref().and_then(|t| t.location_of(Some("family_at"))),
                materials: part.materials.clone(),
                model,
                mesh: part.mesh,
                discretiser,
                grader,
            });
        }

        let slicer = expect_kind!(
            build_default(&registry, StageKind::Slice, &pipeline, &scripts, DEFAULT_SLICER)?,
            Slice
        );
        let sorter = expect_kind!(
            build_default(&registry, StageKind::Sort, &pipeline, &scripts, DEFAULT_SORTER)?,
            Sort
        );
        let orienter = build_optional(
            &registry,
            StageKind::Orient,
            pipeline.stages.get(&StageKind::Orient),
            &scripts,
            &pipeline,
        )?
        .map(|s| -> Result<_> { Ok(expect_kind!(s, Orient)) })
        .transpose()?;
        let sequencer = build_optional(
            &registry,
            StageKind::Sequence,
            pipeline.stages.get(&StageKind::Sequence),
            &scripts,
            &pipeline,
        )?
        .map(|s| -> Result<_> { Ok(expect_kind!(s, Sequence)) })
        .transpose()?;
        let planner = build_optional(
            &registry,
            StageKind::Plan,
            pipeline.stages.get(&StageKind::Plan),
            &scripts,
            &pipeline,
        )?
        .map(|s| -> Result<_> { Ok(expect_kind!(s, Plan)) })
        .transpose()?;
        let mut exporters = Vec::new();
        for t in &pipeline.outputs {
            exporters.push(expect_kind!(
                registry.build_for(StageKind::Export, t, &scripts, &base, pipeline.context())?,
                Export
            ));
        }

        Ok(Engine {
            threads: options.threads,
            pipeline,
            models,
            parts,
            slicer,
            sorter,
            orienter,
            sequencer,
            planner,
            exporters,
        })
    }

    pub fn pipeline(&self) -> &Pipeline {
        &self.pipeline
    }

    /// Short descriptions of what will run, for `lamina check`.
    pub fn summary(&self) -> Vec<String> {
        let mut lines = Vec::new();
        for m in &self.models {
            lines.push(format!("model: {}", m.label));
        }
        for p in &self.parts {
            let mats: Vec<_> = p
                .materials
                .iter()
                .map(|&m| self.pipeline.materials[m].name.as_str())
                .collect();
            lines.push(format!(
                "part `{}`: materials {}; discretise: {}; grade: {}",
                p.name,
                mats.join(", "),
                if p.discretiser.is_some() {
                    "yes"
                } else {
                    "whole families"
                },
                if p.grader.is_some() {
                    "yes"
                } else {
                    "pure material"
                },
            ));
        }
        if let Some(m) = &self.pipeline.machine {
            lines.push(format!(
                "machine: {} ({}, {}, {} bed, {} tool(s))",
                m.name,
                m.flavor.name(),
                m.firmware.name(),
                m.bed.describe(),
                m.tools.len()
            ));
        }
        lines.push(format!("outputs: {}", self.exporters.len()));
        lines
    }

    /// Loads and places the meshes, one entry per model stage.
    fn load_models(&self, timings: &Timings) -> Result<Vec<Vec<Mesh>>> {
        let mut out = Vec::new();
        for m in &self.models {
            let mut meshes = timings.time(StageKind::Model, || m.source.load(&self.pipeline.base_dir))?;
            if meshes.is_empty() || meshes.iter().all(|m| m.triangles.is_empty()) {
                return Err(Error::config(format!("model {} holds no triangles", m.label)));
            }
            if !m.spec.size_given() {
                check_units(&meshes, &m.spec, &m.label)?;
            }
            place(&mut meshes, m.spec.factor(), m.spec.place);
            let bbox = meshes.iter().fold(BBox3::EMPTY, |b, m| b.union(&m.bbox()));
            let corners = [
                bbox.min.x, bbox.min.y, bbox.min.z, bbox.max.x, bbox.max.y, bbox.max.z,
            ];
            if !corners.into_iter().all(crate::limits::is_coordinate) {
                return Err(Error::config(format!(
                    "model {} reaches ({}, {}, {}) to ({}, {}, {}) mm once scaled and placed: \
                     Lamina works within ±{} mm (a kilometre) of the origin",
                    m.label,
                    short(bbox.min.x),
                    short(bbox.min.y),
                    short(bbox.min.z),
                    short(bbox.max.x),
                    short(bbox.max.y),
                    short(bbox.max.z),
                    crate::limits::MAX_COORDINATE
                )));
            }
            out.push(meshes);
        }
        Ok(out)
    }

    /// Runs the pipeline, writing the outputs into `out_dir`. Outputs appear only when
    /// the whole run succeeds.
    pub fn run(&self, out_dir: &Path, observer: &dyn Observer) -> Result<RunReport> {
        let started = Instant::now();
        let timings = Timings::default();
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(self.threads.unwrap_or(0))
            // Scripts recurse within their depth limits on these threads: room for
            // the deepest the limits allow, reserved, not touched.
            .stack_size(WORKER_STACK)
            .build()
            .map_err(|e| Error::config(format!("cannot start worker threads: {e}")))?;

        // Meshes: one per part (a part takes one mesh of its model, or all merged).
        let mut loaded = self.load_models(&timings)?;
        let orientation = match &self.orienter {
            Some(o) => Some(timings.time(StageKind::Orient, || orient(o.as_ref(), &mut loaded))?),
            None => None,
        };
        let mut warnings = 0;
        for mesh in loaded.iter().flatten() {
            for w in &mesh.warnings {
                observer.warning(w);
                warnings += 1;
            }
        }
        let mut meshes: Vec<Arc<Mesh>> = Vec::new();
        let mut part_mesh = Vec::new();
        let mut mesh_keys: Vec<(usize, Option<usize>)> = Vec::new();
        let mut parts_info = Vec::new();
        for p in &self.parts {
            let model = &loaded[p.model];
            let mesh = match p.mesh {
                Some(i) => model.get(i).cloned().ok_or_else(|| {
                    Error::config(format!(
                        "part `{}` asks for mesh {i}, but its model holds {} meshes",
                        p.name,
                        model.len()
                    ))
                })?,
                None => merge(model, &self.models[p.model].label),
            };
            // Parts taking the same mesh of the same model (told apart by `family_at`)
            // share it: it is cut once per layer.
            let key = (p.model, p.mesh);
            let idx = match mesh_keys.iter().position(|k| *k == key) {
                Some(i) => i,
                None => {
                    mesh_keys.push(key);
                    meshes.push(Arc::new(mesh));
                    meshes.len() - 1
                }
            };
            let bb = meshes[idx].bbox();
            part_mesh.push(idx);
            parts_info.push(PartInfo {
                name: p.name.clone(),
                materials: p.materials.clone(),
                mesh: idx,
                z_min: bb.min.z,
                z_max: bb.max.z,
            });
        }
        let bbox = meshes.iter().fold(BBox3::EMPTY, |b, m| b.union(&m.bbox()));
        let xy_bounds = if bbox.is_empty() {
            crate::geom::BBox2::EMPTY
        } else {
            crate::geom::BBox2::from_points([
                Point2::new(bbox.min.x, bbox.min.y),
                Point2::new(bbox.max.x, bbox.max.y),
            ])
        };
        if let Some(machine) = &self.pipeline.machine {
            for (p, &mi) in self.parts.iter().zip(&part_mesh) {
                check_on_bed(machine, &p.name, &meshes[mi], &xy_bounds)?;
            }
        }
        let info = RunInfo {
            base_dir: self.pipeline.base_dir.clone(),
            materials: self.pipeline.materials.clone(),
            parts: parts_info,
            z_min: bbox.min.z,
            z_max: bbox.max.z,
            xy_bounds,
            machine: self.pipeline.machine.clone(),
        };

        let sequence = match &self.sequencer {
            Some(s) => Some(timings.time(StageKind::Sequence, || s.sequence(&info))?),
            None => None,
        };
        let slots = timings.time(StageKind::Slice, || {
            self.slicer.layers(&meshes, &info, sequence.as_ref())
        })?;
        // A part thinner than the thinnest layer is most likely scaled wrong: it is
        // planned, but said.
        let thinnest = slots.iter().map(|s| s.thickness).fold(f64::INFINITY, f64::min);
        for p in &info.parts {
            let tall = p.z_max - p.z_min;
            if tall < thinnest {
                observer.warning(&format!(
                    "part `{}` is {} mm tall, thinner than a layer ({} mm): is its scale right?",
                    p.name,
                    short(tall),
                    short(thinnest)
                ));
                warnings += 1;
            }
        }
        let prepared: Vec<Box<dyn MeshSlicer>> = pool.install(|| {
            meshes
                .par_iter()
                .map(|m| timings.time(StageKind::Slice, || self.slicer.prepare(m.clone())))
                .collect::<Result<Vec<_>>>()
        })?;

        let selections = self.select_families(&slots, &prepared, &part_mesh, &pool, &timings)?;

        let mut outputs = AtomicOutputs::new(out_dir);
        let mut sinks = Vec::new();
        for e in &self.exporters {
            let mut ctx = ExportContext {
                info: &info,
                sequence: sequence.as_ref(),
                orientation: orientation.as_ref(),
                layer_count: slots.len(),
                pipeline_name: &self.pipeline.name,
                files: &mut outputs,
            };
            sinks.push(timings.time(StageKind::Export, || e.open(&mut ctx))?);
        }

        let shared = LayerShared {
            info: &info,
            meshes: &meshes,
            sequence: sequence.as_ref(),
            prepared: &prepared,
            part_mesh: &part_mesh,
            selections: &selections,
            timings: &timings,
        };
        observer.started(slots.len());
        let window = pool.current_num_threads().max(1) * 4;
        let mut regions = 0;
        let mut build_time: Option<f64> = None;
        let mut sequential_time: Option<f64> = None;
        let mut fill: Option<(f64, f64)> = None;
        let mut min_fill = 0.0f64;
        for chunk in slots.chunks(window) {
            let plans: Vec<Result<LayerPlan>> = pool.install(|| {
                chunk
                    .par_iter()
                    .map(|slot| {
                        // A stage that panics on some input ends the run with an
                        // error naming the layer, not with an abort.
                        crate::plugin::guard_call("a layer's stages", || self.process_layer(slot, &shared))
                            .map_err(|e| e.in_layer(slot.index, slot.z))
                    })
                    .collect()
            });
            for plan in plans {
                let plan = plan?;
                for w in &plan.warnings {
                    // Slice warnings name their layer already.
                    if w.contains(&format!("layer {} (", plan.index)) {
                        observer.warning(w);
                    } else {
                        observer.warning(&format!("layer {} (z = {:.4} mm): {w}", plan.index, plan.z));
                    }
                }
                warnings += plan.warnings.len();
                regions += plan.parts.iter().map(|p| p.regions.len()).sum::<usize>();
                if let Some(t) = plan.build_time {
                    *build_time.get_or_insert(0.0) += t;
                }
                if let Some(t) = plan.sequential_time {
                    *sequential_time.get_or_insert(0.0) += t;
                }
                if let Some(f) = plan.fill {
                    let sum = fill.get_or_insert((0.0, 0.0));
                    sum.0 += f.deposited * plan.thickness;
                    sum.1 += f.area * plan.thickness;
                    min_fill = min_fill.max(f.min_ratio);
                }
                for sink in &mut sinks {
                    timings.time(StageKind::Export, || {
                        sink.layer_with_files(&info, &plan, &mut outputs)
                    })?;
                }
                observer.layer_done(plan.index);
            }
        }
        if let Some((deposited, volume)) = fill
            && volume > 0.0
            && deposited < min_fill * volume
        {
            return Err(Error::stage(
                "plan",
                format!(
                    "the toolpaths deposit {deposited:.1} mm³ of the {volume:.1} mm³ to fill ({:.1} %, \
                     below the {:.1} % asked by `min_fill`); see the layers' warnings for what is left out",
                    100.0 * deposited / volume,
                    100.0 * min_fill
                ),
            ));
        }
        for sink in sinks {
            timings.time(StageKind::Export, || sink.finish_with_files(&info, &mut outputs))?;
        }
        let files = outputs.commit()?;
        timings
            .wall
            .store(started.elapsed().as_nanos() as u64, Ordering::Relaxed);
        Ok(RunReport {
            layers: slots.len(),
            regions,
            files,
            warnings,
            timings,
            build_time,
            sequential_time,
            fill,
            orientation,
        })
    }

    /// Slices, sorts, discretises, grades and plans one layer.
    fn process_layer(&self, slot: &LayerSlot, shared: &LayerShared<'_>) -> Result<LayerPlan> {
        let LayerShared {
            info,
            sequence,
            prepared,
            part_mesh,
            selections,
            timings,
            meshes: _,
        } = *shared;
        // Each distinct mesh is cut and sorted once per layer.
        let mut cut: Vec<Option<(Layer, crate::model::ContourTree)>> =
            (0..prepared.len()).map(|_| None).collect();
        let mut warnings = Vec::new();
        let mut parts = Vec::new();
        // A layer of a material region deposits only that region's parts.
        let region_parts = match (slot.region, sequence) {
            (Some(r), Some(seq)) => {
                Some(seq.regions.get(r).map(|r| r.parts.as_slice()).ok_or_else(|| {
                    Error::stage(
                        "slice",
                        format!(
                            "layer names material region {r}, the sequence has {}",
                            seq.regions.len()
                        ),
                    )
                })?)
            }
            (Some(r), None) => {
                return Err(Error::stage(
                    "slice",
                    format!("layer names material region {r}, but the pipeline has no [sequence]"),
                ));
            }
            (None, _) => None,
        };
        for (pi, p) in self.parts.iter().enumerate() {
            if region_parts.is_some_and(|rp| !rp.contains(&pi)) {
                continue;
            }
            let mi = part_mesh[pi];
            if cut[mi].is_none() {
                let layer = timings
                    .time(StageKind::Slice, || prepared[mi].slice(slot))
                    .map_err(|e| e.in_part(&p.name))?;
                let tree = timings
                    .time(StageKind::Sort, || self.sorter.sort(&layer))
                    .map_err(|e| e.in_part(&p.name))?;
                check_tree(&layer, &tree).map_err(|e| e.in_part(&p.name))?;
                warnings.extend(layer.warnings.iter().map(|w| format!("part `{}`: {w}", p.name)));
                cut[mi] = Some((layer, tree));
            }
            let Some((layer, tree)) = &cut[mi] else { continue };
            let families = selections.families(pi, slot.index, layer, tree, part_mesh);
            let part_layer = self
                .process_part(pi, layer, tree, families, shared)
                .map_err(|e| e.in_part(&p.name))?;
            parts.push(part_layer);
        }
        let mut plan = LayerPlan {
            index: slot.index,
            z: slot.z,
            thickness: slot.thickness,
            region: slot.region,
            parts,
            toolpaths: Vec::new(),
            build_time: None,
            sequential_time: None,
            fill: None,
            warnings,
        };
        if let Some(planner) = &self.planner {
            timings.time(StageKind::Plan, || planner.plan(info, &mut plan))?;
        }
        Ok(plan)
    }

    fn process_part(
        &self,
        pi: usize,
        layer: &Layer,
        tree: &crate::model::ContourTree,
        families: Vec<usize>,
        shared: &LayerShared<'_>,
    ) -> Result<PartLayer> {
        let (info, timings) = (shared.info, shared.timings);
        let mesh = shared.meshes.get(shared.part_mesh[pi]).map(|m| &**m);
        let p = &self.parts[pi];
        let n_materials = p.materials.len();
        let mut regions = Vec::new();
        for &f in &families {
            let ctx = FamilyContext {
                info,
                layer,
                tree,
                mesh,
                part: pi,
                family: f,
            };
            let mut family_regions = match &p.discretiser {
                Some(d) => timings.time(StageKind::Discretise, || d.discretise(&ctx))?,
                None => vec![whole_family(tree, layer, f)],
            };
            match &p.grader {
                Some(g) => timings.time(StageKind::Grade, || g.grade(&ctx, &mut family_regions))?,
                None => {
                    // A discretiser whose regions follow the material (grading sources)
                    // grades them itself; the rest are the part's first material.
                    for r in family_regions.iter_mut().filter(|r| r.composition.is_none()) {
                        r.composition = Some(Composition::pure(0, n_materials));
                    }
                }
            }
            for r in &family_regions {
                let c = r.composition.as_ref().ok_or_else(|| {
                    Error::stage(
                        "grade",
                        format!("region {} of family {f} was left without a composition", r.index),
                    )
                })?;
                if c.fractions.len() != n_materials {
                    return Err(Error::stage(
                        "grade",
                        format!(
                            "region {} of family {f} has {} fractions, the part has {n_materials} materials",
                            r.index,
                            c.fractions.len()
                        ),
                    ));
                }
                Composition::check(&c.fractions)
                    .map_err(|e| Error::stage("grade", format!("region {} of family {f}: {e}", r.index)))?;
            }
            regions.extend(family_regions);
        }
        Ok(PartLayer {
            part: pi,
            contours: layer.contours.clone(),
            tree: tree.clone(),
            families,
            regions,
        })
    }
}

/// What every layer of a run reads: the run's facts and what was prepared once.
#[derive(Clone, Copy)]
struct LayerShared<'a> {
    info: &'a RunInfo,
    /// The meshes as sliced (placed and oriented), for stages that measure in space.
    meshes: &'a [Arc<Mesh>],
    sequence: Option<&'a Sequence>,
    prepared: &'a [Box<dyn MeshSlicer>],
    part_mesh: &'a [usize],
    selections: &'a Selections,
    timings: &'a Timings,
}

/// Which families of each layer belong to parts that select theirs with `family_at`:
/// per part, per layer, one sample point inside each selected family.
struct Selections {
    /// `None` for parts without `family_at`.
    samples: Vec<Option<Vec<Vec<Point2>>>>,
}

impl Selections {
    /// The families of `layer` that belong to part `pi`.
    fn families(
        &self,
        pi: usize,
        layer_index: usize,
        layer: &Layer,
        tree: &crate::model::ContourTree,
        part_mesh: &[usize],
    ) -> Vec<usize> {
        let selecting_on_mesh = |o: usize| part_mesh[o] == part_mesh[pi] && self.samples[o].is_some();
        if !(0..self.samples.len()).any(selecting_on_mesh) {
            // Nobody selects on this mesh: the part has every family.
            return (0..tree.families.len()).collect();
        }
        let polygons: Vec<_> = (0..tree.families.len())
            .map(|f| tree.family_polygon(&layer.contours, f))
            .collect();
        let owned_by = |part: usize| -> Vec<usize> {
            let samples = self.samples[part]
                .as_ref()
                .and_then(|s| s.get(layer_index))
                .map(Vec::as_slice)
                .unwrap_or(&[]);
            (0..polygons.len())
                .filter(|&f| samples.iter().any(|&p| polygons[f].contains(p)))
                .collect()
        };
        if self.samples[pi].is_some() {
            return owned_by(pi);
        }
        // A part without `family_at` takes what the selecting parts on its mesh leave.
        let taken: Vec<usize> = (0..self.samples.len())
            .filter(|&o| o != pi && part_mesh[o] == part_mesh[pi] && self.samples[o].is_some())
            .flat_map(owned_by)
            .collect();
        (0..polygons.len()).filter(|f| !taken.contains(f)).collect()
    }
}

/// A family's polygon and a point inside it.
type FamilySample = (crate::geom::Polygon, Point2);

/// Per layer, its families with their points.
type LayerFamilies = Vec<Vec<FamilySample>>;

/// Two families of neighbouring layers overlap when either holds a point of the other.
fn overlaps(a: &FamilySample, b: &FamilySample) -> bool {
    a.0.contains(b.1) || b.0.contains(a.1)
}

impl Engine {
    /// Follows each `family_at` selection through the layers: the family containing the
    /// point in the layer at its height, then in each neighbouring layer the families
    /// overlapping those selected in the layer before, upward and downward.
    fn select_families(
        &self,
        slots: &[LayerSlot],
        prepared: &[Box<dyn MeshSlicer>],
        part_mesh: &[usize],
        pool: &rayon::ThreadPool,
        timings: &Timings,
    ) -> Result<Selections> {
        let mut samples: Vec<Option<Vec<Vec<Point2>>>> = vec![None; self.parts.len()];
        if self.parts.iter().all(|p| p.family_at.is_none()) || slots.is_empty() {
            return Ok(Selections { samples });
        }
        // Families (polygon and inner point) of every layer of the meshes concerned.
        let mut by_mesh: Vec<Option<LayerFamilies>> = (0..prepared.len()).map(|_| None).collect();
        for (pi, p) in self.parts.iter().enumerate() {
            let mi = part_mesh[pi];
            if p.family_at.is_none() || by_mesh[mi].is_some() {
                continue;
            }
            let layers: Vec<Vec<FamilySample>> = pool.install(|| {
                slots
                    .par_iter()
                    .map(|slot| {
                        let layer = timings.time(StageKind::Slice, || prepared[mi].slice(slot))?;
                        let tree = timings.time(StageKind::Sort, || self.sorter.sort(&layer))?;
                        check_tree(&layer, &tree)?;
                        Ok((0..tree.families.len())
                            .map(|f| {
                                let poly = tree.family_polygon(&layer.contours, f);
                                let inside = poly
                                    .outer
                                    .interior_point()
                                    .unwrap_or(Point2::new(f64::NAN, f64::NAN));
                                (poly, inside)
                            })
                            .collect())
                    })
                    .collect::<Result<Vec<_>>>()
            })?;
            by_mesh[mi] = Some(layers);
        }
        for (pi, p) in self.parts.iter().enumerate() {
            let Some([x, y, z]) = p.family_at else { continue };
            let Some(layers) = &by_mesh[part_mesh[pi]] else {
                continue;
            };
            // The layer whose thickness spans z, else the nearest.
            let start = slots
                .iter()
                .position(|s| s.z - s.thickness <= z && z <= s.z)
                .unwrap_or_else(|| {
                    (0..slots.len())
                        .min_by(|&a, &b| (slots[a].cut_z - z).abs().total_cmp(&(slots[b].cut_z - z).abs()))
                        .unwrap_or(0)
                });
            let point = Point2::new(x, y);
            let first: Vec<usize> = (0..layers[start].len())
                .filter(|&f| layers[start][f].0.contains(point))
                .collect();
            if first.is_empty() {
                let message = format!(
                    "part `{}`: no solid at family_at = [{x}, {y}, {z}] (layer {} at z = {:.4} mm has {} families)",
                    p.name,
                    start,
                    slots[start].z,
                    layers[start].len()
                );
                return Err(match &p.family_at_location {
                    Some(loc) => Error::config_at(loc.clone(), message),
                    None => Error::config(message),
                });
            }
            let mut selected: Vec<Vec<usize>> = vec![Vec::new(); slots.len()];
            selected[start] = first;
            for k in start + 1..slots.len() {
                selected[k] = next_selection(&layers[k - 1], &selected[k - 1], &layers[k]);
            }
            for k in (0..start).rev() {
                selected[k] = next_selection(&layers[k + 1], &selected[k + 1], &layers[k]);
            }
            samples[pi] = Some(
                selected
                    .iter()
                    .zip(layers)
                    .map(|(sel, fams)| sel.iter().map(|&f| fams[f].1).collect())
                    .collect(),
            );
        }
        Ok(Selections { samples })
    }
}

/// Families of `next` overlapping the `selected` families of `prev`.
fn next_selection(prev: &[FamilySample], selected: &[usize], next: &[FamilySample]) -> Vec<usize> {
    (0..next.len())
        .filter(|&f| selected.iter().any(|&s| overlaps(&prev[s], &next[f])))
        .collect()
}

/// The single region of a family that is not discretised.
fn whole_family(tree: &crate::model::ContourTree, layer: &Layer, f: usize) -> Region {
    let polygon = tree.family_polygon(&layer.contours, f);
    let reference = polygon
        .outer
        .interior_point()
        .unwrap_or_else(|| polygon.bbox().center());
    Region {
        family: f,
        index: 0,
        count: 1,
        level: 0.0,
        polygon,
        cell: None,
        reference,
        composition: None,
    }
}

/// A sorter's output must describe the layer it was given.
fn check_tree(layer: &Layer, tree: &crate::model::ContourTree) -> Result<()> {
    if tree.nodes.len() != layer.contours.len() {
        return Err(Error::stage(
            "sort",
            format!(
                "tree has {} nodes for {} contours",
                tree.nodes.len(),
                layer.contours.len()
            ),
        ));
    }
    let n = layer.contours.len();
    for fam in &tree.families {
        if fam.outer >= n || fam.holes.iter().any(|&h| h >= n) {
            return Err(Error::stage(
                "sort",
                "a family names a contour the layer does not have",
            ));
        }
    }
    Ok(())
}

/// Merges the meshes of a model into one, keeping per-triangle materials.
fn merge(meshes: &[Mesh], name: &str) -> Mesh {
    if meshes.len() == 1 {
        return meshes[0].clone();
    }
    let mut out = Mesh::new(name, Vec::new(), Vec::new());
    for m in meshes {
        let base = out.vertices.len() as u32;
        out.vertices.extend_from_slice(&m.vertices);
        out.triangles.extend(
            m.triangles
                .iter()
                .map(|t| [t[0] + base, t[1] + base, t[2] + base]),
        );
    }
    out
}

/// Turns every mesh of every model by the orienter's choice, rotating about the
/// object's centre and putting the object back on the bed: the models keep their
/// places relative to each other.
fn orient(orienter: &dyn Orienter, models: &mut [Vec<Mesh>]) -> Result<Orientation> {
    let all: Vec<&Mesh> = models.iter().flatten().collect();
    let orientation = orienter.orient(&all)?;
    let r = &orientation.rotation;
    let m = nalgebra::Matrix3::from_fn(|i, j| r[i][j]);
    let det = m.determinant();
    if !((det - 1.0).abs() < 1e-6 && (m.transpose() * m - nalgebra::Matrix3::identity()).norm() < 1e-6) {
        return Err(Error::stage(
            "orient",
            format!("the orienter returned a matrix that is not a rotation: {r:?}"),
        ));
    }
    let bbox = models
        .iter()
        .flatten()
        .fold(BBox3::EMPTY, |b, m| b.union(&m.bbox()));
    if bbox.is_empty() {
        return Ok(orientation);
    }
    let centre = (bbox.min.coords + bbox.max.coords) * 0.5;
    for mesh in models.iter_mut().flatten() {
        mesh.transform(1.0, -centre);
        mesh.rotate(r);
        mesh.transform(1.0, centre);
    }
    let after = models
        .iter()
        .flatten()
        .fold(BBox3::EMPTY, |b, m| b.union(&m.bbox()));
    for mesh in models.iter_mut().flatten() {
        mesh.transform(1.0, Vector3::new(0.0, 0.0, -after.min.z));
    }
    Ok(orientation)
}

/// Applies a model table's `scale` and `place` to all meshes of the model together, so
/// the meshes of an assembly keep their relative positions.
pub fn place(meshes: &mut [Mesh], scale: f64, placement: Placement) {
    for m in meshes.iter_mut() {
        m.transform(scale, Vector3::zeros());
    }
    let bbox = meshes.iter().fold(BBox3::EMPTY, |b, m| b.union(&m.bbox()));
    if bbox.is_empty() {
        return;
    }
    let offset = match placement {
        Placement::Keep => return,
        Placement::Bed => Vector3::new(0.0, 0.0, -bbox.min.z),
        Placement::Centre => {
            let c = Vector2::new(bbox.min.x + bbox.max.x, bbox.min.y + bbox.max.y) * 0.5;
            Vector3::new(-c.x, -c.y, -bbox.min.z)
        }
    };
    for m in meshes.iter_mut() {
        m.transform(1.0, offset);
    }
}

/// A model whose extents are all under this (mm) is most likely in metres.
const SMALLEST_PLAUSIBLE_MM: f64 = 1.0;
/// A model with an extent over this (mm) is most likely in micrometres (or tenths).
const LARGEST_PLAUSIBLE_MM: f64 = 2000.0;

/// Refuses a model whose size says its file is not in millimetres (a mesh in metres
/// slices to a single layer and an empty file), unless the pipeline gives `scale` or
/// `units`.
fn check_units(meshes: &[Mesh], spec: &ModelSpec, label: &str) -> Result<()> {
    let bbox = meshes.iter().fold(BBox3::EMPTY, |b, m| b.union(&m.bbox()));
    if bbox.is_empty() {
        return Ok(());
    }
    let size = bbox.size();
    let extents = [("wide", size.x), ("deep", size.y), ("tall", size.z)];
    let (word, largest) = extents
        .into_iter()
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap_or(("tall", size.z));
    let (guess, fix) = if largest < SMALLEST_PLAUSIBLE_MM {
        ("is it in metres?", "scale = 1000 or units = \"m\"")
    } else if largest > LARGEST_PLAUSIBLE_MM {
        ("is it in micrometres?", "scale = 0.001")
    } else {
        return Ok(());
    };
    let table = spec.table.path_string();
    let table = if table.is_empty() {
        "model".to_string()
    } else {
        table
    };
    let message = format!(
        "the model `{label}` is {} mm {word} ({} x {} x {} mm): {guess} set [{table}] {fix}",
        short(largest),
        short(size.x),
        short(size.y),
        short(size.z)
    );
    let help = format!(
        "Lamina works in millimetres; `scale` or `units` (\"mm\", \"cm\", \"m\", \"in\") in [{table}] says what the file's numbers mean, and turns this check off"
    );
    Err(match spec
        .table
        .location_of(Some("file"))
        .filter(|_| !spec.table.is_overridden())
    {
        Some(loc) => Error::config_at(loc, message),
        None => Error::config(message),
    }
    .with_help(help))
}

/// A length for messages: three significant digits, no trailing zeros.
fn short(v: f64) -> String {
    if v.abs() >= 1e7 {
        return format!("{v:.2e}");
    }
    let digits = if v == 0.0 {
        0
    } else {
        (2 - v.abs().log10().floor() as i32).max(0) as usize
    };
    let s = format!("{v:.digits$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// Refuses a part that does not fit the machine: placed as the machine says, every
/// vertex must lie on the bed and below the machine's build height.
fn check_on_bed(
    machine: &crate::machine::Machine,
    part: &str,
    mesh: &Mesh,
    all: &crate::geom::BBox2,
) -> Result<()> {
    let offset = machine.placement_offset(all);
    let bbox = mesh.bbox();
    if bbox.is_empty() {
        return Ok(());
    }
    let bed = &machine.bed;
    let on_bed = match bed.shape {
        crate::machine::BedShape::Rectangle { .. } => bed.contains_box(
            &crate::geom::BBox2::from_points([
                Point2::new(bbox.min.x, bbox.min.y) + offset,
                Point2::new(bbox.max.x, bbox.max.y) + offset,
            ]),
            0.0,
        ),
        crate::machine::BedShape::Circle { .. } => mesh
            .vertices
            .iter()
            .all(|v| bed.contains(Point2::new(v.x, v.y) + offset, 0.0)),
    };
    if !on_bed {
        return Err(machine.error(format!(
            "part `{part}` ({} x {} mm, placed at X {:.1}..{:.1}, Y {:.1}..{:.1}) does not fit the {} bed",
            short(bbox.max.x - bbox.min.x),
            short(bbox.max.y - bbox.min.y),
            bbox.min.x + offset.x,
            bbox.max.x + offset.x,
            bbox.min.y + offset.y,
            bbox.max.y + offset.y,
            bed.describe()
        )));
    }
    if bbox.max.z > bed.max_height {
        return Err(machine.error(format!(
            "part `{part}` is {} mm tall, the machine builds up to {} mm",
            short(bbox.max.z),
            bed.max_height
        )));
    }
    Ok(())
}

fn describe_model(spec: &ModelSpec) -> String {
    match (
        spec.table.use_name(),
        spec.table.get("file").and_then(|v| v.as_str()),
    ) {
        (Some(u), Some(f)) => format!("{u} ({f})"),
        (Some(u), None) => u.to_string(),
        (None, Some(f)) => f.to_string(),
        (None, None) => "?".into(),
    }
}

/// Convenience for tests and embedders: parse, build and run a pipeline file.
pub fn run_file(path: &Path, out_dir: &Path, options: &RunOptions) -> Result<RunReport> {
    let pipeline = Pipeline::load(path, &[])?;
    let engine = Engine::build(pipeline, Registry::linked()?, options)?;
    engine.run(out_dir, &Silent)
}
