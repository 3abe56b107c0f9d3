//! Machine profiles and model units end to end, through the `lamina` command line: a
//! profile's errors name the file, line and field; a part the bed cannot hold is
//! refused with its name and the bed's size; a model in metres is refused with the fix;
//! an inline machine extends a built-in one.

use crate::support::{lamina, text, try_run, write};
use std::path::Path;
use std::process::Output;

/// `lamina run --quiet` of `pipeline` into `out`.
fn run(pipeline: &Path, out: &Path) -> Output {
    try_run(pipeline, out, &[])
}

/// A graded box printed by a machine; `model` and `machine` are TOML lines.
fn pipeline(model: &str, machine: &str) -> String {
    format!(
        r#"name = "box"
{machine}

[model]
use = "box"
{model}

[materials.red]
colour = [255, 0, 0]
[materials.green]
colour = [0, 255, 0]

[grade]
use = "z"
f = "linear"

[slice]
use = "uniform"
thickness = 0.25

[plan]
use = "sequential"
mixing = true

[[output]]
use = "gcode"
path = "box.gcode"
"#
    )
}

#[test]
fn a_part_too_big_for_the_bed_is_refused_with_its_name_and_the_bed_size() {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = write(
        dir.path(),
        "big.toml",
        &pipeline("size = [250.0, 40.0, 2.0]", "machine = \"marlin-mixing-2in1\""),
    );
    let out = run(&p, &dir.path().join("out"));
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
    let err = text(&out.stderr);
    assert!(err.contains("part `part`"), "{err}");
    assert!(err.contains("220 x 220 mm"), "{err}");
    assert!(!dir.path().join("out/box.gcode").exists(), "nothing written");

    let tall = write(
        dir.path(),
        "tall.toml",
        &pipeline("size = [20.0, 20.0, 260.0]", "machine = \"marlin-mixing-2in1\""),
    );
    let out = run(&tall, &dir.path().join("out"));
    assert_eq!(out.status.code(), Some(2));
    assert!(
        text(&out.stderr).contains("builds up to 250 mm"),
        "{}",
        text(&out.stderr)
    );
}

