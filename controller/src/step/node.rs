//! [`ControllerNode`]: the controller's synchronous, clock-agnostic control step.
//!
//! `step(now_s, received) -> frames to send` combines the [`Estimator`], the [`Safety`] layer and the
//! [`WorkCycle`] (with Autodig and cleanup inside). It does no I/O and reads no clock, so the real-time
//! loop on SocketCAN ([`crate::io::run`]), the in-process demo and the tests drive the very same code. The
//! output is a fixed-capacity [`Outbox`]; the step allocates nothing except when a dig starts (the
//! pre-dig terrain section) and never panics.
//!
//! Before anything else the node claims the controller's address (`0x27`) with its NAME (J1939-81,
//! [`firmware_bridge::address_claim`]; `[j1939]` of [`ControllerConfig`]): the first step sends
//! Address Claimed, and until the claim has stood for 250 ms (plus one control period: the step's
//! frames leave after its computation) a step sends only claim frames (received
//! frames still feed the estimator; the safety layer and the work cycle wait). A competing claim for
//! `0x27` with a higher NAME is answered with our claim again; one with a lower NAME wins: the node
//! sends Cannot Claim, raises [`Fault::AddressLost`] (latched) and sends nothing else, not even the
//! shutdown frames, since it may no longer use the address ([`ControllerNode::address_lost`]). A
//! Request for Address Claimed is answered with the claim (with Cannot Claim after a loss). In
//! listen-only mode the node claims nothing.
//!
//! A claim for `0x27` or the gateway's `0x80` from a NAME other than the configured ones is an
//! intrusion: logged, counted ([`FrameCounters::intrusions`]) and raised as
//! [`Fault::AddressIntrusion`], latched when the intruder's NAME is lower than the owner's (the owner
//! lost the address; for `0x80` the gateway falls silent). The operator's reset
//! ([`ControllerNode::reset`]) recovers a lost address: the next step sends a Request for Address
//! Claimed to global, then the controller's claim, and waits 250 ms again. A real owner of `0x27`
//! answers and wins again (the fault stays); a transient claim does not, and the claim stands. The
//! gateway answers the same request by claiming `0x80` again, and is armed through the usual
//! handshake once its status is back.
//!
//! Per step, in order:
//!
//! 1. Received frames: address claims and requests go to the claim procedure (claims for `0x27` and
//!    `0x80` are checked against the configured NAMEs); error frames are bus faults; frames from the gateway (`0x80`) feed the
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
//!
//! Its configuration, [`ControllerConfig`], and the checks of every parameter live in [`crate::config`].

use firmware_bridge::address_claim::{
    AddressClaimer, ClaimEvent, NULL_ADDRESS, Name, request_address_claimed,
};
use firmware_bridge::dm1::{CONTROLLER_DTCS, Dm1Reporter};
use firmware_bridge::id::GLOBAL_ADDRESS;
use firmware_bridge::messages::{
    Activity, AutodigStageCode, AuxValveCommand, ControllerStatus as StatusMessage, Message,
    PositionSetpoint, Valve,
};
use firmware_bridge::profile::GatewayTiming;
use firmware_bridge::secoc::{SealError, Sealer, SessionKey};
use firmware_bridge::time::Instant;
use firmware_bridge::transport::BusFault;
use firmware_bridge::{
    CONTROLLER_ADDRESS, CanFrame, CanId, DecodeError, GATEWAY_ADDRESS, J1939Id, TimestampedFrame,
};
use planner::autodig::{AutodigMaps, Stage};
use planner::kinematics::{Joint, Kinematics};
use planner::machine::MachineConfig;
use planner::terrain::TerrainGrid;

use crate::ControllerError;
use crate::config::ControllerConfig;
use crate::step::cycle::{Action, CycleCommand, DigStats, Phase, WorkCycle};
use crate::step::estimate::{Estimator, MachineState};
use crate::step::log_throttle::LogThrottle;
use crate::step::plausibility::{AnglePlausibility, FrozenAngles, Implausible};
use crate::step::safety::{ArmMode, Fault, Safety, SafetyState, bus_fault_stops_motion};

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
    /// Secured frames not sent because no gateway session was known yet.
    pub held_no_session: u64,
    /// Address claims for the controller's or the gateway's address from an unexpected NAME (also
    /// counted in `faulty`).
    pub intrusions: u64,
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
    tracks_moving: bool,
    /// Seals the heartbeat, valve commands and setpoints for the gateway's session.
    sealer: Sealer,
    counters: FrameCounters,
    last_motion: Option<ArmMode>,
    last_command: CycleCommand,
    status_alive: u8,
    out: Outbox,
    /// The J1939-81 claim of the controller's address.
    claim: AddressClaimer,
    /// Whether the lost claim was reported to the safety layer.
    address_lost_raised: bool,
    /// The NAME the gateway at `0x80` claims with.
    gateway_name: Name,
    /// A claim with a NAME lower than the gateway's took `0x80`, and the gateway's claim has not been
    /// seen since.
    gateway_address_lost: bool,
    /// The operator's reset asked for the addresses to be claimed again (at the next step).
    reclaim_requested: bool,
    /// Rate limit of the intrusion log (every intrusion is counted and raised).
    intrusion_log: LogThrottle,
    /// The active fault as J1939-73 DM1 ([`CONTROLLER_DTCS`], index = fault code - 1).
    dm1: Dm1Reporter<{ CONTROLLER_DTCS.len() }>,
    /// The last accepted joint angles, against which a new frame's are judged.
    angles: AnglePlausibility,
    /// Since when each joint's angle has stayed the same with its valve open.
    frozen: FrozenAngles,
}

