//! The watch against independent truth: the preload node's own /diagnostics text for the
//! thresholds, hand-timed arrivals for silence, rates and latency.
#![expect(
    clippy::float_cmp,
    reason = "exact values: parsed, copied or computed without rounding"
)]
#![expect(
    clippy::cast_sign_loss,
    reason = "test and benchmark fixtures: counters, stamps and sizes far inside the target type's range"
)]

use super::*;
use rpkm_core::elastic::{fegm, Stiffness, ALL_ACTIVE};
use rpkm_core::geometry::igm;
use rpkm_core::params::{Model, Params};
use rpkm_msgs::{DiagnosticStatus, KeyValue};
use rpkm_nodes::node::preload_monitor::{Monitor, Thresholds as NodeThresholds};
use rpkm_nodes::node::Geometry;

fn watch() -> Watch {
    Watch::new(WatchConfig::default(), MonitorThresholds::unknown())
}

fn diag(name: &str, level: u8, message: &str) -> DiagnosticArray {
    DiagnosticArray {
        status: vec![DiagnosticStatus {
            level,
            name: format!("rpkm/{name}"),
            message: message.into(),
            hardware_id: String::new(),
            values: vec![KeyValue::default()],
        }],
        ..DiagnosticArray::default()
    }
}

/// A real preload_monitor (the node's state machine) with thresholds 30 / 80 % judging a
/// state whose q3 carrier sits `dq3` mm off its encoder (all drives holding), or, with
/// `followers`, whose q3 encoder reads `dq3` mm off the rigid model: its /diagnostics status.
fn node_status(dq3: f64, followers: bool) -> (DiagnosticStatus, PreloadStatus) {
    let p = Params::nominal();
    let mut node = Monitor::new(
        Geometry {
            params: p,
            model: Model::M29,
            stiffness: Stiffness::default(),
            source: "test".into(),
            effects: rpkm_nodes::node::effects::NodeEffects::default(),
        },
        NodeThresholds {
            warn_percent: 30.0,
            error_percent: 80.0,
            dq_warn_m: 40e-6,
            dq_error_m: 150e-6,
            debounce_samples: 1,
        },
    );
    let q = igm(&p, Model::M29, 0.0, 1700.0).expect("igm").q();
    let mut carriers = q;
    let mut encoders = q;
    if followers {
        encoders[2] += dq3;
    } else {
        carriers[2] += dq3;
    }
    let eq = fegm(&p, &Stiffness::default(), carriers, ALL_ACTIVE).expect("fegm");
    let follower = [false, followers, followers, false];
    let state = ActuatorState {
        position: encoders.map(|v| v / 1e3),
        force: eq.drive_force,
        follower,
        ..ActuatorState::default()
    };
    let e = node.evaluate(&state).expect("evaluated");
    (node.status("preload_monitor"), e.status)
}

#[test]
fn thresholds_come_from_the_preload_nodes_own_report() {
    let (st, _) = node_status(0.5, false);
    assert!(st.message.contains("thresholds"), "{}", st.message);
    assert_eq!(parse_thresholds(&st.message, "%"), Some((30.0, 80.0)));
    let mut w = watch();
    assert!(!w.thresholds.known());
    w.on_diagnostics(
        DiagnosticArray {
            status: vec![st],
            ..DiagnosticArray::default()
        },
        1.0,
    );
    assert_eq!(w.thresholds.source, ThresholdSource::Diagnostics);
    assert_eq!(
        (w.thresholds.warn_percent, w.thresholds.error_percent),
        (30.0, 80.0)
    );
}

