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
    select(n, point, eps, out, None);
}

/// [`simplify_ring`] whose chords straddle the ring instead of cutting inside every
/// convex stretch and outside every concave one. The greedy chords keep vertices of the
/// ring, so a chord across a gentle curve lies wholly on one side of it: on a convex
/// stretch the simplified ring loses, on average, two thirds of the deviation along its
/// whole length, which is area a bead following it leaves unfilled. Here each chord is
/// moved across by half of the widest deviation of the vertices it replaces (to the
/// middle of their range), and each kept vertex goes to where its two moved chords
/// meet: the skipped vertices lie within `eps / 2` of their chord's line, on both sides,
/// and the area lost to a curve's chords falls to a sixth of the deviation. A vertex
/// whose moved chords meet far off (chords nearly parallel) moves by the mean of their
/// two moves instead, so no vertex moves by more than `eps`.
pub fn simplify_straddling(ring: &[[f64; 2]], eps: f64) -> Ring {
    let n = ring.len();
    let mut out = Vec::with_capacity(n / 2 + 3);
    let mut kept = Vec::with_capacity(n / 2 + 3);
    select(n, |i| ring[i], eps, &mut out, Some(&mut kept));
    let m = out.len();
    if m < 3 {
        return out;
    }
    // Each chord's unit direction, left normal and move along it.
    let chords: Vec<([f64; 2], [f64; 2], f64)> = (0..m)
        .map(|j| {
            let (a, b) = (out[j], out[(j + 1) % m]);
            let d = [b[0] - a[0], b[1] - a[1]];
            let len = d[0].hypot(d[1]);
            if len == 0.0 {
                return ([0.0, 0.0], [0.0, 0.0], 0.0);
            }
            let u = [d[0] / len, d[1] / len];
            let normal = [-u[1], u[0]];
            let (mut lo, mut hi) = (0.0f64, 0.0f64);
            let (from, to) = (kept[j], kept[(j + 1) % m]);
            let skipped = if to > from { to - from } else { to + n - from };
            for k in 1..skipped {
                let q = ring[(from + k) % n];
                let s = dot([q[0] - a[0], q[1] - a[1]], normal);
                lo = lo.min(s);
                hi = hi.max(s);
            }
            (u, normal, 0.5 * (lo + hi))
        })
        .collect();
    (0..m)
        .map(|i| {
            let v = out[i];
            let (up, np, sp) = chords[(i + m - 1) % m];
            let (un, nn, sn) = chords[i];
            let mean = [0.5 * (np[0] * sp + nn[0] * sn), 0.5 * (np[1] * sp + nn[1] * sn)];
            // The moved lines: v + np sp + t up and v + nn sn + s un.
            let det = cross(up, un);
            if det.abs() > 1e-9 {
                let w = [nn[0] * sn - np[0] * sp, nn[1] * sn - np[1] * sp];
                let t = cross(w, un) / det;
                let meet = [np[0] * sp + up[0] * t, np[1] * sp + up[1] * t];
                if dot(meet, meet) <= eps * eps {
                    return [v[0] + meet[0], v[1] + meet[1]];
                }
            }
            [v[0] + mean[0], v[1] + mean[1]]
        })
        .collect()
}

/// The greedy chords of [`simplify_into`] into `out`, and the indices of the vertices
/// kept into `kept` when asked.
fn select(
    n: usize,
    point: impl Fn(usize) -> [f64; 2],
    eps: f64,
    out: &mut Ring,
    mut kept: Option<&mut Vec<usize>>,
) {
    out.clear();
    if let Some(k) = kept.as_deref_mut() {
        k.clear();
    }
    if n < 3 {
        out.extend((0..n).map(&point));
        if let Some(k) = kept {
            k.extend(0..n);
        }
        return;
    }
    let p = |i: usize| point(i % n);
    // Start at the sharpest corner, so that the vertex kept unconditionally is a real one.
    let start = (0..n)
        .max_by(|&a, &b| turn(p(a + n - 1), p(a), p(a + 1)).total_cmp(&turn(p(b + n - 1), p(b), p(b + 1))))
        .unwrap_or(0);
    let eps2 = eps * eps;
    out.push(p(start));
    if let Some(k) = kept.as_deref_mut() {
        k.push(start);
    }
    let mut anchor = 0;
    let mut cone = Cone::Open;
    for k in 1..n {
        let next = p(start + k + 1);
        let a = out[out.len() - 1];
        cone.add(a, p(start + k), eps2);
        let fits = k - anchor < MAX_RUN
            && cone
                .admits(a, next)
                .unwrap_or_else(|| (anchor + 1..=k).all(|j| segment_distance2(p(start + j), a, next) < eps2));
        if !fits {
            out.push(p(start + k));
            if let Some(kept) = kept.as_deref_mut() {
                kept.push((start + k) % n);
            }
            anchor = k;
            cone = Cone::Open;
        }
    }
    // The last kept vertex against the chord back to the start.
    while out.len() >= 3 && segment_distance2(out[out.len() - 1], out[out.len() - 2], out[0]) < eps2 {
        out.pop();
        if let Some(k) = kept.as_deref_mut() {
            k.pop();
        }
    }
}

