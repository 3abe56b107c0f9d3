//! What the firmware makes of the lines the exporter writes: positions and modes, the
//! selected tool, heater targets and what has been waited for, and the motion settings
//! with the time every move takes ([`crate::motion`]).
//!
//! The exporter runs everything it writes through this model, templates included, so
//! that it heats and selects a tool before extruding with it whatever a template did,
//! and so that the time estimate is that of the file itself.

use lamina_api::machine::{Firmware as Dialect, Flavor, Heating};

use crate::motion::{Corner, Limits, Planner};

/// Marlin's EXTRUDE_MINTEMP: the firmware refuses to move the extruder below this (°C).
pub const EXTRUDE_MIN_TEMPERATURE: f64 = 170.0;
/// Within this of a target, a heater counts as at temperature (°C), as M109 does.
const TEMPERATURE_WINDOW: f64 = 1.0;
/// RepRapFirmware's `M116` default tolerance (°C).
const M116_TOLERANCE: f64 = 2.0;
/// Where every heater starts (°C).
const AMBIENT: f64 = 25.0;

/// One heater: its target, how hot it is known to be for the firmware's checks (the
/// last target waited for, lowered when the target drops, since the heater cools), and
/// its temperature as the time model follows it: `temperature` at `at` seconds, moving
/// toward the target at the heater's rates.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Heater {
    target: f64,
    reached: f64,
    temperature: f64,
    at: f64,
    /// °C/s up and down.
    heat: f64,
    cool: f64,
}

impl Heater {
    fn new(heat: f64, cool: f64) -> Self {
        Self {
            target: 0.0,
            reached: 0.0,
            temperature: AMBIENT,
            at: 0.0,
            heat,
            cool,
        }
    }

    /// The temperature at `now` (s).
    fn temperature_at(&self, now: f64) -> f64 {
        let dt = (now - self.at).max(0.0);
        let goal = self.target.max(AMBIENT);
        if self.temperature < goal {
            (self.temperature + self.heat * dt).min(goal)
        } else {
            (self.temperature - self.cool * dt).max(goal)
        }
    }

    fn set(&mut self, t: f64, now: f64) {
        self.temperature = self.temperature_at(now);
        self.at = now;
        self.target = t;
        self.reached = self.reached.min(t);
    }

    /// How long a wait at `now` takes until the heater is within `window` of its target
    /// (heating only, or both ways), plus `residency` once it had to move. A heater
    /// already within the window waits no time: current Marlin starts the residency
    /// timer in the future on the first pass of its wait, and its unsigned
    /// `PENDING(now, start, interval)` then ends the wait at once.
    fn wait_time(&self, now: f64, window: f64, both_ways: bool, residency: f64) -> f64 {
        let t = self.temperature_at(now);
        let goal = self.target.max(AMBIENT);
        if t < goal - window {
            (goal - window - t) / self.heat + residency
        } else if both_ways && t > goal + window {
            (t - goal - window) / self.cool + residency
        } else {
            0.0
        }
    }

    /// The wait is over at `now` (the dwell it took already counted): a heater that
    /// had to heat is at its target, one that is hotter goes on cooling.
    fn wait(&mut self, now: f64) {
        self.temperature = self.temperature_at(now);
        self.at = now;
        self.reached = self.target;
    }
}

/// What the time model needs of the heaters and tool changes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Thermal {
    pub heating: Heating,
    /// Seconds a tool change takes besides its moves.
    pub tool_change_time: f64,
}

impl Thermal {
    /// Typical heaters of `dialect`'s firmware and tool changes that take no time of
    /// their own.
    pub fn typical(dialect: Dialect) -> Self {
        Self {
            heating: Heating::typical(dialect),
            tool_change_time: 0.0,
        }
    }
}

