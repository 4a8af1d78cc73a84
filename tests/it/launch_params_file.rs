//! Issue 50: a cell integrator guesses nothing. The ros2_control block of docs/nodes.md, cut
//! out of the page as a user pastes it into a file of the cell's own and passed as the
//! shipped launch file's `params_file:=`, with `source:=joint_states` and no backend given:
//! an independent cell on Cyclone DDS (tests/python/joint_states_peer.py) plays the demo's
//! first poses as JointStates and a Cyclone reader (tests/python/cyclone_peer.py) receives
//! every estimate on DDS, each the core's elasto-geometric solve of the drive state it sent
//! (q2, q3 following, as the block says); the launched nodes are `rpkm-node` processes. The
//! same block pasted into the shipped params.yaml instead is refused at the pasted section's
//! line.

use crate::joint_states_support::{campaign, cell, cell_block, write_script, Script};
use crate::node_support::{python, rpkm, unique, Launch, Proc, TempDir};

use rpkm_core::elastic::{fegm, Stiffness, FOLLOWERS_23};
use rpkm_core::params::Params;

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

const DOMAIN: &str = "47";
/// The demo's first poses the cell plays.
const POSES: usize = 40;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// A Python peer with its stdout lines in a channel (echoed with `tag`).
fn peer(
    py: &Path,
    script: &str,
    args: &[&str],
    tag: &'static str,
) -> (Proc, mpsc::Receiver<String>) {
    let mut child = Command::new(py)
        .arg(repo().join("tests/python").join(script))
        .args(args)
        .stdout(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("start {script}: {e}"));
    let out = child.stdout.take().expect("piped");
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(out).lines().map_while(Result::ok) {
            eprintln!("[{tag}] {line}");
            let _ = tx.send(line);
        }
    });
    (Proc(child), rx)
}

/// The lines of `rx` up to one starting with an element of `last` (inclusive).
fn lines_until(rx: &mpsc::Receiver<String>, last: &[&str], timeout: Duration) -> Vec<String> {
    let mut lines = Vec::new();
    while let Ok(line) = rx.recv_timeout(timeout) {
        let end = last.iter().any(|l| line.starts_with(l));
        lines.push(line);
        if end {
            break;
        }
    }
    lines
}

/// The executable of process `pid`, by its file name.
fn program_of(pid: u32) -> String {
    std::fs::read_link(format!("/proc/{pid}/exe"))
        .map(|p| {
            p.file_name()
                .unwrap_or_default()
                .to_string_lossy()
                .into_owned()
        })
        .unwrap_or_default()
}

#[test]
fn the_documented_cell_block_runs_the_stack_on_dds() {
    let Some(py) = python() else { return };
    let dir = TempDir::new("pfile");
    let cell_file = dir.path("cell.yaml");
    std::fs::write(&cell_file, cell_block()).expect("cell.yaml");
    let c = campaign();
    let script = Script {
        campaign: &c,
        cell: &cell(),
        readers: 1,
        set_followers_on: &[],
        poses: POSES,
        tail: false,
    };
    // a second after ingest's readers matched: the estimate reader is matched too
    let script = write_script(&dir.0, &script.text().replacen('\n', "\nWAIT 1.0\n", 1));
    let launch = repo().join("launch_scripts/rpkm.launch.yaml");
    let params_file = format!("params_file:={}", cell_file.display());
    let envs = [
        ("RPKM_IPC_PREFIX", unique("pfile")),
        ("ROS_DOMAIN_ID", DOMAIN.to_owned()),
    ];
    let envs: Vec<(&str, &str)> = envs.iter().map(|(k, v)| (*k, v.as_str())).collect();
    let mut stack = Launch::start_with(&launch, &["source:=joint_states", &params_file], &envs);
    let count = POSES.to_string();
    let reader_args = [
        "print_estimate",
        "--domain",
        DOMAIN,
        "--count",
        &count,
        "--timeout",
        "60",
    ];
    let (_reader, estimates) = peer(&py, "cyclone_peer.py", &reader_args, "estimates");
    assert_eq!(
        lines_until(&estimates, &["READY"], Duration::from_secs(20))
            .last()
            .map(String::as_str),
        Some("READY")
    );
    let script = script.display().to_string();
    let cell_args = [script.as_str(), "--domain", DOMAIN, "--timeout", "60"];
    let (_cell, said) = peer(&py, "joint_states_peer.py", &cell_args, "cell");
    let played = lines_until(&said, &["PLAYED", "TIMEOUT"], Duration::from_secs(60));
    let received = lines_until(&estimates, &["DONE", "TIMEOUT"], Duration::from_secs(30));
    let programs: Vec<String> = ["ingest", "tcp_estimator", "calibrator", "preload_monitor"]
        .iter()
        .flat_map(|n| stack.started(n))
        .map(program_of)
        .collect();
    stack.stop();
    assert_eq!(
        played.last().map(String::as_str),
        Some(&*format!("PLAYED {POSES}"))
    );
    assert_eq!(
        received.last().map(String::as_str),
        Some("DONE"),
        "{received:?}"
    );
    assert_eq!(programs, ["rpkm-node"; 4], "the launched nodes' programs");
    let mut largest = 0.0f64;
    for line in &received[..received.len() - 1] {
        let e: serde_json::Value = serde_json::from_str(line).expect("a JSON estimate");
        let seq = e["seq"].as_u64().expect("seq");
        let pose = &c.poses[usize::try_from(seq).expect("seq") - 1];
        let want = fegm(
            &Params::nominal(),
            &Stiffness::default(),
            pose.q,
            FOLLOWERS_23,
        )
        .expect("the core solves the drive state");
        let at = |key: &str| f64::from_bits(e[key].as_u64().expect("float bits"));
        let gap = (at("x") * 1e3 - want.x).hypot(at("y") * 1e3 - want.y);
        largest = largest.max(gap);
    }
    eprintln!("{POSES} estimates on DDS; largest distance to the core's solve {largest:e} mm");
    assert!(largest < 1e-9, "{largest} mm");
}

