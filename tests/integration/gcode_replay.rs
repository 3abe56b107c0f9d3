//! The G-code Lamina writes, judged by what a printer would make of it: every example
//! pipeline that writes G-code is run, and its file is replayed by
//! `tests/replay/gcode_replay.py`, a checker written from Marlin's and
//! RepRapFirmware's documented command semantics (not from Lamina's planner). It checks
//! the deposited volume against the mesh's, each sampled layer's coverage by the beads
//! and their overlap (shapely), heating and tool selection before any extrusion or
//! retraction, every move inside the bed, layer heights, mixes, and the file's own time
//! estimate against a look-ahead replay.
//!
//! The checker needs Python 3 with numpy, shapely and trimesh. Without them these tests
//! skip with a note, unless `LAMINA_REQUIRE` is set (as `.ci/run` does), where a skip is
//! a failure.

use crate::support::{allow_models, model, root, skip};
use std::path::{Path, PathBuf};
use std::process::Command;

/// Whether the checker's Python dependencies are there; a note (or a failure under
/// `LAMINA_REQUIRE`) when not.
fn checker_ready() -> bool {
    let ok = Command::new("python3")
        .args(["-c", "import numpy, shapely, trimesh"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !ok {
        skip("python3 with numpy, shapely and trimesh is missing (the G-code replay checker)");
    }
    ok
}

fn lamina(args: &[&str]) -> std::process::Output {
    let out = Command::new(env!("CARGO_BIN_EXE_lamina"))
        .args(args)
        .output()
        .expect("lamina runs");
    assert!(
        out.status.success(),
        "lamina {args:?} failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// The pipeline's model as one STL: a generator's mesh written by `lamina generate`, or
/// the pipeline's own file.
fn model_stl(pipeline: &Path, table: &toml::Table, dir: &Path) -> PathBuf {
    let model = table
        .get("model")
        .and_then(toml::Value::as_table)
        .expect("a [model] table");
    if let Some(file) = model.get("file").and_then(toml::Value::as_str) {
        return pipeline.parent().expect("a folder").join(file);
    }
    let generator = model.get("use").and_then(toml::Value::as_str).expect("model.use");
    let out = dir.join("model.stl");
    let mut args: Vec<String> = vec!["generate".into(), generator.into()];
    for (k, v) in model {
        if k != "use" {
            args.push(format!("{k}={v}"));
        }
    }
    args.push("-o".into());
    args.push(out.to_string_lossy().into_owned());
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    lamina(&args);
    out
}

/// A machine profile by name (a built-in one) or path (relative to the pipeline).
fn profile(name: &str, pipeline: &Path) -> toml::Table {
    let file = if name.ends_with(".toml") {
        pipeline.parent().expect("a folder").join(name)
    } else {
        root().join("machine/profiles").join(format!("{name}.toml"))
    };
    toml::from_str(&std::fs::read_to_string(&file).expect("profile")).expect("profile TOML")
}

/// A machine's profile: a built-in name or an inline table (over its `base`).
fn machine_table(machine: &toml::Value, pipeline: &Path) -> toml::Table {
    match machine {
        toml::Value::String(name) => profile(name, pipeline),
        toml::Value::Table(t) => {
            let mut base = t
                .get("base")
                .and_then(toml::Value::as_str)
                .map(|b| profile(b, pipeline))
                .unwrap_or_default();
            for (k, v) in t {
                base.insert(k.clone(), v.clone());
            }
            base
        }
        _ => panic!("{}: `machine` is neither a name nor a table", pipeline.display()),
    }
}

/// The replay's heating model from a machine's profile: its heaters' rates and
/// residencies and its tool changes' own time (the machine defaults where the profile
/// is silent; the residencies default by firmware in the replay as in Lamina).
fn heating_args(table: &toml::Table) -> Vec<String> {
    let number = |v: &toml::Value| v.as_float().or_else(|| v.as_integer().map(|i| i as f64));
    let heating = table.get("heating").and_then(toml::Value::as_table);
    let get = |key: &str| heating.and_then(|h| h.get(key)).and_then(number);
    let mut args = vec![
        format!("--heating-rate={}", get("nozzle_rate").unwrap_or(2.0)),
        format!("--cooling-rate={}", get("nozzle_cooling").unwrap_or(1.0)),
        format!("--bed-heating-rate={}", get("bed_rate").unwrap_or(0.5)),
    ];
    if let Some(r) = get("residency") {
        args.push(format!("--residency={r}"));
    }
    if let Some(r) = get("bed_residency") {
        args.push(format!("--bed-residency={r}"));
    }
    if let Some(t) = table.get("tool_change_time").and_then(number) {
        args.push(format!("--tool-change-time={t}"));
    }
    args
}

/// The bed rectangle (x0, y0, x1, y1) of a machine's profile.
fn bed(table: &toml::Table) -> [f64; 4] {
    let bed = table.get("bed").and_then(toml::Value::as_table).expect("[bed]");
    let size: Vec<f64> = bed
        .get("size")
        .and_then(toml::Value::as_array)
        .expect("bed.size")
        .iter()
        .map(|v| {
            v.as_float()
                .or_else(|| v.as_integer().map(|i| i as f64))
                .expect("a number")
        })
        .collect();
    match bed
        .get("origin")
        .and_then(toml::Value::as_str)
        .unwrap_or("front-left")
    {
        "centre" | "center" => [-size[0] / 2.0, -size[1] / 2.0, size[0] / 2.0, size[1] / 2.0],
        _ => [0.0, 0.0, size[0], size[1]],
    }
}

/// Runs `pipeline` (with `overrides`, and on another built-in `machine` if given) and
/// replays every G-code file it writes.
fn replay(
    pipeline: &str,
    machine: Option<&str>,
    overrides: &[&str],
    coverage_every: usize,
) -> Vec<serde_json::Value> {
    replay_file(
        &root().join(pipeline),
        machine,
        overrides,
        coverage_every,
        TARGETS,
    )
}

/// Least coverage of a layer by the beads and most overlap between beads.
#[derive(Clone, Copy)]
struct Targets {
    coverage: f64,
    overlap: f64,
    /// Also replay the file with a motion system running slower than it assumes
    /// (system 0's feeds a fifth slower, then system 1's accelerations halved): no collision,
    /// no wait with a loaded nozzle, and the heads the envelopes' sum and one margin
    /// apart all the same.
    perturb: bool,
}

/// Issue targets for the deposition: 99 % of every sampled layer covered, beads
/// sharing at most 5 % of their area.
const TARGETS: Targets = Targets {
    coverage: 0.99,
    overlap: 0.05,
    perturb: false,
};

/// [`TARGETS`], and the timing perturbations of a machine with two motion systems.
const PERTURBED: Targets = Targets {
    perturb: true,
    ..TARGETS
};

/// How far apart the heads of a machine with two motion systems must stay in a
/// replay: the envelopes' sum and the kinematics margin (1 mm unless it says).
fn keep_out(machine: &toml::Table) -> f64 {
    let number = |v: &toml::Value| v.as_float().or_else(|| v.as_integer().map(|i| i as f64));
    let envelopes: f64 = machine
        .get("tools")
        .and_then(toml::Value::as_array)
        .map(|tools| {
            tools
                .iter()
                .filter_map(|t| t.get("envelope").and_then(number))
                .sum()
        })
        .unwrap_or(0.0);
    let margin = machine
        .get("kinematics")
        .and_then(|k| k.get("margin"))
        .and_then(number)
        .unwrap_or(1.0);
    envelopes + margin
}

fn replay_file(
    pipeline: &Path,
    machine: Option<&str>,
    overrides: &[&str],
    coverage_every: usize,
    targets: Targets,
) -> Vec<serde_json::Value> {
    if !checker_ready() {
        return Vec::new();
    }
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("out");
    let machine_override = machine.map(|m| format!("machine=\"{m}\""));
    let mut args = vec![
        "run",
        pipeline.to_str().expect("utf-8"),
        "--out",
        out.to_str().expect("utf-8"),
        "-q",
    ];
    for o in overrides.iter().copied().chain(machine_override.as_deref()) {
        args.push("--set");
        args.push(o);
    }
    let allow = allow_models();
    args.extend(allow.iter().map(String::as_str));
    lamina(&args);
    let mut table: toml::Table =
        toml::from_str(&std::fs::read_to_string(pipeline).expect("pipeline")).expect("TOML");
    // The mesh the run read: an overridden model file replaces the pipeline's.
    for o in overrides {
        if let Some(value) = o.strip_prefix("model.file=") {
            let file: toml::Value =
                toml::from_str::<toml::Table>(&format!("v = {value}")).expect("a TOML value")["v"].clone();
            if let Some(model) = table.get_mut("model").and_then(toml::Value::as_table_mut) {
                model.insert("file".into(), file);
            }
        }
    }
    let mesh = model_stl(pipeline, &table, dir.path());
    let named = machine.map(|m| toml::Value::String(m.to_string()));
    let machine = named.as_ref().or(table.get("machine")).expect("a machine");
    let machine = machine_table(machine, pipeline);
    let [x0, y0, x1, y1] = bed(&machine);
    let files: Vec<PathBuf> = std::fs::read_dir(&out)
        .expect("output folder")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "gcode"))
        .collect();
    assert!(!files.is_empty(), "{} wrote no G-code", pipeline.display());
    let mut reports = Vec::new();
    for gcode in files {
        let report = gcode.with_extension("replay.json");
        let o = Command::new("python3")
            .arg(root().join("tests/replay/gcode_replay.py"))
            .arg(&gcode)
            .arg("--mesh")
            .arg(&mesh)
            .args(["--place", "centre", "--bead-ends", "round"])
            .arg(format!("--bed={x0},{y0},{x1},{y1}"))
            .arg(format!("--coverage-every={coverage_every}"))
            .arg(format!("--coverage-min={}", targets.coverage))
            .arg(format!("--overlap-max={}", targets.overlap))
            .args(heating_args(&machine))
            .arg("--json")
            .arg(&report)
            .output()
            .expect("python3 runs");
        let text = String::from_utf8_lossy(&o.stdout);
        eprintln!("{text}");
        assert!(
            o.status.success(),
            "{} does not replay cleanly:\n{text}\n{}",
            gcode.display(),
            String::from_utf8_lossy(&o.stderr)
        );
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&report).expect("report")).expect("JSON report");
        if json["mode"] == "multi-motion" {
            let keep = keep_out(&machine);
            let closest =
                |r: &serde_json::Value| r["collisions"]["closest_mm"].as_f64().unwrap_or(f64::INFINITY);
            assert!(
                closest(&json) >= keep - 1e-6,
                "{}: the heads come {} mm close, under the {keep} mm keep-out and margin",
                gcode.display(),
                closest(&json)
            );
            let perturbations = if targets.perturb {
                &["0:0.8,1", "1:1,0.5"][..]
            } else {
                &[]
            };
            for p in perturbations {
                let slow = gcode.with_extension("slow.json");
                let o = Command::new("python3")
                    .arg(root().join("tests/replay/gcode_replay.py"))
                    .arg(&gcode)
                    .arg(format!("--bed={x0},{y0},{x1},{y1}"))
                    .arg(format!("--perturb={p}"))
                    .args(heating_args(&machine))
                    .arg("--json")
                    .arg(&slow)
                    .output()
                    .expect("python3 runs");
                let text = String::from_utf8_lossy(&o.stdout);
                assert!(
                    o.status.success(),
                    "{} does not replay cleanly with system {p} slower:\n{text}",
                    gcode.display()
                );
                let r: serde_json::Value =
                    serde_json::from_str(&std::fs::read_to_string(&slow).expect("report"))
                        .expect("JSON report");
                assert!(
                    closest(&r) >= keep - 1e-6,
                    "{}: with system {p} slower the heads come {} mm close (keep-out and margin {keep} mm)",
                    gcode.display(),
                    closest(&r)
                );
                eprintln!(
                    "{}: system {p} slower: {:.1} s, closest approach {:.3} mm, loaded waits {}",
                    gcode.display(),
                    r["time"]["replayed_s"].as_f64().unwrap_or(f64::NAN),
                    closest(&r),
                    r["checks"]["waits"]["violations"]
                );
            }
        }
        reports.push(json);
    }
    reports
}

