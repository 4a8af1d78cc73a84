//! The calibrator's online tracker (issue 15) as the node runs it: `rpkm_core::online`
//! on a worker thread fed every `online_decimation`-th drive state, its reports (Parameters
//! when a parameter moved, a step, a tie settled, a drift), and their words on /diagnostics:
//! the WARN line, and the values of a tie (the motion that separates it, how it was
//! settled) in SI.

use std::fmt::Write as _;

use nalgebra::SMatrix;
use rpkm_core::online::{
    DetectedStep, Drift, DriftMonitor, ForceSample, OnlineEstimator, OnlineOptions, TieResolved,
    TieSoFar, UpdateOutcome as OnlineOutcome, TIE_EVIDENCE_CHI2,
};
use rpkm_core::params::{Params, N_PARAMS};
use rpkm_msgs::ActuatorState;

use crate::units::{drive_positions_mm, m_from_mm, um_from_mm};

/// Settings of the online tracker.
#[derive(Debug, Clone, Copy)]
pub struct OnlineSettings {
    /// Covariance of the start geometry (mm, rad): a calibration's, where the geometry file
    /// carries it (`covariance`, else the σ of `identified`, as `rpkm calibrate --json`
    /// writes), else the tolerance prior (see [`start_covariance`]).
    pub start_cov: SMatrix<f64, N_PARAMS, N_PARAMS>,
    pub decimation: u64,
    pub publish_sigma: f64,
    pub drift_warn_mm: f64,
    pub options: OnlineOptions,
}

/// What the tracker reports back to the node's loop.
#[derive(Debug, Clone)]
pub struct OnlineReport {
    pub params: Params,
    pub sigma: [f64; N_PARAMS],
    /// Stream time, s.
    pub t: f64,
    /// A step change found since the last report.
    pub step: Option<DetectedStep>,
    /// A step that was "this or that", settled by the samples since.
    pub resolved: Option<TieResolved>,
    /// A step still "this or that" at this report, and the evidence so far.
    pub tie: Option<TieSoFar>,
    /// The parameter whose creep explains a significant drift since the tracking began (or
    /// since the last step) beyond the threshold.
    pub drift: Option<Drift>,
}

/// The tracker's side: the estimator, its drift history and when to report.
pub struct OnlineTracker {
    est: OnlineEstimator,
    monitor: DriftMonitor,
    settings: OnlineSettings,
    published: Params,
    updates: u64,
    /// The first error of the force model, reported once.
    pub error: Option<String>,
}

/// Drift history: one point per this many updates.
const DRIFT_EVERY: u64 = 10;

impl OnlineTracker {
    pub fn new(start: &Params, settings: OnlineSettings) -> OnlineTracker {
        OnlineTracker {
            est: OnlineEstimator::from_covariance(*start, &settings.start_cov, settings.options),
            monitor: DriftMonitor::new(4096),
            settings,
            published: *start,
            updates: 0,
            error: None,
        }
    }

    fn sigma(&self) -> [f64; N_PARAMS] {
        std::array::from_fn(|i| self.est.sigma(i))
    }

    /// One decimated sample (mm, N, °C or NaN); a report when the parameters moved
    /// significantly, a step was found or the drift test warns.
    pub fn sample(&mut self, s: &ForceSample, temp_c: f64) -> Option<OnlineReport> {
        self.est.set_temperature(temp_c);
        let outcome = match self.est.update(s) {
            Ok(o) => o,
            Err(e) => {
                self.error
                    .get_or_insert_with(|| format!("t = {:.3} s: {e}", s.t));
                return None;
            }
        };
        self.updates += 1;
        let (step, resolved) = match outcome {
            OnlineOutcome::Step(step) => {
                self.monitor.rebase();
                (Some(step), None)
            }
            OnlineOutcome::Resolved(r) => {
                // the estimate moved to the runner-up's change: the drift test starts again
                if r.swapped {
                    self.monitor.rebase();
                }
                (None, Some(r))
            }
            _ => (None, None),
        };
        // the drift test at each point of the history (a second at 10 Hz)
        let mut drift = None;
        if self.updates % DRIFT_EVERY == 1 || step.is_some() {
            drift = self
                .monitor
                .record(s.t, temp_c, &mut self.est)
                .and_then(|test| test.warning(self.settings.drift_warn_mm).copied());
        }
        let sigma = self.sigma();
        // in the estimate's covariance: the forces pin combinations of the parameters whose
        // single σ stay wide
        let moved = self.est.distance(&self.published) > self.settings.publish_sigma;
        if !(moved || step.is_some() || resolved.is_some() || drift.is_some()) {
            return None;
        }
        self.published = *self.est.params();
        Some(OnlineReport {
            params: self.published,
            sigma,
            t: s.t,
            step,
            resolved,
            tie: self.est.tie(),
            drift,
        })
    }
}

