//! The CMPM hybrid process end to end on the pipe of Fig. 11 (cmpm-process-planning
//! §2 and 4.1): every layer of every work cycle is end-milled where a higher region
//! adjoins, sprayed with allowances, ground, engraved and filled where it is a
//! microstructure, and ground to height. The NC program is read back by a third-party
//! G-code parser (pygcode, `tests/replay/nc_replay.py`) in the process crate's own
//! tests (`plugins/process/tests/operations.rs`), where each method it checks lives.
//!
//! The pipe is three concentric tubes: the microstructure `inner` (radii 5 to 7), the
//! FGM `middle` (7 to 9) and the composite `outer` (9 to 10), so where each machining
//! path must lie is known in closed form.

use std::collections::BTreeMap;
use std::path::Path;

use serde_json::Value;

use crate::support::{pipelines, run_plan, text, try_run_text};

fn run_pipe(out: &Path) -> Value {
    run_plan(
        &pipelines().join("pipe-work-cycles.toml"),
        out,
        &[],
        "pipe-work-cycles.json",
    )
}

/// Radii of each region (inner, middle, outer).
const RADII: [(f64, f64); 3] = [(5.0, 7.0), (7.0, 9.0), (9.0, 10.0)];

fn ops(layer: &Value) -> Vec<&Value> {
    layer["operations"]
        .as_array()
        .map(|a| a.iter().collect())
        .unwrap_or_default()
}

