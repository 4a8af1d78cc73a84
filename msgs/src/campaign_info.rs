//! `rpkm_msgs/msg/CampaignInfo` (msgs/msg/CampaignInfo.msg).

use serde::{Deserialize, Serialize};

/// What a campaign holds besides its poses: source label, comments, covariate names.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct CampaignInfo {
    /// `string source`: label of the source, e.g. the campaign file name.
    pub source: String,
    /// `string[] comments`: comment lines of the campaign file, without `# `.
    pub comments: Vec<String>,
    /// `string[] covariate_names`: names of `ActuatorState::covariates`, in order.
    pub covariate_names: Vec<String>,
}

crate::ros_message!(
    CampaignInfo,
    "rpkm_msgs",
    "CampaignInfo",
    include_str!("../msg/CampaignInfo.msg"),
    []
);
