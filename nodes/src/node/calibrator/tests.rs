//! Unit tests of `calibrator`.

use super::goal::goal_options;
use super::job::split;
use super::node::Calibrator;
use super::*;
use crate::campaign_bag::pose_messages;
use crate::node::geometry::Geometry;
use crate::units::{m_from_mm, mm_from_m};
use rpkm_core::calib::{self, Options};
use rpkm_core::online::TieSoFar;
use rpkm_core::params::{Model, Params};
use rpkm_msgs::calibrate_action::CalibrateGoal;
use rpkm_msgs::{ActuatorState, TcpMeasurement};
use rpkm_twin::{Twin, TwinConfig};

/// The calibrator's start in these tests: the nominal model 29, default stiffness, no
/// effects.
fn nominal_start() -> Geometry {
    Geometry {
        params: Params::nominal(),
        model: Model::M29,
        stiffness: rpkm_core::elastic::Stiffness::default(),
        source: "nominal".into(),
        effects: crate::node::effects::NodeEffects::default(),
    }
}

/// The calibrator with an effects file: the twin's lost motion of carrier 4 (20 µm) is
/// calibrated with the geometry, and the Parameters carry it (SI) within 0.1 µm of the
/// truth (its σ on this campaign is 0.02 µm: core/tests/written_effects.rs).
#[test]
fn parameters_carry_the_written_effects_parameters() -> anyhow::Result<()> {
    use rpkm_core::campaign::Instrument;
    use rpkm_twin::EffectKind;
    let b_true = 0.02;
    let mut twin = Twin::new(TwinConfig {
        seed: 8,
        effects: vec![(EffectKind::LostMotionQ4, b_true)],
        noise: Some(rpkm_core::noise::NoiseModel::default()),
        ..Default::default()
    })?;
    let c = twin.campaign(&[Instrument::Lt, Instrument::Kgm, Instrument::SelfCal])?;
    let file = crate::effects_file::parse(
        "effects:\n  - name: lost_motion_q4\n    summary: carrier 4 lags\n    \
             params: {b: {unit: mm, prior: 0.01}}\n    dq4: \"-b * dir_q4\"\n",
        "lost.yaml",
        &[],
    )?;
    let o = CalibratorOptions {
        start: nominal_start(),
        validation_prefix: "val".into(),
        selection: SelectionRule::Map,
        max_condition: 100.0,
        outlier_sigma: 0.0,
        noise: rpkm_core::noise::NoiseModel::default(),
        effects: Some(std::sync::Arc::new(file)),
        weighting: calib::Noise::ESTIMATE,
    };
    let msg = calibrate_campaign(&c, &o)?.parameters;
    assert_eq!(msg.active_effects, ["lost_motion_q4"]);
    assert_eq!(msg.effect_parameter_names, ["lost_motion_q4.b"]);
    let b = mm_from_m(msg.effect_parameter_values[0]);
    eprintln!("published b = {b} mm (truth {b_true})");
    assert!((b - b_true).abs() < 1e-4, "b = {b} mm");
    Ok(())
}

