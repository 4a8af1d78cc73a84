//! `rpkm launch FILE [name:=value ...]`: launch descriptions in the ROS 2 launch YAML dialect,
//! started and supervised by [`supervisor`].
//!
//! ```yaml
//! launch:
//!   - arg: {name: backend, default: ipc}
//!   - node:
//!       pkg: rpkm
//!       exec: tcp_estimator          # ingest | tcp_estimator | calibrator | preload_monitor
//!       name: tcp_estimator          # parameter section, iceoryx2/DDS node name
//!       param:
//!         - from: params.yaml        # relative to this file's folder
//!         - {name: model, value: 29}
//!         - {name: geometry_file, value: $(var geometry_file)}   # not passed when empty
//!       args: --backend $(var backend)
//!       respawn: true                # default true: restarted with backoff when it crashes
//!       respawn_delay: 0.2           # s, doubled per quick crash, at most 5 s
//!       namespace: /machine_a        # its topics, services, parameters (default /rpkm)
//!       managed: true                # started unconfigured, configured and activated by
//!                                    # the launch in file order (default false: active)
//!       remap: [{from: tcp_estimate, to: /cell/estimate_a}]   # topic remapping
//!       enclave: /rpkm/tcp_estimator # SROS2 enclave (default /rpkm/<name>), used with
//!                                    # ROS_SECURITY_ENABLE=true
//!   - set_env: {name: ROS_DOMAIN_ID, value: "7"}
//!   - executable:                    # another rpkm command, e.g. the recorder
//!       cmd: rpkm record --out $(var bag) --topics /rpkm/tcp_estimate,/diagnostics
//!       name: recorder               # default: the subcommand
//!       respawn: false               # default false for executables
//!       if: $(var record)            # node and executable: started only if true (`unless`)
//! ```
//!
//! The recorder stops with the launch: SIGTERM makes `rpkm record` write what is queued and
//! close its bag (metadata.yaml and summary).
//!
//! A `{name, value}` parameter whose value is empty after substitution is not passed: a launch
//! argument left at an empty default (`geometry_file:=`) leaves the parameter files' value.
//!
//! Keys other than these are errors naming the key and its line (a typo such as `If:` would
//! otherwise switch a recorder on). `respawn_delay` is bounded to 0..=3600 s. Every error
//! names the file and a line: the key's, else its entry's.
//!
//! `rpkm launch FILE --check` starts nothing: it reads the file and, for every node, parses its
//! command line and loads and checks its parameters as the node does before it opens its
//! transport ([`NodeSetup`] and the geometry); exit 0, or 2 naming the node's line.
//!
//! Substitutions in every string: `$(var NAME)` (an `arg`, overridden by `NAME:=VALUE` on the
//! command line), `$(env NAME)` / `$(env NAME DEFAULT)`, `$(dirname)` (this file's folder).

mod description;
mod managed;
pub mod supervisor;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde_yaml::Value;

pub use description::{LaunchDescription, NodeSpec, Program, COMMANDS};

use crate::node::params::{parse_yaml, YamlSyntax};
use crate::node::{declared_keys, Geometry, NodeArgs, NodeKind, NodeSetup, EXECUTABLES};

/// `rpkm launch`.
#[derive(clap::Args, Debug, Clone)]
#[command(
    after_help = "Examples:\n  rpkm launch launch_scripts/rpkm.launch.yaml backend:=both\n  \
rpkm launch launch_scripts/rpkm.launch.yaml source:=campaign.csv record:=true bag_dir:=runs\n\n\
Entries: arg, node (rpkm nodes), executable (`cmd: rpkm record ...` or `rpkm replay ...`), \
set_env; `if:`/`unless:` switch a node or executable. Ctrl-C (or SIGTERM) stops every \
process (a recorder closes its bag); a node that crashes is restarted with backoff."
)]
pub struct LaunchArgs {
    /// Launch description (ROS 2 launch YAML).
    pub file: PathBuf,
    /// Launch arguments as NAME:=VALUE.
    pub args: Vec<String>,
    /// Check the launch file and every node's command line and parameters (files, declared
    /// keys, backends, geometry), start nothing: exit 0, or 2 naming the file and line.
    #[arg(long)]
    pub check: bool,
}

