//! The work cycle (thesis chapters 3 and 6): scan, swing to the dig, Autodig or cleanup, weigh, swing to
//! the spoil pile, dump, return; and tracking backwards.
//!
//! The plan is a list of [`Action`]s (dig at a swing angle from a start pose, cleanup, track back a
//! distance): fixed in the configuration and repeated until the requested number of digs, or pushed one
//! at a time by an external action source (the dig planner, [`crate::session::planned`]). Per action the
//! [`WorkCycle`] runs these phases:
//!
//! ```text
//! Dig / Cleanup:  Scan -> MoveToDig -> Autodig | Cleanup -> Autodig (Pre-Dig) -> Weigh -> SwingToDump
//!                 -> Dump -> (next action; its MoveToDig is the return swing)
//! TrackBack:      TrackBack
//! after the last: Return -> Finished
//! ```
//!
//! - **Scan**: asks the caller for a range scan ([`WorkCycle::take_scan_request`]) and waits for the
//!   terrain ([`WorkCycle::provide_terrain`]) up to a timeout; without one, Autodig runs with its plain
//!   angle rules.
//! - **Autodig** (planner's pure state machine) with the perception enhancements of 3.2: the pre-dig
//!   terrain section along the digging plane is kept, the volume swept over the cutting edge is
//!   integrated ([`planner::terrain::SweptVolume`]), Dig ends at bucket capacity x spill allowance and
//!   Capture ends as soon as the bucket is above that terrain.
//! - **Cleanup** (3.3): waypoints from [`planner::cleanup::Cleanup`] through inverse kinematics to the
//!   gateway's position mode, with the floor elevation detected on the first cleanup and reused
//!   ([`planner::cleanup::FloorEstimate`]), then the hand-over to Autodig in Pre-Dig.
//! - Swing, the implement moves and the tracks are closed by P-controllers on the valve commands.
//!
//! Per dig it records [`DigStats`]: weight (static payload estimate after Capture, Appendix A.2 with the
//! gravity model), time, energy (thesis 6.1: cylinder force times displacement, integrated), swept
//! volume, time in the ground and the action type.
//!
//! The cycle does no I/O and reads no clock; it moves only while the safety layer reports the machine
//! armed in the mode the current phase needs, and holds (neutral) otherwise.
//!
//! # Layout
//!
//! - `action`: [`StartPose`], [`Action`], [`ActionKind`].
//! - `config`: [`CycleConfig`] and [`PGain`], with their validation.
//! - `scan_grid`: [`ScanGrid`].
//! - `snapshot`: [`CycleSnapshot`], the cycle's part of a saved session.
//! - `stats`: [`DigStats`] and the record a running dig keeps.
//! - `weigh`: the payload average over whole oscillation periods and the Weigh thresholds.
//! - this module: [`WorkCycle`] (state, phase changes, [`WorkCycle::step`]); its phases in `moving`
//!   (MoveToDig), `digging` (Autodig, cleanup) and `weigh_dump_track` (Weigh, SwingToDump, Dump,
//!   TrackBack).

mod action;
mod config;
mod digging;
mod moving;
mod scan_grid;
mod snapshot;
mod stats;
#[cfg(test)]
mod test_support;
mod weigh;
mod weigh_dump_track;

pub use action::{Action, ActionKind, StartPose};
pub use config::{CycleConfig, PGain};
pub use scan_grid::ScanGrid;
pub use snapshot::CycleSnapshot;
pub use stats::{DigStats, dig_number};

use planner::autodig::{Autodig, AutodigConfig, AutodigMaps, Stage};
use planner::cleanup::{Cleanup, CleanupConfig, FloorEstimate};
use planner::kinematics::{JointAngles, Kinematics};
use planner::terrain::{SweptVolume, TerrainGrid};
use serde::{Deserialize, Serialize};

use crate::ControllerError;
use crate::step::estimate::Estimator;
use crate::step::safety::{ArmMode, ControlFault};

