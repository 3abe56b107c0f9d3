//! The plugin's side of the boundary: compiled into every dynamic plugin (through its
//! own copy of lamina-core), it answers the host's requests with the plugin's stages
//! and forwards the stages' scripts and output files to the host.
//!
//! Stages, prepared meshes and open outputs live here, in a table of handles; the host
//! holds numbers only. Every request runs under this copy's `catch_unwind`, since a
//! panic cannot cross into the host's copy of the standard library.

use std::borrow::Cow;
use std::cell::Cell;
use std::collections::BTreeMap;
use std::io::Write;
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock};

use super::abi::*;
use super::guard_call;
use super::wire::*;
use crate::error::{Error, Result};
use crate::mesh::Mesh;
use crate::model::{LayerPlan, SubRegion};
use crate::planned::PlanDelta;
use crate::registry::StageFactory;
use crate::script::{Compiler, Script, ScriptArgs, ScriptFn, ScriptHost};
use crate::source::Location;
use crate::stage::*;
use crate::table::TableRef;

/// A descriptor in a static of the plugin.
#[derive(Debug)]
pub struct StaticDescriptor(PluginDescriptor);

// SAFETY: the descriptor's pointers point to `'static` string literals, never written;
// its functions may be called from any thread.
unsafe impl Sync for StaticDescriptor {}

impl StaticDescriptor {
    /// The descriptor of the plugin named `name`, built by
    /// [`export_plugin!`](crate::export_plugin).
    pub const fn new(name: &'static str) -> Self {
        Self(PluginDescriptor {
            magic: PLUGIN_MAGIC,
            abi_major: ABI_MAJOR,
            abi_minor: ABI_MINOR,
            struct_size: std::mem::size_of::<PluginDescriptor>(),
            layout: LAYOUT_FINGERPRINT,
            wire: WIRE_FINGERPRINT,
            name: Bytes {
                ptr: name.as_ptr(),
                len: name.len(),
            },
            core_version: Bytes {
                ptr: crate::VERSION.as_ptr(),
                len: crate::VERSION.len(),
            },
            call: guest_call,
            release: guest_release,
        })
    }

    pub fn get(&'static self) -> *const PluginDescriptor {
        &self.0
    }
}

/// What the plugin made for the host.
enum Object {
    Stage {
        label: Arc<str>,
        stage: AnyStage,
        /// Meshes the host sent with family requests, by the host's number.
        meshes: Mutex<BTreeMap<u64, Arc<Mesh>>>,
    },
    MeshSlicer {
        label: Arc<str>,
        slicer: Box<dyn MeshSlicer>,
    },
    Sink {
        label: Arc<str>,
        sink: Mutex<Option<Box<dyn LayerSink>>>,
    },
}

impl Object {
    fn label(&self) -> &str {
        match self {
            Object::Stage { label, .. } | Object::MeshSlicer { label, .. } | Object::Sink { label, .. } => {
                label
            }
        }
    }
}

static OBJECTS: Mutex<BTreeMap<u64, Arc<Object>>> = Mutex::new(BTreeMap::new());
static NEXT_HANDLE: AtomicU64 = AtomicU64::new(1);

fn keep(object: Object) -> u64 {
    let handle = NEXT_HANDLE.fetch_add(1, Ordering::Relaxed);
    OBJECTS
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .insert(handle, Arc::new(object));
    handle
}

fn object(handle: u64) -> Result<Arc<Object>> {
    OBJECTS
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .get(&handle)
        .cloned()
        .ok_or_else(|| {
            Error::stage(
                "plugin",
                format!("the host named stage handle {handle}, which does not exist"),
            )
        })
}

/// The stages this library registered, in a fixed order.
fn stages() -> &'static [&'static StageFactory] {
    static STAGES: OnceLock<Vec<&'static StageFactory>> = OnceLock::new();
    STAGES.get_or_init(|| {
        let mut v: Vec<&'static StageFactory> = inventory::iter::<StageFactory>.into_iter().collect();
        v.sort_by_key(|f| (f.info.kind, f.info.name));
        v
    })
}

thread_local! {
    /// The host's services for the request this thread is handling.
    static HOST: Cell<*const HostApi> = const { Cell::new(std::ptr::null()) };
}

/// Clears [`HOST`] when a request ends, however it ends.
struct HostScope(*const HostApi);

impl HostScope {
    fn enter(host: *const HostApi) -> Self {
        Self(HOST.with(|h| h.replace(host)))
    }
}

