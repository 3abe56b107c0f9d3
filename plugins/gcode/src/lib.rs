//! lamina-gcode: the `gcode` exporter. It writes the planned toolpaths as G-code for
//! one of three kinds of multi-material printer (`flavor`):
//!
//! - `tool-change`: one tool per material (T0, T1, ...), each with its temperature,
//!   retraction before travel and around tool changes;
//! - `marlin-mixing`: one mixing extruder; before each sub-region the mix is set with
//!   `M163 S<channel> P<fraction>` per channel and stored with `M164 S<virtual tool>`,
//!   or with one `M165 A.. B.. C..` when the firmware has DIRECT_MIXING;
//! - `reprap-mixing`: RepRapFirmware, a tool defined over several drives with `M563`
//!   and its mix set with `M567 P<tool> E<r1>:<r2>:...` per sub-region.
//!
//! Extrusion follows the bead: E = path length x layer height x width over the filament
//! cross-section, absolute or relative. Firmwares drive one tool at a time, so each
//! layer is written tool by tool in the planned order of each tool's paths; the pauses
//! of a concurrent plan coordinate tools that move together and have no meaning here
//! (the per-tool timed paths are in the JSON plan for a controller that can).

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::io::Write;
use std::path::PathBuf;

use lamina_core::stage::{
    AnyStage, ExportContext, Exporter, LayerSink, OptionSpec, StageConfig, StageInfo, StageKind,
};
use lamina_core::{Error, LayerPlan, PathKind, Result, RunInfo, StageFactory, Toolpath};
use serde::Deserialize;

const STAGE: &str = "gcode";

/// The axis letters of `M165`, one per mixing channel, in Marlin's order.
const M165_AXES: [char; 6] = ['A', 'B', 'C', 'D', 'H', 'I'];

/// What kind of machine the G-code drives.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Flavor {
    ToolChange,
    MarlinMixing,
    ReprapMixing,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct Options {
    #[serde(default = "d_path")]
    path: PathBuf,
    #[serde(default = "d_flavor")]
    flavor: Flavor,
    #[serde(default = "d_filament")]
    filament_diameter: f64,
    #[serde(default)]
    relative_e: bool,
    #[serde(default)]
    direct_mixing: bool,
    #[serde(default)]
    virtual_tool: u32,
    #[serde(default = "d_temperature")]
    temperature: f64,
    /// Per material name, for tool-change machines.
    #[serde(default)]
    temperatures: BTreeMap<String, f64>,
    #[serde(default = "d_retract")]
    retract: f64,
    #[serde(default = "d_retract_speed")]
    retract_speed: f64,
    /// Channel order of the mixing head, as material names; default the pipeline's.
    channels: Option<Vec<String>>,
}

fn d_path() -> PathBuf {
    PathBuf::from("plan.gcode")
}
fn d_flavor() -> Flavor {
    Flavor::ToolChange
}
fn d_filament() -> f64 {
    1.75
}
fn d_temperature() -> f64 {
    210.0
}
fn d_retract() -> f64 {
    1.0
}
fn d_retract_speed() -> f64 {
    35.0
}

struct Gcode(Options);

/// Filament (mm of feed) for a bead of `length` x `width` x `height` mm.
pub fn filament_length(length: f64, width: f64, height: f64, filament_diameter: f64) -> f64 {
    let area = std::f64::consts::PI * filament_diameter * filament_diameter / 4.0;
    length * width * height / area
}

struct Sink {
    o: Options,
    out: Box<dyn Write + Send>,
    /// Channel of each pipeline material (mixing flavours).
    channel_of: Vec<Option<usize>>,
    channels: usize,
    /// Absolute E position.
    e: f64,
    /// Feed per channel (mm of filament) for the trailer.
    fed: Vec<f64>,
    tool: Option<usize>,
    mix: Option<Vec<u32>>,
    retracted: bool,
    build_time: f64,
    layers: usize,
}

fn io(path: &std::path::Path, e: std::io::Error) -> Error {
    Error::Io {
        path: path.to_path_buf(),
        source: e,
    }
}

impl Sink {
    fn write(&mut self, text: &str) -> Result<()> {
        self.out
            .write_all(text.as_bytes())
            .map_err(|e| io(&self.o.path, e))
    }

