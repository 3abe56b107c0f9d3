//! The data that flows between stages: layers, contour trees, sub-regions with their
//! compositions, materials and parts, blocks and work cycles, toolpaths, and the plan of
//! one layer that exporters receive.

use serde::{Deserialize, Serialize};

use crate::diagnostic::{Diagnostic, Severity};
use crate::error::{Error, Result};
use crate::geom::{Contour, Point2, Polygon};
use crate::kind::StageKind;

/// Where and how thick one layer is, before it is cut.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LayerSlot {
    /// Position in build order, from 0.
    pub index: usize,
    /// Height of the layer's top surface (mm).
    pub z: f64,
    /// Layer thickness (mm); the layer spans `z - thickness .. z`.
    pub thickness: f64,
    /// Height at which the mesh is cut for this layer (mm).
    pub cut_z: f64,
    /// The material region of the fabrication sequence this layer deposits, when the
    /// layers follow work cycles: only that region's parts are cut. `None`: every part.
    /// Written `region` in files and messages.
    #[serde(default, rename = "region", skip_serializing_if = "Option::is_none")]
    pub material_region: Option<usize>,
}

impl LayerSlot {
    /// A layer of every part: top at `z`, spanning `z - thickness .. z`, cut at `cut_z`.
    pub fn new(index: usize, z: f64, thickness: f64, cut_z: f64) -> Self {
        Self {
            index,
            z,
            thickness,
            cut_z,
            material_region: None,
        }
    }
}

/// One cut of one mesh: closed contours, outer counter-clockwise, holes clockwise.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Layer {
    pub index: usize,
    pub z: f64,
    pub thickness: f64,
    pub contours: Vec<Contour>,
    /// What the slicer repaired or dropped in this layer, for the user.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<crate::diagnostic::Warning>,
    /// The area (mm²) the layer should hold, when the slicer measures it: its
    /// contours' and that of the open chains it dropped (the area each sweeps about a
    /// fixed point, by Green's theorem, whether or not it closes). The run compares the
    /// contours' area with it and fails when a part's layers hold too little of its
    /// volume (an open mesh whose cut could not be closed). ABI 7.3; `None` from older
    /// slicers, whose layers are not checked.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub section_area: Option<f64>,
}

impl Layer {
    pub fn from_slot(slot: &LayerSlot) -> Self {
        Self {
            index: slot.index,
            z: slot.z,
            thickness: slot.thickness,
            contours: Vec::new(),
            warnings: Vec::new(),
            section_area: None,
        }
    }
}

/// A contour's place in the containment hierarchy of its layer.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ContourNode {
    /// Index into the layer's contours.
    pub contour: usize,
    /// Nesting depth: 0 for outermost contours; even levels bound material from outside,
    /// odd levels are holes.
    pub level: usize,
    pub parent: Option<usize>,
    pub children: Vec<usize>,
}

/// One solid area: a contour at an even level and its direct children (its holes).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Family {
    pub outer: usize,
    pub holes: Vec<usize>,
}

/// The containment hierarchy of a layer's contours. `nodes[i]` describes contour `i`.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct ContourTree {
    pub nodes: Vec<ContourNode>,
    pub families: Vec<Family>,
}

impl ContourTree {
    /// The polygon of family `f` built from the layer's contours: a copy of them,
    /// outer counter-clockwise and holes clockwise. Stages that work on a family read
    /// [`crate::stage::FamilyContext::polygon`], built once a layer, instead.
    pub fn family_polygon(&self, contours: &[Contour], f: usize) -> Polygon {
        let fam = &self.families[f];
        Polygon::new(
            contours[fam.outer].clone().oriented(true),
            fam.holes
                .iter()
                .map(|&h| contours[h].clone().oriented(false))
                .collect(),
        )
    }

    /// The polygon of every family, in order: what a layer's discretisers and graders
    /// share ([`crate::stage::FamilyContext::polygons`]).
    pub fn family_polygons(&self, contours: &[Contour]) -> Vec<Polygon> {
        (0..self.families.len())
            .map(|f| self.family_polygon(contours, f))
            .collect()
    }

