//! The kinds of stage: the tables a pipeline is made of, named in its file, in
//! diagnostics and in the registry.

use std::fmt;

use serde::{Deserialize, Serialize};

/// The kinds of stage a pipeline is made of, in the order data flows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum StageKind {
    /// Produces meshes: file readers and model generators.
    Model,
    /// Chooses the build direction of the whole object.
    Orient,
    Slice,
    Sort,
    Discretise,
    Grade,
    Sequence,
    Plan,
    /// Operations of a hybrid process on each layer (spray, mill, grind, engrave, ...).
    Process,
    Export,
}

impl StageKind {
    pub const ALL: [StageKind; 10] = [
        StageKind::Model,
        StageKind::Orient,
        StageKind::Slice,
        StageKind::Sort,
        StageKind::Discretise,
        StageKind::Grade,
        StageKind::Sequence,
        StageKind::Plan,
        StageKind::Process,
        StageKind::Export,
    ];

    /// The pipeline table that configures a stage of this kind.
    pub fn name(self) -> &'static str {
        match self {
            StageKind::Model => "model",
            StageKind::Orient => "orient",
            StageKind::Slice => "slice",
            StageKind::Sort => "sort",
            StageKind::Discretise => "discretise",
            StageKind::Grade => "grade",
            StageKind::Sequence => "sequence",
            StageKind::Plan => "plan",
            StageKind::Process => "process",
            StageKind::Export => "export",
        }
    }

    pub fn parse(s: &str) -> Option<StageKind> {
        StageKind::ALL.into_iter().find(|k| k.name() == s)
    }
}

impl fmt::Display for StageKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}
