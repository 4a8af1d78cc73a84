//! `rpkm bench soak`: the launched node set under an 8 kHz actuator stream for minutes.
//!
//! The shipped launch file runs with `source:=stdin`; this command is the controller: it
//! writes a twin stream (the 100 mm circle, one turn per 2 s, q2 and q3 following) into
//! ingest's standard input at the stream rate, row by row on a clock. It subscribes to
//! `/rpkm/tcp_estimate` and counts what arrives per seq (ingest numbers the states it
//! publishes 1, 2, ...; an estimate echoes its state's seq): lost estimates and their gaps,
//! and, from `/diagnostics`, the gaps the estimator and the monitor saw in their input, so
//! that a loss is placed at its hop. The resident memory of every process of the launch is
//! read from /proc at the start, at each quarter and at the end.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use rpkm_msgs::{ActuatorState, DiagnosticArray, DiagnosticStatus, TcpEstimate};
use rpkm_transport::{topic, Subscriber, Transport, TransportConfig};
use rpkm_twin::{Twin, TwinConfig};

use crate::cli::bad_input;
use rpkm_nodes::node::inputs::SeqGaps;
use rpkm_nodes::stream::{StreamPath, StreamSpec, CIRCLE_PERIOD_S};

#[derive(clap::Args, Debug)]
pub struct SoakArgs {
    /// Length of the stream, s.
    #[arg(long, default_value_t = 180.0)]
    pub seconds: f64,
    /// Stream rate, Hz.
    #[arg(long, default_value_t = 8000.0)]
    pub rate_hz: f64,
    /// The launch file; its ingest must take `--source $(var source)`.
    #[arg(long, default_value = "launch_scripts/rpkm.launch.yaml")]
    pub launch: PathBuf,
    /// More launch arguments, NAME:=VALUE (e.g. backend:=both).
    #[arg(long = "arg")]
    pub args: Vec<String>,
}

/// The nodes that must report on /diagnostics before the stream starts.
const NODES: [&str; 4] = ["ingest", "tcp_estimator", "calibrator", "preload_monitor"];
/// Time for the launch to bring its nodes up.
const STARTUP: Duration = Duration::from_secs(30);
/// After the last row: how long the estimates may take to drain.
const DRAIN: Duration = Duration::from_secs(10);

pub fn run(a: &SoakArgs) -> Result<()> {
    let n = a.seconds * a.rate_hz;
    if !(a.seconds > 0.0 && a.rate_hz > 0.0 && (1.0..=1e9).contains(&n)) {
        return Err(bad_input(format!(
            "--seconds {} --rate-hz {}: expected positive numbers giving 1 to 10^9 samples",
            a.seconds, a.rate_hz
        )));
    }
    if !a.launch.is_file() {
        return Err(bad_input(format!(
            "{}: no such launch file (run from the repository root or give --launch)",
            a.launch.display()
        )));
    }
    let rows = Rows::circle(a.rate_hz)?;
    let total = rpkm_core::convert::round_u64(n);
    let prefix = format!("soak_{}", std::process::id());
    let observer = Transport::new(&TransportConfig::new("soak_observer").ipc_prefix(&prefix))?;
    let estimates = observer.subscriber(&topic::TCP_ESTIMATE)?;
    let diagnostics = observer.subscriber(&topic::DIAGNOSTICS)?;
    let mut launch = Launched::start(&a.launch, &a.args, &prefix)?;
    let result = soak(a, &rows, total, &mut launch, &estimates, &diagnostics);
    launch.stop();
    let (tally, rss) = result?;
    tally.print(a, total);
    rss.print();
    if tally.gaps.lost > 0 || tally.received < total {
        anyhow::bail!(
            "{} of {total} estimates lost",
            total.saturating_sub(tally.received)
        );
    }
    Ok(())
}