#[test]
fn thresholds_are_read_from_the_reports_values_before_any_drive_state() {
    // A preload_monitor that has judged nothing yet says no thresholds in its sentence, but
    // its key-values carry all four as set.
    let node = Monitor::new(
        Geometry {
            params: Params::nominal(),
            model: Model::M29,
            stiffness: Stiffness::default(),
            source: "test".into(),
            effects: rpkm_nodes::node::effects::NodeEffects::default(),
        },
        NodeThresholds {
            warn_percent: 27.5,
            error_percent: 61.0,
            dq_warn_m: 4.5e-5,
            dq_error_m: 1.75e-4,
            debounce_samples: 1,
        },
    );
    let st = node.status("preload_monitor");
    assert_eq!(parse_thresholds(&st.message, "%"), None, "{}", st.message);
    let mut w = watch();
    w.on_diagnostics(
        DiagnosticArray {
            status: vec![st],
            ..DiagnosticArray::default()
        },
        1.0,
    );
    assert_eq!(w.thresholds.source, ThresholdSource::Diagnostics);
    assert_eq!(
        (w.thresholds.warn_percent, w.thresholds.error_percent),
        (27.5, 61.0)
    );
    assert_eq!(w.thresholds.dq_m, Some((4.5e-5, 1.75e-4)));
}

#[test]
fn follower_thresholds_come_from_the_follower_message() {
    // Followers q2, q3 with q3 read 0.3 mm off: the node names the Δq thresholds in mm.
    let (st, s) = node_status(0.3, true);
    assert!(
        (s.dq3 + 0.3e-3).abs() < 1e-6,
        "rgm gives back the true q3: {}",
        s.dq3
    );
    let mut w = watch();
    w.on_diagnostics(diag("preload_monitor", st.level, &st.message), 0.0);
    let (a, b) = w.thresholds.dq_m.expect("dq thresholds in the message");
    assert!(
        (a - 40e-6).abs() < 1e-12 && (b - 150e-6).abs() < 1e-12,
        "{a} {b}"
    );
    assert_eq!(w.thresholds.warn_percent, 30.0);
    assert_eq!(parse_thresholds("ERROR: follower q3 is +0.300 mm off the rigid model (thresholds 0.04 / 0.15 mm); drive q1 deviates +1.0 % (measured 1 %, predicted 0 %; thresholds 30 / 80 %)", "mm"), Some((0.04, 0.15)));
    assert_eq!(
        parse_thresholds(
            "no drive state evaluated yet (0 unsolved, 0 implausible)",
            "%"
        ),
        None
    );
    assert_eq!(parse_thresholds("thresholds nan / 80 %", "%"), None);
}

#[test]
fn a_params_file_wins_over_the_report() {
    let mut w = Watch::new(
        WatchConfig::default(),
        MonitorThresholds {
            warn_percent: 20.0,
            error_percent: 50.0,
            dq_m: None,
            source: ThresholdSource::ParamsFile("p.yaml".into()),
        },
    );
    w.on_diagnostics(
        diag("preload_monitor", 0, "OK: ...; thresholds 30 / 80 %)"),
        0.0,
    );
    assert_eq!(
        (w.thresholds.warn_percent, w.thresholds.error_percent),
        (20.0, 50.0)
    );
}

#[test]
fn drive_levels_against_the_thresholds_match_the_node() {
    // The node's own PreloadStatus of a 0.5 mm fault: the watch's per-drive level of the
    // worst drive is the node's sample level (debounce 1, so its held level).
    let (st, status) = node_status(0.5, false);
    let mut w = watch();
    w.on_diagnostics(diag("preload_monitor", st.level, &st.message), 0.0);
    w.on_preload(&status, 0.0);
    let drives = w.drives().expect("drives");
    let worst = drives
        .iter()
        .map(|d| d.3.expect("thresholds known"))
        .max()
        .expect("4 drives");
    assert_eq!(worst, status.level);
    assert_eq!(worst, st.level);
    // Measured current is the force in % of 8.6 kN.
    assert!(drives.iter().all(|d| d.0.is_finite()));
    let t = &w.thresholds;
    assert_eq!(t.level_of(29.9), Some(PreloadStatus::OK));
    assert_eq!(t.level_of(-30.0), Some(PreloadStatus::WARN));
    assert_eq!(t.level_of(79.99), Some(PreloadStatus::WARN));
    assert_eq!(t.level_of(-80.0), Some(PreloadStatus::ERROR));
    assert_eq!(MonitorThresholds::unknown().level_of(500.0), None);
    // a drive whose force is not measured (a cell without force sensing) has no level
    assert_eq!(t.level_of(f64::NAN), None);
}

