//! Lamina's integration tests, one binary (as ripgrep keeps its own): each module
//! tests one side of the program through the `lamina` binary or the library, and
//! `support` holds what they share (running the binary, the example pipelines, the
//! real models, skipping with a note or, under `LAMINA_REQUIRE`, failing).
//!
//! Run one module with `cargo test --test integration cli::`; the real-model
//! acceptance tests are `#[ignore]`d: `LAMINA_MODELS=../shared/models cargo test
//! --test integration -- --ignored`.

mod support;

mod acceptance;
mod acceptance_grading;
mod boundary;
mod cli;
mod cli_files;
mod code_shape;
mod docs;
mod gcode_replay;
mod generate;
mod golden;
mod grading;
mod hostile;
mod hybrid;
mod layering;
mod linked_plugins;
mod machine;
mod orient;
mod plate;
mod plugins;
mod properties;
mod readme;
mod scaffold;
mod sequence;
mod slicing;
mod sources;
mod stages;
mod threemf_files;
mod toolpaths;
mod viewer;
