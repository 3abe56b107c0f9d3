//! A pipeline table as it crosses the boundary: its values as TOML text, with the file
//! and path its errors point at.

use super::{WireStep, WireTable, file_of};
use crate::error::{Error, Result};
use crate::source::SourceFile;
use crate::table::{MODEL_HOST_KEYS, PathElem, TableRef};

impl TableRef {
    /// The table as a message to a dynamic plugin.
    #[doc(hidden)]
    pub fn to_wire(&self) -> Result<WireTable<'_>> {
        Ok(WireTable {
            file: file_of(&self.file),
            path: self
                .path
                .iter()
                .map(|p| match p {
                    PathElem::Key(k) => WireStep::Key(k.clone()),
                    PathElem::Index(i) => WireStep::Index(*i),
                })
                .collect(),
            values: toml::to_string(&self.table)
                .map_err(|e| Error::config(format!("[{}] cannot be written out: {e}", self.path_string())))?,
            overridden: self.overridden,
            host_keys: self.host_keys.iter().map(ToString::to_string).collect(),
        })
    }

    /// A table a host sent to this dynamic plugin.
    #[doc(hidden)]
    pub fn from_wire(w: WireTable<'_>) -> Result<Self> {
        let file = SourceFile::new(w.file.path.into_owned(), w.file.text.into_owned());
        let table: toml::Table = toml::from_str(&w.values)
            .map_err(|e| Error::config(format!("a table the host sent is not TOML: {e}")))?;
        // The host's keys are one of a few lists; an unknown one is kept for good.
        let known: [&'static [&'static str]; 3] = [&[], &["use"], MODEL_HOST_KEYS];
        let host_keys = known
            .into_iter()
            .find(|k| k.iter().copied().eq(w.host_keys.iter().map(String::as_str)))
            .unwrap_or_else(|| {
                let keys: Vec<&'static str> = w
                    .host_keys
                    .into_iter()
                    .map(|k| &*Box::leak(k.into_boxed_str()))
                    .collect();
                Box::leak(keys.into_boxed_slice())
            });
        Ok(Self {
            table,
            file,
            path: w
                .path
                .into_iter()
                .map(|p| match p {
                    WireStep::Key(k) => PathElem::Key(k),
                    WireStep::Index(i) => PathElem::Index(i),
                })
                .collect(),
            overridden: w.overridden,
            host_keys,
            // Keys renamed in the file are the host's own tables' (`[limits]`); a stage's
            // options carry their former names themselves (`#[formerly]`).
            renamed: &[],
        })
    }
}