/// What a replayed file deposits besides the part (prime, purge, tower, skirt), over
/// all it deposits, from the replay's `;TYPE:` volumes.
fn waste_share(report: &serde_json::Value) -> f64 {
    let by_type = report["volume"]["by_type_mm3"]
        .as_object()
        .expect("volumes by type");
    let total: f64 = by_type.values().filter_map(serde_json::Value::as_f64).sum();
    let part = by_type
        .get("PART")
        .and_then(serde_json::Value::as_f64)
        .unwrap_or(0.0);
    (total - part) / total
}

#[test]
fn gear_mixing_gcode_replays() {
    // The next ring takes each change of mix: the prime line and skirt are the waste.
    for r in replay("pipelines/gear-mixing-gcode.toml", None, &[], 3) {
        let waste = waste_share(&r);
        eprintln!("gear on the mixing head: waste {waste:.4} of all deposition");
        assert!(waste <= 0.10, "waste {waste:.3}");
    }
    // Every change on the tower, as a mixing head without a graded part needs it.
    for r in replay(
        "pipelines/gear-mixing-gcode.toml",
        None,
        &["output.0.purge_into=\"tower\""],
        6,
    ) {
        assert!(waste_share(&r) > 0.3, "the tower takes every change");
    }
}

#[test]
fn gear_and_shaft_on_two_heads_replay() {
    replay("pipelines/assembly-two-tools.toml", None, &[], 2);
}

