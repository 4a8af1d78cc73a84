//! The lint opt-outs are counted: every local `#[expect(clippy::...)]` carries a reason, no
//! source says `#[allow(clippy::...)]` (an `expect` fails once its lint no longer fires, an
//! `allow` stays forever), and docs/lints.md lists each opted-out lint with the number of
//! places that opt out of it, and every workspace-wide opt-out of Cargo.toml.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let entries = std::fs::read_dir(dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
    for entry in entries.map(|e| e.expect("directory entry")) {
        let path = entry.path();
        let name = entry.file_name();
        if path.is_dir() {
            if name != "target" && !name.to_string_lossy().starts_with('.') {
                rust_files(&path, out);
            }
        } else if path.extension().is_some_and(|x| x == "rs") {
            out.push(path);
        }
    }
}

/// One opt-out attribute: the lints it names and whether it gives a reason.
#[derive(Debug, PartialEq)]
struct OptOut {
    kind: &'static str,
    lints: Vec<String>,
    reason: bool,
}

/// The `#[expect(...)]`/`#[allow(...)]` attributes of `text` that name clippy lints.
fn opt_outs(text: &str) -> Vec<OptOut> {
    let mut found = Vec::new();
    for kind in ["expect", "allow"] {
        for pattern in [format!("#[{kind}("), format!("#![{kind}(")] {
            let mut rest = text;
            while let Some(at) = rest.find(&pattern) {
                let body = &rest[at + pattern.len()..];
                let end = body.find(")]").unwrap_or(body.len());
                let inside = &body[..end];
                let lints: Vec<String> = inside
                    .split(|c: char| c == ',' || c.is_whitespace())
                    .filter_map(|w| w.strip_prefix("clippy::"))
                    .map(str::to_owned)
                    .collect();
                if !lints.is_empty() {
                    found.push(OptOut {
                        kind,
                        lints,
                        reason: inside.contains("reason = \""),
                    });
                }
                rest = &body[end..];
            }
        }
    }
    found
}

/// The `| lint | count |` rows of docs/lints.md's table of local opt-outs.
fn documented_counts(doc: &str) -> BTreeMap<String, usize> {
    let mut counts = BTreeMap::new();
    for line in doc.lines() {
        let cells: Vec<&str> = line.split('|').map(str::trim).collect();
        if cells.len() < 4 {
            continue;
        }
        let lint = cells[1].trim_matches('`');
        if let (Some(name), Ok(n)) = (lint.strip_prefix("clippy::"), cells[2].parse()) {
            counts.insert(name.to_owned(), n);
        }
    }
    counts
}

/// The lints Cargo.toml's `[workspace.lints.clippy]` sets to "allow".
fn workspace_opt_outs(manifest: &str) -> Vec<String> {
    let section = manifest
        .split("[workspace.lints.clippy]")
        .nth(1)
        .expect("a [workspace.lints.clippy] section");
    let section = section.split("\n[").next().unwrap_or(section);
    section
        .lines()
        .filter(|l| l.trim_end().ends_with("= \"allow\""))
        .map(|l| l.split('=').next().unwrap_or("").trim().to_owned())
        .collect()
}

#[test]
fn the_reader_sees_expect_allow_and_reasons() {
    let text = "#[expect(clippy::float_cmp, reason = \"exact\")]\nfn a() {}\n\
                #![allow(clippy::cast_sign_loss, clippy::cast_possible_wrap)]\n\
                #[allow(dead_code)]\n";
    let found = opt_outs(text);
    assert_eq!(found.len(), 2, "{found:?}");
    assert_eq!(found[0].kind, "expect");
    assert_eq!(found[0].lints, ["float_cmp"]);
    assert!(found[0].reason);
    assert_eq!(found[1].kind, "allow");
    assert_eq!(found[1].lints, ["cast_sign_loss", "cast_possible_wrap"]);
    assert!(!found[1].reason);
    let doc = "| lint | places | why |\n|---|---|---|\n| `clippy::float_cmp` | 3 | x |\n";
    assert_eq!(documented_counts(doc).get("float_cmp"), Some(&3));
}

#[test]
fn every_opt_out_is_an_expect_with_a_reason_and_counted_in_docs_lints_md() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files = Vec::new();
    for dir in ["core", "msgs", "nodes", "src", "benches", "tests"] {
        rust_files(&root.join(dir), &mut files);
    }
    assert!(files.len() > 100, "found only {} files", files.len());
    let mut counts: BTreeMap<String, usize> = BTreeMap::new();
    let mut offences = Vec::new();
    for file in &files {
        let text = std::fs::read_to_string(file).expect("read source");
        if file.ends_with("tests/lints.rs") {
            continue; // its examples are strings
        }
        for o in opt_outs(&text) {
            if o.kind == "allow" || !o.reason {
                offences.push(format!("{}: {o:?}", file.display()));
            }
            for lint in o.lints {
                *counts.entry(lint).or_default() += 1;
            }
        }
    }
    assert!(
        offences.is_empty(),
        "opt-outs must be #[expect(clippy::..., reason = \"...\")]:\n{}",
        offences.join("\n")
    );
    let doc = std::fs::read_to_string(root.join("docs/lints.md")).expect("docs/lints.md");
    assert_eq!(
        documented_counts(&doc),
        counts,
        "docs/lints.md's table of local opt-outs (left) against the sources (right)"
    );
    let manifest = std::fs::read_to_string(root.join("Cargo.toml")).expect("Cargo.toml");
    let workspace = workspace_opt_outs(&manifest);
    assert!(workspace.len() >= 6, "{workspace:?}");
    for lint in workspace {
        assert!(
            doc.contains(&format!("`{lint}`")),
            "Cargo.toml opts out of {lint} for the workspace; docs/lints.md does not say why"
        );
    }
}

/// The tuple types of `text` that bundle more than two flags (`(bool, bool, bool)`): flags
/// that travel together are a struct with named fields, or the call sites read
/// `(true, false, true)`.
fn flag_tuples(text: &str) -> Vec<String> {
    let mut found = Vec::new();
    for (at, _) in text.match_indices('(') {
        let body = &text[at + 1..];
        let Some(end) = body.find(')') else { continue };
        let items: Vec<&str> = body[..end].split(',').map(str::trim).collect();
        let flags = items.iter().filter(|i| **i == "bool").count();
        if flags > 2 && !body[..end].contains('(') {
            found.push(format!("({})", &body[..end]));
        }
    }
    found
}

#[test]
fn the_flag_tuple_reader_sees_three_flags() {
    assert_eq!(
        flag_tuples("fn f((a, b, c): (bool, bool, bool)) {}").len(),
        1
    );
    assert!(flag_tuples("fn f((warm, screen): (bool, bool)) {}").is_empty());
    assert!(flag_tuples("fn f(x: (usize, f64, bool)) {}").is_empty());
}

/// No function of the workspace takes (or any type bundles) more than two flags in a tuple.
#[test]
fn no_tuple_of_more_than_two_flags() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files = Vec::new();
    for dir in ["core", "twin", "msgs", "nodes", "src", "benches"] {
        rust_files(&root.join(dir), &mut files);
    }
    assert!(files.len() >= 100, "found only {} files", files.len());
    let offences: Vec<String> = files
        .iter()
        .flat_map(|f| {
            let text = std::fs::read_to_string(f).expect("read source");
            flag_tuples(&text)
                .into_iter()
                .map(move |t| format!("{}: {t}", f.display()))
        })
        .collect();
    assert!(offences.is_empty(), "{}", offences.join("\n"));
}
