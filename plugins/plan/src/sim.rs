//! Concurrent deposition with dynamic priority (Choi and Zhu): every tool follows its
//! own route at its own speeds; at a fixed rate the positions each tool would reach in
//! the next step are checked pairwise against the tools' envelopes. On a predicted
//! collision one tool keeps going along its path and the other pauses where it is (a
//! safe point: it was clear there one step ago) until the conflict is gone. Which one
//! pauses is the [`Priority`] rule; the paper's, and the default, is
//! [`Priority::XSpeed`]: the tools' traverse speeds along the x-axis are compared and
//! the faster one has priority.
//!
//! Each check covers the whole step: the closest approach of the two tools' motions
//! during it is computed exactly, so no overlap can hide between two checks. With a
//! look-ahead longer than the step, each check also looks along both routes: a
//! collision in prospect within half the look-ahead pauses, now, a tool whose pausing
//! alone keeps the two apart (the priority rule decides when either would do), until
//! none is in prospect within the whole look-ahead. Checking only the next step, two
//! tools meeting head-on along neighbouring walls both get stuck where neither can
//! pause out of the other's way, and one has to step aside; looking ahead, one waits
//! before the way narrows. And a paused tool goes on only once its way is clear for
//! half the look-ahead, so that a tool catching up with another pauses once for a
//! while instead of at every other check: each pause cuts a bead (and, on a machine
//! with two motion systems, stops both heads at a synchronisation point). When
//! pausing the lower-priority tool does not clear the conflict (it is ahead of the
//! other), the other is held too. When every unfinished tool is held (each waits for
//! another, as tools meeting head-on along neighbouring walls do), the tool with the
//! least work left steps aside to a clear point (never toward the parks) and comes back
//! once the way is free: the layer ends when the busiest tool is done, so that one
//! should not wait. If side-steps do not resolve the layer, the caller falls back to
//! sequential deposition.

use lamina_api::{BBox2, PathKind, Pauses, Point2, TimedPoint, Toolpath, Vector2};
use lamina_geom::segment::segment_distance2;

use crate::route::{Move, ToolSpec, pause, toolpath};

/// Appends the end of a stretch of segment `seg` of move `m` to `path`, with that
/// segment's width when the move's bead varies in width.
fn push_point(path: &mut Toolpath, m: &Move, seg: usize, p: TimedPoint) {
    if !m.widths.is_empty() {
        path.widths.push(m.segment_width(seg));
    }
    path.points.push(p);
}

lamina_api::option_type!(Priority = "string");

/// Which of two tools about to collide keeps going; the other pauses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Priority {
    /// The paper's rule (Choi and Zhu, abstract): the traverse speeds of the tools
    /// along the x-axis are compared and the tool traversing faster has priority; it
    /// goes on depositing along its path while the other pauses until the collision is
    /// no longer in prospect. The speed compared is each tool's speed along X at the
    /// check, the X component of its velocity on the segment it is on (zero along a
    /// wall parallel to Y), not its set deposition or travel speed: the paper compares
    /// speeds *along the x-axis* and assigns priority afresh at every collision it
    /// detects, which a tool's fixed speed would not. On a tie the tool listed first
    /// keeps going. The one exception is feasibility: a tool whose pausing would not
    /// clear the conflict (it is ahead of the other, or the other is already paused)
    /// is not the one paused.
    #[default]
    XSpeed,
    /// Lamina's rules first, then the paper's: when pausing only one of the two tools
    /// clears the conflict (a tool following another along a wall), that one pauses
    /// whatever the speeds; else, looking ahead, one already paused stays paused; else
    /// a tool on its way back from a side-step gives way; else [`Priority::XSpeed`].
    Clearing,
    /// A tool on its way back from a side-step gives way to every other; looking
    /// ahead, one already paused stays paused; else [`Priority::XSpeed`] without its
    /// feasibility exception at the one-step check.
    Returning,
    /// Looking ahead, when either tool's pause would clear the conflict, one already
    /// paused stays paused, so that a tool pauses once for longer rather than the two
    /// taking turns; else [`Priority::XSpeed`] without its feasibility exception at
    /// the one-step check. Often a little faster, but it breaks the paper's rule.
    Waiting,
    /// The critical path: when pausing only one of the two clears the conflict, that
    /// one pauses; else the tool with less of its route left pauses, since the layer
    /// ends when the busiest tool is done (on a tie, [`Priority::XSpeed`]).
    Busiest,
}

/// Why a tool starts a pause at a check (see [`Pauses`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Why {
    XSpeed,
    Forced,
    Other,
}

impl Why {
    /// Why `loser` of the pair `(i, j)` pauses, given whether pausing `i` alone and
    /// `j` alone keeps the two apart: forced when the other's pause would not (or
    /// neither would and both pause), else by the paper's rule when `loser` is the
    /// tool it pauses.
    fn of(loser: usize, i: usize, j: usize, clears: (bool, bool), along_x: &[f64]) -> Why {
        let theirs = if loser == i { clears.1 } else { clears.0 };
        if !theirs {
            Why::Forced
        } else if loser == slower_along_x(i, j, along_x) {
            Why::XSpeed
        } else {
            Why::Other
        }
    }
}

/// Counts `by` (one pause, or one taken back) to the pauses of `why`.
fn tally(pauses: &mut Pauses, why: Why, by: isize) {
    let n = match why {
        Why::XSpeed => &mut pauses.by_x_speed,
        Why::Forced => &mut pauses.forced,
        Why::Other => &mut pauses.other,
    };
    *n = n.checked_add_signed(by).unwrap_or(0);
}

/// The paper's choice between two moving tools: the one slower along X pauses (on a
/// tie, the later one). Speeds within rounding of each other (a part in 10^9: they
/// come from positions along the routes) are a tie.
fn slower_along_x(i: usize, j: usize, along_x: &[f64]) -> usize {
    if along_x[j] > along_x[i] + 1e-9 * along_x[i].abs().max(1.0) {
        i
    } else {
        j
    }
}

/// A concurrent schedule: every tool's toolpaths with their pauses, the time the last
/// tool parks, and why the tools paused.
#[derive(Debug, Clone)]
pub struct Schedule {
    pub paths: Vec<Toolpath>,
    pub end: f64,
    pub pauses: Pauses,
}

/// Why the concurrent schedule gave up.
#[derive(Debug, Clone, PartialEq)]
pub enum Stuck {
    /// Tools kept blocking each other after this many side-steps.
    Deadlock(usize),
    /// The simulation ran past its time budget (s).
    Timeout(f64),
}

impl std::fmt::Display for Stuck {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Stuck::Deadlock(n) => write!(f, "the tools kept blocking each other after {n} side-steps"),
            Stuck::Timeout(s) => write!(f, "the simulation ran past its {s} s budget"),
        }
    }
}

/// Where a tool is on its route.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Cursor {
    mv: usize,
    seg: usize,
    along: f64,
}

struct Agent<'a> {
    spec: &'a ToolSpec,
    route: Vec<Move>,
    at: Cursor,
    pos: Point2,
    done: bool,
    /// The path being written: the current move's, or a pause.
    open: Option<Toolpath>,
    out: Vec<Toolpath>,
    /// Whether the tool has moved on its route (or the route has changed) since its
    /// motion ahead was last walked: a tool held at a check has the same motion ahead
    /// at the next, and a third of the checks hold one tool or the other.
    moved: bool,
    /// The fastest the tool moves on its route or stepping aside (mm/s).
    top_speed: f64,
}

impl<'a> Agent<'a> {
    /// The tool at the start of `route` at time 0.
    fn new(spec: &'a ToolSpec, route: Vec<Move>) -> Self {
        let pos = route.first().map(|m| m.points[0]).unwrap_or_default();
        let open = route
            .first()
            .map(|m| toolpath(spec.index, m, vec![TimedPoint { p: pos, t: 0.0 }]));
        let top_speed = route.iter().map(|m| m.speed).fold(spec.max_speed(), f64::max);
        Agent {
            spec,
            done: route.is_empty(),
            route,
            at: Cursor {
                mv: 0,
                seg: 0,
                along: 0.0,
            },
            pos,
            open,
            out: Vec::new(),
            moved: true,
            top_speed,
        }
    }

    /// The cursor and position after `dt` seconds along the route, whether the route
    /// is done, and the length of route covered; with `emit`, the route's vertices
    /// passed on the way are written with their times from `t`.
    fn walk(&mut self, dt: f64, t: f64, emit: bool, mut track: Option<&mut Track>) -> (Cursor, Point2, bool) {
        let mut c = self.at;
        let mut left = dt;
        let mut pos = self.pos;
        if let Some(tr) = track.as_deref_mut() {
            tr.clear();
            tr.push((0.0, pos));
        }
        loop {
            let Some(m) = self.route.get(c.mv) else {
                if let Some(tr) = track {
                    tr.push((dt, pos));
                }
                return (c, pos, true);
            };
            if c.seg + 1 >= m.points.len() {
                // End of a move: the next one starts where this one ended.
                if emit {
                    self.close();
                }
                c = Cursor {
                    mv: c.mv + 1,
                    seg: 0,
                    along: 0.0,
                };
                if let Some(next) = self.route.get(c.mv)
                    && emit
                {
                    let p = next.points[0];
                    self.open = Some(toolpath(
                        self.spec.index,
                        next,
                        vec![TimedPoint { p, t: t + dt - left }],
                    ));
                }
                continue;
            }
            let (a, b) = (m.points[c.seg], m.points[c.seg + 1]);
            let len = (b - a).norm();
            let need = (len - c.along).max(0.0) / m.speed;
            if need > left {
                c.along += left * m.speed;
                let p = if len > 0.0 {
                    a + (b - a) * (c.along / len)
                } else {
                    a
                };
                if let Some(tr) = track {
                    tr.push((dt, p));
                }
                return (c, p, false);
            }
            left -= need;
            if let Some(tr) = track.as_deref_mut() {
                tr.push((dt - left, b));
            }
            if emit && let Some(path) = &mut self.open {
                push_point(
                    path,
                    m,
                    c.seg,
                    TimedPoint {
                        p: b,
                        t: t + dt - left,
                    },
                );
            }
            c = Cursor {
                mv: c.mv,
                seg: c.seg + 1,
                along: 0.0,
            };
            pos = b;
        }
    }

