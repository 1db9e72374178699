//! Typed excavator messages and their encoding to and from CAN frames.
//!
//! Every message goes through the descriptors generated from `excavator.dbc` ([`crate::dbc`]); nothing
//! here knows a bit position or a scale factor. Units are SI (`docs/ARCHITECTURE.md`) except the valve
//! flows, which are percent of rated flow as in ISO 11783-7.
//!
//! Decoding ([`Message::decode`]) never panics and returns a small `Copy` [`DecodeError`]; encoding
//! ([`Message::encode`]) rejects out-of-range values with an [`EncodeError`] instead of clamping them.

use crate::address_claim::Name;
use crate::dbc::{self, MessageDesc, SignalDesc};
use crate::frame::{CanFrame, CanId, FrameKind};
use crate::id::J1939Id;

pub use crate::dbc::{DecodeError, EncodeError};

/// Defines a `Copy` enum whose variants are the values of one DBC enumeration signal, with a
/// `from_raw` that maps a raw signal value to its variant.
///
/// The first variant listed is the one for raw 0 and for any value outside the listed ones: every
/// caller has already checked the raw value against the signal's DBC range, so the fallback is only
/// reached for values the DBC allows but leaves unnamed.
macro_rules! signal_enum {
    (
        $(#[$meta:meta])*
        pub enum $name:ident {
            $(#[$first_meta:meta])*
            $first:ident = $first_value:literal,
            $( $(#[$variant_meta:meta])* $variant:ident = $value:literal, )*
        }
    ) => {
        $(#[$meta])*
        pub enum $name {
            $(#[$first_meta])*
            $first = $first_value,
            $( $(#[$variant_meta])* $variant = $value, )*
        }

        impl $name {
            /// Every state, in the order of their raw values.
            pub const ALL: &'static [Self] = &[Self::$first, $( Self::$variant, )*];

            /// The state's name in the DBC's value table of its signal (a test checks the table).
            pub const fn name(self) -> &'static str {
                match self {
                    Self::$first => stringify!($first),
                    $( Self::$variant => stringify!($variant), )*
                }
            }

            fn from_raw(raw: i64) -> Self {
                match raw {
                    $( $value => Self::$variant, )*
                    _ => Self::$first,
                }
            }
        }
    };
}

/// The six valve sections, in the valve-number order of the ISO 11783-7 PGNs (PGN 65072 + number).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Valve {
    /// Valve 0: boom cylinder.
    Boom = 0,
    /// Valve 1: stick cylinder.
    Stick = 1,
    /// Valve 2: bucket cylinder.
    Bucket = 2,
    /// Valve 3: swing motor.
    Swing = 3,
    /// Valve 4: left track motor.
    LeftTrack = 4,
    /// Valve 5: right track motor.
    RightTrack = 5,
}

impl Valve {
    /// All valves in number order (the array order of `docs/ARCHITECTURE.md`).
    pub const ALL: [Valve; 6] = [
        Self::Boom,
        Self::Stick,
        Self::Bucket,
        Self::Swing,
        Self::LeftTrack,
        Self::RightTrack,
    ];

    /// The ISO 11783-7 valve number.
    pub const fn number(self) -> u8 {
        self as u8
    }

    /// The valve with this number.
    pub const fn from_number(number: u8) -> Option<Self> {
        match number {
            0 => Some(Self::Boom),
            1 => Some(Self::Stick),
            2 => Some(Self::Bucket),
            3 => Some(Self::Swing),
            4 => Some(Self::LeftTrack),
            5 => Some(Self::RightTrack),
            _ => None,
        }
    }
}

/// The three implement cylinders that report measured flow and port pressures.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Cylinder {
    /// Valve 0: boom cylinder.
    Boom = 0,
    /// Valve 1: stick cylinder.
    Stick = 1,
    /// Valve 2: bucket cylinder.
    Bucket = 2,
}

impl Cylinder {
    /// All cylinders, `[boom, stick, bucket]`.
    pub const ALL: [Cylinder; 3] = [Self::Boom, Self::Stick, Self::Bucket];

    /// The ISO 11783-7 valve number.
    pub const fn number(self) -> u8 {
        self as u8
    }
}

signal_enum! {
    /// ISO 11783-7 valve state.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
    pub enum ValveState {
        /// Block (neutral): both work ports closed.
        Block = 0,
        /// Flow to the extend port (cylinder extends).
        Extend = 1,
        /// Flow to the retract port (cylinder retracts).
        Retract = 2,
        /// Float: both work ports to tank.
        Float = 3,
    }
}

signal_enum! {
    /// ISO 11783-7 fail-safe mode: what the valve does when commands stop arriving.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
    pub enum FailSafeMode {
        /// Go to block (neutral). The project always uses this.
        Block = 0,
        /// Go to float.
        Float = 1,
    }
}

signal_enum! {
    /// Gateway operating mode.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
    pub enum GatewayMode {
        /// Valves held neutral; commands ignored.
        Disarmed = 0,
        /// Valve commands from the controller are applied.
        ArmedValve = 1,
        /// The gateway's closed-loop position control follows [`PositionSetpoint`].
        ArmedPosition = 2,
        /// A fault latched; valves neutral until the controller disarms.
        Faulted = 3,
    }
}

signal_enum! {
    /// The mode the controller asks the gateway for.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
    pub enum RequestedMode {
        /// Go to disarmed (valves neutral).
        Disarm = 0,
        /// Arm and apply valve commands.
        ArmValve = 1,
        /// Arm and follow position setpoints.
        ArmPosition = 2,
        /// Emergency stop: neutral valves and latch the `E_STOP` fault.
        EStop = 3,
        /// The operator's reset of a latched e-stop: clears `E_STOP` (the gateway stays Faulted
        /// until a `Disarm` acknowledges; then an arm request). Sent only on an operator reset.
        ResetEStop = 4,
    }
}

/// Gateway fault bits (the `FaultBits` signal of `GatewayStatus`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct GatewayFaults(pub u16);

impl GatewayFaults {
    /// No heartbeat within the watchdog period.
    pub const WATCHDOG_TIMEOUT: u16 = 1 << 0;
    /// A heartbeat with a wrong checksum.
    pub const BAD_CHECKSUM: u16 = 1 << 1;
    /// A heartbeat or setpoint whose alive counter did not advance by one.
    pub const BAD_ALIVE_COUNTER: u16 = 1 << 2;
    /// A valve command or setpoint older than allowed.
    pub const STALE_COMMAND: u16 = 1 << 3;
    /// Emergency stop requested or wired e-stop pressed.
    pub const E_STOP: u16 = 1 << 4;
    /// Bus-off, error passive or other bus error.
    pub const BUS_ERROR: u16 = 1 << 5;
    /// A joint reached a hard limit.
    pub const JOINT_LIMIT: u16 = 1 << 6;
    /// A position setpoint outside the joint range.
    pub const SETPOINT_OUT_OF_RANGE: u16 = 1 << 7;
    /// The gateway's time input was not finite or went backwards: its watchdog and staleness checks
    /// cannot be trusted, so it latched (in any mode).
    pub const CLOCK_FAULT: u16 = 1 << 8;
    /// A secured frame from the controller's address that did not verify for this session and a fresh
    /// counter: replayed, recorded in another session, from a second sender, or without the key
    /// ([`crate::secoc`]).
    pub const AUTH_FAILURE: u16 = 1 << 9;
    /// Another node with a lower NAME claimed the gateway's address (J1939-81,
    /// [`crate::address_claim`]): the gateway sent Cannot Claim and acts on nothing and sends nothing
    /// else until a Request for Address Claimed to global makes it claim again and that claim has
    /// stood 250 ms; then its status reports the bit until the controller's `Disarm`.
    pub const ADDRESS_LOST: u16 = 1 << 10;

    /// True if every bit of `bits` is set.
    pub const fn contains(self, bits: u16) -> bool {
        self.0 & bits == bits
    }

    /// True if no fault bit is set.
    pub const fn is_empty(self) -> bool {
        self.0 == 0
    }

    /// With `bits` added.
    pub const fn with(self, bits: u16) -> Self {
        Self(self.0 | bits)
    }
}

/// ISO 11783-7 Auxiliary Valve Command (PGN 65072 + valve number), controller to gateway.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AuxValveCommand {
    /// Which valve.
    pub valve: Valve,
    /// Port flow, percent of rated flow, `0..=100`. Sent both as the 0.4 %/bit standard byte and the
    /// 0.0025 %/bit fine flow in bytes 4-5.
    pub flow_percent: f64,
    /// Valve state (direction).
    pub state: ValveState,
    /// Fail-safe mode.
    pub fail_safe: FailSafeMode,
}

impl AuxValveCommand {
    /// Neutral (block, zero flow, fail-safe block): the command sent on any fault and at shutdown.
    pub const fn neutral(valve: Valve) -> Self {
        Self {
            valve,
            flow_percent: 0.0,
            state: ValveState::Block,
            fail_safe: FailSafeMode::Block,
        }
    }

    /// From a command in `[-1, 1]` (fraction of maximum cylinder velocity, positive = extend).
    ///
    /// # Errors
    /// [`EncodeError::NotFinite`] or [`EncodeError::OutOfRange`] outside `[-1, 1]`.
    pub fn from_fraction(valve: Valve, command: f64) -> Result<Self, EncodeError> {
        let signal = "command";
        if !command.is_finite() {
            return Err(EncodeError::NotFinite { signal });
        }
        if !(-1.0..=1.0).contains(&command) {
            return Err(EncodeError::OutOfRange {
                signal,
                value: command,
                min: -1.0,
                max: 1.0,
            });
        }
        let state = if command > 0.0 {
            ValveState::Extend
        } else if command < 0.0 {
            ValveState::Retract
        } else {
            ValveState::Block
        };
        Ok(Self {
            valve,
            flow_percent: command.abs() * 100.0,
            state,
            fail_safe: FailSafeMode::Block,
        })
    }

    /// The command as a fraction in `[-1, 1]`: `+flow` for extend, `-flow` for retract, 0 for block
    /// and float.
    pub fn to_fraction(&self) -> f64 {
        match self.state {
            ValveState::Extend => self.flow_percent / 100.0,
            ValveState::Retract => -self.flow_percent / 100.0,
            ValveState::Block | ValveState::Float => 0.0,
        }
    }
}

/// ISO 11783-7 Auxiliary Valve Measured Flow (PGN 65056 + valve number), gateway to controller.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AuxValveMeasured {
    /// Which cylinder.
    pub cylinder: Cylinder,
    /// Measured flow through the valve, percent of rated flow, `0..=160`.
    pub flow_percent: f64,
    /// Valve state the flow goes with.
    pub state: ValveState,
    /// Extend-port (cylinder head side) pressure, Pa, `0..=100e6`, 5 kPa resolution.
    pub head_pressure_pa: f64,
    /// Retract-port (cylinder rod side) pressure, Pa, `0..=100e6`, 5 kPa resolution.
    pub rod_pressure_pa: f64,
}

/// Resolver joint angles (Proprietary B PGN 0xFF50), rad, `[-pi, pi]`, 1e-4 rad resolution.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct JointAngles {
    /// Boom angle to base `x`.
    pub boom_rad: f64,
    /// Stick angle relative to the boom line.
    pub stick_rad: f64,
    /// Bucket angle relative to the stick line.
    pub bucket_rad: f64,
    /// Swing angle.
    pub swing_rad: f64,
}

/// Joint angular rates (Proprietary B PGN 0xFF51), rad/s, `[-32, 32]`, 1e-3 rad/s resolution.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct JointRates {
    /// Boom rate.
    pub boom_rad_per_s: f64,
    /// Stick rate.
    pub stick_rad_per_s: f64,
    /// Bucket rate.
    pub bucket_rad_per_s: f64,
    /// Swing rate.
    pub swing_rad_per_s: f64,
}

/// Main pump outlet pressures (Proprietary B PGN 0xFF52), Pa, `0..=64e6`, 1 kPa resolution.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PumpPressures {
    /// Pump 1 pressure.
    pub pump1_pa: f64,
    /// Pump 2 pressure.
    pub pump2_pa: f64,
}

