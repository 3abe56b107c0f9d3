//! The host's side of dynamic plugins: loading a library after inspecting its file,
//! and the proxies that call its stages (`host`). The boundary itself (C types,
//! messages, the plugin's side) is `lamina_api::plugin`.

mod child;
pub(crate) mod host;
mod inspect;
mod library;
mod refusal;

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

pub use child::{ChildProgram, Isolation, serve as serve_child};
pub use inspect::inspect;
pub use lamina_api::plugin::*;

use crate::error::Result;
use crate::registry::{Origin, Registry, StageFactory};
use library::open_library;
use refusal::refuse;

/// Libraries loaded so far, by canonical path and whether they run apart, with their
/// stages. Kept for the life of the process: nothing is ever unloaded. (A child
/// process that stopped is started again by the next load.)
static LOADED: Mutex<Vec<LoadedPlugin>> = Mutex::new(Vec::new());

#[derive(Debug, Clone)]
struct LoadedPlugin {
    path: PathBuf,
    apart: bool,
    library: Arc<host::Library>,
    stages: Vec<(&'static StageFactory, host::RemoteFactory)>,
}

/// Loads a plugin library into this process and adds its stages to `registry`.
/// Loading the same file twice adds its stages once per registry.
pub fn load(registry: &mut Registry, path: &Path) -> Result<String> {
    load_with(registry, path, &Isolation::InProcess)
}

/// [`load`], with the library's code running where `isolation` says.
pub fn load_with(registry: &mut Registry, path: &Path, isolation: &Isolation) -> Result<String> {
    let canonical = path
        .canonicalize()
        .map_err(|e| refuse(path, format!("cannot open: {e}")))?;
    let apart = matches!(isolation, Isolation::Child(_));
    let mut loaded = LOADED.lock().unwrap_or_else(|e| e.into_inner());
    loaded.retain(|p| p.library.stopped().is_none());
    let plugin = match loaded.iter().find(|p| p.path == canonical && p.apart == apart) {
        Some(p) => p.clone(),
        None => {
            let p = match isolation {
                Isolation::InProcess => open(&canonical)?,
                Isolation::Child(program) => open_apart(&canonical, program)?,
            };
            loaded.push(p.clone());
            p
        }
    };
    drop(loaded);
    for (factory, remote) in &plugin.stages {
        registry.add_dynamic(
            factory,
            Origin::Dynamic {
                path: canonical.clone(),
                plugin: plugin.library.name.clone(),
            },
            remote.clone(),
        )?;
    }
    Ok(plugin.library.name.clone())
}

fn open(path: &Path) -> Result<LoadedPlugin> {
    let library = open_library(path, false)?;
    let stages = library.describe()?;
    Ok(LoadedPlugin {
        path: path.to_path_buf(),
        apart: false,
        library,
        stages,
    })
}

/// Starts a child process that loads the library, after the same inspection: a file
/// that is no plugin of this host is refused before any process runs it.
fn open_apart(path: &Path, program: &ChildProgram) -> Result<LoadedPlugin> {
    let entry = inspect::entry_symbol(path, true)?;
    let (link, name) = child::Link::spawn(program, path)?;
    let library = Arc::new(host::Library::child(path, name, entry.minor, link));
    let stages = library.describe()?;
    Ok(LoadedPlugin {
        path: path.to_path_buf(),
        apart: true,
        library,
        stages,
    })
}

/// Adds the stages linked into this program to `registry` as if a plugin library named
/// `name` held them: every call goes through the boundary (messages, handles, the
/// host's services) without a library file. For tests of the boundary: a pipeline run
/// this way must give what the linked stages give.
pub fn add_linked_through_boundary(registry: &mut Registry, name: &'static str) -> Result<()> {
    add_linked_through_boundary_as(registry, name, abi::ABI_MINOR)
}

/// [`add_linked_through_boundary`], the host taking the plugin for one of ABI minor
/// `minor`: it is sent only the requests of that minor, as an older plugin would be.
#[doc(hidden)]
pub fn add_linked_through_boundary_as(registry: &mut Registry, name: &'static str, minor: u32) -> Result<()> {
    let descriptor: &'static StaticDescriptor = Box::leak(Box::new(StaticDescriptor::new(name)));
    let path = PathBuf::from(format!("<{name}>"));
    // SAFETY: the descriptor is this copy's own, leaked for the life of the process.
    let mut library = unsafe { host::Library::new(&path, descriptor.get()) }?;
    library.minor = minor.min(library.minor);
    let library = Arc::new(library);
    for (factory, remote) in library.describe()? {
        registry.add_dynamic(
            factory,
            Origin::Dynamic {
                path: path.clone(),
                plugin: name.to_string(),
            },
            remote,
        )?;
    }
    Ok(())
}
