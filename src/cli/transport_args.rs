//! What `rpkm record`, `replay` and `monitor` share: the transport options and the stop flag
//! SIGINT and SIGTERM set.

use anyhow::{Context, Result};
use rpkm_transport::{Transport, TransportConfig};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

/// Transport options shared by `rpkm record` and `rpkm replay`.
#[derive(clap::Args, Debug, Clone)]
pub struct TransportArgs {
    /// Middleware: ipc (iceoryx2, rpkm processes on this host), dds (ROS 2 tools, other
    /// hosts) or both (recording receives from iceoryx2 then, like every rpkm subscriber).
    #[arg(long, default_value = "ipc", value_parser = parse_backend)]
    pub backend: rpkm_transport::Backend,
    /// Prefix of the iceoryx2 service names: processes talk only with the same prefix
    /// (default: env RPKM_IPC_PREFIX, as the nodes, else none).
    #[arg(long)]
    pub ipc_prefix: Option<String>,
    /// Open every topic reliable: iceoryx2 publishers then wait for slow subscribers instead
    /// of overwriting, so nothing is dropped even at `rpkm replay --rate max`. Every process
    /// on those topics must use it (the replayer and the recorder), not nodes started without.
    #[arg(long)]
    pub reliable: bool,
    /// ROS 2 namespace of the node set (as launched with `namespace:=NS`): its topics are
    /// `NS/tcp_estimate`, ... (default /rpkm).
    #[arg(long, default_value = rpkm_transport::NODE_NAMESPACE)]
    pub namespace: String,
    /// SROS2 enclave of the DDS participant, used when ROS_SECURITY_ENABLE=true (default
    /// /rpkm/record, /rpkm/replay, /rpkm/monitor: the enclaves `rpkm security enclave` makes).
    #[arg(long)]
    pub enclave: Option<String>,
}

/// `ipc`, `dds` or `both`.
pub fn parse_backend(s: &str) -> Result<rpkm_transport::Backend, String> {
    match s {
        "ipc" => Ok(rpkm_transport::Backend::Ipc),
        "dds" => Ok(rpkm_transport::Backend::Dds),
        "both" => Ok(rpkm_transport::Backend::Both),
        other => Err(format!("{other:?}: expected ipc, dds or both")),
    }
}

impl TransportArgs {
    /// Opens the transport as node `name`, in `--enclave` or else `default_enclave`.
    /// How the topics are opened: `--reliable`, or as their publishers offer.
    pub fn delivery(&self) -> rpkm_nodes::topics::Delivery {
        if self.reliable {
            rpkm_nodes::topics::Delivery::Reliable
        } else {
            rpkm_nodes::topics::Delivery::AsOffered
        }
    }

    pub fn open(&self, name: &str, default_enclave: &str) -> Result<Transport> {
        let prefix = match &self.ipc_prefix {
            Some(p) => p.clone(),
            None => std::env::var("RPKM_IPC_PREFIX").unwrap_or_default(),
        };
        let names = rpkm_transport::Names::new(&self.namespace, &[])
            .map_err(|e| rpkm_nodes::error::bad_input(format!("--namespace: {e}")))?;
        let enclave = self.enclave.as_deref().unwrap_or(default_enclave);
        if let Some(why) = rpkm_transport::security::enclave_name_error(enclave) {
            return Err(rpkm_nodes::error::bad_input(format!(
                "--enclave {enclave:?}: {why}"
            )));
        }
        let config = TransportConfig::new(name)
            .backend(self.backend)
            .ipc_prefix(prefix)
            .names(names)
            .enclave(enclave);
        Transport::new(&config).with_context(|| format!("opening the transport of {name}"))
    }
}

/// A flag that SIGINT and SIGTERM set.
pub fn stop_flag() -> Result<Arc<AtomicBool>> {
    let stop = Arc::new(AtomicBool::new(false));
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(signal, Arc::clone(&stop))
            .with_context(|| format!("installing the handler of signal {signal}"))?;
    }
    Ok(stop)
}