#[test]
fn gear_and_shaft_on_a_tool_changer_replay() {
    replay(
        "pipelines/assembly-two-tools.toml",
        Some("marlin-toolchanger-2"),
        &[],
        2,
    );
}

/// The gear and shaft on a machine with two motion systems: the concurrent plan's
/// file runs both heads at once (RepRapFirmware 3.5's M596/M598, replayed stream by
/// stream by `multi_motion.py`) with no collision, the time it states, and each tool's
/// planned volume; and it is done sooner than the same machine's file for the plan
/// that takes the tools one at a time.
#[test]
fn gear_and_shaft_on_two_motion_systems_replay_without_collision() {
    let concurrent = replay_file(
        &root().join("pipelines/assembly-two-tools.toml"),
        Some("rrf-two-systems-2"),
        &[],
        2,
        PERTURBED,
    );
    let sequential = replay(
        "pipelines/assembly-two-tools.toml",
        Some("rrf-two-systems-2"),
        &["plan.use=\"sequential\""],
        4,
    );
    let (Some(c), Some(s)) = (concurrent.first(), sequential.first()) else {
        return;
    };
    assert_eq!(c["mode"], "multi-motion");
    assert_eq!(c["collisions"]["count"], 0);
    let time = |r: &serde_json::Value| r["time"]["replayed_s"].as_f64().expect("replayed time");
    let ratio = time(c) / time(s);
    // The sequential file's moves side by side, per layer: no schedule of them is
    // shorter.
    let bound = s["time"]["layers_busiest_s"].as_f64().expect("per-layer bound");
    // Of the same file's printing moves alone: no order of these deposits at their
    // feeds is shorter.
    let printing = s["time"]["layers_busiest_print_s"]
        .as_f64()
        .expect("per-layer printing");
    eprintln!(
        "gear and shaft: concurrent {:.1} s, one tool at a time {:.1} s (ratio {ratio:.3}; the busier tool per layer alone {:.3}, its printing alone {:.3}); paused {:.1} % and {:.1} %",
        time(c),
        time(s),
        bound / time(s),
        printing / time(s),
        100.0 * c["streams"][0]["paused_share"].as_f64().unwrap_or(f64::NAN),
        100.0 * c["streams"][1]["paused_share"].as_f64().unwrap_or(f64::NAN),
    );
    assert!(time(c) >= bound, "faster than the busier tool's work alone");
    assert!(
        bound > printing,
        "the busier tool's work is more than its printing"
    );
    // Layer by layer, the busier tool's work alone takes 0.69 of the sequential time:
    // no schedule of these routes does better. Its printing alone takes 0.56: no
    // order of these deposits does better. Looking ahead 0.5 s the replayed ratio is
    // 0.76, with the heads pulling their filament back at the synchronisations where
    // they may wait: what the schedule costs over that floor is 0.07 of the
    // sequential time.
    let floor = bound / time(s);
    assert!(
        ratio <= 0.77 && ratio - floor <= 0.08,
        "the concurrent file is not fast enough: {ratio}, {floor} for the busier tool alone"
    );
}

/// The gear and shaft on two gantries with real 15 mm heads: the heads keep their
/// order in Y (the replay checks it, also with either system running slower than the
/// file assumes), and the file is never slower than the same machine taking the
/// tools one at a time: on a part this small the heads cannot work at once, and the
/// planner deposits the layers one tool at a time.
#[test]
fn gear_and_shaft_on_two_gantries_keep_their_order_and_lose_no_time() {
    // The concurrent schedule kept on every layer: the heads keep their order and
    // the firmware's own M597 rule, also with either system slower than planned.
    let forced = replay_file(
        &root().join("pipelines/assembly-two-tools.toml"),
        Some("rrf-dual-gantry-2"),
        &["plan.keep_faster=false"],
        8,
        PERTURBED,
    );
    if let Some(f) = forced.first() {
        assert_eq!(f["collisions"]["mode"], "dual-gantry");
        assert_eq!(f["checks"]["separation"]["status"], "pass");
        assert!(
            f["time"]["barriers"].as_u64().unwrap_or(0) > 100,
            "the heads work at once"
        );
    }
    let concurrent = replay(
        "pipelines/assembly-two-tools.toml",
        Some("rrf-dual-gantry-2"),
        &[],
        4,
    );
    let sequential = replay(
        "pipelines/assembly-two-tools.toml",
        Some("rrf-dual-gantry-2"),
        &["plan.use=\"sequential\""],
        8,
    );
    let (Some(c), Some(s)) = (concurrent.first(), sequential.first()) else {
        return;
    };
    assert_eq!(c["collisions"]["mode"], "dual-gantry");
    assert_eq!(c["collisions"]["count"], 0);
    let time = |r: &serde_json::Value| r["time"]["replayed_s"].as_f64().expect("replayed time");
    eprintln!(
        "gear and shaft on two gantries: {:.1} s, one tool at a time {:.1} s",
        time(c),
        time(s)
    );
    assert!(
        time(c) <= time(s) * 1.001,
        "slower than one tool at a time: {} s against {} s",
        time(c),
        time(s)
    );
}

