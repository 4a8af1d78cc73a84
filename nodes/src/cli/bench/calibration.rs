//! `rpkm bench calibration`: how calibration and diagnosis scale with the campaign, as a user
//! runs them (whole `rpkm calibrate` processes), side by side in one run.
//!
//! - Calibration of twin self-calibration campaigns of about 10³, 10⁴ and 10⁵ poses (the
//!   thesis's self-calibration design repeated; each run a child `rpkm calibrate` process):
//!   wall time, LM iterations, peak resident memory (the child's `ru_maxrss`), time per pose.
//! - The same calibrations on one thread (`--threads 1`): the parallel speed-up.
//! - Diagnosis of a campaign of about 1,000 poses with every library effect tried, in
//!   process: screened (the default) and with every candidate fitted to convergence.
//! - When Python with scipy is there: the plain `scipy.optimize.least_squares` script of
//!   tests/python on the smallest campaign, and the ratio of its time to ours.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use anyhow::{Context, Result};
use rpkm_core::campaign::{Campaign, Instrument};
use rpkm_core::diagnose::{self, Options};
use rpkm_core::twin::{Twin, TwinConfig};

use crate::cli::bad_input;

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
    println!(
        "{:>9} {:>9} {:>7} {:>10} {:>9} {:>10} {:>9}",
        "poses", "rows", "iters", "time (s)", "µs/pose", "1 thread", "peak MB"
    );
    let mut smallest: Option<(PathBuf, f64)> = None;
    for &k in &a.repeats {
        let (path, poses) = write_self_campaign(&dir, a.seed, k)?;
        let all = calibrate(&path, None)?;
        let one = calibrate(&path, Some(1))?;
        println!(
            "{poses:>9} {:>9} {:>7} {:>10.3} {:>9.1} {:>9.2}x {:>9.1}",
            2 * poses,
            all.iterations,
            all.seconds,
            all.seconds / poses as f64 * 1e6,
            one.seconds / all.seconds,
            all.max_rss_mb
        );
        if Some(&k) == a.repeats.iter().min() && smallest.is_none() {
            smallest = Some((path, all.seconds));
        }
    }
    diagnosis(a.seed)?;
    if let Some((path, ours)) = smallest {
        scipy_baseline(&path, ours);
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

/// `rpkm calibrate FILE` as a child process: wall time, iterations (from its JSON), peak
/// memory (from wait4's resource usage of that child alone).
fn calibrate(path: &Path, threads: Option<usize>) -> Result<Run> {
    let json = path.with_extension(format!("t{}.json", threads.unwrap_or(0)));
    let mut cmd = Command::new(std::env::current_exe()?);
    cmd.arg("calibrate").arg(path).arg("--json").arg(&json);
    if let Some(t) = threads {
        cmd.arg("--threads").arg(t.to_string());
    }
    cmd.stdout(std::process::Stdio::null());
    let t0 = Instant::now();
    let child = cmd.spawn().context("starting rpkm calibrate")?;
    let (status, max_rss_kb) = wait_with_rusage(child.id())?;
    let seconds = t0.elapsed().as_secs_f64();
    if status != 0 {
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
        max_rss_mb: max_rss_kb as f64 / 1024.0,
    })
}

/// Waits for child `pid`; its exit code and its peak resident memory (kB).
fn wait_with_rusage(pid: u32) -> Result<(i32, i64)> {
    let mut status = 0;
    // SAFETY: rusage is plain data; wait4 fills it for the child we spawned and never waited
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    let pid = libc::pid_t::try_from(pid).context("child pid out of range")?;
    // SAFETY: status and usage point to live locals of the right types
    let r = unsafe { libc::wait4(pid, &raw mut status, 0, &raw mut usage) };
    if r != pid {
        anyhow::bail!("wait4: {}", std::io::Error::last_os_error());
    }
    let code = if libc::WIFEXITED(status) {
        libc::WEXITSTATUS(status)
    } else {
        128 + libc::WTERMSIG(status)
    };
    Ok((code, usage.ru_maxrss))
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
        let opts = Options {
            screen,
            ..Options::default()
        };
        let t0 = Instant::now();
        let d = diagnose::diagnose(&cal, Some(&val), &[], &opts)?;
        ms[k] = t0.elapsed().as_secs_f64() * 1e3;
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

/// tests/python/scipy_calibration.py on `path`, when Python with scipy is there: the time of
/// its fit against our whole process (`ours`, s; the script's figure leaves out reading the
/// file, so the ratio is on the modest side).
fn scipy_baseline(path: &Path, ours: f64) {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/python/scipy_calibration.py");
    if !script.is_file() {
        println!("\nscipy baseline: {} not found", script.display());
        return;
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
    let out = Command::new(&python).arg(&script).arg(path).output();
    let seconds = out
        .as_ref()
        .ok()
        .filter(|o| o.status.success())
        .and_then(|o| {
            String::from_utf8_lossy(&o.stdout).lines().find_map(|l| {
                l.strip_prefix("seconds ")
                    .and_then(|s| s.trim().parse::<f64>().ok())
            })
        });
    match (seconds, out) {
        (Some(s), _) => println!(
            "\nscipy least_squares on {}: {s:.2} s, rpkm {ours:.3} s: {:.0}x",
            path.display(),
            s / ours
        ),
        (None, Ok(o)) => println!(
            "\nscipy baseline not run ({python}): {}",
            String::from_utf8_lossy(&o.stderr)
                .lines()
                .last()
                .unwrap_or("no output")
        ),
        (None, Err(e)) => println!("\nscipy baseline not run ({python}): {e}"),
    }
}
