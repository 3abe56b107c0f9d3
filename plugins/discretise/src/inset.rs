//! Inward offsets of a whole family on its integer grid (i_overlay's outline with a
//! negative distance): the outer contour moves in, and the holes move out too unless
//! only the outer boundary is the grading reference.

use i_overlay::i_float::int::angle::Angle;
use i_overlay::i_shape::int::shape::IntShapes;
use i_overlay::mesh::int::arc::ArcOptions;
use i_overlay::mesh::int::outline::offset::IntOutlineOffset;
use i_overlay::mesh::int::style::{IntLineJoin, IntOutlineStyle};
use lamina_core::{Error, Result};
use serde::Deserialize;

use crate::bands::options;
use crate::grid::Grid;

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
    /// Sharp corners (clipped below 5 degrees).
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

impl Inset {
    /// `base` (valid shapes on `grid`) offset inward by `distance` mm.
    pub fn apply(
        &self,
        grid: &Grid,
        base: &IntShapes<i32>,
        distance: f64,
        stage: &str,
    ) -> Result<IntShapes<i32>> {
        let d = grid.length(distance);
        let join = match self.join {
            Join::Round => {
                let ratio = (self.tolerance / distance).min(1.0);
                let step = 2.0 * (1.0 - ratio).acos();
                let max_step = Angle::from_radians(step).unwrap_or(ArcOptions::MAX_STEP);
                IntLineJoin::Round(ArcOptions {
                    max_step,
                    ..ArcOptions::default()
                })
            }
            Join::Miter => {
                IntLineJoin::Miter(Angle::from_radians(5f64.to_radians()).unwrap_or(ArcOptions::MAX_STEP))
            }
            Join::Bevel => IntLineJoin::Bevel,
        };
        let inner = match self.from {
            From::All => -d,
            From::Outer => 0,
        };
        let style = IntOutlineStyle::new(-d).inner_offset(inner).line_join(join);
        base.outline_custom(&style, options())
            .map_err(|e| Error::stage(stage, format!("offset by {distance} mm: {e}")))
    }
}
