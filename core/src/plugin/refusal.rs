//! How the host says it refuses a library: an error naming the file, with the
//! loader's own reasons.

use std::path::Path;

use crate::error::Error;

/// The error refusing the library at `path`.
pub(super) fn refuse(path: &Path, message: impl Into<String>) -> Error {
    Error::Plugin {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

/// An error and its sources, `a: b: c`: the loader's own reason is in the source.
pub(super) fn chain(e: &dyn std::error::Error) -> String {
    let mut out = e.to_string();
    let mut cur = e.source();
    while let Some(s) = cur {
        let s_text = s.to_string();
        if !out.contains(&s_text) {
            out = format!("{out}: {s_text}");
        }
        cur = s.source();
    }
    out
}
