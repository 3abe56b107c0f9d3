//! `lamina new-plugin`: writes a plugin crate that builds with one `cargo build`, loads
//! with `--plugin`, and tests its stage with `lamina-test-support`, linked and loaded
//! through the real loader.
//!
//! The crate depends on `lamina-api` and `lamina-test-support` by version, with the lock
//! file Lamina itself is built and tested with. `--lamina PATH` adds a `[patch]` table
//! that takes them from a local checkout instead (until they are published, that is
//! how a plugin builds); nothing else names a folder of the machine.

use std::path::PathBuf;

use lamina_core::{Error, Result, StageKind};

/// The kinds a template exists for, with the trait their stage implements.
const KINDS: &[(StageKind, &str, &str)] = &[
    (StageKind::Grade, "Grader", include_str!("scaffold/grade.rs.in")),
    (
        StageKind::Discretise,
        "Discretiser",
        include_str!("scaffold/discretise.rs.in"),
    ),
    (
        StageKind::Export,
        "Exporter",
        include_str!("scaffold/export.rs.in"),
    ),
    (
        StageKind::Model,
        "ModelSource",
        include_str!("scaffold/model.rs.in"),
    ),
    (StageKind::Plan, "Planner", include_str!("scaffold/plan.rs.in")),
    (
        StageKind::Process,
        "Process",
        include_str!("scaffold/process.rs.in"),
    ),
    (
        StageKind::Orient,
        "Orienter",
        include_str!("scaffold/orient.rs.in"),
    ),
    (StageKind::Sort, "Sorter", include_str!("scaffold/sort.rs.in")),
    (StageKind::Slice, "Slicer", include_str!("scaffold/slice.rs.in")),
    (
        StageKind::Sequence,
        "Sequencer",
        include_str!("scaffold/sequence.rs.in"),
    ),
];

/// What to write.
#[derive(Debug)]
pub struct Request {
    /// The stage's name, which is also the crate's.
    pub name: String,
    pub kind: StageKind,
    /// The crate's folder (must not exist).
    pub dir: PathBuf,
    /// A checkout of Lamina's source to take its crates from (holding `api/` and
    /// `test-support/`), if any.
    pub lamina: Option<PathBuf>,
}

fn usage(message: impl Into<String>) -> Error {
    Error::config(message)
}

