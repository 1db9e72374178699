//! [`ControllerNode`]: the controller's synchronous, clock-agnostic control step.
//!
//! `step(now_s, received) -> frames to send` combines the [`Estimator`], the [`Safety`] layer and the
//! [`WorkCycle`] (with Autodig and cleanup inside). It does no I/O and reads no clock, so the real-time
//! loop on SocketCAN ([`crate::run`]), the in-process demo and the tests drive the very same code. The
//! output is a fixed-capacity [`Outbox`]; the step allocates nothing except when a dig starts (the
//! pre-dig terrain section) and never panics.
//!
//! Per step, in order:
//!
//! 1. Received frames: error frames are bus faults; frames from the gateway (`0x80`) feed the
//!    estimator; decode errors of protocol frames, frames from the gateway's address that the gateway
//!    does not send, frames with the controller's own address (`0x27`) and protocol messages from other
//!    addresses are faults. Other traffic (unknown PGNs from other nodes, 11-bit ids, remote and FD
//!    frames) is counted and ignored: a real machine bus carries engine and display traffic.
//! 2. The estimator derives forces and the tip; the safety layer checks staleness, limits and the
//!    gateway status.
//! 3. The work cycle computes the wanted mode and command; a cycle error is a fault.
//! 4. The safety layer decides: motion commands (valves, or a position setpoint), neutral valves, the
//!    `ControllerStatus` (20 Hz: activity, Autodig stage, dig number, fault code) and the heartbeat,
//!    which is always the last frame of the step.
//!
//! Valve commands for boom, stick, bucket and swing go out every step while armed in valve mode; the
//! track valves every [`ControllerConfig::track_every_steps`] steps (20 Hz, docs/protocol.md), and at
//! once when they must become neutral.

use firmware_bridge::messages::{
    Activity, AutodigStageCode, AuxValveCommand, ControllerStatus as StatusMessage, Message,
    PositionSetpoint, Valve,
};
use firmware_bridge::transport::BusFault;
use firmware_bridge::{
    CONTROLLER_ADDRESS, CanFrame, CanId, DecodeError, GATEWAY_ADDRESS, J1939Id, TimestampedFrame,
};
use planner::autodig::{AutodigConfig, AutodigMaps, Stage};
use planner::cleanup::CleanupConfig;
use planner::kinematics::{Joint, Kinematics};
use planner::machine::MachineConfig;
use planner::terrain::TerrainGrid;
use serde::{Deserialize, Serialize};

use crate::ControllerError;
use crate::cycle::{Action, CycleCommand, CycleConfig, DigStats, Phase, WorkCycle};
use crate::estimate::{Estimator, EstimatorConfig, MachineState};
use crate::safety::{ArmMode, Fault, Safety, SafetyConfig, SafetyState, bus_fault_stops_motion};

/// Most frames one step sends: six valve commands or a setpoint, neutral valves, and the heartbeat.
pub const OUTBOX_CAPACITY: usize = 16;

/// The frames one step sends, in order (fixed capacity, no allocation).
#[derive(Clone, Copy)]
pub struct Outbox {
    frames: [CanFrame; OUTBOX_CAPACITY],
    len: usize,
}

impl std::fmt::Debug for Outbox {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_list().entries(self.as_slice()).finish()
    }
}

impl Outbox {
    /// An empty outbox.
    ///
    /// # Errors
    /// Never in practice: the filler frame (an empty 11-bit data frame) is always valid.
    pub fn new() -> Result<Self, firmware_bridge::frame::FrameError> {
        // Only `..len` is ever exposed; the filler is never sent.
        let filler = CanFrame::new_data(CanId::Standard(0), &[])?;
        Ok(Self {
            frames: [filler; OUTBOX_CAPACITY],
            len: 0,
        })
    }

    /// The frames, in send order.
    pub fn as_slice(&self) -> &[CanFrame] {
        &self.frames[..self.len]
    }

    /// Number of frames.
    pub fn len(&self) -> usize {
        self.len
    }

