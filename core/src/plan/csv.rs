//! PLAN.csv: a planned campaign in the campaign grammar without measured values. One row per
//! pose to visit: `setup,instrument,reset,follower,x,y`, x and y the target TCP (mm, absolute:
//! nothing is measured yet), `follower` the drives in follower mode as the campaign CSV
//! writes them: `23` for self-calibration (q2, q3 followers) and for an external instrument
//! the mode the plan measures in (`23`, or empty: all four drives active, which only a model
//! with the preload's deflection can represent). `#` lines are comments (the planner says
//! there what each setup is for and why its drives are in their mode). Within a setup the
//! reset pose comes first, as in [`crate::design`].

use crate::campaign::{follower_text, parse_follower, Instrument};
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
        let _ = writeln!(
            out,
            "{},{},{},{},{},{}",
            p.setup,
            p.instrument.as_str(),
            u8::from(p.reset),
            follower_text(p.follower),
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
    let follower = parse_follower(f[3]).ok_or_else(|| {
        (
            4,
            format!(
                "follower `{}`: expected distinct drive digits 1-4 such as `23`, or nothing",
                f[3]
            ),
        )
    })?;
    if instrument == Instrument::SelfCal && follower != design::FOLLOWERS_23 {
        return Err((4, format!("follower `{}`: expected `23` for self", f[3])));
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
        follower,
        ..PlannedPose::new(f[0], instrument, reset, (x, y))
    })
}

/// The header of a list of target TCP positions (`--where`).
pub const TARGETS_HEADER: &str = "x,y";

/// Parses a list of target TCP positions (`x,y` header, then one `x,y` per line, mm, `#`
/// comments): where the TCP must be right (a production path); every target inside the
/// workspace, at least one.
pub fn parse_targets(text: &str, source: &str) -> Result<Vec<(f64, f64)>, PlanCsvError> {
    let err = |line: usize, column: usize, what: String| PlanCsvError {
        file: source.to_owned(),
        line,
        column,
        what,
    };
    let mut header_seen = false;
    let mut out = Vec::new();
    for (k, raw) in text.lines().enumerate() {
        let t = raw.trim();
        if t.is_empty() || t.starts_with('#') {
            continue;
        }
        if !header_seen {
            if t.replace(' ', "") != TARGETS_HEADER {
                return Err(err(
                    k + 1,
                    1,
                    format!("expected the header `{TARGETS_HEADER}`"),
                ));
            }
            header_seen = true;
            continue;
        }
        let f: Vec<&str> = t.split(',').map(str::trim).collect();
        if f.len() != 2 {
            return Err(err(
                k + 1,
                1,
                format!("expected 2 fields (x,y), found {}", f.len()),
            ));
        }
        let mut v = [0.0; 2];
        for (c, slot) in v.iter_mut().enumerate() {
            *slot = f[c]
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| {
                    err(
                        k + 1,
                        c + 1,
                        format!("`{}` is not a finite number (mm)", f[c]),
                    )
                })?;
        }
        if design::clamp_to_workspace(v[0], v[1]) != (v[0], v[1]) {
            return Err(err(
                k + 1,
                1,
                format!("target ({}, {}) mm is outside the workspace", v[0], v[1]),
            ));
        }
        out.push((v[0], v[1]));
    }
    if out.is_empty() {
        return Err(err(
            1,
            1,
            format!("no target: expected `{TARGETS_HEADER}` then lines of x,y (mm)"),
        ));
    }
    Ok(out)
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
        poses[3].follower = design::FOLLOWERS_23;
        poses.extend(design::self_cal()[..3].iter().cloned());
        let text = to_csv(&poses, &["what it is for".to_owned()]);
        assert!(text.starts_with("# what it is for\n"));
        assert_eq!(parse(&text, "p.csv").expect("a plan"), poses);
    }

    #[test]
    fn targets_read_back_and_a_bad_one_names_its_place() {
        let t = parse_targets("# path\nx,y\n0,1700\n-150, 700\n", "w.csv").expect("targets");
        assert_eq!(t, vec![(0.0, 1700.0), (-150.0, 700.0)]);
        let e = parse_targets("x,y\n0,abc\n", "w.csv").expect_err("number");
        assert_eq!((e.line, e.column), (2, 2), "{e}");
        let e = parse_targets("x,y\n0,3000\n", "w.csv").expect_err("outside");
        assert_eq!(e.line, 2, "{e}");
        assert!(parse_targets("x,y\n", "w.csv").is_err());
    }

    #[test]
    fn a_bad_plan_names_line_and_column() {
        let head = format!("# c\n{HEADER}\n");
        let e = parse(&format!("{head}s,self,0,,0,1700\n"), "p.csv").expect_err("follower");
        assert_eq!((e.line, e.column), (3, 4), "{e}");
        let e = parse(&format!("{head}s,lt,1,22,0,1700\n"), "p.csv").expect_err("twice");
        assert_eq!((e.line, e.column), (3, 4), "{e}");
        let e = parse(&format!("{head}s,lt,0,,0,1700\n"), "p.csv").expect_err("no reset");
        assert_eq!((e.line, e.column), (3, 1), "{e}");
        let e = parse(&format!("{head}s,lt,1,,0,3000\n"), "p.csv").expect_err("outside");
        assert_eq!((e.line, e.column), (3, 5), "{e}");
        let e = parse("s,lt,1,,0,1700\n", "p.csv").expect_err("header");
        assert_eq!((e.line, e.column), (1, 1), "{e}");
    }
}
