//! The options of the offset discretisers: which boundaries the offsets start from and
//! how offset edges meet. The offsets themselves are lamina-geom's
//! ([`lamina_geom::offset`]), one engine for every stage.

use lamina_geom::offset::RawOffset;
use serde::Deserialize;

pub use lamina_geom::offset::Join;

lamina_api::option_type!(From = "string");

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

/// An inward offsetter with its settings.
#[derive(Debug, Clone, Copy)]
pub struct Inset {
    pub from: From,
    pub join: Join,
    /// Largest distance (mm) between an arc and its chords for round joins.
    pub tolerance: f64,
}

impl Inset {
    /// The offsetter these settings make.
    pub fn raw(&self) -> RawOffset {
        RawOffset {
            join: self.join,
            tolerance: self.tolerance,
        }
    }
}
