//! Dig planning (thesis chapter 5): where to dig, when to clean the floor, how far to track back, and
//! the soil hardness index Autodig should use.
//!
//! # Layout (data flows top to bottom)
//!
//! - [`mapper`]: [`TerrainMapper`] keeps the terrain grid current from successive range scans (5.3).
//! - [`region`]: a dig region, the strip of the workspace the coarse planner lays out and the refined
//!   planner searches.
//! - [`coarse`]: the coarse dig location planner (5.1.1.1, Fig. 44): the workspace between the machine
//!   and the nearer of the bench edge and the kinematic reach, within +-30 degrees of the tracks, cut into
//!   regions one bucket wide, ordered away from the spoil side, with a region pointer.
//! - [`refined`]: the refined planner (5.1.1.2, Figs. 45-48): candidate starts `(d, alpha)` over one
//!   region, kinematic and floor constraints, the dig model ([`crate::dig_model`]) and the dig quality of
//!   Fig. 46.
//! - [`cleanup_track`]: the cleanup and tracking planners (5.1.2, Figs. 49-51).
//! - [`action`]: the action selection of Fig. 42.
//! - [`hardness`]: the soil hardness index from the average soil force (5.2, Eq. 25, Fig. 53), and the
//!   simulation that fits its regression.
//!
//! [`Planner`] runs one planning cycle (coarse + refined + cleanup + tracking + selection) on a terrain
//! map and a machine pose; [`PlannerState`] carries what persists between cycles (the region pointer and
//! the per-swing-angle cleanup counters). Everything here is pure computation: no I/O, no clock,
//! deterministic for its inputs, typed errors and never a panic.
//!
//! Frames: the terrain map is in the world frame; plans are in the machine's base frame (docs/
//! ARCHITECTURE.md): swing angles counter-clockwise from the tracks' forward direction (positive = left),
//! radii from the swing axis, heights above the ground the tracks stand on. The desired floor elevation
//! is a base-frame height (0 when the floor is the ground the machine stands on).

pub mod action;
pub mod cleanup_track;
pub mod coarse;
pub mod hardness;
pub mod mapper;
pub mod refined;
pub mod region;

pub use action::{ActionChoice, select_action};
pub use cleanup_track::{
    CleanupCandidate, CleanupConfig, CleanupStatus, CleanupTrackPlan, MaterialBoundary,
    TrackingConfig, TrackingLimit, reach_track_distance_m, view_track_distance_m,
};
pub use coarse::{CoarseConfig, CoarsePlan, SpoilSide};
pub use hardness::{HardnessRegression, average_soil_force_n};
pub use mapper::TerrainMapper;
pub use refined::{
    Candidate, CandidateStatus, DigChoice, DigQuality, QualityConfig, RefinedConfig, RefinedPlan,
};
pub use region::DigRegion;

use crate::dig_model::{ActuatorDynamics, DigModel, DigModelError};
use crate::estimate::EstimateError;
use crate::kinematics::{Kinematics, KinematicsError, MachinePose};
use crate::machine::MachineConfig;
use crate::terrain::{TerrainError, TerrainGrid};
use gateway_core::range::Limits;
use serde::{Deserialize, Serialize};

/// The shipped planner settings (`config/planner.toml`).
pub const DEFAULT_PLANNER_TOML: &str = include_str!("../../../config/planner.toml");

