//! J1939-81 (ISO 11783-5) address claim: the 64-bit NAME and the claim procedure that the
//! controller and the gateway both run before they send anything else.
//!
//! # The NAME
//!
//! [`Name`] is the 64-bit number a node is known by; [`NameFields`] its fields. The bit layout is the
//! `AddressClaimed` message of `excavator.dbc` (J1939-81's: identity number bits 0-20, manufacturer
//! code 21-31, ECU instance 32-34, function instance 35-39, function 40-47, reserved 48, vehicle
//! system 49-55, vehicle system instance 56-59, industry group 60-62, arbitrary address capable 63;
//! a test holds the DBC to it), read and written through the generated descriptors; [`NAME_FIELDS`]
//! is the one list of the fields, their keys and widths. On the wire the NAME is the 8 data bytes,
//! least significant first. A lower NAME has priority.
//!
//! # The procedure ([`AddressClaimer`])
//!
//! - On start a node sends Address Claimed (PGN 60928, `0xEE00`, to global, data = its NAME) from
//!   its address and sends nothing else until that claim has stood uncontested for
//!   [`CLAIM_HOLD_NS`] (250 ms): [`AddressClaimer::may_transmit`].
//! - An Address Claimed for its address from another NAME (at start or at any later time: a late
//!   claimant) is a contest. The lower NAME wins (J1939-81). The winner sends its claim again and keeps
//!   its address; while it is still in its 250 ms it waits 250 ms from the new claim. The loser is
//!   not arbitrary-address capable (the project's addresses are fixed), so it sends Cannot Claim
//!   (Address Claimed from the null address `0xFE` with its NAME) and never transmits application
//!   frames again. An equal NAME from our address can only be a second unit configured with our NAME
//!   (a node does not receive its own frames): neither can prove priority, so it counts as lost.
//! - A Request (PGN 59904, `0xEA00`) for PGN 60928 to global or to its address is answered with its
//!   claim, or with Cannot Claim once it has lost. J1939-81 lets a node delay Cannot Claim by a
//!   pseudo-random 0-153 ms to spread answers; the project's two nodes answer at once.
//!
//! # Recovery after a loss
//!
//! A node that lost stays silent until it is told to try again; how depends on the node
//! ([`AfterLoss`]):
//!
//! - The controller ([`AfterLoss::CannotClaim`], J1939-81 as written) answers requests with Cannot
//!   Claim. The operator's reset calls [`AddressClaimer::reclaim`]: the node sends a Request for
//!   Address Claimed to global ([`request_address_claimed`]), then its claim, and holds 250 ms again.
//!   A real competitor answers the request (or our claim) with its lower NAME and wins again; a
//!   transient claim (a frame from a faulty or foreign node that does not take part in the
//!   procedure) does not answer, and the claim stands.
//! - The gateway ([`AfterLoss::ReclaimOnRequest`], a deviation from J1939-81, which has a loser
//!   answer with Cannot Claim) answers a Request for Address Claimed to global by claiming its address
//!   again, with the same 250 ms hold. A fixed-address gateway has no other address to go to and no
//!   operator at its panel, so without this only a power cycle would bring it back. It cannot steal
//!   the bus from a real owner: the owner receives the same request, answers with its lower NAME and
//!   wins again. A request addressed to the gateway's address is not for a gateway that lost it.
//!
//! Address claims are not authenticated (J1939 has no means to), so any node on the bus can take an
//! address by claiming it with a lower NAME. That stops the machine (both nodes treat a lost claim as
//! a fault with the valves neutral); it cannot make it move.
//!
//! No allocation, integer time ([`Instant`]): the gateway's firmware runs it on a microcontroller.

use core::fmt;

use crate::dbc::{self, EncodeError, SignalDesc, address_claimed as ac};
use crate::frame::CanFrame;
use crate::id::{CONTROLLER_ADDRESS, GATEWAY_ADDRESS, GLOBAL_ADDRESS, J1939Id};
use crate::messages::{Message, RequestPgn};
use crate::time::Instant;

/// PGN 60928 (`0xEE00`): Address Claimed, and Cannot Claim from the null address.
pub const ADDRESS_CLAIMED_PGN: u32 = ac::PGN;
/// PGN 59904 (`0xEA00`): Request.
pub const REQUEST_PGN: u32 = dbc::request_pgn::PGN;
/// Whether `pgn` is J1939 network management (Address Claimed, Request): the same on every J1939
/// network, so a machine profile passes these frames through unchanged instead of mapping them.
pub const fn is_network_management(pgn: u32) -> bool {
    pgn == ADDRESS_CLAIMED_PGN || pgn == REQUEST_PGN
}

/// The null address: the source of Cannot Claim.
pub const NULL_ADDRESS: u8 = 0xFE;
/// How long a claim must stand uncontested before a node sends anything else: 250 ms (J1939-81).
pub const CLAIM_HOLD_NS: i64 = 250_000_000;

