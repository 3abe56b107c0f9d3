//! Named stage factories: `(kind, name) -> build(table)`. Linked plugins register them
//! with `inventory` ([`register_stage!`](crate::register_stage)); a dynamic plugin's
//! are handed to the host when it loads the library.

use crate::error::Result;
use crate::stage::{AnyStage, StageConfig, StageInfo, StageKind};

/// A named stage implementation: its self-description and how to build it from its
/// pipeline table.
#[derive(Debug)]
pub struct StageFactory {
    pub info: StageInfo,
    pub build: fn(&StageConfig<'_>) -> Result<AnyStage>,
}

inventory::collect!(StageFactory);

/// Registers a [`StageFactory`] with the registry of the crate that links this one.
///
/// ```ignore
/// lamina_api::register_stage!(StageFactory { info: INFO, build: build_uniform });
/// ```
#[macro_export]
macro_rules! register_stage {
    ($factory:expr) => {
        $crate::inventory::submit! { $factory }
    };
}

/// The stage a pipeline gets for a kind every run needs (slice, sort) when it has no
/// table for that kind. The plugin that provides the stage declares it, so core names
/// no stage.
#[derive(Debug)]
pub struct DefaultStage {
    pub kind: StageKind,
    pub name: &'static str,
}

inventory::collect!(DefaultStage);

/// Declares a linked stage as the default of its kind ([`DefaultStage`]).
///
/// ```ignore
/// lamina_api::register_default!(StageKind::Slice, "uniform");
/// ```
#[macro_export]
macro_rules! register_default {
    ($kind:expr, $name:literal) => {
        $crate::inventory::submit! { $crate::registry::DefaultStage { kind: $kind, name: $name } }
    };
}
