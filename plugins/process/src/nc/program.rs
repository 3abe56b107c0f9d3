//! The program as the controller will run it: the lines, the machine's state they
//! leave (position, feed, spindle, laser, outputs, tool), and the time they take.
//!
//! A move is written only for the axes it changes, as they will be printed: a move to
//! where the tool already is, or a feed word already in force, is not written. Every
//! position is checked against the machine's travel.
//!
//! The time of each move follows the controller's limits: its speed is the feed (or the
//! rapid speed) capped so no axis exceeds its own, its acceleration the most every axis
//! allows along it, on a trapezoidal profile. A rapid starts and ends at rest, and so
//! does every run of feed moves, which any other line ends. Within a run, the speed
//! through a corner is the one that keeps the tool within the machine's junction deviation
//! δ of the corner at its acceleration a: v² = a δ sin(θ/2) / (1 − sin(θ/2)), θ the
//! angle between the moves (the junction-deviation rule of Grbl's planner, a model of a
//! controller blending within a tolerance), and a look-ahead over the run lowers each
//! corner's speed so the tool can still brake for the next.

use std::collections::{BTreeMap, BTreeSet};

use lamina_api::{Error, Result};

use crate::hybrid::{HybridMachine, render};

/// A feed move waiting for the run it belongs to to end.
#[derive(Debug, Clone, Copy)]
struct Pending {
    length: f64,
    /// Cruise speed (mm/s) and acceleration (mm/s²).
    speed: f64,
    accel: f64,
    unit: [f64; 3],
}

/// Seconds for `length` entered at `v0`, left at `v1`, at most `v`, at acceleration `a`.
pub fn segment(length: f64, v0: f64, v1: f64, v: f64, a: f64) -> f64 {
    if length <= 0.0 {
        return 0.0;
    }
    let peak = ((2.0 * a * length + v0 * v0 + v1 * v1) / 2.0).sqrt();
    if peak <= v {
        (peak - v0).max(0.0) / a + (peak - v1).max(0.0) / a
    } else {
        let accel = (v * v - v0 * v0) / (2.0 * a);
        let brake = (v * v - v1 * v1) / (2.0 * a);
        (v - v0) / a + (v - v1) / a + (length - accel - brake) / v
    }
}

/// Seconds for a run of feed moves from rest to rest, corners taken at the speed the
/// junction deviation `delta` allows.
fn run_time(moves: &[Pending], delta: f64) -> f64 {
    let n = moves.len();
    // Speed limits at each junction: 0 at both ends.
    let mut j = vec![0.0f64; n + 1];
    for k in 1..n {
        let (p, q) = (&moves[k - 1], &moves[k]);
        let cos = -(p.unit[0] * q.unit[0] + p.unit[1] * q.unit[1] + p.unit[2] * q.unit[2]);
        let limit = if delta <= 0.0 || cos > 0.999_999 {
            0.0
        } else if cos < -0.999_999 {
            f64::INFINITY
        } else {
            let s = (0.5 * (1.0 - cos)).sqrt();
            (p.accel.min(q.accel) * delta * s / (1.0 - s)).sqrt()
        };
        j[k] = limit.min(p.speed).min(q.speed);
    }
    for k in (0..n).rev() {
        j[k] = j[k].min((j[k + 1] * j[k + 1] + 2.0 * moves[k].accel * moves[k].length).sqrt());
    }
    for k in 0..n {
        j[k + 1] = j[k + 1].min((j[k] * j[k] + 2.0 * moves[k].accel * moves[k].length).sqrt());
    }
    moves
        .iter()
        .enumerate()
        .map(|(k, m)| segment(m.length, j[k], j[k + 1], m.speed, m.accel))
        .sum()
}

/// What the program's time went to, in the order first met.
#[derive(Debug, Default)]
pub struct Shares {
    pub by: Vec<(String, f64)>,
}

impl Shares {
    fn add(&mut self, what: &str, seconds: f64) {
        match self.by.iter_mut().find(|(k, _)| k == what) {
            Some((_, s)) => *s += seconds,
            None => self.by.push((what.to_string(), seconds)),
        }
    }

    pub fn total(&self) -> f64 {
        self.by.iter().map(|(_, s)| s).sum()
    }
}

pub struct Program {
    pub machine: HybridMachine,
    pub text: String,
    /// Position in work coordinates as printed; `None` until known (after a retract in
    /// machine coordinates, z is not).
    pos: [Option<f64>; 3],
    /// True from a retract to the safe height until z moves.
    safe: bool,
    feed: Option<String>,
    /// Tool in the spindle, by name.
    pub tool: Option<String>,
    length: bool,
    /// Speed while the spindle turns (rev/min).
    spindle: Option<f64>,
    laser: bool,
    outputs: BTreeSet<u32>,
    analog: BTreeMap<u32, String>,
    /// The last line, when it is a rapid along z alone: (where the line starts in
    /// `text`, z before it, its seconds). A rapid along z that follows it the same way
    /// replaces it, since both go along the same line.
    last_z_rapid: Option<(usize, f64, f64)>,
    /// The feed moves of the run not yet ended.
    run: Vec<Pending>,
    /// What the time goes to now.
    pub doing: String,
    pub shares: Shares,
}

