//! The node's parameters: keys, ROS descriptors and the typed settings, the online tracker's
//! among them.

use super::job::{CalibratorOptions, SelectionRule};
use super::start_covariance::start_covariance;
use crate::node::context::bad_param;
use crate::node::declare::{keys, ParamBound, ParamDefault, ParamSpec};
use crate::node::geometry::{self, Geometry};
use crate::node::online_tracker::OnlineSettings;
use crate::node::params::{self, NodeParams, BUFFER_LEN, DURATION_S, MEASUREMENT_COUNT};
use crate::units::mm_from_um;
use rpkm_core::calib;
use rpkm_core::online::OnlineOptions;

const MODEL: ParamSpec = ParamSpec {
    description: "model of the next calibration: 24 or 29 parameters",
    ..geometry::MODEL
};
const EFFECTS_FILE: ParamSpec = ParamSpec {
    description: "effects written as data (YAML, docs/effects.md) calibrated with the geometry",
    ..geometry::EFFECTS_FILE
};
const CALIBRATE_EVERY: ParamSpec = ParamSpec::live(
    "calibrate_every",
    ParamDefault::U64(0),
    "calibrate after N measurements, 0 for at the end marker only",
)
.bound(ParamBound::Count(MEASUREMENT_COUNT.0, MEASUREMENT_COUNT.1));
const IDLE_END: ParamSpec = ParamSpec::live(
    "idle_end_s",
    ParamDefault::F64(0.0),
    "end a campaign after this long without a measurement (0: never)",
)
.unit("s")
.bound(ParamBound::Within(DURATION_S.0, DURATION_S.1));
const VALIDATION_PREFIX: ParamSpec = ParamSpec::live(
    "validation_prefix",
    ParamDefault::Str("val"),
    "setups whose name starts with this are held out for validation",
);
const SELECTION: ParamSpec = ParamSpec::live(
    "selection",
    ParamDefault::Str("map"),
    "map (every parameter under its tolerance) or auto (the thesis's selection)",
);
const MAX_CONDITION: ParamSpec = ParamSpec::live(
    "max_condition",
    ParamDefault::F64(100.0),
    "condition-number limit of selection auto",
)
.bound(ParamBound::Positive);
const OUTLIER_SIGMA: ParamSpec = ParamSpec::live(
    "outlier_sigma",
    ParamDefault::F64(0.0),
    "outlier threshold (0: keep all)",
)
.unit("σ")
.bound(ParamBound::Within(
    params::OUTLIER_SIGMA.0,
    params::OUTLIER_SIGMA.1,
));
const NOISE_ESTIMATION: ParamSpec = ParamSpec::live(
    "noise_estimation",
    ParamDefault::Bool(true),
    "weight the rows by the noise the campaign shows (false: the stated noise)",
);
/// Bounded before the ring is preallocated from it (4294967296 asked for 650 GB).
pub(super) const STATE_BUFFER: ParamSpec = ParamSpec::fixed(
    "state_buffer",
    ParamDefault::U64(4096),
    "drive states kept for pairing with measurements",
)
.bound(ParamBound::Count(BUFFER_LEN.0, BUFFER_LEN.1));

// The online tracker's (read at start: the tracker's thread is set up once); its noise
// levels are the core's defaults (the calibration's stated ones: a test holds them equal).
const ONLINE: ParamSpec = ParamSpec::fixed(
    "online",
    ParamDefault::Bool(false),
    "track the geometry live from the drive forces",
);
const ONLINE_DECIMATION: ParamSpec = ParamSpec::fixed(
    "online_decimation",
    ParamDefault::U64(100),
    "online tracker: every N-th drive state",
)
.bound(ParamBound::Count(1, 1_000_000));
const ONLINE_PUBLISH_SIGMA: ParamSpec = ParamSpec::fixed(
    "online_publish_sigma",
    ParamDefault::F64(1.0),
    "online tracker: publish when a parameter moved by this many sigma",
)
.bound(ParamBound::Positive);
const ONLINE_DRIFT_WARN: ParamSpec = ParamSpec::fixed(
    "online_drift_warn_um",
    ParamDefault::F64(10.0),
    "online tracker: WARN from this drift",
)
.unit("µm")
.bound(ParamBound::Within(0.1, 10_000.0));
pub(super) const ONLINE_FORCE_SIGMA: ParamSpec = ParamSpec::fixed(
    "online_force_sigma_n",
    ParamDefault::F64(5.0),
    "online tracker: drive force noise",
)
.unit("N")
.bound(ParamBound::Positive);
pub(super) const ONLINE_ENCODER_SIGMA: ParamSpec = ParamSpec::fixed(
    "online_encoder_sigma_um",
    ParamDefault::F64(0.2),
    "online tracker: drive encoder noise (the forces move by the rods' stiffness)",
)
.unit("µm")
.bound(ParamBound::Within(0.0, 100.0));

