//! The calibrated effects a node applies to its drive states (the TCP estimator and the
//! preload monitor evaluate the model at each state's carriers and parameters under them).
//!
//! Written effects only (docs/effects.md). Their expressions come from one place, the
//! node's `effects_file`: the file the calibrator fitted them with (a launch sets it once for
//! every node). Their values come with the geometry: a Parameters message (`active_effects`,
//! `effect_parameter_names` `EFFECT.PARAMETER`, values in SI by
//! [`crate::effects_file::si_per_unit`]) or a calibration JSON (`effects`, each value in its
//! parameter's unit, as `rpkm calibrate --json` and `save_calibration` write it).
//!
//! Nothing is applied in part: an effect the node's file does not have, a parameter it does
//! not declare or leaves without a value, and a calibration JSON whose recorded expressions
//! (`effects_file`) differ from the node's are refused with the effect named. The library's
//! effects are bound to campaigns, not to a drive state; a geometry that carries them says
//! in its source that they are not applied live.

use std::fmt::Write as _;
use std::path::Path;
use std::sync::Arc;

use rpkm_core::effects::{self, LiveEffects, LiveError, LiveState, Written};
use rpkm_core::params::Params;
use rpkm_msgs::Parameters;

use crate::calibration_file::{CalibrationFile, RecordedEffects};
use crate::effects_file::{si_per_unit, EffectsFile};

/// Why calibrated effects cannot be applied.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EffectsError {
    #[error("effect `{effect}` is not in the node's effects_file {file} (it has {known})")]
    NotInFile {
        effect: String,
        file: String,
        known: String,
    },
    #[error(
        "effect `{effect}` is not the library's and the node has no effects_file: set \
         `effects_file` to the file it was calibrated with"
    )]
    NoFile { effect: String },
    #[error("`{name}`: expected EFFECT.PARAMETER of an effect in active_effects")]
    Name { name: String },
    #[error("effect `{effect}` has no parameter `{param}` (it has {known})")]
    Param {
        effect: String,
        param: String,
        known: String,
    },
    #[error("effect `{effect}`: no value for its parameter `{param}`")]
    Missing { effect: String, param: String },
    #[error("effect `{effect}`: parameter `{param}` = {value} is not finite")]
    NonFinite {
        effect: String,
        param: String,
        value: f64,
    },
    #[error("effect `{effect}`: parameter `{param}` in {found}, the effects_file says {unit}")]
    Unit {
        effect: String,
        param: String,
        found: String,
        unit: String,
    },
    #[error(
        "effect `{effect}` was calibrated with {target} = {calibrated:?}, the node's \
         effects_file {file} says {node:?}"
    )]
    Expression {
        effect: String,
        target: String,
        calibrated: String,
        node: String,
        file: String,
    },
    #[error("{names} effect parameter names but {values} values")]
    Lengths { names: usize, values: usize },
    #[error(transparent)]
    Live(#[from] LiveError),
}

/// The effects a node knows (its `effects_file`) and those it applies, with their values.
#[derive(Debug, Clone, Default)]
pub struct NodeEffects {
    file: Option<Arc<EffectsFile>>,
    live: LiveEffects,
    /// The library's effects of the calibration (not applied live).
    not_applied: Vec<String>,
}

impl PartialEq for NodeEffects {
    fn eq(&self, other: &Self) -> bool {
        let file = |e: &NodeEffects| e.file.as_ref().map(|f| f.file.clone());
        file(self) == file(other)
            && self.live.values().eq(other.live.values())
            && self.not_applied == other.not_applied
    }
}

/// Values of one effect by parameter name, in the spec's units.
type Values = Vec<(String, f64)>;

impl NodeEffects {
    /// The effects of `file` (none applied yet).
    pub fn known(file: Option<EffectsFile>) -> NodeEffects {
        NodeEffects {
            file: file.map(Arc::new),
            ..NodeEffects::default()
        }
    }

    /// The node's effects file.
    pub fn file(&self) -> Option<&Arc<EffectsFile>> {
        self.file.as_ref()
    }

    /// Whether no effect is applied.
    pub fn is_empty(&self) -> bool {
        self.live.is_empty()
    }

