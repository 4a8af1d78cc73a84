//! Errors of [`Campaign::parse`](super::Campaign::parse) and
//! [`Campaign::validate`](super::Campaign::validate).

use super::write::number;
use super::Instrument;

/// A field's text for a message: at most 40 characters (a garbage field can be a whole line).
pub(super) fn clip(text: &str) -> String {
    const MAX: usize = 40;
    match text.char_indices().nth(MAX) {
        Some((end, _)) => format!("{}… ({} characters)", &text[..end], text.chars().count()),
        None => text.to_owned(),
    }
}

/// Why a campaign file was rejected. Every variant names the file (`file`, the label given to
/// the parser) and, where there is one, the 1-based line and the 1-based field index
/// (`column`) with the column's header name (`name`). The messages read like
/// `campaign.csv:17:6 (q2): expected a number, found "abc"`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum CampaignError {
    /// No header line: the text is empty or only comments and blank lines.
    #[error("{file}: empty campaign, expected a header line (t,setup,instrument,reset,q1..q4,f1..f4,follower,x,y,r,psi)")]
    Empty { file: String },
    /// A header but no data row.
    #[error("{file}:{line}: the header is not followed by any pose")]
    NoPoses { file: String, line: usize },
    /// A required column is absent from the header.
    #[error("{file}:{line}: missing column {name:?} in the header")]
    MissingColumn {
        file: String,
        line: usize,
        name: &'static str,
    },
    /// A column name appears twice in the header.
    #[error("{file}:{line}:{column} ({name}): duplicate column, first at field {first}")]
    DuplicateColumn {
        file: String,
        line: usize,
        column: usize,
        name: String,
        first: usize,
    },
    /// A header field is empty (e.g. a trailing comma).
    #[error("{file}:{line}:{column}: empty column name in the header")]
    EmptyColumnName {
        file: String,
        line: usize,
        column: usize,
    },
    /// A data row has another number of fields than the header.
    #[error("{file}:{line}: expected {expected} fields as in the header, found {found}")]
    WrongFieldCount {
        file: String,
        line: usize,
        expected: usize,
        found: usize,
    },
    /// A field that must hold a number does not.
    #[error("{file}:{line}:{column} ({name}): expected a number, found {text:?}")]
    BadNumber {
        file: String,
        line: usize,
        column: usize,
        name: String,
        text: String,
    },
    /// A number is NaN or infinite.
    #[error("{file}:{line}:{column} ({name}): expected a finite number, found {text:?}")]
    NonFinite {
        file: String,
        line: usize,
        column: usize,
        name: String,
        text: String,
    },
    /// A number past what any machine can measure (see the module `plausible`: |q| ≤ 1e5 mm,
    /// |f| ≤ 8.6e6 N, |ψ| ≤ 2π, |t| and covariates ≤ 1e10).
    #[error("{file}:{line}:{column} ({name}): {} is beyond any machine, expected |{name}| <= {}", quantity(*.value, unit), quantity(*.limit, unit))]
    OutOfRange {
        file: String,
        line: usize,
        column: usize,
        name: String,
        value: f64,
        limit: f64,
        unit: &'static str,
    },
    /// Actuator positions the machine cannot take: its rods cannot close.
    #[error("{file}:{line}:{column} ({name}): unreachable pose, {why}")]
    Unreachable {
        file: String,
        line: usize,
        column: usize,
        name: &'static str,
        why: String,
    },
    /// Bytes that are not UTF-8.
    #[error("{file}:{line}: invalid UTF-8 at byte {offset} of the file (byte {in_line} of the line), expected UTF-8 text")]
    InvalidUtf8 {
        file: String,
        line: usize,
        /// 0-based byte offset in the file.
        offset: usize,
        /// 1-based byte in the line.
        in_line: usize,
    },
    /// The `instrument` field is not one of the spec's spellings.
    #[error("{file}:{line}:{column} (instrument): expected one of lt, kgm, dbb, li_x, li_y, li_psi, self, circle, none, found {text:?}")]
    UnknownInstrument {
        file: String,
        line: usize,
        column: usize,
        text: String,
    },
    /// The `reset` field is neither `0` nor `1`.
    #[error("{file}:{line}:{column} (reset): expected 0 or 1, found {text:?}")]
    BadReset {
        file: String,
        line: usize,
        column: usize,
        text: String,
    },
    /// The `follower` field is not a set of distinct actuator digits 1..4 (e.g. `23`) or empty.
    #[error("{file}:{line}:{column} (follower): expected distinct actuator digits 1-4 such as \"23\", or none (or nothing), found {text:?}")]
    BadFollower {
        file: String,
        line: usize,
        column: usize,
        text: String,
    },
    /// `t` decreases (equal times are accepted).
    #[error("{file}:{line}:{column} (t): time {} s is before {} s of line {previous_line}; t must be monotonic", number(*.t), number(*.previous))]
    TimeNotMonotonic {
        file: String,
        line: usize,
        column: usize,
        t: f64,
        previous: f64,
        previous_line: usize,
    },
    /// A setup of a relative instrument has no reset pose.
    #[error("{file}:{line}: setup {setup:?} ({instrument}) has no reset pose (a row with reset = 1); its first row is here")]
    MissingReset {
        file: String,
        line: usize,
        setup: String,
        instrument: Instrument,
    },
    /// A setup has a second reset pose.
    #[error("{file}:{line}:{column} (reset): setup {setup:?} already has its reset pose at line {first_line}")]
    DuplicateReset {
        file: String,
        line: usize,
        column: usize,
        setup: String,
        first_line: usize,
    },
    /// A reset pose on an instrument that has no reference (`self`, `none`).
    #[error(
        "{file}:{line}:{column} (reset): instrument {instrument} takes no reset pose, expected 0"
    )]
    UnexpectedReset {
        file: String,
        line: usize,
        column: usize,
        instrument: Instrument,
    },
    /// A measured value the row's instrument gives is empty.
    #[error("{file}:{line}:{column} ({name}): instrument {instrument} measures {name}, expected a value, found nothing")]
    MissingMeasurement {
        file: String,
        line: usize,
        column: usize,
        name: &'static str,
        instrument: Instrument,
    },
    /// A measured value in a column the row's instrument does not give.
    #[error("{file}:{line}:{column} ({name}): instrument {instrument} does not measure {name}, expected nothing, found {}", number(*.value))]
    UnexpectedMeasurement {
        file: String,
        line: usize,
        column: usize,
        name: &'static str,
        instrument: Instrument,
        value: f64,
    },
    /// A self-calibration row without q2 and q3 in follower mode.
    #[error("{file}:{line}:{column} (follower): instrument self needs q2 and q3 in follower mode, expected \"23\", found {text}")]
    SelfNeedsFollowers {
        file: String,
        line: usize,
        column: usize,
        text: String,
    },
    /// A reset pose with a non-zero measured value.
    #[error("{file}:{line}:{column} ({name}): a reset pose measures 0 by definition, expected 0 or nothing, found {}", number(*.value))]
    ResetNotZero {
        file: String,
        line: usize,
        column: usize,
        name: &'static str,
        value: f64,
    },
    /// Rows of one setup name different instruments.
    #[error("{file}:{line}:{column} (instrument): setup {setup:?} was measured with {first} from line {first_line}, found {instrument}")]
    MixedInstrumentsInSetup {
        file: String,
        line: usize,
        column: usize,
        setup: String,
        instrument: Instrument,
        first: Instrument,
        first_line: usize,
    },
}

