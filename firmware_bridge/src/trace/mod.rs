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
//!
//! **CAN FD flags.** can-utils (`lib.c`: `sprint_canframe` prints `cf->flags & 0xF` as one hex digit,
//! `parse_canframe` reads one hex digit) carries the flags as a single nibble: `CANFD_BRS` 0x01,
//! `CANFD_ESI` 0x02, `CANFD_FDF` 0x04 and the spare 0x08. Every value 0x0-0xF round-trips exactly;
//! a frame with flag bits above 0x0F has no candump form, and the writer refuses it
//! ([`FormatError::FdFlags`]) instead of dropping the bits ([`Recorder`] counts such frames as
//! rejected).
//!
//! The reader also takes `candump`'s screen format (without `-L`, with or without a `-t` timestamp):
//! see [`parse_screen_line`]. A screen line without a timestamp gets time 0 and is counted
//! ([`TraceReader::untimed`]).
//!
//! **Bounded input.** The reader never holds more than [`MAX_LINE_BYTES`] of a line: a longer line
//! is malformed ([`LineError::TooLong`]), counted, and skipped up to the next newline without being
//! buffered, so a file without newlines (or `/dev/zero`) is read in constant memory.

mod candump;
mod recorder;

pub use candump::{ScreenLine, ScreenTime, is_screen_line, parse_screen_line};
pub use recorder::{MAX_QUEUE_CAPACITY, Recorder, RecorderError, RecorderStats};

use std::fmt::Write as _;
use std::io::{self, BufRead, Write};

use crate::frame::{
    CAN_ERR_FLAG, CAN_ERR_MASK, CAN_MAX_LEN, CANFD_LENGTHS, CANFD_MAX_LEN, CanFrame, CanId,
    FrameKind,
};

/// The longest line the reader accepts, bytes before the newline (a CR of a CRLF counts). The
/// longest line the writer
/// produces (a 64-byte CAN FD frame with `.` separators, a 9-digit fraction, a 15-byte interface
/// name and a marker) is under 250 bytes.
pub const MAX_LINE_BYTES: usize = 4096;

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
    #[error(
        "expected `(time) iface id#data [R|T]` (candump -L) or `[(time)] iface id [len] data` \
         (candump)"
    )]
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
    /// The line is longer than [`MAX_LINE_BYTES`]; the reader skips it without buffering it.
    #[error("line longer than {MAX_LINE_BYTES} bytes")]
    TooLong,
}

/// Why a frame or line cannot be written in the candump format.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum FormatError {
    /// CAN FD flag bits above the low nibble: candump carries the flags as one hex digit.
    #[error("CAN FD flags {flags:#04x} do not fit the candump flags digit (0x0-0xF)")]
    FdFlags {
        /// The frame's flags.
        flags: u8,
    },
    /// An interface name that is empty or contains whitespace would split the line's fields.
    #[error("interface name is empty or contains whitespace")]
    Interface,
}

