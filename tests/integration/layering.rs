//! The crates' layering, read from their manifests: geometry at the bottom, core (the
//! stage API) on it, plugins on those two and never on each other, so a built-in plugin
//! is written exactly as a third-party crate would be.

use std::path::Path;

use crate::support::root;

/// The `lamina-*` crates a manifest's `[dependencies]` names.
fn lamina_dependencies(manifest: &Path) -> Vec<String> {
    let text = std::fs::read_to_string(manifest).unwrap_or_else(|e| panic!("{}: {e}", manifest.display()));
    let doc: toml::Table = toml::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", manifest.display()));
    let mut names: Vec<String> = doc
        .get("dependencies")
        .and_then(toml::Value::as_table)
        .map(|deps| {
            deps.keys()
                .filter(|k| k.starts_with("lamina-"))
                .cloned()
                .collect()
        })
        .unwrap_or_default();
    names.sort();
    names
}

#[test]
fn plugins_depend_on_core_and_geom_alone() {
    let root = root();
    assert!(lamina_dependencies(&root.join("geom/Cargo.toml")).is_empty());
    assert_eq!(
        lamina_dependencies(&root.join("core/Cargo.toml")),
        ["lamina-geom"]
    );
    let mut plugins = 0;
    for entry in std::fs::read_dir(root.join("plugins")).expect("plugins/") {
        let manifest = entry.expect("entry").path().join("Cargo.toml");
        if !manifest.exists() {
            continue;
        }
        plugins += 1;
        for dep in lamina_dependencies(&manifest) {
            assert!(
                dep == "lamina-core" || dep == "lamina-geom",
                "{} depends on {dep}: plugins depend on lamina-core and lamina-geom only",
                manifest.display()
            );
        }
    }
    assert!(plugins >= 10, "found {plugins} plugin crates");
}
