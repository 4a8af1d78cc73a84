//! The `dds` source: ActuatorState and TcpMeasurement from a controller over DDS.

use std::time::Duration;

use rpkm_msgs::{ActuatorState, TcpMeasurement};
use rpkm_transport::{topic, Backend, Qos, Topic};

use super::output::Output;
use crate::error::bad_input;
use crate::node::declare::{ParamDefault, ParamSpec};
use crate::node::{bad_param, shutdown, Idle, NodeContext};

/// Default DDS topic of the controller's drive states.
pub const ACTUATOR_TOPIC: &str = "/rpkm/controller/actuator_state";
/// Default DDS topic of the controller's measurements.
pub const MEASUREMENT_TOPIC: &str = "/rpkm/controller/tcp_measurement";

/// Parameter `input_actuator_topic`.
pub const ACTUATOR_TOPIC_PARAM: ParamSpec = ParamSpec::fixed(
    "input_actuator_topic",
    ParamDefault::Str(ACTUATOR_TOPIC),
    "DDS topic of the drive states (source dds)",
);
/// Parameter `input_measurement_topic`.
pub const MEASUREMENT_TOPIC_PARAM: ParamSpec = ParamSpec::fixed(
    "input_measurement_topic",
    ParamDefault::Str(MEASUREMENT_TOPIC),
    "DDS topic of the measurements (source dds)",
);

/// A topic name that lives as long as the node (the transport keeps `&'static str` names).
fn leak(s: String) -> &'static str {
    Box::leak(s.into_boxed_str())
}

/// Republishes what the controller sends until shutdown.
pub(super) fn run(ctx: &NodeContext, out: &mut Output<'_>) -> anyhow::Result<()> {
    let p = &ctx.params;
    let a_name = leak(ACTUATOR_TOPIC_PARAM.string(p).map_err(bad_param)?);
    let m_name = leak(MEASUREMENT_TOPIC_PARAM.string(p).map_err(bad_param)?);
    if ctx.output != Backend::Ipc
        && (a_name == topic::ACTUATOR_STATE.name() || m_name == topic::TCP_MEASUREMENT.name())
    {
        return Err(bad_input(format!(
            "ingest: input topics {a_name}, {m_name} would also receive this node's own \
             DDS output; use other input topics or --backend ipc"
        )));
    }
    let a_topic: Topic<ActuatorState> = Topic::new(a_name, topic::ACTUATOR_STATE.qos());
    let m_topic: Topic<TcpMeasurement> = Topic::new(m_name, Qos::reliable(256));
    let states = ctx.transport.subscriber_on(&a_topic, Backend::Dds)?;
    let measurements = ctx.transport.subscriber_on(&m_topic, Backend::Dds)?;
    let mut idle = Idle::new(Duration::from_millis(50), Duration::from_micros(500));
    while !shutdown::requested() {
        let mut worked = false;
        while let Some(s) = states.try_recv()? {
            worked = true;
            out.state(&s, a_name)?;
        }
        while let Some(m) = measurements.try_recv()? {
            worked = true;
            out.live_measurement(&m, m_name)?;
        }
        out.report_if_due()?;
        if worked {
            idle.worked();
        } else {
            idle.wait();
        }
    }
    Ok(())
}
