//! The machines `rpkm bench discovery` draws: a class, its hidden effects and conventions, the
//! campaign's composition, the written effects a user of that class would offer, and the
//! held-out floor the truth gives.

use anyhow::Result;
use rand::{rngs::StdRng, Rng, SeedableRng};
use rpkm_core::campaign::{Campaign, Instrument};
use rpkm_core::effects::{self, Family};
use rpkm_core::noise::{NoiseModel, N_GROUPS};
use rpkm_nodes::effects_file::{self, EffectsFile};
use rpkm_twin::{EffectKind, ThermalPhysics, Twin, TwinConfig, ZeroDrift};
use std::collections::BTreeMap;
use std::fmt::Write;

/// The kinds of machine the bench draws, each reported on its own line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, serde::Serialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
#[value(rename_all = "snake_case")]
pub enum Class {
    /// Nothing hidden.
    Nothing,
    /// One or two effects of the library.
    Library,
    /// Lost motion (backlash), outside the library.
    LostMotion,
    /// A periodic error of one carrier's scale, 1-5 µm over a pitch of 10-200 mm, outside
    /// the library.
    Cyclic,
    /// All drives active (preload_elastic) and one rod 0.5-0.8x or 1.25-2x as stiff as the
    /// others: `preload_elastic` named, settled to the rod's own compliance
    /// (`preload_elastic:rodN`), and nothing missing.
    SoftRod,
    /// An instrument alignment 0.2-1x its default: down to where it hardly matters.
    SmallAlignment,
    /// Thermal expansion measured by a tracker and self-calibration only: a campaign that
    /// cannot separate every part of the family.
    FamilyApart,
    /// Thermal expansion with all drives active (preload_elastic): each alone predicts worse,
    /// the two together at the floor.
    ThermalPreload,
    /// The guides warm at rates of their own (0.5-0.85x and 1.15-1.5x the mean), with a
    /// thermometer on each guide or without.
    Gradient,
    /// The tracker's readings creep 0.5-2 µm per minute after each zero; the user offers
    /// the drift written as data (`dx: "-vx * 1e-3 * t / 60"`).
    TrackerDrift,
    /// Lost motion of carrier 4 and a periodic scale error at once, both outside the library
    /// and both offered written as data.
    TwoOutside,
    /// Thermal expansion read by thermometers 2-30 minutes behind the parts (a first-order
    /// lag), measured by a tracker, a grid encoder and self-calibration or by a tracker and
    /// self-calibration only: `thermal` and `thermal_lag` named, `nothing_missing` (a lag
    /// too short to matter may go unnamed at the floor). Drawn on demand only
    /// (`--class thermometer_lag`): the series' machines stay the ones earlier figures and
    /// tests name.
    ThermometerLag,
}

/// How many kinds of machine the series draws (k in `0..KINDS`).
const KINDS: u32 = 35;

/// The classes drawn only on demand, outside the series.
const ON_DEMAND: [Class; 1] = [Class::ThermometerLag];

/// What a machine hides: its class and its hidden effects of the twin.
pub(super) struct Hidden {
    pub class: Class,
    pub effects: Vec<EffectKind>,
}

fn log_uniform(rng: &mut StdRng, lo: f64, hi: f64) -> f64 {
    (rng.gen_range(lo.ln()..hi.ln())).exp()
}

/// The class of machine `k` (0..KINDS) and its hidden effects.
fn hidden_of(k: u32, rng: &mut StdRng) -> Hidden {
    let library: Vec<EffectKind> = EffectKind::ALL
        .iter()
        .copied()
        .filter(|e| !e.outside_library())
        .collect();
    let pick = |rng: &mut StdRng| library[rng.gen_range(0..library.len())];
    let (class, effects) = match k {
        0..=5 => (Class::Nothing, Vec::new()),
        6..=13 => (Class::Library, vec![pick(rng)]),
        14..=15 => {
            let first = pick(rng);
            let mut second = pick(rng);
            while second == first {
                second = pick(rng);
            }
            (Class::Library, vec![first, second])
        }
        16..=17 => (Class::LostMotion, vec![EffectKind::Backlash]),
        18..=20 => (Class::Cyclic, Vec::new()),
        21..=22 => (Class::SoftRod, vec![EffectKind::PreloadElastic]),
        23..=24 => (Class::SmallAlignment, vec![EffectKind::InstrumentAlignment]),
        25..=26 => (Class::FamilyApart, vec![EffectKind::Thermal]),
        27..=28 => (
            Class::ThermalPreload,
            vec![EffectKind::PreloadElastic, EffectKind::Thermal],
        ),
        29..=30 => (Class::Gradient, vec![EffectKind::Thermal]),
        31..=32 => (Class::TrackerDrift, Vec::new()),
        _ => (Class::TwoOutside, vec![EffectKind::LostMotionQ4]),
    };
    Hidden { class, effects }
}

