//! The reader and the checks shared by [`Campaign::parse`] and [`Campaign::validate`].

use std::collections::HashMap;

use super::{Campaign, CampaignError, Instrument, Pose, REQUIRED_COLUMNS};

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
            text: text.to_owned(),
        })?;
        if !value.is_finite() {
            return Err(CampaignError::NonFinite {
                file: self.file.to_owned(),
                line: self.line,
                column: i + 1,
                name: name.to_owned(),
                text: text.to_owned(),
            });
        }
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

    fn pose(&self, layout: &Layout, covariates: &[(usize, String)]) -> Result<Pose, CampaignError> {
        let t = self.required_number(layout, T)?;
        let setup = self.text(layout.field[SETUP]).to_owned();
        let text = self.text(layout.field[INSTRUMENT]);
        let instrument: Instrument =
            text.parse().map_err(|_| CampaignError::UnknownInstrument {
                file: self.file.to_owned(),
                line: self.line,
                column: layout.column(INSTRUMENT),
                text: text.to_owned(),
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
                    text: text.to_owned(),
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
            text: text.to_owned(),
        })?;
        let x = self.optional_number(layout, X)?;
        let y = self.optional_number(layout, Y)?;
        let r = self.optional_number(layout, R)?;
        let psi = self.optional_number(layout, PSI)?;
        let covariates = covariates
            .iter()
            .map(|(i, name)| self.number_at(*i, name))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Pose {
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

/// `23` → `[false, true, true, false]`; empty → none; `None` for anything else than distinct
/// digits 1..4.
pub(super) fn parse_follower(text: &str) -> Option<[bool; 4]> {
    let mut follower = [false; 4];
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

pub(super) fn parse(text: &str, source: &str) -> Result<Campaign, CampaignError> {
    let mut comments = Vec::new();
    let mut head: Option<Header> = None;
    let mut poses: Vec<Pose> = Vec::new();
    let mut checker = Checker::new(source);
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    for (n, raw) in text.lines().enumerate() {
        let line = n + 1;
        let trimmed = raw.trim();
        if let Some(comment) = trimmed.strip_prefix('#') {
            // Keep the comment's own spacing: strip the `#` and one space after it only.
            let body = raw.trim_start().strip_prefix('#').unwrap_or(comment);
            let body = body.strip_prefix(' ').unwrap_or(body);
            comments.push(body.trim_end_matches(['\r', '\n']).to_owned());
            continue;
        }
        if trimmed.is_empty() {
            continue;
        }
        let fields: Vec<&str> = raw.split(',').map(str::trim).collect();
        match &head {
            None => head = Some(header(&fields, source, line)?),
            Some(Header {
                layout, covariates, ..
            }) => {
                let expected = layout.field.len() + covariates.len();
                if fields.len() != expected {
                    return Err(CampaignError::WrongFieldCount {
                        file: source.to_owned(),
                        line,
                        expected,
                        found: fields.len(),
                    });
                }
                let row = Row {
                    file: source,
                    line,
                    fields,
                };
                let pose = row.pose(layout, covariates)?;
                checker.add(&pose, layout)?;
                poses.push(pose);
            }
        }
    }
    let Some(Header {
        line: header_line,
        covariates,
        ..
    }) = head
    else {
        return Err(CampaignError::Empty {
            file: source.to_owned(),
        });
    };
    if poses.is_empty() {
        return Err(CampaignError::NoPoses {
            file: source.to_owned(),
            line: header_line,
        });
    }
    checker.finish()?;
    Ok(Campaign {
        source: source.to_owned(),
        comments,
        covariate_names: covariates.into_iter().map(|(_, n)| n).collect(),
        poses,
    })
}

pub(super) fn validate(campaign: &Campaign) -> Result<(), CampaignError> {
    let file = campaign.source.as_str();
    let layout = Layout::canonical();
    let mut checker = Checker::new(file);
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
        for (column, name, value) in numbers.chain(measured).chain(covariates) {
            if let Some(v) = value {
                if !v.is_finite() {
                    return Err(CampaignError::NonFinite {
                        file: file.to_owned(),
                        line: pose.line,
                        column,
                        name,
                        text: v.to_string(),
                    });
                }
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
        checker.add(pose, &layout)?;
    }
    checker.finish()
}

/// What the checker knows about one setup.
struct SetupState {
    id: String,
    instrument: Instrument,
    first_line: usize,
    reset_line: Option<usize>,
}

/// The checks across rows: monotonic time, one instrument and the right resets per setup; and
/// the per-row checks of resets and measured columns.
struct Checker<'a> {
    file: &'a str,
    previous: Option<(f64, usize)>,
    setups: Vec<SetupState>,
    index: HashMap<String, usize>,
}

impl<'a> Checker<'a> {
    fn new(file: &'a str) -> Self {
        Checker {
            file,
            previous: None,
            setups: Vec::new(),
            index: HashMap::new(),
        }
    }

    fn add(&mut self, pose: &Pose, layout: &Layout) -> Result<(), CampaignError> {
        let file = self.file.to_owned();
        let line = pose.line;
        if let Some((previous, previous_line)) = self.previous {
            if pose.t < previous {
                return Err(CampaignError::TimeNotMonotonic {
                    file,
                    line,
                    column: layout.column(T),
                    t: pose.t,
                    previous,
                    previous_line,
                });
            }
        }
        self.previous = Some((pose.t, line));
        check_row(pose, layout, self.file)?;
        let k = match self.index.get(&pose.setup) {
            Some(&k) => k,
            None => {
                self.setups.push(SetupState {
                    id: pose.setup.clone(),
                    instrument: pose.instrument,
                    first_line: line,
                    reset_line: None,
                });
                self.index.insert(pose.setup.clone(), self.setups.len() - 1);
                self.setups.len() - 1
            }
        };
        let Some(setup) = self.setups.get_mut(k) else {
            return Ok(());
        };
        if setup.instrument != pose.instrument {
            return Err(CampaignError::MixedInstrumentsInSetup {
                file,
                line,
                column: layout.column(INSTRUMENT),
                setup: pose.setup.clone(),
                instrument: pose.instrument,
                first: setup.instrument,
                first_line: setup.first_line,
            });
        }
        if pose.reset {
            if let Some(first_line) = setup.reset_line {
                return Err(CampaignError::DuplicateReset {
                    file,
                    line,
                    column: layout.column(RESET),
                    setup: pose.setup.clone(),
                    first_line,
                });
            }
            setup.reset_line = Some(line);
        }
        Ok(())
    }

    fn finish(self) -> Result<(), CampaignError> {
        match self
            .setups
            .into_iter()
            .find(|s| s.instrument.is_relative() && s.reset_line.is_none())
        {
            Some(s) => Err(CampaignError::MissingReset {
                file: self.file.to_owned(),
                line: s.first_line,
                setup: s.id,
                instrument: s.instrument,
            }),
            None => Ok(()),
        }
    }
}

/// The checks of one row on its own: reset allowed, followers of `self`, measured columns.
fn check_row(pose: &Pose, layout: &Layout, file: &str) -> Result<(), CampaignError> {
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
            text: super::write::follower_text(pose.follower),
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
