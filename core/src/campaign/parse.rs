//! The reader ([`CampaignReader`], [`Campaign::parse`]) and the checks it shares with
//! [`Campaign::validate`].

use std::collections::HashMap;

use super::error::clip;
use super::plausible;
use super::write::NO_FOLLOWERS;
use super::{Campaign, CampaignError, Instrument, MeasuredPose, REQUIRED_COLUMNS};

// Positions in `REQUIRED_COLUMNS`.
const T: usize = 0;
const SETUP: usize = 1;
const INSTRUMENT: usize = 2;
const RESET: usize = 3;
const Q: usize = 4;
const F: usize = 8;
const FOLLOWER: usize = 12;
const X: usize = 13;
const Y: usize = 14;
const R: usize = 15;
const PSI: usize = 16;

/// Where the required columns are: `field[k]` is the 0-based field index of
/// `REQUIRED_COLUMNS[k]`.
#[derive(Debug)]
struct Layout {
    field: [usize; REQUIRED_COLUMNS.len()],
}

impl Layout {
    /// The layout [`Campaign::to_csv`] writes.
    fn canonical() -> Layout {
        let mut field = [0; REQUIRED_COLUMNS.len()];
        for (k, f) in field.iter_mut().enumerate() {
            *f = k;
        }
        Layout { field }
    }

    /// 1-based column of required column `k`.
    fn column(&self, k: usize) -> usize {
        self.field.get(k).map_or(0, |f| f + 1)
    }
}

/// Name of required column `k`.
fn name(k: usize) -> &'static str {
    REQUIRED_COLUMNS.get(k).copied().unwrap_or("?")
}

/// A data line being read: its fields and where it is.
struct Row<'a> {
    file: &'a str,
    line: usize,
    fields: Vec<&'a str>,
}

impl<'a> Row<'a> {
    fn text(&self, i: usize) -> &'a str {
        self.fields.get(i).copied().unwrap_or("")
    }

    fn number_at(&self, i: usize, name: &str) -> Result<Option<f64>, CampaignError> {
        let text = self.text(i);
        if text.is_empty() {
            return Ok(None);
        }
        let value: f64 = text.parse().map_err(|_| CampaignError::BadNumber {
            file: self.file.to_owned(),
            line: self.line,
            column: i + 1,
            name: name.to_owned(),
            text: clip(text),
        })?;
        let at = At {
            file: self.file,
            line: self.line,
        };
        at.number(i + 1, name, value, text)?;
        Ok(Some(value))
    }

    fn required_number(&self, layout: &Layout, k: usize) -> Result<f64, CampaignError> {
        let i = layout.field[k];
        self.number_at(i, name(k))?
            .ok_or_else(|| CampaignError::BadNumber {
                file: self.file.to_owned(),
                line: self.line,
                column: i + 1,
                name: name(k).to_owned(),
                text: String::new(),
            })
    }

    fn optional_number(&self, layout: &Layout, k: usize) -> Result<Option<f64>, CampaignError> {
        self.number_at(layout.field[k], name(k))
    }

    fn pose(
        &self,
        layout: &Layout,
        covariates: &[(usize, String)],
    ) -> Result<MeasuredPose, CampaignError> {
        let t = self.required_number(layout, T)?;
        let setup = self.text(layout.field[SETUP]).to_owned();
        let text = self.text(layout.field[INSTRUMENT]);
        let instrument: Instrument =
            text.parse().map_err(|_| CampaignError::UnknownInstrument {
                file: self.file.to_owned(),
                line: self.line,
                column: layout.column(INSTRUMENT),
                text: clip(text),
            })?;
        let text = self.text(layout.field[RESET]);
        let reset = match text {
            "0" => false,
            "1" => true,
            _ => {
                return Err(CampaignError::BadReset {
                    file: self.file.to_owned(),
                    line: self.line,
                    column: layout.column(RESET),
                    text: clip(text),
                })
            }
        };
        let mut q = [0.0; 4];
        for (j, v) in q.iter_mut().enumerate() {
            *v = self.required_number(layout, Q + j)?;
        }
        let mut f = [0.0; 4];
        for (j, v) in f.iter_mut().enumerate() {
            *v = self.required_number(layout, F + j)?;
        }
        let text = self.text(layout.field[FOLLOWER]);
        let follower = parse_follower(text).ok_or_else(|| CampaignError::BadFollower {
            file: self.file.to_owned(),
            line: self.line,
            column: layout.column(FOLLOWER),
            text: clip(text),
        })?;
        let x = self.optional_number(layout, X)?;
        let y = self.optional_number(layout, Y)?;
        let r = self.optional_number(layout, R)?;
        let psi = self.optional_number(layout, PSI)?;
        let covariates = covariates
            .iter()
            .map(|(i, name)| self.number_at(*i, name))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(MeasuredPose {
            t,
            setup,
            instrument,
            reset,
            q,
            f,
            follower,
            x,
            y,
            r,
            psi,
            covariates,
            line: self.line,
        })
    }
}

