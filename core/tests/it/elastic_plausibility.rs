//! Plausibility of elastic equilibria (issue 16): the checks reject the non-physical branches
//! a warm-started solve can land on after a 1 m jump, and accept the machine's equilibria;
//! the guarded solve replays campaigns with 1 m jumps and every estimate stays within 2 mm of
//! truth that does not come from the elastic solver (the rigid forward model of the same
//! encoders, the twin's true poses, the targets of compatible commands).
#![expect(
    clippy::float_cmp,
    reason = "exact values: parsed, copied or computed without rounding"
)]

use std::f64::consts::PI;

use rpkm_core::campaign::Campaign;
use rpkm_core::elastic::plausibility::check;
use rpkm_core::elastic::{
    fegm, fegm_checked, fegm_from, fegm_unchecked, wrap_angle, Equilibrium, Limits, Reason,
    RigidPose, Stiffness, ALL_ACTIVE, FOLLOWERS_23,
};
use rpkm_core::geometry::{fgm, igm};
use rpkm_core::params::{self, Model, Params};
use rpkm_twin::{Twin, TwinConfig};

const DEMO: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../bags/demo/campaign.csv");

fn demo() -> Campaign {
    let text = std::fs::read_to_string(DEMO).expect("bags/demo/campaign.csv");
    Campaign::parse(&text, "demo").expect("demo campaign parses")
}

fn truth_params() -> Params {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../bags/demo/truth.json");
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path).expect("truth")).expect("json");
    let mut p = Params::nominal();
    for (name, v) in truth["params"].as_object().expect("params") {
        p[params::index_of(name).expect("known name")] = v.as_f64().expect("number");
    }
    p
}

/// Distance of an equilibrium's TCP from the rigid model of (q1, q4), mm.
fn off_rigid(p: &Params, q: &[f64; 4], eq: &Equilibrium) -> f64 {
    let r = fgm(p, Model::M29, q[0], q[3]).expect("rigid model of a campaign pose");
    (eq.x - r.x()).hypot(eq.y - r.y())
}

/// The demo campaign estimated sample after sample, each solve warm-started from the last
/// (what tcp_estimator does); returns (wrong estimates, unsolved).
fn replay(p: &Params, c: &Campaign, checked: bool) -> (usize, usize) {
    let k = Stiffness::default();
    let (mut prev, mut wrong, mut unsolved) = (None::<Equilibrium>, 0, 0);
    for pose in &c.poses {
        let r = if checked {
            fegm_checked(
                p,
                &k,
                pose.q,
                pose.follower,
                prev.as_ref(),
                &Limits::default(),
            )
            .map(|s| s.eq)
        } else {
            fegm_unchecked(p, &k, pose.q, pose.follower, prev.as_ref())
        };
        if let Ok(eq) = r {
            if off_rigid(p, &pose.q, &eq) > 2.0 || eq.psi.abs() > PI || eq.psi.is_nan() {
                wrong += 1;
            }
            prev = Some(eq);
        } else {
            unsolved += 1;
            prev = None;
        }
    }
    (wrong, unsolved)
}

#[test]
fn demo_campaign_warm_chain_never_leaves_the_machine() {
    let c = demo();
    assert_eq!(c.poses.len(), 194);
    for p in [Params::nominal(), truth_params()] {
        let (raw_wrong, _) = replay(&p, &c, false);
        // The bug of issue 16, kept visible: the raw warm chain goes wrong at the 1 m jump.
        assert!(raw_wrong >= 100, "raw warm chain: {raw_wrong} wrong");
        let (wrong, unsolved) = replay(&p, &c, true);
        assert_eq!((wrong, unsolved), (0, 0), "checked warm chain");
    }
}

