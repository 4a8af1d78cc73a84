//! The screen of `rpkm monitor`, drawn from a [`Watch`] with ratatui. Nothing here keeps
//! state: every frame is a function of the watch, the time and the terminal's size, and a
//! terminal of any size (down to 0×0) gets a frame without a panic.

use ratatui::layout::{Constraint, Layout, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::text::{Line, Span};
use ratatui::widgets::{Block, Paragraph, Wrap};
use ratatui::Frame;
use rpkm_msgs::PreloadStatus;
use rpkm_nodes::units::{mm_from_m, mrad_from_rad, um_from_m};

use super::state::{level_name, reason_name, MonitorThresholds, ThresholdSource, Watch};

/// Below this size the monitor shows a short summary instead of its panels.
pub const MIN_WIDTH: u16 = 60;
pub const MIN_HEIGHT: u16 = 16;

fn level_color(level: u8) -> Color {
    match level {
        0 => Color::Green,
        1 => Color::Yellow,
        _ => Color::Red,
    }
}

fn bold(color: Color) -> Style {
    Style::new().fg(color).add_modifier(Modifier::BOLD)
}

/// One frame. `source` says what is watched (`ipc prefix "x"`, `dds domain 0`).
pub fn frame(f: &mut Frame, w: &Watch, now: f64, source: &str) {
    let area = f.area();
    if area.width < MIN_WIDTH || area.height < MIN_HEIGHT {
        f.render_widget(
            Paragraph::new(small_summary(w, now, area)).wrap(Wrap { trim: true }),
            area,
        );
        return;
    }
    let listed = w.nodes.len() + w.not_heard().len() + w.gone().len();
    let nodes = u16::try_from(listed.clamp(1, 8)).unwrap_or(8);
    let [title, alert, preload, tcp, nodes_area, calib] = Layout::vertical([
        Constraint::Length(1),
        Constraint::Length(1),
        Constraint::Length(14),
        Constraint::Length(5),
        Constraint::Length(nodes + 2),
        Constraint::Min(4),
    ])
    .areas(area);
    let title_text = format!("rpkm monitor · {source} · {now:.1} s · q quits");
    f.render_widget(Paragraph::new(title_text).style(bold(Color::Cyan)), title);
    f.render_widget(Paragraph::new(silence_line(w, now)), alert);
    draw_preload(f, w, now, preload);
    f.render_widget(
        Paragraph::new(tcp_lines(w)).block(Block::bordered().title(" TCP estimator ")),
        tcp,
    );
    let nodes_title = match &w.last_receive_error {
        None => " Nodes ".to_owned(),
        Some((e, t)) => format!(
            " Nodes · {} receive errors, last at {t:.1} s: {e} ",
            w.receive_errors
        ),
    };
    f.render_widget(
        Paragraph::new(node_lines(w, now)).block(Block::bordered().title(nodes_title)),
        nodes_area,
    );
    f.render_widget(
        Paragraph::new(calibrator_lines(w))
            .wrap(Wrap { trim: true })
            .block(Block::bordered().title(" Calibrator ")),
        calib,
    );
}

/// What a tiny terminal still shows: the level, the silent nodes, how to get more room.
fn small_summary(w: &Watch, now: f64, area: Rect) -> Vec<Line<'static>> {
    let level = w
        .preload
        .map_or("no PreloadStatus yet", |(s, _)| level_name(s.level));
    let silent: Vec<&str> = w.silent(now).iter().map(|(n, _)| *n).collect();
    vec![
        Line::from(format!("preload {level}")),
        Line::from(if silent.is_empty() {
            "no node silent".to_owned()
        } else {
            format!("SILENT: {}", silent.join(", "))
        }),
        Line::from(format!(
            "terminal {}x{}: {MIN_WIDTH}x{MIN_HEIGHT} or more for the full view; q quits",
            area.width, area.height
        )),
    ]
}

