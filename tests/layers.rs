//! Layers never call upward: the nodes and the launcher (`nodes/src/node`, `nodes/src/launch`)
//! do not name the command line (`nodes/src/cli`). Errors, exit codes and file readers they
//! share with it live in `nodes/src/error.rs` and `nodes/src/input.rs`.

use std::path::Path;

/// The places in `text` that name the command-line module from below it.
fn upward_references(text: &str) -> Vec<(usize, String)> {
    let mut found = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let code = line.split("//").next().unwrap_or("");
        let names_cli = code.contains("crate::cli")
            || code.contains("rpkm::cli")
            || code.contains("super::super::cli")
            || (code.contains("crate::{")
                && code
                    .split(|c: char| !c.is_alphanumeric() && c != '_')
                    .any(|w| w == "cli"));
        if names_cli {
            found.push((n + 1, line.trim().to_owned()));
        }
    }
    found
}

#[test]
fn the_detector_sees_each_spelling() {
    assert_eq!(upward_references("use crate::cli::bad_input;").len(), 1);
    assert_eq!(
        upward_references("    crate::cli::read_params(p)?").len(),
        1
    );
    assert_eq!(upward_references("use crate::{cli, node};").len(), 1);
    assert!(upward_references("use crate::error::bad_input; // not crate::cli").is_empty());
    assert!(upward_references("use crate::{client, node};").is_empty());
}

#[test]
fn nodes_and_launch_never_name_the_cli() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("nodes/src");
    let mut files = Vec::new();
    for layer in ["node", "launch"] {
        file_graph::rust_files(&root.join(layer), &mut files);
    }
    assert!(files.len() >= 8, "found only {files:?}");
    let mut offences = Vec::new();
    for file in &files {
        let text = std::fs::read_to_string(file).expect("read source");
        for (line, code) in upward_references(&text) {
            offences.push(format!("{}:{line}: {code}", file.display()));
        }
    }
    assert!(
        offences.is_empty(),
        "the nodes call up into the command line:\n{}",
        offences.join("\n")
    );
}

#[path = "layers_support/file_graph.rs"]
mod file_graph;

/// No file of the nodes crate or of the transport imports a file that imports it, directly or
/// around a loop: what two subcommands share lives in a module both call
/// (`cli/effect_stages.rs`, `cli/summary.rs`, `cli/transport_args.rs`, `cli/bag_files.rs`),
/// never in one of them; what every node is made of in `node/context.rs` and
/// `node/geometry.rs`, never in `node/mod.rs`, which runs them.
#[test]
fn no_file_of_the_nodes_or_the_transport_imports_in_a_circle() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    for (src, at_least) in [("nodes/src", 60), ("nodes/transport/src", 10)] {
        let graph = file_graph::graph(&root.join(src));
        assert!(graph.len() >= at_least, "{src}: only {} files", graph.len());
        let cycles = file_graph::cycles(&graph);
        assert!(
            cycles.is_empty(),
            "{src}: files import each other:\n{}",
            cycles.join("\n")
        );
    }
}

/// No subcommand of the command line imports another (each is one file or folder of `cli/`
/// with a `run`; what they share is a module without one).
#[test]
fn no_subcommand_imports_another() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("nodes/src");
    let graph = file_graph::graph(&root);
    let files = file_graph::crate_files(&root);
    let subcommand = |m: &str| {
        m.strip_prefix("cli::")
            .map(|rest| rest.split("::").next().unwrap_or(rest))
            .filter(|top| {
                let file = files.get(&format!("cli::{top}"));
                file.is_some_and(|f| {
                    std::fs::read_to_string(f).is_ok_and(|t| t.contains("pub fn run("))
                })
            })
            .map(str::to_owned)
    };
    let mut offences = Vec::new();
    for (module, deps) in &graph {
        let Some(from) = subcommand(module) else {
            continue;
        };
        for d in deps {
            if subcommand(d).is_some_and(|to| to != from) {
                offences.push(format!("{module} -> {d}"));
            }
        }
    }
    assert!(offences.is_empty(), "{}", offences.join("\n"));
}

