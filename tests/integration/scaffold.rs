//! docs/plugins.md, step by step: `lamina new-plugin` writes a crate outside the
//! workspace, `cargo build` and `cargo test` pass in it, and `lamina` loads the library
//! and runs the pipeline the crate comes with. Every kind with a template is built and
//! tested; the grader's output is checked against what its template computes.

use crate::support::{self, lamina_in, root, target_dir};
use std::path::{Path, PathBuf};

/// Runs cargo in a scaffolded crate, with the lock file it comes with: the crate
/// resolves the releases Lamina is built and tested with, not whatever the registry
/// holds today. The crates scaffolded share one build folder, so their dependencies
/// are compiled once.
fn cargo(dir: &Path, args: &[&str]) {
    assert!(
        dir.join("Cargo.lock").is_file(),
        "the scaffold carries no lock file"
    );
    let out = support::cargo_outside(dir, args).output().expect("cargo runs");
    assert!(
        out.status.success(),
        "cargo {args:?} in {}:\n{}\n{}",
        dir.display(),
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

fn library(name: &str) -> PathBuf {
    target_dir().join("debug").join(format!(
        "{}{}{}",
        std::env::consts::DLL_PREFIX,
        name.replace('-', "_"),
        std::env::consts::DLL_SUFFIX
    ))
}

/// Scaffolds, builds and tests a crate of `kind`, then runs its pipeline with the
/// library loaded; returns the crate's folder and the run's output folder.
fn scaffold(work: &Path, name: &str, kind: &str) -> (PathBuf, PathBuf) {
    let checkout = root().to_str().expect("utf-8").to_string();
    let out = lamina_in(work, &["new-plugin", name, "--kind", kind, "--lamina", &checkout]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let krate = work.join(name);
    // Lamina's crates by version, from the checkout named on the command line only.
    let manifest = std::fs::read_to_string(krate.join("Cargo.toml")).expect("manifest");
    assert!(
        manifest.contains(&format!("lamina-api = \"{}\"", lamina_core::VERSION))
            && manifest.contains("[patch.crates-io]")
            && manifest.matches(checkout.as_str()).count() == 2,
        "{manifest}"
    );
    // What a plugin author starts from is formatted as `cargo fmt` would.
    let fmt = std::process::Command::new(std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into()))
        .args(["fmt", "--check"])
        .current_dir(&krate)
        .output()
        .expect("cargo fmt runs");
    assert!(fmt.status.success(), "{}", String::from_utf8_lossy(&fmt.stdout));
    cargo(&krate, &["build", "--quiet"]);
    cargo(&krate, &["test", "--quiet"]);
    let lib = library(name);
    let listed = lamina_in(
        &krate,
        &["plugins", kind, "--plugin", lib.to_str().expect("utf-8")],
    );
    assert!(listed.status.success());
    assert!(
        String::from_utf8_lossy(&listed.stdout).contains(name),
        "{}",
        String::from_utf8_lossy(&listed.stdout)
    );
    let run = lamina_in(
        &krate,
        &[
            "run",
            "pipeline.toml",
            "--plugin",
            lib.to_str().expect("utf-8"),
            "--out",
            "out",
            "-q",
        ],
    );
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    (krate.clone(), krate.join("out"))
}

/// The JSON plan `file` a run wrote into `dir`.
fn plan_in(dir: &Path, file: &str) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(dir.join(file)).expect("the plan")).expect("json")
}

/// The plan of the crate's pipeline with the built-in stage `set` names in place of the
/// template's.
fn built_in_plan(krate: &Path, set: &str) -> serde_json::Value {
    let run = lamina_in(
        krate,
        &["run", "pipeline.toml", "--set", set, "--out", "built-in", "-q"],
    );
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    plan_in(&krate.join("built-in"), "plan.json")
}

