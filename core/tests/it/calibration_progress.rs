//! The calibration's progress observer (`calib::Request::progress`): called once per LM
//! iteration the calibration counts and once per noise round, with the estimate the
//! calibration returns at the last; a `Flow::Stop` ends the calibration as
//! `CalibrationError::Cancelled`, and the observer hears nothing after it.
//!
//! The campaign: a twin measured with the double ball bar (a forward instrument: the fit has
//! a step 2, rod 2 from virtual rows), noisier than the stated levels so that the noise is
//! estimated in more than one round (2 rounds, 6 and 4 iterations).

use std::cell::RefCell;

use rpkm_core::calib::{self, CalibrationError, Flow, Options, Progress};
use rpkm_core::campaign::{Campaign, Instrument};
use rpkm_core::noise::NoiseModel;
use rpkm_core::obs::Step;
use rpkm_core::params::Params;
use rpkm_core::variance::NoiseEstimate;
use rpkm_twin::{Twin, TwinConfig};

/// What the observer heard, in order.
#[derive(Debug, Clone, PartialEq)]
enum Heard {
    Iteration {
        step: Step,
        iteration: usize,
        cost: f64,
    },
    Round(usize),
}

fn campaign() -> Campaign {
    let noise = NoiseModel {
        lt_along_mm: 8e-3,
        encoder_mm: 0.4e-3,
        ..NoiseModel::default()
    };
    let mut twin = Twin::new(TwinConfig {
        seed: 29,
        noise: Some(noise),
        ..Default::default()
    })
    .expect("twin");
    twin.campaign(&[Instrument::Dbb]).expect("campaign")
}

/// The events of each round: (its iterations, in order; the round number that ended it).
fn rounds(heard: &[Heard]) -> Vec<(Vec<Heard>, usize)> {
    let mut out = Vec::new();
    let mut current = Vec::new();
    for h in heard {
        match h {
            Heard::Round(r) => out.push((std::mem::take(&mut current), *r)),
            it @ Heard::Iteration { .. } => current.push(it.clone()),
        }
    }
    assert!(
        current.is_empty(),
        "iterations after the last round: {current:?}"
    );
    out
}

/// Calibrates `c` as the tests do, with `observer`.
fn calibrate(
    c: &Campaign,
    observer: &dyn Fn(&Progress) -> Flow,
) -> Result<(calib::Calibration, NoiseEstimate), CalibrationError> {
    let start = Params::nominal();
    let opts = Options::default();
    calib::calibrate(&calib::Request {
        noise: calib::Noise::ESTIMATE,
        progress: Some(observer),
        ..calib::Request::new(c, &start, &opts)
    })
}

/// The calibration of `c` and what an observer heard, round by round.
fn heard(c: &Campaign) -> (calib::Calibration, NoiseEstimate, Vec<(Vec<Heard>, usize)>) {
    let heard = RefCell::new(Vec::new());
    let observe = |p: &Progress| {
        heard.borrow_mut().push(match *p {
            Progress::Iteration {
                step,
                iteration,
                cost,
            } => Heard::Iteration {
                step,
                iteration,
                cost,
            },
            Progress::NoiseRound { round, .. } => Heard::Round(round),
        });
        Flow::Continue
    };
    let (cal, noise) = calibrate(c, &observe).expect("calibrates");
    let rounds = rounds(&heard.into_inner());
    (cal, noise, rounds)
}

#[test]
fn the_observer_hears_every_iteration_and_noise_round() {
    let (cal, noise, rounds) = heard(&campaign());
    eprintln!(
        "{} rounds, iterations per round {:?}, the last {}",
        noise.rounds,
        rounds.iter().map(|r| r.0.len()).collect::<Vec<_>>(),
        cal.iterations
    );
    assert!(noise.rounds > 1, "{} noise rounds", noise.rounds);
    // a round each, numbered from 1
    let numbers: Vec<usize> = rounds.iter().map(|r| r.1).collect();
    assert_eq!(numbers, (1..=noise.rounds).collect::<Vec<_>>());
    // the last round's fit is the calibration: its iterations are the ones it counts
    let (last, _) = rounds.last().expect("a round");
    assert_eq!(last.len(), cal.iterations);
    for (its, round) in &rounds {
        assert!(!its.is_empty(), "round {round} without an iteration");
        check_runs(its);
        // rod 2's step follows the direct one's in every round (the ball bar is forward)
        let steps: Vec<Step> = its
            .iter()
            .filter_map(|h| match h {
                Heard::Iteration { step, .. } => Some(*step),
                Heard::Round(_) => None,
            })
            .collect();
        assert_eq!(steps[0], Step::Direct);
        assert!(steps.contains(&Step::VirtualQ2), "round {round}: {steps:?}");
    }
}

