//! Every built-in stage through the plugin boundary: each stage's example pipeline runs
//! once with the linked stages and once with every stage reached through the boundary's
//! messages, handles and host services (as a dynamic plugin's are), and writes the same
//! bytes.

use lamina_core::pipeline::Pipeline;
use lamina_core::runtime::{Engine, RunOptions, Silent};
use lamina_core::{Registry, SourceFile};

fn run(
    registry: &Registry,
    text: &str,
    dir: &std::path::Path,
    out: &std::path::Path,
) -> Result<Vec<(String, Vec<u8>)>, String> {
    let file = SourceFile::new(dir.join("p.toml"), text);
    let pipeline = Pipeline::parse(file, dir.to_path_buf(), &[]).map_err(|e| e.to_string())?;
    let engine =
        Engine::build(pipeline, registry.clone(), &RunOptions::default()).map_err(|e| e.to_string())?;
    let report = engine.run(out, &Silent).map_err(|e| e.to_string())?;
    let mut files: Vec<(String, Vec<u8>)> = report
        .files
        .iter()
        .map(|f| {
            let name = f.strip_prefix(out).unwrap_or(f).display().to_string();
            (name, std::fs::read(f).unwrap_or_default())
        })
        .collect();
    files.sort();
    Ok(files)
}

#[test]
fn every_built_in_stage_gives_the_same_output_through_the_boundary() {
    let linked = lamina_test_support::registry();
    let remote = lamina_test_support::registry_through_boundary("loopback");
    assert_eq!(remote.list(None).len(), linked.list(None).len());
    assert!(
        remote
            .list(None)
            .iter()
            .all(|e| matches!(e.origin, lamina_core::registry::Origin::Dynamic { .. }))
    );
    let dir = tempfile::tempdir().expect("tempdir");
    lamina_test_support::write_models(dir.path());
    for entry in linked.list(None) {
        let info = entry.info();
        let text = lamina_test_support::pipeline_for(info.kind, info.example);
        let label = entry.label().replace(':', "-");
        let [direct, through] = [
            (&linked, "linked", ""),
            (&remote, "remote", " through the boundary"),
        ]
        .map(|(registry, folder, how)| {
            run(registry, &text, dir.path(), &dir.path().join(folder).join(&label))
                .unwrap_or_else(|e| panic!("{label}{how}: {e}"))
        });
        assert_eq!(
            direct.iter().map(|f| &f.0).collect::<Vec<_>>(),
            through.iter().map(|f| &f.0).collect::<Vec<_>>(),
            "{label}"
        );
        for ((name, a), (_, b)) in direct.iter().zip(&through) {
            assert!(a == b, "{label}: {name} differs through the boundary");
        }
    }
}

/// A plugin of ABI 7.1 is sent what it knows: graders that read no geometry get the
/// regions whole, polygons emptied (`Grade`), not their facts (`GradeFacts`, 7.2). Every
/// grader's example gives what the linked grader gives either way.
#[test]
fn graders_give_the_same_output_as_plugins_of_an_older_minor() {
    let linked = lamina_test_support::registry();
    let mut older = lamina_core::Registry::new();
    lamina_core::plugin::add_linked_through_boundary_as(&mut older, "older", 1).expect("the linked stages");
    older.adopt_defaults(&linked).expect("the default stages");
    let dir = tempfile::tempdir().expect("tempdir");
    lamina_test_support::write_models(dir.path());
    let graders = linked.list(Some(lamina_core::stage::StageKind::Grade));
    assert!(graders.len() >= 5, "{}", graders.len());
    for entry in graders {
        let info = entry.info();
        let text = lamina_test_support::pipeline_for(info.kind, info.example);
        let label = entry.label().replace(':', "-");
        let [direct, through] = [(&linked, "linked"), (&older, "older")].map(|(registry, folder)| {
            run(registry, &text, dir.path(), &dir.path().join(folder).join(&label))
                .unwrap_or_else(|e| panic!("{label} ({folder}): {e}"))
        });
        assert_eq!(direct, through, "{label}");
    }
}