/// `GONE: ingest (exited with code 2)`, `SILENT: tcp_estimator (1.4 s)`, `NOT HEARD:
/// calibrator`, or that every node reports (every node the launch declared, when a launch
/// reports).
fn silence_line(w: &Watch, now: f64) -> Line<'static> {
    let silent = w.silent(now);
    let gone = w.gone();
    let not_heard = w.not_heard();
    if w.nodes.is_empty() && gone.is_empty() && not_heard.is_empty() {
        return Line::styled("no node heard yet", bold(Color::Yellow));
    }
    let mut alarms = Vec::new();
    if !gone.is_empty() {
        let names: Vec<String> = gone.iter().map(|(n, how)| format!("{n} ({how})")).collect();
        alarms.push(format!("GONE: {}", names.join(", ")));
    }
    if !silent.is_empty() {
        let names: Vec<String> = silent
            .iter()
            .map(|(n, quiet)| format!("{n} ({quiet:.1} s)"))
            .collect();
        alarms.push(format!("SILENT: {} — nothing heard", names.join(", ")));
    }
    if !not_heard.is_empty() {
        alarms.push(format!("NOT HEARD: {}", not_heard.join(", ")));
    }
    if !alarms.is_empty() {
        return Line::styled(alarms.join(" · "), bold(Color::Red));
    }
    let text = match &w.launch {
        Some(l) => format!("all {} launched nodes reporting", l.nodes.len()),
        None => format!("all {} nodes reporting", w.nodes.len()),
    };
    Line::styled(text, bold(Color::Green))
}

fn thresholds_text(t: &MonitorThresholds) -> String {
    match &t.source {
        ThresholdSource::Unknown => {
            "thresholds unknown (no report of preload_monitor yet; --params FILE)".to_owned()
        }
        ThresholdSource::ParamsFile(file) => format!(
            "WARN {} % · ERROR {} % (from {file})",
            t.warn_percent, t.error_percent
        ),
        ThresholdSource::Diagnostics => format!(
            "WARN {} % · ERROR {} % (from preload_monitor)",
            t.warn_percent, t.error_percent
        ),
    }
}

fn draw_preload(f: &mut Frame, w: &Watch, now: f64, area: Rect) {
    let title = format!(" Preload · {} ", thresholds_text(&w.thresholds));
    let block = Block::bordered().title(title);
    let inner = block.inner(area);
    f.render_widget(block, area);
    let width = usize::from(inner.width);
    let mut lines = vec![held_line(w)];
    match w.drives() {
        None => lines.push(Line::from("no PreloadStatus received yet")),
        Some(drives) => {
            let range = axis_range(&drives, &w.thresholds);
            for (i, (m, p, d, level)) in drives.iter().enumerate() {
                lines.push(drive_line(i, *m, *p, *d, *level));
                let cells = axis_cells(width.saturating_sub(4), range, *m, *p, &w.thresholds);
                let mut spans = vec![Span::raw("    ")];
                spans.extend(cells.iter().map(|c| c.span(level.unwrap_or(0))));
                lines.push(Line::from(spans));
            }
        }
    }
    lines.push(history_line(w, now, width));
    lines.push(follower_line(w));
    let message = w
        .nodes
        .get("preload_monitor")
        .and_then(|n| n.diagnostic.as_ref())
        .map_or_else(String::new, |(d, _)| d.message.clone());
    lines.push(Line::from(message));
    f.render_widget(Paragraph::new(lines), inner);
}

fn held_line(w: &Watch) -> Line<'static> {
    let Some((s, _)) = w.preload else {
        return Line::from("held level: -");
    };
    let when = |t: Option<f64>| t.map_or("-".to_owned(), |t| format!("{t:.1} s"));
    Line::from(vec![
        Span::raw("held level "),
        Span::styled(level_name(s.level), bold(level_color(s.level))),
        Span::raw(format!(
            "  (first WARN at {}, first ERROR at {}; {} statuses)",
            when(w.first_warn_s),
            when(w.first_error_s),
            w.preload_count
        )),
    ])
}

