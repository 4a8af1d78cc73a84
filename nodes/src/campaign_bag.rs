//! Campaign ⇄ messages: the one place where a campaign (the spec's CSV model, mm) becomes ROS
//! messages (SI) and back. `rpkm ingest`, `rpkm simulate --out BAG`, `rpkm bag campaign` and
//! the ingest node all go through here.
//!
//! A campaign travels as:
//! - one [`CampaignInfo`] (source, comments, covariate names), latched, first;
//! - per pose, in file order, one [`ActuatorState`] (`seq` = pose index, q in m, f in N,
//!   followers, covariates with NaN for an empty field) followed by one [`TcpMeasurement`]
//!   (setup, instrument, reset, x/y/r in m, ψ in rad, each with its `_valid` flag), both
//!   stamped with the pose's time `t`.
//!
//! Back, [`CampaignAssembler`] makes one pose of every `TcpMeasurement` with the
//! `ActuatorState` of the same stamp (the first one not yet used: two poses may share a time),
//! or else the latest state stamped before it (a live stream: the drive state at the
//! measurement). Pairing goes by stamp, not by arrival, because a recorder receives each topic
//! from its own queue. The round trip is exact but for the unit
//! conversions (q/1000·1000 may differ from q in the last bit) and time stamps, which hold
//! `t` to the nanosecond.
//!
//! No physics here: units and field mapping only.

use std::collections::{BTreeMap, VecDeque};

use rpkm_core::campaign::{Campaign, CampaignError, Instrument, MeasuredPose};
use rpkm_core::noise::{NoiseModel, NoiseSpecError};
use rpkm_msgs::actuator_state::MAX_COVARIATES;
use rpkm_msgs::{ActuatorState, CampaignInfo, TcpMeasurement, Time};
use rpkm_transport::bag::{BagReader, BagWriteError, BagWriter, TopicHandle};
use rpkm_transport::topic;

pub use crate::units::MM_PER_M;
const NS_PER_S: i64 = 1_000_000_000;

/// A campaign that cannot be put into messages.
#[derive(Debug, thiserror::Error)]
pub enum ToMessagesError {
    /// More covariate columns than `ActuatorState::covariates` holds.
    #[error(
        "{source_label}: {count} covariate columns ({names}), but ActuatorState carries at most \
         {MAX_COVARIATES}"
    )]
    TooManyCovariates {
        source_label: String,
        count: usize,
        names: String,
    },
    /// A time that a ROS stamp (int32 seconds) or a bag log time (ns ≥ 0) cannot hold.
    #[error("{source_label}:{line} (t): t = {t} s cannot be a {what} (expected {expected})")]
    Time {
        source_label: String,
        line: usize,
        t: f64,
        what: &'static str,
        expected: &'static str,
    },
}

/// Messages that do not make a campaign.
#[derive(Debug, thiserror::Error)]
pub enum FromMessagesError {
    /// A measurement whose stated σ is negative or not a number.
    #[error("TcpMeasurement {index} (stamp {stamp_s} s): sigma {value}, expected a finite value >= 0 (0: none stated)")]
    Sigma {
        index: usize,
        stamp_s: f64,
        value: f64,
    },
    /// A measurement with no drive state before it.
    #[error(
        "TcpMeasurement {index} (stamp {stamp_s} s, setup {setup:?}) has no ActuatorState \
         stamped at or before it: expected the drive state of its pose first"
    )]
    NoState {
        index: usize,
        stamp_s: f64,
        setup: String,
    },
    /// An instrument id outside the `.msg` constants.
    #[error("TcpMeasurement {index} (stamp {stamp_s} s): instrument id {value}, expected 0..=8")]
    UnknownInstrument {
        index: usize,
        stamp_s: f64,
        value: u8,
    },
    /// A drive state whose covariate count disagrees with the campaign's covariate names.
    #[error(
        "ActuatorState seq {seq} (stamp {stamp_s} s): {count} covariates, but CampaignInfo \
         names {expected} ({names})"
    )]
    CovariateCount {
        seq: u64,
        stamp_s: f64,
        count: usize,
        expected: usize,
        names: String,
    },
    /// A second, different CampaignInfo: two campaigns mixed in one stream.
    #[error(
        "a second CampaignInfo (source {second:?}) differs from the first ({first:?}): one \
         campaign per bag"
    )]
    SecondInfo { first: String, second: String },
    /// The rebuilt campaign breaks a rule of the campaign format.
    #[error("the rebuilt campaign is not valid: {0}")]
    Invalid(#[from] CampaignError),
}

