//! How long the moves of a file take on a firmware with acceleration limits: each move
//! is a block with a trapezoidal velocity profile (accelerate, cruise, decelerate), the
//! speed through each junction is bounded by Marlin's junction deviation or by jerk,
//! and look-ahead sets the speeds at the junctions with a backward pass (every block
//! can still brake to the end) and a forward pass (every block can be reached by
//! accelerating from the previous one), as firmware planners do.
//!
//! Files have millions of moves, so blocks are planned in a window: a junction whose
//! speed is held by its own limit (the corner or the blocks' speeds) rather than by
//! braking distance no longer depends on later moves, and every block before it is
//! final. The result is the same as planning the whole file at once.

use std::collections::VecDeque;

/// Marlin's MINIMUM_PLANNER_SPEED (mm/s): the slowest junction through a reversal.
const MINIMUM_PLANNER_SPEED: f64 = 0.05;
/// Blocks kept before the window is settled.
const WINDOW: usize = 4096;
/// A window that never settles (braking decides every junction) is cut here, as if the
/// machine stopped: only an endless run of tiny accelerating moves gets this far.
const HARD_LIMIT: usize = 1 << 20;

/// How the firmware lets the head through corners.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Corner {
    /// Marlin's junction deviation (mm).
    JunctionDeviation(f64),
    /// Largest instantaneous speed change per axis X, Y, Z, E (mm/s).
    Jerk([f64; 4]),
}

/// The firmware's motion settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Acceleration of moves that extrude while the head moves (mm/s²).
    pub print: f64,
    /// Acceleration of moves without extrusion.
    pub travel: f64,
    /// Acceleration of extruder-only moves.
    pub retract: f64,
    pub corner: Corner,
    /// Per-axis speed limits X, Y, Z, E (mm/s); infinite when unset.
    pub max_speed: [f64; 4],
    /// Per-axis acceleration limits (mm/s²); infinite when unset.
    pub max_acceleration: [f64; 4],
}

impl Default for Limits {
    /// Marlin's stock settings for a small printer: 1000 mm/s², junction deviation
    /// 0.013 mm, no per-axis limits.
    fn default() -> Self {
        Self {
            print: 1000.0,
            travel: 1000.0,
            retract: 1000.0,
            corner: Corner::JunctionDeviation(0.013),
            max_speed: [f64::INFINITY; 4],
            max_acceleration: [f64::INFINITY; 4],
        }
    }
}

/// One move, planned.
#[derive(Debug, Clone, Copy)]
struct Block {
    /// Path length (mm): of X, Y, Z, or of E for an extruder-only move.
    length: f64,
    /// Cruise speed (mm/s) after the per-axis limits.
    nominal: f64,
    acceleration: f64,
    /// Highest speed at the start of this block: the junction with the previous block.
    max_entry: f64,
    /// Speed this block may start or stop at when the machine is at rest.
    rest: f64,
    entry: f64,
    /// The backward pass left `entry` at `max_entry`: later blocks cannot change it.
    settled: bool,
}

/// What the junction with the next block needs of the last one.
#[derive(Debug, Clone, Copy)]
struct Previous {
    /// Per-axis direction: delta over the path length.
    direction: [f64; 4],
    /// Unit vector of the head's motion (X, Y, Z; or E alone), for junction deviation.
    unit: [f64; 4],
    nominal: f64,
}

/// Sums the time of moves as the firmware would execute them.
#[derive(Debug, Clone)]
pub struct Planner {
    limits: Limits,
    window: VecDeque<Block>,
    /// Settled entry speed of the window's first block.
    head_entry: f64,
    previous: Option<Previous>,
    time: f64,
    window_size: usize,
}

impl Planner {
    pub fn new(limits: Limits) -> Self {
        Self {
            limits,
            window: VecDeque::new(),
            head_entry: 0.0,
            previous: None,
            time: 0.0,
            window_size: WINDOW,
        }
    }

    /// Settings for the moves that follow (the firmware applies `M204` and the like to
    /// blocks planned after it).
    pub fn set_limits(&mut self, limits: Limits) {
        self.limits = limits;
    }

    pub fn limits(&self) -> &Limits {
        &self.limits
    }

