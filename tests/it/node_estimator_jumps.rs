//! Issue 16 through the launched stack: `bags/demo/campaign.csv` (1 m jumps between its setups)
//! streamed by ingest into the real tcp_estimator and preload_monitor processes with the
//! default (nominal) parameters, as `rpkm launch launch_scripts/rpkm.launch.yaml
//! source:=bags/demo/campaign.csv` does. Every TcpEstimate must lie within 2 mm of the rigid
//! model of its own encoders (computed here from the CSV, not by the nodes' solver), with ψ in
//! (−π, π] and flagged correctly: `converged: true` only for a plausible elastic equilibrium.
//! Before the plausibility checks, 118 of the 194 estimates were a turned-over platform
//! flagged converged, and the monitor predicted 749,800 % current.

use crate::node_support;

use std::collections::HashMap;
use std::f64::consts::PI;
use std::time::{Duration, Instant};

use node_support::{launch_from_params, unique, Launch, TempDir};
use rpkm_core::campaign::Campaign;
use rpkm_core::geometry::fgm;
use rpkm_core::params::{Model, Params};
use rpkm_msgs::TcpEstimate;
use rpkm_nodes::campaign_bag::stamp_from_seconds;
use rpkm_transport::{topic, Transport, TransportConfig};

const RATE_HZ: f64 = 200.0;

fn demo() -> Campaign {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/bags/demo/campaign.csv");
    let text = std::fs::read_to_string(path).expect("bags/demo/campaign.csv");
    Campaign::parse(&text, "demo").expect("demo campaign")
}

fn write_launch(dir: &TempDir) -> std::path::PathBuf {
    let csv = concat!(env!("CARGO_MANIFEST_DIR"), "/bags/demo/campaign.csv");
    std::fs::write(
        dir.path("params.yaml"),
        format!(
            "/**:\n  ros__parameters:\n    diagnostics_period_s: 0.2\n\
             ingest:\n  ros__parameters:\n    rate_hz: {RATE_HZ}\n    start_delay_s: 1.5\n\
             preload_monitor:\n  ros__parameters:\n    status_every: 1\n"
        ),
    )
    .expect("params");
    launch_from_params(
        dir,
        "jumps.launch.yaml",
        std::path::Path::new(csv),
        &["tcp_estimator", "preload_monitor"],
    )
}

#[test]
#[expect(
    clippy::too_many_lines,
    reason = "an end-to-end scenario, read top to bottom"
)]
fn demo_campaign_estimates_stay_on_the_rigid_model_of_their_pose() {
    let c = demo();
    let n = c.poses.len();
    let p = Params::nominal();
    let dir = TempDir::new("jumps");
    let launch = write_launch(&dir);
    let by_stamp: HashMap<_, _> = c
        .poses
        .iter()
        .enumerate()
        .filter_map(|(k, pose)| Some((stamp_from_seconds(pose.t)?, k)))
        .collect();
    let prefix = unique("jumps");
    let t = Transport::new(&TransportConfig::new(unique("obs")).ipc_prefix(&prefix))
        .expect("transport");
    let estimates = t.subscriber(&topic::TCP_ESTIMATE).expect("sub");
    let statuses = t.subscriber(&topic::PRELOAD_STATUS).expect("sub");
    let diagnostics = t.subscriber(&topic::DIAGNOSTICS).expect("sub");
    let mut launched = Launch::start(&launch, &[("RPKM_IPC_PREFIX", prefix.as_str())]);
    let mut seen = vec![false; n];
    let (mut worst_mm, mut worst_current, mut not_converged) = (0.0f64, 0.0f64, 0);
    let mut cold_after_warm = 0u64;
    let mut estimator_diag = None;
    let deadline = Instant::now() + Duration::from_secs(60);
    while Instant::now() < deadline && !(seen.iter().all(|s| *s) && estimator_diag.is_some()) {
        let mut idle = true;
        while let Some(e) = estimates.try_recv().expect("recv") {
            idle = false;
            let k = *by_stamp.get(&e.stamp).expect("a campaign stamp");
            let q = c.poses[k].q;
            let r = fgm(&p, Model::M29, q[0], q[3]).expect("rigid model of a campaign pose");
            let d = (e.x * 1e3 - r.x()).hypot(e.y * 1e3 - r.y());
            assert!(d < 2.0, "pose {} ({k}): {d} mm off the rigid model", k + 1);
            assert!(e.psi > -PI && e.psi <= PI, "pose {}: ψ {}", k + 1, e.psi);
            worst_mm = worst_mm.max(d);
            not_converged += usize::from(!e.converged);
            // The message's own flag agrees with converged, and names a check when it says
            // the warm solve was rejected.
            match e.outcome {
                TcpEstimate::OUTCOME_OK => assert_eq!(e.reason, TcpEstimate::REASON_NONE),
                TcpEstimate::OUTCOME_WARM_REJECTED_COLD_OK => {
                    assert!((1..=6).contains(&e.reason), "pose {}: {e:?}", k + 1);
                    cold_after_warm += 1;
                }
                other => panic!("pose {}: outcome {other} ({e:?})", k + 1),
            }
            seen[k] = true;
        }
        while let Some(s) = statuses.try_recv().expect("recv") {
            idle = false;
            for c in s.predicted_current {
                worst_current = worst_current.max(c.abs());
            }
        }
        while let Some(a) = diagnostics.try_recv().expect("recv") {
            idle = false;
            for st in a.status {
                if st.name.ends_with("tcp_estimator") && seen.iter().all(|s| *s) {
                    estimator_diag = Some(st);
                }
            }
        }
        if idle {
            std::thread::sleep(Duration::from_millis(1));
        }
    }
    launched.stop();
    let missing: Vec<usize> = (0..n).filter(|&k| !seen[k]).map(|k| k + 1).collect();
    assert!(missing.is_empty(), "no estimate for poses {missing:?}");
    // In follower mode nothing is preloaded: every pose has a plausible elastic equilibrium.
    assert_eq!(not_converged, 0, "estimates flagged not converged");
    assert!(worst_mm < 1e-3, "worst {worst_mm} mm");
    assert!(
        worst_current < 1000.0,
        "predicted current {worst_current} %"
    );
    let st = estimator_diag.expect("estimator /diagnostics after the last estimate");
    let value = |k: &str| {
        st.values
            .iter()
            .find(|v| v.key == k)
            .map(|v| v.value.clone())
    };
    eprintln!("estimator /diagnostics: {} {:?}", st.message, st.values);
    assert_eq!(st.level, 0, "{}", st.message);
    let rejected: u64 = value("warm_rejected")
        .and_then(|v| v.parse().ok())
        .expect("warm_rejected");
    assert!(rejected >= 1, "the 1 m jumps were caught: {}", st.message);
    assert_eq!(
        cold_after_warm, rejected,
        "one estimate flagged WARM_REJECTED_COLD_OK per rejected warm start"
    );
}
