//! `trace decode`: one line per frame with the message name and its signals.
//!
//! The format follows `cantools decode --single-line`: the candump line as read, `::`, then
//! `Message(Signal: value unit, ...)` with enum names from the DBC:
//!
//! ```text
//! (1700000000.123456) vcan0 0CFE3027#7DFF31204EFFFFFF T :: AuxValveCommand_Boom(PortFlowCommand: 50 %, ValveState: Extend, FailSafeMode: Block, PortFlowCommandFine: 50 %)
//! ```
//!
//! Every signal is shown as on the wire (`n/a`, `error`, `out of range (raw N)` for J1939 special and
//! invalid values); when [`Message::decode`] rejects the frame, its reason follows after `!!` (a bad
//! heartbeat checksum, a wrong DLC, a signal a receiver would refuse). Frames that are not project
//! messages say what they are (`unknown id`, `error frame: BusOff`, `remote frame`, ...).
//!
//! With `--profile FILE` (a machine profile, `docs/machine-profile.md`) the trace holds that
//! gateway's wire frames: each line shows the wire frame as read and decodes the project's message it
//! carries, in the project's units; a frame the profile does not map says so.

use std::fmt::Write as _;
use std::io::{self, BufRead, Write};

use anyhow::Context as _;
use firmware_bridge::dbc;
use firmware_bridge::frame::{CanFrame, CanId, FrameKind};
use firmware_bridge::profile::Profile;
use firmware_bridge::trace::{Direction, TraceRecord, format_frame};
use firmware_bridge::transport::BusFault;
use firmware_bridge::{J1939Id, Message};

use super::input::{self, ReadSummary};
use super::signals::{self, SignalValue};
use super::{InputArgs, format_timestamp};

/// `trace decode` arguments.
#[derive(Debug, Clone, clap::Args)]
pub struct DecodeArgs {
    /// The trace.
    #[command(flatten)]
    pub input: InputArgs,
    /// Only this message (DBC name like `JointAngles`, or a family like `AuxValveCommand`); repeatable.
    #[arg(long = "message", value_name = "NAME")]
    pub messages: Vec<String>,
    /// Only frames carrying this signal, and only this signal of them (`BoomAngle`, or
    /// `Message.Signal`); repeatable.
    #[arg(long = "signal", value_name = "NAME")]
    pub signals: Vec<String>,
    /// Only frames from this J1939 source address (`0x80` gateway, `0x27` controller).
    #[arg(long, value_name = "SA", value_parser = super::parse_source_address)]
    pub source_address: Option<u8>,
    /// Start of the time window, seconds after the first frame of the trace.
    #[arg(long, value_name = "S")]
    pub from: Option<f64>,
    /// End of the time window, seconds after the first frame of the trace.
    #[arg(long, value_name = "S")]
    pub to: Option<f64>,
    /// Flush after every line (the default when reading stdin, so `candump -L vcan0 | ... decode -`
    /// shows frames live).
    #[arg(long)]
    pub line_buffered: bool,
}

/// What [`Decoder`] shows.
#[derive(Debug, Clone, Default)]
pub struct DecodeFilter {
    /// Per DBC message: shown? Empty = all messages (and non-project frames).
    messages: Vec<bool>,
    /// Per DBC message: bit mask of the signals to show. Empty = all signals.
    signal_masks: Vec<u64>,
    source_address: Option<u8>,
    from_s: Option<f64>,
    to_s: Option<f64>,
}

