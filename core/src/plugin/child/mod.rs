//! Plugins in a child process: the library is loaded by a process of its own (the
//! `lamina plugin-host` command, which ends in [`serve`]), and the same request and
//! reply bytes travel over its standard input and output, framed ([`frame`]). A
//! segfault, abort or hang there ends the child, not the run: the call fails with an
//! error naming the plugin, and the run fails cleanly. The plugin's calls are served
//! one at a time, so this mode trades the speed of parallel layers for containment.

mod frame;
mod serve;

pub use serve::serve;

use std::ffi::OsString;
use std::io::{self, BufReader, BufWriter};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, ExitStatus, Stdio};
use std::sync::Mutex;
use std::sync::mpsc::{Receiver, RecvTimeoutError, channel};
use std::time::{Duration, Instant};

use super::refusal::refuse;
use crate::error::Result;

/// Where a plugin library's code runs.
#[derive(Debug, Clone, Default, PartialEq)]
pub enum Isolation {
    /// Loaded into this process: calls cost a copy of their messages, and layers call
    /// the plugin in parallel; a crash in the plugin is a crash of the process.
    #[default]
    InProcess,
    /// Loaded by a child process: a crash or hang of the plugin is an error of the
    /// run, and the plugin's calls are served one at a time.
    Child(ChildProgram),
}

/// The command that loads a plugin in a child process: `program args… LIBRARY`. It
/// must end in [`serve`], as `lamina plugin-host` does.
#[derive(Debug, Clone, PartialEq)]
pub struct ChildProgram {
    pub program: PathBuf,
    pub args: Vec<OsString>,
    /// How long the plugin may go without answering (a call, or its next service
    /// request within one) before its process is stopped.
    pub timeout: Duration,
}

impl ChildProgram {
    /// The time a plugin may go without answering, unless the caller says otherwise.
    pub const DEFAULT_TIMEOUT: Duration = Duration::from_secs(60);

    /// This very program, run as `<this program> args… LIBRARY`.
    pub fn this(args: &[&str]) -> io::Result<Self> {
        Ok(Self {
            program: std::env::current_exe()?,
            args: args.iter().map(OsString::from).collect(),
            timeout: Self::DEFAULT_TIMEOUT,
        })
    }
}

/// The host's end of a child plugin process.
#[derive(Debug)]
pub(crate) struct Link {
    timeout: Duration,
    state: Mutex<State>,
}

#[derive(Debug)]
struct State {
    child: Child,
    to_child: Option<BufWriter<ChildStdin>>,
    /// Frames read by a thread of their own, so that waiting for one can time out.
    from_child: Receiver<io::Result<(u8, Vec<u8>)>>,
    /// Why the child is no longer served (it crashed, hung or broke the protocol).
    stopped: Option<String>,
}

/// What a call through a [`Link`] came to.
pub(crate) enum Answer {
    Reply(Vec<u8>),
    /// The plugin's call returned a failure without a reply.
    Failed,
}

