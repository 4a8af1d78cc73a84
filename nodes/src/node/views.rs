//! The standard views: what RViz, Foxglove, PlotJuggler and tf2 show of a running cell
//! without rpkm's interface package.
//!
//! - tcp_estimator: `geometry_msgs/PoseStamped` on `/rpkm/tcp_pose` (frame [`MACHINE_FRAME`])
//!   and `tf2_msgs/TFMessage` on `/tf` ([`MACHINE_FRAME`] → [`PLATFORM_FRAME`]), from every
//!   `view_every`-th TcpEstimate: position (x, y, 0) m, orientation the yaw ψ about z;
//! - ingest: `sensor_msgs/JointState` on `/joint_states` from every `view_every`-th accepted
//!   ActuatorState: joints `q1`..`q4`, position m, effort the drive force N (0 in follower
//!   mode, as the ActuatorState says), velocity empty (not measured).
//!
//! The views go on DDS only (on iceoryx2 the rpkm types are the views). Parameter `views`
//! (default: on when the node publishes on DDS) switches them; off, the node's sample path
//! only tests an `Option`. On, the messages are kept and filled in place; only every
//! `view_every`-th sample is converted and sent (default 100: 80 Hz of an 8 kHz stream).

use rpkm_msgs::{
    ActuatorState, JointState, PoseStamped, Quaternion, TcpEstimate, TfMessage, Transform,
    TransformStamped, Vector3,
};
use rpkm_transport::{topic, Backend, Publisher};

use super::context::{bad_param, NodeContext};
use super::declare::{ParamBound, ParamDefault, ParamSpec};
use crate::error::bad_input;

/// Parameter `views` (tcp_estimator and ingest; each node says what its views are). Its
/// default depends on the backend ([`on_by_default`]): the nodes serve it with theirs.
pub const VIEWS: ParamSpec = ParamSpec::fixed(
    "views",
    ParamDefault::Bool(false),
    "publish the standard views on DDS (default: on with DDS output)",
);
/// Parameter `view_every`.
pub const VIEW_EVERY_PARAM: ParamSpec = ParamSpec::live(
    "view_every",
    ParamDefault::U64(VIEW_EVERY),
    "publish the views of every N-th sample",
)
.bound(ParamBound::Count(VIEW_EVERY_RANGE.0, VIEW_EVERY_RANGE.1));

/// The fixed frame of the machine: the spec's absolute frame (y along the guides, x across,
/// z out of the plane), origin as the spec places it.
pub const MACHINE_FRAME: &str = "machine";
/// The platform frame: origin at the TCP, rotated by ψ about z.
pub const PLATFORM_FRAME: &str = "platform";
/// Joint names of the drives, in ActuatorState order.
pub const JOINT_NAMES: [&str; 4] = ["q1", "q2", "q3", "q4"];

/// Default of `view_every`.
pub const VIEW_EVERY: u64 = 100;
/// Range of `view_every`.
pub const VIEW_EVERY_RANGE: (u64, u64) = (1, 1_000_000);

/// Every `every`-th call of [`Decimator::due`] is true, the `every`-th first.
#[derive(Debug, Clone, Copy)]
pub struct Decimator {
    every: u64,
    count: u64,
}

impl Decimator {
    /// `every` ≥ 1.
    pub fn new(every: u64) -> Self {
        Self {
            every: every.max(1),
            count: 0,
        }
    }

    /// Whether this sample is one to view.
    pub fn due(&mut self) -> bool {
        self.count += 1;
        if self.count == self.every {
            self.count = 0;
            true
        } else {
            false
        }
    }
}

/// Whether the views are on unless parameter `views` says otherwise: with DDS output.
pub fn on_by_default(ctx: &NodeContext) -> bool {
    matches!(ctx.output, Backend::Dds | Backend::Both)
}

/// `view_every` if the views are on (parameter `views`, default `default_on`), else `None`.
/// Views asked for without DDS are bad configuration: they would go nowhere.
pub fn settings(ctx: &NodeContext, default_on: bool) -> anyhow::Result<Option<u64>> {
    let dds = on_by_default(ctx);
    let on = VIEWS
        .with_default(ParamDefault::Bool(default_on))
        .bool(&ctx.params)
        .map_err(bad_param)?;
    let every = VIEW_EVERY_PARAM.u64(&ctx.params).map_err(bad_param)?;
    if on && !dds {
        return Err(bad_input(format!(
            "node {}: views: true needs DDS output (the standard views are DDS only); \
             set backend dds or both, or views false",
            ctx.name
        )));
    }
    Ok(on.then_some(every))
}

/// Fills `pose` with the estimate: stamp, frame [`MACHINE_FRAME`], (x, y, 0) m, yaw ψ.
pub fn fill_pose(e: &TcpEstimate, pose: &mut PoseStamped) {
    pose.header.stamp = e.stamp;
    pose.pose.position.x = e.x;
    pose.pose.position.y = e.y;
    pose.pose.position.z = 0.0;
    pose.pose.orientation = Quaternion::about_z(e.psi);
}

/// Fills `tf` with the estimate as the transform [`MACHINE_FRAME`] → [`PLATFORM_FRAME`].
pub fn fill_transform(e: &TcpEstimate, tf: &mut TransformStamped) {
    tf.header.stamp = e.stamp;
    tf.transform = Transform {
        translation: Vector3 {
            x: e.x,
            y: e.y,
            z: 0.0,
        },
        rotation: Quaternion::about_z(e.psi),
    };
}

