//! Jobs for a machine with two motion systems (RepRapFirmware 3.5, "Multiple motion
//! systems"): each head's paths go to its own motion system, and the concurrent plan's
//! timing is kept by synchronisation points, not by dwells.
//!
//! After the start (homing, heating, on motion system 0) `M606 S1` forks the job: each
//! motion system reads the file on its own, and `M596 P<n>` says which one the next
//! lines are for. Motion system `n` drives head `n`, on the axis letters of its profile
//! (the second head's X and Y are written as its own letters, U and V say). `M598`
//! makes each system wait for the other there. Barriers go:
//!
//! - around each layer change: Z is one axis both share, so it moves while both wait;
//! - where a head waits in the plan (a dynamic-priority pause, or a head idle until the
//!   other clears its way): the waiting head stands at its safe point and the barrier
//!   is where the other head's plan reaches the end of the wait, so the waiting head
//!   goes on only once the other has passed the point where the conflict ends.
//!
//! Between two barriers each system runs its own moves at the plan's speeds. The
//! estimate in the file comes from replaying each stream (accelerations, junctions)
//! and releasing every barrier when the later system reaches it.

use std::fmt::Write as _;

use lamina_api::machine::{FirstLayerSpeed, HeadClass, Kinematics};
use lamina_api::{BBox2, Error, LayerPlan, PathKind, Point2, Result, Toolpath};

use super::{DEFAULT_PRINT_SPEED, PARK_CLEARANCE, PRIME_SPEED, RETRACT_MIN_TRAVEL, Writer};
use crate::firmware::Firmware;
use crate::setup::System;
use crate::text::num;
use crate::tower::Feature;

/// Seconds: plan times closer than this are one instant.
const SAME_TIME: f64 = 1e-6;

/// How much slower than the file's time model (a share of its time since the last
/// barrier) the machine may run one motion system's moves before a stream the model
/// has reaching a barrier last could reach it first.
const SLOWER_THAN_PLANNED: f64 = 0.5;

/// Seconds a nozzle may stand loaded at a barrier: as long as it stands at a sharp
/// corner of any print, too short to ooze. A stream that may wait longer pulls its
/// filament back first.
const SHORT_WAIT: f64 = 0.2;

/// Longest stretch (mm) a head moves between two instants the barrier placement
/// looks at.
const PROBE_STEP: f64 = 0.5;

/// A head's planned position at time `t` along its time-sorted track.
fn position(track: &[(f64, Point2)], t: f64) -> Option<Point2> {
    let k = track.partition_point(|q| q.0 <= t);
    match (k.checked_sub(1).and_then(|i| track.get(i)), track.get(k)) {
        (Some(a), Some(b)) if b.0 > a.0 => Some(a.1 + (b.1 - a.1) * ((t - a.0) / (b.0 - a.0))),
        (Some(a), _) => Some(a.1),
        (None, Some(b)) => Some(b.1),
        (None, None) => None,
    }
}

/// A head's planned positions over the layer: its paths' timed points, in time order.
fn track(paths: &[&Toolpath]) -> Vec<(f64, Point2)> {
    let mut t: Vec<(f64, Point2)> = paths
        .iter()
        .flat_map(|p| p.points.iter().map(|q| (q.t, q.p)))
        .collect();
    t.sort_by(|x, y| x.0.total_cmp(&y.0));
    t
}

/// A head's planned course: its timed positions and the time spans of its beads.
#[derive(Clone, Copy)]
struct Course<'a> {
    track: &'a [(f64, Point2)],
    beads: &'a [(f64, f64)],
}

/// The time spans of a head's beads, in order.
fn beads(paths: &[&Toolpath]) -> Vec<(f64, f64)> {
    let mut b: Vec<(f64, f64)> = paths
        .iter()
        .filter(|p| p.kind == PathKind::Extrude)
        .map(|p| (p.points[0].t, p.points[p.points.len() - 1].t))
        .collect();
    b.sort_by(|x, y| x.0.total_cmp(&y.0));
    b
}

/// Distance between segments `a0 a1` and `b0 b1`.
fn segment_gap(a0: Point2, a1: Point2, b0: Point2, b1: Point2) -> f64 {
    use lamina_api::geom::segment_distance as d;
    let (da, db) = (a1 - a0, b1 - b0);
    let cross = |u: lamina_api::Vector2, v: lamina_api::Vector2| u.x * v.y - u.y * v.x;
    let den = cross(da, db);
    if den.abs() > 1e-18 {
        let t = cross(b0 - a0, db) / den;
        let u = cross(b0 - a0, da) / den;
        if (0.0..=1.0).contains(&t) && (0.0..=1.0).contains(&u) {
            return 0.0;
        }
    }
    d(a0, b0, b1)
        .min(d(a1, b0, b1))
        .min(d(b0, a0, a1))
        .min(d(b1, a0, a1))
}

