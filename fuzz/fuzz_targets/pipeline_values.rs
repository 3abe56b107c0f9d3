//! Pipeline values end to end: an example pipeline with some of its numeric options set
//! to arbitrary values (tiny, huge, negative, NaN, infinite, or any number) runs every
//! stage on its small generated model. Each must end in outputs or a clean error.
#![no_main]

#[path = "common.rs"]
mod common;

use std::sync::OnceLock;

use arbitrary::Arbitrary;
use lamina_core::pipeline::Override;
use libfuzzer_sys::fuzz_target;

const PIPELINES: [&str; 8] = [
    include_str!("../../pipelines/tube-gradient.toml"),
    include_str!("../../pipelines/gear-z-gradient.toml"),
    include_str!("../../pipelines/gear-z-wave.toml"),
    include_str!("../../pipelines/grading-sources.toml"),
    include_str!("../../pipelines/blade-skin.toml"),
    include_str!("../../pipelines/distance-field-power.toml"),
    include_str!("../../pipelines/pipe-work-cycles.toml"),
    include_str!("../../pipelines/blade-zxy.toml"),
];

#[derive(Debug, Arbitrary)]
enum Value {
    Zero,
    Tiny,
    Huge,
    Negative,
    NaN,
    Infinite,
    Float(f64),
    Int(i64),
}

#[derive(Debug, Arbitrary)]
struct Case {
    pipeline: u8,
    sets: Vec<(u16, Value)>,
}

/// The dotted paths of every number in a TOML value, with whether it is an integer.
fn numbers(v: &toml::Value, path: String, out: &mut Vec<(String, bool)>) {
    match v {
        toml::Value::Integer(_) => out.push((path, true)),
        toml::Value::Float(_) => out.push((path, false)),
        toml::Value::Table(t) => {
            for (k, v) in t {
                let p = if path.is_empty() {
                    k.clone()
                } else {
                    format!("{path}.{k}")
                };
                numbers(v, p, out);
            }
        }
        toml::Value::Array(a) => {
            for (i, v) in a.iter().enumerate() {
                numbers(v, format!("{path}.{i}"), out);
            }
        }
        _ => {}
    }
}

fn paths() -> &'static Vec<Vec<(String, bool)>> {
    static PATHS: OnceLock<Vec<Vec<(String, bool)>>> = OnceLock::new();
    PATHS.get_or_init(|| {
        PIPELINES
            .iter()
            .map(|text| {
                let mut out = Vec::new();
                let doc: toml::Value = toml::from_str(text).expect("an example pipeline");
                numbers(&doc, String::new(), &mut out);
                out
            })
            .collect()
    })
}

fuzz_target!(|case: Case| {
    let index = case.pipeline as usize % PIPELINES.len();
    let numeric = &paths()[index];
    if numeric.is_empty() {
        return;
    }
    let mut overrides = Vec::new();
    for (i, value) in case.sets.iter().take(4) {
        let (path, integer) = &numeric[*i as usize % numeric.len()];
        let text = match (value, integer) {
            (Value::Zero, _) => "0".to_string(),
            (Value::Tiny, false) => "1e-300".to_string(),
            (Value::Tiny, true) => "1".to_string(),
            (Value::Huge, false) => "1e300".to_string(),
            (Value::Huge, true) => i64::MAX.to_string(),
            (Value::Negative, _) => "-1".to_string(),
            (Value::NaN, _) => "nan".to_string(),
            (Value::Infinite, _) => "inf".to_string(),
            (Value::Float(f), false) if f.is_finite() => format!("{f:e}"),
            (Value::Float(_), false) => "nan".to_string(),
            (Value::Float(f), true) => format!("{}", *f as i64),
            (Value::Int(n), _) => n.to_string(),
        };
        if let Ok(o) = format!("{path}={text}").parse::<Override>() {
            overrides.push(o);
        }
    }
    let dir = tempfile::tempdir().expect("tempdir");
    std::fs::write(
        dir.path().join("gradient.rhai"),
        include_str!("../../pipelines/gradient.rhai"),
    )
    .expect("script");
    let _ = common::run(PIPELINES[index], dir.path(), &overrides);
});
