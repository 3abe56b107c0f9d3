//! Building a pipeline's stages: each kind from its table, or the default its plugin
//! declares; one model source per model table; the checks that need several stages at
//! once (a part with several materials needs a grader).

use std::path::{Path, PathBuf};

use super::RunOptions;
use crate::error::{Error, Result};
use crate::pipeline::{ModelSpec, Pipeline, TableRef};
use crate::registry::Registry;
use crate::script::ScriptHost;
use crate::stage::*;

pub(super) struct ModelStage {
    pub(super) source: Box<dyn ModelSource>,
    pub(super) spec: ModelSpec,
    /// What the model is, for messages: the generator or the file.
    pub(super) label: String,
}

pub(super) struct PartStages {
    pub(super) name: String,
    pub(super) family_at: Option<[f64; 3]>,
    /// Where `family_at` is written, for errors.
    pub(super) family_at_location: Option<crate::source::Location>,
    pub(super) materials: Vec<usize>,
    /// Index into `Engine::models`.
    pub(super) model: usize,
    pub(super) mesh: Option<usize>,
    /// How many of the part the plate holds, and the gap between them (mm).
    pub(super) copies: usize,
    pub(super) copy_gap: f64,
    pub(super) copy_columns: Option<usize>,
    pub(super) discretiser: Option<Box<dyn Discretiser>>,
    pub(super) grader: Option<Box<dyn Grader>>,
}

/// A pipeline with every stage built, ready to run.
pub struct Engine {
    pub(super) pipeline: Pipeline,
    pub(super) threads: Option<usize>,
    pub(super) models: Vec<ModelStage>,
    pub(super) parts: Vec<PartStages>,
    pub(super) slicer: Box<dyn Slicer>,
    pub(super) sorter: Box<dyn Sorter>,
    pub(super) orienter: Option<Box<dyn Orienter>>,
    pub(super) sequencer: Option<Box<dyn Sequencer>>,
    pub(super) planner: Option<Box<dyn Planner>>,
    /// `[[process]]` stages, in their order.
    pub(super) process: Vec<Box<dyn Process>>,
    pub(super) exporters: Vec<Box<dyn Exporter>>,
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

/// Builds the stage of type `S` from its table, or the default its plugin declares
/// when the pipeline has none.
fn build_default<S: StageType + ?Sized>(
    registry: &Registry,
    pipeline: &Pipeline,
    scripts: &ScriptHost,
) -> Result<Box<S>> {
    let kind = S::KIND;
    if let Some(t) = pipeline.stages.get(&kind) {
        return registry.build_for::<S>(t, scripts, &pipeline.base_dir, pipeline.context());
    }
    let default = registry.default_for(kind).ok_or_else(|| {
        Error::config(format!(
            "the pipeline has no [{kind}] table, and no plugin declares a default {kind} stage"
        ))
        .with_help(format!(
            "add a [{kind}] table; `lamina plugins {kind}` lists the stages"
        ))
    })?;
    let mut table = toml::Table::new();
    table.insert("use".into(), toml::Value::String(default.into()));
    let t = TableRef::detached(kind.name(), table);
    registry
        .build_for::<S>(&t, scripts, &pipeline.base_dir, pipeline.context())
        .map_err(|e| {
            Error::config(format!(
                "the pipeline has no [{kind}] table and the default {kind} stage \
                 `{default}` could not be built: {e}"
            ))
        })
}

/// Builds the stage of type `S` from `table`, when there is one.
fn build_optional<S: StageType + ?Sized>(
    registry: &Registry,
    table: Option<&TableRef>,
    scripts: &ScriptHost,
    pipeline: &Pipeline,
) -> Result<Option<Box<S>>> {
    table
        .map(|t| registry.build_for::<S>(t, scripts, &pipeline.base_dir, pipeline.context()))
        .transpose()
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
    if table.get("use").is_some() {
        return registry.build_for::<dyn ModelSource>(table, scripts, base_dir, context);
    }
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
    registry
        .build_entry_for(entry, table, scripts, base_dir, context)?
        .into_type()
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

/// A pipeline's libraries are data: those it lists run only when the caller loads them
/// (the command line's `--plugin`), so each must be among the loaded ones.
fn check_plugins_loaded(pipeline: &Pipeline, options: &RunOptions) -> Result<()> {
    for path in &pipeline.plugins {
        let same = |p: &PathBuf| match (p.canonicalize(), path.canonicalize()) {
            (Ok(a), Ok(b)) => a == b,
            _ => p == path,
        };
        if !options.plugins.iter().any(same) {
            return Err(Error::config(format!(
                "{}: `plugins` lists {}, which was not loaded: a pipeline cannot load code by itself",
                pipeline.file.path.display(),
                path.display()
            ))
            .with_help(format!(
                "load it on the command line: --plugin {}",
                path.display()
            )));
        }
    }
    Ok(())
}

/// The stages of a pipeline as they are built. Every stage is built even when an
/// earlier one failed, so that one pass reports every wrong table (`lamina check`
/// prints them all, as a compiler does): errors are gathered, not returned.
struct Builder<'a> {
    registry: &'a Registry,
    pipeline: &'a Pipeline,
    scripts: &'a ScriptHost,
    options: &'a RunOptions,
    errors: Vec<Error>,
    models: Vec<ModelStage>,
}

impl Builder<'_> {
    /// The value of `r`, or `None` with its error gathered.
    fn kept<T>(&mut self, r: Result<T>) -> Option<T> {
        r.map_err(|e| self.errors.push(e)).ok()
    }

