//! An independent check of the concurrent planner: the timed paths it outputs are
//! re-simulated exactly (between any two breakpoints of two tools both move in straight
//! lines at constant speed, so their closest approach has a closed form) and no two
//! envelopes may ever overlap. Layouts of 2 to 4 tools are drawn at random (a small
//! deterministic generator, so failures repeat).

use std::path::PathBuf;

use fastrand::Rng;
use lamina_core::stage::Planner;
use lamina_core::{
    BBox2, Composition, Contour, ContourTree, LayerPlan, Material, PartInfo, PartLayer, PathKind, Point2,
    Polygon, Registry, RunInfo, SubRegion, Toolpath,
};
use lamina_plan::route::{Move, ToolSpec};
use lamina_plan::sim::{self, Priority, Settings};

fn build(table: &str) -> lamina_core::Result<Box<dyn Planner>> {
    use lamina_plan as _;
    let registry = Registry::linked().expect("registry");
    let dir = std::env::temp_dir();
    let scripts = lamina_core::script::local(&dir, Default::default());
    let table = lamina_core::pipeline::TableRef::parse_snippet("plan", table).expect("table");
    registry.build::<dyn Planner>(&table, &scripts, &dir)
}

fn planner(table: &str) -> Box<dyn Planner> {
    build(table).expect("builds")
}

fn disc(c: Point2, r: f64, n: usize) -> Contour {
    Contour::new(
        (0..n)
            .map(|i| {
                let a = std::f64::consts::TAU * i as f64 / n as f64;
                Point2::new(c.x + r * a.cos(), c.y + r * a.sin())
            })
            .collect(),
    )
}

fn rect(x0: f64, y0: f64, w: f64, h: f64) -> Contour {
    Contour::new(vec![
        Point2::new(x0, y0),
        Point2::new(x0 + w, y0),
        Point2::new(x0 + w, y0 + h),
        Point2::new(x0, y0 + h),
    ])
}

/// A number uniform in [a, b).
fn range(rng: &mut Rng, a: f64, b: f64) -> f64 {
    a + (b - a) * rng.f64()
}

/// `tools` materials, one part each, with 1 to 3 random shapes per part in a 60 mm
/// square (shapes of different parts may sit side by side or close together).
fn layout(rng: &mut Rng, tools: usize) -> (RunInfo, LayerPlan) {
    let materials = (0..tools)
        .map(|i| Material {
            name: format!("m{i}"),
            colour: [0, 0, 0],
            layer_thickness: None,
        })
        .collect();
    let parts: Vec<PartInfo> = (0..tools)
        .map(|i| PartInfo {
            name: format!("p{i}"),
            materials: vec![i],
            mesh: i,
            z_min: 0.0,
            z_max: 1.0,
            z_gradient: None,
        })
        .collect();
    let mut layers = Vec::new();
    for part in 0..tools {
        let mut regions = Vec::new();
        for index in 0..1 + (rng.f64() * 3.0) as usize {
            let c = Point2::new(range(rng, 0.0, 60.0), range(rng, 0.0, 60.0));
            let outer = if rng.f64() < 0.5 {
                disc(c, range(rng, 1.0, 8.0), 48)
            } else {
                rect(c.x, c.y, range(rng, 1.0, 15.0), range(rng, 0.5, 12.0))
            };
            // Each region an island of its own (random shapes may overlap, which
            // sub-regions of one family never do).
            regions.push(SubRegion {
                family: index,
                index: 0,
                count: 1,
                level: 0.0,
                polygon: Polygon::new(outer, Vec::new()),
                cell: None,
                reference: c,
                composition: Some(Composition::pure(0, 1)),
                samples: Vec::new(),
            });
        }
        layers.push(PartLayer {
            part,
            contours: Vec::new(),
            tree: ContourTree::default(),
            families: Vec::new(),
            regions,
        });
    }
    let info = RunInfo {
        base_dir: PathBuf::from("."),
        materials,
        parts,
        z_min: 0.0,
        z_max: 1.0,
        xy_bounds: lamina_core::BBox2::EMPTY,
        machine: None,
        model_frame: None,
    };
    let plan = LayerPlan {
        index: 0,
        z: 0.2,
        thickness: 0.2,
        material_region: None,
        parts: layers,
        toolpaths: Vec::new(),
        build_time: None,
        sequential_time: None,
        fill: None,
        pauses: None,
        operations: Vec::new(),
        diagnostics: Vec::new(),
    };
    (info, plan)
}

/// One tool's motion: (t, position) breakpoints in time order, checked continuous.
fn timeline(paths: &[Toolpath], tool: usize) -> Vec<(f64, Point2)> {
    let mut mine: Vec<&Toolpath> = paths.iter().filter(|p| p.tool == tool).collect();
    mine.sort_by(|a, b| a.points[0].t.total_cmp(&b.points[0].t));
    let mut out: Vec<(f64, Point2)> = Vec::new();
    for p in mine {
        for q in &p.points {
            if let Some(&(t, at)) = out.last() {
                assert!(q.t >= t - 1e-9, "tool {tool}: time goes back at {t}");
                // A tool never jumps: consecutive points are reachable.
                if q.t - t < 1e-9 {
                    assert!((q.p - at).norm() < 1e-6, "tool {tool} jumps at t = {t}");
                }
            }
            out.push((q.t, q.p));
        }
    }
    out
}

fn position(line: &[(f64, Point2)], t: f64) -> Point2 {
    match line.iter().position(|&(s, _)| s > t) {
        None => line[line.len() - 1].1,
        Some(0) => line[0].1,
        Some(i) => {
            let (t0, p0) = line[i - 1];
            let (t1, p1) = line[i];
            if t1 - t0 <= 0.0 {
                p1
            } else {
                p0 + (p1 - p0) * ((t - t0) / (t1 - t0))
            }
        }
    }
}

