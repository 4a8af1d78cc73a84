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

use rpkm_transport::dds_params::{ParamDecl, ParamServer, ParameterValue};
use serde_yaml::Value;

use super::context::{Every, NodeContext, COMMON};
pub use super::declare::{ParamBound, ParamDefault, ParamSpec};
use super::kept::Kept;
use super::params::NodeParams;

/// How often a node looks for accepted changes: a person or a tool sets them, and the check
/// must cost the servo loop nothing.
const CHANGE_CHECK: Duration = Duration::from_millis(20);

impl ParamSpec {
    /// The value the node's parameters give this parameter (its default where not set), as
    /// the services hold it.
    fn value(&self, p: &NodeParams) -> anyhow::Result<ParameterValue> {
        let bad = super::context::bad_param;
        Ok(match self.default {
            ParamDefault::F64(_) => ParameterValue::Double(self.f64(p).map_err(bad)?),
            ParamDefault::U64(_) => {
                let v = self.u64(p).map_err(bad)?;
                ParameterValue::Integer(i64::try_from(v).unwrap_or(i64::MAX))
            }
            ParamDefault::Bool(_) => ParameterValue::Boolean(self.bool(p).map_err(bad)?),
            ParamDefault::Str(_) => ParameterValue::String(self.string(p).map_err(bad)?),
            ParamDefault::Strs(_) => ParameterValue::StringArray(self.strings(p).map_err(bad)?),
            ParamDefault::F64s(_) => ParameterValue::DoubleArray(self.f64s(p).map_err(bad)?),
            ParamDefault::Group => ParameterValue::NotSet,
        })
    }

    /// The descriptor and value of this parameter on the services.
    pub fn decl(&self, p: &NodeParams) -> anyhow::Result<ParamDecl> {
        let value = self.value(p)?;
        let description = self.describe();
        Ok(if self.live {
            ParamDecl::live(self.key, value, &description, self.range())
        } else {
            ParamDecl {
                range: self.range(),
                ..ParamDecl::read_only(self.key, value, &description)
            }
        })
    }
}

/// The entries set of group `spec` (`temperatures.temp_machine`, `geometry.l1`), each
/// read-only (a group is read at the start): a group has no value of its own to list.
fn group_entries(spec: &ParamSpec, p: &NodeParams) -> anyhow::Result<Vec<ParamDecl>> {
    let bad = super::context::bad_param;
    let description = spec.describe();
    let decl = |name: &str, value| {
        ParamDecl::read_only(&format!("{}{name}", spec.key), value, &description)
    };
    // a group holds strings (thermometer topics) or numbers (geometry in SI)
    Ok(match p.string_group(spec.key) {
        Ok(entries) => entries
            .into_iter()
            .map(|(name, text, _)| decl(&name, ParameterValue::String(text)))
            .collect(),
        Err(_) => p
            .group(spec.key)
            .map_err(bad)?
            .into_iter()
            .map(|(name, x, _)| decl(&name, ParameterValue::Double(x)))
            .collect(),
    })
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
    /// Where the accepted changes are kept for a restart by the launcher, and the node's
    /// name for the line that says a change could not be kept.
    kept: Option<(Kept, String)>,
}

impl LiveParams {
    /// Declares `specs` (with [`COMMON`]) on the node's DDS parameter services; without
    /// DDS there are none (nothing outside rpkm could call them). `configure` builds the
    /// node's configuration from a parameter set, as at start-up: a set it refuses is refused
    /// with its message.
    pub fn start(
        ctx: &NodeContext,
        specs: &[ParamSpec],
        configure: impl Fn(&NodeParams) -> anyhow::Result<()> + Send + 'static,
    ) -> anyhow::Result<Self> {
        let mut decls = Vec::new();
        for s in super::declare::served(&[&COMMON, specs]) {
            if s.default == ParamDefault::Group {
                decls.extend(group_entries(&s, &ctx.params)?);
            } else {
                decls.push(s.decl(&ctx.params)?);
            }
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
        let kept = Kept::from_env(ctx.transport.names().namespace(), &ctx.name)
            .map_err(super::context::bad_param)?;
        for said in kept.iter().flat_map(Kept::said) {
            ctx.log(said);
        }
        Ok(Self {
            kept: kept.map(|k| (k, ctx.name.clone())),
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
        self.keep(&changes);
        self.current.extend(changes);
        Some((
            with_changes(&self.base, &self.initial, &self.current),
            names,
        ))
    }

    /// Writes the accepted `changes` where the node's restart finds them: a change is rare
    /// (a person or a cell controller sets it), and the file is a few lines.
    fn keep(&mut self, changes: &[(String, ParameterValue)]) {
        let Some((kept, node)) = self.kept.as_mut() else {
            return;
        };
        let values: Vec<(String, Value)> =
            changes.iter().map(|(k, v)| (k.clone(), yaml(v))).collect();
        if let Err(e) = kept.record(&values) {
            let names: Vec<&str> = changes.iter().map(|(k, _)| k.as_str()).collect();
            super::context::log_line(
                node,
                format!(
                    "WARN: {} not kept for a restart (the files' values would come back): {e}",
                    names.join(", ")
                ),
            );
        }
    }
}
