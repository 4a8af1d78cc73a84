//! What a user reads is in the repository and agrees with the code (issue 50). Every relative
//! link of README.md and docs/*.md resolves to a file of the repository (an anchor to a
//! heading of it), every repository path a page names in backticks exists, and no page sends
//! the reader outside (`../shared`). docs/campaign-format.md's tables are `rpkm_core`'s: the
//! 29 parameters (index, name, nominal value, unit, subsystem, model 24), which carrier sits on
//! which guide with which rods, the check values (the core's igm), the instruments' rated
//! noise (the core's defaults), and its example campaign reads with the core's reader and is
//! the shipped demo's rows it says it is. docs/interfaces.md's definition blocks are the files
//! of msgs/ byte for byte; `RPKM_BLESS=1 cargo test --test it docs_in_repo` copies them in.

use std::path::{Path, PathBuf};

use rpkm_core::campaign::{Campaign, Instrument};
use rpkm_core::geometry::{fgm, igm};
use rpkm_core::noise::NoiseModel;
use rpkm_core::params::{self, Guide, Model, Params, N_PARAMS, RODS};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// README.md and every docs/*.md.
fn pages() -> Vec<PathBuf> {
    let mut pages = vec![root().join("README.md")];
    for entry in std::fs::read_dir(root().join("docs")).expect("docs/") {
        let path = entry.expect("a docs/ entry").path();
        if path.extension().is_some_and(|e| e == "md") {
            pages.push(path);
        }
    }
    pages.sort();
    pages
}

/// The lines of a page outside its fenced code blocks, with their 1-based numbers.
fn prose(text: &str) -> Vec<(usize, &str)> {
    let mut fenced = false;
    let mut lines = Vec::new();
    for (n, line) in text.lines().enumerate() {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
        } else if !fenced {
            lines.push((n + 1, line));
        }
    }
    lines
}

/// A heading's anchor as GitHub makes it: lower case, punctuation dropped, spaces to `-`.
fn anchor(heading: &str) -> String {
    heading
        .trim_start_matches('#')
        .trim()
        .to_lowercase()
        .chars()
        .filter(|c| c.is_alphanumeric() || matches!(c, ' ' | '-' | '_'))
        .map(|c| if c == ' ' { '-' } else { c })
        .collect()
}

/// The targets of a line's `[text](target)` links (images too), without a title.
fn link_targets(line: &str) -> Vec<&str> {
    line.match_indices("](")
        .filter_map(|(at, _)| {
            let rest = &line[at + 2..];
            rest.find(')')
                .map(|end| rest[..end].split_whitespace().next().unwrap_or(""))
        })
        .collect()
}

/// Checks one link of `page`; `Err` says why it does not resolve.
fn resolve(page: &Path, target: &str) -> Result<(), String> {
    let (file, fragment) = target.split_once('#').unwrap_or((target, ""));
    let path = if file.is_empty() {
        page.to_path_buf()
    } else {
        page.parent().expect("a page's folder").join(file)
    };
    let Ok(real) = path.canonicalize() else {
        return Err(format!("{} does not exist", path.display()));
    };
    if !real.starts_with(root().canonicalize().expect("the repository")) {
        return Err(format!("{} is outside the repository", real.display()));
    }
    let is_page = real.extension().is_some_and(|e| e == "md");
    if fragment.is_empty() || !is_page {
        return Ok(());
    }
    let text = read(&real);
    let found = prose(&text)
        .iter()
        .any(|(_, l)| l.starts_with('#') && anchor(l) == fragment);
    if found {
        Ok(())
    } else {
        Err(format!("{} has no heading #{fragment}", real.display()))
    }
}

#[test]
fn every_link_of_the_readme_and_the_docs_resolves_inside_the_repository() {
    let (mut links, mut broken) = (0, Vec::new());
    for page in pages() {
        let text = read(&page);
        assert!(
            !text.contains("../shared"),
            "{} sends the reader to ../shared, outside the repository",
            page.display()
        );
        for (n, line) in prose(&text) {
            for target in link_targets(line) {
                if ["http://", "https://", "mailto:"]
                    .iter()
                    .any(|s| target.starts_with(s))
                {
                    continue;
                }
                links += 1;
                if let Err(why) = resolve(&page, target) {
                    broken.push(format!("{}:{n}: ({target}) {why}", page.display()));
                }
            }
        }
    }
    assert!(
        broken.is_empty(),
        "links that do not resolve:\n{}",
        broken.join("\n")
    );
    assert!(
        links >= 8,
        "only {links} relative links found: is the parser blind?"
    );
}

