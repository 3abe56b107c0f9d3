//! The physical ranges of a machine's values: wider than any machine builds, narrow
//! enough that every value is a number the firmware reads (a speed of 5e-324 mm/s would
//! be written `F0`, one of 1e300 a word of 300 digits).

/// Longest travel, bed side or height (mm).
pub(super) const MAX_TRAVEL: f64 = 10_000.0;
/// Slowest and fastest speed (mm/s).
pub(super) const MIN_SPEED: f64 = 0.01;
pub(super) const MAX_SPEED: f64 = 5_000.0;
/// Largest jerk (mm/s).
pub(super) const MAX_JERK: f64 = 1_000.0;
/// Smallest and largest acceleration (mm/s²).
pub(super) const MIN_ACCELERATION: f64 = 1.0;
pub(super) const MAX_ACCELERATION: f64 = 500_000.0;
/// Hotter than any FFF hotend goes (°C).
pub(super) const MAX_NOZZLE_TEMPERATURE: f64 = 500.0;
pub(super) const MAX_BED_TEMPERATURE: f64 = 200.0;
