//! lamina-plan: toolpath planners. Every sub-region is filled with contour-parallel
//! closed loops along its iso-material contours (`fill`), the loops are handed to the
//! tools and ordered nearest-next (`route`), and the tools' routes are timed either one
//! tool after another (`sequential`, the baseline, also registered as `contour` for the
//! single-tool and mixing-head case) or all at once with dynamic priority
//! (`concurrent`, `sim`).
//!
//! Tools: without `mixing`, there is one tool per pipeline material (tool i deposits
//! material i) and the beads of a graded sub-region are shared between the tools by its
//! fractions (`assign`): each path carries the one material its tool deposits. With
//! `mixing = true` a single mixing tool deposits everything and each path carries its
//! sub-region's composition for the mixing head. Either way the composition on the
//! path is what it deposits, so exporters can meter mixtures.

pub mod assign;
pub mod axis;
pub mod bead;
pub mod fill;
pub mod group;
pub mod pieces;
pub mod route;
pub mod sim;

use std::collections::BTreeMap;

use lamina_api::machine::HeadClass;
use lamina_api::stage::{AnyStage, Planner, StageConfig, StageInfo, StageKind};
use lamina_api::{BBox2, Error, LayerPlan, Point2, Result, RunInfo, StageFactory, Toolpath, Vector2};
use serde::Deserialize;

use crate::assign::Assign;
use crate::fill::Widths;
use crate::group::Thin;
use crate::route::{Move, Parks, Seam, ToolSpec, distribute, pause, route, timed};
use crate::sim::Priority;

/// Side-steps allowed per layer before the concurrent planner falls back to sequential.
const MAX_SIDE_STEPS: usize = 200;

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct ToolOptions {
    speed: Option<f64>,
    travel_speed: Option<f64>,
    envelope: Option<f64>,
}

