//! The calibration file: the JSON `rpkm calibrate --json` and the calibrator node's `save`
//! write, and the parameter files, the tracker's start covariance and the node's effects read.
//! One type, so that a field the writer renames is a field every reader loses at compile time.

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};

use rpkm_core::calib;

use crate::error::bad_input;

/// A calibration as its file holds it. The fields our readers use are typed; the rest of the
/// report (fit statistics, noise, held-out check, ...) is read by people and other tools and
/// travels as written in `report`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CalibrationFile {
    /// Spec names to values (mm, rad).
    pub parameters: BTreeMap<String, f64>,
    /// The posterior with its correlations (absent in a hand-written file).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub covariance: Option<PosteriorCovariance>,
    /// The identified parameters with their σ: the start covariance of a file without
    /// `covariance` (written before it was).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub identified: Option<Vec<IdentifiedEntry>>,
    /// The effects' parameters, each value in its parameter's unit (absent: none).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub effects: Vec<EffectValue>,
    /// The effects file as the calibration read it: what the values in `effects` mean.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub effects_file: Option<RecordedEffects>,
    /// Everything else the writer reports, as written.
    #[serde(flatten)]
    pub report: Map<String, Value>,
}

/// The `covariance` object: rows and columns in `names` order, mm and rad.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PosteriorCovariance {
    pub names: Vec<String>,
    pub matrix: Vec<Vec<f64>>,
}

/// One `identified` entry: the parameter's index in the spec's order and its σ; the rest
/// (name, nominal, value, step) as written.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct IdentifiedEntry {
    pub index: usize,
    /// None where the calibration wrote no finite σ (`null`).
    pub sigma: Option<f64>,
    #[serde(flatten)]
    pub rest: Map<String, Value>,
}

/// One effect parameter's value: `effect`, `name`, `value` in `unit`; the calibration's σ,
/// observability and the like as written.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EffectValue {
    pub effect: String,
    pub name: String,
    pub unit: String,
    pub value: f64,
    #[serde(flatten)]
    pub rest: Map<String, Value>,
}

/// The recorded effects file: each effect's `name` and `expressions` (target to text).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RecordedEffects {
    #[serde(default)]
    pub effects: Vec<RecordedEffect>,
    #[serde(flatten)]
    pub rest: Map<String, Value>,
}

/// One effect as the calibration read it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RecordedEffect {
    pub name: String,
    #[serde(default)]
    pub expressions: BTreeMap<String, String>,
    #[serde(flatten)]
    pub rest: Map<String, Value>,
}

impl IdentifiedEntry {
    /// The entry of an identified parameter, as `rpkm calibrate --json` writes it.
    pub fn of(p: &calib::Identified) -> anyhow::Result<Self> {
        Ok(IdentifiedEntry {
            index: p.index,
            sigma: Some(p.sigma).filter(|s| s.is_finite()),
            rest: rest_of(p, &["index", "sigma"])?,
        })
    }
}

impl EffectValue {
    /// The entry of an effect parameter, as `rpkm calibrate --json` writes it.
    pub fn of(e: &calib::EffectEstimate) -> anyhow::Result<Self> {
        Ok(EffectValue {
            effect: e.effect.clone(),
            name: e.name.clone(),
            unit: e.unit.clone(),
            value: e.value,
            rest: rest_of(e, &["effect", "name", "unit", "value"])?,
        })
    }
}

/// The fields of `v` as JSON but for the `typed` ones.
fn rest_of(v: &impl Serialize, typed: &[&str]) -> anyhow::Result<Map<String, Value>> {
    let Value::Object(mut map) = serde_json::to_value(v)? else {
        anyhow::bail!("not a JSON object");
    };
    map.retain(|k, _| !typed.contains(&k.as_str()));
    Ok(map)
}

impl CalibrationFile {
    /// The file as JSON with its keys in the order every calibration file has had them
    /// (serde_json's object, sorted by name), not the struct's.
    pub fn to_value(&self) -> anyhow::Result<Value> {
        Ok(serde_json::to_value(self)?)
    }

