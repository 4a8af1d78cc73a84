//! Shared by the tests of a ros2_control cell (`node_joint_states*.rs`): the campaign both
//! paths play, the cell's parameter block from docs/nodes.md, the script a DDS peer plays as
//! the cell (JointState at 1 kHz, a thermometer at 10 Hz, a follower switch, refused
//! messages, a silent thermometer), the launched stack and what it published, and the
//! reference: the same campaign through the CSV source, once per test run.
#![allow(dead_code)] // each test file uses a part

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use rpkm_core::campaign::Campaign;
use rpkm_msgs::{ActuatorState, CampaignInfo, DiagnosticStatus, PreloadStatus, TcpEstimate, Time};
use rpkm_nodes::campaign_bag::stamp_from_seconds;
use rpkm_transport::{topic, Subscriber, Transport, TransportConfig};

use crate::node_support::{twin_stream, unique, Launch, TempDir};

/// Poses of the twin under preload appended to the demo's: every drive holds, forces of kN.
pub const TWIN_POSES: usize = 100;
/// The extra joint the broadcaster lists among the drives (another device's).
pub const GRIPPER: &str = "gripper_joint";
/// The thermometer's topic in the cell block.
pub const THERMOMETER: &str = "/cell/frame_temperature";
/// A JointState of a campaign is sent every this many: 10 Hz at 1 kHz.
const TEMPERATURE_EVERY: usize = 100;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The campaign both paths play: `bags/demo/campaign.csv` (194 poses, q2 and q3 followers,
/// no drive force), then [`TWIN_POSES`] poses of the twin under preload 10 s later (every
/// drive holding, forces of kN), q3's encoder 50 µm off the position the nominal model
/// makes compatible (so that the model predicts a preload while q3 holds, none while it
/// follows). Read back from its CSV text, so that the CSV source and the cell's messages
/// start from the same numbers.
pub fn campaign() -> Campaign {
    let demo_text =
        std::fs::read_to_string(repo().join("bags/demo/campaign.csv")).expect("demo campaign");
    let mut c = Campaign::parse(&demo_text, "demo").expect("demo campaign parses");
    let t_end = c.poses.last().expect("demo poses").t;
    let twin = twin_stream(TWIN_POSES, 1000.0, |_| 0.02);
    let shift = t_end + 10.0 - twin.campaign.poses[0].t;
    for (k, mut pose) in twin.campaign.poses.into_iter().enumerate() {
        pose.t += shift;
        pose.setup = "cell".into();
        pose.covariates = vec![Some(20.5 + k as f64 * 1e-3)];
        pose.q[2] += 0.05;
        c.poses.push(pose);
    }
    Campaign::parse(&c.to_csv(), "joint_states.csv").expect("the campaign reads back")
}

/// Index of the first pose of the twin: where the follower switch happens.
pub fn split(c: &Campaign) -> usize {
    c.poses.len() - TWIN_POSES
}

/// The cell's parameter block, as docs/nodes.md shows it (after its marker).
pub fn cell_block() -> String {
    let doc = std::fs::read_to_string(repo().join("docs/nodes.md")).expect("docs/nodes.md");
    let at = doc
        .find("<!-- ros2_control cell block -->")
        .expect("the cell block's marker in docs/nodes.md");
    let rest = &doc[at..];
    let start = rest.find("```yaml\n").expect("```yaml") + "```yaml\n".len();
    let len = rest[start..].find("```").expect("the block's end");
    rest[start..start + len].to_owned()
}

/// What the cell block says of the joints.
pub struct CellBlock {
    /// The joints of drives q1..q4.
    pub joints: [String; 4],
    /// effort = sign × drive force (the signs are ±1).
    pub effort_sign: [f64; 4],
}

/// The joints and signs of the docs' block, read as YAML.
pub fn cell() -> CellBlock {
    let v: serde_yaml::Value = serde_yaml::from_str(&cell_block()).expect("the block is YAML");
    let p = &v["ingest"]["ros__parameters"];
    let joints: Vec<String> = p["joint_names"]
        .as_sequence()
        .expect("joint_names")
        .iter()
        .map(|n| n.as_str().expect("a name").to_owned())
        .collect();
    let signs: Vec<f64> = p["effort_sign"]
        .as_sequence()
        .expect("effort_sign")
        .iter()
        .map(|n| n.as_f64().expect("a number"))
        .collect();
    assert_eq!(
        p["temperatures"]["temp_machine"].as_str(),
        Some(THERMOMETER)
    );
    CellBlock {
        joints: joints.try_into().expect("four joints"),
        effort_sign: signs.try_into().expect("four signs"),
    }
}

fn list(v: &[f64]) -> String {
    if v.is_empty() {
        return "-".into();
    }
    v.iter().map(f64::to_string).collect::<Vec<_>>().join(",")
}

/// One script line: a JointState as the broadcaster lists it, the drives shuffled (q3, the
/// gripper, q1, q4, q2), efforts in the joints' sign (`velocity` empty: not measured).
pub fn joint_line(cell: &CellBlock, stamp: Time, q_m: [f64; 4], f: [f64; 4]) -> String {
    let order = [2, 4, 0, 3, 1];
    let (mut names, mut pos, mut eff) = (Vec::new(), Vec::new(), Vec::new());
    for i in order {
        if i == 4 {
            names.push(GRIPPER.to_owned());
            pos.push(0.012);
            eff.push(f64::NAN);
        } else {
            names.push(cell.joints[i].clone());
            pos.push(q_m[i]);
            eff.push(cell.effort_sign[i] * f[i]);
        }
    }
    format!(
        "J {} {} {} {} - {}\n",
        stamp.sec,
        stamp.nanosec,
        names.join(","),
        list(&pos),
        list(&eff)
    )
}

pub fn temperature_line(stamp: Time, celsius: f64) -> String {
    format!(
        "T {THERMOMETER} {} {} {celsius}\n",
        stamp.sec, stamp.nanosec
    )
}

/// Who the script sets `followers` on at the switch (besides ingest, a node reading the
/// cell directly).
pub struct Script<'a> {
    pub campaign: &'a Campaign,
    pub cell: &'a CellBlock,
    /// Readers of each topic the cell waits for before it plays.
    pub readers: usize,
    /// Nodes whose `followers` the cell sets at the switch; none: no switch.
    pub set_followers_on: &'a [&'a str],
    /// How many of the campaign's poses the cell plays.
    pub poses: usize,
    /// Whether the refused messages and the silent thermometer follow the poses.
    pub tail: bool,
}

