//! DDS backend through ros2-client (RustDDS): interoperates with every ROS 2 vendor.
//!
//! Topic `/rpkm/x` is the DDS topic `rt/rpkm/x`, type `rpkm_msgs::msg::dds_::Name_`, CDR
//! (XCDR1) payload. The domain id comes from [`domain_id_from_env`] (`ROS_DOMAIN_ID`,
//! default 0) unless the configuration names one.
//!
//! The node's non-real-time DDS side (parameter services, `/parameter_events`, `/rosout`)
//! runs on a current-thread tokio runtime in a thread of its own ([`DdsRuntime`]), beside the
//! node: a sample loop hands it work through a channel and never waits for the wire.

use std::sync::{Arc, Mutex};

use ros2_client::{
    qos::{Durability as RDurability, History, Reliability as RReliability, WhenFull},
    Context, ContextOptions, MessageTypeName, Name, Node, NodeName, NodeOptions, QosProfile,
};
use rpkm_msgs::RosMessage;
use serde::{Deserialize, Serialize};

use crate::error::TransportError;
use crate::topic::{Durability, Qos, Reliability, Topic};

const BACKEND: &str = "dds";
/// Largest DDS domain id ROS 2 allows with the default port mapping.
const MAX_DOMAIN_ID: u16 = 232;

/// Reads `ROS_DOMAIN_ID`: unset or empty gives 0; anything but an integer in 0..=232 is an
/// error.
pub fn domain_id_from_env() -> Result<u16, TransportError> {
    match std::env::var("ROS_DOMAIN_ID") {
        Err(_) => Ok(0),
        Ok(v) if v.trim().is_empty() => Ok(0),
        Ok(v) => match v.trim().parse::<u16>() {
            Ok(d) if d <= MAX_DOMAIN_ID => Ok(d),
            _ => Err(TransportError::DomainId { value: v }),
        },
    }
}

/// Severity of a `/rosout` record.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RosoutLevel {
    /// 10.
    Debug,
    /// 20.
    Info,
    /// 30.
    Warn,
    /// 40.
    Error,
}

/// A message as ros2-client sees it: the same serde form, with ros2-client's marker trait.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(transparent)]
pub(crate) struct Wire<T>(pub(crate) T);

impl<T: RosMessage> ros2_client::Message for Wire<T> {}

/// The ros2-client QoS of a topic QoS.
pub fn qos_profile(qos: Qos) -> QosProfile {
    let reliability = match qos.reliability {
        Reliability::BestEffort => RReliability::BestEffort,
        Reliability::Reliable => RReliability::Reliable {
            when_full: WhenFull::DEFAULT,
        },
    };
    let durability = match qos.durability {
        Durability::Volatile => RDurability::Volatile,
        Durability::TransientLocal => RDurability::TransientLocal,
    };
    QosProfile::publisher_default()
        .reliability(reliability)
        .durability(durability)
        .history(History::KeepLast {
            depth: qos.depth.max(1),
        })
}

/// Records a `/rosout` queue holds before the node's log lines are counted as dropped: a
/// node logs a few lines per report period, a queue this long is a stuck runtime.
const ROSOUT_QUEUE: usize = 1024;

/// One `/rosout` record on its way to the runtime.
struct RosoutRecord {
    level: RosoutLevel,
    msg: String,
    file: String,
    line: u32,
    stamp: ros2_client::builtin_interfaces::Time,
}

