//! The `work-cycles` sequencer as a pipeline builds it: where each region's thickness
//! comes from (the `thickness` table, the materials, `auto` from a base cell or the
//! sampled gradient), regions that group parts, heights in whole micrometres, and the
//! refusals that name their key.

use std::path::Path;

use lamina_api::stage::{Sequencer, StageKind};
use lamina_api::{BBox2, Material, MaterialRegion, PartInfo, RunInfo};
use lamina_test_support::{stage, try_stage};

fn sequencer(options: &str) -> Box<dyn Sequencer> {
    stage(StageKind::Sequence, &table(options), Path::new("."))
        .into_type()
        .expect("a sequencer")
}

fn table(options: &str) -> String {
    format!("use = \"work-cycles\"\n{options}")
}

/// The message of the error building `options` gives.
fn refused(options: &str) -> String {
    match try_stage(StageKind::Sequence, &table(options), Path::new(".")) {
        Ok(_) => panic!("{options:?} was accepted"),
        Err(e) => e.to_string(),
    }
}

fn material(name: &str, layer_thickness: Option<f64>) -> Material {
    Material {
        name: name.into(),
        colour: [0, 0, 0],
        layer_thickness,
    }
}

fn part(name: &str, materials: &[usize], z: (f64, f64), z_gradient: Option<f64>) -> PartInfo {
    PartInfo {
        name: name.into(),
        materials: materials.to_vec(),
        mesh: 0,
        z_min: z.0,
        z_max: z.1,
        z_gradient,
    }
}

/// Three parts after the paper's example (cmpm-process-planning 4.1): a microstructure
/// `m` (materials preferring 0.2 mm), an FGM `f` (0.5 mm) and a composite `c`
/// (no preference of its own).
fn info() -> RunInfo {
    RunInfo {
        base_dir: ".".into(),
        materials: vec![
            material("m1", Some(0.2)),
            material("m2", Some(0.3)),
            material("f1", Some(0.5)),
            material("c1", None),
        ],
        parts: vec![
            part("m", &[0, 1], (0.0, 6.0), None),
            part("f", &[2], (0.00049, 4.50051), Some(1.0 / 6.0)),
            part("c", &[3], (1.2344, 6.0), Some(0.0)),
        ],
        z_min: 0.0,
        z_max: 6.0,
        xy_bounds: BBox2::EMPTY,
        machine: None,
        model_frame: None,
    }
}

fn regions(options: &str) -> Vec<MaterialRegion> {
    sequencer(options).sequence(&info()).expect("a sequence").regions
}

/// Message of the error the sequence of `options` ends in.
fn fails(options: &str) -> String {
    match sequencer(options).sequence(&info()) {
        Ok(s) => panic!("{options:?} gave {:?}", s.regions),
        Err(e) => e.to_string(),
    }
}

fn thicknesses(regions: &[MaterialRegion]) -> Vec<(&str, u64)> {
    regions
        .iter()
        .map(|r| (r.name.as_str(), r.thickness_um))
        .collect()
}

#[test]
fn each_part_is_a_region_with_its_materials_thinnest_layer_or_the_default() {
    let r = regions("default_thickness = 1.5");
    assert_eq!(thicknesses(&r), [("m", 200), ("f", 500), ("c", 1500)]);
    assert_eq!(
        r.iter().map(|r| r.parts.clone()).collect::<Vec<_>>(),
        [[0], [1], [2]]
    );
    // Heights in whole micrometres: 0.00049 is 0, 4.50051 is 4.501, 1.2344 is 1.234.
    assert_eq!((r[1].z_start, r[1].z_end), (0.0, 4.501));
    assert_eq!((r[2].z_start, r[2].z_end), (1.234, 6.0));
    assert!(r.iter().all(|r| r.rule.is_none()), "{r:?}");
    // The paper's 0.2 / 0.5 / 1.5 mm: a 3 mm work cycle.
    let sequence = sequencer("default_thickness = 1.5")
        .sequence(&info())
        .expect("a sequence");
    let all = sequence
        .blocks
        .iter()
        .find(|b| b.regions.len() == 3)
        .expect("a block of all three");
    assert_eq!(
        (all.cycle.height_um, all.cycle.steps.len()),
        (3000, 18),
        "{all:?}"
    );
}

