//! Layers never call upward: the node set (the crate `rpkm-nodes`, `nodes/src`) cannot name the
//! command line (the `rpkm` package, `src/`) by construction, and links none of what only the
//! command line needs (the charts, the terminal monitor, the keystore writer); the launcher
//! (`src/launch`) does not name the subcommands (`src/cli`). Errors, exit codes and file
//! readers the nodes share with the command line live in `nodes/src/error.rs` and
//! `nodes/src/input.rs`.

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
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files = Vec::new();
    for layer in ["nodes/src", "src/launch"] {
        file_graph::rust_files(&root.join(layer), &mut files);
    }
    assert!(files.len() >= 60, "found only {files:?}");
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

/// No file of the command line, the nodes' crate or the transport imports a file that imports
/// it, directly or around a loop: what two subcommands share lives in a module both call
/// (`cli/effect_stages.rs`, `cli/summary.rs`, `cli/transport_args.rs`, `cli/bag_files.rs`),
/// never in one of them; what every node is made of in `node/context.rs` and
/// `node/geometry.rs`, never in `node/mod.rs`, which runs them.
#[test]
fn no_file_of_the_nodes_or_the_transport_imports_in_a_circle() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    for (src, at_least) in [("src", 60), ("nodes/src", 50), ("nodes/transport/src", 10)] {
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
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
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

/// Whether `code` defines a factor between two units of one quantity (`MM_PER_M`,
/// `RAD_PER_MRAD`, `MS_PER_S`, ...), not a physical constant such as `N_PER_MM`.
fn unit_factor_const(code: &str) -> bool {
    const UNITS: [&str; 11] = [
        "M", "MM", "UM", "NM", "RAD", "MRAD", "URAD", "S", "MS", "US", "NS",
    ];
    let Some(rest) = code.split("const ").nth(1) else {
        return false;
    };
    let name = rest.split(':').next().unwrap_or("").trim();
    // NAME_PER_OTHER: the unit right before `_PER_` and the one after it
    match name.split_once("_PER_") {
        Some((a, b)) => {
            let a = a.rsplit('_').next().unwrap_or(a);
            UNITS.contains(&a) && UNITS.contains(&b) && code.contains("f64")
        }
        None => false,
    }
}

#[test]
fn a_unit_factor_is_told_from_a_physical_constant() {
    assert!(unit_factor_const("pub const MM_PER_M: f64 = 1000.0;"));
    assert!(unit_factor_const("const RAD_PER_MRAD: f64 = 1e-3;"));
    assert!(!unit_factor_const(
        "pub const DEFAULT_ROD_STIFFNESS_N_PER_MM: f64 = 97_700.0;"
    ));
    assert!(!unit_factor_const(
        "pub const STEEL_E_N_PER_MM2: f64 = 210_000.0;"
    ));
}

/// The unit factors (`MM_PER_M`, `UM_PER_MM`, ...) are defined once, in `core/src/units.rs`:
/// no other file of any crate or of the benches defines its own.
#[test]
fn one_module_defines_the_unit_factor() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files = Vec::new();
    for dir in CRATE_SOURCES.iter().chain(&["benches", "core/benches"]) {
        file_graph::rust_files(&root.join(dir), &mut files);
    }
    let offences: Vec<String> = files
        .iter()
        .filter(|f| !f.ends_with("core/src/units.rs"))
        .flat_map(|f| {
            let text = std::fs::read_to_string(f).expect("read source");
            text.lines()
                .enumerate()
                .filter(|(_, l)| unit_factor_const(l.split("//").next().unwrap_or("")))
                .map(|(n, l)| format!("{}:{}: {}", f.display(), n + 1, l.trim()))
                .collect::<Vec<_>>()
        })
        .collect();
    assert!(files.len() >= 200, "found only {} files", files.len());
    assert!(offences.is_empty(), "{}", offences.join("\n"));
}

/// The files that ARE the conversion, the only ones where a bare factor is written: `units.rs`
/// of the core names each factor and each conversion once for the whole workspace (the nodes'
/// `units.rs` re-exports it).
const UNIT_CONVERSIONS: [&str; 1] = ["core/src/units.rs"];