impl DecodeFilter {
    /// A filter from names as given on the command line.
    ///
    /// # Errors
    /// Unknown message or signal names.
    pub fn new(
        messages: &[String],
        signal_names: &[String],
        source_address: Option<u8>,
        from_s: Option<f64>,
        to_s: Option<f64>,
    ) -> anyhow::Result<Self> {
        let n = dbc::MESSAGES.len();
        let mut filter = Self {
            source_address,
            from_s,
            to_s,
            ..Self::default()
        };
        if !messages.is_empty() {
            filter.messages = vec![false; n];
            for name in messages {
                for i in signals::resolve_messages(name).map_err(anyhow::Error::msg)? {
                    filter.messages[i] = true;
                }
            }
        }
        if !signal_names.is_empty() {
            filter.signal_masks = vec![0; n];
            for name in signal_names {
                // A bare name selects the signal in every message that has it (ValveState).
                let mut found = false;
                for s in signals::all_signals() {
                    let full_match = name
                        .split_once('.')
                        .map(|(m, sig)| {
                            s.message().name.eq_ignore_ascii_case(m)
                                && s.signal().name.eq_ignore_ascii_case(sig)
                        })
                        .unwrap_or_else(|| s.signal().name.eq_ignore_ascii_case(name));
                    if full_match && s.sig_index < 64 {
                        filter.signal_masks[s.msg_index] |= 1 << s.sig_index;
                        found = true;
                    }
                }
                if !found {
                    signals::resolve_signal(name).map_err(anyhow::Error::msg)?;
                }
            }
        }
        Ok(filter)
    }

    fn selects_only_messages(&self) -> bool {
        !self.messages.is_empty() || !self.signal_masks.is_empty()
    }

    fn message_selected(&self, msg_index: usize) -> bool {
        (self.messages.is_empty() || self.messages.get(msg_index).copied().unwrap_or(false))
            && (self.signal_masks.is_empty()
                || self.signal_masks.get(msg_index).copied().unwrap_or(0) != 0)
    }

    fn signal_selected(&self, msg_index: usize, sig_index: usize) -> bool {
        self.signal_masks.is_empty()
            || (sig_index < 64
                && self.signal_masks.get(msg_index).copied().unwrap_or(0) & (1 << sig_index) != 0)
    }
}

/// Turns records into decoded lines. Holds only the filter and the first timestamp.
#[derive(Debug, Clone)]
pub struct Decoder {
    filter: DecodeFilter,
    first_ns: Option<u64>,
    profile: Option<std::sync::Arc<Profile>>,
}

impl Decoder {
    /// A decoder with `filter`.
    pub fn new(filter: DecodeFilter) -> Self {
        Self {
            filter,
            first_ns: None,
            profile: None,
        }
    }

    /// Reads the frames as `profile`'s wire frames and decodes the project's messages they carry.
    #[must_use]
    pub fn with_profile(mut self, profile: std::sync::Arc<Profile>) -> Self {
        self.profile = Some(profile).filter(|p| !p.is_identity());
        self
    }

    /// Appends the decoded line for `rec` (without newline) to `out`; returns false (and appends
    /// nothing) when the filter drops the frame.
    pub fn format_record(&mut self, rec: &TraceRecord, out: &mut String) -> bool {
        let first = *self.first_ns.get_or_insert(rec.timestamp_ns);
        if self.filter.from_s.is_some() || self.filter.to_s.is_some() {
            let t = rec.timestamp_ns as f64 * 1e-9 - first as f64 * 1e-9;
            if self.filter.from_s.is_some_and(|from| t < from)
                || self.filter.to_s.is_some_and(|to| t > to)
            {
                return false;
            }
        }
        let wire = &rec.frame;
        let (translated, unmapped) = match self.profile.as_deref().map(|p| p.from_wire(wire)) {
            Some(Ok(canonical)) => (canonical, None),
            Some(Err(e)) => (*wire, Some(e)),
            None => (*wire, None),
        };
        let frame = &translated;
        let known = if unmapped.is_some() {
            None
        } else {
            signals::message_of(frame)
        };
        if let Some(sa) = self.filter.source_address {
            match frame.id() {
                CanId::Extended(id) if !frame.is_error() && (id & 0xFF) as u8 == sa => {}
                _ => return false,
            }
        }
        if self.filter.selects_only_messages() {
            match known {
                Some((i, _)) if self.filter.message_selected(i) => {}
                _ => return false,
            }
        }
        out.push('(');
        format_timestamp(rec.timestamp_ns, out);
        out.push_str(") ");
        out.push_str(&rec.interface);
        out.push(' ');
        push_frame(wire, out);
        match rec.direction {
            Some(Direction::Receive) => out.push_str(" R"),
            Some(Direction::Transmit) => out.push_str(" T"),
            None => {}
        }
        out.push_str(" :: ");
        match known {
            Some((msg_index, desc)) => {
                self.format_message(msg_index, desc, frame, out);
            }
            None => match (&unmapped, self.profile.as_deref()) {
                (Some(e), Some(p)) => {
                    let _ = write!(out, "not in profile {}: {e}", p.origin());
                }
                _ => describe_other(frame, out),
            },
        }
        true
    }

