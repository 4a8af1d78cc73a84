//! What every node is made of: its command-line arguments, its identity and parameters, its
//! transport (`NodeContext`), its diagnostics and its pacing. The nodes read this file; it
//! reads none of them.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use super::declare::{ParamBound, ParamDefault, ParamSpec};
use super::params::{self, NodeParams, ParamError};
use anyhow::Context;
use rpkm_msgs::{DiagnosticArray, DiagnosticStatus, Header, KeyValue, Time};
use rpkm_transport::dds::RosoutLevel;
use rpkm_transport::{
    Backend, IpcMessage, Publisher, Subscriber, Topic, Transport, TransportConfig,
};

/// A backend on the command line.
#[derive(clap::ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum BackendArg {
    /// iceoryx2 shared memory (same host).
    Ipc,
    /// DDS (ROS 2 tools, other hosts).
    Dds,
    /// Publish on both (subscriptions use iceoryx2).
    Both,
}

impl BackendArg {
    fn backend(self) -> Backend {
        match self {
            Self::Ipc => Backend::Ipc,
            Self::Dds => Backend::Dds,
            Self::Both => Backend::Both,
        }
    }
    fn parse(s: &str) -> Option<Self> {
        match s {
            "ipc" | "iceoryx2" => Some(Self::Ipc),
            "dds" => Some(Self::Dds),
            "both" => Some(Self::Both),
            _ => None,
        }
    }
}

/// Options every node takes.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct CommonArgs {
    /// ROS 2 parameter YAML file; repeat for several (later files override earlier ones).
    #[arg(long = "params", value_name = "FILE.yaml")]
    pub params: Vec<PathBuf>,
    /// One parameter as key=value (value read as YAML), applied after the files.
    #[arg(long = "param", value_name = "KEY=VALUE")]
    pub param: Vec<String>,
    /// Node name: its section in the parameter files and its iceoryx2/DDS name
    /// (default: the executable name).
    #[arg(long)]
    pub name: Option<String>,
    /// Where the node publishes (default: parameter `backend`, else ipc).
    #[arg(long, value_enum)]
    pub backend: Option<BackendArg>,
    /// Where the node subscribes: ipc or dds (default: parameter `input_backend`, else dds
    /// when publishing on dds only, ipc otherwise).
    #[arg(long, value_enum)]
    pub input_backend: Option<BackendArg>,
    /// Prefix of the iceoryx2 service names (default: env RPKM_IPC_PREFIX, else none).
    #[arg(long)]
    pub ipc_prefix: Option<String>,
    /// DDS domain id (default: env ROS_DOMAIN_ID, else 0).
    #[arg(long)]
    pub domain: Option<u16>,
    /// Start as a managed node in the unconfigured state: it publishes nothing until a
    /// lifecycle client configures and activates it (`ros2 lifecycle set NODE configure`);
    /// needs DDS. Without it the node starts active (and can still be deactivated).
    #[arg(long)]
    pub unconfigured: bool,
    /// ROS 2 arguments, last on the line: `--ros-args -r __ns:=/machine_a -r __node:=NAME
    /// -r FROM:=TO -p KEY:=VALUE --params-file FILE --enclave /rpkm/NAME` (namespace, name,
    /// topic remapping, parameters, SROS2 enclave).
    #[arg(long = "ros-args", num_args = 0.., allow_hyphen_values = true, value_name = "ARGS")]
    pub ros_args: Vec<String>,
}

impl CommonArgs {
    /// Who the node is and where its parameters come from: the command line with its
    /// `--ros-args` (which win, as with rcl).
    pub fn identity(&self, kind: &str) -> anyhow::Result<Identity> {
        let ros = RosArgs::parse(&self.ros_args).map_err(crate::error::bad_input)?;
        let name = ros
            .node
            .clone()
            .or_else(|| self.name.clone())
            .unwrap_or_else(|| kind.to_owned());
        if let Some(why) = node_name_error(&name) {
            return Err(crate::error::bad_input(format!("--name: {why}")));
        }
        let namespace = ros
            .namespace
            .as_deref()
            .unwrap_or(rpkm_transport::NODE_NAMESPACE);
        let names = rpkm_transport::Names::new(namespace, &ros.remaps)
            .map_err(|e| crate::error::bad_input(format!("--ros-args: {e}")))?;
        let mut files = self.params.clone();
        files.extend(ros.param_files.iter().cloned());
        let mut overrides = self.param.clone();
        overrides.extend(ros.params.iter().cloned());
        Ok(Identity {
            name,
            names,
            files,
            overrides,
            enclave: ros.enclave,
        })
    }
}

