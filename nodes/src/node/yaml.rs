//! YAML text read with its places: parameter files and launch files name the line of what is
//! wrong. serde_yaml refuses a key written twice in one map ("duplicate entry") but places
//! the error at the map's start, for a parameter file its first section, not at the second
//! `ingest:` that a reader pasted below the first; the second key's own line is found here
//! from the parser's marked events.

use std::collections::BTreeMap;

use serde_yaml::Value;
use yaml_rust2::parser::{Event, MarkedEventReceiver, Parser};
use yaml_rust2::scanner::Marker;

/// A YAML text that does not parse, with the place (parameter and launch files).
#[derive(Debug, thiserror::Error)]
#[error("{file}:{line}:{column}: not YAML: {message}")]
pub struct YamlSyntax {
    pub file: String,
    pub line: usize,
    pub column: usize,
    pub message: String,
}

/// Parses the YAML `text` of `file`; a key written twice in one map is an error at the
/// second one's line, naming the first's.
pub fn parse_yaml(text: &str, file: &str) -> Result<Value, YamlSyntax> {
    serde_yaml::from_str(text).map_err(|e| {
        let message = e.to_string();
        if message.contains("duplicate entry with key") {
            if let Some(d) = first_duplicate_key(text) {
                return YamlSyntax {
                    file: file.to_owned(),
                    line: d.line,
                    column: d.column,
                    message: format!(
                        "key {:?} again (first at line {}): a key appears once in its map; \
                         merge the two",
                        d.key, d.first_line
                    ),
                };
            }
        }
        let (line, column) = e.location().map_or((0, 0), |l| (l.line(), l.column()));
        YamlSyntax {
            file: file.to_owned(),
            line,
            column,
            message,
        }
    })
}

/// A key written a second time in the same map.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DuplicateKey {
    pub key: String,
    /// 1-based line and column of the second one.
    pub line: usize,
    pub column: usize,
    /// 1-based line of the first one.
    pub first_line: usize,
}

/// The first key (in the text's order) written twice in one map, if any; scalar keys only.
pub fn first_duplicate_key(text: &str) -> Option<DuplicateKey> {
    let mut keys = KeyWatch::default();
    // a text that does not parse has no duplicate to report: serde_yaml's error stands
    Parser::new_from_str(text).load(&mut keys, false).ok()?;
    keys.found
}

/// An open collection: a sequence, or a map with the lines of its keys so far and whether
/// its next node is a key.
enum Open {
    Seq,
    Map {
        keys: BTreeMap<String, usize>,
        next_is_key: bool,
    },
}

/// Follows the parser's events through the first document, noting each map's keys.
#[derive(Default)]
struct KeyWatch {
    open: Vec<Open>,
    found: Option<DuplicateKey>,
    /// Past the first document (serde_yaml reads one).
    done: bool,
}

impl KeyWatch {
    /// A node (`key`: its text when it is a scalar) in the innermost open collection.
    fn node(&mut self, key: Option<&str>, mark: Marker) {
        let Some(Open::Map { keys, next_is_key }) = self.open.last_mut() else {
            return;
        };
        if *next_is_key {
            if let Some(k) = key {
                match keys.get(k) {
                    Some(&first_line) if self.found.is_none() => {
                        self.found = Some(DuplicateKey {
                            key: k.to_owned(),
                            line: mark.line(),
                            column: mark.col() + 1,
                            first_line,
                        });
                    }
                    Some(_) => {}
                    None => {
                        keys.insert(k.to_owned(), mark.line());
                    }
                }
            }
        }
        *next_is_key = !*next_is_key;
    }
}

impl MarkedEventReceiver for KeyWatch {
    fn on_event(&mut self, ev: Event, mark: Marker) {
        if self.done {
            return;
        }
        match ev {
            Event::Scalar(text, ..) => self.node(Some(&text), mark),
            Event::Alias(_) => self.node(None, mark),
            Event::SequenceStart(..) => {
                self.node(None, mark);
                self.open.push(Open::Seq);
            }
            Event::MappingStart(..) => {
                self.node(None, mark);
                self.open.push(Open::Map {
                    keys: BTreeMap::new(),
                    next_is_key: true,
                });
            }
            Event::SequenceEnd | Event::MappingEnd => {
                self.open.pop();
            }
            Event::DocumentEnd => self.done = true,
            _ => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The docs' cell block pasted below the shipped file's own `ingest:` section: the
    /// error is at the pasted section's line and names the first.
    #[test]
    fn a_section_pasted_twice_is_named_at_its_second_line() {
        let text = "/**:\n  ros__parameters:\n    model: 29\n\
                    ingest:\n  ros__parameters:\n    source: dds\n\
                    tcp_estimator:\n  ros__parameters:\n    view_every: 100\n\
                    # pasted\n\
                    ingest:\n  ros__parameters:\n    followers: \"23\"\n";
        let e = parse_yaml(text, "params.yaml").expect_err("a duplicate section");
        assert_eq!((e.line, e.column), (11, 1), "{e}");
        assert_eq!(
            e.to_string(),
            "params.yaml:11:1: not YAML: key \"ingest\" again (first at line 4): a key \
             appears once in its map; merge the two"
        );
    }

    /// Keys of different maps may repeat; a repeated key inside a section is found too, in
    /// flow style as well.
    #[test]
    fn only_keys_of_one_map_collide() {
        let fine = "a:\n  ros__parameters:\n    x: 1\nb:\n  ros__parameters:\n    x: 2\n";
        assert!(parse_yaml(fine, "f").is_ok());
        assert_eq!(first_duplicate_key(fine), None);
        let inner = "a:\n  ros__parameters:\n    x: 1\n    y: [1, 2]\n    x: 3\n";
        let d = first_duplicate_key(inner).expect("x twice");
        assert_eq!((d.key.as_str(), d.line, d.first_line), ("x", 5, 3));
        let e = parse_yaml("launch: [{arg: {name: a, name: b}}]\n", "l.yaml").expect_err("dup");
        assert_eq!((e.line, e.column), (1, 26), "{e}");
    }
}
