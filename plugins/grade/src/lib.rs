//! Graders for Lamina: they give every sub-region of a family its composition, the
//! volume fractions of the part's primary materials.
//!
//! - `script`: fractions from a Rhai expression or function of the region's level r,
//!   its reference point (x, y), the layer's height z and index, and the part's name;
//! - `constant`: one composition for the whole part (a discrete part of an assembly);
//! - `z`: a control function of the layer's level between two layers or heights;
//! - `xy`: a control function of the sub-region's level across the layer;
//! - `zxy`: a Z grading and an X-Y grading at once, combined by weights (Eq. 8);
//! - `idw`: inverse-distance weighting of materials carried by a family's contours.

mod constant;
#[cfg(test)]
mod fixtures;
mod z;
mod zxy;
/// The name the `script` grader registers under, as a macro so that its example can
/// name it too (a test fixture builds the same source as a dynamic plugin under
/// another name).
macro_rules! script_stage {
    () => {
        "script"
    };
}

pub mod control;
mod idw;
mod script;
mod xy;

const SCRIPT_STAGE: &str = script_stage!();
