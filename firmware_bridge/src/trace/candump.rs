//! The `candump` screen format (without `-L`): `  vcan0  123   [8]  01 02 03 04 05 06 07 08`, as
//! can-utils' `candump.c` and `lib.c` (`sprint_long_canframe`) print it, with or without a `-t`
//! timestamp in front.
//!
//! A line is `[(time)] iface [TX|RX flags flags] id [len] data...` where
//!
//! - `(time)` is `-ta` `(1700000000.123456)`, `-tz` / `-td` `(000.010000)` or `-tA`
//!   `(2023-11-14 22:13:20.123456)`; without `-t` there is none;
//! - the `TX - -` / `RX B E` column is `-x`'s (direction, CAN FD bit-rate switch and error state);
//! - `id` is 3 hex digits (11-bit) or 8 (29-bit, or an error frame with `CAN_ERR_FLAG`);
//! - `[len]` is one digit for classic CAN, two for CAN FD (`[12]`);
//! - the data are `len` hex bytes, or `remote request`; after them `-a`'s ASCII column (`'..3DU.'`)
//!   and the `ERRORFRAME` marker are allowed and ignored.
//!
//! `-tA` prints local time without a zone; it is read as UTC (the trace's times are then offset by
//! the recording machine's zone, which differences between frames do not see). `-td` gives the time
//! since the previous frame: [`super::TraceReader::with_delta_timestamps`] adds them up.

use super::{Direction, LineError, parse_frame, parse_timestamp};
use crate::frame::CanFrame;

/// The timestamp of a screen-format line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ScreenTime {
    /// No `-t`: the line carries no time.
    None,
    /// The time in the line, ns (absolute for `-ta` / `-tA`, from the first frame for `-tz`, from the
    /// previous frame for `-td`).
    Stamp(u64),
}

/// One screen-format line, parsed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ScreenLine {
    /// The time field.
    pub time: ScreenTime,
    /// Interface name.
    pub interface: String,
    /// The frame.
    pub frame: CanFrame,
    /// `-x`'s `TX` / `RX`, if present.
    pub direction: Option<Direction>,
}

/// True if `line` is in the screen format rather than `candump -L`'s: it has a `[len]` field.
pub fn is_screen_line(line: &str) -> bool {
    line.split_ascii_whitespace().any(|t| {
        t.strip_prefix('[')
            .and_then(|t| t.strip_suffix(']'))
            .is_some_and(|n| (1..=2).contains(&n.len()) && n.bytes().all(|b| b.is_ascii_digit()))
    })
}