/// Waits for the nodes, streams, drains; returns what arrived and the memory samples.
fn soak(
    a: &SoakArgs,
    rows: &Rows,
    total: u64,
    launch: &mut Launched,
    estimates: &Subscriber<TcpEstimate>,
    diagnostics: &Subscriber<DiagnosticArray>,
) -> Result<(Tally, Rss)> {
    let mut tally = Tally::default();
    let up = Instant::now();
    while NODES.iter().any(|n| !tally.last_status.contains_key(*n)) {
        if up.elapsed() > STARTUP {
            anyhow::bail!(
                "the launch did not bring up {NODES:?} within {STARTUP:?} (seen: {:?})",
                tally.last_status.keys().collect::<Vec<_>>()
            );
        }
        launch.check_alive()?;
        tally.drain_diagnostics(diagnostics)?;
        std::thread::sleep(Duration::from_millis(20));
    }
    let mut rss = Rss::default();
    rss.sample("start", launch.pid());
    let mut writer = Writer::new(launch.stdin()?, rows, total, a.rate_hz);
    let quarter = Duration::from_secs_f64(a.seconds / 4.0);
    let mut next_sample = 1u32;
    let mut drained_since: Option<Instant> = None;
    loop {
        let more = writer.write_due()?;
        tally.drain_estimates(estimates)?;
        tally.drain_diagnostics(diagnostics)?;
        if next_sample < 4 && writer.started.elapsed() >= quarter * next_sample {
            rss.sample(
                ["", "25 %", "50 %", "75 %"][next_sample as usize],
                launch.pid(),
            );
            next_sample += 1;
        }
        if more {
            estimates.wait(writer.until_due())?;
            continue;
        }
        let since = *drained_since.get_or_insert_with(Instant::now);
        if tally.last >= Some(total) || since.elapsed() > DRAIN {
            break;
        }
        estimates.wait(Duration::from_millis(5))?;
    }
    rss.sample("end", launch.pid());
    // The nodes' counters after the last state: one more report period.
    let reported = Instant::now();
    tally.last_status.clear();
    while reported.elapsed() < Duration::from_secs(3)
        && ["tcp_estimator", "preload_monitor"]
            .iter()
            .any(|n| !tally.last_status.contains_key(*n))
    {
        tally.drain_diagnostics(diagnostics)?;
        std::thread::sleep(Duration::from_millis(20));
    }
    Ok((tally, rss))
}

/// One period of the twin's circle as campaign rows without their time, repeated.
struct Rows {
    header: String,
    /// Each row after its `t` field.
    rest: Vec<String>,
}

impl Rows {
    fn circle(rate_hz: f64) -> Result<Self> {
        let twin = Twin::new(TwinConfig {
            noise: None,
            ..TwinConfig::default()
        })?;
        let spec = StreamSpec {
            hz: rate_hz,
            seconds: CIRCLE_PERIOD_S,
            motion: StreamPath::Circle,
            fault: None,
            start_s: 0.0,
            first_seq: 1,
        };
        let mut rest = Vec::new();
        rpkm_nodes::stream::run(&twin, &spec, |_, s| {
            rest.push(row_after_t(s));
            Ok(())
        })?;
        Ok(Self {
            header: "t,setup,instrument,reset,q1,q2,q3,q4,f1,f2,f3,f4,follower,x,y,r,psi,\
                     temp_machine"
                .into(),
            rest,
        })
    }

    /// Row `k` (0-based) of the stream, time 1 s + k / rate.
    fn line(&self, k: u64, rate_hz: f64) -> String {
        let t = 1.0 + k as f64 / rate_hz;
        let rest = &self.rest[usize::try_from(k).unwrap_or(0) % self.rest.len()];
        format!("{t},{rest}\n")
    }
}

/// `setup,instrument,reset,q1..q4 (mm),f1..f4,follower,x,y,r,psi,temp_machine` of a state.
fn row_after_t(s: &ActuatorState) -> String {
    let q = rpkm_nodes::units::drive_positions_mm(s);
    let follower: String = (b'1'..=b'4')
        .zip(s.follower)
        .filter_map(|(digit, on)| on.then_some(char::from(digit)))
        .collect();
    let temp = s.covariates[0];
    format!(
        "soak,none,0,{},{},{},{},{},{},{},{},{follower},,,,,{temp}",
        q[0], q[1], q[2], q[3], s.force[0], s.force[1], s.force[2], s.force[3]
    )
}

/// When row `k` is due after the stream's start.
fn due(k: u64, rate_hz: f64) -> Duration {
    Duration::from_secs_f64(k as f64 / rate_hz)
}