/// A launch description that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum LaunchError {
    #[error("{file}: cannot read: {source}")]
    Read {
        file: String,
        #[source]
        source: std::io::Error,
    },
    #[error("{file}:{line}: invalid UTF-8 at byte {offset}, expected UTF-8 text")]
    Utf8 {
        file: String,
        line: usize,
        offset: usize,
    },
    #[error(transparent)]
    Yaml(#[from] YamlSyntax),
    /// An entry that cannot be used, at `line` (its key's, else the entry's first).
    #[error("{file}:{line}: {what}")]
    Invalid {
        file: String,
        line: usize,
        what: String,
    },
    /// A `NAME:=VALUE` of the command line.
    #[error("{file}: {what}")]
    Argument { file: String, what: String },
}

/// Bounds of `respawn_delay`, s (the supervisor caps the doubled delay at 5 s anyway).
const MIN_DELAY_S: f64 = 0.0;
const MAX_DELAY_S: f64 = 3600.0;

/// The keys each kind of entry takes: anything else is a typo (`If:`, `respwan:`) that
/// would otherwise silently change what runs.
const NODE_KEYS: [&str; 13] = [
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
const EXECUTABLE_KEYS: [&str; 6] = ["cmd", "name", "respawn", "respawn_delay", "if", "unless"];
const ARG_KEYS: [&str; 3] = ["name", "default", "description"];
const SET_ENV_KEYS: [&str; 2] = ["name", "value"];
const PARAM_KEYS: [&str; 3] = ["from", "name", "value"];
const REMAP_KEYS: [&str; 2] = ["from", "to"];

struct Ctx<'a> {
    file: String,
    /// The file's text, to find the line of a key (serde_yaml values carry no positions).
    text: &'a str,
    dir: &'a Path,
    vars: BTreeMap<String, String>,
    /// Lines `[first, end)` (1-based) of the entry being read: errors name its line.
    entry: (usize, usize),
}

impl Ctx<'_> {
    /// An error at the entry being read.
    fn err(&self, what: String) -> LaunchError {
        LaunchError::Invalid {
            file: self.file.clone(),
            line: self.entry.0,
            what,
        }
    }

    /// An error at `key:` of the entry being read (at the entry when the key is not found).
    fn err_at(&self, key: &str, what: String) -> LaunchError {
        LaunchError::Invalid {
            file: self.file.clone(),
            line: key_line(self.text, key, self.entry).unwrap_or(self.entry.0),
            what,
        }
    }

    /// Errors on a key of `entry` that is not in `known`, with the line where it first
    /// appears in the file.
    fn check_keys(
        &self,
        body: &serde_yaml::Mapping,
        entry: &str,
        known: &[&str],
    ) -> Result<(), LaunchError> {
        for key in body.keys() {
            let name = match key {
                Value::String(s) => s.clone(),
                other => serde_yaml::to_string(other)
                    .map(|s| s.trim().to_owned())
                    .unwrap_or_default(),
            };
            if known.contains(&name.as_str()) {
                continue;
            }
            return Err(self.err_at(
                &name,
                format!(
                    "{entry}: unknown key {name:?} (known: {})",
                    known.join(", ")
                ),
            ));
        }
        Ok(())
    }

    /// Applies `$(var ..)`, `$(env ..)`, `$(dirname)`.
    fn subst(&self, s: &str) -> Result<String, LaunchError> {
        let mut out = String::new();
        let mut rest = s;
        while let Some(start) = rest.find("$(") {
            out.push_str(&rest[..start]);
            let after = &rest[start + 2..];
            let end = after
                .find(')')
                .ok_or_else(|| self.err(format!("unclosed substitution in {s:?}")))?;
            let words: Vec<&str> = after[..end].split_whitespace().collect();
            let value =
                match words.as_slice() {
                    ["var", name] => self.vars.get(*name).cloned().ok_or_else(|| {
                        self.err(format!("$(var {name}): no such launch argument"))
                    })?,
                    ["env", name] => std::env::var(name).map_err(|_| {
                        self.err(format!(
                            "$(env {name}): not set (give a default: $(env {name} x))"
                        ))
                    })?,
                    ["env", name, default] => {
                        std::env::var(name).unwrap_or_else(|_| (*default).to_owned())
                    }
                    ["dirname"] => self.dir.display().to_string(),
                    other => {
                        return Err(self.err(format!(
                            "unknown substitution $({}) (var, env, dirname)",
                            other.join(" ")
                        )))
                    }
                };
            out.push_str(&value);
            rest = &after[end + 1..];
        }
        out.push_str(rest);
        Ok(out)
    }

    fn string(&self, v: &Value, what: &str) -> Result<String, LaunchError> {
        let s = match v {
            Value::String(s) => s.clone(),
            Value::Number(n) => n.to_string(),
            Value::Bool(b) => b.to_string(),
            _ => return Err(self.err(format!("{what}: expected a string"))),
        };
        self.subst(&s)
    }
}

