//! A small planar frame: nodes with 3 dof (optionally in a rotated nodal frame, for carriers on
//! inclined guides), beams, scalar springs between dofs, prescribed dofs and nodal loads; and a
//! linear static solver that keeps its buffers between solves.
//!
//! Prescribed dofs are eliminated symmetrically (their columns go to the right-hand side and
//! their rows become identities), so the system stays symmetric positive definite for a
//! structure that is held, and an in-place Cholesky factorises it. A pivot that vanishes
//! relative to its own diagonal is a mechanism (an unheld dof) and is reported with its name,
//! never solved into garbage. Reactions are K·u − f on the full matrix.

use super::beam::{self, Axis, Section, M6, V6};
use super::error::{Component, DofLabel, FeError, Label};
use nalgebra::{DMatrix, DVector, Vector2, Vector3};

/// A Cholesky pivot below this fraction of its diagonal entry means the dof is not held (the
/// structure is a mechanism there). Well-posed structures here stay above 1e-3; a true
/// mechanism falls to round-off (1e-16).
pub const PIVOT_RATIO_MIN: f64 = 1e-11;

pub type NodeId = usize;
pub type DofId = usize;
pub type BeamId = usize;

/// A node: position (mm), nodal frame angle φ (rad; its dofs u1, u2 are along R(φ)·x̂ and
/// R(φ)·ŷ) and its three dofs. Hinge nodes share u1, u2 with their parent.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Node {
    pub position: Vector2<f64>,
    pub frame: f64,
    pub dofs: [DofId; 3],
}

/// A beam between two nodes with an initial elongation (mm) imposed as initial strain.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Beam {
    pub a: NodeId,
    pub b: NodeId,
    pub section: Section,
    pub elongation: f64,
    pub label: Label,
}

/// A scalar spring between dof `a` and dof `b` (or the ground), stiffness N/mm or N·mm/rad.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Spring {
    pub a: DofId,
    pub b: Option<DofId>,
    pub k: f64,
}

#[derive(Clone, Copy, Debug, PartialEq)]
struct Dof {
    label: DofLabel,
    prescribed: Option<f64>,
    load: f64,
}

/// The structure: built by the `add_*` calls, cleared and rebuilt without reallocating.
#[derive(Clone, Debug, Default)]
pub struct AssemblyStructure {
    nodes: Vec<Node>,
    beams: Vec<Beam>,
    springs: Vec<Spring>,
    dofs: Vec<Dof>,
}

impl AssemblyStructure {
    pub fn new() -> AssemblyStructure {
        AssemblyStructure::default()
    }

    /// Empties the structure, keeping its storage.
    pub fn clear(&mut self) {
        self.nodes.clear();
        self.beams.clear();
        self.springs.clear();
        self.dofs.clear();
    }

    fn new_dof(&mut self, owner: Label, component: Component) -> DofId {
        self.dofs.push(Dof {
            label: DofLabel { owner, component },
            prescribed: None,
            load: 0.0,
        });
        self.dofs.len() - 1
    }

    /// A node with three new dofs, in the nodal frame rotated by `frame` rad.
    pub fn add_node(&mut self, position: Vector2<f64>, frame: f64, label: Label) -> NodeId {
        let dofs = [
            self.new_dof(label, Component::U1),
            self.new_dof(label, Component::U2),
            self.new_dof(label, Component::Rotation),
        ];
        self.nodes.push(Node {
            position,
            frame,
            dofs,
        });
        self.nodes.len() - 1
    }

    /// A hinge on `parent`: the same position and translations, its own rotation (a revolute
    /// joint: what is attached to the hinge turns independently of what is attached to the
    /// parent, unless a rotational spring couples them).
    pub fn add_hinge(&mut self, parent: NodeId, label: Label) -> NodeId {
        let mut node = self.nodes[parent];
        node.dofs[2] = self.new_dof(label, Component::Rotation);
        self.nodes.push(node);
        self.nodes.len() - 1
    }