    fn close(&mut self) {
        if let Some(path) = self.open.take() {
            let keep = path.points.len() >= 2
                && match path.kind {
                    PathKind::Pause => path.points[path.points.len() - 1].t > path.points[0].t,
                    _ => path.length() > 0.0,
                };
            if keep {
                self.out.push(path);
            }
        }
    }

    /// Holds the tool at its position for `[t, t + dt]`.
    fn hold(&mut self, t: f64, dt: f64) {
        match &mut self.open {
            Some(p) if p.kind == PathKind::Pause => {
                if let Some(last) = p.points.last_mut() {
                    last.t = t + dt;
                }
            }
            _ => {
                if let Some(path) = &mut self.open
                    && path.points.last().is_none_or(|q| q.p != self.pos)
                {
                    let seg = self.at.seg;
                    if let Some(m) = self.route.get(self.at.mv) {
                        push_point(path, m, seg, TimedPoint { p: self.pos, t });
                    } else {
                        path.points.push(TimedPoint { p: self.pos, t });
                    }
                }
                self.close();
                self.open = Some(pause(self.spec.index, self.pos, t, t + dt));
            }
        }
    }

    /// Moves the tool for `dt` from `t`, ending a pause first.
    fn advance(&mut self, t: f64, dt: f64) {
        if self.open.as_ref().is_some_and(|p| p.kind == PathKind::Pause) {
            self.close();
            if let Some(m) = self.route.get(self.at.mv) {
                self.open = Some(toolpath(self.spec.index, m, vec![TimedPoint { p: self.pos, t }]));
            }
        }
        let (c, p, done) = self.walk(dt, t, true, None);
        self.at = c;
        self.pos = p;
        self.moved = true;
        // Between vertices the motion is straight at constant speed: the position is
        // written only when the tool stops (`hold`) or passes the next vertex.
        if done {
            self.close();
            self.done = true;
        }
    }

    /// Whether the tool is on its way back from a side-step.
    fn yields(&self) -> bool {
        self.route.get(self.at.mv).is_some_and(|m| m.yields)
    }

    /// Seconds of route left from the cursor.
    fn remaining(&self) -> f64 {
        let c = self.at;
        let Some(m) = self.route.get(c.mv) else {
            return 0.0;
        };
        let here: f64 = m.points[c.seg.min(m.points.len() - 1)..]
            .windows(2)
            .map(|w| (w[1] - w[0]).norm())
            .sum::<f64>()
            - c.along;
        here.max(0.0) / m.speed + self.route[c.mv + 1..].iter().map(Move::duration).sum::<f64>()
    }

    /// Leaves the route at the current position for `to` and comes back, then goes on.
    fn side_step(&mut self, to: Point2) {
        let c = self.at;
        let Some(m) = self.route.get(c.mv).cloned() else {
            return;
        };
        let here = self.pos;
        let mut head: Vec<Point2> = m.points[..=c.seg.min(m.points.len() - 1)].to_vec();
        head.push(here);
        let mut tail = vec![here];
        tail.extend_from_slice(&m.points[(c.seg + 1).min(m.points.len())..]);
        let speed = self.spec.travel_speed;
        let seg = head.len() - 2;
        let along = (head[seg + 1] - head[seg]).norm();
        // A variable-width bead keeps each segment's width on both sides of the cut:
        // the cut segment's on its two pieces.
        let (head_w, tail_w) = if m.widths.is_empty() {
            (Vec::new(), Vec::new())
        } else {
            let cut = c.seg.min(m.widths.len().saturating_sub(1));
            (m.widths[..=cut].to_vec(), m.widths[cut..].to_vec())
        };
        self.route[c.mv].points = head;
        self.route[c.mv].widths = head_w;
        let rest = Move {
            points: tail,
            widths: tail_w,
            ..m
        };
        self.route.splice(
            c.mv + 1..c.mv + 1,
            [
                Move::travel(vec![here, to], speed),
                Move {
                    yields: true,
                    ..Move::travel(vec![to, here], speed)
                },
                rest,
            ],
        );
        self.at = Cursor { mv: c.mv, seg, along };
        self.moved = true;
    }
}

/// Timed points of a tool's motion within one step, from 0 to the step length.
type Track = Vec<(f64, Point2)>;

/// Whether two motions over the same step keep at least `e` apart over its first
/// `until` seconds: between consecutive breakpoints of either, both move straight at
/// constant speed, so their difference runs along a segment whose distance to the
/// origin is exact. The planner needs only the yes or no, so the walk stops at the
/// first stretch that comes closer.
fn keep_apart_until(a: &[(f64, Point2)], b: &[(f64, Point2)], until: f64, e: f64) -> bool {
    closest_below(a, b, until, e) >= e
}

/// How far apart two tools must keep, by the machine's kinematics.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Separation {
    /// Discs: the nozzles keep the sum of their envelopes apart in the plane.
    #[default]
    Discs,
    /// Heads on gantries of their own over one pair of Y rails: the rear head (see
    /// [`ToolSpec::rear`]) stays the envelopes' sum behind (+Y) the front one, wherever
    /// either is in X, and the two never pass.
    OrderedY,
}

impl Separation {
    /// Whether tools `a` and `b`, on tracks `ta` and `tb`, keep `e` apart over the
    /// first `until` seconds.
    fn apart_until(
        self,
        a: &ToolSpec,
        b: &ToolSpec,
        ta: &[(f64, Point2)],
        tb: &[(f64, Point2)],
        until: f64,
        e: f64,
    ) -> bool {
        // Boxes of the two motions that far apart settle it without the walk: most
        // pairs of tools work far from each other. The boxes are of the motions up to
        // `until` only: a track runs on to the look-ahead, and looking half as far
        // (a pair that waited at no check) sweeps about half the box.
        if self.bound_until(a, b, ta, tb, until) >= e {
            return true;
        }
        match self {
            Separation::Discs => keep_apart_until(ta, tb, until, e),
            Separation::OrderedY => behind_until(ta, tb, until, y_order(a, b)) >= e,
        }
    }

    /// [`Separation::apart_until`] over the whole tracks.
    fn apart(self, a: &ToolSpec, b: &ToolSpec, ta: &[(f64, Point2)], tb: &[(f64, Point2)], e: f64) -> bool {
        self.apart_until(a, b, ta, tb, f64::INFINITY, e)
    }

    /// A lower bound of the separation of two motions, from their bounding boxes.
    #[cfg(test)]
    fn bound(self, a: &ToolSpec, b: &ToolSpec, ta: &[(f64, Point2)], tb: &[(f64, Point2)]) -> f64 {
        self.bound_until(a, b, ta, tb, f64::INFINITY)
    }

    /// A lower bound of the separation of two motions over their first `until`
    /// seconds, from the bounding boxes of those stretches.
    fn bound_until(
        self,
        a: &ToolSpec,
        b: &ToolSpec,
        ta: &[(f64, Point2)],
        tb: &[(f64, Point2)],
        until: f64,
    ) -> f64 {
        match self {
            Separation::Discs => gap_until(ta, tb, until),
            Separation::OrderedY => {
                if y_order(a, b) == 0.0 {
                    return f64::INFINITY;
                }
                let (front, rear) = if a.rear { (tb, ta) } else { (ta, tb) };
                let max_front = bounds_until(front, until)[3];
                let min_rear = bounds_until(rear, until)[1];
                min_rear - max_front
            }
        }
    }
}

/// On gantries, the sign by which `a.y - b.y` must stay ahead: 1 when `a` is the rear
/// head and `b` the front one, -1 the other way round, 0 for two heads on one side
/// (nothing to keep).
fn y_order(a: &ToolSpec, b: &ToolSpec) -> f64 {
    if a.rear == b.rear {
        0.0
    } else if a.rear {
        1.0
    } else {
        -1.0
    }
}

/// The least of `sign * (a.y - b.y)` over the first `until` seconds of the two motions
/// (both piecewise straight at constant speed: the least is at a breakpoint). With
/// `sign` 0 (two heads on the same side) there is nothing to keep.
fn behind_until(a: &[(f64, Point2)], b: &[(f64, Point2)], until: f64, sign: f64) -> f64 {
    if a.is_empty() || b.is_empty() || sign == 0.0 {
        return f64::INFINITY;
    }
    let at = |tr: &[(f64, Point2)], t: f64| -> f64 {
        let k = tr.partition_point(|q| q.0 <= t);
        match (k.checked_sub(1).map(|i| tr[i]), tr.get(k)) {
            (Some((t0, p0)), Some(&(t1, p1))) if t1 > t0 => p0.y + (p1.y - p0.y) * ((t - t0) / (t1 - t0)),
            (Some((_, p0)), _) => p0.y,
            (None, Some(&(_, p1))) => p1.y,
            (None, None) => 0.0,
        }
    };
    let end = until.min(a[a.len() - 1].0.max(b[b.len() - 1].0));
    let start = a[0].0.min(b[0].0).min(end);
    a.iter()
        .chain(b)
        .map(|q| q.0)
        .filter(|&t| t > start && t < end)
        .chain([start, end])
        .map(|t| sign * (at(a, t) - at(b, t)))
        .fold(f64::INFINITY, f64::min)
}