fn label(op: &Value) -> String {
    match op["pass"].as_str() {
        Some(p) if op["kind"] == "grind" => format!("grind/{p}"),
        _ => op["kind"].as_str().expect("kind").to_string(),
    }
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

fn points(path: &Value) -> Vec<[f64; 2]> {
    path["points"]
        .as_array()
        .expect("points")
        .iter()
        .map(|p| [f(&p[0]), f(&p[1])])
        .collect()
}

fn radius(p: [f64; 2]) -> f64 {
    p[0].hypot(p[1])
}

/// The design surface of every region before each layer: the top of its last layer.
fn design_surfaces(layers: &[Value], regions: usize) -> Vec<Vec<Option<f64>>> {
    let mut now = vec![None; regions];
    let mut out = Vec::new();
    for l in layers {
        out.push(now.clone());
        now[l["region"].as_u64().expect("region") as usize] = Some(f(&l["z"]));
    }
    out
}

#[test]
fn each_step_of_the_18_step_cycle_runs_the_operations_of_section_2_in_order() {
    let dir = tempfile::tempdir().expect("tempdir");
    let plan = run_pipe(dir.path());
    let block = &plan["sequence"]["blocks"][0];
    let cycle: Vec<u64> = block["cycle"]["steps"]
        .as_array()
        .expect("steps")
        .iter()
        .map(|s| s["height_um"].as_u64().expect("height"))
        .collect();
    assert_eq!(
        cycle,
        [
            200, 400, 500, 600, 800, 1000, 1200, 1400, 1500, 1600, 1800, 2000, 2200, 2400, 2500, 2600, 2800,
            3000
        ]
    );
    let layers = plan["layers"].as_array().expect("layers");
    let surfaces = design_surfaces(layers, 3);
    let adjoining = |a: usize, b: usize| a.abs_diff(b) == 1;
    let mut milled = 0;
    for (i, l) in layers.iter().enumerate() {
        let r = l["region"].as_u64().expect("region") as usize;
        let (z, t) = (f(&l["z"]), f(&l["thickness"]));
        let labels: Vec<String> = ops(l).iter().map(|o| label(o)).collect();
        // Step 1 exactly where an adjoining region stands above this layer's base.
        let higher = (0..3).any(|q| adjoining(q, r) && surfaces[i][q].is_some_and(|s| s > z - t + 1e-9));
        let mut want: Vec<&str> = Vec::new();
        if higher {
            want.push("end-mill");
            milled += 1;
        }
        want.extend(["spray", "grind/rough"]);
        if r == 0 {
            // The microstructure: voids engraved and filled where the lattice meets the
            // layer's plane (spheres of 0.25 mm every 0.6 mm in z), then the finish grind.
            let cut = z - t / 2.0;
            let k = (cut / 0.6).round();
            if (cut - 0.6 * k).abs() < 0.25 {
                want.extend(["engrave", "fill"]);
            }
            want.push("grind/finish");
        }
        // Step 7 repeats from step 1: the filler stays in the voids, nothing melts it out.
        assert_eq!(labels, want, "layer {i} (region {r}, z {z})");
        for o in ops(l) {
            assert_eq!(o["region"].as_u64(), Some(r as u64), "layer {i}: {o}");
        }
    }
    assert!(milled >= 10, "only {milled} layers were milled");
}

#[test]
fn every_regions_surface_is_sprayed_high_ground_back_and_ends_at_its_design_height() {
    let dir = tempfile::tempdir().expect("tempdir");
    let plan = run_pipe(dir.path());
    let layers = plan["layers"].as_array().expect("layers");
    let rough = 0.1;
    let finish = [0.02, 0.0, 0.0];
    let mut top: [Option<f64>; 3] = [None; 3];
    let mut trace: Vec<Vec<f64>> = vec![Vec::new(); 3];
    for (i, l) in layers.iter().enumerate() {
        let r = l["region"].as_u64().expect("region") as usize;
        let z = f(&l["z"]);
        let mut heights = Vec::new();
        for o in ops(l) {
            let Some(s) = o["surface"].as_f64() else { continue };
            if o["levels"] == true {
                // The paper's rule: the surface to be ground stands higher than the others.
                for q in (0..3).filter(|&q| q != r) {
                    if let Some(h) = top[q] {
                        assert!(
                            h <= s + 1e-9,
                            "layer {i}: {} to {s} beside region {q} at {h}",
                            label(o)
                        );
                    }
                }
            }
            heights.push((label(o), s));
            top[r] = Some(s);
            trace[r].push(s);
        }
        let want: Vec<(String, f64)> = match r {
            0 => vec![
                ("spray".into(), z + rough + finish[0]),
                ("grind/rough".into(), z + finish[0]),
                ("grind/finish".into(), z),
            ],
            _ => vec![("spray".into(), z + rough), ("grind/rough".into(), z)],
        };
        assert_eq!(heights.len(), want.len(), "layer {i}: {heights:?}");
        for ((l1, h1), (l2, h2)) in heights.iter().zip(&want) {
            assert_eq!(l1, l2, "layer {i}");
            assert!((h1 - h2).abs() < 1e-9, "layer {i} {l1}: {h1} vs {h2}");
        }
        assert!(
            (top[r].expect("set") - z).abs() < 1e-9,
            "layer {i} ends at its height"
        );
    }
    // Through the whole block (6 mm, two cycles) each region ends at the design height.
    for (r, t) in top.iter().enumerate() {
        assert!(
            (t.expect("every region deposited") - 6.0).abs() < 1e-9,
            "region {r}: {t:?}"
        );
        assert!(trace[r].len() >= 4, "region {r}: {:?}", trace[r]);
    }
}

#[test]
fn machining_paths_keep_their_tools_radius_from_the_boundaries() {
    // A 4 mm wheel, so that covering the ring takes passes where they belong (the
    // pipe's own 20 mm wheel covers it from one line through the centre); the NC file
    // is left out, its machine has the 20 mm wheel.
    let dir = tempfile::tempdir().expect("tempdir");
    let pipe = std::fs::read_to_string(pipelines().join("pipe-work-cycles.toml")).expect("pipe");
    let small = pipe
        .replace("pass = \"rough\"\n", "pass = \"rough\"\ndiameter = 4.0\n")
        .replace("pass = \"finish\"\n", "pass = \"finish\"\ndiameter = 4.0\n")
        .replace("machine = \"cmpm-hybrid\"", "tools = { cup-wheel = 3 }");
    assert_eq!(small.matches("diameter = 4.0").count(), 2);
    let plan = crate::support::run_text(dir.path(), &small, "pipe-work-cycles.json");
    let layers = plan["layers"].as_array().expect("layers");
    let surfaces = design_surfaces(layers, 3);
    let (mut milled, mut ground, mut engraved) = (0, 0, 0);
    for (i, l) in layers.iter().enumerate() {
        let r = l["region"].as_u64().expect("region") as usize;
        let (z, t) = (f(&l["z"]), f(&l["thickness"]));
        let (ri, ro) = RADII[r];
        for o in ops(l) {
            let tool = &o["tool"];
            let paths = o["paths"].as_array().cloned().unwrap_or_default();
            match o["kind"].as_str().expect("kind") {
                "end-mill" => {
                    // Along the inner boundary only if the region inside stands higher,
                    // along the outer only if the one outside does; a cutter radius in.
                    let rad = f(&tool["diameter"]) / 2.0;
                    let inside_higher = r > 0 && surfaces[i][r - 1].is_some_and(|s| s > z - t + 1e-9);
                    let outside_higher = r < 2 && surfaces[i][r + 1].is_some_and(|s| s > z - t + 1e-9);
                    let (mut inner_side, mut outer_side) = (0.0, 0.0);
                    for p in &paths {
                        assert!(
                            (f(&p["z"]) - (z - t)).abs() < 1e-9,
                            "layer {i}: mills down to the base"
                        );
                        let pts = points(p);
                        for w in pts.windows(2) {
                            let d = (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]);
                            let rho = radius(w[0]);
                            if (rho - (ri + rad)).abs() < 0.01 {
                                inner_side += d;
                            } else if (rho - (ro - rad)).abs() < 0.01 {
                                outer_side += d;
                            } else {
                                panic!(
                                    "layer {i}: end-mill at radius {rho}, not {} or {}",
                                    ri + rad,
                                    ro - rad
                                );
                            }
                        }
                    }
                    let full = |radius: f64| 2.0 * std::f64::consts::PI * radius;
                    if inside_higher {
                        assert!(inner_side > 0.97 * full(ri + rad), "layer {i}: {inner_side}");
                    } else {
                        assert_eq!(inner_side, 0.0, "layer {i}: nothing higher inside");
                    }
                    if outside_higher {
                        assert!(outer_side > 0.97 * full(ro - rad), "layer {i}: {outer_side}");
                    } else {
                        assert_eq!(outer_side, 0.0, "layer {i}: nothing higher outside");
                    }
                    milled += 1;
                }
                "grind" => {
                    // The wheel's face passes over every point of the sprayed area.
                    let wheel = f(&tool["diameter"]) / 2.0;
                    let segments: Vec<([f64; 2], [f64; 2])> = paths
                        .iter()
                        .flat_map(|p| {
                            let pts = points(p);
                            pts.windows(2).map(|w| (w[0], w[1])).collect::<Vec<_>>()
                        })
                        .collect();
                    for k in 0..=20 {
                        let rho = ri + (ro - ri) * k as f64 / 20.0;
                        for a in 0..72 {
                            let phi = a as f64 * std::f64::consts::PI / 36.0;
                            let p = [rho * phi.cos(), rho * phi.sin()];
                            let near = segments.iter().any(|&(a, b)| segment_distance(p, a, b) <= wheel);
                            assert!(near, "layer {i}: {p:?} is not under the wheel");
                        }
                    }
                    ground += 1;
                }
                "engrave" => {
                    // Every ring inside a void of the lattice (period 1 x 1 x 0.6, radius
                    // 0.25) cut at mid-layer, half a spot in, and inside the region.
                    let spot = f(&tool["diameter"]);
                    let cut = z - t / 2.0;
                    let k = (cut / 0.6).round();
                    let rc = (0.25f64.powi(2) - (cut - 0.6 * k).powi(2)).sqrt();
                    for p in &paths {
                        for q in points(p) {
                            let (cx, cy) = (q[0].round(), q[1].round());
                            let d = (q[0] - cx).hypot(q[1] - cy);
                            assert!(d <= rc - spot / 2.0 + 1e-6, "layer {i}: {q:?} outside its void");
                            let rho = radius(q);
                            assert!(
                                rho >= ri - 1e-6 && rho <= ro + 1e-6,
                                "layer {i}: {q:?} outside the region"
                            );
                        }
                    }
                    // As many voids as lattice points whose circle meets the ring.
                    let mut want = 0;
                    for x in -8i32..=8 {
                        for y in -8i32..=8 {
                            let rho = f64::from(x).hypot(f64::from(y));
                            if rho + rc > ri && rho - rc < ro {
                                want += 1;
                            }
                        }
                    }
                    assert_eq!(f(&o["values"]["voids"]) as i32, want, "layer {i}");
                    // The rings clear each whole void: every point of it lies within half
                    // a spot of a ring (checked on the first layers, at every depth of cut).
                    let rings: Vec<Vec<[f64; 2]>> = paths.iter().map(points).collect();
                    for x in (-8i32..=8).filter(|_| engraved < 4) {
                        for y in -8i32..=8 {
                            let (cx, cy) = (f64::from(x), f64::from(y));
                            let rho = cx.hypot(cy);
                            if rho - rc < ri + 0.01 || rho + rc > ro - 0.01 {
                                continue;
                            }
                            // The void is the inscribed 32-gon of the circle.
                            let inner = rc * (std::f64::consts::PI / 32.0).cos();
                            for s in 0..12 {
                                let d = inner * f64::from(s) / 12.0;
                                for a in 0..24 {
                                    let phi = f64::from(a) * std::f64::consts::PI / 12.0;
                                    let p = [cx + d * phi.cos(), cy + d * phi.sin()];
                                    let near = rings.iter().any(|r| {
                                        (0..r.len()).any(|k| {
                                            segment_distance(p, r[k], r[(k + 1) % r.len()])
                                                <= spot / 2.0 + 1e-9
                                        })
                                    });
                                    assert!(
                                        near,
                                        "layer {i}: {p:?} in the void at ({cx}, {cy}) is not engraved"
                                    );
                                }
                            }
                        }
                    }
                    engraved += 1;
                }
                _ => {}
            }
        }
    }
    assert!(
        milled >= 10 && ground >= 46 && engraved >= 10,
        "{milled} {ground} {engraved}"
    );
}

