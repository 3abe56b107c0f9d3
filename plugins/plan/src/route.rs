//! What each tool does in a layer, before any timing: its tool settings, its share of
//! the sub-regions, and its route (park, nearest-next contour loops with their seams,
//! back to park) as a list of moves at the tool's own speeds.

use lamina_api::{BBox2, Composition, LayerPlan, PathKind, Point2, RunInfo, SubRegion, TimedPoint, Toolpath};

use crate::assign::{Assign, Shares};
use crate::bead::Bead;
use crate::fill::Widths;
use crate::group::{Group, Thin, group};

lamina_api::option_type!(Seam = "string");

/// Where each loop starts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Seam {
    /// At the loop's vertex nearest to where the tool is: shortest travel.
    #[default]
    Nearest,
    /// At the loop's vertex of largest x: seams line up along one side of the part.
    Aligned,
}

/// One tool's settings for a layer.
#[derive(Debug, Clone, PartialEq)]
pub struct ToolSpec {
    pub index: usize,
    pub name: String,
    /// Deposition speed (mm/s).
    pub speed: f64,
    /// Travel speed (mm/s).
    pub travel_speed: f64,
    /// Envelope radius (mm): two tools collide when their centres come closer than the
    /// sum of their radii.
    pub envelope: f64,
    /// The rear head of two gantries: it parks and enters behind the work (+Y), and
    /// the other stays in front of it.
    pub rear: bool,
}

impl ToolSpec {
    pub fn max_speed(&self) -> f64 {
        self.speed.max(self.travel_speed)
    }
}

/// One continuous move of a route, untimed.
#[derive(Debug, Clone, PartialEq)]
pub struct Move {
    pub kind: PathKind,
    pub points: Vec<Point2>,
    pub speed: f64,
    pub width: f64,
    /// Width of each segment of a variable-width bead; empty when all are `width`.
    pub widths: Vec<f64>,
    pub composition: Option<Composition>,
    pub part: Option<usize>,
    pub sub_region: Option<usize>,
    /// The way back from a side-step: under the `clearing` and `returning` priorities
    /// it gives way to every tool it meets, returning once the way is free instead of
    /// pushing in by its speed along X.
    pub yields: bool,
}

impl Move {
    pub fn travel(points: Vec<Point2>, speed: f64) -> Self {
        Move {
            kind: PathKind::Travel,
            points,
            speed,
            width: 0.0,
            widths: Vec::new(),
            composition: None,
            part: None,
            sub_region: None,
            yields: false,
        }
    }

    pub fn length(&self) -> f64 {
        self.points.windows(2).map(|w| (w[1] - w[0]).norm()).sum()
    }

    pub fn duration(&self) -> f64 {
        self.length() / self.speed
    }

    /// The width of segment `i`.
    pub fn segment_width(&self, i: usize) -> f64 {
        self.widths.get(i).copied().unwrap_or(self.width)
    }
}

/// A bead to deposit, with what it deposits.
#[derive(Debug, Clone)]
pub struct Job {
    pub pass: Bead,
    pub composition: Option<Composition>,
    pub part: usize,
    pub sub_region: usize,
    /// Lower bound of the distance from a point to the loop, by its bounding box.
    pub bbox: BBox2,
}

/// The loops of every tool of a layer, and the sub-regions no pass fits in.
#[derive(Debug, Default)]
pub struct Work {
    /// `jobs[tool]`.
    pub jobs: Vec<Vec<Job>>,
    /// (part name, region index, area) of what is too thin for one pass.
    pub thin: Vec<(String, usize, f64)>,
    /// Sub-regions deposited together with their neighbours.
    pub merged: usize,
    /// (part name, families) whose graded sub-regions (three or more compositions)
    /// all went into one group: the gradient became one mix.
    pub collapsed: Vec<(String, usize)>,
    /// Bounding box of everything deposited in the layer.
    pub bbox: BBox2,
}

