//! The library describes itself (issue 53). Every effect of the registry
//! (`rpkm_core::effects::library`, core/src/effects/mod.rs) has a kind of the twin with a
//! default magnitude (`rpkm_twin::EffectKind`), a row of docs/effects.md's table naming the
//! parameters and units the effect declares, a place in README.md's list, and a line of
//! `rpkm diagnose --help` and `rpkm calibrate --help` (made from the registry); every kind of
//! the twin is in the library or says it is not, and has a row of docs/twin.md's table with its
//! unit and default and a line of `rpkm simulate --help` (made from the twin). A new effect
//! that lacks one of them fails here with a message saying where to add it; the help texts
//! follow the registry and the twin by themselves.

use std::path::PathBuf;
use std::process::Command;
use std::str::FromStr;

use rpkm_core::campaign::{Campaign, Instrument};
use rpkm_core::effects::{self, Effect, EffectSet};
use rpkm_core::params::Params;
use rpkm_twin::{EffectKind, Twin, TwinConfig};

fn read(page: &str) -> String {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(page);
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn help(command: &str) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_rpkm"))
        .args([command, "--help"])
        .output()
        .expect("run rpkm");
    assert!(out.status.success(), "rpkm {command} --help");
    String::from_utf8(out.stdout).expect("utf-8")
}

/// The rows of the first table of `text` under the header line starting `header`: each row's
/// cells, trimmed, with the backticks of its first cell removed.
fn table(text: &str, header: &str) -> Vec<Vec<String>> {
    text.lines()
        .skip_while(|l| !l.starts_with(header))
        .skip(2)
        .take_while(|l| l.starts_with('|'))
        .map(|l| {
            l.trim_matches('|')
                .split('|')
                .enumerate()
                .map(|(k, c)| {
                    let c = c.trim();
                    if k == 0 { c.trim_matches('`') } else { c }.to_owned()
                })
                .collect()
        })
        .collect()
}

/// A campaign every library effect binds to: drive forces (the twin's preload) and a
/// temperature, tracker setups for the alignment.
fn campaign() -> Campaign {
    let mut twin = Twin::new(TwinConfig {
        seed: 1,
        effects: vec![
            (EffectKind::PreloadElastic, 0.3),
            (EffectKind::Thermal, 3.0),
        ],
        ..Default::default()
    })
    .expect("twin");
    twin.campaign(&[Instrument::Lt]).expect("campaign")
}

/// The twin's kind of a library effect: its own, or that of the family it refines.
fn twin_kind(effect: &dyn Effect) -> Result<EffectKind, String> {
    let family = effect.beside().unwrap_or(effect.name());
    EffectKind::from_str(family).map_err(|_| {
        format!(
            "library effect {} has no kind in the twin: add {family} to rpkm_twin::EffectKind \
             (twin/src/effects.rs) with its unit, default magnitude and note, and simulate it \
             (twin/src/lib.rs)",
            effect.name()
        )
    })
}