lamina_api::stage_options! {
    #[derive(Debug, Clone)]
    struct Options {
        /// nominal bead width (mm), by default the machine's nozzle diameter: loops at w/2, 3w/2, ... inside each sub-region, the width bent within `width_range` to fill a band with a whole number of beads; what loops leave is filled by variable-width beads along its centre line
        #[range(MIN_WIDTH, MAX_WIDTH)]
        width: f64 = "0.4",
        /// narrowest and widest bead as fractions of `width`; sub-regions narrower than the narrowest merge with their neighbours (`thin`)
        #[range(0.05, 10.0)]
        width_range: [f64; 2] = "[0.6, 1.5]",
        /// least share of the sub-regions' volume the beads must deposit over the run; below it the run fails
        #[range(0.0, 1.0)]
        min_fill: f64 = "0.98",
        /// where loops start: `nearest` (to the tool) or `aligned` (largest x)
        seam: Seam = r#""nearest""#,
        /// one mixing tool for everything (composition on the path) instead of one tool per material
        mixing: bool = "false",
        /// with one tool per material, who lays a graded sub-region's beads: `fraction` (each tool its material's share of the area, in whole beads and bands, the remainder carried to the next sub-region; each bead is labelled with the material it deposits) or `dominant` (all by the tool of the largest fraction)
        assign: Assign = r#""fraction""#,
        /// sub-regions narrower than the narrowest bead: `merge` (deposited with the next levels of their family, mean composition) or `skip` (left out); either way they are reported
        thin: Thin = r#""merge""#,
        /// deposition speed (mm/s)
        #[range(0.01, MAX_SPEED)]
        speed: f64 = "30.0",
        /// travel speed (mm/s)
        #[range(0.01, MAX_SPEED)]
        travel_speed: f64 = "120.0",
        /// tool envelope radius (mm); tools park outside each other's envelopes; the machine's head envelope plus 1 mm when it gives one (and at least the envelope)
        #[range(0.001, 1e4)]
        envelope: f64 = "5.0",
        /// seconds to change tools between two tools' turns (sequential); 0 by default on a machine whose heads are on motion systems of their own
        #[range(0.0, 3600.0)]
        tool_change: f64 = "5.0",
        /// per-tool `speed`, `travel_speed`, `envelope`, keyed by material name (or `mixer`)
        tools: BTreeMap<String, ToolOptions> = "{}",
        // The concurrent planner's own options, after the COMMON_OPTIONS every planner
        // documents.
        /// seconds between collision checks
        #[range(1e-4, 10.0)]
        step: f64 = "0.01",
        /// add a note to each layer with the sequential build time
        compare: bool = "false",
        /// who keeps going when two tools are about to collide: `x-speed` (the paper's rule: the tool faster along X at the check, the X component of its velocity, goes on and the other pauses; on a tie the first tool goes on; a tool whose pausing would not clear the conflict is never the one paused), `clearing` (a tool whose pausing alone clears the conflict pauses, else one already paused stays paused, else one returning from a side-step gives way, else `x-speed`), `returning` (a tool returning from a side-step gives way, else one already paused stays paused, else `x-speed`) `waiting` (one already paused stays paused, else `x-speed`) or `busiest` (a tool whose pausing alone clears the conflict pauses, else the one with less of its route left: the layer ends when the busiest tool is done); the run counts the pauses each rule decided
        priority: Priority = r#""x-speed""#,
        /// seconds ahead a collision is looked for: one in prospect within half of it pauses a tool now, where its pausing alone keeps the tools apart (when either would, the priority decides), until none is in prospect within the whole of it, and a paused tool goes on once its way is clear for half of it; tools meeting head-on then wait before the way narrows instead of one stepping aside, and a tool following another pauses seldom and for longer, cutting its bead (and making both heads stop at a synchronisation point) less often. 0 (up to `step`) checks only the next step, as the paper does
        #[range(0.0, 60.0)]
        look_ahead: f64 = "0.5",
        /// room (mm) beyond the envelopes that looking ahead keeps between two tools: one following another hangs back this much more, pausing less often and for longer (on a machine with two motion systems, far fewer synchronisation points, each of which stops both nozzles with their filament pulled back); the envelopes themselves are kept either way
        #[range(0.0, 1e3)]
        room: f64 = "0.0",
        /// how many orders of each tool's loops two free heads try per layer: the nearest-next order from where the tool enters, then from the corners of the work farthest from it; every pair of orders is scheduled (`orders`² schedules a layer) and the fastest kept, each synchronisation counted at its cost (see `keep_faster`). 1 tries the first order only. Heads on two gantries, which sweep the layer front to back, three or more busy tools, and a machine whose heads print one at a time (one motion system) take the first
        #[range(1, 5)]
        orders: usize = "2",
        /// deposit a layer one tool at a time when that is faster than the concurrent schedule, each synchronisation of the heads counted at what it costs the machine (a stop, and a retraction, on a machine with two motion systems); a note says which and why. `false` keeps the concurrent schedule (with a warning when it is slower). A layer whose tools stay blocked falls back to one tool at a time regardless
        keep_faster: bool = "true",
    }
}

/// How many of [`Options::SPECS`], from the first, every planner documents; the
/// others are the concurrent planner's.
const COMMON_OPTIONS: usize = 12;

/// Narrowest and widest bead (mm): from a fine nozzle to a wide laser-deposition track.
const MIN_WIDTH: f64 = 0.01;
const MAX_WIDTH: f64 = 50.0;
/// Fastest move (mm/s).
const MAX_SPEED: f64 = 10_000.0;

/// Name of the single tool when `mixing = true`.
pub const MIXER: &str = "mixer";