    /// Feed `de` mm of filament: the E word, absolute or relative.
    fn e_word(&mut self, de: f64) -> String {
        self.e += de;
        if self.o.relative_e {
            format!("E{de:.5}")
        } else {
            format!("E{:.5}", self.e)
        }
    }

    fn retract(&mut self, s: &mut String) {
        if self.o.retract > 0.0 && !self.retracted {
            let f = self.o.retract_speed * 60.0;
            let e = self.e_word(-self.o.retract);
            let _ = writeln!(s, "G1 {e} F{f:.0}");
            self.retracted = true;
        }
    }

    fn unretract(&mut self, s: &mut String) {
        if self.retracted {
            let f = self.o.retract_speed * 60.0;
            let e = self.e_word(self.o.retract);
            let _ = writeln!(s, "G1 {e} F{f:.0}");
            self.retracted = false;
        }
    }

    /// The mix of a path over the head's channels, in percent summing to 100.
    fn mix_of(&self, info: &RunInfo, path: &Toolpath) -> Vec<u32> {
        let mut f = vec![0.0; self.channels];
        match (&path.composition, path.part.and_then(|p| info.parts.get(p))) {
            (Some(c), Some(part)) => {
                for (x, m) in c.fractions.iter().zip(&part.materials) {
                    if let Some(Some(ch)) = self.channel_of.get(*m) {
                        f[*ch] += x;
                    }
                }
            }
            (_, Some(part)) => {
                if let Some(Some(ch)) = part.materials.first().and_then(|m| self.channel_of.get(*m)) {
                    f[*ch] = 1.0;
                }
            }
            _ => {}
        }
        percentages(&f)
    }

    fn set_mix(&mut self, s: &mut String, mix: Vec<u32>) {
        if self.mix.as_ref() == Some(&mix) {
            return;
        }
        match self.o.flavor {
            Flavor::MarlinMixing if self.o.direct_mixing => {
                let words: Vec<String> = mix
                    .iter()
                    .zip(M165_AXES)
                    .map(|(p, a)| format!("{a}{:.2}", f64::from(*p) / 100.0))
                    .collect();
                let _ = writeln!(s, "M165 {}", words.join(" "));
            }
            Flavor::MarlinMixing => {
                for (ch, p) in mix.iter().enumerate() {
                    let _ = writeln!(s, "M163 S{ch} P{:.2}", f64::from(*p) / 100.0);
                }
                let _ = writeln!(s, "M164 S{}", self.o.virtual_tool);
            }
            Flavor::ReprapMixing => {
                let r: Vec<String> = mix
                    .iter()
                    .map(|p| format!("{:.2}", f64::from(*p) / 100.0))
                    .collect();
                let _ = writeln!(s, "M567 P0 E{}", r.join(":"));
            }
            Flavor::ToolChange => {}
        }
        self.mix = Some(mix);
    }

    fn tool_change(&mut self, s: &mut String, tool: usize, info: &RunInfo) {
        if self.tool == Some(tool) {
            return;
        }
        self.retract(s);
        let temp = info
            .materials
            .get(tool)
            .and_then(|m| self.o.temperatures.get(&m.name))
            .copied()
            .unwrap_or(self.o.temperature);
        let _ = writeln!(s, "T{tool}");
        let _ = writeln!(s, "M109 T{tool} S{temp:.0}");
        if !self.o.relative_e {
            // Each tool's E axis starts over: keep the absolute E of this file continuous
            // by setting the position rather than trusting the firmware's per-tool state.
            let _ = writeln!(s, "G92 E{:.5}", self.e);
        }
        self.tool = Some(tool);
    }
}

/// Fractions as whole percentages summing to 100 (largest remainders), so that
/// firmwares that normalise or reject sums other than 1 agree on the mix.
pub fn percentages(f: &[f64]) -> Vec<u32> {
    let sum: f64 = f.iter().sum();
    if f.is_empty() || sum <= 0.0 {
        let mut p = vec![0; f.len()];
        if let Some(x) = p.first_mut() {
            *x = 100;
        }
        return p;
    }
    let raw: Vec<f64> = f.iter().map(|x| x / sum * 100.0).collect();
    let mut p: Vec<u32> = raw.iter().map(|x| x.floor() as u32).collect();
    let mut left = 100u32.saturating_sub(p.iter().sum());
    let mut order: Vec<usize> = (0..f.len()).collect();
    order.sort_by(|&a, &b| (raw[b] - raw[b].floor()).total_cmp(&(raw[a] - raw[a].floor())));
    for i in order.into_iter().cycle().take(f.len() * 2) {
        if left == 0 {
            break;
        }
        p[i] += 1;
        left -= 1;
    }
    p
}

