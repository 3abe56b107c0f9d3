//! G-code templates of a machine profile: text with `{variable}` placeholders, `{{` and
//! `}}` for literal braces (RepRapFirmware's expressions use them). The variables a
//! template may name are checked when the profile is read, so a misspelt one is an
//! error at its line instead of a broken file.

use serde::{Deserialize, Serialize};

/// Variables every template may use.
pub const COMMON_VARIABLES: &[&str] = &[
    "bed_temperature",
    "first_layer_bed_temperature",
    "first_tool",
    "nozzle_temperature",
    "first_layer_temperature",
    "standby_temperature",
    "filament_diameter",
    "nozzle_diameter",
    "print_min_x",
    "print_min_y",
    "print_max_x",
    "print_max_y",
    "max_z",
    "park_z",
];

/// Per-tool variables, written `<name>_<tool>` (`nozzle_temperature_1`).
pub const TOOL_VARIABLES: &[&str] = &[
    "nozzle_temperature",
    "first_layer_temperature",
    "standby_temperature",
];

/// Variables of the tool-change template only.
pub const TOOL_CHANGE_VARIABLES: &[&str] = &["previous_tool", "next_tool", "next_temperature", "layer_z"];

/// Variables of the end template only.
pub const END_VARIABLES: &[&str] = &["layer_z"];

/// Which template, for the variables it may use.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TemplateKind {
    Start,
    End,
    ToolChange,
}

impl TemplateKind {
    fn extra(self) -> &'static [&'static str] {
        match self {
            TemplateKind::Start => &[],
            TemplateKind::End => END_VARIABLES,
            TemplateKind::ToolChange => TOOL_CHANGE_VARIABLES,
        }
    }

    /// Whether `name` is a variable of this template on a machine with `tools` tools.
    pub fn knows(self, name: &str, tools: usize) -> bool {
        if COMMON_VARIABLES.contains(&name) || self.extra().contains(&name) {
            return true;
        }
        name.rsplit_once('_').is_some_and(|(base, n)| {
            TOOL_VARIABLES.contains(&base)
                && n.parse::<usize>().is_ok_and(|n| n < tools)
                && !n.starts_with('+')
        })
    }

    /// Every name this template may use, for messages.
    pub fn describe(self, tools: usize) -> String {
        let mut names: Vec<String> = COMMON_VARIABLES
            .iter()
            .chain(self.extra())
            .map(|s| s.to_string())
            .collect();
        if tools > 0 {
            names.extend(TOOL_VARIABLES.iter().map(|v| format!("{v}_0..{}", tools - 1)));
        }
        names.join(", ")
    }
}

/// One piece of a template.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Piece<'a> {
    Text(&'a str),
    /// A literal `{` or `}` written doubled.
    Brace(char),
    Variable(&'a str),
}

/// A G-code template as written in the profile.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Template {
    pub text: String,
}

/// What is wrong with a template: the message and the byte range in the text.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TemplateError {
    pub message: String,
    pub at: std::ops::Range<usize>,
}

impl Template {
    pub fn new(text: impl Into<String>) -> Self {
        Self { text: text.into() }
    }

    /// The template cut into text, braces and variables.
    pub fn pieces(&self) -> Result<Vec<Piece<'_>>, TemplateError> {
        let s = self.text.as_str();
        let mut out = Vec::new();
        let mut start = 0;
        let mut i = 0;
        let bytes = s.as_bytes();
        while i < bytes.len() {
            match bytes[i] {
                b'{' | b'}' if bytes.get(i + 1) == Some(&bytes[i]) => {
                    if start < i {
                        out.push(Piece::Text(&s[start..i]));
                    }
                    out.push(Piece::Brace(bytes[i] as char));
                    i += 2;
                    start = i;
                }
                b'{' => {
                    let end = s[i..].find('}').map(|e| i + e).ok_or_else(|| TemplateError {
                        message: "`{` without its `}` (write `{{` for a literal brace)".into(),
                        at: i..s.len(),
                    })?;
                    let name = &s[i + 1..end];
                    if name.is_empty() || !name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
                        return Err(TemplateError {
                            message: format!(
                                "`{{{name}}}` is not a variable name (write `{{{{` for a literal brace)"
                            ),
                            at: i..end + 1,
                        });
                    }
                    if start < i {
                        out.push(Piece::Text(&s[start..i]));
                    }
                    out.push(Piece::Variable(name));
                    i = end + 1;
                    start = i;
                }
                b'}' => {
                    return Err(TemplateError {
                        message: "`}` without its `{` (write `}}` for a literal brace)".into(),
                        at: i..i + 1,
                    });
                }
                _ => i += 1,
            }
        }
        if start < s.len() {
            out.push(Piece::Text(&s[start..]));
        }
        Ok(out)
    }

    /// Checks the syntax and that every variable is one `kind` knows.
    pub fn check(&self, kind: TemplateKind, tools: usize) -> Result<(), TemplateError> {
        let mut offset = 0;
        for piece in self.pieces()? {
            match piece {
                Piece::Text(t) => offset += t.len(),
                Piece::Brace(_) => offset += 2,
                Piece::Variable(name) => {
                    if !kind.knows(name, tools) {
                        return Err(TemplateError {
                            message: format!(
                                "unknown variable `{{{name}}}`; this template knows {}",
                                kind.describe(tools)
                            ),
                            at: offset..offset + name.len() + 2,
                        });
                    }
                    offset += name.len() + 2;
                }
            }
        }
        Ok(())
    }

    /// The text with every variable replaced by `value(name)`; a variable without a value
    /// is an error naming it.
    pub fn render(&self, value: impl Fn(&str) -> Option<String>) -> Result<String, String> {
        let mut out = String::with_capacity(self.text.len());
        for piece in self.pieces().map_err(|e| e.message)? {
            match piece {
                Piece::Text(t) => out.push_str(t),
                Piece::Brace(c) => out.push(c),
                Piece::Variable(name) => {
                    out.push_str(&value(name).ok_or_else(|| format!("no value for `{{{name}}}`"))?)
                }
            }
        }
        Ok(out)
    }

    pub fn is_empty(&self) -> bool {
        self.text.trim().is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn renders_variables_and_braces() {
        let t = Template::new("M190 S{bed_temperature}\necho {{x}}\nT{first_tool}");
        let out = t
            .render(|n| match n {
                "bed_temperature" => Some("60".into()),
                "first_tool" => Some("1".into()),
                _ => None,
            })
            .expect("renders");
        assert_eq!(out, "M190 S60\necho {x}\nT1");
        assert!(t.check(TemplateKind::Start, 2).is_ok());
    }

    #[test]
    fn unknown_variables_are_located() {
        let t = Template::new("M140 S{bed_temp}\n");
        let e = t.check(TemplateKind::Start, 1).expect_err("unknown");
        assert_eq!(e.at, 6..16);
        assert!(e.message.contains("bed_temperature"), "{}", e.message);
        assert!(Template::new("{layer_z}").check(TemplateKind::Start, 1).is_err());
        assert!(Template::new("{layer_z}").check(TemplateKind::End, 1).is_ok());
        assert!(
            Template::new("{standby_temperature_1}")
                .check(TemplateKind::ToolChange, 2)
                .is_ok()
        );
        assert!(
            Template::new("{standby_temperature_2}")
                .check(TemplateKind::ToolChange, 2)
                .is_err()
        );
        assert!(Template::new("M104 S{").check(TemplateKind::Start, 1).is_err());
        assert!(Template::new("a } b").check(TemplateKind::Start, 1).is_err());
    }
}
