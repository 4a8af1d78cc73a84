//! Does the calibrator's online tracker delay the 8 kHz estimator? End-to-end latency through
//! the real `tcp_estimator` process (ActuatorState published here, TcpEstimate of the same seq
//! received here, one clock), at 8 kHz over iceoryx2, with a `calibrator` process beside it on
//! the same topics, its online tracker off, on at its default decimation (1 state in 100: 80 Hz)
//! and on at 1 in 8 (1 kHz, to load it), side by side with the ratios.
//!
//! `cargo bench -p rpkm --bench online_latency` (or `cargo test --bench online_latency` in the
//! optimised test profile). Env `RPKM_BENCH_SECS`: seconds per case (default 2).

use std::process::Command;
use std::time::Duration;

use rpkm_transport::{Backend, Transport, TransportConfig};
use support::{us, Node, Stats};

mod support;

fn run(
    online: Option<u64>,
    rate_hz: u64,
    secs: f64,
    prefix: &str,
) -> Result<Stats, Box<dyn std::error::Error>> {
    let backend = Backend::Ipc;
    let name = "ipc";
    let node = |which: &str, params: &[String]| -> std::io::Result<Node> {
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_rpkm"));
        cmd.args(["node", which, "--backend", "ipc", "--ipc-prefix", prefix]);
        for p in params {
            cmd.args(["--param", p]);
        }
        cmd.spawn().map(Node)
    };
    let _calibrator = node(
        "calibrator",
        &[
            format!("online={}", online.is_some()),
            format!("online_decimation={}", online.unwrap_or(100)),
        ],
    )?;
    let _node = node("tcp_estimator", &[])?;
    let t = Transport::new(
        &TransportConfig::new(format!("bench_{name}_{rate_hz}"))
            .backend(backend)
            .ipc_prefix(prefix),
    )?;
    support::measure(&t, rate_hz, secs)
}

fn main() {
    let (secs, nanos) = (support::case_seconds(), support::run_nanos());
    println!("ActuatorState -> tcp_estimator -> TcpEstimate at 8 kHz, calibrator beside it, {secs} s per case");
    println!(
        "{:<22} {:>7} {:>6} {:>10} {:>10} {:>10}",
        "calibrator", "sent", "lost", "p50 us", "p99 us", "max us"
    );
    let mut got = Vec::new();
    for online in [None, Some(100), Some(8)] {
        let prefix = format!(
            "rpkm_obench_{}_{nanos}_{}",
            std::process::id(),
            online.unwrap_or(0)
        );
        let label = match online {
            None => "online tracker off".to_owned(),
            Some(d) => format!("on, 1 state in {d}"),
        };
        match run(online, 8000, secs, &prefix) {
            Ok(s) => {
                println!(
                    "{label:<22} {:>7} {:>6} {:>10.1} {:>10.1} {:>10.1}",
                    s.sent,
                    s.lost,
                    us(s.p50),
                    us(s.p99),
                    us(s.max)
                );
                got.push((s.p50, s.p99));
            }
            Err(e) => println!("{label:<22} failed: {e}"),
        }
    }
    if let [off, on, stress] = got[..] {
        let r = |a: Duration, b: Duration| a.as_secs_f64() / b.as_secs_f64().max(1e-12);
        println!(
            "on/off (1 in 100, 80 Hz): p50 x{:.2}, p99 x{:.2}",
            r(on.0, off.0),
            r(on.1, off.1)
        );
        println!(
            "on/off (1 in 8, 1 kHz): p50 x{:.2}, p99 x{:.2}",
            r(stress.0, off.0),
            r(stress.1, off.1)
        );
    }
}
