//! Node parameters as ROS 2 sees them while the node runs: declared with descriptors on the
//! node's DDS parameter services (`ros2 param list|describe|get|set`), checked by the same
//! bounded readers as the parameter files ([`super::params`]), applied live where the node
//! can take a change between samples, refused with the reason otherwise.
//!
//! A set is checked by building the node's configuration from the parameters it would
//! leave (the files' values with every accepted change on top): what a file may not hold,
//! a service may not set, and the reply names the key, the value and the bound.

use std::collections::BTreeMap;
use std::time::Duration;

use rpkm_transport::dds_params::{ParamDecl, ParamRange, ParamServer, ParameterValue};
use serde_yaml::Value;

use super::context::{Every, NodeContext};
use super::params::NodeParams;

/// How often a node looks for accepted changes: a person or a tool sets them, and the check
/// must cost the servo loop nothing.
const CHANGE_CHECK: Duration = Duration::from_millis(20);

/// A parameter's type and default as the node reads it.
#[derive(Debug, Clone, Copy)]
pub enum Default {
    /// A double.
    F64(f64),
    /// A non-negative integer.
    U64(u64),
    /// A boolean.
    Bool(bool),
    /// A string.
    Str(&'static str),
    /// A list of strings.
    Strs(&'static [&'static str]),
    /// A list of doubles.
    F64s(&'static [f64]),
}

/// One parameter of a node: key, default, description with unit, range, and whether the node
/// takes a change while it runs.
#[derive(Debug, Clone, Copy)]
pub struct ParamSpec {
    pub key: &'static str,
    pub default: Default,
    pub description: &'static str,
    pub range: ParamRange,
    pub live: bool,
}

impl ParamSpec {
    /// A parameter the node applies while it runs.
    pub const fn live(
        key: &'static str,
        default: Default,
        description: &'static str,
        range: ParamRange,
    ) -> Self {
        Self {
            key,
            default,
            description,
            range,
            live: true,
        }
    }
    /// A parameter whose change needs a restart.
    pub const fn fixed(key: &'static str, default: Default, description: &'static str) -> Self {
        Self {
            key,
            default,
            description,
            range: ParamRange::None,
            live: false,
        }
    }