/// The directions from the last kept vertex in which a chord passes within `eps` of
/// every vertex skipped since: the intersection of one wedge per skipped vertex
/// (half-angle asin(eps / r) about its direction, at distance r). It answers most
/// chord tests at once instead of measuring every skipped vertex again, so a run
/// costs its length, not its square; where it cannot be sure it says so, and the
/// vertices are measured.
#[derive(Clone, Copy)]
enum Cone {
    /// No skipped vertex farther than `eps`: every direction.
    Open,
    /// Chords between `right` and `left` (counter-clockwise from `right`), both
    /// unnormalised, less than half a turn apart; `far2` the largest squared distance
    /// of a skipped vertex.
    Between {
        right: [f64; 2],
        left: [f64; 2],
        far2: f64,
    },
    /// The wedges do not meet: no chord fits.
    Empty,
    /// Skipped vertices on both sides (the ring turns back): measured each time.
    Unsure,
}

impl Cone {
    /// Narrows the cone to the wedge of the skipped vertex `q` seen from `a`.
    fn add(&mut self, a: [f64; 2], q: [f64; 2], eps2: f64) {
        let u = [q[0] - a[0], q[1] - a[1]];
        let r2 = u[0] * u[0] + u[1] * u[1];
        if r2 <= eps2 {
            // Within eps of the chord's start, whatever the chord.
            return;
        }
        // The wedge's sides: u turned by +-asin(eps / r), scaled by r cos (the
        // length is irrelevant to the side tests).
        let (sin, cos) = (eps2.sqrt(), (r2 - eps2).sqrt());
        let turn = |s: f64| [u[0] * cos - u[1] * s, u[0] * s + u[1] * cos];
        let (l, r) = (turn(sin), turn(-sin));
        *self = match *self {
            Cone::Open => Cone::Between {
                right: r,
                left: l,
                far2: r2,
            },
            Cone::Between { right, left, far2 } => {
                let mid = [right[0] + left[0], right[1] + left[1]];
                if dot(mid, u) <= 0.0 {
                    Cone::Unsure
                } else {
                    let left = if cross(left, l) < 0.0 { l } else { left };
                    let right = if cross(right, r) > 0.0 { r } else { right };
                    if cross(right, left) <= 0.0 {
                        Cone::Empty
                    } else {
                        Cone::Between {
                            right,
                            left,
                            far2: far2.max(r2),
                        }
                    }
                }
            }
            other => other,
        };
    }

    /// Whether the chord from `a` to `b` passes within `eps` of every skipped vertex:
    /// `None` when only measuring them can tell.
    fn admits(&self, a: [f64; 2], b: [f64; 2]) -> Option<bool> {
        let v = [b[0] - a[0], b[1] - a[1]];
        match *self {
            Cone::Open => Some(true),
            Cone::Empty => Some(false),
            Cone::Unsure => None,
            Cone::Between { right, left, far2 } => {
                if cross(right, v) <= 0.0 || cross(v, left) <= 0.0 {
                    // Farther than eps from the line of the chord through some vertex,
                    // so from the chord too.
                    Some(false)
                } else if v[0] * v[0] + v[1] * v[1] >= far2 {
                    // Every skipped vertex projects onto the chord itself (in front of
                    // `a`, within its wedge, and not beyond `b`): its distance to the
                    // chord is its distance to the line, under eps.
                    Some(true)
                } else {
                    None
                }
            }
        }
    }
}

fn cross(u: [f64; 2], v: [f64; 2]) -> f64 {
    u[0] * v[1] - u[1] * v[0]
}

fn dot(u: [f64; 2], v: [f64; 2]) -> f64 {
    u[0] * v[0] + u[1] * v[1]
}

