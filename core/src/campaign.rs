//! Campaign CSV: the metrology interchange format of the spec (section "Campaign CSV").
//!
//! One row per machine pose, comma-separated, header line first, `#` lines are comments.
//! [`Campaign::parse`] reads a file's text (no I/O here: the caller reads the file and passes a
//! label for messages), [`Campaign::to_csv`] writes it back; `parse(to_csv(c)) == c` for every
//! campaign that [`Campaign::validate`] accepts and whose strings are writable (see
//! [`Campaign::to_csv`]).
//!
//! Rules the reader enforces, beyond the spec's table (each breach is a typed
//! [`CampaignError`] naming file, line and column; nothing is dropped or guessed):
//! - fields are plain: no quoting, surrounding white space is trimmed; a leading UTF-8 byte
//!   order mark (as spreadsheets write) is ignored;
//! - the text is UTF-8 (an error names the line and byte offset of the first byte that is not);
//! - `t`, `q1..q4`, `f1..f4` must be finite numbers; `x`, `y`, `r`, `psi` and covariates are
//!   finite numbers or empty (absent). NaN and infinities are rejected everywhere, and so are
//!   magnitudes no machine has ([`plausible`]: |q|, |x|, |y|, |r| ≤ 1e5 mm, |f| ≤ 8.6e6 N,
//!   |ψ| ≤ 2π, |t| and covariates ≤ 1e10);
//! - the actuator positions are a pose of the machine: rods 1 and 4 meet at (q1, q4) and q2,
//!   q3 are within 100 mm of what rods 2 and 3 need there (nominal geometry; see
//!   [`plausible::reachable`]), the reset pose of a setup included;
//! - `t` is monotonic: non-decreasing (equal times are accepted);
//! - all rows of one setup use one instrument;
//! - relative instruments (`lt`, `kgm`, `dbb`, `li_x`, `li_y`, `li_psi`) have exactly one reset
//!   pose per setup; `circle` at most one (the ball-bar pivot); `self` and `none` none;
//! - a reset pose measures 0 or nothing; any other pose of an instrument has a value in each
//!   column the instrument measures (`lt`, `kgm`: x, y; `dbb`, `circle`: r; `li_x`: x;
//!   `li_y`: y; `li_psi`: psi) and nothing in the others; `self` rows have q2 and q3 in
//!   follower mode (their measured values are those encoders).
//!
//! ```
//! use rpkm_core::campaign::{Campaign, Instrument};
//! let text = "# laser tracker, one setup\n\
//!             t,setup,instrument,reset,q1,q2,q3,q4,f1,f2,f3,f4,follower,x,y,r,psi,temp\n\
//!             0,A,lt,1,2611,2611,789,789,0,0,0,0,,0,0,,,20.5\n\
//!             1,A,lt,0,2600,2600,780,780,0,0,0,0,,-10.5,12.25,,,20.6\n";
//! let c = Campaign::parse(text, "campaign.csv")?;
//! assert_eq!(c.poses_of(Instrument::Lt).count(), 2);
//! assert_eq!(c.covariate("temp"), Some(vec![Some(20.5), Some(20.6)]));
//! assert_eq!(Campaign::parse(&c.to_csv(), "campaign.csv")?, c);
//!
//! let bad = text.replace("2600,2600", "2600,abc");
//! let e = Campaign::parse(&bad, "campaign.csv").expect_err("not a number");
//! assert_eq!(e.to_string(), r#"campaign.csv:4:6 (q2): expected a number, found "abc""#);
//! # Ok::<(), rpkm_core::campaign::CampaignError>(())
//! ```
//!
//! Every [`MeasuredPose`] keeps its source `line` so that the caller can name `file:line`.
//! [`CampaignReader`] reads a stream line by line with the same rules (the ingest node).

mod error;
pub mod motion;
mod parse;
pub mod plausible;
mod write;

use std::collections::HashMap;
use std::fmt;
use std::str::FromStr;

pub use error::CampaignError;
pub use motion::{Motion, MotionCovariates};
pub use parse::{parse_follower, CampaignReader};
pub use write::{follower_text, followers_words, NO_FOLLOWERS};

