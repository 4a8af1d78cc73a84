//! The rpkm topics by name, for the commands that handle topics they only know at run time:
//! `rpkm record` (a typed subscriber writing into a bag), `rpkm replay` (a typed publisher fed
//! from a bag's CDR payloads) and the bag tests (payload → JSON).

use std::time::{SystemTime, UNIX_EPOCH};

use rpkm_msgs::RosMessage;
use rpkm_transport::bag::{
    self, BagDurability, BagReliability, BagWriteError, BagWriter, History, QosProfile, TopicHandle,
};
use rpkm_transport::{
    topic, Durability, IpcMessage, Publisher, Qos, Reliability, Subscriber, Topic, Transport,
    TransportError,
};

/// Every topic rpkm publishes, in the order `rpkm record` lists them.
pub const ALL: [&str; 8] = [
    "/rpkm/campaign_info",
    "/rpkm/actuator_state",
    "/rpkm/tcp_measurement",
    "/rpkm/tcp_estimate",
    "/rpkm/parameters",
    "/rpkm/diagnosis",
    "/rpkm/preload_status",
    "/diagnostics",
];

/// Runs `$body` with `$t` bound to the typed [`Topic`] called `$name`, or evaluates `$else`.
macro_rules! with_topic {
    ($name:expr, $t:ident => $body:expr, _ => $else:expr) => {{
        let name: &str = $name;
        if name == topic::CAMPAIGN_INFO.name() {
            let $t = topic::CAMPAIGN_INFO;
            $body
        } else if name == topic::ACTUATOR_STATE.name() {
            let $t = topic::ACTUATOR_STATE;
            $body
        } else if name == topic::TCP_MEASUREMENT.name() {
            let $t = topic::TCP_MEASUREMENT;
            $body
        } else if name == topic::TCP_ESTIMATE.name() {
            let $t = topic::TCP_ESTIMATE;
            $body
        } else if name == topic::PARAMETERS.name() {
            let $t = topic::PARAMETERS;
            $body
        } else if name == topic::DIAGNOSIS.name() {
            let $t = topic::DIAGNOSIS;
            $body
        } else if name == topic::PRELOAD_STATUS.name() {
            let $t = topic::PRELOAD_STATUS;
            $body
        } else if name == topic::DIAGNOSTICS.name() {
            let $t = topic::DIAGNOSTICS;
            $body
        } else {
            $else
        }
    }};
}

/// A topic name that is not one of [`ALL`].
#[derive(Debug, thiserror::Error)]
#[error("unknown topic {name:?}: rpkm knows {}", ALL.join(", "))]
pub struct UnknownTopic {
    pub name: String,
}

/// Checks topic names given on the command line.
pub fn check_names(names: &[String]) -> Result<(), UnknownTopic> {
    match names.iter().find(|n| !ALL.contains(&n.as_str())) {
        Some(n) => Err(UnknownTopic { name: n.clone() }),
        None => Ok(()),
    }
}

/// The ROS type name (`rpkm_msgs/msg/ActuatorState`) of an rpkm topic.
pub fn type_name(name: &str) -> Option<String> {
    fn of<T: RosMessage>(_: Topic<T>) -> String {
        T::type_name()
    }
    with_topic!(name, t => Some(of(t)), _ => None)
}

/// The QoS profile a bag stores for a topic: the one its rpkm publishers offer.
pub fn bag_qos(qos: Qos) -> QosProfile {
    QosProfile {
        history: History::KeepLast,
        depth: u32::try_from(qos.depth).unwrap_or(u32::MAX),
        reliability: match qos.reliability {
            Reliability::Reliable => BagReliability::Reliable,
            Reliability::BestEffort => BagReliability::BestEffort,
        },
        durability: match qos.durability {
            Durability::Volatile => BagDurability::Volatile,
            Durability::TransientLocal => BagDurability::TransientLocal,
        },
        ..QosProfile::default()
    }
}

