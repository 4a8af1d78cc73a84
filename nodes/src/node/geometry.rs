//! The model a node evaluates (`Geometry`: parameters, model, stiffness, calibrated effects),
//! its parameter keys and its Parameters message.

use std::fmt::Write as _;

use super::context::bad_param;
use super::declare::{ParamBound, ParamDefault, ParamSpec};
use super::effects;
use super::params::NodeParams;
use crate::units::MM_PER_M;
use rpkm_core::elastic::Stiffness;
use rpkm_core::params::{self as core_params, Model, Params, NAMES};
use rpkm_msgs::Parameters;

/// Parameter `model`.
pub const MODEL: ParamSpec = ParamSpec::live(
    "model",
    ParamDefault::U64(29),
    "geometric model: 24 or 29 parameters",
)
.bound(ParamBound::Count(24, 29));
/// Parameter `stiffness_factor`.
pub const STIFFNESS_FACTOR: ParamSpec = ParamSpec::live(
    "stiffness_factor",
    ParamDefault::F64(1.0),
    "scale of the spring model's stiffnesses",
)
.bound(ParamBound::Positive);
/// Parameter `geometry_file`.
pub const GEOMETRY_FILE: ParamSpec = ParamSpec::fixed(
    "geometry_file",
    ParamDefault::Str(""),
    "JSON of parameter name -> value (mm, rad) as rpkm calibrate --json writes",
);
/// Parameter `effects_file`.
pub const EFFECTS_FILE: ParamSpec = ParamSpec::fixed(
    "effects_file",
    ParamDefault::Str(""),
    "effects written as data (YAML, docs/effects.md) whose calibrated values apply",
);
/// Parameter group `geometry.`: single parameters in SI (m, rad), after `geometry_file`.
pub const GEOMETRY_OVERRIDES: ParamSpec = ParamSpec::group(
    "geometry.",
    "single geometric parameters in SI (m, rad), applied after geometry_file",
);
/// Parameter `follow_parameters`.
pub const FOLLOW_PARAMETERS: ParamSpec = ParamSpec::fixed(
    "follow_parameters",
    ParamDefault::Bool(true),
    "replace the geometry by every /rpkm/parameters message",
);

/// The parameters of the nodes that evaluate the model ([`Geometry::from_params`]): model and
/// stiffness live (the next sample uses them), the files and following need a restart.
pub const GEOMETRY: [ParamSpec; 6] = [
    MODEL,
    STIFFNESS_FACTOR,
    GEOMETRY_FILE,
    EFFECTS_FILE,
    GEOMETRY_OVERRIDES,
    FOLLOW_PARAMETERS,
];

/// Whether a parameter key changes the model ([`Geometry::from_params`]).
pub fn is_geometry_key(key: &str) -> bool {
    GEOMETRY
        .iter()
        .any(|g| g.key == key || (g.key.ends_with('.') && key.starts_with(g.key)))
}

/// The model a node evaluates: parameters (mm, rad), model, stiffness.
#[derive(Debug, Clone, PartialEq)]
pub struct Geometry {
    /// The 29 parameters, mm and rad.
    pub params: Params,
    /// Model 24 or 29.
    pub model: Model,
    /// Stiffness of the spring model.
    pub stiffness: Stiffness,
    /// Where the parameters came from, for messages.
    pub source: String,
    /// The calibrated effects applied at each state, and those the node knows
    /// (`effects_file`).
    pub effects: effects::NodeEffects,
}

/// A Parameters message that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum ParametersMsgError {
    #[error("/rpkm/parameters: model {0} is not 24 or 29")]
    Model(u8),
    #[error("/rpkm/parameters: {names} names but {values} values")]
    Lengths { names: usize, values: usize },
    #[error("/rpkm/parameters: unknown parameter name {0:?}")]
    Name(String),
    #[error("/rpkm/parameters: parameter {name}: {value} is not finite")]
    NonFinite { name: String, value: f64 },
    #[error("/rpkm/parameters: {0}")]
    Effects(#[from] effects::EffectsError),
}

/// Length parameters: mm in the core, m on topics and in YAML.
fn si_factor(i: usize) -> f64 {
    match core_params::unit(i) {
        core_params::Unit::Mm => MM_PER_M,
        core_params::Unit::Rad => 1.0,
    }
}

