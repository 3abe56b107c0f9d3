//! A merged machine profile's values, checked and turned into a [`Machine`]: the bed,
//! temperatures, fan, first layer, retraction, motion, skirt, prime line, wipe tower,
//! mixer, G-code templates; the tools in [`super::tools`].

use super::check::Check;
use super::limits::{
    MAX_ACCELERATION, MAX_BED_TEMPERATURE, MAX_JERK, MAX_SPEED, MAX_TRAVEL, MIN_ACCELERATION, MIN_SPEED,
};
use super::raw::{
    RawAxes, RawBed, RawFan, RawFirstLayer, RawHeating, RawMachine, RawMixer, RawMotion, RawPlacement,
    RawPrimeLine, RawRetraction, RawShape, RawSkirt, RawTemplates, RawWipeTower, Switch,
};
use super::template::TemplateKind;
use super::tools::{check_motion_systems, tools};
use super::*;
use lamina_api::error::Result;

pub(super) fn validate(raw: RawMachine, c: &Check<'_>) -> Result<Machine> {
    let name = profile_name(raw.name, c)?;
    let flavor = c.required(
        raw.flavor,
        "flavor",
        "how the firmware changes material: \"tool-change\", \"marlin-mixing\" or \"reprap-mixing\"",
    )?;
    let firmware = firmware(flavor, raw.firmware, c)?;
    let bed = bed(raw.bed, c)?;
    let placement = placement(raw.placement, &bed, c)?;

    let nozzle_diameter = c.within(
        raw.nozzle_diameter.unwrap_or(0.4),
        0.05,
        3.0,
        "nozzle_diameter",
        "mm",
    )?;
    let filament_diameter = c.within(
        raw.filament_diameter.unwrap_or(1.75),
        0.5,
        5.0,
        "filament_diameter",
        "mm",
    )?;
    let (bed_temperature, first_layer_bed_temperature) =
        bed_temperatures(raw.bed_temperature, raw.first_layer_bed_temperature, c)?;

    let tools = tools(raw.tools, flavor, c)?;
    let fan = fan(raw.fan.unwrap_or_default(), c)?;
    let max_layer_height = c.within(
        raw.max_layer_height.unwrap_or(0.75 * nozzle_diameter),
        0.01,
        nozzle_diameter,
        "max_layer_height",
        "mm (at most the nozzle's bore)",
    )?;
    let first_layer = first_layer(raw.first_layer.unwrap_or_default(), max_layer_height, c)?;
    let retraction = retraction(raw.retraction.unwrap_or_default(), c)?;
    let travel_speed = c.within(
        raw.travel_speed.unwrap_or(150.0),
        MIN_SPEED,
        MAX_SPEED,
        "travel_speed",
        "mm/s",
    )?;
    let motion = motion(raw.motion, firmware, c)?;
    let skirt = skirt(raw.skirt, c)?;
    let prime_line = prime_line(raw.prime_line, nozzle_diameter, c)?;
    let wipe_tower = wipe_tower(raw.wipe_tower, &bed, flavor, nozzle_diameter, c)?;
    let mixer = mixer(raw.mixer, flavor, wipe_tower.is_some(), c)?;
    let heating = heating(raw.heating.unwrap_or_default(), firmware, c)?;
    let tool_change_time = c.within(
        raw.tool_change_time.unwrap_or(0.0),
        0.0,
        600.0,
        "tool_change_time",
        "s",
    )?;
    let gcode = templates(raw.gcode.unwrap_or_default(), tools.len(), c)?;

    let motion_systems = raw.motion_systems.unwrap_or(1);
    check_motion_systems(c, motion_systems, firmware, flavor, &tools)?;
    let kinematics = kinematics(c, raw.kinematics, motion_systems, &tools)?;
    Ok(Machine {
        name,
        motion_systems,
        description: raw.description.unwrap_or_default(),
        flavor,
        firmware,
        bed,
        placement,
        nozzle_diameter,
        max_layer_height,
        filament_diameter,
        tools,
        bed_temperature,
        first_layer_bed_temperature,
        fan,
        first_layer,
        retraction,
        travel_speed,
        motion,
        skirt,
        prime_line,
        wipe_tower,
        mixer,
        heating,
        kinematics,
        tool_change_time,
        gcode,
        origin: MachineOrigin::default(),
    })
}