    /// Adds a move of `delta` (X, Y, Z, E in mm) at `feed` (mm/s).
    pub fn push(&mut self, delta: [f64; 4], feed: f64) {
        let xyz = (delta[0] * delta[0] + delta[1] * delta[1] + delta[2] * delta[2]).sqrt();
        let (length, unit) = if xyz > 1e-9 {
            (xyz, [delta[0] / xyz, delta[1] / xyz, delta[2] / xyz, 0.0])
        } else if delta[3].abs() > 1e-9 {
            (delta[3].abs(), [0.0, 0.0, 0.0, delta[3].signum()])
        } else {
            return;
        };
        let direction = delta.map(|d| d / length);
        let l = &self.limits;
        let mut nominal = feed.max(MINIMUM_PLANNER_SPEED);
        let mut acceleration = if delta[3] == 0.0 {
            l.travel
        } else if xyz <= 1e-9 {
            l.retract
        } else {
            l.print
        };
        for (a, d) in direction.iter().enumerate() {
            let d = d.abs();
            if d > 0.0 {
                nominal = nominal.min(l.max_speed[a] / d);
                acceleration = acceleration.min(l.max_acceleration[a] / d);
            }
        }
        let rest = self.rest_speed(&direction, nominal);
        let max_entry = match self.previous {
            None => rest,
            Some(p) => self.junction(&p, &direction, &unit, nominal, acceleration),
        };
        self.window.push_back(Block {
            length,
            nominal,
            acceleration,
            max_entry,
            rest,
            entry: max_entry,
            settled: false,
        });
        if self.window.len() == 1 && self.previous.is_none() {
            self.head_entry = rest;
        }
        self.previous = Some(Previous {
            direction,
            unit,
            nominal,
        });
        if self.window.len() >= self.window_size {
            self.settle();
        }
    }

    /// Speed a block may start from (or end at) standing still: 0 with junction
    /// deviation, the jerk of its axes otherwise.
    fn rest_speed(&self, direction: &[f64; 4], nominal: f64) -> f64 {
        match self.limits.corner {
            Corner::JunctionDeviation(_) => 0.0,
            Corner::Jerk(jerk) => (0..4)
                .filter(|&a| direction[a].abs() > 0.0)
                .fold(nominal, |v, a| v.min(jerk[a] / direction[a].abs())),
        }
    }

    /// The highest speed through the junction of `p` and the next block.
    fn junction(
        &self,
        p: &Previous,
        direction: &[f64; 4],
        unit: &[f64; 4],
        nominal: f64,
        acceleration: f64,
    ) -> f64 {
        let cap = p.nominal.min(nominal);
        match self.limits.corner {
            Corner::JunctionDeviation(deviation) => {
                let cos_theta = -(0..4).map(|a| p.unit[a] * unit[a]).sum::<f64>();
                if cos_theta > 0.999_999 {
                    MINIMUM_PLANNER_SPEED.min(cap)
                } else if cos_theta < -0.999_999 {
                    cap
                } else {
                    let sin_theta_d2 = (0.5 * (1.0 - cos_theta)).sqrt();
                    let v2 = acceleration * deviation * sin_theta_d2 / (1.0 - sin_theta_d2);
                    v2.sqrt().min(cap)
                }
            }
            Corner::Jerk(jerk) => (0..4).fold(cap, |v, a| {
                let change = (direction[a] - p.direction[a]).abs();
                if change * v > jerk[a] { jerk[a] / change } else { v }
            }),
        }
    }

    /// The machine stops (a dwell, a heater wait, a tool change): every block is final.
    pub fn stop(&mut self) {
        self.plan(self.window.len());
        self.previous = None;
    }

    /// Waits `seconds` standing still.
    pub fn dwell(&mut self, seconds: f64) {
        self.stop();
        if seconds.is_finite() && seconds > 0.0 {
            self.time += seconds;
        }
    }

    /// Seconds of the moves so far without stopping the machine: those still open to
    /// look-ahead at their cruise speed. For what runs beside the motion, such as a
    /// heater set by one line and waited for many moves later.
    pub fn elapsed(&self) -> f64 {
        self.time
            + self
                .window
                .iter()
                .map(|b| {
                    if b.nominal > 0.0 {
                        b.length / b.nominal
                    } else {
                        0.0
                    }
                })
                .sum::<f64>()
    }

    /// Seconds of every move so far, as if the machine stopped after the last one.
    pub fn total(&mut self) -> f64 {
        self.stop();
        self.time
    }

    /// Plans the window with the machine stopping after its last block, and times the
    /// blocks whose speeds later blocks can no longer change.
    fn settle(&mut self) {
        let last_settled = self.backward();
        match last_settled {
            Some(k) if k > 0 => self.forward_and_time(k),
            _ if self.window.len() >= HARD_LIMIT => self.plan(self.window.len()),
            _ => {}
        }
    }

    /// Plans and times the first `n` blocks as if the machine stopped after them.
    fn plan(&mut self, n: usize) {
        if n == 0 {
            return;
        }
        debug_assert_eq!(n, self.window.len());
        self.backward();
        self.forward_and_time(n);
        self.head_entry = 0.0;
    }

