//! The 29 geometric parameters of the Scissors-Kinematics (spec tables, thesis tables 4.2-4.3).
//!
//! Storage index = thesis index − 1, so `P[L1] ` is the thesis's parameter 1. Indexes 1-17 form
//! the non-redundant subsystem (q1, q4 and the parallel-holder), 18-29 the redundant one.

use serde::{Deserialize, Serialize};
use std::fmt;

/// Number of geometric parameters of the complete model.
pub const N_PARAMS: usize = 29;

/// A row over the 29 parameters: a Jacobian row, or an effect's correction of the parameters.
pub type Row = nalgebra::SVector<f64, N_PARAMS>;

pub const L1: usize = 0;
pub const L4: usize = 1;
pub const L5: usize = 2;
pub const XA1R: usize = 3;
pub const XA4R: usize = 4;
pub const XA5R: usize = 5;
pub const YA1R: usize = 6;
pub const YA4R: usize = 7;
pub const YA5R: usize = 8;
pub const XB1R: usize = 9;
pub const XB4R: usize = 10;
pub const XB5R: usize = 11;
pub const YB1R: usize = 12;
pub const YB4R: usize = 13;
pub const YB5R: usize = 14;
pub const D2: usize = 15;
pub const GAMMA2: usize = 16;
pub const L2: usize = 17;
pub const L3: usize = 18;
pub const XA2R: usize = 19;
pub const XA3R: usize = 20;
pub const YA2R: usize = 21;
pub const YA3R: usize = 22;
pub const XB2R: usize = 23;
pub const XB3R: usize = 24;
pub const YB2R: usize = 25;
pub const YB3R: usize = 26;
pub const D1: usize = 27;
pub const GAMMA1: usize = 28;

/// Names as spelled in files and on the command line (spec: angles are `gamma1`, `gamma2`).
pub const NAMES: [&str; N_PARAMS] = [
    "l1", "l4", "l5", "xa1r", "xa4r", "xa5r", "ya1r", "ya4r", "ya5r", "xb1r", "xb4r", "xb5r",
    "yb1r", "yb4r", "yb5r", "d2", "gamma2", "l2", "l3", "xa2r", "xa3r", "ya2r", "ya3r", "xb2r",
    "xb3r", "yb2r", "yb3r", "d1", "gamma1",
];

const NOMINAL: [f64; N_PARAMS] = [
    950.0, 950.0, 950.0, 520.0, 520.0, 520.0, 280.0, -280.0, 280.0, -310.0, -310.0, -310.0, 80.0,
    -80.0, 480.0, 1460.0, 0.0, 950.0, 950.0, -520.0, -520.0, 280.0, -280.0, 310.0, 310.0, 80.0,
    -80.0, -1460.0, 0.0,
];

/// Unit of a parameter: the thesis's length (mm) or angle (rad).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Unit {
    Mm,
    Rad,
}

/// Unit of parameter `i`.
pub fn unit(i: usize) -> Unit {
    if i == GAMMA1 || i == GAMMA2 {
        Unit::Rad
    } else {
        Unit::Mm
    }
}

/// The variation range the thesis uses for sensitivity and range scaling: 0.1 mm, 1°.
pub fn variation_range(i: usize) -> f64 {
    match unit(i) {
        Unit::Mm => 0.1,
        Unit::Rad => 1f64.to_radians(),
    }
}

/// Thesis index (1-based) of parameter `i`.
pub fn thesis_index(i: usize) -> usize {
    i + 1
}

/// Storage index of a parameter by its name (`l1`, `gamma2`, ...); `γ1`/`γ2` accepted too.
pub fn index_of(name: &str) -> Option<usize> {
    let n = name.trim();
    let n = match n {
        "γ1" => "gamma1",
        "γ2" => "gamma2",
        other => other,
    };
    NAMES.iter().position(|&m| m.eq_ignore_ascii_case(n))
}

/// Which geometric model: the thesis's model 24 (perfect parallel-holder) or model 29.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, Default)]
pub enum Model {
    /// Rod 5 dropped, platform angle ψ ≡ γ2 (perfect parallel-holder).
    M24,
    /// All 29 parameters; ψ is a parasitic angle set by rods 4 and 5.
    #[default]
    M29,
}

impl Model {
    /// The model's number as the thesis writes it (24 or 29).
    pub fn number(self) -> u32 {
        match self {
            Model::M24 => 24,
            Model::M29 => 29,
        }
    }

    /// From 24 or 29.
    pub fn from_number(n: u32) -> Option<Model> {
        match n {
            24 => Some(Model::M24),
            29 => Some(Model::M29),
            _ => None,
        }
    }

    /// Whether parameter `i` belongs to this model (model 24 drops rod 5's five parameters).
    pub fn has_param(self, i: usize) -> bool {
        match self {
            Model::M29 => i < N_PARAMS,
            Model::M24 => i < N_PARAMS && !matches!(i, L5 | XA5R | YA5R | XB5R | YB5R),
        }
    }

