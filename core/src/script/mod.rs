//! The host's script engine: Rhai, each script compiled once per run and run in a
//! sandbox (operation, depth, size and time limits; no modules, no files, no network),
//! its results checked as volume fractions before anyone uses them. Stages reach it
//! through `lamina_api::script` ([`ScriptHost`], [`ScriptFn`]).

mod local;
mod stop;

pub use lamina_api::script::*;
pub use stop::CountingAllocator;

use crate::reach::Reach;
use local::LocalHost;

use std::path::PathBuf;
use std::time::Duration;

/// Sandbox limits of every script call.
#[derive(Debug, Clone, Copy)]
pub struct ScriptLimits {
    pub max_operations: u64,
    pub max_call_levels: usize,
    pub max_expr_depth: usize,
    pub max_string_size: usize,
    pub max_array_size: usize,
    /// Wall-clock budget of one call.
    pub time_limit: Duration,
    /// Bytes one call may hold, counted when the program installs
    /// [`CountingAllocator`] (the `lamina` binary does): the size limits do not see
    /// every copy (a map whose entries are large arrays).
    pub max_memory: usize,
    /// Functions one script file may define.
    pub max_functions: usize,
}

impl Default for ScriptLimits {
    fn default() -> Self {
        Self {
            max_operations: 5_000_000,
            max_call_levels: 48,
            max_expr_depth: 64,
            max_string_size: 64 * 1024,
            max_array_size: 100_000,
            time_limit: Duration::from_millis(500),
            max_functions: 10_000,
            max_memory: 128 << 20,
        }
    }
}

/// The host's scripts for a run whose pipeline lies in `base_dir`: script files are
/// read there only (see [`local_within`]).
pub fn local(base_dir: impl Into<PathBuf>, limits: ScriptLimits) -> ScriptHost {
    ScriptHost::new(LocalHost::new(base_dir, limits))
}

/// The host's scripts, reading script files within `reach`.
pub fn local_within(base_dir: impl Into<PathBuf>, limits: ScriptLimits, reach: Reach) -> ScriptHost {
    ScriptHost::new(LocalHost::new(base_dir, limits).with_reach(reach))
}

#[cfg(test)]
mod tests {
    use std::time::Instant;

    use super::local::*;
    use super::*;

    fn host() -> LocalHost {
        LocalHost::new(".", ScriptLimits::default()).with_reach(Reach::folder(&std::env::temp_dir()))
    }

    #[test]
    fn inline_expression_sees_variables_and_constants() {
        let f = host().expression("sin(r * PI)", None).expect("compiles");
        let args = ScriptArgs {
            r: 0.5,
            ..Default::default()
        };
        assert!((f.number(&args, "t").expect("runs") - 1.0).abs() < 1e-12);
        let f = host().expression("1", None).expect("compiles");
        assert_eq!(f.fractions(&args, 2, "t").expect("int accepted"), vec![1.0, 0.0]);
    }

    #[test]
    fn a_script_cannot_read_the_clock_so_outputs_stay_the_same_from_run_to_run() {
        let f = host().expression("timestamp().elapsed", None);
        let args = ScriptArgs::default();
        let e = match f {
            Err(e) => e.to_string(),
            Ok(f) => f.number(&args, "t").expect_err("no clock").to_string(),
        };
        assert!(e.contains("timestamp"), "{e}");
    }

    #[test]
    fn integer_arguments_are_accepted() {
        let f = host()
            .expression("linear(1, 0, r) + sin(0)", None)
            .expect("compiles");
        let args = ScriptArgs {
            r: 0.25,
            ..Default::default()
        };
        assert_eq!(f.number(&args, "t").expect("runs"), 0.25);
    }

