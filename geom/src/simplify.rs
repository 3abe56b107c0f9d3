//! One ring simplifier for every stage: fine grids and offsets of offsets leave
//! hundreds of vertices per millimetre of round or stepped boundary, and everything
//! downstream (offsets, booleans, toolpaths, files) pays for each of them.
//!
//! Greedy chords: from the ring's sharpest corner, a vertex is dropped while every
//! vertex skipped since the last one kept stays within `eps` of the chord that replaces
//! them. So no vertex of the original is further than `eps` from the result, and the
//! error never adds up along a gentle curve. Runs are capped at [`MAX_RUN`] vertices,
//! which bounds the work at `MAX_RUN` distance tests per vertex.

use crate::ring::Ring;
use crate::segment::segment_distance2;

/// Most vertices one chord may replace.
pub const MAX_RUN: usize = 64;

/// The ring without the vertices that lie within `eps` of the chord replacing them.
pub fn simplify_ring(ring: &[[f64; 2]], eps: f64) -> Ring {
    let mut out = Vec::with_capacity(ring.len() / 2 + 3);
    simplify_into(ring.len(), |i| ring[i], eps, &mut out);
    out
}

/// [`simplify_ring`] for a ring of `n` points given by `point(i)` (for callers holding
/// another point type), written into `out` so that a loop over many rings reuses one
/// buffer. Rings of fewer than three points are copied as they are.
pub fn simplify_into(n: usize, point: impl Fn(usize) -> [f64; 2], eps: f64, out: &mut Ring) {
    out.clear();
    if n < 3 {
        out.extend((0..n).map(&point));
        return;
    }
    let p = |i: usize| point(i % n);
    // Start at the sharpest corner, so that the vertex kept unconditionally is a real one.
    let start = (0..n)
        .max_by(|&a, &b| turn(p(a + n - 1), p(a), p(a + 1)).total_cmp(&turn(p(b + n - 1), p(b), p(b + 1))))
        .unwrap_or(0);
    let eps2 = eps * eps;
    out.push(p(start));
    let mut anchor = 0;
    for k in 1..n {
        let next = p(start + k + 1);
        let a = out[out.len() - 1];
        let fits =
            k - anchor < MAX_RUN && (anchor + 1..=k).all(|j| segment_distance2(p(start + j), a, next) < eps2);
        if !fits {
            out.push(p(start + k));
            anchor = k;
        }
    }
    // The last kept vertex against the chord back to the start.
    while out.len() >= 3 && segment_distance2(out[out.len() - 1], out[out.len() - 2], out[0]) < eps2 {
        out.pop();
    }
}

/// 1 - cos of the turn at `b`: 0 straight on, 2 turning back.
fn turn(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    let (u, v) = ([b[0] - a[0], b[1] - a[1]], [c[0] - b[0], c[1] - b[1]]);
    let norm = u[0].hypot(u[1]) * v[0].hypot(v[1]);
    if norm > 0.0 {
        1.0 - (u[0] * v[0] + u[1] * v[1]) / norm
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::segment::segment_distance2;

    #[test]
    fn nearly_collinear_vertices_are_dropped() {
        let square = [
            [0.0, 0.0],
            [500.0, 1.0],
            [1000.0, 0.0],
            [1000.0, 1000.0],
            [0.0, 1000.0],
        ];
        assert_eq!(simplify_ring(&square, 2.0).len(), 4);
        assert_eq!(simplify_ring(&square, 0.5).len(), 5);
    }

    #[test]
    fn a_circle_keeps_its_vertices_and_a_polyline_of_it_stays_within_eps() {
        let ring: Ring = (0..400)
            .map(|i| {
                let a = std::f64::consts::TAU * f64::from(i) / 400.0;
                [10.0 * a.cos(), 10.0 * a.sin()]
            })
            .collect();
        // The sagitta of one step is 10 (1 - cos(pi / 400)) = 3.1e-4 mm.
        assert_eq!(simplify_ring(&ring, 1e-6).len(), 400);
        let coarse = simplify_ring(&ring, 0.01);
        assert!(coarse.len() < 100 && coarse.len() > 10, "{}", coarse.len());
        for p in &ring {
            let d2 = (0..coarse.len())
                .map(|i| segment_distance2(*p, coarse[i], coarse[(i + 1) % coarse.len()]))
                .fold(f64::INFINITY, f64::min);
            assert!(d2 < 0.01 * 0.01);
        }
    }

    #[test]
    fn straight_sides_keep_one_vertex_a_run() {
        // A 10 mm square with 100 vertices on two sides: the corners stay, and of
        // the straight runs one vertex every `MAX_RUN` at most.
        let mut ring: Ring = (0..100).map(|i| [f64::from(i) * 0.1, 0.0]).collect();
        ring.extend((0..100).map(|i| [10.0, f64::from(i) * 0.1]));
        ring.extend([[10.0, 10.0], [0.0, 10.0]]);
        let s = simplify_ring(&ring, 1e-6);
        assert!(s.len() <= 4 + 200 / MAX_RUN, "{s:?}");
        for corner in [[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]] {
            assert!(s.contains(&corner), "{corner:?} kept");
        }
    }

    #[test]
    fn short_rings_are_copied() {
        assert_eq!(simplify_ring(&[[0.0, 0.0], [1.0, 0.0]], 1.0).len(), 2);
        assert!(simplify_ring(&[], 1.0).is_empty());
    }
}
