//! `rpkm monitor` as a user sees it: in a detached tmux session (its own server socket), on
//! the launched tcp_estimator and preload_monitor (real processes over iceoryx2, a unique
//! prefix), while `rpkm replay` publishes `bags/preload_fault`. The screen is read with
//! `tmux capture-pane -p` by bounded polling:
//! - the faulty drive of the truth file (q3) shows WARN while its deviation is between the
//!   thresholds, then ERROR above them, and at the end the deviation the core gives for the
//!   bag's last sample;
//! - after SIGKILL of tcp_estimator the screen names it within 2 s, and only it: GONE,
//!   killed by signal 9, as the launch reports it (SILENT before the monitor knew the launch);
//! - `q` ends the monitor with exit status 0.
//!
//! Skipped with a message where tmux is missing, unless RPKM_REQUIRE_PYTHON or CI is set.
#![expect(
    clippy::cast_possible_truncation,
    reason = "test and benchmark fixtures: counters, stamps and sizes far inside the target type's range"
)]

use crate::bag_support;
use crate::node_support;

use std::process::Command;
use std::time::{Duration, Instant};

use bag_support::{decode_all, reference_bag, rpkm, scratch, Watched};
use node_support::{unique, write_truth_json, Launch};
use rpkm_core::elastic::{fegm, Stiffness, ALL_ACTIVE, NOMINAL_DRIVE_FORCE_N};
use rpkm_core::params::{self, Params};
use rpkm_msgs::ActuatorState;
use rpkm_transport::{topic, Transport, TransportConfig};
use serde_json::Value;

const WARN: f64 = 30.0;
const ERROR: f64 = 80.0;

/// A tmux server of the test's own (`-L socket`), killed on drop.
struct Tmux {
    socket: String,
}

impl Tmux {
    fn cmd(&self) -> Command {
        let mut c = Command::new("tmux");
        c.args(["-L", &self.socket, "-f", "/dev/null"]);
        c
    }

