//! The checks every sample passes before it is republished, whatever its source: finite
//! numbers, the configured ranges (SI), order (stamp never going back, seq increasing).

use rpkm_msgs::{ActuatorState, TcpMeasurement, Time};

use crate::node::declare::{ParamBound, ParamDefault, ParamSpec};
use crate::node::params::{NodeParams, ParamError};

/// Why a sample was rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RejectKind {
    /// Not a row of the campaign format (wrong field count, not a number, unknown name).
    Malformed,
    /// NaN or infinity where a number is required (a force may be NaN: not measured).
    NonFinite,
    /// Outside the configured ranges.
    OutOfRange,
    /// Stamp earlier than the last accepted one, or seq not increasing.
    OutOfOrder,
}

impl RejectKind {
    pub(super) const ALL: [RejectKind; 4] = [
        Self::Malformed,
        Self::NonFinite,
        Self::OutOfRange,
        Self::OutOfOrder,
    ];
    /// The key on /diagnostics.
    pub fn key(self) -> &'static str {
        match self {
            Self::Malformed => "rejected_malformed",
            Self::NonFinite => "rejected_non_finite",
            Self::OutOfRange => "rejected_out_of_range",
            Self::OutOfOrder => "rejected_out_of_order",
        }
    }
}

/// A rejected sample: kind and a message naming where and what.
#[derive(Debug, Clone, PartialEq)]
pub struct Reject {
    /// Kind.
    pub kind: RejectKind,
    /// What was wrong.
    pub detail: String,
}

pub(super) fn reject(kind: RejectKind, detail: String) -> Reject {
    Reject { kind, detail }
}

/// Accepted ranges (SI).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InputLimits {
    /// Actuator positions, m.
    pub position_min_m: f64,
    /// Actuator positions, m.
    pub position_max_m: f64,
    /// |drive force|, N.
    pub force_max_n: f64,
    /// |x|, |y|, |r| of a measurement, m.
    pub measurement_max_m: f64,
}

/// Parameter `position_min_m`.
pub const POSITION_MIN: ParamSpec = ParamSpec::live(
    "position_min_m",
    ParamDefault::F64(-0.5),
    "lowest accepted drive position (below position_max_m)",
)
.unit("m");
/// Parameter `position_max_m`.
pub const POSITION_MAX: ParamSpec = ParamSpec::live(
    "position_max_m",
    ParamDefault::F64(4.5),
    "highest accepted drive position",
)
.unit("m");
/// Parameter `force_max_n`: five times a drive's nominal force.
pub const FORCE_MAX: ParamSpec = ParamSpec::live(
    "force_max_n",
    ParamDefault::F64(5.0 * rpkm_core::elastic::NOMINAL_DRIVE_FORCE_N),
    "largest accepted |drive force|",
)
.unit("N")
.bound(ParamBound::Positive);
/// Parameter `measurement_max_m`.
pub const MEASUREMENT_MAX: ParamSpec = ParamSpec::live(
    "measurement_max_m",
    ParamDefault::F64(5.0),
    "largest accepted |x|, |y|, |r| of a measurement",
)
.unit("m")
.bound(ParamBound::Positive);

impl Default for InputLimits {
    fn default() -> Self {
        Self {
            position_min_m: POSITION_MIN.default_f64(),
            position_max_m: POSITION_MAX.default_f64(),
            force_max_n: FORCE_MAX.default_f64(),
            measurement_max_m: MEASUREMENT_MAX.default_f64(),
        }
    }
}

impl InputLimits {
    /// The limits of a parameter set (at start-up and for every set on the parameter
    /// services): forces and measurements above 0, positions an interval.
    pub fn from_params(p: &NodeParams) -> Result<Self, ParamError> {
        let d = Self::default();
        let (position_min_m, position_max_m) = p.interval(
            (POSITION_MIN.key, d.position_min_m),
            (POSITION_MAX.key, d.position_max_m),
        )?;
        Ok(Self {
            position_min_m,
            position_max_m,
            force_max_n: FORCE_MAX.f64(p)?,
            measurement_max_m: MEASUREMENT_MAX.f64(p)?,
        })
    }
}

/// Checks every sample and remembers the last accepted stamps and seq.
#[derive(Debug, Clone, Default)]
pub struct Validator {
    limits: InputLimits,
    last_state: Option<(Time, u64)>,
    last_measurement: Option<Time>,
}

impl Validator {
    /// A validator with `limits`.
    pub fn new(limits: InputLimits) -> Self {
        Self {
            limits,
            ..Default::default()
        }
    }

    /// Judges the next samples by `limits` (the order of stamps and seq stays).
    pub fn set_limits(&mut self, limits: InputLimits) {
        self.limits = limits;
    }

