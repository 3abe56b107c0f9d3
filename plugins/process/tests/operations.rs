//! The numbers each operation of the CMPM process (cmpm-process-planning §2) hands to
//! the machine, read back from a whole run of the stages on the pipe of Fig. 11: three
//! concentric tubes in work cycles, a microstructure inside, a graded FGM in the
//! middle and a composite outside. The end-to-end tests (`hybrid::` in the `lamina`
//! package) check where the paths lie and the order of the operations; these check
//! what the operations say: the sprayed mix and inclusions, the raster's spacing, the
//! heights each grind takes the surface from and to, the wheel's spindle speed from
//! its surface speed, the end mill's depth, the filled voids' volume, and the filler
//! removed once at the end.

use lamina_process as _;
use serde_json::Value;

/// The pipe, with a spray track overlap and a removal of the filler that the shipped
/// pipeline leaves at their defaults or out, and only the plan written.
const PIPE: &str = r#"
name = "pipe"

[materials.microstructure]
colour = [70, 130, 180]
layer_thickness = 0.2
[materials.ceramic]
colour = [240, 240, 230]
layer_thickness = 0.5
[materials.metal]
colour = [90, 90, 100]
layer_thickness = 0.5
[materials.composite]
colour = [150, 75, 0]
layer_thickness = 1.5

[[parts]]
name = "inner"
materials = ["microstructure"]
[parts.model]
use = "tube"
outer_radius = 7.0
inner_radius = 5.0
height = 3.0

[[parts]]
name = "middle"
materials = ["ceramic", "metal"]
[parts.model]
use = "tube"
outer_radius = 9.0
inner_radius = 7.0
height = 3.0
[parts.grade]
use = "script"
f = "z / 3.0"

[[parts]]
name = "outer"
materials = ["composite"]
[parts.model]
use = "tube"
outer_radius = 10.0
inner_radius = 9.0
height = 3.0

[sequence]
use = "work-cycles"

[slice]
use = "adaptive"

# Two rings per tube: the graded tube's are of one mix (the grade follows z alone), and
# are sprayed in one operation.
[discretise]
use = "offset"
count = 2

[[process]]
use = "end-mill"
diameter = 0.8
passes = 2

[[process]]
use = "spray"
rough_allowance = 0.1
finish_allowance = { inner = 0.02 }
inclusions = { outer = { SiC = 0.2 } }
diameter = 2.0
overlap = 0.4

[[process]]
use = "grind"
pass = "rough"

[[process]]
use = "engrave"
regions = ["inner"]
period = [1.0, 1.0, 0.6]
void_radius = 0.25

[[process]]
use = "fill"
regions = ["inner"]

[[process]]
use = "grind"
pass = "finish"

[[process]]
use = "remove-filler"
method = "melt-out"
temperature = 300.0

[[output]]
use = "json"
path = "pipe.json"
"#;

/// The regions in the sequence's order, their radii (mm) and finish allowances.
const REGIONS: [&str; 3] = ["inner", "middle", "outer"];
const RADII: [(f64, f64); 3] = [(5.0, 7.0), (7.0, 9.0), (9.0, 10.0)];
const FINISH: [f64; 3] = [0.02, 0.0, 0.0];
const ROUGH: f64 = 0.1;

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

fn layers(plan: &Value) -> &Vec<Value> {
    plan["layers"].as_array().expect("layers")
}

fn ops(layer: &Value) -> Vec<&Value> {
    layer["operations"]
        .as_array()
        .map(|a| a.iter().collect())
        .unwrap_or_default()
}

fn value(op: &Value, key: &str) -> f64 {
    f(&op["values"][key])
}

/// The one operation of `kind` (and grind `pass`) on the layer, if any.
fn one<'a>(layer: &'a Value, kind: &str, pass: Option<&str>) -> Option<&'a Value> {
    let mut found = ops(layer)
        .into_iter()
        .filter(|o| o["kind"] == kind && pass.is_none_or(|p| o["pass"] == p));
    let op = found.next();
    assert!(found.next().is_none(), "two {kind} operations on a layer");
    op
}

/// A path's points as (x, y).
fn points(path: &Value) -> Vec<(f64, f64)> {
    path["points"]
        .as_array()
        .expect("points")
        .iter()
        .map(|q| (f(&q[0]), f(&q[1])))
        .collect()
}

/// The distinct y of an operation's passes (each pass's first point), in order.
fn pass_ys(op: &Value) -> Vec<f64> {
    let mut ys: Vec<f64> = op["paths"]
        .as_array()
        .expect("paths")
        .iter()
        .map(|p| f(&p["points"][0][1]))
        .collect();
    ys.sort_by(f64::total_cmp);
    ys.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
    ys
}

fn run() -> Value {
    lamina_test_support::run_pipeline(PIPE).json("pipe.json")
}