/// A RepRapFirmware tool's active and standby temperatures (`G10 P.. S.. R..`).
#[derive(Debug, Clone, Copy, Default)]
struct RrfTemperatures {
    active: f64,
    standby: f64,
    /// Selected once: it waits at standby when deselected (a tool never used is off).
    used: bool,
    /// The heater state `M568 A` forced while the tool is not selected: 0 off, 1
    /// standby, 2 active (RepRapFirmware 3.3 and later). Selecting or deselecting the
    /// tool sets it again as the firmware does.
    forced: Option<u8>,
}

/// The words of a linear move (`G0`, `G1`): the axes it names and its feed.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Words {
    pub x: Option<f64>,
    pub y: Option<f64>,
    pub z: Option<f64>,
    pub e: Option<f64>,
    /// mm/min
    pub f: Option<f64>,
}

/// The firmware's state, fed line by line.
#[derive(Debug, Clone)]
pub struct Firmware {
    dialect: Dialect,
    mixing: bool,
    /// X, Y, Z, E as the firmware counts them.
    position: [f64; 4],
    absolute: bool,
    absolute_e: bool,
    /// Modal feed (mm/min).
    feed: f64,
    tool: Option<usize>,
    heaters: Vec<Heater>,
    rrf: Vec<RrfTemperatures>,
    bed: Heater,
    thermal: Thermal,
    /// Seconds spent waiting for heaters, and changing tools.
    heating_wait: f64,
    tool_changes: f64,
    /// Part-cooling fan, 0 to 1.
    fan: f64,
    /// X, Y and Z homed.
    homed: [bool; 3],
    planner: Planner,
    /// The first line that moves the extruder of a cold or unselected tool.
    cold: Option<String>,
    /// The words of the line being read.
    params: Vec<(char, f64)>,
}

impl Firmware {
    pub fn new(dialect: Dialect, flavor: Flavor, tools: usize, limits: Limits, thermal: Thermal) -> Self {
        let heaters = if flavor.is_mixing() { 1 } else { tools.max(1) };
        let h = thermal.heating;
        Self {
            dialect,
            mixing: flavor.is_mixing(),
            position: [0.0; 4],
            absolute: true,
            absolute_e: true,
            feed: 3000.0,
            tool: None,
            heaters: vec![Heater::new(h.nozzle_rate, h.nozzle_cooling); heaters],
            rrf: vec![RrfTemperatures::default(); heaters],
            bed: Heater::new(h.bed_rate, h.nozzle_cooling),
            thermal,
            heating_wait: 0.0,
            tool_changes: 0.0,
            fan: 0.0,
            homed: [false; 3],
            planner: Planner::new(limits),
            cold: None,
            params: Vec::new(),
        }
    }

    /// Feeds every line of `text`.
    pub fn feed_text(&mut self, text: &str) {
        for line in text.lines() {
            self.feed_line(line);
        }
    }

