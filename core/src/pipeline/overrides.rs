//! `--set TABLE.KEY=VALUE` overrides, parsed and applied on top of a pipeline file.

use crate::error::{Error, Result};

use super::table::*;

/// A `--set TABLE.KEY=VALUE` override.
#[derive(Debug, Clone, PartialEq)]
pub struct Override {
    pub path: Vec<PathElem>,
    pub value: toml::Value,
}

/// Most parts of a `--set` path.
const MAX_SET_DEPTH: usize = 16;

impl std::str::FromStr for Override {
    type Err = Error;

    /// `slice.thickness=0.3`, `parts.0.grade.use="xy"`; a value that is not valid TOML
    /// is taken as a string.
    fn from_str(s: &str) -> Result<Self> {
        let (path, value) = s
            .split_once('=')
            .ok_or_else(|| Error::config(format!("--set {s}: expected TABLE.KEY=VALUE")))?;
        // No pipeline nests tables this deep; a longer path would only build a
        // tower of tables that overflows the stack when it is dropped.
        if path.split('.').count() > MAX_SET_DEPTH {
            return Err(Error::config(format!(
                "--set: the path has more than {MAX_SET_DEPTH} parts"
            )));
        }
        let path: Vec<PathElem> = path
            .trim()
            .split('.')
            .map(|p| match p.parse::<usize>() {
                Ok(i) => PathElem::Index(i),
                Err(_) => key(p.trim()),
            })
            .collect();
        if path.iter().any(|p| matches!(p, PathElem::Key(k) if k.is_empty())) {
            return Err(Error::config(format!("--set {s}: empty key in path")));
        }
        let value = value.trim();
        let value = toml::from_str::<toml::Table>(&format!("v = {value}"))
            .ok()
            .and_then(|mut t| t.remove("v"))
            .unwrap_or_else(|| toml::Value::String(value.to_string()));
        Ok(Override { path, value })
    }
}

impl Override {
    pub(super) fn apply(&self, root: &mut toml::Value) -> Result<()> {
        let err = |m: &str| {
            let p: Vec<String> = self.path.iter().map(ToString::to_string).collect();
            Error::config(format!("--set {}: {m}", p.join(".")))
        };
        let (last, init) = self.path.split_last().ok_or_else(|| err("empty path"))?;
        let mut cur = root;
        for elem in init {
            cur = match (cur, elem) {
                (toml::Value::Table(t), PathElem::Key(k)) => t
                    .entry(k.clone())
                    .or_insert_with(|| toml::Value::Table(toml::Table::new())),
                (toml::Value::Array(a), PathElem::Index(i)) => {
                    a.get_mut(*i).ok_or_else(|| err("index out of range"))?
                }
                _ => return Err(err("path does not lead to a table")),
            };
        }
        match (cur, last) {
            (toml::Value::Table(t), PathElem::Key(k)) => {
                t.insert(k.clone(), self.value.clone());
            }
            (toml::Value::Array(a), PathElem::Index(i)) => {
                *a.get_mut(*i).ok_or_else(|| err("index out of range"))? = self.value.clone();
            }
            _ => return Err(err("path does not lead to a table")),
        }
        Ok(())
    }
}

/// Whether `a` is a prefix of `b` or `b` of `a`.
pub(super) fn paths_touch(a: &[PathElem], b: &[PathElem]) -> bool {
    a.iter().zip(b).all(|(x, y)| x == y)
}
