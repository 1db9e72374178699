//! `candump -L` traces: line format, a streaming reader, a writer and the [`Recorder`].
//!
//! A line is `(<seconds>.<fraction>) <interface> <frame>[ R| T]`, where `<frame>` is, as can-utils
//! prints it:
//!
//! - `123#0102` (11-bit id, 3 hex digits) or `0CFE3027#0102...` (29-bit id, 8 hex digits),
//! - `123#R` / `123#R5` (remote frame, optional requested length),
//! - `20000040#0000000000000000` (error frame: [`crate::frame::CAN_ERR_FLAG`] in the 8-digit id),
//! - `123##1<data>` (CAN FD with its flags nibble).
//!
//! The writer produces exactly these lines with 6-digit fractions (microseconds, as `candump -L`);
//! the reader accepts 6- and 9-digit fractions, `.` separators between data bytes and the optional
//! ` R` (received) / ` T` (transmitted) marker of `candump -L -x`. Files written here are read by
//! can-utils (`canplayer`, `log2asc`), python-can and `cantools decode` (see the interop tests).

mod recorder;

pub use recorder::{Recorder, RecorderError, RecorderStats};

use std::fmt::Write as _;
use std::io::{self, BufRead, Write};

use crate::frame::{
    CAN_ERR_FLAG, CAN_ERR_MASK, CAN_MAX_LEN, CANFD_LENGTHS, CANFD_MAX_LEN, CanFrame, CanId,
    FrameKind,
};

/// Whether a node sent or received a frame (the ` T` / ` R` marker).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Direction {
    /// Received from the bus (` R`).
    Receive,
    /// Transmitted by this node (` T`).
    Transmit,
}

/// One line of a trace.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TraceRecord {
    /// Timestamp, nanoseconds (since the Unix epoch for wall-clock traces).
    pub timestamp_ns: u64,
    /// Interface name.
    pub interface: String,
    /// The frame.
    pub frame: CanFrame,
    /// Direction marker, if the line had one.
    pub direction: Option<Direction>,
}

/// What is wrong with a line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum LineError {
    /// Not valid UTF-8.
    #[error("not UTF-8 text")]
    NotUtf8,
    /// Not 3 or 4 space-separated fields.
    #[error("expected `(time) iface frame [R|T]`")]
    Fields,
    /// The `(seconds.fraction)` field is malformed or its fraction is not 6 or 9 digits.
    #[error("bad timestamp (expected (seconds.ffffff) or (seconds.fffffffff))")]
    Timestamp,
    /// No `#` in the frame field.
    #[error("frame has no '#'")]
    NoHash,
    /// The id is not 3 or 8 hex digits, or out of range.
    #[error("bad CAN id (3 hex digits for 11-bit, 8 for 29-bit)")]
    Id,
    /// Data is not hex byte pairs.
    #[error("bad data (hex byte pairs expected)")]
    Data,
    /// More data than the frame type allows, or an invalid CAN FD length.
    #[error("bad data length")]
    Length,
    /// The remote-frame length is not a digit 0-8.
    #[error("bad remote frame length")]
    RemoteLength,
    /// The CAN FD flags nibble is missing or not hex.
    #[error("bad CAN FD flags")]
    FdFlags,
    /// The fourth field is not `R` or `T`.
    #[error("bad direction marker (R or T expected)")]
    Marker,
}

/// Trace errors.
#[derive(Debug, thiserror::Error)]
pub enum TraceError {
    /// A malformed line.
    #[error("line {line}: {kind}")]
    Malformed {
        /// 1-based line number.
        line: u64,
        /// What is wrong.
        kind: LineError,
    },
    /// The last line has no newline and does not parse: the file was cut while being written.
    #[error("line {line}: truncated last line ({kind})")]
    Truncated {
        /// 1-based line number.
        line: u64,
        /// What is wrong.
        kind: LineError,
    },
    /// Reading failed.
    #[error("I/O error after line {line}: {source}")]
    Io {
        /// Lines read before the error.
        line: u64,
        /// The error.
        source: io::Error,
    },
}

/// Result alias for this module.
pub type Result<T> = std::result::Result<T, TraceError>;

fn hex_val(c: u8) -> Option<u8> {
    match c {
        b'0'..=b'9' => Some(c - b'0'),
        b'a'..=b'f' => Some(c - b'a' + 10),
        b'A'..=b'F' => Some(c - b'A' + 10),
        _ => None,
    }
}

