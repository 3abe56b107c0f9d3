//! The host's side of the boundary: loads a plugin library, and stands in for each of
//! its stages with a proxy that turns every trait call into a [`Request`] and the
//! [`Reply`] back into values. It also serves the plugin's [`HostRequest`]s: scripts
//! compiled and run by the host's engine under the host's limits, and output files
//! created through the run's atomic output.

use std::borrow::Cow;
use std::cell::RefCell;
use std::collections::{BTreeMap, HashSet};
use std::ffi::c_void;
use std::io::Write;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, RwLock};
use std::thread::ThreadId;

use super::abi::*;
use super::wire::*;
use super::{copy_reply, refuse};
use crate::error::{Error, Result};
use crate::mesh::Mesh;
use crate::model::*;
use crate::registry::StageFactory;
use crate::script::{ScriptFn, ScriptHost};
use crate::stage::*;

/// A loaded plugin library: its two functions. Never unloaded, since a library's
/// thread-local destructors and statics may run until the process ends.
#[derive(Debug)]
pub struct Library {
    pub path: PathBuf,
    pub name: String,
    call: unsafe extern "C" fn(Bytes, *const HostApi, *const ReplySink) -> i32,
    release: unsafe extern "C" fn(u64),
}

/// A stage of a loaded library, by its number in the library's description.
#[derive(Debug, Clone)]
pub struct RemoteFactory {
    pub(crate) library: Arc<Library>,
    pub(crate) index: usize,
}

impl Library {
    /// Reads the full descriptor at `descriptor` after its prefix was checked.
    ///
    /// # Safety
    /// `descriptor` must point to a [`PluginDescriptor`] of this ABI and layout that
    /// lives as long as the process (a static of a library never unloaded).
    pub(crate) unsafe fn new(path: &Path, descriptor: *const PluginDescriptor) -> Result<Self> {
        // SAFETY: guaranteed by the caller.
        let d = unsafe { &*descriptor };
        // SAFETY: the descriptor's strings are `'static` data of the library.
        let name = String::from_utf8_lossy(unsafe { d.name.as_slice() }).into_owned();
        Ok(Self {
            path: path.to_path_buf(),
            name,
            call: d.call,
            release: d.release,
        })
    }

    fn error(&self, message: impl Into<String>) -> Error {
        refuse(&self.path, format!("plugin `{}`: {}", self.name, message.into()))
    }

    /// Sends one request and waits for its reply, serving the plugin's service
    /// requests with `ctx` meanwhile.
    fn request(&self, request: &Request<'_>, ctx: &HostCtx<'_, '_>) -> Result<Response> {
        let bytes = encode(request).map_err(|m| self.error(m))?;
        let mut reply: Vec<u8> = Vec::new();
        let sink = ReplySink {
            ctx: (&raw mut reply).cast(),
            write: copy_reply,
        };
        let api = HostApi {
            ctx: std::ptr::from_ref(ctx).cast(),
            call: host_call,
        };
        // SAFETY: `call` is the plugin's entry, checked to have this ABI and layout;
        // the request bytes, `api` (and the context it points to) and the sink all
        // outlive the call, and the plugin copies nothing of them past it.
        let status = unsafe { (self.call)(Bytes::of(&bytes), &api, &sink) };
        if status != 0 {
            return Err(self.error("failed without a reply (it could not encode one)"));
        }
        let reply: Reply = decode(&reply).map_err(|m| self.error(m))?;
        reply.map_err(Error::from)
    }

