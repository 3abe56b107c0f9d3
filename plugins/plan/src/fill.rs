//! Contour-parallel fill of one sub-region: closed loops along the iso-material
//! contours (the region's boundary offset inward by w/2, 3w/2, ...). Each loop's bead
//! covers the band within w/2 of it, so consecutive loops w apart neither leave a gap
//! nor deposit twice; what stays uncovered is the part of the medial band narrower
//! than one width.

use i_overlay::mesh::float::outline::offset::OutlineOffset;
use i_overlay::mesh::float::style::{LineJoin, OutlineStyle};
use lamina_core::{Point2, Polygon};

/// Largest distance (mm) between a round offset corner and its chords.
const TOLERANCE: f64 = 0.005;

/// Upper bound on passes per region, so a huge region with a tiny width cannot run
/// away with memory.
const MAX_PASSES: usize = 100_000;

/// One closed pass: `points.first() == points.last()`.
#[derive(Debug, Clone, PartialEq)]
pub struct Loop {
    pub points: Vec<Point2>,
}

impl Loop {
    pub fn length(&self) -> f64 {
        self.points.windows(2).map(|w| (w[1] - w[0]).norm()).sum()
    }

    /// Restarts the closed loop at vertex `i` (the seam), keeping start = end.
    pub fn rotated(&self, i: usize) -> Loop {
        let n = self.points.len().saturating_sub(1);
        if n == 0 || i == 0 || i >= n {
            return self.clone();
        }
        let mut points: Vec<Point2> = self.points[i..n].to_vec();
        points.extend_from_slice(&self.points[..=i]);
        Loop { points }
    }

    /// Index and distance of the vertex nearest to `p`.
    pub fn nearest_vertex(&self, p: Point2) -> (usize, f64) {
        let n = self.points.len().saturating_sub(1).max(1).min(self.points.len());
        let mut best = (0, f64::INFINITY);
        for (i, q) in self.points[..n].iter().enumerate() {
            let d2 = (q - p).norm_squared();
            if d2 < best.1 {
                best = (i, d2);
            }
        }
        (best.0, best.1.sqrt())
    }

    /// Index of the vertex with the largest x (then largest y): an aligned seam.
    pub fn max_x_vertex(&self) -> usize {
        let n = self.points.len().saturating_sub(1).max(1);
        let mut best = 0;
        for (i, q) in self.points[..n.min(self.points.len())].iter().enumerate() {
            let b = self.points[best];
            if q.x > b.x || (q.x == b.x && q.y > b.y) {
                best = i;
            }
        }
        best
    }
}

fn shapes_of(p: &Polygon) -> Vec<Vec<Vec<[f64; 2]>>> {
    vec![
        p.contours()
            .map(|c| c.points.iter().map(|q| [q.x, q.y]).collect())
            .collect(),
    ]
}

/// The passes filling `polygon` at extrusion width `width`, outermost first. Empty
/// when the region is thinner than one width everywhere.
pub fn contour_passes(polygon: &Polygon, width: f64) -> Vec<Loop> {
    let mut loops = Vec::new();
    if width.is_nan() || width <= 0.0 || polygon.outer.len() < 3 || polygon.area() <= 0.0 {
        return loops;
    }
    // Each pass is the previous one offset by one width (the first by half a width):
    // erosions by discs compose, and small offsets need far fewer arc segments for the
    // same chord tolerance than one large offset of the region.
    let mut current = shapes_of(polygon);
    for k in 0..MAX_PASSES {
        let d = if k == 0 { width / 2.0 } else { width };
        let step = 2.0 * (1.0 - (TOLERANCE / d).min(1.0)).acos();
        let style = OutlineStyle::new(-d).line_join(LineJoin::Round(step.max(0.01)));
        let inset: Vec<Vec<Vec<[f64; 2]>>> = current.outline(&style);
        if inset.is_empty() {
            break;
        }
        for shape in &inset {
            for contour in shape {
                if contour.len() < 3 {
                    continue;
                }
                let contour = simplify(contour, TOLERANCE);
                if contour.len() < 3 {
                    continue;
                }
                let mut points: Vec<Point2> = contour.iter().map(|q| Point2::new(q[0], q[1])).collect();
                points.push(points[0]);
                loops.push(Loop { points });
            }
        }
        // Offsets of offsets would multiply the arc vertices pass after pass.
        current = inset
            .into_iter()
            .map(|shape| {
                shape
                    .into_iter()
                    .map(|c| simplify(&c, TOLERANCE))
                    .filter(|c| c.len() >= 3)
                    .collect()
            })
            .filter(|s: &Vec<Vec<[f64; 2]>>| !s.is_empty())
            .collect();
    }
    loops
}