#[test]
fn the_thickness_table_overrides_the_materials() {
    let r = regions("default_thickness = 1.5\nthickness = { m = 0.1, c = 1.0 }");
    assert_eq!(thicknesses(&r), [("m", 100), ("f", 500), ("c", 1000)]);
}

#[test]
fn a_part_without_any_thickness_is_refused_at_the_thickness_key() {
    let e = fails("");
    assert!(
        e.contains("part `c` has no layer thickness") && e.contains("default_thickness"),
        "{e}"
    );
    // Materials whose preference is no whole micrometre.
    let mut odd = info();
    odd.materials[2].layer_thickness = Some(0.0005);
    let e = match sequencer("default_thickness = 1.5").sequence(&odd) {
        Ok(s) => panic!("{:?}", s.regions),
        Err(e) => e.to_string(),
    };
    assert!(e.contains("layer_thickness of part `f`'s materials"), "{e}");
}

#[test]
fn auto_thicknesses_come_from_the_base_cell_or_the_sampled_gradient() {
    let options = "default_thickness = 1.5\nbase_cell = { m = 3.0 }\nthickness = { m = \"auto\", f = \"auto\", c = \"auto\" }";
    let r = regions(options);
    // A twentieth of the 3 mm cell; 0.1 / (1/6) = 0.6 mm; constant: 2 mm.
    assert_eq!(thicknesses(&r), [("m", 150), ("f", 600), ("c", 2000)]);
    let rules: Vec<&str> = r.iter().map(|r| r.rule.as_deref().expect("a rule")).collect();
    assert_eq!(rules[0], "auto: 1/20 of the 3 mm base cell");
    assert_eq!(
        rules[1],
        "auto: fractions change by up to 0.1667 per mm, 0.1 per layer"
    );
    assert_eq!(rules[2], "auto: constant composition");
    // A larger step allows thicker layers, within 2 mm.
    let r = regions(&format!("{options}\nstep = 0.25"));
    assert_eq!(thicknesses(&r)[1], ("f", 1500));
    // Only a graded `auto` needs the gradients sampled.
    assert!(sequencer(options).needs_gradients());
    assert!(!sequencer("base_cell = { m = 3.0 }\nthickness = { m = \"auto\" }").needs_gradients());
    assert!(!sequencer("thickness = { m = 0.2 }").needs_gradients());
    assert!(!sequencer("").needs_gradients());
    let grouped = "regions = [{ name = \"all\", parts = [\"m\", \"f\", \"c\"], thickness = \"auto\" }]";
    assert!(sequencer(grouped).needs_gradients());
    assert!(!sequencer(&format!("{grouped}\nbase_cell = {{ all = 1.0 }}")).needs_gradients());
    let fixed = "regions = [{ name = \"all\", parts = [\"m\", \"f\", \"c\"], thickness = 0.5 }]";
    assert!(!sequencer(fixed).needs_gradients());
}

#[test]
fn a_base_cell_under_ten_micrometres_is_refused() {
    let e = fails("default_thickness = 1.5\nbase_cell = { m = 0.005 }\nthickness = { m = \"auto\" }");
    assert!(e.contains("base cell of 0.005 mm is under 10 µm"), "{e}");
}

