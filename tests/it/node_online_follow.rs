//! Calibration that never stops, node to node (issue 15): `rpkm launch` starts ingest, the
//! calibrator with `online: true`, the tcp_estimator and the preload_monitor (both following
//! `/rpkm/parameters`, their default) on the twin's production stream with a crash
//! (`rpkm simulate --production-seconds 40 --production-step l3=0.1@15`), replayed four
//! times faster than it was recorded. Everything is checked against the twin's truth over
//! time (`prod.truth.csv`), never against the nodes' own arithmetic:
//! - the calibrator publishes Parameters after the crash whose l3 is the truth's;
//! - the estimator's TCP error against the twin's true TCP jumps at the crash and falls back
//!   near its pre-crash level once it follows, while the geometry it started with (what it
//!   would keep without following, evaluated by the core) stays off by the crash;
//! - the preload monitor's predicted-vs-measured residual jumps and falls back likewise;
//! - the calibrator's WARN on /diagnostics names the rod.

use crate::node_support;

use std::collections::HashMap;
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use node_support::{launch_from_params, rpkm, unique, Launch, TempDir};
use rpkm_core::campaign::Campaign;
use rpkm_core::elastic::{fegm, Stiffness, ALL_ACTIVE, NOMINAL_DRIVE_FORCE_N};
use rpkm_core::params::{index_of, Params, NAMES, N_PARAMS};
use rpkm_msgs::{DiagnosticStatus, Parameters, PreloadStatus, Time};
use rpkm_nodes::campaign_bag::stamp_from_seconds;
use rpkm_transport::{topic, Transport, TransportConfig};

const SECONDS: f64 = 40.0;
const STEP_AT_S: f64 = 15.0;
const STEP_MM: f64 = 0.1;
/// Rows of the stream file per second of stream (1 kHz written every 100th sample).
const ROWS_HZ: f64 = 10.0;
/// Replay: four times the stream's own rate.
const REPLAY_HZ: f64 = 40.0;

/// One row of the twin's truth over time.
struct Truth {
    t: f64,
    tcp: [f64; 2],
    params: Params,
}

fn read_truth(path: &Path) -> Vec<Truth> {
    let text = std::fs::read_to_string(path).expect("truth csv");
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().expect("truth header").split(',').collect();
    assert_eq!(&header[..4], ["t", "x", "y", "psi"], "truth header");
    assert_eq!(header[8..], NAMES[..], "truth header: the 29 parameters");
    lines
        .map(|l| {
            let v: Vec<f64> = l
                .split(',')
                .map(|s| s.parse().expect("truth number"))
                .collect();
            let mut params = Params::nominal();
            for i in 0..N_PARAMS {
                params[i] = v[8 + i];
            }
            Truth {
                t: v[0],
                tcp: [v[1], v[2]],
                params,
            }
        })
        .collect()
}