/// Adds an rpkm topic to a bag with its type and offered QoS.
pub fn add_bag_topic<T: RosMessage>(
    bag: &mut BagWriter,
    t: &Topic<T>,
) -> Result<TopicHandle<T>, BagWriteError> {
    bag.add_topic::<T>(t.name(), &bag_qos(t.qos()))
}

/// How a tool opens a topic: with the QoS its publishers offer, or reliable whatever that is
/// (`--reliable`: iceoryx2 publishers then wait for the slowest subscriber instead of
/// overwriting). iceoryx2 services must be opened alike by every process, so all processes
/// on the topic must open it alike.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Delivery {
    AsOffered,
    Reliable,
}

impl Delivery {
    /// `t` opened so: reliable keeps its depth and durability.
    pub fn topic<T>(self, t: Topic<T>) -> Topic<T> {
        match self {
            Delivery::AsOffered => t,
            Delivery::Reliable => t.with_qos(Qos {
                reliability: Reliability::Reliable,
                ..t.qos()
            }),
        }
    }
}

/// Nanoseconds since the Unix epoch (the recorder's log time).
pub fn now_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
}

/// A subscriber that writes what it receives into a bag.
pub trait RecordPort {
    /// The topic name.
    fn topic(&self) -> &'static str;
    /// Takes up to `max` queued samples and writes them with the receive time; returns how
    /// many were taken.
    fn drain(&mut self, bag: &mut BagWriter, max: usize) -> anyhow::Result<usize>;
    /// Samples written so far.
    fn count(&self) -> u64;
}

struct Recorder<T: IpcMessage> {
    subscriber: Subscriber<T>,
    handle: TopicHandle<T>,
    count: u64,
}

impl<T: IpcMessage> RecordPort for Recorder<T> {
    fn topic(&self) -> &'static str {
        self.subscriber.topic()
    }
    fn drain(&mut self, bag: &mut BagWriter, max: usize) -> anyhow::Result<usize> {
        let mut taken = 0;
        while taken < max {
            let Some(msg) = self.subscriber.try_recv()? else {
                break;
            };
            bag.write(&self.handle, now_ns(), &msg)?;
            taken += 1;
        }
        self.count += taken as u64;
        Ok(taken)
    }
    fn count(&self) -> u64 {
        self.count
    }
}

/// A recorder of topic `name` (one of [`ALL`]): a subscriber on `transport`, opened as
/// `delivery` says, and the topic in `bag`.
pub fn recorder(
    name: &str,
    transport: &Transport,
    bag: &mut BagWriter,
    delivery: Delivery,
) -> anyhow::Result<Box<dyn RecordPort>> {
    fn make<T: IpcMessage>(
        t: Topic<T>,
        transport: &Transport,
        bag: &mut BagWriter,
        delivery: Delivery,
    ) -> anyhow::Result<Box<dyn RecordPort>> {
        // The bag stores what the publishers offer, not the override.
        let handle = add_bag_topic(bag, &t)?;
        let t = delivery.topic(t);
        Ok(Box::new(Recorder {
            subscriber: transport.subscriber(&t)?,
            handle,
            count: 0,
        }))
    }
    with_topic!(name, t => make(t, transport, bag, delivery),
        _ => Err(UnknownTopic { name: name.to_owned() }.into()))
}

/// A publisher fed with CDR payloads taken from a bag.
pub trait ReplayPort {
    fn topic(&self) -> &'static str;
    /// Decodes `cdr` (with encapsulation header) and publishes it.
    fn publish(&self, cdr: &[u8]) -> Result<(), ReplayError>;
    /// Hands the last samples of a transient-local topic to subscribers that joined since.
    fn deliver_history(&self) -> Result<(), ReplayError>;
}

/// A payload that cannot be published.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    #[error("{topic}: payload is not a {type_name}: {source}")]
    Decode {
        topic: &'static str,
        type_name: String,
        source: bag::CdrError,
    },
    #[error(transparent)]
    Transport(#[from] TransportError),
}