use self::stats::DigRecord;

/// Valve direction per implement joint: +1 when cylinder extension raises the joint angle
/// (docs/ARCHITECTURE.md: boom up; stick and bucket extension lower their angles).
pub const JOINT_SIGN: [f64; 3] = [1.0, -1.0, -1.0];

/// MoveToDig stall escalation: a joint whose error has not shrunk by this much for
/// [`STALL_WAIT_S`](moving::STALL_WAIT_S) is stalled, rad (0.2 deg). Judged on the angle, not the rate signal: a
/// cylinder chattering in place reports a rate without getting anywhere.
const STALL_PROGRESS_RAD: f64 = 0.0035;

/// Dump: a bucket whose opening port has stayed at or above this fraction of its relief pressure for
/// [`RELIEF_RELIFT_S`](weigh_dump_track::RELIEF_RELIFT_S) is held too, even while it creeps open (a bucket pushed back into the spoil
/// pile yields slowly at relief); the boom lifts it clear.
const RELIEF_RELIFT_FRACTION: f64 = 0.9;

/// The phase of the work cycle.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Phase {
    /// Not started.
    Idle,
    /// Waiting for a range scan.
    Scan,
    /// Swinging to the dig and moving the implement to the start pose.
    MoveToDig,
    /// Autodig running.
    Autodig,
    /// Cleanup waypoints in position mode.
    Cleanup,
    /// Holding still after Capture to weigh the payload.
    Weigh,
    /// Raising the boom and swinging to the spoil pile.
    SwingToDump,
    /// Uncurling the bucket over the pile.
    Dump,
    /// Tracking backwards.
    TrackBack,
    /// Swinging home after the last action.
    Return,
    /// All done.
    Finished,
}

impl Phase {
    /// The gateway mode this phase needs (`None`: stay disarmed).
    pub const fn mode(self) -> Option<ArmMode> {
        match self {
            Phase::Idle | Phase::Finished => None,
            Phase::Cleanup => Some(ArmMode::Position),
            _ => Some(ArmMode::Valve),
        }
    }
}

/// What the cycle wants sent this period.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CycleCommand {
    /// All valves neutral.
    Neutral,
    /// Valve commands `[boom, stick, bucket, swing, left track, right track]` in `[-1, 1]`.
    Valves([f64; 6]),
    /// Position setpoints `[boom, stick, bucket, swing]`, rad.
    Position([f64; 4]),
}

/// The cycle's output for one period.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CycleOutput {
    /// The gateway mode needed now.
    pub want: Option<ArmMode>,
    /// The command (meaningful only when armed in `want`).
    pub command: CycleCommand,
}