#[test]
fn each_region_is_sprayed_its_allowances_high_with_its_mix_and_its_inclusions() {
    let plan = run();
    let mut sprayed = [0; 3];
    for (i, l) in layers(&plan).iter().enumerate() {
        let r = l["region"].as_u64().expect("region") as usize;
        let (z, t) = (f(&l["z"]), f(&l["thickness"]));
        let mixes: Vec<&Value> = ops(l).into_iter().filter(|o| o["kind"] == "spray").collect();
        assert!(!mixes.is_empty(), "layer {i}: not sprayed");
        // The layer's compositions, by material name, as its sub-regions carry them.
        let compositions: Vec<&Value> = l["parts"]
            .as_array()
            .expect("parts")
            .iter()
            .flat_map(|p| p["families"].as_array().expect("families"))
            .flat_map(|fam| fam["sub_regions"].as_array().expect("sub-regions"))
            .map(|s| &s["composition"])
            .collect();
        for op in &mixes {
            let surface = f(&op["surface"]);
            assert!(
                (surface - (z + ROUGH + FINISH[r])).abs() < 1e-9,
                "layer {i} ({}): sprayed to {surface}, not {} + {ROUGH} + {}",
                REGIONS[r],
                z,
                FINISH[r]
            );
            assert!((value(op, "thickness") - t).abs() < 1e-12);
            assert!((value(op, "rough_allowance") - ROUGH).abs() < 1e-12);
            assert!((value(op, "finish_allowance") - FINISH[r]).abs() < 1e-12);
            // The feeders are set to the mix of a sub-region of the layer, which adds up
            // to the whole.
            let fractions: Vec<(&str, f64)> = op["values"]
                .as_object()
                .expect("values")
                .iter()
                .filter_map(|(k, v)| k.strip_prefix("fraction:").map(|m| (m, f(v))))
                .collect();
            let sum: f64 = fractions.iter().map(|(_, v)| v).sum();
            assert!((sum - 1.0).abs() < 1e-9, "layer {i}: fractions {fractions:?}");
            assert!(
                compositions.iter().any(|c| {
                    fractions
                        .iter()
                        .all(|(m, v)| c[*m].as_f64().is_some_and(|w| (w - v).abs() < 1e-9))
                }),
                "layer {i}: {fractions:?} is no sub-region's mix"
            );
            let inclusion = op["values"].get("inclusion:SiC").map(f);
            assert_eq!(inclusion, (r == 2).then_some(0.2), "layer {i}");
            // Passes along x, one track width less the overlap apart (2 mm, 40 %).
            for p in op["paths"].as_array().expect("paths") {
                assert!(
                    (f(&p["z"]) - surface).abs() < 1e-12,
                    "layer {i}: a pass off the surface"
                );
                let pts = p["points"].as_array().expect("points");
                let (a, b) = (&pts[0], &pts[pts.len() - 1]);
                assert!(
                    (f(&a[1]) - f(&b[1])).abs() < 1e-12,
                    "layer {i}: a pass not along x"
                );
            }
            let ys = pass_ys(op);
            assert!(ys.len() >= 10, "layer {i}: {} passes", ys.len());
            for w in ys.windows(2) {
                assert!(
                    (w[1] - w[0] - 1.2).abs() < 1e-9,
                    "layer {i}: passes {} apart",
                    w[1] - w[0]
                );
            }
        }
        // One operation per mix, the graded middle's changing with height.
        assert_eq!(mixes.len(), 1, "layer {i}");
        if r == 1 {
            assert!(
                mixes
                    .iter()
                    .all(|o| (value(o, "fraction:ceramic") - (z / 3.0)).abs() < 1e-9),
                "layer {i} at {z}: the mix is f = z / 3 at the layer's top"
            );
        } else {
            let only = if r == 0 {
                "fraction:microstructure"
            } else {
                "fraction:composite"
            };
            assert_eq!(value(mixes[0], only), 1.0);
        }
        sprayed[r] += 1;
    }
    assert!(sprayed.iter().all(|&n| n >= 2), "{sprayed:?}");
}

#[test]
fn each_grind_takes_the_surface_from_where_the_last_operation_left_it() {
    let plan = run();
    // v = pi d n: 25 m/s on the default 20 mm wheel.
    let spindle = (25.0 * 60_000.0 / (std::f64::consts::PI * 20.0)).round();
    let mut finished = 0;
    for (i, l) in layers(&plan).iter().enumerate() {
        let r = l["region"].as_u64().expect("region") as usize;
        let z = f(&l["z"]);
        let spray = one(l, "spray", None).expect("sprayed");
        let rough = one(l, "grind", Some("rough")).expect("rough ground");
        assert_eq!(f(&rough["tool"]["spindle"]), spindle, "layer {i}");
        assert_eq!(rough["levels"], true);
        let from = f(&spray["surface"]);
        assert!((value(rough, "from") - from).abs() < 1e-12, "layer {i}");
        let to = f(&rough["surface"]);
        assert!((to - (z + FINISH[r])).abs() < 1e-9, "layer {i}: rough to {to}");
        assert!((value(rough, "removed") - (from - to)).abs() < 1e-12, "layer {i}");
        // The wheel's centre runs in lines half its diameter apart (the default
        // stepover), centred on the area.
        let ys = pass_ys(rough);
        assert!(ys.len() >= 2, "layer {i}: {ys:?}");
        assert!(
            ys.windows(2).all(|w| (w[1] - w[0] - 10.0).abs() < 1e-9),
            "layer {i}: {ys:?}"
        );
        assert!((ys[0] + ys[ys.len() - 1]).abs() < 1e-9, "layer {i}: {ys:?}");
        match one(l, "grind", Some("finish")) {
            Some(finish) => {
                assert!(FINISH[r] > 0.0, "layer {i}: a finish grind without an allowance");
                // After the fill, which leaves the surface where the rough grind did.
                assert!((value(finish, "from") - to).abs() < 1e-12, "layer {i}");
                assert!((f(&finish["surface"]) - z).abs() < 1e-12, "layer {i}");
                assert!((value(finish, "removed") - FINISH[r]).abs() < 1e-9, "layer {i}");
                finished += 1;
            }
            None => assert_eq!(FINISH[r], 0.0, "layer {i}: no finish grind"),
        }
    }
    assert!(finished >= 5, "{finished}");
}

