//! What a node reads from its parameters to take drive states from ros2_control: the
//! JointState topic and its QoS, which joint is which drive, the sign of each joint's effort,
//! which drives follow, and the thermometers.

use std::time::Duration;

use rpkm_core::campaign::{followers_words, parse_follower};
use rpkm_msgs::actuator_state::MAX_COVARIATES;
use rpkm_transport::names::absolute_name_error;

use crate::node::declare::{ParamBound, ParamDefault as Value, ParamSpec};
use crate::node::params::{NodeParams, ParamError};

/// Default of `joint_states_topic`: the joint_state_broadcaster's.
pub const JOINT_STATES_TOPIC: &str = "/joint_states";
/// Default of `joint_names`.
pub const JOINT_NAMES: [&str; 4] = ["q1_joint", "q2_joint", "q3_joint", "q4_joint"];
/// Default of `effort_sign`: a joint's effort is the drive force, positive towards larger q.
pub const EFFORT_SIGN: [f64; 4] = [1.0; 4];

const TOPIC: ParamSpec = ParamSpec::fixed(
    "joint_states_topic",
    Value::Str(JOINT_STATES_TOPIC),
    "sensor_msgs/JointState topic of the drives (ros2_control's joint_state_broadcaster)",
);
const QOS: ParamSpec = ParamSpec::fixed(
    "joint_states_qos",
    Value::Str("reliable"),
    "reliability of the JointState reader: reliable (the broadcaster's) or best_effort",
);
const NAMES: ParamSpec = ParamSpec::fixed(
    "joint_names",
    Value::Strs(&JOINT_NAMES),
    "the joints of drives q1, q2, q3, q4; other joints of the message are ignored",
);
const SIGNS: ParamSpec = ParamSpec::fixed(
    "effort_sign",
    Value::F64s(&EFFORT_SIGN),
    "drive force = sign x joint effort, per drive (1 or -1; rpkm: positive towards larger q)",
);
const FOLLOWERS: ParamSpec = ParamSpec::live(
    "followers",
    Value::Str(""),
    "drives in follower mode, e.g. \"23\" (none or \"\": no drive follows); applies from the next state",
);
const THERMOMETERS: ParamSpec = ParamSpec::group(
    "temperatures.",
    "covariate name -> sensor_msgs/Temperature topic of a thermometer",
);
/// A thermometer silent this long is not measured: default ten periods of a 5 Hz one.
const TEMPERATURE_TIMEOUT: ParamSpec = ParamSpec::fixed(
    "temperature_timeout_s",
    Value::F64(2.0),
    "a thermometer silent this long is not measured",
)
.unit("s")
.bound(ParamBound::Within(1e-3, 3600.0));

/// JointState silent this long: the input is quiet, WARN by name (a cell publishes at its
/// controller's rate, 100 Hz to kHz: a second is a hundred states missed).
const QUIET_TIMEOUT: ParamSpec = ParamSpec::fixed(
    "joint_states_timeout_s",
    Value::F64(1.0),
    "no JointState this long: /diagnostics WARNs that the drive states are quiet",
)
.unit("s")
.bound(ParamBound::Within(1e-3, 3600.0));

/// The JointState input's parameters: `followers` live (from the next state on), the rest
/// need a restart (`temperatures.` is a group: covariate name → topic).
pub const PARAMS: [ParamSpec; 8] = [
    TOPIC,
    QOS,
    NAMES,
    SIGNS,
    FOLLOWERS,
    THERMOMETERS,
    TEMPERATURE_TIMEOUT,
    QUIET_TIMEOUT,
];

/// One thermometer: the covariate its readings become and the topic they come on.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Thermometer {
    /// Covariate name (`temp_machine`), as a campaign column names it.
    pub covariate: String,
    /// Absolute topic of its `sensor_msgs/Temperature` (`/cell/frame_temperature`).
    pub topic: String,
}

