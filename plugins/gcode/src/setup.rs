//! What the exporter writes for: the machine profile the pipeline names, or, without
//! one, a machine described by the exporter's own options (no homing, no bed, no
//! skirt or tower: what the exporter always wrote, made safe). Everything the writer
//! needs is resolved here once, with the pipeline's materials mapped to the machine's
//! tools or mixing channels.

use std::collections::BTreeMap;

use lamina_api::machine::{
    Bed, BedOrigin, Cornering, Fan, Firmware as Dialect, FirstLayerSpeed, Flavor, Machine, PrimeLine,
    Retraction, Skirt, Templates, WipeTower,
};
use lamina_api::{Error, Result, RunInfo};

use crate::motion::{Corner, Limits};
use crate::text::clean;

/// A heater-and-nozzle the firmware selects: a tool of a tool changer, or the one
/// nozzle of a mixing head.
#[derive(Debug, Clone)]
pub struct Head {
    /// The firmware's tool number.
    pub index: usize,
    /// For comments: what it carries, and its name on the machine.
    pub label: String,
    pub nozzle_temperature: f64,
    pub first_layer_temperature: f64,
    /// Where it waits while another head prints; `None`: it stays at temperature.
    pub standby_temperature: Option<f64>,
}

impl Head {
    /// The printing temperature of layer `index`.
    pub fn temperature(&self, layer: usize) -> f64 {
        if layer == 0 {
            self.first_layer_temperature
        } else {
            self.nozzle_temperature
        }
    }
}

/// A motion system of a machine that runs several (RepRapFirmware 3.5): the axis
/// letters of its head, the disc the other head keeps out of, and where homing leaves
/// it. System `n` drives head `n`.
#[derive(Debug, Clone)]
pub struct System {
    pub x: String,
    pub y: String,
    pub envelope: f64,
    pub home: Option<[f64; 2]>,
}

/// The exporter's own options, for a pipeline without a machine.
#[derive(Debug, Clone)]
pub struct OwnOptions {
    pub flavor: Flavor,
    pub filament_diameter: f64,
    pub temperature: f64,
    pub temperatures: BTreeMap<String, f64>,
    pub retract: f64,
    pub retract_speed: f64,
    pub channels: Option<Vec<String>>,
}

/// Everything the writer needs, resolved.
#[derive(Debug, Clone)]
pub struct Setup {
    pub flavor: Flavor,
    pub dialect: Dialect,
    /// The profile's name; `None` without a machine.
    pub machine: Option<String>,
    pub filament_diameter: f64,
    pub nozzle_diameter: f64,
    /// Thickest layer the machine lays (mm); none without a machine.
    pub max_layer_height: Option<f64>,
    pub relative_e: bool,
    pub direct_mixing: bool,
    pub virtual_tool: u32,
    /// Tool changers: one per firmware tool; mixing heads: the one nozzle.
    pub heads: Vec<Head>,
    /// Per pipeline material: its head (tool changers) or channel (mixing heads).
    pub slot_of: Vec<Option<usize>>,
    /// Mixing channels, with the material each carries.
    pub channel_names: Vec<String>,
    pub bed: Option<Bed>,
    pub bed_temperature: f64,
    pub first_layer_bed_temperature: f64,
    pub fan: Option<Fan>,
    pub first_layer_speed: Option<FirstLayerSpeed>,
    pub retraction: Retraction,
    pub travel_speed: f64,
    /// The motion settings the file sets and the time estimate uses.
    pub limits: Limits,
    /// Whether the file sets per-axis limits (the profile gives them).
    pub axis_limits: bool,
    pub skirt: Option<Skirt>,
    pub prime_line: Option<PrimeLine>,
    pub wipe_tower: Option<WipeTower>,
    /// Volume a mixing head purges after a change of mix (mm³).
    pub transition_volume: f64,
    /// Changes of mix smaller than this share are blended in place, not purged.
    pub blend_below: f64,
    /// A mixing head follows the compositions graded at points along each bead.
    pub mix_along: bool,
    /// Where the transition after a change of tool or mix goes.
    pub purge_into: crate::transition::PurgeInto,
    /// The heaters' rates and the tool changes' own time, for the time estimate.
    pub thermal: crate::firmware::Thermal,
    /// The motion systems when the machine runs two at once; `None`: one head at a time.
    pub systems: Option<Vec<System>>,
    /// How the heads move around each other, and the margin plans keep beyond their
    /// envelopes.
    pub kinematics: lamina_api::machine::Kinematics,
    pub templates: Templates,
    /// Whether the parts are placed by the machine (else moved only off negative
    /// coordinates).
    pub placed: bool,
}

