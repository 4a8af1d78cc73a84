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

use std::process::{Child, Command};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use rpkm_core::geometry::igm;
use rpkm_core::params::{Model, Params};
use rpkm_msgs::ActuatorState;
use rpkm_transport::{topic, Backend, Transport, TransportConfig};

const DDS_DOMAIN: u16 = 62;

struct Stats {
    sent: usize,
    lost: usize,
    p50: Duration,
    p99: Duration,
    max: Duration,
}

struct Node(Child);

impl Drop for Node {
    fn drop(&mut self) {
        let _ = Command::new("kill")
            .args(["-TERM", &self.0.id().to_string()])
            .status();
        let deadline = Instant::now() + Duration::from_secs(5);
        while Instant::now() < deadline {
            if let Ok(Some(_)) = self.0.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Actuator positions (m) along a 100 mm circle around (0, 1700) mm: a real solve per sample.
fn path(n: usize) -> Result<Vec<[f64; 4]>, Box<dyn std::error::Error>> {
    let p = Params::nominal();
    (0..n)
        .map(|k| {
            let a = std::f64::consts::TAU * k as f64 / 2000.0;
            let q = igm(&p, Model::M29, 100.0 * a.cos(), 1700.0 + 100.0 * a.sin())?.q();
            Ok(q.map(|v| v / 1e3))
        })
        .collect()
}

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
    let publ = t.publisher(&topic::ACTUATOR_STATE)?;
    let sub = t.subscriber(&topic::TCP_ESTIMATE)?;
    let n = (secs * rate_hz as f64) as usize;
    let qs = path(n)?;
    // Warm up until the node answers (process start, DDS discovery).
    let start = Instant::now();
    loop {
        publ.publish(&ActuatorState {
            seq: u64::MAX,
            position: qs[0],
            ..Default::default()
        })?;
        if sub.recv_timeout(Duration::from_millis(50))?.is_some() {
            break;
        }
        if start.elapsed() > Duration::from_secs(30) {
            return Err("tcp_estimator did not answer within 30 s".into());
        }
    }
    std::thread::sleep(Duration::from_millis(200));
    while sub.try_recv()?.is_some() {}

    let period = Duration::from_nanos(1_000_000_000 / rate_hz);
    let mut sent_at: Vec<Option<Instant>> = vec![None; n];
    let mut latency: Vec<Duration> = Vec::with_capacity(n);
    let take = |sent_at: &[Option<Instant>],
                latency: &mut Vec<Duration>|
     -> Result<bool, Box<dyn std::error::Error>> {
        match sub.try_recv()? {
            Some(e) => {
                if let Some(Some(t)) = sent_at.get(e.seq as usize) {
                    latency.push(t.elapsed());
                }
                Ok(true)
            }
            None => Ok(false),
        }
    };
    let t0 = Instant::now();
    for (seq, q) in qs.iter().enumerate() {
        let due = t0 + period * seq as u32;
        while Instant::now() < due {
            if !take(&sent_at, &mut latency)? {
                std::thread::yield_now();
            }
        }
        sent_at[seq] = Some(Instant::now());
        publ.publish(&ActuatorState {
            seq: seq as u64,
            position: *q,
            ..Default::default()
        })?;
    }
    let drain = Instant::now();
    while drain.elapsed() < Duration::from_millis(300) && latency.len() < n {
        if !take(&sent_at, &mut latency)? {
            std::thread::yield_now();
        }
    }
    latency.sort_unstable();
    let pick = |q: f64| {
        latency
            .get(((latency.len() as f64 - 1.0) * q).round() as usize)
            .copied()
            .unwrap_or_default()
    };
    Ok(Stats {
        sent: n,
        lost: n - latency.len(),
        p50: pick(0.5),
        p99: pick(0.99),
        max: latency.last().copied().unwrap_or_default(),
    })
}

fn us(d: Duration) -> f64 {
    d.as_secs_f64() * 1e6
}

fn main() {
    let secs: f64 = std::env::var("RPKM_BENCH_SECS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(2.0);
    let nanos = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.subsec_nanos())
        .unwrap_or(0);
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
