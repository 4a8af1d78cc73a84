//! The figures of a diagnosis an engineer looks at: residuals per instrument direction, the
//! worst residuals located for maps, the TCP error vectors, the noise per group.

use super::structure::sparse;
use super::types::{
    DiagnoseError, ErrorVector, GroupRms, NoiseReport, Noisier, ResidualPoint, NOISIER_THAN_RATED,
};
use crate::calib::Calibration;
use crate::campaign::Campaign;
use crate::effects::{Effect, EffectSet};
use crate::obs::{self, RowValue};
use crate::params::Model;
use crate::variance::GroupNoise;
use std::collections::BTreeMap;

/// The error vectors of every 2-D relative pose of `campaign` under the calibration `cal` of
/// the model with `effects`.
pub(crate) fn error_vectors(
    campaign: &Campaign,
    effects: &[&dyn Effect],
    cal: &Calibration,
    model: Model,
) -> Result<Vec<ErrorVector>, DiagnoseError> {
    let set = EffectSet::bind(effects, campaign, &cal.start)?;
    let errs = obs::tcp_errors_with(
        campaign,
        &cal.params,
        model,
        &set.corrections(&cal.theta, &cal.params),
    )
    .map_err(DiagnoseError::Vectors)?;
    let mut xy: BTreeMap<usize, [Option<f64>; 2]> = BTreeMap::new();
    for e in &errs {
        let slot = xy.entry(e.pose).or_default();
        match e.direction {
            obs::TcpDirection::X => slot[0] = Some(e.value),
            obs::TcpDirection::Y => slot[1] = Some(e.value),
            obs::TcpDirection::R => {}
        }
    }
    let tcp = sparse::nominal_tcp(campaign);
    let mut out = Vec::new();
    for setup in campaign.setups() {
        let Some(reset) = setup.reset else { continue };
        for &i in &setup.poses {
            // a tracker or grid-encoder pose gives both coordinates; a single one is no vector
            let Some([Some(dx), Some(dy)]) = xy.get(&i).copied() else {
                continue;
            };
            let pose = &campaign.poses[i];
            out.push(ErrorVector {
                pose: i,
                line: pose.line,
                instrument: pose.instrument.as_str().to_owned(),
                setup: setup.id.to_owned(),
                x: tcp[i].0,
                y: tcp[i].1,
                reset_x: tcp[reset].0,
                reset_y: tcp[reset].1,
                dx,
                dy,
            });
        }
    }
    Ok(out)
}

/// The groups estimated from the data above [`NOISIER_THAN_RATED`] times their rating.
pub(crate) fn noisier(groups: &[GroupNoise]) -> Vec<Noisier> {
    groups
        .iter()
        .filter(|g| g.estimated_from_data && g.assumed > 0.0)
        .map(|g| Noisier {
            group: g.group.to_owned(),
            ratio: g.estimated / g.assumed,
            capped: g.capped,
        })
        .filter(|n| n.ratio > NOISIER_THAN_RATED)
        .collect()
}

/// The noise table of the JSON: per group, the stated and the estimated level.
pub(crate) fn noise_map(groups: &[GroupNoise]) -> BTreeMap<String, NoiseReport> {
    groups
        .iter()
        .map(|g| {
            (
                g.group.to_owned(),
                NoiseReport {
                    unit: g.unit,
                    assumed: g.assumed,
                    estimated: g.estimated,
                    dof: g.dof,
                    capped: g.capped,
                },
            )
        })
        .collect()
}

/// Values (mm) of the length rows (not ψ, not forces).
pub(crate) fn length_values(rows: &[RowValue]) -> Vec<f64> {
    rows.iter()
        .filter(|r| r.direction.is_length())
        .map(|r| r.value)
        .collect()
}

pub(crate) fn length_sigmas(rows: &[RowValue]) -> Vec<f64> {
    rows.iter()
        .filter(|r| r.direction.is_length())
        .map(|r| r.sigma)
        .collect()
}

/// RMS against noise per instrument direction.
pub(crate) fn groups(rows: &[RowValue]) -> Vec<GroupRms> {
    /// Sums over the rows of one instrument and direction.
    #[derive(Default)]
    struct Sums {
        rows: usize,
        value2: f64,
        sigma2: f64,
        chi2: f64,
    }
    let mut acc: std::collections::BTreeMap<(String, String), (Sums, f64)> =
        std::collections::BTreeMap::default();
    for r in rows {
        let (e, scale) = acc
            .entry((r.instrument.as_str().to_owned(), r.direction.to_string()))
            .or_default();
        *scale = r.direction.report_unit().0;
        e.rows += 1;
        e.value2 += r.value * r.value;
        e.sigma2 += r.sigma * r.sigma;
        e.chi2 += (r.value / r.sigma).powi(2);
    }
    acc.into_iter()
        .map(|((instrument, direction), (sum, scale))| {
            let n = sum.rows as f64;
            GroupRms {
                instrument,
                direction,
                rows: sum.rows,
                rms: (sum.value2 / n).sqrt() * scale,
                noise: (sum.sigma2 / n).sqrt() * scale,
                chi2_per_row: sum.chi2 / n,
            }
        })
        .collect()
}

/// Every residual located, worst (largest |r/σ|) first.
pub(crate) fn points(campaign: &Campaign, rows: &[RowValue]) -> Vec<ResidualPoint> {
    let tcp = sparse::nominal_tcp(campaign);
    let mut out: Vec<ResidualPoint> = rows
        .iter()
        .map(|r| {
            let pose = &campaign.poses[r.pose];
            let (x, y) = tcp[r.pose];
            ResidualPoint {
                pose: r.pose,
                line: pose.line,
                instrument: r.instrument.as_str().to_owned(),
                direction: r.direction.to_string(),
                x,
                y,
                t: pose.t,
                value: r.value * r.direction.report_unit().0,
                sigma: r.sigma * r.direction.report_unit().0,
            }
        })
        .collect();
    out.sort_by(|a, b| {
        (b.value / b.sigma)
            .abs()
            .total_cmp(&(a.value / a.sigma).abs())
    });
    out
}
