//! Campaign CSV, rosbag2 bags and node parameter files, mutated.

use super::harness::{
    copy_any, family, judge, keep, mutate_text, rpkm, run, scratch, simulated_lt_campaign,
    ODD_VALUES,
};
use crate::fuzz_support::Rng;
use std::path::Path;
use std::time::Duration;

/// Cases per family: a few thousand in all, well within a minute of the debug test build on
/// two cores (docs/nodes.md has the measured time).
const CSV_CASES: usize = 600;
const BAG_CASES: usize = 750;
const PARAM_CASES: usize = 600;
#[test]
fn fuzzed_campaigns_end_in_0_or_2_naming_their_file() {
    let dir = scratch("csv");
    let base = dir.join("base.csv");
    simulated_lt_campaign(&base, "3");
    let text = std::fs::read_to_string(&base).expect("base campaign");
    let failures = family(CSV_CASES, |case| {
        let mut rng = Rng(0x0c5f_0000 + case as u64 * 7919);
        let file = dir.join(format!("case{case}.csv"));
        std::fs::write(&file, mutate_text(&text, &mut rng)).expect("write case");
        let mut cmd = rpkm();
        cmd.arg("calibrate").arg(&file);
        let out = run(cmd, Duration::from_secs(60));
        let places = [format!("case{case}.csv")];
        let broken = judge(&out, &places).map(|why| keep("csv", case, &file, &why, &out));
        let _ = std::fs::remove_file(&file);
        (broken, out.code == Some(2))
    });
    let _ = std::fs::remove_dir_all(&dir);
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
}

#[test]
fn fuzzed_bags_end_in_0_or_2_naming_their_file() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("bags/calibration");
    let dir = scratch("bags");
    let failures = family(BAG_CASES, |case| {
        let mut rng = Rng(0xba95_0000 + case as u64 * 104_729);
        let bag = dir.join(format!("case{case}"));
        copy_any(&src, &bag).expect("copy the reference bag");
        if rng.below(5) == 0 {
            let meta = bag.join("metadata.yaml");
            let text = std::fs::read_to_string(&meta).expect("metadata");
            std::fs::write(&meta, mutate_text(&text, &mut rng)).expect("write metadata");
        } else {
            let mcap = bag.join("calibration_0.mcap");
            let mut bytes = std::fs::read(&mcap).expect("mcap");
            match rng.below(3) {
                0 => bytes.truncate(rng.below(bytes.len())),
                _ => {
                    for _ in 0..=rng.below(4) {
                        let at = rng.below(bytes.len());
                        bytes[at] ^= 1 << rng.below(8);
                    }
                }
            }
            std::fs::write(&mcap, bytes).expect("write mcap");
        }
        let mut cmd = rpkm();
        cmd.args(["bag", "info"]).arg(&bag);
        let out = run(cmd, Duration::from_secs(30));
        let places = [format!("case{case}")];
        let broken = judge(&out, &places).map(|why| keep("bag", case, &bag, &why, &out));
        let _ = std::fs::remove_dir_all(&bag);
        (broken, out.code == Some(2))
    });
    let _ = std::fs::remove_dir_all(&dir);
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
}

#[test]
fn fuzzed_parameter_files_end_in_0_or_2_naming_their_place() {
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("launch_scripts/params.yaml");
    let text = std::fs::read_to_string(shipped).expect("params.yaml");
    let dir = scratch("params");
    let failures = family(PARAM_CASES, |case| {
        let mut rng = Rng(0x9a4a_0000 + case as u64 * 15_485_863);
        let file = dir.join(format!("case{case}.yaml"));
        // YAML values sit after ": ", so the field mutation is on ':' here
        let mutated = text
            .lines()
            .map(|l| {
                if rng.below(12) == 0 {
                    match l.split_once(": ") {
                        Some((key, _)) => format!("{key}: {}", rng.pick(&ODD_VALUES)),
                        None => l.to_owned(),
                    }
                } else {
                    l.to_owned()
                }
            })
            .collect::<Vec<_>>()
            .join("\n");
        std::fs::write(&file, mutate_text(&mutated, &mut rng)).expect("write case");
        let missing = dir.join(format!("missing{case}.csv"));
        let mut cmd = rpkm();
        // ingest waits start_delay_s (default 1 s) before it opens its source: 0 from the
        // command line, so that a case costs its parsing, not the wait (this one key's
        // mutations are left to tests/it/cli_bad_config.rs)
        cmd.args(["node", "ingest", "--param", "start_delay_s=0", "--params"])
            .arg(&file)
            .arg("--source")
            .arg(&missing)
            .arg("--ipc-prefix")
            .arg(format!("fuzz{}_{case}_", std::process::id()));
        let out = run(cmd, Duration::from_secs(30));
        let places = [format!("case{case}.yaml"), format!("missing{case}.csv")];
        let broken = judge(&out, &places).map(|why| keep("params", case, &file, &why, &out));
        let _ = std::fs::remove_file(&file);
        (broken, out.code == Some(2))
    });
    let _ = std::fs::remove_dir_all(&dir);
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
}
