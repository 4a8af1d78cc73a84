//! What each rpkm program may do on DDS: the governance of the domain and the grant of each
//! enclave, as the DDS topic names the programs open (`rt/` topics, `rq/`…`Request` and
//! `rr/`…`Reply` for services, as rmw names them).
//!
//! The grants are built from the names the programs use: the topic constants
//! (`rpkm_transport::topic`), the service names of the parameter, lifecycle and calibration
//! servers, and the topics ros2-client opens for every participant. Nothing else: a node
//! granted only these cannot publish an end marker it never publishes, nor call a service.

use std::collections::BTreeSet;
use std::fmt::Write as _;

use rpkm_transport::{topic, Names};

use rpkm_nodes::node::joint_input::JOINT_STATES_TOPIC;

/// rpkm's programs that have a default grant, by the last part of their enclave's name
/// (`rpkm security enclave --all` makes one enclave for each).
pub const PROGRAMS: [&str; 8] = [
    "ingest",
    "tcp_estimator",
    "calibrator",
    "preload_monitor",
    "record",
    "replay",
    "monitor",
    "launch",
];

/// The default grant of a cell controller's enclave (`--node cell`, an enclave named by the
/// cell: `/cell/controller`): not one of rpkm's programs, so not in [`PROGRAMS`].
pub const CELL: &str = "cell";

/// The DDS topics a grant allows to publish and to subscribe.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Grant {
    /// DDS topic names written.
    pub publish: BTreeSet<String>,
    /// DDS topic names read.
    pub subscribe: BTreeSet<String>,
}

/// The parameter services every rpkm node answers (`rpkm_transport::dds_params`).
const PARAMETER_SERVICES: [&str; 6] = [
    "list_parameters",
    "describe_parameters",
    "get_parameters",
    "get_parameter_types",
    "set_parameters",
    "set_parameters_atomically",
];

/// The lifecycle services of a managed node (`nodes/src/node/lifecycle.rs`).
const LIFECYCLE_SERVICES: [&str; 4] = [
    "change_state",
    "get_state",
    "get_available_states",
    "get_available_transitions",
];

/// The calibration services of the nodes that hold a geometry
/// (`nodes/src/node/calibration_services.rs`).
const CALIBRATION_SERVICES: [&str; 2] = ["load_calibration", "save_calibration"];

/// The calibrator's action `~/calibrate` (`nodes/src/node/calibrate_action.rs`): its three
/// services and its two topics, as ROS 2 names an action's parts.
const CALIBRATE_ACTION: &str = "calibrate";
const ACTION_SERVICES: [&str; 3] = ["send_goal", "cancel_goal", "get_result"];
const ACTION_TOPICS: [&str; 2] = ["feedback", "status"];

/// The topics ros2-client opens in every participant: the ROS graph (`ros_discovery_info`,
/// written and read), the node's log and parameter events, and the `/clock` topic it creates
/// for simulated time.
fn participant(g: &mut Grant) {
    g.publish.insert("ros_discovery_info".into());
    g.subscribe.insert("ros_discovery_info".into());
    g.publish.insert("rt/rosout".into());
    g.publish.insert("rt/parameter_events".into());
    g.subscribe.insert("rt/clock".into());
}

/// Builds a grant from ROS names, resolved in a namespace as the programs resolve them.
struct Builder {
    names: Names,
    namespace: String,
    grant: Grant,
}

