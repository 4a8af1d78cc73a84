//! One evaluation of a campaign's rows: the pieces across setups, the reset pose solved once,
//! every pose's rows.

use super::context::{AtReset, Ctx};
use super::force::force_rows;
use super::forward::{forward_rows, self_rows, virtual_q2_row};
use super::forward_solve::{forward, Forward};
use super::inverse::inverse_rows;
use super::reset::{share_reset, zero_covariance};
use super::row::{ModelError, PoseError, Residual};
use crate::campaign::{Campaign, Instrument, MeasuredPose};
use crate::effects::Corrections;
use crate::geometry::{self, Subsystem};
use crate::noise::{NoiseModel, XyInstrument};
use crate::params::{Model, Params};

/// Which kinds of rows to build.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Step {
    /// Direct rows of every instrument (inverse, forward, self-calibration).
    Direct,
    /// Second step of forward instruments: q2 from virtual measurements made with `p_cal`.
    VirtualQ2,
}

/// Rows of one campaign under parameters `p`. Reset poses of relative instruments give no
/// row of their own (their measured value is zero by definition); `circle` and `none` poses
/// give none (the circular test is an evaluation, not a calibration measurement).
pub fn residuals(
    campaign: &Campaign,
    p: &Params,
    model: Model,
    step: Step,
    p_cal: &Params,
    noise: &NoiseModel,
) -> Result<Vec<Residual>, PoseError> {
    residuals_in(
        campaign,
        p,
        model,
        step,
        p_cal,
        &Corrections::default(),
        noise,
        Form::Thesis,
    )
}

/// How a 2-D instrument's rows are written.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Form {
    /// The four q rows of eq. 4.30, as the thesis writes them (its observability tables).
    Thesis,
    /// Decorrelated ([`Direction::Along`], [`Direction::Across`], [`Direction::Compat`]):
    /// the calibration's rows.
    Decorrelated,
    /// Decorrelated within each pose, the errors a setup's reset pose shares with its rows
    /// left in each row's [`Residual::reset_gain`] (covariance [`zero_covariance`]): for the
    /// planner, which adds a setup's poses one by one and marginalises the shared zero
    /// itself.
    PerPose,
}

/// [`residuals`] with the effects' corrections `corr` of every pose.
pub fn residuals_with(
    campaign: &Campaign,
    p: &Params,
    model: Model,
    step: Step,
    p_cal: &Params,
    corr: &Corrections,
    noise: &NoiseModel,
) -> Result<Vec<Residual>, PoseError> {
    residuals_in(
        campaign,
        p,
        model,
        step,
        p_cal,
        corr,
        noise,
        Form::Decorrelated,
    )
}

/// [`residuals_with`] in either [`Form`].
#[expect(
    clippy::too_many_arguments,
    reason = "the rows of one campaign: each argument is one independent input of the model"
)]
pub fn residuals_in(
    campaign: &Campaign,
    p: &Params,
    model: Model,
    step: Step,
    p_cal: &Params,
    corr: &Corrections,
    noise: &NoiseModel,
    form: Form,
) -> Result<Vec<Residual>, PoseError> {
    let eval = Evaluation {
        campaign,
        p,
        model,
        step,
        p_cal,
        corr,
        noise,
        form,
    };
    let pieces = Pieces::new(campaign, usize::MAX);
    let mut out = Vec::with_capacity(campaign.poses.len() * 4);
    for k in 0..pieces.len() {
        eval.piece_into(&pieces, k, &mut out)?;
    }
    Ok(out)
}

/// A campaign cut into pieces of at most `size` poses, in file order within each setup.
/// Consecutive setups share pieces (a piece's part of a setup reads that setup's reset
/// pose; a relative setup is never cut in two, its rows share its reset reading): the 1,043 self-calibration poses of 28 setups make 5 pieces, not 28, and a
/// campaign's 3,000 laser-tracker and grid-encoder setups of 10 poses 118, not 3,000 (a
/// piece's sums and its R factor cost the same for 10 poses as for 256; issue 30).
/// Drive-force setups keep pieces of their own: merged, the
/// sums of the online tracker's start calibration regroup, and that round-off alone moved
/// its six-minute drift test's share of checks below p = 0.01 from 0.033 to 0.074, past the
/// test's 0.05 (docs/calibration.md, "Since: pieces across setups"). Evaluated piece
/// by piece and concatenated, the rows are those of [`residuals_in`] in the same order; a
/// piece is the unit of parallel work of a large calibration, and fixed pieces make its
/// sums the same on any number of threads.
#[derive(Clone, Debug)]
pub struct Pieces {
    /// Per setup: its reset pose and its poses.
    pub(super) setups: Vec<(Option<usize>, Vec<usize>)>,
    /// The pieces' parts, piece after piece: a setup and the range of that setup's poses.
    pub(super) parts: Vec<(usize, std::ops::Range<usize>)>,
    /// Per piece: the range of its parts.
    spans: Vec<std::ops::Range<usize>>,
}