/// ROS stamp of a time in seconds, rounded to the nanosecond.
pub fn stamp_from_seconds(t: f64) -> Option<Time> {
    let ns = (t * NS_PER_S as f64).round();
    // i32 seconds: |t| < 2^31 s.
    if ns.is_nan() || ns.abs() >= 2f64.powi(31) * NS_PER_S as f64 {
        return None;
    }
    let ns = rpkm_core::convert::round_i64(ns);
    let sec = i32::try_from(ns.div_euclid(NS_PER_S)).ok()?;
    let nanosec = u32::try_from(ns.rem_euclid(NS_PER_S)).ok()?;
    Some(Time { sec, nanosec })
}

/// Nanoseconds of a stamp (negative before the epoch).
pub fn stamp_ns(stamp: Time) -> i64 {
    i64::from(stamp.sec) * NS_PER_S + i64::from(stamp.nanosec)
}

/// Seconds of a stamp: one correctly rounded division of the exact nanosecond count, so a
/// time written with at most nine decimals comes back as the same `f64`.
pub fn seconds_from_stamp(stamp: Time) -> f64 {
    stamp_ns(stamp) as f64 / NS_PER_S as f64
}

fn instrument_id(i: Instrument) -> u8 {
    match i {
        Instrument::Lt => TcpMeasurement::LT,
        Instrument::Kgm => TcpMeasurement::KGM,
        Instrument::Dbb => TcpMeasurement::DBB,
        Instrument::LiX => TcpMeasurement::LI_X,
        Instrument::LiY => TcpMeasurement::LI_Y,
        Instrument::LiPsi => TcpMeasurement::LI_PSI,
        Instrument::SelfCal => TcpMeasurement::SELF,
        Instrument::Circle => TcpMeasurement::CIRCLE,
        Instrument::None => TcpMeasurement::NONE,
    }
}

fn instrument_of_id(id: u8) -> Option<Instrument> {
    Some(match id {
        TcpMeasurement::LT => Instrument::Lt,
        TcpMeasurement::KGM => Instrument::Kgm,
        TcpMeasurement::DBB => Instrument::Dbb,
        TcpMeasurement::LI_X => Instrument::LiX,
        TcpMeasurement::LI_Y => Instrument::LiY,
        TcpMeasurement::LI_PSI => Instrument::LiPsi,
        TcpMeasurement::SELF => Instrument::SelfCal,
        TcpMeasurement::CIRCLE => Instrument::Circle,
        TcpMeasurement::NONE => Instrument::None,
        _ => return None,
    })
}

/// Nominal noise σ of an instrument's reading in SI (m; rad for ψ), for
/// `TcpMeasurement::sigma`: the campaign file does not carry it, so this is the spec's value
/// (`rpkm_core::noise`; the laser tracker's along-beam σ). Not read back into the campaign.
fn nominal_sigma_si(i: Instrument) -> f64 {
    let s = rpkm_core::noise::NoiseModel::default()
        .scalar_sigma(i)
        .unwrap_or(0.0);
    if i == Instrument::LiPsi {
        s
    } else {
        s / MM_PER_M
    }
}

/// The [`CampaignInfo`] of a campaign; checks that its covariates fit an `ActuatorState`.
pub fn campaign_info(c: &Campaign) -> Result<CampaignInfo, ToMessagesError> {
    if c.covariate_names.len() > MAX_COVARIATES {
        return Err(ToMessagesError::TooManyCovariates {
            source_label: c.source.clone(),
            count: c.covariate_names.len(),
            names: c.covariate_names.join(", "),
        });
    }
    Ok(CampaignInfo {
        source: c.source.clone(),
        comments: c.comments.clone(),
        covariate_names: c.covariate_names.clone(),
    })
}

