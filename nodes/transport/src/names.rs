//! ROS 2 names of one node: its namespace and its remapping rules (`--ros-args -r __ns:=NS
//! -r FROM:=TO`), applied to every topic it opens, so that two node sets in one DDS domain
//! (or on one host's iceoryx2) never hear each other.
//!
//! rpkm's topics are written `/rpkm/<name>` in the code: the default namespace. A node in
//! namespace `/machine_a` resolves them to `/machine_a/<name>`, as ROS 2 resolves a relative
//! topic name. The global names (`/diagnostics`, `/tf`, `/joint_states`) stay global on DDS,
//! as in ROS 2; on iceoryx2, which only rpkm processes share, they move into the namespace
//! too (`/machine_a/diagnostics`), so that nothing of one set reaches the other. Then the
//! first rule whose FROM is the name (absolute, or relative to the namespace) replaces it.

use std::collections::HashSet;
use std::sync::{Mutex, PoisonError};

/// The ROS 2 namespace of every rpkm node (`/rpkm/ingest`, `/rpkm/tcp_estimator`, ...).
pub const NODE_NAMESPACE: &str = "/rpkm";

/// A namespace or remapping rule that ROS 2 would refuse.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{what} {given:?}: {why}")]
pub struct NameError {
    /// `namespace` or `remap`.
    pub what: &'static str,
    /// The text given.
    pub given: String,
    /// What is wrong with it.
    pub why: String,
}

/// Longest namespace or topic name taken (rmw's topic names are bounded; 255 is far past any
/// cell's).
const NAME_MAX: usize = 255;

/// A node's namespace and remapping rules.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Names {
    namespace: String,
    /// (FROM, TO), both absolute.
    remaps: Vec<(String, String)>,
}

impl Default for Names {
    fn default() -> Self {
        Self {
            namespace: NODE_NAMESPACE.to_owned(),
            remaps: Vec::new(),
        }
    }
}

/// Why `name` is not an absolute ROS 2 name (`/a/b_2`), or `None`.
pub fn absolute_name_error(name: &str) -> Option<String> {
    let Some(rest) = name.strip_prefix('/') else {
        return Some("expected an absolute name starting with `/`".into());
    };
    if name.len() > NAME_MAX {
        return Some(format!("longer than {NAME_MAX} characters"));
    }
    if rest.is_empty() {
        return None;
    }
    for token in rest.split('/') {
        if token.is_empty() {
            return Some("has an empty part (`//` or a trailing `/`)".into());
        }
        if token.starts_with(|c: char| c.is_ascii_digit()) {
            return Some(format!("part {token:?} starts with a digit"));
        }
        if !token.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
            return Some(format!(
                "part {token:?} has a character other than a letter, a digit or `_`"
            ));
        }
    }
    None
}

impl Names {
    /// A node in `namespace` (absolute; `/` is the root) with the rules `remaps` (FROM, TO:
    /// absolute, or relative to the namespace).
    pub fn new(namespace: &str, remaps: &[(String, String)]) -> Result<Self, NameError> {
        if let Some(why) = absolute_name_error(namespace) {
            return Err(NameError {
                what: "namespace",
                given: namespace.to_owned(),
                why,
            });
        }
        let mut names = Self {
            namespace: namespace.to_owned(),
            remaps: Vec::new(),
        };
        for (from, to) in remaps {
            let (from_abs, to_abs) = (names.absolute(from), names.absolute(to));
            for name in [&from_abs, &to_abs] {
                if let Some(why) = absolute_name_error(name) {
                    return Err(NameError {
                        what: "remap",
                        given: format!("{from}:={to}"),
                        why,
                    });
                }
            }
            names.remaps.push((from_abs, to_abs));
        }
        Ok(names)
    }

    /// The namespace (`/rpkm` by default).
    pub fn namespace(&self) -> &str {
        &self.namespace
    }

    /// Whether this is rpkm's default: namespace `/rpkm`, no rule.
    pub fn is_default(&self) -> bool {
        self.namespace == NODE_NAMESPACE && self.remaps.is_empty()
    }

    /// `name` made absolute against the namespace.
    fn absolute(&self, name: &str) -> String {
        if name.starts_with('/') {
            name.to_owned()
        } else if self.namespace == "/" {
            format!("/{name}")
        } else {
            format!("{}/{name}", self.namespace)
        }
    }

