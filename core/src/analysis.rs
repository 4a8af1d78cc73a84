//! Sensitivity and observability analyses of the calibration methods (thesis 3.3.2-3.3.5,
//! 4.2.3-4.2.4, 4.3.3-4.3.4: figures 4.10-4.22, tables 4.4-4.8).
//!
//! Both analyses work on the calibration Jacobian of a method at nominal parameters: a
//! [`nominal_campaign`] (the poses of a design at parameters `p`, measured values consistent
//! with `p`) goes through [`obs::residuals`], whose rows carry the Jacobian over the 29
//! parameters and each row's standard deviation.
//!
//! - Sensitivity (eq. 3.14-3.16, 2-norm): for parameter k and measurement direction d,
//!   σ_{d,k} = sqrt(Σ_{i∈I_d} (J_{i,k}·δp_k)² / m_d), δp_k = 0.1 mm or 1°. Reported in µm
//!   (mrad for ψ). Evaluated on the 231-point grid (11 × 21) of the workspace, relative
//!   instruments with one reset at the centre; the grid encoder on its own 16-setup design
//!   (thesis 4.2.3.1: its sensitivities are smaller *because* each setup covers only its disc).
//! - Observability (eq. 3.20-3.30): weighted (1/σ per row, eq. 3.21) Jacobian with parameter
//!   scaling (eq. 3.23: range scaling after Schröer, or column norms eq. 3.25); singular values,
//!   practical rank (eq. 3.27-3.28), and the parameters in QR-pivot order with the condition
//!   number of the column-normalised Jacobian (eq. 3.26) as each one is added.
//!
//! The default [`ObservabilityOptions`] reproduce the order of table 4.7 (self-calibration,
//! model 24); see `docs/observability.md` for the comparison with tables 4.4-4.8.

use crate::campaign::{Campaign, Instrument, MeasuredPose};
use crate::design::{self, PlannedPose, CENTRE};
use crate::effects::{Corrections, Delta};
use crate::geometry::{self, GeometryError};
use crate::noise::NoiseModel;
use crate::obs::{self, Direction, PoseError, Residual, Step};
use crate::observability::{condition_number, normalize_columns, pivot_order};
use crate::params::{variation_range, Model, Params, NAMES};
use nalgebra::{DMatrix, DVector};
use std::collections::BTreeMap;
use std::fmt;
use std::str::FromStr;

/// Why an analysis could not be made.
#[derive(Debug, thiserror::Error)]
pub enum AnalysisError {
    /// A planned pose the inverse model cannot reach at the given parameters.
    #[error("planned pose {index} ({setup}, x = {x} mm, y = {y} mm): {error}")]
    MeasuredPose {
        index: usize,
        setup: String,
        x: f64,
        y: f64,
        #[source]
        error: GeometryError,
    },
    /// The calibration rows could not be evaluated.
    #[error(transparent)]
    Rows(#[from] PoseError),
    /// The campaign gave no calibration row.
    #[error("the campaign gives no calibration row")]
    NoRows,
}

/// A calibration method of the thesis (the instrument and its campaign).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// Laser tracker, inverse calibration (q1..q4 rows).
    Lt,
    /// Grid encoder KGM 182, inverse calibration.
    Kgm,
    /// Double ball-bar, forward calibration (+ second step q2).
    Dbb,
    /// Laser interferometer along x and y (`li_x` + `li_y`), forward calibration.
    Li,
    /// Laser tracker completed by platform-angle measurements (`lt` + `li_psi`), as the
    /// thesis's "LT 29 with platform angle measurements" (table 4.6, figure 4.18): ψ alone is
    /// relative and, in model 24, identically γ2, so it identifies nothing by itself.
    Psi,
    /// Self-calibration: q2, q3 followers against rgm(q1, q4).
    SelfCal,
    /// The drive forces (redundancy currents) with all four drives position-controlled and
    /// no instrument (issue 15), with the stiffness factor as an unknown beside the
    /// parameters ([`STIFFNESS_FACTOR`]).
    Currents,
}