impl NodeContext {
    /// The node's parameters read again from its files (a lifecycle configure), checked
    /// against `declared` as at its start.
    pub fn reread_params(
        &self,
        args: &CommonArgs,
        kind: &str,
        declared: &[&str],
    ) -> anyhow::Result<NodeParams> {
        let params = args.identity(kind)?.params().map_err(bad_param)?;
        params
            .check_declared(&with_common(declared))
            .map_err(bad_param)?;
        Ok(params)
    }
}

/// A node's name, namespace and remapping rules, and its parameter sources.
#[derive(Debug, Clone)]
pub struct Identity {
    /// Node name.
    pub name: String,
    /// Namespace and remapping rules.
    pub names: rpkm_transport::Names,
    /// Parameter files, in order.
    pub files: Vec<PathBuf>,
    /// `key=value` overrides, in order.
    pub overrides: Vec<String>,
    /// `--ros-args --enclave E`.
    pub enclave: Option<String>,
}

impl Identity {
    /// The merged parameters of this node, from its files and overrides.
    /// The values set at run time before a restart by the launcher come last
    /// ([`super::kept`]): the value set last wins.
    pub fn params(&self) -> Result<NodeParams, ParamError> {
        let mut params = NodeParams::load_in(
            self.names.namespace(),
            &self.name,
            &self.files,
            &self.overrides,
        )?;
        if let Some(kept) = super::kept::Kept::from_env(self.names.namespace(), &self.name)? {
            kept.apply(&mut params)?;
        }
        Ok(params)
    }
}

/// What `--ros-args` says, as rcl reads it: `-r __ns:=NS`, `-r __node:=NAME`, `-r FROM:=TO`,
/// `-p KEY:=VALUE`, `--params-file FILE`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RosArgs {
    /// `-r __ns:=NS`.
    pub namespace: Option<String>,
    /// `-r __node:=NAME` (or `__name`).
    pub node: Option<String>,
    /// `-r FROM:=TO`, in order.
    pub remaps: Vec<(String, String)>,
    /// `-p KEY:=VALUE`, as `key=value` (`--param`).
    pub params: Vec<String>,
    /// `--params-file FILE`.
    pub param_files: Vec<PathBuf>,
    /// `-e E` / `--enclave E`: the SROS2 enclave.
    pub enclave: Option<String>,
}

impl RosArgs {
    /// Reads the words after `--ros-args` (up to a `--`); an error names the word.
    pub fn parse(words: &[String]) -> Result<Self, String> {
        let mut out = Self::default();
        let mut words = words.iter();
        while let Some(flag) = words.next() {
            let flag = flag.as_str();
            match flag {
                "--" => break,
                // rcl takes several `--ros-args` sections (the launch appends one)
                "--ros-args" => continue,
                _ => {}
            }
            let value = |w: Option<&String>| {
                w.cloned()
                    .ok_or_else(|| format!("--ros-args {flag}: expected a value after it"))
            };
            match flag {
                "-r" | "--remap" => out.remap(&value(words.next())?)?,
                "-p" | "--param" => {
                    let v = value(words.next())?;
                    let (key, val) = v
                        .split_once(":=")
                        .ok_or_else(|| format!("--ros-args -p {v:?}: expected KEY:=VALUE"))?;
                    out.params.push(format!("{key}={val}"));
                }
                "--params-file" => out.param_files.push(PathBuf::from(value(words.next())?)),
                "-e" | "--enclave" => out.enclave = Some(value(words.next())?),
                other => {
                    return Err(format!(
                        "--ros-args: unknown argument {other:?} (-r FROM:=TO, -r __ns:=NS, \
                         -r __node:=NAME, -p KEY:=VALUE, --params-file FILE, --enclave E)"
                    ))
                }
            }
        }
        Ok(out)
    }

