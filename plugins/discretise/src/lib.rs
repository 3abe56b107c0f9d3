//! Discretisers for Lamina: they divide one contour family into sub-regions of constant
//! material that tile it exactly, each with a level r in [0, 1] from the grading
//! reference.
//!
//! - `offset`: rings between equally spaced inward offsets (Method 1 of the
//!   topological-hierarchy paper, N_R = int(L_s / D_N));
//! - `step-width`: the grading step-width truncation, N_c = 1 / t_g + 1 regions at
//!   levels 0, t_g, ..., 1 bounded by offsets at the half steps;
//! - `distance-field`: iso-contours of a normalised distance field to a material
//!   feature (boundary, outer, holes, centre, point), clipped to the family;
//! - `radial`: offset contours through the equal divisions of radial lines from the
//!   outer contour to the inner ones (Method 2, Eq. 17).
//!
//! Every discretiser can also split its sub-regions around into circumferential cells
//! (Fig. 13, [`cells`]).
//!
//! All geometry of a family runs on one integer grid ([`grid`]); each region is the
//! boolean difference of two nested sets read from one overlay graph ([`bands`]), so
//! regions never overlap and add up to the family.

mod bands;
pub mod cells;
pub mod check;
pub mod distance_field;
mod grid;
mod inset;
pub mod measure;
mod offset;
mod options;
mod radial;
mod regions;
pub mod shapes;
pub mod step_width;