/// Cuts every sub-region of the layer into passes (merging slivers with their
/// neighbours, [`group`]) and hands each to its tool: everything to the mixing tool,
/// which lays each group's own composition, or each bead to one single-material tool
/// by the group's fractions ([`Shares`]), the bead then depositing that tool's
/// material alone.
pub fn distribute(
    info: &RunInfo,
    plan: &LayerPlan,
    tools: usize,
    widths: &Widths,
    mixing: bool,
    thin: Thin,
    assign: Assign,
) -> Work {
    let mut work = Work {
        jobs: vec![Vec::new(); tools],
        ..Work::default()
    };
    for part in &plan.parts {
        let grouping = group(&part.regions, widths, thin);
        work.merged += grouping.merged();
        let collapsed = collapsed_families(&part.regions, &grouping.groups);
        if collapsed > 0 {
            let name = info
                .parts
                .get(part.part)
                .map(|p| p.name.clone())
                .unwrap_or_default();
            work.collapsed.push((name, collapsed));
        }
        if !grouping.thin.is_empty() {
            let name = info
                .parts
                .get(part.part)
                .map(|p| p.name.clone())
                .unwrap_or_default();
            work.thin
                .extend(grouping.thin.iter().map(|&(r, a)| (name.clone(), r, a)));
        }
        let mut shares = Shares::new(info, part.part, tools, assign);
        for g in grouping.groups {
            let owners = if mixing {
                vec![0; g.passes.len()]
            } else {
                let areas: Vec<f64> = g.passes.iter().map(Bead::area).collect();
                shares.hand_out(g.composition.as_ref(), &areas)
            };
            for (pass, tool) in g.passes.into_iter().zip(owners) {
                let tool = tool.min(tools - 1);
                let composition = if mixing {
                    g.composition.clone()
                } else {
                    shares.deposited(tool).or_else(|| g.composition.clone())
                };
                let bbox = BBox2::from_points(pass.points.iter().copied());
                work.bbox = work.bbox.union(&bbox);
                work.jobs[tool].push(Job {
                    pass,
                    composition,
                    part: part.part,
                    sub_region: g.members[0],
                    bbox,
                });
            }
        }
    }
    work
}

/// How many families of `regions` were graded (three or more distinct compositions)
/// and had every sub-region filled in one group: their gradient is one mix.
fn collapsed_families(regions: &[SubRegion], groups: &[Group]) -> usize {
    // Each sub-region's group, found once: a family has collapsed when all its
    // sub-regions share one.
    let mut group_of = vec![None; regions.len()];
    for (g, group) in groups.iter().enumerate() {
        for &m in &group.members {
            if let Some(slot) = group_of.get_mut(m) {
                *slot = Some(g);
            }
        }
    }
    // Per family (in order): its one group so far (`None` once two differ or one is
    // missing), and its mixes, consecutive repeats counted once.
    let mut families: std::collections::BTreeMap<usize, (Option<usize>, Vec<&Composition>)> =
        std::collections::BTreeMap::new();
    for (r, region) in regions.iter().enumerate() {
        let (group, mixes) = families.entry(region.family).or_insert((group_of[r], Vec::new()));
        if *group != group_of[r] {
            *group = None;
        }
        if let Some(c) = region.composition.as_ref()
            && mixes.last() != Some(&c)
        {
            mixes.push(c);
        }
    }
    families
        .values()
        .filter(|(group, mixes)| group.is_some() && mixes.len() >= 3)
        .count()
}

/// Where tools wait: a row below the layer, at least `spacing` apart, and the row just
/// below the layer every tool passes through on its way in and out. Everything a tool
/// does in the layer stays above `entry_y`, at least `spacing` above every park, so a
/// parked tool is never in anyone's way. The parks spread over the layer's width, the
/// first tool's at its left end and the last one's at its right: each tool's
/// nearest-next route starts from its own side, and tools working the same loops go
/// round them apart instead of one behind the other.
#[derive(Debug, Clone, Copy)]
pub struct Parks {
    pub x0: f64,
    /// Between two neighbouring parks (mm): at least the spacing asked for.
    pub spacing: f64,
    pub park_y: f64,
    pub entry_y: f64,
    /// The row behind the layer where the rear head of two gantries enters, and its
    /// park behind that.
    pub rear_entry_y: f64,
    pub rear_park_y: f64,
}

