//! A table of a pipeline file as stages see it: its values, its path from the
//! document's root, and the places of its keys for errors; deserialiser messages in
//! the words of a pipeline's reader.

use std::sync::Arc;

use serde::de::DeserializeOwned;
use toml::Spanned;
use toml::de::{DeTable, DeValue};

use crate::error::{Error, Result};
use crate::source::{Location, SourceFile};

/// Keys of a `[model]` table that the host reads itself.
pub const MODEL_HOST_KEYS: &[&str] = &["use", "scale", "units", "place"];

/// One step of a path from the document root to a table.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum PathElem {
    Key(String),
    Index(usize),
}

impl std::fmt::Display for PathElem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            PathElem::Key(k) => f.write_str(k),
            PathElem::Index(i) => write!(f, "{i}"),
        }
    }
}

/// A step by key.
pub fn key(k: &str) -> PathElem {
    PathElem::Key(k.to_string())
}

/// A table of a pipeline file together with where it came from, so that a stage can
/// deserialise its options and point errors at the right key.
#[derive(Debug, Clone)]
pub struct TableRef {
    /// The table as it is after `--set` overrides.
    pub(crate) table: toml::Table,
    pub(crate) file: Arc<SourceFile>,
    pub(crate) path: Vec<PathElem>,
    /// True when an override changed something in this table: spans then no longer
    /// describe the values, and errors name the override instead.
    pub(crate) overridden: bool,
    /// Keys the host consumes before the stage sees the table (`use`, placement).
    pub(crate) host_keys: &'static [&'static str],
    /// Keys the file names otherwise than the type it is parsed into: (name in the
    /// file, name in the type). A setting renamed in the file keeps its former name on
    /// the plugin wire, and an error about it is still placed in the file.
    pub(crate) renamed: &'static [(&'static str, &'static str)],
}

impl TableRef {
    /// A table of a pipeline file read by the host: `table` as it is after the
    /// overrides, at `path` in `file`; `overridden` when an override changed it.
    pub fn new(table: toml::Table, file: Arc<SourceFile>, path: Vec<PathElem>, overridden: bool) -> Self {
        Self {
            table,
            file,
            path,
            overridden,
            host_keys: &["use"],
            renamed: &[],
        }
    }

    /// The table's values, after `--set` overrides.
    pub fn values(&self) -> &toml::Table {
        &self.table
    }