    /// True if nothing is to be sent.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Appends a frame; returns false (and drops it) when full.
    pub fn push(&mut self, frame: CanFrame) -> bool {
        match self.frames.get_mut(self.len) {
            Some(slot) => {
                *slot = frame;
                self.len += 1;
                true
            }
            None => false,
        }
    }

    fn clear(&mut self) {
        self.len = 0;
    }
}

impl std::ops::Deref for Outbox {
    type Target = [CanFrame];
    fn deref(&self) -> &[CanFrame] {
        self.as_slice()
    }
}

impl<'a> IntoIterator for &'a Outbox {
    type Item = &'a CanFrame;
    type IntoIter = std::slice::Iter<'a, CanFrame>;
    fn into_iter(self) -> Self::IntoIter {
        self.as_slice().iter()
    }
}

/// Everything the node is configured with (besides the machine and the Autodig maps).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ControllerConfig {
    /// Safety layer.
    pub safety: SafetyConfig,
    /// Estimator.
    pub estimator: EstimatorConfig,
    /// Work cycle and plan.
    pub cycle: CycleConfig,
    /// Autodig parameters. The relief pressures and the bucket capacity are taken from the machine
    /// file at construction; the perception flags are set per dig.
    pub autodig: AutodigConfig,
    /// Cleanup parameters (relief pressures from the machine file).
    pub cleanup: CleanupConfig,
    /// Send the track valve commands every this many steps (5: 20 Hz at 100 Hz). Default 5.
    pub track_every_steps: u32,
    /// Start the work cycle at the first step (otherwise call [`ControllerNode::start`]). Default true.
    pub autostart: bool,
}

impl Default for ControllerConfig {
    fn default() -> Self {
        Self {
            safety: SafetyConfig::default(),
            estimator: EstimatorConfig::default(),
            cycle: CycleConfig::default(),
            autodig: AutodigConfig::default(),
            // The gateway's position loop lags a lowering setpoint by several centimetres; a slower
            // probe and a larger lag threshold keep that lag from passing for floor contact. The
            // planner starts a cleanup above what is left of the bench (up to about 2.5 m over the
            // floor on the default bench), so the probe may need to go that far down.
            cleanup: CleanupConfig {
                descent_speed_m_per_s: 0.05,
                probe_lag_m: 0.15,
                probe_max_depth_m: 3.0,
                ..CleanupConfig::default()
            },
            track_every_steps: 5,
            autostart: true,
        }
    }
}

impl ControllerConfig {
    /// Parses a TOML file's text; missing fields take their defaults.
    ///
    /// # Errors
    /// [`ControllerError::Config`] with the parser's message.
    pub fn from_toml_str(text: &str) -> Result<Self, ControllerError> {
        toml::from_str(text).map_err(|e| ControllerError::Config {
            field: "controller config",
            reason: e.to_string(),
        })
    }
}

/// Counters of frames the node did not act on.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FrameCounters {
    /// Frames received.
    pub received: u64,
    /// Frames consumed by the estimator.
    pub consumed: u64,
    /// Frames ignored (other nodes' traffic).
    pub ignored: u64,
    /// Frames that caused a fault.
    pub faulty: u64,
    /// Bus error reports.
    pub bus_errors: u64,
    /// Frames that did not fit the outbox (never expected).
    pub outbox_overflow: u64,
}

/// The controller's status (sent on the bus as `ControllerStatus` at 20 Hz, with the fault code).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ControllerStatus {
    /// The work-cycle phase.
    pub phase: Phase,
    /// Autodig's stage while it runs.
    pub stage: Option<Stage>,
    /// The index of the current action in the plan.
    pub action_index: usize,
    /// Digs completed.
    pub dig_index: u32,
    /// The safety state.
    pub safety: SafetyState,
}

/// The controller node.
#[derive(Debug, Clone)]
pub struct ControllerNode {
    est: Estimator,
    safety: Safety,
    cycle: WorkCycle,
    track_every_steps: u32,
    steps: u64,
    setpoint_sequence: u8,
    tracks_moving: bool,
    counters: FrameCounters,
    last_motion: Option<ArmMode>,
    last_command: CycleCommand,
    status_alive: u8,
    out: Outbox,
}

