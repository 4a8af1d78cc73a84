//! `rpkm history`: a machine's calibrations as recorded (`rpkm calibrate --history`, the
//! calibrator node's `history`), what changed between two of them and whether it is real,
//! the trends and when a parameter leaves its tolerance; as text, CSV and an HTML report.

mod csv;
mod json;

use super::bad_input;
use crate::report::history::HistoryPage;
use rpkm_core::params::{index_of, unit, Unit, NAMES};
use rpkm_history::{CalibrationRecord, Store, Stored};
use rpkm_nodes::history::{analyse, words, Analysis};
use std::path::PathBuf;

/// Show a machine's history: every calibration kept, what changed since the last one, and
/// trends.
///
/// Between two calibrations (default: the last two) each parameter's change is given with
/// the σ of both covariances and flagged beyond 3σ where both campaigns determined it; a
/// change neither could see is unknown, not zero. Each parameter's line over the
/// calibrations since its last break, with its significance, and, where significant, when
/// it leaves its tolerance.
///
/// Examples:
///   rpkm calibrate c.csv --history cell.db --machine cell-1       # record a calibration
///   rpkm history cell.db                                          # the machines recorded
///   rpkm history cell.db --machine cell-1 --report cell-1-history/ --csv cell-1.csv
///   rpkm history postgres://rpkm@plant-db/history --machine cell-1 --from 3 --to 7
#[derive(clap::Args, Debug)]
pub struct HistoryArgs {
    /// The history: an SQLite file, or a PostgreSQL URL (postgres://user@host/db; the
    /// password as libpq finds it: PGPASSWORD, ~/.pgpass or PGPASSFILE, PGSERVICE).
    pub db: String,
    /// The machine; without it, the machines recorded are listed.
    #[arg(long)]
    pub machine: Option<String>,
    /// The earlier calibration to compare (its id in the list); default: the one before the
    /// last.
    #[arg(long)]
    pub from: Option<i64>,
    /// The later calibration to compare (its id); default: the last.
    #[arg(long)]
    pub to: Option<i64>,
    /// Tolerance bands of the trends, NAME=VALUE comma-separated (mm, mrad for angles);
    /// default: each calibration's prior (0.1 mm, 1 mrad). Example: --tolerance l1=0.05
    #[arg(long)]
    pub tolerance: Option<String>,
    /// Write the history as CSV: one row per calibration, each parameter's value and σ
    /// (empty where that calibration did not determine it).
    #[arg(long)]
    pub csv: Option<PathBuf>,
    /// Write what the text says as JSON: the calibrations, the change (every parameter's
    /// change, σ, z, which determined it), each parameter's trend (slope per month, σ, its
    /// run) and tolerance crossing (UTC Unix seconds and σ).
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write the report into this folder (history.html: one self-contained page with the
    /// change, every parameter over time with its trend and tolerance, the held-out RMS).
    #[arg(long)]
    pub report: Option<PathBuf>,
}

/// `--tolerance`: (parameter, band in mm or rad).
fn tolerances(spec: Option<&str>) -> anyhow::Result<Vec<(usize, f64)>> {
    let mut out = Vec::new();
    for item in spec
        .unwrap_or("")
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
    {
        let (name, value) = item.split_once('=').ok_or_else(|| {
            bad_input(format!(
                "--tolerance {item}: expected NAME=VALUE (mm, mrad)"
            ))
        })?;
        let i = index_of(name.trim()).ok_or_else(|| {
            bad_input(format!(
                "--tolerance {item}: unknown parameter `{name}` (expected one of {})",
                NAMES.join(", ")
            ))
        })?;
        let v: f64 = value
            .trim()
            .parse()
            .ok()
            .filter(|v: &f64| v.is_finite() && *v > 0.0)
            .ok_or_else(|| bad_input(format!("--tolerance {item}: expected a positive number")))?;
        let scale = if unit(i) == Unit::Rad { 1e-3 } else { 1.0 };
        out.push((i, v * scale));
    }
    Ok(out)
}

/// The position of calibration `id` in `cals`.
fn position(cals: &[Stored<CalibrationRecord>], id: i64, flag: &str) -> anyhow::Result<usize> {
    cals.iter().position(|c| c.id == id).ok_or_else(|| {
        let ids: Vec<String> = cals.iter().map(|c| c.id.to_string()).collect();
        bad_input(format!(
            "{flag} {id}: no such calibration of this machine (its ids: {})",
            ids.join(", ")
        ))
    })
}

/// The store at `db`, what opening it noticed said (a password file ignored).
fn open(db: &str) -> anyhow::Result<Store> {
    let store = Store::open(db)?;
    for n in store.notes() {
        eprintln!("warning: {n}");
    }
    Ok(store)
}

pub fn run(args: &HistoryArgs) -> anyhow::Result<()> {
    // reading: a mistyped path must not become a new, empty history
    let is_url = args.db.starts_with("postgres://") || args.db.starts_with("postgresql://");
    if !is_url && !std::path::Path::new(&args.db).exists() {
        return Err(bad_input(format!(
            "{}: no such history (an SQLite file that `rpkm calibrate --history` writes, or a \
             postgres:// URL)",
            args.db
        )));
    }
    let mut store = open(&args.db)?;
    let Some(machine) = &args.machine else {
        let machines = store.machines()?;
        if machines.is_empty() {
            println!("{}: no calibration recorded yet", store.location());
        }
        for (name, n) in machines {
            println!("{name}: {n} calibrations");
        }
        return Ok(());
    };
    let cals = store.calibrations(machine)?;
    let events = store.events(machine)?;
    if cals.is_empty() {
        return Err(bad_input(format!(
            "{}: no calibration of machine `{machine}` (rpkm history {} lists the machines)",
            store.location(),
            args.db
        )));
    }
    let last = cals.len() - 1;
    let to = args.to.map(|id| position(&cals, id, "--to")).transpose()?;
    let from = args
        .from
        .map(|id| position(&cals, id, "--from"))
        .transpose()?;
    let pair = match (from, to) {
        (None, None) => None,
        (f, t) => {
            let t = t.unwrap_or(last);
            Some((f.unwrap_or(t.saturating_sub(1)), t))
        }
    };
    let analysis = analyse(&cals, pair, &tolerances(args.tolerance.as_deref())?);
    print_history(machine, &cals, &analysis);
    if !events.is_empty() {
        println!("\nonline events:");
        for e in &events {
            let r = &e.record;
            println!(
                "  {}  {:<12} {}",
                words::date_time(r.at_s),
                r.kind,
                r.message
            );
        }
    }
    if let Some(path) = &args.csv {
        std::fs::write(path, csv::table(&cals))
            .map_err(|e| anyhow::anyhow!("writing {}: {e}", path.display()))?;
        println!("\nwrote {}", path.display());
    }
    if let Some(path) = &args.json {
        super::write_json(path, &json::to_json(machine, &cals, &analysis))?;
        println!("wrote {}", path.display());
    }
    if let Some(dir) = &args.report {
        std::fs::create_dir_all(dir)
            .map_err(|e| anyhow::anyhow!("creating {}: {e}", dir.display()))?;
        let page = dir.join("history.html");
        let html = HistoryPage {
            machine,
            calibrations: &cals,
            events: &events,
            analysis: &analysis,
        }
        .html();
        std::fs::write(&page, html)
            .map_err(|e| anyhow::anyhow!("writing {}: {e}", page.display()))?;
        println!("report: {}", page.display());
    }
    Ok(())
}

/// A calibration whose campaign (its SHA-256) an earlier one of the machine already
/// calibrated: the same measurements recorded again, not a new measurement of the machine,
/// so that a change between the two (χ² 0.0) says nothing of it.
fn same_campaigns(cals: &[Stored<CalibrationRecord>]) -> Vec<String> {
    let mut first: std::collections::HashMap<&str, i64> = std::collections::HashMap::new();
    cals.iter()
        .filter_map(|c| {
            let digest = c.record.campaign.digest.as_str();
            if let Some(&id) = first.get(digest) {
                return Some(format!(
                    "calibration {} is the same campaign as calibration {id} (SHA-256 {}...): \
                     recorded again, not an independent measurement",
                    c.id,
                    &digest[..digest.len().min(12)]
                ));
            }
            first.insert(digest, c.id);
            None
        })
        .collect()
}

/// The calibrations, then what the analysis says.
fn print_history(machine: &str, cals: &[Stored<CalibrationRecord>], a: &Analysis) {
    println!("History of {machine}: {} calibrations", cals.len());
    println!(
        "\n{:>5}  {:<20} {:<24} {:>6} {:>6} {:>11} {:>8} {:>10}",
        "id", "date", "campaign", "poses", "model", "determined", "chi2/dof", "held-out"
    );
    for c in cals {
        let r = &c.record;
        println!(
            "{:>5}  {:<20} {:<24} {:>6} {:>6} {:>11} {:>8.2} {:>10}",
            c.id,
            words::date_time(r.at_s),
            r.campaign.name,
            r.campaign.poses,
            r.model.number(),
            r.determined
                .map_or("-".to_owned(), |(n, of)| format!("{n}/{of}")),
            r.chi2_per_dof,
            r.held_out_rms_um
                .map_or("-".to_owned(), |v| format!("{v:.2} µm"))
        );
    }
    for line in same_campaigns(cals) {
        println!("{line}");
    }
    println!();
    for line in words::summary(a, cals) {
        println!("{line}");
    }
}