/// Where a topic's or a bag's SI meets the core's mm besides the conversions: the message
/// adapters, which may name `MM_PER_M` itself. `campaign_bag.rs` turns campaigns into
/// messages and back, `node/geometry.rs` the Parameters message into the nodes' geometry and
/// back, `nodes/src/units.rs` re-exports the conversions.
const UNIT_ADAPTERS: [&str; 3] = [
    "nodes/src/units.rs",
    "nodes/src/campaign_bag.rs",
    "nodes/src/node/geometry.rs",
];

/// A factor that is text, not a conversion: the effects file a benchmark machine hides, the
/// YAML a user writes (`dx: "-vx * 1e-3 * t / 60"`, µm/min in the effects file's own
/// expression language), which the checker, reading code, cannot tell from Rust.
const FACTORS_IN_TEXT: [&str; 1] = ["src/cli/bench/machines.rs"];

/// The code of a Rust file without its tests (a `#[cfg(test)]` module runs to the end of the
/// file here; a `tests.rs` has none) and without comments, with its line numbers.
fn non_test_code(path: &Path) -> Vec<(usize, String)> {
    if path.ends_with("tests.rs") {
        return Vec::new();
    }
    let text = std::fs::read_to_string(path).expect("read source");
    text.lines()
        .enumerate()
        .take_while(|(_, l)| l.trim() != "#[cfg(test)]")
        .map(|(n, l)| (n + 1, l.split("//").next().unwrap_or("").to_owned()))
        .collect()
}

/// A multiplication or division by a bare scale factor in `code` (spaces ignored): `* 1e3`,
/// `/ 1000.0`, `* 1e-6`, ...
fn bare_factor(code: &str) -> Option<String> {
    let code: String = code.chars().filter(|c| !c.is_whitespace()).collect();
    ["1e3", "1e-3", "1e-6", "1e6", "1000.0", "0.001"]
        .iter()
        .flat_map(|f| [format!("*{f}"), format!("/{f}")])
        .find(|pat| {
            code.match_indices(pat.as_str()).any(|(i, _)| {
                !code[i + pat.len()..].starts_with(|c: char| c.is_ascii_digit() || c == '_')
            })
        })
}

#[test]
fn the_bare_factor_finder_sees_factors_not_bounds() {
    assert_eq!(bare_factor("let x = v * 1e3;").as_deref(), Some("*1e3"));
    assert_eq!(bare_factor("um.map(|v| v *1e-6)").as_deref(), Some("*1e-6"));
    assert_eq!(bare_factor("(w / 1000.0, 1)").as_deref(), Some("/1000.0"));
    assert_eq!(bare_factor(".bound(Within(1e-3, 3600.0))"), None);
    assert_eq!(bare_factor("x * 1e30"), None);
    assert_eq!(bare_factor("x * RAD_PER_MRAD"), None);
}

/// The bare factors of the non-test code of `files` outside the allow-lists, and every
/// `MM_PER_M` outside the conversions and the message adapters.
fn unit_offences(root: &Path, files: &[std::path::PathBuf]) -> Vec<String> {
    let rel = |f: &Path| f.strip_prefix(root).unwrap_or(f).display().to_string();
    let mut offences = Vec::new();
    for f in files {
        let name = rel(f);
        if UNIT_CONVERSIONS.contains(&name.as_str()) {
            continue;
        }
        let text = std::fs::read_to_string(f).expect("read source");
        if !UNIT_ADAPTERS.contains(&name.as_str()) {
            for (n, l) in text.lines().enumerate() {
                if l.split("//").next().unwrap_or("").contains("MM_PER_M") {
                    offences.push(format!("{name}:{}: MM_PER_M: {}", n + 1, l.trim()));
                }
            }
        }
        if FACTORS_IN_TEXT.contains(&name.as_str()) {
            continue;
        }
        for (n, code) in non_test_code(f) {
            if let Some(factor) = bare_factor(&code) {
                offences.push(format!("{name}:{n}: bare {factor}: {}", code.trim()));
            }
        }
    }
    offences
}