impl ControllerNode {
    /// A node for `machine` with Autodig `maps` and `config`.
    ///
    /// # Errors
    /// [`ControllerError`] for a configuration value that [`ControllerConfig::validate`] refuses, an
    /// inconsistent machine, or an unreachable start pose.
    pub fn new(
        machine: &MachineConfig,
        maps: AutodigMaps,
        config: ControllerConfig,
    ) -> Result<Self, ControllerError> {
        config.validate()?;
        let (name, gateway_name) = config.j1939.names()?;
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
            est: Estimator::new(kin, machine.tracks.gauge_m, config.estimator)?,
            safety: Safety::new(config.safety, limits)?,
            cycle,
            track_every_steps: config.track_every_steps,
            steps: 0,
            tracks_moving: false,
            sealer: Sealer::new(&SessionKey::PUBLIC),
            counters: FrameCounters::default(),
            last_motion: None,
            last_command: CycleCommand::Neutral,
            status_alive: 15,
            dm1: Dm1Reporter::new(&CONTROLLER_DTCS),
            angles: AnglePlausibility::default(),
            frozen: FrozenAngles::default(),
            // The step's frames leave after its computation (and its logs): a period of margin
            // keeps the claim's 250 ms on the wire when a step is late.
            claim: AddressClaimer::controller_named(name).with_hold_margin(
                i64::try_from(firmware_bridge::dbc::CONTROL_PERIOD.as_nanos()).unwrap_or(0),
            ),
            address_lost_raised: false,
            gateway_name,
            gateway_address_lost: false,
            reclaim_requested: false,
            intrusion_log: LogThrottle::default(),
            out: Outbox::new().map_err(|e| ControllerError::Config {
                field: "outbox",
                reason: e.to_string(),
            })?,
        })
    }

    /// Provisions the machine's authentication key (the gateway holds the same one); without it the
    /// frames carry freshness and the session binding, keyed with [`SessionKey::PUBLIC`]. Call before
    /// the first step: the session is learnt again from the gateway.
    pub fn set_key(&mut self, key: &SessionKey) {
        self.sealer = Sealer::new(key);
    }

    /// The address claim (state, NAME, address).
    pub fn address_claim(&self) -> &AddressClaimer {
        &self.claim
    }

    /// The fault while another node holds the controller's address: the node sends nothing until
    /// the operator's reset claims it again ([`Self::reset`]).
    pub fn address_lost(&self) -> Option<Fault> {
        self.claim.lost().map(|by| Fault::AddressLost {
            address: self.claim.address(),
            winner_name: by.raw(),
        })
    }

    /// The gateway session the node seals its frames for, once the gateway has announced one.
    pub fn session(&self) -> Option<u32> {
        self.sealer.session()
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

    /// Hook for an external action source (`crate::session::planned`): see [`WorkCycle::set_external_plan`].
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

    /// Puts a saved session's work cycle and dead-reckoned pose into this fresh node (see
    /// [`crate::session::session_state`]); the arming handshake runs as for a new session.
    ///
    /// # Errors
    /// As [`crate::step::cycle::WorkCycle::restore`].
    pub fn restore(
        &mut self,
        cycle: &crate::step::cycle::CycleSnapshot,
        pose: planner::kinematics::MachinePose,
        odometry_m: Option<[f64; 2]>,
    ) -> Result<(), crate::ControllerError> {
        self.cycle.restore(cycle, self.est.kinematics())?;
        self.est.continue_from(pose, odometry_m);
        Ok(())
    }

    /// The operator's pause or resume (see [`WorkCycle::set_paused`]).
    pub fn set_paused(&mut self, paused: bool) {
        self.cycle.set_paused(paused);
    }

    /// The operator's resume: the cycle goes on ([`WorkCycle::set_paused`]) and a fault stop that
    /// waits for the operator is acknowledged ([`Safety::acknowledge`]; an e-stop or a latching fault
    /// still needs [`Self::reset`]).
    pub fn resume(&mut self) {
        self.cycle.set_paused(false);
        self.safety.acknowledge();
    }

    /// The operator's stop after the current action (see [`WorkCycle::request_stop`]).
    pub fn request_stop(&mut self) {
        self.cycle.request_stop();
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

    /// The plausibility checks of a `JointAngles` frame from the gateway (`step::plausibility`): no
    /// joint farther from the last accepted frame than it can turn, none frozen while the valve
    /// commands in force hold its valve open.
    fn check_angles(&mut self, angles: [f64; 4], time_s: f64) -> Result<(), Implausible> {
        let config = self.safety.config();
        self.angles.check(
            angles,
            time_s,
            &config.max_joint_speed_rad_per_s,
            GatewayTiming::secs(config.gateway.sensor_period_ms),
        )?;
        let valves = match (self.last_motion, self.last_command) {
            (Some(ArmMode::Valve), CycleCommand::Valves(v)) => Some([v[0], v[1], v[2], v[3]]),
            _ => None,
        };
        self.frozen
            .check(angles, time_s, valves, config.frozen_sensor_s)
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

    /// The operator's acknowledgement of an e-stop or a latched fault. When the controller's address
    /// or the gateway's was lost, the next step also starts the recovery (module docs): a Request for
    /// Address Claimed to global, then the controller's claim.
    pub fn reset(&mut self) {
        self.safety.reset();
        if self.safety.state() != SafetyState::ListenOnly
            && (self.claim.lost().is_some() || self.gateway_address_lost)
        {
            self.reclaim_requested = true;
        }
    }

    /// Whether a claim for `0x80` with a NAME lower than the gateway's was seen and the gateway has
    /// not claimed its address since.
    pub fn gateway_address_lost(&self) -> bool {
        self.gateway_address_lost
    }

    /// Checks a claim from `source` against the configured NAMEs: another NAME for `0x27` or `0x80`
    /// is an intrusion (a lower one for `0x27` is [`Fault::AddressLost`], raised by the claim
    /// procedure). Returns whether the frame was an intrusion.
    fn check_claim(&mut self, source: u8, name: Name, time_s: f64) -> bool {
        let owner = match source {
            CONTROLLER_ADDRESS => self.claim.name(),
            GATEWAY_ADDRESS => self.gateway_name,
            _ => return false,
        };
        if name == owner {
            if source == GATEWAY_ADDRESS && self.gateway_address_lost {
                tracing::info!("the gateway claimed its address again");
                self.gateway_address_lost = false;
            }
            return false;
        }
        let owner_lost = name < owner;
        self.counters.intrusions += 1;
        self.counters.faulty += 1;
        if let Some(held_back) = self.intrusion_log.allow(time_s) {
            tracing::error!(
                address = format_args!("{source:#04X}"),
                name = format_args!("{:#018X}", name.raw()),
                expected = format_args!("{:#018X}", owner.raw()),
                owner_lost,
                intrusions = self.counters.intrusions,
                held_back,
                "address claim from an unexpected NAME: intrusion"
            );
        }
        if source == CONTROLLER_ADDRESS && owner_lost {
            // The claim procedure loses the address and raises `AddressLost`.
            return true;
        }
        if source == GATEWAY_ADDRESS && owner_lost {
            self.gateway_address_lost = true;
        }
        self.raise(
            time_s,
            Fault::AddressIntrusion {
                address: source,
                name: name.raw(),
                owner_lost,
            },
        );
        true
    }

    /// True once after the work cycle asked for a range scan; answer with [`Self::provide_terrain`].
    pub fn take_scan_request(&mut self) -> bool {
        self.cycle.take_scan_request()
    }

    /// Hands over a terrain map built from a range scan (see [`crate::step::cycle::ScanGrid::terrain`]).
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
                let at = Instant::from_secs_f64(time_s).unwrap_or_default();
                let intrusion = match decoded.message {
                    Message::AddressClaimed(claimed) => self.check_claim(sa, claimed.name, time_s),
                    _ => false,
                };
                if let Some(event) = self.claim.on_message(decoded.id, &decoded.message, at) {
                    // An intrusion was counted as faulty by `check_claim`.
                    let (consumed, ignored) = if intrusion {
                        (0, 0)
                    } else if matches!(event, ClaimEvent::Noted | ClaimEvent::Reclaimed { .. }) {
                        (0, 1)
                    } else {
                        (1, 0)
                    };
                    self.counters.consumed += consumed;
                    self.counters.ignored += ignored;
                    match event {
                        ClaimEvent::Lost { competitor } => tracing::error!(
                            winner_name = format_args!("{:#018X}", competitor.raw()),
                            "address claim lost: Cannot Claim, the controller is silent until \
                             the operator's reset"
                        ),
                        ClaimEvent::Defended { competitor } => tracing::warn!(
                            competitor_name = format_args!("{:#018X}", competitor.raw()),
                            "a node with a higher NAME claimed our address: claimed it again"
                        ),
                        ClaimEvent::Noted | ClaimEvent::Reclaimed { .. } | ClaimEvent::Answered => {
                        }
                    }
                } else if matches!(decoded.message, Message::Dm1(_)) && sa != CONTROLLER_ADDRESS {
                    // Trouble codes for service tools (the gateway's faults reach the safety layer
                    // through its status); any J1939 node may broadcast them.
                    self.counters.ignored += 1;
                } else if let (GATEWAY_ADDRESS, Message::GatewaySession(session)) =
                    (sa, decoded.message)
                {
                    if self.sealer.set_session(session.session_id) {
                        tracing::info!(session = session.session_id, "gateway session");
                    }
                    self.counters.consumed += 1;
                } else if let (GATEWAY_ADDRESS, Message::JointAngles(a)) = (sa, &decoded.message)
                    && let Err(e) = self
                        .check_angles([a.boom_rad, a.stick_rad, a.bucket_rad, a.swing_rad], time_s)
                {
                    // Not used: the estimator keeps the last plausible angles.
                    self.counters.faulty += 1;
                    self.raise(time_s, Fault::ImplausibleSensor(e));
                } else if sa == GATEWAY_ADDRESS && self.est.on_message(&decoded.message, time_s) {
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
        match self.sealer.seal(&message) {
            Ok(f) => self.push(f),
            // Before the gateway's first `GatewaySession` nothing secured can be accepted; the safety
            // layer does not arm before a gateway status, which comes with the session.
            Err(SealError::NoSession) => self.counters.held_no_session += 1,
            Err(SealError::Encode(e)) => tracing::error!(error = %e, ?message, "cannot encode"),
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
        let sp = PositionSetpoint {
            boom_rad: q[0],
            stick_rad: q[1],
            bucket_rad: q[2],
            swing_rad: q[3],
        };
        match self.sealer.seal(&Message::PositionSetpoint(sp)) {
            Ok(f) => {
                self.push(f);
                true
            }
            Err(SealError::NoSession) => {
                self.counters.held_no_session += 1;
                true
            }
            Err(SealError::Encode(_)) => false,
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
        if !self.claim_allows_transmit(now_s) {
            return self.out;
        }
        if self.last_motion.is_some() && self.safety.motion().is_none() {
            // Motion stopped by the safety layer this step (stale data, gateway fault, ...).
            self.cycle.on_fault(false);
        }
        let armed = self.safety.motion();
        let output = match self.cycle.step(now_s, &self.est, armed) {
            Ok(o) => o,
            Err(e) => {
                self.raise(now_s, Fault::Control(e));
                crate::step::cycle::CycleOutput {
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
                        Fault::Control(crate::step::safety::ControlFault::Kinematics(
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
        self.dm1.observe(dm1_active(self.safety.active_fault()));
        if self.safety.state() != SafetyState::ListenOnly
            && let Some(now) = Instant::from_secs_f64(now_s)
            && let Some(dm1) = self.dm1.poll(now)
        {
            self.push_message(Message::Dm1(dm1));
        }
        if let Some(hb) = tick.heartbeat {
            self.push_message(Message::ControllerHeartbeat(hb));
        }
        self.out
    }

    /// Runs the address claim for this step: queues its frame, raises the lost claim once, and says
    /// whether application frames may follow. Listen-only nodes claim nothing and send nothing.
    fn claim_allows_transmit(&mut self, now_s: f64) -> bool {
        if self.safety.state() == SafetyState::ListenOnly {
            return true;
        }
        let now = Instant::from_secs_f64(now_s);
        if self.reclaim_requested
            && let Some(now) = now
        {
            self.reclaim_requested = false;
            // Without an address of its own the request comes from the null address (J1939-81).
            let source = if self.claim.lost().is_some() {
                NULL_ADDRESS
            } else {
                self.claim.address()
            };
            if let Ok(request) = request_address_claimed(GLOBAL_ADDRESS, source) {
                self.push(request);
            }
            // A global request is answered by its sender too: our claim follows it.
            if let Some(by) = self.claim.reclaim(now) {
                tracing::warn!(
                    lost_to = format_args!("{:#018X}", by.raw()),
                    "operator reset: Request for Address Claimed sent, claiming 0x27 again"
                );
                self.address_lost_raised = false;
            } else {
                tracing::warn!(
                    "operator reset: Request for Address Claimed sent for the gateway's address"
                );
            }
        }
        if let Some(now) = now {
            self.claim.update(now);
        }
        if let Ok(Some(frame)) = self.claim.take_frame() {
            self.push(frame);
        }
        if let Some(fault) = self.address_lost() {
            if !self.address_lost_raised {
                self.address_lost_raised = true;
                self.raise(now_s, fault);
            }
            return false;
        }
        self.claim.may_transmit()
    }

    /// The `ControllerStatus` message (20 Hz): activity, Autodig stage, dig number, hardness index,
    /// swept volume and fault code.
    fn status_message(&mut self) -> StatusMessage {
        self.status_alive = (self.status_alive + 1) % 16;
        self.bus_status()
    }

    /// What the controller reports on the bus as `ControllerStatus` now (the last alive counter
    /// sent), for a view of the session that shows what a trace would.
    pub fn bus_status(&self) -> StatusMessage {
        let activity = if self.safety.active_fault().is_some() {
            Activity::Faulted
        } else if self.cycle.paused() && self.cycle.phase() == Phase::Idle {
            Activity::Paused
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
        if self.safety.state() != SafetyState::ListenOnly && !self.claim.may_transmit() {
            // Before the claim stands (or after it was lost) the address is not ours to use; nothing
            // was armed.
            self.safety.shutdown(now_s);
            if let Ok(Some(frame)) = self.claim.take_frame() {
                self.push(frame);
            }
            return self.out;
        }
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

/// DM1's active set for the controller's `fault` (bit `code - 1`, [`CONTROLLER_DTCS`]; none when
/// healthy).
fn dm1_active(fault: Option<Fault>) -> u32 {
    match fault.map(|f| f.code()) {
        Some(code @ 1..=32) => 1 << (code - 1),
        _ => 0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::check::toml_float;
    use crate::config::{ConfigFileError, MAX_TRACK_EVERY_STEPS};
    use crate::step::cycle::CycleConfig;
    use crate::step::estimate::EstimatorConfig;
    use crate::step::safety::SafetyConfig;
    use crate::step::safety::{GATEWAY_STATUS_PERIOD_S, GATEWAY_WATCHDOG_S, SENSOR_PERIOD_S};
    use std::path::Path;

    /// The four settings of issue #23 that gave a session that silently did nothing, or one that
    /// drove the valves for 60 s with the sensor frames cut.
    const ISSUE_23: [(&str, &str, usize); 4] = [
        (
            "[safety]\nsensor_max_age_s = nan\n",
            "safety.sensor_max_age_s = nan",
            2,
        ),
        (
            "autostart = true\n\n[safety]\nstatus_max_age_s = -5\n",
            "safety.status_max_age_s = -5.0",
            4,
        ),
        (
            "[safety]\nsensor_max_age_s = 1e308\n",
            "safety.sensor_max_age_s = 1e308",
            2,
        ),
        ("track_every_steps = 0\n", "track_every_steps = 0", 1),
    ];

    /// A float field of a config type, by its key in the file.
    type Field<C> = (&'static str, fn(&mut C) -> &mut f64);

    fn load(text: &str) -> Result<ControllerConfig, ConfigFileError> {
        ControllerConfig::from_toml_str_named(text, "plan.toml")
    }

    fn machine() -> MachineConfig {
        MachineConfig::default_machine().expect("default machine")
    }

    #[test]
    fn issue_23_settings_are_refused_naming_file_line_and_field() {
        for (text, field, line) in ISSUE_23 {
            let err = load(text).expect_err(text);
            let msg = err.to_string();
            assert!(
                msg.starts_with(&format!("plan.toml:{line}: {field}: must be")),
                "{msg}"
            );
            assert!(
                matches!(err, ConfigFileError::Invalid { line: Some(l), .. } if l == line),
                "{err:?}"
            );
        }
        let msg = load(ISSUE_23[0].0).unwrap_err().to_string();
        assert_eq!(
            msg,
            "plan.toml:2: safety.sensor_max_age_s = nan: must be finite and in (0.01, 0.1] s \
             (above the 10 ms sensor period, at most the gateway's 100 ms watchdog)"
        );
    }

    #[test]
    fn issue_23_settings_are_refused_in_process_too() {
        for (text, field, _) in ISSUE_23 {
            // Parsed without validation, as code building a config would.
            let config: ControllerConfig = toml::from_str(text).expect("parses");
            let key = field.split_once(" = ").map_or(field, |(k, _)| k);
            let err = config.validate().expect_err(text);
            assert_eq!(err.path(), key);
            let err = ControllerNode::new(&machine(), AutodigMaps::builtin().unwrap(), config)
                .expect_err(text);
            let leaf = key.rsplit('.').next().unwrap_or(key);
            assert!(err.to_string().contains(leaf), "{err}");
        }
    }

    #[test]
    fn defaults_are_valid() {
        ControllerConfig::default().validate().unwrap();
        let node = ControllerNode::new(
            &machine(),
            AutodigMaps::builtin().unwrap(),
            ControllerConfig::default(),
        );
        assert!(node.is_ok());
        assert!(load("").is_ok());
    }

    #[test]
    fn protocol_constants_match_the_gateway_and_the_schedule() {
        let gateway = firmware_bridge::gateway::GatewayConfig::default();
        assert_eq!(gateway.heartbeat_timeout_s, GATEWAY_WATCHDOG_S);
        assert_eq!(gateway.command_timeout_s, GATEWAY_WATCHDOG_S);
        let rate = |name: &str| {
            firmware_bridge::busload::SCHEDULE
                .iter()
                .find(|e| e.message == name)
                .map(|e| e.rate_hz)
        };
        assert_eq!(rate("JointAngles"), Some(1.0 / SENSOR_PERIOD_S));
        assert_eq!(rate("JointRates"), Some(1.0 / SENSOR_PERIOD_S));
        assert_eq!(rate("GatewayStatus"), Some(1.0 / GATEWAY_STATUS_PERIOD_S));
        // The track commands go out every `MAX_TRACK_EVERY_STEPS` steps at most: half the timeout.
        let period = firmware_bridge::dbc::CONTROL_PERIOD.as_secs_f64();
        assert!(
            f64::from(MAX_TRACK_EVERY_STEPS) * period <= gateway.command_timeout_s / 2.0 + 1e-12
        );
    }

    /// Every float of `SafetyConfig` refuses NaN, infinities and negative values.
    #[test]
    fn safety_config_refuses_nan_negative_and_infinite_values() {
        let fields: [Field<SafetyConfig>; 9] = [
            ("sensor_max_age_s", |c| &mut c.sensor_max_age_s),
            ("status_max_age_s", |c| &mut c.status_max_age_s),
            ("arm_timeout_s", |c| &mut c.arm_timeout_s),
            ("clear_hold_s", |c| &mut c.clear_hold_s),
            ("neutral_hold_s", |c| &mut c.neutral_hold_s),
            ("joint_limit_margin_rad", |c| &mut c.joint_limit_margin_rad),
            ("rearm_reset_s", |c| &mut c.rearm_reset_s),
            ("heartbeat_period_s", |c| &mut c.heartbeat_period_s),
            ("frozen_sensor_s", |c| &mut c.frozen_sensor_s),
        ];
        for (key, field) in fields {
            for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, -1.0, 1e308] {
                let mut c = SafetyConfig::default();
                *field(&mut c) = bad;
                let err = c.validate().expect_err(key);
                assert_eq!(err.path(), format!("safety.{key}"), "{bad}");
                assert_eq!(err.value, Some(toml_float(bad)));
                let limits = [(0.0, 1.0); 3];
                assert!(Safety::new(c, limits).is_err(), "{key} = {bad}");
            }
        }
        let c = SafetyConfig {
            max_auto_rearms: u32::MAX,
            ..SafetyConfig::default()
        };
        assert_eq!(c.validate().unwrap_err().path(), "safety.max_auto_rearms");
        // A frozen-signal window shorter than ten sensor periods would take the resolvers' noise
        // for a fault.
        let c = SafetyConfig {
            frozen_sensor_s: 0.05,
            ..SafetyConfig::default()
        };
        assert_eq!(c.validate().unwrap_err().path(), "safety.frozen_sensor_s");
        // The silent fallback for long heartbeat periods is now an error.
        let c = SafetyConfig {
            heartbeat_period_s: 0.1,
            ..SafetyConfig::default()
        };
        assert!(c.validate().is_err());
        // Joint limits handed to the safety layer are checked too.
        let nan_limits = [(0.0, 1.0), (f64::NAN, 1.0), (0.0, 1.0)];
        assert!(Safety::new(SafetyConfig::default(), nan_limits).is_err());
        let inverted = [(0.0, 1.0), (0.0, 1.0), (1.0, 0.0)];
        assert!(Safety::new(SafetyConfig::default(), inverted).is_err());
    }

    #[test]
    fn estimator_config_refuses_nan_negative_and_infinite_values() {
        let fields: [Field<EstimatorConfig>; 5] = [
            ("rate_filter_time_constant_s", |c| {
                &mut c.rate_filter_time_constant_s
            }),
            ("weigh_stroke_end_margin", |c| {
                &mut c.weigh_stroke_end_margin
            }),
            ("initial_pose.x_m", |c| &mut c.initial_pose.x_m),
            ("initial_pose.y_m", |c| &mut c.initial_pose.y_m),
            ("initial_pose.heading_rad", |c| {
                &mut c.initial_pose.heading_rad
            }),
        ];
        let kin = Kinematics::new(&machine()).unwrap();
        for (key, field) in fields {
            let negative = if key == "weigh_stroke_end_margin" {
                -2.0
            } else {
                -1.0e7
            };
            for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, negative] {
                let mut c = EstimatorConfig::default();
                *field(&mut c) = bad;
                let err = c.validate().expect_err(key);
                assert_eq!(err.path(), format!("estimator.{key}"), "{bad}");
                assert!(
                    Estimator::new(kin.clone(), 2.0, c).is_err(),
                    "{key} = {bad}"
                );
            }
        }
        // A negative margin counts every joint (documented); only nonsense is refused.
        let counting_all = EstimatorConfig {
            weigh_stroke_end_margin: -1.0,
            ..EstimatorConfig::default()
        };
        assert!(counting_all.validate().is_ok());
        let msg = load("[estimator]\nrate_filter_time_constant_s = -0.5\n")
            .unwrap_err()
            .to_string();
        assert!(
            msg.starts_with("plan.toml:2: estimator.rate_filter_time_constant_s = -0.5: "),
            "{msg}"
        );
    }

    #[test]
    fn cycle_config_refuses_nan_negative_and_infinite_values() {
        let fields: [Field<CycleConfig>; 16] = [
            ("dump_swing_deg", |c| &mut c.dump_swing_rad),
            ("home_swing_deg", |c| &mut c.home_swing_rad),
            ("carry_boom_deg", |c| &mut c.carry_boom_rad),
            ("carry_tip_z_m", |c| &mut c.carry_tip_z_m),
            ("dump_bucket_deg", |c| &mut c.dump_bucket_rad),
            ("dump_bucket_abs_deg", |c| &mut c.dump_bucket_abs_rad),
            ("dump_hold_s", |c| &mut c.dump_hold_s),
            ("settle_s", |c| &mut c.settle_s),
            ("move_timeout_s", |c| &mut c.move_timeout_s),
            ("scan_timeout_s", |c| &mut c.scan_timeout_s),
            ("section_step_m", |c| &mut c.section_step_m),
            ("weigh_settle_s", |c| &mut c.weigh_settle_s),
            ("weigh_window_s", |c| &mut c.weigh_window_s),
            ("joint.min_command", |c| &mut c.joint.min_command),
            ("swing.kd", |c| &mut c.swing.kd),
            ("scan_grid.cell_m", |c| &mut c.scan_grid.cell_m),
        ];
        for (key, field) in fields {
            for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, -1.0e6] {
                let mut c = CycleConfig::default();
                *field(&mut c) = bad;
                let err = c.validate().expect_err(key);
                assert_eq!(err.path(), format!("cycle.{key}"), "{bad}: {err}");
            }
        }
        // Counts and distances that make no sense.
        let no_digs = CycleConfig {
            max_digs: Some(0),
            ..CycleConfig::default()
        };
        assert_eq!(no_digs.validate().unwrap_err().path(), "cycle.max_digs");
        let far = CycleConfig {
            actions: vec![Action::TrackBack { distance_m: 1e9 }],
            ..CycleConfig::default()
        };
        assert_eq!(
            far.validate().unwrap_err().path(),
            "cycle.actions.0.distance_m"
        );
    }

    #[test]
    fn a_min_command_above_the_max_is_refused_not_a_panic() {
        // `f64::clamp` panics on NaN or crossed bounds; the P-controller used to receive both.
        let c = CycleConfig {
            track: PGainFixture::crossed(),
            ..CycleConfig::default()
        };
        let err = c.validate().unwrap_err();
        assert_eq!(err.path(), "cycle.track.min_command");
    }

    struct PGainFixture;

    impl PGainFixture {
        fn crossed() -> crate::step::cycle::PGain {
            crate::step::cycle::PGain {
                kp: 1.0,
                max_command: 0.3,
                min_command: 0.5,
                kd: 0.0,
                tolerance: 0.05,
            }
        }
    }

    #[test]
    fn errors_point_at_array_entries_and_at_the_table_of_defaults() {
        let text = "\
[cycle]
repeat = true

[[cycle.actions]]
kind = \"dig\"
swing_deg = 0.0
start = { kind = \"tip\", x_m = 7.5, z_m = 2.4, bucket_abs_deg = -55.0 }

[[cycle.actions]]
kind = \"dig\"
swing_deg = 7.0
start = { kind = \"tip\", x_m = inf, z_m = 2.4, bucket_abs_deg = -55.0 }
";
        let msg = load(text).unwrap_err().to_string();
        assert!(
            msg.starts_with("plan.toml:12: cycle.actions.1.start.x_m = inf: "),
            "{msg}"
        );
        // A timeout shorter than the default settle time: the settle time (left at its default) is
        // inconsistent; the error points at the table.
        let msg = load("\n[cycle]\nmove_timeout_s = 0.1\n")
            .unwrap_err()
            .to_string();
        assert!(
            msg.starts_with("plan.toml:2: cycle.settle_s = 0.2: must be finite and in (0, 0.1) s"),
            "{msg}"
        );
    }

    #[test]
    fn type_errors_name_file_line_and_field() {
        let msg = load("autostart = true\ntrack_every_steps = -1\n")
            .unwrap_err()
            .to_string();
        assert!(msg.starts_with("plan.toml:2: track_every_steps: "), "{msg}");
        let msg = load("[safety]\nsensor_max_age = 0.05\n")
            .unwrap_err()
            .to_string();
        assert!(
            msg.starts_with("plan.toml:2: ") && msg.contains("sensor_max_age"),
            "{msg}"
        );
        // Without a file name the line is still given.
        let err =
            ControllerConfig::from_toml_str("[safety]\nsensor_max_age_s = nan\n").unwrap_err();
        assert!(
            err.to_string()
                .contains("line 2: safety.sensor_max_age_s = nan"),
            "{err}"
        );
    }

    #[test]
    fn autodig_and_cleanup_parameters_are_checked_with_their_line() {
        let msg = load("[autodig.contact]\ntimeout_s = nan\n")
            .unwrap_err()
            .to_string();
        assert!(
            msg.starts_with("plan.toml:2: autodig.contact.timeout_s: "),
            "{msg}"
        );
        let msg = load("[cleanup]\nperiod_s = -1.0\n")
            .unwrap_err()
            .to_string();
        assert!(msg.starts_with("plan.toml:2: cleanup.period_s: "), "{msg}");
    }

    #[test]
    fn the_key_file_is_taken_from_the_config_files_folder_and_an_empty_one_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let plan = dir.path().join("plan.toml");
        std::fs::write(&plan, "[security]\nkey_file = \"machine.key\"\n").unwrap();
        let c = ControllerConfig::from_toml_file(&plan).unwrap();
        assert_eq!(c.security.key_file, Some(dir.path().join("machine.key")));
        // Not there yet: the error names it.
        let e = c.security.load_key().unwrap_err().to_string();
        assert!(e.contains("machine.key"), "{e}");
        std::fs::write(
            &plan,
            "track_every_steps = 5\n[security]\nkey_file = \"\"\n",
        )
        .unwrap();
        let e = ControllerConfig::from_toml_file(&plan)
            .unwrap_err()
            .to_string();
        assert!(e.ends_with("plan.toml:3: security.key_file = \"\": must name the key file (or be left out: no key)"), "{e}");
        assert_eq!(ControllerConfig::default().security.load_key(), Ok(None));
    }

    #[test]
    fn a_missing_file_is_named() {
        let err =
            ControllerConfig::from_toml_file(Path::new("/nonexistent/plan.toml")).unwrap_err();
        assert!(
            err.to_string()
                .starts_with("/nonexistent/plan.toml: cannot read"),
            "{err}"
        );
    }

    /// The fault a joint-angle frame that jumps raises is the plausibility check's own finding
    /// (`step::plausibility::Implausible`, one type for both): the same joint and figures, the
    /// same text, fault code 15 and the DM1 code of the `ImplausibleSensor` DTC (SPN 520463, FMI 2).
    #[test]
    fn a_jumping_angle_frame_raises_the_checks_finding_with_its_text_and_dm1_code() {
        use crate::step::plausibility::{AnglePlausibility, Implausible, SensedJoint};
        use firmware_bridge::messages::JointAngles;
        let mut n = ControllerNode::new(
            &machine(),
            AutodigMaps::builtin().unwrap(),
            ControllerConfig::default(),
        )
        .unwrap();
        let angles = |boom_rad: f64| [boom_rad, -1.6, -0.9, 0.0];
        let frame = |time_s: f64, q: [f64; 4]| TimestampedFrame {
            timestamp_ns: (time_s * 1e9).round() as u64,
            frame: Message::JointAngles(JointAngles {
                boom_rad: q[0],
                stick_rad: q[1],
                bucket_rad: q[2],
                swing_rad: q[3],
            })
            .encode_from(GATEWAY_ADDRESS)
            .unwrap(),
        };
        // The boom 0.5 rad away one sensor period later: at most 2 rad/s x 10 ms + 3 mrad is possible.
        let _ = n.step(0.0, &[frame(0.0, angles(0.5))]);
        assert_eq!(n.fault(), None);
        let _ = n.step(0.01, &[frame(0.01, angles(1.0))]);

        let config = ControllerConfig::default();
        let mut check = AnglePlausibility::default();
        let speeds = config.safety.max_joint_speed_rad_per_s;
        let period_s = GatewayTiming::secs(config.safety.gateway.sensor_period_ms);
        check.check(angles(0.5), 0.0, &speeds, period_s).unwrap();
        let finding = check
            .check(angles(1.0), 0.01, &speeds, period_s)
            .unwrap_err();
        assert_eq!(finding.joint(), SensedJoint::Boom);
        let fault = n.fault().expect("the jump raised no fault");
        assert_eq!(fault, Fault::ImplausibleSensor(finding));
        assert_eq!(fault, Fault::from(finding));
        let Fault::ImplausibleSensor(Implausible::Jump {
            jump_rad,
            allowed_rad,
            ..
        }) = fault
        else {
            unreachable!("compared above")
        };
        assert!((jump_rad - 0.5).abs() < 1e-3, "{jump_rad}");
        assert!((allowed_rad - 0.023).abs() < 1e-9, "{allowed_rad}");
        assert_eq!(
            fault.to_string(),
            "implausible joint angles: the boom moved 0.5000 rad between two frames, at most \
             0.0230 rad is possible (a second sender of JointAngles, or a resolver fault)"
        );
        assert_eq!(fault.to_string(), finding.to_string());
        assert_eq!(fault.code(), 15);
        let active = dm1_active(Some(fault));
        let dtc = CONTROLLER_DTCS[active.trailing_zeros() as usize];
        assert_eq!(active.count_ones(), 1);
        assert_eq!(
            (dtc.name, dtc.spn, dtc.fmi),
            ("ImplausibleSensor", 520_463, 2)
        );
    }

    mod address_claim {
        use super::*;
        use firmware_bridge::address_claim::{CONTROLLER_NAME, GATEWAY_NAME};
        use firmware_bridge::messages::{AddressClaimed, GatewaySession};
        use firmware_bridge::name_config::NameConfig;

        const CLAIM_ID: u32 = 0x18EE_FF27;
        const CANNOT_CLAIM_ID: u32 = 0x18EE_FFFE;
        const HEARTBEAT_ID: u32 = 0x0CFF_6127;

        fn node() -> ControllerNode {
            ControllerNode::new(
                &machine(),
                AutodigMaps::builtin().unwrap(),
                ControllerConfig::default(),
            )
            .unwrap()
        }

        fn at(time_s: f64, frame: CanFrame) -> TimestampedFrame {
            TimestampedFrame {
                timestamp_ns: (time_s * 1e9).round() as u64,
                frame,
            }
        }

        fn claim(name: Name) -> CanFrame {
            Message::AddressClaimed(AddressClaimed { name })
                .encode_from(CONTROLLER_ADDRESS)
                .unwrap()
        }

        /// Steps `node` every 10 ms over `[from_s, to_s)` with the gateway's session nonce and the
        /// `injected` frames at their times; returns what it sent, with the step times in ms.
        fn run(
            node: &mut ControllerNode,
            from_s: f64,
            to_s: f64,
            injected: &[(f64, CanFrame)],
        ) -> Vec<(i64, u32)> {
            let session = Message::GatewaySession(GatewaySession { session_id: 7 })
                .encode_from(GATEWAY_ADDRESS)
                .unwrap();
            let mut sent = Vec::new();
            let mut k = 0;
            loop {
                let t = from_s + f64::from(k) * 0.01;
                if t >= to_s - 1e-9 {
                    return sent;
                }
                k += 1;
                let mut inbox = vec![at(t, session)];
                inbox.extend(
                    injected
                        .iter()
                        .filter(|(ti, _)| (*ti - t).abs() < 0.005)
                        .map(|(ti, f)| at(*ti, *f)),
                );
                for f in &node.step(t, &inbox) {
                    sent.push(((t * 1e3).round() as i64, f.id().raw()));
                }
            }
        }

        /// When the node sent its Address Claimed, ms.
        fn claim_times(sent: &[(i64, u32)]) -> Vec<i64> {
            sent.iter()
                .filter(|(_, id)| *id == CLAIM_ID)
                .map(|(t, _)| *t)
                .collect()
        }

        fn application(sent: &[(i64, u32)]) -> Vec<(i64, u32)> {
            sent.iter()
                .copied()
                .filter(|(_, id)| *id != CLAIM_ID && *id != CANNOT_CLAIM_ID)
                .collect()
        }

        #[test]
        fn uncontested_claim_first_then_application_frames_after_250_ms() {
            let mut n = node();
            let sent = run(&mut n, 0.0, 1.0, &[]);
            assert_eq!(sent[0], (0, CLAIM_ID));
            assert_eq!(sent.iter().filter(|(_, id)| *id == CLAIM_ID).count(), 1);
            let app = application(&sent);
            let first = app.first().expect("heartbeats after the claim stood");
            assert!(first.0 >= 250, "first application frame at {} ms", first.0);
            assert!(app.iter().any(|(_, id)| *id == HEARTBEAT_ID));
            assert!(n.address_lost().is_none() && n.fault().is_none());
        }

        const DM1_ID: u32 = 0x18FE_CA27;

        #[test]
        fn dm1_goes_out_after_the_claim_every_second_and_on_a_change() {
            let mut n = node();
            let sent = run(&mut n, 0.0, 3.5, &[]);
            let dm1: Vec<i64> = sent
                .iter()
                .filter(|(_, id)| *id == DM1_ID)
                .map(|(t, _)| *t)
                .collect();
            assert!(dm1.first().is_some_and(|t| *t >= 250), "{dm1:?}");
            assert!(dm1.len() >= 4, "{dm1:?}");
            for w in dm1.windows(2) {
                let gap = w[1] - w[0];
                assert!((100..=1000).contains(&gap), "DM1 at {dm1:?}");
            }
        }

        #[test]
        fn another_nodes_dm1_is_ignored_not_a_fault() {
            let mut n = node();
            let dm1 = |source: u8| {
                Message::Dm1(firmware_bridge::dm1::Dm1Reporter::new(&CONTROLLER_DTCS).current())
                    .encode_from(source)
                    .unwrap()
            };
            run(
                &mut n,
                0.0,
                0.3,
                &[(0.1, dm1(0x00)), (0.2, dm1(GATEWAY_ADDRESS))],
            );
            assert_eq!(n.counters().faulty, 0);
            run(&mut n, 0.3, 0.4, &[(0.35, dm1(CONTROLLER_ADDRESS))]);
            assert_eq!(n.counters().faulty, 1, "our own address from someone else");
        }

        #[test]
        fn a_competing_lower_name_wins_the_node_sends_cannot_claim_and_nothing_else() {
            let mut n = node();
            let winner = Name::from_raw(CONTROLLER_NAME.raw() - 1);
            let sent = run(&mut n, 0.0, 2.0, &[(0.1, claim(winner))]);
            assert_eq!(sent, [(0, CLAIM_ID), (100, CANNOT_CLAIM_ID)]);
            let fault = n.address_lost().unwrap();
            assert_eq!(
                fault,
                Fault::AddressLost {
                    address: CONTROLLER_ADDRESS,
                    winner_name: winner.raw()
                }
            );
            assert_eq!(n.fault(), Some(fault));
            assert!(
                n.shutdown(2.0).is_empty(),
                "no shutdown frames without an address"
            );
            assert!(fault.to_string().contains("lost"), "{fault}");
        }

        #[test]
        fn a_competing_higher_name_is_answered_and_the_node_keeps_going() {
            let mut n = node();
            let loser = Name::from_raw(CONTROLLER_NAME.raw() + 1);
            let sent = run(&mut n, 0.0, 1.0, &[(0.5, claim(loser))]);
            let claims = claim_times(&sent);
            assert_eq!(claims, [0, 500]);
            assert!(application(&sent).iter().any(|(t, _)| *t > 500));
            assert!(n.address_lost().is_none());
            // Not the configured NAME: an intrusion, which clears like any fault event.
            assert_eq!(
                n.fault(),
                Some(Fault::AddressIntrusion {
                    address: CONTROLLER_ADDRESS,
                    name: loser.raw(),
                    owner_lost: false
                })
            );
            assert!(!n.safety().needs_reset());
            assert_eq!(n.counters().intrusions, 1);
        }

        #[test]
        fn a_late_claimant_with_a_lower_name_silences_a_running_node() {
            let mut n = node();
            let sent = run(&mut n, 0.0, 3.0, &[(2.0, claim(Name::from_raw(0)))]);
            assert!(application(&sent).iter().any(|(t, _)| *t < 2000));
            let after: Vec<(i64, u32)> = sent.into_iter().filter(|(t, _)| *t >= 2000).collect();
            assert_eq!(after, [(2000, CANNOT_CLAIM_ID)]);
            assert!(matches!(n.fault(), Some(Fault::AddressLost { .. })));
        }

        #[test]
        fn a_request_for_address_claimed_is_answered_with_the_claim() {
            let mut n = node();
            let request = request_address_claimed(0xFF, 0x99).unwrap();
            let sent = run(&mut n, 0.0, 1.0, &[(0.7, request)]);
            let claims = claim_times(&sent);
            assert_eq!(claims, [0, 700]);
            assert!(n.fault().is_none());
        }

        const REQUEST_FROM_NULL_ID: u32 = 0x18EA_FFFE;
        const REQUEST_FROM_US_ID: u32 = 0x18EA_FF27;

        fn claim_from(source: u8, name: Name) -> CanFrame {
            Message::AddressClaimed(AddressClaimed { name })
                .encode_from(source)
                .unwrap()
        }

        /// A node that lost 0x27 to a transient claim (NAME 0) at 100 ms, run to 1 s.
        fn lost_node() -> ControllerNode {
            let mut n = node();
            let sent = run(&mut n, 0.0, 1.0, &[(0.1, claim(Name::from_raw(0)))]);
            assert_eq!(sent, [(0, CLAIM_ID), (100, CANNOT_CLAIM_ID)]);
            assert!(n.safety().needs_reset());
            assert_eq!(n.counters().intrusions, 1);
            n
        }

        #[test]
        fn after_a_transient_claim_the_operators_reset_reclaims_and_the_claim_stands() {
            let mut n = lost_node();
            n.reset();
            let sent = run(&mut n, 1.0, 2.0, &[]);
            // The request from the null address, then our claim, then 250 ms of nothing else.
            assert_eq!(sent[..2], [(1000, REQUEST_FROM_NULL_ID), (1000, CLAIM_ID)]);
            let app = application(&sent[2..]);
            assert!(!app.is_empty(), "the controller stays silent: {sent:?}");
            assert!(
                app[0].0 >= 1250,
                "first application frame at {} ms",
                app[0].0
            );
            assert!(n.address_lost().is_none());
            assert!(!n.safety().needs_reset());
        }

        #[test]
        fn after_the_reset_the_real_owner_answers_and_wins_again() {
            let mut n = lost_node();
            n.reset();
            // The owner answers our request with its claim.
            let owner = claim(Name::from_raw(0));
            let sent = run(&mut n, 1.0, 2.0, &[(1.02, owner)]);
            assert_eq!(
                sent,
                [
                    (1000, REQUEST_FROM_NULL_ID),
                    (1000, CLAIM_ID),
                    (1020, CANNOT_CLAIM_ID)
                ]
            );
            assert!(matches!(n.fault(), Some(Fault::AddressLost { .. })));
            assert!(n.safety().needs_reset(), "the new loss needs a new reset");
        }

        #[test]
        fn an_unexpected_name_for_the_gateways_address_is_an_intrusion() {
            let mut n = node();
            let higher = Name::from_raw(GATEWAY_NAME.raw() + 1);
            run(
                &mut n,
                0.0,
                0.5,
                &[(0.3, claim_from(GATEWAY_ADDRESS, higher))],
            );
            assert_eq!(n.counters().intrusions, 1);
            assert_eq!(
                n.fault(),
                Some(Fault::AddressIntrusion {
                    address: GATEWAY_ADDRESS,
                    name: higher.raw(),
                    owner_lost: false
                })
            );
            assert_eq!(n.fault().map(|f| f.code()), Some(14));
            // The gateway defends 0x80: no reset needed, nothing to claim again.
            assert!(!n.safety().needs_reset() && !n.gateway_address_lost());

            // A lower NAME takes 0x80 from the gateway: latched until the operator's reset.
            let lower = Name::from_raw(GATEWAY_NAME.raw() - 1);
            run(
                &mut n,
                0.5,
                1.0,
                &[(0.6, claim_from(GATEWAY_ADDRESS, lower))],
            );
            assert_eq!(n.counters().intrusions, 2);
            assert!(n.safety().needs_reset() && n.gateway_address_lost());
            n.reset();
            let sent = run(&mut n, 1.0, 1.3, &[]);
            // Our own address stands: the request comes from 0x27, with our claim as its answer.
            assert_eq!(sent[..2], [(1000, REQUEST_FROM_US_ID), (1000, CLAIM_ID)]);
            assert!(n.address_lost().is_none());
            // The gateway's own claim (its configured NAME) ends the loss.
            run(
                &mut n,
                1.3,
                1.4,
                &[(1.31, claim_from(GATEWAY_ADDRESS, GATEWAY_NAME))],
            );
            assert!(!n.gateway_address_lost());
            assert_eq!(n.counters().intrusions, 2);
        }

        #[test]
        fn the_names_come_from_the_config_and_the_expected_gateway_name_is_checked() {
            let name = NameConfig {
                identity_number: 77,
                ..NameConfig::from(CONTROLLER_NAME)
            };
            let gateway = NameConfig {
                identity_number: 78,
                ..NameConfig::from(GATEWAY_NAME)
            };
            let mut config = ControllerConfig::default();
            config.j1939.name = name;
            config.j1939.gateway_name = gateway;
            let mut n =
                ControllerNode::new(&machine(), AutodigMaps::builtin().unwrap(), config).unwrap();
            let ours = name.name().unwrap();
            assert_eq!(n.address_claim().name(), ours);
            // The project's default gateway NAME is not the configured one any more.
            let sent = run(
                &mut n,
                0.0,
                0.5,
                &[(0.3, claim_from(GATEWAY_ADDRESS, GATEWAY_NAME))],
            );
            assert_eq!(sent[0], (0, CLAIM_ID));
            assert_eq!(n.counters().intrusions, 1);
            let mut n = node();
            run(
                &mut n,
                0.0,
                0.5,
                &[(0.3, claim_from(GATEWAY_ADDRESS, GATEWAY_NAME))],
            );
            assert_eq!(n.counters().intrusions, 0);
        }

        #[test]
        fn a_name_field_too_wide_is_refused_with_its_line() {
            let text = "[j1939.name]\nidentity_number = 1\nmanufacturer_code = 0\n\
                        ecu_instance = 9\nfunction_instance = 0\nfunction = 130\n\
                        vehicle_system = 0\nvehicle_system_instance = 0\nindustry_group = 3\n\
                        arbitrary_address_capable = false\n";
            let err = ControllerConfig::from_toml_str_named(text, "c.toml").unwrap_err();
            assert_eq!(
                err.to_string(),
                "c.toml:4: j1939.name.ecu_instance = 9: must fit 3 bits (0 to 7)"
            );
            let same = format!(
                "[j1939.gateway_name]\n{}",
                toml::to_string(&NameConfig::from(CONTROLLER_NAME)).unwrap()
            );
            let err = ControllerConfig::from_toml_str_named(&same, "c.toml").unwrap_err();
            assert!(err.to_string().contains("must differ"), "{err}");
            let partial = "[j1939.name]\nidentity_number = 5\n";
            let err = ControllerConfig::from_toml_str_named(partial, "c.toml").unwrap_err();
            assert!(err.to_string().contains("missing field"), "{err}");
        }

        #[test]
        fn a_listen_only_node_claims_nothing() {
            let mut config = ControllerConfig::default();
            config.safety.listen_only = true;
            let mut n =
                ControllerNode::new(&machine(), AutodigMaps::builtin().unwrap(), config).unwrap();
            assert!(run(&mut n, 0.0, 0.5, &[]).is_empty());
        }
    }
}
