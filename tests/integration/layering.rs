//! The crates' layering, read from their manifests: geometry at the bottom, the stage
//! API on it, the papers' shared methods and machine profiles on the API, the engine
//! (core) on the API, geometry and profiles, and plugins on the API, geometry and shared
//! methods (and machine profiles, for the exporters that write machine files), never on
//! the engine or on each other: a built-in plugin is written exactly as
//! a third-party crate would be, and compiles none of the engine.

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
fn plugins_depend_on_the_stage_api_and_geom_alone() {
    let root = root();
    assert!(lamina_dependencies(&root.join("geom/Cargo.toml")).is_empty());
    assert_eq!(lamina_dependencies(&root.join("api/Cargo.toml")), ["lamina-geom"]);
    assert_eq!(
        lamina_dependencies(&root.join("fgm/Cargo.toml")),
        ["lamina-api", "lamina-geom"]
    );
    assert_eq!(
        lamina_dependencies(&root.join("machine/Cargo.toml")),
        ["lamina-api"]
    );
    assert_eq!(
        lamina_dependencies(&root.join("core/Cargo.toml")),
        ["lamina-api", "lamina-geom", "lamina-machine"]
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
                ["lamina-api", "lamina-fgm", "lamina-geom", "lamina-machine"].contains(&dep.as_str()),
                "{} depends on {dep}: plugins depend on lamina-api, lamina-fgm, lamina-geom and lamina-machine only",
                manifest.display()
            );
        }
    }
    assert!(plugins >= 10, "found {plugins} plugin crates");
}

/// What a plugin compiles besides its own code: the engine's script engine, library
/// loader and thread pool stay out of the stage API.
#[test]
fn the_stage_api_carries_none_of_the_engine() {
    let manifest = root().join("api/Cargo.toml");
    let text = std::fs::read_to_string(&manifest).expect("api/Cargo.toml");
    let doc: toml::Table = toml::from_str(&text).expect("TOML");
    let deps = doc
        .get("dependencies")
        .and_then(toml::Value::as_table)
        .expect("[dependencies]");
    for engine in ["rhai", "libloading", "rayon", "tempfile", "object", "lamina-core"] {
        assert!(!deps.contains_key(engine), "lamina-api depends on {engine}");
    }
}
