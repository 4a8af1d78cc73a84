//! ROS 2 parameter services of a DDS node (`ros2 param list|describe|get|set|dump`,
//! `rqt_reconfigure`): `list_parameters`, `describe_parameters`, `get_parameters`,
//! `get_parameter_types`, `set_parameters`, `set_parameters_atomically`, with each
//! parameter's descriptor (type, description, range, read-only), and a
//! `rcl_interfaces/ParameterEvent` on `/parameter_events` for every accepted change.
//!
//! Why our own servers and not ros2-client's (`start_parameter_services(true)`): each of its
//! servers speaks one request mapping, and a ROS 2 cell may speak either: rmw_fastrtps (the
//! default middleware) the enhanced one, rmw_cyclonedds a header in the payload (ros2-client
//! issues 24, 35). These servers answer both, decided per request ([`crate::dds_rpc`]); their
//! descriptors also carry the range, read-only flag and description. Checked with independent
//! Cyclone DDS and Fast DDS peers (tests/it/node_ros2_params.rs and the Fast DDS service tests).
//!
//! A set passes, in order: the parameter exists, its type is the declared one, it is not
//! read-only, it lies in its range, and the node's own check of the whole resulting set
//! (`Check`) accepts it; otherwise the reply says `successful: false` with the reason and
//! the value stays. Accepted changes go to the node through [`ParamServer::changes`].

use std::collections::BTreeMap;
use std::sync::mpsc;
use std::sync::Arc;

use futures::{FutureExt, StreamExt};
use ros2_client::parameters::raw;
use ros2_client::rcl_interfaces::{
    DescribeParametersRequest, DescribeParametersResponse, GetParameterTypesRequest,
    GetParameterTypesResponse, GetParametersRequest, GetParametersResponse, ListParametersRequest,
    ListParametersResponse, ListParametersResult, SetParametersRequest, SetParametersResponse,
};
use serde::{Deserialize, Serialize};

pub use ros2_client::ParameterValue;

use crate::dds::DdsNode;
use crate::dds_rpc::{reply_timer, RpcServer, RpcTypes};
use crate::error::TransportError;

/// The numeric range of a parameter, inclusive (`rcl_interfaces/FloatingPointRange`,
/// `IntegerRange` with step 0: any value in between).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ParamRange {
    /// No range.
    None,
    /// A double in `lo..=hi`.
    Float(f64, f64),
    /// An integer in `lo..=hi`.
    Integer(i64, i64),
}

impl ParamRange {
    /// The integer range of a count `lo..=hi`; a bound beyond `i64::MAX` (ROS 2 integers are
    /// signed) is capped there.
    pub fn count((lo, hi): (u64, u64)) -> Self {
        let signed = |v: u64| i64::try_from(v).unwrap_or(i64::MAX);
        ParamRange::Integer(signed(lo), signed(hi))
    }
}

/// One declared parameter: its value now and its descriptor.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamDecl {
    /// Name (`warn_percent`, `geometry.l1`).
    pub name: String,
    /// Current value; its type is the parameter's type.
    pub value: ParameterValue,
    /// What it is, with its unit.
    pub description: String,
    /// Range of a number.
    pub range: ParamRange,
    /// True when a change needs a restart of the node (backends, buffer sizes, sources).
    pub read_only: bool,
}

impl ParamDecl {
    /// A parameter that can change while the node runs.
    pub fn live(name: &str, value: ParameterValue, description: &str, range: ParamRange) -> Self {
        Self {
            name: name.to_owned(),
            value,
            description: description.to_owned(),
            range,
            read_only: false,
        }
    }

    /// A parameter whose change needs a restart.
    pub fn read_only(name: &str, value: ParameterValue, description: &str) -> Self {
        Self {
            read_only: true,
            ..Self::live(name, value, description, ParamRange::None)
        }
    }