    /// Feeds one line of G-code.
    pub fn feed_line(&mut self, line: &str) {
        let code = line.split(';').next().unwrap_or("").trim();
        if code.is_empty() {
            return;
        }
        let mut words = code.split_whitespace();
        let Some(command) = words.next() else { return };
        // The words' buffer is kept from line to line, and a command in capitals (as
        // written) is read as it is: a file is hundreds of thousands of lines.
        let mut params = std::mem::take(&mut self.params);
        params.clear();
        params.extend(words.filter_map(|w| {
            let mut c = w.chars();
            let letter = c.next()?.to_ascii_uppercase();
            Some((letter, c.as_str().parse::<f64>().ok()?))
        }));
        let get = |l: char| params.iter().find(|(k, _)| *k == l).map(|(_, v)| *v);
        let upper;
        let command = if command.bytes().any(|b| b.is_ascii_lowercase()) {
            upper = command.to_ascii_uppercase();
            upper.as_str()
        } else {
            command
        };
        match command {
            "G0" | "G1" => self.linear(
                Words {
                    x: get('X'),
                    y: get('Y'),
                    z: get('Z'),
                    e: get('E'),
                    f: get('F'),
                },
                line,
            ),
            "G4" => {
                let seconds = get('S').unwrap_or(0.0) + get('P').unwrap_or(0.0) / 1000.0;
                self.planner.dwell(seconds);
            }
            "G10" | "M568" if self.dialect == Dialect::RepRapFirmware => {
                self.rrf_tool_temperatures(command, &get)
            }
            "G28" => self.home(code),
            "G29" | "M400" => self.planner.stop(),
            "G90" => {
                self.absolute = true;
                if self.dialect == Dialect::Marlin {
                    self.absolute_e = true;
                }
            }
            "G91" => {
                self.absolute = false;
                if self.dialect == Dialect::Marlin {
                    self.absolute_e = false;
                }
            }
            "M82" => self.absolute_e = true,
            "M83" => self.absolute_e = false,
            "G92" => {
                for (a, letter) in ['X', 'Y', 'Z', 'E'].into_iter().enumerate() {
                    if let Some(v) = get(letter) {
                        self.position[a] = v;
                    }
                }
            }
            "M104" | "M109" => self.nozzle_temperature(command, &get),
            "M116" => self.wait_for_temperatures(&get),
            "M140" | "M190" => self.bed_temperature(command, &get),
            "M106" => {
                let s = get('S').unwrap_or(255.0);
                // Marlin counts to 255; RepRapFirmware takes either a fraction or 0..255.
                self.fan = if self.dialect == Dialect::RepRapFirmware && s <= 1.0 {
                    s
                } else {
                    s / 255.0
                };
            }
            "M107" => self.fan = 0.0,
            "M201" | "M203" | "M204" | "M205" | "M566" => self.motion_setting(command, &get),
            _ if command.starts_with('T') => self.select(command[1..].parse::<i64>().ok()),
            _ => {}
        }
        self.params = params;
    }

    /// `G10 P<tool> S<active> R<standby>` or `M568` (which may also set the heater's
    /// state, `A`): a RepRapFirmware tool's two temperatures, its heater following them.
    fn rrf_tool_temperatures(&mut self, command: &str, get: &dyn Fn(char) -> Option<f64>) {
        if let Some(p) = get('P').map(|p| p as usize)
            && p < self.rrf.len()
        {
            if let Some(s) = get('S') {
                self.rrf[p].active = s;
            }
            if let Some(r) = get('R') {
                self.rrf[p].standby = r;
            }
            if command == "M568"
                && let Some(a) = get('A')
            {
                self.rrf[p].forced = Some(a.clamp(0.0, 2.0) as u8);
            }
            self.rrf_heater_follows(p);
        }
    }

    /// `G28`: the machine stops, and the axes it homes are at zero.
    fn home(&mut self, code: &str) {
        self.planner.stop();
        // `G28` homes every axis; `G28 X` (or `G28 X0 Y0`) only those named,
        // with or without a value.
        let named: Vec<char> = code
            .split_whitespace()
            .skip(1)
            .filter_map(|w| w.chars().next())
            .map(|c| c.to_ascii_uppercase())
            .filter(|c| "XYZ".contains(*c))
            .collect();
        let all = named.is_empty();
        for (a, letter) in ['X', 'Y', 'Z'].into_iter().enumerate() {
            if all || named.contains(&letter) {
                self.position[a] = 0.0;
                self.homed[a] = true;
            }
        }
    }

    /// `M104` sets a nozzle's temperature, `M109` also waits for it.
    fn nozzle_temperature(&mut self, command: &str, get: &dyn Fn(char) -> Option<f64>) {
        let heater = self.heater_of(get('T'));
        if let (Some(h), Some(t)) = (heater, get('S').or(get('R'))) {
            if self.dialect == Dialect::RepRapFirmware {
                self.rrf[h].active = t;
            }
            let now = self.planner.elapsed();
            self.heaters[h].set(t, now);
            if command == "M109" {
                // `S` waits only to heat, `R` either way; Marlin lets the
                // heater settle once it had to move.
                let both = get('R').is_some();
                let residency = self.thermal.heating.residency;
                self.wait_for(|f, now| f.heaters[h].wait_time(now, TEMPERATURE_WINDOW, both, residency));
                let now = self.planner.elapsed();
                self.heaters[h].wait(now);
            }
        }
    }

