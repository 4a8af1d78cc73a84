//! `rpkm monitor`: what a running node set (or a replayed bag) says, kept in a plain struct
//! ([`state::Watch`]) that the receiving loop feeds and the drawing ([`draw`]) reads. The
//! monitor is a thin subscriber: it computes nothing the nodes compute (levels, predictions
//! and thresholds come from their messages); it only counts, times and remembers.

pub mod draw;
pub mod rate;
pub mod state;

pub use state::{MonitorThresholds, ThresholdSource, Watch, WatchConfig};
