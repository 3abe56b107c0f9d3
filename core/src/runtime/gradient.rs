//! A part's composition gradient along z, sampled from its grading before the
//! sequence is planned: the CMPM rule that a region whose composition changes faster
//! takes thinner layers (cmpm-process-planning 4.1) needs it.
//!
//! The part is cut at `SAMPLES` heights through its range and each cut discretised and
//! graded as a layer would be. Between neighbouring cuts, each sub-region of the lower
//! one is looked up at its reference point in the upper one; the largest change of any
//! material's fraction over the height between them is the gradient.

use std::sync::Arc;

use rayon::prelude::*;

use super::engine::Engine;
use super::families::Selections;
use super::layer::LayerShared;
use super::mend::LayerCuts;
use super::report::Timings;
use crate::error::Result;
use crate::mesh::Mesh;
use crate::model::{LayerSlot, SubRegion};
use crate::stage::{MeshSlicer, RunInfo, StageKind};

/// Heights each part is cut at.
const SAMPLES: usize = 24;

impl Engine {
    /// Every part's gradient (fraction per mm), `None` for a part of one material
    /// (nothing to change) or too thin to cut twice.
    pub(super) fn z_gradients(
        &self,
        info: &RunInfo,
        meshes: &[Arc<Mesh>],
        prepared: &[Box<dyn MeshSlicer>],
        part_mesh: &[usize],
        timings: &Timings,
    ) -> Result<Vec<Option<f64>>> {
        let selections = Selections::none(self.parts.len());
        let bare_info = RunInfo {
            machine: None,
            ..info.clone()
        };
        let shared = LayerShared {
            info,
            bare_info: &bare_info,
            meshes,
            sequence: None,
            prepared,
            part_mesh,
            copies: &[],
            selections: &selections,
            timings,
            surfaces: &[],
            layer_count: SAMPLES,
            cuts: &LayerCuts::new(prepared, meshes, &[]),
        };
        (0..self.parts.len())
            .map(|pi| {
                let p = &info.parts[pi];
                let span = p.z_max - p.z_min;
                if p.materials.len() < 2 || !span.is_finite() || span <= 0.0 {
                    return Ok(None);
                }
                let dz = span / SAMPLES as f64;
                let cuts: Vec<(f64, Vec<SubRegion>)> = (0..SAMPLES)
                    .into_par_iter()
                    .map(|k| {
                        let z = p.z_min + (k as f64 + 0.5) * dz;
                        let slot = LayerSlot::new(k, z + dz / 2.0, dz, z);
                        let layer =
                            timings.time(StageKind::Slice, || prepared[part_mesh[pi]].slice(&slot))?;
                        let tree = timings.time(StageKind::Sort, || self.sorter.sort(&layer))?;
                        let families: Vec<usize> = (0..tree.families.len()).collect();
                        let polygons = tree.family_polygons(&layer.contours);
                        let regions = self.process_part(pi, &layer, &tree, &polygons, &families, &shared)?;
                        Ok((z, regions))
                    })
                    .collect::<Result<_>>()
                    .map_err(|e: crate::Error| e.in_part(&p.name))?;
                let mut steepest = 0.0f64;
                for pair in cuts.windows(2) {
                    let ((z0, lower), (z1, upper)) = (&pair[0], &pair[1]);
                    for r in lower {
                        let Some(a) = &r.composition else { continue };
                        let Some(b) = upper
                            .iter()
                            .find(|u| u.polygon.contains(r.reference))
                            .and_then(|u| u.composition.as_ref())
                        else {
                            continue;
                        };
                        for (x, y) in a.fractions.iter().zip(&b.fractions) {
                            steepest = steepest.max((y - x).abs() / (z1 - z0));
                        }
                    }
                }
                Ok(Some(steepest))
            })
            .collect()
    }
}
