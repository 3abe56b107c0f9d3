//! The runtime: builds the stages a pipeline names, loads the model, and drives the
//! layers through slice → sort → discretise → grade → plan in parallel, handing the
//! finished layers to the exporters in build order.
//!
//! Layers are independent, so every thread of a rayon pool takes the next layer as soon
//! as it is free, at most a few layers per thread ahead of the exporters, which take
//! the finished layers in build order on the calling thread ([`stream`]). Memory
//! therefore stays bounded by those few layers plus the meshes, and the output does not
//! depend on the number of threads.
//!
//! One module a step of a run, in the order a run takes them:
//! - [`engine`]: building every stage a pipeline names (with the defaults for the
//!   kinds it leaves out), the model sources, and what `lamina check` summarises;
//! - [`meshes`]: loading, unit and size checks, placement, orientation and merging of
//!   the meshes, and the check that each part fits the machine;
//! - [`copies`]: the copies of a part on the plate, each the part's plan moved;
//! - [`families`]: which families of a layer belong to a part that picks its solid
//!   with `family_at`, followed from layer to layer;
//! - [`layer`]: one layer through slice, sort, discretise, grade and plan;
//! - [`run`]: the whole run: the pool, the layers, the exporters;
//! - [`stream`]: layers computed on the pool and consumed in order, with a bounded lead;
//! - [`report`]: what a run tells its observer and returns.

use std::path::{Path, PathBuf};

use crate::error::Result;
use crate::pipeline::Pipeline;
use crate::registry::Registry;
use crate::script::ScriptLimits;

mod copies;
mod engine;
mod families;
mod gradient;
mod layer;
mod mend;
mod meshes;
mod report;
mod run;
mod stream;
mod volume;

pub use engine::Engine;
pub use meshes::place;
pub use report::{Observer, RunReport, Silent, Timings};

/// How a run is carried out (as opposed to what it makes, which the pipeline says).
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// Worker threads; `None` uses every core.
    pub threads: Option<usize>,
    /// Replaces the model file of a single-part pipeline.
    pub model: Option<PathBuf>,
    /// Dynamic plugins to load in addition to the pipeline's `plugins`.
    pub plugins: Vec<PathBuf>,
    /// Where the plugins' code runs: in this process, or each in a child process.
    pub isolation: crate::plugin::Isolation,
    /// Limits applied to every Rhai script.
    pub script_limits: ScriptLimits,
}

/// Convenience for tests and embedders: parse, build and run a pipeline file.
pub fn run_file(path: &Path, out_dir: &Path, options: &RunOptions) -> Result<RunReport> {
    let pipeline = Pipeline::load(path, &[])?;
    let engine = Engine::build(pipeline, Registry::linked()?, options)?;
    engine.run(out_dir, &Silent)
}