impl ControllerNode {
    /// A node for `machine` with Autodig `maps` and `config`.
    ///
    /// # Errors
    /// [`ControllerError`] for an inconsistent machine, invalid Autodig, cleanup or cycle parameters,
    /// or an unreachable start pose.
    pub fn new(
        machine: &MachineConfig,
        maps: AutodigMaps,
        config: ControllerConfig,
    ) -> Result<Self, ControllerError> {
        let kin = Kinematics::new(machine)?;
        let relief = [machine.hydraulics.relief_pressure_pa; 3];
        let mut autodig = config.autodig;
        autodig.relief_pressure_pa = relief;
        autodig.perception.bucket_capacity_m3 = machine.bucket.capacity_m3;
        let mut cleanup = config.cleanup;
        cleanup.relief_pressure_pa = relief;
        // The safety limit is the cylinder's stroke-limited range: Autodig legitimately ends stages
        // at the stroke ends (cylinder limits), which lie just outside the machine file's software
        // limits; a reading beyond the stroke is a resolver or calibration fault.
        let limits = Joint::ALL.map(|j| {
            let (slo, shi) = kin.joint_limits(j);
            let (rlo, rhi) = kin.stroke_limited_range(j);
            (slo.min(rlo), shi.max(rhi))
        });
        let cycle = {
            let mut c = WorkCycle::new(
                config.cycle,
                autodig,
                maps,
                cleanup,
                machine.bucket.width_m,
                &kin,
            )?;
            if config.autostart {
                c.start();
            }
            c
        };
        Ok(Self {
            est: Estimator::new(kin, machine.tracks.gauge_m, config.estimator),
            safety: Safety::new(config.safety, limits),
            cycle,
            track_every_steps: config.track_every_steps.max(1),
            steps: 0,
            setpoint_sequence: 15,
            tracks_moving: false,
            counters: FrameCounters::default(),
            last_motion: None,
            last_command: CycleCommand::Neutral,
            status_alive: 15,
            out: Outbox::new().map_err(|e| ControllerError::Config {
                field: "outbox",
                reason: e.to_string(),
            })?,
        })
    }

    /// The estimate.
    pub fn state(&self) -> &MachineState {
        self.est.state()
    }

    /// The estimator (ages, payload estimate, kinematics).
    pub fn estimator(&self) -> &Estimator {
        &self.est
    }

    /// The safety layer.
    pub fn safety(&self) -> &Safety {
        &self.safety
    }

    /// The work cycle.
    pub fn cycle(&self) -> &WorkCycle {
        &self.cycle
    }

    /// Hook for an external action source (`crate::planned`): see [`WorkCycle::set_external_plan`].
    pub fn set_external_plan(&mut self, on: bool) {
        self.cycle.set_external_plan(on);
    }

    /// Sets Autodig's soil hardness index for the next digs (see [`WorkCycle::set_hardness_index`]).
    pub fn set_hardness_index(&mut self, index: f64) {
        self.cycle.set_hardness_index(index);
    }

    /// Appends an action to the work cycle's plan (see [`WorkCycle::push_action`]).
    ///
    /// # Errors
    /// As [`WorkCycle::push_action`].
    pub fn push_action(&mut self, action: Action) -> Result<(), crate::ControllerError> {
        self.cycle.push_action(action, self.est.kinematics())
    }

    /// The active fault (motion stopped), if any.
    pub fn fault(&self) -> Option<Fault> {
        self.safety.active_fault()
    }

    /// The most recent fault, kept after it cleared.
    pub fn last_fault(&self) -> Option<Fault> {
        self.safety.last_fault()
    }

    /// Autodig's current stage.
    pub fn stage(&self) -> Option<Stage> {
        self.cycle.autodig_stage()
    }

    /// Per-dig statistics so far.
    pub fn statistics(&self) -> &[DigStats] {
        self.cycle.stats()
    }

