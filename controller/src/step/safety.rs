//! The safety layer: a pure state machine between the work cycle and the bus.
//!
//! It owns the arming handshake with the gateway (`firmware_bridge::gateway`), the heartbeat, and every
//! rule that stops motion. It does no I/O and reads no clock: the node reports events
//! ([`Safety::report`]), lets it check the estimate ([`Safety::observe`]) and asks once per control
//! period what to do ([`Safety::tick`]).
//!
//! # States
//!
//! ```text
//!             want arm, healthy,             GatewayStatus
//!             gateway Disarmed               confirms the mode
//! Disarmed ---------------------> Arming(m) -----------------> Armed(m)
//!    ^                               |                           |
//!    |  cause clear for clear_hold_s |  any fault                | any fault
//!    +------------ Faulted <---------+---------------------------+
//! ListenOnly: decodes and logs, never transmits.  Shutdown: terminal.
//! ```
//!
//! # Rules (each one ends in neutral valves and a logged reason)
//!
//! - Stale or missing sensor data: a control signal (angles, rates, the three cylinder pressures) older
//!   than [`SafetyConfig::sensor_max_age_s`] (3 control periods by default), or the gateway status older
//!   than [`SafetyConfig::status_max_age_s`], while arming or armed.
//! - A frozen gateway: status frames keep coming but their alive counter has not changed for
//!   [`SafetyConfig::status_max_age_s`] (7 status periods at 20 Hz): a repeated status is not a new
//!   one, so a gateway whose firmware hangs while its CAN controller repeats the last frame is caught.
//! - A decode error of a frame of the protocol, any frame from the gateway's address that the gateway
//!   does not send, or a frame of the protocol from another address (the node reports these).
//! - A joint beyond its limit by more than [`SafetyConfig::joint_limit_margin_rad`]. The node passes
//!   the wider of the machine file's software limits and the cylinder's stroke-limited range, because
//!   Autodig ends stages at the stroke ends; a reading beyond the stroke is a sensor fault.
//! - An e-stop request ([`Safety::request_estop`]): latched, the heartbeat requests `EStop` until
//!   [`Safety::reset`]. The gateway latches its own `E_STOP`, which only a `ResetEStop` request clears:
//!   after the operator's reset the heartbeat requests `ResetEStop` until a gateway status received
//!   after it shows `E_STOP` cleared, then `Disarm` (the gateway's acknowledgement), then the usual
//!   arming handshake.
//! - A gateway that reports a fault or leaves the armed mode on its own; an arm request the gateway does
//!   not confirm within [`SafetyConfig::arm_timeout_s`].
//! - CAN error frames: bus-off, error passive, no-ack, transmit timeout, controller overflow, protocol and
//!   transceiver errors (warnings and lost arbitration are only logged).
//! - Errors of the work cycle (Autodig, cleanup, kinematics, timeouts), and shutdown.
//!
//! On a fault the state becomes `Faulted`: every period the node sends neutral valve commands for all
//! six valves (at least for [`SafetyConfig::neutral_hold_s`] and as long as the gateway still reports an
//! armed mode) followed by a `Disarm` heartbeat, which also acknowledges a gateway fault. Motion resumes
//! only through a fresh arming handshake, once the cause has cleared: sensors fresh, gateway status fresh
//! and `Disarmed` without fault bits, joints inside their limits, and no new fault event for
//! [`SafetyConfig::clear_hold_s`].
//!
//! # Stops that stay stopped
//!
//! A fault that stopped motion (raised while arming or armed) is not followed by a restart the
//! operator did not ask for (ISO 13849-1, start/restart function): once its cause has cleared the layer waits for the
//! operator's [`Safety::acknowledge`] (`resume`) or [`Safety::reset`] ([`Safety::needs_reset`]
//! says so). An e-stop and the latching faults ([`Fault::latches`]) take a reset; a resume does not
//! clear them. Two exceptions re-arm on their own, at most [`SafetyConfig::max_auto_rearms`] times
//! without [`SafetyConfig::rearm_reset_s`] of clean armed time ([`Fault::recovery`]):
//! - a fault of the work cycle ([`Fault::Control`]): the cycle's own controlled stop, its action
//!   abandoned (the bucket raised and emptied) and the next one planned, as the cycle does after a
//!   completed action;
//! - opt-in, for simulation only ([`SafetyConfig::auto_rearm`], off by default, logged at `WARN`
//!   when the layer starts and at each re-arm): the transient faults of a simulator on a loaded host
//!   ([`Fault::transient`]: stale sensor data, a decode error, an unexpected frame, a CAN bus
//!   fault); never after an e-stop, a joint limit or a gateway fault.
//!
//! A fault raised while disarmed stopped nothing: it holds off arming until its cause clears.

use firmware_bridge::messages::{
    ControllerHeartbeat, DecodeError, GatewayFaults, GatewayMode, RequestedMode,
};
use firmware_bridge::profile::GatewayTiming;
use firmware_bridge::transport::BusFault;
use planner::autodig::AutodigError;
use planner::cleanup::CleanupError;
use planner::kinematics::Joint;
use serde::{Deserialize, Serialize};

use crate::ControllerError;
use crate::check::{Limits, ParamError, check, check_count};
use crate::step::estimate::{Estimator, Signal, joint_angle};
use crate::step::log_throttle::LogThrottle;
use crate::step::plausibility::{Implausible, JointSpeeds};

/// The gateway mode the controller arms for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum ArmMode {
    /// Valve commands (Autodig, swing, tracks).
    Valve,
    /// Position setpoints (cleanup).
    Position,
}

impl ArmMode {
    /// The heartbeat request for this mode.
    pub const fn request(self) -> RequestedMode {
        match self {
            ArmMode::Valve => RequestedMode::ArmValve,
            ArmMode::Position => RequestedMode::ArmPosition,
        }
    }

    /// The gateway mode that confirms it.
    pub const fn gateway_mode(self) -> GatewayMode {
        match self {
            ArmMode::Valve => GatewayMode::ArmedValve,
            ArmMode::Position => GatewayMode::ArmedPosition,
        }
    }
}

/// An error of the work cycle that stops motion.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum ControlFault {
    /// Autodig rejected its inputs.
    #[error("autodig: {0}")]
    Autodig(AutodigError),
    /// Cleanup rejected its inputs or found no floor.
    #[error("cleanup: {0}")]
    Cleanup(CleanupError),
    /// A kinematics computation failed (e.g. a cleanup waypoint out of reach).
    #[error("kinematics: {0}")]
    Kinematics(&'static str),
    /// A motion did not finish in time.
    #[error("timeout: {0}")]
    Timeout(&'static str),
    /// A motion pushed at relief without progress: something it cannot move is in the way.
    #[error("blocked: {0}")]
    Blocked(&'static str),
}

/// Why motion stopped.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum Fault {
    /// A sensor signal is older than allowed (or never arrived).
    #[error("stale sensor data: {signal} is {age_s:.3} s old")]
    StaleSensor {
        /// Which signal.
        signal: Signal,
        /// Its age, s (infinite if never received).
        age_s: f64,
    },
    /// A frame of the protocol failed to decode.
    #[error("decode error on {id:#010X}: {error}")]
    Decode {
        /// The 29-bit (or 11-bit) id, without flags.
        id: u32,
        /// What was wrong.
        error: DecodeError,
    },
    /// A frame that must not appear: from the gateway's address but not a gateway message, with the
    /// controller's own address, or a protocol message from an unknown address.
    #[error("unexpected frame {id:#010X} from source address {source_address:#04X}")]
    UnexpectedFrame {
        /// The 29-bit id.
        id: u32,
        /// Its J1939 source address.
        source_address: u8,
    },
    /// A joint beyond its limit.
    #[error("{joint} joint at {angle_rad:.4} rad is beyond its limit")]
    JointLimit {
        /// Which joint.
        joint: Joint,
        /// Its angle, rad.
        angle_rad: f64,
    },
    /// Emergency stop requested.
    #[error("emergency stop")]
    EStop,
    /// The gateway reported fault bits.
    #[error("gateway fault bits {:#06x}", .0.0)]
    GatewayFault(GatewayFaults),
    /// The gateway left the armed mode on its own.
    #[error("gateway reports {reported:?} while {expected:?} was confirmed")]
    GatewayMode {
        /// The confirmed mode.
        expected: GatewayMode,
        /// What it reports now.
        reported: GatewayMode,
    },
    /// The gateway did not confirm an arm request in time.
    #[error("gateway did not confirm {0:?} in time")]
    ArmTimeout(ArmMode),
    /// The gateway status keeps arriving with the same alive counter: the gateway is not running.
    #[error("gateway status frozen: alive counter {alive_counter} unchanged for {frozen_s:.3} s")]
    GatewayFrozen {
        /// The repeated counter.
        alive_counter: u8,
        /// How long it has not changed, s.
        frozen_s: f64,
    },
    /// A CAN error frame.
    #[error("CAN bus fault: {0:?}")]
    Bus(BusFault),
    /// The work cycle failed.
    #[error("control: {0}")]
    Control(ControlFault),
    /// The program is shutting down.
    #[error("shutdown")]
    Shutdown,
    /// Another node claimed the controller's J1939 address with a lower NAME (J1939-81): the
    /// controller sent Cannot Claim and may send nothing else, so it cannot command the machine
    /// until the operator's reset claims the address again (`ControllerNode::reset`).
    #[error(
        "J1939 address {address:#04X} lost to a node with a lower NAME {winner_name:#018X}: \
         Cannot Claim sent, no commands, heartbeats or status until the operator's reset"
    )]
    AddressLost {
        /// The address that was lost.
        address: u8,
        /// The winner's NAME.
        winner_name: u64,
    },
    /// A claim for the controller's or the gateway's address from a NAME that is not the configured
    /// one (`[j1939]` of the controller config): a misconfigured or foreign node, or a forged frame.
    /// When that NAME is lower than the owner's the owner lost the address (J1939-81): latched, and
    /// the operator's reset asks for the address to be claimed again (`ControllerNode::reset`).
    #[error(
        "J1939 address {address:#04X} claimed by an unexpected NAME {name:#018X}{}",
        if *owner_lost { ", lower than its owner's: the owner lost the address" } else { "" }
    )]
    AddressIntrusion {
        /// The address claimed.
        address: u8,
        /// The intruder's NAME.
        name: u64,
        /// Whether the intruder's NAME wins over the owner's.
        owner_lost: bool,
    },
    /// A joint-angle frame that puts a joint farther from the last accepted one than it can move in
    /// the time between them (`step::plausibility`): a second sender of the angles on the bus or a
    /// resolver fault. The frame is not used; the operator's resume or reset re-arms.
    #[error(transparent)]
    ImplausibleSensor(#[from] Implausible),
}