    fn descriptor(&self) -> raw::ParameterDescriptor {
        let (floating_point_range, integer_range) = match self.range {
            ParamRange::None => (vec![], vec![]),
            ParamRange::Float(from_value, to_value) => (
                vec![raw::FloatingPointRange {
                    from_value,
                    to_value,
                    step: 0.0,
                }],
                vec![],
            ),
            ParamRange::Integer(from_value, to_value) => (
                vec![],
                vec![raw::IntegerRange {
                    from_value,
                    to_value,
                    step: 0,
                }],
            ),
        };
        let constraints = if self.read_only {
            "read-only: set it in the parameter file and restart the node".to_owned()
        } else {
            String::new()
        };
        raw::ParameterDescriptor {
            name: self.name.clone(),
            r#type: ParameterValue::to_parameter_type_raw(&self.value),
            description: self.description.clone(),
            additional_constraints: constraints,
            read_only: self.read_only,
            dynamic_typing: false,
            floating_point_range,
            integer_range,
        }
    }

    /// Why `value` may not replace this parameter's value, if it may not (the node's own
    /// check comes after).
    fn refuse(&self, value: &ParameterValue) -> Option<String> {
        let name = &self.name;
        if std::mem::discriminant(value) != std::mem::discriminant(&self.value) {
            return Some(format!(
                "{name}: wrong type {:?}, the parameter is of type {:?}",
                value.to_parameter_type(),
                self.value.to_parameter_type()
            ));
        }
        if self.read_only {
            return Some(format!(
                "{name} is read-only: a change needs a restart of the node"
            ));
        }
        let outside = match (self.range, value) {
            (ParamRange::Float(lo, hi), ParameterValue::Double(x)) => {
                (!(lo..=hi).contains(x)).then(|| (x.to_string(), lo.to_string(), hi.to_string()))
            }
            (ParamRange::Integer(lo, hi), ParameterValue::Integer(x)) => {
                (!(lo..=hi).contains(x)).then(|| (x.to_string(), lo.to_string(), hi.to_string()))
            }
            _ => None,
        };
        outside.map(|(x, lo, hi)| format!("{name}: {x} is out of range: expected {lo} to {hi}"))
    }
}

/// The node's check of a whole proposed parameter set (cross-parameter rules such as
/// `error_percent >= warn_percent`, the same bounded readers as at start-up): `Err(reason)`
/// refuses the set.
pub type Check = dyn Fn(&BTreeMap<String, ParameterValue>) -> Result<(), String> + Send;

/// The running parameter services of one node: a task on the node's DDS runtime.
pub struct ParamServer {
    changes: mpsc::Receiver<Vec<(String, ParameterValue)>>,
    stop: Option<futures::channel::oneshot::Sender<()>>,
    task: Option<tokio::task::JoinHandle<()>>,
}

impl std::fmt::Debug for ParamServer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ParamServer").finish_non_exhaustive()
    }
}

impl ParamServer {
    /// The changes accepted since the last call, one batch per accepted request, in order.
    /// Costs one atomic load when there are none.
    pub fn changes(&self) -> Vec<(String, ParameterValue)> {
        self.changes.try_iter().flatten().collect()
    }
}

impl Drop for ParamServer {
    fn drop(&mut self) {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        // The task ends at its next poll, on the runtime's thread; waiting for it here
        // keeps the servers from answering for a node that is gone.
        if let Some(task) = self.task.take() {
            let _ = futures::executor::block_on(task);
        }
    }
}

type Server<Q, R> = RpcServer<Q, R>;

#[derive(Debug, Clone, Serialize, Deserialize)]
struct SetAtomicRequest {
    parameter: Vec<raw::Parameter>,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
struct SetAtomicResponse {
    result: raw::SetParametersResult,
}

struct Servers {
    list: Server<ListParametersRequest, ListParametersResponse>,
    describe: Server<DescribeParametersRequest, DescribeParametersResponse>,
    get: Server<GetParametersRequest, GetParametersResponse>,
    types: Server<GetParameterTypesRequest, GetParameterTypesResponse>,
    set: Server<SetParametersRequest, SetParametersResponse>,
    set_atomic: Server<SetAtomicRequest, SetAtomicResponse>,
}

impl Servers {
    /// Sends the replies whose readers have matched since.
    fn flush(&self) {
        self.list.flush();
        self.describe.flush();
        self.get.flush();
        self.types.flush();
        self.set.flush();
        self.set_atomic.flush();
    }

