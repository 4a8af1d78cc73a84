//! Fuzzed input through the real command line, judged against the contract, not the code:
//! whatever a user hands rpkm, it ends with 0 or 2, never a panic (101), an abort or another
//! signal, never a hang; and a rejection (2) names its place: the file it read. Eight
//! families, fixed seeds, 7,900 cases:
//! - campaign CSV through `rpkm calibrate` (a small tracker campaign, mutated);
//! - rosbag2 bags through `rpkm bag info` (the reference calibration bag, bytes flipped,
//!   cut, metadata.yaml edited);
//! - node parameter YAML through `rpkm node ingest --params` (the shipped file, mutated; the
//!   source is a missing file, so a node whose parameters pass exits 2 naming that file);
//! - launch YAML through `rpkm launch --check` (the shipped launch file, mutated: values, key
//!   typos, indentation, lines, bytes); a rejection names the launch file and a line;
//! - issue 29's: launches that run (a node's name, arguments, parameters mutated: never
//!   restarted in a loop), parameter maps where values belong (refused with their key),
//!   bags with corrupt payloads through `rpkm replay` and `rpkm bag campaign` (replay's 2
//!   names bag, topic and message), validation campaigns (a reading 5 m off refused with
//!   its line).
//!
//! A failing case is left in `target/fuzz-failures/` with the command that failed.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::fuzz_support;
use fuzz_support::Rng;

/// Cases per family: a few thousand in all, well within a minute of the debug test build on
/// two cores (docs/nodes.md has the measured time).
const CSV_CASES: usize = 1200;
const BAG_CASES: usize = 1500;
const PARAM_CASES: usize = 1200;
const LAUNCH_CASES: usize = 2000;
/// Cases of the families issue 29 added: launches that run, parameter maps, corrupt bag
/// payloads, validation campaigns (2,000 in all).
const LAUNCH_RUN_CASES: usize = 300;
const PARAM_MAP_CASES: usize = 800;
const BAG_PAYLOAD_CASES: usize = 400;
const VALIDATION_CASES: usize = 500;

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
        .stdin(Stdio::null())
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

/// Node names a launch file's author (or a generator) writes: too long, a digit first, a
/// path, a dash, a space, non-ASCII; and good ones.
fn odd_name(rng: &mut Rng) -> String {
    match rng.below(10) {
        0 => "a".repeat(5000),
        1 => "n".repeat(256),
        2 => "n".repeat(255),
        3 => "1ingest".to_owned(),
        4 => "in-gest".to_owned(),
        5 => "in gest".to_owned(),
        6 => "/rpkm/ingest".to_owned(),
        7 => "ingést".to_owned(),
        8 => "\"\"".to_owned(),
        _ => "ingest_2".to_owned(),
    }
}

/// One mutation of the one-node launch file of [`fuzzed_launches_end_without_a_restart`]:
/// its name, an extra argument, an inline parameter, the respawn delay.
fn mutate_one_node_launch(text: &str, rng: &mut Rng) -> String {
    let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
    for _ in 0..=rng.below(2) {
        let i = rng.below(lines.len());
        let Some((head, _)) = lines[i].split_once(": ") else {
            continue;
        };
        let value = match head.trim() {
            "name" => odd_name(rng),
            "args" => format!(
                "--source $(var source) {}",
                rng.pick(&[
                    "--name=x-y",
                    "--domain 99999",
                    "--backend foo",
                    "--ipc-prefix /"
                ])
            ),
            "value" => rng.pick(&ODD_VALUES).to_owned(),
            _ => rng.pick(&LAUNCH_VALUES).to_owned(),
        };
        lines[i] = format!("{head}: {value}");
    }
    lines.join("\n")
}

