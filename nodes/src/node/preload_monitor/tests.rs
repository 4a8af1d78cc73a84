//! The preload monitor's tests: levels, debounce, followers' Δq, forces not measured.

use super::*;
use crate::units::m_from_mm;
use rpkm_core::elastic::{fegm, Stiffness, ALL_ACTIVE};
use rpkm_core::geometry::igm;
use rpkm_core::params::{Model, Params};

fn monitor(debounce: u32) -> Monitor {
    Monitor::new(
        Geometry {
            params: Params::nominal(),
            model: Model::M29,
            stiffness: Stiffness::default(),
            source: "test".into(),
            effects: crate::node::effects::NodeEffects::default(),
        },
        Thresholds {
            debounce_samples: debounce,
            ..Thresholds::default()
        },
    )
}

/// A state at (0, 1700) mm whose drive forces are those of q3 offset by `dq3` mm.
fn state(dq3: f64) -> Result<ActuatorState, Box<dyn std::error::Error>> {
    let p = Params::nominal();
    let q = igm(&p, Model::M29, 0.0, 1700.0)?.q();
    let mut s = q;
    s[2] += dq3;
    let eq = fegm(&p, &Stiffness::default(), s, ALL_ACTIVE)?;
    Ok(ActuatorState {
        position: q.map(m_from_mm),
        force: eq.drive_force,
        ..Default::default()
    })
}

#[test]
fn levels_follow_the_deviation_with_debounce() -> Result<(), Box<dyn std::error::Error>> {
    let mut m = monitor(2);
    let ok = m.evaluate(&state(0.0)?).ok_or("unsolved")?;
    assert_eq!(ok.sample_level, PreloadLevel::Ok);
    assert!(ok.status.deviation.iter().all(|d| d.abs() < 1e-6));
    // every drive holds: no follower compatibility measured
    assert!(ok.status.dq2.is_nan() && ok.status.dq3.is_nan());
    // 0.4 mm on q3 is about 100 % on the most loaded drive (core default stiffness).
    let big = state(0.4)?;
    let first = m.evaluate(&big).ok_or("unsolved")?;
    assert_eq!(first.sample_level, PreloadLevel::Error);
    assert_eq!(first.status.level, PreloadStatus::OK, "held for debounce");
    let second = m.evaluate(&big).ok_or("unsolved")?;
    assert!(second.changed);
    assert_eq!(second.status.level, PreloadStatus::ERROR);
    let f = big.force;
    let worst = (0..4)
        .max_by(|&a, &b| f[a].abs().total_cmp(&f[b].abs()))
        .ok_or("no drive")?;
    assert_eq!(second.worst_drive, worst);
    assert!(m.status("m").message.contains(&format!("q{}", worst + 1)));
    Ok(())
}

#[test]
fn follower_mode_reports_the_compatibility_offsets() -> Result<(), Box<dyn std::error::Error>> {
    let p = Params::nominal();
    let q = igm(&p, Model::M29, 0.0, 1700.0)?.q();
    let mut m = monitor(1);
    let s = ActuatorState {
        position: [q[0], q[1] + 0.1, q[2] - 0.3, q[3]].map(m_from_mm),
        follower: [false, true, true, false],
        ..Default::default()
    };
    let e = m.evaluate(&s).ok_or("unsolved")?;
    assert!((e.status.dq2 + 0.1e-3).abs() < 1e-9, "{}", e.status.dq2);
    assert!((e.status.dq3 - 0.3e-3).abs() < 1e-9, "{}", e.status.dq3);
    assert_eq!(e.sample_level, PreloadLevel::Error, "0.3 mm > 200 µm");
    Ok(())
}

#[test]
fn an_implausible_prediction_is_skipped_not_compared() -> Result<(), Box<dyn std::error::Error>> {
    // q3 50 mm off: the elastic model's only answer needs 100x the drives' force. The
    // measured currents are small; comparing with that answer would raise ERROR.
    let mut m = monitor(1);
    let mut s = state(0.0)?;
    s.position[2] += 0.05;
    assert!(m.evaluate(&s).is_none());
    assert_eq!((m.implausible, m.samples), (1, 0));
    assert_eq!(m.level(), PreloadLevel::Ok);
    assert!(m.status("m").message.contains("1 implausible"));
    // and a plausible state afterwards is evaluated as usual
    let ok = m.evaluate(&state(0.0)?).ok_or("unsolved")?;
    assert_eq!(ok.sample_level, PreloadLevel::Ok);
    Ok(())
}

