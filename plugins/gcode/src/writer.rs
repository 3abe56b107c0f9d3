//! The G-code file: start (modes, motion settings, the start template, homing and
//! heating), prime lines, then each layer (skirt, the parts' paths tool by tool or mix
//! by mix, the wipe tower's purges after each change), and the end (template, heaters
//! off, the time estimate).
//!
//! Every line goes through the firmware model ([`Firmware`]) as it is written, so the
//! writer knows at each point which tool is selected and which heaters were waited
//! for: a tool is selected and at temperature before it moves its extruder, whatever
//! the templates did, and the time estimate is that of the file itself.

use std::fmt::Write as _;
use std::io::Write;
use std::path::PathBuf;

use lamina_api::machine::{Firmware as Dialect, FirstLayerSpeed, Flavor, Machine};
use lamina_api::{
    Composition, Error, LayerPlan, MachineFileReport, PathKind, Point2, Result, RunInfo, Toolpath,
};

use crate::firmware::{EXTRUDE_MIN_TEMPERATURE, Firmware, Words};
use crate::layout::Layout;
use crate::setup::Setup;
use crate::text::{clean, num, push_fixed, push_num};
use crate::tower::{Feature, Stroke, Tower};
use crate::transition::PurgeInto;

pub use crate::commands::M165_AXES;

mod multi;
mod spool;

use spool::Spool;

/// Travel shorter than this (mm) keeps the filament where it is (PrusaSlicer's
/// `retract_before_travel` default): short hops stay over the part.
const RETRACT_MIN_TRAVEL: f64 = 2.0;
/// Speeds of what the exporter adds (mm/s), before the first layer's slow-down.
const SKIRT_SPEED: f64 = 30.0;
const PRIME_SPEED: f64 = 25.0;
const TOWER_SPEED: f64 = 40.0;
/// A planned path without timing is extruded at this speed (mm/s).
const DEFAULT_PRINT_SPEED: f64 = 30.0;
/// Z speed when the machine sets no Z limit (mm/s).
const DEFAULT_Z_SPEED: f64 = 10.0;
/// The last digit of the E words (mm of filament).
const E_RESOLUTION: f64 = 1e-5;
/// A segment shorter than this (mm) that feeds nothing is passed over.
const SLIVER: f64 = 0.01;
/// Seconds a preheated tool is at temperature before its change, to spare.
const PREHEAT_MARGIN: f64 = 2.0;
/// Clearance above the print when parking (mm).
const PARK_CLEARANCE: f64 = 10.0;

/// Along a bead (`mix_along`) the mix changes only once some channel would move by
/// this many percent.
const MIX_DEAD_BAND: u32 = 2;

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

/// One planned path to extrude, with the head and mix it needs.
struct Job<'a> {
    head: usize,
    mix: Option<Vec<u32>>,
    path: &'a Toolpath,
    /// The path goes on from where the previous one ended, in the same part: one
    /// extrusion whose mix changes in place, neither purged nor reordered.
    continues: bool,
}

/// The head and the mix in use, and what a mixing head's nozzle holds (fractions per
/// channel, [`crate::transition`]).
#[derive(Debug, Clone, Default)]
struct State {
    head: Option<usize>,
    mix: Option<Vec<u32>>,
    nozzle: Option<Vec<f64>>,
}

/// A change of head or mix before a job: what its transition puts on the wipe tower
/// and into the part's next beads (mm³).
#[derive(Debug, Clone, Copy)]
struct Change {
    tower: f64,
    part: f64,
}

/// A layer's jobs from a given state, their mixes along each bead, the change before
/// each job (if any), and the state the layer ends in.
struct Analysis<'a> {
    jobs: Vec<Job<'a>>,
    along: Vec<Vec<Vec<u32>>>,
    changes: Vec<Option<Change>>,
    /// A job whose last mm³ already take the next job's mix (the transition begun in
    /// the beads before the change): that volume and mix.
    early: Vec<Option<(f64, Vec<u32>)>>,
    end: State,
}

/// The G-code being written.
pub struct Writer {
    s: Setup,
    layout: Layout,
    out: Box<dyn Write + Send>,
    path: PathBuf,
    fw: Firmware,
    buf: String,
    /// Position in `s.heads` of the head in use.
    head: Option<usize>,
    /// Filament pulled back, per head (mm).
    retracted: Vec<f64>,
    /// The solid areas of the layer being written, for its travels.
    solid: Option<crate::solid::Solid>,
    /// RepRapFirmware heads whose standby temperature was raised to heat them ahead of
    /// their change.
    raised: Vec<bool>,
    /// Whether each head has extruded: a head fresh from loading has nothing to pull
    /// back.
    extruded: Vec<bool>,
    /// Height of the layer being written.
    z: f64,
    feature: Option<Feature>,
    mix: Option<Vec<u32>>,
    tower: Option<Tower>,
    /// With a tower: the state after the last layer received (written or spooled).
    received: Option<State>,
    /// What a mixing head's nozzle holds, as the transitions' model follows it.
    nozzle: Option<Vec<f64>>,
    /// Layers received but not yet written (see [`Writer::write_layer`]).
    spool: Spool,
    /// Volume of transitions the part's beads took (mm³).
    transition: f64,
    /// Volume deposited per kind of stroke (mm³), in [`Feature`] order.
    deposited: [f64; 5],
    layers: usize,
    started: bool,
    /// Filament fed per head (tool changers) or channel (mixing heads), mm.
    fed: Vec<f64>,
    /// Per-tool temperatures for the templates' `_<n>` variables.
    tool_temperatures: Vec<(f64, f64, f64)>,
    z_max: f64,
    /// Planned layer build times (s), summed.
    planned: f64,
    /// The lowest head the parts use: the templates' `{first_tool}`.
    first_head: usize,
    /// The streams of a machine with two motion systems working at once.
    multi: Option<multi::Multi>,
    /// The line being written, kept for the next one.
    text: String,
}

fn io(path: &std::path::Path, e: std::io::Error) -> Error {
    Error::io(path, e)
}

impl Writer {
    /// Opens the file: header, modes, motion settings, the start template, homing and
    /// heating.
    pub fn open(
        s: Setup,
        info: &RunInfo,
        layout: Layout,
        out: Box<dyn Write + Send>,
        path: PathBuf,
        header: &Header<'_>,
    ) -> Result<Writer> {
        let fw = Firmware::new(s.dialect, s.flavor, s.heads.len(), s.limits, s.thermal);
        let multi = s
            .systems
            .clone()
            .map(|systems| multi::Multi::new(systems, s.kinematics));
        let used_heads = s.used_heads(info);
        let mut multi = multi;
        if let Some(m) = multi.as_mut() {
            m.used = used_heads.clone();
        }
        let tower = layout.tower.map(|r| Tower::new(r, s.line_width()));
        let fed = vec![
            0.0;
            if s.flavor.is_mixing() {
                s.channel_names.len()
            } else {
                s.heads.len()
            }
        ];
        let tool_temperatures = match info.machine.as_ref() {
            Some(m) => m
                .tools
                .iter()
                .map(|t| {
                    (
                        t.nozzle_temperature,
                        t.first_layer_temperature,
                        t.standby_temperature.unwrap_or(t.nozzle_temperature),
                    )
                })
                .collect(),
            None => s
                .heads
                .iter()
                .map(|h| {
                    (
                        h.nozzle_temperature,
                        h.first_layer_temperature,
                        h.nozzle_temperature,
                    )
                })
                .collect(),
        };
        let mut w = Writer {
            retracted: vec![0.0; s.heads.len()],
            raised: vec![false; s.heads.len()],
            solid: None,
            extruded: vec![false; s.heads.len()],
            received: None,
            nozzle: None,
            spool: Spool::default(),
            transition: 0.0,
            deposited: [0.0; 5],
            s,
            layout,
            out,
            path,
            fw,
            buf: String::new(),
            head: None,
            z: 0.0,
            feature: None,
            mix: None,
            tower,
            layers: 0,
            started: false,
            fed,
            tool_temperatures,
            z_max: info.z_max,
            planned: 0.0,
            first_head: used_heads.first().copied().unwrap_or(0),
            multi,
            text: String::new(),
        };
        w.header(info, header, &used_heads);
        w.start(&used_heads)?;
        w.flush()?;
        Ok(w)
    }

    // ------------------------------------------------------------------ lines

    /// Writes one line and lets the firmware model read it.
    fn line(&mut self, text: impl AsRef<str>) {
        let text = text.as_ref();
        if self.multi.is_some() {
            self.stream_line(text);
            return;
        }
        self.fw.feed_line(text);
        self.buf.push_str(text);
        self.buf.push('\n');
    }

