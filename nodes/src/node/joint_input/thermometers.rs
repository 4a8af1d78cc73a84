//! The cell's thermometers as covariates of the drive states: the latest reading of each,
//! "not measured" (NaN, as in a campaign) once it is older than the timeout. Ages are taken
//! on this host's clock when a reading arrives, not from the thermometer's stamp: a
//! thermometer's clock need not agree with the drives', and a reading is fresh when it came.

use std::time::{Duration, Instant};

use super::config::Thermometer;

/// What changed about a thermometer since the last state: for the log.
#[derive(Debug, Clone, PartialEq)]
pub enum ThermometerChange {
    /// It went quiet: the states carry its covariate as not measured from now on.
    Quiet {
        /// Covariate name.
        covariate: String,
        /// Its topic.
        topic: String,
        /// How long it has been quiet (`None`: never heard).
        for_s: Option<f64>,
    },
    /// It spoke again.
    Back {
        /// Covariate name.
        covariate: String,
        /// Its topic.
        topic: String,
    },
}

impl std::fmt::Display for ThermometerChange {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Quiet {
                covariate,
                topic,
                for_s: Some(s),
            } => write!(
                f,
                "WARN: thermometer {covariate} ({topic}) quiet for {s:.1} s: drive states \
                 carry {covariate} not measured"
            ),
            Self::Quiet {
                covariate, topic, ..
            } => write!(
                f,
                "WARN: thermometer {covariate} ({topic}) not heard yet: drive states carry \
                 {covariate} not measured"
            ),
            Self::Back { covariate, topic } => {
                write!(f, "thermometer {covariate} ({topic}) measures again")
            }
        }
    }
}

/// The thermometers' latest readings and their bookkeeping.
#[derive(Debug, Clone)]
pub struct Thermometers {
    list: Vec<Thermometer>,
    timeout: Duration,
    /// Latest finite reading, °C, and when it arrived.
    latest: Vec<Option<(f64, Instant)>>,
    /// Quiet as of the last state.
    quiet: Vec<bool>,
    /// States that carried the covariate as not measured.
    not_measured: Vec<u64>,
    /// Readings refused (NaN or infinite).
    pub refused: u64,
}

impl Thermometers {
    /// `list` in covariate order; a reading older than `timeout` is not measured.
    pub fn new(list: Vec<Thermometer>, timeout: Duration) -> Self {
        let n = list.len();
        Self {
            list,
            timeout,
            latest: vec![None; n],
            // a thermometer counts as heard until the first state says otherwise: its
            // silence is logged then
            quiet: vec![false; n],
            not_measured: vec![0; n],
            refused: 0,
        }
    }

    /// The thermometers, in covariate order.
    pub fn list(&self) -> &[Thermometer] {
        &self.list
    }

    /// Takes a reading of thermometer `i` that arrived at `now`; a NaN or infinite one is
    /// refused (the last good reading stays and ages), with the reason.
    pub fn reading(&mut self, i: usize, celsius: f64, now: Instant) -> Result<(), String> {
        if !celsius.is_finite() {
            self.refused += 1;
            let t = &self.list[i];
            return Err(format!(
                "thermometer {} ({}): temperature {celsius}",
                t.covariate, t.topic
            ));
        }
        self.latest[i] = Some((celsius, now));
        Ok(())
    }

    /// The reading of thermometer `i` at `now`, `None` when it is not measured.
    fn fresh(&self, i: usize, now: Instant) -> Option<f64> {
        self.latest[i]
            .filter(|(_, at)| now.saturating_duration_since(*at) <= self.timeout)
            .map(|(v, _)| v)
    }

    /// The covariates of a state at `now` into `out` (NaN: not measured), and the
    /// thermometers that went quiet or spoke again since the last state.
    pub fn covariates(&mut self, now: Instant, out: &mut [f64]) -> Vec<ThermometerChange> {
        let mut changes = Vec::new();
        for (i, slot) in out.iter_mut().enumerate().take(self.list.len()) {
            let value = self.fresh(i, now);
            *slot = value.unwrap_or(f64::NAN);
            let quiet = value.is_none();
            if quiet {
                self.not_measured[i] += 1;
            }
            if quiet != self.quiet[i] {
                self.quiet[i] = quiet;
                let t = &self.list[i];
                let (covariate, topic) = (t.covariate.clone(), t.topic.clone());
                changes.push(if quiet {
                    ThermometerChange::Quiet {
                        covariate,
                        topic,
                        for_s: self.latest[i]
                            .map(|(_, at)| now.saturating_duration_since(at).as_secs_f64()),
                    }
                } else {
                    ThermometerChange::Back { covariate, topic }
                });
            }
        }
        changes
    }