/// The block pasted below the shipped params.yaml's own `ingest:` section, as the docs once
/// said: refused (exit 2) at the pasted section's line, naming the first one's.
#[test]
fn the_block_pasted_into_the_shipped_file_is_refused_at_its_line() {
    let dir = TempDir::new("pfdup");
    let shipped = repo().join("launch_scripts");
    std::fs::copy(
        shipped.join("rpkm.launch.yaml"),
        dir.path("rpkm.launch.yaml"),
    )
    .expect("copy");
    let params = std::fs::read_to_string(shipped.join("params.yaml")).expect("params.yaml");
    let pasted = format!("{params}\n{}", cell_block());
    std::fs::write(dir.path("params.yaml"), &pasted).expect("params.yaml");
    let line_of = |n: usize| {
        pasted
            .lines()
            .enumerate()
            .filter(|(_, l)| l.starts_with("ingest:"))
            .nth(n)
            .map(|(i, _)| i + 1)
            .expect("an ingest section")
    };
    let out = Command::new(rpkm())
        .arg("launch")
        .arg(dir.path("rpkm.launch.yaml"))
        .arg("--check")
        .output()
        .expect("rpkm launch --check");
    let text = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{text}");
    let want = format!(
        "params.yaml:{}:1: not YAML: key \"ingest\" again (first at line {})",
        line_of(1),
        line_of(0)
    );
    assert!(text.contains(&want), "{want} in {text}");
}

/// Without `rpkm-node` beside it, `rpkm` says so and starts the nodes as `rpkm node ...`
/// (`--check` prints the command line each node would start with).
#[test]
fn without_the_node_program_the_launch_says_so_and_runs_rpkm_node() {
    let dir = TempDir::new("pfsolo");
    let solo = dir.path("rpkm");
    std::fs::copy(rpkm(), &solo).expect("copy rpkm alone");
    let out = Command::new(&solo)
        .arg("launch")
        .arg(repo().join("launch_scripts/rpkm.launch.yaml"))
        .arg("--check")
        .output()
        .expect("rpkm launch --check");
    let text = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(0), "{text}");
    assert!(
        text.contains(&format!("rpkm-node not found beside {}", solo.display())),
        "{text}"
    );
    assert!(
        text.contains(": tcp_estimator: rpkm node tcp_estimator --name=tcp_estimator"),
        "{text}"
    );
    // beside it, the node program
    let out = Command::new(rpkm())
        .arg("launch")
        .arg(repo().join("launch_scripts/rpkm.launch.yaml"))
        .arg("--check")
        .output()
        .expect("rpkm launch --check");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains(": tcp_estimator: rpkm-node tcp_estimator --name=tcp_estimator"),
        "{text}"
    );
    assert!(!text.contains("not found"), "{text}");
}
