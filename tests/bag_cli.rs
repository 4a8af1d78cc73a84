//! The bag commands as real processes: `rpkm ingest` and `rpkm bag campaign` round trip a
//! campaign; `rpkm record` killed with SIGKILL during an 8 kHz stream is rescued by
//! `rpkm bag recover` with every message of its complete chunks; a reliable replay goes on
//! when its recorder dies with a full queue; `rpkm replay --rate max` into `rpkm record`
//! reproduces a bag message for message.
#![expect(
    clippy::float_cmp,
    reason = "exact values: parsed, copied or computed without rounding"
)]

// A binary of its own, not a module of tests/it: its SIGKILLed recorders must stay dead
// and uncleaned until its replayer has seen their full queues, and any iceoryx2 node that
// starts meanwhile removes dead nodes' resources machine-wide (run beside the tests of
// tests/it, its first test failed so). Cargo runs test binaries one after the other.
#[path = "it/bag_support/mod.rs"]
mod bag_support;

use std::time::Duration;

use bag_support::*;
use rpkm_core::campaign::{Campaign, Instrument};
use rpkm_msgs::{ActuatorState, CampaignInfo, TcpMeasurement};
use rpkm_transport::bag::BagReader;
use rpkm_twin::{Twin, TwinConfig};

/// `a` and `b` equal but for the mm → m → mm conversion: a relative error of a few ulp.
fn close_mm(a: f64, b: f64) -> bool {
    (a - b).abs() <= 4.0 * f64::EPSILON * a.abs().max(b.abs())
}

fn close_opt(a: Option<f64>, b: Option<f64>) -> bool {
    match (a, b) {
        (Some(a), Some(b)) => close_mm(a, b),
        (None, None) => true,
        _ => false,
    }
}

/// A campaign with every instrument and the awkward cases: a second covariate with empty
/// fields, two poses at the same time, a blank comment line, times with decimals.
fn awkward_campaign() -> Campaign {
    let mut twin = Twin::new(TwinConfig {
        seed: 11,
        ..TwinConfig::default()
    })
    .expect("twin");
    let mut c = twin
        .campaign(&[
            Instrument::Lt,
            Instrument::Dbb,
            Instrument::LiX,
            Instrument::LiPsi,
            Instrument::SelfCal,
            Instrument::Circle,
        ])
        .expect("campaign");
    c.comments.push(String::new());
    c.comments.push("second comment, with a comma".into());
    c.covariate_names.push("temp_guide1".into());
    for (i, pose) in c.poses.iter_mut().enumerate() {
        pose.t += 0.1 * (i % 7) as f64 / 7.0;
        pose.covariates
            .push((i % 3 != 0).then_some(19.5 + i as f64 * 1e-3));
    }
    let t = c.poses[10].t;
    c.poses[11].t = t;
    c.validate().expect("still a valid campaign");
    c
}