/// The profile's name, which may not be blank.
fn profile_name(name: Option<String>, c: &Check<'_>) -> Result<String> {
    let name = c.required(name, "name", "the profile's name")?;
    if name.trim().is_empty() {
        return Err(c.err("name", "must not be empty"));
    }
    Ok(name)
}

/// The firmware the profile names, or the one its flavor implies; a mixing flavor
/// belongs to one firmware only.
fn firmware(flavor: Flavor, named: Option<Firmware>, c: &Check<'_>) -> Result<Firmware> {
    Ok(match (flavor, named) {
        (Flavor::MarlinMixing, Some(Firmware::RepRapFirmware))
        | (Flavor::ReprapMixing, Some(Firmware::Marlin)) => {
            return Err(c.err(
                "firmware",
                format!("the `{}` flavor is for another firmware", flavor.name()),
            ));
        }
        (_, Some(f)) => f,
        (Flavor::ReprapMixing, None) => Firmware::RepRapFirmware,
        (_, None) => Firmware::Marlin,
    })
}

/// The `[bed]`: a rectangle or a circle (never both), where its origin lies, and how
/// high the machine builds.
fn bed(raw_bed: Option<RawBed>, c: &Check<'_>) -> Result<Bed> {
    let raw_bed = c.required(raw_bed, "bed", "the [bed] table (size or diameter, max_height)")?;
    let shape = match (raw_bed.shape, raw_bed.size, raw_bed.diameter) {
        (Some(RawShape::Circle), Some(_), _)
        | (Some(RawShape::Rectangle), _, Some(_))
        | (None, Some(_), Some(_)) => {
            return Err(c.err(
                "bed",
                "a rectangular bed has `size = [x, y]`, a circular one `diameter`: give one",
            ));
        }
        (Some(RawShape::Rectangle) | None, Some(size), None) => {
            c.within(size[0], 1.0, MAX_TRAVEL, "bed.size", "mm")?;
            c.within(size[1], 1.0, MAX_TRAVEL, "bed.size", "mm")?;
            BedShape::Rectangle { size }
        }
        (Some(RawShape::Circle) | None, None, Some(d)) => BedShape::Circle {
            diameter: c.within(d, 1.0, MAX_TRAVEL, "bed.diameter", "mm")?,
        },
        (_, None, None) => {
            return Err(c.err(
                "bed.size",
                "missing: `size = [x, y]` (mm), or `diameter` for a round bed",
            ));
        }
    };
    let origin = raw_bed.origin.unwrap_or(match shape {
        BedShape::Rectangle { .. } => BedOrigin::FrontLeft,
        BedShape::Circle { .. } => BedOrigin::Centre,
    });
    let max_height = c.within(
        c.required(
            raw_bed.max_height,
            "bed.max_height",
            "how high the machine builds (mm)",
        )?,
        1.0,
        MAX_TRAVEL,
        "bed.max_height",
        "mm",
    )?;
    Ok(Bed {
        shape,
        origin,
        max_height,
    })
}

/// Where the parts go: the bed's centre, or a point that must be on the bed.
fn placement(raw: Option<RawPlacement>, bed: &Bed, c: &Check<'_>) -> Result<BedPlacement> {
    Ok(match raw.unwrap_or(RawPlacement::Centre) {
        RawPlacement::Centre => BedPlacement::Centre,
        RawPlacement::At(p) => {
            if !bed.contains(Point2::new(p[0], p[1]), 0.0) {
                return Err(c.err(
                    "placement",
                    format!("[{}, {}] is not on the {} bed", p[0], p[1], bed.describe()),
                ));
            }
            BedPlacement::At(p)
        }
    })
}

