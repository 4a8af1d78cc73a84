//! Effects files: physical effects written as data (docs/effects.md), read into the core's
//! [`Written`] effects. Every mistake is told with the file, line and column (1-based) of the
//! value at fault; nothing is guessed or defaulted.
//!
//! The YAML is read with `yaml-rust2`'s marked events rather than `serde_yaml` (the parameter
//! files' reader): an expression's unknown name must be pointed at inside its string, which
//! needs the place of every scalar, and serde_yaml gives places of its own errors only.
//!
//! ```yaml
//! effects:
//!   - name: cyclic_q4
//!     summary: pitch error of carrier 4's scale, 60 mm
//!     params: {a: {unit: mm, prior: 0.005}, c: {unit: mm, prior: 0.005}}
//!     dq4: "a * sin(2*pi*q4/60) + c * cos(2*pi*q4/60)"
//! ```

use rpkm_core::campaign::Campaign;
use rpkm_core::effects::written::{BindError, Spec, SpecError, WrittenParam};
use rpkm_core::effects::{self, Effect, Written};
use std::fmt::Write as _;
use std::path::Path;
use yaml_rust2::parser::{Event, MarkedEventReceiver, Parser};
use yaml_rust2::scanner::{Marker, TScalarStyle};

/// A place in the file: line and column, 1-based.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Place {
    pub line: usize,
    pub column: usize,
}

/// What is wrong with an effects file, and where.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{file}:{}:{}: {what}", place.line, place.column)]
pub struct EffectsFileError {
    pub file: String,
    pub place: Place,
    pub what: String,
}

/// A YAML node with its place.
#[derive(Debug, Clone)]
enum Node {
    Scalar {
        text: String,
        /// Where its text starts (after an opening quote).
        place: Place,
        /// Whether the text is on one line of the file as written (columns inside it count).
        one_line: bool,
    },
    Seq(Vec<Node>, Place),
    Map(Vec<(Node, Node)>, Place),
}

impl Node {
    fn place(&self) -> Place {
        match self {
            Node::Scalar { place, .. } | Node::Seq(_, place) | Node::Map(_, place) => *place,
        }
    }
}

/// Builds the tree of the first document from the parser's events.
#[derive(Default)]
struct Builder {
    /// Open collections: a sequence's items or a mapping's flat key, value list.
    open: Vec<(bool, Vec<Node>, Place)>,
    root: Option<Node>,
    /// An anchor or alias (not supported: an effect is written out where it is used).
    alias: Option<Place>,
}

fn place_of(mark: Marker) -> Place {
    Place {
        line: mark.line(),
        column: mark.col() + 1,
    }
}

impl MarkedEventReceiver for Builder {
    fn on_event(&mut self, ev: Event, mark: Marker) {
        let place = place_of(mark);
        let node = match ev {
            Event::Alias(_) => {
                self.alias.get_or_insert(place);
                return;
            }
            Event::Scalar(text, style, anchor, _) => {
                if anchor != 0 {
                    self.alias.get_or_insert(place);
                }
                let quoted = matches!(
                    style,
                    TScalarStyle::SingleQuoted | TScalarStyle::DoubleQuoted
                );
                let one_line = matches!(style, TScalarStyle::Plain) || quoted;
                Node::Scalar {
                    one_line: one_line && !text.contains('\n'),
                    text,
                    place: Place {
                        column: place.column + usize::from(quoted),
                        ..place
                    },
                }
            }
            Event::SequenceStart(..) | Event::MappingStart(..) => {
                let is_map = matches!(ev, Event::MappingStart(..));
                self.open.push((is_map, Vec::new(), place));
                return;
            }
            Event::SequenceEnd | Event::MappingEnd => {
                let Some((is_map, items, place)) = self.open.pop() else {
                    return;
                };
                if is_map {
                    // a block mapping's event comes after its first key: the key is its place
                    let place = items.first().map_or(place, Node::place);
                    let mut it = items.into_iter();
                    let mut pairs = Vec::new();
                    while let (Some(k), Some(v)) = (it.next(), it.next()) {
                        pairs.push((k, v));
                    }
                    Node::Map(pairs, place)
                } else {
                    Node::Seq(items, place)
                }
            }
            _ => return,
        };
        match self.open.last_mut() {
            Some(parent) => parent.1.push(node),
            None => {
                self.root.get_or_insert(node);
            }
        }
    }
}

/// The effects of one file, checked, with the places of what they are made of.
#[derive(Debug, Clone)]
pub struct EffectsFile {
    pub file: String,
    pub effects: Vec<Written>,
    places: Vec<Places>,
}

/// Where the parts of one effect are written.
#[derive(Debug, Clone, Default)]
struct Places {
    name: Place,
    /// Each target's expression: its start and whether columns inside it count.
    targets: Vec<(Place, bool)>,
}

