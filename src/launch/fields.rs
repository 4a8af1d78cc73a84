//! What entries share: the keys each may have, a key's value, flags, `if`/`unless` and respawn.

use super::args::LaunchError;
use super::place::Ctx;
use serde_yaml::Value;

/// Bounds of `respawn_delay`, s (the supervisor caps the doubled delay at 5 s anyway).
const MIN_DELAY_S: f64 = 0.0;
const MAX_DELAY_S: f64 = 3600.0;

/// The keys each kind of entry takes: anything else is a typo (`If:`, `respwan:`) that
/// would otherwise silently change what runs.
pub(super) const NODE_KEYS: [&str; 13] = [
    "pkg",
    "exec",
    "name",
    "namespace",
    "remap",
    "enclave",
    "managed",
    "param",
    "args",
    "respawn",
    "respawn_delay",
    "if",
    "unless",
];
pub(super) const EXECUTABLE_KEYS: [&str; 6] =
    ["cmd", "name", "respawn", "respawn_delay", "if", "unless"];
pub(super) const ARG_KEYS: [&str; 3] = ["name", "default", "description"];
pub(super) const SET_ENV_KEYS: [&str; 2] = ["name", "value"];
pub(super) const LET_KEYS: [&str; 4] = ["name", "value", "if", "unless"];
pub(super) const PARAM_KEYS: [&str; 3] = ["from", "name", "value"];
pub(super) const REMAP_KEYS: [&str; 2] = ["from", "to"];

pub(super) fn get<'a>(m: &'a serde_yaml::Mapping, key: &str) -> Option<&'a Value> {
    m.get(key)
}

/// `if:` / `unless:` of an entry (ROS 2 launch): true, false, 1 or 0 after substitution.
pub(super) fn condition(
    ctx: &Ctx<'_>,
    body: &serde_yaml::Mapping,
    what: &str,
) -> Result<bool, LaunchError> {
    let flag = |key: &str| -> Result<Option<bool>, LaunchError> {
        let Some(v) = get(body, key) else {
            return Ok(None);
        };
        let s = ctx.string(v, &format!("{what} {key}"))?;
        match s.trim().to_ascii_lowercase().as_str() {
            "true" | "1" => Ok(Some(true)),
            "false" | "0" => Ok(Some(false)),
            other => Err(ctx.err_at(
                key,
                format!("{what} {key}: {other:?}: expected true, false, 1 or 0"),
            )),
        }
    };
    Ok(flag("if")?.unwrap_or(true) && !flag("unless")?.unwrap_or(false))
}

/// `respawn` and `respawn_delay` of an entry named `name`.
pub(super) fn respawn(
    ctx: &Ctx<'_>,
    body: &serde_yaml::Mapping,
    name: &str,
    default: bool,
) -> Result<(bool, f64), LaunchError> {
    let field = |key: &str| -> Result<Option<String>, LaunchError> {
        get(body, key)
            .map(|v| ctx.string(v, &format!("{name} {key}")))
            .transpose()
    };
    let respawn = match field("respawn")?.as_deref() {
        None => default,
        Some("true" | "True") => true,
        Some("false" | "False") => false,
        Some(other) => {
            return Err(ctx.err_at(
                "respawn",
                format!("{name}: respawn {other:?}: expected true or false"),
            ))
        }
    };
    let delay = match field("respawn_delay")? {
        None => 0.2,
        // Bounded here: the supervisor turns it into a `Duration`, which panics on 1e308.
        Some(s) => s
            .parse::<f64>()
            .ok()
            .filter(|d| (MIN_DELAY_S..=MAX_DELAY_S).contains(d))
            .ok_or_else(|| {
                ctx.err_at(
                    "respawn_delay",
                    format!(
                        "{name}: respawn_delay {s:?}: expected seconds from {MIN_DELAY_S} to \
                         {MAX_DELAY_S}"
                    ),
                )
            })?,
    };
    Ok((respawn, delay))
}

/// A boolean key of an entry (`true`, `false`, `1`, `0` after substitution), false when
/// absent.
pub(super) fn flag(
    ctx: &Ctx<'_>,
    body: &serde_yaml::Mapping,
    key: &str,
    what: &str,
) -> Result<bool, LaunchError> {
    let Some(v) = get(body, key) else {
        return Ok(false);
    };
    let s = ctx.string(v, &format!("{what} {key}"))?;
    match s.as_str() {
        "true" | "1" => Ok(true),
        "false" | "0" => Ok(false),
        _ => Err(ctx.err_at(key, format!("{what}: {key} {s:?}: expected true or false"))),
    }
}
