//! Loading a plugin library into this process, once its file (`inspect`), entry point
//! and descriptor check out.

use std::path::Path;
use std::sync::Arc;

use super::refusal::{chain, refuse};
use super::{ENTRY_PREFIX, abi, host, inspect};
use crate::error::Result;

/// Loads a library into this process once its file, entry and descriptor check out.
/// One that runs `apart` (in a child process serving a host) may abort on panics.
pub(super) fn open_library(path: &Path, apart: bool) -> Result<Arc<host::Library>> {
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
