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
                .flat_map(|f| f["regions"].as_array().into_iter().flatten())
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
                    for r in f["regions"].as_array().expect("regions") {
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
            for r in f["regions"].as_array().expect("regions") {
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
}