impl Options {
    fn check(&self, config: &StageConfig<'_>, concurrent: bool) -> Result<()> {
        // Each value within what a machine can do: a bead of a nanometre or a check
        // every nanosecond would only multiply the work without bound.
        let within = |k: &str, v: f64, lo: f64, hi: f64, unit: &str| {
            if v.is_finite() && v >= lo && v <= hi {
                Ok(())
            } else {
                Err(config.error(k, format!("must be between {lo} and {hi} {unit}, not {v}")))
            }
        };
        let positive = |k: &str, v: f64| within(k, v, 1e-3, 1e5, "");
        within("width", self.width(), MIN_WIDTH, MAX_WIDTH, "mm")?;
        let [lo, hi] = self.width_range;
        if !((0.05..=1.0).contains(&lo) && (1.0..=10.0).contains(&hi)) {
            return Err(config.error(
                "width_range",
                "must be [min, max] fractions of `width` with 0.05 <= min <= 1 <= max <= 10",
            ));
        }
        // `min_fill`, the speeds, `envelope`, `tool_change`, `step`, `look_ahead` and
        // `room` are held to their declared ranges as they are read. `step`, `compare`,
        // `priority` and `keep_faster` mean nothing to the sequential planner but are
        // accepted, so that `--set plan.use=sequential` compares a concurrent pipeline.
        let _ = concurrent;
        for (name, t) in &self.tools {
            for (k, v) in [
                ("speed", t.speed),
                ("travel_speed", t.travel_speed),
                ("envelope", t.envelope),
            ] {
                if let Some(v) = v
                    && positive(k, v).is_err()
                {
                    return Err(config.error(
                        "tools",
                        format!("tools.{name}.{k} must be a positive number up to 1e5"),
                    ));
                }
            }
        }
        Ok(())
    }

    /// The tools of a run: one per material, or the mixer.
    fn tools(&self, info: &RunInfo) -> Result<Vec<ToolSpec>> {
        let names: Vec<String> = if self.mixing {
            vec![MIXER.to_string()]
        } else {
            info.materials.iter().map(|m| m.name.clone()).collect()
        };
        for key in self.tools.keys() {
            if !names.contains(key) {
                return Err(Error::stage(
                    "plan",
                    format!("tools.{key}: no such tool (the tools are {})", names.join(", ")),
                ));
            }
        }
        Ok(names
            .into_iter()
            .enumerate()
            .map(|(index, name)| {
                let t = self.tools.get(&name);
                ToolSpec {
                    index,
                    speed: t.and_then(|t| t.speed).unwrap_or(self.speed),
                    travel_speed: t.and_then(|t| t.travel_speed).unwrap_or(self.travel_speed),
                    envelope: t.and_then(|t| t.envelope).unwrap_or(self.envelope),
                    rear: rear(info, index, &name),
                    name,
                }
            })
            .collect())
    }

    fn step(&self) -> f64 {
        self.step
    }

    fn width(&self) -> f64 {
        self.width
    }

    /// Options as written, with the width the machine's nozzle gives when the stage
    /// names none.
    fn parse(config: &StageConfig<'_>) -> Result<Self> {
        let mut o: Options = config.parse()?;
        if !config.has("width")
            && let Some(m) = config.machine
        {
            o.width = m.nozzle_diameter;
        }
        // Heads that must keep out of each other: the machine's envelopes are the least
        // the plan may keep.
        // Heads on motion systems of their own change no tool: one waits in its park
        // while the other works.
        if !config.has("tool_change")
            && let Some(m) = config.machine
            && m.motion_systems > 1
        {
            o.tool_change = 0.0;
        }
        let margin = config.machine.map_or(1.0, |m| m.kinematics.margin);
        let machine = config
            .machine
            .and_then(|m| m.tools.iter().filter_map(|t| t.envelope).reduce(f64::max));
        if let Some(e) = machine {
            if !config.has("envelope") {
                o.envelope = e + margin;
            } else if o.envelope < e {
                return Err(config.error(
                    "envelope",
                    format!(
                        "{} mm is less than the {e} mm the machine's heads keep out of each other",
                        o.envelope
                    ),
                ));
            }
        }
        Ok(o)
    }

    fn widths(&self) -> Widths {
        Widths {
            nominal: self.width(),
            min: self.width() * self.width_range[0],
            max: self.width() * self.width_range[1],
        }
    }
}