/// Barrier times for two heads: between two consecutive barriers, every stretch of
/// path one head sweeps stays at least `keep_out` from every stretch the other sweeps.
/// Whatever the firmware's accelerations do to either head's timing between the
/// barriers, the heads cannot meet. `fixed` are barriers that must be there (the ends
/// of the plan's waits); where the heads pass close, barriers come as often as the
/// plan's own clearance needs.
fn safe_times(first: Course<'_>, second: Course<'_>, fixed: &[f64], keep: Keep, end: f64) -> Vec<f64> {
    let Keep {
        distance: keep_out,
        front,
    } = keep;
    let (a, beads_a, b, beads_b) = (first.track, first.beads, second.track, second.beads);
    if a.is_empty() || b.is_empty() {
        // One head at work: the other stays where it was, out of the layer's way.
        return fixed.to_vec();
    }
    // The instants looked at: every vertex of either track, points along long
    // stretches, and the fixed barriers.
    let mut events: Vec<f64> = Vec::new();
    for track in [a, b] {
        for w in track.windows(2) {
            events.push(w[0].0);
            let len = (w[1].1 - w[0].1).norm();
            let k = (len / PROBE_STEP).ceil().min(1e5) as usize;
            for i in 1..k {
                events.push(w[0].0 + (w[1].0 - w[0].0) * i as f64 / k as f64);
            }
        }
        if let Some(l) = track.last() {
            events.push(l.0);
        }
    }
    events.extend_from_slice(fixed);
    events.retain(|&t| t > SAME_TIME && t <= end);
    events.push(end);
    events.sort_by(f64::total_cmp);
    events.dedup_by(|x, y| (*x - *y).abs() <= SAME_TIME);
    let is_fixed = |t: f64| fixed.iter().any(|f| (f - t).abs() <= SAME_TIME);

    let mut out = Vec::new();
    let at = |track: &[(f64, Point2)], t: f64| position(track, t).unwrap_or(Point2::origin());
    // Whether a head is laying a bead at `t`: a barrier there stops it mid-bead.
    let extruding = |beads: &[(f64, f64)], t: f64| {
        let k = beads.partition_point(|b| b.0 < t - SAME_TIME);
        k.checked_sub(1).is_some_and(|i| beads[i].1 > t + SAME_TIME)
    };
    // The stretches swept since the last barrier, and their bounding boxes: a stretch
    // whose box keeps clear of the other head's box needs no closer look.
    let (mut sa, mut sb) = (Swept::new(keep_out), Swept::new(keep_out));
    // Index of the event where the current stretch starts.
    let mut start = 0usize;
    let mut i = 0usize;
    while i < events.len() {
        let t = events[i];
        let prev = if i == 0 { 0.0 } else { events[i - 1] };
        let na = (at(a, prev), at(a, t));
        let nb = (at(b, prev), at(b, t));
        let fits = match front {
            None => {
                sb.clear_of(na, keep_out)
                    && sa.clear_of(nb, keep_out)
                    && segment_gap(na.0, na.1, nb.0, nb.1) >= keep_out
            }
            // Gantries: whatever either swept since the barrier, the front one's
            // furthest back stays the keep-out in front of the rear one's furthest
            // forward.
            Some(f) => {
                let (fs, rs, fseg, rseg) = if f == 0 {
                    (&sa, &sb, na, nb)
                } else {
                    (&sb, &sa, nb, na)
                };
                let front_max = fs.bbox.max.y.max(fseg.0.y).max(fseg.1.y);
                let rear_min = rs.bbox.min.y.min(rseg.0.y).min(rseg.1.y);
                rear_min - front_max >= keep_out
            }
        };
        if !fits && i > start {
            // A barrier before this step: at the latest instant of the stretch where
            // neither head is in the middle of a bead, else just before the step.
            let cut = (start.max(1)..i)
                .rev()
                .find(|&k| !extruding(beads_a, events[k]) && !extruding(beads_b, events[k]))
                .unwrap_or(i - 1);
            out.push(events[cut]);
            sa = Swept::new(keep_out);
            sb = Swept::new(keep_out);
            start = cut + 1;
            i = cut + 1;
            continue;
        }
        sa.push(na);
        sb.push(nb);
        if is_fixed(t) {
            out.push(t);
            sa = Swept::new(keep_out);
            sb = Swept::new(keep_out);
            start = i + 1;
        }
        i += 1;
    }
    out
}

/// The barriers of a layer in plan time: where a head's wait in the plan ends and,
/// for two heads, where their paths come close ([`safe_times`]); the last at the
/// layer's end.
fn barrier_times(paths: &[Vec<&Toolpath>], tracks: &[Vec<(f64, Point2)>], keep: Keep) -> Vec<f64> {
    let end = paths
        .iter()
        .flatten()
        .filter_map(|p| p.points.last().map(|q| q.t))
        .fold(0.0, f64::max);
    let mut times: Vec<f64> = Vec::new();
    for list in paths {
        // A head idle from the layer's start waits too.
        let mut busy_until = 0.0f64;
        for p in list {
            let (t0, t1) = (p.points[0].t, p.points[p.points.len() - 1].t);
            if p.kind == PathKind::Pause {
                times.push(t1);
            } else if t0 > busy_until + SAME_TIME {
                times.push(t0);
            }
            busy_until = busy_until.max(t1);
        }
    }
    // Between barriers each stream runs on its own, and the firmware's
    // accelerations let one fall behind the plan more than the other: barriers
    // also go where the heads' paths come close ([`safe_times`]).
    times.retain(|&t| t > SAME_TIME && t < end - SAME_TIME);
    if paths.len() == 2 {
        let (ba, bb) = (beads(&paths[0]), beads(&paths[1]));
        let course = |track, beads| Course { track, beads };
        times = safe_times(
            course(&tracks[0], &ba),
            course(&tracks[1], &bb),
            &times,
            keep,
            end,
        );
    }
    times.push(end);
    times.sort_by(f64::total_cmp);
    times.dedup_by(|a, b| (*a - *b).abs() <= SAME_TIME);
    times
}

/// The stretches of path a head swept since the last barrier, filed in a grid of
/// keep-out-sized buckets so that a new stretch is checked only against those near it.
struct Swept {
    segments: Vec<(Point2, Point2)>,
    bbox: BBox2,
    bucket: f64,
    grid: std::collections::HashMap<(i64, i64), Vec<usize>>,
}

impl Swept {
    fn new(keep_out: f64) -> Self {
        Swept {
            segments: Vec::new(),
            bbox: BBox2::default(),
            bucket: keep_out.max(0.5),
            grid: std::collections::HashMap::new(),
        }
    }

    /// The buckets a box grown by `margin` covers.
    fn buckets(&self, b: &BBox2, margin: f64) -> impl Iterator<Item = (i64, i64)> + use<> {
        let c = self.bucket;
        let lo = |v: f64| ((v - margin) / c).floor() as i64;
        let hi = |v: f64| ((v + margin) / c).floor() as i64;
        let (x0, x1, y0, y1) = (lo(b.min.x), hi(b.max.x), lo(b.min.y), hi(b.max.y));
        (x0..=x1).flat_map(move |x| (y0..=y1).map(move |y| (x, y)))
    }

