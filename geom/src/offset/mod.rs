//! Offsets of shapes in or out, by one engine: the raw loops of [`raw`], resolved under
//! the positive fill rule. The discretisers work on their family's integer grid and add
//! the loops of each step to overlays of their own ([`RawOffset::add_loops`]); the float
//! [`round_outline`] and [`round_offset`] (bead loops, machining passes, distance
//! sources) put their shapes on a grid of their own for each call.

pub mod raw;

pub use raw::{Join, RawOffset, Scratch, fits};

use i_overlay::core::fill_rule::FillRule;
use i_overlay::core::overlay::{IntOverlayOptions, Overlay};
use i_overlay::core::overlay_rule::OverlayRule;
use i_overlay::core::solver::Solver;
use i_overlay::i_float::int::point::IntPoint;
use i_overlay::i_shape::int::shape::IntShapes;

use crate::{Shapes, simplify_ring};

/// Largest coordinate magnitude put on a grid: far inside the i32 engine's safe range
/// (2^30), leaving room for offset construction and for areas in i64.
pub const HALF_RANGE: f64 = (1u64 << 26) as f64;

/// Pieces smaller than this many square grid units (about 4 um by 4 um at the finest
/// scale of a discretiser's family) are rounding slivers, not areas.
pub const MIN_AREA: u64 = 64;

/// The largest power-of-two scale (grid units per mm) that keeps coordinates up to
/// `half` mm from the grid's origin within [`HALF_RANGE`]. Powers of two make the
/// scaling exact both ways.
pub fn grid_scale(half: f64) -> f64 {
    2f64.powi((HALF_RANGE / half).log2().floor() as i32)
}

/// OGC-valid output (holes touch their outer at most at single points, every ring
/// simple), slivers dropped.
pub fn overlay_options() -> IntOverlayOptions<u64> {
    IntOverlayOptions {
        ogc: true,
        min_output_area: MIN_AREA,
        ..IntOverlayOptions::default()
    }
}

/// The runtime runs layers in parallel already: the overlay stays on the caller's thread.
pub fn solver() -> Solver {
    Solver {
        multithreading: None,
        ..Solver::default()
    }
}

/// The angle (radians) between the chords of a round join of radius `d` whose
/// chords stray at most `tolerance` from the arc; never below 0.01, which bounds the
/// vertices a join can take.
pub fn join_step(d: f64, tolerance: f64) -> f64 {
    let step = 2.0 * (1.0 - (tolerance / d.abs()).min(1.0)).acos();
    step.max(0.01)
}

/// `shapes` (outer rings counter-clockwise, holes clockwise) offset by `d` (negative:
/// inward) with round joins straying at most `tolerance` from the arcs: the raw loops
/// of [`RawOffset`] on a grid of the shapes' own, resolved under the positive rule.
/// Rings come back as the overlay writes them (outer counter-clockwise, holes
/// clockwise). Shapes with no finite extent have no offset.
pub fn round_outline(shapes: &Shapes, d: f64, tolerance: f64) -> Shapes {
    if shapes.is_empty() || d == 0.0 {
        return shapes.clone();
    }
    let Some(grid) = OwnGrid::around(shapes, d) else {
        return Vec::new();
    };
    let on_grid: IntShapes<i32> = shapes
        .iter()
        .map(|shape| shape.iter().map(|ring| grid.ring(ring)).collect())
        .collect();
    let edges: usize = on_grid.iter().flatten().map(Vec::len).sum();
    let mut overlay = Overlay::new_custom(2 * edges, overlay_options(), solver());
    let offset = RawOffset {
        join: Join::Round,
        tolerance,
    };
    if !offset.add_loops(&mut overlay, &on_grid, d, grid.scale, &mut Scratch::default()) {
        return Vec::new();
    }
    overlay
        .overlay(OverlayRule::Clip, FillRule::Positive)
        .iter()
        .map(|shape| shape.iter().map(|ring| grid.unring(ring)).collect())
        .collect()
}

