//! `trace replay`: sends a trace onto a CAN interface with its original timing, like can-utils
//! `canplayer`.
//!
//! Frame `n` is sent at `start + (t_n - t_0) / speed`, where `t_0` is the first frame of the file (so
//! an id filter keeps the recorded timing of the frames it lets through) and `start` is when the replay
//! (or the current `--loop` pass) began. The schedule is absolute, so a late frame does not delay
//! the ones after it; a timestamp that goes backwards is sent at once, never earlier than the frame
//! before it ([`ReplayClock`]). Error frames and CAN FD frames cannot be sent on a classic socket and
//! are skipped and counted. The file is streamed: each `--loop` pass reopens it.

use std::collections::HashSet;
use std::io::{self, Write as _};
use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::Context as _;
use firmware_bridge::frame::CanId;
use firmware_bridge::trace::TraceError;
use firmware_bridge::transport::{Bus, SocketCanBus};

use super::input::{self, Records};

/// `trace replay` arguments.
#[derive(Debug, Clone, clap::Args)]
pub struct ReplayArgs {
    /// The trace (`-` for stdin, without `--loop`).
    pub file: PathBuf,
    /// SocketCAN interface to send on (all frames go there, whatever interface they were recorded on).
    #[arg(long)]
    pub iface: String,
    /// Time scale: 2 plays twice as fast, 0.5 at half speed.
    #[arg(long, default_value_t = 1.0)]
    pub speed: f64,
    /// Only frames with this id (hex, as candump prints it: `0CFE3027`, `123`); repeatable.
    #[arg(long = "id", value_name = "ID", value_parser = super::parse_can_id)]
    pub ids: Vec<u32>,
    /// Replay the file again and again until interrupted.
    #[arg(long = "loop")]
    pub repeat: bool,
    /// Stop at the first malformed line (default: report it and skip it).
    #[arg(long)]
    pub strict: bool,
}

/// Maps trace timestamps to send offsets from the start of the replay.
#[derive(Debug, Clone, PartialEq)]
pub struct ReplayClock {
    speed: f64,
    first_ns: Option<u64>,
    last: Duration,
}

impl ReplayClock {
    /// A clock playing at `speed` (must be positive and finite).
    ///
    /// # Errors
    /// A speed that is not positive and finite.
    pub fn new(speed: f64) -> anyhow::Result<Self> {
        if !(speed.is_finite() && speed > 0.0) {
            anyhow::bail!("--speed must be a positive number, got {speed}");
        }
        Ok(Self {
            speed,
            first_ns: None,
            last: Duration::ZERO,
        })
    }

    /// The offset from the replay start at which the frame recorded at `timestamp_ns` is sent. The
    /// first call defines `t_0`; offsets never decrease.
    pub fn offset(&mut self, timestamp_ns: u64) -> Duration {
        let first = *self.first_ns.get_or_insert(timestamp_ns);
        let rel_s = timestamp_ns.saturating_sub(first) as f64 * 1e-9 / self.speed;
        let at = Duration::try_from_secs_f64(rel_s).unwrap_or(Duration::MAX);
        self.last = self.last.max(at);
        self.last
    }
}

/// What a replay did.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ReplaySummary {
    /// Frames sent.
    pub sent: u64,
    /// Frames left out by the id filter.
    pub filtered: u64,
    /// Error and CAN FD frames that cannot be sent.
    pub unsendable: u64,
    /// Malformed lines skipped.
    pub malformed: u64,
    /// Passes over the file.
    pub passes: u64,
    /// Largest delay of a send behind its schedule.
    pub max_late: Duration,
}

