//! The sets {d < D} of a source in a layer plane as polygons (discs, ellipses, strips,
//! half-planes, clipped to a box around the family), and the boolean operations that
//! cut a family along them.

use i_overlay::core::fill_rule::FillRule;
use i_overlay::core::overlay_rule::OverlayRule;
use i_overlay::core::solver::Solver;
use i_overlay::float::overlay::{FloatOverlay, OverlayOptions};
use i_overlay::float::simplify::SimplifyShape;
use lamina_api::BBox2;
use lamina_api::mesh::Point3;
use lamina_fgm::surface::Surface;
use lamina_geom::field::Field;
use lamina_geom::iso::iso_loops;
use lamina_geom::offset::round_outline;
use lamina_geom::ring::ring_of;
use lamina_geom::simplify_ring;

use crate::source::Datum;

pub use lamina_geom::Shapes;

/// A set of the plane, kept symbolic when it is all or nothing.
#[derive(Debug, Clone)]
pub enum Set {
    Empty,
    Whole,
    Shapes(Shapes),
}

/// OGC-valid results (every ring simple: a ring pinched at a vertex comes out as an
/// outer and a hole touching it, not as one ring through the vertex twice), hairline
/// pieces under `MIN_AREA` dropped, on the caller's thread.
fn options() -> OverlayOptions<f64> {
    let mut o = OverlayOptions::<f64>::default();
    o.ogc = true;
    o.min_output_area = MIN_AREA;
    o
}

/// Pieces under this (mm²) are rounding residue of successive booleans.
const MIN_AREA: f64 = 1e-8;

fn solver() -> Solver {
    Solver {
        multithreading: None,
        ..Solver::default()
    }
}

fn overlay(a: &Shapes, b: &Shapes, rule: OverlayRule) -> Shapes {
    FloatOverlay::with_subj_and_clip_custom(a, b, options(), solver()).overlay(rule, FillRule::EvenOdd)
}

/// The shapes resolved into OGC-valid ones (the family as the slicer gave it may not be).
pub fn clean(a: &Shapes) -> Shapes {
    a.simplify_shape_custom(FillRule::EvenOdd, options(), solver())
}

pub fn intersect(a: &Shapes, b: &Shapes) -> Shapes {
    if a.is_empty() || b.is_empty() {
        return Vec::new();
    }
    overlay(a, b, OverlayRule::Intersect)
}

pub fn difference(a: &Shapes, b: &Shapes) -> Shapes {
    if a.is_empty() || b.is_empty() {
        return a.clone();
    }
    overlay(a, b, OverlayRule::Difference)
}

pub fn union(a: &Shapes, b: &Shapes) -> Shapes {
    if a.is_empty() {
        return b.clone();
    }
    if b.is_empty() {
        return a.clone();
    }
    overlay(a, b, OverlayRule::Union)
}

impl Set {
    pub fn intersect(&self, a: &Shapes) -> Shapes {
        match self {
            Set::Empty => Vec::new(),
            Set::Whole => a.clone(),
            Set::Shapes(s) => intersect(a, s),
        }
    }

    pub fn subtract_from(&self, a: &Shapes) -> Shapes {
        match self {
            Set::Empty => a.clone(),
            Set::Whole => Vec::new(),
            Set::Shapes(s) => difference(a, s),
        }
    }
}

/// Segments for an arc of radius `r` whose chords stray at most `tolerance`.
fn segments(r: f64, tolerance: f64) -> usize {
    let ratio = (1.0 - tolerance / r).clamp(-1.0, 1.0);
    let step = 2.0 * ratio.acos();
    ((std::f64::consts::TAU / step.max(1e-6)).ceil() as usize).clamp(16, 20_000)
}

/// An ellipse with semi-axes `a` along `e1` and `b` across it, as a polygon whose
/// area is the ellipse's (its vertices sit slightly outside), so the steps' areas are
/// right however coarse the polygon.
fn ellipse(c: [f64; 2], e1: [f64; 2], a: f64, b: f64, tolerance: f64) -> Shapes {
    let n = segments(a.max(b), tolerance);
    let wedge = std::f64::consts::TAU / n as f64;
    let grow = (wedge / wedge.sin()).sqrt();
    let (a, b) = (a * grow, b * grow);
    let m = [-e1[1], e1[0]];
    let ring: Vec<[f64; 2]> = (0..n)
        .map(|i| {
            let t = std::f64::consts::TAU * i as f64 / n as f64;
            let (u, v) = (a * t.cos(), b * t.sin());
            [c[0] + u * e1[0] + v * m[0], c[1] + u * e1[1] + v * m[1]]
        })
        .collect();
    vec![vec![ring]]
}

