//! The development material beside the clone (`../shared`: the independent simulator's
//! campaigns, the machine's specification), which a clone of the repository alone does not
//! have. The one place that decides whether a test reading it runs: present, it runs; absent,
//! it skips with a one-line reason on stderr; absent under `CI=true` (or `CI=1`), where the
//! material must be there, it fails, as the Python peers do under `RPKM_REQUIRE_PYTHON`.

use std::path::{Path, PathBuf};

/// `../shared/<relative>` beside the clone, or `None` with `skipped: ...` said on stderr
/// (`what` names what a clone lacks without it); a failure under `CI=true`.
pub fn path(relative: &str, what: &str) -> Option<PathBuf> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared")
        .join(relative);
    if path.exists() {
        return Some(path);
    }
    assert!(
        !required(),
        "CI is set: {} ({what}) must be beside the clone",
        path.display()
    );
    eprintln!("skipped: ../shared/{relative} is absent (a clone without {what})");
    None
}

/// Whether the environment says the development material must be there: `CI=true` (as CI
/// services set it) or `CI=1`.
fn required() -> bool {
    std::env::var("CI").is_ok_and(|v| v.eq_ignore_ascii_case("true") || v == "1")
}