/// A closed ring with the vertices dropped that stray less than `tol` from the chord
/// replacing them (greedy, runs of at most 64 vertices).
pub fn simplify(ring: &[[f64; 2]], tol: f64) -> Vec<[f64; 2]> {
    let n = ring.len();
    if n <= 3 {
        return ring.to_vec();
    }
    let mut out = Vec::with_capacity(n / 2 + 3);
    let mut a = 0;
    out.push(ring[0]);
    while a < n {
        // Extend the chord from `a` as far as every skipped vertex stays within `tol`.
        let mut b = a + 1;
        while b < n && b - a < 64 {
            let next = b + 1;
            let end = ring[next % n];
            let ok = (a + 1..next).all(|k| chord_distance(ring[k % n], ring[a % n], end) <= tol);
            if !ok {
                break;
            }
            b = next;
        }
        if b >= n {
            break;
        }
        out.push(ring[b % n]);
        a = b;
    }
    out
}

fn chord_distance(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    lamina_core::geom::segment_distance(
        Point2::new(p[0], p[1]),
        Point2::new(a[0], a[1]),
        Point2::new(b[0], b[1]),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use lamina_core::Contour;

    fn square(c: f64, h: f64) -> Contour {
        Contour::new(vec![
            Point2::new(c - h, c - h),
            Point2::new(c + h, c - h),
            Point2::new(c + h, c + h),
            Point2::new(c - h, c + h),
        ])
    }

    #[test]
    fn a_square_gets_concentric_closed_loops() {
        let p = Polygon::new(square(0.0, 5.0), vec![]);
        let loops = contour_passes(&p, 0.4);
        // Offsets at 0.2, 0.6, ..., 4.6 (12 passes; 5.0 is the inradius).
        assert_eq!(loops.len(), 12, "{}", loops.len());
        for l in &loops {
            assert_eq!(l.points.first(), l.points.last());
        }
        let deposited: f64 = loops.iter().map(|l| l.length() * 0.4).sum();
        assert!((deposited - p.area()).abs() / p.area() < 0.02, "{deposited}");
    }

    #[test]
    fn a_ring_gets_loops_around_the_hole_and_a_thin_region_none() {
        let p = Polygon::new(square(0.0, 5.0), vec![square(0.0, 3.0).oriented(false)]);
        let loops = contour_passes(&p, 0.4);
        // A 2 mm band: passes at 0.2 and 0.6 mm from each side, and small loops in the
        // four thicker corners; along the sides the medial band 0.8..1.2 mm (one width)
        // stays open rather than being deposited twice.
        assert_eq!(loops.len(), 8);
        let deposited: f64 = loops.iter().map(|l| l.length() * 0.4).sum();
        let gap = 8.0 * 4.0 * 0.4;
        assert!(
            deposited <= p.area() && deposited + gap >= p.area() - 0.5,
            "{deposited} vs {}",
            p.area()
        );
        let thin = Polygon::new(square(0.0, 0.15), vec![]);
        assert!(contour_passes(&thin, 0.4).is_empty());
    }

    #[test]
    fn seams_rotate_and_keep_the_loop_closed() {
        let l = Loop {
            points: vec![
                Point2::new(0.0, 0.0),
                Point2::new(1.0, 0.0),
                Point2::new(1.0, 1.0),
                Point2::new(0.0, 1.0),
                Point2::new(0.0, 0.0),
            ],
        };
        assert_eq!(l.max_x_vertex(), 2);
        let r = l.rotated(2);
        assert_eq!(r.points.first(), Some(&Point2::new(1.0, 1.0)));
        assert_eq!(r.points.first(), r.points.last());
        assert!((r.length() - 4.0).abs() < 1e-12);
        assert_eq!(l.nearest_vertex(Point2::new(0.1, 0.9)).0, 3);
    }
}
