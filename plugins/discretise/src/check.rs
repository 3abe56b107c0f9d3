//! Checks that sub-regions tile their family: areas add up, no two overlap (measured by
//! a boolean union), every ring of every region (and of the family) is simple and
//! oriented (outer counter-clockwise, holes clockwise). Simple means what OGC asks of a
//! ring: no two edges meet except neighbours at their shared vertex, so a ring that
//! crosses itself, visits a vertex twice or touches itself (a vertex on another edge,
//! an edge folding back over the previous one) is not. Used by the tests and the
//! acceptance suite on real models.

use i_overlay::core::fill_rule::FillRule;
use i_overlay::core::overlay_rule::OverlayRule;
use i_overlay::float::single::SingleFloatOverlay;
use lamina_api::{Contour, Polygon, SubRegion};
use lamina_geom::Ring;
use lamina_geom::ring::{ring_area, ring_of};

/// How well a set of regions tiles a family.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tiling {
    pub family_area: f64,
    /// Sum of the regions' areas.
    pub region_area: f64,
    /// |region area - family area| / family area.
    pub area_error: f64,
    /// Area covered more than once (sum of areas less the area of their union), relative
    /// to the family's area.
    pub overlap: f64,
    /// Contours wrongly oriented (outer clockwise or hole counter-clockwise).
    pub misoriented: usize,
    /// SubRegion contours that are not simple ([`is_simple`]).
    pub non_simple: usize,
    /// The family's own contours that are not simple (the slicer's output): reported,
    /// not part of [`Tiling::is_ok`], as a discretiser is given families of any shape
    /// and must still tile them with simple regions.
    pub family_non_simple: usize,
}

impl Tiling {
    /// Within the targets: 1e-3 of the area, no overlap, every polygon valid.
    pub fn is_ok(&self, tolerance: f64) -> bool {
        self.area_error <= tolerance
            && self.overlap <= tolerance
            && self.misoriented == 0
            && self.non_simple == 0
    }
}

/// Measures how `regions` tile `family`.
pub fn tiling(family: &Polygon, regions: &[SubRegion]) -> Tiling {
    let family_area = family.area();
    let region_area: f64 = regions.iter().map(SubRegion::area).sum();
    let paths: Vec<Ring> = regions
        .iter()
        .flat_map(|r| r.polygon.contours())
        .map(ring_of)
        .collect();
    let empty: Vec<Ring> = Vec::new();
    // Each region's holes are clockwise: the positive rule counts every covered point
    // once, the union's area is what the regions cover.
    let union = if paths.is_empty() {
        Vec::new()
    } else {
        paths.overlay(&empty, OverlayRule::Subject, FillRule::Positive)
    };
    let union_area: f64 = union.iter().flatten().map(|c| ring_area(c)).sum();
    let scale = family_area.abs().max(f64::MIN_POSITIVE);
    let mut misoriented = 0;
    let mut non_simple = 0;
    for r in regions {
        if !r.polygon.outer.is_ccw() {
            misoriented += 1;
        }
        misoriented += r.polygon.holes.iter().filter(|h| h.is_ccw()).count();
        non_simple += r.polygon.contours().filter(|c| !is_simple(c)).count();
    }
    let family_non_simple = family.contours().filter(|c| !is_simple(c)).count();
    Tiling {
        family_area,
        region_area,
        area_error: (region_area - family_area).abs() / scale,
        overlap: ((region_area - union_area) / scale).max(0.0),
        misoriented,
        non_simple,
        family_non_simple,
    }
}