impl Geometry {
    /// From the node parameters: `geometry_file` (JSON of name -> value in mm/rad, as
    /// `rpkm calibrate --json` writes), then `geometry.<name>` overrides in SI (m, rad),
    /// `model` (24|29), `stiffness_factor`.
    pub fn from_params(p: &NodeParams) -> anyhow::Result<Self> {
        // the check below says "24 or 29", not a range
        let model_n = MODEL.bound(ParamBound::Any).u64(p).map_err(bad_param)?;
        // try_from, not `as`: 4294967320 must not wrap around to model 24.
        let model = u32::try_from(model_n)
            .ok()
            .and_then(Model::from_number)
            .ok_or_else(|| {
                crate::error::bad_input(format!(
                    "{}/model: expected 24 or 29, found {model_n}",
                    p.origin("model")
                        .map(std::string::ToString::to_string)
                        .unwrap_or_default()
                ))
            })?;
        let factor = STIFFNESS_FACTOR.f64(p).map_err(bad_param)?;
        let file = GEOMETRY_FILE.string(p).map_err(bad_param)?;
        let known = effects::NodeEffects::from_params(p)?;
        let (mut params, mut source, effects) = if file.is_empty() {
            (Params::nominal(), "nominal parameters".to_owned(), known)
        } else {
            let path = std::path::Path::new(&file);
            let doc = crate::calibration_file::CalibrationFile::read(path)?;
            (
                crate::input::params_of(path, &doc)?,
                file.clone(),
                known.read_calibration(path, &doc)?,
            )
        };
        let overrides = p.group(GEOMETRY_OVERRIDES.key).map_err(bad_param)?;
        for (name, value, origin) in &overrides {
            let i = core_params::index_of(name).ok_or_else(|| {
                crate::error::bad_input(format!(
                    "{origin}/geometry.{name}: unknown parameter (expected one of {})",
                    NAMES.join(", ")
                ))
            })?;
            params[i] = value * si_factor(i);
        }
        if !overrides.is_empty() {
            let _ = write!(source, " with {} YAML overrides", overrides.len());
        }
        if model == Model::M24 {
            params = params.with_perfect_parallelogram();
        }
        source.push_str(&effects.describe());
        Ok(Self {
            params,
            model,
            stiffness: Stiffness::default().scaled(factor),
            source,
            effects,
        })
    }

    /// From a Parameters message (SI); parameters it does not name stay as in `self`.
    pub fn updated(&self, msg: &Parameters) -> Result<Self, ParametersMsgError> {
        let model =
            Model::from_number(u32::from(msg.model)).ok_or(ParametersMsgError::Model(msg.model))?;
        if msg.names.len() != msg.values.len() {
            return Err(ParametersMsgError::Lengths {
                names: msg.names.len(),
                values: msg.values.len(),
            });
        }
        let mut params = self.params;
        for (name, &value) in msg.names.iter().zip(&msg.values) {
            let i = core_params::index_of(name)
                .ok_or_else(|| ParametersMsgError::Name(name.clone()))?;
            if !value.is_finite() {
                return Err(ParametersMsgError::NonFinite {
                    name: name.clone(),
                    value,
                });
            }
            params[i] = value * si_factor(i);
        }
        if model == Model::M24 {
            params = params.with_perfect_parallelogram();
        }
        let effects = self.effects.of_message(msg)?;
        Ok(Self {
            params,
            model,
            stiffness: self.stiffness,
            source: format!(
                "/rpkm/parameters (model {}, {} measurements){}",
                model.number(),
                msg.measurement_count,
                effects.describe()
            ),
            effects,
        })
    }
}

/// A Parameters message of `p` (the model's parameters, SI), with `sigmas` in mm/rad by index
/// (0 for parameters not identified).
///
/// # Panics
/// Never: a model number (24 or 29) fits a byte.
pub fn parameters_msg(
    p: &Params,
    model: Model,
    sigmas: &[f64; core_params::N_PARAMS],
) -> Parameters {
    let ids = model.params();
    Parameters {
        model: u8::try_from(model.number()).expect("model number is 24 or 29"),
        names: ids.iter().map(|&i| NAMES[i].to_owned()).collect(),
        values: ids.iter().map(|&i| p[i] / si_factor(i)).collect(),
        sigmas: ids.iter().map(|&i| sigmas[i] / si_factor(i)).collect(),
        ..Default::default()
    }
}
