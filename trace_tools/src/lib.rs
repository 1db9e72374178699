//! `excavator-ctl trace ...`: candump trace debugging that knows the project's messages.
//!
//! # Layout
//!
//! - [`input`]: opens a file or stdin and streams [`TraceRecord`]s with every malformed line reported
//!   by line number (skipped by default, fatal with `--strict`), reading a truncated file up to the
//!   damage.
//! - [`signals`]: DBC-driven signal decoding for display (every signal of a frame, J1939 special values
//!   kept visible, enum names from the DBC's `VAL_` tables) and `Message.Signal` name resolution.
//! - [`decode`]: one line per frame, like `cantools decode --single-line`, with filters.
//! - [`stats`]: per-id counts, rates, jitter, gaps, alive-counter and checksum errors, bus load.
//! - [`plot`]: chosen signals over time as SVG, and the `dig` preset (joint angles, pressures, valve
//!   commands, Autodig stage, bucket-tip path).
//! - [`convert`]: wide CSV and MCAP (JSON messages with JSON schemas, one channel per message).
//! - [`replay`]: canplayer-like replay onto SocketCAN with the original timing.
//! - [`diff`]: where two traces of the same scenario first diverge, per signal.
//! - [`view`]: the Foxglove view of a session (topics, frames, well-known schemas) shared by the MCAP
//!   export and the live stream.
//! - [`synth`]: realistic synthetic traces from the message schedule (tests, benchmark, docs).
//!
//! # Data flow
//!
//! ```text
//! file | stdin --input (parse_line, line numbers)--> TraceRecord --Message::decode / signals--> command
//! ```
//!
//! Every command streams: state is per message id or per signal, never per frame, so memory does not
//! grow with the length of the trace (plots keep a bounded, decimated series per signal).

pub mod convert;
pub mod decode;
pub mod diff;
pub mod input;
pub mod plot;
pub mod replay;
pub mod signals;
pub mod stats;
pub mod synth;
pub mod view;

use std::path::PathBuf;

use anyhow::Context as _;
pub use firmware_bridge::trace::TraceRecord;

/// Arguments shared by the commands that read one trace.
#[derive(Debug, Clone, clap::Args)]
pub struct InputArgs {
    /// The `candump -L` / `candump -l` log or `candump` screen output (with or without `-t`), or
    /// `-` for stdin.
    pub file: PathBuf,
    /// Stop at the first malformed line with a non-zero exit status (default: report it with its line
    /// number on stderr and skip it).
    #[arg(long)]
    pub strict: bool,
    /// Machine profile the trace was recorded with (`run --profile`, `excavator-sim --profile`,
    /// `demo --profile`): its wire frames are read as the project's messages.
    #[arg(long, value_name = "FILE")]
    pub profile: Option<PathBuf>,
    /// The trace is `candump -td` output: each timestamp is the time since the previous frame.
    #[arg(long)]
    pub delta_timestamps: bool,
}

impl InputArgs {
    /// How to read the trace, the profile's wire frames translated to the project's messages.
    ///
    /// # Errors
    /// The profile cannot be loaded.
    pub fn read_options(&self) -> anyhow::Result<input::ReadOptions> {
        Ok(input::ReadOptions {
            profile: input::load_profile(self.profile.as_deref())?,
            ..self.wire_options()
        })
    }

    /// How to read the trace as recorded (wire frames, for commands that handle the profile
    /// themselves).
    pub fn wire_options(&self) -> input::ReadOptions {
        input::ReadOptions {
            strict: self.strict,
            delta_timestamps: self.delta_timestamps,
            profile: None,
        }
    }
}

/// The `trace` subcommands.
#[derive(Debug, Clone, clap::Subcommand)]
pub enum TraceCommand {
    /// One line per frame with the message name and its signals (like `cantools decode`).
    Decode(decode::DecodeArgs),
    /// Per-id counts, rates, period jitter, gaps, counter/checksum errors and bus load.
    Stats(stats::StatsArgs),
    /// Chosen signals over time as SVG, or `--preset dig`.
    Plot(plot::PlotArgs),
    /// Converts to a wide CSV of signals or to MCAP for Foxglove / PlotJuggler.
    Convert(convert::ConvertArgs),
    /// Replays a trace onto a SocketCAN interface with its original timing (like canplayer).
    Replay(replay::ReplayArgs),
    /// Where two traces of the same scenario first diverge, per signal.
    Diff(diff::DiffArgs),
}