impl LayerSink for Sink {
    fn layer(&mut self, info: &RunInfo, plan: &LayerPlan) -> Result<()> {
        let mut s = String::new();
        let _ = writeln!(
            s,
            ";LAYER:{} Z{:.4} height {:.4}",
            plan.index, plan.z, plan.thickness
        );
        self.retract(&mut s);
        let _ = writeln!(s, "G0 Z{:.4} F600", plan.z);
        // Tool by tool, each tool's paths in planned time order.
        let mut order: Vec<&Toolpath> = plan
            .toolpaths
            .iter()
            .filter(|p| p.kind != PathKind::Pause)
            .collect();
        order.sort_by(|a, b| {
            let ta = a.points.first().map(|p| p.t).unwrap_or(0.0);
            let tb = b.points.first().map(|p| p.t).unwrap_or(0.0);
            a.tool.cmp(&b.tool).then(ta.total_cmp(&tb))
        });
        let mut at: Option<lamina_core::Point2> = None;
        for path in order {
            let (Some(first), Some(last)) = (path.points.first(), path.points.last()) else {
                continue;
            };
            let duration = last.t - first.t;
            let length = path.length();
            let feed = if duration > 0.0 && length > 0.0 {
                length / duration * 60.0
            } else {
                1800.0
            };
            match path.kind {
                PathKind::Extrude => {
                    if self.o.flavor == Flavor::ToolChange {
                        self.tool_change(&mut s, path.tool, info);
                    } else {
                        let mix = self.mix_of(info, path);
                        self.set_mix(&mut s, mix);
                    }
                    if at.is_none_or(|p| (p - first.p).norm() > 1e-9) {
                        self.retract(&mut s);
                        let _ = writeln!(s, "G0 X{:.4} Y{:.4}", first.p.x, first.p.y);
                    }
                    self.unretract(&mut s);
                    let mut fed_f = true;
                    let mix = if self.o.flavor == Flavor::ToolChange {
                        None
                    } else {
                        Some(self.mix_of(info, path))
                    };
                    for (i, w) in path.points.windows(2).enumerate() {
                        let d = (w[1].p - w[0].p).norm();
                        if d <= 0.0 {
                            continue;
                        }
                        let de = filament_length(
                            d,
                            path.segment_width(i),
                            plan.thickness,
                            self.o.filament_diameter,
                        );
                        let e = self.e_word(de);
                        match &mix {
                            None => {
                                if let Some(x) = self.fed.get_mut(path.tool) {
                                    *x += de;
                                }
                            }
                            Some(m) => {
                                for (x, p) in self.fed.iter_mut().zip(m) {
                                    *x += de * f64::from(*p) / 100.0;
                                }
                            }
                        }
                        if fed_f {
                            let _ = writeln!(s, "G1 X{:.4} Y{:.4} {e} F{feed:.0}", w[1].p.x, w[1].p.y);
                            fed_f = false;
                        } else {
                            let _ = writeln!(s, "G1 X{:.4} Y{:.4} {e}", w[1].p.x, w[1].p.y);
                        }
                    }
                    at = Some(last.p);
                }
                PathKind::Travel => {
                    if length > 0.0 {
                        if self.o.flavor == Flavor::ToolChange {
                            self.tool_change(&mut s, path.tool, info);
                        }
                        self.retract(&mut s);
                        for (i, p) in path.points.iter().skip(1).enumerate() {
                            if i == 0 {
                                let _ = writeln!(s, "G0 X{:.4} Y{:.4} F{feed:.0}", p.p.x, p.p.y);
                            } else {
                                let _ = writeln!(s, "G0 X{:.4} Y{:.4}", p.p.x, p.p.y);
                            }
                        }
                        at = Some(last.p);
                    }
                }
                PathKind::Pause => {}
            }
        }
        self.build_time += plan.build_time.unwrap_or(0.0);
        self.layers += 1;
        self.write(&s)
    }