// The machine's history (read at start: the store is opened once).
pub(super) const HISTORY: ParamSpec = ParamSpec::fixed(
    "history",
    ParamDefault::Str(""),
    "record each calibration and online step here: an SQLite file or a postgres:// URL",
);
pub(super) const HISTORY_MACHINE: ParamSpec = ParamSpec::fixed(
    "history_machine",
    ParamDefault::Str(""),
    "the machine's name in the history (default: the node's namespace, rpkm without)",
);
pub(super) const HISTORY_SPOOL: ParamSpec = ParamSpec::fixed(
    "history_spool",
    ParamDefault::Str(""),
    "where records wait while a PostgreSQL history is away (default: \
     $XDG_STATE_HOME/rpkm, else ~/.local/state/rpkm, history-spool-MACHINE.db)",
);
pub(super) const HISTORY_SPOOL_MAX: ParamSpec = ParamSpec::fixed(
    "history_spool_max",
    ParamDefault::U64(10_000),
    "records that may wait in the spool; beyond, a record is not recorded and said so",
)
.bound(ParamBound::Count(1, 1_000_000));
pub(super) const HISTORY_RETRY: ParamSpec = ParamSpec::fixed(
    "history_retry_s",
    ParamDefault::F64(1.0),
    "first wait before a PostgreSQL history away is tried again, doubling to 60 s",
)
.unit("s")
.bound(ParamBound::Within(0.01, 60.0));

/// The node's parameters: what the next calibration uses and when a campaign ends are live;
/// the buffer, the online tracker and the history need a restart. Of the geometry it takes
/// the model, the files and the overrides (no stiffness, no follower).
pub const PARAMS: [ParamSpec; 23] = [
    MODEL,
    geometry::GEOMETRY_FILE,
    EFFECTS_FILE,
    geometry::GEOMETRY_OVERRIDES,
    CALIBRATE_EVERY,
    IDLE_END,
    VALIDATION_PREFIX,
    SELECTION,
    MAX_CONDITION,
    OUTLIER_SIGMA,
    NOISE_ESTIMATION,
    STATE_BUFFER,
    ONLINE,
    ONLINE_DECIMATION,
    ONLINE_PUBLISH_SIGMA,
    ONLINE_DRIFT_WARN,
    ONLINE_FORCE_SIGMA,
    ONLINE_ENCODER_SIGMA,
    HISTORY,
    HISTORY_MACHINE,
    HISTORY_SPOOL,
    HISTORY_SPOOL_MAX,
    HISTORY_RETRY,
];

/// Every parameter key the node declares besides the common ones.
pub fn declared() -> Vec<&'static str> {
    keys(&[&PARAMS])
}

/// Every parameter the node declares besides the common ones.
pub fn declarations() -> Vec<ParamSpec> {
    PARAMS.to_vec()
}

/// What a parameter set changes while the node runs: the options of the next calibration
/// (start geometry, selection, outliers, held-out prefix) and when a campaign ends.
pub(super) struct Settings {
    pub(super) options: CalibratorOptions,
    pub(super) every: u64,
    pub(super) idle_end: f64,
}

/// The calibrator's settings of a parameter set (at start-up and for every set on the
/// parameter services, by the same bounded readers).
pub(super) fn configure(p: &NodeParams) -> anyhow::Result<Settings> {
    let text = SELECTION.string(p).map_err(bad_param)?;
    let selection = SelectionRule::parse(&text).ok_or_else(|| {
        crate::error::bad_input(format!("selection: expected map or auto, found {text}"))
    })?;
    let start = Geometry::from_params(p)?;
    Ok(Settings {
        options: CalibratorOptions {
            effects: start.effects.file().cloned(),
            start,
            validation_prefix: VALIDATION_PREFIX.string(p).map_err(bad_param)?,
            selection,
            max_condition: MAX_CONDITION.f64(p).map_err(bad_param)?,
            outlier_sigma: OUTLIER_SIGMA.f64(p).map_err(bad_param)?,
            noise: rpkm_core::noise::NoiseModel::default(),
            weighting: if NOISE_ESTIMATION.bool(p).map_err(bad_param)? {
                calib::Noise::ESTIMATE
            } else {
                calib::Noise::Stated
            },
        },
        every: CALIBRATE_EVERY.u64(p).map_err(bad_param)?,
        idle_end: IDLE_END.f64(p).map_err(bad_param)?,
    })
}

/// The online tracker's settings from the parameters, if `online` is on.
pub(super) fn online_settings(p: &NodeParams) -> anyhow::Result<Option<OnlineSettings>> {
    if !ONLINE.bool(p).map_err(bad_param)? {
        return Ok(None);
    }
    Ok(Some(OnlineSettings {
        start_cov: start_covariance(&geometry::GEOMETRY_FILE.string(p).map_err(bad_param)?)?,
        decimation: ONLINE_DECIMATION.u64(p).map_err(bad_param)?,
        publish_sigma: ONLINE_PUBLISH_SIGMA.f64(p).map_err(bad_param)?,
        drift_warn_mm: mm_from_um(ONLINE_DRIFT_WARN.f64(p).map_err(bad_param)?),
        options: OnlineOptions {
            force_sigma_n: ONLINE_FORCE_SIGMA.f64(p).map_err(bad_param)?,
            encoder_sigma_mm: mm_from_um(ONLINE_ENCODER_SIGMA.f64(p).map_err(bad_param)?),
            ..OnlineOptions::default()
        },
    }))
}