/// The work cycle state machine.
#[derive(Debug, Clone)]
pub struct WorkCycle {
    config: CycleConfig,
    autodig_config: AutodigConfig,
    maps: AutodigMaps,
    cleanup_config: CleanupConfig,
    bucket_width_m: f64,
    starts: Vec<JointAngles>,
    started: bool,
    phase: Phase,
    phase_since_s: f64,
    settle_since_s: Option<f64>,
    action_index: usize,
    digs_done: u32,
    autodig: Option<Autodig>,
    cleanup: Option<Cleanup>,
    swept: Option<SweptVolume>,
    floor: FloorEstimate,
    terrain: Option<TerrainGrid>,
    terrain_fresh: bool,
    scan_request: bool,
    record: Option<DigRecord>,
    stats: Vec<DigStats>,
    track_target_m: f64,
    last_now_s: f64,
    /// MoveToDig: the tip has been lifted to the start height once (lift-first is not re-entered).
    lifted: bool,
    /// Stall escalation per joint (boom, stick, bucket, swing): the extra command magnitude
    /// ([`STALL_BOOST_PER_S`](moving::STALL_BOOST_PER_S)), the smallest error so far and when it last shrank
    /// ([`STALL_PROGRESS_RAD`]); and the time of the last move step.
    stall_boost: [f64; 4],
    stall_best_rad: [f64; 4],
    stall_progress_s: [f64; 4],
    /// Dump: since when the bucket's opening port has been near relief ([`RELIEF_RELIFT_FRACTION`]);
    /// MoveToDig: since when a commanded implement cylinder's port has been near relief
    /// ([`MOVE_BLOCKED_S`](moving::MOVE_BLOCKED_S)).
    relief_since_s: Option<f64>,
    /// MoveToDig: when some cylinder was last at relief ([`moving::MOVE_RELIEF_GAP_S`]), s.
    relief_seen_s: f64,
    last_move_s: Option<f64>,
    /// MoveToDig close enough: the tip's least distance to the start's tip so far and when it last
    /// shrank by 1 cm.
    move_best_m: f64,
    move_progress_s: f64,
    /// MoveToDig: the boom is lifting the tip back to its terrain clearance.
    clearing: bool,
    /// MoveToDig: the terrain heights along the start's digging plane, every [`CLEARANCE_STEP_M`](moving::CLEARANCE_STEP_M)
    /// from the swing axis (NaN where unknown); filled on the first use in a move.
    clearance_profile: Vec<f64>,
    /// Hook for an external action source (`crate::session::planned`): hold in Idle when the actions run out.
    external_plan: bool,
    /// Control faults of the current action so far.
    failed_attempts: u32,
    /// The current action was abandoned and is tried again when the bucket has been emptied.
    retry_pending: bool,
    /// The operator's pause: no new action starts.
    paused: bool,
    /// The operator's stop: after the current action the cycle returns home and finishes.
    stop_requested: bool,
}

impl WorkCycle {
    /// A cycle for the machine of `kin` (resolves the start poses).
    ///
    /// # Errors
    /// [`ControllerError`] for an invalid config, an unreachable start pose, or invalid Autodig or
    /// cleanup parameters.
    pub fn new(
        config: CycleConfig,
        autodig_config: AutodigConfig,
        maps: AutodigMaps,
        cleanup_config: CleanupConfig,
        bucket_width_m: f64,
        kin: &Kinematics,
    ) -> Result<Self, ControllerError> {
        config.validate()?;
        autodig_config.validate()?;
        cleanup_config.validate()?;
        let mut starts = Vec::with_capacity(config.actions.len());
        for a in &config.actions {
            starts.push(match a {
                Action::Dig { start, .. } | Action::Cleanup { start, .. } => start.resolve(kin)?,
                Action::TrackBack { .. } => JointAngles::default(),
            });
        }
        let floor = FloorEstimate::new(config.floor_policy);
        Ok(Self {
            config,
            autodig_config,
            maps,
            cleanup_config,
            bucket_width_m,
            starts,
            started: false,
            phase: Phase::Idle,
            phase_since_s: 0.0,
            settle_since_s: None,
            action_index: 0,
            digs_done: 0,
            autodig: None,
            cleanup: None,
            swept: None,
            floor,
            terrain: None,
            terrain_fresh: false,
            scan_request: false,
            record: None,
            stats: Vec::new(),
            track_target_m: 0.0,
            last_now_s: 0.0,
            lifted: false,
            stall_boost: [0.0; 4],
            stall_best_rad: [f64::INFINITY; 4],
            stall_progress_s: [0.0; 4],
            relief_since_s: None,
            relief_seen_s: f64::NEG_INFINITY,
            last_move_s: None,
            move_best_m: f64::INFINITY,
            move_progress_s: 0.0,
            clearing: false,
            clearance_profile: Vec::new(),
            external_plan: false,
            failed_attempts: 0,
            retry_pending: false,
            paused: false,
            stop_requested: false,
        })
    }

    /// Hook for an external action source (the dig planner, `crate::session::planned`): with `on`, the cycle
    /// holds neutral in Idle when its actions run out (instead of returning home) until
    /// [`Self::push_action`] adds one.
    pub fn set_external_plan(&mut self, on: bool) {
        self.external_plan = on;
    }

