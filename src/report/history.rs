//! The history report: one self-contained HTML page (inline SVG, no script) of a machine's
//! calibrations: what changed between two of them and whether it is real, each parameter
//! over time with its σ, its trend and tolerance band and when it leaves it, the held-out
//! RMS over time, every calibration and event. The diagnosis report's style and charts.

use super::sections::figure;
use crate::plot::{self, escape, Dated, Line, TimeChart};
use rpkm_core::history::Seen;
use rpkm_core::params::{unit, Params, Unit, NAMES};
use rpkm_history::{CalibrationRecord, EventRecord, Stored};
use rpkm_nodes::history::words::{self, change_unit, date};
use rpkm_nodes::history::{charted, Analysis, ParamTrend};
use std::fmt::Write as _;

const DAY_S: f64 = 86_400.0;

/// What the page shows.
pub struct HistoryPage<'a> {
    pub machine: &'a str,
    pub calibrations: &'a [Stored<CalibrationRecord>],
    pub events: &'a [Stored<EventRecord>],
    pub analysis: &'a Analysis,
}

impl HistoryPage<'_> {
    /// The page.
    pub fn html(&self) -> String {
        let mut html = super::head(&format!("History of {}", self.machine));
        html.push_str(&self.summary());
        html.push_str(&self.change_table());
        html.push_str(&self.charts());
        html.push_str(&self.calibration_table());
        html.push_str(&self.event_table());
        html.push_str("<footer><p>Made by rpkm history; hover over a point for its calibration, value and σ.</p></footer></body></html>");
        html
    }

    fn summary(&self) -> String {
        let cals = self.calibrations;
        let span = match (cals.first(), cals.last()) {
            (Some(a), Some(b)) => {
                format!("from {} to {}", date(a.record.at_s), date(b.record.at_s))
            }
            _ => "none yet".to_owned(),
        };
        let mut o = format!(
            "<section id=\"summary\"><h1>History of {}</h1><p class=\"muted\">{} calibrations {span}; {} events.</p>",
            escape(self.machine),
            cals.len(),
            self.events.len()
        );
        let moved = self
            .analysis
            .change
            .as_ref()
            .is_some_and(|(_, c)| !c.flagged().is_empty())
            || self.analysis.trends.iter().any(ParamTrend::significant);
        let _ = write!(
            o,
            "<div class=\"verdict{}\"><ul>",
            if moved { "" } else { " ok" }
        );
        for line in words::summary(self.analysis, cals) {
            let _ = write!(o, "<li>{}</li>", escape(&line));
        }
        o.push_str("</ul></div></section>");
        o
    }

    /// Every parameter's change between the two compared, flagged rows first.
    fn change_table(&self) -> String {
        let Some(((a, b), c)) = &self.analysis.change else {
            return String::new();
        };
        let (ra, rb) = (&self.calibrations[*a].record, &self.calibrations[*b].record);
        let mut o = format!(
            "<section id=\"change\"><h2>What changed between {} and {}</h2><table><tr><th>parameter</th><th>before</th><th>after</th><th>change ± σ</th><th>|z|</th><th>determined by</th></tr>",
            escape(&date(ra.at_s)),
            escape(&date(rb.at_s))
        );
        let mut rows: Vec<_> = c.params.iter().collect();
        rows.sort_by_key(|p| (!p.flagged(), p.seen != Seen::Both, p.param));
        for p in rows {
            let (s, u) = change_unit(p.param);
            let seen = match p.seen {
                Seen::Both => "both",
                Seen::Before => "the earlier only",
                Seen::After => "the later only",
                Seen::Neither => "neither",
            };
            let _ = write!(
                o,
                "<tr{}><td>{}</td><td>{:.4}</td><td>{:.4}</td><td>{:+.4} ± {:.4} {u}</td><td>{}</td><td>{seen}</td></tr>",
                if p.flagged() { " class=\"flag\" style=\"background:#fbe3e0\"" } else { "" },
                NAMES[p.param],
                ra.params[p.param] * s,
                rb.params[p.param] * s,
                p.change * s,
                p.sigma * s,
                p.z().map_or("unknown".to_owned(), |z| format!("{:.1}", z.abs()))
            );
        }
        o.push_str("</table></section>");
        o
    }

    /// Each charted parameter over time, then the held-out RMS.
    fn charts(&self) -> String {
        let mut o = String::from("<section id=\"trends\"><h2>Over time</h2><div class=\"row\">");
        for t in charted(self.analysis) {
            o.push_str(&self.param_chart(t));
        }
        let rms: Vec<Dated> = self
            .calibrations
            .iter()
            .filter_map(|c| {
                let v = c.record.held_out_rms_um?;
                Some(Dated {
                    day: c.record.at_s as f64 / DAY_S,
                    value: v,
                    sigma: 0.0,
                    hover: format!("calibration {} ({}): {v:.2} µm", c.id, date(c.record.at_s)),
                })
            })
            .collect();
        if !rms.is_empty() {
            let svg = plot::time_chart(&TimeChart {
                title: "Held-out TCP RMS",
                y_label: "RMS (µm)",
                points: rms,
                ..TimeChart::default()
            });
            o.push_str(&figure(
                &svg,
                "After each calibration, on poses it never saw: the accuracy the machine had.",
            ));
        }
        o.push_str("</div></section>");
        o
    }

    /// One parameter's values (from nominal) with σ, its trend and its tolerance band.
    fn param_chart(&self, t: &ParamTrend) -> String {
        let (s, u) = match unit(t.param) {
            Unit::Mm => (1e3, "µm"),
            Unit::Rad => (1e6, "µrad"),
        };
        let nominal = Params::nominal()[t.param];
        let name = NAMES[t.param];
        let points: Vec<Dated> = t
            .points
            .iter()
            .map(|(k, p)| Dated {
                day: p.t_s / DAY_S,
                value: (p.value - nominal) * s,
                sigma: p.sigma * s,
                hover: format!(
                    "calibration {} ({}): {name} {:+.1} ± {:.1} {u} from nominal",
                    self.calibrations[*k].id,
                    date(self.calibrations[*k].record.at_s),
                    (p.value - nominal) * s,
                    p.sigma * s
                ),
            })
            .collect();
        let now = self.calibrations.last().map_or(0, |c| c.record.at_s);
        let line = t.trend.filter(|_| t.significant()).and_then(|tr| {
            let first = t.points.get(tr.from)?.1.t_s;
            let last = t.crossing.map_or(now as f64, |c| c.t_s.max(now as f64));
            Some(Line {
                from: (first / DAY_S, (tr.at(first) - nominal) * s),
                to: (last / DAY_S, (tr.at(last) - nominal) * s),
                name: words::trend(t, self.calibrations).unwrap_or_default(),
            })
        });
        let date_of = t.crossing.map(|c| {
            (
                c.t_s / DAY_S,
                c.sigma_s / DAY_S,
                words::crossing(t, now).unwrap_or_default(),
            )
        });
        let band = t.tolerance * s;
        let title = format!("{name} from nominal");
        let svg = plot::time_chart(&TimeChart {
            title: &title,
            y_label: &format!("{name} − nominal ({u})"),
            points,
            line,
            bounds: vec![
                (band, format!("tolerance +{band:.0} {u}")),
                (-band, format!("tolerance −{band:.0} {u}")),
            ],
            date: date_of,
        });
        figure(
            &svg,
            &format!(
                "{name}: each calibration that determined it, ±1σ; dashed: its tolerance; the line: its trend where significant, to where it leaves the band."
            ),
        )
    }

    fn calibration_table(&self) -> String {
        let mut o = String::from("<section id=\"calibrations\"><h2>Calibrations</h2><table><tr><th>id</th><th>date</th><th>source</th><th>campaign</th><th>poses</th><th>model</th><th>determined</th><th>χ²/dof</th><th>held-out RMS µm</th><th>verdict</th></tr>");
        for c in self.calibrations {
            let r = &c.record;
            let _ = write!(
                o,
                "<tr><td>{}</td><td>{}</td><td>{}</td><td title=\"sha256 {}\">{}</td><td>{}</td><td>{}</td><td>{}</td><td>{:.2}</td><td>{}</td><td>{}</td></tr>",
                c.id,
                escape(&words::date_time(r.at_s)),
                escape(&r.source),
                escape(&r.campaign.digest),
                escape(&r.campaign.name),
                r.campaign.poses,
                r.model.number(),
                r.determined.map_or("-".to_owned(), |(n, of)| format!("{n} of {of}")),
                r.chi2_per_dof,
                r.held_out_rms_um.map_or("-".to_owned(), |v| format!("{v:.2}")),
                escape(r.verdict.as_deref().unwrap_or("-"))
            );
        }
        o.push_str("</table></section>");
        o
    }

    fn event_table(&self) -> String {
        if self.events.is_empty() {
            return String::new();
        }
        let mut o = String::from("<section id=\"events\"><h2>Online events</h2><table><tr><th>date</th><th>source</th><th>kind</th><th>what</th></tr>");
        for e in self.events {
            let r = &e.record;
            let _ = write!(
                o,
                "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
                escape(&words::date_time(r.at_s)),
                escape(&r.source),
                escape(r.kind.as_str()),
                escape(&r.message)
            );
        }
        o.push_str("</table></section>");
        o
    }
}
