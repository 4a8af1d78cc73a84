//! The `joint_states` source: drive states from ros2_control's JointState and the cell's
//! thermometers ([`crate::node::joint_input`]), numbered, validated and republished as
//! ActuatorStates like every other source's.

use std::time::Duration;

use rpkm_msgs::CampaignInfo;

use super::output::Output;
use super::validate::{reject, RejectKind};
use crate::node::joint_input::{JointConfig, JointInput, JointReject, RefusalLevel};
use crate::node::{shutdown, Idle, NodeContext};

/// A refused JointState as ingest counts it: a NaN is non-finite, the rest malformed.
fn refusal(r: &JointReject, topic: &str) -> super::Reject {
    let kind = match r {
        JointReject::NonFinite { .. } => RejectKind::NonFinite,
        _ => RejectKind::Malformed,
    };
    reject(kind, format!("{topic}: {r}"))
}

/// Republishes the cell's drive states until shutdown.
pub(super) fn run(
    ctx: &NodeContext,
    out: &mut Output<'_>,
    config: JointConfig,
) -> anyhow::Result<()> {
    let mut input = JointInput::open(ctx, config)?;
    out.info_message(&CampaignInfo {
        source: format!("joint_states {}", input.topic()),
        comments: vec![],
        covariate_names: input.covariate_names(),
    })?;
    let mut idle = Idle::new(Duration::from_millis(50), Duration::from_micros(500));
    while !shutdown::requested() {
        let mut worked = false;
        loop {
            // a set through the parameter services applies from the next state on
            if let Some(p) = out.parameter_changes(true)? {
                input.take_followers(ctx, &p, out.next_seq())?;
            }
            let Some(next) = input.next(ctx)? else {
                break;
            };
            worked = true;
            match next {
                Ok(state) => out.numbered_state(state, input.topic())?,
                Err(r) if out.publishing() => out.reject(refusal(&r, input.topic())),
                Err(_) => {}
            }
        }
        out.serve_lifecycle();
        out.report_due_with(|st| input.annotate(st, RefusalLevel::ValuesOnly))?;
        if worked {
            idle.worked();
        } else {
            idle.wait();
        }
    }
    Ok(())
}