    /// A dof that belongs to no node (the far end of a spring).
    pub fn add_scalar_dof(&mut self, label: Label) -> DofId {
        self.new_dof(label, Component::Scalar)
    }

    pub fn add_beam(
        &mut self,
        a: NodeId,
        b: NodeId,
        section: Section,
        elongation: f64,
        label: Label,
    ) -> BeamId {
        self.beams.push(Beam {
            a,
            b,
            section,
            elongation,
            label,
        });
        self.beams.len() - 1
    }

    pub fn add_spring(&mut self, a: DofId, b: Option<DofId>, k: f64) {
        self.springs.push(Spring { a, b, k });
    }

    /// Holds `dof` at the displacement `value`.
    pub fn prescribe(&mut self, dof: DofId, value: f64) {
        self.dofs[dof].prescribed = Some(value);
    }

    /// Adds an external force (or moment) on `dof`.
    pub fn add_load(&mut self, dof: DofId, value: f64) {
        self.dofs[dof].load += value;
    }

    pub fn node(&self, id: NodeId) -> &Node {
        &self.nodes[id]
    }

    pub fn beam(&self, id: BeamId) -> &Beam {
        &self.beams[id]
    }

    pub fn n_dofs(&self) -> usize {
        self.dofs.len()
    }

    pub fn dof_label(&self, dof: DofId) -> DofLabel {
        self.dofs[dof].label
    }

    fn beam_axis(&self, beam: &Beam) -> Result<Axis, FeError> {
        Axis::between(self.nodes[beam.a].position, self.nodes[beam.b].position)
            .ok_or(FeError::DegenerateBeam { beam: beam.label })
    }

    /// Element dofs of a beam and the map G from those dofs to the element's global
    /// (x, y, θ) displacements: blockdiag(R(φ_a) ⊕ 1, R(φ_b) ⊕ 1); `None` when both nodal
    /// frames are the global one (G = I: most beams, every beam for straight guides), which
    /// spares two 6×6 products per beam.
    fn beam_map(&self, beam: &Beam) -> ([DofId; 6], Option<M6>) {
        let (na, nb) = (&self.nodes[beam.a], &self.nodes[beam.b]);
        let dofs = [
            na.dofs[0], na.dofs[1], na.dofs[2], nb.dofs[0], nb.dofs[1], nb.dofs[2],
        ];
        if na.frame == 0.0 && nb.frame == 0.0 {
            return (dofs, None);
        }
        let mut g = M6::zeros();
        for (o, node) in [(0, na), (3, nb)] {
            let (s, c) = node.frame.sin_cos();
            g[(o, o)] = c;
            g[(o, o + 1)] = -s;
            g[(o + 1, o)] = s;
            g[(o + 1, o + 1)] = c;
            g[(o + 2, o + 2)] = 1.0;
        }
        (dofs, Some(g))
    }
}

/// Linear static solver with buffers reused from one solve to the next.
#[derive(Clone, Debug)]
pub struct Solver {
    /// Full stiffness matrix (all dofs), kept for the reactions.
    k: DMatrix<f64>,
    /// System matrix after elimination of the prescribed dofs, factorised in place.
    factor: DMatrix<f64>,
    /// Full load vector: external loads plus initial-strain loads.
    f: DVector<f64>,
    /// Right-hand side, then the solution.
    u: DVector<f64>,
    /// K·u − f: the reactions at prescribed dofs (round-off elsewhere).
    reaction: DVector<f64>,
    /// Diagonal of the system matrix before factorisation: the scale of each pivot.
    diag: Vec<f64>,
}

impl Default for Solver {
    fn default() -> Self {
        Solver::new()
    }
}

impl Solver {
    pub fn new() -> Solver {
        Solver {
            k: DMatrix::zeros(0, 0),
            factor: DMatrix::zeros(0, 0),
            f: DVector::zeros(0),
            u: DVector::zeros(0),
            reaction: DVector::zeros(0),
            diag: Vec::new(),
        }
    }

