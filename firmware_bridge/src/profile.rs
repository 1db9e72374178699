//! A machine profile: which message and signal of a gateway's DBC carries each quantity the controller
//! and the simulator exchange, loaded at run time, and the translation between the project's
//! protocol and that gateway's frames.
//!
//! The controller and the simulator speak the project's protocol ([`crate::messages`], compiled from
//! `excavator.dbc`: the *canonical* frames). A profile names another DBC (the *wire* protocol) and
//! maps every signal of every canonical message to a wire signal, a constant, and a linear unit
//! conversion. [`Profile::to_wire`] and [`Profile::from_wire`] translate frames at the transport
//! boundary, so nothing above the bus changes and a trace of the bus shows the wire frames.
//!
//! ```text
//! node --canonical frame--> Profile::to_wire --wire frame--> bus (trace records this)
//! node <--canonical frame-- Profile::from_wire <--wire frame-- bus
//! ```
//!
//! # Lossless where it must be
//!
//! The control frames (valve commands, position setpoint, heartbeat) carry a freshness value, an
//! authenticator over the canonical frame's id and bytes, and the heartbeat an alive counter and a
//! CRC over its canonical bytes ([`crate::secoc`]). The receiving end rebuilds the canonical frame
//! from the wire frame and checks those, so each of their signals must come through unchanged: the
//! profile must map it to a wire signal of at least as many bits and the same signedness whose raw
//! grid is the canonical grid in the wire's units (`wire factor = factor * scale`,
//! `wire offset = offset * scale + conversion offset`), or to a constant that the sender always
//! uses. A profile that does not is refused at load. Sensor and status frames may lose resolution
//! (degrees in hundredths, say); J1939 "not available" values map to the wire signal's
//! all-ones (unsigned) or largest (signed) value and back.
//!
//! # The file
//!
//! ```toml
//! dbc = "other_gateway.dbc"             # relative to this file
//!
//! [messages.JointAngles]                # a canonical message
//! wire = "ArmAngles"                    # the wire message carrying it
//! [messages.JointAngles.signals]
//! BoomAngle = { signal = "BoomDeg", scale = 57.29577951308232 }   # wire = canonical * scale + offset
//! ```
//!
//! A canonical signal left out maps to the wire signal of the same name with no conversion. Every
//! canonical message must be mapped, except J1939 network management (Address Claimed, Request:
//! [`crate::address_claim::is_network_management`]) and the J1939-73 DM1 ([`passes_through`]), which
//! are the same on every J1939 network and whose source address is part of their meaning (a Cannot
//! Claim comes from `0xFE`, a claim from whoever claims, a DM1 from the node whose faults it lists):
//! they may not be mapped. On a J1939 wire bus (the DBC's `ProtocolType` is `J1939`)
//! those frames pass through unchanged in both directions; on any other there is no address to claim,
//! so they are not sent ([`TranslateError::NotOnThisBus`]) and not taken from it.
//! `mux` picks the multiplexor value when the wire message is multiplexed. The format is documented
//! in `docs/machine-profile.md`.

use std::collections::BTreeMap;

/// Whether frames of `pgn` pass through every profile unchanged on a J1939 wire bus instead of being
/// mapped: J1939 network management ([`crate::address_claim::is_network_management`]) and DM1
/// ([`crate::dm1::DM1_PGN`]), standard messages whose source address is part of their meaning.
pub const fn passes_through(pgn: u32) -> bool {
    crate::address_claim::is_network_management(pgn) || pgn == crate::dm1::DM1_PGN
}
use std::path::{Path, PathBuf};

use serde::Deserialize;
use toml::Spanned;

use crate::dbc::{self, MessageDesc, SignalDesc};
use crate::frame::{CanFrame, CanId, FrameKind};
use crate::id::J1939Id;
use crate::secoc;
use crate::wire_dbc::{self, Mux, ValueKind, WireDbc, WireSignal};

/// The shipped default profile (the project's own DBC, every signal unchanged).
pub const DEFAULT_PROFILE_TEXT: &str = include_str!("../../profiles/default.toml");

/// Why a profile could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum ProfileError {
    /// A file could not be read. The cause is in the message, not also a `source`: printed with
    /// its chain (`{:#}`) it would show twice.
    #[error("{path}: {error}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        error: std::io::Error,
    },
    /// The profile's DBC could not be loaded.
    #[error("{path}: {error} (the DBC of {origin})")]
    Dbc {
        /// The DBC file.
        path: PathBuf,
        /// The profile naming it.
        origin: String,
        /// What is wrong with it.
        error: wire_dbc::LoadError,
    },
    /// The profile is not valid TOML, or a mapping is missing or wrong.
    #[error("{origin}{}: {message}", line.map(|l| format!(":{l}")).unwrap_or_default())]
    Invalid {
        /// The profile file.
        origin: String,
        /// The 1-based line the problem is on, when known.
        line: Option<usize>,
        /// What is missing or wrong, naming the quantity.
        message: String,
    },
}

/// Why a frame could not be translated. Each is counted by the caller as a rejected frame.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TranslateError {
    /// A wire frame whose id (and multiplexor value) the profile maps to no canonical message.
    #[error("unmapped frame {0}")]
    Unmapped(CanId),
    /// J1939 network management (an address claim, a request) for a wire bus that is not a J1939
    /// network: there are no addresses to claim there, so it is not sent (not an error).
    #[error("J1939 network management or DM1 {0}: the wire bus is not J1939")]
    NotOnThisBus(CanId),
    /// A frame of a known id with the wrong length or kind.
    #[error("{message}: {actual} data bytes, expected {expected}")]
    WrongLength {
        /// The message name.
        message: String,
        /// The expected length.
        expected: usize,
        /// The length received.
        actual: usize,
    },
    /// A canonical value that the wire signal cannot hold.
    #[error("{quantity}: value {value} does not fit wire signal {signal}")]
    NotRepresentable {
        /// `Message.Signal` of the canonical protocol.
        quantity: String,
        /// The wire signal.
        signal: String,
        /// The value in wire units.
        value: f64,
    },
    /// A canonical signal mapped to a constant carries another value.
    #[error("{quantity}: raw {raw}, but the profile maps it to the constant {constant}")]
    NotConstant {
        /// `Message.Signal` of the canonical protocol.
        quantity: String,
        /// The raw value in the frame.
        raw: i64,
        /// The profile's constant.
        constant: i64,
    },
}

