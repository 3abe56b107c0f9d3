//! A sub-region's reference point, the one point a grader that varies with position
//! evaluates for the whole region, chosen by one rule wherever the region comes from:
//! the centre of a circumferential cell (topological-hierarchy Fig. 14), and elsewhere
//! a point inside the region, central across its width. A family graded whole and the
//! same family as the one region of a discretiser get the same point.

use crate::centroid::polygon_centroid;
use crate::segment::closest_on_segment;
use crate::shape::{Point2, Polygon};

/// The reference point of a region that is not a cell: [`interior_point`], or the
/// middle of its box for a region too thin to find one in.
pub fn reference_point(polygon: &Polygon) -> Point2 {
    interior_point(polygon).unwrap_or_else(|| polygon.bbox().center())
}

/// A point inside the polygon, central across its width: the midpoint of the widest
/// inside interval of a few horizontal scan lines. Cheap (no distance queries); `None`
/// when no scan line finds an inside.
pub fn interior_point(polygon: &Polygon) -> Option<Point2> {
    let bbox = polygon.bbox();
    let mut best: Option<(f64, Point2)> = None;
    let mut xs = Vec::new();
    // Odd fractions avoid scanning exactly through vertices of axis-aligned shapes.
    for f in [0.5013, 0.2507, 0.7493, 0.1249, 0.3751, 0.6249, 0.8751] {
        let y = bbox.min.y + f * bbox.height();
        xs.clear();
        for c in polygon.contours() {
            for (a, b) in c.edges() {
                if (a.y <= y) != (b.y <= y) {
                    xs.push(a.x + (y - a.y) / (b.y - a.y) * (b.x - a.x));
                }
            }
        }
        xs.sort_unstable_by(f64::total_cmp);
        for pair in xs.chunks_exact(2) {
            let width = pair[1] - pair[0];
            if width > best.map_or(0.0, |b| b.0) {
                best = Some((width, Point2::new(0.5 * (pair[0] + pair[1]), y)));
            }
        }
        if best.is_some() && f < 0.5 {
            // One line through the middle and one more are enough for a reference.
            break;
        }
    }
    best.map(|b| b.1)
}