/// A grid for one offset: origin at the shapes' bounding-box centre, the largest
/// power-of-two scale that holds them and their outward offset ([`grid_scale`]).
struct OwnGrid {
    origin: [f64; 2],
    scale: f64,
}

impl OwnGrid {
    fn around(shapes: &Shapes, d: f64) -> Option<Self> {
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for p in shapes.iter().flatten().flatten() {
            for a in 0..2 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
        let half = 0.5 * (hi[0] - lo[0]).max(hi[1] - lo[1]) + d.max(0.0);
        if !(half.is_finite() && half > 0.0) {
            return None;
        }
        Some(Self {
            origin: [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])],
            scale: grid_scale(half),
        })
    }

    /// A ring's points on the grid (the raw loops drop repeats and whatever else lies
    /// on a chord).
    fn ring(&self, ring: &[[f64; 2]]) -> Vec<IntPoint<i32>> {
        ring.iter()
            .map(|p| {
                IntPoint::new(
                    ((p[0] - self.origin[0]) * self.scale).round() as i32,
                    ((p[1] - self.origin[1]) * self.scale).round() as i32,
                )
            })
            .collect()
    }

    fn unring(&self, ring: &[IntPoint<i32>]) -> Vec<[f64; 2]> {
        ring.iter()
            .map(|p| {
                [
                    f64::from(p.x) / self.scale + self.origin[0],
                    f64::from(p.y) / self.scale + self.origin[1],
                ]
            })
            .collect()
    }
}

/// [`round_outline`] with each ring simplified within `tolerance` and what
/// simplifies away dropped: offsets of offsets would otherwise multiply the arc
/// vertices pass after pass.
pub fn round_offset(shapes: &Shapes, d: f64, tolerance: f64) -> Shapes {
    if shapes.is_empty() || d == 0.0 {
        return shapes.clone();
    }
    tidy(round_outline(shapes, d, tolerance), tolerance)
}

/// Every ring simplified within `tolerance`; rings and shapes left with nothing
/// dropped.
pub fn tidy(shapes: Shapes, tolerance: f64) -> Shapes {
    tidy_with(shapes, |c| simplify_ring(c, tolerance))
}

/// [`tidy`] with chords that straddle each ring ([`crate::simplify::simplify_straddling`]):
/// for rings a nozzle follows, whose chords would otherwise leave a convex stretch
/// short of material along its whole length.
pub fn tidy_straddling(shapes: Shapes, tolerance: f64) -> Shapes {
    tidy_with(shapes, |c| crate::simplify::simplify_straddling(c, tolerance))
}

/// [`round_outline`] tidied with straddling chords ([`tidy_straddling`]): the
/// [`round_offset`] of paths a nozzle follows.
pub fn round_offset_straddling(shapes: &Shapes, d: f64, tolerance: f64) -> Shapes {
    if shapes.is_empty() || d == 0.0 {
        return shapes.clone();
    }
    tidy_straddling(round_outline(shapes, d, tolerance), tolerance)
}

/// Every ring through `simplify`; rings and shapes left with nothing dropped.
fn tidy_with(shapes: Shapes, simplify: impl Fn(&[[f64; 2]]) -> crate::Ring) -> Shapes {
    shapes
        .into_iter()
        .map(|shape| {
            shape
                .into_iter()
                .map(|c| simplify(&c))
                .filter(|c| c.len() >= 3)
                .collect::<Vec<_>>()
        })
        .filter(|s| !s.is_empty())
        .collect()
}

#[cfg(test)]
mod tests {
    use std::f64::consts::PI;

    use i_overlay::core::fill_rule::FillRule;
    use i_overlay::core::overlay::{Overlay, ShapeType};
    use i_overlay::core::overlay_rule::OverlayRule;
    use i_overlay::i_float::int::point::IntPoint;
    use i_overlay::i_shape::int::shape::IntShapes;