    /// Accepts or rejects a drive state; `label` names its source in the reason.
    pub fn state(&mut self, s: &ActuatorState, label: &str) -> Result<(), Reject> {
        let l = &self.limits;
        for i in 0..4 {
            let (q, f) = (s.position[i], s.force[i]);
            // a NaN force is not measured (a cell without force sensing); infinite is wrong
            if !q.is_finite() || f.is_infinite() {
                return Err(reject(
                    RejectKind::NonFinite,
                    format!("{label}: seq {}: q{} = {q}, f{} = {f}", s.seq, i + 1, i + 1),
                ));
            }
            if !(l.position_min_m..=l.position_max_m).contains(&q) {
                return Err(reject(
                    RejectKind::OutOfRange,
                    format!(
                        "{label}: seq {}: q{} = {q} m outside [{}, {}] m",
                        s.seq,
                        i + 1,
                        l.position_min_m,
                        l.position_max_m
                    ),
                ));
            }
            if f.abs() > l.force_max_n {
                return Err(reject(
                    RejectKind::OutOfRange,
                    format!(
                        "{label}: seq {}: |f{}| = {} N above {} N",
                        s.seq,
                        i + 1,
                        f.abs(),
                        l.force_max_n
                    ),
                ));
            }
        }
        if usize::from(s.covariate_count) > s.covariates.len() {
            return Err(reject(
                RejectKind::OutOfRange,
                format!(
                    "{label}: seq {}: covariate_count {} above {}",
                    s.seq,
                    s.covariate_count,
                    s.covariates.len()
                ),
            ));
        }
        // NaN marks a covariate not measured at this pose (campaign_bag); infinities are wrong.
        if let Some(c) = s.covariates().iter().find(|c| c.is_infinite()) {
            return Err(reject(
                RejectKind::NonFinite,
                format!("{label}: seq {}: covariate {c}", s.seq),
            ));
        }
        if let Some((stamp, seq)) = self.last_state {
            if s.stamp < stamp || s.seq <= seq {
                return Err(reject(
                    RejectKind::OutOfOrder,
                    format!(
                        "{label}: seq {} stamp {}.{:09} after seq {seq} stamp {}.{:09}",
                        s.seq, s.stamp.sec, s.stamp.nanosec, stamp.sec, stamp.nanosec
                    ),
                ));
            }
        }
        self.last_state = Some((s.stamp, s.seq));
        Ok(())
    }

    /// Accepts or rejects a measurement.
    pub fn measurement(&mut self, m: &TcpMeasurement, label: &str) -> Result<(), Reject> {
        if m.instrument > TcpMeasurement::NONE {
            return Err(reject(
                RejectKind::OutOfRange,
                format!("{label}: instrument id {} (expected 0..=8)", m.instrument),
            ));
        }
        let values = [
            ("x", m.x, m.x_valid),
            ("y", m.y, m.y_valid),
            ("r", m.r, m.r_valid),
            ("psi", m.psi, m.psi_valid),
            ("sigma", m.sigma, true),
        ];
        for (name, v, valid) in values {
            if valid && !v.is_finite() {
                return Err(reject(
                    RejectKind::NonFinite,
                    format!("{label}: setup {:?}: {name} = {v}", m.setup),
                ));
            }
        }
        for (name, v, valid) in &values[..3] {
            if *valid && v.abs() > self.limits.measurement_max_m {
                return Err(reject(
                    RejectKind::OutOfRange,
                    format!(
                        "{label}: setup {:?}: |{name}| = {} m above {} m",
                        m.setup,
                        v.abs(),
                        self.limits.measurement_max_m
                    ),
                ));
            }
        }
        if m.sigma < 0.0 {
            return Err(reject(
                RejectKind::OutOfRange,
                format!("{label}: setup {:?}: sigma {} < 0", m.setup, m.sigma),
            ));
        }
        if let Some(stamp) = self.last_measurement {
            if m.stamp < stamp {
                return Err(reject(
                    RejectKind::OutOfOrder,
                    format!(
                        "{label}: measurement stamp {}.{:09} before {}.{:09}",
                        m.stamp.sec, m.stamp.nanosec, stamp.sec, stamp.nanosec
                    ),
                ));
            }
        }
        self.last_measurement = Some(m.stamp);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn state(seq: u64, sec: i32) -> ActuatorState {
        ActuatorState {
            seq,
            stamp: Time { sec, nanosec: 0 },
            position: [2.6, 2.6, 0.79, 0.79],
            ..Default::default()
        }
    }

    #[test]
    fn validator_rejects_each_kind() {
        let mut v = Validator::new(InputLimits::default());
        assert_eq!(v.state(&state(1, 10), "t"), Ok(()));
        let mut nan = state(2, 11);
        nan.position[2] = f64::NAN;
        assert_eq!(
            v.state(&nan, "t").map_err(|r| r.kind),
            Err(RejectKind::NonFinite)
        );
        let mut far = state(2, 11);
        far.position[0] = 7.0;
        assert_eq!(
            v.state(&far, "t").map_err(|r| r.kind),
            Err(RejectKind::OutOfRange)
        );
        let mut infinite = state(2, 11);
        infinite.force[1] = f64::INFINITY;
        assert_eq!(
            v.state(&infinite, "t").map_err(|r| r.kind),
            Err(RejectKind::NonFinite)
        );
        let mut force = state(2, 11);
        force.force[3] = -1e6;
        assert_eq!(
            v.state(&force, "t").map_err(|r| r.kind),
            Err(RejectKind::OutOfRange)
        );
        assert_eq!(
            v.state(&state(1, 11), "t").map_err(|r| r.kind),
            Err(RejectKind::OutOfOrder)
        );
        assert_eq!(
            v.state(&state(3, 9), "t").map_err(|r| r.kind),
            Err(RejectKind::OutOfOrder)
        );
        // Rejected samples do not move the order reference.
        assert_eq!(v.state(&state(2, 11), "t"), Ok(()));
        // forces not measured (NaN) are no reason to refuse a state
        let mut unmeasured = state(3, 12);
        unmeasured.force = [f64::NAN; 4];
        assert_eq!(v.state(&unmeasured, "t"), Ok(()));
    }
}