impl Drop for HostScope {
    fn drop(&mut self) {
        HOST.with(|h| h.set(self.0));
    }
}

/// Asks the host for a service, from within a request.
fn host_call(request: &HostRequest<'_>) -> Result<HostResponse> {
    let host = HOST.with(Cell::get);
    if host.is_null() {
        return Err(Error::stage(
            "plugin",
            "host services (scripts, output files) are available only on the thread the host called the stage on, during the call",
        ));
    }
    let bytes = encode(request).map_err(|m| Error::stage("plugin", m))?;
    let mut reply: Vec<u8> = Vec::new();
    let sink = ReplySink {
        ctx: (&raw mut reply).cast(),
        write: super::copy_reply,
    };
    // SAFETY: `host` was handed to this thread by the host for the request being
    // handled, which has not returned (the scope clears it); the request bytes and the
    // sink outlive the call.
    let status = unsafe { ((*host).call)((*host).ctx, Bytes::of(&bytes), &sink) };
    if status != 0 {
        return Err(Error::stage(
            "plugin",
            "the host failed to answer a service request",
        ));
    }
    let reply: HostReply = decode(&reply).map_err(|m| Error::stage("plugin", m))?;
    reply.map_err(Error::from)
}

/// The scripts of the host that called into this plugin: every script is compiled and
/// run by the host's engine under the host's limits, whatever copy of a script engine
/// the plugin links.
#[derive(Debug)]
struct HostScripts;

/// A script the host compiled for this plugin, by the host's number.
#[derive(Debug)]
struct HostScript(u64);

impl Compiler for HostScripts {
    fn compile(&self, spec: &str, origin: Option<Location>) -> Result<ScriptFn> {
        compile(spec, origin).map(|id| ScriptFn::new(HostScript(id)))
    }
}

impl Script for HostScript {
    fn number(&self, args: &ScriptArgs<'_>, context: &str) -> Result<f64> {
        number(self.0, args, context)
    }

    fn fractions(&self, args: &ScriptArgs<'_>, n: usize, context: &str) -> Result<Vec<f64>> {
        fractions(self.0, args, n, context)
    }

    fn fractions_batch(
        &self,
        calls: &[ScriptArgs<'_>],
        n: usize,
    ) -> std::result::Result<Vec<Vec<f64>>, (usize, Error)> {
        // Parts are named once each; the calls refer to them by number.
        let mut parts: Vec<Cow<'_, str>> = Vec::new();
        let calls_sent = calls
            .iter()
            .map(|a| {
                let part = match parts.iter().rposition(|p| p == a.part) {
                    Some(i) => i,
                    None => {
                        parts.push(Cow::Borrowed(a.part));
                        parts.len() - 1
                    }
                };
                WireCall(a.r, a.d, a.x, a.y, a.z, a.layer, part)
            })
            .collect();
        // An error that is no call's (the host unreachable, a reply out of place)
        // names no call.
        let nowhere = |e: Error| (calls.len(), e);
        match host_call(&HostRequest::FractionsBatch {
            script: self.0,
            parts,
            calls: calls_sent,
            n,
        })
        .map_err(nowhere)?
        {
            HostResponse::FractionSets(v) if v.len() == calls.len() && v.iter().all(|f| f.len() == n) => {
                Ok(v)
            }
            HostResponse::FailedAt { index, error } if index < calls.len() => {
                Err((index, Error::from(error)))
            }
            other => Err(nowhere(unexpected(&other))),
        }
    }
}

/// Compiles a script with the host's engine.
fn compile(spec: &str, origin: Option<Location>) -> Result<u64> {
    match host_call(&HostRequest::Compile {
        spec: Cow::Borrowed(spec),
        origin: origin.as_ref().map(WireLocation::from),
    })? {
        HostResponse::Script(id) => Ok(id),
        other => Err(unexpected(&other)),
    }
}

/// Runs a host script for a number.
fn number(script: u64, args: &ScriptArgs<'_>, context: &str) -> Result<f64> {
    match host_call(&HostRequest::Number {
        script,
        args: args.into(),
        context: Cow::Borrowed(context),
    })? {
        HostResponse::Number(v) => Ok(v),
        other => Err(unexpected(&other)),
    }
}

/// Runs a host script for fractions.
fn fractions(script: u64, args: &ScriptArgs<'_>, n: usize, context: &str) -> Result<Vec<f64>> {
    match host_call(&HostRequest::Fractions {
        script,
        args: args.into(),
        n,
        context: Cow::Borrowed(context),
    })? {
        HostResponse::Fractions(v) if v.len() == n => Ok(v),
        other => Err(unexpected(&other)),
    }
}

fn unexpected(r: &HostResponse) -> Error {
    Error::stage("plugin", format!("the host answered {r:?} to a service request"))
}

/// Output files created through the host.
struct HostFiles;

impl OutputFiles for HostFiles {
    fn create(&mut self, name: &Path) -> Result<Box<dyn Write + Send>> {
        match host_call(&HostRequest::Create {
            name: Cow::Borrowed(name),
        })? {
            HostResponse::File(file) => Ok(Box::new(std::io::BufWriter::with_capacity(
                1 << 16,
                HostFile { file, closed: false },
            ))),
            other => Err(unexpected(&other)),
        }
    }

