//! The library's effects by identity ([`Family`]) and the family of an effect's name
//! ([`family_of`]): a leaf every effect's file names itself from.

/// The effects of `effects::all` by identity: what code compares where it means one of them (the
/// name is what a user writes and a report prints; each effect's file names itself by its
/// family's [`Family::name`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Family {
    Parallelogram,
    PreloadElastic,
    Thermal,
    ThermalLag,
    EncoderScale,
    GuideStraightness,
    InstrumentAlignment,
    StiffnessFactor,
}

impl Family {
    pub(super) const ALL: [Family; 8] = [
        Family::Parallelogram,
        Family::PreloadElastic,
        Family::Thermal,
        Family::ThermalLag,
        Family::EncoderScale,
        Family::GuideStraightness,
        Family::InstrumentAlignment,
        Family::StiffnessFactor,
    ];

    /// The family's name on the command line and in reports.
    pub const fn name(self) -> &'static str {
        match self {
            Family::Parallelogram => "parallelogram",
            Family::PreloadElastic => "preload_elastic",
            Family::Thermal => "thermal",
            Family::ThermalLag => "thermal_lag",
            Family::EncoderScale => "encoder_scale",
            Family::GuideStraightness => "guide_straightness",
            Family::InstrumentAlignment => "instrument_alignment",
            Family::StiffnessFactor => "stiffness_factor",
        }
    }

    /// The family of effect name `name` (`thermal:rods` is [`Family::Thermal`]); None for a
    /// written effect.
    pub fn of(name: &str) -> Option<Family> {
        let family = family_of(name);
        Self::ALL.into_iter().find(|f| f.name() == family)
    }
}

/// The parts (indices into [`super::effect::Effect::parts`]) an effect pinned to some of its family's
/// parts holds (`thermal:rods+scales`: 0 and 2); None where its name pins none or names a
/// part the family does not have.
pub fn pinned_parts(effect: &dyn super::effect::Effect) -> Option<Vec<usize>> {
    let (_, names) = effect.name().split_once(':')?;
    names
        .split('+')
        .map(|n| effect.parts().iter().position(|p| *p == n))
        .collect()
}

/// The names of the parts an effect holds: those its name pins (`thermal:rods+scales`: rods
/// and scales), else all of its family's.
pub fn held_parts(effect: &dyn super::effect::Effect) -> Vec<&'static str> {
    let all = effect.parts();
    pinned_parts(effect).map_or_else(|| all.to_vec(), |ix| ix.iter().map(|&i| all[i]).collect())
}

/// The family of an effect name: `thermal` for `thermal:rods` (the name itself where it
/// pins no part).
pub fn family_of(name: &str) -> &str {
    name.split_once(':').map_or(name, |(f, _)| f)
}
