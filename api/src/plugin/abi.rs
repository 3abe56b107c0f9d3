//! The C types that cross between the host and a dynamic plugin, and their layout
//! fingerprint.
//!
//! Nothing else crosses: stage data travels as MessagePack bytes (see
//! [`wire`](super::wire)), written by one side into a buffer the other side owns. A byte
//! slice handed over is borrowed for the length of the call; a reply is copied by the
//! receiver through a [`ReplySink`], so memory is always freed by the side that
//! allocated it, and neither side depends on the other's allocator, standard library,
//! compiler or dependency versions.

use std::ffi::c_void;

/// `b"LAMINAPL"` as a little-endian integer: marks a Lamina plugin descriptor.
pub const PLUGIN_MAGIC: u64 = u64::from_le_bytes(*b"LAMINAPL");
/// Incremented when the descriptor, the C types or the meaning of a message change:
/// a plugin of another major is refused.
pub const ABI_MAJOR: u32 = 7;
/// The messages' schema at each minor version of [`ABI_MAJOR`], oldest first: hashes of
/// the schema `api/wire-schema.json` records, which `api/tests/wire_schema.rs` traces
/// from the serde definitions of every type a message carries. Comments, tests and
/// code that does not change a message leave it alone.
///
/// A change to the messages fails that test until it is given a version here: a hash
/// appended for an addition an older peer can do without (a field with
/// `#[serde(default)]`, which an older plugin never sees and a newer one finds filled
/// in; a request only plugins of the new minor are sent), or, for anything else, a new
/// major whose list starts again with the one hash.
pub const WIRE_SCHEMAS: &[u64] = &[
    0xc0eb_8b22_9dd3_ce19,
    // 7.1: options carry their physical range (`WireOption::range`).
    0x4406_817e_a6d0_9d30,
    // 7.2: graders that read no geometry are sent regions' facts (`GradeFacts`), and
    // answer with compositions only (`Graded`); script batches carry no contexts
    // (`FractionsBatch`, `FailedAt`).
    0xc68b_340e_c503_2918,
    // 7.3: diagnostics carry a code (`Diagnostic::code`), toolpaths the material their
    // tool carries (`Toolpath::material`), and layers the area they should hold
    // (`Layer::section_area`). Warnings of meshes, layers and machine files carry
    // their code inside the string an older plugin reads (`Warning`).
    0xd3fc_00ea_dc1e_9a83,
    // 7.4: discretisers and graders say whether they read the run's machine
    // (`ReadsMachine`); those that do not are sent the run without it.
    0xa974_ebfb_e110_89b7,
    // 7.5: exporters' notes on their files (`HostRequest::Tell`) and machine files'
    // reports (`HostRequest::Report`) reach the host, as they do from linked exporters.
    0x1e09_41f0_080a_ce60,
];
/// The minor version of this build: a plugin of this major and of this minor or an
/// older one loads (the host reads every message an older plugin writes, and sends it
/// only what it knows); a plugin of a newer minor asks for a newer host.
pub const ABI_MINOR: u32 = (WIRE_SCHEMAS.len() - 1) as u32;
/// Entry symbols are this prefix and the plugin's name, so that two plugin crates
/// linked into one program do not clash. The ABI is in the descriptor and the note,
/// not in the name, so that a plugin of another ABI is found and refused by name.
pub const ENTRY_PREFIX: &str = "lamina_plugin_";

/// Bytes borrowed for the length of one call.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct Bytes {
    pub ptr: *const u8,
    pub len: usize,
}

impl Bytes {
    pub fn of(bytes: &[u8]) -> Self {
        Self {
            ptr: bytes.as_ptr(),
            len: bytes.len(),
        }
    }

    /// The bytes.
    ///
    /// # Safety
    /// `ptr` must point to `len` readable bytes that stay valid and unchanged for `'a`
    /// (or `len` must be 0).
    pub unsafe fn as_slice<'a>(self) -> &'a [u8] {
        if self.len == 0 || self.ptr.is_null() {
            return &[];
        }
        // SAFETY: guaranteed by the caller.
        unsafe { std::slice::from_raw_parts(self.ptr, self.len) }
    }
}

/// Where a callee puts its reply: it calls `write` with bytes the caller copies before
/// `write` returns.
#[repr(C)]
#[derive(Debug)]
pub struct ReplySink {
    pub ctx: *mut c_void,
    pub write: unsafe extern "C" fn(ctx: *mut c_void, reply: Bytes),
}