/// Name of the stiffness factor's column in the analyses of [`Method::Currents`].
pub const STIFFNESS_FACTOR: &str = "stiffness_factor";
/// Its variation range (the scaling of its column, as 0.1 mm and 1° are the parameters'):
/// 10 % of the default stiffness.
pub const STIFFNESS_RANGE: f64 = crate::effects::stiffness_factor::PRIOR;

impl Method {
    pub const ALL: [Method; 7] = [
        Method::Lt,
        Method::Kgm,
        Method::Dbb,
        Method::Li,
        Method::Psi,
        Method::SelfCal,
        Method::Currents,
    ];

    /// Spelling on the command line: `lt`, `kgm`, `dbb`, `li`, `psi`, `self`.
    pub fn as_str(self) -> &'static str {
        match self {
            Method::Lt => "lt",
            Method::Kgm => "kgm",
            Method::Dbb => "dbb",
            Method::Li => "li",
            Method::Psi => "psi",
            Method::SelfCal => "self",
            Method::Currents => "currents",
        }
    }

    /// The instruments of the method.
    pub fn instruments(self) -> Vec<Instrument> {
        match self {
            Method::Lt => vec![Instrument::Lt],
            Method::Kgm => vec![Instrument::Kgm],
            Method::Dbb => vec![Instrument::Dbb],
            Method::Li => vec![Instrument::LiX, Instrument::LiY],
            Method::Psi => vec![Instrument::Lt, Instrument::LiPsi],
            Method::SelfCal => vec![Instrument::SelfCal],
            Method::Currents => vec![Instrument::None],
        }
    }

    /// Whether the method is a forward calibration with a second step (q2 from virtual
    /// measurements, thesis 4.2.1).
    pub fn has_second_step(self) -> bool {
        matches!(self, Method::Dbb | Method::Li)
    }

    /// The campaign design of the method (observability).
    pub fn design(self) -> Vec<PlannedPose> {
        if self == Method::Currents {
            return grid_design(Instrument::None);
        }
        self.instruments()
            .into_iter()
            .flat_map(design::for_instrument)
            .collect()
    }

    /// The design of the sensitivity analysis: each instrument on the 231-point grid, one
    /// setup reset at the workspace centre for relative instruments; the grid encoder on its
    /// own campaign design (its sensitivity is limited by its 16 small setups).
    pub fn sensitivity_design(self) -> Vec<PlannedPose> {
        self.instruments()
            .into_iter()
            .flat_map(|inst| match inst {
                Instrument::Kgm => design::kgm(),
                _ => grid_design(inst),
            })
            .collect()
    }
}

impl fmt::Display for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A method name that is not one of `lt`, `kgm`, `dbb`, `li`, `psi`, `self`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown method {0:?}, expected one of lt, kgm, dbb, li, psi, self, currents")]
pub struct ParseMethodError(pub String);

impl FromStr for Method {
    type Err = ParseMethodError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Method::ALL
            .into_iter()
            .find(|m| m.as_str() == s)
            .ok_or_else(|| ParseMethodError(s.to_owned()))
    }
}

/// The 231-point grid as one setup of `instrument`, reset at the workspace centre (a grid
/// point) for relative instruments, no reset for self-calibration.
pub fn grid_design(instrument: Instrument) -> Vec<PlannedPose> {
    let relative = instrument.is_relative();
    let setup = format!("grid_{}", instrument.as_str());
    let mut out = Vec::with_capacity(232);
    if relative {
        out.push(PlannedPose::new(&setup, instrument, true, CENTRE));
    }
    for (x, y) in design::grid_231() {
        if relative && (x - CENTRE.0).abs() < 1e-9 && (y - CENTRE.1).abs() < 1e-9 {
            continue;
        }
        out.push(PlannedPose::new(&setup, instrument, false, (x, y)));
    }
    out
}