    /// The table as written in its file, with the places of its keys; `None` when an
    /// override changed it (the places then no longer describe the values).
    pub fn written(&self) -> Option<Spanned<DeValue<'_>>> {
        if self.overridden {
            return None;
        }
        navigate_de(self.file.toml()?, &self.path)
    }

    /// A table that did not come from a file (tests, examples, generated pipelines).
    pub fn detached(name: &str, table: toml::Table) -> Self {
        let text = toml::to_string(&table).unwrap_or_default();
        Self {
            table,
            file: SourceFile::new(format!("<{name}>"), text),
            path: Vec::new(),
            overridden: false,
            host_keys: &["use"],
            renamed: &[],
        }
    }

    /// Parses `text` as the body of one table (e.g. a stage's example snippet).
    pub fn parse_snippet(name: &str, text: &str) -> Result<Self> {
        let file = SourceFile::new(format!("<{name}>"), text);
        let table: toml::Table = toml::from_str(text).map_err(|e| toml_error(&file, &e))?;
        Ok(Self {
            table,
            file,
            path: Vec::new(),
            overridden: false,
            host_keys: &["use"],
            renamed: &[],
        })
    }

    pub fn file(&self) -> &Arc<SourceFile> {
        &self.file
    }

    /// Where this table is in its file, from the document root.
    pub fn path(&self) -> &[PathElem] {
        &self.path
    }

    /// True when a `--set` override changed this table, so its spans are stale.
    pub fn is_overridden(&self) -> bool {
        self.overridden
    }

    /// The dotted path of this table in its file (`slice`, `parts.0.grade`).
    pub fn path_string(&self) -> String {
        self.path
            .iter()
            .map(ToString::to_string)
            .collect::<Vec<_>>()
            .join(".")
    }

    /// The `use = "name"` of a stage table.
    pub fn use_name(&self) -> Option<&str> {
        self.table.get("use").and_then(|v| v.as_str())
    }

    /// The value of key `k`, after overrides.
    pub fn get(&self, k: &str) -> Option<&toml::Value> {
        self.table.get(k)
    }

    /// True when the table sets `key` (after overrides).
    pub fn has(&self, key: &str) -> bool {
        self.table.contains_key(key)
    }

    /// Same table with a different set of host-consumed keys.
    pub fn with_host_keys(mut self, keys: &'static [&'static str]) -> Self {
        self.host_keys = keys;
        self
    }

    /// Same table with keys that the file names otherwise than the type it is parsed
    /// into: pairs of (name in the file, name in the type). The file may give either
    /// name, not both.
    pub fn with_renamed_keys(mut self, renamed: &'static [(&'static str, &'static str)]) -> Self {
        self.renamed = renamed;
        self
    }

    /// Deserialises the table, less the host's keys, into `T`. Errors point at the key
    /// or value in the file.
    pub fn parse<T: DeserializeOwned>(&self) -> Result<T> {
        for (new, old) in self.renamed {
            if self.table.contains_key(*new) && self.table.contains_key(*old) {
                return Err(self.error_at(old, format!("give `{new}` or its former name `{old}`, not both")));
            }
        }
        if !self.overridden
            && let Some(doc) = self.file.toml()
            && let Some(value) = navigate_de(doc, &self.path)
        {
            let span = value.span();
            let mut inner = value.into_inner();
            if let DeValue::Table(t) = &mut inner {
                let host: Vec<_> = t
                    .iter()
                    .filter(|(k, _)| self.host_keys.contains(&k.get_ref().as_ref()))
                    .map(|(k, _)| k.clone())
                    .collect();
                for k in host {
                    t.remove(&k);
                }
                for (new, old) in self.renamed {
                    let written = t.keys().find(|k| k.get_ref().as_ref() == *new).cloned();
                    if let Some(k) = written
                        && let Some(v) = t.remove(&k)
                    {
                        // The key keeps its place in the file under the type's name.
                        t.insert(Spanned::new(k.span(), std::borrow::Cow::Borrowed(*old)), v);
                    }
                }
            }
            let de = toml::de::ValueDeserializer::from(Spanned::new(span, inner));
            return T::deserialize(de).map_err(|e| self.de_error(&e));
        }
        let mut table = self.table.clone();
        for k in self.host_keys {
            table.remove(*k);
        }
        for (new, old) in self.renamed {
            if let Some(v) = table.remove(*new) {
                table.insert(old.to_string(), v);
            }
        }
        // The table as the overrides left it has no file: write it out and read it
        // back, so that an error still finds the key it is about.
        let text = toml::to_string(&table).unwrap_or_default();
        if let Ok(doc) = DeTable::parse(&text) {
            let span = doc.span();
            let keys: Vec<(String, std::ops::Range<usize>)> = doc
                .get_ref()
                .iter()
                .map(|(k, v)| (k.get_ref().to_string(), k.span().start..v.span().end))
                .collect();
            let de = toml::de::ValueDeserializer::from(Spanned::new(span, DeValue::Table(doc.into_inner())));
            return T::deserialize(de).map_err(|e| {
                let key = e.span().and_then(|at| {
                    keys.iter()
                        .filter(|(_, r)| r.start <= at.start && at.end <= r.end.max(r.start + 1))
                        .min_by_key(|(_, r)| r.end - r.start)
                        .map(|(k, _)| k.clone())
                });
                let message = self.in_file_words(e.message().trim());
                match key {
                    Some(k) => self.error_at(self.file_name(&k), message),
                    None => Error::config(format!("[{}] {message}", self.path_string())),
                }
            });
        }
        T::deserialize(toml::Value::Table(table)).map_err(|e| {
            Error::config(format!(
                "[{}] {}",
                self.path_string(),
                self.in_file_words(e.message().trim())
            ))
        })
    }

    /// The name the file gives a key the type names `k`.
    fn file_name<'k>(&self, k: &'k str) -> &'k str {
        self.renamed
            .iter()
            .find(|(_, old)| *old == k)
            .map_or(k, |(new, _)| new)
    }

    /// A deserialiser's message in the reader's words, its keys named as the file
    /// names them.
    fn in_file_words(&self, message: &str) -> String {
        let mut out = plain(message);
        for (new, old) in self.renamed {
            out = out.replace(&format!("`{old}`"), &format!("`{new}`"));
        }
        out
    }

    fn de_error(&self, e: &toml::de::Error) -> Error {
        let location = e
            .span()
            .map(|s| Location::new(self.file.clone(), s))
            .or_else(|| self.location_of(None));
        Error::Config {
            location,
            message: format!(
                "[{}] {}",
                self.path_string(),
                self.in_file_words(e.message().trim())
            ),
            help: None,
        }
    }

    /// Where `key` of this table is written, or the table itself when `key` is `None` or
    /// absent.
    pub fn location_of(&self, key: Option<&str>) -> Option<Location> {
        let value = navigate_de(self.file.toml()?, &self.path)?;
        let table_span = value.span();
        if let (Some(k), DeValue::Table(t)) = (key, value.get_ref())
            && let Some((kk, _)) = t.iter().find(|(kk, _)| kk.get_ref().as_ref() == k)
        {
            return Some(Location::new(self.file.clone(), kk.span()));
        }
        Some(Location::new(self.file.clone(), table_span))
    }

    /// Where the string value of `key` is written in the file, when the file still
    /// holds the value the table has: `None` when a `--set` override replaced it, so
    /// that positions inside the string (a script's) are not read off another text.
    /// A value a `--set` override gave is located in a text of its own, the override
    /// as a TOML line (`grade.f = "..."`), so that its errors point at the override.
    pub fn string_location(&self, key: &str) -> Option<Location> {
        let current = self.table.get(key)?.as_str()?;
        let mut path = self.path.clone();
        path.push(PathElem::Key(key.to_string()));
        let file = self.file.toml()?;
        match navigate_de(file, &path).as_ref().map(Spanned::get_ref) {
            Some(DeValue::String(s)) if s.as_ref() == current => self.location_of(Some(key)),
            _ => {
                let name = path.iter().map(ToString::to_string).collect::<Vec<_>>().join(".");
                // A literal string when it can be one: no escapes, so that positions
                // in the value are positions in the line.
                let value = if current.contains(['\'', '\n', '\r']) {
                    toml::Value::String(current.to_string()).to_string()
                } else {
                    format!("'{current}'")
                };
                let line = format!("{name} = {value}");
                let len = line.len();
                Some(Location::new(SourceFile::new("--set", line), 0..len))
            }
        }
    }

    /// A configuration error at `key` of this table.
    pub fn error_at(&self, key: &str, message: impl Into<String>) -> Error {
        let message = format!("[{}] {}: {}", self.path_string(), key, message.into());
        match (self.overridden, self.location_of(Some(key))) {
            (false, Some(loc)) => Error::config_at(loc, message),
            _ => Error::config(message),
        }
    }
}

