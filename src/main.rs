//! `rpkm`: accuracy of redundantly actuated parallel kinematic machines.

use clap::{Parser, Subcommand};
use rpkm::cli;

/// rpkm keeps redundantly actuated parallel kinematic machines (the Scissors-Kinematics:
/// a planar 2-dof platform on four position-controlled linear drives) accurate: calibration
/// with every method of the thesis, observability analysis, elasto-geometric preload, a
/// digital twin, and model discovery. Lengths in mm and angles in rad in files; SI on ROS topics.
#[derive(Parser, Debug)]
#[command(name = "rpkm", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Identify the geometric parameters from a campaign CSV (see `rpkm calibrate --help`).
    Calibrate(cli::calibrate::CalibrateArgs),
    /// Find the physical effect the model is missing (see `rpkm diagnose --help`).
    Diagnose(cli::diagnose::DiagnoseArgs),
    /// A machine's calibrations as recorded: what changed since the last one and whether it
    /// is real, trends and tolerance crossings; text, CSV, HTML (see `rpkm history --help`).
    History(cli::history::HistoryArgs),
    /// Sensitivity and observability of the parameters for a calibration method (thesis 4.2.3-4.3.4).
    Analyze(cli::analyze::AnalyzeArgs),
    /// Simulate measurement campaigns on the digital twin, with hidden effects.
    Simulate(cli::simulate::SimulateArgs),
    // about: the first paragraph of `PlanArgs`' documentation, `--help` all of it
    Plan(cli::plan::PlanArgs),
    /// Predicted rod and drive forces and redundancy current at a pose.
    Preload(cli::preload::PreloadArgs),
    /// The whole story on the embedded default data: model vs measurements, where it fails,
    /// the missing effect, the held-out error falling; writes an HTML report.
    Demo(cli::demo::DemoArgs),
    /// Record rpkm topics into a rosbag2 MCAP bag; survives SIGKILL (see `rpkm bag recover`).
    Record(cli::record::RecordArgs),
    /// Publish a bag's rpkm topics with the recorded timing, scaled, or as fast as possible.
    Replay(cli::replay::ReplayArgs),
    /// Inspect (info), repair (recover) and convert back (campaign) rosbag2 MCAP bags.
    Bag(cli::bag::BagArgs),
    /// Convert a campaign CSV into a bag of ActuatorState and TcpMeasurement messages (SI).
    Ingest(cli::ingest::IngestArgs),
    /// Live terminal view of a running node set or a replayed bag: currents against the
    /// preload thresholds, levels, TCP estimates, silent nodes (see `rpkm monitor --help`).
    Monitor(cli::monitor::MonitorArgs),
    /// Run one ROS 2 node: ingest, tcp_estimator, calibrator or preload_monitor.
    Node(rpkm_nodes::node::NodeArgs),
    /// Start and supervise the nodes of a launch description (ROS 2 launch YAML).
    Launch(rpkm::launch::LaunchArgs),
    /// Benchmarks of the product as a user meets it (`rpkm bench discovery --help`).
    Bench(cli::bench::BenchArgs),
    /// SROS2 keystores for DDS security: CA, governance, an enclave per program
    /// (`rpkm security keystore --help`).
    Security(cli::security::SecurityArgs),
}

impl Command {
    /// Whether the command is a filter-like report writer (stdout may be `| head`), as
    /// opposed to the long-running processes on the transports (nodes, launch, record,
    /// replay), which must report a broken connection instead of vanishing on a signal.
    fn writes_reports(&self) -> bool {
        !matches!(
            self,
            Command::Node(_)
                | Command::Launch(_)
                | Command::Record(_)
                | Command::Replay(_)
                | Command::Monitor(_)
        )
    }
}

/// Restores the default SIGPIPE disposition. Rust ignores SIGPIPE, so output into a closed
/// pipe (`rpkm calibrate c.csv | head -1`) makes `println!` panic with exit 101; with the
/// default the process ends quietly on the signal, as every Unix filter does.
fn quiet_broken_pipe() {
    // SAFETY: signal(2) with a valid signal number and the default disposition, called
    // from main before any thread is started.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

fn main() {
    // as `rpkm-node` does: a node runs here as it runs there
    rpkm_nodes::program::keep_freed_memory();
    let args = Cli::parse();
    if args.command.writes_reports() {
        quiet_broken_pipe();
    }
    rpkm_nodes::logging::init();
    let result = match &args.command {
        Command::Calibrate(a) => cli::calibrate::run(a),
        Command::Diagnose(a) => cli::diagnose::run(a),
        Command::History(a) => cli::history::run(a),
        Command::Analyze(a) => cli::analyze::run(a),
        Command::Simulate(a) => cli::simulate::run(a),
        Command::Plan(a) => cli::plan::run(a),
        Command::Preload(a) => cli::preload::run(a),
        Command::Demo(a) => cli::demo::run(a),
        Command::Record(a) => cli::record::run(a),
        Command::Replay(a) => cli::replay::run(a),
        Command::Bag(a) => cli::bag::run(a),
        Command::Ingest(a) => cli::ingest::run(a),
        Command::Monitor(a) => cli::monitor::run(a),
        Command::Node(a) => rpkm_nodes::node::run(a),
        Command::Launch(a) => rpkm::launch::run(a),
        Command::Bench(a) => cli::bench::run(a),
        Command::Security(a) => cli::security::run(a),
    };
    if let Err(e) = result {
        eprintln!("error: {}", cli::error_chain(&e));
        std::process::exit(cli::exit_code(&e));
    }
}
