//! Centroids of the areas contours and polygons bound: where a region's centre is
//! (a cell's reference point, the centre a radial line starts from).

use crate::shape::{Contour, Point2, Polygon};

/// The unsigned area a closed contour bounds and its first moments (area times the
/// centroid's x and y), whatever its orientation; summed relative to its first point
/// for precision far from the origin. Zero for a contour without area.
fn moments(c: &Contour) -> (f64, f64, f64) {
    let Some(&o) = c.points.first() else {
        return (0.0, 0.0, 0.0);
    };
    let (mut twice, mut mx, mut my) = (0.0, 0.0, 0.0);
    for (a, b) in c.edges() {
        let (a, b) = (a - o, b - o);
        let cross = a.x * b.y - b.x * a.y;
        twice += cross;
        mx += (a.x + b.x) * cross;
        my += (a.y + b.y) * cross;
    }
    if twice == 0.0 {
        return (0.0, 0.0, 0.0);
    }
    let area = (twice / 2.0).abs();
    let (cx, cy) = (o.x + mx / (3.0 * twice), o.y + my / (3.0 * twice));
    (area, area * cx, area * cy)
}

/// The centroid of the area a closed contour bounds; `None` without area.
pub fn contour_centroid(c: &Contour) -> Option<Point2> {
    let (a, mx, my) = moments(c);
    (a > 0.0).then(|| Point2::new(mx / a, my / a))
}

/// The centroid of a polygon's material area (the outer region less the holes);
/// `None` without area. It may lie outside the polygon (a ring, a cell bent around a
/// corner).
pub fn polygon_centroid(polygon: &Polygon) -> Option<Point2> {
    let (mut a, mut mx, mut my) = moments(&polygon.outer);
    for h in &polygon.holes {
        let (ha, hx, hy) = moments(h);
        a -= ha;
        mx -= hx;
        my -= hy;
    }
    (a > 0.0).then(|| Point2::new(mx / a, my / a))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn contour(points: &[(f64, f64)]) -> Contour {
        Contour::new(points.iter().map(|&(x, y)| Point2::new(x, y)).collect())
    }

    fn close(p: Point2, x: f64, y: f64, tol: f64) -> bool {
        (p.x - x).abs() < tol && (p.y - y).abs() < tol
    }

    #[test]
    fn a_contours_centroid_is_its_areas_either_way_round() {
        // A triangle: the mean of its corners.
        let t = contour(&[(1.0, 2.0), (7.0, 3.0), (2.0, 11.0)]);
        let c = contour_centroid(&t).expect("an area");
        assert!(close(c, 10.0 / 3.0, 16.0 / 3.0, 1e-12), "{c:?}");
        assert!(close(
            contour_centroid(&t.clone().oriented(false)).expect("an area"),
            10.0 / 3.0,
            16.0 / 3.0,
            1e-12
        ));
        // An L of a 4 x 1 and a 1 x 3 rectangle: their centroids weighted by area.
        let l = contour(&[
            (0.0, 0.0),
            (4.0, 0.0),
            (4.0, 1.0),
            (1.0, 1.0),
            (1.0, 4.0),
            (0.0, 4.0),
        ]);
        let want = ((4.0 * 2.0 + 3.0 * 0.5) / 7.0, (4.0 * 0.5 + 3.0 * 2.5) / 7.0);
        let c = contour_centroid(&l).expect("an area");
        assert!(close(c, want.0, want.1, 1e-12), "{c:?}");
        let c = contour_centroid(&l.oriented(false)).expect("an area");
        assert!(close(c, want.0, want.1, 1e-12), "{c:?}");
    }

    #[test]
    fn far_from_the_origin_the_centroid_keeps_its_precision() {
        // A 1 um square a thousand kilometres out: summed about the first point, its
        // centroid is exact to far below its size.
        let (x0, y0, s) = (1.0e9, -2.0e9, 1e-3);
        let sq = contour(&[(x0, y0), (x0 + s, y0), (x0 + s, y0 + s), (x0, y0 + s)]);
        let c = contour_centroid(&sq).expect("an area");
        assert!(close(c, x0 + s / 2.0, y0 + s / 2.0, 1e-6), "{c:?}");
    }

    #[test]
    fn contours_without_area_have_no_centroid() {
        assert!(contour_centroid(&contour(&[])).is_none());
        assert!(contour_centroid(&contour(&[(1.0, 1.0), (2.0, 2.0), (3.0, 3.0)])).is_none());
        let p = Polygon::new(
            contour(&[(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]),
            vec![contour(&[(0.0, 0.0), (0.0, 1.0), (1.0, 1.0), (1.0, 0.0)])],
        );
        assert!(polygon_centroid(&p).is_none());
    }

    #[test]
    fn a_polygons_centroid_leaves_its_holes_out() {
        // A 10 x 6 plate with a 2 x 2 hole at (6..8, 1..3), holes clockwise or not.
        let outer = contour(&[(0.0, 0.0), (10.0, 0.0), (10.0, 6.0), (0.0, 6.0)]);
        let hole = contour(&[(6.0, 1.0), (8.0, 1.0), (8.0, 3.0), (6.0, 3.0)]);
        let want = ((60.0 * 5.0 - 4.0 * 7.0) / 56.0, (60.0 * 3.0 - 4.0 * 2.0) / 56.0);
        for h in [hole.clone(), hole.oriented(false)] {
            let p = Polygon::new(outer.clone(), vec![h]);
            let c = polygon_centroid(&p).expect("an area");
            assert!(close(c, want.0, want.1, 1e-12), "{c:?}");
        }
        // A ring about a point: its centroid is the centre, outside its material.
        let ring = Polygon::new(
            Contour::circle(Point2::new(3.0, -4.0), 5.0, 64),
            vec![Contour::circle(Point2::new(3.0, -4.0), 4.0, 64).oriented(false)],
        );
        let c = polygon_centroid(&ring).expect("an area");
        assert!(close(c, 3.0, -4.0, 1e-9) && !ring.contains(c), "{c:?}");
    }
}