/// The closest approach of the two motions over the first `until` seconds, or, as
/// soon as one stretch comes closer than `stop`, that stretch's approach. The
/// breakpoints of the two are walked together, in time order, without sorting or
/// allocating: this runs for every pair of tools at every check.
fn closest_below(a: &[(f64, Point2)], b: &[(f64, Point2)], until: f64, stop: f64) -> f64 {
    if a.is_empty() || b.is_empty() {
        return f64::INFINITY;
    }
    // The position at `t` of a track whose first breakpoint after `t` is `k`.
    let at = |tr: &[(f64, Point2)], k: usize, t: f64| -> Point2 {
        if k == 0 {
            return tr[0].1;
        }
        let Some(&(t1, p1)) = tr.get(k) else {
            return tr[tr.len() - 1].1;
        };
        let (t0, p0) = tr[k - 1];
        if t1 > t0 {
            p0 + (p1 - p0) * ((t - t0) / (t1 - t0))
        } else {
            p1
        }
    };
    let origin = Point2::origin();
    // The closest approach is sought squared: the root is taken of a new closest only.
    let mut best2 = f64::INFINITY;
    let mut prev: Option<Point2> = None;
    let (mut ia, mut ib) = (0, 0);
    let mut t = a[0].0.min(b[0].0).min(until);
    loop {
        while ia < a.len() && a[ia].0 <= t {
            ia += 1;
        }
        while ib < b.len() && b[ib].0 <= t {
            ib += 1;
        }
        let d = origin + (at(a, ia, t) - at(b, ib, t));
        let d2 = match prev {
            Some(q) => segment_distance2([0.0, 0.0], [q.x, q.y], [d.x, d.y]),
            None => (d - origin).norm_squared(),
        };
        if d2 < best2 {
            best2 = d2;
            let best = d2.sqrt();
            if best < stop {
                return best;
            }
        }
        prev = Some(d);
        if t >= until {
            break;
        }
        let next = match (a.get(ia), b.get(ib)) {
            (Some(x), Some(y)) => x.0.min(y.0),
            (Some(x), None) => x.0,
            (None, Some(y)) => y.0,
            (None, None) => break,
        };
        t = next.min(until);
    }
    best2.sqrt()
}

/// The speed along X (mm/s) at the start of a tool's motion over a step: the X
/// component of its velocity on its first stretch that takes time (a stretch of less
/// than a nanosecond is what rounding leaves of a segment the tool has just finished:
/// the tool is at a vertex and moves on along the next one).
fn speed_along_x(track: &[(f64, Point2)]) -> f64 {
    track
        .windows(2)
        .find(|w| w[1].0 - w[0].0 > 1e-9)
        .map_or(0.0, |w| (w[1].1.x - w[0].1.x).abs() / (w[1].0 - w[0].0))
}

/// How the concurrent schedule is run.
#[derive(Debug, Clone, Copy)]
pub struct Settings {
    /// Seconds between two collision checks.
    pub step: f64,
    /// Simulated seconds after which the schedule gives up.
    pub budget: f64,
    /// Side-steps after which the schedule gives up.
    pub max_side_steps: usize,
    /// Who keeps going when two tools are about to collide.
    pub priority: Priority,
    /// Seconds ahead a collision is looked for (only the next step when no longer than
    /// it): one in prospect within half of it pauses, now, a tool whose pausing alone
    /// keeps the two apart, until none is in prospect within the whole of it; a paused
    /// tool goes on once its way is clear for half of it.
    pub look_ahead: f64,
    /// How the tools keep apart.
    pub separation: Separation,
    /// Room (mm) beyond the envelopes that looking ahead keeps: a tool pauses before
    /// coming closer than the envelopes and this, and goes on once its way is that
    /// clear. The envelopes alone are never entered either way; the room makes a tool
    /// following another hang back instead of tracking it at the envelopes' distance,
    /// where every stretch it moves would need its own synchronisation point.
    pub room: f64,
}

/// Runs the tools' routes together from time 0 with checks every `settings.step`
/// seconds. Tools stepping aside stay inside `arena` (an empty box: anywhere).
pub fn concurrent(
    tools: &[(&ToolSpec, Vec<Move>)],
    settings: &Settings,
    arena: &BBox2,
) -> Result<Schedule, Stuck> {
    let mut run = Run::start(tools, settings, arena);
    while run.agents.iter().any(|a| !a.done) {
        if run.t > settings.budget {
            return Err(Stuck::Timeout(settings.budget));
        }
        run.why.fill(None);
        if run.far_apart() {
            // No check can find two tools closer than they must keep: every tool moves
            // on, as the checks would have it, without walking the motions ahead.
            for (m, a) in run.moving.iter_mut().zip(&run.agents) {
                *m = !a.done;
            }
            run.follow_the_rear();
        } else {
            run.look_along_routes();
            run.follow_the_rear();
            run.checks();
        }
        if !run.moving.iter().any(|&m| m) {
            if !run.step_aside()? {
                break;
            }
            continue;
        }
        run.take_step();
    }
    Ok(run.finish())
}

impl Run<'_> {
    /// Whether every two unfinished tools stay farther apart than any check of this
    /// step asks, whatever they do until the farthest horizon a check looks to: each
    /// moves no faster than its top speed, so two that far apart need no walk along
    /// their routes. On 3DBenchy in two tools, two checks in five.
    fn far_apart(&self) -> bool {
        let Settings {
            step,
            look_ahead,
            room,
            separation,
            ..
        } = self.settings;
        let horizon = if self.anticipate {
            look_ahead.max(step)
        } else {
            step
        };
        let agents = &self.agents;
        (0..agents.len()).all(|i| {
            (i + 1..agents.len()).all(|j| {
                let (a, b) = (&agents[i], &agents[j]);
                if a.done || b.done {
                    return true;
                }
                let keep = a.spec.envelope + b.spec.envelope + room;
                let reach = (a.top_speed + b.top_speed) * horizon;
                // A micrometre to spare for the checks' rounding.
                let margin = 1e-3;
                let apart = match (separation, y_order(a.spec, b.spec)) {
                    (Separation::Discs, _) => (a.pos - b.pos).norm(),
                    (Separation::OrderedY, 0.0) => f64::INFINITY,
                    (Separation::OrderedY, sign) => sign * (a.pos.y - b.pos.y),
                };
                apart - reach >= keep + margin
            })
        })
    }

    /// The checks of a step where two tools may come close: collisions looked for
    /// ahead and over the step, and held tools kept waiting until their way is clear.
    fn checks(&mut self) {
        let settings = self.settings;
        let run = self;
        if run.anticipate {
            anticipate_holds(
                &run.agents,
                &run.ahead,
                &run.along_x,
                &mut run.moving,
                &mut run.why,
                &run.waited,
                &settings,
            );
        }
        run.hold_colliding();
        if run.anticipate {
            run.keep_waiting();
        }
    }
}

/// The room two tools need between their centres when both may move for a step of
/// `step` seconds: their envelopes, and half a step at their top speeds.
fn clearance(a: &Agent<'_>, b: &Agent<'_>, step: f64) -> f64 {
    a.spec.envelope + b.spec.envelope + (a.spec.max_speed() + b.spec.max_speed()) * step / 2.0
}

/// What the checks of a concurrent schedule share: the tools, the clock, and per tool
/// what the check under way has found.
struct Run<'a> {
    agents: Vec<Agent<'a>>,
    settings: Settings,
    arena: &'a BBox2,
    /// Whether checks look along the routes beyond the next step.
    anticipate: bool,
    t: f64,
    side_steps: usize,
    /// Per tool: its speed along X at the check, and the timed points of its motion
    /// during the step and over the look-ahead.
    along_x: Vec<f64>,
    tracks: Vec<Track>,
    ahead: Vec<Track>,
    /// Per tool: whether it paused at the last check.
    waited: Vec<bool>,
    /// Per tool: whether it moves on at this check.
    moving: Vec<bool>,
    /// Per tool: why it was first held at this check.
    why: Vec<Option<Why>>,
    /// Per tool: whether it may leave the start of its route (see
    /// [`Run::follow_the_rear`]).
    released: Vec<bool>,
    /// Per tool: how its pause under way is counted.
    counted: Vec<Why>,
    pauses: Pauses,
}