    fn remap(&mut self, rule: &str) -> Result<(), String> {
        let (from, to) = rule
            .split_once(":=")
            .ok_or_else(|| format!("--ros-args -r {rule:?}: expected FROM:=TO"))?;
        match from {
            "__ns" => self.namespace = Some(to.to_owned()),
            "__node" | "__name" => self.node = Some(to.to_owned()),
            _ => self.remaps.push((from.to_owned(), to.to_owned())),
        }
        Ok(())
    }
}

/// Parameter `enclave`.
const ENCLAVE: ParamSpec = ParamSpec::fixed(
    "enclave",
    ParamDefault::Str(""),
    "SROS2 enclave of the node's DDS participant (default /rpkm/<name>)",
);
/// Parameter `diagnostics_period_s`.
const DIAGNOSTICS_PERIOD: ParamSpec = ParamSpec::fixed(
    "diagnostics_period_s",
    ParamDefault::F64(1.0),
    "period of the /diagnostics report",
)
.unit("s")
.bound(ParamBound::Within(1e-3, params::DURATION_S.1));

/// The parameters every node declares.
pub const COMMON: [ParamSpec; 4] = [
    ParamSpec::fixed(
        "backend",
        ParamDefault::Str("ipc"),
        "where the node publishes: ipc, dds or both",
    ),
    ParamSpec::fixed(
        "input_backend",
        ParamDefault::Str(""),
        "where the node subscribes: ipc or dds (empty: from backend)",
    ),
    DIAGNOSTICS_PERIOD,
    ENCLAVE,
];

/// `declared` with the keys every node declares.
fn with_common<'a>(declared: &[&'a str]) -> Vec<&'a str> {
    let mut all = declared.to_vec();
    all.extend(COMMON.iter().map(|s| s.key));
    all
}

/// An opened node: its name, parameters and transport.
pub struct NodeContext {
    /// Node name.
    pub name: String,
    /// Its status name on /diagnostics: `rpkm/<name>`, `<namespace>/<name>`.
    pub status_name: String,
    /// Merged parameters.
    pub params: NodeParams,
    /// The transport (iceoryx2, DDS or both, as the ports need).
    pub transport: Transport,
    /// Backend of the publishers.
    pub output: Backend,
    /// Backend of the subscribers (iceoryx2 or DDS).
    pub input: Backend,
    /// SROS2 enclave of its DDS participant.
    pub enclave: String,
}

/// A node's configuration as its command line and parameter files give it, checked, before
/// anything is opened (`rpkm launch --check` stops here).
pub struct NodeSetup {
    /// Node name.
    pub name: String,
    /// Namespace and remapping rules.
    pub names: rpkm_transport::Names,
    /// Merged parameters, every key declared.
    pub params: NodeParams,
    /// Backend of the publishers.
    pub output: Backend,
    /// Backend of the subscribers (iceoryx2 or DDS).
    pub input: Backend,
    /// Every backend the transport needs.
    pub transport: Backend,
    /// SROS2 enclave: `--ros-args --enclave`, else parameter `enclave`, else `/rpkm/<name>`.
    pub enclave: String,
}

fn union(a: Backend, b: Backend) -> Backend {
    match (a, b) {
        (Backend::Ipc, Backend::Ipc) => Backend::Ipc,
        (Backend::Dds, Backend::Dds) => Backend::Dds,
        _ => Backend::Both,
    }
}

/// Longest node name: rmw's `RMW_NODE_NAME_MAX_NAME_LENGTH`.
pub const NODE_NAME_MAX: usize = 255;

/// Why `name` cannot name a ROS 2 node (rmw's rules: letters, digits and `_`, not starting
/// with a digit, at most [`NODE_NAME_MAX`] characters), or `None`. Checked before anything
/// is opened: a name the transport refuses later would make a node that fails at every
/// start.
pub fn node_name_error(name: &str) -> Option<String> {
    let shown = if name.chars().count() > 40 {
        let head: String = name.chars().take(40).collect();
        format!("{head:?}... ({} characters)", name.chars().count())
    } else {
        format!("{name:?}")
    };
    let why = if name.is_empty() {
        "is empty"
    } else if name.len() > NODE_NAME_MAX {
        "is longer than 255 characters"
    } else if name.starts_with(|c: char| c.is_ascii_digit()) {
        "starts with a digit"
    } else if !name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
        "has a character other than a letter, a digit or `_`"
    } else {
        return None;
    };
    Some(format!("node name {shown} {why}"))
}

