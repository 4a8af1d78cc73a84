//! `rpkm launch` as a cell controller meets it: a normal launch says only rpkm's lines (no
//! library banner), and `rpkm monitor` knows which nodes the launch declared and which one
//! is gone, with its exit code.

use crate::node_support;

use std::io::{BufRead, BufReader, Read};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use node_support::{rpkm, unique, TempDir};

/// The names rpkm's lines start with: the launch, the nodes of the shipped launch file.
const OURS: [&str; 5] = [
    "[launch] ",
    "[ingest] ",
    "[tcp_estimator] ",
    "[calibrator] ",
    "[preload_monitor] ",
];

/// A launch with stdout and stderr read line by line into one channel.
struct Running {
    child: Child,
    lines: mpsc::Receiver<String>,
    seen: Vec<String>,
}

impl Running {
    fn start(args: &[&str], envs: &[(&str, &str)]) -> Self {
        let mut child = Command::new(rpkm())
            .arg("launch")
            .args(args)
            .envs(envs.iter().copied())
            .env_remove("RPKM_LOG")
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("start rpkm launch");
        let (tx, lines) = mpsc::channel();
        let out: Box<dyn Read + Send> = Box::new(child.stdout.take().expect("stdout"));
        let err: Box<dyn Read + Send> = Box::new(child.stderr.take().expect("stderr"));
        for pipe in [out, err] {
            let tx = tx.clone();
            std::thread::spawn(move || {
                for line in BufReader::new(pipe).lines().map_while(Result::ok) {
                    eprintln!("{line}");
                    let _ = tx.send(line);
                }
            });
        }
        Self {
            child,
            lines,
            seen: Vec::new(),
        }
    }

    /// Reads lines until one contains `needle`.
    fn wait_for(&mut self, needle: &str, timeout: Duration) {
        let deadline = Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.lines.recv_timeout(left) {
                Ok(l) => {
                    let found = l.contains(needle);
                    self.seen.push(l);
                    if found {
                        return;
                    }
                }
                Err(e) => panic!(
                    "no line with {needle:?} within {timeout:?}: {e}\n{:#?}",
                    self.seen
                ),
            }
        }
    }

    /// SIGINT, as Ctrl-C; every line until both pipes close.
    fn interrupt(mut self) -> Vec<String> {
        let _ = Command::new("kill")
            .args(["-INT", &self.child.id().to_string()])
            .status();
        let _ = self.child.wait();
        let mut seen = std::mem::take(&mut self.seen);
        seen.extend(self.lines.iter());
        seen
    }
}

impl Drop for Running {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The shipped launch file on the demo campaign, until the calibrator has calibrated it and
/// then Ctrl-C: every line on stdout and stderr is one of rpkm's, none a library's (iceoryx2
/// said "No config file was loaded ..." five times per launch before).
#[test]
fn a_normal_launch_prints_only_rpkm_lines() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let launch = root.join("launch_scripts/rpkm.launch.yaml");
    let campaign = root.join("bags/demo/campaign.csv");
    let source = format!("source:={}", campaign.display());
    let mut run = Running::start(
        &[launch.to_str().expect("utf-8 path"), &source],
        &[("RPKM_IPC_PREFIX", &unique("quiet"))],
    );
    run.wait_for("[calibrator] ", Duration::from_secs(120));
    run.wait_for("[ingest] ", Duration::from_secs(120));
    // the end of the campaign reaches the calibrator, which calibrates and says so
    run.wait_for("[calibrator] calibration ", Duration::from_secs(120));
    let lines = run.interrupt();
    let foreign: Vec<&String> = lines
        .iter()
        .filter(|l| !OURS.iter().any(|o| l.starts_with(o)))
        .collect();
    assert!(
        foreign.is_empty(),
        "lines that are not rpkm's: {foreign:#?}"
    );
    assert!(
        lines
            .iter()
            .any(|l| l.starts_with("[launch] stopping every node")),
        "{lines:#?}"
    );
}