/// What one synchronisation of two heads costs a machine that runs them on motion
/// systems of their own (s): each head stops from its deposition speed and starts
/// again, and pulls its filament back and pushes it out while it may wait. Machines
/// that take the tools in turn synchronise nothing.
fn sync_cost(o: &Options, info: &RunInfo) -> f64 {
    let Some(m) = info.machine.as_ref().filter(|m| m.motion_systems > 1) else {
        return 0.0;
    };
    let stop = o.speed / m.motion.print_acceleration.max(1.0);
    let retract = 2.0 * m.retraction.length / m.retraction.speed.max(1e-3);
    stop + retract
}

/// The machine's heads' kinematics class (free heads without a machine).
/// The bed in the plan's coordinates (where the exporter places the plan on it), or
/// an empty box without a machine: what the heads can reach. A round bed gives the
/// square inside it.
fn bed_reach(info: &RunInfo) -> BBox2 {
    let Some(m) = &info.machine else {
        return BBox2::EMPTY;
    };
    let off = m.placement_offset(&info.xy_bounds);
    let b = m.bed.bounds();
    let inset = match m.bed.shape {
        lamina_api::machine::BedShape::Rectangle { .. } => 0.0,
        lamina_api::machine::BedShape::Circle { diameter } => {
            diameter / 2.0 * (1.0 - std::f64::consts::FRAC_1_SQRT_2)
        }
    };
    BBox2 {
        min: b.min - off + Vector2::new(inset, inset),
        max: b.max - off - Vector2::new(inset, inset),
    }
}

/// Refuses beads two gantries cannot lay: with the front head as far forward as the
/// bed goes, the rear head reaches no nearer the front edge than the two envelopes,
/// and the front head no nearer the back edge. A plate that fills the bed in Y puts
/// some of the rear head's beads out of its reach (or the front head's).
fn within_gantry_reach(tools: &[ToolSpec], jobs: &[Vec<route::Job>], info: &RunInfo) -> Result<()> {
    let reach = bed_reach(info);
    if reach.is_empty() {
        return Ok(());
    }
    let keep = |rear: bool| {
        tools
            .iter()
            .filter(|t| t.rear != rear)
            .map(|t| t.envelope)
            .fold(0.0, f64::max)
    };
    let shift = info
        .machine
        .as_ref()
        .map_or(0.0, |m| m.placement_offset(&info.xy_bounds).y);
    for (t, jobs) in tools.iter().zip(jobs) {
        let (lo, hi) = jobs
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), j| {
                (lo.min(j.bbox.min.y), hi.max(j.bbox.max.y))
            });
        let gap = t.envelope + keep(t.rear);
        let (out, limit, edge) = if t.rear {
            (lo < reach.min.y + gap, reach.min.y + gap, "front")
        } else {
            (hi > reach.max.y - gap, reach.max.y - gap, "back")
        };
        if out {
            let at = if t.rear { lo } else { hi };
            return Err(Error::stage(
                "plan",
                format!(
                    "the {} head (tool {}, {}) has beads at Y {:.1} mm on the bed, but on two gantries it reaches no nearer the bed's {edge} edge than Y {:.1} mm (the heads' envelopes apart, the other head at the edge): move the parts away from that edge (fewer copies or a smaller `copy_gap`, or a smaller plate)",
                    if t.rear { "rear" } else { "front" },
                    t.index,
                    t.name,
                    at + shift,
                    limit + shift
                ),
            ));
        }
    }
    Ok(())
}

fn head_class(info: &RunInfo) -> HeadClass {
    info.machine
        .as_ref()
        .map_or(HeadClass::Free, |m| m.kinematics.class)
}

/// Whether tool `index` (material `name`) is on the rear gantry of a two-gantry
/// machine: its head homes behind the other's.
fn rear(info: &RunInfo, index: usize, name: &str) -> bool {
    let Some(m) = info
        .machine
        .as_ref()
        .filter(|m| m.kinematics.class == HeadClass::DualGantry)
    else {
        return false;
    };
    let home_y = |slot: usize| m.tools.get(slot).and_then(|t| t.home).map(|h| h[1]);
    let front = (0..m.tools.len())
        .filter_map(home_y)
        .fold(f64::INFINITY, f64::min);
    m.tool_of(name, index).and_then(home_y).is_some_and(|y| y > front)
}