/// Without a profile, RepRapFirmware's stock jerk (M566 X900 Y900 Z12 E120, mm/min).
const RRF_DEFAULT_JERK: [f64; 4] = [15.0, 15.0, 0.2, 2.0];

impl Setup {
    /// The setup for a machine profile.
    pub fn from_machine(
        m: &Machine,
        info: &RunInfo,
        relative_e: bool,
        direct_mixing: bool,
        virtual_tool: u32,
    ) -> Result<Setup> {
        let slot_of: Vec<Option<usize>> = info
            .materials
            .iter()
            .enumerate()
            .map(|(i, mat)| m.tool_of(&mat.name, i))
            .collect();
        check_materials_carried(info, &slot_of, || carried(m, info)).map_err(|e| m.error(e))?;
        let heads = machine_heads(m, info, &slot_of, virtual_tool);
        let channel_names = if m.flavor.is_mixing() {
            (0..m.tools.len()).map(|i| tool_label(m, info, i)).collect()
        } else {
            Vec::new()
        };
        let mo = &m.motion;
        let limits = machine_limits(m);
        Ok(Setup {
            flavor: m.flavor,
            dialect: m.firmware,
            machine: Some(m.name.clone()),
            filament_diameter: m.filament_diameter,
            nozzle_diameter: m.nozzle_diameter,
            max_layer_height: Some(m.max_layer_height),
            relative_e,
            direct_mixing,
            virtual_tool,
            heads,
            slot_of,
            channel_names,
            bed: Some(m.bed),
            bed_temperature: m.bed_temperature,
            first_layer_bed_temperature: m.first_layer_bed_temperature,
            fan: Some(m.fan),
            first_layer_speed: Some(m.first_layer.speed),
            // Z is one axis both motion systems share: no system may hop it while
            // the other prints.
            retraction: if m.motion_systems > 1 {
                lamina_api::machine::Retraction {
                    z_hop: 0.0,
                    ..m.retraction
                }
            } else {
                m.retraction
            },
            travel_speed: m.travel_speed,
            limits,
            axis_limits: mo.max_speed.is_some() || mo.max_acceleration.is_some(),
            // Two heads at work: no skirt, which would run between them.
            skirt: m.skirt.filter(|_| m.motion_systems < 2),
            prime_line: m.prime_line,
            wipe_tower: m.wipe_tower,
            transition_volume: m.mixer.map_or(0.0, |x| x.transition_volume),
            blend_below: m.mixer.map_or(0.0, |x| x.blend_below),
            mix_along: false,
            purge_into: crate::transition::PurgeInto::Part,
            thermal: crate::firmware::Thermal {
                heating: m.heating,
                tool_change_time: m.tool_change_time,
            },
            systems: (m.motion_systems > 1).then(|| {
                m.tools
                    .iter()
                    .map(|t| System {
                        x: t.axis.clone().unwrap_or_else(|| "X".into()),
                        y: t.y_axis.clone().unwrap_or_else(|| "Y".into()),
                        envelope: t.envelope.unwrap_or(0.0),
                        home: t.home,
                    })
                    .collect()
            }),
            kinematics: m.kinematics,
            templates: m.gcode.clone(),
            placed: true,
        })
    }

