//! Dynamic plugins: third-party crates built as `cdylib` and loaded with `libloading`.
//!
//! A plugin exports one C-ABI entry symbol, [`ENTRY_SYMBOL`], returning a `#[repr(C)]`
//! [`PluginDescriptor`]. The descriptor's first four fields (magic, ABI major, ABI
//! minor, struct size) keep their layout forever, so any host can read them and refuse
//! a plugin of another ABI with a message naming both versions. Stage factories are
//! Rust values: they are used only when the plugin was built against the same
//! lamina-core version by the same compiler.
//!
//! `inventory` registrations made inside a loaded library land in that library's own
//! copy of the registry, so the entry point collects them there and hands them over.
//! Every call into a plugin's stages goes through `catch_unwind`: a panicking plugin
//! yields an error, not an aborted host. Libraries are never unloaded, since their code
//! and statics back the factories handed over.

use std::ffi::{CStr, CString, c_char};
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use crate::error::{Error, Result};
use crate::mesh::Mesh;
use crate::model::*;
use crate::registry::{Origin, Registry, StageFactory};
use crate::stage::*;

/// `b"LAMINAPL"` as a little-endian integer: marks a Lamina plugin descriptor.
pub const PLUGIN_MAGIC: u64 = u64::from_le_bytes(*b"LAMINAPL");
/// Incremented when the meaning of the descriptor or of the stage traits changes.
pub const ABI_MAJOR: u32 = 5;
/// Incremented for additions a host of the same major can ignore.
pub const ABI_MINOR: u32 = 0;
/// The entry symbol; `v1` is the version of the descriptor's frozen prefix.
pub const ENTRY_SYMBOL: &str = "lamina_plugin_entry_v1";
/// The compiler that built this copy of lamina-core.
pub const RUSTC_VERSION: &str = env!("LAMINA_RUSTC_VERSION");

/// What a plugin's entry symbol returns. Never constructed by hand: use
/// [`export_plugin!`](crate::export_plugin).
#[repr(C)]
#[derive(Debug)]
pub struct PluginDescriptor {
    pub magic: u64,
    pub abi_major: u32,
    pub abi_minor: u32,
    /// `size_of::<PluginDescriptor>()` as the plugin saw it.
    pub struct_size: usize,
    /// NUL-terminated lamina-core version the plugin was built against.
    pub core_version: *const c_char,
    /// NUL-terminated `rustc --version` of the plugin's compiler.
    pub rustc_version: *const c_char,
    /// NUL-terminated plugin name.
    pub name: *const c_char,
    pub stages: *const &'static StageFactory,
    pub stage_count: usize,
    /// Builds a stage inside the plugin, guarded by the plugin's own `catch_unwind`.
    pub build: GuardedBuild,
}

/// Builds one of a plugin's stages on the plugin's side of the boundary.
///
/// A plugin links its own copy of the standard library, and a panic raised by one copy
/// cannot be caught by another (it is a foreign exception there). So the guard must run
/// in the plugin's code: the descriptor carries this function, compiled into the
/// plugin, which builds the stage under the plugin's `catch_unwind` and wraps it so that
/// every later call is guarded the same way.
pub type GuardedBuild = fn(&'static StageFactory, &str, &StageConfig<'_>) -> Result<AnyStage>;

/// The [`GuardedBuild`] of the copy of lamina-core it is compiled into.
pub fn build_guarded(
    factory: &'static StageFactory,
    label: &str,
    config: &StageConfig<'_>,
) -> Result<AnyStage> {
    let stage = guard_call(label, || (factory.build)(config))?;
    Ok(guard_stage(label.to_string(), stage))
}

/// The frozen prefix of [`PluginDescriptor`], readable whatever the plugin's ABI.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
struct DescriptorPrefix {
    magic: u64,
    abi_major: u32,
    abi_minor: u32,
    struct_size: usize,
}

/// Signature of the entry symbol.
pub type EntryFn = unsafe extern "C" fn() -> *const PluginDescriptor;

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

