//! ROS 2 parameter YAML: the files `ros2 run ... --ros-args --params-file F` reads.
//!
//! ```yaml
//! /**:                      # every node
//!   ros__parameters:
//!     model: 29
//! preload_monitor:          # one node, also spelled /preload_monitor or /ns/preload_monitor
//!   ros__parameters:
//!     warn_percent: 20.0
//!     geometry:             # nested maps flatten with '.': geometry.l1
//!       l1: 0.9503          # SI on the ROS side: m, rad, N, s
//! ```
//!
//! Sections apply in file order, files in command-line order, `--param key=value` last; a
//! later value replaces an earlier one. Keys set in a section that names the node itself must
//! be keys the node declares ([`NodeParams::check_declared`]): a typo is an error, not a
//! silently ignored setting. Wildcard sections may carry keys for other nodes.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde_yaml::Value;

// The YAML reader with places, shared with the launch files; named here as before.
pub use super::yaml::{parse_yaml, YamlSyntax};

/// Bounds of a duration read from a parameter, s: an hour is beyond any period, delay or
/// timeout the nodes use, and far inside what a `Duration` holds.
pub const DURATION_S: (f64, f64) = (0.0, 3600.0);
/// Bounds of a buffer length read from a parameter: a million entries is minutes of an
/// 8 kHz stream, and a few tens of MB at most.
pub const BUFFER_LEN: (u64, u64) = (1, 1_000_000);
/// Bounds of a busy-poll time, ms: it costs a core while it lasts, and beyond a second it
/// is no longer a latency measure.
pub const BUSY_POLL_MS: (f64, f64) = (0.0, 1000.0);
/// Bounds of a count of samples (`status_every`, `debounce_samples`): at least one sample,
/// at most a million (two minutes of an 8 kHz stream; beyond, a level or a report never
/// comes).
pub const SAMPLE_COUNT: (u64, u64) = (1, 1_000_000);
/// Bounds of `calibrate_every`, measurements: 0 (off) or up to a million held in memory.
pub const MEASUREMENT_COUNT: (u64, u64) = (0, 1_000_000);
/// Bounds of `rt_priority`: 0 (normal scheduling) or a SCHED_FIFO priority 1..=99.
pub const RT_PRIORITY: (u64, u64) = (0, 99);
/// Bounds of `outlier_sigma`, σ: 0 (no outlier removal) up to 100.
pub const OUTLIER_SIGMA: (f64, f64) = (0.0, 100.0);

/// Where a parameter value came from, for messages: `file.yaml: /node/ros__parameters/key`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Origin {
    /// The file, or `--param` for the command line.
    pub file: String,
    /// The node section (`/**`, `tcp_estimator`, ...).
    pub section: String,
    /// Whether the section names this node (not a wildcard).
    pub specific: bool,
}

impl std::fmt::Display for Origin {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}/ros__parameters", self.file, self.section)
    }
}

/// A parameter file or value that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum ParamError {
    /// The file cannot be read.
    #[error("{file}: cannot read parameters: {source}")]
    Read {
        file: String,
        #[source]
        source: std::io::Error,
    },
    /// The file is not YAML.
    #[error(transparent)]
    Yaml(#[from] YamlSyntax),
    /// The YAML does not have the ROS 2 layout.
    #[error("{file}: {what}")]
    Layout { file: String, what: String },
    /// A value has the wrong type or is out of its range.
    #[error("{origin}/{key}: expected {expected}, found {found}")]
    Type {
        origin: Box<Origin>,
        key: String,
        expected: &'static str,
        found: String,
    },
    /// A number outside the bounds the node can use (a duration, rate or buffer size that
    /// would overflow a `Duration` or ask for an absurd allocation).
    #[error("{origin}/{key}: {found} is out of range: expected {expected}")]
    Range {
        origin: Box<Origin>,
        key: String,
        found: String,
        /// The bounds with their unit: `0 to 3600 s`.
        expected: String,
    },
    /// Two keys that bound an interval, the lower one not below the upper.
    #[error("{origin}/{lo_key}: {lo} must be below {hi_key} {hi}")]
    Interval {
        origin: Box<Origin>,
        lo_key: String,
        lo: f64,
        hi_key: String,
        hi: f64,
    },
    /// A key the node does not declare.
    #[error("{origin}/{key}: unknown parameter of node {node} (known: {known})")]
    Unknown {
        origin: Box<Origin>,
        key: String,
        node: String,
        known: String,
    },
    /// `--param` without `=`.
    #[error("--param {0:?}: expected key=value")]
    Override(String),
}