/// Replays one pass of `input` onto `bus`.
///
/// # Errors
/// A malformed line with `strict`, read errors, and send errors.
pub async fn replay_pass<B: Bus>(
    bus: &B,
    input: Box<dyn io::BufRead + Send>,
    speed: f64,
    ids: &HashSet<u32>,
    strict: bool,
    summary: &mut ReplaySummary,
) -> anyhow::Result<()> {
    let mut clock = ReplayClock::new(speed)?;
    let start = tokio::time::Instant::now();
    let mut reported = 0u64;
    for item in Records::new(input) {
        let rec = match item {
            Ok(rec) => rec,
            Err(TraceError::Malformed { line, kind } | TraceError::Truncated { line, kind }) => {
                if strict {
                    anyhow::bail!("line {line}: malformed: {kind}");
                }
                summary.malformed += 1;
                if reported < input::MAX_REPORTED_LINES {
                    reported += 1;
                    eprintln!("warning: line {line}: {kind} (skipped)");
                }
                continue;
            }
            Err(e) => return Err(anyhow::Error::new(e).context("reading the trace")),
        };
        let at = start + clock.offset(rec.timestamp_ns);
        let frame = rec.frame;
        if !ids.is_empty() {
            let id = match frame.id() {
                CanId::Standard(id) => u32::from(id),
                CanId::Extended(id) => id,
            };
            if frame.is_error() || !ids.contains(&id) {
                summary.filtered += 1;
                continue;
            }
        }
        if frame.is_error() || frame.is_fd() {
            summary.unsendable += 1;
            continue;
        }
        tokio::time::sleep_until(at).await;
        summary.max_late = summary
            .max_late
            .max(tokio::time::Instant::now().saturating_duration_since(at));
        bus.send(frame)
            .await
            .with_context(|| format!("sending on {}", bus.interface()))?;
        summary.sent += 1;
    }
    summary.passes += 1;
    Ok(())
}

/// Replays `path` onto `bus`, once or (`repeat`) until `stop` resolves.
///
/// # Errors
/// As [`replay_pass`], and a file that cannot be opened; `repeat` with stdin.
pub async fn replay_to<B: Bus>(
    bus: &B,
    path: &Path,
    speed: f64,
    ids: &[u32],
    repeat: bool,
    strict: bool,
    stop: impl std::future::Future<Output = ()>,
) -> anyhow::Result<ReplaySummary> {
    if repeat && input::is_stdin(path) {
        anyhow::bail!("--loop needs a file, not stdin");
    }
    ReplayClock::new(speed)?;
    let ids: HashSet<u32> = ids.iter().copied().collect();
    let mut summary = ReplaySummary::default();
    let work = async {
        loop {
            let reader = input::open(path)?;
            replay_pass(bus, reader, speed, &ids, strict, &mut summary).await?;
            if !repeat {
                return anyhow::Ok(());
            }
        }
    };
    tokio::select! {
        r = work => r?,
        () = stop => {}
    }
    Ok(summary)
}

/// Runs `trace replay` on SocketCAN, stopping on Ctrl-C.
///
/// # Errors
/// A missing interface (with how to create it), and as [`replay_to`].
pub async fn run(args: &ReplayArgs) -> anyhow::Result<()> {
    ReplayClock::new(args.speed)?;
    let bus = SocketCanBus::open(&args.iface)
        .with_context(|| format!("cannot replay onto {}", args.iface))?;
    let stop = async {
        // Without a signal handler, run until the file ends.
        if tokio::signal::ctrl_c().await.is_err() {
            std::future::pending::<()>().await;
        }
    };
    let summary = replay_to(
        &bus,
        &args.file,
        args.speed,
        &args.ids,
        args.repeat,
        args.strict,
        stop,
    )
    .await?;
    let mut err = io::stderr();
    let _ = writeln!(
        err,
        "replayed {} frame(s) onto {} in {} pass(es); {} filtered, {} error/FD frame(s) skipped, {} malformed line(s); latest send {:.3} ms behind schedule",
        summary.sent,
        args.iface,
        summary.passes,
        summary.filtered,
        summary.unsendable,
        summary.malformed,
        summary.max_late.as_secs_f64() * 1e3
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn offsets_scale_and_never_go_back() {
        let mut c = ReplayClock::new(2.0).unwrap();
        let t0 = 1_700_000_000_000_000_000;
        assert_eq!(c.offset(t0), Duration::ZERO);
        assert_eq!(c.offset(t0 + 10_000_000), Duration::from_millis(5));
        // Backwards in time: sent right after the previous frame.
        assert_eq!(c.offset(t0 + 4_000_000), Duration::from_millis(5));
        assert_eq!(c.offset(t0 + 1_000_000_000), Duration::from_millis(500));
        assert!(ReplayClock::new(0.0).is_err());
        assert!(ReplayClock::new(f64::NAN).is_err());
    }
}
