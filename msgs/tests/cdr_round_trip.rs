//! CDR round trip of every message type, and the bytes of one ActuatorState checked by hand
//! against the CDR rules (XCDR1: encapsulation header `00 01 00 00`, primitives aligned to
//! their size relative to the start of the body, sequences and strings prefixed by a uint32
//! length, strings NUL-terminated).

use rpkm_msgs::*;

fn round_trip<T: RosMessage + PartialEq + std::fmt::Debug>(msg: &T) {
    let bytes = to_cdr(msg).expect("encode");
    assert_eq!(bytes[..4], CDR_LE_HEADER, "{}", T::type_name());
    let back: T = from_cdr(&bytes).expect("decode");
    assert_eq!(&back, msg, "{}", T::type_name());
}

fn stamp() -> Time {
    Time {
        sec: 1_763_700_000,
        nanosec: 123_456_789,
    }
}

fn actuator_state() -> ActuatorState {
    let mut m = ActuatorState {
        stamp: stamp(),
        seq: 0x0102_0304_0506_0708,
        position: [2.611_055_6, 2.611_055_6, 0.788_944_4, 0.788_944_4],
        force: [120.5, -80.25, 0.0, 3.0],
        follower: [false, true, true, false],
        ..Default::default()
    };
    m.set_covariates(&[21.5, 22.25, -1.0])
        .expect("3 covariates fit");
    m
}

#[test]
#[expect(
    clippy::too_many_lines,
    reason = "an end-to-end scenario, read top to bottom"
)]
fn every_type_round_trips() {
    round_trip(&stamp());
    round_trip(&actuator_state());
    round_trip(&TcpEstimate {
        stamp: stamp(),
        seq: 42,
        x: 0.01,
        y: 1.7,
        psi: -1e-5,
        loop_residuals: [1e-9, -2e-9, 3e-9, 0.0, 5e-9],
        rod_forces: [1.0, 2.0, 3.0, 4.0, 5.0],
        drive_forces: [-1.0, -2.0, -3.0, -4.0],
        iterations: 3,
        model: TcpEstimate::MODEL_29,
        converged: true,
        outcome: TcpEstimate::OUTCOME_WARM_REJECTED_COLD_OK,
        reason: TcpEstimate::REASON_PLATFORM_ANGLE,
    });
    round_trip(&TcpMeasurement {
        stamp: stamp(),
        setup: "kgm_y1700_x-70".into(),
        instrument: TcpMeasurement::KGM,
        reset: false,
        x: 0.07,
        x_valid: true,
        y: -0.07,
        y_valid: true,
        r: 0.0,
        r_valid: false,
        psi: 0.0,
        psi_valid: false,
        sigma: 1e-6,
    });
    round_trip(&CampaignInfo {
        source: "bags/demo/campaign.csv".into(),
        comments: vec!["rpkm digital twin: seed 7".into(), String::new()],
        covariate_names: vec!["temp_machine".into(), "temp_guide1".into()],
    });
    round_trip(&Parameters {
        model: 24,
        names: vec!["l1".into(), "gamma1".into()],
        values: vec![0.95, 0.0],
        sigmas: vec![1e-6, 1e-7],
        active_effects: vec!["thermal".into()],
        effect_parameter_names: vec!["alpha".into()],
        effect_parameter_values: vec![1.2e-5],
        measurement_count: 45,
        cal_rms: 5e-6,
        val_rms: 7e-6,
        max_abs_residual: 2e-5,
        condition_number: 1234.5,
    });
    round_trip(&Diagnosis {
        missing_effect: "thermal_guide1".into(),
        candidates: vec![
            DiagnosisCandidate {
                effect: "thermal_guide1".into(),
                significant: true,
                explained_fraction: 0.8,
                val_rms_before: 2e-5,
                val_rms_after: 6e-6,
            },
            DiagnosisCandidate::default(),
        ],
        baseline_cal_rms: 1e-5,
        baseline_val_rms: 2e-5,
        noise_floor: 1e-6,
        verdict_kind: "missing_effect".into(),
        verdict: "missing effect: thermal".into(),
        missing_effects: vec!["thermal:rods".into(), "preload_elastic".into()],
        model_effects: vec!["lost_motion_q4".into()],
        baseline_val_rms_relative: 1.5e-5,
        floor_relative: 5e-6,
        held_out_agrees: false,
    });
    round_trip(&PreloadStatus {
        stamp: stamp(),
        measured_current: [10.0, 20.0, 30.0, 40.0],
        predicted_current: [11.0, 19.0, 31.0, 39.0],
        deviation: [-1.0, 1.0, -1.0, 1.0],
        dq2: 0.414e-3,
        dq3: 0.641e-3,
        level: PreloadStatus::WARN,
    });
    round_trip(&Header {
        stamp: stamp(),
        frame_id: "base".into(),
    });
    round_trip(&DiagnosticArray {
        header: Header {
            stamp: stamp(),
            frame_id: String::new(),
        },
        status: vec![DiagnosticStatus {
            level: DiagnosticStatus::WARN,
            name: "rpkm/preload".into(),
            message: "current high".into(),
            hardware_id: "drive2".into(),
            values: vec![KeyValue {
                key: "current".into(),
                value: "81 %".into(),
            }],
        }],
    });
}

