//! Whether a plan for the TCP pays: what the planner decides of a [`Forecast`], the rules
//! `rpkm plan` and `rpkm bench plan` read (their words stay in the command line).

use super::accuracy::Forecast;

/// A plan that lowers the TCP's own error (the expected held-out RMS above the readings'
/// noise) by less than this share of it buys nothing.
pub const WORTH: f64 = 0.05;

/// The TCP's own error in an expected held-out RMS `rms` (mm): what is left above the
/// held-out readings' noise `floor` (mm, in quadrature); none where the noise is all of it.
pub fn own_error(rms: f64, floor: f64) -> f64 {
    (rms * rms - floor * floor).max(0.0).sqrt()
}

impl Forecast {
    /// Whether the plan buys something: the TCP's own error lower after it by [`WORTH`] of
    /// itself now.
    pub fn pays(&self) -> bool {
        let now = own_error(self.now_mm, self.floor_mm);
        now - own_error(self.after_mm, self.floor_mm) >= WORTH * now
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 5 over a floor of 3 leaves 4 (a 3-4-5 triangle); under the floor, nothing.
    #[test]
    fn the_own_error_is_what_is_left_above_the_floor_in_quadrature() {
        assert!((own_error(0.005, 0.003) - 0.004).abs() < 1e-15);
        assert!(own_error(0.002, 0.003) <= 0.0);
    }

    /// Own error 4 µm now: to 3.85 (3.75 % lower) buys nothing, to 3.75 (6.25 %) pays.
    #[test]
    fn a_plan_pays_from_five_percent_of_the_own_error() {
        let at = |own_after: f64| Forecast {
            now_mm: 0.005,
            after_mm: (own_after * own_after + 0.003 * 0.003).sqrt(),
            floor_mm: 0.003,
        };
        assert!(!at(0.00385).pays());
        assert!(at(0.00375).pays());
    }
}
