//! The rate of a stream as the monitor shows it, the same way for every stream.

use std::collections::VecDeque;

/// Messages per second over the last second before the latest tick: arrivals counted in
/// buckets of [`RateMeter::BUCKET_S`], summed over the buckets of that second (over the time
/// since the first arrival while that is shorter). Every stream's rate is taken over the same
/// second at a redraw (`Watch::tick`), so two streams that arrive alike read alike, and a
/// stream that stopped falls to 0 within a second.
#[derive(Debug, Clone, Default)]
pub struct RateMeter {
    /// (bucket index, arrivals in it), oldest first, within the last second.
    buckets: VecDeque<(u64, u64)>,
    first_s: Option<f64>,
    rate_hz: f64,
}

impl RateMeter {
    const WINDOW_S: f64 = 1.0;
    const BUCKET_S: f64 = 0.01;

    pub fn count(&mut self, now: f64) {
        let b = Self::bucket(now);
        match self.buckets.back_mut() {
            Some((last, n)) if *last == b => *n += 1,
            _ => self.buckets.push_back((b, 1)),
        }
        self.first_s.get_or_insert(now);
        self.tick(now);
    }

    /// The rate over the second before `now`.
    pub fn tick(&mut self, now: f64) {
        let b = Self::bucket(now);
        let per_window = rpkm_core::convert::round_u64(Self::WINDOW_S / Self::BUCKET_S);
        let oldest = b.saturating_sub(per_window - 1);
        while self.buckets.front().is_some_and(|(i, _)| *i < oldest) {
            self.buckets.pop_front();
        }
        let n: u64 = self.buckets.iter().map(|(_, n)| n).sum();
        // from the oldest bucket's start (or the first arrival, if later) to now
        let from = (oldest as f64 * Self::BUCKET_S).max(self.first_s.unwrap_or(0.0));
        self.rate_hz = n as f64 / (now - from).max(Self::BUCKET_S);
    }

    fn bucket(t: f64) -> u64 {
        let b = t / Self::BUCKET_S;
        if b.is_finite() && b > 0.0 {
            rpkm_core::convert::round_u64(b.floor())
        } else {
            0
        }
    }

    pub fn rate_hz(&self) -> f64 {
        self.rate_hz
    }
}
