//! The Scissors-Kinematics as a planar frame, laid on an assembled pose.
//!
//! Mesh (node positions from `Params` and the pose, as the rigid model places the joints):
//! - platform: the TCP node and one joint node per rod, joined by five spokes from the TCP and
//!   by the edges A1–A2, A2–A3, A3–A4, A4–A1 and A4–A5, so the plate is triangulated and its
//!   members work mostly axially, as a plate does in its plane. Rod 5's joint keeps its own node
//!   (it lies on rod 1's joint in the nominal design, yet is a separate bearing);
//! - carriers: a guide node per carrier at o + e·s (its nodal frame turned by γ so that u1 is
//!   across the guide and u2 along it; across and rotation held by the guide), an arm to each
//!   rod joint B_i it carries, and the edge B4–B5 on carrier 4 (the parallel-holder's two
//!   joints);
//! - rods: one beam from its platform joint to its carrier joint, hinged at both ends as
//!   [`RodEndJoint`] says;
//! - drives: the carrier's along-guide dof prescribed (rigid drive) or tied to a prescribed
//!   drive dof by a spring (compliant drive); a follower's carrier slides freely.

use super::assembly::{AssemblyStructure, BeamId, DofId, NodeId};
use super::beam::{Section, STEEL_E_N_PER_MM2};
use super::error::FeError;
use super::error::Label;
use crate::elastic::spring::{Followers, Stiffness};
use crate::geometry::{carrier_joint, guide_frame, platform_joint};
use crate::params::{Params, RODS};
use nalgebra::Vector2;

/// Rod length the default rod sections are sized on, mm (all five rods are 950 mm nominal).
pub const NOMINAL_ROD_LENGTH_MM: f64 = 950.0;

/// Rod-end joints.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum RodEndJoint {
    /// Ideal revolute joint: the rod turns freely, no moment is transmitted (the real machine).
    Pinned,
    /// Revolute joint with a rotational spring, N·mm/rad (friction or a flexure).
    Rotational(f64),
    /// The rod is welded to the platform and carrier: the frame carries bending.
    Rigid,
}

/// Stiffness of the finite-element model.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FeStiffness {
    /// Sections of rods 1..=5.
    pub rod: [Section; 5],
    /// Section of every platform member (spokes and edges).
    pub platform: Section,
    /// Section of every carrier member (arms and carrier 4's edge).
    pub carrier: Section,
    /// Joints at both ends of every rod.
    pub joint: RodEndJoint,
    /// Along-guide stiffness of drives 1..=4 (servo and transmission), N/mm; `None` = the
    /// carrier sits exactly at its commanded position (integral action).
    pub drive: [Option<f64>; 4],
}

/// Section of a solid steel round rod whose axial stiffness E·A/L over `length` is
/// `axial_stiffness` (N/mm): A = k·L/E, I = A²/(4π).
pub fn rod_section(axial_stiffness: f64, length: f64) -> Section {
    let area = axial_stiffness * length / STEEL_E_N_PER_MM2;
    Section {
        ea: axial_stiffness * length,
        ei: STEEL_E_N_PER_MM2 * area * area / (4.0 * std::f64::consts::PI),
    }
}

impl FeStiffness {
    /// Platform members by default: steel 400 mm deep in the plane, 80 mm thick (the platform
    /// carries the spindle; a massive part next to a rod).
    pub const DEFAULT_PLATFORM_WIDTH_MM: f64 = 400.0;
    pub const DEFAULT_PLATFORM_THICKNESS_MM: f64 = 80.0;
    /// Carrier members by default: steel 400 mm deep, 100 mm thick (carriage plates). The arms
    /// from the guide to the rod joints (320-574 mm) bend, and they are what the frame's
    /// compliance mostly is: with these sections the FE drive forces are about 1.3 % below the
    /// spring model's (the spring's k lumps rod, joints and carrier and is calibrated on the
    /// thesis; see docs/elastic-methods.md).
    pub const DEFAULT_CARRIER_WIDTH_MM: f64 = 400.0;
    pub const DEFAULT_CARRIER_THICKNESS_MM: f64 = 100.0;

