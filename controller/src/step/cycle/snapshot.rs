//! What a resumed session needs of the work cycle: the plan so far, where it stands, the statistics
//! of the finished digs, the floor estimate and the hardness index ([`CycleSnapshot`]), taken while
//! the cycle is between actions and put back into a fresh cycle.

use planner::cleanup::FloorEstimate;
use planner::kinematics::Kinematics;
use serde::{Deserialize, Serialize};

use super::{Action, DigStats, Phase, WorkCycle};
use crate::ControllerError;

/// The work cycle's part of a saved session (see [`crate::session::session_state`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CycleSnapshot {
    /// The plan so far (the config's list, or every action the planner pushed).
    pub actions: Vec<Action>,
    /// The index of the next action to run.
    pub action_index: usize,
    /// Digs and cleanups completed.
    pub digs_done: u32,
    /// Their statistics, in order.
    pub stats: Vec<DigStats>,
    /// The floor elevation detected by the cleanups.
    pub floor: FloorEstimate,
    /// Autodig's soil hardness index.
    pub hardness_index: f64,
}

impl WorkCycle {
    /// The cycle's state for a saved session.
    pub fn snapshot(&self) -> CycleSnapshot {
        CycleSnapshot {
            actions: self.config.actions.clone(),
            action_index: self.action_index,
            digs_done: self.digs_done,
            stats: self.stats.clone(),
            floor: self.floor,
            hardness_index: self.autodig_config.hardness_index,
        }
    }

    /// Puts a saved session's state into this fresh cycle: with an external plan the saved actions
    /// replace the (empty) list; a fixed plan must be the saved one. The cycle starts from Idle at
    /// the saved action.
    ///
    /// # Errors
    /// [`ControllerError::Config`] when this cycle has run already or its fixed plan differs from
    /// the saved one, [`ControllerError::Kinematics`] for an unreachable saved start.
    pub fn restore(&mut self, s: &CycleSnapshot, kin: &Kinematics) -> Result<(), ControllerError> {
        let refuse = |field, reason: &str| ControllerError::Config {
            field,
            reason: reason.to_owned(),
        };
        if self.phase != Phase::Idle || self.action_index != 0 || !self.stats.is_empty() {
            return Err(refuse("cycle", "a running cycle cannot be restored"));
        }
        if s.action_index > s.actions.len() || s.stats.len() != s.digs_done as usize {
            return Err(refuse("cycle", "inconsistent saved cycle"));
        }
        if self.external_plan {
            self.config.actions.clear();
            self.starts.clear();
            for a in &s.actions {
                self.push_action(*a, kin)?;
            }
        } else if self.config.actions != s.actions {
            return Err(refuse(
                "cycle.actions",
                "the saved plan is not this configuration's",
            ));
        }
        self.action_index = s.action_index;
        self.digs_done = s.digs_done;
        self.stats.clone_from(&s.stats);
        self.floor = s.floor;
        self.set_hardness_index(s.hardness_index);
        Ok(())
    }
}
