//! iceoryx2 backend: shared-memory publish/subscribe between processes of one host.
//!
//! Fixed-size `#[repr(C)]` messages ([`ActuatorState`], [`TcpEstimate`]) travel as
//! themselves: the publisher writes the value straight into a loaned shared-memory sample
//! and the subscriber reads it in place, without serialisation. All other messages travel as
//! their CDR bytes (with encapsulation header) in a `[u8]` slice service.
//!
//! Service names are the ROS 2 topic name without its leading `/`, under an optional
//! prefix: prefix `test_42` and topic `/rpkm/actuator_state` give service
//! `test_42/rpkm/actuator_state`. iceoryx2 services are global to the machine, so tests use
//! unique prefixes.

use std::fmt::Debug;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::Duration;

use iceoryx2::port::listener::{Listener as IoxListener, ListenerWaitError};
use iceoryx2::port::notifier::Notifier as IoxNotifier;
use iceoryx2::port::publisher::Publisher as IoxPublisher;
use iceoryx2::port::subscriber::Subscriber as IoxSubscriber;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::port::{BackpressureAction, BackpressureInfo, SendError};
use iceoryx2::prelude::*;
use rpkm_msgs::lifecycle_msgs::TransitionEvent;
use rpkm_msgs::{
    from_cdr, to_cdr, ActuatorState, CampaignInfo, Diagnosis, DiagnosticArray, JointState,
    Parameters, PoseStamped, PreloadStatus, RosMessage, TcpEstimate, TcpMeasurement, Temperature,
    TfMessage,
};

use crate::error::TransportError;
use crate::topic::{Durability, Qos, Reliability, Topic};

/// The iceoryx2 service flavour used: inter-process, ports usable from any thread.
pub type IpcService = ipc_threadsafe::Service;

const BACKEND: &str = "iceoryx2";
/// Limits every process must agree on when opening a service.
const MAX_PUBLISHERS: usize = 8;
const MAX_SUBSCRIBERS: usize = 16;
const MAX_NODES: usize = 32;
/// Initial slice length of CDR services; grows by powers of two when needed.
const INITIAL_CDR_LEN: usize = 1024;

/// An iceoryx2 node and the service-name prefix.
#[derive(Debug)]
pub struct IpcNode {
    // Shared with the reliable publishers, which remove dead subscribers' resources.
    node: Arc<Node<IpcService>>,
    prefix: String,
}

impl IpcNode {
    /// Creates the node (signal handling left to the application) and removes the stale
    /// shared-memory resources of dead nodes (e.g. processes killed with SIGKILL).
    pub fn new(name: &str, prefix: &str) -> Result<Self, TransportError> {
        let err = |reason: String| TransportError::IpcNode {
            node: name.to_owned(),
            reason,
        };
        let node_name = NodeName::new(name).map_err(|e| err(format!("{e:?}")))?;
        let node = NodeBuilder::new()
            .name(&node_name)
            .signal_handling_mode(SignalHandlingMode::Disabled)
            .create::<IpcService>()
            .map_err(|e| err(format!("{e:?}")))?;
        let state = node.try_cleanup_dead_nodes();
        if state.cleanups > 0 || state.failed_cleanups > 0 {
            log::info!(
                "iceoryx2: removed the resources of {} dead nodes ({} failed)",
                state.cleanups,
                state.failed_cleanups
            );
        }
        Ok(Self {
            node: Arc::new(node),
            prefix: prefix.to_owned(),
        })
    }

    /// Removes the resources of dead nodes again; returns (cleaned, failed).
    pub fn cleanup_dead_nodes(&self) -> (u64, u64) {
        let s = self.node.try_cleanup_dead_nodes();
        (s.cleanups, s.failed_cleanups)
    }

    /// The iceoryx2 service name of a ROS 2 topic name.
    pub fn service_name(&self, topic: &str) -> String {
        service_name(&self.prefix, topic)
    }

    fn service(&self, topic: &str) -> Result<ServiceName, TransportError> {
        let name = self.service_name(topic);
        ServiceName::new(&name).map_err(|e| TransportError::TopicName {
            topic: topic.to_owned(),
            reason: format!("iceoryx2 service name {name:?}: {e:?}"),
        })
    }
}