impl Pieces {
    pub fn new(campaign: &Campaign, size: usize) -> Pieces {
        Self::of_setups(campaign, size, |_| true)
    }

    /// [`Pieces::new`] of the setups `keep` picks (by their index in [`Campaign::setups`])
    /// alone: each setup's rows read only its own poses and its reset pose, so they are the
    /// rows those setups have among the whole campaign's (cross-validation evaluates one
    /// fold's setups, not the campaign).
    pub fn of_setups(campaign: &Campaign, size: usize, keep: impl Fn(usize) -> bool) -> Pieces {
        let size = size.max(1);
        let setups: Vec<(Option<usize>, Vec<usize>)> = campaign
            .setups()
            .into_iter()
            .map(|s| (s.reset, s.poses))
            .collect();
        let mut cut = Cut {
            size,
            parts: Vec::new(),
            spans: Vec::new(),
            open: None,
        };
        for (k, (reset, poses)) in setups.iter().enumerate().filter(|(k, _)| keep(*k)) {
            let shared = !poses
                .iter()
                .any(|&i| campaign.poses[i].instrument == Instrument::None);
            // a relative setup's rows share its reset reading: one piece holds them all
            let whole = reset.is_some_and(|r| campaign.poses[r].instrument.is_relative());
            cut.setup(k, poses.len(), shared, whole);
        }
        cut.close();
        Pieces {
            setups,
            parts: cut.parts,
            spans: cut.spans,
        }
    }

    pub fn len(&self) -> usize {
        self.spans.len()
    }

    pub fn is_empty(&self) -> bool {
        self.spans.is_empty()
    }
}

/// [`Pieces::new`]'s cutting, setup after setup.
struct Cut {
    size: usize,
    pub(super) parts: Vec<(usize, std::ops::Range<usize>)>,
    spans: Vec<std::ops::Range<usize>>,
    /// The piece still open to the next setup: its first part and its poses so far.
    open: Option<(usize, usize)>,
}

impl Cut {
    /// Setup `k` of `n` poses; `shared`: a setup that may share a piece with its neighbours
    /// (every one but a drive-force one); `whole`: a setup never cut in two (a relative
    /// one: a piece holding it may exceed `size` by up to its length).
    fn setup(&mut self, k: usize, n: usize, shared: bool, whole: bool) {
        if !shared {
            self.close();
        }
        let mut a = 0usize;
        loop {
            let (first, held) = self.open.unwrap_or((self.parts.len(), 0));
            let b = if whole {
                n
            } else {
                n.min(a.saturating_add(self.size - held))
            };
            self.parts.push((k, a..b));
            self.open = Some((first, held + (b - a)));
            if held + (b - a) >= self.size || !shared {
                self.close();
            }
            if b == n {
                break;
            }
            a = b;
        }
    }

    /// Ends the open piece, if any.
    fn close(&mut self) {
        if let Some((first, _)) = self.open.take() {
            self.spans.push(first..self.parts.len());
        }
    }
}

/// One evaluation of a campaign's rows: at parameters `p` (virtual measurements made with
/// `p_cal`), with the effects' corrections `corr`, weighted by `noise`.
#[derive(Clone, Copy)]
pub struct Evaluation<'a> {
    pub campaign: &'a Campaign,
    pub p: &'a Params,
    pub model: Model,
    pub step: Step,
    pub p_cal: &'a Params,
    pub corr: &'a Corrections,
    pub noise: &'a NoiseModel,
    pub form: Form,
}

