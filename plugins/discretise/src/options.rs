//! Options that several discretisers share, with their documentation and checks, so
//! that `nozzle`, `count`, `join` and `tolerance` read and fail alike everywhere.

use lamina_api::options::SharedOption;
use lamina_api::stage::StageConfig;
use lamina_api::{Limit, Limits, Result};

/// Finest arc-to-chord tolerance (mm): a tenth of a micrometre, far below any
/// machine's resolution. Finer ones only multiply the vertices of round corners.
pub const MIN_TOLERANCE: f64 = 1e-4;

pub const NOZZLE: SharedOption =
    SharedOption::new("0.4", "nozzle diameter D_N (mm) for N_R = int(L_s / D_N)").within(0.01, 50.0);

pub const COUNT: SharedOption =
    SharedOption::without_default("number of sub-regions N_R instead of the nozzle rule").within(1.0, 1e6);

pub const JOIN: SharedOption = SharedOption::new(
    "\"round\"",
    "offset corners: `round` (exact distance), `miter` or `bevel`",
);

/// Round corners of sub-regions are drawn to the resolution of the G-code that lays
/// them (PrusaSlicer's 0.0125 mm, the planner's own chord tolerance): beads are
/// planned to that tolerance whatever the sub-region, and a finer one only multiplies
/// the vertices every offset of a family crosses (a fifth of the discretiser's time on
/// the graded 3DBenchy at 0.005 mm).
pub const TOLERANCE: SharedOption =
    SharedOption::new("0.0125", "largest arc-to-chord distance of round corners (mm)")
        .within(MIN_TOLERANCE, 10.0);

/// A `count` within the run's `limits.regions`, when given (its declared range, 1 and
/// up, is checked as the options are read).
pub fn count(config: &StageConfig<'_>, count: Option<usize>) -> Result<()> {
    match count {
        Some(n) => regions(config, "count", n as f64),
        None => Ok(()),
    }
}

/// Refuses an option that asks for more sub-regions per family than `limits.regions`.
pub fn regions(config: &StageConfig<'_>, key: &str, n: f64) -> Result<()> {
    config
        .limits
        .check(Limit::Regions, n, &format!("`{key}`"))
        .map_err(|e| config.error(key, e.to_string()))
}

/// A count the geometry implies (a reach over a spacing), at least 1, refused when it
/// exceeds `limits.regions`: a spacing of a micrometre on a large part is a typo, and
/// its millions of rings would take hours.
pub fn derived_count(limits: &Limits, n: f64, what: &str) -> Result<usize> {
    let n = n.floor().max(1.0);
    limits.check(Limit::Regions, n, what)?;
    Ok(n as usize)
}
