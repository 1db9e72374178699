//! Reading traces: a file or stdin, streamed record by record, malformed lines reported by number.
//!
//! [`Records`] is [`firmware_bridge::trace::TraceReader`] in `ReadMode::Report`: empty lines are
//! ignored, every malformed line is an error naming its line and the stream carries on, a last line
//! without a newline that does not parse is [`TraceError::Truncated`] and ends the stream (the file
//! was cut while being written), an I/O error ends the stream.

use std::fs::File;
use std::io::{self, BufRead, BufReader, Write};
use std::path::Path;

use anyhow::Context as _;
use firmware_bridge::trace::{ReadMode, TraceError, TraceReader, TraceRecord};

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

/// A streaming iterator over the records of a `candump -L` log that yields every malformed line as
/// an error with its line number and continues after it (a truncated last line and I/O errors end
/// the stream). Memory is one line buffer.
#[derive(Debug)]
pub struct Records<R: BufRead> {
    reader: TraceReader<R>,
}

impl<R: BufRead> Records<R> {
    /// Records of `input`.
    pub fn new(input: R) -> Self {
        Self {
            reader: TraceReader::new(input, ReadMode::Report),
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
        self.reader.next()
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

/// Streams the records of `input` into `on_record`.
///
/// Malformed lines are reported on `diag` (the first [`MAX_REPORTED_LINES`] individually, by line
/// number) and skipped, or with `strict` returned as the error. A truncated last line is reported and
/// ends the stream: an error with `strict`, otherwise the records before it were already delivered.
/// `on_record` returns `Ok(false)` to stop early.
///
/// # Errors
/// I/O errors, a malformed or truncated line with `strict`, and errors of `on_record`.
pub fn for_each_record<R: BufRead>(
    input: R,
    strict: bool,
    diag: &mut dyn Write,
    mut on_record: impl FnMut(TraceRecord) -> anyhow::Result<bool>,
) -> anyhow::Result<ReadSummary> {
    let mut records = Records::new(input);
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

    #[test]
    fn arbitrary_bytes_never_panic() {
        let junk: Vec<u8> = (0..4096u32).map(|i| (i * 7919 % 251) as u8).collect();
        let _ = for_each_record(&junk[..], false, &mut io::sink(), |_| Ok(true));
    }
}
