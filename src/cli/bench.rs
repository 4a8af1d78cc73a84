//! `rpkm bench`: the product measured as a user meets it (discovery, soak, calibration,
//! plans), one module per benchmark.

mod calibration;
mod discovery;
mod growth;
mod machines;
mod plan;
mod soak;

use anyhow::Result;

/// Benchmarks of the product as a user meets it.
#[derive(clap::Args, Debug)]
pub struct BenchArgs {
    #[command(subcommand)]
    pub which: Bench,
}

#[derive(clap::Subcommand, Debug)]
pub enum Bench {
    /// The discovery loop (diagnose, add the named effect, again) on N random machines from
    /// the twin, with conventions drawn at random per machine: every noise group 0.5x-3x the
    /// spec's figures (the diagnosis starts from the spec's), relative instruments zeroed on
    /// a noisy reading, which thermal parts expand and by how much, effect magnitudes from
    /// 0.3x to 3x their defaults, parameter errors. Classes: no hidden effect, one or two of
    /// the library, lost motion, a periodic scale error (1-5 µm, pitch 10-200 mm, any
    /// carrier), a rod softer or stiffer than the others with all drives active, an
    /// instrument alignment down to where it hardly matters; and campaign compositions and
    /// combinations: thermal expansion measured by a tracker and self-calibration only,
    /// thermal expansion with the preload of all drives active, guides warming at rates of
    /// their own (with a thermometer per guide or without), a tracker creeping after each
    /// zero (offered written as data), lost motion and a periodic scale error at once (both
    /// offered written as data). Prints the confusion matrix (hidden vs named), each class's
    /// share right, the machines where a named effect raised the held-out error, the
    /// false-alarm rate on machines with nothing hidden, every `nothing_missing` the held-out
    /// data contradict, and the held-out RMS after the loop divided by the true floor. On a
    /// class whose hidden effects can be written as a model (`--class thermometer_lag`: the
    /// twin's parts of thermal and thermal_lag pinned), it also diagnoses that truth itself on
    /// the same campaigns and prints how often even the truth ends nothing_missing at the
    /// floor, and on which of the loop's wrong machines it does not (`truth` in the JSON).
    ///
    /// Example: rpkm bench discovery --machines 200 --seed 1 --threads 2 --json bench.json
    Discovery(DiscoveryArgs),
    /// The launched node set (launch_scripts/rpkm.launch.yaml, source:=stdin) under an
    /// actuator stream written into ingest's stdin at the stream rate for SECONDS: counts the
    /// estimates lost and their gaps (at the observer, and in the estimator's and the
    /// monitor's input) and prints the resident memory of every process at the start, each
    /// quarter and the end. Exit 1 when an estimate was lost.
    ///
    /// Example: rpkm bench soak --seconds 180 --rate-hz 8000
    Soak(soak::SoakArgs),
    /// Calibration time, LM iterations and peak memory of `rpkm calibrate` on twin
    /// self-calibration campaigns of about 10³, 10⁴ and 10⁵ poses (child processes, on every
    /// core and on one), the same 10⁵ random-target poses in 10, 100 and 1,000 setups and a
    /// campaign of the foreign simulator's class of design (each against the best), the diagnosis of a 1,000-pose campaign with every library effect, and,
    /// when Python with scipy is there, a plain scipy least_squares script's fit against
    /// rpkm's fit of the same problem alone and against whole `rpkm calibrate` processes.
    ///
    /// Example: rpkm bench calibration --repeats 7,67,672
    Calibration(calibration::CalibrationArgs),
    /// Planned tracker poses against random ones on twin machines (`rpkm bench plan --help`).
    Plan(plan::PlanStudyArgs),
}

#[derive(clap::Args, Debug)]
pub struct DiscoveryArgs {
    #[arg(long, default_value_t = 50)]
    pub machines: usize,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Only the machines of this class: the series' first --machines of it (machine i the same
    /// as without --class), or for thermometer_lag, drawn only on demand, --machines of it.
    /// Example: --class thermometer_lag --machines 12
    #[arg(long)]
    pub class: Option<machines::Class>,
    /// Worker threads (one machine each at a time).
    #[arg(long, default_value_t = 2)]
    pub threads: usize,
    /// Write every machine's outcome as JSON.
    #[arg(long)]
    pub json: Option<std::path::PathBuf>,
    /// Run only machine I of the series and print every verdict of its loop (to look at
    /// one the table counts wrong).
    #[arg(long)]
    pub only: Option<usize>,
    /// With --only: write that machine's campaigns (cal.csv, val.csv), the effects a user
    /// offers (effects.yaml, where the class offers any) and what it hides (machine.txt)
    /// into this folder, to run `rpkm diagnose DIR/cal.csv --validate DIR/val.csv` on.
    #[arg(long, requires = "only")]
    pub write: Option<std::path::PathBuf>,
}

pub fn run(args: &BenchArgs) -> Result<()> {
    match &args.which {
        Bench::Discovery(a) => discovery::run(a),
        Bench::Soak(a) => soak::run(a),
        Bench::Calibration(a) => calibration::run(a),
        Bench::Plan(a) => plan::run(a),
    }
}
