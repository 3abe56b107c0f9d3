//! The papers' grading numbers, end to end through the example pipelines: the gear's
//! colour table along Z (topological-hierarchy-fgm Fig. 3) and the wave function of
//! Fig. 4.

use crate::support::{pipelines, run_plan};

fn run(pipeline: &str, json: &str) -> serde_json::Value {
    let dir = tempfile::tempdir().expect("tempdir");
    run_plan(&pipelines().join(pipeline), dir.path(), &[], json)
}

/// Colour and red fraction of one region.
type Shade = ([u8; 3], f64);

/// The shades of the gear's regions, per layer index.
fn gear_layers(plan: &serde_json::Value) -> Vec<(u64, Vec<Shade>)> {
    plan["layers"]
        .as_array()
        .expect("layers")
        .iter()
        .filter_map(|l| {
            let gear = l["parts"].as_array()?.iter().find(|p| p["part"] == "gear")?;
            let regions = gear["families"]
                .as_array()?
                .iter()
                .flat_map(|f| f["sub_regions"].as_array().into_iter().flatten())
                .map(|r| {
                    let c = &r["colour"];
                    let rgb = [0, 1, 2].map(|i| c[i].as_u64().unwrap_or(999) as u8);
                    (rgb, r["composition"]["red"].as_f64().unwrap_or(f64::NAN))
                })
                .collect::<Vec<_>>();
            (!regions.is_empty()).then(|| (l["index"].as_u64().unwrap_or(0), regions))
        })
        .collect()
}

#[test]
fn gear_graded_along_z_gives_the_papers_colour_table() {
    let plan = run("gear-z-gradient.toml", "gear-z-gradient.json");
    let layers = gear_layers(&plan);
    assert_eq!(layers.len(), 10, "the gear is 5 mm of 0.5 mm layers");
    let expected = [
        [0, 255, 0],
        [43, 212, 0],
        [85, 170, 0],
        [128, 127, 0],
        [170, 85, 0],
        [213, 42, 0],
        [255, 0, 0],
    ];
    for (index, regions) in &layers {
        let want = expected[(*index as usize).saturating_sub(3).min(6)];
        for (rgb, _) in regions {
            assert_eq!(*rgb, want, "layer {index}");
        }
    }
    // The shaft is blue throughout.
    for l in plan["layers"].as_array().expect("layers") {
        for p in l["parts"].as_array().expect("parts") {
            if p["part"] == "shaft" {
                for f in p["families"].as_array().expect("families") {
                    for r in f["sub_regions"].as_array().expect("regions") {
                        assert_eq!(r["colour"], serde_json::json!([0, 0, 255]));
                        assert_eq!(r["composition"]["blue"], 1.0);
                    }
                }
            }
        }
    }
}

#[test]
fn gear_graded_by_the_wave_function() {
    let plan = run("gear-z-wave.toml", "gear-z-wave.json");
    for (index, regions) in gear_layers(&plan) {
        let r = ((index as f64 - 3.0) / 6.0).clamp(0.0, 1.0);
        let want = (r * std::f64::consts::PI).sin();
        for (_, red) in regions {
            assert!(
                (red - want).abs() < 1e-9,
                "layer {index}: {red} vs sin({r} pi) = {want}"
            );
        }
    }
}

