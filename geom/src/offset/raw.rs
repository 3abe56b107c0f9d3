//! Raw offset loops on an integer grid, whose points of positive winding are the offset
//! set (the construction of Chen and McMains that Clipper and i_overlay use): each edge
//! moves by the distance, the corners where the moved edges cross take a detour through
//! the corner that the winding cancels, and the corners where they part take a join.
//! Inward, the crossing corners are the convex ones and the joins fill the reflex ones;
//! outward it is the other way round.
//!
//! The loops are built here rather than by i_overlay's outline because at nearly
//! straight crossing corners (the chord points an STL slice leaves on a curve, turns of
//! a few micro-radians) the detour's rounded ends no longer cross, and the detour stays
//! as a zero-width spike from the offset back to the boundary that cuts the rings into
//! pieces. Here those corners take the crossing point itself, and vertices within a
//! small fraction of the tolerance of their neighbours' chord are dropped first.

use i_overlay::core::overlay::{Overlay, ShapeType};
use i_overlay::i_float::int::point::IntPoint;
use i_overlay::i_shape::int::shape::IntShapes;

use crate::simplify::simplify_into;

/// How offset edges meet where they part; written `"round"`, `"miter"` or `"bevel"`
/// in a pipeline's options.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Join {
    /// Arcs: the offset is the exact Euclidean erosion or dilation (within the
    /// tolerance).
    #[default]
    Round,
    /// Sharp corners (bevelled where the corner's inside angle is below 5 degrees).
    Miter,
    /// Corners cut straight.
    Bevel,
}

/// A raw-loop offsetter with its settings.
#[derive(Debug, Clone, Copy)]
pub struct RawOffset {
    pub join: Join,
    /// Largest distance (mm) between an arc and its chords for round joins.
    pub tolerance: f64,
}

/// Buffers reused from one contour and one offset to the next.
#[derive(Debug, Default)]
pub struct Scratch {
    points: Vec<[f64; 2]>,
    dirs: Vec<[f64; 2]>,
    lens: Vec<f64>,
    out: Vec<IntPoint<i32>>,
}

/// Below this cosine of the turn (about 2.6 degrees) a crossing corner takes the
/// crossing point of its two offset edges instead of the detour through the corner.
const NEARLY_STRAIGHT: f64 = 0.999;

/// 2 sin^2(2.5 degrees): miter corners whose inside angle is below 5 degrees are
/// bevelled instead, as their tip would reach far beyond the offset.
const MITER_LIMIT: f64 = 0.003_805;

/// One offset of one call: the distance on the grid and which way it goes.
#[derive(Clone, Copy)]
struct Move {
    /// The distance in grid units, positive.
    delta: f64,
    /// +1 inward (toward the material, on the contours' left), -1 outward.
    side: f64,
    /// Vertices this close (grid units) to the chord replacing them are dropped.
    eps: f64,
    /// The angle of one chord of a round join.
    step: f64,
}

