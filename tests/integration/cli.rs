//! The `lamina` command line as users and scripts rely on it: exit codes, error
//! positions, listings, and outputs that do not depend on the thread count.

use crate::support::{box_stl, lamina, pipelines, text, try_run, write};
use std::path::{Path, PathBuf};
use std::process::Output;

#[test]
fn version_is_printed() {
    let out = lamina(&["--version"]);
    assert!(out.status.success());
    assert!(text(&out.stdout).contains(env!("CARGO_PKG_VERSION")));
}

#[test]
fn plugins_lists_the_built_in_stages_of_every_kind() {
    let out = lamina(&["plugins", "--json"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let list: serde_json::Value = serde_json::from_slice(&out.stdout).expect("json");
    let names: Vec<String> = list
        .as_array()
        .expect("array")
        .iter()
        .map(|e| {
            format!(
                "{}:{}",
                e["kind"].as_str().unwrap_or(""),
                e["name"].as_str().unwrap_or("")
            )
        })
        .collect();
    for expected in [
        "model:stl",
        "model:obj",
        "model:3mf",
        "model:gear",
        "model:gear-shaft",
        "model:tube",
        "model:box",
        "model:cube",
        "model:blade",
        "orient:candidates",
        "slice:uniform",
        "slice:adaptive",
        "sort:hierarchy",
        "discretise:offset",
        "discretise:sources",
        "grade:z",
        "grade:xy",
        "grade:idw",
        "sequence:work-cycles",
        "export:json",
        "export:cli",
        "export:bitmap",
        "export:3mf",
    ] {
        assert!(
            names.contains(&expected.to_string()),
            "{expected} missing from {names:?}"
        );
    }
    for e in list.as_array().expect("array") {
        assert!(
            !e["doc"].as_str().unwrap_or("").is_empty(),
            "undocumented stage {e}"
        );
    }
}

#[test]
fn misspelled_key_is_located_and_exits_2() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = write(
        dir.path(),
        "bad.toml",
        "[model]\nuse = \"box\"\n\n[materials.a]\ncolour = [1, 2, 3]\n\n[slice]\nuse = \"uniform\"\nthicknes = 0.3\n",
    );
    let err = refused(&path);
    assert!(err.contains("bad.toml:9:1"), "{err}");
    assert!(err.contains("thicknes"), "{err}");
}

#[test]
fn unknown_stage_lists_the_available_ones() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = write(
        dir.path(),
        "p.toml",
        "[model]\nuse = \"box\"\n[materials.a]\ncolour = [1, 2, 3]\n[slice]\nuse = \"unifrom\"\n",
    );
    let err = refused(&path);
    assert!(err.contains("p.toml:6:1"), "{err}");
    assert!(err.contains("uniform"), "{err}");
}

#[test]
fn missing_model_file_is_a_mistake_in_the_pipeline_and_leaves_nothing() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = write(
        dir.path(),
        "p.toml",
        "[model]\nfile = \"nothing.stl\"\n[materials.a]\ncolour = [1, 2, 3]\n[[output]]\nuse = \"json\"\n",
    );
    let out_dir = dir.path().join("out");
    let out = lamina(&[
        "run",
        path.to_str().expect("utf-8"),
        "--out",
        out_dir.to_str().expect("utf-8"),
    ]);
    // Found while the pipeline is built, as `check` finds it: exit code 2, the field.
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
    assert!(text(&out.stderr).contains("nothing.stl"));
    assert!(text(&out.stderr).contains("p.toml:2:1"), "{}", text(&out.stderr));
    assert!(!out_dir.join("plan.json").exists());
}

#[test]
fn thread_count_does_not_change_the_output() {
    let dir = tempfile::tempdir().expect("tempdir");
    let pipeline = pipelines().join("assembly.toml");
    let mut outputs = Vec::new();
    for threads in ["1", "2"] {
        let out_dir = dir.path().join(threads);
        let out = lamina(&[
            "run",
            pipeline.to_str().expect("utf-8"),
            "--out",
            out_dir.to_str().expect("utf-8"),
            "--threads",
            threads,
            "--quiet",
            "--set",
            "slice.thickness=0.1",
        ]);
        assert!(out.status.success(), "{}", text(&out.stderr));
        outputs.push(std::fs::read(out_dir.join("assembly.json")).expect("written"));
    }
    assert!(!outputs[0].is_empty());
    assert!(outputs[0] == outputs[1], "outputs differ between 1 and 2 threads");
}

