//! Pipeline TOML through the code path of `lamina check`: parse, apply `--set`
//! overrides, build every stage (scripts compiled, machines resolved, options checked).
//! Lines `#set KEY=VALUE` of the input, TOML comments, are also parsed as overrides.
#![no_main]

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use lamina_core::pipeline::{Override, Pipeline};
use lamina_core::runtime::{Engine, RunOptions};
use lamina_core::{Registry, SourceFile};
use libfuzzer_sys::fuzz_target;

// The stages register themselves when their crates are linked.
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

/// A folder holding the example pipelines' script, as their own folder would.
fn base_dir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = tempfile::tempdir().expect("tempdir").keep();
        std::fs::write(
            dir.join("gradient.rhai"),
            include_str!("../../pipelines/gradient.rhai"),
        )
        .expect("script");
        dir
    })
}

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data).into_owned();
    let overrides: Vec<Override> = text
        .lines()
        .filter_map(|l| l.strip_prefix("#set "))
        .filter_map(|o| o.parse().ok())
        .collect();
    let file = SourceFile::new(base_dir().join("fuzz.toml"), text);
    let Ok(pipeline) = Pipeline::parse(file, base_dir().to_path_buf(), &overrides) else {
        return;
    };
    let Ok(registry) = Registry::linked() else {
        return;
    };
    let options = RunOptions {
        threads: Some(1),
        ..RunOptions::default()
    };
    if let Ok(engine) = Engine::build(pipeline, registry, &options) {
        let _ = engine.summary();
    }
});
