//! Rhai scripting for user grading functions: each script compiled once per run, run in
//! a sandbox (operation, depth, size and time limits; no modules, no files, no network),
//! and its results checked as volume fractions before anyone uses them.
//!
//! A script is either an inline expression of the pipeline (`f = "sin(r * PI)"`) or a
//! function in a `.rhai` file beside it (`f = "grading.rhai#ceramic"`). Functions receive
//! their parameters by name from the variables the caller offers (r, d, x, y, z, layer,
//! part), so `fn f(r)` and `fn f(z, r)` both work.

use std::cell::Cell;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use rhai::{AST, CallFnOptions, Dynamic, Engine, EvalAltResult, FLOAT, INT, Position, Scope};

use crate::error::{Error, Result};
use crate::model::COMPOSITION_TOLERANCE;
use crate::source::{Location, SourceFile};

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

thread_local! {
    /// Deadline of the script call running on this thread.
    static DEADLINE: Cell<Option<Instant>> = const { Cell::new(None) };
    /// Whether the call running on this thread was stopped at least once. Some of
    /// Rhai's functions swallow their callbacks' errors (a sort comparator that is
    /// stopped only makes the sort go on): once stopped, the whole call fails.
    static STOPPED: Cell<bool> = const { Cell::new(false) };
    /// Why the call running on this thread was stopped.
    static STOP_REASON: Cell<&'static str> = const { Cell::new("time limit exceeded") };
    /// Bytes this thread holds, as [`CountingAllocator`] counts them.
    static HELD: Cell<isize> = const { Cell::new(0) };
    /// What this thread held when its script call started.
    static HELD_AT_START: Cell<isize> = const { Cell::new(0) };
}

/// A global allocator that counts the bytes each thread holds, so that a script call
/// is stopped when it holds more than [`ScriptLimits::max_memory`]. A program opts in
/// with `#[global_allocator] static A: CountingAllocator = CountingAllocator;`;
/// without it no memory limit applies. The count is a thread-local addition per
/// allocation.
#[derive(Debug, Default, Clone, Copy)]
pub struct CountingAllocator;

fn count_held(bytes: isize) {
    // The counter is a const-initialised `Cell` without destructor: using it allocates
    // nothing, and after the thread's end `try_with` just skips.
    let _ = HELD.try_with(|h| h.set(h.get().wrapping_add(bytes)));
}

