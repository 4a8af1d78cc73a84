//! A machine's records analysed: what changed between two of them, each parameter's trend
//! and when it leaves its tolerance (the arithmetic is `rpkm_core::history`'s).

use rpkm_core::history::{
    change, crossing, trend, Change, Crossing, Trend, TrendPoint, FLAG_SIGMA,
};
use rpkm_core::params::Params;
use rpkm_history::{CalibrationRecord, Stored};

/// A trend is named when its slope exceeds this many σ (as a change is flagged).
pub const TREND_SIGMA: f64 = FLAG_SIGMA;

/// One parameter over a machine's calibrations.
#[derive(Clone, Debug)]
pub struct ParamTrend {
    pub param: usize,
    /// The calibrations that determined it (indices into the history) and their values.
    pub points: Vec<(usize, TrendPoint)>,
    /// Its line over the run a line explains (`from` indexes `points`).
    pub trend: Option<Trend>,
    /// When a significant trend leaves nominal ± `tolerance`.
    pub crossing: Option<Crossing>,
    /// The band a trend is judged against (mm, rad): the latest calibration's tolerance, or
    /// the one asked for.
    pub tolerance: f64,
}

impl ParamTrend {
    /// Whether its trend is significant.
    pub fn significant(&self) -> bool {
        self.trend.is_some_and(|t| t.z().abs() >= TREND_SIGMA)
    }
}

/// What a machine's history says.
#[derive(Clone, Debug)]
pub struct Analysis {
    /// The two calibrations compared (indices into the history, earlier first) and what
    /// changed between them.
    pub change: Option<((usize, usize), Change)>,
    /// Every parameter of the latest calibration's model.
    pub trends: Vec<ParamTrend>,
}

/// The analysis of `cals` (oldest first): the change between `pair` (default: the last two)
/// and each parameter's trend; `tolerance` replaces a parameter's band (mm, rad).
pub fn analyse(
    cals: &[Stored<CalibrationRecord>],
    pair: Option<(usize, usize)>,
    tolerance: &[(usize, f64)],
) -> Analysis {
    let pair = pair.or_else(|| (cals.len() >= 2).then(|| (cals.len() - 2, cals.len() - 1)));
    let change = pair.and_then(|(a, b)| {
        let (a, b) = (a.min(b), a.max(b));
        let (ra, rb) = (&cals.get(a)?.record, &cals.get(b)?.record);
        Some(((a, b), change(&ra.estimate(), &rb.estimate())))
    });
    let Some(latest) = cals.last() else {
        return Analysis {
            change,
            trends: Vec::new(),
        };
    };
    let nominal = Params::nominal();
    let trends = latest
        .record
        .model
        .params()
        .into_iter()
        .map(|i| {
            let band = tolerance
                .iter()
                .find(|t| t.0 == i)
                .map_or(latest.record.tolerance[i], |t| t.1);
            param_trend(cals, i, nominal[i], band)
        })
        .collect();
    Analysis { change, trends }
}

fn param_trend(
    cals: &[Stored<CalibrationRecord>],
    i: usize,
    nominal: f64,
    tolerance: f64,
) -> ParamTrend {
    let points: Vec<(usize, TrendPoint)> = cals
        .iter()
        .enumerate()
        .filter(|(_, c)| c.record.estimate().determined(i))
        .map(|(k, c)| {
            let e = c.record.estimate();
            (
                k,
                TrendPoint {
                    t_s: e.t_s,
                    value: e.params[i],
                    sigma: e.sigma(i),
                },
            )
        })
        .collect();
    let plain: Vec<TrendPoint> = points.iter().map(|p| p.1).collect();
    let line = trend(&plain);
    let crossing = line
        .filter(|t| t.z().abs() >= TREND_SIGMA)
        .and_then(|t| crossing(&t, nominal, tolerance));
    ParamTrend {
        param: i,
        points,
        trend: line,
        crossing,
        tolerance,
    }
}

/// The parameters a reader looks at first: flagged in the change, then significant trends,
/// then the rest determined at least [`rpkm_core::history::MIN_POINTS`] times.
pub fn charted(a: &Analysis) -> Vec<&ParamTrend> {
    let flagged = |i: usize| {
        a.change
            .as_ref()
            .is_some_and(|(_, c)| c.params.iter().any(|p| p.param == i && p.flagged()))
    };
    let mut out: Vec<&ParamTrend> = a
        .trends
        .iter()
        .filter(|t| t.points.len() >= rpkm_core::history::MIN_POINTS || flagged(t.param))
        .collect();
    out.sort_by_key(|t| (!flagged(t.param), !t.significant(), t.param));
    out
}
