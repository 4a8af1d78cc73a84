//! The Foxglove layout (`launch_scripts/foxglove-layout.json`) against the message
//! definitions: every message path a panel names (Plot series and x axes, State Transitions,
//! Indicator, Raw Messages, Diagnostics) must be a topic rpkm publishes and a chain of fields
//! that exists in `msgs/msg/*.msg` (and in the standard definitions rpkm ships for
//! /diagnostics), with array indices inside fixed sizes and filters on existing fields. A
//! layout naming a field that does not exist fails. The layout's tree must place every panel
//! it configures, and the panels must show what `rpkm monitor` shows.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use rpkm_msgs::RosMessage;
use serde_json::Value;

/// One field of a message: its type (package-qualified for messages) and array size.
#[derive(Debug, Clone)]
struct Field {
    ty: String,
    #[expect(
        clippy::option_option,
        reason = "the .msg grammar's three cases: no array, unbounded `[]`, fixed `[n]`"
    )]
    array: Option<Option<usize>>,
}

type Types = BTreeMap<String, BTreeMap<String, Field>>;

const PRIMITIVES: [&str; 16] = [
    "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16", "int32",
    "uint32", "int64", "uint64", "string", "wstring", "octet",
];

/// Fields of one `.msg` text of package `pkg` (constants and comments skipped).
fn parse_msg(text: &str, pkg: &str) -> BTreeMap<String, Field> {
    let mut fields = BTreeMap::new();
    for line in text.lines() {
        let code = line.split('#').next().unwrap_or("").trim();
        let mut words = code.split_whitespace();
        let (Some(ty), Some(name)) = (words.next(), words.next()) else {
            continue;
        };
        if name.contains('=') || words.next().is_some_and(|w| w.starts_with('=')) {
            continue; // a constant
        }
        let (base, array) = match ty.split_once('[') {
            None => (ty, None),
            Some((b, rest)) => {
                let n = rest.trim_end_matches(']');
                (
                    b,
                    Some(n.parse::<usize>().ok().filter(|_| !n.starts_with("<="))),
                )
            }
        };
        let ty = if PRIMITIVES.contains(&base) || base.contains('/') {
            base.replace("/msg/", "/")
        } else {
            format!("{pkg}/{base}")
        };
        fields.insert(name.to_owned(), Field { ty, array });
    }
    fields
}

/// Every type: rpkm's from `msgs/msg/*.msg`, the standard ones (diagnostic_msgs,
/// std_msgs, builtin_interfaces) from the definitions rpkm writes into bags.
fn types(root: &Path) -> Types {
    let mut out = Types::new();
    let dir = root.join("msgs/msg");
    for entry in std::fs::read_dir(&dir).expect("msgs/msg") {
        let path = entry.expect("entry").path();
        if path.extension().is_some_and(|e| e == "msg") {
            let name = path
                .file_stem()
                .expect("stem")
                .to_string_lossy()
                .into_owned();
            let text = std::fs::read_to_string(&path).expect("read .msg");
            out.insert(format!("rpkm_msgs/{name}"), parse_msg(&text, "rpkm_msgs"));
        }
    }
    for definition in [
        rpkm_msgs::DiagnosticArray::definition(),
        rpkm_msgs::ActuatorState::definition(),
    ] {
        for section in definition.split("\nMSG: ").skip(1) {
            let (name, text) = section.split_once('\n').expect("MSG: line");
            let name = name.trim().replace("/msg/", "/");
            let pkg = name.split('/').next().expect("package").to_owned();
            let text = text.split("\n====").next().unwrap_or(text);
            out.entry(name).or_insert_with(|| parse_msg(text, &pkg));
        }
    }
    let top = parse_msg(
        rpkm_msgs::DiagnosticArray::definition()
            .split("\n====")
            .next()
            .expect("top"),
        "diagnostic_msgs",
    );
    out.insert("diagnostic_msgs/DiagnosticArray".into(), top);
    out
}