    fn format_message(
        &self,
        msg_index: usize,
        desc: &dbc::MessageDesc,
        frame: &CanFrame,
        out: &mut String,
    ) {
        out.push_str(desc.name);
        let data = frame.data();
        if data.len() == usize::from(desc.dlc) {
            out.push('(');
            let mut first = true;
            for (sig_index, sig) in desc.signals.iter().enumerate() {
                if !self.filter.signal_selected(msg_index, sig_index) {
                    continue;
                }
                if !first {
                    out.push_str(", ");
                }
                first = false;
                out.push_str(sig.name);
                out.push_str(": ");
                match dbc::decode_raw(sig, data) {
                    Ok(raw) => signal_formats()[msg_index][sig_index].push(sig, raw, out),
                    Err(_) => format_value(desc, sig, signals::decode_signal(sig, data), out),
                }
            }
            out.push(')');
        }
        if let Err(e) = Message::decode(frame) {
            // Writing to a String cannot fail.
            let _ = write!(out, " !! {e}");
        }
    }
}

/// Appends the candump frame field; data frames without `write!` per byte (the decode hot path).
fn push_frame(frame: &CanFrame, out: &mut String) {
    const HEX: &[u8; 16] = b"0123456789ABCDEF";
    let (FrameKind::Data, id) = (frame.kind(), frame.id()) else {
        format_frame(frame, out);
        return;
    };
    let (raw, digits) = match id {
        CanId::Standard(id) => (u32::from(id), 3),
        CanId::Extended(id) => (id, 8),
    };
    for i in (0..digits).rev() {
        out.push(char::from(HEX[((raw >> (4 * i)) & 0xF) as usize]));
    }
    out.push('#');
    for b in frame.data() {
        out.push(char::from(HEX[usize::from(b >> 4)]));
        out.push(char::from(HEX[usize::from(b & 0xF)]));
    }
}

/// Appends a value of signal `sig` of message `desc` with its unit or enum name (the message's own
/// value table: the two DM1 messages name the same signal's values differently).
pub fn format_value(
    desc: &dbc::MessageDesc,
    sig: &dbc::SignalDesc,
    value: SignalValue,
    out: &mut String,
) {
    let name = |raw: i64| signals::value_name_in(desc, sig.name, raw);
    format_value_inner(sig, &name, value, out);
}

/// How the in-range values of one signal print, worked out once per signal of the DBC (the decode
/// hot path): its value table, and its physical value as an exact decimal of the raw value.
#[derive(Debug, Clone, Copy)]
struct SignalFormat {
    table: Option<&'static [(i64, &'static str)]>,
    /// The factor as `numerator / 10^k` ([`dbc::decimal_factor`]).
    decimal: Option<(i64, i64)>,
    /// `(numerator, offset_scaled, decimals)`: the physical value is `(raw * numerator +
    /// offset_scaled) / 10^decimals` exactly, for factors and offsets of at most nine decimals.
    exact: Option<(i64, i64, u32)>,
}

/// Decimal digits below which a decimal is the shortest representation of the `f64` nearest to
/// it (what `{}` prints for that `f64`): 15 significant digits round-trip through `f64`.
const EXACT_LIMIT: i64 = 1_000_000_000_000_000;

