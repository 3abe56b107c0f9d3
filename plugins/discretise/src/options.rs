//! Options that several discretisers share, with their documentation and checks, so
//! that `nozzle`, `count`, `join` and `tolerance` read and fail alike everywhere.

use lamina_core::Result;
use lamina_core::stage::{OptionSpec, StageConfig};

/// More rings than any nozzle could deposit in a layer: a guard against typos.
pub const MAX_COUNT: usize = 10_000;

pub const NOZZLE: OptionSpec = OptionSpec::new(
    "nozzle",
    "float",
    "0.4",
    "nozzle diameter D_N (mm) for N_R = int(L_s / D_N)",
);

pub const COUNT: OptionSpec = OptionSpec::new(
    "count",
    "integer",
    "none",
    "number of sub-regions N_R instead of the nozzle rule",
);

pub const JOIN: OptionSpec = OptionSpec::new(
    "join",
    "string",
    "\"round\"",
    "offset corners: `round` (exact distance), `miter` or `bevel`",
);

pub const TOLERANCE: OptionSpec = OptionSpec::new(
    "tolerance",
    "float",
    "0.005",
    "largest arc-to-chord distance of round corners (mm)",
);

/// `v` when it is a positive, finite number of millimetres.
pub fn positive_mm(config: &StageConfig<'_>, key: &str, v: f64) -> Result<f64> {
    if v > 0.0 && v.is_finite() {
        Ok(v)
    } else {
        Err(config.error(key, format!("`{key}` must be a positive number of mm, not {v}")))
    }
}

/// A `count` within `1..=MAX_COUNT`, when given.
pub fn count(config: &StageConfig<'_>, count: Option<usize>) -> Result<Option<usize>> {
    match count {
        Some(n) if !(1..=MAX_COUNT).contains(&n) => {
            Err(config.error("count", format!("`count` must be in 1..={MAX_COUNT}, not {n}")))
        }
        n => Ok(n),
    }
}