/// The parameters of one node, merged from its files and overrides.
#[derive(Debug, Clone, Default)]
pub struct NodeParams {
    node: String,
    /// The node's namespace: which sections address it.
    namespace: String,
    values: BTreeMap<String, (Value, Origin)>,
}

/// Whether a section name addresses the node `node` in namespace `ours` (rpkm's
/// [`rpkm_transport::NODE_NAMESPACE`] by default): `Some(false)` for every node (`/**`),
/// `Some(true)` for this one (`node`, `/node`, `/rpkm/node`, `/**/node`, `/*/node`), `None`
/// otherwise, a section of the same node name in another namespace (`/foo/ingest`)
/// included: ROS 2 would not apply it either.
fn section_matches(section: &str, node: &str, ours: &str) -> Option<bool> {
    let s = section.trim();
    if s == "/**" || s == "**" {
        return Some(false);
    }
    let (namespace, last) = s.rsplit_once('/').unwrap_or(("", s));
    if last != node {
        return None;
    }
    let one_level = ours.matches('/').count() == 1;
    let here = match namespace {
        "" | "/**" => true,
        "/*" => one_level,
        ns => ns == ours,
    };
    here.then_some(true)
}

fn flatten(prefix: &str, v: &Value, out: &mut Vec<(String, Value)>) {
    match v {
        // an empty map stays a value, so that a getter refuses it (`period: {}`) instead
        // of the key vanishing
        Value::Mapping(m) if m.is_empty() => out.push((prefix.to_owned(), v.clone())),
        Value::Mapping(m) => {
            for (k, v) in m {
                let key = match k {
                    Value::String(s) => s.clone(),
                    other => yaml_text(other),
                };
                let full = if prefix.is_empty() {
                    key
                } else {
                    format!("{prefix}.{key}")
                };
                flatten(&full, v, out);
            }
        }
        other => out.push((prefix.to_owned(), other.clone())),
    }
}

pub(super) fn yaml_text(v: &Value) -> String {
    match v {
        Value::String(s) => format!("{s:?}"),
        // on one line, as a flow sequence, so that a message stays one line
        Value::Sequence(items) => {
            let items: Vec<String> = items.iter().map(yaml_text).collect();
            format!("[{}]", items.join(", "))
        }
        other => serde_yaml::to_string(other)
            .map_or_else(|_| format!("{other:?}"), |s| s.trim().to_owned()),
    }
}

impl NodeParams {
    /// No parameters (every getter returns its default).
    pub fn empty(node: &str) -> Self {
        Self {
            node: node.to_owned(),
            namespace: rpkm_transport::NODE_NAMESPACE.to_owned(),
            values: BTreeMap::new(),
        }
    }

    /// Reads `files` in order, then applies `overrides` (`key=value`, value as YAML).
    pub fn load(node: &str, files: &[PathBuf], overrides: &[String]) -> Result<Self, ParamError> {
        Self::load_in(rpkm_transport::NODE_NAMESPACE, node, files, overrides)
    }