/// Reads the effects file `path`; `columns` are the covariate columns of the campaign the
/// effects will meet (names an expression may read besides the fixed variables), where known.
pub fn read(path: &Path, columns: &[String]) -> Result<EffectsFile, EffectsFileError> {
    let file = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| EffectsFileError {
        file: file.clone(),
        place: Place { line: 1, column: 1 },
        what: format!("cannot read: {e}"),
    })?;
    parse(&text, &file, columns)
}

/// Parses the effects file `text` named `file` (see [`read`]).
pub fn parse(text: &str, file: &str, columns: &[String]) -> Result<EffectsFile, EffectsFileError> {
    let err = |place: Place, what: String| EffectsFileError {
        file: file.to_owned(),
        place,
        what,
    };
    let mut builder = Builder::default();
    Parser::new_from_str(text)
        .load(&mut builder, false)
        .map_err(|e| err(place_of(*e.marker()), format!("not YAML: {}", e.info())))?;
    if let Some(place) = builder.alias {
        return Err(err(
            place,
            "anchors and aliases are not supported: write each effect out".into(),
        ));
    }
    let start = Place { line: 1, column: 1 };
    let Some(Node::Map(top, top_place)) = builder.root else {
        return Err(err(
            start,
            "expected a mapping with the key `effects`".into(),
        ));
    };
    let mut list = None;
    for (k, v) in &top {
        match scalar(k) {
            Some("effects") => list = Some(v),
            _ => {
                return Err(err(
                    k.place(),
                    format!("unknown key {}: expected `effects`", shown(k)),
                ))
            }
        }
    }
    let Some(Node::Seq(items, list_place)) = list else {
        let place = list.map_or(top_place, Node::place);
        return Err(err(place, "`effects` must be a list of effects".into()));
    };
    if items.is_empty() {
        return Err(err(*list_place, "`effects` is empty".into()));
    }
    let mut out = EffectsFile {
        file: file.to_owned(),
        effects: Vec::new(),
        places: Vec::new(),
    };
    for item in items {
        let (spec, places) = effect_spec(item).map_err(|(p, w)| err(p, w))?;
        let named = |n: &str| n == spec.name;
        if out.effects.iter().any(|e| named(e.name())) {
            return Err(err(
                places.name,
                format!("a second effect named `{}`", spec.name),
            ));
        }
        if effects::names().iter().any(|n| named(n)) {
            return Err(err(
                places.name,
                format!(
                    "`{}` is the library's effect: choose another name",
                    spec.name
                ),
            ));
        }
        let written = Written::new(spec.clone(), columns).map_err(|e| {
            let (place, what) = spec_error_place(&e, &spec, &places, item);
            err(place, what)
        })?;
        out.effects.push(written);
        out.places.push(places);
    }
    Ok(out)
}

fn scalar(n: &Node) -> Option<&str> {
    match n {
        Node::Scalar { text, .. } => Some(text),
        _ => None,
    }
}

fn shown(n: &Node) -> String {
    scalar(n).map_or_else(|| "(not a word)".to_owned(), |s| format!("`{s}`"))
}

type Fault = (Place, String);

/// The number a scalar spells, or a fault at it.
fn number(n: &Node, what: &str) -> Result<f64, Fault> {
    scalar(n)
        .and_then(|s| s.trim().parse::<f64>().ok())
        .filter(|v| v.is_finite())
        .ok_or_else(|| {
            (
                n.place(),
                format!("{what}: expected a number, found {}", shown(n)),
            )
        })
}

fn text(n: &Node, what: &str) -> Result<String, Fault> {
    scalar(n)
        .map(str::to_owned)
        .ok_or_else(|| (n.place(), format!("{what}: expected text")))
}

/// One effect's mapping as the core's [`Spec`], with the places of its parts.
fn effect_spec(item: &Node) -> Result<(Spec, Places), Fault> {
    let Node::Map(entries, at) = item else {
        return Err((
            item.place(),
            "an effect must be a mapping (name, summary, params, expressions)".into(),
        ));
    };
    let mut spec = Spec::default();
    let mut places = Places::default();
    let mut seen: Vec<&str> = Vec::new();
    for (k, v) in entries {
        let key = scalar(k).ok_or_else(|| (k.place(), "a key must be a word".to_owned()))?;
        if seen.contains(&key) {
            return Err((k.place(), format!("`{key}` given twice")));
        }
        seen.push(key);
        match key {
            "name" => {
                spec.name = text(v, "name")?;
                places.name = v.place();
            }
            "summary" => spec.summary = text(v, "summary")?,
            "params" => spec.params = params(v)?,
            "instruments" => {
                let Node::Seq(list, _) = v else {
                    return Err((
                        v.place(),
                        "instruments: expected a list such as [lt]".into(),
                    ));
                };
                spec.instruments = Some(
                    list.iter()
                        .map(|n| text(n, "instruments"))
                        .collect::<Result<_, _>>()?,
                );
            }
            target => {
                spec.targets.push((target.to_owned(), text(v, target)?));
                let one_line = matches!(v, Node::Scalar { one_line: true, .. });
                places.targets.push((v.place(), one_line));
            }
        }
    }
    if !seen.contains(&"name") {
        return Err((*at, "the effect has no `name`".into()));
    }
    if !seen.contains(&"summary") {
        return Err((
            places.name,
            format!("effect `{}` has no `summary`", spec.name),
        ));
    }
    Ok((spec, places))
}