impl Builder {
    fn topic(name: &str) -> String {
        format!("rt{name}")
    }
    fn publish(&mut self, ros: &[&str]) {
        for n in ros {
            let dds = Self::topic(&self.names.resolve(n));
            self.grant.publish.insert(dds);
        }
    }
    fn subscribe(&mut self, ros: &[&str]) {
        for n in ros {
            let dds = Self::topic(&self.names.resolve(n));
            self.grant.subscribe.insert(dds);
        }
    }
    /// Services of node `node` that it answers: reads requests, writes replies.
    fn serve(&mut self, node: &str, services: &[&str]) {
        for s in services {
            let fqn = format!("{}/{node}/{s}", self.namespace);
            self.grant.subscribe.insert(format!("rq{fqn}Request"));
            self.grant.publish.insert(format!("rr{fqn}Reply"));
        }
    }
    /// Services of node `node` that this program calls: writes requests, reads replies.
    fn call(&mut self, node: &str, services: &[&str]) {
        for s in services {
            let fqn = format!("{}/{node}/{s}", self.namespace);
            self.grant.publish.insert(format!("rq{fqn}Request"));
            self.grant.subscribe.insert(format!("rr{fqn}Reply"));
        }
    }
    /// A node's own parameter and lifecycle services and `~/transition_event` (every node is
    /// a managed node); for the nodes that hold a geometry (all but ingest) the calibration
    /// services.
    fn node(&mut self, node: &str, holds_geometry: bool) {
        self.serve(node, &PARAMETER_SERVICES);
        self.serve(node, &LIFECYCLE_SERVICES);
        let event = format!("rt{}/{node}/transition_event", self.namespace);
        self.grant.publish.insert(event);
        if holds_geometry {
            self.serve(node, &CALIBRATION_SERVICES);
        }
    }
    /// An action `action` that node `node` serves: its services and its topics.
    fn serve_action(&mut self, node: &str, action: &str) {
        let services = ACTION_SERVICES.map(|s| format!("{action}/_action/{s}"));
        let services: Vec<&str> = services.iter().map(String::as_str).collect();
        self.serve(node, &services);
        for t in ACTION_TOPICS {
            let topic = format!("rt{}/{node}/{action}/_action/{t}", self.namespace);
            self.grant.publish.insert(topic);
        }
    }
}

/// Why a grant cannot be made.
#[derive(Debug, thiserror::Error)]
pub enum PolicyError {
    /// The program has no default grant.
    #[error("no default permissions for {program:?}: expected one of {}, {CELL} (--node)", PROGRAMS.join(", "))]
    UnknownProgram {
        /// The name given.
        program: String,
    },
    /// A topic given is not an absolute ROS 2 name.
    #[error("topic {topic:?}: {reason}")]
    Topic {
        /// The name given.
        topic: String,
        /// rpkm_transport's words.
        reason: String,
    },
    /// The namespace is not a ROS 2 namespace.
    #[error("--namespace {namespace:?}: {reason}")]
    Namespace {
        /// The name given.
        namespace: String,
        /// rpkm_transport's words.
        reason: String,
    },
}

/// The default grant of `program` (one of [`PROGRAMS`]) for a node set in `namespace`
/// (`/rpkm` by default; the nodes' topics and services move with it, `/diagnostics`, `/tf`
/// and `/joint_states` stay).
pub fn grant(program: &str, namespace: &str) -> Result<Grant, PolicyError> {
    let names = Names::new(namespace, &[]).map_err(|e| PolicyError::Namespace {
        namespace: namespace.to_owned(),
        reason: e.to_string(),
    })?;
    let mut b = Builder {
        namespace: names.namespace().trim_end_matches('/').to_owned(),
        names,
        grant: Grant::default(),
    };
    participant(&mut b.grant);
    let every: Vec<&str> = rpkm_nodes::topics::ALL.to_vec();
    match program {
        "ingest" => ingest(&mut b),
        "tcp_estimator" => tcp_estimator(&mut b),
        "calibrator" => calibrator(&mut b),
        "preload_monitor" => preload_monitor(&mut b),
        "record" | "monitor" => b.subscribe(&every),
        "replay" => b.publish(&every),
        "launch" => {
            for node in ["ingest", "tcp_estimator", "calibrator", "preload_monitor"] {
                b.call(node, &LIFECYCLE_SERVICES[..2]);
            }
        }
        CELL => cell(&mut b),
        other => {
            return Err(PolicyError::UnknownProgram {
                program: other.to_owned(),
            })
        }
    }
    Ok(b.grant)
}

/// A cell controller driving the set as a ROS 2 cell does: every node's parameter,
/// lifecycle and calibration services, the calibrator's action (its services, its feedback
/// and status read), and `/parameter_events` read.
fn cell(b: &mut Builder) {
    for node in ["ingest", "tcp_estimator", "calibrator", "preload_monitor"] {
        b.call(node, &PARAMETER_SERVICES);
        b.call(node, &LIFECYCLE_SERVICES);
        if node != "ingest" {
            b.call(node, &CALIBRATION_SERVICES);
        }
    }
    let services = ACTION_SERVICES.map(|s| format!("{CALIBRATE_ACTION}/_action/{s}"));
    let services: Vec<&str> = services.iter().map(String::as_str).collect();
    b.call("calibrator", &services);
    for t in ACTION_TOPICS {
        let topic = format!(
            "rt{}/calibrator/{CALIBRATE_ACTION}/_action/{t}",
            b.namespace
        );
        b.grant.subscribe.insert(topic);
    }
    b.grant.subscribe.insert("rt/parameter_events".into());
}