#[test]
fn a_node_is_silent_after_its_patience_and_named() {
    let mut w = watch();
    // tcp_estimator reports every 0.2 s until 5.0 s; preload_monitor publishes until 10 s.
    for k in 0..=25 {
        w.on_diagnostics(diag("tcp_estimator", 0, "ok"), f64::from(k) * 0.2);
    }
    for k in 0..=1000 {
        w.on_preload(&PreloadStatus::default(), f64::from(k) * 0.01);
    }
    assert!(w.silent(5.9).is_empty(), "1.0 s patience not yet over");
    assert!(
        w.silent(6.0).is_empty(),
        "exactly 1.0 s quiet is not silent yet"
    );
    let silent = w.silent(6.05);
    assert_eq!(silent.len(), 1);
    assert_eq!(silent[0].0, "tcp_estimator");
    assert!((silent[0].1 - 1.05).abs() < 1e-9);
    assert!(
        w.nodes.contains_key("preload_monitor"),
        "named by its topic"
    );
    let both: Vec<&str> = w.silent(11.5).iter().map(|(n, _)| *n).collect();
    assert_eq!(both, ["preload_monitor", "tcp_estimator"]);
}

#[test]
fn a_slow_reporter_gets_one_and_a_half_periods() {
    let mut w = watch();
    for k in 0..5 {
        w.on_diagnostics(diag("calibrator", 0, "idle"), f64::from(k) * 2.0);
    }
    // Last report at 8 s, period 2 s: patience 3 s.
    assert!(w.silent(10.9).is_empty());
    assert_eq!(w.silent(11.1).len(), 1);
    // A node never heard is never called silent.
    assert!(!w.nodes.contains_key("ingest"));
}

#[test]
fn rates_count_a_second_and_fall_to_zero() {
    let mut w = watch();
    let e = TcpEstimate::default();
    for k in 0..=1000 {
        let t = f64::from(k) * 0.002; // 500 Hz for 2 s
        w.on_state(
            &ActuatorState {
                seq: k as u64,
                ..ActuatorState::default()
            },
            t,
        );
        w.on_estimate(&TcpEstimate { seq: k as u64, ..e }, t + 0.0004);
    }
    let r = w.estimate_rate.rate_hz();
    assert!((r - 500.0).abs() < 2.0, "{r}");
    assert!((w.state_rate.rate_hz() - 500.0).abs() < 2.0);
    let lat = w.latency.last_ms.expect("latency");
    assert!((lat - 0.4).abs() < 1e-6, "{lat}");
    w.tick(3.5);
    w.tick(4.6);
    assert_eq!(w.estimate_rate.rate_hz(), 0.0);
    assert_eq!(w.estimate_count, 1001);
}

#[test]
fn latency_needs_the_state_of_the_same_seq() {
    let mut w = watch();
    w.on_state(
        &ActuatorState {
            seq: 7,
            ..ActuatorState::default()
        },
        1.0,
    );
    w.on_estimate(
        &TcpEstimate {
            seq: 8,
            ..TcpEstimate::default()
        },
        1.001,
    );
    assert_eq!(w.latency.last_ms, None);
    w.on_estimate(
        &TcpEstimate {
            seq: 7,
            ..TcpEstimate::default()
        },
        1.002,
    );
    assert!((w.latency.last_ms.expect("latency") - 2.0).abs() < 1e-9);
}