/// The ellipse of [`ellipse`] as far as it matters within `bbox`: itself when it is
/// not much larger than the box; otherwise only its part over the box (grown by a
/// margin), built from the ellipse's own arcs. An axis nearly parallel to the layer
/// cuts an ellipse kilometres long; handed whole to the boolean operations it would
/// coarsen their integer grid until the family's own edges snap.
fn ellipse_over(c: [f64; 2], e1: [f64; 2], a: f64, b: f64, tolerance: f64, bbox: &BBox2) -> Set {
    let diagonal = bbox.diagonal().max(tolerance);
    let centre = bbox.center();
    let far = (c[0] - centre.x).hypot(c[1] - centre.y) + a.max(b);
    if far <= 4.0 * diagonal {
        return Set::Shapes(ellipse(c, e1, a, b, tolerance));
    }
    // The box in the ellipse's frame: s along e1, t across, from its centre.
    let m = [-e1[1], e1[0]];
    let margin = 0.1 * diagonal;
    let corners = [
        [bbox.min.x - margin, bbox.min.y - margin],
        [bbox.max.x + margin, bbox.min.y - margin],
        [bbox.max.x + margin, bbox.max.y + margin],
        [bbox.min.x - margin, bbox.max.y + margin],
    ];
    let frame = |p: [f64; 2]| {
        let (x, y) = (p[0] - c[0], p[1] - c[1]);
        (x * e1[0] + y * e1[1], x * m[0] + y * m[1])
    };
    let (mut s_lo, mut s_hi, mut t_lo, mut t_hi) =
        (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY);
    for p in corners {
        let (s, t) = frame(p);
        s_lo = s_lo.min(s);
        s_hi = s_hi.max(s);
        t_lo = t_lo.min(t);
        t_hi = t_hi.max(t);
    }
    if s_hi <= -a || s_lo >= a || t_hi <= -b || t_lo >= b {
        return Set::Empty;
    }
    // The arcs over [s_lo, s_hi]: angles θ with s = a cos θ, in steps whose chords
    // stray at most `tolerance`; across, the box's range clamps them.
    let (th1, th2) = (
        (s_hi / a).clamp(-1.0, 1.0).acos(),
        (s_lo / a).clamp(-1.0, 1.0).acos(),
    );
    let step = (8.0 * tolerance / a.max(b)).sqrt();
    let n = (((th2 - th1) / step).ceil() as usize).clamp(2, 20_000);
    let point = |th: f64, side: f64| {
        let (s, t) = (a * th.cos(), (side * b * th.sin()).clamp(t_lo, t_hi));
        [c[0] + s * e1[0] + t * m[0], c[1] + s * e1[1] + t * m[1]]
    };
    let angle = |i: usize| th1 + (th2 - th1) * i as f64 / n as f64;
    let mut ring: Vec<[f64; 2]> = (0..=n).map(|i| point(angle(i), 1.0)).collect();
    ring.extend((0..=n).rev().map(|i| point(angle(i), -1.0)));
    Set::Shapes(vec![vec![ring]])
}

/// The box `b` cut to the side n . p < c (a convex polygon, Sutherland-Hodgman).
fn half_plane(b: &BBox2, n: [f64; 2], c: f64) -> Set {
    let corners = [
        [b.min.x, b.min.y],
        [b.max.x, b.min.y],
        [b.max.x, b.max.y],
        [b.min.x, b.max.y],
    ];
    let side = |p: &[f64; 2]| n[0] * p[0] + n[1] * p[1] - c;
    let mut out = Vec::new();
    for i in 0..4 {
        let (p, q) = (corners[i], corners[(i + 1) % 4]);
        let (sp, sq) = (side(&p), side(&q));
        if sp < 0.0 {
            out.push(p);
        }
        if (sp < 0.0) != (sq < 0.0) {
            let t = sp / (sp - sq);
            out.push([p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])]);
        }
    }
    if out.len() < 3 {
        return if side(&corners[0]) < 0.0 {
            Set::Whole
        } else {
            Set::Empty
        };
    }
    if out.len() == 4 && corners.iter().all(|p| side(p) < 0.0) {
        return Set::Whole;
    }
    Set::Shapes(vec![vec![out]])
}