    /// The current action of the plan.
    pub fn action(&self) -> Option<&Action> {
        self.cycle.action()
    }

    /// Phase, stage, action and dig index, and the safety state.
    pub fn status(&self) -> ControllerStatus {
        ControllerStatus {
            phase: self.cycle.phase(),
            stage: self.cycle.autodig_stage(),
            action_index: self.cycle.action_index(),
            dig_index: self.cycle.digs_done(),
            safety: self.safety.state(),
        }
    }

    /// Frame counters.
    pub fn counters(&self) -> FrameCounters {
        self.counters
    }

    /// The command of the last step (for logs and plots).
    pub fn last_command(&self) -> CycleCommand {
        self.last_command
    }

    /// Whether the plan is complete (the node then stays disarmed).
    pub fn finished(&self) -> bool {
        self.cycle.phase() == Phase::Finished
    }

    /// Starts the work cycle (when not autostarted).
    pub fn start(&mut self) {
        self.cycle.start();
    }

    /// Requests an emergency stop (latched until [`Self::reset`]).
    pub fn request_estop(&mut self, now_s: f64) {
        self.safety.request_estop(now_s);
        self.cycle.on_fault(false);
    }

    /// The operator's acknowledgement of an e-stop or a latched fault.
    pub fn reset(&mut self) {
        self.safety.reset();
    }

    /// True once after the work cycle asked for a range scan; answer with [`Self::provide_terrain`].
    pub fn take_scan_request(&mut self) -> bool {
        self.cycle.take_scan_request()
    }

    /// Hands over a terrain map built from a range scan (see [`crate::cycle::ScanGrid::terrain`]).
    pub fn provide_terrain(&mut self, terrain: TerrainGrid) {
        self.cycle.provide_terrain(terrain);
    }

    /// Reports a bus condition the transport delivered outside the frame stream (SocketCAN error
    /// frames surface as `transport::Error::Fault`).
    pub fn on_bus_fault(&mut self, now_s: f64, fault: BusFault) {
        self.counters.bus_errors += 1;
        if bus_fault_stops_motion(fault) {
            self.raise(now_s, Fault::Bus(fault));
        } else {
            tracing::info!(?fault, "CAN bus condition");
        }
    }

    fn raise(&mut self, now_s: f64, fault: Fault) {
        let was_moving = self.safety.motion().is_some();
        self.safety.report(now_s, fault);
        if was_moving || matches!(fault, Fault::Control(_)) {
            self.cycle.on_fault(matches!(fault, Fault::Control(_)));
        }
    }

    fn on_frame(&mut self, tf: &TimestampedFrame, now_s: f64) {
        self.counters.received += 1;
        let t = tf.time_s();
        let time_s = if t.is_finite() { t } else { now_s };
        let frame = &tf.frame;
        if let Some(bus) = BusFault::from_error_frame(frame) {
            self.on_bus_fault(time_s, bus);
            return;
        }
        let raw_id = frame.id().raw();
        let source = match frame.id() {
            CanId::Extended(id) => J1939Id::from_raw(id).ok().map(|i| i.source_address()),
            CanId::Standard(_) => None,
        };
        match Message::decode(frame) {
            Ok(decoded) => {
                let sa = decoded.id.source_address();
                if sa == GATEWAY_ADDRESS && self.est.on_message(&decoded.message, time_s) {
                    self.counters.consumed += 1;
                } else {
                    // Our address used by someone else, a gateway frame the gateway does not send, or
                    // a protocol message from a node that is not the gateway.
                    self.counters.faulty += 1;
                    self.raise(
                        time_s,
                        Fault::UnexpectedFrame {
                            id: raw_id,
                            source_address: sa,
                        },
                    );
                }
            }
            Err(DecodeError::UnknownPgn { .. }) => {
                if matches!(source, Some(GATEWAY_ADDRESS | CONTROLLER_ADDRESS)) {
                    self.counters.faulty += 1;
                    self.raise(
                        time_s,
                        Fault::UnexpectedFrame {
                            id: raw_id,
                            source_address: source.unwrap_or(0),
                        },
                    );
                } else {
                    self.counters.ignored += 1;
                }
            }
            Err(DecodeError::StandardId(_) | DecodeError::RemoteFrame | DecodeError::FdFrame) => {
                self.counters.ignored += 1;
            }
            Err(error) => {
                self.counters.faulty += 1;
                self.raise(time_s, Fault::Decode { id: raw_id, error });
            }
        }
    }