/// The poses of `design` on a machine with parameters `p`: actuator positions from the inverse
/// model, measured values exactly consistent with `p` (0 at resets; the ball-bar distance from
/// the reset TCP; ψ relative to the reset's ψ), the drives in the design's modes.
/// `obs::residuals(&c, p, model, Step::Direct, p)` then has zero values and the calibration
/// Jacobian of the method at `p`.
pub fn nominal_campaign(
    design: &[PlannedPose],
    p: &Params,
    model: Model,
) -> Result<Campaign, AnalysisError> {
    let mut sols = Vec::with_capacity(design.len());
    for (index, pp) in design.iter().enumerate() {
        let sol =
            geometry::igm(p, model, pp.x, pp.y).map_err(|error| AnalysisError::MeasuredPose {
                index,
                setup: pp.setup.clone(),
                x: pp.x,
                y: pp.y,
                error,
            })?;
        sols.push(sol);
    }
    // reset pose (index) of each setup
    let mut resets: BTreeMap<&str, usize> = BTreeMap::new();
    for (i, pp) in design.iter().enumerate() {
        if pp.reset {
            resets.entry(pp.setup.as_str()).or_insert(i);
        }
    }
    let mut poses = Vec::with_capacity(design.len());
    for (i, (pp, sol)) in design.iter().zip(&sols).enumerate() {
        let m = pp.instrument.measures();
        let reset = resets.get(pp.setup.as_str()).map(|&r| &sols[r]);
        let (dx, dy, dpsi) = match reset {
            Some(r) if !pp.reset => (sol.x() - r.x(), sol.y() - r.y(), sol.psi() - r.psi()),
            _ => (0.0, 0.0, 0.0),
        };
        poses.push(MeasuredPose {
            t: i as f64,
            setup: pp.setup.clone(),
            instrument: pp.instrument,
            reset: pp.reset,
            q: sol.q(),
            f: [0.0; 4],
            follower: pp.follower,
            x: m.x.then_some(dx),
            y: m.y.then_some(dy),
            r: m.r.then_some(dx.hypot(dy)),
            psi: m.psi.then_some(dpsi),
            covariates: Vec::new(),
            line: 0,
        });
    }
    Ok(Campaign {
        source: "nominal campaign".to_owned(),
        comments: Vec::new(),
        covariate_names: Vec::new(),
        poses,
    })
}

/// The calibration rows of a design at `p`: the direct rows and, when `second_step`, the
/// virtual q2 rows of the forward instruments (with p_cal = p).
pub fn design_rows(
    design: &[PlannedPose],
    p: &Params,
    model: Model,
    second_step: bool,
) -> Result<Vec<Residual>, AnalysisError> {
    let c = nominal_campaign(design, p, model)?;
    if design.iter().all(|d| d.instrument == Instrument::None) {
        return currents_rows(&c, p);
    }
    let mut rows = obs::residuals(&c, p, model, Step::Direct, p, &NoiseModel::default())?;
    if second_step {
        rows.extend(obs::residuals(
            &c,
            p,
            model,
            Step::VirtualQ2,
            p,
            &NoiseModel::default(),
        )?);
    }
    if rows.is_empty() {
        return Err(AnalysisError::NoRows);
    }
    Ok(rows)
}

/// The drive-force rows of every pose of `c` with all four drives position-controlled, at
/// `p`, with the stiffness factor's derivative as their one `d_theta` (an analysis of
/// [`Method::Currents`]; planned poses consistent with `p` have no preload, so its column is
/// zero there: only a recorded path shows it).
pub fn currents_rows(c: &Campaign, p: &Params) -> Result<Vec<Residual>, AnalysisError> {
    let stiffness = Delta {
        dk: 1.0,
        ..Default::default()
    };
    let corr = Corrections::uniform(c.poses.len(), Delta::default(), &[stiffness]);
    let rows = obs::force_residuals(c, p, &corr, &NoiseModel::default())?;
    if rows.is_empty() {
        return Err(AnalysisError::NoRows);
    }
    Ok(rows)
}

/// The columns of an analysis: the model's parameters (by index) and, for the currents,
/// the stiffness factor (the rows' `d_theta[0]`).
#[derive(Clone, Debug)]
struct Columns {
    /// Parameter index, or None for the stiffness factor.
    ids: Vec<Option<usize>>,
}