    fn push(&mut self, s: (Point2, Point2)) {
        // A head standing still sweeps nothing new.
        if self.segments.last() == Some(&s) {
            return;
        }
        let b = BBox2::from_points([s.0, s.1]);
        self.bbox = self.bbox.union(&b);
        let k = self.segments.len();
        self.segments.push(s);
        // The buckets borrow nothing of `self`: filed as they come.
        for c in self.buckets(&b, 0.0) {
            self.grid.entry(c).or_default().push(k);
        }
    }

    /// Whether segment `s` stays `keep_out` from every stretch.
    fn clear_of(&self, s: (Point2, Point2), keep_out: f64) -> bool {
        if self.segments.is_empty() {
            return true;
        }
        let b = BBox2::from_points([s.0, s.1]);
        let dx = (self.bbox.min.x - b.max.x)
            .max(b.min.x - self.bbox.max.x)
            .max(0.0);
        let dy = (self.bbox.min.y - b.max.y)
            .max(b.min.y - self.bbox.max.y)
            .max(0.0);
        if dx.hypot(dy) >= keep_out {
            return true;
        }
        self.buckets(&b, keep_out).all(|c| {
            self.grid.get(&c).is_none_or(|list| {
                list.iter().all(|&k| {
                    let o = self.segments[k];
                    segment_gap(s.0, s.1, o.0, o.1) >= keep_out
                })
            })
        })
    }
}

/// How far apart two heads keep, by the machine's kinematics.
#[derive(Debug, Clone, Copy)]
struct Keep {
    /// The envelopes' sum and the plan's margin around each (mm).
    distance: f64,
    /// On two gantries, the head in front (lower Y): the other stays `distance`
    /// behind it in Y. `None`: free heads, discs apart in the plane.
    front: Option<usize>,
}

impl Keep {
    /// Whether head 0 sweeping `a` and head 1 sweeping `b`, at any pace, keep apart.
    fn apart(&self, a: (Point2, Point2), b: (Point2, Point2)) -> bool {
        match self.front {
            None => segment_gap(a.0, a.1, b.0, b.1) >= self.distance,
            Some(f) => {
                let (fr, re) = if f == 0 { (a, b) } else { (b, a) };
                re.0.y.min(re.1.y) - fr.0.y.max(fr.1.y) >= self.distance
            }
        }
    }
}

/// A stream's state while another is selected.
struct Saved {
    fw: Firmware,
    head: Option<usize>,
    feature: Option<Feature>,
}

/// The streams of a job on two motion systems.
pub(super) struct Multi {
    systems: Vec<System>,
    /// State of each stream not selected.
    saved: Vec<Option<Saved>>,
    current: usize,
    forked: bool,
    /// The layer each stream was last told it is in (`;LAYER:` per stream).
    marked: Vec<Option<usize>>,
    /// When the last barrier released (s, file time).
    release: f64,
    /// Time the streams spent moving (not waiting at barriers), added up (s).
    busy: f64,
    barriers: usize,
    /// Planned deposit per head (mm³).
    planned: Vec<f64>,
    kinematics: Kinematics,
    /// Barriers inside layers, where both nozzles wait pulled back.
    retracted_barriers: usize,
    /// The heads the parts use.
    pub(super) used: Vec<usize>,
}

impl Multi {
    pub(super) fn new(systems: Vec<System>, kinematics: Kinematics) -> Self {
        let n = systems.len();
        Multi {
            kinematics,
            retracted_barriers: 0,
            used: (0..n).collect(),
            systems,
            saved: (0..n).map(|_| None).collect(),
            current: 0,
            forked: false,
            marked: vec![None; n],
            release: 0.0,
            busy: 0.0,
            barriers: 0,
            planned: vec![0.0; n],
        }
    }

    /// How far apart the heads keep whatever the firmware's accelerations do to their
    /// timing between two barriers: the envelopes' sum and the margin, in the plane
    /// or, on two gantries, in Y. The plan keeps the margin around each head, twice
    /// this margin in all: the other half is the room a barrier stretch may use.
    fn keep(&self) -> Keep {
        let distance = self.systems.iter().map(|s| s.envelope).sum::<f64>() + self.kinematics.margin;
        let front = (self.kinematics.class == HeadClass::DualGantry).then(|| {
            let y = |i: usize| {
                self.systems
                    .get(i)
                    .and_then(|s| s.home)
                    .map_or(i as f64, |h| h[1])
            };
            usize::from(y(1) < y(0))
        });
        Keep { distance, front }
    }

    /// The header's description of the machine the file assumes.
    pub(super) fn describe(&self) -> String {
        let mut t = String::new();
        let _ = writeln!(
            t,
            "; machine: two motion systems (RepRapFirmware 3.5: M606 S1 forks the job, M596 P<n> selects a system, M598 synchronises)"
        );
        for (i, s) in self.systems.iter().enumerate() {
            let home = s
                .home
                .map(|[x, y]| format!(", home X {} Y {}", num(x, 3), num(y, 3)))
                .unwrap_or_default();
            let _ = writeln!(
                t,
                "; motion system {i}: X axis {}, Y axis {}, Z axis Z, envelope {} mm{home}",
                s.x,
                s.y,
                num(s.envelope, 3)
            );
        }
        let keep = self.keep();
        if let Some(f) = keep.front {
            let _ = writeln!(
                t,
                "; machine: dual gantry (each head on a beam of its own over one pair of Y rails: head {f} in front, head {} behind it in Y)",
                1 - f
            );
        }
        let _ = writeln!(
            t,
            "; keep-out distance between the heads: {} mm (the envelopes' sum and a margin of {} mm){}",
            num(keep.distance, 3),
            num(self.kinematics.margin, 3),
            if keep.front.is_some() { ", in Y" } else { "" }
        );
        t
    }