/// Splits `a.b[0]{k=="v.w"}.c` into segments at the dots outside brackets and quotes.
fn segments(path: &str) -> Vec<String> {
    let (mut out, mut cur, mut depth, mut quoted) = (Vec::new(), String::new(), 0, false);
    for c in path.chars() {
        match c {
            '"' => quoted = !quoted,
            '[' | '{' if !quoted => depth += 1,
            ']' | '}' if !quoted => depth -= 1,
            '.' if !quoted && depth == 0 => {
                out.push(std::mem::take(&mut cur));
                continue;
            }
            _ => {}
        }
        cur.push(c);
    }
    out.push(cur);
    out
}

/// Checks one Foxglove message path; the error says which part does not exist.
fn check_path(path: &str, types: &Types) -> Result<(), String> {
    let mut segs = segments(path);
    let topic = segs.remove(0);
    let type_name = rpkm_nodes::topics::type_name(&topic)
        .ok_or_else(|| format!("{path}: topic {topic:?} is not an rpkm topic"))?
        .replace("/msg/", "/");
    let mut ty = type_name;
    for seg in segs {
        let name_end = seg.find(['[', '{']).unwrap_or(seg.len());
        let (name, mut rest) = seg.split_at(name_end);
        let fields = types
            .get(&ty)
            .ok_or_else(|| format!("{path}: {ty} has no fields (at {name:?})"))?;
        let field = fields
            .get(name)
            .ok_or_else(|| format!("{path}: {ty} has no field {name:?}"))?;
        if let Some(index) = rest.strip_prefix('[') {
            let (inside, after) = index.split_once(']').ok_or(format!("{path}: unclosed ["))?;
            let size = field
                .array
                .ok_or_else(|| format!("{path}: {ty}.{name} is not an array"))?;
            if inside != ":" {
                let i: usize = inside
                    .parse()
                    .map_err(|_| format!("{path}: index {inside:?} is not a number"))?;
                if size.is_some_and(|n| i >= n) {
                    return Err(format!("{path}: index {i} outside {ty}.{name}[{size:?}]"));
                }
            }
            rest = after;
        } else if field.array.is_some() && !rest.is_empty() {
            return Err(format!("{path}: filter on the array {name:?} without [:]"));
        }
        ty = field.ty.clone();
        while let Some(filter) = rest.strip_prefix('{') {
            let (inside, after) = filter
                .split_once('}')
                .ok_or(format!("{path}: unclosed {{"))?;
            let key = inside.split("==").next().unwrap_or("").trim();
            let element = types.get(&ty).ok_or(format!("{path}: filter on {ty}"))?;
            if !element.contains_key(key) {
                return Err(format!("{path}: filter field {key:?} is not in {ty}"));
            }
            rest = after;
        }
        if !rest.is_empty() {
            return Err(format!("{path}: cannot read {rest:?}"));
        }
    }
    Ok(())
}

/// Every message path of a layout: the values of the keys panels use for them.
fn message_paths(v: &Value, out: &mut Vec<String>) {
    match v {
        Value::Object(m) => {
            for (k, v) in m {
                match (k.as_str(), v) {
                    ("value" | "path" | "topicPath" | "topicToRender", Value::String(s))
                        if !s.is_empty() =>
                    {
                        out.push(s.clone());
                    }
                    _ => message_paths(v, out),
                }
            }
        }
        Value::Array(a) => a.iter().for_each(|v| message_paths(v, out)),
        _ => {}
    }
}

fn layout_errors(layout: &Value, types: &Types) -> Vec<String> {
    let mut paths = Vec::new();
    message_paths(&layout["configById"], &mut paths);
    let mut errors: Vec<String> = paths
        .iter()
        .filter_map(|p| check_path(p, types).err())
        .collect();
    if paths.is_empty() {
        errors.push("no message path at all".into());
    }
    // Every configured panel is placed in the tree, and the tree names no unknown panel.
    #[expect(
        clippy::items_after_statements,
        reason = "the walk belongs to this check only"
    )]
    fn leaves(v: &Value, out: &mut BTreeSet<String>) {
        match v {
            Value::String(s) => {
                out.insert(s.clone());
            }
            Value::Object(m) => {
                for k in ["first", "second"] {
                    if let Some(c) = m.get(k) {
                        leaves(c, out);
                    }
                }
            }
            _ => {}
        }
    }
    let mut placed = BTreeSet::new();
    leaves(&layout["layout"], &mut placed);
    let configured: BTreeSet<String> = layout["configById"]
        .as_object()
        .map(|m| m.keys().cloned().collect())
        .unwrap_or_default();
    for id in placed.symmetric_difference(&configured) {
        errors.push(format!(
            "panel {id:?} configured but not placed, or placed but not configured"
        ));
    }
    errors
}

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn shipped() -> Value {
    let text = std::fs::read_to_string(root().join("launch_scripts/foxglove-layout.json"))
        .expect("launch_scripts/foxglove-layout.json");
    serde_json::from_str(&text).expect("the layout is JSON")
}

