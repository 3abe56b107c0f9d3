//! The operations of a hybrid process: what a layer takes besides deposition beads.
//!
//! The CMPM process (cmpm-process-planning §2) works each layer of a material region in
//! steps: end-mill away what overhangs where higher regions adjoin, spray the layer with
//! grinding allowances (and inclusions), grind it back, engrave the voids of a periodic
//! microstructure, fill them, grind again. Each step is an [`Operation`] on the layer's
//! plan, planned by a `[[process]]` stage (a plugin, so a third party adds its own, a
//! curing step say). Core knows the data and one rule that spans layers: a surface is
//! levelled only where nothing around it stands higher, and every layer ends at its
//! design height. The runtime checks both as the layers pass in build order.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::geom::{Point2, Polygon};
use crate::model::Sequence;
pub use crate::stage::ProcessContext;

/// One operation of a layer, in the order the machine does them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Operation {
    /// What is done: `spray`, `end-mill`, `grind`, `engrave`, `fill`, `remove-filler`,
    /// or the name a plugin gives its own.
    pub kind: String,
    /// Which pass of its kind, e.g. `rough` or `finish`; empty when there is one.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub pass: String,
    /// The material region worked on (index into the sequence's regions), if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub region: Option<usize>,
    /// The tool and how it runs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tool: Option<OperationTool>,
    /// Height of the region's surface once the operation is done (mm), when the
    /// operation sets it: a spray raises it, a grind takes it down.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub surface: Option<f64>,
    /// True when the tool levels the surface beyond the region's own area (the face of
    /// a cup wheel): every other region must then stand no higher than `surface`.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub levels: bool,
    /// Where the tool works, in order. Each path is at its own height.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub paths: Vec<OperationPath>,
    /// Numbers the operation was planned with that a reader may want (allowances,
    /// inclusion fractions, depths), by name.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub values: BTreeMap<String, f64>,
}

impl Operation {
    /// An operation of `kind` on `region`, with nothing else set.
    pub fn new(kind: impl Into<String>, region: Option<usize>) -> Self {
        Self {
            kind: kind.into(),
            pass: String::new(),
            region,
            tool: None,
            surface: None,
            levels: false,
            paths: Vec::new(),
            values: BTreeMap::new(),
        }
    }

    /// Length of all paths (mm).
    pub fn path_length(&self) -> f64 {
        self.paths.iter().map(OperationPath::length).sum()
    }
}

/// The tool of an operation and its settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OperationTool {
    /// The tool's name, which an NC exporter maps to a tool number.
    pub name: String,
    /// What kind of tool it is: `spray`, `end-mill`, `grinding-wheel`, `laser`,
    /// `dispenser`, or a plugin's own.
    pub kind: String,
    /// Diameter of what touches the work (mm): cutter, wheel, laser spot or spray spot.
    pub diameter: f64,
    /// Feed along the paths (mm/s).
    pub feed: f64,
    /// Spindle speed (rev/min) of a rotating tool.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub spindle: Option<f64>,
    /// Power (W) of a laser or a spray torch.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub power: Option<f64>,
}

/// One continuous pass of a tool at one height.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OperationPath {
    /// Height of the tool's working end (mm).
    pub z: f64,
    pub points: Vec<Point2>,
    /// True when the path returns from its last point to its first.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub closed: bool,
}

impl OperationPath {
    /// Length of the path (mm), the closing segment included.
    pub fn length(&self) -> f64 {
        let open: f64 = self.points.windows(2).map(|w| (w[1] - w[0]).norm()).sum();
        match (self.closed, self.points.first(), self.points.last()) {
            (true, Some(a), Some(b)) if self.points.len() > 2 => open + (*a - *b).norm(),
            _ => open,
        }
    }
}

/// The outline of another material region at a layer's cut height.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RegionOutline {
    /// Index into the sequence's regions.
    pub region: usize,
    /// Its surface height when the layer begins (mm).
    pub surface: f64,
    pub polygons: Vec<Polygon>,
}