    /// The letters a line for the current stream is written with, when not X and Y.
    fn letters(&self) -> Option<(&str, &str)> {
        let s = &self.systems[self.current];
        (s.x != "X" || s.y != "Y").then_some((s.x.as_str(), s.y.as_str()))
    }
}

/// `line` with its X and Y words renamed, for moves and position settings.
fn renamed(line: &str, x: &str, y: &str) -> Option<String> {
    let (code, comment) = match line.find(';') {
        Some(i) => line.split_at(i),
        None => (line, ""),
    };
    let mut words = code.split_whitespace();
    let command = words.next()?;
    if !["G0", "G1", "G2", "G3", "G28", "G92"].contains(&command.to_ascii_uppercase().as_str()) {
        return None;
    }
    let mut out = String::from(command);
    for w in words {
        out.push(' ');
        match w.as_bytes().first() {
            Some(b'X' | b'x') => {
                out.push_str(x);
                out.push_str(&w[1..]);
            }
            Some(b'Y' | b'y') => {
                out.push_str(y);
                out.push_str(&w[1..]);
            }
            _ => out.push_str(w),
        }
    }
    if !comment.is_empty() {
        out.push(' ');
        out.push_str(comment);
    }
    Some(out)
}

/// A stretch of one planned path between two plan times.
struct Piece {
    kind: PathKind,
    points: Vec<Point2>,
    /// Width of each segment.
    widths: Vec<f64>,
    /// Length of the planned segment each segment is part of: a travel retracts by
    /// the planned segment's length, wherever a barrier cuts it.
    spans: Vec<f64>,
    t0: f64,
    t1: f64,
}

/// The part of `path` between plan times `a` and `b` (points interpolated at both).
fn clip(path: &Toolpath, a: f64, b: f64) -> Option<Piece> {
    let pts = &path.points;
    let (start, end) = (pts.first()?.t, pts.last()?.t);
    let (a, b) = (a.max(start), b.min(end));
    if b - a <= SAME_TIME {
        return None;
    }
    let at = |i: usize, t: f64| {
        let (p, q) = (&pts[i], &pts[i + 1]);
        if q.t - p.t <= 0.0 {
            q.p
        } else {
            p.p + (q.p - p.p) * ((t - p.t) / (q.t - p.t)).clamp(0.0, 1.0)
        }
    };
    let mut points = Vec::new();
    let mut widths = Vec::new();
    let mut spans = Vec::new();
    for i in 0..pts.len() - 1 {
        let (s, e) = (pts[i].t, pts[i + 1].t);
        if e <= a || s >= b {
            continue;
        }
        if points.is_empty() {
            points.push(at(i, a.max(s)));
        }
        points.push(at(i, b.min(e)));
        widths.push(path.segment_width(i));
        spans.push((pts[i + 1].p - pts[i].p).norm());
    }
    (points.len() >= 2).then_some(Piece {
        kind: path.kind,
        points,
        widths,
        spans,
        t0: a,
        t1: b,
    })
}

impl Writer {
    /// Selects the stream of motion system `n` for the lines that follow.
    fn select_stream(&mut self, n: usize) {
        let Some(m) = self.multi.as_mut() else { return };
        if m.current == n {
            return;
        }
        let Some(mut next) = m.saved[n].take() else { return };
        std::mem::swap(&mut self.fw, &mut next.fw);
        std::mem::swap(&mut self.head, &mut next.head);
        std::mem::swap(&mut self.feature, &mut next.feature);
        let old = m.current;
        m.saved[old] = Some(next);
        m.current = n;
        self.buf.push_str(&format!("M596 P{n} ; motion system {n}\n"));
    }

    /// Where the head of stream `h` is (machine coordinates).
    fn stream_position(&self, h: usize) -> Point2 {
        let p = match self.multi.as_ref() {
            Some(m) if m.current != h => m.saved[h].as_ref().map(|s| s.fw.position()),
            _ => None,
        }
        .unwrap_or_else(|| self.fw.position());
        Point2::new(p[0], p[1])
    }

    /// A line for the current stream, with its own axis letters.
    pub(super) fn stream_line(&mut self, text: &str) {
        self.fw.feed_line(text);
        match self
            .multi
            .as_ref()
            .and_then(Multi::letters)
            .and_then(|(x, y)| renamed(text, x, y))
        {
            Some(r) => self.buf.push_str(&r),
            None => self.buf.push_str(text),
        }
        self.buf.push('\n');
    }

    /// Every stream stops and waits for the other here.
    fn barrier(&mut self) {
        self.barrier_at(None);
    }

    /// [`Self::barrier`] where the plan's layer time is `t` (said in the comment).
    fn barrier_at(&mut self, t: Option<f64>) {
        let Some(m) = self.multi.as_mut() else { return };
        let mut times = vec![self.fw.time()];
        for s in m.saved.iter_mut().flatten() {
            times.push(s.fw.time());
        }
        let release = times.iter().copied().fold(m.release, f64::max);
        m.busy += times.iter().map(|t| (t - m.release).max(0.0)).sum::<f64>();
        self.fw.wait_until(release);
        for s in m.saved.iter_mut().flatten() {
            s.fw.wait_until(release);
        }
        m.release = release;
        m.barriers += 1;
        match t {
            Some(t) => {
                let _ = writeln!(
                    self.buf,
                    "M598 ; the motion systems meet (plan: {t:.3} s into the layer)"
                );
            }
            None => self.buf.push_str("M598 ; the motion systems meet\n"),
        }
    }

    /// `;LAYER:` for the current stream, once per layer.
    fn mark_layer(&mut self, plan: &LayerPlan) {
        let Some(m) = self.multi.as_mut() else { return };
        if m.marked[m.current] != Some(plan.index) {
            m.marked[m.current] = Some(plan.index);
            let _ = writeln!(
                self.buf,
                ";LAYER:{} Z{:.4} height {:.4}",
                plan.index, plan.z, plan.thickness
            );
        }
    }

