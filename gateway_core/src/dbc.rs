//! Signal descriptors generated from `excavator.dbc`, and the generic signal codec.
//!
//! `build.rs` parses the DBC with `can-dbc` and writes one module per message (for example
//! [`joint_angles`]) holding a [`MessageDesc`] and one [`SignalDesc`] per signal. The typed messages in
//! [`crate::messages`] use only these descriptors and the functions here to put values on the wire, so
//! the layout, scaling and ranges exist in exactly one place: the DBC.
//!
//! Raw values outside a signal's `[min, max]` are classified with the J1939 conventions: for unsigned
//! signals of 8 bits or more, a top byte of `0xFF` is "not available" and `0xFE` is an "error indicator";
//! for shorter unsigned signals all ones is "not available" and all ones minus one is "error indicator".
//! Signed signals (two's complement, a project choice) use the largest positive value for "not
//! available" and the one below it for "error indicator". Anything else outside the range is
//! "out of range".

/// The DBC text (`excavator.dbc`), embedded so the binaries need no data files: the same file
/// `build.rs` generates the descriptors from.
pub const DBC_TEXT: &str = include_str!("../excavator.dbc");

/// The controller's control period: the DBC's cycle time (`GenMsgCycleTime`) of its periodic command,
/// `AuxValveCommand_Boom` (every joint's command and the position setpoint have the same). The
/// controller steps at this period, and the simulator, the lab and the tests that step with it use
/// this constant, so the message schedule and the step rate are one fact.
pub const CONTROL_PERIOD: core::time::Duration =
    core::time::Duration::from_millis(aux_valve_command_boom::MESSAGE.cycle_time_ms as u64);

/// The gateway's sensor period: the DBC's cycle time of `JointAngles` (`JointRates` and the three
/// `AuxValveMeasured` have the same; the gateway samples its resolvers and transducers at this
/// rate). The controller's staleness limits, the simulator's schedule and the tests' sample clock
/// take it from here.
pub const SENSOR_PERIOD: core::time::Duration =
    core::time::Duration::from_millis(joint_angles::MESSAGE.cycle_time_ms as u64);

/// The gateway's `PumpPressures` period (the DBC's cycle time).
pub const PUMP_PERIOD: core::time::Duration =
    core::time::Duration::from_millis(pump_pressures::MESSAGE.cycle_time_ms as u64);

/// The gateway's `TrackOdometry` period (the DBC's cycle time).
pub const ODOMETRY_PERIOD: core::time::Duration =
    core::time::Duration::from_millis(track_odometry::MESSAGE.cycle_time_ms as u64);

/// The gateway's status period: the DBC's cycle time of `GatewayStatus` (`GatewaySession` has the
/// same).
pub const STATUS_PERIOD: core::time::Duration =
    core::time::Duration::from_millis(gateway_status::MESSAGE.cycle_time_ms as u64);

/// Description of one signal, generated from the DBC.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SignalDesc {
    /// Signal name in the DBC.
    pub name: &'static str,
    /// Start bit (DBC numbering; little-endian: bit 0 is the LSB of byte 0).
    pub start_bit: u16,
    /// Length in bits (1..=32).
    pub len: u16,
    /// Byte order: always little-endian (Intel) in this project; `build.rs` rejects anything else.
    pub little_endian: bool,
    /// Two's complement signed.
    pub signed: bool,
    /// Physical value per raw bit.
    pub factor: f64,
    /// Physical offset.
    pub offset: f64,
    /// Smallest valid physical value.
    pub min: f64,
    /// Largest valid physical value.
    pub max: f64,
    /// Smallest valid raw value (from `min`).
    pub raw_min: i64,
    /// Largest valid raw value (from `max`).
    pub raw_max: i64,
    /// Unit string from the DBC.
    pub unit: &'static str,
}