    /// A kind a pipeline may leave out, from its top-level table.
    fn optional<S: StageType + ?Sized>(&self) -> Result<Option<Box<S>>> {
        let table = self.pipeline.stages.get(&S::KIND);
        build_optional::<S>(self.registry, table, self.scripts, self.pipeline)
    }

    /// A stage for each of `tables` (`[[process]]`, `[[output]]`), in their order.
    fn each<S: StageType + ?Sized>(&mut self, tables: &[TableRef]) -> Vec<Box<S>> {
        let mut stages = Vec::new();
        for t in tables {
            let stage = self.registry.build_for::<S>(
                t,
                self.scripts,
                &self.pipeline.base_dir,
                self.pipeline.context(),
            );
            stages.extend(self.kept(stage));
        }
        stages
    }

    /// A model table (the pipeline's or a part's) built, with `--model` applied; its
    /// index in `models`.
    fn model(&mut self, spec: &ModelSpec) -> Result<usize> {
        let spec = match &self.options.model {
            Some(p) => replace_model_file(spec, p)?,
            None => spec.clone(),
        };
        let source = build_model(
            self.registry,
            &spec,
            self.scripts,
            &self.pipeline.base_dir,
            self.pipeline.context(),
        )?;
        self.models.push(ModelStage {
            source,
            label: describe_model(&spec),
            spec,
        });
        Ok(self.models.len() - 1)
    }

    /// Every part's stages: its model (its own or the pipeline's), discretiser and
    /// grader.
    fn parts(&mut self) -> Vec<PartStages> {
        let pipeline = self.pipeline;
        let global = pipeline.model.as_ref().map(|spec| self.model(spec)).transpose();
        let global_failed = global.is_err();
        let global = self.kept(global).flatten();
        let mut parts = Vec::new();
        for part in &pipeline.parts {
            let model = match &part.model {
                Some(spec) => self.model(spec).map(Some),
                None if global_failed => Ok(None),
                None => global
                    .map(Some)
                    .ok_or_else(|| Error::config(format!("part `{}` has no model", part.name))),
            };
            let model = self.kept(model).flatten();
            if let Some(stages) = self.part(part, model) {
                parts.push(stages);
            }
        }
        parts
    }

