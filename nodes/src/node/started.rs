//! The signal a node gives `rpkm launch` at its start-up line: the launch starts its nodes one
//! at a time, each once the one before has created every endpoint it opens at its start (a
//! Fast DDS 2.9 participant that runs while several RustDDS participants announce their
//! first endpoints may never report some of them: docs/nodes.md, "A Fast DDS participant
//! running while the nodes start"). The launch passes the write end of a pipe in
//! [`READY_FD_ENV`]; the node writes one byte to it and closes it. A node started otherwise
//! has no such variable and does nothing.

use std::sync::Once;

/// The variable naming the file descriptor of the launch's pipe.
pub const READY_FD_ENV: &str = "RPKM_READY_FD";

/// Writes the byte once, whichever node calls it how often: a second call must not write
/// to a descriptor number that may name another file by then.
pub fn tell_launch() {
    static DONE: Once = Once::new();
    DONE.call_once(|| {
        let Some(fd) = std::env::var(READY_FD_ENV)
            .ok()
            .and_then(|v| v.parse::<libc::c_int>().ok())
        else {
            return;
        };
        // Only a pipe: a stale variable (a shell that inherited it) must not make the node
        // write into whatever file has that number.
        // SAFETY: fstat fills `st`, a plain struct, for any descriptor number; an invalid
        // one fails with EBADF.
        let mut st: libc::stat = unsafe { std::mem::zeroed() };
        if unsafe { libc::fstat(fd, &raw mut st) } != 0
            || st.st_mode & libc::S_IFMT != libc::S_IFIFO
        {
            return;
        }
        // SAFETY: one byte from a live buffer to a descriptor checked above, then closed:
        // nothing else in this process uses it (the launch made it for this byte only).
        unsafe {
            libc::write(fd, b"\n".as_ptr().cast(), 1);
            libc::close(fd);
        }
    });
}