    /// Asks for the library's stages and makes a registry factory of each.
    pub(crate) fn describe(self: &Arc<Self>) -> Result<Vec<(&'static StageFactory, RemoteFactory)>> {
        let scripts = ScriptTable::new(None);
        let files = FileTable::default();
        let stages = match self.request(&Request::Describe, &HostCtx::new(&scripts, &files, None))? {
            Response::Stages(s) => s,
            other => return Err(self.error(format!("answered {} to a description request", name_of(&other)))),
        };
        Ok(stages
            .into_iter()
            .enumerate()
            .map(|(index, s)| {
                let leak = |s: String| -> &'static str { Box::leak(s.into_boxed_str()) };
                let options: Vec<OptionSpec> = s
                    .options
                    .into_iter()
                    .map(|o| OptionSpec {
                        name: leak(o.name),
                        ty: leak(o.ty),
                        default: o.default.map(leak),
                        doc: leak(o.doc),
                    })
                    .collect();
                let factory: &'static StageFactory = Box::leak(Box::new(StageFactory {
                    info: StageInfo {
                        kind: s.kind,
                        name: leak(s.name),
                        doc: leak(s.doc),
                        options: Box::leak(options.into_boxed_slice()),
                        example: leak(s.example),
                    },
                    build: built_by_library,
                }));
                (
                    factory,
                    RemoteFactory {
                        library: self.clone(),
                        index,
                    },
                )
            })
            .collect())
    }
}

/// The `build` of a dynamic plugin's factory in the registry: never called, since the
/// registry builds those stages through [`build`].
fn built_by_library(_: &StageConfig<'_>) -> Result<AnyStage> {
    Err(Error::stage(
        "plugin",
        "a dynamic plugin's stage is built through its library",
    ))
}

fn name_of(r: &Response) -> &'static str {
    match r {
        Response::Stages(_) => "stages",
        Response::Handle(_) => "a handle",
        Response::Meshes(_) => "meshes",
        Response::Orientation(_) => "an orientation",
        Response::Slots(_) => "layer slots",
        Response::Layer(_) => "a layer",
        Response::Tree(_) => "a contour tree",
        Response::Regions(_) => "regions",
        Response::Bool(_) => "a yes or no",
        Response::Sequence(_) => "a sequence",
        Response::Plan(_) => "a plan",
        Response::Done => "done",
    }
}

/// Scripts the host compiled for one plugin stage, by number.
struct ScriptTable {
    host: Option<ScriptHost>,
    compiled: RwLock<Vec<ScriptFn>>,
}

impl ScriptTable {
    fn new(host: Option<ScriptHost>) -> Self {
        Self {
            host,
            compiled: RwLock::new(Vec::new()),
        }
    }

    fn get(&self, id: u64) -> Result<ScriptFn> {
        let compiled = self.compiled.read().unwrap_or_else(|e| e.into_inner());
        usize::try_from(id)
            .ok()
            .and_then(|i| compiled.get(i).cloned())
            .ok_or_else(|| {
                Error::stage(
                    "plugin",
                    format!("named script {id}, which the host did not compile for it"),
                )
            })
    }
}

/// Output files a plugin's exporter created, by number.
#[derive(Default)]
struct FileTable {
    open: Mutex<BTreeMap<u64, Box<dyn Write + Send>>>,
    next: AtomicU64,
}

/// What the host offers a plugin during one request.
struct HostCtx<'a, 'f> {
    /// Services are served on the thread that made the request only.
    thread: ThreadId,
    scripts: &'a ScriptTable,
    files: &'a FileTable,
    /// Where new output files are created, while the stage may create them.
    creator: RefCell<Option<&'f mut (dyn OutputFiles + 'f)>>,
}

