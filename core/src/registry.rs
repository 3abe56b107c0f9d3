//! The registry of named stage factories: `(kind, name) -> build(table)`. Built-in and
//! linked plugins register with `inventory`; dynamic plugins hand their factories over
//! when loaded (see [`crate::plugin`]).

use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::pipeline::TableRef;
use crate::script::ScriptHost;
use crate::stage::{AnyStage, PipelineContext, StageConfig, StageInfo, StageKind, StageType};

pub use lamina_api::registry::{DefaultStage, StageFactory};

/// Where a factory came from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Origin {
    /// Linked into this program.
    Linked,
    /// Loaded from a dynamic library.
    Dynamic { path: PathBuf, plugin: String },
}

/// A factory in the registry.
#[derive(Debug, Clone)]
pub struct Registered {
    pub factory: &'static StageFactory,
    pub origin: Origin,
    /// For dynamic plugins: the library and stage number that build it.
    remote: Option<crate::plugin::host::RemoteFactory>,
}

impl Registered {
    pub fn info(&self) -> &StageInfo {
        &self.factory.info
    }

    /// `kind:name`, for messages.
    pub fn label(&self) -> String {
        format!("{}:{}", self.factory.info.kind, self.factory.info.name)
    }
}

/// All stage factories known to a run.
#[derive(Debug, Default, Clone)]
pub struct Registry {
    entries: Vec<Registered>,
    /// `(kind, stage)`: the defaults the linked plugins declare.
    defaults: Vec<(StageKind, &'static str)>,
}

impl Registry {
    /// An empty registry.
    pub fn new() -> Self {
        Self::default()
    }

    /// Every factory linked into this program (built-in plugins and linked third-party
    /// crates).
    pub fn linked() -> Result<Self> {
        let mut r = Self::new();
        for f in inventory::iter::<StageFactory> {
            r.add(f, Origin::Linked)?;
        }
        for d in inventory::iter::<DefaultStage> {
            r.set_default(d.kind, d.name)?;
        }
        Ok(r)
    }

    /// Makes `name` the default `kind` stage; a second, different default for one kind
    /// is refused, naming both.
    pub fn set_default(&mut self, kind: StageKind, name: &'static str) -> Result<()> {
        match self.defaults.iter().find(|(k, _)| *k == kind) {
            Some((_, existing)) if *existing != name => Err(Error::config(format!(
                "two linked plugins declare the default {kind} stage: `{existing}` and `{name}`"
            ))),
            Some(_) => Ok(()),
            None => {
                self.defaults.push((kind, name));
                Ok(())
            }
        }
    }

    /// Takes `other`'s default stages for the kinds it has one: a registry of loaded
    /// stages gets the program's defaults for the kinds a pipeline leaves out, as
    /// `lamina` gives them.
    pub fn adopt_defaults(&mut self, other: &Registry) -> Result<()> {
        for &(kind, name) in &other.defaults {
            self.set_default(kind, name)?;
        }
        Ok(())
    }

    /// The default stage of `kind`, if a plugin declared one.
    pub fn default_for(&self, kind: StageKind) -> Option<&'static str> {
        self.defaults.iter().find(|(k, _)| *k == kind).map(|(_, n)| *n)
    }

    /// Adds a factory; a second factory with the same kind and name is refused.
    pub fn add(&mut self, factory: &'static StageFactory, origin: Origin) -> Result<()> {
        self.insert(factory, origin, None)
    }

    /// Adds a stage of a dynamic plugin, built by its library.
    pub(crate) fn add_dynamic(
        &mut self,
        factory: &'static StageFactory,
        origin: Origin,
        remote: crate::plugin::host::RemoteFactory,
    ) -> Result<()> {
        self.insert(factory, origin, Some(remote))
    }

    fn insert(
        &mut self,
        factory: &'static StageFactory,
        origin: Origin,
        remote: Option<crate::plugin::host::RemoteFactory>,
    ) -> Result<()> {
        if let Some(existing) = self.get(factory.info.kind, factory.info.name) {
            let describe = |o: &Origin| match o {
                Origin::Linked => "built in".to_string(),
                Origin::Dynamic { path, .. } => path.display().to_string(),
            };
            return Err(Error::Plugin {
                path: match &origin {
                    Origin::Dynamic { path, .. } => path.clone(),
                    Origin::Linked => PathBuf::from("<linked>"),
                },
                message: format!(
                    "a {} stage named `{}` exists already ({})",
                    factory.info.kind,
                    factory.info.name,
                    describe(&existing.origin)
                ),
            });
        }
        self.entries.push(Registered {
            factory,
            origin,
            remote,
        });
        Ok(())
    }

