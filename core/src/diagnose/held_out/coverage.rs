//! Whether the held-out campaign lies where the calibration's does: its covariates (the
//! temperatures and any other column), their rates along the campaign's time, and its poses,
//! each against the calibration's range. A model is only known where it was calibrated: a
//! held-out campaign that heats faster, runs warmer or reaches poses the calibration never
//! saw judges an extrapolation, and the judge's words must say so beside its verdict.

use crate::campaign::{Campaign, Instrument};
use crate::diagnose::structure::sparse::nominal_tcp;

/// The window (s) over which a covariate's rate is fitted at each row: a straight line
/// through the readings within half of it either side, so that a thermometer's reading
/// noise (a few mK, a quantised last digit) does not read as a rate.
pub const RATE_WINDOW_S: f64 = 300.0;

/// Fewest readings in a window for a rate.
const RATE_MIN_READINGS: usize = 3;

/// A held-out range is said to reach beyond the calibration's only by more than this share
/// of the calibration's span (and more than three σ of the readings' noise): a thermometer's
/// last digits at a constant temperature, or a pose a millimetre past the calibration's, are
/// no extrapolation.
pub const OUTSIDE_SHARE: f64 = 0.1;

/// One quantity over both campaigns: the calibration's range, the held-out one's, and how
/// far the held-out one reaches beyond (0 where within).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Span {
    /// The covariate (`temp_machine`), its rate (`rate(temp_machine)`, per minute), or the
    /// pose's `x` or `y` (mm, nominal TCP).
    pub name: String,
    /// The calibration's smallest and largest value.
    pub calibration: (f64, f64),
    /// The held-out campaign's smallest and largest value.
    pub held_out: (f64, f64),
    /// How far the held-out values lie below the calibration's smallest (0 where not).
    pub below: f64,
    /// How far the held-out values lie above the calibration's largest (0 where not).
    pub above: f64,
    /// How far they may lie beyond and still count as within: [`OUTSIDE_SHARE`] of the
    /// calibration's span, or three σ of the readings' noise where that is larger.
    pub tolerance: f64,
    /// The instrument whose readings both ranges hold (`lt`); None where every reading is.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub instrument: Option<String>,
}

impl Span {
    /// The span of `name`, the readings' noise σ `noise` (0 for exact values).
    fn of(name: String, calibration: (f64, f64), held_out: (f64, f64), noise: f64) -> Span {
        Span {
            name,
            calibration,
            held_out,
            below: (calibration.0 - held_out.0).max(0.0),
            above: (held_out.1 - calibration.1).max(0.0),
            tolerance: (OUTSIDE_SHARE * (calibration.1 - calibration.0)).max(3.0 * noise),
            instrument: None,
        }
    }

    /// Whether the held-out campaign reaches beyond the calibration's range by more than its
    /// tolerance.
    pub fn outside(&self) -> bool {
        self.below > self.tolerance || self.above > self.tolerance
    }

    /// The largest magnitude of the held-out values over the calibration's: 4 where the
    /// held-out campaign heats 4x as fast as the calibration ever did (None where the
    /// calibration's is 0).
    pub fn magnitude_ratio(&self) -> Option<f64> {
        let max_abs = |r: (f64, f64)| r.0.abs().max(r.1.abs());
        let cal = max_abs(self.calibration);
        (cal > 0.0).then(|| max_abs(self.held_out) / cal)
    }
}

/// The held-out campaign against the calibration's: each covariate both campaigns have, its
/// rate per minute, and the poses' nominal TCP x and y.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Coverage {
    pub covariates: Vec<Span>,
    pub rates: Vec<Span>,
    pub poses: Vec<Span>,
    /// A covariate of the held-out readings of one instrument against the calibration's
    /// readings of the same instrument, where those saw a narrower range than the calibration
    /// as a whole and the held-out ones reach beyond it: what that instrument alone measures
    /// is extrapolated there, however wide the calibration's range: a tracker that measured
    /// the machine cold while a self-calibration saw it warm (on the lag class's machines so
    /// measured whose three parts expand with their lags, even the twin's own model does not
    /// reach the held-out floor).
    pub instruments: Vec<Span>,
}

impl Coverage {
    /// Every span that reaches beyond the calibration's range.
    pub fn outside(&self) -> impl Iterator<Item = &Span> {
        self.covariates
            .iter()
            .chain(&self.rates)
            .chain(&self.poses)
            .filter(|s| s.outside())
    }
}

