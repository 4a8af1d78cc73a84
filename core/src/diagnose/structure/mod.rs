//! The three structure tests of a residual, none resting on the noise's level: the
//! dictionary of smooth terms ([`sparse`]), the periodogram of the carriers'
//! positions ([`periodic`]) and neighbours along the setups' paths
//! ([`neighbours`]). The calibration's residual and the held-out residual are tested
//! alike. Beside them, [`carried`]: what a lagging thermometer's noise leaves in a residual,
//! read without before the tests.

pub mod carried;
pub mod neighbours;
pub mod periodic;
pub mod sparse;

use crate::campaign::Campaign;
use crate::obs::RowValue;

/// What the three tests found in one residual.
pub(crate) struct Shape {
    pub dictionary: sparse::Structure,
    pub periodic: Option<periodic::Periodic>,
    pub neighbours: Option<neighbours::Neighbours>,
    /// Each test's level (a third of the diagnosis's: the family's stays α).
    level: f64,
}

impl Shape {
    /// The three tests of the residual `rows` of `campaign`, each at `level`.
    pub fn of(campaign: &Campaign, rows: &[RowValue], level: f64) -> Shape {
        Self::with(campaign, rows, level, sparse::structure(campaign, rows))
    }

    /// [`Shape::of`], the dictionary's test already made (`dictionary`: of the same rows).
    pub fn with(
        campaign: &Campaign,
        rows: &[RowValue],
        level: f64,
        dictionary: sparse::Structure,
    ) -> Shape {
        // the two tests read the same rows and nothing of each other: side by side
        let (periodic, neighbours) = std::thread::scope(|scope| {
            let periodic = scope.spawn(|| periodic::periodogram(campaign, rows, level));
            let neighbours = neighbours::neighbours(campaign, rows);
            // a panic in the periodogram is a bug: it goes on in this thread
            let periodic = periodic
                .join()
                .unwrap_or_else(|p| std::panic::resume_unwind(p));
            (periodic, neighbours)
        });
        Shape {
            dictionary,
            periodic,
            neighbours,
            level,
        }
    }

    /// Whether any of the three finds structure at its level.
    pub fn structured(&self) -> bool {
        self.smallest_p() < self.level
    }

    /// The smallest of the three p-values (1 where none could be made).
    pub fn smallest_p(&self) -> f64 {
        let periodic = self.periodic.as_ref().map_or(1.0, |p| p.p_value);
        let neighbours = self.neighbours.as_ref().map_or(1.0, |n| n.p_value);
        self.dictionary.p_value.min(periodic).min(neighbours)
    }
}
