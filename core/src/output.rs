//! Output files that appear under their final names only when a run succeeds: each is
//! written to a temporary file beside its destination and renamed at the end, so a
//! failed or killed run leaves nothing half-written under a final name.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Component, Path, PathBuf};

use tempfile::TempPath;

use crate::error::{Error, Result};
use crate::stage::OutputFiles;

/// The outputs of one run, in one folder.
#[derive(Debug)]
pub struct AtomicOutputs {
    dir: PathBuf,
    pending: Vec<(TempPath, PathBuf)>,
}

impl AtomicOutputs {
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        Self {
            dir: dir.into(),
            pending: Vec::new(),
        }
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Final paths of the files created so far.
    pub fn paths(&self) -> Vec<PathBuf> {
        self.pending.iter().map(|(_, p)| p.clone()).collect()
    }

    /// Renames every temporary file to its final name. Call after all writers were
    /// flushed and dropped.
    pub fn commit(self) -> Result<Vec<PathBuf>> {
        let mut done = Vec::new();
        for (temp, dest) in self.pending {
            temp.persist(&dest).map_err(|e| Error::io(&dest, e.error))?;
            done.push(dest);
        }
        Ok(done)
    }
}

impl OutputFiles for AtomicOutputs {
    fn create(&mut self, name: &Path) -> Result<Box<dyn Write + Send>> {
        if name.is_absolute() || name.components().any(|c| matches!(c, Component::ParentDir)) {
            return Err(Error::config(format!(
                "output path `{}` must be relative and stay inside the output folder",
                name.display()
            )));
        }
        let dest = self.dir.join(name);
        if self.pending.iter().any(|(_, d)| d == &dest) {
            return Err(Error::config(format!("two outputs write `{}`", dest.display())));
        }
        let parent = dest.parent().unwrap_or(&self.dir).to_path_buf();
        std::fs::create_dir_all(&parent).map_err(|e| Error::io(&parent, e))?;
        let mut builder = tempfile::Builder::new();
        builder.prefix(".lamina-").suffix(".partial");
        // Temporary files are private by default; outputs are ordinary files.
        #[cfg(unix)]
        builder.permissions(std::os::unix::fs::PermissionsExt::from_mode(0o644));
        let temp = builder.tempfile_in(&parent).map_err(|e| Error::io(&parent, e))?;
        let (file, path): (File, TempPath) = temp.into_parts();
        self.pending.push((path, dest));
        Ok(Box::new(BufWriter::with_capacity(1 << 16, file)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn files_appear_only_on_commit() {
        let dir = tempfile::tempdir().expect("tempdir");
        let mut out = AtomicOutputs::new(dir.path());
        let mut w = out.create(Path::new("a/b.txt")).expect("create");
        w.write_all(b"hello").expect("write");
        drop(w);
        assert!(!dir.path().join("a/b.txt").exists());
        out.commit().expect("commit");
        assert_eq!(std::fs::read(dir.path().join("a/b.txt")).expect("read"), b"hello");
    }

    #[test]
    fn dropped_outputs_leave_nothing() {
        let dir = tempfile::tempdir().expect("tempdir");
        let mut out = AtomicOutputs::new(dir.path());
        let mut w = out.create(Path::new("x.txt")).expect("create");
        w.write_all(b"partial").expect("write");
        drop(w);
        drop(out);
        assert_eq!(std::fs::read_dir(dir.path()).expect("list").count(), 0);
    }

    #[test]
    fn escaping_paths_are_refused() {
        let dir = tempfile::tempdir().expect("tempdir");
        let mut out = AtomicOutputs::new(dir.path());
        assert!(out.create(Path::new("../x")).is_err());
    }
}
