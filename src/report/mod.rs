//! The diagnosis report: one self-contained HTML file (every chart inline SVG, no script, no
//! network) that prints one section per page. Summary first (the verdict, the held-out error
//! falling effect by effect, the noise the campaign shows against its rating), then the
//! machine with the campaign, per instrument and direction the residual maps before and after
//! on one colour scale, the error vectors of the 2-D instruments, the residual against time
//! and against the term the verdict points at, and the effects tried.
//!
//! `history`: the page of a machine's history (`rpkm history --report`), in the same style.
//!
//! Beside the page, `report.json` holds the numbers behind the error-vector maps, so that a
//! script (or a test) can check what the arrows show.

mod contents;
mod held_out;
pub mod history;
mod sections;

pub use contents::{ModelRow, ModelTable, Report};

use crate::plot::escape;
use anyhow::Context;
use rpkm_core::diagnose::ModelDiagnosis;
use rpkm_core::units::um_from_mm;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

impl Report<'_> {
    /// The stage of a diagnosis' current model.
    pub fn stage_of(d: &ModelDiagnosis) -> ModelRow {
        // the effects as fitted (a family named whole keeps the parts the data tell apart):
        // the model whose figures these are
        let with = if d.model_effects.is_empty() {
            String::new()
        } else {
            format!(" + {}", d.model_effects.join(" + "))
        };
        ModelRow {
            model: format!("{}{with}", d.model),
            cal_rms_um: um_from_mm(d.baseline.cal_rms),
            val_rms_um: d.baseline.val_rms.map(um_from_mm),
            chi2_per_dof: d.baseline.chi2_per_dof,
        }
    }

    /// Writes `report.html` and `report.json` into `dir`; returns the page's path.
    pub fn write(&self, dir: &Path) -> anyhow::Result<PathBuf> {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        let page = dir.join("report.html");
        std::fs::write(&page, self.html())
            .with_context(|| format!("writing {}", page.display()))?;
        let json = serde_json::json!({
            "command": self.command,
            "campaign": self.campaign.source,
            "effects_before": self.before.effects_in_model,
            "effects_after": self.after.map(|a| a.effects_in_model.clone()),
            "stages": self.stages,
            "stages_chi2_under": self.chi2_under,
            "error_vectors": {
                "before": self.before.error_vectors,
                "after": self.after.map_or(&[][..], |a| &a.error_vectors[..]),
            },
        });
        let path = dir.join("report.json");
        std::fs::write(&path, serde_json::to_string_pretty(&json)?)
            .with_context(|| format!("writing {}", path.display()))?;
        Ok(page)
    }

    /// The page.
    pub fn html(&self) -> String {
        let mut html = head(&format!("{} — {}", self.command, self.campaign.source));
        html.push_str(&sections::summary(self));
        html.push_str(&sections::machine(self));
        html.push_str(&sections::instruments(self));
        html.push_str(&sections::against(self));
        html.push_str(&held_out::section(self));
        html.push_str(&sections::effects(self));
        let _ = write!(
            html,
            "<footer><p>{}</p><p>Made by {} from {}; hover over a point for its file line, pose, value and σ.</p></footer></body></html>",
            escape(&rpkm_nodes::words::test(&self.before.test)),
            escape(self.command),
            escape(&self.campaign.source)
        );
        html
    }
}

/// A page's start: its head with `title` and the style, the body opened.
fn head(title: &str) -> String {
    format!(
        "<!doctype html><html lang=\"en\"><head><meta charset=\"utf-8\">\
         <meta name=\"viewport\" content=\"width=device-width\">\
         <title>{}</title><style>{CSS}</style></head><body>",
        escape(title)
    )
}

/// Screen and print: sections start on a new page, figures are never split; in print the
/// screen's layout is scaled to the A4 width (a pair of maps and its colour bar stay on one
/// line).
const CSS: &str = "\
body{font-family:system-ui,-apple-system,'Segoe UI',sans-serif;color:#1d2329;margin:0 auto;\
max-width:1180px;padding:18px 24px;line-height:1.4}\
h1{font-size:1.55em;margin:.2em 0}h2{font-size:1.25em;border-bottom:2px solid #d6dbe0;\
padding-bottom:.2em;margin-top:1.6em}h3{font-size:1.05em;margin:1.1em 0 .3em}\
.verdict{border-left:6px solid #b2182b;background:#fbf1f0;padding:.6em 1em;font-size:1.05em}\
.verdict.ok{border-color:#59a14f;background:#eff7ee}\
.row{display:flex;flex-wrap:wrap;gap:10px;align-items:flex-start}\
figure{margin:0;break-inside:avoid}figcaption{font-size:.85em;color:#4a5560;max-width:540px}\
figure svg{display:block}.side{display:flex;gap:6px;align-items:flex-start}\
table{border-collapse:collapse;font-size:.9em;margin:.4em 0}\
td,th{border:1px solid #d6dbe0;padding:3px 8px;text-align:right}\
th{background:#f1f3f5}td:first-child,th:first-child{text-align:left}\
.muted{color:#5f6b76;font-size:.9em}\
@page{size:A4;margin:12mm}\
@media print{body{max-width:1180px;padding:0;zoom:.6}section{break-before:page}\
section#summary{break-before:auto}h2,h3{break-after:avoid}.pair{break-inside:avoid}}";