/// A machine of the bench: the twin's configuration, what it hides, and the campaign's
/// instruments.
pub(super) struct Machine {
    pub config: TwinConfig,
    pub hidden: Hidden,
    pub instruments: Vec<Instrument>,
}

/// Machine `i` of the series `seed`: its hidden effects and conventions; of a class drawn
/// on demand ([`ON_DEMAND`]) where `class` is one, else the series' own machine.
pub(super) fn draw(seed: u64, i: usize, class: Option<Class>) -> Machine {
    let mut rng = StdRng::seed_from_u64(seed.wrapping_mul(0x9e37_79b9).wrapping_add(i as u64));
    let k = rng.gen_range(0..KINDS);
    let hidden = match class.filter(|c| ON_DEMAND.contains(c)) {
        Some(class) => Hidden {
            class,
            effects: vec![EffectKind::Thermal],
        },
        None => hidden_of(k, &mut rng),
    };
    let noise: [f64; N_GROUPS] = std::array::from_fn(|_| log_uniform(&mut rng, 0.5, 3.0));
    let thermal = thermal_of(&mut rng, hidden.class);
    let (lo, hi) = if hidden.class == Class::SmallAlignment {
        (0.2, 1.0)
    } else {
        (0.3, 3.0)
    };
    let effects = hidden
        .effects
        .iter()
        .map(|e| (*e, e.default_magnitude() * log_uniform(&mut rng, lo, hi)))
        .collect();
    let mut stiffness = rpkm_core::elastic::Stiffness::default();
    if hidden.class == Class::SoftRod {
        let rod = rng.gen_range(0..4);
        stiffness.rod[rod] *= if rng.gen_bool(0.5) {
            rng.gen_range(0.5..0.8)
        } else {
            rng.gen_range(1.25..2.0)
        };
    }
    let cyclic =
        matches!(hidden.class, Class::Cyclic | Class::TwoOutside).then(|| rpkm_twin::CyclicScale {
            carrier: rng.gen_range(0..4),
            amplitude_mm: rng.gen_range(1e-3..5e-3),
            pitch_mm: log_uniform(&mut rng, 10.0, 200.0),
            phase: rng.gen_range(0.0..std::f64::consts::TAU),
        });
    let drift = (hidden.class == Class::TrackerDrift).then(|| {
        let (speed, heading) = (
            rng.gen_range(0.5e-3..2e-3) / 60.0,
            rng.gen_range(0.0..std::f64::consts::TAU),
        );
        ZeroDrift {
            instrument: Instrument::Lt,
            rate_per_s: [speed * heading.cos(), speed * heading.sin()],
        }
    });
    let apart = match hidden.class {
        Class::FamilyApart => true,
        Class::ThermometerLag => rng.gen_bool(0.5),
        _ => false,
    };
    let instruments = if apart {
        vec![Instrument::Lt, Instrument::SelfCal]
    } else {
        vec![Instrument::Lt, Instrument::Kgm, Instrument::SelfCal]
    };
    let config = TwinConfig {
        stiffness,
        cyclic,
        drift,
        seed: rng.gen(),
        effects,
        length_sigma_mm: rng.gen_range(0.05..0.1),
        angle_sigma_rad: rng.gen_range(1e-4..3e-4),
        noise: Some(NoiseModel::default().scaled(&noise)),
        thermal,
        ..Default::default()
    };
    Machine {
        config,
        hidden,
        instruments,
    }
}

