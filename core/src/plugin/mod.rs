//! The host's side of dynamic plugins: loading a library after inspecting its file,
//! and the proxies that call its stages (`host`). The boundary itself (C types,
//! messages, the plugin's side) is `lamina_api::plugin`.

mod child;
pub(crate) mod host;
mod inspect;

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

pub use child::{ChildProgram, Isolation, serve as serve_child};
pub use inspect::inspect;
pub use lamina_api::plugin::*;

use crate::error::{Error, Result};
use crate::registry::{Origin, Registry, StageFactory};

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

fn refuse(path: &Path, message: impl Into<String>) -> Error {
    Error::Plugin {
        path: path.to_path_buf(),
        message: message.into(),
    }
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

/// An error and its sources, `a: b: c`: the loader's own reason is in the source.
fn chain(e: &dyn std::error::Error) -> String {
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

/// Loads a library into this process once its file, entry and descriptor check out.
/// One that runs `apart` (in a child process serving a host) may abort on panics.
fn open_library(path: &Path, apart: bool) -> Result<Arc<host::Library>> {
    let entry_symbol = inspect::entry_symbol(path, apart)?.symbol;
    // SAFETY: loading a library runs its initialisers; plugins are code the user chose
    // to run, like the pipeline that names them, and the file was inspected first.
    let lib = unsafe { libloading::Library::new(path) }
        .map_err(|e| refuse(path, format!("cannot load library: {}", chain(&e))))?;
    let symbol = format!("{entry_symbol}\0");
    // SAFETY: the symbol has the signature `export_plugin!` gives it, as the ABI note
    // the file carries says.
    let entry: abi::EntryFn = unsafe { lib.get::<abi::EntryFn>(symbol.as_bytes()) }
        .map(|s| *s)
        .map_err(|e| refuse(path, format!("cannot find `{entry_symbol}`: {}", chain(&e))))?;
    // SAFETY: the entry only returns the address of a static.
    let ptr = unsafe { entry() };
    if ptr.is_null() {
        return Err(refuse(path, "the plugin's entry point returned no descriptor"));
    }
    // SAFETY: every Lamina descriptor starts with the frozen prefix.
    let prefix = unsafe { std::ptr::read(ptr.cast::<abi::DescriptorPrefix>()) };
    inspect::check_descriptor(path, &entry_symbol[ENTRY_PREFIX.len()..], &prefix)?;
    // SAFETY: magic, ABI, size and layout checked: the full descriptor is there, in a
    // static of a library that is never unloaded.
    let library = Arc::new(unsafe { host::Library::new(path, ptr) }?);
    // Never unloaded: the descriptor's functions are the library's code.
    std::mem::forget(lib);
    Ok(library)
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