/// A node's 64-bit J1939 NAME. Ordered by value: the lower NAME wins an address contest.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Name(u64);

/// The fields of a [`Name`] (J1939-81), each checked against its width when a NAME is built.
///
/// With the `std` feature it is also the NAME as a config file spells it (the controller's
/// `[j1939.name]`, the simulator's machine file `[gateway_name]`): every field by its key in
/// [`NAME_FIELDS`], every one required, no other key.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(
    feature = "std",
    derive(serde::Serialize, serde::Deserialize),
    serde(deny_unknown_fields)
)]
pub struct NameFields {
    /// Serial number of the unit, unique for its manufacturer (21 bits).
    pub identity_number: u32,
    /// SAE-assigned manufacturer code (11 bits).
    pub manufacturer_code: u16,
    /// Which of several ECUs of one function (3 bits).
    pub ecu_instance: u8,
    /// Which of several instances of the function (5 bits).
    pub function_instance: u8,
    /// What the node does (8 bits; 128-253 are defined per industry group).
    pub function: u8,
    /// The vehicle system it belongs to (7 bits).
    pub vehicle_system: u8,
    /// Which of several vehicle systems of that kind (4 bits).
    pub vehicle_system_instance: u8,
    /// Industry group (3 bits; 3 = construction equipment).
    pub industry_group: u8,
    /// Whether the node can pick another address after losing a claim. The project's nodes cannot
    /// ([`NameFields::name`] refuses it).
    pub arbitrary_address_capable: bool,
}

/// One field of the NAME: its key (as [`NameFields`] and config files spell it) and its signal in
/// `excavator.dbc`'s `AddressClaimed` (position and width).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NameField {
    /// The key (`identity_number`).
    pub key: &'static str,
    /// The DBC signal: start bit and width.
    pub signal: &'static SignalDesc,
}

impl NameField {
    const fn new(key: &'static str, signal: &'static SignalDesc) -> Self {
        Self { key, signal }
    }
}

/// The NAME's fields in the order of [`NameFields`] (the reserved bit 48 stays 0): the one list of
/// the fields, their keys and (through the DBC) their widths that every NAME codec and check uses.
pub const NAME_FIELDS: [NameField; 9] = [
    NameField::new("identity_number", &ac::IDENTITY_NUMBER),
    NameField::new("manufacturer_code", &ac::MANUFACTURER_CODE),
    NameField::new("ecu_instance", &ac::ECU_INSTANCE),
    NameField::new("function_instance", &ac::FUNCTION_INSTANCE),
    NameField::new("function", &ac::FUNCTION),
    NameField::new("vehicle_system", &ac::VEHICLE_SYSTEM),
    NameField::new("vehicle_system_instance", &ac::VEHICLE_SYSTEM_INSTANCE),
    NameField::new("industry_group", &ac::INDUSTRY_GROUP),
    NameField::new("arbitrary_address_capable", &ac::ARBITRARY_ADDRESS_CAPABLE),
];

/// Why a [`NameFields`] is not a NAME the project's nodes can claim with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NameRule {
    /// The field is wider than its bits.
    Width {
        /// The field's width.
        bits: u16,
    },
    /// `arbitrary_address_capable` is set, but the project's addresses are fixed: a node that says
    /// otherwise would be expected to move.
    FixedAddress,
}

impl fmt::Display for NameRule {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::Width { bits } => {
                write!(f, "must fit {bits} bits (0 to {})", (1u64 << bits) - 1)
            }
            Self::FixedAddress => f.write_str(
                "must be false: the controller (0x27) and the gateway (0x80) have fixed addresses",
            ),
        }
    }
}

/// A NAME field that does not fit its width, or a NAME the project's nodes cannot use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("{field} = {value}: {rule}")]
pub struct NameFieldError {
    /// The key as the file spells it (`identity_number`).
    pub field: &'static str,
    /// The value given.
    pub value: u64,
    /// What it breaks.
    pub rule: NameRule,
}

impl NameFields {
    /// The values in [`NAME_FIELDS`] order.
    pub const fn values(&self) -> [u64; 9] {
        [
            self.identity_number as u64,
            self.manufacturer_code as u64,
            self.ecu_instance as u64,
            self.function_instance as u64,
            self.function as u64,
            self.vehicle_system as u64,
            self.vehicle_system_instance as u64,
            self.industry_group as u64,
            self.arbitrary_address_capable as u64,
        ]
    }

    /// The NAME the project's nodes claim with.
    ///
    /// # Errors
    /// [`NameFieldError`] naming the first field wider than its bits, or `arbitrary_address_capable`
    /// set (the project's addresses are fixed).
    pub fn name(&self) -> Result<Name, NameFieldError> {
        for (field, value) in NAME_FIELDS.iter().zip(self.values()) {
            let bits = field.signal.len;
            if value > (1u64 << bits) - 1 {
                return Err(NameFieldError {
                    field: field.key,
                    value,
                    rule: NameRule::Width { bits },
                });
            }
        }
        if self.arbitrary_address_capable {
            return Err(NameFieldError {
                field: "arbitrary_address_capable",
                value: 1,
                rule: NameRule::FixedAddress,
            });
        }
        // Every field fits its width (checked above).
        Ok(pack(self))
    }
}