impl NodeSetup {
    /// Loads the parameters and checks them against `declared` and the backends; `extra_input`
    /// is a backend the node subscribes on besides its input (ingest's DDS source).
    pub fn load(
        kind: &str,
        args: &CommonArgs,
        declared: &[&str],
        extra_input: Option<Backend>,
    ) -> anyhow::Result<Self> {
        let Identity {
            name,
            names,
            enclave,
            ..
        } = args.identity(kind)?;
        let params = args.identity(kind)?.params().map_err(bad_param)?;
        params
            .check_declared(&with_common(declared))
            .map_err(bad_param)?;
        let from_param = |key: &str| -> anyhow::Result<Option<BackendArg>> {
            if !params.has(key) {
                return Ok(None);
            }
            let s = params.string(key, "").map_err(bad_param)?;
            BackendArg::parse(&s).map(Some).ok_or_else(|| {
                crate::error::bad_input(format!(
                    "{}/{key}: expected ipc, dds or both, found {s:?}",
                    params
                        .origin(key)
                        .map(std::string::ToString::to_string)
                        .unwrap_or_default()
                ))
            })
        };
        let output = match args.backend {
            Some(b) => b,
            None => from_param("backend")?.unwrap_or(BackendArg::Ipc),
        }
        .backend();
        let input = match args.input_backend {
            Some(b) => Some(b),
            None => from_param("input_backend")?,
        };
        let input = match input {
            Some(BackendArg::Both) => {
                return Err(crate::error::bad_input(
                    "input backend: a node subscribes on ipc or dds, not both".into(),
                ))
            }
            Some(b) => b.backend(),
            None if output == Backend::Dds => Backend::Dds,
            None => Backend::Ipc,
        };
        let mut transport = union(output, input);
        if let Some(extra) = extra_input {
            transport = union(transport, extra);
        }
        diagnostics_period(&params)?;
        let enclave = node_enclave(enclave, &params, &name)?;
        Ok(Self {
            name,
            names,
            params,
            output,
            input,
            transport,
            enclave,
        })
    }
}

/// The node's SROS2 enclave: `--ros-args --enclave` wins over parameter `enclave`; by
/// default `/rpkm/<name>`, the enclave `rpkm security enclave` makes for each node.
fn node_enclave(
    from_args: Option<String>,
    params: &NodeParams,
    name: &str,
) -> anyhow::Result<String> {
    let (enclave, what) = match from_args {
        Some(e) => (e, "--ros-args --enclave".to_owned()),
        None if params.has("enclave") => (
            ENCLAVE.string(params).map_err(bad_param)?,
            params
                .origin("enclave")
                .map_or_else(|| "enclave".to_owned(), |o| format!("{o}/enclave")),
        ),
        None => return Ok(format!("{}/{name}", rpkm_transport::NODE_NAMESPACE)),
    };
    match rpkm_transport::security::enclave_name_error(&enclave) {
        Some(why) => Err(crate::error::bad_input(format!(
            "{what} {enclave:?}: {why}"
        ))),
        None => Ok(enclave),
    }
}

/// Period of the regular /diagnostics report, parameter `diagnostics_period_s`.
fn diagnostics_period(params: &NodeParams) -> anyhow::Result<Duration> {
    let s = DIAGNOSTICS_PERIOD.f64(params).map_err(bad_param)?;
    Ok(Duration::from_secs_f64(s))
}

