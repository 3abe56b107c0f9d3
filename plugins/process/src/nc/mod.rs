//! `nc`: the operations as an NC program for a hybrid machine, in the dialect of the machine's
//! controller (`hybrid.rs`: LinuxCNC, a Fanuc-like controller and Grbl ship built in).
//!
//! - **Start and end.** The controller's header and safe start (units, plane, modes,
//!   compensations cancelled, work offset); at the end everything stops, the length
//!   offset is cancelled, the head rises to the safe height in machine coordinates,
//!   then the program ends.
//! - **Tool changes** at the safe height in machine coordinates, with the length offset
//!   cancelled before and the new tool's applied after. Tools are numbered by the machine,
//!   or without one by the `tools` table, the rest in the order they first come.
//! - **Cutters never plunge.** An end mill ramps down along its own path
//!   (`entry::ramp`); a cup wheel enters each pass from the side, lowered beside the
//!   part where its face is clear (`entry::side_entry`). Both turn at the machine's cutting
//!   data (a wheel's speed from its surface speed) with the chip vacuum on.
//! - **The laser** stays at its focal height across a layer's rings, off between them;
//!   it steps down to each pass's floor, so the engraving's depth is in Z.
//! - **The spray** sets every powder feeder to its volume fraction in the sub-region's
//!   composition, with the inclusions (a composite's matrix takes what they leave),
//!   before the gun opens; the gun stands `spray_standoff` above the surface.
//! - **No wasted lines.** A move to where the tool is, or a word already in force, is
//!   not written.
//! - **Cycle time.** The program's header gives the time it takes by the machine's motion
//!   limits, tool-change and spindle times, with each operation's share; the run's
//!   summary prints the same.
//!
//! The program is held until the last layer, since its header carries the time.

mod entry;
mod program;

use std::collections::BTreeMap;
use std::io::Write;
use std::path::PathBuf;

use lamina_api::stage::{
    AnyStage, ExportContext, Exporter, LayerSink, OutputFiles, StageConfig, StageInfo, StageKind,
};
use lamina_api::{
    Error, LayerPlan, MachineFileReport, Operation, Point2, Polygon, Result, RunInfo, Sequence, StageFactory,
    Warning,
};

use crate::area::{distance_to_area, layer_area};
use crate::hybrid::{Cutting, HybridMachine, RAMP_ANGLE};
use crate::tool::LENGTH;
use program::{Program, number};

lamina_api::stage_options! {
    #[derive(Debug, Clone)]
    struct Options {
        /// the NC file
        path: PathBuf = r#""job.nc""#,
        /// the hybrid machine: a built-in profile (`cmpm-hybrid`, `cmpm-hybrid-fanuc`, `grbl-laser`) or a TOML file; its controller, tools, feeders and motion shape the program, and every operation is checked against it; empty: a LinuxCNC program with tools numbered by `tools` (formerly `cell`)
        #[formerly("cell")]
        machine: String = "\"\"",
        /// tool numbers by tool name, without a `machine`; tools not listed get the next free number
        tools: BTreeMap<String, u32> = "{}",
        /// height above the highest surface so far at which tools travel between operations (mm)
        #[range(0.0, LENGTH)]
        clearance: f64 = "5.0",
        /// height above the highest surface so far from which cutters ramp in and at which they move between passes (mm)
        #[range(0.0, LENGTH)]
        approach: f64 = "1.0",
        /// room between a cup wheel's face and the part where it is lowered beside it (mm)
        #[range(0.0, LENGTH)]
        wheel_margin: f64 = "1.0",
        /// height of the spray gun above the surface it sprays (mm)
        #[range(0.0, LENGTH)]
        spray_standoff: f64 = "80.0",
        /// height of the filler nozzle above the surface (mm)
        #[range(0.0, LENGTH)]
        fill_standoff: f64 = "1.0",
        /// feed of a cutter's ramp into the work, as a share of its feed
        #[range(0.01, 1.0)]
        plunge: f64 = "0.3",
    }
}

/// The controller and motion of a program written without a machine.
const GENERIC: &str = include_str!("../../machines/generic-linuxcnc.toml");

struct Nc {
    options: Options,
    /// The machine named, or the generic profile (`named` false).
    machine: HybridMachine,
    named: bool,
}

struct Sink {
    out: Box<dyn Write + Send>,
    path: PathBuf,
    options: Options,
    regions: Vec<String>,
    numbers: BTreeMap<String, u32>,
    named: bool,
    program: Program,
    /// Highest surface so far (mm).
    top: f64,
    notes: Vec<Warning>,
    title: String,
}

fn io(path: &std::path::Path) -> impl Fn(std::io::Error) -> Error + '_ {
    move |e| Error::io(path, e)
}

/// A comment's text: one line, no parentheses (they would end it) and no semicolons
/// (they start a comment of their own), at most 200 characters (LinuxCNC reads lines of
/// up to 255).
pub(crate) fn comment(s: &str) -> String {
    let text = lamina_api::text::one_line(s)
        .replace(['(', ')'], "")
        .replace(';', ",");
    match text.char_indices().nth(200) {
        Some((i, _)) => text[..i].to_string(),
        None => text,
    }
}

/// Seconds as hours, minutes and seconds.
fn duration(s: f64) -> String {
    let s = s.round() as u64;
    match (s / 3600, s % 3600 / 60, s % 60) {
        (0, 0, sec) => format!("{sec} s"),
        (0, m, sec) => format!("{m} min {sec} s"),
        (h, m, sec) => format!("{h} h {m} min {sec} s"),
    }
}