    /// The area (mm²) of family `f`: its outer contour's less its holes', read from the
    /// contours without building the polygon.
    pub fn family_area(&self, contours: &[Contour], f: usize) -> f64 {
        let fam = &self.families[f];
        contours[fam.outer].area() - fam.holes.iter().map(|&h| contours[h].area()).sum::<f64>()
    }

    /// Contours with no parent.
    pub fn roots(&self) -> impl Iterator<Item = usize> + '_ {
        self.nodes
            .iter()
            .enumerate()
            .filter(|(_, n)| n.parent.is_none())
            .map(|(i, _)| i)
    }
}

/// A sub-region of constant material inside one family.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SubRegion {
    /// Family index in the layer's contour tree.
    pub family: usize,
    /// Order from the grading reference outward-in: 0, 1, ..., n-1.
    pub index: usize,
    /// Number of sub-regions the family was divided into (N_R).
    pub count: usize,
    /// Normalised level r in [0, 1]: 0 at the grading reference, 1 at the far end.
    pub level: f64,
    pub polygon: Polygon,
    /// Circumferential cell index when the region is split along its length.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cell: Option<usize>,
    /// Reference point for graders that vary with position (cell centre, centroid).
    pub reference: Point2,
    /// The material composition, once graded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub composition: Option<Composition>,
    /// Compositions at points of the region, from graders that grade at points
    /// (Eq. 18 at a point, not one r for the region): what a mixing head can follow
    /// along a bead. Empty when the region has one composition throughout.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub samples: Vec<Sample>,
}

/// The composition at one point of a sub-region.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Sample {
    pub at: Point2,
    pub composition: Composition,
}

impl SubRegion {
    /// Region `index` of `count` of family `family`, at `level`, not yet graded, with
    /// its reference point by the one rule every stage uses
    /// ([`lamina_geom::reference::reference_point`]): the same polygon gets the same
    /// point whichever stage cut it.
    pub fn new(family: usize, index: usize, count: usize, level: f64, polygon: crate::geom::Polygon) -> Self {
        Self {
            family,
            index,
            count,
            level,
            reference: lamina_geom::reference::reference_point(&polygon),
            polygon,
            cell: None,
            composition: None,
            samples: Vec::new(),
        }
    }

    pub fn area(&self) -> f64 {
        self.polygon.area()
    }
}

/// Tolerance for a composition's sum.
pub const COMPOSITION_TOLERANCE: f64 = 1e-9;

/// Volume fractions over the part's primary materials (same order), each in [0, 1],
/// summing to 1.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Composition {
    pub fractions: Vec<f64>,
}

impl Composition {
    /// Checks that every fraction lies in [0, 1] and that they sum to 1 (1e-9).
    pub fn new(fractions: Vec<f64>) -> Result<Self> {
        Self::check(&fractions)?;
        Ok(Self { fractions })
    }

    /// A pure material `i` of `n`.
    pub fn pure(i: usize, n: usize) -> Self {
        let mut fractions = vec![0.0; n];
        if let Some(f) = fractions.get_mut(i) {
            *f = 1.0;
        }
        Self { fractions }
    }

    /// Two materials: `f` of the first and `1 - f` of the second.
    pub fn binary(f: f64) -> Result<Self> {
        Self::new(vec![f, 1.0 - f])
    }

    pub fn check(fractions: &[f64]) -> Result<()> {
        if fractions.is_empty() {
            return Err(Error::Composition("no fractions".into()));
        }
        for (i, &f) in fractions.iter().enumerate() {
            if !f.is_finite() || !(-COMPOSITION_TOLERANCE..=1.0 + COMPOSITION_TOLERANCE).contains(&f) {
                return Err(Error::Composition(format!(
                    "fraction {i} is {f}, outside [0, 1] (fractions {fractions:?})"
                )));
            }
        }
        let sum: f64 = fractions.iter().sum();
        if (sum - 1.0).abs() > COMPOSITION_TOLERANCE {
            return Err(Error::Composition(format!(
                "fractions {fractions:?} sum to {sum}, not 1"
            )));
        }
        Ok(())
    }