#[test]
fn csv_to_bag_to_campaign_round_trip() {
    let dir = scratch("round-trip");
    let csv = dir.join("awkward.csv");
    std::fs::write(&csv, awkward_campaign().to_csv()).expect("write csv");
    let original = Campaign::parse(
        &std::fs::read_to_string(&csv).expect("read"),
        &csv.display().to_string(),
    )
    .expect("parse");
    let bag = dir.join("awkward_bag");
    run_ok(rpkm().arg("ingest").arg(&csv).arg("--out").arg(&bag));

    // The bag itself: SI units on the topics, one state and one measurement per pose.
    let states: Vec<ActuatorState> = decode_all(&bag, "/rpkm/actuator_state");
    let measurements: Vec<TcpMeasurement> = decode_all(&bag, "/rpkm/tcp_measurement");
    let infos: Vec<CampaignInfo> = decode_all(&bag, "/rpkm/campaign_info");
    assert_eq!(states.len(), original.poses.len());
    assert_eq!(measurements.len(), original.poses.len());
    assert_eq!(infos.len(), 1);
    assert_eq!(infos[0].covariate_names, ["temp_machine", "temp_guide1"]);
    let dbb = original
        .poses
        .iter()
        .position(|p| p.instrument == Instrument::Dbb && !p.reset)
        .expect("a dbb pose");
    assert_eq!(measurements[dbb].instrument, TcpMeasurement::DBB);
    assert!(measurements[dbb].r_valid && !measurements[dbb].x_valid);
    assert_eq!(
        measurements[dbb].r,
        original.poses[dbb].r.expect("r") / 1000.0
    );
    assert_eq!(states[dbb].position[0], original.poses[dbb].q[0] / 1000.0);
    assert_eq!(states[dbb].seq, dbb as u64);
    assert!(
        states[0].covariates[1].is_nan(),
        "empty covariate travels as NaN"
    );

    // Back to a campaign.
    let back_csv = dir.join("back.csv");
    run_ok(
        rpkm()
            .args(["bag", "campaign"])
            .arg(&bag)
            .arg("--out")
            .arg(&back_csv),
    );
    let back = Campaign::parse(
        &std::fs::read_to_string(&back_csv).expect("read back"),
        "back.csv",
    )
    .expect("parse back");
    assert_eq!(back.comments, original.comments);
    assert_eq!(back.covariate_names, original.covariate_names);
    assert_eq!(back.poses.len(), original.poses.len());
    for (a, b) in original.poses.iter().zip(&back.poses) {
        let at = format!("pose at line {} (t = {})", a.line, a.t);
        // Stamps hold t to the nanosecond.
        assert!(
            (a.t - b.t).abs() <= 0.5e-9 + 4.0 * f64::EPSILON * a.t.abs(),
            "{at}: t {}",
            b.t
        );
        assert_eq!(
            (&a.setup, a.instrument, a.reset, a.follower, a.f),
            (&b.setup, b.instrument, b.reset, b.follower, b.f),
            "{at}"
        );
        for i in 0..4 {
            assert!(
                close_mm(a.q[i], b.q[i]),
                "{at}: q{} {} vs {}",
                i + 1,
                a.q[i],
                b.q[i]
            );
        }
        assert!(close_opt(a.x, b.x), "{at}: x {:?} vs {:?}", a.x, b.x);
        assert!(close_opt(a.y, b.y), "{at}: y {:?} vs {:?}", a.y, b.y);
        assert!(close_opt(a.r, b.r), "{at}: r {:?} vs {:?}", a.r, b.r);
        assert_eq!(a.psi, b.psi, "{at}: psi (rad on both sides)");
        assert_eq!(a.covariates, b.covariates, "{at}: covariates");
    }
}

#[test]
fn ingest_refuses_what_a_message_cannot_hold() {
    let dir = scratch("ingest-bad");
    let mut c = awkward_campaign();
    c.covariate_names = (1..=9).map(|k| format!("c{k}")).collect();
    for pose in &mut c.poses {
        pose.covariates = vec![Some(1.0); 9];
    }
    let csv = dir.join("nine.csv");
    std::fs::write(&csv, c.to_csv()).expect("write");
    let bag = dir.join("nine_bag");
    let out = rpkm()
        .arg("ingest")
        .arg(&csv)
        .arg("--out")
        .arg(&bag)
        .output()
        .expect("run");
    assert_eq!(out.status.code(), Some(2), "bad input exits with 2");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("9 covariate columns") && err.contains("at most 8"),
        "{err}"
    );
    assert!(!bag.exists(), "no bag is left behind for refused input");
}

/// The source stream: 4000 ActuatorState of the reference bag, seq 0..3999.
fn reference_stream() -> Vec<ActuatorState> {
    let states: Vec<ActuatorState> =
        decode_all(&reference_bag("stream_8khz"), "/rpkm/actuator_state");
    assert_eq!(states.len(), 4000);
    states
}