#[test]
fn the_wrong_branch_of_the_demo_is_rejected_and_the_cold_solve_accepted() {
    let c = demo();
    let p = Params::nominal();
    let k = Stiffness::default();
    // Pose 76 -> 77 (0-based) is the 1 m jump between the laser tracker and the first
    // self-calibration line.
    let (a, b) = (&c.poses[75], &c.poses[76]);
    let prev = fegm(&p, &k, a.q, a.follower).expect("pose 76");
    let raw = fegm_unchecked(&p, &k, b.q, b.follower, Some(&prev)).expect("raw solve");
    let rigid = fgm(&p, Model::M29, b.q[0], b.q[3]).expect("rigid");
    let reference = RigidPose {
        x: rigid.x(),
        y: rigid.y(),
        psi: rigid.psi(),
    };
    let limits = Limits::default();
    let v = check(&p, &k, &b.q, &b.follower, &raw, &reference, &limits).expect_err("wrong");
    assert!(
        off_rigid(&p, &b.q, &raw) > 100.0,
        "the raw solve is far off"
    );
    assert_eq!(v.reason, Reason::PlatformAngle, "{v}");
    let s = fegm_checked(&p, &k, b.q, b.follower, Some(&prev), &limits).expect("checked");
    assert!(s.cold, "retried cold");
    assert_eq!(
        s.warm_rejected.map(|v| v.reason),
        Some(Reason::PlatformAngle)
    );
    assert!(
        off_rigid(&p, &b.q, &s.eq) < 1e-6,
        "follower mode: the rigid pose"
    );
    assert!(check(&p, &k, &b.q, &b.follower, &s.eq, &reference, &limits).is_ok());
}

/// A correct preloaded equilibrium (q3 0.2 mm off at the workspace centre) and its rigid pose.
fn good() -> (Params, [f64; 4], Equilibrium, RigidPose) {
    let p = Params::nominal();
    let mut q = igm(&p, Model::M29, 30.0, 1700.0).expect("igm").q();
    q[2] += 0.2;
    let eq = fegm(&p, &Stiffness::default(), q, ALL_ACTIVE).expect("fegm");
    let r = fgm(&p, Model::M29, q[0], q[3]).expect("fgm");
    let rigid = RigidPose {
        x: r.x(),
        y: r.y(),
        psi: r.psi(),
    };
    (p, q, eq, rigid)
}

fn reason_of(p: &Params, q: &[f64; 4], eq: &Equilibrium, rigid: &RigidPose) -> Option<Reason> {
    let k = Stiffness::default();
    check(p, &k, q, &ALL_ACTIVE, eq, rigid, &Limits::default())
        .err()
        .map(|v| v.reason)
}

#[test]
fn checks_accept_a_correct_equilibrium_and_name_each_violation() {
    let (p, q, eq, rigid) = good();
    assert!(eq.max_current() > 10.0, "preloaded: {} %", eq.max_current());
    assert_eq!(reason_of(&p, &q, &eq, &rigid), None);
    // The figures of issue 16: ψ = −9.49 rad, loop residual 1 m, rod forces 9e7 N.
    let turned = Equilibrium { psi: -9.49, ..eq };
    assert_eq!(
        reason_of(&p, &q, &turned, &rigid),
        Some(Reason::PlatformAngle)
    );
    let mut forces = eq;
    forces.rod_force[0] = 9e7;
    assert_eq!(reason_of(&p, &q, &forces, &rigid), Some(Reason::ForceLimit));
    let mut drive = eq;
    drive.drive_force[3] = -1e6;
    assert_eq!(reason_of(&p, &q, &drive, &rigid), Some(Reason::ForceLimit));
    let mut carrier = eq;
    carrier.carrier[1] += 1000.0;
    assert_eq!(
        reason_of(&p, &q, &carrier, &rigid),
        Some(Reason::LoopClosure)
    );
    let mut stretched = eq;
    stretched.rod_force[2] += 5000.0; // 0.05 mm of stretch the rod does not have
    assert_eq!(
        reason_of(&p, &q, &stretched, &rigid),
        Some(Reason::LoopClosure)
    );
    let far = RigidPose {
        x: rigid.x + 3.0,
        ..rigid
    };
    assert_eq!(reason_of(&p, &q, &eq, &far), Some(Reason::FarFromRigid));
    let nan = Equilibrium { x: f64::NAN, ..eq };
    assert_eq!(reason_of(&p, &q, &nan, &rigid), Some(Reason::NotConverged));
}

#[test]
fn an_unbalanced_platform_is_rejected() {
    // The rod forces of another preload (q2 instead of q3 off) on this pose: each force is
    // within the drives, each stretch within the loosened closure limit, but the platform is
    // not in balance.
    let (p, q, eq, rigid) = good();
    let mut q2 = igm(&p, Model::M29, 30.0, 1700.0).expect("igm").q();
    q2[1] -= 0.3;
    let other = fegm(&p, &Stiffness::default(), q2, ALL_ACTIVE).expect("fegm");
    let mut unbalanced = eq;
    unbalanced.rod_force = other.rod_force;
    let k = Stiffness::default();
    let limits = Limits {
        closure_mm: 1.0,
        ..Limits::default()
    };
    let v = check(&p, &k, &q, &ALL_ACTIVE, &unbalanced, &rigid, &limits).expect_err("off");
    assert_eq!(v.reason, Reason::ForceBalance, "{v}");
}

