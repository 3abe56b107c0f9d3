//! lamina-core: the engine that runs Lamina's pipelines: pipeline files, the registry of
//! stages, Rhai scripting, dynamic plugin loading, atomic outputs and the runtime that
//! drives layers through the stages.
//!
//! What a stage is written against (the model, the stage traits, options, machine data,
//! the plugin boundary) is `lamina-api`, re-exported here module by module so that a
//! program embedding the engine names one crate. This crate knows no concrete
//! algorithm: slicers, sorters, discretisers, graders, sequencers, planners and
//! exporters live in plugin crates that depend on lamina-api.

pub mod output;
pub mod pipeline;
pub mod plugin;
pub mod registry;
pub mod runtime;
pub mod script;

pub use lamina_api::{
    diagnostic, error, geom, limits, mesh, model, options, planned, process, reach, source, stage, text,
};
pub use lamina_api::{option_type, register_default, register_stage, stage_options};

/// Machine profiles: the data stages read (`lamina_api::machine`) and how profiles are
/// read and checked (`lamina_machine`).
pub mod machine {
    pub use lamina_api::machine::*;
    pub use lamina_machine::{builtin, load, resolve};
}

pub use diagnostic::{Diagnostic, Severity, Warning};
pub use error::{Error, Result};
pub use geom::{BBox2, Contour, Point2, Polygon, Vector2};
pub use limits::{Limit, Limits};
pub use machine::Machine;
pub use mesh::{BBox3, Mesh, Point3};
pub use model::*;
pub use process::{Operation, OperationPath, OperationTool, ProcessContext, RegionOutline};
pub use registry::{Registry, StageFactory};
pub use source::{SourceFile, Span};
pub use stage::*;

/// Re-exported so plugin crates register stages with the same `inventory` as the host.
pub use lamina_api::inventory;

/// Version of the stage API this engine was built with, compared against the version a
/// dynamic plugin was built with.
pub const VERSION: &str = lamina_api::VERSION;