impl Exporter for Nc {
    fn open(&self, ctx: &mut ExportContext<'_>) -> Result<Box<dyn LayerSink>> {
        let path = self.options.path.clone();
        let out = ctx.files.create(&path)?;
        let regions = ctx
            .sequence
            .map(|s: &Sequence| s.regions.iter().map(|r| r.name.clone()).collect())
            .unwrap_or_default();
        let numbers: BTreeMap<String, u32> = if self.named {
            self.machine
                .tools
                .iter()
                .map(|t| (t.name.clone(), t.number))
                .collect()
        } else {
            self.options.tools.clone()
        };
        Ok(Box::new(Sink {
            out,
            path,
            options: self.options.clone(),
            regions,
            numbers,
            named: self.named,
            program: Program::new(self.machine.clone()),
            top: 0.0,
            notes: Vec::new(),
            title: format!("lamina nc: {}, {} layers", ctx.pipeline_name, ctx.layer_count),
        }))
    }
}

impl Sink {
    fn region_name(&self, r: Option<usize>, none: &str) -> String {
        r.map(|r| self.regions.get(r).cloned().unwrap_or_else(|| format!("#{r}")))
            .unwrap_or_else(|| none.into())
    }

    /// Over to `p` and down to `z`: first up to `clear` where the tool stands lower
    /// (from an unknown height, the safe height, across first).
    fn travel_to(&mut self, p: Point2, z: f64, clear: f64) -> Result<()> {
        let pr = &mut self.program;
        match pr.z() {
            Some(now) if now < clear - 1e-9 => pr.rapid(None, None, Some(clear))?,
            _ => {}
        }
        pr.rapid(Some(p.x), Some(p.y), None)?;
        pr.rapid(None, None, Some(z))
    }

    fn operation(&mut self, op: &Operation, area: &[Polygon]) -> Result<()> {
        let mut about = op.kind.clone();
        if !op.pass.is_empty() {
            about.push_str(&format!(" {}", op.pass));
        }
        about.push_str(&format!(", region {}", self.region_name(op.region, "-")));
        if let Some(s) = op.surface {
            about.push_str(&format!(", surface to {}", number(s, false)));
        }
        for (k, v) in &op.values {
            about.push_str(&format!(", {k} {}", number(*v, false)));
        }
        self.program.line(format!("({})", comment(&about)));
        let Some(tool) = &op.tool else {
            // An operation without a tool is for the operator, with everything off and
            // the head out of the way.
            let pr = &mut self.program;
            pr.spindle_off();
            pr.laser_off();
            pr.outputs_off();
            pr.retract();
            pr.line("M0 (operator: see the comment above)");
            return Ok(());
        };
        if op.paths.is_empty() {
            return Ok(());
        }
        let next = self.numbers.values().max().copied().unwrap_or(0) + 1;
        let n = *self.numbers.entry(tool.name.clone()).or_insert(next);
        self.program.change(&tool.name, n)?;
        self.program.doing = op.kind.clone();
        let cutting = if self.named {
            self.program.machine.cutting(tool, &mut self.notes)?
        } else {
            Cutting {
                feed: tool.feed,
                spindle: tool.spindle,
                power: tool.power,
                ramp_angle: RAMP_ANGLE,
            }
        };
        let top = self
            .top
            .max(op.paths.iter().map(|p| p.z).fold(f64::NEG_INFINITY, f64::max));
        match tool.kind.as_str() {
            "spray" => self.spray(op, &cutting)?,
            "dispenser" => self.fill(op, &cutting, area)?,
            "laser" => self.laser(op, &cutting)?,
            "grinding-wheel" => self.grind(op, &cutting, tool.diameter / 2.0, area)?,
            _ => self.cut(op, &cutting)?,
        }
        self.top = top;
        if let Some(s) = op.surface {
            self.top = self.top.max(s);
        }
        let z = self.top + self.options.clearance;
        self.program.rapid(None, None, Some(z))
    }

    /// The feeders set to the spray's mix, then each pass with the gun open.
    fn spray(&mut self, op: &Operation, c: &Cutting) -> Result<()> {
        let fractions: Vec<(&str, f64)> = op
            .values
            .iter()
            .filter_map(|(k, v)| k.strip_prefix("fraction:").map(|m| (m, *v)))
            .collect();
        let inclusions: Vec<(&str, f64)> = op
            .values
            .iter()
            .filter_map(|(k, v)| k.strip_prefix("inclusion:").map(|m| (m, *v)))
            .collect();
        let matrix = 1.0 - inclusions.iter().map(|(_, v)| v).sum::<f64>();
        let mix: Vec<(&str, f64)> = fractions
            .iter()
            .map(|&(m, f)| (m, f * matrix))
            .chain(inclusions.iter().copied())
            .collect();
        let feeders = self.program.machine.feeders.clone();
        if feeders.outputs.is_empty() {
            let said: Vec<String> = mix
                .iter()
                .map(|(m, f)| format!("{m} {}", number(*f, false)))
                .collect();
            self.program.line(format!(
                "({})",
                comment(&format!(
                    "mix set by hand, the machine has no feeders: {}",
                    said.join(", ")
                ))
            ));
        } else {
            if fractions.is_empty() {
                return Err(Error::stage(
                    "export:nc",
                    "`spray`: the plan gives no composition to set the feeders to (a part of several materials that is not graded)",
                ));
            }
            for (m, _) in &mix {
                if !feeders.outputs.contains_key(*m) {
                    let names: Vec<&str> = feeders.outputs.keys().map(String::as_str).collect();
                    return Err(Error::stage(
                        "export:nc",
                        format!(
                            "`spray`: the machine `{}` has no feeder for `{m}` (feeders: {})",
                            self.program.machine.name,
                            names.join(", ")
                        ),
                    ));
                }
            }
            for (name, &output) in &feeders.outputs {
                let f: f64 = mix.iter().filter(|(m, _)| m == name).map(|(_, f)| f).sum();
                self.program.analog(output, f * feeders.scale)?;
            }
        }
        let gun = self.program.machine.outputs.spray;
        let standoff = self.options.spray_standoff;
        let clear = self.top + self.options.clearance;
        for (i, p) in op.paths.iter().enumerate() {
            let Some(&first) = p.points.first() else { continue };
            let h = p.z + standoff;
            if i == 0 {
                self.travel_to(first, h, clear.max(h))?;
            } else {
                // The gun stands far above everything: straight over.
                self.program.rapid(Some(first.x), Some(first.y), Some(h))?;
            }
            self.program.output(gun, true, "spray gun")?;
            self.along(&p.points, p.closed, h, c.feed)?;
            self.program.output(gun, false, "spray gun")?;
        }
        Ok(())
    }

