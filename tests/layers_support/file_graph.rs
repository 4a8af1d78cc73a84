//! The import graph between the files of one crate, and a cycle in it if there is one: the
//! rule that no file imports a file that imports it (directly or around a loop), so the work
//! flows one way and each file can be read knowing only those below it. Shared by
//! `core/tests/layers.rs` (the core) and `tests/layers.rs` (the nodes and the transport).
//!
//! A file's references are the paths it names through `crate::`, `super::` and `self::`,
//! groups `{a, b::{c, d}}` included, and in a `mod.rs`, `lib.rs` or `main.rs` the paths
//! through its own submodules (`child::f`). A path leads to the deepest file its segments
//! name: `super::types::Options` to `types.rs`, `super::Options` to the parent's file. A
//! `mod child;` declaration is not a reference. Comments and the `#[cfg(test)]` module at a
//! file's end (tests read everything through `use super::*`) are not part of the layering.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Every `.rs` file under `src`, by its module path (`calib::types`, `calib`, or `` for the
/// crate root).
pub fn crate_files(src: &Path) -> BTreeMap<String, PathBuf> {
    let mut files = Vec::new();
    rust_files(src, &mut files);
    // a binary beside the library is a crate of its own: it names the library by its name
    let has_lib = src.join("lib.rs").is_file();
    files.retain(|f| !(has_lib && f.parent() == Some(src) && f.ends_with("main.rs")));
    files.into_iter().map(|f| (module_of(src, &f), f)).collect()
}

/// Every `.rs` file under `dir`, depth first.
pub fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
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

fn module_of(src: &Path, file: &Path) -> String {
    let rel = file
        .strip_prefix(src)
        .expect("under src")
        .with_extension("");
    let mut parts: Vec<String> = rel
        .components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect();
    if matches!(
        parts.last().map(String::as_str),
        Some("mod" | "lib" | "main")
    ) {
        parts.pop();
    }
    parts.join("::")
}

/// The code of a file without comments and without its trailing test module.
pub fn code_of(text: &str) -> String {
    let body = text.split("#[cfg(test)]").next().unwrap_or("");
    body.lines()
        .map(|l| without_visibility_paths(l.split("//").next().unwrap_or("")) + "\n")
        .collect()
}

/// `line` with each `pub(in path)` read as `pub`: a visibility names the module it opens to,
/// it imports nothing from it.
fn without_visibility_paths(line: &str) -> String {
    let mut out = String::new();
    let mut rest = line;
    while let Some(at) = rest.find("pub(in ") {
        out.push_str(&rest[..at]);
        out.push_str("pub");
        rest = rest[at..].find(')').map_or("", |end| &rest[at + end + 1..]);
    }
    out.push_str(rest);
    out
}

fn ident(s: &str) -> &str {
    let end = s
        .find(|c: char| !(c.is_alphanumeric() || c == '_'))
        .unwrap_or(s.len());
    &s[..end]
}

/// The paths `code` names from each of `roots` (`crate`, `super`, `self`, or a submodule),
/// each as its segments; a group `{a, b::{c, d}}` gives one path per leaf.
pub fn paths(code: &str, roots: &[&str]) -> Vec<Vec<String>> {
    let mut out = Vec::new();
    let bytes = code.as_bytes();
    // a root inside a path already read (`lm` in `super::{lm::State}`) is that path's
    let mut read: Vec<(usize, usize)> = Vec::new();
    for root in roots {
        let needle = format!("{root}::");
        for (at, _) in code.match_indices(&needle) {
            let starts_word = at == 0 || {
                let b = bytes[at - 1];
                !(b.is_ascii_alphanumeric() || b == b'_' || b == b':')
            };
            if starts_word && !read.iter().any(|&(a, b)| a < at && at < b) {
                read.push((at, at + path_len(&code[at..])));
                expand(&code[at..], &mut Vec::new(), &mut out);
            }
        }
    }
    out
}

/// The length of the path at the start of `s`: names and `::`, and groups in braces.
fn path_len(s: &str) -> usize {
    let mut depth = 0;
    for (i, c) in s.char_indices() {
        match c {
            '{' => depth += 1,
            '}' if depth > 0 => depth -= 1,
            c if depth > 0 || c.is_alphanumeric() || c == '_' || c == ':' => {}
            _ => return i,
        }
    }
    s.len()
}

/// The path at the start of `s` (segments joined by `::`, a group expanded), appended to
/// `prefix`, into `out`.
fn expand(s: &str, prefix: &mut Vec<String>, out: &mut Vec<Vec<String>>) {
    let mut rest = s;
    let depth = prefix.len();
    loop {
        rest = rest.trim_start();
        if let Some(group) = rest.strip_prefix('{') {
            for item in split_group(group) {
                expand(item, prefix, out);
            }
            break;
        }
        let name = ident(rest);
        if name.is_empty() {
            break;
        }
        prefix.push(name.to_owned());
        rest = &rest[name.len()..];
        let Some(next) = rest.strip_prefix("::") else {
            out.push(prefix.clone());
            break;
        };
        rest = next;
    }
    prefix.truncate(depth);
}

