//! A whole run: meshes, sequence and layer slots, then the layers on the worker pool,
//! each finished layer streamed to the exporters in build order.

use std::path::Path;
use std::sync::atomic::Ordering;
use std::time::Instant;

use rayon::prelude::*;

use super::engine::Engine;
use super::layer::LayerShared;
use super::mend::LayerCuts;
use super::meshes::{PartMeshes, short};
use super::report::{Observer, RunReport, Timings};
use crate::diagnostic::Diagnostic;
use crate::error::{Error, Result};
use crate::model::{LayerPlan, LayerSlot, Orientation, Sequence};
use crate::output::AtomicOutputs;
use crate::stage::*;

/// Stack of each worker thread (bytes).
const WORKER_STACK: usize = 64 << 20;

/// What the layers add up to, tallied as each is handed to the exporters.
#[derive(Default)]
struct Tally {
    regions: usize,
    build_time: Option<f64>,
    sequential_time: Option<f64>,
    pauses: Option<crate::Pauses>,
    /// Deposited and filled volume (mm³).
    fill: Option<(f64, f64)>,
    /// The largest share of its volume any layer's planner was asked to fill.
    min_fill: f64,
    operations: std::collections::BTreeMap<String, usize>,
    /// What the meshes' cuts enclosed and their contours kept.
    volumes: super::volume::Volumes,
}

impl Tally {
    fn add(&mut self, plan: &LayerPlan) {
        self.regions += plan.parts.iter().map(|p| p.regions.len()).sum::<usize>();
        for op in &plan.operations {
            *self.operations.entry(op.kind.clone()).or_default() += 1;
        }
        if let Some(t) = plan.build_time {
            *self.build_time.get_or_insert(0.0) += t;
        }
        if let Some(t) = plan.sequential_time {
            *self.sequential_time.get_or_insert(0.0) += t;
        }
        if let Some(p) = &plan.pauses {
            self.pauses.get_or_insert_default().add(p);
        }
        if let Some(f) = plan.fill {
            let sum = self.fill.get_or_insert((0.0, 0.0));
            sum.0 += f.deposited * plan.thickness;
            sum.1 += f.area * plan.thickness;
            self.min_fill = self.min_fill.max(f.min_ratio);
        }
    }

    /// A part whose toolpaths deposit less than the planner was asked to fill is an
    /// error: written, it would be printed short.
    fn check_fill(&self) -> Result<()> {
        if let Some((deposited, volume)) = self.fill
            && volume > 0.0
            && deposited < self.min_fill * volume
        {
            return Err(Error::stage(
                "plan",
                format!(
                    "the toolpaths deposit {deposited:.1} mm³ of the {volume:.1} mm³ to fill ({:.1} %, \
                     below the {:.1} % asked by `min_fill`); see the layers' warnings for what is left out",
                    100.0 * deposited / volume,
                    100.0 * self.min_fill
                ),
            ));
        }
        Ok(())
    }
}

/// The run's layers laid out before any is computed: the parts' meshes prepared for
/// slicing, the sequence, the layer slots and what every stage may consult.
struct Layout {
    meshes: Vec<std::sync::Arc<crate::mesh::Mesh>>,
    part_mesh: Vec<usize>,
    info: RunInfo,
    orientation: Option<Orientation>,
    prepared: Vec<Box<dyn MeshSlicer>>,
    sequence: Option<Sequence>,
    slots: Vec<LayerSlot>,
    /// The parts' copies; copy `k` is part `parts + k` of `info`.
    copies: Vec<super::copies::PartCopy>,
}

/// Worker threads for the layers.
fn worker_pool(threads: Option<usize>) -> Result<rayon::ThreadPool> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads.unwrap_or(0))
        // Scripts recurse within their depth limits on these threads: room for the
        // deepest the limits allow, reserved, not touched.
        .stack_size(WORKER_STACK)
        .build()
        .map_err(|e| Error::config(format!("cannot start worker threads: {e}")))
}

/// A part thinner than the thinnest layer is most likely scaled wrong: it is planned,
/// but said.
fn thin_parts(info: &RunInfo, slots: &[LayerSlot]) -> Vec<Diagnostic> {
    let thinnest = slots.iter().map(|s| s.thickness).fold(f64::INFINITY, f64::min);
    info.parts
        .iter()
        .filter(|p| p.z_max - p.z_min < thinnest)
        .map(|p| {
            let message = format!(
                "{} mm tall, thinner than a layer ({} mm): is its scale right?",
                short(p.z_max - p.z_min),
                short(thinnest)
            );
            Diagnostic::warning(StageKind::Slice, "part-thinner-than-layer", message).in_part(&p.name)
        })
        .collect()
}

