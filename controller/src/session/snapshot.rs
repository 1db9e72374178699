//! The serialized types of a session, shared by the session driver, the planned session and the
//! state file: the snapshots a checkpoint holds ([`DriverSnapshot`] with the planned session's
//! [`PlannedSnapshot`] and its [`TerrainSnapshot`]), and the values they carry ([`Strategy`],
//! [`PredefinedSequence`], [`PlannedDig`]). Each snapshot checks itself on loading ([`Validate`]).
//! The behaviour lives with the owners: [`PredefinedSequence::new`](crate::session::planned) in
//! the planned session, the taking and restoring of snapshots in the driver and the planned session.

use planner::estimate::SoilSample;
use planner::kinematics::{JointAngles, MachinePose};
use planner::plan::PlannerState;
use planner::soil::EmpiricalSoilModel;
use planner::terrain::TerrainGrid;
use serde::{Deserialize, Serialize};

use crate::session::state_file::{FieldError, Validate, all_finite, finite};
use crate::step::cycle::{Action, CycleSnapshot};

/// Which action source drives the cycle (`demo --strategy planned|predefined`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Strategy {
    /// The perception-based dig planner (5.1).
    Planned,
    /// The predefined excavation sequence (6.2).
    Predefined,
}

/// The predefined excavation sequence of 6.2.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PredefinedSequence {
    /// Implement joint angles of every dig start (the median of the planner's).
    pub start: JointAngles,
    /// Swing angles of the regions, in dig order (from the spoil side).
    pub swings_rad: Vec<f64>,
    /// Cleanup start radius: the far reach at floor level, m.
    pub cleanup_start_m: f64,
    /// Cleanup end radius, m.
    pub cleanup_min_m: f64,
    /// Cleanup start pose height over the floor and bucket angle.
    pub cleanup_start_z_m: f64,
    /// Cleanup start bucket angle to the horizontal, rad.
    pub cleanup_bucket_abs_rad: f64,
    /// Track-back distance, m (1.3 in the thesis).
    pub backup_m: f64,
}

/// What the planner predicted for an action it pushed (for the dig's record).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlannedDig {
    /// Dig quality (Eq. 26 terms weighted).
    pub quality: Option<f64>,
    /// Predicted swept volume, m^3.
    pub volume_m3: Option<f64>,
    /// Predicted time, s.
    pub time_s: Option<f64>,
    /// Predicted energy, kJ.
    pub energy_kj: Option<f64>,
    /// Predicted lowest tip height, m.
    pub min_tip_z_m: Option<f64>,
    /// Planned start `[r_m, z_m, bucket_deg]` in the base frame.
    pub start: Option<[f64; 3]>,
}

/// A terrain map in a state file: unknown cells are `null` (JSON has no NaN).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TerrainSnapshot {
    /// World position of the grid's lower-left corner `[x, y]`, m.
    pub origin_m: [f64; 2],
    /// Cell size, m.
    pub resolution_m: f64,
    /// Cells along x.
    pub nx: usize,
    /// Cells along y.
    pub ny: usize,
    /// Heights row-major (`j * nx + i`), m; `null` for an unknown cell.
    pub heights_m: Vec<Option<f64>>,
}

impl TerrainSnapshot {
    /// The map `grid`.
    #[must_use]
    pub fn of(grid: &TerrainGrid) -> Self {
        let heights_m = (0..grid.ny())
            .flat_map(|j| (0..grid.nx()).map(move |i| (i, j)))
            .map(|(i, j)| grid.cell(i, j))
            .collect();
        Self {
            origin_m: grid.origin(),
            resolution_m: grid.resolution_m(),
            nx: grid.nx(),
            ny: grid.ny(),
            heights_m,
        }
    }

    /// The grid (validated first: [`Validate`]).
    ///
    /// # Errors
    /// A field naming what the grid refused.
    pub fn grid(&self) -> Result<TerrainGrid, FieldError> {
        let mut grid = TerrainGrid::new_unknown(
            self.origin_m[0],
            self.origin_m[1],
            self.resolution_m,
            self.nx,
            self.ny,
        )
        .map_err(|e| FieldError::new("nx", e.to_string()))?;
        for (k, h) in self.heights_m.iter().enumerate() {
            grid.set_cell(k % self.nx, k / self.nx, *h)
                .map_err(|e| FieldError::new(format!("heights_m[{k}]"), e.to_string()))?;
        }
        Ok(grid)
    }
}

impl Validate for TerrainSnapshot {
    fn validate(&self) -> Result<(), FieldError> {
        all_finite("origin_m", &self.origin_m)?;
        finite("resolution_m", self.resolution_m)?;
        if self.heights_m.len() != self.nx.saturating_mul(self.ny) {
            return Err(FieldError::new(
                "heights_m",
                format!(
                    "{} cells, the grid has {} x {}",
                    self.heights_m.len(),
                    self.nx,
                    self.ny
                ),
            ));
        }
        Ok(())
    }
}