/// Runs a `trace` subcommand, printing to stdout (reports and warnings to stderr).
///
/// The file-based commands run on a blocking thread; `replay` runs on the caller's tokio runtime.
///
/// # Errors
/// Unreadable input, a malformed line in `--strict` mode, an output that cannot be written, a
/// missing CAN interface for `replay`.
pub async fn run(cmd: TraceCommand) -> anyhow::Result<()> {
    match cmd {
        TraceCommand::Replay(args) => replay::run(&args).await,
        other => tokio::task::spawn_blocking(move || run_blocking(other))
            .await
            .context("trace command thread failed")?,
    }
}

/// Runs a `trace` subcommand synchronously; `replay` gets its own single-threaded tokio runtime.
/// For callers without a runtime (do not call from inside one: use [`run`]).
///
/// # Errors
/// As [`run`].
pub fn run_blocking(cmd: TraceCommand) -> anyhow::Result<()> {
    match cmd {
        TraceCommand::Decode(args) => decode::run(&args),
        TraceCommand::Stats(args) => stats::run(&args),
        TraceCommand::Plot(args) => plot::run(&args),
        TraceCommand::Convert(args) => convert::run(&args),
        TraceCommand::Diff(args) => diff::run(&args),
        TraceCommand::Replay(args) => {
            let rt = tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()
                .context("starting the tokio runtime for replay")?;
            rt.block_on(replay::run(&args))
        }
    }
}

/// Parses a number given as hex (`0x80`, `0X1f`) or decimal (`128`).
///
/// # Errors
/// A message naming the text when it is neither.
pub fn parse_u32_auto(text: &str) -> Result<u32, String> {
    let t = text.trim();
    let parsed = match t.strip_prefix("0x").or_else(|| t.strip_prefix("0X")) {
        Some(hex) => u32::from_str_radix(hex, 16),
        None => t.parse(),
    };
    parsed.map_err(|_| format!("{text:?} is not a number (decimal or 0x-prefixed hex)"))
}

/// Parses a J1939 source address (`0x80`, `128`).
///
/// # Errors
/// Not a number, or above 255.
pub fn parse_source_address(text: &str) -> Result<u8, String> {
    let v = parse_u32_auto(text)?;
    u8::try_from(v).map_err(|_| format!("source address {text:?} is above 0xFF"))
}

/// Parses a CAN id as candump writes it: hex without prefix (`0CFE3027`, `123`), or `0x`-prefixed.
///
/// # Errors
/// Not hex, or above 29 bits.
pub fn parse_can_id(text: &str) -> Result<u32, String> {
    let t = text.trim();
    let hex = t
        .strip_prefix("0x")
        .or_else(|| t.strip_prefix("0X"))
        .unwrap_or(t);
    let v = u32::from_str_radix(hex, 16)
        .map_err(|_| format!("{text:?} is not a hex CAN id (e.g. 0CFE3027)"))?;
    if v > 0x1FFF_FFFF {
        return Err(format!("CAN id {text:?} is above 29 bits"));
    }
    Ok(v)
}

/// Formats a timestamp in candump style: `seconds.micros`, or nanoseconds when they are not whole
/// microseconds (9-digit input).
pub fn format_timestamp(timestamp_ns: u64, out: &mut String) {
    let secs = timestamp_ns / 1_000_000_000;
    let frac = timestamp_ns % 1_000_000_000;
    // Without `write!`: this runs once per line of `trace decode`.
    let mut buf = itoa::Buffer::new();
    out.push_str(buf.format(secs));
    out.push('.');
    let (frac, width) = if frac.is_multiple_of(1000) {
        (frac / 1000, 6)
    } else {
        (frac, 9)
    };
    let digits = buf.format(frac);
    for _ in digits.len()..width {
        out.push('0');
    }
    out.push_str(digits);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_parse_in_hex_and_decimal() {
        assert_eq!(parse_source_address("0x80"), Ok(0x80));
        assert_eq!(parse_source_address("39"), Ok(0x27));
        assert!(parse_source_address("0x100").is_err());
        assert!(parse_source_address("boom").is_err());
        assert_eq!(parse_can_id("0CFE3027"), Ok(0x0CFE_3027));
        assert_eq!(parse_can_id("0x123"), Ok(0x123));
        assert!(parse_can_id("3FFFFFFF").is_err());
    }

    #[test]
    fn timestamps_keep_their_resolution() {
        let mut s = String::new();
        format_timestamp(1_700_000_000_123_456_000, &mut s);
        assert_eq!(s, "1700000000.123456");
        s.clear();
        format_timestamp(1_700_000_000_123_456_789, &mut s);
        assert_eq!(s, "1700000000.123456789");
    }
}