    fn value(&self, p: &NodeParams) -> anyhow::Result<ParameterValue> {
        let bad = super::context::bad_param;
        Ok(match self.default {
            Default::F64(d) => ParameterValue::Double(p.f64(self.key, d).map_err(bad)?),
            Default::U64(d) => {
                let v = p.u64(self.key, d).map_err(bad)?;
                ParameterValue::Integer(i64::try_from(v).unwrap_or(i64::MAX))
            }
            Default::Bool(d) => ParameterValue::Boolean(p.bool(self.key, d).map_err(bad)?),
            Default::Str(d) => ParameterValue::String(p.string(self.key, d).map_err(bad)?),
            Default::Strs(d) => ParameterValue::StringArray(p.strings(self.key, d).map_err(bad)?),
            Default::F64s(d) => ParameterValue::DoubleArray(p.f64s(self.key, d).map_err(bad)?),
        })
    }
}

/// The parameters every node declares.
pub fn common_specs() -> [ParamSpec; 4] {
    [
        ParamSpec::fixed(
            "backend",
            Default::Str("ipc"),
            "where the node publishes: ipc, dds or both",
        ),
        ParamSpec::fixed(
            "input_backend",
            Default::Str(""),
            "where the node subscribes: ipc or dds (empty: from backend)",
        ),
        ParamSpec::fixed(
            "diagnostics_period_s",
            Default::F64(1.0),
            "period of the /diagnostics report, s (0.001 to 3600)",
        ),
        ParamSpec::fixed(
            "enclave",
            Default::Str(""),
            "SROS2 enclave of the node's DDS participant (default /rpkm/<name>)",
        ),
    ]
}

/// The value a parameter file would hold for `v`.
fn yaml(v: &ParameterValue) -> Value {
    match v {
        ParameterValue::Boolean(b) => Value::Bool(*b),
        ParameterValue::Integer(i) => Value::Number((*i).into()),
        ParameterValue::Double(x) => Value::Number((*x).into()),
        ParameterValue::String(s) => Value::String(s.clone()),
        ParameterValue::StringArray(a) => {
            Value::Sequence(a.iter().cloned().map(Value::String).collect())
        }
        ParameterValue::DoubleArray(a) => {
            Value::Sequence(a.iter().map(|x| Value::Number((*x).into())).collect())
        }
        other => Value::String(format!("{other:?}")),
    }
}

/// `base` with every value of `proposed` that differs from its declared value `initial`.
fn with_changes(
    base: &NodeParams,
    initial: &BTreeMap<String, ParameterValue>,
    proposed: &BTreeMap<String, ParameterValue>,
) -> NodeParams {
    let mut p = base.clone();
    for (k, v) in proposed {
        if initial.get(k) != Some(v) {
            p.set_from_service(k, yaml(v));
        }
    }
    p
}

/// The parameter services of a running node and the changes they accepted.
pub struct LiveParams {
    server: Option<ParamServer>,
    check: Every,
    base: NodeParams,
    initial: BTreeMap<String, ParameterValue>,
    current: BTreeMap<String, ParameterValue>,
}

impl LiveParams {
    /// Declares `specs` (with [`common_specs`]) on the node's DDS parameter services; without
    /// DDS there are none (nothing outside rpkm could call them). `configure` builds the
    /// node's configuration from a parameter set, as at start-up: a set it refuses is refused
    /// with its message.
    pub fn start(
        ctx: &NodeContext,
        specs: &[ParamSpec],
        configure: impl Fn(&NodeParams) -> anyhow::Result<()> + Send + 'static,
    ) -> anyhow::Result<Self> {
        let mut decls = Vec::new();
        for s in common_specs().iter().chain(specs) {
            let value = s.value(&ctx.params)?;
            decls.push(if s.live {
                ParamDecl::live(s.key, value, s.description, s.range)
            } else {
                ParamDecl {
                    range: s.range,
                    ..ParamDecl::read_only(s.key, value, s.description)
                }
            });
        }
        // The backends as the command line may have chosen them, not only the files.
        let name = |b: rpkm_transport::Backend| match b {
            rpkm_transport::Backend::Ipc => "ipc",
            rpkm_transport::Backend::Dds => "dds",
            rpkm_transport::Backend::Both => "both",
        };
        for d in &mut decls {
            match d.name.as_str() {
                "backend" => d.value = ParameterValue::String(name(ctx.output).into()),
                "input_backend" => d.value = ParameterValue::String(name(ctx.input).into()),
                "enclave" => d.value = ParameterValue::String(ctx.enclave.clone()),
                _ => {}
            }
        }
        let initial: BTreeMap<String, ParameterValue> = decls
            .iter()
            .map(|d| (d.name.clone(), d.value.clone()))
            .collect();
        let server = match ctx.transport.dds_node() {
            None => None,
            Some(dds) => {
                let base = ctx.params.clone();
                let init = initial.clone();
                let check = move |proposed: &BTreeMap<String, ParameterValue>| {
                    configure(&with_changes(&base, &init, proposed)).map_err(|e| format!("{e:#}"))
                };
                Some(dds.serve_parameters(decls, Box::new(check))?)
            }
        };
        Ok(Self {
            server,
            check: Every::new(CHANGE_CHECK),
            base: ctx.params.clone(),
            current: initial.clone(),
            initial,
        })
    }

    /// The node's parameters after the changes accepted since the last call, with their
    /// names; `None` when there were none. At most one look per [`CHANGE_CHECK`].
    pub fn poll(&mut self) -> Option<(NodeParams, Vec<String>)> {
        if self.server.is_none() || !self.check.due() {
            return None;
        }
        self.poll_now()
    }

    /// [`Self::poll`] without waiting for its period: for a parameter that applies from the
    /// next sample on (the services queue a change before they reply, so a sample sent after
    /// the reply finds it queued). One atomic load when nothing changed.
    pub fn poll_now(&mut self) -> Option<(NodeParams, Vec<String>)> {
        let server = self.server.as_ref()?;
        let changes = server.changes();
        if changes.is_empty() {
            return None;
        }
        let names = changes.iter().map(|(k, _)| k.clone()).collect();
        self.current.extend(changes);
        Some((
            with_changes(&self.base, &self.initial, &self.current),
            names,
        ))
    }
}