/// Description of one message, generated from the DBC.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MessageDesc {
    /// Message name in the DBC.
    pub name: &'static str,
    /// The 29-bit id in the DBC: priority, PGN and the sender's source address.
    pub default_id: u32,
    /// Parameter group number.
    pub pgn: u32,
    /// Data length in bytes.
    pub dlc: u8,
    /// Sending node in the DBC (`Controller` or `Gateway`).
    pub transmitter: &'static str,
    /// Transmission period in the DBC (`GenMsgCycleTime`), ms; 0 for the event messages (Address
    /// Claimed and Request, sent at start, in a contest and on request: never on a schedule).
    pub cycle_time_ms: u16,
    /// Signals in DBC order.
    pub signals: &'static [SignalDesc],
}

include!(concat!(env!("OUT_DIR"), "/dbc_generated.rs"));

/// Why a frame could not be decoded. Small and `Copy` for the receive hot path.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    /// The PGN is not one of the project's messages.
    #[error("unknown PGN {pgn:#06X} (id {id:#010X})")]
    UnknownPgn {
        /// The PGN of the frame.
        pgn: u32,
        /// The 29-bit id.
        id: u32,
    },
    /// An 11-bit id where a 29-bit J1939 id was expected.
    #[error("standard (11-bit) id {0:#05X} where a 29-bit J1939 id was expected")]
    StandardId(u16),
    /// A remote transmission request.
    #[error("remote (RTR) frame")]
    RemoteFrame,
    /// An error frame.
    #[error("error frame (class {0:#010X})")]
    ErrorFrame(u32),
    /// A CAN FD frame (the protocol is classic CAN).
    #[error("CAN FD frame where a classic frame was expected")]
    FdFrame,
    /// The payload length does not match the DBC.
    #[error("{message}: {actual} data bytes, expected {expected}")]
    WrongDlc {
        /// DBC message name.
        message: &'static str,
        /// DLC in the DBC.
        expected: u8,
        /// Bytes in the frame.
        actual: u8,
    },
    /// A raw value outside the signal's range that is not a J1939 special value.
    #[error("signal {signal}: raw value {raw} out of range")]
    OutOfRange {
        /// DBC signal name.
        signal: &'static str,
        /// The raw value.
        raw: i64,
    },
    /// The J1939 "not available" value.
    #[error("signal {signal}: not available")]
    NotAvailable {
        /// DBC signal name.
        signal: &'static str,
    },
    /// The J1939 "error indicator" value.
    #[error("signal {signal}: error indicator")]
    ErrorIndicator {
        /// DBC signal name.
        signal: &'static str,
    },
    /// The heartbeat checksum does not match.
    #[error("bad checksum: received {received:#04X}, computed {computed:#04X}")]
    BadChecksum {
        /// Checksum in the frame.
        received: u8,
        /// Checksum computed over the frame.
        computed: u8,
    },
}

/// Why a value could not be encoded. No value is silently clamped.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum EncodeError {
    /// The physical value is outside the signal's `[min, max]`.
    #[error("signal {signal}: value {value} outside [{min}, {max}]")]
    OutOfRange {
        /// DBC signal name.
        signal: &'static str,
        /// The rejected value.
        value: f64,
        /// Smallest valid value.
        min: f64,
        /// Largest valid value.
        max: f64,
    },
    /// NaN or infinite.
    #[error("signal {signal}: value is not finite")]
    NotFinite {
        /// DBC signal name.
        signal: &'static str,
    },
    /// A J1939 identifier could not be built. Ids come from the DBC and source addresses are `u8`, so
    /// this does not happen in practice; the variant lets id errors propagate instead of panicking.
    #[error("invalid identifier: {0}")]
    Id(#[from] crate::id::IdError),
}