impl Columns {
    fn new(model: Model, exclude: &[usize], method: Method) -> Columns {
        let mut ids: Vec<Option<usize>> = model
            .params()
            .into_iter()
            .filter(|i| !exclude.contains(i))
            .map(Some)
            .collect();
        if method == Method::Currents {
            ids.push(None);
        }
        Columns { ids }
    }
    fn name(&self, k: usize) -> String {
        self.ids[k]
            .map_or(STIFFNESS_FACTOR, |i| NAMES[i])
            .to_owned()
    }
    fn range(&self, k: usize) -> f64 {
        self.ids[k].map_or(STIFFNESS_RANGE, variation_range)
    }
    fn entry(&self, r: &Residual, k: usize) -> f64 {
        match self.ids[k] {
            Some(i) => r.jacobian[i],
            None => r.d_theta.first().copied().unwrap_or(0.0),
        }
    }
    fn jacobian(&self, rows: &[Residual], weighted: bool) -> DMatrix<f64> {
        DMatrix::from_fn(rows.len(), self.ids.len(), |i, k| {
            let w = if weighted { 1.0 / rows[i].sigma } else { 1.0 };
            self.entry(&rows[i], k) * w
        })
    }
}

/// One measurement direction of a sensitivity table.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct SensitivityDirection {
    /// Label: `q1`..`q4`, `r(q1,q4)`, `x(q3,q4)`, `psi(q1,q4)`, `q2 (virtual)` ...
    pub name: String,
    /// Instrument of its rows.
    pub instrument: Instrument,
    /// Unit of its entries: `µm`, `mrad` or `N`.
    pub unit: &'static str,
    /// Number of rows m_d.
    pub rows: usize,
}

/// Sensitivity of each parameter in each measurement direction (eq. 3.16).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct SensitivityTable {
    pub method: Method,
    pub model: u32,
    /// Parameter names, in thesis order (the model's parameters).
    pub parameters: Vec<String>,
    pub directions: Vec<SensitivityDirection>,
    /// `values[k][d]`: parameter k, direction d, in the direction's unit (µm or mrad).
    pub values: Vec<Vec<f64>>,
}

impl SensitivityTable {
    /// The entry of a parameter (by name) and direction (by label).
    pub fn get(&self, parameter: &str, direction: &str) -> Option<f64> {
        let k = self.parameters.iter().position(|p| p == parameter)?;
        let d = self.directions.iter().position(|d| d.name == direction)?;
        Some(self.values[k][d])
    }
}

/// Sensitivity table of rows (eq. 3.14-3.16): per direction (instrument and [`Direction`]),
/// the 2-norm mean of J_{i,k}·δp_k over the direction's rows, ×1000 (mm → µm, rad → mrad;
/// forces stay in N). The currents have the stiffness factor as a last parameter.
pub fn sensitivity_of_rows(rows: &[Residual], method: Method, model: Model) -> SensitivityTable {
    let cols = Columns::new(model, &[], method);
    let mut groups: BTreeMap<(Instrument, Direction), Vec<&Residual>> = BTreeMap::new();
    for r in rows {
        groups
            .entry((r.instrument, r.direction))
            .or_default()
            .push(r);
    }
    let directions: Vec<SensitivityDirection> = groups
        .iter()
        .map(|((inst, dir), g)| SensitivityDirection {
            name: match (method, dir) {
                (Method::Psi, Direction::Q(_)) => format!("{dir}"),
                _ => dir.to_string(),
            },
            instrument: *inst,
            unit: if dir.is_angle() {
                "mrad"
            } else if dir.is_force() {
                "N"
            } else {
                "µm"
            },
            rows: g.len(),
        })
        .collect();
    let values = (0..cols.ids.len())
        .map(|k| {
            groups
                .iter()
                .map(|((_, dir), g)| {
                    let s: f64 = g
                        .iter()
                        .map(|r| (cols.entry(r, k) * cols.range(k)).powi(2))
                        .sum();
                    let unit = if dir.is_force() { 1.0 } else { 1000.0 };
                    unit * (s / g.len() as f64).sqrt()
                })
                .collect()
        })
        .collect();
    SensitivityTable {
        method,
        model: model.number(),
        parameters: (0..cols.ids.len()).map(|k| cols.name(k)).collect(),
        directions,
        values,
    }
}

