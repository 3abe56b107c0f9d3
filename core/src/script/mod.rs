//! Rhai scripting for user grading functions: each script compiled once per run, run in
//! a sandbox (operation, depth, size and time limits; no modules, no files, no network),
//! and its results checked as volume fractions before anyone uses them.
//!
//! A script is either an inline expression of the pipeline (`f = "sin(r * PI)"`) or a
//! function in a `.rhai` file beside it (`f = "grading.rhai#ceramic"`). Functions receive
//! their parameters by name from the variables the caller offers (r, d, x, y, z, layer,
//! part), so `fn f(r)` and `fn f(z, r)` both work.

mod local;
mod stop;

pub use stop::CountingAllocator;

use crate::reach::Reach;
use local::{LocalFn, LocalHost};

use std::path::PathBuf;
use std::time::Duration;

use rhai::Dynamic;

use crate::error::Result;
use crate::source::Location;

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

/// The names a script may read; anything else is refused when the script is compiled.
pub const SCRIPT_VARIABLES: &[&str] = &["r", "d", "x", "y", "z", "layer", "part"];

/// Values offered to a script call.
#[derive(Debug, Clone, Copy, Default)]
pub struct ScriptArgs<'a> {
    /// Normalised level in [0, 1].
    pub r: f64,
    /// A distance (mm), e.g. to a grading source.
    pub d: f64,
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub layer: i64,
    pub part: &'a str,
}

impl ScriptArgs<'_> {
    fn value(&self, name: &str) -> Option<Dynamic> {
        Some(match name {
            "r" => Dynamic::from_float(self.r),
            "d" => Dynamic::from_float(self.d),
            "x" => Dynamic::from_float(self.x),
            "y" => Dynamic::from_float(self.y),
            "z" => Dynamic::from_float(self.z),
            "layer" => Dynamic::from_int(self.layer),
            "part" => Dynamic::from(self.part.to_string()),
            _ => return None,
        })
    }
}

/// Compiles scripts for the stages of one run. Cheap to share between threads.
///
/// In a dynamic plugin, the host's scripts are reached through the host: a script is
/// compiled and run by the host's engine under the host's limits, whatever copy of
/// Rhai the plugin links.
#[derive(Clone, Debug)]
pub struct ScriptHost(HostKind);

#[derive(Clone, Debug)]
enum HostKind {
    Local(LocalHost),
    /// In a dynamic plugin: every script goes to the host.
    Remote,
}

impl ScriptHost {
    pub fn new(base_dir: impl Into<PathBuf>, limits: ScriptLimits) -> Self {
        Self(HostKind::Local(LocalHost::new(base_dir, limits)))
    }

    /// The scripts of the host that called into this dynamic plugin.
    pub(crate) fn remote() -> Self {
        Self(HostKind::Remote)
    }

    /// Reads script files within `reach` (by default, the base folder only).
    pub fn with_reach(self, reach: Reach) -> Self {
        match self.0 {
            HostKind::Local(host) => Self(HostKind::Local(host.with_reach(reach))),
            remote => Self(remote),
        }
    }

    /// Compiles a script reference from a pipeline: `file.rhai#function` names a
    /// function in a file beside the pipeline; anything else is an inline expression.
    /// `origin` is where the reference is written (for error positions).
    pub fn compile(&self, spec: &str, origin: Option<Location>) -> Result<ScriptFn> {
        match &self.0 {
            HostKind::Local(host) => host.compile(spec, origin).map(|f| ScriptFn(FnKind::Local(f))),
            HostKind::Remote => {
                crate::plugin::guest::compile(spec, origin).map(|id| ScriptFn(FnKind::Remote(id)))
            }
        }
    }
}

/// A compiled script: call it as often as needed, from any thread (in a dynamic
/// plugin: from the threads the host calls the plugin's stages on).
#[derive(Clone, Debug)]
pub struct ScriptFn(FnKind);

#[derive(Clone, Debug)]
enum FnKind {
    Local(LocalFn),
    /// A script the host compiled for this dynamic plugin, by the host's number.
    Remote(u64),
}

impl ScriptFn {
    /// Calls the script for a single number (any finite value).
    pub fn number(&self, args: &ScriptArgs<'_>, context: &str) -> Result<f64> {
        match &self.0 {
            FnKind::Local(f) => f.number(args, context),
            FnKind::Remote(id) => crate::plugin::guest::number(*id, args, context),
        }
    }

    /// Calls the script for the volume fractions of `n` materials. A single number `f`
    /// means `[f, 1 - f]` when `n == 2`; otherwise an array of `n` numbers is expected.
    /// Every fraction must lie in [0, 1] and they must sum to 1 (1e-9).
    pub fn fractions(&self, args: &ScriptArgs<'_>, n: usize, context: &str) -> Result<Vec<f64>> {
        match &self.0 {
            FnKind::Local(f) => f.fractions(args, n, context),
            FnKind::Remote(id) => crate::plugin::guest::fractions(*id, args, n, context),
        }
    }
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