/// Extracts the raw bits of `sig` from `data` (sign-extended if signed). Returns `None` if the signal
/// does not fit in `data`.
pub fn extract_raw(sig: &SignalDesc, data: &[u8]) -> Option<i64> {
    let start = usize::from(sig.start_bit);
    let len = usize::from(sig.len);
    if len == 0 || len > 32 || start + len > data.len() * 8 {
        return None;
    }
    // Intel (little-endian) bit numbering: the signal is bits `start..start + len` of the payload
    // read as one little-endian word.
    let value: u64 = if data.len() <= 8 {
        let mut word = [0_u8; 8];
        word[..data.len()].copy_from_slice(data);
        (u64::from_le_bytes(word) >> start) & ((1_u64 << len) - 1)
    } else {
        (0..len).fold(0, |v, i| {
            let bit = start + i;
            v | (u64::from((data[bit / 8] >> (bit % 8)) & 1) << i)
        })
    };
    if sig.signed && (value >> (len - 1)) & 1 == 1 {
        Some(value as i64 - (1i64 << len))
    } else {
        Some(value as i64)
    }
}

/// Writes the raw value `raw` (two's complement if negative) into the bits of `sig`.
/// Bits outside the signal are untouched. Returns `None` if the signal does not fit in `data`.
pub fn insert_raw(sig: &SignalDesc, raw: i64, data: &mut [u8]) -> Option<()> {
    let start = usize::from(sig.start_bit);
    let len = usize::from(sig.len);
    if len == 0 || len > 32 || start + len > data.len() * 8 {
        return None;
    }
    let bits = raw as u64;
    for i in 0..len {
        let bit = start + i;
        let mask = 1u8 << (bit % 8);
        if (bits >> i) & 1 == 1 {
            data[bit / 8] |= mask;
        } else {
            data[bit / 8] &= !mask;
        }
    }
    Some(())
}

/// Classifies a raw value outside `[raw_min, raw_max]` with the J1939 conventions.
fn classify_invalid(sig: &SignalDesc, raw: i64) -> DecodeError {
    let len = u32::from(sig.len);
    let signal = sig.name;
    if sig.signed {
        let max = (1i64 << (len - 1)) - 1;
        if raw == max {
            return DecodeError::NotAvailable { signal };
        }
        if raw == max - 1 {
            return DecodeError::ErrorIndicator { signal };
        }
    } else if len >= 8 {
        match (raw >> (len - 8)) & 0xFF {
            0xFF => return DecodeError::NotAvailable { signal },
            0xFE => return DecodeError::ErrorIndicator { signal },
            _ => {}
        }
    } else {
        let all_ones = (1i64 << len) - 1;
        if raw == all_ones {
            return DecodeError::NotAvailable { signal };
        }
        if raw == all_ones - 1 && len >= 2 {
            return DecodeError::ErrorIndicator { signal };
        }
    }
    DecodeError::OutOfRange { signal, raw }
}

/// Decodes the raw value of `sig`, checking its range.
///
/// # Errors
/// [`DecodeError::NotAvailable`], [`DecodeError::ErrorIndicator`] or [`DecodeError::OutOfRange`] for raw
/// values outside the signal's range; [`DecodeError::OutOfRange`] if the data is too short (callers
/// check the DLC first, so this does not happen in practice).
pub fn decode_raw(sig: &SignalDesc, data: &[u8]) -> Result<i64, DecodeError> {
    let raw = extract_raw(sig, data).ok_or(DecodeError::OutOfRange {
        signal: sig.name,
        raw: -1,
    })?;
    if raw < sig.raw_min || raw > sig.raw_max {
        return Err(classify_invalid(sig, raw));
    }
    Ok(raw)
}

/// Decodes the physical value of `sig` (`raw * factor + offset`), checking its range.
///
/// # Errors
/// As [`decode_raw`].
pub fn decode_physical(sig: &SignalDesc, data: &[u8]) -> Result<f64, DecodeError> {
    decode_raw(sig, data).map(|raw| raw_to_physical(sig, raw))
}