/// The smallest distance between two tools over the whole layer, exactly.
fn closest(a: &[(f64, Point2)], b: &[(f64, Point2)]) -> (f64, f64) {
    let mut times: Vec<f64> = a.iter().chain(b).map(|&(t, _)| t).collect();
    times.sort_by(f64::total_cmp);
    times.dedup();
    let mut best = (f64::INFINITY, 0.0);
    for w in times.windows(2) {
        let (t0, t1) = (w[0], w[1]);
        let d0 = position(a, t0) - position(b, t0);
        let d1 = position(a, t1) - position(b, t1);
        // Relative position moves linearly from d0 to d1.
        let v = d1 - d0;
        let s = if v.norm_squared() > 0.0 {
            (-d0.dot(&v) / v.norm_squared()).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let d = (d0 + v * s).norm();
        if d < best.0 {
            best = (d, t0 + (t1 - t0) * s);
        }
    }
    best
}

/// The area the extrusions cover (their widths lined up with their segments).
fn extruded(paths: &[Toolpath]) -> f64 {
    paths
        .iter()
        .filter(|p| p.kind == PathKind::Extrude)
        .inspect(|p| assert!(p.widths.is_empty() || p.widths.len() + 1 == p.points.len()))
        .map(Toolpath::bead_area)
        .sum()
}

/// A tool's velocity along X (its absolute X component, mm/s) on the first stretch of
/// its timeline that starts at or after `t` and takes time.
fn speed_along_x_from(line: &[(f64, Point2)], t: f64) -> f64 {
    line.windows(2)
        .find(|w| w[0].0 >= t - 1e-9 && w[1].0 - w[0].0 > 1e-9)
        .map_or(0.0, |w| (w[1].1.x - w[0].1.x).abs() / (w[1].0 - w[0].0))
}

/// A tool's velocity along X on the stretch of its timeline that ends at `t`, if any.
fn speed_along_x_before(line: &[(f64, Point2)], t: f64) -> Option<f64> {
    line.windows(2)
        .filter(|w| (w[1].0 - t).abs() <= 1e-9 && w[1].0 - w[0].0 > 1e-9)
        .map(|w| (w[1].1.x - w[0].1.x).abs() / (w[1].0 - w[0].0))
        .next()
}

/// A tool's velocity along X on the stretch of its timeline under way at `t` (zero
/// once it is done).
fn speed_along_x_at(line: &[(f64, Point2)], t: f64) -> f64 {
    line.windows(2)
        .find(|w| w[0].0 <= t + 1e-9 && w[1].0 - w[0].0 > 1e-9 && w[1].0 > t + 1e-9)
        .map_or(0.0, |w| (w[1].1.x - w[0].1.x).abs() / (w[1].0 - w[0].0))
}

/// One pause of a tool: when it starts and ends, and where.
#[derive(Debug, Clone, Copy)]
struct Hold {
    tool: usize,
    from: f64,
    to: f64,
    at: Point2,
}

fn holds(paths: &[Toolpath]) -> Vec<Hold> {
    let mut out: Vec<Hold> = paths
        .iter()
        .filter(|p| p.kind == PathKind::Pause)
        .map(|p| Hold {
            tool: p.tool,
            from: p.points[0].t,
            to: p.points[p.points.len() - 1].t,
            at: p.points[0].p,
        })
        .collect();
    out.sort_by(|a, b| a.from.total_cmp(&b.from));
    out
}

/// The intervals in which `tool` does not follow its route: its pauses, and its
/// side-steps (a travel out and the travel straight back to where it left).
fn off_route(paths: &[Toolpath], tool: usize) -> Vec<(f64, f64)> {
    let mut mine: Vec<&Toolpath> = paths.iter().filter(|p| p.tool == tool).collect();
    mine.sort_by(|a, b| a.points[0].t.total_cmp(&b.points[0].t));
    let ends = |p: &Toolpath| (p.points[0], p.points[p.points.len() - 1]);
    let mut out = Vec::new();
    for (k, p) in mine.iter().enumerate() {
        if p.kind == PathKind::Pause {
            out.push((ends(p).0.t, ends(p).1.t));
        } else if let Some(back) = mine.get(k + 1)
            && p.kind == PathKind::Travel
            && back.kind == PathKind::Travel
            && (ends(back).1.p - ends(p).0.p).norm() < 1e-9
        {
            out.push((ends(p).0.t, ends(back).1.t));
        }
    }
    out
}

/// The seconds a tool has followed its route at time `t`: `t` less the time it spent
/// off it before ([`off_route`]).
fn route_time(off: &[(f64, f64)], t: f64) -> f64 {
    t - off
        .iter()
        .map(|&(from, to)| (t.min(to) - from).max(0.0))
        .sum::<f64>()
}

/// Checks the paper's rule on a two-tool schedule: whenever one tool starts a pause
/// while the other goes on (an encounter decided by priority, not a tool held behind
/// a held one or both held for a side-step), the one going on was at least as fast
/// along X as the paused one was about to move, unless pausing the other instead would
/// not have kept the two apart: the paused tool, going on along its route (as it does
/// after the pause) for `horizon` seconds, comes within `e` of the other held where it
/// was. Returns the encounters decided by speed and those forced.
fn check_priority_by_speed_along_x(paths: &[Toolpath], step: f64, horizon: f64, e: f64) -> (usize, usize) {
    let lines = [timeline(paths, 0), timeline(paths, 1)];
    let off = [off_route(paths, 0), off_route(paths, 1)];
    let routes = [0, 1].map(|tool| {
        lines[tool]
            .iter()
            .map(|&(t, p)| (route_time(&off[tool], t), p))
            .collect::<Vec<_>>()
    });
    let (mut decided, mut forced) = (0, 0);
    for h in holds(paths) {
        let other = 1 - h.tool;
        let line = &lines[other];
        if line.is_empty() {
            continue;
        }
        // The other tool moves over the step where this one starts to wait.
        let moved = (position(line, h.from + step) - position(line, h.from)).norm();
        if moved < 1e-9 {
            continue;
        }
        // A travel is routed afresh from where the tool waited, so that what it does
        // after the pause is not what it would have done: only pauses on a bead, which
        // the tool takes up where it left it, are checked.
        let on_bead = paths
            .iter()
            .any(|p| p.tool == h.tool && p.kind == PathKind::Extrude && (p.points[0].t - h.to).abs() <= 1e-9);
        if !on_bead {
            continue;
        }
        // Would holding the other have cleared the way? Its position then against this
        // tool's motion after the pause, sampled finely (a little slack for the
        // samples missing the closest approach between them).
        // The route is followed for `horizon` seconds of motion: later pauses and
        // side-steps of this tool are left out, as the planner's look along the route
        // leaves them out.
        let held = position(line, h.from);
        let route = &routes[h.tool];
        let start = route_time(&off[h.tool], h.to);
        let samples = (horizon / 1e-3).ceil() as usize;
        let near = (0..=samples).any(|k| {
            let t = start + horizon * k as f64 / samples as f64;
            (position(route, t) - held).norm() < e + 0.05
        });
        if near {
            forced += 1;
            continue;
        }
        // The paused tool's speed along X is that of the stretch it was on when held
        // (after the pause it may step aside instead of going on), or at the start of
        // the layer the stretch it starts with.
        let mine = speed_along_x_before(&lines[h.tool], h.from)
            .unwrap_or_else(|| speed_along_x_from(&lines[h.tool], h.to));
        let theirs = speed_along_x_at(line, h.from);
        assert!(
            mine <= theirs + 1e-6 * theirs.max(1.0),
            "tool {} paused at t = {:.3} s at {:?} for tool {other}, which is slower along X ({theirs:.3} mm/s against {mine:.3} mm/s), though pausing that one would have cleared the way",
            h.tool,
            h.from,
            h.at
        );
        decided += 1;
    }
    (decided, forced)
}

/// The seconds a tool of a plan spends moving (its paths other than pauses).
fn busy_time(plan: &LayerPlan, tool: usize) -> f64 {
    plan.toolpaths
        .iter()
        .filter(|p| p.tool == tool && p.kind != PathKind::Pause)
        .map(|p| p.points[p.points.len() - 1].t - p.points[0].t)
        .sum()
}

fn says_slower(plan: &LayerPlan) -> bool {
    plan.diagnostics
        .iter()
        .any(|d| d.message.contains("is slower than one tool at a time"))
}

/// Two tools trying more orders of their loops: the same beads, never a slower
/// layer (without a machine a synchronisation costs nothing, so the schedule kept is
/// the quickest of those tried, the first order's among them), and on some layouts a
/// faster one, said in a note.
#[test]
fn more_orders_of_the_loops_never_make_a_layer_slower() {
    let mut rng = Rng::with_seed(0x0dde_5eed_0000_0002);
    let (mut faster, mut noted) = (0, 0);
    for case in 0..30 {
        let (info, plan) = layout(&mut rng, 2);
        let table = format!(
            "use = \"concurrent\"\nwidth = 0.5\nenvelope = {}\nstep = 0.02\nspeed = {}\n",
            range(&mut rng, 1.5, 6.0),
            range(&mut rng, 10.0, 40.0)
        );
        let planned = |orders: usize| {
            let mut p = plan.clone();
            planner(&format!("{table}orders = {orders}\n"))
                .plan(&info, &mut p)
                .expect("plans");
            p
        };
        let first = planned(1);
        assert!(!first.diagnostics.iter().any(|d| d.code == "other-orders"));
        let (t1, a1) = (first.build_time.unwrap_or(0.0), extruded(&first.toolpaths));
        let mut best = t1;
        for orders in [2, 3, 5] {
            let p = planned(orders);
            let t = p.build_time.unwrap_or(0.0);
            assert!(
                t <= best + 1e-9,
                "case {case}: {orders} orders take {t} s, fewer {best} s"
            );
            let a = extruded(&p.toolpaths);
            assert!(
                (a - a1).abs() <= 1e-6 * a1.max(1.0),
                "case {case}: {a} against {a1}"
            );
            let said = p.diagnostics.iter().any(|d| d.code == "other-orders");
            assert_eq!(
                said,
                t < t1,
                "case {case}: {t} s against {t1} s, {:?}",
                p.diagnostics
            );
            noted += usize::from(said);
            best = t;
        }
        faster += usize::from(best < t1);
    }
    assert!(
        faster >= 3,
        "only {faster} of 30 layouts are faster in other orders"
    );
    assert!(noted >= faster);
}

/// Random layouts planned checking the next step only (`look_ahead = 0`, the
/// paper's check: every two-tool encounter is then decided by speed along X) and
/// with the default look-ahead.
#[test]
fn random_layouts_of_two_to_four_tools_never_collide() {
    random_layouts(Some(0.0));
    random_layouts(None);
}

fn random_layouts(look_ahead: Option<f64>) {
    let mut rng = Rng::with_seed(0x5eed_1234_abcd_0001);
    let (mut pauses, mut faster, mut slower, mut decided) = (0, 0, 0, 0);
    for case in 0..40 {
        let tools = 2 + case % 3;
        let envelope = range(&mut rng, 1.5, 6.0);
        let table = format!(
            "use = \"concurrent\"\nwidth = 0.5\nenvelope = {envelope}\nstep = 0.02\nspeed = {}\ntravel_speed = 100.0\n{}\
             [tools.m0]\nspeed = {}",
            range(&mut rng, 10.0, 40.0),
            look_ahead.map_or(String::new(), |s| format!("look_ahead = {s}\n")),
            range(&mut rng, 10.0, 40.0)
        );
        let (info, plan) = layout(&mut rng, tools);
        let mut conc = plan.clone();
        planner(&table).plan(&info, &mut conc).expect("plans");
        let mut seq = plan.clone();
        let seq_table = table.replace("\"concurrent\"", "\"sequential\"");
        planner(&seq_table).plan(&info, &mut seq).expect("plans");

        let lines: Vec<Vec<(f64, Point2)>> = (0..tools).map(|t| timeline(&conc.toolpaths, t)).collect();
        for i in 0..tools {
            for j in i + 1..tools {
                if lines[i].is_empty() || lines[j].is_empty() {
                    continue;
                }
                let (d, t) = closest(&lines[i], &lines[j]);
                assert!(
                    d >= 2.0 * envelope - 1e-6,
                    "case {case}: tools {i} and {j} come {d:.4} mm apart at t = {t:.3} s (envelopes {envelope:.3})"
                );
            }
        }
        // The same beads are deposited either way.
        let (a, b) = (extruded(&conc.toolpaths), extruded(&seq.toolpaths));
        assert!((a - b).abs() <= 1e-6 * b.max(1.0), "case {case}: {a} vs {b}");
        let (tc, ts) = (conc.build_time.unwrap_or(0.0), seq.build_time.unwrap_or(0.0));
        // No tool finishes before its own work is done.
        for tool in 0..tools {
            let own = busy_time(&seq, tool);
            assert!(
                tc >= own - 1e-6,
                "case {case}: {tc} s for tool {tool}'s {own} s of work"
            );
        }
        if !conc.diagnostics.iter().any(|d| d.message.contains("gave up")) {
            // The concurrent schedule is what is planned, faster or not; a slower one
            // is said.
            assert_eq!(
                says_slower(&conc),
                tc > ts,
                "case {case}: {tc} s against {ts} s, {:?}",
                conc.diagnostics
            );
            if tc < ts {
                faster += 1;
            }
            // A tool may pause because only its pausing keeps the two apart, whatever
            // the speeds: the rule decides the free choices.
            if tools == 2 {
                let horizon = look_ahead.unwrap_or(0.5).max(0.02);
                decided += check_priority_by_speed_along_x(&conc.toolpaths, 0.02, horizon, 2.0 * envelope).0;
            }
        }
        // Asked for, the faster of the two is kept.
        let mut keep = plan.clone();
        planner(&table.replace("[tools.m0]", "keep_faster = true\n[tools.m0]"))
            .plan(&info, &mut keep)
            .expect("plans");
        let tk = keep.build_time.unwrap_or(0.0);
        assert!(
            (tk - tc.min(ts)).abs() <= 1e-9,
            "case {case}: kept {tk} s of {tc} s and {ts} s"
        );
        if tc > ts {
            slower += 1;
            assert_eq!(keep.toolpaths, seq.toolpaths, "case {case}");
            assert!(says_slower(&keep), "case {case}");
        }
        pauses += conc
            .toolpaths
            .iter()
            .filter(|p| p.kind == PathKind::Pause)
            .count();
    }
    // Crowded layouts of 3 or 4 tools with large envelopes often deadlock and fall back
    // to taking turns (collision-free too); two tools rarely do.
    assert!(
        faster >= 15,
        "concurrent was faster in only {faster} of 40 layouts"
    );
    assert!(pauses > 0, "no layout made a tool give way");
    assert!(decided > 0, "no two-tool encounter was decided by priority");
    println!(
        "look-ahead {look_ahead:?}: {faster} of 40 layouts faster concurrently, {slower} slower; {decided} two-tool encounters by speed along X"
    );
}

#[test]
fn tools_crossing_head_on_give_way_by_speed_along_x() {
    // Two bars side by side with a narrow gap: the tools must pass each other.
    let mut rng = Rng::with_seed(9);
    let (info, mut plan) = layout(&mut rng, 2);
    plan.parts[0].regions.truncate(1);
    plan.parts[1].regions.truncate(1);
    plan.parts[0].regions[0].polygon = Polygon::new(rect(0.0, 0.0, 40.0, 2.0), vec![]);
    plan.parts[1].regions[0].polygon = Polygon::new(rect(0.0, 3.0, 40.0, 2.0), vec![]);
    planner("use = \"concurrent\"\nenvelope = 2.0\nstep = 0.01\nlook_ahead = 0.0\n[tools.m1]\nspeed = 10.0")
        .plan(&info, &mut plan)
        .expect("plans");
    let a = timeline(&plan.toolpaths, 0);
    let b = timeline(&plan.toolpaths, 1);
    assert!(closest(&a, &b).0 >= 4.0 - 1e-6);
    assert!(plan.toolpaths.iter().any(|p| p.kind == PathKind::Pause));
    // Every pause while the other tool goes on is the slower tool's along X (tool 1
    // deposits at 10 mm/s, tool 0 at 30 mm/s).
    let (decided, forced) = check_priority_by_speed_along_x(&plan.toolpaths, 0.01, 0.01, 4.0);
    assert!(decided + forced > 0, "no pause was decided");
    // Split extrusions keep their beads' widths: loops of 2 mm / 5 = 0.4 mm... bent
    // to the bars' mean width, centre beads narrower.
    for p in plan.toolpaths.iter().filter(|p| p.kind == PathKind::Extrude) {
        assert!(p.points.len() >= 2);
        assert!(p.widths.is_empty() || p.widths.len() + 1 == p.points.len());
        for i in 0..p.points.len() - 1 {
            let w = p.segment_width(i);
            assert!(w > 0.0 && w <= 1.2, "{w}");
        }
    }
    let fill = plan.fill.expect("fill reported");
    assert!((fill.deposited - fill.area).abs() <= 0.02 * fill.area, "{fill:?}");
}

#[test]
fn thin_regions_are_reported() {
    let mut rng = Rng::with_seed(3);
    let (info, mut plan) = layout(&mut rng, 2);
    // 0.15 mm wide: under the narrowest bead (0.6 x 0.4 mm), and alone in its part.
    plan.parts[0].regions.truncate(1);
    plan.parts[0].regions[0].polygon = Polygon::new(rect(0.0, 0.0, 10.0, 0.15), vec![]);
    planner("use = \"sequential\"")
        .plan(&info, &mut plan)
        .expect("plans");
    assert!(
        plan.diagnostics
            .iter()
            .any(|d| d.message.contains("narrower than the narrowest bead")
                && d.message.contains("even with their neighbours")),
        "{:?}",
        plan.diagnostics
    );
}

#[test]
fn sequential_time_is_path_length_over_speed_plus_tool_changes() {
    let mut rng = Rng::with_seed(5);
    let (info, mut plan) = layout(&mut rng, 2);
    planner("use = \"sequential\"\nspeed = 20.0\ntravel_speed = 100.0\ntool_change = 7.0")
        .plan(&info, &mut plan)
        .expect("plans");
    let mut expected = 7.0;
    for p in &plan.toolpaths {
        match p.kind {
            PathKind::Extrude => expected += p.length() / 20.0,
            PathKind::Travel => expected += p.length() / 100.0,
            PathKind::Pause => {}
        }
    }
    let t = plan.build_time.expect("timed");
    assert!((t - expected).abs() < 1e-6, "{t} vs {expected}");
    // The beads fill the sub-regions: loops, and centre beads where loops leave off.
    let fill = plan.fill.expect("fill reported");
    assert!((fill.deposited - fill.area).abs() <= 0.02 * fill.area, "{fill:?}");
    assert!(plan.toolpaths.iter().any(
        |p| p.kind == PathKind::Extrude && (p.points[0].p - p.points[p.points.len() - 1].p).norm() < 1e-9
    ));
}

/// Area each tool's beads cover, after checking every extrusion's widths line up with
/// its segments.
fn bead_area_by_tool(plan: &LayerPlan, tools: usize) -> Vec<f64> {
    let mut area = vec![0.0; tools];
    for p in plan.toolpaths.iter().filter(|p| p.kind == PathKind::Extrude) {
        assert!(
            p.widths.is_empty() || p.widths.len() + 1 == p.points.len(),
            "{} widths for {} points",
            p.widths.len(),
            p.points.len()
        );
        area[p.tool] += p.bead_area();
    }
    area
}

#[test]
fn concurrent_plans_report_the_sequential_baseline() {
    for seed in 1..6 {
        let mut rng = Rng::with_seed(seed);
        let (info, plan) = layout(&mut rng, 3);
        let mut conc = plan.clone();
        planner("use = \"concurrent\"\nenvelope = 2.0")
            .plan(&info, &mut conc)
            .expect("plans");
        let mut seq = plan;
        planner("use = \"sequential\"\nenvelope = 2.0")
            .plan(&info, &mut seq)
            .expect("plans");
        let (t, s) = (conc.build_time.expect("timed"), seq.build_time.expect("timed"));
        assert_eq!(conc.sequential_time, Some(s), "seed {seed}");
        // Holds and side-steps split beads but deposit every one of them whole.
        let (a, b) = (bead_area_by_tool(&conc, 3), bead_area_by_tool(&seq, 3));
        for (x, y) in a.iter().zip(&b) {
            assert!((x - y).abs() <= 1e-9 * y.max(1.0), "seed {seed}: {a:?} vs {b:?}");
        }
        assert!(seq.sequential_time.is_none());
        let mut contour = conc.clone();
        contour.toolpaths.clear();
        contour.build_time = None;
        planner("use = \"contour\"\nenvelope = 2.0")
            .plan(&info, &mut contour)
            .expect("plans");
        assert_eq!(
            contour.toolpaths, seq.toolpaths,
            "`contour` is the sequential fill"
        );
        // Slower or not, the concurrent schedule is planned; slower, it is said.
        assert_eq!(
            says_slower(&conc),
            t > s,
            "seed {seed}: concurrent {t} s, sequential {s} s"
        );
    }
}

fn tool(index: usize, speed: f64, envelope: f64) -> ToolSpec {
    ToolSpec {
        index,
        name: format!("m{index}"),
        speed,
        travel_speed: speed,
        envelope,
        rear: false,
    }
}

/// A straight bead from `a` to `b`.
fn bead(a: Point2, b: Point2, speed: f64) -> Move {
    Move {
        kind: PathKind::Extrude,
        width: 0.5,
        ..Move::travel(vec![a, b], speed)
    }
}

const STEP: f64 = 0.01;

fn simulate(tools: &[(&ToolSpec, Vec<Move>)], priority: Priority) -> Vec<Toolpath> {
    simulate_ahead(tools, priority, 0.0)
}

fn simulate_ahead(tools: &[(&ToolSpec, Vec<Move>)], priority: Priority, look_ahead: f64) -> Vec<Toolpath> {
    schedule(tools, priority, look_ahead).paths
}

/// The concurrent schedule of two tools, checked to keep them apart.
fn schedule(tools: &[(&ToolSpec, Vec<Move>)], priority: Priority, look_ahead: f64) -> sim::Schedule {
    let settings = Settings {
        step: STEP,
        budget: 100.0,
        max_side_steps: 20,
        priority,
        look_ahead,
        separation: sim::Separation::Discs,
        room: 0.0,
    };
    let s = sim::concurrent(tools, &settings, &BBox2::EMPTY).expect("no deadlock");
    let lines = [timeline(&s.paths, 0), timeline(&s.paths, 1)];
    let (d, t) = closest(&lines[0], &lines[1]);
    assert!(
        d >= 2.0 * tools[0].0.envelope - 1e-6,
        "{priority:?}: {d} mm apart at t = {t}"
    );
    assert_eq!(
        s.pauses.total(),
        holds(&s.paths).len(),
        "{priority:?}: every pause is counted once"
    );
    s
}

/// Two tools whose paths cross at right angles at the origin: tool 0 runs up along Y at
/// 40 mm/s (0 mm/s along X), tool 1 along X at 20 mm/s. Tool 0 is the faster tool and
/// the first one, tool 1 the faster along X. Tool 0 comes within 4 mm of tool 1's path
/// (y = -4, the two envelopes) at t = 1.45 s, when tool 1 is 1 mm short of the
/// crossing.
fn crossing() -> (ToolSpec, ToolSpec, Vec<Move>, Vec<Move>) {
    let (up, across) = (tool(0, 40.0, 2.0), tool(1, 20.0, 2.0));
    let r0 = vec![bead(Point2::new(0.0, -62.1), Point2::new(0.0, 57.9), 40.0)];
    let r1 = vec![bead(Point2::new(-30.0, 0.0), Point2::new(30.0, 0.0), 20.0)];
    (up, across, r0, r1)
}

#[test]
fn at_a_crossing_the_tool_faster_along_x_goes_on_and_the_other_pauses_before_it() {
    let (up, across, r0, r1) = crossing();
    let paths = simulate(&[(&up, r0), (&across, r1)], Priority::XSpeed);
    let h = holds(&paths);
    // Tool 1, faster along X though slower and listed second, never pauses; tool 0
    // pauses where it reaches tool 1's path, until tool 1 has gone by, then edges on
    // behind it (it is faster along Y than tool 1 moves off).
    assert!(!h.is_empty(), "nobody gave way");
    assert!(h.iter().all(|h| h.tool == 0), "{h:?}");
    let first = h[0];
    assert!((first.from - 1.45).abs() < 1e-6, "{first:?}");
    assert!(
        (first.at - Point2::new(0.0, -4.1)).norm() < 1e-6,
        "tool 0 waits at {:?}",
        first.at
    );
    let across_line = timeline(&paths, 1);
    let passed = position(&across_line, first.to);
    assert!(passed.x > 1.0, "tool 0 goes on with tool 1 at {passed:?}");
    assert!(h[h.len() - 1].to < 1.8, "tool 0 waits until {:?}", h[h.len() - 1]);
    // Tool 1 keeps its pace: 60 mm at 20 mm/s.
    let end = across_line[across_line.len() - 1].0;
    assert!((end - 3.0).abs() < 1e-9, "tool 1 ends at {end} s");
    let (decided, forced) = check_priority_by_speed_along_x(&paths, STEP, 0.5, 4.0);
    assert_eq!(decided + forced, h.len());
}

#[test]
fn looking_ahead_the_tool_slower_along_x_still_gives_way_at_a_crossing_only_sooner() {
    // Either tool pausing would keep them apart: the paper's rule decides, and would
    // fail here if the slower tool along X (tool 0) got priority.
    let (up, across, r0, r1) = crossing();
    let paths = simulate_ahead(&[(&up, r0), (&across, r1)], Priority::XSpeed, 0.5);
    let h = holds(&paths);
    assert!(!h.is_empty(), "nobody gave way");
    assert!(h.iter().all(|h| h.tool == 0), "{h:?}");
    // Half a second before it would reach the 4 mm line (t = 1.45 s): at most 0.5 s
    // sooner than checking one step ahead, farther back along its path.
    let first = h[0];
    assert!(first.from < 1.45 - 1e-6 && first.from >= 0.95 - 1e-6, "{first:?}");
    assert!(first.at.y < -4.1 - 1e-6, "tool 0 waits at {:?}", first.at);
    let across_line = timeline(&paths, 1);
    let end = across_line[across_line.len() - 1].0;
    assert!((end - 3.0).abs() < 1e-9, "tool 1 ends at {end} s");
    let (decided, forced) = check_priority_by_speed_along_x(&paths, STEP, 0.5, 4.0);
    assert_eq!(decided + forced, h.len());
}

#[test]
fn looking_ahead_a_tool_waits_before_the_way_narrows_instead_of_stepping_aside() {
    // Checking one step ahead by speed along X alone (`waiting` does not exclude a
    // pause that cannot clear the way), tool 1 (faster along X) comes up to tool 0,
    // which is still on its path, both are held and tool 0 steps aside, off its bead.
    let (up, across, r0, r1) = on_the_crossing(false);
    let one_step = simulate(&[(&up, r0.clone()), (&across, r1.clone())], Priority::Waiting);
    let off = |paths: &[Toolpath]| paths.iter().any(|p| p.tool == 0 && p.kind == PathKind::Travel);
    assert!(
        off(&one_step),
        "tool 0 did not step aside checking one step ahead"
    );
    // Looking ahead, tool 1 is paused before it gets near, where its pause alone keeps
    // them apart: nobody leaves its bead, each is late by its own waits alone, and
    // the two finish sooner than with the side-step.
    let paths = simulate_ahead(&[(&up, r0), (&across, r1)], Priority::XSpeed, 0.5);
    assert!(!off(&paths), "tool 0 stepped aside looking ahead");
    let h = holds(&paths);
    assert!(h.iter().any(|h| h.tool == 1), "{h:?}");
    let end = |paths: &[Toolpath], tool: usize| {
        let line = timeline(paths, tool);
        line[line.len() - 1].0
    };
    let waited = |tool: usize| -> f64 { h.iter().filter(|h| h.tool == tool).map(|h| h.to - h.from).sum() };
    for (tool, alone) in [(0, 6.0), (1, 7.4)] {
        let e = end(&paths, tool);
        assert!(
            (e - (alone + waited(tool))).abs() < 1e-6,
            "tool {tool} ends at {e} s"
        );
    }
    // Tool 0 clears tool 1's path by the two envelopes 0.4 s after reaching it: the
    // waits come to little more than that.
    assert!(waited(0) + waited(1) <= 0.5, "{h:?}");
    assert!(end(&paths, 1) < end(&one_step, 1).max(end(&one_step, 0)));
}

#[test]
fn looking_ahead_a_tool_catching_up_with_another_pauses_seldom() {
    // Tool 1 follows tool 0 along one line at twice its speed and soon has to keep
    // 4 mm behind it (`clearing`: the paper's rule would pause tool 0, faster along X
    // and in front, and both would be stuck). Checking one step ahead it pauses and
    // goes on step by step;
    // looking ahead it goes on only once its way is clear for a quarter of a second,
    // at most that much later in the end.
    let (lead, follow) = (tool(0, 10.0, 2.0), tool(1, 20.0, 2.0));
    let r0 = vec![bead(Point2::new(0.0, 0.0), Point2::new(60.0, 0.0), 10.0)];
    let r1 = vec![bead(Point2::new(-30.0, 0.0), Point2::new(50.0, 0.0), 20.0)];
    let pauses = |paths: &[Toolpath]| holds(paths).iter().filter(|h| h.tool == 1).count();
    let end = |paths: &[Toolpath]| {
        let line = timeline(paths, 1);
        line[line.len() - 1].0
    };
    let one_step = simulate(&[(&lead, r0.clone()), (&follow, r1.clone())], Priority::Clearing);
    let ahead = simulate_ahead(&[(&lead, r0), (&follow, r1)], Priority::Clearing, 0.5);
    assert!(holds(&ahead).iter().all(|h| h.tool == 1));
    let (n1, n2) = (pauses(&one_step), pauses(&ahead));
    assert!(n1 >= 100, "{n1} pauses checking one step ahead");
    assert!(n2 * 10 <= n1, "{n2} pauses looking ahead, {n1} checking one step");
    // Tool 1 ends at x = 50 when tool 0 is 4 mm ahead, at 5.4 s at the earliest; it
    // goes on once its way is clear for 0.25 s, so that it is late by no more than
    // that.
    for (paths, late) in [(&one_step, 2.0 * STEP), (&ahead, 0.25 + 2.0 * STEP)] {
        let e = end(paths);
        assert!(e >= 5.4 - 1e-9 && e <= 5.4 + late, "tool 1 ends at {e} s");
    }
}

/// Tool 0 crosses tool 1's path at 10 mm/s along Y (0 along X) and is 2 mm past the
/// crossing when tool 1 comes along X at 20 mm/s, 4 mm short of it at t = 3.2 s:
/// holding tool 1 alone clears the way (tool 0 moves off), holding tool 0 does not.
/// Tool 1 has more work left: when both are held, tool 0 steps aside. With `returning`,
/// tool 1's move is the way back from a side-step.
fn on_the_crossing(returning: bool) -> (ToolSpec, ToolSpec, Vec<Move>, Vec<Move>) {
    let (up, across) = (tool(0, 10.0, 2.0), tool(1, 20.0, 2.0));
    let r0 = vec![bead(Point2::new(0.0, -30.0), Point2::new(0.0, 30.0), 10.0)];
    let r1 = vec![Move {
        yields: returning,
        ..bead(Point2::new(-68.0, 0.0), Point2::new(80.0, 0.0), 20.0)
    }];
    (up, across, r0, r1)
}

/// What happens on the crossing: which tools gave way (paused, or stepped off their
/// one bead) and which did first, and where tool 1 first paused.
struct Outcome {
    gave_way: [bool; 2],
    first: Option<usize>,
    paused_at: Option<Point2>,
}

fn on_the_crossing_with(returning: bool, priority: Priority) -> Outcome {
    let (up, across, r0, r1) = on_the_crossing(returning);
    let paths = simulate(&[(&up, r0), (&across, r1)], priority);
    let h = holds(&paths);
    let since = [0, 1].map(|tool| {
        let held = h.iter().find(|h| h.tool == tool).map(|h| h.from);
        let off = paths
            .iter()
            .filter(|p| p.tool == tool && p.kind != PathKind::Extrude)
            .map(|p| p.points[0].t)
            .reduce(f64::min);
        let line = timeline(&paths, tool);
        // Each bead alone: 60 mm at 10 mm/s, 148 mm at 20 mm/s.
        let late = line[line.len() - 1].0 > [6.0, 7.4][tool] + 1e-9;
        let since = [held, off].into_iter().flatten().reduce(f64::min);
        assert_eq!(since.is_some(), late, "{priority:?}, tool {tool}");
        since
    });
    Outcome {
        gave_way: since.map(|s| s.is_some()),
        first: match since {
            [Some(a), Some(b)] => Some(if a <= b { 0 } else { 1 }),
            [Some(_), None] => Some(0),
            [None, Some(_)] => Some(1),
            [None, None] => None,
        },
        paused_at: h.iter().find(|h| h.tool == 1).map(|h| h.at),
    }
}

#[test]
fn priority_by_clearing_pauses_the_tool_whose_pausing_clears_the_way() {
    // Speed along X alone (`waiting` at the one-step check): tool 1, faster along X,
    // has priority; tool 0 gives way first (it is held on tool 1's path, so it steps
    // aside).
    assert_eq!(on_the_crossing_with(false, Priority::Waiting).first, Some(0));
    // `clearing`, and the paper's rule with its one exception (holding tool 0 would
    // not clear the way): tool 1 waits, where it comes within 4 mm of tool 0 (2 mm off
    // its path), for tool 0 to move off; tool 0 never waits.
    for priority in [Priority::Clearing, Priority::XSpeed] {
        let o = on_the_crossing_with(false, priority);
        assert_eq!(o.gave_way, [false, true], "{priority:?}");
        let at = o.paused_at.expect("tool 1 paused");
        assert!(
            at.x < -3.2 && at.x > -3.7 && at.y.abs() < 1e-9,
            "{priority:?}: {at:?}"
        );
    }
    // Counted as forced, not as decided by speed.
    let (up, across, r0, r1) = on_the_crossing(false);
    let s = schedule(&[(&up, r0.clone()), (&across, r1.clone())], Priority::XSpeed, 0.0);
    assert!(
        s.pauses.forced > 0 && s.pauses.by_x_speed == 0 && s.pauses.other == 0,
        "{:?}",
        s.pauses
    );
    // Listed the other way round, the tool along X (now the first) still waits and the
    // one on the crossing never does.
    let (mut up, mut across) = (up, across);
    (up.index, across.index) = (1, 0);
    let s = schedule(&[(&across, r1), (&up, r0)], Priority::XSpeed, 0.0);
    let h = holds(&s.paths);
    assert!(!h.is_empty() && h.iter().all(|h| h.tool == 0), "{h:?}");
    assert!(
        !s.paths.iter().any(|p| p.tool == 1 && p.kind != PathKind::Extrude),
        "the tool on the crossing gave way"
    );
}

#[test]
fn priority_by_returning_pauses_the_tool_back_from_a_side_step() {
    // Without a side-step, `returning` is the paper's rule.
    assert_eq!(on_the_crossing_with(false, Priority::Returning).first, Some(0));
    // Tool 1 on its way back from a side-step gives way with `returning` (and
    // `clearing`): it waits and tool 0 never does; not by speed along X alone.
    for priority in [Priority::Returning, Priority::Clearing] {
        let o = on_the_crossing_with(true, priority);
        assert_eq!(o.gave_way, [false, true], "{priority:?}");
        assert!(o.paused_at.is_some(), "{priority:?}: tool 1 paused");
    }
    assert_eq!(on_the_crossing_with(true, Priority::Waiting).first, Some(0));
}

/// Two tools heading for a crossing where either pause would keep them apart, listed
/// in both orders: tool `up` runs along Y (0 mm/s along X) and is the faster, tool
/// `across` runs along X. Whichever is listed first, the one slower along X pauses and
/// the pause is counted as decided by speed; a rule that ignored X speed (always the
/// first, or always the second) or reversed it would pause `across`.
#[test]
fn the_tool_slower_along_x_pauses_whichever_is_listed_first() {
    let (up, across, r0, r1) = crossing();
    // The same crossing 50 mm along +x too: a speed along X taken from positions
    // rather than displacements would rank the tool along Y first there.
    let shift = |r: &[Move], dx: f64| -> Vec<Move> {
        r.iter()
            .map(|m| Move {
                points: m.points.iter().map(|p| Point2::new(p.x + dx, p.y)).collect(),
                ..m.clone()
            })
            .collect()
    };
    for (look_ahead, dx) in [(0.5, 0.0), (1.0, 0.0), (0.5, 50.0)] {
        let (r0, r1) = (shift(&r0, dx), shift(&r1, dx));
        for swap in [false, true] {
            let (mut a, mut b) = (up.clone(), across.clone());
            let tools = if swap {
                a.index = 1;
                b.index = 0;
                vec![(&b, r1.clone()), (&a, r0.clone())]
            } else {
                vec![(&a, r0.clone()), (&b, r1.clone())]
            };
            let s = schedule(&tools, Priority::XSpeed, look_ahead);
            let h = holds(&s.paths);
            let (up_index, across_index) = (a.index, b.index);
            assert!(
                !h.is_empty(),
                "look-ahead {look_ahead}, swapped {swap}: nobody gave way"
            );
            assert!(
                h.iter().all(|h| h.tool == up_index),
                "look-ahead {look_ahead}, swapped {swap}: {h:?}"
            );
            // The tool along X keeps its pace: 60 mm at 20 mm/s.
            let line = timeline(&s.paths, across_index);
            assert!((line[line.len() - 1].0 - 3.0).abs() < 1e-9);
            assert!(
                s.pauses.by_x_speed >= 1 && s.pauses.other == 0,
                "look-ahead {look_ahead}, swapped {swap}: {:?}",
                s.pauses
            );
        }
    }
    // `waiting` puts one rule of its own first, and is counted when it decides.
    let s = schedule(
        &[(&up, r0.clone()), (&across, r1.clone())],
        Priority::Waiting,
        0.5,
    );
    assert_eq!(s.pauses.total(), holds(&s.paths).len());
    // A look-ahead no longer than about a step is the paper's one-step check.
    let one = schedule(&[(&up, r0.clone()), (&across, r1.clone())], Priority::XSpeed, 0.0);
    let step = schedule(&[(&up, r0), (&across, r1)], Priority::XSpeed, STEP);
    assert_eq!(one.paths, step.paths);
}

/// Two tools crossing diagonally at the same speed along X (one up and right, one up
/// and left): a tie, where the paper's rule lets the tool listed first go on, whichever
/// it is. Looking ahead, so that either pause would clear the way when the collision
/// comes in prospect.
#[test]
fn on_a_tie_along_x_the_tool_listed_first_goes_on() {
    let right = vec![bead(Point2::new(-20.0, -20.0), Point2::new(20.0, 20.0), 20.0)];
    let left = vec![bead(Point2::new(22.0, -18.0), Point2::new(-18.0, 22.0), 20.0)];
    for look_ahead in [0.5, 1.0] {
        for swap in [false, true] {
            let (a, b) = (tool(0, 20.0, 2.0), tool(1, 20.0, 2.0));
            let routes = if swap { [&left, &right] } else { [&right, &left] };
            let s = schedule(
                &[(&a, routes[0].clone()), (&b, routes[1].clone())],
                Priority::XSpeed,
                look_ahead,
            );
            let h = holds(&s.paths);
            assert!(
                !h.is_empty(),
                "look-ahead {look_ahead}, swapped {swap}: nobody gave way"
            );
            assert!(
                h.iter().all(|h| h.tool == 1),
                "look-ahead {look_ahead}, swapped {swap}: {h:?} {:?}",
                s.pauses
            );
            assert!(s.pauses.by_x_speed >= 1, "{:?}", s.pauses);
        }
    }
}

#[test]
fn priority_and_keep_faster_are_options_of_the_concurrent_planner() {
    for ok in [
        "priority = \"x-speed\"",
        "priority = \"clearing\"",
        "priority = \"returning\"",
        "keep_faster = true",
        "look_ahead = 2.0",
        "look_ahead = 0",
    ] {
        assert!(build(&format!("use = \"concurrent\"\n{ok}")).is_ok(), "{ok}");
        // Accepted by the sequential planner too, which ignores them.
        assert!(build(&format!("use = \"sequential\"\n{ok}")).is_ok(), "{ok}");
    }
    for bad in [
        "priority = \"fastest\"",
        "priority = 1",
        "keep_faster = \"yes\"",
        "look_ahead = -1.0",
        "look_ahead = 1000.0",
    ] {
        assert!(build(&format!("use = \"concurrent\"\n{bad}")).is_err(), "{bad}");
    }
}

/// Two gantries: the rear head never comes closer than the envelopes' sum behind the
/// front one in Y, however far apart they are in X; the same routes as free heads
/// pass without a pause.
#[test]
fn heads_on_two_gantries_keep_their_order_in_y() {
    let front = tool(0, 30.0, 5.0);
    let rear = ToolSpec {
        rear: true,
        ..tool(1, 10.0, 5.0)
    };
    // Both sweep from front to back, 60 mm apart in X: the faster front head catches
    // up with the slower rear one.
    let a = vec![bead(Point2::new(0.0, 0.0), Point2::new(0.0, 60.0), 30.0)];
    // The rear head then goes back to its park behind the layer, out of the way.
    let b = vec![
        bead(Point2::new(60.0, 15.0), Point2::new(60.0, 45.0), 10.0),
        Move::travel(vec![Point2::new(60.0, 45.0), Point2::new(60.0, 100.0)], 10.0),
    ];
    let mut laid = Vec::new();
    for (separation, look_ahead) in [
        (sim::Separation::OrderedY, 0.0),
        (sim::Separation::OrderedY, 0.5),
        (sim::Separation::Discs, 0.5),
    ] {
        let settings = Settings {
            step: STEP,
            budget: 100.0,
            max_side_steps: 20,
            priority: Priority::XSpeed,
            look_ahead,
            separation,
            room: 0.0,
        };
        let s = sim::concurrent(
            &[(&front, a.clone()), (&rear, b.clone())],
            &settings,
            &BBox2::EMPTY,
        )
        .expect("no deadlock");
        let (ta, tb) = (timeline(&s.paths, 0), timeline(&s.paths, 1));
        let end = s.end;
        let steps = 20_000;
        let least = (0..=steps)
            .map(|k| end * k as f64 / steps as f64)
            .map(|t| position(&tb, t).y - position(&ta, t).y)
            .fold(f64::INFINITY, f64::min);
        let paused = s.pauses.by_x_speed + s.pauses.forced + s.pauses.other;
        laid.push(extruded(&s.paths));
        if separation == sim::Separation::OrderedY {
            assert!(least >= 10.0 - 1e-6, "look-ahead {look_ahead}: {least} mm in Y");
            // Looking ahead, the front head hangs back once for a while instead of
            // pausing at every other check (7 pauses against 175).
            if look_ahead > 0.0 {
                assert!(paused < 20, "look-ahead {look_ahead}: {paused} pauses");
            } else {
                assert!(paused > 50, "{paused} pauses");
            }
            assert!(paused > 0, "the front head waits behind the rear one");
        } else {
            assert!(least < 0.0, "free heads pass each other in Y");
            assert_eq!(paused, 0);
        }
    }
    // Pauses cut beads, never shorten them: every schedule lays the same beads.
    assert!(laid.iter().all(|v| (v - laid[0]).abs() < 1e-6), "{laid:?}");
}

/// At the same crossing, `busiest` lets the tool with more of its route left go on:
/// tool 0 (120 mm at 40 mm/s, 3 s) keeps going and tool 1 (60 mm at 20 mm/s, 3 s,
/// less once both have started) gives way, the other way round from the paper's rule.
#[test]
fn by_busiest_the_tool_with_more_work_left_goes_on() {
    let (up, across, r0, mut r1) = crossing();
    // Tool 1's route made shorter: 40 mm, 2 s.
    r1[0].points[1] = Point2::new(10.0, 0.0);
    // Looking ahead, where either pause would clear the way, so that the rule decides.
    let paths = simulate_ahead(
        &[(&up, r0.clone()), (&across, r1.clone())],
        Priority::Busiest,
        0.5,
    );
    let h = holds(&paths);
    assert!(!h.is_empty(), "nobody gave way");
    assert!(h.iter().all(|h| h.tool == 1), "{h:?}");
    // Tool 0 keeps its pace: 120 mm at 40 mm/s.
    let line = timeline(&paths, 0);
    assert!((line[line.len() - 1].0 - 3.0).abs() < 1e-9);
    // Listed the other way round, the same tool gives way.
    let paths = simulate_ahead(
        &[(&across, r1.clone()), (&up, r0.clone())],
        Priority::Busiest,
        0.5,
    );
    let h = holds(&paths);
    assert!(!h.is_empty() && h.iter().all(|h| h.tool == 1), "{h:?}");
    // The paper's rule pauses tool 0 instead.
    let paths = simulate_ahead(&[(&up, r0), (&across, r1)], Priority::XSpeed, 0.5);
    assert!(holds(&paths).iter().all(|h| h.tool == 0));
}

/// Two gantries sweeping three rows front to back, one bead a row each (20 s): the rear
/// head leads from the front row while the front head waits at its park, then each
/// row is beaded by the rear head while the front head beads the row before it: the
/// layer takes under three quarters of one head after the other, and the heads keep
/// their order and distance in Y throughout.
#[test]
fn on_two_gantries_the_rear_head_leads_and_the_front_head_follows_a_row_behind() {
    let front = tool(0, 10.0, 5.0);
    let rear = ToolSpec {
        rear: true,
        ..tool(1, 10.0, 5.0)
    };
    let rows = [0.0, 40.0, 80.0];
    let route = |park: Point2| {
        let mut moves = Vec::new();
        let mut at = park;
        for (k, &y) in rows.iter().enumerate() {
            // Serpentine, as the nearest-neighbour routes go.
            let (x0, x1) = if k % 2 == 0 { (0.0, 200.0) } else { (200.0, 0.0) };
            let (a, b) = (Point2::new(x0, y), Point2::new(x1, y));
            moves.push(Move::travel(vec![at, a], 10.0));
            moves.push(bead(a, b, 10.0));
            at = b;
        }
        moves.push(Move::travel(vec![at, park], 10.0));
        moves
    };
    let (a, b) = (route(Point2::new(0.0, -30.0)), route(Point2::new(200.0, 110.0)));
    let settings = Settings {
        step: STEP,
        budget: 1000.0,
        max_side_steps: 20,
        priority: Priority::XSpeed,
        look_ahead: 0.5,
        separation: sim::Separation::OrderedY,
        room: 0.0,
    };
    let s = sim::concurrent(
        &[(&front, a.clone()), (&rear, b.clone())],
        &settings,
        &BBox2::EMPTY,
    )
    .expect("no deadlock");
    let duration = |r: &[Move]| -> f64 {
        r.iter()
            .map(|m| m.points.windows(2).map(|w| (w[1] - w[0]).norm()).sum::<f64>() / m.speed)
            .sum()
    };
    let one_after_the_other = duration(&a) + duration(&b);
    println!(
        "{:.1} s against {one_after_the_other:.1} s one after the other",
        s.end
    );
    assert!(
        s.end < 0.75 * one_after_the_other,
        "{} s of {one_after_the_other}",
        s.end
    );
    let first_bead = |tool: usize| {
        s.paths
            .iter()
            .filter(|p| p.tool == tool && p.kind == PathKind::Extrude)
            .map(|p| p.points[0].t)
            .fold(f64::INFINITY, f64::min)
    };
    assert!(first_bead(1) < first_bead(0), "the rear head begins");
    // The front head waits at its park until the rear head has beaded the front row
    // and gone on, not only until it has begun.
    let first_path = |tool: usize| {
        s.paths
            .iter()
            .filter(|p| p.tool == tool)
            .min_by(|a, b| a.points[0].t.total_cmp(&b.points[0].t))
            .expect("a path")
    };
    let waits = first_path(0);
    let rear_row = s
        .paths
        .iter()
        .filter(|p| p.tool == 1 && p.kind == PathKind::Extrude)
        .min_by(|a, b| a.points[0].t.total_cmp(&b.points[0].t))
        .expect("a bead");
    assert_eq!(waits.kind, PathKind::Pause);
    assert_eq!(waits.points[0].p, Point2::new(0.0, -30.0));
    let until = waits.points.last().expect("end").t;
    let row_done = rear_row.points.last().expect("end").t;
    assert!(
        until >= row_done - STEP,
        "the front head left its park at {until} s, the rear head's row ends at {row_done} s"
    );
    // It leaves as soon as the rear head is the two envelopes (10 mm) beyond the front
    // head's first bead (y 0), on its way to the next row, and not later.
    let tb = timeline(&s.paths, 1);
    let beyond = (0..=200_000)
        .map(|k| s.end * k as f64 / 200_000.0)
        .find(|&t| t > row_done && position(&tb, t).y >= 10.0)
        .expect("the rear head goes on");
    assert!(
        (until - beyond).abs() <= 2.0 * STEP,
        "the front head left its park at {until} s, the rear head was 10 mm beyond its first bead at {beyond} s"
    );
    let ta = timeline(&s.paths, 0);
    let least = (0..=20_000)
        .map(|k| s.end * k as f64 / 20_000.0)
        .map(|t| position(&tb, t).y - position(&ta, t).y)
        .fold(f64::INFINITY, f64::min);
    assert!(least >= 10.0 - 1e-6, "{least} mm in Y");
}

/// A layer of two parts, one a material, each a 40 mm wide rectangle: tool 0's (the
/// front head's) from y `front.0` to `front.1`, tool 1's (the rear head's) from
/// `rear.0` to `rear.1`, on a plate from y 0 to `depth` (other parts fill the rest),
/// on `machine`, placed as the exporter places them.
fn gantry_layer(
    machine: lamina_core::Machine,
    front: (f64, f64),
    rear: (f64, f64),
    depth: f64,
) -> (RunInfo, LayerPlan) {
    let mut rng = Rng::with_seed(1);
    let (mut info, mut plan) = layout(&mut rng, 2);
    for (part, (y0, y1)) in [front, rear].into_iter().enumerate() {
        let outer = rect(0.0, y0, 40.0, y1 - y0);
        plan.parts[part].regions.truncate(1);
        let r = &mut plan.parts[part].regions[0];
        r.reference = Point2::new(20.0, (y0 + y1) / 2.0);
        r.polygon = Polygon::new(outer, Vec::new());
    }
    info.xy_bounds = lamina_core::BBox2::from_points([Point2::new(0.0, 0.0), Point2::new(40.0, depth)]);
    info.machine = Some(machine);
    (info, plan)
}

/// On two gantries (rrf-dual-gantry-2: a 300 mm deep bed, the plate centred on it) the
/// rear head reaches no nearer the bed's front edge than the two envelopes (5 mm each
/// here), nor the front head the back edge: a plan that puts the rear head's beads at
/// Y 5-15 mm, or the front head's at 285-295 mm, is refused naming the head and how
/// far it reaches; with room at both edges it is planned. A round bed's reach is the
/// square inside it.
#[test]
fn on_two_gantries_beads_beyond_a_heads_reach_are_refused() {
    let gantry = lamina_core::machine::load::builtin("rrf-dual-gantry-2").expect("profile");
    let p = planner("use = \"concurrent\"");
    // The message of a plan refused for the layer `gantry_layer` makes.
    let refused = |planner: &dyn Planner,
                   machine: &lamina_core::Machine,
                   rear: (f64, f64),
                   front: (f64, f64),
                   depth: f64| {
        let (info, mut plan) = gantry_layer(machine.clone(), rear, front, depth);
        planner
            .plan(&info, &mut plan)
            .expect_err("out of a head's reach")
            .to_string()
    };
    // The rear head's part at the front of a plate 290 mm deep: Y 5-15 on the bed.
    let e = refused(&*p, &gantry, (100.0, 140.0), (0.0, 10.0), 290.0);
    assert!(
        e.contains("the rear head (tool 1, m1)") && e.contains("front edge than Y 10.0 mm"),
        "{e}"
    );
    // The front head's part at the back: Y 285-295.
    let e = refused(&*p, &gantry, (280.0, 290.0), (100.0, 140.0), 290.0);
    assert!(
        e.contains("the front head (tool 0, m0)") && e.contains("back edge than Y 290.0 mm"),
        "{e}"
    );
    // Room at both edges: planned, every bead on the bed.
    let (info, mut plan) = gantry_layer(gantry.clone(), (0.0, 40.0), (60.0, 100.0), 100.0);
    p.plan(&info, &mut plan).expect("within reach");
    assert!(!plan.toolpaths.is_empty());
    let off = gantry.placement_offset(&info.xy_bounds);
    for t in &plan.toolpaths {
        for q in &t.points {
            let y = q.p.y + off.y;
            assert!((0.0..=300.0).contains(&y), "tool {} at Y {y} on the bed", t.tool);
        }
    }
    // A round bed of 300 mm: the square inside it starts 43.9 mm from the round bed's
    // box, so the rear head reaches no nearer than Y 53.9 mm; the plate, 240 mm deep,
    // puts its part at Y 30-50.
    let mut round = gantry.clone();
    round.bed.shape = lamina_core::machine::BedShape::Circle { diameter: 300.0 };
    let e = refused(&*p, &round, (100.0, 140.0), (0.0, 20.0), 240.0);
    assert!(e.contains("front edge than Y 53.9 mm"), "{e}");
    // And the front head no nearer its back edge than Y 246.1 mm.
    let e = refused(&*p, &round, (220.0, 240.0), (100.0, 140.0), 240.0);
    assert!(e.contains("back edge than Y 246.1 mm"), "{e}");
    // Heads of different sizes: the rear head (8 mm) keeps its own envelope and the
    // front head's (5 mm) from the front edge.
    let sized = planner("use = \"concurrent\"\ntools = { m1 = { envelope = 8.0 } }");
    let e = refused(&*sized, &round, (100.0, 140.0), (0.0, 20.0), 240.0);
    assert!(e.contains("front edge than Y 56.9 mm"), "{e}");
}
