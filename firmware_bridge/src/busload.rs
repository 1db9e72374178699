//! Bit-exact frame lengths on the wire and the bus load of a message schedule.
//!
//! [`stuffed_bits`] builds the actual bit sequence of a classic CAN frame (SOF, arbitration, control,
//! data, the real CRC-15), counts the stuff bits the controller would insert (one complement bit after
//! five equal bits, from SOF through the CRC sequence) and adds the fixed 13-bit tail (CRC delimiter,
//! ACK slot and delimiter, 7-bit EOF, 3-bit interframe space). [`worst_case_bits`] is the textbook bound
//! `g + 8n + 13 + floor((g + 8n - 1) / 4)` with `g = 34` (11-bit id) or `54` (29-bit id).
//!
//! [`SCHEDULE`] is the project's message rate table (`docs/protocol.md`); a test asserts its
//! worst-case load at 500 kbit/s stays under 40 %.

use crate::dbc::{self, MessageDesc};
use crate::frame::{CanFrame, CanId, FrameKind};

/// The bus bit rate, bit/s.
pub const BITRATE: u32 = 500_000;

/// Bits after the CRC that are never stuffed: CRC delimiter, ACK slot, ACK delimiter, EOF, IFS.
pub const TAIL_BITS: u32 = 1 + 1 + 1 + 7 + 3;

fn push_bits(bits: &mut Vec<bool>, value: u32, count: u32) {
    for i in (0..count).rev() {
        bits.push((value >> i) & 1 == 1);
    }
}

/// The CAN CRC-15 (polynomial 0x4599, no initial value, no reflection, no final XOR), from the `crc`
/// crate's catalogue.
pub const CRC15_CAN: crc::Crc<u16> = crc::Crc::<u16>::new(&crc::CRC_15_CAN);

/// CAN CRC-15 ([`CRC15_CAN`]) over a bit sequence, first bit first.
///
/// A frame's bit count is rarely a multiple of eight. With a zero initial value leading zero bits
/// leave the register at zero, so the sequence is padded with zeros in front to whole bytes and the
/// bytes are fed most significant bit first.
pub fn crc15(bits: &[bool]) -> u16 {
    let pad = (8 - bits.len() % 8) % 8;
    let mut digest = CRC15_CAN.digest();
    let mut byte = 0u8;
    for (i, &bit) in core::iter::repeat_n(&false, pad).chain(bits).enumerate() {
        byte = (byte << 1) | u8::from(bit);
        if i % 8 == 7 {
            digest.update(&[byte]);
        }
    }
    digest.finalize()
}

/// Counts the stuff bits a transmitter inserts into `bits`.
pub fn count_stuff_bits(bits: &[bool]) -> u32 {
    let mut stuffed = 0;
    let mut last: Option<bool> = None;
    let mut run = 0;
    for &bit in bits {
        if Some(bit) == last {
            run += 1;
        } else {
            last = Some(bit);
            run = 1;
        }
        if run == 5 {
            stuffed += 1;
            // The stuff bit is the complement and starts a new run of length one.
            last = Some(!bit);
            run = 1;
        }
    }
    stuffed
}

/// The unstuffed bit sequence of a classic frame from SOF through the CRC sequence; `None` for error
/// and CAN FD frames.
pub fn frame_bits(frame: &CanFrame) -> Option<Vec<bool>> {
    let remote = match frame.kind() {
        FrameKind::Data => false,
        FrameKind::Remote => true,
        FrameKind::Error | FrameKind::Fd { .. } => return None,
    };
    let mut bits = Vec::with_capacity(160);
    bits.push(false); // SOF
    match frame.id() {
        CanId::Standard(id) => {
            push_bits(&mut bits, u32::from(id), 11);
            bits.push(remote); // RTR
            bits.push(false); // IDE
            bits.push(false); // r0
        }
        CanId::Extended(id) => {
            push_bits(&mut bits, id >> 18, 11);
            bits.push(true); // SRR
            bits.push(true); // IDE
            push_bits(&mut bits, id & 0x3_FFFF, 18);
            bits.push(remote); // RTR
            bits.push(false); // r1
            bits.push(false); // r0
        }
    }
    push_bits(&mut bits, frame.dlc() as u32, 4);
    for &byte in frame.data() {
        push_bits(&mut bits, u32::from(byte), 8);
    }
    let crc = crc15(&bits);
    push_bits(&mut bits, u32::from(crc), 15);
    Some(bits)
}