    #[test]
    fn functions_take_parameters_by_name() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("g.rhai");
        std::fs::write(&path, "let big = 1000;\nfn f(z, r) { [r, 1.0 - r - z] }\n").expect("write");
        let f = host().function(&path, "f", None).expect("compiles");
        let args = ScriptArgs {
            r: 0.25,
            z: 0.0,
            ..Default::default()
        };
        assert_eq!(f.fractions(&args, 2, "t").expect("runs"), vec![0.25, 0.75]);
    }

    #[test]
    fn endless_loop_is_stopped_quickly() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("g.rhai");
        std::fs::write(&path, "fn f(r) {\n  loop { }\n}\n").expect("write");
        let f = host().function(&path, "f", None).expect("compiles");
        let t = Instant::now();
        let e = f
            .fractions(&ScriptArgs::default(), 2, "layer 3")
            .expect_err("stopped");
        assert!(t.elapsed() < Duration::from_secs(1), "took {:?}", t.elapsed());
        assert!(e.to_string().contains("stopped"), "{e}");
    }

    #[test]
    fn a_comparator_that_sorts_again_is_stopped_quickly() {
        // Found by the `script` fuzz target: each comparison calls `f`, which sorts
        // again, so the calls make a tree that grows with every level.
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("g.rhai");
        std::fs::write(
            &path,
            "fn f(r, z) {\n  let a = [3, 1, 2];\n  a.sort(f);\n  r\n}\n",
        )
        .expect("write");
        let f = host().function(&path, "f", None).expect("compiles");
        let t = Instant::now();
        let e = f.number(&ScriptArgs::default(), "layer 1").expect_err("stopped");
        assert!(t.elapsed() < Duration::from_secs(3), "took {:?}", t.elapsed());
        assert!(
            e.to_string().contains("stopped") || e.to_string().contains("limit"),
            "{e}"
        );
    }

    #[test]
    fn fractions_not_summing_to_one_are_refused_with_position() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("g.rhai");
        std::fs::write(&path, "// grading\n\nfn bad(r) { [0.5, 0.4] }\n").expect("write");
        let f = host().function(&path, "bad", None).expect("compiles");
        let e = f
            .fractions(&ScriptArgs::default(), 2, "layer 2, region 1")
            .expect_err("refused");
        let loc = e.location().expect("located");
        assert_eq!(loc.line_col(), (3, 1));
        let text = e.to_string();
        assert!(
            text.contains("0.9") && text.contains("layer 2, region 1"),
            "{text}"
        );
    }

    #[test]
    fn scripts_cannot_import_or_eval() {
        assert!(
            host().expression("import \"x\" as y; 1", None).is_err()
                || host()
                    .expression("import \"x\" as y; 1", None)
                    .and_then(|f| f.number(&ScriptArgs::default(), "t"))
                    .is_err()
        );
        assert!(host().expression("eval(\"1\")", None).is_err());
    }

    #[test]
    fn unknown_parameter_is_refused() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("g.rhai");
        std::fs::write(&path, "fn f(q) { q }\n").expect("write");
        assert!(host().function(&path, "f", None).is_err());
    }

    #[test]
    fn limits_hold_inside_callbacks_sleep_and_recursion() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("g.rhai");
        std::fs::write(
            &path,
            "fn sorter(r) {\n  let a = [3, 1, 2, 5, 4];\n  a.sort(|x, y| { loop { } });\n  0.5\n}\n\n\
             fn deep(r) {\n  deep(((((r + 1.0)))))\n}\n\nfn nap(r) {\n  sleep(1);\n  0.5\n}\n",
        )
        .expect("write");
        // A sort swallows its comparator's stop; the call fails all the same.
        let f = host().function(&path, "sorter", None).expect("compiles");
        let t = Instant::now();
        let e = f.number(&ScriptArgs::default(), "t").expect_err("stopped");
        assert!(t.elapsed() < Duration::from_secs(2), "took {:?}", t.elapsed());
        assert!(e.to_string().contains("stopped"), "{e}");
        assert_eq!(e.location().expect("located").line_col(), (1, 1));
        // Endless recursion: stopped at the depth limit, pointed at the function.
        let f = host().function(&path, "deep", None).expect("compiles");
        let e = f.number(&ScriptArgs::default(), "t").expect_err("stopped");
        assert!(e.to_string().contains("recursion"), "{e}");
        assert_eq!(e.location().expect("located").line_col(), (7, 1));
        // No sleeping.
        let f = host().function(&path, "nap", None).expect("compiles");
        let t = Instant::now();
        let e = f.number(&ScriptArgs::default(), "t").expect_err("refused");
        assert!(t.elapsed() < Duration::from_millis(500), "took {:?}", t.elapsed());
        assert!(e.to_string().contains("sleep"), "{e}");
        // A later call on the same thread starts afresh.
        let ok = host().expression("r + 0.25", None).expect("compiles");
        assert_eq!(ok.number(&ScriptArgs::default(), "t").expect("runs"), 0.25);
    }
}
