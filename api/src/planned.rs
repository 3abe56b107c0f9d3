//! What a planned layer must be, whoever planned it: the runtime checks every plan a
//! planner or a `[[process]]` stage hands back, built-in or loaded from a plugin, before
//! an exporter writes a machine file from it. A path at NaN, a bead of negative width
//! or a tool the machine does not have would otherwise reach the machine.

use crate::limits::is_coordinate;
use crate::model::{Composition, LayerPlan, Toolpath};
use crate::process::Operation;
use crate::stage::RunInfo;

/// What a planner or a process stage added to a layer's plan, and the layer's timings
/// and fill as it left them: all a stage may change. The plugin boundary carries this
/// back rather than the whole layer, so the layer's contours and regions stay the
/// host's.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PlanDelta {
    #[serde(default)]
    pub toolpaths: Vec<Toolpath>,
    #[serde(default)]
    pub operations: Vec<Operation>,
    #[serde(default)]
    pub diagnostics: Vec<crate::diagnostic::Diagnostic>,
    #[serde(default)]
    pub build_time: Option<f64>,
    #[serde(default)]
    pub sequential_time: Option<f64>,
    #[serde(default)]
    pub fill: Option<crate::model::Fill>,
    #[serde(default)]
    pub pauses: Option<crate::model::Pauses>,
}

impl PlanDelta {
    /// What `plan` holds beyond the first `toolpaths`, `operations` and `diagnostics`
    /// it had before the stage ran, taken out of it.
    pub fn taken(plan: &mut LayerPlan, before: Counts) -> Self {
        fn tail<T>(v: &mut Vec<T>, from: usize) -> Vec<T> {
            v.split_off(from.min(v.len()))
        }
        Self {
            toolpaths: tail(&mut plan.toolpaths, before.toolpaths),
            operations: tail(&mut plan.operations, before.operations),
            diagnostics: tail(&mut plan.diagnostics, before.diagnostics),
            build_time: plan.build_time,
            sequential_time: plan.sequential_time,
            fill: plan.fill,
            pauses: plan.pauses,
        }
    }

    /// Adds what a stage planned to the host's copy of the layer.
    pub fn apply(self, plan: &mut LayerPlan) {
        plan.toolpaths.extend(self.toolpaths);
        plan.operations.extend(self.operations);
        plan.diagnostics.extend(self.diagnostics);
        plan.build_time = self.build_time;
        plan.sequential_time = self.sequential_time;
        plan.fill = self.fill;
        plan.pauses = self.pauses;
    }
}

/// How many toolpaths, operations and diagnostics a plan held.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Counts {
    pub toolpaths: usize,
    pub operations: usize,
    pub diagnostics: usize,
}

impl LayerPlan {
    /// How many toolpaths, operations and diagnostics this plan holds.
    pub fn counts(&self) -> Counts {
        Counts {
            toolpaths: self.toolpaths.len(),
            operations: self.operations.len(),
            diagnostics: self.diagnostics.len(),
        }
    }

    /// Checks what the stages planned on this layer: every point a finite coordinate
    /// (and every time finite and in order), widths finite and not negative, one width
    /// per segment when widths vary, compositions valid over their part's materials,
    /// parts and sub-regions that exist, tools the machine has; operations at finite
    /// places with finite tools and values; timings and fill finite.
    pub fn check(&self, info: &RunInfo) -> std::result::Result<(), String> {
        self.check_since(info, Counts::default())
    }

    /// [`check`](Self::check) of what a stage added to a plan that held `before`: the
    /// toolpaths and operations past those, and the timings and fill.
    pub fn check_since(&self, info: &RunInfo, before: Counts) -> std::result::Result<(), String> {
        let fail = Err;
        let tools = info
            .machine
            .as_ref()
            .map(|m| m.tools.len())
            .unwrap_or(0)
            .max(info.materials.len())
            .max(1);
        for (i, path) in self.toolpaths.iter().enumerate().skip(before.toolpaths) {
            if let Err(why) = self.check_path(path, info, tools) {
                return fail(format!("toolpath {i}: {why}"));
            }
        }
        for (i, op) in self.operations.iter().enumerate().skip(before.operations) {
            if let Err(why) = check_operation(op) {
                return fail(format!("operation {i} (`{}`): {why}", op.kind));
            }
        }
        for (name, v) in [
            ("build time", self.build_time),
            ("sequential time", self.sequential_time),
        ] {
            if let Some(v) = v
                && !(v.is_finite() && v >= 0.0)
            {
                return fail(format!("its {name} is {v} s"));
            }
        }
        if let Some(f) = &self.fill
            && ![f.area, f.deposited, f.min_ratio]
                .iter()
                .all(|v| v.is_finite() && *v >= 0.0)
        {
            return fail(format!("its fill is {f:?}"));
        }
        Ok(())
    }