fn segment_distance(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len2 = dx * dx + dy * dy;
    let s = if len2 > 0.0 {
        (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p[0] - a[0] - s * dx).hypot(p[1] - a[1] - s * dy)
}

#[test]
fn a_missing_finish_grind_or_a_misnamed_region_is_refused_and_writes_nothing() {
    let dir = tempfile::tempdir().expect("tempdir");
    let pipe = std::fs::read_to_string(pipelines().join("pipe-work-cycles.toml")).expect("pipe");
    // Without the finish grind the microstructure ends each layer 0.02 mm high.
    let without = pipe.replace("[[process]]\nuse = \"grind\"\npass = \"finish\"\n", "");
    assert_ne!(without, pipe);
    let o = try_run_text(dir.path(), &without);
    let err = text(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("region `inner` ends the layer at 0.220 mm, its design height is 0.200 mm"),
        "{err}"
    );
    assert!(
        !dir.path().join("out/pipe-work-cycles.nc").exists(),
        "no partial output"
    );
    // A region the sequence does not have is named with the key that named it.
    let misnamed = pipe.replace(
        "finish_allowance = { inner = 0.02 }",
        "finish_allowance = { core = 0.02 }",
    );
    let o = try_run_text(dir.path(), &misnamed);
    let err = text(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("finish_allowance") && err.contains("no material region named `core`"),
        "{err}"
    );
}

/// The largest closed ring around each void centre of the `engrave` operations of a
/// layer: (centre, ring).
fn first_rings(layer: &Value) -> Vec<([f64; 2], Vec<[f64; 2]>)> {
    let mut by_centre: BTreeMap<(i64, i64), Vec<[f64; 2]>> = BTreeMap::new();
    for o in ops(layer).into_iter().filter(|o| o["kind"] == "engrave") {
        for p in o["paths"].as_array().expect("paths") {
            let pts = points(p);
            let n = pts.len() as f64;
            let c = [
                pts.iter().map(|q| q[0]).sum::<f64>() / n,
                pts.iter().map(|q| q[1]).sum::<f64>() / n,
            ];
            let key = ((c[0] * 20.0).round() as i64, (c[1] * 20.0).round() as i64);
            let keep = by_centre.entry(key).or_default();
            if ring_area(&pts) > ring_area(keep) {
                *keep = pts;
            }
        }
    }
    by_centre
        .into_values()
        .map(|pts| {
            let n = pts.len() as f64;
            (
                [
                    pts.iter().map(|q| q[0]).sum::<f64>() / n,
                    pts.iter().map(|q| q[1]).sum::<f64>() / n,
                ],
                pts,
            )
        })
        .collect()
}

fn ring_area(pts: &[[f64; 2]]) -> f64 {
    let n = pts.len();
    (0..n)
        .map(|i| {
            let (a, b) = (pts[i], pts[(i + 1) % n]);
            a[0] * b[1] - b[0] * a[1]
        })
        .sum::<f64>()
        .abs()
        / 2.0
}

const CELLS: &str = r#"
[materials.m]
colour = [70, 130, 180]

[model]
use = "box"
size = [20.0, 10.0, 2.0]

[slice]
use = "uniform"
thickness = 0.5

[[process]]
use = "engrave"
diameter = 0.02
base_cell = CELL

[[output]]
use = "json"
path = "plan.json"

[[output]]
use = "bitmap"
path = "cells"
pixel = 0.01
base_cell = CELL
"#;

#[test]
fn base_cells_take_their_size_turn_and_inserting_point_from_rhai_functions() {
    // Boxes of half-edges 1.5 s x s x s, s = 0.1 + 0.01 x, turned 3 x degrees about the
    // vertical, inserted only where x > 2; one row of the lattice every 1 mm at
    // z = 0.25 and 1.25, which the layers cut through the middle (at 0.25 and 1.25).
    let cell = r#"{ shape = "box", size = "0.1 + 0.01 * x", aspect = [1.5, 1.0, 1.0], turn = "3.0 * x", insert = "x - 2.0", period = [1.0, 1.0, 1.0], origin = [0.5, 0.5, 0.25] }"#;
    let dir = tempfile::tempdir().expect("tempdir");
    let plan = crate::support::run_text(dir.path(), &CELLS.replace("CELL", cell), "plan.json");
    let layers = plan["layers"].as_array().expect("layers");
    let spot = 0.02;
    let mut checked = 0;
    for (i, l) in layers.iter().enumerate() {
        let rings = first_rings(l);
        let cut = f(&l["z"]) - f(&l["thickness"]) / 2.0;
        let through = (cut - 0.25).rem_euclid(1.0) < 1e-9;
        if !through {
            assert!(rings.is_empty(), "layer {i}: the plane at {cut} misses every box");
            continue;
        }
        // Every inserting point with x > 2 and its box inside the part, and no other.
        let mut want = 0;
        for (c, ring) in &rings {
            assert!(
                c[0] > 2.0,
                "layer {i}: a cell at x = {} where the inserting function is negative",
                c[0]
            );
            if c[0] < 1.0 || c[0] > 19.0 || c[1] < 1.0 || c[1] > 9.0 {
                continue;
            }
            // On the lattice.
            let off = |v: f64| (v - 0.5 - (v - 0.5).round()).abs();
            assert!(off(c[0]) < 1e-6 && off(c[1]) < 1e-6, "{c:?}");
            let s = 0.1 + 0.01 * c[0];
            let (w, h) = (3.0 * s - spot, 2.0 * s - spot);
            assert!(
                (ring_area(ring) - w * h).abs() < 1e-6,
                "layer {i} at {c:?}: {} vs {}",
                ring_area(ring),
                w * h
            );
            // The long side runs at the turn, 3 x degrees.
            let n = ring.len();
            let (a, b) = (0..n)
                .map(|k| (ring[k], ring[(k + 1) % n]))
                .max_by(|p, q| {
                    let d = |e: &([f64; 2], [f64; 2])| (e.1[0] - e.0[0]).hypot(e.1[1] - e.0[1]);
                    d(p).total_cmp(&d(q))
                })
                .expect("edges");
            let angle = (b[1] - a[1]).atan2(b[0] - a[0]).to_degrees().rem_euclid(180.0);
            let turn = (3.0 * c[0]).rem_euclid(180.0);
            let diff = (angle - turn).abs();
            assert!(
                diff.min(180.0 - diff) < 1e-6,
                "layer {i} at {c:?}: {angle} vs {turn}"
            );
            want += 1;
        }
        // x = 2.5 .. 18.5 by 1 (17 columns) over y = 1.5 .. 8.5 (8 rows).
        assert_eq!(want, 17 * 8, "layer {i}");
        checked += 1;
    }
    assert_eq!(checked, 2);
    // The bitmap leaves out the same boxes: its zeros add up to their sections.
    let header = std::fs::read_to_string(dir.path().join("out/cells.hdr")).expect("header");
    assert!(
        header.contains("box cells of size `0.1 + 0.01 * x` mm"),
        "{header}"
    );
    let data = std::fs::read_to_string(dir.path().join("out/cells.dat")).expect("data");
    let rows: Vec<&str> = header.lines().filter(|l| !l.starts_with('#')).collect();
    let first = rows[0].split_whitespace().collect::<Vec<_>>();
    let (width, height) = (
        first[7].parse::<usize>().expect("w"),
        first[8].parse::<usize>().expect("h"),
    );
    let zeros = data
        .lines()
        .take(height)
        .map(|row| row.bytes().filter(|&b| b == b'0').count())
        .sum::<usize>() as f64
        * 1e-4;
    let mut want = 0.0;
    for i in 0..20 {
        let x = 0.5 + f64::from(i);
        if x > 2.0 {
            want += 10.0 * 6.0 * (0.1 + 0.01 * x) * (0.1 + 0.01 * x);
        }
    }
    assert!(
        width > 1900 && (zeros - want).abs() < 0.02 * want,
        "{zeros} mm² of voids, {want} mm² of boxes"
    );
}

#[test]
fn a_tilted_lattice_is_cut_where_the_layer_plane_meets_each_sphere() {
    // Spheres of 0.3 mm on a 1 mm lattice whose z axis leans 30 degrees from the
    // vertical (Fig. 5): the plane meets spheres of several lattice rows, each in a
    // circle of radius sqrt(0.3² - dz²), dz the height of its centre over the plane.
    let cell = r#"{ size = 0.3, period = [1.0, 1.0, 1.0], tilt = 30.0 }"#;
    let dir = tempfile::tempdir().expect("tempdir");
    let plan = crate::support::run_text(dir.path(), &CELLS.replace("CELL", cell), "plan.json");
    let phi = 30f64.to_radians();
    let spot = 0.02;
    let apothem = (std::f64::consts::PI / 32.0).cos();
    let mut rows = std::collections::BTreeSet::new();
    let mut seen = 0;
    for l in plan["layers"].as_array().expect("layers") {
        let cut = f(&l["z"]) - f(&l["thickness"]) / 2.0;
        let rings = first_rings(l);
        // Every sphere the plane cuts through, away from the part's sides, is there.
        let mut want = 0;
        for k in -5i32..=5 {
            for j in -5i32..=15 {
                for i in 0i32..=20 {
                    let (x, yl, zl) = (f64::from(i), f64::from(j), f64::from(k));
                    let (y, z) = (yl * phi.cos() - zl * phi.sin(), yl * phi.sin() + zl * phi.cos());
                    let dz = z - cut;
                    let rc2 = 0.09 - dz * dz;
                    // Sections wide enough for a ring, clear of the box's sides.
                    if rc2 <= (0.012f64).powi(2) || !(0.5..=19.5).contains(&x) || !(0.5..=9.5).contains(&y) {
                        continue;
                    }
                    want += 1;
                    let (c, ring) = rings
                        .iter()
                        .find(|(c, _)| (c[0] - x).abs() < 1e-6 && (c[1] - y).abs() < 1e-6)
                        .unwrap_or_else(|| panic!("layer at {cut}: no void at ({x}, {y}) of row k = {k}"));
                    // The section is a 32-gon in the circle; its first ring half a spot in.
                    let rc = rc2.sqrt();
                    let r = ((rc * apothem - spot / 2.0) / apothem).max(0.0);
                    let area = 16.0 * r * r * (std::f64::consts::TAU / 32.0).sin();
                    assert!(
                        (ring_area(ring) - area).abs() < 1e-6,
                        "({x}, {y}) row {k}: {} vs {area} {c:?}",
                        ring_area(ring)
                    );
                    rows.insert(k);
                }
            }
        }
        seen += want;
    }
    assert!(seen > 100 && rows.len() > 1, "{seen} voids from rows {rows:?}");
}

#[test]
fn cells_that_outgrow_their_lattice_or_conflicting_void_options_are_refused() {
    let dir = tempfile::tempdir().expect("tempdir");
    let big =
        r#"{ shape = "box", size = "0.2 + 0.1 * x", period = [1.0, 1.0, 1.0], origin = [0.5, 0.5, 0.25] }"#;
    let o = try_run_text(dir.path(), &CELLS.replace("CELL", big));
    let err = text(&o.stderr);
    assert!(!o.status.success());
    assert!(err.contains("more than half the lattice's diagonal"), "{err}");
    assert!(!dir.path().join("out/plan.json").exists(), "no partial output");
    let shape = r#"{ shape = "cone", size = 0.2, period = [1.0, 1.0, 1.0] }"#;
    let err = text(&try_run_text(dir.path(), &CELLS.replace("CELL", shape)).stderr);
    assert!(err.contains("cell") && err.contains("`shape` is `cone`"), "{err}");
    let both = CELLS.replace(
        "diameter = 0.02\nbase_cell = CELL",
        "diameter = 0.02\nvoid_radius = 0.2\nbase_cell = { size = 0.2, period = [1.0, 1.0, 1.0] }",
    );
    let err = text(
        &try_run_text(
            dir.path(),
            &both.replace("CELL", "{ size = 0.2, period = [1.0, 1.0, 1.0] }"),
        )
        .stderr,
    );
    assert!(
        err.contains("void_radius") && err.contains("give either `base_cell`"),
        "{err}"
    );
}

#[test]
fn the_nc_file_is_refused_where_the_machine_could_not_run_the_plan() {
    let dir = tempfile::tempdir().expect("tempdir");
    let pipe = std::fs::read_to_string(pipelines().join("pipe-work-cycles.toml")).expect("pipe");
    // A 1 mm cutter in the plan, 0.8 mm in the machine.
    let wider = pipe.replace(
        "use = \"end-mill\"\ndiameter = 0.8",
        "use = \"end-mill\"\ndiameter = 1.0",
    );
    assert_ne!(wider, pipe);
    let o = try_run_text(dir.path(), &wider);
    let err = text(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("`end-mill` measures 0.8 mm in the machine, the plan was made for 1 mm"),
        "{err}"
    );
    assert!(
        !dir.path().join("out/pipe-work-cycles.nc").exists(),
        "no partial output"
    );
    // A machine whose table is too small for the pipe (radius 10).
    let machine = include_str!("../../plugins/process/machines/cmpm-hybrid.toml")
        .replace("x = [-150.0, 150.0]", "x = [-5.0, 5.0]");
    std::fs::write(dir.path().join("small.toml"), machine).expect("machine");
    let small = pipe.replace("machine = \"cmpm-hybrid\"", "machine = \"small.toml\"");
    let err = text(&try_run_text(dir.path(), &small).stderr);
    assert!(err.contains("travel x [-5.0, 5.0]"), "{err}");
    // Numbers come from the machine or from `tools`, not both.
    let both = pipe.replace(
        "machine = \"cmpm-hybrid\"",
        "machine = \"cmpm-hybrid\"\ntools = { laser = 9 }",
    );
    let err = text(&try_run_text(dir.path(), &both).stderr);
    assert!(err.contains("give `machine` or `tools`, not both"), "{err}");
}

#[test]
fn options_that_would_exhaust_the_machine_stop_at_the_grid_limit() {
    let dir = tempfile::tempdir().expect("tempdir");
    let pipe = std::fs::read_to_string(pipelines().join("pipe-work-cycles.toml")).expect("pipe");
    // A spray spot of a nanometre is no spray gun's: refused at its key before any
    // pass is counted.
    let fine = pipe.replace(
        "inclusions = { outer = { SiC = 0.2 } }",
        "inclusions = { outer = { SiC = 0.2 } }\ndiameter = 1e-9",
    );
    assert_ne!(fine, pipe);
    let err = text(&try_run_text(dir.path(), &fine).stderr);
    assert!(
        err.contains("`diameter` = 1e-9 is outside its range 0.001 to 1000"),
        "{err}"
    );
    // A lattice a micrometre apart over the pipe's layers.
    // (The engraving's lattice; the bitmap keeps a coarse one.)
    let dense = CELLS
        .replacen("CELL", "{ size = 1e-4, period = [1e-3, 1e-3, 1e-3] }", 1)
        .replace("CELL", "{ size = 0.3, period = [1.0, 1.0, 1.0] }");
    let err = text(&try_run_text(dir.path(), &dense).stderr);
    assert!(err.contains("grid_samples"), "{err}");
}

#[test]
fn cells_turn_with_the_model_when_it_is_oriented_by_them() {
    // Plate-like cells, half-edges 0.2 x 0.4 x 0.1 in the model's frame: their faces
    // weigh least built along the model's y, so the plate is turned to stand on its
    // side. The engraved voids are the turned cells' sections: 0.4 (cell x) by 0.2
    // (cell z) across, not 0.4 by 0.8 as the cell table would read in the build frame.
    let cell = r#"{ shape = "box", size = 0.2, aspect = [1.0, 2.0, 0.5], period = [1.0, 1.0, 1.0], origin = [0.5, 0.5, 0.5] }"#;
    let text = format!(
        "[materials.m]\ncolour = [70, 130, 180]\n[model]\nuse = \"box\"\nsize = [10.0, 2.0, 1.0]\n\
         [orient]\nuse = \"candidates\"\ncriterion = \"base-cell\"\nbase_cell = {cell}\n\
         [slice]\nuse = \"uniform\"\nthickness = 0.5\n\
         [[process]]\nuse = \"engrave\"\ndiameter = 0.02\nbase_cell = {cell}\n\
         [[output]]\nuse = \"json\"\npath = \"plan.json\"\n"
    );
    let dir = tempfile::tempdir().expect("tempdir");
    let plan = crate::support::run_text(dir.path(), &text, "plan.json");
    assert!(plan["orientation"]["direction"][1].as_f64().expect("y").abs() > 1.0 - 1e-9);
    let spot = 0.02;
    let want = (0.4 - spot) * (0.2 - spot);
    let mut seen = 0;
    for l in plan["layers"].as_array().expect("layers") {
        for (c, ring) in first_rings(l) {
            let area = ring_area(&ring);
            assert!((area - want).abs() < 1e-6, "at {c:?}: {area} vs {want}");
            seen += 1;
        }
    }
    // The plate's 20 cells (10 along x, 2 up its turned 2 mm height, 1 across its
    // 1 mm), each cut by the two layers through it.
    assert_eq!(seen, 10 * 2 * 2, "{seen}");
}

/// The pipe's pipeline with only the outputs `keep` (by their `use`).
fn pipe_with_outputs(pipe: &str, keep: &[&str]) -> String {
    let mut parts = pipe.split("[[output]]");
    let mut out = parts.next().expect("the head").to_string();
    for block in parts {
        if keep.iter().any(|k| block.contains(&format!("use = \"{k}\""))) {
            out.push_str("[[output]]");
            out.push_str(block);
        }
    }
    out
}

#[test]
fn the_program_speaks_its_controllers_dialect_or_is_refused_with_what_the_controller_lacks() {
    let dir = tempfile::tempdir().expect("tempdir");
    let pipe = std::fs::read_to_string(pipelines().join("pipe-work-cycles.toml")).expect("pipe");
    let pipe = pipe_with_outputs(&pipe, &["nc"]);
    // A Fanuc-like controller: program number, reference return, M06, feeders as macro
    // variables, a decimal point on every coordinate.
    let fanuc = pipe.replace("machine = \"cmpm-hybrid\"", "machine = \"cmpm-hybrid-fanuc\"");
    let o = try_run_text(dir.path(), &fanuc);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let nc = std::fs::read_to_string(dir.path().join("out/pipe-work-cycles.nc")).expect("nc");
    assert!(nc.starts_with("%\nO1000 (LAMINA HYBRID)\n("), "{}", &nc[..80]);
    assert!(
        nc.ends_with("G49\nG91 G28 Z0.\nG90\nM30\n%\n"),
        "{}",
        &nc[nc.len() - 80..]
    );
    assert!(nc.contains("\nT2 M06\nG43 H2\n") && nc.contains("\n#501=") && !nc.contains("M68"));
    for line in nc.lines().filter(|l| l.starts_with("G0") || l.starts_with("G1")) {
        for word in line.split_whitespace().filter(|w| w.starts_with(['X', 'Y', 'Z'])) {
            assert!(
                word.contains('.'),
                "`{word}` in `{line}` reads as micrometres on a Fanuc"
            );
        }
    }
    // Grbl cannot hold the hybrid process: no spray gun, no tool changer.
    let grbl = pipe.replace("machine = \"cmpm-hybrid\"", "machine = \"grbl-laser\"");
    let dir = tempfile::tempdir().expect("tempdir");
    let o = try_run_text(dir.path(), &grbl);
    assert!(!o.status.success());
    assert!(
        text(&o.stderr).contains("the machine `grbl-laser` has no tool `spray-gun` (tools: laser)"),
        "{}",
        text(&o.stderr)
    );
    assert!(
        !dir.path().join("out/pipe-work-cycles.nc").exists(),
        "no partial output"
    );
    // It can engrave: one tool, already loaded; the laser in M4 at S per its scale.
    let mut engrave_only = String::new();
    for (i, block) in grbl.split("[[process]]").enumerate() {
        if i == 0 {
            engrave_only.push_str(block);
        } else if block.contains("use = \"engrave\"") {
            engrave_only.push_str("[[process]]");
            engrave_only.push_str(block);
        } else if let Some(at) = block.find("[[output]]") {
            // The outputs follow the last process.
            engrave_only.push_str(&block[at..]);
        }
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let o = try_run_text(dir.path(), &engrave_only);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let nc = std::fs::read_to_string(dir.path().join("out/pipe-work-cycles.nc")).expect("nc");
    assert!(
        !nc.contains("M6") && !nc.contains("G43") && !nc.contains("M64"),
        "{}",
        &nc[..400]
    );
    assert!(nc.contains("\nM4 S400\n"), "20 W at 20 S per W");
    assert!(nc.ends_with("M9\nG53 G0 Z0\nM2\n"), "{}", &nc[nc.len() - 60..]);
}

#[test]
fn a_wheel_its_spindle_cannot_turn_fast_enough_grinds_at_the_top_speed_and_the_run_says_so() {
    let dir = tempfile::tempdir().expect("tempdir");
    let machine = include_str!("../../plugins/process/machines/cmpm-hybrid.toml");
    let slow = machine.replacen(
        "surface_speed = 25.0\nramp_angle = 5.0\nmax_spindle = 30000.0",
        "surface_speed = 25.0\nramp_angle = 5.0\nmax_spindle = 6000.0",
        1,
    );
    assert_ne!(slow, machine);
    std::fs::write(dir.path().join("slow.toml"), slow).expect("machine");
    let pipe = std::fs::read_to_string(pipelines().join("pipe-work-cycles.toml")).expect("pipe");
    let pipe =
        pipe_with_outputs(&pipe, &["nc"]).replace("machine = \"cmpm-hybrid\"", "machine = \"slow.toml\"");
    let o = try_run_text(dir.path(), &pipe);
    let err = text(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains(
            "`cup-wheel` turns at most 6000 rev/min: 6.3 m/s on its 20 mm rim, below the 25 m/s it wants"
        ),
        "{err}"
    );
    let nc = std::fs::read_to_string(dir.path().join("out/pipe-work-cycles.nc")).expect("nc");
    assert!(nc.contains("\nS6000 M3\n") && !nc.contains("S23873"));
    // The shipped cell reaches it.
    let dir = tempfile::tempdir().expect("tempdir");
    let shipped = pipe.replace("machine = \"slow.toml\"", "machine = \"cmpm-hybrid\"");
    let o = try_run_text(dir.path(), &shipped);
    assert!(
        o.status.success() && !text(&o.stderr).contains("rev/min"),
        "{}",
        text(&o.stderr)
    );
    let nc = std::fs::read_to_string(dir.path().join("out/pipe-work-cycles.nc")).expect("nc");
    assert!(nc.contains("\nS23873 M3\n"), "25 m/s on 20 mm");
}

#[test]
fn tool_numbers_beyond_any_machine_are_refused_at_their_key_with_the_range() {
    let pipe = std::fs::read_to_string(pipelines().join("pipe-work-cycles.toml")).expect("pipe");
    for (from, to, want) in [
        (
            "use = \"end-mill\"\ndiameter = 0.8",
            "use = \"end-mill\"\ndiameter = 1e300",
            "`diameter` = 1e300 is outside its range 0.001 to 1000",
        ),
        (
            "rough_allowance = 0.1\n",
            "rough_allowance = 0.1\nfeed = 5e-324\n",
            "`feed` = 5e-324 is outside its range 0.01 to 10000",
        ),
        (
            "pass = \"rough\"\n",
            "pass = \"rough\"\nspindle = 1e9\n",
            "`spindle` = 1e9 is outside its range 1 to 200000",
        ),
    ] {
        let dir = tempfile::tempdir().expect("tempdir");
        let bad = pipe.replace(from, to);
        assert_ne!(bad, pipe, "{from}");
        let o = try_run_text(dir.path(), &bad);
        let err = text(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{to}: {err}");
        assert!(err.contains(want), "{to}: {err}");
    }
}

#[test]
fn a_part_name_with_a_line_break_stays_on_its_line_in_the_bitmap_header() {
    let dir = tempfile::tempdir().expect("tempdir");
    let pipe = std::fs::read_to_string(pipelines().join("pipe-work-cycles.toml")).expect("pipe");
    let named = pipe_with_outputs(&pipe, &["bitmap"])
        .replace("\"inner\"", "\"inner\\nG28\"")
        .replace("{ inner = 0.02 }", "{ \"inner\\nG28\" = 0.02 }");
    assert!(named.matches("inner\\nG28").count() >= 4, "{named}");
    let o = try_run_text(dir.path(), &named);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let header = std::fs::read_to_string(dir.path().join("out/inner-bitmap.hdr")).expect("header");
    assert!(header.contains("# parts: inner G28\n"), "{header}");
    assert!(
        header
            .lines()
            .all(|l| l.starts_with('#') || l.starts_with(|c: char| c.is_ascii_digit())),
        "{header}"
    );
}