/// Days from 1970-01-01 to the civil date `y-m-d` (proleptic Gregorian; H. Hinnant's algorithm).
fn days_from_civil(y: i64, m: u32, d: u32) -> i64 {
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let mp = (i64::from(m) + 9) % 12;
    let doy = (153 * mp + 2) / 5 + i64::from(d) - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

/// `-tA`'s `(YYYY-MM-DD` and `HH:MM:SS.ffffff)` as ns since the epoch, read as UTC.
fn parse_date_time(date: &str, time: &str) -> Result<u64, LineError> {
    let date = date.strip_prefix('(').ok_or(LineError::Timestamp)?;
    let time = time.strip_suffix(')').ok_or(LineError::Timestamp)?;
    let num = |s: &str, len: usize| -> Result<u32, LineError> {
        if s.len() == len && s.bytes().all(|b| b.is_ascii_digit()) {
            s.parse().map_err(|_| LineError::Timestamp)
        } else {
            Err(LineError::Timestamp)
        }
    };
    let mut d = date.split('-');
    let (Some(y), Some(mo), Some(da), None) = (d.next(), d.next(), d.next(), d.next()) else {
        return Err(LineError::Timestamp);
    };
    let (y, mo, da) = (num(y, 4)?, num(mo, 2)?, num(da, 2)?);
    let (hms, frac) = time.split_once('.').ok_or(LineError::Timestamp)?;
    let mut t = hms.split(':');
    let (Some(h), Some(mi), Some(s), None) = (t.next(), t.next(), t.next(), t.next()) else {
        return Err(LineError::Timestamp);
    };
    let (h, mi, s) = (num(h, 2)?, num(mi, 2)?, num(s, 2)?);
    if !(1..=12).contains(&mo) || !(1..=31).contains(&da) || h > 23 || mi > 59 || s > 60 {
        return Err(LineError::Timestamp);
    }
    let days = days_from_civil(i64::from(y), mo, da);
    let secs = days * 86_400 + i64::from(h * 3600 + mi * 60 + s);
    let secs = u64::try_from(secs).map_err(|_| LineError::Timestamp)?;
    // The fraction and the overflow checks are those of the `(seconds.fraction)` form.
    parse_timestamp(&format!("({secs}.{frac})"))
}

/// Parses one screen-format line (see the module docs).
///
/// # Errors
/// The [`LineError`] describing the problem.
pub fn parse_screen_line(line: &str) -> Result<ScreenLine, LineError> {
    let mut tokens = line.split_ascii_whitespace().peekable();
    let mut time = ScreenTime::None;
    if let Some(first) = tokens.peek().copied()
        && first.starts_with('(')
    {
        tokens.next();
        time = ScreenTime::Stamp(if first.ends_with(')') {
            parse_timestamp(first)?
        } else {
            parse_date_time(first, tokens.next().ok_or(LineError::Timestamp)?)?
        });
    }
    let interface = tokens.next().ok_or(LineError::Fields)?.to_string();
    let mut direction = None;
    if let Some(dir @ ("TX" | "RX")) = tokens.peek().copied() {
        tokens.next();
        direction = Some(if dir == "TX" {
            Direction::Transmit
        } else {
            Direction::Receive
        });
        for allowed in [["-", "B"], ["-", "E"]] {
            match tokens.next() {
                Some(flag) if allowed.contains(&flag) => {}
                _ => return Err(LineError::Fields),
            }
        }
    }
    let id = tokens.next().ok_or(LineError::Fields)?;
    let len_field = tokens.next().ok_or(LineError::Fields)?;
    let digits = len_field
        .strip_prefix('[')
        .and_then(|t| t.strip_suffix(']'))
        .filter(|n| (1..=2).contains(&n.len()))
        .ok_or(LineError::Length)?;
    let len: usize = digits.parse().map_err(|_| LineError::Length)?;
    let fd = digits.len() == 2;
    // The frame in `candump -L` form, so that one parser checks ids, lengths and kinds.
    let mut field = String::with_capacity(id.len() + 3 + 2 * len);
    field.push_str(id);
    field.push('#');
    if tokens.peek() == Some(&"remote") {
        tokens.next();
        if tokens.next() != Some("request") || fd || len > 9 {
            return Err(LineError::RemoteLength);
        }
        field.push('R');
        field.push_str(digits);
    } else {
        if fd {
            // The screen format shows no CAN FD flags without `-x`.
            field.push_str("#0");
        }
        for _ in 0..len {
            let byte = tokens.next().ok_or(LineError::Length)?;
            if byte.len() != 2 {
                return Err(LineError::Data);
            }
            field.push_str(byte);
        }
    }
    match tokens.next() {
        None => {}
        Some(t) if t == "ERRORFRAME" || t.starts_with('\'') => {}
        Some(_) => return Err(LineError::Fields),
    }
    Ok(ScreenLine {
        time,
        interface,
        frame: parse_frame(&field)?,
        direction,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::{CanId, FrameKind};

    /// Lines as can-utils' candump prints them (2023.03), one per option.
    const PLAIN: &str = "  vcan0  123   [8]  01 02 03 04 05 06 07 08";
    const EXTENDED: &str = "  vcan0  0CFE3027   [8]  7D FF 31 20 4E FF FF FF";
    const ABSOLUTE: &str = " (1700000000.123456)  vcan0  0CFE3027   [8]  7D FF 31 20 4E FF FF FF";
    const ZERO: &str = " (000.020000)  vcan0  123   [2]  01 02";
    const DATE: &str = " (2023-11-14 22:13:20.123456)  vcan0  123   [1]  AA";
    const EXTRA: &str = " (1.000000)  vcan0  TX - -  123   [1]  AA";
    const REMOTE: &str = "  vcan0  123   [5]  remote request";
    const ERROR: &str = "  vcan0  20000004   [8]  00 10 00 00 00 00 00 00   ERRORFRAME";
    const ASCII: &str = "  vcan0  123   [3]  41 42 43   'ABC'";
    const FD: &str = "  vcan0  123  [12]  00 11 22 33 44 55 66 77 88 99 AA BB";
    const EMPTY: &str = "  vcan0  7FF   [0] ";

    #[test]
    fn every_candump_screen_form_parses() {
        let p = parse_screen_line(PLAIN).unwrap();
        assert_eq!(p.time, ScreenTime::None);
        assert_eq!(p.interface, "vcan0");
        assert_eq!(p.frame.id(), CanId::Standard(0x123));
        assert_eq!(p.frame.data(), &[1, 2, 3, 4, 5, 6, 7, 8]);
        let e = parse_screen_line(EXTENDED).unwrap();
        assert_eq!(e.frame.id(), CanId::Extended(0x0CFE_3027));
        let a = parse_screen_line(ABSOLUTE).unwrap();
        assert_eq!(a.time, ScreenTime::Stamp(1_700_000_000_123_456_000));
        assert_eq!(a.frame, e.frame);
        assert_eq!(
            parse_screen_line(ZERO).unwrap().time,
            ScreenTime::Stamp(20_000_000)
        );
        // 2023-11-14 22:13:20 UTC is 1700000000 s after the epoch.
        assert_eq!(
            parse_screen_line(DATE).unwrap().time,
            ScreenTime::Stamp(1_700_000_000_123_456_000)
        );
        assert_eq!(
            parse_screen_line(EXTRA).unwrap().direction,
            Some(Direction::Transmit)
        );
        let r = parse_screen_line(REMOTE).unwrap().frame;
        assert!(r.is_remote() && r.dlc() == 5);
        let err = parse_screen_line(ERROR).unwrap().frame;
        assert!(err.is_error() && err.error_class() == 0x4);
        assert_eq!(parse_screen_line(ASCII).unwrap().frame.data(), b"ABC");
        let fd = parse_screen_line(FD).unwrap().frame;
        assert_eq!((fd.kind(), fd.len()), (FrameKind::Fd { flags: 0 }, 12));
        assert!(parse_screen_line(EMPTY).unwrap().frame.is_empty());
        for line in [PLAIN, ABSOLUTE, DATE, REMOTE, FD] {
            assert!(is_screen_line(line), "{line}");
        }
        assert!(!is_screen_line("(1.000000) vcan0 123#0102"));
    }

    #[test]
    fn bad_screen_lines_say_what_is_wrong() {
        for (line, kind) in [
            ("  vcan0  123   [8]  01 02", LineError::Length),
            ("  vcan0  123   [2]  01 0Z", LineError::Data),
            ("  vcan0  12   [1]  01", LineError::Id),
            ("  vcan0  123   [1]  01 junk", LineError::Fields),
            (
                " (2023-13-14 22:13:20.123456)  vcan0  123   [1]  AA",
                LineError::Timestamp,
            ),
            (" (1.0)  vcan0  123   [1]  AA", LineError::Timestamp),
            ("  vcan0  TX X -  123   [1]  AA", LineError::Fields),
            ("  vcan0  123   [9]  remote", LineError::RemoteLength),
        ] {
            assert_eq!(parse_screen_line(line), Err(kind), "{line}");
        }
    }

    #[test]
    fn civil_days_match_known_dates() {
        assert_eq!(days_from_civil(1970, 1, 1), 0);
        assert_eq!(days_from_civil(2000, 3, 1), 11_017);
        assert_eq!(days_from_civil(2023, 11, 14), 19_675);
    }
}