    fn reset(&mut self, n: usize) {
        if self.k.nrows() == n {
            self.k.fill(0.0);
            self.f.fill(0.0);
        } else {
            self.k = DMatrix::zeros(n, n);
            self.factor = DMatrix::zeros(n, n);
            self.f = DVector::zeros(n);
            self.u = DVector::zeros(n);
            self.reaction = DVector::zeros(n);
            self.diag = vec![0.0; n];
        }
    }

    /// Solves the structure: displacements of every dof and reactions at prescribed dofs.
    pub fn solve(&mut self, s: &AssemblyStructure) -> Result<(), FeError> {
        let n = s.n_dofs();
        self.reset(n);
        self.assemble(s)?;
        if !(self.k.iter().all(|v| v.is_finite()) && self.f.iter().all(|v| v.is_finite())) {
            return Err(FeError::NonFinite);
        }
        self.eliminate_prescribed(s);
        for i in 0..n {
            self.diag[i] = self.factor[(i, i)];
        }
        cholesky_in_place(&mut self.factor, &self.diag).map_err(|(dof, ratio)| {
            FeError::Singular {
                dof: s.dof_label(dof),
                ratio,
            }
        })?;
        substitute(&self.factor, &mut self.u);
        self.reaction.gemv(1.0, &self.k, &self.u, 0.0);
        self.reaction -= &self.f;
        Ok(())
    }

    fn assemble(&mut self, s: &AssemblyStructure) -> Result<(), FeError> {
        for b in &s.beams {
            let axis = s.beam_axis(b)?;
            let (dofs, g) = s.beam_map(b);
            let mut ke = beam::global_stiffness(&b.section, &axis);
            let mut fe = beam::initial_elongation_load(&b.section, &axis, b.elongation);
            if let Some(g) = g {
                ke = g.transpose() * ke * g;
                fe = g.transpose() * fe;
            }
            for (r, &dr) in dofs.iter().enumerate() {
                self.f[dr] += fe[r];
                for (c, &dc) in dofs.iter().enumerate() {
                    self.k[(dr, dc)] += ke[(r, c)];
                }
            }
        }
        for sp in &s.springs {
            self.k[(sp.a, sp.a)] += sp.k;
            if let Some(b) = sp.b {
                self.k[(b, b)] += sp.k;
                self.k[(sp.a, b)] -= sp.k;
                self.k[(b, sp.a)] -= sp.k;
            }
        }
        for (i, d) in s.dofs.iter().enumerate() {
            self.f[i] += d.load;
        }
        Ok(())
    }

    /// Symmetric elimination: u_p moves to the right-hand side, row and column p become the
    /// identity, so the free block stays symmetric positive definite.
    fn eliminate_prescribed(&mut self, s: &AssemblyStructure) {
        self.factor.copy_from(&self.k);
        self.u.copy_from(&self.f);
        let n = s.n_dofs();
        for (p, d) in s.dofs.iter().enumerate() {
            let Some(v) = d.prescribed else { continue };
            for i in 0..n {
                self.u[i] -= self.factor[(i, p)] * v;
                self.factor[(i, p)] = 0.0;
                self.factor[(p, i)] = 0.0;
            }
            self.factor[(p, p)] = 1.0;
        }
        for (p, d) in s.dofs.iter().enumerate() {
            if let Some(v) = d.prescribed {
                self.u[p] = v;
            }
        }
    }

    /// Displacement of a dof (mm or rad, in its node's frame).
    pub fn displacement(&self, dof: DofId) -> f64 {
        self.u[dof]
    }

    /// Reaction at a prescribed dof: the force (N or N·mm) the support applies to the
    /// structure along that dof.
    pub fn reaction(&self, dof: DofId) -> f64 {
        self.reaction[dof]
    }