/// `v` in the program's unit, a ten-thousandth of a millimetre: what is printed.
fn quantum(v: f64) -> i64 {
    (v * 10_000.0).round() as i64
}

/// `v` as the controller reads it: four decimals at most, no trailing zeros, and a
/// decimal point on every number where the dialect wants one. Written from the
/// rounded integer: formatting floats to a fixed precision is the program's hot path.
pub fn number(v: f64, decimal_point: bool) -> String {
    use std::fmt::Write as _;
    if !(v.is_finite() && v.abs() < 1e14) {
        return format!("{v}");
    }
    let n = quantum(v);
    let (int, frac) = (n.unsigned_abs() / 10_000, n.unsigned_abs() % 10_000);
    let mut s = String::with_capacity(16);
    if n < 0 {
        s.push('-');
    }
    let _ = write!(s, "{int}");
    if frac != 0 {
        let _ = write!(s, ".{frac:04}");
        while s.ends_with('0') {
            s.pop();
        }
    } else if decimal_point {
        s.push('.');
    }
    s
}

/// Seconds to travel `length` from rest to rest at top speed `v` and acceleration `a`.
pub fn trapezoid(length: f64, v: f64, a: f64) -> f64 {
    segment(length, 0.0, 0.0, v, a)
}

impl Program {
    pub fn new(machine: HybridMachine) -> Self {
        Self {
            machine,
            text: String::new(),
            pos: [None; 3],
            safe: false,
            feed: None,
            tool: None,
            length: false,
            spindle: None,
            laser: false,
            outputs: BTreeSet::new(),
            analog: BTreeMap::new(),
            last_z_rapid: None,
            run: Vec::new(),
            doing: "setup".into(),
            shares: Shares::default(),
        }
    }

    /// A line that is not a feed move: the run of feed moves before it ends.
    pub fn line(&mut self, s: impl AsRef<str>) {
        self.end_run();
        self.last_z_rapid = None;
        self.push(s.as_ref());
    }

    fn push(&mut self, s: &str) {
        self.text.push_str(s);
        self.text.push('\n');
    }

    /// Times the run of feed moves written since the last other line.
    pub fn end_run(&mut self) {
        if self.run.is_empty() {
            return;
        }
        let t = run_time(&self.run, self.machine.motion.junction_deviation);
        self.run.clear();
        self.wait(t);
    }

    pub fn num(&self, v: f64) -> String {
        number(v, self.machine.controller.decimal_point)
    }

    fn wait(&mut self, seconds: f64) {
        let doing = self.doing.clone();
        self.shares.add(&doing, seconds);
    }

    /// The lines of a template, each with `values` put in.
    fn template(&mut self, lines: &[String], values: &[(&str, String)]) {
        for l in lines {
            let s = render(l, values);
            self.line(s);
        }
    }

    /// A needed capability the controller lacks.
    fn lacks(&self, key: &str, what: &str) -> Error {
        Error::stage(
            "export:nc",
            format!(
                "the machine `{}` cannot {what}: its controller ({}) has no `controller.{key}`",
                self.machine.name, self.machine.controller.dialect
            ),
        )
    }

    pub fn z(&self) -> Option<f64> {
        self.pos[2]
    }

