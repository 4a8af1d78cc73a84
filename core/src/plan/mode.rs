//! The drive mode a plan measures its external instruments in. A redundant machine with all
//! four drives position-controlled is preloaded: a geometric error becomes internal force
//! and the rods stretch, which a model without the preload's deflection
//! (`preload_elastic`) cannot represent. So a plan measures in the mode of the campaign's
//! external rows (the mode the model was calibrated in), with all drives active only where
//! the model carries the preload and the drive forces are recorded, or in the mode the user
//! names.

use crate::campaign::{Campaign, Instrument};
use crate::design::FOLLOWERS_23;
use crate::effects::{Effect, Family};

/// Whether the model carries the preload's deflection (`preload_elastic`): where it does
/// not, a pose with all four drives active carries a deflection the model cannot represent.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Preload {
    Modelled,
    NotModelled,
}

impl Preload {
    /// Of the effects in the model: modelled where one is of the preload's family (whole,
    /// or a rod of its own).
    pub fn of(effects: &[&dyn Effect]) -> Preload {
        if effects
            .iter()
            .any(|e| Family::of(e.name()) == Some(Family::PreloadElastic))
        {
            Preload::Modelled
        } else {
            Preload::NotModelled
        }
    }
}

/// Why the plan's drives are in their mode.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum DriveModeReason {
    /// The user named it (`--follower`).
    Named,
    /// The model carries the preload's deflection and the campaign recorded the drive
    /// forces of poses with all four drives active.
    PreloadModelled,
    /// The mode of the campaign's external rows: `rows` of its `of` external rows.
    Campaign { rows: usize, of: usize },
    /// The campaign has no external row, and the model no preload: q2, q3 follow, as in
    /// self-calibration, so that no planned pose carries a preload.
    NoPreload,
}

/// The drives' mode of a plan's external-instrument poses (`follower[i]` for q(i+1), the
/// campaign's column), and why.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct DriveMode {
    pub follower: [bool; 4],
    pub reason: DriveModeReason,
}

impl DriveMode {
    /// Whether all four drives are position-controlled (the preload's mode).
    pub fn all_active(&self) -> bool {
        self.follower == [false; 4]
    }
}

/// Whether a pose of `campaign` was measured with all four drives active and its drive
/// forces recorded: what `preload_elastic` reads its deflection from.
fn loaded(campaign: &Campaign) -> bool {
    campaign
        .poses
        .iter()
        .any(|p| p.follower == [false; 4] && p.f.iter().any(|f| *f != 0.0))
}