    /// The first effect that reads a drive force `f` does not have (NaN: not measured), and
    /// the drive 0..=3.
    pub fn unmeasured_force(&self, f: &[f64; 4]) -> Option<(&str, usize)> {
        self.live.unmeasured_force(f)
    }

    /// The parameters and carrier positions (mm) the model is evaluated at for state `s`.
    pub fn apply(&mut self, p: &Params, s: &LiveState) -> (Params, [f64; 4]) {
        self.live.apply(p, s)
    }

    /// The same known effects applying `values` (effect, parameter values by name in the
    /// spec's units); the library's effect names are kept as not applied.
    fn applying(&self, values: Vec<(String, Values)>) -> Result<NodeEffects, EffectsError> {
        let library = effects::names();
        let mut not_applied = Vec::new();
        let mut applied: Vec<(&Written, Vec<f64>)> = Vec::new();
        for (effect, by_name) in values {
            if library.contains(&effect) {
                not_applied.push(effect);
                continue;
            }
            let w = self.written(&effect)?;
            applied.push((w, theta_of(w, &by_name)?));
        }
        Ok(NodeEffects {
            file: self.file.clone(),
            live: LiveEffects::new(&applied)?,
            not_applied,
        })
    }

    /// The node's written effect `effect`.
    fn written(&self, effect: &str) -> Result<&Written, EffectsError> {
        let Some(file) = &self.file else {
            return Err(EffectsError::NoFile {
                effect: effect.to_owned(),
            });
        };
        file.get(effect).ok_or_else(|| EffectsError::NotInFile {
            effect: effect.to_owned(),
            file: file.file.clone(),
            known: names_of(file),
        })
    }

    /// The effects of a Parameters message, in place of these (a message without effects
    /// applies none: it is a whole calibration).
    pub fn of_message(&self, msg: &Parameters) -> Result<NodeEffects, EffectsError> {
        let (names, values) = (&msg.effect_parameter_names, &msg.effect_parameter_values);
        if names.len() != values.len() {
            return Err(EffectsError::Lengths {
                names: names.len(),
                values: values.len(),
            });
        }
        let mut by_effect: Vec<(String, Values)> = msg
            .active_effects
            .iter()
            .map(|e| (e.clone(), Vec::new()))
            .collect();
        for (name, &value) in names.iter().zip(values) {
            let bad = || EffectsError::Name { name: name.clone() };
            let (effect, param) = name.split_once('.').ok_or_else(bad)?;
            let slot = by_effect
                .iter_mut()
                .find(|e| e.0 == effect)
                .ok_or_else(bad)?;
            // SI on the topic, the spec's unit in the model (unknown parameters: as sent,
            // the check below names them)
            let unit = self
                .file
                .as_ref()
                .and_then(|f| f.get(effect))
                .and_then(|w| w.spec().params.iter().find(|p| p.name == param))
                .map_or(1.0, |p| si_per_unit(&p.unit));
            slot.1.push((param.to_owned(), value / unit));
        }
        self.applying(by_effect)
    }

    /// The effects of the calibration file `doc`, in place of these: its `effects` (value
    /// in each parameter's unit), its recorded expressions checked against the node's. A
    /// parameters file without `effects` applies none.
    pub fn of_calibration(&self, doc: &CalibrationFile) -> Result<NodeEffects, EffectsError> {
        let mut by_effect: Vec<(String, Values)> = Vec::new();
        for e in &doc.effects {
            if let Ok(w) = self.written(&e.effect) {
                check_unit(w, &e.name, &e.unit)?;
            }
            let value = (e.name.clone(), e.value);
            match by_effect.iter_mut().find(|b| b.0 == e.effect) {
                Some(b) => b.1.push(value),
                None => by_effect.push((e.effect.clone(), vec![value])),
            }
        }
        let out = self.applying(by_effect)?;
        if let Some(recorded) = &doc.effects_file {
            self.check_expressions(recorded, &out)?;
        }
        Ok(out)
    }

