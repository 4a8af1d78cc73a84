//! Where every source's samples go: the publishers, the validation of the messages, the counts
//! and the one `/diagnostics` report.

use rpkm_core::campaign::{Campaign, MeasuredPose};
use rpkm_msgs::{
    ActuatorState, CampaignInfo, DiagnosticArray, DiagnosticStatus, TcpMeasurement, Time,
};
use rpkm_transport::{dds::DdsNode, topic, Publisher};

use super::report::Tally;
use super::validate::{reject, InputLimits, Reject, RejectKind, Validator};
use super::END_OF_CAMPAIGN;
use crate::campaign_bag::{campaign_info, pose_messages};
use crate::node::lifecycle::{self, Lifecycle};
use crate::node::live::LiveParams;
use crate::node::params::NodeParams;
use crate::node::views::JointViews;
use crate::node::{shutdown, CommonArgs, Every, NodeContext};

/// The publishers and bookkeeping shared by the sources, and the node's lifecycle: only an
/// active ingest publishes samples.
pub(super) struct Output<'a> {
    states: Publisher<ActuatorState>,
    measurements: Publisher<TcpMeasurement>,
    info: Publisher<CampaignInfo>,
    diagnostics: Publisher<DiagnosticArray>,
    views: Option<JointViews>,
    validator: Validator,
    pub(super) tally: Tally,
    seq: u64,
    last_stamp: Time,
    report: Every,
    /// The parameter services; their accepted changes are taken between samples.
    live: LiveParams,
    /// Where the node's log lines go besides stderr: `/rosout`.
    dds: Option<std::sync::Arc<DdsNode>>,
    node: String,
    /// Its status name on /diagnostics.
    status_name: String,
    source: String,
    lifecycle: Lifecycle,
    /// What a lifecycle configure reads the parameters again with.
    ctx: &'a NodeContext,
    args: &'a CommonArgs,
}

impl<'a> Output<'a> {
    /// The publishers of node `ctx` (started as `args` say) and its JointState view,
    /// validating with `limits`; `source` names the input on /diagnostics.
    pub(super) fn open(
        (ctx, args): (&'a NodeContext, &'a CommonArgs),
        limits: InputLimits,
        source: &str,
        (live, views): (LiveParams, Option<JointViews>),
    ) -> anyhow::Result<Self> {
        Ok(Self {
            states: ctx.publisher(&topic::ACTUATOR_STATE)?,
            measurements: ctx.publisher(&topic::TCP_MEASUREMENT)?,
            info: ctx.publisher(&topic::CAMPAIGN_INFO)?,
            diagnostics: ctx.publisher(&topic::DIAGNOSTICS)?,
            views,
            validator: Validator::new(limits),
            tally: Tally::default(),
            seq: 0,
            last_stamp: Time::default(),
            report: Every::new(ctx.diagnostics_period()?),
            live,
            dds: ctx.transport.dds_node().cloned(),
            node: ctx.name.clone(),
            status_name: ctx.status_name.clone(),
            source: source.to_owned(),
            lifecycle: Lifecycle::open(ctx, lifecycle::start(args))?,
            ctx,
            args,
        })
    }

    /// Performs the lifecycle transition asked for, if any: configure reads the parameters
    /// again (the validation limits and `view_every`; the source and pacing stay).
    pub(super) fn serve_lifecycle(&mut self) {
        let (ctx, args) = (self.ctx, self.args);
        let validator = &mut self.validator;
        let views = &mut self.views;
        self.lifecycle.serve(ctx, || {
            let p = ctx
                .reread_params(args, "ingest", &super::declared())
                .map_err(|e| crate::error::error_chain(&e))?;
            let (limits, every) =
                super::configure(&p).map_err(|e| crate::error::error_chain(&e))?;
            validator.set_limits(limits);
            if let Some(v) = views.as_mut() {
                v.set_every(every);
            }
            Ok(())
        });
    }

