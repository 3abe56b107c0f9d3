//! Output files that appear under their final names only when a run succeeds: each is
//! written to a temporary file beside its destination and renamed at the end, so a
//! failed or killed run leaves nothing half-written under a final name.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Component, Path, PathBuf};

use tempfile::TempPath;

use crate::error::{Error, Result};
use crate::stage::OutputFiles;
pub use lamina_api::text::one_line;

/// Temporary outputs are named `.lamina-<pid>-<random>.partial`: the process id tells
/// a later run which are left over from a run that was killed.
const PARTIAL_PREFIX: &str = ".lamina-";

/// Most entries [`remove_stale`] looks at in one output folder tree: an output folder
/// is no place for a million files, and the search must not cost more than the run.
const STALE_SEARCH_ENTRIES: usize = 100_000;

/// Removes the temporary files of runs that are no longer running anywhere under `dir`
/// (a killed run leaves its partial outputs behind, in whatever subfolder they were
/// being written; a run still writing keeps its own). Links are not followed.
fn remove_stale(dir: &Path) {
    let mut folders = vec![dir.to_path_buf()];
    let mut seen = 0;
    while let Some(folder) = folders.pop() {
        let Ok(entries) = std::fs::read_dir(&folder) else {
            continue;
        };
        for entry in entries.flatten() {
            seen += 1;
            if seen > STALE_SEARCH_ENTRIES {
                return;
            }
            let Ok(kind) = entry.file_type() else { continue };
            if kind.is_dir() {
                folders.push(entry.path());
            } else if kind.is_file() && stale(&entry.file_name()) {
                let _ = std::fs::remove_file(entry.path());
            }
        }
    }
}

/// Whether `name` is a temporary output of a process that no longer runs.
fn stale(name: &std::ffi::OsStr) -> bool {
    let Some(name) = name.to_str() else { return false };
    let Some(rest) = name.strip_prefix(PARTIAL_PREFIX) else {
        return false;
    };
    if !name.ends_with(".partial") {
        return false;
    }
    let Some(pid) = rest.split('-').next().and_then(|p| p.parse::<u32>().ok()) else {
        return false;
    };
    pid != std::process::id() && !process_alive(pid)
}

/// The temporary outputs and the folders made for them that this process holds, so
/// that a signal that ends it can remove them ([`abandon`]).
struct Live {
    files: Vec<PathBuf>,
    folders: Vec<PathBuf>,
    /// Set by [`abandon`]: the process is ending, and no new temporary file may stay.
    abandoned: bool,
}

static LIVE: std::sync::Mutex<Live> = std::sync::Mutex::new(Live {
    files: Vec::new(),
    folders: Vec::new(),
    abandoned: false,
});

fn live() -> std::sync::MutexGuard<'static, Live> {
    LIVE.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// Removes every temporary output of this process and the (empty) folders made for
/// them, for a process that a signal ends: call it, then exit without returning. The
/// lock stays held, so that no thread of the run creates or commits a file after it.
pub fn abandon() {
    let mut live = live();
    live.abandoned = true;
    for file in &live.files {
        let _ = std::fs::remove_file(file);
    }
    for folder in live.folders.iter().rev() {
        let _ = std::fs::remove_dir(folder);
    }
    live.files.clear();
    std::mem::forget(live);
}

/// Whether process `pid` runs (Linux: its `/proc` entry; elsewhere assumed alive, so
/// nothing is removed).
fn process_alive(pid: u32) -> bool {
    if cfg!(target_os = "linux") {
        Path::new("/proc").join(pid.to_string()).exists()
    } else {
        true
    }
}

/// The outputs of one run, in one folder.
#[derive(Debug)]
pub struct AtomicOutputs {
    dir: PathBuf,
    pending: Vec<(TempPath, PathBuf)>,
    reports: Vec<crate::stage::MachineFileReport>,
    /// What exporters told of their files, in the order they told it.
    told: Vec<lamina_api::Diagnostic>,
    /// Folders this run created, outermost first: a run that fails removes them again
    /// where they are empty, so it leaves nothing behind.
    made: Vec<PathBuf>,
    /// Whether the output folder was searched for the leftovers of killed runs.
    searched: bool,
}

