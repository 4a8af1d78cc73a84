//! The node: its inputs, when a campaign ends, the calibration published, its history, the
//! loop.

use super::accumulator::Accumulator;
use super::goal::{goal_options, goal_result};
use super::job::{calibrate_campaign, calibrate_job, CalibratorOptions, Job, JobOutcome};
use super::params::{
    configure, declared, online_settings, Settings, HISTORY, HISTORY_MACHINE, HISTORY_RETRY,
    HISTORY_SPOOL, HISTORY_SPOOL_MAX, PARAMS, STATE_BUFFER,
};
use crate::node::calibrate_action::{CalibrateAction, Running};
use crate::node::context::{bad_param, status, CommonArgs, Every, Idle, NodeContext};
use crate::node::declare::served;
use crate::node::geometry::parameters_msg;
use crate::node::history::{HistorySettings, NodeHistory, Said};
use crate::node::ingest::END_OF_CAMPAIGN;
use crate::node::lifecycle::Lifecycle;
use crate::node::live::LiveParams;
use crate::node::online_tracker::{report_warning, state_name, tie_values, OnlineWorker};
use rpkm_core::calib;
use rpkm_core::online::{TieSoFar, TIE_EVIDENCE_CHI2};
use rpkm_core::params::Model;
use rpkm_msgs::calibrate_action::{CalibrateGoal, CalibrateResult};
use rpkm_msgs::{
    ActuatorState, CampaignInfo, Diagnosis, DiagnosticArray, DiagnosticStatus, Parameters,
    TcpMeasurement,
};
use rpkm_transport::dds_actions::GoalEnd;
use rpkm_transport::{topic, Publisher, Subscriber};
use std::time::{Duration, Instant};

/// The machine's history of the parameters `history`, `history_machine`, `history_spool`,
/// `history_spool_max`, `history_retry_s` (None when off).
fn open_history(ctx: &NodeContext) -> anyhow::Result<Option<NodeHistory>> {
    let p = &ctx.params;
    let location = HISTORY.string(p).map_err(bad_param)?;
    if location.is_empty() {
        return Ok(None);
    }
    let mut machine = HISTORY_MACHINE.string(p).map_err(bad_param)?;
    if machine.is_empty() {
        machine = crate::node::history::default_machine(&ctx.status_name, &ctx.name);
    }
    let spool = match HISTORY_SPOOL.string(p).map_err(bad_param)? {
        s if s.is_empty() => crate::node::history::default_spool(&machine),
        s => s.into(),
    };
    let settings = HistorySettings {
        location,
        machine,
        source: ctx.status_name.clone(),
        spool,
        spool_max: usize::try_from(HISTORY_SPOOL_MAX.u64(p).map_err(bad_param)?)
            .unwrap_or(usize::MAX),
        first_retry: Duration::from_secs_f64(HISTORY_RETRY.f64(p).map_err(bad_param)?),
    };
    let (h, notes) = NodeHistory::open(&settings)?;
    ctx.log(format!("history: {}", h.describe()));
    for n in notes {
        ctx.log(format!("WARN: history: {n}"));
    }
    if let Some(why) = h.away() {
        ctx.log(format!(
            "WARN: history: the server is away ({why}): records wait in {}, tried again \
             from {:.1} s on",
            settings.spool.display(),
            settings.first_retry.as_secs_f64()
        ));
    }
    Ok(Some(h))
}

/// The node's outputs.
pub(super) struct Outputs {
    pub(super) parameters: Publisher<Parameters>,
    pub(super) diagnosis: Publisher<Diagnosis>,
    diagnostics: Publisher<DiagnosticArray>,
}

/// What the node's loop keeps between samples.
pub(super) struct Calibrator {
    acc: Accumulator,
    online: Option<OnlineWorker>,
    temp_name: String,
    last_measurement: Option<Instant>,
    calibrations: u64,
    /// The last status: level and message.
    last: (u8, String),
    /// The online tracker's step still "this or that" at its last report.
    pub(super) tie: Option<TieSoFar>,
    /// The machine's history, where the node records (parameter `history`).
    history: Option<NodeHistory>,
}

impl Calibrator {
    fn campaign_info(&mut self, info: &CampaignInfo) {
        if let Some(name) = info.covariate_names.first() {
            self.temp_name.clone_from(name);
        }
        if let Err(e) = self.acc.info(info) {
            self.last = (DiagnosticStatus::WARN, format!("campaign info: {e:#}"));
        }
    }