/// A goal on the campaign collected so far reads it without taking it (a cancelled goal
/// leaves it collected); the goal's settings go over the node's, a bad one is refused
/// with what was expected.
#[test]
fn a_goal_reads_the_collected_campaign_and_sets_its_options() -> anyhow::Result<()> {
    let mut twin = Twin::new(TwinConfig::default())?;
    let c = twin.campaign_by_names(&["lt"], 0)?;
    let mut acc = Accumulator::new(8);
    for (i, pose) in c.poses.iter().enumerate() {
        let (s, m) = pose_messages(&c, i, pose)?;
        acc.state(&s);
        assert!(acc.measurement(&m)?);
    }
    let (seen, _) = acc.peek()?;
    assert_eq!(acc.measurements, c.poses.len() as u64);
    let (taken, _) = acc.take()?;
    assert_eq!(seen.poses, taken.poses);
    assert_eq!(seen.poses.len(), c.poses.len());
    assert_eq!(acc.measurements, 0);

    let node = CalibratorOptions {
        start: nominal_start(),
        validation_prefix: "val".into(),
        selection: SelectionRule::Map,
        max_condition: 100.0,
        outlier_sigma: 0.0,
        noise: rpkm_core::noise::NoiseModel::default(),
        effects: None,
        weighting: calib::Noise::ESTIMATE,
    };
    let goal = |selection: &str, noise| CalibrateGoal {
        selection: selection.into(),
        noise,
        ..CalibrateGoal::default()
    };
    let noise = rpkm_core::noise::NoiseModel::default;
    let o = goal_options(&node, &goal("", CalibrateGoal::NOISE_NODE), noise())?;
    assert_eq!(
        (o.selection, o.weighting),
        (SelectionRule::Map, calib::Noise::ESTIMATE)
    );
    let o = goal_options(&node, &goal("auto", CalibrateGoal::NOISE_STATED), noise())?;
    assert_eq!(
        (o.selection, o.weighting),
        (SelectionRule::Auto, calib::Noise::Stated)
    );
    let bad = goal_options(&node, &goal("all", 0), noise()).map(|_| ());
    let e = bad.expect_err("selection all");
    assert!(e.to_string().contains("expected map, auto"), "{e}");
    assert_eq!(crate::error::exit_code(&e), 2);
    let e = goal_options(&node, &goal("", 7), noise())
        .map(|_| ())
        .expect_err("noise 7");
    assert!(e.to_string().contains("found 7"), "{e}");
    Ok(())
}

#[test]
fn poses_without_a_measurement_are_not_kept() -> anyhow::Result<()> {
    let mut acc = Accumulator::new(8);
    for seq in 1..=1000u64 {
        let s = ActuatorState {
            seq,
            stamp: rpkm_msgs::Time {
                sec: 1,
                nanosec: u32::try_from(seq).expect("seq <= 1000"),
            },
            ..Default::default()
        };
        acc.state(&s);
        let m = TcpMeasurement {
            stamp: s.stamp,
            setup: "stream".into(),
            instrument: TcpMeasurement::NONE,
            ..Default::default()
        };
        assert!(acc.measurement(&m)?);
    }
    assert_eq!((acc.measurements, acc.unmeasured), (0, 1000));
    Ok(())
}

#[test]
fn messages_rebuild_the_campaign_and_calibrate_like_the_core() -> anyhow::Result<()> {
    // a noisy twin: the diagnosis estimates its noise and tries every effect
    let mut twin = Twin::new(TwinConfig::default())?;
    let c = twin.campaign_by_names(&["lt", "validation"], 20)?;
    let mut acc = Accumulator::new(8);
    for (i, pose) in c.poses.iter().enumerate() {
        let (s, m) = pose_messages(&c, i, pose)?;
        acc.state(&s);
        assert!(acc.measurement(&m)?);
    }
    let (rebuilt, stated) = acc.take()?;
    // The messages carry the spec's σ of each instrument: read back, it is the default.
    assert_eq!(stated, rpkm_core::noise::NoiseModel::default());
    let o = CalibratorOptions {
        start: nominal_start(),
        validation_prefix: "val".into(),
        selection: SelectionRule::Map,
        max_condition: 100.0,
        outlier_sigma: 0.0,
        noise: stated,
        effects: None,
        weighting: calib::Noise::ESTIMATE,
    };
    let out = calibrate_campaign(&rebuilt, &o)?;
    // Independent truth: the core on the original campaign without its held-out setup.
    let (cal_part, _) = split(&c, "val");
    let opts = Options {
        outlier_sigma: None,
        ..Options::default()
    };
    let nominal = Params::nominal();
    let (direct, _) = calib::calibrate(&calib::Request {
        noise: calib::Noise::ESTIMATE,
        ..calib::Request::new(&cal_part, &nominal, &opts)
    })?;
    for (name, v) in out.parameters.names.iter().zip(&out.parameters.values) {
        let i = rpkm_core::params::index_of(name)
            .ok_or("name")
            .map_err(anyhow::Error::msg)?;
        let expect = if rpkm_core::params::unit(i) == rpkm_core::params::Unit::Mm {
            m_from_mm(direct.params[i])
        } else {
            direct.params[i]
        };
        assert!((v - expect).abs() < 1e-9, "{name}: {v} vs {expect}");
    }
    assert_eq!(out.parameters.model, 29);
    // The measurements of the calibration part (the held-out setup excluded), not the
    // fit's rows (x and y of a tracker pose are two).
    assert_eq!(
        out.parameters.measurement_count as usize,
        cal_part.poses.len()
    );
    assert!(direct.rows > cal_part.poses.len(), "rows {}", direct.rows);
    assert!(out.parameters.val_rms.is_finite());
    // the tracker's noise (5 µm along the beam, 25-30 µm across) sets the held-out RMS
    assert!(
        out.parameters.val_rms < 40e-6,
        "held-out {} m",
        out.parameters.val_rms
    );
    let d = out
        .diagnosis
        .ok_or_else(|| anyhow::anyhow!("not diagnosed"))?
        .map_err(anyhow::Error::msg)?;
    assert_eq!(d.missing_effect, "", "an effect-free twin misses no effect");
    assert!(!d.candidates.is_empty());
    Ok(())
}