    fn push(&mut self, frame: CanFrame) {
        if !self.out.push(frame) {
            self.counters.outbox_overflow += 1;
        }
    }

    fn push_message(&mut self, message: Message) {
        match message.encode() {
            Ok(f) => self.push(f),
            Err(e) => tracing::error!(error = %e, ?message, "cannot encode"),
        }
    }

    fn push_valve(&mut self, valve: Valve, command: f64) {
        let u = if command.is_finite() {
            command.clamp(-1.0, 1.0)
        } else {
            0.0
        };
        let cmd =
            AuxValveCommand::from_fraction(valve, u).unwrap_or(AuxValveCommand::neutral(valve));
        self.push_message(Message::AuxValveCommand(cmd));
    }

    fn push_neutral(&mut self) {
        for valve in Valve::ALL {
            self.push_message(Message::AuxValveCommand(AuxValveCommand::neutral(valve)));
        }
        self.tracks_moving = false;
    }

    fn push_setpoint(&mut self, q: [f64; 4]) -> bool {
        let next = (self.setpoint_sequence + 1) % 16;
        let sp = PositionSetpoint {
            boom_rad: q[0],
            stick_rad: q[1],
            bucket_rad: q[2],
            swing_rad: q[3],
            sequence: next,
        };
        match Message::PositionSetpoint(sp).encode() {
            Ok(f) => {
                self.setpoint_sequence = next;
                self.push(f);
                true
            }
            Err(_) => false,
        }
    }

    fn hold_setpoint(&self) -> [f64; 4] {
        let s = self.est.state();
        [
            s.joints.boom_rad,
            s.joints.stick_rad,
            s.joints.bucket_rad,
            s.swing_rad,
        ]
    }

    /// One control step at `now_s` (the bus clock, s) with the frames received since the last step.
    /// Returns the frames to send, in order; the heartbeat is last. In listen-only mode it is always
    /// empty.
    pub fn step(&mut self, now_s: f64, received: &[TimestampedFrame]) -> Outbox {
        self.out.clear();
        for tf in received {
            self.on_frame(tf, now_s);
        }
        self.est.update();
        self.safety.observe(now_s, &self.est);
        if self.last_motion.is_some() && self.safety.motion().is_none() {
            // Motion stopped by the safety layer this step (stale data, gateway fault, ...).
            self.cycle.on_fault(false);
        }
        let armed = self.safety.motion();
        let output = match self.cycle.step(now_s, &self.est, armed) {
            Ok(o) => o,
            Err(e) => {
                self.raise(now_s, Fault::Control(e));
                crate::cycle::CycleOutput {
                    want: None,
                    command: CycleCommand::Neutral,
                }
            }
        };
        let tick = self.safety.tick(now_s, output.want);
        self.last_motion = tick.motion;
        self.last_command = if tick.motion.is_some() {
            output.command
        } else {
            CycleCommand::Neutral
        };
        self.steps += 1;
        let track_slot = self.steps.is_multiple_of(u64::from(self.track_every_steps));
        match (tick.motion, output.command) {
            (Some(ArmMode::Valve), CycleCommand::Valves(v)) => {
                for (valve, u) in Valve::ALL.into_iter().zip(v).take(4) {
                    self.push_valve(valve, u);
                }
                let tracks_move = v[4] != 0.0 || v[5] != 0.0;
                if track_slot || tracks_move != self.tracks_moving {
                    self.push_valve(Valve::LeftTrack, v[4]);
                    self.push_valve(Valve::RightTrack, v[5]);
                    self.tracks_moving = tracks_move;
                }
            }
            (Some(ArmMode::Valve), _) => {
                for valve in Valve::ALL.into_iter().take(4) {
                    self.push_valve(valve, 0.0);
                }
                if track_slot || self.tracks_moving {
                    self.push_valve(Valve::LeftTrack, 0.0);
                    self.push_valve(Valve::RightTrack, 0.0);
                    self.tracks_moving = false;
                }
            }
            (Some(ArmMode::Position), CycleCommand::Position(q)) => {
                if !self.push_setpoint(q) {
                    // Out of the setpoint range: the gateway would fault anyway; stop cleanly.
                    self.raise(
                        now_s,
                        Fault::Control(crate::safety::ControlFault::Kinematics(
                            "setpoint out of the encodable range",
                        )),
                    );
                    self.push_neutral();
                }
            }
            (Some(ArmMode::Position), _) => {
                let hold = self.hold_setpoint();
                self.push_setpoint(hold);
            }
            (None, _) => {}
        }
        if tick.hold_position {
            let hold = self.hold_setpoint();
            self.push_setpoint(hold);
        }
        if tick.send_neutral {
            self.push_neutral();
        }
        if track_slot && self.safety.state() != SafetyState::ListenOnly {
            let status = self.status_message();
            self.push_message(Message::ControllerStatus(status));
        }
        if let Some(hb) = tick.heartbeat {
            self.push_message(Message::ControllerHeartbeat(hb));
        }
        self.out
    }

