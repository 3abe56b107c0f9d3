//! An example third-party plugin, built as a `cdylib` and loaded by Lamina at run time:
//! the `zigzag` planner fills every sub-region with parallel extrusion lines joined
//! boustrophedon-style, one timed toolpath per line, with travel moves between them.
//!
//! It also adds a process operation of its own, `cure`: a UV lamp passes over the
//! outline of each layer's solid areas (a step the CMPM process does not have, as a
//! third party would add one).
//!
//! It depends on lamina-api alone, registers its stages with `register_stage!`, and
//! exports the entry point with `export_plugin!`; that is all a plugin needs.

use lamina_api::stage::{AnyStage, Planner, Process, StageConfig, StageInfo, StageKind};
use lamina_api::{
    Contour, LayerPlan, Operation, OperationPath, OperationTool, PathKind, Point2, Polygon, ProcessContext,
    Result, RunInfo, StageFactory, TimedPoint, Toolpath,
};

lamina_api::export_plugin!("zigzag");

lamina_api::stage_options! {
    #[derive(Debug, Clone)]
    struct Options {
        /// line spacing and extrusion width (mm)
        #[range(0.01, 50.0)]
        width: f64 = "0.4",
        /// line direction (degrees from x)
        #[range(-360.0, 360.0)]
        angle: f64 = "45.0",
        /// turn the lines by 90 degrees every other layer
        alternate: bool = "true",
        /// deposition speed (mm/s)
        #[range(0.01, 10_000.0)]
        speed: f64 = "40.0",
        /// travel speed (mm/s)
        #[range(0.01, 10_000.0)]
        travel_speed: f64 = "150.0",
    }
}

struct ZigZag(Options);

/// Fill lines of `polygon` along x at heights `y0 + k * width`, in boustrophedon order.
/// Scanlines take crossings with the half-open rule (an edge covers `[min y, max y)`),
/// so a line through a vertex counts it once.
pub fn fill_lines(polygon: &Polygon, width: f64) -> Vec<(Point2, Point2)> {
    let bb = polygon.bbox();
    let mut lines = Vec::new();
    if bb.is_empty() || width <= 0.0 {
        return lines;
    }
    let count = ((bb.height() / width).floor() as usize).min(1_000_000);
    let mut xs: Vec<f64> = Vec::new();
    for k in 0..=count {
        let y = bb.min.y + width * (k as f64 + 0.5);
        if y >= bb.max.y {
            break;
        }
        xs.clear();
        for c in polygon.contours() {
            for (a, b) in c.edges() {
                if (a.y <= y) != (b.y <= y) {
                    xs.push(a.x + (y - a.y) / (b.y - a.y) * (b.x - a.x));
                }
            }
        }
        xs.sort_by(f64::total_cmp);
        let mut row: Vec<(Point2, Point2)> = xs
            .chunks_exact(2)
            .filter(|p| p[1] > p[0])
            .map(|p| (Point2::new(p[0], y), Point2::new(p[1], y)))
            .collect();
        if k % 2 == 1 {
            row.reverse();
            for seg in &mut row {
                *seg = (seg.1, seg.0);
            }
        }
        lines.extend(row);
    }
    lines
}

fn rotate(p: Point2, (s, c): (f64, f64)) -> Point2 {
    Point2::new(c * p.x - s * p.y, s * p.x + c * p.y)
}

fn rotate_polygon(p: &Polygon, sc: (f64, f64)) -> Polygon {
    let r = |c: &Contour| Contour::new(c.points.iter().map(|&q| rotate(q, sc)).collect());
    Polygon::new(r(&p.outer), p.holes.iter().map(r).collect())
}

impl Planner for ZigZag {
    fn plan(&self, _info: &RunInfo, plan: &mut LayerPlan) -> Result<()> {
        let o = &self.0;
        let angle = if o.alternate && plan.index % 2 == 1 {
            o.angle + 90.0
        } else {
            o.angle
        }
        .to_radians();
        let forward = angle.sin_cos();
        let back = (-forward.0, forward.1);
        let mut t = 0.0;
        let mut at: Option<Point2> = None;
        let mut paths = Vec::new();
        for part in &plan.parts {
            for (ri, region) in part.regions.iter().enumerate() {
                // Rotate the region so the fill runs along x, then rotate the lines back.
                let lines = fill_lines(&rotate_polygon(&region.polygon, back), o.width);
                for (a, b) in lines {
                    let (a, b) = (rotate(a, forward), rotate(b, forward));
                    if let Some(p) = at {
                        let dt = (a - p).norm() / o.travel_speed;
                        paths.push(Toolpath {
                            tool: 0,
                            material: None,
                            kind: PathKind::Travel,
                            points: vec![TimedPoint { p, t }, TimedPoint { p: a, t: t + dt }],
                            width: 0.0,
                            widths: Vec::new(),
                            composition: None,
                            part: None,
                            sub_region: None,
                        });
                        t += dt;
                    }
                    let dt = (b - a).norm() / o.speed;
                    paths.push(Toolpath {
                        tool: 0,
                        material: None,
                        kind: PathKind::Extrude,
                        points: vec![TimedPoint { p: a, t }, TimedPoint { p: b, t: t + dt }],
                        width: o.width,
                        widths: Vec::new(),
                        composition: region.composition.clone(),
                        part: Some(part.part),
                        sub_region: Some(ri),
                    });
                    t += dt;
                    at = Some(b);
                }
            }
        }
        plan.toolpaths.extend(paths);
        plan.build_time = Some(plan.build_time.unwrap_or(0.0) + t);
        Ok(())
    }
}