/// `lamina check <path>`, which must exit 2 (a usage error); its error output.
fn refused(path: &Path) -> String {
    let out = lamina(&["check", path.to_str().expect("utf-8")]);
    assert_eq!(out.status.code(), Some(2));
    text(&out.stderr)
}

const SCRIPTED: &str = "[model]\nuse = \"tube\"\nheight = 1.0\n[materials.a]\ncolour = [255, 0, 0]\n[materials.b]\ncolour = [0, 255, 0]\n[slice]\nuse = \"uniform\"\nthickness = 0.5\n[grade]\nuse = \"script\"\nf = \"g.rhai#f\"\n[[output]]\nuse = \"json\"\n";

#[test]
fn endless_script_is_stopped_within_a_second() {
    let dir = tempfile::tempdir().expect("tempdir");
    write(dir.path(), "g.rhai", "fn f(r) {\n    loop { }\n}\n");
    let p = write(dir.path(), "p.toml", SCRIPTED);
    let out_dir = dir.path().join("out");
    let start = std::time::Instant::now();
    let out = lamina(&[
        "run",
        p.to_str().expect("utf-8"),
        "--out",
        out_dir.to_str().expect("utf-8"),
        "--threads",
        "1",
    ]);
    assert!(start.elapsed().as_secs_f64() < 1.5, "took {:?}", start.elapsed());
    assert_eq!(out.status.code(), Some(1));
    let err = text(&out.stderr);
    assert!(err.contains("stopped"), "{err}");
    assert!(err.contains("g.rhai:"), "{err}");
    assert!(!out_dir.join("plan.json").exists());
}

#[test]
fn fractions_summing_to_0_9_are_refused_with_their_position() {
    let dir = tempfile::tempdir().expect("tempdir");
    write(
        dir.path(),
        "g.rhai",
        "// two materials\n\nfn f(r) {\n    [0.5, 0.4]\n}\n",
    );
    let p = write(dir.path(), "p.toml", SCRIPTED);
    let out = lamina(&[
        "run",
        p.to_str().expect("utf-8"),
        "--out",
        dir.path().join("o").to_str().expect("utf-8"),
    ]);
    assert_eq!(out.status.code(), Some(1));
    let err = text(&out.stderr);
    assert!(err.contains("g.rhai:3:1"), "{err}");
    assert!(err.contains("sum to 0.9"), "{err}");
    assert!(err.contains("layer 0"), "{err}");
}