/// The repository's top folders: a backticked path starting with one names a file of ours.
const TOP: [&str; 12] = [
    "bags",
    "benches",
    "core",
    "docs",
    "history",
    "launch_scripts",
    "msgs",
    "nodes",
    "src",
    "tests",
    "twin",
    ".ci",
];
/// Paths a page asks the reader to create (docs/effects.md's walk-through of a new effect).
const TO_BE_WRITTEN: [&str; 1] = ["core/src/effects/cyclic_error.rs"];

/// The code spans of a line that are repository paths (`tests/it/x.rs`, `core/src/diagnose/`).
fn repository_paths(line: &str) -> Vec<&str> {
    line.split('`')
        .skip(1)
        .step_by(2)
        .filter(|span| {
            span.chars()
                .all(|c| c.is_ascii_alphanumeric() || "_.-/".contains(c))
                && span
                    .split_once('/')
                    .is_some_and(|(top, rest)| TOP.contains(&top) && !rest.is_empty())
        })
        .collect()
}

#[test]
fn every_repository_path_the_readme_and_the_docs_name_exists() {
    let (mut named, mut missing) = (0, Vec::new());
    for page in pages() {
        let text = read(&page);
        for (n, line) in prose(&text) {
            for path in repository_paths(line) {
                named += 1;
                if !root().join(path).exists() && !TO_BE_WRITTEN.contains(&path) {
                    missing.push(format!("{}:{n}: {path}", page.display()));
                }
            }
        }
    }
    assert!(
        missing.is_empty(),
        "paths that do not exist:\n{}",
        missing.join("\n")
    );
    assert!(
        named >= 50,
        "only {named} paths found: is the parser blind?"
    );
}

fn format_page() -> String {
    read(&root().join("docs/campaign-format.md"))
}

/// The section of `text` under the level-2 heading that starts with `title`.
fn section<'a>(text: &'a str, title: &str) -> &'a str {
    let start = text
        .find(&format!("\n## {title}"))
        .unwrap_or_else(|| panic!("no section '{title}'"));
    let body = &text[start + 1..];
    let end = body[3..].find("\n## ").map_or(body.len(), |e| e + 3);
    &body[..end]
}

/// The data rows of the tables of `text`, cells trimmed, backticks dropped.
fn table_rows(text: &str) -> Vec<Vec<String>> {
    text.lines()
        .filter(|l| l.starts_with('|') && !l.starts_with("|---"))
        .map(|l| {
            l.trim_matches('|')
                .split('|')
                .map(|c| c.trim().trim_matches('`').to_owned())
                .collect()
        })
        .collect()
}

#[test]
fn the_parameter_table_is_the_codes() {
    let page = format_page();
    let rows: Vec<Vec<String>> = table_rows(section(&page, "The 29 parameters"))
        .into_iter()
        .filter(|r| r[0].parse::<usize>().is_ok())
        .collect();
    assert_eq!(rows.len(), N_PARAMS, "{rows:?}");
    let nominal = Params::nominal();
    for (i, row) in rows.iter().enumerate() {
        let what = format!("row {}: {row:?}", i + 1);
        assert_eq!(row[0], params::thesis_index(i).to_string(), "{what}");
        assert_eq!(row[1], params::NAMES[i], "{what}");
        let value: f64 = row[2].parse().unwrap_or_else(|e| panic!("{what}: {e}"));
        assert!(
            value.to_bits() == nominal[i].to_bits(),
            "{what}: nominal {value}, the code's {}",
            nominal[i]
        );
        let unit = match params::unit(i) {
            params::Unit::Mm => "mm",
            params::Unit::Rad => "rad",
        };
        assert_eq!(row[3], unit, "{what}");
        // the thesis's indexes 1-17 are the non-redundant subsystem (q1, q4, the holder)
        let subsystem = if i < params::L2 {
            "non-redundant"
        } else {
            "redundant"
        };
        assert_eq!(row[5], subsystem, "{what}");
        let in_24 = if Model::M24.has_param(i) { "yes" } else { "no" };
        assert_eq!(row[6], in_24, "{what}: model 24");
    }
}