/// The routes of every tool with work in the layer, and the layer's warnings.
struct Layer {
    tools: Vec<ToolSpec>,
    routes: Vec<Vec<Move>>,
    /// Per tool, its routes in other orders (`Options::orders`; none for a planner
    /// that takes the first).
    others: Vec<Vec<Vec<Move>>>,
    /// Where a tool may step aside: anywhere above the entry row below the deposits,
    /// which keeps it clear of every park.
    arena: BBox2,
}

impl Layer {
    /// The busy tools, tool k on its route in order `choice[k]` (0: the first).
    fn in_orders(&self, choice: &[usize]) -> Vec<(&ToolSpec, Vec<Move>)> {
        self.tools
            .iter()
            .zip(&self.routes)
            .enumerate()
            .filter(|(_, (_, r))| !r.is_empty())
            .map(|(k, (t, r))| {
                let c = choice.get(k).copied().unwrap_or(0);
                let other = c.checked_sub(1).and_then(|c| self.others.get(k)?.get(c));
                (t, other.unwrap_or(r).clone())
            })
            .collect()
    }

    /// The concurrent schedule of the first orders and, for two busy tools, of every
    /// other pair of their orders: the first of the fastest (each synchronisation
    /// counted at `sync` seconds; strictly faster replaces, so that ties keep the lower
    /// orders), with the orders it takes (0: the first).
    fn fastest_orders(
        &self,
        settings: &sim::Settings,
        sync: f64,
    ) -> (std::result::Result<sim::Schedule, sim::Stuck>, (usize, usize)) {
        let costed = |r: &std::result::Result<sim::Schedule, sim::Stuck>| {
            r.as_ref()
                .map_or(f64::INFINITY, |s| s.end + syncs(&s.pauses) * sync)
        };
        let mut run = sim::concurrent(&self.in_orders(&[]), settings, &self.arena);
        let mut chosen = (0, 0);
        let busy: Vec<usize> = (0..self.tools.len())
            .filter(|&k| !self.routes[k].is_empty())
            .collect();
        if let [a, b] = busy[..] {
            let n = |k: usize| self.others.get(k).map_or(0, Vec::len) + 1;
            for (i, j) in (0..n(a)).flat_map(|i| (0..n(b)).map(move |j| (i, j))).skip(1) {
                let mut choice = vec![0; self.tools.len()];
                (choice[a], choice[b]) = (i, j);
                let other = sim::concurrent(&self.in_orders(&choice), settings, &self.arena);
                if costed(&other) < costed(&run) {
                    run = other;
                    chosen = (i, j);
                }
            }
        }
        (run, chosen)
    }
}

/// The synchronisations a schedule's pauses make: each ends where the waiting head
/// goes on.
fn syncs(p: &lamina_api::Pauses) -> f64 {
    (p.by_x_speed + p.forced + p.other) as f64
}