/// `raw * factor + offset`, correctly rounded for decimal factors.
///
/// A factor like 0.4 or 0.0001 is not exact in binary, so `raw * factor` can land one ulp off the
/// decimal value (3 * 0.4 = 1.2000000000000002). The factor is written as `numerator / 10^k` with
/// the smallest such `k` and the value computed as `(raw * numerator) / 10^k`, one correctly rounded
/// division of exact integers (3 * 0.4 -> 1.2, not 1.2000000000000002). That keeps decoding the same
/// physical value from a coarse and a fine signal bit-identical.
pub fn raw_to_physical(sig: &SignalDesc, raw: i64) -> f64 {
    raw_to_physical_with(sig, decimal_factor(sig.factor), raw)
}

/// [`raw_to_physical`] with the signal's [`decimal_factor`] already worked out (a decoder that
/// keeps it per signal).
#[must_use]
pub fn raw_to_physical_with(sig: &SignalDesc, decimal: Option<(i64, i64)>, raw: i64) -> f64 {
    let scaled = match decimal {
        Some((numerator, denominator))
            if (raw.unsigned_abs() as f64) * (numerator as f64) < 9.0e15 =>
        {
            (raw as f64 * numerator as f64) / denominator as f64
        }
        _ => raw as f64 * sig.factor,
    };
    scaled + sig.offset
}

/// `factor` as `numerator / 10^k` (both exact integers in `f64`), if it has at most nine decimals.
#[must_use]
pub fn decimal_factor(factor: f64) -> Option<(i64, i64)> {
    let mut denominator: i64 = 1;
    for _ in 0..=9 {
        let numerator = factor * denominator as f64;
        // The nearest integer, ties away from zero, as `f64::round` (a library call on baseline
        // x86-64; this runs for every signal decoded) without the call: a saturating cast.
        let half = if numerator < 0.0 { -0.5 } else { 0.5 };
        let rounded = (numerator + half) as i64;
        if rounded != 0
            && (numerator - rounded as f64).abs() <= 1e-9 * (rounded as f64).abs()
            && rounded.unsigned_abs() < 1_000_000_000
        {
            return Some((rounded, denominator));
        }
        denominator *= 10;
    }
    None
}

/// The raw value that encodes `value`, rounded to the nearest step.
///
/// # Errors
/// [`EncodeError::NotFinite`] or [`EncodeError::OutOfRange`] (values more than half a step outside
/// `[min, max]`; values within half a step round to the limit).
pub fn physical_to_raw(sig: &SignalDesc, value: f64) -> Result<i64, EncodeError> {
    if !value.is_finite() {
        return Err(EncodeError::NotFinite { signal: sig.name });
    }
    let raw = libm::round((value - sig.offset) / sig.factor);
    if raw < sig.raw_min as f64 || raw > sig.raw_max as f64 {
        return Err(EncodeError::OutOfRange {
            signal: sig.name,
            value,
            min: sig.min,
            max: sig.max,
        });
    }
    Ok(raw as i64)
}

/// Encodes the physical `value` of `sig` into `data`.
///
/// # Errors
/// As [`physical_to_raw`].
pub fn encode_physical(sig: &SignalDesc, value: f64, data: &mut [u8]) -> Result<(), EncodeError> {
    let raw = physical_to_raw(sig, value)?;
    encode_raw(sig, raw, data)
}

/// Encodes a raw value of `sig` into `data`, checking it against the signal's raw range.
///
/// # Errors
/// [`EncodeError::OutOfRange`] if `raw` is outside `[raw_min, raw_max]` or the signal does not fit
/// `data`.
pub fn encode_raw(sig: &SignalDesc, raw: i64, data: &mut [u8]) -> Result<(), EncodeError> {
    let out_of_range = EncodeError::OutOfRange {
        signal: sig.name,
        value: raw as f64,
        min: sig.raw_min as f64,
        max: sig.raw_max as f64,
    };
    if raw < sig.raw_min || raw > sig.raw_max {
        return Err(out_of_range);
    }
    insert_raw(sig, raw, data).ok_or(out_of_range)
}

