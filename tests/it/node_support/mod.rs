//! Shared by the node tests: the rpkm binary, unique iceoryx2 prefixes, a twin actuator
//! stream as a campaign file, and `rpkm launch` as a child whose `[launch]` lines are read.
#![allow(dead_code)] // each test file uses a part

use std::fmt::Write as _;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc::{self, Receiver};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use rpkm_core::campaign::{Campaign, Instrument, MeasuredPose};
use rpkm_core::elastic::Stiffness;
use rpkm_core::params::{Params, NAMES};
use rpkm_twin::{EffectKind, MachineState, Twin, TwinConfig};

pub fn rpkm() -> &'static str {
    env!("CARGO_BIN_EXE_rpkm")
}

/// A prefix no other test or run uses (iceoryx2 services are global to the machine).
pub fn unique(tag: &str) -> String {
    let ns = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.subsec_nanos());
    format!("t_{tag}_{}_{ns}", std::process::id())
}

/// A twin stream: the machine under `preload_elastic` moving along x at y = 1700 mm, every
/// drive holding; `q3_drift_mm(k)` is how far drive 3's carrier sits from what its encoder
/// reads at sample k (an offset on q3 that the controller does not see).
pub struct Stream {
    pub twin: Twin,
    pub campaign: Campaign,
    pub truth: Vec<MachineState>,
    pub drift_mm: Vec<f64>,
}

pub fn twin_stream(n: usize, rate_hz: f64, q3_drift_mm: impl Fn(usize) -> f64) -> Stream {
    let twin = Twin::new(TwinConfig {
        seed: 11,
        effects: vec![(EffectKind::PreloadElastic, 1.0)],
        noise: None,
        ..TwinConfig::default()
    })
    .expect("twin");
    let mut poses = Vec::with_capacity(n);
    let mut truth = Vec::with_capacity(n);
    let mut drift_mm = Vec::with_capacity(n);
    for k in 0..n {
        let s = k as f64 / (n.max(2) - 1) as f64;
        let x = -100.0 + 200.0 * s;
        let d = q3_drift_mm(k);
        let t = 10.0 + k as f64 / rate_hz;
        let st = twin
            .machine_state("stream", x, 1700.0, t, [0.0, 0.0, d, 0.0], false)
            .expect("machine state");
        poses.push(MeasuredPose {
            t,
            setup: "stream".into(),
            instrument: Instrument::None,
            reset: false,
            q: st.q,
            f: st.f,
            follower: st.follower,
            x: None,
            y: None,
            r: None,
            psi: None,
            covariates: vec![],
            line: 0,
        });
        truth.push(st);
        drift_mm.push(d);
    }
    let campaign = Campaign {
        source: "twin stream".into(),
        comments: vec!["twin stream for the node tests".into()],
        covariate_names: vec![],
        poses,
    };
    Stream {
        twin,
        campaign,
        truth,
        drift_mm,
    }
}

/// The twin's true parameters as the JSON `geometry_file` the nodes read (mm, rad).
pub fn write_truth_json(p: &Params, path: &Path) {
    let obj: serde_json::Map<String, serde_json::Value> = NAMES
        .iter()
        .enumerate()
        .map(|(i, n)| ((*n).to_owned(), serde_json::json!(p[i])))
        .collect();
    std::fs::write(path, serde_json::Value::Object(obj).to_string()).expect("write params");
}

/// The stiffness the nodes use by default, which is the twin's.
pub fn stiffness() -> Stiffness {
    Stiffness::default()
}

/// `rpkm launch FILE` with its stderr collected; stopped with SIGTERM on drop.
pub struct Launch {
    pub child: Child,
    pub log: Arc<Mutex<Vec<String>>>,
    lines: Receiver<String>,
}

impl Launch {
    pub fn start(file: &Path, envs: &[(&str, &str)]) -> Launch {
        Self::start_with(file, &[], envs)
    }