/// Planner errors.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlanError {
    /// A configuration value is invalid.
    #[error("planner config {field}: {reason}")]
    Config {
        /// The field.
        field: &'static str,
        /// What is wrong.
        reason: String,
    },
    /// A NaN or infinite input.
    #[error("non-finite input: {what}")]
    NonFinite {
        /// Which input.
        what: &'static str,
    },
    /// An input out of its range.
    #[error("invalid input: {what}")]
    InvalidInput {
        /// Which input and why.
        what: &'static str,
    },
    /// The terrain map.
    #[error("terrain: {0}")]
    Terrain(#[from] TerrainError),
    /// The dig model (other than the per-candidate rejections, which are candidate statuses).
    #[error("dig model: {0}")]
    DigModel(#[from] DigModelError),
    /// Kinematics.
    #[error("kinematics: {0}")]
    Kinematics(#[from] KinematicsError),
    /// Soil property estimation.
    #[error("soil estimation: {0}")]
    Estimate(#[from] EstimateError),
    /// The machine cannot reach any point of the workspace.
    #[error("no reachable workspace: {what}")]
    NoWorkspace {
        /// Why.
        what: &'static str,
    },
}

/// Result alias for this module.
pub type Result<T> = std::result::Result<T, PlanError>;

/// Fig. 42's thresholds.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ActionConfig {
    /// Dig when the best dig's quality exceeds this. Default 3.0 (of at most 6 with the default
    /// weights: a dig needs about a full bucket to pass).
    pub min_quality: f64,
    /// Track back when the allowed distance exceeds this, m. Default 0.5.
    pub min_track_distance_m: f64,
    /// Try further regions in order when the pointer's region has no dig above `min_quality`
    /// (the thesis refines one region per cycle; this keeps a poor region from stopping the dig).
    /// Default true.
    pub search_all_regions: bool,
    /// With no material in view, Fig. 42 tracks back (the bench the machine stands on lies behind
    /// the sensor's view); after this many such blind track backs in a row the bench is taken as
    /// removed and the planner chooses nothing, which ends the session (thesis test 3: "bench
    /// removed"). Without the limit a machine that reached the end of its bench, or of a simulated
    /// map, tracked back 3 m at a time until its time budget ran out (a 200-dig session: 3250 track
    /// backs, about 10 km). Default 2.
    pub max_blind_track_backs: u32,
}

impl Default for ActionConfig {
    fn default() -> Self {
        Self {
            min_quality: 3.0,
            min_track_distance_m: 0.5,
            search_all_regions: true,
            max_blind_track_backs: 2,
        }
    }
}

/// All planner settings (`config/planner.toml`; angles in degrees there).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PlannerConfig {
    /// Desired floor elevation in the base frame, m (0: the ground the tracks stand on).
    pub floor_z_m: f64,
    /// Coarse planner (5.1.1.1).
    pub coarse: CoarseConfig,
    /// Refined planner (5.1.1.2).
    pub refined: RefinedConfig,
    /// Dig quality (Fig. 46).
    pub quality: QualityConfig,
    /// Cleanup planner (5.1.2).
    pub cleanup: CleanupConfig,
    /// Tracking planner (5.1.2, Fig. 51).
    pub tracking: TrackingConfig,
    /// Action selection (Fig. 42).
    pub action: ActionConfig,
}

impl PlannerConfig {
    /// Parses and validates `config/planner.toml`.
    ///
    /// # Errors
    /// [`PlanError::Config`] naming the problem.
    pub fn from_toml_str(text: &str) -> Result<Self> {
        let cfg: Self = toml::from_str(text).map_err(|e| PlanError::Config {
            field: "planner.toml",
            reason: e.to_string(),
        })?;
        cfg.validate()?;
        Ok(cfg)
    }

    /// The shipped settings ([`DEFAULT_PLANNER_TOML`]).
    ///
    /// # Errors
    /// As [`Self::from_toml_str`] (the shipped file is tested).
    pub fn nominal() -> Result<Self> {
        Self::from_toml_str(DEFAULT_PLANNER_TOML)
    }

    /// Checks every section.
    ///
    /// # Errors
    /// [`PlanError::Config`] naming the field.
    pub fn validate(&self) -> Result<()> {
        finite("floor_z_m", self.floor_z_m)?;
        self.coarse.validate()?;
        self.refined.validate()?;
        self.quality.validate()?;
        self.cleanup.validate()?;
        self.tracking.validate()?;
        finite("action.min_quality", self.action.min_quality)?;
        non_negative(
            "action.min_track_distance_m",
            self.action.min_track_distance_m,
        )
    }
}

/// `Ok` if `v` is finite and within `limits` ([`gateway_core::range`]), else the config error naming
/// `field`, the value and the rule.
pub(crate) fn within(field: &'static str, v: f64, limits: Limits) -> Result<()> {
    limits.check(v).map_err(|e| PlanError::Config {
        field,
        reason: format!("{v}: {e}"),
    })
}

pub(crate) fn finite(field: &'static str, v: f64) -> Result<()> {
    within(field, v, Limits::FINITE)
}

pub(crate) fn positive(field: &'static str, v: f64) -> Result<()> {
    within(field, v, Limits::POSITIVE)
}

pub(crate) fn non_negative(field: &'static str, v: f64) -> Result<()> {
    within(field, v, Limits::NON_NEGATIVE)
}

/// What persists between planning cycles.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct PlannerState {
    /// Index (in dig order) of the region the coarse planner offers next (5.1.1.1: the regions are dug
    /// in order so the bench erodes evenly).
    pub region_pointer: usize,
    /// Cleanups executed per swing-angle bin since the last track back (5.1.2: "not cleanable" after
    /// repeated tries), keyed by the bin index of [`CleanupConfig::swing_step_rad`].
    pub cleanup_tries: std::collections::BTreeMap<i32, u32>,
    /// World-frame tips `[x, y, z]` of dig starts the work cycle could not reach since the last track
    /// back (its move to the start timed out): the refined planner does not choose a start within
    /// [`ABANDONED_START_RADIUS_M`] of one again (the map is unchanged, so it would choose the same
    /// start forever: without this, one start was chosen 28 times in a row, 40 s each).
    #[serde(default)]
    pub abandoned_starts: Vec<[f64; 3]>,
    /// Track backs in a row that were made with no material in view (reset by a dig or a cleanup,
    /// and by a track back with material in view); see [`ActionConfig::max_blind_track_backs`].
    #[serde(default)]
    pub blind_track_backs: u32,
}