/// Sensitivity analysis of a method at parameters `p` on its sensitivity design
/// ([`Method::sensitivity_design`]), the second step's q2 included for dbb and li (figures
/// 4.12, 4.13: "dr, dq2", "dx, dq2").
pub fn sensitivity(
    method: Method,
    p: &Params,
    model: Model,
) -> Result<SensitivityTable, AnalysisError> {
    let rows = design_rows(
        &method.sensitivity_design(),
        p,
        model,
        method.has_second_step(),
    )?;
    Ok(sensitivity_of_rows(&rows, method, model))
}

/// Parameter scaling of the observability matrix (eq. 3.23-3.25).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ParamScaling {
    /// Each column × the parameter's variation range (0.1 mm, 1°), after Schröer (3.3.4.2).
    #[default]
    Range,
    /// Each column to unit norm (eq. 3.25).
    ColumnNorm,
    /// No scaling (columns in mm⁻¹ or rad⁻¹ mixed).
    None,
}

/// How the parameters are sorted.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Pivoting {
    /// QR with column pivoting on the scaled Jacobian itself: at each step the parameter with
    /// the largest effect not explained by those already chosen (section 4.2.4: "the one
    /// with the smallest sensitivity is sorted out").
    #[default]
    Jacobian,
    /// QR with column pivoting of V_rᵀ (eq. 3.29), V_r the first r right singular vectors of
    /// the scaled Jacobian (r = [`ObservabilityOptions::block`], else the practical rank):
    /// the first r parameters. Then "the parameter sorting process is done on the rest of the
    /// Jacobian matrix" (4.2.4): the chosen columns are projected out and the next parameter
    /// is the largest component of the dominant right singular vector of what remains, one
    /// at a time, until nothing independent remains; exactly dependent columns last.
    SingularVectors,
}

/// Which matrix the condition number of each prefix is taken on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ConditionOn {
    /// The column-normalised Jacobian J_H (eq. 3.25-3.26): "the condition number of the
    /// normalized Jacobian matrix" of tables 4.4-4.8.
    #[default]
    Normalized,
    /// The scaled matrix the pivoting used.
    Scaled,
}

/// Options of the observability analysis.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ObservabilityOptions {
    /// Rows divided by their standard deviation (task-variable scaling, eq. 3.21).
    pub weighted: bool,
    pub scaling: ParamScaling,
    pub pivoting: Pivoting,
    pub condition_on: ConditionOn,
    /// Tolerance τ of the practical rank (eq. 3.27), applied to the singular values of the
    /// weighted, range-scaled Jacobian: with rows in units of their standard deviation
    /// (ε_meas = 1) and columns in units of the variation range, a singular value below 1
    /// is a parameter combination whose whole range of variation moves the measurements by
    /// less than their noise.
    pub tau: f64,
    /// Size r of the first block of [`Pivoting::SingularVectors`]; None: the practical rank.
    pub block: Option<usize>,
}

impl Default for ObservabilityOptions {
    fn default() -> Self {
        ObservabilityOptions {
            weighted: true,
            scaling: ParamScaling::Range,
            pivoting: Pivoting::Jacobian,
            condition_on: ConditionOn::Normalized,
            tau: 1.0,
            block: None,
        }
    }
}

/// One line of the sorted parameter list.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct OrderEntry {
    pub parameter: String,
    /// Condition number with this and all earlier parameters (∞ written as `null` in JSON
    /// by serde_json).
    pub condition_number: f64,
}

/// Result of the observability analysis.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Observability {
    pub method: Method,
    pub model: u32,
    pub options: ObservabilityOptions,
    /// Number of calibration rows.
    pub rows: usize,
    /// Parameters in decreasing order of importance with the condition number of each prefix.
    pub order: Vec<OrderEntry>,
    /// Singular values of the weighted, range-scaled Jacobian, descending.
    pub singular_values: Vec<f64>,
    /// Practical rank: singular values above `options.tau`.
    pub practical_rank: usize,
    /// Condition number of the whole (column-normalised) Jacobian.
    pub condition_number: f64,
    /// The currents only: how the stiffness factor separates from the geometry.
    pub stiffness: Option<StiffnessSeparation>,
}

