//! The gateway firmware logic: what the machine's CAN gateway does with the controller's frames.
//!
//! Pure logic, no physics, no clock of its own and no I/O: the caller feeds received frames with
//! [`Gateway::on_frame`] and calls [`Gateway::tick`] at its control rate with the measured joint
//! angles; the returned [`GatewayOutputs`] carry the per-valve commands in `[-1, 1]` for the valve
//! drivers and the [`GatewayStatus`] to report. The same code runs in the simulator (`vcan_sim`) and on
//! a real gateway computer bridging CAN to valve drivers.
//!
//! # Modes and arming (the exact rule)
//!
//! - The gateway boots **Disarmed**: valves neutral, commands ignored.
//! - A valid controller heartbeat requesting `ArmValve` or `ArmPosition` arms it (**ArmedValve** /
//!   **ArmedPosition**) when it is Disarmed. A heartbeat requesting `Disarm` returns it to Disarmed.
//!   Switching directly between the two armed modes is allowed (valves go neutral for that tick).
//! - A fault moves it to **Faulted**: valves neutral, the fault bits reported. It stays Faulted, whatever
//!   the controller requests, until a valid heartbeat requests `Disarm`; that acknowledges the fault,
//!   clears the bits and returns to Disarmed. Motion then needs a fresh arm request. Hence after any
//!   fault the controller must send at least one `Disarm` heartbeat, then an `Arm*` heartbeat.
//! - `EStop` in a valid heartbeat latches the `E_STOP` fault in any mode. `Disarm` does **not** clear
//!   it: only `ResetEStop` (sent on the operator's reset) does, and the gateway stays Faulted after it,
//!   so the sequence back to motion is `ResetEStop`, `Disarm`, `Arm*`. Arm requests while `E_STOP` is
//!   latched are ignored. `ResetEStop` in an armed mode disarms (it is not an arm request); while
//!   Disarmed it does nothing.
//!
//! # Time
//!
//! The caller's clock is checked, not trusted: the time of every [`Gateway::on_frame`] and
//! [`Gateway::tick`] call must be finite and never earlier than the latest time seen before (equal is
//! fine). Otherwise the gateway latches `CLOCK_FAULT` in any mode (valves neutral; the watchdog and the
//! staleness checks depend on the clock), rejects the frame, and takes the new time as its reference
//! (a non-finite one is never taken), so the controller's `Disarm` in the new time base acknowledges
//! the fault. Stamp frames with the same monotonic clock as the ticks, when they are handed over.
//!
//! # Watchdog and checks (armed modes latch a fault; while Disarmed they only count)
//!
//! - No valid heartbeat for [`GatewayConfig::heartbeat_timeout_s`] (100 ms): `WATCHDOG_TIMEOUT`. The
//!   output of a tick holds until the next one, so the check keeps a margin of one tick period
//!   ([`GatewayConfig::tick_period_s`]): a tick that finds the heartbeat older than
//!   `heartbeat_timeout_s - tick_period_s` already goes neutral, and the valves are neutral within
//!   `heartbeat_timeout_s` of the last heartbeat at any phase of the ticks.
//! - A heartbeat with a bad checksum: `BAD_CHECKSUM`. A heartbeat whose 4-bit alive counter is neither
//!   the previous one (a replay: rejected and ignored) nor its successor: `BAD_ALIVE_COUNTER`.
//! - ArmedValve: a non-neutral valve command older than [`GatewayConfig::command_timeout_s`]:
//!   `STALE_COMMAND`. ArmedPosition: no setpoint for `command_timeout_s`: `STALE_COMMAND`; a setpoint
//!   outside [`GatewayConfig::setpoint_range_rad`]: `SETPOINT_OUT_OF_RANGE`.
//! - A CAN error frame while armed: `BUS_ERROR`.
//!
//! # Frames it does not act on
//!
//! - **ignored** (expected, not counted on the bus): the controller's `ControllerStatus` (for traces,
//!   the gateway has no use for it) and neutral valve commands (block, zero flow) outside ArmedValve.
//!   Neutral is what every other mode outputs anyway, and the controller sends neutral commands on any
//!   disarm or fault without knowing whether the gateway already left ArmedValve (`controller::safety`),
//!   so they are not errors. [`Gateway::ignored_frames`] counts them for tests and logs.
//!
//! Counted and reported in the status frame, never acted on:
//! - **unexpected**: ids it does not consume (unknown PGN, 11-bit ids, remote and FD frames, the
//!   gateway's own messages from another node, a `ControllerStatus` from another address);
//! - **rejected**: messages it consumes that fail a check (wrong source address, wrong DLC, signal out
//!   of range or not available, bad checksum, replayed heartbeat, a setpoint with a repeated sequence
//!   counter, a command of the wrong kind for the mode: a non-neutral valve command outside
//!   ArmedValve, a setpoint outside ArmedPosition).
//!
//! # Position mode
//!
//! Per joint a PI position loop with anti-windup turns `setpoint - measured` into a valve command,
//! clamped to `max_command` and rate limited to `rate_limit_per_s`; the sign maps joint angle to
//! cylinder direction (`docs/ARCHITECTURE.md`: stick and bucket extension lowers their angles).

use crate::frame::CanFrame;
use crate::id::CONTROLLER_ADDRESS;
use crate::messages::{
    DecodeError, GatewayFaults, GatewayMode, GatewayStatus, Message, RequestedMode,
    heartbeat_checksum, is_next_alive,
};

/// Number of valve outputs: boom, stick, bucket, swing, left track, right track.
pub const VALVES: usize = 6;
/// Number of position-controlled joints: boom, stick, bucket, swing.
pub const JOINTS: usize = 4;

/// Gateway parameters (checked by [`GatewayConfig::validate`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GatewayConfig {
    /// Heartbeat watchdog: the valves are neutral within this of the last valid heartbeat (s).
    pub heartbeat_timeout_s: f64,
    /// The period the caller calls [`Gateway::tick`] at (s); the watchdog keeps this margin. Must be
    /// below `heartbeat_timeout_s`. Default 0.001 (the simulator's physics step).
    pub tick_period_s: f64,
    /// Age after which a non-neutral valve command or a setpoint is stale (s).
    pub command_timeout_s: f64,
    /// Position loop proportional gain (command per rad), per joint.
    pub kp: [f64; JOINTS],
    /// Position loop integral gain (command per rad s), per joint.
    pub ki: [f64; JOINTS],
    /// Largest position-mode valve command magnitude.
    pub max_command: f64,
    /// Largest change of a position-mode valve command per second.
    pub rate_limit_per_s: f64,
    /// Valve direction per joint: +1 when extension raises the joint angle (boom, swing), -1 otherwise.
    pub joint_sign: [f64; JOINTS],
    /// Accepted setpoint range `(min, max)` per joint (rad).
    pub setpoint_range_rad: [(f64, f64); JOINTS],
}