    /// Hook for the online soil hardness index (thesis 5.2, `crate::session::planned`): the index Autodig uses
    /// from the next dig on. Non-finite values are ignored.
    pub fn set_hardness_index(&mut self, index: f64) {
        if index.is_finite() {
            self.autodig_config.hardness_index = index;
        }
    }

    /// The operator's pause (`true`) or resume: while paused the current action runs to its end and
    /// no new one starts (the cycle holds neutral in Idle, disarmed).
    pub fn set_paused(&mut self, paused: bool) {
        self.paused = paused;
    }

    /// Whether the operator paused the cycle.
    pub fn paused(&self) -> bool {
        self.paused
    }

    /// The operator's stop: the current action runs to its end, then the cycle returns home and
    /// finishes instead of starting another.
    pub fn request_stop(&mut self) {
        self.stop_requested = true;
    }

    /// Whether the operator asked the cycle to stop.
    pub fn stop_requested(&self) -> bool {
        self.stop_requested
    }

    /// True when the cycle waits for the next action from an external source.
    pub fn needs_action(&self) -> bool {
        self.external_plan
            && !self.paused
            && !self.stop_requested
            && self.started
            && self.phase == Phase::Idle
            && self.action_index >= self.config.actions.len()
            && !self.finished_digs()
    }

    /// Appends an action to the plan (its start pose resolved now).
    ///
    /// # Errors
    /// [`ControllerError::Kinematics`] for an unreachable start, [`ControllerError::Config`] for a
    /// non-positive track distance.
    pub fn push_action(&mut self, action: Action, kin: &Kinematics) -> Result<(), ControllerError> {
        let start = match &action {
            Action::Dig { start, .. } | Action::Cleanup { start, .. } => start.resolve(kin)?,
            Action::TrackBack { distance_m } => {
                if !(distance_m.is_finite() && *distance_m > 0.0) {
                    return Err(ControllerError::Config {
                        field: "actions.track_back.distance_m",
                        reason: "must be finite and > 0".to_owned(),
                    });
                }
                JointAngles::default()
            }
        };
        self.config.actions.push(action);
        self.starts.push(start);
        Ok(())
    }

    /// Starts (or resumes) the plan at the next step.
    pub fn start(&mut self) {
        self.started = true;
    }

    /// Ends the plan: the machine holds neutral and disarms.
    pub fn stop(&mut self) {
        self.started = false;
        self.autodig = None;
        self.cleanup = None;
        self.phase = Phase::Finished;
    }

    /// The configuration.
    pub fn config(&self) -> &CycleConfig {
        &self.config
    }

    /// The current phase.
    pub fn phase(&self) -> Phase {
        self.phase
    }

    /// Autodig's stage while it runs.
    pub fn autodig_stage(&self) -> Option<Stage> {
        self.autodig.as_ref().map(Autodig::stage)
    }

    /// The index of the current action in the plan.
    pub fn action_index(&self) -> usize {
        self.action_index
    }

    /// The current action.
    pub fn action(&self) -> Option<&Action> {
        self.config.actions.get(self.action_index)
    }

    /// Digs completed (dig and cleanup actions).
    pub fn digs_done(&self) -> u32 {
        self.digs_done
    }

    /// Statistics of the completed digs.
    pub fn stats(&self) -> &[DigStats] {
        &self.stats
    }

    /// The floor estimate kept between cleanups.
    pub fn floor(&self) -> FloorEstimate {
        self.floor
    }

    /// The terrain map in use.
    pub fn terrain(&self) -> Option<&TerrainGrid> {
        self.terrain.as_ref()
    }

    /// The soil hardness index Autodig is configured with.
    pub fn hardness_index(&self) -> f64 {
        self.autodig
            .as_ref()
            .map_or(self.autodig_config.hardness_index, Autodig::hardness_index)
    }

