//! Action selection (thesis Fig. 42): dig if the best dig is good enough, else track back if the
//! machine can move back far enough, else clean up.
//!
//! ```text
//! if dig quality > minimum quality                      then execute a dig
//! else if tracking distance > minimum tracking distance then track the machine backwards
//! else                                                       execute a cleanup
//! ```
//!
//! The bias is toward removing material by digging and avoiding the slow cleanups; the cleanup removes
//! the farthest material, which may let the machine track back on the next cycle. When no cleanup plan
//! is eligible either, there is nothing left to do from this position ([`ActionChoice::Nothing`]).

use super::cleanup_track::{CleanupCandidate, CleanupTrackPlan};
use super::refined::DigChoice;
use serde::{Deserialize, Serialize};

/// The three actions of Fig. 42 by kind (the decision table without the plans).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ActionKind {
    /// Execute the dig.
    Dig,
    /// Track the machine backwards.
    TrackBack,
    /// Execute a cleanup.
    Cleanup,
}

/// Fig. 42 on the two quantities the dig planner provides.
#[must_use]
pub fn fig42(
    dig_quality: f64,
    min_quality: f64,
    tracking_distance_m: f64,
    min_tracking_distance_m: f64,
) -> ActionKind {
    if dig_quality > min_quality {
        ActionKind::Dig
    } else if tracking_distance_m > min_tracking_distance_m {
        ActionKind::TrackBack
    } else {
        ActionKind::Cleanup
    }
}

/// The selected action with its plan.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum ActionChoice {
    /// Dig from the refined planner's best start.
    Dig(DigChoice),
    /// Track straight back.
    TrackBack {
        /// Distance, m.
        distance_m: f64,
    },
    /// Clean up along the chosen plan.
    Cleanup(CleanupCandidate),
    /// Fig. 42 asks for a cleanup but no plan is eligible, or for another track back with no
    /// material in view after [`super::ActionConfig::max_blind_track_backs`] of them: nothing useful
    /// to do from here.
    Nothing,
}

impl ActionChoice {
    /// The kind, `None` for [`ActionChoice::Nothing`].
    #[must_use]
    pub fn kind(&self) -> Option<ActionKind> {
        match self {
            Self::Dig(_) => Some(ActionKind::Dig),
            Self::TrackBack { .. } => Some(ActionKind::TrackBack),
            Self::Cleanup(_) => Some(ActionKind::Cleanup),
            Self::Nothing => None,
        }
    }
}

/// Fig. 42 with the plans: the best dig (if any), the cleanup and tracking plans.
#[must_use]
pub fn select_action(
    best_dig: Option<&DigChoice>,
    cleanup_track: &CleanupTrackPlan,
    min_quality: f64,
    min_tracking_distance_m: f64,
) -> ActionChoice {
    let quality = best_dig.map_or(0.0, |d| d.quality.quality);
    match fig42(
        quality,
        min_quality,
        cleanup_track.tracking_distance_m,
        min_tracking_distance_m,
    ) {
        ActionKind::Dig => best_dig.map_or(ActionChoice::Nothing, |d| ActionChoice::Dig(d.clone())),
        ActionKind::TrackBack => ActionChoice::TrackBack {
            distance_m: cleanup_track.tracking_distance_m,
        },
        ActionKind::Cleanup => cleanup_track
            .chosen
            .map_or(ActionChoice::Nothing, ActionChoice::Cleanup),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fig42_decision_table() {
        use ActionKind::*;
        // (quality, tracking distance) -> action, with minimum quality 3 and minimum distance 0.5 m.
        let table = [
            (4.0, 0.0, Dig),
            (4.0, 2.0, Dig),
            (3.0, 2.0, TrackBack), // "greater than" the minimum, not equal
            (0.0, 0.6, TrackBack),
            (2.9, 0.5, Cleanup),
            (0.0, 0.0, Cleanup),
            (f64::NAN, f64::NAN, Cleanup),
        ];
        for (q, d, want) in table {
            assert_eq!(fig42(q, 3.0, d, 0.5), want, "q = {q}, d = {d}");
        }
    }

    #[test]
    fn cleanup_without_an_eligible_plan_is_nothing() {
        let ct = CleanupTrackPlan {
            reach_m: 9.0,
            candidates: Vec::new(),
            chosen: None,
            tracking_distance_m: 0.0,
            limiting_swing_rad: None,
            material_found: false,
        };
        assert_eq!(select_action(None, &ct, 3.0, 0.5), ActionChoice::Nothing);
        let far = CleanupTrackPlan {
            tracking_distance_m: 1.3,
            ..ct
        };
        assert_eq!(
            select_action(None, &far, 3.0, 0.5),
            ActionChoice::TrackBack { distance_m: 1.3 }
        );
    }
}