    /// Holds a file or stdin source where it is while the node is not active (unconfigured
    /// or inactive), serving the lifecycle and reporting; `Ok(None)` when the node is to
    /// stop, else whether it waited.
    pub(super) fn wait_active(&mut self) -> anyhow::Result<Option<bool>> {
        let mut waited = false;
        loop {
            self.serve_lifecycle();
            if self.lifecycle.active() {
                return Ok(Some(waited));
            }
            if shutdown::requested() {
                return Ok(None);
            }
            waited = true;
            self.report_if_due()?;
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
    }

    /// Whether a live source's sample may go out: an inactive node takes it (no backlog at
    /// activation), counts it and publishes nothing.
    pub(super) fn publishing(&mut self) -> bool {
        let active = self.lifecycle.active();
        if !active {
            self.tally.dropped_inactive += 1;
        }
        active
    }

    /// Counts a reject and logs it: nothing the node drops goes unsaid.
    pub(super) fn reject(&mut self, r: Reject) {
        crate::node::log_line(&self.node, format_args!("rejected: {}", r.detail));
        self.tally.reject(r);
    }

    /// The campaign's CampaignInfo (source, comments, covariate names); `at` names the header.
    pub(super) fn info(&mut self, c: &Campaign, at: &str) -> anyhow::Result<()> {
        match campaign_info(c) {
            Ok(i) => self.info.publish(&i)?,
            Err(e) => self.reject(reject(RejectKind::Malformed, format!("{at}: {e}"))),
        }
        Ok(())
    }

    /// Validates and publishes one pose of a campaign (state, then its measurement).
    pub(super) fn pose(&mut self, c: &Campaign, pose: &MeasuredPose) -> anyhow::Result<()> {
        let label = format!("{}:{}", c.source, pose.line);
        let (mut state, measurement) =
            match pose_messages(c, usize::try_from(self.seq).unwrap_or(usize::MAX), pose) {
                Ok(m) => m,
                Err(e) => {
                    self.reject(reject(RejectKind::OutOfRange, format!("{label}: {e}")));
                    return Ok(());
                }
            };
        // seq counts the published states over the node's life, so that it increases across
        // campaigns and the estimates echo a unique number.
        state.seq = self.seq + 1;
        if let Err(r) = self.validator.state(&state, &label) {
            self.reject(r);
            return Ok(());
        }
        self.publish_state(&state)?;
        // A bad measurement does not hold back its state, which was fine.
        self.measurement(&measurement, &label)
    }

    /// The CampaignInfo of a live source that names its covariates.
    pub(super) fn info_message(&mut self, info: &CampaignInfo) -> anyhow::Result<()> {
        self.info.publish(info)?;
        Ok(())
    }

    /// Numbers a drive state of a live source that has no seq of its own (the next one
    /// published: a refused state takes no number), then validates and publishes it.
    pub(super) fn numbered_state(
        &mut self,
        mut s: ActuatorState,
        label: &str,
    ) -> anyhow::Result<()> {
        s.seq = self.seq + 1;
        self.state(&s, label)
    }

    /// The seq the next published state gets.
    pub(super) fn next_seq(&self) -> u64 {
        self.seq + 1
    }

    /// Validates and publishes a drive state from a live source.
    pub(super) fn state(&mut self, s: &ActuatorState, label: &str) -> anyhow::Result<()> {
        if !self.publishing() {
            return Ok(());
        }
        match self.validator.state(s, label) {
            Ok(()) => self.publish_state(s),
            Err(r) => {
                self.reject(r);
                Ok(())
            }
        }
    }

    /// Validates and publishes a measurement of a live source.
    pub(super) fn live_measurement(
        &mut self,
        m: &TcpMeasurement,
        label: &str,
    ) -> anyhow::Result<()> {
        if !self.publishing() {
            return Ok(());
        }
        self.measurement(m, label)
    }

    /// Validates and publishes a measurement.
    pub(super) fn measurement(&mut self, m: &TcpMeasurement, label: &str) -> anyhow::Result<()> {
        match self.validator.measurement(m, label) {
            Ok(()) => {
                self.measurements.publish(m)?;
                self.tally.accepted_measurements += 1;
            }
            Err(r) => self.reject(r),
        }
        Ok(())
    }

    fn publish_state(&mut self, state: &ActuatorState) -> anyhow::Result<()> {
        self.states.publish(state)?;
        if let Some(v) = self.views.as_mut() {
            v.offer(state)?;
        }
        self.seq = state.seq;
        self.last_stamp = state.stamp;
        self.tally.accepted_states += 1;
        Ok(())
    }

    /// The end-of-campaign marker: the calibrator runs when it receives it.
    pub(super) fn end_marker(&mut self) -> anyhow::Result<()> {
        self.measurements.publish(&TcpMeasurement {
            stamp: self.last_stamp,
            setup: END_OF_CAMPAIGN.to_owned(),
            instrument: TcpMeasurement::NONE,
            ..Default::default()
        })?;
        Ok(())
    }

    /// Takes the changes the parameter services accepted (`now`: without waiting for the
    /// check's period): the limits and `view_every` apply here, and the parameters come back
    /// for what the source applies itself (the followers of a JointState source).
    pub(super) fn parameter_changes(&mut self, now: bool) -> anyhow::Result<Option<NodeParams>> {
        let changed = if now {
            self.live.poll_now()
        } else {
            self.live.poll()
        };
        let Some((p, names)) = changed else {
            return Ok(None);
        };
        let (limits, every) = super::configure(&p)?;
        self.validator.set_limits(limits);
        if let Some(v) = self.views.as_mut() {
            v.set_every(every);
        }
        let text = format!("parameters set: {}", names.join(", "));
        crate::node::log_line(&self.node, &text);
        if let Some(dds) = &self.dds {
            dds.rosout(crate::node::severity(&text), &text, file!(), line!());
        }
        Ok(Some(p))
    }

    /// Publishes the /diagnostics status when its period has passed, takes the changes the
    /// parameter services accepted (between samples: the next one is judged by them) and
    /// performs a lifecycle transition asked for.
    pub(super) fn report_if_due(&mut self) -> anyhow::Result<()> {
        self.serve_lifecycle();
        self.parameter_changes(false)?;
        self.report_due_with(|_| {})
    }

    /// Publishes the /diagnostics status, `annotate`d by the source, when its period has
    /// passed.
    pub(super) fn report_due_with(
        &mut self,
        annotate: impl FnOnce(&mut DiagnosticStatus),
    ) -> anyhow::Result<()> {
        if self.report.due() {
            self.report_now_with(annotate)?;
            // a subscriber that joined late gets the campaign's info now
            self.info.deliver_history()?;
        }
        Ok(())
    }

    /// Publishes the /diagnostics status now.
    pub(super) fn report_now(&mut self) -> anyhow::Result<()> {
        self.report_now_with(|_| {})
    }

    /// Publishes the /diagnostics status, `annotate`d by the source, now.
    pub(super) fn report_now_with(
        &mut self,
        annotate: impl FnOnce(&mut DiagnosticStatus),
    ) -> anyhow::Result<()> {
        let mut status = self.tally.status(&self.status_name, &self.source);
        annotate(&mut status);
        self.diagnostics.publish(&self.ctx.diagnostics(status))?;
        Ok(())
    }
}