/// The bed's temperature while printing and on the first layer (that of the others
/// unless given), 0 for an unheated bed.
fn bed_temperatures(printing: Option<f64>, first_layer: Option<f64>, c: &Check<'_>) -> Result<(f64, f64)> {
    let bed_temperature = c.within(
        printing.unwrap_or(0.0),
        0.0,
        MAX_BED_TEMPERATURE,
        "bed_temperature",
        "°C",
    )?;
    let first_layer_bed_temperature = c.within(
        first_layer.unwrap_or(bed_temperature),
        0.0,
        MAX_BED_TEMPERATURE,
        "first_layer_bed_temperature",
        "°C",
    )?;
    Ok((bed_temperature, first_layer_bed_temperature))
}

/// The `[fan]`: its speed (%), and from which layer it runs.
fn fan(raw_fan: RawFan, c: &Check<'_>) -> Result<Fan> {
    Ok(Fan {
        speed: c.within(raw_fan.speed.unwrap_or(100.0), 0.0, 100.0, "fan.speed", "%")?,
        first_layer: raw_fan.first_layer.unwrap_or(false),
        full_speed_layer: raw_fan.full_speed_layer.unwrap_or(1),
    })
}

/// The `[first_layer]`: its height (at most `max_layer_height`) and its speed, given
/// in mm/s or as a factor of the planned speed, not both.
fn first_layer(raw_first: RawFirstLayer, max_layer_height: f64, c: &Check<'_>) -> Result<FirstLayer> {
    Ok(FirstLayer {
        height: raw_first
            .height
            .map(|h| {
                c.within(
                    h,
                    0.01,
                    max_layer_height,
                    "first_layer.height",
                    "mm (at most max_layer_height)",
                )
            })
            .transpose()?,
        speed: match (raw_first.speed, raw_first.speed_factor) {
            (Some(_), Some(_)) => {
                return Err(c.err("first_layer", "give `speed` (mm/s) or `speed_factor`, not both"));
            }
            (Some(s), None) => {
                FirstLayerSpeed::Speed(c.within(s, MIN_SPEED, MAX_SPEED, "first_layer.speed", "mm/s")?)
            }
            (None, Some(f)) => {
                FirstLayerSpeed::Factor(c.within(f, 0.05, 1.0, "first_layer.speed_factor", "")?)
            }
            (None, None) => FirstLayerSpeed::Factor(0.5),
        },
    })
}

/// The `[retraction]`: how far and fast the filament is pulled back, further at a tool
/// change, and the Z hop over travels.
fn retraction(raw_retraction: RawRetraction, c: &Check<'_>) -> Result<Retraction> {
    let length = c.within(
        raw_retraction.length.unwrap_or(1.0),
        0.0,
        30.0,
        "retraction.length",
        "mm",
    )?;
    Ok(Retraction {
        length,
        tool_change_length: c.within(
            raw_retraction.tool_change_length.unwrap_or(length),
            0.0,
            100.0,
            "retraction.tool_change_length",
            "mm",
        )?,
        speed: c.within(
            raw_retraction.speed.unwrap_or(35.0),
            MIN_SPEED,
            MAX_SPEED,
            "retraction.speed",
            "mm/s",
        )?,
        z_hop: c.within(
            raw_retraction.z_hop.unwrap_or(0.0),
            0.0,
            10.0,
            "retraction.z_hop",
            "mm",
        )?,
    })
}

