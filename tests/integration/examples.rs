//! Every example pipeline in pipelines/ runs with one command on a fresh checkout.
//! Pipelines that read the real meshes of ../shared/models are left to the benchmarks.

use crate::support::{pipelines, try_run};

#[test]
fn every_example_pipeline_runs() {
    let dir = pipelines();
    let out = tempfile::tempdir().expect("tempdir");
    let mut ran = 0;
    let mut entries: Vec<_> = std::fs::read_dir(&dir)
        .expect("pipelines/")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    entries.sort();
    for path in entries {
        let text = std::fs::read_to_string(&path).expect("read");
        if text.contains("shared/models") {
            println!(
                "note: {} reads ../shared/models; left to the benchmarks",
                path.display()
            );
            continue;
        }
        let name = path.file_stem().expect("stem").to_string_lossy().into_owned();
        let result = try_run(&path, &out.path().join(&name), &[]);
        assert!(
            result.status.success(),
            "{}: {}",
            path.display(),
            String::from_utf8_lossy(&result.stderr)
        );
        let written = std::fs::read_dir(out.path().join(&name))
            .map(|d| d.count())
            .unwrap_or(0);
        assert!(written > 0, "{}: wrote nothing", path.display());
        ran += 1;
    }
    assert!(ran >= 8, "only {ran} example pipelines ran");
}
