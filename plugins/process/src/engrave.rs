//! `engrave`: step 4 of the process. A periodic microstructure is an array of base
//! cells, voids on a lattice (cmpm-process-planning 4.3, `lamina_fgm::microstructure`):
//! spheres by default, or the `base_cell` table's shape, size, orientation and inserting
//! function. The voids the layer's plane cuts (at mid-layer, where the contours are
//! cut) are engraved by a laser from the surface down through the layer: rings inside
//! each void's outline, the first half a spot in, the next ones a spot less the overlap
//! further, and one at the deepest point where a core would be left, so the void is
//! cleared. A void narrower than the spot gets none, and the layer says so. The rings
//! are burnt in passes of `depth_per_pass`, each focused on the floor it leaves, so the
//! last pass's height is the layer's bottom: the depth is in the paths' Z.

use i_overlay::core::fill_rule::FillRule;
use i_overlay::core::overlay_rule::OverlayRule;
use i_overlay::float::single::SingleFloatOverlay;
use lamina_api::stage::{AnyStage, Process, StageConfig, StageInfo, StageKind};
use lamina_api::table::TableRef;
use lamina_api::{
    Contour, LayerPlan, Limit, Operation, OperationPath, OperationTool, Point2, Polygon, ProcessContext,
    Result, StageFactory,
};
use lamina_fgm::microstructure::{BaseCellSpec, Microstructure};
use lamina_geom::Shapes;
use lamina_geom::base_cell::inset_convex;
use lamina_geom::ring::{polygons_of, ring_of, shape_of};

use crate::area::{distance_to_area, layer_area, offset, surface_now};
use crate::regions::selected;
use crate::tool::{DIAMETER, FEED, LENGTH, POWER, ToolSpec, checked};

lamina_api::stage_options! {
    #[derive(Debug)]
    struct Options {
        /// the material regions with the microstructure; default: every layer
        regions: Vec<String> = "[]",
        /// lattice spacing in x, y, z (mm)
        #[range(0.001, LENGTH)]
        period: [f64; 3] = "[1.0, 1.0, 1.0]",
        /// one inserting point of the lattice (mm)
        #[range(-1e4, 1e4)]
        origin: [f64; 3] = "[0.0, 0.0, 0.0]",
        /// radius of the spherical void at each inserting point (mm)
        #[range(0.001, LENGTH)]
        void_radius: f64 = "0.3",
        /// the base cell instead of spheres: `{ shape = "sphere" | "box" | "cylinder", size, aspect, turn, lean, insert, period, origin, tilt }`, sizes and angles numbers or Rhai expressions of x, y, z (formerly `cell`)
        #[formerly("cell")]
        base_cell: Option<BaseCellSpec>,
        /// the laser's name
        tool: String = r#""laser""#,
        /// spot diameter (mm)
        #[range(DIAMETER.0, DIAMETER.1)]
        diameter: f64 = "0.05",
        /// share of a ring the next one covers again
        #[range(0.0, 0.9)]
        overlap: f64 = "0.2",
        /// scan speed (mm/s)
        #[range(FEED.0, FEED.1)]
        feed: f64 = "50.0",
        /// laser power (W)
        #[range(POWER.0, POWER.1)]
        power: f64 = "20.0",
        /// depth one pass of the laser takes off (mm): the rings are repeated, each pass focused on the floor it leaves, down to the layer's bottom
        #[range(0.001, 100.0)]
        depth_per_pass: f64 = "0.1",
    }
}

/// A void the plane cuts: a whole cell section, or the part of one inside the area.
enum Void {
    /// Convex, inside the area.
    Whole(Contour),
    Cut(Polygon),
}

impl Void {
    fn bbox(&self) -> lamina_api::BBox2 {
        match self {
            Void::Whole(c) => c.bbox(),
            Void::Cut(p) => p.bbox(),
        }
    }

    fn area(&self) -> f64 {
        match self {
            Void::Whole(c) => c.area(),
            Void::Cut(p) => p.area(),
        }
    }