/// The profile file as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ProfileFile {
    dbc: Spanned<String>,
    messages: Spanned<BTreeMap<String, Spanned<MessageEntry>>>,
    #[serde(default)]
    timeouts: Option<Spanned<TimeoutsEntry>>,
    #[serde(default)]
    addresses: Option<Spanned<AddressesEntry>>,
}

/// The J1939 addresses the wire DBC's ids must carry (checked, never rewritten).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct AddressesEntry {
    #[serde(default)]
    controller: Option<u8>,
    #[serde(default)]
    gateway: Option<u8>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct TimeoutsEntry {
    #[serde(default)]
    heartbeat_ms: Option<Spanned<i64>>,
    #[serde(default)]
    command_ms: Option<Spanned<i64>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct MessageEntry {
    wire: Spanned<String>,
    #[serde(default)]
    mux: Option<Spanned<u64>>,
    #[serde(default)]
    period_ms: Option<Spanned<i64>>,
    #[serde(default)]
    signals: BTreeMap<String, Spanned<SignalEntry>>,
}

#[derive(Debug, Deserialize)]
#[serde(untagged)]
enum SignalEntry {
    Name(String),
    Full(SignalMap),
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct SignalMap {
    signal: Option<String>,
    scale: Option<f64>,
    offset: Option<f64>,
    constant: Option<i64>,
}

/// How one canonical signal travels.
#[derive(Debug, Clone, PartialEq)]
enum Target {
    /// The raw integer unchanged (the grids coincide).
    Raw { wire: usize },
    /// Through the physical value: `wire = canonical * scale + offset`.
    Physical {
        wire: usize,
        scale: f64,
        offset: f64,
    },
    /// Not on the wire: always this raw value.
    Constant(i64),
}

#[derive(Debug, Clone, PartialEq)]
struct Field {
    canonical: &'static SignalDesc,
    target: Target,
}

/// One canonical message and where it travels.
#[derive(Debug, Clone, PartialEq)]
struct Route {
    canonical: &'static MessageDesc,
    wire: usize,
    mux: Option<u64>,
    fields: Vec<Field>,
    /// The message's period on this gateway, ms.
    period_ms: u32,
}

/// The longest period or timeout a profile may give, ms: slower than this no loop closes.
pub const MAX_PERIOD_MS: u32 = 10_000;
/// The longest watchdog (`timeouts.heartbeat_ms`, `timeouts.command_ms`), ms: they bound how long the
/// machine moves on after the controller falls silent, at most ISO 11783-7's 100 ms.
pub const MAX_TIMEOUT_MS: u32 = 100;
/// The range of a signal's `scale` magnitude: a unit conversion between the canonical unit and the
/// wire's (Pa to MPa is 1e-6, rad to mrad 1e3). Outside it a value rounds away on the wire (a scale
/// of 1e-300 read every boom angle as 0 rad) or overflows it.
pub const SCALE_RANGE: (f64, f64) = (1e-6, 1e6);

/// The timing of the gateway a profile describes: the periods at which it sends its feedback and
/// expects the controller's frames, and its watchdogs, ms (`docs/machine-profile.md`, "Rates and
/// timeouts"). The default profile's is [`GatewayTiming::canonical`], the project's gateway.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GatewayTiming {
    /// `JointAngles`, `JointRates` and the three `AuxValveMeasured` (sent together).
    pub sensor_period_ms: u32,
    /// `PumpPressures`.
    pub pump_period_ms: u32,
    /// `TrackOdometry`.
    pub odometry_period_ms: u32,
    /// `GatewayStatus` and `GatewaySession` (sent together).
    pub status_period_ms: u32,
    /// `ControllerHeartbeat`, as the gateway expects it.
    pub heartbeat_period_ms: u32,
    /// The longest period of the valve commands and the position setpoint the gateway expects.
    pub command_period_ms: u32,
    /// Heartbeat watchdog: the gateway goes neutral this long after the last valid heartbeat.
    pub heartbeat_timeout_ms: u32,
    /// A non-neutral valve command or a setpoint older than this is stale to the gateway.
    pub command_timeout_ms: u32,
}

/// The canonical messages the gateway sends together every sensor period.
const SENSOR_GROUP: [&str; 5] = [
    "JointAngles",
    "JointRates",
    "AuxValveMeasured_Boom",
    "AuxValveMeasured_Stick",
    "AuxValveMeasured_Bucket",
];
/// The canonical messages the gateway sends together every status period.
const STATUS_GROUP: [&str; 2] = ["GatewayStatus", "GatewaySession"];
/// The commands whose longest period the command timeout must cover.
const COMMAND_GROUP: [&str; 7] = [
    "AuxValveCommand_Boom",
    "AuxValveCommand_Stick",
    "AuxValveCommand_Bucket",
    "AuxValveCommand_Swing",
    "AuxValveCommand_LeftTrack",
    "AuxValveCommand_RightTrack",
    "PositionSetpoint",
];

/// How many periods a timeout must cover at least.
pub const TIMEOUT_PERIODS: u32 = 2;

impl GatewayTiming {
    /// The project's gateway: the periods of `excavator.dbc`'s `GenMsgCycleTime` and the watchdogs of
    /// [`crate::gateway::GatewayConfig::default`].
    pub fn canonical() -> Self {
        let gateway = crate::gateway::GatewayConfig::default();
        let ms = |s: f64| (s * 1000.0).round() as u32;
        Self::of(
            |name| {
                dbc::MESSAGES
                    .iter()
                    .find(|m| m.name == name)
                    .map_or(0, |m| u32::from(m.cycle_time_ms))
            },
            ms(gateway.heartbeat_timeout_s),
            ms(gateway.command_timeout_s),
        )
    }

    fn of(
        period: impl Fn(&str) -> u32,
        heartbeat_timeout_ms: u32,
        command_timeout_ms: u32,
    ) -> Self {
        Self {
            sensor_period_ms: period(SENSOR_GROUP[0]),
            pump_period_ms: period("PumpPressures"),
            odometry_period_ms: period("TrackOdometry"),
            status_period_ms: period(STATUS_GROUP[0]),
            heartbeat_period_ms: period("ControllerHeartbeat"),
            command_period_ms: COMMAND_GROUP.iter().map(|n| period(n)).max().unwrap_or(0),
            heartbeat_timeout_ms,
            command_timeout_ms,
        }
    }

    /// Seconds of a number of ms.
    pub fn secs(ms: u32) -> f64 {
        f64::from(ms) / 1000.0
    }
}

impl Default for GatewayTiming {
    fn default() -> Self {
        Self::canonical()
    }
}

/// A loaded machine profile.
#[derive(Debug, Clone, PartialEq)]
pub struct Profile {
    origin: String,
    dbc_path: PathBuf,
    wire: WireDbc,
    /// One per canonical message, in [`dbc::MESSAGES`] order.
    routes: Vec<Route>,
    identity: bool,
    timing: GatewayTiming,
}

fn line_of_offset(text: &str, offset: usize) -> usize {
    text.get(..offset.min(text.len()))
        .map_or(1, |head| head.matches('\n').count() + 1)
}

impl Profile {
    /// The default profile: the project's own `excavator.dbc`, every signal unchanged.
    ///
    /// # Errors
    /// Never in a correct build (the test suite loads it); the error is returned rather than assumed.
    pub fn default_profile() -> Result<Self, ProfileError> {
        Self::from_toml_str(
            DEFAULT_PROFILE_TEXT,
            "profiles/default.toml",
            Path::new("excavator.dbc"),
            dbc::DBC_TEXT,
        )
    }

    /// Loads a profile file and the DBC it names (relative to the profile's folder).
    ///
    /// # Errors
    /// [`ProfileError`] naming the file, the line and the missing or wrong quantity.
    pub fn load(path: &Path) -> Result<Self, ProfileError> {
        let text = read_text(path).map_err(|error| ProfileError::Io {
            path: path.to_path_buf(),
            error,
        })?;
        let origin = path.display().to_string();
        let file = parse_file(&text, &origin)?;
        let dbc_path = path
            .parent()
            .unwrap_or_else(|| Path::new(""))
            .join(file.dbc.get_ref());
        let dbc_text = read_text(&dbc_path).map_err(|error| ProfileError::Invalid {
            origin: origin.clone(),
            line: Some(line_of_offset(&text, file.dbc.span().start)),
            message: format!(
                "dbc = {:?}: cannot read {}: {error}",
                file.dbc.get_ref(),
                dbc_path.display()
            ),
        })?;
        Self::build(&text, &origin, file, dbc_path, &dbc_text)
    }

    /// Loads a profile from its text and its DBC's text (`dbc_path` only names the DBC in errors).
    ///
    /// # Errors
    /// [`ProfileError`] naming `origin`, the line and the missing or wrong quantity.
    pub fn from_toml_str(
        text: &str,
        origin: &str,
        dbc_path: &Path,
        dbc_text: &str,
    ) -> Result<Self, ProfileError> {
        let file = parse_file(text, origin)?;
        Self::build(text, origin, file, dbc_path.to_path_buf(), dbc_text)
    }

    fn build(
        text: &str,
        origin: &str,
        file: ProfileFile,
        dbc_path: PathBuf,
        dbc_text: &str,
    ) -> Result<Self, ProfileError> {
        let wire = WireDbc::parse(dbc_text).map_err(|error| ProfileError::Dbc {
            path: dbc_path.clone(),
            origin: origin.to_string(),
            error,
        })?;
        let invalid = |span: std::ops::Range<usize>, message: String| ProfileError::Invalid {
            origin: origin.to_string(),
            line: Some(line_of_offset(text, span.start)),
            message,
        };
        let dbc_name = dbc_path.display().to_string();
        let entries = file.messages.get_ref();
        for (name, entry) in entries {
            if let Some(m) = dbc::MESSAGES.iter().find(|m| m.name == name)
                && passes_through(m.pgn)
            {
                return Err(invalid(
                    entry.span(),
                    format!(
                        "[messages.{name}]: a J1939 standard message (PGN {:#06X}: network \
                         management or DM1) passes through every profile unchanged and is not \
                         mapped",
                        m.pgn
                    ),
                ));
            }
            if !dbc::MESSAGES.iter().any(|m| m.name == name) {
                return Err(invalid(
                    entry.span(),
                    format!(
                        "[messages.{name}]: no canonical message of that name (they are: {})",
                        dbc::MESSAGES
                            .iter()
                            .map(|m| m.name)
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                ));
            }
        }
        let mut routes = Vec::with_capacity(dbc::MESSAGES.len());
        let mut periods = Vec::with_capacity(dbc::MESSAGES.len());
        for canonical in dbc::MESSAGES.iter().filter(|m| !passes_through(m.pgn)) {
            let Some(entry) = entries.get(canonical.name) else {
                return Err(invalid(
                    file.messages.span(),
                    format!(
                        "missing quantity: no [messages.{}] (signals {})",
                        canonical.name,
                        canonical
                            .signals
                            .iter()
                            .map(|s| s.name)
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                ));
            };
            let e = entry.get_ref();
            let wire_index = wire
                .messages
                .iter()
                .position(|m| m.name == *e.wire.get_ref())
                .ok_or_else(|| {
                    invalid(
                        e.wire.span(),
                        format!(
                            "{}: wire message {:?} is not in {dbc_name}",
                            canonical.name,
                            e.wire.get_ref()
                        ),
                    )
                })?;
            let wmsg = &wire.messages[wire_index];
            let mux = e.mux.as_ref().map(|m| *m.get_ref());
            match (wmsg.multiplexor, mux) {
                (Some(_), None) => {
                    return Err(invalid(
                        entry.span(),
                        format!(
                            "{}: wire message {} is multiplexed; say which value with `mux = N`",
                            canonical.name, wmsg.name
                        ),
                    ));
                }
                (None, Some(_)) => {
                    return Err(invalid(
                        entry.span(),
                        format!(
                            "{}: wire message {} has no multiplexor, remove `mux`",
                            canonical.name, wmsg.name
                        ),
                    ));
                }
                (Some(i), Some(v)) => {
                    let (_, hi) = wmsg.signals[i].raw_limits();
                    if i128::from(v) > hi {
                        return Err(invalid(
                            entry.span(),
                            format!(
                                "{}: mux {v} does not fit multiplexor {}",
                                canonical.name, wmsg.signals[i].name
                            ),
                        ));
                    }
                }
                (None, None) => {}
            }
            if let Some(other) = routes
                .iter()
                .find(|r: &&Route| r.wire == wire_index && r.mux == mux)
            {
                return Err(invalid(
                    entry.span(),
                    format!(
                        "{}: wire message {} (mux {mux:?}) already carries {}",
                        canonical.name, wmsg.name, other.canonical.name
                    ),
                ));
            }
            for (sig_name, s) in &e.signals {
                if !canonical.signals.iter().any(|c| c.name == sig_name) {
                    return Err(invalid(
                        s.span(),
                        format!("{}.{sig_name}: no such canonical signal", canonical.name),
                    ));
                }
            }
            let period_ms = match &e.period_ms {
                Some(p) => period_in_range(*p.get_ref()).ok_or_else(|| {
                    invalid(
                        p.span(),
                        format!(
                            "{}.period_ms = {}: must be 1 to {MAX_PERIOD_MS} ms",
                            canonical.name,
                            p.get_ref()
                        ),
                    )
                })?,
                None => match wmsg.cycle_time_ms {
                    Some(ms) if ms > MAX_PERIOD_MS => {
                        return Err(invalid(
                            e.wire.span(),
                            format!(
                                "{}: GenMsgCycleTime {ms} of {} in {dbc_name} is over \
                                 {MAX_PERIOD_MS} ms; give `period_ms`",
                                canonical.name, wmsg.name
                            ),
                        ));
                    }
                    Some(ms) => ms,
                    // A DBC without rates: the project's.
                    None => u32::from(canonical.cycle_time_ms),
                },
            };
            periods.push((
                period_ms,
                e.period_ms
                    .as_ref()
                    .map_or_else(|| entry.span(), Spanned::span),
            ));
            let secured = secoc::is_secured(canonical.pgn);
            let mut fields = Vec::with_capacity(canonical.signals.len());
            let mut used = Vec::new();
            for csig in canonical.signals {
                let quantity = format!("{}.{}", canonical.name, csig.name);
                let spec = e.signals.get(csig.name);
                let span = spec.map_or_else(|| entry.span(), Spanned::span);
                let (wire_name, scale, offset, constant) = match spec.map(Spanned::get_ref) {
                    None => (Some(csig.name.to_string()), 1.0, 0.0, None),
                    Some(SignalEntry::Name(n)) => (Some(n.clone()), 1.0, 0.0, None),
                    Some(SignalEntry::Full(m)) => (
                        m.signal.clone(),
                        m.scale.unwrap_or(1.0),
                        m.offset.unwrap_or(0.0),
                        m.constant,
                    ),
                };
                let target = match (wire_name, constant) {
                    (Some(_), Some(_)) | (None, None) => {
                        return Err(invalid(
                            span,
                            format!("{quantity}: give either `signal` or `constant`"),
                        ));
                    }
                    (None, Some(c)) => {
                        if c < csig.raw_min || c > csig.raw_max {
                            return Err(invalid(
                                span,
                                format!(
                                    "{quantity}: constant {c} outside the raw range [{}, {}]",
                                    csig.raw_min, csig.raw_max
                                ),
                            ));
                        }
                        Target::Constant(c)
                    }
                    (Some(wname), None) => {
                        let Some(windex) = wmsg.signal_index(&wname) else {
                            let how = if spec.is_none() {
                                format!(
                                    "missing quantity: {quantity} is not mapped and {} has no signal {wname}",
                                    wmsg.name
                                )
                            } else {
                                format!(
                                    "{quantity}: wire message {} has no signal {wname}",
                                    wmsg.name
                                )
                            };
                            return Err(invalid(span, how));
                        };
                        let wsig = &wmsg.signals[windex];
                        let present = match wsig.mux {
                            Mux::Plain => true,
                            Mux::Multiplexor => false,
                            Mux::Multiplexed(v) => mux == Some(v),
                        };
                        if !present {
                            return Err(invalid(
                                span,
                                format!(
                                    "{quantity}: wire signal {wname} is not present in {} with mux {mux:?}",
                                    wmsg.name
                                ),
                            ));
                        }
                        if used.contains(&windex) {
                            return Err(invalid(
                                span,
                                format!(
                                    "{quantity}: wire signal {wname} already carries another quantity"
                                ),
                            ));
                        }
                        used.push(windex);
                        let (lo, hi) = SCALE_RANGE;
                        if !(scale.abs() >= lo && scale.abs() <= hi && offset.is_finite()) {
                            return Err(invalid(
                                span,
                                format!(
                                    "{quantity}: scale = {scale}, offset = {offset}: the scale's \
                                     magnitude must be {lo:e} to {hi:e} (a unit conversion), the \
                                     offset finite"
                                ),
                            ));
                        }
                        field_target(csig, wsig, windex, scale, offset, secured)
                            .map_err(|why| invalid(span, format!("{quantity}: {why}")))?
                    }
                };
                fields.push(Field {
                    canonical: csig,
                    target,
                });
            }
            routes.push(Route {
                canonical,
                wire: wire_index,
                mux,
                fields,
                period_ms,
            });
        }
        let timing = timing_of(&routes, &periods, file.timeouts.as_ref(), &invalid)?;
        if let Some(addresses) = &file.addresses {
            check_addresses(&routes, &wire, addresses.get_ref())
                .map_err(|why| invalid(addresses.span(), why))?;
        }
        let identity = routes.iter().all(|r| {
            let w = &wire.messages[r.wire];
            r.mux.is_none()
                && w.id == CanId::Extended(r.canonical.default_id)
                && w.size == usize::from(r.canonical.dlc)
                && r.fields.iter().all(|f| match f.target {
                    Target::Raw { wire } => {
                        let ws = &w.signals[wire];
                        ws.byte_order == wire_dbc::ByteOrder::Intel
                            && ws.start_bit == f.canonical.start_bit
                            && ws.len == f.canonical.len
                    }
                    _ => false,
                })
                && w.signals.len() == r.fields.len()
        });
        Ok(Self {
            origin: origin.to_string(),
            dbc_path,
            wire,
            routes,
            identity,
            timing,
        })
    }

    /// The period of the canonical message `canonical` on this gateway, ms (0 for a message sent on
    /// events), and the name of the wire message carrying it; `None` for a message the profile does
    /// not route (J1939 network management).
    pub fn route_of(&self, canonical: &str) -> Option<(u32, &str)> {
        self.routes
            .iter()
            .find(|r| r.canonical.name == canonical)
            .map(|r| (r.period_ms, self.wire.messages[r.wire].name.as_str()))
    }

    /// The gateway's periods and timeouts.
    pub fn timing(&self) -> GatewayTiming {
        self.timing
    }

    /// The profile file it was loaded from.
    pub fn origin(&self) -> &str {
        &self.origin
    }

    /// The DBC of the wire protocol.
    pub fn dbc_path(&self) -> &Path {
        &self.dbc_path
    }

    /// The wire protocol.
    pub fn wire(&self) -> &WireDbc {
        &self.wire
    }

    /// True if the wire protocol is the canonical one bit for bit (the default profile): translation
    /// returns every frame unchanged.
    pub fn is_identity(&self) -> bool {
        self.identity
    }

    /// The wire frame of a canonical frame (encoded by [`crate::messages`], sealed or not).
    ///
    /// # Errors
    /// [`TranslateError`] for a frame that is not a canonical message, or a value the wire signal
    /// cannot hold.
    pub fn to_wire(&self, canonical: &CanFrame) -> Result<CanFrame, TranslateError> {
        if self.identity {
            return Ok(*canonical);
        }
        if network_management(canonical) {
            return if self.wire.j1939 {
                Ok(*canonical)
            } else {
                Err(TranslateError::NotOnThisBus(canonical.id()))
            };
        }
        let route = self.route_of_canonical(canonical)?;
        let wmsg = &self.wire.messages[route.wire];
        let data = canonical.data();
        let mut bits = Vec::with_capacity(route.fields.len());
        for field in &route.fields {
            let c = field.canonical;
            let raw = dbc::extract_raw(c, data).unwrap_or(0);
            let quantity = || format!("{}.{}", route.canonical.name, c.name);
            match field.target {
                Target::Constant(constant) => {
                    if raw != constant {
                        return Err(TranslateError::NotConstant {
                            quantity: quantity(),
                            raw,
                            constant,
                        });
                    }
                }
                Target::Raw { wire } => {
                    let ws = &wmsg.signals[wire];
                    let (lo, hi) = ws.raw_limits();
                    let raw = i128::from(raw);
                    let b = wire_bits_or_not_available(ws, (lo..=hi).contains(&raw), || {
                        Ok(ws.bits_of_integer(raw))
                    })?;
                    bits.push((wire, b));
                }
                Target::Physical {
                    wire,
                    scale,
                    offset,
                } => {
                    let ws = &wmsg.signals[wire];
                    let available = (c.raw_min..=c.raw_max).contains(&raw);
                    let b = wire_bits_or_not_available(ws, available, || {
                        let value = dbc::raw_to_physical(c, raw) * scale + offset;
                        ws.bits_of(value, false)
                            .map_err(|_| TranslateError::NotRepresentable {
                                quantity: quantity(),
                                signal: ws.name.clone(),
                                value,
                            })
                    })?;
                    bits.push((wire, b));
                }
            }
        }
        let payload = wmsg.encode_bits(route.mux, &bits, 0xFF).map_err(|e| {
            TranslateError::NotRepresentable {
                quantity: route.canonical.name.to_string(),
                signal: e.to_string(),
                value: f64::NAN,
            }
        })?;
        CanFrame::new_data(wmsg.id, &payload).map_err(|_| TranslateError::WrongLength {
            message: wmsg.name.clone(),
            expected: 8,
            actual: payload.len(),
        })
    }

    /// The canonical frame of a wire frame, with the canonical id of its message (the project's
    /// source addresses).
    ///
    /// # Errors
    /// [`TranslateError::Unmapped`] for a frame the profile does not map (count and reject it like any
    /// unexpected frame), [`TranslateError::WrongLength`] for a mapped id of the wrong length.
    pub fn from_wire(&self, wire: &CanFrame) -> Result<CanFrame, TranslateError> {
        if self.identity || (self.wire.j1939 && network_management(wire)) {
            return Ok(*wire);
        }
        if wire.kind() != FrameKind::Data {
            return Err(TranslateError::Unmapped(wire.id()));
        }
        let Some(windex) = self.wire.message_index_by_id(wire.id()) else {
            return Err(TranslateError::Unmapped(wire.id()));
        };
        let wmsg = &self.wire.messages[windex];
        let data = wire.data();
        if data.len() != wmsg.size {
            return Err(TranslateError::WrongLength {
                message: wmsg.name.clone(),
                expected: wmsg.size,
                actual: data.len(),
            });
        }
        let mux = wmsg.multiplexor.map(|i| wmsg.signals[i].bits(data));
        let Some(route) = self
            .routes
            .iter()
            .find(|r| r.wire == windex && r.mux == mux)
        else {
            return Err(TranslateError::Unmapped(wire.id()));
        };
        let c_msg = route.canonical;
        let mut out = [0xFFu8; 8];
        let out_data = &mut out[..usize::from(c_msg.dlc)];
        for field in &route.fields {
            let c = field.canonical;
            let raw = match field.target {
                Target::Constant(constant) => constant,
                Target::Raw { wire } => {
                    let ws = &wmsg.signals[wire];
                    canonical_raw_or_not_available(c, Some(ws.raw_integer(ws.bits(data))))
                }
                Target::Physical {
                    wire,
                    scale,
                    offset,
                } => {
                    let ws = &wmsg.signals[wire];
                    let b = ws.bits(data);
                    let raw = (b != not_available_bits(ws))
                        .then(|| {
                            let value = (ws.physical(b) - offset) / scale;
                            ((value - c.offset) / c.factor).round()
                        })
                        .filter(|raw| raw.is_finite())
                        .map(|raw| raw as i128);
                    canonical_raw_or_not_available(c, raw)
                }
            };
            // `fits` checked the raw value against the signal's bits.
            let _ = dbc::insert_raw(c, raw, out_data);
        }
        CanFrame::new_data(CanId::Extended(c_msg.default_id), out_data).map_err(|_| {
            TranslateError::WrongLength {
                message: c_msg.name.to_string(),
                expected: usize::from(c_msg.dlc),
                actual: out_data.len(),
            }
        })
    }

    fn route_of_canonical(&self, frame: &CanFrame) -> Result<&Route, TranslateError> {
        let CanId::Extended(raw) = frame.id() else {
            return Err(TranslateError::Unmapped(frame.id()));
        };
        let pgn = J1939Id::from_raw(raw)
            .map_err(|_| TranslateError::Unmapped(frame.id()))?
            .pgn();
        let route = self
            .routes
            .iter()
            .find(|r| r.canonical.pgn == pgn)
            .ok_or(TranslateError::Unmapped(frame.id()))?;
        let expected = usize::from(route.canonical.dlc);
        if frame.kind() != FrameKind::Data || frame.len() != expected {
            return Err(TranslateError::WrongLength {
                message: route.canonical.name.to_string(),
                expected,
                actual: frame.len(),
            });
        }
        Ok(route)
    }
}

/// Checks that every wire message carries the declared addresses: the sender's as its J1939 source
/// address, and the gateway's as the destination of a controller's PDU1 message.
fn check_addresses(
    routes: &[Route],
    wire: &WireDbc,
    addresses: &AddressesEntry,
) -> Result<(), String> {
    for route in routes {
        let wmsg = &wire.messages[route.wire];
        let name = route.canonical.name;
        let CanId::Extended(raw) = wmsg.id else {
            return Err(format!(
                "[addresses]: {name} travels in {}, an 11-bit id, which carries no address",
                wmsg.name
            ));
        };
        let id = J1939Id::from_raw(raw).map_err(|e| format!("[addresses]: {name}: {e}"))?;
        let (sender, receiver) = match route.canonical.transmitter {
            "Controller" => (addresses.controller, addresses.gateway),
            _ => (addresses.gateway, addresses.controller),
        };
        let role = route.canonical.transmitter.to_lowercase();
        if let Some(sa) = sender
            && id.source_address() != sa
        {
            return Err(format!(
                "[addresses]: {name} travels in {} (id 0x{raw:08X}) with source address 0x{:02X}, \
                 but the {role}'s is 0x{sa:02X}",
                wmsg.name,
                id.source_address()
            ));
        }
        if let (Some(da), Some(to)) = (receiver, id.destination_address())
            && to != da
            && to != 0xFF
        {
            return Err(format!(
                "[addresses]: {name} travels in {} (id 0x{raw:08X}) to address 0x{to:02X}, not \
                 0x{da:02X}",
                wmsg.name
            ));
        }
    }
    Ok(())
}

/// A period or timeout from the file, ms, if in `1..=MAX_PERIOD_MS`.
fn period_in_range(ms: i64) -> Option<u32> {
    u32::try_from(ms)
        .ok()
        .filter(|ms| (1..=MAX_PERIOD_MS).contains(ms))
}

/// The gateway's timing of `routes` (with each period's span in `periods`) and the `[timeouts]` table,
/// checked: the messages sent together share one period, each timeout covers [`TIMEOUT_PERIODS`]
/// periods of what it watches.
fn timing_of(
    routes: &[Route],
    periods: &[(u32, std::ops::Range<usize>)],
    timeouts: Option<&Spanned<TimeoutsEntry>>,
    invalid: &dyn Fn(std::ops::Range<usize>, String) -> ProfileError,
) -> Result<GatewayTiming, ProfileError> {
    let index = |name: &str| routes.iter().position(|r| r.canonical.name == name);
    let period = |name: &str| index(name).map_or(0, |i| periods[i].0);
    for group in [&SENSOR_GROUP[..], &STATUS_GROUP[..]] {
        let first = period(group[0]);
        for name in &group[1..] {
            let Some(i) = index(name) else { continue };
            if periods[i].0 != first {
                return Err(invalid(
                    periods[i].1.clone(),
                    format!(
                        "{name}: period {} ms, but {} has {first} ms: the gateway sends {} together",
                        periods[i].0,
                        group[0],
                        group.join(", ")
                    ),
                ));
            }
        }
    }
    let canonical = GatewayTiming::canonical();
    let timeout = |field: Option<&Spanned<i64>>, default: u32, key: &str| match field {
        None => Ok((default, None)),
        Some(v) => u32::try_from(*v.get_ref())
            .ok()
            .filter(|ms| (1..=MAX_TIMEOUT_MS).contains(ms))
            .map(|ms| (ms, Some(v.span())))
            .ok_or_else(|| {
                invalid(
                    v.span(),
                    format!(
                        "timeouts.{key} = {}: must be 1 to {MAX_TIMEOUT_MS} ms (ISO 11783-7: a \
                         timeout that bounds motion after the controller falls silent)",
                        v.get_ref()
                    ),
                )
            }),
    };
    let t = timeouts.map(Spanned::get_ref);
    let (heartbeat_ms, heartbeat_span) = timeout(
        t.and_then(|t| t.heartbeat_ms.as_ref()),
        canonical.heartbeat_timeout_ms,
        "heartbeat_ms",
    )?;
    let (command_ms, command_span) = timeout(
        t.and_then(|t| t.command_ms.as_ref()),
        canonical.command_timeout_ms,
        "command_ms",
    )?;
    let timing = GatewayTiming::of(period, heartbeat_ms, command_ms);
    for (key, timeout_ms, span, watched) in [
        (
            "heartbeat_ms",
            heartbeat_ms,
            heartbeat_span,
            &["ControllerHeartbeat"][..],
        ),
        ("command_ms", command_ms, command_span, &COMMAND_GROUP[..]),
    ] {
        for name in watched {
            let Some(i) = index(name) else { continue };
            let p = periods[i].0;
            if timeout_ms < TIMEOUT_PERIODS * p {
                let origin = if span.is_some() { "" } else { " (the default)" };
                return Err(invalid(
                    span.unwrap_or_else(|| periods[i].1.clone()),
                    format!(
                        "timeouts.{key} = {timeout_ms}{origin}: must cover {TIMEOUT_PERIODS} periods of \
                         {name} ({p} ms), at least {} ms",
                        TIMEOUT_PERIODS * p
                    ),
                ));
            }
        }
    }
    Ok(timing)
}

/// Whether `frame` is a data frame of a J1939 standard message (29-bit id, Address Claimed, Request
/// or DM1: [`passes_through`]), which every profile passes through unchanged.
fn network_management(frame: &CanFrame) -> bool {
    match frame.id() {
        CanId::Extended(raw) if frame.kind() == FrameKind::Data => {
            J1939Id::from_raw(raw).is_ok_and(|id| passes_through(id.pgn()))
        }
        _ => false,
    }
}

fn parse_file(text: &str, origin: &str) -> Result<ProfileFile, ProfileError> {
    toml::from_str(text).map_err(|e| {
        let field = e.span().and_then(|s| field_at(text, s.start));
        let message = e.message().trim();
        ProfileError::Invalid {
            origin: origin.to_string(),
            line: e.span().map(|s| line_of_offset(text, s.start)),
            message: match field {
                // The parser's type errors name the value, not the key.
                Some(field) if !message.contains(&field) => format!("{field}: {message}"),
                _ => message.to_string(),
            },
        }
    })
}

/// The dotted name of the TOML key whose value is at `offset` (`messages.JointAngles.mux`): the key
/// before `=` on its line under the last `[table]` header above it.
fn field_at(text: &str, offset: usize) -> Option<String> {
    let head = text.get(..offset.min(text.len()))?;
    let line_start = head.rfind('\n').map_or(0, |i| i + 1);
    let line = text[line_start..].lines().next()?;
    let key = line.split_once('=')?.0.trim();
    if key.is_empty() || key.starts_with('[') || key.starts_with('#') {
        return None;
    }
    let table = head[..line_start].lines().rev().find_map(|l| {
        let l = l.trim();
        l.strip_prefix('[')
            .and_then(|t| t.split(']').next())
            .map(|t| t.trim_start_matches('[').trim().to_string())
    });
    Some(match table {
        Some(t) => format!("{t}.{key}"),
        None => key.to_string(),
    })
}

/// The wire bits of a canonical value: `bits()` when the value is `available`, else the wire signal's
/// "not available" bits (one rule for both ways a value reaches the wire).
fn wire_bits_or_not_available(
    ws: &WireSignal,
    available: bool,
    bits: impl FnOnce() -> Result<u64, TranslateError>,
) -> Result<u64, TranslateError> {
    if available {
        bits()
    } else {
        Ok(not_available_bits(ws))
    }
}

/// The canonical raw value of a wire value (`None`: not available or not a number), "not available"
/// when it does not fit the canonical signal.
fn canonical_raw_or_not_available(c: &SignalDesc, raw: Option<i128>) -> i64 {
    match raw {
        Some(raw) if fits(c, raw) => raw as i64,
        _ => not_available_raw(c),
    }
}

/// True if `raw` fits the canonical signal's bits.
fn fits(c: &SignalDesc, raw: i128) -> bool {
    let len = u32::from(c.len);
    if c.signed {
        raw >= -(1i128 << (len - 1)) && raw < (1i128 << (len - 1))
    } else {
        raw >= 0 && raw < (1i128 << len)
    }
}

/// The J1939 "not available" raw value of a canonical signal (`docs/protocol.md`).
fn not_available_raw(c: &SignalDesc) -> i64 {
    if c.signed {
        (1i64 << (c.len - 1)) - 1
    } else {
        (1i64 << c.len) - 1
    }
}

/// The "not available" bits of a wire signal: all ones unsigned, the largest value signed, NaN float.
fn not_available_bits(ws: &WireSignal) -> u64 {
    match ws.kind {
        ValueKind::Float32 => u64::from(f32::NAN.to_bits()),
        ValueKind::Float64 => f64::NAN.to_bits(),
        _ => {
            let (_, hi) = ws.raw_limits();
            ws.bits_of_integer(hi)
        }
    }
}

/// How a canonical signal maps onto a wire signal; for a secured message only a lossless way.
fn field_target(
    c: &SignalDesc,
    ws: &WireSignal,
    wire: usize,
    scale: f64,
    offset: f64,
    secured: bool,
) -> Result<Target, String> {
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * a.abs().max(b.abs()).max(1e-12);
    let integer = matches!(ws.kind, ValueKind::Signed | ValueKind::Unsigned);
    let same_grid = integer
        && close(ws.factor, c.factor * scale)
        && (close(ws.offset, c.offset * scale + offset)
            || (ws.offset - (c.offset * scale + offset)).abs() <= 1e-12);
    let wide_enough = ws.len >= c.len && (ws.kind == ValueKind::Signed) == c.signed;
    if same_grid && (wide_enough || !secured) {
        return Ok(Target::Raw { wire });
    }
    if secured {
        return Err(format!(
            "the frame is authenticated, so the value must travel unchanged: wire signal {} needs \
             factor {} and offset {} in its units, at least {} bits, {} (it has factor {}, offset {}, \
             {} bits, {:?})",
            ws.name,
            c.factor * scale,
            c.offset * scale + offset,
            c.len,
            if c.signed { "signed" } else { "unsigned" },
            ws.factor,
            ws.offset,
            ws.len,
            ws.kind
        ));
    }
    Ok(Target::Physical {
        wire,
        scale,
        offset,
    })
}

/// The text of the file at `path` read as untrusted input ([`gateway_core::file::read_text`], the
/// workspace's one bounded reader: a regular file, not a FIFO, which would block, nor a device such
/// as `/dev/zero`, which never ends, of at most [`gateway_core::file::MAX_CONFIG_BYTES`]).
fn read_text(path: &Path) -> std::io::Result<String> {
    Ok(gateway_core::file::read_text(path)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `/dev/zero` (which never ends) or a FIFO (which blocks) as a profile or as its DBC: refused
    /// at once, memory bounded, the file named.
    #[cfg(unix)]
    #[test]
    fn a_device_or_a_fifo_as_the_profile_or_its_dbc_is_refused_at_once() {
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("fifo");
        let made = std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap();
        assert!(made.success());
        let example = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/other_gateway.toml");
        let text = std::fs::read_to_string(&example).unwrap();
        let dbc_line = text
            .lines()
            .find(|l| l.trim_start().starts_with("dbc"))
            .unwrap();
        let mut cases = vec![
            (Path::new("/dev/zero").to_path_buf(), "/dev/zero"),
            (fifo.clone(), "fifo"),
        ];
        for (name, target) in [("zero.toml", "/dev/zero"), ("fifo.toml", "fifo")] {
            let profile = dir.path().join(name);
            std::fs::write(
                &profile,
                text.replace(dbc_line, &format!("dbc = {target:?}")),
            )
            .unwrap();
            cases.push((profile, target));
        }
        for (path, named) in cases {
            let started = std::time::Instant::now();
            let e = Profile::load(&path).unwrap_err().to_string();
            assert!(e.contains("not a regular file") && e.contains(named), "{e}");
            assert!(started.elapsed() < std::time::Duration::from_secs(1), "{e}");
        }
    }

    /// Regression for what a user saw: a missing DBC printed its cause twice and named no profile
    /// line, `mux = "2"` said `invalid type` without the field, and unmapped ids printed as
    /// `Extended(218058880)`.
    #[test]
    fn profile_errors_name_the_file_line_and_field_once() {
        let dir = std::env::temp_dir().join(format!("profile-errors-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let example = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/other_gateway.toml");
        let text = std::fs::read_to_string(&example).unwrap();
        let missing = dir.join("missing.toml");
        std::fs::write(&missing, text.replace("other_gateway.dbc", "nope.dbc")).unwrap();
        let err = Profile::load(&missing).unwrap_err();
        let dbc_line = text.lines().position(|l| l.starts_with("dbc =")).unwrap() + 1;
        assert_eq!(
            format!("{:#}", anyhow_like(&err)),
            format!(
                "{}:{dbc_line}: dbc = \"nope.dbc\": cannot read {}: No such file or directory \
                 (os error 2)",
                missing.display(),
                dir.join("nope.dbc").display()
            )
        );
        let bad_mux = dir.join("mux.toml");
        std::fs::write(&bad_mux, text.replacen("mux = 2", "mux = \"2\"", 1)).unwrap();
        let mux_line = text.lines().position(|l| l == "mux = 2").unwrap() + 1;
        let err = Profile::load(&bad_mux).unwrap_err().to_string();
        assert!(
            err.starts_with(&format!(
                "{}:{mux_line}: messages.AuxValveCommand_Bucket.mux: invalid type",
                bad_mux.display()
            )),
            "{err}"
        );
        let bad_dbc = dir.join("other_gateway.dbc");
        std::fs::write(&bad_dbc, "VERSION \"\"\nBO_ nonsense\n").unwrap();
        let syntax = dir.join("syntax.toml");
        std::fs::write(&syntax, &text).unwrap();
        let err = Profile::load(&syntax).unwrap_err();
        let shown = format!("{:#}", anyhow_like(&err));
        assert!(shown.contains("not a valid DBC"), "{shown}");
        assert_eq!(shown.matches("not a valid DBC").count(), 1, "{shown}");
        assert!(shown.contains(&syntax.display().to_string()), "{shown}");
        let _ = std::fs::remove_dir_all(&dir);
        assert_eq!(
            TranslateError::Unmapped(CanId::Extended(0x0CFF_1234)).to_string(),
            "unmapped frame 0x0CFF1234"
        );
        assert_eq!(
            TranslateError::Unmapped(CanId::Standard(0x7F)).to_string(),
            "unmapped frame 0x07F"
        );
    }

    /// The error with its whole `source` chain, as a binary prints it with `{:#}`.
    fn anyhow_like(err: &dyn std::error::Error) -> String {
        let mut text = err.to_string();
        let mut cause = err.source();
        while let Some(c) = cause {
            text += &format!(": {c}");
            cause = c.source();
        }
        text
    }

    #[test]
    fn the_default_profile_is_the_identity() {
        let profile = Profile::default_profile().expect("the shipped default profile loads");
        assert!(profile.is_identity());
        let mapped = dbc::MESSAGES
            .iter()
            .filter(|m| !passes_through(m.pgn))
            .count();
        assert_eq!(profile.routes.len(), mapped);
    }

    #[test]
    fn network_management_passes_a_j1939_bus_only_and_may_not_be_mapped() {
        use crate::address_claim::{CONTROLLER_NAME, NULL_ADDRESS, request_address_claimed};
        use crate::messages::{AddressClaimed, Message};
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/other_gateway.toml");
        let other = Profile::load(&path).expect("the example profile loads");
        assert!(!other.wire().j1939);
        let mut j1939 = Profile::default_profile().expect("loads");
        j1939.identity = false;
        assert!(j1939.wire().j1939);
        let claim = Message::AddressClaimed(AddressClaimed {
            name: CONTROLLER_NAME,
        });
        for frame in [
            claim.encode_from(0x27).expect("encodes"),
            claim.encode_from(NULL_ADDRESS).expect("encodes"),
            request_address_claimed(0xFF, 0x27).expect("encodes"),
        ] {
            assert_eq!(j1939.to_wire(&frame), Ok(frame));
            assert_eq!(j1939.from_wire(&frame), Ok(frame));
            assert_eq!(
                other.to_wire(&frame),
                Err(TranslateError::NotOnThisBus(frame.id()))
            );
            assert_eq!(
                other.from_wire(&frame),
                Err(TranslateError::Unmapped(frame.id()))
            );
        }
        let text = format!(
            "{}\n[messages.AddressClaimed]\nwire = \"X\"\n",
            DEFAULT_PROFILE_TEXT
        );
        let err =
            Profile::from_toml_str(&text, "p.toml", Path::new("excavator.dbc"), dbc::DBC_TEXT)
                .expect_err("mapping network management is refused");
        assert!(err.to_string().contains("network management"), "{err}");
    }

    #[test]
    fn the_default_mapping_translates_to_the_same_bytes_without_the_shortcut() {
        use crate::messages::*;
        let mut profile = Profile::default_profile().expect("loads");
        profile.identity = false;
        let mut sealer = secoc::Sealer::new(&secoc::SessionKey::PUBLIC);
        sealer.set_session(7);
        let mut messages: Vec<Message> = Valve::ALL
            .into_iter()
            .map(|v| {
                Message::AuxValveCommand(
                    AuxValveCommand::from_fraction(v, -0.37).expect("in range"),
                )
            })
            .collect();
        messages.extend([
            Message::JointAngles(JointAngles {
                boom_rad: 0.5,
                stick_rad: -1.25,
                bucket_rad: -3.1,
                swing_rad: 0.0001,
            }),
            Message::TrackOdometry(TrackOdometry {
                left_m: -12.3456,
                right_m: 199_999.0,
            }),
            Message::ControllerHeartbeat(ControllerHeartbeat {
                mode: RequestedMode::ArmPosition,
                alive_counter: 14,
            }),
            Message::PositionSetpoint(PositionSetpoint {
                boom_rad: 0.5,
                stick_rad: -1.0,
                bucket_rad: 0.6994,
                swing_rad: -3.0,
            }),
            Message::GatewaySession(GatewaySession {
                session_id: u32::MAX,
            }),
        ]);
        for m in &messages {
            let frame = sealer.seal(m).expect("seals");
            assert_eq!(profile.to_wire(&frame), Ok(frame), "{m:?}");
            assert_eq!(profile.from_wire(&frame), Ok(frame), "{m:?}");
        }
        // A "not available" raw value (0xFFFF fine flow) passes unchanged too.
        let mut data = [0xFFu8; 8];
        data[0] = 0x10;
        let na = CanFrame::new_extended(dbc::aux_valve_command_boom::MESSAGE.default_id, &data)
            .expect("valid");
        assert_eq!(profile.to_wire(&na), Ok(na));
    }

    #[test]
    fn lines_count_from_one() {
        assert_eq!(line_of_offset("a\nb\nc", 0), 1);
        assert_eq!(line_of_offset("a\nb\nc", 2), 2);
        assert_eq!(line_of_offset("a\nb\nc", 99), 3);
    }
}