    /// Feed moves along `points` at height `z` (closed: back to the first).
    fn along(&mut self, points: &[Point2], closed: bool, z: f64, feed: f64) -> Result<()> {
        let closing = closed && points.len() > 2;
        for q in points.iter().skip(1).chain(closing.then_some(&points[0])) {
            self.program.feed(Some(q.x), Some(q.y), Some(z), feed)?;
        }
        Ok(())
    }

    /// The laser's rings: down to each pass's focal height, on along a ring, off
    /// between rings, never up until the operation ends.
    fn laser(&mut self, op: &Operation, c: &Cutting) -> Result<()> {
        let vacuum = self.program.machine.outputs.vacuum;
        if vacuum.is_some() {
            self.program.output(vacuum, true, "chip vacuum")?;
        }
        let power = c.power.ok_or_else(|| {
            Error::stage(
                "export:nc",
                "`engrave`: the laser has no power, in the plan or in the machine",
            )
        })?;
        let clear = self.top + self.options.clearance;
        for (i, p) in op.paths.iter().enumerate() {
            let Some(&first) = p.points.first() else { continue };
            if i == 0 {
                self.travel_to(first, p.z, clear)?;
            } else {
                self.program.rapid(Some(first.x), Some(first.y), Some(p.z))?;
            }
            self.program.laser_on(power)?;
            self.along(&p.points, p.closed, p.z, c.feed)?;
            self.program.laser_off();
        }
        Ok(())
    }

    /// The filler's passes, the nozzle lifted between them only where the way over
    /// leaves the layer's area (where another region may stand higher).
    fn fill(&mut self, op: &Operation, c: &Cutting, area: &[Polygon]) -> Result<()> {
        let output = self.program.machine.outputs.filler;
        let standoff = self.options.fill_standoff;
        let (clear, approach) = (
            self.top + self.options.clearance,
            self.top + self.options.approach,
        );
        let mut at: Option<Point2> = None;
        for (i, p) in op.paths.iter().enumerate() {
            let Some(&first) = p.points.first() else { continue };
            let h = p.z + standoff;
            match at {
                Some(from) if i > 0 && over(from, first, area) => {
                    self.program.rapid(Some(first.x), Some(first.y), Some(h))?;
                }
                _ => self.travel_to(first, h, if i == 0 { clear } else { approach.max(h) })?,
            }
            self.program.output(output, true, "filler nozzle")?;
            self.along(&p.points, p.closed, h, c.feed)?;
            self.program.output(output, false, "filler nozzle")?;
            at = if p.closed {
                Some(first)
            } else {
                p.points.last().copied()
            };
        }
        Ok(())
    }

    /// A rotating cutter (an end mill, or a plugin's tool): ramped in along each path
    /// from just above the highest surface, up to it between paths. Every move of the
    /// ramp that goes down, the one reaching the depth too, runs at the plunge feed;
    /// the path at depth at the cutting feed.
    fn cut(&mut self, op: &Operation, c: &Cutting) -> Result<()> {
        self.spin(c)?;
        let approach = self.top + self.options.approach;
        let clear = self.top + self.options.clearance;
        for (i, p) in op.paths.iter().enumerate() {
            let start = approach.max(p.z);
            let way = entry::ramp(&p.points, p.closed, start, p.z, c.ramp_angle);
            let Some(&(first, _)) = way.first() else { continue };
            self.travel_to(first, start, if i == 0 { clear } else { approach })?;
            for w in way.windows(2) {
                let ((_, from), (q, z)) = (w[0], w[1]);
                let feed = if z < from - 1e-9 {
                    c.feed * self.options.plunge
                } else {
                    c.feed
                };
                self.program.feed(Some(q.x), Some(q.y), Some(z), feed)?;
            }
            self.program.rapid(None, None, Some(approach))?;
        }
        Ok(())
    }

    /// A cup wheel's passes, each entered from the side.
    fn grind(&mut self, op: &Operation, c: &Cutting, radius: f64, area: &[Polygon]) -> Result<()> {
        self.spin(c)?;
        let approach = self.top + self.options.approach;
        let clear = self.top + self.options.clearance;
        for (i, p) in op.paths.iter().enumerate() {
            let (Some(&a), Some(&b)) = (p.points.first(), p.points.last()) else {
                continue;
            };
            let wheel = entry::Wheel {
                radius,
                margin: self.options.wheel_margin,
                angle_deg: c.ramp_angle,
            };
            let way = entry::side_entry(a, b, p.z, approach.max(p.z), wheel, area);
            let Some(&(first, z0)) = way.first() else { continue };
            self.travel_to(first, z0, if i == 0 { clear } else { approach })?;
            let (down, _) = way[1];
            self.program.feed(
                Some(down.x),
                Some(down.y),
                Some(p.z),
                c.feed * self.options.plunge,
            )?;
            for &(q, z) in &way[2..] {
                self.program.feed(Some(q.x), Some(q.y), Some(z), c.feed)?;
            }
            self.program.rapid(None, None, Some(approach))?;
        }
        Ok(())
    }