/// Little-endian bytes of an f64.
fn f(v: f64) -> [u8; 8] {
    v.to_le_bytes()
}

#[test]
fn actuator_state_bytes_follow_the_cdr_rules() {
    let m = actuator_state();
    let bytes = to_cdr(&m).expect("encode");
    let mut expected: Vec<u8> = vec![0x00, 0x01, 0x00, 0x00]; // CDR_LE, options 0
                                                              // stamp: int32 sec, uint32 nanosec at body offsets 0 and 4.
    expected.extend_from_slice(&1_763_700_000i32.to_le_bytes());
    expected.extend_from_slice(&123_456_789u32.to_le_bytes());
    // uint64 seq at offset 8 (already 8-aligned).
    expected.extend_from_slice(&[0x08, 0x07, 0x06, 0x05, 0x04, 0x03, 0x02, 0x01]);
    // float64[4] position at 16, float64[4] force at 48: fixed arrays have no length prefix.
    for v in m.position.iter().chain(m.force.iter()) {
        expected.extend_from_slice(&f(*v));
    }
    // bool[4] follower at 80, one byte each.
    expected.extend_from_slice(&[0, 1, 1, 0]);
    // uint8 covariate_count at 84.
    expected.push(3);
    // float64[8] covariates: aligned to 8 -> 3 padding bytes, starts at 88.
    expected.extend_from_slice(&[0, 0, 0]);
    for v in [21.5, 22.25, -1.0, 0.0, 0.0, 0.0, 0.0, 0.0] {
        expected.extend_from_slice(&f(v));
    }
    assert_eq!(expected.len(), 4 + 152);
    assert_eq!(bytes, expected);
}

#[test]
fn strings_and_sequences_carry_lengths() {
    let m = DiagnosisCandidate {
        effect: "ab".into(),
        significant: true,
        explained_fraction: 0.5,
        val_rms_before: 0.0,
        val_rms_after: 0.0,
    };
    let bytes = to_cdr(&m).expect("encode");
    // uint32 length 3 (with NUL), "ab\0", bool at body 7; the float64 is at body 8, aligned.
    assert_eq!(&bytes[4..12], &[3, 0, 0, 0, b'a', b'b', 0, 1]);
    assert_eq!(&bytes[12..20], &f(0.5));
    assert_eq!(bytes.len(), 4 + 8 + 3 * 8);
}

#[test]
fn bad_input_is_an_error_not_a_panic() {
    assert!(matches!(
        from_cdr::<ActuatorState>(&[0, 1]),
        Err(CdrError::Truncated { len: 2 })
    ));
    assert!(matches!(
        from_cdr::<ActuatorState>(&[0, 9, 0, 0, 1, 2]),
        Err(CdrError::Encapsulation { found: [0, 9] })
    ));
    let bytes = to_cdr(&actuator_state()).expect("encode");
    assert!(matches!(
        from_cdr::<ActuatorState>(&bytes[..100]),
        Err(CdrError::Body { .. })
    ));
    // A string length beyond the buffer.
    let mut bad = CDR_LE_HEADER.to_vec();
    bad.extend_from_slice(&u32::MAX.to_le_bytes());
    assert!(from_cdr::<Diagnosis>(&bad).is_err());
    assert!(actuator_state().covariates().len() == 3);
    let odd = ActuatorState {
        covariate_count: 200,
        ..Default::default()
    };
    assert_eq!(odd.covariates().len(), 8);
}
