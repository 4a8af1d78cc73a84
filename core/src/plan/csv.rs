//! PLAN.csv: a planned campaign in the campaign grammar without measured values. One row per
//! pose to visit: `setup,instrument,reset,follower,x,y`, x and y the target TCP (mm, absolute:
//! nothing is measured yet), `follower` `23` for self-calibration (q2, q3 followers) and
//! empty where the cell's drives hold their positions as they do for its other campaigns.
//! `#` lines are comments (the planner says there what each setup is for). Within a setup
//! the reset pose comes first, as in [`crate::design`].

use crate::campaign::Instrument;
use crate::design::{self, PlannedPose};
use std::fmt::Write as _;

/// The header of PLAN.csv.
pub const HEADER: &str = "setup,instrument,reset,follower,x,y";

/// A PLAN.csv that is not one: file, line, column and what was expected.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{file}:{line}:{column}: {what}")]
pub struct PlanCsvError {
    pub file: String,
    pub line: usize,
    pub column: usize,
    pub what: String,
}

/// The plan's poses as PLAN.csv, `comments` first (one `# ` line each).
pub fn to_csv(poses: &[PlannedPose], comments: &[String]) -> String {
    let mut out = String::new();
    for c in comments.iter().flat_map(|c| c.lines()) {
        let _ = writeln!(out, "# {c}");
    }
    out.push_str(HEADER);
    out.push('\n');
    for p in poses {
        let follower = if p.instrument == Instrument::SelfCal {
            "23"
        } else {
            ""
        };
        let _ = writeln!(
            out,
            "{},{},{},{follower},{},{}",
            p.setup,
            p.instrument.as_str(),
            u8::from(p.reset),
            p.x,
            p.y
        );
    }
    out
}

/// Parses PLAN.csv (`source` names it in errors): every field checked, every relative
/// setup with exactly one reset pose, first; targets inside the workspace.
pub fn parse(text: &str, source: &str) -> Result<Vec<PlannedPose>, PlanCsvError> {
    let err = |line: usize, column: usize, what: String| PlanCsvError {
        file: source.to_owned(),
        line,
        column,
        what,
    };
    let mut poses = Vec::new();
    let mut lines = Vec::new();
    let mut header_seen = false;
    for (k, raw) in text.lines().enumerate() {
        let line = k + 1;
        let t = raw.trim();
        if t.is_empty() || t.starts_with('#') {
            continue;
        }
        if !header_seen {
            if t != HEADER {
                return Err(err(line, 1, format!("expected the header `{HEADER}`")));
            }
            header_seen = true;
            continue;
        }
        poses.push(parse_row(t).map_err(|(col, what)| err(line, col, what))?);
        lines.push(line);
    }
    if !header_seen {
        return Err(err(1, 1, format!("no header `{HEADER}`")));
    }
    check_setups(&poses).map_err(|(k, what)| err(lines[k], 1, what))?;
    Ok(poses)
}

/// One row: the pose and its line, or (column, what was expected).
fn parse_row(t: &str) -> Result<PlannedPose, (usize, String)> {
    let f: Vec<&str> = t.split(',').map(str::trim).collect();
    if f.len() != 6 {
        return Err((
            1,
            format!("expected 6 fields ({HEADER}), found {}", f.len()),
        ));
    }
    if f[0].is_empty() {
        return Err((1, "empty setup id".to_owned()));
    }
    let instrument: Instrument = f[1]
        .parse()
        .map_err(|_| (2, format!("unknown instrument `{}`", f[1])))?;
    if matches!(instrument, Instrument::None | Instrument::Circle) {
        return Err((2, format!("`{}` measures nothing to plan", f[1])));
    }
    let reset = match f[2] {
        "0" => false,
        "1" => true,
        other => return Err((3, format!("reset `{other}`: expected 0 or 1"))),
    };
    let want = if instrument == Instrument::SelfCal {
        "23"
    } else {
        ""
    };
    if f[3] != want {
        return Err((
            4,
            format!("follower `{}`: expected `{want}` for {instrument}", f[3]),
        ));
    }
    let number = |col: usize| {
        f[col - 1]
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or((col, format!("`{}` is not a finite number (mm)", f[col - 1])))
    };
    let (x, y) = (number(5)?, number(6)?);
    if design::clamp_to_workspace(x, y) != (x, y) {
        return Err((5, format!("target ({x}, {y}) mm is outside the workspace")));
    }
    Ok(PlannedPose {
        setup: f[0].to_owned(),
        instrument,
        reset,
        x,
        y,
    })
}

/// Every setup one instrument, a relative setup's reset first and once, self none; the
/// error names the index of the pose where a setup breaks the rule.
fn check_setups(poses: &[PlannedPose]) -> Result<(), (usize, String)> {
    for (k, p) in poses.iter().enumerate() {
        let first = poses.iter().position(|o| o.setup == p.setup) == Some(k);
        let owner = &poses[poses.iter().position(|o| o.setup == p.setup).unwrap_or(k)];
        if owner.instrument != p.instrument {
            return Err((k, format!("setup {} mixes instruments", p.setup)));
        }
        let relative = p.instrument.is_relative();
        if p.reset && !(relative && first) {
            return Err((
                k,
                format!(
                    "setup {}: a reset pose only first in a relative setup",
                    p.setup
                ),
            ));
        }
        if relative && first && !p.reset {
            return Err((
                k,
                format!("setup {}: its first pose must be its reset", p.setup),
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_plan_reads_back_as_written() {
        let mut poses = design::kgm()[..9].to_vec();
        poses.extend(design::self_cal()[..3].iter().cloned());
        let text = to_csv(&poses, &["what it is for".to_owned()]);
        assert!(text.starts_with("# what it is for\n"));
        assert_eq!(parse(&text, "p.csv").expect("a plan"), poses);
    }

    #[test]
    fn a_bad_plan_names_line_and_column() {
        let head = format!("# c\n{HEADER}\n");
        let e = parse(&format!("{head}s,self,0,,0,1700\n"), "p.csv").expect_err("follower");
        assert_eq!((e.line, e.column), (3, 4), "{e}");
        let e = parse(&format!("{head}s,lt,0,,0,1700\n"), "p.csv").expect_err("no reset");
        assert_eq!((e.line, e.column), (3, 1), "{e}");
        let e = parse(&format!("{head}s,lt,1,,0,3000\n"), "p.csv").expect_err("outside");
        assert_eq!((e.line, e.column), (3, 5), "{e}");
        let e = parse("s,lt,1,,0,1700\n", "p.csv").expect_err("header");
        assert_eq!((e.line, e.column), (1, 1), "{e}");
    }
}