    fn run(&self, args: &[&str]) -> String {
        let out = self.cmd().args(args).output().expect("run tmux");
        assert!(
            out.status.success(),
            "tmux {args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).into_owned()
    }

    fn screen(&self) -> String {
        self.run(&["capture-pane", "-p", "-t", "mon"])
    }

    /// Polls the screen until `pred` holds; panics with the last screen after `timeout`.
    fn wait_screen(&self, what: &str, timeout: Duration, pred: impl Fn(&str) -> bool) -> String {
        let deadline = Instant::now() + timeout;
        loop {
            let s = self.screen();
            if pred(&s) {
                return s;
            }
            assert!(
                Instant::now() < deadline,
                "no screen with {what} within {timeout:?}; last screen:\n{s}"
            );
            std::thread::sleep(Duration::from_millis(30));
        }
    }
}

impl Drop for Tmux {
    fn drop(&mut self) {
        let _ = self.cmd().arg("kill-server").output();
    }
}

fn tmux_available() -> bool {
    let found = Command::new("tmux")
        .arg("-V")
        .output()
        .is_ok_and(|o| o.status.success());
    let required =
        std::env::var_os("RPKM_REQUIRE_PYTHON").is_some() || std::env::var_os("CI").is_some();
    assert!(
        found || !required,
        "tmux is missing but RPKM_REQUIRE_PYTHON/CI is set (.ci/run installs it)"
    );
    if !found {
        eprintln!("SKIPPED monitor_tmux: tmux is not installed (apt-get install tmux)");
    }
    found
}

/// The line of drive `q` (`q3 measured ... deviation +113.2 %  ERROR`): (deviation, label).
fn drive_row(screen: &str, drive: usize) -> Option<(f64, String)> {
    let line = screen
        .lines()
        .find(|l| l.contains(&format!("q{drive} measured")))?;
    let after = line.split("deviation").nth(1)?;
    let mut words = after.split_whitespace();
    let value: f64 = words.next()?.parse().ok()?;
    let _percent = words.next()?;
    let label = words.next()?.trim_end_matches('│').to_owned();
    Some((value, label))
}

fn truth() -> Value {
    let text = std::fs::read_to_string(reference_bag("preload_fault.truth.json")).expect("truth");
    serde_json::from_str(&text).expect("JSON")
}

fn truth_params(truth: &Value) -> Params {
    let mut p = Params::nominal();
    for (name, v) in truth["params"].as_object().expect("params") {
        p[params::index_of(name).expect("known name")] = v.as_f64().expect("number");
    }
    p
}

/// The deviation (%) of drive index `d` the core gives for the bag's last state.
fn core_last_deviation(p: &Params, d: usize) -> f64 {
    let states: Vec<ActuatorState> =
        decode_all(&reference_bag("preload_fault"), "/rpkm/actuator_state");
    let last = states.last().expect("states");
    let eq = fegm(
        p,
        &Stiffness::default(),
        last.position.map(|v| v * 1e3),
        ALL_ACTIVE,
    )
    .expect("core fegm");
    (last.force[d] - eq.drive_force[d]) / NOMINAL_DRIVE_FORCE_N * 100.0
}

/// Starts tcp_estimator and preload_monitor (no respawn: a killed node stays dead) on the
/// bag's true geometry; returns once both report on /diagnostics.
fn start_nodes(dir: &std::path::Path, p: &Params, prefix: &str) -> Launch {
    let geometry = dir.join("true_params.json");
    write_truth_json(p, &geometry);
    std::fs::write(
        dir.join("params.yaml"),
        format!(
            "/**:\n  ros__parameters:\n    geometry_file: {}\n    diagnostics_period_s: 0.2\n\
             preload_monitor:\n  ros__parameters:\n    warn_percent: {WARN}\n    \
             error_percent: {ERROR}\n    debounce_samples: 3\n    status_every: 1\n",
            geometry.display()
        ),
    )
    .expect("params.yaml");
    let launch_file = dir.join("monitor.launch.yaml");
    std::fs::write(
        &launch_file,
        "launch:\n  - node: {pkg: rpkm, exec: tcp_estimator, param: [{from: params.yaml}], \
         respawn: false}\n  \
         - node: {pkg: rpkm, exec: preload_monitor, param: [{from: params.yaml}]}\n",
    )
    .expect("launch file");
    let observer = Transport::new(&TransportConfig::new(unique("monobs")).ipc_prefix(prefix))
        .expect("transport");
    let diagnostics = observer.subscriber(&topic::DIAGNOSTICS).expect("sub");
    let launched = Launch::start(&launch_file, &[("RPKM_IPC_PREFIX", prefix)]);
    let mut reporting = std::collections::BTreeSet::new();
    let deadline = Instant::now() + Duration::from_secs(60);
    while reporting.len() < 2 {
        assert!(
            Instant::now() < deadline,
            "nodes not reporting: {reporting:?}"
        );
        while let Some(d) = diagnostics.try_recv().expect("recv") {
            reporting.extend(d.status.into_iter().map(|s| s.name));
        }
        reporting.retain(|n| n == "rpkm/preload_monitor" || n == "rpkm/tcp_estimator");
        std::thread::sleep(Duration::from_millis(10));
    }
    launched
}

#[test]
#[expect(
    clippy::too_many_lines,
    reason = "an end-to-end scenario, read top to bottom"
)]
fn monitor_in_tmux_shows_the_fault_and_the_silent_estimator() {
    // its SIGKILLed node's resources are its own to see cleaned up (crate::KILLS_A_NODE)
    let _alone = crate::KILLS_A_NODE
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    if !tmux_available() {
        return;
    }
    let truth = truth();
    let faulty = truth["stream"]["fault"]["drive"]
        .as_u64()
        .expect("fault drive") as usize
        + 1;
    assert_eq!(faulty, 3, "the bag's fault is on q3");
    let p = truth_params(&truth);
    let dir = scratch("monitor-tmux");
    let prefix = unique("mon");
    let mut launched = start_nodes(&dir, &p, &prefix);

    let tmux = Tmux {
        socket: unique("tmux"),
    };
    // The monitor's exit status through a file its shell writes: tmux's #{pane_dead_status}
    // stays empty on some runs (the pane marked dead at the pty's end, the child reaped
    // later; 1 run in 3 here).
    let status_file = dir.join("monitor.status");
    let monitor = format!(
        "{} monitor --ipc-prefix {prefix}; echo $? > {}",
        env!("CARGO_BIN_EXE_rpkm"),
        status_file.display()
    );
    tmux.run(&[
        "new-session",
        "-d",
        "-s",
        "mon",
        "-x",
        "130",
        "-y",
        "50",
        &monitor,
    ]);
    tmux.run(&["set-option", "-t", "mon", "remain-on-exit", "on"]);
    // The thresholds come with preload_monitor's first report, as key-values, before any
    // drive state (the parameter file's 30 / 80 %).
    tmux.wait_screen("both nodes reporting", Duration::from_secs(30), |s| {
        s.contains("all 2 nodes reporting")
            && s.contains("WARN 30 % · ERROR 80 % (from preload_monitor)")
            && s.contains("no drive state evaluated yet")
    });

    // Replay at half speed (2,000 samples in 4 s) and read the screen as it goes.
    let mut replay = Watched::spawn(
        rpkm()
            .arg("replay")
            .arg(reference_bag("preload_fault"))
            .args(["--rate", "0.5", "--ipc-prefix", &prefix]),
    );
    let mut seen_warn: Option<(usize, f64)> = None;
    let mut seen_error: Option<(usize, f64)> = None;
    let mut captures = 0;
    let deadline = Instant::now() + Duration::from_secs(120);
    let mut last = String::new();
    while Instant::now() < deadline {
        last = tmux.screen();
        captures += 1;
        if let Some((dev, label)) = drive_row(&last, faulty) {
            match label.as_str() {
                "WARN" => {
                    seen_warn.get_or_insert((captures, dev));
                }
                "ERROR" => {
                    seen_error.get_or_insert((captures, dev));
                }
                _ => {}
            }
        }
        let replay_done = matches!(replay.child.try_wait(), Ok(Some(_)));
        if replay_done && seen_error.is_some() && last.contains("statuses") {
            break;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let status = replay.wait(Duration::from_secs(60));
    assert!(status.success(), "replay: {}", replay.seen.join("\n"));
    let (kw, dev_w) = seen_warn.unwrap_or_else(|| panic!("q{faulty} never shown WARN:\n{last}"));
    let (ke, dev_e) = seen_error.unwrap_or_else(|| panic!("q{faulty} never shown ERROR:\n{last}"));
    assert!(kw < ke, "WARN (capture {kw}) before ERROR (capture {ke})");
    assert!(
        (WARN..ERROR).contains(&dev_w.abs()),
        "WARN shown at deviation {dev_w} %"
    );
    assert!(dev_e.abs() >= ERROR, "ERROR shown at deviation {dev_e} %");

    // Once the replay is over the last status is the bag's last sample: the core's number.
    let want = core_last_deviation(&p, faulty - 1);
    let end = tmux.wait_screen("the last sample", Duration::from_secs(20), |s| {
        drive_row(s, faulty).is_some_and(|(d, _)| (d - want).abs() <= 0.051)
    });
    assert!(
        end.contains("held level ERROR"),
        "the held level says ERROR:\n{end}"
    );
    assert!(
        end.contains("WARN 30 % · ERROR 80 % (from preload_monitor)"),
        "{end}"
    );

    // Kill the estimator: named gone (the launch says so) within 2 s, the monitor node not.
    let pid = *launched
        .started("tcp_estimator")
        .last()
        .expect("tcp_estimator pid");
    let killed = Instant::now();
    let status = Command::new("kill")
        .args(["-KILL", &pid.to_string()])
        .status()
        .expect("kill");
    assert!(status.success());
    let silent = tmux.wait_screen("tcp_estimator GONE", Duration::from_secs(10), |s| {
        s.lines()
            .any(|l| l.contains("GONE: tcp_estimator (killed by signal 9)"))
    });
    let took = killed.elapsed();
    eprintln!(
        "monitor_tmux: q{faulty} shown WARN at {dev_w:+.1} %, ERROR at {dev_e:+.1} % \
         ({captures} captures); tcp_estimator named silent {took:?} after SIGKILL"
    );
    assert!(
        took < Duration::from_secs(2),
        "named silent after {took:?}:\n{silent}"
    );
    let alert = silent
        .lines()
        .find(|l| l.contains("GONE:"))
        .expect("alert line");
    assert!(!alert.contains("preload_monitor"), "{alert}");

    // q quits with exit status 0.
    tmux.run(&["send-keys", "-t", "mon", "q"]);
    let deadline = Instant::now() + Duration::from_secs(10);
    let status = loop {
        // the shell writes the status after the monitor has exited: wait for a whole line
        let s = std::fs::read_to_string(&status_file).unwrap_or_default();
        if s.ends_with('\n') || Instant::now() > deadline {
            break s;
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    assert_eq!(status.trim(), "0", "the monitor quit on q with status 0");
    launched.stop();
}