    pub(super) fn state(&mut self, s: &ActuatorState) {
        self.acc.state(s);
        if let Some(w) = &mut self.online {
            w.offer(s);
        }
    }

    /// Publishes what the online tracker reported; whether it reported anything.
    fn online_reports(
        &mut self,
        ctx: &NodeContext,
        out: &Outputs,
        model: Model,
    ) -> anyhow::Result<bool> {
        let Some(w) = &self.online else {
            return Ok(false);
        };
        let mut worked = false;
        while let Ok(report) = w.rx.try_recv() {
            worked = true;
            let r = match report {
                Ok(r) => r,
                Err(e) => {
                    self.last = (DiagnosticStatus::WARN, format!("online calibration: {e}"));
                    continue;
                }
            };
            self.tie = r.tie;
            out.parameters
                .publish(&parameters_msg(&r.params, model, &r.sigma))?;
            if let Some(warning) = report_warning(&r, &self.temp_name) {
                let warning = match self.history.as_mut().and_then(|h| h.event(&r, &warning)) {
                    None => warning,
                    Some(said) => format!("{warning}; {said}"),
                };
                ctx.log(&warning);
                self.last = (DiagnosticStatus::WARN, warning);
                let mut t = vec![("online_t_s", format!("{:.3}", r.t))];
                t.extend(tie_values(&r));
                out.diagnostics.publish(&ctx.diagnostics(status(
                    self.last.0,
                    &ctx.status_name,
                    self.last.1.clone(),
                    t,
                )))?;
            }
        }
        Ok(worked)
    }

    /// Pairs one measurement with its state; whether the campaign ends with it.
    pub(super) fn measurement(
        &mut self,
        m: &TcpMeasurement,
        states: &Subscriber<ActuatorState>,
        every: u64,
    ) -> anyhow::Result<bool> {
        if m.setup == END_OF_CAMPAIGN {
            return Ok(true);
        }
        // Its state may have arrived after the drain above (a fast publisher interleaves
        // state, measurement, state, ...): drain the states again before pairing.
        if !self.acc.has_state_for(m) {
            while let Some(s) = states.try_recv()? {
                self.acc.state(&s);
            }
        }
        match self.acc.measurement(m) {
            Ok(_) => self.last_measurement = Some(Instant::now()),
            Err(e) => self.last = (DiagnosticStatus::WARN, format!("measurement: {e:#}")),
        }
        Ok(every > 0 && self.acc.measurements >= every)
    }

    /// Takes the drive states (first: ingest publishes a pose's state before its
    /// measurement), then the measurements up to a campaign's end; (whether any came,
    /// whether a campaign ended).
    fn drain(
        &mut self,
        states: &Subscriber<ActuatorState>,
        measurements: &Subscriber<TcpMeasurement>,
        every: u64,
    ) -> anyhow::Result<(bool, bool)> {
        let mut worked = false;
        while let Some(s) = states.try_recv()? {
            self.state(&s);
            worked = true;
        }
        while let Some(m) = measurements.try_recv()? {
            if self.measurement(&m, states, every)? {
                return Ok((true, true));
            }
            worked = true;
        }
        Ok((worked, false))
    }

    /// Whether the campaign so far has been idle for `idle_end` seconds.
    fn idle_ended(&self, idle_end: f64) -> bool {
        idle_end > 0.0
            && self.acc.measurements > 0
            && self
                .last_measurement
                .is_some_and(|t| t.elapsed().as_secs_f64() >= idle_end)
    }

    /// Calibrates the campaign so far and publishes the outcome.
    pub(super) fn calibrate(
        &mut self,
        ctx: &NodeContext,
        out: &Outputs,
        options: &CalibratorOptions,
    ) -> anyhow::Result<()> {
        let n = self.acc.measurements;
        let result = self.acc.take().and_then(|(c, noise)| {
            let stated = CalibratorOptions {
                noise,
                ..options.clone()
            };
            calibrate_campaign(&c, &stated)
        });
        self.publish(ctx, out, n, result.as_ref())
    }