/// `23` → `[false, true, true, false]`; `none` and empty both → none (every reader of
/// followers: a campaign's column, a plan, the node parameter, `rpkm plan --follower`);
/// `None` for anything else than distinct digits 1..4.
pub fn parse_follower(text: &str) -> Option<[bool; 4]> {
    let mut follower = [false; 4];
    let text = text.trim();
    if text == NO_FOLLOWERS {
        return Some(follower);
    }
    for c in text.chars() {
        let k = match c {
            '1' => 0,
            '2' => 1,
            '3' => 2,
            '4' => 3,
            _ => return None,
        };
        let slot = follower.get_mut(k)?;
        if *slot {
            return None;
        }
        *slot = true;
    }
    Some(follower)
}

/// The header line of a file.
#[derive(Debug)]
struct Header {
    line: usize,
    layout: Layout,
    /// The covariates (field index, name), in header order.
    covariates: Vec<(usize, String)>,
}

fn header(fields: &[&str], file: &str, line: usize) -> Result<Header, CampaignError> {
    let mut seen: HashMap<&str, usize> = HashMap::new();
    let mut field = [usize::MAX; REQUIRED_COLUMNS.len()];
    let mut covariates = Vec::new();
    for (i, &name) in fields.iter().enumerate() {
        if name.is_empty() {
            return Err(CampaignError::EmptyColumnName {
                file: file.to_owned(),
                line,
                column: i + 1,
            });
        }
        if let Some(first) = seen.insert(name, i) {
            return Err(CampaignError::DuplicateColumn {
                file: file.to_owned(),
                line,
                column: i + 1,
                name: name.to_owned(),
                first: first + 1,
            });
        }
        match REQUIRED_COLUMNS.iter().position(|&r| r == name) {
            Some(k) => {
                if let Some(f) = field.get_mut(k) {
                    *f = i;
                }
            }
            None => covariates.push((i, name.to_owned())),
        }
    }
    for (k, &f) in field.iter().enumerate() {
        if f == usize::MAX {
            return Err(CampaignError::MissingColumn {
                file: file.to_owned(),
                line,
                name: name(k),
            });
        }
    }
    Ok(Header {
        line,
        layout: Layout { field },
        covariates,
    })
}

/// Reads a campaign file one line at a time, with every rule a line and the lines before it
/// can break: the grammar (header, field count, numbers, names), the values (finite, within
/// the [`plausible`](super::plausible) bounds, reachable), and across rows monotonic time, one
/// instrument and at most one reset per setup. [`Campaign::parse`] is this reader over a whole
/// file, stopping at the first error; a stream (the ingest node) reads on after an error as if
/// the bad line were absent. [`CampaignReader::finish`] adds the rules only the whole file can
/// break.
///
/// ```
/// use rpkm_core::campaign::CampaignReader;
/// let mut reader = CampaignReader::new("stdin");
/// let header = b"t,setup,instrument,reset,q1,q2,q3,q4,f1,f2,f3,f4,follower,x,y,r,psi";
/// assert_eq!(reader.read_line(header), Ok(None));
/// let bad = reader.read_line(b"0,A,none,true,2611,2611,789,789,0,0,0,0,,,,,").unwrap_err();
/// assert_eq!(bad.to_string(), r#"stdin:2:4 (reset): expected 0 or 1, found "true""#);
/// let pose = reader.read_line(b"1,A,none,0,2611,2611,789,789,0,0,0,0,,,,,").unwrap();
/// assert_eq!(pose.map(|p| p.line), Some(3));
/// ```
#[derive(Debug)]
pub struct CampaignReader {
    source: String,
    /// Lines read so far (the 1-based number of the last one).
    line: usize,
    /// Bytes read so far: the offset of the next line in the file.
    offset: usize,
    head: Option<Header>,
    checker: Checker,
    comments: Vec<String>,
    poses: usize,
}