    /// The setup of a pipeline without a machine: the exporter's options.
    pub fn from_options(
        o: &OwnOptions,
        info: &RunInfo,
        relative_e: bool,
        direct_mixing: bool,
        virtual_tool: u32,
    ) -> Result<Setup> {
        let (slot_of, channel_names): (Vec<Option<usize>>, Vec<String>) = if o.flavor.is_mixing() {
            match &o.channels {
                Some(names) => {
                    let mut of = vec![None; info.materials.len()];
                    for (ch, n) in names.iter().enumerate() {
                        let m = info.materials.iter().position(|m| &m.name == n).ok_or_else(|| {
                            Error::stage(
                                crate::STAGE,
                                format!("channels: no material `{n}` in the pipeline"),
                            )
                        })?;
                        of[m] = Some(ch);
                    }
                    (of, names.clone())
                }
                None => (
                    (0..info.materials.len()).map(Some).collect(),
                    info.materials.iter().map(|m| m.name.clone()).collect(),
                ),
            }
        } else {
            ((0..info.materials.len()).map(Some).collect(), Vec::new())
        };
        check_materials_carried(info, &slot_of, || {
            format!("the `channels` option lists {}", channel_names.join(", "))
        })
        .map_err(|e| Error::stage(crate::STAGE, e))?;
        let dialect = match o.flavor {
            Flavor::ReprapMixing => Dialect::RepRapFirmware,
            _ => Dialect::Marlin,
        };
        let heads = if o.flavor.is_mixing() {
            vec![Head {
                index: mixing_tool(dialect, virtual_tool),
                label: "mixing head".into(),
                nozzle_temperature: o.temperature,
                first_layer_temperature: o.temperature,
                standby_temperature: None,
            }]
        } else {
            info.materials
                .iter()
                .enumerate()
                .map(|(i, m)| {
                    let t = o.temperatures.get(&m.name).copied().unwrap_or(o.temperature);
                    Head {
                        index: i,
                        label: m.name.clone(),
                        nozzle_temperature: t,
                        first_layer_temperature: t,
                        standby_temperature: None,
                    }
                })
                .collect()
        };
        let limits = match dialect {
            Dialect::Marlin => Limits::default(),
            Dialect::RepRapFirmware => Limits {
                corner: Corner::Jerk(RRF_DEFAULT_JERK),
                ..Limits::default()
            },
        };
        Ok(Setup {
            flavor: o.flavor,
            dialect,
            machine: None,
            filament_diameter: o.filament_diameter,
            nozzle_diameter: 0.4,
            max_layer_height: None,
            relative_e,
            direct_mixing,
            virtual_tool,
            heads,
            slot_of,
            channel_names,
            bed: None,
            bed_temperature: 0.0,
            first_layer_bed_temperature: 0.0,
            fan: None,
            first_layer_speed: None,
            retraction: Retraction {
                length: o.retract,
                tool_change_length: o.retract,
                speed: o.retract_speed,
                z_hop: 0.0,
            },
            travel_speed: 120.0,
            limits,
            axis_limits: false,
            skirt: None,
            prime_line: None,
            wipe_tower: None,
            transition_volume: 0.0,
            blend_below: 0.0,
            mix_along: false,
            purge_into: crate::transition::PurgeInto::Part,
            thermal: crate::firmware::Thermal::typical(dialect),
            systems: None,
            kinematics: Default::default(),
            templates: Templates::default(),
            placed: false,
        })
    }

    /// Filament cross-section (mm²).
    pub fn filament_area(&self) -> f64 {
        std::f64::consts::PI * self.filament_diameter * self.filament_diameter / 4.0
    }

    /// Width of the lines the exporter adds itself (skirt, tower): a little wider than
    /// the nozzle, as slicers print them.
    pub fn line_width(&self) -> f64 {
        self.nozzle_diameter * 1.125
    }

    /// Heads (positions in [`Setup::heads`]) that carry a material some part uses, in
    /// firmware order.
    pub fn used_heads(&self, info: &RunInfo) -> Vec<usize> {
        if self.flavor.is_mixing() {
            return vec![0];
        }
        let mut used = used_slots(info, &self.slot_of);
        used.sort_unstable();
        used
    }

    /// Mixing channels that carry a material some part uses.
    pub fn used_channels(&self, info: &RunInfo) -> Vec<usize> {
        if !self.flavor.is_mixing() {
            return Vec::new();
        }
        let mut used = used_slots(info, &self.slot_of);
        used.sort_unstable();
        used
    }

    /// The bed's origin, for the header.
    pub fn origin_name(&self) -> &'static str {
        match self.bed.map(|b| b.origin) {
            Some(BedOrigin::Centre) => "centre",
            _ => "front-left",
        }
    }
}

/// What the machine's tools or mixing channels carry, for the error that names a
/// material none carries.
fn carried(m: &Machine, info: &RunInfo) -> String {
    let carried: Vec<String> = m
        .tools
        .iter()
        .enumerate()
        .map(|(i, t)| match &t.material {
            Some(name) => format!("tool {i}: {name}"),
            None => format!(
                "tool {i}: {}",
                info.materials.get(i).map_or("nothing", |mat| mat.name.as_str())
            ),
        })
        .collect();
    format!(
        "the machine `{}` has {} {} ({})",
        m.name,
        m.tools.len(),
        if m.flavor.is_mixing() {
            "mixing channels"
        } else {
            "tools"
        },
        carried.join(", ")
    )
}