/// `rpkm launch` for real (not `--check`) of one ingest node whose source is a file that does
/// not exist, with its name, arguments and an inline parameter mutated: whatever the
/// mutation, the node ends with exit 2 (its configuration or its missing source), so the
/// launch ends with 2 and never restarts it (the fuzzer of issue 29 found a 5,000-character
/// name restarted for ever).
#[test]
fn fuzzed_launches_end_without_a_restart() {
    let dir = scratch("launch-run");
    std::fs::write(
        dir.join("p.yaml"),
        "ingest:\n  ros__parameters:\n    start_delay_s: 0.0\n    exit_at_end: true\n",
    )
    .expect("params");
    let text = "launch:\n  - arg: {name: source, default: missing.csv}\n  - node:\n      \
                pkg: rpkm\n      exec: ingest\n      name: ingest\n      param:\n        \
                - from: p.yaml\n        - name: rate_hz\n          value: 1000\n      \
                args: --source $(var source)\n      respawn: true\n      respawn_delay: 0.05\n";
    let failures = family(LAUNCH_RUN_CASES, |case| {
        let mut rng = Rng(0x1a0d_0000 + case as u64 * 3_010_349);
        let file = dir.join(format!("case{case}.yaml"));
        std::fs::write(&file, mutate_one_node_launch(text, &mut rng)).expect("write case");
        let mut cmd = rpkm();
        cmd.arg("launch").arg(&file);
        cmd.env(
            "RPKM_IPC_PREFIX",
            format!("fz{}_{case}_", std::process::id()),
        );
        let out = run(cmd, Duration::from_secs(30));
        let broken = if out.stderr.contains("restarting") {
            Some("restarted a node".to_owned())
        } else if out.code == Some(2) {
            None
        } else {
            judge(&out, &[]).or_else(|| Some("exit 0 with a missing source".to_owned()))
        };
        let broken = broken.map(|why| keep("launch-run", case, &file, &why, &out));
        let _ = std::fs::remove_file(&file);
        (broken, out.code == Some(2))
    });
    let _ = std::fs::remove_dir_all(&dir);
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
}

/// Maps where a parameter's value belongs, block or flow style.
const MAP_VALUES: [&str; 4] = ["{a: 1}", "{}", "{a: {b: 2}}", "\n      a: 1"];

/// The shipped parameter file with one parameter's value replaced by a map (`{a: 1}`, where
/// the fuzzer of issue 29 found the estimator and the calibrator silently taking it) through
/// `rpkm launch --check` of the shipped launch file: exit 2 naming the file and the key.
#[test]
fn fuzzed_parameter_maps_are_refused_with_their_key() {
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("launch_scripts");
    let params = std::fs::read_to_string(shipped.join("params.yaml")).expect("params.yaml");
    let launch = std::fs::read_to_string(shipped.join("rpkm.launch.yaml")).expect("launch");
    // every line that sets a parameter: `    key: value` (not a group, whose value is a map:
    // `temperatures: {}`)
    let settable: Vec<(usize, String)> = params
        .lines()
        .enumerate()
        .filter(|(_, l)| l.starts_with("    ") && !l.trim_start().starts_with('#'))
        .filter(|(_, l)| {
            !l.split_once(':')
                .is_some_and(|(_, v)| v.trim_start().starts_with('{'))
        })
        .filter_map(|(i, l)| Some((i, l.split_once(':')?.0.trim().to_owned())))
        .collect();
    assert!(settable.len() > 30, "{settable:?}");
    let failures = family(PARAM_MAP_CASES, |case| {
        let mut rng = Rng(0x9a4b_0000 + case as u64 * 1_299_709);
        let dir = scratch(&format!("pmap{case}"));
        let (at, key) = &settable[rng.below(settable.len())];
        let mut lines: Vec<String> = params.lines().map(str::to_owned).collect();
        lines[*at] = format!("    {key}: {}", rng.pick(&MAP_VALUES));
        std::fs::write(dir.join("params.yaml"), lines.join("\n")).expect("write params");
        let file = dir.join("rpkm.launch.yaml");
        std::fs::write(&file, &launch).expect("write launch");
        let mut cmd = rpkm();
        cmd.arg("launch").arg(&file).arg("--check");
        let out = run(cmd, Duration::from_secs(30));
        let names_it =
            out.stderr.contains("params.yaml") && out.stderr.contains(&format!("/{key}:"));
        let broken = match out.code {
            Some(2) if names_it => None,
            Some(2) => Some(format!("exit 2 without naming params.yaml and {key}")),
            _ => judge(&out, &[]).or_else(|| Some(format!("{key}: a map accepted"))),
        };
        let broken = broken.map(|why| keep("param-map", case, &dir, &why, &out));
        let _ = std::fs::remove_dir_all(&dir);
        (broken, out.code == Some(2))
    });
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
}