#[test]
fn the_last_rounds_estimate_is_the_one_returned() {
    let c = campaign();
    let (_, noise, _) = heard(&c);
    let estimate = RefCell::new(None);
    let keep = |p: &Progress| {
        if let Progress::NoiseRound { estimate: e, .. } = p {
            *estimate.borrow_mut() = Some((*e).clone());
        }
        Flow::Continue
    };
    let (_, again) = calibrate(&c, &keep).expect("calibrates");
    assert_eq!(estimate.into_inner(), Some(again.clone()));
    assert_eq!(again, noise, "an observer changes nothing");
}

/// Stopped at the second iteration of the second round (its direct fit's or rod 2's): the
/// calibration is cancelled and the observer hears nothing after.
#[test]
fn a_stop_cancels_the_calibration() {
    let c = campaign();
    let (_, _, rounds) = heard(&c);
    // (calls, rounds ended, iterations of round 2)
    let calls = RefCell::new((0usize, 0usize, 0usize));
    let stop = |p: &Progress| {
        let mut c = calls.borrow_mut();
        c.0 += 1;
        match p {
            Progress::NoiseRound { .. } => {
                c.1 += 1;
                Flow::Continue
            }
            Progress::Iteration { .. } if c.1 == 1 => {
                c.2 += 1;
                if c.2 == 2 {
                    Flow::Stop
                } else {
                    Flow::Continue
                }
            }
            Progress::Iteration { .. } => Flow::Continue,
        }
    };
    let stopped = calibrate(&c, &stop);
    assert!(
        matches!(stopped, Err(CalibrationError::Cancelled)),
        "{stopped:?}"
    );
    let first_round = rounds[0].0.len();
    assert_eq!(calls.into_inner(), (first_round + 1 + 2, 1, 2));
}

/// A stop asked through the options (`calib::Options::stop`, what a diagnosis's fits on
/// other threads share) ends the calibration at its next iteration: asked during the 2nd
/// iteration of round 2, the observer hears that iteration and nothing after it.
#[test]
fn a_stop_asked_through_the_options_cancels_at_the_next_iteration() {
    let c = campaign();
    let (_, _, rounds) = heard(&c);
    let stop = calib::Stop::default();
    let calls = RefCell::new((0usize, 0usize, 0usize));
    let observe = |p: &Progress| {
        let mut c = calls.borrow_mut();
        c.0 += 1;
        match p {
            Progress::NoiseRound { .. } => c.1 += 1,
            Progress::Iteration { .. } if c.1 == 1 => {
                c.2 += 1;
                if c.2 == 2 {
                    stop.request();
                }
            }
            Progress::Iteration { .. } => {}
        }
        Flow::Continue
    };
    let start = Params::nominal();
    let opts = Options {
        stop: Some(stop.clone()),
        ..Options::default()
    };
    let stopped = calib::calibrate(&calib::Request {
        noise: calib::Noise::ESTIMATE,
        progress: Some(&observe),
        ..calib::Request::new(&c, &start, &opts)
    });
    assert!(
        matches!(stopped, Err(CalibrationError::Cancelled)),
        "{stopped:?}"
    );
    assert_eq!(calls.into_inner(), (rounds[0].0.len() + 1 + 2, 1, 2));
}

/// A diagnosis asked to stop concludes nothing: `DiagnoseError::Cancelled`, not a verdict
/// from fits that stopped part-way.
#[test]
fn a_stopped_diagnosis_is_cancelled() {
    use rpkm_core::diagnose::{self, DiagnoseError};
    let c = campaign();
    let stop = calib::Stop::default();
    stop.request();
    let opts = diagnose::DiagnosisOptions {
        stop: Some(stop),
        ..diagnose::DiagnosisOptions::default()
    };
    let d = diagnose::diagnose(&c, None, &[], &opts);
    assert!(matches!(d, Err(DiagnoseError::Cancelled)), "{d:?}");
    // and the same diagnosis without the stop concludes
    assert!(diagnose::diagnose(&c, None, &[], &diagnose::DiagnosisOptions::default()).is_ok());
}

/// Within one LM run the iterations count 1, 2, ... and the cost at each start never rises
/// (the LM accepts only steps that lower it).
fn check_runs(its: &[Heard]) {
    let mut previous: Option<(usize, f64)> = None;
    for h in its {
        let Heard::Iteration {
            iteration, cost, ..
        } = *h
        else {
            continue;
        };
        assert!(cost.is_finite() && cost > 0.0, "cost {cost}");
        match previous {
            Some((i, c)) if iteration == i + 1 => {
                assert!(cost <= c, "iteration {iteration}: cost {cost} after {c}");
            }
            _ => assert_eq!(iteration, 1, "a run starts at 1: {its:?}"),
        }
        previous = Some((iteration, cost));
    }
}