/// The node's tokio runtime (current thread) on a thread of its own: the `/rosout` writer
/// and the tasks others spawn on [`Self::handle`] (the parameter services). Dropping it
/// writes the queued `/rosout` records, stops the tasks and joins the thread.
struct DdsRuntime {
    handle: tokio::runtime::Handle,
    rosout: tokio::sync::mpsc::Sender<RosoutRecord>,
    /// Records refused by a full queue since the last one that went through.
    rosout_dropped: std::sync::atomic::AtomicU64,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl DdsRuntime {
    fn start(
        name: &str,
        writer: ros2_client::rosout::NodeLoggingHandle,
        logger: String,
    ) -> std::io::Result<Self> {
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_time()
            .build()?;
        let handle = runtime.handle().clone();
        let (tx, mut rx) = tokio::sync::mpsc::channel::<RosoutRecord>(ROSOUT_QUEUE);
        let (stop_tx, mut stop_rx) = tokio::sync::oneshot::channel::<()>();
        let thread = std::thread::Builder::new()
            .name(format!("rpkm-dds-{name}"))
            .spawn(move || {
                runtime.block_on(async {
                    loop {
                        tokio::select! {
                            Some(r) = rx.recv() => write_rosout(&writer, &logger, &r),
                            _ = &mut stop_rx => break,
                        }
                    }
                    // The node's last lines (why it stopped) still reach /rosout.
                    while let Ok(r) = rx.try_recv() {
                        write_rosout(&writer, &logger, &r);
                    }
                });
            })?;
        Ok(Self {
            handle,
            rosout: tx,
            rosout_dropped: std::sync::atomic::AtomicU64::new(0),
            stop: Some(stop_tx),
            thread: Some(thread),
        })
    }
}

impl Drop for DdsRuntime {
    fn drop(&mut self) {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        if let Some(t) = self.thread.take() {
            // Never join from the runtime's own thread (a task holding the last reference).
            if t.thread().id() != std::thread::current().id() {
                let _ = t.join();
            }
        }
    }
}

fn write_rosout(w: &ros2_client::rosout::NodeLoggingHandle, logger: &str, r: &RosoutRecord) {
    use ros2_client::rosout::RosoutRaw;
    let level = match r.level {
        RosoutLevel::Debug => ros2_client::ros2::LogLevel::Debug,
        RosoutLevel::Info => ros2_client::ros2::LogLevel::Info,
        RosoutLevel::Warn => ros2_client::ros2::LogLevel::Warn,
        RosoutLevel::Error => ros2_client::ros2::LogLevel::Error,
    };
    w.rosout_raw(r.stamp, level, logger, &r.msg, &r.file, "", r.line);
}

/// A DDS participant with one ROS 2 node.
pub struct DdsNode {
    /// The `/rosout` writer and the parameter services' runtime; first, so that it drains
    /// its queue while the node still exists.
    runtime: DdsRuntime,
    pub(crate) node: Mutex<Node>,
    /// The participant the services' own readers and writers join ([`crate::dds_rpc`]).
    participant: ros2_client::dds::rustdds::DomainParticipant,
    /// Requests of this node's services that could not be read, for its /diagnostics.
    unread: crate::dds_rpc::Ledger,
    domain: u16,
}

impl std::fmt::Debug for DdsNode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DdsNode")
            .field("domain", &self.domain)
            .finish_non_exhaustive()
    }
}

impl DdsNode {
    /// Joins `domain` with a node `<namespace>/<name>`, with a `/rosout` writer ([`Self::rosout`])
    /// and a `/parameter_events` writer; with DDS Security where `credentials` are given
    /// (SROS2's enclave folder). The parameter services are rpkm's own
    /// ([`crate::dds_params`]), started by [`Self::serve_parameters`].
    pub fn new(
        name: &str,
        namespace: &str,
        domain: u16,
        credentials: Option<&crate::security::Credentials>,
    ) -> Result<Arc<Self>, TransportError> {
        let err = |reason: String| TransportError::DdsNode {
            node: name.to_owned(),
            domain,
            reason,
        };
        let mut options = ContextOptions::new().domain_id(domain);
        if let Some(c) = credentials {
            // sros2 writes the private key unencrypted (PKCS#8), as rmw expects it.
            options = options.enable_security(&c.dir, String::new());
        }
        let context = Context::with_options(options).map_err(|e| match credentials {
            Some(c) => err(format!("DDS security with enclave {}: {e}", c.enclave)),
            None => err(e.to_string()),
        })?;
        let node_name = NodeName::new(namespace, name).map_err(|e| err(format!("{e:?}")))?;
        let node = context
            .new_node(
                node_name,
                // ros2-client's store is used for the events only: every parameter rpkm
                // declares goes through it undeclared, checked by rpkm's own services.
                NodeOptions::new()
                    .enable_rosout(true)
                    .start_parameter_services(false)
                    .allow_undeclared_parameters(true),
            )
            .map_err(|e| err(format!("{e:?}")))?;
        // rcl's logger name: the namespace's parts and the node's, joined by `.`
        let logger = namespace
            .split('/')
            .filter(|p| !p.is_empty())
            .chain([name])
            .collect::<Vec<_>>()
            .join(".");
        let runtime = DdsRuntime::start(name, node.logging_handle(), logger)
            .map_err(|e| err(format!("starting the DDS runtime: {e}")))?;
        Ok(Arc::new(Self {
            runtime,
            node: Mutex::new(node),
            participant: context.domain_participant(),
            unread: crate::dds_rpc::Ledger::default(),
            domain,
        }))
    }

    /// The node's tokio runtime, for its non-real-time DDS tasks.
    pub(crate) fn runtime(&self) -> &tokio::runtime::Handle {
        &self.runtime.handle
    }