    /// The chip vacuum on and the spindle at the cutting speed.
    fn spin(&mut self, c: &Cutting) -> Result<()> {
        let vacuum = self.program.machine.outputs.vacuum;
        if vacuum.is_some() {
            self.program.output(vacuum, true, "chip vacuum")?;
        }
        match c.spindle {
            Some(s) => self.program.spindle_on(s),
            None => Ok(()),
        }
    }
}

/// True when the straight way from `a` to `b` stays over `area` (sampled every
/// 0.25 mm).
fn over(a: Point2, b: Point2, area: &[Polygon]) -> bool {
    let steps = ((b - a).norm() / 0.25).ceil().max(1.0) as usize;
    (0..=steps).all(|k| distance_to_area(a + (b - a) * (k as f64 / steps as f64), area) == 0.0)
}

impl LayerSink for Sink {
    fn layer(&mut self, _info: &RunInfo, plan: &LayerPlan, _files: &mut dyn OutputFiles) -> Result<()> {
        if plan.operations.is_empty() {
            return Ok(());
        }
        for op in &plan.operations {
            crate::hybrid::readable(op).map_err(|e| e.in_layer(plan.index, plan.z))?;
            if self.named {
                self.program
                    .machine
                    .admits(op)
                    .map_err(|e| e.in_layer(plan.index, plan.z))?;
            }
        }
        let region = self.region_name(plan.material_region, "all");
        self.program.line(format!(
            "(layer {} region {} z {} thickness {})",
            plan.index,
            comment(&region),
            number(plan.z, false),
            number(plan.thickness, false)
        ));
        let needs_area = plan.operations.iter().any(|o| {
            o.tool
                .as_ref()
                .is_some_and(|t| matches!(t.kind.as_str(), "dispenser" | "grinding-wheel"))
        });
        let area = if needs_area { layer_area(plan) } else { Vec::new() };
        for op in &plan.operations {
            self.operation(op, &area)
                .map_err(|e| e.in_layer(plan.index, plan.z))?;
        }
        Ok(())
    }

    fn finish(mut self: Box<Self>, _info: &RunInfo, files: &mut dyn OutputFiles) -> Result<()> {
        self.program.end();
        let machine = &self.program.machine;
        let c = &machine.controller;
        let mut head = String::new();
        for l in c.header.lines() {
            head.push_str(l);
            head.push('\n');
        }
        let mut say = |s: String| {
            head.push_str(&format!("({})\n", comment(&s)));
        };
        say(self.title.clone());
        if self.named {
            say(format!("machine: {} - {}", machine.name, machine.description));
        }
        say(format!("controller: {}", c.dialect));
        let total = self.program.shares.total();
        let shares: Vec<String> = self
            .program
            .shares
            .by
            .iter()
            .filter(|(_, s)| *s > 0.0)
            .map(|(k, s)| format!("{k} {}", duration(*s)))
            .collect();
        say(format!(
            "estimated cycle time {total:.0} s = {}: {}",
            duration(total),
            shares.join(", ")
        ));
        let o = machine.outputs;
        let outputs: Vec<String> = [
            (o.spray, "spray gun"),
            (o.filler, "filler nozzle"),
            (o.vacuum, "chip vacuum"),
        ]
        .into_iter()
        .filter_map(|(n, what)| n.map(|n| format!("{n} {what}")))
        .collect();
        if !outputs.is_empty() {
            say(format!("outputs: {}", outputs.join(", ")));
        }
        if !machine.feeders.outputs.is_empty() {
            let feeders: Vec<String> = machine
                .feeders
                .outputs
                .iter()
                .map(|(m, n)| format!("{n} {m}"))
                .collect();
            say(format!(
                "feeders: {}, each set to its volume fraction times {}",
                feeders.join(", "),
                number(machine.feeders.scale, false)
            ));
        }
        let mut listed: Vec<(&String, &u32)> = self.numbers.iter().collect();
        listed.sort_by_key(|(_, n)| **n);
        for (name, n) in listed {
            say(format!("T{n} {name}"));
        }
        for l in c.start.lines() {
            head.push_str(l);
            head.push('\n');
        }
        self.out.write_all(head.as_bytes()).map_err(io(&self.path))?;
        self.out
            .write_all(self.program.text.as_bytes())
            .map_err(io(&self.path))?;
        self.out.flush().map_err(io(&self.path))?;
        files.report(MachineFileReport {
            file: self.path.clone(),
            time: total,
            shares: self.program.shares.by.clone(),
            notes: std::mem::take(&mut self.notes),
            ..MachineFileReport::default()
        });
        Ok(())
    }
}

