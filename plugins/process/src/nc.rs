//! `nc`: the operations as NC code for a hybrid cell, RS-274/NGC as LinuxCNC reads it.
//!
//! - `G21 G90 G94 G17`: millimetres, absolute, feed per minute, the XY plane;
//! - a tool change is `M5` (anything spinning stops), `T<n> M6`, `G43 H<n>` (its
//!   length offset); tools are numbered by the cell (`cell`, see `cell.rs`: every
//!   operation is checked against its tools and travel first), or without one by the
//!   `tools` table, the rest in the order they first come;
//! - end mills and cup wheels turn with `S<rev/min> M3` while they cut, and the chip
//!   vacuum runs (`M64 P2`, off with `M65 P2`);
//! - the laser is a tool whose `S` word is its power in watts: `M3 S<W>` at the start
//!   of each engraved ring, `M5` at its end;
//! - the spray gun and the filler nozzle are switched by digital outputs (`M64 P0` /
//!   `M65 P0` and `M64 P1` / `M65 P1`) at the start and end of each pass, the gun
//!   standing `spray_standoff` above the surface;
//! - between passes the tool rises to `clearance` above the highest surface so far.
//!
//! Each layer starts with a comment naming it, and each operation with one naming its
//! kind, pass, region and what it was planned with.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::PathBuf;

use lamina_core::stage::{
    AnyStage, ExportContext, Exporter, LayerSink, OutputFiles, StageConfig, StageInfo, StageKind,
};
use lamina_core::{Error, LayerPlan, Operation, OperationPath, Result, RunInfo, Sequence, StageFactory};

use crate::cell::{Cell, Outputs};

lamina_core::stage_options! {
    #[derive(Debug, Clone)]
    struct Options {
        /// the NC file
        path: PathBuf = r#""job.nc""#,
        /// the hybrid cell: a built-in profile (`cmpm-hybrid`) or a TOML file; its tools give the numbers, and every operation is checked against it; empty: no cell
        cell: String = "\"\"",
        /// tool numbers by tool name, without a cell; tools not listed get the next free number
        tools: BTreeMap<String, u32> = "{}",
        /// height above the highest surface so far at which the tool travels (mm)
        clearance: f64 = "5.0",
        /// height of the spray gun above the surface it sprays (mm)
        spray_standoff: f64 = "80.0",
        /// height of the filler nozzle above the surface (mm)
        fill_standoff: f64 = "1.0",
        /// plunge feed as a share of the operation's feed
        plunge: f64 = "0.3",
    }
}

/// Digital outputs of a cell that names none.
const OUTPUTS: Outputs = Outputs {
    spray: 0,
    filler: 1,
    vacuum: 2,
};

struct Nc {
    options: Options,
    cell: Option<Cell>,
}

struct Sink {
    out: Box<dyn Write + Send>,
    path: PathBuf,
    options: Options,
    regions: Vec<String>,
    numbers: BTreeMap<String, u32>,
    cell: Option<Cell>,
    outputs: Outputs,
    /// Tool in the spindle, by name.
    tool: Option<String>,
    /// The spindle's speed while it turns (rev/min).
    spinning: Option<f64>,
    vacuum: bool,
    /// Highest surface so far (mm): travel goes above it.
    top: f64,
    text: String,
}

fn io(path: &std::path::Path) -> impl Fn(std::io::Error) -> Error + '_ {
    move |e| Error::io(path, e)
}

/// A comment's text: one line, no parentheses (they would end it) and no semicolons
/// (they start a comment of their own), at most 200 characters (LinuxCNC reads lines of
/// up to 255).
fn comment(s: &str) -> String {
    let text = lamina_core::output::one_line(s)
        .replace(['(', ')'], "")
        .replace(';', ",");
    match text.char_indices().nth(200) {
        Some((i, _)) => text[..i].to_string(),
        None => text,
    }
}

