//! The machine's moves, read back from a written G-code file for the viewer: what the
//! firmware will do with the file, not what the planner meant, so a user sees the
//! moves, tool changes and waits the printer gets.
//!
//! The reading follows the firmware's documented semantics, not Lamina's exporter:
//!
//! - `G0`/`G1` move linearly to the given axes (`G2`/`G3` are taken as straight moves to
//!   their end points); `G90`/`G91` set absolute/relative axes and `M82`/`M83` the
//!   extruder's mode (Marlin's and RepRapFirmware's rule: `G90`/`G91` set both, `M82`/
//!   `M83` then the extruder alone); `G92` sets positions; `F` is modal, in mm/min.
//! - `T<n>` selects the tool of the current motion system; `G4 P<ms>`/`S<s>` dwell.
//! - RepRapFirmware 3.5's multiple motion systems: `M596 P<n>` sends what follows to
//!   motion system `n`; each system keeps its own modes, feed rate, positions and tool.
//!   `M598`, `M400`, `G4` without a time and `M0`-`M2` are read by every system and are
//!   synchronisation points: every system there waits for the last to arrive (a `G4`
//!   with a time is a dwell of its own system). A system whose moves name `U`/`V` is
//!   drawn at (U, V), otherwise at (X, Y).
//! - Layers are the `;LAYER:<n>` comments (the convention most G-code viewers read);
//!   moves before the first one (homing, priming) are not layers.
//!
//! Time is distance over the feed rate, without acceleration: the viewer plays the moves
//! in their order and proportions, and the waits at synchronisation points; it is not a
//! build-time estimate.

use std::collections::BTreeMap;

/// One straight move of one head.
#[derive(Debug, Clone, PartialEq)]
pub struct Move {
    pub system: usize,
    pub tool: usize,
    /// Extruding (the extruder advanced while the head moved in X-Y).
    pub extrude: bool,
    pub from: [f64; 2],
    pub to: [f64; 2],
    /// Start and end, seconds from the start of the job.
    pub t0: f64,
    pub t1: f64,
}

/// The moves of a file by layer (`;LAYER:` number), each system's in its order: the
/// whole file at once, for the tests.
#[cfg(test)]
#[derive(Debug, Default)]
pub struct Moves {
    pub layers: BTreeMap<usize, Vec<Move>>,
    /// Motion systems the file uses.
    pub systems: usize,
    /// The offset the exporter placed the plan by on the bed (its `; coordinates:`
    /// comment), so the moves can be drawn over the plan; zero when not given.
    pub offset: [f64; 2],
}

/// What one motion system does, before the systems are put on one clock.
#[derive(Debug, Clone)]
enum Step {
    Move {
        m: Move,
        seconds: f64,
        layer: Option<usize>,
    },
    Wait(f64),
    /// The n-th synchronisation point of the file.
    Sync(usize),
    /// A forked system starts when system 0 has done this many steps (`M606`).
    Start(usize),
}

/// One motion system's reader state.
#[derive(Debug, Clone)]
struct System {
    axes: BTreeMap<char, f64>,
    relative: bool,
    relative_e: bool,
    /// mm/min; RepRapFirmware's default for a new reader.
    feed: f64,
    tool: usize,
    uses_uv: bool,
    layer: Option<usize>,
    steps: Vec<Step>,
}

impl System {
    fn new() -> Self {
        System {
            axes: BTreeMap::new(),
            relative: false,
            relative_e: false,
            feed: 3000.0,
            tool: 0,
            uses_uv: false,
            layer: None,
            steps: Vec::new(),
        }
    }

    fn head(&self) -> [f64; 2] {
        let (x, y) = if self.uses_uv { ('U', 'V') } else { ('X', 'Y') };
        [
            self.axes.get(&x).copied().unwrap_or(0.0),
            self.axes.get(&y).copied().unwrap_or(0.0),
        ]
    }