fn build(config: &StageConfig<'_>) -> Result<AnyStage> {
    let options: Options = config.parse()?;
    for (key, v) in [
        ("clearance", options.clearance),
        ("approach", options.approach),
        ("wheel_margin", options.wheel_margin),
        ("spray_standoff", options.spray_standoff),
        ("fill_standoff", options.fill_standoff),
    ] {
        crate::tool::non_negative(config, key, v)?;
    }
    if options.approach > options.clearance {
        return Err(config.error("approach", "must be at most `clearance`"));
    }
    let mut seen = BTreeMap::new();
    for (name, &n) in &options.tools {
        if n == 0 {
            return Err(config.error("tools", format!("`{name}`: tool numbers start at 1")));
        }
        if let Some(other) = seen.insert(n, name) {
            return Err(config.error("tools", format!("`{other}` and `{name}` both have number {n}")));
        }
    }
    let (machine, named) = if options.machine.is_empty() {
        let generic: HybridMachine =
            toml::from_str(GENERIC).map_err(|e| config.error("machine", e.to_string()))?;
        (generic, false)
    } else {
        if !options.tools.is_empty() {
            return Err(config.error(
                "tools",
                "the machine numbers its tools: give `machine` or `tools`, not both",
            ));
        }
        (
            HybridMachine::load(&options.machine, config.base_dir, config.reach)
                .map_err(|m| config.error("machine", m))?,
            true,
        )
    };
    Ok(AnyStage::Export(Box::new(Nc {
        options,
        machine,
        named,
    })))
}

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Export,
        name: "nc",
        doc: "NC program for a hybrid machine in its controller's dialect: safe start, tool changes at the safe height, ramped and side entries, feeders set to each sub-region's composition, laser at focal height, cycle-time estimate.",
        options: Options::SPECS,
        example: "use = \"nc\"\npath = \"job.nc\"\nmachine = \"cmpm-hybrid\"",
    },
    build,
});

#[cfg(test)]
mod tests {
    use super::*;
    use lamina_api::{Contour, OperationPath, OperationTool};

    /// A sink writing for the generic machine, the highest surface so far at `top`.
    fn sink(top: f64) -> Sink {
        let machine: HybridMachine = toml::from_str(GENERIC).expect("the generic machine");
        Sink {
            out: Box::new(std::io::sink()),
            path: PathBuf::from("test.nc"),
            options: Options {
                path: PathBuf::from("test.nc"),
                machine: String::new(),
                tools: BTreeMap::new(),
                clearance: 5.0,
                approach: 1.0,
                wheel_margin: 1.0,
                spray_standoff: 80.0,
                fill_standoff: 1.0,
                plunge: 0.3,
            },
            regions: Vec::new(),
            numbers: BTreeMap::new(),
            named: false,
            program: Program::new(machine),
            top,
            notes: Vec::new(),
            title: String::new(),
        }
    }

    fn operation(kind: &str, tool: &str, paths: Vec<OperationPath>) -> Operation {
        let mut op = Operation::new(kind, Some(0));
        op.tool = Some(OperationTool {
            name: tool.into(),
            kind: tool.into(),
            diameter: 0.8,
            feed: 10.0,
            spindle: Some(10_000.0),
            power: None,
        });
        op.paths = paths;
        op
    }

    fn open(z: f64, points: &[(f64, f64)]) -> OperationPath {
        OperationPath {
            z,
            points: points.iter().map(|&(x, y)| Point2::new(x, y)).collect(),
            closed: false,
        }
    }

    fn square(x0: f64, y0: f64, side: f64) -> Polygon {
        let corners = [(0.0, 0.0), (side, 0.0), (side, side), (0.0, side)];
        Polygon::new(
            Contour::new(
                corners
                    .iter()
                    .map(|&(x, y)| Point2::new(x0 + x, y0 + y))
                    .collect(),
            ),
            Vec::new(),
        )
    }

    /// A move the program makes: rapid or not, where it ends (an axis unknown after a
    /// retract in machine coordinates) and its feed (mm/min), read from the words.
    #[derive(Debug)]
    struct Move {
        rapid: bool,
        to: [Option<f64>; 3],
        feed: Option<f64>,
    }

    /// The moves of a program's text, the modal motion and feed words carried from
    /// line to line as a controller carries them.
    fn moves(text: &str) -> Vec<Move> {
        let (mut rapid, mut feed, mut at) = (true, None, [None; 3]);
        let mut out = Vec::new();
        for line in text.lines() {
            let words: Vec<(char, f64)> = line
                .split('(')
                .next()
                .unwrap_or("")
                .split_whitespace()
                .filter_map(|w| Some((w.chars().next()?, w[1..].parse().ok()?)))
                .collect();
            if words.contains(&('G', 53.0)) {
                at[2] = None;
                continue;
            }
            let mut moved = false;
            for &(letter, v) in &words {
                match letter {
                    'G' if v == 0.0 || v == 1.0 => rapid = v == 0.0,
                    'F' => feed = Some(v),
                    'X' | 'Y' | 'Z' => {
                        at[(letter as u8 - b'X') as usize] = Some(v);
                        moved = true;
                    }
                    _ => {}
                }
            }
            if moved {
                out.push(Move {
                    rapid,
                    to: at,
                    feed: (!rapid).then_some(feed).flatten(),
                });
            }
        }
        out
    }

    /// The heights at which the program crosses in XY by rapid moves, in order.
    fn crossings(text: &str) -> Vec<Option<f64>> {
        let mut at = [None; 3];
        let mut out = Vec::new();
        for m in moves(text) {
            if m.rapid && (m.to[0] != at[0] || m.to[1] != at[1]) {
                out.push(at[2]);
            }
            at = m.to;
        }
        out
    }