/// Track odometry (Proprietary B PGN 0xFF53): signed travel since power-up, m, `+/-200 km`, 0.1 mm.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TrackOdometry {
    /// Left track travel (backwards negative).
    pub left_m: f64,
    /// Right track travel (backwards negative).
    pub right_m: f64,
}

/// Gateway status (Proprietary B PGN 0xFF54), 20 Hz.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GatewayStatus {
    /// Operating mode.
    pub mode: GatewayMode,
    /// Latched fault bits.
    pub faults: GatewayFaults,
    /// Alive counter, increments by one per status frame, wraps 255 -> 0.
    pub alive_counter: u8,
    /// Frames with an unknown id or from an unexpected source; saturating:
    /// [`GatewayStatus::FRAME_COUNT_SATURATED`] means that many or more.
    pub unexpected_frames: u16,
    /// Known frames rejected (bad DLC, range, checksum, counter, wrong kind for the mode); saturating:
    /// [`GatewayStatus::FRAME_COUNT_SATURATED`] means that many or more.
    pub rejected_frames: u16,
}

impl GatewayStatus {
    /// The frame counters stop here: 65535 reads "65535 or more" (DBC value name `Saturated`).
    pub const FRAME_COUNT_SATURATED: u16 = u16::MAX;

    /// True if `unexpected_frames` has saturated (the true count is 65535 or more).
    pub const fn unexpected_frames_saturated(&self) -> bool {
        self.unexpected_frames == Self::FRAME_COUNT_SATURATED
    }

    /// True if `rejected_frames` has saturated (the true count is 65535 or more).
    pub const fn rejected_frames_saturated(&self) -> bool {
        self.rejected_frames == Self::FRAME_COUNT_SATURATED
    }
}

/// Joint position setpoints for the gateway's closed-loop position mode (Proprietary B PGN 0xFF60),
/// rad: 13-bit fields so four angles, a freshness value and an authenticator fit 8 bytes (the
/// freshness is the sender's, [`crate::secoc`]). Boom, stick and bucket at 4e-4 rad around each
/// joint's working range (the DBC's offsets; a zero stick angle is outside it), swing at 8e-4 rad
/// over `[-pi, pi]`. No `Default`: the all-zero pose is not encodable.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PositionSetpoint {
    /// Boom angle setpoint.
    pub boom_rad: f64,
    /// Stick angle setpoint.
    pub stick_rad: f64,
    /// Bucket angle setpoint.
    pub bucket_rad: f64,
    /// Swing angle setpoint.
    pub swing_rad: f64,
}

/// Gateway session (Proprietary B PGN 0xFF55), 20 Hz with the status: the nonce that binds the
/// controller's secured frames to this session ([`crate::secoc`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct GatewaySession {
    /// The session's nonce.
    pub session_id: u32,
}

/// Controller heartbeat and mode request (Proprietary B PGN 0xFF61) with a 4-bit alive counter and a
/// CRC-8 SAE J1850 checksum (see [`heartbeat_checksum`]). The checksum is computed by
/// [`Message::encode`] and verified by [`Message::decode`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ControllerHeartbeat {
    /// Requested gateway mode.
    pub mode: RequestedMode,
    /// Alive counter `0..=15`, increments by one per heartbeat.
    pub alive_counter: u8,
}

impl ControllerHeartbeat {
    /// The heartbeat after this one: same mode, counter advanced by one (mod 16).
    pub const fn next(self, mode: RequestedMode) -> Self {
        Self {
            mode,
            alive_counter: (self.alive_counter + 1) % 16,
        }
    }

    /// Builds a valid heartbeat frame from the controller.
    ///
    /// # Errors
    /// [`EncodeError::OutOfRange`] if `alive_counter > 15`.
    pub fn to_frame(self) -> Result<CanFrame, EncodeError> {
        Message::ControllerHeartbeat(self).encode()
    }

    /// Decodes a frame that must be a valid heartbeat (id, DLC, ranges, checksum).
    ///
    /// # Errors
    /// Any [`DecodeError`]; a frame of another message gives [`DecodeError::UnknownPgn`].
    pub fn verify(frame: &CanFrame) -> Result<(J1939Id, Self), DecodeError> {
        let decoded = Message::decode(frame)?;
        match decoded.message {
            Message::ControllerHeartbeat(hb) => Ok((decoded.id, hb)),
            _ => Err(DecodeError::UnknownPgn {
                pgn: decoded.id.pgn(),
                id: decoded.id.raw(),
            }),
        }
    }
}

/// True if `next` is the successor of `prev` for an alive counter of `bits` bits (4 or 8).
pub const fn is_next_alive(prev: u8, next: u8, bits: u32) -> bool {
    let modulus = 1u16 << bits;
    (prev as u16 + 1) % modulus == next as u16
}

/// CRC-8 SAE J1850: polynomial 0x1D, initial value 0xFF, final XOR 0xFF, no reflection
/// (check value over `"123456789"` is 0x4B), from the `crc` crate's catalogue.
pub const CRC8_SAE_J1850: crc::Crc<u8> = crc::Crc::<u8>::new(&crc::CRC_8_SAE_J1850);

/// CRC-8 SAE J1850 ([`CRC8_SAE_J1850`]) over `bytes`.
pub fn crc8_sae_j1850(bytes: impl IntoIterator<Item = u8>) -> u8 {
    let mut digest = CRC8_SAE_J1850.digest();
    for byte in bytes {
        digest.update(&[byte]);
    }
    digest.finalize()
}