#[test]
fn script_that_does_not_compile_is_a_usage_error() {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = write(dir.path(), "p.toml", &SCRIPTED.replace("g.rhai#f", "sin(r * PI"));
    let out = lamina(&["check", p.to_str().expect("utf-8")]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
    assert!(text(&out.stderr).contains("p.toml:13:"), "{}", text(&out.stderr));
}

#[test]
fn example_pipelines_check() {
    for entry in std::fs::read_dir(pipelines()).expect("pipelines") {
        let path = entry.expect("entry").path();
        if path.extension().is_some_and(|e| e == "toml") {
            // A pipeline on a real model checks that the model is there.
            let source = std::fs::read_to_string(&path).expect("pipeline");
            if source.contains("shared/models") && !crate::support::root().join("../shared/models").is_dir() {
                println!(
                    "note: {} reads ../shared/models, which is absent; not checked",
                    path.display()
                );
                continue;
            }
            // It reads its model outside its folder, where the command line allows.
            let models = crate::support::root().join("../shared/models");
            let out = lamina(&[
                "check",
                path.to_str().expect("utf-8"),
                "--allow",
                models.to_str().expect("utf-8"),
            ]);
            assert!(out.status.success(), "{}: {}", path.display(), text(&out.stderr));
        }
    }
}

#[test]
fn check_finds_a_model_file_that_run_could_not_read() {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = write(
        dir.path(),
        "p.toml",
        "name = \"missing\"\n[model]\nfile = \"nowhere.stl\"\n[materials.a]\ncolour = [1, 2, 3]\n",
    );
    let out = lamina(&["check", p.to_str().expect("utf-8")]);
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("nowhere.stl") && err.contains("file"), "{err}");
    // A folder is not a model either.
    std::fs::create_dir(dir.path().join("folder.stl")).expect("folder");
    let p = write(
        dir.path(),
        "p.toml",
        "name = \"folder\"\n[model]\nfile = \"folder.stl\"\n[materials.a]\ncolour = [1, 2, 3]\n",
    );
    let out = lamina(&["check", p.to_str().expect("utf-8")]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
    assert!(text(&out.stderr).contains("folder"), "{}", text(&out.stderr));
}

#[test]
fn model_option_replaces_the_model_of_a_single_part_pipeline() {
    let dir = tempfile::tempdir().expect("tempdir");
    // An ASCII STL cube of 2 mm, placed away from the origin: `place = "bed"` drops it.
    let stl = box_stl([10.0, 0.0, 5.0], [12.0, 2.0, 7.0]);
    let model = write(dir.path(), "cube.stl", &stl);
    let out_dir = dir.path().join("out");
    let out = lamina(&[
        "run",
        pipelines().join("tube-gradient.toml").to_str().expect("utf-8"),
        "--model",
        model.to_str().expect("utf-8"),
        "--out",
        out_dir.to_str().expect("utf-8"),
        "--quiet",
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let plan: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out_dir.join("tube-gradient.json")).expect("written"))
            .expect("json");
    let layers = plan["layers"].as_array().expect("layers");
    assert_eq!(layers.len(), 4, "2 mm at 0.5 mm");
    let area = layers[0]["parts"][0]["families"][0]["area"]
        .as_f64()
        .expect("area");
    assert!((area - 4.0).abs() < 1e-6, "{area}");

    // Several parts: refused.
    let out = lamina(&[
        "check",
        pipelines().join("assembly.toml").to_str().expect("utf-8"),
        "--model",
        model.to_str().expect("utf-8"),
    ]);
    assert_eq!(out.status.code(), Some(2));
}

#[test]
fn family_at_splits_one_mesh_into_parts_followed_through_the_layers() {
    let dir = tempfile::tempdir().expect("tempdir");
    // Gear and shaft merged into one mesh: the parts are told apart by a point each.
    let p = write(
        dir.path(),
        "p.toml",
        "[model]\nuse = \"gear-shaft\"\nteeth = 16\nheight = 5.0\nshaft_length = 9.0\n\
         [materials.bronze]\ncolour = [205, 127, 50]\n[materials.steel]\ncolour = [140, 140, 150]\n\
         [[parts]]\nname = \"gear\"\nmaterials = [\"bronze\"]\nfamily_at = [18.0, 0.0, 2.0]\n\
         [[parts]]\nname = \"shaft\"\nmaterials = [\"steel\"]\n\
         [slice]\nuse = \"uniform\"\nthickness = 0.5\n[[output]]\nuse = \"json\"\n",
    );
    let out_dir = dir.path().join("out");
    let out = lamina(&[
        "run",
        p.to_str().expect("utf-8"),
        "--out",
        out_dir.to_str().expect("utf-8"),
        "--quiet",
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let plan: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out_dir.join("plan.json")).expect("written")).expect("json");
    let layers = plan["layers"].as_array().expect("layers");
    assert_eq!(layers.len(), 18);
    for layer in layers {
        let z = layer["z"].as_f64().expect("z");
        let families = |part: usize| {
            layer["parts"][part]["families"]
                .as_array()
                .expect("families")
                .len()
        };
        let holes = |part: usize| {
            layer["parts"][part]["families"][0]["holes"]
                .as_array()
                .map_or(0, Vec::len)
        };
        if z <= 5.0 {
            assert_eq!((families(0), families(1)), (1, 1), "z = {z}");
            assert_eq!(holes(0), 1, "the gear keeps its bore");
            assert_eq!(holes(1), 0, "the shaft is solid");
        } else {
            assert_eq!((families(0), families(1)), (0, 1), "z = {z}");
        }
    }

    // A point in no solid is an error at the key.
    let text_bad = std::fs::read_to_string(&p)
        .expect("read")
        .replace("[18.0, 0.0, 2.0]", "[50.0, 0.0, 2.0]");
    std::fs::write(&p, text_bad).expect("write");
    let out = lamina(&[
        "run",
        p.to_str().expect("utf-8"),
        "--out",
        out_dir.to_str().expect("utf-8"),
    ]);
    let err = text(&out.stderr);
    assert!(
        err.contains("no solid at family_at") && err.contains("p.toml:13:"),
        "{err}"
    );
}

/// A part picked with `family_at` whose layers' cuts exceed what the pre-pass keeps
/// (200 layers of 8,192 points, about 26 MB against 16 MB): the layers it did not keep
/// are cut again, and the plan is the one the part gives without `family_at`, which
/// has the tube's one solid anyway.
#[test]
fn family_at_gives_the_same_part_whether_a_layer_was_kept_or_cut_again() {
    let dir = tempfile::tempdir().expect("tempdir");
    let pipeline = |pick: &str| {
        format!(
            "[model]\nuse = \"tube\"\nouter_radius = 10.0\ninner_radius = 7.0\nheight = 10.0\nsegments = 4096\n\
             [materials.a]\ncolour = [255, 0, 0]\n[materials.b]\ncolour = [0, 0, 255]\n\
             [[parts]]\nname = \"tube\"\n{pick}\n\
             [slice]\nuse = \"uniform\"\nthickness = 0.05\n[grade]\nuse = \"z\"\n[[output]]\nuse = \"json\"\n"
        )
    };
    let plans = ["family_at = [8.5, 0.0, 5.0]", ""].map(|pick| {
        let folder = dir.path().join(if pick.is_empty() { "all" } else { "picked" });
        std::fs::create_dir_all(&folder).expect("folder");
        let p = write(&folder, "p.toml", &pipeline(pick));
        let out = lamina(&[
            "run",
            p.to_str().expect("utf-8"),
            "--out",
            folder.join("out").to_str().expect("utf-8"),
            "-q",
        ]);
        assert!(out.status.success(), "{}", text(&out.stderr));
        std::fs::read(folder.join("out/plan.json")).expect("the plan")
    });
    let layers = serde_json::from_slice::<serde_json::Value>(&plans[0]).expect("json")["layers"]
        .as_array()
        .map_or(0, Vec::len);
    assert_eq!(layers, 200);
    assert!(
        plans[0] == plans[1],
        "the picked part differs from the whole mesh's"
    );
}

#[test]
fn view_writes_a_viewer_even_when_the_pipeline_has_none() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = lamina(&[
        "view",
        "--no-open",
        "--out",
        dir.path().to_str().expect("utf-8"),
        pipelines().join("assembly.toml").to_str().expect("utf-8"),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let page = PathBuf::from(text(&out.stdout).trim());
    let html = std::fs::read_to_string(&page).expect("the printed path is the viewer");
    assert!(html.contains("LAYERS.push("));
    assert!(page.starts_with(dir.path()));
}

/// The browser opener gets the viewer's absolute path: an output folder named `-x`
/// must not reach `xdg-open` as an option.
#[cfg(unix)]
#[test]
fn view_hands_the_opener_a_path_never_an_option() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().expect("tempdir");
    let bin = dir.path().join("bin");
    std::fs::create_dir(&bin).expect("mkdir");
    let opener = bin.join("xdg-open");
    std::fs::write(
        &opener,
        "#!/bin/sh\nprintf '%s\\n' \"$@\" > \"$(dirname \"$0\")/args\"\n",
    )
    .expect("write");
    std::fs::set_permissions(&opener, std::fs::Permissions::from_mode(0o755)).expect("chmod");
    let path = format!("{}:{}", bin.display(), std::env::var("PATH").unwrap_or_default());
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_lamina"))
        .current_dir(dir.path())
        .env("PATH", path)
        .args(["view", "--out=-x"])
        .arg(pipelines().join("assembly.toml"))
        .output()
        .expect("lamina runs");
    assert!(out.status.success(), "{}", text(&out.stderr));
    let args = std::fs::read_to_string(bin.join("args")).expect("the opener ran");
    let page = Path::new(args.trim());
    assert!(page.is_absolute() && page.is_file(), "{args}");
    assert!(page.starts_with(dir.path().canonicalize().expect("real")) || page.starts_with(dir.path()));
}

/// The blade with layers so thick that the planner leaves sub-regions out on every
/// layer: the same warning, layer after layer.
fn blade_with_a_warning_on_every_layer(out: &Path, flag: &str) -> Output {
    let pipeline = pipelines().join("blade-idw.toml");
    lamina(&[
        "run",
        pipeline.to_str().expect("utf-8"),
        "--out",
        out.to_str().expect("utf-8"),
        flag,
        "--set",
        "plan.use=\"sequential\"",
        "--set",
        "slice.thickness=10",
    ])
}

#[test]
fn quiet_runs_still_print_warnings_one_line_for_every_kind() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("out");
    let o = blade_with_a_warning_on_every_layer(&out, "-q");
    assert!(o.status.success(), "{}", text(&o.stderr));
    let err = text(&o.stderr);
    assert!(
        err.contains("warning[plan.thin-sub-regions-merged]:")
            && err.contains("narrower than the narrowest bead"),
        "{err}"
    );
    assert!(!err.contains("layers,"), "no summary when quiet: {err}");
    // The same warning on every layer is one line, with the layers it hit and a count.
    let lines: Vec<&str> = err
        .lines()
        .filter(|l| l.contains("narrower than the narrowest bead"))
        .collect();
    assert_eq!(lines.len(), 1, "{err}");

    // The JSON plan carries each one as data: severity, stage, code, layer, message.
    let plan: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("blade-idw.json")).expect("the JSON plan"))
            .expect("JSON");
    let said: Vec<&serde_json::Value> = plan["layers"]
        .as_array()
        .expect("layers")
        .iter()
        .flat_map(|l| l["diagnostics"].as_array().into_iter().flatten())
        .filter(|d| {
            d["message"]
                .as_str()
                .is_some_and(|m| m.contains("narrower than the narrowest bead"))
        })
        .collect();
    assert!(said.len() >= 2, "{said:?}");
    let layers: Vec<u64> = said.iter().map(|d| d["layer"].as_u64().expect("layer")).collect();
    assert!(
        said.iter().all(|d| d["severity"] == "warning"
            && d["stage"] == "plan"
            && d["code"] == "thin-sub-regions-merged"),
        "{said:?}"
    );
    let first = layers.iter().min().expect("one");
    let last = layers.iter().max().expect("one");
    assert!(
        lines[0].contains(&format!("layers {first}-{last}"))
            && lines[0].contains(&format!("{} times", said.len())),
        "{} against {layers:?}",
        lines[0]
    );
}