/// Looks up the descriptor of a message by PGN.
pub fn message_by_pgn(pgn: u32) -> Option<&'static MessageDesc> {
    MESSAGES.iter().find(|m| m.pgn == pgn)
}

/// The index in [`MESSAGES`] of the DBC message a frame with the 29-bit `raw_id` is: the one of its
/// PGN sent from its source address (`AddressClaimed` from `0x27`, `AddressClaimed_Gateway` from
/// `0x80`; `DM1`, `DM1_Gateway`), else the first of its PGN (a message from another address).
pub fn message_index_by_id(raw_id: u32) -> Option<usize> {
    let id = crate::id::J1939Id::from_raw(raw_id).ok()?;
    let pgn = id.pgn();
    let of_pgn = || {
        MESSAGES
            .iter()
            .enumerate()
            .filter(move |(_, m)| m.pgn == pgn)
    };
    of_pgn()
        .find(|(_, m)| m.default_id & 0xFF == u32::from(id.source_address()))
        .or_else(|| of_pgn().next())
        .map(|(i, _)| i)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn generated_tables_match_the_documented_ids() {
        assert_eq!(aux_valve_command_boom::MESSAGE.default_id, 0x0CFE_3027);
        assert_eq!(aux_valve_command_boom::PGN, 65072);
        assert_eq!(aux_valve_measured_boom::PGN, 65056);
        assert_eq!(joint_angles::PGN, 0xFF50);
        assert_eq!(controller_status::MESSAGE.default_id, 0x18FF_6227);
        assert_eq!(MESSAGES.len(), 23);
    }

    /// The `GenMsgCycleTime` of message `name`, ms, read from the DBC text itself (not through
    /// `build.rs`).
    fn dbc_cycle_time_ms(name: &str) -> u64 {
        let id = DBC_TEXT
            .lines()
            .find_map(|l| {
                let mut words = l.split_whitespace();
                (words.next() == Some("BO_"))
                    .then(|| (words.next(), words.next()))
                    .and_then(|(id, n)| (n == Some(&std::format!("{name}:")[..])).then_some(id))
                    .flatten()
            })
            .unwrap_or_else(|| panic!("no message {name} in the DBC"));
        let prefix = std::format!("BA_ \"GenMsgCycleTime\" BO_ {id} ");
        DBC_TEXT
            .lines()
            .find_map(|l| l.strip_prefix(&prefix[..]))
            .and_then(|rest| rest.trim_end_matches(';').trim().parse().ok())
            .unwrap_or_else(|| panic!("no GenMsgCycleTime for {name} ({id})"))
    }

    #[test]
    fn the_control_period_is_the_dbc_cycle_time_of_the_controllers_commands() {
        assert_eq!(CONTROL_PERIOD, core::time::Duration::from_millis(10));
        let period_ms = u64::try_from(CONTROL_PERIOD.as_millis()).unwrap();
        for name in [
            "AuxValveCommand_Boom",
            "AuxValveCommand_Stick",
            "AuxValveCommand_Bucket",
            "AuxValveCommand_Swing",
            "PositionSetpoint",
        ] {
            assert_eq!(dbc_cycle_time_ms(name), period_ms, "{name}");
        }
        // Every other periodic message of the controller goes out every so many steps.
        for m in MESSAGES.iter().filter(|m| m.transmitter == "Controller") {
            let ms = dbc_cycle_time_ms(m.name);
            assert_eq!(ms, u64::from(m.cycle_time_ms), "{}", m.name);
            assert_eq!(ms % period_ms, 0, "{}: {ms} ms", m.name);
        }
    }

    #[test]
    fn the_gateway_periods_are_the_dbc_cycle_times_of_its_messages() {
        let ms = |d: core::time::Duration| u64::try_from(d.as_millis()).unwrap();
        for (period, names) in [
            (
                SENSOR_PERIOD,
                &[
                    "JointAngles",
                    "JointRates",
                    "AuxValveMeasured_Boom",
                    "AuxValveMeasured_Stick",
                    "AuxValveMeasured_Bucket",
                ][..],
            ),
            (PUMP_PERIOD, &["PumpPressures"][..]),
            (ODOMETRY_PERIOD, &["TrackOdometry"][..]),
            (STATUS_PERIOD, &["GatewayStatus", "GatewaySession"][..]),
        ] {
            for name in names {
                assert_eq!(dbc_cycle_time_ms(name), ms(period), "{name}");
            }
        }
        // The project's gateway senses at the controller's rate (docs/protocol.md: 100 Hz).
        assert_eq!(SENSOR_PERIOD, CONTROL_PERIOD);
    }

    #[test]
    fn signed_fields_round_trip_at_odd_offsets() {
        let sig = position_setpoint::STICK_SETPOINT; // 13 bits starting at bit 13
        let mut data = [0xFFu8; 8];
        insert_raw(&sig, -3456, &mut data).unwrap();
        assert_eq!(extract_raw(&sig, &data), Some(-3456));
        // Neighbours untouched.
        assert_eq!(
            extract_raw(&position_setpoint::BOOM_SETPOINT, &data),
            Some(-1)
        );
    }

    #[test]
    fn decimal_factors_decode_correctly_rounded() {
        let coarse = aux_valve_command_boom::PORT_FLOW_COMMAND; // 0.4 %/bit
        let fine = aux_valve_command_boom::PORT_FLOW_COMMAND_FINE; // 0.0025 %/bit
        assert_eq!(raw_to_physical(&coarse, 3), 1.2);
        assert_eq!(raw_to_physical(&fine, 480), 1.2);
        for raw in 0..=250 {
            assert_eq!(
                raw_to_physical(&coarse, raw),
                raw_to_physical(&fine, raw * 160),
                "coarse raw {raw}"
            );
        }
        assert_eq!(raw_to_physical(&joint_angles::BOOM_ANGLE, 1234), 0.1234);
    }

    #[test]
    fn j1939_special_values_are_classified() {
        let flow = aux_valve_command_boom::PORT_FLOW_COMMAND;
        assert_eq!(
            classify_invalid(&flow, 0xFF),
            DecodeError::NotAvailable { signal: flow.name }
        );
        assert_eq!(
            classify_invalid(&flow, 0xFE),
            DecodeError::ErrorIndicator { signal: flow.name }
        );
        assert_eq!(
            classify_invalid(&flow, 0xFB),
            DecodeError::OutOfRange {
                signal: flow.name,
                raw: 0xFB
            }
        );
        let fine = aux_valve_command_boom::PORT_FLOW_COMMAND_FINE;
        assert_eq!(
            classify_invalid(&fine, 0xFF12),
            DecodeError::NotAvailable { signal: fine.name }
        );
        let state = aux_valve_command_boom::VALVE_STATE;
        assert_eq!(
            classify_invalid(&state, 0xF),
            DecodeError::NotAvailable { signal: state.name }
        );
        assert_eq!(
            classify_invalid(&state, 0xE),
            DecodeError::ErrorIndicator { signal: state.name }
        );
        let angle = joint_angles::BOOM_ANGLE;
        assert_eq!(
            classify_invalid(&angle, 0x7FFF),
            DecodeError::NotAvailable { signal: angle.name }
        );
    }

    #[test]
    fn encoding_rejects_instead_of_clamping() {
        let sig = joint_angles::BOOM_ANGLE;
        assert!(matches!(
            physical_to_raw(&sig, 3.2),
            Err(EncodeError::OutOfRange { .. })
        ));
        assert!(matches!(
            physical_to_raw(&sig, f64::NAN),
            Err(EncodeError::NotFinite { .. })
        ));
        assert_eq!(physical_to_raw(&sig, core::f64::consts::PI), Ok(31416));
    }
}
