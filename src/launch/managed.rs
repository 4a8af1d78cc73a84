//! Bringing the launch's managed nodes (`managed: true`, started `--unconfigured`) up in file
//! order, as a ROS 2 launch brings up its lifecycle nodes: for each, wait until its
//! `~/get_state` answers, then `~/change_state` configure, then activate; the next node only
//! once this one is active. A transition that fails stops the bring-up there (the node says
//! why in its log); the others stay unconfigured.

use std::time::Duration;

use rpkm_msgs::lifecycle_msgs::{
    ChangeStateRequest, ChangeStateResponse, EmptyRequest, GetStateResponse, State, Transition,
};
use rpkm_transport::dds_calls::{CallClient, ServiceType};
use rpkm_transport::{Backend, Names, Transport, TransportConfig};

use super::description::{LaunchDescription, NodeSpec};

/// How long a managed node may take to answer its first `~/get_state` (its start, DDS
/// discovery).
const START_TIMEOUT: Duration = Duration::from_secs(60);
/// How long one request waits for its reply before it is asked again.
const REPLY_WAIT: Duration = Duration::from_secs(2);

fn log(msg: impl std::fmt::Display) {
    rpkm_nodes::node::log_line("launch", msg);
}

fn kind(name: &'static str) -> ServiceType {
    ServiceType {
        package: "lifecycle_msgs",
        name,
    }
}

/// The lifecycle clients of one node.
struct Clients {
    get: CallClient<EmptyRequest, GetStateResponse>,
    change: CallClient<ChangeStateRequest, ChangeStateResponse>,
}

impl Clients {
    fn open(
        dds: &std::sync::Arc<rpkm_transport::dds::DdsNode>,
        node: &str,
    ) -> anyhow::Result<Self> {
        Ok(Self {
            get: dds.client(&format!("{node}/get_state"), kind("GetState"))?,
            change: dds.client(&format!("{node}/change_state"), kind("ChangeState"))?,
        })
    }

    /// The node's state, asked until it answers or `timeout` passed.
    async fn state(&self, timeout: Duration) -> Option<u8> {
        let deadline = tokio::time::Instant::now() + timeout;
        while tokio::time::Instant::now() < deadline {
            if let Some(r) = self
                .get
                .call_once(EmptyRequest::default(), REPLY_WAIT)
                .await
            {
                return Some(r.current_state.id);
            }
        }
        None
    }

    /// Performs transition `id` towards `goal`: a request without a reply is asked again
    /// only after `~/get_state` shows the node did not take it (a change must not be
    /// applied twice).
    async fn transition(&self, id: u8, goal: u8) -> Result<(), String> {
        for _ in 0..5 {
            let request = ChangeStateRequest {
                transition: Transition::new(id, ""),
            };
            match self.change.call_once(request, REPLY_WAIT).await {
                Some(r) if r.success => return Ok(()),
                Some(_) => return Err("the node refused or failed it".into()),
                None => match self.state(REPLY_WAIT * 5).await {
                    Some(s) if s == goal => return Ok(()),
                    Some(_) => {}
                    None => return Err("the node no longer answers".into()),
                },
            }
        }
        Err("no reply after 5 requests".into())
    }
}

/// The node's fully qualified name: `/rpkm/tcp_estimator`, `/machine_a/tcp_estimator`.
fn fqn(spec: &NodeSpec) -> String {
    let ns = spec
        .namespace
        .as_deref()
        .unwrap_or(rpkm_transport::NODE_NAMESPACE)
        .trim_end_matches('/');
    format!("{ns}/{}", spec.name)
}

/// The DDS side of the bring-up: a node of the launch's own in the nodes' domain.
fn transport(desc: &LaunchDescription) -> anyhow::Result<Transport> {
    let mut config = TransportConfig::new(format!("rpkm_launch_{}", std::process::id()))
        .backend(Backend::Dds)
        .names(Names::default())
        .enclave("/rpkm/launch");
    if let Some((_, d)) = desc.env.iter().rev().find(|(k, _)| k == "ROS_DOMAIN_ID") {
        let domain = d
            .parse()
            .map_err(|_| anyhow::anyhow!("ROS_DOMAIN_ID {d:?}: expected a domain id"))?;
        config = config.dds_domain(domain);
    }
    Ok(Transport::new(&config)?)
}

/// Configures and activates every managed node of `desc`, in file order.
pub async fn bring_up(desc: &LaunchDescription) {
    let managed: Vec<&NodeSpec> = desc.nodes.iter().filter(|n| n.managed).collect();
    if managed.is_empty() {
        return;
    }
    let transport = match transport(desc) {
        Ok(t) => t,
        Err(e) => return log(format!("managed nodes not brought up: {e:#}")),
    };
    let Some(dds) = transport.dds_node() else {
        return;
    };
    for spec in managed {
        let node = fqn(spec);
        let clients = match Clients::open(dds, &node) {
            Ok(c) => c,
            Err(e) => return log(format!("{}: lifecycle clients: {e:#}", spec.name)),
        };
        if clients.state(START_TIMEOUT).await.is_none() {
            return log(format!(
                "{}: no answer on {node}/get_state within {} s: not brought up (nor the \
                 managed nodes after it)",
                spec.name,
                START_TIMEOUT.as_secs()
            ));
        }
        for (id, goal, label) in [
            (
                Transition::TRANSITION_CONFIGURE,
                State::PRIMARY_STATE_INACTIVE,
                "configured",
            ),
            (
                Transition::TRANSITION_ACTIVATE,
                State::PRIMARY_STATE_ACTIVE,
                "active",
            ),
        ] {
            if let Err(why) = clients.transition(id, goal).await {
                return log(format!(
                    "{}: not {label}: {why} (its lines above say why); the managed nodes \
                     after it stay unconfigured",
                    spec.name
                ));
            }
            log(format!("{} {label}", spec.name));
        }
    }
}
