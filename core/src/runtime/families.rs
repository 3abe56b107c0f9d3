//! Parts that share a mesh and pick their solid with `family_at`: a pre-pass cuts the
//! layers of that mesh and follows the selection through them with
//! [`lamina_geom::follow`]. Of each layer it keeps a point inside each solid area and
//! which areas of the layer above each overlaps, and the cut itself while the cuts kept
//! stay within [`CUT_BUDGET`]: the layer pass takes those instead of cutting again, and
//! cuts the others anew, so memory stays flat however many layers the part has.

use rayon::prelude::*;

use super::engine::Engine;
use super::layer::check_tree;
use super::mend::LayerCuts;
use super::report::Timings;
use crate::error::{Error, Result};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

use lamina_geom::follow::{Area, LayerLinks, follow_links, holding};

use crate::geom::{Point2, Polygon};
use crate::model::{ContourTree, Layer};
use crate::stage::StageKind;

/// Which families of each layer belong to parts that select theirs with `family_at`:
/// per part, per layer, one sample point inside each selected family.
pub(super) struct Selections {
    /// `None` for parts without `family_at`.
    samples: Vec<Option<Vec<Vec<Point2>>>>,
    /// Per mesh followed, per layer, its cut and tree if the pre-pass kept it, until the
    /// layer pass takes it.
    cuts: Vec<Option<Vec<Mutex<Option<Cut>>>>>,
}

/// A layer of one mesh, cut and sorted.
pub(super) type Cut = (Layer, ContourTree);

/// Bytes of cuts the pre-pass keeps for the layer pass, all meshes together: enough for
/// every layer of most parts, and a bound on the memory of one with very many layers
/// (those are cut again).
const CUT_BUDGET: usize = 16 << 20;

/// About the bytes a cut holds.
fn cut_bytes((layer, tree): &Cut) -> usize {
    let points: usize = layer.contours.iter().map(|c| c.points.len()).sum();
    points * std::mem::size_of::<Point2>()
        + layer.contours.len() * 64
        + tree.families.len() * 64
        + std::mem::size_of::<Cut>()
}

/// Layers followed in one piece of work: each piece cuts its first layer's upper
/// neighbour once more than a single pass would, and holds two layers at a time.
const LAYERS_PER_PIECE: usize = 16;

impl Selections {
    /// No part selects its families: every part has them all.
    pub(super) fn none(parts: usize) -> Self {
        Self {
            samples: vec![None; parts],
            cuts: Vec::new(),
        }
    }

    /// The cut of mesh `mesh` at layer `layer_index` kept while following the
    /// selections, if it was kept and not taken yet.
    pub(super) fn take_cut(&self, mesh: usize, layer_index: usize) -> Option<Cut> {
        let slot = self.cuts.get(mesh)?.as_ref()?.get(layer_index)?;
        slot.lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .take()
    }