    /// The `ControllerStatus` message (20 Hz): activity, Autodig stage, dig number, hardness index,
    /// swept volume and fault code.
    fn status_message(&mut self) -> StatusMessage {
        self.status_alive = (self.status_alive + 1) % 16;
        let activity = if self.safety.active_fault().is_some() {
            Activity::Faulted
        } else {
            match self.cycle.phase() {
                Phase::Idle | Phase::Finished | Phase::Weigh => Activity::Idle,
                Phase::Scan => Activity::Scan,
                Phase::MoveToDig => Activity::SwingToDig,
                Phase::Autodig => Activity::Dig,
                Phase::Cleanup => Activity::Cleanup,
                Phase::SwingToDump => Activity::SwingToDump,
                Phase::Dump => Activity::Dump,
                Phase::Return => Activity::Return,
                Phase::TrackBack => Activity::Track,
            }
        };
        let stage = match self.cycle.autodig_stage() {
            None => AutodigStageCode::None,
            Some(Stage::BoomDown) => AutodigStageCode::BoomDown,
            Some(Stage::PreDig) => AutodigStageCode::PreDig,
            Some(Stage::Dig) => AutodigStageCode::Dig,
            Some(Stage::Capture) => AutodigStageCode::Capture,
            Some(Stage::Done) => AutodigStageCode::Done,
        };
        let dig = self.cycle.digs_done() + u32::from(self.cycle.in_dig());
        let clamp = |v: f64, hi: f64| if v.is_finite() { v.clamp(0.0, hi) } else { 0.0 };
        StatusMessage {
            activity,
            stage,
            dig_index: u16::try_from(dig.min(64_255)).unwrap_or(0),
            hardness_index: clamp(self.cycle.hardness_index(), 12.5),
            swept_volume_m3: clamp(self.cycle.swept_volume_m3().unwrap_or(0.0), 6.4),
            fault_reason: self.safety.active_fault().map_or(0, |f| f.code()),
            alive_counter: self.status_alive,
        }
    }

    /// The frames to send when the program stops (Ctrl-C, error, end of the plan): neutral commands for
    /// all six valves, then a `Disarm` heartbeat. After this the node stays shut down. Empty in
    /// listen-only mode.
    pub fn shutdown(&mut self, now_s: f64) -> Outbox {
        self.out.clear();
        self.safety.shutdown(now_s);
        let tick = self.safety.tick(now_s, None);
        if tick.send_neutral {
            self.push_neutral();
        }
        if let Some(hb) = tick.heartbeat {
            self.push_message(Message::ControllerHeartbeat(hb));
        }
        self.out
    }
}