    /// The thermometers quiet at `now`, as a sentence (`None` when all measure).
    pub fn quiet_summary(&self, now: Instant) -> Option<String> {
        let quiet: Vec<String> = (0..self.list.len())
            .filter(|&i| self.fresh(i, now).is_none())
            .map(|i| {
                let t = &self.list[i];
                match self.latest[i] {
                    Some((_, at)) => format!(
                        "thermometer {} ({}) quiet for {:.1} s",
                        t.covariate,
                        t.topic,
                        now.saturating_duration_since(at).as_secs_f64()
                    ),
                    None => format!("thermometer {} ({}) not heard yet", t.covariate, t.topic),
                }
            })
            .collect();
        (!quiet.is_empty()).then(|| {
            format!(
                "{}: its covariate is not measured (timeout {} s)",
                quiet.join(", "),
                self.timeout.as_secs_f64()
            )
        })
    }

    /// The /diagnostics values at `now`: per thermometer its reading and age or why it is
    /// not measured, the states that carried it not measured; the quiet ones by name.
    pub fn values(&self, now: Instant) -> Vec<(String, String)> {
        let mut out = Vec::new();
        let mut quiet = Vec::new();
        for (i, t) in self.list.iter().enumerate() {
            let reading = match (self.latest[i], self.fresh(i, now)) {
                (Some((v, at)), Some(_)) => format!(
                    "{v} degC, {:.2} s ago ({})",
                    now.saturating_duration_since(at).as_secs_f64(),
                    t.topic
                ),
                (Some((_, at)), None) => {
                    quiet.push(t.covariate.clone());
                    format!(
                        "not measured: {} quiet for {:.1} s",
                        t.topic,
                        now.saturating_duration_since(at).as_secs_f64()
                    )
                }
                (None, _) => {
                    quiet.push(t.covariate.clone());
                    format!("not measured: nothing received on {}", t.topic)
                }
            };
            out.push((format!("temperature.{}", t.covariate), reading));
            out.push((
                format!("not_measured_states.{}", t.covariate),
                self.not_measured[i].to_string(),
            ));
        }
        out.push(("thermometers_quiet".into(), quiet.join(", ")));
        out.push(("temperatures_refused".into(), self.refused.to_string()));
        out
    }
}

#[cfg(test)]
#[expect(
    clippy::float_cmp,
    reason = "exact values: parsed, copied or computed without rounding"
)]
mod tests {
    use super::*;

    fn two() -> Thermometers {
        Thermometers::new(
            vec![
                Thermometer {
                    covariate: "temp_machine".into(),
                    topic: "/cell/frame".into(),
                },
                Thermometer {
                    covariate: "temp_spindle".into(),
                    topic: "/cell/spindle".into(),
                },
            ],
            Duration::from_millis(500),
        )
    }

    #[test]
    fn the_latest_reading_is_attached_until_the_thermometer_goes_quiet() {
        let mut t = two();
        let t0 = Instant::now();
        let mut c = [0.0; 2];
        let changes = t.covariates(t0, &mut c);
        assert!(c.iter().all(|v| v.is_nan()), "nothing heard: not measured");
        assert_eq!(changes.len(), 2);
        assert_eq!(
            changes[0].to_string(),
            "WARN: thermometer temp_machine (/cell/frame) not heard yet: drive states carry \
             temp_machine not measured"
        );
        t.reading(0, 20.5, t0).expect("finite");
        t.reading(1, 31.0, t0).expect("finite");
        assert!(t.reading(1, f64::NAN, t0).is_err());
        let changes = t.covariates(t0 + Duration::from_millis(400), &mut c);
        assert_eq!(
            c,
            [20.5, 31.0],
            "the refused NaN leaves the last good reading"
        );
        assert_eq!(changes.len(), 2, "both measure again");
        t.reading(1, 31.5, t0 + Duration::from_millis(400))
            .expect("finite");
        let later = t0 + Duration::from_millis(700);
        let changes = t.covariates(later, &mut c);
        assert!(c[0].is_nan());
        assert_eq!(c[1], 31.5);
        assert_eq!(
            changes,
            [ThermometerChange::Quiet {
                covariate: "temp_machine".into(),
                topic: "/cell/frame".into(),
                for_s: Some(0.7)
            }]
        );
        assert!(t.covariates(later, &mut c).is_empty(), "logged once");
        let quiet = t.quiet_summary(later).expect("one is quiet");
        assert!(
            quiet.starts_with("thermometer temp_machine (/cell/frame) quiet for 0.7 s"),
            "{quiet}"
        );
        let values = t.values(later);
        let value = |k: &str| {
            values
                .iter()
                .find(|(key, _)| key == k)
                .map(|(_, v)| v.clone())
        };
        assert_eq!(value("thermometers_quiet").as_deref(), Some("temp_machine"));
        assert_eq!(
            value("not_measured_states.temp_machine").as_deref(),
            Some("3")
        );
        assert_eq!(value("temperatures_refused").as_deref(), Some("1"));
    }
}