/// A launch of two nodes, one of which (ingest, its source missing) exits 2 and is not
/// restarted: `rpkm monitor --once --json` lists both declared nodes, names ingest gone with
/// exit code 2, and does not say that every node reports.
#[test]
fn the_monitor_names_a_launched_node_that_is_gone_with_its_exit_code() {
    let dir = TempDir::new("gone");
    let file = dir.path("gone.launch.yaml");
    std::fs::write(
        &file,
        format!(
            "launch:\n  - node: {{pkg: rpkm, exec: ingest, args: --source {}}}\n  \
             - node: {{pkg: rpkm, exec: tcp_estimator}}\n",
            dir.path("missing.csv").display()
        ),
    )
    .expect("launch file");
    let prefix = unique("gone");
    let mut run = Running::start(
        &[file.to_str().expect("utf-8 path")],
        &[("RPKM_IPC_PREFIX", &prefix)],
    );
    run.wait_for("ingest rejected its configuration", Duration::from_secs(60));
    let out = Command::new(rpkm())
        .args([
            "monitor",
            "--once",
            "--json",
            "--window",
            "2.5",
            "--ipc-prefix",
            &prefix,
        ])
        .output()
        .expect("rpkm monitor");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let snapshot: serde_json::Value = serde_json::from_str(&text).expect("JSON snapshot");
    let launch: Vec<(String, String)> = snapshot["launch"]
        .as_array()
        .expect("the launch's nodes")
        .iter()
        .map(|n| {
            (
                n["name"].as_str().unwrap_or_default().to_owned(),
                n["state"].as_str().unwrap_or_default().to_owned(),
            )
        })
        .collect();
    assert_eq!(
        launch,
        [
            ("ingest".to_owned(), "gone: exited with code 2".to_owned()),
            ("tcp_estimator".to_owned(), "running".to_owned()),
        ],
        "{text}"
    );
    assert_eq!(
        snapshot["gone"],
        serde_json::json!([{"name": "ingest", "how": "exited with code 2"}]),
        "{text}"
    );
    let lines = run.interrupt();
    assert!(
        lines.iter().any(|l| l.contains("missing.csv")),
        "ingest said why: {lines:#?}"
    );
}

/// A copy of `campaign` with every time shifted by `dt` s, and its times (the stamps of its
/// drive states).
fn shifted_campaign(campaign: &Path, dt: f64, to: &Path) -> Vec<f64> {
    let text = std::fs::read_to_string(campaign).expect("campaign");
    let mut times = Vec::new();
    let mut out = String::new();
    for line in text.lines() {
        let shifted = line.split_once(',').and_then(|(t, rest)| {
            let t: f64 = t.parse().ok()?;
            times.push(t + dt);
            Some(format!("{},{rest}", t + dt))
        });
        out.push_str(shifted.as_deref().unwrap_or(line));
        out.push('\n');
    }
    std::fs::write(to, out).expect("write campaign");
    times
}

/// The stamps (s) of every TcpEstimate that `sub` receives until `expected` came or nothing
/// came for 20 s.
fn estimate_stamps(
    sub: &rpkm_transport::Subscriber<rpkm_msgs::TcpEstimate>,
    expected: usize,
) -> Vec<f64> {
    let mut stamps = Vec::new();
    while stamps.len() < expected {
        match sub.recv_timeout(Duration::from_secs(20)) {
            Ok(Some(e)) => stamps.push(f64::from(e.stamp.sec) + f64::from(e.stamp.nanosec) * 1e-9),
            Ok(None) => break,
            Err(e) => panic!("receiving estimates: {e}"),
        }
    }
    stamps
}