#[test]
fn outcomes_and_fallback_reasons_are_counted() {
    let mut w = watch();
    let e = |outcome, reason| TcpEstimate {
        outcome,
        reason,
        ..TcpEstimate::default()
    };
    w.on_estimate(&e(TcpEstimate::OUTCOME_OK, 0), 0.0);
    w.on_estimate(
        &e(
            TcpEstimate::OUTCOME_WARM_REJECTED_COLD_OK,
            TcpEstimate::REASON_PLATFORM_ANGLE,
        ),
        0.1,
    );
    w.on_estimate(
        &e(
            TcpEstimate::OUTCOME_RIGID_FALLBACK,
            TcpEstimate::REASON_FAR_FROM_RIGID,
        ),
        0.2,
    );
    w.on_estimate(&e(TcpEstimate::OUTCOME_OK, 0), 0.3);
    let o = &w.outcomes;
    assert_eq!((o.ok, o.warm_rejected_cold_ok, o.rigid_fallback), (2, 1, 1));
    assert_eq!(o.last_reason.map(reason_name), Some("far_from_rigid"));
    let snap = w.snapshot(1.0);
    assert_eq!(snap["tcp_estimate"]["outcomes"]["rigid_fallback"], 1);
    assert_eq!(
        snap["tcp_estimate"]["last_fallback_reason"],
        "far_from_rigid"
    );
}

#[test]
fn level_history_is_bounded_and_remembers_the_first_crossings() {
    let mut w = Watch::new(
        WatchConfig {
            history_len: 4,
            history_bucket_s: 0.5,
            ..WatchConfig::default()
        },
        MonitorThresholds::unknown(),
    );
    // Two statuses per second: both land in the same half-second mark, the worst kept.
    for (k, level) in [0u8, 0, 1, 1, 2, 2, 1, 0].iter().enumerate() {
        let s = PreloadStatus {
            level: *level,
            ..PreloadStatus::default()
        };
        w.on_preload(&s, k as f64 * 0.5 + if k % 2 == 0 { 0.0 } else { 0.2 });
    }
    // Statuses at 0, 0.7, 1.0, 1.7, 2.0, 2.7, 3.0, 3.7 s: marks 0, 1, 2, 3, 4, 5, 6, 7.
    assert_eq!(
        w.history.iter().copied().collect::<Vec<_>>(),
        [(4, 2), (5, 2), (6, 1), (7, 0)]
    );
    w.on_preload(
        &PreloadStatus {
            level: 2,
            ..PreloadStatus::default()
        },
        3.9,
    );
    assert_eq!(
        w.history.back(),
        Some(&(7, 2)),
        "the worst level of the mark"
    );
    assert_eq!((w.first_warn_s, w.first_error_s), (Some(1.0), Some(2.0)));
    let snap = w.snapshot(7.0);
    assert_eq!(snap["preload"]["level"], "ERROR");
    assert_eq!(snap["preload"]["count"], 9);
    assert_eq!(snap["preload"]["history"]["WARN"], 3);
    assert_eq!(snap["preload"]["history"]["ERROR"], 3);
    // Unknown thresholds are null in JSON, never a made-up number.
    assert!(snap["thresholds"]["warn_percent"].is_null());
    assert_eq!(snap["thresholds"]["source"], "unknown");
}

/// Issue 41: "drive states 2000 at 1 Hz" beside "estimates 2000 at 403 Hz". Two streams that
/// arrived alike (1 kHz for 2 s), one with a stray early message: each read over the same
/// last second at a redraw, they read alike (before, each over its own window, whose phase
/// the stray message had moved: 833 against 1000 Hz here), and both fall to 0 once stopped.
#[test]
fn streams_that_arrive_alike_read_alike() {
    let mut w = watch();
    w.on_estimate(&TcpEstimate::default(), 0.1);
    for k in 0..2000u32 {
        let t = 0.6 + f64::from(k) * 0.001;
        w.on_state(&ActuatorState::default(), t);
        w.on_estimate(&TcpEstimate::default(), t + 0.0002);
    }
    w.tick(2.8);
    let (s, e) = (w.state_rate.rate_hz(), w.estimate_rate.rate_hz());
    // arrivals in (1.8, 2.8]: 800 of each, within a bucket of the window's edge
    assert!(
        (s - 800.0).abs() <= 10.0 && (e - s).abs() <= 10.0,
        "{s} {e}"
    );
    w.tick(4.0);
    assert_eq!(
        (w.state_rate.rate_hz(), w.estimate_rate.rate_hz()),
        (0.0, 0.0)
    );
}