    /// The fraction-weighted blend of the materials' property colours (Eq. 13 of the
    /// topological-hierarchy paper), in the paper's form: the last material's colour
    /// plus the other materials' fractions times their difference from it, that sum
    /// rounded half away from zero. This is what gives the paper's gear table
    /// ([43, 212, 0] at a sixth red: 42.5 rounds up to 43 and 255 - 42.5 down to 212),
    /// and the channels of a two-material blend always add back up to the pure colours.
    pub fn colour(&self, materials: &[Material]) -> [u8; 3] {
        let n = self.fractions.len().min(materials.len());
        let Some(last) = n.checked_sub(1).map(|i| &materials[i]) else {
            return [0; 3];
        };
        let mut rgb = [0u8; 3];
        for (c, out) in rgb.iter_mut().enumerate() {
            let base = f64::from(last.colour[c]);
            let delta: f64 = self.fractions[..n - 1]
                .iter()
                .zip(materials)
                .map(|(f, m)| f * (f64::from(m.colour[c]) - base))
                .sum();
            *out = (base + delta.round()).clamp(0.0, 255.0) as u8;
        }
        rgb
    }
}

/// A primary material.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Material {
    pub name: String,
    /// Property colour used in previews and in the modified CLI file.
    pub colour: [u8; 3],
    /// Preferred layer thickness (mm), for per-material layer thickness.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub layer_thickness: Option<f64>,
}

/// A part of the object: one mesh (or one family of a mesh), its materials (indices into
/// the pipeline's materials) and how it is graded.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PartInfo {
    pub name: String,
    /// Indices into the pipeline's materials, in the order compositions use.
    pub materials: Vec<usize>,
    /// Index of the part's mesh among the loaded meshes.
    pub mesh: usize,
    /// Height range of the part's mesh (mm).
    pub z_min: f64,
    pub z_max: f64,
    /// The largest change of a material's fraction per mm of height, sampled from the
    /// part's grading, when a sequencer asked for it (`Sequencer::needs_gradients`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub z_gradient: Option<f64>,
}

/// A region of the object that wants its own layer thickness (a periodic
/// microstructure, an FGM, a composite): one or more parts deposited together.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MaterialRegion {
    pub name: String,
    /// The parts (indices into the run's parts) this region deposits.
    pub parts: Vec<usize>,
    /// Layer thickness in integer micrometres: work cycles are least common multiples,
    /// which only exact arithmetic gets right.
    pub thickness_um: u64,
    /// Height range of the region (mm, rounded to whole micrometres).
    pub z_start: f64,
    pub z_end: f64,
    /// How the thickness was chosen, when the sequencer derived it (`auto`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rule: Option<String>,
}

/// A slab of the object between two cutting planes, holding whole material regions.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Block {
    pub z_start: f64,
    pub z_end: f64,
    /// Material regions present in the block (indices into the sequence's regions).
    pub regions: Vec<usize>,
    /// The repeating unit of the block's deposition.
    pub cycle: WorkCycle,
    /// Every deposition step of the block in build order, heights measured from
    /// `z_start`: the cycle repeated up to the block's top, where each region's last
    /// layer is trimmed so that it ends exactly there.
    pub steps: Vec<CycleStep>,
}

/// The repeating unit of deposition in a block: its height is the least common multiple
/// of the thicknesses present.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WorkCycle {
    pub height_um: u64,
    /// One step per height at which something is deposited (the worktable moves down
    /// between steps).
    pub steps: Vec<CycleStep>,
}

/// One step of a work cycle: at `height_um` above the base, one layer of each listed
/// region is deposited, one after another in the listed order.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct CycleStep {
    pub height_um: u64,
    pub deposits: Vec<Deposit>,
}