impl NodeContext {
    /// Loads the parameters, checks them against `declared` ([`NodeSetup::load`]) and opens
    /// the transport.
    pub fn open(
        kind: &str,
        args: &CommonArgs,
        declared: &[&str],
        extra_input: Option<Backend>,
    ) -> anyhow::Result<Self> {
        let setup = NodeSetup::load(kind, args, declared, extra_input)?;
        let name = setup.name;
        let prefix = match &args.ipc_prefix {
            Some(p) => p.clone(),
            None => std::env::var("RPKM_IPC_PREFIX").unwrap_or_default(),
        };
        let status_name = setup.names.status_name(&name);
        let mut config = TransportConfig::new(&name)
            .backend(setup.transport)
            .ipc_prefix(prefix)
            .names(setup.names)
            .enclave(&setup.enclave);
        if let Some(d) = args.domain {
            config = config.dds_domain(d);
        }
        let transport = Transport::new(&config)
            .with_context(|| format!("node {name}: opening the transport"))?;
        if let Some(dds) = transport.dds_node() {
            // The libraries' warnings (a dead subscriber, ...) reach /rosout too.
            let dds = std::sync::Arc::clone(dds);
            crate::logging::forward(Box::new(move |level, text, file, line| {
                let level = match level {
                    log::Level::Error => RosoutLevel::Error,
                    log::Level::Warn => RosoutLevel::Warn,
                    log::Level::Info => RosoutLevel::Info,
                    _ => RosoutLevel::Debug,
                };
                dds.rosout(level, text, file, line);
            }));
        }
        Ok(Self {
            name,
            status_name,
            params: setup.params,
            transport,
            output: setup.output,
            input: setup.input,
            enclave: setup.enclave,
        })
    }

    /// A publisher on the output backend.
    pub fn publisher<T: IpcMessage>(&self, topic: &Topic<T>) -> anyhow::Result<Publisher<T>> {
        self.transport
            .publisher_on(topic, self.output)
            .with_context(|| format!("node {}", self.name))
    }

    /// A subscriber on the input backend.
    pub fn subscriber<T: IpcMessage>(&self, topic: &Topic<T>) -> anyhow::Result<Subscriber<T>> {
        self.transport
            .subscriber_on(topic, self.input)
            .with_context(|| format!("node {}", self.name))
    }

    /// Says the node's start-up line (every endpoint it opens at its start exists) and tells
    /// the launch that started it, which then starts the next node ([`super::started`]).
    #[track_caller]
    pub fn started(&self, msg: impl std::fmt::Display) {
        self.log(msg);
        super::started::tell_launch();
    }

    /// Logs one line to stderr, prefixed with the node name (launch output interleaves), and
    /// with DDS on `/rosout` too, at the severity its prefix names (`WARN:`, `ERROR:`; else
    /// info), with the caller's file and line.
    #[track_caller]
    pub fn log(&self, msg: impl std::fmt::Display) {
        let text = msg.to_string();
        log_line(&self.name, &text);
        if let Some(dds) = self.transport.dds_node() {
            let at = std::panic::Location::caller();
            dds.rosout(severity(&text), &text, at.file(), at.line());
        }
    }

    /// Period of the regular /diagnostics report.
    pub fn diagnostics_period(&self) -> anyhow::Result<Duration> {
        diagnostics_period(&self.params)
    }

    /// The node's /diagnostics report: its status `s`, and where a service of the node met
    /// requests it could not read (or replies whose client's reader never matched) a WARN
    /// status `<status name>/services` naming each service, the count and the last reason.
    pub fn diagnostics(&self, s: DiagnosticStatus) -> DiagnosticArray {
        let mut array = diagnostic_array(s);
        if let Some(services) = self.services_status() {
            array.status.push(services);
        }
        array
    }

    fn services_status(&self) -> Option<DiagnosticStatus> {
        let unread = self.transport.dds_node()?.unread_requests();
        if unread.is_empty() {
            return None;
        }
        let message = unread
            .iter()
            .map(|u| {
                let mut said = Vec::new();
                if u.count > 0 {
                    said.push(format!("{} requests not read ({})", u.count, u.reason));
                }
                if u.replies_lost > 0 {
                    said.push(format!(
                        "{} replies lost (the client's reader never matched)",
                        u.replies_lost
                    ));
                }
                format!("{}: {}", u.service, said.join(", "))
            })
            .collect::<Vec<_>>()
            .join("; ");
        let values = unread
            .iter()
            .flat_map(|u| {
                [
                    ("requests_not_read", format!("{} {}", u.service, u.count)),
                    ("replies_lost", format!("{} {}", u.service, u.replies_lost)),
                ]
            })
            .collect();
        let name = format!("{}/services", self.status_name);
        Some(status(DiagnosticStatus::WARN, &name, message, values))
    }
}

