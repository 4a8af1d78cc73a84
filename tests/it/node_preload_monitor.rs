//! The node set launched together (`rpkm launch`: ingest, tcp_estimator, preload_monitor,
//! real processes over iceoryx2) on a digital-twin stream under `preload_elastic`:
//! - incompatible: drive 3's carrier drifts away from its encoder (0 to 0.4 mm over the
//!   stream), so the forces the drives measure leave the model's prediction; the monitor must
//!   raise WARN, then ERROR, at the sample and on the drive that the core's own elastic model
//!   gives for the configured thresholds and debounce;
//! - compatible: no drift, the monitor's parameters are the twin's: OK on every sample.

use crate::node_support;

use std::collections::HashMap;
use std::time::{Duration, Instant};

use node_support::{
    launch_from_params, twin_stream, unique, write_truth_json, Launch, Stream, TempDir,
};
use rpkm_core::elastic::{fegm, ALL_ACTIVE, NOMINAL_DRIVE_FORCE_N};
use rpkm_msgs::{DiagnosticStatus, PreloadStatus};
use rpkm_nodes::campaign_bag::stamp_from_seconds;
use rpkm_transport::{topic, Transport, TransportConfig};

const N: usize = 400;
const RATE_HZ: f64 = 200.0;
const WARN: f64 = 20.0;
const ERROR: f64 = 50.0;
const DEBOUNCE: usize = 3;

/// Per sample: the deviation (measured − predicted current, %) from the core directly.
fn expected_deviation(s: &Stream) -> Vec<[f64; 4]> {
    let p = s.twin.true_params();
    s.campaign
        .poses
        .iter()
        .map(|pose| {
            // The same unit round trip as on the topics: mm -> m -> mm.
            let q = pose.q.map(|v| v / 1e3 * 1e3);
            let eq = fegm(p, &node_support::stiffness(), q, ALL_ACTIVE).expect("core fegm");
            let pct = |f: f64| f / NOMINAL_DRIVE_FORCE_N * 100.0;
            [0, 1, 2, 3].map(|i| pct(pose.f[i]) - pct(eq.drive_force[i]))
        })
        .collect()
}

/// First sample index at which the held level reaches `threshold` (debounced).
fn first_held(dev: &[[f64; 4]], threshold: f64) -> Option<usize> {
    let mut run = 0;
    for (k, d) in dev.iter().enumerate() {
        let worst = d.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        run = if worst >= threshold { run + 1 } else { 0 };
        if run >= DEBOUNCE {
            return Some(k);
        }
    }
    None
}

fn worst_drive(d: &[f64; 4]) -> usize {
    (0..4)
        .max_by(|&a, &b| d[a].abs().total_cmp(&d[b].abs()))
        .unwrap_or(0)
}

struct Observed {
    statuses: Vec<(usize, PreloadStatus)>,
    diagnostics: Vec<DiagnosticStatus>,
}

fn run(tag: &str, drift: fn(usize) -> f64) -> (Stream, Observed) {
    let dir = TempDir::new(tag);
    let stream = twin_stream(N, RATE_HZ, drift);
    let csv = dir.path("stream.csv");
    std::fs::write(&csv, stream.campaign.to_csv()).expect("write stream");
    let truth = dir.path("truth.json");
    write_truth_json(stream.twin.true_params(), &truth);
    std::fs::write(
        dir.path("params.yaml"),
        format!(
            "/**:\n  ros__parameters:\n    geometry_file: {}\n    diagnostics_period_s: 0.5\n\
             ingest:\n  ros__parameters:\n    rate_hz: {RATE_HZ}\n    start_delay_s: 1.5\n\
             tcp_estimator:\n  ros__parameters:\n    busy_poll_ms: 2.0\n\
             preload_monitor:\n  ros__parameters:\n    warn_percent: {WARN}\n    \
             error_percent: {ERROR}\n    debounce_samples: {DEBOUNCE}\n    status_every: 1\n    \
             busy_poll_ms: 2.0\n",
            truth.display()
        ),
    )
    .expect("params");
    let launch = launch_from_params(
        &dir,
        "test.launch.yaml",
        &csv,
        &["tcp_estimator", "preload_monitor"],
    );

    let prefix = unique(tag);
    let t = Transport::new(&TransportConfig::new(unique("obs")).ipc_prefix(&prefix))
        .expect("transport");
    let statuses_sub = t.subscriber(&topic::PRELOAD_STATUS).expect("sub");
    let diag_sub = t.subscriber(&topic::DIAGNOSTICS).expect("sub");
    let by_stamp: HashMap<_, _> = stream
        .campaign
        .poses
        .iter()
        .enumerate()
        .filter_map(|(k, p)| Some((stamp_from_seconds(p.t)?, k)))
        .collect();
    let mut launched = Launch::start(&launch, &[("RPKM_IPC_PREFIX", prefix.as_str())]);
    let mut obs = Observed {
        statuses: Vec::new(),
        diagnostics: Vec::new(),
    };
    let deadline = Instant::now() + Duration::from_secs(60);
    while Instant::now() < deadline {
        let mut idle = true;
        while let Some(s) = statuses_sub.try_recv().expect("recv") {
            idle = false;
            let k = *by_stamp.get(&s.stamp).expect("a stamp of the stream");
            obs.statuses.push((k, s));
        }
        while let Some(d) = diag_sub.try_recv().expect("recv") {
            idle = false;
            obs.diagnostics.extend(
                d.status
                    .into_iter()
                    .filter(|s| s.name == "rpkm/preload_monitor"),
            );
        }
        if obs.statuses.last().is_some_and(|(k, _)| *k == N - 1) {
            break;
        }
        if idle {
            std::thread::sleep(Duration::from_millis(1));
        }
    }
    // One more diagnostics period so that the final report is in.
    let settle = Instant::now() + Duration::from_millis(700);
    while Instant::now() < settle {
        while let Some(d) = diag_sub.try_recv().expect("recv") {
            obs.diagnostics.extend(
                d.status
                    .into_iter()
                    .filter(|s| s.name == "rpkm/preload_monitor"),
            );
        }
        while statuses_sub.try_recv().expect("recv").is_some() {}
        std::thread::sleep(Duration::from_millis(5));
    }
    launched.stop();
    assert_eq!(
        launched.started("preload_monitor").len(),
        1,
        "the monitor ran once, without crashing"
    );
    (stream, obs)
}