impl Default for GatewayConfig {
    fn default() -> Self {
        Self {
            heartbeat_timeout_s: 0.1,
            tick_period_s: 0.001,
            command_timeout_s: 0.1,
            kp: [4.0, 3.0, 3.0, 3.0],
            ki: [0.5, 0.5, 0.5, 0.2],
            max_command: 1.0,
            rate_limit_per_s: 5.0,
            joint_sign: [1.0, -1.0, -1.0, 1.0],
            setpoint_range_rad: [
                (-1.6, 1.6),
                (-3.0, 0.0),
                (-3.0, 1.0),
                (-std::f64::consts::PI, std::f64::consts::PI),
            ],
        }
    }
}

/// A [`GatewayConfig`] value that cannot be used.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[error("gateway config: {field} = {value} {reason}")]
pub struct GatewayConfigError {
    /// The field.
    pub field: &'static str,
    /// Its value (the offending element for arrays).
    pub value: f64,
    /// What it must be.
    pub reason: &'static str,
}

impl GatewayConfig {
    /// Checks every parameter.
    ///
    /// # Errors
    /// [`GatewayConfigError`] naming the first bad field: timeouts and the tick period must be finite
    /// and positive with the tick period below the heartbeat timeout, gains finite and non-negative,
    /// `max_command` in `(0, 1]`, the rate limit finite and positive, the joint signs +1 or -1, and
    /// every setpoint range finite with `min < max`.
    pub fn validate(&self) -> Result<(), GatewayConfigError> {
        let err = |field, value, reason| {
            Err(GatewayConfigError {
                field,
                value,
                reason,
            })
        };
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if !positive(self.heartbeat_timeout_s) {
            return err(
                "heartbeat_timeout_s",
                self.heartbeat_timeout_s,
                "must be finite and > 0",
            );
        }
        if !positive(self.tick_period_s) || self.tick_period_s >= self.heartbeat_timeout_s {
            return err(
                "tick_period_s",
                self.tick_period_s,
                "must be finite, > 0 and below heartbeat_timeout_s",
            );
        }
        if !positive(self.command_timeout_s) {
            return err(
                "command_timeout_s",
                self.command_timeout_s,
                "must be finite and > 0",
            );
        }
        for (field, gains) in [("kp", self.kp), ("ki", self.ki)] {
            if let Some(&g) = gains.iter().find(|g| !(g.is_finite() && **g >= 0.0)) {
                return err(field, g, "must be finite and >= 0");
            }
        }
        if !(self.max_command > 0.0 && self.max_command <= 1.0) {
            return err("max_command", self.max_command, "must be in (0, 1]");
        }
        if !positive(self.rate_limit_per_s) {
            return err(
                "rate_limit_per_s",
                self.rate_limit_per_s,
                "must be finite and > 0",
            );
        }
        if let Some(&s) = self.joint_sign.iter().find(|s| s.abs() != 1.0) {
            return err("joint_sign", s, "must be +1 or -1");
        }
        for (lo, hi) in self.setpoint_range_rad {
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                let bad = if lo.is_finite() { hi } else { lo };
                return err("setpoint_range_rad", bad, "must be finite with min < max");
            }
        }
        Ok(())
    }
}

/// What the gateway drives this tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GatewayOutputs {
    /// Per-valve commands in `[-1, 1]` (positive extends), all 0 unless armed and healthy.
    pub valve_commands: [f64; VALVES],
    /// The status as it stands (report it with [`Gateway::next_status`], which advances the alive
    /// counter once per status frame).
    pub status: GatewayStatus,
}

/// The gateway firmware state machine.
#[derive(Debug, Clone)]
pub struct Gateway {
    config: GatewayConfig,
    mode: GatewayMode,
    faults: GatewayFaults,
    last_heartbeat_s: Option<f64>,
    last_alive: Option<u8>,
    armed_at_s: f64,
    valve_cmd: [f64; VALVES],
    valve_cmd_at_s: [Option<f64>; VALVES],
    setpoint: Option<[f64; JOINTS]>,
    setpoint_at_s: Option<f64>,
    last_sequence: Option<u8>,
    integral: [f64; JOINTS],
    position_cmd: [f64; JOINTS],
    last_tick_s: Option<f64>,
    /// The latest valid time seen (frames and ticks), the reference of the clock check.
    clock_s: Option<f64>,
    alive_counter: u8,
    unexpected: u16,
    rejected: u16,
    ignored: u64,
}

impl Default for Gateway {
    fn default() -> Self {
        Self::with_valid_config(GatewayConfig::default())
    }
}

/// Outcome of handling one frame, for logs and tests.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameVerdict {
    /// Consumed.
    Accepted,
    /// Expected but not acted on (see the module docs): counted by [`Gateway::ignored_frames`] only.
    Ignored,
    /// Counted as unexpected.
    Unexpected,
    /// Counted as rejected.
    Rejected,
}

impl Gateway {
    /// A gateway in Disarmed mode.
    ///
    /// # Errors
    /// [`GatewayConfigError`] if `config` does not pass [`GatewayConfig::validate`].
    pub fn new(config: GatewayConfig) -> Result<Self, GatewayConfigError> {
        config.validate()?;
        Ok(Self::with_valid_config(config))
    }

    fn with_valid_config(config: GatewayConfig) -> Self {
        Self {
            config,
            mode: GatewayMode::Disarmed,
            faults: GatewayFaults(0),
            last_heartbeat_s: None,
            last_alive: None,
            armed_at_s: 0.0,
            valve_cmd: [0.0; VALVES],
            valve_cmd_at_s: [None; VALVES],
            setpoint: None,
            setpoint_at_s: None,
            last_sequence: None,
            integral: [0.0; JOINTS],
            position_cmd: [0.0; JOINTS],
            last_tick_s: None,
            clock_s: None,
            alive_counter: 0,
            unexpected: 0,
            rejected: 0,
            ignored: 0,
        }
    }

    /// The current mode.
    pub fn mode(&self) -> GatewayMode {
        self.mode
    }

    /// The latched faults.
    pub fn faults(&self) -> GatewayFaults {
        self.faults
    }

    /// Counts of unexpected and rejected frames.
    pub fn frame_counts(&self) -> (u16, u16) {
        (self.unexpected, self.rejected)
    }

    /// Frames expected but not acted on (`ControllerStatus`, neutral valve commands outside
    /// ArmedValve); not reported on the bus.
    pub fn ignored_frames(&self) -> u64 {
        self.ignored
    }

