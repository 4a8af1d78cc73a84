//! End-to-end latency through the real `tcp_estimator` process: an ActuatorState is
//! published here, the node solves the elasto-geometric model (warm-started fegm) and
//! publishes the TcpEstimate of the same seq, which is received here; publish-to-receive on
//! one clock. At 1 kHz and 8 kHz, over iceoryx2 and over DDS (loopback) in the same run;
//! prints p50/p99/max, samples lost and the DDS/iceoryx2 ratio. Both sides poll with
//! `yield_now` (a 2-core machine).
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

fn run(
    backend: Backend,
    rate_hz: u64,
    secs: f64,
    prefix: &str,
) -> Result<Stats, Box<dyn std::error::Error>> {
    let name = if backend == Backend::Ipc {
        "ipc"
    } else {
        "dds"
    };
    let _node = Node(
        Command::new(env!("CARGO_BIN_EXE_rpkm"))
            .args([
                "node",
                "tcp_estimator",
                "--backend",
                name,
                "--ipc-prefix",
                prefix,
            ])
            .args(["--domain", &DDS_DOMAIN.to_string()])
            .spawn()?,
    );
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
        "{:<9} {:>6} {:>7} {:>6} {:>10} {:>10} {:>10}",
        "backend", "rate", "sent", "lost", "p50 us", "p99 us", "max us"
    );
    let mut results = std::collections::BTreeMap::new();
    for rate_hz in [1000u64, 8000] {
        for backend in [Backend::Ipc, Backend::Dds] {
            let name = if backend == Backend::Ipc {
                "iceoryx2"
            } else {
                "dds"
            };
            let prefix = format!(
                "rpkm_nbench_{}_{nanos}_{rate_hz}_{name}",
                std::process::id()
            );
            match run(backend, rate_hz, secs, &prefix) {
                Ok(s) => {
                    println!(
                        "{:<9} {:>4}Hz {:>7} {:>6} {:>10.1} {:>10.1} {:>10.1}",
                        name,
                        rate_hz,
                        s.sent,
                        s.lost,
                        us(s.p50),
                        us(s.p99),
                        us(s.max)
                    );
                    results.insert((rate_hz, name), (s.p50, s.p99));
                }
                Err(e) => println!("{name:<9} {rate_hz:>4}Hz failed: {e}"),
            }
        }
    }
    for rate_hz in [1000u64, 8000] {
        if let (Some(i), Some(d)) = (
            results.get(&(rate_hz, "iceoryx2")),
            results.get(&(rate_hz, "dds")),
        ) {
            println!(
                "DDS/iceoryx2 at {rate_hz} Hz: p50 x{:.1}, p99 x{:.1}",
                d.0.as_secs_f64() / i.0.as_secs_f64().max(1e-12),
                d.1.as_secs_f64() / i.1.as_secs_f64().max(1e-12)
            );
        }
    }
}