    /// Publishes a calibration of `n` measurements (Parameters, Diagnosis) or why it failed,
    /// and says it on /diagnostics and in the log.
    fn publish(
        &mut self,
        ctx: &NodeContext,
        out: &Outputs,
        n: u64,
        result: Result<&JobOutcome, &anyhow::Error>,
    ) -> anyhow::Result<()> {
        self.last = match result {
            Ok(o) => {
                self.calibrations += 1;
                out.parameters.publish(&o.parameters)?;
                let recorded = self.record_calibration(o);
                for held in crate::words::held(&o.calibration.effects) {
                    ctx.log(format!("WARN: {held}"));
                }
                match &o.diagnosis {
                    Some(Ok(d)) => out.diagnosis.publish(d)?,
                    Some(Err(e)) => ctx.log(format!("no diagnosis: {e}")),
                    None => {}
                }
                let (level, history) = match recorded {
                    Some(Said { ok: true, text }) => {
                        (DiagnosticStatus::OK, format!("; history: {text}"))
                    }
                    Some(Said { ok: false, text }) => {
                        (DiagnosticStatus::WARN, format!("; history: {text}"))
                    }
                    None => (DiagnosticStatus::OK, String::new()),
                };
                (
                    level,
                    format!(
                        "calibration {}: {}, RMS {:.2} µm, condition {}{history}",
                        self.calibrations,
                        o.measurements_text(),
                        crate::units::um_from_m(o.parameters.cal_rms),
                        crate::words::condition_short(o.parameters.condition_number)
                    ),
                )
            }
            Err(e) => (
                DiagnosticStatus::ERROR,
                format!("calibration of {n} measurements failed: {e:#}"),
            ),
        };
        ctx.log(&self.last.1);
        let values = vec![("calibrations", self.calibrations.to_string())];
        out.diagnostics.publish(&ctx.diagnostics(status(
            self.last.0,
            &ctx.status_name,
            self.last.1.clone(),
            values,
        )))?;
        Ok(())
    }

    /// Executes a goal of `~/calibrate`: the campaign it names, or the one collected (taken
    /// only when its calibration succeeds), calibrated by the node's options with the goal's
    /// over them; a success is published as the end marker's calibration is.
    fn execute(
        &mut self,
        ctx: &NodeContext,
        out: &Outputs,
        options: &CalibratorOptions,
        (running, goal): (Running, CalibrateGoal),
        meanwhile: &dyn Fn(),
    ) -> anyhow::Result<()> {
        let result = self.goal_outcome(options, &running, &goal, meanwhile);
        // stopped part-way (the calibration or the diagnosis), or done before the cancel
        // took effect
        let stopped = result.as_ref().err().is_some_and(|e| {
            matches!(
                e.downcast_ref::<calib::CalibrationError>(),
                Some(calib::CalibrationError::Cancelled)
            )
        });
        let cancelled = running.cancelled() || stopped;
        let (end, reply) = match (result, cancelled) {
            (_, true) => {
                let message = if stopped {
                    format!("stopped during {}", running.stage())
                } else {
                    "the work was done when the cancel was seen".to_owned()
                };
                (
                    GoalEnd::Canceled,
                    CalibrateResult {
                        message,
                        ..CalibrateResult::default()
                    },
                )
            }
            (Ok((o, n)), false) => {
                if goal.campaign_file.is_empty() {
                    // the collected campaign is calibrated: the next one starts empty
                    self.acc.take()?;
                }
                self.publish(ctx, out, n, Ok(&o))?;
                (GoalEnd::Succeeded, goal_result(&o, &self.last.1))
            }
            (Err(e), false) => {
                let reply = CalibrateResult {
                    message: crate::error::error_chain(&e),
                    ..CalibrateResult::default()
                };
                (GoalEnd::Aborted, reply)
            }
        };
        running.finish(ctx, end, reply);
        Ok(())
    }