impl From<Name> for NameFields {
    fn from(name: Name) -> Self {
        name.fields()
    }
}

impl Name {
    /// The NAME with this 64-bit value (every value is a NAME).
    pub const fn from_raw(raw: u64) -> Self {
        Self(raw)
    }

    /// The 64-bit value.
    pub const fn raw(self) -> u64 {
        self.0
    }

    /// The 8 data bytes of Address Claimed (least significant first).
    pub const fn to_le_bytes(self) -> [u8; 8] {
        self.0.to_le_bytes()
    }

    /// The NAME carried by 8 data bytes.
    pub const fn from_le_bytes(bytes: [u8; 8]) -> Self {
        Self(u64::from_le_bytes(bytes))
    }

    /// Builds a NAME from its fields (the reserved bit 0).
    ///
    /// # Errors
    /// [`EncodeError::OutOfRange`] naming the field that does not fit its width.
    pub fn from_fields(fields: &NameFields) -> Result<Self, EncodeError> {
        let mut bytes = [0u8; 8];
        for (field, value) in NAME_FIELDS.iter().zip(fields.values()) {
            // Every field is at most 21 bits wide: the value fits an i64.
            dbc::encode_raw(field.signal, value as i64, &mut bytes)?;
        }
        Ok(Self::from_le_bytes(bytes))
    }

    /// The fields.
    pub fn fields(self) -> NameFields {
        let bytes = self.to_le_bytes();
        // Every signal fits 8 bytes and is unsigned and at most 21 bits wide, so the raw values are
        // non-negative and fit the field types; 0 is unreachable.
        let [
            identity_number,
            manufacturer_code,
            ecu_instance,
            function_instance,
            function,
            vehicle_system,
            vehicle_system_instance,
            industry_group,
            arbitrary_address_capable,
        ] = NAME_FIELDS.map(|f| dbc::extract_raw(f.signal, &bytes).unwrap_or(0));
        let narrow = |raw: i64| u8::try_from(raw).unwrap_or(0);
        NameFields {
            identity_number: u32::try_from(identity_number).unwrap_or(0),
            manufacturer_code: u16::try_from(manufacturer_code).unwrap_or(0),
            ecu_instance: narrow(ecu_instance),
            function_instance: narrow(function_instance),
            function: narrow(function),
            vehicle_system: narrow(vehicle_system),
            vehicle_system_instance: narrow(vehicle_system_instance),
            industry_group: narrow(industry_group),
            arbitrary_address_capable: arbitrary_address_capable == 1,
        }
    }
}

/// The fields shared by the project's default NAMEs: construction equipment (industry group 3), no
/// SAE manufacturer code (0), a fixed address. A machine's units get their identity numbers (serial
/// numbers) at provisioning; these defaults only have to differ from each other.
const PROJECT_NAME: NameFields = NameFields {
    identity_number: 0,
    manufacturer_code: 0,
    ecu_instance: 0,
    function_instance: 0,
    function: 0,
    vehicle_system: 0,
    vehicle_system_instance: 0,
    industry_group: 3,
    arbitrary_address_capable: false,
};

/// `fields` packed at the start bits of [`NAME_FIELDS`] without the range checks of
/// [`Name::from_fields`], for the constants below and for [`NameFields::name`], which checks the
/// widths first (a test checks it against [`Name::from_fields`]).
const fn pack(f: &NameFields) -> Name {
    let values = f.values();
    let mut raw = 0u64;
    let mut i = 0;
    while i < NAME_FIELDS.len() {
        raw |= values[i] << NAME_FIELDS[i].signal.start_bit;
        i += 1;
    }
    Name(raw)
}

/// The controller's default NAME: function 130 (industry-group specific: the excavation
/// controller), identity number 1.
pub const CONTROLLER_NAME: Name = pack(&NameFields {
    identity_number: 1,
    function: 130,
    ..PROJECT_NAME
});

/// The gateway's default NAME: function 129 (industry-group specific: the machine's CAN gateway),
/// identity number 2.
pub const GATEWAY_NAME: Name = pack(&NameFields {
    identity_number: 2,
    function: 129,
    ..PROJECT_NAME
});

/// Where a node stands in the claim procedure.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ClaimState {
    /// Not started: nothing sent.
    Idle,
    /// Claim sent at `since`; no application frames until it has stood for [`CLAIM_HOLD_NS`].
    Claiming {
        /// When the (last) claim was sent.
        since: Instant,
    },
    /// The claim stands: application frames may go out.
    Claimed,
    /// Another node with a lower (or equal) NAME took the address: Cannot Claim sent, silent for good.
    Lost {
        /// The winner's NAME.
        by: Name,
    },
}