    use super::*;
    use crate::ring::ring_area;

    fn square(s: f64) -> Shapes {
        vec![vec![rect(0.0, 0.0, s, s)]]
    }

    /// The rectangle from `(x0, y0)` to `(x1, y1)`, counter-clockwise.
    fn rect(x0: f64, y0: f64, x1: f64, y1: f64) -> Vec<[f64; 2]> {
        vec![[x0, y0], [x1, y0], [x1, y1], [x0, y1]]
    }

    #[test]
    fn a_square_moves_in_and_out_by_the_distance() {
        // Inward: a smaller square, its sides 2 d shorter.
        let inner = round_offset(&square(10.0), -1.0, 0.005);
        let a: f64 = inner[0].iter().map(|r| ring_area(r).abs()).sum();
        assert!((a - 64.0).abs() < 1e-6, "{a}");
        // Outward: the square, four strips and four quarter discs (round joins),
        // within the chord tolerance.
        let outer = round_offset(&square(10.0), 1.0, 0.005);
        let a = ring_area(&outer[0][0]).abs();
        let exact = 100.0 + 40.0 + PI;
        assert!((a - exact).abs() < 0.05, "{a} against {exact}");
        // Nothing to offset, or no distance: as given.
        assert!(round_offset(&Vec::new(), 1.0, 0.005).is_empty());
        assert_eq!(round_offset(&square(1.0), 0.0, 0.005), square(1.0));
        // Too far in: nothing left.
        assert!(round_offset(&square(1.0), -1.0, 0.005).is_empty());
    }

    #[test]
    fn the_join_step_keeps_chords_within_the_tolerance() {
        let (r, tol) = (2.0, 0.01);
        let step = join_step(r, tol);
        // A chord spanning `step` strays r (1 - cos(step / 2)) from its arc.
        assert!((r * (1.0 - (step / 2.0).cos()) - tol).abs() < 1e-12);
        // A tolerance beyond the radius: a half turn per chord.
        assert_eq!(join_step(0.001, 1.0), PI);
    }

    /// `shapes` on a grid of 1000 units per mm.
    fn on_grid(shapes: &Shapes) -> IntShapes<i32> {
        let unit =
            |p: &[f64; 2]| IntPoint::new((p[0] * 1000.0).round() as i32, (p[1] * 1000.0).round() as i32);
        shapes
            .iter()
            .map(|s| s.iter().map(|r| r.iter().map(unit).collect()).collect())
            .collect()
    }

    /// The raw loops of `shapes` (holes clockwise) on a grid of 1000 units per mm,
    /// resolved: the area of the offset.
    fn resolved(join: Join, shapes: &Shapes, d: f64) -> f64 {
        let mut overlay = Overlay::new_custom(0, overlay_options(), solver());
        let offset = RawOffset {
            join,
            tolerance: 1e-4,
        };
        assert!(offset.add_loops(&mut overlay, &on_grid(shapes), d, 1000.0, &mut Scratch::default()));
        let out = overlay.overlay(OverlayRule::Clip, FillRule::Positive);
        out.iter()
            .flatten()
            .map(|c| {
                ring_area(
                    &c.iter()
                        .map(|p| [f64::from(p.x) / 1e3, f64::from(p.y) / 1e3])
                        .collect::<Vec<_>>(),
                )
            })
            .sum()
    }

