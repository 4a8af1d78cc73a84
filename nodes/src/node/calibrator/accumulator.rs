//! Measurements and actuator states of the same stamp accumulated into a campaign, per setup.

use crate::campaign_bag::CampaignAssembler;
use rpkm_core::campaign::Campaign;
use rpkm_msgs::{ActuatorState, CampaignInfo, TcpMeasurement};
use std::collections::VecDeque;

/// Accumulates the campaign from the two streams.
#[derive(Debug)]
pub struct Accumulator {
    states: VecDeque<ActuatorState>,
    capacity: usize,
    assembler: CampaignAssembler,
    pub(super) info: Option<CampaignInfo>,
    /// Measurements with no drive state of the same stamp (dropped).
    pub unpaired: u64,
    /// Measurements accumulated since the last calibration.
    pub measurements: u64,
    /// Poses without a measurement (instrument NONE), not kept.
    pub unmeasured: u64,
}

impl Accumulator {
    /// Keeps the last `capacity` drive states for the pairing.
    pub fn new(capacity: usize) -> Self {
        Self {
            states: VecDeque::with_capacity(capacity.max(1)),
            capacity: capacity.max(1),
            assembler: CampaignAssembler::new(),
            info: None,
            unpaired: 0,
            measurements: 0,
            unmeasured: 0,
        }
    }

    /// Takes a drive state (no allocation: the ring is preallocated).
    pub fn state(&mut self, s: &ActuatorState) {
        if self.states.len() == self.capacity {
            self.states.pop_front();
        }
        self.states.push_back(*s);
    }

    /// Takes the campaign description.
    pub fn info(&mut self, info: &CampaignInfo) -> anyhow::Result<()> {
        self.assembler.push_info(info)?;
        self.info = Some(info.clone());
        Ok(())
    }

    /// Whether a drive state with the stamp of `m` is buffered.
    pub fn has_state_for(&self, m: &TcpMeasurement) -> bool {
        self.states.iter().rev().any(|s| s.stamp == m.stamp)
    }

    /// Takes a measurement; `Ok(false)` when no state of its stamp is buffered. A pose
    /// without a measurement (instrument NONE: a row of a drive stream) gives the calibration
    /// no row and is not kept: an 8 kHz stream would otherwise grow the campaign by 8,000
    /// poses a second.
    pub fn measurement(&mut self, m: &TcpMeasurement) -> anyhow::Result<bool> {
        if m.instrument == TcpMeasurement::NONE {
            self.unmeasured += 1;
            return Ok(true);
        }
        let Some(state) = self.states.iter().rev().find(|s| s.stamp == m.stamp) else {
            self.unpaired += 1;
            return Ok(false);
        };
        self.assembler.push_state(state)?;
        self.assembler.push_measurement(m)?;
        self.measurements += 1;
        Ok(true)
    }

    /// The campaign so far and the noise its measurements state for themselves, the
    /// accumulator left as it is (an action's goal takes the campaign only when its
    /// calibration succeeded).
    pub fn peek(&self) -> anyhow::Result<(Campaign, rpkm_core::noise::NoiseModel)> {
        let copy = self.assembler.clone();
        let noise = copy.stated_noise(rpkm_core::noise::NoiseModel::default())?;
        Ok((copy.finish()?, noise))
    }

    /// The campaign so far and the noise its measurements state for themselves (over the
    /// spec's defaults); the accumulator starts a new one (keeping the description).
    pub fn take(&mut self) -> anyhow::Result<(Campaign, rpkm_core::noise::NoiseModel)> {
        let mut next = CampaignAssembler::new();
        if let Some(info) = &self.info {
            next.push_info(info)?;
        }
        let done = std::mem::replace(&mut self.assembler, next);
        self.measurements = 0;
        let noise = done.stated_noise(rpkm_core::noise::NoiseModel::default())?;
        Ok((done.finish()?, noise))
    }
}