    /// Displacement of a node in the global frame: (u_x, u_y, θ).
    pub fn node_displacement(&self, s: &AssemblyStructure, node: NodeId) -> Vector3<f64> {
        let nd = s.node(node);
        let (sn, c) = nd.frame.sin_cos();
        let (u1, u2) = (self.u[nd.dofs[0]], self.u[nd.dofs[1]]);
        Vector3::new(c * u1 - sn * u2, sn * u1 + c * u2, self.u[nd.dofs[2]])
    }

    /// A beam's global end displacements (u_xa, u_ya, θ_a, u_xb, u_yb, θ_b).
    fn beam_displacements(&self, s: &AssemblyStructure, b: &Beam) -> V6 {
        let (dofs, g) = s.beam_map(b);
        let u = V6::from(dofs.map(|d| self.u[d]));
        match g {
            Some(g) => g * u,
            None => u,
        }
    }

    /// Axial force of a beam, N, positive in tension.
    pub fn axial_force(&self, s: &AssemblyStructure, beam: BeamId) -> Result<f64, FeError> {
        let b = s.beam(beam);
        let axis = s.beam_axis(b)?;
        let u = self.beam_displacements(s, b);
        Ok(beam::axial_force(&b.section, &axis, &u, b.elongation))
    }

    /// Forces and moments (global) the beam exerts on its nodes a and b: (F_xa, F_ya, M_a,
    /// F_xb, F_yb, M_b).
    pub fn beam_loads_on_nodes(&self, s: &AssemblyStructure, beam: BeamId) -> Result<V6, FeError> {
        let b = s.beam(beam);
        let axis = s.beam_axis(b)?;
        let u = self.beam_displacements(s, b);
        Ok(-beam::end_forces(&b.section, &axis, &u, b.elongation))
    }
}

/// In-place right-looking Cholesky of the lower triangle (column-major, so the inner loop runs
/// down a column); the strict upper triangle is left as it was and never read. Zero entries of
/// the pivot column are skipped: the frame's matrix is sparse. A pivot that falls below
/// [`PIVOT_RATIO_MIN`] of the dof's own diagonal entry (`diag`, saved before factorising)
/// returns (dof, ratio).
fn cholesky_in_place(m: &mut DMatrix<f64>, diag: &[f64]) -> Result<(), (usize, f64)> {
    let n = m.nrows();
    let a = m.as_mut_slice();
    for j in 0..n {
        // Columns j and beyond as separate slices, so the updates below run on zipped column
        // slices without bounds checks (and vectorise).
        let (col_j, rest) = a[j * n..].split_at_mut(n);
        let d = col_j[j];
        let ratio = d / diag[j];
        // NaN (a zero diagonal over zero) is a failed pivot too.
        if ratio.is_nan() || ratio <= PIVOT_RATIO_MIN {
            return Err((j, ratio));
        }
        let ljj = d.sqrt();
        col_j[j] = ljj;
        for v in &mut col_j[j + 1..] {
            *v /= ljj;
        }
        for (k, col_c) in rest.chunks_exact_mut(n).enumerate() {
            let c = j + 1 + k;
            let lcj = col_j[c];
            if lcj == 0.0 {
                continue;
            }
            for (t, l) in col_c[c..].iter_mut().zip(&col_j[c..]) {
                *t -= l * lcj;
            }
        }
    }
    Ok(())
}