impl RawOffset {
    /// Adds to `overlay`, as clip paths, the raw loops of `shapes` (valid shapes
    /// on a grid of `scale` units per mm: outer contours counter-clockwise, holes
    /// clockwise, material on their left) offset by `distance` mm, outward when
    /// positive and inward when negative. Resolve the overlay with the positive fill rule (the loops'
    /// points of positive winding). Returns whether any outer loop was added: `false`
    /// means the offset set is empty.
    ///
    /// A contour whose enclosed side shrinks (an outer one inward, a hole outward) and
    /// whose bounding box is narrower than twice the distance takes no loop: nothing of
    /// it is left (an outer contour's holes then take none either). This also keeps the
    /// raw loops of large inward offsets inside the grid's range.
    pub fn add_loops(
        &self,
        overlay: &mut Overlay<i32>,
        shapes: &IntShapes<i32>,
        distance: f64,
        scale: f64,
        scratch: &mut Scratch,
    ) -> bool {
        let delta = distance.abs() * scale;
        if delta.is_nan() || delta == 0.0 || delta.is_infinite() {
            return false;
        }
        let inward = distance < 0.0;
        // Vertices closer than a fifth of the tolerance to the chord replacing them
        // change nothing the tolerance would notice; dropping them removes the nearly
        // straight corners and most of the chord points a sliced curve carries, which
        // the overlay would otherwise cross-check against every offset edge.
        let m = Move {
            delta,
            side: if inward { 1.0 } else { -1.0 },
            eps: self.eps(scale),
            step: crate::offset::join_step(distance, self.tolerance).min(std::f64::consts::FRAC_PI_2),
        };
        let mut any = false;
        for shape in shapes {
            for (i, contour) in shape.iter().enumerate() {
                // The side a contour encloses shrinks: outer contours inward, holes
                // outward.
                if (i == 0) == inward && !fits(contour, delta) {
                    if i == 0 {
                        break;
                    }
                    continue;
                }
                if self.contour(contour, m, scratch) {
                    overlay.add_contour(&scratch.out, ShapeType::Clip);
                    any |= i == 0;
                }
            }
        }
        any
    }

    /// How far (grid units, on a grid of `scale` units per mm) a contour may be moved
    /// by the simplification that comes before its loop: vertices closer than a fifth
    /// of the tolerance to the chord that replaces them are dropped.
    pub fn eps(&self, scale: f64) -> f64 {
        (self.tolerance * 0.2 * scale).max(2.0)
    }

    /// The raw loop of one contour (material on its left) into `s.out`; `false` for a
    /// contour with no area left after simplifying.
    fn contour(&self, contour: &[IntPoint<i32>], m: Move, s: &mut Scratch) -> bool {
        simplify_into(
            contour.len(),
            |i| [f64::from(contour[i].x), f64::from(contour[i].y)],
            m.eps,
            &mut s.points,
        );
        let n = s.points.len();
        if n < 3 {
            return false;
        }
        s.dirs.clear();
        s.lens.clear();
        for i in 0..n {
            let (a, b) = (s.points[i], s.points[(i + 1) % n]);
            let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
            let len = dx.hypot(dy);
            s.lens.push(len);
            s.dirs.push(if len > 0.0 {
                [dx / len, dy / len]
            } else {
                [0.0, 0.0]
            });
        }
        s.out.clear();
        for i in 0..n {
            let prev = (i + n - 1) % n;
            self.corner(
                s.points[i],
                s.dirs[prev],
                s.dirs[i],
                s.lens[prev].min(s.lens[i]),
                m,
                &mut s.out,
            );
        }
        while s.out.len() > 1 && s.out.first() == s.out.last() {
            s.out.pop();
        }
        s.out.len() >= 3
    }

    /// The loop's points at the corner `v` between the edges of directions `dp` (in)
    /// and `dn` (out), the shorter of them `short` long.
    fn corner(
        &self,
        v: [f64; 2],
        dp: [f64; 2],
        dn: [f64; 2],
        short: f64,
        m: Move,
        out: &mut Vec<IntPoint<i32>>,
    ) {
        // The offset normals: the left ones inward, the right ones outward.
        let (np, nn) = (
            [-dp[1] * m.side, dp[0] * m.side],
            [-dn[1] * m.side, dn[0] * m.side],
        );
        let at = |n: [f64; 2], k: f64| [v[0] + n[0] * k, v[1] + n[1] * k];
        let cross = dp[0] * dn[1] - dp[1] * dn[0];
        let dot = dp[0] * dn[0] + dp[1] * dn[1];
        // The turn toward the offset side: positive where the offset edges cross.
        let turn = cross * m.side;
        if turn > 0.0 {
            let half_tan = turn / (1.0 + dot);
            if dot > NEARLY_STRAIGHT && m.delta * half_tan < 0.5 * short {
                // Nearly straight: the crossing point itself, which no spike leaves.
                push(out, at([np[0] + nn[0], np[1] + nn[1]], m.delta / (1.0 + dot)));
            } else {
                push(out, at(np, m.delta));
                push(out, v);
                push(out, at(nn, m.delta));
            }
            return;
        }
        // The offset edges part (or run straight on) and a join fills in.
        match self.join {
            Join::Round => {
                let angle = (-turn).max(0.0).atan2(dot);
                let k = ((angle / m.step).ceil() as usize).max(1);
                // The normal turns with the edges, away from the offset side: clockwise
                // inward, counter-clockwise outward.
                let (sin, cos) = (-m.side * angle / k as f64).sin_cos();
                let mut r = np;
                push(out, at(r, m.delta));
                for _ in 0..k {
                    r = [r[0] * cos - r[1] * sin, r[0] * sin + r[1] * cos];
                    push(out, at(r, m.delta));
                }
            }
            Join::Miter if 1.0 + dot > MITER_LIMIT => {
                push(out, at([np[0] + nn[0], np[1] + nn[1]], m.delta / (1.0 + dot)));
            }
            Join::Miter | Join::Bevel => {
                push(out, at(np, m.delta));
                push(out, at(nn, m.delta));
            }
        }
    }
}