#[test]
fn the_carrier_table_is_the_codes() {
    let page = format_page();
    let rows: Vec<Vec<String>> = table_rows(section(&page, "The machine"))
        .into_iter()
        .filter(|r| r[0].contains("(q"))
        .collect();
    assert_eq!(rows.len(), 4, "{rows:?}");
    let nominal = Params::nominal();
    for (a, row) in rows.iter().enumerate() {
        assert_eq!(row[0], format!("{} (q{})", a + 1, a + 1), "{row:?}");
        let rods: Vec<_> = RODS.iter().filter(|r| r.actuator == a).collect();
        let guide = rods[0].guide;
        assert!(rods.iter().all(|r| r.guide == guide), "{row:?}");
        let (number, d) = match guide {
            Guide::G1 => (1, nominal[params::D1]),
            Guide::G2 => (2, nominal[params::D2]),
        };
        let side = if d < 0.0 { "left" } else { "right" };
        assert_eq!(row[1], format!("{number} ({side})"), "{row:?}: guide");
        let numbers: Vec<String> = rods.iter().map(|r| r.number.to_string()).collect();
        assert_eq!(row[2], numbers.join(" and "), "{row:?}: rods");
    }
}

#[test]
fn the_check_values_and_the_rated_noise_are_the_codes() {
    let page = format_page();
    let text = page.split_whitespace().collect::<Vec<_>>().join(" ");
    let check = text
        .split("q = (")
        .nth(1)
        .and_then(|t| t.split(')').next())
        .expect("the check values");
    let q: Vec<f64> = check
        .split(", ")
        .map(|v| v.parse().expect("a number"))
        .collect();
    for model in [Model::M24, Model::M29] {
        let s = igm(&Params::nominal(), model, 0.0, 1700.0).expect("igm");
        for (k, want) in q.iter().enumerate() {
            assert!(
                (s.q()[k] - want).abs() < 5e-5,
                "{model} q{}: {}",
                k + 1,
                s.q()[k]
            );
        }
    }
    let n = NoiseModel::default();
    let um = |mm: f64| format!("{}", 1e3 * mm);
    let row = |instrument: &str| {
        table_rows(section(&page, "Instruments and setups"))
            .into_iter()
            .find(|r| r[0] == instrument)
            .unwrap_or_else(|| panic!("no row {instrument}"))
    };
    let lt = format!(
        "about {} µm along the beam, {} µm + {} µm/m across",
        um(n.lt_along_mm),
        um(n.lt_across_mm),
        um(n.lt_across_per_m_mm)
    );
    assert_eq!(row("lt")[4], lt);
    for (instrument, mm) in [("kgm", n.kgm_mm), ("dbb", n.dbb_mm), ("li_x", n.li_mm)] {
        assert_eq!(row(instrument)[4], format!("about {} µm", um(mm)));
    }
    assert_eq!(row("li_y")[4], format!("about {} µm", um(n.li_mm)));
    let psi = format!("about {} µrad", 1e6 * n.psi_rad);
    assert_eq!(row("li_psi")[4], psi);
    let encoder = format!("rpkm assumes {} µm", um(n.encoder_mm));
    assert!(text.contains(&encoder), "{encoder}");
}

/// The example block of docs/campaign-format.md.
fn example(page: &str) -> &str {
    let start = page.find("```csv\n").expect("the example") + 7;
    let len = page[start..].find("```").expect("the example's end");
    &page[start..start + len]
}

#[test]
fn the_example_campaign_reads_and_is_the_demos() {
    let page = format_page();
    let example = example(&page);
    let c = Campaign::parse(example, "docs/campaign-format.md").unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(c.poses_of(Instrument::Lt).count(), 3);
    assert_eq!(c.poses_of(Instrument::SelfCal).count(), 2);
    assert!(c.covariate("temp_machine").is_some());
    // the words under it: zeroed at (0, 1700), the second reading near (-150, 700)
    let at = |k: usize| {
        let q = c.poses[k].q;
        fgm(&Params::nominal(), Model::M29, q[0], q[3]).expect("fgm")
    };
    let (zero, second) = (at(0), at(1));
    assert!(zero.x().abs() < 1.0 && (zero.y() - 1700.0).abs() < 1.0);
    assert!((second.x() + 150.0).abs() < 1.0 && (second.y() - 700.0).abs() < 1.0);
    // the shipped demo's rows, rounded
    let demo = read(&root().join("bags/demo/campaign.csv"));
    let fields = |l: &str| l.split(',').map(str::to_owned).collect::<Vec<_>>();
    for line in example.lines().skip(2) {
        let ours = fields(line);
        let theirs = demo
            .lines()
            .map(fields)
            .find(|f| f.get(..2) == ours.get(..2))
            .unwrap_or_else(|| panic!("not a demo row: {line}"));
        for (a, b) in ours.iter().zip(&theirs) {
            match (a.parse::<f64>(), b.parse::<f64>()) {
                (Ok(a), Ok(b)) => assert!((a - b).abs() < 5.1e-4, "{line}: {a} vs {b}"),
                _ => assert_eq!(a, b, "{line}"),
            }
        }
    }
}