/// Solves L·Lᵀ·x = b in place (b in, x out) with the factor of [`cholesky_in_place`].
fn substitute(l: &DMatrix<f64>, x: &mut DVector<f64>) {
    let n = l.nrows();
    let a = l.as_slice();
    for j in 0..n {
        x[j] /= a[j + j * n];
        let xj = x[j];
        for i in j + 1..n {
            x[i] -= a[i + j * n] * xj;
        }
    }
    for j in (0..n).rev() {
        let mut v = x[j];
        for i in j + 1..n {
            v -= a[i + j * n] * x[i];
        }
        x[j] = v / a[j + j * n];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rel(a: f64, b: f64) -> f64 {
        (a - b).abs() / b.abs()
    }

    fn clamp(s: &mut AssemblyStructure, node: NodeId) {
        for d in s.node(node).dofs {
            s.prescribe(d, 0.0);
        }
    }

    /// A cantilever of two elements along an inclined axis, tip load across and along it:
    /// PL³/3EI and PL²/2EI, PL/EA, and the clamp's reactions balance the load.
    #[test]
    fn two_element_cantilever_matches_beam_theory() {
        let sec = Section {
            ea: 4.2e8,
            ei: 3.0e11,
        };
        let (l, ang) = (1200.0, -0.4_f64);
        let dir = Vector2::new(ang.cos(), ang.sin());
        let across = Vector2::new(-dir.y, dir.x);
        let p = 2500.0;
        for (load, axial) in [(across, false), (dir, true)] {
            let mut s = AssemblyStructure::new();
            let a = s.add_node(Vector2::new(10.0, 20.0), 0.0, Label::new("clamp", 0));
            let m = s.add_node(
                Vector2::new(10.0, 20.0) + dir * (0.3 * l),
                0.0,
                Label::new("mid", 0),
            );
            let b = s.add_node(
                Vector2::new(10.0, 20.0) + dir * l,
                0.0,
                Label::new("tip", 0),
            );
            s.add_beam(a, m, sec, 0.0, Label::new("beam", 1));
            s.add_beam(m, b, sec, 0.0, Label::new("beam", 2));
            clamp(&mut s, a);
            s.add_load(s.node(b).dofs[0], p * load.x);
            s.add_load(s.node(b).dofs[1], p * load.y);
            let mut solver = Solver::new();
            solver.solve(&s).expect("solve");
            let u = solver.node_displacement(&s, b);
            let d = Vector2::new(u.x, u.y).dot(&load);
            if axial {
                assert!(rel(d, p * l / sec.ea) < 1e-10, "{d}");
                assert!(solver.axial_force(&s, 0).map(|n| rel(n, p)).expect("n") < 1e-10);
            } else {
                assert!(rel(d, p * l.powi(3) / (3.0 * sec.ei)) < 1e-10, "{d}");
                assert!(rel(u.z, p * l * l / (2.0 * sec.ei)) < 1e-10, "{}", u.z);
            }
            let [rx, ry, rm] = s.node(a).dofs.map(|d| solver.reaction(d));
            assert!((rx + p * load.x).abs() < 1e-8 && (ry + p * load.y).abs() < 1e-8);
            // Moment of the reaction about the clamp balances the load's moment about it.
            let arm = dir * l;
            let m_load = arm.x * p * load.y - arm.y * p * load.x;
            assert!((rm + m_load).abs() < 1e-6 * p * l, "{rm} vs {m_load}");
        }
    }

    /// A bar clamped at both ends that "wants" to be ΔL longer: N = −E·A·ΔL/L, reactions push
    /// the clamps apart, nothing moves.
    #[test]
    fn held_bar_with_initial_elongation_is_compressed() {
        let sec = Section::steel_round(20.0);
        let mut s = AssemblyStructure::new();
        let a = s.add_node(Vector2::new(0.0, 0.0), 0.0, Label::new("a", 0));
        let b = s.add_node(Vector2::new(300.0, 400.0), 0.0, Label::new("b", 0));
        let bar = s.add_beam(a, b, sec, 0.05, Label::new("bar", 1));
        clamp(&mut s, a);
        clamp(&mut s, b);
        let mut solver = Solver::new();
        solver.solve(&s).expect("solve");
        let n = solver.axial_force(&s, bar).expect("n");
        assert!(rel(n, -sec.ea * 0.05 / 500.0) < 1e-12, "{n}");
        let rb = Vector2::new(
            solver.reaction(s.node(b).dofs[0]),
            solver.reaction(s.node(b).dofs[1]),
        );
        // the support holds node b back towards a: reaction along −(b − a)
        assert!((rb - Vector2::new(0.6, 0.8) * n).norm() < 1e-6 * n.abs());
    }

    /// A carrier-like node in a rotated frame (held across and in rotation, free along), tied by
    /// a spring to a displaced drive dof and by a beam to a clamp: springs in series.
    #[test]
    fn rotated_nodal_frame_and_springs_in_series() {
        let sec = Section {
            ea: 1.0e8,
            ei: 2.0e10,
        };
        let (l, phi, c, delta) = (500.0, 0.3_f64, 4.0e4, 0.02);
        let beam_dir = Vector2::new(1.0, 0.0);
        let mut s = AssemblyStructure::new();
        let clamp_node = s.add_node(Vector2::zeros(), 0.0, Label::new("clamp", 0));
        let carrier = s.add_node(beam_dir * l, phi, Label::new("carrier", 1));
        s.add_beam(clamp_node, carrier, sec, 0.0, Label::new("arm", 1));
        clamp(&mut s, clamp_node);
        let [across, along, rot] = s.node(carrier).dofs;
        s.prescribe(across, 0.0);
        s.prescribe(rot, 0.0);
        let drive = s.add_scalar_dof(Label::new("drive", 1));
        s.add_spring(along, Some(drive), c);
        s.prescribe(drive, delta);
        let mut solver = Solver::new();
        solver.solve(&s).expect("solve");
        // along-guide direction R(φ)ŷ makes angle φ with the beam's normal
        let e = Vector2::new(-phi.sin(), phi.cos());
        // the beam lies along x̂: e's axial part is e·x̂, its transverse part e·ŷ
        let (ca, sa) = (e.dot(&beam_dir), e.y);
        let k_beam = sec.ea / l * ca * ca + 12.0 * sec.ei / l.powi(3) * sa * sa;
        let u_along = c * delta / (c + k_beam);
        assert!(rel(solver.displacement(along), u_along) < 1e-10);
        assert!(rel(solver.reaction(drive), c * (delta - u_along)) < 1e-10);
        let u = solver.node_displacement(&s, carrier);
        assert!((Vector2::new(u.x, u.y) - e * u_along).norm() < 1e-12);
    }

    #[test]
    fn a_mechanism_is_a_singular_error_and_a_zero_length_beam_is_degenerate() {
        let mut s = AssemblyStructure::new();
        let a = s.add_node(Vector2::zeros(), 0.0, Label::new("a", 0));
        let b = s.add_node(Vector2::new(100.0, 0.0), 0.0, Label::new("b", 0));
        s.add_beam(a, b, Section::steel_round(10.0), 0.0, Label::new("bar", 1));
        // translations of a held, everything else free: the bar swings about a
        s.prescribe(s.node(a).dofs[0], 0.0);
        s.prescribe(s.node(a).dofs[1], 0.0);
        s.add_load(s.node(b).dofs[1], 1.0);
        let mut solver = Solver::new();
        assert!(matches!(solver.solve(&s), Err(FeError::Singular { .. })));
        // an unconnected hinge has no rotational stiffness at all
        let mut s2 = AssemblyStructure::new();
        let a = s2.add_node(Vector2::zeros(), 0.0, Label::new("a", 0));
        clamp(&mut s2, a);
        s2.add_hinge(a, Label::new("hinge", 7));
        let err = solver.solve(&s2).expect_err("singular");
        assert!(err.to_string().contains("rotation of hinge 7"), "{err}");
        let mut s3 = AssemblyStructure::new();
        let a = s3.add_node(Vector2::zeros(), 0.0, Label::new("a", 0));
        let b = s3.add_node(Vector2::zeros(), 0.0, Label::new("b", 0));
        s3.add_beam(a, b, Section::steel_round(10.0), 0.0, Label::new("stub", 3));
        assert!(matches!(
            solver.solve(&s3),
            Err(FeError::DegenerateBeam { beam }) if beam == Label::new("stub", 3)
        ));
    }
}
