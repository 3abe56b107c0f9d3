//! What the stages of a run say besides their output: a warning (something repaired,
//! dropped or likely wrong) or a note, with the stage, part and layer it concerns.

use serde::{Deserialize, Serialize};

use crate::kind::StageKind;

/// How much a [`Diagnostic`] matters.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Severity {
    /// Something was repaired, dropped or is likely wrong; the output may not be what
    /// was meant.
    Warning,
    /// Information asked for (a comparison, a figure); nothing is wrong.
    Note,
}

impl Severity {
    pub fn name(self) -> &'static str {
        match self {
            Severity::Warning => "warning",
            Severity::Note => "note",
        }
    }
}

/// Something a stage repaired, dropped or wants the user to know, with where it
/// happened; the run goes on. Carried as data (in the run report and the JSON plan),
/// so a front end can group, count and filter them rather than read strings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Diagnostic {
    pub severity: Severity,
    /// The kind of stage that said it.
    pub stage: StageKind,
    /// The part it concerns, when it concerns one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub part: Option<String>,
    /// The layer it concerns (its index), when it concerns one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub layer: Option<usize>,
    /// That layer's top (mm).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub z: Option<f64>,
    /// What happened, in the user's words: no layer, part or stage in it, which the
    /// fields above carry.
    pub message: String,
}

impl Diagnostic {
    pub fn new(severity: Severity, stage: StageKind, message: impl Into<String>) -> Self {
        Self {
            severity,
            stage,
            part: None,
            layer: None,
            z: None,
            message: message.into(),
        }
    }

    pub fn warning(stage: StageKind, message: impl Into<String>) -> Self {
        Self::new(Severity::Warning, stage, message)
    }

    /// The same, said of layer `index` whose top is at `z`.
    pub fn at_layer(mut self, index: usize, z: f64) -> Self {
        self.layer = Some(index);
        self.z = Some(z);
        self
    }

    /// The same, said of part `name`.
    pub fn in_part(mut self, name: &str) -> Self {
        self.part = Some(name.to_string());
        self
    }
}

impl std::fmt::Display for Diagnostic {
    /// One line that stands on its own: `layer 3 (z = 0.8000 mm), part `gear`: ...`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let mut place = Vec::new();
        if let (Some(l), Some(z)) = (self.layer, self.z) {
            place.push(format!("layer {l} (z = {z:.4} mm)"));
        }
        if let Some(p) = &self.part {
            place.push(format!("part `{p}`"));
        }
        if place.is_empty() {
            write!(f, "{}", self.message)
        } else {
            write!(f, "{}: {}", place.join(", "), self.message)
        }
    }
}