    pub fn get(&self, kind: StageKind, name: &str) -> Option<&Registered> {
        self.entries
            .iter()
            .find(|e| e.factory.info.kind == kind && e.factory.info.name == name)
    }

    /// Factories of one kind (or all), sorted by kind then name.
    pub fn list(&self, kind: Option<StageKind>) -> Vec<&Registered> {
        let mut v: Vec<_> = self
            .entries
            .iter()
            .filter(|e| kind.is_none_or(|k| e.factory.info.kind == k))
            .collect();
        v.sort_by_key(|e| (e.factory.info.kind, e.factory.info.name));
        v
    }

    fn names(&self, kind: StageKind) -> String {
        self.list(Some(kind))
            .iter()
            .map(|e| e.factory.info.name)
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// Builds the stage a table names with `use = "..."`, as its trait:
    /// `registry.build::<dyn Grader>(..)`.
    pub fn build<S: StageType + ?Sized>(
        &self,
        table: &TableRef,
        scripts: &ScriptHost,
        base_dir: &Path,
    ) -> Result<Box<S>> {
        self.build_for::<S>(table, scripts, base_dir, PipelineContext::default())
    }

    /// [`Registry::build`] for a pipeline whose machine and limits the stage may consult
    /// (and check its options against).
    pub fn build_for<S: StageType + ?Sized>(
        &self,
        table: &TableRef,
        scripts: &ScriptHost,
        base_dir: &Path,
        context: PipelineContext<'_>,
    ) -> Result<Box<S>> {
        self.build_any_for(S::KIND, table, scripts, base_dir, context)?
            .into_type()
    }

    /// Builds the stage of kind `kind` a table names with `use = "..."`, whatever its
    /// kind: for callers that choose the kind at run time.
    pub fn build_any(
        &self,
        kind: StageKind,
        table: &TableRef,
        scripts: &ScriptHost,
        base_dir: &Path,
    ) -> Result<AnyStage> {
        self.build_any_for(kind, table, scripts, base_dir, PipelineContext::default())
    }

    /// [`Registry::build_any`] for a pipeline's context.
    pub fn build_any_for(
        &self,
        kind: StageKind,
        table: &TableRef,
        scripts: &ScriptHost,
        base_dir: &Path,
        context: PipelineContext<'_>,
    ) -> Result<AnyStage> {
        let name = match table.get("use") {
            Some(toml::Value::String(s)) => s.as_str(),
            Some(_) => return Err(table.error_at("use", "must be a string naming the stage")),
            None => {
                return Err(table
                    .error_at("use", format!("missing: which {kind} stage to use?"))
                    .with_help(format!("available: {}", self.names(kind))));
            }
        };
        let entry = self.get(kind, name).ok_or_else(|| {
            table
                .error_at("use", format!("no {kind} stage named `{name}`"))
                .with_help(format!("available: {}", self.names(kind)))
        })?;
        self.build_entry_for(entry, table, scripts, base_dir, context)
    }

    /// Builds a stage from a given registry entry.
    pub fn build_entry(
        &self,
        entry: &Registered,
        table: &TableRef,
        scripts: &ScriptHost,
        base_dir: &Path,
    ) -> Result<AnyStage> {
        self.build_entry_for(entry, table, scripts, base_dir, PipelineContext::default())
    }

    /// Builds a stage from a given registry entry for a pipeline's context.
    pub fn build_entry_for(
        &self,
        entry: &Registered,
        table: &TableRef,
        scripts: &ScriptHost,
        base_dir: &Path,
        context: PipelineContext<'_>,
    ) -> Result<AnyStage> {
        // Without the pipeline's reach, a stage reads from `base_dir` only.
        let folder;
        let reach = match context.reach {
            Some(r) => r,
            None => {
                folder = crate::reach::Reach::folder(base_dir);
                &folder
            }
        };
        let config = StageConfig {
            table,
            scripts,
            base_dir,
            reach,
            machine: context.machine,
            limits: context.limits,
        };
        let stage = match (&entry.origin, &entry.remote) {
            (Origin::Dynamic { plugin, .. }, Some(remote)) => crate::plugin::host::build(
                remote,
                entry.factory.info.kind,
                &format!("{plugin}/{}", entry.label()),
                &config,
            )?,
            _ => (entry.factory.build)(&config)?,
        };
        if stage.kind() != entry.factory.info.kind {
            return Err(Error::stage(
                entry.label(),
                format!("factory built a {} stage", stage.kind()),
            ));
        }
        Ok(stage)
    }
}
