//! lamina-machine: reading machine profiles. A pipeline names its machine with a
//! top-level `machine` key: the name of a built-in profile ([`builtin`]), the path of a
//! TOML profile (relative to the pipeline's folder), or an inline table, which may start
//! from `base = "<name or path>"` and override it key by key. [`load`] reads, merges and
//! validates it with errors that name the file, line and field, into the
//! [`Machine`](lamina_api::machine::Machine) that stages read.
//!
//! The description itself is data of the stage API (`lamina_api::machine`); what a
//! firmware makes of it (which values it takes, which template variables it knows) is
//! checked here, so that the host and the exporters that write machine files agree.

pub mod builtin;
mod check;
mod limits;
pub mod load;
mod raw;
mod tools;
mod validate;

#[allow(unused_imports)]
use lamina_api::geom::{BBox2, Point2};
#[allow(unused_imports)]
use lamina_api::machine::*;

pub use load::resolve;
