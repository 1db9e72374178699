//! Reading traces: a file or stdin, streamed record by record, malformed lines reported by number.
//!
//! [`Records`] is [`firmware_bridge::trace::TraceReader`] in `ReadMode::Report`: empty lines are
//! ignored, every malformed line is an error naming its line and the stream carries on, a last line
//! without a newline that does not parse is [`TraceError::Truncated`] and ends the stream (the file
//! was cut while being written), an I/O error ends the stream.
//!
//! [`ReadOptions`] say how to read: `--strict`, `candump -td` deltas, and a machine profile whose wire
//! frames are translated to the project's messages before a command sees them (frames the profile does
//! not map are left out and counted; error frames pass unchanged). A trace from which not one frame
//! was read is an error naming the first bad line.

use std::fs::File;
use std::io::{self, BufRead, BufReader, Write};
use std::path::Path;

use std::sync::Arc;

use anyhow::Context as _;
use firmware_bridge::profile::Profile;
use firmware_bridge::trace::{LineError, ReadMode, TraceError, TraceReader, TraceRecord};

/// Read buffer size: large enough that the kernel read calls do not dominate decoding.
const READ_BUFFER_BYTES: usize = 256 * 1024;

/// How many malformed lines are printed individually before only counting them.
pub const MAX_REPORTED_LINES: u64 = 20;

/// Opens `path` for reading, or stdin for `-`.
///
/// # Errors
/// The file cannot be opened.
pub fn open(path: &Path) -> anyhow::Result<Box<dyn BufRead + Send>> {
    if path.as_os_str() == "-" {
        return Ok(Box::new(BufReader::with_capacity(
            READ_BUFFER_BYTES,
            io::stdin(),
        )));
    }
    let file = File::open(path).with_context(|| format!("cannot open {}", path.display()))?;
    Ok(Box::new(BufReader::with_capacity(READ_BUFFER_BYTES, file)))
}

/// The records of `path` through `reader`, ending at a truncated last line (the recording was cut:
/// logger stopped, power lost, a killed `demo`) with a warning naming the line, so what precedes the
/// cut is used instead of the whole file being lost. Other errors pass through.
pub fn records_until_cut<R: BufRead>(
    path: &Path,
    reader: TraceReader<R>,
) -> impl Iterator<Item = Result<TraceRecord, TraceError>> {
    let path = path.to_owned();
    reader.map_while(move |record| match record {
        Err(TraceError::Truncated { line, kind }) => {
            tracing::warn!(
                "{}: the trace ends in a truncated line {line} ({kind}): the recording was cut; \
                 using what precedes it",
                path.display()
            );
            None
        }
        other => Some(other),
    })
}

/// True when `path` means stdin.
pub fn is_stdin(path: &Path) -> bool {
    path.as_os_str() == "-"
}

/// How a trace is read.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ReadOptions {
    /// Stop at the first malformed line.
    pub strict: bool,
    /// Screen-format timestamps are `candump -td` deltas.
    pub delta_timestamps: bool,
    /// The machine profile whose wire frames the trace holds: records carry the project's (canonical)
    /// frames they translate to, and frames it does not map are left out (counted).
    pub profile: Option<Arc<Profile>>,
}

impl From<bool> for ReadOptions {
    /// Only `strict`.
    fn from(strict: bool) -> Self {
        Self {
            strict,
            ..Self::default()
        }
    }
}

/// Loads the profile at `path` for reading traces: `None` for no path or a profile that is the
/// project's protocol bit for bit.
///
/// # Errors
/// The profile cannot be loaded (its error names the file, line and field).
pub fn load_profile(path: Option<&Path>) -> anyhow::Result<Option<Arc<Profile>>> {
    let Some(path) = path else {
        return Ok(None);
    };
    let profile = Profile::load(path).map_err(anyhow::Error::new)?;
    Ok(Some(Arc::new(profile)).filter(|p| !p.is_identity()))
}

/// The first bad line of a trace, for the message when no frame was read.
#[derive(Debug, Clone, PartialEq, Eq)]
struct FirstBad {
    line: u64,
    text: String,
    kind: LineError,
}

/// A streaming iterator over the records of a `candump -L` log (or `candump` screen output) that
/// yields every malformed line as an error with its line number and continues after it (a truncated
/// last line and I/O errors end the stream). Memory is one line buffer.
#[derive(Debug)]
pub struct Records<R: BufRead> {
    reader: TraceReader<R>,
    profile: Option<Arc<Profile>>,
    not_in_profile: u64,
    first_bad: Option<FirstBad>,
}

impl<R: BufRead> Records<R> {
    /// Records of `input`.
    pub fn new(input: R) -> Self {
        Self::with_options(input, &ReadOptions::default())
    }

    /// Records of `input` read with `options` (its `strict` is the caller's to apply).
    pub fn with_options(input: R, options: &ReadOptions) -> Self {
        Self {
            reader: TraceReader::new(input, ReadMode::Report)
                .with_delta_timestamps(options.delta_timestamps),
            profile: options.profile.clone(),
            not_in_profile: 0,
            first_bad: None,
        }
    }