/// Exact length on the wire in bits, stuff bits and interframe space included; `None` for error and
/// CAN FD frames.
pub fn stuffed_bits(frame: &CanFrame) -> Option<u32> {
    let bits = frame_bits(frame)?;
    Some(bits.len() as u32 + count_stuff_bits(&bits) + TAIL_BITS)
}

/// Worst-case length in bits of a classic data frame with `len` data bytes.
pub const fn worst_case_bits(extended: bool, len: u32) -> u32 {
    let g = if extended { 54 } else { 34 };
    g + 8 * len + TAIL_BITS + (g + 8 * len - 1) / 4
}

/// One row of the message rate table.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScheduleEntry {
    /// DBC message name.
    pub message: &'static str,
    /// Frames per second.
    pub rate_hz: f64,
}

/// The project's message schedule: every periodic DBC message at the rate of its `GenMsgCycleTime`
/// attribute (`docs/protocol.md`: sensing and implement commands at 100 Hz, the rest slower). Position
/// setpoints are counted although they replace the implement valve commands in position mode, so the
/// figure is an upper bound. The event messages (cycle time 0: J1939-81 Address Claimed and Request)
/// are not in it: they go out at start, in a contest and on the operator's reset, a few frames each.
pub const SCHEDULE: &[ScheduleEntry] = &SCHEDULE_FROM_DBC;

/// How many DBC messages are periodic (`GenMsgCycleTime` > 0).
const PERIODIC_MESSAGES: usize = {
    let mut count = 0;
    let mut i = 0;
    while i < dbc::MESSAGES.len() {
        if dbc::MESSAGES[i].cycle_time_ms > 0 {
            count += 1;
        }
        i += 1;
    }
    count
};

const SCHEDULE_FROM_DBC: [ScheduleEntry; PERIODIC_MESSAGES] = {
    let mut out = [ScheduleEntry {
        message: "",
        rate_hz: 0.0,
    }; PERIODIC_MESSAGES];
    let mut i = 0;
    let mut n = 0;
    while i < dbc::MESSAGES.len() {
        let msg = &dbc::MESSAGES[i];
        if msg.cycle_time_ms > 0 {
            out[n] = ScheduleEntry {
                message: msg.name,
                rate_hz: 1000.0 / msg.cycle_time_ms as f64,
            };
            n += 1;
        }
        i += 1;
    }
    out
};

/// The DBC descriptor of a schedule row.
pub fn descriptor(entry: &ScheduleEntry) -> Option<&'static MessageDesc> {
    dbc::MESSAGES.iter().find(|m| m.name == entry.message)
}

/// Worst-case bus load (fraction of `bitrate`) of `schedule`, every frame at its worst-case stuffing.
/// Rows whose message is not in the DBC count as `None`.
pub fn worst_case_load(schedule: &[ScheduleEntry], bitrate: u32) -> Option<f64> {
    let mut bits_per_s = 0.0;
    for entry in schedule {
        let desc = descriptor(entry)?;
        bits_per_s += f64::from(worst_case_bits(true, u32::from(desc.dlc))) * entry.rate_hz;
    }
    Some(bits_per_s / f64::from(bitrate))
}

/// Bus load of frames sent at the given rates, with their exact stuffing.
/// Error and CAN FD frames give `None`.
pub fn exact_load(frames: &[(CanFrame, f64)], bitrate: u32) -> Option<f64> {
    let mut bits_per_s = 0.0;
    for (frame, rate_hz) in frames {
        bits_per_s += f64::from(stuffed_bits(frame)?) * rate_hz;
    }
    Some(bits_per_s / f64::from(bitrate))
}