/// The two messages of pose number `index` (its `seq`) of campaign `c`.
pub fn pose_messages(
    c: &Campaign,
    index: usize,
    pose: &MeasuredPose,
) -> Result<(ActuatorState, TcpMeasurement), ToMessagesError> {
    let stamp = stamp_from_seconds(pose.t).ok_or_else(|| ToMessagesError::Time {
        source_label: c.source.clone(),
        line: pose.line,
        t: pose.t,
        what: "ROS time stamp",
        expected: "|t| < 2^31 s",
    })?;
    let mut state = ActuatorState {
        stamp,
        seq: index as u64,
        position: pose.q.map(|q| q / MM_PER_M),
        force: pose.f,
        follower: pose.follower,
        ..ActuatorState::default()
    };
    let covariates: Vec<f64> = pose
        .covariates
        .iter()
        .map(|v| v.unwrap_or(f64::NAN))
        .collect();
    state
        .set_covariates(&covariates)
        .ok_or_else(|| ToMessagesError::TooManyCovariates {
            source_label: c.source.clone(),
            count: covariates.len(),
            names: c.covariate_names.join(", "),
        })?;
    let si = |v: Option<f64>| (v.map_or(0.0, |v| v / MM_PER_M), v.is_some());
    let (x, x_valid) = si(pose.x);
    let (y, y_valid) = si(pose.y);
    let (r, r_valid) = si(pose.r);
    let measurement = TcpMeasurement {
        stamp,
        setup: pose.setup.clone(),
        instrument: instrument_id(pose.instrument),
        reset: pose.reset,
        x,
        x_valid,
        y,
        y_valid,
        r,
        r_valid,
        psi: pose.psi.unwrap_or(0.0),
        psi_valid: pose.psi.is_some(),
        sigma: nominal_sigma_si(pose.instrument),
    };
    Ok((state, measurement))
}

/// Rebuilds a campaign from messages in the order they were published or recorded.
///
/// ```
/// use rpkm_nodes::campaign_bag::{campaign_info, pose_messages, CampaignAssembler};
/// use rpkm_core::campaign::Campaign;
/// let text = "t,setup,instrument,reset,q1,q2,q3,q4,f1,f2,f3,f4,follower,x,y,r,psi,temp\n\
///             3,A,lt,1,2611,2611,789,789,0,0,0,0,23,0,0,,,20.5\n\
///             6,A,lt,0,2600,2600.5,780,780,0,0,0,0,23,-10.5,12.25,,,\n";
/// let c = Campaign::parse(text, "c.csv")?;
/// let mut back = CampaignAssembler::new();
/// back.push_info(&campaign_info(&c)?)?;
/// for (i, pose) in c.poses.iter().enumerate() {
///     let (state, measurement) = pose_messages(&c, i, pose)?;
///     back.push_state(&state)?;
///     back.push_measurement(&measurement)?;
/// }
/// let rebuilt = back.finish()?;
/// assert_eq!(rebuilt.poses[1].q[1], 2600.5);
/// assert_eq!(rebuilt.poses[1].covariates, vec![None]);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Debug, Clone)]
pub struct CampaignAssembler {
    info: Option<CampaignInfo>,
    /// Drive states not yet paired, by stamp (ns), in arrival order per stamp.
    states: BTreeMap<i64, VecDeque<ActuatorState>>,
    state_count: usize,
    /// Most states kept (see [`STATE_HISTORY`]).
    history: usize,
    poses: Vec<MeasuredPose>,
    /// The σ each measurement states for itself (mm, rad for ψ), by instrument.
    stated_sigma: BTreeMap<Instrument, Vec<f64>>,
}

impl Default for CampaignAssembler {
    fn default() -> Self {
        Self::new()
    }
}

/// Drive states kept for pairing: 8 s of an 8 kHz stream. Older ones are dropped.
pub const STATE_HISTORY: usize = 1 << 16;

impl CampaignAssembler {
    /// For a live stream: keeps the latest [`STATE_HISTORY`] drive states.
    pub fn new() -> Self {
        Self {
            info: None,
            states: BTreeMap::new(),
            state_count: 0,
            history: STATE_HISTORY,
            poses: Vec::new(),
            stated_sigma: BTreeMap::new(),
        }
    }

    /// For a whole recording read at once: keeps every drive state.
    pub fn unbounded() -> Self {
        Self {
            history: usize::MAX,
            ..Self::new()
        }
    }

    /// Takes the campaign's description. A repeated identical one (latched topics are sent
    /// again to late joiners) is ignored.
    pub fn push_info(&mut self, info: &CampaignInfo) -> Result<(), FromMessagesError> {
        match &self.info {
            Some(first) if first != info => Err(FromMessagesError::SecondInfo {
                first: first.source.clone(),
                second: info.source.clone(),
            }),
            Some(_) => Ok(()),
            None => {
                self.info = Some(info.clone());
                Ok(())
            }
        }
    }

