//! `rpkm security keystore|enclave|permissions`: an SROS2 keystore for the cell, as sros2's
//! `ros2 security create_keystore|create_enclave|create_permission` write it, without ROS.

use std::path::PathBuf;

use anyhow::Result;

use crate::security::{policy, Created, Keystore, KeystoreError};

/// SROS2 keystores: the cell's CA, a governance that encrypts everything and admits no
/// unauthenticated participant, and an enclave per program with exactly the topics and
/// services it uses. The nodes use it with ROS_SECURITY_ENABLE=true,
/// ROS_SECURITY_STRATEGY=Enforce and ROS_SECURITY_KEYSTORE=DIR (docs/nodes.md, "Security").
#[derive(clap::Args, Debug, Clone)]
#[command(after_help = "Examples:\n  \
rpkm security keystore cell_keys\n  \
rpkm security enclave cell_keys --all                 # /rpkm/ingest, /rpkm/tcp_estimator, ...\n  \
rpkm security enclave cell_keys /rpkm/tcp_estimator\n  \
rpkm security permissions cell_keys /rpkm/ingest --subscribe /cell/frame_temperature   # a thermometer\n  \
rpkm security permissions cell_keys /rpkm/tcp_estimator --namespace /machine_a\n  \
ROS_SECURITY_ENABLE=true ROS_SECURITY_STRATEGY=Enforce ROS_SECURITY_KEYSTORE=$PWD/cell_keys \\\n    \
rpkm launch launch_scripts/rpkm.launch.yaml backend:=dds")]
pub struct SecurityArgs {
    #[command(subcommand)]
    pub command: SecurityCommand,
}

/// The keystore commands.
#[derive(clap::Subcommand, Debug, Clone)]
pub enum SecurityCommand {
    /// Creates a keystore in DIR: the CA (public/, private/) and the signed governance
    /// (enclaves/governance.p7s). An existing keystore is left as it is.
    Keystore {
        /// Keystore folder (created).
        dir: PathBuf,
    },
    /// Creates an enclave: its identity (cert.pem, key.pem; kept if there), links to the CA
    /// certificates and governance, and its default permissions.
    Enclave(EnclaveArgs),
    /// Rewrites and signs the default permissions of an existing enclave (after a namespace
    /// change, or a new rpkm version's topics).
    Permissions(EnclaveArgs),
}

/// Which enclave, and the program and namespace its permissions are for.
#[derive(clap::Args, Debug, Clone)]
pub struct EnclaveArgs {
    /// Keystore folder.
    pub dir: PathBuf,
    /// Enclave name, an absolute ROS 2 namespace (`/rpkm/tcp_estimator`); its last part
    /// names the program unless --node does.
    #[arg(required_unless_present = "all", conflicts_with = "all")]
    pub name: Option<String>,
    /// Every program's default enclave: /rpkm/ingest, /rpkm/tcp_estimator, /rpkm/calibrator,
    /// /rpkm/preload_monitor, /rpkm/record, /rpkm/replay, /rpkm/monitor, /rpkm/launch.
    #[arg(long)]
    pub all: bool,
    /// The program whose permissions the enclave gets: ingest, tcp_estimator, calibrator,
    /// preload_monitor, record, replay, monitor, launch, or cell (a cell controller: every
    /// node's parameter, lifecycle and calibration services and the Calibrate action, as
    /// `ros2 param`, `ros2 lifecycle` and an action client use them:
    /// `rpkm security enclave KEYS /cell/controller --node cell`).
    #[arg(long, conflicts_with = "all")]
    pub node: Option<String>,
    /// Namespace of the node set (`namespace:=` of the launch): its topics and services.
    #[arg(long, default_value = rpkm_transport::NODE_NAMESPACE)]
    pub namespace: String,
    /// A topic of the cell the enclave also reads (repeatable): a thermometer that ingest's
    /// joint_states source reads (`--subscribe /cell/frame_temperature`).
    #[arg(long, value_name = "TOPIC", conflicts_with = "all")]
    pub subscribe: Vec<String>,
    /// A topic of the cell the enclave also writes (repeatable): for a cell program with an
    /// enclave of this keystore (`--publish /joint_states`).
    #[arg(long, value_name = "TOPIC", conflicts_with = "all")]
    pub publish: Vec<String>,
}

impl EnclaveArgs {
    /// (enclave, program) pairs the command writes.
    fn targets(&self) -> Vec<(String, String)> {
        if self.all {
            return policy::PROGRAMS
                .iter()
                .map(|p| {
                    (
                        format!("{}/{p}", rpkm_transport::NODE_NAMESPACE),
                        (*p).to_owned(),
                    )
                })
                .collect();
        }
        let name = self.name.clone().unwrap_or_default();
        let program = self
            .node
            .clone()
            .unwrap_or_else(|| policy::program_of(&name).to_owned());
        vec![(name, program)]
    }
}

/// Bad input (exit 2): a keystore or enclave that is not there, a name or program that
/// cannot be used. Failing I/O or OpenSSL stays exit 1.
fn classify(e: KeystoreError) -> anyhow::Error {
    match e {
        KeystoreError::NotAKeystore { .. }
        | KeystoreError::NoEnclave { .. }
        | KeystoreError::Enclave { .. } => super::bad_input(e.to_string()),
        other => anyhow::Error::new(other),
    }
}

pub fn run(args: &SecurityArgs) -> Result<()> {
    match &args.command {
        SecurityCommand::Keystore { dir } => {
            let (_, created) = Keystore::create(dir).map_err(classify)?;
            match created {
                Created::New => eprintln!("{}: keystore created", dir.display()),
                Created::Existing => {
                    eprintln!("{}: already a keystore, left as it is", dir.display());
                }
            }
            Ok(())
        }
        SecurityCommand::Enclave(a) => enclaves(a, true),
        SecurityCommand::Permissions(a) => enclaves(a, false),
    }
}

fn enclaves(args: &EnclaveArgs, create: bool) -> Result<()> {
    let ks = Keystore::open(&args.dir).map_err(classify)?;
    for (enclave, program) in args.targets() {
        let grant = policy::grant(&program, &args.namespace)
            .and_then(|g| policy::with_topics(g, &args.namespace, (&args.publish, &args.subscribe)))
            .map_err(|e| super::bad_input(format!("enclave {enclave}: {e}")))?;
        let written = if create {
            ks.create_enclave(&enclave, &grant)
        } else {
            ks.write_permissions(&enclave, &grant)
        }
        .map_err(classify)?;
        eprintln!(
            "{}: enclave {enclave} ({program}: publishes {}, subscribes {} DDS topics)",
            written.display(),
            grant.publish.len(),
            grant.subscribe.len()
        );
    }
    Ok(())
}
