//! `xy`: grading across a layer (topological-hierarchy-fgm Eq. 18-21): the sub-regions
//! of a family, numbered j = 0 .. N_R - 1 from the grading reference (the outer
//! contour) inward, get the level r_j = j / (N_R - 1), or the level the discretiser
//! measured, and a control function of r gives their compositions. The default,
//! f = 1 - r, puts the part's first material at the outer contour and the second at the
//! far end, as the paper's green-to-black example does.

use lamina_api::geom::contour_centroid;
use lamina_api::stage::{AnyStage, FamilyContext, Grader, StageConfig, StageInfo, StageKind};
use lamina_api::{Composition, Contour, Point2, Polygon, Result, Sample, StageFactory, SubRegion, Vector2};
use serde::Deserialize;

use crate::control::{Control, ControlOptions, region_args};

lamina_api::option_type!(LevelSource = "string");

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "lowercase")]
enum LevelSource {
    /// r_j = j / (N_R - 1) from the region's index (Eq. 21).
    #[default]
    Index,
    /// The level the discretiser gave the region (a distance ratio).
    Level,
    /// Eq. 18 at points: r = D_e / L_r at every point of a grid inside the region, along
    /// the radial line through the point (from the centre of the nearest hole, or of the
    /// family's most inland point without holes, out to the outer contour); the control
    /// function is evaluated at each point, with its x and
    /// y, and the region takes the mean composition.
    Points,
}

lamina_api::stage_options! {
    #[derive(Debug)]
    struct Options {
        f: Option<String> = use crate::control::F,
        /// unset: linear: -1 (f = 1 - r, the first material outside); constant: 1; wave: 1
        #[range(-1000, 1000)]
        mu: Option<f64>,
        /// unset: linear: 1; wave: pi
        #[range(-1000, 1000)]
        lambda: Option<f64>,
        alpha: Option<f64> = use crate::control::ALPHA,
        k: Option<f64> = use crate::control::K,
        /// "index" (j / (N_R - 1), Eq. 21), "level" (the discretiser's distance ratio) or "points" (Eq. 18 at the points of a grid in each region, x and y given to the function, the mean composition; the points are kept, so that a mixing head with the gcode exporter's `mix_along` follows Eq. 18 along its beads)
        r: LevelSource = r#""index""#,
        /// spacing (mm) of the points of `r = "points"`
        #[range(0.01, 1e6)]
        grid: f64 = "0.5",
    }
}

/// The default spacing (mm) of the points of `r = "points"`.
#[cfg(test)]
const DEFAULT_GRID: f64 = 0.5;

/// At most this many points a region: beyond it the grid coarsens.
const MAX_POINTS: usize = 4096;

struct InPlane {
    control: Control,
    source: LevelSource,
    grid: f64,
}

/// Points of a square grid of `step` mm inside `polygon` (at cell centres), coarsened
/// to at most `MAX_POINTS`; `fallback` when none falls inside.
fn grid_points(polygon: &Polygon, fallback: Point2, step: f64) -> Vec<Point2> {
    let b = polygon.bbox();
    let mut step = step;
    while (b.width() / step).ceil() * (b.height() / step).ceil() > MAX_POINTS as f64 {
        step *= 2.0;
    }
    let (nx, ny) = (
        (b.width() / step).ceil() as usize,
        (b.height() / step).ceil() as usize,
    );
    let mut points = Vec::new();
    for j in 0..ny {
        for i in 0..nx {
            let p = Point2::new(
                b.min.x + (i as f64 + 0.5) * step,
                b.min.y + (j as f64 + 0.5) * step,
            );
            if polygon.contains(p) {
                points.push(p);
            }
        }
    }
    if points.is_empty() {
        points.push(fallback);
    }
    points
}