impl Parks {
    pub fn new(bbox: &BBox2, tools: usize, spacing: f64) -> Self {
        let (min_x, max_x, min_y, max_y) = if bbox.is_empty() {
            (0.0, 0.0, 0.0, 0.0)
        } else {
            (bbox.min.x, bbox.max.x, bbox.min.y, bbox.max.y)
        };
        let entry_y = min_y - 1.0;
        let rear_entry_y = max_y + 1.0;
        let gaps = tools.saturating_sub(1) as f64;
        let (x0, step) = if gaps > 0.0 && (max_x - min_x) / gaps > spacing {
            (min_x, (max_x - min_x) / gaps)
        } else {
            ((min_x + max_x) / 2.0 - spacing * gaps / 2.0, spacing)
        };
        Parks {
            x0,
            spacing: step,
            park_y: entry_y - spacing,
            entry_y,
            rear_entry_y,
            rear_park_y: rear_entry_y + spacing,
        }
    }

    /// The parks moved onto `reach` (the bed, in the plan's coordinates) where they
    /// would lie beyond its edge: a plate that fills the bed leaves less room than the
    /// spacing in front of and behind the layer, and a head cannot be sent off the
    /// bed. The parks stay out of the layer (the entry rows are not moved).
    pub fn within(mut self, reach: &BBox2) -> Self {
        if reach.is_empty() {
            return self;
        }
        self.park_y = self.park_y.max(reach.min.y).min(self.entry_y);
        self.rear_park_y = self.rear_park_y.min(reach.max.y).max(self.rear_entry_y);
        self
    }

    /// Where `tool` parks: in the front row, or behind the layer for a gantry's rear head.
    pub fn park_of(&self, tool: &ToolSpec) -> Point2 {
        let p = self.park(tool.index);
        if tool.rear {
            Point2::new(p.x, self.rear_park_y)
        } else {
            p
        }
    }

    /// Where `tool` enters the layer, in front of its park.
    pub fn entry_of(&self, tool: &ToolSpec) -> Point2 {
        let p = self.entry(tool.index);
        if tool.rear {
            Point2::new(p.x, self.rear_entry_y)
        } else {
            p
        }
    }

    pub fn park(&self, tool: usize) -> Point2 {
        Point2::new(self.x0 + self.spacing * tool as f64, self.park_y)
    }

    pub fn entry(&self, tool: usize) -> Point2 {
        Point2::new(self.x0 + self.spacing * tool as f64, self.entry_y)
    }
}

/// The route of one tool: out of its park, each loop in nearest-next order starting at
/// its seam, and back. Empty when the tool has nothing to deposit.
///
/// With a `sweep` band (mm), the route works from front to back: the next loop is the
/// nearest of those starting within the band behind the frontmost one left. Heads on
/// two gantries keep their order in Y, so both sweep the same way, the rear head
/// leading and the front one following, instead of meeting where neither can pass.
pub fn route(tool: &ToolSpec, jobs: Vec<Job>, parks: &Parks, seam: Seam, sweep: Option<f64>) -> Vec<Move> {
    route_from(tool, jobs, parks, seam, sweep, parks.entry_of(tool))
}

