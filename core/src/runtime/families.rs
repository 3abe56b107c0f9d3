//! Parts that share a mesh and pick their solid with `family_at`: a pre-pass cuts the
//! layers of that mesh and follows the selection through them with
//! [`lamina_geom::follow`]; the cuts are kept for the layer pass, so no layer is cut
//! twice.

use rayon::prelude::*;

use super::engine::Engine;
use super::layer::check_tree;
use super::report::Timings;
use crate::error::{Error, Result};
use std::sync::Mutex;

use lamina_geom::follow::{Area, follow};

use crate::geom::Point2;
use crate::model::{ContourTree, Layer, LayerSlot};
use crate::stage::{MeshSlicer, StageKind};

/// Which families of each layer belong to parts that select theirs with `family_at`:
/// per part, per layer, one sample point inside each selected family.
pub(super) struct Selections {
    /// `None` for parts without `family_at`.
    samples: Vec<Option<Vec<Vec<Point2>>>>,
    /// Per mesh followed, per layer, its cut and tree until the layer pass takes it.
    cuts: Vec<Option<Vec<Mutex<Option<Cut>>>>>,
}

/// A layer of one mesh, cut and sorted.
pub(super) type Cut = (Layer, ContourTree);

impl Selections {
    /// No part selects its families: every part has them all.
    pub(super) fn none(parts: usize) -> Self {
        Self {
            samples: vec![None; parts],
            cuts: Vec::new(),
        }
    }

    /// The cut of mesh `mesh` at layer `layer_index` made while following the
    /// selections, if it was made and not taken yet.
    pub(super) fn take_cut(&self, mesh: usize, layer_index: usize) -> Option<Cut> {
        let slot = self.cuts.get(mesh)?.as_ref()?.get(layer_index)?;
        slot.lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .take()
    }

    /// The families of `layer` that belong to part `pi`.
    pub(super) fn families(
        &self,
        pi: usize,
        layer_index: usize,
        layer: &Layer,
        tree: &ContourTree,
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

impl Engine {
    /// Follows each `family_at` selection through the layers (see
    /// [`lamina_geom::follow`]). The layers cut and sorted for it are kept in the
    /// selections, for the layer pass to take instead of cutting them again.
    pub(super) fn select_families(
        &self,
        slots: &[LayerSlot],
        prepared: &[Box<dyn MeshSlicer>],
        part_mesh: &[usize],
        pool: &rayon::ThreadPool,
        timings: &Timings,
    ) -> Result<Selections> {
        let mut samples: Vec<Option<Vec<Vec<Point2>>>> = vec![None; self.parts.len()];
        let mut cuts: Vec<Option<Vec<Mutex<Option<Cut>>>>> = (0..prepared.len()).map(|_| None).collect();
        if self.parts.iter().all(|p| p.family_at.is_none()) || slots.is_empty() {
            return Ok(Selections { samples, cuts });
        }
        // The areas of every layer of the meshes concerned.
        let mut by_mesh: Vec<Option<Vec<Vec<Area>>>> = (0..prepared.len()).map(|_| None).collect();
        for (pi, p) in self.parts.iter().enumerate() {
            let mi = part_mesh[pi];
            if p.family_at.is_none() || by_mesh[mi].is_some() {
                continue;
            }
            let layers: Vec<(Cut, Vec<Area>)> = pool.install(|| {
                slots
                    .par_iter()
                    .map(|slot| {
                        let layer = timings.time(StageKind::Slice, || prepared[mi].slice(slot))?;
                        let tree = timings.time(StageKind::Sort, || self.sorter.sort(&layer))?;
                        check_tree(&layer, &tree)?;
                        let areas = (0..tree.families.len())
                            .map(|f| Area::new(tree.family_polygon(&layer.contours, f)))
                            .collect();
                        Ok(((layer, tree), areas))
                    })
                    .collect::<Result<Vec<_>>>()
            })?;
            let (cut, areas): (Vec<Cut>, Vec<Vec<Area>>) = layers.into_iter().unzip();
            // Kept by layer index (a slot whose index is not its place is cut again).
            let kept = cut
                .into_iter()
                .enumerate()
                .map(|(k, c)| Mutex::new((slots[k].index == k).then_some(c)));
            cuts[mi] = Some(kept.collect());
            by_mesh[mi] = Some(areas);
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
            let Some(selected) = follow(layers, start, Point2::new(x, y)) else {
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
            };
            samples[pi] = Some(
                selected
                    .iter()
                    .zip(layers)
                    .map(|(sel, areas)| sel.iter().map(|&f| areas[f].inside).collect())
                    .collect(),
            );
        }
        Ok(Selections { samples, cuts })
    }
}
