//! The folder where a launch's nodes keep the parameter values set at run time
//! (`rpkm_nodes::node::kept`): made fresh at every launch (a new launch starts from the
//! parameter files), kept across the restarts of its nodes, removed when the launch ends.

use std::path::PathBuf;

use rpkm_nodes::node::kept::STATE_DIR_ENV;

/// The launch's state folder; removed on drop.
pub struct StateDir(Option<PathBuf>);

impl StateDir {
    /// A new folder for this launch, under the temporary folder. Without one the nodes keep
    /// nothing across a restart, and the launch says so.
    pub fn create() -> Self {
        let path = std::env::temp_dir().join(format!(
            "rpkm-launch-{}-{}",
            std::process::id(),
            chrono::Utc::now().timestamp_nanos_opt().unwrap_or_default()
        ));
        match std::fs::create_dir_all(&path) {
            Ok(()) => Self(Some(path)),
            Err(e) => {
                rpkm_nodes::node::log_line(
                    "launch",
                    format!(
                        "WARN: no folder for the values set at run time ({}: {e}): a restarted \
                         node comes back with its files' values",
                        path.display()
                    ),
                );
                Self(None)
            }
        }
    }

    /// `env` with the folder named first, so that a `set_env` of the launch file may name
    /// another one.
    pub fn env(&self, env: &[(String, String)]) -> Vec<(String, String)> {
        let mut out = Vec::with_capacity(env.len() + 1);
        if let Some(p) = &self.0 {
            out.push((STATE_DIR_ENV.to_owned(), p.display().to_string()));
        }
        out.extend(env.iter().cloned());
        out
    }
}

impl Drop for StateDir {
    fn drop(&mut self) {
        if let Some(p) = &self.0 {
            let _ = std::fs::remove_dir_all(p);
        }
    }
}