/// Two node sets of the shipped launch file in one DDS domain and on one host's iceoryx2
/// (same prefix), `namespace:=/machine_a` and `namespace:=/machine_b`, each streaming its
/// own campaign (the second one's times 100,000 s later): a DDS subscriber of
/// `/machine_a/tcp_estimate` receives exactly machine a's estimates, one per drive state of
/// its campaign, none of b's, and the other way round.
#[test]
fn two_namespaced_sets_in_one_domain_never_hear_each_other() {
    use rpkm_transport::{topic, Backend, Names, Transport, TransportConfig};
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = TempDir::new("ns");
    // the shipped files, with time for the DDS observers to match before the stream
    let shipped =
        std::fs::read_to_string(root.join("launch_scripts/rpkm.launch.yaml")).expect("launch file");
    let params = std::fs::read_to_string(root.join("launch_scripts/params.yaml"))
        .expect("params")
        .replace("start_delay_s: 1.0", "start_delay_s: 4.0");
    std::fs::write(dir.path("params.yaml"), params).expect("params");
    let launch = dir.path("rpkm.launch.yaml");
    std::fs::write(&launch, shipped).expect("launch");
    let domain: u16 = 83;
    let prefix = unique("ns");
    let mut sets = Vec::new();
    let mut observed = Vec::new();
    for (ns, campaign, dt) in [
        ("/machine_a", "bags/demo/campaign.csv", 0.0),
        ("/machine_b", "bags/demo/campaign.val.csv", 1e5),
    ] {
        let csv = dir.path(&format!("{}.csv", &ns[1..]));
        let times = shifted_campaign(&root.join(campaign), dt, &csv);
        let names = Names::new(ns, &[]).expect("namespace");
        let observer = Transport::new(
            &TransportConfig::new(unique("nsobs"))
                .backend(Backend::Dds)
                .dds_domain(domain)
                .names(names),
        )
        .expect("DDS observer");
        let sub = observer
            .subscriber(&topic::TCP_ESTIMATE)
            .expect("subscriber");
        observed.push((ns, times, observer, sub));
    }
    for (ns, ..) in &observed {
        let source = format!(
            "source:={}",
            dir.path(&format!("{}.csv", &ns[1..])).display()
        );
        sets.push(Running::start(
            &[
                launch.to_str().expect("utf-8 path"),
                &source,
                "backend:=both",
                &format!("namespace:={ns}"),
            ],
            &[
                ("RPKM_IPC_PREFIX", &prefix),
                ("ROS_DOMAIN_ID", &domain.to_string()),
            ],
        ));
    }
    for (ns, times, _observer, sub) in &observed {
        let stamps = estimate_stamps(sub, times.len());
        let mut want = times.clone();
        want.sort_by(f64::total_cmp);
        let mut got = stamps.clone();
        got.sort_by(f64::total_cmp);
        assert_eq!(got.len(), want.len(), "{ns}: {} estimates", got.len());
        for (g, w) in got.iter().zip(&want) {
            assert!(
                (g - w).abs() < 1e-6,
                "{ns}: estimate stamped {g}, expected {w}"
            );
        }
    }
    for run in sets {
        let lines = run.interrupt();
        assert!(
            !lines.iter().any(|l| l.contains("restarting")),
            "{lines:#?}"
        );
    }
}

/// `managed: true`: the launch starts the node unconfigured and brings it up, configure then
/// activate, over its lifecycle services; the node estimates once active.
#[test]
fn the_launch_brings_a_managed_node_up() {
    use rpkm_transport::{topic, Transport, TransportConfig};
    let dir = TempDir::new("managed");
    let file = dir.path("managed.launch.yaml");
    std::fs::write(
        &file,
        "launch:\n  - set_env: {name: ROS_DOMAIN_ID, value: \"78\"}\n  \
         - node: {pkg: rpkm, exec: tcp_estimator, managed: true, args: --backend both}\n",
    )
    .expect("launch file");
    let prefix = unique("managed");
    let t = Transport::new(&TransportConfig::new(unique("mgdobs")).ipc_prefix(&prefix))
        .expect("transport");
    let states = t.publisher(&topic::ACTUATOR_STATE).expect("publisher");
    let estimates = t.subscriber(&topic::TCP_ESTIMATE).expect("subscriber");
    let mut run = Running::start(
        &[file.to_str().expect("utf-8 path")],
        &[("RPKM_IPC_PREFIX", &prefix)],
    );
    run.wait_for("[launch] tcp_estimator configured", Duration::from_secs(90));
    run.wait_for("[launch] tcp_estimator active", Duration::from_secs(30));
    let q = rpkm_core::geometry::igm(
        &rpkm_core::params::Params::nominal(),
        rpkm_core::params::Model::M29,
        0.0,
        1500.0,
    )
    .expect("igm")
    .q();
    let mut got = None;
    for seq in 1..200 {
        let state = rpkm_msgs::ActuatorState {
            seq,
            position: q.map(|v| v * 1e-3),
            follower: [false, true, true, false],
            ..rpkm_msgs::ActuatorState::default()
        };
        states.publish(&state).expect("publish");
        if let Some(e) = estimates
            .recv_timeout(Duration::from_millis(100))
            .expect("receive")
        {
            got = Some(e);
            break;
        }
    }
    let e = got.expect("an estimate once active");
    assert!((e.y - 1.5).abs() < 1e-6 && e.x.abs() < 1e-6, "{e:?}");
    let lines = run.interrupt();
    assert!(
        lines
            .iter()
            .any(|l| l.contains("lifecycle: activate -> active")),
        "{lines:#?}"
    );
}