#[test]
fn psi_is_wrapped() {
    assert_eq!(wrap_angle(PI), PI);
    assert!(
        (wrap_angle(-PI) - PI).abs() < 1e-15,
        "(−π, π]: −π maps to π"
    );
    // the issue's −6.2832 rad (a whole turn: 0), written off the constant
    let turn = -2.0 * PI - 1e-5;
    assert!((wrap_angle(turn) + 1e-5).abs() < 1e-12);
    assert!((wrap_angle(-9.49) - (-9.49 + 4.0 * PI)).abs() < 1e-12);
    assert!((wrap_angle(7.0) - (7.0 - 2.0 * PI)).abs() < 1e-12);
    assert_eq!(wrap_angle(1e-4), 1e-4);
    // A warm start a whole turn away gives the same equilibrium, published wrapped.
    let (p, q, eq, _) = good();
    let turned = Equilibrium {
        psi: eq.psi - 2.0 * PI,
        ..eq
    };
    let again = fegm_from(&p, &Stiffness::default(), q, ALL_ACTIVE, &turned).expect("warm");
    assert!(again.psi.abs() < 0.01 && (again.psi - eq.psi).abs() < 1e-9);
    let raw = fegm_unchecked(&p, &Stiffness::default(), q, ALL_ACTIVE, Some(&turned)).expect("raw");
    assert!(
        raw.psi > -PI && raw.psi <= PI,
        "the core result is wrapped: {}",
        raw.psi
    );
}

/// Targets alternating between the ends of the workspace: every step a jump of 1 m or more.
fn jumping_targets() -> Vec<(f64, f64)> {
    let mut out = Vec::new();
    for (i, x) in [-150.0, -75.0, 0.0, 75.0, 150.0].into_iter().enumerate() {
        for y in [700.0, 2700.0, 1700.0, 2600.0, 800.0] {
            out.push((if i % 2 == 0 { x } else { -x }, y));
        }
    }
    out
}

#[test]
fn twin_campaign_with_1_m_jumps_matches_the_true_poses() {
    let twin = Twin::new(TwinConfig {
        seed: 11,
        ..TwinConfig::default()
    })
    .expect("twin");
    let p = *twin.true_params();
    let k = Stiffness::default();
    let limits = Limits::default();
    let mut prev: Option<Equilibrium> = None;
    for (n, (x, y)) in jumping_targets().into_iter().enumerate() {
        // q2, q3 followers: the twin's true pose is the rigid model of the true machine.
        let st = twin
            .machine_state("jumps", x, y, 3.0 * n as f64, [0.0; 4], true)
            .expect("twin state");
        assert_eq!(st.follower, FOLLOWERS_23);
        let s = fegm_checked(&p, &k, st.q, st.follower, prev.as_ref(), &limits).expect("solve");
        let d = (s.eq.x - st.tcp.x).hypot(s.eq.y - st.tcp.y);
        assert!(
            d < 1e-3,
            "pose {n} ({x}, {y}): {d} mm from the twin's truth"
        );
        assert!((wrap_angle(s.eq.psi - st.psi)).abs() < 1e-6, "pose {n}: ψ");
        prev = Some(s.eq);
    }
}

#[test]
fn all_active_jumps_stay_on_their_compatible_targets() {
    // Compatible commands (igm of the same parameters, a little preload on q3): the truth is
    // the target itself, to within the preload's deflection (µm).
    let p = Params::nominal();
    let k = Stiffness::default();
    let limits = Limits::default();
    let mut prev: Option<Equilibrium> = None;
    let mut cold = 0;
    for (n, (x, y)) in jumping_targets().into_iter().enumerate() {
        let mut q = igm(&p, Model::M29, x, y).expect("igm").q();
        q[2] += if n % 2 == 0 { 0.05 } else { -0.05 };
        let s = fegm_checked(&p, &k, q, ALL_ACTIVE, prev.as_ref(), &limits).expect("solve");
        cold += usize::from(s.cold);
        let d = (s.eq.x - x).hypot(s.eq.y - y);
        assert!(d < 0.05, "pose {n} ({x}, {y}): {d} mm from the target");
        assert!(s.eq.psi.abs() < 0.01, "pose {n}: ψ {}", s.eq.psi);
        prev = Some(s.eq);
    }
    assert!(cold >= 1, "the first solve is cold");
}
