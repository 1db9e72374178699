//! Per-dig statistics ([`DigStats`]) and the record a dig keeps while it runs.

use planner::autodig::EndReason;
use planner::cleanup::HandOverReason;
use serde::{Deserialize, Serialize};

use super::action::ActionKind;
use super::weigh::WeighAverage;

/// Statistics of one dig or cleanup (thesis 6.1, Tables 3 and 4).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DigStats {
    /// The dig's place in the session, from 0 (its index in the statistics); people see
    /// [`DigStats::number`].
    pub index: u32,
    /// Dig or cleanup.
    pub action: ActionKind,
    /// Swing angle of the digging plane, rad.
    pub swing_rad: f64,
    /// When the dig began (Boom-Down or the cleanup probe), s (bus time).
    pub start_time_s: f64,
    /// Duration from the start of Boom-Down (or of the cleanup) to the end of Capture, s.
    pub time_s: f64,
    /// Time the bucket tip was below the pre-dig terrain, s (thesis 6.1); 0 without a terrain map.
    pub ground_contact_time_s: f64,
    /// Energy: the integral of |cylinder force x cylinder displacement| summed over the three
    /// cylinders during the dig, J (thesis 6.1; energy spent lowering against a holding pressure counts
    /// too, as the pumps deliver it).
    pub energy_j: f64,
    /// Volume swept over the cutting edge (3.2), m^3; 0 without a terrain map.
    pub swept_volume_m3: f64,
    /// Weight of the material from the static payload estimate after Capture, N (`None` if the
    /// estimate was unavailable).
    pub weight_n: Option<f64>,
    /// Why Autodig ended.
    pub end_reason: Option<EndReason>,
    /// Why cleanup waypoint following ended (cleanups only).
    pub hand_over: Option<HandOverReason>,
    /// The floor elevation used by a cleanup, m (base frame).
    pub floor_z_m: Option<f64>,
    /// Whether the perception enhancements were active.
    pub perception: bool,
}

/// The dig number people see, from 1, for the dig at `index` (from 0) of a session: the log lines,
/// the live view and the reports say "dig 1" for the first dig, as the bus's `DigIndex` does (it
/// counts the digs begun, so it is the number of the dig in progress or the last one finished).
pub const fn dig_number(index: u32) -> u32 {
    index.saturating_add(1)
}

impl DigStats {
    /// The dig number people see, from 1 ([`dig_number`]).
    pub const fn number(&self) -> u32 {
        dig_number(self.index)
    }

    /// Energy in kJ (the unit of the thesis's tables).
    pub fn energy_kj(&self) -> f64 {
        self.energy_j * 1e-3
    }
}

#[derive(Debug, Clone, Copy)]
pub(super) struct DigRecord {
    pub(super) stats: DigStats,
    pub(super) last_lengths_m: Option<[f64; 3]>,
    pub(super) last_s: Option<f64>,
    pub(super) weigh: WeighAverage,
    /// Weigh found the implement supported: lifts so far and the boom angle of the current lift.
    pub(super) weigh_lifts: u32,
    pub(super) weigh_lift_to_rad: Option<f64>,
}

impl DigRecord {
    /// The record of an action begun at `start_time_s`: nothing measured yet.
    pub(super) fn started(
        index: u32,
        action: ActionKind,
        swing_rad: f64,
        start_time_s: f64,
        perception: bool,
    ) -> Self {
        Self {
            stats: DigStats {
                index,
                action,
                swing_rad,
                start_time_s,
                time_s: 0.0,
                ground_contact_time_s: 0.0,
                energy_j: 0.0,
                swept_volume_m3: 0.0,
                weight_n: None,
                end_reason: None,
                hand_over: None,
                floor_z_m: None,
                perception,
            },
            last_lengths_m: None,
            last_s: None,
            weigh: WeighAverage::default(),
            weigh_lifts: 0,
            weigh_lift_to_rad: None,
        }
    }
}
