//! What the end-to-end targets share: the linked stages and a run of a pipeline text.

use std::path::Path;

use lamina_core::pipeline::{Override, Pipeline};
use lamina_core::runtime::{Engine, RunOptions, Silent};
use lamina_core::{Registry, SourceFile};

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

/// Runs pipeline `text` (its scripts beside it in `dir`) into `dir/out` on one thread.
/// An error is a fine answer to bad values; a panic or an abort is not.
pub fn run(text: &str, dir: &Path, overrides: &[Override]) -> lamina_core::Result<()> {
    let file = SourceFile::new(dir.join("fuzz.toml"), text);
    let pipeline = Pipeline::parse(file, dir.to_path_buf(), overrides)?;
    let options = RunOptions {
        threads: Some(1),
        ..RunOptions::default()
    };
    let engine = Engine::build(pipeline, Registry::linked()?, &options)?;
    engine.run(&dir.join("out"), &Silent).map(|_| ())
}