    /// `M116`: waits for the nozzles' heaters (or the one `P` names) and the bed, within
    /// `S` degrees.
    fn wait_for_temperatures(&mut self, get: &dyn Fn(char) -> Option<f64>) {
        let tolerance = get('S').unwrap_or(M116_TOLERANCE);
        let residency = self.thermal.heating.residency;
        let which: Vec<usize> = match get('P').map(|p| p as usize) {
            Some(p) if p < self.heaters.len() => vec![p],
            Some(_) => Vec::new(),
            None => (0..self.heaters.len()).collect(),
        };
        let bed = get('P').is_none();
        let bed_residency = self.thermal.heating.bed_residency;
        self.wait_for(|f, now| {
            let nozzles = which
                .iter()
                .map(|&h| f.heaters[h].wait_time(now, tolerance, true, residency))
                .fold(0.0, f64::max);
            let bed = if bed {
                f.bed.wait_time(now, tolerance, true, bed_residency)
            } else {
                0.0
            };
            nozzles.max(bed)
        });
        let now = self.planner.elapsed();
        for h in which {
            self.heaters[h].wait(now);
        }
        if bed {
            self.bed.wait(now);
        }
    }

    /// `M140` sets the bed's temperature, `M190` also waits for it.
    fn bed_temperature(&mut self, command: &str, get: &dyn Fn(char) -> Option<f64>) {
        if let Some(t) = get('S').or(get('R')) {
            let now = self.planner.elapsed();
            self.bed.set(t, now);
        }
        if command == "M190" {
            let both = get('R').is_some();
            let residency = self.thermal.heating.bed_residency;
            self.wait_for(|f, now| f.bed.wait_time(now, TEMPERATURE_WINDOW, both, residency));
            let now = self.planner.elapsed();
            self.bed.wait(now);
        }
    }

    /// Feeds a `G1` line whose words the caller has in hand as the values it wrote
    /// them as (each the number a reader parses back from its text): the same as
    /// [`Self::feed_line`] on `line`, without reading the text again. The writer's
    /// moves are most of a file's lines.
    pub fn feed_move(&mut self, words: Words, line: &str) {
        self.linear(words, line);
    }

    fn linear(&mut self, words: Words, line: &str) {
        if let Some(f) = words.f
            && f > 0.0
        {
            self.feed = f;
        }
        let mut target = self.position;
        for (a, v) in [words.x, words.y, words.z, words.e].into_iter().enumerate() {
            if let Some(v) = v {
                let absolute = if a == 3 { self.absolute_e } else { self.absolute };
                target[a] = if absolute { v } else { self.position[a] + v };
            }
        }
        let delta = [0, 1, 2, 3].map(|a| target[a] - self.position[a]);
        if delta[3] != 0.0 && self.cold.is_none() && !self.can_extrude() {
            self.cold = Some(line.trim().to_string());
        }
        self.planner.push(delta, self.feed / 60.0);
        self.position = target;
    }

    /// Whether the extruder may move: a tool is selected (any, on a mixing head) and its
    /// heater has been waited for above the firmware's minimum.
    fn can_extrude(&self) -> bool {
        let heater = if self.mixing { Some(0) } else { self.tool };
        heater.is_some_and(|h| {
            let h = self.heaters[h];
            h.target >= EXTRUDE_MIN_TEMPERATURE && h.reached >= EXTRUDE_MIN_TEMPERATURE - TEMPERATURE_WINDOW
        }) && ((self.mixing && self.dialect == Dialect::Marlin) || self.tool.is_some())
    }

    fn heater_of(&self, t: Option<f64>) -> Option<usize> {
        let h = if self.mixing {
            0
        } else {
            match t {
                Some(t) if t >= 0.0 => t as usize,
                Some(_) => return None,
                None => self.tool.unwrap_or(0),
            }
        };
        (h < self.heaters.len()).then_some(h)
    }