/// An action the planned session handed out, without its plan (the plans stay in the session
/// that made them: `last_plan.json` and `refined_grid.svg` show only the plans of the running
/// process).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StepSnapshot {
    /// The action.
    pub action: Action,
    /// The pose it was planned at.
    pub pose: MachinePose,
}

/// The planned session's part of a saved session.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlannedSnapshot {
    /// The action source.
    pub strategy: Strategy,
    /// What persists between planning cycles (region pointer, cleanup tries, abandoned starts).
    pub planner: PlannerState,
    /// The terrain map.
    pub terrain: TerrainSnapshot,
    /// Scans fused into the map.
    pub map_scans: u64,
    /// The predefined sequence, once set up.
    pub predefined: Option<PredefinedSequence>,
    /// The predefined sequence's next position.
    pub predefined_index: usize,
    /// The latest soil estimate (5.2): it sets the hardness index again.
    pub soil_estimate: Option<EmpiricalSoilModel>,
    /// The joint angles of the dig starts pushed so far.
    pub dig_starts: Vec<JointAngles>,
    /// World-frame start tips of planned digs whose pass is not yet observed.
    pub unconfirmed_digs: Vec<[f64; 3]>,
    /// The actions handed out so far.
    pub steps: Vec<StepSnapshot>,
    /// Whether the session has nothing left to do.
    pub finished: bool,
    /// Why.
    pub end_reason: Option<String>,
}

impl Validate for PlannedSnapshot {
    fn validate(&self) -> Result<(), FieldError> {
        self.terrain.validate().map_err(|e| e.within("terrain"))?;
        if let Some(m) = &self.soil_estimate {
            all_finite("soil_estimate.fx", &m.fx)?;
            all_finite("soil_estimate.fz", &m.fz)?;
            all_finite("soil_estimate.my", &m.my)?;
        }
        for (k, tip) in self.unconfirmed_digs.iter().enumerate() {
            all_finite(&format!("unconfirmed_digs[{k}]"), tip)?;
        }
        Ok(())
    }
}

/// The session driver's part of a saved session (module docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DriverSnapshot {
    /// The work cycle.
    pub cycle: CycleSnapshot,
    /// The dead-reckoned world pose.
    pub pose: MachinePose,
    /// The track odometry reading `[left, right]` the pose belongs to, m.
    pub odometry_m: Option<[f64; 2]>,
    /// What the planner predicted for each action, by action index.
    pub planned: Vec<PlannedDig>,
    /// Wall time of each planning cycle, ms.
    pub plan_ms: Vec<f64>,
    /// The soil estimator's window (4.3.5), oldest first.
    pub soil_window: Vec<SoilSample>,
    /// Track backs begun.
    pub track_backs: usize,
    /// Track backs completed.
    pub backups: usize,
    /// The predefined sequence's start joints.
    pub predefined_joints: Option<JointAngles>,
    /// Why the planner ended the session, once it has.
    pub over: Option<String>,
    /// The planned session (planned and predefined strategies).
    pub session: Option<PlannedSnapshot>,
}

impl Validate for DriverSnapshot {
    fn validate(&self) -> Result<(), FieldError> {
        let c = &self.cycle;
        if c.action_index > c.actions.len() {
            return Err(FieldError::new(
                "cycle.action_index",
                format!("{} beyond the {} actions", c.action_index, c.actions.len()),
            ));
        }
        if c.stats.len() != c.digs_done as usize {
            return Err(FieldError::new(
                "cycle.stats",
                format!("{} records for {} digs", c.stats.len(), c.digs_done),
            ));
        }
        finite("cycle.hardness_index", c.hardness_index)?;
        all_finite(
            "pose",
            &[self.pose.x_m, self.pose.y_m, self.pose.heading_rad],
        )?;
        if let Some(o) = &self.odometry_m {
            all_finite("odometry_m", o)?;
        }
        if self.planned.len() > c.actions.len() + 1 {
            return Err(FieldError::new(
                "planned",
                format!(
                    "{} predictions for {} actions",
                    self.planned.len(),
                    c.actions.len()
                ),
            ));
        }
        all_finite("plan_ms", &self.plan_ms)?;
        if self.backups > self.track_backs {
            return Err(FieldError::new(
                "backups",
                format!("{} of {} track backs", self.backups, self.track_backs),
            ));
        }
        if let Some(s) = &self.session {
            s.validate().map_err(|e| e.within("session"))?;
        }
        Ok(())
    }
}