    /// The outline moved in by `d`: empty once nothing is left.
    fn inset(&self, d: f64) -> Vec<Contour> {
        match self {
            Void::Whole(c) => inset_convex(c, d).into_iter().collect(),
            Void::Cut(p) => offset(std::slice::from_ref(p), -d)
                .iter()
                .flat_map(|q| q.contours().cloned().collect::<Vec<_>>())
                .collect(),
        }
    }

    /// The laser's rings: the outline half a `spot` in, then every `step` further,
    /// while anything is left; where a core lies deeper than the last ring reaches
    /// (its inset plus half a spot), one more ring at the deepest inset, found by
    /// bisection, so the void is cleared. Empty for a void narrower than the spot.
    fn rings(&self, spot: f64, step: f64) -> Vec<Contour> {
        let mut out = Vec::new();
        let mut inset = spot / 2.0;
        let mut last = None;
        loop {
            let ring = self.inset(inset);
            if ring.is_empty() {
                break;
            }
            out.extend(ring);
            last = Some(inset);
            inset += step;
        }
        if let Some(d) = last
            && !self.inset(d + spot / 2.0).is_empty()
        {
            let (mut lo, mut hi) = (d + spot / 2.0, inset);
            for _ in 0..16 {
                let mid = (lo + hi) / 2.0;
                if self.inset(mid).is_empty() {
                    hi = mid;
                } else {
                    lo = mid;
                }
            }
            out.extend(self.inset(lo));
        }
        out
    }
}

struct Engrave {
    options: Options,
    cells: Microstructure,
    tool: OperationTool,
    table: TableRef,
    limits: lamina_api::Limits,
}

impl Engrave {
    /// The voids of the plane at `z` within `area`: whole sections, and the sections
    /// the area's boundary cuts, clipped all at once.
    fn voids(&self, area: &[Polygon], z: f64, frame: Option<&lamina_api::ModelFrame>) -> Result<Vec<Void>> {
        let Some(bbox) = area.iter().map(Polygon::bbox).reduce(|a, b| a.union(&b)) else {
            return Ok(Vec::new());
        };
        let mut out = Vec::new();
        let mut cut: Shapes = Vec::new();
        for section in self.cells.voids(z, &bbox, frame)? {
            let n = section.len() as f64;
            let c = section.points.iter().fold(Point2::new(0.0, 0.0), |s, p| {
                Point2::new(s.x + p.x / n, s.y + p.y / n)
            });
            let reach = section.points.iter().map(|p| (p - c).norm()).fold(0.0, f64::max);
            let inside = area.iter().any(|p| p.contains(c));
            let clear = area
                .iter()
                .map(|p| p.boundary_distance(c))
                .fold(f64::INFINITY, f64::min);
            if inside && clear >= reach {
                out.push(Void::Whole(section));
            } else if distance_to_area(c, area) < reach {
                cut.push(vec![ring_of(&section)]);
            }
        }
        if !cut.is_empty() {
            let clip: Shapes = area.iter().map(shape_of).collect();
            let clipped: Shapes = cut.overlay(&clip, OverlayRule::Intersect, FillRule::NonZero);
            out.extend(
                polygons_of(&clipped)
                    .into_iter()
                    .filter(|p| p.area() > 1e-9)
                    .map(Void::Cut),
            );
        }
        Ok(out)
    }
}

