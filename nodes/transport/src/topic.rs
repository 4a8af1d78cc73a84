//! Topics: a ROS 2 name, a message type and a quality of service, shared by all backends.

use std::marker::PhantomData;

use rpkm_msgs::{
    ActuatorState, CampaignInfo, Diagnosis, DiagnosticArray, JointState, Parameters, PoseStamped,
    PreloadStatus, TcpEstimate, TcpMeasurement, TfMessage,
};

/// Delivery guarantee.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reliability {
    /// Samples may be dropped (a full subscriber queue overwrites its oldest sample).
    BestEffort,
    /// Samples are retransmitted (DDS) or the publisher waits for queue space (iceoryx2).
    Reliable,
}

/// Whether late subscribers receive samples published before they joined.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Durability {
    /// Only samples published after the subscriber joined.
    Volatile,
    /// The last `depth` samples are kept for late joiners.
    TransientLocal,
}

/// Quality of service of a topic: the same on every backend and in every process.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Qos {
    /// Delivery guarantee.
    pub reliability: Reliability,
    /// Late-joiner behaviour.
    pub durability: Durability,
    /// Keep-last depth: subscriber queue length (and history for transient-local), >= 1.
    pub depth: usize,
}

impl Qos {
    /// Best-effort, volatile, keep-last `depth`: high-rate streams (the actuator stream).
    pub const fn best_effort(depth: usize) -> Self {
        Self {
            reliability: Reliability::BestEffort,
            durability: Durability::Volatile,
            depth,
        }
    }
    /// Reliable, volatile, keep-last `depth`.
    pub const fn reliable(depth: usize) -> Self {
        Self {
            reliability: Reliability::Reliable,
            durability: Durability::Volatile,
            depth,
        }
    }
    /// Reliable, transient-local, keep-last `depth`: state that late joiners need.
    pub const fn latched(depth: usize) -> Self {
        Self {
            reliability: Reliability::Reliable,
            durability: Durability::TransientLocal,
            depth,
        }
    }
}

/// A typed topic: ROS 2 name (`/rpkm/actuator_state`) and QoS.
#[derive(Debug)]
pub struct Topic<T> {
    name: &'static str,
    qos: Qos,
    _type: PhantomData<fn() -> T>,
}

impl<T> Clone for Topic<T> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<T> Copy for Topic<T> {}

impl<T> Topic<T> {
    /// A topic; `name` is an absolute ROS 2 topic name. Validated when a port is created.
    pub const fn new(name: &'static str, qos: Qos) -> Self {
        Self {
            name,
            qos,
            _type: PhantomData,
        }
    }
    /// The ROS 2 topic name.
    pub fn name(&self) -> &'static str {
        self.name
    }
    /// The quality of service.
    pub fn qos(&self) -> Qos {
        self.qos
    }
    /// The same topic under another name (a namespace's, a remapping's).
    #[must_use]
    pub const fn renamed(self, name: &'static str) -> Self {
        Self { name, ..self }
    }
    /// The same topic with another QoS.
    #[must_use]
    pub const fn with_qos(self, qos: Qos) -> Self {
        Self { qos, ..self }
    }
}

/// `/rpkm/actuator_state`: drive states at the control rate; best-effort keep-last 4096.
/// Best effort: the drive interface never waits for a consumer. The depth is half a second
/// at 8 kHz: a subscriber that a busy host holds off its core for tens of milliseconds
/// catches up instead of losing the oldest states (64, 8 ms, lost 3.5 % of an 8 kHz
/// stream on a 2-core machine; `rpkm bench soak`).
pub const ACTUATOR_STATE: Topic<ActuatorState> =
    Topic::new("/rpkm/actuator_state", Qos::best_effort(4096));
/// `/rpkm/tcp_estimate`: forward-model answers; reliable keep-last 1024 (a slow subscriber
/// holds the estimator back only after 128 ms at 8 kHz).
pub const TCP_ESTIMATE: Topic<TcpEstimate> = Topic::new("/rpkm/tcp_estimate", Qos::reliable(1024));
/// `/rpkm/tcp_measurement`: metrology measurements; reliable keep-last 256.
pub const TCP_MEASUREMENT: Topic<TcpMeasurement> =
    Topic::new("/rpkm/tcp_measurement", Qos::reliable(256));
/// `/rpkm/parameters`: the current parameter set; reliable transient-local keep-last 1.
pub const PARAMETERS: Topic<Parameters> = Topic::new("/rpkm/parameters", Qos::latched(1));
/// `/rpkm/diagnosis`: diagnosis results; reliable keep-last 8.
pub const DIAGNOSIS: Topic<Diagnosis> = Topic::new("/rpkm/diagnosis", Qos::reliable(8));
/// `/rpkm/preload_status`: preload monitor; reliable keep-last 16.
pub const PRELOAD_STATUS: Topic<PreloadStatus> =
    Topic::new("/rpkm/preload_status", Qos::reliable(16));
/// `/diagnostics`: the standard ROS 2 diagnostics topic; reliable keep-last 16.
pub const DIAGNOSTICS: Topic<DiagnosticArray> = Topic::new("/diagnostics", Qos::reliable(16));
/// `/rpkm/tcp_pose`: the standard view of the TCP estimate (frame `machine`); reliable
/// keep-last 10, the default QoS RViz and Foxglove subscribe with. DDS only.
pub const TCP_POSE: Topic<PoseStamped> = Topic::new("/rpkm/tcp_pose", Qos::reliable(10));
/// `/tf`: the transform `machine` → `platform` of the TCP estimate; reliable keep-last 100
/// as tf2's listeners subscribe. DDS only.
pub const TF: Topic<TfMessage> = Topic::new("/tf", Qos::reliable(100));
/// `/joint_states`: the drives q1..q4 as prismatic joints (m, N); reliable keep-last 10.
/// DDS only.
pub const JOINT_STATES: Topic<JointState> = Topic::new("/joint_states", Qos::reliable(10));
/// `/rpkm/campaign_info`: source, comments and covariate names of the campaign whose poses
/// follow on `/rpkm/actuator_state` and `/rpkm/tcp_measurement`; reliable transient-local
/// keep-last 1.
pub const CAMPAIGN_INFO: Topic<CampaignInfo> = Topic::new("/rpkm/campaign_info", Qos::latched(1));
