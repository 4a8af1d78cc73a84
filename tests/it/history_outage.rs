//! A PostgreSQL history stopped and started under a running calibrator (launched, on the
//! ipc backend; a server of the test's own, history_support), campaigns of the history
//! tests' machine streamed by ingest one at a time:
//! 1. with the server up: recorded;
//! 2. with it stopped (its sessions ended, as a restart ends them): queued, 1 waiting;
//! 3. the calibrator killed and restarted by the launcher while the server is still down:
//!    it starts (no crash loop) and says the server is away; a campaign: queued, 2 waiting
//!    (the first waited through the restart, in the spool file); /diagnostics WARN with
//!    `history_waiting` 2;
//! 4. the server started again: the calibrator says both waiting records are recorded,
//!    without a new calibration to push them;
//! 5. one more campaign: recorded at once.
//!
//! Afterwards the database holds the four calibrations, once each (four campaign digests), in
//! order (each with its calibration's measurements); the spool none.

use crate::history_support::{postgres::OwnServer, scenario};
use crate::node_support::{rpkm, unique, Launch, TempDir};
use rpkm_history::Store;
use rpkm_transport::{topic, Subscriber, Transport, TransportConfig};
use std::process::Command;
use std::time::{Duration, Instant};

const MACHINE: &str = "cell-9";
const WAIT: Duration = Duration::from_secs(120);

/// Waits for the calibrator's /diagnostics status with `key` = `value`; its level.
fn status_with(diagnostics: &Subscriber<rpkm_msgs::DiagnosticArray>, key: &str, value: &str) -> u8 {
    let deadline = Instant::now() + WAIT;
    loop {
        assert!(Instant::now() < deadline, "no status with {key} = {value}");
        while let Some(d) = diagnostics.try_recv().expect("recv") {
            if let Some(s) = d.status.iter().find(|s| {
                s.name == "rpkm/calibrator"
                    && s.values.iter().any(|v| v.key == key && v.value == value)
            }) {
                return s.level;
            }
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// The number of measurements a calibrator's line says it calibrated.
fn measurements(said: &str) -> u64 {
    said.split(": ")
        .nth(1)
        .and_then(|s| s.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("{said}"))
}

/// Streams campaign `k` with ingest (to its end, then it exits); the calibrator's log line
/// of its calibration.
fn calibrate(launched: &Launch, dir: &TempDir, prefix: &str, k: usize) -> String {
    let status = Command::new(rpkm())
        .args(["node", "ingest", "--params"])
        .arg(dir.path("params.yaml"))
        .arg("--source")
        .arg(scenario().campaign(k))
        .env("RPKM_IPC_PREFIX", prefix)
        .status()
        .expect("run ingest");
    assert!(status.success(), "ingest of campaign {k}");
    launched.wait_for(" held out), RMS", WAIT)
}

#[test]
fn every_calibration_made_before_during_and_after_an_outage_is_recorded() {
    let Some(mut server) = OwnServer::new("pgoutage") else {
        return;
    };
    let url = server.database("outage");
    let dir = TempDir::new("pgout");
    let spool = dir.path("spool.db");
    std::fs::write(
        dir.path("params.yaml"),
        format!(
            "/**:\n  ros__parameters:\n    diagnostics_period_s: 0.5\n\
             ingest:\n  ros__parameters:\n    rate_hz: 2000.0\n    start_delay_s: 1.0\n    \
             exit_at_end: true\n\
             calibrator:\n  ros__parameters:\n    history: {url}\n    history_machine: \
             {MACHINE}\n    history_spool: {}\n    history_retry_s: 0.1\n",
            spool.display()
        ),
    )
    .expect("params");
    let launch = dir.path("cal.launch.yaml");
    std::fs::write(
        &launch,
        "launch:\n  - node: {pkg: rpkm, exec: calibrator, param: [{from: params.yaml}]}\n",
    )
    .expect("launch file");
    let prefix = unique("pgout");
    let t = Transport::new(&TransportConfig::new(unique("pgoutobs")).ipc_prefix(&prefix))
        .expect("transport");
    let diagnostics = t.subscriber(&topic::DIAGNOSTICS).expect("sub");
    let launched = Launch::start(&launch, &[("RPKM_IPC_PREFIX", prefix.as_str())]);
    launched.wait_for("history: machine cell-9 in postgres://", WAIT);

    let mut poses = Vec::new();
    let said = calibrate(&launched, &dir, &prefix, 0);
    poses.push(measurements(&said));
    assert!(said.contains("history: recorded as 1;"), "{said}");

    server.stop();
    let said = calibrate(&launched, &dir, &prefix, 1);
    poses.push(measurements(&said));
    assert!(said.contains("history: queued, 1 waiting"), "{said}");

    let pid = *launched.started("calibrator").last().expect("a pid");
    Command::new("kill")
        .args(["-KILL", &pid.to_string()])
        .status()
        .expect("kill");
    let line = launched.wait_for("the server is away", WAIT);
    assert!(line.contains("records wait in"), "{line}");
    let said = calibrate(&launched, &dir, &prefix, 2);
    poses.push(measurements(&said));
    assert!(said.contains("history: queued, 2 waiting"), "{said}");
    // /diagnostics says it too: a WARN, two records waiting
    let level = status_with(&diagnostics, "history_waiting", "2");
    assert_eq!(level, rpkm_msgs::DiagnosticStatus::WARN);

    server.start();
    let said = launched.wait_for("answers again", WAIT);
    assert!(said.contains("2 waiting records recorded"), "{said}");
    assert_eq!(
        status_with(&diagnostics, "history_server", "connected"),
        rpkm_msgs::DiagnosticStatus::OK
    );

    let said = calibrate(&launched, &dir, &prefix, 3);
    poses.push(measurements(&said));
    assert!(said.contains("history: recorded as 4;"), "{said}");

    let mut store = Store::open(&url).expect("open");
    let cals = store.calibrations(MACHINE).expect("read");
    let digests: Vec<&str> = cals
        .iter()
        .map(|c| c.record.campaign.digest.as_str())
        .collect();
    assert_eq!(cals.len(), 4, "{digests:?}");
    let mut distinct = digests.clone();
    distinct.sort_unstable();
    distinct.dedup();
    assert_eq!(distinct.len(), 4, "four campaigns, each once");
    let recorded: Vec<u64> = cals.iter().map(|c| c.record.campaign.poses).collect();
    assert_eq!(recorded, poses, "each calibration's campaign, in order");
    let mut spooled = Store::open(&spool.to_string_lossy()).expect("spool");
    assert_eq!(spooled.calibrations(MACHINE).expect("spool").len(), 0);
}