/// iceoryx2's records, handed to the `log` crate under the target `iceoryx2` at their level,
/// instead of iceoryx2's own console logger (which prints "No config file was loaded ..." at
/// every process start): the process's logger decides what is shown.
struct LogBridge;

impl iceoryx2_log::Log for LogBridge {
    fn log(
        &self,
        level: iceoryx2_log::LogLevel,
        origin: std::fmt::Arguments<'_>,
        message: std::fmt::Arguments<'_>,
    ) {
        use iceoryx2_log::LogLevel as L;
        let level = match level {
            L::Trace => log::Level::Trace,
            L::Debug => log::Level::Debug,
            L::Info => log::Level::Info,
            L::Warn => log::Level::Warn,
            L::Error | L::Fatal => log::Level::Error,
        };
        log::log!(target: "iceoryx2", level, "{message} ({origin})");
    }
}

/// Routes iceoryx2's log records into the `log` crate (warnings and errors; iceoryx2 formats
/// nothing below). Call it before anything of iceoryx2 runs: its logger is set once, at the
/// first record. Returns false when iceoryx2 had already chosen its console logger.
pub fn route_iceoryx2_log() -> bool {
    static BRIDGE: LogBridge = LogBridge;
    set_log_level(LogLevel::Warn);
    set_logger(&BRIDGE)
}

/// `prefix/topic-without-leading-slash`, or the bare topic without prefix.
pub fn service_name(prefix: &str, topic: &str) -> String {
    let topic = topic.trim_start_matches('/');
    let prefix = prefix.trim_matches('/');
    if prefix.is_empty() {
        topic.to_owned()
    } else {
        format!("{prefix}/{topic}")
    }
}

fn create_err(topic: &str, port: &'static str, e: impl Debug) -> TransportError {
    TransportError::CreatePort {
        topic: topic.to_owned(),
        backend: BACKEND,
        port,
        reason: format!("{e:?}"),
    }
}

/// Publisher half of the iceoryx2 backend for one message type.
#[doc(hidden)]
pub trait IpcSend<T>: Send + Sync {
    fn send(&self, msg: &T) -> Result<(), TransportError>;
    /// Connects the subscribers that joined since the last send and hands them the topic's
    /// history (iceoryx2 delivers it only when the publisher looks: at a send, or here).
    fn deliver_history(&self) -> Result<(), TransportError>;
}

/// Subscriber half of the iceoryx2 backend for one message type.
#[doc(hidden)]
pub trait IpcRecv<T>: Send + Sync {
    fn try_recv(&self) -> Result<Option<T>, TransportError>;
    fn update_connections(&self) -> Result<(), TransportError>;
    fn wait(&self, timeout: Duration) -> Result<(), TransportError>;
}

fn connection_err(topic: &str, e: impl Debug) -> TransportError {
    TransportError::Receive {
        topic: topic.to_owned(),
        backend: BACKEND,
        reason: format!("connecting to the publishers: {e:?}"),
    }
}

/// A message type the iceoryx2 backend can carry: zero-copy or as CDR bytes.
pub trait IpcMessage: RosMessage + Sync {
    /// Opens a publisher on `topic`.
    #[doc(hidden)]
    fn ipc_publisher(
        node: &IpcNode,
        topic: &Topic<Self>,
    ) -> Result<Box<dyn IpcSend<Self>>, TransportError>;
    /// Opens a subscriber on `topic`.
    #[doc(hidden)]
    fn ipc_subscriber(
        node: &IpcNode,
        topic: &Topic<Self>,
    ) -> Result<Box<dyn IpcRecv<Self>>, TransportError>;
}

