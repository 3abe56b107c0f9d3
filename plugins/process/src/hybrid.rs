//! The hybrid machine the `nc` exporter writes for, from a built-in profile (`machines/`) or
//! a TOML file of the same form:
//!
//! - its tools (number, kind, size), their cutting data (feed, spindle speed or the
//!   wheel's surface speed, laser power, ramp angle) and their limits;
//! - its travel, digital outputs and powder feeders;
//! - its controller: the dialect's lines for a safe start, a retract to the safe height
//!   in machine coordinates, a tool change, length compensation, outputs and the end
//!   of the program, as templates (`{tool}`, `{output}`, `{value}`); a capability the
//!   controller lacks (Grbl: no tool changer, no `G43 H`, no analog output) is a key
//!   left out, and a program that needs it is refused;
//! - its motion limits, from which the program's cycle time is estimated.
//!
//! Every operation is checked against the machine before a line is written: a tool the
//! machine lacks, of another kind or size, run beyond its limits, or a path outside the
//! travel would be refused by the machine, so the run is refused.

use crate::tool;
use lamina_api::reach::Reach;
use std::collections::BTreeMap;
use std::path::Path;

use lamina_api::{Error, Operation, Result, Warning};
use serde::Deserialize;

/// The machines shipped with Lamina, by name.
const BUILT_IN: &[(&str, &str)] = &[
    ("cmpm-hybrid", include_str!("../machines/cmpm-hybrid.toml")),
    (
        "cmpm-hybrid-fanuc",
        include_str!("../machines/cmpm-hybrid-fanuc.toml"),
    ),
    ("grbl-laser", include_str!("../machines/grbl-laser.toml")),
];

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HybridMachine {
    pub name: String,
    #[serde(default)]
    pub description: String,
    pub travel: Travel,
    #[serde(default)]
    pub outputs: Outputs,
    pub controller: Controller,
    pub motion: Motion,
    #[serde(default)]
    pub feeders: Feeders,
    pub tools: Vec<HybridTool>,
}

#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Travel {
    pub x: [f64; 2],
    pub y: [f64; 2],
    pub z: [f64; 2],
}

/// Digital outputs; one the machine lacks is left out.
#[derive(Debug, Clone, Copy, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Outputs {
    pub spray: Option<u32>,
    pub filler: Option<u32>,
    pub vacuum: Option<u32>,
}

/// One line or several.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(untagged)]
pub enum Lines {
    #[default]
    None,
    One(String),
    Many(Vec<String>),
}

impl Lines {
    pub fn lines(&self) -> &[String] {
        match self {
            Lines::None => &[],
            Lines::One(s) => std::slice::from_ref(s),
            Lines::Many(v) => v,
        }
    }

    pub fn is_empty(&self) -> bool {
        self.lines().is_empty()
    }
}

/// What the controller reads, in its dialect.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Controller {
    /// The dialect's name, printed in the program's header (`linuxcnc`, `fanuc`, `grbl`).
    pub dialect: String,
    /// Lines before the first comment (`%` then a program number on Fanuc).
    #[serde(default)]
    pub header: Lines,
    /// The safe start: units, plane, distance and feed mode, cutter and length
    /// compensation and canned cycles cancelled, the work offset.
    pub start: Lines,
    /// Up to the safe height in machine coordinates: before every tool change and at
    /// the end.
    pub retract: Lines,
    /// Loads tool `{tool}`; left out: the controller changes no tools.
    #[serde(default)]
    pub tool_change: Lines,
    /// Applies tool `{tool}`'s length offset; left out: none.
    #[serde(default)]
    pub length_on: Lines,
    /// Cancels the length offset.
    #[serde(default)]
    pub length_off: Lines,
    /// Switches digital output `{output}` on and off.
    #[serde(default)]
    pub output_on: Lines,
    #[serde(default)]
    pub output_off: Lines,
    /// Sets analog output `{output}` to `{value}`; left out: no analog outputs.
    #[serde(default)]
    pub analog: Lines,
    /// Starts the spindle at `{speed}` rev/min (also a new speed while it turns), and
    /// stops it; left out: no spindle.
    #[serde(default)]
    pub spindle_on: Lines,
    #[serde(default)]
    pub spindle_off: Lines,
    /// Switches the laser on at `{power}` (watts times `power_scale`), and off.
    #[serde(default)]
    pub laser_on: Lines,
    #[serde(default)]
    pub laser_off: Lines,
    /// The laser's power word per watt (Grbl: its `$30` over the laser's watts).
    #[serde(default = "one")]
    pub power_scale: f64,
    /// Every number with a decimal point (`X10.`): a Fanuc reads `X10` as 10 µm.
    #[serde(default)]
    pub decimal_point: bool,
    /// Ends the program (after the final retract).
    pub end: Lines,
}

