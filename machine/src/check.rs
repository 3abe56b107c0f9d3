//! Checks of a merged machine profile's values, each error placed where the layer
//! that wrote the key wrote it.

use std::collections::BTreeMap;

use super::raw::RawAxes;
use super::template::{Template, TemplateKind};
use super::*;
use lamina_api::error::{Error, Result};
use lamina_api::source::Location;

/// Errors at the place each merged key was written.
pub(super) struct Check<'a> {
    pub(super) locations: &'a BTreeMap<String, Location>,
    pub(super) root: Option<Location>,
    pub(super) label: String,
}

impl Check<'_> {
    /// An error at `path`, or at the nearest enclosing key that is written, or at the
    /// profile itself.
    pub(super) fn err(&self, path: &str, message: impl Into<String>) -> Error {
        let mut p = path;
        let location = loop {
            if let Some(l) = self.locations.get(p) {
                break Some(l.clone());
            }
            match p.rsplit_once('.') {
                Some((head, _)) => p = head,
                None => break self.root.clone(),
            }
        };
        config(location, format!("{}: {path}: {}", self.label, message.into()))
    }

    pub(super) fn required<T>(&self, v: Option<T>, path: &str, what: &str) -> Result<T> {
        v.ok_or_else(|| self.err(path, format!("missing: {what}")))
    }

    pub(super) fn within(&self, v: f64, lo: f64, hi: f64, path: &str, unit: &str) -> Result<f64> {
        if v.is_finite() && (lo..=hi).contains(&v) {
            Ok(v)
        } else {
            Err(self.err(path, format!("must lie in {lo}..={hi} {unit}, not {v}")))
        }
    }

    /// Per-axis values, each within `lo..=hi` (in `unit`).
    pub(super) fn axes(&self, a: RawAxes, path: &str, lo: f64, hi: f64, unit: &str) -> Result<Axes> {
        let get = |v: Option<f64>, k: &str| -> Result<f64> {
            let p = format!("{path}.{k}");
            self.within(
                self.required(v, &p, "a value for every axis x, y, z, e")?,
                lo,
                hi,
                &p,
                unit,
            )
        };
        Ok(Axes {
            x: get(a.x, "x")?,
            y: get(a.y, "y")?,
            z: get(a.z, "z")?,
            e: get(a.e, "e")?,
        })
    }

    pub(super) fn template(
        &self,
        text: Option<String>,
        path: &str,
        kind: TemplateKind,
        tools: usize,
    ) -> Result<Template> {
        let t = Template::new(text.unwrap_or_default());
        t.check(kind, tools).map_err(|e| self.err(path, e.message))?;
        Ok(t)
    }
}

/// A configuration error at `location`, or placed nowhere when no file wrote it.
pub(super) fn config(location: Option<Location>, message: String) -> Error {
    Error::Config {
        location,
        message,
        help: None,
    }
}