fn num(v: f64) -> String {
    let s = format!("{v:.4}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" { "0".into() } else { s.to_string() }
}

impl Exporter for Nc {
    fn open(&self, ctx: &mut ExportContext<'_>) -> Result<Box<dyn LayerSink>> {
        let path = self.options.path.clone();
        let mut out = ctx.files.create(&path)?;
        let regions = ctx
            .sequence
            .map(|s: &Sequence| s.regions.iter().map(|r| r.name.clone()).collect())
            .unwrap_or_default();
        let mut head = String::from("%\n");
        head.push_str(&format!(
            "(lamina nc: {}, {} layers)\n",
            comment(ctx.pipeline_name),
            ctx.layer_count
        ));
        let outputs = self.cell.as_ref().map_or(OUTPUTS, |c| c.outputs);
        let numbers: BTreeMap<String, u32> = match &self.cell {
            Some(c) => c.tools.iter().map(|t| (t.name.clone(), t.number)).collect(),
            None => self.options.tools.clone(),
        };
        if let Some(c) = &self.cell {
            head.push_str(&format!(
                "(cell: {} - {})\n",
                comment(&c.name),
                comment(&c.description)
            ));
        }
        head.push_str(&format!(
            "({})\n",
            comment(&format!(
                "outputs: P{} spray gun, P{} filler nozzle, P{} chip vacuum, laser power in W as the S word of M3",
                outputs.spray, outputs.filler, outputs.vacuum
            ))
        ));
        let mut listed: Vec<(&String, &u32)> = numbers.iter().collect();
        listed.sort_by_key(|(_, n)| **n);
        for (name, n) in listed {
            head.push_str(&format!("(T{n} {})\n", comment(name)));
        }
        head.push_str("G21 G90 G94 G17\n");
        out.write_all(head.as_bytes()).map_err(io(&path))?;
        Ok(Box::new(Sink {
            out,
            path,
            options: self.options.clone(),
            regions,
            numbers,
            cell: self.cell.clone(),
            outputs,
            tool: None,
            spinning: None,
            vacuum: false,
            top: 0.0,
            text: String::new(),
        }))
    }
}

impl Sink {
    fn line(&mut self, s: impl AsRef<str>) {
        self.text.push_str(s.as_ref());
        self.text.push('\n');
    }

    fn travel_z(&self) -> f64 {
        self.top + self.options.clearance
    }

    fn stop(&mut self) {
        if self.spinning.take().is_some() {
            self.line("M5");
        }
    }

    fn vacuum(&mut self, on: bool) {
        if on != self.vacuum {
            self.line(format!(
                "{} P{}",
                if on { "M64" } else { "M65" },
                self.outputs.vacuum
            ));
            self.vacuum = on;
        }
    }

    fn select(&mut self, name: &str) {
        if self.tool.as_deref() == Some(name) {
            return;
        }
        self.stop();
        self.vacuum(false);
        let next = self.numbers.values().max().copied().unwrap_or(0) + 1;
        let n = *self.numbers.entry(name.to_string()).or_insert(next);
        let z = self.travel_z();
        self.line(format!("G0 Z{}", num(z)));
        self.line(format!("T{n} M6 ({})", comment(name)));
        self.line(format!("G43 H{n}"));
        self.tool = Some(name.to_string());
    }

    fn operation(&mut self, op: &Operation) {
        let region = op
            .region
            .map(|r| self.regions.get(r).cloned().unwrap_or_else(|| format!("#{r}")))
            .unwrap_or_else(|| "-".into());
        let mut about = format!(
            "{}{}",
            op.kind,
            if op.pass.is_empty() {
                String::new()
            } else {
                format!(" {}", op.pass)
            }
        );
        about.push_str(&format!(", region {region}"));
        if let Some(s) = op.surface {
            about.push_str(&format!(", surface to {}", num(s)));
        }
        for (k, v) in &op.values {
            about.push_str(&format!(", {k} {}", num(*v)));
        }
        self.line(format!("({})", comment(&about)));
        let Some(tool) = &op.tool else {
            // An operation without a tool (removing the filler) is for the operator.
            self.stop();
            self.vacuum(false);
            self.line("M0 (operator: see the comment above)");
            return;
        };
        if op.paths.is_empty() {
            return;
        }
        self.select(&tool.name);
        let feed = tool.feed * 60.0;
        let plunge = feed * self.options.plunge;
        let (standoff, on, off): (f64, String, String) = match tool.kind.as_str() {
            "spray" => (
                self.options.spray_standoff,
                format!("M64 P{}", self.outputs.spray),
                format!("M65 P{}", self.outputs.spray),
            ),
            "dispenser" => (
                self.options.fill_standoff,
                format!("M64 P{}", self.outputs.filler),
                format!("M65 P{}", self.outputs.filler),
            ),
            "laser" => (
                0.0,
                format!("M3 S{}", num(tool.power.unwrap_or(0.0))),
                "M5".to_string(),
            ),
            _ => (0.0, String::new(), String::new()),
        };
        let rotating = tool.spindle.is_some() && on.is_empty();
        if rotating {
            self.vacuum(true);
            // A new speed for the same tool is set as it turns.
            let speed = tool.spindle.unwrap_or(0.0);
            match self.spinning {
                None => self.line(format!("S{} M3", num(speed))),
                Some(s) if s != speed => self.line(format!("S{}", num(speed))),
                Some(_) => {}
            }
            self.spinning = Some(speed);
        } else if tool.kind == "laser" {
            self.vacuum(true);
        }
        for p in &op.paths {
            self.path(p, standoff, feed, plunge, &on, &off);
        }
        self.top = self
            .top
            .max(op.paths.iter().map(|p| p.z).fold(f64::NEG_INFINITY, f64::max));
        if let Some(s) = op.surface {
            self.top = self.top.max(s);
        }
        let z = self.travel_z();
        self.line(format!("G0 Z{}", num(z)));
    }

    fn path(&mut self, p: &OperationPath, standoff: f64, feed: f64, plunge: f64, on: &str, off: &str) {
        let Some(first) = p.points.first() else { return };
        let z = self.travel_z().max(p.z + standoff);
        self.line(format!("G0 Z{}", num(z)));
        self.line(format!("G0 X{} Y{}", num(first.x), num(first.y)));
        self.line(format!("G1 Z{} F{}", num(p.z + standoff), num(plunge)));
        if !on.is_empty() {
            self.line(on);
        }
        let mut first_move = true;
        let closing = p.closed && p.points.len() > 2;
        for q in p.points.iter().skip(1).chain(closing.then_some(first)) {
            if first_move {
                self.line(format!("G1 X{} Y{} F{}", num(q.x), num(q.y), num(feed)));
                first_move = false;
            } else {
                self.line(format!("G1 X{} Y{}", num(q.x), num(q.y)));
            }
        }
        if !off.is_empty() {
            self.line(off);
        }
        self.line(format!("G0 Z{}", num(z)));
    }
}

impl LayerSink for Sink {
    fn layer(&mut self, _info: &RunInfo, plan: &LayerPlan, _files: &mut dyn OutputFiles) -> Result<()> {
        if plan.operations.is_empty() {
            return Ok(());
        }
        let region = plan
            .material_region
            .map(|r| self.regions.get(r).cloned().unwrap_or_else(|| format!("#{r}")))
            .unwrap_or_else(|| "all".into());
        self.line(format!(
            "(layer {} region {} z {} thickness {})",
            plan.index,
            comment(&region),
            num(plan.z),
            num(plan.thickness)
        ));
        for op in &plan.operations {
            crate::cell::readable(op).map_err(|e| e.in_layer(plan.index, plan.z))?;
        }
        if let Some(cell) = &self.cell {
            for op in &plan.operations {
                let standoff = match op.tool.as_ref().map(|t| t.kind.as_str()) {
                    Some("spray") => self.options.spray_standoff,
                    Some("dispenser") => self.options.fill_standoff,
                    _ => 0.0,
                };
                cell.admits(op, standoff)
                    .map_err(|e| e.in_layer(plan.index, plan.z))?;
            }
        }
        for op in &plan.operations {
            self.operation(op);
        }
        let text = std::mem::take(&mut self.text);
        self.out.write_all(text.as_bytes()).map_err(io(&self.path))
    }

    fn finish(mut self: Box<Self>, _info: &RunInfo, _files: &mut dyn OutputFiles) -> Result<()> {
        self.stop();
        self.vacuum(false);
        let z = self.travel_z();
        self.line(format!("G0 Z{}", num(z)));
        self.line("M30");
        self.line("%");
        let text = std::mem::take(&mut self.text);
        self.out.write_all(text.as_bytes()).map_err(io(&self.path))?;
        self.out.flush().map_err(io(&self.path))
    }
}

fn build(config: &StageConfig<'_>) -> Result<AnyStage> {
    let options: Options = config.parse()?;
    for (key, v) in [
        ("clearance", options.clearance),
        ("spray_standoff", options.spray_standoff),
        ("fill_standoff", options.fill_standoff),
    ] {
        crate::tool::non_negative(config, key, v)?;
    }
    if !(options.plunge.is_finite() && options.plunge > 0.0 && options.plunge <= 1.0) {
        return Err(config.error("plunge", "must be above 0 and at most 1"));
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
    let cell = if options.cell.is_empty() {
        None
    } else {
        if !options.tools.is_empty() {
            return Err(config.error(
                "tools",
                "the cell numbers its tools: give `cell` or `tools`, not both",
            ));
        }
        Some(Cell::load(&options.cell, config.base_dir).map_err(|m| config.error("cell", m))?)
    };
    Ok(AnyStage::Export(Box::new(Nc { options, cell })))
}

lamina_core::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Export,
        name: "nc",
        doc: "NC code (RS-274/NGC) for a hybrid cell from the process operations: tool changes, spindle and laser, spray and filler outputs, feeds per operation.",
        options: Options::SPECS,
        example: "use = \"nc\"\npath = \"job.nc\"\ncell = \"cmpm-hybrid\"",
    },
    build,
});