/// The services the host offers a plugin during one call (scripts, output files): a
/// MessagePack request in, a reply through the sink. Returns 0 when a reply was written.
#[repr(C)]
#[derive(Debug)]
pub struct HostApi {
    pub ctx: *const c_void,
    pub call: unsafe extern "C" fn(ctx: *const c_void, request: Bytes, reply: *const ReplySink) -> i32,
}

/// What a plugin's entry symbol returns, from a static in the plugin.
#[repr(C)]
#[derive(Debug)]
pub struct PluginDescriptor {
    pub magic: u64,
    pub abi_major: u32,
    pub abi_minor: u32,
    /// `size_of::<PluginDescriptor>()` as the plugin saw it.
    pub struct_size: usize,
    /// [`LAYOUT_FINGERPRINT`] as the plugin computed it.
    pub layout: u64,
    /// [`WIRE_FINGERPRINT`] of the plugin's copy of the message types.
    pub wire: u64,
    /// The plugin's name (UTF-8, not NUL-terminated).
    pub name: Bytes,
    /// The lamina-api version the plugin was built against, for messages.
    pub core_version: Bytes,
    /// Handles one request ([`wire::Request`](super::wire::Request)); returns 0 when a
    /// reply was written. `host` is valid for the call only.
    pub call: unsafe extern "C" fn(request: Bytes, host: *const HostApi, reply: *const ReplySink) -> i32,
    /// Drops a stage (or a prepared mesh, or an open output) the plugin made.
    pub release: unsafe extern "C" fn(handle: u64),
}

/// The first fields of every descriptor, readable whatever the plugin's ABI.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct DescriptorPrefix {
    pub magic: u64,
    pub abi_major: u32,
    pub abi_minor: u32,
    pub struct_size: usize,
    pub layout: u64,
    pub wire: u64,
}

/// Signature of the entry symbol.
pub type EntryFn = unsafe extern "C" fn() -> *const PluginDescriptor;

/// Where [`fingerprint`] hashes start.
pub const FINGERPRINT_SEED: u64 = 0xcbf2_9ce4_8422_2325;

/// FNV-1a over 64-bit words: how [`LAYOUT_FINGERPRINT`] hashes sizes and offsets.
pub const fn fingerprint(mut hash: u64, words: &[usize]) -> u64 {
    let mut i = 0;
    while i < words.len() {
        let bytes = (words[i] as u64).to_le_bytes();
        let mut j = 0;
        while j < 8 {
            hash ^= bytes[j] as u64;
            hash = hash.wrapping_mul(0x0100_0000_01b3);
            j += 1;
        }
        i += 1;
    }
    hash
}

macro_rules! shape {
    ($t:ty { $($field:ident),* }) => {
        &[
            std::mem::size_of::<$t>(),
            std::mem::align_of::<$t>(),
            $(std::mem::offset_of!($t, $field),)*
        ]
    };
}

/// Sizes, alignments and field offsets of every C type above, hashed: two copies of
/// this module agree on it exactly when their types have the same layout on this
/// target. Checked at load, before any of them is read past the prefix.
pub const LAYOUT_FINGERPRINT: u64 = {
    let mut h = fingerprint(FINGERPRINT_SEED, &[ABI_MAJOR as usize]);
    h = fingerprint(h, shape!(Bytes { ptr, len }));
    h = fingerprint(h, shape!(ReplySink { ctx, write }));
    h = fingerprint(h, shape!(HostApi { ctx, call }));
    h = fingerprint(
        h,
        shape!(DescriptorPrefix {
            magic,
            abi_major,
            abi_minor,
            struct_size,
            layout,
            wire
        }),
    );
    fingerprint(
        h,
        shape!(PluginDescriptor {
            magic,
            abi_major,
            abi_minor,
            struct_size,
            layout,
            wire,
            name,
            core_version,
            call,
            release
        }),
    )
};

/// The schema of this build's messages ([`WIRE_SCHEMAS`] at [`ABI_MINOR`]).
pub const WIRE_FINGERPRINT: u64 = WIRE_SCHEMAS[WIRE_SCHEMAS.len() - 1];