    /// Takes a drive state; the next measurement pairs with the latest one.
    pub fn push_state(&mut self, state: &ActuatorState) -> Result<(), FromMessagesError> {
        if let Some(info) = &self.info {
            let count = usize::from(state.covariate_count);
            if count != info.covariate_names.len() {
                return Err(FromMessagesError::CovariateCount {
                    seq: state.seq,
                    stamp_s: seconds_from_stamp(state.stamp),
                    count,
                    expected: info.covariate_names.len(),
                    names: info.covariate_names.join(", "),
                });
            }
        }
        self.states
            .entry(stamp_ns(state.stamp))
            .or_default()
            .push_back(*state);
        self.state_count += 1;
        if self.state_count > self.history {
            if let Some(mut oldest) = self.states.first_entry() {
                oldest.get_mut().pop_front();
                if oldest.get().is_empty() {
                    oldest.remove();
                }
                self.state_count -= 1;
            }
        }
        Ok(())
    }

    /// The state of a measurement stamped `ns`: the first unused one of the same stamp
    /// (taken), else the latest one before (kept: a stream state may serve several).
    fn state_for(&mut self, ns: i64) -> Option<ActuatorState> {
        if let Some(same) = self.states.get_mut(&ns) {
            if let Some(state) = same.pop_front() {
                self.state_count -= 1;
                if same.is_empty() {
                    self.states.remove(&ns);
                }
                return Some(state);
            }
        }
        self.states
            .range(..ns)
            .next_back()
            .and_then(|(_, states)| states.back().copied())
    }

    /// Makes a pose of `measurement` and its drive state (see the type's documentation).
    pub fn push_measurement(
        &mut self,
        measurement: &TcpMeasurement,
    ) -> Result<(), FromMessagesError> {
        let index = self.poses.len();
        let stamp_s = seconds_from_stamp(measurement.stamp);
        let Some(state) = self.state_for(stamp_ns(measurement.stamp)) else {
            return Err(FromMessagesError::NoState {
                index,
                stamp_s,
                setup: measurement.setup.clone(),
            });
        };
        let instrument = instrument_of_id(measurement.instrument).ok_or(
            FromMessagesError::UnknownInstrument {
                index,
                stamp_s,
                value: measurement.instrument,
            },
        )?;
        if !(measurement.sigma.is_finite() && measurement.sigma >= 0.0) {
            return Err(FromMessagesError::Sigma {
                index,
                stamp_s,
                value: measurement.sigma,
            });
        }
        // 0: the sender states no σ (the noise model's then stands).
        if measurement.sigma > 0.0 {
            let unit = if instrument == Instrument::LiPsi {
                1.0
            } else {
                MM_PER_M
            };
            self.stated_sigma
                .entry(instrument)
                .or_default()
                .push(measurement.sigma * unit);
        }
        let mm = |v: f64, valid: bool| valid.then_some(v * MM_PER_M);
        self.poses.push(MeasuredPose {
            t: stamp_s,
            setup: measurement.setup.clone(),
            instrument,
            reset: measurement.reset,
            q: state.position.map(|q| q * MM_PER_M),
            f: state.force,
            follower: state.follower,
            x: mm(measurement.x, measurement.x_valid),
            y: mm(measurement.y, measurement.y_valid),
            r: mm(measurement.r, measurement.r_valid),
            psi: measurement.psi_valid.then_some(measurement.psi),
            covariates: state
                .covariates()
                .iter()
                .map(|&v| (!v.is_nan()).then_some(v))
                .collect(),
            line: 0,
        });
        Ok(())
    }

    /// `base` with the σ the measurements state for themselves: per instrument, the median
    /// of the `TcpMeasurement::sigma` they carry (those with 0 state none). The stated noise
    /// of the calibration, which estimates the noise from the data from there.
    pub fn stated_noise(&self, base: NoiseModel) -> Result<NoiseModel, NoiseSpecError> {
        let mut noise = base;
        for (&instrument, sigmas) in &self.stated_sigma {
            let mut sorted = sigmas.clone();
            sorted.sort_by(f64::total_cmp);
            noise = noise.with_instrument_sigma(instrument, sorted[sorted.len() / 2])?;
        }
        Ok(noise)
    }

    /// Poses so far.
    pub fn len(&self) -> usize {
        self.poses.len()
    }

