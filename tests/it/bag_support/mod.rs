//! Helpers of the bag tests (`bag_cli`, `bag_reference`): the `rpkm` binary, scratch folders,
//! the Python venv, and children whose stderr lines can be awaited.
#![allow(dead_code)] // each test file uses a different part

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc::{channel, Receiver, RecvTimeoutError};
use std::time::{Duration, Instant};

pub fn rpkm() -> Command {
    Command::new(env!("CARGO_BIN_EXE_rpkm"))
}

pub fn repo_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

pub fn reference_bag(name: &str) -> PathBuf {
    repo_root().join("bags").join(name)
}

/// A fresh, empty scratch folder per test and process.
pub fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("rpkm-bag-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch dir");
    dir
}

/// A unique iceoryx2 service prefix: services are global to the machine.
pub fn ipc_prefix(test: &str) -> String {
    format!("rpkmtest{}{test}", std::process::id())
}

/// Runs a command to completion; panics with its output if it fails.
pub fn run_ok(cmd: &mut Command) -> String {
    let out = cmd.output().expect("run rpkm");
    assert!(
        out.status.success(),
        "{cmd:?} failed ({}):\nstdout:\n{}\nstderr:\n{}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// The venv's Python (or `RPKM_PYTHON`); `None` skips, except under `RPKM_REQUIRE_PYTHON`
/// (CI), where a missing venv fails.
pub fn python() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("RPKM_PYTHON") {
        return Some(PathBuf::from(p));
    }
    let venv = repo_root().join(".venv/bin/python");
    assert!(
        venv.is_file() || std::env::var_os("RPKM_REQUIRE_PYTHON").is_none(),
        "RPKM_REQUIRE_PYTHON is set but {} is missing",
        venv.display()
    );
    venv.is_file().then_some(venv)
}

/// A child process whose stderr is read line by line on a thread.
pub struct Watched {
    pub child: Child,
    lines: Receiver<String>,
    pub seen: Vec<String>,
}

impl Watched {
    pub fn spawn(cmd: &mut Command) -> Self {
        let mut child = cmd
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("spawn rpkm");
        let stderr = child.stderr.take().expect("piped stderr");
        let (tx, lines) = channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stderr).lines() {
                let Ok(line) = line else { break };
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        Self {
            child,
            lines,
            seen: Vec::new(),
        }
    }

    /// Waits up to `timeout` for a stderr line for which `pred` holds; returns it.
    pub fn wait_line(&mut self, timeout: Duration, pred: impl Fn(&str) -> bool) -> String {
        let deadline = Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.lines.recv_timeout(left) {
                Ok(line) => {
                    self.seen.push(line.clone());
                    if pred(&line) {
                        return line;
                    }
                }
                Err(RecvTimeoutError::Timeout) => panic!(
                    "no awaited line within {timeout:?}; stderr so far:\n{}",
                    self.seen.join("\n")
                ),
                Err(RecvTimeoutError::Disconnected) => panic!(
                    "process ended without the awaited line; stderr:\n{}",
                    self.seen.join("\n")
                ),
            }
        }
    }

    /// Takes the lines that arrived so far without waiting.
    pub fn drain(&mut self) {
        while let Ok(line) = self.lines.try_recv() {
            self.seen.push(line);
        }
    }

    /// Waits for the exit (bounded) and returns its status, with all stderr lines read.
    pub fn wait(&mut self, timeout: Duration) -> std::process::ExitStatus {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(status) = self.child.try_wait().expect("try_wait") {
                // The reader thread ends at EOF; collect what is left.
                while let Ok(line) = self.lines.recv_timeout(Duration::from_secs(2)) {
                    self.seen.push(line);
                }
                return status;
            }
            if Instant::now() >= deadline {
                let _ = self.child.kill();
                panic!(
                    "process still running after {timeout:?}; stderr:\n{}",
                    self.seen.join("\n")
                );
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    /// Sends SIGINT (a clean stop for `rpkm record`).
    pub fn interrupt(&self) {
        self.signal("INT");
    }

    /// Sends a signal by name (`INT`, `STOP`, ...).
    pub fn signal(&self, name: &str) {
        let status = Command::new("kill")
            .args([&format!("-{name}"), &self.child.id().to_string()])
            .status()
            .expect("run kill");
        assert!(status.success(), "kill -{name} failed");
    }
}

impl Drop for Watched {
    fn drop(&mut self) {
        // Never leave a child running when a test fails half-way.
        if matches!(self.child.try_wait(), Ok(None)) {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// All messages of one topic of a bag, decoded.
pub fn decode_all<T: rpkm_msgs::RosMessage>(bag: &Path, topic: &str) -> Vec<T> {
    let reader = rpkm_transport::bag::BagReader::open(bag)
        .unwrap_or_else(|e| panic!("open {}: {e}", bag.display()));
    reader
        .decode_topic::<T>(topic)
        .unwrap_or_else(|e| panic!("decode {topic} of {}: {e}", bag.display()))
        .into_iter()
        .map(|(_, m)| m)
        .collect()
}
