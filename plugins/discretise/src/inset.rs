//! Inward offsets of a whole family on its integer grid, built as raw offset loops whose
//! points of positive winding are the offset set (the construction of Chen and McMains
//! that Clipper and i_overlay use): each edge moves in by the distance, reflex corners
//! get joins, convex corners a detour through the corner that the winding cancels.
//!
//! The loops are built here rather than by i_overlay's outline because at nearly
//! straight convex corners (the chord points an STL slice leaves on a curve, turns of a
//! few micro-radians) the detour's rounded ends no longer cross, and the detour stays as
//! a zero-width spike from the offset back to the boundary that cuts the rings into
//! pieces. Here those corners take the crossing point itself, and vertices within a
//! small fraction of the tolerance of their neighbours' chord are dropped first.

use i_overlay::core::overlay::{Overlay, ShapeType};
use i_overlay::i_float::int::point::IntPoint;
use i_overlay::i_shape::int::shape::IntShapes;
use lamina_geom::simplify::simplify_into;
use serde::Deserialize;

lamina_api::option_type!(From = "string"; Join = "string");

/// Which boundaries the offsets start from: the grading reference.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum From {
    /// The outer contour and the holes together (r = 0 on every boundary).
    #[default]
    All,
    /// The outer contour only, toward the holes (the paper's C_3 -> C_2).
    Outer,
}

/// How offset edges meet at corners.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Join {
    /// Arcs: the offset is the exact Euclidean erosion (within `tolerance`).
    #[default]
    Round,
    /// Sharp corners (bevelled where the corner's inside angle is below 5 degrees).
    Miter,
    /// Corners cut straight.
    Bevel,
}

/// An inward offsetter with its settings.
#[derive(Debug, Clone, Copy)]
pub struct Inset {
    pub from: From,
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

/// Below this cosine of the turn (about 2.6 degrees) a convex corner takes the
/// crossing point of its two offset edges instead of the detour through the corner.
const NEARLY_STRAIGHT: f64 = 0.999;

/// 2 sin^2(2.5 degrees): miter corners whose inside angle is below 5 degrees are
/// bevelled instead, as their tip would reach far beyond the offset.
const MITER_LIMIT: f64 = 0.003_805;

impl Inset {
    /// Adds to `overlay`, as clip paths, the raw loops of `shapes` (valid shapes on a
    /// grid of `scale` units per mm) moved inward by `distance` mm: every contour, or
    /// only the outer ones with `outer_only`. Returns whether any outer loop was added:
    /// `false` means the offset set is empty.
    pub fn add_raw(
        &self,
        overlay: &mut Overlay<i32>,
        shapes: &IntShapes<i32>,
        outer_only: bool,
        distance: f64,
        scale: f64,
        scratch: &mut Scratch,
    ) -> bool {
        let delta = distance * scale;
        if delta.is_nan() || delta <= 0.0 || delta.is_infinite() {
            return false;
        }
        // Vertices closer than a fifth of the tolerance to the chord replacing them change
        // nothing the tolerance would notice; dropping them removes the nearly
        // straight corners and most of the chord points a sliced curve carries, which
        // the overlay would otherwise cross-check against every offset edge.
        let eps = (self.tolerance * 0.2 * scale).max(2.0);
        let step = arc_step(self.tolerance / distance);
        let mut any = false;
        for shape in shapes {
            for (i, contour) in shape.iter().enumerate() {
                if i > 0 && outer_only {
                    break;
                }
                if i == 0 && !fits(contour, delta) {
                    // The outer contour is narrower than twice the distance: nothing
                    // of this shape is left (and its holes need no loops).
                    break;
                }
                if self.contour(contour, delta, eps, step, scratch) {
                    overlay.add_contour(&scratch.out, ShapeType::Clip);
                    any |= i == 0;
                }
            }
        }
        any
    }

    /// The raw loop of one contour (material on its left) into `scratch.out`; `false`
    /// for a contour with no area left after simplifying.
    fn contour(&self, contour: &[IntPoint<i32>], delta: f64, eps: f64, step: f64, s: &mut Scratch) -> bool {
        simplify_into(
            contour.len(),
            |i| [f64::from(contour[i].x), f64::from(contour[i].y)],
            eps,
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
            let (dp, dn) = (s.dirs[prev], s.dirs[i]);
            let (np, nn) = ([-dp[1], dp[0]], [-dn[1], dn[0]]);
            let v = s.points[i];
            let at = |n: [f64; 2], k: f64| [v[0] + n[0] * k, v[1] + n[1] * k];
            let cross = dp[0] * dn[1] - dp[1] * dn[0];
            let dot = dp[0] * dn[0] + dp[1] * dn[1];
            let out = &mut s.out;
            if cross > 0.0 {
                // Convex corner: the two offset edges cross inside.
                let half_tan = cross / (1.0 + dot);
                if dot > NEARLY_STRAIGHT && delta * half_tan < 0.5 * s.lens[prev].min(s.lens[i]) {
                    push(out, at([np[0] + nn[0], np[1] + nn[1]], delta / (1.0 + dot)));
                } else {
                    push(out, at(np, delta));
                    push(out, v);
                    push(out, at(nn, delta));
                }
                continue;
            }
            // Reflex (or straight) corner: the offset edges part and a join fills in.
            match self.join {
                Join::Round => {
                    let angle = (-cross).max(0.0).atan2(dot);
                    let k = ((angle / step).ceil() as usize).max(1);
                    let (sin, cos) = (angle / k as f64).sin_cos();
                    let mut r = np;
                    push(out, at(r, delta));
                    for _ in 0..k {
                        // Clockwise: the normal turns with the edge to the right.
                        r = [r[0] * cos + r[1] * sin, r[1] * cos - r[0] * sin];
                        push(out, at(r, delta));
                    }
                }
                Join::Miter if 1.0 + dot > MITER_LIMIT => {
                    push(out, at([np[0] + nn[0], np[1] + nn[1]], delta / (1.0 + dot)));
                }
                Join::Miter | Join::Bevel => {
                    push(out, at(np, delta));
                    push(out, at(nn, delta));
                }
            }
        }
        while s.out.len() > 1 && s.out.first() == s.out.last() {
            s.out.pop();
        }
        s.out.len() >= 3
    }
}

/// The angle of one chord of a round join whose chords stay within `ratio` times the
/// radius of the arc: 2 acos(1 - ratio), kept between a hundredth and a quarter turn.
fn arc_step(ratio: f64) -> f64 {
    let ratio = if ratio.is_nan() {
        1.0
    } else {
        ratio.clamp(0.0, 1.0)
    };
    (2.0 * (1.0 - ratio).acos()).clamp(0.01, std::f64::consts::FRAC_PI_2)
}

/// Whether an inward offset by `delta` can leave anything of the contour's inside: not
/// when the bounding box is narrower than twice the distance. This also keeps the raw
/// loops of large offsets inside the grid's range.
fn fits(contour: &[IntPoint<i32>], delta: f64) -> bool {
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
