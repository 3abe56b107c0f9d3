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

/// ARCHITECTURE.md names every stage the program ships where it describes the crate
/// that holds it, in backticks as a pipeline writes it: a stage added without a word
/// there fails here.
#[test]
fn the_architecture_names_every_built_in_stage() {
    let text = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("ARCHITECTURE.md"))
        .expect("ARCHITECTURE.md");
    let out = Command::new(env!("CARGO_BIN_EXE_lamina"))
        .arg("plugins")
        .output()
        .expect("lamina runs");
    assert!(out.status.success());
    // `kind:` headings, then a line per stage: two spaces, its name, its summary. The
    // machine profiles listed after them are no stages.
    let listing = String::from_utf8(out.stdout).expect("utf-8");
    let mut kind = "";
    let mut names = Vec::new();
    for line in listing.lines() {
        if let Some(k) = line.strip_suffix(':').filter(|k| !k.starts_with(' ')) {
            kind = if k.contains(' ') { "" } else { k };
        } else if let Some(rest) = line
            .strip_prefix("  ")
            .filter(|r| !r.starts_with(' ') && !kind.is_empty())
        {
            let name = rest.split_whitespace().next().unwrap_or_default();
            names.push((kind.to_string(), name.to_string()));
        }
    }
    assert!(names.len() > 40, "{names:?}");
    let missing: Vec<String> = names
        .iter()
        .filter(|(_, name)| !text.contains(&format!("`{name}`")))
        .map(|(kind, name)| format!("{kind}:{name}"))
        .collect();
    assert!(
        missing.is_empty(),
        "ARCHITECTURE.md does not name {}",
        missing.join(", ")
    );
}