    /// Whether a dig or cleanup is in progress (from the move to the dig to the end of the dump).
    pub fn in_dig(&self) -> bool {
        self.record.is_some()
            || (matches!(self.phase, Phase::Scan | Phase::MoveToDig)
                && self
                    .action()
                    .is_some_and(|a| a.kind() != ActionKind::TrackBack))
    }

    /// The swept volume of the running dig, m^3.
    pub fn swept_volume_m3(&self) -> Option<f64> {
        self.swept.as_ref().map(SweptVolume::volume_m3)
    }

    /// True once after the cycle asked for a range scan.
    pub fn take_scan_request(&mut self) -> bool {
        std::mem::take(&mut self.scan_request)
    }

    /// Hands over a terrain map (from a range scan); used by the next dig.
    pub fn provide_terrain(&mut self, terrain: TerrainGrid) {
        self.terrain = Some(terrain);
        self.terrain_fresh = true;
        self.clearance_profile.clear();
    }

    /// Called by the node when a fault stopped motion: a failed action is abandoned (its partial
    /// statistics are dropped), the bucket emptied, and the action tried again up to
    /// [`CycleConfig::retries`] times before the plan goes on with the next one; any other fault pauses
    /// the current phase, which resumes after the re-arm.
    pub fn on_fault(&mut self, control: bool) {
        if let Some(r) = &mut self.record {
            // The motion stopped: do not integrate across the gap.
            r.last_lengths_m = None;
            r.last_s = None;
        }
        self.settle_since_s = None;
        if control {
            let retry = !self.external_plan && self.failed_attempts < self.config.retries;
            if retry {
                self.failed_attempts += 1;
                tracing::warn!(
                    action = self.action_index,
                    attempt = self.failed_attempts + 1,
                    "action abandoned: it is tried again"
                );
            } else {
                tracing::warn!(action = self.action_index, "action abandoned: going on");
            }
            self.retry_pending = retry;
            self.autodig = None;
            self.cleanup = None;
            self.swept = None;
            self.record = None;
            if matches!(
                self.phase,
                Phase::MoveToDig | Phase::Autodig | Phase::Cleanup | Phase::Weigh
            ) {
                // Raise and empty whatever is in the bucket before going on.
                self.phase = Phase::SwingToDump;
            } else {
                if !std::mem::take(&mut self.retry_pending) {
                    self.action_index += 1;
                    self.failed_attempts = 0;
                }
                self.phase = Phase::Idle;
            }
        }
    }

    fn set_phase(&mut self, phase: Phase, now_s: f64) {
        tracing::debug!(?phase, "work cycle phase");
        self.phase = phase;
        self.phase_since_s = now_s;
        self.settle_since_s = None;
        self.lifted = false;
        self.stall_boost = [0.0; 4];
        self.stall_best_rad = [f64::INFINITY; 4];
        self.relief_since_s = None;
        self.relief_seen_s = f64::NEG_INFINITY;
        self.last_move_s = None;
        self.move_best_m = f64::INFINITY;
        self.move_progress_s = now_s;
        self.clearing = false;
        self.clearance_profile.clear();
    }

    fn hold(&self) -> CycleOutput {
        CycleOutput {
            want: self.phase.mode(),
            command: CycleCommand::Neutral,
        }
    }

    /// True when `done` has held for `settle_s`.
    fn settled(&mut self, done: bool, now_s: f64) -> bool {
        if !done {
            self.settle_since_s = None;
            return false;
        }
        let since = *self.settle_since_s.get_or_insert(now_s);
        now_s - since >= self.config.settle_s
    }

    fn timed_out(&self, now_s: f64) -> bool {
        now_s - self.phase_since_s > self.config.move_timeout_s
    }