/// Whether a contour is a simple ring: at least 3 points, no zero-length edge, no
/// vertex visited twice, no two edges meeting anywhere but at the vertex neighbours
/// share, no neighbour folding back over the other. Exact: the overlay's output is on a
/// power-of-two grid, so a vertex it visits twice repeats bit for bit.
pub fn is_simple(c: &Contour) -> bool {
    let n = c.len();
    if n < 3 {
        return false;
    }
    let p = &c.points;
    let mut keys: Vec<(u64, u64)> = p.iter().map(|q| (q.x.to_bits(), q.y.to_bits())).collect();
    keys.sort_unstable();
    if keys.windows(2).any(|w| w[0] == w[1]) {
        return false;
    }
    // Neighbours (a, b), (b, c) folding back: c on the line through a and b, on a's side.
    let folds = (0..n).any(|i| {
        let (a, b, q) = (p[i], p[(i + 1) % n], p[(i + 2) % n]);
        orient(a, b, q) == 0.0 && (a - b).dot(&(q - b)) > 0.0
    });
    !folds && meetings(c, false) == 0
}

/// Pairs of non-adjacent edges of one contour that meet: at a point interior to both
/// (a crossing), or anywhere, touches included, unless `proper_only`.
fn meetings(c: &Contour, proper_only: bool) -> usize {
    let n = c.len();
    if n < 4 {
        return 0;
    }
    let edges: Vec<_> = c.edges().collect();
    let mut order: Vec<usize> = (0..n).collect();
    let lo = |i: usize| edges[i].0.x.min(edges[i].1.x);
    let hi = |i: usize| edges[i].0.x.max(edges[i].1.x);
    order.sort_unstable_by(|&a, &b| lo(a).total_cmp(&lo(b)));
    let mut active: Vec<usize> = Vec::new();
    let mut count = 0;
    for &i in &order {
        let x = lo(i);
        active.retain(|&j| hi(j) >= x);
        for &j in &active {
            let adjacent = (i + 1) % n == j || (j + 1) % n == i;
            let hit = if proper_only {
                crosses(edges[i], edges[j])
            } else {
                meets(edges[i], edges[j])
            };
            if !adjacent && hit {
                count += 1;
            }
        }
        active.push(i);
    }
    count
}

/// Proper crossings between non-adjacent edges of one contour, found by a sweep over
/// the edges sorted by their lowest x. Touches are not crossings: use [`is_simple`].
pub fn self_crossings(c: &Contour) -> usize {
    meetings(c, true)
}

type Seg = (lamina_api::Point2, lamina_api::Point2);

fn orient(p: lamina_api::Point2, q: lamina_api::Point2, r: lamina_api::Point2) -> f64 {
    (q.x - p.x) * (r.y - p.y) - (q.y - p.y) * (r.x - p.x)
}

/// Whether two segments cross at a point interior to both.
fn crosses((a, b): Seg, (c, d): Seg) -> bool {
    let d1 = orient(a, b, c);
    let d2 = orient(a, b, d);
    let d3 = orient(c, d, a);
    let d4 = orient(c, d, b);
    d1 * d2 < 0.0 && d3 * d4 < 0.0
}