/// The two-cavity blade in three materials mixed by inverse distance weighting, on a
/// three-channel mixing head: the example with the finest cells.
#[test]
fn three_material_blade_on_a_mixing_head_replays() {
    let dir = tempfile::tempdir().expect("temp dir");
    let text = std::fs::read_to_string(root().join("pipelines/blade-idw.toml")).expect("pipeline");
    let stages = text.split("[[output]]").next().expect("stages");
    let machine = "[machine]\nbase = \"marlin-mixing-2in1\"\n\
                   [[machine.tools]]\n[[machine.tools]]\n[[machine.tools]]\nnozzle_temperature = 205.0\n\
                   [machine.wipe_tower]\nsize = [60.0, 60.0]\n\n";
    let pipeline = dir.path().join("blade-idw-mixing.toml");
    std::fs::write(
        &pipeline,
        format!(
            "{}\n[plan]\nuse = \"sequential\"\nmixing = true\n\n[[output]]\nuse = \"gcode\"\npath = \"blade.gcode\"\n",
            stages.replacen("[model]", &format!("{machine}[model]"), 1)
        ),
    )
    .expect("write");
    // 266 sub-regions per layer of the airfoil, nearly all cells narrower than a bead
    // whose boundaries do not line up from one level to the next: each wall is filled
    // as one, with beads whose mix changes along them in place.
    replay_file(&pipeline, None, &["slice.thickness=0.3"], 8, TARGETS);
}

/// 3DBenchy on each shipped machine (needs ../shared/models; run by `.ci/run`'s
/// acceptance step).
#[test]
#[ignore = "needs ../shared/models/3DBenchy.stl"]
fn benchy_replays_on_every_machine() {
    let Some(benchy) = model("3DBenchy.stl") else {
        return;
    };
    let file = format!("model.file=\"{}\"", benchy.display());
    let sequential = "plan.use=\"sequential\"";
    // Each machine's run and replay is a process of its own: they run at once, and
    // what they say is checked in order below.
    let jobs: [(Option<&str>, Vec<&str>, usize); 7] = [
        (None, vec![&file], 10),
        (Some("rrf-idex-2"), vec![&file], 10),
        (Some("marlin-mixing-2in1"), vec![&file, "plan.mixing=true"], 10),
        (Some("rrf-two-systems-2"), vec![&file], 10),
        (Some("rrf-two-systems-2"), vec![&file, sequential], 20),
        (Some("rrf-dual-gantry-2"), vec![&file], 20),
        (Some("rrf-dual-gantry-2"), vec![&file, sequential], 40),
    ];
    let mut reports: Vec<Vec<serde_json::Value>> = std::thread::scope(|scope| {
        let handles: Vec<_> = jobs
            .iter()
            .map(|(machine, overrides, every)| {
                scope.spawn(move || replay("pipelines/benchy-two-tools.toml", *machine, overrides, *every))
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().unwrap_or_else(|e| std::panic::resume_unwind(e)))
            .collect::<Vec<_>>()
    })
    .into_iter()
    .rev()
    .collect();
    let mut next = || reports.pop().expect("a report per machine");
    // On the tool changer, each tool's own beads take its prime after a change.
    for r in next() {
        let waste = waste_share(&r);
        eprintln!("3DBenchy on marlin-toolchanger-2: waste {waste:.4} of all deposition");
        assert!(waste <= 0.15, "waste {waste:.3}");
    }
    next();
    next();
    // Both heads at once, on two motion systems, against the same machine taking
    // the tools one at a time.
    let concurrent = next();
    let sequential = next();
    if let (Some(c), Some(s)) = (concurrent.first(), sequential.first()) {
        let time = |r: &serde_json::Value| r["time"]["replayed_s"].as_f64().expect("replayed time");
        let bound = s["time"]["layers_busiest_s"].as_f64().expect("per-layer bound");
        let printing = s["time"]["layers_busiest_print_s"]
            .as_f64()
            .expect("per-layer printing");
        eprintln!(
            "3DBenchy on two motion systems: concurrent {:.1} s, one tool at a time {:.1} s (ratio {:.3}; the busier tool per layer alone {:.3}, its printing alone {:.3}); paused {:.1} % and {:.1} %",
            time(c),
            time(s),
            time(c) / time(s),
            bound / time(s),
            printing / time(s),
            100.0 * c["streams"][0]["paused_share"].as_f64().unwrap_or(f64::NAN),
            100.0 * c["streams"][1]["paused_share"].as_f64().unwrap_or(f64::NAN),
        );
        assert!(time(c) >= bound, "faster than the busier tool's work alone");
        assert!(
            bound > printing,
            "the busier tool's work is more than its printing"
        );
        assert_eq!(c["collisions"]["count"], 0);
        // Layer by layer, the busier tool's work alone takes 0.68 of the sequential
        // time, its printing alone 0.60; the replayed ratio is 0.81, with the heads
        // pulling their filament back at the synchronisations where they may wait.
        assert!(
            time(c) <= 0.85 * time(s),
            "the concurrent file is not fast enough: {:.3}",
            time(c) / time(s)
        );
    }
    // On two gantries with 15 mm heads the boat, 31 mm deep, leaves the heads little
    // to do at once: the file is never slower than one head at a time.
    let concurrent = next();
    let sequential = next();
    if let (Some(c), Some(s)) = (concurrent.first(), sequential.first()) {
        let time = |r: &serde_json::Value| r["time"]["replayed_s"].as_f64().expect("replayed time");
        eprintln!(
            "3DBenchy on two gantries: concurrent {:.1} s, one tool at a time {:.1} s (ratio {:.3})",
            time(c),
            time(s),
            time(c) / time(s)
        );
        assert_eq!(c["collisions"]["mode"], "dual-gantry");
        assert!(time(c) <= time(s) * 1.001, "slower than one tool at a time");
    }
}

/// A tube whose rings all come out at one mix never changes it: no purge, no tower.
#[test]
#[ignore = "needs ../shared/models/tube_round.stl"]
fn a_tube_of_one_mix_builds_no_tower() {
    let Some(tube) = model("tube_round.stl") else {
        return;
    };
    // The gear's pipeline with the tube's mesh for its model.
    let mut table: toml::Table = toml::from_str(
        &std::fs::read_to_string(root().join("pipelines/gear-mixing-gcode.toml")).expect("pipeline"),
    )
    .expect("TOML");
    let mut model = toml::Table::new();
    model.insert("file".into(), tube.display().to_string().into());
    table.insert("model".into(), model.into());
    let dir = tempfile::tempdir().expect("temp dir");
    let pipeline = dir.path().join("tube.toml");
    std::fs::write(&pipeline, toml::to_string(&table).expect("TOML")).expect("written");
    for r in replay_file(&pipeline, None, &[], 10, TARGETS) {
        let waste = waste_share(&r);
        eprintln!("tube_round on the mixing head: waste {waste:.4} of all deposition");
        assert!(waste <= 0.10, "waste {waste:.3}");
        let by_type = r["volume"]["by_type_mm3"].as_object().expect("volumes");
        assert!(!by_type.contains_key("TOWER") && !by_type.contains_key("PURGE"));
    }
}

/// The volume section of a replayed file's JSON report (by feature, the mesh's).
fn replayed_volumes(gcode: &Path, extra: &[&str]) -> serde_json::Value {
    let report = gcode.with_extension("replay.json");
    let o = Command::new("python3")
        .arg(root().join("tests/replay/gcode_replay.py"))
        .arg(gcode)
        .args(extra)
        .arg("--json")
        .arg(&report)
        .output()
        .expect("python3 runs");
    assert!(
        report.exists(),
        "no report for {}:\n{}{}",
        gcode.display(),
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).expect("report")).expect("JSON");
    json["volume"].clone()
}

