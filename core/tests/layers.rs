//! The core's layers: the model never names the simulator (the crate `rpkm-twin`), so that
//! what the model assumes cannot be borrowed from how the twin simulates; and the core stays
//! free of I/O, async and transport crates.

use std::path::Path;

/// Lines of `text` whose code (not comment) names the twin's crate.
fn names_twin(text: &str) -> Vec<(usize, String)> {
    text.lines()
        .enumerate()
        .filter(|(_, line)| {
            let code = line.split("//").next().unwrap_or("");
            code.contains("rpkm_twin")
        })
        .map(|(n, line)| (n + 1, line.trim().to_owned()))
        .collect()
}

#[test]
fn the_detector_sees_each_spelling() {
    assert_eq!(names_twin("use rpkm_twin::{Twin, TwinConfig};").len(), 1);
    assert_eq!(names_twin("    let t = rpkm_twin::Twin::new(c);").len(), 1);
    assert!(names_twin("//! the twin drives them ([`rpkm_twin`])").is_empty());
}

/// The simulator is a crate of its own (`twin/`, `rpkm-twin`) that depends on the core: the
/// model cannot name it by construction (a dependency the other way would be a cycle cargo
/// refuses). What is left to check: no twin folder in the core, the twin not among the core's
/// dependencies (a dev-dependency is the tests'), and no source of the core naming it.
#[test]
fn the_model_never_names_the_twin() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let src = root.join("src");
    assert!(!src.join("twin").exists(), "core/src/twin is back");
    let manifest = std::fs::read_to_string(root.join("Cargo.toml")).expect("core/Cargo.toml");
    let deps = manifest
        .split("[dev-dependencies]")
        .next()
        .unwrap_or_default();
    assert!(!deps.contains("rpkm-twin"), "the core depends on the twin");
    let mut files = Vec::new();
    file_graph::rust_files(&src, &mut files);
    assert!(files.len() >= 40, "found only {files:?}");
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

/// The top-level modules of the core (`core/src/X.rs` or `core/src/X/`), each with the text of
/// its files, comments removed.
fn module_texts(src: &Path) -> Vec<(String, String)> {
    let mut modules = Vec::new();
    let entries = std::fs::read_dir(src).expect("read core/src");
    for entry in entries.map(|e| e.expect("directory entry")) {
        let path = entry.path();
        let stem = path.file_stem().and_then(|s| s.to_str()).unwrap_or("");
        if stem == "lib" || (path.is_file() && path.extension().is_none_or(|x| x != "rs")) {
            continue;
        }
        let mut files = Vec::new();
        if path.is_dir() {
            file_graph::rust_files(&path, &mut files);
        } else {
            files.push(path.clone());
        }
        let code: String = files
            .iter()
            .map(|f| std::fs::read_to_string(f).expect("read source"))
            .flat_map(|t| {
                t.lines()
                    .map(|l| l.split("//").next().unwrap_or("").to_owned() + "\n")
                    .collect::<Vec<_>>()
            })
            .collect();
        match modules
            .iter_mut()
            .find(|(m, _): &&mut (String, String)| m == stem)
        {
            Some((_, text)) => text.push_str(&code),
            None => modules.push((stem.to_owned(), code)),
        }
    }
    modules
}

/// The top-level modules `code` names through `crate::`: `crate::a::b`, and each first name
/// of a group `crate::{a, b::{c, d}}` (nested groups and line breaks included).
fn crate_references(code: &str) -> Vec<String> {
    let ident = |s: &str| -> String {
        s.chars()
            .take_while(|c| c.is_alphanumeric() || *c == '_')
            .collect()
    };
    let mut names = Vec::new();
    for (at, _) in code.match_indices("crate::") {
        let rest = &code[at + "crate::".len()..];
        let Some(group) = rest.strip_prefix('{') else {
            names.push(ident(rest));
            continue;
        };
        let (mut depth, mut start) = (1, true);
        for (i, c) in group.char_indices() {
            match c {
                '{' => depth += 1,
                '}' if depth == 1 => break,
                '}' => depth -= 1,
                ',' if depth == 1 => start = true,
                c if start && depth == 1 && (c.is_alphanumeric() || c == '_') => {
                    names.push(ident(&group[i..]));
                    start = false;
                }
                _ => {}
            }
        }
    }
    names.retain(|n| !n.is_empty());
    names
}

