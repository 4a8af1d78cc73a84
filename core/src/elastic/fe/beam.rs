//! The planar 2-node Euler-Bernoulli beam: axial and bending stiffness, 3 dof per node
//! (u_x, u_y, θ_z), and the equivalent nodal loads of an initial axial elongation (the
//! thermo-mechanical method's "thermal" strain).

use nalgebra::{SMatrix, SVector, Vector2};

/// Young's modulus of steel, N/mm².
pub const STEEL_E_N_PER_MM2: f64 = 210_000.0;

/// 6×6 element matrix and 6-vector of element dofs (u_xa, u_ya, θ_a, u_xb, u_yb, θ_b).
pub type M6 = SMatrix<f64, 6, 6>;
pub type V6 = SVector<f64, 6>;

/// Section stiffness of a beam: the products that the element needs.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Section {
    /// Axial stiffness E·A, N.
    pub ea: f64,
    /// Bending stiffness E·I about the out-of-plane axis, N·mm².
    pub ei: f64,
}

impl Section {
    /// A solid steel rectangle, `width` in the plane of the mechanism (bending depth) and
    /// `thickness` out of it, mm.
    pub fn steel_rectangle(width: f64, thickness: f64) -> Section {
        Section {
            ea: STEEL_E_N_PER_MM2 * width * thickness,
            ei: STEEL_E_N_PER_MM2 * thickness * width.powi(3) / 12.0,
        }
    }

    /// A solid steel round rod of diameter `d`, mm.
    pub fn steel_round(d: f64) -> Section {
        let area = std::f64::consts::PI * d * d / 4.0;
        Section {
            ea: STEEL_E_N_PER_MM2 * area,
            ei: STEEL_E_N_PER_MM2 * std::f64::consts::PI * d.powi(4) / 64.0,
        }
    }

    /// The section with both stiffnesses multiplied by `factor`.
    #[must_use]
    pub fn scaled(self, factor: f64) -> Section {
        Section {
            ea: self.ea * factor,
            ei: self.ei * factor,
        }
    }
}

/// Orientation of a beam from node a to node b in the global frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Axis {
    pub length: f64,
    /// cos and sin of the beam axis angle to global x.
    pub c: f64,
    pub s: f64,
}

impl Axis {
    /// Axis of the beam from `a` to `b`; `None` when the nodes coincide (or are not finite).
    pub fn between(a: Vector2<f64>, b: Vector2<f64>) -> Option<Axis> {
        let d = b - a;
        let length = d.norm();
        if !(length > 0.0 && length.is_finite()) {
            return None;
        }
        Some(Axis {
            length,
            c: d.x / length,
            s: d.y / length,
        })
    }

    /// Rotation from global to element-local dofs, blockdiag(R, R) with R = [[c, s, 0],
    /// [−s, c, 0], [0, 0, 1]].
    fn local_from_global(&self) -> M6 {
        let mut t = M6::zeros();
        for o in [0, 3] {
            t[(o, o)] = self.c;
            t[(o, o + 1)] = self.s;
            t[(o + 1, o)] = -self.s;
            t[(o + 1, o + 1)] = self.c;
            t[(o + 2, o + 2)] = 1.0;
        }
        t
    }
}

/// Element stiffness in local coordinates (x along the beam): the textbook Euler-Bernoulli
/// matrix, axial and bending uncoupled.
pub fn local_stiffness(section: &Section, length: f64) -> M6 {
    let l = length;
    let a = section.ea / l;
    let b12 = 12.0 * section.ei / l.powi(3);
    let b6 = 6.0 * section.ei / (l * l);
    let b4 = 4.0 * section.ei / l;
    let b2 = 2.0 * section.ei / l;
    M6::from_row_slice(&[
        a, 0.0, 0.0, -a, 0.0, 0.0, //
        0.0, b12, b6, 0.0, -b12, b6, //
        0.0, b6, b4, 0.0, -b6, b2, //
        -a, 0.0, 0.0, a, 0.0, 0.0, //
        0.0, -b12, -b6, 0.0, b12, -b6, //
        0.0, b6, b2, 0.0, -b6, b4,
    ])
}