/// For comments: the material tool `i` carries (its own, or the pipeline's material of
/// the same number), and the head's name on the machine.
fn tool_label(m: &Machine, info: &RunInfo, i: usize) -> String {
    let t = &m.tools[i];
    let material = t
        .material
        .clone()
        .or_else(|| info.materials.get(i).map(|x| x.name.clone()));
    match (material, &t.name) {
        (Some(mat), Some(name)) => format!("{mat} ({name} head)"),
        (Some(mat), None) => mat,
        (None, Some(name)) => format!("nothing ({name} head)"),
        (None, None) => "nothing".into(),
    }
}

/// The heads the firmware selects: a tool changer's tools, or a mixing head's one
/// nozzle, heated for the hottest channel the parts use.
fn machine_heads(m: &Machine, info: &RunInfo, slot_of: &[Option<usize>], virtual_tool: u32) -> Vec<Head> {
    if m.flavor.is_mixing() {
        // One heater: the hottest channel that carries a material the parts use.
        let used: Vec<usize> = used_slots(info, slot_of);
        let hottest = |f: fn(&lamina_api::machine::ToolSlot) -> f64| {
            used.iter().map(|&c| f(&m.tools[c])).fold(0.0, f64::max)
        };
        vec![Head {
            index: mixing_tool(m.firmware, virtual_tool),
            label: "mixing head".into(),
            nozzle_temperature: hottest(|t| t.nozzle_temperature),
            first_layer_temperature: hottest(|t| t.first_layer_temperature),
            standby_temperature: None,
        }]
    } else {
        (0..m.tools.len())
            .map(|i| Head {
                index: i,
                label: tool_label(m, info, i),
                nozzle_temperature: m.tools[i].nozzle_temperature,
                first_layer_temperature: m.tools[i].first_layer_temperature,
                standby_temperature: m.tools[i].standby_temperature,
            })
            .collect()
    }
}

/// The motion settings of the profile, as the file sets them and the time estimate
/// uses them: RepRapFirmware retracts at the print acceleration.
fn machine_limits(m: &Machine) -> Limits {
    let mo = &m.motion;
    Limits {
        print: mo.print_acceleration,
        travel: mo.travel_acceleration,
        retract: if m.firmware == Dialect::RepRapFirmware {
            mo.print_acceleration
        } else {
            mo.retract_acceleration
        },
        corner: match mo.cornering {
            Cornering::JunctionDeviation(d) => Corner::JunctionDeviation(d),
            Cornering::Jerk(j) => Corner::Jerk(j.as_array()),
        },
        max_speed: mo.max_speed.map_or([f64::INFINITY; 4], |a| a.as_array()),
        max_acceleration: mo.max_acceleration.map_or([f64::INFINITY; 4], |a| a.as_array()),
    }
}

/// The firmware tool of a mixing head: Marlin stores mixes in a virtual tool, a
/// RepRapFirmware mixing tool is the tool 0 the exporter defines with `M563`.
fn mixing_tool(dialect: Dialect, virtual_tool: u32) -> usize {
    match dialect {
        Dialect::Marlin => virtual_tool as usize,
        Dialect::RepRapFirmware => 0,
    }
}

/// Slots (heads or channels) that carry a material of some part, without repeats.
fn used_slots(info: &RunInfo, slot_of: &[Option<usize>]) -> Vec<usize> {
    let mut used = Vec::new();
    for p in &info.parts {
        for &m in &p.materials {
            if let Some(Some(s)) = slot_of.get(m)
                && !used.contains(s)
            {
                used.push(*s);
            }
        }
    }
    used
}

/// Every material a part uses must be carried by a tool or channel.
fn check_materials_carried(
    info: &RunInfo,
    slot_of: &[Option<usize>],
    describe: impl Fn() -> String,
) -> std::result::Result<(), String> {
    for p in &info.parts {
        for &m in &p.materials {
            if slot_of.get(m).copied().flatten().is_none() {
                let name = info.materials.get(m).map_or("?", |x| x.name.as_str());
                return Err(format!(
                    "part `{}` uses material `{name}`, which no tool carries: {}",
                    clean(&p.name),
                    describe()
                ));
            }
        }
    }
    Ok(())
}