#[test]
fn verbose_runs_print_every_warning_with_its_layer() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("out");
    let o = blade_with_a_warning_on_every_layer(&out, "--verbose");
    assert!(o.status.success(), "{}", text(&o.stderr));
    let err = text(&o.stderr);
    let lines: Vec<&str> = err
        .lines()
        .filter(|l| l.contains("narrower than the narrowest bead"))
        .collect();
    assert!(lines.len() >= 2, "{err}");
    // Each names its layer, in build order.
    let layers: Vec<usize> = lines
        .iter()
        .map(|l| {
            let rest = l
                .strip_prefix("warning[plan.thin-sub-regions-merged]: layer ")
                .expect(l);
            assert!(rest.contains(" (z = "), "{l}");
            rest.split(' ').next().and_then(|n| n.parse().ok()).expect(l)
        })
        .collect();
    assert!(layers.windows(2).all(|w| w[0] < w[1]), "{layers:?}");
}

#[test]
fn overridden_values_are_reported_at_their_key_in_plain_words() {
    let dir = tempfile::tempdir().expect("tempdir");
    let o = lamina(&[
        "generate",
        "gear",
        "--teeth",
        "7.5",
        "-o",
        &dir.path().join("g.stl").to_string_lossy(),
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o.stderr));
    let err = text(&o.stderr);
    assert!(
        err.contains("teeth") && err.contains("expected a whole number"),
        "{err}"
    );
    assert!(!err.contains("usize") && !err.contains("after --set"), "{err}");
    let pipeline = pipelines().join("gear-z-gradient.toml");
    let o = lamina(&[
        "check",
        pipeline.to_str().expect("utf-8"),
        "--set",
        "slice.thickness=\"thin\"",
    ]);
    let err = text(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("[slice] thickness") && err.contains("expected a number"),
        "{err}"
    );
    assert!(!err.contains("f64"), "{err}");
}