impl CampaignReader {
    /// A reader of the source called `source` in messages (a file name, `stdin`).
    pub fn new(source: &str) -> Self {
        CampaignReader {
            source: source.to_owned(),
            line: 0,
            offset: 0,
            head: None,
            checker: Checker::new(),
            comments: Vec::new(),
            poses: 0,
        }
    }

    /// Reads the next line, given without its `\n` (a `\r` before it is ignored). `Ok(None)`
    /// for a comment, a blank line and the header; `Ok(Some(pose))` for a row that keeps
    /// every rule; `Err` names the line (and column, or byte) and what was expected; the
    /// reader then goes on as if the line were absent.
    pub fn read_line(&mut self, bytes: &[u8]) -> Result<Option<MeasuredPose>, CampaignError> {
        self.line += 1;
        let offset = self.offset;
        self.offset += bytes.len() + 1;
        let raw = std::str::from_utf8(bytes).map_err(|e| CampaignError::InvalidUtf8 {
            file: self.source.clone(),
            line: self.line,
            offset: offset + e.valid_up_to(),
            in_line: e.valid_up_to() + 1,
        })?;
        let raw = if self.line == 1 {
            // A leading byte order mark, as spreadsheets write.
            raw.strip_prefix('\u{feff}').unwrap_or(raw)
        } else {
            raw
        };
        let raw = raw.strip_suffix('\r').unwrap_or(raw);
        let trimmed = raw.trim();
        if trimmed.starts_with('#') {
            self.comments.push(comment_body(raw));
            return Ok(None);
        }
        if trimmed.is_empty() {
            return Ok(None);
        }
        let fields: Vec<&str> = raw.split(',').map(str::trim).collect();
        let Some(head) = &self.head else {
            self.head = Some(header(&fields, &self.source, self.line)?);
            return Ok(None);
        };
        let pose = row(head, &self.source, self.line, fields)?;
        self.checker.add(&pose, &head.layout, &self.source)?;
        self.poses += 1;
        Ok(Some(pose))
    }

    /// The 1-based number of the last line read.
    pub fn line(&self) -> usize {
        self.line
    }

    /// Whether the header has been read.
    pub fn has_header(&self) -> bool {
        self.head.is_some()
    }

    /// The covariate names of the header, in header order (none before it).
    pub fn covariate_names(&self) -> Vec<String> {
        self.head
            .iter()
            .flat_map(|h| h.covariates.iter().map(|(_, n)| n.clone()))
            .collect()
    }

    /// The comment lines read so far (without the `#` and one following space).
    pub fn comments(&self) -> &[String] {
        &self.comments
    }

    /// The rules only the whole file can break: a header, at least one pose, a reset pose in
    /// every setup of a relative instrument.
    pub fn finish(&self) -> Result<(), CampaignError> {
        let file = self.source.clone();
        let Some(head) = &self.head else {
            return Err(CampaignError::Empty { file });
        };
        if self.poses == 0 {
            return Err(CampaignError::NoPoses {
                file,
                line: head.line,
            });
        }
        self.checker.finish(&self.source)
    }
}

/// A comment line's text: the `#` and one space after it stripped, its own spacing kept.
fn comment_body(raw: &str) -> String {
    let body = raw.trim_start().strip_prefix('#').unwrap_or(raw);
    let body = body.strip_prefix(' ').unwrap_or(body);
    body.trim_end_matches(['\r', '\n']).to_owned()
}

/// One data row of a file whose header is `head`.
fn row(
    head: &Header,
    file: &str,
    line: usize,
    fields: Vec<&str>,
) -> Result<MeasuredPose, CampaignError> {
    let expected = head.layout.field.len() + head.covariates.len();
    if fields.len() != expected {
        return Err(CampaignError::WrongFieldCount {
            file: file.to_owned(),
            line,
            expected,
            found: fields.len(),
        });
    }
    Row { file, line, fields }.pose(&head.layout, &head.covariates)
}