fn drive_line(i: usize, m: f64, p: f64, d: f64, level: Option<u8>) -> Line<'static> {
    let (label, style) = match level {
        Some(l) => (level_name(l), bold(level_color(l))),
        None => ("-", Style::new()),
    };
    Line::from(vec![
        Span::styled(
            format!("q{} ", i + 1),
            Style::new().add_modifier(Modifier::BOLD),
        ),
        Span::raw(format!(
            "measured {m:+7.1} %  predicted {p:+7.1} %  deviation {d:+7.1} %  "
        )),
        Span::styled(label, style),
    ])
}

/// Half-width of the current axis, %: every drive's measured current and its ERROR band fit,
/// in steps of 50 % so that the scale stays put while the values move.
pub fn axis_range(drives: &[(f64, f64, f64, Option<u8>); 4], t: &MonitorThresholds) -> f64 {
    let band = if t.error_percent.is_finite() {
        t.error_percent
    } else {
        0.0
    };
    let need = drives
        .iter()
        .map(|(m, p, _, _)| m.abs().max(p.abs() + band * 1.1))
        .filter(|v| v.is_finite())
        .fold(100.0f64, f64::max);
    (need / 50.0).ceil() * 50.0
}

/// One character of a drive's axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cell {
    Empty,
    Zero,
    /// Part of the measured-current bar.
    Bar,
    /// A tick drawn over the bar or the empty axis: predicted current, WARN and ERROR limits
    /// (predicted ± threshold), and whether the bar runs under it.
    Predicted(bool),
    Warn(bool),
    Error(bool),
}

impl Cell {
    fn span(self, level: u8) -> Span<'static> {
        let bar = level_color(level);
        let under = |on: bool, s: Style| if on { s.bg(bar) } else { s };
        let (ch, style) = match self {
            Cell::Empty => ('─', Style::new().fg(Color::DarkGray)),
            Cell::Zero => ('│', Style::new().fg(Color::Gray)),
            Cell::Bar => ('█', Style::new().fg(bar)),
            Cell::Predicted(on) => ('◆', under(on, bold(Color::Cyan))),
            Cell::Warn(on) => ('┆', under(on, bold(Color::Yellow))),
            Cell::Error(on) => ('┃', under(on, bold(Color::Red))),
        };
        Span::styled(ch.to_string(), style)
    }
}

/// The axis of one drive, `width` cells over −range..+range %: the bar from 0 to the measured
/// current, ticks at the predicted current and at predicted ± WARN and ± ERROR. The bar
/// crossing a tick is the deviation crossing that threshold.
pub fn axis_cells(width: usize, range: f64, m: f64, p: f64, t: &MonitorThresholds) -> Vec<Cell> {
    if width < 3 || !(range > 0.0) {
        return Vec::new();
    }
    let col = |v: f64| -> Option<usize> {
        let x = (v + range) / (2.0 * range) * (width - 1) as f64;
        (x.is_finite() && (-0.5..(width as f64 - 0.5)).contains(&x))
            .then(|| rpkm_core::convert::round_count(x))
    };
    let zero = (width - 1) / 2;
    let mut cells = vec![Cell::Empty; width];
    let end = col(m.clamp(-range, range)).unwrap_or(zero);
    let (lo, hi) = if end < zero { (end, zero) } else { (zero, end) };
    let in_bar = |c: usize| m.is_finite() && (lo..=hi).contains(&c) && end != zero;
    for (c, cell) in cells.iter_mut().enumerate() {
        if in_bar(c) {
            *cell = Cell::Bar;
        }
    }
    if !in_bar(zero) {
        cells[zero] = Cell::Zero;
    }
    let mut tick = |v: f64, make: fn(bool) -> Cell| {
        if let Some(c) = col(v) {
            cells[c] = make(in_bar(c));
        }
    };
    if t.known() {
        for sign in [-1.0, 1.0] {
            tick(p + sign * t.warn_percent, Cell::Warn);
            tick(p + sign * t.error_percent, Cell::Error);
        }
    }
    tick(p, Cell::Predicted);
    cells
}

