//! `rpkm monitor`: a live terminal view of a running node set, or of a bag replayed into it.
//! A receiving thread drains every rpkm topic into a [`Watch`]; the screen is drawn from it
//! ten times a second. The receiver never waits for the terminal, so a slow terminal cannot
//! hold up a reliable publisher (a node) behind the monitor's queues.

use std::io::{IsTerminal, Write};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use ratatui::backend::TestBackend;
use ratatui::crossterm::event::{self, Event, KeyCode, KeyEventKind, KeyModifiers};
use ratatui::Terminal;
use rpkm_transport::{topic, IpcMessage, Subscriber, Transport, TransportError};

use super::transport_args::{stop_flag, TransportArgs};
use crate::monitor::{draw, MonitorThresholds, ThresholdSource, Watch, WatchConfig};
use rpkm_nodes::node::params::NodeParams;
use rpkm_nodes::topics::Delivery;

/// Watch a running node set: per drive the measured and predicted redundancy current as bars
/// against preload_monitor's WARN/ERROR thresholds, the level history, Δq2/Δq3 in follower
/// mode, the TCP estimate rate, latency and fallbacks, /diagnostics of every node, the
/// calibrator's last Parameters and Diagnosis. A node that was heard and then says nothing
/// (no topic, no /diagnostics) for --silent-after seconds (or 1.5 of its report periods) is
/// named SILENT at the top. `q`, Esc or Ctrl-C quit and restore the terminal.
///
/// Thresholds: those preload_monitor names in its /diagnostics reports, or those a parameter
/// file gives it (`--params`, the file the node was started with).
#[derive(clap::Args, Debug, Clone)]
#[command(after_help = "Examples:\n  \
rpkm launch launch_scripts/rpkm.launch.yaml source:=campaign.csv &\n  \
rpkm monitor                                   # the launched set, over iceoryx2\n  \
rpkm monitor --backend dds                     # a set (or ros2 bag play) on DDS\n  \
rpkm monitor --ipc-prefix cell2 --params launch_scripts/params.yaml\n  \
rpkm replay bags/preload_fault --rate 0.5      # in another terminal: watch a recording\n  \
rpkm monitor --once --json --window 3          # one JSON snapshot after 3 s, for scripts\n  \
rpkm monitor --once                            # the same as text (the screen, 120x48)")]
pub struct MonitorArgs {
    #[command(flatten)]
    pub transport: TransportArgs,
    /// ROS 2 parameter file(s) of preload_monitor: its WARN/ERROR thresholds before (and
    /// instead of) those its /diagnostics report.
    #[arg(long)]
    pub params: Vec<PathBuf>,
    /// Seconds without a topic or /diagnostics of a node before it is named silent.
    #[arg(long, default_value_t = 1.0)]
    pub silent_after: f64,
    /// Print one snapshot after --window seconds and exit (no terminal needed).
    #[arg(long)]
    pub once: bool,
    /// With --once: the snapshot as JSON (SI units as on the topics, currents in %).
    #[arg(long, requires = "once")]
    pub json: bool,
    /// With --once: seconds to collect before the snapshot.
    #[arg(long, default_value_t = 2.0)]
    pub window: f64,
    /// Redraw period of the live view, ms.
    #[arg(long, default_value_t = 100)]
    pub refresh_ms: u64,
}

pub fn run(args: &MonitorArgs) -> Result<()> {
    check_args(args)?;
    let thresholds = thresholds_from_params(&args.params)?;
    let config = WatchConfig {
        silent_after_s: args.silent_after,
        ..WatchConfig::default()
    };
    let mut watch = Watch::new(config, thresholds);
    let names = rpkm_transport::Names::new(&args.transport.namespace, &[])
        .map_err(|e| super::bad_input(format!("--namespace: {e}")))?;
    watch.in_namespace(&names);
    let watch = Arc::new(Mutex::new(watch));
    let stop = stop_flag()?;
    let start = Instant::now();
    let receiver = spawn_receiver(args, Arc::clone(&watch), Arc::clone(&stop), start)?;
    let source = source_text(args);
    let result = if args.once {
        once(args, &watch, &stop, start, &source)
    } else {
        live(args, &watch, &stop, start, &source)
    };
    stop.store(true, Ordering::Relaxed);
    let received = receiver
        .join()
        .map_err(|_| anyhow::anyhow!("the receiving thread of rpkm monitor panicked"))?;
    result.and(received)
}

fn check_args(args: &MonitorArgs) -> Result<()> {
    let positive = |v: f64, name: &str| {
        if v > 0.0 && v <= 3600.0 {
            Ok(())
        } else {
            Err(super::bad_input(format!(
                "--{name} {v}: expected seconds above 0 and at most 3600"
            )))
        }
    };
    positive(args.silent_after, "silent-after")?;
    positive(args.window, "window")?;
    if !(10..=5000).contains(&args.refresh_ms) {
        return Err(super::bad_input(format!(
            "--refresh-ms {}: expected 10 to 5000 ms",
            args.refresh_ms
        )));
    }
    if !args.once && !std::io::stdout().is_terminal() {
        return Err(super::bad_input(
            "rpkm monitor draws on a terminal and standard output is not one; \
             `rpkm monitor --once --json` prints a snapshot for scripts"
                .into(),
        ));
    }
    Ok(())
}