    /// Writes a linear move whose words the caller holds as written ([`Words`]), so
    /// that the firmware model takes them without reading the text back.
    fn move_line(&mut self, text: &str, words: Words) {
        if self.multi.is_some() {
            self.stream_line(text);
            return;
        }
        self.fw.feed_move(words, text);
        self.buf.push_str(text);
        self.buf.push('\n');
    }

    /// Writes a comment (never read as a command: names are cleaned).
    fn comment(&mut self, text: impl AsRef<str>) {
        let text = text.as_ref().replace(['\n', '\r'], " ");
        self.buf.push_str("; ");
        self.buf.push_str(&text);
        self.buf.push('\n');
    }

    /// Writes a rendered template line by line.
    /// Writes a machine template's lines, checked first as the firmware will run them
    /// from the state the file is in: a template is the machine profile's, which a
    /// pipeline names, so its lines are not trusted. Every position must be a number
    /// on the bed (within its shape, Z from 0 to its height), and absolute positioning
    /// must be in force when it ends; otherwise the run fails, naming the template and
    /// its line.
    fn template(&mut self, name: &str, text: &str) -> Result<()> {
        if let Some(bed) = self.s.bed {
            let machine = self.s.machine.as_deref().unwrap_or("?").to_string();
            let fail = |m: String| {
                Err(Error::stage(
                    crate::STAGE,
                    format!("machine `{machine}`: the {name} template {m}"),
                ))
            };
            let mut probe = self.fw.clone();
            for (i, l) in text.lines().enumerate() {
                probe.feed_line(l);
                let [x, y, z, _] = probe.position();
                let on_bed = [x, y, z].iter().all(|v| v.is_finite())
                    && bed.contains(Point2::new(x, y), -1e-6)
                    && (-1e-6..=bed.max_height + 1e-6).contains(&z);
                if !on_bed {
                    return fail(format!(
                        "moves off the bed at its line {} (`{}`): to X {x} Y {y} Z {z}, where the bed spans {} and Z 0 to {}",
                        i + 1,
                        l.trim(),
                        bed_span(&bed),
                        bed.max_height
                    ));
                }
            }
            if !probe.absolute() {
                return fail(
                    "leaves relative positioning (G91) on: every move after it would be taken as a step from the last; end it with G90".into(),
                );
            }
        }
        for l in text.lines() {
            let l = l.trim_end();
            if !l.trim().is_empty() {
                self.line(l);
            }
        }
        Ok(())
    }

    fn flush(&mut self) -> Result<()> {
        self.out
            .write_all(self.buf.as_bytes())
            .map_err(|e| io(&self.path, e))?;
        self.buf.clear();
        Ok(())
    }

    fn set_feature(&mut self, f: Feature) {
        if self.feature != Some(f) {
            self.buf.push_str(";TYPE:");
            self.buf.push_str(f.name());
            self.buf.push('\n');
            self.feature = Some(f);
        }
    }

    // ------------------------------------------------------------------ start

    fn header(&mut self, info: &RunInfo, h: &Header<'_>, used_heads: &[usize]) {
        let s = &self.s;
        let mut t = String::new();
        let _ = writeln!(
            t,
            "; generated by Lamina {} from pipeline `{}`",
            lamina_api::VERSION,
            clean(h.pipeline)
        );
        // The flavour and the firmware in one word, which is what a reader of the file
        // needs to know how to take its commands.
        let _ = writeln!(
            t,
            "; flavor: {}/{}, {} layers",
            s.flavor.name(),
            s.dialect.name(),
            h.layers
        );
        match (&s.machine, s.bed) {
            (Some(name), Some(bed)) => {
                let _ = writeln!(
                    t,
                    "; machine: {}, bed {}, origin {}, build height {} mm",
                    clean(name),
                    bed.describe(),
                    s.origin_name(),
                    num(bed.max_height, 1)
                );
            }
            _ => {
                let _ = writeln!(t, "; machine: none (the exporter's own options)");
            }
        }
        let _ = writeln!(t, "; coordinates: {}", self.layout.note);
        if let Some(m) = &self.multi {
            t.push_str(&m.describe());
        }
        let _ = writeln!(
            t,
            "; filament diameter {} mm, {} E, retraction {} mm at {} mm/s{}",
            num(s.filament_diameter, 3),
            if s.relative_e { "relative" } else { "absolute" },
            num(s.retraction.length, 2),
            num(s.retraction.speed, 1),
            if s.retraction.z_hop > 0.0 {
                format!(", z-hop {} mm", num(s.retraction.z_hop, 2))
            } else {
                String::new()
            }
        );
        if s.flavor.is_mixing() {
            for (i, name) in s.channel_names.iter().enumerate() {
                let _ = writeln!(t, "; channel {i}: {}", clean(name));
            }
        }
        for (i, head) in s.heads.iter().enumerate() {
            let used = if used_heads.contains(&i) { "" } else { ", unused" };
            let standby = head
                .standby_temperature
                .map(|x| format!(", standby {}", num(x, 0)))
                .unwrap_or_default();
            let _ = writeln!(
                t,
                "; tool T{}: {}, {} °C (first layer {}{standby}){used}",
                head.index,
                clean(&head.label),
                num(head.nozzle_temperature, 0),
                num(head.first_layer_temperature, 0)
            );
        }
        for p in &info.parts {
            let mats: Vec<String> = p
                .materials
                .iter()
                .filter_map(|&m| info.materials.get(m).map(|m| clean(&m.name)))
                .collect();
            let _ = writeln!(
                t,
                "; part {}: {} (z {:.3}..{:.3} mm)",
                clean(&p.name),
                mats.join(", "),
                p.z_min,
                p.z_max
            );
        }
        if let Some(r) = self.layout.tower {
            let purge = if s.flavor.is_mixing() {
                format!(
                    "a change of mix of {}% or more flushes {} mm³ (smaller changes, and a mix that changes along a bead, are set in place and blend over about that volume)",
                    num(s.blend_below * 100.0, 1),
                    num(s.transition_volume, 1),
                )
            } else {
                format!(
                    "a tool change primes {} mm³",
                    num(s.wipe_tower.map_or(0.0, |w| w.purge_volume), 1)
                )
            };
            let into = match s.purge_into {
                PurgeInto::Part => {
                    "into the next beads as far as their design composition allows (within half the family's design step), the rest on the tower"
                }
                PurgeInto::Tower => "on the tower",
            };
            let _ = writeln!(
                t,
                "; wipe tower: X {:.1}..{:.1}, Y {:.1}..{:.1}, from the bed to the last layer that purges on it (none if no layer does); {purge}, {into}",
                r.min.x, r.max.x, r.min.y, r.max.y
            );
        }
        self.buf.push_str(&t);
    }