/// Where the ray from `from` along the unit vector `u` crosses `contour`: the ray's
/// parameters (mm along it) at every crossing.
fn crossings(contour: &Contour, from: Point2, u: Vector2) -> impl Iterator<Item = f64> + '_ {
    contour.edges().filter_map(move |(a, b)| {
        let e = b - a;
        let denom = u.x * e.y - u.y * e.x;
        if denom.abs() < 1e-15 {
            return None;
        }
        let w = a - from;
        let t = (w.x * e.y - w.y * e.x) / denom;
        let s = (w.x * u.y - w.y * u.x) / denom;
        ((0.0..=1.0).contains(&s) && t >= 0.0).then_some(t)
    })
}

/// Eq. 18 at the points of one family: r = D_ε / L_r along the radial line through ε
/// (Fig. 7-8). The radial lines run from the outer contour to the centre of the inner
/// contour (the centroid of the hole nearest ε, or `pole` without holes), so the line
/// through ε is the ray from that centre through ε: L_r runs from where it leaves the
/// hole to where it meets the outer contour, D_ε from ε to the outer contour. Where the
/// ray does not meet them in that order (a hole that is not star-shaped about its
/// centre, a point in a bay of the outer contour hidden from the centre), the shortest
/// distances stand in: d_out / (d_out + d_in). The holes' centres are found once per
/// family.
pub struct RadialLines<'a> {
    family: &'a Polygon,
    pole: Option<Point2>,
    centres: Vec<Option<Point2>>,
}

impl<'a> RadialLines<'a> {
    pub fn new(family: &'a Polygon, pole: Option<Point2>) -> Self {
        let centres = family.holes.iter().map(contour_centroid).collect();
        RadialLines {
            family,
            pole,
            centres,
        }
    }

    /// r at the point `p`.
    pub fn level(&self, p: Point2) -> f64 {
        let family = self.family;
        let nearest = family
            .holes
            .iter()
            .enumerate()
            .map(|(k, h)| (k, h, h.distance(p)))
            .min_by(|a, b| a.2.total_cmp(&b.2));
        let (centre, d_in) = match nearest {
            Some((k, _, d)) => (self.centres[k], d),
            None => (self.pole, self.pole.map_or(0.0, |c| (p - c).norm())),
        };
        if let Some(c) = centre {
            let to = p - c;
            let at = to.norm();
            if at > 0.0 {
                let u = to / at;
                // The hole's last crossing before ε (the centre itself without a hole)
                // and the outer contour's first after it.
                let leave = match nearest {
                    Some((_, h, _)) => crossings(h, c, u)
                        .filter(|&t| t <= at)
                        .fold(None, |m: Option<f64>, t| Some(m.map_or(t, |m| m.max(t)))),
                    None => Some(0.0),
                };
                let meet = crossings(&family.outer, c, u)
                    .filter(|&t| t >= at)
                    .fold(None, |m: Option<f64>, t| Some(m.map_or(t, |m| m.min(t))));
                if let (Some(t0), Some(t1)) = (leave, meet)
                    && t1 > t0
                {
                    return ((t1 - at) / (t1 - t0)).clamp(0.0, 1.0);
                }
            }
        }
        let d_out = family.outer.distance(p);
        if d_out + d_in > 0.0 {
            (d_out / (d_out + d_in)).clamp(0.0, 1.0)
        } else {
            0.0
        }
    }
}

/// Eq. 21: r_j = j / (N_R - 1); a family that is one region sits at r = 0.
pub fn index_level(index: usize, count: usize) -> f64 {
    if count <= 1 {
        0.0
    } else {
        index as f64 / (count - 1) as f64
    }
}

