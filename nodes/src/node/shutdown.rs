//! SIGINT/SIGTERM as a flag: nodes and `rpkm launch` poll [`requested`] in their loops and
//! stop cleanly, so that iceoryx2 removes their shared-memory resources on drop.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};

static STOP: OnceLock<Arc<AtomicBool>> = OnceLock::new();

fn flag() -> &'static Arc<AtomicBool> {
    STOP.get_or_init(|| Arc::new(AtomicBool::new(false)))
}

/// Installs the handler for SIGINT and SIGTERM (idempotent). If a handler cannot be
/// registered the process keeps the default disposition (it dies on the signal), which
/// `rpkm launch` handles like a crash.
pub fn install() {
    static INSTALLED: OnceLock<()> = OnceLock::new();
    INSTALLED.get_or_init(|| {
        for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
            if let Err(e) = signal_hook::flag::register(sig, Arc::clone(flag())) {
                eprintln!("cannot handle signal {sig}: {e}");
            }
        }
    });
}

/// Whether SIGINT or SIGTERM arrived (or [`request`] was called).
pub fn requested() -> bool {
    flag().load(Ordering::Relaxed)
}

/// Asks the loops to stop (as a signal would).
pub fn request() {
    flag().store(true, Ordering::SeqCst);
}
