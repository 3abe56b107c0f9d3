//! Rhai grading scripts through the sandbox: compiled as an inline expression and as a
//! `.rhai` file, then called for two fractions. Limits must stop every call, and a
//! result must be a valid composition or an error.
#![no_main]

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use lamina_core::script::{ScriptArgs, ScriptHost, ScriptLimits};
use libfuzzer_sys::fuzz_target;

fn dir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| tempfile::tempdir().expect("tempdir").keep())
}

fn host() -> &'static ScriptHost {
    static HOST: OnceLock<ScriptHost> = OnceLock::new();
    HOST.get_or_init(|| ScriptHost::new(dir(), ScriptLimits::default()))
}

fn check(f: &lamina_core::script::ScriptFn) {
    let args = ScriptArgs {
        r: 0.25,
        d: 1.5,
        x: 1.0,
        y: -2.0,
        z: 3.0,
        layer: 4,
        part: "fuzz",
    };
    if let Ok(fractions) = f.fractions(&args, 2, "fuzz") {
        assert_eq!(fractions.len(), 2);
        assert!(fractions.iter().all(|v| (0.0..=1.0).contains(v)), "{fractions:?}");
        assert!(
            (fractions.iter().sum::<f64>() - 1.0).abs() < 1e-6,
            "{fractions:?}"
        );
    }
}

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    if let Ok(f) = host().compile(&text, None) {
        check(&f);
    }
    if text.contains("fn ") {
        let path = dir().join("f.rhai");
        if std::fs::write(&path, text.as_bytes()).is_ok()
            && let Ok(f) = host().compile("f.rhai#f", None)
        {
            check(&f);
        }
    }
});
