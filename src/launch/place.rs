//! Where an error is: the entry being read, a key's line, a line serde_yaml did not give.

use super::args::LaunchError;
use serde_yaml::Value;
use std::collections::BTreeMap;
use std::path::Path;

pub(super) struct Ctx<'a> {
    pub(super) file: String,
    /// The file's text, to find the line of a key (serde_yaml values carry no positions).
    pub(super) text: &'a str,
    pub(super) dir: &'a Path,
    pub(super) vars: BTreeMap<String, String>,
    /// Lines `[first, end)` (1-based) of the entry being read: errors name its line.
    pub(super) entry: (usize, usize),
}

impl Ctx<'_> {
    /// An error at the entry being read.
    pub(super) fn err(&self, what: String) -> LaunchError {
        LaunchError::Invalid {
            file: self.file.clone(),
            line: self.entry.0,
            what,
        }
    }

    /// An error at `key:` of the entry being read (at the entry when the key is not found).
    pub(super) fn err_at(&self, key: &str, what: String) -> LaunchError {
        LaunchError::Invalid {
            file: self.file.clone(),
            line: key_line(self.text, key, self.entry).unwrap_or(self.entry.0),
            what,
        }
    }

    /// Errors on a key of `entry` that is not in `known`, with the line where it first
    /// appears in the file.
    pub(super) fn check_keys(
        &self,
        body: &serde_yaml::Mapping,
        entry: &str,
        known: &[&str],
    ) -> Result<(), LaunchError> {
        for key in body.keys() {
            let name = match key {
                Value::String(s) => s.clone(),
                other => serde_yaml::to_string(other)
                    .map(|s| s.trim().to_owned())
                    .unwrap_or_default(),
            };
            if known.contains(&name.as_str()) {
                continue;
            }
            return Err(self.err_at(
                &name,
                format!(
                    "{entry}: unknown key {name:?} (known: {})",
                    known.join(", ")
                ),
            ));
        }
        Ok(())
    }

    /// Applies `$(var ..)`, `$(env ..)`, `$(dirname)` and `$(equals A B)`; a substitution's
    /// arguments may hold substitutions (`$(equals $(var source) joint_states)`).
    pub(super) fn subst(&self, s: &str) -> Result<String, LaunchError> {
        let mut out = String::new();
        let mut rest = s;
        while let Some(start) = rest.find("$(") {
            out.push_str(&rest[..start]);
            let after = &rest[start + 2..];
            let end = closing(after)
                .ok_or_else(|| self.err(format!("unclosed substitution in {s:?}")))?;
            out.push_str(&self.substitution(&after[..end])?);
            rest = &after[end + 1..];
        }
        out.push_str(rest);
        Ok(out)
    }

    /// The value of one substitution, `inner` being what stands between `$(` and `)`.
    fn substitution(&self, inner: &str) -> Result<String, LaunchError> {
        let mut words = Vec::new();
        for w in top_level_words(inner) {
            words.push(self.subst(w)?);
        }
        let words: Vec<&str> = words.iter().map(String::as_str).collect();
        Ok(match words.as_slice() {
            ["var", name] => self
                .vars
                .get(*name)
                .cloned()
                .ok_or_else(|| self.err(format!("$(var {name}): no such launch argument")))?,
            ["env", name] => std::env::var(name).map_err(|_| {
                self.err(format!(
                    "$(env {name}): not set (give a default: $(env {name} x))"
                ))
            })?,
            ["env", name, default] => std::env::var(name).unwrap_or_else(|_| (*default).to_owned()),
            ["dirname"] => self.dir.display().to_string(),
            ["equals", a, b] => equals(a, b).to_string(),
            other => {
                return Err(self.err(format!(
                    "unknown substitution $({}) (var, env, dirname, equals A B)",
                    other.join(" ")
                )))
            }
        })
    }

    pub(super) fn string(&self, v: &Value, what: &str) -> Result<String, LaunchError> {
        let s = match v {
            Value::String(s) => s.clone(),
            Value::Number(n) => n.to_string(),
            Value::Bool(b) => b.to_string(),
            _ => return Err(self.err(format!("{what}: expected a string"))),
        };
        self.subst(&s)
    }
}

/// Where the `)` that closes a substitution lies in `after` (the text after its `$(`),
/// substitutions inside it skipped.
fn closing(after: &str) -> Option<usize> {
    let mut depth = 0usize;
    let bytes = after.as_bytes();
    let mut i = 0;
    while i < bytes.len() {
        match bytes[i] {
            b'$' if bytes.get(i + 1) == Some(&b'(') => {
                depth += 1;
                i += 1;
            }
            b')' if depth == 0 => return Some(i),
            b')' => depth -= 1,
            _ => {}
        }
        i += 1;
    }
    None
}

