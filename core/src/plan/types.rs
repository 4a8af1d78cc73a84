//! What the planner speaks of: the unknowns, the candidate setups, the planned setups and
//! what they determine, and how planning fails. Read by every file of the planner.

use crate::analysis::AnalysisError;
use crate::campaign::Instrument;
use crate::design::PlannedPose;
use crate::obs::{self, Residual};
use crate::params::{Model, NAMES};
use nalgebra::DMatrix;

/// Why a plan could not be made.
#[derive(Debug, thiserror::Error)]
pub enum PlanError {
    /// A candidate pose the model cannot reach or evaluate.
    #[error(transparent)]
    Analysis(#[from] AnalysisError),
    #[error(transparent)]
    Rows(#[from] obs::PoseError),
    /// An instrument the planner has no candidate setups for.
    #[error("no candidate setups for instrument {0} (plan with lt, kgm, dbb, li_psi or self)")]
    NoCandidates(Instrument),
    /// A hypothesis the separation does not know.
    #[error("unknown hypothesis `{0}`: expected dir_q1..dir_q4 (lost motion of a carrier) or a parameter name")]
    UnknownHypothesis(String),
    /// Two hypotheses named alike.
    #[error("the two hypotheses are the same (`{0}`)")]
    SameHypothesis(String),
    /// Nowhere to judge the TCP's accuracy.
    #[error("no pose to judge the TCP's accuracy at")]
    NoEvaluationPoses,
    /// A pose where the TCP is judged that the model cannot reach.
    #[error("target ({x}, {y}) mm: {error}")]
    Target {
        x: f64,
        y: f64,
        error: crate::geometry::GeometryError,
    },
}

/// The unknowns a plan is made for: parameter indexes and their tolerance (one σ of the
/// prior, mm or rad): a column of the information is the parameter in units of it.
#[derive(Clone, Debug, PartialEq)]
pub struct Unknowns {
    pub ids: Vec<usize>,
    pub tolerance: Vec<f64>,
}

impl Unknowns {
    /// The parameters of `model`, each under `tolerance(i)`.
    pub fn of_model(model: Model, tolerance: impl Fn(usize) -> f64) -> Unknowns {
        let ids = model.params();
        let tolerance = ids.iter().map(|&i| tolerance(i)).collect();
        Unknowns { ids, tolerance }
    }

    pub fn len(&self) -> usize {
        self.ids.len()
    }

    pub fn is_empty(&self) -> bool {
        self.ids.is_empty()
    }

    /// Names of the unknowns.
    pub fn names(&self) -> Vec<&'static str> {
        self.ids.iter().map(|&i| NAMES[i]).collect()
    }

    /// Rows as a block of the information's square root: (J/σ) T.
    pub fn block(&self, rows: &[&Residual]) -> DMatrix<f64> {
        DMatrix::from_fn(rows.len(), self.len(), |r, k| {
            rows[r].jacobian[self.ids[k]] * self.tolerance[k] / rows[r].sigma
        })
    }

    /// The information G = Bᵀ B of `rows`.
    pub fn information(&self, rows: &[Residual]) -> DMatrix<f64> {
        let refs: Vec<&Residual> = rows.iter().collect();
        let b = self.block(&refs);
        b.tr_mul(&b)
    }
}

/// What a campaign determines: combinations pinned better than their tolerance, out of how
/// many, and the effective number determined (tr G (I + G)⁻¹, each combination counting
/// λ/(1 + λ): half at exactly its tolerance).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Determination {
    pub determined: usize,
    pub of: usize,
    pub effective: f64,
}

impl Determination {
    /// The determination of information `g` (prior-scaled).
    pub fn of(g: &DMatrix<f64>) -> Determination {
        let ev = g.clone().symmetric_eigenvalues();
        Determination {
            determined: ev.iter().filter(|&&v| v > 1.0).count(),
            of: g.nrows(),
            effective: ev.iter().map(|&v| v.max(0.0) / (1.0 + v.max(0.0))).sum(),
        }
    }
}

/// A setup the engineer can mount: its instrument, its reset pose (relative instruments)
/// and the points its travel and range reach from there.
#[derive(Clone, Debug, PartialEq)]
pub struct CandidateSetup {
    pub id: String,
    pub instrument: Instrument,
    pub reset: Option<(f64, f64)>,
    pub points: Vec<(f64, f64)>,
    /// Whether it ends with a return to its reset pose, the drift check (where its
    /// instrument was zeroed on a reading: [`returns_to_zero`]).
    pub returns: bool,
}

impl CandidateSetup {
    /// The pose that ends the setup where it returns ([`Self::returns`]): its reset pose's
    /// target, measured as any other pose (not a reset), whose reading is the instrument's
    /// drift since its zero ([`crate::returns`]). None for a setup that does not return (a
    /// ball-bar's: zeroed on no reading, its pivot) and one without a reset.
    pub fn return_pose(&self) -> Option<PlannedPose> {
        let reset = self.reset.filter(|_| self.returns)?;
        Some(PlannedPose::new(&self.id, self.instrument, false, reset))
    }

    /// Poses the setup costs besides its points: its reset and its return.
    pub fn overhead(&self) -> usize {
        usize::from(self.reset.is_some()) + usize::from(self.return_pose().is_some())
    }

    /// The setup as a design: the reset first, then `points` (indexes into `self.points`).
    pub fn design(&self, points: &[usize]) -> Vec<PlannedPose> {
        let pose =
            |reset: bool, at: (f64, f64)| PlannedPose::new(&self.id, self.instrument, reset, at);
        self.reset
            .map(|r| pose(true, r))
            .into_iter()
            .chain(points.iter().map(|&k| pose(false, self.points[k])))
            .collect()
    }
}

/// Whether a setup of `instrument` ends with a return to its reset pose: an instrument
/// zeroed on a reading (tracker, grid encoder, interferometer, angle optics), whose zero can
/// drift. A ball-bar's zero is its pivot, which the machine cannot return to with the bar
/// mounted.
pub fn returns_to_zero(instrument: Instrument) -> bool {
    instrument.is_relative() && instrument != Instrument::Dbb
}

/// The plan of one setup: what it measures and what is determined once it is measured.
#[derive(Clone, Debug, PartialEq)]
pub struct PlannedSetup {
    pub setup: CandidateSetup,
    /// Indexes into the candidate's points, in measuring order.
    pub points: Vec<usize>,
    /// Poses it costs (its points, its reset and its return).
    pub poses: usize,
    /// The determination after it (and the setups before it).
    pub after: Determination,
    /// The expected held-out RMS after it (and the setups before it), mm: the accuracy
    /// criterion's ([`crate::plan::forecast`]); None in a plan for the determinant.
    pub expected_mm: Option<f64>,
}

impl PlannedSetup {
    /// Its poses as a design: the reset first, then the points, then the return.
    pub fn design(&self) -> Vec<PlannedPose> {
        let mut d = self.setup.design(&self.points);
        d.extend(self.setup.return_pose());
        d
    }
}

/// The plan: the determination now, the setups in order with the determination after each.
#[derive(Clone, Debug, PartialEq)]
pub struct DeterminationPlan {
    pub before: Determination,
    pub setups: Vec<PlannedSetup>,
}

impl DeterminationPlan {
    /// The determination after the whole plan.
    pub fn after(&self) -> Determination {
        self.setups.last().map_or(self.before, |s| s.after)
    }

    /// All planned poses, setup after setup.
    pub fn design(&self) -> Vec<PlannedPose> {
        self.setups.iter().flat_map(PlannedSetup::design).collect()
    }
}