/// Units convert at one boundary: in every crate of the workspace, a length, angle, time or
/// ppm factor is a named conversion of `core/src/units.rs` (`um_from_mm`, `m_from_mm`,
/// `rad_from_mrad`, `seconds_from_ms`, ...), never a bare one, and `MM_PER_M` appears only in
/// the conversions and the message adapters.
#[test]
fn lengths_convert_only_in_the_message_adapters() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let files = crate_files(root);
    assert!(files.len() >= 200, "found only {} files", files.len());
    for listed in UNIT_CONVERSIONS
        .iter()
        .chain(&UNIT_ADAPTERS)
        .chain(&FACTORS_IN_TEXT)
    {
        assert!(root.join(listed).is_file(), "{listed} is listed but gone");
    }
    let offences = unit_offences(root, &files);
    assert!(offences.is_empty(), "{}", offences.join("\n"));
}

/// The check sees a bare factor put back into any crate, the core's included.
#[test]
fn the_unit_check_sees_a_bare_factor_in_any_crate() {
    let dir = std::env::temp_dir().join(format!("rpkm-layers-{}", std::process::id()));
    for (krate, file) in [
        ("core/src", "a.rs"),
        ("twin/src", "b.rs"),
        ("src/cli", "c.rs"),
    ] {
        let path = dir.join(krate).join(file);
        std::fs::create_dir_all(path.parent().expect("a folder")).expect("temp folder");
        std::fs::write(&path, "fn f(mm: f64) -> f64 {\n    mm * 1e3\n}\n").expect("write");
        let offences = unit_offences(&dir, &[path]);
        assert_eq!(offences.len(), 1, "{krate}: {offences:?}");
        assert!(offences[0].contains("bare *1e3"), "{}", offences[0]);
    }
    std::fs::remove_dir_all(&dir).expect("clean up");
}

/// The crates' sources: the core, the command line, the nodes, the transport, the messages,
/// the history's store and the twin.
const CRATE_SOURCES: [&str; 7] = [
    "core/src",
    "src",
    "nodes/src",
    "nodes/transport/src",
    "msgs/src",
    "history/src",
    "twin/src",
];

/// The Rust files of every crate's sources ([`CRATE_SOURCES`]).
fn crate_files(root: &Path) -> Vec<std::path::PathBuf> {
    let mut files = Vec::new();
    for dir in CRATE_SOURCES {
        file_graph::rust_files(&root.join(dir), &mut files);
    }
    files
}

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

/// What only the command line links: the report's charts, the terminal monitor, the SROS2
/// keystore writer (OpenSSL's keys, X.509 certificates and S/MIME signatures).
const COMMAND_LINE_ONLY: [&str; 3] = ["plotters", "ratatui", "crossterm"];

/// The OpenSSL the keystore writer uses; a node reads a keystore through the transport
/// (`rpkm_transport::security`) and needs none of it.
const KEYSTORE_OPENSSL: [&str; 6] = [
    "openssl::x509",
    "openssl::pkcs7",
    "openssl::ec",
    "openssl::pkey",
    "openssl::asn1",
    "openssl::bn",
];

/// The node set links none of the command line's crates (their absence from `cargo tree -p
/// rpkm-nodes`, transitive ones included, is `.ci/run`'s check) and writes no keystore: a
/// node process stays as small as what it runs (`rpkm-node`: the next test).
#[test]
fn the_nodes_link_no_charts_monitor_or_keystore_writer() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let manifest =
        std::fs::read_to_string(root.join("nodes/Cargo.toml")).expect("nodes/Cargo.toml");
    let deps = manifest
        .split("[dependencies]")
        .nth(1)
        .and_then(|rest| rest.split("\n[").next())
        .expect("nodes/Cargo.toml has [dependencies]");
    let names: Vec<&str> = deps
        .lines()
        .map(|l| l.split(['=', ' ', '.']).next().unwrap_or("").trim())
        .filter(|n| !n.is_empty() && !n.starts_with('#'))
        .collect();
    assert!(names.contains(&"rpkm-transport"), "{names:?}");
    let linked: Vec<&&str> = COMMAND_LINE_ONLY
        .iter()
        .filter(|c| names.contains(c))
        .collect();
    assert!(linked.is_empty(), "rpkm-nodes depends on {linked:?}");
    let mut files = Vec::new();
    file_graph::rust_files(&root.join("nodes/src"), &mut files);
    let offences: Vec<String> = files
        .iter()
        .flat_map(|f| {
            let code = file_graph::code_of(&std::fs::read_to_string(f).expect("read source"));
            KEYSTORE_OPENSSL
                .iter()
                .chain(&["security::keystore", "plotters::", "ratatui::"])
                .filter(|k| code.contains(*k))
                .map(|k| format!("{}: {k}", f.display()))
                .collect::<Vec<_>>()
        })
        .collect();
    assert!(offences.is_empty(), "{}", offences.join("\n"));
}

