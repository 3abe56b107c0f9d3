//! Machine profiles and their G-code templates: the input is a profile file, which a
//! one-layer pipeline names (`machine = "machine.toml"`; its `base` may be a built-in
//! profile) and runs to G-code. Every profile ends in a clean error or a file the
//! exporter's own firmware model accepted (homed, absolute positioning, within the
//! bed and the machine's ranges); a panic or an abort is a crash.
#![no_main]

mod common;

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;

/// The scratch folder the profile is written to, beside the pipeline.
fn dir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| tempfile::tempdir().expect("tempdir").keep())
}

/// A small part of two materials (a thin tube, two layers) and its G-code.
const PIPELINE: &str = "machine = \"machine.toml\"\n\
    [model]\nuse = \"tube\"\nheight = 0.4\nouter_radius = 6.0\ninner_radius = 3.0\nsegments = 24\n\
    [materials.a]\ncolour = [255, 0, 0]\n[materials.b]\ncolour = [0, 0, 255]\n\
    [slice]\nuse = \"uniform\"\nthickness = 0.2\n\
    [discretise]\nuse = \"offset\"\ncount = 2\n\
    [grade]\nuse = \"xy\"\n\
    [[output]]\nuse = \"gcode\"\npath = \"part.gcode\"\n";

fuzz_target!(|data: &[u8]| {
    let dir = dir();
    if std::fs::write(dir.join("machine.toml"), data).is_err() {
        return;
    }
    let _ = common::run(PIPELINE, dir, &[]);
});