/// The required columns, in the order [`Campaign::to_csv`] writes them.
pub const REQUIRED_COLUMNS: [&str; 17] = [
    "t",
    "setup",
    "instrument",
    "reset",
    "q1",
    "q2",
    "q3",
    "q4",
    "f1",
    "f2",
    "f3",
    "f4",
    "follower",
    "x",
    "y",
    "r",
    "psi",
];

/// The measuring instrument of a pose (column `instrument`).
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize,
)]
pub enum Instrument {
    /// Laser tracker, `lt`: x and y relative to the setup's reset pose.
    #[serde(rename = "lt")]
    Lt,
    /// Grid encoder KGM 182, `kgm`: x and y relative to the setup's reset pose.
    #[serde(rename = "kgm")]
    Kgm,
    /// Double ball-bar, `dbb`: r, the distance from the pivot (the reset pose's TCP).
    #[serde(rename = "dbb")]
    Dbb,
    /// Laser interferometer along x, `li_x`.
    #[serde(rename = "li_x")]
    LiX,
    /// Laser interferometer along y, `li_y`.
    #[serde(rename = "li_y")]
    LiY,
    /// Laser interferometer angle optics, `li_psi`: platform angle ψ.
    #[serde(rename = "li_psi")]
    LiPsi,
    /// Self-calibration, `self`: q2, q3 in follower mode, their encoders are the measurement.
    #[serde(rename = "self")]
    SelfCal,
    /// Circular test with the ball-bar, `circle`: r.
    #[serde(rename = "circle")]
    Circle,
    /// No measurement, `none` (e.g. a pose logged for the diagnosis only).
    #[serde(rename = "none")]
    None,
}

impl Instrument {
    /// Every instrument, in the spec's order.
    pub const ALL: [Instrument; 9] = [
        Instrument::Lt,
        Instrument::Kgm,
        Instrument::Dbb,
        Instrument::LiX,
        Instrument::LiY,
        Instrument::LiPsi,
        Instrument::SelfCal,
        Instrument::Circle,
        Instrument::None,
    ];

    /// The spelling in files: `lt`, `kgm`, `dbb`, `li_x`, `li_y`, `li_psi`, `self`, `circle`,
    /// `none`.
    pub fn as_str(self) -> &'static str {
        match self {
            Instrument::Lt => "lt",
            Instrument::Kgm => "kgm",
            Instrument::Dbb => "dbb",
            Instrument::LiX => "li_x",
            Instrument::LiY => "li_y",
            Instrument::LiPsi => "li_psi",
            Instrument::SelfCal => "self",
            Instrument::Circle => "circle",
            Instrument::None => "none",
        }
    }

    /// Whether the instrument measures relative to a reset pose, and so needs exactly one reset
    /// pose per setup (`lt`, `kgm`, `dbb`, `li_x`, `li_y`, `li_psi`).
    pub fn is_relative(self) -> bool {
        matches!(
            self,
            Instrument::Lt
                | Instrument::Kgm
                | Instrument::Dbb
                | Instrument::LiX
                | Instrument::LiY
                | Instrument::LiPsi
        )
    }

    /// Whether a setup of this instrument may have a reset pose (relative instruments and
    /// `circle`).
    pub fn takes_reset(self) -> bool {
        self.is_relative() || self == Instrument::Circle
    }

    /// Which of the measured columns (x, y, r, psi) the instrument gives.
    pub fn measures(self) -> Measures {
        let (x, y, r, psi) = match self {
            Instrument::Lt | Instrument::Kgm => (true, true, false, false),
            Instrument::Dbb | Instrument::Circle => (false, false, true, false),
            Instrument::LiX => (true, false, false, false),
            Instrument::LiY => (false, true, false, false),
            Instrument::LiPsi => (false, false, false, true),
            Instrument::SelfCal | Instrument::None => (false, false, false, false),
        };
        Measures { x, y, r, psi }
    }
}