    /// The filler, working a lower surface than the highest so far (2 mm), goes from
    /// one pass to the next at its own height where the way stays over the layer's
    /// area, and climbs to the approach height (top + 1 mm) to cross where it leaves
    /// it; its first pass is reached from the safe height, where the tool change left
    /// it.
    #[test]
    fn the_filler_climbs_to_the_approach_height_only_where_its_way_leaves_the_area() {
        let mut s = sink(2.0);
        // A square, and an L whose foot runs along y = 0 to 2 and whose leg stands at
        // x = 28 to 30: from the foot's far end the way up the leg stays over it, from
        // the foot's near end it would not.
        let l = [
            (20.0, 0.0),
            (30.0, 0.0),
            (30.0, 10.0),
            (28.0, 10.0),
            (28.0, 2.0),
            (20.0, 2.0),
        ];
        let area = [
            square(0.0, 0.0, 10.0),
            Polygon::new(
                Contour::new(l.iter().map(|&(x, y)| Point2::new(x, y)).collect()),
                Vec::new(),
            ),
        ];
        let op = operation(
            "fill",
            "dispenser",
            vec![
                open(0.5, &[(1.0, 1.0), (9.0, 1.0)]),
                open(0.5, &[(21.0, 1.0), (29.0, 1.0)]),
                open(0.5, &[(29.0, 5.0), (29.0, 7.0), (29.0, 9.0)]),
                open(0.5, &[(9.0, 5.0), (1.0, 5.0)]),
            ],
        );
        s.operation(&op, &area).expect("written");
        // Nozzle 1 mm over the 0.5 mm surface; across the gap at 3 mm (the top, 2 mm,
        // and the approach, 1 mm), both ways; from the foot up the leg at 1.5 mm.
        assert_eq!(
            crossings(&s.program.text),
            [None, Some(3.0), Some(1.5), Some(3.0)],
            "{}",
            s.program.text
        );
        // Each pass worked at the nozzle's height, open passes left open (one move per
        // segment, 1 + 1 + 2 + 1), then up to the clearance over the top.
        let all = moves(&s.program.text);
        let worked: Vec<&Move> = all.iter().filter(|m| !m.rapid).collect();
        assert_eq!(worked.len(), 5, "{}", s.program.text);
        assert!(worked.iter().all(|m| m.to[2] == Some(1.5)));
        assert_eq!(all.last().map(|m| m.to[2]), Some(Some(7.0)));
    }

    /// An end mill ramps into each path from the approach height at a share of its
    /// feed (`plunge`), works at depth at its feed, and rises to the approach height
    /// between paths.
    #[test]
    fn an_end_mill_ramps_in_at_its_plunge_feed_and_works_at_depth_at_its_feed() {
        let mut s = sink(1.0);
        let op = operation(
            "end-mill",
            "end-mill",
            vec![
                open(0.6, &[(0.0, 0.0), (20.0, 0.0)]),
                open(0.6, &[(0.0, 5.0), (20.0, 5.0)]),
            ],
        );
        s.operation(&op, &[square(-1.0, -1.0, 30.0)]).expect("written");
        // The ramp's moves down at 180 mm/min (0.3 of 10 mm/s), the one reaching the
        // depth too; the moves along the depth at 600; nothing below it. At 3 degrees
        // from 2 mm down to 0.6 mm the ramp takes 26.7 mm: back along the 20 mm path.
        let all = moves(&s.program.text);
        let (mut down, mut along) = (0, 0);
        for w in all.windows(2) {
            let (from, m) = (&w[0], &w[1]);
            if m.rapid {
                continue;
            }
            let (z0, z) = (from.to[2].expect("z known"), m.to[2].expect("z known"));
            assert!((0.6 - 1e-9..=2.0 + 1e-9).contains(&z), "{m:?}");
            if z < z0 - 1e-9 {
                assert_eq!(m.feed, Some(180.0), "{m:?}");
                down += 1;
            } else {
                assert_eq!(m.feed, Some(600.0), "{m:?}");
                assert!((z - 0.6).abs() < 1e-9, "{m:?}");
                along += 1;
            }
        }
        assert_eq!((down, along), (4, 4), "{}", s.program.text);
        // Between the paths, up to 2 mm (top 1 + approach 1): the second path is
        // reached across at the approach height.
        assert_eq!(
            crossings(&s.program.text),
            [None, Some(2.0)],
            "{}",
            s.program.text
        );
    }

    /// A cup wheel 10 mm across comes down beside the area, its face its margin
    /// (1 mm) clear of it, at its ramp angle from the approach height, at the plunge
    /// feed; it grinds the pass at depth and runs on until it is clear again.
    #[test]
    fn a_cup_wheel_comes_down_beside_the_area_and_runs_out_past_it() {
        let mut s = sink(1.0);
        let mut op = operation(
            "grind",
            "grinding-wheel",
            vec![open(0.6, &[(2.0, 5.0), (8.0, 5.0)])],
        );
        if let Some(tool) = op.tool.as_mut() {
            tool.diameter = 10.0;
        }
        s.operation(&op, &[square(0.0, 0.0, 10.0)]).expect("written");
        let all = moves(&s.program.text);
        let worked: Vec<&Move> = all.iter().filter(|m| !m.rapid).collect();
        let at = |m: &Move| m.to.map(|v| v.expect("known"));
        // Down from the approach height (top 1 + 1 mm) to 0.6 mm over 1.4 / tan 3°,
        // to x = -6, where the wheel's face (radius 5) is 1 mm from the area's side at
        // x = 0, as is x = 16 past the side at x = 10.
        let run = 1.4 / 3f64.to_radians().tan();
        let first = all.iter().position(|m| !m.rapid).expect("a feed move");
        let from = at(&all[first - 1]);
        assert!(
            (from[0] - (-6.0 - run)).abs() < 1e-3 && from[1] == 5.0 && from[2] == 2.0,
            "{from:?}"
        );
        let xs: Vec<[f64; 3]> = worked.iter().map(|m| at(m)).collect();
        assert_eq!(
            xs,
            [
                [-6.0, 5.0, 0.6],
                [2.0, 5.0, 0.6],
                [8.0, 5.0, 0.6],
                [16.0, 5.0, 0.6]
            ],
            "{}",
            s.program.text
        );
        let feeds: Vec<Option<f64>> = worked.iter().map(|m| m.feed).collect();
        assert_eq!(feeds, [Some(180.0), Some(600.0), Some(600.0), Some(600.0)]);
    }

