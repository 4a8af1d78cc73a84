//! What a search draws its models from ([`Pool`]) and the models it adds beside the single
//! candidates: each part of a family that stands out, each with the effect that refines it
//! on the same parts, pairs, and the current model's families with other parts.

use super::entry::{Entry, Judge};
use super::trials::SCREEN_P;
use crate::diagnose::types::Candidate;
use crate::effects::{self, Effect};

/// The best contenders (by BIC gain) are paired among themselves; the best also with every
/// other candidate.
pub(in crate::diagnose) const PAIRED: usize = 3;

/// What a search draws its models from: the candidates tried, the part combinations of
/// their families ([`part_variants`]), and those of the current model's families.
pub(crate) struct Pool<'a> {
    pub tried: &'a [&'a dyn Effect],
    pub variants: &'a [Box<dyn Effect>],
    /// The effects that refine a tried family ([`Effect::beside`]), whole and by each part
    /// combination ([`followers`]).
    pub followers: &'a [Box<dyn Effect>],
    pub swaps: &'a [Box<dyn Effect>],
}

impl<'j> Judge<'j> {
    /// Each part of a family that stands out, on its own and in every smaller combination,
    /// and each refinement of an effect that stands out (`variants`: [`part_variants`]): the
    /// campaign may separate some parts and not others, and a rod of another stiffness is
    /// what another effect beside the preload would absorb otherwise.
    pub(in crate::diagnose) fn add_parts<'a>(
        &self,
        entries: &mut Vec<Entry<'a>>,
        variants: &'a [Box<dyn Effect>],
    ) {
        let families: Vec<usize> = (0..entries.len())
            .filter(|&k| entries[k].added.len() == 1)
            .filter(|&k| {
                let e = entries[k].added[0];
                e.parts().len() > 1 || !e.refinements().is_empty()
            })
            .filter(|&k| entries[k].p_value < SCREEN_P)
            .collect();
        for k in families {
            let family = effects::family_of(entries[k].added[0].name()).to_owned();
            for v in variants
                .iter()
                .filter(|v| effects::family_of(v.name()) == family)
            {
                let tried = self.tried((vec![v.as_ref()], None), &[&entries[k].fitted]);
                entries.extend(tried);
            }
        }
    }

    /// Each family that stands out (whole and by its parts) with the effect that refines it
    /// on the same parts (`thermal:scales` with `thermal_lag:scales`): where the thermometer
    /// lags the parts by more than the campaign's warming spans, the expansion alone reads
    /// the wrong temperature and fits values no material has, and only the two together
    /// predict. The refinement alone is no candidate (it refines nothing without its family).
    pub(in crate::diagnose) fn add_followed<'a>(
        &self,
        entries: &mut Vec<Entry<'a>>,
        followers: &'a [Box<dyn Effect>],
    ) {
        let stands_out: Vec<usize> = (0..entries.len())
            .filter(|&k| entries[k].added.len() == 1 && entries[k].swap.is_none())
            .filter(|&k| entries[k].p_value < SCREEN_P)
            .collect();
        for k in stands_out {
            let effect = entries[k].added[0];
            let Some(follower) = followers.iter().find(|f| follows(f.as_ref(), effect)) else {
                continue;
            };
            let added = vec![effect, follower.as_ref()];
            let tried = self.tried((added, None), &[&entries[k].fitted]);
            entries.extend(tried);
        }
    }

    /// Pairs: the best contenders among themselves, and the best with every other
    /// candidate (an effect that only works with another may not stand out alone). A family
    /// takes part whole and by each of its parts alone.
    pub(in crate::diagnose) fn add_pairs<'a>(
        &self,
        entries: &mut Vec<Entry<'a>>,
        candidates: &[Candidate],
        singles: usize,
    ) {
        let mut contenders: Vec<usize> = (0..singles)
            .filter(|&k| entries[k].p_value < SCREEN_P && entries[k].relevant)
            .collect();
        contenders.sort_by(|&a, &b| {
            let bic = |k: usize| entries[k].candidate.map_or(0.0, |i| candidates[i].bic_gain);
            bic(b).total_cmp(&bic(a))
        });
        // a family takes part whole and by each of its parts alone: which part works with
        // the other effect is what the pair finds out (alone, each absorbs part of the other)
        let variants_of = |k: usize, entries: &[Entry<'a>]| -> Vec<usize> {
            let family = effects::family_of(entries[k].added[0].name());
            (0..entries.len())
                .filter(|&j| j == k || entries[j].candidate.is_none())
                .filter(|&j| entries[j].added.len() == 1)
                .filter(|&j| effects::family_of(entries[j].added[0].name()) == family)
                .filter(|&j| j == k || !entries[j].added[0].name().contains('+'))
                .collect()
        };
        let mut pairs: Vec<(usize, usize)> = Vec::new();
        let top: Vec<usize> = contenders.iter().copied().take(PAIRED).collect();
        for (n, &a) in top.iter().enumerate() {
            for &b in &top[n + 1..] {
                pairs.push((a, b));
            }
        }
        if let Some(&first) = top.first() {
            for b in (0..singles).filter(|b| *b != first && !top.contains(b)) {
                pairs.push((first, b));
            }
        }
        let pairs: Vec<(usize, usize)> = pairs
            .into_iter()
            .flat_map(|(a, b)| {
                let vb = variants_of(b, entries);
                variants_of(a, entries)
                    .into_iter()
                    .flat_map(move |x| vb.clone().into_iter().map(move |y| (x, y)))
            })
            .collect();
        for (a, b) in pairs {
            let added = vec![entries[a].added[0], entries[b].added[0]];
            let tried = self.tried((added, None), &[&entries[a].fitted, &entries[b].fitted]);
            entries.extend(tried);
        }
    }

    /// The best contenders with each other part combination of a family of the current
    /// model (`swaps`: its variants): adding an effect may change the parts a family keeps
    /// (a guide's bow absorbed by the frame's expansion until the bow is in the model).
    pub(in crate::diagnose) fn add_swaps<'a>(
        &self,
        entries: &mut Vec<Entry<'a>>,
        swaps: &'a [Box<dyn Effect>],
        singles: usize,
    ) where
        'j: 'a,
    {
        let settled: Vec<&str> = self.in_model.iter().map(|e| e.name()).collect();
        let mut contenders: Vec<usize> = (0..singles)
            .filter(|&k| entries[k].p_value < SCREEN_P && entries[k].relevant)
            .collect();
        contenders.sort_by(|&a, &b| entries[a].p_value.total_cmp(&entries[b].p_value));
        contenders.truncate(PAIRED);
        // a family's other parts only where what refines it still refines parts it holds
        let swaps: Vec<&'a dyn Effect> = swaps
            .iter()
            .map(AsRef::as_ref)
            .filter(|v| !settled.contains(&v.name()))
            .filter(|v| refines_within(&self.model_of(&[], Some(*v))))
            .collect();
        for k in contenders {
            for &v in &swaps {
                let added = vec![entries[k].added[0]];
                let tried = self.tried((added, Some(v)), &[&entries[k].fitted]);
                entries.extend(tried);
            }
        }
    }
}

