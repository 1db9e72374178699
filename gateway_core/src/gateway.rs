//! The gateway firmware logic: what the machine's CAN gateway does with the controller's frames.
//!
//! Pure logic, no physics, no clock of its own, no I/O and no allocation: the caller feeds received
//! frames with [`Gateway::on_frame`] (or a bus with [`Gateway::poll`], `crate::bus`) and calls
//! [`Gateway::tick`] at its control rate with the measured joint angles; the returned
//! [`GatewayOutputs`] carry the per-valve commands in `[-1, 1]` for the valve drivers and the
//! [`GatewayStatus`] to report. The same code runs in the simulator (`vcan_sim`) and on the machine's
//! microcontroller bridging CAN to valve drivers (`docs/gateway-core.md`).
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
//! Time is an integer, [`Instant`] (nanoseconds): a microcontroller's timer, or `f64` seconds from a
//! host clock converted to the nearest nanosecond ([`ClockReading`]). The caller's clock is checked,
//! not trusted: the time of every [`Gateway::on_frame`] and [`Gateway::tick`] call must be readable
//! (a finite `f64`) and never earlier than the latest time seen before (equal is fine). Otherwise the
//! gateway latches `CLOCK_FAULT` in any mode (valves neutral; the watchdog and the staleness checks
//! depend on the clock), rejects the frame, and takes the new time as its reference (an unreadable
//! one is never taken), so the controller's `Disarm` in the new time base acknowledges the fault.
//! Stamp frames with the same monotonic clock as the ticks, when they are handed over. The
//! durations of [`GatewayConfig`] are converted to nanoseconds once, when the gateway is built.
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
//! # Address claim
//!
//! The gateway claims its address (`0x80`) with its NAME (J1939-81, [`crate::address_claim`]) at its
//! first [`Gateway::tick`], and answers contests and requests through the same claimer. Its status
//! ([`Gateway::status_frames`]) and the board's sensor frames go out only while
//! [`Gateway::may_transmit`]: once the claim has stood for 250 ms. Losing the address to a lower NAME
//! latches `ADDRESS_LOST` in any mode (valves neutral): the controller can no longer address the
//! gateway, so nothing it sends is acted on, and the gateway stays silent except for its Cannot
//! Claim. A Request for Address Claimed to global (the controller sends one on the operator's reset)
//! makes it claim its address again ([`crate::address_claim::AfterLoss::ReclaimOnRequest`], a
//! deviation from J1939-81 documented there): a real owner answers the same request and wins again;
//! after a transient claim the re-claim stands. Until it has stood 250 ms the gateway acts on nothing
//! and sends nothing else; then it reports `Faulted` with `ADDRESS_LOST`, which the controller's
//! `Disarm` acknowledges as any fault, and only a fresh arm request arms it: it never re-arms by
//! itself. Claim frames go out through [`Gateway::take_claim_frame`].
//!
//! # Frames it does not act on
//!
//! - **ignored** (expected, not counted on the bus): other nodes' address claims and requests not
//!   for the gateway, every frame after the address was lost, the controller's `ControllerStatus` (for traces,
//!   the gateway has no use for it) and neutral valve commands (block, zero flow) outside ArmedValve.
//!   Neutral is what every other mode outputs anyway, and the controller sends neutral commands on any
//!   disarm or fault without knowing whether the gateway already left ArmedValve (`controller::step::safety`),
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

use crate::address_claim::{AddressClaimer, ClaimEvent, Name};
use crate::dm1::{Dm1Reporter, GATEWAY_DTCS};
use crate::frame::CanFrame;
use crate::id::CONTROLLER_ADDRESS;
use crate::messages::{
    DecodeError, Dm1, GatewayFaults, GatewayMode, GatewaySession, GatewayStatus, Message,
    RequestedMode, heartbeat_checksum, is_next_alive,
};
use crate::range::Limits;
use crate::secoc::{NonceSource, SessionKey, SessionNonces, Verifier};
use crate::time::{ClockReading, Instant, NANOS_PER_S, secs_to_nanos};

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
                (-core::f64::consts::PI, core::f64::consts::PI),
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

/// The ranges [`GatewayConfig::validate`] checks with the workspace's one finite-and-range check
/// ([`crate::range`]), each with its rule as `range` states it (a `&'static str`: the error holds no
/// allocation; a test checks the two agree).
const GAIN_LIMITS: (Limits, &str) = (Limits::NON_NEGATIVE, "must be finite and >= 0");
const MAX_COMMAND_LIMITS: (Limits, &str) =
    (Limits::above(0.0, 1.0, ""), "must be finite and in (0, 1]");
const RATE_LIMIT_LIMITS: (Limits, &str) = (Limits::POSITIVE, "must be finite and > 0");