/// Length of the [`abi_note`] a plugin carries in its [`ABI_SECTION`].
pub const ABI_NOTE_LEN: usize = 128;

/// The section that holds a plugin's ABI note, per object format (an ELF or PE section
/// name, a Mach-O `segment,section`).
#[cfg(target_os = "macos")]
pub const ABI_SECTION: &str = "__DATA,__lamina_abi";
#[cfg(windows)]
pub const ABI_SECTION: &str = ".lamabi";
#[cfg(not(any(target_os = "macos", windows)))]
pub const ABI_SECTION: &str = ".lamina_abi";

/// True when this build unwinds on a panic: the plugin's guard turns its panics into
/// errors. A plugin built with `panic = "abort"` would end the host at its first panic,
/// so the host refuses it.
pub const PANICS_UNWIND: bool = cfg!(panic = "unwind");

/// The plugin's ABI, readable from the library file without loading it: the magic, the
/// ABI major and minor (little-endian `u32`s), the layout and wire fingerprints
/// (little-endian `u64`s), the lamina-api version (32 bytes, NUL-padded), then one
/// byte, 1 when the plugin's panics unwind ([`PANICS_UNWIND`]). The host refuses a
/// mismatch before the dynamic loader runs any of the library's initialisers.
pub const fn abi_note() -> [u8; ABI_NOTE_LEN] {
    let mut note = [0u8; ABI_NOTE_LEN];
    let magic = PLUGIN_MAGIC.to_le_bytes();
    let major = ABI_MAJOR.to_le_bytes();
    let minor = ABI_MINOR.to_le_bytes();
    let layout = LAYOUT_FINGERPRINT.to_le_bytes();
    let wire = WIRE_FINGERPRINT.to_le_bytes();
    let mut i = 0;
    while i < 8 {
        note[i] = magic[i];
        note[16 + i] = layout[i];
        note[24 + i] = wire[i];
        i += 1;
    }
    i = 0;
    while i < 4 {
        note[8 + i] = major[i];
        note[12 + i] = minor[i];
        i += 1;
    }
    let version = crate::VERSION.as_bytes();
    i = 0;
    while i < version.len() && i < 31 {
        note[32 + i] = version[i];
        i += 1;
    }
    note[64] = PANICS_UNWIND as u8;
    note
}

/// An [`abi_note`] read back.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AbiNote {
    pub magic: u64,
    pub abi_major: u32,
    pub abi_minor: u32,
    pub layout: u64,
    pub wire: u64,
    pub core_version: String,
    /// The plugin's panics unwind (see [`PANICS_UNWIND`]).
    pub unwinds: bool,
}

impl AbiNote {
    pub fn parse(note: &[u8]) -> Option<Self> {
        let note = note.get(..ABI_NOTE_LEN)?;
        let u32_at = |at: usize| u32::from_le_bytes([note[at], note[at + 1], note[at + 2], note[at + 3]]);
        let u64_at = |at: usize| {
            let mut b = [0u8; 8];
            b.copy_from_slice(&note[at..at + 8]);
            u64::from_le_bytes(b)
        };
        let version = &note[32..64];
        let end = version.iter().position(|&b| b == 0).unwrap_or(version.len());
        Some(Self {
            magic: u64_at(0),
            abi_major: u32_at(8),
            abi_minor: u32_at(12),
            layout: u64_at(16),
            wire: u64_at(24),
            core_version: String::from_utf8_lossy(&version[..end]).into_owned(),
            unwinds: note[64] == 1,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_note_reads_back() {
        let note = AbiNote::parse(&abi_note()).expect("note");
        assert_eq!(note.magic, PLUGIN_MAGIC);
        assert_eq!((note.abi_major, note.abi_minor), (ABI_MAJOR, ABI_MINOR));
        assert_eq!(note.layout, LAYOUT_FINGERPRINT);
        assert_eq!(note.wire, WIRE_FINGERPRINT);
        assert_eq!(note.core_version, crate::VERSION);
        assert!(note.unwinds, "the tests are built to unwind");
    }

    #[test]
    fn the_prefix_is_the_descriptors_start() {
        assert_eq!(
            std::mem::offset_of!(PluginDescriptor, wire),
            std::mem::offset_of!(DescriptorPrefix, wire)
        );
        assert!(std::mem::size_of::<DescriptorPrefix>() < std::mem::size_of::<PluginDescriptor>());
    }
}