    /// A straight move to `to` (an axis left `None` stays), rapid or at `feed` (mm/s).
    fn go(&mut self, to: [Option<f64>; 3], feed: Option<f64>) -> Result<()> {
        let travel = self.machine.travel;
        let limits = [travel.x, travel.y, travel.z];
        let mut words = Vec::new();
        let mut delta = [0.0f64; 3];
        let mut next = self.pos;
        for (i, axis) in ['X', 'Y', 'Z'].into_iter().enumerate() {
            let Some(v) = to[i] else { continue };
            let q = quantum(v);
            if self.pos[i].is_some_and(|p| quantum(p) == q) {
                continue;
            }
            let printed = self.num(v);
            let value = q as f64 / 10_000.0;
            let [lo, hi] = limits[i];
            if value < lo - 1e-9 || value > hi + 1e-9 {
                return Err(Error::stage(
                    "export:nc",
                    format!(
                        "a move to {axis} {printed} is outside the machine `{}`'s travel x {:?}, y {:?}, z {:?}",
                        self.machine.name, travel.x, travel.y, travel.z
                    ),
                ));
            }
            // From an unknown position (after a retract in machine coordinates), the
            // distance is the travel's top down to the value.
            delta[i] = match self.pos[i] {
                Some(p) => value - p,
                None => hi - value,
            };
            next[i] = Some(value);
            words.push(format!("{axis}{printed}"));
        }
        if words.is_empty() {
            return Ok(());
        }
        // A second rapid up (or down) along z: one move from where the first began.
        let z_only = feed.is_none() && to[0].is_none() && to[1].is_none();
        let mut before = None;
        if z_only
            && let (Some((start, z0, seconds)), Some(z1), Some(z2)) =
                (self.last_z_rapid, self.pos[2], next[2])
            && (z1 - z0) * (z2 - z1) > 0.0
        {
            self.text.truncate(start);
            let doing = self.doing.clone();
            self.shares.add(&doing, -seconds);
            delta[2] = z2 - z0;
            before = Some(z0);
        }
        let m = self.machine.motion;
        let length = delta.iter().map(|d| d * d).sum::<f64>().sqrt();
        let (mut v, mut a) = (f64::INFINITY, f64::INFINITY);
        for (i, d) in delta.iter().enumerate() {
            let u = d.abs() / length;
            if u > 1e-12 {
                v = v.min(m.rapid[i] / 60.0 / u);
                a = a.min(m.acceleration[i] / u);
            }
        }
        let mut line = match feed {
            None => format!("G0 {}", words.join(" ")),
            Some(f) => {
                v = v.min(f);
                format!("G1 {}", words.join(" "))
            }
        };
        if let Some(f) = feed {
            let word = self.num(f * 60.0);
            if self.feed.as_deref() != Some(word.as_str()) {
                line.push_str(&format!(" F{word}"));
                self.feed = Some(word);
            }
        }
        if feed.is_some() {
            self.last_z_rapid = None;
            self.push(&line);
            let unit = [delta[0] / length, delta[1] / length, delta[2] / length];
            self.run.push(Pending {
                length,
                speed: v,
                accel: a,
                unit,
            });
        } else {
            self.end_run();
            let start = self.text.len();
            self.line(line);
            let seconds = trapezoid(length, v, a);
            self.wait(seconds);
            if z_only && let Some(z0) = before.or(self.pos[2]) {
                self.last_z_rapid = Some((start, z0, seconds));
            }
        }
        if next[2] != self.pos[2] {
            self.safe = false;
        }
        self.pos = next;
        Ok(())
    }

    pub fn rapid(&mut self, x: Option<f64>, y: Option<f64>, z: Option<f64>) -> Result<()> {
        self.go([x, y, z], None)
    }

    pub fn feed(&mut self, x: Option<f64>, y: Option<f64>, z: Option<f64>, feed: f64) -> Result<()> {
        self.go([x, y, z], Some(feed))
    }

    /// Up to the safe height in machine coordinates; z is then unknown.
    pub fn retract(&mut self) {
        if self.safe {
            return;
        }
        let lines = self.machine.controller.retract.lines().to_vec();
        self.template(&lines, &[]);
        let m = self.machine.motion;
        let up = match self.pos[2] {
            Some(z) => self.machine.travel.z[1] - z,
            None => 0.0,
        };
        self.wait(trapezoid(up.max(0.0), m.rapid[2] / 60.0, m.acceleration[2]));
        self.pos[2] = None;
        self.safe = true;
    }

    pub fn spindle_off(&mut self) {
        if self.spindle.take().is_some() {
            let lines = self.machine.controller.spindle_off.lines().to_vec();
            self.template(&lines, &[]);
        }
    }

    pub fn spindle_on(&mut self, speed: f64) -> Result<()> {
        if self.spindle == Some(speed) {
            return Ok(());
        }
        if self.machine.controller.spindle_on.is_empty() {
            return Err(self.lacks("spindle_on", "turn a spindle"));
        }
        let lines = self.machine.controller.spindle_on.lines().to_vec();
        let speed_word = self.num(speed);
        self.template(&lines, &[("speed", speed_word)]);
        if self.spindle.is_none() {
            self.wait(self.machine.motion.spindle_start);
        }
        self.spindle = Some(speed);
        Ok(())
    }

    pub fn laser_on(&mut self, watts: f64) -> Result<()> {
        if self.machine.controller.laser_on.is_empty() {
            return Err(self.lacks("laser_on", "switch a laser"));
        }
        let lines = self.machine.controller.laser_on.lines().to_vec();
        let power = self.num(watts * self.machine.controller.power_scale);
        self.template(&lines, &[("power", power)]);
        self.laser = true;
        Ok(())
    }

    pub fn laser_off(&mut self) {
        if std::mem::take(&mut self.laser) {
            let lines = self.machine.controller.laser_off.lines().to_vec();
            self.template(&lines, &[]);
        }
    }

