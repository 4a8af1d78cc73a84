//! The node's parameters: keys, ROS descriptors and the typed settings, the online tracker's
//! among them.

use super::job::CalibratorOptions;
use super::start_covariance::start_covariance;
use crate::node::context::bad_param;
use crate::node::geometry::Geometry;
use crate::node::live::{self, ParamSpec};
use crate::node::online_tracker::OnlineSettings;
use crate::node::params::NodeParams;
use rpkm_core::calib;
use rpkm_core::online::OnlineOptions;

/// Parameter keys of the node.
pub const KEYS: [&str; 20] = [
    "model",
    "geometry_file",
    "effects_file",
    "geometry.",
    "calibrate_every",
    "idle_end_s",
    "validation_prefix",
    "selection",
    "max_condition",
    "outlier_sigma",
    "noise_estimation",
    "state_buffer",
    "online",
    "online_decimation",
    "online_publish_sigma",
    "online_drift_warn_um",
    "online_force_sigma_n",
    "online_encoder_sigma_um",
    "history",
    "history_machine",
];

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
    let selection = p.string("selection", "map").map_err(bad_param)?;
    if !matches!(selection.as_str(), "map" | "auto") {
        return Err(crate::error::bad_input(format!(
            "selection: expected map or auto, found {selection}"
        )));
    }
    let start = Geometry::from_params(p)?;
    Ok(Settings {
        options: CalibratorOptions {
            effects: start.effects.file().cloned(),
            start,
            validation_prefix: p.string("validation_prefix", "val").map_err(bad_param)?,
            selection,
            max_condition: p.positive("max_condition", 100.0).map_err(bad_param)?,
            outlier_sigma: p
                .f64_in(
                    "outlier_sigma",
                    0.0,
                    crate::node::params::OUTLIER_SIGMA,
                    " σ",
                )
                .map_err(bad_param)?,
            noise: rpkm_core::noise::NoiseModel::default(),
            weighting: if p.bool("noise_estimation", true).map_err(bad_param)? {
                calib::Noise::ESTIMATE
            } else {
                calib::Noise::Stated
            },
        },
        every: p
            .u64_in("calibrate_every", 0, crate::node::params::MEASUREMENT_COUNT)
            .map_err(bad_param)?,
        idle_end: p
            .f64_in("idle_end_s", 0.0, crate::node::params::DURATION_S, " s")
            .map_err(bad_param)?,
    })
}

/// The calibrator's parameters on its ROS 2 parameter services: what the next calibration
/// uses and when a campaign ends are live; the buffer and the online tracker need a restart.
pub(super) fn specs() -> Vec<ParamSpec> {
    use live::Default::{Bool, Str, F64, U64};
    use rpkm_transport::dds_params::ParamRange;
    let int = ParamRange::count;
    let float = |(lo, hi): (f64, f64)| ParamRange::Float(lo, hi);
    let fixed_in = |key, default, description, range| ParamSpec {
        range,
        ..ParamSpec::fixed(key, default, description)
    };
    let [model, _, geometry_file, _, _] = crate::node::geometry::geometry_specs();
    vec![
        ParamSpec {
            description: "model of the next calibration: 24 or 29 parameters",
            ..model
        },
        geometry_file,
        ParamSpec::fixed(
            "effects_file",
            Str(""),
            "effects written as data (YAML, docs/effects.md) calibrated with the geometry",
        ),
        ParamSpec::live(
            "calibrate_every",
            U64(0),
            "calibrate after N measurements, 0 for at the end marker only",
            int(crate::node::params::MEASUREMENT_COUNT),
        ),
        ParamSpec::live(
            "idle_end_s",
            F64(0.0),
            "end a campaign after this long without a measurement, s (0: never)",
            float(crate::node::params::DURATION_S),
        ),
        ParamSpec::live(
            "validation_prefix",
            Str("val"),
            "setups whose name starts with this are held out for validation",
            ParamRange::None,
        ),
        ParamSpec::live(
            "selection",
            Str("map"),
            "map (every parameter under its tolerance) or auto (the thesis's selection)",
            ParamRange::None,
        ),
        ParamSpec::live(
            "max_condition",
            F64(100.0),
            "condition-number limit of selection auto (> 0)",
            ParamRange::None,
        ),
        ParamSpec::live(
            "outlier_sigma",
            F64(0.0),
            "outlier threshold, sigma (0: keep all)",
            float(crate::node::params::OUTLIER_SIGMA),
        ),
        ParamSpec::live(
            "noise_estimation",
            Bool(true),
            "weight the rows by the noise the campaign shows (false: the stated noise)",
            ParamRange::None,
        ),
        fixed_in(
            "state_buffer",
            U64(4096),
            "drive states kept for pairing with measurements",
            int(crate::node::params::BUFFER_LEN),
        ),
    ]
    .into_iter()
    .chain(online_specs())
    .chain(history_specs())
    .collect()
}