/// Whether `needle` occurs in `bytes`.
fn contains(bytes: &[u8], needle: &str) -> bool {
    bytes.windows(needle.len()).any(|w| w == needle.as_bytes())
}

/// The node program `rpkm-node` (what `rpkm launch` starts) links the node set alone: its
/// binary holds no symbol of the charts, the terminal monitor, the keystore writer's OpenSSL
/// calls or the command line's own crate (`_ZN4rpkm`: `rpkm::report`, `rpkm::security`,
/// ...), each of which the `rpkm` binary holds; so it is the smaller file.
#[test]
fn the_node_program_links_none_of_the_command_line() {
    let node_path = env!("CARGO_BIN_EXE_rpkm-node");
    let node = std::fs::read(node_path).expect("the rpkm-node binary");
    let rpkm = std::fs::read(env!("CARGO_BIN_EXE_rpkm")).expect("the rpkm binary");
    let names = COMMAND_LINE_ONLY.iter().copied().chain([
        "X509_sign",
        "PKCS7_sign",
        "EC_KEY_generate_key",
        "_ZN4rpkm",
    ]);
    for name in names {
        assert!(
            contains(&rpkm, name),
            "rpkm links no {name}: the check is blind"
        );
        assert!(!contains(&node, name), "{node_path} links {name}");
    }
    eprintln!("rpkm {} bytes, rpkm-node {} bytes", rpkm.len(), node.len());
    assert!(node.len() < rpkm.len(), "{} >= {}", node.len(), rpkm.len());
}

/// The one place that takes the RMS of held-out errors and removes their setups' zeros: a
/// model's held-out figures ([`rpkm_core::diagnose::HeldOut`]), made once per model.
const HELD_OUT_FIGURES: &str = "core/src/diagnose/held_out/figures.rs";

/// RMS of errors that are no model's held-out figures, each with the code that takes it:
/// `Prediction::compared`, its resolution and support compare two models' errors in any
/// unit (held-out errors in σ, the rows cross-validation leaves out); the settling orders a
/// family's part sets by their errors in σ.
const OTHER_RMS: [(&str, &str); 4] = [
    (
        "core/src/diagnose/held_out/mod.rs",
        "let (rb, ra) = (calib::rms(before), calib::rms(after));",
    ),
    (
        "core/src/diagnose/held_out/mod.rs",
        "let s = calib::rms(before);",
    ),
    (
        "core/src/diagnose/held_out/mod.rs",
        "let scale = calib::rms(before) * size.sqrt();",
    ),
    (
        "core/src/diagnose/search/settle.rs",
        ".then(calib::rms(a.1.held()).total_cmp(&calib::rms(b.1.held())))",
    ),
];

/// Where a model's held-out θ is fitted, and how many times in that file: once per model
/// and held-out campaign (`rpkm calibrate`'s and the node's judge, a diagnosis's fit, the
/// current model whose figures its judge reads), never again for its floor.
const HELD_OUT_THETA_FITS: [(&str, usize); 2] = [
    ("core/src/diagnose/held_out/mod.rs", 2),
    ("core/src/diagnose/current.rs", 1),
];