    fn start(&mut self, used_heads: &[usize]) -> Result<()> {
        self.line("G21 ; millimetres");
        self.line("G90 ; absolute coordinates");
        self.line(if self.s.relative_e {
            "M83 ; relative extrusion"
        } else {
            "M82 ; absolute extrusion"
        });
        for l in crate::commands::motion(&self.s) {
            self.line(l);
        }
        if self.s.flavor == Flavor::ReprapMixing {
            let drives: Vec<String> = (0..self.s.channel_names.len()).map(|d| d.to_string()).collect();
            self.line(format!(
                "M563 P0 D{} H1 S\"mixer\" ; the mixing tool over every drive",
                drives.join(":")
            ));
        }
        if self.s.machine.is_some() {
            let start = self.render(&self.s.templates.start.clone(), None, 0.0)?;
            // Home first unless the template does: nothing may move before.
            let mut probe = self.fw.clone();
            probe.feed_text(&start);
            if !probe.homed() {
                self.line("G28 ; home all axes (the start template does not)");
            }
            // The other tools warm to their standby while the machine homes and the bed
            // heats (warm, not oozing), so that their first heating is short.
            if self.s.dialect == Dialect::Marlin && !self.s.flavor.is_mixing() {
                for &h in used_heads {
                    let head = self.s.heads[h].clone();
                    if h != self.first_head
                        && let Some(standby) = head.standby_temperature
                        && self.fw.target(head.index) < standby - 0.5
                    {
                        self.line(format!(
                            "M104 T{} S{} ; warm at standby while the machine homes",
                            head.index,
                            num(standby, 0)
                        ));
                    }
                }
            }
            // Heads on motion systems of their own heat all at once from the start,
            // while the machine homes and the bed heats (`M568 A2`: a tool's heater
            // active without selecting it, which only its own motion system may do).
            if self.multi.is_some() {
                for &h in used_heads {
                    let head = self.s.heads[h].clone();
                    self.line(crate::commands::rrf_tool_temperatures(
                        head.index,
                        head.first_layer_temperature,
                        head.standby_temperature,
                    ));
                    self.line(format!("M568 P{} A2 ; T{} heats now", head.index, head.index));
                }
            }
            self.template("start", &start)?;
            let bed = self.s.first_layer_bed_temperature;
            if bed > 0.0 && !self.fw.bed_is_hot(bed) {
                if self.fw.bed_target() < bed - 0.5 {
                    self.line(format!("M140 S{}", num(bed, 0)));
                }
                self.line(format!("M190 S{} ; wait for the bed", num(bed, 0)));
            }
            // Every head the parts use warms up together; each is waited for before it
            // moves its extruder. Without prime lines a head that does not print first
            // waits at its standby temperature until it is needed.
            let single = self.multi.is_none();
            for &h in used_heads.iter().filter(|_| single) {
                let head = self.s.heads[h].clone();
                let warm = if self.s.prime_line.is_some() || h == self.first_head {
                    head.first_layer_temperature
                } else {
                    head.standby_temperature.unwrap_or(head.first_layer_temperature)
                };
                match self.s.dialect {
                    Dialect::Marlin => {
                        if self.fw.target(head.index) < warm - 0.5 {
                            self.line(crate::commands::set_temperature(&self.s, head.index, warm));
                        }
                    }
                    Dialect::RepRapFirmware => {
                        self.line(crate::commands::rrf_tool_temperatures(
                            head.index,
                            head.first_layer_temperature,
                            head.standby_temperature,
                        ));
                    }
                }
            }
        } else if self.s.dialect == Dialect::RepRapFirmware {
            let head = self.s.heads[0].clone();
            self.line(crate::commands::rrf_tool_temperatures(
                head.index,
                head.first_layer_temperature,
                head.standby_temperature,
            ));
        }
        if self.s.flavor == Flavor::MarlinMixing {
            self.line(format!(
                "T{} ; the virtual tool that holds the mix",
                self.s.virtual_tool
            ));
        }
        if !self.s.relative_e {
            self.line("G92 E0");
        }
        Ok(())
    }

    /// Values of template variables.
    fn variable(&self, name: &str, change: Option<(Option<usize>, usize)>, layer_z: f64) -> Option<String> {
        let s = &self.s;
        let head = &s.heads[self.first_head];
        let printed = self.layout.printed();
        let park = (self.z_max + PARK_CLEARANCE).min(s.bed.map_or(f64::INFINITY, |b| b.max_height));
        let v = match name {
            "bed_temperature" => num(s.bed_temperature, 0),
            "first_layer_bed_temperature" => num(s.first_layer_bed_temperature, 0),
            "first_tool" => head.index.to_string(),
            "nozzle_temperature" => num(head.nozzle_temperature, 0),
            "first_layer_temperature" => num(head.first_layer_temperature, 0),
            "standby_temperature" => num(head.standby_temperature.unwrap_or(head.nozzle_temperature), 0),
            "filament_diameter" => num(s.filament_diameter, 3),
            "nozzle_diameter" => num(s.nozzle_diameter, 3),
            "print_min_x" => num(printed.min.x, 3),
            "print_min_y" => num(printed.min.y, 3),
            "print_max_x" => num(printed.max.x, 3),
            "print_max_y" => num(printed.max.y, 3),
            "max_z" => num(self.z_max, 3),
            "park_z" => num(park, 3),
            "layer_z" => num(layer_z, 3),
            "previous_tool" => match change {
                Some((Some(p), _)) => s.heads[p].index.to_string(),
                _ => "-1".into(),
            },
            "next_tool" => s.heads[change?.1].index.to_string(),
            "next_temperature" => num(s.heads[change?.1].temperature(self.layers), 0),
            _ => {
                let (base, n) = name.rsplit_once('_')?;
                let (nozzle, first, standby) = *self.tool_temperatures.get(n.parse::<usize>().ok()?)?;
                match base {
                    "nozzle_temperature" => num(nozzle, 0),
                    "first_layer_temperature" => num(first, 0),
                    "standby_temperature" => num(standby, 0),
                    _ => return None,
                }
            }
        };
        Some(v)
    }

    fn render(
        &self,
        t: &lamina_api::machine::Template,
        change: Option<(Option<usize>, usize)>,
        layer_z: f64,
    ) -> Result<String> {
        t.render(|n| self.variable(n, change, layer_z)).map_err(|e| {
            Error::stage(
                crate::STAGE,
                format!("machine `{}`: {e}", self.s.machine.as_deref().unwrap_or("?")),
            )
        })
    }

    // ------------------------------------------------------------------ tools and heat

    /// Selects head `h` (changing tools if need be) and waits until it is at the
    /// temperature of the current layer.
    fn ready(&mut self, h: usize) -> Result<()> {
        if self.head != Some(h) {
            self.change_to(h)?;
        }
        let head = self.s.heads[h].clone();
        let temperature = head.temperature(self.layers);
        if !self.fw.is_hot(head.index, temperature) {
            match self.s.dialect {
                Dialect::Marlin => {
                    let t = if self.s.flavor.is_mixing() {
                        String::new()
                    } else {
                        format!(" T{}", head.index)
                    };
                    self.line(format!("M109{t} S{} ; wait for the nozzle", num(temperature, 0)));
                }
                Dialect::RepRapFirmware => {
                    if (self.fw.target(head.index) - temperature).abs() > 0.5 {
                        self.line(crate::commands::rrf_tool_temperatures(
                            head.index,
                            temperature,
                            head.standby_temperature,
                        ));
                    }
                    self.line(format!("M116 P{} ; wait for the tool's heaters", head.index));
                }
            }
        }
        // A standby raised to heat the tool ahead of its change goes back down, for
        // when the tool waits again.
        if self.raised.get(h).copied().unwrap_or(false) {
            self.raised[h] = false;
            self.line(crate::commands::rrf_tool_temperatures(
                head.index,
                temperature,
                head.standby_temperature,
            ));
        }
        Ok(())
    }