    /// Backward pass: each entry is at most what brakes to the next block's entry (to
    /// the last block's rest speed at the end). Returns the last block whose entry its
    /// own junction limits.
    fn backward(&mut self) -> Option<usize> {
        let n = self.window.len();
        let mut exit = self.window.back().map_or(0.0, |b| b.rest);
        let mut last_settled = None;
        for i in (0..n).rev() {
            let b = &mut self.window[i];
            let reachable = (exit * exit + 2.0 * b.acceleration * b.length).sqrt();
            b.settled = b.max_entry <= reachable;
            b.entry = b.max_entry.min(reachable);
            if b.settled && last_settled.is_none() {
                last_settled = Some(i);
            }
            exit = b.entry;
        }
        if let Some(first) = self.window.front_mut() {
            first.entry = first.entry.min(self.head_entry);
        }
        last_settled
    }

    /// Forward pass over the first `k` blocks (each entry at most what accelerating
    /// from the previous one reaches), then their times; they leave the window.
    fn forward_and_time(&mut self, k: usize) {
        let n = self.window.len();
        for i in 0..k.min(n) {
            let b = self.window[i];
            let exit_cap = (b.entry * b.entry + 2.0 * b.acceleration * b.length).sqrt();
            let exit = if i + 1 < n {
                let next = &mut self.window[i + 1];
                next.entry = next.entry.min(exit_cap);
                next.entry
            } else {
                b.rest.min(exit_cap)
            };
            self.time += trapezoid(b.length, b.entry, exit, b.nominal, b.acceleration);
        }
        self.window.drain(..k.min(n));
        if let Some(first) = self.window.front() {
            self.head_entry = first.entry;
        }
    }
}