/// The JointState input's settings.
#[derive(Debug, Clone, PartialEq)]
pub struct JointConfig {
    /// Absolute topic of the JointState.
    pub topic: String,
    /// Reliable reader (the broadcaster's default, `SystemDefaultsQoS`), else best effort.
    pub reliable: bool,
    /// The joints of drives q1..q4.
    pub joints: [String; 4],
    /// rpkm's drive force = sign × the joint's effort.
    pub effort_sign: [f64; 4],
    /// The drives in follower mode.
    pub followers: [bool; 4],
    /// The thermometers, in covariate name order (the order of ActuatorState.covariates).
    pub thermometers: Vec<Thermometer>,
    /// After this long without a reading a thermometer's covariate is "not measured".
    pub timeout: Duration,
    /// After this long without a JointState the drive states are quiet.
    pub quiet_after: Duration,
}

fn topic(p: &NodeParams, spec: &ParamSpec) -> Result<String, ParamError> {
    let t = spec.string(p)?;
    match absolute_name_error(&t) {
        None => Ok(t),
        Some(_) => Err(p.invalid(spec.key, "an absolute ROS 2 topic name (/joint_states)")),
    }
}

fn joints(p: &NodeParams) -> Result<[String; 4], ParamError> {
    let names = NAMES.strings(p)?;
    let distinct = names
        .iter()
        .enumerate()
        .all(|(i, n)| !n.is_empty() && !names[..i].contains(n));
    match <[String; 4]>::try_from(names) {
        Ok(four) if distinct => Ok(four),
        _ => Err(p.invalid(
            "joint_names",
            "four distinct joint names, of drives q1, q2, q3, q4",
        )),
    }
}

fn effort_sign(p: &NodeParams) -> Result<[f64; 4], ParamError> {
    let signs = SIGNS.f64s(p)?;
    let unit = |s: &f64| (s.abs() - 1.0).abs() < 1e-12;
    match <[f64; 4]>::try_from(signs) {
        Ok(four) if four.iter().all(unit) => Ok(four.map(f64::signum)),
        _ => Err(p.invalid(
            "effort_sign",
            "four signs, 1 or -1, of drives q1, q2, q3, q4",
        )),
    }
}

/// Parameter `followers` (`"23"`: q2 and q3 follow; `none` or `""`: every drive holds).
pub fn followers(p: &NodeParams) -> Result<[bool; 4], ParamError> {
    parse_follower(&FOLLOWERS.string(p)?).ok_or_else(|| {
        p.invalid(
            "followers",
            "distinct drive digits 1-4 such as \"23\", or none (\"\" alike)",
        )
    })
}

fn thermometers(p: &NodeParams) -> Result<Vec<Thermometer>, ParamError> {
    let group = p.string_group(THERMOMETERS.key)?;
    let mut out = Vec::with_capacity(group.len());
    for (covariate, topic, _) in group {
        let key = format!("temperatures.{covariate}");
        if absolute_name_error(&topic).is_some() {
            return Err(p.invalid(&key, "an absolute ROS 2 topic name (/cell/thermometer)"));
        }
        if !covariate
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_')
        {
            return Err(p.invalid(&key, "a covariate name of letters, digits and `_`"));
        }
        out.push(Thermometer { covariate, topic });
    }
    if out.len() > MAX_COVARIATES {
        let key = format!("temperatures.{}", out[MAX_COVARIATES].covariate);
        return Err(p.invalid(&key, "at most 8 thermometers (ActuatorState's covariates)"));
    }
    Ok(out)
}

impl JointConfig {
    /// The settings of parameter set `p`, every value checked; the error names the key and
    /// where it was set.
    pub fn from_params(p: &NodeParams) -> Result<Self, ParamError> {
        let reliable = match QOS.string(p)?.as_str() {
            "reliable" => true,
            "best_effort" => false,
            _ => return Err(p.invalid("joint_states_qos", "reliable or best_effort")),
        };
        let timeout = TEMPERATURE_TIMEOUT.f64(p)?;
        Ok(Self {
            topic: topic(p, &TOPIC)?,
            reliable,
            joints: joints(p)?,
            effort_sign: effort_sign(p)?,
            followers: followers(p)?,
            thermometers: thermometers(p)?,
            timeout: Duration::from_secs_f64(timeout),
            quiet_after: Duration::from_secs_f64(QUIET_TIMEOUT.f64(p)?),
        })
    }

    /// The covariate names, in ActuatorState order.
    pub fn covariate_names(&self) -> Vec<String> {
        self.thermometers
            .iter()
            .map(|t| t.covariate.clone())
            .collect()
    }