/// A number with its unit (`-1e300 mm`), or alone where it has none (a covariate's), so that
/// a message never carries a doubled or trailing space.
fn quantity(value: f64, unit: &str) -> String {
    if unit.is_empty() {
        number(value)
    } else {
        format!("{} {unit}", number(value))
    }
}

impl CampaignError {
    /// The file label the error refers to.
    pub fn file(&self) -> &str {
        use CampaignError as E;
        match self {
            E::Empty { file }
            | E::NoPoses { file, .. }
            | E::MissingColumn { file, .. }
            | E::DuplicateColumn { file, .. }
            | E::EmptyColumnName { file, .. }
            | E::WrongFieldCount { file, .. }
            | E::BadNumber { file, .. }
            | E::NonFinite { file, .. }
            | E::OutOfRange { file, .. }
            | E::Unreachable { file, .. }
            | E::InvalidUtf8 { file, .. }
            | E::UnknownInstrument { file, .. }
            | E::BadReset { file, .. }
            | E::BadFollower { file, .. }
            | E::TimeNotMonotonic { file, .. }
            | E::MissingReset { file, .. }
            | E::DuplicateReset { file, .. }
            | E::UnexpectedReset { file, .. }
            | E::MissingMeasurement { file, .. }
            | E::UnexpectedMeasurement { file, .. }
            | E::SelfNeedsFollowers { file, .. }
            | E::ResetNotZero { file, .. }
            | E::MixedInstrumentsInSetup { file, .. } => file,
        }
    }

    /// The 1-based line the error refers to (`None` for [`CampaignError::Empty`]).
    pub fn line(&self) -> Option<usize> {
        use CampaignError as E;
        match self {
            E::Empty { .. } => None,
            E::NoPoses { line, .. }
            | E::MissingColumn { line, .. }
            | E::DuplicateColumn { line, .. }
            | E::EmptyColumnName { line, .. }
            | E::WrongFieldCount { line, .. }
            | E::BadNumber { line, .. }
            | E::NonFinite { line, .. }
            | E::OutOfRange { line, .. }
            | E::Unreachable { line, .. }
            | E::InvalidUtf8 { line, .. }
            | E::UnknownInstrument { line, .. }
            | E::BadReset { line, .. }
            | E::BadFollower { line, .. }
            | E::TimeNotMonotonic { line, .. }
            | E::MissingReset { line, .. }
            | E::DuplicateReset { line, .. }
            | E::UnexpectedReset { line, .. }
            | E::MissingMeasurement { line, .. }
            | E::UnexpectedMeasurement { line, .. }
            | E::SelfNeedsFollowers { line, .. }
            | E::ResetNotZero { line, .. }
            | E::MixedInstrumentsInSetup { line, .. } => Some(*line),
        }
    }

    /// The 1-based field index the error refers to, where it refers to one field.
    pub fn column(&self) -> Option<usize> {
        use CampaignError as E;
        match self {
            E::DuplicateColumn { column, .. }
            | E::EmptyColumnName { column, .. }
            | E::BadNumber { column, .. }
            | E::NonFinite { column, .. }
            | E::OutOfRange { column, .. }
            | E::Unreachable { column, .. }
            | E::UnknownInstrument { column, .. }
            | E::BadReset { column, .. }
            | E::BadFollower { column, .. }
            | E::TimeNotMonotonic { column, .. }
            | E::DuplicateReset { column, .. }
            | E::UnexpectedReset { column, .. }
            | E::MissingMeasurement { column, .. }
            | E::UnexpectedMeasurement { column, .. }
            | E::SelfNeedsFollowers { column, .. }
            | E::ResetNotZero { column, .. }
            | E::MixedInstrumentsInSetup { column, .. } => Some(*column),
            E::Empty { .. }
            | E::NoPoses { .. }
            | E::MissingColumn { .. }
            | E::WrongFieldCount { .. }
            | E::InvalidUtf8 { .. }
            | E::MissingReset { .. } => None,
        }
    }
}
