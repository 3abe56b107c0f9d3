//! Dynamic plugins: third-party crates built as `cdylib` and loaded with `libloading`.
//!
//! The boundary is a C one, and nothing of Rust's ABI crosses it:
//! - a plugin exports one entry symbol, `lamina_plugin_<name>`, returning a
//!   `#[repr(C)]` [`PluginDescriptor`](abi::PluginDescriptor) with two functions: one
//!   answers requests, one releases what the plugin made;
//! - stage data crosses as MessagePack messages ([`wire`]), borrowed by the callee for
//!   the length of a call; replies are copied by the receiver, so each side frees only
//!   what it allocated;
//! - the plugin's stages, prepared meshes and open outputs stay in the plugin behind
//!   numbered handles; the host holds proxies ([`host`]);
//! - a plugin's scripts are compiled and run by the host under the host's limits, and
//!   its output files are the host's, through service requests made during a call.
//!
//! So a plugin built by another compiler, or resolving other versions of serde, rhai,
//! toml or nalgebra than the host, runs correctly. What must agree is checked from the
//! file before anything of the library runs ([`inspect`]): the ABI major, the layout
//! of the C types ([`abi::LAYOUT_FINGERPRINT`]) and the messages' types
//! ([`abi::WIRE_FINGERPRINT`]); the loader then checks the descriptor itself again.
//!
//! Every request runs under the plugin's own `catch_unwind` ([`guest`]): a panicking
//! plugin yields an error, not an aborted host. Libraries are never unloaded.

pub mod abi;
pub(crate) mod guest;
pub(crate) mod host;
mod inspect;
pub mod wire;

use std::ffi::c_void;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

pub use abi::{ABI_MAJOR, ABI_MINOR, ABI_NOTE_LEN, ABI_SECTION, ENTRY_PREFIX, PLUGIN_MAGIC, abi_note};
pub use guest::StaticDescriptor;
pub use inspect::inspect;

use crate::error::{Error, Result};
use crate::registry::{Origin, Registry, StageFactory};

/// Declares a crate's entry symbol, `lamina_plugin_<name>`: the crate becomes a
/// loadable plugin whose stages are those it registered with
/// [`register_stage!`](crate::register_stage). It also places the
/// [`abi_note`](abi::abi_note) in the library's [`ABI_SECTION`], which the host reads
/// before loading the file. The name must be a string literal.
#[macro_export]
macro_rules! export_plugin {
    ($name:literal) => {
        /// The ABI this plugin was built for, read by the host before it loads the file.
        #[used]
        #[cfg_attr(target_os = "macos", unsafe(link_section = "__DATA,__lamina_abi"))]
        #[cfg_attr(windows, unsafe(link_section = ".lamabi"))]
        #[cfg_attr(
            not(any(target_os = "macos", windows)),
            unsafe(link_section = ".lamina_abi")
        )]
        static LAMINA_PLUGIN_ABI: [u8; $crate::plugin::ABI_NOTE_LEN] = $crate::plugin::abi_note();

        static LAMINA_PLUGIN_DESCRIPTOR: $crate::plugin::StaticDescriptor =
            $crate::plugin::StaticDescriptor::new($name);

        /// Entry point read by Lamina's plugin loader.
        #[unsafe(export_name = concat!("lamina_plugin_", $name))]
        pub extern "C" fn lamina_plugin_entry() -> *const $crate::plugin::abi::PluginDescriptor {
            LAMINA_PLUGIN_DESCRIPTOR.get()
        }
    };
}

/// Copies a reply into the `Vec<u8>` at `ctx` ([`abi::ReplySink::write`]).
///
/// # Safety
/// `ctx` must be the `Vec<u8>` the sink was made for, not otherwise borrowed, and
/// `reply` valid for the call.
unsafe extern "C" fn copy_reply(ctx: *mut c_void, reply: abi::Bytes) {
    // SAFETY: guaranteed by the caller: the sink's maker owns the vector and waits for
    // the call in which this runs.
    let out = unsafe { &mut *ctx.cast::<Vec<u8>>() };
    out.clear();
    // SAFETY: the sender lends the bytes for the length of this call.
    out.extend_from_slice(unsafe { reply.as_slice() });
}

/// Libraries loaded so far, by canonical path, with their stages. Kept for the life of
/// the process: nothing is ever unloaded.
static LOADED: Mutex<Vec<LoadedPlugin>> = Mutex::new(Vec::new());

#[derive(Debug, Clone)]
struct LoadedPlugin {
    path: PathBuf,
    library: Arc<host::Library>,
    stages: Vec<(&'static StageFactory, host::RemoteFactory)>,
}

fn refuse(path: &Path, message: impl Into<String>) -> Error {
    Error::Plugin {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

/// Loads a plugin library and adds its stages to `registry`. Loading the same file
/// twice adds its stages once per registry.
pub fn load(registry: &mut Registry, path: &Path) -> Result<String> {
    let canonical = path
        .canonicalize()
        .map_err(|e| refuse(path, format!("cannot open: {e}")))?;
    let mut loaded = LOADED.lock().unwrap_or_else(|e| e.into_inner());
    let plugin = match loaded.iter().find(|p| p.path == canonical) {
        Some(p) => p.clone(),
        None => {
            let p = open(&canonical)?;
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
    let entry_symbol = inspect::entry_symbol(path)?;
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
    let stages = library.describe()?;
    Ok(LoadedPlugin {
        path: path.to_path_buf(),
        library,
        stages,
    })
}

/// Runs `f`, turning a panic into an error naming `label`.
pub fn guard_call<T>(label: &str, f: impl FnOnce() -> Result<T>) -> Result<T> {
    catch_unwind(AssertUnwindSafe(f)).unwrap_or_else(|payload| {
        let message = payload
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "unknown panic".into());
        Err(Error::Panic {
            stage: label.to_string(),
            message,
        })
    })
}

/// Adds the stages linked into this program to `registry` as if a plugin library named
/// `name` held them: every call goes through the boundary (messages, handles, the
/// host's services) without a library file. For tests of the boundary: a pipeline run
/// this way must give what the linked stages give.
pub fn add_linked_through_boundary(registry: &mut Registry, name: &'static str) -> Result<()> {
    let descriptor: &'static StaticDescriptor = Box::leak(Box::new(StaticDescriptor::new(name)));
    let path = PathBuf::from(format!("<{name}>"));
    // SAFETY: the descriptor is this copy's own, leaked for the life of the process.
    let library = Arc::new(unsafe { host::Library::new(&path, descriptor.get()) }?);
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