    fn linear(&mut self, words: &[(char, f64)]) {
        if let Some(&(_, f)) = words.iter().find(|(c, _)| *c == 'F')
            && f > 0.0
        {
            self.feed = f;
        }
        if words.iter().any(|(c, _)| matches!(c, 'U' | 'V')) {
            self.uses_uv = true;
        }
        let from = self.head();
        let mut travelled = 0.0;
        let mut e = 0.0;
        for &(c, v) in words {
            if !matches!(c, 'X' | 'Y' | 'Z' | 'U' | 'V' | 'E') {
                continue;
            }
            let old = self.axes.get(&c).copied().unwrap_or(0.0);
            let relative = if c == 'E' { self.relative_e } else { self.relative };
            let new = if relative { old + v } else { v };
            self.axes.insert(c, new);
            if c == 'E' {
                e = new - old;
            } else {
                travelled += (new - old) * (new - old);
            }
        }
        let to = self.head();
        let length = travelled.sqrt();
        let seconds = if length > 0.0 { length } else { e.abs() } / (self.feed / 60.0);
        let moved = (to[0] - from[0]).hypot(to[1] - from[1]) > 0.0;
        let m = Move {
            system: 0,
            tool: self.tool,
            extrude: moved && e > 0.0,
            from,
            to,
            t0: 0.0,
            t1: 0.0,
        };
        self.steps.push(Step::Move {
            m,
            seconds: if seconds.is_finite() { seconds } else { 0.0 },
            layer: self.layer,
        });
    }
}

/// The words of a line without its comment, line number and checksum: `G1 X1 Y2` →
/// `[('G', 1), ('X', 1), ('Y', 2)]`. Words that are not a letter and a number are
/// skipped (a firmware would refuse the line; the viewer shows what it can).
fn words(line: &str) -> Vec<(char, f64)> {
    let code = line.split(';').next().unwrap_or("");
    let code = code.split('*').next().unwrap_or("");
    let mut out = Vec::new();
    let mut chars = code.char_indices().peekable();
    while let Some((i, c)) = chars.next() {
        if !c.is_ascii_alphabetic() {
            continue;
        }
        let start = i + 1;
        let mut end = start;
        while let Some(&(j, d)) = chars.peek() {
            if d.is_ascii_digit() || matches!(d, '.' | '-' | '+') {
                end = j + 1;
                chars.next();
            } else {
                break;
            }
        }
        if let Ok(v) = code[start..end].parse::<f64>()
            && v.is_finite()
        {
            out.push((c.to_ascii_uppercase(), v));
        }
    }
    // A line number is not the command.
    if out.first().is_some_and(|(c, _)| *c == 'N') {
        out.remove(0);
    }
    out
}

/// `; coordinates: ... by X+150.000 Y+150.000` → the offset.
fn offset(line: &str) -> Option<[f64; 2]> {
    let rest = line.strip_prefix("; coordinates:")?;
    let by = rest.rsplit(" by ").next()?;
    let mut it = by.split_whitespace();
    let x = it.next()?.strip_prefix('X')?.parse().ok()?;
    let y = it.next()?.strip_prefix('Y')?.parse().ok()?;
    Some([x, y])
}

/// Reads a G-code file's moves at once. Unknown commands are skipped.
#[cfg(test)]
pub fn read(text: &str) -> Moves {
    let mut moves = Moves::default();
    let mut reader = Reader::new();
    let mut keep =
        |layer: usize, list: Vec<Move>, _: [f64; 2]| moves.layers.entry(layer).or_default().extend(list);
    for line in text.lines() {
        reader.line(line, &mut keep);
    }
    let (systems, offset) = reader.finish(&mut keep);
    moves.systems = systems;
    moves.offset = offset;
    moves
}

/// Reads a G-code file line by line and hands over each layer's moves as soon as no
/// motion system can add to it, so that a file of any size is read in the memory of a
/// few layers. Layers are taken to come in the file's order (each system's `;LAYER:`
/// numbers do not go back), as Lamina's files and the common slicers' write them.
pub struct Reader {
    systems: Vec<System>,
    /// The system the lines are for (`M596`).
    current: usize,
    barriers: usize,
    placed: [f64; 2],
    /// Each system's clock and how many of its steps are not yet on it (`steps[..at]`
    /// are done and dropped as the reading goes on).
    time: Vec<f64>,
    at: Vec<usize>,
    /// Steps system 0 has done, and its clock after the steps a forked system waits
    /// for (`Step::Start`).
    done0: usize,
    starts: BTreeMap<usize, f64>,
    /// Moves on the clock whose layers may still grow.
    pending: BTreeMap<usize, Vec<Move>>,
    /// Lines since the steps were last put on the clock.
    unclocked: usize,
}

/// How many lines are read between two passes of the clock: the pass is cheap, and
/// this keeps what waits for it small.
const CLOCK_EVERY: usize = 4096;

impl Default for Reader {
    fn default() -> Self {
        Self::new()
    }
}

