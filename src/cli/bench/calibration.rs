//! `rpkm bench calibration`: how calibration and diagnosis scale with the campaign, as a user
//! runs them (whole `rpkm calibrate` processes), side by side in one run.
//!
//! - Calibration of twin self-calibration campaigns of about 10³, 10⁴ and 10⁵ poses (the
//!   thesis's self-calibration design repeated; each run a child `rpkm calibrate` process):
//!   wall time, LM iterations, peak resident memory (the child's own `VmHWM`, from its JSON),
//!   time per pose.
//! - The same calibrations on one thread (`--threads 1`): the parallel speed-up.
//! - The cost per setup (issue 30): the same 10⁵ random-target self-calibration poses split
//!   into 10, 100 and 1,000 setups, and a campaign of the foreign simulator's class of design
//!   (random targets in small setups of laser tracker, grid encoder and self-calibration),
//!   whole `rpkm calibrate` processes with default options, medians of [`SETUP_RUNS`]; each
//!   against the best of them.
//! - Diagnosis of a campaign of about 1,000 poses with every library effect tried, in
//!   process: screened (the default) and with every candidate fitted to convergence.
//! - Diagnosis at scale: 10⁵ random-target self-calibration poses in 1,000 setups of a machine
//!   with nothing hidden whose temperature swings between 20 and 24 °C (nothing expands), in
//!   process, on every core: its time and verdict (issue 36: `nothing_missing` in under 10 s).
//! - The diagnosis's growth with the rows ([`super::growth`]): 100 to 1,000 setups of 100
//!   self-calibration poses, with and without a validation file, whole processes.
//! - When Python with scipy is there: the plain `scipy.optimize.least_squares` script of
//!   tests/python on the smallest campaign against rpkm's fit of the same problem alone (in
//!   process) and against whole `rpkm calibrate` processes: both ratios in one run.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use anyhow::{Context, Result};
use rpkm_core::campaign::{Campaign, Instrument};
use rpkm_core::diagnose::{self, DiagnosisOptions};
use rpkm_twin::{Twin, TwinConfig};

use crate::cli::bad_input;
use rpkm_core::units::{ms_from_seconds, us_from_seconds};

#[derive(clap::Args, Debug)]
pub struct CalibrationArgs {
    /// Repetitions of the self-calibration design (149 poses each) per campaign,
    /// comma-separated: 7,67,672 is 1,043, 9,983 and 100,128 poses.
    #[arg(long, value_delimiter = ',', default_value = "7,67,672")]
    pub repeats: Vec<usize>,
    /// Seed of the twin machine and its noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Where the campaigns are written (default: a new folder under the system's temp dir).
    #[arg(long)]
    pub dir: Option<PathBuf>,
    /// Only the cost per setup (the campaigns of 10, 100 and 1,000 setups and the foreign
    /// class); with --dir, their files stay there to profile.
    #[arg(long)]
    pub setups_only: bool,
    /// Only the diagnosis at scale (10⁵ self-calibration poses in 1,000 setups, nothing
    /// hidden, the temperature swinging between 20 and 24 °C).
    #[arg(long)]
    pub scale_only: bool,
    /// Only the diagnosis's growth with the rows: campaigns of 100 to 1,000 setups of 100
    /// self-calibration poses, `rpkm diagnose` with and without a validation file against
    /// `rpkm calibrate` of the same file; with --dir, their files stay there to profile.
    #[arg(long)]
    pub growth_only: bool,
}

/// One `rpkm calibrate` process: its wall time, the LM's iterations, peak memory.
struct Run {
    seconds: f64,
    iterations: u64,
    max_rss_mb: f64,
}