/// The heartbeat checksum: CRC-8 SAE J1850 over the PGN (3 bytes, least significant first) followed by
/// every data byte except the checksum byte itself, in order. Including the PGN means a frame with the
/// same bytes under another id does not pass as a heartbeat.
pub fn heartbeat_checksum(data: &[u8]) -> u8 {
    let pgn = dbc::controller_heartbeat::PGN;
    let checksum_byte = usize::from(dbc::controller_heartbeat::CHECKSUM.start_bit / 8);
    let pgn_bytes = [
        (pgn & 0xFF) as u8,
        ((pgn >> 8) & 0xFF) as u8,
        ((pgn >> 16) & 0xFF) as u8,
    ];
    let mut digest = CRC8_SAE_J1850.digest();
    digest.update(&pgn_bytes);
    let (before, from_checksum) = data.split_at(checksum_byte.min(data.len()));
    digest.update(before);
    digest.update(from_checksum.get(1..).unwrap_or_default());
    digest.finalize()
}

signal_enum! {
    /// What the controller is doing (the `Activity` signal of [`ControllerStatus`]).
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
    pub enum Activity {
        /// Not moving the machine.
        #[default]
        Idle = 0,
        /// Taking a range scan.
        Scan = 1,
        /// Swinging to the dig location.
        SwingToDig = 2,
        /// Autodig.
        Dig = 3,
        /// Floor cleanup (waypoint following, then Autodig from Pre-Dig).
        Cleanup = 4,
        /// Swinging to the spoil pile or truck.
        SwingToDump = 5,
        /// Dumping.
        Dump = 6,
        /// Returning from the dump.
        Return = 7,
        /// Tracking (driving) the machine.
        Track = 8,
        /// Halted by a fault; valves neutral.
        Faulted = 9,
        /// Held between actions by the operator's pause; valves neutral, disarmed.
        Paused = 10,
    }
}

signal_enum! {
    /// Autodig stage as sent on the bus (the `AutodigStage` signal of [`ControllerStatus`]).
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
    pub enum AutodigStageCode {
        /// Autodig not running.
        #[default]
        None = 0,
        /// Lowering the boom to the ground.
        BoomDown = 1,
        /// Pre-Dig: curling the bucket into the material.
        PreDig = 2,
        /// Dig: stick in, boom and bucket regulating load.
        Dig = 3,
        /// Capture: boom and bucket up.
        Capture = 4,
        /// Finished.
        Done = 5,
    }
}

/// Controller status (Proprietary B PGN 0xFF62, priority 6), 20 Hz: what the controller is doing, so
/// that a trace alone shows the work cycle and the Autodig stage of every sample.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ControllerStatus {
    /// Current activity of the work cycle.
    pub activity: Activity,
    /// Current Autodig stage.
    pub stage: AutodigStageCode,
    /// Number of the current dig (0 before the first), `0..=64255`.
    pub dig_index: u16,
    /// Autodig soil hardness index in use, `0..=12.5`, 0.05 resolution.
    pub hardness_index: f64,
    /// Swept volume integrated so far in this dig, m^3, `0..=6.4`, 1e-4 resolution.
    pub swept_volume_m3: f64,
    /// 0 when healthy, otherwise the controller's fault code (`0..=250`).
    pub fault_reason: u8,
    /// Alive counter `0..=15`.
    pub alive_counter: u8,
}

/// J1939-81 Address Claimed (PGN 60928): the sender's NAME. From the null address
/// ([`crate::address_claim::NULL_ADDRESS`]) it is Cannot Claim. See [`crate::address_claim`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AddressClaimed {
    /// The sender's NAME.
    pub name: Name,
}

/// J1939-21 Request (PGN 59904): asks the destination (or every node, to global) to send a PGN.
/// The project's nodes answer a request for Address Claimed (PGN 60928).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RequestPgn {
    /// The requested PGN (18 bits).
    pub pgn: u32,
}

signal_enum! {
    /// A J1939-73 lamp's status in DM1.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
    pub enum LampStatus {
        /// Off.
        Off = 0,
        /// On.
        On = 1,
        /// Reserved (J1939-73).
        Reserved = 2,
        /// The node has no such lamp.
        NotAvailable = 3,
    }
}

signal_enum! {
    /// A J1939-73 lamp's flash in DM1.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
    pub enum LampFlash {
        /// Slow flash (1 Hz).
        SlowFlash = 0,
        /// Fast flash (2 Hz or faster).
        FastFlash = 1,
        /// Reserved (J1939-73).
        Reserved = 2,
        /// Do not flash (the project's nodes always send this).
        DoNotFlash = 3,
    }
}

/// One lamp of DM1: its status and flash.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct LampState {
    /// On, off, not available.
    pub status: LampStatus,
    /// How it flashes.
    pub flash: LampFlash,
}

/// The four lamps of DM1 (J1939-73).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Lamps {
    /// Malfunction indicator lamp (emission-related faults).
    pub malfunction_indicator: LampState,
    /// Red stop lamp.
    pub red_stop: LampState,
    /// Amber warning lamp.
    pub amber_warning: LampState,
    /// Protect lamp (a non-electronic subsystem).
    pub protect: LampState,
}

/// One diagnostic trouble code (J1939-73, conversion method 0: the SPN's 19 bits are bytes 3, 4 and
/// the top 3 bits of byte 5, the DBC's `SpnLow` and `SpnHigh`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Dtc {
    /// Suspect parameter number, 19 bits.
    pub spn: u32,
    /// Failure mode identifier, 5 bits.
    pub fmi: u8,
    /// Occurrence count, 7 bits (127 is "not available").
    pub occurrence_count: u8,
}

impl Dtc {
    /// The DTC of a DM1 with no active fault: all zeros (J1939-73).
    pub const NONE: Self = Self {
        spn: 0,
        fmi: 0,
        occurrence_count: 0,
    };
}

/// J1939-73 DM1, active diagnostic trouble codes (PGN 65226 `0xFECA`, priority 6), one DTC in one
/// frame: from the gateway (`DM1_Gateway` in the DBC) and from the controller (`DM1`). See
/// [`crate::dm1`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Dm1 {
    /// Lamp status.
    pub lamps: Lamps,
    /// The active DTC ([`Dtc::NONE`] when none is).
    pub dtc: Dtc,
}

/// Every message of the protocol. Variant names are the names in `docs/protocol.md`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Message {
    /// ISO 11783-7 Auxiliary Valve Command.
    AuxValveCommand(AuxValveCommand),
    /// ISO 11783-7 Auxiliary Valve Measured Flow (with port pressures).
    AuxValveMeasured(AuxValveMeasured),
    /// Resolver joint angles.
    JointAngles(JointAngles),
    /// Joint angular rates.
    JointRates(JointRates),
    /// Pump pressures.
    PumpPressures(PumpPressures),
    /// Track odometry.
    TrackOdometry(TrackOdometry),
    /// Gateway status.
    GatewayStatus(GatewayStatus),
    /// Gateway session nonce.
    GatewaySession(GatewaySession),
    /// Position setpoints.
    PositionSetpoint(PositionSetpoint),
    /// Controller heartbeat.
    ControllerHeartbeat(ControllerHeartbeat),
    /// Controller status (activity, Autodig stage).
    ControllerStatus(ControllerStatus),
    /// J1939-81 Address Claimed (or Cannot Claim, from the null address).
    AddressClaimed(AddressClaimed),
    /// J1939-21 Request.
    RequestPgn(RequestPgn),
    /// J1939-73 DM1, active diagnostic trouble codes.
    Dm1(Dm1),
}

/// A decoded frame: the J1939 id (so receivers can check the source address), the message, and the
/// secured trailer of the controller's control messages.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Decoded {
    /// The frame's id.
    pub id: J1939Id,
    /// The message.
    pub message: Message,
    /// The freshness value and authenticator as received, for the messages that carry them
    /// (valve commands, position setpoints, heartbeats); `None` for the others. Checked by
    /// [`crate::secoc::Verifier`], not by the decoder.
    pub trailer: Option<Trailer>,
}

/// Most signals of one message (DM1 has thirteen: four lamps, their flash, the DTC's SPN in two parts,
/// FMI, occurrence count and conversion method); a test checks the DBC against it.
pub const MAX_SIGNALS: usize = 13;