    /// [`Self::load`] for a node in `namespace`: the sections that address it there.
    pub fn load_in(
        namespace: &str,
        node: &str,
        files: &[PathBuf],
        overrides: &[String],
    ) -> Result<Self, ParamError> {
        let mut out = Self::empty(node);
        namespace.clone_into(&mut out.namespace);
        for f in files {
            let text = std::fs::read_to_string(f).map_err(|source| ParamError::Read {
                file: f.display().to_string(),
                source,
            })?;
            out.merge_text(&text, f)?;
        }
        for o in overrides {
            let (k, v) = o
                .split_once('=')
                .ok_or_else(|| ParamError::Override(o.clone()))?;
            let value: Value =
                serde_yaml::from_str(v).unwrap_or_else(|_| Value::String(v.to_owned()));
            out.values.insert(
                k.trim().to_owned(),
                (
                    value,
                    Origin {
                        file: "--param".into(),
                        section: format!("/{node}"),
                        specific: true,
                    },
                ),
            );
        }
        Ok(out)
    }

    /// Merges the sections of one file's text that address this node.
    pub fn merge_text(&mut self, text: &str, file: &Path) -> Result<(), ParamError> {
        let fname = file.display().to_string();
        let doc = parse_yaml(text, &fname)?;
        let layout = |what: String| ParamError::Layout {
            file: fname.clone(),
            what,
        };
        let top = match doc {
            Value::Mapping(m) => m,
            Value::Null => return Ok(()),
            _ => return Err(layout("expected a map of node names".into())),
        };
        for (section, body) in &top {
            let Value::String(section) = section else {
                return Err(layout(format!(
                    "node name {} is not a string",
                    yaml_text(section)
                )));
            };
            let Some(specific) = section_matches(section, &self.node, &self.namespace) else {
                continue;
            };
            let params = match body {
                Value::Mapping(m) => m.get("ros__parameters"),
                _ => None,
            }
            .ok_or_else(|| layout(format!("{section}: expected a `ros__parameters` map")))?;
            let mut flat = Vec::new();
            flatten("", params, &mut flat);
            for (key, value) in flat {
                if key.is_empty() {
                    continue;
                }
                self.values.insert(
                    key,
                    (
                        value,
                        Origin {
                            file: fname.clone(),
                            section: section.clone(),
                            specific,
                        },
                    ),
                );
            }
        }
        Ok(())
    }

    /// Errors on a key set for this node by name (or `--param`) that is not in `declared`.
    /// A declared key ending in `.` declares a whole group (`geometry.`).
    pub fn check_declared(&self, declared: &[&str]) -> Result<(), ParamError> {
        self.check_shapes(declared)?;
        for (key, (_, origin)) in &self.values {
            // a group is its members, or an empty map under its own name (`group: {}`)
            let known = declared.iter().any(|d| {
                d == key
                    || (d.ends_with('.') && key.starts_with(d))
                    || d.strip_suffix('.') == Some(key.as_str())
            });
            if origin.specific && !known {
                return Err(ParamError::Unknown {
                    origin: Box::new(origin.clone()),
                    key: key.clone(),
                    node: self.node.clone(),
                    known: declared.join(", "),
                });
            }
        }
        Ok(())
    }

    /// Errors on a map where a declared key wants a value (`diagnostics_period_s: {a: 1}`
    /// flattens to `diagnostics_period_s.a`) and on a value where a declared group wants a
    /// map (`geometry: 5`), whichever section set it: a wildcard section's key is one this
    /// node takes, so a wrong shape there is as wrong as in its own section.
    fn check_shapes(&self, declared: &[&str]) -> Result<(), ParamError> {
        for (key, (value, origin)) in &self.values {
            let map_under_value = declared.iter().find(|d| {
                !d.ends_with('.')
                    && key
                        .strip_prefix(**d)
                        .is_some_and(|rest| rest.starts_with('.'))
            });
            if let Some(d) = map_under_value {
                return Err(ParamError::Type {
                    origin: Box::new(origin.clone()),
                    key: (*d).to_owned(),
                    expected: "a value",
                    found: format!("a map (with {key} = {})", yaml_text(value)),
                });
            }
            let group = declared
                .iter()
                .any(|d| d.strip_suffix('.') == Some(key.as_str()));
            let is_map = matches!(value, Value::Mapping(_));
            if group && !is_map {
                return Err(self.type_err(key, "a map of names to values"));
            }
            // an empty map under a value's key (flatten keeps it as the key's value)
            if is_map && declared.contains(&key.as_str()) {
                return Err(self.type_err(key, "a value"));
            }
        }
        Ok(())
    }