/// `history ▁▁▁▅▅███`: the worst held level per time mark up to now, newest right; blank
/// where no PreloadStatus came.
fn history_line(w: &Watch, now: f64, width: usize) -> Line<'static> {
    let label = format!("history ({} s/mark) ", w.config.history_bucket_s);
    let room = width.saturating_sub(label.chars().count()) as u64;
    let latest = w.bucket(now);
    let first = (latest + 1).saturating_sub(room);
    let mut marks = w.history.iter().filter(|(b, _)| *b >= first).peekable();
    let mut spans = vec![Span::raw(label)];
    for b in first..=latest {
        let (ch, style) = match marks.next_if(|(mb, _)| *mb == b) {
            Some((_, l)) => (
                match *l {
                    PreloadStatus::OK => "▁",
                    PreloadStatus::WARN => "▅",
                    _ => "█",
                },
                Style::new().fg(level_color(*l)),
            ),
            None => (" ", Style::new()),
        };
        spans.push(Span::styled(ch, style));
    }
    Line::from(spans)
}

fn follower_line(w: &Watch) -> Line<'static> {
    let Some((s, _)) = w.preload else {
        return Line::from("Δq2/Δq3: -");
    };
    if !w.follower_mode() {
        return Line::from("Δq2/Δq3: q2, q3 position-controlled (no follower compatibility test)");
    }
    let limits = w.thresholds.dq_m.map_or(String::new(), |(a, b)| {
        format!(
            "  (WARN {:.3} mm, ERROR {:.3} mm)",
            mm_from_m(a),
            mm_from_m(b)
        )
    });
    Line::from(format!(
        "followers: Δq2 {:+.4} mm  Δq3 {:+.4} mm{limits}",
        mm_from_m(s.dq2),
        mm_from_m(s.dq3)
    ))
}

fn tcp_lines(w: &Watch) -> Vec<Line<'static>> {
    let ms = |v: Option<f64>| v.map_or("-".to_owned(), |v| format!("{v:.2} ms"));
    let rate = format!(
        "estimates {} at {:.0} Hz · drive states {} at {:.0} Hz · latency {} (max {} over 1 s)",
        w.estimate_count,
        w.estimate_rate.rate_hz(),
        w.state_count,
        w.state_rate.rate_hz(),
        ms(w.latency.last_ms),
        ms(w.latency.max_ms),
    );
    let pose = w.estimate.map_or("no TcpEstimate yet".to_owned(), |e| {
        format!(
            "TCP x {:+.3} mm  y {:+.3} mm  ψ {:+.3} mrad  {}",
            mm_from_m(e.x),
            mm_from_m(e.y),
            mrad_from_rad(e.psi),
            if e.converged {
                "converged"
            } else {
                "NOT converged (rigid model)"
            }
        )
    });
    let o = &w.outcomes;
    let fallback_style = if o.rigid_fallback > 0 {
        bold(Color::Red)
    } else {
        Style::new()
    };
    let outcomes = Line::from(vec![
        Span::raw(format!(
            "outcomes: ok {} · warm rejected, cold ok {} · ",
            o.ok, o.warm_rejected_cold_ok
        )),
        Span::styled(
            format!("rigid fallback {}", o.rigid_fallback),
            fallback_style,
        ),
        Span::raw(format!(
            " · last reason {}",
            o.last_reason.map_or("-", reason_name)
        )),
    ]);
    vec![Line::from(rate), Line::from(pose), outcomes]
}

fn node_lines(w: &Watch, now: f64) -> Vec<Line<'static>> {
    let gone = w.gone();
    let unheard = w.not_heard();
    if w.nodes.is_empty() && gone.is_empty() && unheard.is_empty() {
        return vec![Line::from(
            "nothing heard on /diagnostics or the node topics yet",
        )];
    }
    let mut lines = heard_node_lines(w, now, &gone);
    // the launch's nodes never heard: gone before their first word, or still starting
    for (name, how) in gone.iter().filter(|(n, _)| !w.nodes.contains_key(*n)) {
        lines.push(Line::from(vec![
            Span::raw(format!("{name:<16} ")),
            Span::styled(format!("GONE   {how}"), bold(Color::Red)),
        ]));
    }
    for name in unheard {
        lines.push(Line::from(vec![
            Span::raw(format!("{name:<16} ")),
            Span::styled("not heard yet (launched)", bold(Color::Yellow)),
        ]));
    }
    // the launch's executables (the recorder): no nodes, their state as the launch says it
    for (name, state) in w.launch.iter().flat_map(|l| &l.executables) {
        lines.push(Line::from(format!(
            "{name:<16} {state} (executable of the launch)"
        )));
    }
    lines
}

