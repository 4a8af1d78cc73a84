//! Run-time parameter values kept across a restart: what a cell set through the parameter
//! services (`followers`, a threshold) is what the node carries after `rpkm launch` restarted
//! it, never a silent return to the files' value.
//!
//! The launcher gives its nodes a folder of their own ([`STATE_DIR_ENV`], made fresh at every
//! launch, so that a new launch starts from the files). A node writes every change it
//! accepted to `<folder>/<namespace>.<name>.yaml` (written whole and renamed into place: a
//! node killed while writing leaves the previous file), a ROS 2 parameter file of its own
//! section with the time each value was set:
//!
//! ```yaml
//! /rpkm/ingest:
//!   ros__parameters:
//!     followers: ''
//!   set_at:
//!     followers: 2026-11-29T03:10:02.123Z
//! ```
//!
//! At its start the node reads it after its parameter files and `--param`s (the value set last
//! wins) and says which values it kept and when they were set. A node started without the
//! variable keeps nothing.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde_yaml::{Mapping, Value};

use super::params::{NodeParams, ParamError};

/// The environment variable naming the folder of the kept values (set by `rpkm launch`).
pub const STATE_DIR_ENV: &str = "RPKM_STATE_DIR";

/// The `set_at` map of a kept file's section.
const SET_AT: &str = "set_at";

/// The kept values of one node: its file and what it holds.
#[derive(Debug, Clone)]
pub struct Kept {
    path: PathBuf,
    /// `/namespace/name`: the file's one section.
    section: String,
    values: BTreeMap<String, Value>,
    set_at: BTreeMap<String, String>,
}

/// The file of node `name` in `namespace` under `dir`.
fn file_of(dir: &Path, namespace: &str, name: &str) -> PathBuf {
    let ns = namespace.trim_matches('/').replace('/', ".");
    dir.join(format!("{ns}.{name}.yaml"))
}

fn layout(path: &Path, what: &str) -> ParamError {
    ParamError::Layout {
        file: path.display().to_string(),
        what: what.to_owned(),
    }
}

impl Kept {
    /// The kept values of the node, from [`STATE_DIR_ENV`]; `None` without it.
    pub fn from_env(namespace: &str, name: &str) -> Result<Option<Self>, ParamError> {
        match std::env::var_os(STATE_DIR_ENV) {
            Some(dir) if !dir.is_empty() => Self::read(Path::new(&dir), namespace, name).map(Some),
            _ => Ok(None),
        }
    }

    /// The kept values of the node in `dir` (none when its file is not there yet).
    pub fn read(dir: &Path, namespace: &str, name: &str) -> Result<Self, ParamError> {
        let path = file_of(dir, namespace, name);
        let section = format!("/{}/{name}", namespace.trim_matches('/')).replace("//", "/");
        let mut kept = Self {
            path,
            section,
            values: BTreeMap::new(),
            set_at: BTreeMap::new(),
        };
        let text = match std::fs::read_to_string(&kept.path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(kept),
            Err(source) => {
                return Err(ParamError::Read {
                    file: kept.path.display().to_string(),
                    source,
                })
            }
        };
        let doc = super::params::parse_yaml(&text, &kept.path.display().to_string())?;
        let body = doc
            .get(kept.section.as_str())
            .ok_or_else(|| layout(&kept.path, &format!("expected section {}", kept.section)))?;
        let map = |key: &str| match body.get(key) {
            Some(Value::Mapping(m)) => Ok(m.clone()),
            _ => Err(layout(&kept.path, &format!("expected a `{key}` map"))),
        };
        for (k, v) in map("ros__parameters")? {
            if let Value::String(k) = k {
                kept.values.insert(k, v);
            }
        }
        for (k, v) in map(SET_AT)? {
            if let (Value::String(k), Value::String(v)) = (k, v) {
                kept.set_at.insert(k, v);
            }
        }
        Ok(kept)
    }

    /// Sets the kept values over `params` (origin: the kept file).
    pub fn apply(&self, params: &mut NodeParams) -> Result<(), ParamError> {
        if self.values.is_empty() {
            return Ok(());
        }
        params.merge_text(&self.text(), &self.path)
    }