/// Distance from an abandoned dig start within which the refined planner chooses no start, m (a
/// candidate grid step and a half: 0.2 m in `d`, 5 deg in `alpha`).
pub const ABANDONED_START_RADIUS_M: f64 = 0.3;

impl PlannerState {
    /// Records that a cleanup ran at `swing_rad` (call when the controller executed a planned cleanup).
    pub fn record_cleanup(&mut self, swing_rad: f64, cfg: &CleanupConfig) {
        if let Some(bin) = cfg.bin(swing_rad) {
            *self.cleanup_tries.entry(bin).or_insert(0) += 1;
        }
        self.blind_track_backs = 0;
    }

    /// Records a track back: the swing angles of the material changed, so the counters restart.
    /// `blind`: the plan that chose it saw no material (its
    /// [`CleanupTrackPlan::material_found`] was false).
    pub fn record_track_back(&mut self, blind: bool) {
        self.cleanup_tries.clear();
        self.abandoned_starts.clear();
        self.blind_track_backs = if blind {
            self.blind_track_backs.saturating_add(1)
        } else {
            0
        };
    }

    /// Records that the dig starting with the tip at `tip_world` (world frame) was abandoned before
    /// it dug: the machine could not reach the start.
    pub fn record_abandoned_dig(&mut self, tip_world: [f64; 3]) {
        self.abandoned_starts.push(tip_world);
    }

    /// Records that the dig in region `index` (dig order) was executed: the pointer moves past it.
    pub fn record_dig(&mut self, region_index: usize, region_count: usize) {
        if region_count > 0 {
            self.region_pointer = (region_index + 1) % region_count;
        }
        self.blind_track_backs = 0;
    }
}

/// The result of one planning cycle (Fig. 54's "dig plan": an optimal dig location and its quality,
/// a cleanup plan and a tracking distance), and the action Fig. 42 selects.
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    /// The coarse plan (regions in dig order).
    pub coarse: CoarsePlan,
    /// The refined plans evaluated this cycle, in the order tried (the first is the pointer's region).
    pub refined: Vec<RefinedPlan>,
    /// The best dig found (the one of the first refined plan whose quality passes, else the best seen).
    pub best_dig: Option<DigChoice>,
    /// Cleanup candidates per swing angle, the chosen cleanup and the tracking distance.
    pub cleanup_track: CleanupTrackPlan,
    /// Fig. 42's choice.
    pub action: ActionChoice,
}

/// The dig planner (Fig. 43 and 5.1.2): coarse + refined dig location, cleanup and tracking plans.
#[derive(Debug, Clone)]
pub struct Planner<A: ActuatorDynamics = crate::actuator::ActuatorModel> {
    config: PlannerConfig,
    model: DigModel<A>,
    kin: Kinematics,
    bucket_width_m: f64,
    capacity_m3: f64,
    sensor_height_m: f64,
    sensor_radial_m: f64,
}

