//! A launch file read into its description: arguments, `arg`, `set_env` and `executable`
//! entries.

use super::args::LaunchError;
use super::description::{LaunchDescription, LaunchProgram, NodeSpec, COMMANDS};
use super::fields::{
    condition, get, respawn, ARG_KEYS, EXECUTABLE_KEYS, LET_KEYS, NODE_KEYS, SET_ENV_KEYS,
};
use super::node_entry::node;
use super::place::{entry_lines, unlocated_error_line, utf8_error_place, Ctx};
use rpkm_nodes::node::params::parse_yaml;
use serde_yaml::Value;
use std::collections::BTreeMap;
use std::path::Path;

/// The `NAME:=VALUE` launch arguments of the command line, by name.
fn launch_arguments(overrides: &[String]) -> Result<BTreeMap<String, String>, String> {
    let mut given = BTreeMap::new();
    for o in overrides {
        let (k, v) = o
            .split_once(":=")
            .ok_or_else(|| format!("launch argument {o:?}: expected NAME:=VALUE"))?;
        given.insert(k.to_owned(), v.to_owned());
    }
    Ok(given)
}

impl LaunchDescription {
    /// Reads `file` with the launch arguments `overrides` (`NAME:=VALUE`).
    pub fn load(file: &Path, overrides: &[String]) -> Result<Self, LaunchError> {
        let name = file.display().to_string();
        let bytes = std::fs::read(file).map_err(|source| LaunchError::Read {
            file: name.clone(),
            source,
        })?;
        let text = std::str::from_utf8(&bytes).map_err(|e| {
            let (line, offset) = utf8_error_place(&bytes, &e);
            LaunchError::Utf8 {
                file: name.clone(),
                line,
                offset,
            }
        })?;
        let dir = file.parent().unwrap_or(Path::new("."));
        let dir = if dir.as_os_str().is_empty() {
            Path::new(".")
        } else {
            dir
        };
        Self::parse(text, &name, dir, overrides)
    }

    /// Parses launch YAML; `dir` resolves relative parameter files and `$(dirname)`.
    pub fn parse(
        text: &str,
        file: &str,
        dir: &Path,
        overrides: &[String],
    ) -> Result<Self, LaunchError> {
        let doc = parse_yaml(text, file).map_err(|mut e| {
            // serde_yaml locates most errors, not a second document: name its place
            if e.line == 0 {
                (e.line, e.column) = (unlocated_error_line(text), 1);
            }
            e
        })?;
        let (launch_line, mut starts) = entry_lines(text);
        let end = text.lines().count() + 1;
        let mut ctx = Ctx {
            file: file.to_owned(),
            text,
            dir,
            vars: BTreeMap::new(),
            entry: (launch_line, end),
        };
        let argument = |what: String| LaunchError::Argument {
            file: file.to_owned(),
            what,
        };
        let given = launch_arguments(overrides).map_err(argument)?;
        let items = doc
            .get("launch")
            .and_then(Value::as_sequence)
            .ok_or_else(|| ctx.err("expected a top-level `launch:` list".into()))?;
        if starts.len() != items.len() {
            // not a block list the scan could follow: errors name the `launch:` line
            starts = vec![launch_line; items.len()];
        }
        let mut out = Self {
            file: file.to_owned(),
            nodes: Vec::new(),
            env: Vec::new(),
        };
        for (k, item) in items.iter().enumerate() {
            let first = starts[k];
            let next = starts.get(k + 1).copied().filter(|&n| n > first);
            ctx.entry = (first, next.unwrap_or(end));
            let map = item.as_mapping().filter(|m| m.len() == 1).ok_or_else(|| {
                ctx.err(format!(
                    "launch item {k}: expected one of arg, let, node, executable, set_env"
                ))
            })?;
            let (kind, body) = map
                .iter()
                .next()
                .ok_or_else(|| ctx.err(format!("launch item {k}: empty")))?;
            let body = body
                .as_mapping()
                .ok_or_else(|| ctx.err(format!("launch item {k}: expected a map")))?;
            out.entry(&mut ctx, k, kind, body, &given)?;
        }
        if let Some(unused) = given.keys().find(|k| !ctx.vars.contains_key(*k)) {
            return Err(argument(format!(
                "launch argument {unused}:= is not declared"
            )));
        }
        Ok(out)
    }

