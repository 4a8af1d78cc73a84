//! The effect lists of the help texts, made from the effects registry
//! (`rpkm_core::effects::library`) and the twin's kinds (`rpkm_twin::EffectKind`): an effect
//! added there is in `rpkm diagnose --help`, `rpkm calibrate --help` and `rpkm simulate
//! --help` without a word written here (tests/it/library_described.rs holds the docs to the
//! same lists).

use std::fmt::Write as _;

use rpkm_twin::EffectKind;

/// Width of the name column of the lists.
const NAME_WIDTH: usize = 22;

/// The library's effects, one a line with what each models, in the order the diagnosis
/// tries them (`rpkm diagnose --help`, `rpkm calibrate --help`).
pub fn library() -> String {
    let mut out = String::from(
        "The library's effects (the order the diagnosis tries them; --effects names them):\n",
    );
    for effect in rpkm_core::effects::library() {
        let _ = writeln!(out, "  {:<NAME_WIDTH$}{}", effect.name(), effect.summary());
    }
    out
}

/// The twin's hidden effects, one a line with the default magnitude and its unit
/// (`rpkm simulate --help`).
pub fn twin_effects() -> String {
    let mut out = String::from("Effects (--effect NAME=MAGNITUDE; the default magnitude):\n");
    for kind in EffectKind::ALL {
        let _ = writeln!(
            out,
            "  {:<NAME_WIDTH$}{} {}; {}",
            kind.as_str(),
            kind.default_magnitude(),
            kind.unit(),
            kind.note()
        );
    }
    out
}
