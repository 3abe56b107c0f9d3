//! Every stage describes itself, and its example table runs: each built-in stage's
//! example is placed in a small pipeline on a generated model and run end to end.

use std::path::Path;

use lamina_core::pipeline::Pipeline;
use lamina_core::runtime::{Engine, RunOptions, Silent};
use lamina_core::{Registry, SourceFile, StageKind};

fn registry() -> Registry {
    use lamina_discretise as _;
    use lamina_export as _;
    use lamina_gcode as _;
    use lamina_grade as _;
    use lamina_model as _;
    use lamina_orient as _;
    use lamina_plan as _;
    use lamina_preview as _;
    use lamina_sequence as _;
    use lamina_slice as _;
    use lamina_sort as _;
    use lamina_sources as _;
    Registry::linked().expect("registry")
}

/// A tube written as the files the reader examples name.
fn write_models(dir: &Path) {
    let mut meshes = {
        let table = lamina_core::pipeline::TableRef::parse_snippet("m", "use = \"tube\"\nheight = 2.0")
            .expect("snippet");
        let scripts = lamina_core::script::ScriptHost::new(dir, Default::default());
        match registry()
            .build(StageKind::Model, &table, &scripts, dir)
            .expect("tube")
        {
            lamina_core::AnyStage::Model(m) => m.load(dir).expect("loads"),
            _ => panic!("not a model"),
        }
    };
    let mesh = meshes.remove(0);
    let mut stl = Vec::new();
    lamina_model::stl::write_binary(&mesh, &mut stl).expect("stl");
    std::fs::write(dir.join("part.stl"), stl).expect("write stl");
    let mut obj = String::new();
    for v in &mesh.vertices {
        obj.push_str(&format!("v {} {} {}\n", v.x, v.y, v.z));
    }
    for t in &mesh.triangles {
        obj.push_str(&format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1));
    }
    std::fs::write(dir.join("part.obj"), obj).expect("write obj");
    let package = lamina_model::threemf::write(std::slice::from_ref(&mesh)).expect("3mf");
    std::fs::write(dir.join("part.3mf"), package).expect("write 3mf");
}

fn pipeline_for(kind: StageKind, example: &str) -> String {
    let mut tables = vec![
        ("model", "use = \"tube\"\nheight = 2.0".to_string()),
        ("slice", "use = \"uniform\"\nthickness = 0.5".to_string()),
    ];
    let mut outputs = vec!["use = \"json\"\npath = \"plan.json\"".to_string()];
    match kind {
        StageKind::Export => outputs = vec![example.to_string()],
        k => {
            if let Some(t) = tables.iter_mut().find(|(n, _)| *n == k.name()) {
                t.1 = example.to_string();
            } else {
                tables.push((k.name(), example.to_string()));
            }
        }
    }
    let mut text =
        String::from("[materials.red]\ncolour = [255, 0, 0]\n[materials.green]\ncolour = [0, 255, 0]\n\n");
    if kind != StageKind::Grade {
        // Both materials stay on the part (a discretiser may name them) and a constant
        // grader says how they mix.
        text.push_str("[grade]\nuse = \"constant\"\nmaterial = \"red\"\n\n");
    }
    for (name, body) in tables {
        text.push_str(&format!("[{name}]\n{body}\n\n"));
    }
    for o in outputs {
        text.push_str(&format!("[[output]]\n{o}\n\n"));
    }
    text
}

#[test]
fn every_stage_is_documented_and_its_example_runs() {
    let registry = registry();
    let dir = tempfile::tempdir().expect("tempdir");
    write_models(dir.path());
    let mut names = std::collections::HashSet::new();
    let all = registry.list(None);
    assert!(!all.is_empty());
    for entry in all {
        let info = entry.info();
        assert!(
            names.insert((info.kind, info.name)),
            "duplicate {}",
            entry.label()
        );
        assert!(
            !info.doc.is_empty() && !info.doc.contains('\n'),
            "{}: doc must be one line",
            entry.label()
        );
        assert!(
            info.example.contains(&format!("use = \"{}\"", info.name)),
            "{}: the example must name the stage",
            entry.label()
        );
        for o in info.options {
            assert!(
                !o.doc.is_empty(),
                "{}: option {} undocumented",
                entry.label(),
                o.name
            );
        }
        let text = pipeline_for(info.kind, info.example);
        let file = SourceFile::new(
            dir.path().join(format!("{}-{}.toml", info.kind, info.name)),
            text.clone(),
        );
        let pipeline = Pipeline::parse(file, dir.path().to_path_buf(), &[])
            .unwrap_or_else(|e| panic!("{}: {e}\n{text}", entry.label()));
        let engine = Engine::build(pipeline, registry.clone(), &RunOptions::default())
            .unwrap_or_else(|e| panic!("{}: example does not build: {e}\n{text}", entry.label()));
        let out = dir.path().join("out").join(entry.label().replace(':', "-"));
        let report = engine
            .run(&out, &Silent)
            .unwrap_or_else(|e| panic!("{}: example does not run: {e}\n{text}", entry.label()));
        assert!(
            report.layers > 0 && report.regions > 0,
            "{}: produced nothing",
            entry.label()
        );
        assert!(!report.files.is_empty(), "{}: wrote nothing", entry.label());
    }
}

#[test]
fn the_expected_built_in_stages_are_registered() {
    let registry = registry();
    for (kind, name) in [
        (StageKind::Model, "stl"),
        (StageKind::Model, "obj"),
        (StageKind::Model, "3mf"),
        (StageKind::Model, "gear"),
        (StageKind::Model, "gear-shaft"),
        (StageKind::Model, "tube"),
        (StageKind::Model, "box"),
        (StageKind::Model, "cube"),
        (StageKind::Model, "blade"),
        (StageKind::Orient, "candidates"),
        (StageKind::Slice, "uniform"),
        (StageKind::Slice, "adaptive"),
        (StageKind::Sort, "hierarchy"),
        (StageKind::Discretise, "offset"),
        (StageKind::Discretise, "step-width"),
        (StageKind::Discretise, "distance-field"),
        (StageKind::Discretise, "sources"),
        (StageKind::Grade, "script"),
        (StageKind::Grade, "constant"),
        (StageKind::Grade, "z"),
        (StageKind::Grade, "xy"),
        (StageKind::Grade, "idw"),
        (StageKind::Sequence, "work-cycles"),
        (StageKind::Export, "json"),
        (StageKind::Export, "cli"),
        (StageKind::Export, "bitmap"),
        (StageKind::Export, "3mf"),
        (StageKind::Export, "svg"),
        (StageKind::Export, "png"),
        (StageKind::Export, "contact-sheet"),
        (StageKind::Export, "stack"),
        (StageKind::Export, "html"),
        (StageKind::Export, "gcode"),
        (StageKind::Grade, "zxy"),
        (StageKind::Plan, "sequential"),
        (StageKind::Plan, "concurrent"),
    ] {
        assert!(
            registry.get(kind, name).is_some(),
            "{kind}:{name} is not registered"
        );
    }
}
