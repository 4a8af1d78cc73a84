//! Shared by the latency benchmarks: the real `tcp_estimator` process fed a circle of
//! actuator states at a fixed rate, each TcpEstimate matched to its state by seq on one clock.
#![expect(
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    reason = "test and benchmark fixtures: counters, stamps and sizes far inside the target type's range"
)]
#![allow(dead_code)] // each bench uses a part

use std::process::{Child, Command};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use rpkm_core::geometry::igm;
use rpkm_core::params::{Model, Params};
use rpkm_msgs::ActuatorState;
use rpkm_transport::{topic, Transport};

pub struct Stats {
    pub sent: usize,
    pub lost: usize,
    pub p50: Duration,
    pub p99: Duration,
    pub max: Duration,
}

pub struct Node(pub Child);

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
pub fn path(n: usize) -> Result<Vec<[f64; 4]>, Box<dyn std::error::Error>> {
    let p = Params::nominal();
    (0..n)
        .map(|k| {
            let a = std::f64::consts::TAU * k as f64 / 2000.0;
            let q = igm(&p, Model::M29, 100.0 * a.cos(), 1700.0 + 100.0 * a.sin())?.q();
            Ok(q.map(|v| v / 1e3))
        })
        .collect()
}

/// Latency of `n = secs * rate_hz` states through the estimator that `t` reaches: waits
/// until it answers (process start, discovery), then publishes at the rate and matches.
pub fn measure(
    t: &Transport,
    rate_hz: u64,
    secs: f64,
) -> Result<Stats, Box<dyn std::error::Error>> {
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

/// Microseconds of a duration.
pub fn us(d: Duration) -> f64 {
    d.as_secs_f64() * 1e6
}

/// Seconds per case: `RPKM_BENCH_SECS`, 2 by default.
pub fn case_seconds() -> f64 {
    std::env::var("RPKM_BENCH_SECS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(2.0)
}

/// This run's nanoseconds, to make the iceoryx2 prefixes of its cases unique on the machine.
pub fn run_nanos() -> u32 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.subsec_nanos())
}
