//! iceoryx2 wake-ups: a subscriber that waits sleeps in the kernel until a publisher of its
//! topic sends (zero-copy and CDR types alike), and sleeps its whole timeout when none does.

mod ipc_common;

use std::time::{Duration, Instant};

use ipc_common::unique_prefix;
use rpkm_msgs::{ActuatorState, Diagnosis};
use rpkm_transport::{topic, IpcMessage, Topic, Transport, TransportConfig};

/// Publishes `msg` from another thread 100 ms after the subscriber started waiting; the wait
/// (timeout 20 s) returns once it is sent and the sample is there to take.
fn wakes_on_publish<T: IpcMessage + Clone + PartialEq + std::fmt::Debug + Send + 'static>(
    topic: Topic<T>,
    msg: T,
    tag: &str,
) {
    let prefix = unique_prefix(tag);
    let t = Transport::new(&TransportConfig::new(format!("{tag}_sub")).ipc_prefix(&prefix))
        .expect("transport");
    let sub = t.subscriber(&topic).expect("subscriber");
    let publisher_side =
        Transport::new(&TransportConfig::new(format!("{tag}_pub")).ipc_prefix(&prefix))
            .expect("transport");
    let publ = publisher_side.publisher(&topic).expect("publisher");
    // The first wait arms the wake-up and returns at once.
    sub.wait(Duration::from_secs(20)).expect("arm");
    assert_eq!(sub.try_recv().expect("recv"), None);

    // Nobody publishes: the whole timeout is slept (not returned early, not spun through).
    let quiet = Instant::now();
    sub.wait(Duration::from_millis(300)).expect("wait");
    assert!(
        quiet.elapsed() >= Duration::from_millis(250),
        "woke after {:?} with nothing sent",
        quiet.elapsed()
    );

    let sent = msg.clone();
    let sender = std::thread::spawn(move || {
        std::thread::sleep(Duration::from_millis(100));
        let at = Instant::now();
        publ.publish(&sent).expect("publish");
        // Kept alive: iceoryx2 takes a publisher's unread samples away with it.
        (at, publ)
    });
    let start = Instant::now();
    sub.wait(Duration::from_secs(20)).expect("wait");
    let woke = Instant::now();
    let (sent_at, _publisher) = sender.join().expect("sender");
    assert!(woke >= sent_at, "woke before anything was sent");
    assert!(
        woke - start < Duration::from_secs(10),
        "the publish did not wake the subscriber (slept {:?})",
        woke - start
    );
    assert_eq!(sub.try_recv().expect("recv"), Some(msg));
}

#[test]
fn zero_copy_publish_wakes_a_waiting_subscriber() {
    wakes_on_publish(
        topic::ACTUATOR_STATE,
        ActuatorState {
            seq: 42,
            position: [1.0, 2.0, 0.5, 0.25],
            ..Default::default()
        },
        "wake_zc",
    );
}

#[test]
fn cdr_publish_wakes_a_waiting_subscriber() {
    wakes_on_publish(
        topic::DIAGNOSIS,
        Diagnosis {
            missing_effect: "thermal".into(),
            ..Default::default()
        },
        "wake_cdr",
    );
}
