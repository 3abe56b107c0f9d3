//! lamina-gcode: the `gcode` exporter. It writes the planned toolpaths as G-code for
//! one of three kinds of multi-material printer (`flavor`):
//!
//! - `tool-change`: one tool per material (T0, T1, ...), tool changers and IDEX
//!   machines; idle tools wait at their standby temperature and are heated again, with
//!   a wait, before they print;
//! - `marlin-mixing`: one mixing extruder; before each sub-region the mix is set with
//!   `M163 S<channel> P<fraction>` per channel and stored with `M164 S<virtual tool>`,
//!   or with one `M165 A.. B.. C..` when the firmware has DIRECT_MIXING;
//! - `reprap-mixing`: RepRapFirmware, a tool defined over several drives with `M563`
//!   and its mix set with `M567 P<tool> E<r1>:<r2>:...` per sub-region.
//!
//! With a machine profile (the pipeline's `machine`, see `lamina_api::machine`) the
//! file homes, heats the bed and the tools, places the parts on the bed, primes each
//! tool, prints a skirt, lets the part's next beads take the transition after a tool or
//! mix change where the design allows it and purges the rest on a wipe tower beside the
//! parts ([`transition`]), heats tools ahead of their change, runs the fan and slows the
//! first layer. Without one, the exporter's own
//! options describe the machine and the file holds only the parts.
//!
//! Extrusion follows the bead: E = segment length x width x layer height over the
//! filament cross-section. Firmwares drive one tool at a time, so each layer is written
//! tool by tool in the planned order of each tool's paths; the planned travels and
//! pauses coordinate tools that move together and have no meaning here (the timed paths
//! are in the JSON plan), so the file travels straight from one path to the next.
//!
//! Every line written passes through a model of the firmware ([`firmware`]): it tells
//! the writer which tool is selected and hot, and its motion planner ([`motion`]) gives
//! the time the file takes, written in the footer.

pub mod commands;
pub mod firmware;
pub mod layout;
mod mix_along;
pub mod motion;
pub mod setup;
mod solid;
mod stage_name;
pub mod text;
pub mod tower;
pub mod transition;
pub mod writer;

use std::collections::BTreeMap;
use std::path::PathBuf;

use lamina_api::stage::{
    AnyStage, ExportContext, Exporter, LayerSink, OutputFiles, StageConfig, StageInfo, StageKind,
};
use lamina_api::{Error, LayerPlan, Result, RunInfo, StageFactory};

pub use lamina_api::machine::Flavor;
pub use writer::percentages;

use crate::commands::M165_AXES;
use crate::setup::{OwnOptions, Setup};
use crate::writer::{Header, Writer};

// Every file of the crate names its errors after the stage as `crate::STAGE`.
use stage_name::STAGE;

/// Options a machine profile sets: a pipeline with a machine may not set them here.
const MACHINE_KEYS: &[(&str, &str)] = &[
    ("flavor", "its `flavor`"),
    ("filament_diameter", "its `filament_diameter`"),
    ("temperature", "each tool's `nozzle_temperature`"),
    ("temperatures", "each tool's `nozzle_temperature`"),
    ("retract", "`retraction.length`"),
    ("retract_speed", "`retraction.speed`"),
    ("channels", "each tool's `material` ([[machine.tools]])"),
];

lamina_api::stage_options! {
    #[derive(Debug, Clone)]
    struct Options {
        /// output file
        path: PathBuf = r#""plan.gcode""#,
        /// without a machine: `tool-change` (T0, T1, ...), `marlin-mixing` (M163/M164 or M165) or `reprap-mixing` (M563/M567)
        flavor: Flavor = r#""tool-change""#,
        /// without a machine: filament diameter (mm); E = length x width x height / cross-section
        #[range(0.1, 10.0)]
        filament_diameter: f64 = "1.75",
        /// relative extrusion (M83) instead of absolute (M82)
        relative_e: bool = "false",
        /// marlin-mixing: one M165 per mix instead of M163 per channel and M164
        direct_mixing: bool = "false",
        /// marlin-mixing: the virtual tool M164 stores the mix in
        #[range(0, 255)]
        virtual_tool: u32 = "0",
        /// without a machine: nozzle temperature (°C)
        #[range(1.0, 500.0)]
        temperature: f64 = "210.0",
        /// without a machine, tool-change: temperature per material name
        temperatures: BTreeMap<String, f64> = "{}",
        /// without a machine: retraction before travel and tool changes (mm of filament; 0: none)
        #[range(0.0, 100.0)]
        retract: f64 = "1.0",
        /// without a machine: retraction speed (mm/s)
        #[range(0.1, 1000.0)]
        retract_speed: f64 = "35.0",
        /// without a machine, mixing flavours: material of each channel, in channel order; unset: the pipeline's materials
        channels: Option<Vec<String>>,
        /// where the transition after a change of tool or mix goes: `part`, into the next beads as far as their design composition allows (a mixing head's beads stay within half their family's design step of their composition on average; a tool's own beads take its prime whole), the rest on the wipe tower; `tower`, all of it on the tower
        purge_into: crate::transition::PurgeInto = r#""part""#,
        /// mixing heads: change the mix along a bead to the composition graded nearest each segment (regions graded at points, grade `xy` with `r = "points"`; Eq. 18 at the bead), not one mix per sub-region
        mix_along: bool = "false",
    }
}

