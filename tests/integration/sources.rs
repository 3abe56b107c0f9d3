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
        .flat_map(|f| f["sub_regions"].as_array().expect("regions"))
        .collect()
}

/// Also with `step` left out: its default is the paper's t_g = 0.25.
/// A pipeline: a box of `size` on the bed's centre, in materials `a` and `b`, cut into
/// 1 mm layers and discretised by `sources` with `options` (the lines of its table
/// after `use`), its plan written to `plan.json`.
fn graded_box(size: [f64; 3], options: &str) -> String {
    format!(
        "[model]\nuse = \"box\"\nsize = [{:?}, {:?}, {:?}]\nplace = \"centre\"\n\
        [materials.a]\ncolour = [255, 0, 0]\n[materials.b]\ncolour = [0, 0, 255]\n\
        [discretise]\nuse = \"sources\"\n{options}\n\
        [slice]\nuse = \"uniform\"\nthickness = 1.0\n\
        [[output]]\nuse = \"json\"\npath = \"plan.json\"\n",
        size[0], size[1], size[2]
    )
}

#[test]
fn an_axis_source_steps_in_rings_of_the_right_area() {
    for step in [", step = 0.25", ""] {
        axis_source_rings(step);
    }
}

fn axis_source_rings(step: &str) {
    let plan = run(&graded_box(
        [40.0, 40.0, 2.0],
        &format!(
            "sources = [{{ kind = \"axis\", at = [0.0, 0.0, 0.0], width = 16.0, start = \"a\", end = \"b\"{step} }}]"
        ),
    ));
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

/// A 20 x 20 x 10 mm box in 1 mm layers graded from its outer surface by `source`:
/// per layer (mid-plane z), the regions' (level, area) in level order.
fn box_graded_from_its_surface(source: &str) -> Vec<(f64, Vec<(f64, f64)>)> {
    let text = format!(
        "[model]\nuse = \"box\"\nsize = [20.0, 20.0, 10.0]\nplace = \"centre\"\n\
         [materials.a]\ncolour = [255, 0, 0]\n[materials.b]\ncolour = [0, 0, 255]\n\
         [discretise]\nuse = \"sources\"\nsources = [{source}]\n\
         [slice]\nuse = \"uniform\"\nthickness = 1.0\n\
         [[output]]\nuse = \"json\"\npath = \"plan.json\"\n"
    );
    let plan = run(&text);
    plan["layers"]
        .as_array()
        .expect("layers")
        .iter()
        .map(|layer| {
            let z = layer["z"].as_f64().expect("z") - 0.5;
            let mut rs: Vec<(f64, f64)> = regions(layer)
                .iter()
                .map(|r| {
                    (
                        r["level"].as_f64().expect("level"),
                        r["area"].as_f64().expect("area"),
                    )
                })
                .collect();
            rs.sort_by(|a, b| a.0.total_cmp(&b.0));
            (z, rs)
        })
        .collect()
}

/// Fig. 1d, d = the minimum distance from the *selected* outer surfaces: the bottom
/// face alone grades the box along Z, each layer whole at the step of its height
/// (f = z / 8 in steps of 0.25, thresholds at z = 1, 3, 5, 7).
#[test]
fn a_surface_source_from_the_bottom_face_grades_along_z() {
    let layers = box_graded_from_its_surface(
        "{ kind = \"surface\", faces = { normal = [0.0, 0.0, -1.0] }, width = 8.0, start = \"a\", end = \"b\", step = 0.25 }",
    );
    assert_eq!(layers.len(), 10);
    for (z, rs) in &layers {
        let want = truncated(*z, 8.0, 0.25);
        assert_eq!(rs.len(), 1, "z = {z}: {rs:?}");
        assert_eq!(rs[0].0, want, "z = {z}");
        assert!((rs[0].1 - 400.0).abs() < 1e-6, "z = {z}: {rs:?}");
    }
}

/// With every face, d is the distance in space to the whole outer surface: the bottom
/// layer lies within 1 mm of the bottom face and is one region of the first step,
/// while a middle layer is cut into the bands of the side walls (d < 1, 1 <= d < 3, the
/// core). Measured within the layer (`measure = "layer"`), every layer has the bands.
#[test]
fn a_surface_source_measures_in_space_from_every_face() {
    let source = "{ kind = \"surface\", width = 4.0, start = \"a\", end = \"b\", step = 0.5 }";
    let bands = [(0.0, 400.0 - 324.0), (0.5, 324.0 - 196.0), (1.0, 196.0)];
    let close = |got: &[(f64, f64)], want: &[(f64, f64)]| {
        got.len() == want.len()
            && got
                .iter()
                .zip(want)
                .all(|(g, w)| g.0 == w.0 && (g.1 - w.1).abs() < 0.02 * w.1)
    };
    let space = box_graded_from_its_surface(source);
    let (z, bottom) = &space[0];
    assert_eq!(*z, 0.5);
    assert_eq!(bottom.len(), 1, "{bottom:?}");
    assert_eq!(bottom[0].0, 0.0);
    // The second layer (z = 1.5): the walls' bands, and the bottom face 1.5 mm below
    // the core puts it in the middle step.
    let (_, second) = &space[1];
    assert!(close(second, &[(0.0, 76.0), (0.5, 324.0)]), "{second:?}");
    let (z, middle) = &space[4];
    assert_eq!(*z, 4.5);
    assert!(close(middle, &bands), "{middle:?}");
    let layer = box_graded_from_its_surface(&source.replace(" }", ", measure = \"layer\" }"));
    for (z, rs) in &layer {
        assert!(close(rs, &bands), "in the layer, z = {z}: {rs:?}");
    }
}

/// A plane through the middle of a box, normal +x: behind it lies the -ve
/// complementary region (f(d) < 0, grading-step-width Eq. 3), where the composition is
/// the start composition Ms (Eq. 5) throughout; in front, Eq. 4 in steps of t_g up to
/// the width, and Me beyond it (Eq. 6, the +ve region).
#[test]
fn behind_a_plane_the_composition_is_the_start_one() {
    for combine in ["intersection", "everywhere"] {
        let plan = run(&graded_box(
            [40.0, 40.0, 2.0],
            &format!(
                "combine = \"{combine}\"\n\
                sources = [{{ kind = \"plane\", at = [0.0, 0.0, 0.0], direction = [1.0, 0.0, 0.0], width = 10.0, start = [0.75, 0.25], end = [0.0, 1.0], step = 0.25 }}]"
            ),
        ));
        for layer in plan["layers"].as_array().expect("layers") {
            let mut behind = 0;
            let mut by_a: Vec<(f64, f64)> = Vec::new();
            for r in regions(layer) {
                let a = r["composition"]["a"].as_f64().expect("a");
                let area = r["area"].as_f64().expect("area");
                let x = r["reference"][0].as_f64().expect("x");
                // Every point of a region behind the plane has Ms.
                let xs: Vec<f64> = r["polygon"]["outer"]
                    .as_array()
                    .expect("outer")
                    .iter()
                    .map(|p| p[0].as_f64().expect("x"))
                    .collect();
                if xs.iter().any(|&x| x < -1e-9) {
                    assert_eq!(
                        a, 0.75,
                        "{combine}: a region reaching behind the plane (reference x = {x}) has a = {a}"
                    );
                    behind += 1;
                }
                by_a.push((a, area));
            }
            assert_eq!(behind, 1, "{combine}: one region behind the plane");
            by_a.sort_by(|p, q| q.0.total_cmp(&p.0));
            // Ms behind the plane and on the first half step (x < 1.25); then
            // 0.5625, 0.375, 0.1875 on bands of 2.5 mm; Me from x = 8.75 on.
            let want = [
                (0.75, 21.25 * 40.0),
                (0.5625, 100.0),
                (0.375, 100.0),
                (0.1875, 100.0),
                (0.0, 11.25 * 40.0),
            ];
            assert_eq!(by_a.len(), want.len(), "{combine}: {by_a:?}");
            for ((a, area), (wa, warea)) in by_a.iter().zip(want) {
                assert!((a - wa).abs() < 1e-12, "{combine}: {by_a:?}");
                assert!(
                    (area - warea).abs() < 1e-6 * 1600.0,
                    "{combine}: a = {a}: {area} mm² vs {warea}"
                );
            }
        }
    }
}

/// A source's composition names the part's materials, or as many fractions as it has;
/// otherwise the run fails naming the source (counted from 0) and what is wrong.
#[test]
fn a_source_whose_composition_the_part_cannot_take_is_an_error_naming_it() {
    let cases = [
        ("\"c\"", "source 1: part `box` has no material `c`"),
        (
            "[0.5, 0.3, 0.2]",
            "source 1: 3 fractions, part `box` has 2 materials",
        ),
        ("[1.0]", "source 1: 1 fractions, part `box` has 2 materials"),
    ];
    for (start, message) in cases {
        let text = graded_box(
            [10.0, 10.0, 1.0],
            &format!(
                "sources = [{{ kind = \"point\", at = [0.0, 0.0, 0.0], width = 4.0, start = \"a\", end = \"b\" }}, \
                {{ kind = \"point\", at = [2.0, 0.0, 0.0], width = 4.0, start = {start}, end = \"b\" }}]"
            ),
        ) + "[[parts]]\nname = \"box\"\nmaterials = [\"a\", \"b\"]\n";
        let dir = tempfile::tempdir().expect("tempdir");
        let out = crate::support::try_run_text(dir.path(), &text);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{start}: the run passed");
        assert!(stderr.contains(message), "{start}: {stderr}");
        assert!(
            !dir.path().join("out/plan.json").exists(),
            "{start}: a plan was written"
        );
    }
}

/// Each way a source can be wrong is refused when the stage is built, at the key
/// `sources`, naming the source (counted from 0) and what is wrong with it.
#[test]
fn a_source_that_cannot_grade_is_refused_naming_it() {
    use lamina_core::stage::StageKind;
    let good = "{ kind = \"point\", at = [0.0, 0.0, 0.0], width = 4.0, start = \"a\", end = \"b\" }";
    let cases = [
        (
            "kind = \"point\", at = [1e300, 0.0, 0.0], width = 4.0",
            "`at` must be three numbers within",
        ),
        (
            "kind = \"axis\", at = [0.0, 0.0, 0.0], direction = [0.0, 0.0, 0.0], width = 4.0",
            "`direction` must be a non-zero vector",
        ),
        (
            "kind = \"plane\", at = [0.0, 0.0, 0.0], direction = [0.0, 0.0, 0.0], width = 4.0",
            "`direction` (the normal) must be a non-zero vector",
        ),
        (
            "kind = \"surface\", measure = \"layer\", faces = { normal = [0.0, 0.0, 1.0] }, width = 4.0",
            "`faces` are chosen on the mesh",
        ),
        (
            "kind = \"point\", at = [0.0, 0.0, 0.0]",
            "give `width` (mm over which f runs from 0 to 1) or `alpha`",
        ),
        (
            "kind = \"point\", at = [0.0, 0.0, 0.0], width = 4.0, alpha = 0.25",
            "give either `width` (positive) or `alpha`, not both",
        ),
        (
            "kind = \"point\", at = [0.0, 0.0, 0.0], width = -4.0",
            "give either `width` (positive) or `alpha`, not both",
        ),
        (
            "kind = \"point\", at = [0.0, 0.0, 0.0], alpha = 1e-9",
            "`alpha` must be at least 1e-6 per mm",
        ),
        (
            "kind = \"point\", at = [0.0, 0.0, 0.0], width = 0.0",
            "give either `width` (positive) or `alpha`, not both",
        ),
        (
            "kind = \"point\", at = [0.0, 0.0, 0.0], width = 4.0, k = 0.0",
            "`k` must be a positive number",
        ),
        (
            "kind = \"point\", at = [0.0, 0.0, 0.0], width = 4.0, weight = 0.0",
            "`weight` must be a positive number",
        ),
        (
            "kind = \"point\", at = [0.0, 0.0, 0.0], width = 4.0, measure = \"layer\"",
            "`faces` and `measure` belong to `kind = \"surface\"`",
        ),
        (
            "kind = \"plane\", at = [0.0, 0.0, 0.0], width = 4.0, faces = { normal = [0.0, 0.0, 1.0] }",
            "`faces` and `measure` belong to `kind = \"surface\"`",
        ),
    ];
    for (spec, message) in cases {
        let table =
            format!("use = \"sources\"\nsources = [{good}, {{ {spec}, start = \"a\", end = \"b\" }}]");
        let error = match lamina_test_support::try_stage(StageKind::Discretise, &table, Path::new(".")) {
            Ok(_) => panic!("{spec}: built"),
            Err(e) => e.to_string(),
        };
        assert!(error.contains("sources"), "{spec}: {error}");
        assert!(error.contains(&format!("source 1: {message}")), "{spec}: {error}");
    }
    // One well-made source builds.
    let table = format!("use = \"sources\"\nsources = [{good}]");
    assert!(lamina_test_support::try_stage(StageKind::Discretise, &table, Path::new(".")).is_ok());
}

/// The mesh is handed to the stage only where a source measures in space from the
/// part's faces: a point source and a surface source measured in the layer do without.
#[test]
fn only_a_surface_source_measured_in_space_reads_the_mesh() {
    let cases = [
        ("kind = \"point\", at = [0.0, 0.0, 0.0]", false),
        ("kind = \"surface\", measure = \"layer\"", false),
        ("kind = \"surface\"", true),
    ];
    for (spec, reads) in cases {
        let table = format!(
            "use = \"sources\"\nsources = [{{ kind = \"axis\", at = [0.0, 0.0, 0.0], width = 4.0, start = \"a\", end = \"b\" }}, \
             {{ {spec}, width = 4.0, start = \"a\", end = \"b\" }}]"
        );
        assert_eq!(
            lamina_test_support::discretiser(&table).reads_mesh(),
            reads,
            "{spec}"
        );
    }
}

/// Behind a plane the plane's source does not grade (its effective region is
/// 0 <= f <= 1, Eq. 3 puts the back at f < 0), so a point source there is on its own
/// (Eq. 8 over the effective sources): at its centre its start composition alone, pure
/// `a`, not blended with the plane's Ms. The point lies at the layer's mid-height, where
/// the distance in space is measured.
#[test]
fn behind_a_plane_another_source_grades_alone() {
    let plan = run(&graded_box(
        [40.0, 40.0, 1.0],
        "sources = [{ kind = \"plane\", at = [0.0, 0.0, 0.0], direction = [1.0, 0.0, 0.0], width = 10.0, start = [0.75, 0.25], end = [0.0, 1.0] }, \
        { kind = \"point\", at = [-10.0, 0.0, 0.5], width = 4.0, start = \"a\", end = \"b\" }]",
    ));
    for layer in plan["layers"].as_array().expect("layers") {
        // f = d / 4 below the first half step (d < 0.5 mm): a disc of radius 0.5.
        let pure: Vec<f64> = regions(layer)
            .iter()
            .filter(|r| r["composition"]["a"].as_f64() == Some(1.0))
            .map(|r| r["area"].as_f64().expect("area"))
            .collect();
        let disc = std::f64::consts::PI * 0.25;
        assert!(
            pure.len() == 1 && (pure[0] - disc).abs() < 1e-3 * disc,
            "the point source's centre: {pure:?} mm², want {disc}"
        );
    }
}

/// `alpha` is the inverse of `width`, and a direction is only a direction: a plane
/// given by `alpha = 0.1` and the normal [3, 0, 0] grades as one given by `width = 10`
/// and [1, 0, 0].
#[test]
fn a_source_by_alpha_and_any_length_of_direction_is_the_source_by_width() {
    let plan = |spec: &str| {
        let plan = run(&graded_box(
            [40.0, 40.0, 1.0],
            &format!(
                "sources = [{{ kind = \"plane\", at = [0.0, 0.0, 0.0], {spec}, start = \"a\", end = \"b\" }}]"
            ),
        ));
        let layers = plan["layers"].as_array().expect("layers");
        layers.iter().map(|l| l["parts"].clone()).collect::<Vec<_>>()
    };
    let by_width = plan("direction = [1.0, 0.0, 0.0], width = 10.0");
    let by_alpha = plan("direction = [3.0, 0.0, 0.0], alpha = 0.1");
    assert_eq!(by_width, by_alpha);
    // Steps in front of the plane and the back: the source did grade.
    let regions = by_width[0][0]["families"][0]["sub_regions"]
        .as_array()
        .map(Vec::len);
    assert!(regions.is_some_and(|n| n >= 4), "{regions:?}");
}