    /// The machine stops and waits as long as `how_long` says at that moment.
    fn wait_for(&mut self, how_long: impl Fn(&Self, f64) -> f64) {
        self.planner.stop();
        let seconds = how_long(self, self.planner.elapsed());
        self.planner.dwell(seconds);
        self.heating_wait += seconds;
    }

    fn select(&mut self, tool: Option<i64>) {
        self.planner.stop();
        let previous = self.tool;
        self.tool = match tool {
            Some(t) if t >= 0 && (self.mixing || (t as usize) < self.heaters.len()) => Some(t as usize),
            _ => None,
        };
        // The firmware parks one tool and picks up the next: time of its own (the
        // first selection finds the machine with no tool to park, and is not counted).
        if previous.is_some() && self.tool.is_some() && self.tool != previous && !self.mixing {
            self.planner.dwell(self.thermal.tool_change_time);
            self.tool_changes += self.thermal.tool_change_time;
        }
        if self.dialect == Dialect::RepRapFirmware {
            if self.mixing {
                self.rrf_heater_follows(0);
                return;
            }
            if let Some(t) = self.tool {
                self.rrf[t].used = true;
                self.rrf[t].forced = None;
                self.rrf_heater_follows(t);
            }
            if let Some(p) = previous.filter(|p| Some(*p) != self.tool) {
                self.rrf[p].forced = None;
                self.rrf_heater_follows(p);
            }
        }
    }

    /// A RepRapFirmware tool's heater is at its active temperature while selected, at
    /// standby once used and deselected, and off before its first use.
    fn rrf_heater_follows(&mut self, t: usize) {
        if self.mixing {
            if self.tool.is_some() {
                let active = self.rrf[0].active;
                let now = self.planner.elapsed();
                self.heaters[0].set(active, now);
            }
            return;
        }
        let r = self.rrf[t];
        let target = match r.forced {
            Some(0) => 0.0,
            Some(1) => r.standby,
            Some(_) => r.active,
            None if self.tool == Some(t) => r.active,
            None if r.used => r.standby,
            None => 0.0,
        };
        let now = self.planner.elapsed();
        self.heaters[t].set(target, now);
    }

    fn motion_setting(&mut self, command: &str, get: &dyn Fn(char) -> Option<f64>) {
        let mut l = *self.planner.limits();
        // RepRapFirmware gives speeds and jerk in mm/min.
        let per_minute = if self.dialect == Dialect::RepRapFirmware {
            60.0
        } else {
            1.0
        };
        let axes = |current: [f64; 4], scale: f64| {
            let mut v = current;
            for (a, letter) in ['X', 'Y', 'Z', 'E'].into_iter().enumerate() {
                if let Some(x) = get(letter).filter(|x| *x > 0.0) {
                    v[a] = x / scale;
                }
            }
            v
        };
        match command {
            "M201" => l.max_acceleration = axes(l.max_acceleration, 1.0),
            "M203" => l.max_speed = axes(l.max_speed, per_minute),
            "M204" => {
                if let Some(p) = get('P').or(get('S')).filter(|v| *v > 0.0) {
                    l.print = p;
                    if self.dialect == Dialect::RepRapFirmware {
                        l.retract = p;
                    }
                }
                if let Some(r) = get('R').filter(|v| *v > 0.0) {
                    l.retract = r;
                }
                if let Some(t) = get('T').filter(|v| *v > 0.0) {
                    l.travel = t;
                }
            }
            "M205" => {
                if let Some(j) = get('J').filter(|v| *v > 0.0) {
                    l.corner = Corner::JunctionDeviation(j);
                } else if ['X', 'Y', 'Z', 'E'].iter().any(|c| get(*c).is_some()) {
                    let current = match l.corner {
                        Corner::Jerk(j) => j,
                        Corner::JunctionDeviation(_) => [10.0, 10.0, 0.4, 5.0],
                    };
                    l.corner = Corner::Jerk(axes(current, 1.0));
                }
            }
            "M566" => {
                let current = match l.corner {
                    Corner::Jerk(j) => j,
                    Corner::JunctionDeviation(_) => [15.0, 15.0, 0.2, 2.0],
                };
                l.corner = Corner::Jerk(axes(current, 60.0));
            }
            _ => {}
        }
        self.planner.set_limits(l);
    }