    /// The families of a layer (their `polygons`) that belong to part `pi`.
    pub(super) fn families(
        &self,
        pi: usize,
        layer_index: usize,
        polygons: &[Polygon],
        part_mesh: &[usize],
    ) -> Vec<usize> {
        let selecting_on_mesh = |o: usize| part_mesh[o] == part_mesh[pi] && self.samples[o].is_some();
        if !(0..self.samples.len()).any(selecting_on_mesh) {
            // Nobody selects on this mesh: the part has every family.
            return (0..polygons.len()).collect();
        }
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
    /// [`lamina_geom::follow`]).
    pub(super) fn select_families(
        &self,
        mended: &LayerCuts<'_>,
        part_mesh: &[usize],
        pool: &rayon::ThreadPool,
        timings: &Timings,
    ) -> Result<Selections> {
        let mut samples: Vec<Option<Vec<Vec<Point2>>>> = vec![None; self.parts.len()];
        let slots = mended.slots();
        let mut cuts: Vec<Option<Vec<Mutex<Option<Cut>>>>> = (0..mended.meshes()).map(|_| None).collect();
        if self.parts.iter().all(|p| p.family_at.is_none()) || slots.is_empty() {
            return Ok(Selections { samples, cuts });
        }
        let spent = AtomicUsize::new(0);
        // The solid areas of a layer of mesh `mi`, cut and sorted; the cut goes into
        // `keep` if the budget allows (and the slot's index is its place).
        let areas = |mi: usize, k: usize, keep: Option<&Mutex<Option<Cut>>>| -> Result<Vec<Area>> {
            let layer = timings.time(StageKind::Slice, || mended.at(mi, k))?;
            let tree = timings.time(StageKind::Sort, || self.sorter.sort(&layer))?;
            check_tree(&layer, &tree)?;
            let areas = tree
                .family_polygons(&layer.contours)
                .into_iter()
                .map(Area::new)
                .collect();
            let cut = (layer, tree);
            let bytes = cut_bytes(&cut);
            if let Some(keep) = keep.filter(|_| slots[k].index == k)
                && spent.fetch_add(bytes, Ordering::Relaxed) + bytes <= CUT_BUDGET
            {
                *keep.lock().unwrap_or_else(std::sync::PoisonError::into_inner) = Some(cut);
            }
            Ok(areas)
        };
        // How the areas of every layer of the meshes concerned overlap, a piece of
        // consecutive layers at a time.
        let mut by_mesh: Vec<Option<Vec<LayerLinks>>> = (0..mended.meshes()).map(|_| None).collect();
        for (pi, p) in self.parts.iter().enumerate() {
            let mi = part_mesh[pi];
            if p.family_at.is_none() || by_mesh[mi].is_some() {
                continue;
            }
            let kept: Vec<Mutex<Option<Cut>>> = slots.iter().map(|_| Mutex::new(None)).collect();
            let pieces: Vec<Vec<LayerLinks>> = pool.install(|| {
                (0..slots.len().div_ceil(LAYERS_PER_PIECE))
                    .into_par_iter()
                    .map(|piece| {
                        let first = piece * LAYERS_PER_PIECE;
                        let end = (first + LAYERS_PER_PIECE).min(slots.len());
                        let mut links = Vec::with_capacity(end - first);
                        // A piece's first layer is kept by the piece below, as its
                        // last layer's upper neighbour (the lowest piece keeps it).
                        let mut lower = areas(mi, first, (first == 0).then(|| &kept[0]))?;
                        for k in first..end {
                            let upper = if k + 1 < slots.len() {
                                Some(areas(mi, k + 1, Some(&kept[k + 1]))?)
                            } else {
                                None
                            };
                            links.push(LayerLinks::new(&lower, upper.as_deref()));
                            if let Some(upper) = upper {
                                lower = upper;
                            }
                        }
                        Ok(links)
                    })
                    .collect::<Result<Vec<_>>>()
            })?;
            by_mesh[mi] = Some(pieces.into_iter().flatten().collect());
            cuts[mi] = Some(kept);
        }
        for (pi, p) in self.parts.iter().enumerate() {
            let Some([x, y, z]) = p.family_at else { continue };
            let mi = part_mesh[pi];
            let Some(layers) = &by_mesh[mi] else {
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
            let first = holding(&areas(mi, start, None)?, Point2::new(x, y));
            if first.is_empty() {
                let message = format!(
                    "part `{}`: no solid at family_at = [{x}, {y}, {z}] (layer {} at z = {:.4} mm has {} families)",
                    p.name,
                    start,
                    slots[start].z,
                    layers[start].inside.len()
                );
                return Err(match &p.family_at_location {
                    Some(loc) => Error::config_at(loc.clone(), message),
                    None => Error::config(message),
                });
            }
            let selected = follow_links(layers, start, first);
            samples[pi] = Some(
                selected
                    .iter()
                    .zip(layers)
                    .map(|(sel, links)| sel.iter().map(|&f| links.inside[f]).collect())
                    .collect(),
            );
        }
        Ok(Selections { samples, cuts })
    }
}