/// Errors of [`TraceWriter::write`].
#[derive(Debug, thiserror::Error)]
pub enum WriteError {
    /// The frame (or the interface name) has no candump form; nothing was written.
    #[error("not written: {0}")]
    Unrepresentable(#[from] FormatError),
    /// The underlying writer failed.
    #[error("trace write: {0}")]
    Io(#[from] io::Error),
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

/// Checks that `frame` has a candump form (see the module docs on CAN FD flags).
///
/// # Errors
/// [`FormatError::FdFlags`] for CAN FD flag bits above 0x0F.
pub fn check_frame(frame: &CanFrame) -> std::result::Result<(), FormatError> {
    match frame.kind() {
        FrameKind::Fd { flags } if flags > 0x0F => Err(FormatError::FdFlags { flags }),
        _ => Ok(()),
    }
}

/// Appends the frame field of `frame` in candump format to `out`, or leaves `out` as it was if the
/// frame has no candump form.
///
/// # Errors
/// [`FormatError::FdFlags`] for CAN FD flag bits above 0x0F.
pub fn try_format_frame(
    frame: &CanFrame,
    out: &mut String,
) -> std::result::Result<(), FormatError> {
    check_frame(frame)?;
    format_frame(frame, out);
    Ok(())
}

/// Appends the frame field of `frame` in candump format to `out`.
///
/// For display. A CAN FD frame keeps only the low nibble of its flags here, as `candump` prints
/// it; writers of trace files use [`try_format_frame`] or [`TraceWriter`], which refuse such a
/// frame instead.
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
///
/// For display, like [`format_frame`]; [`try_format_line`] refuses what a trace file cannot carry.
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

/// Formats one `candump -L` line that [`parse_line`] reads back to the same frame, interface and
/// direction (and the timestamp to the microsecond).
///
/// # Errors
/// [`FormatError::FdFlags`] for CAN FD flag bits above 0x0F, [`FormatError::Interface`] for an
/// empty interface name or one with whitespace.
pub fn try_format_line(
    timestamp_ns: u64,
    interface: &str,
    frame: &CanFrame,
    direction: Option<Direction>,
) -> std::result::Result<String, FormatError> {
    check_frame(frame)?;
    if interface.is_empty() || interface.chars().any(char::is_whitespace) {
        return Err(FormatError::Interface);
    }
    Ok(format_line(timestamp_ns, interface, frame, direction))
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
    /// [`WriteError::Unrepresentable`] for a frame without a candump form (nothing is written; see
    /// [`try_format_line`]), [`WriteError::Io`] for errors of the underlying writer.
    pub fn write(
        &mut self,
        timestamp_ns: u64,
        frame: &CanFrame,
        direction: Direction,
    ) -> std::result::Result<(), WriteError> {
        let dir = if self.markers { Some(direction) } else { None };
        let line = try_format_line(timestamp_ns, &self.interface, frame, dir)?;
        self.out.write_all(line.as_bytes())?;
        self.out.write_all(b"\n")?;
        Ok(())
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
/// file's length and of its line lengths (at most [`MAX_LINE_BYTES`] of a line are held). Empty lines
/// are ignored.
///
/// Counters saturate at `u64::MAX`. In [`ReadMode::Skip`] the reader logs how many lines it skipped
/// when it reaches the end of the input.
#[derive(Debug)]
pub struct TraceReader<R: BufRead> {
    input: R,
    mode: ReadMode,
    line_no: u64,
    skipped: u64,
    too_long: u64,
    /// The current line without its newline; never longer than [`MAX_LINE_BYTES`].
    buf: Vec<u8>,
    /// An over-long line was reported and the rest of it, up to its newline, is still to be skipped.
    resync: bool,
    done: bool,
    /// Screen-format timestamps are `candump -td` deltas ([`Self::with_delta_timestamps`]).
    delta: bool,
    /// The running sum of the deltas, ns.
    delta_total_ns: u64,
    untimed: u64,
}

/// What [`TraceReader::read_line`] found.
enum LineRead {
    /// End of input before any byte.
    Eof,
    /// A line of at most [`MAX_LINE_BYTES`] in `buf`; `complete` if it ended in a newline.
    Line { complete: bool },
    /// A line longer than [`MAX_LINE_BYTES`]: `buf` is empty, the rest of the line is unread.
    TooLong,
}

impl<R: BufRead> TraceReader<R> {
    /// A reader over `input`.
    pub fn new(input: R, mode: ReadMode) -> Self {
        Self {
            input,
            mode,
            line_no: 0,
            skipped: 0,
            too_long: 0,
            buf: Vec::with_capacity(MAX_LINE_BYTES),
            resync: false,
            done: false,
            delta: false,
            delta_total_ns: 0,
            untimed: 0,
        }
    }

    /// Reads the timestamps of screen-format lines as `candump -td` prints them: the time since the
    /// previous frame, summed into times since the first (`candump -L` lines stay absolute).
    #[must_use]
    pub fn with_delta_timestamps(mut self, delta: bool) -> Self {
        self.delta = delta;
        self
    }

    /// Records read from screen-format lines without a timestamp (plain `candump`), given time 0.
    pub fn untimed(&self) -> u64 {
        self.untimed
    }

    /// The text of the line read last (lossy UTF-8), for naming a bad line in a message.
    pub fn current_line(&self) -> String {
        String::from_utf8_lossy(&self.buf)
            .trim_end_matches('\r')
            .to_string()
    }

    /// A line in either format.
    fn parse_text(&mut self, text: &str) -> std::result::Result<TraceRecord, LineError> {
        if !is_screen_line(text) {
            return parse_line(text);
        }
        let line = parse_screen_line(text)?;
        let timestamp_ns = match line.time {
            ScreenTime::None => {
                self.untimed = self.untimed.saturating_add(1);
                0
            }
            ScreenTime::Stamp(ns) if self.delta => {
                self.delta_total_ns = self.delta_total_ns.saturating_add(ns);
                self.delta_total_ns
            }
            ScreenTime::Stamp(ns) => ns,
        };
        Ok(TraceRecord {
            timestamp_ns,
            interface: line.interface,
            frame: line.frame,
            direction: line.direction,
        })
    }

    /// Malformed lines so far, over-long and truncated last lines included ([`ReadMode::Skip`],
    /// [`ReadMode::Report`]).
    pub fn skipped(&self) -> u64 {
        self.skipped
    }

    /// Lines longer than [`MAX_LINE_BYTES`] so far (also counted in [`Self::skipped`]).
    pub fn too_long(&self) -> u64 {
        self.too_long
    }

    /// Lines read so far.
    pub fn lines_read(&self) -> u64 {
        self.line_no
    }

    /// Capacity of the line buffer, bytes: [`MAX_LINE_BYTES`] whatever the input (for memory tests
    /// and diagnostics).
    pub fn line_buffer_capacity(&self) -> usize {
        self.buf.capacity()
    }

    /// Skips input up to and including the next newline without keeping it.
    fn skip_rest_of_line(&mut self) -> io::Result<()> {
        loop {
            let available = match self.input.fill_buf() {
                Ok(available) => available,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(e) => return Err(e),
            };
            if available.is_empty() {
                return Ok(());
            }
            match available.iter().position(|&b| b == b'\n') {
                Some(i) => {
                    self.input.consume(i + 1);
                    return Ok(());
                }
                None => {
                    let n = available.len();
                    self.input.consume(n);
                }
            }
        }
    }

    /// Reads the next line into `buf` (without its newline), keeping at most [`MAX_LINE_BYTES`].
    fn read_line(&mut self) -> io::Result<LineRead> {
        self.buf.clear();
        let mut any = false;
        loop {
            let available = match self.input.fill_buf() {
                Ok(available) => available,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(e) => return Err(e),
            };
            if available.is_empty() {
                return Ok(if any {
                    LineRead::Line { complete: false }
                } else {
                    LineRead::Eof
                });
            }
            any = true;
            let newline = available.iter().position(|&b| b == b'\n');
            let part = &available[..newline.unwrap_or(available.len())];
            if self.buf.len() + part.len() > MAX_LINE_BYTES {
                // Leave the rest unread: the caller reports the line and then skips it.
                self.buf.clear();
                return Ok(LineRead::TooLong);
            }
            self.buf.extend_from_slice(part);
            match newline {
                Some(i) => {
                    self.input.consume(i + 1);
                    return Ok(LineRead::Line { complete: true });
                }
                None => {
                    let n = part.len();
                    self.input.consume(n);
                }
            }
        }
    }

    fn io_error(&mut self, source: io::Error) -> Option<Result<TraceRecord>> {
        self.done = true;
        Some(Err(TraceError::Io {
            line: self.line_no,
            source,
        }))
    }

    fn finish(&mut self) -> Option<Result<TraceRecord>> {
        self.done = true;
        if self.mode == ReadMode::Skip && self.skipped > 0 {
            tracing::warn!(
                skipped = self.skipped,
                too_long = self.too_long,
                lines = self.line_no,
                "trace reader skipped malformed lines"
            );
        }
        None
    }

    /// A malformed line: stop, skip or report according to the mode.
    fn malformed(&mut self, kind: LineError) -> Option<Result<TraceRecord>> {
        let err = TraceError::Malformed {
            line: self.line_no,
            kind,
        };
        match self.mode {
            ReadMode::Stop => {
                self.done = true;
                Some(Err(err))
            }
            ReadMode::Skip => {
                self.skipped = self.skipped.saturating_add(1);
                tracing::debug!(line = self.line_no, %kind, "skipping malformed trace line");
                None
            }
            ReadMode::Report => {
                self.skipped = self.skipped.saturating_add(1);
                Some(Err(err))
            }
        }
    }
}

impl<R: BufRead> Iterator for TraceReader<R> {
    type Item = Result<TraceRecord>;

    fn next(&mut self) -> Option<Self::Item> {
        while !self.done {
            if self.resync {
                self.resync = false;
                if let Err(source) = self.skip_rest_of_line() {
                    return self.io_error(source);
                }
            }
            let complete = match self.read_line() {
                Ok(LineRead::Eof) => return self.finish(),
                Ok(LineRead::Line { complete }) => complete,
                Ok(LineRead::TooLong) => {
                    self.line_no = self.line_no.saturating_add(1);
                    self.too_long = self.too_long.saturating_add(1);
                    // Reported before the rest of the line is skipped, so a reader in Stop mode
                    // ends at once even on an endless line.
                    self.resync = true;
                    match self.malformed(LineError::TooLong) {
                        Some(item) => return Some(item),
                        None => continue,
                    }
                }
                Err(source) => return self.io_error(source),
            };
            self.line_no = self.line_no.saturating_add(1);
            let buf = std::mem::take(&mut self.buf);
            let parsed = match std::str::from_utf8(&buf) {
                Ok(text) => {
                    let text = text.trim_end_matches('\r');
                    if text.trim().is_empty() {
                        self.buf = buf;
                        continue;
                    }
                    self.parse_text(text)
                }
                Err(_) => Err(LineError::NotUtf8),
            };
            self.buf = buf;
            match parsed {
                Ok(rec) => return Some(Ok(rec)),
                Err(kind) if !complete => {
                    self.skipped = self.skipped.saturating_add(1);
                    self.done = true;
                    return Some(Err(TraceError::Truncated {
                        line: self.line_no,
                        kind,
                    }));
                }
                Err(kind) => {
                    if let Some(item) = self.malformed(kind) {
                        return Some(item);
                    }
                }
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

    /// Plain `candump vcan0` output was refused as "bad direction marker"; the screen format and
    /// its `-td` deltas read, mixed with `-L` lines.
    #[test]
    fn candump_screen_lines_and_their_deltas_read() {
        let text = "  vcan0  123   [1]  AA\n (000.000000)  vcan0  123   [1]  AA\n \
                    (000.010000)  vcan0  123   [1]  AA\n (000.005000)  vcan0  123   [1]  AA\n";
        let plain: Vec<_> = TraceReader::new(text.as_bytes(), ReadMode::Stop)
            .map(|r| r.unwrap().timestamp_ns)
            .collect();
        assert_eq!(plain, [0, 0, 10_000_000, 5_000_000]);
        let mut reader =
            TraceReader::new(text.as_bytes(), ReadMode::Stop).with_delta_timestamps(true);
        let delta: Vec<_> = reader.by_ref().map(|r| r.unwrap().timestamp_ns).collect();
        assert_eq!(delta, [0, 0, 10_000_000, 15_000_000]);
        assert_eq!(reader.untimed(), 1);
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

    /// Produces `len` bytes of `byte` on demand, never a newline unless `byte` is one, and counts
    /// what was read.
    struct Generated {
        byte: u8,
        len: u64,
        read: u64,
    }

    impl io::Read for Generated {
        fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
            let left = self.len - self.read;
            let n = buf.len().min(usize::try_from(left).unwrap_or(usize::MAX));
            buf[..n].fill(self.byte);
            self.read += n as u64;
            Ok(n)
        }
    }

    #[test]
    fn a_64_mib_line_is_one_malformed_line_read_in_bounded_memory() {
        const LEN: u64 = 64 << 20;
        let mut input = io::BufReader::new(Generated {
            byte: b'A',
            len: LEN,
            read: 0,
        });
        let mut reader = TraceReader::new(&mut input, ReadMode::Report);
        let mut items = Vec::new();
        while let Some(item) = reader.next() {
            assert!(reader.line_buffer_capacity() <= MAX_LINE_BYTES);
            items.push(item);
        }
        assert_eq!(items.len(), 1, "{items:?}");
        assert!(matches!(
            items[0],
            Err(TraceError::Malformed {
                line: 1,
                kind: LineError::TooLong
            })
        ));
        assert_eq!((reader.skipped(), reader.too_long()), (1, 1));
        assert_eq!(reader.lines_read(), 1);
        assert!(reader.line_buffer_capacity() <= MAX_LINE_BYTES);
        drop(reader);
        // The whole stream was consumed (skipped), not just the first 4 KiB.
        assert_eq!(input.get_ref().read, LEN);
    }

    #[test]
    fn zeros_like_dev_zero_do_not_allocate_beyond_the_line_limit() {
        // `/dev/zero` as a bounded stream: skipped as one malformed line.
        let input = io::BufReader::new(io::Read::take(io::repeat(0), 16 << 20));
        let mut reader = TraceReader::new(input, ReadMode::Skip);
        assert!(reader.next().is_none());
        assert_eq!(reader.skipped(), 1);
        assert!(reader.line_buffer_capacity() <= MAX_LINE_BYTES);
        // ... and endless: a reader that stops at the first bad line ends at once.
        let mut reader = TraceReader::new(io::BufReader::new(io::repeat(0)), ReadMode::Stop);
        assert!(matches!(
            reader.next(),
            Some(Err(TraceError::Malformed {
                line: 1,
                kind: LineError::TooLong
            }))
        ));
        assert!(reader.next().is_none());
        assert!(reader.line_buffer_capacity() <= MAX_LINE_BYTES);
    }

    #[test]
    fn reader_resynchronises_after_an_over_long_line() {
        let long = "(1.000000) vcan0 123#".to_owned() + &"0".repeat(2 * MAX_LINE_BYTES);
        let text = format!("{BOOM_LINE}\n{long}\n{BOOM_LINE}\n");
        // A small read buffer splits the lines across reads.
        let input = io::BufReader::with_capacity(7, text.as_bytes());
        let items: Vec<_> = TraceReader::new(input, ReadMode::Report).collect();
        assert_eq!(items.len(), 3, "{items:?}");
        assert!(items[0].is_ok() && items[2].is_ok());
        assert!(matches!(
            items[1],
            Err(TraceError::Malformed {
                line: 2,
                kind: LineError::TooLong
            })
        ));
        let mut skip = TraceReader::new(text.as_bytes(), ReadMode::Skip);
        assert_eq!(skip.by_ref().filter(Result::is_ok).count(), 2);
        assert_eq!(
            (skip.skipped(), skip.too_long(), skip.lines_read()),
            (1, 1, 3)
        );
    }

    #[test]
    fn line_limit_is_exact() {
        // A line of MAX_LINE_BYTES before its newline (a CR counts) is read and judged on its
        // content; one byte more is too long.
        let at_limit = "x".repeat(MAX_LINE_BYTES) + "\n";
        let crlf_at_limit = "x".repeat(MAX_LINE_BYTES - 1) + "\r\n";
        let over = "x".repeat(MAX_LINE_BYTES + 1) + "\n";
        let crlf_over = "x".repeat(MAX_LINE_BYTES) + "\r\n";
        for (text, kind) in [
            (at_limit, LineError::Fields),
            (crlf_at_limit, LineError::Fields),
            (over, LineError::TooLong),
            (crlf_over, LineError::TooLong),
        ] {
            let input = io::BufReader::with_capacity(100, text.as_bytes());
            let items: Vec<_> = TraceReader::new(input, ReadMode::Stop).collect();
            assert!(
                matches!(items[..], [Err(TraceError::Malformed { line: 1, kind: k })] if k == kind),
                "{items:?}"
            );
        }
    }

    #[test]
    fn fd_flags_round_trip_for_every_nibble_and_wider_flags_are_refused() {
        for flags in 0..=0x0F_u8 {
            let fd = CanFrame::new_fd(CanId::Extended(0x0CFF_5080), &[0x5A; 48], flags).unwrap();
            let line = try_format_line(7_000, "can0", &fd, Some(Direction::Receive)).unwrap();
            assert_eq!(parse_line(&line).unwrap().frame, fd, "{line}");
        }
        for flags in [0x10_u8, 0x14, 0x80, 0xFF] {
            let fd = CanFrame::new_fd(CanId::Standard(0x12), &[1, 2], flags).unwrap();
            assert_eq!(check_frame(&fd), Err(FormatError::FdFlags { flags }));
            let mut out = String::new();
            assert!(try_format_frame(&fd, &mut out).is_err());
            assert!(out.is_empty());
            let mut writer = TraceWriter::new(Vec::new(), "can0", false);
            assert!(matches!(
                writer.write(0, &fd, Direction::Transmit),
                Err(WriteError::Unrepresentable(FormatError::FdFlags { .. }))
            ));
            assert!(writer.into_inner().is_empty());
        }
        let data = CanFrame::new_standard(0x12, &[1]).unwrap();
        assert_eq!(
            try_format_line(0, "can 0", &data, None),
            Err(FormatError::Interface)
        );
        assert_eq!(
            try_format_line(0, "", &data, None),
            Err(FormatError::Interface)
        );
    }
}