/// Runs `rpkm ARGS` in `dir`, which must succeed.
fn rpkm_in(dir: &TempDir, args: &[&str]) {
    let out = Command::new(rpkm())
        .args(args)
        .current_dir(&dir.0)
        .output()
        .expect("rpkm runs");
    assert!(
        out.status.success(),
        "rpkm {}: {}",
        args.join(" "),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// What the test saw on the topics, keyed by the truth row of each stamp.
#[derive(Default)]
struct Observed {
    /// Truth row, the estimator's TCP (x, y mm).
    tcp: Vec<(usize, [f64; 2])>,
    /// Truth row, RMS over the drives of measured − predicted force (N).
    preload_residual: Vec<(usize, f64)>,
    parameters: Vec<Parameters>,
    calibrator: Vec<DiagnosticStatus>,
}

fn launch_files(dir: &TempDir, csv: &Path, geometry: &Path) -> std::path::PathBuf {
    std::fs::write(
        dir.path("params.yaml"),
        format!(
            "/**:\n  ros__parameters:\n    geometry_file: {}\n    diagnostics_period_s: 0.5\n\
             ingest:\n  ros__parameters:\n    rate_hz: {REPLAY_HZ}\n    start_delay_s: 1.5\n\
             calibrator:\n  ros__parameters:\n    online: true\n    online_decimation: 1\n\
             tcp_estimator:\n  ros__parameters:\n    follow_parameters: true\n\
             preload_monitor:\n  ros__parameters:\n    follow_parameters: true\n    \
             status_every: 1\n    warn_percent: 1000.0\n    error_percent: 2000.0\n",
            geometry.display()
        ),
    )
    .expect("params");
    launch_from_params(
        dir,
        "online.launch.yaml",
        csv,
        &["calibrator", "tcp_estimator", "preload_monitor"],
    )
}

fn observe(launch: &Path, truth: &[Truth]) -> Observed {
    let prefix = unique("online");
    let t = Transport::new(&TransportConfig::new(unique("obs")).ipc_prefix(&prefix))
        .expect("transport");
    let estimates = t.subscriber(&topic::TCP_ESTIMATE).expect("sub");
    let preload = t.subscriber(&topic::PRELOAD_STATUS).expect("sub");
    let parameters = t.subscriber(&topic::PARAMETERS).expect("sub");
    let diagnostics = t.subscriber(&topic::DIAGNOSTICS).expect("sub");
    let row: HashMap<Time, usize> = truth
        .iter()
        .enumerate()
        .filter_map(|(k, r)| Some((stamp_from_seconds(r.t)?, k)))
        .collect();
    let mut launched = Launch::start(launch, &[("RPKM_IPC_PREFIX", prefix.as_str())]);
    let mut obs = Observed::default();
    let last = truth.len() - 1;
    let (mut est_done, mut pre_done) = (false, false);
    // generous on a loaded machine: the replay itself takes 10 s
    let deadline = Instant::now() + Duration::from_secs(120);
    while !(est_done && pre_done) {
        assert!(
            Instant::now() < deadline,
            "the stream did not come through in 120 s: {} estimates, {} preload statuses, \
             {} Parameters",
            obs.tcp.len(),
            obs.preload_residual.len(),
            obs.parameters.len()
        );
        let mut idle = true;
        while let Some(e) = estimates.try_recv().expect("recv") {
            idle = false;
            let k = *row
                .get(&e.stamp)
                .expect("an estimate of a stamp of the stream");
            est_done |= k == last;
            obs.tcp.push((k, [e.x * 1e3, e.y * 1e3]));
        }
        while let Some(s) = preload.try_recv().expect("recv") {
            idle = false;
            let k = *row
                .get(&s.stamp)
                .expect("a status of a stamp of the stream");
            pre_done |= k == last;
            obs.preload_residual.push((k, residual_n(&s)));
        }
        while let Some(p) = parameters.try_recv().expect("recv") {
            idle = false;
            obs.parameters.push(p);
        }
        while let Some(d) = diagnostics.try_recv().expect("recv") {
            idle = false;
            obs.calibrator
                .extend(d.status.into_iter().filter(|s| s.name == "rpkm/calibrator"));
        }
        if idle {
            std::thread::sleep(Duration::from_millis(2));
        }
    }
    launched.stop();
    assert_eq!(
        launched.started("calibrator").len(),
        1,
        "the calibrator ran once, without crashing"
    );
    obs
}

fn residual_n(s: &PreloadStatus) -> f64 {
    let sq: f64 = s
        .deviation
        .iter()
        .map(|d| (d / 100.0 * NOMINAL_DRIVE_FORCE_N).powi(2))
        .sum();
    (sq / 4.0).sqrt()
}

/// RMS of the values whose truth row lies in the stream-time window [from, to).
fn rms_in(values: &[(usize, f64)], truth: &[Truth], from: f64, to: f64) -> f64 {
    let v: Vec<f64> = values
        .iter()
        .filter(|(k, _)| (from..to).contains(&truth[*k].t))
        .map(|(_, v)| *v)
        .collect();
    assert!(!v.is_empty(), "no values in [{from}, {to}) s");
    (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
}

/// `--production-step` of the crash.
fn crash() -> String {
    format!("--production-step=l3={STEP_MM}@{STEP_AT_S}")
}

/// The twin's production stream of `seconds` into `out` (CSV, its truth beside it), with
/// `extra` arguments (a crash, a commanded motion).
fn production(dir: &TempDir, twin: &[&str], seconds: f64, extra: &[&str], out: &str) {
    let (seconds, decimate) = (seconds.to_string(), (1000.0 / ROWS_HZ).to_string());
    let args = [
        &["simulate", "--production-seconds", &seconds][..],
        extra,
        &["--production-decimate", &decimate, "--out", out],
        twin,
    ];
    rpkm_in(dir, &args.concat());
}

/// The cell runs the motion the WARN named a second after it (the same stream, the
/// commanded poses a second each: `rpkm simulate --production-visit`), and the calibrator
/// settles the tie: l3 alone, l1 ruled out, on /diagnostics.
fn settle_by_the_motion(
    dir: &TempDir,
    twin: &[&str],
    geometry: &Path,
    motion: &[(f64, f64)],
    named_at: f64,
) {
    let poses: Vec<String> = motion.iter().map(|(x, y)| format!("{x},{y}")).collect();
    let visit = format!("--production-visit={}@{}", poses.join(";"), named_at + 1.0);
    // the way there at feed speed (50 mm/s) may cross the workspace: 40 s more
    production(dir, twin, SECONDS + 40.0, &[&crash(), &visit], "motion.csv");
    let truth = read_truth(&dir.path("motion.truth.csv"));
    let obs = observe(
        &launch_files(dir, &dir.path("motion.csv"), geometry),
        &truth,
    );
    let settled = obs
        .calibrator
        .iter()
        .find(|d| d.message.contains("settled"))
        .unwrap_or_else(|| panic!("the tie settled on /diagnostics: {:?}", obs.calibrator));
    let at = settled
        .values
        .iter()
        .find(|v| v.key == "online_t_s")
        .map_or("?", |v| v.value.as_str());
    let dropped = obs
        .calibrator
        .iter()
        .rev()
        .find_map(|d| d.values.iter().find(|v| v.key == "online_dropped"))
        .map_or("?", |v| v.value.as_str());
    eprintln!("the tracker dropped {dropped} samples");
    eprintln!(
        "with the motion {motion:?} from {:.1} s: at {at} s {}",
        named_at + 1.0,
        settled.message
    );
    assert_eq!(settled.level, DiagnosticStatus::WARN);
    assert!(settled.message.contains("l3 alone"), "{}", settled.message);
    let value = |k: &str| {
        settled
            .values
            .iter()
            .find(|v| v.key == k)
            .map(|v| v.value.as_str())
    };
    assert_eq!(
        (value("settled"), value("ruled_out")),
        (Some("l3"), Some("l1"))
    );
}

#[test]
#[expect(
    clippy::too_many_lines,
    reason = "an end-to-end scenario, read top to bottom"
)]
fn the_estimator_and_the_monitor_follow_the_online_calibration_through_a_crash() {
    let dir = TempDir::new("online_follow");
    // the start: a calibration of the same twin (seed) as a user makes one, tracker,
    // self-calibration and 500 production poses, written with its covariance
    let seed = "5";
    let twin = ["--effect", "preload_elastic", "--seed", seed];
    let sim = [
        &[
            "simulate",
            "--campaign",
            "lt,self,production",
            "--validation",
            "0",
        ][..],
        &twin,
    ]
    .concat();
    rpkm_in(&dir, &[&sim[..], &["--out", "start.csv"]].concat());
    // with the effect the discovery names on this campaign (core/tests/it/
    // calibration_currents_online.rs diagnoses the same design): the lt poses are loaded
    rpkm_in(
        &dir,
        &[
            "calibrate",
            "start.csv",
            "--effects",
            "preload_elastic",
            "--json",
            "start.json",
        ],
    );
    production(&dir, &twin, SECONDS, &[&crash()], "prod.csv");
    production(&dir, &twin, SECONDS, &[], "calm.csv");
    let no_crash = read_truth(&dir.path("calm.truth.csv"));
    let csv = dir.path("prod.csv");
    let truth = read_truth(&dir.path("prod.truth.csv"));
    assert_eq!(
        truth.len(),
        rpkm_core::convert::round_count(SECONDS * ROWS_HZ),
        "truth rows"
    );
    let geometry = dir.path("start.json");
    let start = rpkm_nodes::input::read_params(&geometry).expect("start calibration");
    let obs = observe(&launch_files(&dir, &csv, &geometry), &truth);

    let l3 = index_of("l3").expect("l3");
    let after = &truth[truth.len() - 1].params;
    // the calibrator published the crash: its last Parameters hold the truth's l3 within
    // their own 3σ (the forces see combinations of the parameters; the σ says how well)
    let published = obs
        .parameters
        .last()
        .expect("Parameters from the calibrator");
    let (l3_published, l3_sigma) = (published.values[l3] * 1e3, published.sigmas[l3] * 1e3);
    for p in &obs.parameters {
        eprintln!(
            "published l3 {:.4} ± {:.4} mm",
            p.values[l3] * 1e3,
            p.sigmas[l3] * 1e3
        );
    }
    assert!(
        (l3_published - after[l3]).abs() < 3.0 * l3_sigma,
        "published l3 {l3_published:.4} ± {l3_sigma:.4} mm, truth {:.4} mm (start {:.4} mm)",
        after[l3],
        start[l3]
    );
    let warn = obs
        .calibrator
        .iter()
        .find(|d| d.level == DiagnosticStatus::WARN && d.message.contains("step change"))
        .unwrap_or_else(|| panic!("a step WARN on /diagnostics: {:?}", obs.calibrator));
    assert!(warn.message.contains("l3"), "{}", warn.message);
    // on this path the crash ties l3 with l1 (issue 28): the WARN names the motion that
    // separates them, its poses in SI
    assert!(warn.message.contains("l3 or l1"), "{}", warn.message);
    assert!(
        warn.message
            .contains("to tell them apart drive through x, y = "),
        "{}",
        warn.message
    );
    let value = |k: &str| {
        warn.values
            .iter()
            .find(|v| v.key == k)
            .map_or_else(|| panic!("{k} in {:?}", warn.values), |v| v.value.clone())
    };
    let number = |k: &str| value(k).parse::<f64>().expect("a number");
    let motion: Vec<(f64, f64)> = value("separating_poses_m")
        .split("; ")
        .map(|p| {
            let (x, y) = p.split_once(' ').expect("x y");
            (
                x.parse::<f64>().expect("x") * 1e3,
                y.parse::<f64>().expect("y") * 1e3,
            )
        })
        .collect();
    let (xr, yr) = (rpkm_core::design::X_RANGE, rpkm_core::design::Y_RANGE);
    assert!(
        motion
            .iter()
            .all(|(x, y)| (xr.0..=xr.1).contains(x) && (yr.0..=yr.1).contains(y)),
        "{motion:?}"
    );
    assert_eq!(
        (
            number("separating_x_m") * 1e3,
            number("separating_y_m") * 1e3
        ),
        motion[0]
    );
    // without the motion the tie stays open, and the periodic status says so
    assert!(
        !obs.calibrator.iter().any(|d| d.message.contains("settled")),
        "settled without the motion: {:?}",
        obs.calibrator
    );
    let open = obs
        .calibrator
        .iter()
        .rev()
        .find_map(|d| {
            d.values
                .iter()
                .find(|v| v.key == "online_tie_evidence_chi2")
        })
        .map(|v| v.value.clone());
    let tie = obs
        .calibrator
        .iter()
        .rev()
        .find_map(|d| d.values.iter().find(|v| v.key == "online_tie"))
        .map(|v| v.value.clone());
    eprintln!("without the motion: {tie:?} open, evidence {open:?}");
    assert_eq!(tie.as_deref(), Some("l3 or l1"));
    settle_by_the_motion(&dir, &twin, &geometry, &motion, number("online_t_s"));
    // windows of stream time: before the crash, its first second (nothing can have been
    // named yet: a step needs ten held samples), the last ten seconds (followed)
    let window = |v: &[(usize, f64)]| {
        (
            rms_in(v, &truth, 5.0, STEP_AT_S),
            rms_in(v, &truth, STEP_AT_S, STEP_AT_S + 0.9),
            rms_in(v, &truth, SECONDS - 10.0, SECONDS),
        )
    };
    // The start calibration has its own TCP error (the twin's machine is not the model's
    // 29 parameters); what the crash does is the difference of the twin's true TCP with and
    // without it (same seed, same path and noise). The estimator's departure from the
    // geometry it started with (evaluated by the core: what it would give without following)
    // must match that displacement once it follows.
    let k = Stiffness::default();
    let text = std::fs::read_to_string(&csv).expect("stream csv");
    let stream = Campaign::parse(&text, "prod.csv").expect("stream csv parses");
    let mut error = Vec::new();
    let mut error_frozen = Vec::new();
    let mut raw = Vec::new();
    for &(row, est) in &obs.tcp {
        let eq = fegm(&start, &k, stream.poses[row].q, ALL_ACTIVE).expect("core fegm");
        let crash = [0, 1].map(|a| truth[row].tcp[a] - no_crash[row].tcp[a]);
        let moved = [est[0] - eq.x, est[1] - eq.y];
        error.push((row, (moved[0] - crash[0]).hypot(moved[1] - crash[1])));
        error_frozen.push((row, crash[0].hypot(crash[1])));
        raw.push((
            row,
            (est[0] - truth[row].tcp[0]).hypot(est[1] - truth[row].tcp[1]),
        ));
    }
    let (tcp_pre, tcp_crash, tcp_followed) = window(&error);
    let tcp_frozen = rms_in(&error_frozen, &truth, SECONDS - 10.0, SECONDS);
    let (raw_pre, _, raw_followed) = window(&raw);
    let (f_pre, f_crash, f_followed) = window(&obs.preload_residual);
    eprintln!(
        "TCP error from the crash, RMS µm: before {:.1}, crash {:.1}, followed {:.1}, \
         frozen {:.1} (against the true TCP: {:.1} before, {:.1} followed); preload residual \
         RMS N: before {f_pre:.1}, crash {f_crash:.1}, followed {f_followed:.1}; {} Parameters; \
         WARN: {}",
        tcp_pre * 1e3,
        tcp_crash * 1e3,
        tcp_followed * 1e3,
        tcp_frozen * 1e3,
        raw_pre * 1e3,
        raw_followed * 1e3,
        obs.parameters.len(),
        warn.message
    );
    assert!(tcp_crash > 3.0 * tcp_pre, "the crash moves the TCP");
    assert!(
        tcp_followed < 2.0 * tcp_pre.max(0.005),
        "followed: {:.1} µm, before the crash {:.1} µm",
        tcp_followed * 1e3,
        tcp_pre * 1e3
    );
    assert!(tcp_frozen > 3.0 * tcp_followed, "frozen stays off");
    assert!(f_crash > 10.0 * f_pre, "the crash moves the forces");
    assert!(
        f_followed < 2.0 * f_pre,
        "the monitor's residual falls back: {f_followed:.1} N, before {f_pre:.1} N"
    );
}
