//! Grading sources end to end: the steps of one source have the areas the geometry
//! gives, and with three sources every region's composition is what Eq. 2 and 8 give
//! at its reference point, recomputed here independently.

use crate::support::run_text;
use std::path::Path;

/// Runs a pipeline's text; its JSON plan is `plan.json` or, for the example, the
/// example's own.
fn run(pipeline_text: &str) -> serde_json::Value {
    let dir = tempfile::tempdir().expect("tempdir");
    let json = if pipeline_text.contains("grading-sources.json") {
        "grading-sources.json"
    } else {
        "plan.json"
    };
    run_text(dir.path(), pipeline_text, json)
}

fn regions(layer: &serde_json::Value) -> Vec<&serde_json::Value> {
    layer["parts"][0]["families"]
        .as_array()
        .expect("families")
        .iter()
        .flat_map(|f| f["regions"].as_array().expect("regions"))
        .collect()
}

#[test]
fn an_axis_source_steps_in_rings_of_the_right_area() {
    let text = "[model]\nuse = \"box\"\nsize = [40.0, 40.0, 2.0]\nplace = \"centre\"\n\
        [materials.a]\ncolour = [255, 0, 0]\n[materials.b]\ncolour = [0, 0, 255]\n\
        [discretise]\nuse = \"sources\"\n\
        sources = [{ kind = \"axis\", at = [0.0, 0.0, 0.0], width = 16.0, start = \"a\", end = \"b\", step = 0.25 }]\n\
        [slice]\nuse = \"uniform\"\nthickness = 1.0\n\
        [[output]]\nuse = \"json\"\npath = \"plan.json\"\n";
    let plan = run(text);
    let pi = std::f64::consts::PI;
    // f = d / 16 truncated at .125, .375, .625, .875: radii 2, 6, 10, 14.
    let want = [
        (0.0, pi * 4.0),
        (0.25, pi * 32.0),
        (0.5, pi * 64.0),
        (0.75, pi * 96.0),
        (1.0, 1600.0 - pi * 196.0),
    ];
    for layer in plan["layers"].as_array().expect("layers") {
        let rs = regions(layer);
        assert_eq!(rs.len(), 5);
        for (r, (level, area)) in rs.iter().zip(want) {
            assert_eq!(r["level"].as_f64(), Some(level));
            let a = r["area"].as_f64().expect("area");
            assert!((a - area).abs() < 1e-6 * 1600.0, "level {level}: {a} vs {area}");
            let c = &r["composition"];
            assert!((c["a"].as_f64().expect("a") - (1.0 - level)).abs() < 1e-12);
            assert!((c["b"].as_f64().expect("b") - level).abs() < 1e-12);
        }
    }
}

/// f(d) = d / width truncated in steps of t_g at the half steps (grading-step-width 3.1).
fn truncated(d: f64, width: f64, step: f64) -> f64 {
    let f = d / width;
    let n = (1.0 / step - 1e-9).ceil() as usize;
    let mut out = 0.0;
    for u in 0..n {
        let (lo, hi) = (u as f64 * step, ((u + 1) as f64 * step).min(1.0));
        if f >= (lo + hi) / 2.0 {
            out = hi;
        }
    }
    out
}