/// The library's effects that refine a family among `tried` ([`Effect::beside`]) and are
/// not tried themselves, whole and by each part combination: the partners
/// [`Judge::add_followed`] gives a family that stands out.
pub(crate) fn followers(
    library: &[Box<dyn Effect>],
    tried: &[&dyn Effect],
) -> Vec<Box<dyn Effect>> {
    let names: Vec<&str> = tried.iter().map(|e| e.name()).collect();
    let mut out = Vec::new();
    for f in library.iter().filter(|f| !names.contains(&f.name())) {
        let Some(of) = f.beside() else { continue };
        if !tried.iter().any(|e| e.name() == of && e.open_family()) {
            continue;
        }
        out.extend(crate::effects::by_name(f.name()).ok());
        out.extend(part_variants(&[f.as_ref()], false));
    }
    out
}

/// Whether `follower` refines `effect` on the same parts: `thermal_lag` for `thermal`,
/// `thermal_lag:rods+frame` for `thermal:rods+frame`.
fn follows(follower: &dyn Effect, effect: &dyn Effect) -> bool {
    let parts = |name: &str| name.split_once(':').map(|(_, p)| p.to_owned());
    follower.beside() == Some(effects::family_of(effect.name()))
        && parts(follower.name()) == parts(effect.name())
}

