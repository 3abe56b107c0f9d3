//! Points against segments: the nearest point and the distance, in the two forms the
//! stages hold coordinates in (nalgebra points, and `[x, y]` arrays for the boolean
//! engine's rings). Both forms compute the same thing the same way.

use crate::shape::Point2;

/// Distance from `p` to segment `ab`.
pub fn segment_distance(p: Point2, a: Point2, b: Point2) -> f64 {
    (p - closest_on_segment(p, a, b)).norm()
}

/// The point of segment `ab` closest to `p`.
pub fn closest_on_segment(p: Point2, a: Point2, b: Point2) -> Point2 {
    a + (b - a) * segment_parameter(p, a, b)
}

/// Where `p` projects onto segment `ab`: 0 at `a`, 1 at `b`, clamped to the segment
/// (0 for a segment of no length).
pub fn segment_parameter(p: Point2, a: Point2, b: Point2) -> f64 {
    let ab = b - a;
    let len2 = ab.norm_squared();
    if len2 == 0.0 {
        return 0.0;
    }
    ((p - a).dot(&ab) / len2).clamp(0.0, 1.0)
}

/// Squared distance from `p` to segment `ab`, on `[x, y]` arrays: the same nearest
/// point as [`closest_on_segment`], without the root (callers comparing with a squared
/// tolerance need none).
pub fn segment_distance2(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let ab = [b[0] - a[0], b[1] - a[1]];
    let len2 = ab[0] * ab[0] + ab[1] * ab[1];
    let t = if len2 > 0.0 {
        (((p[0] - a[0]) * ab[0] + (p[1] - a[1]) * ab[1]) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let d = [p[0] - (a[0] + ab[0] * t), p[1] - (a[1] + ab[1] * t)];
    d[0] * d[0] + d[1] * d[1]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn both_forms_agree() {
        let (p, a, b) = (
            Point2::new(3.0, 4.0),
            Point2::new(0.0, 0.0),
            Point2::new(10.0, 0.0),
        );
        assert_eq!(segment_distance(p, a, b), 4.0);
        assert_eq!(segment_distance2([3.0, 4.0], [0.0, 0.0], [10.0, 0.0]), 16.0);
        // Beyond an end the nearest point is the end.
        assert_eq!(segment_distance(Point2::new(13.0, 4.0), a, b), 5.0);
        assert_eq!(segment_distance2([13.0, 4.0], [0.0, 0.0], [10.0, 0.0]), 25.0);
        // A degenerate segment is its point.
        assert_eq!(segment_distance2([3.0, 4.0], [0.0, 0.0], [0.0, 0.0]), 25.0);
    }
}