impl Grader for InPlane {
    fn grade(&self, ctx: &FamilyContext<'_>, regions: &mut [SubRegion]) -> Result<()> {
        let part = &ctx.info.parts[ctx.part];
        let n = part.materials.len();
        if self.source == LevelSource::Points {
            let family = ctx.polygon();
            // Without holes the lines run to the family's centre: the most inland of a
            // coarse grid of its points.
            let pole = family.holes.is_empty().then(|| {
                grid_points(family, family.bbox().center(), family.bbox().diagonal() / 64.0)
                    .into_iter()
                    .max_by(|a, b| family.outer.distance(*a).total_cmp(&family.outer.distance(*b)))
                    .unwrap_or_else(|| family.bbox().center())
            });
            let lines = RadialLines::new(family, pole);
            for region in regions.iter_mut() {
                let points = grid_points(&region.polygon, region.reference, self.grid);
                let mut sum = vec![0.0; n];
                let mut samples = Vec::with_capacity(points.len());
                for &p in &points {
                    let r = lines.level(p);
                    let mut args = region_args(ctx, region, r);
                    (args.x, args.y) = (p.x, p.y);
                    let context = || {
                        format!(
                            "part `{}`, layer {} (z = {:.4}), family {}, region {} at ({:.3}, {:.3}) (r = {r})",
                            part.name, ctx.layer.index, ctx.layer.z, ctx.family, region.index, p.x, p.y
                        )
                    };
                    let c = self.control.composition(&args, n, context)?;
                    sum.iter_mut().zip(&c.fractions).for_each(|(s, f)| *s += f);
                    samples.push(Sample {
                        at: p,
                        composition: c,
                    });
                }
                let total: f64 = sum.iter().sum();
                let mean: Vec<f64> = sum.iter().map(|s| s / total).collect();
                region.composition = Some(Composition::new(mean)?);
                // Kept, so that a mixing head can follow the gradient along a bead.
                region.samples = samples;
            }
            return Ok(());
        }
        for region in regions.iter_mut() {
            let r = match self.source {
                LevelSource::Index => index_level(region.index, region.count),
                LevelSource::Level | LevelSource::Points => region.level,
            };
            let args = region_args(ctx, region, r);
            let context = || {
                format!(
                    "part `{}`, layer {} (z = {:.4}), family {}, region {} (r = {r})",
                    part.name, ctx.layer.index, ctx.layer.z, ctx.family, region.index
                )
            };
            region.composition = Some(self.control.composition(&args, n, context)?);
        }
        Ok(())
    }
}