impl<'a, 'f> HostCtx<'a, 'f> {
    fn new(
        scripts: &'a ScriptTable,
        files: &'a FileTable,
        creator: Option<&'f mut (dyn OutputFiles + 'f)>,
    ) -> Self {
        Self {
            thread: std::thread::current().id(),
            scripts,
            files,
            creator: RefCell::new(creator),
        }
    }

    fn serve(&self, request: HostRequest<'_>) -> Result<HostResponse> {
        let io = |name: String| move |e: std::io::Error| Error::io(name, e);
        match request {
            HostRequest::Compile { spec, origin } => {
                let host = self.scripts.host.as_ref().ok_or_else(|| {
                    Error::stage("plugin", "asked to compile a script outside of building a stage")
                })?;
                let f = host.compile(&spec, origin.map(Into::into))?;
                let mut compiled = self.scripts.compiled.write().unwrap_or_else(|e| e.into_inner());
                compiled.push(f);
                Ok(HostResponse::Script(compiled.len() as u64 - 1))
            }
            HostRequest::Number {
                script,
                args,
                context,
            } => self
                .scripts
                .get(script)?
                .number(&args.args(), &context)
                .map(HostResponse::Number),
            HostRequest::Fractions {
                script,
                args,
                n,
                context,
            } => self
                .scripts
                .get(script)?
                .fractions(&args.args(), n, &context)
                .map(HostResponse::Fractions),
            HostRequest::Create { name } => {
                let mut creator = self.creator.borrow_mut();
                let files = creator.as_mut().ok_or_else(|| {
                    Error::stage(
                        "plugin",
                        format!(
                            "asked to create {} where no output may be created",
                            name.display()
                        ),
                    )
                })?;
                let writer = files.create(&name)?;
                let id = self.files.next.fetch_add(1, Ordering::Relaxed);
                self.files
                    .open
                    .lock()
                    .unwrap_or_else(|e| e.into_inner())
                    .insert(id, writer);
                Ok(HostResponse::File(id))
            }
            HostRequest::Write { file, bytes } => {
                let mut open = self.files.open.lock().unwrap_or_else(|e| e.into_inner());
                let w = open.get_mut(&file).ok_or_else(|| no_file(file))?;
                w.write_all(&bytes).map_err(io(format!("output file {file}")))?;
                Ok(HostResponse::Done)
            }
            HostRequest::Flush { file } => {
                let mut open = self.files.open.lock().unwrap_or_else(|e| e.into_inner());
                let w = open.get_mut(&file).ok_or_else(|| no_file(file))?;
                w.flush().map_err(io(format!("output file {file}")))?;
                Ok(HostResponse::Done)
            }
            HostRequest::Close { file } => {
                let w = self
                    .files
                    .open
                    .lock()
                    .unwrap_or_else(|e| e.into_inner())
                    .remove(&file);
                let mut w = w.ok_or_else(|| no_file(file))?;
                w.flush().map_err(io(format!("output file {file}")))?;
                Ok(HostResponse::Done)
            }
        }
    }
}

fn no_file(file: u64) -> Error {
    Error::stage(
        "plugin",
        format!("wrote to output file {file}, which is not open"),
    )
}

/// Serves a plugin's service request ([`HostApi::call`]).
unsafe extern "C" fn host_call(ctx: *const c_void, request: Bytes, reply: *const ReplySink) -> i32 {
    let answer = catch_unwind(AssertUnwindSafe(|| {
        // SAFETY: `ctx` is the `HostCtx` of the request in progress on this thread
        // (checked next before it is used otherwise): `Library::request` made it and
        // outlives the plugin's call.
        let ctx = unsafe { &*ctx.cast::<HostCtx<'_, '_>>() };
        let result = if std::thread::current().id() != ctx.thread {
            Err(Error::stage(
                "plugin",
                "asked for a host service from a thread of its own; scripts and output files are served on the thread that called the stage",
            ))
        } else {
            // SAFETY: the plugin lends the request bytes for the length of the call.
            let bytes = unsafe { request.as_slice() };
            decode::<HostRequest<'static>>(bytes)
                .map_err(|m| Error::stage("plugin", m))
                .and_then(|r| ctx.serve(r))
        };
        let reply: HostReply = result.map_err(|e| WireError::from(&e));
        encode(&reply).ok()
    }));
    match answer {
        Ok(Some(bytes)) if !reply.is_null() => {
            // SAFETY: the plugin's sink is valid for the call and copies the bytes
            // before returning.
            unsafe { ((*reply).write)((*reply).ctx, Bytes::of(&bytes)) };
            0
        }
        _ => 1,
    }
}

