//! The screen: the axis geometry by hand, and every terminal size drawn without a panic.
#![expect(
    clippy::float_cmp,
    reason = "exact values: parsed, copied or computed without rounding"
)]

use super::*;
use crate::monitor::WatchConfig;
use ratatui::backend::TestBackend;
use ratatui::Terminal;
use rpkm_msgs::{DiagnosticArray, DiagnosticStatus, TcpEstimate};

fn thresholds() -> MonitorThresholds {
    MonitorThresholds {
        warn_percent: 30.0,
        error_percent: 80.0,
        dq_m: None,
        source: ThresholdSource::Diagnostics,
    }
}

#[test]
fn the_bar_crosses_the_warn_tick_when_the_deviation_crosses_warn() {
    // 41 cells over -100..100 %: 5 % per cell, 0 % at cell 20.
    let t = thresholds();
    let cells = axis_cells(41, 100.0, 50.0, 0.0, &t);
    assert_eq!(cells.len(), 41);
    assert_eq!(
        cells[20],
        Cell::Predicted(true),
        "predicted 0 %, under the bar"
    );
    assert_eq!(
        cells[26],
        Cell::Warn(true),
        "+30 %: the bar (to +50 %) runs past it"
    );
    assert_eq!(cells[14], Cell::Warn(false));
    assert_eq!(cells[36], Cell::Error(false), "+80 %: not reached");
    assert_eq!(cells[4], Cell::Error(false));
    assert_eq!(cells[30], Cell::Bar, "the bar ends at +50 %");
    assert_eq!(cells[31], Cell::Empty);
    // A negative current with a predicted -40 %: the ticks move with the prediction.
    let cells = axis_cells(41, 100.0, -95.0, -40.0, &t);
    assert_eq!(cells[12], Cell::Predicted(true));
    assert_eq!(cells[1], Cell::Bar);
    assert_eq!(cells[6], Cell::Warn(true), "-70 %");
    assert_eq!(cells[18], Cell::Warn(true), "-10 %");
    assert_eq!(cells[28], Cell::Error(false), "+40 %");
    assert!(
        !cells.contains(&Cell::Error(true)),
        "-120 % is off the axis"
    );
    assert_eq!(cells[20], Cell::Bar, "the bar runs from 0");
    assert_eq!(cells[21], Cell::Empty);
    assert_eq!(
        axis_cells(41, 100.0, 0.0, 50.0, &t)[20],
        Cell::Zero,
        "no bar: the zero mark"
    );
}

#[test]
fn the_axis_range_holds_every_current_and_its_error_band() {
    let d = |m: f64, p: f64| (m, p, m - p, None);
    let t = thresholds();
    assert_eq!(axis_range(&[d(10.0, 5.0); 4], &t), 100.0);
    assert_eq!(
        axis_range(
            &[d(219.0, 19.0), d(37.0, 69.0), d(1.0, 1.0), d(1.0, 1.0)],
            &t
        ),
        250.0
    );
    // p + 1.1 * error = 69 + 88 = 157 -> 200.
    assert_eq!(axis_range(&[d(0.0, 69.0); 4], &t), 200.0);
    assert!(axis_cells(2, 100.0, 1.0, 0.0, &t).is_empty());
    assert!(axis_cells(40, f64::NAN, 1.0, 0.0, &t).is_empty());
}

fn busy_watch() -> Watch {
    let mut w = Watch::new(WatchConfig::default(), thresholds());
    let s = rpkm_msgs::PreloadStatus {
        measured_current: [219.0, -37.0, 219.0, -37.0],
        predicted_current: [19.0, -69.0, 19.0, -69.0],
        deviation: [200.0, 32.0, 200.0, 32.0],
        level: 2,
        ..Default::default()
    };
    w.on_preload(&s, 1.0);
    w.on_estimate(
        &TcpEstimate {
            y: 1.7,
            converged: true,
            ..TcpEstimate::default()
        },
        1.0,
    );
    for name in ["tcp_estimator", "preload_monitor"] {
        let a = DiagnosticArray {
            status: vec![DiagnosticStatus {
                name: format!("rpkm/{name}"),
                message: "a long message ".repeat(20),
                ..DiagnosticStatus::default()
            }],
            ..DiagnosticArray::default()
        };
        w.on_diagnostics(a, if name == "tcp_estimator" { 1.0 } else { 4.0 });
    }
    w
}

#[test]
fn every_terminal_size_draws_without_a_panic() {
    let w = busy_watch();
    for width in (0..=130).step_by(7).chain([1, 59, 60, 61]) {
        for height in (0..=50).step_by(3).chain([1, 15, 16, 17]) {
            let mut term = Terminal::new(TestBackend::new(width, height)).expect("terminal");
            term.draw(|f| frame(f, &w, 4.5, "ipc prefix \"t\""))
                .expect("draw");
        }
    }
}

#[test]
fn the_screen_says_which_drive_is_in_error_and_who_is_silent() {
    let w = busy_watch();
    let mut term = Terminal::new(TestBackend::new(120, 48)).expect("terminal");
    let text = to_text(
        term.draw(|f| frame(f, &w, 4.5, "test"))
            .expect("draw")
            .buffer,
    );
    // A line without the panel's borders.
    let line = |needle: &str| {
        text.lines()
            .find(|l| l.contains(needle))
            .unwrap_or_else(|| panic!("no line with {needle:?} in\n{text}"))
            .trim_matches('│')
            .trim_end()
            .to_owned()
    };
    assert!(line("q1 measured").contains("+200.0 %") && line("q1 measured").ends_with("ERROR"));
    assert!(
        line("q2 measured").ends_with("WARN"),
        "|32| between 30 and 80"
    );
    assert!(line("SILENT").contains("tcp_estimator (3.5 s)"), "{text}");
    assert!(!line("SILENT").contains("preload_monitor"));
    assert!(line("history").contains('█'));
    assert!(line("Preload").contains("WARN 30 % · ERROR 80 %"));
    // Small: still the level and the silent node.
    let mut term = Terminal::new(TestBackend::new(40, 6)).expect("terminal");
    let small = to_text(
        term.draw(|f| frame(f, &w, 4.5, "test"))
            .expect("draw")
            .buffer,
    );
    assert!(
        small.contains("preload ERROR") && small.contains("SILENT: tcp_estimator"),
        "{small}"
    );
}