fn signal_formats() -> &'static [Vec<SignalFormat>] {
    static FORMATS: std::sync::OnceLock<Vec<Vec<SignalFormat>>> = std::sync::OnceLock::new();
    FORMATS.get_or_init(|| {
        dbc::MESSAGES
            .iter()
            .enumerate()
            .map(|(m, desc)| {
                desc.signals
                    .iter()
                    .enumerate()
                    .map(|(i, sig)| SignalFormat {
                        table: signals::value_table(m, i),
                        decimal: dbc::decimal_factor(sig.factor),
                        exact: dbc::decimal_factor(sig.factor).and_then(|(num, den)| {
                            let off = sig.offset * den as f64;
                            let decimals = den.ilog10();
                            (off.round() == off && off.abs() < EXACT_LIMIT as f64)
                                .then_some((num, off as i64, decimals))
                        }),
                    })
                    .collect()
            })
            .collect()
    })
}

impl SignalFormat {
    /// Appends the in-range raw value `raw` of `sig` as [`format_value`] does: the enum name, or
    /// the physical value and the unit, printed from integers when that gives the same text as
    /// `{}` of the `f64` (module docs of [`dbc::raw_to_physical`]), with `{}` otherwise.
    fn push(&self, sig: &dbc::SignalDesc, raw: i64, out: &mut String) {
        if let Some(name) = self
            .table
            .and_then(|t| t.iter().find(|(v, _)| *v == raw).map(|(_, n)| *n))
        {
            out.push_str(name);
            return;
        }
        let value = dbc::raw_to_physical_with(sig, self.decimal, raw);
        let exact = self.exact.and_then(|(num, off, decimals)| {
            let scaled = raw.checked_mul(num)?.checked_add(off)?;
            let pow = 10_i64.pow(decimals);
            // The decimal is the f64's shortest text when it has at most 15 digits and the f64 is
            // the one nearest to it (one correctly rounded division of exact integers).
            (scaled.abs() < EXACT_LIMIT && scaled as f64 / pow as f64 == value)
                .then_some((scaled, pow, decimals))
        });
        match exact {
            Some((scaled, pow, decimals)) => push_decimal(scaled, pow, decimals, out),
            None => {
                let _ = write!(out, "{value}");
            }
        }
        if !sig.unit.is_empty() {
            out.push(' ');
            out.push_str(sig.unit);
        }
    }
}

/// Appends `scaled / pow` (`pow = 10^decimals`) as `{}` prints that decimal: no exponent, no
/// trailing zeros.
fn push_decimal(scaled: i64, pow: i64, decimals: u32, out: &mut String) {
    let mut buf = itoa::Buffer::new();
    if scaled < 0 {
        out.push('-');
    }
    let abs = scaled.unsigned_abs();
    let pow = pow.unsigned_abs();
    out.push_str(buf.format(abs / pow));
    let mut frac = abs % pow;
    if frac == 0 {
        return;
    }
    let mut digits = decimals;
    while frac.is_multiple_of(10) {
        frac /= 10;
        digits -= 1;
    }
    out.push('.');
    let text = buf.format(frac);
    for _ in text.len()..digits as usize {
        out.push('0');
    }
    out.push_str(text);
}

fn format_value_inner(
    sig: &dbc::SignalDesc,
    name_of: &dyn Fn(i64) -> Option<&'static str>,
    value: SignalValue,
    out: &mut String,
) {
    match value {
        SignalValue::Value(v) => {
            let raw = ((v - sig.offset) / sig.factor).round() as i64;
            if let Some(name) = name_of(raw) {
                out.push_str(name);
            } else {
                let _ = write!(out, "{v}");
                if !sig.unit.is_empty() {
                    out.push(' ');
                    out.push_str(sig.unit);
                }
            }
        }
        SignalValue::NotAvailable => out.push_str("n/a"),
        SignalValue::ErrorIndicator => out.push_str("error"),
        SignalValue::OutOfRange(raw) => {
            let _ = write!(out, "out of range (raw {raw})");
        }
    }
}

