//! The diagnosis's growth with the rows (issue 54): `rpkm diagnose` and `rpkm calibrate` as
//! a user runs them (whole child processes) on random-target self-calibration campaigns of
//! 100 poses per setup, 100 to 1,000 setups, of a machine with nothing hidden whose
//! temperature swings between 20 and 24 °C; each campaign diagnosed with a validation file
//! and without one (the setups left out judge: cross-validation by setup). Wall time, peak
//! resident memory, the diagnosis against the calibration of the same file, and each
//! figure's growth from the campaign before, side by side in one run.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use anyhow::{Context, Result};
use rpkm_core::campaign::Instrument;
use rpkm_core::design::random_setups;
use rpkm_twin::{Twin, TwinConfig};

/// Setups of the campaigns (100 poses each).
const SETUPS: [usize; 4] = [100, 250, 500, 1_000];
/// Poses per setup.
const PER_SETUP: usize = 100;
/// Held-out poses of the validation file.
const VALIDATION: usize = 100;

/// One child process: wall time, peak resident memory (MiB, its own `VmHWM`) and the verdict.
struct Child {
    seconds: f64,
    peak_mib: f64,
    verdict: String,
}

/// The twin of a machine with nothing hidden whose temperature swings between 20 and 24 °C
/// while nothing expands (the diagnosis benches' machine).
pub(super) fn still_machine(seed: u64) -> Result<Twin> {
    Ok(Twin::new(TwinConfig {
        seed,
        effects: vec![(rpkm_twin::EffectKind::Thermal, 2.0)],
        thermal: rpkm_twin::ThermalPhysics {
            rods_per_k: 0.0,
            frame_per_k: 0.0,
            scales_per_k: 0.0,
            reference_c: 22.0,
            ..Default::default()
        },
        ..Default::default()
    })?)
}

/// The campaigns' files: the calibration campaign and its validation file.
fn write_campaign(dir: &Path, seed: u64, setups: usize) -> Result<(PathBuf, PathBuf)> {
    let mut twin = still_machine(seed)?;
    let design = random_setups(Instrument::SelfCal, setups, PER_SETUP, seed);
    let cal = twin.run(&design, "self, random targets")?;
    let val = twin.validation(VALIDATION)?;
    let path = dir.join(format!("growth_{setups}.csv"));
    let val_path = dir.join(format!("growth_{setups}.val.csv"));
    std::fs::write(&path, cal.to_csv()).with_context(|| format!("writing {}", path.display()))?;
    std::fs::write(&val_path, val.to_csv())
        .with_context(|| format!("writing {}", val_path.display()))?;
    Ok((path, val_path))
}

/// `rpkm COMMAND FILE [EXTRA] --json J` as a child process.
fn child(command: &str, path: &Path, extra: &[&std::ffi::OsStr]) -> Result<Child> {
    let json = path.with_extension(format!("{command}{}.json", extra.len()));
    let t0 = Instant::now();
    let status = Command::new(std::env::current_exe()?)
        .arg(command)
        .arg(path)
        .args(extra)
        .arg("--json")
        .arg(&json)
        .stdout(std::process::Stdio::null())
        .spawn()
        .with_context(|| format!("starting rpkm {command}"))?
        .wait()
        .with_context(|| format!("waiting for rpkm {command}"))?;
    let seconds = t0.elapsed().as_secs_f64();
    if !status.success() {
        anyhow::bail!("rpkm {command} {} exited {status}", path.display());
    }
    let text =
        std::fs::read_to_string(&json).with_context(|| format!("reading {}", json.display()))?;
    let value: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("parsing {}", json.display()))?;
    Ok(Child {
        seconds,
        // the child's own high-water mark (NaN where the system reports none)
        peak_mib: value["peak_resident_mib"].as_f64().unwrap_or(f64::NAN),
        verdict: value["verdict_kind"].as_str().unwrap_or("").to_owned(),
    })
}

/// The growth table: every campaign written first, then per campaign the calibration, the
/// diagnosis without and with the validation file, one after the other.
pub fn run(dir: &Path, seed: u64) -> Result<()> {
    let mut files = Vec::new();
    for n in SETUPS {
        files.push((n, write_campaign(dir, seed, n)?));
    }
    println!(
        "\nthe diagnosis's growth with the rows ({PER_SETUP} random-target self-calibration \
         poses per setup, nothing hidden, 20-24 °C; whole processes):\n  {:>6} {:>7} {:>9} \
         {:>8} | {:>9} {:>8} {:>6} {:>7} {:>7} | {:>9} {:>8} {:>6} {:>7}",
        "setups",
        "poses",
        "calib s",
        "MB",
        "no val s",
        "MB",
        "/ cal",
        "growth",
        "per row",
        "val s",
        "MB",
        "/ cal",
        "growth"
    );
    let mut last: Option<(f64, f64)> = None;
    let mut verdicts = Vec::new();
    for (n, (path, val_path)) in &files {
        let cal = child("calibrate", path, &[])?;
        let alone = child("diagnose", path, &[])?;
        let with = child(
            "diagnose",
            path,
            &["--validate".as_ref(), val_path.as_os_str()],
        )?;
        let rows = 2 * n * PER_SETUP;
        let growth = |now: f64, before: Option<f64>| {
            before.map_or("-".to_owned(), |b| format!("{:.2}x", now / b))
        };
        println!(
            "  {n:>6} {:>7} {:>9.2} {:>8.0} | {:>9.2} {:>8.0} {:>5.1}x {:>7} {:>5.1}kB | {:>9.2} \
             {:>8.0} {:>5.1}x {:>7}",
            n * PER_SETUP,
            cal.seconds,
            cal.peak_mib,
            alone.seconds,
            alone.peak_mib,
            alone.seconds / cal.seconds,
            growth(alone.seconds, last.map(|l| l.0)),
            alone.peak_mib * 1024.0 / rows as f64,
            with.seconds,
            with.peak_mib,
            with.seconds / cal.seconds,
            growth(with.seconds, last.map(|l| l.1)),
        );
        verdicts.push(format!("{n}: {} / {}", alone.verdict, with.verdict));
        last = Some((alone.seconds, with.seconds));
    }
    println!(
        "  (growth: the time against the campaign above; per row: peak memory per calibration \
         row)\n  verdicts without / with the validation file: {}",
        verdicts.join(", ")
    );
    Ok(())
}