    /// Switches digital output `n`; `what` names it in an error.
    pub fn output(&mut self, n: Option<u32>, on: bool, what: &str) -> Result<()> {
        let Some(n) = n else {
            if on {
                return Err(Error::stage(
                    "export:nc",
                    format!(
                        "the machine `{}` has no output for the {what} (`outputs`)",
                        self.machine.name
                    ),
                ));
            }
            return Ok(());
        };
        if self.outputs.contains(&n) == on {
            return Ok(());
        }
        let c = &self.machine.controller;
        let lines = if on {
            c.output_on.lines()
        } else {
            c.output_off.lines()
        }
        .to_vec();
        if lines.is_empty() {
            return Err(self.lacks("output_on", &format!("switch the {what}")));
        }
        self.template(&lines, &[("output", n.to_string())]);
        if on {
            self.outputs.insert(n);
        } else {
            self.outputs.remove(&n);
        }
        Ok(())
    }

    /// Every digital output off.
    pub fn outputs_off(&mut self) {
        let on: Vec<u32> = self.outputs.iter().copied().collect();
        for n in on {
            let _ = self.output(Some(n), false, "output");
        }
    }

    /// Sets analog output `n` to `value`, unless it holds it already.
    pub fn analog(&mut self, n: u32, value: f64) -> Result<()> {
        let word = self.num(value);
        if self.analog.get(&n) == Some(&word) {
            return Ok(());
        }
        if self.machine.controller.analog.is_empty() {
            return Err(self.lacks("analog", "set the feeders' flow"));
        }
        let lines = self.machine.controller.analog.lines().to_vec();
        self.template(&lines, &[("output", n.to_string()), ("value", word.clone())]);
        self.analog.insert(n, word);
        Ok(())
    }

    /// Loads `name` as tool `number`: everything stops, the length offset is
    /// cancelled, the head goes up to the safe height in machine coordinates, the tool
    /// is changed and its length offset applied.
    pub fn change(&mut self, name: &str, number: u32) -> Result<()> {
        if self.tool.as_deref() == Some(name) {
            return Ok(());
        }
        self.doing = "tool changes".into();
        self.spindle_off();
        self.laser_off();
        self.outputs_off();
        let c = self.machine.controller.clone();
        if self.tool.is_some() && c.tool_change.is_empty() {
            let now = self.tool.clone().unwrap_or_default();
            return Err(self.lacks(
                "tool_change",
                &format!("change tools: the program needs `{now}` and `{name}`"),
            ));
        }
        if self.length {
            self.template(c.length_off.lines(), &[]);
            self.length = false;
        }
        self.retract();
        self.line(format!("(tool {number}: {})", super::comment(name)));
        if !c.tool_change.is_empty() {
            self.template(c.tool_change.lines(), &[("tool", number.to_string())]);
            self.wait(self.machine.motion.tool_change);
        }
        if !c.length_on.is_empty() {
            self.template(c.length_on.lines(), &[("tool", number.to_string())]);
            self.length = true;
        }
        self.tool = Some(name.to_string());
        Ok(())
    }