    fn type_err(&self, key: &str, expected: &'static str) -> ParamError {
        let (v, origin) = &self.values[key];
        ParamError::Type {
            origin: Box::new(origin.clone()),
            key: key.to_owned(),
            expected,
            found: yaml_text(v),
        }
    }

    /// A value of `key` the node cannot use, with what it expected: the error names where the
    /// value was set (`defaults` for a default).
    pub fn invalid(&self, key: &str, expected: &'static str) -> ParamError {
        match self.values.get(key) {
            Some(_) => self.type_err(key, expected),
            None => ParamError::Type {
                origin: Box::new(Origin {
                    file: "defaults".into(),
                    section: self.node.clone(),
                    specific: true,
                }),
                key: key.to_owned(),
                expected,
                found: "the default".into(),
            },
        }
    }

    /// Whether the key is set.
    pub fn has(&self, key: &str) -> bool {
        self.values.contains_key(key)
    }

    /// A finite double (an integer is accepted), or `default`.
    pub fn f64(&self, key: &str, default: f64) -> Result<f64, ParamError> {
        match self.values.get(key) {
            None => Ok(default),
            Some((v, _)) => v
                .as_f64()
                .filter(|x| x.is_finite())
                .ok_or_else(|| self.type_err(key, "a finite number")),
        }
    }

    /// Two finite doubles `lo < hi` (each its default where not set): an interval. The error
    /// names where the keys were set (the lower one's place where both were).
    pub fn interval(
        &self,
        (lo_key, lo_default): (&str, f64),
        (hi_key, hi_default): (&str, f64),
    ) -> Result<(f64, f64), ParamError> {
        let (lo, hi) = (self.f64(lo_key, lo_default)?, self.f64(hi_key, hi_default)?);
        // written so that a NaN fails too
        if lo < hi {
            return Ok((lo, hi));
        }
        let origin = [lo_key, hi_key]
            .iter()
            .find_map(|k| self.values.get(*k).map(|(_, o)| o.clone()))
            .unwrap_or_else(|| Origin {
                file: "defaults".into(),
                section: self.node.clone(),
                specific: true,
            });
        Err(ParamError::Interval {
            origin: Box::new(origin),
            lo_key: lo_key.into(),
            lo,
            hi_key: hi_key.into(),
            hi,
        })
    }

    /// A finite double > 0, or `default`.
    pub fn positive(&self, key: &str, default: f64) -> Result<f64, ParamError> {
        let v = self.f64(key, default)?;
        if v > 0.0 {
            Ok(v)
        } else {
            Err(self.type_err(key, "a number > 0"))
        }
    }

    /// A non-negative integer, or `default`.
    pub fn u64(&self, key: &str, default: u64) -> Result<u64, ParamError> {
        match self.values.get(key) {
            None => Ok(default),
            Some((v, _)) => v
                .as_u64()
                .ok_or_else(|| self.type_err(key, "a non-negative integer")),
        }
    }

    fn range_err(&self, key: &str, expected: String) -> ParamError {
        let (v, origin) = &self.values[key];
        ParamError::Range {
            origin: Box::new(origin.clone()),
            key: key.to_owned(),
            found: yaml_text(v),
            expected,
        }
    }

    /// A finite double in `lo..=hi` (`unit` for the message, e.g. " s"), or `default`.
    /// Every duration, period and rate goes through here: `Duration::from_secs_f64` panics
    /// on values beyond its range, so a number from a file is bounded before it becomes one.
    pub fn f64_in(
        &self,
        key: &str,
        default: f64,
        (lo, hi): (f64, f64),
        unit: &str,
    ) -> Result<f64, ParamError> {
        let v = self.f64(key, default)?;
        if !self.has(key) || (lo..=hi).contains(&v) {
            Ok(v)
        } else {
            Err(self.range_err(key, format!("{lo} to {hi}{unit}")))
        }
    }