/// The plugin's ABI, readable from the library file without loading it: the magic, the
/// ABI major and minor (little-endian `u32`s), then the lamina-core version (32 bytes)
/// and the compiler's version (80 bytes), NUL-padded. The host refuses a mismatch
/// before the dynamic loader runs any of the library's initialisers.
pub const fn abi_note() -> [u8; ABI_NOTE_LEN] {
    let mut note = [0u8; ABI_NOTE_LEN];
    let magic = PLUGIN_MAGIC.to_le_bytes();
    let major = ABI_MAJOR.to_le_bytes();
    let minor = ABI_MINOR.to_le_bytes();
    let mut i = 0;
    while i < 8 {
        note[i] = magic[i];
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
        note[16 + i] = version[i];
        i += 1;
    }
    let rustc = RUSTC_VERSION.as_bytes();
    i = 0;
    while i < rustc.len() && i < 79 {
        note[48 + i] = rustc[i];
        i += 1;
    }
    note
}

/// Declares a crate's entry symbol: the crate becomes a loadable plugin whose stages are
/// those it registered with [`register_stage!`](crate::register_stage). It also places
/// the [`abi_note`] in the library's [`ABI_SECTION`].
#[macro_export]
macro_rules! export_plugin {
    ($name:expr) => {
        /// The ABI this plugin was built for, read by the host before it loads the file.
        #[used]
        #[cfg_attr(target_os = "macos", unsafe(link_section = "__DATA,__lamina_abi"))]
        #[cfg_attr(windows, unsafe(link_section = ".lamabi"))]
        #[cfg_attr(
            not(any(target_os = "macos", windows)),
            unsafe(link_section = ".lamina_abi")
        )]
        static LAMINA_PLUGIN_ABI: [u8; $crate::plugin::ABI_NOTE_LEN] = $crate::plugin::abi_note();

        /// Entry point read by Lamina's plugin loader.
        #[unsafe(no_mangle)]
        pub extern "C" fn lamina_plugin_entry_v1() -> *const $crate::plugin::PluginDescriptor {
            $crate::plugin::describe_linked($name)
        }
    };
}

/// Builds the descriptor of the library this code is linked into, from that library's
/// own `inventory` registrations. Returns null if anything panics.
pub fn describe_linked(name: &'static str) -> *const PluginDescriptor {
    catch_unwind(|| {
        let stages: Vec<&'static StageFactory> = inventory::iter::<StageFactory>.into_iter().collect();
        let stages: &'static [&'static StageFactory] = Box::leak(stages.into_boxed_slice());
        let leak = |s: &str| CString::new(s).unwrap_or_default().into_raw().cast_const();
        let d = PluginDescriptor {
            magic: PLUGIN_MAGIC,
            abi_major: ABI_MAJOR,
            abi_minor: ABI_MINOR,
            struct_size: std::mem::size_of::<PluginDescriptor>(),
            core_version: leak(crate::VERSION),
            rustc_version: leak(RUSTC_VERSION),
            name: leak(name),
            stages: stages.as_ptr(),
            stage_count: stages.len(),
            build: build_guarded,
        };
        Box::leak(Box::new(d)) as *const PluginDescriptor
    })
    .unwrap_or(std::ptr::null())
}

/// Libraries loaded so far, by canonical path, with their name and factories. Kept for
/// the life of the process: nothing is ever unloaded.
static LOADED: Mutex<Vec<LoadedPlugin>> = Mutex::new(Vec::new());

#[derive(Debug, Clone)]
struct LoadedPlugin {
    path: PathBuf,
    name: String,
    stages: Vec<&'static StageFactory>,
    build: GuardedBuild,
}