#[test]
fn the_plugin_guide_works_from_scaffold_to_a_loaded_plugin() {
    let guide = std::fs::read_to_string(root().join("docs/plugins.md")).expect("the guide");
    let lib = library("my-grader");
    let lib_name = lib.file_name().expect("name").to_string_lossy().into_owned();
    for step in [
        "lamina new-plugin my-grader --kind grade --lamina".to_string(),
        "cargo build".to_string(),
        "cargo test".to_string(),
        format!("lamina run pipeline.toml --plugin target/debug/{lib_name} --out out"),
        format!("lamina plugins grade --plugin target/debug/{lib_name}"),
    ] {
        assert!(guide.contains(&step), "docs/plugins.md no longer says `{step}`");
    }
    let work = tempfile::tempdir().expect("tempdir");
    let (_, out) = scaffold(work.path(), "my-grader", "grade");
    // The template blends red into green between z = 0 and 2 mm.
    let plan = plan_in(&out, "plan.json");
    for layer in plan["layers"].as_array().expect("layers") {
        let z = layer["z"].as_f64().expect("z");
        for region in layer["parts"][0]["families"][0]["sub_regions"]
            .as_array()
            .expect("regions")
        {
            let red = region["composition"]["red"].as_f64().expect("graded");
            assert!(
                (red - (1.0 - z / 2.0).clamp(0.0, 1.0)).abs() < 1e-12,
                "z = {z}: {red}"
            );
        }
    }
    // Without a checkout, the crate names no folder: it asks the registry.
    let bare = lamina_in(work.path(), &["new-plugin", "bare-grader"]);
    assert!(bare.status.success(), "{}", String::from_utf8_lossy(&bare.stderr));
    let manifest = std::fs::read_to_string(work.path().join("bare-grader/Cargo.toml")).expect("manifest");
    assert!(
        !manifest.contains("patch") && !manifest.contains("path ="),
        "{manifest}"
    );
    assert!(String::from_utf8_lossy(&bare.stdout).contains("--lamina PATH"));
    // A second scaffold into the same folder is refused and leaves the first alone.
    let again = lamina_in(work.path(), &["new-plugin", "my-grader"]);
    assert_eq!(again.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&again.stderr).contains("exists already"));
}

