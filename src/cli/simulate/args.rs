//! The options of `rpkm simulate`.

use std::path::PathBuf;

/// The campaigns of `rpkm simulate --help`.
const CAMPAIGNS: &str = "Campaigns: lt, kgm, dbb, li_x, li_y, li_psi, self, circle, validation, production (500 poses all drives active, no instrument: the drive forces are the measurements; with --effect preload_elastic).\n";

/// The examples of `rpkm simulate --help`, after the effects.
const EXAMPLES: &str = "A plan (rpkm plan --out plan.csv):\n  rpkm simulate --plan plan.csv --effect lost_motion_q4 --seed 7 --out planned.csv\n\n\
Example:\n  rpkm simulate --campaign lt,self --effect thermal=2,encoder_scale --seed 7 \
--out lt_self.csv --truth truth.json --validation 100\n\n\
Bags (--out not ending in .csv; validation poses go to the bag OUT_val):\n  \
rpkm simulate --campaign lt,self --effect parallelogram=1.0 --seed 7 --out calibration \
--validation 0\n  \
rpkm simulate --stream-hz 8000 --stream-seconds 0.5 --seed 3 --out stream_8khz\n  \
rpkm simulate --stream-hz 1000 --stream-seconds 2 --stream-motion hold --fault q3=0.8 \
--effect preload_elastic=1 --seed 5 --out preload_fault --truth preload_fault.truth.json\n\n\
Production stream (CSV, truth in prod.truth.csv):\n  \
rpkm simulate --production-seconds 600 --production-step l3=0.1@300 --production-decimate 100 \
--effect preload_elastic --seed 3 --out prod.csv\n  \
rpkm simulate --production-seconds 600 --production-step l3=0.1@300 \
--production-visit=-150,2000;150,1600@307 --production-decimate 100 --effect preload_elastic \
--seed 3 --out prod_motion.csv";