    fn waiting(&self) -> bool {
        self.list.waiting()
            || self.describe.waiting()
            || self.get.waiting()
            || self.types.waiting()
            || self.set.waiting()
            || self.set_atomic.waiting()
    }
}

fn create<Q, R>(node: &DdsNode, service: &str, kind: &str) -> Result<Server<Q, R>, String>
where
    Q: serde::de::DeserializeOwned,
    R: Serialize,
{
    node.rpc_server(service, &RpcTypes::new("rcl_interfaces", "srv", kind))
}

fn servers(node: &DdsNode) -> Result<Servers, String> {
    Ok(Servers {
        list: create(node, "list_parameters", "ListParameters")?,
        describe: create(node, "describe_parameters", "DescribeParameters")?,
        get: create(node, "get_parameters", "GetParameters")?,
        types: create(node, "get_parameter_types", "GetParameterTypes")?,
        set: create(node, "set_parameters", "SetParameters")?,
        set_atomic: create(node, "set_parameters_atomically", "SetParametersAtomically")?,
    })
}

/// The declared parameters and the rules of a set, shared by the service thread.
struct Store {
    decls: BTreeMap<String, ParamDecl>,
    check: Box<Check>,
}

impl Store {
    fn values(&self) -> BTreeMap<String, ParameterValue> {
        self.decls
            .iter()
            .map(|(k, d)| (k.clone(), d.value.clone()))
            .collect()
    }

    /// Checks `params` as one change: every rule of every parameter, then the node's check
    /// of the resulting set.
    fn validate(&self, params: &[(String, ParameterValue)]) -> Result<(), String> {
        let mut proposed = self.values();
        for (name, value) in params {
            let decl = self.decls.get(name).ok_or_else(|| {
                format!("{name}: no such parameter (ros2 param list shows the declared ones)")
            })?;
            if let Some(reason) = decl.refuse(value) {
                return Err(reason);
            }
            proposed.insert(name.clone(), value.clone());
        }
        (self.check)(&proposed)
    }

    fn list(&self, req: &ListParametersRequest) -> ListParametersResult {
        let within = |rest: &str| req.depth == 0 || (rest.matches('.').count() as u64) < req.depth;
        let mut result = ListParametersResult {
            names: vec![],
            prefixes: vec![],
        };
        for name in self.decls.keys() {
            let listed = if req.prefixes.is_empty() {
                within(name)
            } else {
                req.prefixes.iter().any(|p| {
                    name == p
                        || name
                            .strip_prefix(p.as_str())
                            .and_then(|r| r.strip_prefix('.'))
                            .is_some_and(|r| within(&format!(".{r}")))
                })
            };
            if listed {
                result.names.push(name.clone());
                if let Some((ns, _)) = name.rsplit_once('.') {
                    if !result.prefixes.iter().any(|p| p == ns) {
                        result.prefixes.push(ns.to_owned());
                    }
                }
            }
        }
        result
    }
}

/// What the service thread needs besides the servers.
struct Service {
    store: Store,
    node: Arc<DdsNode>,
    changes: mpsc::Sender<Vec<(String, ParameterValue)>>,
}

impl Service {
    /// Applies a validated change: stores it, publishes the ParameterEvent (through the
    /// ros2-client node's own parameter store and `/parameter_events` writer), hands it to
    /// the node.
    fn apply(&mut self, params: Vec<(String, ParameterValue)>) {
        for (name, value) in &params {
            if let Some(d) = self.store.decls.get_mut(name) {
                d.value = value.clone();
            }
            self.node.publish_parameter(name, value.clone());
        }
        let _ = self.changes.send(params);
    }

    /// Validates and applies `params` as one change (`set_parameters` calls it per
    /// parameter, `set_parameters_atomically` once for all).
    fn set(&mut self, params: Vec<raw::Parameter>) -> raw::SetParametersResult {
        let change: Vec<(String, ParameterValue)> = params
            .into_iter()
            .map(|p| (p.name, ParameterValue::from(p.value)))
            .collect();
        match self.store.validate(&change) {
            Ok(()) => {
                self.apply(change);
                raw::SetParametersResult {
                    successful: true,
                    reason: String::new(),
                }
            }
            Err(reason) => raw::SetParametersResult {
                successful: false,
                reason,
            },
        }
    }

