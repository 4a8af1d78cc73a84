//! Fuzzed input through the real command line, judged against the contract, not the code:
//! whatever a user hands rpkm, it ends with 0 or 2, never a panic (101), an abort or another
//! signal, never a hang; and a rejection (2) names its place: the file it read. Four
//! families, fixed seeds, 8,000 cases:
//! - campaign CSV through `rpkm calibrate` (a small tracker campaign, mutated);
//! - rosbag2 bags through `rpkm bag info` (the reference calibration bag, bytes flipped,
//!   cut, metadata.yaml edited);
//! - node parameter YAML through `rpkm node ingest --params` (the shipped file, mutated; the
//!   source is a missing file, so a node whose parameters pass exits 2 naming that file);
//! - launch YAML through `rpkm launch --check` (the shipped launch file, mutated: values, key
//!   typos, indentation, lines, bytes); a rejection names the launch file and a line.
//!
//! A failing case is left in `target/fuzz-failures/` with the command that failed.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::fuzz_support;
use fuzz_support::Rng;

/// Cases per family: a few thousand in all, well within a minute of the debug test build on
/// two cores (docs/nodes.md has the measured time).
const CSV_CASES: usize = 1600;
const BAG_CASES: usize = 2000;
const PARAM_CASES: usize = 1600;
const LAUNCH_CASES: usize = 2800;

/// Values a field may be mutated to: the ones a careless export, a unit mix-up or a broken
/// tool produces.
const ODD_VALUES: [&str; 18] = [
    "nan",
    "inf",
    "-inf",
    "1e309",
    "-1e300",
    "1e15",
    "0x10",
    "",
    " ",
    "true",
    "1,5",
    "-0",
    "1e-320",
    "12abc",
    "\u{feff}3",
    "999999999999999999999",
    "١٢",
    "\"7\"",
];

/// One mutation of a text file: a field, a line, the bytes.
fn mutate_text(text: &str, rng: &mut Rng) -> Vec<u8> {
    let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
    let n = lines.len();
    match rng.below(8) {
        0..=2 => {
            let i = rng.below(n);
            let mut fields: Vec<String> = lines[i].split(',').map(str::to_owned).collect();
            let k = rng.below(fields.len());
            rng.pick(&ODD_VALUES).clone_into(&mut fields[k]);
            lines[i] = fields.join(",");
        }
        3 => {
            let i = rng.below(n);
            lines.remove(i);
        }
        4 => {
            let (i, j) = (rng.below(n), rng.below(n));
            lines.swap(i, j);
        }
        5 => {
            let i = rng.below(n);
            let extra = format!("{},{}", lines[i], rng.pick(&ODD_VALUES));
            lines[i] = extra;
        }
        _ => {}
    }
    let mut bytes = lines.join("\n").into_bytes();
    match rng.below(6) {
        0 => {
            let at = rng.below(bytes.len());
            bytes[at] = (rng.next() & 0xff) as u8;
        }
        1 => bytes.truncate(rng.below(bytes.len())),
        2 => {
            let at = rng.below(bytes.len());
            bytes.splice(at..at, [0xff, 0xfe, 0xc3]);
        }
        _ => {}
    }
    bytes
}

/// Values a launch entry's field may be mutated to, besides [`ODD_VALUES`]: what a launch
/// file's author gets wrong.
const LAUNCH_VALUES: [&str; 16] = [
    "1e308",
    "-0.5",
    "$(var nope)",
    "$(env RPKM_FUZZ_UNSET_VARIABLE)",
    "$(var",
    "$(dirname)/x.yaml",
    "[]",
    "{}",
    "{from: missing.yaml}",
    "rpkm launch x.yaml",
    "ros2 bag record -a",
    "talker",
    "--backend foo",
    "--no-such-option",
    "--param model=25",
    "maybe",
];

/// One mutation of a launch file: one to three of a value, a key, an indentation, a
/// duplicated line; in a third of the cases then [`mutate_text`] (lines, bytes).
fn mutate_launch(text: &str, rng: &mut Rng) -> Vec<u8> {
    let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
    for _ in 0..=rng.below(3) {
        let i = rng.below(lines.len());
        let line = lines[i].clone();
        lines[i] = match rng.below(6) {
            0..=2 => mutate_launch_value(&line, rng),
            3 => mutate_launch_key(&line, rng),
            // the indentation
            4 => match rng.below(2) {
                0 => format!("  {line}"),
                _ => line.strip_prefix("  ").unwrap_or(&line).to_owned(),
            },
            // a duplicated line (a duplicate key)
            _ => {
                lines.insert(i, line.clone());
                line
            }
        };
    }
    let text = lines.join("\n");
    match rng.below(3) {
        0 => mutate_text(&text, rng),
        _ => text.into_bytes(),
    }
}

