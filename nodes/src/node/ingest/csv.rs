//! The CSV sources, `stdin` and a campaign file: every line goes through the core's
//! [`CampaignReader`], the grammar and rules `rpkm calibrate` reads files with, so that both
//! reject the same rows with the same message; the poses are published, the rejects counted
//! and logged, and the node reads on after a bad line.

use std::io::BufRead;
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::time::{Duration, Instant};

use rpkm_core::campaign::{Campaign, CampaignError, CampaignReader};

use super::output::Output;
use super::validate::{reject, Reject, RejectKind};
use crate::node::shutdown;

/// What a CSV source gives the loop next.
pub(super) enum Next {
    /// One line, without its `\n`.
    Line(Vec<u8>),
    /// Nothing yet (a live stream): report, check for shutdown, ask again.
    Idle,
    /// The end of the input.
    End,
}

/// A source of CSV lines.
pub(super) trait Lines {
    fn next(&mut self) -> Next;
}

/// Lines of stdin, read on a thread so that the loop reports and stops while it waits.
pub(super) struct Stdin {
    rx: Receiver<Vec<u8>>,
}

impl Stdin {
    pub(super) fn spawn(node: &str) -> Self {
        let (tx, rx) = mpsc::channel();
        let node = node.to_owned();
        std::thread::spawn(move || {
            let mut stdin = std::io::stdin().lock();
            loop {
                let mut line = Vec::new();
                match stdin.read_until(b'\n', &mut line) {
                    Ok(0) => break,
                    Ok(_) => {
                        if line.last() == Some(&b'\n') {
                            line.pop();
                        }
                        if tx.send(line).is_err() {
                            break;
                        }
                    }
                    Err(e) => {
                        crate::node::log_line(&node, format_args!("stdin: {e}; end of input"));
                        break;
                    }
                }
            }
        });
        Self { rx }
    }
}

impl Lines for Stdin {
    fn next(&mut self) -> Next {
        match self.rx.recv_timeout(Duration::from_millis(20)) {
            Ok(line) => Next::Line(line),
            Err(RecvTimeoutError::Timeout) => Next::Idle,
            Err(RecvTimeoutError::Disconnected) => Next::End,
        }
    }
}

/// The lines of a file read whole.
pub(super) struct FileLines<'a> {
    lines: std::slice::Split<'a, u8, fn(&u8) -> bool>,
}

impl<'a> FileLines<'a> {
    pub(super) fn new(bytes: &'a [u8]) -> Self {
        let newline: fn(&u8) -> bool = |&b| b == b'\n';
        Self {
            lines: bytes.split(newline),
        }
    }

    /// The file's comment lines, as the reader keeps them (CampaignInfo carries them all,
    /// also those after the header, and goes out before the first pose).
    pub(super) fn comments(bytes: &[u8], label: &str) -> Vec<String> {
        let mut reader = CampaignReader::new(label);
        for line in bytes.split(|&b| b == b'\n') {
            let text = String::from_utf8_lossy(line);
            if text
                .trim_start_matches('\u{feff}')
                .trim_start()
                .starts_with('#')
            {
                // A comment line is never an error; its number does not matter here.
                reader.read_line(text.as_bytes()).ok();
            }
        }
        reader.comments().to_vec()
    }
}

impl Lines for FileLines<'_> {
    fn next(&mut self) -> Next {
        self.lines
            .next()
            .map_or(Next::End, |l| Next::Line(l.to_vec()))
    }
}

/// Publishes at `rate_hz`: the k-th pose waits until k periods after the first.
pub(super) struct Pacer {
    t0: Instant,
    period: Duration,
    k: u32,
}

impl Pacer {
    pub(super) fn new(rate_hz: f64) -> Self {
        Self {
            t0: Instant::now(),
            period: Duration::from_secs_f64(1.0 / rate_hz),
            k: 0,
        }
    }

    /// Starts the schedule again from now (after the node held its place while inactive).
    fn restart(&mut self) {
        self.t0 = Instant::now();
        self.k = 0;
    }

    fn wait(&mut self) {
        let due = self.t0 + self.period.saturating_mul(self.k);
        self.k = self.k.saturating_add(1);
        let now = Instant::now();
        if due > now {
            std::thread::sleep(due - now);
        }
    }
}

/// A campaign error as a reject of the node, counted under its kind.
pub fn reject_of(e: &CampaignError) -> Reject {
    let kind = match e {
        CampaignError::NonFinite { .. } => RejectKind::NonFinite,
        CampaignError::OutOfRange { .. } | CampaignError::Unreachable { .. } => {
            RejectKind::OutOfRange
        }
        CampaignError::TimeNotMonotonic { .. } => RejectKind::OutOfOrder,
        _ => RejectKind::Malformed,
    };
    reject(kind, e.to_string())
}

/// The one validation loop of the CSV sources: each line through the reader, the header's
/// CampaignInfo (with `comments` when known ahead, else those read so far), each pose
/// published (paced by `pace`), each reject counted; at the end the rules of the whole input
/// (a reset pose per setup). While the node is not active the input waits where it is.
/// Returns whether the input ended (not a shutdown).
pub(super) fn stream(
    lines: &mut dyn Lines,
    label: &str,
    comments: Option<&[String]>,
    out: &mut Output<'_>,
    mut pace: Option<Pacer>,
) -> anyhow::Result<bool> {
    let mut reader = CampaignReader::new(label);
    let mut campaign = Campaign {
        source: label.to_owned(),
        ..Default::default()
    };
    loop {
        // an inactive node holds its place in the input (a line read is published once
        // active again)
        match out.wait_active()? {
            None => return Ok(false),
            Some(true) => pace.iter_mut().for_each(Pacer::restart),
            Some(false) => {}
        }
        if shutdown::requested() {
            return Ok(false);
        }
        match lines.next() {
            Next::Line(bytes) => {
                let had_header = reader.has_header();
                match reader.read_line(&bytes) {
                    Ok(None) if !had_header && reader.has_header() => {
                        campaign.covariate_names = reader.covariate_names();
                        campaign.comments = comments.unwrap_or_else(|| reader.comments()).to_vec();
                        out.info(&campaign, &format!("{label}:{}", reader.line()))?;
                    }
                    Ok(None) => {}
                    Ok(Some(pose)) => {
                        if let Some(p) = &mut pace {
                            p.wait();
                        }
                        out.pose(&campaign, &pose)?;
                    }
                    Err(e) => out.reject(reject_of(&e)),
                }
            }
            Next::Idle => {}
            Next::End => break,
        }
        out.report_if_due()?;
    }
    if let Err(e) = reader.finish() {
        out.reject(reject_of(&e));
    }
    Ok(true)
}