impl Reader {
    pub fn new() -> Self {
        Reader {
            systems: vec![System::new()],
            current: 0,
            barriers: 0,
            placed: [0.0, 0.0],
            time: vec![0.0],
            at: vec![0],
            done0: 0,
            starts: BTreeMap::new(),
            pending: BTreeMap::new(),
            unclocked: 0,
        }
    }

    /// Reads one line; `out` gets every layer completed by it, with its moves and the
    /// offset the exporter placed the plan by (its `; coordinates:` comment, before
    /// any layer).
    pub fn line(&mut self, line: &str, out: &mut impl FnMut(usize, Vec<Move>, [f64; 2])) {
        let line = line.trim();
        if let Some(rest) = line.strip_prefix(";LAYER:") {
            let n = rest.split_whitespace().next().and_then(|n| n.parse().ok());
            self.systems[self.current].layer = n;
            // A new layer is where earlier ones may be done.
            self.clock();
            self.hand_over(out, false);
            return;
        }
        if let Some(o) = offset(line) {
            self.placed = o;
            return;
        }
        self.command(line);
        self.unclocked += 1;
        if self.unclocked >= CLOCK_EVERY {
            self.clock();
        }
    }

    /// Ends the reading: `out` gets the layers left. Returns the number of motion
    /// systems the file used and the offset the exporter placed the plan by.
    pub fn finish(mut self, out: &mut impl FnMut(usize, Vec<Move>, [f64; 2])) -> (usize, [f64; 2]) {
        self.clock();
        self.hand_over(out, true);
        (self.systems.len(), self.placed)
    }

    fn command(&mut self, line: &str) {
        let w = words(line);
        let Some(&(letter, number)) = w.first() else {
            return;
        };
        // Commands with a fraction (`G29.1`) are none the viewer needs.
        if number.fract() != 0.0 || !(-1.0..1e6).contains(&number) {
            return;
        }
        let number = number as i64;
        let rest = &w[1..];
        let arg = |c: char| rest.iter().find(|(l, _)| *l == c).map(|&(_, v)| v);
        // The fork: RepRapFirmware 3.5 has two motion systems, and the second starts
        // reading here, with the first's modes, while the first goes on.
        if (letter, number) == ('M', 606) {
            if self.systems.len() < 2 {
                self.fork();
            }
            return;
        }
        let s = &mut self.systems[self.current];
        match (letter, number) {
            ('G', 0..=3) => s.linear(rest),
            ('G', 4) => {
                let seconds = arg('P').map(|p| p / 1000.0).or(arg('S')).unwrap_or(0.0);
                if seconds > 0.0 {
                    s.steps.push(Step::Wait(seconds));
                } else {
                    self.sync();
                }
            }
            ('G', 90) => (s.relative, s.relative_e) = (false, false),
            ('G', 91) => (s.relative, s.relative_e) = (true, true),
            ('G', 92) => {
                for &(c, v) in rest {
                    s.axes.insert(c, v);
                }
            }
            ('M', 82) => s.relative_e = false,
            ('M', 83) => s.relative_e = true,
            ('M', 400 | 598) => self.sync(),
            ('M', 0..=2) => {
                self.sync();
                self.current = 0;
            }
            ('M', 596) => {
                let p = arg('P').unwrap_or(0.0);
                // More systems than RepRapFirmware's two are taken as given, within
                // reason; one named before any fork starts where the file is.
                if (0.0..8.0).contains(&p) {
                    self.current = p as usize;
                    while self.systems.len() <= self.current {
                        self.fork();
                    }
                }
            }
            ('T', n) if n >= 0 => s.tool = n as usize,
            _ => {}
        }
    }

    /// A new motion system forked from system 0 where system 0's reading now is: its
    /// modes, positions and tool, and a clock that starts when system 0 gets here.
    fn fork(&mut self) {
        let first = &self.systems[0];
        let mut s = first.clone();
        let n = self.done0 + first.steps.len();
        s.steps = vec![Step::Start(n)];
        s.layer = None;
        s.uses_uv = false;
        self.systems.push(s);
        self.time.push(0.0);
        self.at.push(0);
        if n == self.done0 {
            self.starts.insert(n, self.time[0]);
        }
    }

    /// A synchronisation point for every system.
    fn sync(&mut self) {
        for s in &mut self.systems {
            s.steps.push(Step::Sync(self.barriers));
        }
        self.barriers += 1;
    }

