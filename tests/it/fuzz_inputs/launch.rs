//! Launch files, mutated: checked (`--check`) and run (never restarted in a loop).

use super::harness::{
    family, judge, keep, mutate_text, names_a_line, rpkm, run, scratch, ODD_VALUES,
};
use crate::fuzz_support::Rng;
use std::path::Path;
use std::time::Duration;

const LAUNCH_CASES: usize = 1000;
/// Cases of the families issue 29 added: launches that run, parameter maps, corrupt bag
/// payloads, validation campaigns (2,000 in all).
const LAUNCH_RUN_CASES: usize = 150;
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
            listed.contains(&format!(": {node}: rpkm-node {node} ")),
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
