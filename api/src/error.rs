//! The error type of lamina-core and of the stages built on it. Every variant that comes
//! from user input carries where it came from: a file path, a TOML span, a Rhai position,
//! a layer.

use std::path::PathBuf;

use crate::source::Location;

pub type Result<T, E = Error> = std::result::Result<T, E>;

#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A file could not be read or written.
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },

    /// The pipeline (or a `--set` override) is wrong: unknown key, wrong type, bad value.
    #[error("{}{message}", location_prefix(location))]
    Config {
        location: Option<Location>,
        message: String,
        help: Option<String>,
    },

    /// A Rhai script failed to compile, failed at run time, or returned a bad value.
    #[error("{}{message}{}", location_prefix(location), context_suffix(context))]
    Script {
        /// Script file, or the pipeline file holding an inline expression.
        location: Option<Location>,
        message: String,
        /// What was being computed: layer, part, region.
        context: Option<String>,
    },

    /// A mesh or other input model is malformed.
    #[error("{}: {message}", path.display())]
    Model { path: PathBuf, message: String },

    /// A dynamic plugin could not be loaded or was refused.
    #[error("plugin {}: {message}", path.display())]
    Plugin { path: PathBuf, message: String },

    /// A stage panicked; the panic was caught at the plugin boundary.
    #[error("stage `{stage}` panicked: {message}")]
    Panic { stage: String, message: String },

    /// Input or options would need more of a resource than the run allows.
    #[error(
        "{what} needs {needed}, more than the limit `limits.{key}` = {allowed} (raise it in the pipeline's [limits] table if this is meant)"
    )]
    Limit {
        what: String,
        needed: String,
        key: &'static str,
        allowed: u64,
    },

    /// A stage failed for a reason of its own.
    #[error("{stage}: {message}")]
    Stage { stage: String, message: String },

    /// Volume fractions outside [0, 1] or not summing to 1.
    #[error("invalid composition: {0}")]
    Composition(String),

    /// An error while processing one layer.
    #[error("layer {index} (z = {z:.4} mm): {source}")]
    Layer {
        index: usize,
        z: f64,
        #[source]
        source: Box<Error>,
    },

    /// An error while processing one part.
    #[error("part `{part}`: {source}")]
    Part {
        part: String,
        #[source]
        source: Box<Error>,
    },

    /// Several independent errors found in one pass (every wrong stage of a
    /// pipeline, as `lamina check` reports them), in the order they were found.
    #[error("{} errors; the first: {}", .0.len(), .0.first().map(ToString::to_string).unwrap_or_default())]
    Several(Vec<Error>),
}

fn location_prefix(location: &Option<Location>) -> String {
    location.as_ref().map(|l| format!("{l}: ")).unwrap_or_default()
}

fn context_suffix(context: &Option<String>) -> String {
    context
        .as_ref()
        .map(|c| format!(" (while grading {c})"))
        .unwrap_or_default()
}

impl Error {
    /// This error, if a script's, as having happened while computing `context` (a
    /// batch of script calls describes only the call that failed); any other error is
    /// returned as it is.
    pub fn in_context(self, context: String) -> Error {
        match self {
            Error::Script {
                location, message, ..
            } => Error::Script {
                location,
                message,
                context: Some(context),
            },
            other => other,
        }
    }

    /// `errors` as one error: the error itself when there is one, [`Error::Several`]
    /// when there are more; `None` when there are none.
    /// Errors with a place come first, in the order of their places in the files.
    pub fn gathered(mut errors: Vec<Error>) -> Option<Error> {
        errors.sort_by(|a, b| match (a.location(), b.location()) {
            (Some(x), Some(y)) => (&x.file.path, x.span.start).cmp(&(&y.file.path, y.span.start)),
            (Some(_), None) => std::cmp::Ordering::Less,
            (None, Some(_)) => std::cmp::Ordering::Greater,
            (None, None) => std::cmp::Ordering::Equal,
        });
        match errors.len() {
            0 => None,
            1 => errors.pop(),
            _ => Some(Error::Several(errors)),
        }
    }

    /// A configuration error without a known place (the caller may add one).
    pub fn config(message: impl Into<String>) -> Self {
        Error::Config {
            location: None,
            message: message.into(),
            help: None,
        }
    }

    /// A configuration error at a place in a user's file.
    pub fn config_at(location: Location, message: impl Into<String>) -> Self {
        Error::Config {
            location: Some(location),
            message: message.into(),
            help: None,
        }
    }

    /// A stage failure, named by the stage.
    pub fn stage(stage: impl Into<String>, message: impl Into<String>) -> Self {
        Error::Stage {
            stage: stage.into(),
            message: message.into(),
        }
    }

    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            source,
        }
    }

    /// Adds a help line to a configuration error.
    pub fn with_help(mut self, text: impl Into<String>) -> Self {
        if let Error::Config { help, .. } = &mut self {
            *help = Some(text.into());
        }
        self
    }

    /// Wraps the error with the layer it happened in.
    pub fn in_layer(self, index: usize, z: f64) -> Self {
        Error::Layer {
            index,
            z,
            source: Box::new(self),
        }
    }

    /// Wraps the error with the part it happened in.
    pub fn in_part(self, part: &str) -> Self {
        Error::Part {
            part: part.to_string(),
            source: Box::new(self),
        }
    }

    /// True when the error is in what the user asked for (pipeline, options, scripts
    /// that do not compile, refused plugins) rather than in running it: the CLI exits
    /// with code 2 for these.
    pub fn is_usage(&self) -> bool {
        match self {
            Error::Config { .. } | Error::Plugin { .. } => true,
            Error::Several(all) => all.iter().all(Error::is_usage),
            Error::Layer { source, .. } | Error::Part { source, .. } => source.is_usage(),
            _ => false,
        }
    }

    /// The innermost place in a user's file this error points at, if any.
    pub fn location(&self) -> Option<&Location> {
        match self {
            Error::Config { location, .. } | Error::Script { location, .. } => location.as_ref(),
            Error::Layer { source, .. } | Error::Part { source, .. } => source.location(),
            Error::Several(all) => all.first().and_then(Error::location),
            _ => None,
        }
    }

    /// The help line, if any.
    pub fn help(&self) -> Option<&str> {
        match self {
            Error::Config { help, .. } => help.as_deref(),
            Error::Layer { source, .. } | Error::Part { source, .. } => source.help(),
            Error::Several(all) => all.first().and_then(Error::help),
            _ => None,
        }
    }
}