impl<'a> Run<'a> {
    /// Every tool at the start of its route at time 0, none paused.
    fn start(tools: &'a [(&'a ToolSpec, Vec<Move>)], settings: &Settings, arena: &'a BBox2) -> Self {
        let agents: Vec<Agent<'a>> = tools
            .iter()
            .map(|(spec, route)| Agent::new(spec, route.clone()))
            .collect();
        let n = agents.len();
        Run {
            agents,
            settings: *settings,
            arena,
            anticipate: settings.look_ahead > settings.step * 1.5,
            t: 0.0,
            side_steps: 0,
            along_x: vec![0.0; n],
            tracks: vec![Vec::new(); n],
            ahead: vec![Vec::new(); n],
            waited: vec![false; n],
            moving: vec![false; n],
            why: vec![None; n],
            released: vec![false; n],
            counted: vec![Why::Other; n],
            pauses: Pauses::default(),
        }
    }

    /// Where each unfinished tool's route takes it over the next step (and, looking
    /// ahead, over the look-ahead), and its speed along X; every unfinished tool starts
    /// the check moving.
    fn look_along_routes(&mut self) {
        let Settings { step, look_ahead, .. } = self.settings;
        let t = self.t;
        for (i, a) in self.agents.iter_mut().enumerate() {
            self.moving[i] = !a.done;
            if !a.done && !a.moved {
                // Held since the last check: the same motion ahead, already walked.
                continue;
            }
            a.moved = false;
            self.along_x[i] = if a.done {
                0.0
            } else if self.anticipate {
                a.walk(look_ahead, t, false, Some(&mut self.ahead[i]));
                truncate(&self.ahead[i], step, &mut self.tracks[i]);
                speed_along_x(&self.tracks[i])
            } else {
                a.walk(step, t, false, Some(&mut self.tracks[i]));
                speed_along_x(&self.tracks[i])
            };
        }
    }

    /// On gantries in Y order, where every route sweeps the layer front to back, the
    /// rear head leads: the front head leaves its park only once the rear head has
    /// begun its beads a keep-out beyond the front head's first bead (or is done).
    /// Started the other way round, the rear head would wait behind the front one for
    /// the front of the layer until the front head had done all of its work. These
    /// waits count as decided by another rule than speed along X.
    fn follow_the_rear(&mut self) {
        if self.settings.separation != Separation::OrderedY {
            return;
        }
        let n = self.agents.len();
        for i in 0..n {
            let a = &self.agents[i];
            if self.released[i] || a.done || a.spec.rear {
                continue;
            }
            let first = a
                .route
                .iter()
                .find(|m| m.kind == PathKind::Extrude)
                .and_then(|m| m.points.first());
            let Some(first) = first else {
                self.released[i] = true;
                continue;
            };
            let ahead = |j: usize| {
                let b = &self.agents[j];
                let begun = || {
                    b.route
                        .iter()
                        .take(b.at.mv + 1)
                        .any(|m| m.kind == PathKind::Extrude)
                };
                b.done || (b.pos.y >= first.y + a.spec.envelope + b.spec.envelope && begun())
            };
            if (0..n).all(|j| j == i || !self.agents[j].spec.rear || ahead(j)) {
                self.released[i] = true;
            } else {
                self.moving[i] = false;
                self.why[i] = Some(Why::Other);
            }
        }
    }

    /// Whether tools i and j, moving or held, keep their envelopes apart for the
    /// whole step: their closest approach along the two timed motions, exactly.
    fn safe(&self, i: usize, j: usize, mi: bool, mj: bool) -> bool {
        let step = self.settings.step;
        let (a, b) = (&self.agents[i], &self.agents[j]);
        let still = |p: Point2| [(0.0, p), (step, p)];
        let (si, sj) = (still(a.pos), still(b.pos));
        let ti: &[(f64, Point2)] = if mi { &self.tracks[i] } else { &si };
        let tj: &[(f64, Point2)] = if mj { &self.tracks[j] } else { &sj };
        self.settings
            .separation
            .apart(a.spec, b.spec, ti, tj, a.spec.envelope + b.spec.envelope)
    }

    /// Holds the lower-priority tool of each predicted collision until none is left;
    /// held tools stay where they are, which was clear one step ago.
    fn hold_colliding(&mut self) {
        let n = self.agents.len();
        loop {
            let mut change = false;
            for i in 0..n {
                for j in i + 1..n {
                    let (mi, mj) = (self.moving[i], self.moving[j]);
                    if !(mi || mj) || self.safe(i, j, mi, mj) {
                        continue;
                    }
                    let (loser, reason) = match (mi, mj) {
                        (true, true) => self.pair_loser(i, j),
                        // The other is held where it is: only this one's pause helps.
                        (true, false) => (i, Why::Forced),
                        _ => (j, Why::Forced),
                    };
                    self.why[loser].get_or_insert(reason);
                    self.moving[loser] = false;
                    change = true;
                }
            }
            if !change {
                break;
            }
        }
    }

    /// Which of two moving tools about to collide pauses, and why.
    fn pair_loser(&self, i: usize, j: usize) -> (usize, Why) {
        let priority = self.settings.priority;
        // Whether holding i alone, and j alone, clears the other's next position: a
        // tool moving away from the one behind it is not the one to hold.
        let clears = (self.safe(i, j, false, true), self.safe(i, j, true, false));
        let ruled = ruled_loser(priority, &self.agents, i, j, &self.along_x);
        let loser = match (priority, clears) {
            (Priority::XSpeed | Priority::Clearing | Priority::Busiest, (true, false)) => i,
            (Priority::XSpeed | Priority::Clearing | Priority::Busiest, (false, true)) => j,
            _ => ruled,
        };
        (loser, Why::of(loser, i, j, clears, &self.along_x))
    }

    /// A tool that waited at the last check goes on only when its way is clear for
    /// half the look-ahead; else it waits on (where it is clear for the next step), so
    /// that it does not go on for a step and pause again.
    fn keep_waiting(&mut self) {
        let Settings {
            look_ahead,
            separation,
            room,
            ..
        } = self.settings;
        let half = look_ahead / 2.0;
        let n = self.agents.len();
        for i in 0..n {
            if !(self.moving[i] && self.waited[i]) {
                continue;
            }
            let agents = &self.agents;
            let blocked = (0..n).any(|j| {
                j != i && !agents[j].done && {
                    let e = agents[i].spec.envelope + agents[j].spec.envelope + room;
                    let still = [(0.0, agents[j].pos), (half, agents[j].pos)];
                    let other: &[(f64, Point2)] = if self.moving[j] { &self.ahead[j] } else { &still };
                    !separation.apart_until(agents[i].spec, agents[j].spec, &self.ahead[i], other, half, e)
                }
            });
            let others_move = (0..n).any(|j| j != i && self.moving[j]);
            // Staying put is what the one-step check calls safe for a held tool.
            let stay_safe = (0..n).all(|j| j == i || self.safe(i, j, false, self.moving[j]));
            if blocked && others_move && stay_safe {
                self.moving[i] = false;
            }
        }
    }

    /// Every unfinished tool waits for another: the one with the least work left steps
    /// aside, since the layer ends when the busiest tool is done. `false` when no tool
    /// is left to step aside; an error once the side-steps run out.
    fn step_aside(&mut self) -> Result<bool, Stuck> {
        let Settings {
            step,
            max_side_steps,
            separation,
            ..
        } = self.settings;
        self.side_steps += 1;
        if self.side_steps > max_side_steps {
            return Err(Stuck::Deadlock(max_side_steps));
        }
        let agents = &self.agents;
        let n = agents.len();
        let Some(k) = (0..n)
            .filter(|&i| !agents[i].done)
            .map(|i| (i, agents[i].remaining()))
            .min_by(|a, b| a.1.total_cmp(&b.1).then(b.0.cmp(&a.0)))
            .map(|(i, _)| i)
        else {
            return Ok(false);
        };
        let clear = |a: &Agent<'_>, b: &Agent<'_>| clearance(a, b, step);
        let to = match separation {
            Separation::Discs => aside(agents, k, &clear, self.arena),
            // On gantries the only way out of another's way is back toward the
            // tool's own side of the bed.
            Separation::OrderedY => {
                let reach = (0..n)
                    .filter(|&j| j != k)
                    .map(|j| clear(&agents[k], &agents[j]))
                    .fold(0.0, f64::max);
                let dir = if agents[k].spec.rear { 1.0 } else { -1.0 };
                agents[k].pos + Vector2::new(0.0, dir * 2.0 * reach)
            }
        };
        self.agents[k].side_step(to);
        Ok(true)
    }

    /// Counts the pauses this check starts, moves the moving tools on by a step and
    /// holds the others where they are.
    fn take_step(&mut self) {
        let (t, step) = (self.t, self.settings.step);
        for (i, a) in self.agents.iter_mut().enumerate() {
            if !self.moving[i] && !a.done {
                if !self.waited[i] {
                    // A pause starts: counted once, by what started it.
                    self.counted[i] = self.why[i].unwrap_or(Why::Other);
                    tally(&mut self.pauses, self.counted[i], 1);
                } else if self.why[i] == Some(Why::Other) && self.counted[i] != Why::Other {
                    // A pause goes on by another rule than speed along X (one
                    // already paused stays paused where the faster should): it breaks
                    // the rule after all.
                    tally(&mut self.pauses, self.counted[i], -1);
                    self.counted[i] = Why::Other;
                    tally(&mut self.pauses, Why::Other, 1);
                }
            }
            self.waited[i] = !self.moving[i] && !a.done;
            if self.moving[i] {
                a.advance(t, step);
            } else if !a.done {
                a.hold(t, step);
            }
        }
        self.t += step;
    }

    /// Every tool's toolpaths in tool order, and the time the last tool parks.
    fn finish(self) -> Schedule {
        let mut out = Vec::new();
        let mut end = 0.0f64;
        for a in self.agents {
            for p in &a.out {
                if let Some(q) = p.points.last() {
                    end = end.max(q.t);
                }
            }
            out.extend(a.out);
        }
        Schedule {
            paths: out,
            end,
            pauses: self.pauses,
        }
    }
}