fn ingest(b: &mut Builder) {
    b.publish(&[
        topic::ACTUATOR_STATE.name(),
        topic::TCP_MEASUREMENT.name(),
        topic::CAMPAIGN_INFO.name(),
        topic::DIAGNOSTICS.name(),
        topic::JOINT_STATES.name(),
    ]);
    // the controller's topics, ingest's DDS source (parameters input_*_topic), and the
    // broadcaster's JointState of its joint_states source (a thermometer's topic is the
    // cell's own: `rpkm security enclave --subscribe TOPIC`)
    b.subscribe(&[
        rpkm_nodes::node::ingest::ACTUATOR_INPUT,
        rpkm_nodes::node::ingest::MEASUREMENT_INPUT,
        JOINT_STATES_TOPIC,
    ]);
    b.node("ingest", false);
}

fn tcp_estimator(b: &mut Builder) {
    // JointState: its drive states read directly (source joint_states)
    b.subscribe(&[
        topic::ACTUATOR_STATE.name(),
        topic::PARAMETERS.name(),
        JOINT_STATES_TOPIC,
    ]);
    b.publish(&[
        topic::TCP_ESTIMATE.name(),
        topic::DIAGNOSTICS.name(),
        topic::TCP_POSE.name(),
        topic::TF.name(),
    ]);
    b.node("tcp_estimator", true);
}

fn calibrator(b: &mut Builder) {
    b.subscribe(&[
        topic::ACTUATOR_STATE.name(),
        topic::TCP_MEASUREMENT.name(),
        topic::CAMPAIGN_INFO.name(),
    ]);
    b.publish(&[
        topic::PARAMETERS.name(),
        topic::DIAGNOSIS.name(),
        topic::DIAGNOSTICS.name(),
    ]);
    b.node("calibrator", true);
    b.serve_action("calibrator", CALIBRATE_ACTION);
}

fn preload_monitor(b: &mut Builder) {
    b.subscribe(&[
        topic::ACTUATOR_STATE.name(),
        topic::PARAMETERS.name(),
        JOINT_STATES_TOPIC,
    ]);
    b.publish(&[topic::PRELOAD_STATUS.name(), topic::DIAGNOSTICS.name()]);
    b.node("preload_monitor", true);
}

/// `grant` with the cell's own topics a program also reads and writes (ROS names, resolved
/// in `namespace` as the program resolves them): a thermometer ingest reads, the topics of a
/// cell program that has an enclave of this keystore.
pub fn with_topics(
    mut grant: Grant,
    namespace: &str,
    (publish, subscribe): (&[String], &[String]),
) -> Result<Grant, PolicyError> {
    let names = Names::new(namespace, &[]).map_err(|e| PolicyError::Namespace {
        namespace: namespace.to_owned(),
        reason: e.to_string(),
    })?;
    for (topics, set) in [
        (publish, &mut grant.publish),
        (subscribe, &mut grant.subscribe),
    ] {
        for t in topics {
            if let Some(reason) = rpkm_transport::names::absolute_name_error(t) {
                return Err(PolicyError::Topic {
                    topic: t.clone(),
                    reason,
                });
            }
            set.insert(format!("rt{}", names.resolve(t)));
        }
    }
    Ok(grant)
}

/// The program an enclave's name stands for: its last part (`/rpkm/tcp_estimator`).
pub fn program_of(enclave: &str) -> &str {
    enclave.rsplit('/').next().unwrap_or(enclave)
}

/// Domains a keystore's documents cover, so that the same keystore serves whichever
/// `ROS_DOMAIN_ID` the cell uses: 0 to 230, the highest id Cyclone DDS accepts in these
/// documents (with 232, ROS 2's highest, it refuses to parse them: "failed in data
/// callback").
const DOMAINS: &str = "<domains><id_range><min>0</min><max>230</max></id_range></domains>";