/// What the controller's motion allows, for the cycle-time estimate.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Motion {
    /// Rapid speed of x, y and z (mm/min).
    pub rapid: [f64; 3],
    /// Acceleration of x, y and z (mm/s²).
    pub acceleration: [f64; 3],
    /// Seconds a tool change takes.
    pub tool_change: f64,
    /// Seconds the spindle takes to reach its speed.
    #[serde(default)]
    pub spindle_start: f64,
    /// How far the controller may round a corner between feed moves (mm), as its
    /// blending tolerance is set in `start` (LinuxCNC: `G64 P`): the speed through a
    /// corner follows from it and the acceleration. 0: every move stops at its end.
    #[serde(default)]
    pub junction_deviation: f64,
}

/// The spray gun's powder feeders: which analog output meters which powder, and the
/// output's value for a volume fraction of 1.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Feeders {
    #[serde(default)]
    pub outputs: BTreeMap<String, u32>,
    #[serde(default = "one")]
    pub scale: f64,
}

fn one() -> f64 {
    1.0
}

impl Default for Feeders {
    fn default() -> Self {
        Self {
            outputs: BTreeMap::new(),
            scale: 1.0,
        }
    }
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HybridTool {
    pub number: u32,
    pub name: String,
    pub kind: String,
    pub diameter: f64,
    /// Feed along the paths (mm/s); default: the plan's.
    #[serde(default)]
    pub feed: Option<f64>,
    /// Spindle speed (rev/min); default: from `surface_speed`, else the plan's.
    #[serde(default)]
    pub spindle: Option<f64>,
    /// Surface speed of a wheel's rim (m/s), from which its spindle speed follows.
    #[serde(default)]
    pub surface_speed: Option<f64>,
    /// Laser or torch power (W); default: the plan's.
    #[serde(default)]
    pub power: Option<f64>,
    /// Angle of a cutter's ramp into the work (degrees).
    #[serde(default)]
    pub ramp_angle: Option<f64>,
    #[serde(default)]
    pub max_feed: Option<f64>,
    #[serde(default)]
    pub max_spindle: Option<f64>,
    #[serde(default)]
    pub max_power: Option<f64>,
}

/// How a tool runs in the program: the machine's data where it gives them, the plan's
/// otherwise.
#[derive(Debug, Clone, PartialEq)]
pub struct Cutting {
    /// mm/s
    pub feed: f64,
    pub spindle: Option<f64>,
    pub power: Option<f64>,
    /// degrees
    pub ramp_angle: f64,
}

/// Ramp of a cutter that names none (degrees): a common figure for small end mills.
pub const RAMP_ANGLE: f64 = 3.0;

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
            && t.diameter.is_finite()
            && t.diameter > 0.0
            && t.spindle.is_none_or(|s| s.is_finite() && s > 0.0)
            && t.power.is_none_or(|p| p.is_finite() && p > 0.0)
    });
    if finite && tool_ok {
        Ok(())
    } else {
        Err(Error::stage(
            "export:nc",
            format!(
                "`{}`: a height, a point, a value or its tool's size, feed, speed or power is not a finite positive number",
                op.kind
            ),
        ))
    }
}

/// `template` with each `{key}` replaced; the keys were checked when the machine loaded.
pub fn render(template: &str, values: &[(&str, String)]) -> String {
    let mut s = template.to_string();
    for (k, v) in values {
        s = s.replace(&format!("{{{k}}}"), v);
    }
    s
}

/// Checks that `lines` name no placeholder but `allowed`, and hold one line each.
fn placeholders(key: &str, lines: &Lines, allowed: &[&str]) -> std::result::Result<(), String> {
    for line in lines.lines() {
        if line.contains(['\n', '\r']) {
            return Err(format!("controller.{key}: one line per string"));
        }
        let mut rest = line.as_str();
        while let Some(i) = rest.find('{') {
            let Some(j) = rest[i..].find('}') else {
                return Err(format!("controller.{key}: `{line}` opens a `{{` it never closes"));
            };
            let name = &rest[i + 1..i + j];
            if !allowed.contains(&name) {
                return Err(format!(
                    "controller.{key}: `{{{name}}}` means nothing here{}",
                    if allowed.is_empty() {
                        String::new()
                    } else {
                        format!(
                            " (it may use {})",
                            allowed
                                .iter()
                                .map(|a| format!("{{{a}}}"))
                                .collect::<Vec<_>>()
                                .join(", ")
                        )
                    }
                ));
            }
            rest = &rest[i + j + 1..];
        }
    }
    Ok(())
}