/// Element stiffness in global coordinates: Tᵀ k_local T.
pub fn global_stiffness(section: &Section, axis: &Axis) -> M6 {
    let t = axis.local_from_global();
    t.transpose() * local_stiffness(section, axis.length) * t
}

/// Equivalent nodal loads (global) of an initial elongation `elongation` (mm) of the beam:
/// a beam that "wants" to be longer pushes its nodes apart with E·A·ΔL/L when they are held.
pub fn initial_elongation_load(section: &Section, axis: &Axis, elongation: f64) -> V6 {
    let n = section.ea * elongation / axis.length;
    V6::from([-n * axis.c, -n * axis.s, 0.0, n * axis.c, n * axis.s, 0.0])
}

/// Axial force (N, positive in tension) from the element's global displacements and its
/// initial elongation: N = E·A·(δ − ΔL)/L with δ the elongation of the chord.
pub fn axial_force(section: &Section, axis: &Axis, u: &V6, elongation: f64) -> f64 {
    let delta = (u[3] - u[0]) * axis.c + (u[4] - u[1]) * axis.s;
    section.ea * (delta - elongation) / axis.length
}

/// Forces and moments the nodes exert on the element (global): k u − f₀. The element exerts
/// the opposite on its nodes.
pub fn end_forces(section: &Section, axis: &Axis, u: &V6, elongation: f64) -> V6 {
    global_stiffness(section, axis) * u - initial_elongation_load(section, axis, elongation)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rel(a: f64, b: f64) -> f64 {
        (a - b).abs() / b.abs()
    }

    /// Cantilever along an inclined axis, node a clamped: the reduced 3×3 system gives the
    /// analytic tip answers PL/EA (axial) and PL³/3EI, PL²/2EI (transverse).
    #[test]
    fn single_element_reproduces_axial_and_cantilever_formulas() {
        let sec = Section {
            ea: 2.0e8,
            ei: 5.0e10,
        };
        let l = 800.0;
        let ang: f64 = 0.7;
        let axis = Axis::between(Vector2::zeros(), Vector2::new(l * ang.cos(), l * ang.sin()))
            .expect("axis");
        let k = global_stiffness(&sec, &axis);
        let kbb = k.fixed_view::<3, 3>(3, 3).into_owned();
        let p = 1000.0;
        let (along, across) = (
            Vector2::new(ang.cos(), ang.sin()),
            Vector2::new(-ang.sin(), ang.cos()),
        );
        for (dir, axial) in [(along, true), (across, false)] {
            let f = nalgebra::Vector3::new(p * dir.x, p * dir.y, 0.0);
            let u = kbb.lu().solve(&f).expect("solve");
            let d = Vector2::new(u[0], u[1]).dot(&dir);
            if axial {
                assert!(rel(d, p * l / sec.ea) < 1e-12, "{d}");
                assert!(u[2].abs() < 1e-15);
            } else {
                assert!(rel(d, p * l.powi(3) / (3.0 * sec.ei)) < 1e-12, "{d}");
                assert!(rel(u[2], p * l * l / (2.0 * sec.ei)) < 1e-12);
            }
        }
    }

    /// Rigid-body motions cost no energy and no force; initial elongation of a free beam is
    /// released without force.
    #[test]
    fn rigid_motions_are_force_free() {
        let sec = Section::steel_round(20.0);
        let axis = Axis::between(Vector2::new(1.0, 2.0), Vector2::new(301.0, -398.0)).expect("a");
        let k = global_stiffness(&sec, &axis);
        let theta = 1e-3;
        // rotation about node a: node b moves by θ × (b − a)
        let (dx, dy) = (300.0, -400.0);
        let u = V6::from([0.3, -0.2, theta, 0.3 - theta * dy, -0.2 + theta * dx, theta]);
        assert!((k * u).amax() < 1e-9 * k.amax());
        let free = V6::from([0.0, 0.0, 0.0, 0.6 * 0.1, -0.8 * 0.1, 0.0]);
        assert!(axial_force(&sec, &axis, &free, 0.1).abs() < 1e-9);
        assert!(end_forces(&sec, &axis, &free, 0.1).amax() < 1e-6);
    }

    #[test]
    fn coincident_nodes_have_no_axis() {
        assert!(Axis::between(Vector2::new(1.0, 1.0), Vector2::new(1.0, 1.0)).is_none());
    }
}