/// One layer of one material region within a step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Deposit {
    /// Index into the sequence's regions.
    pub region: usize,
    /// Thickness of this layer in micrometres; the region's own thickness except for a
    /// trimmed last layer.
    pub thickness_um: u64,
}

/// The fabrication sequence of the object: its material regions and the blocks, in
/// build order.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Sequence {
    pub regions: Vec<MaterialRegion>,
    pub blocks: Vec<Block>,
}

impl Sequence {
    /// Every layer the sequence deposits, in build order: one slot per deposit, cut at
    /// mid-layer, restricted to the deposit's region.
    pub fn slots(&self) -> Vec<LayerSlot> {
        let mut slots = Vec::new();
        for block in &self.blocks {
            for step in &block.steps {
                let z = block.z_start + um_to_mm(step.height_um);
                for d in &step.deposits {
                    let t = um_to_mm(d.thickness_um);
                    slots.push(LayerSlot {
                        index: slots.len(),
                        z,
                        thickness: t,
                        cut_z: z - t / 2.0,
                        material_region: Some(d.region),
                    });
                }
            }
        }
        slots
    }
}

/// Micrometres to millimetres.
pub fn um_to_mm(um: u64) -> f64 {
    um as f64 / 1000.0
}

/// The build direction chosen for the object and what it was weighed against.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Orientation {
    /// What was minimised, e.g. `surface-angle` or `height`.
    pub criterion: String,
    /// The chosen build direction in the model's own coordinates (a unit vector): it
    /// becomes +z.
    pub direction: [f64; 3],
    /// Row-major rotation applied to every vertex (maps `direction` to +z).
    pub rotation: [[f64; 3]; 3],
    /// Every candidate weighed, best first.
    pub candidates: Vec<OrientationCandidate>,
}

/// A rigid move from the model's own coordinates to the build's: `build = rotation ·
/// model + offset`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ModelFrame {
    /// Row-major.
    pub rotation: [[f64; 3]; 3],
    pub offset: [f64; 3],
}

/// One build direction an orienter weighed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OrientationCandidate {
    /// Unit vector in the model's coordinates.
    pub direction: [f64; 3],
    /// Where the candidate came from (`+z`, `face 3`, `sample 17`).
    pub label: String,
    /// The criterion's value (lower is better).
    pub cost: f64,
    /// Build height along the direction (mm).
    pub height: f64,
    /// Sum over facets of area x the angle between facet and build direction (mm² rad).
    pub surface_angle: f64,
}

/// A tool: one per material or per mixture on a mixing head.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Tool {
    pub index: usize,
    pub name: String,
    /// Materials this tool deposits (indices into the pipeline's materials).
    pub materials: Vec<usize>,
}

/// A point of a timed path.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TimedPoint {
    pub p: Point2,
    /// Seconds from the start of the layer.
    pub t: f64,
}

/// What a path segment does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PathKind {
    Extrude,
    Travel,
    Pause,
}

/// One continuous move of one tool in a layer.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Toolpath {
    /// The tool that moves: an index into the planner's tools (one per material on a
    /// tool changer or independent heads; the one tool of a mixing head).
    pub tool: usize,
    pub kind: PathKind,
    pub points: Vec<TimedPoint>,
    /// Extrusion width (mm); 0 for travel. The width of every segment unless
    /// `widths` says otherwise.
    pub width: f64,
    /// Width of each segment (`points[i]` to `points[i + 1]`) of a variable-width bead,
    /// whose width follows the local width of what it fills; empty when every segment
    /// has `width`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub widths: Vec<f64>,
    /// Composition deposited along the path (over the part's materials), if extruding.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub composition: Option<Composition>,
    /// Part and sub-region (index into the part layer's `regions`) the path fills, if
    /// any. The sub-region keeps the name `region` on the wire, which plugins of ABI
    /// 7.0 to 7.2 read; files write `sub_region`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub part: Option<usize>,
    #[serde(default, rename = "region", skip_serializing_if = "Option::is_none")]
    pub sub_region: Option<usize>,
    /// The run's material (index into `RunInfo::materials`) that the path's tool
    /// carries, when it is a single-material tool: the machine moves the head loaded
    /// with it, whatever the planner numbered its tools. `None` for a mixing head
    /// (`composition` says what it lays) and from planners older than ABI 7.3, whose
    /// tool `i` carried material `i`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub material: Option<usize>,
}