/// `lamina check` reads the model as `run` will: a mesh that does not parse or a part
/// off the machine's bed is refused by `check` (exit 2), not found by the run.
#[test]
fn check_reads_the_model_as_the_run_will() {
    let dir = tempfile::tempdir().expect("tempdir");
    std::fs::write(
        dir.path().join("bad.stl"),
        "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nendloop\nendfacet\n",
    )
    .expect("write");
    let text_of = |file: &str| {
        format!(
            "[model]\nuse = \"stl\"\nfile = \"{file}\"\n[materials.a]\ncolour = [255, 0, 0]\n\
             [slice]\nuse = \"uniform\"\nthickness = 0.5\n"
        )
    };
    let bad = write(dir.path(), "bad.toml", &text_of("bad.stl"));
    let err = refused(&bad);
    assert!(err.contains("bad.stl: line 5"), "{err}");
    // The gear, fine on its own, is checked against the bed once scaled up.
    let gear = pipelines().join("gear-mixing-gcode.toml");
    let o = lamina(&["check", gear.to_str().expect("utf-8")]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert!(
        text(&o.stdout).contains("part `gear`: 1536 triangles, 40 x 40 x 5 mm"),
        "{}",
        text(&o.stdout)
    );
    let o = lamina(&[
        "check",
        gear.to_str().expect("utf-8"),
        "--set",
        "model.tip_radius=400",
        "--set",
        "model.root_radius=380",
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o.stdout));
    assert!(text(&o.stderr).contains("does not fit"), "{}", text(&o.stderr));
}

/// A number outside its option's physical range is refused at the value, naming the key
/// and the range, whether the file or a `--set` gave it; a default is never refused.
#[test]
fn a_number_outside_its_range_is_refused_at_its_value() {
    let dir = tempfile::tempdir().expect("tempdir");
    let text_of = "[model]\nuse = \"tube\"\nheight = 1.0\n\
        [materials.a]\ncolour = [255, 0, 0]\n\
        [slice]\nuse = \"uniform\"\nthickness = 1e-4\n\
        [discretise]\nuse = \"offset\"\nnozzle = 1e300\n";
    let p = write(dir.path(), "p.toml", text_of);
    let err = refused(&p);
    assert!(
        err.contains("p.toml:8:") && err.contains("`thickness` = 0.0001 is outside its range 0.001 to 100"),
        "{err}"
    );
    assert!(
        err.contains("p.toml:11:") && err.contains("`nozzle` = 1e300 is outside its range 0.01 to 50"),
        "{err}"
    );
    let fine = write(
        dir.path(),
        "q.toml",
        &text_of.replace("1e-4", "0.2").replace("1e300", "0.4"),
    );
    let o = lamina(&[
        "check",
        fine.to_str().expect("utf-8"),
        "--set",
        "slice.max_layers=0",
    ]);
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("`max_layers` = 0 is outside its range 1 to 10000000"),
        "{err}"
    );
    let o = lamina(&["check", fine.to_str().expect("utf-8")]);
    assert!(o.status.success(), "{}", text(&o.stderr));
}

