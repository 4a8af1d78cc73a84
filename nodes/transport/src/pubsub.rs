//! The publish/subscribe abstraction over the iceoryx2 and DDS backends.

use std::sync::Arc;
use std::time::{Duration, Instant};

use crate::dds::{domain_id_from_env, DdsNode, DdsPublisher, DdsSubscriber};
use crate::error::TransportError;
use crate::ipc::{IpcMessage, IpcNode, IpcRecv, IpcSend};
use crate::names::Names;
use crate::security::Credentials;
use crate::topic::Topic;

/// Which middleware a port uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Backend {
    /// iceoryx2 shared memory: between rpkm processes on one host.
    Ipc,
    /// DDS (ros2-client): to ROS 2 tools and other hosts.
    Dds,
    /// Publishers send on both; subscribers receive from iceoryx2.
    Both,
}

impl Backend {
    fn name(self) -> &'static str {
        match self {
            Self::Ipc => "iceoryx2",
            Self::Dds => "dds",
            Self::Both => "both",
        }
    }
    fn uses_ipc(self) -> bool {
        matches!(self, Self::Ipc | Self::Both)
    }
    fn uses_dds(self) -> bool {
        matches!(self, Self::Dds | Self::Both)
    }
}

/// Configuration of a [`Transport`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TransportConfig {
    /// Node name (iceoryx2 node name; DDS node `/rpkm/<node_name>`).
    pub node_name: String,
    /// Backends this transport opens; also the default of [`Transport::publisher`].
    pub backend: Backend,
    /// Prefix of the iceoryx2 service names (`<prefix>/rpkm/...`); empty for none.
    pub ipc_prefix: String,
    /// DDS domain id; `None` reads `ROS_DOMAIN_ID` (default 0).
    pub dds_domain: Option<u16>,
    /// Namespace and remapping rules: every topic's name goes through them.
    pub names: Names,
    /// SROS2 enclave of the DDS participant, used when `ROS_SECURITY_ENABLE` is `true`
    /// (default `/rpkm/<node_name>`).
    pub enclave: String,
}

impl TransportConfig {
    /// Defaults: iceoryx2 only, no prefix, domain from the environment.
    pub fn new(node_name: impl Into<String>) -> Self {
        Self {
            node_name: node_name.into(),
            backend: Backend::Ipc,
            ipc_prefix: String::new(),
            dds_domain: None,
            names: Names::default(),
            enclave: String::new(),
        }
        .default_enclave()
    }
    fn default_enclave(mut self) -> Self {
        self.enclave = format!("{}/{}", crate::names::NODE_NAMESPACE, self.node_name);
        self
    }
    /// Sets the SROS2 enclave (`/rpkm/tcp_estimator`).
    #[must_use]
    pub fn enclave(mut self, enclave: impl Into<String>) -> Self {
        self.enclave = enclave.into();
        self
    }
    /// Sets the backend.
    #[must_use]
    pub fn backend(mut self, backend: Backend) -> Self {
        self.backend = backend;
        self
    }
    /// Sets the iceoryx2 service-name prefix.
    #[must_use]
    pub fn ipc_prefix(mut self, prefix: impl Into<String>) -> Self {
        self.ipc_prefix = prefix.into();
        self
    }
    /// Sets the namespace and remapping rules.
    #[must_use]
    pub fn names(mut self, names: Names) -> Self {
        self.names = names;
        self
    }
    /// Sets the DDS domain id instead of reading `ROS_DOMAIN_ID`.
    #[must_use]
    pub fn dds_domain(mut self, domain: u16) -> Self {
        self.dds_domain = Some(domain);
        self
    }
}

/// The SROS2 credentials of `config`'s enclave where the environment switches security on;
/// `None` without (or, under `Permissive`, where the enclave has none: said on the log).
fn security(config: &TransportConfig) -> Result<Option<Credentials>, TransportError> {
    let err = |source| TransportError::Security {
        node: config.node_name.clone(),
        source,
    };
    let Some(env) = crate::security::env().map_err(err)? else {
        return Ok(None);
    };
    let credentials = crate::security::credentials(&env, &config.enclave).map_err(err)?;
    if credentials.is_none() {
        log::warn!(
            "node {}: no SROS2 credentials for enclave {} in {} \
             (ROS_SECURITY_STRATEGY=Permissive): joining DDS without security",
            config.node_name,
            config.enclave,
            env.keystore.display()
        );
    }
    Ok(credentials)
}

/// The nodes of the configured backends; creates [`Publisher`]s and [`Subscriber`]s.
#[derive(Debug)]
pub struct Transport {
    backend: Backend,
    ipc: Option<IpcNode>,
    dds: Option<Arc<DdsNode>>,
    names: Names,
}