    /// Before job `k`: when the layer changes to another head later and that head,
    /// waiting at its standby temperature, would not be at its printing temperature by
    /// then, it starts heating now (Marlin `M104 T`, RepRapFirmware a raised standby
    /// `G10 P R`), so that the change waits for no heater. The time left is that of the
    /// jobs before the change at their planned speeds and the travels between them.
    fn preheat(&mut self, jobs: &[Job<'_>], k: usize) {
        if self.s.flavor.is_mixing() || self.s.machine.is_none() {
            return;
        }
        let Some(current) = self.head else { return };
        let Some(next) = jobs[k..].iter().position(|j| j.head != current).map(|n| k + n) else {
            return;
        };
        let h = jobs[next].head;
        let head = self.s.heads[h].clone();
        let print = head.temperature(self.layers);
        if self.fw.target(head.index) >= print - 0.5 {
            return;
        }
        let mut left = 0.0;
        let mut at = Point2::new(self.fw.position()[0], self.fw.position()[1]) - self.layout.offset;
        for j in &jobs[k..next] {
            let (Some(a), Some(b)) = (j.path.points.first(), j.path.points.last()) else {
                continue;
            };
            left += (a.p - at).norm() / self.s.travel_speed;
            left += if b.t > a.t {
                b.t - a.t
            } else {
                j.path.length() / DEFAULT_PRINT_SPEED
            };
            at = b.p;
        }
        // Heating from where it will be then, with a margin for what the estimate of
        // the moves leaves out (acceleration, retractions).
        let rate = self.fw.nozzle_rate();
        let then = self.fw.temperature_in(head.index, left);
        let needed = (print - then).max(0.0) / rate;
        if 0.8 * left > needed + PREHEAT_MARGIN {
            return;
        }
        match self.s.dialect {
            Dialect::Marlin => {
                self.line(format!(
                    "M104 T{} S{} ; heat ahead of its change",
                    head.index,
                    num(print, 0)
                ));
            }
            Dialect::RepRapFirmware => {
                self.line(format!(
                    "G10 P{} R{} ; heat ahead of its change (standby raised)",
                    head.index,
                    num(print, 0)
                ));
                self.raised[h] = true;
            }
        }
    }

    /// Parks the head in use (retracted, at standby) and selects head `h`.
    fn change_to(&mut self, h: usize) -> Result<()> {
        let to = self.s.heads[h].clone();
        let from = self.head;
        if self.s.flavor.is_mixing() {
            if self.fw.tool() != Some(to.index) {
                self.line(format!("T{} ; select the mixing tool", to.index));
            }
            self.head = Some(h);
            return Ok(());
        }
        if let Some(f) = from {
            let length = self.s.retraction.tool_change_length;
            self.retract(length);
            self.lift();
            let prev = self.s.heads[f].clone();
            if let (Some(standby), Dialect::Marlin) = (prev.standby_temperature, self.s.dialect) {
                self.line(format!("M104 T{} S{} ; standby", prev.index, num(standby, 0)));
            }
        }
        self.comment(format!("tool change to T{} ({})", to.index, clean(&to.label)));
        let text = if self.s.machine.is_some() {
            self.render(&self.s.templates.tool_change.clone(), Some((from, h)), self.z)?
        } else {
            String::new()
        };
        self.template("tool change", &text)?;
        if self.fw.tool() != Some(to.index) {
            self.line(format!("T{}", to.index));
        }
        if !self.s.relative_e {
            // Each tool's E axis starts over: keep this file's E continuous.
            let e = self.fw.position()[3];
            self.line(format!("G92 E{e:.5}"));
        }
        self.head = Some(h);
        Ok(())
    }

    fn can_move_filament(&self) -> bool {
        self.head.is_some_and(|h| {
            let i = self.s.heads[h].index;
            self.fw.tool() == Some(i) && self.fw.is_hot(i, EXTRUDE_MIN_TEMPERATURE)
        })
    }

    /// Pulls the filament of the head in use back to `length` mm (if it is hot).
    fn retract(&mut self, length: f64) {
        let Some(h) = self.head else { return };
        let more = length - self.retracted[h];
        if more > 1e-9 && self.extruded[h] && self.can_move_filament() {
            let e = self.e_word(-more);
            let f = self.s.retraction.speed * 60.0;
            self.line(format!("G1 {e} F{}", num(f, 0)));
            self.retracted[h] = length;
        }
    }

    /// Pushes the filament of the head in use back to the nozzle.
    fn unretract(&mut self) {
        let Some(h) = self.head else { return };
        let back = self.retracted[h];
        if back > 1e-9 && self.can_move_filament() {
            let e = self.e_word(back);
            let f = self.s.retraction.speed * 60.0;
            self.line(format!("G1 {e} F{}", num(f, 0)));
            self.retracted[h] = 0.0;
        }
    }

    /// The E word for `de` mm of filament, absolute or relative.
    fn e_word(&self, de: f64) -> String {
        let mut out = String::with_capacity(16);
        let _ = self.push_e_word(&mut out, de);
        out
    }

    /// [`Writer::e_word`] appended to `out`; returns E as a reader parses it back.
    fn push_e_word(&self, out: &mut String, de: f64) -> f64 {
        out.push('E');
        if self.s.relative_e {
            push_fixed(out, de, 5)
        } else {
            push_fixed(out, self.fw.position()[3] + de, 5)
        }
    }

    fn z_feed(&self) -> f64 {
        let max = self.s.limits.max_speed[2];
        let cap = if max.is_finite() { max } else { DEFAULT_Z_SPEED };
        self.s.travel_speed.min(cap) * 60.0
    }

    /// Lifts the nozzle by the z-hop, when there is one.
    fn lift(&mut self) {
        let hop = self.s.retraction.z_hop;
        if hop > 0.0 && self.fw.position()[2] < self.z + hop - 1e-9 {
            let f = self.z_feed();
            self.line(format!("G1 Z{} F{}", num(self.z + hop, 4), num(f, 0)));
        }
    }

    /// Moves to `to` at the layer's height, retracted (and lifted) when far.
    fn travel(&mut self, to: Point2) {
        self.travel_at(to, self.s.travel_speed);
    }

    /// [`Self::travel`] at `speed` (mm/s).
    fn travel_at(&mut self, to: Point2, speed: f64) {
        let [x, y, z, _] = self.fw.position();
        let d = (to - Point2::new(x, y)).norm();
        // The position is read back from the file, rounded to its 4 decimals.
        if d < 2e-4 && (z - self.z).abs() < 1e-9 {
            return;
        }
        // A travel over the part keeps the filament where it is: what oozes lands on
        // the layer.
        let over_part = || {
            self.solid
                .as_ref()
                .is_some_and(|s| s.holds(Point2::new(x, y), to))
        };
        let f = speed * 60.0;
        let mut ramp = false;
        if d > RETRACT_MIN_TRAVEL && !over_part() {
            // Around what is not part, when one turn inside keeps the way short.
            let turn = self.solid.as_ref().and_then(|s| s.detour(Point2::new(x, y), to));
            match turn {
                Some(w) if (z - self.z).abs() < 1e-9 => {
                    self.line(format!("G0 X{} Y{} F{}", num(w.x, 4), num(w.y, 4), num(f, 0)));
                }
                _ => {
                    self.retract(self.s.retraction.length);
                    // The z-hop rises along the travel (a ramping lift) rather than
                    // before it: the nozzle leaves the layer as it moves away, and the
                    // machine spends no stop on a separate lift.
                    let hop = self.s.retraction.z_hop;
                    ramp = hop > 0.0 && z < self.z + hop - 1e-9;
                }
            }
        }
        let z_word = if ramp {
            format!(" Z{}", num(self.z + self.s.retraction.z_hop, 4))
        } else {
            String::new()
        };
        self.line(format!(
            "G0 X{} Y{}{z_word} F{}",
            num(to.x, 4),
            num(to.y, 4),
            num(f, 0)
        ));
        if (self.fw.position()[2] - self.z).abs() > 1e-9 {
            let f = self.z_feed();
            self.line(format!("G1 Z{} F{}", num(self.z, 4), num(f, 0)));
        }
    }

    /// The feed of an extrusion on the current layer (mm/min).
    fn print_feed(&self, speed: f64) -> f64 {
        let v = match (self.layers, self.s.first_layer_speed) {
            (0, Some(FirstLayerSpeed::Factor(f))) => speed * f,
            (0, Some(FirstLayerSpeed::Speed(s))) => speed.min(s),
            _ => speed,
        };
        v * 60.0
    }

    /// Extrudes along `points` (machine coordinates) with head `h`: segment `i` is
    /// `width(i)` wide and `height` high.
    fn extrude(
        &mut self,
        h: usize,
        points: &[Point2],
        width: &dyn Fn(usize) -> f64,
        height: f64,
        speed: f64,
        feature: Feature,
    ) -> Result<()> {
        self.extrude_mixed(h, points, width, height, speed, feature, &[])
    }

    /// [`Self::extrude`] with a mix for each segment (a mixing head following the
    /// gradient along the bead); the mix is set only where it changes.
    #[allow(clippy::too_many_arguments)]
    fn extrude_mixed(
        &mut self,
        h: usize,
        points: &[Point2],
        width: &dyn Fn(usize) -> f64,
        height: f64,
        speed: f64,
        feature: Feature,
        mixes: &[Vec<u32>],
    ) -> Result<()> {
        let Some(&first) = points.first() else {
            return Ok(());
        };
        self.ready(h)?;
        self.travel(first);
        self.set_feature(feature);
        self.unretract();
        let feed = self.print_feed(speed);
        let area = self.s.filament_area();
        let mut with_feed = (self.fw.feed() - feed).abs() > 0.5;
        // One line buffer for the whole path: a path is thousands of moves.
        let mut text = std::mem::take(&mut self.text);
        let mut from = points[0];
        for (i, w) in points.windows(2).enumerate() {
            let d = (w[1] - from).norm();
            if d <= 1e-9 {
                continue;
            }
            if let Some(m) = mixes.get(i) {
                self.set_mix(m.clone());
            }
            // E is written to five decimals: a move that would feed less than half of
            // the last digit extrudes nothing as written. A stretch the bead leaves
            // empty (no width) is a move without E; a sliver of a segment is passed
            // over, and the next move goes on from the last point written (its length,
            // and so its filament, takes the sliver's).
            let de = d * width(i) * height / area;
            let feeds = de >= E_RESOLUTION / 2.0;
            if !feeds && d < SLIVER {
                continue;
            }
            from = w[1];
            text.clear();
            let mut words = Words::default();
            text.push_str("G1 X");
            words.x = Some(push_num(&mut text, w[1].x, 4));
            text.push_str(" Y");
            words.y = Some(push_num(&mut text, w[1].y, 4));
            if feeds {
                self.account(h, de);
                self.deposited[feature as usize] += de * area;
                self.extruded[h] = true;
                text.push(' ');
                words.e = Some(self.push_e_word(&mut text, de));
            }
            if with_feed {
                with_feed = false;
                text.push_str(" F");
                words.f = Some(push_num(&mut text, feed, 0));
            }
            self.move_line(&text, words);
        }
        self.text = text;
        Ok(())
    }

    /// Counts filament toward the head's or the mix's channels.
    fn account(&mut self, h: usize, de: f64) {
        match &self.mix {
            Some(m) if self.s.flavor.is_mixing() => {
                for (x, p) in self.fed.iter_mut().zip(m) {
                    *x += de * f64::from(*p) / 100.0;
                }
            }
            _ => {
                if let Some(x) = self.fed.get_mut(h) {
                    *x += de;
                }
            }
        }
    }

    fn strokes(&mut self, h: usize, strokes: Vec<Stroke>, height: f64) -> Result<()> {
        let w = self.s.line_width();
        for s in strokes {
            self.extrude(h, &s.points, &|_| w, height, TOWER_SPEED, s.feature)?;
        }
        Ok(())
    }

    // ------------------------------------------------------------------ mixing

    /// The mix of a path over the head's channels, in percent summing to 100.
    fn mix_of(&self, info: &RunInfo, path: &Toolpath) -> Vec<u32> {
        self.mix_for(info, path.part, path.composition.as_ref())
    }

    /// The mix for a composition of a part's materials (its first material alone
    /// without one).
    fn mix_for(&self, info: &RunInfo, part: Option<usize>, composition: Option<&Composition>) -> Vec<u32> {
        let channels = self.s.channel_names.len();
        let mut f = vec![0.0; channels];
        match (composition, part.and_then(|p| info.parts.get(p))) {
            (Some(c), Some(part)) => {
                for (x, m) in c.fractions.iter().zip(&part.materials) {
                    if let Some(Some(ch)) = self.s.slot_of.get(*m) {
                        f[*ch] += x;
                    }
                }
            }
            (_, Some(part)) => {
                if let Some(Some(ch)) = part.materials.first().and_then(|m| self.s.slot_of.get(*m)) {
                    f[*ch] = 1.0;
                }
            }
            _ => {}
        }
        percentages(&f)
    }

    /// With `mix_along`, the mix of each segment of a bead: the composition graded
    /// nearest the segment's middle in the sub-region the bead fills. Empty (one mix for
    /// the bead) otherwise, or when the region was graded as a whole.
    fn mixes_along(&self, info: &RunInfo, plan: &LayerPlan, path: &Toolpath) -> Vec<Vec<u32>> {
        if !self.s.mix_along {
            return Vec::new();
        }
        let region = path.part.zip(path.sub_region).and_then(|(part, r)| {
            plan.parts
                .iter()
                .find(|pl| pl.part == part)
                .and_then(|pl| pl.regions.get(r))
        });
        let Some(region) = region.filter(|r| !r.samples.is_empty()) else {
            return Vec::new();
        };
        let mut current: Option<Vec<u32>> = None;
        path.points
            .windows(2)
            .map(|w| {
                let mid = Point2::from((w[0].p.coords + w[1].p.coords) / 2.0);
                let mix = self.mix_for(
                    info,
                    path.part,
                    crate::mix_along::composition_at(region, mid).as_ref(),
                );
                // A dead band: the samples' own scatter would make a mix of 95 % flicker
                // to 94 and 96 every few segments.
                let keep = current
                    .as_ref()
                    .is_some_and(|c| c.iter().zip(&mix).all(|(a, b)| a.abs_diff(*b) < MIX_DEAD_BAND));
                if !keep {
                    current = Some(mix);
                }
                current.clone().unwrap_or_default()
            })
            .collect()
    }

    fn set_mix(&mut self, mix: Vec<u32>) {
        if self.mix.as_ref() == Some(&mix) {
            return;
        }
        for l in crate::commands::mix(&self.s, &mix) {
            self.line(l);
        }
        self.mix = Some(mix);
    }

    // ------------------------------------------------------------------ layers

    /// The layer's paths in the order they are written: tool changers tool by tool
    /// (starting with the tool in use, to save a change), each tool's paths in planned
    /// order; mixing heads mix by mix, a bead cut into pieces of several mixes kept
    /// whole.
    fn jobs<'a>(&self, info: &RunInfo, plan: &'a LayerPlan, state: &State) -> Vec<Job<'a>> {
        let mut paths: Vec<&Toolpath> = plan
            .toolpaths
            .iter()
            .filter(|p| p.kind == PathKind::Extrude && p.points.len() >= 2)
            .collect();
        let start = |p: &&Toolpath| p.points.first().map_or(0.0, |q| q.t);
        if self.s.flavor.is_mixing() {
            paths.sort_by(|a, b| start(a).total_cmp(&start(b)));
            let mut jobs: Vec<Job<'a>> = Vec::with_capacity(paths.len());
            for path in paths {
                let continues = jobs.last().is_some_and(|prev: &Job<'a>| {
                    prev.path.part == path.part
                        && match (prev.path.points.last(), path.points.first()) {
                            (Some(a), Some(b)) => (a.p - b.p).norm() < 1e-9,
                            _ => false,
                        }
                });
                jobs.push(Job {
                    head: 0,
                    mix: Some(self.mix_of(info, path)),
                    path,
                    continues,
                });
            }
            return self.by_mix(jobs, state.mix.clone());
        }
        let mut jobs: Vec<Job<'a>> = paths
            .into_iter()
            .map(|path| Job {
                head: self.head_of(info, path),
                mix: None,
                path,
                continues: false,
            })
            .collect();
        let current = state.head;
        jobs.sort_by(|a, b| {
            let rank = |h: usize| (Some(h) != current, h);
            rank(a.head)
                .cmp(&rank(b.head))
                .then(start(&a.path).total_cmp(&start(&b.path)))
        });
        jobs
    }

    /// A mixing head's paths ordered by mix: every change of mix between beads may cost
    /// a purge, so each next chain of paths (a bead cut into pieces of several mixes
    /// stays whole) starts with the mix in the nozzle when one does, in planned order,
    /// else with the nearest mix. A layer of a few mixes changes once per mix.
    fn by_mix<'a>(&self, jobs: Vec<Job<'a>>, mut last: Option<Vec<u32>>) -> Vec<Job<'a>> {
        // Paths that go on from the previous one stay with it, under its mix.
        let mut chains: Vec<Vec<Job<'a>>> = Vec::new();
        for j in jobs {
            match chains.last_mut() {
                Some(chain) if j.continues => chain.push(j),
                _ => chains.push(vec![j]),
            }
        }
        // Each next chain starts with the mix the last one ended with when one does (in
        // planned order), else with the nearest mix.
        let first_mix = |c: &[Job<'a>]| c[0].mix.clone().unwrap_or_default();
        let mut by_first: std::collections::HashMap<Vec<u32>, std::collections::VecDeque<usize>> =
            std::collections::HashMap::new();
        for (i, c) in chains.iter().enumerate() {
            by_first.entry(first_mix(c)).or_default().push_back(i);
        }
        let distance = |a: &[u32], b: &[u32]| -> u32 { a.iter().zip(b).map(|(x, y)| x.abs_diff(*y)).sum() };
        let mut left: Vec<Option<Vec<Job<'a>>>> = chains.into_iter().map(Some).collect();
        let mut out = Vec::new();
        for _ in 0..left.len() {
            let same = last.as_ref().and_then(|l| {
                let queue = by_first.get_mut(l)?;
                while let Some(i) = queue.pop_front() {
                    if left[i].is_some() {
                        return Some(i);
                    }
                }
                None
            });
            let next = same.or_else(|| {
                (0..left.len()).filter(|&i| left[i].is_some()).min_by_key(|&i| {
                    let c = left[i].as_deref().expect("left");
                    (last.as_ref().map_or(0, |l| distance(l, &first_mix(c))), i)
                })
            });
            let Some(chain) = next.and_then(|i| left[i].take()) else {
                break;
            };
            last = chain.last().and_then(|j| j.mix.clone()).or(last);
            out.extend(chain);
        }
        out
    }

    /// The head of a path on a tool changer: the one carrying the material its tool
    /// carries, else its dominant material; from a planner that names neither, the
    /// material numbered as its tool.
    fn head_of(&self, info: &RunInfo, path: &Toolpath) -> usize {
        let dominant = || match (&path.composition, path.part.and_then(|p| info.parts.get(p))) {
            (Some(c), Some(part)) if c.fractions.len() == part.materials.len() => c
                .fractions
                .iter()
                .enumerate()
                .max_by(|a, b| a.1.total_cmp(b.1).then(b.0.cmp(&a.0)))
                .map(|(i, _)| part.materials[i]),
            _ => None,
        };
        let material = path.material.or_else(dominant).unwrap_or(path.tool);
        self.s.slot_of.get(material).copied().flatten().unwrap_or(0)
    }

    /// Before the first layer: each head the parts use is heated, selected and primes
    /// its line (the first layer's first head last, so the layer starts with it).
    fn prime(&mut self, info: &RunInfo, plan: &LayerPlan) -> Result<()> {
        self.z = plan.z;
        let jobs = self.jobs(info, plan, &self.state());
        let first = jobs.first().map(|j| j.head);
        let lines = self.layout.prime_lines.clone();
        if lines.is_empty() {
            return Ok(());
        }
        let mut order: Vec<usize> = if self.s.flavor.is_mixing() {
            vec![0]
        } else {
            self.s.used_heads(info)
        };
        if let Some(f) = first {
            order.retain(|h| *h != f);
            order.push(f);
        }
        if self.s.flavor.is_mixing() {
            let mix = self.prime_mix(info, plan);
            self.nozzle = Some(fractions(&mix));
            self.set_mix(mix);
        }
        let width = self.s.prime_line.map_or(self.s.line_width(), |p| p.width);
        // Clear of anything left on the bed, then down to the first layer.
        let above = self.fw.position()[2].max(self.z + 1.0);
        if self.fw.position()[2] < above - 1e-9 {
            let f = self.z_feed();
            self.line(format!("G1 Z{} F{}", num(above, 3), num(f, 0)));
        }
        for (h, (a, b)) in order.into_iter().zip(lines) {
            self.comment(format!("prime line of T{}", self.s.heads[h].index));
            self.extrude(
                h,
                &[a, b],
                &|_| width,
                plan.thickness,
                PRIME_SPEED,
                Feature::Prime,
            )?;
            self.retract(self.s.retraction.length);
        }
        Ok(())
    }

    /// Switches the bed and nozzles from their first-layer temperatures.
    fn after_first_layer(&mut self) {
        let s = self.s.clone();
        if s.machine.is_some() && (s.bed_temperature - s.first_layer_bed_temperature).abs() > 0.5 {
            self.line(format!("M140 S{}", num(s.bed_temperature, 0)));
        }
        for (h, head) in s.heads.iter().enumerate() {
            if (head.nozzle_temperature - head.first_layer_temperature).abs() <= 0.5 {
                continue;
            }
            match s.dialect {
                Dialect::Marlin => {
                    if self.head == Some(h) {
                        self.line(crate::commands::set_temperature(
                            &s,
                            head.index,
                            head.nozzle_temperature,
                        ));
                    }
                }
                Dialect::RepRapFirmware => {
                    if self.fw.target(head.index) > 0.0 || self.head == Some(h) {
                        self.line(crate::commands::rrf_tool_temperatures(
                            head.index,
                            head.nozzle_temperature,
                            head.standby_temperature,
                        ));
                    }
                }
            }
        }
    }

    fn set_fan(&mut self) {
        let Some(fan) = self.s.fan else { return };
        let n = self.layers;
        let full = fan.speed / 100.0;
        let start = usize::from(!fan.first_layer);
        let f = if n < start {
            0.0
        } else if n >= fan.full_speed_layer || fan.full_speed_layer <= start {
            full
        } else {
            full * (n - start + 1) as f64 / (fan.full_speed_layer - start + 1) as f64
        };
        if (f - self.fw.fan()).abs() > 0.005 {
            self.line(crate::commands::fan(&self.s, f));
        }
    }

    /// Takes one layer. Without a wipe tower it is written at once. With one, a layer
    /// whose changes purge nothing on the tower waits (spooled to a temporary file, so
    /// memory stays flat) until a later layer needs the tower, when it is written with a
    /// tower level under that layer's, or until the end, when it is written without:
    /// the tower stands from the bed to the last layer that purges on it, and a job
    /// that never purges has none.
    pub fn write_layer(&mut self, info: &RunInfo, plan: &LayerPlan) -> Result<()> {
        if let Some(max) = self.s.max_layer_height
            && plan.thickness > max + 1e-9
        {
            return Err(Error::stage(
                "gcode",
                format!(
                    "layer {} is {} mm thick; the machine's {} mm nozzle presses layers of at most {} mm (`max_layer_height`): slice thinner layers",
                    plan.index, plan.thickness, self.s.nozzle_diameter, max
                ),
            ));
        }
        if self.multi.is_some() {
            self.write_layer_multi(plan)?;
            self.planned += plan.build_time.unwrap_or(0.0);
            self.layers += 1;
            return self.flush();
        }
        if self.tower.is_none() {
            return self.emit_layer(info, plan, false);
        }
        let start = match self.received {
            Some(ref state) => state.clone(),
            None => self.primed_state(info, plan),
        };
        let analysis = self.analyse(info, plan, &start);
        let on_tower = analysis.changes.iter().flatten().any(|c| c.tower > 0.0);
        self.received = Some(analysis.end.clone());
        if !on_tower {
            return self.spool.push(plan);
        }
        self.write_spooled(info, true)?;
        self.emit_layer(info, plan, true)
    }

    /// Writes the spooled layers, with tower levels or without.
    fn write_spooled(&mut self, info: &RunInfo, tower: bool) -> Result<()> {
        let mut spool = std::mem::take(&mut self.spool);
        spool.drain(|plan| self.emit_layer(info, &plan, tower))?;
        self.spool = spool;
        Ok(())
    }

    /// The head and mix in use when the first layer begins: those the prime lines leave.
    fn primed_state(&self, info: &RunInfo, plan: &LayerPlan) -> State {
        if self.layout.prime_lines.is_empty() {
            return self.state();
        }
        let first = self.jobs(info, plan, &self.state()).first().map(|j| j.head);
        let mix = self.s.flavor.is_mixing().then(|| self.prime_mix(info, plan));
        State {
            head: first.or(self.head),
            nozzle: mix.as_deref().map(fractions).or(self.nozzle.clone()),
            mix: mix.or(self.mix.clone()),
        }
    }

    /// The state in use now.
    fn state(&self) -> State {
        State {
            head: self.head,
            mix: self.mix.clone(),
            nozzle: self.nozzle.clone(),
        }
    }

    /// A mixing head primes with the mix its first bead starts with, so that the first
    /// layer begins without a transition (every channel the parts use in equal shares
    /// when there is no bead).
    fn prime_mix(&self, info: &RunInfo, plan: &LayerPlan) -> Vec<u32> {
        let jobs = self.jobs(info, plan, &self.state());
        if let Some(j) = jobs.first() {
            let along = self.mixes_along(info, plan, j.path);
            if let Some(mix) = along.first().or(j.mix.as_ref()) {
                return mix.clone();
            }
        }
        let mut even = vec![0.0; self.s.channel_names.len()];
        for c in self.s.used_channels(info) {
            even[c] = 1.0;
        }
        percentages(&even)
    }

    /// The layer's jobs from `state` (the head and mix in use before it), each job's
    /// mixes along its bead, and the changes before each job with where their
    /// transitions go (see [`crate::transition`]).
    fn analyse<'a>(&self, info: &RunInfo, plan: &'a LayerPlan, state: &State) -> Analysis<'a> {
        let jobs = self.jobs(info, plan, state);
        // Each bead's mixes along it (`mix_along`; empty: one mix), and the mixes it
        // starts and ends with: a change is decided between one bead's last mix and the
        // next one's first.
        let along: Vec<Vec<Vec<u32>>> = jobs
            .iter()
            .map(|j| self.mixes_along(info, plan, j.path))
            .collect();
        let first_mix = |k: usize| along[k].first().or(jobs[k].mix.as_ref()).cloned();
        let last_mix = |k: usize| along[k].last().or(jobs[k].mix.as_ref()).cloned();
        let mixing = self.s.flavor.is_mixing();
        let full = if mixing {
            self.s.transition_volume
        } else {
            self.s.wipe_tower.map_or(0.0, |w| w.purge_volume)
        };
        // Which jobs follow a change: of head, or of mix beyond what blends in place.
        let mut state = state.clone();
        let mut moves: Vec<Option<bool>> = Vec::with_capacity(jobs.len());
        for (k, j) in jobs.iter().enumerate() {
            let start = first_mix(k).or(state.mix.clone());
            let moved = match (&state.mix, &start) {
                (Some(a), Some(b)) if !j.continues => crate::transition::moved(a, b),
                _ => 0.0,
            };
            let head_change = state.head.is_some_and(|h| h != j.head);
            let purged_mix = moved > 0.0 && moved >= self.s.blend_below;
            moves.push((state.head.is_some() && (head_change || purged_mix)).then_some(head_change));
            state.head = Some(j.head);
            state.mix = last_mix(k).or(start);
        }
        // Each job's bead volume, once.
        let volumes: Vec<f64> = jobs.iter().map(|j| j.path.bead_area() * plan.thickness).collect();
        let volume = |i: usize| volumes[i];
        let mut steps: std::collections::HashMap<(usize, usize), f64> = std::collections::HashMap::new();
        let mut changes = Vec::with_capacity(jobs.len());
        let mut early: Vec<Option<(f64, Vec<u32>)>> = vec![None; jobs.len()];
        // What the nozzle holds before each job, and where the beads before a change
        // began (the last change, or the layer's start).
        let mut before: Vec<Option<Vec<f64>>> = Vec::with_capacity(jobs.len());
        let mut chain_start = 0;
        for (k, j) in jobs.iter().enumerate() {
            let target = first_mix(k).as_deref().map(fractions);
            if let Some(head_change) = moves[k] {
                // The beads up to the next change: the same head, and the same mix or one
                // that blends in place.
                let next = (k + 1..jobs.len())
                    .find(|&i| moves[i].is_some())
                    .unwrap_or(jobs.len());
                let chain: f64 = volumes[k..next].iter().sum();
                let tower = match self.s.purge_into {
                    PurgeInto::Tower => full,
                    PurgeInto::Part if !mixing && head_change => 0.0,
                    PurgeInto::Part => {
                        let step = self.design_step(info, plan, j.path, &mut steps);
                        let moved = match (&state.nozzle, &target) {
                            (Some(n), Some(t)) => crate::transition::departure(n, t),
                            _ => 0.0,
                        };
                        crate::transition::tower_volume(moved, step, chain, full)
                    }
                };
                // Rather than on the tower, the nozzle may start toward the new mix
                // within the last bead before the change, when the beads before it stay
                // within half their own design step (their design lies between the two).
                let mut tower = tower;
                if mixing
                    && tower > 0.0
                    && self.s.purge_into == PurgeInto::Part
                    && k > chain_start
                    && let (Some(n0), Some(t)) = (before[chain_start].clone(), &target)
                {
                    let last = k - 1;
                    let x = tower.min(volume(last));
                    let designs: Vec<Vec<f64>> = (chain_start..k)
                        .map(|i| last_mix(i).as_deref().map(fractions).unwrap_or_else(|| t.clone()))
                        .collect();
                    let mut beads: Vec<(f64, &[f64], &[f64])> = (chain_start..k)
                        .map(|i| {
                            let d = &designs[i - chain_start];
                            (volume(i), d.as_slice(), d.as_slice())
                        })
                        .collect();
                    let own = designs[last - chain_start].as_slice();
                    if let Some(b) = beads.last_mut() {
                        b.0 -= x;
                    }
                    beads.push((x, t.as_slice(), own));
                    let step = self.design_step(info, plan, jobs[last].path, &mut steps);
                    if crate::transition::mean_departure(&n0, &beads, full) <= step / 2.0
                        && let (Some(nl), Some(mix)) = (before[last].clone(), first_mix(k))
                    {
                        let at = crate::transition::flush(&nl, own, volume(last) - x, full);
                        state.nozzle = Some(crate::transition::flush(&at, t, x, full));
                        early[last] = Some((x, mix));
                        tower -= x;
                    }
                }
                if let (Some(n), Some(t)) = (&state.nozzle, &target) {
                    state.nozzle = Some(crate::transition::flush(n, t, tower, full));
                }
                let part = (full - tower).min(chain).max(0.0);
                changes.push(Some(Change { tower, part }));
                chain_start = k;
            } else {
                changes.push(None);
            }
            before.push(state.nozzle.clone());
            // The bead flushes the nozzle toward its mix (its last, along a bead).
            if mixing && let Some(t) = last_mix(k).as_deref().map(fractions).or(target) {
                let from = state.nozzle.clone().unwrap_or_else(|| t.clone());
                state.nozzle = Some(crate::transition::flush(&from, &t, volume(k), full));
            }
        }
        Analysis {
            jobs,
            along,
            changes,
            early,
            end: state,
        }
    }

    /// The design step of the family a path fills ([`crate::transition::design_step`]),
    /// 0 when the path fills no graded sub-region.
    fn design_step(
        &self,
        info: &RunInfo,
        plan: &LayerPlan,
        path: &Toolpath,
        cache: &mut std::collections::HashMap<(usize, usize), f64>,
    ) -> f64 {
        let Some((part, r)) = path.part.zip(path.sub_region) else {
            return 0.0;
        };
        let Some(layer) = plan.parts.iter().find(|pl| pl.part == part) else {
            return 0.0;
        };
        let Some(family) = layer.regions.get(r).map(|x| x.family) else {
            return 0.0;
        };
        *cache.entry((part, family)).or_insert_with(|| {
            let regions: Vec<(f64, Vec<u32>)> = layer
                .regions
                .iter()
                .filter(|x| x.family == family)
                .map(|x| (x.level, self.mix_for(info, Some(part), x.composition.as_ref())))
                .collect();
            crate::transition::design_step(&regions)
        })
    }

    /// Writes one layer, with a level of the wipe tower when `tower`.
    fn emit_layer(&mut self, info: &RunInfo, plan: &LayerPlan, tower: bool) -> Result<()> {
        if !self.started {
            self.prime(info, plan)?;
            self.started = true;
        }
        self.feature = None;
        let _ = writeln!(
            self.buf,
            ";LAYER:{} Z{:.4} height {:.4}",
            plan.index, plan.z, plan.thickness
        );
        if self.layers == 1 {
            self.after_first_layer();
        }
        self.set_fan();
        let analysis = self.analyse(info, plan, &self.state());
        let Analysis {
            jobs,
            mut along,
            changes,
            early,
            end,
        } = analysis;
        // A job that starts the next mix before its end carries the mix of each segment.
        for (k, e) in early.iter().enumerate() {
            let Some((x, mix)) = e else { continue };
            let path = jobs[k].path;
            let segments = path.points.len().saturating_sub(1);
            let mut mixes = if along[k].is_empty() {
                vec![jobs[k].mix.clone().unwrap_or_default(); segments]
            } else {
                along[k].clone()
            };
            let mut from_end = 0.0;
            for i in (0..segments).rev() {
                if from_end >= *x - 1e-9 {
                    break;
                }
                from_end +=
                    (path.points[i + 1].p - path.points[i].p).norm() * path.segment_width(i) * plan.thickness;
                mixes[i] = mix.clone();
            }
            along[k] = mixes;
        }
        self.nozzle = end.nozzle;
        // Up to the layer's height.
        if (plan.z - self.z).abs() > 1e-9 || self.layers == 0 {
            self.retract(self.s.retraction.length);
            self.z = plan.z;
            if (self.fw.position()[2] - plan.z).abs() > 1e-9 {
                let f = self.z_feed();
                self.line(format!("G1 Z{} F{}", num(plan.z, 4), num(f, 0)));
            }
        }
        self.solid = Some(crate::solid::Solid::new(plan, self.layout.offset));
        let tower_here = tower && self.tower.is_some();
        if tower_here && let Some(t) = &mut self.tower {
            t.begin(plan.z);
        }
        // Skirt, with the head in use (or the layer's first).
        if let (Some(skirt), Some(h)) = (self.s.skirt, self.head.or(jobs.first().map(|j| j.head)))
            && self.layers < skirt.layers
        {
            let loops = self.layout.skirt.clone();
            let w = self.s.line_width();
            for l in loops {
                self.extrude(h, &l, &|_| w, plan.thickness, SKIRT_SPEED, Feature::Skirt)?;
            }
        }
        let offset = self.layout.offset;
        let mut left = changes
            .iter()
            .filter(|c| c.as_ref().is_some_and(|c| c.tower > 0.0))
            .count();
        for (k, j) in jobs.iter().enumerate() {
            self.preheat(&jobs, k);
            // Following the gradient along the bead, it starts with its first segment's.
            if let Some(m) = along[k].first().or(j.mix.as_ref()).cloned() {
                self.set_mix(m);
            }
            self.ready(j.head)?;
            if let Some(change) = &changes[k] {
                if change.tower > 0.0 {
                    left = left.saturating_sub(1);
                    if tower_here && !self.tower.as_ref().is_some_and(Tower::open) {
                        self.comment(
                            "the tower's level at this height is complete: the change is not purged",
                        );
                    } else if tower_here {
                        let strokes = match &mut self.tower {
                            Some(t) => t
                                .purge(change.tower)
                                .map_err(|e| e.in_layer(plan.index, plan.z))?,
                            None => Vec::new(),
                        };
                        self.strokes(j.head, strokes, self.tower_height())?;
                        if left == 0 {
                            let strokes = self.tower.as_mut().map(Tower::finish).unwrap_or_default();
                            self.strokes(j.head, strokes, self.tower_height())?;
                        }
                    } else {
                        self.comment("no wipe tower at this height: the change is not purged");
                    }
                }
                if change.part > 0.0 {
                    self.comment(format!(
                        "transition: the next {} mm³ of beads take the change (their design allows it)",
                        num(change.part, 1)
                    ));
                    self.transition += change.part;
                }
            }
            let points: Vec<Point2> = j.path.points.iter().map(|p| p.p + offset).collect();
            let speed = match (j.path.points.first(), j.path.points.last()) {
                (Some(a), Some(b)) if b.t > a.t && j.path.length() > 0.0 => j.path.length() / (b.t - a.t),
                _ => DEFAULT_PRINT_SPEED,
            };
            let path = j.path;
            self.extrude_mixed(
                j.head,
                &points,
                &|i| path.segment_width(i),
                plan.thickness,
                speed,
                Feature::Part,
                &along[k],
            )?;
        }
        if tower_here && self.tower.as_ref().is_some_and(Tower::open) {
            let h = self.head.or(jobs.first().map(|j| j.head));
            if let Some(h) = h {
                let strokes = self.tower.as_mut().map(Tower::finish).unwrap_or_default();
                self.strokes(h, strokes, self.tower_height())?;
            }
        }
        self.planned += plan.build_time.unwrap_or(0.0);
        self.layers += 1;
        self.flush()
    }

    /// What the file deposits, by kind (mm³).
    fn deposit(&self) -> Deposit {
        let d = &self.deposited;
        Deposit {
            part: d[Feature::Part as usize],
            transition: self.transition,
            purge: d[Feature::Purge as usize],
            tower: d[Feature::Tower as usize],
            prime: d[Feature::Prime as usize],
            skirt: d[Feature::Skirt as usize],
        }
    }

    fn tower_height(&self) -> f64 {
        self.tower.as_ref().map_or(0.0, Tower::height)
    }

    /// The end: retraction, the end template, every heater off, and the summary with
    /// the time the file takes.
    pub fn finish_file(mut self: Box<Self>, info: &RunInfo) -> Result<MachineFileReport> {
        // No later layer purges on the tower: the waiting layers go without it.
        self.write_spooled(info, false)?;
        self.end_streams();
        self.retract(self.s.retraction.length);
        self.feature = None;
        if self.s.machine.is_some() {
            let end = self.render(&self.s.templates.end.clone(), None, self.z)?;
            self.template("end", &end)?;
        }
        let targets = self.fw.targets();
        let (heaters, bed) = targets.split_at(targets.len() - 1);
        for (h, t) in heaters.iter().enumerate() {
            if *t > 0.0 {
                let index = if self.s.flavor.is_mixing() {
                    self.s.heads[0].index
                } else {
                    h
                };
                self.line(crate::commands::heater_off(&self.s, index));
            }
        }
        if bed.first().is_some_and(|b| *b > 0.0) {
            self.line("M140 S0 ; bed off");
        }
        if self.fw.fan() > 0.0 {
            self.line("M107 ; fan off");
        }
        if self.s.machine.is_none() {
            self.line("M84 ; motors off");
        }
        if let Some(line) = self.fw.cold_extrusion() {
            return Err(Error::stage(
                crate::STAGE,
                format!(
                    "the file would move the extruder of a cold or unselected tool at `{line}`: \
                     check the machine's start and tool-change templates"
                ),
            ));
        }
        let time = self.fw.time();
        let names: Vec<String> = if self.s.flavor.is_mixing() {
            self.s
                .channel_names
                .iter()
                .map(|n| format!("channel {}", clean(n)))
                .collect()
        } else {
            self.s
                .heads
                .iter()
                .map(|h| format!("T{} {}", h.index, clean(&h.label)))
                .collect()
        };
        let area = self.s.filament_area();
        let mut t = String::new();
        let _ = writeln!(t, "; end: {} layers", self.layers);
        for (name, fed) in names.iter().zip(&self.fed) {
            let _ = writeln!(t, "; filament {name}: {fed:.3} mm ({:.1} mm³)", fed * area);
        }
        if self.multi.is_some() {
            t.push_str(&self.multi_footer());
        } else {
            let _ = writeln!(
                t,
                "; planned build time not stated: the {} flavor runs one tool at a time, so the file takes what it says below (the plan's {:.1} s times tools working together)",
                self.s.flavor.name(),
                self.planned
            );
        }
        let deposit = self.deposit();
        let _ = writeln!(
            t,
            "; deposited: part {:.1} mm³ (of which {:.1} mm³ transitions), purge {:.1}, tower {:.1}, prime {:.1}, skirt {:.1}; waste {:.1} % of all deposition",
            deposit.part,
            deposit.transition,
            deposit.purge,
            deposit.tower,
            deposit.prime,
            deposit.skirt,
            deposit.waste_share() * 100.0
        );
        if let Some(t2) = &self.tower {
            let _ = writeln!(t, "; wipe tower: {} levels", t2.levels());
        }
        let (heating, changes) = self.fw.waits();
        let _ = writeln!(
            t,
            "; of the time below: {heating:.1} s waiting for heaters, {changes:.1} s changing tools besides the moves"
        );
        let _ = writeln!(t, "; estimated printing time: {time:.1} s");
        self.buf.push_str(&t);
        self.flush()?;
        self.out.flush().map_err(|e| io(&self.path, e))?;
        Ok(MachineFileReport {
            file: self.path.clone(),
            time,
            part: deposit.part,
            transition: deposit.transition,
            waste: vec![
                ("purge".into(), deposit.purge),
                ("tower".into(), deposit.tower),
                ("prime".into(), deposit.prime),
                ("skirt".into(), deposit.skirt),
            ],
            ..MachineFileReport::default()
        })
    }
}

