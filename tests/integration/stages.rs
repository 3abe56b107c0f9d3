//! Every stage describes itself, and its example table runs: each built-in stage's
//! example is placed in a small pipeline on a generated model and run end to end, by
//! `lamina-test-support`, as a plugin crate's tests run theirs.

use lamina_core::StageKind;
use lamina_test_support::registry;

#[test]
fn every_stage_is_documented_and_its_example_runs() {
    let registry = registry();
    let mut names = std::collections::HashSet::new();
    for entry in registry.list(None) {
        assert!(
            names.insert((entry.info().kind, entry.info().name)),
            "duplicate {}",
            entry.label()
        );
    }
    assert!(names.len() > 30, "{} stages", names.len());
    // Through the support crate that plugin crates use for their own tests.
    lamina_test_support::assert_examples_run(&[]);
}

#[test]
fn the_expected_built_in_stages_are_registered() {
    let registry = registry();
    for (kind, name) in [
        (StageKind::Model, "stl"),
        (StageKind::Model, "obj"),
        (StageKind::Model, "3mf"),
        (StageKind::Model, "gear"),
        (StageKind::Model, "gear-shaft"),
        (StageKind::Model, "tube"),
        (StageKind::Model, "box"),
        (StageKind::Model, "cube"),
        (StageKind::Model, "blade"),
        (StageKind::Orient, "candidates"),
        (StageKind::Slice, "uniform"),
        (StageKind::Slice, "adaptive"),
        (StageKind::Sort, "hierarchy"),
        (StageKind::Discretise, "offset"),
        (StageKind::Discretise, "step-width"),
        (StageKind::Discretise, "distance-field"),
        (StageKind::Discretise, "sources"),
        (StageKind::Grade, "script"),
        (StageKind::Grade, "constant"),
        (StageKind::Grade, "z"),
        (StageKind::Grade, "xy"),
        (StageKind::Grade, "idw"),
        (StageKind::Sequence, "work-cycles"),
        (StageKind::Export, "json"),
        (StageKind::Export, "cli"),
        (StageKind::Export, "bitmap"),
        (StageKind::Export, "3mf"),
        (StageKind::Export, "svg"),
        (StageKind::Export, "png"),
        (StageKind::Export, "contact-sheet"),
        (StageKind::Export, "stack"),
        (StageKind::Export, "html"),
        (StageKind::Export, "gcode"),
        (StageKind::Grade, "zxy"),
        (StageKind::Plan, "sequential"),
        (StageKind::Plan, "concurrent"),
    ] {
        assert!(
            registry.get(kind, name).is_some(),
            "{kind}:{name} is not registered"
        );
    }
}

/// Every documented default is a TOML literal the stage accepts: each stage is built
/// from its example's options that have no default plus every option that has one,
/// set to its documented default.
#[test]
fn every_documented_default_is_toml_the_stage_accepts() {
    let registry = registry();
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("a temporary folder: {e}"));
    lamina_test_support::write_models(dir.path());
    let mut failures = Vec::new();
    for entry in registry.list(None) {
        let info = entry.info();
        let label = entry.label();
        let mut example: toml::Table =
            toml::from_str(info.example).unwrap_or_else(|e| panic!("{label}: its example is not TOML: {e}"));
        for o in info.options {
            if let Some(d) = o.default {
                match toml::from_str::<toml::Table>(&format!("v = {d}")) {
                    Ok(mut t) => {
                        if let Some(v) = t.remove("v") {
                            example.insert(o.name.to_string(), v);
                        }
                    }
                    Err(e) => failures.push(format!(
                        "{label}: the default of `{}`, {d}, is not TOML: {e}",
                        o.name
                    )),
                }
            } else if o.required && !example.contains_key(o.name) {
                failures.push(format!("{label}: its example lacks the required `{}`", o.name));
            }
        }
        let text = toml::to_string(&example).unwrap_or_default();
        if let Err(e) = lamina_test_support::try_stage(info.kind, &text, dir.path()) {
            failures.push(format!(
                "{label}: its documented defaults do not build: {e}\n{text}"
            ));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
}

/// The TOML types whose every number a declared range holds.
const NUMERIC: [&str; 5] = [
    "float",
    "integer",
    "array of float",
    "array of integer",
    "array of array of float",
];

#[test]
fn every_number_option_has_a_physical_range() {
    let mut failures = Vec::new();
    for entry in registry().list(None) {
        let label = entry.label();
        for o in entry.info().options {
            let numeric = NUMERIC.contains(&o.ty);
            match o.range {
                None if numeric => {
                    failures.push(format!("{label}: `{}` ({}) declares no range", o.name, o.ty))
                }
                Some(_) if !numeric => failures.push(format!(
                    "{label}: `{}` is a {}, which a range does not check",
                    o.name, o.ty
                )),
                Some((min, max)) if !(min.is_finite() && max.is_finite() && min < max) => {
                    failures.push(format!("{label}: `{}` has the range {min} to {max}", o.name))
                }
                _ => {}
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// Every number option refuses a value beyond its declared range, naming itself, when
/// its stage is built: a stage's own check of a number may then rely on the range.
#[test]
fn every_number_option_refuses_a_value_beyond_its_range() {
    let registry = registry();
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("a temporary folder: {e}"));
    lamina_test_support::write_models(dir.path());
    let mut failures = Vec::new();
    let mut checked = 0;
    for entry in registry.list(None) {
        let info = entry.info();
        let label = entry.label();
        let example: toml::Table =
            toml::from_str(info.example).unwrap_or_else(|e| panic!("{label}: its example is not TOML: {e}"));
        for o in info.options {
            let Some((min, max)) = o.range else { continue };
            let beyond = match o.ty {
                "float" => toml::Value::Float(if max > 0.0 { max * 2.0 } else { max + 1.0 }),
                // Below the least the type holds is a refusal too, but of the type.
                "integer" if max < 1e15 => toml::Value::Integer(max as i64 + 1),
                "integer" if min > -1e15 => toml::Value::Integer(min as i64 - 1),
                _ => continue,
            };
            let mut table = example.clone();
            table.insert(o.name.to_string(), beyond.clone());
            let text = toml::to_string(&table).unwrap_or_default();
            checked += 1;
            match lamina_test_support::try_stage(info.kind, &text, dir.path()) {
                Ok(_) => failures.push(format!("{label}: `{}` = {beyond} was taken", o.name)),
                Err(e) if !e.to_string().contains(&format!("`{}`", o.name)) => failures.push(format!(
                    "{label}: `{}` = {beyond}: the error does not name it: {e}",
                    o.name
                )),
                Err(_) => {}
            }
        }
    }
    assert!(checked > 100, "only {checked} options checked");
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
