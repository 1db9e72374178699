//! `trace replay`: sends a trace onto a CAN interface with its original timing, like can-utils
//! `canplayer`.
//!
//! Frame `n` is sent at `start + (t_n - t_0) / speed`, where `t_0` is the first frame of the file (so
//! an id filter keeps the recorded timing of the frames it lets through) and `start` is when the replay
//! (or the current `--loop` pass) began. The schedule is absolute, so a late frame does not delay
//! the ones after it; a timestamp that goes backwards is sent at once, never earlier than the frame
//! before it ([`ReplayClock`]). Error frames and CAN FD frames cannot be sent on a classic socket and
//! are skipped and counted. The file is streamed: each `--loop` pass reopens it.
//!
//! The controller's frames (source address `0x27`) and heartbeats from any address are withheld and
//! counted unless `--allow-control-frames` is given: on a bus with a gateway they request arming and
//! drive valves. The gateway refuses a recording of another session ([`firmware_bridge::secoc`]), but
//! a replay is no place to rely on that; the flag is for benches without a machine.
//!
//! A trace recorded with a machine profile holds that gateway's wire frames: with `--profile FILE`
//! each frame is translated to the project's message it carries and withheld when that is a
//! controller frame or a heartbeat, and the wire frame as recorded is what is sent. Without a
//! profile, frames that are not the project's messages are sent and counted, with a warning that a
//! profile trace needs `--profile`.

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
    /// Also send the controller's frames (source address 0x27) and heartbeats, which are withheld by
    /// default: on a bus with a gateway they arm it and drive the valves. Only on a bench without a
    /// machine.
    #[arg(long)]
    pub allow_control_frames: bool,
    /// Machine profile the trace was recorded with: its controller frames are withheld too.
    #[arg(long, value_name = "FILE")]
    pub profile: Option<PathBuf>,
    /// The trace is `candump -td` output (timestamps since the previous frame).
    #[arg(long)]
    pub delta_timestamps: bool,
}

/// How to replay (the options of [`ReplayArgs`] apart from the file and the interface).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ReplayOptions {
    /// Time scale (positive, finite).
    pub speed: f64,
    /// Only these ids (all when empty).
    pub ids: Vec<u32>,
    /// Loop until stopped.
    pub repeat: bool,
    /// Stop at the first malformed line.
    pub strict: bool,
    /// Send the controller's frames and heartbeats too (see the module docs).
    pub allow_control_frames: bool,
    /// The machine profile of the trace's wire frames.
    pub profile: Option<std::sync::Arc<firmware_bridge::profile::Profile>>,
    /// Screen-format timestamps are `candump -td` deltas.
    pub delta_timestamps: bool,
}

/// True for a frame that can arm the gateway or drive a valve: from the controller's source address,
/// or a heartbeat (the arming request) from any address.
pub fn is_control_frame(frame: &firmware_bridge::CanFrame) -> bool {
    let CanId::Extended(raw) = frame.id() else {
        return false;
    };
    firmware_bridge::J1939Id::from_raw(raw).is_ok_and(|id| {
        id.source_address() == firmware_bridge::CONTROLLER_ADDRESS
            || id.pgn() == firmware_bridge::dbc::controller_heartbeat::PGN
    })
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
    /// Controller frames and heartbeats withheld (without `--allow-control-frames`).
    pub withheld_control: u64,
    /// Frames sent that are not the project's messages (or with a profile, not in it).
    pub foreign: u64,
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
    options: &ReplayOptions,
    ids: &HashSet<u32>,
    summary: &mut ReplaySummary,
) -> anyhow::Result<()> {
    let strict = options.strict;
    let mut clock = ReplayClock::new(options.speed)?;
    let start = tokio::time::Instant::now();
    let mut reported = 0u64;
    let mut records = Records::with_options(
        input,
        &input::ReadOptions {
            strict,
            delta_timestamps: options.delta_timestamps,
            profile: None,
        },
    );
    let mut read = 0u64;
    for item in records.by_ref() {
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
        read += 1;
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
        let project = match &options.profile {
            Some(p) => p.from_wire(&frame).ok(),
            None => Some(frame),
        };
        let project = project.filter(|f| super::signals::message_of(f).is_some());
        if !options.allow_control_frames && project.as_ref().is_some_and(is_control_frame) {
            summary.withheld_control += 1;
            continue;
        }
        if project.is_none() {
            summary.foreign += 1;
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
    if let Some(e) = records.nothing_read(read) {
        return Err(e);
    }
    records.warn_at_end(&mut io::stderr());
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
    options: &ReplayOptions,
    stop: impl std::future::Future<Output = ()>,
) -> anyhow::Result<ReplaySummary> {
    let repeat = options.repeat;
    if repeat && input::is_stdin(path) {
        anyhow::bail!("--loop needs a file, not stdin");
    }
    ReplayClock::new(options.speed)?;
    let ids: HashSet<u32> = options.ids.iter().copied().collect();
    let mut summary = ReplaySummary::default();
    let work = async {
        loop {
            let reader = input::open(path)?;
            replay_pass(bus, reader, options, &ids, &mut summary).await?;
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
    let options = ReplayOptions {
        speed: args.speed,
        ids: args.ids.clone(),
        repeat: args.repeat,
        strict: args.strict,
        allow_control_frames: args.allow_control_frames,
        profile: input::load_profile(args.profile.as_deref())?,
        delta_timestamps: args.delta_timestamps,
    };
    let mut err = io::stderr();
    if args.allow_control_frames {
        let _ = writeln!(
            err,
            "warning: --allow-control-frames: the controller's frames and heartbeats go onto {} as recorded; on a bus with a machine gateway they can arm it and move the machine",
            args.iface
        );
    }
    let summary = replay_to(&bus, &args.file, &options, stop)
        .await
        .with_context(|| format!("replaying {}", args.file.display()))?;
    if summary.foreign > 0 && options.profile.is_none() {
        let _ = writeln!(
            err,
            "warning: sent {} frame(s) that are not the project's messages: a trace recorded with a machine profile needs --profile FILE so that its controller frames are withheld",
            summary.foreign
        );
    }
    if summary.withheld_control > 0 {
        let _ = writeln!(
            err,
            "warning: withheld {} controller frame(s) and heartbeat(s): replayed onto a bus with a machine gateway they request arming and drive valves (--allow-control-frames sends them, on a bench without a machine only)",
            summary.withheld_control
        );
    }
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
