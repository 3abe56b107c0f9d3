//! Generated documentation stays current: docs/pipeline-reference.md is the output of
//! `lamina plugins --markdown`. Run with `LAMINA_UPDATE_DOCS=1` to rewrite it.

use std::path::Path;
use std::process::Command;

#[test]
fn pipeline_reference_is_current() {
    let out = Command::new(env!("CARGO_BIN_EXE_lamina"))
        .args(["plugins", "--markdown"])
        .output()
        .expect("lamina runs");
    assert!(out.status.success());
    let generated = String::from_utf8(out.stdout).expect("utf-8");
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/pipeline-reference.md");
    if std::env::var_os("LAMINA_UPDATE_DOCS").is_some() {
        std::fs::write(&path, &generated).expect("write");
        return;
    }
    let current = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        current == generated,
        "docs/pipeline-reference.md is out of date: run `LAMINA_UPDATE_DOCS=1 cargo test --test integration docs::`"
    );
}