impl<A: ActuatorDynamics> Planner<A> {
    /// A planner for `machine` using `model` to evaluate candidate digs. The quality's `V_max` is the
    /// machine's bucket capacity (Fig. 46) unless the config sets it.
    ///
    /// # Errors
    /// [`PlanError::Config`] for invalid settings, [`PlanError::Kinematics`] for an inconsistent
    /// machine.
    pub fn new(machine: &MachineConfig, model: DigModel<A>, config: PlannerConfig) -> Result<Self> {
        config.validate()?;
        let kin = Kinematics::new(machine)?;
        positive("machine.bucket.width_m", machine.bucket.width_m)?;
        positive("machine.bucket.capacity_m3", machine.bucket.capacity_m3)?;
        Ok(Self {
            config,
            model,
            kin,
            bucket_width_m: machine.bucket.width_m,
            capacity_m3: machine.bucket.capacity_m3,
            sensor_height_m: machine.sensor.height_m,
            sensor_radial_m: machine.sensor.radial_offset_m,
        })
    }

    /// The settings.
    #[must_use]
    pub fn config(&self) -> &PlannerConfig {
        &self.config
    }

    /// The dig model (e.g. to replace its soil with estimated properties or set the hardness index).
    pub fn model_mut(&mut self) -> &mut DigModel<A> {
        &mut self.model
    }

    /// The dig model.
    #[must_use]
    pub fn model(&self) -> &DigModel<A> {
        &self.model
    }

    /// The machine's kinematics.
    #[must_use]
    pub fn kinematics(&self) -> &Kinematics {
        &self.kin
    }

    /// Bucket width, m (the width of the coarse regions and of a bucket pass).
    #[must_use]
    pub fn bucket_width_m(&self) -> f64 {
        self.bucket_width_m
    }

    /// Bucket capacity, m^3 (`V_max` of Fig. 46 by default).
    #[must_use]
    pub fn capacity_m3(&self) -> f64 {
        self.capacity_m3
    }

    /// The coarse plan for the machine at `pose` (5.1.1.1).
    ///
    /// # Errors
    /// As [`coarse::plan_regions`].
    pub fn coarse(&self, grid: &TerrainGrid, pose: &MachinePose) -> Result<CoarsePlan> {
        coarse::plan_regions(
            grid,
            pose,
            &self.kin,
            self.bucket_width_m,
            self.config.floor_z_m,
            &self.config.coarse,
            &self.config.refined,
        )
    }

    /// The refined plan over one region (5.1.1.2).
    ///
    /// # Errors
    /// As [`refined::refine`].
    pub fn refine(
        &self,
        grid: &TerrainGrid,
        pose: &MachinePose,
        region: &DigRegion,
    ) -> Result<RefinedPlan> {
        refined::refine(
            &self.model,
            grid,
            pose,
            region,
            self.config.floor_z_m,
            &self.config.refined,
            &self.quality(),
        )
    }

    /// The quality settings with `V_max` defaulted to the bucket capacity.
    #[must_use]
    pub fn quality(&self) -> QualityConfig {
        let mut q = self.config.quality;
        if q.v_max_m3 <= 0.0 {
            q.v_max_m3 = self.capacity_m3;
        }
        q
    }

    /// The cleanup and tracking plans (5.1.2).
    ///
    /// # Errors
    /// As [`cleanup_track::plan_cleanup_and_tracking`].
    pub fn cleanup_and_tracking(
        &self,
        grid: &TerrainGrid,
        pose: &MachinePose,
        state: &PlannerState,
    ) -> Result<CleanupTrackPlan> {
        cleanup_track::plan_cleanup_and_tracking(
            grid,
            pose,
            &self.kin,
            cleanup_track::Geometry {
                floor_z_m: self.config.floor_z_m,
                bucket_width_m: self.bucket_width_m,
                sensor_height_m: self.sensor_height_m,
                sensor_radial_m: self.sensor_radial_m,
                angular_extent_rad: self.config.coarse.angular_extent_rad,
            },
            &self.config.cleanup,
            &self.config.tracking,
            state,
        )
    }