#[test]
fn the_end_mill_cuts_as_deep_as_the_highest_neighbour_stands_above_the_base() {
    let plan = run();
    // Each region's surface before each layer: the top of its last layer.
    let mut now: [Option<f64>; 3] = [None; 3];
    let (mut milled, mut second) = (0, false);
    for (i, l) in layers(&plan).iter().enumerate() {
        let r = l["region"].as_u64().expect("region") as usize;
        let (z, t) = (f(&l["z"]), f(&l["thickness"]));
        let base = z - t;
        // Every other region standing above the base; the mill cuts along those that
        // adjoin this one.
        let higher: Vec<usize> = (0..3)
            .filter(|&q| q != r && now[q].is_some_and(|s| s > base + 1e-9))
            .collect();
        let beside = higher.iter().any(|&q| q.abs_diff(r) == 1);
        match one(l, "end-mill", None) {
            Some(op) => {
                assert!(beside, "layer {i}: milled with nothing higher beside it");
                let top = higher
                    .iter()
                    .filter_map(|&q| now[q])
                    .fold(f64::NEG_INFINITY, f64::max);
                assert!((value(op, "depth") - (top - base)).abs() < 1e-9, "layer {i}");
                assert_eq!(value(op, "regions_higher"), higher.len() as f64, "layer {i}");
                let paths = op["paths"].as_array().expect("paths");
                assert!(
                    paths.iter().all(|p| (f(&p["z"]) - base).abs() < 1e-9),
                    "layer {i}"
                );
                // Two passes along each side: a cutter radius in (0.4 mm), then a
                // stepover of half the diameter further; the 1 mm outer tube has room
                // for the first only.
                let (ri, ro) = RADII[r];
                let at = [ri + 0.4, ri + 0.8, ro - 0.4, ro - 0.8];
                for p in paths {
                    for q in p["points"].as_array().expect("points") {
                        let rho = f(&q[0]).hypot(f(&q[1]));
                        let k = at.iter().position(|a| (rho - a).abs() < 0.01);
                        assert!(k.is_some(), "layer {i}: the mill at radius {rho}, not {at:?}");
                        second |= matches!(k, Some(1 | 3));
                    }
                }
                milled += 1;
            }
            None => assert!(!beside, "layer {i}: not milled beside {higher:?}"),
        }
        now[r] = Some(z);
    }
    assert!(milled >= 3 && second, "{milled} {second}");
}

/// The area of the engraved voids at height `z`, counted independently: the sections of
/// the spheres of radius 0.25 mm at the lattice points (i, j, 0.6 k) inside the inner
/// tube (radii 5 to 7 mm), sampled on a 0.01 mm grid, each section a 32-gon (its
/// area 32 sin(2 pi / 32) / (2 pi) of its circle's).
fn void_area_on_inner_tube(z: f64) -> f64 {
    let k = (z / 0.6).round();
    let r2 = 0.25f64.powi(2) - (z - 0.6 * k).powi(2);
    if r2 <= 0.0 {
        return 0.0;
    }
    let step = 0.01;
    let mut count = 0usize;
    for j in -700..=700 {
        for i in -700..=700 {
            let (x, y) = (f64::from(i) * step, f64::from(j) * step);
            let rho2 = x * x + y * y;
            if (25.0..=49.0).contains(&rho2) && (x - x.round()).powi(2) + (y - y.round()).powi(2) < r2 {
                count += 1;
            }
        }
    }
    let polygon = 32.0 * (2.0 * std::f64::consts::PI / 32.0).sin() / (2.0 * std::f64::consts::PI);
    count as f64 * step * step * polygon
}

#[test]
fn the_filler_fills_the_engraved_voids_and_is_removed_once_at_the_end() {
    let plan = run();
    let all = layers(&plan);
    let mut filled = 0;
    for (i, l) in all.iter().enumerate() {
        // Only the microstructure's layers are engraved and filled (`regions`).
        let inner = l["region"] == 0;
        match (one(l, "engrave", None), one(l, "fill", None)) {
            (Some(_), _) | (_, Some(_)) if !inner => panic!("layer {i}: engraved or filled outside `inner`"),
            (Some(engraved), Some(fill)) => {
                assert_eq!(value(fill, "voids"), value(engraved, "voids"), "layer {i}");
                // The laser stays on the inner tube (radii 5 to 7 mm): voids its
                // boundary cuts are burnt only where they lie inside it.
                for p in engraved["paths"].as_array().expect("paths") {
                    for q in p["points"].as_array().expect("points") {
                        let rho = f(&q[0]).hypot(f(&q[1]));
                        assert!((5.0..=7.0).contains(&rho), "layer {i}: the laser at radius {rho}");
                    }
                }
                let volume = value(engraved, "void_area") * value(engraved, "depth");
                assert!(volume > 0.0);
                // The voids are the spheres' sections (32-gons) where the inner tube
                // holds them, those its boundary cuts included.
                let mid = f(&l["z"]) - f(&l["thickness"]) / 2.0;
                let (want, got) = (void_area_on_inner_tube(mid), value(engraved, "void_area"));
                assert!(
                    (got - want).abs() < 0.002 * want,
                    "layer {i}: void area {got} against {want}"
                );
                assert!((value(fill, "void_volume") - volume).abs() < 1e-12, "layer {i}");
                // The filler lies on the surface the rough grind left.
                let surface = f(&one(l, "grind", Some("rough")).expect("ground")["surface"]);
                let paths = fill["paths"].as_array().expect("paths");
                assert!(!paths.is_empty(), "layer {i}");
                assert!(paths.iter().all(|p| (f(&p["z"]) - surface).abs() < 1e-12));
                filled += 1;
            }
            (None, None) => {}
            (e, _) => panic!("layer {i}: engraved {} but filled otherwise", e.is_some()),
        }
        let removal = one(l, "remove-filler", None);
        if i + 1 == all.len() {
            let op = removal.expect("the filler removed at the end");
            assert_eq!(op["pass"], "melt-out");
            assert_eq!(value(op, "temperature"), 300.0);
        } else {
            assert!(removal.is_none(), "layer {i}: the filler removed before the end");
        }
    }
    assert!(filled >= 2, "{filled}");
}