impl Link {
    /// Starts `program` on the library at `path` and waits for it to load it, giving
    /// the link and the plugin's name. A library the child refuses is refused here
    /// with the child's reason.
    pub(crate) fn spawn(program: &ChildProgram, path: &Path) -> Result<(Link, String)> {
        let mut child = Command::new(&program.program)
            .args(&program.args)
            .arg(path)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .map_err(|e| {
                refuse(
                    path,
                    format!(
                        "cannot start a process to load it ({}): {e}",
                        program.program.display()
                    ),
                )
            })?;
        let (Some(stdin), Some(stdout)) = (child.stdin.take(), child.stdout.take()) else {
            let _ = child.kill();
            return Err(refuse(path, "its process has no pipes"));
        };
        let (send, from_child) = channel();
        std::thread::Builder::new()
            .name("lamina-plugin-reader".into())
            .spawn(move || {
                let mut input = BufReader::new(stdout);
                loop {
                    let frame = frame::read(&mut input);
                    let end = frame.is_err();
                    if send.send(frame).is_err() || end {
                        break;
                    }
                }
            })
            .map_err(|e| refuse(path, format!("cannot start a thread to read its process: {e}")))?;
        let link = Link {
            timeout: program.timeout,
            state: Mutex::new(State {
                child,
                to_child: Some(BufWriter::new(stdin)),
                from_child,
                stopped: None,
            }),
        };
        let mut state = link.lock();
        let ready = link.next(&mut state);
        let name = match ready {
            Ok((frame::READY, name)) => String::from_utf8_lossy(&name).into_owned(),
            Ok((frame::REFUSED, reason)) => {
                link.stop(&mut state, "refused".into());
                return Err(refuse(path, String::from_utf8_lossy(&reason)));
            }
            Ok((kind, _)) => {
                let reason = format!("its process answered frame {kind} before loading it");
                link.stop(&mut state, reason.clone());
                return Err(refuse(path, reason));
            }
            Err(reason) => return Err(refuse(path, format!("its process could not load it: {reason}"))),
        };
        drop(state);
        Ok((link, name))
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Why the child is no longer served, if it is not.
    pub(crate) fn stopped(&self) -> Option<String> {
        self.lock().stopped.clone()
    }

    /// Sends a request and waits for its reply, answering the plugin's service
    /// requests with `service` meanwhile. An error is why the child is no longer
    /// served: it crashed, hung, or broke the protocol.
    pub(crate) fn call(
        &self,
        request: &[u8],
        service: &mut dyn FnMut(&[u8]) -> Vec<u8>,
    ) -> std::result::Result<Answer, String> {
        let mut state = self.lock();
        self.send(&mut state, frame::CALL, request)?;
        loop {
            match self.next(&mut state)? {
                (frame::REPLY, bytes) => return Ok(Answer::Reply(bytes)),
                (frame::FAILED, _) => return Ok(Answer::Failed),
                (frame::SERVICE, bytes) => {
                    let answer = service(&bytes);
                    self.send(&mut state, frame::SERVICE_REPLY, &answer)?;
                }
                (kind, _) => {
                    let reason = format!("its process sent frame {kind} during a call");
                    self.stop(&mut state, reason.clone());
                    return Err(reason);
                }
            }
        }
    }

    /// Tells the child that the host no longer needs `handle`. A child no longer
    /// served has nothing to release.
    pub(crate) fn release(&self, handle: u64) {
        let mut state = self.lock();
        if state.stopped.is_none() {
            let _ = self.send(&mut state, frame::RELEASE, &handle.to_le_bytes());
        }
    }

    fn send(&self, state: &mut State, kind: u8, bytes: &[u8]) -> std::result::Result<(), String> {
        if let Some(reason) = &state.stopped {
            return Err(reason.clone());
        }
        let sent = match state.to_child.as_mut() {
            Some(w) => frame::write(w, kind, bytes),
            None => Err(io::Error::from(io::ErrorKind::BrokenPipe)),
        };
        sent.map_err(|e| {
            let reason = match e.kind() {
                io::ErrorKind::InvalidInput => e.to_string(),
                _ => self.ended(state),
            };
            self.stop(state, reason.clone());
            reason
        })
    }

    /// The next frame from the child, within the timeout.
    fn next(&self, state: &mut State) -> std::result::Result<(u8, Vec<u8>), String> {
        if let Some(reason) = &state.stopped {
            return Err(reason.clone());
        }
        match state.from_child.recv_timeout(self.timeout) {
            Ok(Ok(frame)) => Ok(frame),
            Err(RecvTimeoutError::Timeout) => {
                let reason = format!(
                    "did not answer within {} s, and its process was stopped",
                    self.timeout.as_secs_f64()
                );
                self.stop(state, reason.clone());
                Err(reason)
            }
            Ok(Err(_)) | Err(RecvTimeoutError::Disconnected) => {
                let reason = self.ended(state);
                self.stop(state, reason.clone());
                Err(reason)
            }
        }
    }

    /// How the child's process ended, once its output closed: it is given the timeout
    /// to exit, and stopped after it.
    fn ended(&self, state: &mut State) -> String {
        state.to_child = None;
        let deadline = Instant::now() + self.timeout;
        loop {
            match state.child.try_wait() {
                Ok(Some(status)) => return describe(status),
                Ok(None) if Instant::now() < deadline => std::thread::sleep(Duration::from_millis(5)),
                Ok(None) => {
                    let _ = state.child.kill();
                    return "closed its output without exiting, and its process was stopped".into();
                }
                Err(e) => return format!("its process cannot be waited for: {e}"),
            }
        }
    }

    fn stop(&self, state: &mut State, reason: String) {
        state.to_child = None;
        let _ = state.child.kill();
        let _ = state.child.wait();
        state.stopped.get_or_insert(reason);
    }
}

/// "crashed: …" or "exited …", for a child process that ended during a call.
fn describe(status: ExitStatus) -> String {
    #[cfg(unix)]
    {
        use std::os::unix::process::ExitStatusExt;
        if let Some(signal) = status.signal() {
            let name = match signal {
                4 => " (SIGILL, an illegal instruction)",
                6 => " (SIGABRT, an abort: a panic built with `panic = \"abort\"`, or a failed check)",
                7 => " (SIGBUS, a bad memory access)",
                8 => " (SIGFPE, an arithmetic fault)",
                9 => " (SIGKILL)",
                11 => " (SIGSEGV, an invalid memory access)",
                _ => "",
            };
            return format!("crashed: its process was killed by signal {signal}{name}");
        }
    }
    match status.code() {
        Some(code) => format!("ended: its process exited with status {code} during a call"),
        None => "ended: its process exited during a call".into(),
    }
}
