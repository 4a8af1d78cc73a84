//! The core's layers: the model (everything but `twin/`) never names the simulator, so that
//! what the model assumes cannot be borrowed from how the twin simulates; and the core stays
//! free of I/O, async and transport crates.

use std::path::{Path, PathBuf};

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let entries = std::fs::read_dir(dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
    for entry in entries.map(|e| e.expect("directory entry")) {
        let path = entry.path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|x| x == "rs") {
            out.push(path);
        }
    }
}

/// Lines of `text` whose code (not comment) names the twin module.
fn names_twin(text: &str) -> Vec<(usize, String)> {
    text.lines()
        .enumerate()
        .filter(|(_, line)| {
            let code = line.split("//").next().unwrap_or("");
            code.contains("twin::") || code.contains("crate::{") && code.contains("twin")
        })
        .map(|(n, line)| (n + 1, line.trim().to_owned()))
        .collect()
}

#[test]
fn the_detector_sees_each_spelling() {
    assert_eq!(names_twin("use crate::twin::effects::bow;").len(), 1);
    assert_eq!(names_twin("use crate::{params, twin};").len(), 1);
    assert!(names_twin("//! the twin drives them ([`crate::twin`])").is_empty());
}

#[test]
fn the_model_never_names_the_twin() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    files.retain(|f| !f.starts_with(src.join("twin")) && !f.ends_with("lib.rs"));
    assert!(files.len() >= 20, "found only {files:?}");
    let offences: Vec<String> = files
        .iter()
        .flat_map(|f| {
            let text = std::fs::read_to_string(f).expect("read source");
            names_twin(&text)
                .into_iter()
                .map(move |(n, l)| format!("{}:{n}: {l}", f.display()))
        })
        .collect();
    assert!(
        offences.is_empty(),
        "the model names the twin:\n{}",
        offences.join("\n")
    );
}

/// Crates that do I/O, async or transport: the nodes' business, never the core's.
const FORBIDDEN: [&str; 7] = [
    "iceoryx2",
    "ros2-client",
    "rustdds",
    "mcap",
    "tokio",
    "serde_yaml",
    "serde_json",
];

#[test]
fn the_core_depends_on_no_transport_crate() {
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR")).join("Cargo.toml");
    let text = std::fs::read_to_string(&manifest).expect("read core/Cargo.toml");
    let mut section = String::new();
    let mut offences = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.starts_with('[') {
            section = line.to_owned();
            continue;
        }
        let name = line.split(['=', ' ', '.']).next().unwrap_or("");
        if section == "[dependencies]" && FORBIDDEN.contains(&name) {
            offences.push(format!("core/Cargo.toml:{}: {line}", n + 1));
        }
    }
    assert!(offences.is_empty(), "{}", offences.join("\n"));
}
