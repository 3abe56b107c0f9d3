//! Source files (pipelines, scripts) and byte spans inside them, so every error that
//! comes from user input can say file, line and column.

use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::{Arc, OnceLock};

use toml::Spanned;
use toml::de::DeTable;

/// A text file the user wrote: a pipeline or a Rhai script. Kept whole so errors can
/// quote the offending line.
pub struct SourceFile {
    pub path: PathBuf,
    pub text: String,
    /// The text read as a TOML document with spans, once: every table of a pipeline
    /// deserialises from its part of this tree, so a file of N tables is read once,
    /// not N times.
    toml: OnceLock<SpannedToml>,
}

self_cell::self_cell!(
    /// A copy of the text and its span-carrying TOML tree (`None` when it does not parse).
    struct SpannedToml {
        owner: String,
        #[covariant]
        dependent: SpannedDoc,
    }
);

type SpannedDoc<'a> = Option<Spanned<DeTable<'a>>>;

impl fmt::Debug for SourceFile {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("SourceFile")
            .field("path", &self.path)
            .field("text", &self.text)
            .finish()
    }
}

impl Clone for SourceFile {
    fn clone(&self) -> Self {
        Self {
            path: self.path.clone(),
            text: self.text.clone(),
            toml: OnceLock::new(),
        }
    }
}

impl PartialEq for SourceFile {
    fn eq(&self, other: &Self) -> bool {
        self.path == other.path && self.text == other.text
    }
}

impl Eq for SourceFile {}

impl SourceFile {
    pub fn new(path: impl Into<PathBuf>, text: impl Into<String>) -> Arc<Self> {
        Arc::new(Self {
            path: path.into(),
            text: text.into(),
            toml: OnceLock::new(),
        })
    }

    /// The text as a TOML document with spans, parsed on first use; `None` when it is
    /// not valid TOML.
    pub fn toml(&self) -> Option<&Spanned<DeTable<'_>>> {
        self.toml
            .get_or_init(|| SpannedToml::new(self.text.clone(), |text| DeTable::parse(text).ok()))
            .borrow_dependent()
            .as_ref()
    }

    /// Reads a text file of at most [`MAX_TEXT_BYTES`] (see [`read_regular`]); the
    /// error names the path.
    pub fn read(path: &Path) -> crate::Result<Arc<Self>> {
        let io = |e| crate::Error::Io {
            path: path.to_path_buf(),
            source: e,
        };
        let bytes = read_regular(path, MAX_TEXT_BYTES).map_err(io)?;
        let text = String::from_utf8(bytes)
            .map_err(|e| io(std::io::Error::new(std::io::ErrorKind::InvalidData, e)))?;
        Ok(Self::new(path, text))
    }

    /// 1-based line and column (in characters) of a byte offset.
    pub fn line_col(&self, offset: usize) -> (usize, usize) {
        let offset = offset.min(self.text.len());
        let before = &self.text[..floor_char_boundary(&self.text, offset)];
        let line = before.matches('\n').count() + 1;
        let line_start = before.rfind('\n').map_or(0, |i| i + 1);
        let col = before[line_start..].chars().count() + 1;
        (line, col)
    }

    /// Byte offset of a 1-based line and column, clamped to the text.
    pub fn offset_of(&self, line: usize, col: usize) -> usize {
        let mut offset = 0;
        for (i, l) in self.text.split_inclusive('\n').enumerate() {
            if i + 1 == line {
                let in_line: usize = l
                    .char_indices()
                    .nth(col.saturating_sub(1))
                    .map_or(l.len(), |(b, _)| b);
                return offset + in_line;
            }
            offset += l.len();
        }
        self.text.len()
    }
}

fn floor_char_boundary(s: &str, mut i: usize) -> usize {
    while i > 0 && !s.is_char_boundary(i) {
        i -= 1;
    }
    i
}

/// A byte range in a [`SourceFile`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Span {
    pub start: usize,
    pub end: usize,
}

impl From<std::ops::Range<usize>> for Span {
    fn from(r: std::ops::Range<usize>) -> Self {
        Self {
            start: r.start,
            end: r.end,
        }
    }
}

/// A place in a user's file: the file, the span and its line/column for display.
#[derive(Debug, Clone)]
pub struct Location {
    pub file: Arc<SourceFile>,
    pub span: Span,
}

impl Location {
    pub fn new(file: Arc<SourceFile>, span: impl Into<Span>) -> Self {
        Self {
            file,
            span: span.into(),
        }
    }

    pub fn line_col(&self) -> (usize, usize) {
        self.file.line_col(self.span.start)
    }
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (line, col) = self.line_col();
        write!(f, "{}:{}:{}", self.file.path.display(), line, col)
    }
}

/// Largest text file read (a pipeline, a machine profile or cell, a script): far above
/// any real one, and what a mistaken or hostile path cannot make the process hold.
pub const MAX_TEXT_BYTES: u64 = 16 << 20;

/// Reads the regular file `path`, at most `cap` bytes. A device, a FIFO or a folder
/// named where a file belongs is refused before it is opened (reading `/dev/zero`
/// would fill the memory, a FIFO would never end), and a file larger than `cap`, or
/// growing past it while read, is refused too.
pub fn read_regular(path: &Path, cap: u64) -> std::io::Result<Vec<u8>> {
    use std::io::{Error, ErrorKind, Read};
    regular_file(path)?;
    let file = std::fs::File::open(path)?;
    let len = file.metadata()?.len();
    let too_large = |n: u64| {
        Error::new(
            ErrorKind::InvalidData,
            format!("{n} bytes or more, more than the {cap} read"),
        )
    };
    if len > cap {
        return Err(too_large(len));
    }
    let mut bytes = Vec::with_capacity(len as usize);
    file.take(cap.saturating_add(1)).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > cap {
        return Err(too_large(bytes.len() as u64));
    }
    Ok(bytes)
}

/// The size of the regular file `path` (links followed); anything else is an error
/// saying what it is.
pub fn regular_file(path: &Path) -> std::io::Result<u64> {
    let meta = std::fs::metadata(path)?;
    if meta.is_file() {
        return Ok(meta.len());
    }
    let what = if meta.is_dir() {
        "a folder"
    } else {
        "not a regular file (a device, a FIFO or a socket)"
    };
    Err(std::io::Error::new(
        std::io::ErrorKind::InvalidInput,
        format!("it is {what}"),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn line_and_column_are_one_based() {
        let f = SourceFile::new("p.toml", "a = 1\nbé = 2\n");
        assert_eq!(f.line_col(0), (1, 1));
        assert_eq!(f.line_col(6), (2, 1));
        assert_eq!(f.line_col(9), (2, 3));
        assert_eq!(f.offset_of(2, 3), 9);
    }
}