/// A deserialiser's message in the words of a pipeline's reader, not of Rust: `usize`
/// is "a whole number", `f64` "a number", and so on.
pub fn plain(message: &str) -> String {
    const WORDS: &[(&str, &str)] = &[
        ("expected usize", "expected a whole number (0 or more)"),
        ("expected u64", "expected a whole number (0 or more)"),
        ("expected u32", "expected a whole number (0 or more)"),
        ("expected u16", "expected a whole number (0 or more)"),
        ("expected u8", "expected a whole number (0 or more)"),
        ("expected i64", "expected a whole number"),
        ("expected i32", "expected a whole number"),
        ("expected isize", "expected a whole number"),
        ("expected f64", "expected a number"),
        ("expected f32", "expected a number"),
        ("expected a boolean", "expected true or false"),
        ("invalid type: floating point", "got the decimal number"),
        ("invalid type: integer", "got the whole number"),
        ("invalid type: string", "got the string"),
        ("invalid type: boolean", "got"),
        ("invalid type: sequence", "got an array"),
        ("invalid type: map", "got a table"),
        ("invalid type: unit variant", "got a value of the wrong kind"),
    ];
    let mut out = message.to_string();
    for (from, to) in WORDS {
        out = out.replace(from, to);
    }
    out
}

/// The value at `path` in a parsed document, copied out of it (only that value is
/// copied, not the document).
pub fn navigate_de<'i>(doc: &Spanned<DeTable<'i>>, path: &[PathElem]) -> Option<Spanned<DeValue<'i>>> {
    let Some((first, rest)) = path.split_first() else {
        return Some(Spanned::new(doc.span(), DeValue::Table(doc.get_ref().clone())));
    };
    let PathElem::Key(k) = first else {
        return None;
    };
    let mut cur = find_key(doc.get_ref(), k)?;
    for elem in rest {
        cur = match (cur.get_ref(), elem) {
            (DeValue::Table(t), PathElem::Key(k)) => find_key(t, k)?,
            (DeValue::Array(a), PathElem::Index(i)) => a.get(*i)?,
            _ => return None,
        };
    }
    Some(cur.clone())
}

fn find_key<'a, 'i>(t: &'a DeTable<'i>, k: &str) -> Option<&'a Spanned<DeValue<'i>>> {
    t.iter()
        .find(|(kk, _)| kk.get_ref().as_ref() == k)
        .map(|(_, v)| v)
}

/// Converts a TOML syntax or type error of the whole file into a located error.
pub fn toml_error(file: &Arc<SourceFile>, e: &toml::de::Error) -> Error {
    Error::Config {
        location: e.span().map(|s| Location::new(file.clone(), s)),
        message: e.message().trim().to_string(),
        help: None,
    }
}
