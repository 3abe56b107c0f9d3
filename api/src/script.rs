//! Scripts as stages see them: a [`ScriptHost`] compiles a pipeline's script reference
//! into a [`ScriptFn`] that stages call for numbers or volume fractions.
//!
//! Stages never see the script engine. The host's engine (Rhai, in a sandbox with
//! operation, depth, size, memory and time limits) lies behind [`Compiler`] and
//! [`Script`]; in a dynamic plugin, the same handles send every compile and call to the
//! host, so a plugin's scripts run under the host's limits whatever it links.
//!
//! A reference is either an inline expression of the pipeline (`f = "sin(r * PI)"`) or a
//! function in a `.rhai` file beside it (`f = "grading.rhai#ceramic"`). Functions receive
//! their parameters by name from the variables the caller offers (r, d, x, y, z, layer,
//! part), so `fn f(r)` and `fn f(z, r)` both work.

use std::fmt;
use std::sync::Arc;

use crate::error::{Error, Result};
use crate::source::Location;

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

/// What compiles script references: the host's engine, or the way to it from a
/// dynamic plugin.
pub trait Compiler: Send + Sync + fmt::Debug {
    /// Compiles `spec` (`file.rhai#function` or an inline expression); `origin` is where
    /// the reference is written, for error positions.
    fn compile(&self, spec: &str, origin: Option<Location>) -> Result<ScriptFn>;
}

/// One compiled script.
pub trait Script: Send + Sync + fmt::Debug {
    /// The script's value for a single number (any finite value).
    fn number(&self, args: &ScriptArgs<'_>, context: &str) -> Result<f64>;
    /// The script's volume fractions of `n` materials, checked.
    fn fractions(&self, args: &ScriptArgs<'_>, n: usize, context: &str) -> Result<Vec<f64>>;

    /// [`fractions`](Self::fractions) for each of `calls`, in order, stopping at the
    /// first error, which comes with the number of the call that failed (`calls.len()`
    /// for an error of no call) and without a context: the caller describes that one
    /// call ([`ScriptFn::fractions_each`]).
    fn fractions_batch(
        &self,
        calls: &[ScriptArgs<'_>],
        n: usize,
    ) -> std::result::Result<Vec<Vec<f64>>, (usize, Error)> {
        calls
            .iter()
            .enumerate()
            .map(|(i, args)| self.fractions(args, n, "").map_err(|e| (i, e)))
            .collect()
    }
}

/// Compiles scripts for the stages of one run. Cheap to clone and share between threads.
#[derive(Clone, Debug)]
pub struct ScriptHost(Arc<dyn Compiler>);

impl ScriptHost {
    pub fn new(compiler: impl Compiler + 'static) -> Self {
        Self(Arc::new(compiler))
    }

    /// Compiles a script reference from a pipeline: `file.rhai#function` names a
    /// function in a file beside the pipeline; anything else is an inline expression.
    /// `origin` is where the reference is written (for error positions).
    pub fn compile(&self, spec: &str, origin: Option<Location>) -> Result<ScriptFn> {
        self.0.compile(spec, origin)
    }
}

/// A compiled script: call it as often as needed, from any thread (in a dynamic
/// plugin: from the threads the host calls the plugin's stages on).
#[derive(Clone, Debug)]
pub struct ScriptFn(Arc<dyn Script>);

impl ScriptFn {
    pub fn new(script: impl Script + 'static) -> Self {
        Self(Arc::new(script))
    }

    /// Calls the script for a single number (any finite value).
    pub fn number(&self, args: &ScriptArgs<'_>, context: &str) -> Result<f64> {
        self.0.number(args, context)
    }

    /// Calls the script for the volume fractions of `n` materials. A single number `f`
    /// means `[f, 1 - f]` when `n == 2`; otherwise an array of `n` numbers is expected.
    /// Every fraction must lie in [0, 1] and they must sum to 1 (1e-9).
    pub fn fractions(&self, args: &ScriptArgs<'_>, n: usize, context: &str) -> Result<Vec<f64>> {
        self.0.fractions(args, n, context)
    }

    /// [`fractions`](Self::fractions) for each of `calls`, in order, stopping at the
    /// first error. A stage that grades many regions at once asks this way: from a
    /// dynamic plugin, the calls reach the host in one request. `context(i)` says what
    /// call `i` computes; it is asked only for a call that fails, since describing
    /// every call costs more than most scripts take to run.
    pub fn fractions_each(
        &self,
        calls: &[ScriptArgs<'_>],
        n: usize,
        context: impl FnOnce(usize) -> String,
    ) -> Result<Vec<Vec<f64>>> {
        self.0.fractions_batch(calls, n).map_err(|(i, e)| {
            if i < calls.len() {
                e.in_context(context(i))
            } else {
                e
            }
        })
    }

    /// [`fractions_each`](Self::fractions_each) for a caller that reports which call
    /// failed rather than what it computed (the host serving a plugin's batch): the
    /// error comes with the call's number (`calls.len()` for an error of no call) and
    /// no context.
    pub fn fractions_batch(
        &self,
        calls: &[ScriptArgs<'_>],
        n: usize,
    ) -> std::result::Result<Vec<Vec<f64>>, (usize, Error)> {
        self.0.fractions_batch(calls, n)
    }
}
