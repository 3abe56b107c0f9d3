//! A whole run: meshes, sequence and layer slots, then the layers on the worker pool,
//! each finished layer streamed to the exporters in build order.

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Instant;

use rayon::prelude::*;

use super::engine::Engine;
use super::layer::LayerShared;
use super::meshes::{check_on_bed, merge, merge_owned, orient, short};
use super::report::{Observer, RunReport, Timings};
use crate::diagnostic::Diagnostic;
use crate::error::{Error, Result};
use crate::geom::Point2;
use crate::mesh::{BBox3, Mesh};
use crate::model::PartInfo;
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
        let mut loaded = self.load_models(&timings)?;
        let (orientation, model_frame) = match &self.orienter {
            Some(o) => {
                let (orientation, frame) =
                    timings.time(StageKind::Orient, || orient(o.as_ref(), &mut loaded))?;
                (Some(orientation), frame)
            }
            None => (None, None),
        };
        let mut diagnostics = Vec::new();
        let mut say = |d: Diagnostic| {
            observer.diagnostic(&d);
            diagnostics.push(d);
        };
        for mesh in loaded.iter().flatten() {
            for w in &mesh.warnings {
                say(Diagnostic::warning(StageKind::Model, w.as_str()));
            }
        }
        // Parts taking the same mesh of the same model (told apart by `family_at`)
        // share it: it is cut once per layer. Each distinct mesh is made once, moved out
        // of the loaded models when nothing else needs it, and the loaded models are
        // dropped: a run holds each mesh once.
        let mut mesh_keys: Vec<(usize, Option<usize>)> = Vec::new();
        for p in &self.parts {
            let model = &loaded[p.model];
            if let Some(i) = p.mesh
                && i >= model.len()
            {
                return Err(Error::config(format!(
                    "part `{}` asks for mesh {i}, but its model holds {} meshes",
                    p.name,
                    model.len()
                )));
            }
            if !mesh_keys.contains(&(p.model, p.mesh)) {
                mesh_keys.push((p.model, p.mesh));
            }
        }
        let meshes: Vec<Arc<Mesh>> = (0..mesh_keys.len())
            .map(|k| {
                let (m, which) = mesh_keys[k];
                // Another key still to be made that reads this model's meshes.
                let needed_later = mesh_keys[k + 1..].iter().any(|&(o, _)| o == m);
                let mesh = match which {
                    Some(i) if needed_later => loaded[m][i].clone(),
                    Some(i) => std::mem::take(&mut loaded[m][i]),
                    None if needed_later => merge(&loaded[m], &self.models[m].label),
                    None => merge_owned(std::mem::take(&mut loaded[m]), &self.models[m].label),
                };
                Arc::new(mesh)
            })
            .collect();
        drop(loaded);
        let mut part_mesh = Vec::new();
        let mut parts_info = Vec::new();
        for p in &self.parts {
            let idx = mesh_keys
                .iter()
                .position(|&k| k == (p.model, p.mesh))
                .unwrap_or_default();
            let bb = meshes[idx].bbox();
            part_mesh.push(idx);
            parts_info.push(PartInfo {
                name: p.name.clone(),
                materials: p.materials.clone(),
                mesh: idx,
                z_min: bb.min.z,
                z_max: bb.max.z,
                z_gradient: None,
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

        let selections = self.select_families(&slots, &prepared, &part_mesh, &pool, &timings)?;

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
