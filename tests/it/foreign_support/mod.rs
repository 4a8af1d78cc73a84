//! The independent simulator's campaigns (`../shared/campaigns/foreign`, beside the clone):
//! where they are, required under CI and skipped with a word elsewhere.
#![allow(dead_code)] // each test file uses a part

use std::path::{Path, PathBuf};

/// The folder of the foreign data set `name` (`null`, `thermal`, `alignment`), or the whole
/// collection for `""`; `None` (skipped, said on stderr) where it is not beside the clone,
/// a failure under CI, where it must be.
pub fn dataset(name: &str) -> Option<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/campaigns/foreign")
        .join(name);
    if dir.is_dir() {
        return Some(dir);
    }
    assert!(
        std::env::var_os("CI").is_none(),
        "CI: {} is missing",
        dir.display()
    );
    eprintln!("skipped: no {}", dir.display());
    None
}

/// A JSON file of the data set (truth.json), or a failure naming it.
pub fn json(path: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}
