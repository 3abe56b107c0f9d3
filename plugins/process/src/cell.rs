//! The hybrid cell the `nc` exporter writes for: its tools (number, kind, size and
//! limits), travel and digital outputs, from a built-in profile (`cells/`) or a TOML
//! file of the same form. Every operation is checked against it before a line is
//! written: a tool the cell lacks, of another kind or size, run beyond its limits, or a
//! path outside the travel would be refused by the machine, so the run is refused.

use std::path::Path;

use lamina_core::{Error, Operation, Result};
use serde::Deserialize;

/// The cells shipped with Lamina, by name.
const BUILT_IN: &[(&str, &str)] = &[("cmpm-hybrid", include_str!("../cells/cmpm-hybrid.toml"))];

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Cell {
    pub name: String,
    #[serde(default)]
    pub description: String,
    pub travel: Travel,
    pub outputs: Outputs,
    pub tools: Vec<CellTool>,
}

#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Travel {
    pub x: [f64; 2],
    pub y: [f64; 2],
    pub z: [f64; 2],
}

#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Outputs {
    pub spray: u32,
    pub filler: u32,
    pub vacuum: u32,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CellTool {
    pub number: u32,
    pub name: String,
    pub kind: String,
    pub diameter: f64,
    #[serde(default)]
    pub max_spindle: Option<f64>,
    #[serde(default)]
    pub max_power: Option<f64>,
}

/// Checks that every number of `op` can be written for a controller: operations may
/// come from a plugin, and a NaN or an infinity is refused, not written.
pub fn readable(op: &Operation) -> Result<()> {
    let finite = op.surface.is_none_or(f64::is_finite)
        && op.values.values().all(|v| v.is_finite())
        && op
            .paths
            .iter()
            .all(|p| p.z.is_finite() && p.points.iter().all(|q| q.x.is_finite() && q.y.is_finite()));
    let tool_ok = op.tool.as_ref().is_none_or(|t| {
        t.feed.is_finite()
            && t.feed > 0.0
            && t.spindle.is_none_or(|s| s.is_finite() && s > 0.0)
            && t.power.is_none_or(|p| p.is_finite() && p > 0.0)
    });
    if finite && tool_ok {
        Ok(())
    } else {
        Err(Error::stage(
            "export:nc",
            format!(
                "`{}`: a height, a point, a value or its tool's feed, speed or power is not a finite positive number",
                op.kind
            ),
        ))
    }
}

impl Cell {
    /// A built-in cell by name, or a file (relative to `base_dir`).
    pub fn load(reference: &str, base_dir: &Path) -> std::result::Result<Cell, String> {
        let (origin, text) = match BUILT_IN.iter().find(|(n, _)| *n == reference) {
            Some((n, text)) => (format!("built-in cell `{n}`"), (*text).to_string()),
            None => {
                let path = base_dir.join(reference);
                let names: Vec<&str> = BUILT_IN.iter().map(|(n, _)| *n).collect();
                let text = std::fs::read_to_string(&path).map_err(|e| {
                    format!(
                        "`{reference}` is no built-in cell ({}) and {} cannot be read: {e}",
                        names.join(", "),
                        path.display()
                    )
                })?;
                (path.display().to_string(), text)
            }
        };
        let cell: Cell = toml::from_str(&text).map_err(|e| format!("{origin}: {e}"))?;
        cell.check().map_err(|e| format!("{origin}: {e}"))?;
        Ok(cell)
    }

    fn check(&self) -> std::result::Result<(), String> {
        for (axis, [lo, hi]) in [("x", self.travel.x), ("y", self.travel.y), ("z", self.travel.z)] {
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return Err(format!("travel.{axis} must be [low, high] with low < high"));
            }
        }
        for (i, t) in self.tools.iter().enumerate() {
            if t.number == 0
                || self.tools[..i]
                    .iter()
                    .any(|o| o.number == t.number || o.name == t.name)
            {
                return Err(format!(
                    "tools[{i}] (`{}`): numbers start at 1, and numbers and names are unique",
                    t.name
                ));
            }
            if !(t.diameter.is_finite() && t.diameter > 0.0) {
                return Err(format!("tools[{i}] (`{}`): diameter must be positive", t.name));
            }
            for (key, v) in [("max_spindle", t.max_spindle), ("max_power", t.max_power)] {
                if v.is_some_and(|v| !(v.is_finite() && v > 0.0)) {
                    return Err(format!("tools[{i}] (`{}`): {key} must be positive", t.name));
                }
            }
        }
        let o = self.outputs;
        if o.spray == o.filler || o.spray == o.vacuum || o.filler == o.vacuum {
            return Err("outputs: the spray gun, the filler and the vacuum need outputs of their own".into());
        }
        Ok(())
    }

    pub fn tool(&self, name: &str) -> Option<&CellTool> {
        self.tools.iter().find(|t| t.name == name)
    }

    /// Checks that the cell can run `op`; the error says what the machine lacks.
    pub fn admits(&self, op: &Operation, standoff: f64) -> Result<()> {
        let fail = |m: String| Err(Error::stage("export:nc", format!("`{}`: {m}", op.kind)));
        readable(op)?;
        let Some(tool) = &op.tool else { return Ok(()) };
        let Some(own) = self.tool(&tool.name) else {
            let names: Vec<&str> = self.tools.iter().map(|t| t.name.as_str()).collect();
            return fail(format!(
                "the cell `{}` has no tool `{}` (tools: {})",
                self.name,
                tool.name,
                names.join(", ")
            ));
        };
        if own.kind != tool.kind {
            return fail(format!(
                "`{}` is a {} in the cell, the plan wants a {}",
                own.name, own.kind, tool.kind
            ));
        }
        if (own.diameter - tool.diameter).abs() > 1e-9 {
            return fail(format!(
                "`{}` measures {} mm in the cell, the plan was made for {} mm",
                own.name, own.diameter, tool.diameter
            ));
        }
        if let (Some(max), Some(s)) = (own.max_spindle, tool.spindle)
            && s > max
        {
            return fail(format!(
                "`{}` turns at most {max} rev/min, the plan asks {s}",
                own.name
            ));
        }
        if let (Some(max), Some(p)) = (own.max_power, tool.power)
            && p > max
        {
            return fail(format!("`{}` gives at most {max} W, the plan asks {p}", own.name));
        }
        let t = &self.travel;
        for path in &op.paths {
            let z = path.z + standoff;
            if z < t.z[0] || z > t.z[1] {
                return fail(format!(
                    "a pass at z {z:.3} is outside the cell's travel {:?}",
                    t.z
                ));
            }
            for p in &path.points {
                if p.x < t.x[0] || p.x > t.x[1] || p.y < t.y[0] || p.y > t.y[1] {
                    return fail(format!(
                        "the point ({:.3}, {:.3}) is outside the cell's travel x {:?}, y {:?}",
                        p.x, p.y, t.x, t.y
                    ));
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_built_in_cell_loads() {
        for (name, _) in BUILT_IN {
            let c = Cell::load(name, Path::new(".")).expect("loads");
            assert_eq!(&c.name, name);
            assert!(c.tools.len() >= 4);
        }
        let err = Cell::load("nowhere.toml", Path::new(".")).expect_err("no file");
        assert!(err.contains("no built-in cell (cmpm-hybrid)"), "{err}");
    }
}