/// `params: {NAME: {unit: U, prior: σ, bounds: [lo, hi], start: v}}`.
fn params(v: &Node) -> Result<Vec<WrittenParam>, Fault> {
    let Node::Map(entries, _) = v else {
        return Err((
            v.place(),
            "params: expected a mapping NAME: {unit: U, prior: σ}".into(),
        ));
    };
    let mut out = Vec::new();
    for (k, spec) in entries {
        let name = text(k, "parameter name")?;
        let Node::Map(fields, _) = spec else {
            return Err((
                spec.place(),
                format!("parameter `{name}`: expected {{unit: U, prior: σ}}"),
            ));
        };
        let (mut unit, mut prior, mut bounds, mut start) = (None, None, None, 0.0);
        for (fk, fv) in fields {
            match scalar(fk) {
                Some("unit") => unit = Some(text(fv, "unit")?),
                Some("prior") => prior = Some(number(fv, "prior")?),
                Some("bounds") => bounds = Some(two_numbers(fv)?),
                Some("start") => start = number(fv, "start")?,
                _ => {
                    return Err((
                        fk.place(),
                        format!(
                        "parameter `{name}`: unknown key {}: expected unit, prior, bounds, start",
                        shown(fk)
                    ),
                    ))
                }
            }
        }
        let missing = |what: &str| (k.place(), format!("parameter `{name}` has no `{what}`"));
        out.push(WrittenParam {
            unit: unit.ok_or_else(|| missing("unit"))?,
            prior: prior.ok_or_else(|| missing("prior"))?,
            bounds,
            start,
            name,
        });
    }
    Ok(out)
}

fn two_numbers(v: &Node) -> Result<(f64, f64), Fault> {
    match v {
        Node::Seq(items, _) if items.len() == 2 => {
            Ok((number(&items[0], "bounds")?, number(&items[1], "bounds")?))
        }
        _ => Err((v.place(), "bounds: expected [lower, upper]".into())),
    }
}

/// The place and message of a core [`SpecError`].
fn spec_error_place(e: &SpecError, spec: &Spec, places: &Places, item: &Node) -> (Place, String) {
    let target_place = |k: usize| places.targets.get(k).map_or(places.name, |t| t.0);
    let place = match e {
        SpecError::UnknownTarget { target, .. } | SpecError::DuplicateTarget { target, .. } => {
            key_place(item, &spec.targets[*target].0).unwrap_or(places.name)
        }
        SpecError::Expression { target, error } => match places.targets.get(*target) {
            Some((p, true)) => Place {
                column: p.column + error.at,
                ..*p
            },
            _ => target_place(*target),
        },
        SpecError::Param { name, .. } => param_place(item, name).unwrap_or(places.name),
        _ => places.name,
    };
    let what = match e {
        SpecError::Expression { target, error } => {
            format!("{}: {error}", spec.targets[*target].0)
        }
        other => other.to_string(),
    };
    (place, format!("effect `{}`: {what}", spec.name))
}

/// Where key `key` of an effect's mapping is written.
fn key_place(item: &Node, key: &str) -> Option<Place> {
    let Node::Map(entries, _) = item else {
        return None;
    };
    entries
        .iter()
        .find(|(k, _)| scalar(k) == Some(key))
        .map(|(k, _)| k.place())
}

/// Where parameter `name` of an effect is written.
fn param_place(item: &Node, name: &str) -> Option<Place> {
    let Node::Map(entries, _) = item else {
        return None;
    };
    let (_, params) = entries.iter().find(|(k, _)| scalar(k) == Some("params"))?;
    let Node::Map(ps, _) = params else {
        return None;
    };
    ps.iter()
        .find(|(k, _)| scalar(k) == Some(name))
        .map(|(k, _)| k.place())
}

impl EffectsFile {
    /// The file's effect called `name`.
    pub fn get(&self, name: &str) -> Option<&Written> {
        self.effects.iter().find(|e| e.name() == name.trim())
    }