/// [`route`] whose first loop is the one nearest `from` instead of the tool's entry:
/// the tool still comes out of its park and goes back to it.
pub fn route_from(
    tool: &ToolSpec,
    jobs: Vec<Job>,
    parks: &Parks,
    seam: Seam,
    sweep: Option<f64>,
    from: Point2,
) -> Vec<Move> {
    let mut moves = Vec::new();
    if jobs.is_empty() {
        return moves;
    }
    let park = parks.park_of(tool);
    let entry = parks.entry_of(tool);
    let mut at = from;
    let mut travel = vec![park, entry];
    let mut left: Vec<Option<Job>> = jobs.into_iter().map(Some).collect();
    let mut order: Vec<(f64, usize)> = Vec::with_capacity(left.len());
    for _ in 0..left.len() {
        // Nearest next loop: exact vertex distances, visited in order of the bounding
        // box lower bound and stopped once the bound exceeds the best found.
        order.clear();
        let reach = sweep.map_or(f64::INFINITY, |band| {
            left.iter()
                .flatten()
                .map(|j| j.bbox.min.y)
                .fold(f64::INFINITY, f64::min)
                + band
        });
        order.extend(
            left.iter()
                .enumerate()
                .filter_map(|(i, j)| j.as_ref().map(|j| (i, j)))
                .filter(|(_, j)| j.bbox.min.y <= reach)
                .map(|(i, j)| (box_distance(&j.bbox, at), i)),
        );
        order.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut best: Option<(usize, usize, f64)> = None;
        for &(bound, i) in &order {
            if best.is_some_and(|b| bound > b.2) {
                break;
            }
            if let Some(j) = &left[i] {
                let (v, d) = j.pass.nearest_start(at);
                if best.is_none_or(|b| d < b.2) {
                    best = Some((i, v, d));
                }
            }
        }
        let Some((i, v, _)) = best else { break };
        let Some(job) = left[i].take() else { break };
        let start = match seam {
            Seam::Nearest => v,
            Seam::Aligned => job.pass.max_x_vertex(),
        };
        let pass = job.pass.started_at(start);
        let uniform = pass.uniform_width();
        let first = pass.points[0];
        travel.push(first);
        push_travel(&mut moves, std::mem::take(&mut travel), tool.travel_speed);
        at = pass.points[pass.points.len() - 1];
        moves.push(Move {
            kind: PathKind::Extrude,
            width: uniform.unwrap_or(0.0),
            widths: if uniform.is_some() {
                Vec::new()
            } else {
                pass.widths
            },
            points: pass.points,
            speed: tool.speed,
            composition: job.composition,
            part: Some(job.part),
            sub_region: Some(job.sub_region),
            yields: false,
        });
        travel.push(at);
    }
    travel.push(entry);
    travel.push(park);
    push_travel(&mut moves, travel, tool.travel_speed);
    moves
}

fn push_travel(moves: &mut Vec<Move>, mut points: Vec<Point2>, speed: f64) {
    points.dedup_by(|a, b| (*a - *b).norm() < 1e-12);
    if points.len() >= 2 {
        moves.push(Move::travel(points, speed));
    }
}

fn box_distance(b: &BBox2, p: Point2) -> f64 {
    let dx = (b.min.x - p.x).max(p.x - b.max.x).max(0.0);
    let dy = (b.min.y - p.y).max(p.y - b.max.y).max(0.0);
    // Millimetres on a bed: no overflow for `hypot` to guard against, at a fifth of its cost.
    (dx * dx + dy * dy).sqrt()
}

/// The route timed on its own, from `t0`: toolpaths and the time it ends.
pub fn timed(tool: usize, moves: &[Move], t0: f64) -> (Vec<Toolpath>, f64) {
    let mut t = t0;
    let mut out = Vec::with_capacity(moves.len());
    for m in moves {
        let mut points = Vec::with_capacity(m.points.len());
        let mut prev: Option<Point2> = None;
        for &p in &m.points {
            if let Some(q) = prev {
                t += (p - q).norm() / m.speed;
            }
            points.push(TimedPoint { p, t });
            prev = Some(p);
        }
        out.push(toolpath(tool, m, points));
    }
    (out, t)
}

/// A toolpath with a move's kind and what it deposits.
pub fn toolpath(tool: usize, m: &Move, points: Vec<TimedPoint>) -> Toolpath {
    Toolpath {
        tool,
        material: None,
        kind: m.kind,
        widths: if m.widths.is_empty() {
            Vec::new()
        } else {
            m.widths[..points.len().saturating_sub(1).min(m.widths.len())].to_vec()
        },
        points,
        width: m.width,
        composition: m.composition.clone(),
        part: m.part,
        sub_region: m.sub_region,
    }
}