/// The measured columns an instrument gives (see [`Instrument::measures`]).
#[expect(
    clippy::struct_excessive_bools,
    reason = "one flag per column of the spec's CSV (x, y, r, psi), any subset measured"
)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Measures {
    pub x: bool,
    pub y: bool,
    pub r: bool,
    pub psi: bool,
}

impl fmt::Display for Instrument {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// An instrument name that is not one of the spec's spellings.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown instrument {0:?}, expected one of lt, kgm, dbb, li_x, li_y, li_psi, self, circle, none")]
pub struct ParseInstrumentError(pub String);

impl FromStr for Instrument {
    type Err = ParseInstrumentError;

    /// Exact spelling, case-sensitive (`lt`, not `LT`).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Instrument::ALL
            .into_iter()
            .find(|i| i.as_str() == s)
            .ok_or_else(|| ParseInstrumentError(s.to_owned()))
    }
}

/// One machine pose: one data row of a campaign file.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MeasuredPose {
    /// Time of the pose, s.
    pub t: f64,
    /// Setup id; relative measurements share their setup's reset pose.
    pub setup: String,
    /// The instrument that measured this pose.
    pub instrument: Instrument,
    /// Whether this is the reset pose of its setup (its measured values are 0).
    pub reset: bool,
    /// Actuator encoder positions q1..q4, mm.
    pub q: [f64; 4],
    /// Drive forces f1..f4, N (0 for a drive in follower mode; NaN not measured, from a
    /// live stream only: a campaign file's are numbers).
    pub f: [f64; 4],
    /// Actuators in follower mode: `follower[i]` for q(i+1); `23` in the file sets
    /// `[false, true, true, false]`.
    pub follower: [bool; 4],
    /// Measured x relative to the setup's reset pose, mm.
    pub x: Option<f64>,
    /// Measured y relative to the setup's reset pose, mm.
    pub y: Option<f64>,
    /// Measured ball-bar distance from the pivot (the reset pose's TCP), mm.
    pub r: Option<f64>,
    /// Measured platform angle relative to the setup's reset pose, rad.
    pub psi: Option<f64>,
    /// Covariate values, aligned with [`Campaign::covariate_names`]; `None` where empty.
    pub covariates: Vec<Option<f64>>,
    /// 1-based line of the row in its source file (0 for a pose built in code).
    pub line: usize,
}

impl MeasuredPose {
    /// Whether the pose carries drive forces as measurements: all four drives
    /// position-controlled (no follower) and forces recorded (none NaN, "not measured", as a
    /// live stream from a cell without force sensing has them).
    pub fn drives_loaded(&self) -> bool {
        self.follower.iter().all(|f| !f)
            && self.f.iter().all(|f| !f.is_nan())
            && self.f.iter().any(|f| *f != 0.0)
    }
}

/// A measurement campaign: the rows of one campaign file.
#[derive(Debug, Clone, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct Campaign {
    /// Label of the source (file name) used in messages.
    pub source: String,
    /// Comment lines (`#` lines of the file, without the `#` and one following space).
    pub comments: Vec<String>,
    /// Names of the covariate columns, in header order.
    pub covariate_names: Vec<String>,
    /// The poses, in file order.
    pub poses: Vec<MeasuredPose>,
}

/// One setup of a campaign (see [`Campaign::setups`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Setup<'a> {
    /// Setup id.
    pub id: &'a str,
    /// The instrument of its rows.
    pub instrument: Instrument,
    /// Index into [`Campaign::poses`] of its reset pose, if any.
    pub reset: Option<usize>,
    /// Indexes into [`Campaign::poses`] of all its poses (the reset pose included), in order.
    pub poses: Vec<usize>,
}

impl Campaign {
    /// Parses a campaign file's text; `source` labels the file in messages. See the module
    /// documentation for the rules.
    pub fn parse(text: &str, source: &str) -> Result<Campaign, CampaignError> {
        parse::parse(text.as_bytes(), source)
    }

    /// [`Campaign::parse`] of a file's bytes: bytes that are not UTF-8 are an error naming
    /// their line and byte offset.
    pub fn parse_bytes(bytes: &[u8], source: &str) -> Result<Campaign, CampaignError> {
        parse::parse(bytes, source)
    }