    /// Seconds the file waits for heaters, and spends changing tools besides its moves.
    pub fn waits(&self) -> (f64, f64) {
        (self.heating_wait, self.tool_changes)
    }

    /// The temperature tool `t`'s heater has `seconds` from now, as the time model
    /// follows it (the moves written so far at their cruise speed).
    pub fn temperature_in(&self, t: usize, seconds: f64) -> f64 {
        let h = if self.mixing { 0 } else { t };
        self.heaters
            .get(h)
            .map_or(AMBIENT, |h| h.temperature_at(self.planner.elapsed() + seconds))
    }

    /// The model's heating rate of a nozzle (°C/s).
    pub fn nozzle_rate(&self) -> f64 {
        self.thermal.heating.nozzle_rate
    }

    /// The selected tool (the virtual tool of a mixing head).
    pub fn tool(&self) -> Option<usize> {
        self.tool
    }

    /// Whether tool `t`'s heater targets `temperature` and has been waited for.
    pub fn is_hot(&self, t: usize, temperature: f64) -> bool {
        let h = if self.mixing { 0 } else { t };
        self.heaters.get(h).is_some_and(|h| {
            h.target >= temperature - TEMPERATURE_WINDOW && h.reached >= temperature - TEMPERATURE_WINDOW
        })
    }

    /// The target of tool `t`'s heater.
    pub fn target(&self, t: usize) -> f64 {
        let h = if self.mixing { 0 } else { t };
        self.heaters.get(h).map_or(0.0, |h| h.target)
    }

    /// Targets of every heater, the bed's last.
    pub fn targets(&self) -> Vec<f64> {
        self.heaters
            .iter()
            .map(|h| h.target)
            .chain([self.bed.target])
            .collect()
    }

    pub fn bed_is_hot(&self, temperature: f64) -> bool {
        self.bed.target >= temperature - TEMPERATURE_WINDOW
            && self.bed.reached >= temperature - TEMPERATURE_WINDOW
    }

    pub fn bed_target(&self) -> f64 {
        self.bed.target
    }

    /// Part-cooling fan, 0 to 1.
    pub fn fan(&self) -> f64 {
        self.fan
    }

    /// True once X, Y and Z have all been homed.
    pub fn homed(&self) -> bool {
        self.homed.iter().all(|&h| h)
    }

    /// True while X, Y and Z moves are absolute (`G90`), false after `G91`.
    pub fn absolute(&self) -> bool {
        self.absolute
    }

    pub fn position(&self) -> [f64; 4] {
        self.position
    }

    pub fn absolute_e(&self) -> bool {
        self.absolute_e
    }

    /// Modal feed (mm/min).
    pub fn feed(&self) -> f64 {
        self.feed
    }

    pub fn limits(&self) -> &Limits {
        self.planner.limits()
    }

    /// The first line that would extrude with a cold or unselected tool, if any.
    pub fn cold_extrusion(&self) -> Option<&str> {
        self.cold.as_deref()
    }

    /// Seconds the file takes so far, as if the machine stopped now.
    pub fn time(&mut self) -> f64 {
        self.planner.total()
    }

    /// Z as another motion system left it: a shared axis this stream did not move.
    pub fn assume_z(&mut self, z: f64) {
        self.position[2] = z;
    }

