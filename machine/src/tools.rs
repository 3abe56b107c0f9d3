//! The tool table of a machine profile: each tool's temperatures, axes, envelope and
//! home, and what several motion systems ask of the tools.

use std::collections::BTreeSet;

use super::check::Check;
use super::limits::{MAX_NOZZLE_TEMPERATURE, MAX_TRAVEL};
use super::raw::RawTool;
use super::*;
use lamina_api::error::Result;

/// The `[[tools]]` of a profile, checked.
pub(super) fn tools(raw_tools: Option<Vec<RawTool>>, flavor: Flavor, c: &Check<'_>) -> Result<Vec<ToolSlot>> {
    let raw_tools = c.required(
        raw_tools,
        "tools",
        "the tool table, one [[tools]] per tool or mixing channel",
    )?;
    if raw_tools.is_empty() {
        return Err(c.err("tools", "a machine has at least one tool"));
    }
    let mut tools = Vec::new();
    let mut seen = BTreeSet::new();
    for (i, t) in raw_tools.into_iter().enumerate() {
        let p = |k: &str| format!("tools.{i}.{k}");
        if let Some(m) = &t.material
            && !seen.insert(m.clone())
        {
            return Err(c.err(&p("material"), format!("`{m}` is carried by an earlier tool too")));
        }
        let nozzle = c.within(
            c.required(
                t.nozzle_temperature,
                &p("nozzle_temperature"),
                "the printing temperature (°C)",
            )?,
            1.0,
            MAX_NOZZLE_TEMPERATURE,
            &p("nozzle_temperature"),
            "°C",
        )?;
        let first = c.within(
            t.first_layer_temperature.unwrap_or(nozzle),
            1.0,
            MAX_NOZZLE_TEMPERATURE,
            &p("first_layer_temperature"),
            "°C",
        )?;
        let standby = t
            .standby_temperature
            .map(|s| {
                c.within(
                    s,
                    0.0,
                    nozzle.max(first),
                    &p("standby_temperature"),
                    "°C (at most the printing temperature)",
                )
            })
            .transpose()?;
        if flavor == Flavor::ToolChange && standby.is_none() {
            return Err(c.err(
                &p("standby_temperature"),
                "missing: the temperature the tool waits at while another prints (°C)",
            ));
        }
        if let Some(axis) = &t.axis
            && !(axis.len() == 1 && axis.chars().all(|ch| ch.is_ascii_uppercase()))
        {
            return Err(c.err(&p("axis"), format!("`{axis}` is not an axis letter (X, U, ...)")));
        }
        if let Some(axis) = &t.y_axis
            && !(axis.len() == 1 && axis.chars().all(|ch| ch.is_ascii_uppercase()))
        {
            return Err(c.err(
                &p("y_axis"),
                format!("`{axis}` is not an axis letter (Y, V, ...)"),
            ));
        }
        let envelope = t
            .envelope
            .map(|e| c.within(e, 0.1, 1_000.0, &p("envelope"), "mm"))
            .transpose()?;
        let travel = MAX_TRAVEL;
        let home = match t.home {
            Some([x, y]) if [x, y].iter().all(|v| v.abs() <= travel) => Some([x, y]),
            Some(_) => {
                return Err(c.err(
                    &p("home"),
                    format!("must be two numbers [x, y] within ±{travel} mm"),
                ));
            }
            None => None,
        };
        tools.push(ToolSlot {
            material: t.material,
            nozzle_temperature: nozzle,
            first_layer_temperature: first,
            standby_temperature: standby,
            name: t.name,
            axis: t.axis,
            y_axis: t.y_axis,
            home,
            envelope,
        });
    }

    Ok(tools)
}

/// Two motion systems: a RepRapFirmware tool changer whose two tools each have their
/// own X and Y axis letters and envelope.
pub(super) fn check_motion_systems(
    c: &Check<'_>,
    n: usize,
    firmware: Firmware,
    flavor: Flavor,
    tools: &[ToolSlot],
) -> Result<()> {
    match n {
        1 => return Ok(()),
        2 => {}
        _ => {
            return Err(c.err(
                "motion_systems",
                format!("must be 1 or 2 (RepRapFirmware 3.5 runs two), not {n}"),
            ));
        }
    }
    if firmware != Firmware::RepRapFirmware {
        return Err(c.err(
            "motion_systems",
            "several motion systems in one job are a RepRapFirmware 3.5 feature (M596): set firmware = \"reprapfirmware\"",
        ));
    }
    if flavor != Flavor::ToolChange || tools.len() != 2 {
        return Err(c.err(
            "motion_systems",
            format!(
                "two motion systems drive two tools of a tool-change machine, one each; this profile is {} with {} tools",
                flavor.name(),
                tools.len()
            ),
        ));
    }
    let mut letters: Vec<&str> = Vec::new();
    for (i, t) in tools.iter().enumerate() {
        let p = |k: &str| format!("tools.{i}.{k}");
        for (key, v) in [("axis", &t.axis), ("y_axis", &t.y_axis)] {
            let Some(v) = v else {
                return Err(c.err(
                    &p(key),
                    "missing: each motion system's head names its axis letters",
                ));
            };
            if ["Z", "E"].contains(&v.as_str()) || letters.contains(&v.as_str()) {
                return Err(c.err(
                    &p(key),
                    format!("`{v}` is not free: each head moves on axes of its own, Z is shared"),
                ));
            }
            letters.push(v);
        }
        if t.envelope.is_none() {
            return Err(c.err(
                &p("envelope"),
                "missing: the radius (mm) around the nozzle that the other head must keep out of",
            ));
        }
    }
    Ok(())
}