/// How far the data separate the stiffness factor from the geometric parameters: its
/// column of the weighted, range-scaled Jacobian (rows in σ, the factor in units of
/// 10 %) and the part of it no combination of the parameters' columns explains.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct StiffnessSeparation {
    /// Norm of its column: 0 where nothing is preloaded (a machine consistent with the
    /// controller), below 1 where its whole range moves the forces by less than their noise.
    pub column_norm: f64,
    /// Norm of the part orthogonal to every parameter's column: what the data determine of
    /// it with the geometry free (its σ with the geometry free is `range / independent_norm`).
    pub independent_norm: f64,
}

impl StiffnessSeparation {
    /// Share of the column the geometry explains (1: indistinguishable).
    pub fn explained(&self) -> f64 {
        if self.column_norm > 0.0 {
            1.0 - (self.independent_norm / self.column_norm).powi(2)
        } else {
            f64::NAN
        }
    }

    /// σ of the stiffness factor (relative) the rows give it with the geometry free.
    pub fn sigma_free(&self) -> f64 {
        STIFFNESS_RANGE / self.independent_norm
    }
}

/// The stiffness factor's column `k` of `m` against the span of the others.
fn stiffness_separation(m: &DMatrix<f64>, k: usize) -> StiffnessSeparation {
    let c = m.column(k).into_owned();
    let others = m.clone().remove_column(k);
    let svd = others.svd(true, false);
    let u = svd.u.expect("U requested");
    let top = svd.singular_values.iter().copied().fold(0.0, f64::max);
    let mut rest = c.clone();
    for (j, s) in svd.singular_values.iter().enumerate() {
        if *s > 1e-12 * top {
            let uj = u.column(j);
            rest -= uj * uj.dot(&c);
        }
    }
    StiffnessSeparation {
        column_norm: c.norm(),
        independent_norm: rest.norm(),
    }
}

impl Observability {
    /// The first `n` parameter names of the order.
    pub fn first(&self, n: usize) -> Vec<&str> {
        self.order
            .iter()
            .take(n)
            .map(|e| e.parameter.as_str())
            .collect()
    }
}

/// The (optionally weighted) Jacobian of rows over the parameters `ids`, unscaled.
pub fn jacobian(rows: &[Residual], ids: &[usize], weighted: bool) -> DMatrix<f64> {
    DMatrix::from_fn(rows.len(), ids.len(), |i, k| {
        let w = if weighted { 1.0 / rows[i].sigma } else { 1.0 };
        rows[i].jacobian[ids[k]] * w
    })
}

fn scale_columns(j: &DMatrix<f64>, cols: &Columns, scaling: ParamScaling) -> DMatrix<f64> {
    match scaling {
        ParamScaling::Range => {
            let h =
                DVector::from_iterator(cols.ids.len(), (0..cols.ids.len()).map(|k| cols.range(k)));
            j * DMatrix::from_diagonal(&h)
        }
        ParamScaling::ColumnNorm => normalize_columns(j),
        ParamScaling::None => j.clone(),
    }
}

/// Indexes of the rows of Vᵀ sorted by descending singular value, with Vᵀ.
fn right_singular_vectors(m: &DMatrix<f64>) -> (Vec<usize>, DMatrix<f64>) {
    let svd = m.clone().svd(false, true);
    let vt = svd.v_t.unwrap_or_else(|| DMatrix::zeros(0, m.ncols()));
    let mut idx: Vec<usize> = (0..svd.singular_values.len()).collect();
    idx.sort_by(|&a, &b| svd.singular_values[b].total_cmp(&svd.singular_values[a]));
    (idx, vt)
}