impl Drop for AtomicOutputs {
    fn drop(&mut self) {
        // The temporary files go first (dropping them deletes them), then the folders
        // made for them, innermost first; one that holds anything else stays.
        let mut live = live();
        for (temp, _) in &self.pending {
            live.files.retain(|f| f.as_path() != &**temp);
        }
        live.folders.retain(|f| !self.made.contains(f));
        self.pending.clear();
        for dir in self.made.iter().rev() {
            let _ = std::fs::remove_dir(dir);
        }
    }
}

impl AtomicOutputs {
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        Self {
            dir: dir.into(),
            pending: Vec::new(),
            reports: Vec::new(),
            told: Vec::new(),
            made: Vec::new(),
            searched: false,
        }
    }

    /// What the machine files of the run said of themselves, in the order they said it.
    pub fn take_reports(&mut self) -> Vec<crate::stage::MachineFileReport> {
        std::mem::take(&mut self.reports)
    }

    /// What exporters told of their files ([`OutputFiles::tell`]), as diagnostics of
    /// the export stage whose message starts with the file's name.
    pub fn take_told(&mut self) -> Vec<lamina_api::Diagnostic> {
        std::mem::take(&mut self.told)
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
        // Whatever can be known to fail is checked before the first rename, so that a
        // run does not end with some of its outputs committed and others not.
        for (_, dest) in &self.pending {
            if dest.is_dir() {
                return Err(Error::config(format!(
                    "output `{}` is a folder: name a file",
                    dest.display()
                )));
            }
        }
        let mut done = Vec::new();
        let mut this = self;
        // Under the lock: a signal that ends the process finds each file either still
        // temporary (and removes it) or committed.
        let mut live = live();
        if live.abandoned {
            return Err(Error::config("the run was interrupted"));
        }
        // Committed: the folders hold the outputs and stay.
        live.folders.retain(|f| !this.made.contains(f));
        this.made.clear();
        for (temp, dest) in std::mem::take(&mut this.pending) {
            live.files.retain(|f| f.as_path() != &*temp);
            temp.persist(&dest).map_err(|e| Error::io(&dest, e.error))?;
            done.push(dest);
        }
        Ok(done)
    }
}

impl OutputFiles for AtomicOutputs {
    fn report(&mut self, report: crate::stage::MachineFileReport) {
        self.reports.push(report);
    }

    fn tell(&mut self, file: &Path, severity: lamina_api::Severity, said: lamina_api::Warning) {
        self.told.push(lamina_api::Diagnostic::new(
            severity,
            lamina_api::kind::StageKind::Export,
            said.code.as_str(),
            format!("{}: {}", file.display(), said.message),
        ));
    }

    fn create(&mut self, name: &Path) -> Result<Box<dyn Write + Send>> {
        check_name(name).map_err(Error::config)?;
        if name.is_absolute() || name.components().any(|c| matches!(c, Component::ParentDir)) {
            return Err(Error::config(format!(
                "output path `{}` must be relative and stay inside the output folder",
                name.display()
            )));
        }
        if name.file_name().is_none() || name.components().all(|c| matches!(c, Component::CurDir)) {
            return Err(Error::config(format!(
                "output path `{}` must name a file inside the output folder",
                name.display()
            )));
        }
        let dest = self.dir.join(name);
        if self.pending.iter().any(|(_, d)| d == &dest) {
            return Err(Error::config(format!("two outputs write `{}`", dest.display())));
        }
        let parent = dest.parent().unwrap_or(&self.dir).to_path_buf();
        let missing: Vec<PathBuf> = parent
            .ancestors()
            .take_while(|a| !a.as_os_str().is_empty() && !a.exists())
            .map(Path::to_path_buf)
            .collect();
        let mut live = live();
        if live.abandoned {
            return Err(Error::config("the run was interrupted"));
        }
        std::fs::create_dir_all(&parent).map_err(|e| Error::io(&parent, e))?;
        live.folders.extend(missing.iter().rev().cloned());
        self.made.extend(missing.into_iter().rev());
        // A link inside the output folder must not lead the file out of it.
        if let (Ok(root), Ok(real)) = (self.dir.canonicalize(), parent.canonicalize())
            && !real.starts_with(&root)
        {
            return Err(Error::config(format!(
                "output path `{}` leads out of the output folder (through a link to `{}`)",
                name.display(),
                real.display()
            )));
        }
        if !self.searched {
            self.searched = true;
            remove_stale(&self.dir);
        }
        let mut builder = tempfile::Builder::new();
        let prefix = format!("{PARTIAL_PREFIX}{}-", std::process::id());
        builder.prefix(&prefix).suffix(".partial");
        // Temporary files are private by default; outputs are ordinary files.
        #[cfg(unix)]
        builder.permissions(std::os::unix::fs::PermissionsExt::from_mode(0o644));
        let temp = builder.tempfile_in(&parent).map_err(|e| Error::io(&parent, e))?;
        let (file, path): (File, TempPath) = temp.into_parts();
        live.files.push(path.to_path_buf());
        self.pending.push((path, dest));
        Ok(Box::new(BufWriter::with_capacity(1 << 16, file)))
    }