/// Whether an offset by `delta` toward the side a contour encloses can leave anything of
/// it: not when its bounding box is narrower than twice the distance.
pub fn fits(contour: &[IntPoint<i32>], delta: f64) -> bool {
    let (mut x0, mut y0, mut x1, mut y1) = (i32::MAX, i32::MAX, i32::MIN, i32::MIN);
    for p in contour {
        x0 = x0.min(p.x);
        y0 = y0.min(p.y);
        x1 = x1.max(p.x);
        y1 = y1.max(p.y);
    }
    let narrow = (f64::from(x1) - f64::from(x0)).min(f64::from(y1) - f64::from(y0));
    2.0 * delta < narrow
}

fn push(out: &mut Vec<IntPoint<i32>>, p: [f64; 2]) {
    let q = IntPoint::new(p[0].round() as i32, p[1].round() as i32);
    if out.last() != Some(&q) {
        out.push(q);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A regular `n`-gon of circumradius `r` grid units, counter-clockwise.
    fn ngon(n: usize, r: f64) -> Vec<IntPoint<i32>> {
        (0..n)
            .map(|i| {
                let a = std::f64::consts::TAU * i as f64 / n as f64;
                IntPoint::new((r * a.cos()).round() as i32, (r * a.sin()).round() as i32)
            })
            .collect()
    }

    /// The raw loop's length of one contour offset by `delta` grid units (negative:
    /// inward) at `tolerance` grid units.
    fn loop_len(contour: &[IntPoint<i32>], delta: f64, tolerance: f64) -> usize {
        let offset = RawOffset {
            join: Join::Round,
            tolerance,
        };
        let m = Move {
            delta: delta.abs(),
            side: if delta < 0.0 { 1.0 } else { -1.0 },
            eps: (tolerance * 0.2).max(2.0),
            step: crate::offset::join_step(delta, tolerance).min(std::f64::consts::FRAC_PI_2),
        };
        let mut s = Scratch::default();
        assert!(offset.contour(contour, m, &mut s));
        s.out.len()
    }

    #[test]
    fn nearly_straight_corners_take_one_point() {
        // A circle of 2000 chord points, 10^6 units round: a fine tolerance keeps every
        // point, and each corner of the inward loop is its edges' crossing point rather
        // than a detour of three, which the overlay would cross-check against every
        // other edge.
        let circle = ngon(2000, 1e6);
        assert_eq!(loop_len(&circle, -1e5, 1.0), 2000);
        // Outward the corners take joins: one chord each at this tolerance.
        assert_eq!(loop_len(&circle, 1e5, 1.0), 4000);
        // A coarser tolerance drops the chord points first: the loop keeps a tenth.
        assert!(loop_len(&circle, -1e5, 500.0) < 250);
    }
}