/// preload_monitor's thresholds as a node started with `files` takes them (its defaults
/// where the files say nothing); unknown without files.
fn thresholds_from_params(files: &[PathBuf]) -> Result<MonitorThresholds> {
    if files.is_empty() {
        return Ok(MonitorThresholds::unknown());
    }
    let p = NodeParams::load("preload_monitor", files, &[]).map_err(rpkm_nodes::node::bad_param)?;
    let d = rpkm_nodes::node::preload_monitor::Thresholds::default();
    let read = |key: &str, default: f64| {
        p.positive(key, default)
            .map_err(rpkm_nodes::node::bad_param)
    };
    let names: Vec<String> = files.iter().map(|f| f.display().to_string()).collect();
    Ok(MonitorThresholds {
        warn_percent: read("warn_percent", d.warn_percent)?,
        error_percent: read("error_percent", d.error_percent)?,
        dq_m: Some((
            read("dq_warn_m", d.dq_warn_m)?,
            read("dq_error_m", d.dq_error_m)?,
        )),
        source: ThresholdSource::ParamsFile(names.join(", ")),
    })
}

fn source_text(args: &MonitorArgs) -> String {
    let prefix = args
        .transport
        .ipc_prefix
        .clone()
        .or_else(|| std::env::var("RPKM_IPC_PREFIX").ok())
        .unwrap_or_default();
    match args.transport.backend {
        rpkm_transport::Backend::Dds => "dds".to_owned(),
        rpkm_transport::Backend::Ipc => format!("ipc prefix {prefix:?}"),
        rpkm_transport::Backend::Both => format!("ipc prefix {prefix:?} (publishing on dds too)"),
    }
}

/// Locks the watch; a panic elsewhere while it was held leaves plain data, still readable.
fn lock(watch: &Mutex<Watch>) -> std::sync::MutexGuard<'_, Watch> {
    watch.lock().unwrap_or_else(PoisonError::into_inner)
}

/// `--once`: collect for the window, print the snapshot.
fn once(
    args: &MonitorArgs,
    watch: &Mutex<Watch>,
    stop: &AtomicBool,
    start: Instant,
    source: &str,
) -> Result<()> {
    let end = start + Duration::from_secs_f64(args.window);
    while Instant::now() < end && !stop.load(Ordering::Relaxed) {
        std::thread::sleep(Duration::from_millis(20));
    }
    let now = start.elapsed().as_secs_f64();
    let mut w = lock(watch);
    w.tick(now);
    let text = if args.json {
        serde_json::to_string_pretty(&w.snapshot(now))? + "\n"
    } else {
        let mut term = Terminal::new(TestBackend::new(120, 48))?;
        let frame = term.draw(|f| draw::frame(f, &w, now, source))?;
        draw::to_text(frame.buffer)
    };
    drop(w);
    let mut out = std::io::stdout().lock();
    out.write_all(text.as_bytes())
        .and_then(|()| out.flush())
        .context("writing the snapshot to standard output")
}

/// The live view until `q`, Esc, Ctrl-C, SIGINT or SIGTERM.
fn live(
    args: &MonitorArgs,
    watch: &Mutex<Watch>,
    stop: &AtomicBool,
    start: Instant,
    source: &str,
) -> Result<()> {
    // try_init: raw mode, alternate screen, and a panic hook that restores the terminal.
    let mut term = ratatui::try_init().context("setting up the terminal")?;
    let refresh = Duration::from_millis(args.refresh_ms);
    let result = (|| -> Result<()> {
        while !stop.load(Ordering::Relaxed) {
            let now = start.elapsed().as_secs_f64();
            term.draw(|f| {
                let mut w = lock(watch);
                w.tick(now);
                draw::frame(f, &w, now, source);
            })?;
            if event::poll(refresh)? && quits(&event::read()?) {
                break;
            }
        }
        Ok(())
    })();
    ratatui::try_restore().context("restoring the terminal")?;
    result
}

fn quits(e: &Event) -> bool {
    let Event::Key(k) = e else { return false };
    k.kind == KeyEventKind::Press
        && (matches!(k.code, KeyCode::Char('q' | 'Q') | KeyCode::Esc)
            || (k.code == KeyCode::Char('c') && k.modifiers.contains(KeyModifiers::CONTROL)))
}