fn build(config: &StageConfig<'_>) -> Result<AnyStage> {
    let o: Options = config.parse()?;
    let control = Control::from_options(
        config,
        &ControlOptions {
            f: o.f,
            mu: o.mu,
            lambda: o.lambda,
            alpha: o.alpha,
            k: o.k,
        },
        (-1.0, 1.0),
    )?;
    let grid = o.grid;
    if !(grid.is_finite() && grid > 0.0) {
        return Err(config.error(
            "grid",
            format!("`grid` must be a positive number of mm, not {grid}"),
        ));
    }
    Ok(AnyStage::Grade(Box::new(InPlane {
        control,
        source: o.r,
        grid,
    })))
}

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Grade,
        name: "xy",
        doc: "Grades across the layer: each sub-region j of N_R gets r = j / (N_R - 1) (or the discretiser's level), fractions from a control function of r (default f = 1 - r: first material at the outer contour).",
        options: Options::SPECS,
        example: "use = \"xy\"\nf = \"linear\"\nmu = -1.0\nlambda = 1.0",
    },
    build,
});

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::{self, regions};
    use lamina_api::{Contour, ContourTree, Layer, Material, Point2, Polygon, RunInfo};

    fn info() -> RunInfo {
        fixtures::info(&[("green", [0, 255, 0]), ("black", [0, 0, 0])])
    }

    /// Eq. 18 along the radial line (Fig. 8): a disc of radius 20 about the origin with
    /// a hole of radius 5 about (5, 3). Straight above the hole's centre, at (5, 12),
    /// the radial line leaves the hole at y = 8 and meets the outer contour at
    /// y = sqrt(400 - 25): D = 19.365 - 12, L = 19.365 - 8, r = 0.648, where the
    /// shortest distances (7 and 4) would give 0.636.
    /// Eq. 25's f = 1 - r (mu = -1, lambda = 1) with levels from `source` on a grid
    /// of `grid` mm.
    fn linear(source: LevelSource, grid: f64) -> InPlane {
        InPlane {
            control: Control::Linear {
                mu: -1.0,
                lambda: 1.0,
            },
            source,
            grid,
        }
    }

    #[test]
    fn eq_18_follows_the_radial_line_from_the_holes_centre() {
        // The hole's points start a third of the way round, not level with its
        // centre, so that a centroid wrong in y shows.
        let mut hole = Contour::circle(Point2::new(5.0, 3.0), 5.0, 4096).oriented(false);
        hole.points.rotate_left(1365);
        let family = Polygon::new(Contour::circle(Point2::new(0.0, 0.0), 20.0, 4096), vec![hole]);
        let top = (400.0f64 - 25.0).sqrt();
        let want = (top - 12.0) / (top - 8.0);
        let lines = RadialLines::new(&family, None);
        let r = lines.level(Point2::new(5.0, 12.0));
        assert!((r - want).abs() < 1e-4, "{r} vs {want}");
        assert!((r - 7.0 / 11.0).abs() > 0.01);
        // Along the hole's centre line to the right, at (12, 3): the line leaves the
        // hole at x = 10 and meets the disc at x = sqrt(400 - 9).
        let right = (400.0f64 - 9.0).sqrt();
        let r = lines.level(Point2::new(12.0, 3.0));
        let want = (right - 12.0) / (right - 10.0);
        assert!((r - want).abs() < 1e-4, "{r} vs {want}");
        // Without a hole, the line runs from the pole: at (0, 10) from (0, 0), 10 of 20.
        let disc = Polygon::new(Contour::circle(Point2::new(0.0, 0.0), 20.0, 4096), vec![]);
        let r = RadialLines::new(&disc, Some(Point2::new(0.0, 0.0))).level(Point2::new(0.0, 10.0));
        assert!((r - 0.5).abs() < 1e-4, "{r}");
        // On the outer contour r = 0, on the hole r = 1.
        assert!(lines.level(Point2::new(-20.0, 0.0)).abs() < 1e-3);
        assert!((lines.level(Point2::new(5.0, -2.0)) - 1.0).abs() < 1e-3);
    }

    /// Where the radial line misses the hole (a U-shaped hole whose centroid lies in
    /// its opening), the shortest distances stand in, d_out / (d_out + d_in): at
    /// (0, 10) in a 40 mm square, 10 mm from the outer contour and sqrt(32) from the
    /// U's nearest corner.
    #[test]
    fn eq_18_falls_back_to_the_shortest_distances_where_the_radial_line_misses() {
        let pts = |v: &[(f64, f64)]| Contour::new(v.iter().map(|&(x, y)| Point2::new(x, y)).collect());
        let u = pts(&[
            (-6.0, -6.0),
            (-6.0, 6.0),
            (-4.0, 6.0),
            (-4.0, -4.0),
            (4.0, -4.0),
            (4.0, 6.0),
            (6.0, 6.0),
            (6.0, -6.0),
        ]);
        let family = Polygon::new(rect_contour(40.0), vec![u]);
        let r = RadialLines::new(&family, None).level(Point2::new(0.0, 10.0));
        let want = 10.0 / (10.0 + 32f64.sqrt());
        assert!((r - want).abs() < 1e-9, "{r} vs {want}");
        // Nearer the outer contour than the hole: at (0, 18), 2 mm from the one and
        // sqrt(160) from the U's corners.
        let r = RadialLines::new(&family, None).level(Point2::new(0.0, 18.0));
        let want = 2.0 / (2.0 + 160f64.sqrt());
        assert!((r - want).abs() < 1e-9, "{r} vs {want}");
    }

    fn rect_contour(side: f64) -> Contour {
        let h = side / 2.0;
        Contour::new(vec![
            Point2::new(-h, -h),
            Point2::new(h, -h),
            Point2::new(h, h),
            Point2::new(-h, h),
        ])
    }

    /// topological-hierarchy-fgm Eq. 20-21 and Fig. 8: ten sub-regions from green at
    /// the outer contour to black at the inner one.
    #[test]
    fn ten_sub_regions_from_green_to_black() {
        let info = info();
        let layer = Layer::default();
        let tree = ContourTree::default();
        let ctx = fixtures::context(&info, &layer, &tree, &[]);
        let grader = linear(LevelSource::Index, DEFAULT_GRID);
        let mut rs = regions(10);
        grader.grade(&ctx, &mut rs).expect("grades");
        let colours: Vec<[u8; 3]> = rs
            .iter()
            .map(|r| r.composition.as_ref().expect("graded").colour(&info.materials))
            .collect();
        let greens: Vec<u8> = colours.iter().map(|c| c[1]).collect();
        assert_eq!(greens, [255, 227, 198, 170, 142, 113, 85, 57, 28, 0]);
        assert!(colours.iter().all(|c| c[0] == 0 && c[2] == 0));
        for r in &rs {
            let f = &r.composition.as_ref().expect("graded").fractions;
            assert!((f[0] + f[1] - 1.0).abs() < 1e-12);
            assert!((f[0] - (1.0 - r.index as f64 / 9.0)).abs() < 1e-12);
        }
    }

    #[test]
    fn a_single_region_is_the_first_material() {
        assert_eq!(index_level(0, 1), 0.0);
        assert_eq!(index_level(4, 5), 1.0);
    }

    #[test]
    fn three_materials_need_a_script() {
        let mut info = info();
        info.materials.push(Material {
            name: "blue".into(),
            colour: [0, 0, 255],
            layer_thickness: None,
        });
        info.parts[0].materials = vec![0, 1, 2];
        let layer = Layer::default();
        let tree = ContourTree::default();
        let ctx = fixtures::context(&info, &layer, &tree, &[]);
        let grader = InPlane {
            control: Control::Wave {
                mu: 1.0,
                lambda: std::f64::consts::PI,
            },
            source: LevelSource::Index,
            grid: DEFAULT_GRID,
        };
        let err = grader.grade(&ctx, &mut regions(3)).expect_err("three materials");
        assert!(err.to_string().contains("returns 3 fractions"), "{err}");
    }

    /// Eq. 18 at points: in a tube of radii 10 and 5, r = (10 - rho) / 5 at radius
    /// rho; with f = 1 - r the green share of the whole ring is its mean over the
    /// area, 1 - 4/9; a thin outer ring is nearly pure green, a thin inner one black.
    #[test]
    fn points_grade_by_eq_18_at_every_point() {
        let info = info();
        let circle = |r: f64, ccw: bool| {
            Contour::new(
                (0..720)
                    .map(|k| {
                        let a = std::f64::consts::TAU * k as f64 / 720.0;
                        Point2::new(r * a.cos(), r * a.sin())
                    })
                    .collect(),
            )
            .oriented(ccw)
        };
        let layer = Layer {
            contours: vec![circle(10.0, true), circle(5.0, false)],
            ..Layer::default()
        };
        let tree = ContourTree {
            nodes: Vec::new(),
            families: vec![lamina_api::Family {
                outer: 0,
                holes: vec![1],
            }],
        };
        let polygons = tree.family_polygons(&layer.contours);
        let ctx = fixtures::context(&info, &layer, &tree, &polygons);
        let grader = linear(LevelSource::Points, 0.1);
        let ring = |a: f64, b: f64, index: usize| SubRegion {
            family: 0,
            index,
            count: 3,
            level: 0.0,
            polygon: Polygon::new(circle(a, true), vec![circle(b, false)]),
            cell: None,
            reference: Point2::new(-(a + b) / 2.0, 0.0),
            composition: None,
            samples: Vec::new(),
        };
        let mut rs = vec![ring(10.0, 5.0, 0), ring(10.0, 9.9, 1), ring(5.1, 5.0, 2)];
        grader.grade(&ctx, &mut rs).expect("grades");
        let green = |r: &SubRegion| r.composition.as_ref().expect("graded").fractions[0];
        assert!((green(&rs[0]) - 5.0 / 9.0).abs() < 5e-3, "{}", green(&rs[0]));
        assert!(green(&rs[1]) > 0.98 && green(&rs[2]) < 0.02);
    }

    /// Without holes the radial lines run from the family's most inland point: in a
    /// right triangle with legs of 30 mm, the incentre (8.79, 8.79), not the box's
    /// centre (15, 15) on the hypotenuse. There r = 1, so with f = 1 - r the point of
    /// the grid with the least of the first material lies next to it.
    #[test]
    fn points_without_holes_grade_from_the_most_inland_point() {
        let info = info();
        let triangle = Contour::new(vec![
            Point2::new(0.0, 0.0),
            Point2::new(30.0, 0.0),
            Point2::new(0.0, 30.0),
        ]);
        let layer = Layer {
            contours: vec![triangle.clone()],
            ..Layer::default()
        };
        let tree = ContourTree {
            nodes: Vec::new(),
            families: vec![lamina_api::Family {
                outer: 0,
                holes: vec![],
            }],
        };
        let polygons = tree.family_polygons(&layer.contours);
        let ctx = fixtures::context(&info, &layer, &tree, &polygons);
        let grader = linear(LevelSource::Points, 0.5);
        let mut rs = regions(1);
        rs[0].polygon = Polygon::new(triangle, vec![]);
        grader.grade(&ctx, &mut rs).expect("grades");
        let darkest = rs[0]
            .samples
            .iter()
            .min_by(|a, b| a.composition.fractions[0].total_cmp(&b.composition.fractions[0]))
            .expect("samples");
        let incentre = 30.0 - 450f64.sqrt();
        assert!(
            (darkest.at - Point2::new(incentre, incentre)).norm() < 1.0,
            "{:?}",
            darkest.at
        );
        assert!(
            darkest.composition.fractions[0] < 0.05,
            "{:?}",
            darkest.composition
        );
    }

    /// The points of `r = "points"` are the centres of a square grid over the
    /// region's box that fall inside it; a grid of more than 4096 squares doubles its
    /// step until it holds at most that many; a region holding no centre gets its
    /// reference point.
    #[test]
    fn points_lie_at_the_centres_of_the_grid_squares_inside_the_region() {
        let rect = |x: f64, y: f64, w: f64, h: f64| {
            Polygon::new(
                Contour::rectangle(Point2::new(x, y), Point2::new(x + w, y + h)),
                Vec::new(),
            )
        };
        let at = |v: &[Point2]| v.iter().map(|p| (p.x, p.y)).collect::<Vec<_>>();
        let fallback = Point2::new(-7.0, -7.0);
        assert_eq!(
            at(&grid_points(&rect(1.0, 2.0, 1.0, 0.5), fallback, 0.5)),
            [(1.25, 2.25), (1.75, 2.25)]
        );
        // An L: the centre of its missing corner square is left out.
        let l = Polygon::new(
            Contour::new(
                [
                    (0.0, 0.0),
                    (2.0, 0.0),
                    (2.0, 1.0),
                    (1.0, 1.0),
                    (1.0, 2.0),
                    (0.0, 2.0),
                ]
                .iter()
                .map(|&(x, y)| Point2::new(x, y))
                .collect(),
            ),
            Vec::new(),
        );
        assert_eq!(
            at(&grid_points(&l, fallback, 1.0)),
            [(0.5, 0.5), (1.5, 0.5), (0.5, 1.5)]
        );
        // 64 x 64 squares exactly: kept; 100 mm across at 0.5 mm (40,000 squares):
        // 1 mm, then 2 mm, 2,500 points 2 mm apart.
        assert_eq!(
            grid_points(&rect(0.0, 0.0, 32.0, 32.0), fallback, 0.5).len(),
            4096
        );
        let coarse = grid_points(&rect(0.0, 0.0, 100.0, 100.0), fallback, 0.5);
        assert_eq!(coarse.len(), 2500);
        assert_eq!(at(&coarse[..2]), [(1.0, 1.0), (3.0, 1.0)]);
        // A sliver narrower than half a step holds no centre.
        assert_eq!(
            at(&grid_points(&rect(0.0, 0.0, 3.0, 0.2), fallback, 1.0)),
            [(-7.0, -7.0)]
        );
    }
}