/// Held by the tests that SIGKILL a recorder: iceoryx2's dead-node clean-up is machine-wide,
/// so one test's replayer would remove the other's dead recorder before that one's queue
/// filled, and the second replayer would never have to go on by itself.
static KILLS_A_RECORDER: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// `rpkm record --reliable` of the actuator stream into `out` with `chunk_kib` chunks,
/// printing each flush, and the reliable replay of `bag` at `rate`, both on `prefix`;
/// returns once the recorder listens, with the replay started.
fn reliable_record_and_replay(
    prefix: &str,
    bag: &std::path::Path,
    out: &std::path::Path,
    chunk_kib: &str,
    rate: &str,
) -> (Watched, Watched) {
    let mut recorder = Watched::spawn(
        rpkm()
            .args(["record", "--topics", "/rpkm/actuator_state", "--reliable"])
            .args(["--chunk-kib", chunk_kib, "--flush-every", "0", "--progress"])
            .args(["--ipc-prefix", prefix])
            .arg("--out")
            .arg(out),
    );
    recorder.wait_line(Duration::from_secs(60), |l| {
        l.contains("recording 1 topics")
    });
    let replay = Watched::spawn(rpkm().arg("replay").arg(bag).args([
        "--rate",
        rate,
        "--reliable",
        "--ipc-prefix",
        prefix,
    ]));
    (recorder, replay)
}

/// A subscriber killed with SIGKILL stays connected to iceoryx2 with its queue full until
/// someone removes dead nodes' resources; a reliable publisher must notice and go on rather
/// than wait for it forever.
#[test]
fn reliable_replay_goes_on_when_its_recorder_dies_with_a_full_queue() {
    let _alone = KILLS_A_RECORDER
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    let dir = scratch("dead_subscriber");
    let prefix = ipc_prefix("dead");
    // A stream five times the subscriber queue: the queue must fill while the recorder is
    // frozen, whatever depth the topic has and however late the first flush comes (three
    // times failed once in five runs on a loaded machine).
    let depth = rpkm_transport::topic::ACTUATOR_STATE.qos().depth;
    let states = 5 * depth;
    let bag = dir.join("stream");
    let made = rpkm()
        .args([
            "simulate",
            "--stream-hz",
            "8000",
            "--stream-motion",
            "circle",
        ])
        .arg("--stream-seconds")
        .arg(format!("{}", states as f64 / 8000.0))
        .arg("--out")
        .arg(&bag)
        .output()
        .expect("run rpkm simulate");
    assert!(
        made.status.success(),
        "{}",
        String::from_utf8_lossy(&made.stderr)
    );
    // at the recorded speed: 2.6 s at 8 kHz, long enough to freeze the recorder mid-stream
    let (mut recorder, mut replay) =
        reliable_record_and_replay(&prefix, &bag, &dir.join("rec"), "4", "1");
    recorder.wait_line(Duration::from_secs(60), |l| {
        l.starts_with("rpkm record: flushed ")
    });
    // Frozen, the recorder takes nothing: its queue fills and the replayer waits for it, as
    // reliable delivery to a live subscriber must.
    recorder.signal("STOP");
    std::thread::sleep(Duration::from_millis(300));
    recorder.child.kill().expect("SIGKILL the recorder");
    recorder.child.wait().expect("reap the recorder");
    let status = replay.wait(Duration::from_secs(60));
    let stderr = replay.seen.join("\n");
    assert!(status.success(), "replay: {stderr}");
    assert!(
        stderr.contains("/rpkm/actuator_state: a subscriber stopped taking samples; removed"),
        "the replay says why it went on: {stderr}"
    );
    assert!(
        stderr.contains(&format!("/rpkm/actuator_state: {states}")),
        "every state published: {stderr}"
    );
}