    /// Forks the job, selects and heats each head in its stream, and primes.
    fn fork(&mut self, plan: &LayerPlan) -> Result<()> {
        self.retract(self.s.retraction.length);
        // Every head has heated since the start (`M568 A2`); the one reader there is
        // so far waits for them all before any nozzle comes near the bed, and each
        // system then selects a tool that is already hot.
        self.line("M116 ; wait for every heater, before any nozzle nears the bed");
        // On two gantries the firmware keeps the order too: it aborts the job before a
        // block that would bring the rear gantry's Y closer than this to the front's.
        if let Some(m) = self.multi.as_ref()
            && let Keep {
                distance,
                front: Some(f),
            } = m.keep()
        {
            let (front, rear) = (m.systems[f].y.clone(), m.systems[1 - f].y.clone());
            self.line(format!(
                "M597 {front}0 {rear}{} ; collision avoidance: {rear} stays {} mm behind {front}",
                num(distance, 3),
                num(distance, 3)
            ));
        }
        // Down to the first layer before the fork: Z is shared, and a forked system
        // moving it would race the other's extrusion.
        self.z = plan.z;
        if (self.fw.position()[2] - plan.z).abs() > 1e-9 {
            let f = self.z_feed();
            self.line(format!("G1 Z{} F{}", num(plan.z, 4), num(f, 0)));
        }
        self.line("M606 S1 ; fork: each motion system reads the job from here");
        let n = self.s.heads.len();
        let Some(m) = self.multi.as_mut() else {
            return Ok(());
        };
        m.forked = true;
        m.release = self.fw.time();
        for i in 1..n {
            m.saved[i] = Some(Saved {
                fw: self.fw.clone(),
                head: None,
                feature: None,
            });
        }
        self.z = plan.z;
        for h in 0..n {
            self.select_stream(h);
            self.line("G90 ; absolute coordinates");
            self.line(if self.s.relative_e {
                "M83 ; relative extrusion"
            } else {
                "M82 ; absolute extrusion"
            });
            // Accelerations are the motion system's own.
            self.line(crate::commands::accelerations(&self.s));
            self.ready(h)?;
        }
        // Prime lines: the first head's along the front, the second's across the bed
        // from it, so that they prime at once far apart.
        if let (Some(p), Some(&(a, b))) = (self.s.prime_line, self.layout.prime_lines.first()) {
            let bed = self
                .s
                .bed
                .map(|bed| bed.bounds())
                .unwrap_or(self.layout.printed());
            let mirror = |q: Point2| Point2::new(bed.min.x + bed.max.x - q.x, bed.min.y + bed.max.y - q.y);
            let lines = [(a, b), (mirror(a), mirror(b))];
            for (h, (a, b)) in lines.into_iter().enumerate().take(n) {
                if h > 0 && BBox2::from_points([a, b]).overlaps(&self.layout.parts) {
                    return Err(Error::stage(
                        crate::STAGE,
                        "the second head's prime line, across the bed from the first's, runs over the parts: \
                         switch prime lines off with `prime_line = false` in [machine]",
                    ));
                }
                self.select_stream(h);
                self.mark_layer(plan);
                self.comment(format!("prime line of T{}", self.s.heads[h].index));
                self.extrude(
                    h,
                    &[a, b],
                    &|_| p.width,
                    plan.thickness,
                    PRIME_SPEED,
                    Feature::Prime,
                )?;
                self.retract(self.s.retraction.length);
            }
            self.barrier();
        }
        Ok(())
    }

    /// Writes one layer of a job on two motion systems.
    pub(super) fn write_layer_multi(&mut self, plan: &LayerPlan) -> Result<()> {
        if !self.multi.as_ref().is_some_and(|m| m.forked) {
            self.fork(plan)?;
        }
        let n = self.s.heads.len();
        let paths = self.head_paths(plan);
        let tracks: Vec<Vec<(f64, Point2)>> = paths.iter().map(|l| track(l)).collect();
        let keep = self.multi.as_ref().map_or(
            Keep {
                distance: 0.0,
                front: None,
            },
            Multi::keep,
        );
        let times = barrier_times(&paths, &tracks, keep);

        // Each head to where its route starts, one at a time, in an order where the
        // moving head passes clear of the standing one; then the layer change: system
        // 0 moves the shared Z while the other waits.
        self.barrier();
        if n == 2 {
            self.go_to_starts(plan, &tracks, keep);
        }
        self.change_layer_multi(plan);

        let mut from = 0.0;
        for &to in &times {
            for (h, list) in paths.iter().enumerate() {
                let pieces: Vec<Piece> = list
                    .iter()
                    .filter(|p| p.kind != PathKind::Pause)
                    .filter_map(|p| clip(p, from, to))
                    .collect();
                if pieces.is_empty() {
                    continue;
                }
                self.select_stream(h);
                self.mark_layer(plan);
                for piece in pieces {
                    self.write_piece(h, piece, plan)?;
                }
            }
            // Either system may get to the barrier first and wait there for the
            // other: with its nozzle pulled back, never oozing onto the part.
            self.retract_streams();
            if let Some(m) = self.multi.as_mut() {
                m.retracted_barriers += 1;
            }
            self.barrier_at(Some(to));
            from = to;
        }
        Ok(())
    }

