//! The session driver: the loop around the controller node that asks the dig planner for the next
//! action and runs it (thesis 5.3, Fig. 42), the one that `demo`, the experiments and `run` share.
//!
//! Called once after every control step ([`SessionDriver::after_step`]), it
//! - answers the work cycle's scan requests with range scans from a [`ScanSource`] (the embedded
//!   simulator in-process, the scan service on a machine) and hands the terrain to the cycle;
//! - when the cycle waits for an action, scans the workspace, lets the [`PlannedSession`] plan the next
//!   dig, cleanup or track back at the dead-reckoned pose and pushes it (or replays the predefined
//!   sequence of 6.2);
//! - follows each dig: its tip path, the soil samples for the online soil estimate (5.2), and at its
//!   end carves the bucket's pass into the map, marks barren starts, and sets the hardness index of
//!   the next digs from the soil estimate.
//!
//! It reports what happened as [`SessionEvent`]s so that a caller can keep its own records (the lab
//! adds the simulator's truth to each dig) without a second copy of this logic.

use firmware_bridge::scan::{Scan, ScanRequest};
use planner::estimate::SoilSample;
use planner::kinematics::{JointAngles, MachinePose, wrap_angle};
use planner::plan::ActionChoice;

use crate::session::planned::{PlannedSession, SoilMonitor, plane_section};
use crate::session::snapshot::{DriverSnapshot, PlannedDig, PredefinedSequence, Strategy};
use crate::session::state_file::FieldError;
use crate::step::cycle::{Action, Phase};
use crate::step::node::ControllerNode;

/// Where range scans come from. A scan is requested, then taken when it is there: the in-process
/// simulator answers at once, a scan service over the network some control periods later, and the
/// control loop never waits for it.
pub trait ScanSource {
    /// Starts a scan for `request` (a source that answers at once keeps the scan for [`Self::take`]).
    fn request(&mut self, request: &ScanRequest);

    /// The requested scan once it is there: `None` while it is on its way.
    ///
    /// # Errors
    /// When no scan can be had (the source's error, boxed).
    fn take(&mut self) -> Option<Result<Scan, BoxError>>;
}

/// Watches a session from the control loop (a live view, a recorder): called after every control
/// step with the node and what the session driver reported for that step. It runs on the control
/// loop, so it must return at once: hand the data to another thread and drop it when that thread is
/// behind, never wait. `demo` and `run` call it at the same point of their loops.
pub trait SessionObserver {
    /// After the control step at `time_s` and the driver's [`SessionDriver::after_step`] (its
    /// `events`); `session` is the planned session when the planner drives (its terrain map).
    fn after_step(
        &mut self,
        time_s: f64,
        node: &ControllerNode,
        session: Option<&PlannedSession>,
        events: &[SessionEvent],
    );

    /// The session ended at `time_s` because of `reason`.
    fn finished(&mut self, time_s: f64, reason: &str) {
        let _ = (time_s, reason);
    }

    /// The session takes operator commands (pause, resume, e-stop, reset, stop) from `sender`, the
    /// control loop's [`crate::io::operator::OperatorPort`]: an observer that offers them (the live
    /// view's operator page) keeps it. Called once, before the first step.
    fn operator_control(&mut self, sender: crate::io::operator::OperatorSender) {
        let _ = sender;
    }
}

/// The observer that watches nothing.
#[derive(Debug, Clone, Copy, Default)]
pub struct NoObserver;

impl SessionObserver for NoObserver {
    fn after_step(
        &mut self,
        _time_s: f64,
        _node: &ControllerNode,
        _session: Option<&PlannedSession>,
        _events: &[SessionEvent],
    ) {
    }
}

/// What a pending scan is for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum ScanPurpose {
    /// The work cycle asked for it (the dig's perception, 3.2).
    Cycle,
    /// The planner's view of the workspace before it plans.
    Workspace,
}

/// A boxed error of a [`ScanSource`].
pub type BoxError = Box<dyn std::error::Error + Send + Sync + 'static>;

