//! One `sensor_msgs/JointState` read as the drive state it carries: the four named joints
//! found wherever the message lists them, the others ignored; positions m, efforts turned into
//! rpkm's drive forces; nothing guessed (a missing joint, arrays of unequal length, a repeated
//! name, a drive's position NaN or infinite, an infinite effort: the message is refused,
//! naming why). A cell without force sensing sends no efforts (an empty `effort` array, as
//! JointState allows) or NaN efforts: a holding drive's force is then NaN, "not measured",
//! never 0; the positions are all the estimate needs.

use rpkm_msgs::{ActuatorState, JointState};

use super::config::JointConfig;

/// Why a JointState gives no drive state.
#[derive(Debug, Clone, PartialEq)]
pub enum JointReject {
    /// A joint of `joint_names` is not in the message.
    MissingJoint {
        /// The joint.
        joint: String,
        /// Its drive, 0..=3.
        drive: usize,
        /// The names the message has.
        names: Vec<String>,
    },
    /// `position` not as long as `name` (or `velocity`, `effort` neither empty nor as long).
    UnequalArrays {
        /// Lengths of name, position, velocity, effort.
        lengths: [usize; 4],
    },
    /// A joint of `joint_names` listed twice: which entry is the drive cannot be told.
    RepeatedJoint {
        /// The joint.
        joint: String,
    },
    /// A drive's position is NaN or infinite, or a holding drive's effort infinite (NaN:
    /// not measured).
    NonFinite {
        /// The joint.
        joint: String,
        /// `position` or `effort`.
        field: &'static str,
        /// The value.
        value: f64,
    },
}

impl JointReject {
    /// The joint the reject names, if it names one.
    pub fn joint(&self) -> Option<&str> {
        match self {
            Self::MissingJoint { joint, .. }
            | Self::RepeatedJoint { joint }
            | Self::NonFinite { joint, .. } => Some(joint),
            Self::UnequalArrays { .. } => None,
        }
    }
}

impl std::fmt::Display for JointReject {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::MissingJoint {
                joint,
                drive,
                names,
            } => write!(
                f,
                "joint {joint} (drive q{}) missing; the message has [{}]",
                drive + 1,
                names.join(", ")
            ),
            Self::UnequalArrays {
                lengths: [n, p, v, e],
            } => write!(
                f,
                "arrays of unequal length: name {n}, position {p}, velocity {v}, effort {e} \
                 (position as long as name, velocity and effort too or empty)"
            ),
            Self::RepeatedJoint { joint } => write!(f, "joint {joint} listed twice"),
            Self::NonFinite {
                joint,
                field,
                value,
            } => write!(f, "joint {joint}: {field} {value}"),
        }
    }
}

/// The drive state of `js` under `config` (stamp, positions m, forces N, follower flags),
/// without seq and covariates (the caller numbers it and attaches the temperatures). A
/// follower's force is 0, as ActuatorState defines it: its controller is off, whatever the
/// joint's effort says. A holding drive without an effort (the array empty) or with a NaN
/// one has force NaN: not measured.
pub fn drive_state(js: &JointState, config: &JointConfig) -> Result<ActuatorState, JointReject> {
    let n = js.name.len();
    let lengths = [n, js.position.len(), js.velocity.len(), js.effort.len()];
    let empty_or_n = |len: usize| len == 0 || len == n;
    if lengths[1] != n || !empty_or_n(lengths[2]) || !empty_or_n(lengths[3]) {
        return Err(JointReject::UnequalArrays { lengths });
    }
    let mut state = ActuatorState {
        stamp: js.header.stamp,
        follower: config.followers,
        ..ActuatorState::default()
    };
    for (drive, joint) in config.joints.iter().enumerate() {
        let mut at = js.name.iter().enumerate().filter(|(_, n)| *n == joint);
        let Some((i, _)) = at.next() else {
            return Err(JointReject::MissingJoint {
                joint: joint.clone(),
                drive,
                names: js.name.clone(),
            });
        };
        if at.next().is_some() {
            return Err(JointReject::RepeatedJoint {
                joint: joint.clone(),
            });
        }
        let non_finite = |field, value: f64| JointReject::NonFinite {
            joint: joint.clone(),
            field,
            value,
        };
        let position = js.position[i];
        if !position.is_finite() {
            return Err(non_finite("position", position));
        }
        state.position[drive] = position;
        if !config.followers[drive] {
            let effort = js.effort.get(i).copied().unwrap_or(f64::NAN);
            if effort.is_infinite() {
                return Err(non_finite("effort", effort));
            }
            // NaN stays NaN: not measured
            state.force[drive] = config.effort_sign[drive] * effort;
        }
    }
    Ok(state)
}