/// `lamina check` reports every wrong stage of a pipeline at once, each at its own
/// line, as a compiler does: here a bad slice thickness, an unknown discretiser option,
/// a script that does not compile and an output of no known kind.
#[test]
fn check_reports_every_error_at_once() {
    let dir = tempfile::tempdir().expect("tempdir");
    let text_of = "[model]\nuse = \"tube\"\nheight = 1.0\n\
        [materials.a]\ncolour = [255, 0, 0]\n[materials.b]\ncolour = [0, 255, 0]\n\
        [slice]\nuse = \"uniform\"\nthickness = -1.0\n\
        [discretise]\nuse = \"offset\"\nrings = 3\n\
        [grade]\nuse = \"script\"\nf = \"sin(r * PI\"\n\
        [[output]]\nuse = \"nonesuch\"\npath = \"x\"\n";
    let p = write(dir.path(), "p.toml", text_of);
    let err = refused(&p);
    // In the order of the file.
    let mut at = 0;
    for line in [10, 13, 16, 18] {
        let found = err[at..].find(&format!("p.toml:{line}:"));
        assert!(
            found.is_some(),
            "no error at line {line} after the one before:\n{err}"
        );
        at += found.unwrap_or_default() + 1;
    }
    assert!(err.contains("4 errors in all"), "{err}");
}

/// A value from `--set` is reported at the override, shown as its own line, not at the
/// file's value it replaced; a placement of the wrong kind says what placements are.
#[test]
fn set_values_are_reported_at_the_override() {
    let dir = tempfile::tempdir().expect("tempdir");
    write(dir.path(), "g.rhai", "fn f(r) {\n    r\n}\n");
    let p = write(dir.path(), "p.toml", SCRIPTED);
    let run = |set: &str| {
        let out = lamina(&["check", p.to_str().expect("utf-8"), "--set", set]);
        assert_eq!(out.status.code(), Some(2), "{set}: {}", text(&out.stderr));
        text(&out.stderr)
    };
    let err = run("grade.f=\"g.rhai#nope\"");
    assert!(
        err.contains("--set:1:1: ") && err.contains("has no function `nope`"),
        "{err}"
    );
    assert!(
        err.contains("grade.f = 'g.rhai#nope'"),
        "the override is shown: {err}"
    );
    // An expression's position is its position in the override.
    let err = run("grade.f=\"r * (1 +\"");
    assert!(err.contains("--set:1:"), "{err}");
    assert!(!err.contains("p.toml:13"), "{err}");
    let err = run("model.place=[100, 100]");
    assert!(
        err.contains("is not a placement") && err.contains("\"keep\""),
        "{err}"
    );
    assert!(!err.contains("variant"), "no serde words: {err}");
}

