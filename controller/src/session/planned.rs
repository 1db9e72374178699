//! The planner-driven action source of the work cycle (thesis 5.3 and 6.2): between digs the session
//! takes the latest terrain map, runs the dig planner ([`planner::plan::Planner`]: coarse and refined
//! dig location, cleanup and tracking plans), picks the action by Fig. 42 and hands the
//! [`crate::WorkCycle`] the next [`Action`]; or it replays the predefined excavation sequence of 6.2.
//!
//! ```text
//! scan points --observe_scan--> TerrainMapper (5.3) --+
//! machine pose (odometry) ----------------------------+--> next_action: Planner::plan -> Fig. 42
//!                                                            -> Action::{Dig, Cleanup, TrackBack}
//! ControllerNode::cycle().needs_action() --drive--> ControllerNode::push_action
//! ```
//!
//! Usage with a [`ControllerNode`] (the in-process demo): call
//! [`ControllerNode::set_external_plan`]`(true)` once (with an empty action list and `repeat = false`),
//! feed every range scan to [`PlannedSession::observe_scan`], and after each node step call
//! [`PlannedSession::drive`], which plans and pushes an action whenever the cycle waits for one and
//! reports when the session is over (the bench is done from here, or nothing is left to do).
//!
//! **Predefined sequence** (6.2, for comparison): one set of implement joint angles for all digs (the
//! median of the planner's choices: [`median_joints`]), the swing stepped across the regions from the
//! spoil side; after one dig in every region a cleanup in every region started at the far reach
//! (without perception there is no distance to the material), each detecting the floor anew (6.2:
//! the floor reuse "was not implemented for the predefined excavation sequence"); then a fixed 1.3 m
//! track back; repeat.

use planner::cleanup::CleanupPlan;
use planner::dig_model::{ActuatorDynamics, DigModel};
use planner::estimate::{SoilSample, SoilWindow, fit_empirical};
use planner::kinematics::{BucketPose, TipForce};
use planner::kinematics::{JointAngles, MachinePose};
use planner::machine::MachineConfig;
use planner::plan::mapper::MapUpdate;
use planner::plan::{
    ActionChoice, HardnessRegression, Plan, PlanError, Planner, PlannerConfig, PlannerState,
    TerrainMapper,
};
use planner::soil::{Contact, EmpiricalSoilModel, dig_geometry};
use planner::terrain::{SectionProfile, TerrainGrid};

use crate::session::snapshot::{
    PlannedSnapshot, PredefinedSequence, StepSnapshot, Strategy, TerrainSnapshot,
};
use crate::session::state_file::FieldError;
use crate::step::cycle::{Action, StartPose};
use crate::step::node::ControllerNode;

/// How far above the planned start the bucket is brought before Autodig's Boom-Down lowers it onto
/// the terrain, m. The planner's start (Fig. 45) has the tip on the surface, where the dig model
/// starts Pre-Dig; the work cycle starts Autodig in Boom-Down, which lowers the boom alone until
/// ground contact, so raising the boom alone by the matching angle lands the tip back on the planned
/// point (a move straight onto the surface would press into the soil and never settle).
/// 0.8 m: from 0.4 m, a start on the bench top near the crest after a backup (r 6-8 m) dragged the
/// bucket through the bench on the way there and the move timed out (26 timeouts in a 30-dig run).
pub const APPROACH_HEIGHT_M: f64 = 0.8;

/// The planned start joints with the boom raised so the tip is `height_m` higher (rotation about the
/// boom foot: `dz = (x_tip - x_foot) d_boom`).
#[must_use]
pub fn approach_joints(
    kin: &planner::kinematics::Kinematics,
    q: JointAngles,
    height_m: f64,
) -> JointAngles {
    let lever = (kin.forward(&q).x_m - kin.boom_foot()[0]).max(1.0);
    JointAngles {
        boom_rad: q.boom_rad + height_m / lever,
        ..q
    }
}

/// A bucket pass that comes this close to a planned dig's start tip confirms that dig, m
/// ([`PlannedSession::observe_bucket_pass`]).
pub const CONFIRM_PASS_DISTANCE_M: f64 = 0.6;

/// A planned dig that swept less than this share of the dig model's predicted volume found the map
/// wrong at its start (material the sensor showed that was not there): the start is not chosen again
/// until the next track back ([`PlannedSession::observe_dig_outcome`]).
pub const BARREN_DIG_SHARE: f64 = 0.25;

