//! A whole run: meshes, sequence and layer slots, then the layers on the worker pool,
//! each finished layer streamed to the exporters in build order.

use std::path::Path;
use std::sync::atomic::Ordering;
use std::time::Instant;

use rayon::prelude::*;

use super::engine::Engine;
use super::layer::LayerShared;
use super::meshes::{PartMeshes, short};
use super::report::{Observer, RunReport, Timings};
use crate::diagnostic::Diagnostic;
use crate::error::{Error, Result};
use crate::output::AtomicOutputs;
use crate::stage::*;

/// Stack of each worker thread (bytes).
const WORKER_STACK: usize = 64 << 20;

impl Engine {
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
        let PartMeshes {
            meshes,
            part_mesh,
            parts_info,
            bbox,
            xy_bounds,
            orientation,
            model_frame,
            warnings,
        } = self.part_meshes(&timings)?;
        let mut diagnostics = Vec::new();
        let mut say = |d: Diagnostic| {
            observer.diagnostic(&d);
            diagnostics.push(d);
        };
        for w in &warnings {
            say(Diagnostic::warning(StageKind::Model, w.as_str()));
        }
        let info = RunInfo {
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
        let mut info = info;
        let sequence = match &self.sequencer {
            Some(s) => {
                if s.needs_gradients() {
                    let gradients =
                        pool.install(|| self.z_gradients(&info, &meshes, &prepared, &part_mesh, &timings))?;
                    for (p, g) in info.parts.iter_mut().zip(gradients) {
                        p.z_gradient = g;
                    }
                }
                Some(timings.time(StageKind::Sequence, || s.sequence(&info))?)
            }
            None => None,
        };
        let info = info;
        let slots = timings.time(StageKind::Slice, || {
            self.slicer.layers(&meshes, &info, sequence.as_ref())
        })?;
        // A part thinner than the thinnest layer is most likely scaled wrong: it is
        // planned, but said.
        let thinnest = slots.iter().map(|s| s.thickness).fold(f64::INFINITY, f64::min);
        for p in &info.parts {
            let tall = p.z_max - p.z_min;
            if tall < thinnest {
                let message = format!(
                    "{} mm tall, thinner than a layer ({} mm): is its scale right?",
                    short(tall),
                    short(thinnest)
                );
                say(Diagnostic::warning(StageKind::Slice, message).in_part(&p.name));
            }
        }

        let selections = self.select_families(&slots, &meshes, &prepared, &part_mesh, &pool, &timings)?;

        let mut outputs = AtomicOutputs::new(out_dir);
        let mut sinks = Vec::new();
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
        for (e, label) in self.exporters.iter().zip(&labels) {
            let mut ctx = ExportContext {
                info: &info,
                sequence: sequence.as_ref(),
                orientation: orientation.as_ref(),
                layer_count: slots.len(),
                pipeline_name: &self.pipeline.name,
                files: &mut outputs,
            };
            sinks.push(timings.time(StageKind::Export, || {
                crate::plugin::guard_call(label, || e.open(&mut ctx))
            })?);
        }

        let surfaces = match (&sequence, self.process.is_empty()) {
            (Some(seq), false) => crate::process::surfaces_before(&slots, seq.regions.len()),
            _ => Vec::new(),
        };
        let mut surface_check = crate::process::SurfaceCheck::new(sequence.as_ref());
        let mut operations = std::collections::BTreeMap::<String, usize>::new();
        let shared = LayerShared {
            surfaces: &surfaces,
            layer_count: slots.len(),
            slots: &slots,
            info: &info,
            meshes: &meshes,
            sequence: sequence.as_ref(),
            prepared: &prepared,
            part_mesh: &part_mesh,
            selections: &selections,
            timings: &timings,
        };
        observer.started(slots.len());
        // Layers computed ahead of the exporters: a few per thread keeps every worker
        // busy while bounding what memory holds.
        let ahead = pool.current_num_threads().max(1) * 4;
        let mut regions = 0;
        let mut build_time: Option<f64> = None;
        let mut sequential_time: Option<f64> = None;
        let mut pauses: Option<crate::Pauses> = None;
        let mut fill: Option<(f64, f64)> = None;
        let mut min_fill = 0.0f64;
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
            |_, plan| {
                let plan = plan?;
                for d in &plan.diagnostics {
                    say(d.clone());
                }
                regions += plan.parts.iter().map(|p| p.regions.len()).sum::<usize>();
                if !self.process.is_empty() {
                    surface_check
                        .layer(&plan)
                        .map_err(|m| Error::stage("process", m).in_layer(plan.index, plan.z))?;
                }
                for op in &plan.operations {
                    *operations.entry(op.kind.clone()).or_default() += 1;
                }
                if let Some(t) = plan.build_time {
                    *build_time.get_or_insert(0.0) += t;
                }
                if let Some(t) = plan.sequential_time {
                    *sequential_time.get_or_insert(0.0) += t;
                }
                if let Some(p) = &plan.pauses {
                    pauses.get_or_insert_default().add(p);
                }
                if let Some(f) = plan.fill {
                    let sum = fill.get_or_insert((0.0, 0.0));
                    sum.0 += f.deposited * plan.thickness;
                    sum.1 += f.area * plan.thickness;
                    min_fill = min_fill.max(f.min_ratio);
                }
                for (sink, label) in sinks.iter_mut().zip(&labels) {
                    timings.time(StageKind::Export, || {
                        crate::plugin::guard_call(label, || sink.layer(&info, &plan, &mut outputs))
                    })?;
                }
                observer.layer_done(plan.index);
                Ok(())
            },
        )?;
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
        for (sink, label) in sinks.into_iter().zip(&labels) {
            timings.time(StageKind::Export, || {
                crate::plugin::guard_call(label, || sink.finish(&info, &mut outputs))
            })?;
        }
        let machine_files = outputs.take_reports();
        for m in &machine_files {
            for note in &m.notes {
                let d = Diagnostic::warning(StageKind::Export, format!("{}: {note}", m.file.display()));
                observer.diagnostic(&d);
                diagnostics.push(d);
            }
        }
        let files = outputs.commit()?;
        timings
            .wall
            .store(started.elapsed().as_nanos() as u64, Ordering::Relaxed);
        Ok(RunReport {
            layers: slots.len(),
            regions,
            files,
            diagnostics,
            timings,
            build_time,
            sequential_time,
            pauses,
            fill,
            orientation,
            operations,
            machine_files,
        })
    }
}
