//! One layer through its stages: each distinct mesh cut and sorted once, each part's
//! families discretised and graded, the compositions checked, the layer planned.

use std::sync::Arc;

use super::engine::Engine;
use super::families::Selections;
use super::mend::LayerCuts;
use super::report::Timings;
use crate::diagnostic::Diagnostic;
use crate::error::{Error, Result};
use crate::geom::Polygon;
use crate::mesh::Mesh;
use crate::model::{Composition, Layer, LayerPlan, LayerSlot, PartLayer, Sequence, SubRegion};
use crate::planned::Counts;
use crate::stage::*;

/// What the cut of one mesh in one layer enclosed and what its contours kept (mm²), for
/// the run to check that each part's layers hold its volume.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Kept {
    pub(super) mesh: usize,
    /// [`Layer::section_area`].
    pub(super) section: f64,
    /// The contours' area, holes less.
    pub(super) kept: f64,
    /// Whether the slicer repaired the cut (it warned: chains dropped, joined across
    /// gaps or holes, or the layer filled from a neighbour).
    pub(super) repaired: bool,
}

impl Engine {
    /// Slices, sorts, discretises, grades and plans one layer; with the plan, what each
    /// mesh's cut kept of its section (from slicers that measure it).
    pub(super) fn process_layer(
        &self,
        slot: &LayerSlot,
        shared: &LayerShared<'_>,
    ) -> Result<(LayerPlan, Vec<Kept>)> {
        let LayerShared {
            info,
            sequence,
            prepared,
            part_mesh,
            copies,
            selections,
            timings,
            meshes: _,
            cuts,
            surfaces: _,
            layer_count: _,
            bare_info: _,
        } = *shared;
        // Each distinct mesh is cut and sorted once per layer, and its families'
        // polygons built once, for every part and stage that reads them.
        let mut cut: Vec<Option<(Layer, crate::model::ContourTree, Vec<Polygon>)>> =
            (0..prepared.len()).map(|_| None).collect();
        let mut diagnostics = Vec::new();
        let mut parts = Vec::new();
        let mut kept = Vec::new();
        // A layer of a material region deposits only that region's parts.
        let region_parts = match (slot.material_region, sequence) {
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
        let in_layer = |pi: usize| region_parts.is_none_or(|rp| rp.contains(&pi));
        // Parts still to come that read each mesh's cut: the last one takes the cut
        // into its part layer rather than copying it.
        let mut readers = vec![0usize; prepared.len()];
        for pi in (0..self.parts.len()).filter(|&pi| in_layer(pi)) {
            readers[part_mesh[pi]] += 1;
        }
        for (pi, p) in self.parts.iter().enumerate() {
            if !in_layer(pi) {
                continue;
            }
            let mi = part_mesh[pi];
            if cut[mi].is_none() {
                // The cut the `family_at` pre-pass made, else a new one.
                let (layer, tree) = match selections.take_cut(mi, slot.index) {
                    Some(made) => made,
                    None => {
                        let layer = timings
                            .time(StageKind::Slice, || cuts.of(mi, slot))
                            .map_err(|e| e.in_part(&p.name))?;
                        let tree = timings
                            .time(StageKind::Sort, || self.sorter.sort(&layer))
                            .map_err(|e| e.in_part(&p.name))?;
                        check_tree(&layer, &tree).map_err(|e| e.in_part(&p.name))?;
                        (layer, tree)
                    }
                };
                diagnostics.extend(layer.warnings.iter().map(|w| {
                    Diagnostic::from_warning(StageKind::Slice, w)
                        .at_layer(slot.index, slot.z)
                        .in_part(&p.name)
                }));
                if let Some(section) = layer.section_area {
                    kept.push(Kept {
                        mesh: mi,
                        section,
                        kept: layer.contours.iter().map(|c| c.signed_area()).sum(),
                        repaired: !layer.warnings.is_empty(),
                    });
                }
                let polygons = tree.family_polygons(&layer.contours);
                cut[mi] = Some((layer, tree, polygons));
            }
            let Some((layer, tree, polygons)) = &cut[mi] else {
                continue;
            };
            let families = selections.families(pi, slot.index, polygons, part_mesh);
            let regions = self
                .process_part(pi, layer, tree, polygons, &families, shared)
                .map_err(|e| e.in_part(&p.name))?;
            readers[mi] -= 1;
            let (contours, tree) = match readers[mi] {
                0 => match cut[mi].take() {
                    Some((layer, tree, _)) => (layer.contours, tree),
                    None => continue,
                },
                _ => (layer.contours.clone(), tree.clone()),
            };
            parts.push(PartLayer {
                part: pi,
                contours,
                tree,
                families,
                regions,
            });
            // Each copy is the part's plan moved: graded once, in the part's frame.
            let own = parts.len() - 1;
            for (k, c) in copies.iter().enumerate().filter(|(_, c)| c.of == pi) {
                let copy = super::copies::moved(&parts[own], self.parts.len() + k, c.offset);
                parts.push(copy);
            }
        }
        let mut plan = LayerPlan {
            index: slot.index,
            z: slot.z,
            thickness: slot.thickness,
            material_region: slot.material_region,
            parts,
            toolpaths: Vec::new(),
            build_time: None,
            sequential_time: None,
            fill: None,
            pauses: None,
            operations: Vec::new(),
            diagnostics,
        };
        if let Some(planner) = &self.planner {
            timings.time(StageKind::Plan, || planner.plan(info, &mut plan))?;
            checked(&plan, info, StageKind::Plan, Counts::default())?;
        }
        if !self.process.is_empty() {
            self.process_operations(slot, shared, &mut plan)?;
        }
        Ok((plan, kept))
    }

    /// Runs the `[[process]]` stages on a planned layer, in their order.
    fn process_operations(
        &self,
        slot: &LayerSlot,
        shared: &LayerShared<'_>,
        plan: &mut LayerPlan,
    ) -> Result<()> {
        let none = Vec::new();
        let surfaces = shared.surfaces.get(slot.index).unwrap_or(&none);
        let higher = if self.process.iter().any(|p| p.needs_higher()) {
            self.higher_regions(slot, surfaces, shared)?
        } else {
            Vec::new()
        };
        let ctx = crate::process::ProcessContext {
            info: shared.info,
            sequence: shared.sequence,
            surfaces,
            higher: &higher,
            last: slot.index + 1 == shared.layer_count,
        };
        for stage in &self.process {
            let before = plan.counts();
            shared
                .timings
                .time(StageKind::Process, || stage.process(&ctx, plan))?;
            checked(plan, shared.info, StageKind::Process, before)?;
        }
        Ok(())
    }

    /// The other material regions standing higher than the base of `slot`'s layer,
    /// cut at its height: where their spray may have landed on this layer's area.
    fn higher_regions(
        &self,
        slot: &LayerSlot,
        surfaces: &[Option<f64>],
        shared: &LayerShared<'_>,
    ) -> Result<Vec<crate::process::RegionOutline>> {
        let (Some(own), Some(sequence)) = (slot.material_region, shared.sequence) else {
            return Ok(Vec::new());
        };
        let base = slot.z - slot.thickness;
        let mut out = Vec::new();
        for (q, region) in sequence.regions.iter().enumerate() {
            let Some(surface) = surfaces.get(q).copied().flatten() else {
                continue;
            };
            if q == own || surface <= base + 1e-6 || slot.cut_z < region.z_start || slot.cut_z > region.z_end
            {
                continue;
            }
            let mut polygons = Vec::new();
            let mut meshes: Vec<usize> = region.parts.iter().map(|&p| shared.part_mesh[p]).collect();
            meshes.sort_unstable();
            meshes.dedup();
            for mi in meshes {
                let layer = shared
                    .timings
                    .time(StageKind::Slice, || shared.prepared[mi].slice(slot))?;
                let tree = shared
                    .timings
                    .time(StageKind::Sort, || self.sorter.sort(&layer))?;
                let own = tree.family_polygons(&layer.contours);
                // The copies of the region's parts on this mesh stand as high.
                let mut offsets: Vec<_> = shared
                    .copies
                    .iter()
                    .filter(|c| region.parts.contains(&c.of) && shared.part_mesh[c.of] == mi)
                    .map(|c| c.offset)
                    .collect();
                offsets.dedup();
                for by in offsets {
                    polygons.extend(own.iter().map(|p| super::copies::moved_polygon(p, by)));
                }
                polygons.extend(own);
            }
            out.push(crate::process::RegionOutline {
                region: q,
                surface,
                polygons,
            });
        }
        Ok(out)
    }

    pub(super) fn process_part(
        &self,
        pi: usize,
        layer: &Layer,
        tree: &crate::model::ContourTree,
        polygons: &[Polygon],
        families: &[usize],
        shared: &LayerShared<'_>,
    ) -> Result<Vec<SubRegion>> {
        let (info, timings) = (shared.info, shared.timings);
        let mesh = shared.meshes.get(shared.part_mesh[pi]).map(|m| &**m);
        let p = &self.parts[pi];
        let n_materials = p.materials.len();
        let mut regions = Vec::new();
        if families.is_empty() {
            return Ok(regions);
        }
        // One call a stage for all the part's families of the layer; the mesh and the
        // machine only to the stages that read them.
        let ctx = |reads_mesh: bool, reads_machine: bool| FamilyContext {
            info: if reads_machine { info } else { shared.bare_info },
            layer,
            tree,
            polygons,
            mesh: mesh.filter(|_| reads_mesh),
            part: pi,
            family: families[0],
        };
        let mut sets = match &p.discretiser {
            Some(d) => timings.time(StageKind::Discretise, || {
                d.discretise_families(&ctx(d.reads_mesh(), d.reads_machine()), families)
            })?,
            // Without a discretiser a family is one region, at level 0.
            None => families
                .iter()
                .map(|&f| vec![SubRegion::new(f, 0, 1, 0.0, polygons[f].clone())])
                .collect(),
        };
        if sets.len() != families.len() {
            return Err(Error::stage(
                "discretise",
                format!("{} lists of regions for {} families", sets.len(), families.len()),
            ));
        }
        match &p.grader {
            Some(g) => timings.time(StageKind::Grade, || {
                g.grade_families(&ctx(g.reads_mesh(), g.reads_machine()), families, &mut sets)
            })?,
            None => {
                // A discretiser whose regions follow the material (grading sources)
                // grades them itself; the rest are the part's first material.
                for r in sets.iter_mut().flatten().filter(|r| r.composition.is_none()) {
                    r.composition = Some(Composition::pure(0, n_materials));
                }
            }
        }
        for (&f, family_regions) in families.iter().zip(sets) {
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
        Ok(regions)
    }
}

/// What every layer of a run reads: the run's facts and what was prepared once.
#[derive(Clone, Copy)]
pub(super) struct LayerShared<'a> {
    pub(super) info: &'a RunInfo,
    /// The run without its machine: what discretisers and graders that do not read it
    /// are given (a dynamic plugin's is sent with every call).
    pub(super) bare_info: &'a RunInfo,
    /// The meshes as sliced (placed and oriented), for stages that measure in space.
    pub(super) meshes: &'a [Arc<Mesh>],
    pub(super) sequence: Option<&'a Sequence>,
    pub(super) prepared: &'a [Box<dyn MeshSlicer>],
    pub(super) part_mesh: &'a [usize],
    /// The parts' copies: copy `k` is part `parts + k`, its source's plan moved.
    pub(super) copies: &'a [super::copies::PartCopy],
    pub(super) selections: &'a Selections,
    pub(super) timings: &'a Timings,
    /// The material regions' surfaces before each layer (empty without process stages).
    pub(super) surfaces: &'a [Vec<Option<f64>>],
    /// Number of layers of the run: the last one takes what ends the job.
    pub(super) layer_count: usize,
    /// The meshes' cuts of the run's layers, mended where an open mesh leaves a
    /// layer empty.
    pub(super) cuts: &'a LayerCuts<'a>,
}

/// What a stage of `kind` added to a plan that held `before`, one a machine can follow
/// ([`LayerPlan::check_since`]), whichever stage planned it: a plugin's plan is held to
/// what the built-in planners give.
fn checked(plan: &LayerPlan, info: &RunInfo, kind: StageKind, before: Counts) -> Result<()> {
    plan.check_since(info, before).map_err(|m| {
        Error::stage(
            kind.name(),
            format!("the {kind} stage left a plan no machine can follow: {m}"),
        )
    })
}

/// A sorter's output must describe the layer it was given.
pub(super) fn check_tree(layer: &Layer, tree: &crate::model::ContourTree) -> Result<()> {
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