/// The layer's work and each tool's route; with `orders` > 1, also each tool's routes
/// in up to `orders - 1` other orders.
fn prepare(o: &Options, info: &RunInfo, plan: &mut LayerPlan, step: f64, orders: usize) -> Result<Layer> {
    let tools = o.tools(info)?;
    if tools.is_empty() {
        return Err(Error::stage("plan", "the pipeline has no materials, so no tools"));
    }
    let widths = o.widths();
    let work = distribute(info, plan, tools.len(), &widths, o.mixing, o.thin, o.assign);
    // A sub-region of no area (below what the message's three decimals show) leaves
    // nothing out of the part: it is not reported.
    let thin: Vec<&(String, usize, f64)> = work.thin.iter().filter(|(_, _, a)| *a >= 0.0005).collect();
    if !thin.is_empty() {
        let list: Vec<String> = thin
            .iter()
            .take(5)
            .map(|(part, r, a)| format!("part `{part}` sub-region {r} ({a:.3} mm²)"))
            .collect();
        let more = thin.len().saturating_sub(5);
        plan.warn(
            StageKind::Plan,
            "thin-sub-regions-left-out",
            format!(
                "{} sub-region(s) narrower than the narrowest bead ({:.3} mm){} are not deposited: {}{}",
                thin.len(),
                widths.min,
                match o.thin {
                    Thin::Merge => ", even with their neighbours,",
                    Thin::Skip => "",
                },
                list.join(", "),
                if more > 0 {
                    format!(" and {more} more")
                } else {
                    String::new()
                }
            ),
        );
    }
    for (part, families) in &work.collapsed {
        plan.warn(
            StageKind::Plan,
            "gradient-collapsed",
            format!(
                "part `{part}`: the gradient collapsed to one mix in {families} graded solid area(s): \
                 its sub-regions are too narrow for beads of their own (the narrowest is {:.3} mm), so all are deposited as one; \
                 use fewer, wider sub-regions (fewer offsets or rings) or a smaller nozzle",
                widths.min
            ),
        );
    }
    if work.merged > 0 {
        plan.warn(StageKind::Plan, "thin-sub-regions-merged", format!(
            "{} sub-region(s) narrower than the narrowest bead ({:.3} mm) are deposited together with their neighbours, \
             with the area-weighted mean composition (`thin = \"skip\"` leaves them out)",
            work.merged, widths.min
        ));
    }
    if head_class(info) == HeadClass::DualGantry {
        within_gantry_reach(&tools, &work.jobs, info)?;
    }
    let rmax = tools.iter().map(|t| t.envelope).fold(0.0, f64::max);
    let vmax = tools.iter().map(ToolSpec::max_speed).fold(0.0, f64::max);
    let parks =
        Parks::new(&work.bbox, tools.len(), 2.0 * rmax + 2.0 * vmax * step + 1.0).within(&bed_reach(info));
    // Gantries sweep the layer front to back in bands of an envelope.
    let sweep = (head_class(info) == HeadClass::DualGantry).then_some(rmax);
    // Each tool's other orders: nearest-next from the corners of the work, farthest
    // from where the tool enters first.
    let others: Vec<Vec<Vec<Move>>> = if orders > 1 && sweep.is_none() && !work.bbox.is_empty() {
        tools
            .iter()
            .zip(&work.jobs)
            .map(|(t, jobs)| {
                let (b, entry) = (&work.bbox, parks.entry_of(t));
                let mut corners = [
                    b.min,
                    Point2::new(b.max.x, b.min.y),
                    b.max,
                    Point2::new(b.min.x, b.max.y),
                ];
                corners.sort_by(|p, q| (q - entry).norm().total_cmp(&(p - entry).norm()));
                corners
                    .into_iter()
                    .take(orders - 1)
                    .map(|from| route::route_from(t, jobs.clone(), &parks, o.seam, sweep, from))
                    .collect()
            })
            .collect()
    } else {
        Vec::new()
    };
    let routes = tools
        .iter()
        .zip(work.jobs)
        .map(|(t, jobs)| route(t, jobs, &parks, o.seam, sweep))
        .collect();
    let arena = if work.bbox.is_empty() || sweep.is_some() {
        work.bbox
    } else {
        BBox2 {
            min: Point2::new(f64::MIN, work.bbox.min.y - 1.0),
            max: Point2::new(f64::MAX, f64::MAX),
        }
    };
    Ok(Layer {
        tools,
        routes,
        others,
        arena,
    })
}

/// One tool after another in tool order, each out of its park and back, with a tool
/// change (a pause of the next tool at its park) between two tools.
fn sequential(layer: &Layer, tool_change: f64) -> (Vec<Toolpath>, f64) {
    let mut t = 0.0;
    let mut out = Vec::new();
    let mut first = true;
    for (tool, moves) in layer.tools.iter().zip(&layer.routes) {
        if moves.is_empty() {
            continue;
        }
        if !first && tool_change > 0.0 {
            out.push(pause(tool.index, moves[0].points[0], t, t + tool_change));
            t += tool_change;
        }
        first = false;
        let (paths, end) = timed(tool.index, moves, t);
        out.extend(paths);
        t = end;
    }
    (out, t)
}