/// The millimetre-per-metre factor between the core and the topics is defined once, in
/// `nodes/src/units.rs`: no other file of the nodes crate or the transport defines its own.
#[test]
fn one_module_defines_the_unit_factor() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files = Vec::new();
    file_graph::rust_files(&root.join("nodes"), &mut files);
    let offences: Vec<String> = files
        .iter()
        .filter(|f| !f.ends_with("nodes/src/units.rs"))
        .flat_map(|f| {
            let text = std::fs::read_to_string(f).expect("read source");
            text.lines()
                .enumerate()
                .filter(|(_, l)| {
                    let code = l.split("//").next().unwrap_or("");
                    code.contains("const ") && code.contains("_PER_M") && code.contains("f64 =")
                })
                .map(|(n, l)| format!("{}:{}: {}", f.display(), n + 1, l.trim()))
                .collect::<Vec<_>>()
        })
        .collect();
    assert!(files.len() >= 80, "found only {} files", files.len());
    assert!(offences.is_empty(), "{}", offences.join("\n"));
}

/// The crates' sources: the core, the nodes and the command line, the transport, the messages,
/// the history's store and the twin.
const CRATE_SOURCES: [&str; 6] = [
    "core/src",
    "nodes/src",
    "nodes/transport/src",
    "msgs/src",
    "history/src",
    "twin/src",
];

/// The public type names (`pub struct`, `pub enum`, `pub type`, `pub trait`) a file defines.
fn public_type_names(text: &str) -> Vec<String> {
    text.lines()
        .filter_map(|line| {
            let code = line.split("//").next().unwrap_or("").trim_start();
            let rest = ["pub struct ", "pub enum ", "pub type ", "pub trait "]
                .iter()
                .find_map(|kw| code.strip_prefix(kw))?;
            let name: String = rest
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_')
                .collect();
            (!name.is_empty()).then_some(name)
        })
        .collect()
}

#[test]
fn the_type_name_finder_sees_each_kind() {
    let text = "pub struct A {\npub(crate) struct B;\n    pub enum C<'a> {\n// pub type D = u8;\n\
                pub type E = f64;\npub trait F: Sized {";
    assert_eq!(public_type_names(text), ["A", "C", "E", "F"]);
}

/// One name per type across the workspace: a reader who meets `Outcome` or `Spec` knows which
/// one it is without looking at the imports. A ROS message keeps its `.msg` name
/// (`rpkm_msgs::Diagnosis`, `Pose`, `Point`); what the core or the command line holds beside it
/// takes a name of its own (`ModelDiagnosis`, `MeasuredPose`, `ResidualPoint`).
#[test]
fn no_public_type_name_is_defined_twice() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut defined = std::collections::BTreeMap::<String, Vec<String>>::new();
    for src in CRATE_SOURCES {
        let mut files = Vec::new();
        file_graph::rust_files(&root.join(src), &mut files);
        for f in files {
            let text = std::fs::read_to_string(&f).expect("read source");
            for name in public_type_names(&text) {
                let at = f.strip_prefix(root).unwrap_or(&f).display().to_string();
                defined.entry(name).or_default().push(at);
            }
        }
    }
    assert!(defined.len() > 300, "found only {} names", defined.len());
    let twice: Vec<String> = defined
        .iter()
        .filter(|(_, at)| at.len() > 1)
        .map(|(name, at)| format!("{name}: {}", at.join(", ")))
        .collect();
    assert!(twice.is_empty(), "defined twice:\n{}", twice.join("\n"));
}

/// Source files above this, inline tests included, hold more than one job.
const MAX_FILE_LINES: usize = 800;

/// No source file over 800 lines: a file that long does several jobs, and becomes a folder
/// whose files are its jobs.
#[test]
fn no_source_file_is_over_800_lines() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut long = Vec::new();
    for dir in CRATE_SOURCES.iter().chain(&["tests", "core/tests"]) {
        let mut files = Vec::new();
        file_graph::rust_files(&root.join(dir), &mut files);
        for f in files {
            let lines = std::fs::read_to_string(&f)
                .expect("read source")
                .lines()
                .count();
            let at = f.strip_prefix(root).unwrap_or(&f).display().to_string();
            if lines > MAX_FILE_LINES {
                long.push(format!("{at}: {lines} lines"));
            }
        }
    }
    assert!(long.is_empty(), "{}", long.join("\n"));
}