/// Whether `code` takes the core's RMS (`calib::rms(`) of something named as held-out
/// errors, their zero-removed or scaled form, or their noise: a word of its argument (split
/// at every character that is not a letter or a digit) is one of those names.
fn held_out_rms(code: &str) -> bool {
    const CALL: &str = "calib::rms(";
    code.match_indices(CALL).any(|(i, _)| {
        let arg: String = code[i + CALL.len()..]
            .chars()
            .scan(1_i32, |depth, c| {
                *depth += match c {
                    '(' => 1,
                    ')' => -1,
                    _ => 0,
                };
                (*depth > 0).then_some(c)
            })
            .collect();
        arg.split(|c: char| !c.is_ascii_alphanumeric()).any(|w| {
            [
                "val", "held", "relative", "after", "before", "errors", "sigma", "scaled",
            ]
            .contains(&w)
        })
    })
}

#[test]
fn the_held_out_rms_finder_sees_each_spelling() {
    assert!(held_out_rms("rms_after_um: 1e3 * calib::rms(after),"));
    assert!(held_out_rms("um_from_mm(calib::rms(&base.fit.val_errors))"));
    assert!(held_out_rms("Ok(1e3 * calib::rms(&relative))"));
    assert!(held_out_rms("um_from_mm(calib::rms(&v.relative_sigma))"));
    assert!(held_out_rms("let r = calib::rms(&e.held.scaled);"));
    assert!(!held_out_rms(
        "um_from_mm(calib::rms(&length_values(&rows)))"
    ));
    assert!(!held_out_rms("calib::rms(&length_sigmas(&base.rows))"));
    assert!(!held_out_rms("rms(&mut before.clone())"));
    assert!(!held_out_rms("rms: cal.rms,"));
}

/// Every held-out RMS outside [`HELD_OUT_FIGURES`] and [`OTHER_RMS`], every zero removal
/// outside it (and the definition and the held-out θ's own fit), and every fit of a held-out
/// θ beyond [`HELD_OUT_THETA_FITS`], in the non-test code of `files`.
fn held_out_offences(root: &Path, files: &[std::path::PathBuf]) -> Vec<String> {
    let rel = |f: &Path| f.strip_prefix(root).unwrap_or(f).display().to_string();
    let zero_removals = [
        HELD_OUT_FIGURES,
        "core/src/obs/zero.rs",
        "core/src/diagnose/held_out/validation.rs",
    ];
    let mut offences = Vec::new();
    for f in files {
        let name = rel(f);
        if name == HELD_OUT_FIGURES {
            continue;
        }
        let mut fits = 0;
        for (n, code) in non_test_code(f) {
            let allowed = OTHER_RMS
                .iter()
                .any(|(file, line)| *file == name && code.trim() == *line);
            if held_out_rms(&code) && !allowed {
                offences.push(format!("{name}:{n}: held-out RMS: {}", code.trim()));
            }
            if code.contains("zero_removed(") && !zero_removals.contains(&name.as_str()) {
                offences.push(format!("{name}:{n}: zero removal: {}", code.trim()));
            }
            if code.contains("held_out_theta(") && !code.contains("fn held_out_theta(") {
                fits += 1;
            }
        }
        let expected = HELD_OUT_THETA_FITS
            .iter()
            .find(|(file, _)| *file == name)
            .map_or(0, |(_, k)| *k);
        if fits != expected {
            offences.push(format!(
                "{name}: {fits} fits of a held-out θ, {expected} expected"
            ));
        }
    }
    offences
}

/// One held-out evaluation: the held-out RMS, the zero removal and the floors are taken in
/// one file, the held-out θ fitted once per model; every command, node and bench reads its
/// held-out figures from there.
#[test]
fn each_held_out_figure_is_made_in_one_place() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let files = crate_files(root);
    let listed = OTHER_RMS.iter().map(|(f, _)| *f);
    for f in listed.chain([HELD_OUT_FIGURES]) {
        assert!(root.join(f).is_file(), "{f} is listed but gone");
    }
    let offences = held_out_offences(root, &files);
    assert!(offences.is_empty(), "{}", offences.join("\n"));
}