/// The help says what each command does, beyond its name: the exit codes the tests
/// above check, that a run commits its outputs only when it succeeds (checked by
/// `missing_model_file_fails_with_exit_1_and_leaves_nothing`), and what the viewer
/// holds.
#[test]
fn help_says_what_happens_and_the_exit_codes() {
    let top = text(&lamina(&["--help"]).stdout);
    for want in [
        "Exit codes: 0 done; 1 the run failed",
        "2 the command line or the pipeline is wrong",
        "lamina check",
    ] {
        assert!(top.contains(want), "`lamina --help` lacks {want:?}:\n{top}");
    }
    let run = text(&lamina(&["run", "--help"]).stdout);
    assert!(run.contains("only when the whole run succeeds"), "{run}");
    assert!(
        !run.contains("(default: `out`"),
        "the default is said once: {run}"
    );
    let view = text(&lamina(&["view", "--help"]).stdout);
    for want in ["G-code", "3D view", "no network"] {
        assert!(
            view.contains(want),
            "`lamina view --help` lacks {want:?}:\n{view}"
        );
    }
}

/// The run's summary gives the machine file's own time and what it deposits, as the
/// file's footer says them, and labels the plan's time as the plan's.
#[test]
fn the_summary_tells_the_machine_files_own_time_and_waste() {
    let out = tempfile::tempdir().expect("tempdir");
    let pipeline = crate::support::pipelines().join("gear-mixing-gcode.toml");
    let o = crate::support::lamina(&[
        "run",
        "--out",
        out.path().to_str().expect("utf-8"),
        pipeline.to_str().expect("utf-8"),
    ]);
    assert!(o.status.success(), "{}", crate::support::text(&o.stderr));
    let summary = crate::support::text(&o.stderr);
    let gcode = std::fs::read_to_string(out.path().join("gear-mixing.gcode")).expect("G-code");
    let estimate = gcode
        .lines()
        .find_map(|l| l.strip_prefix("; estimated printing time: "))
        .and_then(|t| t.strip_suffix(" s"))
        .expect("the file's estimate");
    let line = summary
        .lines()
        .find(|l| l.starts_with("gear-mixing.gcode: "))
        .unwrap_or_else(|| panic!("no line for the G-code in:\n{summary}"));
    assert!(
        line.contains(&format!("({estimate} s) by the file's own estimate")),
        "{line}"
    );
    assert!(
        line.contains("waste ") && line.contains("deposits part "),
        "{line}"
    );
    assert!(!summary.contains("planned build time:"), "{summary}");
    assert!(summary.contains("the plan's build time"), "{summary}");
}