impl Fault {
    /// The fault code sent in `ControllerStatus.FaultReason` (0 is healthy): 1 stale sensor, 2 decode
    /// error, 3 unexpected frame, 4 joint limit, 5 e-stop, 6 gateway fault, 7 gateway mode, 8 arm
    /// timeout, 9 bus fault, 10 control, 11 shutdown, 12 gateway frozen, 13 address lost (on the bus
    /// only after the address was claimed again: the controller is silent meanwhile), 14 address
    /// intrusion, 15 implausible sensor.
    pub const fn code(&self) -> u8 {
        match self {
            Fault::StaleSensor { .. } => 1,
            Fault::Decode { .. } => 2,
            Fault::UnexpectedFrame { .. } => 3,
            Fault::JointLimit { .. } => 4,
            Fault::EStop => 5,
            Fault::GatewayFault(_) => 6,
            Fault::GatewayMode { .. } => 7,
            Fault::ArmTimeout(_) => 8,
            Fault::Bus(_) => 9,
            Fault::Control(_) => 10,
            Fault::Shutdown => 11,
            Fault::GatewayFrozen { .. } => 12,
            Fault::AddressLost { .. } => 13,
            Fault::AddressIntrusion { .. } => 14,
            Fault::ImplausibleSensor(_) => 15,
        }
    }

    /// The faults the simulation policy [`SafetyConfig::auto_rearm`] may recover from on its own:
    /// stale sensor data, a decode error, an unexpected frame, a CAN bus fault, and a gateway fault
    /// whose bits are all of its link's ([`Self::TRANSIENT_GATEWAY_FAULTS`]: a late or rejected
    /// heartbeat or command). These are the false faults of a simulator on a loaded host (a VM's
    /// scheduling gap trips the gateway's watchdog) and of an injected frame. Never an e-stop, a
    /// joint limit, a gateway's e-stop, joint, setpoint, clock or address fault, a mode change, a
    /// frozen status or missing confirmation, an address claim fault, a work-cycle fault (its own
    /// rule, [`Fault::recovery`]) or a shutdown.
    pub const fn transient(&self) -> bool {
        match self {
            Fault::StaleSensor { .. }
            | Fault::Decode { .. }
            | Fault::UnexpectedFrame { .. }
            | Fault::Bus(_) => true,
            Fault::GatewayFault(GatewayFaults(bits)) => {
                *bits != 0 && *bits & !Self::TRANSIENT_GATEWAY_FAULTS == 0
            }
            _ => false,
        }
    }

    /// The gateway's fault bits that concern its link to the controller only (the watchdog, a bad
    /// checksum or alive counter, a stale command, a bus error, a frame that failed authentication):
    /// the gateway fault bits [`Self::transient`] accepts.
    pub const TRANSIENT_GATEWAY_FAULTS: u16 = GatewayFaults::WATCHDOG_TIMEOUT
        | GatewayFaults::BAD_CHECKSUM
        | GatewayFaults::BAD_ALIVE_COUNTER
        | GatewayFaults::STALE_COMMAND
        | GatewayFaults::BUS_ERROR
        | GatewayFaults::AUTH_FAILURE;

    /// How motion may resume after this fault stopped it (module docs, "Stops that stay stopped").
    pub const fn recovery(&self) -> Recovery {
        if self.latches() {
            Recovery::Reset
        } else if matches!(self, Fault::Control(_)) {
            Recovery::WorkCycle
        } else if self.transient() {
            Recovery::Transient
        } else {
            Recovery::Operator
        }
    }

    /// Whether only [`Safety::reset`] clears it.
    pub const fn latches(&self) -> bool {
        matches!(
            self,
            Fault::EStop
                | Fault::Shutdown
                | Fault::AddressLost { .. }
                | Fault::AddressIntrusion {
                    owner_lost: true,
                    ..
                }
        )
    }
}

/// How motion may resume after a fault stopped it, from the most lenient to the strictest (the
/// strictest of the faults since the stop applies).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Recovery {
    /// A work-cycle fault: re-armed once the cause has cleared (counted against
    /// [`SafetyConfig::max_auto_rearms`]).
    WorkCycle,
    /// A transient fault: the operator's resume or reset, or on its own under the simulation policy
    /// [`SafetyConfig::auto_rearm`] (counted the same way).
    Transient,
    /// The operator's resume or reset.
    Operator,
    /// The operator's reset only (an e-stop, a latching fault).
    Reset,
}

/// How serious a bus condition is.
pub fn bus_fault_stops_motion(fault: BusFault) -> bool {
    !matches!(
        fault,
        BusFault::ErrorWarning
            | BusFault::ArbitrationLost
            | BusFault::Restarted
            | BusFault::ErrorActive
    )
}

/// Safety parameters.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SafetyConfig {
    /// Decode and log, never transmit. Default false.
    pub listen_only: bool,
    /// Control signals older than this are stale, s. Default 0.03 (3 control periods).
    pub sensor_max_age_s: f64,
    /// The gateway status (20 Hz) older than this is stale, s; a status whose alive counter has not
    /// changed for this long is frozen. Default 0.35.
    pub status_max_age_s: f64,
    /// The gateway must confirm an arm request within this, s. Default 1.0.
    pub arm_timeout_s: f64,
    /// A cause counts as cleared after this long without a new fault event, s. Default 0.5.
    pub clear_hold_s: f64,
    /// After a fault, neutral valve commands are sent at least this long, s. Default 0.1.
    pub neutral_hold_s: f64,
    /// Tolerance beyond the configured joint limits, rad. Default 1 degree.
    pub joint_limit_margin_rad: f64,
    /// Simulation only, opt-in: after a transient fault ([`Fault::transient`]) that stopped motion,
    /// re-arm on its own once the cause has cleared instead of waiting for the operator's resume
    /// (module docs, "Stops that stay stopped"). Default false; logged at `WARN` when the layer starts
    /// and at each re-arm. `excavator-ctl run` refuses it on a CAN controller with bit timing (a real
    /// bus), and the package's config leaves it off.
    pub auto_rearm: bool,
    /// After this many automatic re-arms (work-cycle faults, and transient ones under `auto_rearm`)
    /// without `rearm_reset_s` of clean armed time, wait for the operator. Default 5.
    pub max_auto_rearms: u32,
    /// Armed time without a fault that resets the re-arm count, s. Default 10.
    pub rearm_reset_s: f64,
    /// The fastest each joint can turn (`[safety.max_joint_speed_rad_per_s]`, rad/s): a joint-angle
    /// frame that moves a joint farther than this allows is rejected
    /// ([`Fault::ImplausibleSensor`], `step::plausibility`). Defaults: boom, stick and swing 2.0,
    /// bucket 8.0.
    pub max_joint_speed_rad_per_s: JointSpeeds,
    /// How long a joint's angle may stay bit-identical while the controller holds its valve open
    /// (at least `step::plausibility::OPEN_FRACTION`) before it is a frozen signal
    /// ([`Fault::ImplausibleSensor`]), s. Default 1.0.
    pub frozen_sensor_s: f64,
    /// Heartbeat period, s. Default 0.05 (20 Hz, the docs/protocol.md budget; the gateway's watchdog
    /// is 100 ms). A change of the requested mode (arm, disarm on a fault, e-stop) and every heartbeat
    /// after a shutdown are sent at once, whatever the period. [`SafetyConfig::validate`] refuses
    /// periods over half the watchdog.
    pub heartbeat_period_s: f64,
    /// The gateway's periods and watchdogs the limits above are checked against: the project's
    /// gateway, or a machine profile's ([`SafetyConfig::for_gateway`]). Not in the file: it comes
    /// with the profile.
    #[serde(skip)]
    pub gateway: GatewayTiming,
}

/// Period of the gateway's control signals (angles, rates, pressures), s: 100 Hz (docs/protocol.md;
/// [`firmware_bridge::dbc::SENSOR_PERIOD`], the DBC's cycle time).
pub const SENSOR_PERIOD_S: f64 = firmware_bridge::dbc::SENSOR_PERIOD.as_secs_f64();
/// Period of the gateway status, s: 20 Hz (docs/protocol.md; [`firmware_bridge::dbc::STATUS_PERIOD`]).
pub const GATEWAY_STATUS_PERIOD_S: f64 = firmware_bridge::dbc::STATUS_PERIOD.as_secs_f64();
/// The gateway's heartbeat watchdog and command timeout, s (`firmware_bridge::gateway::GatewayConfig`).
pub const GATEWAY_WATCHDOG_S: f64 = 0.1;
/// The longest gateway status age, in status periods (1 s at the project's 20 Hz).
const STATUS_AGE_PERIODS: u32 = 20;
/// The controller's control period, s ([`firmware_bridge::dbc::CONTROL_PERIOD`]).
const CONTROL_PERIOD_S: f64 = firmware_bridge::dbc::CONTROL_PERIOD.as_secs_f64();

impl SafetyConfig {
    /// The configuration for the gateway of a machine profile (`docs/machine-profile.md`, "Rates and
    /// timeouts"): the stale-data ages and the heartbeat period, set for the project's gateway, are
    /// scaled by the ratio of that gateway's period to the project's (a gateway that sends its
    /// angles every 20 ms gets twice the sensor age: the same number of periods), and
    /// [`SafetyConfig::validate`] checks them against its periods and watchdogs. The project's
    /// gateway leaves every value as it is.
    #[must_use]
    pub fn for_gateway(mut self, timing: GatewayTiming) -> Self {
        let was = self.gateway;
        let ratio = |now: u32, was: u32| f64::from(now) / f64::from(was);
        // The same number of periods, but never beyond that gateway's watchdog (the limit
        // `validate` holds it to): a file at the project's widest age, 100 ms, stays valid for a
        // gateway with a slower sensor period.
        self.sensor_max_age_s = (self.sensor_max_age_s
            * ratio(timing.sensor_period_ms, was.sensor_period_ms))
        .min(GatewayTiming::secs(timing.heartbeat_timeout_ms));
        self.status_max_age_s *= ratio(timing.status_period_ms, was.status_period_ms);
        self.heartbeat_period_s *= ratio(timing.heartbeat_period_ms, was.heartbeat_period_ms);
        self.gateway = timing;
        self
    }