/// Bus load measured over a sequence of timestamped frames (for example a trace): exact bits of the
/// classic frames divided by the bits the bus could carry between the first and last timestamp.
/// Error and CAN FD frames are not counted. `None` for fewer than two frames or a zero time span.
pub fn measured_load(
    frames: impl IntoIterator<Item = (u64, CanFrame)>,
    bitrate: u32,
) -> Option<f64> {
    let mut first: Option<u64> = None;
    let mut last = 0u64;
    let mut bits = 0u64;
    let mut count = 0u64;
    for (timestamp_ns, frame) in frames {
        first = Some(first.map_or(timestamp_ns, |f| f.min(timestamp_ns)));
        last = last.max(timestamp_ns);
        bits += u64::from(stuffed_bits(&frame).unwrap_or(0));
        count += 1;
    }
    let span_s = last.checked_sub(first?)? as f64 * 1e-9;
    if count < 2 || span_s <= 0.0 {
        return None;
    }
    // The last frame's bits fall after its start time; scale by the intervals seen, not the frames.
    let per_frame = bits as f64 / count as f64;
    Some(per_frame * (count - 1) as f64 / span_s / f64::from(bitrate))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn all_zero_standard_frame_has_six_stuff_bits() {
        // 34 zero bits from SOF through a zero CRC: a stuff bit after every fifth.
        let frame = CanFrame::new_standard(0, &[]).unwrap();
        let bits = frame_bits(&frame).unwrap();
        assert_eq!(bits.len(), 34);
        assert!(bits.iter().all(|b| !b));
        assert_eq!(count_stuff_bits(&bits), 6);
        assert_eq!(stuffed_bits(&frame), Some(34 + 6 + 13));
    }

    #[test]
    fn stuff_bits_restart_runs() {
        // 00000 -> stuff 1; then 1111 joins the stuff bit: 1+4 = 5 ones -> another stuff bit.
        let bits = [false, false, false, false, false, true, true, true, true];
        assert_eq!(count_stuff_bits(&bits), 2);
    }

    #[test]
    fn measured_load_of_a_steady_stream() {
        // 1000 identical frames at 1 kHz: load = bits * 1000 / 500k.
        let frame = CanFrame::new_extended(0x0CFF_5080, &[0x55; 8]).unwrap();
        let bits = f64::from(stuffed_bits(&frame).unwrap());
        let frames = (0..1000u64).map(|n| (n * 1_000_000, frame));
        let load = measured_load(frames, BITRATE).unwrap();
        assert!((load - bits * 1000.0 / 500_000.0).abs() < 1e-9, "{load}");
        assert_eq!(measured_load([(0, frame)], BITRATE), None);
    }

    #[test]
    fn worst_case_matches_the_textbook_values() {
        assert_eq!(worst_case_bits(false, 8), 135);
        assert_eq!(worst_case_bits(true, 8), 160);
    }

    #[test]
    fn exact_never_exceeds_worst_case() {
        for id in [0u32, 0x0CFE_3027, 0x1FFF_FFFF, 0x0CFF_5080] {
            for fill in [0x00u8, 0xFF, 0x55, 0xAA, 0x0F, 0xF0] {
                let f = CanFrame::new_extended(id, &[fill; 8]).unwrap();
                let n = stuffed_bits(&f).unwrap();
                assert!((131..=160).contains(&n), "{id:#x} {fill:#x}: {n}");
            }
        }
    }

    #[test]
    fn crc15_check_value() {
        // The catalogue's check value: CRC-15/CAN over the ASCII bytes "123456789", MSB first.
        let bits: Vec<bool> = b"123456789"
            .iter()
            .flat_map(|b| (0..8).rev().map(move |i| (b >> i) & 1 == 1))
            .collect();
        assert_eq!(crc15(&bits), 0x059E);
        assert_eq!(CRC15_CAN.checksum(b"123456789"), 0x059E);
        // One bit, not byte aligned: the register after shifting in a single 1 is the polynomial.
        assert_eq!(crc15(&[true]), 0x4599);
    }

    #[test]
    fn crc15_residue_of_a_frame_with_its_crc_is_zero() {
        // A CRC without init or final XOR leaves a zero remainder over message + CRC.
        for data in [&[0x01u8, 0x02][..], &[0xFF; 8][..], &[][..]] {
            let frame = CanFrame::new_standard(0x123, data).unwrap();
            let bits = frame_bits(&frame).unwrap();
            assert_eq!(crc15(&bits), 0);
            assert_ne!(crc15(&bits[..bits.len() - 15]), 0);
        }
    }
}
