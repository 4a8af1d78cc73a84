//! The options of `rpkm plan`.

use std::path::PathBuf;

/// What to measure next: the poses that make the TCP most accurate, and what they buy (see
/// `rpkm plan --help`).
///
/// Calibrates the campaign (tolerance prior, noise estimated from it, --effects in the model),
/// then chooses the poses that make the TCP most accurate for the poses spent: the expected
/// held-out RMS after the plan over the workspace grid (or the poses of --where), each
/// relative setup's shared zero in the noise. The summary says it now, after the plan, and
/// after as many random poses, with the TCP's own error above the tracker's noise beside it;
/// with several budgets (--budget 3,5,10,20) for each, to show where more poses stop paying;
/// where the plan buys nothing, which other instruments would.
///
/// "Held-out RMS" is the diagnosis's (`val_rms_relative_um` in `rpkm diagnose --json`): the
/// TCP errors (model minus reading) of a held-out tracker setup less their setup's mean per
/// coordinate, RMS over the values; here expected over the parameters' remaining uncertainty
/// and the tracker's noise, at the grid's 231 poses or the --where poses.
///
/// External instruments measure in the drives' mode of the campaign's external rows (q2, q3
/// following where they did), with all four drives active only where the model carries the
/// preload (--effects preload_elastic) and the campaign recorded the drive forces; --follower
/// names another. Every setup zeroed on a reading ends with a return to its reset pose: its
/// reading is the instrument's drift, which `rpkm calibrate` reports.
///
/// --criterion determinant plans for the parameter combinations determined (issue 28's
/// D-optimal plan); --separate plans the poses that tell two tied explanations apart.
/// Writes PLAN.csv (the campaign grammar without measured values: setup, instrument, reset,
/// follower, target x, y) that `rpkm simulate --plan` runs on the twin. Methods and figures:
/// docs/observability.md, "What to measure next".
#[derive(clap::Args, Debug, Clone)]
#[command(after_long_help = "Examples:\n  \
rpkm plan self.csv --instruments lt --budget 3,5,10,20 --out plan.csv\n  \
rpkm plan cal.csv --effects preload_elastic --where path.csv --budget 8 --out plan.csv\n  \
rpkm plan self.csv --separate dir_q2,dir_q4 --budget 60 --out sep.csv --json sep.json\n\n\
Then: rpkm simulate --plan plan.csv --out planned.csv (the twin measures it), and\n  \
rpkm calibrate with the planned poses: its drift checks report each setup's return.")]
pub struct PlanArgs {
    /// The campaign measured so far (CSV).
    pub campaign: PathBuf,
    /// Parameter model: 24 or 29.
    #[arg(long, default_value_t = 29)]
    pub model: u32,
    /// Instruments the plan may use, comma-separated: lt, kgm, dbb, psi (platform angle),
    /// self (q2, q3 followers). Default: lt, or self with --separate.
    #[arg(long, value_delimiter = ',')]
    pub instruments: Vec<String>,
    /// Poses to plan, its setups' reset and return poses included; several, comma-separated,
    /// print the expected held-out RMS of each (PLAN.csv and --json hold the last's plan).
    #[arg(long, value_delimiter = ',', default_value = "20")]
    pub budget: Vec<usize>,
    /// What the plan is for: `tcp` (the TCP's expected held-out RMS) or `determinant` (the
    /// parameter combinations determined, D-optimal).
    #[arg(long, default_value = "tcp")]
    pub criterion: String,
    /// Where the TCP must be right: a CSV of target positions (header `x,y`, mm), or a
    /// campaign CSV whose poses' (q1, q4) give them (a recorded production path). Default:
    /// the workspace's 231-point grid.
    #[arg(long = "where")]
    pub where_: Option<PathBuf>,
    /// The drives in follower mode while the external instruments measure: `23` (q2, q3
    /// following) or `none` (all four active; `""` alike). Default: as the campaign's external rows,
    /// all active where --effects has preload_elastic and the campaign recorded the forces.
    #[arg(long)]
    pub follower: Option<String>,
    /// Physical effects in the model, as `rpkm calibrate --effects` (e.g. preload_elastic).
    #[arg(long, default_value = "")]
    pub effects: String,
    /// Effects written as data (YAML, docs/effects.md) that --effects may name.
    #[arg(long)]
    pub effects_file: Option<PathBuf>,
    /// Two explanations to separate, A,B: dir_q1..dir_q4 (lost motion of a carrier) or
    /// parameter names (l1, gamma2, ...).
    #[arg(long, value_delimiter = ',')]
    pub separate: Vec<String>,
    /// Size of a lost motion the separation is judged at, mm.
    #[arg(long, default_value_t = 0.01)]
    pub lost_motion_mm: f64,
    /// The tolerances of the calibration and of the plan, as `rpkm calibrate`'s: what the
    /// campaign leaves unmeasured is this uncertain (the "now" of the forecast).
    #[command(flatten)]
    pub tolerance: crate::cli::prior_args::PriorArgs,
    /// Stated noise (as `rpkm calibrate --noise`); the campaign re-estimates what it shows.
    #[arg(long)]
    pub noise: Option<String>,
    /// Where to write PLAN.csv.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Where to write the plan as JSON.
    #[arg(long)]
    pub json: Option<PathBuf>,
}