    fn finish(mut self: Box<Self>, info: &RunInfo) -> Result<()> {
        let mut s = String::new();
        self.retract(&mut s);
        let _ = writeln!(
            s,
            "; end: {} layers, planned build time {:.1} s",
            self.layers, self.build_time
        );
        let names = self.channel_names(info);
        for (name, fed) in names.iter().zip(&self.fed) {
            let _ = writeln!(s, "; filament {name}: {fed:.3} mm");
        }
        let _ = writeln!(s, "M104 S0\nM84");
        self.write(&s)?;
        self.out.flush().map_err(|e| io(&self.o.path, e))
    }
}

impl Sink {
    fn channel_names(&self, info: &RunInfo) -> Vec<String> {
        if self.o.flavor == Flavor::ToolChange {
            return info.materials.iter().map(|m| m.name.clone()).collect();
        }
        let mut names = vec![String::new(); self.channels];
        for (m, ch) in self.channel_of.iter().enumerate() {
            if let (Some(ch), Some(mat)) = (ch, info.materials.get(m)) {
                names[*ch] = mat.name.clone();
            }
        }
        names
    }
}

impl Exporter for Gcode {
    fn open(&self, ctx: &mut ExportContext<'_>) -> Result<Box<dyn LayerSink>> {
        let o = self.0.clone();
        let info = ctx.info;
        let (channel_of, channels) = match &o.channels {
            Some(names) => {
                let mut of = vec![None; info.materials.len()];
                for (ch, n) in names.iter().enumerate() {
                    let m = info.materials.iter().position(|m| &m.name == n).ok_or_else(|| {
                        Error::stage(STAGE, format!("channels: no material `{n}` in the pipeline"))
                    })?;
                    of[m] = Some(ch);
                }
                (of, names.len())
            }
            None => (
                (0..info.materials.len()).map(Some).collect(),
                info.materials.len(),
            ),
        };
        if o.flavor == Flavor::MarlinMixing && o.direct_mixing && channels > M165_AXES.len() {
            return Err(Error::stage(
                STAGE,
                format!(
                    "M165 sets at most {} channels, the head has {channels}",
                    M165_AXES.len()
                ),
            ));
        }
        let out = ctx.files.create(&o.path)?;
        let mut sink = Sink {
            fed: vec![
                0.0;
                if o.flavor == Flavor::ToolChange {
                    info.materials.len()
                } else {
                    channels
                }
            ],
            o,
            out,
            channel_of,
            channels,
            e: 0.0,
            tool: None,
            mix: None,
            retracted: false,
            build_time: 0.0,
            layers: 0,
        };
        let mut s = String::new();
        let flavor = match sink.o.flavor {
            Flavor::ToolChange => "tool-change",
            Flavor::MarlinMixing => "marlin-mixing",
            Flavor::ReprapMixing => "reprap-mixing",
        };
        let _ = writeln!(
            s,
            "; generated by Lamina {} from pipeline `{}`",
            lamina_core::VERSION,
            ctx.pipeline_name
        );
        let _ = writeln!(s, "; flavor: {flavor}, {} layers", ctx.layer_count);
        let _ = writeln!(
            s,
            "; filament diameter {} mm, {} E, retraction {} mm",
            sink.o.filament_diameter,
            if sink.o.relative_e { "relative" } else { "absolute" },
            sink.o.retract
        );
        for (i, name) in sink.channel_names(info).iter().enumerate() {
            let what = if sink.o.flavor == Flavor::ToolChange {
                "tool T"
            } else {
                "channel "
            };
            let _ = writeln!(s, "; {what}{i}: {name}");
        }
        for p in &info.parts {
            let mats: Vec<&str> = p
                .materials
                .iter()
                .filter_map(|&m| info.materials.get(m).map(|m| m.name.as_str()))
                .collect();
            let _ = writeln!(
                s,
                "; part {}: {} (z {:.3}..{:.3} mm)",
                p.name,
                mats.join(", "),
                p.z_min,
                p.z_max
            );
        }
        let _ = writeln!(s, "G21\nG90\n{}", if sink.o.relative_e { "M83" } else { "M82" });
        match sink.o.flavor {
            Flavor::ToolChange => {}
            Flavor::MarlinMixing => {
                let _ = writeln!(s, "T{}", sink.o.virtual_tool);
                let _ = writeln!(s, "M109 S{:.0}", sink.o.temperature);
            }
            Flavor::ReprapMixing => {
                let drives: Vec<String> = (0..sink.channels).map(|d| d.to_string()).collect();
                let _ = writeln!(s, "M563 P0 D{} H1 S\"mixer\"", drives.join(":"));
                let _ = writeln!(s, "G10 P0 S{:.0} R{:.0}", sink.o.temperature, sink.o.temperature);
                let _ = writeln!(s, "T0");
                let _ = writeln!(s, "M116");
            }
        }
        let _ = writeln!(s, "G92 E0");
        sink.write(&s)?;
        Ok(Box::new(sink))
    }
}