/// The governance: no unauthenticated participant, join access control, and discovery,
/// liveliness, every RTPS message and every topic's submessages encrypted (AES-GCM), which
/// carries each sample's data encrypted twice over.
///
/// `data_protection_kind` (a second, end-to-end encryption of the serialized payload alone,
/// for data that crosses relays) is `NONE`: with `ENCRYPT` or `SIGN` RustDDS 0.15.1 cannot
/// read its own protected payloads (every sample between two rpkm processes fails to decode:
/// ring's "Unspecified" error, tried here); the loopback capture of tests/it/security_cell.rs
/// shows no estimate in clear without it.
pub fn governance_xml() -> String {
    format!(
        r#"<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"
    xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_governance.xsd">
  <domain_access_rules>
    <domain_rule>
      {DOMAINS}
      <allow_unauthenticated_participants>false</allow_unauthenticated_participants>
      <enable_join_access_control>true</enable_join_access_control>
      <discovery_protection_kind>ENCRYPT</discovery_protection_kind>
      <liveliness_protection_kind>ENCRYPT</liveliness_protection_kind>
      <rtps_protection_kind>ENCRYPT</rtps_protection_kind>
      <topic_access_rules>
        <topic_rule>
          <topic_expression>*</topic_expression>
          <enable_discovery_protection>true</enable_discovery_protection>
          <enable_liveliness_protection>true</enable_liveliness_protection>
          <enable_read_access_control>true</enable_read_access_control>
          <enable_write_access_control>true</enable_write_access_control>
          <metadata_protection_kind>ENCRYPT</metadata_protection_kind>
          <data_protection_kind>NONE</data_protection_kind>
        </topic_rule>
      </topic_access_rules>
    </domain_rule>
  </domain_access_rules>
</dds>
"#
    )
}

/// The validity of a grant, as the permissions document writes it (UTC, no zone).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Validity {
    /// `YYYY-MM-DDTHH:MM:SS`.
    pub not_before: String,
    /// `YYYY-MM-DDTHH:MM:SS`.
    pub not_after: String,
}