/// The surface heights of the material regions before each layer of `slots`, from
/// their design heights: a layer of region `r` ends with `r`'s surface at its top.
pub fn surfaces_before(slots: &[crate::model::LayerSlot], regions: usize) -> Vec<Vec<Option<f64>>> {
    let mut now = vec![None; regions];
    let mut out = Vec::with_capacity(slots.len());
    for s in slots {
        out.push(now.clone());
        if let Some(r) = s.material_region
            && r < regions
        {
            now[r] = Some(s.z);
        }
    }
    out
}

/// Follows every region's surface through the operations of the layers, in build
/// order, and refuses a plan that levels a surface next to a higher one or leaves a
/// layer off its design height.
#[derive(Debug, Clone, Default)]
pub struct SurfaceCheck {
    surfaces: Vec<Option<f64>>,
    names: Vec<String>,
}

/// Heights closer than this are equal (mm): half a micrometre, the sequence's unit.
const HEIGHT_TOLERANCE: f64 = 5e-4;

impl SurfaceCheck {
    pub fn new(sequence: Option<&Sequence>) -> Self {
        let names: Vec<String> = sequence
            .map(|s| s.regions.iter().map(|r| r.name.clone()).collect())
            .unwrap_or_default();
        Self {
            surfaces: vec![None; names.len()],
            names,
        }
    }

    /// The current surface of every region.
    pub fn surfaces(&self) -> &[Option<f64>] {
        &self.surfaces
    }

    fn name(&self, r: usize) -> String {
        self.names.get(r).cloned().unwrap_or_else(|| format!("#{r}"))
    }