/// A pause of `tool` at `p` from `t0` to `t1`.
pub fn pause(tool: usize, p: Point2, t0: f64, t1: f64) -> Toolpath {
    Toolpath {
        tool,
        material: None,
        kind: PathKind::Pause,
        points: vec![TimedPoint { p, t: t0 }, TimedPoint { p, t: t1 }],
        width: 0.0,
        widths: Vec::new(),
        composition: None,
        part: None,
        sub_region: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_family_whose_graded_sub_regions_all_share_one_group_has_collapsed() {
        let region = |family: usize, f: f64| SubRegion {
            family,
            index: 0,
            count: 1,
            level: f,
            polygon: lamina_api::Polygon::default(),
            cell: None,
            reference: Point2::origin(),
            composition: Some(Composition::binary(f).expect("valid")),
            samples: Vec::new(),
        };
        let group = |members: Vec<usize>| Group {
            members,
            passes: Vec::new(),
            composition: None,
        };
        // Family 0 graded over three mixes, family 1 over two.
        let regions = [0.0, 0.5, 1.0]
            .map(|f| region(0, f))
            .into_iter()
            .chain([region(1, 0.0), region(1, 1.0)]);
        let regions: Vec<SubRegion> = regions.collect();
        assert_eq!(
            collapsed_families(&regions, &[group(vec![0, 1, 2]), group(vec![3, 4])]),
            1
        );
        assert_eq!(
            collapsed_families(&regions, &[group(vec![0, 1]), group(vec![2]), group(vec![3, 4])]),
            0
        );
        // Three sub-regions of one mix are no gradient.
        let flat: Vec<SubRegion> = (0..3).map(|_| region(0, 0.5)).collect();
        assert_eq!(collapsed_families(&flat, &[group(vec![0, 1, 2])]), 0);
    }

    fn bbox(x0: f64, x1: f64) -> BBox2 {
        BBox2::from_points([Point2::new(x0, 10.0), Point2::new(x1, 30.0)])
    }

    #[test]
    fn parks_spread_over_the_layers_width_and_keep_their_spacing() {
        // A 60 mm wide layer, two tools 12 mm apart at least: one park at each end.
        let p = Parks::new(&bbox(-30.0, 30.0), 2, 12.0);
        assert_eq!(p.park(0).x, -30.0);
        assert_eq!(p.park(1).x, 30.0);
        // Three tools: the middle one halfway.
        let p = Parks::new(&bbox(-30.0, 30.0), 3, 12.0);
        assert_eq!(p.park(1).x, 0.0);
        // Below the layer, a spacing under the row every tool enters by.
        assert_eq!(p.entry_y, 9.0);
        assert_eq!(p.park_y, 9.0 - 12.0);
        // A layer narrower than the spacing: the parks keep their spacing about its
        // centre.
        let p = Parks::new(&bbox(0.0, 4.0), 2, 12.0);
        assert_eq!(p.park(0).x, -4.0);
        assert_eq!(p.park(1).x, 8.0);
    }

    #[test]
    fn parks_stay_on_the_bed_and_out_of_the_layer() {
        // A layer from y 10 to 30 on a bed from y 0 to 35: 12 mm in front of the entry
        // row would be off the bed, and so would 12 mm behind the rear entry row.
        let p = Parks::new(&bbox(-30.0, 30.0), 2, 12.0).within(&BBox2::from_points([
            Point2::new(-100.0, 0.0),
            Point2::new(100.0, 35.0),
        ]));
        assert_eq!((p.park_y, p.entry_y), (0.0, 9.0));
        assert_eq!((p.rear_entry_y, p.rear_park_y), (31.0, 35.0));
        // A bed with room leaves them where they were.
        let q = Parks::new(&bbox(-30.0, 30.0), 2, 12.0);
        let r = q.within(&BBox2::from_points([
            Point2::new(-100.0, -100.0),
            Point2::new(100.0, 100.0),
        ]));
        assert_eq!((r.park_y, r.rear_park_y), (q.park_y, q.rear_park_y));
    }
}