/// The stamp of pose `k` of `c`.
pub fn stamp(c: &Campaign, k: usize) -> Time {
    stamp_from_seconds(c.poses[k].t).expect("a campaign stamp")
}

impl Script<'_> {
    /// The script of `tests/python/joint_states_peer.py` (and of the Fast DDS peer): wait for
    /// the readers, a temperature, every pose as a JointState (a temperature every 100th), the
    /// follower switch before the twin's poses; then (`tail`) a JointState without q2's joint,
    /// one with a short effort array, one with q3 at NaN, 2.5 s without a temperature and
    /// the last pose again 4 s later.
    pub fn text(&self) -> String {
        let c = self.campaign;
        let mut out = format!("MATCH {} /joint_states {THERMOMETER}\n", self.readers);
        let temp = |k: usize| c.poses[k].covariates[0].expect("a temperature");
        out.push_str(&temperature_line(stamp(c, 0), temp(0)));
        for (k, pose) in c.poses.iter().enumerate().take(self.poses) {
            if k == split(c) && !self.set_followers_on.is_empty() {
                // every earlier state has been read before the set
                out.push_str("WAIT 0.3\n");
                for node in self.set_followers_on {
                    let _ = writeln!(out, "SET {node} followers ''");
                }
            }
            if k > 0 && k % TEMPERATURE_EVERY == 0 {
                out.push_str(&temperature_line(stamp(c, k), temp(k)));
            }
            let q = pose.q.map(|q| q / rpkm_nodes::units::MM_PER_M);
            out.push_str(&joint_line(self.cell, stamp(c, k), q, pose.f));
        }
        if self.tail {
            out.push_str(&self.tail_text());
        }
        out
    }

    fn tail_text(&self) -> String {
        let c = self.campaign;
        let last = c.poses.last().expect("poses");
        let q = last.q.map(|q| q / rpkm_nodes::units::MM_PER_M);
        let at = |dt: f64| stamp_from_seconds(last.t + dt).expect("stamp");
        let good = joint_line(self.cell, at(1.0), q, last.f);
        let missing = good.replace(&self.cell.joints[1], "q2_link");
        // the effort array one short
        let short = good
            .rsplit_once(',')
            .map(|(a, _)| format!("{a}\n"))
            .expect("list");
        let nan = good.replacen(&format!(" {}", q[2]), " nan", 1);
        assert_ne!(nan, good, "q3's position is listed first");
        let mut out = String::new();
        for line in [missing, short, nan] {
            out.push_str(&line);
        }
        out.push_str("WAIT 2.5\n");
        out.push_str(&joint_line(self.cell, at(4.0), q, last.f));
        out.push_str("WAIT 1.0\n");
        out
    }
}