    /// Takes one layer's operations; an error names the operation and the regions. A
    /// layer whose operations leave its own region's surface alone (none of them sets
    /// it) is taken to end at its design height.
    pub fn layer(&mut self, plan: &crate::model::LayerPlan) -> Result<(), String> {
        let own = plan.material_region.filter(|&r| r < self.surfaces.len());
        let mut touched_own = false;
        for (i, op) in plan.operations.iter().enumerate() {
            let (Some(r), Some(s)) = (op.region, op.surface) else {
                continue;
            };
            if r >= self.surfaces.len() {
                return Err(format!(
                    "operation {} (`{}`) names material region {r}, the sequence has {}",
                    i + 1,
                    op.kind,
                    self.surfaces.len()
                ));
            }
            if op.levels {
                for (q, other) in self.surfaces.iter().enumerate() {
                    if q != r
                        && let Some(h) = other
                        && *h > s + HEIGHT_TOLERANCE
                    {
                        return Err(format!(
                            "operation {} (`{}`{}) levels region `{}` to {s:.3} mm while region `{}` \
                             stands at {h:.3} mm: the surface to be levelled must stand higher than \
                             the others",
                            i + 1,
                            op.kind,
                            if op.pass.is_empty() {
                                String::new()
                            } else {
                                format!(" {}", op.pass)
                            },
                            self.name(r),
                            self.name(q),
                        ));
                    }
                }
            }
            self.surfaces[r] = Some(s);
            touched_own |= Some(r) == own;
        }
        let Some(r) = own else { return Ok(()) };
        if !touched_own {
            self.surfaces[r] = Some(plan.z);
            return Ok(());
        }
        if let Some(s) = self.surfaces[r]
            && (s - plan.z).abs() > HEIGHT_TOLERANCE
        {
            return Err(format!(
                "region `{}` ends the layer at {s:.3} mm, its design height is {:.3} mm: an \
                 operation that brings it down (a finishing grind) is missing",
                self.name(r),
                plan.z
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{LayerPlan, MaterialRegion};

    fn sequence() -> Sequence {
        let region = |name: &str| MaterialRegion {
            name: name.into(),
            parts: vec![0],
            thickness_um: 200,
            z_start: 0.0,
            z_end: 1.0,
            rule: None,
        };
        Sequence {
            regions: vec![region("m"), region("f")],
            blocks: Vec::new(),
        }
    }

    fn layer(region: usize, z: f64, ops: &[(&str, f64, bool)]) -> LayerPlan {
        LayerPlan {
            index: 0,
            z,
            thickness: 0.2,
            material_region: Some(region),
            parts: Vec::new(),
            toolpaths: Vec::new(),
            build_time: None,
            sequential_time: None,
            fill: None,
            pauses: None,
            operations: ops
                .iter()
                .map(|&(kind, surface, levels)| {
                    let mut op = Operation::new(kind, Some(region));
                    op.surface = Some(surface);
                    op.levels = levels;
                    op
                })
                .collect(),
            diagnostics: Vec::new(),
        }
    }

    #[test]
    fn a_levelled_surface_may_not_lie_below_another_region() {
        let seq = sequence();
        let mut check = SurfaceCheck::new(Some(&seq));
        check
            .layer(&layer(0, 0.2, &[("spray", 0.32, false), ("grind", 0.2, true)]))
            .expect("m ground to its height");
        assert_eq!(check.surfaces(), &[Some(0.2), None]);
        // f, at 0.2 as well, is ground to 0.2: level with m, allowed.
        check
            .layer(&layer(1, 0.2, &[("spray", 0.3, false), ("grind", 0.2, true)]))
            .expect("level with m");
        // m sprayed to 0.52 and ground to 0.4, then f ground only to 0.3 would cut m.
        check
            .layer(&layer(0, 0.4, &[("spray", 0.52, false), ("grind", 0.4, true)]))
            .expect("m higher");
        let err = check
            .layer(&layer(1, 0.3, &[("spray", 0.4, false), ("grind", 0.3, true)]))
            .expect_err("f's wheel would cut m");
        assert!(
            err.contains("levels region `f` to 0.300 mm while region `m` stands at 0.400 mm"),
            "{err}"
        );
    }

    #[test]
    fn a_layer_without_operations_on_its_region_ends_at_its_height_and_counts() {
        let seq = sequence();
        let mut check = SurfaceCheck::new(Some(&seq));
        // m's layer has no operation of its own (deposited otherwise): it stands at 0.4.
        check.layer(&layer(0, 0.4, &[])).expect("no operations");
        assert_eq!(check.surfaces(), &[Some(0.4), None]);
        // So grinding f to 0.3 beside it is refused.
        let err = check
            .layer(&layer(1, 0.3, &[("spray", 0.4, false), ("grind", 0.3, true)]))
            .expect_err("m stands higher");
        assert!(err.contains("region `m` stands at 0.400 mm"), "{err}");
    }

    #[test]
    fn a_layer_must_end_at_its_design_height() {
        let seq = sequence();
        let mut check = SurfaceCheck::new(Some(&seq));
        let err = check
            .layer(&layer(0, 0.2, &[("spray", 0.32, false), ("grind", 0.22, true)]))
            .expect_err("0.02 mm high");
        assert!(
            err.contains("region `m` ends the layer at 0.220 mm, its design height is 0.200 mm"),
            "{err}"
        );
    }

    #[test]
    fn surfaces_before_each_layer_follow_the_design_heights() {
        let mut a = crate::model::LayerSlot::new(0, 0.2, 0.2, 0.1);
        a.material_region = Some(0);
        let mut b = crate::model::LayerSlot::new(1, 0.5, 0.5, 0.25);
        b.material_region = Some(1);
        let mut c = crate::model::LayerSlot::new(2, 0.4, 0.2, 0.3);
        c.material_region = Some(0);
        let s = surfaces_before(&[a, b, c], 2);
        assert_eq!(
            s,
            vec![
                vec![None, None],
                vec![Some(0.2), None],
                vec![Some(0.2), Some(0.5)]
            ]
        );
    }
}