/// Which thermal parts expand and how fast (5-25 ppm/K each, at least one), and for a
/// gradient the guides' own rates and whether each has a thermometer.
fn thermal_of(rng: &mut StdRng, class: Class) -> ThermalPhysics {
    let mut parts = [0.0; 3];
    while parts.iter().all(|p| *p == 0.0) {
        for p in &mut parts {
            *p = if rng.gen_bool(0.5) {
                rng.gen_range(5e-6..25e-6)
            } else {
                0.0
            };
        }
    }
    let mut physics = ThermalPhysics {
        rods_per_k: parts[0],
        frame_per_k: parts[1],
        scales_per_k: parts[2],
        ..Default::default()
    };
    if class == Class::Gradient {
        let (slow, fast) = (rng.gen_range(0.5..0.85), rng.gen_range(1.15..1.5));
        physics.guide_rates = if rng.gen_bool(0.5) {
            [slow, fast]
        } else {
            [fast, slow]
        };
        physics.guide_thermometers = rng.gen_bool(0.5);
    }
    if class == Class::ThermometerLag {
        physics.thermometer_lag_s = log_uniform(rng, 120.0, 1800.0);
    }
    physics
}

/// The calibration and held-out campaigns of a machine, and the held-out floor the truth
/// gives.
pub(super) struct Measured {
    pub cal: Campaign,
    pub val: Campaign,
    /// The RMS (µm) of the held-out readings' own errors (the same poses measured without
    /// noise): what a perfect model predicts, each reading's zero noise included.
    pub floor_um: f64,
    /// The same with each setup's mean error removed per coordinate (as the diagnosis
    /// removes each setup's zero), and the count of values less those means: n − g.
    pub floor_relative_um: f64,
    pub relative_dof: usize,
}

/// Measures a machine's campaigns on its twin, and again without noise for the floor.
pub(super) fn measure(m: &Machine) -> Result<Measured> {
    let run = |config: TwinConfig| -> Result<(Campaign, Campaign)> {
        let mut twin = Twin::new(config)?;
        let cal = twin.campaign(&m.instruments)?;
        Ok((cal, twin.validation(100)?))
    };
    let (cal, val) = run(m.config.clone())?;
    let (_, clean) = run(TwinConfig {
        noise: None,
        ..m.config.clone()
    })?;
    let (floor_relative_um, relative_dof) = relative_floor(&val, &clean);
    Ok(Measured {
        floor_um: rpkm_twin::reading_error_rms_um(&val, &clean),
        cal,
        val,
        floor_relative_um,
        relative_dof,
    })
}

/// The held-out readings' own errors with each setup's mean removed per coordinate: their
/// RMS (µm) and the values' count less the means removed.
fn relative_floor(noisy: &Campaign, clean: &Campaign) -> (f64, usize) {
    let mut by_setup: BTreeMap<&str, Vec<[f64; 2]>> = BTreeMap::new();
    for (p, q) in noisy
        .poses
        .iter()
        .zip(&clean.poses)
        .filter(|(p, _)| !p.reset)
    {
        let (Some(px), Some(py), Some(qx), Some(qy)) = (p.x, p.y, q.x, q.y) else {
            continue;
        };
        by_setup
            .entry(p.setup.as_str())
            .or_default()
            .push([px - qx, py - qy]);
    }
    let (mut sum, mut n, mut g) = (0.0, 0usize, 0usize);
    for errors in by_setup.values() {
        for c in 0..2 {
            let mean = errors.iter().map(|e| e[c]).sum::<f64>() / errors.len() as f64;
            sum += errors.iter().map(|e| (e[c] - mean).powi(2)).sum::<f64>();
        }
        n += 2 * errors.len();
        g += 2;
    }
    (1e3 * (sum / n.max(1) as f64).sqrt(), n.saturating_sub(g))
}

/// The effects a user of this class writes and offers beside the library (none for most):
/// the tracker's drift, the lost motion and the cyclic scale error of the carrier the
/// diagnosis's period pointer names, at its pitch.
pub(super) fn offered(m: &Machine, columns: &[String]) -> Result<Option<EffectsFile>> {
    let text = offered_text(m)?;
    if text.is_empty() {
        return Ok(None);
    }
    let file = effects_file::parse(&text, "bench", columns)
        .map_err(|e| anyhow::anyhow!("the bench's written effects: {e}"))?;
    Ok(Some(file))
}