    /// The calibration a goal asks for, and the number of measurements of its campaign.
    fn goal_outcome(
        &self,
        options: &CalibratorOptions,
        running: &Running,
        goal: &CalibrateGoal,
        meanwhile: &dyn Fn(),
    ) -> anyhow::Result<(JobOutcome, u64)> {
        let (campaign, noise) = if goal.campaign_file.is_empty() {
            anyhow::ensure!(
                self.acc.measurements > 0,
                "no measurements collected since the last calibration: name a campaign_file, \
                 or publish the campaign first"
            );
            self.acc.peek()?
        } else {
            let path = std::path::Path::new(&goal.campaign_file);
            let c = crate::input::read_campaign(path)?;
            (c, rpkm_core::noise::NoiseModel::default())
        };
        let validation = match goal.validation_file.as_str() {
            "" => None,
            path => Some(crate::input::read_campaign(std::path::Path::new(path))?),
        };
        let o = goal_options(options, goal, noise)?;
        // what the node answers while the goal runs, at each LM iteration and every few
        // milliseconds of the diagnosis
        let observe = |p: &calib::Progress| {
            meanwhile();
            running.observe(p)
        };
        let diagnosing = || running.diagnosing();
        let cancelled = || {
            meanwhile();
            running.cancelled()
        };
        let job = Job {
            campaign: &campaign,
            validation: validation.as_ref(),
            effects: (!goal.effects.is_empty()).then_some(goal.effects.as_str()),
            diagnose: !goal.skip_diagnosis,
            progress: Some(&observe),
            diagnosing: Some(&diagnosing),
            cancelled: Some(&cancelled),
        };
        let n = u64::try_from(campaign.poses.len()).unwrap_or(u64::MAX);
        Ok((calibrate_job(&job, &o)?, n))
    }

    /// Records a calibration in the machine's history, if the node keeps one: what changed
    /// since the previous one, or that it waits, or why it was not recorded.
    fn record_calibration(&mut self, o: &JobOutcome) -> Option<Said> {
        self.history.as_mut().map(|h| {
            h.calibration(&crate::node::history::Calibrated {
                campaign: &o.campaign,
                calibration: &o.calibration,
                noise: &o.noise,
                val_rms_m: o.parameters.val_rms,
                verdict: o.verdict.as_ref().map(|v| v.1.as_str()),
            })
        })
    }

    /// Tries a history server away again when due; says on /diagnostics and in the log
    /// when it answers again (the waiting records recorded) or is found away.
    fn history_retry(&mut self, ctx: &NodeContext, out: &Outputs) -> anyhow::Result<()> {
        let Some(said) = self
            .history
            .as_mut()
            .map(NodeHistory::retry)
            .transpose()?
            .flatten()
        else {
            return Ok(());
        };
        let level = if said.ok {
            DiagnosticStatus::OK
        } else {
            DiagnosticStatus::WARN
        };
        ctx.log(if said.ok {
            said.text.clone()
        } else {
            format!("WARN: {}", said.text)
        });
        self.last = (level, said.text);
        self.publish_status(ctx, out)
    }

    /// The periodic /diagnostics status: the last message and the counts.
    fn publish_status(&self, ctx: &NodeContext, out: &Outputs) -> anyhow::Result<()> {
        let (level, message) = (self.last.0, self.last.1.clone());
        out.diagnostics.publish(&ctx.diagnostics(status(
            level,
            &ctx.status_name,
            message,
            self.report_values(),
        )))?;
        Ok(())
    }

    /// The periodic /diagnostics values.
    pub(super) fn report_values(&self) -> Vec<(&'static str, String)> {
        let online = |f: fn(&OnlineWorker) -> u64| self.online.as_ref().map_or(0, f).to_string();
        vec![
            ("calibrations", self.calibrations.to_string()),
            ("pending_measurements", self.acc.measurements.to_string()),
            ("unpaired_measurements", self.acc.unpaired.to_string()),
            ("unmeasured_poses", self.acc.unmeasured.to_string()),
            ("online_samples", online(|w| w.offered)),
            ("online_dropped", online(|w| w.dropped)),
            (
                "online_forces_not_measured",
                online(|w| w.forces_not_measured),
            ),
        ]
        .into_iter()
        .chain(self.history.iter().flat_map(NodeHistory::values))
        .chain(self.tie.iter().flat_map(|t| {
            // a tie still open: which two, and how far the evidence has come
            [
                (
                    "online_tie",
                    format!("{} or {}", state_name(t.named), state_name(t.runner_up)),
                ),
                (
                    "online_tie_evidence_chi2",
                    format!("{:.1} of {TIE_EVIDENCE_CHI2:.1}", t.evidence.chi2),
                ),
            ]
        }))
        .collect()
    }
}

/// Runs the node until SIGINT/SIGTERM.
impl Outputs {
    fn open(ctx: &NodeContext) -> anyhow::Result<Self> {
        Ok(Self {
            parameters: ctx.publisher(&topic::PARAMETERS)?,
            diagnosis: ctx.publisher(&topic::DIAGNOSIS)?,
            diagnostics: ctx.publisher(&topic::DIAGNOSTICS)?,
        })
    }
}

