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
    /// What kind of thing it says, set by the stage: a kebab-case name unique within
    /// its stage kind (`open-chains-dropped`), by which front ends group and filter
    /// what a run said without reading the words. Empty from stages of plugins older
    /// than ABI 7.3.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub code: String,
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
    pub fn new(
        severity: Severity,
        stage: StageKind,
        code: impl Into<String>,
        message: impl Into<String>,
    ) -> Self {
        Self {
            severity,
            stage,
            code: code.into(),
            part: None,
            layer: None,
            z: None,
            message: message.into(),
        }
    }

    pub fn warning(stage: StageKind, code: impl Into<String>, message: impl Into<String>) -> Self {
        Self::new(Severity::Warning, stage, code, message)
    }

    /// A [`Warning`] that `stage` attached to its output, as a diagnostic.
    pub fn from_warning(stage: StageKind, w: &Warning) -> Self {
        Self::warning(stage, w.code.as_str(), w.message.as_str())
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

/// A warning a stage attaches to what it hands back (a mesh it read, a layer it cut),
/// before the runtime knows its place: the runtime makes it a [`Diagnostic`] with the
/// stage, part and layer.
///
/// On the wire a warning is one string, `[code] message` (the message alone when it has
/// no code): plugins of ABI 7.0 to 7.2 read and write these lists as strings, and still
/// exchange meshes and layers with this host, whose warnings they pass on as words.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Warning {
    /// As [`Diagnostic::code`]; empty from a plugin older than ABI 7.3.
    pub code: String,
    pub message: String,
}

impl Warning {
    pub fn new(code: impl Into<String>, message: impl Into<String>) -> Self {
        Self {
            code: code.into(),
            message: message.into(),
        }
    }

    /// The wire's form: `[code] message`.
    fn encode(&self) -> String {
        if self.code.is_empty() {
            self.message.clone()
        } else {
            format!("[{}] {}", self.code, self.message)
        }
    }

    /// Reads the wire's form; words that do not start with a bracketed kebab-case code
    /// (an older plugin's) are a message without a code.
    fn decode(text: &str) -> Self {
        let coded = text.strip_prefix('[').and_then(|rest| {
            let (code, message) = rest.split_once("] ")?;
            is_code(code).then(|| Self::new(code, message))
        });
        coded.unwrap_or_else(|| Self::new("", text))
    }
}

/// Whether `s` is a code: lower-case ASCII letters, digits and single hyphens between
/// them, starting with a letter.
pub fn is_code(s: &str) -> bool {
    s.starts_with(|c: char| c.is_ascii_lowercase())
        && !s.ends_with('-')
        && !s.contains("--")
        && s.chars()
            .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '-')
}

impl std::fmt::Display for Warning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.message)
    }
}

impl Serialize for Warning {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_str(&self.encode())
    }
}

impl<'de> Deserialize<'de> for Warning {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let text = std::borrow::Cow::<'de, str>::deserialize(deserializer)?;
        Ok(Self::decode(&text))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_warning_crosses_the_wire_as_one_string_with_its_code() {
        let w = Warning::new("gaps-closed", "closed 2 gap(s) below 0.05 mm");
        let text = serde_json::to_string(&w).expect("encodes");
        assert_eq!(text, r#""[gaps-closed] closed 2 gap(s) below 0.05 mm""#);
        assert_eq!(serde_json::from_str::<Warning>(&text).expect("decodes"), w);
        // An older plugin's words: no code, whatever brackets they hold.
        for old in [
            "dropped 3 chains",
            "[x y] z",
            "[Upper] case",
            "[a-] b",
            "[] empty",
            "[a--b] c",
        ] {
            let json = serde_json::to_string(old).expect("encodes");
            let read: Warning = serde_json::from_str(&json).expect("decodes");
            assert_eq!(read, Warning::new("", old), "{old}");
        }
        // No code: the words alone, as an older plugin writes them.
        let bare = Warning::new("", "as before");
        assert_eq!(serde_json::to_string(&bare).expect("encodes"), r#""as before""#);
    }

    #[test]
    fn codes_are_kebab_case() {
        for ok in ["a", "gaps-closed", "open-chains-dropped", "x2-y"] {
            assert!(is_code(ok), "{ok}");
        }
        for bad in ["", "-a", "a-", "a--b", "A", "a_b", "2a", "a b", "a.b"] {
            assert!(!is_code(bad), "{bad}");
        }
    }
}