/// Adds this planner's `paths` to the plan, each path of a single-material tool
/// naming the material the tool carries: tool `i` carries the run's material `i` (see
/// `Options::tools`); the mixing head lays the composition on its paths.
fn lay(o: &Options, plan: &mut LayerPlan, paths: Vec<Toolpath>) {
    let start = plan.toolpaths.len();
    plan.toolpaths.extend(paths);
    if !o.mixing {
        for p in &mut plan.toolpaths[start..] {
            p.material = Some(p.tool);
        }
    }
}

/// Records how much of the layer's sub-regions the toolpaths fill.
fn report_fill(o: &Options, plan: &mut LayerPlan) {
    let area: f64 = plan.parts.iter().flat_map(|p| &p.regions).map(|r| r.area()).sum();
    let deposited: f64 = plan.toolpaths.iter().map(Toolpath::bead_area).sum();
    plan.fill = Some(lamina_api::Fill {
        area,
        deposited,
        min_ratio: o.min_fill,
    });
}

struct Sequential(Options);
struct Concurrent(Options);

impl Planner for Sequential {
    fn plan(&self, info: &RunInfo, plan: &mut LayerPlan) -> Result<()> {
        let layer = prepare(&self.0, info, plan, self.0.step(), 1)?;
        let (paths, t) = sequential(&layer, self.0.tool_change);
        lay(&self.0, plan, paths);
        plan.build_time = Some(plan.build_time.unwrap_or(0.0) + t);
        report_fill(&self.0, plan);
        Ok(())
    }
}

impl Planner for Concurrent {
    fn plan(&self, info: &RunInfo, plan: &mut LayerPlan) -> Result<()> {
        let o = &self.0;
        // Other orders pay only where the heads work at once: a machine with one motion
        // system writes the tools one at a time whatever the schedule.
        let at_once = info.machine.as_ref().is_none_or(|m| m.motion_systems > 1);
        let layer = prepare(o, info, plan, o.step(), if at_once { o.orders } else { 1 })?;
        let (seq_paths, seq_time) = sequential(&layer, o.tool_change);
        let class = head_class(info);
        if class == HeadClass::SharedBeam && layer.routes.iter().filter(|r| !r.is_empty()).count() > 1 {
            // Two carriages on one beam share its Y: they cannot follow routes of their
            // own at once.
            plan.note(
                StageKind::Plan,
                "shared-beam-one-at-a-time",
                "the heads share one beam (kinematics `shared-beam`): deposited one tool at a time",
            );
            lay(o, plan, seq_paths);
            plan.build_time = Some(plan.build_time.unwrap_or(0.0) + seq_time);
            plan.sequential_time = Some(plan.sequential_time.unwrap_or(0.0) + seq_time);
            report_fill(o, plan);
            return Ok(());
        }
        // The concurrent schedule cannot take longer than every tool's route back to
        // back plus every hold; a budget of several sequential times catches a layer
        // whose tools keep giving way to each other.
        let budget = 4.0 * seq_time + 60.0;
        let settings = sim::Settings {
            step: o.step(),
            budget,
            max_side_steps: MAX_SIDE_STEPS,
            priority: o.priority,
            look_ahead: o.look_ahead,
            room: o.room,
            separation: if class == HeadClass::DualGantry {
                sim::Separation::OrderedY
            } else {
                sim::Separation::Discs
            },
        };
        let sync = sync_cost(o, info);
        let (run, chosen) = layer.fastest_orders(&settings, sync);
        if chosen != (0, 0) {
            plan.note(
                StageKind::Plan,
                "other-orders",
                format!(
                    "the tools take their loops in other orders than nearest-next from where they enter (orders {} and {} of the {} tried each): a faster concurrent schedule",
                    chosen.0 + 1,
                    chosen.1 + 1,
                    o.orders
                ),
            );
        }
        let (paths, t, pauses) = match run {
            // Tools that mostly wait for each other can end up slower than taking turns:
            // said, and the concurrent schedule kept unless asked for the faster one
            // (the sequential schedule is collision-free too).
            Ok(sim::Schedule {
                paths,
                end: t,
                pauses,
            }) if t + syncs(&pauses) * sync > seq_time => {
                let n = syncs(&pauses);
                let costed = if sync > 0.0 && n > 0.0 {
                    format!(
                        ", {:.2} s with its {n} synchronisation{} at {sync:.3} s each",
                        t + n * sync,
                        if n == 1.0 { "" } else { "s" }
                    )
                } else {
                    String::new()
                };
                let what = format!(
                    "the concurrent schedule ({t:.2} s{costed}) is slower than one tool at a time ({seq_time:.2} s)"
                );
                if o.keep_faster {
                    plan.note(
                        StageKind::Plan,
                        "concurrent-slower",
                        format!("{what}: this layer is deposited one tool at a time"),
                    );
                    (seq_paths, seq_time, None)
                } else {
                    plan.warn(
                        StageKind::Plan,
                        "concurrent-slower-kept",
                        format!("{what}; it is kept (`keep_faster = false`)"),
                    );
                    (paths, t, Some(pauses))
                }
            }
            Ok(s) => (s.paths, s.end, Some(s.pauses)),
            Err(e) => {
                plan.warn(
                    StageKind::Plan,
                    "concurrent-gave-up",
                    format!("concurrent planning gave up ({e}); this layer is deposited one tool at a time"),
                );
                (seq_paths, seq_time, None)
            }
        };
        plan.pauses = pauses;
        if o.compare {
            plan.note(
                StageKind::Plan,
                "build-times-compared",
                format!(
                    "build time {t:.2} s concurrent, {seq_time:.2} s sequential (ratio {:.3})",
                    if seq_time > 0.0 { t / seq_time } else { 1.0 }
                ),
            );
        }
        lay(o, plan, paths);
        plan.build_time = Some(plan.build_time.unwrap_or(0.0) + t);
        plan.sequential_time = Some(plan.sequential_time.unwrap_or(0.0) + seq_time);
        report_fill(o, plan);
        Ok(())
    }
}