    /// Between passes a cup wheel goes across at the approach height, as an end mill
    /// does: the clearance is for the way from another operation.
    #[test]
    fn a_cup_wheel_goes_from_pass_to_pass_at_the_approach_height() {
        let mut s = sink(1.0);
        let mut op = operation(
            "grind",
            "grinding-wheel",
            vec![
                open(0.6, &[(2.0, 3.0), (8.0, 3.0)]),
                open(0.6, &[(2.0, 7.0), (8.0, 7.0)]),
            ],
        );
        if let Some(tool) = op.tool.as_mut() {
            tool.diameter = 10.0;
        }
        s.operation(&op, &[square(0.0, 0.0, 10.0)]).expect("written");
        assert_eq!(
            crossings(&s.program.text),
            [None, Some(2.0)],
            "{}",
            s.program.text
        );
    }

    /// The laser burns each pass at its focus height, switched on for the pass and off
    /// after it, and goes from one pass to the next at that height: no ramp, no climb.
    #[test]
    fn the_laser_burns_each_pass_at_its_height_switched_on_only_along_it() {
        let mut s = sink(1.0);
        let mut op = operation(
            "engrave",
            "laser",
            vec![
                OperationPath {
                    z: 0.6,
                    points: square(1.0, 1.0, 2.0).outer.points,
                    closed: true,
                },
                open(0.6, &[(5.0, 1.0), (5.0, 3.0)]),
                // A closed path of two points is a line: burnt once, not back again.
                OperationPath {
                    z: 0.6,
                    points: vec![Point2::new(7.0, 1.0), Point2::new(7.0, 3.0)],
                    closed: true,
                },
            ],
        );
        if let Some(tool) = op.tool.as_mut() {
            tool.power = Some(20.0);
        }
        s.operation(&op, &[square(0.0, 0.0, 10.0)]).expect("written");
        let text = &s.program.text;
        let all = moves(text);
        let worked: Vec<&Move> = all.iter().filter(|m| !m.rapid).collect();
        assert_eq!(worked.len(), 6, "{text}");
        assert!(
            worked
                .iter()
                .all(|m| m.to[2] == Some(0.6) && m.feed == Some(600.0)),
            "{text}"
        );
        assert_eq!(crossings(text), [None, Some(0.6), Some(0.6)], "{text}");
        let switched: Vec<&str> = text
            .lines()
            .filter(|l| l.starts_with("M3") || l.starts_with("M5"))
            .collect();
        assert_eq!(
            switched,
            ["M3 S20", "M5", "M3 S20", "M5", "M3 S20", "M5"],
            "{text}"
        );
    }

    /// Tools the `tools` table does not number take the next number after the highest
    /// in use, and keep it; the comment before each operation names its kind, its pass
    /// and its region.
    #[test]
    fn unnumbered_tools_take_the_next_number_and_each_operation_says_what_it_does() {
        let mut s = sink(1.0);
        s.numbers.insert("end-mill".into(), 4);
        s.regions = vec!["skin".into()];
        let mut grind = operation(
            "grind",
            "grinding-wheel",
            vec![open(0.6, &[(2.0, 5.0), (8.0, 5.0)])],
        );
        grind.pass = "rough".into();
        let mill = operation("end-mill", "end-mill", vec![open(0.6, &[(2.0, 5.0), (8.0, 5.0)])]);
        let mut laser = operation("engrave", "laser", vec![open(0.6, &[(2.0, 5.0), (8.0, 5.0)])]);
        laser.region = Some(3);
        if let Some(tool) = laser.tool.as_mut() {
            tool.power = Some(20.0);
        }
        let area = [square(0.0, 0.0, 10.0)];
        for op in [&grind, &mill, &laser, &grind] {
            s.operation(op, &area).expect("written");
        }
        let tools: Vec<&str> = s
            .program
            .text
            .lines()
            .filter(|l| l.starts_with("(tool "))
            .collect();
        assert_eq!(
            tools,
            [
                "(tool 5: grinding-wheel)",
                "(tool 4: end-mill)",
                "(tool 6: laser)",
                "(tool 5: grinding-wheel)"
            ]
        );
        let about: Vec<&str> = s
            .program
            .text
            .lines()
            .filter(|l| l.starts_with("(grind") || l.starts_with("(end-mill") || l.starts_with("(engrave"))
            .collect();
        assert_eq!(
            about,
            [
                "(grind rough, region skin)",
                "(end-mill, region skin)",
                "(engrave, region #3)",
                "(grind rough, region skin)"
            ]
        );
    }

    /// One in-memory file the program is written into.
    #[derive(Clone, Default)]
    struct Buffer(std::sync::Arc<std::sync::Mutex<Vec<u8>>>);