#[test]
fn every_library_effect_has_a_twin_kind_a_docs_row_and_a_help_line() {
    let library = effects::library();
    let names: Vec<&str> = library.iter().map(|e| e.name()).collect();
    let rows = table(
        &read("docs/effects.md"),
        "| effect | parameters | what it changes |",
    );
    let documented: Vec<&str> = rows.iter().map(|r| r[0].as_str()).collect();
    assert_eq!(
        documented, names,
        "docs/effects.md's table of the library (\"| effect | parameters | what it changes |\") \
         lists the registry's effects in its order, one row each"
    );
    let c = campaign();
    let p = Params::nominal();
    for (effect, row) in library.iter().zip(&rows) {
        twin_kind(effect.as_ref()).unwrap_or_else(|why| panic!("{why}"));
        let set = EffectSet::bind(&[effect.as_ref()], &c, &p).expect("binds to the campaign");
        let setups: Vec<&str> = c.setups().iter().map(|s| s.id).collect();
        for slot in set.layout() {
            // a setup's own parameter is written with SETUP for the setup's name
            let setup = setups
                .iter()
                .filter(|s| slot.param.name.ends_with(&format!("_{s}")))
                .max_by_key(|s| s.len());
            // an anchored nuisance's terms are written with K for the term's number
            let name = match setup {
                Some(s) if slot.setup_local => {
                    let stem = slot.param.name.len() - s.len();
                    format!("{}SETUP", &slot.param.name[..stem])
                }
                _ if slot.param.anchor.is_some() => format!(
                    "{}K",
                    slot.param
                        .name
                        .trim_end_matches(|c: char| c.is_ascii_digit())
                ),
                _ => slot.param.name.clone(),
            };
            let unit = format!("({})", slot.param.unit);
            assert!(
                row[1].contains(&name) && row[1].contains(&unit),
                "docs/effects.md's row of {}: parameter {name} {unit} as the effect declares it, \
                 found \"{}\"",
                effect.name(),
                row[1]
            );
        }
    }
    for command in ["diagnose", "calibrate"] {
        let text = help(command);
        for effect in &library {
            let line = format!("  {:<22}{}", effect.name(), effect.summary());
            assert!(
                text.lines().any(|l| l == line),
                "rpkm {command} --help lists {} (src/cli/library_help.rs)",
                effect.name()
            );
        }
    }
}

#[test]
fn readmes_list_is_the_library_in_its_order() {
    let readme = read("README.md");
    let start = "tries every physical effect of the library (";
    let at = readme.find(start).expect("README.md's list of the library") + start.len();
    // the list runs to its closing parenthesis
    let mut depth = 1;
    let end = readme[at..]
        .char_indices()
        .find(|&(_, ch)| {
            depth += match ch {
                '(' => 1,
                ')' => -1,
                _ => 0,
            };
            depth == 0
        })
        .map(|(k, _)| at + k)
        .expect("the list's closing parenthesis");
    let known: Vec<String> = effects::names()
        .into_iter()
        .chain(EffectKind::ALL.map(|k| k.as_str().to_owned()))
        .collect();
    let mut listed: Vec<&str> = Vec::new();
    for word in readme[at..end].split(|ch: char| !(ch.is_ascii_alphanumeric() || ch == '_')) {
        if known.iter().any(|k| k == word) && !listed.contains(&word) {
            listed.push(word);
        }
    }
    let names: Vec<String> = effects::library()
        .iter()
        .map(|e| e.name().to_owned())
        .collect();
    assert_eq!(
        listed, names,
        "README.md's list (\"{start}...)\") names the registry's effects in its order"
    );
}

#[test]
fn every_twin_kind_is_documented_with_its_default_and_in_simulates_help() {
    let names = effects::names();
    let rows = table(
        &read("docs/twin.md"),
        "| effect | magnitude (default) | model |",
    );
    let documented: Vec<&str> = rows.iter().map(|r| r[0].as_str()).collect();
    assert_eq!(
        documented,
        EffectKind::ALL.map(EffectKind::as_str),
        "docs/twin.md's table of hidden effects lists rpkm_twin::EffectKind::ALL in its order"
    );
    let text = help("simulate");
    for (kind, row) in EffectKind::ALL.into_iter().zip(&rows) {
        assert!(
            names.iter().any(|n| n == kind.as_str()) || kind.outside_library(),
            "twin kind {kind} is neither an effect of the library nor outside_library \
             (twin/src/effects.rs)"
        );
        let magnitude = format!("{} ({})", kind.unit(), kind.default_magnitude());
        assert_eq!(
            row[1], magnitude,
            "docs/twin.md's row of {kind}: its unit and default magnitude"
        );
        let line = format!(
            "  {:<22}{} {}; {}",
            kind.as_str(),
            kind.default_magnitude(),
            kind.unit(),
            kind.note()
        );
        assert!(
            text.lines().any(|l| l == line),
            "rpkm simulate --help lists {kind} with its default: {line:?}"
        );
    }
}