/// The permissions document of `enclave`: one grant for the subject `CN=<enclave>` (the
/// subject of the enclave's certificate), denying what `grant` does not allow.
pub fn permissions_xml(enclave: &str, grant: &Grant, validity: &Validity) -> String {
    let topics = |set: &BTreeSet<String>| {
        set.iter().fold(String::new(), |mut out, t| {
            let _ = writeln!(out, "            <topic>{t}</topic>");
            out
        })
    };
    format!(
        r#"<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"
    xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_permissions.xsd">
  <permissions>
    <grant name="{enclave}">
      <subject_name>CN={enclave}</subject_name>
      <validity>
        <not_before>{}</not_before>
        <not_after>{}</not_after>
      </validity>
      <allow_rule>
        {DOMAINS}
        <publish>
          <topics>
{}          </topics>
        </publish>
        <subscribe>
          <topics>
{}          </topics>
        </subscribe>
      </allow_rule>
      <default>DENY</default>
    </grant>
  </permissions>
</dds>
"#,
        validity.not_before,
        validity.not_after,
        topics(&grant.publish),
        topics(&grant.subscribe),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_estimator_may_write_estimates_but_never_an_end_marker() {
        let g = grant("tcp_estimator", "/rpkm").expect("known program");
        assert!(g.publish.contains("rt/rpkm/tcp_estimate"));
        assert!(g.subscribe.contains("rt/rpkm/actuator_state"));
        assert!(!g.publish.contains("rt/rpkm/campaign_info"));
        assert!(!g.publish.contains("rt/rpkm/actuator_state"));
        assert!(g
            .subscribe
            .contains("rq/rpkm/tcp_estimator/set_parametersRequest"));
        assert!(g
            .publish
            .contains("rr/rpkm/tcp_estimator/set_parametersReply"));
        // it answers its own services, never calls another node's
        assert!(!g.publish.iter().any(|t| t.starts_with("rq/")));
    }

    #[test]
    fn a_cell_controller_calls_what_the_nodes_serve_and_serves_nothing() {
        let cell = grant(CELL, "/rpkm").expect("grant");
        let nodes: Vec<Grant> = ["ingest", "tcp_estimator", "calibrator", "preload_monitor"]
            .iter()
            .map(|n| grant(n, "/rpkm").expect("grant"))
            .collect();
        // every request the cell writes a node reads, every reply it reads a node writes
        for t in cell.publish.iter().filter(|t| t.starts_with("rq")) {
            assert!(
                nodes.iter().any(|g| g.subscribe.contains(t)),
                "{t} served by none"
            );
        }
        for t in cell.subscribe.iter().filter(|t| t.starts_with("rr")) {
            assert!(
                nodes.iter().any(|g| g.publish.contains(t)),
                "{t} written by none"
            );
        }
        assert!(cell
            .publish
            .contains("rq/rpkm/ingest/set_parametersRequest"));
        assert!(cell
            .subscribe
            .contains("rr/rpkm/ingest/set_parametersReply"));
        assert!(cell
            .publish
            .contains("rq/rpkm/calibrator/calibrate/_action/send_goalRequest"));
        assert!(cell
            .subscribe
            .contains("rt/rpkm/calibrator/calibrate/_action/feedback"));
        assert!(
            !cell.subscribe.iter().any(|t| t.starts_with("rq")),
            "serves nothing"
        );
        assert!(
            !cell.publish.iter().any(|t| t.starts_with("rr")),
            "serves nothing"
        );
    }

    #[test]
    fn the_calibrator_serves_its_action_and_ingest_its_lifecycle() {
        let g = grant("calibrator", "/rpkm").expect("grant");
        for s in ["send_goal", "cancel_goal", "get_result"] {
            let fqn = format!("/rpkm/calibrator/calibrate/_action/{s}");
            assert!(g.subscribe.contains(&format!("rq{fqn}Request")), "{s}");
            assert!(g.publish.contains(&format!("rr{fqn}Reply")), "{s}");
        }
        assert!(g
            .publish
            .contains("rt/rpkm/calibrator/calibrate/_action/feedback"));
        assert!(g
            .publish
            .contains("rt/rpkm/calibrator/calibrate/_action/status"));
        let ingest = grant("ingest", "/rpkm").expect("grant");
        assert!(ingest
            .subscribe
            .contains("rq/rpkm/ingest/change_stateRequest"));
        assert!(ingest.publish.contains("rt/rpkm/ingest/transition_event"));
        assert!(!ingest
            .subscribe
            .iter()
            .any(|t| t.contains("load_calibration")));
    }

    #[test]
    fn a_cell_reads_its_joint_states_and_thermometers_with_topics_granted() {
        let ingest = grant("ingest", "/rpkm").expect("grant");
        assert!(ingest.subscribe.contains("rt/joint_states"));
        assert!(!ingest.subscribe.contains("rt/cell/frame_temperature"));
        let cell = with_topics(
            ingest,
            "/rpkm",
            (&[], &["/cell/frame_temperature".to_owned()]),
        )
        .expect("topics");
        assert!(cell.subscribe.contains("rt/cell/frame_temperature"));
        let bad = with_topics(cell, "/rpkm", (&["cell/t".to_owned()], &[]));
        assert!(
            matches!(&bad, Err(PolicyError::Topic { topic, .. }) if topic == "cell/t"),
            "{bad:?}"
        );
    }

    #[test]
    fn a_namespace_moves_the_sets_topics_and_services_not_the_global_ones() {
        let g = grant("preload_monitor", "/machine_a").expect("known program");
        assert!(g.publish.contains("rt/machine_a/preload_status"));
        assert!(g.publish.contains("rt/diagnostics"));
        assert!(g
            .subscribe
            .contains("rq/machine_a/preload_monitor/get_parametersRequest"));
        assert!(!g.publish.iter().any(|t| t.contains("/rpkm/")));
    }

    #[test]
    fn the_recorder_reads_and_the_replayer_writes_every_rpkm_topic() {
        let r = grant("record", "/rpkm").expect("record");
        let p = grant("replay", "/rpkm").expect("replay");
        for t in rpkm_nodes::topics::ALL {
            let dds = format!("rt{t}");
            assert!(
                r.subscribe.contains(&dds) && !r.publish.contains(&dds),
                "{t}"
            );
            assert!(
                p.publish.contains(&dds) && !p.subscribe.contains(&dds),
                "{t}"
            );
        }
        assert!(matches!(
            grant("nosuch", "/rpkm"),
            Err(PolicyError::UnknownProgram { .. })
        ));
    }
}