/// The points of the plane at height `z` (inside `bbox`) whose distance to the datum
/// is below `d`; for the outer surface measured in the layer, the points of `family`
/// within `d` of its boundary. The outer surface in space is sampled
/// ([`SurfaceField`]), not drawn here: `Set::Empty`.
pub fn closer_than(datum: &Datum, d: f64, z: f64, bbox: &BBox2, tolerance: f64, family: &Shapes) -> Set {
    match *datum {
        Datum::Surface => Set::Empty,
        Datum::LayerBoundary => {
            // Round joins whose chords stray at most `tolerance` at radius d. The
            // outline runs on the family with its nearly collinear vertices removed:
            // sliced curves and meshed walls carry thousands of them, and the raw
            // offset of such a contour crosses itself so often that the outline takes
            // seconds instead of a millisecond.
            let simple: Shapes = family
                .iter()
                .map(|shape| shape.iter().map(|c| simplify_ring(c, tolerance / 2.0)).collect())
                .collect();
            let inset = round_outline(&simple, -d, tolerance);
            if inset.is_empty() {
                Set::Whole
            } else {
                Set::Shapes(difference(family, &inset))
            }
        }
        Datum::Point(c) => {
            let r2 = d * d - (z - c[2]).powi(2);
            if r2 <= 0.0 {
                return Set::Empty;
            }
            let r = r2.sqrt();
            ellipse_over([c[0], c[1]], [1.0, 0.0], r, r, tolerance, bbox)
        }
        Datum::Axis { at, direction: u } => {
            let h = u[0].hypot(u[1]);
            let dz = z - at[2];
            if h < 1e-12 {
                return ellipse_over([at[0], at[1]], [1.0, 0.0], d, d, tolerance, bbox);
            }
            let e1 = [u[0] / h, u[1] / h];
            if u[2].abs() < 1e-12 {
                // A horizontal axis: a strip |m . s| < sqrt(d² - dz²).
                let w2 = d * d - dz * dz;
                if w2 <= 0.0 {
                    return Set::Empty;
                }
                let w = w2.sqrt();
                let m = [-e1[1], e1[0]];
                let o = m[0] * at[0] + m[1] * at[1];
                let below = half_plane(bbox, m, o + w);
                let above = half_plane(bbox, [-m[0], -m[1]], -(o - w));
                return match (below, above) {
                    (Set::Empty, _) | (_, Set::Empty) => Set::Empty,
                    (Set::Whole, s) | (s, Set::Whole) => s,
                    (Set::Shapes(a), Set::Shapes(b)) => Set::Shapes(intersect(&a, &b)),
                };
            }
            // dist² = b² + (u_z a - h dz)² in the frame (e1, m) at the axis' trace: an
            // ellipse centred where a = h dz / u_z.
            let a0 = h * dz / u[2];
            let c = [at[0] + a0 * e1[0], at[1] + a0 * e1[1]];
            ellipse_over(c, e1, d / u[2].abs(), d, tolerance, bbox)
        }
        Datum::Plane { at, normal: n } => {
            // n_xy . (p - at_xy) < d - n_z (z - at_z)
            let c = d - n[2] * (z - at[2]);
            if n[0].hypot(n[1]) < 1e-12 {
                return if c > 0.0 { Set::Whole } else { Set::Empty };
            }
            half_plane(bbox, [n[0], n[1]], c + n[0] * at[0] + n[1] * at[1])
        }
    }
}

/// The distance in space from chosen faces of the part, sampled over a family in its
/// layer's mid-plane: the sets {d <= D} of the outer-surface source are its iso-loops.
///
/// Only the samples near a level D are measured one by one. The distance is
/// 1-Lipschitz, so a block of samples whose middle is farther than the block's reach
/// (plus one sample) from every level lies on the same side of every level as its
/// middle, and so do its neighbours: no iso-line crosses an edge that touches it, and
/// the middle's value stands for the block. Distances are measured up to a cap beyond
/// the deepest level, where a sample only needs to know it is farther.
pub struct SurfaceField {
    field: Field,
    /// Minus the distance, so that {d <= D} is the iso-set {v >= -D}; the border
    /// samples are below every level.
    values: Vec<f64>,
}

