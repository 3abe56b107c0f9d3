//! The G-code of every flavour, read back by a third-party parser (the `gcode` crate):
//! the extrusion it commands adds up to the planned bead volumes within 1 %, and each
//! flavour's mixing or tool commands are where they belong.

mod support;

use fastrand::Rng;

use lamina_core::{Composition, LayerPlan, PathKind, Point2, Registry, RunInfo, TimedPoint, Toolpath};

fn info() -> RunInfo {
    support::run_info(["red", "green"], "p".into(), lamina_core::BBox2::EMPTY, None)
}

/// Layers of random extrusions (two tools, graded compositions), travels and pauses.
fn layers(seed: u64) -> Vec<LayerPlan> {
    let mut rng = Rng::with_seed(seed);
    (0..3)
        .map(|index| {
            let mut t = 0.0;
            let mut toolpaths = Vec::new();
            for k in 0..12 {
                let tool = k % 2;
                let n = 2 + (rng.f64() * 6.0) as usize;
                let mut points = Vec::new();
                for _ in 0..n {
                    let p = Point2::new(rng.f64() * 40.0, rng.f64() * 40.0);
                    t += 0.5;
                    points.push(TimedPoint { p, t });
                }
                let f = (rng.f64() * 10.0).floor() / 9.0;
                let kind = if k % 5 == 4 {
                    PathKind::Travel
                } else {
                    PathKind::Extrude
                };
                toolpaths.push(Toolpath {
                    tool,
                    material: None,
                    kind,
                    points: points.clone(),
                    width: if kind == PathKind::Extrude {
                        0.4 + rng.f64() * 0.2
                    } else {
                        0.0
                    },
                    widths: Vec::new(),
                    composition: (kind == PathKind::Extrude)
                        .then(|| Composition::binary(f.min(1.0)).expect("valid")),
                    part: Some(0),
                    sub_region: Some(k),
                });
                if k % 4 == 3 {
                    let p = points[points.len() - 1].p;
                    toolpaths.push(Toolpath {
                        tool,
                        material: None,
                        kind: PathKind::Pause,
                        points: vec![TimedPoint { p, t }, TimedPoint { p, t: t + 1.0 }],
                        width: 0.0,
                        widths: Vec::new(),
                        composition: None,
                        part: None,
                        sub_region: None,
                    });
                }
            }
            support::layer_plan(index, toolpaths, t)
        })
        .collect()
}

fn export(table: &str, plans: &[LayerPlan]) -> String {
    support::export(table, &info(), plans, "test").expect("exports")
}

/// The parsed program. gcode 0.6 reports some commands twice, first without their
/// arguments, then with them (same start): the complete one is kept.
fn parse(text: &str) -> Vec<gcode::GCode> {
    let mut out: Vec<gcode::GCode> = Vec::new();
    for c in gcode::parse(text) {
        if let Some(last) = out.last_mut()
            && last.span().start == c.span().start
        {
            *last = c;
            continue;
        }
        out.push(c);
    }
    out
}

/// Filament the parsed program feeds on moves in the plane (not retractions), by the
/// E words in absolute or relative mode (M82 / M83, G92 resets).
fn parsed_feed(text: &str) -> f64 {
    let mut relative = false;
    let mut e = 0.0f64;
    let mut fed = 0.0;
    for code in parse(text) {
        match (code.mnemonic(), code.major_number()) {
            (gcode::Mnemonic::Miscellaneous, 82) => relative = false,
            (gcode::Mnemonic::Miscellaneous, 83) => relative = true,
            (gcode::Mnemonic::General, 92) => {
                if let Some(v) = code.value_for('E') {
                    e = f64::from(v);
                }
            }
            (gcode::Mnemonic::General, 1) => {
                let Some(v) = code.value_for('E') else { continue };
                let de = if relative { f64::from(v) } else { f64::from(v) - e };
                if !relative {
                    e = f64::from(v);
                }
                if code.value_for('X').is_some() || code.value_for('Y').is_some() {
                    fed += de;
                }
            }
            _ => {}
        }
    }
    fed
}

fn planned_feed(plans: &[LayerPlan], diameter: f64) -> f64 {
    let area = std::f64::consts::PI * diameter * diameter / 4.0;
    plans
        .iter()
        .flat_map(|p| {
            p.toolpaths
                .iter()
                .filter(|t| t.kind == PathKind::Extrude)
                .map(|t| t.length() * t.width * p.thickness / area)
        })
        .sum()
}