/// The bed's extent in words: `X 0 to 220, Y 0 to 220` or a circle's centre and radius.
fn bed_span(bed: &lamina_api::machine::Bed) -> String {
    let b = bed.bounds();
    match bed.shape {
        lamina_api::machine::BedShape::Rectangle { .. } => {
            format!("X {} to {}, Y {} to {}", b.min.x, b.max.x, b.min.y, b.max.y)
        }
        lamina_api::machine::BedShape::Circle { diameter } => format!(
            "a circle of radius {} about X {} Y {}",
            diameter / 2.0,
            b.center().x,
            b.center().y
        ),
    }
}

/// A mix in percent as fractions.
fn fractions(mix: &[u32]) -> Vec<f64> {
    mix.iter().map(|p| f64::from(*p) / 100.0).collect()
}

/// What a file deposits, by kind (mm³): the part (transitions that the part's beads
/// take included), and what is not part.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Deposit {
    pub part: f64,
    /// Of `part`: transitions after a change of tool or mix.
    pub transition: f64,
    pub purge: f64,
    pub tower: f64,
    pub prime: f64,
    pub skirt: f64,
}

impl Deposit {
    /// All that is deposited.
    pub fn total(&self) -> f64 {
        self.part + self.purge + self.tower + self.prime + self.skirt
    }

    /// What is not part, over all deposition (0 when nothing is deposited).
    pub fn waste_share(&self) -> f64 {
        let total = self.total();
        if total > 0.0 {
            (total - self.part) / total
        } else {
            0.0
        }
    }
}

/// What the header says about the run.
pub struct Header<'a> {
    pub pipeline: &'a str,
    pub layers: usize,
}

/// The machine of a run, for errors.
pub fn machine_error(machine: Option<&Machine>) -> impl Fn(String) -> Error + '_ {
    move |m| match machine {
        Some(machine) => machine.error(m),
        None => Error::stage(crate::STAGE, m),
    }
}
