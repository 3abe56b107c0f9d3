//! Where the files a pipeline names may be read from.
//!
//! A pipeline file is untrusted data: it may come with a model from anywhere. The
//! files it names (models, machine profiles and their bases, machining cells, Rhai
//! scripts) are read only inside its own folder and the run's output folder, after
//! links are followed, so that `machine = "/home/me/.netrc.toml"` or a `.rhai` link to
//! a system file is neither read nor quoted in an error. The command line widens the
//! reach (`--allow DIR`, and the file `--model` names); nothing in a pipeline can.

use std::io::{Error, ErrorKind};
use std::path::{Component, Path, PathBuf};

use serde::{Deserialize, Serialize};

/// The folders (or single files) that files named by a pipeline may lie in.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Reach {
    /// Canonical paths when they exist; `None` reaches everywhere.
    roots: Option<Vec<PathBuf>>,
}

impl Reach {
    /// The pipeline's folder `dir`, and nothing else.
    pub fn folder(dir: &Path) -> Reach {
        let mut reach = Reach {
            roots: Some(Vec::new()),
        };
        reach.allow(dir);
        reach
    }

    /// Every file: for programs that build pipelines themselves, and for built-in
    /// profiles' tests, never for a pipeline read from a file.
    pub fn anywhere() -> Reach {
        Reach { roots: None }
    }

    /// Adds a folder (everything under it) or a single file.
    pub fn allow(&mut self, path: &Path) {
        if let Some(roots) = &mut self.roots {
            let root = resolved(path);
            if !roots.contains(&root) {
                roots.push(root);
            }
        }
    }

    /// [`allow`](Self::allow)ed, for building.
    pub fn with(mut self, paths: impl IntoIterator<Item = impl AsRef<Path>>) -> Reach {
        for p in paths {
            self.allow(p.as_ref());
        }
        self
    }

    /// The canonical path of `path` when it lies within reach (links followed); an
    /// error of kind `PermissionDenied` saying where a pipeline may read otherwise, or
    /// the error that finding the file gave.
    pub fn check(&self, path: &Path) -> std::io::Result<PathBuf> {
        let real = path.canonicalize()?;
        let Some(roots) = &self.roots else {
            return Ok(real);
        };
        if roots.iter().any(|r| real.starts_with(r)) {
            return Ok(real);
        }
        let listed = roots
            .iter()
            .map(|r| r.display().to_string())
            .collect::<Vec<_>>()
            .join(", ");
        let linked = if real != normalised(path) {
            format!(" (it leads to {})", real.display())
        } else {
            String::new()
        };
        Err(Error::new(
            ErrorKind::PermissionDenied,
            format!(
                "it lies outside what the pipeline may read{linked}: {listed}; a pipeline \
                 reads files only in its own folder and the output folder, and \
                 `--allow <folder>` on the command line adds one"
            ),
        ))
    }

    /// [`check`](Self::check), then [`read_regular`](crate::source::read_regular).
    pub fn read(&self, path: &Path, cap: u64) -> std::io::Result<Vec<u8>> {
        crate::source::read_regular(&self.check(path)?, cap)
    }

    /// [`read`](Self::read) as UTF-8 text of at most
    /// [`MAX_TEXT_BYTES`](crate::source::MAX_TEXT_BYTES).
    pub fn read_text(&self, path: &Path) -> std::io::Result<String> {
        let bytes = self.read(path, crate::source::MAX_TEXT_BYTES)?;
        String::from_utf8(bytes).map_err(|e| Error::new(ErrorKind::InvalidData, e))
    }
}

/// `path` canonical as far as it exists: a root that does not exist yet (an output
/// folder) keeps its missing tail as written, after its existing ancestor's links.
fn resolved(path: &Path) -> PathBuf {
    let path = normalised(path);
    let mut tail = Vec::new();
    let mut head = path.as_path();
    loop {
        if let Ok(real) = head.canonicalize() {
            return tail.iter().rev().fold(real, |p, c| p.join(c));
        }
        match (head.parent(), head.file_name()) {
            (Some(parent), Some(name)) => {
                tail.push(name.to_os_string());
                head = parent;
            }
            _ => return path,
        }
    }
}

/// `path` made absolute and rid of `.` and `..` without touching the file system.
fn normalised(path: &Path) -> PathBuf {
    let absolute = if path.is_absolute() {
        path.to_path_buf()
    } else {
        std::env::current_dir()
            .map(|d| d.join(path))
            .unwrap_or_else(|_| path.to_path_buf())
    };
    let mut out = PathBuf::new();
    for c in absolute.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                out.pop();
            }
            other => out.push(other),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn files_under_the_folder_are_in_reach_and_links_out_of_it_are_not() {
        let dir = tempfile::tempdir().expect("tempdir");
        let inside = dir.path().join("in");
        let outside = dir.path().join("out");
        std::fs::create_dir_all(inside.join("sub")).expect("mkdir");
        std::fs::create_dir_all(&outside).expect("mkdir");
        std::fs::write(inside.join("sub/a.toml"), "a").expect("write");
        std::fs::write(outside.join("secret.toml"), "token = 1").expect("write");
        let reach = Reach::folder(&inside);
        assert!(reach.check(&inside.join("sub/a.toml")).is_ok());
        assert!(reach.check(&inside.join("sub/../sub/a.toml")).is_ok());
        let err = reach
            .check(&inside.join("../out/secret.toml"))
            .expect_err("outside");
        assert_eq!(err.kind(), ErrorKind::PermissionDenied);
        assert!(err.to_string().contains("--allow"), "{err}");
        #[cfg(unix)]
        {
            std::os::unix::fs::symlink(outside.join("secret.toml"), inside.join("link.toml")).expect("link");
            let err = reach.check(&inside.join("link.toml")).expect_err("a link out");
            assert!(err.to_string().contains("it leads to"), "{err}");
            assert!(reach.read_text(&inside.join("link.toml")).is_err());
        }
        // The command line widens it, to a folder or one file.
        let wider = reach.clone().with([outside.join("secret.toml")]);
        assert_eq!(
            wider.read_text(&outside.join("secret.toml")).expect("allowed"),
            "token = 1"
        );
        assert!(Reach::anywhere().check(&outside.join("secret.toml")).is_ok());
    }

    #[test]
    fn a_root_that_does_not_exist_yet_is_kept_as_written() {
        let dir = tempfile::tempdir().expect("tempdir");
        let out = dir.path().join("later/../out");
        let reach = Reach::folder(dir.path()).with([&out]);
        std::fs::create_dir_all(dir.path().join("out")).expect("mkdir");
        std::fs::write(dir.path().join("out/x"), "x").expect("write");
        assert!(reach.check(&dir.path().join("out/x")).is_ok());
    }
}