/// A field of `code` that holds a length in µm (`name_um: f64`, `Option<f64>`, `Vec<f64>`).
fn um_field(code: &str) -> bool {
    let code = code.trim_start();
    let code = code
        .strip_prefix("pub(crate) ")
        .or_else(|| code.strip_prefix("pub(super) "))
        .or_else(|| code.strip_prefix("pub "))
        .unwrap_or(code);
    code.split_once(':').is_some_and(|(name, ty)| {
        let ty = ty.trim_start();
        name.ends_with("_um")
            && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
            && ["f64", "Option<f64>", "Vec<f64>"]
                .iter()
                .any(|t| ty.starts_with(t))
    })
}

#[test]
fn the_um_field_finder_sees_fields_not_values() {
    assert!(um_field("    pub val_rms_um: Option<f64>,"));
    assert!(um_field("    rms_um: f64,"));
    assert!(um_field("    pub(crate) residual_um: Vec<f64>,"));
    assert!(!um_field("        rms_um: um_from_mm(held.errors.rms),"));
    assert!(!um_field("    pub val_rms: Option<f64>,"));
    assert!(!um_field(
        "    #[serde(rename = \"rms_um\", serialize_with = \"as_um\")]"
    ));
}

/// The core reports mm: no field of its code holds µm (a person reads µm, where the command
/// line, the nodes' words and the JSON writers write them).
#[test]
fn no_core_field_holds_micrometres() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files = Vec::new();
    file_graph::rust_files(&root.join("core/src"), &mut files);
    let offences: Vec<String> = files
        .iter()
        .flat_map(|f| {
            let name = f.strip_prefix(root).unwrap_or(f).display().to_string();
            non_test_code(f)
                .into_iter()
                .filter(|(_, code)| um_field(code))
                .map(move |(n, code)| format!("{name}:{n}: {}", code.trim()))
        })
        .collect();
    assert!(offences.is_empty(), "{}", offences.join("\n"));
}

/// What may calibrate without the calibration every command shares
/// (`calib::calibrate_command`: the effects bound at the start, the noise estimated or stated):
/// the benchmark of the raw fit itself. The core's own fits (the diagnosis's candidates, the
/// settle, the cross-validation) are the core's.
const RAW_CALIBRATIONS: [&str; 1] = ["src/cli/bench/calibration.rs"];

/// The calls of `calib::calibrate(` in the non-test code of `files` outside the core and
/// [`RAW_CALIBRATIONS`].
fn raw_calibrations(root: &Path, files: &[std::path::PathBuf]) -> Vec<String> {
    let mut offences = Vec::new();
    for f in files {
        let rel = f
            .strip_prefix(root)
            .unwrap_or(f)
            .to_string_lossy()
            .into_owned();
        if rel.starts_with("core/") || RAW_CALIBRATIONS.contains(&rel.as_str()) {
            continue;
        }
        for (n, line) in non_test_code(f) {
            if line.contains("calib::calibrate(") {
                offences.push(format!("{rel}:{n}: {}", line.trim()));
            }
        }
    }
    offences
}

/// Every command and node calibrates through the one shared calibration: `rpkm calibrate`,
/// `rpkm plan`, `rpkm bench plan` and the calibrator node read the same fit of the same
/// request. The check sees a direct call put back.
#[test]
fn every_command_calibrates_through_the_shared_calibration() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let files = crate_files(root);
    for listed in RAW_CALIBRATIONS {
        assert!(root.join(listed).is_file(), "{listed} is listed but gone");
    }
    let offences = raw_calibrations(root, &files);
    assert!(offences.is_empty(), "{}", offences.join("\n"));
    let dir = std::env::temp_dir().join(format!("rpkm-raw-cal-{}", std::process::id()));
    let put_back = dir.join("src/cli/plan/put_back.rs");
    std::fs::create_dir_all(put_back.parent().expect("a folder")).expect("temp folder");
    std::fs::write(
        &put_back,
        "fn f() {\n    let (cal, _) = calib::calibrate(&calib::Request::new(c, &s, &o))?;\n}\n",
    )
    .expect("write");
    let seen = raw_calibrations(&dir, &[put_back]);
    std::fs::remove_dir_all(&dir).expect("clean up");
    assert_eq!(seen.len(), 1, "{seen:?}");
}