    pub fn is_empty(&self) -> bool {
        self.poses.is_empty()
    }

    /// The campaign, checked with [`Campaign::validate`]. Without a `CampaignInfo` the
    /// covariates are named `covariate1`, `covariate2`, ... and the source is empty.
    pub fn finish(self) -> Result<Campaign, FromMessagesError> {
        let info = self.info.unwrap_or_else(|| {
            let n = self.poses.first().map_or(0, |p| p.covariates.len());
            CampaignInfo {
                covariate_names: (1..=n).map(|k| format!("covariate{k}")).collect(),
                ..CampaignInfo::default()
            }
        });
        let mut campaign = Campaign {
            source: info.source,
            comments: info.comments,
            covariate_names: info.covariate_names,
            poses: self.poses,
        };
        // Lines as `Campaign::to_csv` would write them, so that messages name a row.
        let comment_lines: usize = campaign
            .comments
            .iter()
            .map(|c| c.split(['\n', '\r']).count())
            .sum();
        for (i, pose) in campaign.poses.iter_mut().enumerate() {
            pose.line = comment_lines + 2 + i;
        }
        campaign.validate()?;
        Ok(campaign)
    }
}

/// The campaign topics of a bag.
#[derive(Debug, Clone)]
pub struct CampaignTopics {
    pub info: TopicHandle<CampaignInfo>,
    pub state: TopicHandle<ActuatorState>,
    pub measurement: TopicHandle<TcpMeasurement>,
}

impl CampaignTopics {
    /// Adds `/rpkm/campaign_info`, `/rpkm/actuator_state`, `/rpkm/tcp_measurement` with the
    /// QoS their publishers offer.
    pub fn add(bag: &mut BagWriter) -> Result<Self, BagWriteError> {
        Ok(Self {
            info: crate::topics::add_bag_topic(bag, &topic::CAMPAIGN_INFO)?,
            state: crate::topics::add_bag_topic(bag, &topic::ACTUATOR_STATE)?,
            measurement: crate::topics::add_bag_topic(bag, &topic::TCP_MEASUREMENT)?,
        })
    }
}

/// Log time of a campaign message: the pose's time in ns, which must be ≥ 0.
fn log_time(c: &Campaign, line: usize, t: f64, stamp: Time) -> Result<u64, ToMessagesError> {
    u64::try_from(stamp_ns(stamp)).map_err(|_| ToMessagesError::Time {
        source_label: c.source.clone(),
        line,
        t,
        what: "bag log time",
        expected: "t >= 0",
    })
}

/// A campaign as messages, with their log times (the poses' times in ns).
#[derive(Debug, Clone)]
pub struct CampaignMessages {
    pub info: CampaignInfo,
    /// Log time of the info: the first pose's.
    pub info_log_time: u64,
    /// Per pose: log time, drive state, measurement.
    pub poses: Vec<(u64, ActuatorState, TcpMeasurement)>,
}

/// Converts a whole campaign, so that a bag is only created for a campaign that fits.
pub fn campaign_messages(c: &Campaign) -> Result<CampaignMessages, ToMessagesError> {
    let info = campaign_info(c)?;
    let mut poses = Vec::with_capacity(c.poses.len());
    for (i, pose) in c.poses.iter().enumerate() {
        let (state, measurement) = pose_messages(c, i, pose)?;
        let t = log_time(c, pose.line, pose.t, state.stamp)?;
        poses.push((t, state, measurement));
    }
    Ok(CampaignMessages {
        info,
        info_log_time: poses.first().map_or(0, |p| p.0),
        poses,
    })
}

/// Writes a converted campaign into `bag`: the info, then every pose's two messages.
/// Returns the number of messages written.
pub fn write_campaign(
    bag: &mut BagWriter,
    topics: &CampaignTopics,
    m: &CampaignMessages,
) -> Result<u64, BagWriteError> {
    bag.write(&topics.info, m.info_log_time, &m.info)?;
    for (t, state, measurement) in &m.poses {
        bag.write(&topics.state, *t, state)?;
        bag.write(&topics.measurement, *t, measurement)?;
    }
    Ok(1 + 2 * m.poses.len() as u64)
}