/// Fig. 19: the blade graded across each layer and along Z at once, with two pairs of
/// materials: red (ductile) on the first layer to green (hard) on the last along Z
/// (Eq. 9: r_i = i / 69), ceramic (yellow) at the skin to metal (blue) inside across
/// (Eq. 25: f_ceramic = 1 - r_j, r_j = j / (N_R - 1)), combined with equal weights.
#[test]
fn blade_graded_along_z_and_across_at_once() {
    let plan = run("blade-zxy.toml", "blade-zxy.json");
    let materials: Vec<(&str, [u64; 3])> = plan["materials"]
        .as_array()
        .expect("materials")
        .iter()
        .map(|m| {
            let c = m["colour"].as_array().expect("colour");
            (
                m["name"].as_str().expect("name"),
                [0, 1, 2].map(|k| c[k].as_u64().expect("rgb")),
            )
        })
        .collect();
    for (name, rgb) in [
        ("red", [255, 0, 0]),
        ("green", [0, 255, 0]),
        ("ceramic", [255, 255, 0]),
        ("metal", [0, 0, 255]),
    ] {
        assert!(materials.contains(&(name, rgb)), "Fig. 19's {name} {rgb:?}");
    }
    let mut checked = 0;
    for layer in plan["layers"].as_array().expect("layers") {
        let ri = (layer["index"].as_f64().expect("index") / 69.0).min(1.0);
        for f in layer["parts"][0]["families"].as_array().expect("families") {
            for r in f["sub_regions"].as_array().expect("regions") {
                let count = r["count"].as_f64().expect("count");
                let rj = if count > 1.0 {
                    r["index"].as_f64().expect("index") / (count - 1.0)
                } else {
                    0.0
                };
                let c = &r["composition"];
                let got = |m: &str| c[m].as_f64().unwrap_or(0.0);
                for (m, want) in [
                    ("red", (1.0 - ri) / 2.0),
                    ("green", ri / 2.0),
                    ("ceramic", (1.0 - rj) / 2.0),
                    ("metal", rj / 2.0),
                ] {
                    assert!(
                        (got(m) - want).abs() < 1e-9,
                        "layer {} region {}: {m} {} vs {want}",
                        layer["index"],
                        r["index"],
                        got(m)
                    );
                }
                checked += 1;
            }
        }
    }
    assert!(checked > 100, "{checked} regions");
    // Across, `linear` without coefficients is Eq. 25's f = 1 - r: the same blade.
    let text = std::fs::read_to_string(pipelines().join("blade-zxy.toml")).expect("pipeline");
    let linear = text.replace("xy_f = \"1.0 - r\"", "xy_f = \"linear\"");
    assert_ne!(linear, text);
    let dir = tempfile::tempdir().expect("tempdir");
    let by_default = crate::support::run_text(dir.path(), &linear, "blade-zxy.json");
    assert_eq!(by_default["layers"], plan["layers"]);
}

type Ring = Vec<[f64; 2]>;

fn ring(v: &serde_json::Value) -> Ring {
    v.as_array()
        .expect("a ring")
        .iter()
        .map(|p| [p[0].as_f64().expect("x"), p[1].as_f64().expect("y")])
        .collect()
}