/// Samples a side of the blocks that one measured sample may stand for.
const BLOCK: usize = 4;

impl SurfaceField {
    /// Samples `surface` at `cells` samples along the longer side of `family`'s box,
    /// at height `z`, for the sets at the distances `levels`.
    pub fn new(surface: &Surface, family: &BBox2, z: f64, cells: usize, levels: &[f64]) -> Self {
        let field = Field::over(family, cells);
        let (nx, ny, h) = (field.nx, field.ny, field.h);
        let half = (BLOCK / 2) as f64;
        // How far a block's samples and their neighbours lie from its middle.
        let reach = half * std::f64::consts::SQRT_2 * h + h;
        let deepest = levels.iter().copied().fold(0.0f64, f64::max);
        // Capped samples stand clear of the deepest level (by more than a block's
        // reach), and the border below them all (finite, so that the iso-lines
        // interpolate).
        let cap = deepest + reach + 2.0 * h;
        let mut values = vec![-2.0 * cap; nx * ny];
        let at = |i: usize, j: usize| {
            let p = field.point(i, j);
            surface.distance_within(Point3::new(p.x, p.y, z), cap)
        };
        for bj in (1..ny - 1).step_by(BLOCK) {
            let j1 = (bj + BLOCK).min(ny - 1);
            for bi in (1..nx - 1).step_by(BLOCK) {
                let i1 = (bi + BLOCK).min(nx - 1);
                let (ic, jc) = ((bi + i1 - 1) / 2, (bj + j1 - 1) / 2);
                let dc = at(ic, jc);
                let near = levels.iter().any(|&d| (dc - d).abs() <= reach);
                for j in bj..j1 {
                    for i in bi..i1 {
                        let d = if near && (i, j) != (ic, jc) { at(i, j) } else { dc };
                        values[j * nx + i] = -d;
                    }
                }
            }
        }
        Self { field, values }
    }