/// One corruption of a CDR payload: bytes flipped, cut, grown, or a length field (a string's
/// or a sequence's, after the 4-byte header) set huge.
fn corrupt_payload(cdr: &mut Vec<u8>, rng: &mut Rng) {
    match rng.below(4) {
        0 => {
            for _ in 0..=rng.below(4) {
                let at = rng.below(cdr.len());
                cdr[at] ^= 1 << rng.below(8);
            }
        }
        1 => cdr.truncate(rng.below(cdr.len())),
        2 => cdr.extend((0..=rng.below(9)).map(|_| (rng.next() & 0xff) as u8)),
        _ => {
            // an aligned u32 after the header: a length in most of rpkm's messages
            let words = cdr.len().saturating_sub(4) / 4;
            if words > 0 {
                let at = 4 + 4 * rng.below(words);
                cdr[at..at + 4].copy_from_slice(&[0xff, 0xff, 0xff, 0x7f]);
            }
        }
    }
}

/// The reference calibration bag rewritten with one to three payloads corrupted (the bag's
/// records and CRCs intact): the corruption of issue 29's fuzzer, which `rpkm replay` took
/// for its own failure (exit 1). Returns whether a payload was changed.
fn write_corrupt_bag(to: &Path, rng: &mut Rng) -> bool {
    use rpkm_transport::bag::{BagReader, BagWriter, BagWriterOptions, RawTopic};
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("bags/calibration");
    let reader = BagReader::open(&src).expect("reference bag");
    let mut writer = BagWriter::create(to, BagWriterOptions::default()).expect("bag writer");
    let handles: Vec<_> = reader
        .topics()
        .iter()
        .map(|t| {
            writer
                .add_topic_raw(RawTopic {
                    name: t.name.clone(),
                    type_name: t.type_name.clone(),
                    definition: t.definition.clone(),
                    offered_qos_yaml: t.offered_qos_profiles.clone(),
                    type_hash: t.type_hash.clone(),
                })
                .expect("topic")
        })
        .collect();
    let n = reader.message_count();
    let bad: Vec<usize> = (0..=rng.below(3)).map(|_| rng.below(n)).collect();
    let mut changed = false;
    for (i, m) in reader.messages().enumerate() {
        let m = m.expect("reference message");
        let mut data = m.data.clone();
        if bad.contains(&i) {
            corrupt_payload(&mut data, rng);
            changed |= data != m.data[..];
        }
        writer
            .write_raw(handles[m.topic_index], m.log_time, m.publish_time, &data)
            .expect("write message");
    }
    writer.finish().expect("finish bag");
    changed
}

/// Bags with corrupt payloads (records and CRCs intact) through `rpkm replay` and `rpkm bag
/// campaign`: exit 0 or 2 naming the bag, and replay's 2 names the topic and the message.
#[test]
fn fuzzed_bag_payloads_end_in_0_or_2_naming_bag_topic_and_message() {
    let dir = scratch("payloads");
    let failures = family(BAG_PAYLOAD_CASES, |case| {
        let mut rng = Rng(0xba96_0000 + case as u64 * 49_979_687);
        let bag = dir.join(format!("case{case}"));
        write_corrupt_bag(&bag, &mut rng);
        let mut cmd = rpkm();
        let replay = rng.below(2) == 0;
        if replay {
            cmd.args([
                "replay",
                "--rate",
                "max",
                "--backend",
                "ipc",
                "--ipc-prefix",
            ])
            .arg(format!("fzb{}_{case}_", std::process::id()));
        } else {
            cmd.args(["bag", "campaign", "--out"])
                .arg(dir.join(format!("c{case}.csv")));
        }
        cmd.arg(&bag);
        let out = run(cmd, Duration::from_secs(60));
        let places = [format!("case{case}")];
        let mut broken = judge(&out, &places);
        // replay publishes what decodes: a payload that does not is named by topic and
        // message (`rpkm bag campaign` judges what decodes too, and names the message by
        // its type and seq, or the rebuilt campaign's row)
        if broken.is_none() && out.code == Some(2) && replay {
            let topic = out.stderr.contains("/rpkm/");
            let message = out.stderr.contains("message ");
            if !(topic && message) {
                broken = Some("exit 2 without naming the topic and the message".to_owned());
            }
        }
        let broken = broken.map(|why| keep("payload", case, &bag, &why, &out));
        let _ = std::fs::remove_dir_all(&bag);
        let _ = std::fs::remove_file(dir.join(format!("c{case}.csv")));
        (broken, out.code == Some(2))
    });
    let _ = std::fs::remove_dir_all(&dir);
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
}

