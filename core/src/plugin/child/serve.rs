//! The child's side: loads one plugin library and relays the host's frames to it.
//! Nothing is decoded here: the request, reply and service bytes pass through as
//! they are, so the child speaks exactly the boundary the library was built for.

use std::cell::RefCell;
use std::ffi::c_void;
use std::io::{self, BufReader, BufWriter, Read, Write};
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::Path;
use std::thread::ThreadId;

use super::frame;
use crate::plugin::abi::{Bytes, HostApi, ReplySink};

/// The pipes to the host.
struct Pipes {
    input: BufReader<Box<dyn Read>>,
    output: BufWriter<Box<dyn Write>>,
}

/// What the relay's service function is lent during one call.
struct Relay<'a> {
    /// Services are relayed for the thread that made the call only, as in-process.
    thread: ThreadId,
    pipes: &'a RefCell<Pipes>,
}

/// Runs in the child process: loads the plugin library at `path` and serves the host's
/// frames on standard input and output until the input closes. The plugin's own
/// writes to standard output go to standard error, and no core file is written if it
/// crashes. Returns the process's exit code.
pub fn serve(path: &Path) -> i32 {
    let (input, output) = match take_stdio() {
        Ok(pipes) => pipes,
        Err(e) => {
            eprintln!("lamina plugin-host: cannot take its standard streams: {e}");
            return 3;
        }
    };
    contain();
    let pipes = RefCell::new(Pipes {
        input: BufReader::new(input),
        output: BufWriter::new(output),
    });
    let library = match crate::plugin::library::open_library(path, true) {
        Ok(library) => library,
        Err(e) => {
            let reason = match &e {
                crate::Error::Plugin { message, .. } => message.clone(),
                other => other.to_string(),
            };
            let _ = frame::write(&mut pipes.borrow_mut().output, frame::REFUSED, reason.as_bytes());
            return 0;
        }
    };
    if frame::write(
        &mut pipes.borrow_mut().output,
        frame::READY,
        library.name.as_bytes(),
    )
    .is_err()
    {
        return 0;
    }
    loop {
        let next = frame::read(&mut pipes.borrow_mut().input);
        let Ok((kind, bytes)) = next else {
            // The host closed the pipe: its run is over.
            return 0;
        };
        match kind {
            frame::CALL => {
                let relay = Relay {
                    thread: std::thread::current().id(),
                    pipes: &pipes,
                };
                let api = HostApi {
                    ctx: std::ptr::from_ref(&relay).cast(),
                    call: relay_call,
                };
                let answer = library.call_raw(&bytes, &api);
                let mut p = pipes.borrow_mut();
                let sent = match answer {
                    Some(reply) => frame::write(&mut p.output, frame::REPLY, &reply),
                    None => frame::write(&mut p.output, frame::FAILED, &[]),
                };
                if sent.is_err() {
                    return 0;
                }
            }
            frame::RELEASE => {
                if let Ok(handle) = <[u8; 8]>::try_from(bytes.as_slice()) {
                    library.release_raw(u64::from_le_bytes(handle));
                }
            }
            other => {
                eprintln!("lamina plugin-host: the host sent frame {other}, which it does not know");
                return 4;
            }
        }
    }
}

/// Relays a plugin's service request to the host and its answer back.
unsafe extern "C" fn relay_call(ctx: *const c_void, request: Bytes, reply: *const ReplySink) -> i32 {
    let answer = catch_unwind(AssertUnwindSafe(|| {
        // SAFETY: `ctx` is the `Relay` of the call in progress, which outlives it.
        let relay = unsafe { &*ctx.cast::<Relay<'_>>() };
        if std::thread::current().id() != relay.thread {
            return None;
        }
        // SAFETY: the plugin lends the request bytes for the length of the call.
        let bytes = unsafe { request.as_slice() };
        let mut pipes = relay.pipes.try_borrow_mut().ok()?;
        frame::write(&mut pipes.output, frame::SERVICE, bytes).ok()?;
        match frame::read(&mut pipes.input).ok()? {
            (frame::SERVICE_REPLY, answer) if !answer.is_empty() => Some(answer),
            _ => None,
        }
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

/// The host's pipes, moved off descriptors 0 and 1: the plugin's prints go to
/// standard error and its reads find nothing, so neither can corrupt a frame.
#[cfg(unix)]
fn take_stdio() -> io::Result<(Box<dyn Read>, Box<dyn Write>)> {
    use std::os::fd::{FromRawFd, OwnedFd};
    let check = |r: libc::c_int| {
        if r < 0 {
            Err(io::Error::last_os_error())
        } else {
            Ok(r)
        }
    };
    // SAFETY: duplicating the process's own standard descriptors; each new descriptor
    // is owned once, by the `OwnedFd` made of it.
    unsafe {
        let input = OwnedFd::from_raw_fd(check(libc::fcntl(0, libc::F_DUPFD_CLOEXEC, 3))?);
        let output = OwnedFd::from_raw_fd(check(libc::fcntl(1, libc::F_DUPFD_CLOEXEC, 3))?);
        check(libc::dup2(2, 1))?;
        let null = check(libc::open(
            c"/dev/null".as_ptr(),
            libc::O_RDONLY | libc::O_CLOEXEC,
        ))?;
        check(libc::dup2(null, 0))?;
        libc::close(null);
        Ok((
            Box::new(std::fs::File::from(input)),
            Box::new(std::fs::File::from(output)),
        ))
    }
}

#[cfg(not(unix))]
fn take_stdio() -> io::Result<(Box<dyn Read>, Box<dyn Write>)> {
    Ok((Box::new(io::stdin()), Box::new(io::stdout())))
}

/// No core file of a crashing plugin, and no child left behind by a host that was
/// killed.
fn contain() {
    #[cfg(unix)]
    {
        let none = libc::rlimit {
            rlim_cur: 0,
            rlim_max: 0,
        };
        // SAFETY: plain system calls on this process.
        unsafe { libc::setrlimit(libc::RLIMIT_CORE, &none) };
    }
    #[cfg(target_os = "linux")]
    {
        // SAFETY: as above.
        unsafe { libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL) };
    }
}