/// How a node that lost its address answers a Request for Address Claimed (module docs, "Recovery
/// after a loss").
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AfterLoss {
    /// With Cannot Claim (J1939-81); only [`AddressClaimer::reclaim`] tries the address again.
    CannotClaim,
    /// A request to global re-claims the address (the project's gateway).
    ReclaimOnRequest,
}

/// What a received claim-procedure message did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ClaimEvent {
    /// A node with a higher NAME claimed our address: we keep it and claim again.
    Defended {
        /// The competitor's NAME.
        competitor: Name,
    },
    /// A node with a lower (or equal) NAME claimed our address: lost, Cannot Claim queued.
    Lost {
        /// The winner's NAME.
        competitor: Name,
    },
    /// A Request for Address Claimed for us: our claim (or Cannot Claim) queued.
    Answered,
    /// A Request for Address Claimed to global after we had lost, with [`AfterLoss::ReclaimOnRequest`]:
    /// our claim queued, the 250 ms hold starts again.
    Reclaimed {
        /// The NAME that had won the address.
        from: Name,
    },
    /// Nothing for us: another address's claim, a Cannot Claim, a request for another node or PGN,
    /// or a contest after we had already lost.
    Noted,
}

/// What is queued to send.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Pending {
    Claim,
    CannotClaim,
}

/// One node's address claim (see the module docs). Feed it received Address Claimed and Request
/// messages ([`Self::on_message`]), advance it with [`Self::update`] every period, send what
/// [`Self::take_frame`] returns, and send application frames only while [`Self::may_transmit`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AddressClaimer {
    name: Name,
    address: u8,
    state: ClaimState,
    pending: Option<Pending>,
    after_loss: AfterLoss,
    /// [`CLAIM_HOLD_NS`] plus the caller's margin.
    hold_ns: i64,
}

impl AddressClaimer {
    /// A node called `name` that will claim `address` and answers requests with Cannot Claim after
    /// losing it ([`AfterLoss::CannotClaim`]).
    pub const fn new(name: Name, address: u8) -> Self {
        Self {
            name,
            address,
            state: ClaimState::Idle,
            pending: None,
            after_loss: AfterLoss::CannotClaim,
            hold_ns: CLAIM_HOLD_NS,
        }
    }

    /// The same node waiting `margin_ns` longer than [`CLAIM_HOLD_NS`] (at most one second more)
    /// before its claim stands: a caller that stamps the claim with the start of a period and sends
    /// it at the period's end passes its period, so the claim stands at least 250 ms on the wire.
    pub const fn with_hold_margin(mut self, margin_ns: i64) -> Self {
        let margin_ns = if margin_ns < 0 {
            0
        } else if margin_ns > 1_000_000_000 {
            1_000_000_000
        } else {
            margin_ns
        };
        self.hold_ns = CLAIM_HOLD_NS + margin_ns;
        self
    }

    /// How long a claim must stand before it is taken as won: [`CLAIM_HOLD_NS`] plus the margin.
    pub const fn hold_ns(&self) -> i64 {
        self.hold_ns
    }

    /// The same node answering requests after a loss as `after_loss` says.
    pub const fn with_after_loss(mut self, after_loss: AfterLoss) -> Self {
        self.after_loss = after_loss;
        self
    }

    /// The controller called `name` at its address.
    pub const fn controller_named(name: Name) -> Self {
        Self::new(name, CONTROLLER_ADDRESS)
    }

    /// The gateway called `name` at its address, re-claiming on request after a loss.
    pub const fn gateway_named(name: Name) -> Self {
        Self::new(name, GATEWAY_ADDRESS).with_after_loss(AfterLoss::ReclaimOnRequest)
    }

    /// The controller with its default NAME and address.
    pub const fn controller() -> Self {
        Self::controller_named(CONTROLLER_NAME)
    }

    /// The gateway with its default NAME and address, re-claiming on request after a loss.
    pub const fn gateway() -> Self {
        Self::gateway_named(GATEWAY_NAME)
    }

    /// How a loss is answered.
    pub const fn after_loss(&self) -> AfterLoss {
        self.after_loss
    }

    /// Our NAME.
    pub const fn name(&self) -> Name {
        self.name
    }

    /// The address we claim.
    pub const fn address(&self) -> u8 {
        self.address
    }

    /// Where the procedure stands (as of the last [`Self::update`]).
    pub const fn state(&self) -> ClaimState {
        self.state
    }

    /// True once the claim has stood for [`CLAIM_HOLD_NS`] and was not lost: application frames may
    /// be sent.
    pub const fn may_transmit(&self) -> bool {
        matches!(self.state, ClaimState::Claimed)
    }

    /// The winner's NAME while the address is lost (until a re-claim).
    pub const fn lost(&self) -> Option<Name> {
        match self.state {
            ClaimState::Lost { by } => Some(by),
            _ => None,
        }
    }