/// A stage (or prepared mesh, or open output) living in a plugin.
struct Remote {
    library: Arc<Library>,
    handle: u64,
    label: Arc<str>,
    scripts: Arc<ScriptTable>,
    files: Arc<FileTable>,
    /// For a discretiser: whether its regions come graded (asked once, when built).
    grades: bool,
    /// Meshes the plugin has been sent, by address: a run's meshes stay where they are
    /// for as long as its stages live.
    meshes_sent: Mutex<HashSet<usize>>,
}

impl Drop for Remote {
    fn drop(&mut self) {
        // SAFETY: `release` is the plugin's, checked with its descriptor; releasing a
        // handle the plugin already dropped (a finished output) does nothing.
        unsafe { (self.library.release)(self.handle) };
    }
}

impl Remote {
    fn request(&self, request: &Request<'_>) -> Result<Response> {
        self.request_with(request, None)
    }

    fn request_with(&self, request: &Request<'_>, files: Option<&mut dyn OutputFiles>) -> Result<Response> {
        let ctx = HostCtx::new(&self.scripts, &self.files, files);
        self.library.request(request, &ctx)
    }

    fn unexpected(&self, r: &Response) -> Error {
        Error::stage(
            self.label.to_string(),
            format!("the plugin answered {}", name_of(r)),
        )
    }

    /// Another object of the same plugin stage (a prepared mesh, an open output).
    fn child(&self, handle: u64) -> Remote {
        Remote {
            library: self.library.clone(),
            handle,
            label: self.label.clone(),
            scripts: self.scripts.clone(),
            files: self.files.clone(),
            grades: false,
            meshes_sent: Mutex::new(HashSet::new()),
        }
    }

    fn family<'a>(&self, ctx: &'a FamilyContext<'a>) -> (WireFamily<'a>, Option<usize>) {
        let mut sent = None;
        let mesh = ctx.mesh.map(|m| {
            let address = std::ptr::from_ref(m) as usize;
            let known = self
                .meshes_sent
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .contains(&address);
            if !known {
                sent = Some(address);
            }
            MeshRef {
                id: address as u64,
                mesh: (!known).then_some(Cow::Borrowed(m)),
            }
        });
        (
            WireFamily {
                info: Cow::Borrowed(ctx.info),
                layer: Cow::Borrowed(ctx.layer),
                tree: Cow::Borrowed(ctx.tree),
                mesh,
                part: ctx.part,
                family: ctx.family,
            },
            sent,
        )
    }

    /// Remembers that the plugin holds a mesh, once a request carrying it succeeded.
    fn mesh_sent(&self, address: Option<usize>) {
        if let Some(a) = address {
            self.meshes_sent
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .insert(a);
        }
    }
}