/// Starts the thread that opens the transport and drains every topic into `watch`; returns
/// once the subscribers are open (or with the error that prevented it).
fn spawn_receiver(
    args: &MonitorArgs,
    watch: Arc<Mutex<Watch>>,
    stop: Arc<AtomicBool>,
    start: Instant,
) -> Result<std::thread::JoinHandle<Result<()>>> {
    let transport_args = args.transport.clone();
    let (ready_tx, ready_rx) = mpsc::channel::<Result<()>>();
    let handle = std::thread::Builder::new()
        .name("rpkm-monitor-rx".into())
        .spawn(move || {
            // Unique: several monitors may watch one set.
            let name = format!("rpkm_monitor_{}", std::process::id());
            let ports = transport_args
                .open(&name, "/rpkm/monitor")
                .and_then(|t| Ports::open(t, &transport_args));
            let mut ports = match ports {
                Ok(p) => {
                    let _ = ready_tx.send(Ok(()));
                    p
                }
                Err(e) => {
                    let _ = ready_tx.send(Err(e));
                    return Ok(());
                }
            };
            while !stop.load(Ordering::Relaxed) {
                if ports.drain(&watch, start) == 0 {
                    std::thread::sleep(IDLE_SLEEP);
                }
            }
            Ok(())
        })
        .context("starting the receiving thread")?;
    match ready_rx.recv() {
        Ok(Ok(())) => Ok(handle),
        Ok(Err(e)) => Err(e),
        Err(_) => Err(anyhow::anyhow!(
            "the receiving thread ended before it opened the topics"
        )),
    }
}

/// Sleep of the receiving thread after a sweep that found nothing: at 8 kHz half a
/// millisecond is four states, far below the queue depths.
const IDLE_SLEEP: Duration = Duration::from_micros(500);
/// Samples taken from one topic per sweep, so that one busy topic cannot starve the others.
const BATCH: usize = 512;

/// The subscribers of every rpkm topic.
struct Ports {
    _transport: Transport,
    state: Subscriber<rpkm_msgs::ActuatorState>,
    estimate: Subscriber<rpkm_msgs::TcpEstimate>,
    preload: Subscriber<rpkm_msgs::PreloadStatus>,
    measurement: Subscriber<rpkm_msgs::TcpMeasurement>,
    campaign: Subscriber<rpkm_msgs::CampaignInfo>,
    parameters: Subscriber<rpkm_msgs::Parameters>,
    diagnosis: Subscriber<rpkm_msgs::Diagnosis>,
    diagnostics: Subscriber<rpkm_msgs::DiagnosticArray>,
}

impl Ports {
    fn open(t: Transport, args: &TransportArgs) -> Result<Self> {
        fn sub<T: IpcMessage>(
            t: &Transport,
            topic: rpkm_transport::Topic<T>,
            delivery: Delivery,
        ) -> Result<Subscriber<T>> {
            let topic = delivery.topic(topic);
            t.subscriber(&topic)
                .with_context(|| format!("subscribing to {}", topic.name()))
        }
        let r = args.delivery();
        Ok(Self {
            state: sub(&t, topic::ACTUATOR_STATE, r)?,
            estimate: sub(&t, topic::TCP_ESTIMATE, r)?,
            preload: sub(&t, topic::PRELOAD_STATUS, r)?,
            measurement: sub(&t, topic::TCP_MEASUREMENT, r)?,
            campaign: sub(&t, topic::CAMPAIGN_INFO, r)?,
            parameters: sub(&t, topic::PARAMETERS, r)?,
            diagnosis: sub(&t, topic::DIAGNOSIS, r)?,
            diagnostics: sub(&t, topic::DIAGNOSTICS, r)?,
            _transport: t,
        })
    }

    /// One sweep over every topic, the watch locked once; returns how many messages came.
    fn drain(&mut self, watch: &Mutex<Watch>, start: Instant) -> usize {
        let mut w = lock(watch);
        let w = &mut *w;
        // Each message gets its own receive time: the latency is state → estimate received.
        let t = || start.elapsed().as_secs_f64();
        let mut n = 0;
        let mut errors = Vec::new();
        n += take(&self.state, &mut errors, |m| w.on_state(&m, t()));
        n += take(&self.estimate, &mut errors, |m| w.on_estimate(&m, t()));
        n += take(&self.preload, &mut errors, |m| w.on_preload(&m, t()));
        n += take(&self.measurement, &mut errors, |m| {
            w.on_measurement(&m, t());
        });
        n += take(&self.campaign, &mut errors, |m| w.on_campaign(m));
        n += take(&self.parameters, &mut errors, |m| w.on_parameters(m, t()));
        n += take(&self.diagnosis, &mut errors, |m| w.on_diagnosis(m, t()));
        n += take(&self.diagnostics, &mut errors, |m| w.on_diagnostics(m, t()));
        let now = t();
        for e in errors {
            w.on_receive_error(e, now);
        }
        n
    }
}

/// Up to [`BATCH`] queued samples of one topic into `f`. A sample that cannot be received
/// is not skipped silently: its error, naming the topic, goes into `errors` (shown on screen).
fn take<T: IpcMessage>(
    sub: &Subscriber<T>,
    errors: &mut Vec<String>,
    mut f: impl FnMut(T),
) -> usize {
    let mut n = 0;
    while n < BATCH {
        match sub.try_recv() {
            Ok(Some(m)) => f(m),
            Ok(None) => break,
            Err(e) => {
                errors.push(receive_error(sub.topic(), &e));
                break;
            }
        }
        n += 1;
    }
    n
}

fn receive_error(topic: &str, e: &TransportError) -> String {
    format!("receiving {topic}: {e}")
}