/// The controller: rows into ingest's stdin on a clock.
struct Writer<'a> {
    /// `None` once closed.
    out: Option<std::io::BufWriter<ChildStdin>>,
    rows: &'a Rows,
    total: u64,
    rate_hz: f64,
    next: u64,
    started: Instant,
}

impl<'a> Writer<'a> {
    fn new(stdin: ChildStdin, rows: &'a Rows, total: u64, rate_hz: f64) -> Self {
        Self {
            out: Some(std::io::BufWriter::new(stdin)),
            rows,
            total,
            rate_hz,
            next: 0,
            started: Instant::now(),
        }
    }

    fn due(&self, k: u64) -> Duration {
        due(k, self.rate_hz)
    }

    /// Writes every row due by now (the header first); false once all are written (stdin is
    /// then closed: ingest sends its end marker).
    fn write_due(&mut self) -> Result<bool> {
        let Some(out) = self.out.as_mut() else {
            return Ok(false);
        };
        if self.next == 0 {
            writeln!(out, "{}", self.rows.header)?;
        }
        let now = self.started.elapsed();
        while self.next < self.total && due(self.next, self.rate_hz) <= now {
            out.write_all(self.rows.line(self.next, self.rate_hz).as_bytes())?;
            self.next += 1;
        }
        out.flush().context("writing to ingest's stdin")?;
        if self.next >= self.total {
            // Closing stdin is ingest's end of input.
            self.out = None;
            return Ok(false);
        }
        Ok(true)
    }

    /// Time until the next row is due.
    fn until_due(&self) -> Duration {
        self.due(self.next)
            .saturating_sub(self.started.elapsed())
            .max(Duration::from_micros(50))
    }
}

/// What arrived.
#[derive(Default)]
struct Tally {
    received: u64,
    /// Gaps between the estimates received (the ones before the first and after the last
    /// are in `total − received`).
    gaps: SeqGaps,
    first: Option<u64>,
    last: Option<u64>,
    /// By outcome: OK, WARM_REJECTED_COLD_OK, RIGID_FALLBACK.
    outcomes: [u64; 3],
    last_status: BTreeMap<String, DiagnosticStatus>,
}

impl Tally {
    fn drain_estimates(&mut self, sub: &Subscriber<TcpEstimate>) -> Result<()> {
        while let Some(e) = sub.try_recv()? {
            self.received += 1;
            self.gaps.next(e.seq);
            self.first.get_or_insert(e.seq);
            self.last = Some(e.seq);
            let k = usize::from(e.outcome.min(2));
            self.outcomes[k] += 1;
        }
        Ok(())
    }

    fn drain_diagnostics(&mut self, sub: &Subscriber<DiagnosticArray>) -> Result<()> {
        while let Some(a) = sub.try_recv()? {
            for st in a.status {
                let node = st.name.rsplit('/').next().unwrap_or_default().to_owned();
                self.last_status.insert(node, st);
            }
        }
        Ok(())
    }

    fn value(&self, node: &str, key: &str) -> String {
        self.last_status
            .get(node)
            .and_then(|s| s.values.iter().find(|v| v.key == key))
            .map_or_else(|| "?".into(), |v| v.value.clone())
    }

    fn print(&self, a: &SoakArgs, total: u64) {
        let lost = total.saturating_sub(self.received);
        println!(
            "soak: {} s at {} Hz through {}: {total} states written to ingest",
            a.seconds,
            a.rate_hz,
            a.launch.display()
        );
        println!(
            "estimates received: {} of {total}; lost {lost} ({:.4} %): {} in {} gaps (largest \
             {}), seq {:?} to {:?} received",
            self.received,
            lost as f64 / total as f64 * 100.0,
            self.gaps.lost,
            self.gaps.gaps,
            self.gaps.largest,
            self.first,
            self.last
        );
        println!(
            "outcomes: {} ok, {} warm rejected (cold ok), {} rigid fallback",
            self.outcomes[0], self.outcomes[1], self.outcomes[2]
        );
        for node in ["tcp_estimator", "preload_monitor"] {
            println!(
                "{node} input: {} states lost in {} gaps (largest {})",
                self.value(node, "input_lost"),
                self.value(node, "input_gaps"),
                self.value(node, "largest_input_gap")
            );
        }
    }
}