/// A substitution's words: split at whitespace outside the substitutions inside it.
fn top_level_words(inner: &str) -> Vec<&str> {
    let mut words = Vec::new();
    let mut rest = inner.trim_start();
    while !rest.is_empty() {
        let mut end = rest.len();
        let mut i = 0;
        while i < rest.len() {
            if rest[i..].starts_with("$(") {
                i += 2 + closing(&rest[i + 2..]).map_or(rest.len() - i - 2, |e| e + 1);
                continue;
            }
            if rest[i..].starts_with(char::is_whitespace) {
                end = i;
                break;
            }
            i += rest[i..].chars().next().map_or(1, char::len_utf8);
        }
        let end = end.min(rest.len());
        words.push(&rest[..end]);
        rest = rest[end..].trim_start();
    }
    words
}

/// ROS 2's `$(equals A B)`: booleans (true, false, 1, 0 in any case) compare as booleans,
/// numbers as numbers (to a relative 1e-9, as Python's `math.isclose`), anything else as
/// text.
fn equals(a: &str, b: &str) -> bool {
    let truth = |s: &str| match s.to_ascii_lowercase().as_str() {
        "true" | "1" => Some(true),
        "false" | "0" => Some(false),
        _ => None,
    };
    if let (Some(x), Some(y)) = (truth(a), truth(b)) {
        return x == y;
    }
    if let (Ok(x), Ok(y)) = (a.trim().parse::<f64>(), b.trim().parse::<f64>()) {
        return x.total_cmp(&y).is_eq() || (x - y).abs() <= 1e-9 * x.abs().max(y.abs());
    }
    a == b
}

/// The 1-based line where `key:` first appears as a mapping key (block or flow style),
/// outside comments, within the lines `[first, end)`.
fn key_line(text: &str, key: &str, (first, end): (usize, usize)) -> Option<usize> {
    let pattern = format!("{key}:");
    let lines = text.lines().enumerate();
    let mut lines = lines
        .skip(first.saturating_sub(1))
        .take(end.saturating_sub(first));
    lines.find_map(|(i, line)| {
        let code = line.split(" #").next().unwrap_or(line);
        code.match_indices(&pattern)
            .any(|(at, _)| {
                let before = code[..at].chars().next_back();
                before.is_none_or(|c| c.is_whitespace() || matches!(c, '{' | ',' | '-'))
            })
            .then_some(i + 1)
    })
}

/// The 1-based line of the top-level `launch:` key (1 when there is none) and the first
/// line of each entry of its block list (`- ` at the list's indentation); no entries for a
/// flow list (`launch: [...]`).
pub(super) fn entry_lines(text: &str) -> (usize, Vec<usize>) {
    let mut lines = text.lines().enumerate();
    let Some((at, _)) = lines.by_ref().find(|(_, l)| l.starts_with("launch:")) else {
        return (1, Vec::new());
    };
    let mut indent = None;
    let mut entries = Vec::new();
    for (i, line) in lines {
        let code = line.trim_start();
        if code.is_empty() || code.starts_with('#') {
            continue;
        }
        let this = line.len() - code.len();
        let item = code == "-" || code.starts_with("- ");
        match indent {
            None if item => indent = Some(this),
            Some(n) if this == n && item => {}
            Some(n) if this > n => continue,
            _ => break,
        }
        entries.push(i + 1);
    }
    (at + 1, entries)
}

/// The line to blame for a YAML error serde_yaml does not locate (a file of several
/// documents): the first document marker (`---`, `...`) after content, else the first line
/// of content, else 1.
pub(super) fn unlocated_error_line(text: &str) -> usize {
    let content = |l: &str| {
        let t = l.trim_start();
        !(t.is_empty() || t.starts_with('#') || t.starts_with('%'))
    };
    let mut lines = text.lines().enumerate();
    let Some((first, _)) = lines.by_ref().find(|(_, l)| content(l)) else {
        return 1;
    };
    lines
        .find(|(_, l)| l.starts_with("---") || l.starts_with("..."))
        .map_or(first + 1, |(i, _)| i + 1)
}

/// Where a UTF-8 error lies in `bytes`: the 1-based line and the byte offset.
pub(super) fn utf8_error_place(bytes: &[u8], error: &std::str::Utf8Error) -> (usize, usize) {
    let offset = error.valid_up_to();
    let line = bytes[..offset].split(|&b| b == b'\n').count();
    (line, offset)
}