    /// Puts the steps read so far on one clock: each system runs on until its next
    /// synchronisation point; when every system that has one left is at it, all go on
    /// from the latest arrival. Steps done are dropped.
    fn clock(&mut self) {
        self.unclocked = 0;
        let n = self.systems.len();
        loop {
            // Every system runs on to its next synchronisation point (or its last
            // step read).
            let mut next = vec![None; n];
            for (k, waits_at) in next.iter_mut().enumerate() {
                while let Some(step) = self.systems[k].steps.get(self.at[k]) {
                    match step {
                        Step::Move { m, seconds, layer } => {
                            let t0 = self.time[k];
                            self.time[k] += seconds;
                            if let Some(layer) = *layer
                                && m.from != m.to
                            {
                                self.pending.entry(layer).or_default().push(Move {
                                    system: k,
                                    t0,
                                    t1: self.time[k],
                                    ..m.clone()
                                });
                            }
                        }
                        Step::Wait(seconds) => self.time[k] += seconds,
                        Step::Sync(b) => {
                            *waits_at = Some(*b);
                            break;
                        }
                        Step::Start(s) => match self.starts.get(s) {
                            Some(&t) => self.time[k] = self.time[k].max(t),
                            // System 0 is held at a point before the fork.
                            None => break,
                        },
                    }
                    self.at[k] += 1;
                    if k == 0 {
                        self.step_done0();
                    }
                }
            }
            // The earliest point in the file any system waits at: the systems there
            // meet (a system started after it never had it).
            let Some(first) = next.iter().flatten().min().copied() else {
                break;
            };
            let meet = (0..n)
                .filter(|&k| next[k] == Some(first))
                .map(|k| self.time[k])
                .fold(0.0, f64::max);
            for (k, waits_at) in next.iter().enumerate() {
                if *waits_at == Some(first) {
                    self.time[k] = meet;
                    self.at[k] += 1;
                    if k == 0 {
                        self.step_done0();
                    }
                }
            }
        }
        for (s, at) in self.systems.iter_mut().zip(&mut self.at) {
            s.steps.drain(..*at);
            *at = 0;
        }
    }

    /// Counts a step of system 0 done, noting its clock where a fork waits for it.
    fn step_done0(&mut self) {
        self.done0 += 1;
        if self.systems.len() > 1 {
            let waited = self.systems[1..]
                .iter()
                .any(|s| matches!(s.steps.first(), Some(Step::Start(n)) if *n == self.done0));
            if waited {
                self.starts.insert(self.done0, self.time[0]);
            }
        }
    }