/// The laser on the microstructure's layers (default spot 0.05 mm, 20 % overlap, 0.1 mm
/// a pass): rings 0.04 mm apart from half a spot inside each void, repeated pass by
/// pass, each pass focused on the floor it leaves, from the surface the rough grind
/// left down to the layer's bottom.
#[test]
fn the_laser_burns_rings_a_step_apart_in_passes_down_to_the_layers_bottom() {
    let plan = run();
    let mut engraved = 0;
    for (i, l) in layers(&plan).iter().enumerate() {
        let Some(op) = one(l, "engrave", None) else {
            continue;
        };
        let (z, t) = (f(&l["z"]), f(&l["thickness"]));
        let surface = f(&one(l, "grind", Some("rough")).expect("ground")["surface"]);
        let depth = value(op, "depth");
        assert!(
            (depth - (surface - (z - t))).abs() < 1e-12,
            "layer {i}: depth {depth}"
        );
        let passes = value(op, "passes");
        assert_eq!(passes, (depth / 0.1 - 1e-9).ceil(), "layer {i}");
        let paths = op["paths"].as_array().expect("paths");
        let per_pass = paths.len() / passes as usize;
        assert_eq!(per_pass * passes as usize, paths.len(), "layer {i}");
        for (k, pass) in paths.chunks(per_pass).enumerate() {
            let want = surface - depth * (k + 1) as f64 / passes;
            for (m, p) in pass.iter().enumerate() {
                assert!(
                    (f(&p["z"]) - want).abs() <= 0.5e-3 + 1e-12,
                    "layer {i}: pass {k} at {}",
                    p["z"]
                );
                // Each pass burns the first pass's rings again, in the same order.
                assert_eq!(p["points"], paths[m]["points"], "layer {i}: pass {k}, ring {m}");
            }
        }
        // The rings of the whole voids (the first pass's, by the lattice point they
        // surround): regular 32-gons whose apothems step in by 0.04 mm from half a spot
        // inside the section's, then possibly one at the deepest inset.
        let mid = z - t / 2.0;
        let r = (0.25f64.powi(2) - (mid - 0.6 * (mid / 0.6).round()).powi(2)).sqrt();
        let section = r * (std::f64::consts::PI / 32.0).cos();
        let mut by_void: std::collections::BTreeMap<(i64, i64), Vec<f64>> = Default::default();
        for p in &paths[..per_pass] {
            let pts = points(p);
            let n = pts.len() as f64;
            let (cx, cy) = pts
                .iter()
                .fold((0.0, 0.0), |(a, b), q| (a + q.0 / n, b + q.1 / n));
            let rho = cx.hypot(cy);
            if pts.len() != 32 || rho < 5.0 + r || rho > 7.0 - r {
                continue;
            }
            let area = pts
                .iter()
                .zip(pts.iter().cycle().skip(1))
                .map(|(a, b)| a.0 * b.1 - b.0 * a.1)
                .sum::<f64>()
                .abs()
                / 2.0;
            let apothem = (area / (32.0 * (std::f64::consts::PI / 32.0).tan())).sqrt();
            by_void
                .entry((cx.round() as i64, cy.round() as i64))
                .or_default()
                .push(apothem);
        }
        assert!(by_void.len() > 10, "layer {i}: {} whole voids", by_void.len());
        for (at, mut apothems) in by_void {
            apothems.sort_by(|a, b| b.total_cmp(a));
            let steps = ((section - 0.025) / 0.04).floor() as usize + 1;
            assert!(
                apothems.len() == steps || apothems.len() == steps + 1,
                "{at:?}: {apothems:?}"
            );
            for (k, a) in apothems.iter().take(steps).enumerate() {
                let want = section - 0.025 - 0.04 * k as f64;
                assert!(
                    (a - want).abs() < 1e-6,
                    "{at:?}: ring {k} apothem {a}, not {want}"
                );
            }
        }
        engraved += 1;
    }
    assert!(engraved >= 2, "{engraved}");
}

/// A 3 x 3 x 0.6 mm block with a void of radius 0.25 mm at (0.5 + i, 0.5 + j, 0.6 k),
/// sliced every 0.15 mm and engraved by the `laser` given (spot and overlap) 0.075 mm
/// a pass: 9 whole voids on each layer, none cut by the block's sides.
fn lattice_block(limits: &str, laser: &str) -> Result<Value, String> {
    let pipeline = format!(
        r#"
name = "lattice"
{limits}
[materials.microstructure]
colour = [70, 130, 180]

[[parts]]
name = "block"
materials = ["microstructure"]
[parts.model]
use = "box"
size = [3.0, 3.0, 0.6]

[slice]
use = "uniform"
thickness = 0.15

[[process]]
use = "engrave"
period = [1.0, 1.0, 0.6]
origin = [0.5, 0.5, 0.0]
void_radius = 0.25
{laser}
depth_per_pass = 0.075

[[output]]
use = "json"
path = "lattice.json"
"#
    );
    lamina_test_support::try_run_pipeline(&pipeline)
        .map(|run| run.json("lattice.json"))
        .map_err(|e| e.to_string())
}