    #[test]
    fn joins_fill_where_offset_edges_part() {
        let mut hole = rect(3.0, 3.0, 7.0, 7.0);
        hole.reverse();
        let plate = vec![vec![rect(0.0, 0.0, 10.0, 10.0), hole]];
        // Inward the hole's corners part the offset edges: a miter keeps the hole
        // square, a bevel cuts each corner by half a unit square.
        let close = |a: f64, b: f64| (a - b).abs() < 1e-4;
        assert!(close(resolved(Join::Miter, &plate, -1.0), 64.0 - 36.0));
        assert!(close(resolved(Join::Bevel, &plate, -1.0), 64.0 - 34.0));
        assert!(close(resolved(Join::Miter, &plate, 1.0), 144.0 - 4.0));
        assert!(close(resolved(Join::Bevel, &plate, 1.0), 142.0 - 4.0));
        // Far enough in, nothing is left: no loop at all.
        let mut overlay = Overlay::new_custom(0, overlay_options(), solver());
        let offset = RawOffset {
            join: Join::Round,
            tolerance: 1e-4,
        };
        assert!(!offset.add_loops(
            &mut overlay,
            &on_grid(&plate),
            -5.0,
            1000.0,
            &mut Scratch::default()
        ));
    }

    /// The raw loops of `shapes` offset by `d` mm on a grid of 1000 units per mm,
    /// resolved, as rings in mm.
    fn resolved_rings(join: Join, shapes: &Shapes, d: f64) -> Vec<Vec<[f64; 2]>> {
        let mut overlay = Overlay::new_custom(0, overlay_options(), solver());
        let offset = RawOffset {
            join,
            tolerance: 1e-3,
        };
        offset.add_loops(&mut overlay, &on_grid(shapes), d, 1000.0, &mut Scratch::default());
        let out = overlay.overlay(OverlayRule::Clip, FillRule::Positive);
        out.iter()
            .flatten()
            .map(|c| {
                c.iter()
                    .map(|p| [f64::from(p.x) / 1e3, f64::from(p.y) / 1e3])
                    .collect()
            })
            .collect()
    }

    /// Whether `p` is inside `rings` by the even-odd rule (a ray to the right).
    fn inside(rings: &[Vec<[f64; 2]>], p: [f64; 2]) -> bool {
        let mut odd = false;
        for r in rings {
            for (i, a) in r.iter().enumerate() {
                let b = r[(i + 1) % r.len()];
                if (a[1] > p[1]) != (b[1] > p[1]) {
                    let x = a[0] + (p[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0]);
                    if x > p[0] {
                        odd = !odd;
                    }
                }
            }
        }
        odd
    }

    /// Distance from `p` to the nearest edge of `rings`.
    fn boundary_distance(rings: &[Vec<[f64; 2]>], p: [f64; 2]) -> f64 {
        rings
            .iter()
            .flat_map(|r| (0..r.len()).map(move |i| (r[i], r[(i + 1) % r.len()])))
            .map(|(a, b)| crate::segment::segment_distance2(p, a, b).sqrt())
            .fold(f64::INFINITY, f64::min)
    }

