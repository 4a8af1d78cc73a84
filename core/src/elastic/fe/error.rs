//! How a finite-element solve fails, and the names of the parts and dofs it names: read by
//! every file of the model, importing none of them.

use crate::geometry::GeometryError;
use std::fmt;

/// A finite-element solve that failed.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum FeError {
    #[error("rigid reference configuration: {0}")]
    Reference(#[from] GeometryError),
    #[error("no pair of active drives among the viable subsystems: the platform is not held")]
    NotHeld,
    #[error("non-finite input or stiffness")]
    NonFinite,
    #[error("{what} has a non-positive stiffness {value}")]
    BadStiffness { what: Label, value: f64 },
    #[error("{beam} has zero length: its two nodes coincide")]
    DegenerateBeam { beam: Label },
    #[error("singular stiffness at the {dof} (pivot ratio {ratio:.2e}): the structure is a mechanism there")]
    Singular { dof: DofLabel, ratio: f64 },
}

/// Name of a node, beam or dof, for errors and reports: a kind and a 1-based number
/// ("rod 2", "carrier 4"); number 0 for a part there is one of ("TCP").
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Label {
    pub kind: &'static str,
    pub number: usize,
}

impl Label {
    pub const fn new(kind: &'static str, number: usize) -> Label {
        Label { kind, number }
    }
}

impl fmt::Display for Label {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.number == 0 {
            write!(f, "{}", self.kind)
        } else {
            write!(f, "{} {}", self.kind, self.number)
        }
    }
}

/// Which component of a node a dof is. In a rotated nodal frame, `U1`/`U2` are along its axes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Component {
    U1,
    U2,
    Rotation,
    /// A dof that belongs to no node (e.g. the far end of a drive spring).
    Scalar,
}

/// A dof's name.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DofLabel {
    pub owner: Label,
    pub component: Component,
}

impl fmt::Display for DofLabel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let c = match self.component {
            Component::U1 => "u1",
            Component::U2 => "u2",
            Component::Rotation => "rotation",
            Component::Scalar => "displacement",
        };
        write!(f, "{} of {}", c, self.owner)
    }
}