/// A wheel rim's surface speed (m/s); the other ranges are the operations' own
/// ([`crate::tool`]).
const RANGE_SURFACE_SPEED: (f64, f64, &str) = (0.01, 500.0, "m/s");

impl HybridMachine {
    /// A built-in machine by name, or a file (relative to `base_dir`, read within `reach`).
    pub fn load(
        reference: &str,
        base_dir: &Path,
        reach: &Reach,
    ) -> std::result::Result<HybridMachine, String> {
        let (origin, text) = match BUILT_IN.iter().find(|(n, _)| *n == reference) {
            Some((n, text)) => (format!("built-in machine `{n}`"), (*text).to_string()),
            None => {
                let path = base_dir.join(reference);
                let names: Vec<&str> = BUILT_IN.iter().map(|(n, _)| *n).collect();
                let text = reach.read_text(&path).map_err(|e| {
                    format!(
                        "`{reference}` is no built-in machine ({}) and {} cannot be read: {e}",
                        names.join(", "),
                        path.display()
                    )
                })?;
                (path.display().to_string(), text)
            }
        };
        let machine: HybridMachine = toml::from_str(&text).map_err(|e| format!("{origin}: {e}"))?;
        machine.check().map_err(|e| format!("{origin}: {e}"))?;
        Ok(machine)
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
            // Physical ranges, wider than any tool: a value outside is a mistake, and a
            // huge one would reach the geometry and the program's words.
            let ranges = [
                ("diameter", Some(t.diameter), tool::DIAMETER),
                ("feed", t.feed, tool::FEED),
                ("spindle", t.spindle, tool::SPINDLE),
                ("surface_speed", t.surface_speed, RANGE_SURFACE_SPEED),
                ("power", t.power, tool::POWER),
                ("max_feed", t.max_feed, tool::FEED),
                ("max_spindle", t.max_spindle, tool::SPINDLE),
                ("max_power", t.max_power, tool::POWER),
            ];
            for (key, v, (lo, hi, unit)) in ranges {
                if v.is_some_and(|v| !(v.is_finite() && (lo..=hi).contains(&v))) {
                    return Err(format!(
                        "tools[{i}] (`{}`): {key} must lie in {lo}..={hi} {unit}",
                        t.name
                    ));
                }
            }
            if t.ramp_angle
                .is_some_and(|a| !(a.is_finite() && a > 0.0 && a <= 45.0))
            {
                return Err(format!(
                    "tools[{i}] (`{}`): ramp_angle must lie in (0, 45] degrees",
                    t.name
                ));
            }
            if t.spindle.is_some() && t.surface_speed.is_some() {
                return Err(format!(
                    "tools[{i}] (`{}`): give `spindle` or `surface_speed`, not both",
                    t.name
                ));
            }
            for (key, v, max) in [
                ("feed", t.feed, t.max_feed),
                ("spindle", t.spindle, t.max_spindle),
                ("power", t.power, t.max_power),
            ] {
                if let (Some(v), Some(max)) = (v, max)
                    && v > max
                {
                    return Err(format!(
                        "tools[{i}] (`{}`): {key} {v} is above the tool's max_{key} {max}",
                        t.name
                    ));
                }
            }
        }
        let o = self.outputs;
        let set: Vec<u32> = [o.spray, o.filler, o.vacuum].into_iter().flatten().collect();
        if set.iter().enumerate().any(|(i, a)| set[..i].contains(a)) {
            return Err("outputs: the spray gun, the filler and the vacuum need outputs of their own".into());
        }
        if !(self.feeders.scale.is_finite() && self.feeders.scale > 0.0) {
            return Err("feeders.scale must be positive".into());
        }
        let m = self.motion;
        let within = |v: &f64, (lo, hi): (f64, f64)| v.is_finite() && (lo..=hi).contains(v);
        if !m.rapid.iter().all(|v| within(v, (1.0, 1e6)))
            || !m.acceleration.iter().all(|v| within(v, (1.0, 1e6)))
        {
            return Err(
                "motion: every rapid speed lies in 1..=1000000 mm/min, every acceleration in 1..=1000000 mm/s²"
                    .into(),
            );
        }
        if !(m.junction_deviation.is_finite() && m.junction_deviation >= 0.0) {
            return Err("motion.junction_deviation must be zero or a positive number of mm".into());
        }
        if !(m.tool_change.is_finite()
            && m.tool_change >= 0.0
            && m.spindle_start.is_finite()
            && m.spindle_start >= 0.0)
        {
            return Err("motion: tool_change and spindle_start are seconds, zero or more".into());
        }
        let c = &self.controller;
        for (key, lines, allowed) in [
            ("header", &c.header, &[][..]),
            ("start", &c.start, &[][..]),
            ("retract", &c.retract, &[][..]),
            ("tool_change", &c.tool_change, &["tool"][..]),
            ("length_on", &c.length_on, &["tool"][..]),
            ("length_off", &c.length_off, &[][..]),
            ("output_on", &c.output_on, &["output"][..]),
            ("output_off", &c.output_off, &["output"][..]),
            ("analog", &c.analog, &["output", "value"][..]),
            ("spindle_on", &c.spindle_on, &["speed"][..]),
            ("spindle_off", &c.spindle_off, &[][..]),
            ("laser_on", &c.laser_on, &["power"][..]),
            ("laser_off", &c.laser_off, &[][..]),
            ("end", &c.end, &[][..]),
        ] {
            placeholders(key, lines, allowed)?;
        }
        if c.start.is_empty() || c.retract.is_empty() || c.end.is_empty() {
            return Err("controller: `start`, `retract` and `end` are needed by every program".into());
        }
        for (on, off, a, b) in [
            (&c.output_on, &c.output_off, "output_on", "output_off"),
            (&c.length_on, &c.length_off, "length_on", "length_off"),
            (&c.spindle_on, &c.spindle_off, "spindle_on", "spindle_off"),
            (&c.laser_on, &c.laser_off, "laser_on", "laser_off"),
        ] {
            if on.is_empty() != off.is_empty() {
                return Err(format!("controller: `{a}` and `{b}` go in pairs"));
            }
        }
        if !(c.power_scale.is_finite() && c.power_scale > 0.0) {
            return Err("controller.power_scale must be positive".into());
        }
        if !self.feeders.outputs.is_empty() && c.analog.is_empty() {
            return Err(format!(
                "feeders: the controller ({}) has no analog outputs (`controller.analog`) to set them",
                c.dialect
            ));
        }
        Ok(())
    }

    pub fn tool(&self, name: &str) -> Option<&HybridTool> {
        self.tools.iter().find(|t| t.name == name)
    }

    /// How the machine runs `tool`: its own data where it gives them, each checked against
    /// its limits. A wheel whose surface speed needs a spindle faster than the machine's
    /// runs at the machine's top speed, and the note says so.
    pub fn cutting(&self, tool: &lamina_api::OperationTool, notes: &mut Vec<Warning>) -> Result<Cutting> {
        let fail = |m: String| Err(Error::stage("export:nc", m));
        let own = self.tool(&tool.name);
        let feed = own.and_then(|t| t.feed).unwrap_or(tool.feed);
        let power = own.and_then(|t| t.power).or(tool.power);
        let ramp_angle = own.and_then(|t| t.ramp_angle).unwrap_or(RAMP_ANGLE);
        let mut spindle = own.and_then(|t| t.spindle).or(tool.spindle);
        if let Some(t) = own
            && let Some(v) = t.surface_speed
        {
            let wanted = v * 60_000.0 / (std::f64::consts::PI * t.diameter);
            let top = t.max_spindle.unwrap_or(f64::INFINITY);
            if wanted > top {
                let reached = top * std::f64::consts::PI * t.diameter / 60_000.0;
                let note = Warning::new(
                    "surface-speed-unreached",
                    format!(
                        "`{}` turns at most {top} rev/min: {reached:.1} m/s on its {} mm rim, below the {v} m/s it wants ({wanted:.0} rev/min)",
                        t.name, t.diameter
                    ),
                );
                if !notes.contains(&note) {
                    notes.push(note);
                }
                spindle = Some(top);
            } else {
                spindle = Some(wanted.round());
            }
        }
        if let Some(t) = own {
            let name = &t.name;
            if let (Some(max), true) = (t.max_feed, t.max_feed.is_some_and(|m| feed > m)) {
                return fail(format!(
                    "`{name}` feeds at most {max} mm/s, the program asks {feed}"
                ));
            }
            if let (Some(max), Some(s)) = (t.max_spindle, spindle)
                && s > max
            {
                return fail(format!(
                    "`{name}` turns at most {max} rev/min, the program asks {s}"
                ));
            }
            if let (Some(max), Some(p)) = (t.max_power, power)
                && p > max
            {
                return fail(format!("`{name}` gives at most {max} W, the program asks {p}"));
            }
        }
        Ok(Cutting {
            feed,
            spindle,
            power,
            ramp_angle,
        })
    }

    /// Checks that the machine has `op`'s tool; the error says what the machine lacks. The
    /// travel is checked move by move as the program is written.
    pub fn admits(&self, op: &Operation) -> Result<()> {
        let fail = |m: String| Err(Error::stage("export:nc", format!("`{}`: {m}", op.kind)));
        readable(op)?;
        let Some(tool) = &op.tool else { return Ok(()) };
        let Some(own) = self.tool(&tool.name) else {
            let names: Vec<&str> = self.tools.iter().map(|t| t.name.as_str()).collect();
            return fail(format!(
                "the machine `{}` has no tool `{}` (tools: {})",
                self.name,
                tool.name,
                names.join(", ")
            ));
        };
        if own.kind != tool.kind {
            return fail(format!(
                "`{}` is a {} in the machine, the plan wants a {}",
                own.name, own.kind, tool.kind
            ));
        }
        if (own.diameter - tool.diameter).abs() > 1e-9 {
            return fail(format!(
                "`{}` measures {} mm in the machine, the plan was made for {} mm",
                own.name, own.diameter, tool.diameter
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_built_in_machine_loads() {
        for (name, _) in BUILT_IN {
            let c = HybridMachine::load(name, Path::new("."), &Reach::anywhere()).expect("loads");
            assert_eq!(&c.name, name);
            assert!(!c.tools.is_empty());
        }
        let err = HybridMachine::load("nowhere.toml", Path::new("."), &Reach::folder(Path::new(".")))
            .expect_err("no file");
        assert!(err.contains("no built-in machine (cmpm-hybrid"), "{err}");
    }

    #[test]
    fn tool_and_motion_values_outside_their_physical_range_are_refused_by_name() {
        let text = include_str!("../machines/cmpm-hybrid.toml");
        for (what, change, expected) in [
            ("a huge mill", "diameter", "diameter must lie in 0.001..=1000 mm"),
            ("a crawling feed", "feed", "feed must lie in 0.01..=10000 mm/s"),
        ] {
            let mut machine: HybridMachine = toml::from_str(text).expect("parses");
            let tool = &mut machine.tools[0];
            match change {
                "diameter" => tool.diameter = 1e300,
                _ => tool.feed = Some(5e-324),
            }
            let err = machine.check().expect_err(what);
            assert!(err.contains(expected), "{what}: {err}");
        }
        let mut machine: HybridMachine = toml::from_str(text).expect("parses");
        machine.motion.rapid[0] = 1e300;
        assert!(
            machine
                .check()
                .expect_err("a rapid of 1e300")
                .contains("1..=1000000 mm/min")
        );
    }

    #[test]
    fn each_mistake_in_a_machine_profile_is_refused_with_what_is_wrong() {
        let text = include_str!("../machines/cmpm-hybrid.toml");
        let good = || -> HybridMachine { toml::from_str(text).expect("parses") };
        assert_eq!(good().check(), Ok(()));
        type Change = fn(&mut HybridMachine);
        // Limits themselves are allowed.
        let allowed: [(&str, Change); 6] = [
            ("a ramp of 45 degrees", |m| m.tools[0].ramp_angle = Some(45.0)),
            ("a feed at its maximum", |m| m.tools[0].feed = m.tools[0].max_feed),
            ("a spindle at its maximum", |m| {
                m.tools[0].spindle = m.tools[0].max_spindle
            }),
            ("no junction deviation", |m| m.motion.junction_deviation = 0.0),
            ("an instant tool change", |m| {
                m.motion.tool_change = 0.0;
                m.motion.spindle_start = 0.0;
            }),
            ("no outputs", |m| m.outputs = Outputs::default()),
        ];
        for (what, change) in allowed {
            let mut m = good();
            change(&mut m);
            assert_eq!(m.check(), Ok(()), "{what}");
        }
        let refused: [(&str, Change); 30] = [
            ("travel.x must be", |m| m.travel.x = [10.0, 10.0]),
            ("travel.y must be", |m| m.travel.y = [f64::NAN, 1.0]),
            ("travel.z must be", |m| m.travel.z = [0.0, f64::INFINITY]),
            ("tools[0] (`end-mill`): numbers start at 1", |m| {
                m.tools[0].number = 0
            }),
            ("tools[2] (`cup-wheel`): numbers start at 1", |m| {
                m.tools[2].number = 1
            }),
            ("tools[1] (`end-mill`): numbers start at 1", |m| {
                m.tools[1].name = "end-mill".into()
            }),
            ("spindle must lie in", |m| m.tools[0].spindle = Some(f64::NAN)),
            ("surface_speed must lie in", |m| {
                m.tools[2].surface_speed = Some(501.0)
            }),
            ("power must lie in", |m| m.tools[3].power = Some(-1.0)),
            ("max_feed must lie in", |m| {
                m.tools[0].max_feed = Some(f64::INFINITY)
            }),
            ("max_spindle must lie in", |m| m.tools[0].max_spindle = Some(0.0)),
            ("max_power must lie in", |m| m.tools[3].max_power = Some(1e12)),
            ("ramp_angle must lie in (0, 45]", |m| {
                m.tools[0].ramp_angle = Some(0.0)
            }),
            ("ramp_angle must lie in (0, 45]", |m| {
                m.tools[0].ramp_angle = Some(45.5)
            }),
            ("give `spindle` or `surface_speed`", |m| {
                m.tools[2].spindle = Some(3000.0)
            }),
            ("feed 60 is above the tool's max_feed 50", |m| {
                m.tools[0].feed = Some(60.0)
            }),
            ("spindle 30001 is above", |m| m.tools[0].spindle = Some(30_001.0)),
            ("power 51 is above", |m| m.tools[3].power = Some(51.0)),
            ("outputs: the spray gun, the filler", |m| {
                m.outputs.vacuum = m.outputs.spray
            }),
            ("feeders.scale must be positive", |m| m.feeders.scale = 0.0),
            ("every acceleration in", |m| m.motion.acceleration[2] = 0.5),
            ("junction_deviation must be zero or", |m| {
                m.motion.junction_deviation = -0.01
            }),
            ("tool_change and spindle_start", |m| {
                m.motion.spindle_start = f64::NAN
            }),
            ("tool_change and spindle_start", |m| m.motion.spindle_start = -1.0),
            ("tool_change and spindle_start", |m| m.motion.tool_change = -1.0),
            ("are needed by every program", |m| {
                m.controller.start = Lines::None
            }),
            ("are needed by every program", |m| {
                m.controller.retract = Lines::None
            }),
            ("are needed by every program", |m| m.controller.end = Lines::None),
            ("`spindle_on` and `spindle_off` go in pairs", |m| {
                m.controller.spindle_off = Lines::None
            }),
            ("has no analog outputs", |m| m.controller.analog = Lines::None),
        ];
        for (expected, change) in refused {
            let mut m = good();
            change(&mut m);
            let err = m.check().expect_err(expected);
            assert!(err.contains(expected), "{expected}: {err}");
        }
        let mut m = good();
        m.controller.power_scale = 0.0;
        assert!(
            m.check()
                .expect_err("power scale")
                .contains("power_scale must be positive")
        );
    }

    #[test]
    fn a_template_naming_what_its_line_cannot_know_is_refused() {
        let text = include_str!("../machines/cmpm-hybrid.toml").replace("T{tool} M6", "T{tol} M6");
        let machine: HybridMachine = toml::from_str(&text).expect("parses");
        let err = machine.check().expect_err("unknown placeholder");
        assert!(err.contains("controller.tool_change: `{tol}`"), "{err}");
    }

    #[test]
    fn a_wheel_too_fast_for_its_spindle_runs_at_the_top_speed_with_a_note() {
        let text = include_str!("../machines/cmpm-hybrid.toml");
        let mut machine: HybridMachine = toml::from_str(text).expect("parses");
        let wheel = machine
            .tools
            .iter_mut()
            .find(|t| t.kind == "grinding-wheel")
            .expect("a wheel");
        wheel.max_spindle = Some(6000.0);
        wheel.surface_speed = Some(25.0);
        let (name, diameter) = (wheel.name.clone(), wheel.diameter);
        let tool = lamina_api::OperationTool {
            name,
            kind: "grinding-wheel".into(),
            diameter,
            feed: 20.0,
            spindle: Some(3000.0),
            power: None,
        };
        let mut notes = Vec::new();
        let c = machine.cutting(&tool, &mut notes).expect("runs");
        assert_eq!(c.spindle, Some(6000.0));
        assert_eq!(notes.len(), 1, "{notes:?}");
        assert!(
            notes[0].code == "surface-speed-unreached"
                && notes[0].message.contains("6.3 m/s")
                && notes[0].message.contains("below the 25 m/s"),
            "{}",
            notes[0]
        );
        // A feed beyond the tool's limit is refused, naming the tool and both figures.
        let mut fast = tool.clone();
        fast.feed = 150.0;
        let err = machine
            .cutting(&fast, &mut notes)
            .expect_err("too fast")
            .to_string();
        assert!(
            err.contains("`cup-wheel` feeds at most 100 mm/s, the program asks 150"),
            "{err}"
        );
        // Within the spindle's range, the speed follows v = pi d n.
        let fast = machine
            .tools
            .iter_mut()
            .find(|t| t.kind == "grinding-wheel")
            .expect("a wheel");
        fast.max_spindle = Some(30_000.0);
        let c = machine.cutting(&tool, &mut notes).expect("runs");
        let want = (25.0 * 60_000.0 / (std::f64::consts::PI * diameter)).round();
        assert_eq!(c.spindle, Some(want));
        // A top speed the wheel needs exactly is reached: no note.
        let exact = 25.0 * 60_000.0 / (std::f64::consts::PI * diameter);
        machine
            .tools
            .iter_mut()
            .find(|t| t.name == "cup-wheel")
            .expect("wheel")
            .max_spindle = Some(exact);
        let mut quiet = Vec::new();
        machine.cutting(&tool, &mut quiet).expect("runs");
        assert!(quiet.is_empty(), "{quiet:?}");
    }

    #[test]
    fn a_tool_runs_up_to_its_own_limits_and_not_beyond() {
        let text = include_str!("../machines/cmpm-hybrid.toml");
        let machine: HybridMachine = toml::from_str(text).expect("parses");
        let tool = |name: &str, feed: f64, spindle: Option<f64>, power: Option<f64>| {
            let own = machine.tool(name).expect("a tool of the machine");
            lamina_api::OperationTool {
                name: name.into(),
                kind: own.kind.clone(),
                diameter: own.diameter,
                feed,
                spindle,
                power,
            }
        };
        let run =
            |t: &lamina_api::OperationTool| machine.cutting(t, &mut Vec::new()).map_err(|e| e.to_string());
        // The laser: the plan's feed and power up to the machine's 2000 mm/s and 50 W.
        let c = run(&tool("laser", 2000.0, None, Some(50.0))).expect("at the limits");
        assert_eq!((c.feed, c.power, c.spindle), (2000.0, Some(50.0), None));
        let err = run(&tool("laser", 2000.5, None, Some(50.0))).expect_err("feed");
        assert!(
            err.contains("`laser` feeds at most 2000 mm/s, the program asks 2000.5"),
            "{err}"
        );
        let err = run(&tool("laser", 100.0, None, Some(50.5))).expect_err("power");
        assert!(
            err.contains("`laser` gives at most 50 W, the program asks 50.5"),
            "{err}"
        );
        // The end mill's own feed and spindle (5 mm/s, 24000 rev/min) win over the plan's.
        let c = run(&tool("end-mill", 40.0, Some(1000.0), None)).expect("its own");
        assert_eq!((c.feed, c.spindle), (5.0, Some(24_000.0)));
        // A tool the machine does not list runs as the plan says.
        let free = lamina_api::OperationTool {
            name: "other".into(),
            kind: "end-mill".into(),
            diameter: 1.0,
            feed: 1e4,
            spindle: Some(1e6),
            power: None,
        };
        assert_eq!(run(&free).expect("unlisted").spindle, Some(1e6));
        let mut fast = machine.clone();
        let mill = fast
            .tools
            .iter_mut()
            .find(|t| t.name == "end-mill")
            .expect("mill");
        mill.spindle = None;
        let at =
            |m: &HybridMachine, s: f64| m.cutting(&tool("end-mill", 1.0, Some(s), None), &mut Vec::new());
        assert_eq!(at(&fast, 30_000.0).expect("at the top").spindle, Some(30_000.0));
        let err = at(&fast, 30_001.0).expect_err("too fast").to_string();
        assert!(
            err.contains("`end-mill` turns at most 30000 rev/min, the program asks 30001"),
            "{err}"
        );
    }

    #[test]
    fn the_machine_admits_an_operation_only_with_a_tool_it_has_as_planned() {
        let text = include_str!("../machines/cmpm-hybrid.toml");
        let machine: HybridMachine = toml::from_str(text).expect("parses");
        let op = |name: &str, kind: &str, diameter: f64| {
            let mut op = Operation::new("mill", Some(0));
            op.tool = Some(lamina_api::OperationTool {
                name: name.into(),
                kind: kind.into(),
                diameter,
                feed: 5.0,
                spindle: Some(24_000.0),
                power: None,
            });
            op
        };
        let admits = |o: &Operation| machine.admits(o).map_err(|e| e.to_string());
        assert_eq!(admits(&op("end-mill", "end-mill", 0.8)), Ok(()));
        assert_eq!(admits(&op("end-mill", "end-mill", 0.8 + 1e-12)), Ok(()));
        assert_eq!(admits(&Operation::new("probe", Some(0))), Ok(()));
        let err = admits(&op("drill", "end-mill", 0.8)).expect_err("no such tool");
        assert!(
            err.contains("`mill`: the machine `cmpm-hybrid` has no tool `drill` (tools: end-mill, spray-gun"),
            "{err}"
        );
        let err = admits(&op("end-mill", "laser", 0.8)).expect_err("another kind");
        assert!(
            err.contains("`end-mill` is a end-mill in the machine, the plan wants a laser"),
            "{err}"
        );
        for d in [0.8 - 1e-6, 0.8 + 1e-6] {
            let err = admits(&op("end-mill", "end-mill", d)).expect_err("another size");
            assert!(
                err.contains("`end-mill` measures 0.8 mm in the machine, the plan was made for"),
                "{err}"
            );
        }
        // An unreadable number is refused before the tool is looked at.
        let mut nan = op("drill", "end-mill", 0.8);
        nan.surface = Some(f64::NAN);
        assert!(admits(&nan).expect_err("NaN").contains("finite positive"));
    }

    #[test]
    fn an_operation_with_a_number_no_controller_can_read_is_refused() {
        let good = || {
            let mut op = Operation::new("grind", Some(0));
            op.surface = Some(1.0);
            op.values.insert("depth".into(), 0.1);
            op.paths.push(lamina_api::OperationPath {
                z: 1.0,
                points: vec![
                    lamina_api::Point2::new(0.0, 0.0),
                    lamina_api::Point2::new(1.0, 0.0),
                ],
                closed: false,
            });
            op.tool = Some(lamina_api::OperationTool {
                name: "wheel".into(),
                kind: "grinding-wheel".into(),
                diameter: 20.0,
                feed: 20.0,
                spindle: Some(3000.0),
                power: Some(100.0),
            });
            op
        };
        assert!(readable(&good()).is_ok());
        let mut no_tool = good();
        no_tool.tool = None;
        no_tool.surface = None;
        assert!(readable(&no_tool).is_ok());
        type Spoil = fn(&mut Operation);
        let spoiled: [(&str, Spoil); 16] = [
            ("surface", |o| o.surface = Some(f64::NAN)),
            ("value", |o| {
                o.values.insert("depth".into(), f64::INFINITY);
            }),
            ("path height", |o| o.paths[0].z = f64::NAN),
            ("x", |o| o.paths[0].points[1].x = f64::INFINITY),
            ("y", |o| o.paths[0].points[0].y = f64::NEG_INFINITY),
            ("feed", |o| o.tool.as_mut().expect("tool").feed = 0.0),
            ("feed", |o| o.tool.as_mut().expect("tool").feed = f64::NAN),
            ("diameter", |o| o.tool.as_mut().expect("tool").diameter = -1.0),
            ("diameter", |o| {
                o.tool.as_mut().expect("tool").diameter = f64::INFINITY
            }),
            ("diameter", |o| o.tool.as_mut().expect("tool").diameter = 0.0),
            ("spindle", |o| o.tool.as_mut().expect("tool").spindle = Some(0.0)),
            ("spindle", |o| {
                o.tool.as_mut().expect("tool").spindle = Some(f64::INFINITY)
            }),
            ("power", |o| o.tool.as_mut().expect("tool").power = Some(f64::NAN)),
            ("power", |o| o.tool.as_mut().expect("tool").power = Some(0.0)),
            ("power", |o| o.tool.as_mut().expect("tool").power = Some(-5.0)),
            ("power", |o| {
                o.tool.as_mut().expect("tool").power = Some(f64::INFINITY)
            }),
        ];
        for (what, spoil) in spoiled {
            let mut op = good();
            spoil(&mut op);
            let err = readable(&op).expect_err(what).to_string();
            assert!(
                err.contains("`grind`") && err.contains("finite positive"),
                "{what}: {err}"
            );
        }
    }

    #[test]
    fn templates_name_only_their_placeholders_and_render_them() {
        let lines = |v: &[&str]| Lines::Many(v.iter().map(|s| s.to_string()).collect());
        assert!(placeholders("start", &lines(&["G21", "S{speed} M3 ; {speed}"]), &["speed"]).is_ok());
        let err = placeholders("start", &lines(&["G21", "T{tol}"]), &["tool", "speed"]).expect_err("unknown");
        assert_eq!(
            err,
            "controller.start: `{tol}` means nothing here (it may use {tool}, {speed})"
        );
        // The scan goes on after each placeholder, wherever it stands in the line.
        let err = placeholders("start", &lines(&["G21 M3 S{speed} T{tol} ; {speed}"]), &["speed"])
            .expect_err("unknown after a known one");
        assert!(err.contains("`{tol}`"), "{err}");
        let err = placeholders("end", &lines(&["M5 {x}"]), &[]).expect_err("none allowed");
        assert_eq!(err, "controller.end: `{x}` means nothing here");
        let err = placeholders("start", &lines(&["S{speed"]), &["speed"]).expect_err("unclosed");
        assert!(err.contains("opens a `{` it never closes"), "{err}");
        let err = placeholders("start", &lines(&["G21\nG90"]), &[]).expect_err("two lines");
        assert_eq!(err, "controller.start: one line per string");
        assert_eq!(
            render(
                "T{tool} M6 ; {tool} at {speed}",
                &[("tool", "3".into()), ("speed", "800".into())]
            ),
            "T3 M6 ; 3 at 800"
        );
    }
}