/// Simulate measurement campaigns on the digital twin (a seeded true machine with hidden
/// effects) and write them in the campaign CSV format, or as a rosbag2 MCAP bag (--out not
/// ending in .csv) holding the same messages as `rpkm ingest` and, with --stream-hz, an
/// ActuatorState stream at the control rate.
///
/// Example:
///   rpkm simulate --campaign lt,self --effect thermal=2,encoder_scale --seed 7 \
///       --out lt_self.csv --truth truth.json --validation 100
/// writes lt_self.csv, the held-out validation poses to lt_self.val.csv and the hidden truth
/// (true parameters, stiffness, effects) to truth.json.
#[derive(clap::Args, Debug, Clone)]
#[command(after_help = format!(
    "{CAMPAIGNS}{}\n{EXAMPLES}",
    crate::cli::library_help::twin_effects()
))]
pub struct SimulateArgs {
    /// Comma-separated campaigns, measured one after the other into one file (optional for
    /// a bag with --stream-hz).
    #[arg(
        long,
        value_delimiter = ',',
        required_unless_present_any = ["stream_hz", "production_seconds", "plan"]
    )]
    pub campaign: Vec<String>,
    /// A planned campaign (`rpkm plan --out PLAN.csv`) to measure instead: its setups and
    /// poses in its order, on the twin (CSV --out only).
    #[arg(long, conflicts_with_all = ["campaign", "production_seconds", "stream_hz"])]
    pub plan: Option<PathBuf>,
    /// Hidden effects, NAME or NAME=MAGNITUDE, comma-separated (default magnitude if none).
    #[arg(long, value_delimiter = ',')]
    pub effect: Vec<String>,
    /// Rods of another stiffness than the model's default, ROD=FACTOR comma-separated (rod
    /// 1..5, the factor on the default axial stiffness): a rod 30 % stiffer than the others,
    /// `--rod-stiffness 3=1.3`. With all drives active (`--effect preload_elastic`) it takes
    /// another share of the preload; `rpkm diagnose` names it `preload_elastic:rod3`.
    #[arg(long, value_delimiter = ',')]
    pub rod_stiffness: Vec<String>,
    /// Seed of the true machine, the noise and the validation poses.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Output: a campaign CSV if it ends in .csv, else a new bag folder.
    #[arg(long)]
    pub out: PathBuf,
    /// Where to write the hidden truth as JSON.
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// Number of held-out validation poses, written to FILE.val.csv (0: none). With
    /// `--campaign validation` alone they go to --out.
    #[arg(long, default_value_t = 100)]
    pub validation: usize,
    /// Noise-free instruments and encoders.
    #[arg(long, conflicts_with = "noise")]
    pub no_noise: bool,
    /// The twin's noise, NAME=VALUE comma-separated (mm, rad for psi; the rest at the spec's
    /// figures): `lt` (isotropic tracker), `lt_along`, `lt_across`, `lt_across_per_m`, `kgm`,
    /// `dbb`, `li`, `psi`, `encoder`, `force` (N), `tracker_x`, `tracker_y`. A machine noisier than what
    /// the calibration assumes: `--noise encoder=0.0005,lt=0.006`.
    #[arg(long)]
    pub noise: Option<String>,
    /// A relative instrument whose readings drift after its zero, INSTRUMENT=VX,VY in µm
    /// per minute along x and y (a single-coordinate instrument takes one value; µrad/min
    /// for li_psi): every reading carries the rate times the time since its setup's reset
    /// pose. A tracker creeping 1 µm/min along y: `--drift lt=0,1`.
    #[arg(long)]
    pub drift: Option<String>,
    /// Bag only: also write an ActuatorState stream at this rate (Hz) on
    /// /rpkm/actuator_state, after the campaign (if any) on the twin's clock.
    #[arg(long)]
    pub stream_hz: Option<f64>,
    /// Length of the stream, s.
    #[arg(long, default_value_t = 1.0)]
    pub stream_seconds: f64,
    /// Commanded path during the stream.
    #[arg(long, value_enum, default_value_t = rpkm_nodes::stream::StreamPath::Circle)]
    pub stream_motion: rpkm_nodes::stream::StreamPath,
    /// A drive whose carrier drifts from its encoder during the stream, qN=MM, ramped from 0
    /// to MM (e.g. q3=0.8: with preload_elastic the drives then fight, the redundancy
    /// current grows; 0.4 mm on q3 is about 100 %).
    #[arg(long)]
    pub fault: Option<rpkm_nodes::stream::Fault>,
    /// A production stream instead of campaigns (issue 15): this many seconds of a
    /// machining-like path (random contour moves at 50 mm/s), all drives active (give
    /// --effect preload_elastic), force noise, a drifting temperature, sampled at --stream-hz
    /// (default 1000) and written every --production-decimate-th sample as a campaign CSV
    /// (instrument none, f1..f4, temp_machine), with the truth over time beside it in
    /// OUT.truth.csv (true TCP, noiseless forces and the 29 true parameters per row).
    #[arg(long)]
    pub production_seconds: Option<f64>,
    /// Temperature drift of the production stream, K/h.
    #[arg(long, default_value_t = 4.0)]
    pub production_drift: f64,
    /// A crash during the production stream: PARAM=CHANGE@SECONDS (mm or rad), e.g.
    /// l3=0.1@2400 bends rod 3 by 0.1 mm at 40 min.
    #[arg(long)]
    pub production_step: Option<String>,
    /// A motion the cell commands during the production stream: X,Y;X,Y;...@SECONDS (mm,
    /// the workspace's poses in order), e.g. the one the calibrator's WARN names to tell a
    /// tie apart: -150,2000;150,1600@36.9. The path goes there at feed speed, stays
    /// --production-dwell at each, then goes on.
    #[arg(long, requires = "production_seconds")]
    pub production_visit: Option<String>,
    /// Seconds at each pose of --production-visit.
    #[arg(long, default_value_t = 1.0)]
    pub production_dwell: f64,
    /// Write one production sample in this many.
    #[arg(long, default_value_t = 1)]
    pub production_decimate: usize,
    /// Bag only: compress chunks with zstd.
    #[arg(long)]
    pub zstd: bool,
    /// Bag only: record the machine's geometry on /rpkm/parameters at the twin's start, as
    /// the calibrator publishes a calibration that found it (the twin's true parameters,
    /// model 29, σ 0): a replay gives the nodes that follow /rpkm/parameters (the estimator,
    /// the preload monitor) and `rpkm monitor` the machine, as a recording of a calibrated
    /// machine does. Example: --stream-hz 1000 --fault q3=0.8 --record-parameters
    #[arg(long)]
    pub record_parameters: bool,
}