#[test]
fn the_cycle_finder_sees_a_cycle_through_a_group_import() {
    let refs = crate_references(
        "use crate::{\n    obs::{a, b},\n    params::Params,\n};\nx(crate::geometry::igm)",
    );
    assert_eq!(refs, ["obs", "params", "geometry"]);
    let graph = |edges: &[(&str, &[&str])]| -> Vec<(String, Vec<String>)> {
        edges
            .iter()
            .map(|(m, e)| ((*m).to_owned(), e.iter().map(|s| (*s).to_owned()).collect()))
            .collect()
    };
    let cycle = file_graph::find_cycle(&graph(&[("a", &["b"]), ("b", &["c"]), ("c", &["a"])]));
    assert_eq!(cycle.expect("a -> b -> c -> a").len(), 4);
    assert!(
        file_graph::find_cycle(&graph(&[("a", &["b", "c"]), ("b", &["c"]), ("c", &[])])).is_none()
    );
}

/// No two modules of the core import each other, directly or around a loop: each layer can be
/// read, tested and changed knowing only those below it.
#[test]
fn no_core_module_imports_in_a_circle() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let modules = module_texts(&src);
    assert!(modules.len() >= 15, "found only {} modules", modules.len());
    let names: Vec<String> = modules.iter().map(|(m, _)| m.clone()).collect();
    let graph: Vec<(String, Vec<String>)> = modules
        .iter()
        .map(|(m, code)| {
            let mut deps = crate_references(code);
            deps.retain(|d| d != m && names.contains(d));
            deps.sort();
            deps.dedup();
            (m.clone(), deps)
        })
        .collect();
    let cycle = file_graph::find_cycle(&graph);
    assert!(
        cycle.is_none(),
        "core modules import each other: {}",
        cycle.unwrap_or_default().join(" -> ")
    );
}

#[path = "../../tests/layers_support/file_graph.rs"]
mod file_graph;

/// The file graph sees an upward import through `super::` and a child's import through a
/// `mod.rs`'s own submodule path, and resolves a group to its files.
#[test]
fn the_file_graph_sees_imports_through_super_and_groups() {
    let p = file_graph::paths(
        "use super::{lm::State, types::{Options, Link}};\nlet x = lm::f();",
        &["super", "lm"],
    );
    let joined: Vec<String> = p.iter().map(|s| s.join("::")).collect();
    assert_eq!(
        joined,
        [
            "super::lm::State",
            "super::types::Options",
            "super::types::Link",
            "lm::f"
        ]
    );
    let code =
        file_graph::code_of("use super::a; // super::b\n#[cfg(test)]\nmod tests { use super::*; }");
    assert_eq!(file_graph::paths(&code, &["super"]).len(), 1);
    // a visibility restricted to a module imports nothing from it
    let code = file_graph::code_of("pub(in crate::diagnose) fn f() -> crate::obs::Row {}");
    let joined: Vec<String> = file_graph::paths(&code, &["crate"])
        .iter()
        .map(|s| s.join("::"))
        .collect();
    assert_eq!(joined, ["crate::obs::Row"]);
}

/// No file of the core imports a file that imports it, directly or around a loop (within a
/// module: calib's files read `types.rs` and each other downwards, never their `mod.rs`).
#[test]
fn no_core_file_imports_in_a_circle() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let graph = file_graph::graph(&src);
    assert!(graph.len() >= 60, "found only {} files", graph.len());
    let calib_fit = graph
        .iter()
        .find(|(m, _)| m == "calib::fit")
        .expect("calib/fit.rs");
    assert!(
        calib_fit.1.iter().any(|d| d == "calib::types"),
        "{calib_fit:?}"
    );
    let cycles = file_graph::cycles(&graph);
    assert!(
        cycles.is_empty(),
        "core files import each other:\n{}",
        cycles.join("\n")
    );
}

/// The online tracker is a module beside `calib`, one layer above it: it starts from a
/// calibration and settles its ties with `calib::tie`, while the calibration knows nothing of
/// the tracker (a calibration that named it could not be read without it).
#[test]
fn the_online_tracker_sits_above_calib() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    assert!(
        !src.join("calib/online").exists(),
        "core/src/calib/online is back"
    );
    let modules = module_texts(&src);
    let refs = |name: &str| -> Vec<String> {
        let (_, code) = modules
            .iter()
            .find(|(m, _)| m == name)
            .unwrap_or_else(|| panic!("core/src/{name} not found"));
        crate_references(code)
    };
    assert!(
        refs("online").iter().any(|d| d == "calib"),
        "online names calib"
    );
    assert!(
        !refs("calib").iter().any(|d| d == "online"),
        "calib names the online tracker"
    );
}
