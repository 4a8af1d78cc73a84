//! A `node` entry: lifecycle management, SROS2 enclave, name, namespace and remappings.

use super::args::LaunchError;
use super::description::{LaunchProgram, NodeSpec};
use super::fields::{flag, get, respawn, PARAM_KEYS, REMAP_KEYS};
use super::place::Ctx;
use rpkm_nodes::node::EXECUTABLES;
use serde_yaml::Value;
use std::path::PathBuf;

pub(super) fn node(ctx: &Ctx<'_>, body: &serde_yaml::Mapping) -> Result<NodeSpec, LaunchError> {
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
    if let Some(why) = rpkm_nodes::node::node_name_error(&name) {
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
                param_files.extend(param_file(ctx, from)?);
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
        program: LaunchProgram::Node,
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

/// A `param: [{from: FILE}]` entry's file. A path written in the launch file is relative to
/// its folder; one that a substitution gave (`$(var params_file)`, the user's on the command
/// line) is used as given, relative to the working directory, as the nodes read
/// `geometry_file:=`. Empty after substitution (`params_file` left at its default): none.
fn param_file(ctx: &Ctx<'_>, from: &Value) -> Result<Option<PathBuf>, LaunchError> {
    let given = ctx.string(from, "param from")?;
    if given.is_empty() {
        return Ok(None);
    }
    let written = from.as_str().is_some_and(|raw| !raw.contains("$("));
    let f = PathBuf::from(given);
    Ok(Some(if f.is_relative() && written {
        ctx.dir.join(f)
    } else {
        f
    }))
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
