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

    #[test]
    fn the_nearest_point_is_the_foot_or_an_end() {
        let (a, b) = (Point2::new(1.0, 2.0), Point2::new(5.0, 5.0));
        // The foot of the perpendicular from a point beside the middle, a quarter of the
        // way along; beyond either end, that end.
        let beside = Point2::new(2.0 - 3.0, 2.75 + 4.0);
        assert!((segment_parameter(beside, a, b) - 0.25).abs() < 1e-12);
        assert!((closest_on_segment(beside, a, b) - Point2::new(2.0, 2.75)).norm() < 1e-12);
        assert!((segment_distance(beside, a, b) - 5.0).abs() < 1e-12);
        assert_eq!(segment_parameter(Point2::new(9.0, 8.0), a, b), 1.0);
        assert_eq!(closest_on_segment(Point2::new(9.0, 8.0), a, b), b);
        assert_eq!(segment_parameter(Point2::new(-3.0, -1.0), a, b), 0.0);
        assert_eq!(closest_on_segment(Point2::new(-3.0, -1.0), a, b), a);
        // A segment of no length is its point.
        assert_eq!(segment_parameter(beside, a, a), 0.0);
        assert_eq!(segment_distance(Point2::new(4.0, 6.0), a, a), 5.0);
    }

    #[test]
    fn distances_are_the_least_over_the_segments_points() {
        let mut rng = fastrand::Rng::with_seed(0x9e37_79b9_7f4a_7c15);
        let mut random = move || rng.f64() * 20.0 - 10.0;
        for _ in 0..500 {
            let (p, a, b) = ([random(), random()], [random(), random()], [random(), random()]);
            let sampled = (0..=4000)
                .map(|k| {
                    let t = f64::from(k) / 4000.0;
                    let q = [a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t];
                    (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)
                })
                .fold(f64::INFINITY, f64::min);
            let d2 = segment_distance2(p, a, b);
            // The least over the samples is at most a sample's step beyond the exact one.
            assert!(
                d2 <= sampled + 1e-9 && sampled.sqrt() - d2.sqrt() < 0.01,
                "{p:?} {a:?} {b:?}"
            );
            let d = segment_distance(
                Point2::new(p[0], p[1]),
                Point2::new(a[0], a[1]),
                Point2::new(b[0], b[1]),
            );
            assert!((d * d - d2).abs() < 1e-9);
        }
    }
}