    /// Stands still until `t` seconds into the file (a synchronisation with another
    /// motion system).
    pub fn wait_until(&mut self, t: f64) {
        let now = self.planner.total();
        self.planner.dwell(t - now);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A move fed as its words leaves the firmware where reading its line does: the
    /// position (relative E too), the modal feed, the time, and the cold line.
    #[test]
    fn a_move_fed_as_words_is_read_as_its_line() {
        let fresh = || {
            Firmware::new(
                Dialect::Marlin,
                Flavor::ToolChange,
                2,
                Limits::default(),
                Thermal::typical(Dialect::Marlin),
            )
        };
        let (mut read, mut fed) = (fresh(), fresh());
        for f in [&mut read, &mut fed] {
            f.feed_text("G28\nM83\nG1 Z0.2 F600\n");
        }
        let moves = [
            (
                "G1 X10.5 Y2.25 E0.41230 F1800",
                [Some(10.5), Some(2.25), None, Some(0.4123), Some(1800.0)],
            ),
            (
                "G1 X12 Y-3.0001 E0.01000",
                [Some(12.0), Some(-3.0001), None, Some(0.01), None],
            ),
            ("G1 X0 Y0", [Some(0.0), Some(0.0), None, None, None]),
            ("G1 Z0.4 F300", [None, None, Some(0.4), None, Some(300.0)]),
        ];
        for (line, [x, y, z, e, f]) in moves {
            read.feed_line(line);
            fed.feed_move(Words { x, y, z, e, f }, line);
            assert_eq!(read.position(), fed.position(), "{line}");
            assert_eq!(read.feed(), fed.feed(), "{line}");
            assert_eq!(read.time(), fed.time(), "{line}");
        }
        assert_eq!(fed.position()[3], 0.4223, "relative E adds up");
        assert_eq!(read.cold_extrusion(), Some("G1 X10.5 Y2.25 E0.41230 F1800"));
        assert_eq!(fed.cold_extrusion(), read.cold_extrusion());
    }

    #[test]
    fn marlin_heats_per_tool_and_cools_on_standby() {
        let mut f = Firmware::new(
            Dialect::Marlin,
            Flavor::ToolChange,
            2,
            Limits::default(),
            Thermal::typical(Dialect::Marlin),
        );
        f.feed_text("M104 T1 S215\nT1\n");
        assert!(!f.is_hot(1, 215.0), "set but not waited for");
        f.feed_line("M109 T1 S215");
        assert!(f.is_hot(1, 215.0));
        f.feed_line("M104 T1 S170 ; standby");
        f.feed_line("M104 T1 S215");
        assert!(!f.is_hot(1, 215.0), "it cooled toward standby in between");
        f.feed_line("G1 X10 E1 F600");
        assert!(f.cold_extrusion().is_none(), "170 °C is warm enough for Marlin");
        f.feed_text("T0\nG1 X20 E2 F600\n");
        assert_eq!(
            f.cold_extrusion(),
            Some("G1 X20 E2 F600"),
            "tool 0 was never heated"
        );
    }

    #[test]
    fn reprapfirmware_tools_go_to_standby_when_deselected() {
        let mut f = Firmware::new(
            Dialect::RepRapFirmware,
            Flavor::ToolChange,
            2,
            Limits::default(),
            Thermal::typical(Dialect::RepRapFirmware),
        );
        f.feed_text("G10 P0 S210 R160\nG10 P1 S215 R160\nT0\nM116 P0\n");
        assert!(f.is_hot(0, 210.0));
        assert_eq!(f.target(1), 0.0, "never used: off");
        f.feed_text("T1\n");
        assert_eq!(f.target(0), 160.0);
        assert_eq!(f.target(1), 215.0);
        assert!(!f.is_hot(1, 215.0));
        f.feed_text("M116 P1\nG1 X5 E0.5 F1200\n");
        assert!(f.cold_extrusion().is_none());
    }

    #[test]
    fn m568_a_sets_a_tools_heater_without_selecting_it() {
        let mut f = Firmware::new(
            Dialect::RepRapFirmware,
            Flavor::ToolChange,
            2,
            Limits::default(),
            Thermal::typical(Dialect::RepRapFirmware),
        );
        f.feed_text("G10 P0 S210 R160\nG10 P1 S215 R150\nM568 P1 A2\n");
        assert_eq!(f.target(1), 215.0, "active, not selected");
        assert_eq!(f.target(0), 0.0, "never used: off");
        f.feed_text("M568 P1 A1\n");
        assert_eq!(f.target(1), 150.0, "standby");
        f.feed_text("M568 P0 A2\nM116\nT0\n");
        assert!(f.is_hot(0, 210.0), "heated before its selection");
        f.feed_text("M568 P0 S0 R0 A0\n");
        assert_eq!(f.target(0), 0.0, "off while selected");
    }

    #[test]
    fn modes_positions_and_motion_settings() {
        let mut f = Firmware::new(
            Dialect::RepRapFirmware,
            Flavor::ReprapMixing,
            2,
            Limits::default(),
            Thermal::typical(Dialect::RepRapFirmware),
        );
        f.feed_text(
            "G90\nM83\nG1 X10 Y10 F6000\nG91\nG1 X5\nG90\nG92 E0\nM566 X600 Y600 Z24 E300\nM204 P800 T2000\n",
        );
        assert_eq!(f.position(), [15.0, 10.0, 0.0, 0.0]);
        assert!(!f.absolute_e(), "G90 leaves RepRapFirmware's E mode alone");
        assert_eq!(f.limits().corner, Corner::Jerk([10.0, 10.0, 0.4, 5.0]));
        assert_eq!((f.limits().print, f.limits().travel), (800.0, 2000.0));
        assert!(f.time() > 0.0);
        assert!(f.absolute());
        f.feed_line("G91");
        assert!(!f.absolute());
    }

    #[test]
    fn only_the_axes_g28_names_are_homed() {
        let mut f = marlin(0.0);
        f.feed_text(
            "G28 X
G28 Y0
",
        );
        assert!(!f.homed(), "Z was never homed");
        f.feed_line("G28 Z");
        assert!(f.homed());
        let mut g = marlin(0.0);
        g.feed_line("G28 ; all");
        assert!(g.homed());
    }

    fn marlin(tool_change_time: f64) -> Firmware {
        let thermal = Thermal {
            heating: Heating::typical(Dialect::Marlin),
            tool_change_time,
        };
        Firmware::new(Dialect::Marlin, Flavor::ToolChange, 2, Limits::default(), thermal)
    }

    #[test]
    fn a_wait_takes_the_heating_and_the_residency_a_preheat_spares_it() {
        // From ambient at 2 °C/s to within a degree of 215, then Marlin's 10 s.
        let mut f = marlin(0.0);
        f.feed_text("M104 T0 S215\nM109 T0 S215\n");
        assert!((f.time() - ((215.0 - 1.0 - 25.0) / 2.0 + 10.0)).abs() < 1e-9);
        assert!((f.waits().0 - f.time()).abs() < 1e-9);
        // Set 200 s of dwell ahead, the heater is there when the wait comes.
        let mut f = marlin(0.0);
        f.feed_text("M104 T0 S215\nG4 S200\nM109 T0 S215\n");
        assert!((f.time() - 200.0).abs() < 1e-9, "{}", f.time());
        // Half heated: the rest of the ramp and the residency.
        let mut f = marlin(0.0);
        f.feed_text("M104 T0 S215\nG4 S50\nM109 T0 S215\n");
        assert!((f.time() - (50.0 + (214.0 - 125.0) / 2.0 + 10.0)).abs() < 1e-9);
        // M109 S does not wait for a hotter heater to cool; M109 R does.
        let mut f = marlin(0.0);
        f.feed_text("M109 T0 S215\nM109 T0 S200\n");
        assert!((f.waits().0 - 104.5).abs() < 1e-9);
        f.feed_text("M109 T0 R190\n");
        assert!((f.waits().0 - (104.5 + (215.0 - 191.0) / 1.0 + 10.0)).abs() < 1e-9);
    }

    #[test]
    fn a_tool_change_takes_the_machines_own_time() {
        let mut f = marlin(5.0);
        f.feed_text("T0\nT1\nT1\nT0\n");
        // The first selection parks nothing; re-selecting changes nothing.
        assert!((f.waits().1 - 10.0).abs() < 1e-9);
        assert!((f.time() - 10.0).abs() < 1e-9);
    }
}