/// Whether two closed segments share a point: a crossing, an end on the other segment
/// (a shared vertex included), or a collinear overlap.
fn meets((a, b): Seg, (c, d): Seg) -> bool {
    if crosses((a, b), (c, d)) {
        return true;
    }
    let within = |p: lamina_api::Point2, q: lamina_api::Point2, r: lamina_api::Point2| {
        r.x >= p.x.min(q.x) && r.x <= p.x.max(q.x) && r.y >= p.y.min(q.y) && r.y <= p.y.max(q.y)
    };
    (orient(a, b, c) == 0.0 && within(a, b, c))
        || (orient(a, b, d) == 0.0 && within(a, b, d))
        || (orient(c, d, a) == 0.0 && within(c, d, a))
        || (orient(c, d, b) == 0.0 && within(c, d, b))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shapes::through as pts;
    use lamina_api::Point2;

    #[test]
    fn a_bow_tie_crosses_itself() {
        let bow = Contour::new(vec![
            Point2::new(0.0, 0.0),
            Point2::new(1.0, 1.0),
            Point2::new(1.0, 0.0),
            Point2::new(0.0, 1.0),
        ]);
        assert_eq!(self_crossings(&bow), 1);
        assert_eq!(self_crossings(&crate::shapes::rect(0.0, 0.0, 1.0, 1.0)), 0);
        assert!(!is_simple(&bow));
        assert!(is_simple(&crate::shapes::rect(0.0, 0.0, 1.0, 1.0)));
    }

    /// 3DBenchy's layers 44-52: a hole ring ...A, B, C, A... with a sub-micron lobe.
    /// It crosses nothing, so only the touch test sees it.
    #[test]
    fn a_ring_through_a_vertex_twice_is_not_simple() {
        let pinched = pts(&[
            (5.0, 5.0),
            (5.0, 15.0),
            (15.0, 15.0),
            (15.0, 5.0),
            (9.0, 5.0),
            (10.0, 5.01),
            (8.5, 5.0),
            (9.0, 5.0),
            (8.0, 4.99),
        ]);
        assert_eq!(self_crossings(&pinched), 0);
        assert!(!is_simple(&pinched));
        // The same lobe without the repeated vertex: A's second visit moved onto the
        // edge before it (a T-touch), and an edge that folds back over the previous one.
        let touching = pts(&[(0.0, 0.0), (4.0, 0.0), (4.0, 4.0), (2.0, 0.0), (0.0, 4.0)]);
        assert!(!is_simple(&touching));
        assert_eq!(self_crossings(&touching), 0);
        let spike = pts(&[(0.0, 0.0), (2.0, 0.0), (1.0, 0.0), (1.0, 1.0)]);
        assert!(!is_simple(&spike));
        assert!(!is_simple(&pts(&[
            (0.0, 0.0),
            (1.0, 0.0),
            (1.0, 0.0),
            (0.0, 1.0)
        ])));
    }

    #[test]
    fn overlapping_regions_are_measured() {
        let family = Polygon::new(crate::shapes::rect(0.0, 0.0, 2.0, 1.0), vec![]);
        let region = |x: f64| SubRegion {
            family: 0,
            index: 0,
            count: 1,
            level: 0.0,
            polygon: Polygon::new(crate::shapes::rect(x, 0.0, 1.5, 1.0), vec![]),
            cell: None,
            reference: Point2::new(x, 0.5),
            composition: None,
            samples: Vec::new(),
        };
        let t = tiling(&family, &[region(0.0), region(0.5)]);
        assert!((t.overlap - 0.5).abs() < 1e-9, "{t:?}");
        assert!((t.area_error - 0.5).abs() < 1e-9);
    }

    fn region(outer: Contour, holes: Vec<Contour>) -> SubRegion {
        SubRegion::new(0, 0, 1, 0.0, Polygon::new(outer, holes))
    }

    /// Three points on a line, the third back between the first two: the ring folds
    /// over itself with no edge to meet but its neighbours. A point on a straight
    /// stretch of a ring does not fold.
    /// A touch is no crossing, from either segment's side and either way round; every
    /// end of either segment on the other one is a meeting.
    #[test]
    fn segments_cross_only_inside_both_and_meet_at_any_shared_point() {
        let p = |x: f64, y: f64| Point2::new(x, y);
        let base = (p(0.0, 0.0), p(4.0, 0.0));
        assert!(crosses(base, (p(2.0, -1.0), p(2.0, 1.0))));
        assert!(crosses((p(2.0, 1.0), p(2.0, -1.0)), base));
        for stem in [
            (p(2.0, 0.0), p(2.0, 2.0)),
            (p(2.0, 2.0), p(2.0, 0.0)),
            (p(2.0, 0.0), p(2.0, -2.0)),
            (p(2.0, -2.0), p(2.0, 0.0)),
        ] {
            assert!(!crosses(base, stem), "{stem:?}");
            assert!(!crosses(stem, base), "{stem:?}");
            assert!(meets(base, stem) && meets(stem, base), "{stem:?}");
        }
        // Apart, side by side on one line, or beyond an end.
        assert!(!meets(base, (p(0.0, 1.0), p(4.0, 1.0))));
        assert!(!meets(base, (p(5.0, 0.0), p(6.0, 0.0))));
        assert!(!meets(base, (p(5.0, -1.0), p(5.0, 1.0))));
        assert!(meets(base, (p(3.0, 0.0), p(6.0, 0.0))));
    }

    #[test]
    fn a_ring_that_folds_back_is_not_simple_and_a_straight_vertex_is() {
        assert!(!is_simple(&pts(&[(0.0, 0.0), (2.0, 0.0), (1.0, 0.0)])));
        assert!(is_simple(&pts(&[
            (0.0, 0.0),
            (1.0, 0.0),
            (2.0, 0.0),
            (2.0, 2.0),
            (0.0, 2.0)
        ])));
        assert!(!is_simple(&pts(&[(0.0, 0.0), (1.0, 1.0)])));
    }

    #[test]
    fn wrong_orientations_and_rings_that_are_not_simple_are_counted() {
        let family = Polygon::new(crate::shapes::rect(0.0, 0.0, 4.0, 4.0), vec![]);
        let square = |x: f64, y: f64| crate::shapes::rect(x, y, 2.0, 2.0).oriented(true);
        let bow = pts(&[(2.0, 2.0), (4.0, 4.0), (4.0, 2.0), (2.0, 4.0)]);
        let regions = [
            // Clockwise outside.
            region(square(0.0, 0.0).oriented(false), vec![]),
            // A hole counter-clockwise.
            region(
                square(2.0, 0.0),
                vec![crate::shapes::rect(2.5, 0.5, 1.0, 1.0).oriented(true)],
            ),
            region(square(0.0, 2.0), vec![]),
            region(bow.clone(), vec![]),
        ];
        let t = tiling(&family, &regions);
        // The bow tie's area is 0: not counter-clockwise either.
        assert_eq!(
            (t.misoriented, t.non_simple, t.family_non_simple),
            (3, 1, 0),
            "{t:?}"
        );
        assert!(!t.is_ok(1.0));
        // Two of each.
        let twice: Vec<_> = regions.iter().chain(&regions).cloned().collect();
        let t = tiling(&family, &twice);
        assert_eq!((t.misoriented, t.non_simple), (6, 2), "{t:?}");
        // A family that crosses itself is reported apart.
        let t = tiling(&Polygon::new(bow, vec![]), &[]);
        assert_eq!((t.family_non_simple, t.non_simple), (1, 0), "{t:?}");
    }

    #[test]
    fn a_tiling_is_ok_only_within_the_tolerance_and_with_every_ring_valid() {
        let good = Tiling {
            family_area: 1.0,
            region_area: 1.0,
            area_error: 1e-4,
            overlap: 1e-4,
            misoriented: 0,
            non_simple: 0,
            family_non_simple: 3,
        };
        assert!(good.is_ok(1e-3));
        for bad in [
            Tiling {
                area_error: 2e-3,
                ..good
            },
            Tiling {
                overlap: 2e-3,
                ..good
            },
            Tiling {
                misoriented: 1,
                ..good
            },
            Tiling {
                non_simple: 1,
                ..good
            },
        ] {
            assert!(!bad.is_ok(1e-3), "{bad:?}");
        }
        // Regions of the family's area, no more and no less, and none covering another.
        let family = Polygon::new(crate::shapes::rect(0.0, 0.0, 2.0, 1.0), vec![]);
        let halves = [
            region(crate::shapes::rect(0.0, 0.0, 1.0, 1.0).oriented(true), vec![]),
            region(crate::shapes::rect(1.0, 0.0, 1.0, 1.0).oriented(true), vec![]),
        ];
        let t = tiling(&family, &halves);
        assert!(t.is_ok(1e-9), "{t:?}");
        assert!(
            (t.region_area - 2.0).abs() < 1e-12 && t.overlap.abs() < 1e-12,
            "{t:?}"
        );
        assert!(!tiling(&family, &halves[..1]).is_ok(1e-3));
    }
}