    fn check_path(&self, path: &Toolpath, info: &RunInfo, tools: usize) -> std::result::Result<(), String> {
        if path.tool >= tools {
            return Err(format!("tool {} of {tools}", path.tool));
        }
        if let Some(m) = path.material
            && m >= info.materials.len()
        {
            return Err(format!("material {m} of {}", info.materials.len()));
        }
        let mut last_t = f64::NEG_INFINITY;
        for (j, p) in path.points.iter().enumerate() {
            if !(is_coordinate(p.p.x) && is_coordinate(p.p.y)) {
                return Err(format!("point {j} at ({}, {})", p.p.x, p.p.y));
            }
            if !p.t.is_finite() || p.t < last_t {
                return Err(format!("point {j} at time {} s, after {last_t} s", p.t));
            }
            last_t = p.t;
        }
        let segments = path.points.len().saturating_sub(1);
        if !path.widths.is_empty() && path.widths.len() != segments {
            return Err(format!("{} widths for {segments} segments", path.widths.len()));
        }
        if let Some(w) = std::iter::once(&path.width)
            .chain(&path.widths)
            .find(|w| !(w.is_finite() && **w >= 0.0 && **w <= crate::limits::MAX_COORDINATE))
        {
            return Err(format!("width {w} mm"));
        }
        let part = match path.part {
            Some(p) => match self.parts.iter().find(|l| l.part == p) {
                Some(l) => Some(l),
                None => return Err(format!("part {p}, which this layer does not hold")),
            },
            None => None,
        };
        if let (Some(r), Some(l)) = (path.sub_region, part)
            && r >= l.regions.len()
        {
            return Err(format!("sub-region {r} of {}", l.regions.len()));
        }
        if let Some(c) = &path.composition {
            let materials = path
                .part
                .and_then(|p| info.parts.get(p))
                .map(|p| p.materials.len());
            check_composition(c, materials)?;
        }
        Ok(())
    }
}

fn check_composition(c: &Composition, materials: Option<usize>) -> std::result::Result<(), String> {
    Composition::check(&c.fractions).map_err(|e| e.to_string())?;
    match materials {
        Some(n) if n > 0 && c.fractions.len() != n => Err(format!(
            "a composition of {} fractions for {n} materials",
            c.fractions.len()
        )),
        _ => Ok(()),
    }
}