    /// Starts the procedure at `now` (queues the claim). Does nothing once started.
    pub fn start(&mut self, now: Instant) {
        if self.state == ClaimState::Idle {
            self.state = ClaimState::Claiming { since: now };
            self.pending = Some(Pending::Claim);
        }
    }

    /// Claims the address again at `now` (module docs, "Recovery after a loss"): after a loss the
    /// claim is queued and the 250 ms hold starts again; a standing or pending claim is only sent
    /// again. The caller sends [`request_address_claimed`] to global first, so that a real owner
    /// answers. Returns the NAME that had won, if the address was lost.
    pub fn reclaim(&mut self, now: Instant) -> Option<Name> {
        let lost = self.lost();
        match self.state {
            ClaimState::Lost { .. } | ClaimState::Idle => {
                self.state = ClaimState::Claiming { since: now };
            }
            ClaimState::Claiming { .. } | ClaimState::Claimed => {}
        }
        self.pending = Some(Pending::Claim);
        lost
    }

    /// Advances the procedure to `now`: starts it if idle, and a claim that has stood for
    /// [`CLAIM_HOLD_NS`] becomes [`ClaimState::Claimed`].
    pub fn update(&mut self, now: Instant) -> ClaimState {
        self.start(now);
        if let ClaimState::Claiming { since } = self.state
            && now.nanos_since(since) >= self.hold_ns
        {
            self.state = ClaimState::Claimed;
        }
        self.state
    }

    /// Handles a received message from `id` at `now`. `None` if it is not part of the procedure
    /// (not Address Claimed or Request), so the caller handles it as before.
    pub fn on_message(
        &mut self,
        id: J1939Id,
        message: &Message,
        now: Instant,
    ) -> Option<ClaimEvent> {
        match *message {
            Message::AddressClaimed(claimed) => Some(self.on_claim(id, claimed.name, now)),
            Message::RequestPgn(request) => Some(self.on_request(id, request, now)),
            _ => None,
        }
    }

    fn on_claim(&mut self, id: J1939Id, theirs: Name, now: Instant) -> ClaimEvent {
        if id.source_address() != self.address || self.lost().is_some() {
            return ClaimEvent::Noted;
        }
        if theirs <= self.name {
            self.state = ClaimState::Lost { by: theirs };
            self.pending = Some(Pending::CannotClaim);
            return ClaimEvent::Lost { competitor: theirs };
        }
        self.pending = Some(Pending::Claim);
        match self.state {
            // Still within the first 250 ms: give the loser as long again to hear our claim.
            ClaimState::Claiming { .. } | ClaimState::Idle => {
                self.state = ClaimState::Claiming { since: now };
            }
            ClaimState::Claimed | ClaimState::Lost { .. } => {}
        }
        ClaimEvent::Defended { competitor: theirs }
    }

    fn on_request(&mut self, id: J1939Id, request: RequestPgn, now: Instant) -> ClaimEvent {
        let global = id.destination_address() == Some(GLOBAL_ADDRESS);
        let to_us =
            global || (id.destination_address() == Some(self.address) && self.lost().is_none());
        if !to_us || request.pgn != ADDRESS_CLAIMED_PGN || self.state == ClaimState::Idle {
            return ClaimEvent::Noted;
        }
        match (self.lost(), self.after_loss) {
            (None, _) => self.pending = Some(Pending::Claim),
            (Some(from), AfterLoss::ReclaimOnRequest) => {
                self.reclaim(now);
                return ClaimEvent::Reclaimed { from };
            }
            (Some(_), AfterLoss::CannotClaim) => self.pending = Some(Pending::CannotClaim),
        }
        ClaimEvent::Answered
    }

    /// The claim-procedure frame to send now, if any (Address Claimed from our address, or Cannot
    /// Claim from the null address). Send it before any application frame of the same period.
    ///
    /// # Errors
    /// [`EncodeError`] never in practice (every 64-bit NAME encodes); the frame then stays queued.
    pub fn take_frame(&mut self) -> Result<Option<CanFrame>, EncodeError> {
        let Some(pending) = self.pending else {
            return Ok(None);
        };
        let source = match pending {
            Pending::Claim => self.address,
            Pending::CannotClaim => NULL_ADDRESS,
        };
        let frame = Message::AddressClaimed(crate::messages::AddressClaimed { name: self.name })
            .encode_from(source)?;
        self.pending = None;
        Ok(Some(frame))
    }
}