    /// Frames left out because the profile does not map them.
    pub fn not_in_profile(&self) -> u64 {
        self.not_in_profile
    }

    /// Records without a timestamp (plain `candump` output), given time 0.
    pub fn untimed(&self) -> u64 {
        self.reader.untimed()
    }

    /// The error for a trace of which no record was read, naming the first bad line (or saying the
    /// input was empty); `None` once a record was read.
    pub fn nothing_read(&self, records: u64) -> Option<anyhow::Error> {
        if records > 0 {
            return None;
        }
        let lines = self.reader.lines_read();
        Some(match (&self.first_bad, self.not_in_profile) {
            (_, n) if n > 0 => anyhow::anyhow!(
                "no frame of the profile in {lines} line(s): all {n} frame(s) are unmapped (is \
                 --profile the one the trace was recorded with?)"
            ),
            (Some(bad), _) => anyhow::anyhow!(
                "no CAN frame in {lines} line(s): line {} `{}`: {}",
                bad.line,
                bad.text,
                bad.kind
            ),
            (None, _) => anyhow::anyhow!("no CAN frame: the trace is empty"),
        })
    }

    /// Warns on `diag` about frames without timestamps and frames the profile does not map.
    pub fn warn_at_end(&self, diag: &mut dyn Write) {
        if self.untimed() > 0 {
            let _ = writeln!(
                diag,
                "warning: {} frame(s) without a timestamp (candump without -t) are at time 0: \
                 rates, gaps and timing need `candump -L` or `candump -ta`",
                self.untimed()
            );
        }
        if let Some(p) = &self.profile
            && self.not_in_profile > 0
        {
            let _ = writeln!(
                diag,
                "warning: {} frame(s) not in profile {} left out",
                self.not_in_profile,
                p.origin()
            );
        }
    }

    /// Lines read so far (including empty and malformed ones).
    pub fn lines_read(&self) -> u64 {
        self.reader.lines_read()
    }

    /// Malformed (including truncated) lines seen so far.
    pub fn malformed(&self) -> u64 {
        self.reader.skipped()
    }
}

impl<R: BufRead> Iterator for Records<R> {
    type Item = Result<TraceRecord, TraceError>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            let item = self.reader.next()?;
            let mut rec = match item {
                Ok(rec) => rec,
                Err(
                    TraceError::Malformed { line, kind } | TraceError::Truncated { line, kind },
                ) => {
                    if self.first_bad.is_none() {
                        let mut text = self.reader.current_line();
                        if text.len() > 80 {
                            let cut = (0..=80).rev().find(|&i| text.is_char_boundary(i));
                            text.truncate(cut.unwrap_or(0));
                            text.push_str("...");
                        }
                        self.first_bad = Some(FirstBad { line, text, kind });
                    }
                    return Some(item);
                }
                Err(e) => return Some(Err(e)),
            };
            let Some(profile) = &self.profile else {
                return Some(Ok(rec));
            };
            if rec.frame.is_error() {
                return Some(Ok(rec));
            }
            match profile.from_wire(&rec.frame) {
                Ok(canonical) => {
                    rec.frame = canonical;
                    return Some(Ok(rec));
                }
                Err(_) => self.not_in_profile += 1,
            }
        }
    }
}

/// Counts of what could not be read, for the end-of-run summary.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ReadSummary {
    /// Lines read.
    pub lines: u64,
    /// Records parsed.
    pub records: u64,
    /// Malformed lines skipped (not counting a truncated last line).
    pub malformed: u64,
    /// Line numbers of the first malformed lines (at most [`MAX_REPORTED_LINES`]).
    pub malformed_lines: Vec<u64>,
    /// The line number of a truncated last line, if the file was cut.
    pub truncated_at: Option<u64>,
}