/// The checker's JSON report on `gcode` replayed with `args`, which must pass; its
/// summary is printed.
fn checked_replay(gcode: &Path, args: &[String]) -> serde_json::Value {
    let report = gcode.with_extension("checked.json");
    let o = Command::new("python3")
        .arg(root().join("tests/replay/gcode_replay.py"))
        .arg(gcode)
        .args(args)
        .arg("--json")
        .arg(&report)
        .output()
        .expect("python3 runs");
    let said = String::from_utf8_lossy(&o.stdout);
    eprintln!("{said}");
    assert!(
        o.status.success(),
        "{} {args:?} does not replay cleanly:\n{said}",
        gcode.display()
    );
    serde_json::from_str(&std::fs::read_to_string(&report).expect("report")).expect("JSON report")
}

/// PrusaSlicer 2.5 (the Debian package), a slicer the printing world trusts, fills the
/// gear solid (100 % rectilinear infill, 0.4 mm nozzle, 0.2 mm layers) and deposits
/// within 2 % of the mesh volume; Lamina's file for the same gear must agree with it
/// and with the mesh. Both files go through the same replay checker.
#[test]
fn prusa_slicer_and_lamina_deposit_the_same_volume_for_the_gear() {
    if !checker_ready() {
        return;
    }
    let prusa = Command::new("prusa-slicer").arg("--help").output();
    if prusa.is_err() {
        skip("prusa-slicer is not installed (Debian package prusa-slicer)");
        return;
    }
    let dir = tempfile::tempdir().expect("temp dir");
    let pipeline = root().join("pipelines/gear-mixing-gcode.toml");
    let table: toml::Table =
        toml::from_str(&std::fs::read_to_string(&pipeline).expect("pipeline")).expect("TOML");
    let mesh = model_stl(&pipeline, &table, dir.path());
    let reference = dir.path().join("prusa.gcode");
    let o = Command::new("prusa-slicer")
        .args([
            "--export-gcode",
            "--fill-density",
            "100%",
            "--fill-pattern",
            "rectilinear",
            "--layer-height",
            "0.2",
            "--first-layer-height",
            "0.2",
            "--nozzle-diameter",
            "0.4",
            "--filament-diameter",
            "1.75",
            "--retract-length",
            "4",
            "--center",
            "110,110",
            "--output",
        ])
        .arg(&reference)
        .arg(&mesh)
        .output()
        .expect("prusa-slicer runs");
    assert!(
        o.status.success(),
        "prusa-slicer failed:\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let theirs: f64 = replayed_volumes(&reference, &["--flavor", "marlin"])["by_type_mm3"]
        .as_object()
        .expect("volumes by feature")
        .iter()
        .filter(|(k, _)| !k.contains("SKIRT") && !k.contains("WIPE"))
        .map(|(_, v)| v.as_f64().expect("mm³"))
        .sum();
    let out = dir.path().join("out");
    lamina(&[
        "run",
        pipeline.to_str().expect("utf-8"),
        "--out",
        out.to_str().expect("utf-8"),
        "-q",
    ]);
    let mesh_arg = format!("--mesh={}", mesh.display());
    let volumes = replayed_volumes(&out.join("gear-mixing.gcode"), &[&mesh_arg]);
    let ours = volumes["by_type_mm3"]["PART"].as_f64().expect("mm³");
    let mesh_volume = volumes["mesh_mm3"].as_f64().expect("mesh mm³");
    eprintln!(
        "gear: mesh {mesh_volume:.1} mm³, PrusaSlicer {theirs:.1} mm³ ({:.4}), Lamina {ours:.1} mm³ ({:.4})",
        theirs / mesh_volume,
        ours / mesh_volume
    );
    assert!((theirs / mesh_volume - 1.0).abs() < 0.02, "PrusaSlicer {theirs}");
    assert!((ours / mesh_volume - 1.0).abs() < 0.02, "Lamina {ours}");
    assert!(
        (ours / theirs - 1.0).abs() < 0.02,
        "Lamina {ours} vs PrusaSlicer {theirs}"
    );
    // Both with 4 mm retractions: travels over the part, and around a gap inside it,
    // keep the filament where it is.
    let read = |p: &Path| std::fs::read_to_string(p).expect("G-code");
    let (ours, theirs) = (
        retraction_count(&read(&out.join("gear-mixing.gcode"))),
        retraction_count(&read(&reference)),
    );
    eprintln!("gear: {ours} retractions, PrusaSlicer {theirs}");
    assert!(ours as f64 <= 1.5 * theirs as f64, "{ours} against {theirs}");
}

/// Moves that only pull filament back (`G1 E` lower, without X or Y), as Marlin reads
/// `M82`/`M83` and `G92`.
fn retraction_count(gcode: &str) -> usize {
    let (mut e, mut relative, mut n) = (0.0f64, false, 0);
    for line in gcode.lines() {
        let code = line.split(';').next().unwrap_or("");
        let mut words = code.split_whitespace();
        let Some(command) = words.next() else { continue };
        let word = |l: char| {
            code.split_whitespace()
                .skip(1)
                .find(|w| w.starts_with(l))
                .and_then(|w| w[1..].parse::<f64>().ok())
        };
        match command {
            "M82" => relative = false,
            "M83" => relative = true,
            "G92" => e = word('E').unwrap_or(e),
            "G0" | "G1" => {
                if let Some(v) = word('E') {
                    let de = if relative { v } else { v - e };
                    e = if relative { e + v } else { v };
                    if de < 0.0 && word('X').is_none() && word('Y').is_none() {
                        n += 1;
                    }
                }
            }
            _ => {}
        }
    }
    n
}

/// PrusaSlicer's own estimate (`estimated printing time (normal mode) = 2h 8m 40s`), s.
fn prusa_estimate(gcode: &str) -> f64 {
    let line = gcode
        .lines()
        .find(|l| l.contains("estimated printing time (normal mode)"))
        .expect("PrusaSlicer's estimate");
    let text = line.split('=').nth(1).expect("a time");
    text.split_whitespace()
        .map(|part| {
            let (value, unit) = part.split_at(part.len() - 1);
            let scale = match unit {
                "d" => 86_400.0,
                "h" => 3_600.0,
                "m" => 60.0,
                _ => 1.0,
            };
            value.parse::<f64>().unwrap_or(0.0) * scale
        })
        .sum()
}

/// The two-tool 3DBenchy on the tool changer, every wait of the file included (heating
/// and tool changes, which the replay times alike), within a quarter more than
/// PrusaSlicer's single-material 3DBenchy at 100 % infill, the same layer height and
/// speeds (../shared/REFERENCES.md).
#[test]
#[ignore = "needs ../shared/models/3DBenchy.stl"]
fn benchy_on_the_tool_changer_takes_at_most_a_quarter_more_than_prusa_slicer() {
    let Some(benchy) = model("3DBenchy.stl") else {
        return;
    };
    if Command::new("prusa-slicer").arg("--help").output().is_err() {
        skip("prusa-slicer is not installed (Debian package prusa-slicer)");
        return;
    }
    let dir = tempfile::tempdir().expect("temp dir");
    let reference = dir.path().join("prusa.gcode");
    let speeds = [
        "--perimeter-speed",
        "--external-perimeter-speed",
        "--infill-speed",
        "--solid-infill-speed",
        "--top-solid-infill-speed",
        "--gap-fill-speed",
        "--small-perimeter-speed",
        "--bridge-speed",
    ];
    let mut args: Vec<String> = [
        "--export-gcode",
        "--layer-height",
        "0.2",
        "--first-layer-height",
        "0.2",
        "--nozzle-diameter",
        "0.4",
        "--fill-density",
        "100%",
        "--fill-pattern",
        "rectilinear",
        "--first-layer-speed",
        "25",
        "--travel-speed",
        "120",
    ]
    .map(String::from)
    .to_vec();
    for s in speeds {
        args.extend([s.to_string(), "30".into()]);
    }
    let o = Command::new("prusa-slicer")
        .args(&args)
        .arg("--output")
        .arg(&reference)
        .arg(&benchy)
        .output()
        .expect("prusa-slicer runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let theirs = prusa_estimate(&std::fs::read_to_string(&reference).expect("G-code"));
    let out = dir.path().join("out");
    let pipeline = root().join("pipelines/benchy-two-tools.toml");
    let run = lamina(&[
        "run",
        pipeline.to_str().expect("utf-8"),
        "--model",
        benchy.to_str().expect("utf-8"),
        "--out",
        out.to_str().expect("utf-8"),
        "-q",
    ]);
    // What the run says is for people: no debug text, no region of no area.
    let said = String::from_utf8_lossy(&run.stderr);
    assert!(
        !said.contains("Deadlock(") && !said.contains("(0.000 mm²)"),
        "{said}"
    );
    let gcode = std::fs::read_to_string(out.join("benchy-two-tools.gcode")).expect("G-code");
    let ours: f64 = gcode
        .lines()
        .find_map(|l| l.strip_prefix("; estimated printing time: "))
        .and_then(|t| t.strip_suffix(" s")?.parse().ok())
        .expect("the file's estimate");
    eprintln!(
        "3DBenchy: Lamina's two-tool file {ours:.1} s, PrusaSlicer single material {theirs:.1} s: {:.3}",
        ours / theirs
    );
    assert!(ours <= 1.25 * theirs, "{ours} s against {theirs} s");
}

#[test]
fn an_under_filled_plan_fails_and_writes_nothing() {
    // Sixty rings across the gear's rim are each far narrower than the narrowest bead;
    // left out (`thin = "skip"`), the beads would fill a fraction of the part.
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("out");
    let pipeline = root().join("pipelines/gear-mixing-gcode.toml");
    let o = Command::new(env!("CARGO_BIN_EXE_lamina"))
        .args([
            "run",
            pipeline.to_str().expect("utf-8"),
            "--out",
            out.to_str().expect("utf-8"),
        ])
        .args(["--set", "discretise.count=60", "--set", "plan.thin=\"skip\""])
        .output()
        .expect("lamina runs");
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("min_fill") && err.contains("mm³"), "{err}");
    let written: Vec<_> = std::fs::read_dir(&out)
        .map(|d| d.filter_map(|e| e.ok()).map(|e| e.path()).collect())
        .unwrap_or_default();
    assert!(
        written.iter().all(|p| p
            .file_name()
            .is_some_and(|n| n.to_string_lossy().starts_with('.'))),
        "{written:?}"
    );
}

/// A tube of radii 10 and 5 in two rings, graded by Eq. 18 at points (`r = "points"`):
/// at radius rho, r = (10 - rho) / 5 and the red share is 1 - r.
const TUBE_GRADED_AT_POINTS: &str = "name = \"mix-along\"\nmachine = \"marlin-mixing-2in1\"\n\
    [model]\nuse = \"tube\"\nouter_radius = 10.0\ninner_radius = 5.0\nheight = 0.6\n\
    [materials.red]\ncolour = [255, 0, 0]\n[materials.green]\ncolour = [0, 255, 0]\n\
    [[parts]]\nname = \"tube\"\nmaterials = [\"red\", \"green\"]\n\
    [parts.grade]\nuse = \"xy\"\nr = \"points\"\ngrid = 0.2\nf = \"linear\"\nmu = -1.0\nlambda = 1.0\n\
    [slice]\nuse = \"uniform\"\nthickness = 0.2\n\
    [discretise]\nuse = \"offset\"\ncount = 2\n\
    [plan]\nuse = \"sequential\"\nmixing = true\nwidth = 0.4\n\
    [[output]]\nuse = \"gcode\"\npath = \"tube.gcode\"\n";

/// The red share of the mix (Marlin: `M163 S0 P<f>` ... `M164 S0` sets virtual tool
/// 0, the one in use) of every extruding move of the part, with the distance of its
/// middle from the tube's axis. The axis is where the header's placement put the origin.
fn part_moves_and_mixes(gcode: &str) -> Vec<(f64, f64)> {
    let placed = gcode
        .lines()
        .find_map(|l| l.strip_prefix("; coordinates:"))
        .and_then(|l| l.rsplit(" by ").next())
        .map(|by| {
            let v: Vec<f64> = by
                .split_whitespace()
                .map(|w| w[1..].parse().expect("offset"))
                .collect();
            (v[0], v[1])
        })
        .expect("placement");
    let word = |line: &str, c: char| {
        line.split(';')
            .next()
            .unwrap_or("")
            .split_whitespace()
            .find_map(|w| w.strip_prefix(c).and_then(|v| v.parse::<f64>().ok()))
    };
    let (mut x, mut y, mut e) = (0.0, 0.0, 0.0);
    let (mut pending, mut mix) = ([0.0f64; 2], [1.0f64, 0.0]);
    let mut part = false;
    let mut out = Vec::new();
    for line in gcode.lines() {
        if let Some(t) = line.strip_prefix(";TYPE:") {
            part = t.trim() == "PART";
        }
        let code = line.split(';').next().unwrap_or("").trim();
        if code.starts_with("M163") {
            let (s, p) = (word(code, 'S').expect("S"), word(code, 'P').expect("P"));
            pending[s as usize] = p;
        } else if code.starts_with("M164") {
            let sum: f64 = pending.iter().sum();
            mix = [pending[0] / sum, pending[1] / sum];
        } else if code.starts_with("G92") {
            e = word(code, 'E').unwrap_or(e);
        } else if code.starts_with("G1") || code.starts_with("G0") {
            let (nx, ny) = (word(code, 'X').unwrap_or(x), word(code, 'Y').unwrap_or(y));
            let ne = word(code, 'E').unwrap_or(e);
            if part && ne > e && (nx != x || ny != y) {
                let (mx, my) = ((x + nx) / 2.0 - placed.0, (y + ny) / 2.0 - placed.1);
                out.push((mx.hypot(my), mix[0]));
            }
            (x, y, e) = (nx, ny, ne);
        }
    }
    out
}

/// Eq. 18 at every point of a bead on a mixing head (`mix_along`): each extruding move
/// of the tube is deposited with the red share 1 - (10 - rho) / 5 of its radius rho,
/// within the 1 % steps of the mix and the 2 % dead band. With one mix per sub-region
/// (two rings 2.5 mm wide) the moves are up to a fifth off; the replay checker passes
/// the file either way.
#[test]
fn a_mixing_head_follows_eq_18_along_its_beads() {
    let dir = tempfile::tempdir().expect("tempdir");
    let pipeline = dir.path().join("tube.toml");
    std::fs::write(&pipeline, TUBE_GRADED_AT_POINTS).expect("pipeline");
    let mut worst = Vec::new();
    for along in [true, false] {
        let out = dir.path().join(format!("out-{along}"));
        lamina(&[
            "run",
            pipeline.to_str().expect("utf-8"),
            "--out",
            out.to_str().expect("utf-8"),
            "-q",
            "--set",
            &format!("output.0.mix_along={along}"),
        ]);
        let gcode = std::fs::read_to_string(out.join("tube.gcode")).expect("G-code");
        let moves = part_moves_and_mixes(&gcode);
        assert!(moves.len() > 100, "{} moves", moves.len());
        let off = moves
            .iter()
            .map(|&(rho, red)| (red - (1.0 - (10.0 - rho) / 5.0)).abs())
            .fold(0.0, f64::max);
        worst.push(off);
    }
    println!(
        "largest error of the red share: {:.4} along beads, {:.4} per region",
        worst[0], worst[1]
    );
    assert!(worst[0] <= 0.03, "along the beads: {}", worst[0]);
    assert!(
        worst[1] > 0.15,
        "one mix per region is this far off: {}",
        worst[1]
    );
    // And the file replays: volumes, coverage, mixes summing to 1, heating order.
    let reports = replay_file(&pipeline, None, &["output.0.mix_along=true"], 1, TARGETS);
    for r in &reports {
        assert!(r.is_object(), "{r}");
    }
}

/// Copies of the graded gear on one plate (`copies = 2`): the replayed G-code deposits
/// each copy whole where the plate puts it (side by side, 10 mm apart), as checked
/// against a plate of gears composed by trimesh, not by Lamina: volume within 2 % and
/// every sampled layer covered. (`plate::` checks the grid's rows and the copies'
/// grading.)
#[test]
fn copies_of_the_gear_are_deposited_whole_where_the_plate_puts_them() {
    if !checker_ready() {
        return;
    }
    let dir = tempfile::tempdir().expect("temp dir");
    let gear = dir.path().join("gear.stl");
    let plate = dir.path().join("plate.stl");
    let out = dir.path().join("out");
    lamina(&[
        "generate",
        "gear",
        "teeth=16",
        "height=2.0",
        "-o",
        gear.to_str().expect("utf-8"),
    ]);
    let composed = Command::new("python3")
        .arg("-c")
        .arg(
            "import sys, trimesh\n\
             g = trimesh.load(sys.argv[1])\n\
             (x0, y0, _), (x1, y1, _) = g.bounds\n\
             w, h = x1 - x0 + 10.0, y1 - y0 + 10.0\n\
             copies = [g.copy().apply_translation([c * w, 0, 0]) for c in (0, 1)]\n\
             trimesh.util.concatenate(copies).export(sys.argv[2])\n",
        )
        .arg(&gear)
        .arg(&plate)
        .output()
        .expect("python3 runs");
    assert!(
        composed.status.success(),
        "{}",
        String::from_utf8_lossy(&composed.stderr)
    );
    let pipeline = root().join("pipelines/gear-mixing-gcode.toml");
    lamina(&[
        "run",
        pipeline.to_str().expect("utf-8"),
        "--model",
        gear.to_str().expect("utf-8"),
        "--set",
        "parts.0.copies=2",
        "--out",
        out.to_str().expect("utf-8"),
        "-q",
    ]);
    let gcode = out.join("gear-mixing.gcode");
    let text = std::fs::read_to_string(&gcode).expect("G-code");
    assert!(
        text.contains("; part gear#2: red, green"),
        "the copy is not named"
    );
    let machine = machine_table(&toml::Value::String("marlin-mixing-2in1".into()), &pipeline);
    let [x0, y0, x1, y1] = bed(&machine);
    let mut args: Vec<String> = [
        "--mesh",
        plate.to_str().expect("utf-8"),
        "--place",
        "centre",
        "--bead-ends",
        "round",
    ]
    .map(String::from)
    .to_vec();
    args.push("--coverage-every=3".into());
    args.push(format!("--bed={x0},{y0},{x1},{y1}"));
    args.extend(heating_args(&machine));
    let r = checked_replay(&gcode, &args);
    eprintln!("volume: {}", r["volume"]);
}

/// Replays the G-code `lamina run` writes for the gear and shaft on `machine` with
/// `overrides`, without a mesh (a plate of copies is not the pipeline's model), once
/// as planned and once per timing perturbation; the reports, or none without the
/// checker.
fn replay_plate(machine: &str, overrides: &[&str], perturb: &[&str]) -> Vec<serde_json::Value> {
    if !checker_ready() {
        return Vec::new();
    }
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("out");
    let pipeline = root().join("pipelines/assembly-two-tools.toml");
    let set_machine = format!("machine=\"{machine}\"");
    let mut args = vec![
        "run",
        pipeline.to_str().expect("utf-8"),
        "--out",
        out.to_str().expect("utf-8"),
        "-q",
        "--set",
        &set_machine,
    ];
    for o in overrides {
        args.extend(["--set", o]);
    }
    lamina(&args);
    let table = machine_table(&toml::Value::String(machine.into()), &pipeline);
    let [x0, y0, x1, y1] = bed(&table);
    let gcode = out.join("assembly-two-tools.gcode");
    let mut reports = Vec::new();
    for p in std::iter::once(None).chain(perturb.iter().map(Some)) {
        let mut args = vec![format!("--bed={x0},{y0},{x1},{y1}")];
        args.extend(heating_args(&table));
        args.extend(p.map(|p| format!("--perturb={p}")));
        reports.push(checked_replay(&gcode, &args));
    }
    reports
}

/// Four gears on their shafts in a column on two gantries (`copies = 4`,
/// `copy_columns = 1`): the rear head leads down the plate and the front head follows
/// a copy behind, so the heads work at once. Replayed, the heads keep their order and
/// distance in Y (also with the rear system's feeds a fifth slower), and the plate
/// takes at most 0.8 of one tool at a time on the same machine (0.77 measured).
#[test]
fn a_column_of_gears_on_two_gantries_is_built_by_both_heads_at_once() {
    let plate = [
        "parts.0.copies=4",
        "parts.1.copies=4",
        "parts.0.copy_columns=1",
        "parts.1.copy_columns=1",
        "parts.0.copy_gap=15.0",
        "parts.1.copy_gap=15.0",
    ];
    let concurrent = replay_plate("rrf-dual-gantry-2", &plate, &["1:0.8,1"]);
    let sequential = replay_plate(
        "rrf-dual-gantry-2",
        &[&plate[..], &["plan.use=\"sequential\""]].concat(),
        &[],
    );
    let (Some(c), Some(s)) = (concurrent.first(), sequential.first()) else {
        return;
    };
    for r in &concurrent {
        assert_eq!(r["collisions"]["mode"], "dual-gantry");
        assert_eq!(r["collisions"]["count"], 0, "{}", r["collisions"]);
        assert_eq!(r["checks"]["separation"]["status"], "pass");
    }
    let time = |r: &serde_json::Value| r["time"]["replayed_s"].as_f64().expect("replayed time");
    let ratio = time(c) / time(s);
    eprintln!(
        "four gears on two gantries: {:.1} s, one tool at a time {:.1} s ({ratio:.3})",
        time(c),
        time(s)
    );
    assert!(ratio <= 0.8, "{ratio}");
}