/// Opens (or creates) the publish-subscribe service of `topic` with payload type `$payload`,
/// its settings derived from the QoS and identical in every process. A macro: iceoryx2 opens
/// sized and slice payloads through different impls.
macro_rules! open_service {
    ($node:expr, $topic:expr, $payload:ty) => {{
        let qos: Qos = $topic.qos();
        let depth = qos.depth.max(1);
        let history = match qos.durability {
            Durability::TransientLocal => depth,
            Durability::Volatile => 0,
        };
        $node
            .node
            .service_builder(&$node.service($topic.name())?)
            .publish_subscribe::<$payload>()
            .enable_safe_overflow(qos.reliability == Reliability::BestEffort)
            .subscriber_max_buffer_size(depth)
            .history_size(history)
            .max_publishers(MAX_PUBLISHERS)
            .max_subscribers(MAX_SUBSCRIBERS)
            .max_nodes(MAX_NODES)
            .open_or_create()
            .map_err(|e| create_err($topic.name(), "service", e))?
    }};
}

fn backpressure(qos: Qos) -> BackpressureStrategy {
    match qos.reliability {
        Reliability::Reliable => BackpressureStrategy::RetryUntilDelivered,
        Reliability::BestEffort => BackpressureStrategy::DiscardData,
    }
}

/// How long a reliable publisher waits on a full subscriber queue before it looks for a
/// dead subscriber, and how often it looks again.
const STALL_CHECK_MS: u64 = 250;

/// Reliable delivery waits for a live subscriber as long as it takes, but a subscriber
/// killed with SIGKILL stays connected (its queue full) until someone removes the stale
/// resources of dead nodes. While it waits, the handler checks every [`STALL_CHECK_MS`] milliseconds
/// whether any node on the machine is dead; if one is, delivery to the stalled queue is
/// abandoned and [`SendSide::sent`] removes the dead nodes.
fn backpressure_handler() -> impl Fn(&BackpressureInfo) -> BackpressureAction + Send {
    let next_check_ms = AtomicU64::new(STALL_CHECK_MS);
    move |info: &BackpressureInfo| {
        let elapsed_ms = u64::try_from(info.elapsed_time.as_millis()).unwrap_or(u64::MAX);
        if info.retries == 0 {
            next_check_ms.store(STALL_CHECK_MS, Ordering::Relaxed);
        }
        if elapsed_ms < next_check_ms.load(Ordering::Relaxed) {
            return BackpressureAction::Retry;
        }
        next_check_ms.store(elapsed_ms.saturating_add(STALL_CHECK_MS), Ordering::Relaxed);
        if any_dead_node() {
            BackpressureAction::DiscardDataAndFail
        } else {
            BackpressureAction::Retry
        }
    }
}

fn any_dead_node() -> bool {
    let mut dead = false;
    let listed = Node::<IpcService>::list(Config::global_config(), |state| {
        if matches!(state, NodeState::Dead(_)) {
            dead = true;
            CallbackProgression::Stop
        } else {
            CallbackProgression::Continue
        }
    });
    // Unable to list: keep the reliable promise and wait on.
    listed.is_ok() && dead
}

fn history_request(qos: Qos) -> usize {
    match qos.durability {
        Durability::TransientLocal => qos.depth.max(1),
        Durability::Volatile => 0,
    }
}

// ---- wake-up: an event service next to each topic ----

/// Every iceoryx2 publisher also notifies the event service `<service>/wake` after each
/// sample, so that a subscriber can sleep in the kernel until data arrives (a servo-rate
/// node with real-time priority must block, not spin) instead of polling.
fn wake_service(node: &IpcNode, topic: &str) -> Result<WakeService, TransportError> {
    let name = format!("{}/wake", node.service_name(topic));
    let service_name = ServiceName::new(&name).map_err(|e| TransportError::TopicName {
        topic: topic.to_owned(),
        reason: format!("iceoryx2 service name {name:?}: {e:?}"),
    })?;
    node.node
        .service_builder(&service_name)
        .event()
        .max_notifiers(MAX_PUBLISHERS)
        .max_listeners(MAX_SUBSCRIBERS)
        .max_nodes(MAX_NODES)
        .open_or_create()
        .map_err(|e| create_err(topic, "wake-up event service", e))
}

/// What both kinds of publisher do around a send: a reliable send that gave up on a stalled
/// subscriber (the backpressure handler saw a dead node) removes the dead nodes' resources,
/// and every sample wakes the topic's waiting subscribers.
struct SendSide {
    topic: &'static str,
    node: Arc<Node<IpcService>>,
    notifier: IoxNotifier<IpcService>,
}