/// Each layer is burnt in as many passes as its depth holds `depth_per_pass`, no more
/// where it holds them exactly (0.15 mm in passes of 0.075 mm: 2). A void narrower
/// than the spot gets no ring, and the layer says how many of its voids did not: at
/// mid-heights 0.075 and 0.525 mm the sections are 0.2385 mm in radius and take a
/// ring, at 0.225 and 0.375 mm they are 0.109 mm in radius, under half the 0.25 mm
/// spot.
#[test]
fn the_laser_takes_as_many_passes_as_the_depth_holds_and_names_the_voids_it_cannot_enter() {
    // A 0.25 mm spot, rings 0.2 mm apart.
    let plan = lattice_block("", "diameter = 0.25").expect("the block runs");
    let narrow: Vec<Vec<String>> = layers(&plan)
        .iter()
        .map(|l| {
            l["diagnostics"]
                .as_array()
                .into_iter()
                .flatten()
                .filter(|d| d["code"] == "voids-narrower-than-spot")
                .map(|d| d["message"].as_str().expect("a message").to_string())
                .collect()
        })
        .collect();
    let said = "engrave: 9 of 9 voids are narrower than the 0.25 mm laser spot and get no ring";
    assert_eq!(
        narrow,
        [vec![], vec![said.to_string()], vec![said.to_string()], vec![]]
    );
    for (i, l) in layers(&plan).iter().enumerate() {
        let op = one(l, "engrave", None).expect("engraved");
        assert_eq!(value(op, "voids"), 9.0, "layer {i}");
        assert_eq!(value(op, "passes"), 2.0, "layer {i}");
        let rings = if narrow[i].is_empty() { 9 } else { 0 };
        assert_eq!(op["paths"].as_array().map_or(0, Vec::len), 2 * rings, "layer {i}");
    }
}

/// The rings a layer may take are counted before any is made, against `grid_samples`:
/// up to half a void's smaller width over the step, plus one, for each void, then for
/// every pass. On the block's first layer with a 0.02 mm spot rings 0.01 mm apart,
/// the sections are 32-gons 0.477 mm across: ceil(0.477 / 2 / 0.01) + 1 = 25 rings for
/// each of 9 voids (225), in 2 passes (450). (The lattice points near a layer, 100,
/// are counted first.)
#[test]
fn the_rings_are_counted_against_the_limit_before_they_are_made() {
    let block = |n: u32| {
        lattice_block(
            &format!("[limits]\ngrid_samples = {n}\n"),
            "diameter = 0.02\noverlap = 0.5",
        )
    };
    let plan = block(450).expect("450 rings allowed");
    let first = one(&layers(&plan)[0], "engrave", None).expect("engraved");
    let burnt = first["paths"].as_array().map_or(0, Vec::len);
    assert!((400..=450).contains(&burnt), "{burnt}");
    let err = block(449).expect_err("450 rings over 449");
    assert!(
        err.contains("laser rings in 2 passes") && err.contains("needs 450"),
        "{err}"
    );
    let err = block(224).expect_err("225 rings over 224");
    assert!(
        err.contains("laser rings 0.01 mm apart") && err.contains("needs 225"),
        "{err}"
    );
}

/// Three parts on every layer: a tube graded across its width (each of its three rings
/// a mix of its own), a tube of bronze and metal graded all bronze, and a tube of
/// bronze alone (the same material, but another mix for the gun's feeders: one
/// operation each). Only sprayed.
const MIXES: &str = r#"
name = "mixes"

[materials.ceramic]
colour = [240, 240, 230]
[materials.metal]
colour = [90, 90, 100]
[materials.bronze]
colour = [200, 120, 50]

[[parts]]
name = "graded"
materials = ["ceramic", "metal"]
[parts.model]
use = "tube"
outer_radius = 9.0
inner_radius = 6.0
height = 1.0
[parts.grade]
use = "script"
f = "(sqrt(x * x + y * y) - 6.0) / 3.0"
[parts.discretise]
use = "offset"
count = 3

[[parts]]
name = "tinted"
materials = ["bronze", "metal"]
[parts.model]
use = "tube"
outer_radius = 4.0
inner_radius = 3.0
height = 1.0
[parts.grade]
use = "script"
f = "1.0"

[[parts]]
name = "bronze"
materials = ["bronze"]
[parts.model]
use = "tube"
outer_radius = 2.0
inner_radius = 1.0
height = 1.0

[slice]
use = "uniform"
thickness = 0.5

[[process]]
use = "spray"
diameter = 0.4
overlap = 0.0

[[output]]
use = "json"
path = "mixes.json"
"#;

/// The `fraction:` values of an operation, by material.
fn fractions(op: &Value) -> Vec<(String, f64)> {
    op["values"]
        .as_object()
        .expect("values")
        .iter()
        .filter_map(|(k, v)| k.strip_prefix("fraction:").map(|m| (m.to_string(), f(v))))
        .collect()
}