    /// One period at `now_s` with the estimate; `armed` is the mode the safety layer allows motion in.
    ///
    /// # Errors
    /// [`ControlFault`] when Autodig or cleanup reject their inputs, a waypoint is out of reach, or a
    /// move times out: send neutral, then call [`Self::on_fault`] with `control = true`.
    pub fn step(
        &mut self,
        now_s: f64,
        est: &Estimator,
        armed: Option<ArmMode>,
    ) -> Result<CycleOutput, ControlFault> {
        self.last_now_s = now_s;
        if self.phase == Phase::Idle {
            if !self.started {
                return Ok(self.hold());
            }
            self.begin_action(now_s, est);
        }
        let want = self.phase.mode();
        if want.is_some() && armed != want && self.phase != Phase::Scan {
            // Not (yet) allowed to move: hold, and keep the phase's clock from counting the wait.
            self.phase_since_s = now_s;
            self.settle_since_s = None;
            if let Some(r) = &mut self.record {
                r.last_lengths_m = None;
                r.last_s = None;
            }
            return Ok(self.hold());
        }
        let command = match self.phase {
            Phase::Idle | Phase::Finished => CycleCommand::Neutral,
            Phase::Scan => self.step_scan(now_s),
            Phase::MoveToDig => self.step_move_to_dig(now_s, est)?,
            Phase::Autodig => self.step_autodig(now_s, est)?,
            Phase::Cleanup => self.step_cleanup(now_s, est)?,
            Phase::Weigh => self.step_weigh(now_s, est),
            Phase::SwingToDump => self.step_swing_to(now_s, est, self.config.dump_swing_rad)?,
            Phase::Dump => self.step_dump(now_s, est)?,
            Phase::TrackBack => self.step_track(now_s, est)?,
            Phase::Return => self.step_swing_to(now_s, est, self.config.home_swing_rad)?,
        };
        Ok(CycleOutput {
            want: self.phase.mode(),
            command,
        })
    }

    fn finished_digs(&self) -> bool {
        self.config.max_digs.is_some_and(|n| self.digs_done >= n)
    }

    fn begin_action(&mut self, now_s: f64, est: &Estimator) {
        if self.stop_requested {
            self.set_phase(Phase::Return, now_s);
            return;
        }
        if self.paused {
            return; // hold in Idle until resumed
        }
        if self.action_index >= self.config.actions.len() {
            if self.external_plan && !self.finished_digs() {
                return; // hold in Idle until push_action
            }
            if self.config.repeat && !self.config.actions.is_empty() && !self.finished_digs() {
                self.action_index = 0;
            } else {
                self.set_phase(Phase::Return, now_s);
                return;
            }
        }
        if self.finished_digs() {
            self.set_phase(Phase::Return, now_s);
            return;
        }
        match self.config.actions.get(self.action_index) {
            Some(Action::TrackBack { distance_m }) => {
                let [l, r] = est.state().track_travel_m;
                self.track_target_m = 0.5 * (l + r) - distance_m;
                tracing::info!(distance_m, "tracking backwards");
                self.set_phase(Phase::TrackBack, now_s);
            }
            Some(_) => {
                if self.config.scan {
                    self.scan_request = true;
                    self.terrain_fresh = false;
                    self.set_phase(Phase::Scan, now_s);
                } else {
                    self.set_phase(Phase::MoveToDig, now_s);
                }
            }
            None => self.set_phase(Phase::Return, now_s),
        }
    }

    fn next_action(&mut self, now_s: f64) {
        if !std::mem::take(&mut self.retry_pending) {
            self.action_index += 1;
            self.failed_attempts = 0;
        }
        self.phase = Phase::Idle;
        self.phase_since_s = now_s;
    }

    fn step_scan(&mut self, now_s: f64) -> CycleCommand {
        if self.terrain_fresh {
            self.set_phase(Phase::MoveToDig, now_s);
        } else if now_s - self.phase_since_s > self.config.scan_timeout_s {
            tracing::warn!("no range scan in time: digging without the perception enhancements");
            self.set_phase(Phase::MoveToDig, now_s);
        }
        CycleCommand::Neutral
    }
}

#[cfg(test)]
mod tests {

    use crate::step::cycle::{Action, CycleCommand, CycleConfig, Phase};
    use crate::step::safety::ArmMode;