/// Every proper part combination of each family among `effects` named whole (thermal: rods,
/// frame, scales, and the pairs of them), and without `whole` each effect's refinements
/// ([`Effect::refinements`]) and each proper part combination of a refinement pinned to its
/// family's parts (`thermal_lag:frame` of `thermal_lag:frame+scales`): what the search tries
/// where a family stands out; with `whole`, the whole family too (the variants of a family
/// in the current model, whose refinements the current model settles itself).
pub(crate) fn part_variants(effects: &[&dyn Effect], whole: bool) -> Vec<Box<dyn Effect>> {
    let mut out = Vec::new();
    if !whole {
        out.extend(effects.iter().flat_map(|e| e.refinements()));
        out.extend(effects.iter().flat_map(|e| pinned_parts(*e)));
    }
    for family in effects.iter().filter(|e| e.open_family()) {
        let n = family.parts().len();
        let last = if whole {
            1usize << n
        } else {
            (1usize << n) - 1
        };
        for mask in 1..last {
            let parts: Vec<usize> = (0..n).filter(|b| mask & (1 << b) != 0).collect();
            out.extend(family.with_parts(&parts));
        }
    }
    out
}

/// Each proper part combination of an effect that refines a family ([`Effect::beside`])
/// pinned to some of its parts (`thermal_lag:rods+frame`: `thermal_lag:rods`,
/// `thermal_lag:frame`); none for any other.
fn pinned_parts(effect: &dyn Effect) -> Vec<Box<dyn Effect>> {
    let whole = effect
        .beside()
        .and_then(|_| effects::by_name(effects::family_of(effect.name())).ok());
    let (Some(whole), Some(kept)) = (whole, effects::pinned_parts(effect)) else {
        return Vec::new();
    };
    (1..(1usize << kept.len()) - 1)
        .filter_map(|mask| {
            let parts: Vec<usize> = (0..kept.len())
                .filter(|b| mask & (1 << b) != 0)
                .map(|b| kept[b])
                .collect();
            whole.with_parts(&parts)
        })
        .collect()
}

/// Whether every effect of `model` that refines a family of it ([`Effect::beside`]:
/// `thermal_lag` beside `thermal`) holds only parts that family holds: a lag of a part that
/// does not expand is no physics (the lag of frame and scales fitted beside the scales'
/// expansion stood in for an encoder scale of 5 ppm).
fn refines_within(model: &[&dyn Effect]) -> bool {
    model.iter().all(|f| {
        let Some(of) = f.beside() else {
            return true;
        };
        model
            .iter()
            .find(|e| effects::family_of(e.name()) == of)
            .is_none_or(|refined| {
                let held = effects::held_parts(*refined);
                effects::held_parts(*f).iter().all(|p| held.contains(p))
            })
    })
}

#[cfg(test)]
mod tests {
    use super::refines_within;
    use crate::effects::{by_name, Effect};

    /// A lag keeps to the parts the expansion holds, whole or pinned.
    #[test]
    fn a_lag_refines_only_parts_that_expand() {
        let within = |names: &[&str]| {
            let boxed: Vec<Box<dyn Effect>> = names
                .iter()
                .map(|n| by_name(n).expect("library effect"))
                .collect();
            let model: Vec<&dyn Effect> = boxed.iter().map(AsRef::as_ref).collect();
            refines_within(&model)
        };
        assert!(within(&["thermal:frame+scales", "thermal_lag:scales"]));
        assert!(within(&["thermal", "thermal_lag:rods"]));
        assert!(within(&["thermal:rods", "thermal_lag:rods"]));
        assert!(within(&["thermal_lag:frame"]));
        assert!(!within(&["thermal:scales", "thermal_lag:frame+scales"]));
        assert!(!within(&["thermal:rods", "thermal_lag"]));
    }
}