    impl Write for Buffer {
        fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
            self.0.lock().expect("lock").extend_from_slice(b);
            Ok(b.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    /// The reports a run's summary is given.
    #[derive(Default)]
    struct Reports(Vec<MachineFileReport>);

    impl OutputFiles for Reports {
        fn create(&mut self, name: &std::path::Path) -> Result<Box<dyn Write + Send>> {
            Err(Error::io(name, std::io::ErrorKind::Unsupported.into()))
        }
        fn report(&mut self, report: MachineFileReport) {
            self.0.push(report);
        }
    }

    fn run_info() -> RunInfo {
        RunInfo {
            base_dir: PathBuf::from("."),
            materials: Vec::new(),
            parts: Vec::new(),
            z_min: 0.0,
            z_max: 1.0,
            xy_bounds: lamina_api::BBox2::from_points([Point2::new(0.0, 0.0)]),
            machine: None,
            model_frame: None,
        }
    }

    /// The program opens with the controller's header, then says what it is for: the
    /// run, the machine, its dialect, the cycle time with each operation's share (those
    /// that took time), the outputs and feeders it switches, the tools by number. Then
    /// the controller's safe start, then the moves. The run's summary is told the same
    /// time and shares, and what the machine will do otherwise than planned.
    #[test]
    fn the_program_opens_with_what_it_is_for_and_the_run_is_told_its_time() {
        let machine: HybridMachine =
            toml::from_str(include_str!("../../machines/cmpm-hybrid.toml")).expect("the machine");
        let description = comment(&machine.description);
        let buffer = Buffer::default();
        let mut s = sink(1.0);
        s.program = Program::new(machine);
        s.out = Box::new(buffer.clone());
        s.named = true;
        s.title = "pipe, 3 layers".into();
        s.numbers = BTreeMap::from([
            ("laser".into(), 4),
            ("end-mill".into(), 1),
            ("spray-gun".into(), 2),
        ]);
        s.program.shares.by = vec![
            ("spray".into(), 30.0),
            ("mill".into(), 0.0),
            ("grind".into(), 65.0),
        ];
        s.program.line("G1 X1 F600");
        let note = Warning::new("wheel-speed", "the cup wheel turns at 6000 rpm");
        s.notes.push(note.clone());
        let mut reports = Reports::default();
        Box::new(s).finish(&run_info(), &mut reports).expect("finished");
        let text = String::from_utf8(buffer.0.lock().expect("lock").clone()).expect("text");
        let [report] = &reports.0[..] else {
            panic!("{} reports", reports.0.len())
        };
        assert_eq!(report.file, PathBuf::from("test.nc"));
        assert_eq!(report.notes, [note]);
        // Ending the program adds its own share, the head's way up: none from a
        // height the program does not know.
        assert_eq!(
            report.shares,
            [
                ("spray".to_string(), 30.0),
                ("mill".to_string(), 0.0),
                ("grind".to_string(), 65.0),
                ("end".to_string(), 0.0)
            ]
        );
        assert_eq!(report.time, 95.0);
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(
            lines[..13],
            [
                "%",
                "(pipe, 3 layers)",
                &format!("(machine: cmpm-hybrid - {description})"),
                "(controller: linuxcnc)",
                "(estimated cycle time 95 s = 1 min 35 s: spray 30 s, grind 1 min 5 s)",
                "(outputs: 0 spray gun, 1 filler nozzle, 2 chip vacuum)",
                "(feeders: 4 SiC, 1 ceramic, 3 composite, 2 metal, 0 microstructure, each set to its volume fraction times 10)",
                "(T1 end-mill)",
                "(T2 spray-gun)",
                "(T4 laser)",
                "G17 G21 G40 G49 G80 G90 G94",
                "G54",
                "G64 P0.01",
            ],
            "{text}"
        );
        assert_eq!(lines[13], "G1 X1 F600", "{text}");
    }

    /// Without a machine nothing is switched and no feeder set: the header lists
    /// neither, nor a machine.
    #[test]
    fn a_program_without_a_machine_names_none_and_lists_no_outputs() {
        let buffer = Buffer::default();
        let mut s = sink(1.0);
        s.program.machine.outputs = Default::default();
        s.out = Box::new(buffer.clone());
        s.title = "bare".into();
        let mut reports = Reports::default();
        Box::new(s).finish(&run_info(), &mut reports).expect("finished");
        let text = String::from_utf8(buffer.0.lock().expect("lock").clone()).expect("text");
        let said: Vec<&str> = text.lines().filter(|l| l.starts_with('(')).collect();
        assert_eq!(said.len(), 3, "{text}");
        assert_eq!(said[..2], ["(bare)", "(controller: linuxcnc)"], "{text}");
        assert!(said[2].starts_with("(estimated cycle time "), "{text}");
    }

    /// A way is over the area only if every point of it is: a gap of 1 mm between two
    /// points 6 mm apart, off their middle, is found.
    #[test]
    fn a_straight_way_over_a_gap_is_not_over_the_area() {
        let area = [
            square(0.0, 0.0, 1.0),
            square(2.0, 0.0, 1.0),
            square(3.0, 0.0, 1.0),
            square(4.0, 0.0, 3.0),
        ];
        assert!(!over(Point2::new(0.5, 0.5), Point2::new(6.5, 0.5), &area));
        assert!(over(Point2::new(2.5, 0.5), Point2::new(6.5, 0.5), &area));
        assert!(over(Point2::new(0.5, 0.5), Point2::new(0.5, 0.5), &area));
    }

    #[test]
    fn durations_read_in_hours_minutes_and_seconds() {
        assert_eq!(duration(0.4), "0 s");
        assert_eq!(duration(59.5), "1 min 0 s");
        assert_eq!(duration(65.0), "1 min 5 s");
        assert_eq!(duration(3599.0), "59 min 59 s");
        assert_eq!(duration(3600.0), "1 h 0 min 0 s");
        assert_eq!(duration(2.0 * 86_400.0 + 3725.0), "49 h 2 min 5 s");
    }

    #[test]
    fn a_comment_is_one_line_without_parentheses_or_semicolons_and_at_most_200_characters() {
        assert_eq!(
            comment("spray (rough); region\ninner"),
            "spray rough, region inner"
        );
        let long: String = "é".repeat(250);
        let cut = comment(&long);
        assert_eq!(cut.chars().count(), 200);
        assert!(long.starts_with(&cut));
        assert_eq!(comment(&"a".repeat(200)), "a".repeat(200));
    }
}