/// The tracker on its own thread: the loop offers it states, it answers with reports.
pub(super) struct OnlineWorker {
    tx: std::sync::mpsc::SyncSender<(ForceSample, f64)>,
    pub(super) rx: std::sync::mpsc::Receiver<Result<OnlineReport, String>>,
    decimation: u64,
    seen: u64,
    /// Samples the worker was too busy to take (counted on /diagnostics).
    pub(super) dropped: u64,
    pub(super) offered: u64,
    /// States not offered: a holding drive's force not measured (NaN), which the tracker,
    /// reading the geometry from the forces, cannot use.
    pub(super) forces_not_measured: u64,
}

impl OnlineWorker {
    pub(super) fn start(start: Params, settings: &OnlineSettings) -> anyhow::Result<OnlineWorker> {
        let tracker_settings = *settings;
        let (tx, samples) = std::sync::mpsc::sync_channel::<(ForceSample, f64)>(256);
        let (reports, rx) = std::sync::mpsc::channel();
        std::thread::Builder::new()
            .name("online-calibration".into())
            .spawn(move || {
                // the lowest priority of the host: the tracker takes what the estimator and
                // the drive stream leave (on Linux a thread's nice value is its own)
                // SAFETY: setpriority on the calling thread with a constant; no memory passed.
                unsafe {
                    libc::setpriority(libc::PRIO_PROCESS, 0, 19);
                }
                let mut tracker = OnlineTracker::new(&start, tracker_settings);
                let mut told = false;
                while let Ok((s, temp)) = samples.recv() {
                    if let Some(r) = tracker.sample(&s, temp) {
                        let _ = reports.send(Ok(r));
                    }
                    if let (Some(e), false) = (&tracker.error, told) {
                        told = true;
                        let _ = reports.send(Err(e.clone()));
                    }
                }
            })?;
        Ok(OnlineWorker {
            tx,
            rx,
            decimation: settings.decimation.max(1),
            seen: 0,
            dropped: 0,
            offered: 0,
            forces_not_measured: 0,
        })
    }

    /// Offers a drive state: every `decimation`-th with all drives active and their forces
    /// measured goes to the worker, without waiting.
    pub(super) fn offer(&mut self, s: &ActuatorState) {
        if s.follower.iter().any(|f| *f) {
            return;
        }
        if s.force.iter().any(|f| f.is_nan()) {
            self.forces_not_measured += 1;
            return;
        }
        self.seen += 1;
        if !(self.seen - 1).is_multiple_of(self.decimation) {
            return;
        }
        let sample = ForceSample {
            t: f64::from(s.stamp.sec) + f64::from(s.stamp.nanosec) * 1e-9,
            q: drive_positions_mm(s),
            f: s.force,
        };
        let temp = if s.covariate_count > 0 {
            s.covariates[0]
        } else {
            f64::NAN
        };
        self.offered += 1;
        if self.tx.try_send((sample, temp)).is_err() {
            self.dropped += 1;
        }
    }
}

/// A state's name: a parameter's, or the stiffness.
pub(super) fn state_name(i: usize) -> &'static str {
    if i < N_PARAMS {
        rpkm_core::params::NAMES[i]
    } else {
        "stiffness"
    }
}

/// The WARN line of a report: the step, else a tie settled, else the drifts (None when
/// nothing moved enough).
pub fn report_warning(r: &OnlineReport, temp_name: &str) -> Option<String> {
    if let Some(step) = &r.step {
        return Some(step_warning(step));
    }
    if let Some(settled) = &r.resolved {
        return Some(settled_warning(settled));
    }
    r.drift
        .as_ref()
        .map(|d| format!("geometry drift: {}", crate::words::drift(d, temp_name)))
}

