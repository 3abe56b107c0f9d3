//! lamina-fgm: the pieces of the papers' methods that several stages need alike, kept
//! in one place so that they select, cut and measure the same way wherever they run.
//!
//! - `steps`: the step-wise truncation of a grading function (grading-step-width
//!   paper, 3.1), read by the `step-width` and `distance-field` discretisers and the
//!   `sources` stage;
//! - `surface`: chosen faces of a part's mesh and the distance in space to them (the
//!   distance-field paper's selected faces, the outer-surface grading source);
//! - `microstructure`: the base cells of a periodic microstructure with their script
//!   size, orientation and inserting functions (cmpm-process-planning 4.3), read by the
//!   `bitmap` exporter, the `engrave` operation and the `base-cell` orientation.
//!
//! It depends on the stage API and the geometry crate only; the engine knows none of
//! it.

pub mod microstructure;
pub mod steps;
pub mod surface;

lamina_api::option_type!(surface::FaceSelection = "table", array "array of table");