/// A launch status as `rpkm launch` sends it: node name, state.
fn launch_status(entries: &[(&str, &str)]) -> DiagnosticArray {
    DiagnosticArray {
        status: vec![DiagnosticStatus {
            level: 0,
            name: format!("rpkm/{LAUNCH_STATUS}"),
            message: String::new(),
            hardware_id: String::new(),
            values: entries
                .iter()
                .map(|(k, v)| KeyValue {
                    key: (*k).to_owned(),
                    value: (*v).to_owned(),
                })
                .collect(),
        }],
        ..DiagnosticArray::default()
    }
}

/// Issue 41: "NOT HEARD: recorder" whenever record:=true. The launch marks its executables;
/// one is never waited for, a node still is, and an executable that died is GONE.
#[test]
fn the_recorder_is_an_executable_not_a_node_never_heard() {
    let mut w = watch();
    let running = format!("running{EXECUTABLE}");
    w.on_diagnostics(
        launch_status(&[("tcp_estimator", "running"), ("recorder", &running)]),
        1.0,
    );
    assert_eq!(w.not_heard(), ["tcp_estimator"]);
    let snap = w.snapshot(1.0);
    assert_eq!(snap["launch"][1]["name"], "recorder");
    assert_eq!(snap["launch"][1]["executable"], true);
    assert_eq!(snap["launch"][1]["state"], "running");
    let died = format!("{GONE}exited with code 1{EXECUTABLE}");
    w.on_diagnostics(
        launch_status(&[("tcp_estimator", "running"), ("recorder", &died)]),
        2.0,
    );
    assert_eq!(w.gone(), [("recorder", "exited with code 1")]);
}

/// preload_monitor's status naming the model it predicts with.
fn predicting_with(model: &str) -> DiagnosticArray {
    let mut a = diag("preload_monitor", 2, "ERROR: drive q1 deviates");
    a.status[0].values = vec![KeyValue {
        key: "parameters".into(),
        value: model.into(),
    }];
    a
}

/// Issue 41: an alarm of the nominal parameters stayed after a calibration replaced them.
/// Once preload_monitor says it predicts with another model (the first Parameters after the
/// nominal ones) or other Parameters come, the old model's first WARN/ERROR are cleared; the
/// same Parameters again (a late joiner's history) clear nothing.
#[test]
fn an_alarm_goes_with_the_model_that_raised_it() {
    let mut w = watch();
    let error = PreloadStatus {
        level: PreloadStatus::ERROR,
        ..PreloadStatus::default()
    };
    w.on_diagnostics(predicting_with("nominal parameters"), 0.5);
    w.on_preload(&error, 1.0);
    assert_eq!(w.first_error_s, Some(1.0));
    let calibrated = Parameters {
        model: 29,
        measurement_count: 194,
        ..Parameters::default()
    };
    w.on_parameters(calibrated.clone(), 2.0);
    w.on_diagnostics(
        predicting_with("/rpkm/parameters (model 29, 194 measurements)"),
        2.1,
    );
    assert_eq!((w.first_warn_s, w.first_error_s), (None, None));
    assert_eq!(w.model_replaced_s, Some(2.1));
    assert_eq!(w.snapshot(3.0)["model_replaced_s"], 2.1);
    // the new model's own alarm is kept, and the same set again clears nothing
    w.on_preload(&error, 3.0);
    w.on_parameters(calibrated.clone(), 3.5);
    assert_eq!(w.first_error_s, Some(3.0));
    // other Parameters: cleared again
    w.on_parameters(
        Parameters {
            measurement_count: 300,
            ..calibrated
        },
        4.0,
    );
    assert_eq!((w.first_error_s, w.model_replaced_s), (None, Some(4.0)));
}