fn build_sequential(config: &StageConfig<'_>) -> Result<AnyStage> {
    let o = Options::parse(config)?;
    o.check(config, false)?;
    Ok(AnyStage::Plan(Box::new(Sequential(o))))
}

fn build_concurrent(config: &StageConfig<'_>) -> Result<AnyStage> {
    let o = Options::parse(config)?;
    o.check(config, true)?;
    Ok(AnyStage::Plan(Box::new(Concurrent(o))))
}

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Plan,
        name: "sequential",
        doc: "Contour-parallel loops in every sub-region, deposited one tool after another (the baseline).",
        options: Options::SPECS.split_at(COMMON_OPTIONS).0,
        example: "use = \"sequential\"\nwidth = 0.5",
    },
    build: build_sequential,
});

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Plan,
        name: "contour",
        doc: "Toolpaths along the iso-material contours: closed contour-parallel loops filling every sub-region, deposited tool by tool (with `mixing = true`, by one mixing head). The fill of `sequential` and `concurrent`, under the name of the method.",
        options: Options::SPECS.split_at(COMMON_OPTIONS).0,
        example: "use = \"contour\"\nwidth = 0.4\nmixing = true\nseam = \"aligned\"",
    },
    build: build_sequential,
});

lamina_api::register_stage!(StageFactory {
    info: StageInfo {
        kind: StageKind::Plan,
        name: "concurrent",
        doc: "Contour-parallel loops deposited by all tools at once; on a predicted collision dynamic priority pauses one tool (by default the paper's rule: the tool slower along X pauses, the faster goes on). A layer goes one tool at a time where that is faster, synchronisations counted at what they cost the machine (`keep_faster = false` keeps every concurrent schedule).",
        options: Options::SPECS,
        example: "use = \"concurrent\"\nwidth = 0.5\nenvelope = 2.0\nstep = 0.02",
    },
    build: build_concurrent,
});