pub fn run(a: &CalibrationArgs) -> Result<()> {
    if a.repeats.is_empty() || a.repeats.iter().any(|&r| r == 0 || r > 10_000) {
        return Err(bad_input(
            "--repeats: expected 1 to 10000 repetitions per campaign".into(),
        ));
    }
    let dir = match &a.dir {
        Some(d) => d.clone(),
        None => std::env::temp_dir().join(format!("rpkm_bench_calibration_{}", std::process::id())),
    };
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    if a.setups_only {
        return setups(&dir, a.seed);
    }
    if a.scale_only {
        return diagnosis_at_scale(a.seed);
    }
    if a.growth_only {
        return super::growth::run(&dir, a.seed);
    }
    println!(
        "{:>9} {:>9} {:>7} {:>10} {:>9} {:>10} {:>9}",
        "poses", "rows", "iters", "time (s)", "µs/pose", "1 thread", "peak MB"
    );
    let mut smallest: Option<PathBuf> = None;
    for &k in &a.repeats {
        let (path, poses) = write_self_campaign(&dir, a.seed, k)?;
        let all = calibrate(&path, None, &[])?;
        let one = calibrate(&path, Some(1), &[])?;
        println!(
            "{poses:>9} {:>9} {:>7} {:>10.3} {:>9.1} {:>9.2}x {:>9.1}",
            2 * poses,
            all.iterations,
            all.seconds,
            us_from_seconds(all.seconds / poses as f64),
            one.seconds / all.seconds,
            all.max_rss_mb
        );
        if Some(&k) == a.repeats.iter().min() && smallest.is_none() {
            smallest = Some(path);
        }
    }
    setups(&dir, a.seed)?;
    diagnosis(a.seed)?;
    diagnosis_at_scale(a.seed)?;
    super::growth::run(&dir, a.seed)?;
    if let Some(path) = smallest {
        scipy_baseline(&path)?;
    }
    if a.dir.is_none() {
        // the campaigns are large: nothing of them is left behind
        std::fs::remove_dir_all(&dir).ok();
    }
    Ok(())
}

/// The self-calibration design measured `k` times on one twin machine, written as CSV.
fn write_self_campaign(dir: &Path, seed: u64, k: usize) -> Result<(PathBuf, usize)> {
    let mut twin = Twin::new(TwinConfig {
        seed,
        ..Default::default()
    })?;
    let campaign = twin.campaign(&vec![Instrument::SelfCal; k])?;
    let path = dir.join(format!("self_x{k}.csv"));
    std::fs::write(&path, campaign.to_csv())
        .with_context(|| format!("writing {}", path.display()))?;
    Ok((path, campaign.poses.len()))
}

/// Poses of the campaigns of [`setups`], and the setups the same poses are split into.
const SETUP_POSES: usize = 100_000;
const SPLITS: [usize; 3] = [10, 100, 1_000];
/// Runs of each campaign of [`setups`] whose median is quoted (the figure).
const SETUP_RUNS: usize = 5;

/// The cost per setup: 10⁵ random-target self-calibration poses measured once on a twin
/// and split into 10, 100 and 1,000 setups (the same poses and readings, only the setup
/// column differs), and a campaign of the foreign simulator's class of design of as many
/// poses; `rpkm calibrate` with default options on each, every figure against the best.
fn setups(dir: &Path, seed: u64) -> Result<()> {
    // the campaigns written and dropped before the first child starts
    let files = write_setup_campaigns(dir, seed)?;
    let mut runs = Vec::new();
    for (what, setups, poses, path) in &files {
        let mut all = (0..SETUP_RUNS)
            .map(|_| calibrate(path, None, &[]))
            .collect::<Result<Vec<Run>>>()?;
        all.sort_by(|a, b| a.seconds.total_cmp(&b.seconds));
        runs.push((what, setups, poses, all.swap_remove(SETUP_RUNS / 2)));
    }
    let best = runs
        .iter()
        .map(|r| r.3.seconds)
        .fold(f64::INFINITY, f64::min);
    println!(
        "\ncost per setup (rpkm calibrate, default options, medians of {SETUP_RUNS}):\n  \
         {:<58} {:>7} {:>7} {:>6} {:>9} {:>8} {:>7}",
        "campaign", "setups", "poses", "iters", "time (s)", "peak MB", "/ best"
    );
    for (what, setups, poses, run) in &runs {
        println!(
            "  {what:<58} {setups:>7} {poses:>7} {:>6} {:>9.3} {:>8.1} {:>6.2}x",
            run.iterations,
            run.seconds,
            run.max_rss_mb,
            run.seconds / best
        );
    }
    Ok(())
}