impl Calibrator {
    /// A calibrator that keeps `capacity` drive states, with its online tracker if any.
    pub(super) fn new(
        capacity: u64,
        online: Option<OnlineWorker>,
        history: Option<NodeHistory>,
    ) -> Self {
        Self {
            acc: Accumulator::new(usize::try_from(capacity).unwrap_or(usize::MAX)),
            online,
            temp_name: "covariate 1".to_owned(),
            last_measurement: None,
            calibrations: 0,
            last: (DiagnosticStatus::OK, "waiting for measurements".into()),
            tie: None,
            history,
        }
    }
}

pub fn run(args: &CommonArgs) -> anyhow::Result<()> {
    let declared = declared();
    let ctx = NodeContext::open("calibrator", args, &declared, None)?;
    let p = &ctx.params;
    let Settings {
        mut options,
        mut every,
        mut idle_end,
    } = configure(p)?;
    let mut live = LiveParams::start(&ctx, &served(&[&PARAMS]), |p| configure(p).map(|_| ()))?;
    // Bounded before the ring is preallocated from it (4294967296 asked for 650 GB).
    let capacity = STATE_BUFFER.u64(p).map_err(bad_param)?;
    let online = match online_settings(p)? {
        Some(settings) => Some(OnlineWorker::start(options.start.params, &settings)?),
        None => None,
    };
    let states = ctx.subscriber(&topic::ACTUATOR_STATE)?;
    let measurements = ctx.subscriber(&topic::TCP_MEASUREMENT)?;
    let infos = ctx.subscriber(&topic::CAMPAIGN_INFO)?;
    let out = Outputs::open(&ctx)?;
    let services = crate::node::calibration_services::CalibrationServices::open(&ctx)?;
    let action = CalibrateAction::open(&ctx)?;
    let mut lifecycle = Lifecycle::open(&ctx, crate::node::lifecycle::start(args))?;
    ctx.started(format!(
        "calibrating {} from {}",
        options.start.model, options.start.source
    ));
    let history = open_history(&ctx)?;
    let mut node = Calibrator::new(capacity, online, history);
    if let Some(why) = node.history.as_ref().and_then(NodeHistory::away) {
        // said on /diagnostics from the first status on, not only in the log
        node.last = (
            DiagnosticStatus::WARN,
            format!("history: the server is away ({why}): records wait in the spool"),
        );
    }
    let mut idle = Idle::new(Duration::from_millis(50), Duration::from_millis(1));
    let mut report = Every::new(ctx.diagnostics_period()?);
    while !crate::node::shutdown::requested() {
        while let Some(info) = infos.try_recv()? {
            node.campaign_info(&info);
        }
        let (mut worked, end) = node.drain(&states, &measurements, every)?;
        worked |= node.online_reports(&ctx, &out, options.start.model)?;
        node.history_retry(&ctx, &out)?;
        // an inactive node collects its campaign and calibrates (publishes) once active
        if (end || node.idle_ended(idle_end)) && node.acc.measurements > 0 && lifecycle.active() {
            node.calibrate(&ctx, &out, &options)?;
        }
        lifecycle.serve(&ctx, || {
            ctx.reread_params(args, "calibrator", &declared)
                .and_then(|p| configure(&p))
                .map(|s| (options, every, idle_end) = (s.options, s.every, s.idle_end))
                .map_err(|e| crate::error::error_chain(&e))
        });
        // a goal of `~/calibrate`, executed now (the loop waits for it, as for a marker)
        if let Some(goal) = action
            .as_ref()
            .and_then(|a| a.next(&ctx, lifecycle.active()))
        {
            // the lifecycle's queries are answered while it runs; a transition waits
            node.execute(&ctx, &out, &options, goal, &|| lifecycle.answer_queries())?;
        }
        // Between calibrations: the next campaign ends and calibrates by the new settings.
        if let Some((p, names)) = live.poll() {
            Settings {
                options,
                every,
                idle_end,
            } = configure(&p)?;
            ctx.log(format!("parameters set: {}", names.join(", ")));
        }
        // the geometry the next calibration starts from
        if let Some(g) = services.as_ref().and_then(|s| s.poll(&ctx, &options.start)) {
            options.start = g;
        }
        if report.due() {
            node.publish_status(&ctx, &out)?;
            // a subscriber that joined late (rpkm monitor) gets the last Parameters now
            out.parameters.deliver_history()?;
        }
        if worked {
            idle.worked();
        } else {
            idle.wait();
        }
    }
    ctx.log("stopping");
    Ok(())
}