    /// Checks every effect against `campaign`: its variables there and its expressions
    /// finite at every pose (the place names the expression; the message the pose's line).
    pub fn check(&self, campaign: &Campaign) -> Result<(), EffectsFileError> {
        for (e, places) in self.effects.iter().zip(&self.places) {
            let (place, what) = match e.bind_checked(campaign) {
                Ok(_) => continue,
                Err(BindError::Variables(n)) => (places.name, n.reason),
                Err(BindError::NotFinite(n)) => (
                    places.targets.get(n.index).map_or(places.name, |t| t.0),
                    n.to_string(),
                ),
            };
            return Err(EffectsFileError {
                file: self.file.clone(),
                place,
                what: format!("effect `{}`: {what}", e.name()),
            });
        }
        Ok(())
    }

    /// Every effect of the file, as effects.
    pub fn all(&self) -> Vec<&dyn Effect> {
        self.effects.iter().map(|e| e as &dyn Effect).collect()
    }
}

/// The effects of the list `a,b,c`: the library's, and the file's where one is given.
pub fn parse_list(list: &str, file: Option<&EffectsFile>) -> Result<Vec<Box<dyn Effect>>, String> {
    let names: Vec<&str> = list.split(',').filter(|s| !s.trim().is_empty()).collect();
    names
        .iter()
        .enumerate()
        .map(|(k, name)| {
            if let Some(w) = file.and_then(|f| f.get(name)) {
                return Ok(Box::new(w.clone()) as Box<dyn Effect>);
            }
            effects::by_name(name).map_err(|e| {
                let mut said = match file {
                    Some(f) => {
                        let own: Vec<&str> = f.effects.iter().map(Effect::name).collect();
                        format!("{e}, or of {}: {}", f.file, own.join(", "))
                    }
                    None => e.to_string(),
                };
                if let Some(pinned) = k.checked_sub(1).and_then(|p| part_after(names[p], name)) {
                    let _ = write!(
                        said,
                        "; several parts of a family are pinned with +, not a comma: {pinned}"
                    );
                }
                said
            })
        })
        .collect()
}

/// Where `name` is a part of the family `previous` pins (`frame` after `thermal:rods`), the
/// list it was meant as (`thermal:rods+frame`).
fn part_after(previous: &str, name: &str) -> Option<String> {
    let (family, _) = previous.trim().split_once(':')?;
    let pinned = format!("{}+{}", previous.trim(), name.trim());
    effects::by_name(&format!("{family}:{}", name.trim()))
        .is_ok()
        .then_some(pinned)
}

/// Each effect of the file (none without one): its name and its expressions as written
/// (`dq4 = -b * dir_q4; dx = ...`), for the report.
pub fn expressions(file: Option<&EffectsFile>) -> Vec<(String, String)> {
    file.map(|f| f.effects.as_slice())
        .unwrap_or_default()
        .iter()
        .map(|e| {
            let s = e.spec();
            let exprs: Vec<String> = s
                .targets
                .iter()
                .map(|(t, x)| format!("{t} = {x}"))
                .collect();
            (s.name.clone(), exprs.join("; "))
        })
        .collect()
}

/// The file's effects as JSON: name, summary, parameters and expressions as written.
pub fn to_json(file: &EffectsFile) -> serde_json::Value {
    effects_json(&file.file, &file.effects.iter().collect::<Vec<_>>())
}

/// Effects `effects` of the file `file` as JSON (see [`to_json`]).
pub fn effects_json(file: &str, effects: &[&Written]) -> serde_json::Value {
    let effects: Vec<serde_json::Value> = effects
        .iter()
        .map(|e| {
            let s = e.spec();
            let params: Vec<serde_json::Value> = s
                .params
                .iter()
                .map(|p| serde_json::json!({"name": p.name, "unit": p.unit, "prior": p.prior, "bounds": p.bounds}))
                .collect();
            let expressions: serde_json::Map<String, serde_json::Value> =
                s.targets.iter().map(|(t, x)| (t.clone(), serde_json::Value::from(x.clone()))).collect();
            serde_json::json!({
                "name": s.name,
                "summary": s.summary,
                "params": params,
                "expressions": expressions,
                "instruments": s.instruments,
            })
        })
        .collect();
    serde_json::json!({"file": file, "effects": effects})
}

/// SI per unit of an effect parameter's value on a topic: lengths in mm or µm and angles in
/// mrad or µrad become m and rad; any other unit stays as the effect states it (`ppm/K`, `1`).
/// The calibrator publishes with it and the nodes that apply the effects read back with it.
pub fn si_per_unit(unit: &str) -> f64 {
    match unit {
        "mm" | "mrad" => 1e-3,
        "um" | "µm" | "urad" | "µrad" => 1e-6,
        _ => 1.0,
    }
}