impl Toolpath {
    pub fn length(&self) -> f64 {
        self.points.windows(2).map(|w| (w[1].p - w[0].p).norm()).sum()
    }

    /// The width of segment `i` (from `points[i]` to `points[i + 1]`).
    pub fn segment_width(&self, i: usize) -> f64 {
        self.widths.get(i).copied().unwrap_or(self.width)
    }

    /// The area the path's bead covers (mm²): each segment's length times its width.
    pub fn bead_area(&self) -> f64 {
        if self.kind != PathKind::Extrude {
            return 0.0;
        }
        self.points
            .windows(2)
            .enumerate()
            .map(|(i, w)| (w[1].p - w[0].p).norm() * self.segment_width(i))
            .sum()
    }
}

/// One part's share of a layer.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PartLayer {
    pub part: usize,
    pub contours: Vec<Contour>,
    pub tree: ContourTree,
    /// Families of the tree that belong to this part (all, unless selected by point).
    pub families: Vec<usize>,
    pub regions: Vec<SubRegion>,
}

/// Everything planned for one layer: what exporters receive, in build order.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LayerPlan {
    pub index: usize,
    pub z: f64,
    pub thickness: f64,
    /// The material region this layer deposits when the layers follow work cycles
    /// (written `region` in files).
    #[serde(default, rename = "region", skip_serializing_if = "Option::is_none")]
    pub material_region: Option<usize>,
    pub parts: Vec<PartLayer>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub toolpaths: Vec<Toolpath>,
    /// Build time of the layer in seconds, when planned.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub build_time: Option<f64>,
    /// Build time of the layer with one tool at a time (s), when a planner that works
    /// tools concurrently also timed that baseline.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sequential_time: Option<f64>,
    /// How much of the layer's sub-regions the planned beads fill, when planned.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fill: Option<Fill>,
    /// Why the tools of a concurrent schedule paused, when one was planned and kept.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pauses: Option<Pauses>,
    /// The operations of a hybrid process on this layer, in the machine's order
    /// (`[[process]]` stages).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub operations: Vec<crate::process::Operation>,
    /// What the layer's stages repaired, dropped or want said, each with its place.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub diagnostics: Vec<Diagnostic>,
}

impl LayerPlan {
    /// Records a warning of `stage` about this layer, of kind `code` (see
    /// [`Diagnostic::code`]).
    pub fn warn(&mut self, stage: StageKind, code: &str, message: impl Into<String>) {
        self.say(Severity::Warning, stage, code, message);
    }

    /// Records a note of `stage` about this layer: information, nothing wrong.
    pub fn note(&mut self, stage: StageKind, code: &str, message: impl Into<String>) {
        self.say(Severity::Note, stage, code, message);
    }

    fn say(&mut self, severity: Severity, stage: StageKind, code: &str, message: impl Into<String>) {
        let d = Diagnostic::new(severity, stage, code, message).at_layer(self.index, self.z);
        self.diagnostics.push(d);
    }
}

/// The area a planner was given to fill in a layer and the area its beads cover
/// (length x width of every extrusion), with the least share the run must reach over
/// all its layers: an under-filled part fails the run rather than leaving quietly.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Fill {
    /// Sub-regions' area (mm²).
    pub area: f64,
    /// Beads' area (mm²).
    pub deposited: f64,
    /// Least deposited / area over the whole run (volumes, layer thickness weighted).
    pub min_ratio: f64,
}