    /// The FE counterpart of a spring-model stiffness: each rod a solid steel round rod with the
    /// spring's axial stiffness over 950 mm (the spring's k is the rod's E·A/L, so for pure axial
    /// behaviour the two models agree), the drives' compliance as the spring's carriers', pinned
    /// joints, and the default platform and carrier sections.
    pub fn matching(spring: &Stiffness) -> FeStiffness {
        FeStiffness {
            rod: spring.rod.map(|k| rod_section(k, NOMINAL_ROD_LENGTH_MM)),
            platform: Section::steel_rectangle(
                Self::DEFAULT_PLATFORM_WIDTH_MM,
                Self::DEFAULT_PLATFORM_THICKNESS_MM,
            ),
            carrier: Section::steel_rectangle(
                Self::DEFAULT_CARRIER_WIDTH_MM,
                Self::DEFAULT_CARRIER_THICKNESS_MM,
            ),
            joint: RodEndJoint::Pinned,
            drive: spring.carrier,
        }
    }

    /// Platform and carriers `factor` times stiffer (a nearly rigid frame: only the rods and
    /// drives deform, as in the spring model).
    #[must_use]
    pub fn with_stiff_frame(mut self, factor: f64) -> FeStiffness {
        self.platform = self.platform.scaled(factor);
        self.carrier = self.carrier.scaled(factor);
        self
    }

    /// Every value finite and positive.
    pub fn validate(&self) -> Result<(), FeError> {
        let bad = |what: Label, v: f64| -> Result<(), FeError> {
            if v > 0.0 && v.is_finite() {
                Ok(())
            } else {
                Err(FeError::BadStiffness { what, value: v })
            }
        };
        for (i, r) in self.rod.iter().enumerate() {
            bad(Label::new("rod E·A", i + 1), r.ea)?;
            bad(Label::new("rod E·I", i + 1), r.ei)?;
        }
        bad(Label::new("platform E·A", 0), self.platform.ea)?;
        bad(Label::new("platform E·I", 0), self.platform.ei)?;
        bad(Label::new("carrier E·A", 0), self.carrier.ea)?;
        bad(Label::new("carrier E·I", 0), self.carrier.ei)?;
        if let RodEndJoint::Rotational(k) = self.joint {
            bad(Label::new("joint rotational stiffness", 0), k)?;
        }
        for (j, c) in self.drive.iter().enumerate() {
            if let Some(c) = c {
                bad(Label::new("drive stiffness", j + 1), *c)?;
            }
        }
        Ok(())
    }
}

impl Default for FeStiffness {
    fn default() -> Self {
        FeStiffness::matching(&Stiffness::default())
    }
}

/// Where the mesh lies and what it is loaded with.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Placement {
    /// Platform pose (x, y, ψ) of the mesh, mm and rad.
    pub pose: [f64; 3],
    /// Carrier positions along the guides (the q coordinate), mm.
    pub carrier: [f64; 4],
    /// Initial elongation of rods 1..=5, mm.
    pub rod_elongation: [f64; 5],
    /// Prescribed displacement of the active drives, mm.
    pub drive_displacement: [f64; 4],
    pub followers: Followers,
}

/// Where the machine's parts sit in the structure.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Layout {
    pub tcp: NodeId,
    pub platform_joint: [NodeId; 5],
    pub rod: [BeamId; 5],
    /// The prescribed dof whose reaction is the drive force (`None` for followers).
    pub drive: [Option<DofId>; 4],
}

/// Builds the frame of `p` in `placement` into `s` (cleared first).
pub(crate) fn build(
    s: &mut AssemblyStructure,
    p: &Params,
    k: &FeStiffness,
    placement: &Placement,
) -> Layout {
    s.clear();
    let [x, y, _] = placement.pose;
    let tcp = s.add_node(Vector2::new(x, y), 0.0, Label::new("TCP", 0));
    let platform_joint = build_platform(s, k, p, tcp, placement.pose);
    let (carrier_joint_node, drive) = build_carriers(s, k, p, placement);
    let mut rod = [0; 5];
    for (i, r) in rod.iter_mut().enumerate() {
        let a = rod_end(
            s,
            k.joint,
            platform_joint[i],
            Label::new("rod end at platform", i + 1),
        );
        let b = rod_end(
            s,
            k.joint,
            carrier_joint_node[i],
            Label::new("rod end at carrier", i + 1),
        );
        *r = s.add_beam(
            a,
            b,
            k.rod[i],
            placement.rod_elongation[i],
            Label::new("rod", i + 1),
        );
    }
    Layout {
        tcp,
        platform_joint,
        rod,
        drive,
    }
}