    /// Each head's paths of the layer, by the material the plan's tool carries (the
    /// concurrent plan times tools; from a planner that names no material, the one
    /// numbered as the tool), in time order; their volume counts towards what each head
    /// is planned to lay.
    fn head_paths<'p>(&mut self, plan: &'p LayerPlan) -> Vec<Vec<&'p Toolpath>> {
        let n = self.s.heads.len();
        let mut paths: Vec<Vec<&Toolpath>> = vec![Vec::new(); n];
        for p in &plan.toolpaths {
            if p.points.len() < 2 {
                continue;
            }
            let h = self
                .s
                .slot_of
                .get(p.material.unwrap_or(p.tool))
                .copied()
                .flatten()
                .unwrap_or(0)
                .min(n - 1);
            paths[h].push(p);
        }
        for (h, list) in paths.iter_mut().enumerate() {
            list.sort_by(|a, b| a.points[0].t.total_cmp(&b.points[0].t));
            let volume: f64 = list.iter().map(|p| p.bead_area() * plan.thickness).sum();
            if let Some(m) = self.multi.as_mut() {
                m.planned[h] += volume;
            }
        }
        paths
    }

    /// Takes the two heads to where their routes start (`tracks`), one at a time: the
    /// one whose move passes clear of the other standing first.
    fn go_to_starts(&mut self, plan: &LayerPlan, tracks: &[Vec<(f64, Point2)>], keep: Keep) {
        let offset = self.layout.offset;
        let starts: Vec<Option<Point2>> = tracks.iter().map(|t| t.first().map(|q| q.1 + offset)).collect();
        let now = [self.stream_position(0), self.stream_position(1)];
        // Head `p` moving first, then `q`: each sweep is clear of the other head
        // where it stands.
        let clear = |p: usize, q: usize| {
            let (p0, p1) = (now[p], starts[p].unwrap_or(now[p]));
            let q1 = starts[q].unwrap_or(now[q]);
            let pair = |mp: (Point2, Point2), mq: (Point2, Point2)| {
                if p == 0 {
                    keep.apart(mp, mq)
                } else {
                    keep.apart(mq, mp)
                }
            };
            pair((p0, p1), (now[q], now[q])) && pair((p1, p1), (now[q], q1))
        };
        let order = if clear(0, 1) || !clear(1, 0) {
            [0, 1]
        } else {
            [1, 0]
        };
        for h in order {
            if let Some(p) = starts[h] {
                self.select_stream(h);
                self.mark_layer(plan);
                self.travel(p);
                self.barrier();
            }
        }
    }

    /// The layer change: Z is shared, so system 0 moves it while the other waits at a
    /// barrier; each head's fan is set for the new layer in its own system.
    fn change_layer_multi(&mut self, plan: &LayerPlan) {
        let n = self.s.heads.len();
        self.select_stream(0);
        self.mark_layer(plan);
        self.feature = None;
        self.retract(self.s.retraction.length);
        self.z = plan.z;
        if (self.fw.position()[2] - plan.z).abs() > 1e-9 {
            let f = self.z_feed();
            self.line(format!("G1 Z{} F{}", num(plan.z, 4), num(f, 0)));
        }
        if self.layers == 1 {
            self.after_first_layer_multi();
        }
        // Each head's part-cooling fan is its tool's, commanded in its own system.
        for h in 0..n {
            if self.stream_head(h).is_some() {
                self.select_stream(h);
                self.set_fan();
            }
        }
        self.select_stream(0);
        self.barrier();
        if let Some(m) = self.multi.as_mut() {
            for st in m.saved.iter_mut().flatten() {
                st.fw.assume_z(plan.z);
            }
        }
    }

    /// Writes one piece of head `h`'s path, at the speed that keeps it to the plan's
    /// timeline: a bead extruded, or a travel.
    fn write_piece(&mut self, h: usize, piece: Piece, plan: &LayerPlan) -> Result<()> {
        let offset = self.layout.offset;
        let points: Vec<Point2> = piece.points.iter().map(|p| p + offset).collect();
        let length: f64 = points.windows(2).map(|w| (w[1] - w[0]).norm()).sum();
        let speed = if piece.t1 > piece.t0 && length > 0.0 {
            length / (piece.t1 - piece.t0)
        } else {
            DEFAULT_PRINT_SPEED
        };
        match piece.kind {
            PathKind::Extrude => {
                let widths = piece.widths;
                self.extrude(
                    h,
                    &points,
                    &|i| widths.get(i).copied().unwrap_or(0.0),
                    plan.thickness,
                    speed,
                    Feature::Part,
                )?;
            }
            _ => {
                self.ready(h)?;
                // The first layer's slow-down stretches the plan's timeline
                // as a whole, travel included, so the heads stay in step.
                let speed = match (self.layers, self.s.first_layer_speed) {
                    (0, Some(FirstLayerSpeed::Factor(f))) => speed * f,
                    _ => speed,
                };
                for (k, &p) in points[1..].iter().enumerate() {
                    // Pulled back where a long planned travel starts, even
                    // when a barrier cuts it into pieces too short to
                    // retract for on their own: the nozzle would ooze on
                    // its way otherwise.
                    if piece.spans.get(k).is_some_and(|&l| l > RETRACT_MIN_TRAVEL) {
                        self.retract(self.s.retraction.length);
                        self.lift();
                    }
                    self.travel_at(p, speed);
                }
            }
        }
        Ok(())
    }

    /// The head stream `h` has selected.
    fn stream_head(&self, h: usize) -> Option<usize> {
        match self.multi.as_ref() {
            Some(m) if m.current != h => m.saved[h].as_ref().and_then(|s| s.head),
            _ => self.head,
        }
    }

    /// When stream `h` gets to the next barrier, by the file's own time model.
    fn stream_time(&mut self, h: usize) -> f64 {
        match self.multi.as_mut() {
            Some(m) if m.current != h => m.saved[h].as_mut().map_or(0.0, |s| s.fw.time()),
            _ => self.fw.time(),
        }
    }

    /// Before a barrier, every stream that may wait there longer than [`SHORT_WAIT`]
    /// pulls its filament back, in its own system, so that no nozzle oozes on the
    /// part while it waits. How long a stream may wait is counted with the other
    /// running its moves since the last barrier [`SLOWER_THAN_PLANNED`] slower than
    /// the file's time model (its feeds a fifth slower, or its accelerations halved,
    /// stay within that): a stream that gets there last by a wide margin need not.
    fn retract_streams(&mut self) {
        let n = self.s.heads.len();
        let length = self.s.retraction.length;
        let current = self.multi.as_ref().map_or(0, |m| m.current);
        let release = self.multi.as_ref().map_or(0.0, |m| m.release);
        let arrival: Vec<f64> = (0..n).map(|h| self.stream_time(h)).collect();
        // The longest stream `h` may wait here: until another running its moves since
        // the last barrier that much slower than planned gets here too.
        let longest_wait = |h: usize| {
            (0..n)
                .filter(|&o| o != h)
                .map(|o| arrival[o] + SLOWER_THAN_PLANNED * (arrival[o] - release).max(0.0) - arrival[h])
                .fold(0.0, f64::max)
        };
        // The selected stream first: no switch when it is the only one to retract.
        let order = std::iter::once(current).chain((0..n).filter(|&h| h != current));
        for h in order.collect::<Vec<_>>() {
            let Some(head) = self.stream_head(h) else { continue };
            if self.extruded[head] && self.retracted[head] < length - 1e-9 && longest_wait(h) > SHORT_WAIT {
                self.select_stream(h);
                self.retract(length);
            }
        }
    }

    /// After the first layer each head goes to its own printing temperature, in its
    /// own stream.
    fn after_first_layer_multi(&mut self) {
        let s = self.s.clone();
        for (h, head) in s.heads.iter().enumerate() {
            if (head.nozzle_temperature - head.first_layer_temperature).abs() <= 0.5 {
                continue;
            }
            self.select_stream(h);
            self.line(crate::commands::rrf_tool_temperatures(
                head.index,
                head.nozzle_temperature,
                head.standby_temperature,
            ));
        }
        self.select_stream(0);
        if s.machine.is_some() && (s.bed_temperature - s.first_layer_bed_temperature).abs() > 0.5 {
            self.line(format!("M140 S{}", num(s.bed_temperature, 0)));
        }
    }

    /// Before the end: every system finishes its head. Each pulls its filament back;
    /// system 0 lifts the shared Z clear of the part while the other waits; each head
    /// then goes home, one at a time in an order that keeps them apart, and each
    /// system turns its own tool's heater and fan off. System 0 then ends the job
    /// (the end template).
    pub(super) fn end_streams(&mut self) {
        if !self.multi.as_ref().is_some_and(|m| m.forked) {
            return;
        }
        let n = self.s.heads.len();
        self.retract_streams();
        self.barrier();
        self.select_stream(0);
        self.feature = None;
        let park = (self.z_max + PARK_CLEARANCE).min(self.s.bed.map_or(f64::INFINITY, |b| b.max_height));
        if self.fw.position()[2] < park - 1e-9 {
            let f = self.z_feed();
            self.line(format!("G1 Z{} F{} ; clear of the part", num(park, 3), num(f, 0)));
            self.z = park;
        }
        self.barrier();
        if let Some(m) = self.multi.as_mut() {
            for st in m.saved.iter_mut().flatten() {
                st.fw.assume_z(park);
            }
        }
        let homes: Vec<Option<Point2>> = self
            .multi
            .as_ref()
            .map(|m| {
                m.systems
                    .iter()
                    .map(|s| s.home.map(|[x, y]| Point2::new(x, y)))
                    .collect()
            })
            .unwrap_or_default();
        if n == 2 {
            let keep = self.multi.as_ref().map(Multi::keep);
            let now = [self.stream_position(0), self.stream_position(1)];
            let to = |h: usize| homes.get(h).copied().flatten().unwrap_or(now[h]);
            let first_clear = |p: usize, q: usize| {
                keep.is_none_or(|k| {
                    let pair = |mp: (Point2, Point2), mq: (Point2, Point2)| {
                        if p == 0 { k.apart(mp, mq) } else { k.apart(mq, mp) }
                    };
                    pair((now[p], to(p)), (now[q], now[q])) && pair((to(p), to(p)), (now[q], to(q)))
                })
            };
            let order = if first_clear(0, 1) || !first_clear(1, 0) {
                [0, 1]
            } else {
                [1, 0]
            };
            for h in order {
                if let Some(home) = homes.get(h).copied().flatten() {
                    self.select_stream(h);
                    self.comment(format!("T{} home, clear of the part", self.s.heads[h].index));
                    self.line(format!(
                        "G0 X{} Y{} F{}",
                        num(home.x, 3),
                        num(home.y, 3),
                        num(self.s.travel_speed * 60.0, 0)
                    ));
                    self.barrier();
                }
            }
        }
        for h in (0..n).rev() {
            let Some(head) = self.stream_head(h) else { continue };
            self.select_stream(h);
            let index = self.s.heads[head].index;
            if self.fw.fan() > 0.0 {
                self.line("M107 ; this system's part-cooling fan off");
            }
            if self.fw.target(index) > 0.0 {
                self.line(format!("M568 P{index} S0 R0 A0 ; T{index} heater off"));
            }
        }
        self.barrier();
        self.select_stream(0);
        // The heaters are the machine's: system 0's model learns what the others did.
        for h in 1..n {
            if let Some(head) = self.stream_head(h) {
                let index = self.s.heads[head].index;
                self.fw.feed_line(&format!("M568 P{index} S0 R0 A0"));
            }
        }
    }

    /// The footer lines of a job on two motion systems: what the plan deposits per
    /// tool, the synchronisations, and the plan's own time.
    pub(super) fn multi_footer(&self) -> String {
        let Some(m) = self.multi.as_ref() else {
            return String::new();
        };
        let mut t = String::new();
        for (h, v) in m.planned.iter().enumerate() {
            let _ = writeln!(t, "; planned extrusion T{}: {v:.3} mm3", self.s.heads[h].index);
        }
        let _ = writeln!(
            t,
            "; synchronisations: {}; the systems move {:.1} s in all (the time below is when the later one is done)",
            m.barriers, m.busy
        );
        let _ = writeln!(
            t,
            "; planned build time: {:.1} s (the concurrent plan, at the plan's constant speeds)",
            self.planned
        );
        t
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn moves_of_the_second_head_name_its_own_axes() {
        assert_eq!(
            renamed("G1 X10.5 Y2 E0.3 F1200 ; go", "U", "V").as_deref(),
            Some("G1 U10.5 V2 E0.3 F1200 ; go")
        );
        assert_eq!(renamed("G92 E0", "U", "V").as_deref(), Some("G92 E0"));
        assert_eq!(renamed("M104 S200", "U", "V"), None);
    }

    #[test]
    fn a_path_is_cut_at_plan_times() {
        use lamina_api::TimedPoint;
        let path = Toolpath {
            tool: 0,
            material: None,
            kind: PathKind::Extrude,
            points: [(0.0, 0.0), (10.0, 1.0), (20.0, 2.0)]
                .iter()
                .map(|&(x, t)| TimedPoint {
                    p: Point2::new(x, 0.0),
                    t,
                })
                .collect(),
            width: 0.4,
            widths: vec![0.4, 0.5],
            composition: None,
            part: Some(0),
            sub_region: None,
        };
        let p = clip(&path, 0.5, 1.5).expect("a piece");
        let xs: Vec<f64> = p.points.iter().map(|q| q.x).collect();
        assert_eq!(xs, vec![5.0, 10.0, 15.0]);
        assert_eq!(p.widths, vec![0.4, 0.5]);
        assert!(clip(&path, 2.0, 3.0).is_none());
    }

    /// Barriers for two heads without beads.
    fn barriers(a: &[(f64, Point2)], b: &[(f64, Point2)], fixed: &[f64]) -> Vec<f64> {
        let course = |track| Course { track, beads: &[] };
        let keep = Keep {
            distance: 10.0,
            front: None,
        };
        safe_times(course(a), course(b), fixed, keep, 10.0)
    }

    fn line_track(from: (f64, f64), to: (f64, f64), t0: f64, t1: f64) -> Vec<(f64, Point2)> {
        vec![(t0, Point2::new(from.0, from.1)), (t1, Point2::new(to.0, to.1))]
    }

    #[test]
    fn gantries_keep_their_order_in_y_whatever_their_x() {
        let keep = Keep {
            distance: 31.0,
            front: Some(0),
        };
        let p = |x: f64, y: f64| Point2::new(x, y);
        // Far apart in X, but head 1 comes within 31 mm behind head 0 in Y.
        assert!(!keep.apart((p(0.0, 0.0), p(0.0, 10.0)), (p(200.0, 40.0), p(200.0, 60.0))));
        assert!(keep.apart((p(0.0, 0.0), p(0.0, 10.0)), (p(200.0, 41.0), p(200.0, 60.0))));
        // In front of it is never apart, however far.
        assert!(!keep.apart((p(0.0, 100.0), p(0.0, 100.0)), (p(0.0, 0.0), p(0.0, 0.0))));
        // Barriers: head 0 sweeps back while head 1 waits ahead of it, then head 1
        // moves on; between barriers the swept spans keep the order.
        let a = line_track((0.0, 0.0), (0.0, 100.0), 0.0, 10.0);
        let b = line_track((50.0, 40.0), (50.0, 140.0), 0.0, 10.0);
        let course = |track| Course { track, beads: &[] };
        let times = safe_times(course(&a), course(&b), &[], keep, 10.0);
        assert!(!times.is_empty(), "40 mm ahead, both moving: barriers");
        let mut bounds = vec![0.0];
        bounds.extend(&times);
        bounds.push(10.0);
        for w in bounds.windows(2) {
            let front_max = position(&a, w[1]).expect("a").y;
            let rear_min = position(&b, w[0]).expect("b").y;
            assert!(
                rear_min - front_max >= 31.0 - 1e-6,
                "{w:?}: {front_max} {rear_min}"
            );
        }
    }

    #[test]
    fn heads_far_apart_need_no_barrier_and_crossing_paths_get_one() {
        // Parallel, 50 mm apart: nothing to synchronise.
        let a = line_track((0.0, 0.0), (100.0, 0.0), 0.0, 10.0);
        let b = line_track((0.0, 50.0), (100.0, 50.0), 0.0, 10.0);
        assert!(barriers(&a, &b, &[]).is_empty());
        // Head b crosses where head a has been: at no instant are they closer than
        // the keep-out in the plan, but b must not start across before a has left.
        let a = line_track((0.0, 0.0), (100.0, 0.0), 0.0, 10.0);
        let b = line_track((20.0, -50.0), (20.0, 50.0), 0.0, 10.0);
        let times = barriers(&a, &b, &[]);
        assert!(!times.is_empty());
        // Between consecutive barriers the swept stretches keep 10 mm apart.
        let mut bounds = vec![0.0];
        bounds.extend(&times);
        bounds.push(10.0);
        for w in bounds.windows(2) {
            let (t0, t1) = (w[0], w[1]);
            let steps = 50;
            let pa: Vec<Point2> = (0..=steps)
                .map(|k| position(&a, t0 + (t1 - t0) * k as f64 / steps as f64).expect("a"))
                .collect();
            let pb: Vec<Point2> = (0..=steps)
                .map(|k| position(&b, t0 + (t1 - t0) * k as f64 / steps as f64).expect("b"))
                .collect();
            // Every position of one in the stretch is clear of every position of the
            // other, whenever each gets there.
            let gap = pa
                .iter()
                .flat_map(|p| pb.iter().map(move |q| (p - q).norm()))
                .fold(f64::INFINITY, f64::min);
            assert!(
                gap >= 10.0 - 1e-6,
                "stretch {t0}..{t1} lets the heads meet ({gap} mm)"
            );
        }
        // The fixed barriers stay.
        let times = barriers(&a, &b, &[3.0]);
        assert!(times.iter().any(|t| (t - 3.0).abs() < 1e-9));
    }
}
