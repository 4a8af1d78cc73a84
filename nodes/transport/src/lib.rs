//! Transport and bag I/O.
//!
//! Publish/subscribe: a [`Transport`] opens the configured backends (iceoryx2 shared memory
//! between rpkm processes on one host, DDS through ros2-client for ROS 2 tools and other
//! hosts, or both) and hands out typed [`Publisher`]s and [`Subscriber`]s for the
//! [`topic`] constants. Errors are [`TransportError`]s naming the topic.
//!
//! ```no_run
//! use rpkm_transport::{topic, Backend, Transport, TransportConfig};
//! # fn main() -> Result<(), rpkm_transport::TransportError> {
//! let transport = Transport::new(&TransportConfig::new("drives").backend(Backend::Both))?;
//! let publisher = transport.publisher(&topic::ACTUATOR_STATE)?;
//! publisher.publish(&rpkm_msgs::ActuatorState::default())?;
//! # Ok(()) }
//! ```
pub mod dds;
pub mod dds_actions;
pub mod dds_calls;
pub mod dds_params;
mod dds_rpc;
pub mod dds_wire;
pub mod error;
pub mod ipc;
pub mod names;
pub mod pubsub;
pub mod security;
pub mod topic;

pub use dds_rpc::Unread;
pub use error::TransportError;
pub use ipc::IpcMessage;
pub use names::{NameError, Names, NODE_NAMESPACE};
pub use pubsub::{Backend, Publisher, Subscriber, Transport, TransportConfig};
pub use topic::{Durability, Qos, Reliability, Topic};
pub mod bag;