/// The mode of a plan's external poses on `campaign`: `named` where the user named one; all
/// drives active where the model carries the preload and the campaign recorded loaded
/// drive forces; else the mode most of the campaign's external rows were measured in (the
/// first such mode on a tie); else q2, q3 following.
pub fn drive_mode(campaign: &Campaign, preload: Preload, named: Option<[bool; 4]>) -> DriveMode {
    if let Some(follower) = named {
        return DriveMode {
            follower,
            reason: DriveModeReason::Named,
        };
    }
    if preload == Preload::Modelled && loaded(campaign) {
        return DriveMode {
            follower: [false; 4],
            reason: DriveModeReason::PreloadModelled,
        };
    }
    let external: Vec<[bool; 4]> = campaign
        .poses
        .iter()
        .filter(|p| p.instrument.takes_reset() && p.instrument != Instrument::Circle)
        .map(|p| p.follower)
        .collect();
    let mut counts: Vec<([bool; 4], usize)> = Vec::new();
    for f in &external {
        match counts.iter_mut().find(|(g, _)| g == f) {
            Some((_, n)) => *n += 1,
            None => counts.push((*f, 1)),
        }
    }
    // the first of the most common: `max_by_key` keeps the last of equals
    let most = counts.iter().rev().max_by_key(|(_, n)| *n).copied();
    match most {
        Some((follower, rows)) => DriveMode {
            follower,
            reason: DriveModeReason::Campaign {
                rows,
                of: external.len(),
            },
        },
        None => DriveMode {
            follower: FOLLOWERS_23,
            reason: DriveModeReason::NoPreload,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::campaign::MeasuredPose;

    fn pose(instrument: Instrument, follower: [bool; 4], f: f64) -> MeasuredPose {
        MeasuredPose {
            t: 0.0,
            setup: "s".into(),
            instrument,
            reset: false,
            q: [0.0; 4],
            f: [f; 4],
            follower,
            x: None,
            y: None,
            r: None,
            psi: None,
            covariates: Vec::new(),
            line: 0,
        }
    }

    fn campaign(poses: Vec<MeasuredPose>) -> Campaign {
        Campaign {
            source: "c".into(),
            comments: Vec::new(),
            covariate_names: Vec::new(),
            poses,
        }
    }

    /// Tracker rows with q2, q3 following and self rows: the plan follows them; with the
    /// preload in the model but no loaded forces recorded it still does; a campaign whose
    /// tracker rows are loaded, with forces, measures all active once the model carries the
    /// preload, and as its rows without it; a named mode wins; nothing external: q2, q3.
    #[test]
    fn the_mode_of_the_campaign_unless_the_model_carries_the_preload() {
        let follow = campaign(vec![
            pose(Instrument::SelfCal, FOLLOWERS_23, 0.0),
            pose(Instrument::Lt, FOLLOWERS_23, 0.0),
            pose(Instrument::Lt, FOLLOWERS_23, 0.0),
            pose(Instrument::Kgm, [false; 4], 0.0),
        ]);
        let m = drive_mode(&follow, Preload::NotModelled, None);
        assert_eq!(m.follower, FOLLOWERS_23);
        assert_eq!(m.reason, DriveModeReason::Campaign { rows: 2, of: 3 });
        assert_eq!(
            drive_mode(&follow, Preload::Modelled, None).follower,
            FOLLOWERS_23
        );
        let loaded = campaign(vec![
            pose(Instrument::SelfCal, FOLLOWERS_23, 0.0),
            pose(Instrument::Lt, [false; 4], 800.0),
        ]);
        let m = drive_mode(&loaded, Preload::Modelled, None);
        assert!(m.all_active());
        assert_eq!(m.reason, DriveModeReason::PreloadModelled);
        let m = drive_mode(&loaded, Preload::NotModelled, None);
        assert!(m.all_active(), "the campaign's mode: {m:?}");
        let named = drive_mode(&loaded, Preload::Modelled, Some(FOLLOWERS_23));
        assert_eq!(named.follower, FOLLOWERS_23);
        assert_eq!(named.reason, DriveModeReason::Named);
        let self_only = campaign(vec![pose(Instrument::SelfCal, FOLLOWERS_23, 0.0)]);
        let m = drive_mode(&self_only, Preload::NotModelled, None);
        assert_eq!(m.follower, FOLLOWERS_23);
        assert_eq!(m.reason, DriveModeReason::NoPreload);
    }

    /// The preload is modelled by its family whole or by a rod of its own, by no other.
    #[test]
    fn the_preload_is_modelled_by_its_family_or_a_refinement() {
        let of = |names: &[&str]| {
            let boxed: Vec<_> = names
                .iter()
                .map(|n| crate::effects::by_name(n).expect("a library effect"))
                .collect();
            let refs: Vec<&dyn Effect> = boxed.iter().map(AsRef::as_ref).collect();
            Preload::of(&refs)
        };
        assert_eq!(of(&[]), Preload::NotModelled);
        assert_eq!(of(&["thermal", "parallelogram"]), Preload::NotModelled);
        assert_eq!(of(&["thermal", "preload_elastic"]), Preload::Modelled);
        assert_eq!(of(&["preload_elastic:rod3"]), Preload::Modelled);
    }
}