/// [`offered`]'s effects file as a user writes it (empty where nothing is offered).
pub(super) fn offered_text(m: &Machine) -> Result<String> {
    let mut text = String::new();
    if m.hidden.class == Class::TrackerDrift {
        write!(
            text,
            "  - name: {}\n    summary: the tracker's readings creep after its zero\n    \
             params: {{vx: {{unit: um/min, prior: 1}}, vy: {{unit: um/min, prior: 1}}}}\n    \
             instruments: [lt]\n    dx: \"-vx * 1e-3 * t / 60\"\n    \
             dy: \"-vy * 1e-3 * t / 60\"\n",
            Offered::TrackerDrift.name()
        )?;
    }
    if m.hidden.class == Class::TwoOutside {
        write!(
            text,
            "  - name: {}\n    summary: carrier 4 lags behind its last move\n    \
             params: {{b: {{unit: mm, prior: 0.01}}}}\n    dq4: \"-b * dir_q4\"\n",
            Offered::LostMotionQ4.name()
        )?;
    }
    if let (Class::TwoOutside, Some(c)) = (m.hidden.class, &m.config.cyclic) {
        let (q, pitch) = (c.carrier + 1, c.pitch_mm);
        write!(
            text,
            "  - name: {name}\n    summary: a periodic error of carrier {q}'s scale\n    \
             params: {{a: {{unit: mm, prior: 0.005}}, c: {{unit: mm, prior: 0.005}}}}\n    \
             dq{q}: \"a * sin(2*pi*q{q}/{pitch}) + c * cos(2*pi*q{q}/{pitch})\"\n",
            name = Offered::CyclicScale.name()
        )?;
    }
    Ok(if text.is_empty() {
        text
    } else {
        format!("effects:\n{text}")
    })
}

/// The hidden effects by name, as the report lists them: the twin's kinds, and the
/// conventions outside the library (named by the written effect a user offers, where one
/// is offered).
pub(super) fn hidden_names(hidden: &Hidden) -> Vec<String> {
    let mut out: Vec<String> = hidden
        .effects
        .iter()
        .map(|e| e.as_str().to_owned())
        .collect();
    match hidden.class {
        Class::Cyclic | Class::TwoOutside => out.push(Offered::CyclicScale.name().to_owned()),
        Class::SoftRod => out.push("soft_rod".to_owned()),
        Class::TrackerDrift => out.push(Offered::TrackerDrift.name().to_owned()),
        Class::ThermometerLag => out.push(Family::ThermalLag.name().to_owned()),
        _ => {}
    }
    out
}

/// An effect the bench offers written as data (its effects file, [`offered_text`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Offered {
    TrackerDrift,
    LostMotionQ4,
    CyclicScale,
}

impl Offered {
    const ALL: [Offered; 3] = [
        Offered::TrackerDrift,
        Offered::LostMotionQ4,
        Offered::CyclicScale,
    ];

    /// Its name in the file: the one thing that tells a written effect.
    pub(super) const fn name(self) -> &'static str {
        match self {
            Offered::TrackerDrift => "tracker_drift",
            Offered::LostMotionQ4 => "lost_motion_q4",
            Offered::CyclicScale => "cyclic_scale",
        }
    }
}

/// An effect the loop names, by identity: a family of the library (whole), an effect the
/// bench offers, or any other name (a family pinned to parts, a written effect not offered:
/// nothing a machine hides).
#[derive(Clone, Debug, PartialEq, Eq)]
pub(super) enum Named {
    Family(Family),
    Offered(Offered),
    Other(String),
}

impl Named {
    /// The effect the loop calls `name`.
    pub(super) fn of(name: &str) -> Named {
        let whole = effects::family_of(name) == name;
        match Family::of(name).filter(|_| whole) {
            Some(f) => Named::Family(f),
            None => Offered::ALL
                .into_iter()
                .find(|o| o.name() == name)
                .map_or_else(|| Named::Other(name.to_owned()), Named::Offered),
        }
    }
}

/// The effects the loop should name for what `hidden` hides: each hidden kind of the
/// library by its family, each convention outside it by the written effect the bench offers
/// for it (none for lost motion of guide 2 or a periodic scale error alone, which nothing
/// offered describes, nor for a rod of its own stiffness, the preload's refinement).
pub(super) fn nameable(hidden: &Hidden) -> Vec<Named> {
    let mut out: Vec<Named> = hidden
        .effects
        .iter()
        .filter_map(|&k| match k {
            EffectKind::LostMotionQ4 => Some(Named::Offered(Offered::LostMotionQ4)),
            k => k.family().map(Named::Family),
        })
        .collect();
    match hidden.class {
        Class::TwoOutside => out.push(Named::Offered(Offered::CyclicScale)),
        Class::TrackerDrift => out.push(Named::Offered(Offered::TrackerDrift)),
        Class::ThermometerLag => out.push(Named::Family(Family::ThermalLag)),
        _ => {}
    }
    out
}