/// The 1-based line where `key:` first appears as a mapping key (block or flow style),
/// outside comments, within the lines `[first, end)`.
fn key_line(text: &str, key: &str, (first, end): (usize, usize)) -> Option<usize> {
    let pattern = format!("{key}:");
    let lines = text.lines().enumerate();
    let mut lines = lines
        .skip(first.saturating_sub(1))
        .take(end.saturating_sub(first));
    lines.find_map(|(i, line)| {
        let code = line.split(" #").next().unwrap_or(line);
        code.match_indices(&pattern)
            .any(|(at, _)| {
                let before = code[..at].chars().next_back();
                before.is_none_or(|c| c.is_whitespace() || matches!(c, '{' | ',' | '-'))
            })
            .then_some(i + 1)
    })
}

/// The 1-based line of the top-level `launch:` key (1 when there is none) and the first
/// line of each entry of its block list (`- ` at the list's indentation); no entries for a
/// flow list (`launch: [...]`).
fn entry_lines(text: &str) -> (usize, Vec<usize>) {
    let mut lines = text.lines().enumerate();
    let Some((at, _)) = lines.by_ref().find(|(_, l)| l.starts_with("launch:")) else {
        return (1, Vec::new());
    };
    let mut indent = None;
    let mut entries = Vec::new();
    for (i, line) in lines {
        let code = line.trim_start();
        if code.is_empty() || code.starts_with('#') {
            continue;
        }
        let this = line.len() - code.len();
        let item = code == "-" || code.starts_with("- ");
        match indent {
            None if item => indent = Some(this),
            Some(n) if this == n && item => {}
            Some(n) if this > n => continue,
            _ => break,
        }
        entries.push(i + 1);
    }
    (at + 1, entries)
}

/// The line to blame for a YAML error serde_yaml does not locate (a file of several
/// documents): the first document marker (`---`, `...`) after content, else the first line
/// of content, else 1.
fn unlocated_error_line(text: &str) -> usize {
    let content = |l: &str| {
        let t = l.trim_start();
        !(t.is_empty() || t.starts_with('#') || t.starts_with('%'))
    };
    let mut lines = text.lines().enumerate();
    let Some((first, _)) = lines.by_ref().find(|(_, l)| content(l)) else {
        return 1;
    };
    lines
        .find(|(_, l)| l.starts_with("---") || l.starts_with("..."))
        .map_or(first + 1, |(i, _)| i + 1)
}

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

/// Where a UTF-8 error lies in `bytes`: the 1-based line and the byte offset.
fn utf8_error_place(bytes: &[u8], error: &std::str::Utf8Error) -> (usize, usize) {
    let offset = error.valid_up_to();
    let line = bytes[..offset].split(|&b| b == b'\n').count();
    (line, offset)
}