pub(super) fn parse(bytes: &[u8], source: &str) -> Result<Campaign, CampaignError> {
    let mut reader = CampaignReader::new(source);
    let mut poses = Vec::new();
    for line in bytes.split(|&b| b == b'\n') {
        poses.extend(reader.read_line(line)?);
    }
    reader.finish()?;
    let covariate_names = reader.covariate_names();
    Ok(Campaign {
        source: source.to_owned(),
        comments: reader.comments,
        covariate_names,
        poses,
    })
}

pub(super) fn validate(campaign: &Campaign) -> Result<(), CampaignError> {
    let file = campaign.source.as_str();
    let layout = Layout::canonical();
    let mut checker = Checker::new();
    for pose in &campaign.poses {
        let numbers = [(T, pose.t)]
            .into_iter()
            .chain(pose.q.iter().enumerate().map(|(j, &v)| (Q + j, v)))
            .chain(pose.f.iter().enumerate().map(|(j, &v)| (F + j, v)))
            .map(|(k, v)| (layout.column(k), name(k).to_owned(), Some(v)));
        let measured = [(X, pose.x), (Y, pose.y), (R, pose.r), (PSI, pose.psi)]
            .into_iter()
            .map(|(k, v)| (layout.column(k), name(k).to_owned(), v));
        let covariates = campaign.covariate_names.iter().enumerate().map(|(j, n)| {
            (
                REQUIRED_COLUMNS.len() + j + 1,
                n.clone(),
                pose.covariates.get(j).copied().flatten(),
            )
        });
        let at = At {
            file,
            line: pose.line,
        };
        for (column, name, value) in numbers.chain(measured).chain(covariates) {
            if let Some(v) = value {
                at.number(column, &name, v, &super::write::number(v))?;
            }
        }
        if pose.covariates.len() != campaign.covariate_names.len() {
            return Err(CampaignError::WrongFieldCount {
                file: file.to_owned(),
                line: pose.line,
                expected: REQUIRED_COLUMNS.len() + campaign.covariate_names.len(),
                found: REQUIRED_COLUMNS.len() + pose.covariates.len(),
            });
        }
        checker.add(pose, &layout, file)?;
    }
    checker.finish(file)
}

/// Where a value is: file and line, for the checks of one number.
struct At<'a> {
    file: &'a str,
    line: usize,
}

impl At<'_> {
    /// A number of column `column` (1-based) called `name`, read from `text`: finite and
    /// within its [`plausible::bound`].
    fn number(
        &self,
        column: usize,
        name: &str,
        value: f64,
        text: &str,
    ) -> Result<(), CampaignError> {
        if !value.is_finite() {
            return Err(CampaignError::NonFinite {
                file: self.file.to_owned(),
                line: self.line,
                column,
                name: name.to_owned(),
                text: clip(text),
            });
        }
        let (limit, unit) = plausible::bound(name);
        if value.abs() > limit {
            return Err(CampaignError::OutOfRange {
                file: self.file.to_owned(),
                line: self.line,
                column,
                name: name.to_owned(),
                value,
                limit,
                unit,
            });
        }
        Ok(())
    }
}

/// What the checker knows about one setup.
#[derive(Debug)]
struct SetupState {
    id: String,
    instrument: Instrument,
    first_line: usize,
    reset_line: Option<usize>,
}

/// The checks across rows: monotonic time, one instrument and the right resets per setup; and
/// the checks of one row (resets, measured columns, reachability). A row that breaks a rule
/// leaves the checker as it was.
#[derive(Debug)]
struct Checker {
    previous: Option<(f64, usize)>,
    setups: Vec<SetupState>,
    index: HashMap<String, usize>,
}

impl Checker {
    fn new() -> Self {
        Checker {
            previous: None,
            setups: Vec::new(),
            index: HashMap::new(),
        }
    }

