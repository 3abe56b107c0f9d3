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
//! ([`abi::WIRE_SCHEMAS`]: a plugin of an older minor of the same major loads); the
//! loader then checks the descriptor itself again.
//!
//! Every request runs under the plugin's own `catch_unwind` ([`guest`]): a panicking
//! plugin yields an error, not an aborted host. Libraries are never unloaded.

pub mod abi;
#[doc(hidden)]
pub mod guest;
pub mod wire;

use std::ffi::c_void;
use std::panic::{AssertUnwindSafe, catch_unwind};

pub use abi::{ABI_MAJOR, ABI_MINOR, ABI_NOTE_LEN, ABI_SECTION, ENTRY_PREFIX, PLUGIN_MAGIC, abi_note};
pub use guest::StaticDescriptor;

use crate::error::{Error, Result};

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
pub unsafe extern "C" fn copy_reply(ctx: *mut c_void, reply: abi::Bytes) {
    // SAFETY: guaranteed by the caller: the sink's maker owns the vector and waits for
    // the call in which this runs.
    let out = unsafe { &mut *ctx.cast::<Vec<u8>>() };
    out.clear();
    // SAFETY: the sender lends the bytes for the length of this call.
    out.extend_from_slice(unsafe { reply.as_slice() });
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