/// Resident memory of the launch's processes at named moments.
#[derive(Default)]
struct Rss {
    moments: Vec<&'static str>,
    /// process name → RSS in kB per moment (absent: not running then).
    by_process: BTreeMap<String, Vec<Option<u64>>>,
}

impl Rss {
    fn sample(&mut self, moment: &'static str, launch_pid: u32) {
        let i = self.moments.len();
        self.moments.push(moment);
        let mut procs = vec![(launch_pid, "launch".to_owned())];
        procs.extend(children(launch_pid));
        procs.push((std::process::id(), "soak (observer)".to_owned()));
        for (pid, name) in procs {
            let col = self.by_process.entry(name).or_default();
            col.resize(i + 1, None);
            col[i] = rss_kb(pid);
        }
    }

    fn print(&self) {
        print!("{:<18}", "RSS MB");
        for m in &self.moments {
            print!("{m:>9}");
        }
        println!();
        for (name, col) in &self.by_process {
            print!("{name:<18}");
            for i in 0..self.moments.len() {
                match col.get(i).copied().flatten() {
                    Some(kb) => print!("{:>9.1}", kb as f64 / 1024.0),
                    None => print!("{:>9}", "-"),
                }
            }
            println!();
        }
    }
}

/// The child processes of `pid`, named by their `--name` (or their command).
fn children(pid: u32) -> Vec<(u32, String)> {
    let Ok(dir) = std::fs::read_dir("/proc") else {
        return Vec::new();
    };
    dir.filter_map(|e| e.ok()?.file_name().to_str()?.parse::<u32>().ok())
        .filter(|&p| parent(p) == Some(pid))
        .map(|p| (p, process_name(p)))
        .collect()
}

/// The parent pid from /proc/PID/stat (the field after the parenthesised command).
fn parent(pid: u32) -> Option<u32> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    let after = &stat[stat.rfind(')')? + 1..];
    after.split_whitespace().nth(1)?.parse().ok()
}

fn process_name(pid: u32) -> String {
    let cmd = std::fs::read(format!("/proc/{pid}/cmdline")).unwrap_or_default();
    let args: Vec<String> = cmd
        .split(|b| *b == 0)
        .map(|a| String::from_utf8_lossy(a).into_owned())
        .collect();
    let after = |flag: &str| {
        args.iter()
            .position(|a| a == flag)
            .and_then(|i| args.get(i + 1))
            .cloned()
    };
    after("--name")
        .or_else(|| after("node"))
        .or_else(|| args.get(1).cloned())
        .unwrap_or_else(|| format!("pid {pid}"))
}

/// VmRSS of a process, kB.
fn rss_kb(pid: u32) -> Option<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let line = status.lines().find(|l| l.starts_with("VmRSS:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

/// `rpkm launch FILE source:=stdin ...` with its stdin piped; SIGTERM on stop.
struct Launched {
    child: Child,
}

impl Launched {
    fn start(file: &Path, args: &[String], prefix: &str) -> Result<Self> {
        let exe = std::env::current_exe().context("the rpkm executable")?;
        let child = Command::new(exe)
            .arg("launch")
            .arg(file)
            .arg("source:=stdin")
            .args(args)
            .env("RPKM_IPC_PREFIX", prefix)
            .stdin(Stdio::piped())
            .spawn()
            .context("starting rpkm launch")?;
        Ok(Self { child })
    }

    fn pid(&self) -> u32 {
        self.child.id()
    }

    fn stdin(&mut self) -> Result<ChildStdin> {
        self.child.stdin.take().context("the launch's stdin")
    }

    fn check_alive(&mut self) -> Result<()> {
        match self.child.try_wait()? {
            Some(status) => anyhow::bail!("rpkm launch ended before the stream: {status}"),
            None => Ok(()),
        }
    }

    fn stop(&mut self) {
        if let Ok(pid) = i32::try_from(self.child.id()) {
            // SAFETY: kill(2) on our own child's pid with a valid signal number.
            unsafe {
                libc::kill(pid, libc::SIGTERM);
            }
        }
        let _ = self.child.wait();
    }
}