/// A launch line with its value (after the last `: `, block or flow style) replaced.
fn mutate_launch_value(line: &str, rng: &mut Rng) -> String {
    let Some((head, tail)) = line.rsplit_once(": ") else {
        return line.to_owned();
    };
    let value = match rng.below(2) {
        0 => rng.pick(&ODD_VALUES),
        _ => rng.pick(&LAUNCH_VALUES),
    };
    // keep a flow map's closing braces, so that the value, not the syntax, is what changed
    let closing: String = tail.chars().rev().take_while(|c| *c == '}').collect();
    format!("{head}: {value}{closing}")
}

/// A launch line with its key misspelt: `If:`, `respwan:`, `exec_:`.
fn mutate_launch_key(line: &str, rng: &mut Rng) -> String {
    let Some((key, rest)) = line.split_once(':') else {
        return line.to_owned();
    };
    let name = key.trim_start().trim_start_matches("- ");
    if name.is_empty() {
        return line.to_owned();
    }
    let lead = &key[..key.len() - name.len()];
    let mut chars: Vec<char> = name.chars().collect();
    match rng.below(3) {
        0 => chars[0] = chars[0].to_ascii_uppercase(),
        1 if chars.len() > 3 => chars.swap(1, 2),
        _ => chars.push('_'),
    }
    let name: String = chars.into_iter().collect();
    format!("{lead}{name}:{rest}")
}

/// Whether `stderr` names `file` with a line: `file:N` with N >= 1.
fn names_a_line(stderr: &str, file: &str) -> bool {
    stderr.match_indices(&format!("{file}:")).any(|(at, m)| {
        let digits: String = stderr[at + m.len()..]
            .chars()
            .take_while(char::is_ascii_digit)
            .collect();
        digits.parse::<u64>().is_ok_and(|n| n >= 1)
    })
}

/// What one run did.
struct Outcome {
    code: Option<i32>,
    hung: bool,
    stderr: String,
}

/// Runs `cmd` with a time limit, killing it when it hangs.
fn run(mut cmd: Command, limit: Duration) -> Outcome {
    let mut child = cmd
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn rpkm");
    let mut stderr_pipe = child.stderr.take().expect("stderr");
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = std::io::Read::read_to_string(&mut stderr_pipe, &mut s);
        s
    });
    let start = Instant::now();
    let (code, hung) = loop {
        if let Some(status) = child.try_wait().expect("wait") {
            break (status.code(), false);
        }
        if start.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            break (None, true);
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    Outcome {
        code,
        hung,
        stderr: reader.join().unwrap_or_default(),
    }
}

/// A case that broke the contract, or None: exit 0 or 2 in time, and a 2 names one of
/// `places`.
fn judge(out: &Outcome, places: &[String]) -> Option<String> {
    if out.hung {
        return Some("hung".to_owned());
    }
    match out.code {
        Some(0) => None,
        Some(2) if places.iter().any(|p| out.stderr.contains(p.as_str())) => None,
        Some(2) => Some(format!("exit 2 without naming {places:?}")),
        Some(c) => Some(format!("exit {c}")),
        None => Some("killed by a signal".to_owned()),
    }
}

fn rpkm() -> Command {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_rpkm"));
    cmd.env("RUST_BACKTRACE", "0");
    cmd
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("rpkm-fuzz-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch folder");
    dir
}

/// Keeps a failing case for a human: its input and what went wrong.
fn keep(family: &str, case: usize, input: &Path, why: &str, out: &Outcome) -> String {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("fuzz-failures");
    let _ = std::fs::create_dir_all(&dir);
    let to = dir.join(format!("{family}-{case}"));
    let _ = copy_any(input, &to);
    format!(
        "{family} case {case} ({}): {why}\n{}",
        to.display(),
        out.stderr.lines().take(6).collect::<Vec<_>>().join("\n")
    )
}

fn copy_any(from: &Path, to: &Path) -> std::io::Result<()> {
    if from.is_dir() {
        std::fs::create_dir_all(to)?;
        for entry in std::fs::read_dir(from)? {
            let entry = entry?;
            std::fs::copy(entry.path(), to.join(entry.file_name()))?;
        }
        Ok(())
    } else {
        std::fs::copy(from, to).map(|_| ())
    }
}