fn build(config: &StageConfig<'_>) -> Result<AnyStage> {
    let o: Options = config.parse()?;
    for (k, v) in [
        ("width", o.width),
        ("speed", o.speed),
        ("travel_speed", o.travel_speed),
    ] {
        if !(v.is_finite() && v > 0.0) {
            return Err(config.error(k, "must be a positive number"));
        }
    }
    if !o.angle.is_finite() {
        return Err(config.error("angle", "must be a number of degrees"));
    }
    Ok(AnyStage::Plan(Box::new(ZigZag(o))))
}

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Plan,
        name: "zigzag",
        doc: "Fills each sub-region with parallel extrusion lines joined boustrophedon-style (example dynamic plugin).",
        options: Options::SPECS,
        example: "use = \"zigzag\"\nwidth = 0.5",
    },
    build,
});

lamina_api::stage_options! {
    #[derive(Debug, Clone)]
    struct CureOptions {
        /// lamp power (W)
        #[range(0.001, 100_000.0)]
        power: f64 = "100.0",
        /// speed of the lamp over the outline (mm/s)
        #[range(0.01, 10_000.0)]
        feed: f64 = "20.0",
        /// height of the lamp above the layer (mm)
        #[range(0.001, 1000.0)]
        height: f64 = "5.0",
    }
}

/// `cure`: a UV lamp over the outline of each layer's solid areas, once more (the
/// `final` pass) on the last layer.
struct Cure(CureOptions);

impl Process for Cure {
    fn process(&self, ctx: &ProcessContext<'_>, plan: &mut LayerPlan) -> Result<()> {
        let mut op = Operation::new("cure", plan.material_region);
        op.tool = Some(OperationTool {
            name: "uv-lamp".into(),
            kind: "lamp".into(),
            diameter: 10.0,
            feed: self.0.feed,
            spindle: None,
            power: Some(self.0.power),
        });
        for part in &plan.parts {
            for &f in &part.families {
                let outer = &part.contours[part.tree.families[f].outer];
                op.paths.push(OperationPath {
                    z: plan.z + self.0.height,
                    points: outer.points.clone(),
                    closed: true,
                });
            }
        }
        // Energy per mm of outline (J/mm).
        op.values.insert("dose".into(), self.0.power / self.0.feed);
        if ctx.last {
            op.pass = "final".into();
        }
        plan.operations.push(op);
        Ok(())
    }
}

fn build_cure(config: &StageConfig<'_>) -> Result<AnyStage> {
    let o: CureOptions = config.parse()?;
    for (k, v) in [("power", o.power), ("feed", o.feed), ("height", o.height)] {
        if !(v.is_finite() && v > 0.0) {
            return Err(config.error(k, "must be a positive number"));
        }
    }
    Ok(AnyStage::Process(Box::new(Cure(o))))
}

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Process,
        name: "cure",
        doc: "Passes a UV lamp over the outline of each layer's solid areas (example process operation of a dynamic plugin).",
        options: CureOptions::SPECS,
        example: "use = \"cure\"\npower = 80.0",
    },
    build: build_cure,
});

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn square_with_hole_is_filled_around_the_hole() {
        let sq = |h: f64| {
            Contour::new(vec![
                Point2::new(-h, -h),
                Point2::new(h, -h),
                Point2::new(h, h),
                Point2::new(-h, h),
            ])
        };
        let p = Polygon::new(sq(5.0), vec![sq(1.0).oriented(false)]);
        let lines = fill_lines(&p, 0.5);
        let length: f64 = lines.iter().map(|(a, b)| (b - a).norm()).sum();
        // Line length times spacing approximates the area (96 mm²).
        assert!((length * 0.5 - p.area()).abs() < 1.0, "{length}");
        // Rows crossing the hole are split in two.
        assert!(lines.len() > 20);
    }
}