impl GatewayConfig {
    /// Checks every parameter.
    ///
    /// # Errors
    /// [`GatewayConfigError`] naming the first bad field: timeouts and the tick period must be finite
    /// durations of at least 1 ns (the gateway's clock counts nanoseconds) with the tick period below
    /// the heartbeat timeout, gains finite and non-negative,
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
        // A duration the gateway's integer clock can hold: at least a nanosecond, under 292 years.
        let duration = |v: f64| secs_to_nanos(v).is_some_and(|ns| ns > 0);
        if !duration(self.heartbeat_timeout_s) {
            return err(
                "heartbeat_timeout_s",
                self.heartbeat_timeout_s,
                "must be a finite duration of at least 1 ns",
            );
        }
        if !duration(self.tick_period_s) || self.tick_period_s >= self.heartbeat_timeout_s {
            return err(
                "tick_period_s",
                self.tick_period_s,
                "must be a finite duration of at least 1 ns, below heartbeat_timeout_s",
            );
        }
        if !duration(self.command_timeout_s) {
            return err(
                "command_timeout_s",
                self.command_timeout_s,
                "must be a finite duration of at least 1 ns",
            );
        }
        for (field, gains) in [("kp", self.kp), ("ki", self.ki)] {
            if let Some(&g) = gains.iter().find(|&&g| !GAIN_LIMITS.0.contains(g)) {
                return err(field, g, GAIN_LIMITS.1);
            }
        }
        if !MAX_COMMAND_LIMITS.0.contains(self.max_command) {
            return err("max_command", self.max_command, MAX_COMMAND_LIMITS.1);
        }
        if !RATE_LIMIT_LIMITS.0.contains(self.rate_limit_per_s) {
            return err(
                "rate_limit_per_s",
                self.rate_limit_per_s,
                RATE_LIMIT_LIMITS.1,
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

/// The durations of a validated [`GatewayConfig`] in nanoseconds: the periodic path compares
/// integers only.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Timing {
    heartbeat_timeout_ns: i64,
    tick_period_ns: i64,
    command_timeout_ns: i64,
}

impl Timing {
    /// `config` has passed [`GatewayConfig::validate`], so every duration converts.
    fn of(config: &GatewayConfig) -> Self {
        let ns = |s: f64| secs_to_nanos(s).unwrap_or(i64::MAX);
        Self {
            heartbeat_timeout_ns: ns(config.heartbeat_timeout_s),
            tick_period_ns: ns(config.tick_period_s),
            command_timeout_ns: ns(config.command_timeout_s),
        }
    }
}

/// The gateway firmware state machine.
#[derive(Debug, Clone)]
pub struct Gateway {
    config: GatewayConfig,
    mode: GatewayMode,
    faults: GatewayFaults,
    /// The durations of `config` in the clock's nanoseconds.
    timing: Timing,
    last_heartbeat: Option<Instant>,
    last_alive: Option<u8>,
    armed_at: Instant,
    valve_cmd: [f64; VALVES],
    valve_cmd_at: [Option<Instant>; VALVES],
    setpoint: Option<[f64; JOINTS]>,
    setpoint_at: Option<Instant>,
    integral: [f64; JOINTS],
    position_cmd: [f64; JOINTS],
    last_tick: Option<Instant>,
    /// The latest valid time seen (frames and ticks), the reference of the clock check.
    clock: Option<Instant>,
    /// Freshness and authentication of the controller's frames in the current session.
    verifier: Verifier,
    nonces: SessionNonces,
    /// A valid heartbeat was accepted in this session (a session ends when they stop).
    session_used: bool,
    alive_counter: u8,
    unexpected: u16,
    rejected: u16,
    ignored: u64,
    /// The J1939-81 address claim of the gateway's address.
    claim: AddressClaimer,
    /// The fault bits as J1939-73 DM1 ([`crate::dm1::GATEWAY_DTCS`]).
    dm1: Dm1Reporter<{ GATEWAY_DTCS.len() }>,
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
    /// A gateway in Disarmed mode whose session nonces start from `nonces`, the platform's source
    /// ([`NonceSource`]: a hardware random number or a persisted boot counter; on a host the OS's,
    /// `OsNonceSource`).
    ///
    /// # Errors
    /// [`GatewayConfigError`] if `config` does not pass [`GatewayConfig::validate`].
    pub fn new(
        config: GatewayConfig,
        nonces: &mut impl NonceSource,
    ) -> Result<Self, GatewayConfigError> {
        config.validate()?;
        Ok(Self::with_valid_config(config, nonces.session_seed()))
    }

    /// [`Self::new`] with [`GatewayConfig::default`], the project's gateway.
    pub fn with_default_config(nonces: &mut impl NonceSource) -> Self {
        Self::with_valid_config(GatewayConfig::default(), nonces.session_seed())
    }

    /// The same gateway with a provisioned `key` (both ends must hold it; [`SessionKey::PUBLIC`] when
    /// none is) and session nonces from `session_seed`, which must differ at every power-up (a
    /// hardware random number or a persisted boot counter): starts a new session.
    pub fn with_security(mut self, key: &SessionKey, session_seed: u64) -> Self {
        self.set_security(key, session_seed);
        self
    }

    /// As [`Self::with_security`], in place.
    pub fn set_security(&mut self, key: &SessionKey, session_seed: u64) {
        self.nonces = SessionNonces::new(session_seed);
        let first = self.nonces.next_after(None);
        self.verifier = Verifier::new(key, first);
        self.session_used = false;
    }

    fn with_valid_config(config: GatewayConfig, session_seed: u64) -> Self {
        let mut nonces = SessionNonces::new(session_seed);
        let first = nonces.next_after(None);
        Self {
            config,
            mode: GatewayMode::Disarmed,
            faults: GatewayFaults(0),
            timing: Timing::of(&config),
            last_heartbeat: None,
            last_alive: None,
            armed_at: Instant::ZERO,
            valve_cmd: [0.0; VALVES],
            valve_cmd_at: [None; VALVES],
            setpoint: None,
            setpoint_at: None,
            integral: [0.0; JOINTS],
            position_cmd: [0.0; JOINTS],
            last_tick: None,
            clock: None,
            verifier: Verifier::new(&SessionKey::PUBLIC, first),
            nonces,
            session_used: false,
            alive_counter: 0,
            unexpected: 0,
            rejected: 0,
            ignored: 0,
            claim: AddressClaimer::gateway(),
            dm1: Dm1Reporter::new(&GATEWAY_DTCS),
        }
    }

    /// The same gateway with another NAME (a machine's provisioned serial number) for its address
    /// claim. Call before the first tick.
    pub fn with_name(mut self, name: Name) -> Self {
        self.set_name(name);
        self
    }

    /// As [`Self::with_name`], in place.
    pub fn set_name(&mut self, name: Name) {
        let margin_ns = self.claim.hold_ns() - crate::address_claim::CLAIM_HOLD_NS;
        self.claim = AddressClaimer::gateway_named(name).with_hold_margin(margin_ns);
    }

    /// The same gateway waiting `margin_ns` longer than 250 ms before its claim stands
    /// ([`AddressClaimer::with_hold_margin`]): for a board whose clock can run behind the bus by up
    /// to that much when its claim leaves. Call before the first tick.
    pub fn with_claim_hold_margin(mut self, margin_ns: i64) -> Self {
        self.set_claim_hold_margin(margin_ns);
        self
    }

    /// As [`Self::with_claim_hold_margin`], in place.
    pub fn set_claim_hold_margin(&mut self, margin_ns: i64) {
        self.claim = self.claim.with_hold_margin(margin_ns);
    }

    /// The address claim (state, NAME, address).
    pub fn address_claim(&self) -> &AddressClaimer {
        &self.claim
    }

    /// True once the gateway's address claim has stood for 250 ms and was not lost: its status and
    /// the board's sensor frames may be sent.
    pub fn may_transmit(&self) -> bool {
        self.claim.may_transmit()
    }

    /// The address-claim frame to send now (the claim at start, a re-claim after a contest, the
    /// answer to a request, or Cannot Claim), if any. Send it before the period's other frames.
    pub fn take_claim_frame(&mut self) -> Option<CanFrame> {
        // Every NAME encodes (`AddressClaimer::take_frame`); an error would keep it queued.
        self.claim.take_frame().ok().flatten()
    }

    /// The current mode.
    pub fn mode(&self) -> GatewayMode {
        self.mode
    }

    /// The latched faults.
    pub fn faults(&self) -> GatewayFaults {
        self.faults
    }

    /// The DM1 to send now, if one is due ([`Dm1Reporter::poll`] at the last tick's time): its fault
    /// bits as J1939-73 trouble codes. `None` before the first tick. Send it only while
    /// [`Self::may_transmit`] ([`Gateway::dm1_frame`] checks it).
    pub fn dm1_due(&mut self) -> Option<Dm1> {
        let now = self.last_tick?;
        self.dm1.poll(now)
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
    const LATCH_IN_ANY_MODE: u16 =
        GatewayFaults::E_STOP | GatewayFaults::CLOCK_FAULT | GatewayFaults::ADDRESS_LOST;

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
        self.valve_cmd_at = [None; VALVES];
        self.setpoint = None;
        self.setpoint_at = None;
        self.integral = [0.0; JOINTS];
        self.position_cmd = [0.0; JOINTS];
    }

    /// Checks a time input (see "Time" in the module docs). On a bad one: `CLOCK_FAULT`, and a finite
    /// time becomes the new reference.
    fn clock_ok(&mut self, now: ClockReading) -> Option<Instant> {
        let ok = now.0.filter(|t| self.clock.is_none_or(|c| *t >= c));
        if ok.is_none() {
            self.fault(GatewayFaults::CLOCK_FAULT);
            // The tick-to-tick interval across the jump means nothing.
            self.last_tick = None;
        }
        if now.0.is_some() {
            self.clock = now.0;
        }
        ok
    }

    /// Handles one received frame at time `now` (the caller's monotonic clock, as for
    /// [`Self::tick`]: an [`Instant`] or `f64` seconds). An unreadable time (a non-finite `f64`) or
    /// one earlier than the latest seen latches `CLOCK_FAULT` and the frame is rejected.
    pub fn on_frame(&mut self, frame: &CanFrame, now: impl Into<ClockReading>) -> FrameVerdict {
        let Some(now) = self.clock_ok(now.into()) else {
            return self.reject();
        };
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
        if let Some(event) = self.claim.on_message(decoded.id, &decoded.message, now) {
            return match event {
                ClaimEvent::Lost { .. } => {
                    self.fault(GatewayFaults::ADDRESS_LOST);
                    FrameVerdict::Accepted
                }
                ClaimEvent::Reclaimed { .. } => {
                    // The heartbeats it ignored meanwhile: a new sequence may start at any counter.
                    self.last_alive = None;
                    FrameVerdict::Accepted
                }
                ClaimEvent::Defended { .. } | ClaimEvent::Answered => FrameVerdict::Accepted,
                ClaimEvent::Noted => self.ignore(),
            };
        }
        if self.claim.lost().is_some()
            || (self.faults.contains(GatewayFaults::ADDRESS_LOST) && !self.claim.may_transmit())
        {
            // Without its address the gateway cannot be commanded, and after a re-claim it acts on
            // nothing until the claim has stood: `ADDRESS_LOST` stays latched until then.
            return self.ignore();
        }
        let from_controller = decoded.id.source_address() == CONTROLLER_ADDRESS;
        if from_controller
            && decoded.trailer.is_some()
            && self.verifier.verify(&decoded, frame).is_err()
        {
            // Replayed, recorded in another session, from a second sender with the controller's
            // address, or without the key. Neutral when armed; counted otherwise.
            self.fault(GatewayFaults::AUTH_FAILURE);
            return self.reject();
        }
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
                self.last_heartbeat = Some(now);
                self.session_used = true;
                self.on_request(hb.mode, now);
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
                self.valve_cmd_at[i] = Some(now);
                FrameVerdict::Accepted
            }
            Message::PositionSetpoint(sp) => {
                if !from_controller || self.mode != GatewayMode::ArmedPosition {
                    return self.reject();
                }
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
                self.setpoint_at = Some(now);
                FrameVerdict::Accepted
            }
            // Sent for traces; the gateway is allowed to see it and has no use for it.
            Message::ControllerStatus(_) if from_controller => self.ignore(),
            // Every J1939 node may broadcast its trouble codes; they are for service tools.
            Message::Dm1(_) if decoded.id.source_address() != self.claim.address() => self.ignore(),
            // The gateway's own messages coming from someone else, or a stranger's controller status.
            _ => self.unexpected(),
        }
    }