    use crate::step::cycle::test_support::{cycle, est_at, kin};

    #[test]
    fn default_start_pose_is_reachable_and_inside_the_limits() {
        let (k, _) = kin();
        for a in CycleConfig::default().actions {
            if let Action::Dig { start, .. } = a {
                let q = start.resolve(&k).expect("reachable");
                k.check_limits(&q).expect("limits");
                let stick_abs = q.stick_abs_rad().to_degrees();
                assert!((-100.0..-20.0).contains(&stick_abs), "{stick_abs}");
            }
        }
    }

    #[test]
    fn idle_until_started_and_wants_no_arming() {
        let mut c = cycle(CycleConfig::default());
        let e = est_at([0.3, -1.6, -0.9, 0.0], 0.0, 0.0);
        let out = c.step(0.0, &e, None).unwrap();
        assert_eq!(out.want, None);
        assert_eq!(out.command, CycleCommand::Neutral);
        c.start();
        let out = c.step(0.01, &e, None).unwrap();
        assert_eq!(c.phase(), Phase::Scan);
        assert!(c.take_scan_request());
        assert!(!c.take_scan_request());
        assert_eq!(out.want, Some(ArmMode::Valve));
    }

    #[test]
    fn holds_neutral_until_armed() {
        let mut c = cycle(CycleConfig {
            scan: false,
            ..CycleConfig::default()
        });
        c.start();
        let e = est_at([0.0, -1.6, -0.9, 0.5], 0.0, 0.0);
        let out = c.step(0.0, &e, None).unwrap();
        assert_eq!(c.phase(), Phase::MoveToDig);
        assert_eq!(out.command, CycleCommand::Neutral);
        let out = c.step(0.01, &e, Some(ArmMode::Valve)).unwrap();
        let CycleCommand::Valves(v) = out.command else {
            panic!("{out:?}")
        };
        // Boom below the start pose: raise first (extend), no swing yet.
        assert!(v[0] > 0.0, "{v:?}");
    }

    #[test]
    fn a_control_fault_abandons_the_dig_and_empties_the_bucket() {
        let mut c = cycle(CycleConfig {
            scan: false,
            ..CycleConfig::default()
        });
        c.start();
        let e = est_at([0.3, -1.6, -0.9, 0.0], 0.0, 0.0);
        c.step(0.0, &e, Some(ArmMode::Valve)).unwrap();
        assert_eq!(c.phase(), Phase::MoveToDig);
        c.on_fault(true);
        assert_eq!(c.phase(), Phase::SwingToDump);
        assert!(c.stats().is_empty());
    }

    #[test]
    fn an_abandoned_action_is_tried_again_then_skipped() {
        let mut c = cycle(CycleConfig {
            actions: vec![
                Action::TrackBack { distance_m: 1.0 },
                Action::TrackBack { distance_m: 2.0 },
            ],
            repeat: false,
            ..CycleConfig::default()
        });
        c.start();
        let e = est_at([0.3, -1.6, -0.9, 0.0], 5.0, 0.0);
        c.step(0.0, &e, Some(ArmMode::Valve)).unwrap();
        assert_eq!((c.phase(), c.action_index()), (Phase::TrackBack, 0));
        c.on_fault(true);
        c.step(0.1, &e, Some(ArmMode::Valve)).unwrap();
        assert_eq!(
            (c.phase(), c.action_index()),
            (Phase::TrackBack, 0),
            "retried once"
        );
        c.on_fault(true);
        c.step(0.2, &e, Some(ArmMode::Valve)).unwrap();
        assert_eq!(
            (c.phase(), c.action_index()),
            (Phase::TrackBack, 1),
            "then skipped"
        );
        // The next action has its own retry.
        c.on_fault(true);
        c.step(0.3, &e, Some(ArmMode::Valve)).unwrap();
        assert_eq!((c.phase(), c.action_index()), (Phase::TrackBack, 1));
    }
}