fn build_platform(
    s: &mut AssemblyStructure,
    k: &FeStiffness,
    p: &Params,
    tcp: NodeId,
    [x, y, psi]: [f64; 3],
) -> [NodeId; 5] {
    let mut joint = [0; 5];
    for (i, n) in joint.iter_mut().enumerate() {
        let pos = platform_joint(p, &RODS[i], x, y, psi);
        *n = s.add_node(pos, 0.0, Label::new("platform joint", i + 1));
        s.add_beam(
            tcp,
            *n,
            k.platform,
            0.0,
            Label::new("platform spoke", i + 1),
        );
    }
    // Edges around the plate (rods 1-4 at its corners) and from rod 4's joint to rod 5's.
    let edges = [(0, 1), (1, 2), (2, 3), (3, 0), (3, 4)];
    for (e, (a, b)) in edges.into_iter().enumerate() {
        s.add_beam(
            joint[a],
            joint[b],
            k.platform,
            0.0,
            Label::new("platform edge", e + 1),
        );
    }
    joint
}

/// Carrier guide nodes, arms and drives; returns the carrier joint node of each rod and the
/// drive dofs.
fn build_carriers(
    s: &mut AssemblyStructure,
    k: &FeStiffness,
    p: &Params,
    placement: &Placement,
) -> ([NodeId; 5], [Option<DofId>; 4]) {
    let mut guide_node = [0; 4];
    let mut drive = [None; 4];
    for j in 0..4 {
        // Rods 1-4 hang on carriers 1-4 in order: rod j's guide is carrier j's.
        let g = RODS[j].guide;
        let (o, e, _) = guide_frame(p, g);
        let pos = o + e * placement.carrier[j];
        let node = s.add_node(pos, p[g.gamma_index()], Label::new("carrier", j + 1));
        let [across, along, rotation] = s.node(node).dofs;
        s.prescribe(across, 0.0);
        s.prescribe(rotation, 0.0);
        guide_node[j] = node;
        if placement.followers[j] {
            continue;
        }
        let held = match k.drive[j] {
            None => along,
            Some(c) => {
                let d = s.add_scalar_dof(Label::new("drive", j + 1));
                s.add_spring(along, Some(d), c);
                d
            }
        };
        s.prescribe(held, placement.drive_displacement[j]);
        drive[j] = Some(held);
    }
    let mut joint = [0; 5];
    for (i, n) in joint.iter_mut().enumerate() {
        let rod = &RODS[i];
        let pos = carrier_joint(p, rod, placement.carrier[rod.actuator]);
        *n = s.add_node(pos, 0.0, Label::new("carrier joint", i + 1));
        s.add_beam(
            guide_node[rod.actuator],
            *n,
            k.carrier,
            0.0,
            Label::new("carrier arm", i + 1),
        );
    }
    s.add_beam(
        joint[3],
        joint[4],
        k.carrier,
        0.0,
        Label::new("carrier edge", 4),
    );
    (joint, drive)
}

/// The node a rod attaches to at `joint`: a hinge (own rotation) for a revolute joint, with a
/// rotational spring to the joint node when it has one; the joint node itself when rigid.
fn rod_end(s: &mut AssemblyStructure, kind: RodEndJoint, joint: NodeId, label: Label) -> NodeId {
    match kind {
        RodEndJoint::Rigid => joint,
        RodEndJoint::Pinned => s.add_hinge(joint, label),
        RodEndJoint::Rotational(kr) => {
            let h = s.add_hinge(joint, label);
            let (rj, rh) = (s.node(joint).dofs[2], s.node(h).dofs[2]);
            s.add_spring(rj, Some(rh), kr);
            h
        }
    }
}