#[test]
fn every_template_builds_tests_and_runs() {
    let work = tempfile::tempdir().expect("tempdir");
    let (_, out) = scaffold(work.path(), "my-regions", "discretise");
    assert!(out.join("plan.json").is_file());
    let (_, out) = scaffold(work.path(), "my-box", "model");
    let plan = plan_in(&out, "plan.json");
    for layer in plan["layers"].as_array().expect("layers") {
        let area: f64 = layer["parts"][0]["families"][0]["area"].as_f64().expect("area");
        assert!((area - 60.0).abs() < 1e-9, "{area}");
    }
    let (_, out) = scaffold(work.path(), "my-table", "export");
    let csv = std::fs::read_to_string(out.join("regions.csv")).expect("the table");
    let mut lines = csv.lines();
    assert_eq!(lines.next(), Some("layer,z,part,family,region,area,red,green"));
    assert_eq!(lines.count(), 4, "{csv}");
    // The planner beads every sub-region's outline with its main material's tool.
    let (_, out) = scaffold(work.path(), "my-beads", "plan");
    let plan = plan_in(&out, "plan.json");
    for layer in plan["layers"].as_array().expect("layers") {
        let regions = layer["parts"][0]["families"][0]["sub_regions"]
            .as_array()
            .expect("regions");
        let paths = layer["toolpaths"].as_array().expect("toolpaths");
        // A tube's sub-region is a ring: a bead outside and one inside.
        assert_eq!(paths.len(), 2 * regions.len(), "{layer}");
    }
    // The process stage probes every layer, the last one twice as `final`.
    let (_, out) = scaffold(work.path(), "my-probe", "process");
    let plan = plan_in(&out, "plan.json");
    let layers = plan["layers"].as_array().expect("layers");
    for (i, layer) in layers.iter().enumerate() {
        let ops = layer["operations"].as_array().expect("operations");
        assert_eq!(ops.len(), 1, "{layer}");
        assert_eq!(ops[0]["kind"], "my-probe");
        assert_eq!(ops[0]["pass"] == "final", i + 1 == layers.len(), "{layer}");
    }
    // The orienter lays the box standing on its end (2 x 6 x 10 mm) down along x: 4
    // layers of 0.5 mm instead of 20.
    let (_, out) = scaffold(work.path(), "my-orient", "orient");
    let plan = plan_in(&out, "plan.json");
    assert_eq!(plan["layers"].as_array().expect("layers").len(), 4);
    // The sorter finds the tube's hole and gives the families the built-in one gives.
    let (krate, out) = scaffold(work.path(), "my-sort", "sort");
    let ours = plan_in(&out, "plan.json");
    let theirs = built_in_plan(&krate, "sort.use=\"hierarchy\"");
    assert_eq!(ours["layers"], theirs["layers"]);
    let family = &ours["layers"][0]["parts"][0]["families"][0];
    assert_eq!(family["holes"].as_array().map(Vec::len), Some(1), "{family}");
    // The slicer cuts the tube as the built-in one does: the same layers, the same
    // areas.
    let (krate, out) = scaffold(work.path(), "my-slicer", "slice");
    let ours = plan_in(&out, "plan.json");
    let theirs = built_in_plan(&krate, "slice.use=\"uniform\"");
    let layers = |plan: &serde_json::Value| plan["layers"].as_array().expect("layers").clone();
    assert_eq!(layers(&ours).len(), 4);
    assert_eq!(layers(&ours).len(), layers(&theirs).len());
    for (a, b) in layers(&ours).iter().zip(layers(&theirs).iter()) {
        assert_eq!(a["z"], b["z"]);
        let area = |l: &serde_json::Value| l["parts"][0]["families"][0]["area"].as_f64().expect("area");
        assert!(
            (area(a) - area(b)).abs() < 1e-9 * area(b),
            "{} against {}",
            area(a),
            area(b)
        );
    }
    // The sequencer gives the paper's pipe (0.2, 0.5 and 1.5 mm layers: an 18-step
    // work cycle) the layers the built-in work cycles give.
    let (krate, out) = scaffold(work.path(), "my-cycles", "sequence");
    assert!(out.join("plan.json").is_file());
    let pipe = std::fs::read_to_string(root().join("pipelines/pipe-work-cycles.toml")).expect("pipe");
    let mine = pipe.replace("use = \"work-cycles\"", "use = \"my-cycles\"");
    assert_ne!(mine, pipe);
    let lib = library("my-cycles");
    for (name, text, plugin) in [("mine", mine.as_str(), true), ("theirs", pipe.as_str(), false)] {
        let file = format!("{name}.toml");
        std::fs::write(krate.join(&file), text).expect("write");
        let mut args = vec!["run", file.as_str(), "--out", name, "-q"];
        if plugin {
            args.extend(["--plugin", lib.to_str().expect("utf-8")]);
        }
        let run = lamina_in(&krate, &args);
        assert!(
            run.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&run.stderr)
        );
    }
    let cycles = |dir: &str| plan_in(&krate.join(dir), "pipe-work-cycles.json");
    let (ours, theirs) = (cycles("mine"), cycles("theirs"));
    assert_eq!(ours["layer_count"], 46, "{}", ours["sequence"]);
    assert_eq!(ours["sequence"], theirs["sequence"]);
    assert_eq!(ours["layers"], theirs["layers"]);
    // Every stage kind has a template; anything else is a clear refusal.
    for kind in lamina_core::StageKind::ALL {
        let dir = work.path().join(format!("any-{kind}"));
        let written = lamina_in(
            work.path(),
            &[
                "new-plugin",
                "any",
                "--kind",
                kind.name(),
                "--dir",
                dir.to_str().expect("utf-8"),
            ],
        );
        assert!(
            written.status.success(),
            "{kind}: {}",
            String::from_utf8_lossy(&written.stderr)
        );
    }
    let refused = lamina_in(work.path(), &["new-plugin", "my-mesh", "--kind", "mesh"]);
    assert_eq!(refused.status.code(), Some(2));
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(
        err.contains("no plugin template for `mesh`") && err.contains("sequence"),
        "{err}"
    );
    assert!(!work.path().join("my-mesh").exists());
}