    /// One full planning cycle: the coarse plan, the refined plan of the pointer's region (and, with
    /// `search_all_regions`, of the following regions until one passes the minimum quality), the
    /// cleanup and tracking plans, and Fig. 42's action. `state` is not changed: call
    /// [`PlannerState::record_dig`], [`PlannerState::record_cleanup`] or
    /// [`PlannerState::record_track_back`] when the action was executed.
    ///
    /// # Errors
    /// [`PlanError`] for non-finite input or an unusable terrain map; candidates the dig model cannot
    /// evaluate are candidate statuses, not errors.
    pub fn plan(
        &self,
        grid: &TerrainGrid,
        pose: &MachinePose,
        state: &PlannerState,
    ) -> Result<Plan> {
        let coarse = self.coarse(grid, pose)?;
        let n = coarse.regions.len();
        let mut refined = Vec::new();
        let mut best: Option<DigChoice> = None;
        let min_q = self.config.action.min_quality;
        let tries = if self.config.action.search_all_regions {
            n
        } else {
            n.min(1)
        };
        for k in 0..tries {
            let idx = (state.region_pointer % n.max(1) + k) % n.max(1);
            let Some(region) = coarse.regions.get(idx) else {
                break;
            };
            if !region.has_material {
                continue;
            }
            let mut r = self.refine(grid, pose, region)?;
            if !state.abandoned_starts.is_empty() {
                let near_abandoned = |c: &refined::Candidate| {
                    let [x, y, z] = pose.world_from_base(region.swing_rad, c.pose.x_m, c.pose.z_m);
                    state.abandoned_starts.iter().any(|a| {
                        (a[0] - x).hypot(a[1] - y).hypot(a[2] - z) < ABANDONED_START_RADIUS_M
                    })
                };
                r.best = refined::select_best(&r.candidates, region, &self.kin, near_abandoned);
            }
            if let Some(b) = &r.best
                && best
                    .as_ref()
                    .is_none_or(|x| b.quality.quality > x.quality.quality)
            {
                best = Some(b.clone());
            }
            let passed = r.best.as_ref().is_some_and(|b| b.quality.quality > min_q);
            refined.push(r);
            if passed {
                break;
            }
        }
        let cleanup_track = self.cleanup_and_tracking(grid, pose, state)?;
        let action = match select_action(
            best.as_ref(),
            &cleanup_track,
            min_q,
            self.config.action.min_track_distance_m,
        ) {
            ActionChoice::TrackBack { .. }
                if !cleanup_track.material_found
                    && state.blind_track_backs >= self.config.action.max_blind_track_backs =>
            {
                ActionChoice::Nothing
            }
            a => a,
        };
        Ok(Plan {
            coarse,
            refined,
            best_dig: best,
            cleanup_track,
            action,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shipped_config_parses_and_bad_values_are_rejected() {
        let cfg = PlannerConfig::nominal().expect("shipped planner.toml");
        assert!((cfg.coarse.angular_extent_rad.to_degrees() - 30.0).abs() < 1e-9);
        assert!((cfg.refined.d_step_m - 0.2).abs() < 1e-12);
        assert!((cfg.refined.alpha_step_rad.to_degrees() - 5.0).abs() < 1e-9);
        assert!((cfg.tracking.repose_rad.to_degrees() - 45.0).abs() < 1e-9);
        assert_eq!(
            (
                cfg.quality.w_volume,
                cfg.quality.w_time,
                cfg.quality.w_energy
            ),
            (3.0, 2.0, 1.0)
        );
        assert!(PlannerConfig::from_toml_str("floor_z_m = nan").is_err());
        assert!(PlannerConfig::from_toml_str("[refined]\nd_step_m = 0.0").is_err());
        assert!(PlannerConfig::from_toml_str("bogus = 1").is_err());
        assert!(PlannerConfig::from_toml_str("").is_ok());
    }

    /// The default bench seen from the machine at the origin (config/bench.toml): 2 m high, toe at
    /// 3 m, 45 degree face, 10 m wide.
    fn bench() -> TerrainGrid {
        TerrainGrid::from_fn(-8.0, -10.0, 0.1, 240, 200, |x, y| {
            if y.abs() > 5.0 || x > 13.0 {
                0.0
            } else {
                (x - 3.0).clamp(0.0, 2.0)
            }
        })
        .expect("grid")
    }

    /// A coarser grid than Fig. 45's so the debug-build test stays fast.
    fn test_planner(floor_z_m: f64) -> Planner {
        let machine = MachineConfig::default_machine().expect("machine");
        let mut cfg = PlannerConfig::nominal().expect("config");
        cfg.floor_z_m = floor_z_m;
        cfg.refined.d_step_m = 0.6;
        cfg.refined.alpha_step_rad = 10f64.to_radians();
        Planner::new(&machine, DigModel::nominal().expect("model"), cfg).expect("planner")
    }

    #[test]
    fn an_abandoned_start_is_not_chosen_again_until_a_track_back() {
        let planner = test_planner(-0.5);
        let grid = bench();
        let pose = MachinePose::default();
        let mut state = PlannerState::default();
        let first = planner.plan(&grid, &pose, &state).expect("plan");
        let d = first.best_dig.expect("a dig on the bench");
        let tip = pose.world_from_base(d.swing_rad, d.pose.x_m, d.pose.z_m);
        state.record_abandoned_dig(tip);
        let second = planner.plan(&grid, &pose, &state).expect("plan");
        let e = second.best_dig.expect("another dig on the bench");
        let other = pose.world_from_base(e.swing_rad, e.pose.x_m, e.pose.z_m);
        let dist = (other[0] - tip[0])
            .hypot(other[1] - tip[1])
            .hypot(other[2] - tip[2]);
        assert!(
            dist >= ABANDONED_START_RADIUS_M,
            "{dist} m from the abandoned start"
        );
        state.record_track_back(false);
        let third = planner.plan(&grid, &pose, &state).expect("plan");
        assert_eq!(third.best_dig.map(|b| b.pose), Some(d.pose));
    }

    #[test]
    fn refined_planner_rejects_unreachable_and_floor_penetrating_and_picks_the_best() {
        // The floor 1 m up the 2 m bench: deep digs and starts low on the face go below it (with the
        // retrained dig model, 1.5 m left no dig over the quality's minimum volume).
        let planner = test_planner(1.0);
        let grid = bench();
        let pose = MachinePose::default();
        let coarse = planner.coarse(&grid, &pose).expect("coarse");
        // A region running past the reach, so some candidates are unreachable.
        let region = DigRegion {
            far_r_m: 11.0,
            ..coarse.regions[coarse.regions.len() / 2]
        };
        let r = planner.refine(&grid, &pose, &region).expect("refined");
        assert_eq!(
            r.candidates.len(),
            r.d_values_m.len() * r.alpha_values_rad.len()
        );
        let kin = planner.kinematics();
        let unreachable = r.count(CandidateStatus::Unreachable);
        let penetrating = r.count(CandidateStatus::PenetratesFloor);
        let valid = r.count(CandidateStatus::Valid);
        assert!(
            unreachable > 0 && penetrating > 0 && valid > 0,
            "{unreachable} {penetrating} {valid}"
        );
        for c in &r.candidates {
            match c.status {
                CandidateStatus::Unreachable => {
                    assert!(c.summary.is_none() && kin.inverse(&c.pose).is_err());
                }
                CandidateStatus::PenetratesFloor => {
                    let s = c.summary.expect("evaluated");
                    assert!(s.floor_penetration && c.quality.is_none());
                }
                CandidateStatus::Valid => {
                    assert!(!c.summary.expect("evaluated").floor_penetration);
                    assert!(c.quality.is_some());
                }
                CandidateStatus::ModelFailed => {}
                CandidateStatus::CurledStart => {
                    assert!(c.summary.is_none());
                    assert!(c.pose.bucket_abs_rad < planner.config().refined.bucket_abs_min_rad);
                }
            }
        }
        let best = r.best.as_ref().expect("a valid dig");
        let max = r
            .candidates
            .iter()
            .filter_map(|c| c.quality.map(|q| q.quality))
            .fold(0.0, f64::max);
        assert!((best.quality.quality - max).abs() < 1e-12 && max > 0.0);
        assert!(!best.summary.floor_penetration);
        // The chosen start is executable: its joints put the tip at the pose.
        let tip = kin.forward(&best.joints);
        assert!((tip.x_m - best.pose.x_m).abs() < 1e-6 && (tip.z_m - best.pose.z_m).abs() < 1e-6);
        // Deterministic.
        assert_eq!(planner.refine(&grid, &pose, &region).expect("again"), r);
        // Starts curled past the limit are kept out of the dig model (on the 45 deg face a start
        // at alpha has bucket_abs = alpha - 45 deg; on the floor alpha - 90 deg).
        let cfg = RefinedConfig {
            bucket_abs_min_rad: (-25f64).to_radians(),
            ..planner.config().refined
        };
        let q = planner.quality();
        let c =
            refined::refine(planner.model(), &grid, &pose, &region, 1.0, &cfg, &q).expect("curled");
        assert!(c.count(CandidateStatus::CurledStart) > 0);
        for k in c
            .candidates
            .iter()
            .filter(|k| k.status == CandidateStatus::CurledStart)
        {
            assert!(k.summary.is_none() && k.pose.bucket_abs_rad < cfg.bucket_abs_min_rad);
            assert!(kin.inverse(&k.pose).is_ok());
        }
        assert!(c.count(CandidateStatus::Valid) < valid);
    }

    #[test]
    fn a_full_cycle_on_the_bench_digs_and_on_bare_floor_does_not() {
        let planner = test_planner(0.0);
        let pose = MachinePose::default();
        let plan = planner
            .plan(&bench(), &pose, &PlannerState::default())
            .expect("plan");
        assert!(
            matches!(plan.action, ActionChoice::Dig(_)),
            "{:?}",
            plan.action.kind()
        );
        // The bench runs past the reach: no backing away from it.
        assert_eq!(plan.cleanup_track.tracking_distance_m, 0.0);
        let flat = TerrainGrid::new_flat(-8.0, -10.0, 0.1, 240, 200, 0.0).expect("flat");
        let plan = planner
            .plan(&flat, &pose, &PlannerState::default())
            .expect("plan");
        assert!(plan.refined.is_empty() && plan.best_dig.is_none());
        // Nothing to dig or clean: Fig. 42 tracks back (the bench lies behind the view).
        assert!(!plan.cleanup_track.material_found);
        assert!(matches!(plan.action, ActionChoice::TrackBack { .. }));
    }

    #[test]
    fn state_pointer_and_counters() {
        let cfg = CleanupConfig::default();
        let mut s = PlannerState::default();
        s.record_dig(2, 3);
        assert_eq!(s.region_pointer, 0);
        s.record_dig(0, 3);
        assert_eq!(s.region_pointer, 1);
        s.record_dig(5, 0);
        assert_eq!(s.region_pointer, 1);
        s.record_cleanup(0.1, &cfg);
        s.record_cleanup(0.1, &cfg);
        s.record_cleanup(f64::NAN, &cfg);
        assert_eq!(s.cleanup_tries.values().sum::<u32>(), 2);
        s.record_track_back(false);
        assert!(s.cleanup_tries.is_empty());
    }

    /// With nothing in view the planner tracks back `max_blind_track_backs` times, then chooses
    /// nothing (the bench is removed); a dig, a cleanup or material in view resets the count.
    #[test]
    fn blind_track_backs_end_in_nothing_after_the_limit() {
        let planner = test_planner(0.0);
        let pose = MachinePose::default();
        let flat = TerrainGrid::new_flat(-8.0, -10.0, 0.1, 240, 200, 0.0).expect("flat");
        let limit = planner.config().action.max_blind_track_backs;
        assert_eq!(limit, 2);
        let mut state = PlannerState::default();
        for _ in 0..limit {
            let plan = planner.plan(&flat, &pose, &state).expect("plan");
            assert!(!plan.cleanup_track.material_found);
            assert!(matches!(plan.action, ActionChoice::TrackBack { .. }));
            state.record_track_back(true);
        }
        let plan = planner.plan(&flat, &pose, &state).expect("plan");
        assert_eq!(plan.action, ActionChoice::Nothing);
        // Material in view: the bench ahead is dug whatever the count.
        let plan = planner.plan(&bench(), &pose, &state).expect("plan");
        assert!(matches!(plan.action, ActionChoice::Dig(_)));
        let mut s = state.clone();
        s.record_dig(0, 3);
        assert_eq!(s.blind_track_backs, 0);
        let mut s = state.clone();
        s.record_cleanup(0.0, &CleanupConfig::default());
        assert_eq!(s.blind_track_backs, 0);
        state.record_track_back(false);
        assert_eq!(state.blind_track_backs, 0);
    }
}