/// Builds a dynamic plugin's stage: the plugin builds it from the stage's
/// configuration and keeps it; the host gets a proxy.
pub(crate) fn build(
    remote: &RemoteFactory,
    kind: StageKind,
    label: &str,
    config: &StageConfig<'_>,
) -> Result<AnyStage> {
    let scripts = Arc::new(ScriptTable::new(Some(config.scripts.clone())));
    let files = Arc::new(FileTable::default());
    let request = Request::Build {
        stage: remote.index,
        label: Cow::Borrowed(label),
        config: WireConfig {
            table: config.table.to_wire()?,
            base_dir: Cow::Borrowed(config.base_dir),
            machine: config.machine.map(Cow::Borrowed),
            limits: config.limits,
        },
    };
    let handle = match remote
        .library
        .request(&request, &HostCtx::new(&scripts, &files, None))?
    {
        Response::Handle(h) => h,
        other => {
            return Err(Error::stage(
                label.to_string(),
                format!("the plugin answered {}", name_of(&other)),
            ));
        }
    };
    let mut stage = Remote {
        library: remote.library.clone(),
        handle,
        label: label.into(),
        scripts,
        files,
        grades: false,
        meshes_sent: Mutex::new(HashSet::new()),
    };
    if kind == StageKind::Discretise {
        stage.grades = match stage.request(&Request::Grades { handle })? {
            Response::Bool(b) => b,
            other => return Err(stage.unexpected(&other)),
        };
    }
    let b = Box::new(stage);
    Ok(match kind {
        StageKind::Model => AnyStage::Model(b),
        StageKind::Orient => AnyStage::Orient(b),
        StageKind::Slice => AnyStage::Slice(b),
        StageKind::Sort => AnyStage::Sort(b),
        StageKind::Discretise => AnyStage::Discretise(b),
        StageKind::Grade => AnyStage::Grade(b),
        StageKind::Sequence => AnyStage::Sequence(b),
        StageKind::Plan => AnyStage::Plan(b),
        StageKind::Export => AnyStage::Export(b),
    })
}

impl ModelSource for Remote {
    fn load(&self, base_dir: &Path) -> Result<Vec<Mesh>> {
        match self.request(&Request::Load {
            handle: self.handle,
            base_dir: Cow::Borrowed(base_dir),
        })? {
            Response::Meshes(meshes) => Ok(meshes
                .into_iter()
                .map(|w| Mesh {
                    warnings: w.warnings,
                    ..w.mesh
                })
                .collect()),
            other => Err(self.unexpected(&other)),
        }
    }
}

impl Orienter for Remote {
    fn orient(&self, meshes: &[&Mesh]) -> Result<Orientation> {
        match self.request(&Request::Orient {
            handle: self.handle,
            meshes: meshes.iter().map(|m| Cow::Borrowed(*m)).collect(),
        })? {
            Response::Orientation(o) => Ok(o),
            other => Err(self.unexpected(&other)),
        }
    }
}

impl Slicer for Remote {
    fn layers(
        &self,
        meshes: &[Arc<Mesh>],
        info: &RunInfo,
        sequence: Option<&Sequence>,
    ) -> Result<Vec<LayerSlot>> {
        match self.request(&Request::Layers {
            handle: self.handle,
            meshes: meshes.iter().map(|m| Cow::Borrowed(&**m)).collect(),
            info: Cow::Borrowed(info),
            sequence: sequence.map(Cow::Borrowed),
        })? {
            Response::Slots(s) => Ok(s),
            other => Err(self.unexpected(&other)),
        }
    }

    fn prepare(&self, mesh: Arc<Mesh>) -> Result<Box<dyn MeshSlicer>> {
        match self.request(&Request::Prepare {
            handle: self.handle,
            mesh: Cow::Borrowed(&mesh),
        })? {
            Response::Handle(h) => Ok(Box::new(self.child(h))),
            other => Err(self.unexpected(&other)),
        }
    }
}

impl MeshSlicer for Remote {
    fn slice(&self, slot: &LayerSlot) -> Result<Layer> {
        match self.request(&Request::Slice {
            handle: self.handle,
            slot: *slot,
        })? {
            Response::Layer(l) => Ok(l),
            other => Err(self.unexpected(&other)),
        }
    }
}

impl Sorter for Remote {
    fn sort(&self, layer: &Layer) -> Result<ContourTree> {
        match self.request(&Request::Sort {
            handle: self.handle,
            layer: Cow::Borrowed(layer),
        })? {
            Response::Tree(t) => Ok(t),
            other => Err(self.unexpected(&other)),
        }
    }
}

impl Discretiser for Remote {
    fn discretise(&self, ctx: &FamilyContext<'_>) -> Result<Vec<Region>> {
        let (family, sent) = self.family(ctx);
        match self.request(&Request::Discretise {
            handle: self.handle,
            family,
        })? {
            Response::Regions(r) => {
                self.mesh_sent(sent);
                Ok(r)
            }
            other => Err(self.unexpected(&other)),
        }
    }