    /// Checks every parameter against the protocol's timing: stale-data ages between the period of
    /// their signal and what the gateway tolerates, a heartbeat well inside the watchdog, finite
    /// holds and timeouts, bounded counts.
    ///
    /// # Errors
    /// The first [`ParamError`] (section `safety`).
    pub fn validate(&self) -> Result<(), ParamError> {
        const S: &str = "safety";
        let g = &self.gateway;
        let secs = GatewayTiming::secs;
        check(
            S,
            "sensor_max_age_s",
            self.sensor_max_age_s,
            Limits::above(secs(g.sensor_period_ms), secs(g.heartbeat_timeout_ms), "s"),
            &format!(
                "above the {} ms sensor period, at most the gateway's {} ms watchdog",
                g.sensor_period_ms, g.heartbeat_timeout_ms
            ),
        )?;
        check(
            S,
            "status_max_age_s",
            self.status_max_age_s,
            Limits::above(
                secs(g.status_period_ms),
                secs(STATUS_AGE_PERIODS * g.status_period_ms),
                "s",
            ),
            &format!("above the {} ms gateway status period", g.status_period_ms),
        )?;
        check(
            S,
            "arm_timeout_s",
            self.arm_timeout_s,
            Limits::above(secs(g.status_period_ms), 10.0, "s"),
            "the confirmation comes with a gateway status",
        )?;
        check(
            S,
            "clear_hold_s",
            self.clear_hold_s,
            Limits::above(0.0, 60.0, "s"),
            "",
        )?;
        check(
            S,
            "neutral_hold_s",
            self.neutral_hold_s,
            Limits::closed(CONTROL_PERIOD_S, 10.0, "s"),
            "at least one control period of neutral commands",
        )?;
        check(
            S,
            "joint_limit_margin_rad",
            self.joint_limit_margin_rad,
            Limits::closed(0.0, 0.2, "rad"),
            "",
        )?;
        check_count(
            S,
            "max_auto_rearms",
            u64::from(self.max_auto_rearms),
            0,
            1000,
            "",
        )?;
        check(
            S,
            "rearm_reset_s",
            self.rearm_reset_s,
            Limits::above(0.0, 3600.0, "s"),
            "",
        )?;
        for (joint, speed) in self.max_joint_speed_rad_per_s.by_joint() {
            check(
                "safety.max_joint_speed_rad_per_s",
                joint.name(),
                speed,
                Limits::closed(0.1, 20.0, "rad/s"),
                "the fastest the joint can turn",
            )?;
        }
        check(
            S,
            "frozen_sensor_s",
            self.frozen_sensor_s,
            Limits::closed(10.0 * secs(g.sensor_period_ms), 10.0, "s"),
            "from ten sensor periods (the resolvers' noise must have had the time to show) to 10 s",
        )?;
        check(
            S,
            "heartbeat_period_s",
            self.heartbeat_period_s,
            Limits::closed(CONTROL_PERIOD_S, secs(g.heartbeat_timeout_ms) / 2.0, "s"),
            &format!(
                "from one control period to half the gateway's {} ms watchdog",
                g.heartbeat_timeout_ms
            ),
        )
    }
}

impl Default for SafetyConfig {
    fn default() -> Self {
        Self {
            listen_only: false,
            sensor_max_age_s: 0.03,
            status_max_age_s: 0.35,
            arm_timeout_s: 1.0,
            clear_hold_s: 0.5,
            neutral_hold_s: 0.1,
            joint_limit_margin_rad: 1.0_f64.to_radians(),
            auto_rearm: false,
            max_auto_rearms: 5,
            rearm_reset_s: 10.0,
            max_joint_speed_rad_per_s: JointSpeeds::default(),
            frozen_sensor_s: 1.0,
            heartbeat_period_s: 0.05,
            gateway: GatewayTiming::canonical(),
        }
    }
}

/// The safety state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SafetyState {
    /// Never transmits.
    ListenOnly,
    /// Not armed; valves neutral at the gateway.
    Disarmed,
    /// Arm request sent, waiting for the gateway status to confirm it.
    Arming {
        /// The requested mode.
        mode: ArmMode,
        /// When the request started, s.
        since_s: f64,
    },
    /// Armed and confirmed: motion allowed.
    Armed {
        /// The confirmed mode.
        mode: ArmMode,
        /// When it was confirmed, s.
        since_s: f64,
    },
    /// Stopped by a fault.
    Faulted {
        /// The first fault.
        fault: Fault,
        /// When it happened, s.
        since_s: f64,
    },
    /// Shut down: neutral and disarm, forever.
    Shutdown,
}

/// What to do this period.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SafetyTick {
    /// The heartbeat to send (every period unless listen-only).
    pub heartbeat: Option<ControllerHeartbeat>,
    /// The mode motion commands may be sent in (armed and confirmed).
    pub motion: Option<ArmMode>,
    /// Send neutral commands for all six valves this period (before the heartbeat).
    pub send_neutral: bool,
    /// Send a position setpoint holding the measured joints (arming position mode: the gateway faults
    /// if no setpoint follows the arm request within its command timeout). Never in the period that
    /// sends the `ArmPosition` request: the node sends the heartbeat last, so a setpoint in that period
    /// would reach the gateway before it is in position mode and be rejected; the next period is well
    /// inside the gateway's 100 ms grace after arming.
    pub hold_position: bool,
}

/// The safety state machine.
#[derive(Debug, Clone)]
pub struct Safety {
    config: SafetyConfig,
    limits: [(f64, f64); 3],
    state: SafetyState,
    alive_counter: u8,
    last_event_s: f64,
    neutral_until_s: f64,
    last_fault: Option<Fault>,
    fault_count: u64,
    rearms: u32,
    /// A latching fault or an e-stop was reported: only [`Safety::reset`] clears it.
    needs_reset: bool,
    /// The cause cleared and the stop waits for the operator's resume or reset.
    waiting: bool,
    /// The strictest recovery of the faults since motion stopped; `None`: the fault came while
    /// disarmed (nothing stopped).
    recovery: Option<Recovery>,
    acked: bool,
    estop: bool,
    /// After the operator reset an e-stop: `Some(first ResetEStop heartbeat time)` until a gateway
    /// status received after it shows `E_STOP` cleared (`Some(None)` before the first one).
    estop_reset: Option<Option<f64>>,
    healthy: Result<(), Fault>,
    gateway_mode: Option<GatewayMode>,
    now_s: f64,
    /// Time and mode of the last heartbeat sent.
    last_heartbeat: Option<(f64, RequestedMode)>,
    /// Rate limit of the listen-only fault log (every fault is still counted).
    listen_only_log: LogThrottle,
}