    /// Reads `path`; every mistake is bad input naming the file, and the field where there
    /// is one. A file without `parameters` is a hand-written parameter file: the whole
    /// object maps spec names to values.
    pub fn read(path: &Path) -> anyhow::Result<Self> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| bad_input(format!("{}: cannot read parameters: {e}", path.display())))?;
        let value: Value = serde_json::from_str(&text).map_err(|e| {
            bad_input(format!(
                "{}:{}:{}: not JSON: {e}",
                path.display(),
                e.line(),
                e.column()
            ))
        })?;
        Self::of_value(path, value)
    }

    /// The file of the JSON `value` read from `path` ([`CalibrationFile::read`]).
    pub fn of_value(path: &Path, value: Value) -> anyhow::Result<Self> {
        let Value::Object(mut obj) = value else {
            return Err(bad_input(format!(
                "{}: expected a JSON object of parameter names to values",
                path.display()
            )));
        };
        let file = path.display();
        let Some(parameters) = obj.remove("parameters") else {
            return Ok(CalibrationFile {
                parameters: parameters_of(path, obj)?,
                ..CalibrationFile::default()
            });
        };
        let Value::Object(parameters) = parameters else {
            return Err(bad_input(format!(
                "{file}: `parameters`: expected a JSON object of parameter names to values"
            )));
        };
        Ok(CalibrationFile {
            parameters: parameters_of(path, parameters)?,
            covariance: field(path, &mut obj, "covariance")?,
            identified: field(path, &mut obj, "identified")?,
            effects: field(path, &mut obj, "effects")?.unwrap_or_default(),
            effects_file: field(path, &mut obj, "effects_file")?,
            report: obj,
        })
    }
}

/// Field `key` of `obj`, typed; a wrong shape is bad input naming the file and the field.
fn field<T: serde::de::DeserializeOwned>(
    path: &Path,
    obj: &mut Map<String, Value>,
    key: &str,
) -> anyhow::Result<Option<T>> {
    obj.remove(key)
        .map(|v| {
            serde_json::from_value(v)
                .map_err(|e| bad_input(format!("{}: `{key}`: {e}", path.display())))
        })
        .transpose()
}

/// Each parameter's value: a finite number, else bad input naming the parameter.
fn parameters_of(path: &Path, obj: Map<String, Value>) -> anyhow::Result<BTreeMap<String, f64>> {
    obj.into_iter()
        .map(|(name, v)| match v.as_f64().filter(|x| x.is_finite()) {
            Some(x) => Ok((name, x)),
            None => Err(bad_input(format!(
                "{}: parameter `{name}`: expected a finite number, found {v}",
                path.display()
            ))),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read(text: &str) -> anyhow::Result<CalibrationFile> {
        CalibrationFile::of_value(Path::new("cal.json"), serde_json::from_str(text)?)
    }

    #[test]
    fn a_written_file_reads_back_to_the_same_text() -> anyhow::Result<()> {
        let text = r#"{"chi2_per_dof":1.25,"covariance":{"matrix":[[1e-6,0.0],[0.0,2.5e-7]],"names":["l1","l4"]},"effects":[{"effect":"warm_q4","identified":true,"name":"a","sigma":null,"unit":"mm","value":0.001}],"effects_file":{"effects":[{"expressions":{"dq4":"a * t"},"name":"warm_q4","summary":"s"}],"file":"e.yaml"},"identified":[{"index":0,"name":"l1","sigma":0.001,"step":1}],"model":29,"parameters":{"l1":100.25,"l4":-0.5}}"#;
        let file = read(text)?;
        assert_eq!(file.parameters.get("l1"), Some(&100.25));
        assert_eq!(file.effects.first().map(|e| e.value), Some(0.001));
        assert_eq!(
            file.identified.as_ref().and_then(|i| i[0].sigma),
            Some(0.001)
        );
        assert_eq!(
            file.effects_file
                .as_ref()
                .map(|f| f.effects[0].expressions["dq4"].as_str()),
            Some("a * t")
        );
        assert_eq!(file.to_value()?.to_string(), text);
        Ok(())
    }

    #[test]
    fn a_bare_object_of_names_is_a_parameter_file() -> anyhow::Result<()> {
        let file = read(r#"{"l1": 100.5}"#)?;
        assert_eq!(file.parameters.get("l1"), Some(&100.5));
        assert!(file.covariance.is_none() && file.effects.is_empty());
        Ok(())
    }

    #[test]
    fn a_field_of_the_wrong_shape_is_named_with_the_file() {
        for (text, says) in [
            (
                r#"{"parameters": {"l1": "x"}}"#,
                "cal.json: parameter `l1`: expected a finite number, found \"x\"",
            ),
            (
                r#"{"parameters": [1]}"#,
                "cal.json: `parameters`: expected a JSON object",
            ),
            (
                r#"{"parameters": {}, "covariance": {"names": []}}"#,
                "cal.json: `covariance`: missing field `matrix`",
            ),
            (
                r#"{"parameters": {}, "effects": [{"effect": "e", "name": "a", "unit": "mm"}]}"#,
                "cal.json: `effects`: missing field `value`",
            ),
            (
                r#"{"parameters": {}, "effects": {}}"#,
                "cal.json: `effects`: invalid type: map",
            ),
            ("[1]", "cal.json: expected a JSON object"),
        ] {
            let err = read(text).map(|_| ()).expect_err(text).to_string();
            assert!(err.starts_with(says), "{text}: {err}");
        }
    }
}