impl Transport {
    /// Opens the configured backends. The iceoryx2 node removes the stale resources of dead
    /// nodes on creation.
    pub fn new(config: &TransportConfig) -> Result<Self, TransportError> {
        let ipc = if config.backend.uses_ipc() {
            Some(IpcNode::new(&config.node_name, &config.ipc_prefix)?)
        } else {
            None
        };
        let dds = if config.backend.uses_dds() {
            let domain = match config.dds_domain {
                Some(d) => d,
                None => domain_id_from_env()?,
            };
            let credentials = security(config)?;
            Some(DdsNode::new(
                &config.node_name,
                config.names.namespace(),
                domain,
                credentials.as_ref(),
            )?)
        } else {
            None
        };
        Ok(Self {
            backend: config.backend,
            ipc,
            dds,
            names: config.names.clone(),
        })
    }

    /// The namespace and remapping rules of this transport's topics.
    pub fn names(&self) -> &Names {
        &self.names
    }

    /// `topic` under this transport's names: for DDS, or (`ipc`) for iceoryx2.
    fn named<T>(&self, topic: &Topic<T>, ipc: bool) -> Topic<T> {
        if self.names.is_default() {
            return *topic;
        }
        let name = if ipc {
            self.names.resolve_ipc(topic.name())
        } else {
            self.names.resolve(topic.name())
        };
        topic.renamed(crate::names::intern(name))
    }

    /// The configured backend.
    pub fn backend(&self) -> Backend {
        self.backend
    }

    /// The DDS node, if DDS is configured (parameter services, `/rosout`).
    pub fn dds_node(&self) -> Option<&Arc<DdsNode>> {
        self.dds.as_ref()
    }

    /// The DDS domain id, if DDS is configured.
    pub fn dds_domain(&self) -> Option<u16> {
        self.dds.as_ref().map(|d| d.domain())
    }

    /// A publisher on the configured backend(s).
    pub fn publisher<T: IpcMessage>(
        &self,
        topic: &Topic<T>,
    ) -> Result<Publisher<T>, TransportError> {
        self.publisher_on(topic, self.backend)
    }

    /// A publisher on `backend`, which this transport must have opened.
    pub fn publisher_on<T: IpcMessage>(
        &self,
        topic: &Topic<T>,
        backend: Backend,
    ) -> Result<Publisher<T>, TransportError> {
        let dds_topic = self.named(topic, false);
        let ipc = if backend.uses_ipc() {
            Some(T::ipc_publisher(
                self.ipc_for(dds_topic.name(), backend)?,
                &self.named(topic, true),
            )?)
        } else {
            None
        };
        let dds = if backend.uses_dds() {
            Some(
                self.dds_for(dds_topic.name(), backend)?
                    .publisher(&dds_topic)?,
            )
        } else {
            None
        };
        Ok(Publisher {
            topic: dds_topic.name(),
            ipc,
            dds,
        })
    }

    /// A subscriber on the configured backend (iceoryx2 for [`Backend::Both`]).
    pub fn subscriber<T: IpcMessage>(
        &self,
        topic: &Topic<T>,
    ) -> Result<Subscriber<T>, TransportError> {
        self.subscriber_on(topic, self.backend)
    }

    /// A subscriber on `backend` ([`Backend::Both`] receives from iceoryx2).
    pub fn subscriber_on<T: IpcMessage>(
        &self,
        topic: &Topic<T>,
        backend: Backend,
    ) -> Result<Subscriber<T>, TransportError> {
        let dds_topic = self.named(topic, false);
        let inner = match backend {
            Backend::Ipc | Backend::Both => SubInner::Ipc(T::ipc_subscriber(
                self.ipc_for(dds_topic.name(), backend)?,
                &self.named(topic, true),
            )?),
            Backend::Dds => SubInner::Dds(Box::new(
                self.dds_for(dds_topic.name(), backend)?
                    .subscriber(&dds_topic)?,
            )),
        };
        Ok(Subscriber {
            topic: dds_topic.name(),
            inner,
        })
    }

    fn ipc_for(&self, topic: &str, backend: Backend) -> Result<&IpcNode, TransportError> {
        self.ipc
            .as_ref()
            .ok_or_else(|| self.disabled(topic, backend))
    }

    fn dds_for(&self, topic: &str, backend: Backend) -> Result<&Arc<DdsNode>, TransportError> {
        self.dds
            .as_ref()
            .ok_or_else(|| self.disabled(topic, backend))
    }

    fn disabled(&self, topic: &str, backend: Backend) -> TransportError {
        TransportError::BackendDisabled {
            topic: topic.to_owned(),
            backend: backend.name(),
            configured: self.backend.name(),
        }
    }
}

/// Publishes `T` on one topic, on iceoryx2, DDS or both.
pub struct Publisher<T: IpcMessage> {
    topic: &'static str,
    ipc: Option<Box<dyn IpcSend<T>>>,
    dds: Option<DdsPublisher<T>>,
}