/// Runs `cases` cases of one family on two threads (each returns its broken contract, if
/// any, and whether the input was rejected); returns the broken ones, after checking that
/// the mutations bite (a fuzzer whose inputs all pass tests nothing).
fn family(cases: usize, one: impl Fn(usize) -> (Option<String>, bool) + Sync) -> Vec<String> {
    let next = std::sync::atomic::AtomicUsize::new(0);
    let rejected = std::sync::atomic::AtomicUsize::new(0);
    let failures = std::sync::Mutex::new(Vec::new());
    std::thread::scope(|s| {
        for _ in 0..2 {
            s.spawn(|| loop {
                let case = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                if case >= cases {
                    break;
                }
                let (failure, was_rejected) = one(case);
                if was_rejected {
                    rejected.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                }
                if let Some(f) = failure {
                    failures
                        .lock()
                        .unwrap_or_else(std::sync::PoisonError::into_inner)
                        .push(f);
                }
            });
        }
    });
    let rejected = rejected.into_inner();
    assert!(
        rejected * 5 >= cases,
        "only {rejected} of {cases} mutated inputs were rejected"
    );
    failures
        .into_inner()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

#[test]
fn fuzzed_campaigns_end_in_0_or_2_naming_their_file() {
    let dir = scratch("csv");
    let base = dir.join("base.csv");
    let made = rpkm()
        .args(["simulate", "--campaign", "lt", "--seed", "3", "--out"])
        .arg(&base)
        .output()
        .expect("rpkm simulate");
    assert!(
        made.status.success(),
        "{}",
        String::from_utf8_lossy(&made.stderr)
    );
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

#[test]
fn fuzzed_launch_files_end_in_0_or_2_naming_file_and_line() {
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("launch_scripts");
    let text = std::fs::read_to_string(shipped.join("rpkm.launch.yaml")).expect("launch file");
    let dir = scratch("launch");
    // the shipped file's `from: params.yaml` resolves next to each case
    std::fs::copy(shipped.join("params.yaml"), dir.join("params.yaml")).expect("params");
    // the unmutated file passes, so that a rejection is the mutation's doing
    let base = dir.join("base.yaml");
    std::fs::write(&base, &text).expect("write base");
    let out = rpkm()
        .arg("launch")
        .arg(&base)
        .arg("--check")
        .output()
        .expect("rpkm launch --check");
    let listed = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for node in ["ingest", "tcp_estimator", "calibrator", "preload_monitor"] {
        assert!(
            listed.contains(&format!(": {node}: rpkm node {node} ")),
            "{listed}"
        );
    }
    let failures = family(LAUNCH_CASES, |case| {
        let mut rng = Rng(0x1a0c_0000 + case as u64 * 2_750_159);
        let file = dir.join(format!("case{case}.yaml"));
        std::fs::write(&file, mutate_launch(&text, &mut rng)).expect("write case");
        let mut cmd = rpkm();
        cmd.arg("launch").arg(&file).arg("--check");
        let out = run(cmd, Duration::from_secs(30));
        let name = format!("case{case}.yaml");
        let mut broken = judge(&out, std::slice::from_ref(&name));
        if broken.is_none() && out.code == Some(2) && !names_a_line(&out.stderr, &name) {
            broken = Some(format!("exit 2 without naming a line of {name}"));
        }
        let broken = broken.map(|why| keep("launch", case, &file, &why, &out));
        let _ = std::fs::remove_file(&file);
        (broken, out.code == Some(2))
    });
    let _ = std::fs::remove_dir_all(&dir);
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
}

#[test]
fn the_line_detector_wants_a_line_number() {
    assert!(names_a_line("error: /t/case3.yaml:12: node", "case3.yaml"));
    assert!(!names_a_line("error: /t/case3.yaml: node", "case3.yaml"));
    assert!(!names_a_line(
        "error: /t/case3.yaml:0:0: not YAML",
        "case3.yaml"
    ));
    assert!(!names_a_line("error: /t/case31.yaml:4: node", "case3.yaml"));
}

/// `rpkm launch --check` loads every node's parameters as the node would: a key the node
/// does not declare (a typo) is refused before anything starts, naming the launch file's line
/// of the node and the parameter.
#[test]
fn launch_check_refuses_a_node_parameter_naming_the_entry() {
    let dir = scratch("launch-check");
    std::fs::write(
        dir.join("p.yaml"),
        "calibrator:\n  ros__parameters:\n    state_bufer: 4096\n",
    )
    .expect("write params");
    let file = dir.join("x.launch.yaml");
    std::fs::write(
        &file,
        "launch:\n  - node: {pkg: rpkm, exec: ingest}\n  \
         - node: {pkg: rpkm, exec: calibrator, param: [{from: p.yaml}]}\n",
    )
    .expect("write launch file");
    let out = rpkm()
        .arg("launch")
        .arg(&file)
        .arg("--check")
        .output()
        .expect("rpkm launch --check");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains(&format!("{}:3: node calibrator: ", file.display()))
            && stderr.contains("state_bufer: unknown parameter"),
        "{stderr}"
    );
    assert!(!stderr.contains("[launch] started"), "{stderr}");
}