struct Replayer<T: IpcMessage> {
    publisher: Publisher<T>,
}

impl<T: IpcMessage> ReplayPort for Replayer<T> {
    fn topic(&self) -> &'static str {
        self.publisher.topic()
    }
    fn publish(&self, cdr: &[u8]) -> Result<(), ReplayError> {
        // Fixed-size types decode onto the stack: no allocation per message.
        let msg: T = bag::decode_cdr(cdr).map_err(|source| ReplayError::Decode {
            topic: self.publisher.topic(),
            type_name: T::type_name(),
            source,
        })?;
        Ok(self.publisher.publish(&msg)?)
    }
    fn deliver_history(&self) -> Result<(), ReplayError> {
        Ok(self.publisher.deliver_history()?)
    }
}

/// A publisher of topic `name` on `transport`, opened as `delivery` says: reliable, a
/// recorder opened alike loses nothing even at `--rate max`.
pub fn publisher(
    name: &str,
    transport: &Transport,
    delivery: Delivery,
) -> anyhow::Result<Box<dyn ReplayPort>> {
    fn make<T: IpcMessage>(
        t: Topic<T>,
        transport: &Transport,
        delivery: Delivery,
    ) -> anyhow::Result<Box<dyn ReplayPort>> {
        let t = delivery.topic(t);
        Ok(Box::new(Replayer {
            publisher: transport.publisher(&t)?,
        }))
    }
    with_topic!(name, t => make(t, transport, delivery),
        _ => Err(UnknownTopic { name: name.to_owned() }.into()))
}

/// Decodes a payload of an rpkm type (by its ROS type name) into JSON, fields in `.msg`
/// order; `None` for a type rpkm does not define.
pub fn decode_json(type_name: &str, cdr: &[u8]) -> Option<Result<serde_json::Value, String>> {
    fn json<T: RosMessage>(cdr: &[u8]) -> Result<serde_json::Value, String> {
        let msg: T = bag::decode_cdr(cdr).map_err(|e| e.to_string())?;
        serde_json::to_value(&msg).map_err(|e| e.to_string())
    }
    use rpkm_msgs::{
        ActuatorState, CampaignInfo, Diagnosis, DiagnosticArray, Parameters, PreloadStatus,
        RosMessage, TcpEstimate, TcpMeasurement,
    };
    let f: fn(&[u8]) -> Result<serde_json::Value, String> = match type_name {
        n if n == CampaignInfo::type_name() => json::<CampaignInfo>,
        n if n == ActuatorState::type_name() => json::<ActuatorState>,
        n if n == TcpMeasurement::type_name() => json::<TcpMeasurement>,
        n if n == TcpEstimate::type_name() => json::<TcpEstimate>,
        n if n == Parameters::type_name() => json::<Parameters>,
        n if n == Diagnosis::type_name() => json::<Diagnosis>,
        n if n == PreloadStatus::type_name() => json::<PreloadStatus>,
        n if n == DiagnosticArray::type_name() => json::<DiagnosticArray>,
        _ => return None,
    };
    Some(f(cdr))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_topic_has_its_type() {
        let names = [
            topic::CAMPAIGN_INFO.name(),
            topic::ACTUATOR_STATE.name(),
            topic::TCP_MEASUREMENT.name(),
            topic::TCP_ESTIMATE.name(),
            topic::PARAMETERS.name(),
            topic::DIAGNOSIS.name(),
            topic::PRELOAD_STATUS.name(),
            topic::DIAGNOSTICS.name(),
        ];
        assert_eq!(names, ALL);
        for name in ALL {
            assert!(type_name(name).is_some(), "{name}");
        }
        assert_eq!(
            type_name("/rpkm/actuator_state").as_deref(),
            Some("rpkm_msgs/msg/ActuatorState")
        );
        assert!(type_name("/rpkm/nope").is_none());
        assert!(check_names(&["/rpkm/nope".into()]).is_err());
    }
}