/// While a tie is open the periodic /diagnostics values say which two and how far the
/// evidence has come; once settled they say nothing of it.
#[test]
fn an_open_tie_is_on_the_periodic_status() {
    use rpkm_core::calib::tie::TieEvidence;
    use rpkm_core::params::{L1, L3};
    let mut c = Calibrator::new(16, None, None);
    let has = |c: &Calibrator, k: &str| {
        c.report_values()
            .into_iter()
            .find(|v| v.0 == k)
            .map(|v| v.1)
    };
    assert_eq!(has(&c, "online_tie"), None);
    c.tie = Some(TieSoFar {
        named: L3,
        runner_up: L1,
        evidence: TieEvidence {
            chi2: 12.84,
            ..TieEvidence::default()
        },
    });
    assert_eq!(has(&c, "online_tie").as_deref(), Some("l3 or l1"));
    assert_eq!(
        has(&c, "online_tie_evidence_chi2").as_deref(),
        Some("12.8 of 27.6")
    );
}

/// A validation campaign of the job's own (a goal's `validation_file`) is counted held out,
/// as the campaign's own held-out setups are: the sentence adds up.
#[test]
fn a_validation_file_is_counted_held_out() -> anyhow::Result<()> {
    use rpkm_core::campaign::Instrument;
    let mut twin = Twin::new(TwinConfig {
        seed: 5,
        noise: Some(rpkm_core::noise::NoiseModel::default()),
        ..Default::default()
    })?;
    let c = twin.campaign(&[Instrument::Lt])?;
    let mut cal = c.clone();
    let val = rpkm_core::campaign::Campaign {
        poses: cal.poses.split_off(cal.poses.len() - 7),
        ..c.clone()
    };
    let o = CalibratorOptions {
        start: nominal_start(),
        validation_prefix: "val".into(),
        selection: SelectionRule::Map,
        max_condition: 100.0,
        outlier_sigma: 0.0,
        noise: rpkm_core::noise::NoiseModel::default(),
        effects: None,
        weighting: calib::Noise::ESTIMATE,
    };
    let job = super::job::Job {
        validation: Some(&val),
        ..super::job::Job::of(&cal)
    };
    let out = super::job::calibrate_job(&job, &o)?;
    let n = cal.poses.len();
    assert_eq!(out.held_out, 7);
    assert_eq!(
        out.measurements_text(),
        format!("{} measurements ({n} calibrated, 7 held out)", n + 7)
    );
    Ok(())
}
