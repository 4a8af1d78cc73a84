//! End-to-end latency: an ActuatorState is published, an echo node answers with the
//! TcpEstimate of the same seq, and the round trip is measured on one clock. At 1 kHz and
//! 8 kHz, over iceoryx2 and over DDS (ros2-client, loopback) in the same run; both sides poll
//! with `yield_now` between polls (two spinning threads on a 2-core machine preempt each
//! other for milliseconds). Prints p50/p99/max of the round trip, samples lost and the DDS/iceoryx2 ratio.
//!
//! `cargo bench -p rpkm-transport --bench latency` (release). Env `RPKM_BENCH_SECS` sets
//! the seconds per case (default 2).
#![expect(
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    reason = "test and benchmark fixtures: counters, stamps and sizes far inside the target type's range"
)]

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use rpkm_msgs::{ActuatorState, TcpEstimate};
use rpkm_transport::{topic, Backend, Transport, TransportConfig};

const DDS_DOMAIN: u16 = 61;

struct Case {
    backend: Backend,
    rate_hz: u64,
}

struct Stats {
    sent: usize,
    lost: usize,
    p50: Duration,
    p99: Duration,
    max: Duration,
}

fn config(name: &str, backend: Backend, prefix: &str) -> TransportConfig {
    TransportConfig::new(name)
        .backend(backend)
        .ipc_prefix(prefix)
        .dds_domain(DDS_DOMAIN)
}

#[expect(
    clippy::too_many_lines,
    reason = "an end-to-end scenario, read top to bottom"
)]
fn run(case: &Case, secs: f64, prefix: &str) -> Result<Stats, Box<dyn std::error::Error>> {
    let stop = Arc::new(AtomicBool::new(false));
    // Echo node: ActuatorState in, TcpEstimate of the same seq out.
    let echo = {
        let stop = Arc::clone(&stop);
        let cfg = config("bench_echo", case.backend, prefix);
        std::thread::spawn(move || -> Result<(), String> {
            let t = Transport::new(&cfg).map_err(|e| e.to_string())?;
            let sub = t
                .subscriber(&topic::ACTUATOR_STATE)
                .map_err(|e| e.to_string())?;
            let publ = t
                .publisher(&topic::TCP_ESTIMATE)
                .map_err(|e| e.to_string())?;
            while !stop.load(Ordering::Relaxed) {
                match sub.try_recv().map_err(|e| e.to_string())? {
                    Some(a) => {
                        let est = TcpEstimate {
                            stamp: a.stamp,
                            seq: a.seq,
                            ..Default::default()
                        };
                        publ.publish(&est).map_err(|e| e.to_string())?;
                    }
                    None => std::thread::yield_now(),
                }
            }
            Ok(())
        })
    };
    let t = Transport::new(&config("bench_main", case.backend, prefix))?;
    let publ = t.publisher(&topic::ACTUATOR_STATE)?;
    let sub = t.subscriber(&topic::TCP_ESTIMATE)?;

    // Warm up until the echo answers (DDS discovery, iceoryx2 connections).
    let start = Instant::now();
    loop {
        publ.publish(&ActuatorState {
            seq: u64::MAX,
            ..Default::default()
        })?;
        if sub.recv_spin(Duration::from_millis(20))?.is_some() {
            break;
        }
        if start.elapsed() > Duration::from_secs(20) {
            return Err("echo node did not answer within 20 s".into());
        }
    }
    std::thread::sleep(Duration::from_millis(100));
    while sub.try_recv()?.is_some() {}

    let n = (secs * case.rate_hz as f64) as usize;
    let period = Duration::from_nanos(1_000_000_000 / case.rate_hz);
    let mut sent_at: Vec<Option<Instant>> = vec![None; n];
    let mut rtt: Vec<Duration> = Vec::with_capacity(n);
    let take = |sent_at: &[Option<Instant>],
                rtt: &mut Vec<Duration>|
     -> Result<bool, Box<dyn std::error::Error>> {
        match sub.try_recv()? {
            Some(est) => {
                if let Some(Some(t_sent)) = sent_at.get(est.seq as usize) {
                    rtt.push(t_sent.elapsed());
                }
                Ok(true)
            }
            None => Ok(false),
        }
    };
    let t0 = Instant::now();
    for seq in 0..n {
        let due = t0 + period * seq as u32;
        while Instant::now() < due {
            if !take(&sent_at, &mut rtt)? {
                std::thread::yield_now();
            }
        }
        sent_at[seq] = Some(Instant::now());
        publ.publish(&ActuatorState {
            seq: seq as u64,
            ..Default::default()
        })?;
    }
    // Drain the last answers.
    let drain = Instant::now();
    while drain.elapsed() < Duration::from_millis(200) && rtt.len() < n {
        if !take(&sent_at, &mut rtt)? {
            std::thread::yield_now();
        }
    }
    stop.store(true, Ordering::Relaxed);
    echo.join().map_err(|_| "echo thread panicked")??;

    rtt.sort_unstable();
    let pick = |q: f64| {
        rtt.get(((rtt.len() as f64 - 1.0) * q).round() as usize)
            .copied()
            .unwrap_or_default()
    };
    Ok(Stats {
        sent: n,
        lost: n - rtt.len(),
        p50: pick(0.5),
        p99: pick(0.99),
        max: rtt.last().copied().unwrap_or_default(),
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
        .map_or(0, |d| d.as_nanos());
    let prefix = format!("rpkm_bench_{}_{nanos}", std::process::id());
    println!("round trip ActuatorState -> echo -> TcpEstimate, {secs} s per case, polling with yield, loopback");
    println!(
        "{:<9} {:>6} {:>7} {:>6} {:>10} {:>10} {:>10}",
        "backend", "rate", "sent", "lost", "p50 us", "p99 us", "max us"
    );
    let mut p50 = std::collections::BTreeMap::new();
    for rate_hz in [1000u64, 8000] {
        for backend in [Backend::Ipc, Backend::Dds] {
            let case = Case { backend, rate_hz };
            let name = if backend == Backend::Ipc {
                "iceoryx2"
            } else {
                "dds"
            };
            match run(&case, secs, &format!("{prefix}_{rate_hz}")) {
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
                    p50.insert((rate_hz, name), (s.p50, s.p99));
                }
                Err(e) => println!("{name:<9} {rate_hz:>4}Hz failed: {e}"),
            }
        }
    }
    for rate_hz in [1000u64, 8000] {
        if let (Some(i), Some(d)) = (p50.get(&(rate_hz, "iceoryx2")), p50.get(&(rate_hz, "dds"))) {
            println!(
                "DDS/iceoryx2 at {rate_hz} Hz: p50 x{:.0}, p99 x{:.0}",
                d.0.as_secs_f64() / i.0.as_secs_f64().max(1e-12),
                d.1.as_secs_f64() / i.1.as_secs_f64().max(1e-12)
            );
        }
    }
}
