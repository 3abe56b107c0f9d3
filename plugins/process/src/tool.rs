//! The tool an operation stage names in its options, checked once when it is built.

use lamina_api::stage::StageConfig;
use lamina_api::{OperationTool, Result};

/// A number as a user typed it: 1e300, not its 301 digits.
fn shown(v: f64) -> String {
    if v != 0.0 && v.is_finite() && !(1e-3..1e6).contains(&v.abs()) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

/// The ranges of a tool's numbers: (lowest, highest, unit).
pub const DIAMETER: (f64, f64, &str) = (0.001, 1000.0, "mm");
pub const FEED: (f64, f64, &str) = (0.01, 10_000.0, "mm/s");
pub const SPINDLE: (f64, f64, &str) = (1.0, 200_000.0, "rev/min");
pub const POWER: (f64, f64, &str) = (0.001, 100_000.0, "W");
/// Longest length option (allowances, standoffs, clearances).
pub const LENGTH: f64 = 1000.0;

/// What a stage's options say of its tool.
pub struct ToolSpec<'a> {
    pub name: &'a str,
    pub kind: &'a str,
    pub diameter: f64,
    /// mm/s
    pub feed: f64,
    pub spindle: Option<f64>,
    pub power: Option<f64>,
}

/// The tool, each number checked against the option that gave it.
pub fn checked(config: &StageConfig<'_>, spec: ToolSpec<'_>) -> Result<OperationTool> {
    if spec.name.trim().is_empty() {
        return Err(config.error("tool", "must name the tool"));
    }
    // What a machine can do, bounds and all: a number outside is a typing slip, and one
    // beyond a machine's reach would be written as a word no controller reads (`F0`
    // from a feed of 5e-324, 301 digits from 1e300) or break the geometry.
    let within = |key: &str, v: f64, (lo, hi, unit): (f64, f64, &str)| {
        if v.is_finite() && (lo..=hi).contains(&v) {
            Ok(())
        } else {
            Err(config.error(
                key,
                format!("must lie between {lo} and {hi} {unit}, not {}", shown(v)),
            ))
        }
    };
    within("diameter", spec.diameter, DIAMETER)?;
    within("feed", spec.feed, FEED)?;
    if let Some(s) = spec.spindle {
        within("spindle", s, SPINDLE)?;
    }
    if let Some(p) = spec.power {
        within("power", p, POWER)?;
    }
    Ok(OperationTool {
        name: spec.name.to_string(),
        kind: spec.kind.to_string(),
        diameter: spec.diameter,
        feed: spec.feed,
        spindle: spec.spindle,
        power: spec.power,
    })
}

/// A length option that must be zero or more, and at most [`LENGTH`] (mm).
pub fn non_negative(config: &StageConfig<'_>, key: &str, v: f64) -> Result<()> {
    if v.is_finite() && (0.0..=LENGTH).contains(&v) {
        Ok(())
    } else {
        Err(config.error(
            key,
            format!("must lie between 0 and {LENGTH} mm, not {}", shown(v)),
        ))
    }
}