#[test]
fn regions_group_parts_at_the_thinnest_of_theirs_or_their_own_thickness() {
    let r = regions(
        "default_thickness = 1.5\nregions = [\
         { name = \"skin\", parts = [\"c\", \"f\"] },\
         { name = \"core\", parts = [\"m\"], thickness = 0.4 }]",
    );
    assert_eq!(thicknesses(&r), [("skin", 500), ("core", 400)]);
    assert_eq!(r[0].parts, [2, 1]);
    assert_eq!(r[1].parts, [0]);
    // The span of its parts: f from 0, c up to 6.
    assert_eq!((r[0].z_start, r[0].z_end), (0.0, 6.0));
    // `auto` over the region's parts: the steepest gradient (f's) rules.
    let r = regions("regions = [{ name = \"all\", parts = [\"m\", \"f\", \"c\"], thickness = \"auto\" }]");
    assert_eq!(thicknesses(&r), [("all", 600)]);
    assert!(
        r[0].rule.as_deref().is_some_and(|w| w.contains("0.1667")),
        "{r:?}"
    );
    let r = regions(
        "regions = [{ name = \"all\", parts = [\"m\", \"f\", \"c\"], thickness = \"auto\" }]\n\
         base_cell = { all = 1.0 }",
    );
    assert_eq!(thicknesses(&r), [("all", 100)]);
    assert_eq!(r[0].rule.as_deref(), Some("auto: 1/10 of the 1 mm base cell"));
}

#[test]
fn regions_that_miss_or_repeat_a_part_are_refused() {
    let cases = [
        (
            "regions = [{ name = \"a\", parts = [\"m\", \"f\", \"x\"] }]",
            "no part named `x` (parts: m, f, c)",
        ),
        (
            "default_thickness = 1.5\nregions = [{ name = \"a\", parts = [\"m\", \"f\"] }, { name = \"b\", parts = [\"f\", \"c\"] }]",
            "part `f` is in both region `a` and region `b`",
        ),
        (
            "default_thickness = 1.5\nregions = [{ name = \"a\", parts = [\"m\", \"f\"] }]",
            "part `c` is in no region",
        ),
        (
            "regions = [{ name = \"a\", parts = [] }]",
            "region `a` lists no parts",
        ),
        (
            "default_thickness = 1.5\nthickness = { x = 0.2 }",
            "no part named `x`",
        ),
        (
            "default_thickness = 1.5\nbase_cell = { x = 1.0 }",
            "no part or region named `x`",
        ),
    ];
    for (options, says) in cases {
        let e = fails(options);
        assert!(e.contains(says), "{options}: {e}");
    }
    // A region's name is known to `base_cell`.
    let r = regions(
        "default_thickness = 1.5\nbase_cell = { all = 1.0 }\n\
         regions = [{ name = \"all\", parts = [\"m\", \"f\", \"c\"], thickness = 0.5 }]",
    );
    assert_eq!(thicknesses(&r), [("all", 500)]);
}

#[test]
fn thicknesses_that_are_no_whole_micrometre_or_no_auto_are_refused_when_built() {
    let cases = [
        ("default_thickness = 0.0005", "default_thickness"),
        (
            "thickness = { m = 0.00025 }",
            "`m`: 0.00025 mm is not a whole number of micrometres",
        ),
        (
            "thickness = { m = \"thin\" }",
            "`m`: `thin` is neither a number of mm nor \"auto\"",
        ),
        (
            "regions = [{ name = \"a\", parts = [\"m\"], thickness = \"thin\" }]",
            "region `a`: `thin` is neither",
        ),
        (
            "regions = [{ name = \"a\", parts = [\"m\"], thickness = -1.0 }]",
            "region `a`: -1 is not a positive number of mm",
        ),
        (
            "base_cell = { m = 0.0 }",
            "`m`: the base cell must be a positive number of mm",
        ),
        (
            "base_cell = { m = 2000.0 }",
            "`m`: the base cell must be a positive number of mm",
        ),
    ];
    for (options, says) in cases {
        let e = refused(options);
        assert!(e.contains(says), "{options}: {e}");
    }
    // The bounds themselves are accepted.
    for options in [
        "base_cell = { m = 1000.0 }",
        "thickness = { m = \"auto\" }",
        "regions = [{ name = \"a\", parts = [\"m\"], thickness = \"auto\" }]",
    ] {
        try_stage(StageKind::Sequence, &table(options), Path::new("."))
            .unwrap_or_else(|e| panic!("{options}: {e}"));
    }
}

#[test]
fn a_step_outside_its_range_is_refused_at_its_key() {
    for step in ["0.0", "1.5", "nan"] {
        let e = refused(&format!("step = {step}"));
        assert!(e.contains("step"), "{step}: {e}");
    }
}
