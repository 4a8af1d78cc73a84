//! [`Campaign::to_csv`]: the writer.

use std::fmt::Write as _;

use super::{Campaign, REQUIRED_COLUMNS};

pub(super) fn to_csv(campaign: &Campaign) -> String {
    let mut out = String::new();
    for comment in &campaign.comments {
        for line in comment.split(['\n', '\r']) {
            if line.is_empty() {
                out.push_str("#\n");
            } else {
                // `writeln!` into a String cannot fail.
                let _ = writeln!(out, "# {line}");
            }
        }
    }
    let header: Vec<&str> = REQUIRED_COLUMNS
        .iter()
        .copied()
        .chain(campaign.covariate_names.iter().map(String::as_str))
        .collect();
    out.push_str(&header.join(","));
    out.push('\n');
    for pose in &campaign.poses {
        let mut fields: Vec<String> = Vec::with_capacity(header.len());
        fields.push(number(pose.t));
        fields.push(pose.setup.clone());
        fields.push(pose.instrument.as_str().to_owned());
        fields.push(if pose.reset { "1" } else { "0" }.to_owned());
        fields.extend(pose.q.iter().map(|&v| number(v)));
        fields.extend(pose.f.iter().map(|&v| number(v)));
        fields.push(follower_text(pose.follower));
        fields.extend([pose.x, pose.y, pose.r, pose.psi].into_iter().map(optional));
        fields.extend(pose.covariates.iter().map(|&v| optional(v)));
        out.push_str(&fields.join(","));
        out.push('\n');
    }
    out
}

/// The shortest text that parses back to the same `f64`: Rust's `Display` (round-trip exact)
/// for ordinary magnitudes, `LowerExp` (also shortest round-trip) for very large or small ones
/// so that 1e-300 does not become 300 zeros.
pub(super) fn number(v: f64) -> String {
    let a = v.abs();
    if a != 0.0 && !(1e-5..1e16).contains(&a) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

fn optional(v: Option<f64>) -> String {
    v.map(number).unwrap_or_default()
}

/// How followers are said when no drive follows: in logs, /diagnostics and messages
/// ([`followers_words`]); [`super::parse_follower`] reads it as it reads `""`.
pub const NO_FOLLOWERS: &str = "none";

/// `[false, true, true, false]` → `23`, no follower → `none`: the one spelling of every text
/// for people (a data file's field is [`follower_text`], empty for none).
pub fn followers_words(follower: [bool; 4]) -> String {
    if follower.contains(&true) {
        follower_text(follower)
    } else {
        NO_FOLLOWERS.to_owned()
    }
}

/// `[false, true, true, false]` → `23`, no follower → empty: the follower field of a
/// campaign or plan file.
pub fn follower_text(follower: [bool; 4]) -> String {
    follower
        .iter()
        .zip(['1', '2', '3', '4'])
        .filter(|(&on, _)| on)
        .map(|(_, c)| c)
        .collect()
}