/// The launch folder: the shipped launch file and params.yaml, the docs' cell block as
/// cell.yaml and the test's settings as test.yaml, both read after params.yaml by every node.
pub fn launch_dir(tag: &str) -> (TempDir, PathBuf) {
    let dir = TempDir::new(tag);
    let shipped = repo().join("launch_scripts");
    std::fs::copy(shipped.join("params.yaml"), dir.path("params.yaml")).expect("params.yaml");
    std::fs::write(dir.path("cell.yaml"), cell_block()).expect("cell.yaml");
    std::fs::write(
        dir.path("test.yaml"),
        "/**:\n  ros__parameters:\n    diagnostics_period_s: 0.2\n\
         ingest:\n  ros__parameters:\n    end_marker: false\n\
         preload_monitor:\n  ros__parameters:\n    status_every: 1\n",
    )
    .expect("test.yaml");
    let launch = std::fs::read_to_string(shipped.join("rpkm.launch.yaml")).expect("launch");
    // every node reads params.yaml, in the flow form or as the first of a block list
    let (flow, block) = (
        "param: [{from: params.yaml}]",
        "        - from: params.yaml\n",
    );
    assert_eq!(
        launch.matches(flow).count() + launch.matches(block).count(),
        4,
        "the shipped launch's nodes"
    );
    let launch = launch
        .replace(
            flow,
            "param: [{from: params.yaml}, {from: cell.yaml}, {from: test.yaml}]",
        )
        .replace(
            block,
            "        - from: params.yaml\n        - from: cell.yaml\n        - from: test.yaml\n",
        );
    let file = dir.path("rpkm.launch.yaml");
    std::fs::write(&file, launch).expect("launch file");
    (dir, file)
}

/// What the stack published, as an rpkm process on the same iceoryx2 prefix sees it.
#[derive(Default)]
pub struct Observed {
    /// TcpEstimates by seq.
    pub estimates: BTreeMap<u64, TcpEstimate>,
    /// PreloadStatus in order.
    pub statuses: Vec<PreloadStatus>,
    /// ActuatorStates in order.
    pub states: Vec<ActuatorState>,
    /// The last CampaignInfo.
    pub info: Option<CampaignInfo>,
    /// The last /diagnostics status of each node, by status name.
    pub diagnostics: BTreeMap<String, DiagnosticStatus>,
    /// TcpEstimates of a second estimator (`extra_estimates`), by seq.
    pub extra: BTreeMap<u64, TcpEstimate>,
}

/// Subscribers on the stack's iceoryx2 prefix.
pub struct Observer {
    estimates: Subscriber<TcpEstimate>,
    statuses: Subscriber<PreloadStatus>,
    states: Subscriber<ActuatorState>,
    info: Subscriber<CampaignInfo>,
    diagnostics: Vec<Subscriber<rpkm_msgs::DiagnosticArray>>,
    extra: Option<Subscriber<TcpEstimate>>,
    _transport: Transport,
    pub seen: Observed,
}

impl Observer {
    /// Subscribed before the stack starts (so that nothing is missed); `extra`: a second
    /// estimator's iceoryx2 topic and /diagnostics (`/direct/tcp_estimate`,
    /// `/direct/diagnostics`).
    pub fn new(prefix: &str, extra: Option<(&'static str, &'static str)>) -> Self {
        let t = Transport::new(&TransportConfig::new(unique("obs")).ipc_prefix(prefix))
            .expect("transport");
        let mut diagnostics = vec![t.subscriber(&topic::DIAGNOSTICS).expect("sub")];
        let extra = extra.map(|(estimates, diag)| {
            diagnostics.push(
                t.subscriber(&topic::DIAGNOSTICS.renamed(diag))
                    .expect("sub"),
            );
            t.subscriber(&topic::TCP_ESTIMATE.renamed(estimates))
                .expect("sub")
        });
        Self {
            estimates: t.subscriber(&topic::TCP_ESTIMATE).expect("sub"),
            statuses: t.subscriber(&topic::PRELOAD_STATUS).expect("sub"),
            states: t.subscriber(&topic::ACTUATOR_STATE).expect("sub"),
            info: t.subscriber(&topic::CAMPAIGN_INFO).expect("sub"),
            diagnostics,
            extra,
            _transport: t,
            seen: Observed::default(),
        }
    }

    /// Takes what arrived; whether anything did.
    pub fn poll(&mut self) -> bool {
        let s = &mut self.seen;
        let mut any = false;
        while let Some(e) = self.estimates.try_recv().expect("recv") {
            assert!(
                s.estimates.insert(e.seq, e).is_none(),
                "seq {} twice",
                e.seq
            );
            any = true;
        }
        while let Some(p) = self.statuses.try_recv().expect("recv") {
            s.statuses.push(p);
            any = true;
        }
        while let Some(a) = self.states.try_recv().expect("recv") {
            s.states.push(a);
            any = true;
        }
        while let Some(i) = self.info.try_recv().expect("recv") {
            s.info = Some(i);
        }
        for sub in &self.diagnostics {
            while let Some(d) = sub.try_recv().expect("recv") {
                for st in d.status {
                    s.diagnostics.insert(st.name.clone(), st);
                }
            }
        }
        if let Some(sub) = &self.extra {
            while let Some(e) = sub.try_recv().expect("recv") {
                assert!(s.extra.insert(e.seq, e).is_none(), "seq {} twice", e.seq);
                any = true;
            }
        }
        any
    }