#[test]
fn the_gun_sprays_each_mix_of_the_layer_in_one_operation_over_its_own_area() {
    let plan = lamina_test_support::run_pipeline(MIXES).json("mixes.json");
    for (i, l) in layers(&plan).iter().enumerate() {
        let sprays: Vec<&Value> = ops(l).into_iter().filter(|o| o["kind"] == "spray").collect();
        // Three rings of three mixes, the tinted tube's area, the bronze tube's.
        assert_eq!(sprays.len(), 5, "layer {i}");
        let mut graded = Vec::new();
        for op in &sprays {
            let mix = fractions(op);
            // Where the passes run: the radii of their points (the tubes' circles are
            // polygons, whose edges pass a few um inside the circles' radii).
            let radii: Vec<f64> = op["paths"]
                .as_array()
                .expect("paths")
                .iter()
                .flat_map(|p| p["points"].as_array().expect("points").iter())
                .map(|p| f(&p[0]).hypot(f(&p[1])))
                .collect();
            assert!(!radii.is_empty(), "layer {i}: {mix:?} not sprayed");
            let (lo, hi) = radii
                .iter()
                .fold((f64::INFINITY, 0.0f64), |(a, b), &r| (a.min(r), b.max(r)));
            let of = |m: &str| mix.iter().find(|(n, _)| n == m).map(|(_, v)| *v);
            match (mix.len(), of("bronze")) {
                // Bronze alone, over its tube.
                (1, Some(b)) => {
                    assert_eq!(b, 1.0, "layer {i}");
                    assert!(lo >= 1.0 - 0.01 && hi <= 2.0 + 0.01, "layer {i}: {lo}-{hi}");
                }
                // Bronze and no metal, over the tinted tube.
                (2, Some(b)) => {
                    assert_eq!((b, of("metal")), (1.0, Some(0.0)), "layer {i}");
                    assert!(lo >= 3.0 - 0.01 && hi <= 4.0 + 0.01, "layer {i}: {lo}-{hi}");
                }
                _ => {
                    let ceramic = of("ceramic").expect("ceramic");
                    let sum: f64 = mix.iter().map(|(_, v)| v).sum();
                    assert!((sum - 1.0).abs() < 1e-9, "layer {i}: {mix:?}");
                    // The grade rises with the radius, one ring a third of the way each.
                    assert!(lo >= 6.0 - 0.01 && hi <= 9.0 + 0.01, "layer {i}: {lo}-{hi}");
                    graded.push((ceramic, lo, hi));
                }
            }
        }
        graded.sort_by(|a, b| a.1.total_cmp(&b.1));
        assert_eq!(graded.len(), 3, "layer {i}: {graded:?}");
        for (k, (ceramic, lo, hi)) in graded.iter().enumerate() {
            // Ring k spans radii 6 + k .. 7 + k; its mix is read at a point inside it.
            let (r0, r1) = (6.0 + k as f64, 7.0 + k as f64);
            assert!(
                *lo >= r0 - 0.01 && *hi <= r1 + 0.01,
                "layer {i}, ring {k}: {lo}-{hi}"
            );
            let f0 = (r0 - 6.0) / 3.0;
            assert!(
                *ceramic > f0 && *ceramic < f0 + 1.0 / 3.0,
                "layer {i}, ring {k}: {ceramic}"
            );
        }
    }
}

/// Builds the process stage a table names; the error's text if it is refused.
fn process_stage(table: &str) -> Result<(), String> {
    stage(lamina_api::StageKind::Process, table)
}

/// A stage of `kind` built from `table`, or the error's text.
fn stage(kind: lamina_api::StageKind, table: &str) -> Result<(), String> {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    lamina_test_support::try_stage(kind, table, dir)
        .map(|_| ())
        .map_err(|e| e.to_string())
}

/// The engraver's table refused where its voids would meet or its spot is wider than
/// a void, naming the key; the limits themselves allowed.
#[test]
fn the_engraver_refuses_voids_that_meet_and_a_spot_wider_than_a_void() {
    let build =
        |options: &str| process_stage(&format!("use = \"engrave\"\nperiod = [1.0, 0.8, 0.6]\n{options}"));
    // Half the smallest period (0.6 mm) at most.
    assert_eq!(build("void_radius = 0.3"), Ok(()));
    let err = build("void_radius = 0.31").expect_err("voids that meet");
    assert!(err.contains("void_radius") && err.contains("(0.3 mm)"), "{err}");
    // A spot no wider than the void's radius.
    assert_eq!(build("void_radius = 0.25\ndiameter = 0.25"), Ok(()));
    let err = build("void_radius = 0.25\ndiameter = 0.26").expect_err("a spot too wide");
    assert!(
        err.contains("diameter") && err.contains("smaller than the void"),
        "{err}"
    );
    // Every spacing a positive length, by the option's range.
    let err = process_stage("use = \"engrave\"\nperiod = [1.0, 0.0, 0.6]").expect_err("a zero spacing");
    assert!(err.contains("period"), "{err}");
    // Rings that cover each other wholly are refused, below that allowed.
    assert_eq!(build("void_radius = 0.25\noverlap = 0.89"), Ok(()));
    let err = build("void_radius = 0.25\noverlap = 0.9").expect_err("overlap 0.9");
    assert!(err.contains("overlap") && err.contains("below 0.9"), "{err}");
    // Spheres or a base cell, not both.
    let err =
        build("void_radius = 0.25\nbase_cell = { shape = \"sphere\", size = 0.5, period = [1.0, 1.0, 1.0] }")
            .expect_err("both");
    assert!(
        err.contains("void_radius") && err.contains("give either"),
        "{err}"
    );
}