    /// An integer in `lo..=hi`, or `default`: buffer sizes and counts are bounded before
    /// anything is allocated from them.
    pub fn u64_in(&self, key: &str, default: u64, (lo, hi): (u64, u64)) -> Result<u64, ParamError> {
        let v = self.u64(key, default)?;
        if !self.has(key) || (lo..=hi).contains(&v) {
            Ok(v)
        } else {
            Err(self.range_err(key, format!("{lo} to {hi}")))
        }
    }

    /// A boolean, or `default`.
    pub fn bool(&self, key: &str, default: bool) -> Result<bool, ParamError> {
        match self.values.get(key) {
            None => Ok(default),
            Some((v, _)) => v
                .as_bool()
                .ok_or_else(|| self.type_err(key, "true or false")),
        }
    }

    /// A string, or `default`.
    pub fn string(&self, key: &str, default: &str) -> Result<String, ParamError> {
        match self.values.get(key) {
            None => Ok(default.to_owned()),
            Some((Value::String(s), _)) => Ok(s.clone()),
            Some((v @ (Value::Number(_) | Value::Bool(_)), _)) => Ok(yaml_text(v)),
            Some(_) => Err(self.type_err(key, "a string")),
        }
    }

    /// A list of strings, or `default`.
    pub fn strings(&self, key: &str, default: &[&str]) -> Result<Vec<String>, ParamError> {
        match self.values.get(key) {
            None => Ok(default.iter().map(|s| (*s).to_owned()).collect()),
            Some((Value::Sequence(items), _)) => items
                .iter()
                .map(|i| match i {
                    Value::String(s) => Ok(s.clone()),
                    _ => Err(self.type_err(key, "a list of strings")),
                })
                .collect(),
            Some(_) => Err(self.type_err(key, "a list of strings")),
        }
    }

    /// A list of finite doubles (integers accepted), or `default`.
    pub fn f64s(&self, key: &str, default: &[f64]) -> Result<Vec<f64>, ParamError> {
        match self.values.get(key) {
            None => Ok(default.to_vec()),
            Some((Value::Sequence(items), _)) => items
                .iter()
                .map(|i| {
                    i.as_f64()
                        .filter(|x| x.is_finite())
                        .ok_or_else(|| self.type_err(key, "a list of finite numbers"))
                })
                .collect(),
            Some(_) => Err(self.type_err(key, "a list of finite numbers")),
        }
    }

    /// The strings of the group `prefix.` (`temperatures.` gives `temp_machine ->
    /// /cell/frame_temperature`), in name order, with their origins; an empty map (`group:
    /// {}`) has none.
    pub fn string_group(&self, prefix: &str) -> Result<Vec<(String, String, Origin)>, ParamError> {
        let mut out = Vec::new();
        for (key, (v, origin)) in self.values.range(prefix.to_owned()..) {
            let Some(name) = key.strip_prefix(prefix) else {
                break;
            };
            let text = match v {
                Value::String(s) => s.clone(),
                _ => return Err(self.type_err(key, "a string")),
            };
            out.push((name.to_owned(), text, origin.clone()));
        }
        Ok(out)
    }

    /// The finite doubles of the group `prefix.` (e.g. `geometry.` gives `l1 -> 0.95`), with
    /// their origins.
    pub fn group(&self, prefix: &str) -> Result<Vec<(String, f64, Origin)>, ParamError> {
        let mut out = Vec::new();
        for (key, (v, origin)) in self.values.range(prefix.to_owned()..) {
            let Some(name) = key.strip_prefix(prefix) else {
                break;
            };
            let x = v
                .as_f64()
                .filter(|x| x.is_finite())
                .ok_or_else(|| self.type_err(key, "a finite number"))?;
            out.push((name.to_owned(), x, origin.clone()));
        }
        Ok(out)
    }