/// Errors that end a session.
#[derive(Debug, thiserror::Error)]
pub enum DriverError {
    /// The scan source failed. Its message carries its causes, so it is not also a `source` (the
    /// chain would print them again).
    #[error("range scan: {0}")]
    Scan(BoxError),
    /// The planned session failed outside planning (predefined start, the cycle refused an action).
    #[error(transparent)]
    Session(#[from] crate::session::planned::SessionError),
    /// The controller refused an action.
    #[error(transparent)]
    Controller(#[from] crate::ControllerError),
    /// The predefined sequence has no start.
    #[error("predefined sequence: no start joints (no valid dig on the map)")]
    NoPredefinedStart,
}

/// What happened in one call of [`SessionDriver::after_step`], in order.
#[derive(Debug, Clone, PartialEq)]
pub enum SessionEvent {
    /// A scan was taken (the work cycle's or the planner's workspace scan).
    Scanned(Scan),
    /// The work cycle changed phase.
    PhaseChanged {
        /// Before.
        from: Phase,
        /// Now.
        to: Phase,
    },
    /// A dig or cleanup began (Autodig or cleanup entered).
    DigStarted {
        /// What the planner predicted for it (default for the fixed plan).
        planned: PlannedDig,
        /// The machine pose the controller dead-reckons at its start.
        pose: MachinePose,
    },
    /// A dig or cleanup ended: its statistics are `node.statistics()[index]`.
    DigFinished {
        /// Index into the node's statistics.
        index: usize,
        /// The bucket tip path `(r, z)` in the base frame, m.
        tip_path: Vec<(f64, f64)>,
        /// The soil samples of the dig (4.3.5).
        soil_samples: Vec<SoilSample>,
    },
}

/// The dig in progress.
#[derive(Debug)]
struct DigInProgress {
    planned: PlannedDig,
    pose: MachinePose,
    tip_path: Vec<(f64, f64)>,
}

/// The session driver (module docs).
#[derive(Debug)]
pub struct SessionDriver {
    session: Option<PlannedSession>,
    predefined_joints: Option<JointAngles>,
    planned: Vec<PlannedDig>,
    over: Option<String>,
    plan_ms: Vec<f64>,
    soil: SoilMonitor,
    soil_samples: Vec<SoilSample>,
    dig: Option<DigInProgress>,
    digs_done: usize,
    last_phase: Phase,
    track_backs: usize,
    backups: usize,
    steps: u64,
    pending_scan: Option<ScanPurpose>,
    cycle_scan_wanted: bool,
    events: Vec<SessionEvent>,
    detached: bool,
    job: Option<Staged>,
    workspace_scan_failures: u32,
    /// The cycle's `(action index, actions)` at the last checkpoint.
    checkpoint_key: Option<(usize, usize)>,
    /// The checkpoint taken in the last [`Self::after_step`], if any.
    checkpoint: Option<Box<DriverSnapshot>>,
    /// A checkpoint taken by [`Self::finish_plan`] between two steps, reported by the next
    /// [`Self::after_step`].
    planned_checkpoint: Option<Box<DriverSnapshot>>,
}

/// A detached planning step.
#[derive(Debug)]
enum Staged {
    /// Staged, not yet taken.
    Ready(Box<PlanJob>),
    /// Taken: running off the loop.
    Away,
}

impl SessionDriver {
    /// A driver for `node`: with a planned session the planner supplies every action (the node is
    /// switched to an external plan); without one the node runs its own action list. For the
    /// predefined strategy `predefined_joints` is the sequence's start (else the virtual expert's).
    pub fn new(
        session: Option<PlannedSession>,
        predefined_joints: Option<JointAngles>,
        node: &mut ControllerNode,
    ) -> Self {
        if session.is_some() {
            node.set_external_plan(true);
        }
        Self {
            session,
            predefined_joints,
            planned: Vec::new(),
            over: None,
            plan_ms: Vec::new(),
            soil: SoilMonitor::default(),
            soil_samples: Vec::new(),
            dig: None,
            digs_done: 0,
            last_phase: node.cycle().phase(),
            track_backs: 0,
            backups: 0,
            steps: 0,
            pending_scan: None,
            cycle_scan_wanted: false,
            events: Vec::new(),
            detached: false,
            job: None,
            workspace_scan_failures: 0,
            checkpoint_key: None,
            checkpoint: None,
            planned_checkpoint: None,
        }
    }

    /// The checkpoint the last [`Self::after_step`] took, if it took one: the session between two
    /// actions, to be saved by the caller with its records ([`crate::session::session_state`]).
    pub fn checkpoint(&self) -> Option<&DriverSnapshot> {
        self.checkpoint.as_deref()
    }

    /// The driver's and `node`'s state now (the planned session must be here, not out planning).
    pub fn snapshot(&self, node: &ControllerNode) -> DriverSnapshot {
        DriverSnapshot {
            cycle: node.cycle().snapshot(),
            pose: node.estimator().state().pose,
            odometry_m: node.estimator().odometry_m(),
            planned: self.planned.clone(),
            plan_ms: self.plan_ms.clone(),
            soil_window: self.soil.window(),
            track_backs: self.track_backs,
            backups: self.backups,
            predefined_joints: self.predefined_joints,
            over: self.over.clone(),
            session: self.session.as_ref().map(PlannedSession::snapshot),
        }
    }

    /// Puts a saved session into this fresh driver and its fresh `node` (built from the same
    /// configuration): the session goes on at the saved action after the arming handshake.
    ///
    /// # Errors
    /// The field of `s` that does not fit (`driver.` prefixed): a planned session saved for a run
    /// without one or the reverse, another strategy or map grid, a plan the node refuses.
    pub fn restore(
        &mut self,
        s: &DriverSnapshot,
        node: &mut ControllerNode,
    ) -> Result<(), FieldError> {
        match (&mut self.session, &s.session) {
            (Some(session), Some(saved)) => session
                .restore(saved)
                .map_err(|e| e.within("driver.session"))?,
            (None, None) => {}
            (have, _) => {
                return Err(FieldError::new(
                    "driver.session",
                    if have.is_some() {
                        "the state has no planned session, this run plans"
                    } else {
                        "the state has a planned session, this run has none"
                    },
                ));
            }
        }
        node.restore(&s.cycle, s.pose, s.odometry_m)
            .map_err(|e| FieldError::new("driver.cycle", e.to_string()))?;
        if let Some(session) = &self.session
            && let Some(index) = session.hardness_index()
        {
            node.set_hardness_index(index);
        }
        if s.over.is_some() {
            node.set_external_plan(false);
        }
        self.planned.clone_from(&s.planned);
        self.plan_ms.clone_from(&s.plan_ms);
        self.soil.restore_window(&s.soil_window);
        self.digs_done = s.cycle.stats.len();
        self.track_backs = s.track_backs;
        self.backups = s.backups;
        self.predefined_joints = s.predefined_joints;
        self.over.clone_from(&s.over);
        self.checkpoint_key = Some((s.cycle.action_index, s.cycle.actions.len()));
        Ok(())
    }

    /// Takes a checkpoint when the cycle stands between actions, the last dig's bookkeeping is done,
    /// the session is here and the plan moved on since the last one: before a planning step, and
    /// once its action is pushed but not begun, so that a resumed session runs that action again
    /// from its start instead of planning another from the half-dug ground.
    fn take_checkpoint(&mut self, node: &ControllerNode) -> Option<Box<DriverSnapshot>> {
        let cycle = node.cycle();
        let key = (cycle.action_index(), cycle.config().actions.len());
        let between = cycle.phase() == Phase::Idle
            && self.dig.is_none()
            && self.digs_done == node.statistics().len()
            && self.job.is_none();
        if between && self.checkpoint_key != Some(key) {
            self.checkpoint_key = Some(key);
            return Some(Box::new(self.snapshot(node)));
        }
        None
    }

    /// The planned session, if the planner drives (`None` while a detached planning step holds it).
    pub fn session(&self) -> Option<&PlannedSession> {
        self.session.as_ref()
    }

    /// Why the planner ended the session, once it has.
    pub fn end_reason(&self) -> Option<&str> {
        self.over.as_deref()
    }

    /// Wall time of each planning cycle, ms.
    pub fn planning_ms(&self) -> &[f64] {
        &self.plan_ms
    }

    /// Track backs begun.
    pub fn track_backs(&self) -> usize {
        self.track_backs
    }

    /// Track backs completed.
    pub fn backups(&self) -> usize {
        self.backups
    }

    /// Digs and cleanups completed.
    pub fn digs_done(&self) -> usize {
        self.digs_done
    }

    /// One call after every control step of `node`: scans, planning, dig bookkeeping (module docs).
    /// Returns what happened.
    ///
    /// # Errors
    /// [`DriverError`]: the scan source failed, the predefined sequence has no start, or the cycle
    /// refused an action. A planning failure is not an error: it ends the session
    /// ([`Self::end_reason`]) and the node finishes its cycle.
    pub fn after_step(
        &mut self,
        node: &mut ControllerNode,
        scans: &mut dyn ScanSource,
    ) -> Result<&[SessionEvent], DriverError> {
        self.events.clear();
        self.checkpoint = self.planned_checkpoint.take();
        if node.take_scan_request() {
            self.cycle_scan_wanted = true;
        }
        if self.cycle_scan_wanted && self.pending_scan.is_none() {
            scans.request(&scan_request(node));
            self.pending_scan = Some(ScanPurpose::Cycle);
            self.cycle_scan_wanted = false;
        }
        if self.pending_scan == Some(ScanPurpose::Cycle)
            && let Some(result) = scans.take()
        {
            self.pending_scan = None;
            match result {
                Ok(scan) => self.on_cycle_scan(node, scan),
                // The cycle's own scan timeout lets Autodig dig on its plain angle rules.
                Err(e) => tracing::warn!(error = %e, "range scan failed: plain angle rules"),
            }
        }
        self.plan(node, scans)?;
        self.follow_dig(node);
        if let Some(cp) = self.take_checkpoint(node) {
            self.checkpoint = Some(cp);
        }
        self.steps += 1;
        Ok(&self.events)
    }

    /// A scan the work cycle asked for: into the session's map (or binned on the cycle's grid
    /// without a session) and on to the cycle.
    fn on_cycle_scan(&mut self, node: &mut ControllerNode, scan: Scan) {
        let terrain = match &mut self.session {
            // The session's map fuses every scan; the cycle digs with it (3.2).
            Some(s) => s
                .observe_scan_from(scan_origin(&scan), &scan.points)
                .map(|_| s.terrain().clone())
                .map_err(|e| e.to_string()),
            None => node
                .cycle()
                .config()
                .scan_grid
                .terrain(&scan.points)
                .map_err(|e| e.to_string()),
        };
        match terrain {
            Ok(grid) => {
                tracing::info!(
                    points = scan.points.len(),
                    "range scan: terrain map handed to the work cycle"
                );
                node.provide_terrain(grid);
            }
            Err(e) => tracing::warn!(error = %e, "scan not usable"),
        }
        self.events.push(SessionEvent::Scanned(scan));
    }

    /// When the cycle waits for an action: scan the workspace, then plan (here, or off the loop as a
    /// [`PlanJob`] when planning is detached) and push.
    fn plan(
        &mut self,
        node: &mut ControllerNode,
        scans: &mut dyn ScanSource,
    ) -> Result<(), DriverError> {
        if self.session.is_none()
            || self.job.is_some()
            || self.over.is_some()
            || !node.cycle().needs_action()
        {
            return Ok(());
        }
        // The map must show the last dig: scan the workspace (swing 0 +- the fan) first.
        if self.pending_scan.is_none() {
            scans.request(&scan_toward(node, 0.0));
            self.pending_scan = Some(ScanPurpose::Workspace);
        }
        if self.pending_scan != Some(ScanPurpose::Workspace) {
            return Ok(());
        }
        let Some(result) = scans.take() else {
            return Ok(());
        };
        self.pending_scan = None;
        let scan = match result {
            Ok(scan) => {
                self.workspace_scan_failures = 0;
                scan
            }
            Err(e) => {
                // Asked again on the next step; a scan service that keeps failing ends the session.
                self.workspace_scan_failures += 1;
                tracing::warn!(
                    error = %e,
                    failures = self.workspace_scan_failures,
                    "workspace scan failed"
                );
                if self.workspace_scan_failures >= MAX_WORKSPACE_SCAN_FAILURES {
                    return Err(DriverError::Scan(e));
                }
                return Ok(());
            }
        };
        // The last chance to save the session between these two actions before the planner holds it.
        if let Some(cp) = self.take_checkpoint(node) {
            self.checkpoint = Some(cp);
        }
        let Some(session) = self.session.take() else {
            return Ok(());
        };
        self.events.push(SessionEvent::Scanned(scan.clone()));
        let job = PlanJob {
            session,
            scan,
            pose: node.estimator().state().pose,
            predefined_joints: self.predefined_joints,
        };
        if self.detached {
            self.job = Some(Staged::Ready(Box::new(job)));
            Ok(())
        } else {
            self.finish_plan(node, job.run())
        }
    }

    /// Plans off the control loop: [`Self::after_step`] then stages each planning step as a
    /// [`PlanJob`] ([`Self::take_plan_job`]) instead of running it, and the work cycle holds in Idle
    /// until [`Self::finish_plan`] pushes the action. The session is inside the job meanwhile
    /// ([`Self::session`] is `None`, [`Self::planning`] true).
    pub fn set_detached_planning(&mut self, detached: bool) {
        self.detached = detached;
    }

    /// The staged planning step, once (detached planning): run it anywhere ([`PlanJob::run`]) and
    /// hand its outcome to [`Self::finish_plan`].
    pub fn take_plan_job(&mut self) -> Option<PlanJob> {
        match self.job.take() {
            Some(Staged::Ready(job)) => {
                self.job = Some(Staged::Away);
                Some(*job)
            }
            other => {
                self.job = other;
                None
            }
        }
    }

    /// Whether a planning step is out (staged or running).
    pub fn planning(&self) -> bool {
        self.job.is_some()
    }

    /// A planning step's outcome after the loop stopped: the session comes back, its action is
    /// dropped.
    pub fn return_session(&mut self, outcome: PlanOutcome) {
        self.job = None;
        self.session = Some(outcome.session);
        self.predefined_joints = outcome.predefined_joints;
    }

    /// A planning step's outcome: the session comes back, the action (if any) goes to the cycle.
    ///
    /// # Errors
    /// [`DriverError`]: the predefined sequence has no start, or the cycle refused the action.
    pub fn finish_plan(
        &mut self,
        node: &mut ControllerNode,
        outcome: PlanOutcome,
    ) -> Result<(), DriverError> {
        self.job = None;
        let PlanOutcome {
            session,
            predefined_joints,
            result,
            plan_ms,
        } = outcome;
        self.session = Some(session);
        self.predefined_joints = predefined_joints;
        match result? {
            Planned::Action { action, planned } => {
                self.plan_ms.push(plan_ms);
                // The cycle appends: the action's index is the current plan length.
                let index = node.cycle().config().actions.len();
                if self.planned.len() <= index {
                    self.planned.resize(index + 1, PlannedDig::default());
                }
                self.planned[index] = planned;
                node.push_action(action)?;
                // Saved before the cycle begins it: a resumed session runs this action again.
                if let Some(cp) = self.take_checkpoint(node) {
                    self.planned_checkpoint = Some(cp);
                }
            }
            Planned::Over(reason) => {
                self.over = Some(reason);
                node.set_external_plan(false);
            }
        }
        Ok(())
    }

    /// Phase changes, the dig's tip path and soil samples, and the planner's updates at its end.
    fn follow_dig(&mut self, node: &mut ControllerNode) {
        let phase = node.cycle().phase();
        if phase != self.last_phase {
            self.events.push(SessionEvent::PhaseChanged {
                from: self.last_phase,
                to: phase,
            });
            if matches!(phase, Phase::Autodig | Phase::Cleanup) && self.dig.is_none() {
                let planned = self
                    .planned
                    .get(node.cycle().action_index())
                    .copied()
                    .unwrap_or_default();
                let pose = node.estimator().state().pose;
                self.soil_samples.clear();
                if let Some(s) = &self.session {
                    let swing_rad = node.state().swing_rad;
                    self.soil.begin(plane_section(
                        s.terrain(),
                        &pose,
                        swing_rad,
                        1.0,
                        12.0,
                        0.05,
                    ));
                }
                self.dig = Some(DigInProgress {
                    planned,
                    pose,
                    tip_path: Vec::new(),
                });
                self.events.push(SessionEvent::DigStarted { planned, pose });
            }
            if phase == Phase::TrackBack {
                self.track_backs += 1;
            }
            if self.last_phase == Phase::TrackBack {
                self.backups += 1;
            }
            self.last_phase = phase;
        }
        if matches!(phase, Phase::Autodig | Phase::Cleanup)
            && let Some(dig) = &mut self.dig
        {
            let st = node.state();
            dig.tip_path.push((st.tip.x_m, st.tip.z_m));
            if phase == Phase::Autodig
                && self.steps.is_multiple_of(2)
                && let Some(sample) = self.soil.sample(
                    &st.tip,
                    st.tip_force,
                    node.cycle().swept_volume_m3().unwrap_or(0.0),
                )
            {
                self.soil_samples.push(sample);
            }
        }
        if node.statistics().len() > self.digs_done
            && let Some(dig) = self.dig.take()
        {
            self.finish_dig(node, dig);
        }
    }

    /// The end of a dig: the planner learns what it did (the map, barren starts, the soil).
    fn finish_dig(&mut self, node: &mut ControllerNode, dig: DigInProgress) {
        let index = self.digs_done;
        let Some(d) = node.statistics().get(index).copied() else {
            return;
        };
        // The map's dead reckoning of the pass: no material above the tip's path (the toe of the
        // face is out of the sensor's sight behind the crest).
        if let Some(s) = &mut self.session {
            let carved = s.observe_bucket_pass(&dig.pose, d.swing_rad, &dig.tip_path);
            tracing::debug!(carved, "bucket pass carved into the map");
            if d.action == crate::step::cycle::ActionKind::Dig
                && let (Some([r_m, z_m, _]), Some(predicted_m3)) =
                    (dig.planned.start, dig.planned.volume_m3)
                && s.observe_dig_outcome(
                    dig.pose.world_from_base(d.swing_rad, r_m, z_m),
                    d.swept_volume_m3,
                    predicted_m3,
                )
            {
                tracing::info!(
                    dig = d.number(),
                    swept_m3 = d.swept_volume_m3,
                    predicted_m3,
                    "barren dig: its start is not planned again until a track back"
                );
            }
            node.provide_terrain(s.terrain().clone());
        }
        self.digs_done += 1;
        self.events.push(SessionEvent::DigFinished {
            index,
            tip_path: dig.tip_path,
            soil_samples: std::mem::take(&mut self.soil_samples),
        });
        // 5.2 online: the soil estimate of the recent digs sets the next digs' index.
        if let Some(s) = &mut self.session
            && let Some(model) = self.soil.end()
        {
            match s.set_soil_estimate(model) {
                Ok(index) => node.set_hardness_index(index),
                Err(e) => tracing::warn!(error = %e, "soil estimate rejected"),
            }
        }
    }
}

/// Workspace scans failing in a row that end the session (a scan service that is gone).
pub const MAX_WORKSPACE_SCAN_FAILURES: u32 = 5;

/// A planning step off the control loop (detached planning): the session, the workspace scan and the
/// pose it was taken at.
#[derive(Debug)]
pub struct PlanJob {
    session: PlannedSession,
    scan: Scan,
    pose: MachinePose,
    predefined_joints: Option<JointAngles>,
}

/// What a [`PlanJob`] decided.
#[derive(Debug)]
enum Planned {
    /// The next action and the planner's prediction for it.
    Action { action: Action, planned: PlannedDig },
    /// The session is over, with the reason.
    Over(String),
}

/// The outcome of a [`PlanJob`], for [`SessionDriver::finish_plan`].
#[derive(Debug)]
pub struct PlanOutcome {
    session: PlannedSession,
    predefined_joints: Option<JointAngles>,
    result: Result<Planned, DriverError>,
    plan_ms: f64,
}

impl PlanJob {
    /// Fuses the workspace scan into the map and plans the next action (or sets up the predefined
    /// sequence and takes its next action). Takes up to a few hundred milliseconds.
    #[must_use]
    pub fn run(self) -> PlanOutcome {
        let Self {
            mut session,
            scan,
            pose,
            mut predefined_joints,
        } = self;
        let t0 = std::time::Instant::now();
        let result = plan_step(&mut session, &scan, &pose, &mut predefined_joints);
        PlanOutcome {
            session,
            predefined_joints,
            result,
            plan_ms: t0.elapsed().as_secs_f64() * 1e3,
        }
    }
}

/// The planning step of [`PlanJob::run`]. A planning failure is not an error: it ends the session.
fn plan_step(
    s: &mut PlannedSession,
    scan: &Scan,
    pose: &MachinePose,
    predefined_joints: &mut Option<JointAngles>,
) -> Result<Planned, DriverError> {
    if let Err(e) = s.observe_scan_from(scan_origin(scan), &scan.points) {
        tracing::warn!(error = %e, "workspace scan not usable");
    }
    if s.strategy() == Strategy::Predefined && s.predefined().is_none() {
        let start = match *predefined_joints {
            Some(q) => Some(q),
            None => s.virtual_expert_start(pose)?,
        };
        let Some(start) = start else {
            return Err(DriverError::NoPredefinedStart);
        };
        // The median start is a planned tip APPROACH_HEIGHT_M (0.8 m) up: Boom-Down starts above
        // the face everywhere (with 0.4 m, and no second raise, the move to a start on the face
        // pressed the bucket into it and timed out).
        *predefined_joints = Some(start);
        let seq = PredefinedSequence::from_planner(s.planner(), s.terrain(), pose, start)?;
        s.set_predefined(seq);
    }
    Ok(match s.next_action(pose) {
        Ok(Some(action)) => {
            let planned = match s.steps().last().and_then(|st| st.plan.as_ref()) {
                Some(plan) => match &plan.action {
                    ActionChoice::Dig(d) => PlannedDig {
                        quality: Some(d.quality.quality),
                        volume_m3: Some(d.summary.swept_volume_m3),
                        time_s: Some(d.summary.time_s),
                        energy_kj: Some(d.summary.energy_kj()),
                        min_tip_z_m: Some(d.summary.min_tip_z_m),
                        start: Some([d.pose.x_m, d.pose.z_m, d.pose.bucket_abs_rad.to_degrees()]),
                    },
                    _ => PlannedDig::default(),
                },
                None => PlannedDig::default(),
            };
            Planned::Action { action, planned }
        }
        Ok(None) => Planned::Over(s.end_reason().unwrap_or("nothing left to do").to_owned()),
        Err(e) => {
            tracing::warn!(error = %e, "planning failed: session ends");
            Planned::Over(format!("planning failed: {e}"))
        }
    })
}

/// The sensor's world position of a scan.
fn scan_origin(scan: &Scan) -> [f64; 3] {
    [scan.sensor.x_m, scan.sensor.y_m, scan.sensor.z_m]
}

/// The scan for the next dig: the default fan, turned toward the action's digging plane (the scan is
/// requested where the last dump left the machine; the sensor turns with the swing).
pub fn scan_request(node: &ControllerNode) -> ScanRequest {
    match node.action() {
        Some(Action::Dig { swing_rad, .. } | Action::Cleanup { swing_rad, .. }) => {
            scan_toward(node, *swing_rad)
        }
        _ => ScanRequest::default(),
    }
}

/// A scan request turned from the current swing to the digging plane at `target_swing_rad`.
fn scan_toward(node: &ControllerNode, target_swing_rad: f64) -> ScanRequest {
    let mut request = ScanRequest::default();
    let offset = wrap_angle(target_swing_rad - node.state().swing_rad);
    if offset.is_finite() {
        request.azimuth_min_rad += offset;
        request.azimuth_max_rad += offset;
    }
    request
}