    /// Polls until `done` says so or `timeout` passes (then the caller's assertions say
    /// what is missing).
    pub fn until(&mut self, timeout: Duration, done: impl Fn(&Observed) -> bool) {
        let deadline = Instant::now() + timeout;
        while Instant::now() < deadline && !done(&self.seen) {
            if !self.poll() {
                std::thread::sleep(Duration::from_millis(1));
            }
        }
    }
}

/// The same campaign through the CSV source (`source:=FILE.csv`), the stack launched as the
/// cell's is: its estimates and preload statuses, once per test run.
pub fn reference() -> &'static Observed {
    static REFERENCE: OnceLock<Observed> = OnceLock::new();
    REFERENCE.get_or_init(|| {
        let c = campaign();
        let (dir, launch) = launch_dir("js_ref");
        let csv = dir.path("joint_states.csv");
        std::fs::write(&csv, c.to_csv()).expect("campaign csv");
        let prefix = unique("jsref");
        let mut obs = Observer::new(&prefix, None);
        let source = format!("source:={}", csv.display());
        let mut stack = Launch::start_with(
            &launch,
            &[&source],
            &[("RPKM_IPC_PREFIX", &prefix), ("ROS_DOMAIN_ID", "63")],
        );
        let n = c.poses.len();
        obs.until(Duration::from_secs(60), |s| {
            s.estimates.len() >= n && s.statuses.len() >= n
        });
        stack.stop();
        assert_eq!(obs.seen.estimates.len(), n, "CSV source: estimates");
        assert_eq!(obs.seen.statuses.len(), n, "CSV source: preload statuses");
        obs.seen
    })
}

/// Newtons per percent of redundancy current.
const N_PER_PERCENT: f64 = rpkm_core::elastic::NOMINAL_DRIVE_FORCE_N / 100.0;

/// The largest differences of two estimates: (m and rad, N); the flags must agree.
pub fn estimate_gap(a: &TcpEstimate, b: &TcpEstimate) -> (f64, f64) {
    assert_eq!(a.stamp, b.stamp, "seq {}", a.seq);
    assert_eq!(
        (a.converged, a.outcome, a.model),
        (b.converged, b.outcome, b.model),
        "seq {}",
        a.seq
    );
    let m = [a.x - b.x, a.y - b.y, a.psi - b.psi]
        .into_iter()
        .chain(
            a.loop_residuals
                .iter()
                .zip(&b.loop_residuals)
                .map(|(x, y)| x - y),
        )
        .fold(0.0f64, |w, d| w.max(d.abs()));
    let n = a
        .rod_forces
        .iter()
        .zip(&b.rod_forces)
        .chain(a.drive_forces.iter().zip(&b.drive_forces))
        .fold(0.0f64, |w, (x, y)| w.max((x - y).abs()));
    (m, n)
}

/// The largest differences of two preload statuses: (m, N); the levels must agree.
pub fn status_gap(a: &PreloadStatus, b: &PreloadStatus) -> (f64, f64) {
    assert_eq!((a.stamp, a.level), (b.stamp, b.level));
    // not measured (NaN) on both sides, or the same number
    let gap = |x: f64, y: f64| match (x.is_nan(), y.is_nan()) {
        (true, true) => 0.0,
        (false, false) => (x - y).abs(),
        _ => f64::INFINITY,
    };
    let m = gap(a.dq2, b.dq2).max(gap(a.dq3, b.dq3));
    let n = a
        .measured_current
        .iter()
        .zip(&b.measured_current)
        .chain(a.predicted_current.iter().zip(&b.predicted_current))
        .fold(0.0f64, |w, (x, y)| w.max((x - y).abs() * N_PER_PERCENT));
    (m, n)
}

/// The value of `key` in a /diagnostics status.
pub fn value<'a>(st: &'a DiagnosticStatus, key: &str) -> Option<&'a str> {
    st.values
        .iter()
        .find(|v| v.key == key)
        .map(|v| v.value.as_str())
}

/// Writes `text` as the peer's script in `dir`.
pub fn write_script(dir: &Path, text: &str) -> PathBuf {
    let path = dir.join("cell.script");
    std::fs::write(&path, text).expect("script");
    path
}