fn step_warning(step: &DetectedStep) -> String {
    let (who, why) = match step.alternative {
        // the path so far moved the forces alike for both: say so, do not pick
        Some(other) => (
            format!("{} or {}", state_name(step.param), state_name(other)),
            "the path cannot tell them apart",
        ),
        None => (state_name(step.param).to_owned(), "next best"),
    };
    let mut line = format!(
        "step change at t = {:.1} s: {who} {:+.0} µm ({why}: explains {:.2}x less)",
        step.since_s,
        um_from_mm(step.change),
        step.margin
    );
    if let (Some(motion), Some(_)) = (&step.separating, step.alternative) {
        let poses: Vec<String> = motion
            .poses
            .iter()
            .map(|(x, y)| format!("({x:.0}, {y:.0})"))
            .collect();
        let _ = write!(
            line,
            "; to tell them apart drive through x, y = {} mm, all four drives \
             position-controlled, a sample at each: evidence χ² {:.0} expected, {:.1} settles it",
            poses.join(", "),
            motion.chi2,
            TIE_EVIDENCE_CHI2
        );
    }
    line
}

fn settled_warning(r: &TieResolved) -> String {
    let mut line = format!(
        "step change at t = {:.1} s settled: {} alone {:+.0} µm, {} ruled out by the samples \
         since (evidence χ² {:.1} over {} samples",
        r.since_s,
        state_name(r.param),
        um_from_mm(r.change),
        state_name(r.ruled_out),
        r.evidence.chi2.abs(),
        r.evidence.counted
    );
    if let Some((x, y)) = r.at {
        let _ = write!(line, ", most at x = {x:.0}, y = {y:.0} mm");
    }
    line.push(')');
    if r.swapped {
        let _ = write!(
            line,
            "; not {} as first named: the estimate now carries {}'s change",
            state_name(r.ruled_out),
            state_name(r.param)
        );
    }
    line
}