/// A validation campaign's row with its measured x or y moved `by_mm`: a reading far from
/// where the machine is (5 m: outside the workspace). Returns the 1-based line changed.
fn move_a_reading(lines: &mut [String], by_mm: f64, rng: &mut Rng) -> Option<usize> {
    // t,setup,instrument,reset,q1..q4,f1..f4,follower,x,y,...: x is field 13, y 14
    let rows: Vec<usize> = (1..lines.len())
        .filter(|&i| {
            let f: Vec<&str> = lines[i].split(',').collect();
            f.len() > 14 && f[3] == "0" && !f[13].is_empty()
        })
        .collect();
    if rows.is_empty() {
        return None;
    }
    let i = rows[rng.below(rows.len())];
    let mut fields: Vec<String> = lines[i].split(',').map(str::to_owned).collect();
    let k = 13 + rng.below(2);
    let v: f64 = fields[k].parse().ok()?;
    fields[k] = format!("{}", v + by_mm);
    lines[i] = fields.join(",");
    Some(i + 1)
}

/// Validation campaigns (`rpkm calibrate C --validate V`) mutated as the calibration
/// campaigns are, and in a third of the cases with one reading moved 5 m (the fuzzer of
/// issue 29 found such a row accepted without a word): exit 0 or 2 naming the validation
/// file, and the moved reading is always refused naming its line.
#[test]
fn fuzzed_validation_campaigns_end_in_0_or_2_naming_their_file() {
    let dir = scratch("val");
    let (base, val) = (dir.join("base.csv"), dir.join("val.csv"));
    for (file, seed) in [(&base, "3"), (&val, "4")] {
        let made = rpkm()
            .args(["simulate", "--campaign", "lt", "--seed", seed, "--out"])
            .arg(file)
            .output()
            .expect("rpkm simulate");
        assert!(
            made.status.success(),
            "{}",
            String::from_utf8_lossy(&made.stderr)
        );
    }
    let text = std::fs::read_to_string(&val).expect("validation campaign");
    let failures = family(VALIDATION_CASES, |case| {
        let mut rng = Rng(0x7a1d_0000 + case as u64 * 86_028_121);
        let file = dir.join(format!("val{case}.csv"));
        let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
        let moved = if rng.below(3) == 0 {
            move_a_reading(&mut lines, 5000.0, &mut rng)
        } else {
            None
        };
        let bytes = match moved {
            Some(_) => lines.join("\n").into_bytes(),
            None => mutate_text(&lines.join("\n"), &mut rng),
        };
        std::fs::write(&file, bytes).expect("write case");
        let mut cmd = rpkm();
        cmd.arg("calibrate").arg(&base).arg("--validate").arg(&file);
        let out = run(cmd, Duration::from_secs(60));
        let name = format!("val{case}.csv");
        let mut broken = judge(&out, std::slice::from_ref(&name));
        if let (None, Some(line)) = (&broken, moved) {
            if !(out.code == Some(2) && out.stderr.contains(&format!("{name}:{line}"))) {
                broken = Some(format!("a reading 5 m off at line {line} not refused"));
            }
        }
        let broken = broken.map(|why| keep("validation", case, &file, &why, &out));
        let _ = std::fs::remove_file(&file);
        (broken, out.code == Some(2))
    });
    let _ = std::fs::remove_dir_all(&dir);
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
}