/// Shortest distance from `p` to the closed ring's edges.
fn ring_distance(r: &Ring, p: [f64; 2]) -> f64 {
    (0..r.len())
        .map(|i| {
            let (a, b) = (r[i], r[(i + 1) % r.len()]);
            let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
            let len2 = dx * dx + dy * dy;
            let t = if len2 > 0.0 {
                (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / len2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            (p[0] - a[0] - t * dx).hypot(p[1] - a[1] - t * dy)
        })
        .fold(f64::INFINITY, f64::min)
}

/// Whether `p` is inside the ring (crossing count of a ray along +x).
fn ring_contains(r: &Ring, p: [f64; 2]) -> bool {
    let mut inside = false;
    for i in 0..r.len() {
        let (a, b) = (r[i], r[(i + 1) % r.len()]);
        if (a[1] > p[1]) != (b[1] > p[1]) && p[0] < a[0] + (p[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0]) {
            inside = !inside;
        }
    }
    inside
}

/// Signed area and area-weighted centroid sums of a ring (shoelace).
fn ring_moments(r: &Ring) -> (f64, f64, f64) {
    let (mut a, mut x, mut y) = (0.0, 0.0, 0.0);
    for i in 0..r.len() {
        let (p, q) = (r[i], r[(i + 1) % r.len()]);
        let c = p[0] * q[1] - q[0] * p[1];
        a += c / 2.0;
        x += (p[0] + q[0]) * c / 6.0;
        y += (p[1] + q[1]) * c / 6.0;
    }
    (a, x, y)
}

#[test]
fn blade_idw_gives_every_cell_eq_23_of_its_cavities_materials_at_its_centre() {
    // Fig. 21: m1 on the blade's outer contour, m2 on the leading cavity and m3 on the
    // trailing one, as the pipeline assigns them (each cavity the material of the
    // nearest listed point), and every cell graded by Eq. 23 at its centre (Fig. 14).
    let plan = run("blade-idw.toml", "blade-idw.json");
    let listed = [([-14.0, 0.0], "m2"), ([8.0, 1.0], "m3")];
    let (mut cells, mut off_centre, mut families, mut farthest) = (0, 0, 0, 0.0f64);
    let mut dominant = std::collections::BTreeMap::<&str, usize>::new();
    for layer in plan["layers"].as_array().expect("layers") {
        for f in layer["parts"][0]["families"].as_array().expect("families") {
            let outer = ring(&f["outer"]);
            let holes: Vec<Ring> = f["holes"].as_array().expect("holes").iter().map(ring).collect();
            assert_eq!(
                holes.len(),
                2,
                "layer {}: a family with two cavities",
                layer["index"]
            );
            families += 1;
            // Each cavity's material: that of the listed point nearest to it.
            let mut contours = vec![(outer, "m1")];
            for h in holes {
                let (_, m) = listed
                    .iter()
                    .map(|(p, m)| (ring_distance(&h, *p), *m))
                    .min_by(|a, b| a.0.total_cmp(&b.0))
                    .expect("listed points");
                contours.push((h, m));
            }
            assert_ne!(contours[1].1, contours[2].1, "each cavity its own material");
            for r in f["sub_regions"].as_array().expect("regions") {
                let reference = [
                    r["reference"][0].as_f64().expect("x"),
                    r["reference"][1].as_f64().expect("y"),
                ];
                // Eq. 23: the weight of contour i is the product of the other contours'
                // distances over the sum of such products.
                let d: Vec<f64> = contours
                    .iter()
                    .map(|(c, _)| ring_distance(c, reference))
                    .collect();
                let prod = |i: usize| -> f64 { (0..d.len()).filter(|&k| k != i).map(|k| d[k]).product() };
                let sum: f64 = (0..d.len()).map(prod).sum();
                let composition = &r["composition"];
                let mut best = ("", 0.0);
                for (i, (_, m)) in contours.iter().enumerate() {
                    let want = prod(i) / sum;
                    let got = composition[*m].as_f64().unwrap_or(0.0);
                    assert!(
                        (got - want).abs() < 1e-6,
                        "layer {} region {} cell {}: {m} {got} against Eq. 23's {want} at {reference:?}",
                        layer["index"],
                        r["index"],
                        r["cell"]
                    );
                    if got > best.1 {
                        best = (m, got);
                    }
                }
                *dominant.entry(best.0).or_default() += 1;
                // The reference point is the cell's centre: its centroid where that lies
                // inside the cell, else a point inside it.
                let polygon = &r["polygon"];
                let outer = ring(&polygon["outer"]);
                let holes: Vec<Ring> = polygon["holes"]
                    .as_array()
                    .expect("holes")
                    .iter()
                    .map(ring)
                    .collect();
                let inside =
                    |p: [f64; 2]| ring_contains(&outer, p) && !holes.iter().any(|h| ring_contains(h, p));
                let (mut a, mut x, mut y) = ring_moments(&outer);
                let s = a.signum();
                (a, x, y) = (a * s, x * s, y * s);
                for h in &holes {
                    let (ha, hx, hy) = ring_moments(h);
                    let hs = ha.signum();
                    (a, x, y) = (a - ha * hs, x - hx * hs, y - hy * hs);
                }
                let centroid = [x / a, y / a];
                assert!(inside(reference), "a reference outside its cell: {reference:?}");
                let off = (reference[0] - centroid[0]).hypot(reference[1] - centroid[1]);
                if inside(centroid) {
                    assert!(off < 1e-6, "reference {reference:?}, centroid {centroid:?}");
                } else {
                    // A cell around a corner: the point of the cell nearest its
                    // centroid.
                    let gap = std::iter::once(&outer)
                        .chain(&holes)
                        .map(|r| ring_distance(r, centroid))
                        .fold(f64::INFINITY, f64::min);
                    assert!(
                        (off - gap).abs() < 1e-3,
                        "reference {reference:?} {off} mm from the centroid {centroid:?}, the cell {gap} mm"
                    );
                    off_centre += 1;
                    farthest = farthest.max(off);
                }
                cells += 1;
            }
        }
    }
    assert_eq!(families, 70, "one family per layer");
    assert!(cells > 10_000, "{cells} cells");
    // Each material dominates the cells about its own contour.
    for m in ["m1", "m2", "m3"] {
        assert!(
            dominant.get(m).copied().unwrap_or(0) > cells / 20,
            "{m}: {dominant:?}"
        );
    }
    // Cells around the blade's corners have their centroid outside them.
    assert!(
        off_centre * 5 <= cells,
        "{off_centre} of {cells} cells off centre"
    );
    println!(
        "{cells} cells by Eq. 23 at their centres ({off_centre} around corners at the point nearest their centroid, at most {farthest:.3} mm off); dominant {dominant:?}"
    );
}

/// f1 = (alpha r)^k over r in [0, 1] is a volume fraction only with alpha <= 1: a
/// larger alpha is refused at its key when the pipeline is read (by `check` as by
/// `run`), not when a layer meets f > 1 mid-run.
#[test]
fn a_power_law_past_one_is_refused_at_its_key() {
    let path = pipelines().join("distance-field-power.toml");
    let text = std::fs::read_to_string(&path).expect("pipeline");
    assert!(text.contains("alpha = 1.0"));
    let dir = tempfile::tempdir().expect("tempdir");
    let bad = crate::support::write(
        dir.path(),
        "power.toml",
        &text.replace("alpha = 1.0", "alpha = 2.0"),
    );
    for command in ["check", "run"] {
        let out = crate::support::lamina_in(dir.path(), &[command, bad.to_str().expect("path")]);
        let err = crate::support::text(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{command}: {err}");
        assert!(
            err.contains("`alpha` = 2 is outside its range 0.0001 to 1"),
            "{command}: {err}"
        );
        let line = text
            .lines()
            .position(|l| l.starts_with("alpha = "))
            .expect("line")
            + 1;
        assert!(err.contains(&format!("power.toml:{line}")), "{command}: {err}");
    }
    assert!(
        !dir.path().join("out").exists(),
        "a refused run leaves nothing behind"
    );
    // No scale at all, or an exponent that is not positive, is refused too, at its key.
    for (from, to, key) in [
        ("alpha = 1.0", "alpha = 0.0", "alpha"),
        ("k = 2.0", "k = 0.0", "k"),
    ] {
        assert!(text.contains(from));
        let bad = crate::support::write(dir.path(), "power.toml", &text.replacen(from, to, 1));
        let out = crate::support::lamina_in(dir.path(), &["check", bad.to_str().expect("path")]);
        let err = crate::support::text(&out.stderr);
        let line = text.lines().position(|l| l.starts_with(from)).expect("line") + 1;
        assert_eq!(out.status.code(), Some(2), "{to}: {err}");
        assert!(
            err.contains(&format!("power.toml:{line}")) && err.contains(key),
            "{to}: {err}"
        );
    }
    // alpha = 1 is the paper's own (Fig. 5): accepted.
    let ok = crate::support::write(dir.path(), "power.toml", &text);
    let out = crate::support::lamina_in(dir.path(), &["check", ok.to_str().expect("path")]);
    assert!(out.status.success(), "{}", crate::support::text(&out.stderr));
}

/// `lamina check` of a pipeline written out from `text`: its exit code and what it
/// printed on stderr.
fn check(dir: &std::path::Path, text: &str) -> (Option<i32>, String) {
    let path = crate::support::write(dir, "check.toml", text);
    let out = crate::support::lamina_in(dir, &["check", path.to_str().expect("path")]);
    (out.status.code(), crate::support::text(&out.stderr))
}

/// Eq. 9's span given as heights: the layers' own heights of layers 3 and 9 give the
/// gear exactly the compositions `from_layer = 3`, `to_layer = 9` give. Spans and
/// weights that mean nothing are refused at their keys.
#[test]
fn a_z_span_by_heights_matches_the_span_by_layers_and_bad_spans_are_refused() {
    let text = std::fs::read_to_string(pipelines().join("gear-z-gradient.toml")).expect("pipeline");
    let by_layers = run("gear-z-gradient.toml", "gear-z-gradient.json");
    let z_of = |i: u64| -> f64 {
        by_layers["layers"]
            .as_array()
            .expect("layers")
            .iter()
            .find(|l| l["index"].as_u64() == Some(i))
            .and_then(|l| l["z"].as_f64())
            .expect("the layer's z")
    };
    let heights = text.replace(
        "from_layer = 3\nto_layer = 9",
        &format!("from_z = {:?}\nto_z = {:?}", z_of(3), z_of(9)),
    );
    assert_ne!(heights, text);
    let dir = tempfile::tempdir().expect("tempdir");
    let by_heights = crate::support::run_text(dir.path(), &heights, "gear-z-gradient.json");
    let (a, b) = (gear_layers(&by_layers), gear_layers(&by_heights));
    assert_eq!(a.len(), b.len());
    let mut graded = 0;
    for ((i, ra), (j, rb)) in a.iter().zip(&b) {
        assert_eq!(i, j);
        for (x, y) in ra.iter().zip(rb) {
            assert!((x.1 - y.1).abs() < 1e-12, "layer {i}: {} vs {}", x.1, y.1);
            graded += usize::from(x.1 > 0.0 && x.1 < 1.0);
        }
    }
    assert!(graded > 0, "no layer between the two materials");
    for (bad, key) in [
        (format!("from_z = {:?}\nto_z = {:?}", z_of(9), z_of(3)), "to_z"),
        ("from_layer = 9\nto_layer = 3".to_string(), "to_layer"),
        (format!("from_z = {:?}", z_of(3)), "from_layer"),
        ("to_layer = 9".to_string(), "from_layer"),
    ] {
        let t = text.replace("from_layer = 3\nto_layer = 9", &bad);
        let (code, err) = check(dir.path(), &t);
        assert_eq!(code, Some(2), "{bad}: {err}");
        assert!(err.contains(key), "{bad}: {err}");
    }
    // A start equal to its end is a step there (Eq. 9's r jumps from 0 to 1), by
    // layers or by heights.
    for step in [
        "from_layer = 6\nto_layer = 6".to_string(),
        format!("from_z = {:?}\nto_z = {:?}", z_of(6), z_of(6)),
    ] {
        let t = text.replace("from_layer = 3\nto_layer = 9", &step);
        let (code, err) = check(dir.path(), &t);
        assert_eq!(code, Some(0), "{step}: {err}");
    }
    // Eq. 8's weights: none negative, not both zero.
    let zxy = std::fs::read_to_string(pipelines().join("blade-zxy.toml")).expect("pipeline");
    // One weight of 0: that grading has no say, which is allowed.
    let t = zxy.replace("weights = [1.0, 1.0]", "weights = [0.0, 1.0]");
    let (code, err) = check(dir.path(), &t);
    assert_eq!(code, Some(0), "{err}");
    for bad in ["weights = [0.0, 0.0]", "weights = [-1.0, 2.0]"] {
        let t = zxy.replace("weights = [1.0, 1.0]", bad);
        assert_ne!(t, zxy);
        let (code, err) = check(dir.path(), &t);
        assert_eq!(code, Some(2), "{bad}: {err}");
        assert!(err.contains("weights"), "{bad}: {err}");
    }
    // IDW's exponent: positive.
    let idw = std::fs::read_to_string(pipelines().join("blade-idw.toml")).expect("pipeline");
    let t = idw.replace("outer = \"m1\"", "outer = \"m1\"\npower = 0.0");
    let (code, err) = check(dir.path(), &t);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("power"), "{err}");
}
