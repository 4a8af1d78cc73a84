//! The weighted rows of a calibration: the problem's fixed inputs, the dependency matrix and
//! the weighted Jacobians the steps and the uncertainty share.

use super::{Link, Options};
use crate::campaign::Campaign;
use crate::effects::{Corrections, EffectSet};
use crate::noise::NoiseModel;
use crate::obs::{self, Direction, PoseError, Residual, Step};
use crate::params::{Model, Params, N_PARAMS};
use nalgebra::{DMatrix, DVector};
use std::collections::HashSet;

/// A row's identity across evaluations: its pose and direction (what outlier elimination
/// drops).
pub(super) type Key = (usize, Direction);

/// What stays fixed through one calibration: the campaign, the model, the start parameters,
/// the noise that weights the rows and the effects bound to the campaign. Built once; every
/// evaluation of the rows goes through it.
pub(super) struct Problem<'a> {
    pub campaign: &'a Campaign,
    pub model: Model,
    pub start: Params,
    pub noise: &'a NoiseModel,
    pub effects: &'a EffectSet,
    pub opts: &'a Options,
}

impl Problem<'_> {
    /// The rows of `step` at parameters `p` (virtual measurements made with `p_cal`) with the
    /// effects' corrections `corr`, less the rows in `drop`.
    pub fn rows(
        &self,
        step: Step,
        p: &Params,
        p_cal: &Params,
        corr: &Corrections,
        drop: &HashSet<Key>,
    ) -> Result<Vec<Residual>, PoseError> {
        let mut rows =
            obs::residuals_with(self.campaign, p, self.model, step, p_cal, corr, self.noise)?;
        rows.retain(|r| !drop.contains(&(r.pose, r.direction)));
        Ok(rows)
    }

    /// The direct rows (step 1) at `p` with corrections `corr`.
    pub fn direct(
        &self,
        p: &Params,
        corr: &Corrections,
        drop: &HashSet<Key>,
    ) -> Result<Vec<Residual>, PoseError> {
        self.rows(Step::Direct, p, &self.start, corr, drop)
    }
}

/// The dependency matrix D (29 × n) for the identified `ids` with `links`.
pub(super) fn dependency(ids: &[usize], links: &[Link]) -> DMatrix<f64> {
    let mut d = DMatrix::zeros(N_PARAMS, ids.len());
    for (k, &i) in ids.iter().enumerate() {
        d[(i, k)] = 1.0;
    }
    for link in links {
        for &(j, a) in &link.terms {
            if let Some(k) = ids.iter().position(|&i| i == j) {
                d[(link.param, k)] += a;
            }
        }
    }
    d
}

/// Weighted residual vector of rows.
pub(super) fn weighted_values(rows: &[Residual]) -> DVector<f64> {
    DVector::from_iterator(rows.len(), rows.iter().map(|row| row.value / row.sigma))
}

/// Weighted Jacobian (m × 29) of rows.
pub(super) fn weighted_jacobian(rows: &[Residual]) -> DMatrix<f64> {
    DMatrix::from_fn(rows.len(), N_PARAMS, |i, k| {
        rows[i].jacobian[k] / rows[i].sigma
    })
}

/// Weighted Jacobian columns (m × k) of the effect parameters `free`. Every row of a
/// calibration with effects carries the derivative for each of them (a row without effects
/// has none, and `free` is then empty).
pub(super) fn weighted_theta(rows: &[Residual], free: &[usize]) -> DMatrix<f64> {
    DMatrix::from_fn(rows.len(), free.len(), |i, k| {
        rows[i].d_theta[free[k]] / rows[i].sigma
    })
}

/// Weighted Jacobian columns (m × n) for parameters `ids` under links.
pub(super) fn reduced_jacobian(rows: &[Residual], ids: &[usize], links: &[Link]) -> DMatrix<f64> {
    weighted_jacobian(rows) * dependency(ids, links)
}

/// ½ Σ (r/σ)² of rows.
pub(super) fn cost_of(rows: &[Residual]) -> f64 {
    0.5 * rows
        .iter()
        .map(|r| (r.value / r.sigma).powi(2))
        .sum::<f64>()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::{L4, L5, XA4R};

    /// D maps the reduced unknowns to the 29 parameters: each identified parameter moves
    /// itself, and a linked one follows its terms (l5 = l4 + 0.5·xa4r, made up for the test).
    #[test]
    fn dependency_moves_linked_parameters_with_their_terms() {
        let links = [Link {
            param: L5,
            terms: vec![(L4, 1.0), (XA4R, 0.5)],
        }];
        let d = dependency(&[L4, XA4R], &links);
        assert_eq!(d.shape(), (N_PARAMS, 2));
        assert_eq!((d[(L4, 0)], d[(XA4R, 1)]), (1.0, 1.0));
        assert_eq!((d[(L5, 0)], d[(L5, 1)]), (1.0, 0.5));
        assert_eq!(d.iter().filter(|&&v| v != 0.0).count(), 4);
    }
}
