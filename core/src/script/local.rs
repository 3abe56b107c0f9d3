//! The host's own Rhai engine: scripts compiled from inline expressions and `.rhai`
//! files within the allowed folders, and called under the sandbox's limits.

use std::cell::Cell;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use rhai::{AST, CallFnOptions, Dynamic, Engine, EvalAltResult, FLOAT, INT, Position, Scope};

use crate::error::{Error, Result};
use crate::model::COMPOSITION_TOLERANCE;
use crate::reach::Reach;
use crate::source::{Location, SourceFile};

use super::stop::*;
use super::*;

/// The host's own Rhai engine and the folders its scripts may come from.
#[derive(Clone)]
pub(super) struct LocalHost {
    engine: Arc<Engine>,
    base_dir: PathBuf,
    /// Where script files may be read from (the pipeline's reach).
    reach: Reach,
    time_limit: Duration,
    max_functions: usize,
    /// Script files compiled so far, by their real path: a file that several parts or
    /// stages name is read and compiled once (compiling is the costly part of a large
    /// script).
    compiled: Arc<std::sync::Mutex<std::collections::HashMap<PathBuf, Compiled>>>,
}

/// A compiled script file.
type Compiled = (Arc<SourceFile>, Arc<AST>);

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
    pub(super) fn new(base_dir: impl Into<PathBuf>, limits: ScriptLimits) -> Self {
        let base_dir = base_dir.into();
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
            // Once stopped, at every operation: a callback whose error Rhai swallows (a
            // sort comparator) must not run on until the next time check, or a
            // comparator that sorts again makes a tree of calls that only the
            // operation count ends, after many seconds.
            if STOPPED.with(Cell::get) {
                return stop(STOP_REASON.with(Cell::get));
            }
            // Memory at every operation: one operation may copy megabytes.
            if HELD.with(Cell::get).wrapping_sub(HELD_AT_START.with(Cell::get)) > max_memory {
                return stop("memory limit exceeded");
            }
            let over = ops >= max_operations;
            // The clock every 1024 operations of this thread, counted here: Rhai's own
            // count starts again in callbacks that native functions make (a sort's
            // comparator), which may never reach 1024 operations each.
            let tick = TICKS.with(|t| {
                let n = t.get().wrapping_add(1);
                t.set(n);
                n
            });
            if !tick.is_multiple_of(1024) && !over {
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
            reach: Reach::folder(&base_dir),
            base_dir,
            time_limit: limits.time_limit,
            max_functions: limits.max_functions,
            compiled: Default::default(),
        }
    }

    pub(super) fn with_reach(mut self, reach: Reach) -> Self {
        self.reach = reach;
        self
    }

    /// Refuses a script file outside the pipeline's reach (after following links: a
    /// `.rhai` link to a system file must not be read, and its lines must not be
    /// quoted in an error); its real path otherwise.
    fn check_script_path(&self, path: &Path) -> std::result::Result<PathBuf, String> {
        self.reach
            .check(path)
            .map_err(|e| format!("cannot read script {}: {e}", path.display()))
    }

    /// Reads (at most [`MAX_SCRIPT_BYTES`]) and compiles the script at `real`, named
    /// `path` in messages, or finds it compiled already.
    fn compiled(&self, path: &Path, real: PathBuf, at: &dyn Fn(String) -> Error) -> Result<Compiled> {
        let cache = || {
            self.compiled
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
        };
        if let Some(done) = cache().get(&real) {
            return Ok(done.clone());
        }
        let bytes = crate::source::read_regular(&real, MAX_SCRIPT_BYTES)
            .map_err(|e| at(format!("cannot read script {}: {e}", path.display())))?;
        let text = String::from_utf8(bytes)
            .map_err(|e| at(format!("cannot read script {}: {e}", path.display())))?;
        let source = SourceFile::new(path, text);
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
        let done = (source, Arc::new(ast));
        cache().insert(real, done.clone());
        Ok(done)
    }

    pub(super) fn compile_fn(&self, spec: &str, origin: Option<Location>) -> Result<LocalFn> {
        match spec.split_once('#') {
            Some((file, function)) if file.trim_end().ends_with(".rhai") => {
                self.function(&self.base_dir.join(file.trim()), function.trim(), origin)
            }
            _ => self.expression(spec, origin),
        }
    }

    /// Compiles an inline expression. Its variables are those of [`SCRIPT_VARIABLES`].
    pub(super) fn expression(&self, text: &str, origin: Option<Location>) -> Result<LocalFn> {
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
    pub(super) fn function(&self, path: &Path, name: &str, origin: Option<Location>) -> Result<LocalFn> {
        let at = |message: String| match origin.clone() {
            Some(o) => Error::config_at(o, message),
            None => Error::config(message),
        };
        let real = self.check_script_path(path).map_err(at)?;
        let (source, ast) = self.compiled(path, real, &at)?;
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
            ast,
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

impl Compiler for LocalHost {
    fn compile(&self, spec: &str, origin: Option<Location>) -> Result<ScriptFn> {
        self.compile_fn(spec, origin).map(ScriptFn::new)
    }
}

impl Script for LocalFn {
    fn number(&self, args: &ScriptArgs<'_>, context: &str) -> Result<f64> {
        LocalFn::number(self, args, context)
    }

    fn fractions(&self, args: &ScriptArgs<'_>, n: usize, context: &str) -> Result<Vec<f64>> {
        LocalFn::fractions(self, args, n, context)
    }
}

/// The value of the script variable `name` in a call with `args`.
fn value(args: &ScriptArgs<'_>, name: &str) -> Option<Dynamic> {
    Some(match name {
        "r" => Dynamic::from_float(args.r),
        "d" => Dynamic::from_float(args.d),
        "x" => Dynamic::from_float(args.x),
        "y" => Dynamic::from_float(args.y),
        "z" => Dynamic::from_float(args.z),
        "layer" => Dynamic::from_int(args.layer),
        "part" => Dynamic::from(args.part.to_string()),
        _ => return None,
    })
}

fn script_scope(args: &ScriptArgs<'_>) -> Scope<'static> {
    let mut scope = Scope::new();
    for name in SCRIPT_VARIABLES {
        if let Some(v) = value(args, name) {
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
pub(super) struct LocalFn {
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
                let values: Vec<Dynamic> = params.iter().filter_map(|p| value(args, p)).collect();
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

    pub(super) fn number(&self, args: &ScriptArgs<'_>, context: &str) -> Result<f64> {
        let v = self.call(args, context)?;
        match as_number(&v) {
            Some(f) if f.is_finite() => Ok(f),
            _ => Err(self.value_error(
                format!("returned {v} ({}), expected a finite number", v.type_name()),
                context,
            )),
        }
    }

    pub(super) fn fractions(&self, args: &ScriptArgs<'_>, n: usize, context: &str) -> Result<Vec<f64>> {
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