/// [`setups`]' campaigns written under `dir`: what each is, its setups, poses and file.
fn write_setup_campaigns(dir: &Path, seed: u64) -> Result<Vec<(String, usize, usize, PathBuf)>> {
    use rpkm_core::design::random_setups;
    let mut twin = Twin::new(TwinConfig {
        seed,
        ..Default::default()
    })?;
    let most = SPLITS[SPLITS.len() - 1];
    let design = random_setups(Instrument::SelfCal, most, SETUP_POSES / most, seed);
    let base = twin.run(&design, "self, random targets")?;
    let mut campaigns = Vec::new();
    for n in SPLITS {
        let mut c = base.clone();
        let per = SETUP_POSES / n;
        for (i, pose) in c.poses.iter_mut().enumerate() {
            pose.setup = format!("self{:04}", i / per);
        }
        campaigns.push((format!("self, {n} setups of {per}"), c));
    }
    drop(base);
    // the foreign class: laser-tracker and grid-encoder setups of 10 poses (reset first),
    // self-calibration setups of 100
    let mut twin = Twin::new(TwinConfig {
        seed: seed + 1,
        ..Default::default()
    })?;
    let mut design = random_setups(Instrument::Lt, 1_500, 10, seed + 1);
    design.extend(random_setups(Instrument::Kgm, 1_500, 10, seed + 2));
    design.extend(random_setups(Instrument::SelfCal, 700, 100, seed + 3));
    campaigns.push((
        "foreign class: 1,500 lt + 1,500 kgm of 10, 700 self of 100".into(),
        twin.run(&design, "foreign class")?,
    ));
    let mut files = Vec::new();
    for (k, (what, c)) in campaigns.into_iter().enumerate() {
        let path = dir.join(format!("setups_{k}.csv"));
        std::fs::write(&path, c.to_csv()).with_context(|| format!("writing {}", path.display()))?;
        files.push((what, c.setups().len(), c.poses.len(), path));
    }
    Ok(files)
}

/// `rpkm calibrate FILE [EXTRA]` as a child process: wall time, iterations and peak memory
/// (both from its JSON: wait4's `ru_maxrss` would count this process's peak, which Linux
/// carries across the child's `execve`).
fn calibrate(path: &Path, threads: Option<usize>, extra: &[&str]) -> Result<Run> {
    let json = path.with_extension(format!("t{}.json", threads.unwrap_or(0)));
    let mut cmd = Command::new(std::env::current_exe()?);
    cmd.arg("calibrate")
        .arg(path)
        .arg("--json")
        .arg(&json)
        .args(extra);
    if let Some(t) = threads {
        cmd.arg("--threads").arg(t.to_string());
    }
    cmd.stdout(std::process::Stdio::null());
    let t0 = Instant::now();
    let status = cmd
        .spawn()
        .context("starting rpkm calibrate")?
        .wait()
        .context("waiting for rpkm calibrate")?;
    let seconds = t0.elapsed().as_secs_f64();
    if !status.success() {
        anyhow::bail!("rpkm calibrate {} exited {status}", path.display());
    }
    let text =
        std::fs::read_to_string(&json).with_context(|| format!("reading {}", json.display()))?;
    let value: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("parsing {}", json.display()))?;
    let iterations = value["iterations"]
        .as_u64()
        .with_context(|| format!("{}: no \"iterations\"", json.display()))?;
    Ok(Run {
        seconds,
        iterations,
        // the child's own high-water mark, from its JSON (NaN where the system reports none)
        max_rss_mb: value["peak_resident_mib"].as_f64().unwrap_or(f64::NAN),
    })
}

/// Diagnosis of a twin campaign of about 1,000 poses (laser tracker, grid encoder and
/// self-calibration, three times over) with held-out poses, every library effect tried; in process, on every
/// core.
fn diagnosis(seed: u64) -> Result<()> {
    let mut twin = Twin::new(TwinConfig {
        seed,
        ..Default::default()
    })?;
    let three = [Instrument::Lt, Instrument::Kgm, Instrument::SelfCal];
    let cal: Campaign = twin.campaign(&three.repeat(3))?;
    let val = twin.validation(100)?;
    // screened (the default) and every candidate fitted to convergence, side by side
    let mut ms = [0.0; 2];
    let mut kinds = Vec::new();
    for (k, screen) in [true, false].into_iter().enumerate() {
        let opts = DiagnosisOptions {
            screen,
            ..DiagnosisOptions::default()
        };
        let t0 = Instant::now();
        let d = diagnose::diagnose(&cal, Some(&val), &[], &opts)?;
        ms[k] = ms_from_seconds(t0.elapsed().as_secs_f64());
        kinds.push((d.verdict_kind, d.candidates.len()));
    }
    println!(
        "\ndiagnosis, {} poses, {} candidate effects: {:.0} ms (verdict: {:?}); every candidate \
         fitted to convergence (--no-screen): {:.0} ms ({:?}), {:.1}x",
        cal.poses.len(),
        kinds[0].1,
        ms[0],
        kinds[0].0,
        ms[1],
        kinds[1].0,
        ms[1] / ms[0]
    );
    Ok(())
}

