//! lamina-api: what a stage of Lamina is written against, and all a plugin crate needs.
//!
//! It holds the model that flows between stages (`mesh`, `geom`, `model`, `process`),
//! one trait per stage kind (`stage`), stage options declared once (`options`), the
//! named factories a plugin registers (`registry`), what stages say besides their output
//! (`diagnostic`, `error`), the machine a plan is made for as data (`machine`), the
//! handles through which stages reach scripts and files (`script`, `reach`), and the
//! plugin boundary itself (`plugin`: the C types, the messages and the plugin's side).
//!
//! The engine that runs pipelines (lamina-core) depends on this crate; plugins depend on
//! it alone, so they compile none of the engine and are versioned by what crosses the
//! boundary, not by the engine's inner workings.

pub mod diagnostic;
pub mod error;
pub mod geom;
pub mod kind;
pub mod limits;
pub mod machine;
pub mod mesh;
pub mod model;
pub mod options;
pub mod planned;
pub mod plugin;
pub mod process;
pub mod reach;
pub mod registry;
pub mod script;
pub mod source;
pub mod stage;
pub mod table;
pub mod text;

pub use diagnostic::{Diagnostic, Severity, Warning};
pub use error::{Error, Result};
pub use geom::{BBox2, Contour, Point2, Polygon, Vector2};
pub use limits::{Limit, Limits};
pub use machine::Machine;
pub use mesh::{BBox3, Mesh, Point3};
pub use model::*;
pub use process::{Operation, OperationPath, OperationTool, ProcessContext, RegionOutline};
pub use registry::StageFactory;
pub use source::{SourceFile, Span};
pub use stage::*;

/// Re-exported so plugin crates register stages with the same `inventory` as the host.
pub use inventory;

/// Version of this crate, compared against the version a dynamic plugin was built with.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");