fn get<'a>(m: &'a serde_yaml::Mapping, key: &str) -> Option<&'a Value> {
    m.get(key)
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
                    "launch item {k}: expected one of arg, node, executable, set_env"
                ))
            })?;
            let (kind, body) = map
                .iter()
                .next()
                .ok_or_else(|| ctx.err(format!("launch item {k}: empty")))?;
            let body = body
                .as_mapping()
                .ok_or_else(|| ctx.err(format!("launch item {k}: expected a map")))?;
            match kind.as_str() {
                Some("arg") => {
                    let (name, value) = arg(&ctx, body, k, &given)?;
                    ctx.vars.insert(name, value);
                }
                Some("set_env") => out.env.push(set_env(&ctx, body)?),
                Some("node") => {
                    ctx.check_keys(body, "node", &NODE_KEYS)?;
                    if condition(&ctx, body, "node")? {
                        out.nodes.push(node(&ctx, body)?);
                    }
                }
                Some("executable") => {
                    ctx.check_keys(body, "executable", &EXECUTABLE_KEYS)?;
                    if condition(&ctx, body, "executable")? {
                        out.nodes.push(executable(&ctx, body)?);
                    }
                }
                _ => {
                    return Err(ctx.err(format!(
                        "launch item {k}: unknown kind {kind:?} (arg, node, executable, set_env)"
                    )))
                }
            }
        }
        if let Some(unused) = given.keys().find(|k| !ctx.vars.contains_key(*k)) {
            return Err(argument(format!(
                "launch argument {unused}:= is not declared"
            )));
        }
        Ok(out)
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

