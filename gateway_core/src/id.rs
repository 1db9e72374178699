//! J1939 29-bit identifiers: priority, parameter group number (PGN) and source address.
//!
//! Layout of the 29 bits (SAE J1939-21):
//!
//! ```text
//!  28..26   25    24   23..16   15..8        7..0
//! priority  EDP   DP    PF       PS           SA
//!                            (PDU1: DA, PDU2: group extension)
//! ```
//!
//! For PDU1 (`PF < 240`) the PS byte is a destination address and not part of the PGN; for PDU2
//! (`PF >= 240`) it is the group extension and belongs to the PGN. Every message of this project is PDU2
//! (broadcast), but the type handles both so foreign traffic is classified correctly.

use core::fmt;

/// The controller's J1939 source address (see `docs/ARCHITECTURE.md`).
pub const CONTROLLER_ADDRESS: u8 = 0x27;
/// The gateway's (machine or simulator) J1939 source address.
pub const GATEWAY_ADDRESS: u8 = 0x80;
/// The global destination address used in PDU1 broadcasts.
pub const GLOBAL_ADDRESS: u8 = 0xFF;

/// Largest 29-bit identifier.
pub const MAX_EXTENDED_ID: u32 = 0x1FFF_FFFF;

/// Errors building a J1939 id from parts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum IdError {
    /// Priority above 7.
    #[error("J1939 priority {0} is above 7")]
    Priority(u8),
    /// PGN above 18 bits.
    #[error("PGN {0:#x} does not fit 18 bits")]
    Pgn(u32),
    /// A PDU1 PGN (PF < 240) whose low byte is not zero: the low byte is the destination address.
    #[error("PDU1 PGN {0:#x} must have a zero low byte (use the destination address instead)")]
    Pdu1LowByte(u32),
    /// Raw id above 29 bits.
    #[error("id {0:#x} does not fit 29 bits")]
    TooLarge(u32),
}

/// Result alias for this module.
pub type Result<T> = core::result::Result<T, IdError>;

/// A 29-bit J1939 identifier.
///
/// ```
/// use gateway_core::id::J1939Id;
/// let id = J1939Id::from_raw(0x0CFE_3027).unwrap();
/// assert_eq!((id.priority(), id.pgn(), id.source_address()), (3, 65072, 0x27));
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct J1939Id(u32);

impl J1939Id {
    /// Wraps a raw 29-bit id.
    ///
    /// # Errors
    /// [`IdError::TooLarge`] if `raw` has bits above bit 28.
    pub const fn from_raw(raw: u32) -> Result<Self> {
        if raw > MAX_EXTENDED_ID {
            return Err(IdError::TooLarge(raw));
        }
        Ok(Self(raw))
    }

    /// Builds an id for a PDU2 (broadcast) or PDU1 PGN. For PDU1 PGNs the destination address is
    /// [`GLOBAL_ADDRESS`]; use [`J1939Id::new_pdu1`] to address one node.
    ///
    /// # Errors
    /// [`IdError`] if the priority or PGN is out of range.
    pub const fn new(priority: u8, pgn: u32, source_address: u8) -> Result<Self> {
        if pgn > 0x3_FFFF {
            return Err(IdError::Pgn(pgn));
        }
        let pf = (pgn >> 8) & 0xFF;
        if pf < 240 {
            if pgn & 0xFF != 0 {
                return Err(IdError::Pdu1LowByte(pgn));
            }
            return Self::new_pdu1(priority, pgn, GLOBAL_ADDRESS, source_address);
        }
        if priority > 7 {
            return Err(IdError::Priority(priority));
        }
        Ok(Self(
            ((priority as u32) << 26) | (pgn << 8) | source_address as u32,
        ))
    }

    /// Builds a PDU1 (destination-specific) id.
    ///
    /// # Errors
    /// [`IdError`] if the priority or PGN is out of range or the PGN is not PDU1.
    pub const fn new_pdu1(
        priority: u8,
        pgn: u32,
        destination_address: u8,
        source_address: u8,
    ) -> Result<Self> {
        if priority > 7 {
            return Err(IdError::Priority(priority));
        }
        if pgn > 0x3_FFFF {
            return Err(IdError::Pgn(pgn));
        }
        if pgn & 0xFF != 0 || ((pgn >> 8) & 0xFF) >= 240 {
            return Err(IdError::Pdu1LowByte(pgn));
        }
        Ok(Self(
            ((priority as u32) << 26)
                | (pgn << 8)
                | ((destination_address as u32) << 8)
                | source_address as u32,
        ))
    }