/// A Request for Address Claimed from `source` to `destination` ([`GLOBAL_ADDRESS`] for all).
///
/// # Errors
/// [`EncodeError::Id`] never in practice (the PGN is PDU1 and the priority the DBC's).
pub fn request_address_claimed(destination: u8, source: u8) -> Result<CanFrame, EncodeError> {
    let desc = dbc::request_pgn::MESSAGE;
    let priority = J1939Id::from_raw(desc.default_id)?.priority();
    let id = J1939Id::new_pdu1(priority, REQUEST_PGN, destination, source)?;
    Message::RequestPgn(RequestPgn {
        pgn: ADDRESS_CLAIMED_PGN,
    })
    .encode_with_id(id)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::CanId;
    use crate::messages::AddressClaimed;

    /// A NAME with every field distinct, laid out by hand from J1939-81's field widths:
    /// identity 0x0ABCDE (bits 0-20) | manufacturer 0x3A5 << 21 = 0x74AABCDE (bytes 0-3);
    /// byte 4 = ECU instance 2 | function instance 5 << 3 = 0x2A; byte 5 = function 0x81;
    /// byte 6 = reserved 0 | vehicle system 0x23 << 1 = 0x46; byte 7 = vehicle system instance 3 |
    /// industry group 3 << 4 | not arbitrary-address capable = 0x33.
    const FIELDS: NameFields = NameFields {
        identity_number: 0x0A_BCDE,
        manufacturer_code: 0x3A5,
        ecu_instance: 2,
        function_instance: 5,
        function: 0x81,
        vehicle_system: 0x23,
        vehicle_system_instance: 3,
        industry_group: 3,
        arbitrary_address_capable: false,
    };
    const FIELDS_BYTES: [u8; 8] = [0xDE, 0xBC, 0xAA, 0x74, 0x2A, 0x81, 0x46, 0x33];

    const T0: Instant = Instant::from_millis(5);

    fn claim_from(source: u8, name: Name) -> (J1939Id, Message) {
        let frame = Message::AddressClaimed(AddressClaimed { name })
            .encode_from(source)
            .unwrap();
        let decoded = Message::decode(&frame).unwrap();
        (decoded.id, decoded.message)
    }

    fn ms(t: Instant, ms: i64) -> Instant {
        Instant::from_nanos(t.nanos() + ms * 1_000_000)
    }

    #[test]
    fn name_fields_match_the_j1939_81_byte_layout() {
        let name = Name::from_fields(&FIELDS).unwrap();
        assert_eq!(name.to_le_bytes(), FIELDS_BYTES);
        assert_eq!(name.raw(), 0x3346_812A_74AA_BCDE);
        assert_eq!(Name::from_le_bytes(FIELDS_BYTES).fields(), FIELDS);
        let frame = Message::AddressClaimed(AddressClaimed { name })
            .encode_from(0x27)
            .unwrap();
        assert_eq!(frame.id(), CanId::Extended(0x18EE_FF27));
        assert_eq!(frame.data(), &FIELDS_BYTES);
        assert_eq!(
            Message::decode(&frame).unwrap().message,
            Message::AddressClaimed(AddressClaimed { name })
        );
    }

    #[test]
    fn arbitrary_address_capable_is_the_top_bit() {
        let name = Name::from_fields(&NameFields {
            arbitrary_address_capable: true,
            ..FIELDS
        })
        .unwrap();
        assert_eq!(name.raw() >> 63, 1);
        assert!(name > Name::from_fields(&FIELDS).unwrap());
    }

    #[test]
    fn a_field_wider_than_its_bits_is_refused_by_name() {
        let err = Name::from_fields(&NameFields {
            identity_number: 1 << 21,
            ..FIELDS
        })
        .unwrap_err();
        assert!(matches!(
            err,
            EncodeError::OutOfRange {
                signal: "IdentityNumber",
                ..
            }
        ));
    }

    #[test]
    fn the_default_names_are_the_packed_fields_and_differ() {
        for (name, identity, function) in [(CONTROLLER_NAME, 1, 130), (GATEWAY_NAME, 2, 129)] {
            let fields = NameFields {
                identity_number: identity,
                function,
                ..PROJECT_NAME
            };
            assert_eq!(Name::from_fields(&fields).unwrap(), name);
            assert_eq!(name.fields(), fields);
        }
        assert_ne!(CONTROLLER_NAME, GATEWAY_NAME);
    }

    #[test]
    fn uncontested_claim_stands_after_250_ms_and_not_before() {
        let mut c = AddressClaimer::controller();
        assert!(!c.may_transmit());
        c.update(T0);
        let frame = c.take_frame().unwrap().unwrap();
        assert_eq!(frame.id(), CanId::Extended(0x18EE_FF27));
        assert_eq!(frame.data(), &CONTROLLER_NAME.to_le_bytes());
        assert_eq!(c.take_frame().unwrap(), None);
        c.update(ms(T0, 249));
        assert!(!c.may_transmit());
        c.update(ms(T0, 250));
        assert!(c.may_transmit());
    }

    #[test]
    fn a_lower_name_for_our_address_wins_and_we_send_cannot_claim() {
        let mut c = AddressClaimer::controller();
        c.update(T0);
        c.take_frame().unwrap();
        let winner = Name::from_raw(CONTROLLER_NAME.raw() - 1);
        let (id, msg) = claim_from(CONTROLLER_ADDRESS, winner);
        assert_eq!(
            c.on_message(id, &msg, ms(T0, 10)),
            Some(ClaimEvent::Lost { competitor: winner })
        );
        let frame = c.take_frame().unwrap().unwrap();
        assert_eq!(frame.id(), CanId::Extended(0x18EE_FFFE));
        assert_eq!(frame.data(), &CONTROLLER_NAME.to_le_bytes());
        c.update(ms(T0, 1000));
        assert!(!c.may_transmit());
        assert_eq!(c.lost(), Some(winner));
    }

    #[test]
    fn a_higher_name_for_our_address_loses_and_we_claim_again() {
        let mut c = AddressClaimer::gateway();
        c.update(T0);
        c.take_frame().unwrap();
        let loser = Name::from_raw(GATEWAY_NAME.raw() + 1);
        let (id, msg) = claim_from(GATEWAY_ADDRESS, loser);
        assert_eq!(
            c.on_message(id, &msg, ms(T0, 100)),
            Some(ClaimEvent::Defended { competitor: loser })
        );
        let frame = c.take_frame().unwrap().unwrap();
        assert_eq!(frame.id(), CanId::Extended(0x18EE_FF80));
        // The hold restarts from the second claim.
        c.update(ms(T0, 300));
        assert!(!c.may_transmit());
        c.update(ms(T0, 350));
        assert!(c.may_transmit());
    }

    #[test]
    fn a_late_claimant_is_handled_as_a_contest() {
        let mut c = AddressClaimer::controller();
        c.update(T0);
        c.update(ms(T0, 300));
        assert!(c.may_transmit());
        // Higher NAME later: defended without a pause.
        let (id, msg) = claim_from(CONTROLLER_ADDRESS, Name::from_raw(u64::MAX));
        c.on_message(id, &msg, ms(T0, 5000));
        assert!(c.may_transmit());
        assert!(c.take_frame().unwrap().is_some());
        // Lower NAME later: lost at once.
        let (id, msg) = claim_from(CONTROLLER_ADDRESS, Name::from_raw(0));
        c.on_message(id, &msg, ms(T0, 6000));
        assert!(!c.may_transmit());
        assert_eq!(c.lost(), Some(Name::from_raw(0)));
    }

    #[test]
    fn an_equal_name_from_our_address_is_a_duplicate_unit_and_loses() {
        let mut c = AddressClaimer::controller();
        c.update(T0);
        let (id, msg) = claim_from(CONTROLLER_ADDRESS, CONTROLLER_NAME);
        c.on_message(id, &msg, ms(T0, 1));
        assert_eq!(c.lost(), Some(CONTROLLER_NAME));
    }

    #[test]
    fn claims_for_other_addresses_and_cannot_claims_are_noted() {
        let mut c = AddressClaimer::controller();
        c.update(T0);
        c.take_frame().unwrap();
        for source in [GATEWAY_ADDRESS, NULL_ADDRESS, 0x99] {
            let (id, msg) = claim_from(source, Name::from_raw(0));
            assert_eq!(c.on_message(id, &msg, T0), Some(ClaimEvent::Noted));
        }
        assert_eq!(c.take_frame().unwrap(), None);
        c.update(ms(T0, 250));
        assert!(c.may_transmit());
    }

    #[test]
    fn a_request_for_address_claimed_is_answered_with_the_claim() {
        let mut c = AddressClaimer::gateway();
        c.update(T0);
        c.take_frame().unwrap();
        for destination in [GLOBAL_ADDRESS, GATEWAY_ADDRESS] {
            let decoded =
                Message::decode(&request_address_claimed(destination, 0x99).unwrap()).unwrap();
            assert_eq!(decoded.id.destination_address(), Some(destination));
            assert_eq!(
                c.on_message(decoded.id, &decoded.message, T0),
                Some(ClaimEvent::Answered)
            );
            let frame = c.take_frame().unwrap().unwrap();
            assert_eq!(frame.id(), CanId::Extended(0x18EE_FF80));
        }
        // To another node: not ours to answer.
        let decoded = Message::decode(&request_address_claimed(0x27, 0x99).unwrap()).unwrap();
        assert_eq!(
            c.on_message(decoded.id, &decoded.message, T0),
            Some(ClaimEvent::Noted)
        );
        assert_eq!(c.take_frame().unwrap(), None);
    }

    #[test]
    fn after_losing_a_request_is_answered_with_cannot_claim() {
        let mut c = AddressClaimer::controller();
        c.update(T0);
        let (id, msg) = claim_from(CONTROLLER_ADDRESS, Name::from_raw(0));
        c.on_message(id, &msg, T0);
        c.take_frame().unwrap();
        let decoded =
            Message::decode(&request_address_claimed(GLOBAL_ADDRESS, NULL_ADDRESS).unwrap())
                .unwrap();
        c.on_message(decoded.id, &decoded.message, T0);
        let frame = c.take_frame().unwrap().unwrap();
        assert_eq!(frame.id(), CanId::Extended(0x18EE_FFFE));
    }

    /// Loses `c`'s address to NAME 0 at `T0` + 10 ms and drops the Cannot Claim.
    fn lose(c: &mut AddressClaimer) {
        c.update(T0);
        c.take_frame().unwrap();
        let (id, msg) = claim_from(c.address(), Name::from_raw(0));
        c.on_message(id, &msg, ms(T0, 10));
        assert_eq!(c.take_frame().unwrap().unwrap().id().raw(), 0x18EE_FFFE);
        c.update(ms(T0, 1000));
        assert_eq!(c.lost(), Some(Name::from_raw(0)));
    }

    fn request(destination: u8) -> (J1939Id, Message) {
        let decoded =
            Message::decode(&request_address_claimed(destination, CONTROLLER_ADDRESS).unwrap())
                .unwrap();
        (decoded.id, decoded.message)
    }

    #[test]
    fn a_reclaim_after_a_transient_claim_stands_250_ms_later() {
        let mut c = AddressClaimer::controller();
        lose(&mut c);
        let at = ms(T0, 2000);
        assert_eq!(c.reclaim(at), Some(Name::from_raw(0)));
        let frame = c.take_frame().unwrap().unwrap();
        assert_eq!(frame.id(), CanId::Extended(0x18EE_FF27));
        assert_eq!(frame.data(), &CONTROLLER_NAME.to_le_bytes());
        c.update(ms(at, 249));
        assert!(!c.may_transmit() && c.lost().is_none());
        c.update(ms(at, 250));
        assert!(c.may_transmit());
    }

    #[test]
    fn a_reclaim_loses_again_when_the_owner_answers() {
        let mut c = AddressClaimer::controller();
        lose(&mut c);
        let at = ms(T0, 2000);
        c.reclaim(at);
        c.take_frame().unwrap();
        // The owner answers the request (or our claim) with its lower NAME.
        let (id, msg) = claim_from(CONTROLLER_ADDRESS, Name::from_raw(0));
        assert_eq!(
            c.on_message(id, &msg, ms(at, 5)),
            Some(ClaimEvent::Lost {
                competitor: Name::from_raw(0)
            })
        );
        assert_eq!(c.take_frame().unwrap().unwrap().id().raw(), 0x18EE_FFFE);
        c.update(ms(at, 300));
        assert!(!c.may_transmit());
    }

    #[test]
    fn a_hold_margin_delays_the_claim_standing() {
        let mut c = AddressClaimer::controller().with_hold_margin(10_000_000);
        c.update(T0);
        c.update(ms(T0, 259));
        assert!(!c.may_transmit());
        c.update(ms(T0, 260));
        assert!(c.may_transmit());
    }

    #[test]
    fn a_reclaim_of_a_standing_claim_only_sends_it_again() {
        let mut c = AddressClaimer::controller();
        c.update(T0);
        c.update(ms(T0, 300));
        assert_eq!(c.reclaim(ms(T0, 400)), None);
        assert!(c.may_transmit());
        assert!(c.take_frame().unwrap().is_some());
    }

    #[test]
    fn after_losing_the_gateway_reclaims_on_a_global_request_only() {
        let mut g = AddressClaimer::gateway();
        lose(&mut g);
        // Addressed to 0x80: for the node that holds it now, not for us.
        let (id, msg) = request(GATEWAY_ADDRESS);
        assert_eq!(
            g.on_message(id, &msg, ms(T0, 1500)),
            Some(ClaimEvent::Noted)
        );
        assert_eq!(g.take_frame().unwrap(), None);
        let (id, msg) = request(GLOBAL_ADDRESS);
        let at = ms(T0, 2000);
        assert_eq!(
            g.on_message(id, &msg, at),
            Some(ClaimEvent::Reclaimed {
                from: Name::from_raw(0)
            })
        );
        let frame = g.take_frame().unwrap().unwrap();
        assert_eq!(frame.id(), CanId::Extended(0x18EE_FF80));
        assert_eq!(frame.data(), &GATEWAY_NAME.to_le_bytes());
        g.update(ms(at, 249));
        assert!(!g.may_transmit());
        g.update(ms(at, 250));
        assert!(g.may_transmit());
    }

    #[test]
    fn the_controller_answers_a_request_after_losing_with_cannot_claim_not_a_claim() {
        let mut c = AddressClaimer::controller();
        assert_eq!(c.after_loss(), AfterLoss::CannotClaim);
        lose(&mut c);
        let (id, msg) = request(GLOBAL_ADDRESS);
        assert_eq!(
            c.on_message(id, &msg, ms(T0, 2000)),
            Some(ClaimEvent::Answered)
        );
        assert_eq!(c.take_frame().unwrap().unwrap().id().raw(), 0x18EE_FFFE);
        assert!(c.lost().is_some());
    }

    #[test]
    fn the_request_frame_has_three_bytes_with_the_pgn() {
        let frame = request_address_claimed(GLOBAL_ADDRESS, 0x27).unwrap();
        assert_eq!(frame.id(), CanId::Extended(0x18EA_FF27));
        assert_eq!(frame.data(), &[0x00, 0xEE, 0x00]);
    }
}