/// The three sources of `grading-sources.toml` at every region: Eq. 2 per source and
/// Eq. 8 over the sources whose effective region (0 <= f <= 1) holds the region (over
/// all of them, with their complementary compositions, where none does), or over all
/// of them everywhere.
/// Returns the number of regions of a pure material.
fn check_three_sources(plan: &serde_json::Value, everywhere: bool) -> usize {
    let mut pure = 0;
    for layer in plan["layers"].as_array().expect("layers") {
        let z = layer["z"].as_f64().expect("z") - layer["thickness"].as_f64().expect("t") / 2.0;
        let family: f64 = layer["parts"][0]["families"][0]["area"].as_f64().expect("area");
        let rs = regions(layer);
        let total: f64 = rs.iter().map(|r| r["area"].as_f64().expect("area")).sum();
        assert!(
            (total - family).abs() < 1e-6 * family,
            "tiling: {total} vs {family}"
        );
        let mut seen = std::collections::HashSet::new();
        for r in &rs {
            let p = r["reference"].as_array().expect("reference");
            let (x, y) = (p[0].as_f64().expect("x"), p[1].as_f64().expect("y"));
            // Axis (weight 2): core -> skin over 16 mm from the centre line.
            let da = x.hypot(y) / 16.0;
            // Point (weight 1): skin -> core over 20 mm from (20, 20, 3).
            let dp = ((x - 20.0).powi(2) + (y - 20.0).powi(2) + (z - 3.0).powi(2)).sqrt() / 20.0;
            // Plane (weight 1): skin -> core over 10 mm from x = -20.
            let dl = (x + 20.0) / 10.0;
            let (fa, fp, fl) = (
                truncated(da, 1.0, 0.25),
                truncated(dp, 1.0, 0.25),
                truncated(dl, 1.0, 0.25),
            );
            let terms = [
                (2.0, fa, (0.0..=1.0).contains(&da)),
                (1.0, 1.0 - fp, (0.0..=1.0).contains(&dp)),
                (1.0, 1.0 - fl, (0.0..=1.0).contains(&dl)),
            ];
            let any = !everywhere && terms.iter().any(|t| t.2);
            let (sum, weight) = terms
                .iter()
                .filter(|t| !any || t.2)
                .fold((0.0, 0.0), |(s, w), t| (s + t.0 * t.1, w + t.0));
            let skin = sum / weight;
            let c = &r["composition"];
            let got = c["skin"].as_f64().expect("skin");
            assert!((got - skin).abs() < 1e-9, "region at ({x}, {y}): {got} vs {skin}");
            assert!((got + c["core"].as_f64().expect("core") - 1.0).abs() < 1e-12);
            seen.insert((fa.to_bits(), fp.to_bits(), fl.to_bits()));
            if got == 0.0 || got == 1.0 {
                pure += 1;
            }
        }
        assert!(
            seen.len() > 10,
            "the three sources' steps overlap in many ways: {}",
            seen.len()
        );
    }
    pure
}

#[test]
fn three_sources_combine_by_eq_8_where_their_regions_intersect() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("pipelines/grading-sources.toml");
    let text = std::fs::read_to_string(path).expect("pipeline");
    let paper = check_three_sources(&run(&text), false);
    let everywhere = text.replace("use = \"sources\"", "use = \"sources\"\ncombine = \"everywhere\"");
    assert_ne!(everywhere, text);
    let blended = check_three_sources(&run(&everywhere), true);
    // R1' = R1 minus R12 keeps a source's own composition (the axis source alone is
    // pure skin along its centre line), where blending everywhere mixes it.
    assert!(
        paper > blended,
        "pure regions: {paper} with the paper's booleans, {blended} blended everywhere"
    );
}

/// A distance field from chosen faces of the part's mesh, measured in space: the top
/// face of a 4 mm box grades its layers along Z (layer mid-heights 3.5, 2.5, 1.5 and
/// 0.5 mm below it, r = d / 4 in four parts).
#[test]
fn a_surface_feature_measures_from_the_mesh_in_space() {
    let text = "[model]\nuse = \"box\"\nsize = [40.0, 20.0, 4.0]\n\
        [materials.a]\ncolour = [255, 0, 0]\n[materials.b]\ncolour = [0, 0, 255]\n\
        [slice]\nuse = \"uniform\"\nthickness = 1.0\n\
        [discretise]\nuse = \"distance-field\"\nfeature = \"surface\"\n\
        faces = { normal = [0.0, 0.0, 1.0], within = 5.0 }\ncount = 4\nwidth = 4.0\n\
        [grade]\nuse = \"xy\"\n\
        [[output]]\nuse = \"json\"\npath = \"plan.json\"\n";
    let plan = run(text);
    let got: Vec<Vec<u64>> = plan["layers"]
        .as_array()
        .expect("layers")
        .iter()
        .map(|l| {
            regions(l)
                .iter()
                .map(|r| r["index"].as_u64().expect("index"))
                .collect()
        })
        .collect();
    assert_eq!(got, [[3], [2], [1], [0]]);
}
