//! Starting the nodes one at a time: a node gets the write end of a pipe (its number in
//! `RPKM_READY_FD`) and writes one byte to it at its start-up line, once every endpoint it
//! opens at its start exists (`rpkm_nodes::node::started`). The launch starts the next node
//! only then, or after [`START_WAIT`] with a warning, or when the node ended before. Why: a
//! Fast DDS 2.9 participant running while several RustDDS participants announce their first
//! endpoints may never report some of them (docs/nodes.md, "A Fast DDS participant running
//! while the nodes start").

use std::io::Read;
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};
use std::time::Duration;

use rpkm_nodes::node::started::READY_FD_ENV;
use tokio::process::Command;
use tokio::time::Instant;

/// How long the launch waits for a node's start-up line before it starts the next one.
pub const START_WAIT: Duration = Duration::from_secs(10);

/// How a node's start ended for the launch.
pub enum NodeStart {
    /// It said its start-up line after this long.
    Said(Duration),
    /// Its process ended (or closed the pipe) without saying it.
    Ended,
    /// Nothing within [`START_WAIT`].
    TimedOut,
}

/// The pipe one node's start is signalled on.
pub struct ReadyPipe {
    read: OwnedFd,
    write: OwnedFd,
}

impl ReadyPipe {
    /// A new pipe, both ends closed on exec (the child's copy of the write end is opened in
    /// [`ReadyPipe::pass_to`] only): no other process inherits it.
    pub fn new() -> std::io::Result<Self> {
        let mut fds: [libc::c_int; 2] = [0; 2];
        // SAFETY: pipe2 writes two descriptors into the array it is given.
        if unsafe { libc::pipe2(fds.as_mut_ptr(), libc::O_CLOEXEC) } != 0 {
            return Err(std::io::Error::last_os_error());
        }
        // SAFETY: two descriptors just made, owned by nothing else.
        let (read, write) = unsafe { (OwnedFd::from_raw_fd(fds[0]), OwnedFd::from_raw_fd(fds[1])) };
        Ok(Self { read, write })
    }

    /// Makes the write end the child's: its number in the environment, kept open across
    /// `exec` in the child only.
    pub fn pass_to(&self, cmd: &mut Command) {
        let fd = self.write.as_raw_fd();
        cmd.env(READY_FD_ENV, fd.to_string());
        // SAFETY: the closure runs in the forked child before exec and calls fcntl only,
        // which is async-signal-safe; it changes the child's copy of the descriptor.
        unsafe {
            cmd.pre_exec(move || {
                if libc::fcntl(fd, libc::F_SETFD, 0) == -1 {
                    Err(std::io::Error::last_os_error())
                } else {
                    Ok(())
                }
            });
        }
    }

    /// Waits, once the child runs, for its byte, for the end of its process or for
    /// [`START_WAIT`]. The launch closes its own write end first, so that the child's exit
    /// reads as the end of the pipe. The blocking read runs on a thread of its own: one
    /// left waiting by a timeout ends with the node's process (or the launch).
    pub async fn wait(self) -> NodeStart {
        let Self { read, write } = self;
        drop(write);
        let since = Instant::now();
        let (tx, rx) = tokio::sync::oneshot::channel();
        std::thread::spawn(move || {
            let mut byte = [0u8; 1];
            let said = matches!(std::fs::File::from(read).read(&mut byte), Ok(1));
            // the receiver is gone when the launch stopped waiting
            let _ = tx.send(said);
        });
        match tokio::time::timeout(START_WAIT, rx).await {
            Ok(Ok(true)) => NodeStart::Said(since.elapsed()),
            Ok(_) => NodeStart::Ended,
            Err(_) => NodeStart::TimedOut,
        }
    }
}