#[test]
fn incompatible_stream_raises_warn_then_error_on_the_right_drive() {
    let (stream, obs) = run("pm_bad", |k| 0.4 * k as f64 / (N - 1) as f64);
    let dev = expected_deviation(&stream);
    let k_warn = first_held(&dev, WARN).expect("the drift crosses WARN");
    let k_error = first_held(&dev, ERROR).expect("the drift crosses ERROR");
    assert!(k_warn < k_error);
    let ks: Vec<usize> = obs.statuses.iter().map(|(k, _)| *k).collect();
    assert_eq!(
        ks,
        (0..N).collect::<Vec<_>>(),
        "one PreloadStatus per sample, none lost"
    );
    let first = |level: u8| {
        obs.statuses
            .iter()
            .find(|(_, s)| s.level == level)
            .map(|(k, s)| (*k, *s))
    };
    let (kw, sw) = first(PreloadStatus::WARN).expect("a WARN");
    let (ke, se) = first(PreloadStatus::ERROR).expect("an ERROR");
    assert_eq!(kw, k_warn, "WARN at the sample the core gives");
    assert_eq!(ke, k_error, "ERROR at the sample the core gives");
    for (k, s) in [(kw, sw), (ke, se)] {
        for (i, (got, core)) in s.deviation.iter().zip(&dev[k]).enumerate() {
            assert!(
                (got - core).abs() < 1e-6,
                "sample {k} drive q{}: {got} vs core {core}",
                i + 1
            );
        }
    }
    // Levels never go back on a growing drift.
    assert!(obs
        .statuses
        .windows(2)
        .all(|w| w[1].1.level >= w[0].1.level));
    let drive = format!("drive q{}", worst_drive(&dev[k_error]) + 1);
    let warn_diag = obs
        .diagnostics
        .iter()
        .find(|d| d.level == DiagnosticStatus::WARN)
        .expect("a WARN on /diagnostics");
    assert!(warn_diag
        .message
        .contains(&format!("drive q{}", worst_drive(&dev[k_warn]) + 1)));
    let error_diag = obs
        .diagnostics
        .iter()
        .find(|d| d.level == DiagnosticStatus::ERROR)
        .expect("an ERROR on /diagnostics");
    assert!(
        error_diag.message.contains(&drive),
        "{}",
        error_diag.message
    );
    let worst_key = obs
        .diagnostics
        .iter()
        .rev()
        .find(|d| d.level == DiagnosticStatus::ERROR)
        .and_then(|d| d.values.iter().find(|v| v.key == "worst_drive"))
        .map(|v| v.value.clone());
    assert_eq!(worst_key.as_deref(), Some(&drive["drive ".len()..]));
    // The drift is on q3: the twin's truth says it is the drive that carries most of it.
    assert!(stream.drift_mm[N - 1] > 0.39);
}

#[test]
fn compatible_stream_stays_ok() {
    let (_stream, obs) = run("pm_ok", |_| 0.0);
    assert_eq!(obs.statuses.len(), N, "one PreloadStatus per sample");
    for (k, s) in &obs.statuses {
        assert_eq!(s.level, PreloadStatus::OK, "sample {k}: {s:?}");
        let worst = s.deviation.iter().fold(0.0f64, |m, d| m.max(d.abs()));
        assert!(worst < 1e-6, "sample {k}: deviation {worst} %");
        assert!(
            s.measured_current.iter().any(|c| c.abs() > 1.0),
            "the twin's controller is incompatible with the machine, so drives do carry \
             preload; the monitor predicts it: {s:?}"
        );
    }
    assert!(
        !obs.diagnostics.is_empty(),
        "the monitor reports on /diagnostics"
    );
    assert!(obs
        .diagnostics
        .iter()
        .all(|d| d.level == DiagnosticStatus::OK));
}