/// The held-out campaign `val` against the calibration campaign `cal`.
pub fn coverage(cal: &Campaign, val: &Campaign) -> Coverage {
    let mut covariates = Vec::new();
    let mut rates = Vec::new();
    for name in cal
        .covariate_names
        .iter()
        .filter(|n| val.covariate_index(n).is_some())
    {
        let (a, b) = (readings(cal, name), readings(val, name));
        let noise = reading_noise(&a).max(reading_noise(&b));
        if let (Some(ra), Some(rb)) = (range(a.iter().map(|r| r.1)), range(b.iter().map(|r| r.1))) {
            covariates.push(Span::of(name.clone(), ra, rb, noise));
        }
        let (sa, sb) = (rates_of(&a, noise), rates_of(&b, noise));
        let rate_noise = sa.iter().chain(&sb).map(|r| r.1).fold(0.0, f64::max);
        if let (Some(ra), Some(rb)) = (range(sa.iter().map(|r| r.0)), range(sb.iter().map(|r| r.0)))
        {
            rates.push(Span::of(format!("rate({name})"), ra, rb, rate_noise));
        }
    }
    let (ct, vt) = (nominal_tcp(cal), nominal_tcp(val));
    let mut poses = Vec::new();
    for (axis, pick) in [("x", 0), ("y", 1)] {
        let of = |t: &[(f64, f64)]| range(t.iter().map(|p| if pick == 0 { p.0 } else { p.1 }));
        if let (Some(a), Some(b)) = (of(&ct), of(&vt)) {
            poses.push(Span::of(axis.to_owned(), a, b, 0.0));
        }
    }
    let instruments = instrument_spans(cal, val, &covariates);
    Coverage {
        covariates,
        rates,
        poses,
        instruments,
    }
}

/// See [`Coverage::instruments`]: each covariate of `whole` (the campaigns' spans) read on the
/// held-out campaign's instruments one by one.
fn instrument_spans(cal: &Campaign, val: &Campaign, whole: &[Span]) -> Vec<Span> {
    let measured: Vec<Instrument> = (Instrument::ALL.into_iter())
        .filter(|&i| i != Instrument::None && val.poses_of(i).next().is_some())
        .collect();
    let mut out = Vec::new();
    for w in whole {
        for &instrument in &measured {
            let of = |c: &Campaign| readings_of(c, &w.name, Some(instrument));
            let (a, b) = (of(cal), of(val));
            let noise = reading_noise(&a).max(reading_noise(&b));
            let (Some(ra), Some(rb)) = (range(a.iter().map(|r| r.1)), range(b.iter().map(|r| r.1)))
            else {
                continue;
            };
            let narrower = (w.calibration.1 - w.calibration.0) - (ra.1 - ra.0) > w.tolerance;
            let span = Span {
                instrument: Some(instrument.as_str().to_owned()),
                ..Span::of(w.name.clone(), ra, rb, noise)
            };
            if narrower && span.outside() {
                out.push(span);
            }
        }
    }
    out
}

/// A covariate's readings (time s, value) in time order, the empty ones left out.
fn readings(c: &Campaign, name: &str) -> Vec<(f64, f64)> {
    readings_of(c, name, None)
}

/// The same at the poses of `instrument` alone (every pose where None).
fn readings_of(c: &Campaign, name: &str, instrument: Option<Instrument>) -> Vec<(f64, f64)> {
    let Some(k) = c.covariate_index(name) else {
        return Vec::new();
    };
    let mut out: Vec<(f64, f64)> = c
        .poses
        .iter()
        .filter(|p| instrument.is_none_or(|i| p.instrument == i))
        .filter_map(|p| p.covariates.get(k).copied().flatten().map(|v| (p.t, v)))
        .filter(|(t, v)| t.is_finite() && v.is_finite())
        .collect();
    out.sort_by(|a, b| a.0.total_cmp(&b.0));
    out
}

/// The rate per minute at each reading, with its σ from the readings' `noise`: the
/// least-squares slope of the readings within [`RATE_WINDOW_S`] / 2 either side (where at
/// least [`RATE_MIN_READINGS`] at two times or more).
fn rates_of(r: &[(f64, f64)], noise: f64) -> Vec<(f64, f64)> {
    let half = RATE_WINDOW_S / 2.0;
    r.iter()
        .filter_map(|&(t0, _)| {
            let near: Vec<(f64, f64)> = r
                .iter()
                .copied()
                .filter(|(t, _)| (t - t0).abs() <= half)
                .collect();
            (near.len() >= RATE_MIN_READINGS)
                .then(|| slope(&near))
                .flatten()
                .map(|(s, stt)| (s * 60.0, noise / stt.sqrt() * 60.0))
        })
        .collect()
}

/// The σ of a covariate's readings about their smooth course: from the second differences
/// of successive readings (each the sum of three readings' noise, variance 6σ², where a
/// smooth course adds next to nothing); 0 with fewer than three.
fn reading_noise(r: &[(f64, f64)]) -> f64 {
    let d2: Vec<f64> = r
        .windows(3)
        .map(|w| w[2].1 - 2.0 * w[1].1 + w[0].1)
        .collect();
    if d2.is_empty() {
        return 0.0;
    }
    (d2.iter().map(|d| d * d).sum::<f64>() / (6.0 * d2.len() as f64)).sqrt()
}