#[test]
fn profile_errors_name_the_file_line_and_field() {
    let dir = tempfile::tempdir().expect("tempdir");
    write(
        dir.path(),
        "printer.toml",
        "base = \"marlin-toolchanger-2\"\nname = \"mine\"\n\n[retraction]\nspeed = -35.0\n",
    );
    let p = write(dir.path(), "p.toml", &pipeline("", "machine = \"printer.toml\""));
    let out = lamina(&["check", &p.to_string_lossy()]);
    assert_eq!(out.status.code(), Some(2));
    let err = text(&out.stderr);
    assert!(err.contains("printer.toml:5:1"), "{err}");
    assert!(err.contains("retraction.speed"), "{err}");

    // Inline: the line in the pipeline.
    let p = write(
        dir.path(),
        "inline.toml",
        &pipeline("", "[machine]\nbase = \"rrf-idex-2\"\nplacement = [900.0, 10.0]"),
    );
    let out = lamina(&["check", &p.to_string_lossy()]);
    assert_eq!(out.status.code(), Some(2));
    let err = text(&out.stderr);
    assert!(err.contains("inline.toml:4:1"), "{err}");
    assert!(err.contains("placement"), "{err}");

    let p = write(dir.path(), "unknown.toml", &pipeline("", "machine = \"prusa\""));
    let out = lamina(&["check", &p.to_string_lossy()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        text(&out.stderr).contains("rrf-idex-2"),
        "lists the built-in profiles"
    );
}

#[test]
fn an_inline_machine_extends_a_builtin_one() {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = write(
        dir.path(),
        "p.toml",
        &pipeline(
            "size = [20.0, 20.0, 1.0]",
            "[machine]\nbase = \"marlin-mixing-2in1\"\nplacement = [60.0, 150.0]\nbed_temperature = 55.0\n\
             [machine.bed]\nmax_height = 100.0",
        ),
    );
    let out_dir = dir.path().join("out");
    let out = run(&p, &out_dir);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let gcode = std::fs::read_to_string(out_dir.join("box.gcode")).expect("gcode");
    assert!(gcode.contains("marlin-mixing-2in1"));
    assert!(gcode.contains("build height 100 mm"));
    assert!(gcode.contains("M140 S55"), "the second layer's bed temperature");
    // The box's corner (0, 0) lands 10 mm left and below the placement point.
    assert!(
        gcode.contains("by X+50.000 Y+140.000"),
        "{}",
        &gcode[..gcode.len().min(800)]
    );
}

#[test]
fn a_model_in_metres_is_refused_with_the_fix_unless_its_units_are_given() {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = write(dir.path(), "m.toml", &pipeline("size = [0.04, 0.03, 0.0156]", ""));
    let out = run(&p, &dir.path().join("out"));
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
    let err = text(&out.stderr);
    assert!(err.contains("is 0.04 mm wide"), "{err}");
    assert!(
        err.contains("is it in metres? set [model] scale = 1000 or units = \"m\""),
        "{err}"
    );

    for fix in ["units = \"m\"", "scale = 1000"] {
        let p = write(
            dir.path(),
            "fixed.toml",
            &pipeline(&format!("size = [0.04, 0.03, 0.002]\n{fix}"), ""),
        );
        let out = run(&p, &dir.path().join("out2"));
        assert!(out.status.success(), "{fix}: {}", text(&out.stderr));
    }

    let p = write(
        dir.path(),
        "km.toml",
        &pipeline("size = [40000.0, 30.0, 2.0]", ""),
    );
    // `check` reads the mesh as the run does, and finds it too.
    for out in [
        lamina(&["check", &p.to_string_lossy()]),
        run(&p, &dir.path().join("out3")),
    ] {
        assert_eq!(out.status.code(), Some(2));
        assert!(
            text(&out.stderr).contains("scale = 0.001"),
            "{}",
            text(&out.stderr)
        );
    }

    let p = write(dir.path(), "bad.toml", &pipeline("units = \"furlong\"", ""));
    let out = lamina(&["check", &p.to_string_lossy()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("units"), "{}", text(&out.stderr));
}

#[test]
fn beads_take_the_machine_nozzle_width_unless_the_plan_names_one() {
    let dir = tempfile::tempdir().expect("tempdir");
    // A 20 mm box graded along Z: loops bent from the nominal width to fill its
    // 10 mm half width with a whole number of beads.
    let run = |plan_width: &str| -> f64 {
        let source = pipeline(
            "size = [20.0, 20.0, 1.0]",
            "[machine]\nbase = \"marlin-mixing-2in1\"\nnozzle_diameter = 0.6",
        )
        .replace(
            "[[output]]\nuse = \"gcode\"\npath = \"box.gcode\"",
            "[[output]]\nuse = \"json\"\npath = \"box.json\"",
        )
        .replace("mixing = true", &format!("mixing = true\n{plan_width}"));
        let p = write(dir.path(), "w.toml", &source);
        let out_dir = dir.path().join(format!("out{}", plan_width.len()));
        let out = run(&p, &out_dir);
        assert!(out.status.success(), "{}", text(&out.stderr));
        let plan: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out_dir.join("box.json")).expect("json"))
                .expect("JSON");
        // The width of the outermost loop of the first layer.
        plan["layers"][0]["toolpaths"]
            .as_array()
            .expect("toolpaths")
            .iter()
            .find(|t| t["kind"] == "extrude" && t.get("widths").is_none())
            .and_then(|t| t["width"].as_f64())
            .expect("a loop")
    };
    let from_machine = run("");
    let named = run("width = 0.4");
    // 10 / 0.6 = 16.7 beads: 17 of 0.588; 10 / 0.4 = 25 beads of 0.4.
    assert!((from_machine - 10.0 / 17.0).abs() < 1e-3, "{from_machine}");
    assert!((named - 0.4).abs() < 1e-3, "{named}");
}

