//! End-to-end latency through the real `tcp_estimator` process: an ActuatorState is
//! published here, the node solves the elasto-geometric model (warm-started fegm) and
//! publishes the TcpEstimate of the same seq, which is received here; publish-to-receive on
//! one clock. At 1 kHz and 8 kHz, on a quiet host and with one busy process beside it, in
//! the same run:
//! - `ipc wait`: iceoryx2, the node sleeping until the publisher's wake-up (the default);
//! - `ipc spin`: iceoryx2, the node polling with `yield_now` (`busy_poll_ms: 50`);
//! - `ipc wait rt`: the default with `rt_priority: 50` (SCHED_FIFO; needs root or
//!   CAP_SYS_NICE, else the node says so and it is `ipc wait` again);
//! - `dds`: DDS over loopback, the node waiting the same way.
//!
//! Prints p50/p99/max, samples lost, and the ratios loaded/quiet and DDS/iceoryx2. The
//! bench side publishes on time by polling with `yield_now`.
//!
//! `cargo bench -p rpkm --bench node_latency`. Env `RPKM_BENCH_SECS`: seconds per case
//! (default 2).

use std::process::Command;
use std::time::Duration;

use rpkm_transport::{Backend, Transport, TransportConfig};
use support::{us, Node, Stats};

mod support;

const DDS_DOMAIN: u16 = 62;

/// How the node under test runs.
#[derive(Clone, Copy)]
struct Variant {
    label: &'static str,
    backend: Backend,
    params: &'static [&'static str],
}

const VARIANTS: [Variant; 4] = [
    Variant {
        label: "ipc wait",
        backend: Backend::Ipc,
        params: &[],
    },
    Variant {
        label: "ipc spin",
        backend: Backend::Ipc,
        params: &["busy_poll_ms=50"],
    },
    Variant {
        label: "ipc wait rt",
        backend: Backend::Ipc,
        params: &["rt_priority=50"],
    },
    Variant {
        label: "dds",
        backend: Backend::Dds,
        params: &[],
    },
];

/// A process that keeps one core busy while it lives: the "loaded host" cases.
fn hog() -> std::io::Result<Node> {
    Command::new("sh")
        .args(["-c", "while :; do :; done"])
        .spawn()
        .map(Node)
}

fn run(
    variant: Variant,
    rate_hz: u64,
    secs: f64,
    prefix: &str,
) -> Result<Stats, Box<dyn std::error::Error>> {
    let backend = variant.backend;
    let name = if backend == Backend::Ipc {
        "ipc"
    } else {
        "dds"
    };
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_rpkm"));
    cmd.args([
        "node",
        "tcp_estimator",
        "--backend",
        name,
        "--ipc-prefix",
        prefix,
    ])
    .args(["--domain", &DDS_DOMAIN.to_string()]);
    for p in variant.params {
        cmd.args(["--param", p]);
    }
    let _node = Node(cmd.spawn()?);
    let t = Transport::new(
        &TransportConfig::new(format!("bench_{name}_{rate_hz}"))
            .backend(backend)
            .ipc_prefix(prefix)
            .dds_domain(DDS_DOMAIN),
    )?;
    support::measure(&t, rate_hz, secs)
}

fn main() {
    let (secs, nanos) = (support::case_seconds(), support::run_nanos());
    println!(
        "ActuatorState -> rpkm node tcp_estimator (elastic fegm) -> TcpEstimate, {secs} s per case"
    );
    println!(
        "{:<12} {:>6} {:<6} {:>7} {:>6} {:>10} {:>10} {:>10}",
        "node", "rate", "host", "sent", "lost", "p50 us", "p99 us", "max us"
    );
    let mut results = std::collections::BTreeMap::new();
    for loaded in [false, true] {
        // One busy process beside the two of the case, on a 2-core machine: every core is
        // contended, as on a cell PC doing other work.
        let _hog = if loaded {
            match hog() {
                Ok(h) => Some(h),
                Err(e) => {
                    println!("cannot start the load process: {e}");
                    break;
                }
            }
        } else {
            None
        };
        let host = if loaded { "loaded" } else { "quiet" };
        for rate_hz in [1000u64, 8000] {
            for v in VARIANTS {
                let prefix = format!(
                    "rpkm_nbench_{}_{nanos}_{rate_hz}_{}_{host}",
                    std::process::id(),
                    v.label.replace(' ', "_")
                );
                match run(v, rate_hz, secs, &prefix) {
                    Ok(s) => {
                        println!(
                            "{:<12} {:>4}Hz {:<6} {:>7} {:>6} {:>10.1} {:>10.1} {:>10.1}",
                            v.label,
                            rate_hz,
                            host,
                            s.sent,
                            s.lost,
                            us(s.p50),
                            us(s.p99),
                            us(s.max)
                        );
                        results.insert((v.label, rate_hz, loaded), (s.p50, s.p99));
                    }
                    Err(e) => println!("{:<12} {rate_hz:>4}Hz {host:<6} failed: {e}", v.label),
                }
            }
        }
    }
    let ratio = |a: Duration, b: Duration| a.as_secs_f64() / b.as_secs_f64().max(1e-12);
    for rate_hz in [1000u64, 8000] {
        for loaded in [false, true] {
            let host = if loaded { "loaded" } else { "quiet" };
            if let (Some(i), Some(d)) = (
                results.get(&("ipc wait", rate_hz, loaded)),
                results.get(&("dds", rate_hz, loaded)),
            ) {
                println!(
                    "DDS/iceoryx2 (wait) at {rate_hz} Hz, {host}: p50 x{:.1}, p99 x{:.1}",
                    ratio(d.0, i.0),
                    ratio(d.1, i.1)
                );
            }
        }
        for v in VARIANTS {
            if let (Some(q), Some(l)) = (
                results.get(&(v.label, rate_hz, false)),
                results.get(&(v.label, rate_hz, true)),
            ) {
                println!(
                    "loaded/quiet {} at {rate_hz} Hz: p50 x{:.1}, p99 x{:.1}",
                    v.label,
                    ratio(l.0, q.0),
                    ratio(l.1, q.1)
                );
            }
        }
    }
}