impl Safety {
    /// A safety layer for joints with `limits` `[(min, max); 3]` (rad, `[boom, stick, bucket]`).
    ///
    /// # Errors
    /// [`ControllerError::Config`] for a parameter [`SafetyConfig::validate`] refuses, or limits that
    /// are not finite with min < max.
    pub fn new(config: SafetyConfig, limits: [(f64, f64); 3]) -> Result<Self, ControllerError> {
        config.validate()?;
        for (joint, (lo, hi)) in Joint::ALL.into_iter().zip(limits) {
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return Err(ControllerError::Config {
                    field: "safety",
                    reason: format!(
                        "{joint} joint limits [{lo}, {hi}] rad must be finite with min < max"
                    ),
                });
            }
        }
        if config.auto_rearm && !config.listen_only {
            tracing::warn!(
                max_auto_rearms = config.max_auto_rearms,
                "safety.auto_rearm is on (simulation only): after a transient fault (stale sensor \
                 data, decode error, unexpected frame, CAN bus fault, a gateway fault of its link \
                 alone) motion resumes without the operator"
            );
        }
        Ok(Self {
            config,
            limits,
            state: if config.listen_only {
                SafetyState::ListenOnly
            } else {
                SafetyState::Disarmed
            },
            // The first heartbeat carries counter 0.
            alive_counter: 15,
            last_event_s: f64::NEG_INFINITY,
            neutral_until_s: f64::NEG_INFINITY,
            last_fault: None,
            fault_count: 0,
            rearms: 0,
            needs_reset: false,
            waiting: false,
            recovery: None,
            acked: false,
            estop: false,
            estop_reset: None,
            healthy: Err(Fault::StaleSensor {
                signal: Signal::JointAngles,
                age_s: f64::INFINITY,
            }),
            gateway_mode: None,
            now_s: f64::NEG_INFINITY,
            last_heartbeat: None,
            listen_only_log: LogThrottle::default(),
        })
    }

    /// The configuration.
    pub fn config(&self) -> &SafetyConfig {
        &self.config
    }

    /// The current state.
    pub fn state(&self) -> SafetyState {
        self.state
    }

    /// The mode motion may be commanded in now.
    pub fn motion(&self) -> Option<ArmMode> {
        match self.state {
            SafetyState::Armed { mode, .. } => Some(mode),
            _ => None,
        }
    }

    /// The most recent fault (kept after it cleared, for display).
    pub fn last_fault(&self) -> Option<Fault> {
        self.last_fault
    }

    /// The active fault, if faulted.
    pub fn active_fault(&self) -> Option<Fault> {
        match self.state {
            SafetyState::Faulted { fault, .. } => Some(fault),
            _ => None,
        }
    }

    /// Faults reported so far (including repeats while faulted).
    pub fn fault_count(&self) -> u64 {
        self.fault_count
    }

    /// Why arming is not possible right now (`Ok` when healthy), from the last [`Self::observe`].
    pub fn health(&self) -> Result<(), Fault> {
        self.healthy
    }

    /// Whether the safety layer waits for the operator (a [`Self::reset`], or for a stop that does
    /// not latch also a [`Self::acknowledge`]) before it re-arms.
    pub fn needs_reset(&self) -> bool {
        self.needs_reset || self.estop || self.waiting
    }

    /// Whether only [`Self::reset`] clears the stop (an e-stop or a latching fault): the operator's
    /// resume ([`Self::acknowledge`]) does not.
    pub fn needs_full_reset(&self) -> bool {
        self.needs_reset || self.estop
    }

    /// Reports a fault event at `now_s`. In listen-only mode it is only logged.
    pub fn report(&mut self, now_s: f64, fault: Fault) {
        self.fault_count = self.fault_count.saturating_add(1);
        self.last_fault = Some(fault);
        if now_s.is_finite() {
            self.last_event_s = self.last_event_s.max(now_s);
        }
        if fault.latches() {
            // A reset given before this fault does not acknowledge it.
            self.needs_reset = true;
            self.acked = false;
        }
        if matches!(self.state, SafetyState::Faulted { .. }) {
            // A further fault after the stop: the strictest one since decides how it resumes.
            self.recovery = self.recovery.map(|r| r.max(fault.recovery()));
        }
        match self.state {
            SafetyState::ListenOnly => {
                if let Some(held_back) = self.listen_only_log.allow(now_s) {
                    tracing::warn!(%fault, held_back, "listen-only: would stop motion");
                }
            }
            SafetyState::Shutdown => {}
            SafetyState::Faulted { since_s, .. } => {
                if fault == Fault::EStop {
                    // The operator's stop is the latest safety reason: status reports it, not the
                    // older fault it came on top of.
                    tracing::warn!(%fault, "e-stop while faulted");
                    self.state = SafetyState::Faulted { fault, since_s };
                } else {
                    tracing::debug!(%fault, "further fault while faulted");
                }
            }
            SafetyState::Armed { .. } | SafetyState::Arming { .. } => {
                tracing::warn!(%fault, "fault: valves neutral, disarming");
                self.enter_fault(now_s, fault);
                self.recovery = Some(fault.recovery());
            }
            SafetyState::Disarmed => {
                // Nothing moves; still hold off re-arming until the cause clears, and keep the
                // reason visible.
                tracing::warn!(%fault, "fault while disarmed");
                self.enter_fault(now_s, fault);
                self.recovery = None;
            }
        }
    }

    fn enter_fault(&mut self, now_s: f64, fault: Fault) {
        let t = if now_s.is_finite() { now_s } else { self.now_s };
        self.state = SafetyState::Faulted { fault, since_s: t };
        self.acked = false;
        self.neutral_until_s = t + self.config.neutral_hold_s;
    }

    /// Emergency stop: neutral valves, the heartbeat requests `EStop` (the gateway latches it), and
    /// nothing moves until [`Self::reset`].
    pub fn request_estop(&mut self, now_s: f64) {
        self.estop = true;
        self.estop_reset = None;
        self.report(now_s, Fault::EStop);
    }

    /// Clears an e-stop and a latched fault (the operator's acknowledgement). After an e-stop the
    /// heartbeat then requests `ResetEStop` (the only request that clears the gateway's latched
    /// `E_STOP`) until the gateway reports it cleared, then `Disarm`. Motion still needs the cause to
    /// clear and a fresh arming handshake.
    pub fn reset(&mut self) {
        if self.state == SafetyState::Shutdown {
            return;
        }
        tracing::info!("safety reset by operator");
        if self.estop {
            self.estop_reset = Some(None);
        }
        self.estop = false;
        self.needs_reset = false;
        self.waiting = false;
        self.acked = true;
        self.rearms = 0;
    }

    /// The operator's resume: acknowledges a stop that does not latch, so motion resumes (through a
    /// fresh arming handshake) once its cause has cleared. An e-stop or a latching fault still needs
    /// [`Self::reset`]. Returns whether it acknowledged a stop.
    pub fn acknowledge(&mut self) -> bool {
        if self.state == SafetyState::Shutdown || self.active_fault().is_none() {
            return false;
        }
        if self.needs_full_reset() {
            tracing::warn!("resume: an e-stop or a latched fault needs the operator's reset");
            return false;
        }
        tracing::info!("fault stop acknowledged by the operator (resume)");
        self.waiting = false;
        self.acked = true;
        self.rearms = 0;
        true
    }

    /// Shutdown: from now on neutral valves and `Disarm` heartbeats only.
    pub fn shutdown(&mut self, now_s: f64) {
        if self.state != SafetyState::ListenOnly && self.state != SafetyState::Shutdown {
            tracing::info!("shutdown: valves neutral, disarming");
            self.last_fault = Some(Fault::Shutdown);
            self.state = SafetyState::Shutdown;
            self.neutral_until_s = now_s;
        }
    }

    /// Checks the estimate at `now_s`: staleness, joint limits and the gateway status. A failed check
    /// while arming or armed is a fault; otherwise it only blocks arming.
    pub fn observe(&mut self, now_s: f64, est: &Estimator) {
        if now_s.is_finite() {
            self.now_s = now_s;
        }
        self.healthy = self.check(now_s, est);
        let status = est.state().gateway;
        self.gateway_mode = status.map(|s| s.mode);
        if let Some(Some(sent_s)) = self.estop_reset
            && let Some(s) = status
            && est
                .last_received_s(Signal::GatewayStatus)
                .is_some_and(|t| t > sent_s)
            && !s.faults.contains(GatewayFaults::E_STOP)
        {
            tracing::info!("gateway e-stop reset confirmed");
            self.estop_reset = None;
        }
        let fresh_status = est.age_s(Signal::GatewayStatus, now_s) <= self.config.status_max_age_s;
        // A gateway e-stop this controller did not give (one from before a restart of the controller
        // process): the gateway keeps it latched, so adopt it, show it, and let `reset` clear it with
        // ResetEStop.
        if let Some(s) = status.filter(|_| fresh_status)
            && s.faults.contains(GatewayFaults::E_STOP)
            && !self.estop
            && self.estop_reset.is_none()
            && matches!(
                self.state,
                SafetyState::Disarmed | SafetyState::Faulted { .. }
            )
        {
            tracing::warn!("the gateway reports a latched e-stop: waiting for an operator reset");
            self.request_estop(now_s);
        }
        match self.state {
            SafetyState::Armed { mode, since_s } => {
                if let Err(fault) = self.healthy {
                    self.report(now_s, fault);
                } else if let Some(s) = status.filter(|_| fresh_status)
                    && est
                        .last_received_s(Signal::GatewayStatus)
                        .is_some_and(|t| t >= since_s)
                    && s.mode != mode.gateway_mode()
                {
                    let fault = if s.faults.is_empty() {
                        Fault::GatewayMode {
                            expected: mode.gateway_mode(),
                            reported: s.mode,
                        }
                    } else {
                        Fault::GatewayFault(s.faults)
                    };
                    self.report(now_s, fault);
                } else if now_s - since_s >= self.config.rearm_reset_s {
                    self.rearms = 0;
                }
            }
            SafetyState::Arming { mode, since_s } => {
                if let Err(fault) = self.healthy {
                    self.report(now_s, fault);
                } else if let Some(s) = status
                    && est
                        .last_received_s(Signal::GatewayStatus)
                        .is_some_and(|t| t >= since_s)
                    && s.mode == mode.gateway_mode()
                {
                    tracing::info!(?mode, "armed: gateway confirmed");
                    self.state = SafetyState::Armed {
                        mode,
                        since_s: now_s,
                    };
                } else if let Some(s) = status
                    && s.mode == GatewayMode::Faulted
                    && est
                        .last_received_s(Signal::GatewayStatus)
                        .is_some_and(|t| t >= since_s)
                {
                    self.report(now_s, Fault::GatewayFault(s.faults));
                } else if now_s - since_s > self.config.arm_timeout_s {
                    self.report(now_s, Fault::ArmTimeout(mode));
                }
            }
            SafetyState::Disarmed
            | SafetyState::Faulted { .. }
            | SafetyState::ListenOnly
            | SafetyState::Shutdown => {}
        }
    }

    /// Staleness, joint limits, gateway status: `Ok` when arming would be allowed (given a gateway
    /// that is `Disarmed` or already in the requested mode).
    fn check(&self, now_s: f64, est: &Estimator) -> Result<(), Fault> {
        let (signal, age_s) = est.stalest_control_signal(now_s);
        if age_s.is_nan() || age_s > self.config.sensor_max_age_s {
            return Err(Fault::StaleSensor { signal, age_s });
        }
        let status_age = est.age_s(Signal::GatewayStatus, now_s);
        if status_age.is_nan() || status_age > self.config.status_max_age_s {
            return Err(Fault::StaleSensor {
                signal: Signal::GatewayStatus,
                age_s: if status_age.is_nan() {
                    f64::INFINITY
                } else {
                    status_age
                },
            });
        }
        // Fresh by age but not moving on; a NaN age counts as frozen.
        let frozen_s = est.gateway_alive_age_s(now_s);
        if frozen_s.is_nan() || frozen_s > self.config.status_max_age_s {
            return Err(Fault::GatewayFrozen {
                alive_counter: est.gateway_alive_counter().unwrap_or(0),
                frozen_s: if frozen_s.is_nan() {
                    f64::INFINITY
                } else {
                    frozen_s
                },
            });
        }
        let q = est.state().joints;
        let m = self.config.joint_limit_margin_rad;
        for joint in Joint::ALL {
            let (lo, hi) = self.limits[joint.index()];
            let a = joint_angle(&q, joint);
            if !(a >= lo - m && a <= hi + m) {
                return Err(Fault::JointLimit {
                    joint,
                    angle_rad: a,
                });
            }
        }
        Ok(())
    }

    fn next_heartbeat(&mut self, mode: RequestedMode) -> ControllerHeartbeat {
        self.alive_counter = (self.alive_counter + 1) % 16;
        ControllerHeartbeat {
            mode,
            alive_counter: self.alive_counter,
        }
    }

    fn gateway_armed(&self) -> bool {
        matches!(
            self.gateway_mode,
            Some(GatewayMode::ArmedValve | GatewayMode::ArmedPosition)
        )
    }

    /// One control period at `now_s`: `want` is the mode the work cycle needs (`None`: stay disarmed).
    /// Advances the arming handshake and the fault recovery and says what to send. The heartbeat goes
    /// out every [`SafetyConfig::heartbeat_period_s`], and at once when the requested mode changes.
    pub fn tick(&mut self, now_s: f64, want: Option<ArmMode>) -> SafetyTick {
        let mut tick = self.tick_every_period(now_s, want);
        if let Some(hb) = tick.heartbeat {
            let period =
                if self.config.heartbeat_period_s > 0.0 && self.config.heartbeat_period_s < 0.1 {
                    self.config.heartbeat_period_s
                } else {
                    0.05
                };
            let due = match self.last_heartbeat {
                None => true,
                Some((t, mode)) => {
                    mode != hb.mode
                        || self.state == SafetyState::Shutdown
                        // Also when the clock is not finite: send rather than starve the watchdog.
                        || (now_s - t).partial_cmp(&(period - 1e-6)) != Some(std::cmp::Ordering::Less)
                }
            };
            if due {
                self.last_heartbeat = Some((now_s, hb.mode));
            } else {
                // Not sent: the gateway expects the alive counter to advance by one per heartbeat.
                self.alive_counter = (self.alive_counter + 15) % 16;
                tick.heartbeat = None;
            }
        }
        tick
    }

    fn tick_every_period(&mut self, now_s: f64, want: Option<ArmMode>) -> SafetyTick {
        if now_s.is_finite() {
            self.now_s = now_s;
        }
        let quiet = SafetyTick {
            heartbeat: None,
            motion: None,
            send_neutral: false,
            hold_position: false,
        };
        match self.state {
            SafetyState::ListenOnly => quiet,
            SafetyState::Shutdown => SafetyTick {
                heartbeat: Some(self.next_heartbeat(RequestedMode::Disarm)),
                send_neutral: true,
                ..quiet
            },
            SafetyState::Faulted { fault, since_s } => {
                let send_neutral = now_s <= self.neutral_until_s || self.gateway_armed();
                let request = match self.estop_reset {
                    _ if self.estop => RequestedMode::EStop,
                    Some(sent) => {
                        if sent.is_none() {
                            // The last finite time, so the confirmation can come after it.
                            self.estop_reset = Some(Some(self.now_s));
                        }
                        RequestedMode::ResetEStop
                    }
                    None => RequestedMode::Disarm,
                };
                let cleared = self.healthy.is_ok()
                    && self.gateway_mode == Some(GatewayMode::Disarmed)
                    && now_s - self.last_event_s >= self.config.clear_hold_s
                    && now_s - since_s >= self.config.clear_hold_s;
                if cleared && !self.estop {
                    // None: the fault came while disarmed and stopped nothing.
                    let auto = match self.recovery {
                        None => Some(false),
                        Some(Recovery::WorkCycle) => Some(true),
                        Some(Recovery::Transient) if self.config.auto_rearm => Some(true),
                        Some(_) => None,
                    }
                    .filter(|counted| {
                        !self.needs_reset && (!counted || self.rearms < self.config.max_auto_rearms)
                    });
                    if self.acked || auto.is_some() {
                        if !self.acked && auto == Some(true) {
                            self.rearms += 1;
                            if self.recovery == Some(Recovery::Transient) {
                                tracing::warn!(
                                    %fault,
                                    rearm = self.rearms,
                                    "safety.auto_rearm (simulation only): re-arming without the \
                                     operator"
                                );
                            }
                        }
                        self.acked = false;
                        self.waiting = false;
                        tracing::info!(%fault, rearm = self.rearms, "cause cleared: re-arming allowed");
                        self.state = SafetyState::Disarmed;
                    } else if !self.waiting && !self.needs_reset {
                        tracing::warn!(
                            %fault,
                            "cause cleared: motion stopped, waiting for the operator's resume or reset"
                        );
                        self.waiting = true;
                    }
                }
                SafetyTick {
                    heartbeat: Some(self.next_heartbeat(request)),
                    send_neutral,
                    ..quiet
                }
            }
            SafetyState::Disarmed => {
                let send_neutral = now_s <= self.neutral_until_s;
                if let Some(mode) = want
                    && self.healthy.is_ok()
                    && self.gateway_mode == Some(GatewayMode::Disarmed)
                    && !self.needs_reset()
                {
                    tracing::info!(?mode, "arming");
                    self.state = SafetyState::Arming {
                        mode,
                        since_s: now_s,
                    };
                    return SafetyTick {
                        heartbeat: Some(self.next_heartbeat(mode.request())),
                        send_neutral,
                        ..quiet
                    };
                }
                SafetyTick {
                    heartbeat: Some(self.next_heartbeat(RequestedMode::Disarm)),
                    send_neutral,
                    ..quiet
                }
            }
            SafetyState::Arming { mode, .. } => match want {
                None => self.disarm(now_s),
                Some(w) if w != mode => {
                    self.state = SafetyState::Arming {
                        mode: w,
                        since_s: now_s,
                    };
                    SafetyTick {
                        heartbeat: Some(self.next_heartbeat(w.request())),
                        ..quiet
                    }
                }
                Some(_) => SafetyTick {
                    heartbeat: Some(self.next_heartbeat(mode.request())),
                    hold_position: mode == ArmMode::Position,
                    ..quiet
                },
            },
            SafetyState::Armed { mode, .. } => match want {
                None => self.disarm(now_s),
                Some(w) if w != mode => {
                    // Switching modes goes through a fresh confirmation; the gateway allows the
                    // direct switch and holds the valves neutral for that tick.
                    tracing::info!(from = ?mode, to = ?w, "switching gateway mode");
                    self.state = SafetyState::Arming {
                        mode: w,
                        since_s: now_s,
                    };
                    SafetyTick {
                        heartbeat: Some(self.next_heartbeat(w.request())),
                        send_neutral: mode == ArmMode::Valve,
                        ..quiet
                    }
                }
                Some(_) => SafetyTick {
                    heartbeat: Some(self.next_heartbeat(mode.request())),
                    motion: Some(mode),
                    ..quiet
                },
            },
        }
    }

    fn disarm(&mut self, now_s: f64) -> SafetyTick {
        tracing::info!("disarming: nothing to do");
        self.state = SafetyState::Disarmed;
        self.neutral_until_s = now_s + self.config.neutral_hold_s;
        SafetyTick {
            heartbeat: Some(self.next_heartbeat(RequestedMode::Disarm)),
            motion: None,
            send_neutral: true,
            hold_position: false,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::step::estimate::EstimatorConfig;
    use firmware_bridge::messages::{
        AuxValveMeasured, Cylinder, GatewayStatus, JointAngles, JointRates, Message, ValveState,
    };
    use planner::kinematics::Kinematics;
    use planner::machine::MachineConfig;

    /// A profile's gateway: the stale-data limits and the heartbeat keep their number of periods, the
    /// limits are those of its periods and watchdogs; the project's gateway changes nothing.
    #[test]
    fn the_limits_follow_the_gateways_periods_and_watchdogs() {
        let d = SafetyConfig::default();
        assert_eq!(d.for_gateway(GatewayTiming::canonical()), d);
        let slow = GatewayTiming {
            sensor_period_ms: 20,
            status_period_ms: 100,
            heartbeat_timeout_ms: 200,
            ..GatewayTiming::canonical()
        };
        let c = d.for_gateway(slow);
        assert!((c.sensor_max_age_s - 0.06).abs() < 1e-12, "{c:?}");
        assert!((c.status_max_age_s - 0.7).abs() < 1e-12, "{c:?}");
        assert_eq!(c.heartbeat_period_s, d.heartbeat_period_s);
        c.validate().unwrap();
        // Back to the project's gateway: the values of the file again.
        let back = c.for_gateway(GatewayTiming::canonical());
        assert!((back.sensor_max_age_s - d.sensor_max_age_s).abs() < 1e-15);
        // An age of 10 ms is one period of the project's gateway but half of this one's.
        let mut short = c;
        short.sensor_max_age_s = 0.015;
        let err = short.validate().unwrap_err().to_string();
        assert!(err.contains("above the 20 ms sensor period"), "{err}");
        // A heartbeat at 80 ms needs a watchdog of at least 160 ms.
        let mut hb = d;
        hb.heartbeat_period_s = 0.08;
        assert!(hb.validate().is_err());
        assert!(hb.for_gateway(slow).validate().is_ok());
        // The widest age for the project's gateway (config/vm.toml's 100 ms) on a gateway with a
        // 20 ms sensor period and a 100 ms watchdog (examples/other_gateway.toml): held to that
        // watchdog, not doubled past it.
        let wide = SafetyConfig {
            sensor_max_age_s: 0.1,
            ..d
        };
        let profile = GatewayTiming {
            sensor_period_ms: 20,
            heartbeat_timeout_ms: 100,
            ..GatewayTiming::canonical()
        };
        let held = wide.for_gateway(profile);
        assert!((held.sensor_max_age_s - 0.1).abs() < 1e-15, "{held:?}");
        held.validate().unwrap();
    }

    /// `ControllerStatus.FaultReason`'s value table in `excavator.dbc` names each fault code by its
    /// variant (and 0 `Healthy`), so cantools and candump readers see the same names as the log.
    #[test]
    fn fault_codes_are_the_dbc_value_table() {
        let dbc = firmware_bridge::wire_dbc::WireDbc::parse(firmware_bridge::dbc::DBC_TEXT)
            .expect("excavator.dbc parses");
        let signal = dbc
            .message("ControllerStatus")
            .and_then(|m| m.signal("FaultReason"))
            .expect("ControllerStatus.FaultReason");
        let every_variant = [
            Fault::StaleSensor {
                signal: crate::step::estimate::Signal::JointAngles,
                age_s: 0.1,
            },
            Fault::Decode {
                id: 0x0CFF_5080,
                error: DecodeError::RemoteFrame,
            },
            Fault::UnexpectedFrame {
                id: 0x0CFF_5099,
                source_address: 0x99,
            },
            Fault::JointLimit {
                joint: planner::kinematics::Joint::Boom,
                angle_rad: 2.0,
            },
            Fault::EStop,
            Fault::GatewayFault(firmware_bridge::messages::GatewayFaults(1)),
            Fault::GatewayMode {
                expected: GatewayMode::ArmedValve,
                reported: GatewayMode::Disarmed,
            },
            Fault::ArmTimeout(ArmMode::Valve),
            Fault::Bus(BusFault::BusOff),
            Fault::Control(ControlFault::Kinematics("test")),
            Fault::Shutdown,
            Fault::GatewayFrozen {
                alive_counter: 3,
                frozen_s: 0.5,
            },
            Fault::AddressLost {
                address: 0x27,
                winner_name: 0,
            },
            Fault::AddressIntrusion {
                address: 0x80,
                name: 0,
                owner_lost: true,
            },
            Fault::ImplausibleSensor(Implausible::Jump {
                joint: crate::step::plausibility::SensedJoint::Boom,
                jump_rad: 0.1,
                allowed_rad: 0.03,
            }),
        ];
        let mut table = vec![(0, "Healthy".to_owned())];
        for fault in every_variant {
            let debug = format!("{fault:?}");
            let variant: String = debug
                .chars()
                .take_while(char::is_ascii_alphanumeric)
                .collect();
            // DM1 reports the fault code as the DTC of the same name (`gateway_core::dm1`).
            let dtc = firmware_bridge::dm1::CONTROLLER_DTCS[usize::from(fault.code()) - 1];
            assert_eq!(
                dtc.name,
                variant,
                "DM1 entry of fault code {}",
                fault.code()
            );
            table.push((i64::from(fault.code()), variant));
        }
        assert_eq!(table.len() - 1, firmware_bridge::dm1::CONTROLLER_DTCS.len());
        table.sort();
        assert_eq!(signal.value_table, table);
    }

    const PERIOD_S: f64 = CONTROL_PERIOD_S;
    /// A pose inside the default machine's limits.
    const Q: [f64; 3] = [0.3, -1.6, -0.9];

    struct Rig {
        est: Estimator,
        safety: Safety,
        gateway_mode: GatewayMode,
        faults: u16,
        status_alive: u8,
    }

    impl Rig {
        fn new(config: SafetyConfig) -> Self {
            let m = MachineConfig::default_machine().unwrap();
            let kin = Kinematics::new(&m).unwrap();
            let limits = Joint::ALL.map(|j| kin.joint_limits(j));
            Self {
                est: Estimator::new(kin, m.tracks.gauge_m, EstimatorConfig::default()).unwrap(),
                safety: Safety::new(config, limits).unwrap(),
                gateway_mode: GatewayMode::Disarmed,
                faults: 0,
                status_alive: 0,
            }
        }

        fn feed_sensors(&mut self, now_s: f64, q: [f64; 3]) {
            let msgs = [
                Message::JointAngles(JointAngles {
                    boom_rad: q[0],
                    stick_rad: q[1],
                    bucket_rad: q[2],
                    swing_rad: 0.0,
                }),
                Message::JointRates(JointRates::default()),
            ];
            for m in msgs {
                self.est.on_message(&m, now_s);
            }
            for c in Cylinder::ALL {
                let m = Message::AuxValveMeasured(AuxValveMeasured {
                    cylinder: c,
                    flow_percent: 0.0,
                    state: ValveState::Block,
                    head_pressure_pa: 5e6,
                    rod_pressure_pa: 1e6,
                });
                self.est.on_message(&m, now_s);
            }
        }

        fn feed_status(&mut self, now_s: f64) {
            self.status_alive = self.status_alive.wrapping_add(1);
            let s = Message::GatewayStatus(GatewayStatus {
                mode: self.gateway_mode,
                faults: GatewayFaults(self.faults),
                alive_counter: self.status_alive,
                unexpected_frames: 0,
                rejected_frames: 0,
            });
            self.est.on_message(&s, now_s);
        }

        /// One period: sensors (unless `dropout`), status, observe, tick; the simulated gateway
        /// follows the heartbeat request like `firmware_bridge::gateway`.
        fn period(&mut self, now_s: f64, want: Option<ArmMode>, dropout: bool) -> SafetyTick {
            if !dropout {
                self.feed_sensors(now_s, Q);
            }
            self.feed_status(now_s);
            self.est.update();
            self.safety.observe(now_s, &self.est);
            let t = self.safety.tick(now_s, want);
            if let Some(hb) = t.heartbeat {
                let estop = self.faults & GatewayFaults::E_STOP != 0;
                self.gateway_mode = match (hb.mode, self.gateway_mode) {
                    (RequestedMode::EStop, _) => {
                        self.faults |= GatewayFaults::E_STOP;
                        GatewayMode::Faulted
                    }
                    (RequestedMode::ResetEStop, GatewayMode::Faulted) => {
                        self.faults &= !GatewayFaults::E_STOP;
                        GatewayMode::Faulted
                    }
                    (RequestedMode::ResetEStop, _) => GatewayMode::Disarmed,
                    (_, mode) if estop => mode,
                    (RequestedMode::Disarm, _) => {
                        self.faults = 0;
                        GatewayMode::Disarmed
                    }
                    (_, GatewayMode::Faulted) => GatewayMode::Faulted,
                    (RequestedMode::ArmValve, _) => GatewayMode::ArmedValve,
                    (RequestedMode::ArmPosition, _) => GatewayMode::ArmedPosition,
                };
            }
            t
        }

        /// Runs periods from `t0` for `n` periods; returns the last tick and the end time.
        fn run(&mut self, t0: f64, n: usize, want: Option<ArmMode>) -> (SafetyTick, f64) {
            let mut t = t0;
            let mut last = None;
            for _ in 0..n {
                last = Some(self.period(t, want, false));
                t += PERIOD_S;
            }
            (last.unwrap(), t)
        }

        fn armed(config: SafetyConfig) -> (Self, f64) {
            let mut rig = Self::new(config);
            let (tick, t) = rig.run(0.0, 5, Some(ArmMode::Valve));
            assert_eq!(
                tick.motion,
                Some(ArmMode::Valve),
                "{:?}",
                rig.safety.state()
            );
            (rig, t)
        }
    }

    #[test]
    fn arming_waits_for_the_gateway_to_confirm() {
        let mut rig = Rig::new(SafetyConfig::default());
        // The first tick requests arming but motion waits for the status.
        let t0 = rig.period(0.0, Some(ArmMode::Valve), false);
        assert_eq!(t0.heartbeat.unwrap().mode, RequestedMode::ArmValve);
        assert_eq!(t0.motion, None);
        let t1 = rig.period(0.01, Some(ArmMode::Valve), false);
        assert_eq!(t1.motion, Some(ArmMode::Valve));
    }

    #[test]
    fn no_arming_without_fresh_sensors() {
        let mut rig = Rig::new(SafetyConfig::default());
        rig.feed_status(0.0);
        rig.est.update();
        rig.safety.observe(0.0, &rig.est);
        let t = rig.safety.tick(0.0, Some(ArmMode::Valve));
        assert_eq!(t.heartbeat.unwrap().mode, RequestedMode::Disarm);
        assert!(matches!(
            rig.safety.health(),
            Err(Fault::StaleSensor { .. })
        ));
    }

    #[test]
    fn heartbeat_goes_out_at_20_hz_and_its_counter_advances_by_one_per_heartbeat() {
        let mut rig = Rig::new(SafetyConfig::default());
        let mut prev = None;
        let mut sent = Vec::new();
        let mut t = 0.0;
        for k in 0..100 {
            if let Some(hb) = rig.period(t, Some(ArmMode::Valve), false).heartbeat {
                if let Some(p) = prev {
                    assert_eq!(hb.alive_counter, (p + 1) % 16);
                } else {
                    assert_eq!(hb.alive_counter, 0);
                }
                prev = Some(hb.alive_counter);
                sent.push(k);
            }
            t += PERIOD_S;
        }
        // Every 5th period (20 Hz) apart from the mode changes (disarm -> arm), sent at once; never a
        // gap near the gateway's 100 ms watchdog.
        assert!((19..=23).contains(&sent.len()), "{sent:?}");
        assert!(sent.windows(2).all(|w| w[1] - w[0] <= 5), "{sent:?}");
    }

    #[test]
    fn a_fault_sends_the_disarm_heartbeat_in_the_same_period() {
        let (mut rig, t) = Rig::armed(SafetyConfig::default());
        let mut now = t;
        for _ in 0..20 {
            let tick = rig.period(now, Some(ArmMode::Valve), true);
            if tick.motion.is_none() {
                assert_eq!(tick.heartbeat.map(|h| h.mode), Some(RequestedMode::Disarm));
                return;
            }
            now += PERIOD_S;
        }
        panic!("no stop");
    }

    #[test]
    fn sensor_dropout_stops_motion_after_the_configured_age() {
        let (mut rig, t) = Rig::armed(SafetyConfig::default());
        let mut now = t;
        let mut neutral_at = None;
        for k in 0..10 {
            let tick = rig.period(now, Some(ArmMode::Valve), true);
            if tick.motion.is_none() {
                assert!(tick.send_neutral);
                assert_eq!(tick.heartbeat.unwrap().mode, RequestedMode::Disarm);
                neutral_at = Some(k);
                break;
            }
            now += PERIOD_S;
        }
        // Last data at t - PERIOD; stale once older than 0.03 s (3 periods, up to rounding): neutral
        // within one period of the configured age.
        let k = neutral_at.expect("neutral");
        assert!((2..=3).contains(&k), "{k}");
        assert!(matches!(
            rig.safety.active_fault(),
            Some(Fault::StaleSensor { .. })
        ));
    }

    /// Under the simulation policy (`auto_rearm`), a transient fault re-arms on its own once the
    /// cause has cleared, through a fresh handshake.
    #[test]
    fn motion_resumes_only_after_the_cause_clears_and_a_new_handshake() {
        let (mut rig, t) = Rig::armed(SafetyConfig {
            auto_rearm: true,
            ..SafetyConfig::default()
        });
        rig.safety.report(
            t,
            Fault::Decode {
                id: 0x0CFF_5080,
                error: DecodeError::RemoteFrame,
            },
        );
        let (tick, t2) = rig.run(t, 1, Some(ArmMode::Valve));
        assert!(tick.send_neutral && tick.motion.is_none());
        // Not before clear_hold_s.
        let (tick, t3) = rig.run(t2, 40, Some(ArmMode::Valve));
        assert!(tick.motion.is_none());
        // Then Disarmed -> Arming -> Armed.
        let mut armed_at = None;
        let mut now = t3;
        for _ in 0..30 {
            let tick = rig.period(now, Some(ArmMode::Valve), false);
            if tick.motion.is_some() {
                armed_at = Some(now);
                break;
            }
            now += PERIOD_S;
        }
        let armed_at = armed_at.expect("re-armed");
        assert!(armed_at - t >= 0.5, "{armed_at} {t}");
    }

    #[test]
    fn joint_limit_stops_motion() {
        let (mut rig, t) = Rig::armed(SafetyConfig::default());
        rig.feed_sensors(t, [Q[0], -3.0, Q[2]]);
        rig.feed_status(t);
        rig.est.update();
        rig.safety.observe(t, &rig.est);
        let tick = rig.safety.tick(t, Some(ArmMode::Valve));
        assert!(tick.send_neutral && tick.motion.is_none());
        assert!(matches!(
            rig.safety.active_fault(),
            Some(Fault::JointLimit {
                joint: Joint::Stick,
                ..
            })
        ));
    }

    #[test]
    fn estop_latches_until_reset() {
        // A heartbeat every period, so the last period's shows the request.
        let (mut rig, t) = Rig::armed(SafetyConfig {
            heartbeat_period_s: PERIOD_S,
            ..SafetyConfig::default()
        });
        rig.safety.request_estop(t);
        let (tick, t2) = rig.run(t, 100, Some(ArmMode::Valve));
        assert_eq!(tick.heartbeat.unwrap().mode, RequestedMode::EStop);
        assert!(tick.motion.is_none());
        assert_eq!(rig.gateway_mode, GatewayMode::Faulted);
        rig.safety.reset();
        // The requests after the reset: ResetEStop, then Disarm, then ArmValve (#23 finding 5).
        let mut requests: Vec<RequestedMode> = Vec::new();
        let mut t = t2;
        let mut tick = None;
        for _ in 0..100 {
            let tk = rig.period(t, Some(ArmMode::Valve), false);
            if let Some(hb) = tk.heartbeat
                && requests.last() != Some(&hb.mode)
            {
                requests.push(hb.mode);
            }
            tick = Some(tk);
            t += PERIOD_S;
        }
        assert_eq!(
            requests,
            [
                RequestedMode::ResetEStop,
                RequestedMode::Disarm,
                RequestedMode::ArmValve
            ]
        );
        assert_eq!(tick.unwrap().motion, Some(ArmMode::Valve));
    }

    /// #23 finding 5, both sides: the safety layer and the real gateway firmware, heartbeats as frames,
    /// status at 20 Hz. Disarm does not clear the gateway's e-stop; the operator's reset does, through
    /// ResetEStop, Disarm, Arm.
    #[test]
    fn estop_reset_with_the_gateway_firmware_goes_reset_disarm_arm() {
        use firmware_bridge::gateway::{Gateway, VALVES};
        use firmware_bridge::messages::{AuxValveCommand, Valve};
        use firmware_bridge::secoc::{Sealer, SessionKey};
        /// What the gateway saw and did: requested modes (each change once) and the boom output
        /// of every 1 ms gateway tick.
        #[derive(Default)]
        struct Log {
            requests: Vec<RequestedMode>,
            boom: Vec<f64>,
        }
        fn run(rig: &mut Rig, gw: &mut Gateway, t: &mut f64, periods: u32, log: &mut Log) {
            // The frames sealed for the gateway's session, as the node sends them.
            let mut sealer = Sealer::new(&SessionKey::PUBLIC);
            for k in 0..periods {
                sealer.set_session(gw.session().session_id);
                rig.feed_sensors(*t, Q);
                if k % 5 == 0 {
                    let status = Message::GatewayStatus(gw.next_status());
                    rig.est.on_message(&status, *t);
                }
                rig.est.update();
                rig.safety.observe(*t, &rig.est);
                let tick = rig.safety.tick(*t, Some(ArmMode::Valve));
                if tick.motion == Some(ArmMode::Valve) {
                    let cmd = AuxValveCommand::from_fraction(Valve::Boom, 1.0).unwrap();
                    let frame = sealer.seal(&Message::AuxValveCommand(cmd)).unwrap();
                    gw.on_frame(&frame, *t);
                }
                if let Some(hb) = tick.heartbeat {
                    let frame = sealer.seal(&Message::ControllerHeartbeat(hb)).unwrap();
                    gw.on_frame(&frame, *t);
                    if log.requests.last() != Some(&hb.mode) {
                        log.requests.push(hb.mode);
                    }
                }
                for ms in 0..10 {
                    let out = gw.tick(*t + f64::from(ms) * 0.001, None);
                    log.boom.push(out.valve_commands[0]);
                    assert!(out.valve_commands[1..VALVES].iter().all(|u| *u == 0.0));
                }
                *t += PERIOD_S;
            }
        }
        let mut rig = Rig::new(SafetyConfig::default());
        let mut gw =
            Gateway::with_default_config(&mut firmware_bridge::secoc::SeededNonceSource(0));
        let mut log = Log::default();
        let mut t = 0.0;
        run(&mut rig, &mut gw, &mut t, 100, &mut log);
        assert_eq!(gw.mode(), GatewayMode::ArmedValve);
        assert_eq!(log.boom.last(), Some(&1.0));
        rig.safety.request_estop(t);
        run(&mut rig, &mut gw, &mut t, 200, &mut log);
        assert!(gw.faults().contains(GatewayFaults::E_STOP));
        assert_eq!(gw.mode(), GatewayMode::Faulted);
        assert_eq!(log.boom.last(), Some(&0.0));
        log.requests.clear();
        rig.safety.reset();
        run(&mut rig, &mut gw, &mut t, 200, &mut log);
        assert_eq!(
            log.requests,
            [
                RequestedMode::ResetEStop,
                RequestedMode::Disarm,
                RequestedMode::ArmValve
            ]
        );
        assert_eq!(gw.mode(), GatewayMode::ArmedValve);
        assert!(gw.faults().is_empty());
        assert_eq!(log.boom.last(), Some(&1.0));
    }

    /// Regression: after an e-stop and a controller restart the new process showed "Disarmed, fault
    /// none" and its reset never sent ResetEStop, so the gateway stayed faulted until a power cycle.
    /// The restarted controller reads the latched e-stop from the gateway's status.
    #[test]
    fn a_restarted_controller_shows_the_gateways_estop_and_its_reset_clears_it() {
        // The gateway as the first controller's e-stop left it; a fresh safety layer starts.
        let mut rig = Rig::new(SafetyConfig::default());
        rig.gateway_mode = GatewayMode::Faulted;
        rig.faults = GatewayFaults::E_STOP;
        let (tick, t) = rig.run(0.0, 20, Some(ArmMode::Valve));
        assert!(
            matches!(
                rig.safety.state(),
                SafetyState::Faulted {
                    fault: Fault::EStop,
                    ..
                }
            ),
            "{:?}",
            rig.safety.state()
        );
        assert!(rig.safety.needs_reset());
        assert_eq!(tick.motion, None);
        rig.safety.reset();
        let mut requests = Vec::new();
        let mut t = t;
        for _ in 0..200 {
            let tick = rig.period(t, Some(ArmMode::Valve), false);
            if let Some(hb) = tick.heartbeat
                && requests.last() != Some(&hb.mode)
            {
                requests.push(hb.mode);
            }
            t += PERIOD_S;
        }
        assert_eq!(
            requests.first(),
            Some(&RequestedMode::ResetEStop),
            "{requests:?}"
        );
        assert_eq!(
            rig.faults & GatewayFaults::E_STOP,
            0,
            "the gateway's e-stop cleared"
        );
        assert_eq!(rig.safety.motion(), Some(ArmMode::Valve), "{requests:?}");
    }

    /// Regression: an e-stop given while already faulted (e.g. a stale sensor) was latched but
    /// reported as the older fault.
    #[test]
    fn an_estop_while_faulted_is_reported_as_the_latest_reason() {
        let (mut rig, t) = Rig::armed(SafetyConfig::default());
        rig.safety.report(t, Fault::ArmTimeout(ArmMode::Valve));
        assert!(matches!(
            rig.safety.state(),
            SafetyState::Faulted {
                fault: Fault::ArmTimeout(_),
                ..
            }
        ));
        rig.safety.request_estop(t + 0.01);
        assert!(matches!(
            rig.safety.state(),
            SafetyState::Faulted {
                fault: Fault::EStop,
                ..
            }
        ));
        assert_eq!(rig.safety.last_fault(), Some(Fault::EStop));
    }

    /// #20: a gateway whose status keeps coming with the same alive counter is not running.
    #[test]
    fn a_frozen_gateway_status_stops_motion_and_blocks_arming() {
        let (mut rig, t) = Rig::armed(SafetyConfig::default());
        let frozen = rig.status_alive;
        let mut now = t;
        let mut stopped_at = None;
        for _ in 0..100 {
            // The status goes on arriving every period, fresh by age, with the same counter.
            rig.status_alive = frozen.wrapping_sub(1);
            let tick = rig.period(now, Some(ArmMode::Valve), false);
            if tick.motion.is_none() {
                stopped_at = Some(now);
                break;
            }
            now += PERIOD_S;
        }
        let stopped_at = stopped_at.expect("a frozen gateway went unnoticed");
        let frozen_s = stopped_at - (t - PERIOD_S);
        assert!(
            frozen_s > SafetyConfig::default().status_max_age_s && frozen_s < 0.4,
            "{frozen_s}"
        );
        assert!(matches!(
            rig.safety.active_fault(),
            Some(Fault::GatewayFrozen { alive_counter, .. }) if alive_counter == frozen
        ));
        // Still frozen: no re-arming.
        let mut now = stopped_at;
        for _ in 0..200 {
            rig.status_alive = frozen.wrapping_sub(1);
            assert!(
                rig.period(now, Some(ArmMode::Valve), false)
                    .motion
                    .is_none()
            );
            now += PERIOD_S;
        }
        assert!(matches!(
            rig.safety.health(),
            Err(Fault::GatewayFrozen { .. })
        ));
        // Running again (the counter advances): it waits for the operator, then re-arms.
        let (tick, now) = rig.run(now, 100, Some(ArmMode::Valve));
        assert!(tick.motion.is_none() && rig.safety.needs_reset());
        rig.safety.acknowledge();
        let (tick, _) = rig.run(now, 100, Some(ArmMode::Valve));
        assert_eq!(tick.motion, Some(ArmMode::Valve));
    }

    #[test]
    fn gateway_fault_bits_stop_motion_and_are_acknowledged() {
        let (mut rig, t) = Rig::armed(SafetyConfig::default());
        rig.gateway_mode = GatewayMode::Faulted;
        rig.faults = GatewayFaults::WATCHDOG_TIMEOUT;
        rig.feed_status(t);
        rig.feed_sensors(t, Q);
        rig.est.update();
        rig.safety.observe(t, &rig.est);
        assert_eq!(
            rig.safety.active_fault(),
            Some(Fault::GatewayFault(GatewayFaults(
                GatewayFaults::WATCHDOG_TIMEOUT
            )))
        );
        let tick = rig.safety.tick(t, Some(ArmMode::Valve));
        assert!(tick.send_neutral);
        assert_eq!(tick.heartbeat.unwrap().mode, RequestedMode::Disarm);
    }

    #[test]
    fn gateway_leaving_the_mode_is_a_fault() {
        let (mut rig, t) = Rig::armed(SafetyConfig::default());
        rig.gateway_mode = GatewayMode::Disarmed;
        let tick = rig.period(t, Some(ArmMode::Valve), false);
        assert!(tick.motion.is_none());
        assert!(matches!(
            rig.safety.active_fault(),
            Some(Fault::GatewayMode { .. })
        ));
    }

    #[test]
    fn bus_faults_stop_motion_but_warnings_do_not() {
        assert!(bus_fault_stops_motion(BusFault::BusOff));
        assert!(bus_fault_stops_motion(BusFault::ErrorPassive));
        assert!(bus_fault_stops_motion(BusFault::NoAck));
        assert!(!bus_fault_stops_motion(BusFault::ErrorWarning));
        let (mut rig, t) = Rig::armed(SafetyConfig::default());
        rig.safety.report(t, Fault::Bus(BusFault::BusOff));
        let tick = rig.period(t, Some(ArmMode::Valve), false);
        assert!(tick.send_neutral && tick.motion.is_none());
    }

    #[test]
    fn arm_timeout_when_the_gateway_never_confirms() {
        let mut rig = Rig::new(SafetyConfig::default());
        let mut t = 0.0;
        for _ in 0..150 {
            rig.feed_sensors(t, Q);
            // The gateway stays disarmed (e.g. its heartbeat input is broken).
            rig.gateway_mode = GatewayMode::Disarmed;
            rig.feed_status(t);
            rig.est.update();
            rig.safety.observe(t, &rig.est);
            rig.safety.tick(t, Some(ArmMode::Valve));
            t += PERIOD_S;
        }
        assert_eq!(
            rig.safety.last_fault(),
            Some(Fault::ArmTimeout(ArmMode::Valve))
        );
    }

    #[test]
    fn listen_only_never_transmits() {
        let mut rig = Rig::new(SafetyConfig {
            listen_only: true,
            ..SafetyConfig::default()
        });
        let (tick, t) = rig.run(0.0, 10, Some(ArmMode::Valve));
        assert_eq!(
            tick,
            SafetyTick {
                heartbeat: None,
                motion: None,
                send_neutral: false,
                hold_position: false
            }
        );
        rig.safety.report(t, Fault::EStop);
        let tick = rig.safety.tick(t, Some(ArmMode::Valve));
        assert!(tick.heartbeat.is_none() && !tick.send_neutral);
        assert_eq!(rig.safety.last_fault(), Some(Fault::EStop));
    }

    /// #46 finding 7: one injected frame (a decode error) mid-motion stopped the machine and it
    /// re-armed 0.5 s later with no operator action. By default it stays neutral and disarmed, however
    /// long the cause has been clear, until the operator's resume.
    #[test]
    fn a_single_fault_mid_motion_stays_stopped_until_the_operators_resume() {
        let (mut rig, t) = Rig::armed(SafetyConfig::default());
        rig.safety.report(
            t,
            Fault::Decode {
                id: 0x0CFF_5080,
                error: DecodeError::RemoteFrame,
            },
        );
        let mut now = t;
        // 60 s with the cause clear from the first period on.
        for _ in 0..6000 {
            let tick = rig.period(now, Some(ArmMode::Valve), false);
            assert!(
                tick.motion.is_none(),
                "re-armed at {now} without the operator"
            );
            assert!(
                tick.heartbeat
                    .is_none_or(|h| h.mode == RequestedMode::Disarm),
                "{tick:?}"
            );
            now += PERIOD_S;
        }
        assert_eq!(rig.gateway_mode, GatewayMode::Disarmed);
        assert!(rig.safety.needs_reset() && !rig.safety.needs_full_reset());
        assert!(matches!(
            rig.safety.active_fault(),
            Some(Fault::Decode { .. })
        ));
        assert!(rig.safety.acknowledge());
        let (tick, _) = rig.run(now, 10, Some(ArmMode::Valve));
        assert_eq!(tick.motion, Some(ArmMode::Valve));
    }

    /// The simulation policy covers the stated transient faults only: after a joint limit, a gateway
    /// fault beyond its link's (joint, clock), an arm timeout or an e-stop it waits for the operator
    /// as well; a work-cycle fault
    /// re-arms on its own by default, and every automatic re-arm is counted.
    #[test]
    fn the_simulation_policy_recovers_transient_faults_only() {
        let sim = SafetyConfig {
            auto_rearm: true,
            ..SafetyConfig::default()
        };
        let transient = [
            Fault::StaleSensor {
                signal: Signal::JointAngles,
                age_s: 0.05,
            },
            Fault::Decode {
                id: 0x0CFF_5080,
                error: DecodeError::RemoteFrame,
            },
            Fault::UnexpectedFrame {
                id: 0x0CFF_5099,
                source_address: 0x99,
            },
            Fault::Bus(BusFault::NoAck),
            // The gateway's watchdog and a rejected frame (a VM's scheduling gap, a spoofed frame).
            Fault::GatewayFault(GatewayFaults(GatewayFaults::WATCHDOG_TIMEOUT)),
            Fault::GatewayFault(GatewayFaults(
                GatewayFaults::WATCHDOG_TIMEOUT | GatewayFaults::AUTH_FAILURE,
            )),
        ];
        let operator = [
            Fault::JointLimit {
                joint: Joint::Stick,
                angle_rad: -3.0,
            },
            Fault::GatewayFault(GatewayFaults(GatewayFaults::JOINT_LIMIT)),
            Fault::GatewayFault(GatewayFaults(
                GatewayFaults::WATCHDOG_TIMEOUT | GatewayFaults::CLOCK_FAULT,
            )),
            Fault::GatewayFault(GatewayFaults(0)),
            Fault::GatewayMode {
                expected: GatewayMode::ArmedValve,
                reported: GatewayMode::Disarmed,
            },
            Fault::GatewayFrozen {
                alive_counter: 3,
                frozen_s: 0.5,
            },
            Fault::ArmTimeout(ArmMode::Valve),
            Fault::EStop,
        ];
        let resumes = |config: SafetyConfig, fault: Fault| {
            let (mut rig, t) = Rig::armed(config);
            rig.safety.report(t, fault);
            let (tick, _) = rig.run(t, 300, Some(ArmMode::Valve));
            tick.motion.is_some()
        };
        for f in transient {
            assert!(f.transient() && f.recovery() == Recovery::Transient, "{f}");
            assert!(resumes(sim, f), "{f} not recovered under auto_rearm");
            assert!(
                !resumes(SafetyConfig::default(), f),
                "{f} re-armed by default"
            );
        }
        for f in operator {
            assert!(!f.transient(), "{f}");
            assert!(!resumes(sim, f), "{f} re-armed under auto_rearm");
        }
        let control = Fault::Control(ControlFault::Timeout("test"));
        assert_eq!(control.recovery(), Recovery::WorkCycle);
        assert!(resumes(SafetyConfig::default(), control));
        // A transient stop followed by a gateway's joint-limit fault while stopped: the stricter
        // rule applies.
        let (mut rig, t) = Rig::armed(sim);
        rig.safety.report(t, transient[0]);
        rig.safety.report(t + PERIOD_S, operator[1]);
        let (tick, _) = rig.run(t, 300, Some(ArmMode::Valve));
        assert!(tick.motion.is_none() && rig.safety.needs_reset());
        // Counted: after max_auto_rearms in a row it waits for the operator.
        let (mut rig, mut t) = Rig::armed(SafetyConfig {
            max_auto_rearms: 2,
            ..sim
        });
        for k in 0..3 {
            rig.safety.report(t, transient[1]);
            let (tick, t2) = rig.run(t, 100, Some(ArmMode::Valve));
            assert_eq!(tick.motion.is_some(), k < 2, "re-arm {k}");
            t = t2;
        }
        assert!(rig.safety.needs_reset());
    }

    /// The operator's resume acknowledges an ordinary stop but not an e-stop, which takes a reset.
    #[test]
    fn resume_does_not_clear_an_estop() {
        let (mut rig, t) = Rig::armed(SafetyConfig::default());
        rig.safety.request_estop(t);
        let (_, t2) = rig.run(t, 100, Some(ArmMode::Valve));
        assert!(!rig.safety.acknowledge());
        let (tick, t3) = rig.run(t2, 100, Some(ArmMode::Valve));
        assert!(tick.motion.is_none() && rig.safety.needs_full_reset());
        rig.safety.reset();
        let (tick, _) = rig.run(t3, 100, Some(ArmMode::Valve));
        assert_eq!(tick.motion, Some(ArmMode::Valve));
    }

    #[test]
    fn without_auto_rearm_a_reset_is_needed() {
        let (mut rig, t) = Rig::armed(SafetyConfig {
            auto_rearm: false,
            ..SafetyConfig::default()
        });
        rig.safety.report(t, Fault::Bus(BusFault::NoAck));
        let (tick, t2) = rig.run(t, 200, Some(ArmMode::Valve));
        assert!(tick.motion.is_none());
        assert!(rig.safety.needs_reset());
        rig.safety.reset();
        let (tick, _) = rig.run(t2, 10, Some(ArmMode::Valve));
        assert_eq!(tick.motion, Some(ArmMode::Valve));
    }

    /// Regression (#20): the hold setpoint went out in the period of the `ArmPosition` request, ahead
    /// of the heartbeat, and the gateway (not yet in position mode) rejected it at every switch.
    #[test]
    fn position_mode_arming_holds_position_from_the_period_after_the_request() {
        let mut rig = Rig::new(SafetyConfig::default());
        let tick = rig.period(0.0, Some(ArmMode::Position), false);
        assert!(!tick.hold_position, "a setpoint would precede the request");
        assert_eq!(tick.heartbeat.unwrap().mode, RequestedMode::ArmPosition);
        // Until a status confirms (none arrives in this period): setpoints holding the joints.
        let tick = rig.safety.tick(0.01, Some(ArmMode::Position));
        assert!(tick.hold_position && tick.motion.is_none());
        let tick = rig.period(0.02, Some(ArmMode::Position), false);
        assert_eq!(tick.motion, Some(ArmMode::Position));
        // Switching from valve to position mode: the same.
        let (mut rig, t) = Rig::armed(SafetyConfig::default());
        let tick = rig.period(t, Some(ArmMode::Position), false);
        assert_eq!(tick.heartbeat.unwrap().mode, RequestedMode::ArmPosition);
        assert!(tick.send_neutral && !tick.hold_position);
        assert!(
            rig.safety
                .tick(t + PERIOD_S, Some(ArmMode::Position))
                .hold_position
        );
    }

    #[test]
    fn shutdown_sends_neutral_and_disarm() {
        let (mut rig, t) = Rig::armed(SafetyConfig::default());
        rig.safety.shutdown(t);
        let tick = rig.period(t, Some(ArmMode::Valve), false);
        assert!(tick.send_neutral && tick.motion.is_none());
        assert_eq!(tick.heartbeat.unwrap().mode, RequestedMode::Disarm);
        rig.safety.reset();
        assert_eq!(rig.safety.state(), SafetyState::Shutdown);
    }
}