/// The `[motion]`: accelerations, how the firmware corners, and the optional per-axis
/// limits.
fn motion(raw_motion: Option<RawMotion>, firmware: Firmware, c: &Check<'_>) -> Result<Motion> {
    let raw_motion = c.required(
        raw_motion,
        "motion",
        "the [motion] table (accelerations, junction_deviation or jerk)",
    )?;
    let acceleration = |v: f64, key: &str| c.within(v, MIN_ACCELERATION, MAX_ACCELERATION, key, "mm/s²");
    let print_acceleration = acceleration(
        c.required(
            raw_motion.print_acceleration,
            "motion.print_acceleration",
            "mm/s²",
        )?,
        "motion.print_acceleration",
    )?;
    let cornering = cornering(raw_motion.junction_deviation, raw_motion.jerk, firmware, c)?;
    Ok(Motion {
        print_acceleration,
        travel_acceleration: acceleration(
            raw_motion.travel_acceleration.unwrap_or(print_acceleration),
            "motion.travel_acceleration",
        )?,
        retract_acceleration: acceleration(
            raw_motion.retract_acceleration.unwrap_or(print_acceleration),
            "motion.retract_acceleration",
        )?,
        cornering,
        max_speed: raw_motion
            .max_speed
            .map(|a| c.axes(a, "motion.max_speed", MIN_SPEED, MAX_SPEED, "mm/s"))
            .transpose()?,
        max_acceleration: raw_motion
            .max_acceleration
            .map(|a| {
                c.axes(
                    a,
                    "motion.max_acceleration",
                    MIN_ACCELERATION,
                    MAX_ACCELERATION,
                    "mm/s²",
                )
            })
            .transpose()?,
    })
}

/// How the firmware corners: Marlin by junction deviation or jerk, RepRapFirmware by
/// jerk only.
fn cornering(
    junction_deviation: Option<f64>,
    jerk: Option<RawAxes>,
    firmware: Firmware,
    c: &Check<'_>,
) -> Result<Cornering> {
    Ok(match (junction_deviation, jerk) {
        (Some(_), Some(_)) => {
            return Err(c.err("motion", "give `junction_deviation` or `jerk`, not both"));
        }
        (Some(_), None) if firmware == Firmware::RepRapFirmware => {
            return Err(c.err(
                "motion.junction_deviation",
                "RepRapFirmware corners by jerk (M566): give `jerk = { x, y, z, e }` (mm/s)",
            ));
        }
        (Some(jd), None) => {
            Cornering::JunctionDeviation(c.within(jd, 0.001, 1.0, "motion.junction_deviation", "mm")?)
        }
        (None, Some(j)) => Cornering::Jerk(c.axes(j, "motion.jerk", MIN_SPEED, MAX_JERK, "mm/s")?),
        (None, None) => {
            return Err(c.err(
                "motion.junction_deviation",
                "missing: how the firmware corners, `junction_deviation` (Marlin) or `jerk = { x, y, z, e }`",
            ));
        }
    })
}

/// The `[skirt]`, if any: at least one loop on at least one layer.
fn skirt(raw: Option<Switch<RawSkirt>>, c: &Check<'_>) -> Result<Option<Skirt>> {
    Ok(match raw {
        None | Some(Switch::Off) => None,
        Some(Switch::On) => {
            return Err(c.err(
                "skirt",
                "`true` needs a base profile's [skirt], or give the table",
            ));
        }
        Some(Switch::Table(s)) => {
            let loops = s.loops.unwrap_or(1);
            if loops == 0 {
                return Err(c.err("skirt.loops", "at least one loop (or `skirt = false`)"));
            }
            let layers = s.layers.unwrap_or(1);
            if layers == 0 {
                return Err(c.err("skirt.layers", "at least one layer (or `skirt = false`)"));
            }
            Some(Skirt {
                loops,
                distance: c.within(s.distance.unwrap_or(3.0), 0.0, 100.0, "skirt.distance", "mm")?,
                layers,
            })
        }
    })
}