    fn written(&self) -> Vec<(PathBuf, PathBuf)> {
        self.pending
            .iter()
            .filter_map(|(temp, dest)| {
                let name = dest.strip_prefix(&self.dir).ok()?;
                Some((name.to_path_buf(), temp.to_path_buf()))
            })
            .collect()
    }
}

/// Longest name of one file or folder, in bytes: the limit of ext4, XFS, btrfs and
/// APFS (255), below NTFS's 255 UTF-16 units for any name that fits it.
pub const NAME_MAX: usize = 255;

/// Checks what no file system would take in an output's path: a NUL, or a file or
/// folder name longer than [`NAME_MAX`] bytes. Checked when the pipeline is read and
/// again when the file is created, so that a run never writes some outputs and then
/// fails on the name of the next.
pub fn check_name(name: &Path) -> std::result::Result<(), String> {
    let text = name.to_string_lossy();
    if text.contains('\0') {
        return Err(format!(
            "output path `{}` holds a NUL character",
            text.replace('\0', "\\0")
        ));
    }
    for c in name.components() {
        let part = c.as_os_str();
        if part.len() > NAME_MAX {
            return Err(format!(
                "output path `{}`: a name of {} bytes, longer than the {NAME_MAX} a file system takes",
                one_line(&text),
                part.len()
            ));
        }
    }
    Ok(())
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

    #[test]
    fn paths_that_name_no_file_or_lead_out_are_refused() {
        let dir = tempfile::tempdir().expect("tempdir");
        let mut out = AtomicOutputs::new(dir.path());
        for bad in ["", ".", "./", "../x.json", "/tmp/x.json"] {
            assert!(out.create(Path::new(bad)).is_err(), "{bad:?}");
        }
        #[cfg(unix)]
        {
            let outside = tempfile::tempdir().expect("tempdir");
            std::os::unix::fs::symlink(outside.path(), dir.path().join("link")).expect("symlink");
            let e = out.create(Path::new("link/x.json")).err().expect("refused");
            assert!(e.to_string().contains("leads out"), "{e}");
            assert_eq!(std::fs::read_dir(outside.path()).expect("list").count(), 0);
        }
    }

    #[test]
    fn nothing_is_committed_when_an_output_is_a_folder() {
        let dir = tempfile::tempdir().expect("tempdir");
        std::fs::create_dir(dir.path().join("b.json")).expect("mkdir");
        let mut out = AtomicOutputs::new(dir.path());
        drop(out.create(Path::new("a.json")).expect("create"));
        drop(out.create(Path::new("b.json")).expect("create"));
        assert!(out.commit().is_err());
        assert!(!dir.path().join("a.json").exists());
    }

    #[test]
    fn partial_files_of_dead_runs_are_removed_by_the_next() {
        let dir = tempfile::tempdir().expect("tempdir");
        // No process has this id (beyond Linux's pid_max).
        let stale = dir.path().join(".lamina-4194399-abc.partial");
        std::fs::write(&stale, b"left over").expect("write");
        let mine = dir
            .path()
            .join(format!(".lamina-{}-keep.partial", std::process::id()));
        std::fs::write(&mine, b"in progress").expect("write");
        let mut out = AtomicOutputs::new(dir.path());
        drop(out.create(Path::new("a.json")).expect("create"));
        if cfg!(target_os = "linux") {
            assert!(!stale.exists());
        }
        assert!(mine.exists());
    }
}
