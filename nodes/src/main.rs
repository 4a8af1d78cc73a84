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
}

fn main() {
    let args = Cli::parse();
    let result = match &args.command {
        Command::Calibrate(a) => cli::calibrate::run(a),
    };
    if let Err(e) = result {
        eprintln!("error: {e:#}");
        std::process::exit(cli::exit_code(&e));
    }
}
