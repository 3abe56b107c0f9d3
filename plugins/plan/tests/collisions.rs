//! An independent check of the concurrent planner: the timed paths it outputs are
//! re-simulated exactly (between any two breakpoints of two tools both move in straight
//! lines at constant speed, so their closest approach has a closed form) and no two
//! envelopes may ever overlap. Layouts of 2 to 4 tools are drawn at random (a small
//! deterministic generator, so failures repeat).

use std::path::PathBuf;

use lamina_core::stage::{AnyStage, Planner};
use lamina_core::{
    Composition, Contour, ContourTree, LayerPlan, Material, PartInfo, PartLayer, PathKind, Point2, Polygon,
    Region, Registry, RunInfo, StageKind, Toolpath,
};

struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
    }
    fn range(&mut self, a: f64, b: f64) -> f64 {
        a + (b - a) * self.next()
    }
}

fn planner(table: &str) -> Box<dyn Planner> {
    use lamina_plan as _;
    let registry = Registry::linked().expect("registry");
    let dir = std::env::temp_dir();
    let scripts = lamina_core::script::ScriptHost::new(&dir, Default::default());
    let table = lamina_core::pipeline::TableRef::parse_snippet("plan", table).expect("table");
    match registry
        .build(StageKind::Plan, &table, &scripts, &dir)
        .expect("builds")
    {
        AnyStage::Plan(p) => p,
        _ => panic!("not a planner"),
    }
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
        })
        .collect();
    let mut layers = Vec::new();
    for part in 0..tools {
        let mut regions = Vec::new();
        for index in 0..1 + (rng.next() * 3.0) as usize {
            let c = Point2::new(rng.range(0.0, 60.0), rng.range(0.0, 60.0));
            let outer = if rng.next() < 0.5 {
                disc(c, rng.range(1.0, 8.0), 48)
            } else {
                rect(c.x, c.y, rng.range(1.0, 15.0), rng.range(0.5, 12.0))
            };
            // Each region an island of its own (random shapes may overlap, which
            // sub-regions of one family never do).
            regions.push(Region {
                family: index,
                index: 0,
                count: 1,
                level: 0.0,
                polygon: Polygon::new(outer, Vec::new()),
                cell: None,
                reference: c,
                composition: Some(Composition::pure(0, 1)),
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
    };
    let plan = LayerPlan {
        index: 0,
        z: 0.2,
        thickness: 0.2,
        region: None,
        parts: layers,
        toolpaths: Vec::new(),
        build_time: None,
        sequential_time: None,
        fill: None,
        warnings: Vec::new(),
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

#[test]
fn random_layouts_of_two_to_four_tools_never_collide() {
    let mut rng = Rng(0x5eed_1234_abcd_0001);
    let mut pauses = 0;
    let mut faster = 0;
    for case in 0..40 {
        let tools = 2 + case % 3;
        let envelope = rng.range(1.5, 6.0);
        let table = format!(
            "use = \"concurrent\"\nwidth = 0.5\nenvelope = {envelope}\nstep = 0.02\nspeed = {}\ntravel_speed = 100.0\n\
             [tools.m0]\nspeed = {}",
            rng.range(10.0, 40.0),
            rng.range(10.0, 40.0)
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
        if !conc.warnings.iter().any(|w| w.contains("gave up")) {
            assert!(
                tc <= ts + 1e-6,
                "case {case}: concurrent {tc} s slower than sequential {ts} s"
            );
            if tc < ts {
                faster += 1;
            }
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
}

#[test]
fn tools_crossing_head_on_give_way_by_speed_along_x() {
    // Two bars side by side with a narrow gap: the tools must pass each other.
    let mut rng = Rng(9);
    let (info, mut plan) = layout(&mut rng, 2);
    plan.parts[0].regions.truncate(1);
    plan.parts[1].regions.truncate(1);
    plan.parts[0].regions[0].polygon = Polygon::new(rect(0.0, 0.0, 40.0, 2.0), vec![]);
    plan.parts[1].regions[0].polygon = Polygon::new(rect(0.0, 3.0, 40.0, 2.0), vec![]);
    planner("use = \"concurrent\"\nenvelope = 2.0\nstep = 0.01\n[tools.m1]\nspeed = 10.0")
        .plan(&info, &mut plan)
        .expect("plans");
    let a = timeline(&plan.toolpaths, 0);
    let b = timeline(&plan.toolpaths, 1);
    assert!(closest(&a, &b).0 >= 4.0 - 1e-6);
    assert!(plan.toolpaths.iter().any(|p| p.kind == PathKind::Pause));
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
    let mut rng = Rng(3);
    let (info, mut plan) = layout(&mut rng, 2);
    // 0.15 mm wide: under the narrowest bead (0.6 x 0.4 mm), and alone in its part.
    plan.parts[0].regions.truncate(1);
    plan.parts[0].regions[0].polygon = Polygon::new(rect(0.0, 0.0, 10.0, 0.15), vec![]);
    planner("use = \"sequential\"")
        .plan(&info, &mut plan)
        .expect("plans");
    assert!(
        plan.warnings
            .iter()
            .any(|w| w.contains("narrower than the narrowest bead")
                && w.contains("even with their neighbours")),
        "{:?}",
        plan.warnings
    );
}

#[test]
fn sequential_time_is_path_length_over_speed_plus_tool_changes() {
    let mut rng = Rng(5);
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
        let mut rng = Rng(seed);
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
        assert!(t <= s + 1e-9, "seed {seed}: concurrent {t} > sequential {s}");
    }
}