/// Which of two moving tools `priority` pauses, feasibility aside (for
/// [`Priority::Clearing`], its rule once either pause would clear the way).
fn ruled_loser(priority: Priority, agents: &[Agent<'_>], i: usize, j: usize, along_x: &[f64]) -> usize {
    let by_speed = slower_along_x(i, j, along_x);
    let (yi, yj) = (agents[i].yields(), agents[j].yields());
    let by_return = (yi != yj).then_some(if yi { i } else { j });
    match priority {
        Priority::XSpeed => by_speed,
        Priority::Returning | Priority::Clearing => by_return.unwrap_or(by_speed),
        Priority::Waiting => by_speed,
        Priority::Busiest => {
            let (ri, rj) = (agents[i].remaining(), agents[j].remaining());
            if (ri - rj).abs() <= 1e-9 * ri.max(rj).max(1.0) {
                by_speed
            } else if ri < rj {
                i
            } else {
                j
            }
        }
    }
}

/// The bounding box `[x0, y0, x1, y1]` of a motion over its first `until` seconds:
/// its breakpoints up to then and where it is at `until` (straight at constant speed
/// between breakpoints, so the box holds the whole stretch).
fn bounds_until(tr: &[(f64, Point2)], until: f64) -> [f64; 4] {
    let mut b = [f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY];
    let mut add = |p: Point2| {
        b = [b[0].min(p.x), b[1].min(p.y), b[2].max(p.x), b[3].max(p.y)];
    };
    for (k, &(t, p)) in tr.iter().enumerate() {
        if t <= until || k == 0 {
            add(p);
            continue;
        }
        let (t0, p0) = tr[k - 1];
        if t > t0 && until > t0 {
            add(p0 + (p - p0) * ((until - t0) / (t - t0)));
        }
        break;
    }
    b
}

/// A lower bound of the distance between two motions: between their bounding boxes.
#[cfg(test)]
fn gap(a: &[(f64, Point2)], b: &[(f64, Point2)]) -> f64 {
    gap_until(a, b, f64::INFINITY)
}

/// A lower bound of the distance between two motions over their first `until`
/// seconds: between the bounding boxes of those stretches.
fn gap_until(a: &[(f64, Point2)], b: &[(f64, Point2)], until: f64) -> f64 {
    let ([ax0, ay0, ax1, ay1], [bx0, by0, bx1, by1]) = (bounds_until(a, until), bounds_until(b, until));
    let dx = (bx0 - ax1).max(ax0 - bx1).max(0.0);
    let dy = (by0 - ay1).max(ay0 - by1).max(0.0);
    // Millimetres on a bed: no overflow for `hypot` to guard against, at a fifth of its cost.
    (dx * dx + dy * dy).sqrt()
}

/// The first `h` seconds of `track` into `out`.
fn truncate(track: &[(f64, Point2)], h: f64, out: &mut Track) {
    out.clear();
    for (k, &(t, p)) in track.iter().enumerate() {
        if t < h {
            out.push((t, p));
            continue;
        }
        let end = match k.checked_sub(1).map(|i| track[i]) {
            Some((t0, p0)) if t > t0 => p0 + (p - p0) * ((h - t0) / (t - t0)),
            _ => p,
        };
        out.push((h, end));
        return;
    }
    if let Some(&(_, p)) = track.last() {
        out.push((h, p));
    }
}

/// Pauses, among tools that would all move, one of each pair heading for a collision
/// within the look-ahead, when pausing that one alone keeps the two apart over it;
/// when either pause would, `settings.priority` decides (the paper's rule by default;
/// the others first let one already waiting wait on). When neither would, the one-step
/// check deals with it. A pair neither of
/// whose tools waited at the last check looks half as far: a pause begins when a
/// collision is in prospect within half the look-ahead and ends when none is within
/// the whole of it, so that a tool following another does not pause and go on at
/// every check, cutting its bead each time.
fn anticipate_holds(
    agents: &[Agent<'_>],
    ahead: &[Track],
    along_x: &[f64],
    moving: &mut [bool],
    why: &mut [Option<Why>],
    waited: &[bool],
    settings: &Settings,
) {
    let Settings {
        priority,
        look_ahead,
        separation,
        ..
    } = *settings;
    let n = agents.len();
    let still = |p: Point2| [(0.0, p), (look_ahead, p)];
    loop {
        let mut change = false;
        for i in 0..n {
            for j in i + 1..n {
                if !(moving[i] && moving[j]) {
                    continue;
                }
                let (a, b) = (&agents[i], &agents[j]);
                let e = a.spec.envelope + b.spec.envelope + settings.room;
                let h = if waited[i] || waited[j] {
                    look_ahead
                } else {
                    look_ahead / 2.0
                };
                let apart = |ta: &[(f64, Point2)], tb: &[(f64, Point2)]| {
                    separation.apart_until(a.spec, b.spec, ta, tb, h, e)
                };
                if apart(&ahead[i], &ahead[j]) {
                    continue;
                }
                let hold_i = apart(&still(a.pos), &ahead[j]);
                let hold_j = apart(&ahead[i], &still(b.pos));
                let loser = match (hold_i, hold_j) {
                    (true, true)
                        if !matches!(priority, Priority::XSpeed | Priority::Busiest)
                            && waited[i] != waited[j] =>
                    {
                        Some(if waited[i] { i } else { j })
                    }
                    (true, true) => Some(ruled_loser(priority, agents, i, j, along_x)),
                    (true, false) => Some(i),
                    (false, true) => Some(j),
                    (false, false) => None,
                };
                if let Some(l) = loser {
                    moving[l] = false;
                    why[l].get_or_insert(Why::of(l, i, j, (hold_i, hold_j), along_x));
                    change = true;
                }
            }
        }
        if !change {
            break;
        }
    }
}

/// A point clear of every other tool, away from the nearest ones, for tool `k` to wait
/// at: straight away from the tools around it first, then turning until clear.
fn aside(
    agents: &[Agent<'_>],
    k: usize,
    clear: &dyn Fn(&Agent<'_>, &Agent<'_>) -> f64,
    arena: &BBox2,
) -> Point2 {
    let here = agents[k].pos;
    let mut away = Vector2::zeros();
    let mut reach: f64 = 0.0;
    for (j, b) in agents.iter().enumerate() {
        if j == k {
            continue;
        }
        let d = here - b.pos;
        let c = clear(&agents[k], b);
        reach = reach.max(c);
        if d.norm() < 3.0 * c && d.norm() > 0.0 {
            away += d / d.norm();
        }
    }
    if away.norm() < 1e-9 {
        away = Vector2::new(0.0, -1.0);
    }
    let away = away.normalize();
    let inside = |p: Point2| {
        arena.is_empty()
            || (p.x >= arena.min.x && p.x <= arena.max.x && p.y >= arena.min.y && p.y <= arena.max.y)
    };
    let ok = |p: Point2| {
        inside(p)
            && agents
                .iter()
                .enumerate()
                .all(|(j, b)| j == k || (p - b.pos).norm() >= clear(&agents[k], b) * 1.5)
    };
    // Nearest first: every millimetre out is a millimetre back.
    for scale in [2.0, 3.0, 5.0] {
        for turn in [0.0f64, 45.0, -45.0, 90.0, -90.0, 135.0, -135.0, 180.0] {
            let (s, c) = turn.to_radians().sin_cos();
            let dir = Vector2::new(c * away.x - s * away.y, s * away.x + c * away.y);
            let p = here + dir * reach * scale;
            if ok(p) {
                return p;
            }
        }
    }
    let p = here + away * reach * 2.0;
    if arena.is_empty() {
        p
    } else {
        Point2::new(
            p.x.clamp(arena.min.x, arena.max.x),
            p.y.clamp(arena.min.y, arena.max.y),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The exact closest approach over the first `until` seconds.
    fn closest_until(a: &[(f64, Point2)], b: &[(f64, Point2)], until: f64) -> f64 {
        closest_below(a, b, until, f64::NEG_INFINITY)
    }

    fn closest(a: &[(f64, Point2)], b: &[(f64, Point2)]) -> f64 {
        closest_until(a, b, f64::INFINITY)
    }

    /// The closest approach by brute force: both motions sampled every `dt`.
    fn sampled(a: &[(f64, Point2)], b: &[(f64, Point2)], until: f64, dt: f64) -> f64 {
        let at = |tr: &[(f64, Point2)], t: f64| -> Point2 {
            match tr.iter().position(|q| q.0 > t) {
                Some(0) => tr[0].1,
                None => tr[tr.len() - 1].1,
                Some(k) => {
                    let ((t0, p0), (t1, p1)) = (tr[k - 1], tr[k]);
                    p0 + (p1 - p0) * ((t - t0) / (t1 - t0))
                }
            }
        };
        let mut best = f64::INFINITY;
        let mut t = 0.0;
        while t <= until {
            best = best.min((at(a, t) - at(b, t)).norm());
            t += dt;
        }
        best
    }

    #[test]
    fn the_closest_approach_over_a_horizon_is_that_of_the_sampled_motions() {
        let mut seed = fastrand::Rng::with_seed(0x2545_f491_4f6c_dd1d);
        let next = |rng: &mut fastrand::Rng| rng.f64();
        fn track(seed: &mut fastrand::Rng, n: usize) -> Vec<(f64, Point2)> {
            let next = |rng: &mut fastrand::Rng| rng.f64();
            let mut t = 0.0;
            (0..n)
                .map(|k| {
                    if k > 0 {
                        t += 0.05 + next(seed) * 0.3;
                    }
                    (t, Point2::new(next(seed) * 20.0, next(seed) * 20.0))
                })
                .collect()
        }
        for _ in 0..300 {
            let (na, nb) = (
                2 + (next(&mut seed) * 8.0) as usize,
                2 + (next(&mut seed) * 8.0) as usize,
            );
            let (a, b) = (track(&mut seed, na), track(&mut seed, nb));
            let until = next(&mut seed) * 2.0;
            let exact = closest_until(&a, &b, until);
            let brute = sampled(&a, &b, until, 1e-4);
            // Exact is never above the samples, and the samples come within what the
            // two move in half a sampling step (speeds here are below 600 mm/s).
            assert!(exact <= brute + 1e-9, "{exact} > {brute}");
            assert!(brute - exact <= 0.07, "{exact} vs {brute}");
            // Stopping at the first stretch closer than a clearance answers as the
            // exact approach does, on either side of it and at it.
            for e in [
                exact * 0.5,
                exact,
                exact * (1.0 + 1e-12),
                exact * 2.0,
                next(&mut seed) * 20.0,
            ] {
                assert_eq!(
                    keep_apart_until(&a, &b, until, e),
                    exact >= e,
                    "{exact} against {e}"
                );
            }
        }
    }

    #[test]
    fn the_least_gap_in_y_is_that_of_the_sampled_motions() {
        let mut rng = fastrand::Rng::with_seed(0x9e37_79b9_7f4a_7c15);
        let mut next = move || rng.f64();
        let y_at = |tr: &[(f64, Point2)], t: f64| -> f64 {
            match tr.iter().position(|q| q.0 > t) {
                Some(0) => tr[0].1.y,
                None => tr[tr.len() - 1].1.y,
                Some(k) => {
                    let ((t0, p0), (t1, p1)) = (tr[k - 1], tr[k]);
                    p0.y + (p1.y - p0.y) * ((t - t0) / (t1 - t0))
                }
            }
        };
        for _ in 0..300 {
            // Breakpoints of the two at different times, so that each is read
            // between two of its own at the other's.
            let mut track = |n: usize| {
                let mut t = 0.0;
                (0..n)
                    .map(|k| {
                        if k > 0 {
                            t += 0.05 + next() * 0.3;
                        }
                        (t, Point2::new(next() * 20.0, next() * 20.0))
                    })
                    .collect::<Vec<_>>()
            };
            let (a, b) = (track(2 + 5), track(3 + 4));
            for (sign, until) in [
                (1.0, f64::INFINITY),
                (-1.0, f64::INFINITY),
                (1.0, 0.4),
                (-1.0, 0.7),
            ] {
                let exact = behind_until(&a, &b, until, sign);
                let end = until.min(a[a.len() - 1].0.max(b[b.len() - 1].0));
                let steps = 20_000;
                let brute = (0..=steps)
                    .map(|k| end * k as f64 / steps as f64)
                    .map(|t| sign * (y_at(&a, t) - y_at(&b, t)))
                    .fold(f64::INFINITY, f64::min);
                assert!(exact <= brute + 1e-9, "{exact} > {brute}");
                assert!(brute - exact <= 0.05, "{exact} against {brute}");
            }
        }
        // Two heads on the same side keep nothing.
        let a = [(0.0, Point2::new(0.0, 0.0)), (1.0, Point2::new(0.0, 1.0))];
        assert_eq!(behind_until(&a, &a, 1.0, 0.0), f64::INFINITY);
    }

    /// The look-ahead skips a pair whose bound is clear: the bound of two gantries is
    /// the rear track's least Y less the front track's greatest, whichever is listed
    /// first, and no more than the least gap in Y over the tracks; two heads on the
    /// same side have none to keep, and discs are bounded by their boxes.
    #[test]
    fn the_bound_of_two_motions_is_below_their_least_separation() {
        let spec = |rear: bool| ToolSpec {
            index: usize::from(rear),
            name: String::new(),
            speed: 10.0,
            travel_speed: 10.0,
            envelope: 5.0,
            rear,
        };
        let (front, rear) = (spec(false), spec(true));
        // The front head from y 0 to 10, the rear one from 40 back to 30.
        let f = [(0.0, Point2::new(0.0, 0.0)), (1.0, Point2::new(5.0, 10.0))];
        let r = [(0.0, Point2::new(8.0, 40.0)), (1.0, Point2::new(2.0, 30.0))];
        let y = Separation::OrderedY;
        assert_eq!(y.bound(&front, &rear, &f, &r), 20.0);
        assert_eq!(y.bound(&rear, &front, &r, &f), 20.0);
        assert_eq!(y.bound(&front, &front, &f, &r), f64::INFINITY);
        assert_eq!(y.bound(&rear, &rear, &f, &r), f64::INFINITY);
        // Over the motions the least gap in Y is 20 too (at the end), and in the plane
        // it is at least what the boxes say.
        assert_eq!(behind_until(&r, &f, f64::INFINITY, 1.0), 20.0);
        let discs = Separation::Discs.bound(&front, &rear, &f, &r);
        assert_eq!(discs, gap(&f, &r));
        assert!(discs > 0.0 && discs <= closest(&f, &r), "{discs}");
        // Passing heads: the rear one's track dips below the front one's top, and
        // the bound goes below zero with it.
        let low = [(0.0, Point2::new(8.0, 4.0)), (1.0, Point2::new(2.0, 30.0))];
        assert_eq!(y.bound(&front, &rear, &f, &low), -6.0);
        assert!(y.bound(&front, &rear, &f, &low) <= behind_until(&low, &f, f64::INFINITY, 1.0));
    }

    #[test]
    fn closest_approach_is_found_between_the_checks() {
        // Two tools passing each other 1 mm apart: 10 mm apart at both ends of the
        // step, 1 mm at its middle.
        let a = [(0.0, Point2::new(0.0, 0.0)), (1.0, Point2::new(10.0, 0.0))];
        let b = [(0.0, Point2::new(10.0, 1.0)), (1.0, Point2::new(0.0, 1.0))];
        assert!((closest(&a, &b) - 1.0).abs() < 1e-12);
        // A breakpoint of one motion inside the step: tool a turns at t = 0.5 toward b.
        let a = [
            (0.0, Point2::new(0.0, 0.0)),
            (0.5, Point2::new(5.0, 0.0)),
            (1.0, Point2::new(5.0, 5.0)),
        ];
        let b = [(0.0, Point2::new(5.0, 8.0)), (1.0, Point2::new(5.0, 8.0))];
        assert!((closest(&a, &b) - 3.0).abs() < 1e-12);
        // A tool without a motion meets nothing.
        assert_eq!(closest(&a, &[]), f64::INFINITY);
        assert_eq!(closest(&[], &b), f64::INFINITY);
    }

    fn tool() -> ToolSpec {
        ToolSpec {
            index: 0,
            name: "t".into(),
            speed: 5.0,
            travel_speed: 50.0,
            envelope: 1.0,
            rear: false,
        }
    }

    fn bead(points: &[(f64, f64)]) -> Move {
        Move {
            kind: PathKind::Extrude,
            width: 0.4,
            ..Move::travel(points.iter().map(|&(x, y)| Point2::new(x, y)).collect(), 5.0)
        }
    }

    fn travel(points: &[(f64, f64)]) -> Move {
        Move::travel(points.iter().map(|&(x, y)| Point2::new(x, y)).collect(), 50.0)
    }

    /// A point and its time: x, y, t.
    type Timed = (f64, f64, f64);

    /// The kind, and the timed points (to a nanometre and a nanosecond), of each path
    /// a tool wrote.
    fn written(a: &Agent<'_>) -> Vec<(PathKind, Vec<Timed>)> {
        let r = |v: f64| (v * 1e9).round() / 1e9;
        a.out
            .iter()
            .map(|p| {
                (
                    p.kind,
                    p.points.iter().map(|q| (r(q.p.x), r(q.p.y), r(q.t))).collect(),
                )
            })
            .collect()
    }

    /// The route left is timed from where the tool is: the rest of its move at the
    /// move's speed, and the moves after it.
    #[test]
    fn the_route_left_is_timed_from_the_tools_place() {
        let spec = tool();
        // 20 mm of bead at 5 mm/s, then 10 mm of travel at 50 mm/s.
        let mut a = Agent::new(
            &spec,
            vec![
                bead(&[(0.0, 0.0), (10.0, 0.0), (10.0, 10.0)]),
                travel(&[(10.0, 10.0), (0.0, 10.0)]),
            ],
        );
        let near = |x: f64, y: f64| (x - y).abs() < 1e-12;
        assert!(near(a.remaining(), 4.2), "{}", a.remaining());
        a.advance(0.0, 1.0);
        assert_eq!(a.pos, Point2::new(5.0, 0.0));
        assert!(near(a.remaining(), 3.2), "{}", a.remaining());
        a.advance(1.0, 2.0);
        assert_eq!(a.pos, Point2::new(10.0, 5.0));
        assert!(near(a.remaining(), 1.2), "{}", a.remaining());
        // Past the bead's end, 5 mm into the travel.
        a.advance(3.0, 1.1);
        assert!((a.pos - Point2::new(5.0, 10.0)).norm() < 1e-9, "{:?}", a.pos);
        assert!(near(a.remaining(), 0.1), "{}", a.remaining());
        assert!(!a.done);
        a.advance(4.1, 1.0);
        assert!(a.done && a.remaining() == 0.0);
        assert_eq!(
            written(&a),
            [
                (
                    PathKind::Extrude,
                    vec![(0.0, 0.0, 0.0), (10.0, 0.0, 2.0), (10.0, 10.0, 4.0)]
                ),
                (PathKind::Travel, vec![(10.0, 10.0, 4.0), (0.0, 10.0, 4.2)]),
            ]
        );
    }

    /// A pause that lasts no time and a move that goes nowhere leave no path.
    #[test]
    fn empty_pauses_and_moves_are_not_written() {
        let spec = tool();
        let mut a = Agent::new(
            &spec,
            vec![
                travel(&[(0.0, 0.0), (0.0, 0.0)]),
                bead(&[(0.0, 0.0), (10.0, 0.0)]),
            ],
        );
        a.hold(0.0, 0.0);
        a.advance(0.0, 1.0);
        a.hold(1.0, 0.5);
        a.advance(1.5, 2.0);
        assert!(a.done);
        assert_eq!(
            written(&a),
            [
                (PathKind::Extrude, vec![(0.0, 0.0, 0.0), (5.0, 0.0, 1.0)]),
                (PathKind::Pause, vec![(5.0, 0.0, 1.0), (5.0, 0.0, 1.5)]),
                (PathKind::Extrude, vec![(5.0, 0.0, 1.5), (10.0, 0.0, 2.5)]),
            ]
        );
    }

    /// A side-step leaves the bead where the tool is, travels to the side and back
    /// (the way back yielding), and finishes the bead; the tool stays where it was.
    #[test]
    fn a_side_step_goes_aside_and_back_and_finishes_the_bead() {
        let spec = tool();
        let mut a = Agent::new(&spec, vec![bead(&[(0.0, 0.0), (10.0, 0.0)])]);
        a.advance(0.0, 1.0);
        a.side_step(Point2::new(5.0, 5.0));
        type Leg = (PathKind, Vec<(f64, f64)>, bool);
        let route: Vec<Leg> = a
            .route
            .iter()
            .map(|m| (m.kind, m.points.iter().map(|p| (p.x, p.y)).collect(), m.yields))
            .collect();
        assert_eq!(
            route,
            [
                (PathKind::Extrude, vec![(0.0, 0.0), (5.0, 0.0)], false),
                (PathKind::Travel, vec![(5.0, 0.0), (5.0, 5.0)], false),
                (PathKind::Travel, vec![(5.0, 5.0), (5.0, 0.0)], true),
                (PathKind::Extrude, vec![(5.0, 0.0), (10.0, 0.0)], false),
            ]
        );
        assert_eq!(a.pos, Point2::new(5.0, 0.0));
        // At the end of the first piece: 5 mm aside and back at 50 mm/s, 5 mm of bead.
        assert!((a.remaining() - 1.2).abs() < 1e-12, "{}", a.remaining());
        assert!(!a.yields());
        a.advance(1.0, 0.15);
        assert!(a.yields(), "on the way back");
        a.advance(1.15, 2.0);
        assert!(a.done && !a.yields());
        let kinds: Vec<PathKind> = a.out.iter().map(|p| p.kind).collect();
        assert_eq!(
            kinds,
            [
                PathKind::Extrude,
                PathKind::Travel,
                PathKind::Travel,
                PathKind::Extrude
            ]
        );
        assert!((a.out[3].points[1].t - 2.2).abs() < 1e-12);
    }

    #[test]
    fn a_stuck_schedule_says_why() {
        assert_eq!(
            Stuck::Deadlock(40).to_string(),
            "the tools kept blocking each other after 40 side-steps"
        );
        assert_eq!(
            Stuck::Timeout(600.0).to_string(),
            "the simulation ran past its 600 s budget"
        );
    }

    fn settings(step: f64, look_ahead: f64, separation: Separation) -> Settings {
        Settings {
            step,
            budget: 1e4,
            max_side_steps: 2,
            priority: Priority::XSpeed,
            look_ahead,
            separation,
            room: 0.0,
        }
    }

    /// Two tools are far apart when they keep their envelopes (and the room) apart
    /// even if both ran at their top speeds toward each other until the farthest
    /// horizon a check looks to: the look-ahead when looking ahead, else the step.
    #[test]
    fn tools_are_far_apart_beyond_their_top_speeds_over_the_horizon() {
        let spec = tool();
        let arena = BBox2::EMPTY;
        let far = |d: f64, look_ahead: f64, separation: Separation, fast: f64| {
            let mut second = bead(&[(d, 0.0), (d, 10.0)]);
            second.speed = fast;
            let tools = [
                (&spec, vec![bead(&[(0.0, 0.0), (0.0, 10.0)])]),
                (&spec, vec![second]),
            ];
            Run::start(&tools, &settings(0.1, look_ahead, separation), &arena).far_apart()
        };
        // Top speeds 50 and 50 mm/s over 0.5 s, envelopes 1 + 1 mm.
        assert!(far(52.01, 0.5, Separation::Discs, 5.0));
        assert!(!far(51.99, 0.5, Separation::Discs, 5.0));
        // Over the step alone: 10 mm of reach.
        assert!(far(12.01, 0.0, Separation::Discs, 5.0));
        assert!(!far(11.99, 0.0, Separation::Discs, 5.0));
        // A move faster than the travels sets the top speed.
        assert!(!far(52.01, 0.5, Separation::Discs, 80.0));
        assert!(far(67.01, 0.5, Separation::Discs, 80.0));
        // Gantries: only Y counts (the rear head 52 mm behind, whatever the X), and
        // heads on the same side never meet.
        let front = ToolSpec {
            rear: false,
            ..tool()
        };
        let rear = ToolSpec { rear: true, ..tool() };
        let gantries = |y: f64| {
            let tools = [
                (&front, vec![bead(&[(0.0, 0.0), (10.0, 0.0)])]),
                (&rear, vec![bead(&[(200.0, y), (210.0, y)])]),
            ];
            Run::start(&tools, &settings(0.1, 0.5, Separation::OrderedY), &arena).far_apart()
        };
        assert!(gantries(52.01) && !gantries(51.99) && !gantries(-60.0));
        let same = [
            (&front, vec![bead(&[(0.0, 0.0), (10.0, 0.0)])]),
            (&front, vec![bead(&[(0.0, 1.0), (10.0, 1.0)])]),
        ];
        assert!(Run::start(&same, &settings(0.1, 0.5, Separation::OrderedY), &arena).far_apart());
    }

    /// Looking ahead means looking more than a step and a half ahead.
    #[test]
    fn a_run_looks_ahead_beyond_a_step_and_a_half() {
        let spec = tool();
        let tools = [(&spec, vec![bead(&[(0.0, 0.0), (10.0, 0.0)])])];
        let arena = BBox2::EMPTY;
        let ahead = |look_ahead: f64| {
            Run::start(&tools, &settings(0.5, look_ahead, Separation::Discs), &arena).anticipate
        };
        assert!(!ahead(0.0) && !ahead(0.5) && !ahead(0.75));
        assert!(ahead(0.76) && ahead(2.0));
    }

    /// On gantries a deadlock is broken by the head with less work left backing off
    /// toward its own side, twice the room the two need (envelopes and half a step at
    /// top speed) beyond where it is; past `max_side_steps` the schedule is stuck.
    #[test]
    fn a_gantry_head_steps_back_toward_its_own_side() {
        let front = tool();
        let rear = ToolSpec {
            index: 1,
            envelope: 3.0,
            travel_speed: 100.0,
            rear: true,
            ..tool()
        };
        let arena = BBox2::EMPTY;
        let set = settings(0.01, 0.0, Separation::OrderedY);
        // The room between them: 1 + 3 + (50 + 100) x 0.01 / 2 = 4.75 mm.
        let side_step = |front_work: f64, rear_work: f64| {
            let tools = [
                (&front, vec![bead(&[(0.0, 10.0), (front_work, 10.0)])]),
                (&rear, vec![bead(&[(0.0, 14.0), (rear_work, 14.0)])]),
            ];
            let mut run = Run::start(&tools, &set, &arena);
            assert_eq!(run.step_aside(), Ok(true));
            let moved: Vec<Vec<(f64, f64)>> = run
                .agents
                .iter()
                .map(|a| {
                    a.route
                        .get(1)
                        .map_or(Vec::new(), |m| m.points.iter().map(|p| (p.x, p.y)).collect())
                })
                .collect();
            assert_eq!(run.step_aside(), Ok(true));
            assert_eq!(run.step_aside(), Err(Stuck::Deadlock(2)));
            moved
        };
        assert_eq!(side_step(40.0, 80.0), [vec![(0.0, 10.0), (0.0, 0.5)], vec![]]);
        assert_eq!(side_step(80.0, 40.0), [vec![], vec![(0.0, 14.0), (0.0, 23.5)]]);
    }

    /// The box bound: the gap between the tracks' bounding boxes.
    #[test]
    fn the_box_gap_is_that_of_the_tracks_boxes() {
        let a = [(0.0, Point2::new(0.0, 0.0)), (1.0, Point2::new(2.0, 2.0))];
        let b = [
            (0.0, Point2::new(6.0, 7.0)),
            (0.5, Point2::new(5.0, 6.0)),
            (1.0, Point2::new(6.0, 6.5)),
        ];
        assert_eq!(gap(&a, &b), 5.0);
        assert_eq!(gap(&b, &a), 5.0);
        // Overlapping in X: the gap in Y; overlapping boxes: 0.
        let c = [(0.0, Point2::new(1.0, 5.0)), (1.0, Point2::new(9.0, 5.0))];
        assert_eq!(gap(&a, &c), 3.0);
        assert_eq!(gap(&c, &b), 1.0);
        let d = [(0.0, Point2::new(4.0, 4.0)), (1.0, Point2::new(7.0, 6.5))];
        assert_eq!(gap(&d, &b), 0.0);
    }

    /// Over a horizon, the box is that of the motion up to it: the breakpoints before
    /// it and where the track is at it, not what comes after.
    #[test]
    fn the_box_gap_over_a_horizon_is_that_of_the_motion_up_to_it() {
        let p = |x: f64, y: f64| Point2::new(x, y);
        let a = [(0.0, p(0.0, 0.0)), (1.0, p(2.0, 0.0)), (3.0, p(10.0, 0.0))];
        let b = [(0.0, p(10.0, 0.0)), (3.0, p(10.0, 3.0))];
        // At 2 s, a is at x = 6: 4 mm short of b's box.
        assert_eq!(gap_until(&a, &b, 2.0), 4.0);
        assert_eq!(gap_until(&a, &b, 1.0), 8.0);
        assert_eq!(gap_until(&a, &b, 0.0), 10.0);
        assert_eq!(gap_until(&a, &b, 5.0), 0.0);
        assert_eq!(bounds_until(&a, 2.0), [0.0, 0.0, 6.0, 0.0]);
        // Gantries: the rear head's least Y and the front head's greatest, up to then.
        let (front, rear) = (
            ToolSpec {
                rear: false,
                ..tool()
            },
            ToolSpec { rear: true, ..tool() },
        );
        let f = [(0.0, p(0.0, 0.0)), (2.0, p(0.0, 4.0))];
        let r = [(0.0, p(0.0, 10.0)), (2.0, p(0.0, 2.0))];
        let y = Separation::OrderedY;
        assert_eq!(y.bound_until(&front, &rear, &f, &r, 1.0), 4.0);
        assert_eq!(y.bound_until(&rear, &front, &r, &f, 1.0), 4.0);
        assert_eq!(y.bound_until(&front, &rear, &f, &r, 2.0), -2.0);
    }

    /// The first `h` seconds of a track end where the track is at `h`.
    #[test]
    fn a_track_is_cut_where_it_is_at_the_horizon() {
        let p = |x: f64, y: f64| Point2::new(x, y);
        let track = [(0.0, p(0.0, 0.0)), (1.0, p(10.0, 0.0)), (2.0, p(10.0, 10.0))];
        let mut out = Vec::new();
        let mut cut = |h: f64| {
            truncate(&track, h, &mut out);
            out.iter().map(|&(t, q)| (t, q.x, q.y)).collect::<Vec<_>>()
        };
        assert_eq!(cut(0.5), [(0.0, 0.0, 0.0), (0.5, 5.0, 0.0)]);
        assert_eq!(cut(1.0), [(0.0, 0.0, 0.0), (1.0, 10.0, 0.0)]);
        assert_eq!(cut(1.25), [(0.0, 0.0, 0.0), (1.0, 10.0, 0.0), (1.25, 10.0, 2.5)]);
        assert_eq!(
            cut(3.0),
            [
                (0.0, 0.0, 0.0),
                (1.0, 10.0, 0.0),
                (2.0, 10.0, 10.0),
                (3.0, 10.0, 10.0)
            ]
        );
        // Along a two-second segment, a quarter of it.
        let slow = [(0.0, p(0.0, 0.0)), (2.0, p(10.0, 0.0))];
        truncate(&slow, 0.5, &mut out);
        assert_eq!(out, [(0.0, p(0.0, 0.0)), (0.5, p(2.5, 0.0))]);
        // A jump (two points at one time) is cut at its end.
        let jump = [
            (0.0, p(0.0, 0.0)),
            (1.0, p(0.0, 0.0)),
            (1.0, p(4.0, 0.0)),
            (2.0, p(4.0, 0.0)),
        ];
        truncate(&jump, 1.0, &mut out);
        assert_eq!(out.last(), Some(&(1.0, p(0.0, 0.0))));
    }

    /// A tool stepping aside goes away from the tools within three times the room it
    /// needs from them, twice that room out, to the nearest place (turning by 45° at a
    /// time, then farther) that leaves it 1.5 times the room from every other tool
    /// and lies inside the arena; with no tool near, toward -Y; with no such place,
    /// straight away, clamped into the arena.
    #[test]
    fn a_tool_steps_aside_away_from_its_neighbours_inside_the_arena() {
        let spec = tool();
        let at = |x: f64, y: f64| Agent::new(&spec, vec![bead(&[(x, y), (x + 1.0, y)])]);
        // The room two tools need: 2 mm.
        let clear = |_: &Agent<'_>, _: &Agent<'_>| 2.0;
        let open = BBox2::EMPTY;
        let aside_of = |agents: &[Agent<'_>], arena: &BBox2| {
            let p = aside(agents, 0, &clear, arena);
            ((p.x * 1e9).round() / 1e9, (p.y * 1e9).round() / 1e9)
        };
        let h = 4.0 / 2f64.sqrt();
        let h = (h * 1e9).round() / 1e9;
        let h3 = (6.0 / 2f64.sqrt() * 1e9).round() / 1e9;
        // A tool 3 mm to the right: 4 mm to the left.
        assert_eq!(aside_of(&[at(0.0, 0.0), at(3.0, 0.0)], &open), (-4.0, 0.0));
        // One within three times the room (6 mm) pushes too: away from both; one at
        // 6 mm does not.
        assert_eq!(
            aside_of(&[at(0.0, 0.0), at(3.0, 0.0), at(0.0, 5.9)], &open),
            (-h, -h)
        );
        assert_eq!(
            aside_of(&[at(0.0, 0.0), at(3.0, 0.0), at(0.0, 6.0)], &open),
            (-4.0, 0.0)
        );
        // Directions count, not distances: away from (3, 0) and (0, -2) alike.
        assert_eq!(
            aside_of(&[at(0.0, 0.0), at(3.0, 0.0), at(0.0, -2.0)], &open),
            (-h, h)
        );
        // No tool near, or one in the same place: toward -Y.
        assert_eq!(aside_of(&[at(0.0, 0.0), at(30.0, 0.0)], &open), (0.0, -4.0));
        assert_eq!(aside_of(&[at(0.0, 0.0), at(0.0, 0.0)], &open), (0.0, -4.0));
        // A tool 6.5 mm to the left does not push, but (-4, 0) is too close to it: the
        // next place, turned 45°.
        assert_eq!(
            aside_of(&[at(0.0, 0.0), at(3.0, 0.0), at(-6.5, 0.0)], &open),
            (-h, -h)
        );
        // One at 7.2 mm leaves (-4, 0) 3.2 mm from it, room enough.
        assert_eq!(
            aside_of(&[at(0.0, 0.0), at(3.0, 0.0), at(-7.2, 0.0)], &open),
            (-4.0, 0.0)
        );
        // Inside an arena from x = -1: turned 90°, to -Y; from y = -1 too: to +Y.
        let arena = |x0: f64, y0: f64, x1: f64, y1: f64| BBox2 {
            min: Point2::new(x0, y0),
            max: Point2::new(x1, y1),
        };
        let pair = [at(0.0, 0.0), at(3.0, 0.0)];
        assert_eq!(aside_of(&pair, &arena(-1.0, -10.0, 10.0, 10.0)), (0.0, -4.0));
        assert_eq!(aside_of(&pair, &arena(-1.0, -1.0, 10.0, 10.0)), (0.0, 4.0));
        // The arena's other sides: a tool to the left sends it right, unless the
        // arena ends at x = 1; one below sends it up, unless it ends at y = 1.
        let left = [at(0.0, 0.0), at(-3.0, 0.0)];
        assert_eq!(aside_of(&left, &arena(-10.0, -10.0, 10.0, 10.0)), (4.0, 0.0));
        assert_eq!(aside_of(&left, &arena(-10.0, -1.0, 1.0, 10.0)), (0.0, 4.0));
        let below = [at(0.0, 0.0), at(0.0, -3.0)];
        assert_eq!(aside_of(&below, &arena(-10.0, -10.0, 10.0, 1.0)), (-4.0, 0.0));
        // From x = -3 and y = -1: turned -45°; from x = 2 and y = -1: turned -135°, and
        // three times the room out (twice is too close to the tool at (3, 0)).
        assert_eq!(aside_of(&pair, &arena(-3.0, -1.0, 10.0, 10.0)), (-h, h));
        assert_eq!(aside_of(&pair, &arena(2.0, -1.0, 10.0, 10.0)), (h3, h3));
        // Nowhere with room inside a narrow arena: straight away, twice the room.
        let crowd = [at(0.0, 0.0), at(3.0, 0.0), at(-6.5, 0.0)];
        assert_eq!(aside_of(&crowd, &arena(-5.0, -0.5, 5.0, 0.5)), (-4.0, 0.0));
        // Boxed in: straight away, clamped.
        assert_eq!(aside_of(&pair, &arena(-1.0, -1.0, 1.0, 1.0)), (-1.0, 0.0));
    }

    /// A pause is counted once, by what started it; when it goes on by another rule
    /// than the paper's, it is counted again as a break of the rule.
    #[test]
    fn a_pause_that_goes_on_by_another_rule_is_counted_as_a_break() {
        let spec = tool();
        let tools = [
            (&spec, vec![bead(&[(0.0, 0.0), (10.0, 0.0)])]),
            (&spec, vec![bead(&[(0.0, 5.0), (10.0, 5.0)])]),
        ];
        let arena = BBox2::EMPTY;
        let mut run = Run::start(&tools, &settings(0.1, 0.0, Separation::Discs), &arena);
        let counts = |run: &Run<'_>| (run.pauses.by_x_speed, run.pauses.forced, run.pauses.other);
        let check = |run: &mut Run<'_>, why: Option<Why>| {
            run.moving = vec![false, true];
            run.why = vec![why, None];
            run.take_step();
        };
        check(&mut run, Some(Why::XSpeed));
        assert_eq!(counts(&run), (1, 0, 0));
        check(&mut run, Some(Why::XSpeed));
        assert_eq!(counts(&run), (1, 0, 0));
        check(&mut run, Some(Why::Other));
        assert_eq!(counts(&run), (0, 0, 1));
        check(&mut run, Some(Why::Other));
        assert_eq!(counts(&run), (0, 0, 1));
        // Moving on, then a forced pause.
        run.moving = vec![true, true];
        run.take_step();
        check(&mut run, Some(Why::Forced));
        assert_eq!(counts(&run), (0, 1, 1));
        // The held tool kept its place; the other moved 0.5 mm a step.
        assert_eq!(run.agents[0].pos, Point2::new(0.5, 0.0));
        assert!((run.agents[1].pos - Point2::new(3.0, 5.0)).norm() < 1e-9);
    }
}