fn parse_timestamp(field: &str) -> std::result::Result<u64, LineError> {
    let inner = field
        .strip_prefix('(')
        .and_then(|f| f.strip_suffix(')'))
        .ok_or(LineError::Timestamp)?;
    let (secs, frac) = inner.split_once('.').ok_or(LineError::Timestamp)?;
    if secs.is_empty() || !secs.bytes().all(|b| b.is_ascii_digit()) {
        return Err(LineError::Timestamp);
    }
    if !(frac.len() == 6 || frac.len() == 9) || !frac.bytes().all(|b| b.is_ascii_digit()) {
        return Err(LineError::Timestamp);
    }
    let secs: u64 = secs.parse().map_err(|_| LineError::Timestamp)?;
    let frac_val: u64 = frac.parse().map_err(|_| LineError::Timestamp)?;
    let frac_ns = if frac.len() == 6 {
        frac_val * 1000
    } else {
        frac_val
    };
    secs.checked_mul(1_000_000_000)
        .and_then(|ns| ns.checked_add(frac_ns))
        .ok_or(LineError::Timestamp)
}

/// Parses hex byte pairs, allowing a `.` between bytes, into `out`; returns the byte count.
fn parse_data(text: &str, out: &mut [u8; CANFD_MAX_LEN]) -> std::result::Result<usize, LineError> {
    let bytes = text.as_bytes();
    let mut n = 0;
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'.' {
            i += 1;
            continue;
        }
        let hi = hex_val(bytes[i]).ok_or(LineError::Data)?;
        let lo = bytes
            .get(i + 1)
            .copied()
            .and_then(hex_val)
            .ok_or(LineError::Data)?;
        if n >= CANFD_MAX_LEN {
            return Err(LineError::Length);
        }
        out[n] = (hi << 4) | lo;
        n += 1;
        i += 2;
    }
    Ok(n)
}

/// Parses the frame field (`id#data` and its variants).
///
/// # Errors
/// The [`LineError`] describing the problem.
pub fn parse_frame(field: &str) -> std::result::Result<CanFrame, LineError> {
    let (id_text, rest) = field.split_once('#').ok_or(LineError::NoHash)?;
    if !id_text.bytes().all(|b| hex_val(b).is_some()) {
        return Err(LineError::Id);
    }
    let id_val = u32::from_str_radix(id_text, 16).map_err(|_| LineError::Id)?;
    let mut data = [0u8; CANFD_MAX_LEN];
    let id = match id_text.len() {
        3 => CanId::standard(id_val as u16).map_err(|_| LineError::Id)?,
        8 if id_val & CAN_ERR_FLAG != 0 => {
            if id_val & !(CAN_ERR_FLAG | CAN_ERR_MASK) != 0 {
                return Err(LineError::Id);
            }
            let n = parse_data(rest, &mut data)?;
            if n > CAN_MAX_LEN {
                return Err(LineError::Length);
            }
            let mut details = [0u8; CAN_MAX_LEN];
            details.copy_from_slice(&data[..CAN_MAX_LEN]);
            return CanFrame::new_error(id_val & CAN_ERR_MASK, details).map_err(|_| LineError::Id);
        }
        8 => CanId::extended(id_val).map_err(|_| LineError::Id)?,
        _ => return Err(LineError::Id),
    };
    if let Some(fd) = rest.strip_prefix('#') {
        let flags = fd
            .bytes()
            .next()
            .and_then(hex_val)
            .ok_or(LineError::FdFlags)?;
        let n = parse_data(&fd[1..], &mut data)?;
        if !CANFD_LENGTHS.contains(&n) {
            return Err(LineError::Length);
        }
        return CanFrame::new_fd(id, &data[..n], flags).map_err(|_| LineError::Length);
    }
    if let Some(dlc) = rest.strip_prefix('R').or_else(|| rest.strip_prefix('r')) {
        let dlc = match dlc.as_bytes() {
            [] => 0,
            [d] if (b'0'..=b'8').contains(d) => d - b'0',
            _ => return Err(LineError::RemoteLength),
        };
        return CanFrame::new_remote(id, dlc).map_err(|_| LineError::RemoteLength);
    }
    let n = parse_data(rest, &mut data)?;
    if n > CAN_MAX_LEN {
        return Err(LineError::Length);
    }
    CanFrame::new_data(id, &data[..n]).map_err(|_| LineError::Length)
}