impl Engine {
    /// Runs the pipeline, writing the outputs into `out_dir`. Outputs appear only when
    /// the whole run succeeds.
    pub fn run(&self, out_dir: &Path, observer: &dyn Observer) -> Result<RunReport> {
        let started = Instant::now();
        let timings = Timings::default();
        let pool = worker_pool(self.threads)?;
        let mut diagnostics = Vec::new();
        let mut say = |d: Diagnostic| {
            observer.diagnostic(&d);
            diagnostics.push(d);
        };
        let layout = self.lay_out(&pool, &timings, &mut say)?;
        let Layout {
            meshes,
            part_mesh,
            info,
            prepared,
            sequence,
            slots,
            copies,
            ..
        } = &layout;
        let cuts = LayerCuts::new(prepared, meshes, slots);
        let selections = self.select_families(&cuts, part_mesh, &pool, &timings)?;

        let mut outputs = AtomicOutputs::new(out_dir);
        // Exporters run under the panic guard, as every other stage does: a panic in
        // one is an error naming it, and the run's outputs are removed.
        let labels: Vec<String> = (0..self.exporters.len())
            .map(|i| {
                let name = self
                    .pipeline
                    .outputs
                    .get(i)
                    .and_then(|t| t.use_name())
                    .unwrap_or("?");
                format!("output `{name}`")
            })
            .collect();
        let mut sinks = self.open_outputs(&layout, &labels, &mut outputs, &timings)?;

        let surfaces = match (sequence, self.process.is_empty()) {
            (Some(seq), false) => crate::process::surfaces_before(slots, seq.regions.len()),
            _ => Vec::new(),
        };
        let mut surface_check = crate::process::SurfaceCheck::new(sequence.as_ref());
        let bare_info = RunInfo {
            machine: None,
            ..info.clone()
        };
        let shared = LayerShared {
            surfaces: &surfaces,
            layer_count: slots.len(),
            cuts: &cuts,
            info,
            bare_info: &bare_info,
            meshes,
            sequence: sequence.as_ref(),
            prepared,
            part_mesh,
            copies,
            selections: &selections,
            timings: &timings,
        };
        observer.started(slots.len());
        // Layers computed ahead of the exporters: a few per thread keeps every worker
        // busy while bounding what memory holds.
        let ahead = pool.current_num_threads().max(1) * 4;
        let mut tally = Tally::default();
        // The pool computes the layers while this thread hands each finished one, in
        // build order, to the exporters.
        super::stream::ordered(
            &pool,
            slots.len(),
            ahead,
            |i| {
                let slot = &slots[i];
                // A stage that panics on some input ends the run with an error naming
                // the layer, not with an abort.
                crate::plugin::guard_call("a layer's stages", || self.process_layer(slot, &shared))
                    .map_err(|e| e.in_layer(slot.index, slot.z))
            },
            |_, done| {
                let (plan, kept) = done?;
                tally.volumes.add(plan.index, plan.z, plan.thickness, &kept);
                for d in &plan.diagnostics {
                    say(d.clone());
                }
                if !self.process.is_empty() {
                    surface_check
                        .layer(&plan)
                        .map_err(|m| Error::stage("process", m).in_layer(plan.index, plan.z))?;
                }
                tally.add(&plan);
                for (sink, label) in sinks.iter_mut().zip(&labels) {
                    timings.time(StageKind::Export, || {
                        crate::plugin::guard_call(label, || sink.layer(info, &plan, &mut outputs))
                    })?;
                }
                observer.layer_done(plan.index);
                Ok(())
            },
        )?;
        tally.check_fill()?;
        let said = tally.volumes.check(|mesh| {
            let parts: Vec<String> = (0..part_mesh.len())
                .filter(|&p| part_mesh[p] == mesh)
                .map(|p| format!("`{}`", info.parts[p].name))
                .collect();
            let word = if parts.len() == 1 { "part" } else { "parts" };
            format!("{word} {}", parts.join(", "))
        })?;
        for (code, message) in said {
            say(Diagnostic::warning(StageKind::Slice, code, message));
        }
        for (sink, label) in sinks.into_iter().zip(&labels) {
            timings.time(StageKind::Export, || {
                crate::plugin::guard_call(label, || sink.finish(info, &mut outputs))
            })?;
        }
        for d in outputs.take_told() {
            say(d);
        }
        let machine_files = outputs.take_reports();
        for m in &machine_files {
            for note in &m.notes {
                say(Diagnostic::warning(
                    StageKind::Export,
                    note.code.as_str(),
                    format!("{}: {}", m.file.display(), note.message),
                ));
            }
        }
        let files = outputs.commit()?;
        timings
            .wall
            .store(started.elapsed().as_nanos() as u64, Ordering::Relaxed);
        Ok(RunReport {
            layers: slots.len(),
            regions: tally.regions,
            files,
            diagnostics,
            timings,
            build_time: tally.build_time,
            sequential_time: tally.sequential_time,
            pauses: tally.pauses,
            fill: tally.fill,
            orientation: layout.orientation,
            operations: tally.operations,
            machine_files,
        })
    }