/// The definition files of msgs/ (`msg/`, `srv/`, `action/`), as paths from the root.
fn definitions() -> Vec<String> {
    let mut files = Vec::new();
    for folder in ["msg", "srv", "action"] {
        for entry in std::fs::read_dir(root().join("msgs").join(folder)).expect("msgs/") {
            let name = entry.expect("an entry").file_name();
            let name = name.to_str().expect("a UTF-8 name");
            if name.ends_with(&format!(".{folder}")) {
                files.push(format!("msgs/{folder}/{name}"));
            }
        }
    }
    files.sort();
    files
}

/// Where the block under the heading `` ### `PATH` `` lies in `page` (byte range).
fn block(page: &str, path: &str) -> Option<std::ops::Range<usize>> {
    let heading = page.find(&format!("\n### `{path}`\n"))?;
    let open = heading + page[heading..].find("\n```\n")? + 5;
    let len = page[open..].find("\n```\n")? + 1;
    Some(open..open + len)
}

#[test]
fn the_interface_definitions_are_the_files_of_msgs() {
    let page_path = root().join("docs/interfaces.md");
    let mut page = read(&page_path);
    let files = definitions();
    assert!(files.len() >= 11, "{files:?}");
    let headings = page.matches("\n### `msgs/").count();
    assert_eq!(
        headings,
        files.len(),
        "a heading per file of msgs/: {files:?}"
    );
    let bless = std::env::var_os("RPKM_BLESS").is_some();
    let mut differ = Vec::new();
    for path in &files {
        let want = read(&root().join(path));
        let at = block(&page, path).unwrap_or_else(|| panic!("docs/interfaces.md has no {path}"));
        if page[at.clone()] != want {
            differ.push(path.clone());
            page.replace_range(at, &want);
        }
    }
    if bless {
        std::fs::write(&page_path, &page).expect("write docs/interfaces.md");
        return;
    }
    assert!(
        differ.is_empty(),
        "docs/interfaces.md differs from {differ:?}: RPKM_BLESS=1 cargo test --test it \
         docs_in_repo copies the files in"
    );
}

/// The fields (`TYPE NAME`) and constants (`NAME=VALUE`) of one part of a definition.
fn declarations(part: &str) -> (Vec<String>, Vec<String>) {
    let lines = part
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'));
    let (constants, fields): (Vec<&str>, Vec<&str>) = lines.partition(|l| l.contains('='));
    // a constant is `TYPE NAME=VALUE` in the file, `NAME=VALUE` in the words
    let constants = constants
        .iter()
        .filter_map(|l| l.split_whitespace().last())
        .map(str::to_owned)
        .collect();
    (fields.into_iter().map(str::to_owned).collect(), constants)
}

/// The backticked declarations of one numbered item of the page's words on the action.
fn declarations_in_words(item: &str) -> (Vec<String>, Vec<String>) {
    let spans: Vec<&str> = item.split('`').skip(1).step_by(2).collect();
    let fields = spans.iter().filter(|s| s.contains(' ') && !s.contains('='));
    let constants = spans.iter().filter(|s| s.contains('='));
    (
        fields.map(|s| (*s).to_owned()).collect(),
        constants.map(|s| (*s).to_owned()).collect(),
    )
}

#[test]
fn the_calibrate_layout_in_words_is_the_actions() {
    let page = read(&root().join("docs/interfaces.md"));
    let action = read(&root().join("msgs/action/Calibrate.action"));
    let parts: Vec<&str> = action.split("\n---\n").collect();
    assert_eq!(parts.len(), 3, "goal, result, feedback");
    let words = section(&page, "The action");
    for (k, (part, name)) in parts.iter().zip(["Goal", "Result", "Feedback"]).enumerate() {
        let start = words
            .find(&format!("{}. **{name}**", k + 1))
            .unwrap_or_else(|| panic!("no item {name}"));
        let item = &words[start..];
        let next = item.find(&format!("\n{}. **", k + 2));
        let end = [item.find("\n\n"), next]
            .into_iter()
            .flatten()
            .min()
            .unwrap_or(item.len());
        let item = &item[..end];
        let in_words = declarations_in_words(item);
        assert_eq!(
            in_words,
            declarations(part),
            "{name}: the words against the file"
        );
        assert!(!in_words.0.is_empty(), "{name}: no fields found");
    }
}