/// Describes a frame that is not a project message.
fn describe_other(frame: &CanFrame, out: &mut String) {
    match (frame.kind(), frame.id()) {
        (FrameKind::Error, _) => {
            let fault = BusFault::from_error_frame(frame);
            let _ = write!(
                out,
                "error frame: {} (class {:#010X})",
                fault.map_or_else(|| "?".to_string(), |f| format!("{f:?}")),
                frame.error_class()
            );
        }
        (FrameKind::Remote, _) => out.push_str("remote frame"),
        (FrameKind::Fd { .. }, _) => out.push_str("CAN FD frame (the protocol is classic CAN)"),
        (FrameKind::Data, CanId::Standard(_)) => out.push_str("11-bit id (not a J1939 frame)"),
        (FrameKind::Data, CanId::Extended(id)) => match J1939Id::from_raw(id) {
            Ok(j) => {
                let _ = write!(
                    out,
                    "unknown id (PGN {:#06X}, SA {:#04X})",
                    j.pgn(),
                    j.source_address()
                );
            }
            Err(_) => out.push_str("unknown id"),
        },
    }
}

/// Counts of a decode run.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct DecodeSummary {
    /// What the reader saw.
    pub read: ReadSummary,
    /// Lines written.
    pub lines_out: u64,
}

/// Decodes `input` into `out`, one line per selected frame; `line_flush` flushes after every line.
/// A closed output (`| head`) ends the run without error.
///
/// # Errors
/// As [`input::for_each_record`], and write errors other than a broken pipe.
pub fn decode_stream<R: BufRead>(
    input: R,
    filter: DecodeFilter,
    strict: bool,
    out: &mut dyn Write,
    diag: &mut dyn Write,
    line_flush: bool,
) -> anyhow::Result<DecodeSummary> {
    decode_stream_with(input, Decoder::new(filter), strict, out, diag, line_flush)
}

/// As [`decode_stream`] with a given decoder (a profile's, [`Decoder::with_profile`]).
///
/// # Errors
/// As [`decode_stream`].
pub fn decode_stream_with<R: BufRead>(
    input: R,
    decoder: Decoder,
    read: impl Into<input::ReadOptions>,
    out: &mut dyn Write,
    diag: &mut dyn Write,
    line_flush: bool,
) -> anyhow::Result<DecodeSummary> {
    let mut decoder = decoder;
    let mut line = String::with_capacity(256);
    let mut lines_out = 0u64;
    let mut pipe_closed = false;
    let read = input::for_each_record(input, read, diag, |rec| {
        line.clear();
        if !decoder.format_record(&rec, &mut line) {
            return Ok(true);
        }
        line.push('\n');
        let written = out
            .write_all(line.as_bytes())
            .and_then(|()| if line_flush { out.flush() } else { Ok(()) });
        match written {
            Ok(()) => {
                lines_out += 1;
                Ok(true)
            }
            Err(e) if e.kind() == io::ErrorKind::BrokenPipe => {
                pipe_closed = true;
                Ok(false)
            }
            Err(e) => Err(anyhow::Error::new(e).context("writing the decoded lines")),
        }
    })?;
    if !pipe_closed {
        match out.flush() {
            Err(e) if e.kind() != io::ErrorKind::BrokenPipe => {
                return Err(anyhow::Error::new(e).context("writing the decoded lines"));
            }
            _ => {}
        }
    }
    Ok(DecodeSummary { read, lines_out })
}