fn codes(text: &str, mnemonic: gcode::Mnemonic, number: u32) -> usize {
    parse(text)
        .into_iter()
        .filter(|c| c.mnemonic() == mnemonic && c.major_number() == number)
        .count()
}

#[test]
fn parsed_extrusion_matches_the_planned_volumes_in_every_flavour() {
    for seed in [1u64, 7, 42] {
        let plans = layers(seed);
        for (table, diameter) in [
            ("use = \"gcode\"\nflavor = \"tool-change\"", 1.75),
            (
                "use = \"gcode\"\nflavor = \"tool-change\"\nrelative_e = true\nfilament_diameter = 2.85",
                2.85,
            ),
            ("use = \"gcode\"\nflavor = \"marlin-mixing\"", 1.75),
            (
                "use = \"gcode\"\nflavor = \"marlin-mixing\"\ndirect_mixing = true\nrelative_e = true",
                1.75,
            ),
            ("use = \"gcode\"\nflavor = \"reprap-mixing\"", 1.75),
        ] {
            let text = export(table, &plans);
            let parsed = parsed_feed(&text);
            let planned = planned_feed(&plans, diameter);
            assert!(planned > 0.0);
            assert!(
                (parsed - planned).abs() <= 0.01 * planned,
                "{table} seed {seed}: parsed {parsed} vs planned {planned}"
            );
        }
    }
}

#[test]
fn each_flavour_writes_its_own_commands() {
    use gcode::Mnemonic::{Miscellaneous as M, ToolChange as T};
    let plans = layers(3);
    let tc = export("use = \"gcode\"\nflavor = \"tool-change\"", &plans);
    assert!(codes(&tc, T, 0) > 0 && codes(&tc, T, 1) > 0, "T0 and T1");
    assert!(codes(&tc, M, 109) >= 2, "temperatures");
    assert_eq!(codes(&tc, M, 163), 0);
    assert!(tc.starts_with("; generated by Lamina"));

    let marlin = export("use = \"gcode\"\nflavor = \"marlin-mixing\"", &plans);
    let m163 = codes(&marlin, M, 163);
    let m164 = codes(&marlin, M, 164);
    assert!(
        m164 > 1 && m163 == 2 * m164,
        "{m163} M163 for {m164} M164 on two channels"
    );
    // The fractions of each mix add up to 1.
    let mut sum = 0.0;
    for c in parse(&marlin) {
        if c.mnemonic() == M && c.major_number() == 163 {
            sum += c.value_for('P').unwrap_or(0.0);
        }
        if c.mnemonic() == M && c.major_number() == 164 {
            assert!((sum - 1.0).abs() < 1e-4, "{sum}");
            sum = 0.0;
        }
    }

    let direct = export(
        "use = \"gcode\"\nflavor = \"marlin-mixing\"\ndirect_mixing = true",
        &plans,
    );
    assert!(codes(&direct, M, 165) > 1);
    for c in parse(&direct)
        .into_iter()
        .filter(|c| c.mnemonic() == M && c.major_number() == 165)
    {
        let s = c.value_for('A').unwrap_or(0.0) + c.value_for('B').unwrap_or(0.0);
        assert!((s - 1.0).abs() < 1e-4, "{s}");
    }

    let rrf = export("use = \"gcode\"\nflavor = \"reprap-mixing\"", &plans);
    assert_eq!(codes(&rrf, M, 563), 1);
    assert!(codes(&rrf, M, 567) > 1);
    assert!(rrf.contains("M563 P0 D0:1 H1"));
}

#[test]
fn bad_options_are_refused_with_their_key() {
    use lamina_gcode as _;
    let registry = Registry::linked().expect("registry");
    let dir = std::env::temp_dir();
    let scripts = lamina_core::script::local(&dir, Default::default());
    for (text, key) in [
        ("use = \"gcode\"\nfilament_diameter = -1.0", "filament_diameter"),
        (
            "use = \"gcode\"\nflavor = \"tool-change\"\ndirect_mixing = true",
            "direct_mixing",
        ),
        ("use = \"gcode\"\nflavor = \"klipper\"", "flavor"),
    ] {
        let table = lamina_core::pipeline::TableRef::parse_snippet("gcode", text).expect("table");
        let err = registry
            .build::<dyn lamina_core::Exporter>(&table, &scripts, &dir)
            .err()
            .unwrap_or_else(|| panic!("{text} accepted"));
        assert!(
            err.to_string().contains(key) || format!("{err:?}").contains(key),
            "{err}"
        );
    }
}
