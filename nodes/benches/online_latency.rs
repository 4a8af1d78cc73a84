//! Does the calibrator's online tracker delay the 8 kHz estimator? End-to-end latency through
//! the real `tcp_estimator` process (ActuatorState published here, TcpEstimate of the same seq
//! received here, one clock), at 8 kHz over iceoryx2, with a `calibrator` process beside it on
//! the same topics, its online tracker off, on at its default decimation (1 state in 100: 80 Hz)
//! and on at 1 in 8 (1 kHz, to load it), side by side with the ratios.
//!
//! `cargo bench -p rpkm --bench online_latency` (or `cargo test --bench online_latency` in the
//! optimised test profile). Env `RPKM_BENCH_SECS`: seconds per case (default 2).

use std::process::{Child, Command};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use rpkm_core::geometry::igm;
use rpkm_core::params::{Model, Params};
use rpkm_msgs::ActuatorState;
use rpkm_transport::{topic, Backend, Transport, TransportConfig};

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