    /// Item `k` of the `launch:` list, of `kind`: an argument or variable into `ctx`, a
    /// process or an environment variable into the description.
    fn entry(
        &mut self,
        ctx: &mut Ctx<'_>,
        k: usize,
        kind: &Value,
        body: &serde_yaml::Mapping,
        given: &BTreeMap<String, String>,
    ) -> Result<(), LaunchError> {
        match kind.as_str() {
            Some("arg") => {
                let (name, value) = arg(ctx, body, k, given)?;
                ctx.vars.insert(name, value);
            }
            Some("let") => {
                if let Some((name, value)) = let_entry(ctx, body)? {
                    ctx.vars.insert(name, value);
                }
            }
            Some("set_env") => self.env.push(set_env(ctx, body)?),
            Some("node") => {
                ctx.check_keys(body, "node", &NODE_KEYS)?;
                if condition(ctx, body, "node")? {
                    self.nodes.push(node(ctx, body)?);
                }
            }
            Some("executable") => {
                ctx.check_keys(body, "executable", &EXECUTABLE_KEYS)?;
                if condition(ctx, body, "executable")? {
                    self.nodes.push(executable(ctx, body)?);
                }
            }
            _ => {
                return Err(ctx.err(format!(
                    "launch item {k}: unknown kind {kind:?} (arg, let, node, executable, set_env)"
                )))
            }
        }
        Ok(())
    }
}

/// An `arg` entry (item `k`): its name and value, the command line's over the default.
fn arg(
    ctx: &Ctx<'_>,
    body: &serde_yaml::Mapping,
    k: usize,
    given: &BTreeMap<String, String>,
) -> Result<(String, String), LaunchError> {
    ctx.check_keys(body, "arg", &ARG_KEYS)?;
    let name = ctx.string(
        get(body, "name").ok_or_else(|| ctx.err(format!("arg {k}: no name")))?,
        "arg name",
    )?;
    let value = match (given.get(&name), get(body, "default")) {
        (Some(v), _) => v.clone(),
        (None, Some(d)) => ctx.string(d, &format!("arg {name} default"))?,
        (None, None) => {
            return Err(ctx.err(format!(
                "launch argument {name} has no default: give {name}:=VALUE"
            )))
        }
    };
    Ok((name, value))
}

/// A `let` entry (ROS 2's SetLaunchConfiguration): a launch variable set from here on, over
/// an `arg`'s value, when its `if:`/`unless:` say so (`None` when they do not).
fn let_entry(
    ctx: &Ctx<'_>,
    body: &serde_yaml::Mapping,
) -> Result<Option<(String, String)>, LaunchError> {
    ctx.check_keys(body, "let", &LET_KEYS)?;
    let name = ctx.string(
        get(body, "name").ok_or_else(|| ctx.err("let: no name".into()))?,
        "let name",
    )?;
    let value = ctx.string(
        get(body, "value").ok_or_else(|| ctx.err(format!("let {name}: no value")))?,
        &format!("let {name} value"),
    )?;
    Ok(condition(ctx, body, &format!("let {name}"))?.then_some((name, value)))
}

/// A `set_env` entry: the variable and its value.
fn set_env(ctx: &Ctx<'_>, body: &serde_yaml::Mapping) -> Result<(String, String), LaunchError> {
    ctx.check_keys(body, "set_env", &SET_ENV_KEYS)?;
    let name = ctx.string(
        get(body, "name").ok_or_else(|| ctx.err("set_env: no name".into()))?,
        "set_env name",
    )?;
    let value = ctx.string(
        get(body, "value").ok_or_else(|| ctx.err("set_env: no value".into()))?,
        "set_env value",
    )?;
    Ok((name, value))
}

/// An `executable` entry: `cmd: rpkm COMMAND ARGS`, run with this rpkm binary.
fn executable(ctx: &Ctx<'_>, body: &serde_yaml::Mapping) -> Result<NodeSpec, LaunchError> {
    let cmd = get(body, "cmd")
        .map(|v| ctx.string(v, "executable cmd"))
        .transpose()?
        .ok_or_else(|| ctx.err("executable without cmd".into()))?;
    let mut words = cmd.split_whitespace().map(str::to_owned);
    if words.next().as_deref() != Some("rpkm") {
        return Err(ctx.err_at(
            "cmd",
            format!(
                "executable cmd {cmd:?}: only rpkm commands can be launched (`rpkm record ...`)"
            ),
        ));
    }
    let exec = words.next().unwrap_or_default();
    if !COMMANDS.contains(&exec.as_str()) {
        return Err(ctx.err_at(
            "cmd",
            format!(
                "executable cmd {cmd:?}: expected `rpkm {}` (nodes go in `node` entries)",
                COMMANDS.join("` or `rpkm ")
            ),
        ));
    }
    let name = get(body, "name")
        .map(|v| ctx.string(v, "executable name"))
        .transpose()?
        .unwrap_or_else(|| exec.clone());
    let (respawn, respawn_delay) = respawn(ctx, body, &name, false)?;
    Ok(NodeSpec {
        program: LaunchProgram::Command,
        exec,
        name,
        param_files: Vec::new(),
        params: Vec::new(),
        args: words.collect(),
        namespace: None,
        remaps: Vec::new(),
        enclave: None,
        managed: false,
        respawn,
        respawn_delay,
        line: ctx.entry.0,
    })
}