    /// Hands `out` each layer no system can add to any more: below every layer a
    /// system still has steps in, or is reading; every layer at the end.
    fn hand_over(&mut self, out: &mut impl FnMut(usize, Vec<Move>, [f64; 2]), all: bool) {
        let open = if all {
            usize::MAX
        } else {
            self.systems
                .iter()
                .map(|s| {
                    let waiting = s.steps.iter().find_map(|step| match step {
                        Step::Move { layer, .. } => *layer,
                        _ => None,
                    });
                    waiting.or(s.layer).unwrap_or(usize::MAX)
                })
                .min()
                .unwrap_or(usize::MAX)
        };
        while let Some(entry) = self.pending.first_entry() {
            if *entry.key() >= open {
                break;
            }
            let (layer, mut list) = entry.remove_entry();
            // Each system's moves stay in order; systems follow one another.
            list.sort_by_key(|m| m.system);
            out(layer, list, self.placed);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The second system starts where the job forks, not at the job's start: system
    /// 0 moves 2 s before `M606`, so system 1's first move starts at 2 s.
    #[test]
    fn a_forked_system_starts_at_the_fork() {
        let text = "G90\nM83\nG1 X20 Y0 F600\nM606 S1\nM596 P1\n;LAYER:0\nG1 U10 V0 F600\n";
        let m = read(text);
        let l = &m.layers[&0];
        assert_eq!(l.len(), 1);
        assert!(
            (l[0].t0 - 2.0).abs() < 1e-9 && (l[0].t1 - 3.0).abs() < 1e-9,
            "{l:?}"
        );
    }

    /// Each layer is handed over once no system can add to it, not at the end: the
    /// reader holds a few layers, whatever the file's size.
    #[test]
    fn layers_are_handed_over_as_soon_as_every_system_is_past_them() {
        let mut reader = Reader::new();
        let mut got: Vec<(usize, usize)> = Vec::new();
        let mut lines = 0;
        let mut feed = |reader: &mut Reader, text: &str, got: &mut Vec<(usize, usize)>| {
            for line in text.lines() {
                lines += 1;
                reader.line(line, &mut |layer, list, _| got.push((layer, list.len())));
            }
        };
        feed(
            &mut reader,
            "G90\nM83\n;LAYER:0\nG1 X10 Y0 E1 F600\n;LAYER:1\n",
            &mut got,
        );
        assert_eq!(got, vec![(0, 1)]);
        feed(
            &mut reader,
            "G1 X10 Y10 E1\nG1 X0 Y10 E1\n;LAYER:2\nG1 X0 Y0\n",
            &mut got,
        );
        assert_eq!(got, vec![(0, 1), (1, 2)]);
        reader.finish(&mut |layer, list, _| got.push((layer, list.len())));
        assert_eq!(got, vec![(0, 1), (1, 2), (2, 1)]);
        // Two systems: system 0 past layer 0 does not close it while system 1 is in
        // it.
        let mut reader = Reader::new();
        let mut got = Vec::new();
        feed(
            &mut reader,
            "G90\nM83\nM606 S1\nM596 P0\n;LAYER:0\nG1 X20 Y0 E1 F600\nM596 P1\n;LAYER:0\nG1 U10 V0 F600\nM596 P0\n;LAYER:1\nG1 X0 Y0 E1\n",
            &mut got,
        );
        assert!(got.is_empty(), "{got:?}");
        feed(&mut reader, "M596 P1\n;LAYER:1\n", &mut got);
        assert_eq!(got, vec![(0, 2)]);
        assert!(lines > 0);
    }

    #[test]
    fn words_skip_comments_line_numbers_and_checksums() {
        assert_eq!(
            words("N12 G1 X1.5 Y-2 E.3*57 ; move"),
            vec![('G', 1.0), ('X', 1.5), ('Y', -2.0), ('E', 0.3)]
        );
        assert_eq!(words("; only a comment"), vec![]);
    }

    #[test]
    fn extrusion_follows_the_extruder_modes_and_g92() {
        let text = "; coordinates: placed on the bed of machine `m` by X+10.000 Y-5.500\n\
                    G90\nM82\nG92 E0\nG1 X0 Y0 F6000\n;LAYER:0 Z0.2\n\
                    G1 X10 Y0 E1 F600\nG1 X10 Y10 E1\nG92 E0\nG1 X0 Y10 E0.5\n\
                    M83\nG1 X0 Y0 E0.5\nG1 E-0.8\nG1 X5 Y5\nG91\nG1 X1 Y1 E0.1\n";
        let m = read(text);
        assert_eq!(m.offset, [10.0, -5.5]);
        let l = &m.layers[&0];
        let kinds: Vec<bool> = l.iter().map(|m| m.extrude).collect();
        // extrude, travel (E unchanged), extrude after G92, extrude (relative),
        // travel, extrude (all relative).
        assert_eq!(kinds, vec![true, false, true, true, false, true]);
        assert_eq!(l[5].to, [6.0, 6.0]);
        // 10 mm at 600 mm/min.
        assert!((l[0].t1 - l[0].t0 - 1.0).abs() < 1e-9);
    }

    #[test]
    fn motion_systems_run_at_once_and_meet_at_m598() {
        // System 0 reaches its barrier after 4 s, system 1 after 1 s; then both go on.
        let text = "G90\nM83\nM606 S1\nM596 P1\nG90\nM83\nM596 P0\n\
                    ;LAYER:0\nT0\nG1 X20 Y0 F600\nG1 X40 Y0 E1\n\
                    M596 P1\n;LAYER:0\nT1\nG1 U10 V0 F600\n\
                    M598\n\
                    M596 P0\nG1 X60 Y0 E1\nM596 P1\nG1 U10 V10 E1\n";
        let m = read(text);
        assert_eq!(m.systems, 2);
        let l = &m.layers[&0];
        let s1: Vec<&Move> = l.iter().filter(|m| m.system == 1).collect();
        assert_eq!(s1.len(), 2);
        assert_eq!((s1[0].tool, s1[0].from, s1[0].to), (1, [0.0, 0.0], [10.0, 0.0]));
        assert!((s1[0].t0, s1[0].t1) == (0.0, 1.0));
        // System 1 waited 1 s at the barrier for system 0.
        assert!(
            (s1[1].t0 - 4.0).abs() < 1e-9 && (s1[1].t1 - 5.0).abs() < 1e-9,
            "{s1:?}"
        );
        let s0: Vec<&Move> = l.iter().filter(|m| m.system == 0).collect();
        assert!((s0[2].t0 - 4.0).abs() < 1e-9, "{s0:?}");
        assert!(s0.iter().all(|m| m.tool == 0));
    }
}
