//! Rhai grading scripts through the sandbox: compiled as an inline expression and as a
//! `.rhai` file, then called for two fractions. Limits must stop every call, and a
//! result must be a valid composition or an error.
#![no_main]

use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use lamina_core::script::{ScriptArgs, ScriptHost, ScriptLimits};
use libfuzzer_sys::fuzz_target;

fn dir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| tempfile::tempdir().expect("tempdir").keep())
}

/// The sandbox with tighter limits than a run's (20 ms and 50,000 operations a call):
/// what is fuzzed is that every limit stops every call, which a smaller budget shows as
/// well, at a tenth of the cost of an input that runs into it.
fn host() -> &'static ScriptHost {
    static HOST: OnceLock<ScriptHost> = OnceLock::new();
    HOST.get_or_init(|| {
        let limits = ScriptLimits {
            time_limit: LIMIT,
            max_operations: 50_000,
            ..ScriptLimits::default()
        };
        lamina_core::script::local(dir(), limits)
    })
}

const LIMIT: Duration = Duration::from_millis(20);

/// A call must end soon after its time limit: one that runs on has escaped it.
const ESCAPED: Duration = Duration::from_secs(2);

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
    let start = Instant::now();
    let result = f.fractions(&args, 2, "fuzz");
    let took = start.elapsed();
    assert!(took < ESCAPED, "a call ran {took:?} against a limit of {LIMIT:?}");
    if let Ok(fractions) = result {
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
