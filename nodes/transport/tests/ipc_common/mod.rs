//! Shared by the iceoryx2 tests.

use std::time::{SystemTime, UNIX_EPOCH};

/// A service prefix no other test run shares (iceoryx2 services are machine-global).
pub fn unique_prefix(test: &str) -> String {
    let nanos = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos());
    format!("rpkm_test_{test}_{}_{nanos}", std::process::id())
}
