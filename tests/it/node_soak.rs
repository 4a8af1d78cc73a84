//! The 8 kHz soak through the launched node set (`rpkm bench soak`): no estimate lost, memory
//! of every process printed. Ignored: minutes long, and the actuator stream is best effort,
//! so a host that keeps a node off its core longer than the queue lasts (half a second)
//! loses states by design; run it by hand on a quiet machine:
//!
//!     cargo test -p rpkm --test it node_soak -- --ignored --nocapture
//!
//! `RPKM_SOAK_SECONDS` (default 180) sets the length.
#![expect(
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    reason = "test and benchmark fixtures: counters, stamps and sizes far inside the target type's range"
)]

use std::process::Command;

#[test]
#[ignore = "minutes long; a best-effort stream guarantees nothing on a loaded host"]
fn an_8_khz_stream_loses_no_estimate() {
    let seconds = std::env::var("RPKM_SOAK_SECONDS").unwrap_or_else(|_| "180".into());
    let out = Command::new(env!("CARGO_BIN_EXE_rpkm"))
        .args(["bench", "soak", "--rate-hz", "8000", "--seconds", &seconds])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("run rpkm bench soak");
    let stdout = String::from_utf8_lossy(&out.stdout);
    println!("{stdout}");
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let expected = (seconds.parse::<f64>().expect("seconds") * 8000.0).round() as u64;
    assert!(
        stdout.contains(&format!(
            "estimates received: {expected} of {expected}; lost 0 "
        )),
        "{stdout}"
    );
}