fn build(config: &StageConfig<'_>) -> Result<AnyStage> {
    let o: Options = config.parse()?;
    for (k, v) in [
        ("filament_diameter", o.filament_diameter),
        ("retract_speed", o.retract_speed),
        ("temperature", o.temperature),
    ] {
        if !(v.is_finite() && v > 0.0) {
            return Err(config.error(k, "must be a positive number"));
        }
    }
    if !(o.retract.is_finite() && o.retract >= 0.0) {
        return Err(config.error("retract", "must be zero or more mm"));
    }
    if o.direct_mixing && o.flavor != Flavor::MarlinMixing {
        return Err(config.error("direct_mixing", "only the `marlin-mixing` flavor has M165"));
    }
    if let Some((name, _)) = o.temperatures.iter().find(|(_, t)| !(t.is_finite() && **t > 0.0)) {
        return Err(config.error("temperatures", format!("{name}: must be a positive temperature")));
    }
    if o.channels.as_ref().is_some_and(Vec::is_empty) {
        return Err(config.error("channels", "a mixing head has at least one channel"));
    }
    Ok(AnyStage::Export(Box::new(Gcode(o))))
}

lamina_core::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Export,
        name: "gcode",
        doc: "G-code of the planned toolpaths for tool-change, Marlin mixing or RepRapFirmware mixing machines.",
        options: &[
            OptionSpec::new("path", "string", "\"plan.gcode\"", "output file"),
            OptionSpec::new(
                "flavor",
                "string",
                "\"tool-change\"",
                "`tool-change` (T0, T1, ...), `marlin-mixing` (M163/M164 or M165) or `reprap-mixing` (M563/M567)"
            ),
            OptionSpec::new(
                "filament_diameter",
                "float",
                "1.75",
                "filament diameter (mm): E = length x height x width / cross-section"
            ),
            OptionSpec::new(
                "relative_e",
                "bool",
                "false",
                "relative extrusion (M83) instead of absolute (M82)"
            ),
            OptionSpec::new(
                "direct_mixing",
                "bool",
                "false",
                "marlin-mixing: one M165 per mix instead of M163 per channel and M164"
            ),
            OptionSpec::new(
                "virtual_tool",
                "integer",
                "0",
                "marlin-mixing: the virtual tool M164 stores the mix in"
            ),
            OptionSpec::new("temperature", "float", "210.0", "nozzle temperature (°C)"),
            OptionSpec::new(
                "temperatures",
                "table",
                "{}",
                "tool-change: temperature per material name"
            ),
            OptionSpec::new(
                "retract",
                "float",
                "1.0",
                "retraction before travel and tool changes (mm of filament; 0: none)"
            ),
            OptionSpec::new("retract_speed", "float", "35.0", "retraction speed (mm/s)"),
            OptionSpec::new(
                "channels",
                "array of string",
                "the pipeline's materials",
                "mixing flavours: material of each channel, in channel order"
            ),
        ],
        example: "use = \"gcode\"\npath = \"plan.gcode\"\nflavor = \"marlin-mixing\"",
    },
    build,
});

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentages_sum_to_a_hundred() {
        assert_eq!(
            percentages(&[1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0])
                .iter()
                .sum::<u32>(),
            100
        );
        assert_eq!(percentages(&[0.25, 0.75]), vec![25, 75]);
        assert_eq!(percentages(&[0.0, 0.0]), vec![100, 0]);
        assert_eq!(percentages(&[0.125, 0.875]).iter().sum::<u32>(), 100);
    }

    #[test]
    fn filament_follows_the_bead_volume() {
        let e = filament_length(100.0, 0.4, 0.2, 1.75);
        let area = std::f64::consts::PI * 1.75f64.powi(2) / 4.0;
        assert!((e * area - 8.0).abs() < 1e-9);
    }
}