/// The nodes heard so far: live, SILENT, or GONE when the launch says so.
fn heard_node_lines(w: &Watch, now: f64, gone: &[(&str, &str)]) -> Vec<Line<'static>> {
    w.nodes
        .iter()
        .map(|(name, n)| {
            let quiet = now - n.last_heard_s;
            let state = if let Some((_, how)) = gone.iter().find(|(g, _)| g == name) {
                Span::styled(format!("GONE   {how}"), bold(Color::Red))
            } else if quiet > n.patience_s(&w.config) {
                Span::styled(format!("SILENT {quiet:>5.1} s"), bold(Color::Red))
            } else {
                Span::styled(
                    format!("live   {quiet:>5.1} s"),
                    Style::new().fg(Color::Green),
                )
            };
            let diag =
                n.diagnostic
                    .as_ref()
                    .map_or(vec![Span::raw("(no /diagnostics yet)")], |(d, _)| {
                        vec![
                            Span::styled(
                                format!("{:<5} ", level_name(d.level)),
                                bold(level_color(d.level)),
                            ),
                            Span::raw(d.message.clone()),
                        ]
                    });
            let mut spans = vec![Span::raw(format!("{name:<16} ")), state, Span::raw("  ")];
            spans.extend(diag);
            Line::from(spans)
        })
        .collect()
}

fn calibrator_lines(w: &Watch) -> Vec<Line<'static>> {
    let um = |m: f64| {
        if m.is_finite() {
            format!("{:.1} µm", um_from_m(m))
        } else {
            "-".to_owned()
        }
    };
    let params =
        w.parameters
            .as_ref()
            .map_or("Parameters: none received yet".to_owned(), |(p, t)| {
                let identified = p.sigmas.iter().filter(|s| **s > 0.0).count();
                let effects = if p.active_effects.is_empty() {
                    "none".to_owned()
                } else {
                    p.active_effects.join(", ")
                };
                let condition = rpkm_nodes::words::condition_short(p.condition_number);
                format!(
                "Parameters (at {t:.1} s): model {}, {} measurements, {identified} identified, \
                 cal RMS {}, val RMS {}, condition {condition}, effects {effects}",
                p.model,
                p.measurement_count,
                um(p.cal_rms),
                um(p.val_rms),
            )
            });
    let diagnosis =
        w.diagnosis
            .as_ref()
            .map_or("Diagnosis: none received yet".to_owned(), |(d, t)| {
                let missing = if d.missing_effect.is_empty() {
                    "nothing missing".to_owned()
                } else {
                    format!("missing effect {}", d.missing_effect)
                };
                format!(
                "Diagnosis (at {t:.1} s): {missing}; {} candidates tested; baseline val RMS {}, \
                 noise floor {}",
                d.candidates.len(),
                um(d.baseline_val_rms),
                um(d.noise_floor)
            )
            });
    vec![Line::from(params), Line::from(diagnosis)]
}

/// The frame as plain text lines (what `--once` without `--json` prints, and what the unit
/// tests read).
pub fn to_text(buffer: &ratatui::buffer::Buffer) -> String {
    let area = buffer.area;
    let mut out = String::new();
    for y in 0..area.height {
        let mut line = String::new();
        for x in 0..area.width {
            line.push_str(buffer[(area.x + x, area.y + y)].symbol());
        }
        out.push_str(line.trim_end());
        out.push('\n');
    }
    out
}

#[cfg(test)]
mod tests;