    /// The server of this node's service `~/<service>` (`/rpkm/ingest/<service>`), for
    /// clients of either request mapping.
    pub(crate) fn rpc_server<Q, R>(
        &self,
        service: &str,
        types: &crate::dds_rpc::RpcTypes,
    ) -> Result<crate::dds_rpc::RpcServer<Q, R>, String>
    where
        Q: serde::de::DeserializeOwned,
        R: Serialize,
    {
        let fqn = self
            .node
            .lock()
            .map_err(|_| "the DDS node mutex is poisoned".to_owned())?
            .fully_qualified_name();
        let name = format!("{}/{service}", fqn.trim_end_matches('/'));
        // ROS 2's rules for the name, checked as ros2-client checks a service's.
        Name::parse(&name).map_err(|e| format!("~/{service}: {e:?}"))?;
        crate::dds_rpc::RpcServer::new(&self.participant, &name, types, self.unread.clone())
    }

    /// The participant, for the readers and writers ros2-client does not make.
    pub(crate) fn participant(&self) -> &ros2_client::dds::rustdds::DomainParticipant {
        &self.participant
    }

    /// The requests of this node's services that could not be read (neither request
    /// mapping decodes them as the service's type), per service, and the replies dropped
    /// because a client's reply reader was never matched.
    pub fn unread_requests(&self) -> Vec<crate::dds_rpc::Unread> {
        self.unread.lock().map(|u| u.clone()).unwrap_or_default()
    }

    /// The DDS domain id.
    pub fn domain(&self) -> u16 {
        self.domain
    }

    /// Publishes one `rcl_interfaces/Log` on `/rosout` (rqt_console, `ros2 topic echo
    /// /rosout`, bags): `level` as ROS 2 numbers it (10 debug, 20 info, 30 warn, 40 error,
    /// 50 fatal).
    ///
    /// Queued for the node's runtime, which writes it: the caller (a sample loop) never
    /// waits for DDS. A record that finds the queue full is counted, and the count goes out
    /// with the next record that fits (never dropped unsaid).
    pub fn rosout(&self, level: RosoutLevel, msg: &str, file: &str, line: u32) {
        use std::sync::atomic::Ordering;
        let rt = &self.runtime;
        let dropped = rt.rosout_dropped.swap(0, Ordering::Relaxed);
        let msg = if dropped > 0 {
            format!("{msg} ({dropped} earlier /rosout records dropped: queue full)")
        } else {
            msg.to_owned()
        };
        let record = RosoutRecord {
            level,
            msg,
            file: file.to_owned(),
            line,
            stamp: ros2_client::builtin_interfaces::Time::now(),
        };
        if rt.rosout.try_send(record).is_err() {
            rt.rosout_dropped
                .fetch_add(dropped.saturating_add(1), Ordering::Relaxed);
        }
    }

    /// Stores `value` in ros2-client's parameter store, which publishes the
    /// `rcl_interfaces/ParameterEvent` (new or changed) on `/parameter_events`.
    pub(crate) fn publish_parameter(&self, name: &str, value: ros2_client::ParameterValue) {
        match self.node.lock() {
            Ok(node) => {
                if let Err(e) = node.set_parameter(name, value) {
                    log::warn!("/parameter_events: {name}: {e}");
                }
            }
            Err(_) => log::warn!("/parameter_events: {name}: the DDS node mutex is poisoned"),
        }
    }

    fn topic<T: RosMessage>(
        node: &mut Node,
        topic: &Topic<T>,
    ) -> Result<ros2_client::dds::rustdds::Topic, TransportError> {
        let name = Name::parse(topic.name()).map_err(|e| TransportError::TopicName {
            topic: topic.name().to_owned(),
            reason: format!("{e:?}"),
        })?;
        node.create_topic(
            &name,
            MessageTypeName::new(T::PACKAGE, T::NAME),
            &qos_profile(topic.qos()),
        )
        .map_err(|e| create_err(topic.name(), "topic", e))
    }

    pub(crate) fn publisher<T: RosMessage>(
        self: &Arc<Self>,
        topic: &Topic<T>,
    ) -> Result<DdsPublisher<T>, TransportError> {
        let mut node = self.lock(topic.name())?;
        let dds_topic = Self::topic(&mut node, topic)?;
        let publisher = node
            .create_publisher::<Wire<T>>(&dds_topic, Some(qos_profile(topic.qos())))
            .map_err(|e| create_err(topic.name(), "publisher", e))?;
        Ok(DdsPublisher {
            topic: topic.name(),
            publisher,
            _node: Arc::clone(self),
        })
    }

