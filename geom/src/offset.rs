//! Round offsets of shapes through the outline engine: the one place that turns a
//! chord tolerance into the engine's join step and tidies what it returns, for every
//! stage that offsets (bead loops, machining passes, distance sources).

use i_overlay::mesh::float::outline::offset::OutlineOffset;
use i_overlay::mesh::float::style::{LineJoin, OutlineStyle};

use crate::{Shapes, simplify_ring};

/// The angle (radians) between the chords of a round join of radius `d` whose
/// chords stray at most `tolerance` from the arc; never below 0.01, which bounds the
/// vertices a join can take.
pub fn join_step(d: f64, tolerance: f64) -> f64 {
    let step = 2.0 * (1.0 - (tolerance / d.abs()).min(1.0)).acos();
    step.max(0.01)
}

/// `shapes` offset by `d` (negative: inward) with round joins straying at most
/// `tolerance` from the arcs, as the engine returns them (rings in the engine's
/// orientation, holes the other way round).
pub fn round_outline(shapes: &Shapes, d: f64, tolerance: f64) -> Shapes {
    if shapes.is_empty() || d == 0.0 {
        return shapes.clone();
    }
    let style = OutlineStyle::new(d).line_join(LineJoin::Round(join_step(d, tolerance)));
    shapes.outline(&style)
}

/// [`round_outline`] with each ring simplified within `tolerance` and what
/// simplifies away dropped: offsets of offsets would otherwise multiply the arc
/// vertices pass after pass.
pub fn round_offset(shapes: &Shapes, d: f64, tolerance: f64) -> Shapes {
    if shapes.is_empty() || d == 0.0 {
        return shapes.clone();
    }
    tidy(round_outline(shapes, d, tolerance), tolerance)
}

/// Every ring simplified within `tolerance`; rings and shapes left with nothing
/// dropped.
pub fn tidy(shapes: Shapes, tolerance: f64) -> Shapes {
    shapes
        .into_iter()
        .map(|shape| {
            shape
                .into_iter()
                .map(|c| simplify_ring(&c, tolerance))
                .filter(|c| c.len() >= 3)
                .collect::<Vec<_>>()
        })
        .filter(|s| !s.is_empty())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ring::ring_area;

    fn square(s: f64) -> Shapes {
        vec![vec![vec![[0.0, 0.0], [s, 0.0], [s, s], [0.0, s]]]]
    }

    #[test]
    fn a_square_moves_in_and_out_by_the_distance() {
        // Inward: a smaller square, its sides 2 d shorter.
        let inner = round_offset(&square(10.0), -1.0, 0.005);
        let a: f64 = inner[0].iter().map(|r| ring_area(r).abs()).sum();
        assert!((a - 64.0).abs() < 1e-6, "{a}");
        // Outward: the square, four strips and four quarter discs (round joins),
        // within the chord tolerance.
        let outer = round_offset(&square(10.0), 1.0, 0.005);
        let a = ring_area(&outer[0][0]).abs();
        let exact = 100.0 + 40.0 + std::f64::consts::PI;
        assert!((a - exact).abs() < 0.05, "{a} against {exact}");
        // Nothing to offset, or no distance: as given.
        assert!(round_offset(&Vec::new(), 1.0, 0.005).is_empty());
        assert_eq!(round_offset(&square(1.0), 0.0, 0.005), square(1.0));
        // Too far in: nothing left.
        assert!(round_offset(&square(1.0), -1.0, 0.005).is_empty());
    }

    #[test]
    fn the_join_step_keeps_chords_within_the_tolerance() {
        let (r, tol) = (2.0, 0.01);
        let step = join_step(r, tol);
        // A chord spanning `step` strays r (1 - cos(step / 2)) from its arc.
        assert!((r * (1.0 - (step / 2.0).cos()) - tol).abs() < 1e-12);
        // A tolerance beyond the radius: a half turn per chord.
        assert_eq!(join_step(0.001, 1.0), std::f64::consts::PI);
    }
}
