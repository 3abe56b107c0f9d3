//! The host's side of the boundary: loads a plugin library, and stands in for each of
//! its stages with a proxy that turns every trait call into a [`Request`] and the
//! [`Reply`] back into values. It also serves the plugin's [`HostRequest`]s: scripts
//! compiled and run by the host's engine under the host's limits, and output files
//! created through the run's atomic output.

mod remote;

pub(crate) use remote::build;

use std::cell::RefCell;
use std::collections::BTreeMap;
use std::ffi::c_void;
use std::io::Write;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, RwLock};
use std::thread::ThreadId;

use super::abi::*;
use super::child::{Answer, Link};
use super::copy_reply;
use super::refusal::refuse;
use super::wire::*;
use crate::error::{Error, Result};
use crate::registry::StageFactory;
use crate::script::{ScriptArgs, ScriptFn, ScriptHost};
use crate::stage::*;

/// A loaded plugin library. Never unloaded, since a library's thread-local
/// destructors and statics may run until the process ends.
#[derive(Debug)]
pub struct Library {
    pub path: PathBuf,
    pub name: String,
    /// The plugin's ABI minor version: it is sent only requests of that minor or older.
    pub minor: u32,
    transport: Transport,
}

/// How requests reach a library.
#[derive(Debug)]
enum Transport {
    /// Its two functions, in this process.
    InProcess {
        call: unsafe extern "C" fn(Bytes, *const HostApi, *const ReplySink) -> i32,
        release: unsafe extern "C" fn(u64),
    },
    /// A child process that loaded it.
    Child(Link),
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
            minor: d.abi_minor,
            transport: Transport::InProcess {
                call: d.call,
                release: d.release,
            },
        })
    }

    /// A library that a child process loaded, reached through `link`.
    pub(crate) fn child(path: &Path, name: String, minor: u32, link: Link) -> Self {
        Self {
            path: path.to_path_buf(),
            name,
            minor,
            transport: Transport::Child(link),
        }
    }

    /// Why the library's child process is no longer served, if it is not.
    pub(crate) fn stopped(&self) -> Option<String> {
        match &self.transport {
            Transport::InProcess { .. } => None,
            Transport::Child(link) => link.stopped(),
        }
    }

    /// Calls an in-process library with request bytes and the host functions `api`,
    /// giving its reply bytes, or `None` if it failed without a reply. (A child
    /// process relays its host's frames with this.)
    pub(crate) fn call_raw(&self, request: &[u8], api: &HostApi) -> Option<Vec<u8>> {
        let Transport::InProcess { call, .. } = &self.transport else {
            return None;
        };
        let mut reply: Vec<u8> = Vec::new();
        let sink = ReplySink {
            ctx: (&raw mut reply).cast(),
            write: copy_reply,
        };
        // SAFETY: `call` is the plugin's entry, checked to have this ABI and layout;
        // the request bytes, `api` (and the context it points to) and the sink all
        // outlive the call, and the plugin copies nothing of them past it.
        let status = unsafe { call(Bytes::of(request), api, &sink) };
        (status == 0).then_some(reply)
    }

    /// Tells the library that the host no longer needs `handle`.
    pub(crate) fn release_raw(&self, handle: u64) {
        match &self.transport {
            // SAFETY: `release` is the plugin's, checked with its descriptor; releasing a
            // handle the plugin already dropped (a finished output) does nothing.
            Transport::InProcess { release, .. } => unsafe { release(handle) },
            Transport::Child(link) => link.release(handle),
        }
    }

    fn error(&self, message: impl Into<String>) -> Error {
        refuse(&self.path, format!("plugin `{}`: {}", self.name, message.into()))
    }

    /// Sends one request for the stage `label` and waits for its reply, serving the
    /// plugin's service requests with `ctx` meanwhile.
    fn request(&self, label: &str, request: &Request<'_>, ctx: &HostCtx<'_, '_>) -> Result<Response> {
        let bytes = encode(request).map_err(|m| self.error(m))?;
        let reply = match &self.transport {
            Transport::InProcess { .. } => {
                let api = HostApi {
                    ctx: std::ptr::from_ref(ctx).cast(),
                    call: host_call,
                };
                self.call_raw(&bytes, &api)
            }
            Transport::Child(link) => match link.call(&bytes, &mut |b| answer(ctx, b).unwrap_or_default()) {
                Ok(Answer::Reply(r)) => Some(r),
                Ok(Answer::Failed) => None,
                Err(reason) => {
                    return Err(Error::stage(
                        label,
                        format!("plugin `{}` ({}) {reason}", self.name, self.path.display()),
                    ));
                }
            },
        };
        let reply = reply.ok_or_else(|| self.error("failed without a reply (it could not encode one)"))?;
        let reply: Reply = decode(&reply).map_err(|m| self.error(m))?;
        reply.map_err(Error::from)
    }

    /// Asks for the library's stages and makes a registry factory of each.
    pub(crate) fn describe(self: &Arc<Self>) -> Result<Vec<(&'static StageFactory, RemoteFactory)>> {
        let scripts = ScriptTable::new(None);
        let files = FileTable::default();
        let stages = match self.request(
            "plugin",
            &Request::Describe,
            &HostCtx::new(&scripts, &files, None),
        )? {
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
                        required: o.required,
                        range: o.range,
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
        Response::RegionSets(_) => "regions",
        Response::Bool(_) => "a yes or no",
        Response::Sequence(_) => "a sequence",
        Response::Planned(_) => "a plan",
        Response::Done => "done",
        Response::Graded(_) => "compositions",
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
            HostRequest::FractionsEach { script, calls, n } => {
                let f = self.scripts.get(script)?;
                calls
                    .iter()
                    .map(|(args, context)| f.fractions(&args.args(), n, context))
                    .collect::<Result<Vec<_>>>()
                    .map(HostResponse::FractionSets)
            }
            HostRequest::FractionsBatch {
                script,
                parts,
                calls,
                n,
            } => {
                let f = self.scripts.get(script)?;
                let args = calls
                    .iter()
                    .map(|c| {
                        let part = parts.get(c.6).ok_or_else(|| {
                            Error::stage(
                                "plugin",
                                format!("named part {} of a script call, of {} sent", c.6, parts.len()),
                            )
                        })?;
                        Ok(ScriptArgs {
                            r: c.0,
                            d: c.1,
                            x: c.2,
                            y: c.3,
                            z: c.4,
                            layer: c.5,
                            part,
                        })
                    })
                    .collect::<Result<Vec<_>>>()?;
                Ok(match f.fractions_batch(&args, n) {
                    Ok(sets) => HostResponse::FractionSets(sets),
                    Err((index, e)) if index < args.len() => HostResponse::FailedAt {
                        index,
                        error: WireError::from(&e),
                    },
                    Err((_, e)) => return Err(e),
                })
            }
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
            HostRequest::Tell { file, severity, said } => {
                if let Some(files) = self.creator.borrow_mut().as_mut() {
                    files.tell(&file, severity, said);
                }
                Ok(HostResponse::Done)
            }
            HostRequest::Report(report) => {
                if let Some(files) = self.creator.borrow_mut().as_mut() {
                    files.report(report);
                }
                Ok(HostResponse::Done)
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

/// The encoded answer to a plugin's encoded service request, or `None` if it cannot
/// be encoded.
fn answer(ctx: &HostCtx<'_, '_>, bytes: &[u8]) -> Option<Vec<u8>> {
    let result = if std::thread::current().id() != ctx.thread {
        Err(Error::stage(
            "plugin",
            "asked for a host service from a thread of its own; scripts and output files are served on the thread that called the stage",
        ))
    } else {
        decode::<HostRequest<'static>>(bytes)
            .map_err(|m| Error::stage("plugin", m))
            .and_then(|r| ctx.serve(r))
    };
    let reply: HostReply = result.map_err(|e| WireError::from(&e));
    encode(&reply).ok()
}

/// Serves a plugin's service request ([`HostApi::call`]).
unsafe extern "C" fn host_call(ctx: *const c_void, request: Bytes, reply: *const ReplySink) -> i32 {
    let answer = catch_unwind(AssertUnwindSafe(|| {
        // SAFETY: `ctx` is the `HostCtx` of the request in progress: `Library::request`
        // made it and outlives the plugin's call (`answer` checks the thread before
        // the context is used otherwise).
        let ctx = unsafe { &*ctx.cast::<HostCtx<'_, '_>>() };
        // SAFETY: the plugin lends the request bytes for the length of the call.
        answer(ctx, unsafe { request.as_slice() })
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::script::ScriptLimits;
    use std::borrow::Cow;

    /// The host's answer to a plugin's service request, as the bytes a plugin reads.
    fn served(request: &HostRequest<'_>) -> HostReply {
        let scripts = ScriptTable::new(Some(crate::script::local(".", ScriptLimits::default())));
        let files = FileTable::default();
        let ctx = HostCtx::new(&scripts, &files, None);
        // What `Compile` gives the script the calls name.
        let compile = HostRequest::Compile {
            spec: Cow::Borrowed("if r > 0.75 { 2.0 } else { r }"),
            origin: None,
        };
        let reply: HostReply =
            decode(&answer(&ctx, &encode(&compile).expect("encodes")).expect("a reply")).expect("decodes");
        assert!(matches!(reply, Ok(HostResponse::Script(0))), "{reply:?}");
        decode(&answer(&ctx, &encode(request).expect("encodes")).expect("a reply")).expect("decodes")
    }

    fn call(r: f64, part: usize) -> WireCall {
        WireCall(r, 0.0, 1.0, 2.0, 3.0, 4, part)
    }

    /// A batch without contexts answers each call, or names the call that failed so
    /// that the plugin describes it; the parts are named once.
    #[test]
    fn a_batch_names_the_call_that_failed() {
        let parts = vec![Cow::Borrowed("a"), Cow::Borrowed("b")];
        let batch = |calls| HostRequest::FractionsBatch {
            script: 0,
            parts: parts.clone(),
            calls,
            n: 2,
        };
        match served(&batch(vec![call(0.25, 0), call(0.5, 1)])) {
            Ok(HostResponse::FractionSets(sets)) => assert_eq!(sets, vec![vec![0.25, 0.75], vec![0.5, 0.5]]),
            other => panic!("{other:?}"),
        }
        match served(&batch(vec![
            call(0.25, 0),
            call(0.5, 1),
            call(1.0, 0),
            call(0.0, 0),
        ])) {
            Ok(HostResponse::FailedAt { index, error }) => {
                assert_eq!(index, 2);
                let e = Error::from(error);
                assert!(e.to_string().contains("outside [0, 1]"), "{e}");
                // The plugin says what the call computed.
                assert!(
                    e.in_context("region 7".into())
                        .to_string()
                        .contains("(while grading region 7)"),
                );
            }
            other => panic!("{other:?}"),
        }
        // A call naming a part that was not sent is the plugin's error.
        let e = served(&batch(vec![call(0.25, 2)])).expect_err("refused");
        assert!(
            Error::from(e)
                .to_string()
                .contains("named part 2 of a script call, of 2 sent")
        );
    }

    /// A plugin of ABI 7.0 or 7.1 asks with a context for each call: it is still
    /// served, and its errors carry the context it gave.
    #[test]
    fn an_older_plugins_batch_with_contexts_is_served() {
        let args = |r| WireArgs {
            r,
            d: 0.0,
            x: 0.0,
            y: 0.0,
            z: 0.0,
            layer: 0,
            part: Cow::Borrowed("p"),
        };
        let each = |calls| HostRequest::FractionsEach {
            script: 0,
            calls,
            n: 2,
        };
        match served(&each(vec![(args(0.5), Cow::Borrowed("one"))])) {
            Ok(HostResponse::FractionSets(sets)) => assert_eq!(sets, vec![vec![0.5, 0.5]]),
            other => panic!("{other:?}"),
        }
        let e = served(&each(vec![
            (args(0.5), Cow::Borrowed("one")),
            (args(0.9), Cow::Borrowed("two")),
        ]))
        .expect_err("fails");
        assert!(Error::from(e).to_string().contains("(while grading two)"));
    }
}
