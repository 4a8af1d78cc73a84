//! Each setup's zero removed from the held-out TCP errors: the reading a relative setup was
//! zeroed on is in all its readings and no model predicts it, so the errors are compared less
//! the mean of their setup and coordinate, and their noise is what is left of it then.

use super::tcp::{TcpDirection, TcpError};
use crate::campaign::Campaign;

/// Each TCP error's (setup, coordinate) as an index, in the order of `errs`: the errors of
/// one share the reading their setup was zeroed on.
pub fn zero_groups(campaign: &Campaign, errs: &[TcpError]) -> Vec<usize> {
    let mut keys: Vec<(&str, TcpDirection)> = Vec::new();
    errs.iter()
        .map(|e| {
            let key = (campaign.poses[e.pose].setup.as_str(), e.direction);
            keys.iter().position(|k| *k == key).unwrap_or_else(|| {
                keys.push(key);
                keys.len() - 1
            })
        })
        .collect()
}

/// Per group of `zero` (an index per value), the sum of `values` and their count.
pub(crate) fn group_sums(zero: &[usize], values: &[f64]) -> Vec<(f64, usize)> {
    let n = zero.iter().max().map_or(0, |m| m + 1);
    let mut sum = vec![(0.0, 0usize); n];
    for (&g, v) in zero.iter().zip(values) {
        sum[g].0 += v;
        sum[g].1 += 1;
    }
    sum
}

/// `values` less the mean of their group of `zero` ([`zero_groups`]): what a model can
/// predict of held-out errors (no model predicts the error of the reading a setup was zeroed
/// on, and one that happens to follow it would beat the truth).
pub fn zero_removed(zero: &[usize], values: &[f64]) -> Vec<f64> {
    let sum = group_sums(zero, values);
    zero.iter()
        .zip(values)
        .map(|(&g, e)| e - sum[g].0 / sum[g].1.max(1) as f64)
        .collect()
}

/// var(e_i − ē) of one error of a group of `n` whose own variance is `own` and whose
/// variances sum to `group_total`: σ_i² (1 − 2/n) + Σ σ_j² / n² (the zero removed takes the
/// mean's own noise with it).
pub fn zero_removed_variance(own: f64, group_total: f64, n: f64) -> f64 {
    (own * (1.0 - 2.0 / n) + group_total / (n * n)).max(0.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two groups interleaved: each value less its own group's mean, by hand.
    #[test]
    fn each_value_loses_its_own_groups_mean() {
        let got = zero_removed(&[0, 1, 0, 1, 0], &[1.0, 10.0, 2.0, 20.0, 6.0]);
        assert_eq!(got, vec![-2.0, -5.0, -1.0, 5.0, 3.0]);
    }
}