    /// Each applied effect's expressions as the calibration recorded them against the
    /// node's file's.
    fn check_expressions(
        &self,
        recorded: &RecordedEffects,
        applied: &NodeEffects,
    ) -> Result<(), EffectsError> {
        for (name, _) in applied.live.values() {
            let Some(r) = recorded.effects.iter().find(|r| r.name == *name) else {
                continue;
            };
            let w = self.written(name)?;
            let ours = &w.spec().targets;
            let theirs = &r.expressions;
            let differs = |target: &str, node: &str| EffectsError::Expression {
                effect: name.to_owned(),
                target: target.to_owned(),
                calibrated: theirs
                    .get(target)
                    .map_or("(none)", String::as_str)
                    .to_owned(),
                node: node.to_owned(),
                file: self.file.as_ref().map_or(String::new(), |f| f.file.clone()),
            };
            for (target, text) in ours {
                if theirs.get(target) != Some(text) {
                    return Err(differs(target, text));
                }
            }
            if let Some(extra) = theirs
                .keys()
                .find(|k| !ours.iter().any(|(target, _)| target == *k))
            {
                return Err(differs(extra, "(none)"));
            }
        }
        Ok(())
    }

    /// What the geometry's source adds: the applied effects with their values, and the
    /// library's that are not applied (empty without either).
    pub fn describe(&self) -> String {
        let mut parts = Vec::new();
        for (name, theta) in self.live.values() {
            let values: Vec<String> = self
                .file
                .as_ref()
                .and_then(|f| f.get(name))
                .map(|w| {
                    w.spec()
                        .params
                        .iter()
                        .zip(theta)
                        .map(|(p, v)| format!("{} = {v:.6} {}", p.name, p.unit))
                        .collect()
                })
                .unwrap_or_default();
            parts.push(format!("{name} ({})", values.join(", ")));
        }
        let mut out = String::new();
        if !parts.is_empty() {
            out = format!(" with effects {}", parts.join("; "));
        }
        if !self.not_applied.is_empty() {
            let _ = write!(
                out,
                " (the library's {} not applied live)",
                self.not_applied.join(", ")
            );
        }
        out
    }

    /// The applied effects as a calibration JSON's `effects` (value in each parameter's
    /// unit) and `effects_file` (their expressions), as `rpkm calibrate --json` writes them.
    pub fn to_json(&self) -> Option<(serde_json::Value, serde_json::Value)> {
        let file = self.file.as_ref()?;
        let mut effects = Vec::new();
        let mut written = Vec::new();
        for (name, theta) in self.live.values() {
            let w = file.get(name)?;
            for (p, v) in w.spec().params.iter().zip(theta) {
                effects.push(serde_json::json!({
                    "effect": name, "name": p.name, "unit": p.unit, "value": v,
                }));
            }
            written.push(w);
        }
        if effects.is_empty() {
            return None;
        }
        Some((
            serde_json::Value::Array(effects),
            crate::effects_file::effects_json(&file.file, &written),
        ))
    }
}

/// Names of the file's effects, for messages.
fn names_of(file: &EffectsFile) -> String {
    let names: Vec<&str> = file
        .effects
        .iter()
        .map(|e| e.spec().name.as_str())
        .collect();
    names.join(", ")
}

/// θ of `w` (spec order) from values by parameter name: every parameter once, none other.
fn theta_of(w: &Written, by_name: &Values) -> Result<Vec<f64>, EffectsError> {
    let spec = w.spec();
    let effect = || spec.name.clone();
    for (param, value) in by_name {
        if !spec.params.iter().any(|p| p.name == *param) {
            let known: Vec<&str> = spec.params.iter().map(|p| p.name.as_str()).collect();
            return Err(EffectsError::Param {
                effect: effect(),
                param: param.clone(),
                known: known.join(", "),
            });
        }
        if !value.is_finite() {
            return Err(EffectsError::NonFinite {
                effect: effect(),
                param: param.clone(),
                value: *value,
            });
        }
    }
    spec.params
        .iter()
        .map(|p| {
            by_name
                .iter()
                .find(|(n, _)| *n == p.name)
                .map(|(_, v)| *v)
                .ok_or_else(|| EffectsError::Missing {
                    effect: effect(),
                    param: p.name.clone(),
                })
        })
        .collect()
}

