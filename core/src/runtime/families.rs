//! Parts that share a mesh and pick their solid with `family_at`: the family holding
//! the point in the layer at its height, then, layer by layer upward and downward, the
//! families overlapping those picked in the layer before.

use rayon::prelude::*;

use super::engine::Engine;
use super::layer::check_tree;
use super::report::Timings;
use crate::error::{Error, Result};
use crate::geom::Point2;
use crate::model::{Layer, LayerSlot};
use crate::stage::{MeshSlicer, StageKind};

/// Which families of each layer belong to parts that select theirs with `family_at`:
/// per part, per layer, one sample point inside each selected family.
pub(super) struct Selections {
    /// `None` for parts without `family_at`.
    samples: Vec<Option<Vec<Vec<Point2>>>>,
}

impl Selections {
    /// The families of `layer` that belong to part `pi`.
    pub(super) fn families(
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
    pub(super) fn select_families(
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