    /// What the node says at its start: `joints q1_joint, ..., followers 23 (from the
    /// parameter files), thermometers temp_machine (/cell/frame_temperature)`; `kept_at`: when
    /// the followers were set at run time before a restart by the launcher.
    pub fn started(&self, kept_at: Option<&str>) -> String {
        let whence = kept_at.map_or_else(
            || "from the parameter files".to_owned(),
            |at| format!("kept from the run before the restart, set at {at}"),
        );
        let thermometers: Vec<String> = self
            .thermometers
            .iter()
            .map(|t| format!("{} ({})", t.covariate, t.topic))
            .collect();
        format!(
            "joints {} (drives q1 to q4), followers {} ({whence}), thermometers {}",
            self.joints.join(", "),
            self.followers_text(),
            if thermometers.is_empty() {
                "none".to_owned()
            } else {
                thermometers.join(", ")
            }
        )
    }

    /// `followers` as the logs and /diagnostics write them (`23`; `none` for no drive).
    pub fn followers_text(&self) -> String {
        followers_words(self.followers)
    }
}

#[cfg(test)]
#[expect(
    clippy::float_cmp,
    reason = "exact values: parsed, copied or computed without rounding"
)]
mod tests {
    use super::*;
    use std::path::Path;

    fn params(text: &str) -> NodeParams {
        let mut p = NodeParams::empty("ingest");
        p.merge_text(text, Path::new("cell.yaml")).expect("yaml");
        p
    }

    #[test]
    fn a_cell_block_reads_with_thermometers_in_name_order() -> Result<(), ParamError> {
        let c = JointConfig::from_params(&params(
            "ingest:\n  ros__parameters:\n    joint_names: [a, b, c, d]\n    \
             effort_sign: [1, -1.0, 1, -1]\n    followers: 23\n    temperatures:\n      \
             temp_spindle: /cell/t2\n      temp_machine: /cell/t1\n",
        ))?;
        assert_eq!(c.joints, ["a", "b", "c", "d"]);
        assert_eq!(c.effort_sign, [1.0, -1.0, 1.0, -1.0]);
        assert_eq!(c.followers, [false, true, true, false]);
        assert_eq!(c.covariate_names(), ["temp_machine", "temp_spindle"]);
        assert_eq!(c.thermometers[0].topic, "/cell/t1");
        assert!(c.reliable);
        assert_eq!(c.topic, "/joint_states");
        let none = JointConfig::from_params(&params(
            "ingest:\n  ros__parameters:\n    temperatures: {}\n",
        ))?;
        assert!(none.thermometers.is_empty());
        assert_eq!(none.followers_text(), "none");
        // a launch file's `none` and `''` are one value, written `none`
        for spelling in ["none", "''", "\"\""] {
            let c = JointConfig::from_params(&params(&format!(
                "ingest:\n  ros__parameters:\n    followers: {spelling}\n"
            )))?;
            assert_eq!(c.followers, [false; 4], "{spelling}");
            assert_eq!(c.followers_text(), "none");
        }
        Ok(())
    }

    #[test]
    fn bad_values_name_the_key_and_what_was_expected() {
        for (line, says) in [
            (
                "joint_names: [a, b, c]",
                "joint_names: expected four distinct joint names",
            ),
            (
                "joint_names: [a, b, c, a]",
                "joint_names: expected four distinct joint names",
            ),
            (
                "effort_sign: [1, 1, 0.5, 1]",
                "effort_sign: expected four signs",
            ),
            (
                "followers: \"25\"",
                "followers: expected distinct drive digits",
            ),
            (
                "joint_states_topic: joint_states",
                "expected an absolute ROS 2 topic",
            ),
            ("joint_states_qos: fast", "expected reliable or best_effort"),
            (
                "temperatures: {t: cell/t}",
                "temperatures.t: expected an absolute ROS 2 topic",
            ),
            (
                "temperature_timeout_s: 0",
                "out of range: expected 0.001 to 3600 s",
            ),
        ] {
            let e = JointConfig::from_params(&params(&format!(
                "ingest:\n  ros__parameters:\n    {line}\n"
            )))
            .expect_err(line);
            let text = e.to_string();
            assert!(
                text.starts_with("cell.yaml: ingest/ros__parameters/"),
                "{text}"
            );
            assert!(text.contains(says), "{line}: {text}");
        }
    }
}