impl Process for Engrave {
    fn process(&self, ctx: &ProcessContext<'_>, plan: &mut LayerPlan) -> Result<()> {
        if !selected(ctx, &self.table, plan, &self.options.regions)? {
            return Ok(());
        }
        let area = layer_area(plan);
        let voids = self.voids(
            &area,
            plan.z - plan.thickness / 2.0,
            ctx.info.model_frame.as_ref(),
        )?;
        if voids.is_empty() {
            return Ok(());
        }
        let bottom = plan.z - plan.thickness;
        // The laser burns from the surface down to the layer's bottom.
        let surface = surface_now(plan);
        let spot = self.tool.diameter;
        let step = spot * (1.0 - self.options.overlap);
        // Rings to come, at most a void's width over the step each: counted first.
        let rings: f64 = voids
            .iter()
            .map(|v| {
                let b = v.bbox();
                (b.width().min(b.height()) / 2.0 / step).ceil() + 1.0
            })
            .sum();
        self.limits.check(
            Limit::GridSamples,
            rings,
            &format!("laser rings {step} mm apart in the layer's voids"),
        )?;
        let depth = surface - bottom;
        let passes = (depth / self.options.depth_per_pass - 1e-9).ceil().max(1.0);
        self.limits.check(
            Limit::GridSamples,
            rings * passes,
            &format!(
                "laser rings in {passes} passes of {} mm",
                self.options.depth_per_pass
            ),
        )?;
        let mut rings = Vec::new();
        let mut narrow = 0;
        for v in &voids {
            let r = v.rings(spot, step);
            if r.is_empty() {
                narrow += 1;
            }
            rings.extend(r);
        }
        // Pass k focuses on the floor it leaves, the last on the layer's bottom.
        let mut paths = Vec::with_capacity(rings.len() * passes as usize);
        for k in 1..=passes as usize {
            let z = crate::area::micrometres(surface - depth * k as f64 / passes);
            paths.extend(rings.iter().map(|c| OperationPath {
                z,
                points: c.points.clone(),
                closed: true,
            }));
        }
        if narrow > 0 {
            plan.warn(
                StageKind::Process,
                "voids-narrower-than-spot",
                format!(
                    "engrave: {narrow} of {} voids are narrower than the {spot} mm laser spot and get no ring",
                    voids.len()
                ),
            );
        }
        let mut op = Operation::new("engrave", plan.material_region);
        op.tool = Some(self.tool.clone());
        op.paths = paths;
        op.values.insert("voids".into(), voids.len() as f64);
        op.values
            .insert("void_area".into(), voids.iter().map(Void::area).sum());
        op.values.insert("depth".into(), depth);
        op.values.insert("passes".into(), passes);
        plan.operations.push(op);
        Ok(())
    }
}

fn build(config: &StageConfig<'_>) -> Result<AnyStage> {
    let options: Options = config.parse()?;
    let cells = match &options.base_cell {
        Some(spec) => {
            if let Some(k) = ["period", "origin", "void_radius"]
                .into_iter()
                .find(|k| config.has(k))
            {
                return Err(config.error(
                    k,
                    "give either `base_cell` or the spheres' `period`, `origin` and `void_radius`",
                ));
            }
            Microstructure::new(spec, config, "base_cell")?
        }
        None => {
            // `period` and `void_radius` are positive numbers by their declared ranges.
            let smallest = options.period.iter().copied().fold(f64::INFINITY, f64::min);
            if options.void_radius > smallest / 2.0 {
                return Err(config.error(
                    "void_radius",
                    format!(
                        "must be at most half the smallest period ({} mm): voids that large would meet",
                        smallest / 2.0
                    ),
                ));
            }
            if options.diameter > options.void_radius {
                return Err(config.error(
                    "diameter",
                    "the laser spot must be smaller than the void's radius",
                ));
            }
            Microstructure::spheres(options.period, options.origin, options.void_radius, config.limits)
        }
    };
    if !(options.overlap.is_finite() && (0.0..0.9).contains(&options.overlap)) {
        return Err(config.error("overlap", "must be at least 0 and below 0.9"));
    }
    let tool = checked(
        config,
        ToolSpec {
            name: &options.tool,
            kind: "laser",
            diameter: options.diameter,
            feed: options.feed,
            spindle: None,
            power: Some(options.power),
        },
    )?;
    Ok(AnyStage::Process(Box::new(Engrave {
        options,
        cells,
        tool,
        table: config.table.clone(),
        limits: config.limits,
    })))
}

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Process,
        name: "engrave",
        doc: "Engraves the voids of a periodic microstructure (spheres, or base cells whose size and orientation follow Rhai functions, on a lattice that may be tilted) with a laser, ring by ring (CMPM step 4).",
        options: Options::SPECS,
        example: "use = \"engrave\"\nperiod = [1.0, 1.0, 1.0]\nvoid_radius = 0.3",
    },
    build,
});

#[cfg(test)]
mod tests {
    use super::*;