impl SendSide {
    fn new(node: &IpcNode, topic: &'static str) -> Result<Self, TransportError> {
        let notifier = wake_service(node, topic)?
            .notifier_builder()
            .create()
            .map_err(|e| create_err(topic, "wake-up notifier", e))?;
        Ok(Self {
            topic,
            node: Arc::clone(&node.node),
            notifier,
        })
    }

    fn publish_err(&self, e: impl Debug) -> TransportError {
        TransportError::Publish {
            topic: self.topic.to_owned(),
            backend: BACKEND,
            reason: format!("{e:?}"),
        }
    }

    /// Maps the result of a send, then wakes the listeners. After a dead-node clean-up that
    /// freed something, the stalled subscriber was the dead one and every live subscriber
    /// got the sample. A failed wake-up costs a subscriber at most its timeout, so it is
    /// logged, not returned.
    fn sent(&self, sent: Result<usize, SendError>) -> Result<(), TransportError> {
        match sent {
            Ok(_) => {}
            Err(SendError::UnableToDeliver) => {
                let cleaned = self.node.try_cleanup_dead_nodes();
                if cleaned.cleanups == 0 {
                    return Err(TransportError::Publish {
                        topic: self.topic.to_owned(),
                        backend: BACKEND,
                        reason: "a subscriber's queue stayed full and no dead node could be \
                                 removed; the sample did not reach that subscriber"
                            .to_owned(),
                    });
                }
                log::warn!(
                    "{}: a subscriber stopped taking samples; removed the resources of {} dead \
                     node(s), the live subscribers have the sample",
                    self.topic,
                    cleaned.cleanups
                );
            }
            Err(e) => return Err(self.publish_err(e)),
        }
        if let Err(e) = self.notifier.notify() {
            log::debug!("{}: wake-up notification failed: {e:?}", self.topic);
        }
        Ok(())
    }
}

type WakeService = iceoryx2::service::port_factory::event::PortFactory<IpcService>;

/// The listener of a subscriber, made on its first wait (most subscribers only poll, and a
/// listener nobody waits on would only collect notifications).
struct Waker {
    topic: &'static str,
    service: WakeService,
    listener: OnceLock<IoxListener<IpcService>>,
}

impl Waker {
    fn new(node: &IpcNode, topic: &'static str) -> Result<Self, TransportError> {
        Ok(Self {
            topic,
            service: wake_service(node, topic)?,
            listener: OnceLock::new(),
        })
    }

    /// Blocks until a publisher notifies or `timeout` passes. The first call only creates the
    /// listener and returns: the caller polls again, and from then on no notification is missed.
    fn wait(&self, timeout: Duration) -> Result<(), TransportError> {
        let err = |reason: String| TransportError::Receive {
            topic: self.topic.to_owned(),
            backend: BACKEND,
            reason,
        };
        if let Some(listener) = self.listener.get() {
            match listener.timed_wait(|_| {}, timeout) {
                // A signal (SIGTERM: the node's stop request) ends the wait like a wake-up;
                // the caller's loop then sees the request.
                Ok(_) | Err(ListenerWaitError::InterruptSignal) => {}
                Err(e) => return Err(err(format!("waiting for a wake-up: {e:?}"))),
            }
        } else {
            let listener = self
                .service
                .listener_builder()
                .create()
                .map_err(|e| err(format!("creating the wake-up listener: {e:?}")))?;
            let _ = self.listener.set(listener);
        }
        Ok(())
    }
}

// ---- zero-copy: the value itself in shared memory ----

struct ZcPub<T: ZeroCopySend + Debug + 'static> {
    side: SendSide,
    publisher: IoxPublisher<IpcService, T, ()>,
}

struct ZcSub<T: ZeroCopySend + Debug + 'static> {
    topic: &'static str,
    waker: Waker,
    subscriber: IoxSubscriber<IpcService, T, ()>,
}

