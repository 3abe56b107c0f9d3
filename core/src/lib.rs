//! lamina-core: the model that flows between Lamina's stages, one trait per stage kind,
//! the registry of named stage factories, pipeline files, Rhai scripting, dynamic plugin
//! loading, machine profiles and the runtime that drives layers through the stages.
//!
//! This crate knows no concrete algorithm: slicers, sorters, discretisers, graders,
//! sequencers, planners and exporters live in plugin crates that depend on this one.

pub mod diagnostic;
pub mod error;
pub mod geom;
pub mod limits;
pub mod machine;
pub mod mesh;
pub mod microstructure;
pub mod model;
pub mod options;
pub mod output;
pub mod pipeline;
pub mod plugin;
pub mod process;
pub mod reach;
pub mod registry;
pub mod runtime;
pub mod script;
pub mod source;
pub mod stage;
pub mod steps;
pub mod surface;

pub use diagnostic::{Diagnostic, Severity};
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
pub use inventory;

/// Version of this crate, compared against the version a dynamic plugin was built with.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");
