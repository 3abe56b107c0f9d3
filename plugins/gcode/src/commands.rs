//! The commands that differ between firmwares and flavours: temperatures, fan, motion
//! settings and mixes. Marlin takes speeds in mm/s and sets temperatures per tool with
//! `M104 T`; RepRapFirmware takes speeds and jerk in mm/min and gives each tool an
//! active and a standby temperature with `G10`, switching between them itself when
//! tools change.

use lamina_api::machine::{Firmware as Dialect, Flavor};

use crate::motion::Corner;
use crate::setup::Setup;
use crate::text::num;

/// The axis letters of `M165`, one per mixing channel, in Marlin's order.
pub const M165_AXES: [char; 6] = ['A', 'B', 'C', 'D', 'H', 'I'];

/// The print and travel accelerations (`M204`). RepRapFirmware 3.5 keeps them per
/// motion system: a job on two writes them again in each system's stream.
pub fn accelerations(s: &Setup) -> String {
    let l = &s.limits;
    match s.dialect {
        Dialect::Marlin => format!(
            "M204 P{} R{} T{} ; print, retract and travel accelerations (mm/s²)",
            num(l.print, 0),
            num(l.retract, 0),
            num(l.travel, 0)
        ),
        Dialect::RepRapFirmware => format!(
            "M204 P{} T{} ; print and travel accelerations (mm/s²)",
            num(l.print, 0),
            num(l.travel, 0)
        ),
    }
}

/// Motion settings at the start of the file, so the firmware runs with the ones the
/// time estimate assumes and a replay can read them.
pub fn motion(s: &Setup) -> Vec<String> {
    let l = &s.limits;
    let per_minute = if s.dialect == Dialect::RepRapFirmware {
        60.0
    } else {
        1.0
    };
    // Axis settings are per axis: the heads of other motion systems (their own X and Y
    // letters, U and V say) take the same as X and Y, or they would run at the
    // firmware's defaults.
    let others: Vec<(&str, &str)> = s
        .systems
        .iter()
        .flatten()
        .filter(|m| m.x != "X" || m.y != "Y")
        .map(|m| (m.x.as_str(), m.y.as_str()))
        .collect();
    let axes = |v: [f64; 4], scale: f64| {
        let mut t = format!("X{} Y{}", num(v[0] * scale, 2), num(v[1] * scale, 2));
        for (x, y) in &others {
            t.push_str(&format!(
                " {x}{} {y}{}",
                num(v[0] * scale, 2),
                num(v[1] * scale, 2)
            ));
        }
        t.push_str(&format!(" Z{} E{}", num(v[2] * scale, 2), num(v[3] * scale, 2)));
        t
    };
    let mut out = Vec::new();
    if s.axis_limits {
        if l.max_acceleration.iter().all(|v| v.is_finite()) {
            out.push(format!(
                "M201 {} ; axis accelerations (mm/s²)",
                axes(l.max_acceleration, 1.0)
            ));
        }
        if l.max_speed.iter().all(|v| v.is_finite()) {
            let unit = if per_minute > 1.0 { "mm/min" } else { "mm/s" };
            out.push(format!(
                "M203 {} ; axis speeds ({unit})",
                axes(l.max_speed, per_minute)
            ));
        }
    }
    out.push(accelerations(s));
    match (s.dialect, l.corner) {
        (Dialect::Marlin, Corner::JunctionDeviation(j)) => {
            out.push(format!("M205 J{} ; junction deviation (mm)", num(j, 4)))
        }
        (Dialect::Marlin, Corner::Jerk(j)) => out.push(format!("M205 {} ; jerk (mm/s)", axes(j, 1.0))),
        (Dialect::RepRapFirmware, Corner::Jerk(j)) => {
            out.push(format!("M566 {} ; jerk (mm/min)", axes(j, 60.0)))
        }
        // The profile check refuses junction deviation on RepRapFirmware.
        (Dialect::RepRapFirmware, Corner::JunctionDeviation(_)) => {}
    }
    out
}

/// Sets a tool's temperature without waiting (Marlin).
pub fn set_temperature(s: &Setup, tool: usize, t: f64) -> String {
    if s.flavor.is_mixing() {
        format!("M104 S{}", num(t, 0))
    } else {
        format!("M104 T{tool} S{}", num(t, 0))
    }
}

/// A RepRapFirmware tool's active and standby temperatures.
pub fn rrf_tool_temperatures(tool: usize, active: f64, standby: Option<f64>) -> String {
    format!(
        "G10 P{tool} S{} R{}",
        num(active, 0),
        num(standby.unwrap_or(active), 0)
    )
}

/// Turns a tool's heater off.
pub fn heater_off(s: &Setup, tool: usize) -> String {
    match (s.dialect, s.flavor) {
        (Dialect::RepRapFirmware, _) => format!("G10 P{tool} S0 R0 ; heater off"),
        (Dialect::Marlin, Flavor::ToolChange) => format!("M104 T{tool} S0 ; heater off"),
        (Dialect::Marlin, _) => "M104 S0 ; heater off".to_string(),
    }
}

/// The part-cooling fan at `f` (0 to 1).
pub fn fan(s: &Setup, f: f64) -> String {
    if f <= 0.0 {
        return "M107".to_string();
    }
    match s.dialect {
        Dialect::Marlin => format!("M106 S{}", (f * 255.0).round().clamp(1.0, 255.0)),
        Dialect::RepRapFirmware => format!("M106 S{}", num(f, 2)),
    }
}

/// Sets a mixing head's mix (percentages per channel).
pub fn mix(s: &Setup, mix: &[u32]) -> Vec<String> {
    let fraction = |p: u32| format!("{:.2}", f64::from(p) / 100.0);
    match s.flavor {
        Flavor::MarlinMixing if s.direct_mixing => {
            let words: Vec<String> = mix
                .iter()
                .zip(M165_AXES)
                .map(|(p, a)| format!("{a}{}", fraction(*p)))
                .collect();
            vec![format!("M165 {}", words.join(" "))]
        }
        Flavor::MarlinMixing => {
            let mut out: Vec<String> = mix
                .iter()
                .enumerate()
                .map(|(ch, p)| format!("M163 S{ch} P{}", fraction(*p)))
                .collect();
            out.push(format!("M164 S{}", s.virtual_tool));
            out
        }
        Flavor::ReprapMixing => {
            let r: Vec<String> = mix.iter().map(|p| fraction(*p)).collect();
            vec![format!("M567 P0 E{}", r.join(":"))]
        }
        Flavor::ToolChange => Vec::new(),
    }
}