/// Streams the records of `input`, read with `options` (`strict`, or [`ReadOptions`]), into
/// `on_record`.
///
/// Malformed lines are reported on `diag` (the first [`MAX_REPORTED_LINES`] individually, by line
/// number) and skipped, or with `strict` returned as the error. A truncated last line is reported and
/// ends the stream: an error with `strict`, otherwise the records before it were already delivered.
/// `on_record` returns `Ok(false)` to stop early.
///
/// # Errors
/// I/O errors, a malformed or truncated line with `strict`, a trace of which no frame was read
/// ([`Records::nothing_read`]), and errors of `on_record`.
pub fn for_each_record<R: BufRead>(
    input: R,
    options: impl Into<ReadOptions>,
    diag: &mut dyn Write,
    mut on_record: impl FnMut(TraceRecord) -> anyhow::Result<bool>,
) -> anyhow::Result<ReadSummary> {
    let options = options.into();
    let strict = options.strict;
    let mut records = Records::with_options(input, &options);
    let mut summary = ReadSummary::default();
    for item in records.by_ref() {
        match item {
            Ok(rec) => {
                summary.records += 1;
                if !on_record(rec)? {
                    break;
                }
            }
            Err(TraceError::Malformed { line, kind }) => {
                if strict {
                    return Err(anyhow::anyhow!("line {line}: malformed: {kind}"));
                }
                summary.malformed += 1;
                if summary.malformed <= MAX_REPORTED_LINES {
                    summary.malformed_lines.push(line);
                    // Diagnostics are best effort: a closed stderr must not stop the decoding.
                    let _ = writeln!(diag, "warning: line {line}: {kind} (skipped)");
                } else if summary.malformed == MAX_REPORTED_LINES + 1 {
                    let _ = writeln!(
                        diag,
                        "warning: more malformed lines; reporting only the count from here"
                    );
                }
            }
            Err(TraceError::Truncated { line, kind }) => {
                summary.truncated_at = Some(line);
                if strict {
                    return Err(anyhow::anyhow!(
                        "line {line}: truncated last line ({kind}); the file was cut"
                    ));
                }
                let _ = writeln!(
                    diag,
                    "warning: line {line}: truncated last line ({kind}); read up to the damage"
                );
            }
            Err(e @ TraceError::Io { .. }) => {
                return Err(anyhow::Error::new(e).context("reading the trace"));
            }
        }
    }
    summary.lines = records.lines_read();
    if let Some(e) = records.nothing_read(summary.records) {
        return Err(e);
    }
    records.warn_at_end(diag);
    if summary.malformed > 0 {
        let _ = writeln!(
            diag,
            "warning: {} malformed line(s) skipped of {}",
            summary.malformed, summary.lines
        );
    }
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = "(1700000000.123456) vcan0 0CFE3027#7DFF31204EFFFFFF";

    #[test]
    fn every_malformed_line_is_named_and_skipped() {
        let text = format!("{GOOD}\ngarbage\n\n{GOOD}\n(1.0) vcan0 123#00\n{GOOD}\n");
        let mut diag = Vec::new();
        let mut n = 0;
        let summary = for_each_record(text.as_bytes(), false, &mut diag, |_| {
            n += 1;
            Ok(true)
        })
        .unwrap();
        assert_eq!(n, 3);
        assert_eq!(summary.malformed_lines, vec![2, 5]);
        let diag = String::from_utf8(diag).unwrap();
        assert!(
            diag.contains("line 2:") && diag.contains("line 5:"),
            "{diag}"
        );
    }

    #[test]
    fn strict_mode_fails_at_the_first_bad_line() {
        let text = format!("{GOOD}\ngarbage\n{GOOD}\n");
        let err = for_each_record(text.as_bytes(), true, &mut io::sink(), |_| Ok(true))
            .unwrap_err()
            .to_string();
        assert!(err.contains("line 2"), "{err}");
    }

    #[test]
    fn truncated_file_is_read_up_to_the_damage() {
        let text = format!("{GOOD}\n{GOOD}\n(1700000000.12");
        let mut n = 0;
        let summary = for_each_record(text.as_bytes(), false, &mut io::sink(), |_| {
            n += 1;
            Ok(true)
        })
        .unwrap();
        assert_eq!((n, summary.truncated_at), (2, Some(3)));
        assert!(for_each_record(text.as_bytes(), true, &mut io::sink(), |_| Ok(true)).is_err());
    }

    /// A file of nothing but unparsable lines exited 0; it is an error naming the first bad line.
    #[test]
    fn a_trace_without_one_frame_is_an_error_naming_the_first_bad_line() {
        let err = for_each_record(
            "\ngarbage\nneither\n".as_bytes(),
            false,
            &mut io::sink(),
            |_| Ok(true),
        )
        .unwrap_err()
        .to_string();
        assert_eq!(
            err,
            "no CAN frame in 3 line(s): line 2 `garbage`: expected `(time) iface id#data [R|T]` \
             (candump -L) or `[(time)] iface id [len] data` (candump)"
        );
        let empty = for_each_record(&b""[..], false, &mut io::sink(), |_| Ok(true)).unwrap_err();
        assert_eq!(empty.to_string(), "no CAN frame: the trace is empty");
    }

    /// Plain `candump vcan0` output reads, and its missing timestamps are named.
    #[test]
    fn candump_screen_output_reads_and_untimed_frames_are_named() {
        let text = "  vcan0  0CFE3027   [8]  7D FF 31 20 4E FF FF FF\n  vcan0  123   [2]  01 02\n";
        let mut diag = Vec::new();
        let mut frames = Vec::new();
        let summary = for_each_record(text.as_bytes(), true, &mut diag, |rec| {
            frames.push(rec.frame);
            Ok(true)
        })
        .unwrap();
        assert_eq!(summary.records, 2);
        assert_eq!(
            frames[0],
            firmware_bridge::trace::parse_line(GOOD).unwrap().frame
        );
        let diag = String::from_utf8(diag).unwrap();
        assert!(diag.contains("2 frame(s) without a timestamp"), "{diag}");
    }

    #[test]
    fn arbitrary_bytes_never_panic() {
        let junk: Vec<u8> = (0..4096u32).map(|i| (i * 7919 % 251) as u8).collect();
        let _ = for_each_record(&junk[..], false, &mut io::sink(), |_| Ok(true));
    }
}
