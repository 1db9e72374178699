//! What a prediction starts from and gives: the dig site and start, the per-step samples of the
//! trace, the summary and the end reason.

use super::{DigModelError, Result};
use crate::autodig::{EndReason, Stage};
use crate::kinematics::{BucketPose, JointAngles, MachinePose, TipForce};
use crate::terrain::{SectionProfile, TerrainGrid};
use serde::{Deserialize, Serialize};

/// The terrain a dig is predicted over: the pre-dig section along the digging plane and the floor.
#[derive(Debug, Clone, PartialEq)]
pub struct DigSite {
    pub(super) profile: SectionProfile,
    pub(super) floor_z_m: f64,
}

impl DigSite {
    /// A site from a section profile (base-frame `x` = distance from the swing axis) and the floor
    /// elevation in the base frame, m.
    ///
    /// # Errors
    /// [`DigModelError::NonFinite`] for a non-finite floor.
    pub fn new(profile: SectionProfile, floor_z_m: f64) -> Result<Self> {
        if !floor_z_m.is_finite() {
            return Err(DigModelError::NonFinite {
                what: "floor elevation",
            });
        }
        Ok(Self { profile, floor_z_m })
    }

    /// The section of a terrain map along the digging plane at `swing_rad` from `r_start_m` to
    /// `r_end_m` every `step_m` (thesis 3.2's pre-dig section).
    ///
    /// # Errors
    /// [`DigModelError::Terrain`] for unknown cells (gaps), a range outside the map or a bad range;
    /// [`DigModelError::NonFinite`].
    pub fn from_grid(
        grid: &TerrainGrid,
        pose: &MachinePose,
        swing_rad: f64,
        r_start_m: f64,
        r_end_m: f64,
        step_m: f64,
        floor_z_m: f64,
    ) -> Result<Self> {
        Self::new(
            grid.section(pose, swing_rad, r_start_m, r_end_m, step_m)?,
            floor_z_m,
        )
    }

    /// The pre-dig section.
    #[must_use]
    pub fn profile(&self) -> &SectionProfile {
        &self.profile
    }

    /// Floor elevation, m (base frame).
    #[must_use]
    pub fn floor_z_m(&self) -> f64 {
        self.floor_z_m
    }
}

/// Where a dig starts (Autodig starts in Pre-Dig there: the bucket on the terrain, thesis 4.1).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum DigStart {
    /// A bucket pose (tip and `bucket_abs`); joint angles by inverse kinematics (stick under the boom).
    Pose(BucketPose),
    /// Joint angles (e.g. the measured start of a recorded dig).
    Joints(JointAngles),
}

/// Why a predicted dig ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum DigEnd {
    /// Autodig reached Done; the reason of the last stage that ended.
    Autodig(EndReason),
    /// The time limit ([`DigModelConfig::max_time_s`](super::DigModelConfig::max_time_s)) was reached first.
    TimeLimit,
}

/// One step of a predicted dig.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DigSample {
    /// Time since the start, s.
    pub time_s: f64,
    /// Autodig stage the command belongs to.
    pub stage: Stage,
    /// Tip `x` (distance from the swing axis), m.
    pub tip_x_m: f64,
    /// Tip `z`, m.
    pub tip_z_m: f64,
    /// Bucket angle to the horizontal, rad.
    pub bucket_abs_rad: f64,
    /// Joint angles `[boom, stick, bucket]`, rad.
    pub joint_rad: [f64; 3],
    /// Autodig commands `[boom, stick, bucket]`, fractions of maximum cylinder velocity.
    pub command: [f64; 3],
    /// Head pressures, Pa.
    pub head_pa: [f64; 3],
    /// Rod pressures, Pa.
    pub rod_pa: [f64; 3],
    /// Cylinder forces, N (Eq. A20 sign).
    pub force_n: [f64; 3],
    /// Cylinder velocities, m/s.
    pub velocity_m_per_s: [f64; 3],
    /// Soil force on the bucket (base frame), after the force factor.
    pub soil_force: TipForce,
    /// Swept volume so far, m^3.
    pub swept_volume_m3: f64,
}

/// A preallocated trajectory buffer: [`DigModel::predict_into`](super::DigModel::predict_into) records into it without growing it.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct DigTrace {
    pub(super) samples: Vec<DigSample>,
    pub(super) truncated: bool,
}

impl DigTrace {
    /// A buffer for `max_steps` samples (a dig of `max_time_s` needs `max_time_s / dt + 1`).
    #[must_use]
    pub fn with_capacity(max_steps: usize) -> Self {
        Self {
            samples: Vec::with_capacity(max_steps),
            truncated: false,
        }
    }

    /// The recorded samples.
    #[must_use]
    pub fn samples(&self) -> &[DigSample] {
        &self.samples
    }

    /// Whether the dig had more steps than the buffer holds (the rest was not recorded).
    #[must_use]
    pub fn truncated(&self) -> bool {
        self.truncated
    }

    pub(super) fn clear(&mut self) {
        self.samples.clear();
        self.truncated = false;
    }

    #[inline]
    pub(super) fn push(&mut self, s: DigSample) {
        if self.samples.len() < self.samples.capacity() {
            self.samples.push(s);
        } else {
            self.truncated = true;
        }
    }
}

/// The statistics of a predicted dig (the dig planner's inputs, thesis 5.1.1.2).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DigSummary {
    /// Dig time from the start to Autodig's Done (or the time limit), s.
    pub time_s: f64,
    /// Energy `sum_i |F_i dL_i|` over the cylinders, J.
    pub energy_j: f64,
    /// Volume swept over the cutting edge (3.2), m^3.
    pub swept_volume_m3: f64,
    /// The tip went below the floor elevation minus the tolerance.
    pub floor_penetration: bool,
    /// Lowest tip elevation, m.
    pub min_tip_z_m: f64,
    /// Why the dig ended.
    pub end: DigEnd,
    /// Model steps run.
    pub steps: usize,
    /// Largest soil force magnitude `|(F_x, F_z)|`, N.
    pub peak_soil_force_n: f64,
}

impl DigSummary {
    /// Energy, kJ.
    #[must_use]
    pub fn energy_kj(&self) -> f64 {
        self.energy_j * 1e-3
    }
}

/// A predicted dig: statistics and the trajectory (tip, commands, pressures, forces per step).
#[derive(Debug, Clone, PartialEq)]
pub struct DigPrediction {
    /// The statistics.
    pub summary: DigSummary,
    /// The trajectory.
    pub samples: Vec<DigSample>,
}