    pub(crate) fn subscriber<T: RosMessage>(
        self: &Arc<Self>,
        topic: &Topic<T>,
    ) -> Result<DdsSubscriber<T>, TransportError> {
        let mut node = self.lock(topic.name())?;
        let dds_topic = Self::topic(&mut node, topic)?;
        let requested = qos_profile(topic.qos());
        let subscription = node
            .create_subscription::<Wire<T>>(&dds_topic, Some(requested.clone()))
            .map_err(|e| create_err(topic.name(), "subscriber", e))?;
        Ok(DdsSubscriber {
            topic: topic.name(),
            dds_topic: ros2_client::dds::rustdds::TopicDescription::name(&dds_topic),
            requested,
            subscription,
            node: Arc::clone(self),
        })
    }

    fn lock(&self, topic: &str) -> Result<std::sync::MutexGuard<'_, Node>, TransportError> {
        self.node.lock().map_err(|_| TransportError::CreatePort {
            topic: topic.to_owned(),
            backend: BACKEND,
            port: "node",
            reason: "the DDS node mutex is poisoned".into(),
        })
    }
}

fn create_err(topic: &str, port: &'static str, e: impl std::fmt::Display) -> TransportError {
    TransportError::CreatePort {
        topic: topic.to_owned(),
        backend: BACKEND,
        port,
        reason: e.to_string(),
    }
}

/// DDS half of a [`crate::Publisher`].
pub(crate) struct DdsPublisher<T: RosMessage> {
    topic: &'static str,
    publisher: ros2_client::Publisher<Wire<T>>,
    _node: Arc<DdsNode>,
}

impl<T: RosMessage> DdsPublisher<T> {
    pub(crate) fn send(&self, msg: &T) -> Result<(), TransportError> {
        self.publisher
            .publish(Wire(msg.clone()))
            .map_err(|e| TransportError::Publish {
                topic: self.topic.to_owned(),
                backend: BACKEND,
                reason: e.to_string(),
            })
    }
}

/// DDS half of a [`crate::Subscriber`].
pub(crate) struct DdsSubscriber<T: RosMessage> {
    topic: &'static str,
    /// The DDS topic (`rt/joint_states`), as the discovered writers name theirs.
    dds_topic: String,
    /// The QoS this reader requests.
    requested: QosProfile,
    subscription: ros2_client::Subscription<Wire<T>>,
    node: Arc<DdsNode>,
}

impl<T: RosMessage> DdsSubscriber<T> {
    /// The writers of this topic discovered on the domain that offer a QoS this reader's
    /// request does not accept (DDS's RequestedIncompatibleQos: they are never matched, and
    /// nothing they write arrives), each as `GUID offers POLICY ...`. A look into the
    /// discovery database: for a report's period, not for the sample path.
    pub(crate) fn incompatible_writers(&self) -> Vec<String> {
        self.node
            .participant()
            .discovered_writers()
            .iter()
            .filter(|w| w.publication_topic_data.topic_name == self.dds_topic)
            .filter_map(|w| {
                let offered = w.publication_topic_data.qos();
                let requested = ros2_client::dds::rustdds::QosPolicies::from(&self.requested);
                let policy = offered.compliance_failure_wrt(&requested)?;
                Some(format!(
                    "writer {:?} offers {}, this reader requests {} (incompatible {policy:?})",
                    w.writer_proxy.remote_writer_guid,
                    qos_text(&QosProfile::from(&offered)),
                    qos_text(&self.requested),
                ))
            })
            .collect()
    }

    pub(crate) fn try_recv(&self) -> Result<Option<T>, TransportError> {
        match self.subscription.take() {
            Ok(Some((Wire(msg), _info))) => Ok(Some(msg)),
            Ok(None) => Ok(None),
            Err(e) => Err(TransportError::Receive {
                topic: self.topic.to_owned(),
                backend: BACKEND,
                reason: e.to_string(),
            }),
        }
    }
}

/// Reliability and durability of `qos` in ROS 2's words (`best_effort volatile`): the
/// policies a ROS 2 QoS mismatch is almost always about.
fn qos_text(qos: &QosProfile) -> String {
    let reliability = match qos.reliability {
        RReliability::BestEffort => "best_effort",
        RReliability::Reliable { .. } => "reliable",
    };
    let durability = match qos.durability {
        RDurability::TransientLocal => "transient_local",
        RDurability::Volatile => "volatile",
    };
    format!("{reliability} {durability}")
}