    fn is_armed(&self) -> bool {
        matches!(
            self.mode,
            GatewayMode::ArmedValve | GatewayMode::ArmedPosition
        )
    }

    fn unexpected(&mut self) -> FrameVerdict {
        self.unexpected = self.unexpected.saturating_add(1);
        FrameVerdict::Unexpected
    }

    fn ignore(&mut self) -> FrameVerdict {
        self.ignored = self.ignored.saturating_add(1);
        FrameVerdict::Ignored
    }

    fn reject(&mut self) -> FrameVerdict {
        self.rejected = self.rejected.saturating_add(1);
        FrameVerdict::Rejected
    }

    /// Faults that latch in any mode, not only in the armed ones.
    const LATCH_IN_ANY_MODE: u16 = GatewayFaults::E_STOP | GatewayFaults::CLOCK_FAULT;

    /// Latches a fault: Faulted, valves neutral. Only in armed modes, except the e-stop and the clock.
    fn fault(&mut self, bits: u16) {
        if self.is_armed()
            || bits & Self::LATCH_IN_ANY_MODE != 0
            || self.mode == GatewayMode::Faulted
        {
            self.faults = self.faults.with(bits);
            self.mode = GatewayMode::Faulted;
            self.clear_commands();
        }
    }

    fn clear_commands(&mut self) {
        self.valve_cmd = [0.0; VALVES];
        self.valve_cmd_at_s = [None; VALVES];
        self.setpoint = None;
        self.setpoint_at_s = None;
        self.integral = [0.0; JOINTS];
        self.position_cmd = [0.0; JOINTS];
    }

    /// Checks a time input (see "Time" in the module docs). On a bad one: `CLOCK_FAULT`, and a finite
    /// time becomes the new reference.
    fn clock_ok(&mut self, now_s: f64) -> bool {
        let ok = now_s.is_finite() && self.clock_s.is_none_or(|t| now_s >= t);
        if !ok {
            self.fault(GatewayFaults::CLOCK_FAULT);
            // The tick-to-tick interval across the jump means nothing.
            self.last_tick_s = None;
        }
        if now_s.is_finite() {
            self.clock_s = Some(now_s);
        }
        ok
    }

    /// Handles one received frame at time `now_s` (the caller's monotonic clock, as for
    /// [`Self::tick`]). A non-finite time or one earlier than the latest seen latches `CLOCK_FAULT`
    /// and the frame is rejected.
    pub fn on_frame(&mut self, frame: &CanFrame, now_s: f64) -> FrameVerdict {
        if !self.clock_ok(now_s) {
            return self.reject();
        }
        let decoded = match Message::decode(frame) {
            Ok(d) => d,
            Err(DecodeError::ErrorFrame(_)) => {
                self.fault(GatewayFaults::BUS_ERROR);
                return self.reject();
            }
            Err(DecodeError::BadChecksum { .. }) => {
                self.fault(GatewayFaults::BAD_CHECKSUM);
                return self.reject();
            }
            Err(
                DecodeError::UnknownPgn { .. }
                | DecodeError::StandardId(_)
                | DecodeError::RemoteFrame
                | DecodeError::FdFrame,
            ) => return self.unexpected(),
            Err(_) => return self.reject(),
        };
        let from_controller = decoded.id.source_address() == CONTROLLER_ADDRESS;
        match decoded.message {
            Message::ControllerHeartbeat(hb) => {
                if !from_controller {
                    return self.reject();
                }
                // The checksum was verified by decode; check it again in case the codec changes.
                let data = frame.data();
                if data.len() == 8 && heartbeat_checksum(data) != data[7] {
                    self.fault(GatewayFaults::BAD_CHECKSUM);
                    return self.reject();
                }
                match self.last_alive {
                    Some(prev) if prev == hb.alive_counter => return self.reject(),
                    Some(prev) if !is_next_alive(prev, hb.alive_counter, 4) => {
                        self.last_alive = Some(hb.alive_counter);
                        self.fault(GatewayFaults::BAD_ALIVE_COUNTER);
                        return self.reject();
                    }
                    _ => {}
                }
                self.last_alive = Some(hb.alive_counter);
                self.last_heartbeat_s = Some(now_s);
                self.on_request(hb.mode, now_s);
                FrameVerdict::Accepted
            }
            Message::AuxValveCommand(cmd) => {
                if !from_controller {
                    return self.reject();
                }
                let i = usize::from(cmd.valve.number());
                if i >= VALVES {
                    return self.reject();
                }
                let u = cmd.to_fraction();
                if !u.is_finite() {
                    return self.reject();
                }
                if self.mode != GatewayMode::ArmedValve {
                    // Neutral asks for what this mode already does: the controller's fail-safe.
                    return if u == 0.0 {
                        self.ignore()
                    } else {
                        self.reject()
                    };
                }
                self.valve_cmd[i] = u.clamp(-1.0, 1.0);
                self.valve_cmd_at_s[i] = Some(now_s);
                FrameVerdict::Accepted
            }
            Message::PositionSetpoint(sp) => {
                if !from_controller || self.mode != GatewayMode::ArmedPosition {
                    return self.reject();
                }
                if self.last_sequence == Some(sp.sequence) {
                    return self.reject();
                }
                self.last_sequence = Some(sp.sequence);
                let target = [sp.boom_rad, sp.stick_rad, sp.bucket_rad, sp.swing_rad];
                let in_range = target
                    .iter()
                    .zip(self.config.setpoint_range_rad)
                    .all(|(v, (lo, hi))| v.is_finite() && *v >= lo && *v <= hi);
                if !in_range {
                    self.fault(GatewayFaults::SETPOINT_OUT_OF_RANGE);
                    return self.reject();
                }
                self.setpoint = Some(target);
                self.setpoint_at_s = Some(now_s);
                FrameVerdict::Accepted
            }
            // Sent for traces; the gateway is allowed to see it and has no use for it.
            Message::ControllerStatus(_) if from_controller => self.ignore(),
            // The gateway's own messages coming from someone else, or a stranger's controller status.
            _ => self.unexpected(),
        }
    }