    fn get(&self, names: &[String]) -> Vec<raw::ParameterValue> {
        names
            .iter()
            .map(|n| {
                self.store
                    .decls
                    .get(n)
                    .map_or(ParameterValue::NotSet, |d| d.value.clone())
                    .into()
            })
            .collect()
    }

    fn describe(&self, names: &[String]) -> Vec<raw::ParameterDescriptor> {
        names
            .iter()
            .map(|n| match self.store.decls.get(n) {
                Some(d) => d.descriptor(),
                None => {
                    ParamDecl::read_only(n, ParameterValue::NotSet, "not declared").descriptor()
                }
            })
            .collect()
    }
}

async fn serve(s: Servers, mut svc: Service, stop: futures::channel::oneshot::Receiver<()>) {
    let mut stop = stop.fuse();
    let list = s.list.stream().fuse();
    futures::pin_mut!(list);
    let describe = s.describe.stream().fuse();
    futures::pin_mut!(describe);
    let get = s.get.stream().fuse();
    futures::pin_mut!(get);
    let types = s.types.stream().fuse();
    futures::pin_mut!(types);
    let set = s.set.stream().fuse();
    futures::pin_mut!(set);
    let set_atomic = s.set_atomic.stream().fuse();
    futures::pin_mut!(set_atomic);
    // The reply writers' match events: a reply waiting for its client's reader goes out
    // when the reader matches.
    let mut matches = futures::stream::select_all([
        s.list.matches().boxed(),
        s.describe.matches().boxed(),
        s.get.matches().boxed(),
        s.types.matches().boxed(),
        s.set.matches().boxed(),
        s.set_atomic.matches().boxed(),
    ])
    .fuse();
    loop {
        let mut flush = reply_timer(s.waiting());
        futures::select! {
            _ = stop => break,
            (caller, req) = list.select_next_some() => {
                let result = svc.store.list(&req);
                s.list.reply(caller, &ListParametersResponse { result });
            },
            (caller, req) = describe.select_next_some() => {
                let values = svc.describe(&req.names);
                s.describe.reply(caller, &DescribeParametersResponse { values });
            },
            (caller, req) = get.select_next_some() => {
                let values = svc.get(&req.names);
                s.get.reply(caller, &GetParametersResponse { values });
            },
            (caller, req) = types.select_next_some() => {
                let values = svc.get(&req.names).iter().map(|v| v.ptype).collect();
                s.types.reply(caller, &GetParameterTypesResponse { values });
            },
            (caller, req) = set.select_next_some() => {
                let results = req.parameter.into_iter().map(|p| svc.set(vec![p])).collect();
                s.set.reply(caller, &SetParametersResponse { results });
            },
            (caller, req) = set_atomic.select_next_some() => {
                let result = svc.set(req.parameter);
                s.set_atomic.reply(caller, &SetAtomicResponse { result });
            },
            () = matches.select_next_some() => {},
            () = flush => s.flush(),
        }
    }
}

impl DdsNode {
    /// Declares `decls` and starts the six parameter services as a task on the node's tokio
    /// runtime (it sleeps until a request arrives: nothing of it runs on the node's sample
    /// path). `check` sees every proposed set after the per-parameter rules.
    pub fn serve_parameters(
        self: &Arc<Self>,
        decls: Vec<ParamDecl>,
        check: Box<Check>,
    ) -> Result<ParamServer, TransportError> {
        let err = |reason: String| TransportError::CreatePort {
            topic: "parameter services".into(),
            backend: "dds",
            port: "server",
            reason,
        };
        let servers = servers(self).map_err(err)?;
        // The declarations, as rclcpp announces them: one event with every new parameter.
        for d in &decls {
            self.publish_parameter(&d.name, d.value.clone());
        }
        let (tx, rx) = mpsc::channel();
        let (stop_tx, stop_rx) = futures::channel::oneshot::channel();
        let svc = Service {
            store: Store {
                decls: decls.into_iter().map(|d| (d.name.clone(), d)).collect(),
                check,
            },
            node: Arc::clone(self),
            changes: tx,
        };
        let task = self.runtime().spawn(serve(servers, svc, stop_rx));
        Ok(ParamServer {
            changes: rx,
            stop: Some(stop_tx),
            task: Some(task),
        })
    }
}