    /// The points of `family` whose distance is at most `d`.
    pub fn closer_than(&self, d: f64, family: &Shapes) -> Set {
        let loops = iso_loops(&self.field, &self.values, -d);
        if loops.is_empty() {
            return Set::Empty;
        }
        let rings: Vec<Vec<[f64; 2]>> = loops.iter().map(ring_of).collect();
        let within = intersect(family, &vec![rings]);
        if within.is_empty() {
            Set::Empty
        } else {
            Set::Shapes(within)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use lamina_api::{Point2, Polygon};
    use lamina_geom::ring::polygons_of;

    fn area(s: &Shapes) -> f64 {
        polygons_of(s).iter().map(Polygon::area).sum()
    }

    fn bbox() -> BBox2 {
        BBox2::from_points([Point2::new(-50.0, -50.0), Point2::new(50.0, 50.0)])
    }

    /// The points of the box `bbox()` closer than `d` to a datum in space, at 1e-4 mm,
    /// for a datum that needs no family.
    fn near(datum: &Datum, d: f64, z: f64) -> Set {
        closer_than(datum, d, z, &bbox(), 1e-4, &vec![])
    }

    /// How far the chords of a regular `n`-gon inscribed in a circle of radius `r`
    /// stray from the circle.
    fn sagitta(r: f64, n: usize) -> f64 {
        r * (1.0 - (std::f64::consts::PI / n as f64).cos())
    }

    #[test]
    fn arcs_take_the_fewest_chords_within_the_tolerance() {
        for (r, tolerance) in [(10.0, 0.01), (2.0, 1e-4), (40.0, 0.005), (0.5, 1e-3)] {
            let n = segments(r, tolerance);
            assert!(n > 16 && n < 20_000, "{r} {tolerance}: {n}");
            assert!(sagitta(r, n) <= tolerance * (1.0 + 1e-9), "{r} {tolerance}: {n}");
            assert!(
                sagitta(r, n - 1) > tolerance,
                "{r} {tolerance}: {n} is not the fewest"
            );
        }
        // A tolerance near the radius would take a few chords; a circle keeps 16. A
        // tolerance far below it would take millions; 20,000 bound the work.
        assert_eq!(segments(1.0, 0.9), 16);
        assert_eq!(segments(1.0, 5.0), 16);
        assert_eq!(segments(100.0, 1e-9), 20_000);
    }

    /// The box from `(x0, y0)` to `(x1, y1)` as shapes.
    fn rect(x0: f64, y0: f64, x1: f64, y1: f64) -> Shapes {
        vec![vec![vec![[x0, y0], [x1, y0], [x1, y1], [x0, y1]]]]
    }

    fn shapes(set: Set) -> Shapes {
        match set {
            Set::Shapes(s) => s,
            other => panic!("shapes expected, not {other:?}"),
        }
    }

    /// The area of the points of the box `[x0, x1] x [y0, y1]` where `inside` holds, by
    /// the midpoint rule on a fine grid.
    fn grid_area(inside: impl Fn(f64, f64) -> bool, [x0, y0, x1, y1]: [f64; 4]) -> f64 {
        let n = 2000;
        let (cx, cy) = ((x1 - x0) / n as f64, (y1 - y0) / n as f64);
        let count = (0..n)
            .flat_map(|i| (0..n).map(move |j| (i, j)))
            .filter(|&(i, j)| inside(x0 + (i as f64 + 0.5) * cx, y0 + (j as f64 + 0.5) * cy))
            .count();
        count as f64 * cx * cy
    }

    /// The area of the ellipse of centre `c`, semi-axes `a` along `e1` and `b` across,
    /// within the box `[x0, x1] x [y0, y1]`.
    fn ellipse_in(c: [f64; 2], e1: [f64; 2], a: f64, b: f64, area: [f64; 4]) -> f64 {
        grid_area(
            |x, y| {
                let (x, y) = (x - c[0], y - c[1]);
                let (s, t) = (x * e1[0] + y * e1[1], -x * e1[1] + y * e1[0]);
                (s / a).powi(2) + (t / b).powi(2) < 1.0
            },
            area,
        )
    }

    #[test]
    fn an_ellipse_far_larger_than_the_box_is_cut_to_it_from_its_own_arcs() {
        // An axis nearly parallel to the layer: an ellipse a kilometre long whose end
        // crosses the box. Only its part over the box is drawn, and within the box it
        // is the ellipse.
        let h = 50.0;
        let (x0, y0) = (0.6f64, 0.8f64);
        for (c, e1, a, b) in [
            ([1000.0, 5.0], [1.0, 0.0], 1020.0, 30.0),
            ([-1000.0 * x0, -1000.0 * y0 + 10.0], [x0, y0], 1030.0, 25.0),
            ([3.0, 900.0], [0.0, 1.0], 930.0, 40.0),
            // Wide enough to cover the whole box, square to it or turned.
            ([1000.0, 0.0], [1.0, 0.0], 1100.0, 500.0),
            ([-1000.0 * x0, -1000.0 * y0], [x0, y0], 1100.0, 500.0),
        ] {
            let set = ellipse_over(c, e1, a, b, 1e-3, &bbox());
            let within = intersect(&shapes(set), &rect(-h, -h, h, h));
            let want = ellipse_in(c, e1, a, b, [-h, -h, h, h]);
            assert!(
                (area(&within) - want).abs() < 2e-3 * want,
                "{c:?}: {} against {want}",
                area(&within)
            );
            // Drawn over the box (grown by its margin) only, not a kilometre long.
            let drawn = shapes(ellipse_over(c, e1, a, b, 1e-3, &bbox()));
            let reach = 1.1 * 2.0 * h * std::f64::consts::SQRT_2;
            for p in drawn.iter().flatten().flatten() {
                assert!(p[0].hypot(p[1]) <= reach, "{p:?} is far from the box");
            }
        }
        // A long ellipse that passes the box by: nothing, on either side and either end.
        for c in [[1100.0, 0.0], [-1100.0, 0.0], [0.0, 1100.0], [0.0, -1100.0]] {
            assert!(
                matches!(
                    ellipse_over(c, [1.0, 0.0], 1000.0, 20.0, 1e-3, &bbox()),
                    Set::Empty
                ),
                "{c:?}"
            );
            assert!(
                matches!(
                    ellipse_over(c, [0.0, 1.0], 1000.0, 20.0, 1e-3, &bbox()),
                    Set::Empty
                ),
                "{c:?}"
            );
        }
        // Near the box, the whole ellipse, of the ellipse's own area.
        let whole = shapes(ellipse_over([10.0, -5.0], [x0, y0], 30.0, 12.0, 1e-3, &bbox()));
        let want = std::f64::consts::PI * 30.0 * 12.0;
        assert!((area(&whole) - want).abs() < 1e-9 * want, "{}", area(&whole));
        // Turned along its axis: a quarter of the plane about its centre holds the
        // share the ellipse puts there.
        let quarter = [10.0, -5.0, 60.0, 60.0];
        let want = ellipse_in([10.0, -5.0], [x0, y0], 30.0, 12.0, quarter);
        let got = area(&intersect(
            &whole,
            &rect(quarter[0], quarter[1], quarter[2], quarter[3]),
        ));
        assert!((got - want).abs() < 2e-3 * want, "{got} against {want}");
    }

    #[test]
    fn a_half_plane_cuts_the_box() {
        let b = BBox2::from_points([Point2::new(0.0, 0.0), Point2::new(10.0, 20.0)]);
        // x < 3: a strip of the box.
        assert!((area(&shapes(half_plane(&b, [1.0, 0.0], 3.0))) - 60.0).abs() < 1e-9);
        // -x < -3, that is x > 3.
        assert!((area(&shapes(half_plane(&b, [-1.0, 0.0], -3.0))) - 140.0).abs() < 1e-9);
        // y < 15, and y > 15.
        assert!((area(&shapes(half_plane(&b, [0.0, 1.0], 15.0))) - 150.0).abs() < 1e-9);
        assert!((area(&shapes(half_plane(&b, [0.0, -1.0], -15.0))) - 50.0).abs() < 1e-9);
        // x + y < 5: the triangle at the origin's corner; x + y < 25: all but the
        // triangle at the far corner.
        assert!((area(&shapes(half_plane(&b, [1.0, 1.0], 5.0))) - 12.5).abs() < 1e-9);
        assert!((area(&shapes(half_plane(&b, [1.0, 1.0], 25.0))) - (200.0 - 12.5)).abs() < 1e-9);
        // The whole box on the side, or none of it.
        assert!(matches!(half_plane(&b, [1.0, 0.0], 11.0), Set::Whole));
        assert!(matches!(half_plane(&b, [1.0, 1.0], 31.0), Set::Whole));
        assert!(matches!(half_plane(&b, [1.0, 0.0], -1.0), Set::Empty));
        assert!(matches!(half_plane(&b, [-1.0, -1.0], -31.0), Set::Empty));
        // Touching a corner only: nothing of the box is on the side.
        assert!(matches!(half_plane(&b, [1.0, 1.0], 0.0), Set::Empty));
    }

    #[test]
    fn a_horizontal_axis_off_the_centre_cuts_a_strip_of_its_own_width() {
        // An axis along y through x = 10, at height 2; a distance of 5 at z = 6 leaves
        // |x - 10| < 3 over the box's 100 mm.
        let axis = Datum::Axis {
            at: [10.0, 0.0, 2.0],
            direction: [0.0, 1.0, 0.0],
        };
        let strip = shapes(near(&axis, 5.0, 6.0));
        assert!((area(&strip) - 600.0).abs() < 1e-6, "{}", area(&strip));
        for p in strip.iter().flatten().flatten() {
            assert!((p[0] - 10.0).abs() <= 3.0 + 1e-9, "{p:?}");
        }
        // Too high above it, nothing; a strip beyond the box, nothing; one wider than
        // the box, all of it.
        assert!(matches!(near(&axis, 5.0, 7.5), Set::Empty));
        let aside = Datum::Axis {
            at: [80.0, 0.0, 0.0],
            direction: [0.0, -2.0, 0.0],
        };
        assert!(matches!(near(&aside, 5.0, 0.0), Set::Empty));
        let wide = Datum::Axis {
            at: [0.0, 0.0, 0.0],
            direction: [0.0, 1.0, 0.0],
        };
        assert!(matches!(near(&wide, 80.0, 0.0), Set::Whole));
        // A vertical axis: a disc of the distance at every height.
        let vertical = Datum::Axis {
            at: [5.0, -5.0, 0.0],
            direction: [0.0, 0.0, 1.0],
        };
        let disc = shapes(near(&vertical, 4.0, 30.0));
        assert!((area(&disc) - std::f64::consts::PI * 16.0).abs() < 1e-9);
    }

    #[test]
    fn sets_meet_shapes_as_all_nothing_or_their_own() {
        let a = rect(0.0, 0.0, 10.0, 10.0);
        let b = rect(5.0, 0.0, 15.0, 10.0);
        let none: Shapes = Vec::new();
        assert!((area(&intersect(&a, &b)) - 50.0).abs() < 1e-9);
        assert!((area(&difference(&a, &b)) - 50.0).abs() < 1e-9);
        assert!((area(&union(&a, &b)) - 150.0).abs() < 1e-9);
        assert!(intersect(&a, &none).is_empty() && intersect(&none, &a).is_empty());
        assert_eq!(difference(&a, &none), a);
        assert!(difference(&none, &a).is_empty());
        assert_eq!(union(&a, &none), a);
        assert_eq!(union(&none, &b), b);
        assert!(Set::Empty.intersect(&a).is_empty());
        assert_eq!(Set::Whole.intersect(&a), a);
        assert!((area(&Set::Shapes(b.clone()).intersect(&a)) - 50.0).abs() < 1e-9);
        assert_eq!(Set::Empty.subtract_from(&a), a);
        assert!(Set::Whole.subtract_from(&a).is_empty());
        assert!((area(&Set::Shapes(b).subtract_from(&a)) - 50.0).abs() < 1e-9);
        // A bow tie (a ring through itself) resolves into its two triangles.
        let bow: Shapes = vec![vec![vec![[0.0, 0.0], [10.0, 10.0], [10.0, 0.0], [0.0, 10.0]]]];
        let clean = clean(&bow);
        assert_eq!(clean.len(), 2, "{clean:?}");
        assert!((area(&clean) - 50.0).abs() < 1e-9);
    }

    #[test]
    fn sources_off_the_origin_and_turned_cut_where_they_lie() {
        // Compared quarter by quarter about a point none of them is centred on, so that
        // a set of the right area in the wrong place or turned the wrong way fails.
        let quarters = [
            [-50.0, -50.0, 4.5, -4.0],
            [4.5, -50.0, 50.0, -4.0],
            [-50.0, -4.0, 4.5, 50.0],
            [4.5, -4.0, 50.0, 50.0],
        ];
        let check = |datum: &Datum, z: f64, d: f64, inside: &dyn Fn(f64, f64) -> bool| {
            let set = near(datum, d, z);
            let wants: Vec<f64> = quarters.iter().map(|&q| grid_area(inside, q)).collect();
            let total: f64 = wants.iter().sum();
            for (q, want) in quarters.iter().zip(wants) {
                let got = match &set {
                    Set::Shapes(s) => area(&intersect(s, &rect(q[0], q[1], q[2], q[3]))),
                    Set::Whole => (q[2] - q[0]) * (q[3] - q[1]),
                    Set::Empty => 0.0,
                };
                assert!(
                    (got - want).abs() < 2e-3 * total,
                    "{datum:?} at z {z}, over {q:?}: {got} against {want}"
                );
            }
        };
        // A point 2 mm below the layer: a disc of radius sqrt(25 - 4) about its foot.
        let (px, py) = (5.0, -3.0);
        check(&Datum::Point([px, py, 3.0]), 1.0, 5.0, &|x, y| {
            (x - px).powi(2) + (y - py).powi(2) + 4.0 < 25.0
        });
        // A horizontal axis along (0.6, 0.8) through (10, 5), 4 mm below the layer: a
        // strip 3 mm either side of its trace.
        let horizontal = Datum::Axis {
            at: [10.0, 5.0, 2.0],
            direction: [0.6, 0.8, 0.0],
        };
        check(&horizontal, 6.0, 5.0, &|x, y| {
            (-0.8 * (x - 10.0) + 0.6 * (y - 5.0)).abs() < 3.0
        });
        // An axis turned out of the layer (of unit length, as the stage hands it
        // over): the points of the layer within 2 mm of the line in space.
        let norm = 0.5f64.sqrt();
        let (at, u) = ([4.0, -6.0, 1.0], [0.3 / norm, 0.4 / norm, 0.5 / norm]);
        let z = 3.0;
        let near_line = |x: f64, y: f64| {
            let v = [x - at[0], y - at[1], z - at[2]];
            let along = v[0] * u[0] + v[1] * u[1] + v[2] * u[2];
            v[0] * v[0] + v[1] * v[1] + v[2] * v[2] - along * along < 4.0
        };
        check(&Datum::Axis { at, direction: u }, z, 2.0, &near_line);
        // A plane turned out of the layer, off the origin: the side n . (p - at) < d.
        let n = [0.6, 0.0, 0.8];
        let plane = Datum::Plane {
            at: [2.0, 3.0, 1.0],
            normal: n,
        };
        check(&plane, 4.0, 1.0, &|x, y| {
            n[0] * (x - 2.0) + n[1] * (y - 3.0) + n[2] * (4.0 - 1.0) < 1.0
        });
        // Turned about both axes of the layer, its point off both: every component of
        // the normal and of the point counts.
        let n = [0.48, 0.6, 0.64];
        let plane = Datum::Plane {
            at: [-3.0, 5.0, 2.0],
            normal: n,
        };
        check(&plane, 0.5, 2.0, &|x, y| {
            n[0] * (x + 3.0) + n[1] * (y - 5.0) + n[2] * (0.5 - 2.0) < 2.0
        });
    }

    #[test]
    fn a_point_cuts_a_disc_of_the_remaining_radius() {
        let s = near(&Datum::Point([0.0, 0.0, 3.0]), 5.0, 0.0);
        let Set::Shapes(s) = s else { panic!("a disc") };
        assert!((area(&s) - std::f64::consts::PI * 16.0).abs() < 1e-9);
        assert!(matches!(
            near(&Datum::Point([0.0, 0.0, 6.0]), 5.0, 0.0),
            Set::Empty
        ));
    }

    #[test]
    fn a_tilted_axis_cuts_an_ellipse() {
        let s = 0.5f64.sqrt();
        let axis = Datum::Axis {
            at: [0.0, 0.0, 0.0],
            direction: [s, 0.0, s],
        };
        let Set::Shapes(e) = closer_than(&axis, 2.0, 1.0, &bbox(), 1e-5, &vec![]) else {
            panic!("an ellipse")
        };
        // Semi-axes 2 / cos 45° and 2.
        let want = std::f64::consts::PI * 2.0 * 2.0 / s;
        assert!((area(&e) - want).abs() < 1e-3 * want);
        // Centred where the axis crosses z = 1: x = 1.
        let c = lamina_geom::centroid::polygon_centroid(&polygons_of(&e)[0]).expect("an area");
        assert!((c.x - 1.0).abs() < 1e-6 && c.y.abs() < 1e-6, "{c:?}");
    }

    #[test]
    fn planes_cut_half_planes_and_horizontal_axes_strips() {
        let plane = Datum::Plane {
            at: [0.0; 3],
            normal: [1.0, 0.0, 0.0],
        };
        let Set::Shapes(h) = near(&plane, 10.0, 0.0) else {
            panic!("a half plane")
        };
        assert!((area(&h) - 60.0 * 100.0).abs() < 1e-6);
        let flat = Datum::Plane {
            at: [0.0; 3],
            normal: [0.0, 0.0, 1.0],
        };
        assert!(matches!(near(&flat, 1.0, 0.5), Set::Whole));
        assert!(matches!(near(&flat, 1.0, 1.5), Set::Empty));
        let axis = Datum::Axis {
            at: [0.0, 0.0, 0.0],
            direction: [1.0, 0.0, 0.0],
        };
        let Set::Shapes(strip) = near(&axis, 5.0, 3.0) else {
            panic!("a strip")
        };
        assert!((area(&strip) - 8.0 * 100.0).abs() < 1e-6);
    }

    #[test]
    fn the_outer_surface_cuts_a_band_along_the_boundary() {
        let square: Shapes = vec![vec![vec![[0.0, 0.0], [20.0, 0.0], [20.0, 20.0], [0.0, 20.0]]]];
        let Set::Shapes(band) = closer_than(&Datum::LayerBoundary, 2.0, 0.0, &bbox(), 1e-4, &square) else {
            panic!("a band")
        };
        assert!((area(&band) - (400.0 - 256.0)).abs() < 1e-6, "{}", area(&band));
        assert!(matches!(
            closer_than(&Datum::LayerBoundary, 11.0, 0.0, &bbox(), 1e-4, &square),
            Set::Whole
        ));
    }
}