#[test]
fn every_path_of_the_layout_exists_in_the_message_definitions() {
    let types = types(root());
    assert!(types.contains_key("rpkm_msgs/PreloadStatus"));
    assert!(
        types.contains_key("diagnostic_msgs/DiagnosticStatus"),
        "{:?}",
        types.keys()
    );
    let layout = shipped();
    let errors = layout_errors(&layout, &types);
    assert!(errors.is_empty(), "{}", errors.join("\n"));
}

#[test]
fn the_layout_shows_currents_levels_and_the_tcp_pose() {
    let layout = shipped();
    let mut paths = Vec::new();
    message_paths(&layout["configById"], &mut paths);
    for drive in 0..4 {
        for field in ["measured_current", "predicted_current", "deviation"] {
            let p = format!("/rpkm/preload_status.{field}[{drive}]");
            assert!(paths.contains(&p), "no panel plots {p}");
        }
    }
    for p in [
        "/rpkm/preload_status.level",
        "/rpkm/preload_status.dq2",
        "/rpkm/preload_status.dq3",
        "/rpkm/tcp_estimate.x",
        "/rpkm/tcp_estimate.y",
        "/rpkm/tcp_estimate.psi",
        "/rpkm/tcp_estimate.outcome",
        "/diagnostics",
        "/rpkm/parameters",
        "/rpkm/diagnosis",
    ] {
        assert!(paths.iter().any(|x| x == p), "no panel shows {p}");
    }
    let plots = layout["configById"]
        .as_object()
        .expect("configById")
        .keys()
        .filter(|k| k.starts_with("Plot!"))
        .count();
    assert!(plots >= 4, "{plots} Plot panels");
}

#[test]
fn a_layout_naming_a_missing_field_fails() {
    let types = types(root());
    let text = std::fs::read_to_string(root().join("launch_scripts/foxglove-layout.json"))
        .expect("layout");
    for (from, to) in [
        ("measured_current[2]", "measured_curent[2]"),
        ("deviation[3]", "deviation[4]"),
        ("/rpkm/tcp_estimate.psi", "/rpkm/tcp_estimate.theta"),
        ("/rpkm/tcp_estimate.x", "/rpkm/tcp_estimates.x"),
        ("{name==", "{label=="),
        ("/rpkm/preload_status.dq2", "/rpkm/preload_status.dq2[0]"),
        (
            "/rpkm/preload_status.level",
            "/rpkm/preload_status.level.value",
        ),
    ] {
        assert!(text.contains(from), "{from}");
        let broken: Value = serde_json::from_str(&text.replacen(from, to, 1)).expect("JSON");
        let errors = layout_errors(&broken, &types);
        assert!(!errors.is_empty(), "{from} -> {to} passed");
    }
    // An unplaced panel.
    let mut broken = shipped();
    broken["configById"]["Plot!orphan"] = serde_json::json!({"paths": []});
    assert!(layout_errors(&broken, &types)
        .iter()
        .any(|e| e.contains("Plot!orphan")));
    // The checker's grammar on its own.
    assert!(check_path(
        "/diagnostics.status[:]{name==\"a.b\"}.values[:].key",
        &types
    )
    .is_ok());
    assert!(check_path("/rpkm/preload_status.stamp.sec", &types).is_ok());
    assert!(check_path("/rpkm/preload_status.stamp.seconds", &types).is_err());
    assert!(check_path("/rpkm/actuator_state.follower[4]", &types).is_err());
}