/// Parses one line (without its newline).
///
/// # Errors
/// The [`LineError`] describing the problem.
pub fn parse_line(line: &str) -> std::result::Result<TraceRecord, LineError> {
    let mut fields = line.split_ascii_whitespace();
    let (Some(ts), Some(iface), Some(frame)) = (fields.next(), fields.next(), fields.next()) else {
        return Err(LineError::Fields);
    };
    let direction = match fields.next() {
        None => None,
        Some("R") | Some("r") => Some(Direction::Receive),
        Some("T") | Some("t") => Some(Direction::Transmit),
        Some(_) => return Err(LineError::Marker),
    };
    if fields.next().is_some() {
        return Err(LineError::Fields);
    }
    Ok(TraceRecord {
        timestamp_ns: parse_timestamp(ts)?,
        interface: iface.to_string(),
        frame: parse_frame(frame)?,
        direction,
    })
}

/// Appends the frame field of `frame` in candump format to `out`.
pub fn format_frame(frame: &CanFrame, out: &mut String) {
    // Writing to a String cannot fail; the results are ignored for that reason.
    match (frame.kind(), frame.id()) {
        (FrameKind::Error, id) => {
            let _ = write!(out, "{:08X}#", id.raw() | CAN_ERR_FLAG);
        }
        (_, CanId::Standard(id)) => {
            let _ = write!(out, "{id:03X}#");
        }
        (_, CanId::Extended(id)) => {
            let _ = write!(out, "{id:08X}#");
        }
    }
    match frame.kind() {
        FrameKind::Remote => {
            out.push('R');
            if frame.dlc() > 0 {
                let _ = write!(out, "{}", frame.dlc());
            }
            return;
        }
        FrameKind::Fd { flags } => {
            let _ = write!(out, "#{:X}", flags & 0xF);
        }
        FrameKind::Data | FrameKind::Error => {}
    }
    for b in frame.data() {
        let _ = write!(out, "{b:02X}");
    }
}

/// Formats one `candump -L` line (without newline), with a 6-digit (microsecond) fraction.
pub fn format_line(
    timestamp_ns: u64,
    interface: &str,
    frame: &CanFrame,
    direction: Option<Direction>,
) -> String {
    let mut out = String::with_capacity(64 + 2 * frame.len());
    let _ = write!(
        out,
        "({}.{:06}) {} ",
        timestamp_ns / 1_000_000_000,
        (timestamp_ns % 1_000_000_000) / 1000,
        interface
    );
    format_frame(frame, &mut out);
    match direction {
        Some(Direction::Receive) => out.push_str(" R"),
        Some(Direction::Transmit) => out.push_str(" T"),
        None => {}
    }
    out
}

/// Writes `candump -L` lines.
#[derive(Debug)]
pub struct TraceWriter<W: Write> {
    out: W,
    interface: String,
    markers: bool,
}

impl<W: Write> TraceWriter<W> {
    /// A writer naming `interface` on every line; `markers` adds ` R`/` T`.
    pub fn new(out: W, interface: &str, markers: bool) -> Self {
        Self {
            out,
            interface: interface.to_string(),
            markers,
        }
    }

    /// Writes one line.
    ///
    /// # Errors
    /// I/O errors of the underlying writer.
    pub fn write(
        &mut self,
        timestamp_ns: u64,
        frame: &CanFrame,
        direction: Direction,
    ) -> io::Result<()> {
        let dir = if self.markers { Some(direction) } else { None };
        let line = format_line(timestamp_ns, &self.interface, frame, dir);
        self.out.write_all(line.as_bytes())?;
        self.out.write_all(b"\n")
    }

    /// Flushes the underlying writer.
    ///
    /// # Errors
    /// I/O errors of the underlying writer.
    pub fn flush(&mut self) -> io::Result<()> {
        self.out.flush()
    }

    /// The underlying writer.
    pub fn into_inner(self) -> W {
        self.out
    }
}

/// How a [`TraceReader`] treats malformed lines.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReadMode {
    /// Yield the error for the first malformed line, then stop.
    Stop,
    /// Skip malformed lines and count them ([`TraceReader::skipped`]). A truncated last line is
    /// still reported, as the final item.
    Skip,
    /// Yield every malformed line as an error with its line number and carry on after it (counted
    /// as in [`ReadMode::Skip`]). A truncated last line is reported, as the final item.
    Report,
}

/// A streaming reader over a `candump -L` log: an iterator of records, with memory independent of the
/// file's length. Empty lines are ignored.
#[derive(Debug)]
pub struct TraceReader<R: BufRead> {
    input: R,
    mode: ReadMode,
    line_no: u64,
    skipped: u64,
    buf: Vec<u8>,
    done: bool,
}