/// Time of a block of `length` entered at `v0`, left at `v1`, cruising at most at
/// `vn`, accelerating and braking at `a`.
pub fn trapezoid(length: f64, v0: f64, v1: f64, vn: f64, a: f64) -> f64 {
    let vn = vn.max(v0).max(v1);
    let accelerate = (vn * vn - v0 * v0) / (2.0 * a);
    let brake = (vn * vn - v1 * v1) / (2.0 * a);
    if accelerate + brake <= length {
        (vn - v0) / a + (vn - v1) / a + (length - accelerate - brake) / vn
    } else {
        // Never reaches the cruise speed: accelerate to the peak, then brake.
        let peak = ((2.0 * a * length + v0 * v0 + v1 * v1) / 2.0)
            .sqrt()
            .max(v0)
            .max(v1);
        (peak - v0) / a + (peak - v1) / a
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() <= 1e-9 * b.abs().max(1.0)
    }

    fn jd(a: f64, deviation: f64) -> Limits {
        Limits {
            print: a,
            travel: a,
            retract: a,
            corner: Corner::JunctionDeviation(deviation),
            ..Limits::default()
        }
    }

    #[test]
    fn a_single_long_move_accelerates_cruises_and_brakes() {
        let mut p = Planner::new(jd(1000.0, 0.013));
        p.push([100.0, 0.0, 0.0, 0.0], 50.0);
        // 0.05 s to 50 mm/s over 1.25 mm, the same to stop, 97.5 mm at 50 mm/s.
        assert!(close(p.total(), 0.05 + 0.05 + 97.5 / 50.0), "{}", p.time);
    }

    #[test]
    fn a_short_move_never_cruises() {
        let mut p = Planner::new(jd(1000.0, 0.013));
        p.push([1.0, 0.0, 0.0, 0.0], 100.0);
        // Peak sqrt(a L) = 31.62 mm/s, reached and lost at 1000 mm/s².
        assert!(close(p.total(), 2.0 * (1000.0f64).sqrt() / 1000.0));
    }

    #[test]
    fn a_square_corner_slows_to_the_junction_deviation_speed() {
        let (a, d, v) = (1000.0, 0.05, 50.0);
        let mut p = Planner::new(jd(a, d));
        p.push([20.0, 0.0, 0.0, 0.0], v);
        p.push([0.0, 20.0, 0.0, 0.0], v);
        // 90°: cos θ = 0, sin(θ/2) = √½, v_j² = a d sin / (1 - sin).
        let s = 0.5f64.sqrt();
        let vj = (a * d * s / (1.0 - s)).sqrt();
        let leg = trapezoid(20.0, 0.0, vj, v, a);
        assert!(vj < v);
        assert!(close(p.total(), 2.0 * leg), "{} vs {}", p.time, 2.0 * leg);
    }

    #[test]
    fn collinear_moves_take_as_long_as_one() {
        let mut one = Planner::new(jd(800.0, 0.013));
        one.push([30.0, 40.0, 0.0, 2.0], 60.0);
        let mut ten = Planner::new(jd(800.0, 0.013));
        for _ in 0..10 {
            ten.push([3.0, 4.0, 0.0, 0.2], 60.0);
        }
        assert!(close(one.total(), ten.total()), "{} vs {}", one.time, ten.time);
    }

    #[test]
    fn a_reversal_stops() {
        let mut p = Planner::new(jd(1000.0, 0.013));
        p.push([10.0, 0.0, 0.0, 0.0], 50.0);
        p.push([-10.0, 0.0, 0.0, 0.0], 50.0);
        let leg = trapezoid(10.0, 0.0, MINIMUM_PLANNER_SPEED, 50.0, 1000.0);
        assert!(close(p.total(), 2.0 * leg));
    }

    #[test]
    fn axis_limits_cap_speed_and_acceleration() {
        let mut limits = jd(1000.0, 0.013);
        limits.max_speed = [300.0, 300.0, 10.0, 50.0];
        limits.max_acceleration = [3000.0, 3000.0, 100.0, 3000.0];
        let mut p = Planner::new(limits);
        p.push([0.0, 0.0, 5.0, 0.0], 50.0);
        assert!(close(p.total(), trapezoid(5.0, 0.0, 0.0, 10.0, 100.0)));
    }

    #[test]
    fn extruder_only_moves_use_the_retract_acceleration() {
        let mut limits = jd(1000.0, 0.013);
        limits.retract = 250.0;
        let mut p = Planner::new(limits);
        p.push([0.0, 0.0, 0.0, -2.0], 40.0);
        assert!(close(p.total(), trapezoid(2.0, 0.0, 0.0, 40.0, 250.0)));
    }

    #[test]
    fn jerk_lets_a_gentle_corner_through_at_speed() {
        let limits = Limits {
            corner: Corner::Jerk([10.0, 10.0, 0.4, 5.0]),
            ..jd(1000.0, 0.0)
        };
        let mut p = Planner::new(limits);
        // From rest the block may start at the jerk speed of its axis.
        p.push([50.0, 0.0, 0.0, 0.0], 50.0);
        let single = p.clone().total();
        assert!(close(single, trapezoid(50.0, 10.0, 10.0, 50.0, 1000.0)));
        // A 5° turn changes Y by 50 sin 5° = 4.4 mm/s < 10: no slowing at the corner.
        let t = 5f64.to_radians();
        p.push([50.0 * t.cos(), 50.0 * t.sin(), 0.0, 0.0], 50.0);
        // It may stop from 10 / cos 5° on X, its larger axis.
        let rest = 10.0 / t.cos();
        let expected = trapezoid(50.0, 10.0, 50.0, 50.0, 1000.0) + trapezoid(50.0, 50.0, rest, 50.0, 1000.0);
        assert!(close(p.total(), expected), "{} vs {expected}", p.time);
    }

    #[test]
    fn dwells_and_stops_add_up() {
        let mut p = Planner::new(jd(1000.0, 0.013));
        p.push([100.0, 0.0, 0.0, 0.0], 50.0);
        p.dwell(2.5);
        p.push([100.0, 0.0, 0.0, 0.0], 50.0);
        assert!(close(p.total(), 2.0 * 2.05 + 2.5));
    }

    /// The windowed planner gives the time of planning everything at once.
    #[test]
    fn the_window_changes_nothing() {
        let mut rng = fastrand::Rng::with_seed(0x9E37_79B9_7F4A_7C15);
        let mut next = move || rng.f64();
        let moves: Vec<([f64; 4], f64)> = (0..20_000)
            .map(|i| {
                let long = i % 97 == 0;
                let scale = if long { 80.0 } else { 2.0 };
                let d = [
                    (next() - 0.5) * scale,
                    (next() - 0.3) * scale,
                    if i % 500 == 0 { 0.2 } else { 0.0 },
                    if i % 7 == 0 { 0.0 } else { next() * 0.1 },
                ];
                (d, 20.0 + next() * 100.0)
            })
            .collect();
        for corner in [
            Corner::JunctionDeviation(0.02),
            Corner::Jerk([8.0, 8.0, 0.4, 5.0]),
        ] {
            let limits = Limits {
                corner,
                max_speed: [200.0, 200.0, 10.0, 60.0],
                ..jd(1500.0, 0.02)
            };
            let mut windowed = Planner::new(limits);
            windowed.window_size = 64;
            let mut whole = Planner::new(limits);
            whole.window_size = usize::MAX;
            for (d, f) in &moves {
                windowed.push(*d, *f);
                whole.push(*d, *f);
            }
            let (a, b) = (windowed.total(), whole.total());
            assert!((a - b).abs() <= 1e-6 * b, "{a} vs {b}");
        }
    }
}