/// The least-squares slope of value on time and the spread of the times, Σ(t − t̄)²; None
/// where the times do not spread.
fn slope(points: &[(f64, f64)]) -> Option<(f64, f64)> {
    let n = points.len() as f64;
    let mt = points.iter().map(|p| p.0).sum::<f64>() / n;
    let mv = points.iter().map(|p| p.1).sum::<f64>() / n;
    let stt: f64 = points.iter().map(|p| (p.0 - mt).powi(2)).sum();
    let stv: f64 = points.iter().map(|p| (p.0 - mt) * (p.1 - mv)).sum();
    (stt > 0.0).then(|| (stv / stt, stt))
}

/// The smallest and largest finite value, None where there is none.
fn range(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    values
        .filter(|v| v.is_finite())
        .fold(None, |acc, v| match acc {
            None => Some((v, v)),
            Some((lo, hi)) => Some((f64::min(lo, v), f64::max(hi, v))),
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A campaign of `steps` + 1 lt rows 10 s apart with `temp_machine` `temp(t)`.
    fn heating(steps: u32, temp: impl Fn(f64) -> f64) -> Campaign {
        use std::fmt::Write as _;
        let mut text = String::from(
            "t,setup,instrument,reset,q1,q2,q3,q4,f1,f2,f3,f4,follower,x,y,r,psi,temp_machine\n",
        );
        for i in 0..=steps {
            let t = f64::from(i) * 10.0;
            let _ = writeln!(
                text,
                "{t},a,lt,{},2612.2,2613.1,788.6,788.8,0,0,0,0,23,0,0,,,{:.3}",
                u8::from(i == 0),
                temp(t)
            );
        }
        Campaign::parse(&text, "c").expect("parses")
    }

    /// A linear heating's rate is its slope per minute, and a held-out campaign that heats 3x
    /// as fast and ends 0.5 K warmer is outside by those figures; the poses coincide; a
    /// held-out temperature past the calibration's by less than a tenth of its span is not.
    #[test]
    fn a_faster_warmer_held_out_campaign_is_outside_by_its_figures() {
        let cal = heating(360, |t| 20.0 + 4.0 * t / 3600.0);
        let val = heating(90, |t| 21.5 + 3.0 * t / 900.0);
        let c = coverage(&cal, &val);
        let temp = &c.covariates[0];
        assert!((temp.above - 0.5).abs() < 1e-9, "{temp:?}");
        assert!(temp.below.abs() < 1e-12);
        let rate = &c.rates[0];
        // 4 K/h is 0.0667 K/min; 3 K in 15 min is 0.2 K/min
        assert!((rate.calibration.1 - 4.0 / 60.0).abs() < 1e-3, "{rate:?}");
        assert!((rate.held_out.1 - 0.2).abs() < 1e-3, "{rate:?}");
        let ratio = rate.magnitude_ratio().expect("a rate");
        assert!((ratio - 3.0).abs() < 0.05, "{ratio}");
        assert!(c.poses.iter().all(|p| !p.outside()), "{:?}", c.poses);
        assert_eq!(c.outside().count(), 2);
        assert!(
            c.instruments.is_empty(),
            "one instrument: {:?}",
            c.instruments
        );
        let near = heating(90, |t| 20.0 + 4.3 * t / 900.0);
        let c = coverage(&cal, &near);
        assert!((c.covariates[0].above - 0.3).abs() < 1e-9);
        assert!(!c.covariates[0].outside(), "0.3 K past a 4 K span");
    }

    /// A tracker that measured the calibration at 20.0-20.2 °C while the self-calibration
    /// went on to 24 °C: its held-out readings at 23.5-24.0 °C lie within the calibration's
    /// range, 3.3 K beyond its own readings' (which are said, with the instrument).
    #[test]
    fn an_instrument_that_saw_one_temperature_is_said() {
        let lt = heating(20, |t| 20.0 + 0.2 * t / 200.0);
        let mut cal = lt.clone();
        let mut warm = heating(100, |t| 20.2 + 3.8 * t / 1000.0);
        for p in &mut warm.poses {
            p.instrument = Instrument::SelfCal;
        }
        cal.poses.extend(warm.poses);
        let val = heating(50, |t| 23.5 + 0.5 * t / 500.0);
        let c = coverage(&cal, &val);
        assert_eq!(c.outside().count(), 0, "{c:?}");
        assert_eq!(c.instruments.len(), 1, "{:?}", c.instruments);
        let s = &c.instruments[0];
        assert_eq!(s.instrument.as_deref(), Some("lt"));
        assert!((s.calibration.1 - 20.2).abs() < 1e-3, "{s:?}");
        assert!((s.above - 3.8).abs() < 1e-3, "{s:?}");
    }
}