    /// One part's discretiser and grader, checked together: a part of several
    /// materials needs something that mixes them.
    fn part(&mut self, part: &crate::pipeline::PartSpec, model: Option<usize>) -> Option<PartStages> {
        let pipeline = self.pipeline;
        let discretise_table = part
            .discretise
            .as_ref()
            .or(pipeline.stages.get(&StageKind::Discretise));
        let discretiser =
            build_optional::<dyn Discretiser>(self.registry, discretise_table, self.scripts, pipeline);
        let grade_table = part.grade.as_ref().or(pipeline.stages.get(&StageKind::Grade));
        let grader = build_optional::<dyn Grader>(self.registry, grade_table, self.scripts, pipeline);
        let (discretiser, grader) = match (discretiser, grader) {
            (Ok(d), Ok(g)) => (d, g),
            (d, g) => {
                self.errors.extend([d.err(), g.err()].into_iter().flatten());
                return None;
            }
        };
        let discretiser_grades = discretiser.as_ref().is_some_and(|d| d.grades());
        if grader.is_none() && !discretiser_grades && part.materials.len() > 1 {
            self.errors.push(no_grader(pipeline, part));
            return None;
        }
        Some(PartStages {
            name: part.name.clone(),
            family_at: part.family_at,
            family_at_location: part.table.as_ref().and_then(|t| t.location_of(Some("family_at"))),
            materials: part.materials.clone(),
            model: model?,
            mesh: part.mesh,
            copies: part.copies,
            copy_gap: part.copy_gap,
            copy_columns: part.copy_columns,
            discretiser,
            grader,
        })
    }
}

/// The error of a part with several materials and nothing to mix them, placed at its
/// `materials` when the part has a table.
fn no_grader(pipeline: &Pipeline, part: &crate::pipeline::PartSpec) -> Error {
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
    .with_help("add a [grade] table, or give the part a single material with `materials = [\"...\"]`");
    match part.table.as_ref().and_then(|t| t.location_of(Some("materials"))) {
        Some(loc) => Error::Config {
            location: Some(loc),
            message: err.to_string(),
            help: err.help().map(str::to_string),
        },
        None => err,
    }
}

impl Engine {
    /// Loads plugins and builds every stage of `pipeline`. Scripts are compiled here, so
    /// a pipeline that builds is a pipeline whose configuration is valid.
    pub fn build(mut pipeline: Pipeline, mut registry: Registry, options: &RunOptions) -> Result<Engine> {
        for path in &options.plugins {
            crate::plugin::load_with(&mut registry, path, &options.isolation)?;
        }
        check_plugins_loaded(&pipeline, options)?;
        // The model file the caller names replaces the pipeline's, and is read wherever
        // it is.
        if let Some(model) = &options.model {
            pipeline.reach.allow(model);
        }
        if options.model.is_some() && pipeline.parts.len() > 1 {
            return Err(Error::config(format!(
                "--model replaces the model of a single-part pipeline, and `{}` has {} parts",
                pipeline.file.path.display(),
                pipeline.parts.len()
            )));
        }
        let scripts =
            crate::script::local_within(&pipeline.base_dir, options.script_limits, pipeline.reach.clone());
        let mut builder = Builder {
            registry: &registry,
            pipeline: &pipeline,
            scripts: &scripts,
            options,
            errors: Vec::new(),
            models: Vec::new(),
        };
        let parts = builder.parts();
        let slicer = build_default::<dyn Slicer>(&registry, &pipeline, &scripts);
        let sorter = build_default::<dyn Sorter>(&registry, &pipeline, &scripts);
        let orienter = builder.optional::<dyn Orienter>();
        let sequencer = builder.optional::<dyn Sequencer>();
        let planner = builder.optional::<dyn Planner>();
        let process = builder.each::<dyn Process>(&pipeline.process);
        let exporters = builder.each::<dyn Exporter>(&pipeline.outputs);
        // Errors in the order `lamina check` has always listed them.
        let (slicer, sorter) = (builder.kept(slicer), builder.kept(sorter));
        let (orienter, sequencer, planner) = (
            builder.kept(orienter),
            builder.kept(sequencer),
            builder.kept(planner),
        );
        let Builder { errors, models, .. } = builder;
        if let Some(e) = Error::gathered(errors) {
            return Err(e);
        }
        // Every stage above built when nothing was gathered.
        let built = || Error::stage("runtime", "a stage was not built");
        let (slicer, sorter) = (slicer.ok_or_else(built)?, sorter.ok_or_else(built)?);
        let (orienter, sequencer, planner) = (
            orienter.ok_or_else(built)?,
            sequencer.ok_or_else(built)?,
            planner.ok_or_else(built)?,
        );
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
            process,
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
        if !self.process.is_empty() {
            lines.push(format!("process stages: {}", self.process.len()));
        }
        lines.push(format!("outputs: {}", self.exporters.len()));
        lines
    }
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