/// The pauses of a concurrent schedule by what decided them, so that a reader can
/// check the schedule against its priority rule: of two moving tools heading for a
/// collision where either pause would keep them apart, the paper's rule (Choi and
/// Zhu) pauses the one slower along X. Every pause that starts is counted once.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Pauses {
    /// Either tool's pause would have cleared the way and the one slower along X
    /// paused (on a tie, the later one).
    pub by_x_speed: usize,
    /// Only this tool's pause cleared the way: the other's would not have (it was
    /// ahead, or already paused), or neither alone would and both paused.
    pub forced: usize,
    /// Decided by another rule than X speed (a `priority` other than `x-speed`):
    /// breaks of the paper's rule.
    pub other: usize,
}

impl Pauses {
    pub fn total(&self) -> usize {
        self.by_x_speed + self.forced + self.other
    }

    pub fn add(&mut self, o: &Pauses) {
        self.by_x_speed += o.by_x_speed;
        self.forced += o.forced;
        self.other += o.other;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mat(name: &str, colour: [u8; 3]) -> Material {
        Material {
            name: name.into(),
            colour,
            layer_thickness: None,
        }
    }

    #[test]
    fn composition_checks_bounds_and_sum() {
        assert!(Composition::new(vec![0.25, 0.75]).is_ok());
        assert!(Composition::new(vec![0.5, 0.4]).is_err());
        assert!(Composition::new(vec![1.5, -0.5]).is_err());
        assert!(Composition::new(vec![f64::NAN, 1.0]).is_err());
        assert!(Composition::new(vec![]).is_err());
    }

    /// topological-hierarchy-fgm, Fig. 3: gear layers 4..10 graded linearly from green
    /// to red along Z (f_red = r_i, f_green = 1 - r_i).
    #[test]
    fn gear_colour_table_of_the_paper() {
        let m = [mat("red", [255, 0, 0]), mat("green", [0, 255, 0])];
        let expected = [
            [0, 255, 0],
            [43, 212, 0],
            [85, 170, 0],
            [128, 127, 0],
            [170, 85, 0],
            [213, 42, 0],
            [255, 0, 0],
        ];
        for (i, e) in expected.iter().enumerate() {
            let r = i as f64 / 6.0;
            let c = Composition::new(vec![r, 1.0 - r]).expect("valid");
            assert_eq!(c.colour(&m), *e, "layer {}", i + 4);
        }
    }

    /// topological-hierarchy-fgm, Eq. 20-21: ten sub-regions from green to black.
    #[test]
    fn ten_sub_regions_green_to_black() {
        let m = [mat("green", [0, 255, 0]), mat("black", [0, 0, 0])];
        let greens: Vec<u8> = (0..10)
            .map(|j| {
                let f = 1.0 - j as f64 / 9.0;
                Composition::new(vec![f, 1.0 - f]).expect("valid").colour(&m)[1]
            })
            .collect();
        assert_eq!(greens, [255, 227, 198, 170, 142, 113, 85, 57, 28, 0]);
    }

    #[test]
    fn colour_of_three_materials_blends_all() {
        let m = [
            mat("red", [255, 0, 0]),
            mat("green", [0, 255, 0]),
            mat("blue", [0, 0, 255]),
        ];
        let c = Composition::new(vec![0.25, 0.25, 0.5]).expect("valid");
        assert_eq!(c.colour(&m), [64, 64, 127], "255 - 127.5 rounds to 127");
    }

    #[test]
    fn colour_is_fraction_weighted_blend() {
        let m = [mat("red", [255, 0, 0]), mat("green", [0, 255, 0])];
        let c = Composition::binary(0.5).expect("valid");
        assert_eq!(c.colour(&m), [128, 127, 0], "the paper's layer 7");
        assert_eq!(Composition::pure(1, 2).colour(&m), [0, 255, 0]);
        assert_eq!(Composition::pure(0, 2).colour(&m), [255, 0, 0]);
    }
}