    /// The parts' meshes (a part takes one mesh of its model, or all merged), prepared
    /// for slicing; their gradients along z when the sequencer needs them; the
    /// sequence; and the layer slots.
    fn lay_out(
        &self,
        pool: &rayon::ThreadPool,
        timings: &Timings,
        say: &mut dyn FnMut(Diagnostic),
    ) -> Result<Layout> {
        let PartMeshes {
            meshes,
            part_mesh,
            parts_info,
            bbox,
            xy_bounds,
            orientation,
            model_frame,
            warnings,
            copies,
        } = self.part_meshes(timings)?;
        for w in &warnings {
            say(Diagnostic::from_warning(StageKind::Model, w));
        }
        let mut info = RunInfo {
            base_dir: self.pipeline.base_dir.clone(),
            materials: self.pipeline.materials.clone(),
            parts: parts_info,
            z_min: bbox.min.z,
            z_max: bbox.max.z,
            xy_bounds,
            machine: self.pipeline.machine.clone(),
            model_frame,
        };
        let prepared: Vec<Box<dyn MeshSlicer>> = pool.install(|| {
            meshes
                .par_iter()
                .map(|m| timings.time(StageKind::Slice, || self.slicer.prepare(m.clone())))
                .collect::<Result<Vec<_>>>()
        })?;
        let sequence = match &self.sequencer {
            Some(s) => {
                if s.needs_gradients() {
                    let gradients =
                        pool.install(|| self.z_gradients(&info, &meshes, &prepared, &part_mesh, timings))?;
                    for (p, g) in info.parts.iter_mut().zip(gradients) {
                        p.z_gradient = g;
                    }
                }
                Some(timings.time(StageKind::Sequence, || s.sequence(&info))?)
            }
            None => None,
        };
        let slots = timings.time(StageKind::Slice, || {
            self.slicer.layers(&meshes, &info, sequence.as_ref())
        })?;
        for d in thin_parts(&info, &slots) {
            say(d);
        }
        // The copies join the parts once the sequence and the layers are made: they
        // follow their parts' material regions and are cut with them.
        for c in &copies {
            let mut copy = info.parts[c.of].clone();
            copy.name = format!("{}#{}", copy.name, c.number);
            info.parts.push(copy);
        }
        Ok(Layout {
            meshes,
            part_mesh,
            info,
            orientation,
            prepared,
            sequence,
            slots,
            copies,
        })
    }

    /// Every exporter's output opened, each under the panic guard with its label.
    fn open_outputs(
        &self,
        layout: &Layout,
        labels: &[String],
        outputs: &mut AtomicOutputs,
        timings: &Timings,
    ) -> Result<Vec<Box<dyn LayerSink>>> {
        let mut sinks = Vec::new();
        for (e, label) in self.exporters.iter().zip(labels) {
            let mut ctx = ExportContext {
                info: &layout.info,
                sequence: layout.sequence.as_ref(),
                orientation: layout.orientation.as_ref(),
                layer_count: layout.slots.len(),
                pipeline_name: &self.pipeline.name,
                files: outputs,
            };
            sinks.push(timings.time(StageKind::Export, || {
                crate::plugin::guard_call(label, || e.open(&mut ctx))
            })?);
        }
        Ok(sinks)
    }
}