/// The predefined sequence's track-back distance (6.2: "a typical distance selected by the
/// perception based dig planner (1.3 meters)").
pub const PREDEFINED_BACKUP_M: f64 = 1.3;

/// Session errors.
#[derive(Debug, thiserror::Error)]
pub enum SessionError {
    /// The planner.
    #[error("planner: {0}")]
    Plan(#[from] PlanError),
    /// The controller rejected an action.
    #[error("controller: {0}")]
    Controller(#[from] crate::ControllerError),
    /// A bad predefined sequence.
    #[error("predefined sequence: {0}")]
    Predefined(&'static str),
}

/// Result alias of this module.
pub type Result<T> = std::result::Result<T, SessionError>;

impl PredefinedSequence {
    /// The sequence for a planner's geometry: regions of its coarse plan on `grid` at `pose`, cleanup
    /// from the floor-level reach, 1.3 m backups, and the given start joints.
    ///
    /// # Errors
    /// [`SessionError::Plan`] from the coarse or cleanup planner.
    pub fn from_planner<A: ActuatorDynamics>(
        planner: &Planner<A>,
        grid: &planner::terrain::TerrainGrid,
        pose: &MachinePose,
        start: JointAngles,
    ) -> Result<Self> {
        let coarse = planner.coarse(grid, pose)?;
        let ct = planner.cleanup_and_tracking(grid, pose, &PlannerState::default())?;
        let c = planner.config().cleanup;
        Ok(Self {
            start,
            swings_rad: coarse.regions.iter().map(|r| r.swing_rad).collect(),
            cleanup_start_m: ct.reach_m,
            cleanup_min_m: c.min_radius_m,
            cleanup_start_z_m: planner.config().floor_z_m + c.start_height_m,
            cleanup_bucket_abs_rad: c.bucket_abs_rad,
            backup_m: PREDEFINED_BACKUP_M,
        })
    }

    /// The `k`-th action of the repeating sequence: one dig per region, one cleanup per region, one
    /// backup.
    #[must_use]
    pub fn action(&self, k: usize) -> Option<Action> {
        let n = self.swings_rad.len();
        if n == 0 {
            return None;
        }
        let period = 2 * n + 1;
        let i = k % period;
        Some(if i < n {
            Action::Dig {
                swing_rad: self.swings_rad[i],
                start: StartPose::Joints {
                    boom_rad: self.start.boom_rad,
                    stick_rad: self.start.stick_rad,
                    bucket_rad: self.start.bucket_rad,
                },
            }
        } else if i < 2 * n {
            Action::Cleanup {
                swing_rad: self.swings_rad[i - n],
                start: StartPose::Tip {
                    x_m: self.cleanup_start_m,
                    z_m: self.cleanup_start_z_m,
                    bucket_abs_rad: self.cleanup_bucket_abs_rad,
                },
                plan: CleanupPlan {
                    start_radius_m: self.cleanup_start_m,
                    min_radius_m: self.cleanup_min_m,
                },
            }
        } else {
            Action::TrackBack {
                distance_m: self.backup_m,
            }
        })
    }
}

/// The median of each joint angle over the planner's chosen starts (6.2's "virtual expert").
#[must_use]
pub fn median_joints(starts: &[JointAngles]) -> Option<JointAngles> {
    if starts.is_empty() {
        return None;
    }
    let median = |f: fn(&JointAngles) -> f64| {
        let mut v: Vec<f64> = starts.iter().map(f).filter(|x| x.is_finite()).collect();
        v.sort_by(f64::total_cmp);
        v.get(v.len() / 2).copied()
    };
    Some(JointAngles {
        boom_rad: median(|q| q.boom_rad)?,
        stick_rad: median(|q| q.stick_rad)?,
        bucket_rad: median(|q| q.bucket_rad)?,
    })
}

/// One action the session handed to the cycle, with the plan behind it (for plots and statistics).
#[derive(Debug, Clone, PartialEq)]
pub struct SessionStep {
    /// The action pushed to the work cycle.
    pub action: Action,
    /// The planning cycle that chose it (planned strategy only).
    pub plan: Option<Plan>,
    /// The machine pose it was planned at.
    pub pose: MachinePose,
}

/// The action source of an autonomous session.
#[derive(Debug)]
pub struct PlannedSession {
    planner: Planner,
    state: PlannerState,
    mapper: TerrainMapper,
    strategy: Strategy,
    predefined: Option<PredefinedSequence>,
    predefined_index: usize,
    regression: HardnessRegression,
    hardness_index: Option<f64>,
    /// The latest soil estimate given to [`Self::set_soil_estimate`].
    soil_estimate: Option<EmpiricalSoilModel>,
    dig_starts: Vec<JointAngles>,
    /// World-frame start tips of planned digs whose bucket pass has not been observed yet, oldest
    /// first. The caller observes a dig's pass after it has planned the next action (the statistics
    /// arrive as the cycle turns idle), so the newest entry is not judged; an older one still here
    /// was abandoned (its move to the start timed out).
    unconfirmed_digs: Vec<[f64; 3]>,
    steps: Vec<SessionStep>,
    finished: bool,
    /// Why [`Self::next_action`] returned `None`.
    end_reason: Option<String>,
}

impl PlannedSession {
    /// A session with the planner on `machine` (nominal dig model, `config`), an empty terrain map of
    /// the given grid, and the shipped hardness regression.
    ///
    /// # Errors
    /// [`SessionError::Plan`] for an invalid config, grid or dig model.
    pub fn new(
        machine: &MachineConfig,
        config: PlannerConfig,
        mapper: TerrainMapper,
        strategy: Strategy,
    ) -> Result<Self> {
        let model = DigModel::nominal().map_err(PlanError::from)?;
        Self::with_model(machine, model, config, mapper, strategy)
    }

    /// As [`Self::new`] with a given dig model.
    ///
    /// # Errors
    /// As [`Self::new`].
    pub fn with_model(
        machine: &MachineConfig,
        model: DigModel,
        config: PlannerConfig,
        mapper: TerrainMapper,
        strategy: Strategy,
    ) -> Result<Self> {
        Ok(Self {
            planner: Planner::new(machine, model, config)?,
            state: PlannerState::default(),
            mapper,
            strategy,
            predefined: None,
            predefined_index: 0,
            regression: HardnessRegression::nominal()?,
            hardness_index: None,
            soil_estimate: None,
            dig_starts: Vec::new(),
            unconfirmed_digs: Vec::new(),
            steps: Vec::new(),
            finished: false,
            end_reason: None,
        })
    }

    /// Why the session is over (`None` while it goes on): `bench removed` (nothing in view after the
    /// planner's blind track backs), or `nothing left to do` (material in view, but no dig, track
    /// back or cleanup possible), or no predefined sequence.
    #[must_use]
    pub fn end_reason(&self) -> Option<&str> {
        self.end_reason.as_deref()
    }

    /// Replaces the hardness regression (5.2) the online index follows.
    pub fn set_regression(&mut self, regression: HardnessRegression) {
        self.regression = regression;
    }

    /// The predefined sequence in use, if any.
    #[must_use]
    pub fn predefined(&self) -> Option<&PredefinedSequence> {
        self.predefined.as_ref()
    }

    /// Uses the predefined sequence (6.2) instead of the planner.
    pub fn set_predefined(&mut self, sequence: PredefinedSequence) {
        self.predefined = Some(sequence);
        self.predefined_index = 0;
        self.strategy = Strategy::Predefined;
    }

    /// The strategy.
    #[must_use]
    pub fn strategy(&self) -> Strategy {
        self.strategy
    }

    /// The planner.
    #[must_use]
    pub fn planner(&self) -> &Planner {
        &self.planner
    }

    /// What persists between planning cycles.
    #[must_use]
    pub fn state(&self) -> &PlannerState {
        &self.state
    }

    /// The terrain map.
    #[must_use]
    pub fn terrain(&self) -> &planner::terrain::TerrainGrid {
        self.mapper.grid()
    }

    /// The actions handed out so far, with their plans.
    #[must_use]
    pub fn steps(&self) -> &[SessionStep] {
        &self.steps
    }

    /// The joint angles of the dig starts pushed so far (the planner's start raised by
    /// [`APPROACH_HEIGHT_M`]; their median seeds the predefined sequence: [`median_joints`]).
    #[must_use]
    pub fn dig_starts(&self) -> &[JointAngles] {
        &self.dig_starts
    }

    /// Whether the session has nothing left to do.
    #[must_use]
    pub fn finished(&self) -> bool {
        self.finished
    }

    /// The soil hardness index from the latest soil estimate (5.2), if one was given.
    #[must_use]
    pub fn hardness_index(&self) -> Option<f64> {
        self.hardness_index
    }

    /// The "virtual expert" start of 6.2 when no planned run is at hand: the median of the joint
    /// angles of the best dig the refined planner finds in every region with material on the current
    /// map, from `pose`. `None` when no region has a valid dig.
    ///
    /// # Errors
    /// [`SessionError::Plan`] when the map is unusable.
    pub fn virtual_expert_start(&self, pose: &MachinePose) -> Result<Option<JointAngles>> {
        let grid = self.mapper.grid();
        let coarse = self.planner.coarse(grid, pose)?;
        let mut starts = Vec::new();
        for region in coarse.regions.iter().filter(|r| r.has_material) {
            if let Some(best) = self.planner.refine(grid, pose, region)?.best {
                starts.push(approach_joints(
                    self.planner.kinematics(),
                    best.joints,
                    APPROACH_HEIGHT_M,
                ));
            }
        }
        Ok(median_joints(&starts))
    }

    /// Fuses a range scan (world-frame points) into the terrain map (5.3).
    ///
    /// # Errors
    /// [`SessionError::Plan`] when no point falls in the map.
    pub fn observe_scan(&mut self, points: &[[f64; 3]]) -> Result<MapUpdate> {
        Ok(self.mapper.integrate(points)?)
    }

    /// Fuses a range scan taken from the sensor at `origin` (world frame), carving the free space its
    /// rays crossed (material dug out of sight leaves the map; [`TerrainMapper::integrate_from`]).
    ///
    /// # Errors
    /// [`SessionError::Plan`] when no point falls in the map or the origin is not finite.
    pub fn observe_scan_from(
        &mut self,
        origin: [f64; 3],
        points: &[[f64; 3]],
    ) -> Result<MapUpdate> {
        Ok(self.mapper.integrate_from(origin, points)?)
    }

    /// Carves the swath of an executed dig or cleanup into the terrain map: the tip moved along
    /// `tip_path` (`(r, z)` in the base frame, m) in the digging plane at `swing_rad` with the machine
    /// at `pose`, and no material is left above it over the bucket width
    /// ([`TerrainMapper::carve_swath`]). The toe of the receding face is hidden behind its crest
    /// from the sensor, so the scans alone left the material dug there in the map. Returns the cells
    /// lowered.
    pub fn observe_bucket_pass(
        &mut self,
        pose: &MachinePose,
        swing_rad: f64,
        tip_path: &[(f64, f64)],
    ) -> usize {
        let path: Vec<[f64; 3]> = tip_path
            .iter()
            .map(|&(r, z)| pose.world_from_base(swing_rad, r, z))
            .collect();
        // The pass confirms the oldest planned dig it went through (Boom-Down lowers the tip onto
        // the planned start).
        let through = |start: &[f64; 3]| {
            path.iter().any(|p| {
                (p[0] - start[0])
                    .hypot(p[1] - start[1])
                    .hypot(p[2] - start[2])
                    < CONFIRM_PASS_DISTANCE_M
            })
        };
        if let Some(i) = self.unconfirmed_digs.iter().position(through) {
            self.unconfirmed_digs.remove(i);
        }
        let [x0, y0, _] = pose.world_from_base(swing_rad, 0.0, 0.0);
        let [x1, y1, _] = pose.world_from_base(swing_rad, 1.0, 0.0);
        let lateral = [-(y1 - y0), x1 - x0];
        self.mapper
            .carve_swath(&path, lateral, self.planner.bucket_width_m())
    }

    /// A planned dig ended: it started with the tip at `start_world` (world frame), swept
    /// `swept_m3` where the dig model predicted `predicted_m3`. A barren dig (under
    /// [`BARREN_DIG_SHARE`] of the prediction: the bucket met little or no soil where the map showed
    /// it) marks its start like an abandoned one, so the planner does not send the bucket back there
    /// until the next track back. Returns whether it did.
    pub fn observe_dig_outcome(
        &mut self,
        start_world: [f64; 3],
        swept_m3: f64,
        predicted_m3: f64,
    ) -> bool {
        let barren = swept_m3.is_finite()
            && predicted_m3.is_finite()
            && predicted_m3 > 0.0
            && swept_m3 < BARREN_DIG_SHARE * predicted_m3;
        if barren {
            self.state.record_abandoned_dig(start_world);
        }
        barren
    }

    /// Takes estimated empirical soil properties (Eqs. 21-23): the hardness index follows the
    /// regression of 5.2 (Eq. 25) and is given to the dig model (and returned, for Autodig). The dig
    /// model keeps its analytical soil (the modified FEE of the moving bucket with bearing, Eqs.
    /// 14-18): the linear Eq. 21 fitted on the recent digs has no term for the bucket's direction of
    /// motion or for its back pushed into the soil and measures depth on the pre-dig surface, so for
    /// starts high on the face it let the predicted tip sink 0.5-1.2 m deeper than Autodig took it
    /// (docs/planner.md).
    ///
    /// # Errors
    /// [`SessionError::Plan`] for non-finite coefficients.
    pub fn set_soil_estimate(&mut self, soil: EmpiricalSoilModel) -> Result<f64> {
        let index = self.regression.index_for_model(&soil)?;
        let model = self.planner.model_mut();
        model.set_hardness_index(index).map_err(PlanError::from)?;
        self.hardness_index = Some(index);
        self.soil_estimate = Some(soil);
        Ok(index)
    }

    /// The session's state for a saved session (the plans behind the steps are left out).
    #[must_use]
    pub fn snapshot(&self) -> PlannedSnapshot {
        PlannedSnapshot {
            strategy: self.strategy,
            planner: self.state.clone(),
            terrain: TerrainSnapshot::of(self.mapper.grid()),
            map_scans: self.mapper.scans(),
            predefined: self.predefined.clone(),
            predefined_index: self.predefined_index,
            soil_estimate: self.soil_estimate,
            dig_starts: self.dig_starts.clone(),
            unconfirmed_digs: self.unconfirmed_digs.clone(),
            steps: self
                .steps
                .iter()
                .map(|st| StepSnapshot {
                    action: st.action,
                    pose: st.pose,
                })
                .collect(),
            finished: self.finished,
            end_reason: self.end_reason.clone(),
        }
    }

    /// Puts a saved session's state into this fresh session (same strategy and map grid).
    ///
    /// # Errors
    /// The field of `s` this session cannot take: another strategy, another map grid, a soil
    /// estimate the regression refuses.
    pub fn restore(&mut self, s: &PlannedSnapshot) -> std::result::Result<(), FieldError> {
        if s.strategy != self.strategy {
            return Err(FieldError::new(
                "strategy",
                format!("{:?}, this session is {:?}", s.strategy, self.strategy),
            ));
        }
        let grid = s.terrain.grid().map_err(|e| e.within("terrain"))?;
        self.mapper
            .restore(grid, s.map_scans)
            .map_err(|e| FieldError::new("terrain", e.to_string()))?;
        if let Some(model) = s.soil_estimate {
            self.set_soil_estimate(model)
                .map_err(|e| FieldError::new("soil_estimate", e.to_string()))?;
        }
        self.state.clone_from(&s.planner);
        self.predefined.clone_from(&s.predefined);
        self.predefined_index = s.predefined_index;
        self.dig_starts.clone_from(&s.dig_starts);
        self.unconfirmed_digs.clone_from(&s.unconfirmed_digs);
        self.steps = s
            .steps
            .iter()
            .map(|st| SessionStep {
                action: st.action,
                plan: None,
                pose: st.pose,
            })
            .collect();
        self.finished = s.finished;
        self.end_reason.clone_from(&s.end_reason);
        Ok(())
    }

    /// Plans the next action for the machine at `pose` (world frame) on the current terrain map.
    /// `None` when the session is over: no dig, backup or cleanup is possible from here (planned), or
    /// the predefined sequence is missing.
    ///
    /// # Errors
    /// [`SessionError::Plan`] when the map is unusable.
    pub fn next_action(&mut self, pose: &MachinePose) -> Result<Option<Action>> {
        if self.finished {
            return Ok(None);
        }
        let (action, plan) = match self.strategy {
            Strategy::Predefined => {
                let Some(seq) = &self.predefined else {
                    self.finished = true;
                    self.end_reason = Some("no predefined sequence".to_owned());
                    return Ok(None);
                };
                let a = seq.action(self.predefined_index);
                self.predefined_index += 1;
                (a, None)
            }
            Strategy::Planned => {
                let judged = self.unconfirmed_digs.len().saturating_sub(1);
                for tip in self.unconfirmed_digs.drain(..judged) {
                    self.state.record_abandoned_dig(tip);
                }
                let plan = self.planner.plan(self.mapper.grid(), pose, &self.state)?;
                let regions = plan.coarse.regions.len();
                let action = match &plan.action {
                    ActionChoice::Dig(d) => {
                        self.state.record_dig(d.region_index, regions);
                        self.unconfirmed_digs.push(pose.world_from_base(
                            d.swing_rad,
                            d.pose.x_m,
                            d.pose.z_m,
                        ));
                        let q =
                            approach_joints(self.planner.kinematics(), d.joints, APPROACH_HEIGHT_M);
                        self.dig_starts.push(q);
                        Some(Action::Dig {
                            swing_rad: d.swing_rad,
                            start: StartPose::Joints {
                                boom_rad: q.boom_rad,
                                stick_rad: q.stick_rad,
                                bucket_rad: q.bucket_rad,
                            },
                        })
                    }
                    ActionChoice::TrackBack { distance_m } => {
                        self.state
                            .record_track_back(!plan.cleanup_track.material_found);
                        self.unconfirmed_digs.clear();
                        Some(Action::TrackBack {
                            distance_m: *distance_m,
                        })
                    }
                    ActionChoice::Cleanup(c) => match c.plan {
                        Some(p) => {
                            self.state
                                .record_cleanup(c.swing_rad, &self.planner.config().cleanup);
                            Some(Action::Cleanup {
                                swing_rad: c.swing_rad,
                                start: StartPose::Tip {
                                    x_m: c.start.x_m,
                                    z_m: c.start.z_m,
                                    bucket_abs_rad: c.start.bucket_abs_rad,
                                },
                                plan: p,
                            })
                        }
                        None => None,
                    },
                    ActionChoice::Nothing => None,
                };
                (action, Some(plan))
            }
        };
        match action {
            Some(a) => {
                self.steps.push(SessionStep {
                    action: a,
                    plan,
                    pose: *pose,
                });
                Ok(Some(a))
            }
            None => {
                self.finished = true;
                let blind = self
                    .steps
                    .last()
                    .is_some_and(|st| matches!(st.action, Action::TrackBack { .. }))
                    && self.state.blind_track_backs > 0;
                self.end_reason = Some(if blind {
                    format!(
                        "bench removed: no material in view after {} track backs",
                        self.state.blind_track_backs
                    )
                } else {
                    "nothing left to do".to_owned()
                });
                Ok(None)
            }
        }
    }

    /// Between node steps: when the work cycle waits for an action, plans one at the node's
    /// dead-reckoned pose and pushes it. Returns `false` once the session is over (the caller then
    /// stops the node, which returns home).
    ///
    /// # Errors
    /// [`SessionError`] from the planner or when the cycle rejects the action.
    pub fn drive(&mut self, node: &mut ControllerNode) -> Result<bool> {
        if !node.cycle().needs_action() {
            return Ok(!self.finished);
        }
        let pose = node.estimator().state().pose;
        match self.next_action(&pose)? {
            Some(a) => {
                node.push_action(a)?;
                Ok(true)
            }
            None => Ok(false),
        }
    }
}

/// The terrain section along the digging plane at `swing_rad` from `r0_m` to `r1_m` (every `step_m`),
/// unknown samples filled from their known neighbours (the last known height carried forward,
/// [`planner::terrain::GapFill::HoldLast`]); `None` when nothing along it is known.
#[must_use]
pub fn plane_section(
    grid: &TerrainGrid,
    pose: &MachinePose,
    swing_rad: f64,
    r0_m: f64,
    r1_m: f64,
    step_m: f64,
) -> Option<SectionProfile> {
    use planner::terrain::GapFill;
    grid.plane_section(pose, swing_rad, r0_m, r1_m, step_m, GapFill::HoldLast)
        .ok()
}

/// The soil estimator of the planned session (thesis 5.3's Soil Estimator, 4.3.4-4.3.5): during each
/// dig it intersects the bucket with the pre-dig terrain section (`Gamma`, [`dig_geometry`]) and
/// pairs it with the measured tip force; after the dig it fits the empirical model (Eqs. 21-23) on a
/// sliding window of the recent samples, which the session turns into the hardness index (Eq. 25 and
/// the regression of 5.2, [`PlannedSession::set_soil_estimate`]).
#[derive(Debug, Clone)]
pub struct SoilMonitor {
    window: SoilWindow,
    section: Option<SectionProfile>,
    fresh: usize,
    min_samples: usize,
}

impl Default for SoilMonitor {
    fn default() -> Self {
        Self::new(600, 40)
    }
}

impl SoilMonitor {
    /// A monitor keeping the last `window` samples, fitting once a dig added `min_samples` (4.3.5: a
    /// window of about 300 samples).
    #[must_use]
    pub fn new(window: usize, min_samples: usize) -> Self {
        Self {
            window: SoilWindow::new(window),
            section: None,
            fresh: 0,
            min_samples: min_samples.max(planner::estimate::EMPIRICAL_TERMS),
        }
    }

    /// A dig starts over the terrain `section` of its plane (or `None`: no samples this dig).
    pub fn begin(&mut self, section: Option<SectionProfile>) {
        self.section = section;
        self.fresh = 0;
    }

    /// One sample during the dig: the tip pose, the measured soil force on the tip and the swept
    /// volume so far. Poses out of the ground, or without a force or section, are skipped; the sample
    /// kept is returned.
    pub fn sample(
        &mut self,
        tip: &BucketPose,
        force: Option<TipForce>,
        swept_volume_m3: f64,
    ) -> Option<SoilSample> {
        let (Some(section), Some(force)) = (&self.section, force) else {
            return None;
        };
        if !(force.fx_n.is_finite() && force.fz_n.is_finite() && force.my_nm.is_finite()) {
            return None;
        }
        if let Ok(Contact::InContact(geometry)) =
            dig_geometry(tip, section, swept_volume_m3.max(0.0))
            && geometry.depth_m > 0.05
        {
            let sample = SoilSample { geometry, force };
            self.window.push(sample);
            self.fresh += 1;
            Some(sample)
        } else {
            None
        }
    }

    /// Samples held in the window.
    #[must_use]
    pub fn len(&self) -> usize {
        self.window.len()
    }

    /// The window's samples, oldest first (a saved session).
    #[must_use]
    pub fn window(&self) -> Vec<SoilSample> {
        self.window.iter().copied().collect()
    }

    /// Puts a saved window back (between digs).
    pub fn restore_window(&mut self, samples: &[SoilSample]) {
        for s in samples {
            self.window.push(*s);
        }
    }

    /// Whether no sample is held.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.window.is_empty()
    }

    /// The dig ended: the empirical soil model fitted on the window, when this dig added enough
    /// samples and the fit is well posed.
    pub fn end(&mut self) -> Option<EmpiricalSoilModel> {
        self.section = None;
        if self.fresh < self.min_samples {
            return None;
        }
        let fit = fit_empirical(self.window.samples()).ok()?;
        planner::plan::average_soil_force_n(&fit.model)
            .ok()
            .filter(|f| f.is_finite())
            .map(|_| fit.model)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use planner::terrain::TerrainGrid;

    fn bench_points() -> Vec<[f64; 3]> {
        let mut pts = Vec::new();
        for i in 0..240 {
            for j in 0..200 {
                let (x, y) = (
                    -8.0 + 0.05 + 0.1 * f64::from(i),
                    -10.0 + 0.05 + 0.1 * f64::from(j),
                );
                let z = if y.abs() > 5.0 || x > 13.0 {
                    0.0
                } else {
                    (x - 3.0).clamp(0.0, 2.0)
                };
                pts.push([x, y, z]);
            }
        }
        pts
    }

    fn session(strategy: Strategy) -> PlannedSession {
        let machine = MachineConfig::default_machine().expect("machine");
        let mut cfg = PlannerConfig::nominal().expect("config");
        // Coarser than Fig. 45 so the debug-build test stays fast.
        cfg.refined.d_step_m = 0.6;
        cfg.refined.alpha_step_rad = 10f64.to_radians();
        let mapper = TerrainMapper::new(-8.0, -10.0, 0.1, 240, 200, 5).expect("mapper");
        PlannedSession::new(&machine, cfg, mapper, strategy).expect("session")
    }

    #[test]
    fn planned_session_digs_the_bench_and_records_the_region() {
        let mut s = session(Strategy::Planned);
        s.observe_scan(&bench_points()).expect("scan");
        let pose = MachinePose::default();
        let a = s.next_action(&pose).expect("plan").expect("an action");
        assert!(matches!(a, Action::Dig { .. }), "{a:?}");
        assert_eq!(s.steps().len(), 1);
        assert!(s.steps()[0].plan.is_some());
        assert_eq!(s.dig_starts().len(), 1);
        // The pointer moved past the dug region.
        let Some(ActionChoice::Dig(d)) = s.steps()[0].plan.as_ref().map(|p| p.action.clone())
        else {
            panic!("dig plan expected");
        };
        let n = s.steps()[0]
            .plan
            .as_ref()
            .map_or(0, |p| p.coarse.regions.len());
        assert_eq!(s.state().region_pointer, (d.region_index + 1) % n);
    }

    #[test]
    fn a_barren_dig_keeps_the_planner_away_from_its_start_until_a_track_back() {
        let mut s = session(Strategy::Planned);
        s.observe_scan(&bench_points()).expect("scan");
        let pose = MachinePose::default();
        s.next_action(&pose).expect("plan").expect("an action");
        let Some(ActionChoice::Dig(d)) = s.steps()[0].plan.as_ref().map(|p| p.action.clone())
        else {
            panic!("dig plan expected");
        };
        let start = pose.world_from_base(d.swing_rad, d.pose.x_m, d.pose.z_m);
        // A dig that filled as predicted, or nearly empty with no prediction, marks nothing.
        assert!(!s.observe_dig_outcome(start, 1.8, 2.0));
        assert!(!s.observe_dig_outcome(start, 0.0, 0.0));
        assert!(!s.observe_dig_outcome(start, f64::NAN, 2.0));
        assert!(s.state().abandoned_starts.is_empty());
        // A dig that swept under a quarter of its prediction marks its start.
        assert!(s.observe_dig_outcome(start, 0.3, 2.0));
        assert_eq!(s.state().abandoned_starts, vec![start]);
        let Some(Action::Dig { .. }) = s.next_action(&pose).expect("plan") else {
            panic!("dig expected");
        };
        let Some(ActionChoice::Dig(next)) = s.steps()[1].plan.as_ref().map(|p| p.action.clone())
        else {
            panic!("dig plan expected");
        };
        let again = pose.world_from_base(next.swing_rad, next.pose.x_m, next.pose.z_m);
        let dist = (again[0] - start[0])
            .hypot(again[1] - start[1])
            .hypot(again[2] - start[2]);
        assert!(
            dist > planner::plan::ABANDONED_START_RADIUS_M,
            "{dist} m from the barren start"
        );
    }

    #[test]
    fn predefined_sequence_steps_regions_then_cleans_then_backs_up() {
        let s = session(Strategy::Predefined);
        let grid = TerrainGrid::new_flat(-8.0, -10.0, 0.1, 240, 200, 0.0).expect("grid");
        let start = median_joints(&[
            JointAngles {
                boom_rad: 0.1,
                stick_rad: -1.2,
                bucket_rad: -0.5,
            },
            JointAngles {
                boom_rad: 0.3,
                stick_rad: -1.0,
                bucket_rad: -0.7,
            },
            JointAngles {
                boom_rad: 0.2,
                stick_rad: -1.4,
                bucket_rad: -0.6,
            },
        ])
        .expect("median");
        assert_eq!(
            start,
            JointAngles {
                boom_rad: 0.2,
                stick_rad: -1.2,
                bucket_rad: -0.6
            }
        );
        let seq =
            PredefinedSequence::from_planner(s.planner(), &grid, &MachinePose::default(), start)
                .expect("sequence");
        let n = seq.swings_rad.len();
        assert!(n >= 5);
        for k in 0..n {
            assert!(
                matches!(seq.action(k), Some(Action::Dig { swing_rad, .. }) if swing_rad == seq.swings_rad[k])
            );
            let Some(Action::Cleanup { plan, .. }) = seq.action(n + k) else {
                panic!("cleanup expected");
            };
            assert!((plan.start_radius_m - seq.cleanup_start_m).abs() < 1e-12);
        }
        assert_eq!(
            seq.action(2 * n),
            Some(Action::TrackBack { distance_m: 1.3 })
        );
        assert_eq!(seq.action(2 * n + 1), seq.action(0));
        let mut s = s;
        s.set_predefined(seq);
        let a = s.next_action(&MachinePose::default()).expect("next");
        assert!(matches!(a, Some(Action::Dig { .. })));
        assert!(median_joints(&[]).is_none());
    }

    #[test]
    fn nothing_to_do_ends_the_session() {
        let mut s = session(Strategy::Planned);
        // Bare floor everywhere in view, machine boxed in: the planner can only track back; a
        // planned session on an unknown map fails with a typed error, not a panic.
        let pose = MachinePose::default();
        assert!(s.next_action(&pose).is_err() || s.finished() || !s.steps().is_empty());
        let mut p = session(Strategy::Predefined);
        assert_eq!(p.next_action(&pose).expect("no sequence"), None);
        assert!(p.finished());
    }
}