    /// Whether every point of `void` on a fine grid at least half a `spot` from its
    /// outline lies within half a spot of one of `rings`: the laser clears the void
    /// (all but the corners a round spot cannot reach).
    fn cleared(void: &Void, rings: &[Contour], spot: f64) -> bool {
        let b = void.bbox();
        let inside = |p: Point2| match void {
            Void::Whole(c) => c.contains(p) && c.distance(p) >= spot / 2.0,
            Void::Cut(q) => q.contains(p) && q.boundary_distance(p) >= spot / 2.0,
        };
        (0..=80).all(|j| {
            (0..=80).all(|i| {
                let p = Point2::new(
                    b.min.x + b.width() * f64::from(i) / 80.0,
                    b.min.y + b.height() * f64::from(j) / 80.0,
                );
                // The offset engine's grid rounds the cut void's rings by a few nm.
                !inside(p) || rings.iter().any(|r| r.distance(p) <= spot / 2.0 + 1e-6)
            })
        })
    }

    #[test]
    fn rings_start_half_a_spot_in_step_in_and_clear_the_void() {
        // A void of radius 0.3 (a 32-gon), a 0.05 mm spot, rings 0.04 apart: insets
        // 0.025, 0.065, ..., 0.265, then one at the deepest inset (the apothem), as
        // 0.265 + 0.025 leaves a core.
        let circle = Contour::circle(Point2::new(1.0, -2.0), 0.3, 32);
        let apothem = 0.3 * (std::f64::consts::PI / 32.0).cos();
        let void = Void::Whole(circle.clone());
        let rings = void.rings(0.05, 0.04);
        assert_eq!(rings.len(), 8);
        for (k, r) in rings.iter().take(7).enumerate() {
            let inset = 0.025 + 0.04 * k as f64;
            let want = circle.area() * ((apothem - inset) / apothem).powi(2);
            assert!(
                (r.area() - want).abs() < 1e-9,
                "ring {k}: {} against {want}",
                r.area()
            );
        }
        assert!(rings[7].area() < 1e-6, "{}", rings[7].area());
        assert!(cleared(&void, &rings, 0.05));
        // Without the last ring a core would be left.
        assert!(!cleared(&void, &rings[..7], 0.05));
        // With an apothem of 0.27 the seventh ring (inset 0.265) reaches 0.29, past the
        // centre: no core is left, and no eighth ring is burnt.
        let r = 0.27 / (std::f64::consts::PI / 32.0).cos();
        let void = Void::Whole(Contour::circle(Point2::new(1.0, -2.0), r, 32));
        let rings = void.rings(0.05, 0.04);
        assert_eq!(rings.len(), 7);
        assert!(cleared(&void, &rings, 0.05));
        // A void narrower than the spot gets none.
        assert!(
            Void::Whole(Contour::circle(Point2::new(0.0, 0.0), 0.02, 32))
                .rings(0.05, 0.04)
                .is_empty()
        );
    }

    #[test]
    fn a_void_the_boundary_cuts_is_cleared_too() {
        // Half of a disc of radius 0.4, cut along a chord 0.1 from its centre.
        let disc = Contour::circle(Point2::new(0.0, 0.0), 0.4, 48);
        let clip = vec![vec![lamina_geom::ring::ring_of(&Contour::rectangle(
            Point2::new(-1.0, 0.1),
            Point2::new(1.0, 1.0),
        ))]];
        let cut: Shapes =
            vec![vec![ring_of(&disc)]].overlay(&clip, OverlayRule::Intersect, FillRule::NonZero);
        let polygon = polygons_of(&cut).remove(0);
        let void = Void::Cut(polygon);
        let rings = void.rings(0.06, 0.045);
        assert!(rings.len() >= 3, "{}", rings.len());
        assert!(cleared(&void, &rings, 0.06));
        // Every ring stays inside the void, half a spot from its edge at least.
        let Void::Cut(p) = &void else { unreachable!() };
        for r in &rings {
            for q in &r.points {
                assert!(p.contains(*q) && p.boundary_distance(*q) >= 0.03 - 1e-6, "{q:?}");
            }
        }
    }
}