/// The spray's inclusions and track overlap refused by key where a feeder could not
/// follow them; the limits themselves allowed.
#[test]
fn the_spray_refuses_inclusions_beyond_the_whole_and_tracks_wholly_over_each_other() {
    let build = |options: &str| process_stage(&format!("use = \"spray\"\n{options}"));
    assert_eq!(build("inclusions = { outer = { SiC = 0.5, WC = 0.5 } }"), Ok(()));
    for bad in [
        "inclusions = { outer = { SiC = 0.6, WC = 0.6 } }",
        "inclusions = { outer = { SiC = inf } }",
        "inclusions = { outer = { SiC = nan } }",
        "inclusions = { outer = { SiC = -0.1 } }",
    ] {
        let err = build(bad).expect_err(bad);
        assert!(
            err.contains("inclusions") && err.contains("sum to at most 1"),
            "{bad}: {err}"
        );
    }
    assert_eq!(build("overlap = 0.89"), Ok(()));
    let err = build("overlap = 0.9").expect_err("overlap 0.9");
    assert!(err.contains("overlap") && err.contains("below 0.9"), "{err}");
}

/// The NC program of the pipe read back by `tests/replay/nc_replay.py` (pygcode, a
/// third-party RS-274 parser, and LinuxCNC's semantics) on the `cmpm-hybrid` machine,
/// as a machinist's controller would run it:
/// - no violation (among them: no tool change away from the safe height, no rapid of a
///   cutter or the filler below a surface worked, no tool off crawling over the part);
/// - no move to where the tool is, no plunge of a cutter, the laser never up and down
///   again within an engraving, a tool change for each new tool of the plan's order
///   and an operator's stop for each operation without a tool (the filler's melt-out);
/// - each tool working the length its operations plan (the mill and the wheel more:
///   ramps, and a wheel running on past the part);
/// - each tool's lowest height on each layer where the plan puts it (the gun and the
///   filler nozzle their standoffs above the surface, the laser's last pass on the
///   layer's bottom);
/// - the feeders set, when the gun opens, to the layer's mix with its inclusions;
/// - the program's own cycle-time estimate within 5 % of the replay's.
#[test]
fn the_nc_program_runs_each_operation_of_the_plan_on_the_machine() {
    let probe = std::process::Command::new("python3")
        .args(["-c", "import pygcode, tomllib"])
        .output();
    if !probe.is_ok_and(|o| o.status.success()) {
        lamina_test_support::skip("the pygcode Python package is not installed");
        return;
    }
    // The machine's gun is 3 mm wide.
    let pipe = PIPE.replace("diameter = 2.0", "diameter = 3.0");
    assert_ne!(pipe, PIPE);
    let run = lamina_test_support::run_pipeline(&format!(
        "{pipe}\n[[output]]\nuse = \"nc\"\npath = \"pipe.nc\"\nmachine = \"cmpm-hybrid\"\n"
    ));
    let plan = run.json("pipe.json");
    let program = run.file("pipe.nc");
    let replay = crate_dir().join("../../tests/replay/nc_replay.py");
    let nc = std::env::temp_dir().join(format!("lamina-process-{}.nc", std::process::id()));
    std::fs::write(&nc, &program).expect("the program written");
    let out = std::process::Command::new("python3")
        .arg(&replay)
        .arg(&nc)
        .arg("--machine")
        .arg(crate_dir().join("machines/cmpm-hybrid.toml"))
        .output()
        .expect("python3 runs");
    let _ = std::fs::remove_file(&nc);
    let report: Value = serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(&out.stderr)));
    assert!(out.status.success(), "violations: {}", report["violations"]);
    // The replay knows every kind of tool the machine has.
    let help = std::process::Command::new("python3")
        .arg(&replay)
        .arg("--help")
        .output()
        .expect("python3 runs");
    let help = String::from_utf8_lossy(&help.stdout);
    assert!(
        help.contains("dispenser, end-mill, grinding-wheel, laser, spray"),
        "{help}"
    );
    program_runs_as_planned(&plan, &report, &String::from_utf8_lossy(&program));
    each_tool_works_its_paths(&plan, &report);
}

fn crate_dir() -> &'static std::path::Path {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// The counts, the estimate and each layer's lowest heights of the replay's `report`
/// against the `plan` and the `program`'s header.
fn program_runs_as_planned(plan: &Value, report: &Value, program: &str) {
    assert_eq!(report["noop_moves"], 0, "moves to where the tool is");
    assert_eq!(report["plunges"], 0, "plunges");
    assert_eq!(report["laser_z_cycles"], 0, "the laser up and down again");
    // One tool change wherever the plan's next tool is another; one stop for the
    // operator wherever an operation has no tool.
    let (mut changes, mut stops, mut loaded) = (0, 0, None);
    for l in layers(plan) {
        for op in ops(l) {
            match op["tool"]["name"].as_str() {
                None => stops += 1,
                Some(name) if loaded != Some(name) && !op["paths"].as_array().expect("paths").is_empty() => {
                    changes += 1;
                    loaded = Some(name);
                }
                Some(_) => {}
            }
        }
    }
    assert!(changes > 20 && stops == 1, "{changes} changes, {stops} stops");
    assert_eq!(report["tool_changes"], changes);
    assert_eq!(report["tool_changes_at_safe_height"], changes);
    assert_eq!(report["pauses"], stops);
    // The program's own estimate against the replay's.
    let header = program
        .lines()
        .find_map(|l| l.strip_prefix("(estimated cycle time "))
        .expect("an estimate in the header");
    let own: f64 = header
        .split_whitespace()
        .next()
        .and_then(|w| w.parse().ok())
        .unwrap_or_else(|| panic!("no seconds in {header}"));
    let replayed = f(&report["time"]);
    assert!(
        (own - replayed).abs() <= 0.05 * replayed,
        "{own} s by the program, {replayed} s by the replay"
    );
    // Each tool's lowest height on each layer: where its paths lie, the gun its
    // standoff (80 mm) and the filler's nozzle its own (1 mm) above them.
    let kinds = [
        ("end-mill", "end-mill", 0.0),
        ("spray", "spray", 80.0),
        ("grind", "grinding-wheel", 0.0),
        ("engrave", "laser", 0.0),
        ("fill", "dispenser", 1.0),
    ];
    let replayed = report["layers"].as_array().expect("layers");
    assert_eq!(replayed.len(), layers(plan).len());
    for (i, (l, r)) in layers(plan).iter().zip(replayed).enumerate() {
        let lowest = r["lowest"].as_object().expect("lowest");
        let mut want = serde_json::Map::new();
        for (kind, tool, standoff) in kinds {
            let low = ops(l)
                .into_iter()
                .filter(|o| o["kind"] == kind)
                .flat_map(|o| o["paths"].as_array().expect("paths"))
                .map(|p| f(&p["z"]) + standoff)
                .fold(f64::INFINITY, f64::min);
            if low.is_finite() {
                want.insert(tool.into(), low.into());
            }
        }
        assert_eq!(
            lowest.keys().collect::<Vec<_>>(),
            want.keys().collect::<Vec<_>>(),
            "layer {i}"
        );
        for (tool, z) in &want {
            let got = f(&lowest[tool]);
            assert!(
                (got - f(z)).abs() <= 0.5e-3 + 1e-9,
                "layer {i}: the {tool} down to {got}, its paths at {z}"
            );
        }
    }
}