/// Fills `js` (names already set) with the drive state: positions m, efforts N.
pub fn fill_joint_state(s: &ActuatorState, js: &mut JointState) {
    js.header.stamp = s.stamp;
    js.position.clear();
    js.position.extend_from_slice(&s.position);
    js.effort.clear();
    js.effort.extend_from_slice(&s.force);
}

/// The TCP views of tcp_estimator.
pub struct TcpViews {
    pose_pub: Publisher<PoseStamped>,
    tf_pub: Publisher<TfMessage>,
    pose: PoseStamped,
    tf: TfMessage,
    every: Decimator,
}

impl TcpViews {
    /// The views' publishers on DDS, or `None` when [`settings`] says off.
    pub fn open(ctx: &NodeContext) -> anyhow::Result<Option<Self>> {
        let Some(every) = settings(ctx, on_by_default(ctx))? else {
            return Ok(None);
        };
        let mut pose = PoseStamped::default();
        pose.header.frame_id = MACHINE_FRAME.into();
        let mut tf = TransformStamped {
            child_frame_id: PLATFORM_FRAME.into(),
            ..Default::default()
        };
        tf.header.frame_id = MACHINE_FRAME.into();
        Ok(Some(Self {
            pose_pub: dds_publisher(ctx, &topic::TCP_POSE)?,
            tf_pub: dds_publisher(ctx, &topic::TF)?,
            pose,
            tf: TfMessage {
                transforms: vec![tf],
            },
            every: Decimator::new(every),
        }))
    }

    /// A new `view_every` (a parameter set while the node runs); counts again from 0.
    pub fn set_every(&mut self, every: u64) {
        self.every = Decimator::new(every);
    }

    /// Publishes the views of `e` if it is a `view_every`-th estimate.
    pub fn offer(&mut self, e: &TcpEstimate) -> anyhow::Result<()> {
        if !self.every.due() {
            return Ok(());
        }
        fill_pose(e, &mut self.pose);
        self.pose_pub.publish(&self.pose)?;
        for t in &mut self.tf.transforms {
            fill_transform(e, t);
        }
        self.tf_pub.publish(&self.tf)?;
        Ok(())
    }
}

/// The JointState view of ingest.
pub struct JointViews {
    publisher: Publisher<JointState>,
    msg: JointState,
    every: Decimator,
}

impl JointViews {
    /// The view's publisher on DDS, or `None` when [`settings`] says off (`default_on`: the
    /// setting without parameter `views`).
    pub fn open(ctx: &NodeContext, default_on: bool) -> anyhow::Result<Option<Self>> {
        let Some(every) = settings(ctx, default_on)? else {
            return Ok(None);
        };
        let msg = JointState {
            name: JOINT_NAMES.map(String::from).to_vec(),
            position: Vec::with_capacity(4),
            effort: Vec::with_capacity(4),
            ..Default::default()
        };
        Ok(Some(Self {
            publisher: dds_publisher(ctx, &topic::JOINT_STATES)?,
            msg,
            every: Decimator::new(every),
        }))
    }

    /// A new `view_every` (a parameter set while the node runs); counts again from 0.
    pub fn set_every(&mut self, every: u64) {
        self.every = Decimator::new(every);
    }

    /// The DDS topic the view goes on.
    pub fn topic(&self) -> &'static str {
        self.publisher.topic()
    }

    /// Publishes the view of `s` if it is a `view_every`-th state.
    pub fn offer(&mut self, s: &ActuatorState) -> anyhow::Result<()> {
        if self.every.due() {
            fill_joint_state(s, &mut self.msg);
            self.publisher.publish(&self.msg)?;
        }
        Ok(())
    }
}

fn dds_publisher<T: rpkm_transport::IpcMessage>(
    ctx: &NodeContext,
    t: &rpkm_transport::Topic<T>,
) -> anyhow::Result<Publisher<T>> {
    use anyhow::Context;
    ctx.transport
        .publisher_on(t, Backend::Dds)
        .with_context(|| format!("node {}: view {}", ctx.name, t.name()))
}

#[cfg(test)]
#[expect(
    clippy::float_cmp,
    reason = "exact values: parsed, copied or computed without rounding"
)]
mod tests {
    use super::*;
    use rpkm_msgs::Time;

    #[test]
    fn every_third_sample_is_viewed() {
        let mut d = Decimator::new(3);
        let due: Vec<u64> = (1..=10).filter(|_| d.due()).collect();
        assert_eq!(due, [3, 6, 9]);
        let mut all = Decimator::new(1);
        assert!((0..5).all(|_| all.due()));
    }

    #[test]
    fn the_pose_and_transform_carry_the_estimate_in_si_with_yaw_psi() {
        let e = TcpEstimate {
            stamp: Time {
                sec: 12,
                nanosec: 345,
            },
            x: 0.02,
            y: 1.65,
            psi: 0.7,
            ..Default::default()
        };
        let mut pose = PoseStamped::default();
        fill_pose(&e, &mut pose);
        let mut tf = TransformStamped::default();
        fill_transform(&e, &mut tf);
        let q = pose.pose.orientation;
        // yaw of a unit quaternion (ZYX convention), as tf2::getYaw computes it
        let yaw = (2.0 * (q.w * q.z + q.x * q.y)).atan2(1.0 - 2.0 * (q.y * q.y + q.z * q.z));
        assert!((yaw - 0.7).abs() < 1e-15, "{yaw}");
        assert_eq!(pose.header.stamp, e.stamp);
        assert_eq!((pose.pose.position.x, pose.pose.position.y), (0.02, 1.65));
        assert_eq!(tf.transform.rotation, q);
        assert_eq!(tf.transform.translation.y, 1.65);
    }
}