    /// The raw 29-bit value.
    pub const fn raw(self) -> u32 {
        self.0
    }

    /// Priority, 0 (highest) to 7.
    pub const fn priority(self) -> u8 {
        ((self.0 >> 26) & 0x7) as u8
    }

    /// Extended data page bit.
    pub const fn edp(self) -> bool {
        (self.0 >> 25) & 1 == 1
    }

    /// Data page bit.
    pub const fn dp(self) -> bool {
        (self.0 >> 24) & 1 == 1
    }

    /// PDU format byte.
    pub const fn pdu_format(self) -> u8 {
        ((self.0 >> 16) & 0xFF) as u8
    }

    /// PDU specific byte (destination address for PDU1, group extension for PDU2).
    pub const fn pdu_specific(self) -> u8 {
        ((self.0 >> 8) & 0xFF) as u8
    }

    /// True for PDU2 (broadcast, `PF >= 240`).
    pub const fn is_pdu2(self) -> bool {
        self.pdu_format() >= 240
    }

    /// The parameter group number, including EDP and DP; the PS byte only for PDU2.
    pub const fn pgn(self) -> u32 {
        let page_and_pf = (self.0 >> 8) & 0x3_FF00;
        if self.is_pdu2() {
            page_and_pf | self.pdu_specific() as u32
        } else {
            page_and_pf
        }
    }

    /// Destination address for PDU1, `None` for PDU2 (broadcast).
    pub const fn destination_address(self) -> Option<u8> {
        if self.is_pdu2() {
            None
        } else {
            Some(self.pdu_specific())
        }
    }

    /// Source address of the sender.
    pub const fn source_address(self) -> u8 {
        (self.0 & 0xFF) as u8
    }

    /// The same id with a different source address.
    pub const fn with_source_address(self, source_address: u8) -> Self {
        Self((self.0 & !0xFF) | source_address as u32)
    }
}

impl fmt::Display for J1939Id {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{:08X} (prio {}, PGN {:#06X}, SA {:#04X})",
            self.0,
            self.priority(),
            self.pgn(),
            self.source_address()
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const BOOM_VALVE_COMMAND_ID: u32 = 0x0CFE_3027;

    #[test]
    fn boom_valve_command_id_splits_into_its_fields() {
        let id = J1939Id::from_raw(BOOM_VALVE_COMMAND_ID).unwrap();
        assert_eq!(id.priority(), 3);
        assert_eq!(id.pgn(), 65072);
        assert_eq!(id.source_address(), CONTROLLER_ADDRESS);
        assert!(id.is_pdu2());
        assert_eq!(id.destination_address(), None);
        assert_eq!(J1939Id::new(3, 65072, 0x27).unwrap(), id);
    }

    #[test]
    fn pdu1_pgn_excludes_destination_address() {
        // TSC1 (PGN 0) to engine 0x00 from 0x27 at priority 3.
        let id = J1939Id::new_pdu1(3, 0, 0x00, 0x27).unwrap();
        assert_eq!(id.raw(), 0x0C00_0027);
        let id = J1939Id::from_raw(0x18EA_0027).unwrap(); // request PGN 59904 to DA 0
        assert_eq!(id.pgn(), 0xEA00);
        assert_eq!(id.destination_address(), Some(0));
    }

    #[test]
    fn data_page_bits_are_part_of_the_pgn() {
        let id = J1939Id::from_raw(0x03FF_5080).unwrap();
        assert!(id.edp() && id.dp());
        assert_eq!(id.pgn(), 0x3_FF50);
        assert_eq!(J1939Id::new(0, 0x3_FF50, 0x80).unwrap(), id);
    }

    #[test]
    fn out_of_range_parts_are_rejected() {
        assert_eq!(J1939Id::new(8, 0xFF50, 0), Err(IdError::Priority(8)));
        assert_eq!(J1939Id::new(3, 0x4_0000, 0), Err(IdError::Pgn(0x4_0000)));
        assert_eq!(
            J1939Id::new(3, 0xEA01, 0),
            Err(IdError::Pdu1LowByte(0xEA01))
        );
        assert_eq!(
            J1939Id::from_raw(0x2000_0000),
            Err(IdError::TooLarge(0x2000_0000))
        );
    }
}
