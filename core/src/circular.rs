//! Circular test (spec "Circular test", thesis table 4.21): a programmed circle measured with
//! the ball-bar; radius deviation = |mean measured radius − nominal radius|, circularity =
//! max − min radius.

use crate::campaign::{Campaign, Instrument};

/// Result of one circle.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct CircularTest {
    pub setup: String,
    pub points: usize,
    /// |mean radius − nominal|, mm.
    pub radius_deviation: f64,
    /// max − min radius, mm.
    pub circularity: f64,
    pub mean_radius: f64,
}

/// Evaluate every `circle` setup of a campaign against the programmed radius (mm). Setups
/// with fewer than three measured points are skipped (no circle to speak of).
pub fn evaluate(campaign: &Campaign, nominal_radius: f64) -> Vec<CircularTest> {
    campaign
        .setups()
        .into_iter()
        .filter(|s| s.instrument == Instrument::Circle)
        .filter_map(|s| {
            let radii: Vec<f64> = s
                .poses
                .iter()
                .map(|&i| &campaign.poses[i])
                .filter(|p| !p.reset)
                .filter_map(|p| p.r)
                .collect();
            if radii.len() < 3 {
                return None;
            }
            let mean = radii.iter().sum::<f64>() / radii.len() as f64;
            let (min, max) = radii
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &r| {
                    (lo.min(r), hi.max(r))
                });
            Some(CircularTest {
                setup: s.id.to_string(),
                points: radii.len(),
                radius_deviation: (mean - nominal_radius).abs(),
                circularity: max - min,
                mean_radius: mean,
            })
        })
        .collect()
}