/// A calibration's unit of `param` against the file's.
fn check_unit(w: &Written, param: &str, unit: &str) -> Result<(), EffectsError> {
    match w.spec().params.iter().find(|p| p.name == param) {
        Some(p) if p.unit != unit => Err(EffectsError::Unit {
            effect: w.spec().name.clone(),
            param: param.to_owned(),
            found: unit.to_owned(),
            unit: p.unit.clone(),
        }),
        _ => Ok(()),
    }
}

impl NodeEffects {
    /// The node's known effects from its `effects_file` parameter (none where empty), read
    /// with every mistake told at its file, line and column (bad input: the node exits 2).
    pub fn from_params(p: &super::params::NodeParams) -> anyhow::Result<NodeEffects> {
        let path = p
            .string("effects_file", "")
            .map_err(super::context::bad_param)?;
        if path.is_empty() {
            return Ok(NodeEffects::default());
        }
        crate::effects_file::read(Path::new(&path), &[])
            .map(|f| NodeEffects::known(Some(f)))
            .map_err(|e| crate::error::bad_input(e.to_string()))
    }

    /// The effects of the calibration file `doc` read from `path`
    /// ([`NodeEffects::of_calibration`]), a mistake told as bad input naming the file.
    pub fn read_calibration(
        &self,
        path: &Path,
        doc: &CalibrationFile,
    ) -> anyhow::Result<NodeEffects> {
        self.of_calibration(doc)
            .map_err(|e| crate::error::bad_input(format!("{}: {e}", path.display())))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rpkm_core::campaign::MotionCovariates;

    const LOST: &str = "effects:\n  - name: lost_motion_q4\n    summary: s\n    \
                        params: {b: {unit: mm, prior: 0.01}}\n    dq4: \"-b * dir_q4\"\n";

    fn known(text: &str) -> NodeEffects {
        let file = crate::effects_file::parse(text, "lost.yaml", &[]).expect("effects file");
        NodeEffects::known(Some(file))
    }

    fn message(effects: &[&str], names: &[&str], values: &[f64]) -> Parameters {
        let own = |v: &[&str]| v.iter().map(|s| (*s).to_owned()).collect();
        Parameters {
            model: 29,
            active_effects: own(effects),
            effect_parameter_names: own(names),
            effect_parameter_values: values.to_vec(),
            ..Default::default()
        }
    }

    fn live(q4: f64, dir4: f64) -> LiveState {
        LiveState {
            q: [1000.0, 1100.0, 900.0, q4],
            f: [0.0; 4],
            t: 3.0,
            motion: MotionCovariates {
                dir: [1.0, 1.0, 1.0, dir4],
                travel: [0.0; 4],
                t_run: 0.0,
            },
        }
    }

    #[test]
    fn message_values_come_back_in_the_files_units() -> Result<(), EffectsError> {
        let mut e = known(LOST).of_message(&message(
            &["lost_motion_q4"],
            &["lost_motion_q4.b"],
            &[0.02e-3],
        ))?;
        let p = Params::nominal();
        let (pc, q) = e.apply(&p, &live(-300.0, -1.0));
        assert!((q[3] - (-300.0 + 0.02)).abs() < 1e-12, "{}", q[3]);
        assert_eq!(pc, p, "dq4 only");
        let (_, q) = e.apply(&p, &live(-300.0, 1.0));
        assert!((q[3] - (-300.0 - 0.02)).abs() < 1e-12, "{}", q[3]);
        assert!(
            e.describe().contains("lost_motion_q4 (b = 0.020000 mm)"),
            "{}",
            e.describe()
        );
        // a message without effects applies none (it is a whole calibration)
        let none = e.of_message(&message(&[], &[], &[]))?;
        assert!(none.is_empty());
        Ok(())
    }

    #[test]
    fn an_effect_the_node_does_not_know_is_refused_naming_it() {
        let msg = message(&["cyclic_q2"], &["cyclic_q2.a"], &[1e-6]);
        let e = known(LOST).of_message(&msg);
        assert!(
            matches!(&e, Err(EffectsError::NotInFile { effect, known, .. })
                if effect == "cyclic_q2" && known == "lost_motion_q4"),
            "{e:?}"
        );
        let e = NodeEffects::default().of_message(&msg);
        assert!(
            matches!(&e, Err(EffectsError::NoFile { effect }) if effect == "cyclic_q2"),
            "{e:?}"
        );
        // through the geometry: the typed error of the message
        let g = super::super::Geometry {
            params: Params::nominal(),
            model: rpkm_core::params::Model::M29,
            stiffness: rpkm_core::elastic::Stiffness::default(),
            source: "test".into(),
            effects: known(LOST),
        };
        let err = g.updated(&msg).map(|_| ()).map_err(|e| e.to_string());
        assert_eq!(
            err,
            Err(
                "/rpkm/parameters: effect `cyclic_q2` is not in the node's effects_file \
                 lost.yaml (it has lost_motion_q4)"
                    .to_owned()
            )
        );
    }

    #[test]
    fn parameters_must_be_the_effects_own_and_complete() {
        let k = known(LOST);
        let e = k.of_message(&message(&["lost_motion_q4"], &["lost_motion_q4.c"], &[1.0]));
        assert!(
            matches!(&e, Err(EffectsError::Param { param, .. }) if param == "c"),
            "{e:?}"
        );
        let e = k.of_message(&message(&["lost_motion_q4"], &[], &[]));
        assert!(
            matches!(&e, Err(EffectsError::Missing { param, .. }) if param == "b"),
            "{e:?}"
        );
        let e = k.of_message(&message(&["lost_motion_q4"], &["b"], &[1.0]));
        assert!(matches!(&e, Err(EffectsError::Name { .. })), "{e:?}");
        let e = k.of_message(&message(
            &["lost_motion_q4"],
            &["lost_motion_q4.b"],
            &[f64::NAN],
        ));
        assert!(matches!(&e, Err(EffectsError::NonFinite { .. })), "{e:?}");
        // the library's effects are named as not applied, not refused
        let lib = k.of_message(&message(&["thermal"], &["thermal.alpha_rods"], &[1.0]));
        let lib = lib.map(|e| e.describe());
        assert_eq!(
            lib,
            Ok(" (the library's thermal not applied live)".to_owned())
        );
    }

    #[test]
    fn an_effect_reading_a_temperature_is_refused_live() {
        let k = known(
            "effects:\n  - name: warm_q4\n    summary: s\n    params: {a: {unit: mm, prior: 0.01}}\n    \
             dq4: \"a * (temp_machine - 20)\"\n",
        );
        let e = k.of_message(&message(&["warm_q4"], &["warm_q4.a"], &[1e-6]));
        assert!(
            matches!(&e, Err(EffectsError::Live(LiveError::NotLive { effect, variable }))
                if effect == "warm_q4" && variable == "temp_machine"),
            "{e:?}"
        );
    }

    #[test]
    fn a_calibration_json_round_trips_and_other_expressions_are_refused() -> anyhow::Result<()> {
        let k = known(LOST);
        let e = k.of_message(&message(
            &["lost_motion_q4"],
            &["lost_motion_q4.b"],
            &[0.02e-3],
        ))?;
        let (effects, file) = e.to_json().ok_or_else(|| anyhow::anyhow!("no effects"))?;
        let mut doc =
            serde_json::json!({"parameters": {}, "effects": effects, "effects_file": file});
        let of = |doc: &serde_json::Value| {
            let file = CalibrationFile::of_value(Path::new("cal.json"), doc.clone())?;
            Ok::<_, anyhow::Error>(k.of_calibration(&file))
        };
        let back = of(&doc)??;
        assert_eq!(back, e);
        doc["effects_file"]["effects"][0]["expressions"]["dq4"] = "b * dir_q4".into();
        let err = of(&doc)?;
        assert!(
            matches!(&err, Err(EffectsError::Expression { effect, calibrated, .. })
                if effect == "lost_motion_q4" && calibrated == "b * dir_q4"),
            "{err:?}"
        );
        doc["effects"][0]["unit"] = "um".into();
        let err = of(&doc)?;
        assert!(matches!(&err, Err(EffectsError::Unit { .. })), "{err:?}");
        Ok(())
    }
}