// SAFETY: every call is passed unchanged to the system allocator, which upholds the
// `GlobalAlloc` contract; the counting touches no allocation.
unsafe impl std::alloc::GlobalAlloc for CountingAllocator {
    unsafe fn alloc(&self, layout: std::alloc::Layout) -> *mut u8 {
        count_held(layout.size() as isize);
        // SAFETY: the caller keeps `alloc`'s contract, which `System` shares.
        unsafe { std::alloc::System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: std::alloc::Layout) -> *mut u8 {
        count_held(layout.size() as isize);
        // SAFETY: as for `alloc`.
        unsafe { std::alloc::System.alloc_zeroed(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: std::alloc::Layout) {
        count_held(-(layout.size() as isize));
        // SAFETY: `ptr` came from `System` through this allocator with `layout`.
        unsafe { std::alloc::System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: std::alloc::Layout, new_size: usize) -> *mut u8 {
        count_held(new_size as isize - layout.size() as isize);
        // SAFETY: as for `dealloc`, with the caller's valid `new_size`.
        unsafe { std::alloc::System.realloc(ptr, layout, new_size) }
    }
}

/// Stops the call running on this thread for `reason`.
fn stop(reason: &'static str) -> Option<Dynamic> {
    STOPPED.with(|s| s.set(true));
    STOP_REASON.with(|r| r.set(reason));
    Some(Dynamic::from(reason.to_string()))
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

    /// Also lets scripts be read from these folders (the pipeline's `script_dirs`).
    pub fn with_script_dirs(self, dirs: Vec<PathBuf>) -> Self {
        match self.0 {
            HostKind::Local(host) => Self(HostKind::Local(host.with_script_dirs(dirs))),
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

/// The host's own Rhai engine and the folders its scripts may come from.
#[derive(Clone)]
struct LocalHost {
    engine: Arc<Engine>,
    base_dir: PathBuf,
    /// Folders besides `base_dir` whose scripts may be read (the pipeline's
    /// `script_dirs`).
    script_dirs: Vec<PathBuf>,
    time_limit: Duration,
    max_functions: usize,
}

/// Largest script file read (bytes).
pub const MAX_SCRIPT_BYTES: u64 = 1 << 20;

impl std::fmt::Debug for LocalHost {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LocalHost")
            .field("base_dir", &self.base_dir)
            .finish()
    }
}

fn as_number(v: &Dynamic) -> Option<f64> {
    v.as_float().ok().or_else(|| v.as_int().ok().map(|i| i as f64))
}

fn num(v: Dynamic, what: &str) -> std::result::Result<f64, Box<EvalAltResult>> {
    as_number(&v).ok_or_else(|| format!("{what}: expected a number, got {}", v.type_name()).into())
}

impl LocalHost {
    fn new(base_dir: impl Into<PathBuf>, limits: ScriptLimits) -> Self {
        let mut engine = Engine::new();
        engine
            .set_max_operations(limits.max_operations)
            .set_max_call_levels(limits.max_call_levels)
            .set_max_expr_depths(limits.max_expr_depth, limits.max_expr_depth)
            .set_max_string_size(limits.max_string_size)
            .set_max_array_size(limits.max_array_size)
            .set_max_map_size(limits.max_array_size)
            .set_max_modules(0)
            .set_module_resolver(rhai::module_resolvers::DummyModuleResolver::new())
            .disable_symbol("eval")
            .on_print(|_| {})
            .on_debug(|_, _, _| {});
        let max_operations = limits.max_operations;
        let max_memory = isize::try_from(limits.max_memory).unwrap_or(isize::MAX);
        engine.on_progress(move |ops| {
            // Memory at every operation: one operation may copy megabytes.
            if HELD.with(Cell::get).wrapping_sub(HELD_AT_START.with(Cell::get)) > max_memory {
                return stop("memory limit exceeded");
            }
            let over = ops >= max_operations;
            if ops % 1024 != 0 && !over {
                return None;
            }
            if over || DEADLINE.with(|d| d.get().is_some_and(|t| Instant::now() > t)) {
                return stop("time limit exceeded");
            }
            None
        });
        // A grading function has no business waiting.
        engine.register_fn(
            "sleep",
            |_: FLOAT| -> std::result::Result<(), Box<EvalAltResult>> {
                Err("`sleep` is not available to grading scripts".into())
            },
        );
        engine.register_fn("sleep", |_: INT| -> std::result::Result<(), Box<EvalAltResult>> {
            Err("`sleep` is not available to grading scripts".into())
        });
        // Constants usable everywhere, including inside script functions, which cannot
        // see the caller's scope.
        #[expect(deprecated, reason = "on_var is marked volatile, not deprecated")]
        engine.on_var(|name, _, _| {
            Ok(match name {
                "PI" => Some(Dynamic::from_float(std::f64::consts::PI)),
                "E" => Some(Dynamic::from_float(std::f64::consts::E)),
                "TAU" => Some(Dynamic::from_float(std::f64::consts::TAU)),
                _ => None,
            })
        });
        // The control functions of the papers, accepting integers or floats.
        engine.register_fn("linear", |mu: Dynamic, lambda: Dynamic, r: Dynamic| {
            Ok::<FLOAT, Box<EvalAltResult>>(
                num(mu, "linear mu")? * num(r, "linear r")? + num(lambda, "linear lambda")?,
            )
        });
        engine.register_fn("wave", |mu: Dynamic, lambda: Dynamic, r: Dynamic| {
            Ok::<FLOAT, Box<EvalAltResult>>(
                num(mu, "wave mu")? * (num(lambda, "wave lambda")? * num(r, "wave r")?).sin(),
            )
        });
        engine.register_fn("power", |alpha: Dynamic, d: Dynamic, k: Dynamic| {
            Ok::<FLOAT, Box<EvalAltResult>>(
                (num(alpha, "power alpha")? * num(d, "power d")?).powf(num(k, "power k")?),
            )
        });
        engine.register_fn("clamp01", |v: Dynamic| {
            Ok::<FLOAT, Box<EvalAltResult>>(num(v, "clamp01")?.clamp(0.0, 1.0))
        });
        engine.register_fn("lerp", |a: Dynamic, b: Dynamic, t: Dynamic| {
            let (a, b, t) = (num(a, "lerp a")?, num(b, "lerp b")?, num(t, "lerp t")?);
            Ok::<FLOAT, Box<EvalAltResult>>(a + (b - a) * t)
        });
        // Rhai's math functions take floats only; accept integers as well.
        for f in ["sin", "cos", "tan", "sqrt", "exp", "ln", "abs_f"] {
            let op: fn(f64) -> f64 = match f {
                "sin" => f64::sin,
                "cos" => f64::cos,
                "tan" => f64::tan,
                "sqrt" => f64::sqrt,
                "exp" => f64::exp,
                "ln" => f64::ln,
                _ => f64::abs,
            };
            engine.register_fn(f, move |v: INT| op(v as f64));
        }
        engine.register_fn("pow", |a: Dynamic, b: Dynamic| {
            Ok::<FLOAT, Box<EvalAltResult>>(num(a, "pow")?.powf(num(b, "pow")?))
        });
        Self {
            engine: Arc::new(engine),
            base_dir: base_dir.into(),
            script_dirs: Vec::new(),
            time_limit: limits.time_limit,
            max_functions: limits.max_functions,
        }
    }

    fn with_script_dirs(mut self, dirs: Vec<PathBuf>) -> Self {
        self.script_dirs = dirs;
        self
    }

    /// Refuses a script file outside the pipeline's folder and its `script_dirs` (after
    /// following links: a `.rhai` link to a system file must not be read, and its
    /// lines must not be quoted in an error) or larger than [`MAX_SCRIPT_BYTES`].
    fn check_script_path(&self, path: &Path) -> std::result::Result<(), String> {
        let real = path
            .canonicalize()
            .map_err(|e| format!("cannot read script {}: {e}", path.display()))?;
        let inside = std::iter::once(&self.base_dir)
            .chain(&self.script_dirs)
            .filter_map(|d| d.canonicalize().ok())
            .any(|d| real.starts_with(d));
        if !inside {
            return Err(format!(
                "script {} lies outside the pipeline's folder {}: list its folder in the pipeline's `script_dirs` to allow it",
                path.display(),
                self.base_dir.display()
            ));
        }
        let size = std::fs::metadata(&real).map(|m| m.len()).unwrap_or(0);
        if size > MAX_SCRIPT_BYTES {
            return Err(format!(
                "script {} has {size} bytes, more than the {MAX_SCRIPT_BYTES} a grading script may have",
                path.display()
            ));
        }
        Ok(())
    }

    fn compile(&self, spec: &str, origin: Option<Location>) -> Result<LocalFn> {
        match spec.split_once('#') {
            Some((file, function)) if file.trim_end().ends_with(".rhai") => {
                self.function(&self.base_dir.join(file.trim()), function.trim(), origin)
            }
            _ => self.expression(spec, origin),
        }
    }

    /// Compiles an inline expression. Its variables are those of [`SCRIPT_VARIABLES`].
    fn expression(&self, text: &str, origin: Option<Location>) -> Result<LocalFn> {
        let source = match &origin {
            Some(o) => o.file.clone(),
            None => SourceFile::new("<expression>", text),
        };
        let base = origin
            .as_ref()
            .and_then(|o| inline_base(&o.file.text, o.span.start));
        let ast = self
            .engine
            .compile_with_scope(&script_scope(&ScriptArgs::default()), text)
            .map_err(|e| {
                let pos = e.position();
                script_error(
                    &source,
                    base,
                    pos,
                    format!("does not compile: {}", e.err_type()),
                    None,
                )
            })?;
        Ok(LocalFn {
            engine: self.engine.clone(),
            time_limit: self.time_limit,
            ast: Arc::new(ast),
            function: None,
            source,
            base,
            definition: origin.map_or(0, |o| o.span.start),
        })
    }

    /// Compiles a `.rhai` file and selects one of its functions.
    fn function(&self, path: &Path, name: &str, origin: Option<Location>) -> Result<LocalFn> {
        let at = |message: String| match origin.clone() {
            Some(o) => Error::config_at(o, message),
            None => Error::config(message),
        };
        self.check_script_path(path).map_err(at)?;
        let source = SourceFile::read(path).map_err(|e| match origin.clone() {
            Some(o) => Error::config_at(o, format!("cannot read script: {e}")),
            None => e,
        })?;
        // Rhai's parser slows down with the square of the number of functions.
        let functions = source.text.split_whitespace().filter(|w| *w == "fn").count();
        if functions > self.max_functions {
            return Err(at(format!(
                "{} defines {functions} functions, more than the {} a grading script may have",
                path.display(),
                self.max_functions
            )));
        }
        let ast = self.engine.compile(&source.text).map_err(|e| {
            script_error(
                &source,
                None,
                e.position(),
                format!("does not compile: {}", e.err_type()),
                None,
            )
        })?;
        let meta = ast.iter_functions().find(|f| f.name == name).ok_or_else(|| {
            // Sorted: the AST keeps its functions in a hash map.
            let mut names: Vec<_> = ast.iter_functions().map(|f| f.name.to_string()).collect();
            names.sort();
            names.dedup();
            let msg = format!(
                "{} has no function `{name}` (it has: {})",
                path.display(),
                names.join(", ")
            );
            match origin.clone() {
                Some(o) => Error::config_at(o, msg),
                None => Error::config(msg),
            }
        })?;
        let params: Vec<String> = meta.params.iter().map(|p| p.to_string()).collect();
        if let Some(bad) = params.iter().find(|p| !SCRIPT_VARIABLES.contains(&p.as_str())) {
            return Err(script_error(
                &source,
                None,
                Position::NONE,
                format!(
                    "function `{name}` has parameter `{bad}`; parameters must be among {}",
                    SCRIPT_VARIABLES.join(", ")
                ),
                None,
            ));
        }
        let definition = find_definition(&source.text, name);
        Ok(LocalFn {
            engine: self.engine.clone(),
            time_limit: self.time_limit,
            ast: Arc::new(ast),
            function: Some((name.to_string(), params)),
            source,
            base: None,
            definition,
        })
    }
}

/// Offset of the first character inside a TOML string literal starting at `start`.
fn inline_base(text: &str, start: usize) -> Option<usize> {
    let rest = text.get(start..)?;
    let quote = rest.find(['"', '\''])?;
    let q = &rest[quote..];
    let skip = if q.starts_with("\"\"\"") || q.starts_with("'''") {
        3
    } else {
        1
    };
    Some(start + quote + skip)
}

fn find_definition(text: &str, name: &str) -> usize {
    let pattern = format!("fn {name}");
    text.match_indices(&pattern)
        .find(|(i, _)| {
            text[i + pattern.len()..]
                .chars()
                .next()
                .is_some_and(|c| c == '(' || c.is_whitespace())
        })
        .map_or(0, |(i, _)| i)
}

fn script_scope(args: &ScriptArgs<'_>) -> Scope<'static> {
    let mut scope = Scope::new();
    for name in SCRIPT_VARIABLES {
        if let Some(v) = args.value(name) {
            scope.push_dynamic(*name, v);
        }
    }
    scope
}

fn script_error(
    source: &Arc<SourceFile>,
    base: Option<usize>,
    pos: Position,
    message: String,
    context: Option<String>,
) -> Error {
    let offset = match (pos.line(), base) {
        (Some(1), Some(base)) => Some(base + pos.position().unwrap_or(1) - 1),
        (Some(_), Some(base)) => Some(base),
        (Some(line), None) => Some(source.offset_of(line, pos.position().unwrap_or(1))),
        (None, Some(base)) => Some(base),
        (None, None) => None,
    };
    Error::Script {
        location: Some(Location::new(
            source.clone(),
            offset.unwrap_or(0)..offset.unwrap_or(0),
        )),
        message,
        context,
    }
}

/// A script compiled by the host's engine.
#[derive(Clone)]
struct LocalFn {
    engine: Arc<Engine>,
    time_limit: Duration,
    ast: Arc<AST>,
    /// Function name and parameter names; `None` for an inline expression.
    function: Option<(String, Vec<String>)>,
    source: Arc<SourceFile>,
    /// Offset of an inline expression inside `source`.
    base: Option<usize>,
    /// Offset of the function definition (or expression) for value errors.
    definition: usize,
}

impl std::fmt::Debug for LocalFn {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LocalFn")
            .field("source", &self.source.path)
            .field("function", &self.function)
            .finish()
    }
}

/// Clears the deadline when a call ends, however it ends.
struct DeadlineGuard;

impl Drop for DeadlineGuard {
    fn drop(&mut self) {
        DEADLINE.with(|d| d.set(None));
        STOPPED.with(|s| s.set(false));
    }
}

impl LocalFn {
    /// Runs the script with `args`, within the host's limits.
    fn call(&self, args: &ScriptArgs<'_>, context: &str) -> Result<Dynamic> {
        DEADLINE.with(|d| d.set(Some(Instant::now() + self.time_limit)));
        STOPPED.with(|s| s.set(false));
        HELD_AT_START.with(|h| h.set(HELD.with(Cell::get)));
        STOP_REASON.with(|r| r.set("time limit exceeded"));
        let _guard = DeadlineGuard;
        let result = match &self.function {
            None => {
                let mut scope = script_scope(args);
                self.engine.eval_ast_with_scope::<Dynamic>(&mut scope, &self.ast)
            }
            Some((name, params)) => {
                let values: Vec<Dynamic> = params.iter().filter_map(|p| args.value(p)).collect();
                let mut scope = Scope::new();
                let options = CallFnOptions::new().eval_ast(false).rewind_scope(true);
                self.engine
                    .call_fn_with_options::<Dynamic>(options, &mut scope, &self.ast, name, values)
            }
        };
        // Stopped inside a function that swallowed the error: the call still fails.
        let result = match result {
            Ok(_) if STOPPED.with(Cell::get) => Err(Box::new(EvalAltResult::ErrorTerminated(
                Dynamic::from(STOP_REASON.with(Cell::get).to_string()),
                Position::NONE,
            ))),
            other => other,
        };
        result.map_err(|e| {
            let pos = e.position();
            if pos.is_none() {
                // No position (a limit hit deep inside): the function, not the file's top.
                return self.value_error(
                    match *e {
                        EvalAltResult::ErrorTerminated(..) => match STOP_REASON.with(Cell::get) {
                            "memory limit exceeded" => "stopped: memory limit exceeded".to_string(),
                            _ => "stopped: time or operation limit exceeded".to_string(),
                        },
                        EvalAltResult::ErrorStackOverflow(..) => {
                            "stopped: too many nested function calls (endless recursion?)".to_string()
                        }
                        other => format!("failed: {other}"),
                    },
                    context,
                );
            }
            let message = match *e {
                EvalAltResult::ErrorTerminated(..) => format!("stopped: {}", STOP_REASON.with(Cell::get)),
                EvalAltResult::ErrorTooManyOperations(..) => {
                    "stopped: too many operations (an endless loop?)".to_string()
                }
                other => format!("failed: {other}"),
            };
            script_error(&self.source, self.base, pos, message, Some(context.to_string()))
        })
    }

    /// An error about the value the script returned, pointed at its definition.
    fn value_error(&self, message: String, context: &str) -> Error {
        Error::Script {
            location: Some(Location::new(
                self.source.clone(),
                self.definition..self.definition,
            )),
            message,
            context: Some(context.to_string()),
        }
    }

    fn number(&self, args: &ScriptArgs<'_>, context: &str) -> Result<f64> {
        let v = self.call(args, context)?;
        match as_number(&v) {
            Some(f) if f.is_finite() => Ok(f),
            _ => Err(self.value_error(
                format!("returned {v} ({}), expected a finite number", v.type_name()),
                context,
            )),
        }
    }

    fn fractions(&self, args: &ScriptArgs<'_>, n: usize, context: &str) -> Result<Vec<f64>> {
        let v = self.call(args, context)?;
        let fractions = if let Some(f) = as_number(&v) {
            match n {
                1 => vec![f],
                2 => vec![f, 1.0 - f],
                _ => {
                    return Err(self.value_error(
                        format!("returned one number {f}, expected an array of {n} fractions"),
                        context,
                    ));
                }
            }
        } else if let Some(arr) = v.clone().try_cast::<rhai::Array>() {
            let values: Option<Vec<f64>> = arr.iter().map(as_number).collect();
            match values {
                Some(values) if values.len() == n => values,
                _ => {
                    return Err(
                        self.value_error(format!("returned {v}, expected an array of {n} numbers"), context)
                    );
                }
            }
        } else {
            return Err(self.value_error(
                format!("returned {v} ({}), expected fractions", v.type_name()),
                context,
            ));
        };
        check_fractions(&fractions).map_err(|m| self.value_error(m, context))?;
        // Fractions within tolerance of the bounds are snapped into [0, 1].
        Ok(fractions.into_iter().map(|f| f.clamp(0.0, 1.0)).collect())
    }
}

fn check_fractions(fractions: &[f64]) -> std::result::Result<(), String> {
    for (i, f) in fractions.iter().enumerate() {
        if !f.is_finite() || *f < -COMPOSITION_TOLERANCE || *f > 1.0 + COMPOSITION_TOLERANCE {
            return Err(format!("fraction {i} is {f}, outside [0, 1]"));
        }
    }
    let sum: f64 = fractions.iter().sum();
    if (sum - 1.0).abs() > COMPOSITION_TOLERANCE {
        return Err(format!("fractions {fractions:?} sum to {sum}, not 1"));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn host() -> LocalHost {
        LocalHost::new(".", ScriptLimits::default()).with_script_dirs(vec![std::env::temp_dir()])
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