impl Evaluation<'_> {
    /// Appends the rows of piece `k` to `out`.
    pub fn piece_into(
        &self,
        pieces: &Pieces,
        k: usize,
        out: &mut Vec<Residual>,
    ) -> Result<(), PoseError> {
        let Some(parts) = pieces.spans.get(k) else {
            return Ok(());
        };
        let ctx = Ctx {
            p: self.p,
            p_cal: self.p_cal,
            model: self.model,
            corr: self.corr,
            noise: self.noise,
            decorrelated: self.form != Form::Thesis,
            shared: self.form == Form::Decorrelated,
            frames: geometry::frames(self.p),
        };
        // one buffer of the forward solves' sensitivities for the piece's poses
        let mut f = Forward::zeros();
        for (setup, range) in &pieces.parts[parts.clone()] {
            let (reset, poses) = &pieces.setups[*setup];
            self.part_into(&ctx, (*reset, poses), range.clone(), &mut f, out)?;
        }
        Ok(())
    }

    /// Appends the rows of the poses `range` of one setup (its reset pose and poses).
    fn part_into(
        &self,
        ctx: &Ctx,
        (reset, poses): (Option<usize>, &[usize]),
        range: std::ops::Range<usize>,
        f: &mut Forward,
        out: &mut Vec<Residual>,
    ) -> Result<(), PoseError> {
        let campaign = self.campaign;
        let reset = reset.map(|i| (i, &campaign.poses[i]));
        let mut at_reset = AtReset::default();
        // a reset pose that cannot be solved is blamed on its own line, not on the first
        // pose measured relative to it
        if let Some((ri, reset)) = reset.filter(|(_, r)| r.instrument.is_relative()) {
            let (p_r, q_r) = self.corr.delta(ri).applied(self.p, &reset.q);
            let nr = forward(&p_r, self.model, Subsystem::NR, &q_r)
                .map_err(|e| PoseError::at(campaign, reset, e))?;
            if self.step == Step::Direct {
                at_reset = AtReset::of(ctx, reset, (&p_r, &q_r), nr);
            }
        }
        let first = out.len();
        for &i in &poses[range.clone()] {
            let pose = &campaign.poses[i];
            if pose.reset && pose.instrument.is_relative() {
                continue;
            }
            let err = |error: ModelError| PoseError::at(campaign, pose, error);
            match self.step {
                Step::Direct => {
                    pose_rows(ctx, (i, pose), (reset, &at_reset), f, out).map_err(err)?;
                }
                Step::VirtualQ2 => {
                    virtual_q2_row(ctx, i, pose, self.p_cal, out).map_err(|e| err(e.into()))?;
                }
            }
        }
        // a relative setup is never split between pieces ([`Pieces::new`]): here are all
        // its rows
        if let Some((_, reset)) = reset.filter(|_| ctx.shared && self.step == Step::Direct) {
            let cov = zero_covariance(ctx.noise, (ctx.p_cal, ctx.model), reset)
                .map_err(|e| PoseError::at(campaign, reset, e))?;
            share_reset(&mut out[first..], &cov);
        }
        // the reset pose of a forward instrument still yields a virtual q2 measurement,
        // after the setup's last pose
        if self.step == Step::VirtualQ2 && range.end == poses.len() {
            if let Some((i, pose)) = reset {
                let err = |error| PoseError::at(campaign, pose, error);
                virtual_q2_row(ctx, i, pose, self.p_cal, out).map_err(err)?;
            }
        }
        Ok(())
    }
}

fn pose_rows(
    ctx: &Ctx,
    (i, pose): (usize, &MeasuredPose),
    (reset, at): (Option<(usize, &MeasuredPose)>, &AtReset),
    f: &mut Forward,
    out: &mut Vec<Residual>,
) -> Result<(), ModelError> {
    use Instrument::{Dbb, Kgm, LiPsi, LiX, LiY, Lt, None, SelfCal};
    match (pose.instrument, reset) {
        (Lt, Some(reset)) => Ok(inverse_rows(
            ctx,
            XyInstrument::Lt,
            (i, pose),
            (reset, at),
            out,
        )?),
        (Kgm, Some(reset)) => Ok(inverse_rows(
            ctx,
            XyInstrument::Kgm,
            (i, pose),
            (reset, at),
            out,
        )?),
        (Dbb | LiX | LiY | LiPsi, Some(reset)) => Ok(forward_rows(ctx, i, pose, (reset, at), out)?),
        (SelfCal, _) => Ok(self_rows(ctx, (i, pose), f, out)?),
        (None, _) if pose.drives_loaded() => Ok(force_rows(ctx, i, pose, out)?),
        _ => Ok(()),
    }
}