impl Request {
    pub fn new(name: &str, kind: &str, dir: Option<PathBuf>, lamina: Option<PathBuf>) -> Result<Self> {
        let valid = name.chars().next().is_some_and(|c| c.is_ascii_lowercase())
            && name
                .chars()
                .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '-' || c == '_')
            && name.len() <= 64;
        if !valid {
            return Err(usage(format!(
                "`{name}` cannot name a plugin: use lower-case letters, digits, `-` and `_`, starting with a letter"
            )));
        }
        let kinds = || KINDS.iter().map(|k| k.0.name()).collect::<Vec<_>>().join(", ");
        let kind = StageKind::parse(kind)
            .filter(|k| KINDS.iter().any(|t| t.0 == *k))
            .ok_or_else(|| {
                usage(format!("no plugin template for `{kind}`: it is not a stage kind")).with_help(format!(
                    "kinds: {}; plugins/zigzag in Lamina's source is another planner and process stage to start from",
                    kinds()
                ))
            })?;
        let dir = dir.unwrap_or_else(|| PathBuf::from(name));
        if dir.exists() {
            return Err(usage(format!(
                "{} exists already: choose another --dir",
                dir.display()
            )));
        }
        let lamina = match lamina {
            None => None,
            Some(lamina) => {
                let lamina = lamina
                    .canonicalize()
                    .map_err(|e| usage(format!("Lamina's source folder {}: {e}", lamina.display())))?;
                for part in ["api/Cargo.toml", "test-support/Cargo.toml"] {
                    if !lamina.join(part).is_file() {
                        return Err(usage(format!(
                            "{} is not Lamina's source folder (it has no {part})",
                            lamina.display()
                        ))
                        .with_help("give the folder of Lamina's source with --lamina PATH"));
                    }
                }
                Some(lamina)
            }
        };
        Ok(Self {
            name: name.to_string(),
            kind,
            dir,
            lamina,
        })
    }

    /// The library's name, as Rust and the linker see it.
    fn lib(&self) -> String {
        self.name.replace('-', "_")
    }

    fn fill(&self, template: &str) -> String {
        let (_, trait_name, _) = KINDS
            .iter()
            .find(|k| k.0 == self.kind)
            .copied()
            .unwrap_or(KINDS[0]);
        template
            .replace("{{crate}}", &self.name)
            .replace("{{name}}", &self.name)
            .replace("{{lib}}", &self.lib())
            .replace("{{kind}}", self.kind.name())
            .replace("{{trait}}", trait_name)
            .replace(
                "{{dylib}}",
                &format!(
                    "{}{}{}",
                    std::env::consts::DLL_PREFIX,
                    self.lib(),
                    std::env::consts::DLL_SUFFIX
                ),
            )
            .replace("{{version}}", lamina_core::VERSION)
            .replace("{{patch}}", &self.patch())
    }

    /// The `[patch]` table that takes Lamina's crates from the checkout `--lamina`
    /// names; nothing without one.
    fn patch(&self) -> String {
        let Some(lamina) = &self.lamina else {
            return String::new();
        };
        let path = |p: &str| toml::Value::String(lamina.join(p).to_string_lossy().into_owned()).to_string();
        format!(
            "\n# Lamina's crates from a local checkout (`lamina new-plugin --lamina PATH`) rather than\n\
             # a registry; remove this table to build against published releases.\n\
             [patch.crates-io]\nlamina-api = {{ path = {} }}\nlamina-test-support = {{ path = {} }}\n",
            path("api"),
            path("test-support")
        )
    }

    /// A pipeline that runs the stage's example on a tube.
    fn pipeline(&self) -> String {
        let example = match self.kind {
            StageKind::Grade => format!("use = \"{}\"\nto_z = 2.0", self.name),
            StageKind::Discretise => format!("use = \"{}\"\nlevel = 0.5", self.name),
            StageKind::Export => format!("use = \"{}\"\npath = \"regions.csv\"", self.name),
            StageKind::Plan => format!("use = \"{}\"\nwidth = 0.45", self.name),
            StageKind::Process => format!("use = \"{}\"\nfeed = 12.0", self.name),
            StageKind::Orient | StageKind::Sort => format!("use = \"{}\"", self.name),
            StageKind::Slice => format!("use = \"{}\"\nthickness = 0.5", self.name),
            StageKind::Sequence => format!("use = \"{}\"\ndefault_thickness = 0.5", self.name),
            _ => format!("use = \"{}\"\nsize = [10.0, 6.0, 2.0]", self.name),
        };
        let mut text = format!(
            "# Runs the `{name}` stage: lamina run pipeline.toml --plugin target/debug/{prefix}{lib}{suffix}\nname = \"{name}-example\"\n\n",
            name = self.name,
            prefix = std::env::consts::DLL_PREFIX,
            lib = self.lib(),
            suffix = std::env::consts::DLL_SUFFIX
        );
        let model = match self.kind {
            StageKind::Model => example.clone(),
            // A box standing on its end, for the orienter to lay down.
            StageKind::Orient => "use = \"box\"\nsize = [2.0, 6.0, 10.0]".to_string(),
            _ => "use = \"tube\"\nheight = 2.0".to_string(),
        };
        let slice = match self.kind {
            StageKind::Slice => example.clone(),
            // Layers where the sequence puts them.
            StageKind::Sequence => "use = \"adaptive\"".to_string(),
            _ => "use = \"uniform\"\nthickness = 0.5".to_string(),
        };
        text.push_str(&format!(
            "[model]\n{model}\n\n[materials.red]\ncolour = [255, 0, 0]\n[materials.green]\ncolour = [0, 255, 0]\n\n[slice]\n{slice}\n\n"
        ));
        if matches!(
            self.kind,
            StageKind::Orient | StageKind::Sort | StageKind::Sequence
        ) {
            text.push_str(&format!("[{}]\n{example}\n\n", self.kind));
        }
        if self.kind == StageKind::Discretise {
            text.push_str(&format!("[discretise]\n{example}\n\n"));
        }
        if self.kind == StageKind::Grade {
            text.push_str(&format!("[grade]\n{example}\n\n"));
        } else {
            text.push_str("[grade]\nuse = \"z\"\nf = \"linear\"\nfrom_layer = 0\nto_layer = 3\n\n");
        }
        if self.kind == StageKind::Plan {
            text.push_str(&format!("[plan]\n{example}\n\n"));
        }
        if self.kind == StageKind::Process {
            text.push_str(&format!("[[process]]\n{example}\n\n"));
        }
        if self.kind == StageKind::Export {
            text.push_str(&format!("[[output]]\n{example}\n"));
        } else {
            text.push_str("[[output]]\nuse = \"json\"\npath = \"plan.json\"\n");
        }
        text
    }

    /// The crate's files, relative to its folder.
    fn files(&self) -> Vec<(&'static str, String)> {
        let (_, _, source) = KINDS
            .iter()
            .find(|k| k.0 == self.kind)
            .copied()
            .unwrap_or(KINDS[0]);
        vec![
            ("Cargo.toml", self.fill(include_str!("scaffold/Cargo.toml.in"))),
            ("src/lib.rs", self.fill(source)),
            (
                "tests/examples.rs",
                self.fill(include_str!("scaffold/tests.rs.in")),
            ),
            ("pipeline.toml", self.pipeline()),
            ("README.md", self.fill(include_str!("scaffold/README.md.in"))),
            // The releases Lamina is built and tested with: the first build resolves
            // nothing anew (cargo drops what the crate does not use).
            ("Cargo.lock", include_str!("../Cargo.lock").to_string()),
            (".gitignore", "/target\n".to_string()),
        ]
    }

    /// Writes the crate into a temporary folder beside `dir`, then renames it: either
    /// the whole crate appears or nothing does.
    pub fn write(&self) -> Result<Vec<PathBuf>> {
        let parent = match self.dir.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        std::fs::create_dir_all(&parent).map_err(|e| Error::io(&parent, e))?;
        let staging = tempfile::Builder::new()
            .prefix(".lamina-new-plugin-")
            .tempdir_in(&parent)
            .map_err(|e| Error::io(&parent, e))?;
        let mut written = Vec::new();
        for (name, text) in self.files() {
            let path = staging.path().join(name);
            if let Some(folder) = path.parent() {
                std::fs::create_dir_all(folder).map_err(|e| Error::io(folder, e))?;
            }
            std::fs::write(&path, text).map_err(|e| Error::io(&path, e))?;
            written.push(self.dir.join(name));
        }
        let staged = staging.keep();
        std::fs::rename(&staged, &self.dir).map_err(|e| {
            let _ = std::fs::remove_dir_all(&staged);
            Error::io(&self.dir, e)
        })?;
        Ok(written)
    }
}