    /// `name` in the namespace: `/rpkm/x` becomes `NS/x`; other names stay.
    fn in_namespace(&self, name: &str) -> String {
        match name
            .strip_prefix(NODE_NAMESPACE)
            .and_then(|r| r.strip_prefix('/'))
        {
            Some(rest) => self.absolute(rest),
            None => name.to_owned(),
        }
    }

    /// The DDS name of rpkm's topic `name` (written `/rpkm/...` or global): in the
    /// namespace, then remapped by the first rule that names it (as written in the code or
    /// as resolved).
    pub fn resolve(&self, name: &str) -> String {
        let resolved = self.in_namespace(name);
        self.remaps
            .iter()
            .find(|(from, _)| *from == resolved || from == name)
            .map_or(resolved, |(_, to)| to.clone())
    }

    /// The iceoryx2 name of rpkm's topic `name`: [`Self::resolve`], and a global name moved
    /// into a namespace other than rpkm's default (only rpkm shares iceoryx2, and two sets
    /// must not share /diagnostics there).
    pub fn resolve_ipc(&self, name: &str) -> String {
        let resolved = self.resolve(name);
        let inside = resolved
            .strip_prefix(&self.namespace)
            .is_some_and(|r| r.starts_with('/'));
        if self.namespace == NODE_NAMESPACE || self.namespace == "/" || inside {
            resolved
        } else {
            format!("{}{resolved}", self.namespace)
        }
    }

    /// The status name of node `node` on /diagnostics: `rpkm/tcp_estimator`, or
    /// `machine_a/tcp_estimator` in namespace `/machine_a`.
    pub fn status_name(&self, node: &str) -> String {
        let ns = self.namespace.trim_start_matches('/');
        if ns.is_empty() {
            node.to_owned()
        } else {
            format!("{ns}/{node}")
        }
    }
}

/// `name` as a `&'static str`, kept for the rest of the process: topics carry static names,
/// and a node resolves each of its few topics once. The same text is stored once.
pub fn intern(name: String) -> &'static str {
    static NAMES: Mutex<Option<HashSet<&'static str>>> = Mutex::new(None);
    let mut names = NAMES.lock().unwrap_or_else(PoisonError::into_inner);
    let set = names.get_or_insert_with(HashSet::new);
    if let Some(known) = set.get(name.as_str()) {
        return known;
    }
    let leaked: &'static str = Box::leak(name.into_boxed_str());
    set.insert(leaked);
    leaked
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn topics_follow_the_namespace_and_the_rules() -> Result<(), NameError> {
        let d = Names::default();
        assert_eq!(d.resolve("/rpkm/tcp_estimate"), "/rpkm/tcp_estimate");
        assert_eq!(d.resolve_ipc("/diagnostics"), "/diagnostics");
        let a = Names::new(
            "/machine_a",
            &[
                ("tcp_estimate".into(), "/cell/estimate_a".into()),
                ("/rpkm/parameters".into(), "geometry".into()),
            ],
        )?;
        assert_eq!(
            a.resolve("/rpkm/actuator_state"),
            "/machine_a/actuator_state"
        );
        assert_eq!(a.resolve("/rpkm/tcp_estimate"), "/cell/estimate_a");
        assert_eq!(a.resolve("/rpkm/parameters"), "/machine_a/geometry");
        assert_eq!(a.resolve("/diagnostics"), "/diagnostics");
        assert_eq!(a.resolve_ipc("/diagnostics"), "/machine_a/diagnostics");
        assert_eq!(
            a.resolve_ipc("/rpkm/actuator_state"),
            "/machine_a/actuator_state"
        );
        assert_eq!(a.status_name("ingest"), "machine_a/ingest");
        let nested = Names::new("/cell/m2", &[])?;
        assert_eq!(
            nested.resolve("/rpkm/tcp_estimate"),
            "/cell/m2/tcp_estimate"
        );
        Ok(())
    }

    #[test]
    fn names_ros_2_would_refuse_are_refused() {
        for ns in ["machine_a", "/a//b", "/a/", "/1a", "/a-b", "/ä"] {
            assert!(Names::new(ns, &[]).is_err(), "{ns}");
        }
        let e = Names::new("/m", &[("x".into(), "/a b".into())]).expect_err("space");
        assert_eq!(e.what, "remap");
        assert!(Names::new(&format!("/{}", "a".repeat(300)), &[]).is_err());
    }

    #[test]
    fn interned_names_are_stored_once() {
        let a = intern("/machine_q/x".to_owned());
        let b = intern("/machine_q/x".to_owned());
        assert!(std::ptr::eq(a, b));
    }
}