    /// Sets `key` as the node's `set_parameters` service accepted it (origin
    /// `set_parameters: /<node>/ros__parameters`).
    pub fn set_from_service(&mut self, key: &str, value: Value) {
        let origin = Origin {
            file: "set_parameters".into(),
            section: format!("/{}", self.node),
            specific: true,
        };
        self.values.insert(key.to_owned(), (value, origin));
    }

    /// The origin of a key, for messages.
    pub fn origin(&self, key: &str) -> Option<&Origin> {
        self.values.get(key).map(|(_, o)| o)
    }
}

#[cfg(test)]
#[expect(
    clippy::float_cmp,
    reason = "exact values: parsed, copied or computed without rounding"
)]
mod tests {
    use super::*;

    const FILE: &str = "\
/**:
  ros__parameters:
    model: 24
    other_node_key: 1
preload_monitor:
  ros__parameters:
    warn_percent: 20
    error_percent: 50.5
    geometry:
      l1: 0.9501
      gamma1: -0.0002
tcp_estimator:
  ros__parameters:
    model: 29
";

    fn load(text: &str, node: &str) -> Result<NodeParams, ParamError> {
        let mut p = NodeParams::empty(node);
        p.merge_text(text, Path::new("p.yaml"))?;
        Ok(p)
    }

    #[test]
    fn sections_merge_in_order_and_flatten() -> Result<(), ParamError> {
        let p = load(FILE, "preload_monitor")?;
        assert_eq!(p.u64("model", 29)?, 24);
        assert_eq!(p.f64("warn_percent", 0.0)?, 20.0);
        assert_eq!(p.f64("error_percent", 0.0)?, 50.5);
        assert_eq!(p.f64("absent", 7.5)?, 7.5);
        let g = p.group("geometry.")?;
        let names: Vec<&str> = g.iter().map(|(n, _, _)| n.as_str()).collect();
        assert_eq!(names, ["gamma1", "l1"]);
        assert_eq!(g[1].1, 0.9501);
        let e = load(FILE, "tcp_estimator")?;
        assert_eq!(e.u64("model", 0)?, 29, "the node's own section comes later");
        Ok(())
    }

    /// A section addresses a node as ROS 2 resolves it: its name alone, its name in rpkm's
    /// namespace, or under a wildcard; the same name in another namespace is another node.
    #[test]
    fn sections_of_another_namespace_are_not_applied() -> Result<(), ParamError> {
        for (section, applied) in [
            ("ingest", true),
            ("/ingest", true),
            ("/rpkm/ingest", true),
            ("/**/ingest", true),
            ("/*/ingest", true),
            ("/foo/ingest", false),
            ("/rpkm/sub/ingest", false),
            ("/rpkm/ingest_2", false),
        ] {
            let p = load(
                &format!("{section}:\n  ros__parameters:\n    rate_hz: 5.0\n"),
                "ingest",
            )?;
            let want = if applied { 5.0 } else { 1.0 };
            assert_eq!(p.f64("rate_hz", 1.0)?, want, "{section}");
        }
        Ok(())
    }

    #[test]
    fn undeclared_keys_of_the_own_section_are_errors() -> Result<(), ParamError> {
        let p = load(FILE, "preload_monitor")?;
        p.check_declared(&["model", "warn_percent", "error_percent", "geometry."])?;
        let err = p
            .check_declared(&["model", "warn_percent", "geometry."])
            .expect_err("error_percent undeclared");
        assert!(
            err.to_string()
                .starts_with("p.yaml: preload_monitor/ros__parameters/error_percent: unknown"),
            "{err}"
        );
        Ok(())
    }