fn check_operation(op: &Operation) -> std::result::Result<(), String> {
    for (k, path) in op.paths.iter().enumerate() {
        if !is_coordinate(path.z) {
            return Err(format!("path {k} at z = {}", path.z));
        }
        if let Some(p) = path
            .points
            .iter()
            .find(|p| !(is_coordinate(p.x) && is_coordinate(p.y)))
        {
            return Err(format!("path {k} has a point at ({}, {})", p.x, p.y));
        }
    }
    if let Some(t) = &op.tool {
        let numbers = [Some(t.diameter), Some(t.feed), t.spindle, t.power];
        if let Some(v) = numbers
            .into_iter()
            .flatten()
            .find(|v| !(v.is_finite() && *v >= 0.0))
        {
            return Err(format!(
                "tool `{}` has {v} among its diameter, feed, spindle and power",
                t.name
            ));
        }
    }
    if let Some(s) = op.surface
        && !is_coordinate(s)
    {
        return Err(format!("surface at {s} mm"));
    }
    if let Some((k, v)) = op.values.iter().find(|(_, v)| !v.is_finite()) {
        return Err(format!("value `{k}` = {v}"));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use std::path::PathBuf;

    use super::*;
    use crate::geom::{BBox2, Point2};
    use crate::model::{ContourTree, Fill, Material, PartInfo, PartLayer, PathKind, TimedPoint};
    use crate::process::OperationPath;

    fn info() -> RunInfo {
        let material = |name: &str| Material {
            name: name.into(),
            colour: [0, 0, 0],
            layer_thickness: None,
        };
        RunInfo {
            base_dir: PathBuf::from("."),
            materials: vec![material("a"), material("b")],
            parts: vec![PartInfo {
                name: "p".into(),
                materials: vec![0, 1],
                mesh: 0,
                z_min: 0.0,
                z_max: 1.0,
                z_gradient: None,
            }],
            z_min: 0.0,
            z_max: 1.0,
            xy_bounds: BBox2::EMPTY,
            machine: None,
            model_frame: None,
        }
    }

    fn bead() -> Toolpath {
        Toolpath {
            tool: 1,
            material: None,
            kind: PathKind::Extrude,
            points: [(0.0, 0.0, 0.0), (10.0, 0.0, 0.5), (10.0, 5.0, 0.75)]
                .map(|(x, y, t)| TimedPoint {
                    p: Point2::new(x, y),
                    t,
                })
                .to_vec(),
            width: 0.45,
            widths: Vec::new(),
            composition: Some(Composition {
                fractions: vec![0.25, 0.75],
            }),
            part: Some(0),
            sub_region: None,
        }
    }

    fn plan(paths: Vec<Toolpath>) -> LayerPlan {
        LayerPlan {
            index: 3,
            z: 0.6,
            thickness: 0.2,
            material_region: None,
            parts: vec![PartLayer {
                part: 0,
                contours: Vec::new(),
                tree: ContourTree::default(),
                families: Vec::new(),
                regions: Vec::new(),
            }],
            toolpaths: paths,
            build_time: Some(0.75),
            sequential_time: None,
            fill: None,
            pauses: None,
            operations: Vec::new(),
            diagnostics: Vec::new(),
        }
    }

    fn refused(p: Toolpath) -> String {
        plan(vec![bead(), p]).check(&info()).expect_err("refused")
    }

    #[test]
    fn what_a_machine_cannot_follow_is_refused_naming_the_path() {
        plan(vec![bead()]).check(&info()).expect("a sound bead");
        let mut p = bead();
        p.points[1].p.x = f64::NAN;
        assert!(refused(p).starts_with("toolpath 1: point 1 at (NaN"));
        let mut p = bead();
        p.points[2].t = 0.25;
        assert!(refused(p).contains("point 2 at time 0.25 s"));
        let mut p = bead();
        p.tool = 2;
        assert!(refused(p).contains("tool 2 of 2"));
        let mut p = bead();
        p.material = Some(1);
        plan(vec![p.clone()]).check(&info()).expect("the second material");
        p.material = Some(2);
        assert!(refused(p).contains("material 2 of 2"));
        let mut p = bead();
        p.widths = vec![0.4];
        assert!(refused(p).contains("1 widths for 2 segments"));
        let mut p = bead();
        p.width = -0.1;
        assert!(refused(p).contains("width -0.1 mm"));
        let mut p = bead();
        p.composition = Some(Composition {
            fractions: vec![0.5, 0.6],
        });
        assert!(refused(p).contains("composition"));
        let mut p = bead();
        p.composition = Some(Composition { fractions: vec![1.0] });
        assert!(refused(p).contains("1 fractions for 2 materials"));
        let mut p = bead();
        p.part = Some(4);
        assert!(refused(p).contains("part 4, which this layer does not hold"));
        let mut p = bead();
        p.sub_region = Some(0);
        assert!(refused(p).contains("sub-region 0 of 0"));
        // A later stage is held to what it added, not to what came before it.
        let mut p = bead();
        p.tool = 7;
        let earlier = plan(vec![p]);
        let before = earlier.counts();
        earlier.check_since(&info(), before).expect("nothing added");
        assert!(earlier.check_since(&info(), Counts::default()).is_err());
        let mut bad = plan(vec![bead()]);
        bad.build_time = Some(f64::INFINITY);
        assert!(bad.check(&info()).expect_err("refused").contains("build time"));
        // A point may come at the same time as the one before it (a corner taken at
        // once), not earlier.
        let mut p = bead();
        p.points[2].t = p.points[1].t;
        plan(vec![p]).check(&info()).expect("simultaneous points");
    }

    /// Timings and fill: finite and not negative, zero included.
    #[test]
    fn timings_and_fill_must_be_finite_and_not_negative() {
        let with = |build: Option<f64>, sequential: Option<f64>, fill: Option<Fill>| {
            let mut p = plan(vec![bead()]);
            p.build_time = build;
            p.sequential_time = sequential;
            p.fill = fill;
            p.check(&info())
        };
        let fill = |area: f64, deposited: f64, min_ratio: f64| {
            Some(Fill {
                area,
                deposited,
                min_ratio,
            })
        };
        with(Some(0.0), Some(0.0), fill(0.0, 0.0, 0.0)).expect("zeros");
        with(None, None, None).expect("nothing said");
        with(Some(2.0), Some(3.0), fill(10.0, 9.9, 0.99)).expect("a layer");
        for (build, sequential, says) in [
            (Some(-1.0), None, "its build time is -1 s"),
            (Some(f64::NAN), None, "its build time is NaN s"),
            (None, Some(-0.5), "its sequential time is -0.5 s"),
            (Some(1.0), Some(f64::INFINITY), "its sequential time is inf s"),
        ] {
            let e = with(build, sequential, None).expect_err("refused");
            assert_eq!(e, says);
        }
        for f in [
            fill(-1.0, 1.0, 1.0),
            fill(1.0, f64::NAN, 1.0),
            fill(1.0, 1.0, -0.1),
            fill(f64::INFINITY, 1.0, 1.0),
        ] {
            let e = with(None, None, f).expect_err("refused");
            assert!(e.starts_with("its fill is Fill"), "{e}");
        }
    }

    #[test]
    fn operations_must_lie_at_finite_places() {
        let mut p = plan(Vec::new());
        let mut op = Operation::new("mill", None);
        op.paths.push(OperationPath {
            z: 1.0,
            points: vec![Point2::new(0.0, 0.0), Point2::new(1.0, 2e6)],
            closed: false,
        });
        p.operations.push(op);
        let e = p.check(&info()).expect_err("refused");
        assert!(
            e.contains("operation 0 (`mill`): path 0 has a point at (1, 2000000)"),
            "{e}"
        );
        // Its tool's numbers finite and not negative (zero allowed), its surface and
        // values finite, its paths at finite heights.
        let checked = |change: &dyn Fn(&mut Operation)| {
            let mut op = Operation::new("mill", None);
            op.tool = Some(crate::process::OperationTool {
                name: "end-mill".into(),
                kind: "end-mill".into(),
                diameter: 2.0,
                feed: 0.0,
                spindle: Some(0.0),
                power: None,
            });
            op.surface = Some(1.5);
            op.values.insert("depth".into(), -0.2);
            change(&mut op);
            let mut p = plan(Vec::new());
            p.operations.push(op);
            p.check(&info())
        };
        checked(&|_| {}).expect("a sound operation");
        for (change, says) in [
            (
                &(|op: &mut Operation| op.tool.as_mut().expect("tool").feed = -1.0)
                    as &dyn Fn(&mut Operation),
                "tool `end-mill` has -1 among its diameter, feed, spindle and power",
            ),
            (
                &|op: &mut Operation| op.tool.as_mut().expect("tool").power = Some(f64::NAN),
                "tool `end-mill` has NaN among",
            ),
            (
                &|op: &mut Operation| op.surface = Some(f64::INFINITY),
                "surface at inf mm",
            ),
            (
                &|op: &mut Operation| {
                    op.values.insert("depth".into(), f64::NAN);
                },
                "value `depth` = NaN",
            ),
            (
                &|op: &mut Operation| {
                    op.paths.push(OperationPath {
                        z: f64::NAN,
                        points: vec![Point2::new(0.0, 0.0)],
                        closed: false,
                    })
                },
                "path 0 at z = NaN",
            ),
        ] {
            let e = checked(change).expect_err("refused");
            assert!(e.contains(says), "{e}");
        }
    }

    #[test]
    fn a_delta_carries_what_a_stage_added_and_nothing_of_the_layer() {
        let mut sent = plan(vec![bead()]);
        let before = sent.counts();
        sent.toolpaths.push(bead());
        sent.operations.push(Operation::new("cure", None));
        sent.build_time = Some(2.0);
        sent.parts.clear();
        let delta = PlanDelta::taken(&mut sent, before);
        assert_eq!((delta.toolpaths.len(), delta.operations.len()), (1, 1));
        let mut ours = plan(vec![bead()]);
        delta.apply(&mut ours);
        assert_eq!(
            (ours.toolpaths.len(), ours.operations.len(), ours.parts.len()),
            (2, 1, 1)
        );
        assert_eq!(ours.build_time, Some(2.0));
    }
}