    /// `rpkm launch FILE ARGS...` (launch arguments `name:=value`).
    pub fn start_with(file: &Path, args: &[&str], envs: &[(&str, &str)]) -> Launch {
        let mut child = Command::new(rpkm())
            .arg("launch")
            .arg(file)
            .args(args)
            .envs(envs.iter().copied())
            .stderr(Stdio::piped())
            .spawn()
            .expect("start rpkm launch");
        let stderr = child.stderr.take().expect("piped");
        let log = Arc::new(Mutex::new(Vec::new()));
        let (tx, lines) = mpsc::channel();
        let log2 = Arc::clone(&log);
        std::thread::spawn(move || {
            for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                eprintln!("{line}");
                if let Ok(mut l) = log2.lock() {
                    l.push(line.clone());
                }
                let _ = tx.send(line);
            }
        });
        Launch { child, log, lines }
    }

    /// Waits for a stderr line containing `needle`.
    pub fn wait_for(&self, needle: &str, timeout: Duration) -> String {
        let deadline = Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.lines.recv_timeout(left) {
                Ok(l) if l.contains(needle) => return l,
                Ok(_) => {}
                Err(e) => panic!("no line with {needle:?} within {timeout:?}: {e}"),
            }
        }
    }

    /// Pids of `[launch] started NAME pid PID` lines so far.
    pub fn started(&self, name: &str) -> Vec<u32> {
        let prefix = format!("[launch] started {name} pid ");
        self.log
            .lock()
            .map(|l| {
                l.iter()
                    .filter_map(|s| {
                        let at = s.find(&prefix)? + prefix.len();
                        let digits: String =
                            s[at..].chars().take_while(char::is_ascii_digit).collect();
                        digits.parse().ok()
                    })
                    .collect()
            })
            .unwrap_or_default()
    }

    pub fn stop(&mut self) {
        if let Ok(Some(_)) = self.child.try_wait() {
            return;
        }
        if let Ok(pid) = i32::try_from(self.child.id()) {
            let _ = Command::new("kill")
                .args(["-TERM", &pid.to_string()])
                .status();
        }
        let deadline = Instant::now() + Duration::from_secs(10);
        while Instant::now() < deadline {
            if let Ok(Some(_)) = self.child.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for Launch {
    fn drop(&mut self) {
        self.stop();
    }
}

/// A temporary folder removed on drop.
pub struct TempDir(pub PathBuf);

/// Writes the launch file `name` in `dir`: ingest replaying `source`, then `nodes`, each node
/// with its parameters from the folder's params.yaml; its path.
pub fn launch_from_params(dir: &TempDir, name: &str, source: &Path, nodes: &[&str]) -> PathBuf {
    let mut text = format!(
        "launch:\n  - node: {{pkg: rpkm, exec: ingest, param: [{{from: params.yaml}}], args: \
         --source {}}}\n",
        source.display()
    );
    for node in nodes {
        let _ = writeln!(
            text,
            "  - node: {{pkg: rpkm, exec: {node}, param: [{{from: params.yaml}}]}}"
        );
    }
    let launch = dir.path(name);
    std::fs::write(&launch, text).expect("launch file");
    launch
}

impl TempDir {
    pub fn new(tag: &str) -> TempDir {
        let p = std::env::temp_dir().join(unique(tag));
        std::fs::create_dir_all(&p).expect("temp dir");
        TempDir(p)
    }
    pub fn path(&self, name: &str) -> PathBuf {
        self.0.join(name)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// The test venv's Python (the independent peers: Cyclone DDS, readers); `None` skips with a
/// word, except under `RPKM_REQUIRE_PYTHON` (CI), where it must be there.
pub fn python() -> Option<PathBuf> {
    let py = Path::new(env!("CARGO_MANIFEST_DIR")).join(".venv/bin/python");
    if py.exists() {
        return Some(py);
    }
    assert!(
        std::env::var_os("RPKM_REQUIRE_PYTHON").is_none(),
        "RPKM_REQUIRE_PYTHON is set but {} is missing",
        py.display()
    );
    eprintln!(
        "SKIPPED: {} not found; create it with `python3 -m venv .venv && \
         .venv/bin/pip install -r tests/python/requirements.txt`",
        py.display()
    );
    None
}

/// A child process stopped with SIGTERM (its clean shutdown) when the test lets go of it,
/// killed where it has not ended 5 s later (a test never hangs on a node that will not stop).
pub struct Proc(pub Child);

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = Command::new("kill")
            .args(["-TERM", &self.0.id().to_string()])
            .status();
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(5);
        while std::time::Instant::now() < deadline {
            if let Ok(Some(_)) = self.0.try_wait() {
                return;
            }
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// The first message on `sub` within `within`; fails naming `what` with the launch's log.
pub fn first_message<T: rpkm_transport::IpcMessage>(
    sub: &rpkm_transport::Subscriber<T>,
    launched: &Launch,
    what: &str,
    within: std::time::Duration,
) -> T {
    let deadline = std::time::Instant::now() + within;
    loop {
        if let Some(m) = sub.try_recv().expect("recv") {
            return m;
        }
        assert!(
            std::time::Instant::now() < deadline,
            "no {what} within {} s: {:?}",
            within.as_secs(),
            launched.log.lock().map(|l| l.clone()).unwrap_or_default()
        );
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
}