/// Rebuilds the campaign held by a bag's campaign topics (other topics are ignored): every
/// measurement, in the bag's order, with its drive state (see [`CampaignAssembler`]).
pub fn read_campaign(bag: &BagReader) -> anyhow::Result<Campaign> {
    let mut assembler = CampaignAssembler::unbounded();
    let (info, state, measurement) = (
        topic::CAMPAIGN_INFO.name(),
        topic::ACTUATOR_STATE.name(),
        topic::TCP_MEASUREMENT.name(),
    );
    // Info and states first: pairing goes by stamp, and a recording made live may hold a
    // measurement before its state (each topic arrives through its own queue).
    for m in bag.messages() {
        let m = m?;
        if m.topic == info {
            assembler.push_info(&m.decode::<CampaignInfo>()?)?;
        }
    }
    for m in bag.messages() {
        let m = m?;
        if m.topic == state {
            assembler.push_state(&m.decode::<ActuatorState>()?)?;
        }
    }
    for m in bag.messages() {
        let m = m?;
        if m.topic == measurement {
            assembler.push_measurement(&m.decode::<TcpMeasurement>()?)?;
        }
    }
    if assembler.is_empty() {
        anyhow::bail!(
            "{}: no {measurement} message: the bag holds no campaign",
            bag.path().display()
        );
    }
    Ok(assembler.finish()?)
}

#[cfg(test)]
#[expect(
    clippy::float_cmp,
    reason = "exact values: parsed, copied or computed without rounding"
)]
mod tests {
    use super::*;

    #[test]
    fn stamps_keep_nine_decimals() {
        for t in [0.0, 3.0, 0.1, 12.345, 1_234.000_000_001, -0.5, 1.7e9] {
            let s = stamp_from_seconds(t).expect("in range");
            assert_eq!(seconds_from_stamp(s), t, "{t}");
        }
        assert_eq!(
            stamp_from_seconds(-0.5),
            Some(Time {
                sec: -1,
                nanosec: 500_000_000
            })
        );
        assert_eq!(stamp_from_seconds(f64::NAN), None);
        assert_eq!(stamp_from_seconds(3e9), None);
    }

    #[test]
    fn instrument_ids_are_the_msg_constants() {
        for i in Instrument::ALL {
            let id = instrument_id(i);
            assert_eq!(instrument_of_id(id), Some(i));
            let wire = rpkm_msgs::InstrumentId::try_from(id).expect("msgs knows the id");
            assert_eq!(wire.csv_name(), i.as_str());
        }
        assert_eq!(instrument_of_id(9), None);
    }

    #[test]
    fn measurement_before_state_is_an_error() {
        let mut a = CampaignAssembler::new();
        let e = a
            .push_measurement(&TcpMeasurement::default())
            .expect_err("no state");
        assert!(e.to_string().contains("has no ActuatorState"), "{e}");
    }

    /// A grid-encoder reading stating 3 µm, another 5 µm, a third 4 µm: the calibration's
    /// stated kgm noise is their median, 0.004 mm; a NaN σ is refused by name.
    #[test]
    fn measurements_state_their_own_sigma() {
        let mut a = CampaignAssembler::new();
        for (k, sigma_m) in [3e-6, 5e-6, 4e-6].into_iter().enumerate() {
            let stamp = Time {
                sec: i32::try_from(k).expect("small") + 1,
                nanosec: 0,
            };
            a.push_state(&ActuatorState {
                stamp,
                ..ActuatorState::default()
            })
            .expect("state");
            a.push_measurement(&TcpMeasurement {
                stamp,
                setup: "kgm1".into(),
                instrument: TcpMeasurement::KGM,
                reset: k == 0,
                sigma: sigma_m,
                ..TcpMeasurement::default()
            })
            .expect("measurement");
        }
        let stated = a.stated_noise(NoiseModel::default()).expect("valid σ");
        assert!((stated.kgm_mm - 0.004).abs() < 1e-15, "{}", stated.kgm_mm);
        assert_eq!(stated.li_mm, NoiseModel::default().li_mm);
        let stamp = Time { sec: 9, nanosec: 0 };
        a.push_state(&ActuatorState {
            stamp,
            ..ActuatorState::default()
        })
        .expect("state");
        let e = a
            .push_measurement(&TcpMeasurement {
                stamp,
                instrument: TcpMeasurement::KGM,
                sigma: f64::NAN,
                ..TcpMeasurement::default()
            })
            .expect_err("NaN σ");
        assert!(e.to_string().contains("sigma NaN"), "{e}");
    }
}