    /// Storage indexes of the model's parameters, in thesis order.
    pub fn params(self) -> Vec<usize> {
        (0..N_PARAMS).filter(|&i| self.has_param(i)).collect()
    }
}

impl fmt::Display for Model {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "model {}", self.number())
    }
}

/// One guide: origin x position d and angle γ to the y-axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Guide {
    /// Left guide (d1, γ1): carriers 2 and 3.
    G1,
    /// Right guide (d2, γ2): carriers 1 and 4, and rod 5 on carrier 4.
    G2,
}

impl Guide {
    pub fn d_index(self) -> usize {
        match self {
            Guide::G1 => D1,
            Guide::G2 => D2,
        }
    }
    pub fn gamma_index(self) -> usize {
        match self {
            Guide::G1 => GAMMA1,
            Guide::G2 => GAMMA2,
        }
    }
}

/// The parameter indexes of one rod and the carrier it hangs on.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rod {
    /// Rod number 1..=5.
    pub number: usize,
    pub l: usize,
    pub xa: usize,
    pub ya: usize,
    pub xb: usize,
    pub yb: usize,
    pub guide: Guide,
    /// Actuator index 0..=3 (q1..q4) whose carrier holds the rod.
    pub actuator: usize,
    /// Assembly mode (seed eq. 4.6): +1 when the carrier lies above its platform joint.
    pub k: f64,
}

/// Rods 1..=5 (index 0..=4).
pub const RODS: [Rod; 5] = [
    Rod {
        number: 1,
        l: L1,
        xa: XA1R,
        ya: YA1R,
        xb: XB1R,
        yb: YB1R,
        guide: Guide::G2,
        actuator: 0,
        k: 1.0,
    },
    Rod {
        number: 2,
        l: L2,
        xa: XA2R,
        ya: YA2R,
        xb: XB2R,
        yb: YB2R,
        guide: Guide::G1,
        actuator: 1,
        k: 1.0,
    },
    Rod {
        number: 3,
        l: L3,
        xa: XA3R,
        ya: YA3R,
        xb: XB3R,
        yb: YB3R,
        guide: Guide::G1,
        actuator: 2,
        k: -1.0,
    },
    Rod {
        number: 4,
        l: L4,
        xa: XA4R,
        ya: YA4R,
        xb: XB4R,
        yb: YB4R,
        guide: Guide::G2,
        actuator: 3,
        k: -1.0,
    },
    Rod {
        number: 5,
        l: L5,
        xa: XA5R,
        ya: YA5R,
        xb: XB5R,
        yb: YB5R,
        guide: Guide::G2,
        actuator: 3,
        k: -1.0,
    },
];

/// A full parameter set (29 values, mm and rad), indexed by the constants of this module.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Params(pub [f64; N_PARAMS]);

impl Default for Params {
    fn default() -> Self {
        Self::nominal()
    }
}

impl Params {
    /// The nominal (design) parameters of the spec.
    pub fn nominal() -> Self {
        Params(NOMINAL)
    }

    /// Value by name.
    pub fn get(&self, name: &str) -> Option<f64> {
        index_of(name).map(|i| self.0[i])
    }

    /// Set by name; returns false for an unknown name.
    pub fn set(&mut self, name: &str, value: f64) -> bool {
        match index_of(name) {
            Some(i) => {
                self.0[i] = value;
                true
            }
            None => false,
        }
    }

    /// A copy in which model 24's perfect parallel-holder holds: rod 5 is rod 4 shifted by the
    /// nominal holder offset (used to make model-29 data that model 24 describes exactly).
    #[must_use]
    pub fn with_perfect_parallelogram(mut self) -> Self {
        self.0[L5] = self.0[L4];
        self.0[XA5R] = self.0[XA4R];
        self.0[XB5R] = self.0[XB4R];
        self.0[YA5R] = self.0[YA4R] + (NOMINAL[YA5R] - NOMINAL[YA4R]);
        self.0[YB5R] = self.0[YB4R] + (NOMINAL[YB5R] - NOMINAL[YB4R]);
        self
    }
}

impl std::ops::Index<usize> for Params {
    type Output = f64;
    fn index(&self, i: usize) -> &f64 {
        &self.0[i]
    }
}

impl std::ops::IndexMut<usize> for Params {
    fn index_mut(&mut self, i: usize) -> &mut f64 {
        &mut self.0[i]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_thesis_indexes() {
        for (i, n) in NAMES.iter().enumerate() {
            assert_eq!(index_of(n), Some(i));
        }
        assert_eq!(thesis_index(GAMMA2), 17);
        assert_eq!(thesis_index(L2), 18);
        assert_eq!(thesis_index(GAMMA1), 29);
        assert_eq!(index_of("γ1"), Some(GAMMA1));
        assert_eq!(Model::M24.params().len(), 24);
        assert_eq!(Model::M29.params().len(), 29);
    }
}
