//! iceoryx2 publish/subscribe between two threads: a burst of 10,000 ActuatorState samples
//! (zero-copy type) arrives complete, in order and intact; CDR-carried types arrive intact.
#![expect(
    clippy::cast_possible_truncation,
    reason = "test and benchmark fixtures: counters, stamps and sizes far inside the target type's range"
)]

mod ipc_common;

use std::time::Duration;

use ipc_common::unique_prefix;
use rpkm_msgs::{ActuatorState, Diagnosis, DiagnosisCandidate, Time};
use rpkm_transport::{topic, Backend, Qos, Topic, Transport, TransportConfig};

const BURST: u64 = 10_000;
const WAIT: Duration = Duration::from_secs(10);

fn sample(seq: u64) -> ActuatorState {
    let s = seq as f64;
    let mut m = ActuatorState {
        stamp: Time {
            sec: seq as i32,
            nanosec: (seq * 7) as u32,
        },
        seq,
        position: [s, s + 0.25, -s, 1e-3 * s],
        force: [s * 2.0, -s, 0.5, 8600.0],
        follower: [seq.is_multiple_of(2), seq.is_multiple_of(3), false, true],
        ..Default::default()
    };
    m.set_covariates(&[20.0 + s * 1e-4, 21.0])
        .expect("2 covariates fit");
    m
}

#[test]
fn burst_of_10000_zero_copy_samples_arrives_complete() {
    let prefix = unique_prefix("burst");
    // Reliable: the publisher waits for queue space instead of overwriting.
    let topic: Topic<ActuatorState> = topic::ACTUATOR_STATE.with_qos(Qos::reliable(64));
    let rx = Transport::new(&TransportConfig::new("burst_rx").ipc_prefix(&prefix))
        .expect("iceoryx2 transport for the subscriber");
    let subscriber = rx.subscriber(&topic).expect("subscriber");

    let tx_prefix = prefix.clone();
    let (ready_tx, ready_rx) = std::sync::mpsc::channel::<()>();
    let (go_tx, go_rx) = std::sync::mpsc::channel::<()>();
    let producer = std::thread::spawn(move || {
        let tx = Transport::new(&TransportConfig::new("burst_tx").ipc_prefix(&tx_prefix))
            .expect("iceoryx2 transport for the publisher");
        let publisher = tx.publisher(&topic).expect("publisher");
        ready_tx.send(()).expect("main thread gone");
        go_rx.recv_timeout(WAIT).expect("no go from the subscriber");
        for seq in 0..BURST {
            publisher.publish(&sample(seq)).expect("publish");
        }
    });

    // Handshake: the subscriber connects to the publisher before the burst starts.
    ready_rx
        .recv_timeout(WAIT)
        .expect("publisher not created within the timeout");
    subscriber.update_connections().expect("connect");
    go_tx.send(()).expect("publisher thread gone");
    for seq in 0..BURST {
        let got = subscriber
            .recv_timeout(WAIT)
            .expect("receive")
            .unwrap_or_else(|| panic!("sample {seq} of {BURST} not received within {WAIT:?}"));
        assert_eq!(got, sample(seq), "sample {seq} differs");
    }
    producer.join().expect("publisher thread panicked");
    assert_eq!(
        subscriber.try_recv().expect("receive"),
        None,
        "extra samples after the burst"
    );
}

#[test]
fn cdr_types_travel_over_iceoryx2() {
    let prefix = unique_prefix("cdr");
    let t = Transport::new(
        &TransportConfig::new("cdr_node")
            .ipc_prefix(&prefix)
            .backend(Backend::Ipc),
    )
    .expect("iceoryx2 transport");
    let subscriber = t.subscriber(&topic::DIAGNOSIS).expect("subscriber");
    let publisher = t.publisher(&topic::DIAGNOSIS).expect("publisher");
    let msg = Diagnosis {
        missing_effect: "thermal_guide1".into(),
        candidates: vec![DiagnosisCandidate {
            effect: "thermal_guide1".repeat(200), // larger than the initial 1 KiB slice
            significant: true,
            explained_fraction: 0.75,
            val_rms_before: 2e-5,
            val_rms_after: 5e-6,
        }],
        baseline_cal_rms: 1e-5,
        baseline_val_rms: 2e-5,
        noise_floor: 1e-6,
        ..Default::default()
    };
    publisher.publish(&msg).expect("publish");
    let got = subscriber
        .recv_timeout(WAIT)
        .expect("receive")
        .expect("Diagnosis not received");
    assert_eq!(got, msg);
}

#[test]
fn subscriber_on_a_missing_backend_is_a_typed_error() {
    let t = Transport::new(&TransportConfig::new("no_dds").ipc_prefix(unique_prefix("nodds")))
        .expect("iceoryx2 transport");
    let err = t
        .subscriber_on(&topic::TCP_ESTIMATE, Backend::Dds)
        .err()
        .expect("must fail");
    assert!(err.to_string().contains("/rpkm/tcp_estimate"), "{err}");
}