/// 1 - cos of the turn at `b`: 0 straight on, 2 turning back.
fn turn(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    let (u, v) = ([b[0] - a[0], b[1] - a[1]], [c[0] - b[0], c[1] - b[1]]);
    // One square root of the product: the two lengths' own (`hypot`) cost more than
    // the rest of a simplification.
    let norm = (dot(u, u) * dot(v, v)).sqrt();
    if norm > 0.0 { 1.0 - dot(u, v) / norm } else { 0.0 }
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

    /// The definition the cone answers for: every skipped vertex measured against
    /// every candidate chord.
    fn measured(ring: &[[f64; 2]], eps: f64) -> Ring {
        let n = ring.len();
        let p = |i: usize| ring[i % n];
        let start = (0..n)
            .max_by(|&a, &b| {
                turn(p(a + n - 1), p(a), p(a + 1)).total_cmp(&turn(p(b + n - 1), p(b), p(b + 1)))
            })
            .unwrap_or(0);
        let eps2 = eps * eps;
        let mut out = vec![p(start)];
        let mut anchor = 0;
        for k in 1..n {
            let (a, next) = (out[out.len() - 1], p(start + k + 1));
            if !(k - anchor < MAX_RUN
                && (anchor + 1..=k).all(|j| segment_distance2(p(start + j), a, next) < eps2))
            {
                out.push(p(start + k));
                anchor = k;
            }
        }
        while out.len() >= 3 && segment_distance2(out[out.len() - 1], out[out.len() - 2], out[0]) < eps2 {
            out.pop();
        }
        out
    }

    #[test]
    fn the_cone_keeps_the_vertices_that_measuring_keeps() {
        // Noisy loops, wavy and doubling back, at tolerances from a tenth of the noise
        // to ten times it.
        let mut rng = fastrand::Rng::with_seed(0x2545_f491_4f6c_dd1d);
        let mut random = move || rng.f64();
        let mut kept = 0;
        for case in 0..300 {
            let n = 20 + (random() * 600.0) as usize;
            let noise = 0.001 + random() * 0.5;
            let wave = random() * 3.0;
            let ring: Ring = (0..n)
                .map(|i| {
                    let a = std::f64::consts::TAU * i as f64 / n as f64;
                    let r = 10.0 + wave * (7.0 * a).sin() + noise * (random() - 0.5);
                    [r * a.cos(), r * a.sin()]
                })
                .collect();
            let eps = noise * [0.1, 1.0, 10.0][case % 3];
            let fast = simplify_ring(&ring, eps);
            assert_eq!(fast, measured(&ring, eps), "case {case}: {n} vertices, eps {eps}");
            kept += fast.len();
        }
        assert!(kept > 0);
    }

    #[test]
    fn straddling_chords_keep_a_curve_s_area_and_stay_within_eps() {
        use crate::ring::ring_area;
        // A wavy ring (convex and concave stretches) of 2,000 points.
        let ring: Ring = (0..2000)
            .map(|i| {
                let a = std::f64::consts::TAU * f64::from(i) / 2000.0;
                let r = 10.0 + 1.5 * (5.0 * a).sin();
                [r * a.cos(), r * a.sin()]
            })
            .collect();
        let eps = 0.0125;
        let plain = simplify_ring(&ring, eps);
        let straddling = simplify_straddling(&ring, eps);
        // The same vertices kept, each moved by no more than eps.
        assert_eq!(plain.len(), straddling.len());
        assert!(plain.len() < 400, "{}", plain.len());
        for (p, q) in plain.iter().zip(&straddling) {
            assert!(
                (p[0] - q[0]).hypot(p[1] - q[1]) <= eps + 1e-12,
                "{p:?} moved to {q:?}"
            );
        }
        // Every point of the ring within eps of the straddling ring.
        let n = straddling.len();
        for p in &ring {
            let d2 = (0..n)
                .map(|i| segment_distance2(*p, straddling[i], straddling[(i + 1) % n]))
                .fold(f64::INFINITY, f64::min);
            assert!(d2 <= eps * eps, "{p:?} strays {}", d2.sqrt());
        }
        // One-sided chords cut the convex stretches more than the concave ones and lose
        // area; straddling ones lose about a quarter of that (a sixth of the sagitta against
        // two thirds, on an arc).
        let exact = ring_area(&ring);
        let lost_plain = exact - ring_area(&plain);
        let lost_straddling = (exact - ring_area(&straddling)).abs();
        assert!(lost_plain > 0.0);
        assert!(
            lost_straddling < 0.3 * lost_plain,
            "{lost_straddling} against {lost_plain}"
        );
        // A polygon whose chords replace nothing stays as it is.
        let square = [[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]];
        assert_eq!(simplify_straddling(&square, 0.1), simplify_ring(&square, 0.1));
        assert!(simplify_straddling(&[[0.0, 0.0], [1.0, 0.0]], 1.0).len() == 2);
    }

    #[test]
    fn short_rings_are_copied() {
        assert_eq!(simplify_ring(&[[0.0, 0.0], [1.0, 0.0]], 1.0).len(), 2);
        assert!(simplify_ring(&[], 1.0).is_empty());
    }

    #[test]
    fn the_ring_is_walked_from_its_sharpest_corner() {
        // The last point lies halfway along a side: it goes, the four corners stay
        // (from the last of the sharpest).
        let square = [[10.0, 0.0], [10.0, 10.0], [0.0, 10.0], [0.0, 0.0], [5.0, 0.0]];
        let s = simplify_ring(&square, 0.1);
        assert_eq!(s, vec![[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]]);
        // The turn: 0 straight on, 1 at a right angle either way, 2 turning back, and
        // 0 where a side has no length.
        assert_eq!(turn([0.0, 0.0], [1.0, 0.0], [2.0, 0.0]), 0.0);
        assert!((turn([0.0, 0.0], [2.0, 0.0], [2.0, 3.0]) - 1.0).abs() < 1e-12);
        assert!((turn([0.0, 0.0], [2.0, 0.0], [2.0, -3.0]) - 1.0).abs() < 1e-12);
        assert!((turn([0.0, 0.0], [2.0, 0.0], [0.5, 0.0]) - 2.0).abs() < 1e-12);
        assert!((turn([0.0, 0.0], [1.0, 1.0], [1.0, 2.0]) - (1.0 - 0.5f64.sqrt())).abs() < 1e-12);
        assert_eq!(turn([1.0, 1.0], [1.0, 1.0], [2.0, 0.0]), 0.0);
    }
}