#[test]
fn the_first_layer_takes_the_machine_height_and_layers_stay_within_the_nozzle() {
    let dir = tempfile::tempdir().expect("tempdir");
    // The machine's first layer (0.3 mm), then the pipeline's 0.25 mm layers.
    let source = pipeline(
        "size = [20.0, 20.0, 1.05]",
        "[machine]\nbase = \"marlin-mixing-2in1\"\nfirst_layer = { height = 0.3 }",
    )
    .replace(
        "[[output]]\nuse = \"gcode\"\npath = \"box.gcode\"",
        "[[output]]\nuse = \"json\"\npath = \"box.json\"",
    );
    let p = write(dir.path(), "first.toml", &source);
    let out_dir = dir.path().join("out");
    let out = run(&p, &out_dir);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let plan: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out_dir.join("box.json")).expect("json"))
            .expect("JSON");
    let thickness: Vec<f64> = plan["layers"]
        .as_array()
        .expect("layers")
        .iter()
        .map(|l| l["thickness"].as_f64().expect("thickness"))
        .collect();
    assert_eq!(thickness.len(), 4, "{thickness:?}");
    assert!((thickness[0] - 0.3).abs() < 1e-9, "{thickness:?}");
    assert!(
        thickness[1..].iter().all(|t| (t - 0.25).abs() < 1e-9),
        "{thickness:?}"
    );

    // A layer thicker than the nozzle presses is refused at its key, nothing written.
    let thick = write(
        dir.path(),
        "thick.toml",
        &pipeline("size = [20.0, 20.0, 1.0]", "machine = \"marlin-mixing-2in1\"")
            .replace("thickness = 0.25", "thickness = 0.5"),
    );
    let out_dir = dir.path().join("thick-out");
    let out = run(&thick, &out_dir);
    assert!(!out.status.success());
    let err = text(&out.stderr);
    assert!(
        err.contains("thickness") && err.contains("max_layer_height"),
        "{err}"
    );
    assert!(!out_dir.join("box.gcode").exists());
}

#[test]
fn a_template_that_leaves_relative_moves_on_or_moves_off_the_bed_is_refused_and_a_partial_home_is_completed()
{
    let dir = tempfile::tempdir().expect("tempdir");
    let with_start = |start: &str| {
        pipeline(
            "size = [20.0, 20.0, 1.0]",
            &format!(
                "[machine]\nbase = \"marlin-mixing-2in1\"\n\n[machine.gcode]\nstart = \"\"\"\n{start}\n\"\"\""
            ),
        )
    };
    for (start, want) in [
        (
            "G28\nG91\nG1 Z5 F600",
            "the start template leaves relative positioning (G91) on",
        ),
        (
            "G28\nG1 Z-10 F600",
            "the start template moves off the bed at its line 2 (`G1 Z-10 F600`)",
        ),
        (
            "G28\nG1 X1e300 F600",
            "the start template moves off the bed at its line 2 (`G1 X1e300 F600`)",
        ),
        ("G28\nG1 X500 Y10 F6000", "where the bed spans X 0 to"),
    ] {
        let p = write(dir.path(), "hostile.toml", &with_start(start));
        let out = run(&p, &dir.path().join("out"));
        let err = text(&out.stderr);
        assert!(!out.status.success(), "{start}: {err}");
        assert!(err.contains(want), "{start}: {err}");
        assert!(
            !dir.path().join("out/box.gcode").exists(),
            "{start}: no partial output"
        );
    }
    // `G28 X` homes X alone: the file homes every axis before anything moves.
    let p = write(dir.path(), "partial.toml", &with_start("G28 X\nG1 Z5 F600"));
    let out = run(&p, &dir.path().join("out"));
    assert!(out.status.success(), "{}", text(&out.stderr));
    let gcode = std::fs::read_to_string(dir.path().join("out/box.gcode")).expect("gcode");
    let home = gcode.find("\nG28 ; home all axes").expect("a full home added");
    assert!(
        home < gcode.find("\nG28 X").expect("the template's line"),
        "{}",
        &gcode[..home + 40]
    );
}