/// The items of a group body `a, b::{c, d}, e}...` up to its closing brace.
fn split_group(body: &str) -> Vec<&str> {
    let (mut items, mut depth, mut start) = (Vec::new(), 0, 0);
    for (i, c) in body.char_indices() {
        match c {
            '{' => depth += 1,
            '}' if depth == 0 => {
                items.push(&body[start..i]);
                return items;
            }
            '}' => depth -= 1,
            ',' if depth == 0 => {
                items.push(&body[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    items
}

/// The file-level import graph: each module's file and the modules (files) it references.
pub fn graph(src: &Path) -> Vec<(String, Vec<String>)> {
    let files = crate_files(src);
    files
        .iter()
        .map(|(module, path)| {
            let text = std::fs::read_to_string(path).expect("read source");
            let code = code_of(&text);
            let own: Vec<String> = if module.is_empty() {
                Vec::new()
            } else {
                module.split("::").map(str::to_owned).collect()
            };
            let is_dir_module = path
                .file_stem()
                .is_some_and(|s| s == "mod" || s == "lib" || s == "main");
            let children: Vec<String> = files
                .keys()
                .filter(|m| is_child(&own, m))
                .map(|m| m.rsplit("::").next().unwrap_or("").to_owned())
                .collect();
            let mut roots = vec!["crate", "super", "self"];
            if is_dir_module {
                roots.extend(children.iter().map(String::as_str));
            }
            let mut deps: Vec<String> = paths(&code, &roots)
                .iter()
                .filter_map(|p| resolve(&own, p, &files))
                .filter(|target| target != module)
                .collect();
            deps.sort();
            deps.dedup();
            (module.clone(), deps)
        })
        .collect()
}

fn is_child(parent: &[String], module: &str) -> bool {
    let parts: Vec<&str> = module.split("::").filter(|s| !s.is_empty()).collect();
    parts.len() == parent.len() + 1 && parts.iter().zip(parent).all(|(a, b)| a == b)
}

/// The deepest module file `path` leads to, named from the file of module `own`.
fn resolve(own: &[String], path: &[String], files: &BTreeMap<String, PathBuf>) -> Option<String> {
    let mut at: Vec<String> = match path.first().map(String::as_str) {
        Some("crate") => Vec::new(),
        _ => own.to_vec(),
    };
    let mut segments = path.iter().peekable();
    if path.first().is_some_and(|s| s == "crate" || s == "self") {
        segments.next();
    }
    while segments.peek().is_some_and(|s| *s == "super") {
        segments.next();
        at.pop()?;
    }
    for seg in segments {
        let mut deeper = at.clone();
        deeper.push(seg.clone());
        if files.contains_key(&deeper.join("::")) {
            at = deeper;
        } else {
            break;
        }
    }
    Some(at.join("::"))
}

/// A cycle of the graph, as the modules along it, if any (depth-first search).
pub fn find_cycle(graph: &[(String, Vec<String>)]) -> Option<Vec<String>> {
    fn visit(
        graph: &[(String, Vec<String>)],
        node: &str,
        path: &mut Vec<String>,
        done: &mut Vec<String>,
    ) -> Option<Vec<String>> {
        if let Some(pos) = path.iter().position(|m| m == node) {
            let mut cycle = path[pos..].to_vec();
            cycle.push(node.to_owned());
            return Some(cycle);
        }
        if done.iter().any(|m| m == node) {
            return None;
        }
        path.push(node.to_owned());
        let edges = graph
            .iter()
            .find(|(m, _)| m == node)
            .map(|(_, e)| e.as_slice());
        for next in edges.unwrap_or_default() {
            if let Some(cycle) = visit(graph, next, path, done) {
                return Some(cycle);
            }
        }
        path.pop();
        done.push(node.to_owned());
        None
    }
    let mut done = Vec::new();
    graph
        .iter()
        .find_map(|(m, _)| visit(graph, m, &mut Vec::new(), &mut done))
}

/// Every cycle the search meets, each broken at its closing edge before the next search:
/// the whole list of what imports in a circle, a line each (`a -> b -> a`) for the message.
pub fn cycles(graph: &[(String, Vec<String>)]) -> Vec<String> {
    let mut g = graph.to_vec();
    let mut found = Vec::new();
    while let Some(cycle) = find_cycle(&g) {
        let (from, to) = (&cycle[cycle.len() - 2], &cycle[cycle.len() - 1]);
        if let Some((_, deps)) = g.iter_mut().find(|(m, _)| m == from) {
            deps.retain(|d| d != to);
        }
        found.push(cycle.join(" -> "));
    }
    found
}