/// Order of [`Pivoting::SingularVectors`] with a first block of `r` parameters.
///
/// # Panics
/// Never: a column remains while fewer than `r <= n` are ordered.
pub fn sv_pivot_order(m: &DMatrix<f64>, r: usize) -> Vec<usize> {
    let n = m.ncols();
    let scale = (0..n).map(|j| m.column(j).norm()).fold(0.0, f64::max);
    let (idx, vt) = right_singular_vectors(m);
    let r = r.min(idx.len());
    let vr = DMatrix::from_fn(r, n, |i, k| vt[(idx[i], k)]);
    let mut order: Vec<usize> = pivot_order(&vr).into_iter().take(r).collect();
    while order.len() < n {
        // project the chosen columns out of the matrix
        let q = m.select_columns(order.iter()).qr().q();
        let mut rest = m - &q * (q.transpose() * m);
        for &c in &order {
            rest.column_mut(c).fill(0.0);
        }
        let best = (0..n)
            .filter(|c| !order.contains(c))
            .map(|c| (c, rest.column(c).norm()))
            .fold((usize::MAX, 0.0), |a, b| if b.1 > a.1 { b } else { a });
        if !(best.1 > 1e-10 * scale) {
            break;
        }
        let (idx, vt) = right_singular_vectors(&rest);
        let next = (0..n)
            .filter(|c| !order.contains(c))
            .max_by(|&a, &b| vt[(idx[0], a)].abs().total_cmp(&vt[(idx[0], b)].abs()))
            .expect("a column remains");
        order.push(next);
    }
    // exactly dependent columns: in QR-pivot order of the whole matrix
    for c in pivot_order(m) {
        if !order.contains(&c) {
            order.push(c);
        }
    }
    order
}

/// Observability analysis of calibration rows over the model's parameters.
///
/// `exclude`: parameters left out of the analysis (e.g. d1 for self-calibration with model 29,
/// thesis 4.3.4.2). The currents have the stiffness factor as a last unknown.
pub fn observability_of_rows(
    rows: &[Residual],
    method: Method,
    model: Model,
    exclude: &[usize],
    opts: &ObservabilityOptions,
) -> Observability {
    let cols = Columns::new(model, exclude, method);
    let ids = &cols.ids;
    let j = cols.jacobian(rows, opts.weighted);
    let scaled = scale_columns(&j, &cols, opts.scaling);
    let ranged = scale_columns(&j, &cols, ParamScaling::Range);
    let mut sv: Vec<f64> = ranged.singular_values().iter().copied().collect();
    sv.sort_by(|a, b| b.total_cmp(a));
    let rank = sv.iter().filter(|&&s| s > opts.tau).count();
    let order = match opts.pivoting {
        Pivoting::Jacobian => pivot_order(&scaled),
        Pivoting::SingularVectors => {
            sv_pivot_order(&scaled, opts.block.unwrap_or(rank).clamp(1, ids.len()))
        }
    };
    let cond_matrix = match opts.condition_on {
        ConditionOn::Normalized => normalize_columns(&j),
        ConditionOn::Scaled => scaled.clone(),
    };
    let order_entries = (0..order.len())
        .map(|k| OrderEntry {
            parameter: cols.name(order[k]),
            condition_number: condition_number(&cond_matrix.select_columns(order[..=k].iter())),
        })
        .collect();
    Observability {
        method,
        model: model.number(),
        options: *opts,
        rows: rows.len(),
        order: order_entries,
        singular_values: sv,
        practical_rank: rank,
        condition_number: condition_number(&normalize_columns(&j)),
        stiffness: ids
            .iter()
            .position(Option::is_none)
            .map(|k| stiffness_separation(&ranged, k)),
    }
}

/// Observability analysis of a method on its campaign design at parameters `p`. Forward
/// methods (dbb, li) are analysed on their first step only, as tables 4.4-4.5 list them
/// (rod 2's parameters are then unobservable and sort last with an infinite condition
/// number).
pub fn observability(
    method: Method,
    p: &Params,
    model: Model,
    exclude: &[usize],
    opts: &ObservabilityOptions,
) -> Result<Observability, AnalysisError> {
    let rows = design_rows(&method.design(), p, model, false)?;
    Ok(observability_of_rows(&rows, method, model, exclude, opts))
}