/// The hidden effects as a model of the library holding exactly the twin's parts
/// (`thermal:rods+frame`, `thermal_lag:rods+frame`), where the class hides nothing else:
/// what the bench fits beside the loop to learn whether the campaigns let the truth itself
/// pass. None for the other classes.
pub(super) fn truth_model(m: &Machine) -> Option<Vec<String>> {
    if m.hidden.class != Class::ThermometerLag {
        return None;
    }
    let t = &m.config.thermal;
    let parts: Vec<&str> = [
        ("rods", t.rods_per_k),
        ("frame", t.frame_per_k),
        ("scales", t.scales_per_k),
    ]
    .iter()
    .filter(|(_, rate)| *rate != 0.0)
    .map(|(part, _)| *part)
    .collect();
    let parts = parts.join("+");
    Some(vec![
        format!("{}:{parts}", Family::Thermal.name()),
        format!("{}:{parts}", Family::ThermalLag.name()),
    ])
}

/// Whether `class` is drawn on demand only ([`ON_DEMAND`]).
pub(super) fn on_demand(class: Class) -> bool {
    ON_DEMAND.contains(&class)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The first machine of series 1 of `class`.
    fn first_of(class: Class) -> Machine {
        (0..500)
            .map(|i| draw(1, i, None))
            .find(|m| m.hidden.class == class)
            .unwrap_or_else(|| panic!("no {class:?} machine among the first 500"))
    }

    /// The truth the bench fits beside the loop holds exactly the parts the twin expands,
    /// in both families, each name one the effects list parses; a class with more than the
    /// thermal families hidden has none.
    #[test]
    fn the_truth_model_holds_the_parts_the_twin_expands() {
        for i in 0..12 {
            let m = draw(1, i, Some(Class::ThermometerLag));
            let t = &m.config.thermal;
            let rate = |part: &str| match part {
                "rods" => t.rods_per_k,
                "frame" => t.frame_per_k,
                _ => t.scales_per_k,
            };
            let names = truth_model(&m).expect("a lag machine's truth is a model");
            let model = effects_file::parse_list(&names.join(","), None).expect("its names parse");
            let families: Vec<&str> = model.iter().map(|e| effects::family_of(e.name())).collect();
            assert_eq!(families, ["thermal", "thermal_lag"], "machine {i}");
            for e in &model {
                let held = effects::held_parts(e.as_ref());
                for part in e.parts() {
                    assert_eq!(
                        held.contains(part),
                        rate(part) > 0.0,
                        "machine {i}: {}",
                        e.name()
                    );
                }
            }
        }
        assert!(truth_model(&first_of(Class::ThermalPreload)).is_none());
    }

    /// The judge's identities of the names the loop gives: each library effect whole is its
    /// family, one pinned to parts is not; an effect the bench offers is the one its file
    /// names, and the file offers exactly the written effects the judge wants named.
    #[test]
    fn the_loop_s_names_are_the_judge_s_effects() {
        for e in effects::library() {
            let family = Family::of(e.name()).expect("a library effect has a family");
            assert_eq!(Named::of(e.name()), Named::Family(family));
        }
        assert_eq!(
            Named::of("thermal:rods"),
            Named::Other("thermal:rods".to_owned())
        );
        for class in [Class::TwoOutside, Class::TrackerDrift] {
            let m = first_of(class);
            let columns = ["t", "dir_q4", "q1", "q2", "q3", "q4"].map(str::to_owned);
            let file = offered(&m, &columns)
                .expect("the bench's file parses")
                .expect("a file offered");
            let mut in_file: Vec<Named> = file.all().iter().map(|e| Named::of(e.name())).collect();
            let mut wanted: Vec<Named> = nameable(&m.hidden)
                .into_iter()
                .filter(|n| matches!(n, Named::Offered(_)))
                .collect();
            let key = |n: &Named| format!("{n:?}");
            in_file.sort_by_key(key);
            wanted.sort_by_key(key);
            assert_eq!(in_file, wanted, "{class:?}");
            assert!(!wanted.is_empty(), "{class:?}");
        }
    }
}