/// The reference point of a circumferential cell: its centre, as the paper locates it
/// (topological-hierarchy Fig. 14), that is the centroid of its area. A cell that
/// wraps around a corner of its ring (an L) has its centroid outside it; a composition
/// is the cell's own only at a point of the cell, so it takes the point of the cell
/// nearest its centroid (a hair inside the boundary), and a central point inside it
/// ([`interior_point`]) should that fail.
pub fn cell_centre(polygon: &Polygon) -> Option<Point2> {
    let c = polygon_centroid(polygon)?;
    if polygon.contains(c) {
        return Some(c);
    }
    let q = polygon
        .contours()
        .flat_map(|r| r.edges())
        .map(|(a, b)| closest_on_segment(c, a, b))
        .min_by(|p, q| (p - c).norm_squared().total_cmp(&(q - c).norm_squared()));
    // From outside, the way to the nearest boundary point goes on into the cell.
    let hair = 1e-6 * polygon.bbox().diagonal().max(1e-3);
    q.and_then(|q| {
        let d = q - c;
        let n = d.norm();
        (n > 0.0).then(|| q + d * (hair / n))
    })
    .filter(|&p| polygon.contains(p))
    .or_else(|| interior_point(polygon))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shape::Contour;

    fn square(x: f64, y: f64, w: f64, h: f64) -> Contour {
        Contour::new(vec![
            Point2::new(x, y),
            Point2::new(x + w, y),
            Point2::new(x + w, y + h),
            Point2::new(x, y + h),
        ])
    }

    fn circle(r: f64, n: usize) -> Contour {
        Contour::new(
            (0..n)
                .map(|i| {
                    let a = std::f64::consts::TAU * i as f64 / n as f64;
                    Point2::new(r * a.cos(), r * a.sin())
                })
                .collect(),
        )
    }

    #[test]
    fn the_centre_of_a_ring_and_of_an_l() {
        // A 10 x 10 square less a 2 x 2 hole off centre (1..3): centroid by moments.
        let ring = Polygon::new(
            square(0.0, 0.0, 10.0, 10.0),
            vec![square(1.0, 1.0, 2.0, 2.0).oriented(false)],
        );
        let c = polygon_centroid(&ring).expect("an area");
        let want = (100.0 * 5.0 - 4.0 * 2.0) / 96.0;
        assert!((c.x - want).abs() < 1e-12 && (c.y - want).abs() < 1e-12, "{c:?}");
        // Inside: the centroid itself.
        assert_eq!(cell_centre(&ring), Some(c));
        // An L (4 x 1 and 1 x 4 legs): its centroid (19/14, 19/14) lies in the notch,
        // outside; the centre is the point of the L nearest to it, on one of the inner
        // edges, 5/14 mm away.
        let l = Polygon::new(
            Contour::new(
                [
                    (0.0, 0.0),
                    (4.0, 0.0),
                    (4.0, 1.0),
                    (1.0, 1.0),
                    (1.0, 4.0),
                    (0.0, 4.0),
                ]
                .map(|(x, y)| Point2::new(x, y))
                .to_vec(),
            ),
            vec![],
        );
        let c = polygon_centroid(&l).expect("an area");
        assert!(!l.contains(c));
        let p = cell_centre(&l).expect("a point");
        assert!(l.contains(p));
        assert!(((p - c).norm() - 5.0 / 14.0).abs() < 1e-4, "{p:?}");
        assert!((p.x - 1.0).abs() < 1e-4 || (p.y - 1.0).abs() < 1e-4, "{p:?}");
    }

    #[test]
    fn scan_lines_cross_slanted_edges_where_they_are() {
        // A right triangle with legs of 4, its right angle at (0, 1): the middle line
        // crosses from the vertical leg at x = 0 to the hypotenuse at x = 5 - y; the
        // line a quarter up is wider, and its middle is taken.
        let t = Polygon::new(
            Contour::new(vec![
                Point2::new(0.0, 1.0),
                Point2::new(4.0, 1.0),
                Point2::new(0.0, 5.0),
            ]),
            vec![],
        );
        let y = 1.0 + 4.0 * 0.2507;
        let p = interior_point(&t).expect("inside");
        assert!(
            (p.y - y).abs() < 1e-12 && (p.x - 0.5 * (5.0 - y)).abs() < 1e-12,
            "{p:?}"
        );
        // Turned upside down, the widest line is the middle one after all: a line a
        // quarter up is narrower, and the middle line stands.
        let v = Polygon::new(
            Contour::new(vec![
                Point2::new(0.0, 0.0),
                Point2::new(4.0, 4.0),
                Point2::new(0.0, 4.0),
            ]),
            vec![],
        );
        let y = 4.0 * 0.5013;
        let p = interior_point(&v).expect("inside");
        assert!((p.y - y).abs() < 1e-12 && (p.x - 0.5 * y).abs() < 1e-12, "{p:?}");
    }

    #[test]
    fn the_interior_point_is_central_across_the_widest_span() {
        // A tube (r 10 and 5): the middle line crosses walls 5 mm wide; the second line,
        // a quarter up, grazes the hole and finds a wider inside, from the hole's
        // x = sqrt(25 - y²) to the outside's sqrt(100 - y²), whose middle it takes.
        let tube = Polygon::new(circle(10.0, 256), vec![circle(5.0, 256).oriented(false)]);
        let p = interior_point(&tube).expect("inside");
        assert!(tube.contains(p));
        let y: f64 = -10.0 + 20.0 * 0.2507;
        let x = 0.5 * ((25.0 - y * y).sqrt() + (100.0 - y * y).sqrt());
        assert!((p.y - y).abs() < 1e-9 && (p.x.abs() - x).abs() < 0.02, "{p:?}");
        // A rectangle: the middle of its middle line (the first fraction, 0.5013).
        let r = Polygon::new(square(0.0, 0.0, 10.0, 4.0), vec![]);
        let p = reference_point(&r);
        assert!(
            (p.x - 5.0).abs() < 1e-12 && (p.y - 4.0 * 0.5013).abs() < 1e-12,
            "{p:?}"
        );
        // A sliver with no inside on any scan line: the middle of its box.
        let flat = Polygon::new(
            Contour::new(vec![
                Point2::new(0.0, 1.0),
                Point2::new(4.0, 1.0),
                Point2::new(2.0, 1.0),
            ]),
            vec![],
        );
        assert_eq!(reference_point(&flat), Point2::new(2.0, 1.0));
    }
}