/// The machine's history (read at start: the store is opened once).
fn history_specs() -> Vec<ParamSpec> {
    use live::Default::Str;
    vec![
        ParamSpec::fixed(
            "history",
            Str(""),
            "record each calibration and online step here: an SQLite file or a postgres:// URL",
        ),
        ParamSpec::fixed(
            "history_machine",
            Str(""),
            "the machine's name in the history (default: the node's namespace, rpkm without)",
        ),
    ]
}

/// The online tracker's parameters (read at start: the tracker's thread is set up once).
fn online_specs() -> Vec<ParamSpec> {
    use live::Default::{Bool, F64, U64};
    use rpkm_transport::dds_params::ParamRange;
    // the tracker's noise levels default to the core's (the calibration's stated ones)
    let tracker = OnlineOptions::default();
    let fixed_in = |key, default, description, range| ParamSpec {
        range,
        ..ParamSpec::fixed(key, default, description)
    };
    vec![
        ParamSpec::fixed(
            "online",
            Bool(false),
            "track the geometry live from the drive forces",
        ),
        fixed_in(
            "online_decimation",
            U64(100),
            "online tracker: every N-th drive state",
            ParamRange::count((1, 1_000_000)),
        ),
        ParamSpec::fixed(
            "online_publish_sigma",
            F64(1.0),
            "online tracker: publish when a parameter moved by this many sigma (> 0)",
        ),
        fixed_in(
            "online_drift_warn_um",
            F64(10.0),
            "online tracker: WARN from this drift, um",
            ParamRange::Float(0.1, 10_000.0),
        ),
        ParamSpec::fixed(
            "online_force_sigma_n",
            F64(tracker.force_sigma_n),
            "online tracker: drive force noise, N (> 0)",
        ),
        fixed_in(
            "online_encoder_sigma_um",
            F64(tracker.encoder_sigma_mm * 1000.0),
            "online tracker: drive encoder noise, um (the forces move by the rods' stiffness)",
            ParamRange::Float(0.0, 100.0),
        ),
    ]
}

/// The online tracker's settings from the parameters, if `online` is on.
pub(super) fn online_settings(p: &NodeParams) -> anyhow::Result<Option<OnlineSettings>> {
    if !p.bool("online", false).map_err(bad_param)? {
        return Ok(None);
    }
    let tracker = OnlineOptions::default();
    Ok(Some(OnlineSettings {
        start_cov: start_covariance(&p.string("geometry_file", "").map_err(bad_param)?)?,
        decimation: p
            .u64_in("online_decimation", 100, (1, 1_000_000))
            .map_err(bad_param)?,
        publish_sigma: p.positive("online_publish_sigma", 1.0).map_err(bad_param)?,
        drift_warn_mm: p
            .f64_in("online_drift_warn_um", 10.0, (0.1, 10_000.0), " µm")
            .map_err(bad_param)?
            / 1000.0,
        options: OnlineOptions {
            force_sigma_n: p
                .positive("online_force_sigma_n", tracker.force_sigma_n)
                .map_err(bad_param)?,
            encoder_sigma_mm: p
                .f64_in(
                    "online_encoder_sigma_um",
                    tracker.encoder_sigma_mm * 1000.0,
                    (0.0, 100.0),
                    " µm",
                )
                .map_err(bad_param)?
                / 1000.0,
            ..tracker
        },
    }))
}