    fn on_request(&mut self, requested: RequestedMode, now_s: f64) {
        let estop = self.faults.contains(GatewayFaults::E_STOP);
        match (requested, self.mode) {
            (RequestedMode::EStop, _) => self.fault(GatewayFaults::E_STOP),
            (RequestedMode::ResetEStop, GatewayMode::Faulted) => {
                // Only the e-stop bit: a `Disarm` acknowledges the rest and leaves Faulted.
                self.faults = GatewayFaults(self.faults.0 & !GatewayFaults::E_STOP);
            }
            (RequestedMode::ResetEStop, GatewayMode::ArmedValve | GatewayMode::ArmedPosition) => {
                self.mode = GatewayMode::Disarmed;
                self.clear_commands();
            }
            (RequestedMode::ResetEStop, GatewayMode::Disarmed) => {}
            // A latched e-stop ignores Disarm and arm requests until the reset.
            _ if estop => {}
            (RequestedMode::Disarm, _) => {
                self.mode = GatewayMode::Disarmed;
                self.faults = GatewayFaults(0);
                self.clear_commands();
            }
            (_, GatewayMode::Faulted) => {}
            (RequestedMode::ArmValve, m) if m != GatewayMode::ArmedValve => {
                self.clear_commands();
                self.mode = GatewayMode::ArmedValve;
                self.armed_at_s = now_s;
            }
            (RequestedMode::ArmPosition, m) if m != GatewayMode::ArmedPosition => {
                self.clear_commands();
                self.mode = GatewayMode::ArmedPosition;
                self.armed_at_s = now_s;
                self.last_sequence = None;
            }
            _ => {}
        }
    }

    /// Runs the watchdog and the position loop at `now_s` with the measured joint angles
    /// `[boom, stick, bucket, swing]` (None when the resolvers are unavailable: valves neutral in
    /// position mode), and returns the valve commands and the status.
    ///
    /// A non-finite `now_s` or one earlier than the latest time seen latches `CLOCK_FAULT` (valves
    /// neutral from this tick on).
    pub fn tick(&mut self, now_s: f64, measured: Option<[f64; JOINTS]>) -> GatewayOutputs {
        let dt = if self.clock_ok(now_s) {
            let dt = self
                .last_tick_s
                .map_or(0.0, |t| (now_s - t).clamp(0.0, 1.0));
            self.last_tick_s = Some(now_s);
            dt
        } else {
            0.0
        };
        if self.is_armed() {
            let hb_age = self.last_heartbeat_s.map_or(f64::INFINITY, |t| now_s - t);
            // This output holds until the next tick, up to one tick period later: go neutral now if
            // the deadline could pass before then. Written so a NaN or infinite age counts as expired.
            let alive = hb_age + self.config.tick_period_s + 1e-9 < self.config.heartbeat_timeout_s;
            if !alive {
                self.fault(GatewayFaults::WATCHDOG_TIMEOUT);
                // A new heartbeat sequence may start at any counter after a timeout.
                self.last_alive = None;
            }
        }
        let mut out = [0.0; VALVES];
        match self.mode {
            GatewayMode::ArmedValve => {
                let timeout = self.config.command_timeout_s;
                let stale = (0..VALVES).any(|i| {
                    self.valve_cmd[i] != 0.0
                        && self.valve_cmd_at_s[i].is_none_or(|t| now_s - t > timeout)
                });
                if stale {
                    self.fault(GatewayFaults::STALE_COMMAND);
                } else {
                    out = self.valve_cmd;
                }
            }
            GatewayMode::ArmedPosition => {
                let fresh = self
                    .setpoint_at_s
                    .is_some_and(|t| now_s - t <= self.config.command_timeout_s);
                let waiting = self.setpoint_at_s.is_none()
                    && now_s - self.armed_at_s <= self.config.command_timeout_s;
                if !fresh && !waiting {
                    self.fault(GatewayFaults::STALE_COMMAND);
                } else if let (Some(sp), Some(q)) = (self.setpoint, measured) {
                    out[..JOINTS].copy_from_slice(&self.position_loop(sp, q, dt));
                } else {
                    self.position_cmd = [0.0; JOINTS];
                }
            }
            GatewayMode::Disarmed | GatewayMode::Faulted => {}
        }
        let out = out.map(|u| {
            if u.is_finite() {
                u.clamp(-1.0, 1.0)
            } else {
                0.0
            }
        });
        // The alive counter is not touched here: it counts status frames (`next_status`), not ticks.
        GatewayOutputs {
            valve_commands: out,
            status: self.status(),
        }
    }

    fn position_loop(&mut self, sp: [f64; JOINTS], q: [f64; JOINTS], dt: f64) -> [f64; JOINTS] {
        let c = self.config;
        let mut out = [0.0; JOINTS];
        for j in 0..JOINTS {
            if !q[j].is_finite() {
                self.integral[j] = 0.0;
                self.position_cmd[j] = 0.0;
                continue;
            }
            let error = sp[j] - q[j];
            let unsat = c.kp[j] * error + c.ki[j] * self.integral[j];
            // Anti-windup: integrate only while the output is not saturated in the error's direction.
            if unsat.abs() < c.max_command || unsat.signum() != error.signum() {
                self.integral[j] += error * dt;
            }
            let target = c.joint_sign[j] * (c.kp[j] * error + c.ki[j] * self.integral[j]);
            let target = target.clamp(-c.max_command, c.max_command);
            let step = c.rate_limit_per_s * dt;
            let prev = self.position_cmd[j];
            self.position_cmd[j] = prev + (target - prev).clamp(-step, step);
            out[j] = self.position_cmd[j];
        }
        out
    }

    /// The status for the next status frame: advances the 8-bit alive counter by one. Call it exactly
    /// once per `GatewayStatus` frame sent; nothing else advances the counter, so consecutive frames
    /// carry consecutive counters (`messages::is_next_alive(prev, next, 8)`).
    pub fn next_status(&mut self) -> GatewayStatus {
        self.alive_counter = self.alive_counter.wrapping_add(1);
        self.status()
    }