    fn add(
        &mut self,
        pose: &MeasuredPose,
        layout: &Layout,
        file: &str,
    ) -> Result<(), CampaignError> {
        if let Some((previous, previous_line)) = self.previous {
            if pose.t < previous {
                return Err(CampaignError::TimeNotMonotonic {
                    file: file.to_owned(),
                    line: pose.line,
                    column: layout.column(T),
                    t: pose.t,
                    previous,
                    previous_line,
                });
            }
        }
        check_row(pose, layout, file)?;
        check_reachable(pose, layout, file)?;
        let known = self
            .index
            .get(&pose.setup)
            .and_then(|&k| self.setups.get(k));
        if let Some(setup) = known {
            check_setup(setup, pose, layout, file)?;
        }
        self.previous = Some((pose.t, pose.line));
        let k = if let Some(&k) = self.index.get(&pose.setup) {
            k
        } else {
            self.setups.push(SetupState {
                id: pose.setup.clone(),
                instrument: pose.instrument,
                first_line: pose.line,
                reset_line: None,
            });
            self.index.insert(pose.setup.clone(), self.setups.len() - 1);
            self.setups.len() - 1
        };
        if let Some(setup) = self.setups.get_mut(k) {
            if pose.reset {
                setup.reset_line = Some(pose.line);
            }
        }
        Ok(())
    }

    fn finish(&self, file: &str) -> Result<(), CampaignError> {
        match self
            .setups
            .iter()
            .find(|s| s.instrument.is_relative() && s.reset_line.is_none())
        {
            Some(s) => Err(CampaignError::MissingReset {
                file: file.to_owned(),
                line: s.first_line,
                setup: s.id.clone(),
                instrument: s.instrument,
            }),
            None => Ok(()),
        }
    }
}

/// A further row of a known setup: the same instrument, no second reset pose.
fn check_setup(
    setup: &SetupState,
    pose: &MeasuredPose,
    layout: &Layout,
    file: &str,
) -> Result<(), CampaignError> {
    if setup.instrument != pose.instrument {
        return Err(CampaignError::MixedInstrumentsInSetup {
            file: file.to_owned(),
            line: pose.line,
            column: layout.column(INSTRUMENT),
            setup: pose.setup.clone(),
            instrument: pose.instrument,
            first: setup.instrument,
            first_line: setup.first_line,
        });
    }
    match setup.reset_line {
        Some(first_line) if pose.reset => Err(CampaignError::DuplicateReset {
            file: file.to_owned(),
            line: pose.line,
            column: layout.column(RESET),
            setup: pose.setup.clone(),
            first_line,
        }),
        _ => Ok(()),
    }
}

/// The row's actuator positions are a pose of the machine ([`plausible::reachable`]); the
/// error names the actuator to blame.
fn check_reachable(pose: &MeasuredPose, layout: &Layout, file: &str) -> Result<(), CampaignError> {
    plausible::reachable(pose.q).map_err(|u| CampaignError::Unreachable {
        file: file.to_owned(),
        line: pose.line,
        column: layout.column(Q + u.actuator),
        name: name(Q + u.actuator),
        why: u.why,
    })
}

/// The checks of one row on its own: reset allowed, followers of `self`, measured columns.
fn check_row(pose: &MeasuredPose, layout: &Layout, file: &str) -> Result<(), CampaignError> {
    let instrument = pose.instrument;
    if pose.reset && !instrument.takes_reset() {
        return Err(CampaignError::UnexpectedReset {
            file: file.to_owned(),
            line: pose.line,
            column: layout.column(RESET),
            instrument,
        });
    }
    if instrument == Instrument::SelfCal && !(pose.follower[1] && pose.follower[2]) {
        return Err(CampaignError::SelfNeedsFollowers {
            file: file.to_owned(),
            line: pose.line,
            column: layout.column(FOLLOWER),
            text: super::write::followers_words(pose.follower),
        });
    }
    let m = instrument.measures();
    for (k, measured, value) in [
        (X, m.x, pose.x),
        (Y, m.y, pose.y),
        (R, m.r, pose.r),
        (PSI, m.psi, pose.psi),
    ] {
        let column = layout.column(k);
        match value {
            Some(value) if !measured => {
                return Err(CampaignError::UnexpectedMeasurement {
                    file: file.to_owned(),
                    line: pose.line,
                    column,
                    name: name(k),
                    instrument,
                    value,
                })
            }
            Some(value) if pose.reset && value != 0.0 => {
                return Err(CampaignError::ResetNotZero {
                    file: file.to_owned(),
                    line: pose.line,
                    column,
                    name: name(k),
                    value,
                })
            }
            None if measured && !pose.reset => {
                return Err(CampaignError::MissingMeasurement {
                    file: file.to_owned(),
                    line: pose.line,
                    column,
                    name: name(k),
                    instrument,
                })
            }
            _ => {}
        }
    }
    Ok(())
}