/// The `[prime_line]`, if any: its length, and a width the nozzle can lay.
fn prime_line(
    raw: Option<Switch<RawPrimeLine>>,
    nozzle_diameter: f64,
    c: &Check<'_>,
) -> Result<Option<PrimeLine>> {
    Ok(match raw {
        None | Some(Switch::Off) => None,
        Some(Switch::On) => {
            return Err(c.err(
                "prime_line",
                "`true` needs a base profile's [prime_line], or give the table",
            ));
        }
        Some(Switch::Table(p)) => Some(PrimeLine {
            length: c.within(
                c.required(p.length, "prime_line.length", "mm")?,
                1.0,
                MAX_TRAVEL,
                "prime_line.length",
                "mm",
            )?,
            width: c.within(
                p.width.unwrap_or(nozzle_diameter * 1.5),
                nozzle_diameter * 0.5,
                nozzle_diameter * 3.0,
                "prime_line.width",
                "mm",
            )?,
        }),
    })
}

/// The `[wipe_tower]`, if any: a footprint wide enough for a few beads, on the bed
/// where it is placed, and the volume purged after a tool change (a mixing head's
/// purge is the mixer's).
fn wipe_tower(
    raw: Option<Switch<RawWipeTower>>,
    bed: &Bed,
    flavor: Flavor,
    nozzle_diameter: f64,
    c: &Check<'_>,
) -> Result<Option<WipeTower>> {
    let w = match raw {
        None | Some(Switch::Off) => return Ok(None),
        Some(Switch::On) => {
            return Err(c.err(
                "wipe_tower",
                "`true` needs a base profile's [wipe_tower], or give the table",
            ));
        }
        Some(Switch::Table(w)) => w,
    };
    let size = c.required(w.size, "wipe_tower.size", "the footprint [x, y] (mm)")?;
    let min = 6.0 * nozzle_diameter;
    c.within(size[0], min, 1000.0, "wipe_tower.size", "mm")?;
    c.within(size[1], min, 1000.0, "wipe_tower.size", "mm")?;
    if let Some(p) = w.position {
        let b = BBox2 {
            min: Point2::new(p[0], p[1]),
            max: Point2::new(p[0] + size[0], p[1] + size[1]),
        };
        if !bed.contains_box(&b, 0.0) {
            return Err(c.err(
                "wipe_tower.position",
                format!(
                    "a {} x {} mm tower at [{}, {}] is not on the {} bed",
                    size[0],
                    size[1],
                    p[0],
                    p[1],
                    bed.describe()
                ),
            ));
        }
    }
    Ok(Some(WipeTower {
        position: w.position,
        size,
        purge_volume: match (flavor.is_mixing(), w.purge_volume) {
            (true, Some(_)) => {
                return Err(c.err(
                    "wipe_tower.purge_volume",
                    "a mixing head purges `mixer.transition_volume` after each mix change; remove this key",
                ));
            }
            (true, None) => 0.0,
            (false, v) => c.within(
                c.required(v, "wipe_tower.purge_volume", "mm³ purged after each tool change")?,
                0.0,
                10_000.0,
                "wipe_tower.purge_volume",
                "mm³",
            )?,
        },
    }))
}

/// The `[mixer]`, which a mixing flavor needs and no other has: the volume of a mix
/// change's transition (purged on the wipe tower, so there must be one) and the change
/// below which beads blend in place.
fn mixer(
    raw: Option<RawMixer>,
    flavor: Flavor,
    has_wipe_tower: bool,
    c: &Check<'_>,
) -> Result<Option<Mixer>> {
    Ok(match (flavor.is_mixing(), raw) {
        (true, Some(m)) => {
            let transition_volume = c.within(
                c.required(
                    m.transition_volume,
                    "mixer.transition_volume",
                    "mm³ purged after a mix change",
                )?,
                0.0,
                10_000.0,
                "mixer.transition_volume",
                "mm³",
            )?;
            if transition_volume > 0.0 && !has_wipe_tower {
                return Err(c.err(
                    "mixer.transition_volume",
                    "the transition is purged on the wipe tower: add a [wipe_tower] with its size",
                ));
            }
            let blend_below = c.within(m.blend_below.unwrap_or(0.0), 0.0, 1.0, "mixer.blend_below", "")?;
            Some(Mixer {
                transition_volume,
                blend_below,
            })
        }
        (true, None) => {
            return Err(c.err(
                "mixer",
                "missing: a mixing head's [mixer] with transition_volume (mm³ purged after a mix change)",
            ));
        }
        (false, Some(_)) => return Err(c.err("mixer", "only a mixing flavor has a mixer")),
        (false, None) => None,
    })
}