/// Diagnosis of 10⁵ random-target self-calibration poses in 1,000 setups of a machine with
/// nothing hidden whose temperature swings between 20 and 24 °C while nothing expands: a
/// gain too small to matter must not be named at that size. In process, on every core.
fn diagnosis_at_scale(seed: u64) -> Result<()> {
    use rpkm_core::design::random_setups;
    let mut twin = super::growth::still_machine(seed)?;
    let design = random_setups(Instrument::SelfCal, 1_000, 100, seed);
    let cal = twin.run(&design, "self, random targets")?;
    let val = twin.validation(100)?;
    let t0 = Instant::now();
    let d = diagnose::diagnose(&cal, Some(&val), &[], &DiagnosisOptions::default())?;
    println!(
        "\ndiagnosis at scale, {} poses in {} setups, nothing hidden, 20-24 °C: {:.1} s \
         (verdict: {:?}{})",
        cal.poses.len(),
        cal.setups().len(),
        t0.elapsed().as_secs_f64(),
        d.verdict_kind,
        d.missing_effect
            .as_ref()
            .map_or(String::new(), |e| format!(", names {e}"))
    );
    println!("  {}", rpkm_nodes::words::verdict(&d));
    Ok(())
}

/// The smallest campaign against tests/python/scipy_calibration.py, like with like and
/// whole process, side by side (docs/calibration.md, "Against scipy": what each includes).
///
/// - scipy: the script's own `seconds`, its `least_squares` alone (no Python start, no file
///   reading), median of [`SCIPY_RUNS`]; BLAS on one thread (its 3 × 3 solves gain nothing
///   from more, and its idle threads spin against the other processes of a shared machine).
/// - rpkm, the fit alone: the same problem (the script's rows, the 29 unknowns of model 29
///   held by the same tolerance prior, the encoder noise fixed at the spec's 0.2 µm: no noise
///   estimation, no outlier test) calibrated in this process on one thread (core against
///   core: scipy runs on one BLAS thread), then on every core (`--threads 0`,
///   what `rpkm calibrate` does by default: the per-pose work spread over the pieces), the
///   campaign read before the clock starts; medians of [`RPKM_RUNS`].
/// - rpkm, whole processes: `rpkm calibrate --no-noise-estimation` (the same problem) and
///   plain `rpkm calibrate` (noise estimated: a fit per round, one round where the stated
///   noise holds), process start and reading included;
///   medians of [`RPKM_RUNS`].
fn scipy_baseline(path: &Path) -> Result<()> {
    let Some(scipy) = scipy_seconds(path) else {
        return Ok(());
    };
    let fit = fit_alone(path)?;
    let same = median_of(RPKM_RUNS, || {
        calibrate(path, None, &["--no-noise-estimation"]).map(|r| r.seconds)
    })?;
    let default = median_of(RPKM_RUNS, || calibrate(path, None, &[]).map(|r| r.seconds))?;
    println!(
        "\nagainst scipy on {} ({} poses; medians: scipy of {SCIPY_RUNS} runs, rpkm of \
         {RPKM_RUNS}):",
        path.display(),
        fit.poses
    );
    let line = |what: &str, s: f64| println!("  {what:<62} {s:>8.4} s {:>7.0}x", scipy / s);
    println!(
        "  {:<62} {scipy:>8.4} s",
        "scipy least_squares, its fit alone"
    );
    line(
        "rpkm, the same fit alone (in process, 1 thread)",
        fit.one_thread_s,
    );
    let cores = std::thread::available_parallelism().map_or(1, std::num::NonZero::get);
    line(
        &format!("rpkm, the same fit alone (in process, all {cores} cores)"),
        fit.all_cores_s,
    );
    line("rpkm calibrate --no-noise-estimation, whole process", same);
    line(
        "rpkm calibrate (default: noise estimated), whole process",
        default,
    );
    println!(
        "  (reading the CSV in process: {:.4} s, not in the fits' figures)",
        fit.read_s
    );
    Ok(())
}