    #[test]
    fn round_offsets_are_the_erosion_and_the_dilation() {
        // A seven-pointed star (convex tips, reflex notches) with a square hole turned
        // 30 degrees, and more below: inward, a point is in the offset when it is in the part and at
        // least |d| from its boundary; outward, when it is in the part or within d of
        // it. Points near the offset's boundary (within the tolerance and the grid's
        // rounding) are left out.
        let star: Vec<[f64; 2]> = (0..14)
            .map(|i| {
                let a = PI * f64::from(i) / 7.0 + 0.1;
                let r = if i % 2 == 0 { 10.0 } else { 5.5 };
                [r * a.cos() + 0.3, r * a.sin() - 0.2]
            })
            .collect();
        let mut hole: Vec<[f64; 2]> = (0..4)
            .map(|i| {
                let a = PI / 6.0 + PI * f64::from(i) / 2.0;
                [1.5 * a.cos() + 0.8, 1.5 * a.sin() + 0.5]
            })
            .collect();
        hole.reverse();
        // A disc of 720 chord points (offset within the chord tolerance, after the
        // vertices the tolerance drops), and a triangle (the fewest vertices).
        let disc: Vec<[f64; 2]> = (0..720)
            .map(|i| {
                let a = PI * f64::from(i) / 360.0;
                [8.0 * a.cos() - 1.0, 8.0 * a.sin() + 0.5]
            })
            .collect();
        let triangle = vec![[-9.0, -8.0], [9.0, -7.0], [1.0, 9.0]];
        let mut rng = fastrand::Rng::with_seed(0x853c_49e6_748f_ea9b);
        let mut random = move || rng.f64();
        let cases: [(Shapes, &[f64]); 3] = [
            (vec![vec![star, hole]], &[-0.4, -1.1, -2.6, 0.4, 1.7]),
            (vec![vec![disc]], &[-3.0, -0.3, 0.5]),
            (vec![vec![triangle]], &[-2.0, 1.2]),
        ];
        for (part, distances) in &cases {
            for &d in *distances {
                let rings = resolved_rings(Join::Round, part, d);
                assert!(!rings.is_empty(), "{d}");
                let (mut tested, mut within) = (0, 0);
                for _ in 0..6000 {
                    let p = [random() * 26.0 - 13.0, random() * 26.0 - 13.0];
                    let (in_part, dist) = (inside(&part[0], p), boundary_distance(&part[0], p));
                    if (dist - d.abs()).abs() < 0.005 {
                        continue;
                    }
                    let want = if d < 0.0 {
                        in_part && dist > -d
                    } else {
                        in_part || dist < d
                    };
                    assert_eq!(
                        inside(&rings, p),
                        want,
                        "offset {d} at {p:?}: {dist} from the part"
                    );
                    tested += 1;
                    within += usize::from(want);
                }
                assert!(tested > 5000 && within > 0, "{d}: {within} of {tested}");
            }
        }
        // Far enough in, nothing is left.
        assert!(resolved_rings(Join::Round, &cases[0].0, -6.0).is_empty());
        // No distance, or none that is a number: no loop.
        for d in [0.0, f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            let mut overlay = Overlay::new_custom(0, overlay_options(), solver());
            let offset = RawOffset {
                join: Join::Round,
                tolerance: 1e-3,
            };
            assert!(!offset.add_loops(
                &mut overlay,
                &on_grid(&cases[2].0),
                d,
                1000.0,
                &mut Scratch::default()
            ));
            assert!(
                overlay.overlay(OverlayRule::Clip, FillRule::Positive).is_empty(),
                "{d}"
            );
        }
    }

    #[test]
    fn miter_joins_keep_corners_sharp_and_bevel_the_sharpest() {
        // Outward, a triangle's mitred offset is the triangle scaled about its
        // incentre: the 3-4-5 triangle (inradius 1) by 1.5 at 0.5 mm, area 6 x 2.25.
        let t = vec![vec![vec![[0.0, 0.0], [4.0, 0.0], [0.0, 3.0]]]];
        let area: f64 = resolved_rings(Join::Miter, &t, 0.5)
            .iter()
            .map(|r| ring_area(r))
            .sum();
        assert!((area - 13.5).abs() < 1e-3, "{area}");
        // A spike of 2.9 degrees is bevelled: the offset ends about 0.1 mm past its
        // tip, where a miter would reach 0.1 / sin(1.43 degrees) = 4 mm.
        let spike = vec![vec![vec![[0.0, 0.0], [10.0, 0.0], [0.0, 0.5]]]];
        let rings = resolved_rings(Join::Miter, &spike, 0.1);
        let far = rings.iter().flatten().map(|p| p[0]).fold(f64::MIN, f64::max);
        assert!(far > 10.0 && far < 10.2, "{far}");
    }