#[cfg(test)]
#[expect(
    clippy::float_cmp,
    reason = "exact values: parsed, copied or computed without rounding"
)]
mod tests {
    use super::*;
    use rpkm_msgs::{Header, Time};
    use std::time::Duration;

    fn config(followers: [bool; 4]) -> JointConfig {
        JointConfig {
            topic: "/joint_states".into(),
            reliable: true,
            joints: ["q1_joint", "q2_joint", "q3_joint", "q4_joint"].map(String::from),
            effort_sign: [1.0, 1.0, -1.0, -1.0],
            followers,
            thermometers: vec![],
            timeout: Duration::from_secs(1),
            quiet_after: Duration::from_secs(1),
        }
    }

    /// The broadcaster's message: the drives in another order, a gripper among them.
    fn message() -> JointState {
        JointState {
            header: Header {
                stamp: Time {
                    sec: 12,
                    nanosec: 5,
                },
                frame_id: String::new(),
            },
            name: ["q3_joint", "gripper", "q1_joint", "q4_joint", "q2_joint"]
                .map(String::from)
                .to_vec(),
            position: vec![0.789, 0.01, 2.611, 0.788, 2.610],
            velocity: vec![],
            effort: vec![30.0, f64::NAN, 10.0, -40.0, 20.0],
        }
    }

    #[test]
    fn joints_are_found_by_name_and_efforts_signed() -> Result<(), JointReject> {
        let s = drive_state(&message(), &config([false; 4]))?;
        assert_eq!(s.position, [2.611, 2.610, 0.789, 0.788]);
        assert_eq!(s.force, [10.0, 20.0, -30.0, 40.0]);
        assert_eq!(s.stamp, message().header.stamp);
        assert_eq!(s.follower, [false; 4]);
        let f = drive_state(&message(), &config([false, true, true, false]))?;
        assert_eq!(f.force, [10.0, 0.0, 0.0, 40.0], "followers carry no force");
        assert_eq!(f.follower, [false, true, true, false]);
        Ok(())
    }

    #[test]
    fn what_cannot_be_read_is_refused_naming_why() {
        let c = config([false; 4]);
        let mut missing = message();
        missing.name[4] = "q2_link".into();
        let e = drive_state(&missing, &c).expect_err("q2_joint missing");
        assert_eq!(e.joint(), Some("q2_joint"));
        assert_eq!(
            e.to_string(),
            "joint q2_joint (drive q2) missing; the message has [q3_joint, gripper, q1_joint, \
             q4_joint, q2_link]"
        );
        let mut short = message();
        short.effort.pop();
        let e = drive_state(&short, &c).expect_err("unequal");
        assert_eq!(
            e,
            JointReject::UnequalArrays {
                lengths: [5, 5, 0, 4]
            }
        );
        let mut nan = message();
        nan.position[0] = f64::NAN;
        let e = drive_state(&nan, &c).expect_err("NaN");
        assert_eq!(e.to_string(), "joint q3_joint: position NaN");
        let mut twice = message();
        twice.name[1] = "q1_joint".into();
        let e = drive_state(&twice, &c).expect_err("twice");
        assert_eq!(e.joint(), Some("q1_joint"));
        let mut infinite = message();
        infinite.effort[2] = f64::INFINITY;
        let e = drive_state(&infinite, &c).expect_err("infinite effort");
        assert_eq!(e.to_string(), "joint q1_joint: effort inf");
        // a NaN effort of a follower is no drive force: the state is read
        let mut follower_nan = message();
        follower_nan.effort[0] = f64::NAN;
        assert!(drive_state(&follower_nan, &config([false, false, true, false])).is_ok());
    }

    /// A cell without force sensing: no effort array, or NaN efforts. The positions are read;
    /// a holding drive's force is not measured (NaN), a follower's 0 as ever.
    #[test]
    fn without_efforts_the_positions_are_read_and_forces_not_measured() -> Result<(), JointReject> {
        let mut none = message();
        none.effort.clear();
        let mut nan = message();
        nan.effort = vec![f64::NAN; 5];
        for js in [none, nan] {
            let s = drive_state(&js, &config([false, true, true, false]))?;
            assert_eq!(s.position, [2.611, 2.610, 0.789, 0.788]);
            assert!(s.force[0].is_nan() && s.force[3].is_nan(), "{:?}", s.force);
            assert_eq!((s.force[1], s.force[2]), (0.0, 0.0), "followers");
        }
        // one drive's effort NaN: that drive alone not measured
        let mut one = message();
        one.effort[4] = f64::NAN;
        let s = drive_state(&one, &config([false; 4]))?;
        assert_eq!(s.force[0], 10.0);
        assert!(s.force[1].is_nan());
        assert_eq!(s.force[2..], [-30.0, 40.0]);
        Ok(())
    }
}