/// `if:` / `unless:` of an entry (ROS 2 launch): true, false, 1 or 0 after substitution.
fn condition(ctx: &Ctx<'_>, body: &serde_yaml::Mapping, what: &str) -> Result<bool, LaunchError> {
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
fn respawn(
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
        program: Program::Command,
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

fn node(ctx: &Ctx<'_>, body: &serde_yaml::Mapping) -> Result<NodeSpec, LaunchError> {
    let field = |key: &str| -> Result<Option<String>, LaunchError> {
        get(body, key)
            .map(|v| ctx.string(v, &format!("node {key}")))
            .transpose()
    };
    let pkg = field("pkg")?.unwrap_or_default();
    if pkg != "rpkm" {
        return Err(ctx.err_at(
            "pkg",
            format!("node pkg {pkg:?}: only rpkm nodes can be launched"),
        ));
    }
    let exec = field("exec")?.ok_or_else(|| ctx.err("node without exec".into()))?;
    if !EXECUTABLES.contains(&exec.as_str()) {
        return Err(ctx.err_at(
            "exec",
            format!(
                "node exec {exec:?}: expected one of {}",
                EXECUTABLES.join(", ")
            ),
        ));
    }
    let name = field("name")?.unwrap_or_else(|| exec.clone());
    if let Some(why) = crate::node::node_name_error(&name) {
        return Err(ctx.err_at("name", why));
    }
    let mut param_files = Vec::new();
    let mut params = Vec::new();
    if let Some(list) = get(body, "param") {
        let list = list
            .as_sequence()
            .ok_or_else(|| ctx.err_at("param", format!("node {name}: param: expected a list")))?;
        for p in list {
            let m = p
                .as_mapping()
                .ok_or_else(|| ctx.err(format!("node {name}: param entry: expected a map")))?;
            ctx.check_keys(m, &format!("node {name} param entry"), &PARAM_KEYS)?;
            if let Some(from) = get(m, "from") {
                let f = PathBuf::from(ctx.string(from, "param from")?);
                param_files.push(if f.is_relative() { ctx.dir.join(f) } else { f });
            } else {
                let key = get(m, "name")
                    .ok_or_else(|| ctx.err(format!("node {name}: param without from or name")))?;
                let key = ctx.string(key, "param name")?;
                let value = get(m, "value")
                    .ok_or_else(|| ctx.err(format!("node {name}: param {key} without value")))?;
                let value = match value {
                    Value::String(s) => ctx.subst(s)?,
                    other => serde_yaml::to_string(other)
                        .map(|s| s.trim().to_owned())
                        .map_err(|e| ctx.err(format!("node {name}: param {key}: {e}")))?,
                };
                // empty (`$(var geometry_file)` at its default): the files' value stands
                if !value.is_empty() {
                    params.push(format!("{key}={value}"));
                }
            }
        }
    }
    let args = field("args")?
        .map(|a| a.split_whitespace().map(str::to_owned).collect())
        .unwrap_or_default();
    let (respawn, respawn_delay) = respawn(ctx, body, &format!("node {name}"), true)?;
    let (namespace, remaps) = names(ctx, body, &name)?;
    let managed = managed(ctx, body, &name)?;
    Ok(NodeSpec {
        program: Program::Node,
        enclave: enclave(ctx, body, &name)?,
        exec,
        name,
        param_files,
        params,
        args,
        namespace,
        remaps,
        managed,
        respawn,
        respawn_delay,
        line: ctx.entry.0,
    })
}

/// A boolean key of an entry (`true`, `false`, `1`, `0` after substitution), false when
/// absent.
fn flag(
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

/// A node entry's `managed:` (every rpkm node is a managed node).
fn managed(ctx: &Ctx<'_>, body: &serde_yaml::Mapping, name: &str) -> Result<bool, LaunchError> {
    flag(ctx, body, "managed", &format!("node {name}"))
}

/// A node entry's `enclave:`, checked as the node checks it (an absolute ROS 2 namespace).
fn enclave(
    ctx: &Ctx<'_>,
    body: &serde_yaml::Mapping,
    name: &str,
) -> Result<Option<String>, LaunchError> {
    let Some(v) = get(body, "enclave") else {
        return Ok(None);
    };
    let enclave = ctx.string(v, &format!("node {name} enclave"))?;
    match rpkm_transport::security::enclave_name_error(&enclave) {
        Some(why) => Err(ctx.err_at(
            "enclave",
            format!("node {name}: enclave {enclave:?}: {why}"),
        )),
        None => Ok(Some(enclave)),
    }
}

/// Topic remapping rules, (FROM, TO) in order.
type Remaps = Vec<(String, String)>;

/// A node entry's `namespace:` and `remap: [{from, to}]`, checked as the node will check
/// them (ROS 2's name rules).
fn names(
    ctx: &Ctx<'_>,
    body: &serde_yaml::Mapping,
    name: &str,
) -> Result<(Option<String>, Remaps), LaunchError> {
    let namespace = get(body, "namespace")
        .map(|v| ctx.string(v, &format!("node {name} namespace")))
        .transpose()?;
    let mut remaps = Vec::new();
    if let Some(list) = get(body, "remap") {
        let list = list
            .as_sequence()
            .ok_or_else(|| ctx.err_at("remap", format!("node {name}: remap: expected a list")))?;
        for rule in list {
            let m = rule.as_mapping().ok_or_else(|| {
                ctx.err_at("remap", format!("node {name}: remap entry: expected a map"))
            })?;
            ctx.check_keys(m, &format!("node {name} remap entry"), &REMAP_KEYS)?;
            let part = |key: &str| {
                get(m, key)
                    .map(|v| ctx.string(v, &format!("node {name} remap {key}")))
                    .transpose()?
                    .ok_or_else(|| {
                        ctx.err_at("remap", format!("node {name}: remap entry without {key}"))
                    })
            };
            remaps.push((part("from")?, part("to")?));
        }
    }
    let ns = namespace
        .as_deref()
        .unwrap_or(rpkm_transport::NODE_NAMESPACE);
    if let Err(e) = rpkm_transport::Names::new(ns, &remaps) {
        let key = if e.what == "namespace" {
            "namespace"
        } else {
            "remap"
        };
        return Err(ctx.err_at(key, format!("node {name}: {e}")));
    }
    Ok((namespace, remaps))
}

/// Runs `rpkm launch`.
pub fn run(args: &LaunchArgs) -> anyhow::Result<()> {
    let desc = LaunchDescription::load(&args.file, &args.args)
        .map_err(|e| crate::error::bad_input(e.to_string()))?;
    if args.check {
        return check(&desc);
    }
    supervisor::run(&desc)
}

/// `rpkm launch --check`: every node's command line and configuration as it would start,
/// nothing started. An `executable` entry's command line is checked when it starts.
fn check(desc: &LaunchDescription) -> anyhow::Result<()> {
    for spec in &desc.nodes {
        let argv: Vec<String> = spec
            .argv()
            .iter()
            .map(|a| a.to_string_lossy().into_owned())
            .collect();
        if spec.program == Program::Node {
            check_node(spec).map_err(|e| {
                crate::error::bad_input(format!(
                    "{}:{}: node {}: {}",
                    desc.file,
                    spec.line,
                    spec.name,
                    crate::error::error_chain(&e)
                ))
            })?;
        }
        println!(
            "{}:{}: {}: rpkm {}",
            desc.file,
            spec.line,
            spec.name,
            argv.join(" ")
        );
    }
    Ok(())
}

/// Parses a node's command line as `rpkm node` would and loads and checks its parameters:
/// files, declared keys, backends, diagnostics period, geometry.
fn check_node(spec: &NodeSpec) -> anyhow::Result<()> {
    use clap::{Args, FromArgMatches};
    // `node` stands where clap expects the binary's name
    let args = NodeArgs::augment_args(clap::Command::new("rpkm node"))
        .try_get_matches_from(spec.argv())
        .and_then(|m| NodeArgs::from_arg_matches(&m))
        .map_err(|e| {
            let text = e.render().to_string();
            let first = text.lines().next().unwrap_or_default();
            anyhow::anyhow!("args: {}", first.trim_start_matches("error: "))
        })?;
    let kind = args.kind.exec_name();
    let declared = declared_keys(kind).unwrap_or_default();
    let (common, geometry) = match &args.kind {
        NodeKind::Ingest(a) => (&a.common, false),
        NodeKind::TcpEstimator(c) | NodeKind::Calibrator(c) | NodeKind::PreloadMonitor(c) => {
            (c, true)
        }
    };
    let setup = NodeSetup::load(kind, common, &declared, None)?;
    if geometry {
        Geometry::from_params(&setup.params)?;
    }
    // the JointState input's settings: read by the three nodes that take drive states
    if !matches!(args.kind, NodeKind::Calibrator(_)) {
        crate::node::joint_input::JointConfig::from_params(&setup.params)
            .map_err(crate::node::bad_param)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const FILE: &str = "\
launch:
  - arg: {name: backend, default: ipc}
  - arg: {name: rate}
  - set_env: {name: ROS_DOMAIN_ID, value: \"7\"}
  - node:
      pkg: rpkm
      exec: tcp_estimator
      name: estimator_a
      param:
        - from: params.yaml
        - {name: model, value: 24}
        - {name: source, value: $(dirname)/c.csv}
      args: --backend $(var backend) --param rate_hz=$(var rate)
      respawn: \"false\"
  - node: {pkg: rpkm, exec: ingest}
  - node: {pkg: rpkm, exec: calibrator, unless: \"$(var rate)\"}
  - executable:
      cmd: rpkm record --out $(dirname)/bag --topics /rpkm/tcp_estimate
      if: \"1\"
";

    #[test]
    fn parses_nodes_args_and_substitutions() -> Result<(), LaunchError> {
        let d =
            LaunchDescription::parse(FILE, "x.launch.yaml", Path::new("/l"), &["rate:=1".into()])?;
        assert_eq!(d.env, vec![("ROS_DOMAIN_ID".into(), "7".into())]);
        let a = &d.nodes[0];
        assert_eq!(a.name, "estimator_a");
        assert_eq!(a.param_files, vec![PathBuf::from("/l/params.yaml")]);
        assert_eq!(a.params, vec!["model=24", "source=/l/c.csv"]);
        assert_eq!(a.args, ["--backend", "ipc", "--param", "rate_hz=1"]);
        assert!(!a.respawn);
        let b = &d.nodes[1];
        assert_eq!(
            (b.name.as_str(), b.respawn, b.respawn_delay),
            ("ingest", true, 0.2)
        );
        // `unless: 1` left the calibrator out; the recorder is an rpkm command.
        assert_eq!(d.nodes.len(), 3);
        let r = &d.nodes[2];
        assert_eq!(
            (r.program, r.exec.as_str(), r.name.as_str(), r.respawn),
            (Program::Command, "record", "record", false)
        );
        assert_eq!(
            r.args,
            ["--out", "/l/bag", "--topics", "/rpkm/tcp_estimate"]
        );
        Ok(())
    }

    #[test]
    fn unknown_keys_in_a_launch_entry_are_rejected_with_the_line() {
        for (text, says) in [
            (
                "launch:\n  - node:\n      pkg: rpkm\n      exec: ingest\n      If: \"false\"\n",
                "z.yaml:5: node: unknown key \"If\" (known: pkg, exec,",
            ),
            (
                "launch:\n  - node: {pkg: rpkm, exec: ingest}\n  \
                 - executable: {cmd: rpkm record, respwan: false}\n",
                "z.yaml:3: executable: unknown key \"respwan\"",
            ),
            (
                "launch:\n  - arg: {name: a, defualt: 1}\n",
                "z.yaml:2: arg: unknown key \"defualt\"",
            ),
            (
                "launch:\n  - node: {pkg: rpkm, exec: ingest, param: [{form: p.yaml}]}\n",
                "z.yaml:2: node ingest param entry: unknown key \"form\"",
            ),
        ] {
            let e = LaunchDescription::parse(text, "z.yaml", Path::new("."), &[]).expect_err(text);
            assert!(e.to_string().starts_with(says), "{text}: {e}");
        }
    }

    #[test]
    fn errors_name_the_problem() {
        let e = LaunchDescription::parse(FILE, "x.launch.yaml", Path::new("/l"), &[])
            .expect_err("rate has no default");
        assert!(e.to_string().contains("rate has no default"), "{e}");
        let e = LaunchDescription::parse(
            "launch:\n  - node: {pkg: rpkm, exec: talker}\n",
            "y.yaml",
            Path::new("."),
            &[],
        )
        .expect_err("unknown exec");
        assert!(
            e.to_string().starts_with("y.yaml:2: node exec \"talker\""),
            "{e}"
        );
        let e = LaunchDescription::parse(
            FILE,
            "x",
            Path::new("."),
            &["rate:=1".into(), "nope:=2".into()],
        )
        .expect_err("undeclared");
        assert!(e.to_string().contains("nope"), "{e}");
        for (entry, says) in [
            (
                "executable: {cmd: ros2 bag record -a}",
                "only rpkm commands",
            ),
            (
                "executable: {cmd: rpkm launch x.yaml}",
                "expected `rpkm record`",
            ),
            (
                "node: {pkg: rpkm, exec: ingest, if: maybe}",
                "node if: \"maybe\"",
            ),
            (
                "node: {pkg: rpkm, exec: ingest, respawn_delay: 1e308}",
                "node ingest: respawn_delay \"1e308\": expected seconds from 0 to 3600",
            ),
        ] {
            let e = LaunchDescription::parse(
                &format!("launch:\n  - {entry}\n"),
                "z.yaml",
                Path::new("."),
                &[],
            )
            .expect_err(entry);
            assert!(e.to_string().contains(says), "{entry}: {e}");
        }
    }

    #[test]
    fn every_error_names_the_line_of_its_entry_or_key() {
        for (text, says) in [
            (
                "# c\nlaunch:\n  - arg: {name: a, default: x}\n\n  - node:\n      pkg: rpkm\n      \
                 exec: talker\n",
                "z.yaml:7: node exec \"talker\"",
            ),
            (
                "launch:\n- node: {pkg: rpkm, exec: ingest}\n- node:\n    pkg: ros\n",
                "z.yaml:4: node pkg \"ros\"",
            ),
            (
                "launch:\n  - node:\n      pkg: rpkm\n      exec: ingest\n      respawn: maybe\n",
                "z.yaml:5: node ingest: respawn \"maybe\"",
            ),
            (
                "launch:\n  - node: {pkg: rpkm, exec: ingest}\n  - node: {pkg: rpkm, exec: ingest}\n  \
                 - executable:\n      cmd: rpkm record\n      unless: 2\n",
                "z.yaml:6: executable unless: \"2\"",
            ),
            (
                "launch:\n  - arg: {name: a}\n",
                "z.yaml:2: launch argument a has no default",
            ),
            // a flow list: the `launch:` line
            (
                "\nlaunch: [{node: {pkg: rpkm, exec: x}}]\n",
                "z.yaml:2: node exec \"x\"",
            ),
            ("other: 1\n", "z.yaml:1: expected a top-level `launch:` list"),
            (
                "# two documents\nlaunch: []\n---\nlaunch: []\n",
                "z.yaml:3:1: not YAML",
            ),
        ] {
            let e = LaunchDescription::parse(text, "z.yaml", Path::new("."), &[]).expect_err(text);
            assert!(e.to_string().starts_with(says), "{text}: {e}");
        }
    }

    /// `enclave:` reaches the node as rcl's `--ros-args --enclave`.
    #[test]
    fn an_enclave_goes_to_the_node_as_ros_args() -> Result<(), LaunchError> {
        let d = LaunchDescription::parse(
            "launch:\n  - node:\n      pkg: rpkm\n      exec: tcp_estimator\n      \
             enclave: /cell/estimator_a\n",
            "n.yaml",
            Path::new("."),
            &[],
        )?;
        let argv: Vec<String> = d.nodes[0]
            .argv()
            .iter()
            .map(|a| a.to_string_lossy().into_owned())
            .collect();
        assert_eq!(
            argv[argv.len() - 3..],
            ["--ros-args", "--enclave", "/cell/estimator_a"]
        );
        Ok(())
    }

    /// `namespace:` and `remap:` reach the node as rcl's `--ros-args -r`, last on its line;
    /// a name ROS 2 would refuse is refused with its key's line, as an unusable node name is
    /// (an enclave too).
    #[test]
    fn namespace_and_remap_go_to_the_node_as_ros_args() -> Result<(), LaunchError> {
        let entry = "launch:\n  - node:\n      pkg: rpkm\n      exec: tcp_estimator\n";
        let d = LaunchDescription::parse(
            &format!(
                "{entry}      namespace: /machine_a\n      \
                 remap: [{{from: tcp_estimate, to: /cell/estimate_a}}]\n"
            ),
            "n.yaml",
            Path::new("."),
            &[],
        )?;
        let argv: Vec<String> = d.nodes[0]
            .argv()
            .iter()
            .map(|a| a.to_string_lossy().into_owned())
            .collect();
        assert_eq!(
            argv[argv.len() - 5..],
            [
                "--ros-args",
                "-r",
                "__ns:=/machine_a",
                "-r",
                "tcp_estimate:=/cell/estimate_a"
            ]
        );
        for (tail, says) in [
            (
                "      namespace: machine_a\n",
                "n.yaml:5: node tcp_estimator: namespace \"machine_a\": expected an absolute",
            ),
            (
                "      remap: [{from: a, to: b c}]\n",
                "n.yaml:5: node tcp_estimator: remap \"a:=b c\"",
            ),
            (
                "      name: 1st\n",
                "n.yaml:5: node name \"1st\" starts with a digit",
            ),
            (
                &format!("      name: {}\n", "a".repeat(5000)),
                "n.yaml:5: node name \"aaaa",
            ),
            (
                "      enclave: rpkm/estimator\n",
                "n.yaml:5: node tcp_estimator: enclave \"rpkm/estimator\": expected an absolute",
            ),
        ] {
            let e =
                LaunchDescription::parse(&format!("{entry}{tail}"), "n.yaml", Path::new("."), &[])
                    .expect_err(tail);
            assert!(e.to_string().starts_with(says), "{tail}: {e}");
        }
        Ok(())
    }

    #[test]
    fn invalid_utf8_names_line_and_byte() {
        let dir = tempfile::tempdir().expect("tempdir");
        let file = dir.path().join("u.yaml");
        std::fs::write(&file, b"launch:\n  - arg: {name: a, default: \xc3(}\n").expect("write");
        let e = LaunchDescription::load(&file, &[]).expect_err("not UTF-8");
        // "launch:\n" is 8 bytes, "  - arg: {name: a, default: " 28
        assert_eq!(
            e.to_string(),
            format!(
                "{}:2: invalid UTF-8 at byte 36, expected UTF-8 text",
                file.display()
            )
        );
    }
}