/// The `[heating]` rates and waits, each defaulting to what is typical of the firmware.
fn heating(raw_heating: RawHeating, firmware: Firmware, c: &Check<'_>) -> Result<Heating> {
    let typical = Heating::typical(firmware);
    let rate = |v: Option<f64>, d: f64, key: &str| c.within(v.unwrap_or(d), 0.01, 100.0, key, "°C/s");
    let wait = |v: Option<f64>, d: f64, key: &str| c.within(v.unwrap_or(d), 0.0, 600.0, key, "s");
    Ok(Heating {
        nozzle_rate: rate(
            raw_heating.nozzle_rate,
            typical.nozzle_rate,
            "heating.nozzle_rate",
        )?,
        nozzle_cooling: rate(
            raw_heating.nozzle_cooling,
            typical.nozzle_cooling,
            "heating.nozzle_cooling",
        )?,
        bed_rate: rate(raw_heating.bed_rate, typical.bed_rate, "heating.bed_rate")?,
        residency: wait(raw_heating.residency, typical.residency, "heating.residency")?,
        bed_residency: wait(
            raw_heating.bed_residency,
            typical.bed_residency,
            "heating.bed_residency",
        )?,
    })
}

/// The `[gcode]` templates, each checked for the variables its place knows of `n`
/// tools; a tool change selects the next tool unless the profile says otherwise.
fn templates(raw_gcode: RawTemplates, n: usize, c: &Check<'_>) -> Result<Templates> {
    Ok(Templates {
        start: c.template(raw_gcode.start, "gcode.start", TemplateKind::Start, n)?,
        end: c.template(raw_gcode.end, "gcode.end", TemplateKind::End, n)?,
        tool_change: c.template(
            raw_gcode.tool_change.or_else(|| Some("T{next_tool}".into())),
            "gcode.tool_change",
            TemplateKind::ToolChange,
            n,
        )?,
    })
}

/// The heads' kinematics class and margin. Two gantries need heads homing at
/// different Y (their order); one beam cannot carry two motion systems (they would
/// share its Y).
fn kinematics(
    c: &Check<'_>,
    raw: Option<super::raw::RawKinematics>,
    motion_systems: usize,
    tools: &[ToolSlot],
) -> Result<Kinematics> {
    let raw = raw.unwrap_or_default();
    let class = raw.class.unwrap_or_default();
    let margin = c.within(raw.margin.unwrap_or(1.0), 0.0, 100.0, "kinematics.margin", "mm")?;
    match class {
        HeadClass::DualGantry if motion_systems == 2 => {
            let ys: Vec<Option<f64>> = tools.iter().map(|t| t.home.map(|h| h[1])).collect();
            match ys[..] {
                [Some(a), Some(b)] if (a - b).abs() > 1e-9 => {}
                _ => {
                    return Err(c.err(
                        "kinematics.class",
                        "two gantries keep their heads in Y order: give each tool a `home` with its own Y \
                         (the head homing nearer Y = 0 is the front one)",
                    ));
                }
            }
        }
        HeadClass::SharedBeam if motion_systems > 1 => {
            return Err(c.err(
                "kinematics.class",
                "two carriages on one beam share its Y axis, so they cannot be two motion systems",
            ));
        }
        _ => {}
    }
    Ok(Kinematics { class, margin })
}