impl<R: BufRead> TraceReader<R> {
    /// A reader over `input`.
    pub fn new(input: R, mode: ReadMode) -> Self {
        Self {
            input,
            mode,
            line_no: 0,
            skipped: 0,
            buf: Vec::with_capacity(256),
            done: false,
        }
    }

    /// Malformed lines so far, a truncated last line included ([`ReadMode::Skip`], [`ReadMode::Report`]).
    pub fn skipped(&self) -> u64 {
        self.skipped
    }

    /// Lines read so far.
    pub fn lines_read(&self) -> u64 {
        self.line_no
    }
}

impl<R: BufRead> Iterator for TraceReader<R> {
    type Item = Result<TraceRecord>;

    fn next(&mut self) -> Option<Self::Item> {
        while !self.done {
            self.buf.clear();
            let n = match self.input.read_until(b'\n', &mut self.buf) {
                Ok(n) => n,
                Err(source) => {
                    self.done = true;
                    return Some(Err(TraceError::Io {
                        line: self.line_no,
                        source,
                    }));
                }
            };
            if n == 0 {
                self.done = true;
                return None;
            }
            self.line_no += 1;
            let complete = self.buf.last() == Some(&b'\n');
            let parsed = match std::str::from_utf8(&self.buf) {
                Ok(text) => {
                    let text = text.trim_end_matches(['\n', '\r']);
                    if text.trim().is_empty() {
                        continue;
                    }
                    parse_line(text)
                }
                Err(_) => Err(LineError::NotUtf8),
            };
            match parsed {
                Ok(rec) => return Some(Ok(rec)),
                Err(kind) if !complete => {
                    self.skipped += 1;
                    self.done = true;
                    return Some(Err(TraceError::Truncated {
                        line: self.line_no,
                        kind,
                    }));
                }
                Err(kind) => match self.mode {
                    ReadMode::Stop => {
                        self.done = true;
                        return Some(Err(TraceError::Malformed {
                            line: self.line_no,
                            kind,
                        }));
                    }
                    ReadMode::Skip => {
                        self.skipped += 1;
                        tracing::debug!(line = self.line_no, %kind, "skipping malformed trace line");
                    }
                    ReadMode::Report => {
                        self.skipped += 1;
                        return Some(Err(TraceError::Malformed {
                            line: self.line_no,
                            kind,
                        }));
                    }
                },
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const BOOM_LINE: &str = "(1700000000.123456) vcan0 0CFE3027#7DFF31204EFFFFFF";

    #[test]
    fn writer_produces_candump_lines() {
        let frame = CanFrame::new_extended(
            0x0CFE_3027,
            &[0x7D, 0xFF, 0x31, 0x20, 0x4E, 0xFF, 0xFF, 0xFF],
        )
        .unwrap();
        assert_eq!(
            format_line(1_700_000_000_123_456_789, "vcan0", &frame, None),
            BOOM_LINE
        );
        let rtr = CanFrame::new_remote(CanId::Standard(0x123), 5).unwrap();
        assert_eq!(
            format_line(0, "can0", &rtr, Some(Direction::Transmit)),
            "(0.000000) can0 123#R5 T"
        );
        let err = CanFrame::new_error(0x40, [0; 8]).unwrap();
        assert_eq!(
            format_line(0, "can0", &err, None),
            "(0.000000) can0 20000040#0000000000000000"
        );
        let fd = CanFrame::new_fd(CanId::Standard(0x12), &[0xAA; 12], 1).unwrap();
        assert_eq!(
            format_line(0, "can0", &fd, None),
            format!("(0.000000) can0 012##1{}", "AA".repeat(12))
        );
    }

    #[test]
    fn reader_accepts_every_documented_form() {
        let text = "\
(1700000000.123456) vcan0 0CFE3027#7DFF31204EFFFFFF
(1700000000.123456789) vcan0 123#0102 R
(1.000000) can0 123#R
(1.000000) can0 123#R5 T
(1.000000) can0 20000004#0010000000000000
(1.000000) can0 123##311.22.33.44.55.66.77.88.99.AA.BB.CC
(1.000000) can0 7FF#
";
        let recs: Vec<_> = TraceReader::new(text.as_bytes(), ReadMode::Stop)
            .collect::<Result<_>>()
            .unwrap();
        assert_eq!(recs.len(), 7);
        assert_eq!(recs[0].timestamp_ns, 1_700_000_000_123_456_000);
        assert_eq!(recs[1].timestamp_ns, 1_700_000_000_123_456_789);
        assert_eq!(recs[1].direction, Some(Direction::Receive));
        assert!(recs[2].frame.is_remote() && recs[2].frame.dlc() == 0);
        assert_eq!(recs[3].frame.dlc(), 5);
        assert!(recs[4].frame.is_error());
        assert_eq!(recs[4].frame.error_class(), 0x4);
        assert_eq!(recs[5].frame.kind(), FrameKind::Fd { flags: 3 });
        assert_eq!(recs[5].frame.len(), 12);
        assert!(recs[6].frame.is_empty());
        // Every line written back reads the same.
        for r in &recs {
            let line = format_line(r.timestamp_ns, &r.interface, &r.frame, r.direction);
            let again = parse_line(&line).unwrap();
            assert_eq!(again.frame, r.frame);
        }
    }

    #[test]
    fn malformed_lines_report_their_line_number() {
        let text = format!("{BOOM_LINE}\n(1.0) vcan0 123#00\n{BOOM_LINE}\n");
        let mut stop = TraceReader::new(text.as_bytes(), ReadMode::Stop);
        assert!(stop.next().unwrap().is_ok());
        let err = stop.next().unwrap().unwrap_err();
        assert!(
            matches!(
                err,
                TraceError::Malformed {
                    line: 2,
                    kind: LineError::Timestamp
                }
            ),
            "{err}"
        );
        assert!(stop.next().is_none());

        let mut skip = TraceReader::new(text.as_bytes(), ReadMode::Skip);
        assert_eq!(skip.by_ref().filter(|r| r.is_ok()).count(), 2);
        assert_eq!(skip.skipped(), 1);

        let report: Vec<_> = TraceReader::new(text.as_bytes(), ReadMode::Report).collect();
        assert_eq!(report.len(), 3);
        assert!(report[0].is_ok() && report[2].is_ok());
        assert!(matches!(
            report[1],
            Err(TraceError::Malformed {
                line: 2,
                kind: LineError::Timestamp
            })
        ));
    }

    #[test]
    fn rejects_bad_frames() {
        for (field, kind) in [
            ("12#00", LineError::Id),
            ("800#00", LineError::Id),
            ("40000000#00", LineError::Id),
            ("123#0", LineError::Data),
            ("123#010203040506070809", LineError::Length),
            ("123##1010203040506070809", LineError::Length),
            ("123#R9", LineError::RemoteLength),
            ("123##", LineError::FdFlags),
            ("123", LineError::NoHash),
        ] {
            assert_eq!(parse_frame(field), Err(kind), "{field}");
        }
        assert_eq!(
            parse_line("(1.000000) can0 123#00 X").unwrap_err(),
            LineError::Marker
        );
    }

    /// Produces `lines` copies of a line on demand, so the test never holds the whole text.
    struct Endless {
        line: &'static [u8],
        lines: u64,
        pos: usize,
    }

    impl io::Read for Endless {
        fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
            if self.lines == 0 {
                return Ok(0);
            }
            let n = buf.len().min(self.line.len() - self.pos);
            buf[..n].copy_from_slice(&self.line[self.pos..self.pos + n]);
            self.pos += n;
            if self.pos == self.line.len() {
                self.pos = 0;
                self.lines -= 1;
            }
            Ok(n)
        }
    }

    #[test]
    fn reader_streams_long_inputs() {
        const LINES: u64 = 50_000;
        let input = Endless {
            line: b"(1700000000.123456) vcan0 0CFE3027#7DFF31204EFFFFFF T\n",
            lines: LINES,
            pos: 0,
        };
        let mut reader = TraceReader::new(io::BufReader::new(input), ReadMode::Stop);
        let mut count = 0u64;
        for record in reader.by_ref() {
            record.unwrap();
            count += 1;
        }
        assert_eq!(count, LINES);
        assert_eq!(reader.lines_read(), LINES);
    }

    #[test]
    fn truncated_last_line_is_reported_after_the_good_lines() {
        let text = format!("{BOOM_LINE}\n{BOOM_LINE}\n(1700000000.1234");
        for mode in [ReadMode::Stop, ReadMode::Skip] {
            let items: Vec<_> = TraceReader::new(text.as_bytes(), mode).collect();
            assert_eq!(items.len(), 3);
            assert!(items[0].is_ok() && items[1].is_ok());
            assert!(matches!(
                items[2],
                Err(TraceError::Truncated { line: 3, .. })
            ));
        }
        // A complete last line without a newline is fine.
        let items: Vec<_> = TraceReader::new(BOOM_LINE.as_bytes(), ReadMode::Stop).collect();
        assert!(items.len() == 1 && items[0].is_ok());
    }
}
