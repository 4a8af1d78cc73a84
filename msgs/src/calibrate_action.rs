//! `rpkm_msgs/action/Calibrate` (msgs/action/Calibrate.action): the calibrator's
//! `~/calibrate` action, its goal, result and feedback field for field. The action's wire
//! wrappers (goal id, status) are ROS 2's, added by the transport.

use serde::{Deserialize, Serialize};

use crate::Parameters;

/// The goal: what to calibrate and how.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct CalibrateGoal {
    /// `string campaign_file`: a campaign CSV on the node's host; empty: the campaign the
    /// node collected from its topics.
    pub campaign_file: String,
    /// `string validation_file`: a held-out campaign CSV; empty: the setups named by the
    /// node's `validation_prefix`.
    pub validation_file: String,
    /// `string selection`: `map` or `auto`; empty: the node's.
    pub selection: String,
    /// `string effects`: comma-separated effects; empty: the node's effects file's.
    pub effects: String,
    /// `uint8 noise`: [`CalibrateGoal::NOISE_NODE`], `NOISE_ESTIMATE` or `NOISE_STATED`.
    pub noise: u8,
    /// `bool skip_diagnosis`.
    pub skip_diagnosis: bool,
}

impl CalibrateGoal {
    pub const NOISE_NODE: u8 = 0;
    pub const NOISE_ESTIMATE: u8 = 1;
    pub const NOISE_STATED: u8 = 2;
}

/// The result.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct CalibrateResult {
    /// `Parameters parameters` (SI); empty when cancelled or failed.
    pub parameters: Parameters,
    /// `float64 val_rms`: held-out RMS, m (NaN without a validation campaign).
    pub val_rms: f64,
    /// `uint32 iterations`: LM iterations of the final fit.
    pub iterations: u32,
    /// `uint32 noise_rounds`.
    pub noise_rounds: u32,
    /// `string[] noise_groups`.
    pub noise_groups: Vec<String>,
    /// `float64[] noise_stated`: m, rad for ψ.
    pub noise_stated: Vec<f64>,
    /// `float64[] noise_estimated`: m, rad for ψ.
    pub noise_estimated: Vec<f64>,
    /// `string verdict`: `nothing_missing`, `missing_effect`, `unexplained_structure` or empty.
    pub verdict: String,
    /// `string message`.
    pub message: String,
}

/// The feedback.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct CalibrateFeedback {
    /// `uint8 phase`: [`CalibrateFeedback::PHASE_ITERATION`], `PHASE_NOISE_ROUND` or
    /// `PHASE_DIAGNOSIS`.
    pub phase: u8,
    /// `uint32 round`: the noise round, from 1.
    pub round: u32,
    /// `uint8 step`: 1 direct rows, 2 rod 2's virtual rows.
    pub step: u8,
    /// `uint32 iteration`: the round's LM iterations so far, from 1.
    pub iteration: u32,
    /// `float64 cost`: the LM cost at the iteration's start.
    pub cost: f64,
    /// `string[] noise_groups`.
    pub noise_groups: Vec<String>,
    /// `float64[] noise_estimated`: m, rad for ψ.
    pub noise_estimated: Vec<f64>,
}

impl CalibrateFeedback {
    pub const PHASE_ITERATION: u8 = 1;
    pub const PHASE_NOISE_ROUND: u8 = 2;
    pub const PHASE_DIAGNOSIS: u8 = 3;
}

/// The action's type name (`rpkm_msgs/action/Calibrate`).
pub const CALIBRATE: &str = "Calibrate";

crate::ros_message!(
    CalibrateGoal,
    "rpkm_msgs",
    "Calibrate_Goal",
    "string campaign_file\nstring validation_file\nstring selection\nstring effects\n\
     uint8 noise\nbool skip_diagnosis\n",
    []
);
crate::ros_message!(
    CalibrateResult,
    "rpkm_msgs",
    "Calibrate_Result",
    "Parameters parameters\nfloat64 val_rms\nuint32 iterations\nuint32 noise_rounds\n\
     string[] noise_groups\nfloat64[] noise_stated\nfloat64[] noise_estimated\n\
     string verdict\nstring message\n",
    [Parameters]
);
crate::ros_message!(
    CalibrateFeedback,
    "rpkm_msgs",
    "Calibrate_Feedback",
    "uint8 phase\nuint32 round\nuint8 step\nuint32 iteration\nfloat64 cost\n\
     string[] noise_groups\nfloat64[] noise_estimated\n",
    []
);

#[cfg(test)]
mod tests {
    use super::*;

    /// The Rust fields are the .action file's, section by section, in order.
    #[test]
    fn fields_follow_the_action_file() {
        let text = include_str!("../action/Calibrate.action");
        let sections: Vec<Vec<String>> = text
            .split("\n---\n")
            .map(|s| {
                s.lines()
                    .map(|l| l.split('#').next().unwrap_or_default().trim())
                    .filter(|l| !l.is_empty() && !l.contains('='))
                    .map(str::to_owned)
                    .collect()
            })
            .collect();
        let rust = [
            <CalibrateGoal as crate::MsgText>::TEXT,
            <CalibrateResult as crate::MsgText>::TEXT,
            <CalibrateFeedback as crate::MsgText>::TEXT,
        ];
        assert_eq!(sections.len(), 3);
        for (section, fields) in sections.iter().zip(rust) {
            let fields: Vec<&str> = fields.lines().collect();
            assert_eq!(section, &fields);
        }
    }
}