/// A part of two boxes. When the smaller misses a triangle of a side wall, every layer
/// cuts it into a chain that stops at the hole, 4 mm wide at the bottom: the slicer
/// closes it across the hole, and the part is made whole, as from the whole mesh. When
/// the smaller is only a fence (three walls, no floor, roof or fourth wall), its cut
/// stops at the fence's open side and nothing says it encloses anything: the run fails
/// naming the part, what its layers hold of the volume its mesh encloses and where, and
/// leaves no output, rather than exit 0 with a plan of a part and a half.
#[test]
fn a_holed_wall_is_closed_and_a_part_its_layers_do_not_hold_fails_the_run_naming_where() {
    let dir = tempfile::tempdir().expect("tempdir");
    let solid = |stl: String| stl.replace("endsolid box\n", "").replace("solid box\n", "");
    let big = solid(box_stl([0.0, 0.0, 0.0], [10.0, 10.0, 2.0]));
    let small = solid(box_stl([20.0, 0.0, 0.0], [24.0, 6.0, 2.0]));
    let whole = format!("solid two\n{big}{small}endsolid two\n");
    // The facets of a box: bottom, top, then the walls at y = 0, y = 6, x = 20 and
    // x = 24, two each.
    let facets: Vec<&str> = small.split_inclusive("endfacet\n").collect();
    let without = |drop: &[usize]| -> String {
        facets
            .iter()
            .enumerate()
            .filter(|(i, _)| !drop.contains(i))
            .map(|(_, f)| *f)
            .collect()
    };
    let holed = format!("solid two\n{big}{}endsolid two\n", without(&[4]));
    let fence = format!("solid two\n{big}{}endsolid two\n", without(&[0, 1, 2, 3, 4, 5]));
    let run = |stl: &str, name: &str| {
        let model = write(dir.path(), name, stl);
        let out_dir = dir.path().join(format!("out-{name}"));
        let out = lamina(&[
            "run",
            pipelines().join("tube-gradient.toml").to_str().expect("utf-8"),
            "--model",
            model.to_str().expect("utf-8"),
            "--out",
            out_dir.to_str().expect("utf-8"),
        ]);
        (out, out_dir)
    };
    let plan = |out_dir: &Path| -> serde_json::Value {
        let file = std::fs::read_dir(out_dir)
            .expect("outputs")
            .map(|e| e.expect("entry").path())
            .find(|p| p.extension().is_some_and(|e| e == "json"))
            .expect("a JSON plan");
        serde_json::from_slice(&std::fs::read(file).expect("plan")).expect("JSON")
    };
    let areas = |plan: &serde_json::Value| -> Vec<f64> {
        plan["layers"]
            .as_array()
            .expect("layers")
            .iter()
            .map(|l| {
                l["parts"][0]["families"]
                    .as_array()
                    .expect("families")
                    .iter()
                    .map(|f| f["area"].as_f64().expect("area"))
                    .sum()
            })
            .collect()
    };
    let (out, whole_dir) = run(&whole, "whole.stl");
    assert!(out.status.success(), "{}", text(&out.stderr));
    let (out, holed_dir) = run(&holed, "holed.stl");
    assert!(out.status.success(), "{}", text(&out.stderr));
    let said = text(&out.stderr);
    assert!(
        said.contains("warning[slice.holes-closed]: layers 0-3") && said.contains("(1 hole(s)"),
        "{said}"
    );
    let (a, b) = (areas(&plan(&whole_dir)), areas(&plan(&holed_dir)));
    assert_eq!(a.len(), b.len());
    for (a, b) in a.iter().zip(&b) {
        assert!((a - b).abs() < 1e-9 * a, "{b} against {a}");
        assert!((a - 124.0).abs() < 1e-9, "{a}");
    }
    let (out, out_dir) = run(&fence, "fence.stl");
    let err = text(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(
        err.contains("part `part`: the layers hold 200.0 mm³ of the")
            && err.contains("short on layers 0-3 (z 0.000-2.000 mm)"),
        "{err}"
    );
    assert!(!out_dir.exists() || std::fs::read_dir(&out_dir).expect("folder").next().is_none());
}

/// Options renamed so that "cell" means a circumferential cell alone are still read by
/// their former names, with the same outcome: a pipeline written before the renames
/// runs as it did (`cells` of the distance field is `samples` now, the NC exporter's
/// hybrid `cell` its `machine`).
#[test]
fn pipelines_with_former_option_names_run_as_with_the_new_ones() {
    for (name, new, old, file) in [
        ("blade-skin", "samples = 128", "cells = 128", "blade-skin.json"),
        (
            "pipe-work-cycles",
            "machine = \"cmpm-hybrid\"",
            "cell = \"cmpm-hybrid\"",
            "pipe-work-cycles.nc",
        ),
    ] {
        let shipped = std::fs::read_to_string(pipelines().join(format!("{name}.toml"))).expect("pipeline");
        assert!(shipped.contains(new), "{name} says `{new}`");
        let outputs: Vec<Vec<u8>> = [shipped.clone(), shipped.replace(new, old)]
            .iter()
            .map(|t| {
                let dir = tempfile::tempdir().expect("tempdir");
                let pipeline = write(dir.path(), &format!("{name}.toml"), t);
                let out = dir.path().join("out");
                let o = try_run(&pipeline, &out, &[]);
                assert!(o.status.success(), "{name}: {}", text(&o.stderr));
                std::fs::read(out.join(file)).expect("the output")
            })
            .collect();
        assert!(outputs[0] == outputs[1], "{name}: the former name changed {file}");
    }
}