/// Runs of the scipy script, and of each rpkm figure, whose median is quoted.
const SCIPY_RUNS: usize = 3;
const RPKM_RUNS: usize = 7;

/// The median of `n` runs of `f`.
fn median_of(n: usize, mut f: impl FnMut() -> Result<f64>) -> Result<f64> {
    let mut v = (0..n).map(|_| f()).collect::<Result<Vec<f64>>>()?;
    v.sort_by(f64::total_cmp);
    Ok(v[n / 2])
}

/// The scipy problem in process: seconds reading the CSV, median seconds of the fit on one
/// thread and on every core (`--threads 0`, the default of `rpkm calibrate`), poses.
fn fit_alone(path: &Path) -> Result<FitAlone> {
    use rpkm_core::calib::{self, Options, Prior, Selection};
    let t0 = Instant::now();
    let campaign = rpkm_nodes::input::read_campaign(path)?;
    let read_s = t0.elapsed().as_secs_f64();
    let start = rpkm_core::params::Params::nominal();
    let fit_on = |threads: usize| {
        let opts = Options {
            selection: Selection::Prior(Prior::default()),
            outlier_sigma: None,
            threads,
            ..Options::default()
        };
        median_of(RPKM_RUNS, || {
            let t = Instant::now();
            let cal = calib::calibrate(&calib::Request::new(&campaign, &start, &opts))
                .map(|(cal, _)| cal)?;
            std::hint::black_box(&cal);
            Ok(t.elapsed().as_secs_f64())
        })
    };
    Ok(FitAlone {
        read_s,
        one_thread_s: fit_on(1)?,
        all_cores_s: fit_on(0)?,
        poses: campaign.poses.len(),
    })
}

/// [`fit_alone`]'s figures.
struct FitAlone {
    read_s: f64,
    one_thread_s: f64,
    all_cores_s: f64,
    poses: usize,
}

/// The median `seconds` of tests/python/scipy_calibration.py on `path`, when Python with
/// scipy is there (None, said why, otherwise).
fn scipy_seconds(path: &Path) -> Option<f64> {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/python/scipy_calibration.py");
    if !script.is_file() {
        println!("\nscipy baseline: {} not found", script.display());
        return None;
    }
    // the project's venv (.ci/run installs scipy there), else RPKM_PYTHON, else python3
    let venv = Path::new(env!("CARGO_MANIFEST_DIR")).join(".venv/bin/python");
    let python = std::env::var("RPKM_PYTHON").unwrap_or_else(|_| {
        if venv.is_file() {
            venv.display().to_string()
        } else {
            "python3".into()
        }
    });
    let mut runs = Vec::new();
    for _ in 0..SCIPY_RUNS {
        let out = Command::new(&python)
            .arg(&script)
            .arg(path)
            .envs(["OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"].map(|k| (k, "1")))
            .output();
        let seconds = out
            .as_ref()
            .ok()
            .filter(|o| o.status.success())
            .and_then(|o| {
                String::from_utf8_lossy(&o.stdout).lines().find_map(|l| {
                    l.strip_prefix("seconds ")
                        .and_then(|s| s.trim().parse().ok())
                })
            });
        match (seconds, out) {
            (Some(s), _) => runs.push(s),
            (None, Ok(o)) => {
                let why = String::from_utf8_lossy(&o.stderr);
                println!(
                    "\nscipy baseline not run ({python}): {}",
                    why.lines().last().unwrap_or("no output")
                );
                return None;
            }
            (None, Err(e)) => {
                println!("\nscipy baseline not run ({python}): {e}");
                return None;
            }
        }
    }
    runs.sort_by(f64::total_cmp);
    Some(runs[runs.len() / 2])
}
