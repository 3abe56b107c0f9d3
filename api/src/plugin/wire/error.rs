//! Errors and places in users' files as they cross the boundary: an error keeps its
//! kind, its place (with the file's text) and its help on the other side.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use crate::error::Error;
use crate::limits::Limit;
use crate::source::{Location, SourceFile};

/// A place in a user's file, with the file's text so that the receiver can show it.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct WireLocation {
    pub path: PathBuf,
    pub text: String,
    pub start: usize,
    pub end: usize,
}

impl From<&Location> for WireLocation {
    fn from(l: &Location) -> Self {
        Self {
            path: l.file.path.clone(),
            text: l.file.text.clone(),
            start: l.span.start,
            end: l.span.end,
        }
    }
}

impl From<WireLocation> for Location {
    /// A place the other side sent: its span is kept inside the text and on character
    /// boundaries, whatever the numbers say.
    fn from(l: WireLocation) -> Self {
        let floor = |mut i: usize| {
            i = i.min(l.text.len());
            while !l.text.is_char_boundary(i) {
                i -= 1;
            }
            i
        };
        let start = floor(l.start);
        let end = floor(l.end.max(start));
        Location::new(SourceFile::new(l.path, l.text), start..end)
    }
}

/// An [`Error`] as data.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub enum WireError {
    Io {
        path: PathBuf,
        message: String,
    },
    Config {
        location: Option<WireLocation>,
        message: String,
        help: Option<String>,
    },
    Script {
        location: Option<WireLocation>,
        message: String,
        context: Option<String>,
    },
    Model {
        path: PathBuf,
        message: String,
    },
    Plugin {
        path: PathBuf,
        message: String,
    },
    Panic {
        stage: String,
        message: String,
    },
    Limit {
        what: String,
        needed: String,
        key: String,
        allowed: u64,
    },
    Stage {
        stage: String,
        message: String,
    },
    Composition(String),
    Layer {
        index: usize,
        z: f64,
        source: Box<WireError>,
    },
    Part {
        part: String,
        source: Box<WireError>,
    },
}

impl From<&Error> for WireError {
    fn from(e: &Error) -> Self {
        let at = |l: &Option<Location>| l.as_ref().map(WireLocation::from);
        match e {
            Error::Io { path, source } => WireError::Io {
                path: path.clone(),
                message: source.to_string(),
            },
            Error::Config {
                location,
                message,
                help,
            } => WireError::Config {
                location: at(location),
                message: message.clone(),
                help: help.clone(),
            },
            Error::Script {
                location,
                message,
                context,
            } => WireError::Script {
                location: at(location),
                message: message.clone(),
                context: context.clone(),
            },
            Error::Model { path, message } => WireError::Model {
                path: path.clone(),
                message: message.clone(),
            },
            Error::Plugin { path, message } => WireError::Plugin {
                path: path.clone(),
                message: message.clone(),
            },
            Error::Panic { stage, message } => WireError::Panic {
                stage: stage.clone(),
                message: message.clone(),
            },
            Error::Limit {
                what,
                needed,
                key,
                allowed,
            } => WireError::Limit {
                what: what.clone(),
                needed: needed.clone(),
                key: key.to_string(),
                allowed: *allowed,
            },
            Error::Stage { stage, message } => WireError::Stage {
                stage: stage.clone(),
                message: message.clone(),
            },
            Error::Composition(m) => WireError::Composition(m.clone()),
            Error::Layer { index, z, source } => WireError::Layer {
                index: *index,
                z: *z,
                source: Box::new(WireError::from(&**source)),
            },
            Error::Part { part, source } => WireError::Part {
                part: part.clone(),
                source: Box::new(WireError::from(&**source)),
            },
            // Only a whole pipeline's build gathers several; one stage call answers
            // with one, so the first stands for them on the wire.
            Error::Several(all) => match all.first() {
                Some(first) => WireError::from(first),
                None => WireError::Stage {
                    stage: "runtime".into(),
                    message: e.to_string(),
                },
            },
        }
    }
}

impl From<WireError> for Error {
    fn from(e: WireError) -> Self {
        match e {
            WireError::Io { path, message } => Error::Io {
                path,
                source: std::io::Error::other(message),
            },
            WireError::Config {
                location,
                message,
                help,
            } => Error::Config {
                location: location.map(Location::from),
                message,
                help,
            },
            WireError::Script {
                location,
                message,
                context,
            } => Error::Script {
                location: location.map(Location::from),
                message,
                context,
            },
            WireError::Model { path, message } => Error::Model { path, message },
            WireError::Plugin { path, message } => Error::Plugin { path, message },
            WireError::Panic { stage, message } => Error::Panic { stage, message },
            WireError::Limit {
                what,
                needed,
                key,
                allowed,
            } => match Limit::ALL.into_iter().find(|l| l.key() == key) {
                Some(limit) => Error::Limit {
                    what,
                    needed,
                    key: limit.key(),
                    allowed,
                },
                None => Error::stage(
                    what,
                    format!("needs {needed}, more than the limit `limits.{key}` = {allowed}"),
                ),
            },
            WireError::Stage { stage, message } => Error::Stage { stage, message },
            WireError::Composition(m) => Error::Composition(m),
            WireError::Layer { index, z, source } => Error::Layer {
                index,
                z,
                source: Box::new(Error::from(*source)),
            },
            WireError::Part { part, source } => Error::Part {
                part,
                source: Box::new(Error::from(*source)),
            },
        }
    }
}