struct Gcode(Options);

/// Filament (mm of feed) for a bead of `length` x `width` x `height` mm.
pub fn filament_length(length: f64, width: f64, height: f64, filament_diameter: f64) -> f64 {
    let area = std::f64::consts::PI * filament_diameter * filament_diameter / 4.0;
    length * width * height / area
}

impl Options {
    fn own(&self) -> OwnOptions {
        OwnOptions {
            flavor: self.flavor,
            filament_diameter: self.filament_diameter,
            temperature: self.temperature,
            temperatures: self.temperatures.clone(),
            retract: self.retract,
            retract_speed: self.retract_speed,
            channels: self.channels.clone(),
        }
    }
}

impl Exporter for Gcode {
    fn open(&self, ctx: &mut ExportContext<'_>) -> Result<Box<dyn LayerSink>> {
        let o = &self.0;
        let info = ctx.info;
        let mut setup = match &info.machine {
            Some(m) => Setup::from_machine(m, info, o.relative_e, o.direct_mixing, o.virtual_tool)?,
            None => Setup::from_options(&o.own(), info, o.relative_e, o.direct_mixing, o.virtual_tool)?,
        };
        setup.mix_along = o.mix_along && setup.flavor.is_mixing();
        setup.purge_into = o.purge_into;
        if setup.flavor == Flavor::MarlinMixing
            && setup.direct_mixing
            && setup.channel_names.len() > M165_AXES.len()
        {
            return Err(Error::stage(
                STAGE,
                format!(
                    "M165 sets at most {} channels, the head has {}",
                    M165_AXES.len(),
                    setup.channel_names.len()
                ),
            ));
        }
        // Two motion systems never change tools: no tower, each head primes alone.
        let multi = setup.systems.is_some();
        let needs_tower = !multi
            && setup.wipe_tower.is_some()
            && if setup.flavor.is_mixing() {
                setup.transition_volume > 0.0 && setup.used_channels(info).len() >= 2
            } else {
                // A tool's own beads take its prime when the part may take it.
                setup.used_heads(info).len() >= 2 && setup.purge_into == transition::PurgeInto::Tower
            };
        let primed = match (setup.prime_line, setup.flavor.is_mixing()) {
            (None, _) => 0,
            (Some(_), true) => 1,
            (Some(_), false) if multi => 1,
            (Some(_), false) => setup.used_heads(info).len(),
        };
        let layout = layout::plan(
            &setup,
            info,
            &writer::machine_error(info.machine.as_ref()),
            needs_tower,
            primed,
        )?;
        let out = ctx.files.create(&o.path)?;
        let header = Header {
            pipeline: ctx.pipeline_name,
            layers: ctx.layer_count,
        };
        Ok(Box::new(Sink(Box::new(Writer::open(
            setup,
            info,
            layout,
            out,
            o.path.clone(),
            &header,
        )?))))
    }
}

struct Sink(Box<Writer>);

impl LayerSink for Sink {
    fn layer(&mut self, info: &RunInfo, plan: &LayerPlan, _files: &mut dyn OutputFiles) -> Result<()> {
        self.0.write_layer(info, plan)
    }

    fn finish(self: Box<Self>, info: &RunInfo, files: &mut dyn OutputFiles) -> Result<()> {
        let report = self.0.finish_file(info)?;
        files.report(report);
        Ok(())
    }
}

fn build(config: &StageConfig<'_>) -> Result<AnyStage> {
    let o: Options = config.parse()?;
    if let Some(m) = config.machine {
        for (key, what) in MACHINE_KEYS {
            if config.has(key) {
                return Err(config
                    .error(
                        key,
                        format!("the machine `{}` sets this: its profile gives {what}", m.name),
                    )
                    .with_help("change it in the pipeline's [machine] table, or remove it here"));
            }
        }
        if o.direct_mixing && m.flavor != Flavor::MarlinMixing {
            return Err(config.error(
                "direct_mixing",
                format!(
                    "only a `marlin-mixing` machine has M165; `{}` is {}",
                    m.name,
                    m.flavor.name()
                ),
            ));
        }
    }
    if o.direct_mixing && config.machine.is_none() && o.flavor != Flavor::MarlinMixing {
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

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Export,
        name: "gcode",
        doc: "G-code of the planned toolpaths for tool-change, Marlin mixing or RepRapFirmware mixing machines; with a `machine` profile, a complete print (homing, heating, placement, prime lines, skirt, wipe tower, fan) and its estimated time.",
        options: Options::SPECS,
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
