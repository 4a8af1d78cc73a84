//! Where every source's samples go: the publishers, the validation of the messages, the counts
//! and the one `/diagnostics` report.

use rpkm_core::campaign::{Campaign, Pose};
use rpkm_msgs::{ActuatorState, CampaignInfo, DiagnosticArray, TcpMeasurement, Time};
use rpkm_transport::{dds::DdsNode, topic, Publisher};

use super::report::Tally;
use super::validate::{reject, Limits, Reject, RejectKind, Validator};
use super::END_OF_CAMPAIGN;
use crate::campaign_bag::{campaign_info, pose_messages};
use crate::node::live::LiveParams;
use crate::node::views::JointViews;
use crate::node::{diagnostic_array, Every, NodeContext};

/// The publishers and bookkeeping shared by the sources.
pub(super) struct Output {
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
}

impl Output {
    /// The publishers of node `ctx`, validating with `limits`; `source` names the input on
    /// /diagnostics.
    pub(super) fn open(
        ctx: &NodeContext,
        limits: Limits,
        source: &str,
        live: LiveParams,
    ) -> anyhow::Result<Self> {
        Ok(Self {
            states: ctx.publisher(&topic::ACTUATOR_STATE)?,
            measurements: ctx.publisher(&topic::TCP_MEASUREMENT)?,
            info: ctx.publisher(&topic::CAMPAIGN_INFO)?,
            diagnostics: ctx.publisher(&topic::DIAGNOSTICS)?,
            views: JointViews::open(ctx)?,
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
        })
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
    pub(super) fn pose(&mut self, c: &Campaign, pose: &Pose) -> anyhow::Result<()> {
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

    /// Validates and publishes a drive state from a live source.
    pub(super) fn state(&mut self, s: &ActuatorState, label: &str) -> anyhow::Result<()> {
        match self.validator.state(s, label) {
            Ok(()) => self.publish_state(s),
            Err(r) => {
                self.reject(r);
                Ok(())
            }
        }
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

    /// Publishes the /diagnostics status when its period has passed, and takes the changes
    /// the parameter services accepted (between samples: the next one is judged by them).
    pub(super) fn report_if_due(&mut self) -> anyhow::Result<()> {
        if let Some((p, names)) = self.live.poll() {
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
        }
        if self.report.due() {
            self.report_now()?;
        }
        Ok(())
    }

    /// Publishes the /diagnostics status now.
    pub(super) fn report_now(&mut self) -> anyhow::Result<()> {
        let status = self.tally.status(&self.status_name, &self.source);
        self.diagnostics.publish(&diagnostic_array(status))?;
        Ok(())
    }
}