    /// Everything stopped and off, the length offset cancelled, up to the safe height,
    /// and the program's end.
    pub fn end(&mut self) {
        self.doing = "end".into();
        self.spindle_off();
        self.laser_off();
        self.outputs_off();
        let c = self.machine.controller.clone();
        if self.length {
            self.template(c.length_off.lines(), &[]);
            self.length = false;
        }
        self.retract();
        self.template(c.end.lines(), &[]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn program(machine: &str) -> Program {
        Program::new(
            HybridMachine::load(
                machine,
                std::path::Path::new("."),
                &lamina_api::reach::Reach::anywhere(),
            )
            .expect("machine"),
        )
    }

    #[test]
    fn a_move_accelerates_cruises_and_brakes_in_the_seconds_its_profile_takes() {
        let close = |a: f64, b: f64| (a - b).abs() < 1e-12;
        // 100 mm at 10 mm/s and 100 mm/s²: 0.1 s up and down over 0.5 mm each, the
        // 99 mm between at speed.
        assert!(close(trapezoid(100.0, 10.0, 100.0), 0.2 + 9.9));
        // Too short to reach the speed: a triangle peaking at sqrt(a L).
        assert!(close(trapezoid(0.5, 10.0, 100.0), 2.0 * 50f64.sqrt() / 100.0));
        // Entered at 5 and left at rest: 0.05 s up over 0.375 mm, 0.1 s down over
        // 0.5 mm, the rest at 10.
        assert!(close(
            segment(10.0, 5.0, 0.0, 10.0, 100.0),
            0.05 + 0.1 + (10.0 - 0.875) / 10.0
        ));
        // Entered and left at speed: length over speed. Short, entered fast: the peak
        // lies between the two ends' speeds.
        assert!(close(segment(3.0, 10.0, 10.0, 10.0, 100.0), 0.3));
        let peak = ((2.0 * 100.0 * 0.1 + 9.0 + 1.0) / 2.0f64).sqrt();
        assert!(close(
            segment(0.1, 3.0, 1.0, 10.0, 100.0),
            (peak - 3.0) / 100.0 + (peak - 1.0) / 100.0
        ));
        assert_eq!(segment(0.0, 1.0, 1.0, 10.0, 100.0), 0.0);
    }

    #[test]
    fn corners_slow_a_run_as_much_as_their_turn_and_the_deviation_ask() {
        let along = |x: f64, y: f64| Pending {
            length: 10.0,
            speed: 10.0,
            accel: 100.0,
            unit: [x, y, 0.0],
        };
        let straight = [along(1.0, 0.0), along(1.0, 0.0)];
        let square = [along(1.0, 0.0), along(0.0, 1.0)];
        // Straight on: one move of the whole length.
        assert!((run_time(&straight, 0.05) - trapezoid(20.0, 10.0, 100.0)).abs() < 1e-12);
        // A right angle without deviation stops; with some, the corner is taken at
        // sqrt(a delta s / (1 - s)), s = sin 45 degrees.
        let stop = 2.0 * trapezoid(10.0, 10.0, 100.0);
        assert!((run_time(&square, 0.0) - stop).abs() < 1e-12);
        let s = 0.5f64.sqrt();
        let v = (100.0 * 0.05 * s / (1.0 - s)).sqrt();
        let want = 2.0 * segment(10.0, 0.0, v, 10.0, 100.0);
        assert!((run_time(&square, 0.05) - want).abs() < 1e-12);
        assert!(want < stop);
        // The same right angle between diagonals, and a turn in x-z of
        // cos theta = 0.36 - 0.64 (s = 0.6).
        let h = 0.5f64.sqrt();
        let diagonal = [along(h, h), along(h, -h)];
        assert!((run_time(&diagonal, 0.05) - want).abs() < 1e-12);
        let dive = |z: f64| Pending {
            unit: [0.6, 0.0, z],
            ..along(0.0, 0.0)
        };
        let v = (100.0f64 * 0.05 * 0.6 / 0.4).sqrt();
        let want = 2.0 * segment(10.0, 0.0, v, 10.0, 100.0);
        assert!((run_time(&[dive(0.8), dive(-0.8)], 0.05) - want).abs() < 1e-12);
        // Without deviation (exact stop) even a straight run stops at each move's end.
        assert!((run_time(&straight, 0.0) - stop).abs() < 1e-12);
        // Short moves straight on, before or after a long one: one move of the whole
        // length, each pass carrying the speed reached so far into the next junction.
        let short = |l: f64| Pending {
            length: l,
            ..along(1.0, 0.0)
        };
        let whole = trapezoid(10.02, 10.0, 100.0);
        for run in [
            [short(0.01), short(0.01), short(10.0)],
            [short(10.0), short(0.01), short(0.01)],
        ] {
            assert!((run_time(&run, 0.05) - whole).abs() < 1e-12, "{}", run[0].length);
        }
        // Turning right back stops whatever the deviation.
        assert!((run_time(&[along(1.0, 0.0), along(-1.0, 0.0)], 0.05) - stop).abs() < 1e-12);
        // A short last move caps the corner before it at the speed it can shed before
        // the run stops, however gentle the corner.
        let short = Pending {
            length: 0.01,
            ..along(0.0, 1.0)
        };
        let v = (2.0f64 * 100.0 * 0.01).sqrt();
        let want = segment(10.0, 0.0, v, 10.0, 100.0) + segment(0.01, v, 0.0, 10.0, 100.0);
        assert!((run_time(&[along(1.0, 0.0), short], 1.0) - want).abs() < 1e-12);
    }

    #[test]
    fn a_run_of_feed_moves_is_timed_when_another_line_ends_it() {
        let mut p = program("cmpm-hybrid");
        p.rapid(Some(0.0), Some(0.0), Some(1.0)).expect("in travel");
        let before = p.shares.total();
        p.doing = "mill".into();
        // Corners whose speeds depend on each move's direction in x, y and z.
        let to = [
            [10.0, 0.0, 1.0],
            [20.0, 10.0, 1.0],
            [20.0, 20.0, 2.0],
            [30.0, 20.0, 3.0],
        ];
        for [x, y, z] in to {
            p.feed(Some(x), Some(y), Some(z), 20.0).expect("in travel");
        }
        // Not timed until the run ends.
        assert_eq!(p.shares.total(), before);
        p.line("M5");
        // Each move at the acceleration the most each axis allows (500, 500 and 300
        // mm/s² over the axis's share of the direction).
        let mut from = [0.0, 0.0, 1.0];
        let moves: Vec<Pending> = to
            .iter()
            .map(|q| {
                let d = [q[0] - from[0], q[1] - from[1], q[2] - from[2]];
                from = *q;
                let length = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                let unit = d.map(|c| c / length);
                let accel = [500.0, 500.0, 300.0]
                    .iter()
                    .zip(unit)
                    .filter(|(_, u)| u.abs() > 0.0)
                    .map(|(a, u)| a / u.abs())
                    .fold(f64::INFINITY, f64::min);
                Pending {
                    length,
                    speed: 20.0,
                    accel,
                    unit,
                }
            })
            .collect();
        let want = run_time(&moves, 0.01);
        let mill = p.shares.by.iter().find(|(k, _)| k == "mill").expect("timed").1;
        assert!((mill - want).abs() < 1e-12, "{mill} {want}");
        assert!(
            p.text
                .ends_with("G1 X10 F1200\nG1 X20 Y10\nG1 Y20 Z2\nG1 X30 Z3\nM5\n"),
            "{}",
            p.text
        );
    }

    #[test]
    fn rapids_take_the_time_of_the_slowest_axis_and_two_climbs_in_z_are_one() {
        // cmpm-hybrid: rapids 6000, 6000, 3000 mm/min; accelerations 500, 500, 300 mm/s².
        let mut p = program("cmpm-hybrid");
        p.rapid(Some(0.0), Some(0.0), Some(1.0)).expect("in travel");
        p.doing = "travel".into();
        // 30 x 40: along y (0.8 of the way) the axis limits bind first.
        p.rapid(Some(30.0), Some(40.0), None).expect("in travel");
        let xy = trapezoid(50.0, 100.0 / 0.8, 500.0 / 0.8);
        let time = |p: &Program| p.shares.by.iter().find(|(k, _)| k == "travel").expect("timed").1;
        assert!((time(&p) - xy).abs() < 1e-12, "{} {xy}", time(&p));
        // Up 4, then up 5 more: one climb of 9 mm, one line.
        p.rapid(None, None, Some(5.0)).expect("in travel");
        p.rapid(None, None, Some(10.0)).expect("in travel");
        assert!(p.text.ends_with("G0 X30 Y40\nG0 Z10\n"), "{}", p.text);
        let climb = trapezoid(9.0, 50.0, 300.0);
        assert!((time(&p) - xy - climb).abs() < 1e-12, "{}", time(&p) - xy);
        // Down again is a move of its own.
        p.rapid(None, None, Some(8.0)).expect("in travel");
        assert!(p.text.ends_with("G0 Z10\nG0 Z8\n"), "{}", p.text);
        assert!((time(&p) - xy - climb - trapezoid(2.0, 50.0, 300.0)).abs() < 1e-12);
        // On down twice more: one descent from 10. Then up and over in x is a move of
        // its own.
        p.rapid(None, None, Some(3.0)).expect("in travel");
        p.rapid(None, None, Some(1.5)).expect("in travel");
        p.rapid(Some(35.0), None, Some(4.0)).expect("in travel");
        assert!(p.text.ends_with("G0 Z10\nG0 Z1.5\nG0 X35 Z4\n"), "{}", p.text);
        // 5 mm in x and 2.5 in z: x's limits bind the speed and the acceleration alike.
        let l = 31.25f64.sqrt();
        let over = trapezoid(l, 100.0 * l / 5.0, 500.0 * l / 5.0);
        let so_far = xy + climb + trapezoid(8.5, 50.0, 300.0) + over;
        assert!((time(&p) - so_far).abs() < 1e-12, "{}", time(&p) - so_far);
        // A climb, then over in x and further up: the second is not a climb alone.
        p.rapid(None, None, Some(6.0)).expect("in travel");
        p.rapid(Some(40.0), None, Some(9.0)).expect("in travel");
        assert!(p.text.ends_with("G0 X35 Z4\nG0 Z6\nG0 X40 Z9\n"), "{}", p.text);
        let l = 34f64.sqrt();
        let so_far = so_far + trapezoid(2.0, 50.0, 300.0) + trapezoid(l, 50.0 * l / 3.0, 100.0 * l);
        assert!((time(&p) - so_far).abs() < 1e-12, "{}", time(&p) - so_far);
        // From the safe height, z unknown, the way down starts at the travel's top.
        p.retract();
        let up = time(&p) - so_far;
        assert!((up - trapezoid(191.0, 50.0, 300.0)).abs() < 1e-12, "{up}");
        p.rapid(None, None, Some(2.5)).expect("in travel");
        assert!((time(&p) - so_far - up - trapezoid(197.5, 50.0, 300.0)).abs() < 1e-12);
    }

    #[test]
    fn a_tool_is_loaded_run_and_put_away_with_everything_off_at_the_safe_height() {
        let mut p = program("cmpm-hybrid");
        let start = p.text.len();
        p.change("end-mill", 1).expect("a changer");
        p.doing = "run".into();
        p.rapid(Some(1.0), Some(2.0), Some(5.0)).expect("in travel");
        p.spindle_on(24_000.0).expect("a spindle");
        p.spindle_on(24_000.0).expect("turning already");
        p.output(Some(2), true, "chip vacuum").expect("an output");
        p.output(Some(2), true, "chip vacuum").expect("on already");
        p.output(None, false, "nothing").expect("nothing to switch off");
        let err = p
            .output(None, true, "spray gun")
            .expect_err("no output")
            .to_string();
        assert!(err.contains("has no output for the spray gun"), "{err}");
        // The next tool: spindle and output off, offset cancelled, up, changed.
        p.change("end-mill", 1).expect("loaded already");
        p.change("laser", 4).expect("a changer");
        p.doing = "run".into();
        p.rapid(None, None, Some(3.0)).expect("in travel");
        p.laser_on(20.0).expect("a laser");
        p.end();
        let lines: Vec<&str> = p.text[start..].lines().collect();
        assert_eq!(
            lines,
            [
                "G53 G0 Z0",
                "(tool 1: end-mill)",
                "T1 M6",
                "G43 H1",
                "G0 X1 Y2 Z5",
                "S24000 M3",
                "M64 P2",
                "M5",
                "M65 P2",
                "G49",
                "G53 G0 Z0",
                "(tool 4: laser)",
                "T4 M6",
                "G43 H4",
                "G0 Z3",
                "M3 S20",
                "M5",
                "G49",
                "G53 G0 Z0",
                "M30",
                "%",
            ],
            "{}",
            p.text
        );
        // Two tool changes and the climb from 5 mm to the safe height (the first from
        // an unknown height takes none); the end's climb from 3 mm; one spindle start.
        let time = |k: &str| p.shares.by.iter().find(|(w, _)| w == k).map_or(0.0, |s| s.1);
        let up = |z: f64| trapezoid(200.0 - z, 50.0, 300.0);
        assert!(
            (time("tool changes") - (2.0 * 8.0 + up(5.0))).abs() < 1e-9,
            "{:?}",
            p.shares.by
        );
        assert!((time("end") - up(3.0)).abs() < 1e-12, "{:?}", p.shares.by);
        // The run: the first move from an unknown place (from the travel's corner:
        // 149, 148 and 195 mm), the spindle's start, the way down to 3 mm.
        let d = [149.0f64, 148.0, 195.0];
        let l = d.iter().map(|v| v * v).sum::<f64>().sqrt();
        let (rapid, accel) = ([100.0, 100.0, 50.0], [500.0, 500.0, 300.0]);
        let v = (0..3).map(|i| rapid[i] * l / d[i]).fold(f64::INFINITY, f64::min);
        let a = (0..3).map(|i| accel[i] * l / d[i]).fold(f64::INFINITY, f64::min);
        let run = trapezoid(l, v, a) + 2.0 + trapezoid(197.0, 50.0, 300.0);
        assert!((time("run") - run).abs() < 1e-9, "{:?}", p.shares.by);
    }

    #[test]
    fn shares_of_the_time_add_up_per_kind_in_the_order_first_met() {
        let mut shares = Shares::default();
        shares.add("spray", 2.0);
        shares.add("grind", 1.5);
        shares.add("spray", 0.5);
        assert_eq!(
            shares.by,
            vec![("spray".to_string(), 2.5), ("grind".to_string(), 1.5)]
        );
        assert_eq!(shares.total(), 4.0);
    }

    #[test]
    fn numbers_are_printed_to_a_ten_thousandth_without_trailing_zeros() {
        for (v, plain, pointed) in [
            (1.5, "1.5", "1.5"),
            (2.0, "2", "2."),
            (-1.23456, "-1.2346", "-1.2346"),
            (0.1, "0.1", "0.1"),
            (-0.5, "-0.5", "-0.5"),
            (-0.00004, "0", "0."),
            (120.00049, "120.0005", "120.0005"),
            (1e15, "1000000000000000", "1000000000000000"),
        ] {
            assert_eq!(number(v, false), plain, "{v}");
            assert_eq!(number(v, true), pointed, "{v}");
        }
    }

    #[test]
    fn a_move_is_written_only_for_what_it_changes_and_two_rises_are_one() {
        let mut p = program("cmpm-hybrid");
        p.rapid(Some(1.0), Some(2.0), Some(10.0)).expect("in travel");
        p.rapid(Some(1.0), Some(2.0), Some(10.00001)).expect("in travel");
        p.feed(Some(3.0), Some(2.0), None, 10.0).expect("in travel");
        p.feed(Some(4.0), Some(2.0), None, 10.0).expect("in travel");
        p.rapid(None, None, Some(12.0)).expect("in travel");
        p.rapid(None, None, Some(15.0)).expect("in travel");
        assert_eq!(p.text, "G0 X1 Y2 Z10\nG1 X3 F600\nG1 X4\nG0 Z15\n");
        // Up then down is two moves.
        p.rapid(None, None, Some(14.0)).expect("in travel");
        assert!(p.text.ends_with("G0 Z15\nG0 Z14\n"), "{}", p.text);
        // The merged rise takes the time of one move of 3 mm, not of two.
        let z = p.machine.motion;
        let one = trapezoid(3.0, z.rapid[2] / 60.0, z.acceleration[2]);
        let two = trapezoid(2.0, z.rapid[2] / 60.0, z.acceleration[2])
            + trapezoid(1.0, z.rapid[2] / 60.0, z.acceleration[2]);
        assert!(one < two);
        let before = p.shares.total();
        let mut q = program("cmpm-hybrid");
        q.rapid(Some(1.0), Some(2.0), Some(10.0)).expect("in travel");
        q.feed(Some(3.0), Some(2.0), None, 10.0).expect("in travel");
        q.feed(Some(4.0), Some(2.0), None, 10.0).expect("in travel");
        q.rapid(None, None, Some(15.0)).expect("in travel");
        q.rapid(None, None, Some(14.0)).expect("in travel");
        assert!((before - q.shares.total()).abs() < 1e-12);
    }

    #[test]
    fn feed_moves_run_through_corners_as_the_junction_deviation_allows() {
        let along = |x: f64, y: f64, length: f64| Pending {
            length,
            speed: 50.0,
            accel: 500.0,
            unit: [x, y, 0.0],
        };
        // A straight line in two moves takes what it takes in one.
        let one = run_time(&[along(1.0, 0.0, 20.0)], 0.01);
        let two = run_time(&[along(1.0, 0.0, 8.0), along(1.0, 0.0, 12.0)], 0.01);
        assert!((one - two).abs() < 1e-12, "{one} {two}");
        assert!((one - trapezoid(20.0, 50.0, 500.0)).abs() < 1e-12);
        // Round a square: without deviation every corner stops, with it the tool keeps
        // v = sqrt(a d sin(45) / (1 - sin(45))) through them.
        let square: Vec<Pending> = [(1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0)]
            .iter()
            .map(|&(x, y)| along(x, y, 5.0))
            .collect();
        let stops = run_time(&square, 0.0);
        assert!((stops - 4.0 * trapezoid(5.0, 50.0, 500.0)).abs() < 1e-12);
        let s = std::f64::consts::FRAC_1_SQRT_2;
        let corner = (500.0 * 0.01 * s / (1.0 - s)).sqrt();
        let rounded = run_time(&square, 0.01);
        let want = segment(5.0, 0.0, corner, 50.0, 500.0)
            + 2.0 * segment(5.0, corner, corner, 50.0, 500.0)
            + segment(5.0, corner, 0.0, 50.0, 500.0);
        assert!(
            (rounded - want).abs() < 1e-12 && rounded < stops,
            "{rounded} {want} {stops}"
        );
    }

    #[test]
    fn a_move_beyond_the_travel_is_refused_and_a_fanuc_gets_decimal_points() {
        let mut p = program("cmpm-hybrid");
        let err = p.rapid(Some(151.0), None, None).expect_err("outside").to_string();
        assert!(
            err.contains("X 151 is outside the machine `cmpm-hybrid`'s travel"),
            "{err}"
        );
        // The travel's ends themselves are in it, a ten-thousandth beyond is not.
        let [lo, hi] = p.machine.travel.y;
        p.rapid(None, Some(lo), None).expect("the low end");
        p.rapid(None, Some(hi), None).expect("the high end");
        let err = p
            .rapid(None, Some(lo - 0.0001), None)
            .expect_err("below")
            .to_string();
        assert!(err.contains("is outside the machine"), "{err}");
        // Where the tool stands in z: known after a move, unknown after a retract.
        assert_eq!(p.z(), None);
        p.rapid(None, None, Some(2.5)).expect("in travel");
        assert_eq!(p.z(), Some(2.5));
        p.retract();
        assert_eq!(p.z(), None);
        let mut f = program("cmpm-hybrid-fanuc");
        f.rapid(Some(10.0), Some(-2.5), Some(0.0)).expect("in travel");
        assert_eq!(f.text, "G0 X10. Y-2.5 Z0.\n");
        for (v, want) in [
            (-0.00001, "0"),
            (1.23456, "1.2346"),
            (-0.0001, "-0.0001"),
            (0.5, "0.5"),
            (-2.5, "-2.5"),
            (123.4, "123.4"),
            (80.32, "80.32"),
        ] {
            assert_eq!(number(v, false), want, "{v}");
            assert_eq!(number(v, false), {
                let s = format!("{v:.4}");
                let s = s.trim_end_matches('0').trim_end_matches('.').to_string();
                if s == "-0" { "0".to_string() } else { s }
            });
        }
        assert_eq!(number(10.0, true), "10.");
    }

    #[test]
    fn grbl_changes_no_tools_and_sets_no_feeders_and_says_so() {
        let mut g = program("grbl-laser");
        g.change("laser", 1).expect("the first tool is the one loaded");
        assert!(!g.text.contains("M6") && !g.text.contains("G43"), "{}", g.text);
        let err = g.change("end-mill", 2).expect_err("no changer").to_string();
        assert!(
            err.contains("cannot change tools: the program needs `laser` and `end-mill`")
                && err.contains("(grbl) has no `controller.tool_change`"),
            "{err}"
        );
        let err = g.analog(0, 5.0).expect_err("no analog").to_string();
        assert!(err.contains("cannot set the feeders' flow"), "{err}");
        g.laser_on(10.0).expect("laser mode");
        assert!(g.text.ends_with("M4 S200\n"), "{}", g.text);
    }
}
