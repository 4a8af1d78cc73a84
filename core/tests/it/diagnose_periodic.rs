//! The period pointer on the twin (issue 41, item 1), by hand: `cargo test --release -p
//! rpkm-core --test it diagnose_periodic -- --ignored --nocapture` (two to five minutes).
//! A pitch error of carrier 1 or 2 under every campaign with self-calibration lines, over
//! pitches, amplitudes, phases and seeds, alone and beside a lost motion of carrier 4 that
//! the model holds: wherever the reported period is significant, the truth is the carrier
//! named or one tied with it, never another carrier alone. The truth is the twin's
//! configuration. The quick cases are `tests/it/first_use_period.rs`.

use rpkm_core::campaign::Instrument;
use rpkm_core::diagnose::{self, DiagnosisOptions};
use rpkm_core::effects::written::{Spec, WrittenParam};
use rpkm_core::effects::{Effect, Written};
use rpkm_twin::{CyclicScale, EffectKind, Twin, TwinConfig};

/// `dq4 = -b * dir_q4`, as an effects file writes it.
fn lost_motion() -> Written {
    let spec = Spec {
        name: "lost_motion_q4".into(),
        summary: "carrier 4 lags against its last direction".into(),
        params: vec![WrittenParam {
            name: "b".into(),
            unit: "mm".into(),
            prior: 0.02,
            bounds: None,
            start: 0.0,
        }],
        targets: vec![("dq4".to_owned(), "-b * dir_q4".to_owned())],
        instruments: None,
    };
    Written::new(spec, &[]).expect("a valid effect")
}

/// One machine: the carriers the pointer names (best first) when the period is significant,
/// and a line saying what it found.
fn pointer(
    cyclic: CyclicScale,
    seed: u64,
    lost: bool,
    instruments: &[Instrument],
) -> (Vec<usize>, String) {
    let mut twin = Twin::new(TwinConfig {
        seed,
        cyclic: Some(cyclic),
        effects: if lost {
            vec![(EffectKind::LostMotionQ4, 0.01)]
        } else {
            Vec::new()
        },
        ..Default::default()
    })
    .expect("twin");
    let cal = twin.campaign(instruments).expect("campaign");
    let val = twin.validation(60).expect("held-out poses");
    let lm = lost_motion();
    let with: Vec<&dyn Effect> = if lost { vec![&lm] } else { Vec::new() };
    let d = diagnose::diagnose(&cal, Some(&val), &with, &DiagnosisOptions::default())
        .expect("diagnose");
    let Some(p) = d.periodic.filter(|p| p.p_value < d.test.dictionary_level) else {
        return (Vec::new(), "no significant period".to_owned());
    };
    let named: Vec<usize> = std::iter::once(p.carrier)
        .chain(p.tied.iter().map(|t| t.carrier))
        .collect();
    let line = format!(
        "{} {} {:.1} mm of carriers {named:?} ({:.0} %)",
        p.instrument,
        p.direction,
        p.pitch_mm,
        100.0 * p.explained
    );
    (named, line)
}

#[test]
#[ignore = "minutes in release: run by hand"]
fn a_pitch_error_is_never_another_carriers_alone() {
    use Instrument::{Dbb, Kgm, Lt, SelfCal};
    let campaigns: [&[Instrument]; 4] = [
        &[Lt, Kgm, Dbb, SelfCal],
        &[SelfCal],
        &[Lt, SelfCal],
        &[Kgm, SelfCal],
    ];
    let (mut runs, mut tied, mut wrong) = (0, 0, Vec::new());
    for instruments in campaigns {
        for seed in 1..=6u64 {
            for pitch_mm in [12.0, 23.0, 50.0, 90.0, 160.0] {
                for carrier in 0..2 {
                    for lost in [false, true] {
                        let cyclic = CyclicScale {
                            carrier,
                            amplitude_mm: 1e-3 * (1.0 + (seed % 4) as f64),
                            pitch_mm,
                            phase: 1.3 * seed as f64,
                        };
                        let (named, line) = pointer(cyclic, seed, lost, instruments);
                        runs += 1;
                        tied += usize::from(named.len() > 1);
                        let what = format!("carrier {} {pitch_mm} mm, seed {seed}, lost motion {lost}, {instruments:?}: {line}", carrier + 1);
                        eprintln!("{what}");
                        if !named.is_empty() && !named.contains(&(carrier + 1)) {
                            wrong.push(what);
                        }
                    }
                }
            }
        }
    }
    eprintln!(
        "{runs} machines, {tied} named with a tie, {} wrong",
        wrong.len()
    );
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}
