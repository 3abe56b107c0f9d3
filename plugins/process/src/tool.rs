//! The tool an operation stage names in its options, checked once when it is built.

use lamina_core::stage::StageConfig;
use lamina_core::{OperationTool, Result};

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
    let positive = |key: &str, v: f64| {
        if v.is_finite() && v > 0.0 {
            Ok(())
        } else {
            Err(config.error(key, format!("must be a positive number, not {v}")))
        }
    };
    positive("diameter", spec.diameter)?;
    positive("feed", spec.feed)?;
    if let Some(s) = spec.spindle {
        positive("spindle", s)?;
    }
    if let Some(p) = spec.power {
        positive("power", p)?;
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

/// A length option that must be zero or more (mm).
pub fn non_negative(config: &StageConfig<'_>, key: &str, v: f64) -> Result<()> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(config.error(key, format!("must be zero or a positive number of mm, not {v}")))
    }
}
