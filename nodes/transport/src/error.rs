//! Errors of the publish/subscribe transport. Every variant names the topic it concerns.

use rpkm_msgs::CdrError;

/// The backend a [`TransportError`] comes from.
pub type BackendName = &'static str;

/// Failure of the publish/subscribe transport.
#[derive(Debug, thiserror::Error)]
pub enum TransportError {
    /// `ROS_DOMAIN_ID` is set but not a valid domain id.
    #[error("invalid ROS_DOMAIN_ID {value:?}: expected an integer in 0..=232")]
    DomainId {
        /// The value found in the environment.
        value: String,
    },
    /// SROS2 credentials are missing (`Enforce`) or invalid.
    #[error("node {node}: DDS security: {source}")]
    Security {
        /// Node name.
        node: String,
        /// Which file, and what is wrong.
        #[source]
        source: crate::security::SecurityError,
    },
    /// The iceoryx2 node could not be created.
    #[error("cannot create the iceoryx2 node {node:?}: {reason}")]
    IpcNode {
        /// Node name.
        node: String,
        /// iceoryx2's message.
        reason: String,
    },
    /// The DDS context or node could not be created.
    #[error("cannot create the DDS node {node:?} in domain {domain}: {reason}")]
    DdsNode {
        /// Node name.
        node: String,
        /// DDS domain id.
        domain: u16,
        /// ros2-client's message.
        reason: String,
    },
    /// The transport was built without the backend a port asks for.
    #[error("topic {topic}: the transport has no {backend} backend (configured: {configured})")]
    BackendDisabled {
        /// Topic name.
        topic: String,
        /// The backend asked for.
        backend: BackendName,
        /// The transport's configured backend.
        configured: BackendName,
    },
    /// The topic name is not a valid ROS 2 / iceoryx2 name.
    #[error("invalid topic name {topic:?}: {reason}")]
    TopicName {
        /// Topic name.
        topic: String,
        /// Why it is invalid.
        reason: String,
    },
    /// A publisher or subscriber could not be created.
    #[error("topic {topic}: cannot create the {backend} {port}: {reason}")]
    CreatePort {
        /// Topic name.
        topic: String,
        /// `iceoryx2` or `dds`.
        backend: BackendName,
        /// `service`, `publisher` or `subscriber`.
        port: &'static str,
        /// The backend's message.
        reason: String,
    },
    /// A sample could not be sent.
    #[error("topic {topic}: {backend} publish failed: {reason}")]
    Publish {
        /// Topic name.
        topic: String,
        /// `iceoryx2` or `dds`.
        backend: BackendName,
        /// The backend's message.
        reason: String,
    },
    /// A sample could not be received.
    #[error("topic {topic}: {backend} receive failed: {reason}")]
    Receive {
        /// Topic name.
        topic: String,
        /// `iceoryx2` or `dds`.
        backend: BackendName,
        /// The backend's message.
        reason: String,
    },
    /// A sample could not be encoded or decoded as CDR.
    #[error("topic {topic}: {source}")]
    Cdr {
        /// Topic name.
        topic: String,
        /// The codec's error.
        #[source]
        source: CdrError,
    },
}