fn zc_publisher<T>(node: &IpcNode, topic: &Topic<T>) -> Result<Box<dyn IpcSend<T>>, TransportError>
where
    T: ZeroCopySend + Debug + Copy + Send + Sync + 'static,
{
    let service = open_service!(node, topic, T);
    let publisher = service
        .publisher_builder()
        .backpressure_strategy(backpressure(topic.qos()))
        .set_backpressure_handler(backpressure_handler())
        .create()
        .map_err(|e| create_err(topic.name(), "publisher", e))?;
    publisher
        .update_connections()
        .map_err(|e| create_err(topic.name(), "publisher", e))?;
    Ok(Box::new(ZcPub {
        side: SendSide::new(node, topic.name())?,
        publisher,
    }))
}

fn zc_subscriber<T>(node: &IpcNode, topic: &Topic<T>) -> Result<Box<dyn IpcRecv<T>>, TransportError>
where
    T: ZeroCopySend + Debug + Copy + Send + Sync + 'static,
{
    let service = open_service!(node, topic, T);
    let subscriber = service
        .subscriber_builder()
        .buffer_size(topic.qos().depth.max(1))
        .history_request(history_request(topic.qos()))
        .create()
        .map_err(|e| create_err(topic.name(), "subscriber", e))?;
    Ok(Box::new(ZcSub {
        topic: topic.name(),
        waker: Waker::new(node, topic.name())?,
        subscriber,
    }))
}

impl<T: ZeroCopySend + Debug + Copy + Send + Sync + 'static> IpcSend<T> for ZcPub<T> {
    fn send(&self, msg: &T) -> Result<(), TransportError> {
        let sample = self
            .publisher
            .loan_uninit()
            .map_err(|e| self.side.publish_err(e))?;
        self.side.sent(sample.write_payload(*msg).send())
    }
    fn deliver_history(&self) -> Result<(), TransportError> {
        self.publisher
            .update_connections()
            .map_err(|e| self.side.publish_err(e))
    }
}

impl<T: ZeroCopySend + Debug + Copy + Send + Sync + 'static> IpcRecv<T> for ZcSub<T> {
    fn try_recv(&self) -> Result<Option<T>, TransportError> {
        match self.subscriber.receive() {
            Ok(sample) => Ok(sample.map(|s| *s.payload())),
            Err(e) => Err(TransportError::Receive {
                topic: self.topic.to_owned(),
                backend: BACKEND,
                reason: format!("{e:?}"),
            }),
        }
    }
    fn update_connections(&self) -> Result<(), TransportError> {
        self.subscriber
            .update_connections()
            .map_err(|e| connection_err(self.topic, e))
    }
    fn wait(&self, timeout: Duration) -> Result<(), TransportError> {
        // Connected before sleeping: a publisher that appeared since the last poll then
        // delivers what it sends next.
        self.subscriber
            .update_connections()
            .map_err(|e| connection_err(self.topic, e))?;
        self.waker.wait(timeout)
    }
}

// ---- CDR bytes in a [u8] slice ----

struct CdrPub {
    side: SendSide,
    publisher: IoxPublisher<IpcService, [u8], ()>,
}

struct CdrSub {
    topic: &'static str,
    waker: Waker,
    subscriber: IoxSubscriber<IpcService, [u8], ()>,
}

fn cdr_publisher<T: RosMessage>(
    node: &IpcNode,
    topic: &Topic<T>,
) -> Result<Box<dyn IpcSend<T>>, TransportError> {
    let service = open_service!(node, topic, [u8]);
    let publisher = service
        .publisher_builder()
        .initial_max_slice_len(INITIAL_CDR_LEN)
        .allocation_strategy(AllocationStrategy::PowerOfTwo)
        .backpressure_strategy(backpressure(topic.qos()))
        .set_backpressure_handler(backpressure_handler())
        .create()
        .map_err(|e| create_err(topic.name(), "publisher", e))?;
    publisher
        .update_connections()
        .map_err(|e| create_err(topic.name(), "publisher", e))?;
    Ok(Box::new(CdrPub {
        side: SendSide::new(node, topic.name())?,
        publisher,
    }))
}