    /// Checks a campaign built in code against the rules [`Campaign::parse`] enforces (finite
    /// numbers, monotonic time, resets, measured columns, one instrument per setup). Errors
    /// name each pose's `line` and the columns as [`Campaign::to_csv`] writes them.
    pub fn validate(&self) -> Result<(), CampaignError> {
        parse::validate(self)
    }

    /// The setups in order of first appearance, with their instrument (of their first row),
    /// reset pose and poses.
    pub fn setups(&self) -> Vec<Setup<'_>> {
        let mut setups: Vec<Setup<'_>> = Vec::new();
        let mut index: HashMap<&str, usize> = HashMap::new();
        for (i, pose) in self.poses.iter().enumerate() {
            let k = *index.entry(pose.setup.as_str()).or_insert_with(|| {
                setups.push(Setup {
                    id: pose.setup.as_str(),
                    instrument: pose.instrument,
                    reset: None,
                    poses: Vec::new(),
                });
                setups.len() - 1
            });
            if let Some(setup) = setups.get_mut(k) {
                setup.poses.push(i);
                if pose.reset && setup.reset.is_none() {
                    setup.reset = Some(i);
                }
            }
        }
        setups
    }

    /// The poses measured with `instrument`, in file order.
    pub fn poses_of(&self, instrument: Instrument) -> impl Iterator<Item = &MeasuredPose> + '_ {
        self.poses
            .iter()
            .filter(move |p| p.instrument == instrument)
    }

    /// Index of a covariate column by name.
    pub fn covariate_index(&self, name: &str) -> Option<usize> {
        self.covariate_names.iter().position(|n| n == name)
    }

    /// One covariate column over all poses (`None` entries where the file's field was empty),
    /// or `None` if there is no covariate of that name.
    pub fn covariate(&self, name: &str) -> Option<Vec<Option<f64>>> {
        let Some(k) = self.covariate_index(name) else {
            return self
                .derived_covariates()
                .into_iter()
                .find(|d| d.0 == name)
                .map(|d| d.1.into_iter().map(Some).collect());
        };
        Some(
            self.poses
                .iter()
                .map(|p| p.covariates.get(k).copied().flatten())
                .collect(),
        )
    }

    /// Covariates derived from the pose sequence, in file order: `dir_q1`..`dir_q4` (±1, the
    /// direction of the last move of each carrier: lost motion and friction depend on it),
    /// `travel_q1`..`travel_q4` (mm moved since that carrier's last reversal) and `t_run` (s
    /// since the first pose). [`Campaign::covariate`] offers them under these names when the
    /// file has no column of that name.
    pub fn derived_covariates(&self) -> Vec<(String, Vec<f64>)> {
        let mut motion = Motion::default();
        let at: Vec<MotionCovariates> = self.poses.iter().map(|p| motion.next(p.q, p.t)).collect();
        let mut out: Vec<(String, Vec<f64>)> = (0..4)
            .map(|a| {
                (
                    format!("dir_q{}", a + 1),
                    at.iter().map(|m| m.dir[a]).collect(),
                )
            })
            .collect();
        out.extend((0..4).map(|a| {
            (
                format!("travel_q{}", a + 1),
                at.iter().map(|m| m.travel[a]).collect(),
            )
        }));
        out.push(("t_run".to_owned(), at.iter().map(|m| m.t_run).collect()));
        out
    }

    /// Writes the campaign in the spec format: `# ` comment lines, the header (required columns
    /// in [`REQUIRED_COLUMNS`] order, then the covariates), one row per pose. Numbers are
    /// written so that they parse back to the same `f64` (shortest round-trip form).
    ///
    /// The output parses back to an equal campaign (`line` fields aside, which name the new
    /// file's lines) when the campaign passes [`Campaign::validate`] and its strings are
    /// writable: setup ids and covariate names without `,`, line breaks or surrounding white
    /// space, covariate names distinct and not a required column's name, comments without line
    /// breaks (a comment with line breaks is written as several comment lines).
    pub fn to_csv(&self) -> String {
        write::to_csv(self)
    }
}

#[cfg(test)]
mod tests;
