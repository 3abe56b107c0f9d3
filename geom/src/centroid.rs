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