    #[test]
    fn the_engine_returns_holes_touching_their_outer_as_holes_and_no_slivers() {
        // A square less a triangle touching its bottom edge at one point: OGC-valid
        // output is the outer ring and a hole, not one ring through the point twice.
        let unit = |x: i32, y: i32| IntPoint::new(x * 1000, y * 1000);
        let mut overlay = Overlay::new_custom(0, overlay_options(), solver());
        overlay.add_contour(
            &[unit(0, 0), unit(10, 0), unit(10, 10), unit(0, 10)],
            ShapeType::Subject,
        );
        overlay.add_contour(&[unit(5, 0), unit(3, 4), unit(7, 4)], ShapeType::Clip);
        let out = overlay.overlay(OverlayRule::Difference, FillRule::NonZero);
        let rings: Vec<Vec<usize>> = out.iter().map(|s| s.iter().map(Vec::len).collect()).collect();
        assert_eq!(rings, vec![vec![4, 3]]);
        // A piece of 7 x 7 grid units is a rounding sliver, 8 x 8 is kept.
        for (side, kept) in [(7, 0), (8, 1)] {
            let mut overlay = Overlay::new_custom(0, overlay_options(), solver());
            let square = [
                IntPoint::new(0, 0),
                IntPoint::new(side, 0),
                IntPoint::new(side, side),
                IntPoint::new(0, side),
            ];
            overlay.add_contour(&square, ShapeType::Subject);
            assert_eq!(
                overlay.overlay(OverlayRule::Subject, FillRule::NonZero).len(),
                kept,
                "{side}"
            );
        }
    }

    #[test]
    fn the_grid_scale_is_the_largest_power_of_two_within_range() {
        for half in [0.3, 1.0, 100.0, 1234.5, 1e6] {
            let scale = grid_scale(half);
            assert_eq!(scale.log2().fract(), 0.0, "{half}: {scale}");
            assert!(
                half * scale <= HALF_RANGE && half * scale * 2.0 > HALF_RANGE,
                "{half}: {scale}"
            );
        }
        // 2^26 / 100 = 671,088.64: 2^19.
        assert_eq!(grid_scale(100.0), 524_288.0);
        assert_eq!(HALF_RANGE, 67_108_864.0);
    }

    #[test]
    fn no_distance_or_nothing_outlines_to_the_shapes_as_given() {
        assert_eq!(round_outline(&square(3.0), 0.0, 0.01), square(3.0));
        assert!(round_outline(&Vec::new(), 1.0, 0.01).is_empty());
        // No extent that a grid can hold: no offset.
        let far = vec![vec![vec![[0.0, 0.0], [f64::INFINITY, 0.0], [0.0, 1.0]]]];
        assert!(round_outline(&far, 1.0, 0.01).is_empty());
        assert!(round_outline(&square(3.0), f64::NAN, 0.01).is_empty());
        // Far enough in, nothing is left; outward, a square on a grid of its own far
        // from the origin comes back a square with round corners, its sides exact.
        assert!(round_outline(&square(3.0), -1.5, 0.01).is_empty());
        let off: Shapes = vec![vec![rect(1000.0, -2000.0, 1003.0, -1997.0)]];
        let grown = round_outline(&off, 0.5, 0.001);
        let xs = grown[0][0].iter().map(|p| p[0]);
        let (lo, hi) = (xs.clone().fold(f64::MAX, f64::min), xs.fold(f64::MIN, f64::max));
        assert!(
            (lo - 999.5).abs() < 1e-6 && (hi - 1003.5).abs() < 1e-6,
            "{lo} {hi}"
        );
        let area = ring_area(&grown[0][0]);
        assert!((area - (9.0 + 12.0 * 0.5 + PI * 0.25)).abs() < 2e-3, "{area}");
        // Grown far beyond its own size, the grid still holds the offset: a disc of
        // radius 100 about a 1 mm square.
        let disc = round_outline(&square(1.0), 100.0, 0.01);
        let area = ring_area(&disc[0][0]);
        let exact = 1.0 + 400.0 + PI * 1e4;
        assert!((area - exact).abs() < 1e-3 * exact, "{area} against {exact}");
        assert!(tidy(vec![vec![vec![[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]]]], 0.01).is_empty());
    }
}