    /// The status as it stands (mode, faults, alive counter, frame counters).
    pub fn status(&self) -> GatewayStatus {
        GatewayStatus {
            mode: self.mode,
            faults: self.faults,
            alive_counter: self.alive_counter,
            unexpected_frames: self.unexpected,
            rejected_frames: self.rejected,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::id::GATEWAY_ADDRESS;
    use crate::messages::{
        Activity, AutodigStageCode, AuxValveCommand, ControllerHeartbeat, ControllerStatus,
        JointAngles, PositionSetpoint, Valve,
    };
    use proptest::prelude::*;

    const PERIOD_S: f64 = 0.01;

    fn hb(mode: RequestedMode, alive: u8) -> CanFrame {
        ControllerHeartbeat {
            mode,
            alive_counter: alive % 16,
        }
        .to_frame()
        .unwrap()
    }

    fn valve(v: Valve, u: f64) -> CanFrame {
        Message::AuxValveCommand(AuxValveCommand::from_fraction(v, u).unwrap())
            .encode()
            .unwrap()
    }

    fn setpoint(q: [f64; 4], seq: u8) -> CanFrame {
        Message::PositionSetpoint(PositionSetpoint {
            boom_rad: q[0],
            stick_rad: q[1],
            bucket_rad: q[2],
            swing_rad: q[3],
            sequence: seq % 16,
        })
        .encode()
        .unwrap()
    }

    /// A gateway armed in valve mode at t = 0 with heartbeat counter 0.
    fn armed() -> Gateway {
        let mut g = Gateway::default();
        assert_eq!(
            g.on_frame(&hb(RequestedMode::ArmValve, 0), 0.0),
            FrameVerdict::Accepted
        );
        assert_eq!(g.mode(), GatewayMode::ArmedValve);
        g
    }

    #[test]
    fn boots_disarmed_and_ignores_commands() {
        let mut g = Gateway::default();
        assert_eq!(
            g.on_frame(&valve(Valve::Boom, 0.5), 0.0),
            FrameVerdict::Rejected
        );
        assert_eq!(g.tick(0.0, None).valve_commands, [0.0; VALVES]);
        assert_eq!(g.mode(), GatewayMode::Disarmed);
    }

    #[test]
    fn armed_valve_mode_applies_commands() {
        let mut g = armed();
        g.on_frame(&valve(Valve::Stick, -0.25), 0.005);
        let out = g.tick(0.01, None);
        assert!((out.valve_commands[1] + 0.25).abs() < 1e-3);
        assert_eq!(out.status.mode, GatewayMode::ArmedValve);
    }

    #[test]
    fn missing_heartbeat_neutralises_within_100_ms_and_needs_disarm_then_arm() {
        let mut g = armed();
        let mut t = 0.0;
        let mut alive = 0;
        // Heartbeats and commands every 10 ms for 0.5 s.
        while t < 0.5 {
            t += PERIOD_S;
            alive += 1;
            g.on_frame(&hb(RequestedMode::ArmValve, alive), t);
            g.on_frame(&valve(Valve::Boom, 1.0), t);
            assert_eq!(g.tick(t, None).valve_commands[0], 1.0);
        }
        // Heartbeats stop; commands keep coming.
        let last_hb = t;
        let mut neutral_at = None;
        while t < 1.0 {
            t += 0.001;
            g.on_frame(&valve(Valve::Boom, 1.0), t);
            if g.tick(t, None).valve_commands == [0.0; VALVES] && neutral_at.is_none() {
                neutral_at = Some(t);
            }
        }
        let neutral_at = neutral_at.unwrap();
        assert!(
            neutral_at - last_hb <= 0.1 + 1e-9,
            "{}",
            neutral_at - last_hb
        );
        assert_eq!(g.mode(), GatewayMode::Faulted);
        assert!(g.faults().contains(GatewayFaults::WATCHDOG_TIMEOUT));
        // Arm requests alone do not clear the fault.
        g.on_frame(&hb(RequestedMode::ArmValve, 3), t);
        g.on_frame(&hb(RequestedMode::ArmValve, 4), t + 0.01);
        assert_eq!(g.mode(), GatewayMode::Faulted);
        // Disarm acknowledges, then a fresh arm request re-arms.
        g.on_frame(&hb(RequestedMode::Disarm, 5), t + 0.02);
        assert_eq!(g.mode(), GatewayMode::Disarmed);
        assert!(g.faults().is_empty());
        g.on_frame(&hb(RequestedMode::ArmValve, 6), t + 0.03);
        assert_eq!(g.mode(), GatewayMode::ArmedValve);
        // The old command does not come back: valves stay neutral until a new one arrives.
        assert_eq!(g.tick(t + 0.035, None).valve_commands, [0.0; VALVES]);
    }

    #[test]
    fn stale_command_faults() {
        let mut g = armed();
        g.on_frame(&valve(Valve::Bucket, 0.6), 0.0);
        for k in 1..=9 {
            g.on_frame(&hb(RequestedMode::ArmValve, k), 0.01 * f64::from(k));
        }
        assert_eq!(g.tick(0.09, None).valve_commands[2], 0.6);
        let out = g.tick(0.11, None);
        assert_eq!(out.valve_commands, [0.0; VALVES]);
        assert!(out.status.faults.contains(GatewayFaults::STALE_COMMAND));
    }

    #[test]
    fn bad_checksum_faults_and_is_rejected() {
        let mut g = armed();
        let frame = hb(RequestedMode::ArmValve, 1);
        let mut data = [0u8; 8];
        data.copy_from_slice(frame.data());
        data[7] ^= 0x5A;
        let bad = CanFrame::new_data(frame.id(), &data).unwrap();
        assert_eq!(g.on_frame(&bad, 0.01), FrameVerdict::Rejected);
        assert!(g.faults().contains(GatewayFaults::BAD_CHECKSUM));
        assert_eq!(g.tick(0.01, None).status.rejected_frames, 1);
        let (a, b) = (g.next_status().alive_counter, g.next_status().alive_counter);
        assert_eq!(b, a.wrapping_add(1));
    }

    /// Regression (#20): the counter advanced once per 1 kHz tick as well as once per status frame, so
    /// at 20 Hz consecutive status frames differed by 51.
    #[test]
    fn status_alive_counter_advances_once_per_status_frame_not_per_tick() {
        let mut g = armed();
        let mut prev = g.next_status().alive_counter;
        let mut t = 0.0;
        for frame in 0..600u32 {
            // 100 ticks of 1 ms (a heartbeat every 10 ms) between two status frames.
            for k in 0..100u32 {
                t += 0.001;
                if k % 10 == 0 {
                    g.on_frame(
                        &hb(RequestedMode::ArmValve, (frame * 10 + k / 10 + 1) as u8),
                        t,
                    );
                }
                let out = g.tick(t, None);
                assert_eq!(out.status.alive_counter, prev, "a tick moved the counter");
            }
            let next = g.next_status().alive_counter;
            assert!(is_next_alive(prev, next, 8), "{prev} -> {next}");
            prev = next;
        }
        assert_eq!(g.mode(), GatewayMode::ArmedValve);
    }

    #[test]
    fn skipped_alive_counter_faults_and_replay_is_rejected_only() {
        let mut g = armed();
        assert_eq!(
            g.on_frame(&hb(RequestedMode::ArmValve, 0), 0.005),
            FrameVerdict::Rejected
        );
        assert_eq!(
            g.mode(),
            GatewayMode::ArmedValve,
            "a replay is ignored, not a fault"
        );
        assert_eq!(
            g.on_frame(&hb(RequestedMode::ArmValve, 2), 0.01),
            FrameVerdict::Rejected
        );
        assert!(g.faults().contains(GatewayFaults::BAD_ALIVE_COUNTER));
    }

    #[test]
    fn e_stop_latches_in_any_mode() {
        let mut g = Gateway::default();
        g.on_frame(&hb(RequestedMode::EStop, 0), 0.0);
        assert_eq!(g.mode(), GatewayMode::Faulted);
        assert!(g.faults().contains(GatewayFaults::E_STOP));
    }

    /// Regression (#23 finding 5): one valid `Disarm` cleared the e-stop, and e-stop, Disarm, ArmValve,
    /// boom 100 % moved the boom 1 ms after the e-stop.
    #[test]
    fn e_stop_is_not_cleared_by_disarm_only_by_a_reset_then_disarm_then_arm() {
        let mut g = armed();
        g.on_frame(&valve(Valve::Boom, 0.5), 0.001);
        g.on_frame(&hb(RequestedMode::EStop, 1), 0.002);
        g.on_frame(&hb(RequestedMode::Disarm, 2), 0.0025);
        g.on_frame(&hb(RequestedMode::ArmValve, 3), 0.0026);
        g.on_frame(&valve(Valve::Boom, 1.0), 0.0027);
        let out = g.tick(0.003, None);
        assert_eq!(
            out.valve_commands, [0.0; VALVES],
            "the boom moved after the e-stop"
        );
        assert_eq!(g.mode(), GatewayMode::Faulted);
        assert!(g.faults().contains(GatewayFaults::E_STOP));
        // The reset clears the e-stop but not the Faulted mode: arm requests still do nothing.
        g.on_frame(&hb(RequestedMode::ResetEStop, 4), 0.01);
        assert!(!g.faults().contains(GatewayFaults::E_STOP));
        assert_eq!(g.mode(), GatewayMode::Faulted);
        g.on_frame(&hb(RequestedMode::ArmValve, 5), 0.02);
        g.on_frame(&valve(Valve::Boom, 1.0), 0.02);
        assert_eq!(g.tick(0.021, None).valve_commands, [0.0; VALVES]);
        assert_eq!(g.mode(), GatewayMode::Faulted);
        // Disarm acknowledges, then an arm request arms.
        g.on_frame(&hb(RequestedMode::Disarm, 6), 0.03);
        assert_eq!(g.mode(), GatewayMode::Disarmed);
        assert!(g.faults().is_empty());
        g.on_frame(&hb(RequestedMode::ArmValve, 7), 0.04);
        g.on_frame(&valve(Valve::Boom, 1.0), 0.04);
        assert_eq!(g.tick(0.041, None).valve_commands[0], 1.0);
    }

    #[test]
    fn reset_request_without_an_e_stop_never_arms() {
        let mut g = armed();
        g.on_frame(&valve(Valve::Boom, 1.0), 0.001);
        g.on_frame(&hb(RequestedMode::ResetEStop, 1), 0.002);
        assert_eq!(g.mode(), GatewayMode::Disarmed);
        assert_eq!(g.tick(0.003, None).valve_commands, [0.0; VALVES]);
        g.on_frame(&hb(RequestedMode::ResetEStop, 2), 0.01);
        assert_eq!(g.mode(), GatewayMode::Disarmed);
    }

    /// Drives the boom at 100 % with heartbeats and commands every 10 ms and 1 ms ticks from `t0_s` for
    /// 0.2 s; returns the time of the last tick.
    fn drive_boom(g: &mut Gateway, t0_s: f64, alive: &mut u8) -> f64 {
        let mut t = t0_s;
        for k in 0..200 {
            t = t0_s + f64::from(k) * 0.001;
            if k % 10 == 0 {
                *alive = alive.wrapping_add(1);
                g.on_frame(&hb(RequestedMode::ArmValve, *alive), t);
                g.on_frame(&valve(Valve::Boom, 1.0), t);
            }
            g.tick(t, None);
        }
        t
    }

    /// #23 finding 4: with the clock stepped back, the heartbeat and the commands looked 10 s younger
    /// than they were, so a controller that died just then kept the boom driven for 10 s.
    #[test]
    fn clock_stepped_back_10_s_does_not_keep_valves_driven() {
        let mut g = Gateway::default();
        let mut alive = 0;
        g.on_frame(&hb(RequestedMode::ArmValve, alive), 100.0);
        let t = drive_boom(&mut g, 100.0, &mut alive);
        assert_eq!(g.tick(t, None).valve_commands[0], 1.0);
        // The clock steps back 10 s and the controller says nothing more.
        let back = t - 10.0;
        let out = g.tick(back, None);
        assert_eq!(out.valve_commands, [0.0; VALVES]);
        assert!(out.status.faults.contains(GatewayFaults::CLOCK_FAULT));
        assert_eq!(out.status.mode, GatewayMode::Faulted);
        for k in 1..=2000 {
            let out = g.tick(back + f64::from(k) * 0.001, None);
            assert_eq!(out.valve_commands, [0.0; VALVES]);
        }
        // In the new time base the controller's Disarm acknowledges and motion needs a fresh arm.
        let t = back + 2.001;
        alive += 1;
        g.on_frame(&hb(RequestedMode::ArmValve, alive), t);
        g.on_frame(&valve(Valve::Boom, 1.0), t);
        assert_eq!(
            g.tick(t, None).valve_commands,
            [0.0; VALVES],
            "still Faulted"
        );
        alive += 1;
        g.on_frame(&hb(RequestedMode::Disarm, alive), t + 0.01);
        assert_eq!(g.mode(), GatewayMode::Disarmed);
        assert!(g.faults().is_empty());
        let t = drive_boom(&mut g, t + 0.02, &mut alive);
        assert_eq!(g.tick(t, None).valve_commands[0], 1.0);
    }

    #[test]
    fn a_command_stamped_nan_does_not_drive_the_boom() {
        let mut g = armed();
        assert_eq!(
            g.on_frame(&valve(Valve::Boom, 1.0), f64::NAN),
            FrameVerdict::Rejected
        );
        assert!(g.faults().contains(GatewayFaults::CLOCK_FAULT));
        // Heartbeats and ticks go on with good times: the boom stays put until Disarm, Arm.
        for k in 1..=20u8 {
            let t = f64::from(k) * 0.005;
            g.on_frame(&hb(RequestedMode::ArmValve, k), t);
            assert_eq!(g.tick(t, None).valve_commands, [0.0; VALVES]);
        }
        // A frame from before the latest time is a clock fault too, as is a NaN tick.
        let mut g = armed();
        g.tick(0.01, None);
        assert_eq!(
            g.on_frame(&valve(Valve::Boom, 1.0), 0.009),
            FrameVerdict::Rejected
        );
        assert!(g.faults().contains(GatewayFaults::CLOCK_FAULT));
        let mut g = armed();
        g.on_frame(&valve(Valve::Boom, 1.0), 0.001);
        assert_eq!(g.tick(0.002, None).valve_commands[0], 1.0);
        let out = g.tick(f64::NAN, None);
        assert_eq!(out.valve_commands, [0.0; VALVES]);
        assert!(out.status.faults.contains(GatewayFaults::CLOCK_FAULT));
        // Equal times are fine.
        let mut g = armed();
        g.on_frame(&valve(Valve::Boom, 1.0), 0.0);
        assert_eq!(g.tick(0.0, None).valve_commands[0], 1.0);
        assert!(g.faults().is_empty());
    }

    #[test]
    fn frame_counters_saturate_and_say_so() {
        let mut g = Gateway::default();
        let unknown = CanFrame::new_extended(0x18FE_EE00, &[1, 2, 3]).unwrap();
        for k in 0..70_000u32 {
            g.on_frame(&unknown, f64::from(k) * 1e-6);
        }
        let status = g.next_status();
        assert_eq!(
            status.unexpected_frames,
            GatewayStatus::FRAME_COUNT_SATURATED
        );
        assert!(status.unexpected_frames_saturated());
        assert!(!status.rejected_frames_saturated());
        // The saturated value survives the wire.
        let frame = Message::GatewayStatus(status).encode().unwrap();
        let Message::GatewayStatus(back) = Message::decode(&frame).unwrap().message else {
            panic!("not a status");
        };
        assert!(back.unexpected_frames_saturated());
    }

    #[test]
    fn invalid_configs_are_errors() {
        assert!(GatewayConfig::default().validate().is_ok());
        let bad = [
            GatewayConfig {
                heartbeat_timeout_s: f64::NAN,
                ..GatewayConfig::default()
            },
            GatewayConfig {
                tick_period_s: 0.1,
                ..GatewayConfig::default()
            },
            GatewayConfig {
                tick_period_s: 0.0,
                ..GatewayConfig::default()
            },
            GatewayConfig {
                command_timeout_s: -1.0,
                ..GatewayConfig::default()
            },
            GatewayConfig {
                kp: [4.0, f64::INFINITY, 3.0, 3.0],
                ..GatewayConfig::default()
            },
            GatewayConfig {
                max_command: 1.5,
                ..GatewayConfig::default()
            },
            GatewayConfig {
                rate_limit_per_s: 0.0,
                ..GatewayConfig::default()
            },
            GatewayConfig {
                joint_sign: [1.0, 0.0, -1.0, 1.0],
                ..GatewayConfig::default()
            },
            GatewayConfig {
                setpoint_range_rad: [(1.0, -1.0); JOINTS],
                ..GatewayConfig::default()
            },
        ];
        for config in bad {
            let e = Gateway::new(config).unwrap_err();
            assert!(!e.to_string().is_empty());
        }
    }

    #[test]
    fn foreign_source_address_and_unknown_frames_are_counted_not_acted_on() {
        let mut g = armed();
        let foreign =
            Message::AuxValveCommand(AuxValveCommand::from_fraction(Valve::Boom, 1.0).unwrap())
                .encode_from(0x33)
                .unwrap();
        assert_eq!(g.on_frame(&foreign, 0.001), FrameVerdict::Rejected);
        let unknown = CanFrame::new_extended(0x18FEEE00, &[1, 2, 3]).unwrap();
        assert_eq!(g.on_frame(&unknown, 0.002), FrameVerdict::Unexpected);
        let standard = CanFrame::new_standard(0x123, &[0; 8]).unwrap();
        assert_eq!(g.on_frame(&standard, 0.002), FrameVerdict::Unexpected);
        let own = Message::JointAngles(JointAngles {
            boom_rad: 0.0,
            stick_rad: 0.0,
            bucket_rad: 0.0,
            swing_rad: 0.0,
        })
        .encode_from(GATEWAY_ADDRESS)
        .unwrap();
        assert_eq!(g.on_frame(&own, 0.003), FrameVerdict::Unexpected);
        let good = valve(Valve::Boom, 1.0);
        let short = CanFrame::new_data(good.id(), &good.data()[..4]).unwrap();
        assert_eq!(g.on_frame(&short, 0.004), FrameVerdict::Rejected);
        let out = g.tick(0.005, None);
        assert_eq!(out.valve_commands, [0.0; VALVES]);
        assert_eq!(out.status.mode, GatewayMode::ArmedValve);
        assert_eq!(
            (out.status.unexpected_frames, out.status.rejected_frames),
            (3, 2)
        );
    }

    /// Regression (#20): the controller's own 20 Hz `ControllerStatus` counted as unexpected, so the
    /// counter rose by one per frame and saturated within an hour.
    #[test]
    fn controller_status_is_ignored_not_unexpected() {
        let mut g = armed();
        let status = Message::ControllerStatus(ControllerStatus {
            activity: Activity::Dig,
            stage: AutodigStageCode::Dig,
            dig_index: 3,
            hardness_index: 1.0,
            swept_volume_m3: 0.5,
            fault_reason: 0,
            alive_counter: 1,
        });
        let own = status.encode().unwrap();
        assert_eq!(g.on_frame(&own, 0.001), FrameVerdict::Ignored);
        // The same message from a stranger is not expected.
        let foreign = status.encode_from(0x33).unwrap();
        assert_eq!(g.on_frame(&foreign, 0.002), FrameVerdict::Unexpected);
        assert_eq!(g.frame_counts(), (1, 0));
        assert_eq!(g.ignored_frames(), 1);
        assert_eq!(g.mode(), GatewayMode::ArmedValve);
    }

    /// Regression (#20): after each planned disarm the controller's neutral valve commands (its neutral
    /// hold, and the step that re-arms) counted as rejected, six per period, next to every re-arm.
    #[test]
    fn neutral_valve_commands_outside_valve_mode_are_ignored_others_rejected() {
        let mut g = armed();
        g.on_frame(&hb(RequestedMode::Disarm, 1), 0.01);
        assert_eq!(g.mode(), GatewayMode::Disarmed);
        for v in Valve::ALL {
            assert_eq!(g.on_frame(&valve(v, 0.0), 0.02), FrameVerdict::Ignored);
        }
        assert_eq!(
            g.on_frame(&valve(Valve::Boom, 0.3), 0.02),
            FrameVerdict::Rejected,
            "motion while disarmed is wrong"
        );
        // The same in position mode: neutral ignored, motion rejected, and nothing moves the valve.
        g.on_frame(&hb(RequestedMode::ArmPosition, 2), 0.03);
        assert_eq!(g.mode(), GatewayMode::ArmedPosition);
        assert_eq!(
            g.on_frame(&valve(Valve::Stick, 0.0), 0.031),
            FrameVerdict::Ignored
        );
        assert_eq!(
            g.on_frame(&valve(Valve::Stick, -1.0), 0.032),
            FrameVerdict::Rejected
        );
        assert_eq!(g.tick(0.033, None).valve_commands, [0.0; VALVES]);
        assert_eq!(g.frame_counts(), (0, 2));
        assert_eq!(g.ignored_frames(), 7);
    }

    #[test]
    fn position_mode_drives_toward_the_setpoint_with_rate_limit() {
        let mut g = Gateway::default();
        g.on_frame(&hb(RequestedMode::ArmPosition, 0), 0.0);
        assert_eq!(g.mode(), GatewayMode::ArmedPosition);
        g.on_frame(&setpoint([0.5, -1.0, -1.0, 0.0], 0), 0.0);
        let q = [0.0, -1.5, -0.5, 0.0];
        let first = g.tick(0.0, Some(q)).valve_commands;
        assert_eq!(first, [0.0; VALVES], "rate limited from zero");
        g.on_frame(&hb(RequestedMode::ArmPosition, 1), 0.01);
        g.on_frame(&setpoint([0.5, -1.0, -1.0, 0.0], 1), 0.01);
        let out = g.tick(0.01, Some(q)).valve_commands;
        assert!((out[0] - 0.05).abs() < 1e-9, "boom up: extend, {out:?}");
        assert!(out[1] < 0.0, "stick angle must rise: retract, {out:?}");
        assert!(out[2] > 0.0, "bucket angle must fall: extend, {out:?}");
        assert_eq!(out[3], 0.0);
        // Same sequence counter again: a replay, rejected.
        assert_eq!(
            g.on_frame(&setpoint([0.5, -1.0, -1.0, 0.0], 1), 0.015),
            FrameVerdict::Rejected
        );
    }

    #[test]
    fn position_mode_faults_on_stale_or_out_of_range_setpoints() {
        let mut g = Gateway::default();
        g.on_frame(&hb(RequestedMode::ArmPosition, 0), 0.0);
        g.on_frame(&hb(RequestedMode::ArmPosition, 1), 0.09);
        g.tick(0.09, Some([0.0; 4]));
        assert_eq!(
            g.mode(),
            GatewayMode::ArmedPosition,
            "grace period after arming"
        );
        g.tick(0.11, Some([0.0; 4]));
        assert!(g.faults().contains(GatewayFaults::STALE_COMMAND));
        let mut g = Gateway::default();
        g.on_frame(&hb(RequestedMode::ArmPosition, 0), 0.0);
        g.on_frame(&setpoint([0.0, 0.0, 0.0, 0.0], 0), 0.0);
        g.on_frame(&setpoint([0.0, -1.0, 2.0, 0.0], 1), 0.0);
        assert!(g.faults().contains(GatewayFaults::SETPOINT_OUT_OF_RANGE));
    }

    /// Heartbeat period of the phase sweep (the tightest the controller may use), s.
    const SWEEP_HEARTBEAT_PERIOD_S: f64 = 0.01;
    /// The gateway's tick period in the simulator and on the reference gateway, s.
    const SWEEP_TICK_S: f64 = 0.001;

    /// Runs a gateway ticking every `SWEEP_TICK_S` from t = 0 with heartbeats (and a fresh boom command)
    /// every `SWEEP_HEARTBEAT_PERIOD_S` from `phase_s`, the last one number `last`; boom commands go on
    /// after it. Returns the last heartbeat's time and the time of the first tick with neutral output.
    fn first_neutral_after_last_heartbeat(phase_s: f64, last: u32) -> (f64, f64) {
        let mut g = Gateway::default();
        let last_hb_s = phase_s + f64::from(last) * SWEEP_HEARTBEAT_PERIOD_S;
        let mut n = 0u32;
        let mut k = 0u32;
        loop {
            let t = f64::from(k) * SWEEP_TICK_S;
            // Deliver the frames due by this tick, stamped with their own time.
            loop {
                let at = phase_s + f64::from(n) * SWEEP_HEARTBEAT_PERIOD_S;
                if at > t {
                    break;
                }
                if n <= last {
                    let mode = RequestedMode::ArmValve;
                    g.on_frame(&hb(mode, (n % 16) as u8), at);
                }
                g.on_frame(&valve(Valve::Boom, 1.0), at);
                n += 1;
            }
            let out = g.tick(t, None);
            if t >= last_hb_s && out.valve_commands == [0.0; VALVES] {
                return (last_hb_s, t);
            }
            assert!(t < last_hb_s + 1.0, "never neutral");
            k += 1;
        }
    }

    #[test]
    fn watchdog_neutralises_within_100_ms_at_every_heartbeat_phase() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0x57A7_C4D0);
        let (mut best_s, mut worst_s) = (f64::INFINITY, 0.0_f64);
        for _ in 0..1000 {
            let phase_s = rng.random_range(0.0..SWEEP_HEARTBEAT_PERIOD_S);
            let last = rng.random_range(5..40);
            let (last_hb_s, neutral_s) = first_neutral_after_last_heartbeat(phase_s, last);
            best_s = best_s.min(neutral_s - last_hb_s);
            worst_s = worst_s.max(neutral_s - last_hb_s);
        }
        println!(
            "watchdog: last heartbeat to neutral valves over 1000 phases: best {:.3} ms, worst {:.3} ms",
            best_s * 1e3,
            worst_s * 1e3
        );
        assert!(worst_s <= 0.1 + 1e-9, "{:.3} ms", worst_s * 1e3);
    }

    proptest! {
        /// Garbage frames never panic and never produce motion from a disarmed gateway.
        #[test]
        fn garbage_frames_never_panic(
            frames in proptest::collection::vec(
                (any::<u32>(), proptest::collection::vec(any::<u8>(), 0..=8), any::<bool>()),
                0..50
            ),
            measured in proptest::array::uniform4(any::<f64>()),
        ) {
            let mut g = Gateway::default();
            let mut t = 0.0;
            for (id, data, extended) in frames {
                let frame = if extended {
                    CanFrame::new_extended(id & 0x1FFF_FFFF, &data)
                } else {
                    CanFrame::new_standard((id & 0x7FF) as u16, &data)
                };
                if let Ok(frame) = frame {
                    g.on_frame(&frame, t);
                }
                t += 0.003;
                let out = g.tick(t, Some(measured));
                prop_assert!(out.valve_commands.iter().all(|u| u.is_finite() && u.abs() <= 1.0));
            }
        }
    }
}