/// Runs `trace decode`.
///
/// # Errors
/// As [`decode_stream`], and bad filter names.
pub fn run(args: &DecodeArgs) -> anyhow::Result<()> {
    let filter = DecodeFilter::new(
        &args.messages,
        &args.signals,
        args.source_address,
        args.from,
        args.to,
    )?;
    let mut decoder = Decoder::new(filter);
    if let Some(profile) = input::load_profile(args.input.profile.as_deref())? {
        decoder = decoder.with_profile(profile);
    }
    let reader = input::open(&args.input.file)?;
    let line_flush = args.line_buffered || input::is_stdin(&args.input.file);
    let stdout = io::stdout();
    let mut out = io::BufWriter::with_capacity(64 * 1024, stdout.lock());
    let mut diag = io::stderr();
    decode_stream_with(
        reader,
        decoder,
        args.input.wire_options(),
        &mut out,
        &mut diag,
        line_flush,
    )
    .with_context(|| format!("decoding {}", args.input.file.display()))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use firmware_bridge::trace::parse_line;

    const BOOM_HALF: &str = "(1700000000.123456) vcan0 0CFE3027#7DFF31204EFFFFFF T";
    const HEARTBEAT_OK: &str = "(1700000000.200000) vcan0 0CFF6127#51FFFFFFFFFFFF16";
    const HEARTBEAT_BAD: &str = "(1700000000.250000) vcan0 0CFF6127#51FFFFFFFFFFFF17";

    fn line(filter: DecodeFilter, text: &str) -> Option<String> {
        let rec = parse_line(text).unwrap();
        let mut out = String::new();
        Decoder::new(filter)
            .format_record(&rec, &mut out)
            .then_some(out)
    }

    #[test]
    fn boom_command_decodes_like_cantools() {
        assert_eq!(
            line(DecodeFilter::default(), BOOM_HALF).unwrap(),
            "(1700000000.123456) vcan0 0CFE3027#7DFF31204EFFFFFF T :: AuxValveCommand_Boom(\
             PortFlowCommand: 50 %, FreshnessValue: 255, ValveState: Extend, FailSafeMode: Block, \
             PortFlowCommandFine: 50 %, Authenticator: 16777215)"
        );
    }

    #[test]
    fn frames_print_as_candump_does() {
        for text in [
            "(1.000000) can0 123#0102",
            "(1.000000) can0 7FF#",
            "(1.000000) can0 0CFE3027#7DFF31204EFFFFFF",
            "(1.000000) can0 123#R5",
            "(1.000000) can0 20000040#0000000000000000",
        ] {
            let rec = parse_line(text).unwrap();
            let mut fast = String::new();
            push_frame(&rec.frame, &mut fast);
            let mut reference = String::new();
            format_frame(&rec.frame, &mut reference);
            assert_eq!(fast, reference);
        }
    }

    #[test]
    fn bad_checksum_is_flagged() {
        assert!(
            !line(DecodeFilter::default(), HEARTBEAT_OK)
                .unwrap()
                .contains("!!")
        );
        let bad = line(DecodeFilter::default(), HEARTBEAT_BAD).unwrap();
        assert!(bad.contains("RequestedMode: ArmValve"), "{bad}");
        assert!(bad.contains("!! bad checksum"), "{bad}");
    }

    #[test]
    fn other_frames_say_what_they_are() {
        let err = line(
            DecodeFilter::default(),
            "(1.000000) can0 20000040#0000000000000000",
        )
        .unwrap();
        assert!(err.contains("error frame: BusOff"), "{err}");
        let unknown = line(DecodeFilter::default(), "(1.000000) can0 18FEF100#00").unwrap();
        assert!(
            unknown.contains("unknown id (PGN 0xFEF1, SA 0x00)"),
            "{unknown}"
        );
        let short = line(DecodeFilter::default(), "(1.000000) can0 0CFE3027#7D").unwrap();
        assert!(short.contains("1 data bytes, expected 8"), "{short}");
    }

    #[test]
    fn filters_select_messages_signals_and_sources() {
        let by_msg = DecodeFilter::new(&["JointAngles".into()], &[], None, None, None).unwrap();
        assert!(line(by_msg.clone(), BOOM_HALF).is_none());
        let by_family =
            DecodeFilter::new(&["AuxValveCommand".into()], &[], None, None, None).unwrap();
        assert!(line(by_family, BOOM_HALF).is_some());
        let by_sig = DecodeFilter::new(&[], &["ValveState".into()], None, None, None).unwrap();
        let shown = line(by_sig, BOOM_HALF).unwrap();
        assert!(
            shown.ends_with("AuxValveCommand_Boom(ValveState: Extend)"),
            "{shown}"
        );
        let gateway = DecodeFilter::new(&[], &[], Some(0x80), None, None).unwrap();
        assert!(line(gateway, BOOM_HALF).is_none());
        let controller = DecodeFilter::new(&[], &[], Some(0x27), None, None).unwrap();
        assert!(line(controller, BOOM_HALF).is_some());
        assert!(DecodeFilter::new(&["Nope".into()], &[], None, None, None).is_err());
        assert!(DecodeFilter::new(&[], &["Nope".into()], None, None, None).is_err());
    }

    /// The integer printing of the hot path gives the text `{}` gives, for every signal of the DBC
    /// over its whole raw range (sampled) and its ends.
    #[test]
    fn fast_value_text_is_the_display_text() {
        for (m, desc) in dbc::MESSAGES.iter().enumerate() {
            for (i, sig) in desc.signals.iter().enumerate() {
                let span = (sig.raw_max - sig.raw_min).max(1);
                let step = (span / 5000).max(1);
                let raws = (sig.raw_min..=sig.raw_max)
                    .step_by(usize::try_from(step).unwrap())
                    .chain([sig.raw_max, sig.raw_max - 1, sig.raw_min + 1]);
                for raw in raws.filter(|r| (sig.raw_min..=sig.raw_max).contains(r)) {
                    let mut fast = String::new();
                    signal_formats()[m][i].push(sig, raw, &mut fast);
                    let mut reference = String::new();
                    format_value(
                        desc,
                        sig,
                        SignalValue::Value(dbc::raw_to_physical(sig, raw)),
                        &mut reference,
                    );
                    assert_eq!(fast, reference, "{}.{} raw {raw}", desc.name, sig.name);
                }
            }
        }
        for (scaled, pow, decimals, text) in [
            (-5, 100, 2, "-0.05"),
            (1360, 100, 2, "13.6"),
            (8117, 100, 2, "81.17"),
            (7, 1, 0, "7"),
            (1_000_001, 1_000, 3, "1000.001"),
        ] {
            let mut out = String::new();
            push_decimal(scaled, pow, decimals, &mut out);
            assert_eq!(out, text);
        }
    }

    #[test]
    fn a_profile_decodes_the_wire_frames_as_the_project_messages() {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../examples/other_gateway.toml"
        );
        let profile = std::sync::Arc::new(Profile::load(std::path::Path::new(path)).unwrap());
        // The boom command of BOOM_HALF as the example gateway's ValveCmd (11-bit id 0x210).
        let canonical = parse_line(BOOM_HALF).unwrap().frame;
        let wire = profile.to_wire(&canonical).unwrap();
        let mut wire_line = String::from("(1700000000.123456) vcan0 ");
        push_frame(&wire, &mut wire_line);
        assert!(wire_line.ends_with("210#0FF17D4E20FFFFFF"), "{wire_line}");
        let text = format!("{wire_line} T\n(1700000000.200000) vcan0 7FF#00\n");
        let mut out = Vec::new();
        let decoder = Decoder::new(DecodeFilter::default()).with_profile(profile);
        decode_stream_with(
            text.as_bytes(),
            decoder,
            true,
            &mut out,
            &mut Vec::new(),
            false,
        )
        .unwrap();
        let out = String::from_utf8(out).unwrap();
        let lines: Vec<&str> = out.lines().collect();
        assert_eq!(
            lines[0],
            format!(
                "{wire_line} T :: AuxValveCommand_Boom(PortFlowCommand: 50 %, FreshnessValue: 255, ValveState: Extend, FailSafeMode: Block, PortFlowCommandFine: 50 %, Authenticator: 16777215)"
            )
        );
        assert!(
            lines[1]
                .ends_with(&(":: not in profile ".to_owned() + path + ": unmapped frame 0x7FF")),
            "{}",
            lines[1]
        );
    }

    #[test]
    fn time_window_is_relative_to_the_first_frame() {
        let text = format!("{BOOM_HALF}\n{HEARTBEAT_OK}\n{HEARTBEAT_BAD}\n");
        let filter = DecodeFilter::new(&[], &[], None, Some(0.05), Some(0.1)).unwrap();
        let mut out = Vec::new();
        let summary = decode_stream(
            text.as_bytes(),
            filter,
            false,
            &mut out,
            &mut io::sink(),
            false,
        )
        .unwrap();
        assert_eq!(summary.lines_out, 1);
        assert!(
            String::from_utf8(out)
                .unwrap()
                .starts_with("(1700000000.200000)")
        );
    }
}