/// The `/rosout` severity of a node's log line: the nodes write levels as a prefix.
pub fn severity(line: &str) -> RosoutLevel {
    if line.starts_with("ERROR") {
        RosoutLevel::Error
    } else if line.starts_with("WARN") {
        RosoutLevel::Warn
    } else {
        RosoutLevel::Info
    }
}

/// Writes `[who] msg` to stderr in one `write`: the processes of a launch share one stderr,
/// and a line written in pieces would interleave with the others'.
pub fn log_line(who: &str, msg: impl std::fmt::Display) {
    use std::io::Write;
    let line = format!("[{who}] {msg}\n");
    let _ = std::io::stderr().lock().write_all(line.as_bytes());
}

/// A parameter error as bad input (exit code 2: `rpkm launch` does not restart the node).
#[expect(
    clippy::needless_pass_by_value,
    reason = "used as `map_err(bad_param)`"
)]
pub fn bad_param(e: ParamError) -> anyhow::Error {
    crate::error::bad_input(e.to_string())
}

/// One `diagnostic_msgs/DiagnosticStatus` of an rpkm node; `name` is its status name
/// ([`NodeContext::status_name`]: `rpkm/tcp_estimator`, `machine_a/tcp_estimator`).
pub fn status(
    level: u8,
    name: &str,
    message: String,
    values: Vec<(&str, String)>,
) -> DiagnosticStatus {
    DiagnosticStatus {
        level,
        name: name.to_owned(),
        message,
        hardware_id: "scissors_kinematics".into(),
        values: values
            .into_iter()
            .map(|(k, v)| KeyValue {
                key: k.to_owned(),
                value: v,
            })
            .collect(),
    }
}

/// A DiagnosticArray stamped now with one status.
pub fn diagnostic_array(s: DiagnosticStatus) -> DiagnosticArray {
    DiagnosticArray {
        header: Header {
            stamp: Time::now(),
            frame_id: String::new(),
        },
        status: vec![s],
    }
}

/// How a node waits when its inputs are empty: `yield` for `busy` after the last sample (the
/// next one of a servo stream is due within a millisecond, and a sleep would cost the
/// latency), then sleeps `idle_sleep` between polls so that an idle node costs no core.
#[derive(Debug, Clone, Copy)]
pub struct Idle {
    last_work: Instant,
    busy: Duration,
    sleep: Duration,
}

impl Idle {
    /// A waiter that yields for `busy` after work, then sleeps `idle_sleep`.
    pub fn new(busy: Duration, idle_sleep: Duration) -> Self {
        Self {
            last_work: Instant::now(),
            busy,
            sleep: idle_sleep,
        }
    }
    /// Records that a sample was processed.
    pub fn worked(&mut self) {
        self.last_work = Instant::now();
    }
    /// Waits a little before the next poll.
    pub fn wait(&self) {
        if self.last_work.elapsed() < self.busy {
            std::thread::yield_now();
        } else {
            std::thread::sleep(self.sleep);
        }
    }
    /// Waits for `input`: yields during the busy time after work, then sleeps until a
    /// publisher's wake-up (iceoryx2) or for at most `idle_sleep` (the caller's other duties,
    /// reports and parameter checks, need the loop back by then).
    pub fn wait_for<T: rpkm_transport::IpcMessage>(
        &self,
        input: &rpkm_transport::Subscriber<T>,
    ) -> Result<(), rpkm_transport::TransportError> {
        if self.last_work.elapsed() < self.busy {
            std::thread::yield_now();
            Ok(())
        } else {
            input.wait(self.sleep)
        }
    }
}

/// A regular timer: `due()` is true once per period.
#[derive(Debug, Clone, Copy)]
pub struct Every {
    next: Instant,
    period: Duration,
}

impl Every {
    /// First due one period from now.
    pub fn new(period: Duration) -> Self {
        Self {
            next: Instant::now() + period,
            period,
        }
    }
    /// True (and re-armed) when the period has passed.
    pub fn due(&mut self) -> bool {
        let now = Instant::now();
        if now >= self.next {
            self.next = now + self.period;
            true
        } else {
            false
        }
    }
}