    // What the host cannot take in is dropped, as a host that keeps no summary would:
    // neither is part of the file.
    fn report(&mut self, report: crate::stage::MachineFileReport) {
        let _ = host_call(&HostRequest::Report(report));
    }

    fn tell(&mut self, file: &Path, severity: crate::diagnostic::Severity, said: crate::diagnostic::Warning) {
        let _ = host_call(&HostRequest::Tell {
            file: Cow::Borrowed(file),
            severity,
            said,
        });
    }
}

/// An output file the host holds.
struct HostFile {
    file: u64,
    closed: bool,
}

fn io_error(e: Error) -> std::io::Error {
    std::io::Error::other(e.to_string())
}

impl Write for HostFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        host_call(&HostRequest::Write {
            file: self.file,
            bytes: Cow::Borrowed(serde_bytes::Bytes::new(buf)),
        })
        .map_err(io_error)?;
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        host_call(&HostRequest::Flush { file: self.file }).map_err(io_error)?;
        Ok(())
    }
}

impl Drop for HostFile {
    fn drop(&mut self) {
        if !self.closed {
            self.closed = true;
            // Outside a request (the host dropped a failed run's output) there is no
            // host to tell, and nothing of the file is kept.
            let _ = host_call(&HostRequest::Close { file: self.file });
        }
    }
}

/// The entry of every request: decodes it, handles it under `catch_unwind` and writes
/// the reply.
unsafe extern "C" fn guest_call(request: Bytes, host: *const HostApi, reply: *const ReplySink) -> i32 {
    let answer = std::panic::catch_unwind(|| {
        // SAFETY: the host lends the request bytes for the length of the call.
        let bytes = unsafe { request.as_slice() };
        let _scope = HostScope::enter(host);
        let reply: Reply = match decode::<Request<'static>>(bytes) {
            Ok(request) => handle(request).map_err(|e| WireError::from(&e)),
            Err(m) => Err(WireError::from(&Error::stage("plugin", m))),
        };
        encode(&reply).ok()
    });
    match answer {
        Ok(Some(bytes)) if !reply.is_null() => {
            // SAFETY: the host's sink is valid for the call and copies the bytes
            // before returning.
            unsafe { ((*reply).write)((*reply).ctx, Bytes::of(&bytes)) };
            0
        }
        _ => 1,
    }
}

unsafe extern "C" fn guest_release(handle: u64) {
    let _ = std::panic::catch_unwind(|| {
        let removed = OBJECTS.lock().unwrap_or_else(|e| e.into_inner()).remove(&handle);
        drop(removed);
    });
}

fn wrong(o: &Object, what: &str) -> Error {
    Error::stage(
        o.label().to_string(),
        format!("the host asked it to {what}, which it does not do"),
    )
}

/// Runs `f` on the stage behind `handle`; `f` answers `None` when the stage is not of
/// the kind the request is for (`what` the request asked).
fn on_stage<T>(
    handle: u64,
    what: &str,
    f: impl FnOnce(&Object, &AnyStage, &Arc<str>) -> Option<Result<T>>,
) -> Result<T> {
    let o = object(handle)?;
    match &*o {
        Object::Stage { stage, label, .. } => f(&o, stage, label).unwrap_or_else(|| Err(wrong(&o, what))),
        other => Err(wrong(other, what)),
    }
}