    fn on_request(&mut self, requested: RequestedMode, now: Instant) {
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
                self.armed_at = now;
            }
            (RequestedMode::ArmPosition, m) if m != GatewayMode::ArmedPosition => {
                self.clear_commands();
                self.mode = GatewayMode::ArmedPosition;
                self.armed_at = now;
            }
            _ => {}
        }
    }

    /// Runs the watchdog and the position loop at `now` (an [`Instant`] or `f64` seconds) with the
    /// measured joint angles `[boom, stick, bucket, swing]` (None when the resolvers are unavailable:
    /// valves neutral in position mode), and returns the valve commands and the status.
    ///
    /// An unreadable `now` or one earlier than the latest time seen latches `CLOCK_FAULT` (valves
    /// neutral from this tick on).
    pub fn tick(
        &mut self,
        now: impl Into<ClockReading>,
        measured: Option<[f64; JOINTS]>,
    ) -> GatewayOutputs {
        let reading = now.into();
        let ok = self.clock_ok(reading);
        if let Some(now) = ok {
            self.claim.update(now);
        }
        let dt_s = match ok {
            Some(now) => {
                let dt_ns = self
                    .last_tick
                    .map_or(0, |t| now.nanos_since(t).clamp(0, NANOS_PER_S));
                self.last_tick = Some(now);
                dt_ns as f64 / NANOS_PER_S as f64
            }
            None => 0.0,
        };
        let timing = self.timing;
        // The heartbeat's age; `None` when unknown (no heartbeat yet, or an unreadable clock).
        let hb_age_ns = reading
            .0
            .zip(self.last_heartbeat)
            .map(|(now, t)| now.nanos_since(t));
        if self.session_used && hb_age_ns.is_none_or(|age| age >= timing.heartbeat_timeout_ns) {
            // The controller of this session is gone: nothing recorded in it will be accepted again,
            // and the next controller starts a new one.
            self.new_session();
        }
        if self.is_armed() {
            // This output holds until the next tick, up to one tick period later: go neutral now if
            // the deadline could pass before then.
            let alive = hb_age_ns.is_some_and(|age| {
                age.saturating_add(timing.tick_period_ns) < timing.heartbeat_timeout_ns
            });
            if !alive {
                self.fault(GatewayFaults::WATCHDOG_TIMEOUT);
                // A new heartbeat sequence may start at any counter after a timeout.
                self.last_alive = None;
            }
        }
        // Armed modes only remain with a good clock reading (a bad one latched `CLOCK_FAULT`).
        let age_ns = |t: Instant| ok.map_or(i64::MAX, |now| now.nanos_since(t));
        let mut out = [0.0; VALVES];
        match self.mode {
            GatewayMode::ArmedValve => {
                let timeout = timing.command_timeout_ns;
                let stale = (0..VALVES).any(|i| {
                    self.valve_cmd[i] != 0.0
                        && self.valve_cmd_at[i].is_none_or(|t| age_ns(t) > timeout)
                });
                if stale {
                    self.fault(GatewayFaults::STALE_COMMAND);
                } else {
                    out = self.valve_cmd;
                }
            }
            GatewayMode::ArmedPosition => {
                let timeout = timing.command_timeout_ns;
                let fresh = self.setpoint_at.is_some_and(|t| age_ns(t) <= timeout);
                let waiting = self.setpoint_at.is_none() && age_ns(self.armed_at) <= timeout;
                if !fresh && !waiting {
                    self.fault(GatewayFaults::STALE_COMMAND);
                } else if let (Some(sp), Some(q)) = (self.setpoint, measured) {
                    out[..JOINTS].copy_from_slice(&self.position_loop(sp, q, dt_s));
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
        self.dm1.observe(u32::from(self.faults.0));
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

    fn new_session(&mut self) {
        let next = self.nonces.next_after(Some(self.verifier.session()));
        self.verifier.start_session(next);
        self.session_used = false;
        self.last_alive = None;
    }

    /// The session nonce to broadcast (`GatewaySession`, with every status frame).
    pub fn session(&self) -> GatewaySession {
        GatewaySession {
            session_id: self.verifier.session(),
        }
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
    use crate::id::{GATEWAY_ADDRESS, GLOBAL_ADDRESS};
    use crate::messages::{
        Activity, AutodigStageCode, AuxValveCommand, ControllerHeartbeat, ControllerStatus,
        JointAngles, PositionSetpoint, Valve,
    };
    use crate::secoc::{OsNonceSource, Sealer, SeededNonceSource, SessionKey};
    use proptest::prelude::*;
    use std::println;
    use std::string::ToString;
    use std::vec::Vec;

    /// The nonce seed of the tests' gateways (fixed: the tests are reproducible).
    const TEST_SEED: u64 = 0;

    /// The project's gateway with its nonces from [`TEST_SEED`].
    fn test_gateway() -> Gateway {
        Gateway::with_default_config(&mut SeededNonceSource(TEST_SEED))
    }

    /// The controller's heartbeat and command period of these tests, s.
    const PERIOD_S: f64 = crate::dbc::CONTROL_PERIOD.as_secs_f64();

    /// The controller's side of the link: seals its frames in the gateway's current session, as the
    /// controller does after reading `GatewaySession`.
    #[derive(Default)]
    struct Link {
        sealer: Option<Sealer>,
    }

    impl Link {
        fn seal(&mut self, g: &Gateway, message: Message) -> CanFrame {
            let sealer = self
                .sealer
                .get_or_insert_with(|| Sealer::new(&SessionKey::PUBLIC));
            sealer.set_session(g.session().session_id);
            sealer.seal(&message).unwrap()
        }

        fn hb(&mut self, g: &Gateway, mode: RequestedMode, alive: u8) -> CanFrame {
            let hb = ControllerHeartbeat {
                mode,
                alive_counter: alive % 16,
            };
            self.seal(g, Message::ControllerHeartbeat(hb))
        }

        fn valve(&mut self, g: &Gateway, v: Valve, u: f64) -> CanFrame {
            let cmd = AuxValveCommand::from_fraction(v, u).unwrap();
            self.seal(g, Message::AuxValveCommand(cmd))
        }

        fn setpoint(&mut self, g: &Gateway, q: [f64; 4]) -> CanFrame {
            let sp = PositionSetpoint {
                boom_rad: q[0],
                stick_rad: q[1],
                bucket_rad: q[2],
                swing_rad: q[3],
            };
            self.seal(g, Message::PositionSetpoint(sp))
        }
    }

    /// A gateway armed in valve mode at t = 0 with heartbeat counter 0, and its controller link.
    fn armed() -> (Gateway, Link) {
        let mut g = test_gateway();

        let mut l = Link::default();
        assert_eq!(
            g.on_frame(&l.hb(&g, RequestedMode::ArmValve, 0), 0.0),
            FrameVerdict::Accepted
        );
        assert_eq!(g.mode(), GatewayMode::ArmedValve);
        (g, l)
    }

    #[test]
    fn the_config_reasons_state_the_range_rules() {
        use std::string::ToString as _;
        for (limits, rule) in [GAIN_LIMITS, MAX_COMMAND_LIMITS, RATE_LIMIT_LIMITS] {
            assert_eq!(limits.check(f64::NAN).unwrap_err().to_string(), rule);
        }
    }

    #[test]
    fn boots_disarmed_and_ignores_commands() {
        let mut g = test_gateway();
        let mut l = Link::default();
        assert_eq!(
            g.on_frame(&l.valve(&g, Valve::Boom, 0.5), 0.0),
            FrameVerdict::Rejected
        );
        assert_eq!(g.tick(0.0, None).valve_commands, [0.0; VALVES]);
        assert_eq!(g.mode(), GatewayMode::Disarmed);
    }

    #[test]
    fn armed_valve_mode_applies_commands() {
        let (mut g, mut l) = armed();
        g.on_frame(&l.valve(&g, Valve::Stick, -0.25), 0.005);
        let out = g.tick(0.01, None);
        assert!((out.valve_commands[1] + 0.25).abs() < 1e-3);
        assert_eq!(out.status.mode, GatewayMode::ArmedValve);
    }

    #[test]
    fn missing_heartbeat_neutralises_within_100_ms_and_needs_disarm_then_arm() {
        let (mut g, mut l) = armed();
        let mut t = 0.0;
        let mut alive = 0;
        // Heartbeats and commands every 10 ms for 0.5 s.
        while t < 0.5 {
            t += PERIOD_S;
            alive += 1;
            g.on_frame(&l.hb(&g, RequestedMode::ArmValve, alive), t);
            g.on_frame(&l.valve(&g, Valve::Boom, 1.0), t);
            assert_eq!(g.tick(t, None).valve_commands[0], 1.0);
        }
        // Heartbeats stop; commands keep coming.
        let last_hb = t;
        let mut neutral_at = None;
        while t < 1.0 {
            t += 0.001;
            g.on_frame(&l.valve(&g, Valve::Boom, 1.0), t);
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
        g.on_frame(&l.hb(&g, RequestedMode::ArmValve, 3), t);
        g.on_frame(&l.hb(&g, RequestedMode::ArmValve, 4), t + 0.01);
        assert_eq!(g.mode(), GatewayMode::Faulted);
        // Disarm acknowledges, then a fresh arm request re-arms.
        g.on_frame(&l.hb(&g, RequestedMode::Disarm, 5), t + 0.02);
        assert_eq!(g.mode(), GatewayMode::Disarmed);
        assert!(g.faults().is_empty());
        g.on_frame(&l.hb(&g, RequestedMode::ArmValve, 6), t + 0.03);
        assert_eq!(g.mode(), GatewayMode::ArmedValve);
        // The old command does not come back: valves stay neutral until a new one arrives.
        assert_eq!(g.tick(t + 0.035, None).valve_commands, [0.0; VALVES]);
    }

    #[test]
    fn stale_command_faults() {
        let (mut g, mut l) = armed();
        g.on_frame(&l.valve(&g, Valve::Bucket, 0.6), 0.0);
        for k in 1..=9 {
            g.on_frame(&l.hb(&g, RequestedMode::ArmValve, k), 0.01 * f64::from(k));
        }
        assert_eq!(g.tick(0.09, None).valve_commands[2], 0.6);
        let out = g.tick(0.11, None);
        assert_eq!(out.valve_commands, [0.0; VALVES]);
        assert!(out.status.faults.contains(GatewayFaults::STALE_COMMAND));
    }

    #[test]
    fn bad_checksum_faults_and_is_rejected() {
        let (mut g, mut l) = armed();
        let frame = l.hb(&g, RequestedMode::ArmValve, 1);
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
        let (mut g, mut l) = armed();
        let mut prev = g.next_status().alive_counter;
        let mut t = 0.0;
        for frame in 0..600u32 {
            // 100 ticks of 1 ms (a heartbeat every 10 ms) between two status frames.
            for k in 0..100u32 {
                t += 0.001;
                if k % 10 == 0 {
                    g.on_frame(
                        &l.hb(&g, RequestedMode::ArmValve, (frame * 10 + k / 10 + 1) as u8),
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

    /// The controller's frames over 0.5 s of a session: arm, then heartbeats every 50 ms and boom and
    /// stick commands every 10 ms, each with its time; the gateway ticks every 1 ms. Returns the
    /// recording and the time of its last frame.
    fn record_session(g: &mut Gateway, l: &mut Link, t0_s: f64) -> (Vec<(f64, CanFrame)>, f64) {
        let mut recording = Vec::new();
        let mut t = t0_s;
        for k in 0..500u32 {
            t = t0_s + f64::from(k) * 0.001;
            if k % 50 == 0 {
                let frame = l.hb(g, RequestedMode::ArmValve, (k / 50) as u8);
                recording.push((t, frame));
                g.on_frame(&frame, t);
            }
            if k % 10 == 0 {
                for (v, u) in [(Valve::Boom, 1.0), (Valve::Stick, -0.8)] {
                    let frame = l.valve(g, v, u);
                    recording.push((t, frame));
                    g.on_frame(&frame, t);
                }
            }
            g.tick(t, None);
        }
        assert_eq!(
            g.mode(),
            GatewayMode::ArmedValve,
            "the recorded session drove"
        );
        (recording, t)
    }

    /// Plays `recording` into `g` from `start_s` with its original spacing, ticking every 1 ms, and
    /// returns the largest valve output seen and whether the gateway was ever armed.
    fn replay(g: &mut Gateway, recording: &[(f64, CanFrame)], start_s: f64) -> (f64, bool) {
        let t0 = recording.first().map_or(0.0, |(t, _)| *t);
        let (mut peak, mut armed) = (0.0_f64, false);
        let mut next = 0;
        for k in 0..1000u32 {
            let t = start_s + f64::from(k) * 0.001;
            while let Some((at, frame)) = recording.get(next) {
                if start_s + (at - t0) > t {
                    break;
                }
                g.on_frame(frame, t);
                next += 1;
            }
            let out = g.tick(t, None);
            peak = out.valve_commands.iter().fold(peak, |m, u| m.max(u.abs()));
            armed |= g.is_armed();
        }
        (peak, armed)
    }

    /// Regression: with the controller dead, `trace replay` of the controller's ids from an earlier
    /// session armed the gateway within 0.46 s and moved all joints; after the watchdog fault any
    /// valid `Disarm` cleared it and `ArmValve` re-armed.
    #[test]
    fn a_replayed_controller_trace_neither_arms_nor_drives() {
        let mut g = test_gateway().with_security(&SessionKey::PUBLIC, 1);
        let mut l = Link::default();
        let (recording, end) = record_session(&mut g, &mut l, 0.0);
        // The controller dies; the watchdog faults and ends the session.
        for k in 1..=200u32 {
            g.tick(end + f64::from(k) * 0.001, None);
        }
        assert_eq!(g.mode(), GatewayMode::Faulted);
        let (peak, armed) = replay(&mut g, &recording, end + 0.3);
        assert_eq!((peak, armed), (0.0, false), "the replay moved the machine");
        assert_eq!(
            g.mode(),
            GatewayMode::Faulted,
            "a replayed Disarm cleared the fault"
        );
        // A gateway after a power cycle (a new seed: a new session) does not take it either.
        let mut rebooted = test_gateway().with_security(&SessionKey::PUBLIC, 2);
        let (peak, armed) = replay(&mut rebooted, &recording, 0.0);
        assert_eq!((peak, armed), (0.0, false));
        assert!(rebooted.frame_counts().1 > 0, "the replay is counted");
    }

    /// Regression: `Gateway::default()` and `Gateway::new` started every gateway at the same session
    /// nonce, so every power-up repeated the sessions of the last. On the product path the nonce
    /// comes from the platform's source (here the host's OS random source).
    #[test]
    fn two_gateways_on_the_product_path_start_different_sessions() {
        let a = Gateway::new(GatewayConfig::default(), &mut OsNonceSource).unwrap();
        let b = Gateway::new(GatewayConfig::default(), &mut OsNonceSource).unwrap();
        assert_ne!(a.session(), b.session());
        let c = Gateway::with_default_config(&mut OsNonceSource);
        assert_ne!(a.session(), c.session());
        // A seeded source is reproducible, which is what the demo needs and a machine must not use.
        assert_eq!(
            Gateway::with_default_config(&mut SeededNonceSource(7)).session(),
            Gateway::with_default_config(&mut SeededNonceSource(7)).session()
        );
    }

    /// Regression: a demo trace (its nonces drawn from the demo's public seed) replayed verbatim onto
    /// a fresh gateway armed and drove it, because both started at the same nonce. Even with the
    /// demo's key, a product gateway (its nonce from the OS) takes none of it.
    #[test]
    fn a_demo_trace_replayed_onto_a_fresh_product_gateway_does_not_arm_it() {
        /// The demo's seed: public (in its summary and docs).
        const DEMO_SEED: u64 = 1;
        let key = SessionKey::from_hex("2b7e151628aed2a6abf7158809cf4f3c").unwrap();
        let mut demo = Gateway::with_default_config(&mut SeededNonceSource(DEMO_SEED))
            .with_security(&key, DEMO_SEED);
        let mut l = Link {
            sealer: Some(Sealer::new(&key)),
        };
        let (recording, _) = record_session(&mut demo, &mut l, 0.0);
        let mut product = Gateway::with_default_config(&mut OsNonceSource)
            .with_security(&key, OsNonceSource.session_seed());
        let (peak, armed) = replay(&mut product, &recording, 0.0);
        assert_eq!(
            (peak, armed),
            (0.0, false),
            "the demo trace moved the machine"
        );
        assert!(product.frame_counts().1 > 0, "the replay is counted");
        // The same replay onto a gateway seeded as the demo's arms: what the nonce source prevents.
        let mut same = Gateway::with_default_config(&mut SeededNonceSource(DEMO_SEED))
            .with_security(&key, DEMO_SEED);
        assert!(replay(&mut same, &recording, 0.0).1);
    }

    /// Regression: sixteen recorded heartbeats replayed in order passed the 4-bit alive counter
    /// forever; after the controller was killed they and each valve's last command kept the valves
    /// driven.
    #[test]
    fn replayed_heartbeats_do_not_keep_the_valves_driven() {
        let mut g = test_gateway();
        let mut l = Link::default();
        let (recording, end) = record_session(&mut g, &mut l, 0.0);
        let pgn = |f: &CanFrame| Message::decode(f).map(|d| d.id.pgn()).unwrap_or(0);
        let heartbeats: Vec<CanFrame> = recording
            .iter()
            .map(|(_, f)| *f)
            .filter(|f| pgn(f) == crate::dbc::controller_heartbeat::PGN)
            .collect();
        let last_commands: Vec<CanFrame> =
            recording.iter().rev().take(2).map(|(_, f)| *f).collect();
        // Killed at `end`: the attacker plays the heartbeats cyclically at 50 ms and the last commands
        // at 10 ms, for 5 s.
        let mut driven_until = end;
        for k in 1..=5000u32 {
            let t = end + f64::from(k) * 0.001;
            if k % 50 == 0 {
                let hb = heartbeats[(k as usize / 50) % heartbeats.len()];
                g.on_frame(&hb, t);
            }
            if k % 10 == 0 {
                for f in &last_commands {
                    g.on_frame(f, t);
                }
            }
            if g.tick(t, None).valve_commands != [0.0; VALVES] {
                driven_until = t;
            }
        }
        assert!(
            driven_until - end <= 0.1 + 1e-9,
            "driven {:.3} s after the kill",
            driven_until - end
        );
        assert_eq!(g.mode(), GatewayMode::Faulted);
    }

    /// Regression: a command spoofed from the controller's own address was applied for one control
    /// period before the controller noticed. A second sender with the controller's address (its own
    /// counters) is never applied, and with a provisioned key not even one that copies the
    /// controller's counters is.
    #[test]
    fn a_spoofed_command_from_the_controllers_address_is_never_applied() {
        let (mut g, mut l) = armed();
        let mut spoofer = Link::default();
        g.on_frame(&l.valve(&g, Valve::Boom, 0.2), 0.001);
        assert_eq!(
            g.on_frame(&spoofer.valve(&g, Valve::Boom, 1.0), 0.002),
            FrameVerdict::Rejected
        );
        let out = g.tick(0.003, None);
        assert_eq!(out.valve_commands, [0.0; VALVES], "spoofed once: neutral");
        assert!(out.status.faults.contains(GatewayFaults::AUTH_FAILURE));

        let key = SessionKey::from_hex("2b7e151628aed2a6abf7158809cf4f3c").unwrap();
        let mut g = test_gateway().with_security(&key, 9);
        let mut owner = Sealer::new(&key);
        owner.set_session(g.session().session_id);
        let hb = |mode| {
            Message::ControllerHeartbeat(ControllerHeartbeat {
                mode,
                alive_counter: 0,
            })
        };
        assert_eq!(
            g.on_frame(&owner.seal(&hb(RequestedMode::ArmValve)).unwrap(), 0.0),
            FrameVerdict::Accepted
        );
        // The spoofer reads the session and follows the counters, but has no key.
        let mut spoofer = Sealer::new(&SessionKey::PUBLIC);
        spoofer.set_session(g.session().session_id);
        spoofer.seal(&hb(RequestedMode::ArmValve)).unwrap();
        let boom =
            Message::AuxValveCommand(AuxValveCommand::from_fraction(Valve::Boom, 1.0).unwrap());
        assert_eq!(
            g.on_frame(&spoofer.seal(&boom).unwrap(), 0.001),
            FrameVerdict::Rejected
        );
        assert_eq!(g.tick(0.002, None).valve_commands, [0.0; VALVES]);
        // Nor can a node without the key arm a disarmed gateway.
        let mut g = test_gateway().with_security(&key, 10);
        let mut stranger = Sealer::new(&SessionKey::PUBLIC);
        stranger.set_session(g.session().session_id);
        for k in 0..100u32 {
            let frame = stranger.seal(&hb(RequestedMode::ArmValve)).unwrap();
            g.on_frame(&frame, f64::from(k) * 0.01);
        }
        assert_eq!(g.mode(), GatewayMode::Disarmed);
    }

    #[test]
    fn a_new_controller_gets_a_new_session_after_the_old_one_falls_silent() {
        let (mut g, mut l) = armed();
        let first = g.session();
        g.on_frame(&l.hb(&g, RequestedMode::Disarm, 1), 0.01);
        for k in 1..=150u32 {
            g.tick(0.01 + f64::from(k) * 0.001, None);
        }
        assert_ne!(g.session(), first, "silence ends the session");
        // A restarted controller (new counters) in the new session arms.
        let mut restarted = Link::default();
        g.on_frame(&restarted.hb(&g, RequestedMode::ArmValve, 9), 0.2);
        assert_eq!(g.mode(), GatewayMode::ArmedValve);
        // An unused session does not expire on its own.
        let session = g.session();
        let mut idle = test_gateway();
        let before = idle.session();
        for k in 0..1000u32 {
            idle.tick(f64::from(k) * 0.001, None);
        }
        assert_eq!(idle.session(), before);
        assert_ne!(session, before);
    }

    #[test]
    fn skipped_alive_counter_faults_and_replay_is_rejected_only() {
        let (mut g, mut l) = armed();
        assert_eq!(
            g.on_frame(&l.hb(&g, RequestedMode::ArmValve, 0), 0.005),
            FrameVerdict::Rejected
        );
        assert_eq!(
            g.mode(),
            GatewayMode::ArmedValve,
            "a replay is ignored, not a fault"
        );
        assert_eq!(
            g.on_frame(&l.hb(&g, RequestedMode::ArmValve, 2), 0.01),
            FrameVerdict::Rejected
        );
        assert!(g.faults().contains(GatewayFaults::BAD_ALIVE_COUNTER));
    }

    #[test]
    fn an_e_stop_is_reported_in_dm1_at_once_with_the_red_stop_lamp() {
        use crate::dm1::GATEWAY_DTCS;
        use crate::messages::LampStatus;
        let mut g = test_gateway();
        let mut l = Link::default();
        g.tick(0.0, None);
        let first = g.dm1_due().expect("the first DM1 at the first tick");
        assert_eq!(first.dtc, crate::messages::Dtc::NONE);
        g.tick(0.05, None);
        assert!(g.dm1_due().is_none(), "nothing changed: a second later");
        g.on_frame(&l.hb(&g, RequestedMode::EStop, 0), 0.2);
        g.tick(0.2, None);
        let dm1 = g.dm1_due().expect("a change goes out at once");
        assert_eq!(dm1.dtc.spn, GATEWAY_DTCS[4].spn);
        assert_eq!(GATEWAY_DTCS[4].name, "EStop");
        assert_eq!(dm1.dtc.occurrence_count, 1);
        assert_eq!(dm1.lamps.red_stop.status, LampStatus::On);
        // Frames are `Some` only once the claim stands.
        let mut fresh = test_gateway();
        fresh.tick(0.0, None);
        assert_eq!(
            fresh.may_transmit(),
            fresh.dm1_frame::<CanFrame>().unwrap().is_some()
        );
    }

    #[test]
    fn e_stop_latches_in_any_mode() {
        let mut g = test_gateway();
        let mut l = Link::default();
        g.on_frame(&l.hb(&g, RequestedMode::EStop, 0), 0.0);
        assert_eq!(g.mode(), GatewayMode::Faulted);
        assert!(g.faults().contains(GatewayFaults::E_STOP));
    }

    /// Regression (#23 finding 5): one valid `Disarm` cleared the e-stop, and e-stop, Disarm, ArmValve,
    /// boom 100 % moved the boom 1 ms after the e-stop.
    #[test]
    fn e_stop_is_not_cleared_by_disarm_only_by_a_reset_then_disarm_then_arm() {
        let (mut g, mut l) = armed();
        g.on_frame(&l.valve(&g, Valve::Boom, 0.5), 0.001);
        g.on_frame(&l.hb(&g, RequestedMode::EStop, 1), 0.002);
        g.on_frame(&l.hb(&g, RequestedMode::Disarm, 2), 0.0025);
        g.on_frame(&l.hb(&g, RequestedMode::ArmValve, 3), 0.0026);
        g.on_frame(&l.valve(&g, Valve::Boom, 1.0), 0.0027);
        let out = g.tick(0.003, None);
        assert_eq!(
            out.valve_commands, [0.0; VALVES],
            "the boom moved after the e-stop"
        );
        assert_eq!(g.mode(), GatewayMode::Faulted);
        assert!(g.faults().contains(GatewayFaults::E_STOP));
        // The reset clears the e-stop but not the Faulted mode: arm requests still do nothing.
        g.on_frame(&l.hb(&g, RequestedMode::ResetEStop, 4), 0.01);
        assert!(!g.faults().contains(GatewayFaults::E_STOP));
        assert_eq!(g.mode(), GatewayMode::Faulted);
        g.on_frame(&l.hb(&g, RequestedMode::ArmValve, 5), 0.02);
        g.on_frame(&l.valve(&g, Valve::Boom, 1.0), 0.02);
        assert_eq!(g.tick(0.021, None).valve_commands, [0.0; VALVES]);
        assert_eq!(g.mode(), GatewayMode::Faulted);
        // Disarm acknowledges, then an arm request arms.
        g.on_frame(&l.hb(&g, RequestedMode::Disarm, 6), 0.03);
        assert_eq!(g.mode(), GatewayMode::Disarmed);
        assert!(g.faults().is_empty());
        g.on_frame(&l.hb(&g, RequestedMode::ArmValve, 7), 0.04);
        g.on_frame(&l.valve(&g, Valve::Boom, 1.0), 0.04);
        assert_eq!(g.tick(0.041, None).valve_commands[0], 1.0);
    }

    #[test]
    fn reset_request_without_an_e_stop_never_arms() {
        let (mut g, mut l) = armed();
        g.on_frame(&l.valve(&g, Valve::Boom, 1.0), 0.001);
        g.on_frame(&l.hb(&g, RequestedMode::ResetEStop, 1), 0.002);
        assert_eq!(g.mode(), GatewayMode::Disarmed);
        assert_eq!(g.tick(0.003, None).valve_commands, [0.0; VALVES]);
        g.on_frame(&l.hb(&g, RequestedMode::ResetEStop, 2), 0.01);
        assert_eq!(g.mode(), GatewayMode::Disarmed);
    }

    /// Drives the boom at 100 % with heartbeats and commands every 10 ms and 1 ms ticks from `t0_s` for
    /// 0.2 s; returns the time of the last tick.
    fn drive_boom(g: &mut Gateway, l: &mut Link, t0_s: f64, alive: &mut u8) -> f64 {
        let mut t = t0_s;
        for k in 0..200 {
            t = t0_s + f64::from(k) * 0.001;
            if k % 10 == 0 {
                *alive = alive.wrapping_add(1);
                g.on_frame(&l.hb(g, RequestedMode::ArmValve, *alive), t);
                g.on_frame(&l.valve(g, Valve::Boom, 1.0), t);
            }
            g.tick(t, None);
        }
        t
    }

    /// #23 finding 4: with the clock stepped back, the heartbeat and the commands looked 10 s younger
    /// than they were, so a controller that died just then kept the boom driven for 10 s.
    #[test]
    fn clock_stepped_back_10_s_does_not_keep_valves_driven() {
        let mut g = test_gateway();
        let mut l = Link::default();
        let mut alive = 0;
        g.on_frame(&l.hb(&g, RequestedMode::ArmValve, alive), 100.0);
        let t = drive_boom(&mut g, &mut l, 100.0, &mut alive);
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
        g.on_frame(&l.hb(&g, RequestedMode::ArmValve, alive), t);
        g.on_frame(&l.valve(&g, Valve::Boom, 1.0), t);
        assert_eq!(
            g.tick(t, None).valve_commands,
            [0.0; VALVES],
            "still Faulted"
        );
        alive += 1;
        g.on_frame(&l.hb(&g, RequestedMode::Disarm, alive), t + 0.01);
        assert_eq!(g.mode(), GatewayMode::Disarmed);
        assert!(g.faults().is_empty());
        let t = drive_boom(&mut g, &mut l, t + 0.02, &mut alive);
        assert_eq!(g.tick(t, None).valve_commands[0], 1.0);
    }

    #[test]
    fn a_command_stamped_nan_does_not_drive_the_boom() {
        let (mut g, mut l) = armed();
        assert_eq!(
            g.on_frame(&l.valve(&g, Valve::Boom, 1.0), f64::NAN),
            FrameVerdict::Rejected
        );
        assert!(g.faults().contains(GatewayFaults::CLOCK_FAULT));
        // Heartbeats and ticks go on with good times: the boom stays put until Disarm, Arm.
        for k in 1..=20u8 {
            let t = f64::from(k) * 0.005;
            g.on_frame(&l.hb(&g, RequestedMode::ArmValve, k), t);
            assert_eq!(g.tick(t, None).valve_commands, [0.0; VALVES]);
        }
        // A frame from before the latest time is a clock fault too, as is a NaN tick.
        let (mut g, mut l) = armed();
        g.tick(0.01, None);
        assert_eq!(
            g.on_frame(&l.valve(&g, Valve::Boom, 1.0), 0.009),
            FrameVerdict::Rejected
        );
        assert!(g.faults().contains(GatewayFaults::CLOCK_FAULT));
        let (mut g, mut l) = armed();
        g.on_frame(&l.valve(&g, Valve::Boom, 1.0), 0.001);
        assert_eq!(g.tick(0.002, None).valve_commands[0], 1.0);
        let out = g.tick(f64::NAN, None);
        assert_eq!(out.valve_commands, [0.0; VALVES]);
        assert!(out.status.faults.contains(GatewayFaults::CLOCK_FAULT));
        // Equal times are fine.
        let (mut g, mut l) = armed();
        g.on_frame(&l.valve(&g, Valve::Boom, 1.0), 0.0);
        assert_eq!(g.tick(0.0, None).valve_commands[0], 1.0);
        assert!(g.faults().is_empty());
    }

    #[test]
    fn frame_counters_saturate_and_say_so() {
        let mut g = test_gateway();

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
            let e = Gateway::new(config, &mut SeededNonceSource(TEST_SEED)).unwrap_err();
            assert!(!e.to_string().is_empty());
        }
    }

    #[test]
    fn foreign_source_address_and_unknown_frames_are_counted_not_acted_on() {
        let (mut g, mut l) = armed();
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
        let good = l.valve(&g, Valve::Boom, 1.0);
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
        let (mut g, _) = armed();
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
        let (mut g, mut l) = armed();
        g.on_frame(&l.hb(&g, RequestedMode::Disarm, 1), 0.01);
        assert_eq!(g.mode(), GatewayMode::Disarmed);
        for v in Valve::ALL {
            assert_eq!(
                g.on_frame(&l.valve(&g, v, 0.0), 0.02),
                FrameVerdict::Ignored
            );
        }
        assert_eq!(
            g.on_frame(&l.valve(&g, Valve::Boom, 0.3), 0.02),
            FrameVerdict::Rejected,
            "motion while disarmed is wrong"
        );
        // The same in position mode: neutral ignored, motion rejected, and nothing moves the valve.
        g.on_frame(&l.hb(&g, RequestedMode::ArmPosition, 2), 0.03);
        assert_eq!(g.mode(), GatewayMode::ArmedPosition);
        assert_eq!(
            g.on_frame(&l.valve(&g, Valve::Stick, 0.0), 0.031),
            FrameVerdict::Ignored
        );
        assert_eq!(
            g.on_frame(&l.valve(&g, Valve::Stick, -1.0), 0.032),
            FrameVerdict::Rejected
        );
        assert_eq!(g.tick(0.033, None).valve_commands, [0.0; VALVES]);
        assert_eq!(g.frame_counts(), (0, 2));
        assert_eq!(g.ignored_frames(), 7);
    }

    #[test]
    fn position_mode_drives_toward_the_setpoint_with_rate_limit() {
        let mut g = test_gateway();
        let mut l = Link::default();
        g.on_frame(&l.hb(&g, RequestedMode::ArmPosition, 0), 0.0);
        assert_eq!(g.mode(), GatewayMode::ArmedPosition);
        g.on_frame(&l.setpoint(&g, [0.5, -1.0, -1.0, 0.0]), 0.0);
        let q = [0.0, -1.5, -0.5, 0.0];
        let first = g.tick(0.0, Some(q)).valve_commands;
        assert_eq!(first, [0.0; VALVES], "rate limited from zero");
        g.on_frame(&l.hb(&g, RequestedMode::ArmPosition, 1), 0.01);
        let second = l.setpoint(&g, [0.5, -1.0, -1.0, 0.0]);
        g.on_frame(&second, 0.01);
        let out = g.tick(0.01, Some(q)).valve_commands;
        assert!((out[0] - 0.05).abs() < 1e-9, "boom up: extend, {out:?}");
        assert!(out[1] < 0.0, "stick angle must rise: retract, {out:?}");
        assert!(out[2] > 0.0, "bucket angle must fall: extend, {out:?}");
        assert_eq!(out[3], 0.0);
        // The same frame again: a replay, rejected (and a fault: armed).
        assert_eq!(g.on_frame(&second, 0.015), FrameVerdict::Rejected);
        assert!(g.faults().contains(GatewayFaults::AUTH_FAILURE));
    }

    #[test]
    fn position_mode_faults_on_stale_or_out_of_range_setpoints() {
        let mut g = test_gateway();
        let mut l = Link::default();
        g.on_frame(&l.hb(&g, RequestedMode::ArmPosition, 0), 0.0);
        g.on_frame(&l.hb(&g, RequestedMode::ArmPosition, 1), 0.09);
        g.tick(0.09, Some([0.0; 4]));
        assert_eq!(
            g.mode(),
            GatewayMode::ArmedPosition,
            "grace period after arming"
        );
        g.tick(0.11, Some([0.0; 4]));
        assert!(g.faults().contains(GatewayFaults::STALE_COMMAND));
        let mut g = test_gateway();
        let mut l = Link::default();
        g.on_frame(&l.hb(&g, RequestedMode::ArmPosition, 0), 0.0);
        g.on_frame(&l.setpoint(&g, [0.0, -1.0, -1.0, 0.0]), 0.0);
        // On the wire (boom to +-1.638 rad) but past the gateway's boom range (+-1.6 rad).
        g.on_frame(&l.setpoint(&g, [1.62, -1.0, -1.0, 0.0]), 0.0);
        assert!(g.faults().contains(GatewayFaults::SETPOINT_OUT_OF_RANGE));
    }

    /// Heartbeat period of the phase sweep (the tightest the controller may use), s.
    const SWEEP_HEARTBEAT_PERIOD_S: f64 = crate::dbc::CONTROL_PERIOD.as_secs_f64();
    /// The gateway's tick period in the simulator and on the reference gateway, s.
    const SWEEP_TICK_S: f64 = 0.001;

    /// Runs a gateway ticking every `SWEEP_TICK_S` from t = 0 with heartbeats (and a fresh boom command)
    /// every `SWEEP_HEARTBEAT_PERIOD_S` from `phase_s`, the last one number `last`; boom commands go on
    /// after it. Returns the last heartbeat's time and the time of the first tick with neutral output.
    fn first_neutral_after_last_heartbeat(phase_s: f64, last: u32) -> (f64, f64) {
        let mut g = test_gateway();
        let mut l = Link::default();
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
                    g.on_frame(&l.hb(&g, mode, (n % 16) as u8), at);
                }
                g.on_frame(&l.valve(&g, Valve::Boom, 1.0), at);
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
            let mut g = test_gateway();

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

    fn claim(source: u8, name: Name) -> CanFrame {
        Message::AddressClaimed(crate::messages::AddressClaimed { name })
            .encode_from(source)
            .unwrap()
    }

    #[test]
    fn the_gateway_claims_its_address_and_reports_only_after_250_ms() {
        let mut g = test_gateway();
        assert!(g.take_claim_frame().is_none());
        g.tick(0.0, None);
        let frame = g.take_claim_frame().unwrap();
        assert_eq!(frame.id().raw(), 0x18EE_FF80);
        assert_eq!(
            frame.data(),
            &crate::address_claim::GATEWAY_NAME.to_le_bytes()
        );
        g.tick(0.249, None);
        assert!(!g.may_transmit());
        g.tick(0.25, None);
        assert!(g.may_transmit());
        assert!(g.take_claim_frame().is_none());
    }

    #[test]
    fn losing_the_address_neutralises_latches_and_silences_the_gateway() {
        let (mut g, mut l) = armed();
        g.tick(0.0, None);
        g.take_claim_frame();
        g.on_frame(&l.valve(&g, Valve::Boom, 0.5), 0.005);
        assert_eq!(g.tick(0.01, None).valve_commands[0], 0.5);
        // A late claimant with a lower NAME takes 0x80 while the gateway drives the boom.
        let winner = Name::from_raw(crate::address_claim::GATEWAY_NAME.raw() - 1);
        assert_eq!(
            g.on_frame(&claim(GATEWAY_ADDRESS, winner), 0.012),
            FrameVerdict::Accepted
        );
        let cannot = g.take_claim_frame().unwrap();
        assert_eq!(cannot.id().raw(), 0x18EE_FFFE);
        let out = g.tick(0.013, None);
        assert_eq!(out.valve_commands, [0.0; VALVES]);
        assert_eq!(g.mode(), GatewayMode::Faulted);
        assert!(g.faults().contains(GatewayFaults::ADDRESS_LOST));
        // Silent, and the controller's disarm and re-arm are not acted on.
        g.tick(0.5, None);
        assert!(!g.may_transmit());
        assert!(g.status_frames::<CanFrame>().unwrap().is_none());
        for (i, mode) in [RequestedMode::Disarm, RequestedMode::ArmValve]
            .into_iter()
            .enumerate()
        {
            let t = 0.51 + i as f64 * 0.01;
            assert_eq!(
                g.on_frame(&l.hb(&g, mode, 1 + i as u8), t),
                FrameVerdict::Ignored
            );
            assert_eq!(g.tick(t, None).valve_commands, [0.0; VALVES]);
        }
        assert_eq!(g.mode(), GatewayMode::Faulted);
    }

    #[test]
    fn a_claim_hold_margin_survives_a_name_change() {
        use crate::address_claim::{AddressClaimer, CLAIM_HOLD_NS};
        let other = AddressClaimer::controller().name();
        for g in [
            test_gateway()
                .with_claim_hold_margin(40_000_000)
                .with_name(other),
            test_gateway()
                .with_name(other)
                .with_claim_hold_margin(40_000_000),
        ] {
            assert_eq!(g.address_claim().hold_ns(), CLAIM_HOLD_NS + 40_000_000);
            assert_eq!(g.address_claim().name(), other);
        }
    }

    #[test]
    fn after_a_lost_address_a_global_request_reclaims_it_and_the_gateway_stays_disarmed() {
        let (mut g, mut l) = armed();
        g.tick(0.0, None);
        g.take_claim_frame();
        g.tick(0.3, None);
        let transient = Name::from_raw(0);
        g.on_frame(&claim(GATEWAY_ADDRESS, transient), 0.31);
        g.take_claim_frame();
        g.tick(1.0, None);
        // Addressed to 0x80, the request is for whoever holds it now.
        let to_gateway =
            crate::address_claim::request_address_claimed(GATEWAY_ADDRESS, CONTROLLER_ADDRESS)
                .unwrap();
        assert_eq!(g.on_frame(&to_gateway, 1.0), FrameVerdict::Ignored);
        assert!(g.take_claim_frame().is_none());
        // The controller's request to global after the operator's reset: the gateway claims again.
        let request =
            crate::address_claim::request_address_claimed(GLOBAL_ADDRESS, CONTROLLER_ADDRESS)
                .unwrap();
        assert_eq!(g.on_frame(&request, 1.0), FrameVerdict::Accepted);
        assert_eq!(g.take_claim_frame().unwrap().id().raw(), 0x18EE_FF80);
        assert!(g.address_claim().lost().is_none());
        // For 250 ms: silent, and the controller's requests are not acted on.
        let mut counter = 1;
        let mut hb = |g: &Gateway, mode| {
            counter += 1;
            l.hb(g, mode, counter)
        };
        for t in [1.05, 1.1, 1.2, 1.249] {
            assert_eq!(
                g.on_frame(&hb(&g, RequestedMode::Disarm), t),
                FrameVerdict::Ignored
            );
            assert_eq!(g.tick(t, None).valve_commands, [0.0; VALVES]);
            assert!(!g.may_transmit());
            assert!(g.status_frames::<CanFrame>().unwrap().is_none());
        }
        g.tick(1.25, None);
        assert!(g.may_transmit());
        assert_eq!(g.mode(), GatewayMode::Faulted);
        assert!(g.faults().contains(GatewayFaults::ADDRESS_LOST));
        // Never armed by itself: the controller's Disarm acknowledges, then its arm request arms.
        g.on_frame(&hb(&g, RequestedMode::Disarm), 1.26);
        g.tick(1.27, None);
        assert_eq!(g.mode(), GatewayMode::Disarmed);
        assert!(g.faults().is_empty());
        g.on_frame(&hb(&g, RequestedMode::Disarm), 1.3);
        assert_eq!(g.tick(1.31, None).valve_commands, [0.0; VALVES]);
        assert_eq!(g.mode(), GatewayMode::Disarmed);
        g.on_frame(&hb(&g, RequestedMode::ArmValve), 1.32);
        assert_eq!(g.mode(), GatewayMode::ArmedValve);
    }

    #[test]
    fn a_competitor_with_a_higher_name_is_answered_and_the_gateway_keeps_going() {
        let mut g = test_gateway();
        let mut l = Link::default();
        g.tick(0.0, None);
        g.take_claim_frame();
        g.tick(0.3, None);
        assert!(g.may_transmit());
        let loser = Name::from_raw(crate::address_claim::GATEWAY_NAME.raw() + 1);
        g.on_frame(&l.hb(&g, RequestedMode::ArmValve, 1), 0.301);
        assert_eq!(g.mode(), GatewayMode::ArmedValve);
        assert_eq!(
            g.on_frame(&claim(GATEWAY_ADDRESS, loser), 0.302),
            FrameVerdict::Accepted
        );
        assert_eq!(g.take_claim_frame().unwrap().id().raw(), 0x18EE_FF80);
        assert!(g.may_transmit());
        g.on_frame(&l.valve(&g, Valve::Boom, 0.5), 0.303);
        assert_eq!(g.tick(0.304, None).valve_commands[0], 0.5);
        assert!(g.faults().is_empty());
    }

    #[test]
    fn a_request_for_address_claimed_gets_the_claim_and_other_claims_are_ignored() {
        let mut g = test_gateway();
        g.tick(0.0, None);
        g.take_claim_frame();
        let request = crate::address_claim::request_address_claimed(GATEWAY_ADDRESS, 0x99).unwrap();
        assert_eq!(g.on_frame(&request, 0.1), FrameVerdict::Accepted);
        assert_eq!(g.take_claim_frame().unwrap().id().raw(), 0x18EE_FF80);
        // The controller's claim and a stranger's: normal traffic, neither unexpected nor rejected.
        for source in [CONTROLLER_ADDRESS, 0x99] {
            let frame = claim(source, Name::from_raw(0));
            assert_eq!(g.on_frame(&frame, 0.2), FrameVerdict::Ignored);
        }
        assert_eq!(g.frame_counts(), (0, 0));
        g.tick(0.25, None);
        assert!(g.may_transmit());
    }
}