/// The /diagnostics values of a tie, SI as on every topic: the motion that separates one
/// (its first pose alone too, for a cell that goes to one pose), or how one was settled.
pub(super) fn tie_values(r: &OnlineReport) -> Vec<(&'static str, String)> {
    let mut t = Vec::new();
    if let Some(motion) = r.step.as_ref().and_then(|s| s.separating.as_ref()) {
        if let Some(&(x, y)) = motion.poses.first() {
            t.push(("separating_x_m", format!("{}", m_from_mm(x))));
            t.push(("separating_y_m", format!("{}", m_from_mm(y))));
        }
        let poses: Vec<String> = motion
            .poses
            .iter()
            .map(|(x, y)| format!("{} {}", m_from_mm(*x), m_from_mm(*y)))
            .collect();
        t.push(("separating_poses_m", poses.join("; ")));
        t.push(("separating_chi2", format!("{:.1}", motion.chi2)));
    }
    if let Some(settled) = &r.resolved {
        t.push(("settled", state_name(settled.param).to_owned()));
        t.push(("ruled_out", state_name(settled.ruled_out).to_owned()));
        t.push((
            "evidence_chi2",
            format!("{:.1}", settled.evidence.chi2.abs()),
        ));
    }
    t
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::SVector;
    use rpkm_twin::{Twin, TwinConfig};

    /// The node's tracker on the twin's production stream as the node receives it (SI
    /// messages converted back, every 100th state of 1 kHz): a crash that bends rod 3 by
    /// 0.1 mm at 30 s is reported within 10 s as a WARN naming l3, with Parameters whose l3
    /// moved by the crash (the twin's truth), and nothing is reported as a step before it.
    #[test]
    fn the_online_tracker_warns_of_a_crash_by_name() -> anyhow::Result<()> {
        use rpkm_twin::{EffectKind, ProductionConfig, ProductionStream, StepChange as Crash};
        let elastic = EffectKind::PreloadElastic;
        let twin = Twin::new(TwinConfig {
            seed: 5,
            effects: vec![(elastic, elastic.default_magnitude())],
            ..Default::default()
        })?;
        let l3 = rpkm_core::params::index_of("l3").ok_or_else(|| anyhow::anyhow!("l3"))?;
        let cfg = ProductionConfig {
            seconds: 45.0,
            step: Some(Crash {
                at_s: 30.0,
                param: l3,
                change: 0.1,
            }),
            seed: 5,
            ..Default::default()
        };
        let settings = OnlineSettings {
            start_cov: SMatrix::from_diagonal(&SVector::<f64, N_PARAMS>::from_fn(|i, _| {
                rpkm_core::calib::Prior::default().sigma(i).powi(2)
            })),
            decimation: 100,
            publish_sigma: 1.0,
            drift_warn_mm: 0.01,
            options: OnlineOptions::default(),
        };
        let mut tracker = OnlineTracker::new(twin.true_params(), settings);
        let mut warned = None;
        for (n, s) in ProductionStream::new(&twin, cfg).enumerate() {
            let s = s?;
            if n % 100 != 0 {
                continue;
            }
            let sample = ForceSample {
                t: s.t,
                q: s.q,
                f: s.f,
            };
            if let Some(r) = tracker.sample(&sample, s.temp_c) {
                if let (Some(w), Some(_)) = (report_warning(&r, "temp_machine"), r.step) {
                    assert!(s.t >= 30.0, "a step reported at {} s", s.t);
                    warned.get_or_insert((s.t, w, r.params[l3] - twin.true_params()[l3]));
                }
            }
        }
        assert!(tracker.error.is_none(), "{:?}", tracker.error);
        let (t, w, moved) = warned.ok_or_else(|| anyhow::anyhow!("no step reported"))?;
        assert!(t - 30.0 <= 10.0, "reported at {t} s");
        // l3, alone or with l1 that the forces cannot tell from it, and then with the
        // motion that would
        assert!(w.contains("l3 +") || w.contains("l3 or l1 +"), "{w}");
        if w.contains("l3 or l1 +") {
            assert!(
                w.contains("to tell them apart drive through x, y = "),
                "{w}"
            );
        }
        assert!((moved - 0.1).abs() < 0.02, "l3 moved {moved} mm");
        Ok(())
    }

    /// A tie is reported with the motion that separates it (its poses in mm, its drive
    /// mode, the evidence expected), the same poses in SI on /diagnostics; a tie settled says
    /// which stands, by how much evidence, and whether the estimate moved.
    #[test]
    fn a_tie_is_reported_with_the_motion_that_separates_it() {
        use rpkm_core::calib::tie::{Decisive, SeparatingMotion, TieEvidence};
        use rpkm_core::params::{L1, L3};
        let step = DetectedStep {
            param: L3,
            change: 0.1,
            sigma: 0.001,
            since_s: 20.0,
            margin: 1.02,
            alternative: Some(L1),
            separating: Some(SeparatingMotion {
                poses: vec![(-150.0, 2000.0), (150.0, 1600.0)],
                chi2: 118.4,
                first_chi2: 26.5,
            }),
        };
        let mut r = OnlineReport {
            params: Params::nominal(),
            sigma: [0.0; N_PARAMS],
            t: 21.0,
            step: Some(step),
            resolved: None,
            tie: None,
            drift: None,
        };
        assert_eq!(
            report_warning(&r, "temp_machine").as_deref(),
            Some(
                "step change at t = 20.0 s: l3 or l1 +100 µm (the path cannot tell them apart: \
                 explains 1.02x less); to tell them apart drive through x, y = (-150, 2000), \
                 (150, 1600) mm, all four drives position-controlled, a sample at each: \
                 evidence χ² 118 expected, 27.6 settles it"
            )
        );
        let values = tie_values(&r);
        let get = |k: &str| values.iter().find(|v| v.0 == k).map(|v| v.1.as_str());
        assert_eq!(get("separating_x_m"), Some("-0.15"));
        assert_eq!(get("separating_y_m"), Some("2"));
        assert_eq!(get("separating_poses_m"), Some("-0.15 2; 0.15 1.6"));
        r.step = None;
        r.resolved = Some(TieResolved {
            param: L1,
            change: 0.0998,
            ruled_out: L3,
            since_s: 20.0,
            swapped: true,
            evidence: TieEvidence {
                chi2: -31.24,
                counted: 12,
                neither: 0,
                decisive: Some(Decisive {
                    t: 24.0,
                    q: [0.0; 4],
                    chi2: -20.0,
                }),
            },
            at: Some((-149.6, 1998.2)),
        });
        assert_eq!(
            report_warning(&r, "temp_machine").as_deref(),
            Some(
                "step change at t = 20.0 s settled: l1 alone +100 µm, l3 ruled out by the \
                 samples since (evidence χ² 31.2 over 12 samples, most at x = -150, y = 1998 \
                 mm); not l3 as first named: the estimate now carries l1's change"
            )
        );
        let values = tie_values(&r);
        let get = |k: &str| values.iter().find(|v| v.0 == k).map(|v| v.1.as_str());
        assert_eq!((get("settled"), get("ruled_out")), (Some("l1"), Some("l3")));
    }
}