    /// What the node says at its start: `followers "" (kept from the run before the
    /// restart, set at 2026-11-29T03:10:02.123Z)`, one per kept value; empty when none.
    pub fn said(&self) -> Vec<String> {
        self.values.keys().filter_map(|k| self.note(k)).collect()
    }

    /// `KEY VALUE (kept from the run before the restart, set at T)` when `key` is kept.
    pub fn note(&self, key: &str) -> Option<String> {
        let v = self.values.get(key)?;
        let at = self.set_at(key)?;
        Some(format!(
            "{key} {} (kept from the run before the restart, set at {at})",
            super::params::yaml_text(v)
        ))
    }

    /// When `key`'s kept value was set; `None` when it is not kept.
    pub fn set_at(&self, key: &str) -> Option<&str> {
        self.values.get(key)?;
        Some(
            self.set_at
                .get(key)
                .map_or("an unknown time", String::as_str),
        )
    }

    /// Records `changes` (accepted now) and writes the file whole, renamed into place.
    pub fn record(&mut self, changes: &[(String, Value)]) -> std::io::Result<()> {
        let now = chrono::Utc::now()
            .format("%Y-%m-%dT%H:%M:%S%.3fZ")
            .to_string();
        for (k, v) in changes {
            self.values.insert(k.clone(), v.clone());
            self.set_at.insert(k.clone(), now.clone());
        }
        if let Some(dir) = self.path.parent() {
            std::fs::create_dir_all(dir)?;
        }
        let tmp = self
            .path
            .with_extension(format!("yaml.{}", std::process::id()));
        std::fs::write(&tmp, self.text())?;
        std::fs::rename(&tmp, &self.path)
    }

    /// The file's text.
    fn text(&self) -> String {
        let to_map = |m: BTreeMap<String, Value>| -> Mapping {
            m.into_iter().map(|(k, v)| (Value::String(k), v)).collect()
        };
        let set_at = self
            .set_at
            .iter()
            .map(|(k, v)| (k.clone(), Value::String(v.clone())))
            .collect();
        let mut body = Mapping::new();
        body.insert(
            "ros__parameters".into(),
            Value::Mapping(to_map(self.values.clone())),
        );
        body.insert(SET_AT.into(), Value::Mapping(to_map(set_at)));
        let mut doc = Mapping::new();
        doc.insert(Value::String(self.section.clone()), Value::Mapping(body));
        serde_yaml::to_string(&doc).unwrap_or_default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_recorded_change_is_read_back_over_the_files_with_its_time() {
        let dir = std::env::temp_dir().join(format!("rpkm-kept-{}", std::process::id()));
        let mut kept = Kept::read(&dir, "/machine_a", "ingest").expect("no file yet");
        assert!(kept.said().is_empty());
        kept.record(&[("followers".into(), Value::String(String::new()))])
            .expect("written");
        kept.record(&[("warn_percent".into(), Value::from(35.5))])
            .expect("written");
        let files = dir.join("params.yaml");
        std::fs::write(
            &files,
            "ingest:\n  ros__parameters:\n    followers: '23'\n    rate_hz: 5.0\n",
        )
        .expect("params");
        let mut p = NodeParams::load_in("/machine_a", "ingest", &[files], &[]).expect("load");
        let back = Kept::read(&dir, "/machine_a", "ingest").expect("read back");
        back.apply(&mut p).expect("applied");
        assert_eq!(p.string("followers", "x").expect("a string"), "");
        assert!((p.f64("warn_percent", 0.0).expect("f64") - 35.5).abs() < 1e-12);
        assert!((p.f64("rate_hz", 0.0).expect("f64") - 5.0).abs() < 1e-12);
        let said = back.said();
        assert_eq!(said.len(), 2);
        assert!(
            said[0].starts_with("followers \"\" (kept from the run before the restart, set at 20"),
            "{said:?}"
        );
        // another node, another namespace: nothing kept
        let other = Kept::read(&dir, "/rpkm", "ingest").expect("read");
        assert!(other.said().is_empty());
        std::fs::remove_dir_all(&dir).expect("cleanup");
    }
}