/// Grades `regions` (a list per family of `families`) with the grader behind `handle`;
/// the reply holds what grading set, since the host has the rest.
fn grade(
    handle: u64,
    family: WireFamily<'static>,
    families: &[usize],
    mut regions: Vec<Vec<SubRegion>>,
) -> Result<Response> {
    on_stage(handle, "grade", |o, stage, label| match stage {
        AnyStage::Grade(s) => Some(
            with_family(o, family, |ctx| {
                guard_call(label, || s.grade_families(ctx, families, &mut regions))
            })
            .map(|()| Response::Graded(Graded::of_sets(regions))),
        ),
        _ => None,
    })
}

/// Rebuilds a family's context from its message and calls `f` with it.
fn with_family<T>(
    o: &Object,
    family: WireFamily<'static>,
    f: impl FnOnce(&FamilyContext<'_>) -> Result<T>,
) -> Result<T> {
    let Object::Stage { meshes, .. } = o else {
        return Err(wrong(o, "work on a family"));
    };
    let mesh = match family.mesh {
        None => None,
        Some(MeshRef { id, mesh: Some(m) }) => {
            let m = Arc::new(m.into_owned());
            meshes
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .insert(id, m.clone());
            Some(m)
        }
        Some(MeshRef { id, mesh: None }) => Some(
            meshes
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .get(&id)
                .cloned()
                .ok_or_else(|| {
                    Error::stage(
                        o.label().to_string(),
                        format!("the host named mesh {id} before sending it"),
                    )
                })?,
        ),
    };
    // Built once for the call, which covers every family of the part's layer; a tree
    // naming contours the layer lacks is an error here, not a panic.
    let n = family.layer.contours.len();
    if let Some(f) = family
        .tree
        .families
        .iter()
        .find(|f| f.outer >= n || f.holes.iter().any(|&h| h >= n))
    {
        return Err(Error::stage(
            "plugin",
            format!(
                "the host sent a family (outer contour {}) beyond the layer's {n} contours",
                f.outer
            ),
        ));
    }
    let polygons = family.tree.family_polygons(&family.layer.contours);
    let ctx = FamilyContext {
        info: &family.info,
        layer: &family.layer,
        tree: &family.tree,
        polygons: &polygons,
        mesh: mesh.as_deref(),
        part: family.part,
        family: 0,
    };
    f(&ctx)
}

fn handle(request: Request<'static>) -> Result<Response> {
    match request {
        Request::Describe => Ok(describe()),
        Request::Build { stage, label, config } => build(stage, label, config),
        Request::Load { handle, base_dir } => load(handle, &base_dir),
        Request::Orient { handle, meshes } => on_stage(handle, "orient", |_, stage, label| match stage {
            AnyStage::Orient(s) => {
                let refs: Vec<&Mesh> = meshes.iter().map(|m| &**m).collect();
                Some(guard_call(label, || s.orient(&refs)).map(Response::Orientation))
            }
            _ => None,
        }),
        Request::Layers {
            handle,
            meshes,
            info,
            sequence,
        } => on_stage(handle, "choose layers", |_, stage, label| match stage {
            AnyStage::Slice(s) => {
                let meshes: Vec<Arc<Mesh>> = meshes.into_iter().map(|m| Arc::new(m.into_owned())).collect();
                Some(guard_call(label, || s.layers(&meshes, &info, sequence.as_deref())).map(Response::Slots))
            }
            _ => None,
        }),
        Request::Prepare { handle, mesh } => prepare(handle, mesh.into_owned()),
        Request::Slice { handle, slot } => {
            let o = object(handle)?;
            match &*o {
                Object::MeshSlicer { label, slicer } => {
                    guard_call(label, || slicer.slice(&slot)).map(Response::Layer)
                }
                o => Err(wrong(o, "slice a prepared mesh")),
            }
        }
        Request::Sort { handle, layer } => on_stage(handle, "sort", |_, stage, label| match stage {
            AnyStage::Sort(s) => Some(guard_call(label, || s.sort(&layer)).map(Response::Tree)),
            _ => None,
        }),
        Request::Discretise {
            handle,
            family,
            families,
        } => on_stage(handle, "discretise", |o, stage, label| match stage {
            AnyStage::Discretise(s) => Some(
                with_family(o, family, |ctx| {
                    guard_call(label, || s.discretise_families(ctx, &families))
                })
                .map(Response::RegionSets),
            ),
            _ => None,
        }),
        Request::Grade {
            handle,
            family,
            families,
            regions,
        } => grade(handle, family, &families, regions.into_owned()),
        Request::GradeFacts {
            handle,
            family,
            families,
            regions,
        } => {
            let regions = regions
                .into_iter()
                .zip(families.iter())
                .map(|(facts, &f)| facts.into_iter().map(|r| r.region(f)).collect())
                .collect();
            grade(handle, family, &families, regions)
        }
        Request::Sequence { handle, info } => on_stage(handle, "sequence", |_, stage, label| match stage {
            AnyStage::Sequence(s) => Some(guard_call(label, || s.sequence(&info)).map(Response::Sequence)),
            _ => None,
        }),
        Request::Plan { handle, info, plan } => on_stage(handle, "plan", |_, stage, label| match stage {
            AnyStage::Plan(s) => {
                let mut plan = plan.into_owned();
                let before = plan.counts();
                Some(
                    guard_call(label, || s.plan(&info, &mut plan))
                        .map(|()| Response::Planned(PlanDelta::taken(&mut plan, before))),
                )
            }
            _ => None,
        }),
        Request::Process {
            handle,
            info,
            context,
            plan,
        } => process(handle, &info, &context, plan.into_owned()),
        Request::Open { handle, export } => open(handle, &export),
        Request::Layer { handle, info, plan } => write_layer(handle, &info, &plan),
        Request::Finish { handle, info } => finish(handle, &info),
        Request::Grades { handle } => answer(handle, "say whether it grades", |stage| match stage {
            AnyStage::Discretise(s) => Some(s.grades()),
            _ => None,
        }),
        Request::ReadsMesh { handle } => {
            answer(handle, "say whether it reads the mesh", |stage| match stage {
                AnyStage::Discretise(s) => Some(s.reads_mesh()),
                AnyStage::Grade(s) => Some(s.reads_mesh()),
                _ => None,
            })
        }
        Request::ReadsMachine { handle } => {
            answer(handle, "say whether it reads the machine", |stage| match stage {
                AnyStage::Discretise(s) => Some(s.reads_machine()),
                AnyStage::Grade(s) => Some(s.reads_machine()),
                _ => None,
            })
        }
        Request::ReadsGeometry { handle } => {
            answer(handle, "say whether it reads contours", |stage| match stage {
                AnyStage::Grade(s) => Some(s.reads_geometry()),
                _ => None,
            })
        }
        Request::NeedsGradients { handle } => {
            answer(
                handle,
                "say whether it needs the gradients",
                |stage| match stage {
                    AnyStage::Sequence(s) => Some(s.needs_gradients()),
                    _ => None,
                },
            )
        }
        Request::NeedsHigher { handle } => answer(
            handle,
            "say whether it needs the higher regions",
            |stage| match stage {
                AnyStage::Process(s) => Some(s.needs_higher()),
                _ => None,
            },
        ),
    }
}

/// A model source's meshes, each with what its reader repaired beside it.
fn load(handle: u64, base_dir: &Path) -> Result<Response> {
    on_stage(handle, "load a model", |_, stage, label| match stage {
        AnyStage::Model(s) => Some(guard_call(label, || s.load(base_dir)).map(|meshes| {
            Response::Meshes(
                meshes
                    .into_iter()
                    .map(|mut mesh| WireMesh {
                        warnings: std::mem::take(&mut mesh.warnings),
                        mesh,
                    })
                    .collect(),
            )
        })),
        _ => None,
    })
}

/// The plugin's stages as the host lists them: names, documentation, options.
fn describe() -> Response {
    Response::Stages(
        stages()
            .iter()
            .map(|f| WireStage {
                kind: f.info.kind,
                name: f.info.name.to_string(),
                doc: f.info.doc.to_string(),
                options: f
                    .info
                    .options
                    .iter()
                    .map(|o| WireOption {
                        name: o.name.to_string(),
                        ty: o.ty.to_string(),
                        default: o.default.map(ToString::to_string),
                        doc: o.doc.to_string(),
                        required: o.required,
                        range: o.range,
                    })
                    .collect(),
                example: f.info.example.to_string(),
            })
            .collect(),
    )
}

/// Builds stage number `stage` from its pipeline table; its scripts compile in the host.
fn build(stage: usize, label: Cow<'static, str>, config: WireConfig<'static>) -> Result<Response> {
    let factory = stages().get(stage).ok_or_else(|| {
        Error::stage(
            label.to_string(),
            format!("the plugin has no stage number {stage}"),
        )
    })?;
    let table = TableRef::from_wire(config.table)?;
    let scripts = ScriptHost::new(HostScripts);
    let machine = config.machine.map(Cow::into_owned);
    let stage_config = StageConfig {
        table: &table,
        scripts: &scripts,
        base_dir: &config.base_dir,
        reach: &config.reach,
        machine: machine.as_ref(),
        limits: config.limits,
    };
    let stage = guard_call(&label, || (factory.build)(&stage_config))?;
    Ok(Response::Handle(keep(Object::Stage {
        label: label.into(),
        stage,
        meshes: Mutex::new(BTreeMap::new()),
    })))
}

/// A slicer's mesh prepared once; the host slices it layer by layer through the handle.
fn prepare(handle: u64, mesh: Mesh) -> Result<Response> {
    on_stage(handle, "prepare a mesh", |_, stage, label| match stage {
        AnyStage::Slice(s) => Some(guard_call(label, || s.prepare(Arc::new(mesh))).map(|slicer| {
            Response::Handle(keep(Object::MeshSlicer {
                label: label.clone(),
                slicer,
            }))
        })),
        _ => None,
    })
}

/// A question a host asks a stage once, before a run (what it reads and needs); `ask`
/// answers `None` when the stage is not of the kind the question is for.
fn answer(handle: u64, what: &str, ask: impl FnOnce(&AnyStage) -> Option<bool>) -> Result<Response> {
    on_stage(handle, what, |_, stage, label| {
        match guard_call(label, || Ok(ask(stage))) {
            Ok(reply) => reply.map(|b| Ok(Response::Bool(b))),
            Err(e) => Some(Err(e)),
        }
    })
}

/// A process stage's operations on one layer, sent back as what it added.
fn process(handle: u64, info: &RunInfo, context: &WireProcess<'_>, mut plan: LayerPlan) -> Result<Response> {
    on_stage(handle, "plan its operations", |_, stage, label| match stage {
        AnyStage::Process(s) => {
            let ctx = ProcessContext {
                info,
                sequence: context.sequence.as_deref(),
                surfaces: &context.surfaces,
                higher: &context.higher,
                last: context.last,
            };
            let before = plan.counts();
            Some(
                guard_call(label, || s.process(&ctx, &mut plan))
                    .map(|()| Response::Planned(PlanDelta::taken(&mut plan, before))),
            )
        }
        _ => None,
    })
}

/// Opens an exporter's output; its files are written through the host.
fn open(handle: u64, export: &WireExport<'_>) -> Result<Response> {
    on_stage(handle, "open an output", |_, stage, label| match stage {
        AnyStage::Export(s) => {
            let mut files = HostFiles;
            let mut ctx = ExportContext {
                info: &export.info,
                sequence: export.sequence.as_deref(),
                orientation: export.orientation.as_deref(),
                layer_count: export.layer_count,
                pipeline_name: &export.pipeline_name,
                files: &mut files,
            };
            Some(guard_call(label, || s.open(&mut ctx)).map(|sink| {
                Response::Handle(keep(Object::Sink {
                    label: label.clone(),
                    sink: Mutex::new(Some(sink)),
                }))
            }))
        }
        _ => None,
    })
}

/// One layer written to an open output.
fn write_layer(handle: u64, info: &RunInfo, plan: &LayerPlan) -> Result<Response> {
    let o = object(handle)?;
    match &*o {
        Object::Sink { label, sink } => {
            let mut sink = sink.lock().unwrap_or_else(|e| e.into_inner());
            let sink = sink
                .as_mut()
                .ok_or_else(|| Error::stage(label.to_string(), "output already finished"))?;
            guard_call(label, || sink.layer(info, plan, &mut HostFiles))?;
            Ok(Response::Done)
        }
        o => Err(wrong(o, "write a layer")),
    }
}

/// Finishes an output and forgets its handle, whether it finished or failed.
fn finish(handle: u64, info: &RunInfo) -> Result<Response> {
    let o = object(handle)?;
    let result = match &*o {
        Object::Sink { label, sink } => {
            let taken = sink.lock().unwrap_or_else(|e| e.into_inner()).take();
            let sink = taken.ok_or_else(|| Error::stage(label.to_string(), "output already finished"))?;
            guard_call(label, || sink.finish(info, &mut HostFiles)).map(|()| Response::Done)
        }
        o => Err(wrong(o, "finish an output")),
    };
    OBJECTS.lock().unwrap_or_else(|e| e.into_inner()).remove(&handle);
    result
}