/// A calibrated lost motion of carrier 4 (`dq4 = -b * dir_q4`, b = 0.05 mm, from a
/// Parameters message in SI): the monitor predicts the forces of carrier 4 standing b
/// behind its encoder (the core's elastic model at the shifted carrier), where the
/// geometry alone predicts none.
#[test]
fn predicted_forces_include_a_calibrated_effect() -> Result<(), Box<dyn std::error::Error>> {
    let file = crate::effects_file::parse(
        "effects:\n  - name: lost_motion_q4\n    summary: s\n    \
         params: {b: {unit: mm, prior: 0.01}}\n    dq4: \"-b * dir_q4\"\n",
        "lost.yaml",
        &[],
    )?;
    let mut m = monitor(1);
    let mut g = m.geometry().clone();
    g.effects = crate::node::effects::NodeEffects::known(Some(file));
    let msg = rpkm_msgs::Parameters {
        model: 29,
        active_effects: vec!["lost_motion_q4".into()],
        effect_parameter_names: vec!["lost_motion_q4.b".into()],
        effect_parameter_values: vec![0.05e-3],
        ..Default::default()
    };
    m.set_geometry(g.updated(&msg)?);
    let p = Params::nominal();
    let q = igm(&p, Model::M29, 0.0, 1700.0)?.q();
    let s = ActuatorState {
        position: q.map(m_from_mm),
        ..Default::default()
    };
    // the first state of the stream: carrier 4's last move counts as +1
    let e = m.evaluate(&s).ok_or("unsolved")?;
    let mut shifted = q;
    shifted[3] -= 0.05;
    let truth = fegm(&p, &Stiffness::default(), shifted, ALL_ACTIVE)?;
    for i in 0..4 {
        let want = truth.drive_force[i] / NOMINAL_DRIVE_FORCE_N * 100.0;
        assert!(
            (e.status.predicted_current[i] - want).abs() < 1e-6,
            "drive {}: {} %, the core's {want} %",
            i + 1,
            e.status.predicted_current[i]
        );
    }
    let largest = truth.drive_force.iter().fold(0.0f64, |a, f| a.max(f.abs()));
    assert!(largest > 100.0, "0.05 mm preloads the drives: {largest} N");
    Ok(())
}

/// A cell without force sensing: at 0.4 mm of preload on q3 (ERROR when measured) the
/// currents are not measured, the prediction is the same, no level is raised and the status
/// says why; a calibrated effect that reads a force skips the state, naming itself.
#[test]
fn forces_not_measured_raise_nothing_and_say_why() -> Result<(), Box<dyn std::error::Error>> {
    let measured = monitor(1).evaluate(&state(0.4)?).ok_or("unsolved")?;
    assert_eq!(measured.sample_level, PreloadLevel::Error);
    let mut m = monitor(1);
    let mut s = state(0.4)?;
    s.force = [f64::NAN; 4];
    let e = m.evaluate(&s).ok_or("unsolved")?;
    assert_eq!(e.sample_level, PreloadLevel::Ok);
    assert_eq!(e.status.level, PreloadStatus::OK);
    assert!(e.status.measured_current.iter().all(|c| c.is_nan()));
    assert!(e.status.deviation.iter().all(|d| d.is_nan()));
    // the same prediction, bit for bit
    assert_eq!(
        e.status.predicted_current.map(f64::to_bits),
        measured.status.predicted_current.map(f64::to_bits)
    );
    assert_eq!(m.forces_not_measured, 1);
    let st = m.status("m");
    assert_eq!(st.level, DiagnosticStatus::OK);
    assert!(
        st.message.starts_with(
            "OK: drive forces of q1, q2, q3, q4 not measured (a cell without force sensing)"
        ),
        "{}",
        st.message
    );
    let file = crate::effects_file::parse(
        "effects:\n  - name: drive_compliance_q1\n    summary: s\n    \
         params: {c: {unit: mm, prior: 0.01}}\n    dq1: \"c * f1 / 1000\"\n",
        "compliance.yaml",
        &[],
    )?;
    let mut g = m.geometry().clone();
    g.effects = crate::node::effects::NodeEffects::known(Some(file));
    let msg = rpkm_msgs::Parameters {
        model: 29,
        active_effects: vec!["drive_compliance_q1".into()],
        effect_parameter_names: vec!["drive_compliance_q1.c".into()],
        effect_parameter_values: vec![0.01e-3],
        ..Default::default()
    };
    m.set_geometry(g.updated(&msg)?);
    assert!(m.evaluate(&s).is_none(), "no force for the effect");
    assert_eq!(m.skipped_unmeasured.0, 1);
    let st = m.status("m");
    assert!(
        st.message.contains(
            "1 states skipped: effect `drive_compliance_q1` reads f1, which the drive state \
             does not measure (NaN)"
        ),
        "{}",
        st.message
    );
    Ok(())
}