fn cdr_subscriber<T: RosMessage>(
    node: &IpcNode,
    topic: &Topic<T>,
) -> Result<Box<dyn IpcRecv<T>>, TransportError> {
    let service = open_service!(node, topic, [u8]);
    let subscriber = service
        .subscriber_builder()
        .buffer_size(topic.qos().depth.max(1))
        .history_request(history_request(topic.qos()))
        .create()
        .map_err(|e| create_err(topic.name(), "subscriber", e))?;
    Ok(Box::new(CdrSub {
        topic: topic.name(),
        waker: Waker::new(node, topic.name())?,
        subscriber,
    }))
}

impl<T: RosMessage> IpcSend<T> for CdrPub {
    fn send(&self, msg: &T) -> Result<(), TransportError> {
        let bytes = to_cdr(msg).map_err(|source| TransportError::Cdr {
            topic: self.side.topic.to_owned(),
            source,
        })?;
        let sample = self
            .publisher
            .loan_slice_uninit(bytes.len())
            .map_err(|e| self.side.publish_err(e))?;
        self.side.sent(sample.write_from_slice(&bytes).send())
    }
    fn deliver_history(&self) -> Result<(), TransportError> {
        self.publisher
            .update_connections()
            .map_err(|e| self.side.publish_err(e))
    }
}

impl<T: RosMessage> IpcRecv<T> for CdrSub {
    fn try_recv(&self) -> Result<Option<T>, TransportError> {
        let sample = self
            .subscriber
            .receive()
            .map_err(|e| TransportError::Receive {
                topic: self.topic.to_owned(),
                backend: BACKEND,
                reason: format!("{e:?}"),
            })?;
        match sample {
            None => Ok(None),
            Some(s) => from_cdr(s.payload())
                .map(Some)
                .map_err(|source| TransportError::Cdr {
                    topic: self.topic.to_owned(),
                    source,
                }),
        }
    }
    fn update_connections(&self) -> Result<(), TransportError> {
        self.subscriber
            .update_connections()
            .map_err(|e| connection_err(self.topic, e))
    }
    fn wait(&self, timeout: Duration) -> Result<(), TransportError> {
        // Connected before sleeping: a publisher that appeared since the last poll then
        // delivers what it sends next.
        self.subscriber
            .update_connections()
            .map_err(|e| connection_err(self.topic, e))?;
        self.waker.wait(timeout)
    }
}

macro_rules! zero_copy {
    ($($ty:ty),*) => {$(
        impl IpcMessage for $ty {
            fn ipc_publisher(node: &IpcNode, topic: &Topic<Self>)
                -> Result<Box<dyn IpcSend<Self>>, TransportError> {
                zc_publisher(node, topic)
            }
            fn ipc_subscriber(node: &IpcNode, topic: &Topic<Self>)
                -> Result<Box<dyn IpcRecv<Self>>, TransportError> {
                zc_subscriber(node, topic)
            }
        }
    )*};
}

macro_rules! as_cdr {
    ($($ty:ty),*) => {$(
        impl IpcMessage for $ty {
            fn ipc_publisher(node: &IpcNode, topic: &Topic<Self>)
                -> Result<Box<dyn IpcSend<Self>>, TransportError> {
                cdr_publisher(node, topic)
            }
            fn ipc_subscriber(node: &IpcNode, topic: &Topic<Self>)
                -> Result<Box<dyn IpcRecv<Self>>, TransportError> {
                cdr_subscriber(node, topic)
            }
        }
    )*};
}

zero_copy!(ActuatorState, TcpEstimate);
as_cdr!(
    TcpMeasurement,
    Parameters,
    Diagnosis,
    PreloadStatus,
    DiagnosticArray,
    CampaignInfo,
    PoseStamped,
    TfMessage,
    JointState,
    Temperature,
    TransitionEvent
);

#[cfg(test)]
mod tests {
    use super::service_name;

    #[test]
    fn service_names() {
        assert_eq!(
            service_name("", "/rpkm/actuator_state"),
            "rpkm/actuator_state"
        );
        assert_eq!(service_name("t1/", "/rpkm/x"), "t1/rpkm/x");
        assert_eq!(service_name("/a/b", "/rpkm/x"), "a/b/rpkm/x");
    }
}