    #[test]
    fn wrong_types_name_file_section_and_key() -> Result<(), ParamError> {
        let p = load(
            "/rpkm/ingest:\n  ros__parameters:\n    rate_hz: fast\n",
            "ingest",
        )?;
        let err = p.f64("rate_hz", 1.0).expect_err("not a number");
        assert_eq!(
            err.to_string(),
            "p.yaml: /rpkm/ingest/ros__parameters/rate_hz: expected a finite number, found \"fast\""
        );
        let bad = load("ingest: [1, 2\n", "ingest").expect_err("not YAML");
        assert!(
            matches!(bad, ParamError::Yaml(YamlSyntax { line: 2, .. })),
            "{bad}"
        );
        let layout = load("ingest:\n  rate_hz: 3\n", "ingest").expect_err("no ros__parameters");
        assert!(layout.to_string().contains("ros__parameters"), "{layout}");
        Ok(())
    }

    /// A map where a value belongs (the fuzzer's `diagnostics_period_s: {a: 1}`, in the
    /// wildcard section) and a value where the geometry map belongs are refused with the
    /// key; an empty map too (it does not vanish).
    #[test]
    fn maps_and_values_in_each_others_place_are_refused_with_the_key() -> Result<(), ParamError> {
        let declared = ["diagnostics_period_s", "model", "geometry."];
        for (text, says) in [
            (
                "/**:\n  ros__parameters:\n    diagnostics_period_s: {a: 1}\n",
                "p.yaml: /**/ros__parameters/diagnostics_period_s: expected a value, found a map \
                 (with diagnostics_period_s.a = 1)",
            ),
            (
                "tcp_estimator:\n  ros__parameters:\n    geometry: 5\n",
                "p.yaml: tcp_estimator/ros__parameters/geometry: expected a map of names to \
                 values, found 5",
            ),
        ] {
            let p = load(text, "tcp_estimator")?;
            let err = p.check_declared(&declared).expect_err(text);
            assert_eq!(err.to_string(), says);
        }
        let p = load(
            "/**:\n  ros__parameters:\n    diagnostics_period_s: {}\n",
            "tcp_estimator",
        )?;
        let err = p
            .check_declared(&declared)
            .expect_err("an empty map is not a value");
        assert!(
            err.to_string()
                .ends_with("diagnostics_period_s: expected a value, found {}"),
            "{err}"
        );
        // a key of another node under a wildcard stays none of this node's business
        let p = load(
            "/**:\n  ros__parameters:\n    rate_hz: {a: 1}\n",
            "tcp_estimator",
        )?;
        p.check_declared(&declared)?;
        Ok(())
    }

    #[test]
    fn out_of_range_values_name_file_key_and_bounds() -> Result<(), ParamError> {
        let p = load(
            "calibrator:\n  ros__parameters:\n    state_buffer: 4294967296\n    idle_end_s: 1e308\n",
            "calibrator",
        )?;
        let err = p
            .u64_in("state_buffer", 4096, (1, 1_000_000))
            .expect_err("too large");
        assert_eq!(
            err.to_string(),
            "p.yaml: calibrator/ros__parameters/state_buffer: 4294967296 is out of range: \
             expected 1 to 1000000"
        );
        let err = p
            .f64_in("idle_end_s", 0.0, (0.0, 3600.0), " s")
            .expect_err("too long");
        assert!(
            err.to_string()
                .starts_with("p.yaml: calibrator/ros__parameters/idle_end_s: 1e308 is out"),
            "{err}"
        );
        assert!(err.to_string().ends_with("expected 0 to 3600 s"), "{err}");
        // Absent keys take the default; values at the bounds are accepted.
        assert_eq!(p.f64_in("absent", 2.0, (0.0, 3600.0), " s")?, 2.0);
        let q = load(
            "calibrator:\n  ros__parameters:\n    state_buffer: 1000000\n",
            "calibrator",
        )?;
        assert_eq!(q.u64_in("state_buffer", 4096, (1, 1_000_000))?, 1_000_000);
        Ok(())
    }
}