/// Each tool's worked length in the replay's `report` against its paths in the `plan`,
/// and the feeders' mix when the gun opens against each layer's.
fn each_tool_works_its_paths(plan: &Value, report: &Value) {
    // Planned lengths by tool number (the machine's: end mill 1, gun 2, wheel 3,
    // laser 4, filler 5).
    let numbers = ["end-mill", "spray-gun", "cup-wheel", "laser", "filler"];
    let mut planned = [0.0f64; 5];
    for l in layers(plan) {
        for op in ops(l) {
            let Some(name) = op["tool"]["name"].as_str() else {
                continue;
            };
            let n = numbers
                .iter()
                .position(|t| *t == name)
                .expect("a tool of the machine");
            for p in op["paths"].as_array().expect("paths") {
                let pts = points(p);
                let closing = if p["closed"] == true && pts.len() > 2 {
                    1
                } else {
                    0
                };
                planned[n] += (0..pts.len() - 1 + closing)
                    .map(|k| {
                        let (a, b) = (pts[k], pts[(k + 1) % pts.len()]);
                        (b.0 - a.0).hypot(b.1 - a.1)
                    })
                    .sum::<f64>();
            }
        }
    }
    for (i, want) in planned.iter().enumerate() {
        let got = f(&report["lengths"][(i + 1).to_string()]);
        assert!(*want > 0.0, "{}: nothing planned", numbers[i]);
        if i == 0 || i == 2 {
            assert!(
                got >= want - 1e-3,
                "{}: {got} mm worked, {want} planned",
                numbers[i]
            );
        } else {
            assert!(
                (got - want).abs() <= 1e-3 * want,
                "{}: {got} mm worked, {want} planned",
                numbers[i]
            );
        }
    }
    // The feeders when the gun opens: the layer's mix, the composite's a fifth SiC.
    let replayed = report["layers"].as_array().expect("layers");
    assert_eq!(replayed.len(), layers(plan).len());
    for (i, (l, r)) in layers(plan).iter().zip(replayed).enumerate() {
        let sprays = r["sprays"].as_array().expect("sprays");
        let op = one(l, "spray", None).expect("sprayed");
        assert_eq!(sprays.len(), 1, "layer {i}: {sprays:?}");
        let inclusion = op["values"].get("inclusion:SiC").map_or(0.0, f);
        for (m, v) in fractions(op) {
            let read = f(&sprays[0][m.as_str()]);
            assert!(
                (read - v * (1.0 - inclusion)).abs() <= 0.01,
                "layer {i}, {m}: {read} read, {v} planned"
            );
        }
        assert!((f(&sprays[0]["SiC"]) - inclusion).abs() <= 0.01, "layer {i}");
    }
}

/// The NC exporter's table refused by key where its heights or tool numbers cannot
/// make a program; the limits themselves allowed.
#[test]
fn the_nc_exporter_refuses_an_approach_over_the_clearance_and_tool_numbers_that_clash() {
    let build = |options: &str| {
        stage(
            lamina_api::StageKind::Export,
            &format!("use = \"nc\"\npath = \"job.nc\"\n{options}"),
        )
    };
    assert_eq!(build("clearance = 2.0\napproach = 2.0"), Ok(()));
    let err = build("clearance = 2.0\napproach = 2.5").expect_err("approach over clearance");
    assert!(
        err.contains("approach") && err.contains("at most `clearance`"),
        "{err}"
    );
    for plunge in ["0.0", "1.5", "nan", "inf"] {
        let err = build(&format!("plunge = {plunge}")).expect_err("plunge out of range");
        assert!(err.contains("plunge"), "{err}");
    }
    assert_eq!(build("plunge = 1.0"), Ok(()));
    assert_eq!(build("tools = { mill = 1, wheel = 2 }"), Ok(()));
    let err = build("tools = { mill = 0 }").expect_err("tool number 0");
    assert!(
        err.contains("tools") && err.contains("`mill`: tool numbers start at 1"),
        "{err}"
    );
    let err = build("tools = { mill = 3, wheel = 3 }").expect_err("one number twice");
    assert!(err.contains("both have number 3"), "{err}");
    let err = build("machine = \"cmpm-hybrid\"\ntools = { mill = 1 }").expect_err("both");
    assert!(err.contains("not both"), "{err}");
}