impl<T: IpcMessage> Publisher<T> {
    /// Sends `msg` on every backend of this publisher. With both, DDS is tried even if
    /// iceoryx2 failed; the first error is returned.
    pub fn publish(&self, msg: &T) -> Result<(), TransportError> {
        let ipc = self.ipc.as_ref().map_or(Ok(()), |p| p.send(msg));
        let dds = self.dds.as_ref().map_or(Ok(()), |p| p.send(msg));
        ipc.and(dds)
    }

    /// Hands a transient-local topic's last samples to the subscribers that joined since the
    /// last publish (a monitor started after the calibration): iceoryx2 delivers history only
    /// when the publisher looks, so a node that publishes such a topic rarely calls this in
    /// its loop. DDS delivers it itself.
    pub fn deliver_history(&self) -> Result<(), TransportError> {
        self.ipc.as_ref().map_or(Ok(()), |p| p.deliver_history())
    }

    /// The ROS 2 topic name.
    pub fn topic(&self) -> &'static str {
        self.topic
    }
}

enum SubInner<T: IpcMessage> {
    Ipc(Box<dyn IpcRecv<T>>),
    // Boxed: the DDS reader is 30 times the size of the iceoryx2 handle.
    Dds(Box<DdsSubscriber<T>>),
}

/// Receives `T` from one topic.
pub struct Subscriber<T: IpcMessage> {
    topic: &'static str,
    inner: SubInner<T>,
}

/// Busy-polls this long before [`Subscriber::recv_timeout`] starts sleeping between polls.
const SPIN: Duration = Duration::from_micros(200);
/// Sleep between polls after the spin phase.
const POLL_SLEEP: Duration = Duration::from_micros(100);

impl<T: IpcMessage> Subscriber<T> {
    /// The next sample if one is queued.
    pub fn try_recv(&self) -> Result<Option<T>, TransportError> {
        match &self.inner {
            SubInner::Ipc(s) => s.try_recv(),
            SubInner::Dds(s) => s.try_recv(),
        }
    }

    /// The publishers of this topic that offer a QoS this subscriber does not accept (DDS:
    /// never matched, nothing they write arrives), named with the policy; none on iceoryx2.
    /// Looks into the DDS discovery database: call it at a report's period.
    pub fn incompatible_publishers(&self) -> Vec<String> {
        match &self.inner {
            SubInner::Ipc(_) => Vec::new(),
            SubInner::Dds(s) => s.incompatible_writers(),
        }
    }

    /// Connects to publishers that appeared since the last call (iceoryx2; a no-op on DDS).
    /// `try_recv` does this too. Reliable iceoryx2 delivery (the publisher waits for queue
    /// space) holds once the subscriber has connected to the publisher; before that a
    /// publisher overwrites samples the subscriber has not yet taken.
    pub fn update_connections(&self) -> Result<(), TransportError> {
        match &self.inner {
            SubInner::Ipc(s) => s.update_connections(),
            SubInner::Dds(_) => Ok(()),
        }
    }

    /// Sleeps until a publisher may have sent something or `timeout` passes, without taking
    /// a sample: on iceoryx2 in the kernel until a publisher's wake-up (the first call only
    /// arms it and returns), on DDS for at most [`POLL_SLEEP`]. Poll with
    /// [`Subscriber::try_recv`] afterwards; a wake-up may be spurious.
    pub fn wait(&self, timeout: Duration) -> Result<(), TransportError> {
        match &self.inner {
            SubInner::Ipc(s) => s.wait(timeout),
            SubInner::Dds(_) => {
                std::thread::sleep(POLL_SLEEP.min(timeout));
                Ok(())
            }
        }
    }

    /// Waits up to `timeout` for the next sample; `Ok(None)` on timeout. Busy-polls for the
    /// first 200 µs, then polls every 100 µs.
    pub fn recv_timeout(&self, timeout: Duration) -> Result<Option<T>, TransportError> {
        let start = Instant::now();
        loop {
            if let Some(msg) = self.try_recv()? {
                return Ok(Some(msg));
            }
            let elapsed = start.elapsed();
            if elapsed >= timeout {
                return Ok(None);
            }
            if elapsed < SPIN {
                std::hint::spin_loop();
            } else {
                std::thread::sleep(POLL_SLEEP.min(timeout.saturating_sub(elapsed)));
            }
        }
    }

    /// Busy-polls (no sleep) up to `timeout`: lowest latency, one core spinning.
    pub fn recv_spin(&self, timeout: Duration) -> Result<Option<T>, TransportError> {
        let start = Instant::now();
        loop {
            if let Some(msg) = self.try_recv()? {
                return Ok(Some(msg));
            }
            if start.elapsed() >= timeout {
                return Ok(None);
            }
            std::hint::spin_loop();
        }
    }

    /// The ROS 2 topic name.
    pub fn topic(&self) -> &'static str {
        self.topic
    }
}
