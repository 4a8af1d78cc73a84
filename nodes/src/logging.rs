//! The `log` records of rpkm's crates (the transport's warnings about dead subscribers, the
//! iceoryx2 clean-up of dead nodes) on stderr, so that nothing the libraries report is lost.
//!
//! `RPKM_LOG` sets the level for rpkm's own crates (`error`, `warn` (default), `info`,
//! `debug`, `trace`, `off`). The other crates (rustdds, ros2-client, iceoryx2) are quiet by
//! default: rustdds reports routine shutdown races as errors, iceoryx2 warns at every start
//! that it found no config file. From `info` on they report warnings.

use std::sync::OnceLock;

use log::{Level, LevelFilter, Log, Metadata, Record};

/// Where a node sends the records it also writes to stderr: `/rosout`.
type Sink = Box<dyn Fn(Level, &str, &str, u32) + Send + Sync>;
static FORWARD: OnceLock<Sink> = OnceLock::new();

/// Sends every record written to stderr from now on to `sink` as well (a node's `/rosout`);
/// the first sink of the process stays.
pub fn forward(sink: Sink) {
    let _ = FORWARD.set(sink);
}

struct StderrLog {
    rpkm: LevelFilter,
    others: LevelFilter,
}

impl StderrLog {
    fn limit(&self, target: &str) -> LevelFilter {
        if target.starts_with("rpkm") {
            self.rpkm
        } else {
            self.others
        }
    }
}

impl Log for StderrLog {
    fn enabled(&self, m: &Metadata) -> bool {
        m.level() <= self.limit(m.target())
    }

    fn log(&self, r: &Record) {
        if self.enabled(r.metadata()) {
            let level = match r.level() {
                Level::Error => "error",
                Level::Warn => "warning",
                Level::Info => "info",
                Level::Debug => "debug",
                Level::Trace => "trace",
            };
            eprintln!("rpkm {level} [{}]: {}", r.target(), r.args());
            // rpkm's own records only: ros2-client reports each /rosout record again through
            // its logging, which would come back here.
            if let Some(sink) = FORWARD.get().filter(|_| r.target().starts_with("rpkm")) {
                let text = format!("[{}] {}", r.target(), r.args());
                sink(
                    r.level(),
                    &text,
                    r.file().unwrap_or(""),
                    r.line().unwrap_or(0),
                );
            }
        }
    }

    fn flush(&self) {}
}

/// Installs the stderr logger; an unknown `RPKM_LOG` value falls back to `warn` and says so.
pub fn init() {
    let value = std::env::var("RPKM_LOG").unwrap_or_default();
    let rpkm = match value.to_ascii_lowercase().as_str() {
        "" | "warn" => LevelFilter::Warn,
        "error" => LevelFilter::Error,
        "info" => LevelFilter::Info,
        "debug" => LevelFilter::Debug,
        "trace" => LevelFilter::Trace,
        "off" => LevelFilter::Off,
        other => {
            eprintln!("rpkm: RPKM_LOG={other:?} is not one of error, warn, info, debug, trace, off; using warn");
            LevelFilter::Warn
        }
    };
    let others = if rpkm >= LevelFilter::Info {
        LevelFilter::Warn
    } else {
        LevelFilter::Off
    };
    if log::set_boxed_logger(Box::new(StderrLog { rpkm, others })).is_ok() {
        log::set_max_level(rpkm.max(others));
    }
    // iceoryx2 logs to the console by itself (a warning at every start that no config file
    // was found): its records go through this logger too, quiet like the other crates'.
    rpkm_transport::ipc::route_iceoryx2_log();
}