fn refuse(path: &Path, message: impl Into<String>) -> Error {
    Error::Plugin {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

/// Reads a NUL-terminated string from a plugin.
///
/// # Safety
/// `p` must be null or point to a NUL-terminated string that outlives the call.
unsafe fn plugin_str(p: *const c_char) -> Option<String> {
    if p.is_null() {
        return None;
    }
    // SAFETY: the caller guarantees a valid NUL-terminated string.
    Some(unsafe { CStr::from_ptr(p) }.to_string_lossy().into_owned())
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
    for f in &plugin.stages {
        registry.add_dynamic(
            f,
            Origin::Dynamic {
                path: canonical.clone(),
                plugin: plugin.name.clone(),
            },
            plugin.build,
        )?;
    }
    Ok(plugin.name)
}

/// A NUL-padded string field of an ABI note.
fn note_str(field: &[u8]) -> String {
    let end = field.iter().position(|&b| b == 0).unwrap_or(field.len());
    String::from_utf8_lossy(&field[..end]).into_owned()
}

/// Reads a library file as an object file and refuses it before the dynamic loader
/// sees it: a file that is not a library of this platform, a truncated one (the loader
/// would map pages past its end, and touching them kills the process with SIGBUS), one
/// without Lamina's entry symbol, or one whose ABI note names another ABI, lamina-core
/// or compiler. Nothing of the library runs here.
pub fn inspect(path: &Path) -> Result<()> {
    use object::{Object, ObjectSection, ObjectSegment};
    let data = std::fs::read(path).map_err(|e| refuse(path, format!("cannot read: {e}")))?;
    let file = object::File::parse(&*data).map_err(|e| {
        refuse(
            path,
            format!("not a complete shared library of this platform (truncated, or of another format): {e}"),
        )
    })?;
    let size = data.len() as u64;
    for segment in file.segments() {
        let (offset, length) = segment.file_range();
        if offset.checked_add(length).is_none_or(|end| end > size) {
            return Err(refuse(
                path,
                format!(
                    "truncated: a segment needs bytes {offset}..{} of the file, which has {size}",
                    offset.saturating_add(length)
                ),
            ));
        }
    }
    let exports = file
        .exports()
        .map_err(|e| refuse(path, format!("cannot read its exported symbols: {e}")))?;
    let exported = exports.iter().any(|e| {
        let name = e.name();
        name == ENTRY_SYMBOL.as_bytes() || name.strip_prefix(b"_") == Some(ENTRY_SYMBOL.as_bytes())
    });
    if !exported {
        return Err(refuse(
            path,
            format!("not a Lamina plugin: it exports no `{ENTRY_SYMBOL}` (use lamina_core::export_plugin!)"),
        ));
    }
    let section_name = ABI_SECTION.rsplit(',').next().unwrap_or(ABI_SECTION);
    let note = file
        .section_by_name(section_name)
        .and_then(|s| s.data().ok())
        .filter(|d| d.len() >= ABI_NOTE_LEN)
        .ok_or_else(|| {
            refuse(
                path,
                format!(
                    "it carries no ABI note (section `{ABI_SECTION}`): it was built against an older lamina-core; rebuild it against lamina-core {}",
                    crate::VERSION
                ),
            )
        })?;
    let word = |at: usize| u32::from_le_bytes([note[at], note[at + 1], note[at + 2], note[at + 3]]);
    let magic = u64::from_le_bytes([
        note[0], note[1], note[2], note[3], note[4], note[5], note[6], note[7],
    ]);
    if magic != PLUGIN_MAGIC {
        return Err(refuse(path, "its ABI note is not a Lamina plugin's"));
    }
    let (major, minor) = (word(8), word(12));
    let (core_version, rustc_version) = (note_str(&note[16..48]), note_str(&note[48..128]));
    if major != ABI_MAJOR || minor > ABI_MINOR {
        return Err(refuse(
            path,
            format!(
                "built for plugin ABI {major}.{minor}, this lamina {} supports ABI {ABI_MAJOR}.{ABI_MINOR}: rebuild the plugin against lamina-core {}",
                crate::VERSION,
                crate::VERSION
            ),
        ));
    }
    same_build(path, "", &core_version, &rustc_version)
}

/// Refuses a plugin built against another lamina-core or by another compiler; `who`
/// starts the message (`plugin `x` was `), or is empty.
fn same_build(path: &Path, who: &str, core_version: &str, rustc_version: &str) -> Result<()> {
    if core_version != crate::VERSION {
        return Err(refuse(
            path,
            format!(
                "{who}built against lamina-core {core_version}, this lamina is {}: rebuild it",
                crate::VERSION
            ),
        ));
    }
    if rustc_version != RUSTC_VERSION {
        return Err(refuse(
            path,
            format!(
                "{who}built by `{rustc_version}`, this lamina by `{RUSTC_VERSION}`: rebuild it with the same compiler"
            ),
        ));
    }
    Ok(())
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
    inspect(path)?;
    // SAFETY: loading a library runs its initialisers; plugins are code the user chose to
    // run, like the pipeline that names them, and the file was inspected first.
    let lib = unsafe { libloading::Library::new(path) }
        .map_err(|e| refuse(path, format!("cannot load library: {}", chain(&e))))?;
    let symbol = format!("{ENTRY_SYMBOL}\0");
    // SAFETY: the symbol, if present, has the signature `export_plugin!` gives it.
    let entry: EntryFn = unsafe { lib.get::<EntryFn>(symbol.as_bytes()) }
        .map(|s| *s)
        .map_err(|_| {
            refuse(
                path,
                format!(
                    "not a Lamina plugin: it exports no `{ENTRY_SYMBOL}` (use lamina_core::export_plugin!)"
                ),
            )
        })?;
    // SAFETY: calling the entry is the plugin contract; a panic inside it is caught by
    // `describe_linked` on the plugin's side.
    let ptr = unsafe { entry() };
    if ptr.is_null() {
        return Err(refuse(path, "the plugin's entry point failed"));
    }
    // SAFETY: every Lamina descriptor starts with the frozen prefix.
    let prefix = unsafe { std::ptr::read(ptr.cast::<DescriptorPrefix>()) };
    if prefix.magic != PLUGIN_MAGIC {
        return Err(refuse(
            path,
            "entry point returned something that is not a Lamina plugin descriptor",
        ));
    }
    if prefix.abi_major != ABI_MAJOR || prefix.abi_minor > ABI_MINOR {
        return Err(refuse(
            path,
            format!(
                "built for plugin ABI {}.{}, this lamina {} supports ABI {}.{}: rebuild the plugin against lamina-core {}",
                prefix.abi_major,
                prefix.abi_minor,
                crate::VERSION,
                ABI_MAJOR,
                ABI_MINOR,
                crate::VERSION
            ),
        ));
    }
    if prefix.struct_size < std::mem::size_of::<PluginDescriptor>() {
        return Err(refuse(
            path,
            format!(
                "descriptor is {} bytes, expected at least {}",
                prefix.struct_size,
                std::mem::size_of::<PluginDescriptor>()
            ),
        ));
    }
    // SAFETY: magic, ABI and size checked: the full descriptor is there.
    let d = unsafe { &*ptr };
    // SAFETY: the descriptor's strings are leaked NUL-terminated strings.
    let (core_version, rustc_version, name) = unsafe {
        (
            plugin_str(d.core_version).unwrap_or_default(),
            plugin_str(d.rustc_version).unwrap_or_default(),
            plugin_str(d.name).unwrap_or_else(|| "unnamed".into()),
        )
    };
    same_build(
        path,
        &format!("plugin `{name}` was "),
        &core_version,
        &rustc_version,
    )?;
    let stages = if d.stage_count == 0 || d.stages.is_null() {
        Vec::new()
    } else {
        // SAFETY: same core version and compiler: the table is `stage_count` valid
        // `&'static StageFactory` kept alive by the never-unloaded library.
        unsafe { std::slice::from_raw_parts(d.stages, d.stage_count) }.to_vec()
    };
    // Never unloaded: the factories point into the library.
    std::mem::forget(lib);
    Ok(LoadedPlugin {
        path: path.to_path_buf(),
        name,
        stages,
        build: d.build,
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

/// A stage of a dynamic plugin: every call is guarded.
struct Guarded<T: ?Sized> {
    label: Arc<str>,
    inner: Box<T>,
}

impl<T: ?Sized> Guarded<T> {
    fn wrap<U: ?Sized>(&self, inner: Box<U>) -> Guarded<U> {
        Guarded {
            label: self.label.clone(),
            inner,
        }
    }
}

/// Wraps a stage built by a dynamic plugin so that its panics become errors.
pub fn guard_stage(label: String, stage: AnyStage) -> AnyStage {
    let label: Arc<str> = label.into();
    macro_rules! g {
        ($inner:expr) => {
            Box::new(Guarded {
                label: label.clone(),
                inner: $inner,
            })
        };
    }
    match stage {
        AnyStage::Model(s) => AnyStage::Model(g!(s)),
        AnyStage::Orient(s) => AnyStage::Orient(g!(s)),
        AnyStage::Slice(s) => AnyStage::Slice(g!(s)),
        AnyStage::Sort(s) => AnyStage::Sort(g!(s)),
        AnyStage::Discretise(s) => AnyStage::Discretise(g!(s)),
        AnyStage::Grade(s) => AnyStage::Grade(g!(s)),
        AnyStage::Sequence(s) => AnyStage::Sequence(g!(s)),
        AnyStage::Plan(s) => AnyStage::Plan(g!(s)),
        AnyStage::Export(s) => AnyStage::Export(g!(s)),
    }
}

impl ModelSource for Guarded<dyn ModelSource> {
    fn load(&self, base_dir: &Path) -> Result<Vec<Mesh>> {
        guard_call(&self.label, || self.inner.load(base_dir))
    }
}

impl Orienter for Guarded<dyn Orienter> {
    fn orient(&self, meshes: &[&Mesh]) -> Result<Orientation> {
        guard_call(&self.label, || self.inner.orient(meshes))
    }
}

impl Slicer for Guarded<dyn Slicer> {
    fn layers(
        &self,
        meshes: &[Arc<Mesh>],
        info: &RunInfo,
        sequence: Option<&Sequence>,
    ) -> Result<Vec<LayerSlot>> {
        guard_call(&self.label, || self.inner.layers(meshes, info, sequence))
    }

    fn prepare(&self, mesh: Arc<Mesh>) -> Result<Box<dyn MeshSlicer>> {
        let inner = guard_call(&self.label, || self.inner.prepare(mesh))?;
        Ok(Box::new(self.wrap(inner)))
    }
}

impl MeshSlicer for Guarded<dyn MeshSlicer> {
    fn slice(&self, slot: &LayerSlot) -> Result<Layer> {
        guard_call(&self.label, || self.inner.slice(slot))
    }
}

impl Sorter for Guarded<dyn Sorter> {
    fn sort(&self, layer: &Layer) -> Result<ContourTree> {
        guard_call(&self.label, || self.inner.sort(layer))
    }
}

impl Discretiser for Guarded<dyn Discretiser> {
    fn discretise(&self, ctx: &FamilyContext<'_>) -> Result<Vec<Region>> {
        guard_call(&self.label, || self.inner.discretise(ctx))
    }

    fn grades(&self) -> bool {
        guard_call(&self.label, || Ok(self.inner.grades())).unwrap_or(false)
    }
}

impl Grader for Guarded<dyn Grader> {
    fn grade(&self, ctx: &FamilyContext<'_>, regions: &mut [Region]) -> Result<()> {
        guard_call(&self.label, || self.inner.grade(ctx, regions))
    }
}

impl Sequencer for Guarded<dyn Sequencer> {
    fn sequence(&self, info: &RunInfo) -> Result<Sequence> {
        guard_call(&self.label, || self.inner.sequence(info))
    }
}

impl Planner for Guarded<dyn Planner> {
    fn plan(&self, info: &RunInfo, plan: &mut LayerPlan) -> Result<()> {
        guard_call(&self.label, || self.inner.plan(info, plan))
    }
}

impl Exporter for Guarded<dyn Exporter> {
    fn open(&self, ctx: &mut ExportContext<'_>) -> Result<Box<dyn LayerSink>> {
        let inner = guard_call(&self.label, || self.inner.open(ctx))?;
        Ok(Box::new(self.wrap(inner)))
    }
}

impl LayerSink for Guarded<dyn LayerSink> {
    fn layer(&mut self, info: &RunInfo, plan: &LayerPlan) -> Result<()> {
        guard_call(&self.label, || self.inner.layer(info, plan))
    }

    fn layer_with_files(
        &mut self,
        info: &RunInfo,
        plan: &LayerPlan,
        files: &mut dyn OutputFiles,
    ) -> Result<()> {
        guard_call(&self.label, || self.inner.layer_with_files(info, plan, files))
    }

    fn finish(self: Box<Self>, info: &RunInfo) -> Result<()> {
        let Guarded { label, inner } = *self;
        guard_call(&label, || inner.finish(info))
    }

    fn finish_with_files(self: Box<Self>, info: &RunInfo, files: &mut dyn OutputFiles) -> Result<()> {
        let Guarded { label, inner } = *self;
        guard_call(&label, || inner.finish_with_files(info, files))
    }
}