/// A message's values by DBC signal name ([`Message::signal_values`]), held inline: at most
/// [`MAX_SIGNALS`] pairs, no heap. Dereferences to the slice of pairs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SignalValues {
    values: [(&'static str, f64); MAX_SIGNALS],
    len: usize,
}

impl SignalValues {
    /// The first [`MAX_SIGNALS`] of `values` (every message has fewer; the generated tables are
    /// checked against it).
    fn of(values: &[(&'static str, f64)]) -> Self {
        let mut out = Self {
            values: [("", 0.0); MAX_SIGNALS],
            len: values.len().min(MAX_SIGNALS),
        };
        out.values[..out.len].copy_from_slice(&values[..out.len]);
        out
    }
}

impl core::ops::Deref for SignalValues {
    type Target = [(&'static str, f64)];
    fn deref(&self) -> &Self::Target {
        &self.values[..self.len]
    }
}

impl core::ops::DerefMut for SignalValues {
    fn deref_mut(&mut self) -> &mut Self::Target {
        &mut self.values[..self.len]
    }
}

impl<'a> IntoIterator for &'a SignalValues {
    type Item = &'a (&'static str, f64);
    type IntoIter = core::slice::Iter<'a, (&'static str, f64)>;
    fn into_iter(self) -> Self::IntoIter {
        self.iter()
    }
}

impl IntoIterator for SignalValues {
    type Item = (&'static str, f64);
    type IntoIter = core::iter::Take<core::array::IntoIter<(&'static str, f64), MAX_SIGNALS>>;
    fn into_iter(self) -> Self::IntoIter {
        self.values.into_iter().take(self.len)
    }
}

impl Decoded {
    /// The values by DBC signal name, as [`Message::signal_values`] but with the trailer received.
    pub fn signal_values(&self) -> SignalValues {
        let mut values = self.message.signal_values();
        let Some(t) = self.trailer else {
            return values;
        };
        // The heartbeat's checksum covers the trailer: recompute it over the bytes as received.
        let checksum = trailer_signals(self.id.pgn()).and_then(|(fv, auth)| {
            let frame = self.message.encode().ok()?;
            let mut d: [u8; 8] = frame.data().try_into().ok()?;
            dbc::encode_raw(fv, i64::from(t.freshness), &mut d).ok()?;
            dbc::encode_raw(auth, i64::from(t.authenticator), &mut d).ok()?;
            Some(heartbeat_checksum(&d))
        });
        for (name, v) in values.iter_mut() {
            match *name {
                "FreshnessValue" => *v = f64::from(t.freshness),
                "Authenticator" => *v = f64::from(t.authenticator),
                "Checksum" => *v = checksum.map_or(f64::NAN, f64::from),
                _ => {}
            }
        }
        values
    }
}

/// The freshness value (the low bits of the sender's counter) and the truncated authenticator of a
/// secured message, raw as on the wire.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Trailer {
    /// `FreshnessValue`: the low 8 (setpoint: 4) bits of the sender's freshness counter.
    pub freshness: u8,
    /// `Authenticator`: the truncated CMAC, 24 (setpoint: 8) bits.
    pub authenticator: u32,
}

/// The trailer signals (`FreshnessValue`, `Authenticator`) of a secured message, by PGN.
pub(crate) fn trailer_signals(pgn: u32) -> Option<(&'static SignalDesc, &'static SignalDesc)> {
    use dbc::{controller_heartbeat as hb, position_setpoint as sp};
    if AUX_VALVE_COMMAND.iter().any(|m| m.pgn == pgn) {
        return Some((&cmd::FRESHNESS_VALUE, &cmd::AUTHENTICATOR));
    }
    match pgn {
        hb::PGN => Some((&hb::FRESHNESS_VALUE, &hb::AUTHENTICATOR)),
        sp::PGN => Some((&sp::FRESHNESS_VALUE, &sp::AUTHENTICATOR)),
        _ => None,
    }
}

/// The trailer of `data` for a message with these trailer signals (raw values; every raw value is in
/// range, the DBC ranges cover them all).
fn read_trailer(
    (fv, auth): (&'static SignalDesc, &'static SignalDesc),
    data: &[u8],
) -> Result<Trailer, DecodeError> {
    Ok(Trailer {
        freshness: raw_u8(fv, data)?,
        authenticator: u32::try_from(raw(auth, data)?).map_err(|_| DecodeError::OutOfRange {
            signal: auth.name,
            raw: -1,
        })?,
    })
}

const AUX_VALVE_COMMAND: [&MessageDesc; 6] = [
    &dbc::aux_valve_command_boom::MESSAGE,
    &dbc::aux_valve_command_stick::MESSAGE,
    &dbc::aux_valve_command_bucket::MESSAGE,
    &dbc::aux_valve_command_swing::MESSAGE,
    &dbc::aux_valve_command_left_track::MESSAGE,
    &dbc::aux_valve_command_right_track::MESSAGE,
];

const AUX_VALVE_MEASURED: [&MessageDesc; 3] = [
    &dbc::aux_valve_measured_boom::MESSAGE,
    &dbc::aux_valve_measured_stick::MESSAGE,
    &dbc::aux_valve_measured_bucket::MESSAGE,
];

// The six valve-command messages (and the three measured ones) share one layout; the boom modules'
// signal descriptors are used for all of them. `tests::valve_messages_share_one_layout` checks it.
mod cmd {
    pub use crate::dbc::aux_valve_command_boom::{
        AUTHENTICATOR, FAIL_SAFE_MODE, FRESHNESS_VALUE, PORT_FLOW_COMMAND, PORT_FLOW_COMMAND_FINE,
        VALVE_STATE,
    };
}
mod meas {
    pub use crate::dbc::aux_valve_measured_boom::{
        EXTEND_PORT_PRESSURE, MEASURED_FLOW, RETRACT_PORT_PRESSURE, VALVE_STATE,
    };
}

fn get(sig: &SignalDesc, data: &[u8]) -> Result<f64, DecodeError> {
    dbc::decode_physical(sig, data)
}

fn raw(sig: &SignalDesc, data: &[u8]) -> Result<i64, DecodeError> {
    dbc::decode_raw(sig, data)
}

/// Raw values of counters and bit fields fit their Rust type because the DBC range was checked.
fn raw_u16(sig: &SignalDesc, data: &[u8]) -> Result<u16, DecodeError> {
    let r = raw(sig, data)?;
    u16::try_from(r).map_err(|_| DecodeError::OutOfRange {
        signal: sig.name,
        raw: r,
    })
}

fn raw_u8(sig: &SignalDesc, data: &[u8]) -> Result<u8, DecodeError> {
    let r = raw(sig, data)?;
    u8::try_from(r).map_err(|_| DecodeError::OutOfRange {
        signal: sig.name,
        raw: r,
    })
}

impl Message {
    /// The DBC descriptor this message is sent with.
    pub fn descriptor(&self) -> &'static MessageDesc {
        match self {
            Self::AuxValveCommand(m) => AUX_VALVE_COMMAND[usize::from(m.valve.number())],
            Self::AuxValveMeasured(m) => AUX_VALVE_MEASURED[usize::from(m.cylinder.number())],
            Self::JointAngles(_) => &dbc::joint_angles::MESSAGE,
            Self::JointRates(_) => &dbc::joint_rates::MESSAGE,
            Self::PumpPressures(_) => &dbc::pump_pressures::MESSAGE,
            Self::TrackOdometry(_) => &dbc::track_odometry::MESSAGE,
            Self::GatewayStatus(_) => &dbc::gateway_status::MESSAGE,
            Self::GatewaySession(_) => &dbc::gateway_session::MESSAGE,
            Self::PositionSetpoint(_) => &dbc::position_setpoint::MESSAGE,
            Self::ControllerHeartbeat(_) => &dbc::controller_heartbeat::MESSAGE,
            Self::ControllerStatus(_) => &dbc::controller_status::MESSAGE,
            Self::AddressClaimed(_) => &dbc::address_claimed::MESSAGE,
            Self::RequestPgn(_) => &dbc::request_pgn::MESSAGE,
            // Both nodes' DM1 have one layout (`tests::dm1_messages_share_one_layout`): the
            // controller's descriptor, sent from either address with `encode_from`.
            Self::Dm1(_) => &dbc::dm1::MESSAGE,
        }
    }

    /// Encodes with the DBC's id: its priority and the sender's source address
    /// ([`crate::id::CONTROLLER_ADDRESS`] or [`crate::id::GATEWAY_ADDRESS`]).
    ///
    /// # Errors
    /// [`EncodeError`] for a value outside its signal's range; nothing is clamped.
    pub fn encode(&self) -> Result<CanFrame, EncodeError> {
        let desc = self.descriptor();
        self.encode_with_id(J1939Id::from_raw(desc.default_id)?)
    }

    /// Encodes with the DBC's priority and PGN but another source address.
    ///
    /// # Errors
    /// As [`Message::encode`].
    pub fn encode_from(&self, source_address: u8) -> Result<CanFrame, EncodeError> {
        let desc = self.descriptor();
        self.encode_with_id(J1939Id::from_raw(desc.default_id)?.with_source_address(source_address))
    }

    /// Encodes with an explicit id: a PDU1 message to one destination (a request), say.
    ///
    /// # Errors
    /// As [`Message::encode`].
    pub fn encode_with_id(&self, id: J1939Id) -> Result<CanFrame, EncodeError> {
        let desc = self.descriptor();
        // Unused bits are 1, the J1939 convention for reserved bits.
        let mut data = [0xFFu8; 8];
        self.encode_signals(&mut data)?;
        let len = usize::from(desc.dlc).min(data.len());
        // The id came from a `J1939Id` (<= 29 bits) and len <= 8, so this cannot fail; map anyway.
        CanFrame::new_data(CanId::Extended(id.raw()), &data[..len])
            .map_err(|_| EncodeError::Id(crate::id::IdError::TooLarge(id.raw())))
    }

    fn encode_signals(&self, d: &mut [u8; 8]) -> Result<(), EncodeError> {
        use dbc::encode_physical as put;
        match self {
            Self::AuxValveCommand(m) => {
                // The standard byte is derived from the fine raw value (not from the float) so that
                // decode -> encode reproduces the same bytes even at rounding ties.
                let fine_raw = dbc::physical_to_raw(&cmd::PORT_FLOW_COMMAND_FINE, m.flow_percent)?;
                let ratio =
                    libm::round(cmd::PORT_FLOW_COMMAND.factor / cmd::PORT_FLOW_COMMAND_FINE.factor)
                        as i64;
                dbc::encode_raw(
                    &cmd::PORT_FLOW_COMMAND,
                    (fine_raw + ratio / 2) / ratio.max(1),
                    d,
                )?;
                dbc::encode_raw(&cmd::PORT_FLOW_COMMAND_FINE, fine_raw, d)?;
                dbc::encode_raw(&cmd::VALVE_STATE, m.state as i64, d)?;
                dbc::encode_raw(&cmd::FAIL_SAFE_MODE, m.fail_safe as i64, d)?;
            }
            Self::AuxValveMeasured(m) => {
                put(&meas::MEASURED_FLOW, m.flow_percent, d)?;
                dbc::encode_raw(&meas::VALVE_STATE, m.state as i64, d)?;
                put(&meas::EXTEND_PORT_PRESSURE, m.head_pressure_pa, d)?;
                put(&meas::RETRACT_PORT_PRESSURE, m.rod_pressure_pa, d)?;
            }
            Self::JointAngles(m) => {
                use dbc::joint_angles as s;
                put(&s::BOOM_ANGLE, m.boom_rad, d)?;
                put(&s::STICK_ANGLE, m.stick_rad, d)?;
                put(&s::BUCKET_ANGLE, m.bucket_rad, d)?;
                put(&s::SWING_ANGLE, m.swing_rad, d)?;
            }
            Self::JointRates(m) => {
                use dbc::joint_rates as s;
                put(&s::BOOM_RATE, m.boom_rad_per_s, d)?;
                put(&s::STICK_RATE, m.stick_rad_per_s, d)?;
                put(&s::BUCKET_RATE, m.bucket_rad_per_s, d)?;
                put(&s::SWING_RATE, m.swing_rad_per_s, d)?;
            }
            Self::PumpPressures(m) => {
                use dbc::pump_pressures as s;
                put(&s::PUMP1_PRESSURE, m.pump1_pa, d)?;
                put(&s::PUMP2_PRESSURE, m.pump2_pa, d)?;
            }
            Self::TrackOdometry(m) => {
                use dbc::track_odometry as s;
                put(&s::LEFT_TRACK_TRAVEL, m.left_m, d)?;
                put(&s::RIGHT_TRACK_TRAVEL, m.right_m, d)?;
            }
            Self::GatewayStatus(m) => {
                use dbc::gateway_status as s;
                dbc::encode_raw(&s::MODE, m.mode as i64, d)?;
                dbc::encode_raw(&s::ALIVE_COUNTER, i64::from(m.alive_counter), d)?;
                dbc::encode_raw(&s::FAULT_BITS, i64::from(m.faults.0), d)?;
                dbc::encode_raw(&s::UNEXPECTED_FRAMES, i64::from(m.unexpected_frames), d)?;
                dbc::encode_raw(&s::REJECTED_FRAMES, i64::from(m.rejected_frames), d)?;
            }
            Self::GatewaySession(m) => {
                use dbc::gateway_session as s;
                dbc::encode_raw(&s::SESSION_ID, i64::from(m.session_id), d)?;
            }
            Self::PositionSetpoint(m) => {
                use dbc::position_setpoint as s;
                put(&s::BOOM_SETPOINT, m.boom_rad, d)?;
                put(&s::STICK_SETPOINT, m.stick_rad, d)?;
                put(&s::BUCKET_SETPOINT, m.bucket_rad, d)?;
                put(&s::SWING_SETPOINT, m.swing_rad, d)?;
            }
            Self::ControllerHeartbeat(m) => {
                use dbc::controller_heartbeat as s;
                dbc::encode_raw(&s::REQUESTED_MODE, m.mode as i64, d)?;
                dbc::encode_raw(&s::ALIVE_COUNTER, i64::from(m.alive_counter), d)?;
                let crc = heartbeat_checksum(&d[..]);
                dbc::encode_raw(&s::CHECKSUM, i64::from(crc), d)?;
            }
            Self::ControllerStatus(m) => {
                use dbc::controller_status as s;
                dbc::encode_raw(&s::ACTIVITY, m.activity as i64, d)?;
                dbc::encode_raw(&s::AUTODIG_STAGE, m.stage as i64, d)?;
                dbc::encode_raw(&s::DIG_INDEX, i64::from(m.dig_index), d)?;
                put(&s::HARDNESS_INDEX, m.hardness_index, d)?;
                put(&s::SWEPT_VOLUME, m.swept_volume_m3, d)?;
                dbc::encode_raw(&s::FAULT_REASON, i64::from(m.fault_reason), d)?;
                dbc::encode_raw(&s::ALIVE_COUNTER, i64::from(m.alive_counter), d)?;
            }
            Self::AddressClaimed(m) => {
                // The NAME's fields are the message's signals; they cover all 64 bits.
                let name = m.name.to_le_bytes();
                for sig in dbc::address_claimed::SIGNALS {
                    let raw = dbc::extract_raw(sig, &name).unwrap_or(0);
                    dbc::encode_raw(sig, raw, d)?;
                }
            }
            Self::RequestPgn(m) => {
                dbc::encode_raw(&dbc::request_pgn::REQUESTED_PGN, i64::from(m.pgn), d)?;
            }
            Self::Dm1(m) => {
                use dbc::dm1 as s;
                let lamps = [
                    (
                        &s::MALFUNCTION_INDICATOR_LAMP_STATUS,
                        &s::FLASH_MALFUNCTION_INDICATOR_LAMP,
                        m.lamps.malfunction_indicator,
                    ),
                    (
                        &s::RED_STOP_LAMP_STATUS,
                        &s::FLASH_RED_STOP_LAMP,
                        m.lamps.red_stop,
                    ),
                    (
                        &s::AMBER_WARNING_LAMP_STATUS,
                        &s::FLASH_AMBER_WARNING_LAMP,
                        m.lamps.amber_warning,
                    ),
                    (
                        &s::PROTECT_LAMP_STATUS,
                        &s::FLASH_PROTECT_LAMP,
                        m.lamps.protect,
                    ),
                ];
                for (status, flash, lamp) in lamps {
                    dbc::encode_raw(status, lamp.status as i64, d)?;
                    dbc::encode_raw(flash, lamp.flash as i64, d)?;
                }
                let spn = i64::from(m.dtc.spn);
                dbc::encode_raw(&s::SPN_LOW, spn & 0xFFFF, d)?;
                dbc::encode_raw(&s::SPN_HIGH, spn >> 16, d)?;
                dbc::encode_raw(&s::FMI, i64::from(m.dtc.fmi), d)?;
                dbc::encode_raw(&s::OCCURRENCE_COUNT, i64::from(m.dtc.occurrence_count), d)?;
                dbc::encode_raw(&s::CONVERSION_METHOD, 0, d)?;
            }
        }
        Ok(())
    }

    /// Decodes a frame. Never panics.
    ///
    /// # Errors
    /// [`DecodeError`]: error, remote or FD frame, 11-bit id, unknown PGN, wrong DLC, a signal out of
    /// range or "not available"/"error indicator", or a bad heartbeat checksum.
    pub fn decode(frame: &CanFrame) -> Result<Decoded, DecodeError> {
        let raw_id = match (frame.kind(), frame.id()) {
            (FrameKind::Error, _) => return Err(DecodeError::ErrorFrame(frame.error_class())),
            (FrameKind::Remote, _) => return Err(DecodeError::RemoteFrame),
            (FrameKind::Fd { .. }, _) => return Err(DecodeError::FdFrame),
            (FrameKind::Data, CanId::Standard(id)) => return Err(DecodeError::StandardId(id)),
            (FrameKind::Data, CanId::Extended(id)) => id,
        };
        // `CanId::Extended` never exceeds 29 bits by construction.
        let id = J1939Id::from_raw(raw_id)
            .map_err(|_| DecodeError::UnknownPgn { pgn: 0, id: raw_id })?;
        let pgn = id.pgn();
        let desc = dbc::message_by_pgn(pgn).ok_or(DecodeError::UnknownPgn { pgn, id: raw_id })?;
        let data = frame.data();
        if data.len() != usize::from(desc.dlc) {
            return Err(DecodeError::WrongDlc {
                message: desc.name,
                expected: desc.dlc,
                actual: data.len() as u8,
            });
        }
        let message = Self::decode_body(desc, data)?;
        let trailer = trailer_signals(pgn)
            .map(|signals| read_trailer(signals, data))
            .transpose()?;
        Ok(Decoded {
            id,
            message,
            trailer,
        })
    }

    fn decode_body(desc: &MessageDesc, d: &[u8]) -> Result<Self, DecodeError> {
        let unknown = DecodeError::UnknownPgn {
            pgn: desc.pgn,
            id: desc.default_id,
        };
        if let Some(n) = AUX_VALVE_COMMAND.iter().position(|m| m.pgn == desc.pgn) {
            let valve = Valve::from_number(n as u8).ok_or(unknown)?;
            let coarse = get(&cmd::PORT_FLOW_COMMAND, d)?;
            // Fine flow takes precedence; "not available" there means the sender only has the
            // standard 0.4 %/bit resolution.
            let flow_percent = match get(&cmd::PORT_FLOW_COMMAND_FINE, d) {
                Ok(fine) => fine,
                Err(DecodeError::NotAvailable { .. }) => coarse,
                Err(e) => return Err(e),
            };
            return Ok(Self::AuxValveCommand(AuxValveCommand {
                valve,
                flow_percent,
                state: ValveState::from_raw(raw(&cmd::VALVE_STATE, d)?),
                fail_safe: FailSafeMode::from_raw(raw(&cmd::FAIL_SAFE_MODE, d)?),
            }));
        }
        if let Some(n) = AUX_VALVE_MEASURED.iter().position(|m| m.pgn == desc.pgn) {
            let cylinder = *Cylinder::ALL.get(n).ok_or(unknown)?;
            return Ok(Self::AuxValveMeasured(AuxValveMeasured {
                cylinder,
                flow_percent: get(&meas::MEASURED_FLOW, d)?,
                state: ValveState::from_raw(raw(&meas::VALVE_STATE, d)?),
                head_pressure_pa: get(&meas::EXTEND_PORT_PRESSURE, d)?,
                rod_pressure_pa: get(&meas::RETRACT_PORT_PRESSURE, d)?,
            }));
        }
        Ok(match desc.pgn {
            dbc::joint_angles::PGN => {
                use dbc::joint_angles as s;
                Self::JointAngles(JointAngles {
                    boom_rad: get(&s::BOOM_ANGLE, d)?,
                    stick_rad: get(&s::STICK_ANGLE, d)?,
                    bucket_rad: get(&s::BUCKET_ANGLE, d)?,
                    swing_rad: get(&s::SWING_ANGLE, d)?,
                })
            }
            dbc::joint_rates::PGN => {
                use dbc::joint_rates as s;
                Self::JointRates(JointRates {
                    boom_rad_per_s: get(&s::BOOM_RATE, d)?,
                    stick_rad_per_s: get(&s::STICK_RATE, d)?,
                    bucket_rad_per_s: get(&s::BUCKET_RATE, d)?,
                    swing_rad_per_s: get(&s::SWING_RATE, d)?,
                })
            }
            dbc::pump_pressures::PGN => {
                use dbc::pump_pressures as s;
                Self::PumpPressures(PumpPressures {
                    pump1_pa: get(&s::PUMP1_PRESSURE, d)?,
                    pump2_pa: get(&s::PUMP2_PRESSURE, d)?,
                })
            }
            dbc::track_odometry::PGN => {
                use dbc::track_odometry as s;
                Self::TrackOdometry(TrackOdometry {
                    left_m: get(&s::LEFT_TRACK_TRAVEL, d)?,
                    right_m: get(&s::RIGHT_TRACK_TRAVEL, d)?,
                })
            }
            dbc::gateway_status::PGN => {
                use dbc::gateway_status as s;
                Self::GatewayStatus(GatewayStatus {
                    mode: GatewayMode::from_raw(raw(&s::MODE, d)?),
                    alive_counter: raw_u8(&s::ALIVE_COUNTER, d)?,
                    faults: GatewayFaults(raw_u16(&s::FAULT_BITS, d)?),
                    unexpected_frames: raw_u16(&s::UNEXPECTED_FRAMES, d)?,
                    rejected_frames: raw_u16(&s::REJECTED_FRAMES, d)?,
                })
            }
            dbc::gateway_session::PGN => {
                use dbc::gateway_session as s;
                let raw_id = raw(&s::SESSION_ID, d)?;
                Self::GatewaySession(GatewaySession {
                    session_id: u32::try_from(raw_id).map_err(|_| DecodeError::OutOfRange {
                        signal: s::SESSION_ID.name,
                        raw: raw_id,
                    })?,
                })
            }
            dbc::position_setpoint::PGN => {
                use dbc::position_setpoint as s;
                Self::PositionSetpoint(PositionSetpoint {
                    boom_rad: get(&s::BOOM_SETPOINT, d)?,
                    stick_rad: get(&s::STICK_SETPOINT, d)?,
                    bucket_rad: get(&s::BUCKET_SETPOINT, d)?,
                    swing_rad: get(&s::SWING_SETPOINT, d)?,
                })
            }
            dbc::controller_heartbeat::PGN => {
                use dbc::controller_heartbeat as s;
                let received = raw_u8(&s::CHECKSUM, d)?;
                let computed = heartbeat_checksum(d);
                if received != computed {
                    return Err(DecodeError::BadChecksum { received, computed });
                }
                Self::ControllerHeartbeat(ControllerHeartbeat {
                    mode: RequestedMode::from_raw(raw(&s::REQUESTED_MODE, d)?),
                    alive_counter: raw_u8(&s::ALIVE_COUNTER, d)?,
                })
            }
            dbc::controller_status::PGN => {
                use dbc::controller_status as s;
                Self::ControllerStatus(ControllerStatus {
                    activity: Activity::from_raw(raw(&s::ACTIVITY, d)?),
                    stage: AutodigStageCode::from_raw(raw(&s::AUTODIG_STAGE, d)?),
                    dig_index: raw_u16(&s::DIG_INDEX, d)?,
                    hardness_index: get(&s::HARDNESS_INDEX, d)?,
                    swept_volume_m3: get(&s::SWEPT_VOLUME, d)?,
                    fault_reason: raw_u8(&s::FAULT_REASON, d)?,
                    alive_counter: raw_u8(&s::ALIVE_COUNTER, d)?,
                })
            }
            dbc::address_claimed::PGN => {
                // Every raw value of the NAME's fields is valid; check them through the codec all
                // the same, and take the NAME from the bytes they cover.
                for sig in dbc::address_claimed::SIGNALS {
                    raw(sig, d)?;
                }
                let mut bytes = [0u8; 8];
                let n = d.len().min(8);
                bytes[..n].copy_from_slice(&d[..n]);
                Self::AddressClaimed(AddressClaimed {
                    name: Name::from_le_bytes(bytes),
                })
            }
            dbc::request_pgn::PGN => {
                let pgn = raw(&dbc::request_pgn::REQUESTED_PGN, d)?;
                Self::RequestPgn(RequestPgn {
                    pgn: u32::try_from(pgn).map_err(|_| DecodeError::OutOfRange {
                        signal: dbc::request_pgn::REQUESTED_PGN.name,
                        raw: pgn,
                    })?,
                })
            }
            dbc::dm1::PGN => {
                use dbc::dm1 as s;
                let lamp =
                    |status: &SignalDesc, flash: &SignalDesc| -> Result<LampState, DecodeError> {
                        Ok(LampState {
                            status: LampStatus::from_raw(raw(status, d)?),
                            flash: LampFlash::from_raw(raw(flash, d)?),
                        })
                    };
                // Conversion method 1 is the SPN layout of J1939-73's first editions: its SPN
                // cannot be read as the one meant.
                let cm = raw(&s::CONVERSION_METHOD, d)?;
                if cm != 0 {
                    return Err(DecodeError::OutOfRange {
                        signal: s::CONVERSION_METHOD.name,
                        raw: cm,
                    });
                }
                let spn = raw(&s::SPN_LOW, d)? | (raw(&s::SPN_HIGH, d)? << 16);
                Self::Dm1(Dm1 {
                    lamps: Lamps {
                        malfunction_indicator: lamp(
                            &s::MALFUNCTION_INDICATOR_LAMP_STATUS,
                            &s::FLASH_MALFUNCTION_INDICATOR_LAMP,
                        )?,
                        red_stop: lamp(&s::RED_STOP_LAMP_STATUS, &s::FLASH_RED_STOP_LAMP)?,
                        amber_warning: lamp(
                            &s::AMBER_WARNING_LAMP_STATUS,
                            &s::FLASH_AMBER_WARNING_LAMP,
                        )?,
                        protect: lamp(&s::PROTECT_LAMP_STATUS, &s::FLASH_PROTECT_LAMP)?,
                    },
                    dtc: Dtc {
                        spn: u32::try_from(spn).map_err(|_| DecodeError::OutOfRange {
                            signal: s::SPN_LOW.name,
                            raw: spn,
                        })?,
                        fmi: raw_u8(&s::FMI, d)?,
                        occurrence_count: raw_u8(&s::OCCURRENCE_COUNT, d)?,
                    },
                })
            }
            _ => return Err(unknown),
        })
    }

    /// The message's values by DBC signal name, as this decoder understands them (physical units of the
    /// DBC; enums and counters as their raw numbers). Used to compare with other DBC tools and to print
    /// traces. The heartbeat's `Checksum` and the trailer (`FreshnessValue`, `Authenticator`) are as
    /// [`Message::encode`] sends them, unsealed (all ones); [`Decoded::signal_values`] has the trailer
    /// received.
    pub fn signal_values(&self) -> SignalValues {
        const UNSEALED_FRESHNESS: f64 = 255.0;
        const UNSEALED_AUTHENTICATOR: f64 = 16_777_215.0;
        match self {
            Self::AuxValveCommand(m) => SignalValues::of(&[
                ("PortFlowCommand", m.flow_percent),
                ("FreshnessValue", UNSEALED_FRESHNESS),
                ("ValveState", f64::from(m.state as u8)),
                ("FailSafeMode", f64::from(m.fail_safe as u8)),
                ("PortFlowCommandFine", m.flow_percent),
                ("Authenticator", UNSEALED_AUTHENTICATOR),
            ]),
            Self::AuxValveMeasured(m) => SignalValues::of(&[
                ("MeasuredFlow", m.flow_percent),
                ("ValveState", f64::from(m.state as u8)),
                ("ExtendPortPressure", m.head_pressure_pa),
                ("RetractPortPressure", m.rod_pressure_pa),
            ]),
            Self::JointAngles(m) => SignalValues::of(&[
                ("BoomAngle", m.boom_rad),
                ("StickAngle", m.stick_rad),
                ("BucketAngle", m.bucket_rad),
                ("SwingAngle", m.swing_rad),
            ]),
            Self::JointRates(m) => SignalValues::of(&[
                ("BoomRate", m.boom_rad_per_s),
                ("StickRate", m.stick_rad_per_s),
                ("BucketRate", m.bucket_rad_per_s),
                ("SwingRate", m.swing_rad_per_s),
            ]),
            Self::PumpPressures(m) => {
                SignalValues::of(&[("Pump1Pressure", m.pump1_pa), ("Pump2Pressure", m.pump2_pa)])
            }
            Self::TrackOdometry(m) => SignalValues::of(&[
                ("LeftTrackTravel", m.left_m),
                ("RightTrackTravel", m.right_m),
            ]),
            Self::GatewayStatus(m) => SignalValues::of(&[
                ("Mode", f64::from(m.mode as u8)),
                ("AliveCounter", f64::from(m.alive_counter)),
                ("FaultBits", f64::from(m.faults.0)),
                ("UnexpectedFrames", f64::from(m.unexpected_frames)),
                ("RejectedFrames", f64::from(m.rejected_frames)),
            ]),
            Self::GatewaySession(m) => SignalValues::of(&[("SessionId", f64::from(m.session_id))]),
            Self::PositionSetpoint(m) => SignalValues::of(&[
                ("BoomSetpoint", m.boom_rad),
                ("StickSetpoint", m.stick_rad),
                ("BucketSetpoint", m.bucket_rad),
                ("SwingSetpoint", m.swing_rad),
                ("FreshnessValue", 15.0),
                ("Authenticator", 255.0),
            ]),
            Self::ControllerHeartbeat(m) => {
                let checksum = self
                    .encode()
                    .ok()
                    .and_then(|f| f.data().get(7).copied())
                    .map_or(f64::NAN, f64::from);
                SignalValues::of(&[
                    ("RequestedMode", f64::from(m.mode as u8)),
                    ("AliveCounter", f64::from(m.alive_counter)),
                    ("FreshnessValue", UNSEALED_FRESHNESS),
                    ("Authenticator", UNSEALED_AUTHENTICATOR),
                    ("Checksum", checksum),
                ])
            }
            Self::ControllerStatus(m) => SignalValues::of(&[
                ("Activity", f64::from(m.activity as u8)),
                ("AutodigStage", f64::from(m.stage as u8)),
                ("DigIndex", f64::from(m.dig_index)),
                ("HardnessIndex", m.hardness_index),
                ("SweptVolume", m.swept_volume_m3),
                ("FaultReason", f64::from(m.fault_reason)),
                ("AliveCounter", f64::from(m.alive_counter)),
            ]),
            Self::AddressClaimed(m) => {
                let f = m.name.fields();
                let reserved =
                    dbc::extract_raw(&dbc::address_claimed::RESERVED, &m.name.to_le_bytes())
                        .unwrap_or(0);
                SignalValues::of(&[
                    ("IdentityNumber", f64::from(f.identity_number)),
                    ("ManufacturerCode", f64::from(f.manufacturer_code)),
                    ("EcuInstance", f64::from(f.ecu_instance)),
                    ("FunctionInstance", f64::from(f.function_instance)),
                    ("Function", f64::from(f.function)),
                    ("Reserved", reserved as f64),
                    ("VehicleSystem", f64::from(f.vehicle_system)),
                    (
                        "VehicleSystemInstance",
                        f64::from(f.vehicle_system_instance),
                    ),
                    ("IndustryGroup", f64::from(f.industry_group)),
                    (
                        "ArbitraryAddressCapable",
                        f64::from(u8::from(f.arbitrary_address_capable)),
                    ),
                ])
            }
            Self::RequestPgn(m) => SignalValues::of(&[("RequestedPgn", f64::from(m.pgn))]),
            Self::Dm1(m) => {
                let l = &m.lamps;
                let status = |s: LampState| f64::from(s.status as u8);
                let flash = |s: LampState| f64::from(s.flash as u8);
                SignalValues::of(&[
                    ("ProtectLampStatus", status(l.protect)),
                    ("AmberWarningLampStatus", status(l.amber_warning)),
                    ("RedStopLampStatus", status(l.red_stop)),
                    (
                        "MalfunctionIndicatorLampStatus",
                        status(l.malfunction_indicator),
                    ),
                    ("FlashProtectLamp", flash(l.protect)),
                    ("FlashAmberWarningLamp", flash(l.amber_warning)),
                    ("FlashRedStopLamp", flash(l.red_stop)),
                    (
                        "FlashMalfunctionIndicatorLamp",
                        flash(l.malfunction_indicator),
                    ),
                    ("SpnLow", f64::from(m.dtc.spn & 0xFFFF)),
                    ("Fmi", f64::from(m.dtc.fmi)),
                    ("SpnHigh", f64::from(m.dtc.spn >> 16)),
                    ("OccurrenceCount", f64::from(m.dtc.occurrence_count)),
                    ("ConversionMethod", 0.0),
                ])
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::vec::Vec;

    #[test]
    fn every_message_fits_signal_values() {
        for desc in dbc::MESSAGES {
            assert!(desc.signals.len() <= MAX_SIGNALS, "{}", desc.name);
        }
    }

    /// Boom extend at 50 %: flow byte 125, reserved 0xFF, state 1 with fail-safe block and reserved bits
    /// 4-5 set, fine flow 20000 = 0x4E20, reserved bytes 6-8.
    const BOOM_EXTEND_HALF: [u8; 8] = [0x7D, 0xFF, 0x31, 0x20, 0x4E, 0xFF, 0xFF, 0xFF];

    #[test]
    fn boom_command_matches_the_documented_bytes() {
        let msg =
            Message::AuxValveCommand(AuxValveCommand::from_fraction(Valve::Boom, 0.5).unwrap());
        let frame = msg.encode().unwrap();
        assert_eq!(frame.id(), CanId::Extended(0x0CFE_3027));
        assert_eq!(frame.data(), &BOOM_EXTEND_HALF);
        let decoded = Message::decode(&frame).unwrap();
        assert_eq!(decoded.id.source_address(), crate::id::CONTROLLER_ADDRESS);
        assert_eq!(decoded.message, msg);
    }

    #[test]
    fn coarse_flow_is_used_when_fine_flow_is_not_available() {
        let mut data = BOOM_EXTEND_HALF;
        data[3] = 0xFF;
        data[4] = 0xFF;
        let frame = CanFrame::new_extended(0x0CFE_3027, &data).unwrap();
        let Message::AuxValveCommand(cmd) = Message::decode(&frame).unwrap().message else {
            panic!("not a valve command");
        };
        assert_eq!(cmd.flow_percent, 50.0);
    }

    #[test]
    fn coarse_flow_byte_is_stable_at_a_rounding_tie() {
        // 40.5995 % quantizes to a fine value of 40.6 %, which sits exactly between two 0.4 % steps;
        // re-encoding the decoded command once flipped the standard byte from 101 to 102.
        let msg = Message::AuxValveCommand(AuxValveCommand {
            flow_percent: 40.599_544,
            ..AuxValveCommand::neutral(Valve::Boom)
        });
        let frame = msg.encode().unwrap();
        let again = Message::decode(&frame).unwrap().message.encode().unwrap();
        assert_eq!(again, frame);
    }

    #[test]
    fn crc8_sae_j1850_check_value() {
        assert_eq!(crc8_sae_j1850(*b"123456789"), 0x4B);
    }

    /// Arm-valve, alive counter 5 (the fixture in docs/protocol.md).
    const HEARTBEAT_ARM_VALVE_5: [u8; 8] = [0x51, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0x16];

    #[test]
    fn heartbeat_matches_the_documented_bytes() {
        let hb = ControllerHeartbeat {
            mode: RequestedMode::ArmValve,
            alive_counter: 5,
        };
        let frame = hb.to_frame().unwrap();
        assert_eq!(frame.id(), CanId::Extended(0x0CFF_6127));
        assert_eq!(frame.data(), &HEARTBEAT_ARM_VALVE_5);
    }

    #[test]
    fn heartbeat_with_a_flipped_bit_is_rejected() {
        let hb = ControllerHeartbeat {
            mode: RequestedMode::ArmValve,
            alive_counter: 7,
        };
        let frame = hb.to_frame().unwrap();
        assert_eq!(ControllerHeartbeat::verify(&frame).unwrap().1, hb);
        let mut data = [0u8; 8];
        data.copy_from_slice(frame.data());
        data[0] ^= 0x10; // alive counter 7 -> 6
        let bad = CanFrame::new_extended(0x0CFF_6127, &data).unwrap();
        assert!(matches!(
            Message::decode(&bad),
            Err(DecodeError::BadChecksum { .. })
        ));
    }

    #[test]
    fn alive_counter_successor() {
        assert!(is_next_alive(15, 0, 4));
        assert!(is_next_alive(255, 0, 8));
        assert!(!is_next_alive(3, 5, 4));
    }

    #[test]
    fn non_j1939_frames_give_typed_errors() {
        let std_frame = CanFrame::new_standard(0x123, &[0; 8]).unwrap();
        assert_eq!(
            Message::decode(&std_frame),
            Err(DecodeError::StandardId(0x123))
        );
        let rtr = CanFrame::new_remote(CanId::Extended(0x0CFE_3027), 8).unwrap();
        assert_eq!(Message::decode(&rtr), Err(DecodeError::RemoteFrame));
        let err = CanFrame::new_error(0x40, [0; 8]).unwrap();
        assert_eq!(Message::decode(&err), Err(DecodeError::ErrorFrame(0x40)));
        let short = CanFrame::new_extended(0x0CFE_3027, &[0; 4]).unwrap();
        assert!(matches!(
            Message::decode(&short),
            Err(DecodeError::WrongDlc { actual: 4, .. })
        ));
        let unknown = CanFrame::new_extended(0x0CFE_4027, &[0; 8]).unwrap();
        assert!(matches!(
            Message::decode(&unknown),
            Err(DecodeError::UnknownPgn { pgn: 0xFE40, .. })
        ));
    }

    #[test]
    fn not_available_angle_is_reported() {
        let frame = CanFrame::new_extended(0x0CFF_5080, &[0xFF, 0x7F, 0, 0, 0, 0, 0, 0]).unwrap();
        assert_eq!(
            Message::decode(&frame),
            Err(DecodeError::NotAvailable {
                signal: "BoomAngle"
            })
        );
    }

    #[test]
    fn valve_messages_share_one_layout() {
        let strip = |s: &SignalDesc| {
            (
                s.start_bit,
                s.len,
                s.signed,
                s.factor.to_bits(),
                s.raw_min,
                s.raw_max,
                s.name,
            )
        };
        for group in [&AUX_VALVE_COMMAND[..], &AUX_VALVE_MEASURED[..]] {
            for (n, desc) in group.iter().enumerate() {
                assert_eq!(desc.pgn, group[0].pgn + n as u32, "{}", desc.name);
                let a: Vec<_> = desc.signals.iter().map(strip).collect();
                let b: Vec<_> = group[0].signals.iter().map(strip).collect();
                assert_eq!(a, b, "{} differs from {}", desc.name, group[0].name);
            }
        }
    }

    #[test]
    fn dm1_messages_share_one_layout() {
        let strip = |s: &SignalDesc| (s.start_bit, s.len, s.signed, s.raw_min, s.raw_max, s.name);
        let a: Vec<_> = dbc::dm1::SIGNALS.iter().map(strip).collect();
        let b: Vec<_> = dbc::dm1_gateway::SIGNALS.iter().map(strip).collect();
        assert_eq!(a, b);
        assert_eq!(dbc::dm1::PGN, crate::dm1::DM1_PGN);
        assert_eq!(dbc::dm1_gateway::PGN, crate::dm1::DM1_PGN);
        assert_eq!(dbc::dm1::MESSAGE.default_id, 0x18FE_CA27);
        assert_eq!(dbc::dm1_gateway::MESSAGE.default_id, 0x18FE_CA80);
    }

    /// The gateway's e-stop as DM1 (docs/protocol.md): red stop lamp on, no flash, SPN 520196 =
    /// `0x7F004` (bytes 3-4 `04 F0`, its top 3 bits 7 over FMI 31 in byte 5: `FF`), occurrence 1.
    const GATEWAY_ESTOP_DM1: [u8; 8] = [0x10, 0xFF, 0x04, 0xF0, 0xFF, 0x01, 0xFF, 0xFF];
    /// No active fault: lamps off, DTC all zeros (J1939-73).
    const NO_FAULT_DM1: [u8; 8] = [0x00, 0xFF, 0x00, 0x00, 0x00, 0x00, 0xFF, 0xFF];

    #[test]
    fn dm1_matches_the_documented_bytes_and_round_trips() {
        let off = LampState {
            status: LampStatus::Off,
            flash: LampFlash::DoNotFlash,
        };
        let estop = Dm1 {
            lamps: Lamps {
                malfunction_indicator: off,
                red_stop: LampState {
                    status: LampStatus::On,
                    ..off
                },
                amber_warning: off,
                protect: off,
            },
            dtc: Dtc {
                spn: 520_196,
                fmi: 31,
                occurrence_count: 1,
            },
        };
        let frame = Message::Dm1(estop)
            .encode_from(crate::id::GATEWAY_ADDRESS)
            .unwrap();
        assert_eq!(frame.id(), CanId::Extended(0x18FE_CA80));
        assert_eq!(frame.data(), &GATEWAY_ESTOP_DM1);
        assert_eq!(
            Message::decode(&frame).unwrap().message,
            Message::Dm1(estop)
        );
        let none = Dm1 {
            lamps: Lamps {
                malfunction_indicator: off,
                red_stop: off,
                amber_warning: off,
                protect: off,
            },
            dtc: Dtc::NONE,
        };
        let frame = Message::Dm1(none).encode().unwrap();
        assert_eq!(frame.id(), CanId::Extended(0x18FE_CA27));
        assert_eq!(frame.data(), &NO_FAULT_DM1);
        // The SPN layout of conversion method 1 is not read as if it were the current one.
        let mut old_layout = NO_FAULT_DM1;
        old_layout[5] = 0x80;
        let frame = CanFrame::new_extended(0x18FE_CA80, &old_layout).unwrap();
        assert!(matches!(
            Message::decode(&frame),
            Err(DecodeError::OutOfRange {
                signal: "ConversionMethod",
                ..
            })
        ));
    }

    #[test]
    fn a_frame_names_the_dbc_message_of_its_source_address() {
        let name = |id: u32| dbc::MESSAGES[dbc::message_index_by_id(id).unwrap()].name;
        assert_eq!(name(0x18EE_FF27), "AddressClaimed");
        assert_eq!(name(0x18EE_FF80), "AddressClaimed_Gateway");
        assert_eq!(name(0x18EE_FFFE), "AddressClaimed");
        assert_eq!(name(0x18FE_CA27), "DM1");
        assert_eq!(name(0x18FE_CA80), "DM1_Gateway");
        assert_eq!(name(0x18FE_CA00), "DM1");
    }

    #[test]
    fn out_of_range_values_are_not_clamped() {
        let msg = Message::JointAngles(JointAngles {
            boom_rad: 4.0,
            ..Default::default()
        });
        assert!(matches!(
            msg.encode(),
            Err(EncodeError::OutOfRange {
                signal: "BoomAngle",
                ..
            })
        ));
        let hb = ControllerHeartbeat {
            mode: RequestedMode::Disarm,
            alive_counter: 16,
        };
        assert!(hb.to_frame().is_err());
        assert!(AuxValveCommand::from_fraction(Valve::Boom, 1.5).is_err());
    }
}
