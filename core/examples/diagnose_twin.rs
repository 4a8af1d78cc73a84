//! The diagnosis over the twin's hidden effects: for each effect (and none), several seeds,
//! the geometric calibration's residual and what `diagnose` names. Regenerates the per-effect
//! table of docs/diagnosis.md:
//!
//!     cargo run --release -p rpkm-core --example diagnose_twin [SEEDS]
use rpkm_core::campaign::Instrument;
use rpkm_core::diagnose::{self, DiagnosisOptions};
use rpkm_core::units::um_from_mm;
use rpkm_twin::{EffectKind, Twin, TwinConfig};

fn main() {
    let seeds: u64 = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(3);
    let mut cases: Vec<Option<EffectKind>> = vec![None];
    cases.extend(EffectKind::ALL.iter().map(|e| Some(*e)));
    println!("| hidden effect | seed | cal RMS um | val RMS um | floor um | chi2/dof (stated noise) | verdict | 1st candidate (expl., signif.) | val after um |");
    println!("|---|---|---|---|---|---|---|---|---|");
    for case in cases {
        for seed in 1..=seeds {
            let effects = case
                .map(|e| vec![(e, e.default_magnitude())])
                .unwrap_or_default();
            let mut twin = Twin::new(TwinConfig {
                seed,
                effects,
                ..Default::default()
            })
            .expect("twin");
            let cal = twin
                .campaign(&[Instrument::Lt, Instrument::Kgm, Instrument::SelfCal])
                .expect("campaign");
            let val = twin.validation(100).expect("validation");
            let t0 = std::time::Instant::now();
            let d = diagnose::diagnose(&cal, Some(&val), &[], &DiagnosisOptions::default())
                .expect("diagnose");
            let c = d.candidates.first();
            println!(
                "| {} | {seed} | {:.1} | {:.1} | {:.1} | {:.2} | {} | {} | {} |",
                case.map_or("none".to_owned(), |e| e.to_string()),
                um_from_mm(d.baseline.cal_rms),
                d.baseline.val_rms.map_or(f64::NAN, um_from_mm),
                um_from_mm(d.baseline.noise_floor),
                d.baseline.chi2_per_dof,
                d.missing_effect.as_deref().unwrap_or(match d.verdict_kind {
                    diagnose::VerdictKind::UnexplainedStructure => "unexplained structure",
                    _ => "nothing missing",
                }),
                c.map_or("-".to_owned(), |c| format!(
                    "{} ({:.2}, {})",
                    c.effect, c.explained_fraction, c.significant
                )),
                c.and_then(|c| c.val_rms_after.map(um_from_mm))
                    .map_or("-".to_owned(), |v| format!("{v:.1}")),
            );
            eprintln!("  {:.1} s", t0.elapsed().as_secs_f64());
            if std::env::var("VERBOSE").is_ok() {
                for c in &d.candidates {
                    println!(
                        "    {} expl {:.2} sig {} p {:.1e} bic {:.1} val {:?}, follows {:?}",
                        c.effect,
                        c.explained_fraction,
                        c.significant,
                        c.p_value,
                        c.bic_gain,
                        c.val_rms_after.map(um_from_mm),
                        c.follows.as_ref().map(|f| (&f.feature, f.r))
                    );
                }
                for s in &d.skipped {
                    println!("    skipped {}: {}", s.effect, s.reason);
                }
                println!("    {:?} {:?}", d.verdict_kind, d.missing_effect);
            }
        }
    }
}
