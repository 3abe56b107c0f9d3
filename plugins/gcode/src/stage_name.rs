//! The stage's name, which each of its errors carries.

/// The key a pipeline names the exporter by.
pub(crate) const STAGE: &str = "gcode";