    fn grades(&self) -> bool {
        self.grades
    }
}

impl Grader for Remote {
    fn grade(&self, ctx: &FamilyContext<'_>, regions: &mut [Region]) -> Result<()> {
        let (family, sent) = self.family(ctx);
        match self.request(&Request::Grade {
            handle: self.handle,
            family,
            regions: Cow::Borrowed(regions),
        })? {
            Response::Regions(r) if r.len() == regions.len() => {
                self.mesh_sent(sent);
                regions.clone_from_slice(&r);
                Ok(())
            }
            Response::Regions(r) => Err(Error::stage(
                self.label.to_string(),
                format!("graded {} regions, it was given {}", r.len(), regions.len()),
            )),
            other => Err(self.unexpected(&other)),
        }
    }
}

impl Sequencer for Remote {
    fn sequence(&self, info: &RunInfo) -> Result<Sequence> {
        match self.request(&Request::Sequence {
            handle: self.handle,
            info: Cow::Borrowed(info),
        })? {
            Response::Sequence(s) => Ok(s),
            other => Err(self.unexpected(&other)),
        }
    }
}

impl Planner for Remote {
    fn plan(&self, info: &RunInfo, plan: &mut LayerPlan) -> Result<()> {
        match self.request(&Request::Plan {
            handle: self.handle,
            info: Cow::Borrowed(info),
            plan: Cow::Borrowed(plan),
        })? {
            Response::Plan(p) => {
                *plan = p;
                Ok(())
            }
            other => Err(self.unexpected(&other)),
        }
    }
}

impl Exporter for Remote {
    fn open(&self, ctx: &mut ExportContext<'_>) -> Result<Box<dyn LayerSink>> {
        let request = Request::Open {
            handle: self.handle,
            export: WireExport {
                info: Cow::Borrowed(ctx.info),
                sequence: ctx.sequence.map(Cow::Borrowed),
                orientation: ctx.orientation.map(Cow::Borrowed),
                layer_count: ctx.layer_count,
                pipeline_name: Cow::Borrowed(ctx.pipeline_name),
            },
        };
        match self.request_with(&request, Some(&mut *ctx.files))? {
            Response::Handle(h) => Ok(Box::new(self.child(h))),
            other => Err(self.unexpected(&other)),
        }
    }
}

impl LayerSink for Remote {
    fn layer(&mut self, info: &RunInfo, plan: &LayerPlan, files: &mut dyn OutputFiles) -> Result<()> {
        self.send_layer(info, plan, files)
    }

    fn finish(self: Box<Self>, info: &RunInfo, files: &mut dyn OutputFiles) -> Result<()> {
        self.send_finish(info, files)
    }
}

impl Remote {
    fn send_layer(&self, info: &RunInfo, plan: &LayerPlan, files: &mut dyn OutputFiles) -> Result<()> {
        let request = Request::Layer {
            handle: self.handle,
            info: Cow::Borrowed(info),
            plan: Cow::Borrowed(plan),
        };
        match self.request_with(&request, Some(files))? {
            Response::Done => Ok(()),
            other => Err(self.unexpected(&other)),
        }
    }

    fn send_finish(&self, info: &RunInfo, files: &mut dyn OutputFiles) -> Result<()> {
        let request = Request::Finish {
            handle: self.handle,
            info: Cow::Borrowed(info),
        };
        match self.request_with(&request, Some(files))? {
            Response::Done => {
                let left = std::mem::take(&mut *self.files.open.lock().unwrap_or_else(|e| e.into_inner()));
                for (file, mut w) in left {
                    w.flush()
                        .map_err(|e| Error::io(format!("output file {file}"), e))?;
                }
                Ok(())
            }
            other => Err(self.unexpected(&other)),
        }
    }
}
