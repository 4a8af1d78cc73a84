//! DDS (ros2-client) Rust-to-Rust over loopback: exact values, in order; transient-local
//! Parameters reach a late subscriber. Domain 57 keeps it apart from other tests.
#![expect(
    clippy::cast_possible_truncation,
    reason = "test and benchmark fixtures: counters, stamps and sizes far inside the target type's range"
)]

use std::time::{Duration, Instant};

use rpkm_msgs::{Parameters, TcpEstimate, Time};
use rpkm_transport::{topic, Backend, Transport, TransportConfig};

const DOMAIN: u16 = 57;
const DISCOVERY: Duration = Duration::from_secs(15);

fn estimate(seq: u64) -> TcpEstimate {
    let s = seq as f64;
    TcpEstimate {
        stamp: Time {
            sec: 100 + seq as i32,
            nanosec: 5,
        },
        seq,
        x: 1e-3 * s,
        y: 1.7 + s,
        psi: -1e-6 * s,
        loop_residuals: [s, 2.0 * s, 3.0, 4.0, 5.0],
        rod_forces: [1.0, -2.0, s, 0.0, 9.0],
        drive_forces: [-s, 1.0, 2.0, 3.0],
        iterations: seq as u32,
        model: TcpEstimate::MODEL_24,
        converged: seq % 2 == 1,
        outcome: (seq % 3) as u8,
        reason: (seq % 7) as u8,
    }
}

fn dds(name: &str) -> Transport {
    Transport::new(
        &TransportConfig::new(name)
            .backend(Backend::Dds)
            .dds_domain(DOMAIN),
    )
    .expect("DDS transport")
}

#[test]
fn tcp_estimates_arrive_exactly() {
    let rx = dds("loop_rx");
    let tx = dds("loop_tx");
    let subscriber = rx.subscriber(&topic::TCP_ESTIMATE).expect("subscriber");
    let publisher = tx.publisher(&topic::TCP_ESTIMATE).expect("publisher");

    // Probe (seq 0) until discovery has matched the two.
    let start = Instant::now();
    loop {
        publisher.publish(&estimate(0)).expect("publish probe");
        if let Some(got) = subscriber
            .recv_timeout(Duration::from_millis(50))
            .expect("receive")
        {
            assert_eq!(got, estimate(0));
            break;
        }
        assert!(
            start.elapsed() < DISCOVERY,
            "DDS reader and writer did not match within {DISCOVERY:?}"
        );
    }
    for seq in 1..=50 {
        publisher.publish(&estimate(seq)).expect("publish");
    }
    let mut next = 1;
    while next <= 50 {
        let got = subscriber
            .recv_timeout(Duration::from_secs(5))
            .expect("receive")
            .unwrap_or_else(|| panic!("TcpEstimate seq {next} not received within 5 s"));
        if got.seq == 0 {
            continue; // a late probe
        }
        assert_eq!(got, estimate(next));
        next += 1;
    }
}

#[test]
fn parameters_are_latched_for_late_subscribers() {
    let tx = dds("latch_tx");
    let publisher = tx.publisher(&topic::PARAMETERS).expect("publisher");
    let params = Parameters {
        model: 29,
        names: vec!["l1".into(), "gamma2".into()],
        values: vec![0.950_012, 1e-4],
        sigmas: vec![1e-6, 1e-7],
        measurement_count: 45,
        cal_rms: 4e-6,
        ..Default::default()
    };
    publisher.publish(&params).expect("publish");
    // The subscriber joins after the sample was published.
    let rx = dds("latch_rx");
    let subscriber = rx.subscriber(&topic::PARAMETERS).expect("subscriber");
    let got = subscriber
        .recv_timeout(DISCOVERY)
        .expect("receive")
        .unwrap_or_else(|| panic!("latched Parameters not received within {DISCOVERY:?}"));
    assert_eq!(got, params);
}