#[test]
fn recorder_killed_during_8khz_stream_is_recovered() {
    let _alone = KILLS_A_RECORDER
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    let dir = scratch("sigkill");
    let prefix = ipc_prefix("kill");
    let rec = dir.join("rec");
    // Reliable: the replayer waits for the recorder, so the recording is the source's prefix.
    let (mut recorder, mut replay) =
        reliable_record_and_replay(&prefix, &reference_bag("stream_8khz"), &rec, "16", "1");
    // Kill once a good part of the stream is on disk, while the rest is still coming.
    let line = recorder.wait_line(Duration::from_secs(60), |l| {
        l.strip_prefix("rpkm record: flushed ")
            .and_then(|r| r.split(' ').next())
            .and_then(|n| n.parse::<u64>().ok())
            .is_some_and(|n| n >= 1000)
    });
    recorder.child.kill().expect("SIGKILL the recorder");
    recorder.child.wait().expect("reap the recorder");
    recorder.drain();
    let flushed: u64 = recorder
        .seen
        .iter()
        .filter_map(|l| l.strip_prefix("rpkm record: flushed "))
        .filter_map(|r| r.split(' ').next()?.parse().ok())
        .max()
        .unwrap_or_else(|| panic!("no flushed count in {line:?}"));
    let replay_status = replay.wait(Duration::from_secs(60));
    assert!(
        replay_status.success(),
        "replay: {}",
        replay.seen.join("\n")
    );
    assert!(
        !rec.join("metadata.yaml").exists(),
        "the recorder was killed before it could finish the bag"
    );
    assert!(
        matches!(
            BagReader::open(&rec),
            Err(rpkm_transport::bag::BagOpenError::Truncated { .. })
        ),
        "the killed recording is not a finished bag"
    );

    let fixed = dir.join("rec_fixed");
    let report = run_ok(
        rpkm()
            .args(["bag", "recover"])
            .arg(&rec)
            .arg("--out")
            .arg(&fixed),
    );
    let recovered_line = report
        .lines()
        .find(|l| l.starts_with("recovered "))
        .unwrap_or_else(|| panic!("no summary line in:\n{report}"));
    let recovered: Vec<ActuatorState> = decode_all(&fixed, "/rpkm/actuator_state");
    let n = recovered.len();
    assert!(
        recovered_line.starts_with(&format!("recovered {n} messages")),
        "{recovered_line}"
    );
    assert!(
        n as u64 >= flushed,
        "{n} recovered, but {flushed} were reported on disk before the kill"
    );
    let source = reference_stream();
    assert!(
        n < source.len(),
        "the kill came after the whole stream: {n}"
    );
    for (i, (got, want)) in recovered.iter().zip(&source).enumerate() {
        assert_eq!(
            got, want,
            "message {i}: the recovered stream is the source's prefix"
        );
    }
    // The recovered bag is a finished one, with metadata for ros2 bag and rosbags.
    let meta = std::fs::read_to_string(fixed.join("metadata.yaml")).expect("metadata.yaml");
    assert!(meta.contains(&format!("message_count: {n}")), "{meta}");
}

#[test]
fn replay_at_max_rate_reproduces_the_stream() {
    let dir = scratch("replay");
    let prefix = ipc_prefix("replay");
    let rec = dir.join("again");
    let mut recorder = Watched::spawn(
        rpkm()
            .args(["record", "--reliable", "--ipc-prefix", &prefix])
            .arg("--out")
            .arg(&rec),
    );
    recorder.wait_line(Duration::from_secs(60), |l| {
        l.contains("recording 8 topics")
    });
    let mut replay = Watched::spawn(
        rpkm()
            .arg("replay")
            .arg(reference_bag("stream_8khz"))
            .args(["--rate", "max", "--reliable", "--ipc-prefix", &prefix]),
    );
    let status = replay.wait(Duration::from_secs(120));
    assert!(status.success(), "replay: {}", replay.seen.join("\n"));
    // Every sample has been delivered into the recorder's queue (reliable); SIGINT makes it
    // drain the queue and finish the bag.
    recorder.interrupt();
    let status = recorder.wait(Duration::from_secs(60));
    assert!(status.success(), "record: {}", recorder.seen.join("\n"));

    let got: Vec<ActuatorState> = decode_all(&rec, "/rpkm/actuator_state");
    let want = reference_stream();
    assert_eq!(got.len(), want.len(), "message count");
    for (i, (g, w)) in got.iter().zip(&want).enumerate() {
        assert_eq!(g, w, "message {i} differs");
    }
    let info: Vec<CampaignInfo> = decode_all(&rec, "/rpkm/campaign_info");
    let want_info: Vec<CampaignInfo> =
        decode_all(&reference_bag("stream_8khz"), "/rpkm/campaign_info");
    assert_eq!(info, want_info);
}
