//! `trace stats`: per message id counts, rates, period jitter, gaps, alive-counter and checksum errors,
//! unknown ids, error frames, malformed lines, and the total and peak bus load with exact stuff bits.
//!
//! State is per id (at most [`MAX_IDS`] ids; further ids are only counted) plus the current load
//! window, so memory does not depend on the trace length.
//!
//! - Period statistics use the time between consecutive frames of the same id (Welford mean and
//!   standard deviation, maximum); a frame whose timestamp goes backwards is counted, not used.
//! - A gap is a period above the threshold: `--gap-ms`, or by default 3 times the nominal period of the
//!   message in `busload::SCHEDULE` (ids that are not in the schedule have no default threshold).
//! - Alive counters: `ControllerHeartbeat.AliveCounter` (4 bits), `GatewayStatus.AliveCounter` (8),
//!   `ControllerStatus.AliveCounter` (4), `PositionSetpoint.SequenceCounter` (4): each frame must carry
//!   the successor of the previous one of the same id (`messages::is_next_alive`).
//! - Checksum: the heartbeat's CRC-8 (`messages::heartbeat_checksum`).
//! - Invalid: other reasons [`Message::decode`] rejects a frame of a known message (DLC, range).
//! - Bus load: `busload::stuffed_bits` of every classic frame; the total over the trace's span as in
//!   `busload::measured_load`, the peak over fixed windows (`--window-ms`, 100 ms) from the first frame.
//! - Expected messages: every periodic message of the schedule that the trace never carries is listed
//!   as absent.
//!
//! With `--profile FILE` the trace holds that gateway's wire frames: each is translated to the
//! project's message it carries ([`Profile::from_wire`]) and checked as above (counters, checksum,
//! validity), against the profile's periods (its DBC's `GenMsgCycleTime` and `period_ms`) instead of
//! the project's schedule; the id column shows the wire id, the message column the project's message
//! and the wire message carrying it; frames the profile does not map are the unknown ones. The bus
//! load is that of the wire frames.

use std::collections::{BTreeMap, HashMap};
use std::fmt::Write as _;
use std::io::{self, BufRead, Write};

use anyhow::Context as _;
use firmware_bridge::busload;
use firmware_bridge::dbc::{self, DecodeError};
use firmware_bridge::frame::{CanId, FrameKind};
use firmware_bridge::messages::{self, Message};
use firmware_bridge::profile::Profile;
use firmware_bridge::trace::TraceRecord;
use firmware_bridge::transport::BusFault;
use serde::Serialize;

use super::InputArgs;
use super::input::{self, ReadSummary};
use super::signals;

/// Most distinct ids tracked individually; frames of further ids are only counted.
pub const MAX_IDS: usize = 4096;
/// Gaps listed per id (all are counted).
const GAPS_LISTED: usize = 5;

/// `trace stats` arguments.
#[derive(Debug, Clone, clap::Args)]
pub struct StatsArgs {
    /// The trace.
    #[command(flatten)]
    pub input: InputArgs,
    /// Gap threshold for every id, ms (default: 3x the nominal period of each message).
    #[arg(long, value_name = "MS")]
    pub gap_ms: Option<f64>,
    /// Bus bit rate for the load figures, bit/s.
    #[arg(long, default_value_t = busload::BITRATE)]
    pub bitrate: u32,
    /// Window of the peak bus load, ms.
    #[arg(long, default_value_t = 100.0, value_name = "MS")]
    pub window_ms: f64,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
}

/// Settings of [`StatsCollector`].
#[derive(Debug, Clone, PartialEq)]
pub struct StatsOptions {
    /// Gap threshold for every id, s (`None`: 3x the nominal period).
    pub gap_s: Option<f64>,
    /// Bus bit rate, bit/s.
    pub bitrate: u32,
    /// Peak load window, s.
    pub window_s: f64,
    /// The machine profile of the trace's wire frames (see the module docs).
    pub profile: Option<std::sync::Arc<Profile>>,
}

impl Default for StatsOptions {
    fn default() -> Self {
        Self {
            gap_s: None,
            bitrate: busload::BITRATE,
            window_s: 0.1,
            profile: None,
        }
    }
}

impl StatsOptions {
    /// The nominal period of `msg` on the trace's gateway, s: the profile's, or the project's
    /// schedule's.
    fn nominal_period_s(&self, msg: &dbc::MessageDesc) -> Option<f64> {
        match &self.profile {
            Some(p) => p
                .route_of(msg.name)
                .filter(|(ms, _)| *ms > 0)
                .map(|(ms, _)| f64::from(ms) * 1e-3),
            None => signals::nominal_period_s(msg),
        }
    }
}

/// A gap in one id's frames.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Gap {
    /// Time of the frame after the gap, s after the first frame of the trace.
    pub at_s: f64,
    /// Length of the gap (period), ms.
    pub length_ms: f64,
}

/// Statistics of one id.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct IdReport {
    /// The id as candump prints it (`0CFE3027`, `123`).
    pub id: String,
    /// DBC message name, or what the frames are (`unknown`, `11-bit`, `remote`, `CAN FD`).
    pub message: String,
    /// Frames.
    pub count: u64,
    /// Mean rate over the id's own span, Hz (`None` for fewer than two frames).
    pub rate_hz: Option<f64>,
    /// Nominal rate from the schedule, Hz.
    pub nominal_hz: Option<f64>,
    /// Mean period, ms.
    pub period_mean_ms: Option<f64>,
    /// Standard deviation of the period (jitter), ms.
    pub period_std_ms: Option<f64>,
    /// Largest period, ms.
    pub period_max_ms: Option<f64>,
    /// Gap threshold used, ms.
    pub gap_threshold_ms: Option<f64>,
    /// Periods above the threshold.
    pub gaps: u64,
    /// The first gaps.
    pub first_gaps: Vec<Gap>,
    /// Alive/sequence counter errors (`None`: the message has no counter).
    pub alive_errors: Option<u64>,
    /// Checksum errors (`None`: the message has no checksum).
    pub checksum_errors: Option<u64>,
    /// Frames [`Message::decode`] rejects for another reason.
    pub invalid: u64,
    /// The last such reason.
    pub last_invalid: Option<String>,
    /// Frames whose timestamp is before the previous frame of the id.
    pub backwards: u64,
}

/// The whole report.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StatsReport {
    /// Frames read.
    pub frames: u64,
    /// First to last timestamp, s.
    pub span_s: f64,
    /// Malformed lines skipped.
    pub malformed_lines: u64,
    /// Line numbers of the first malformed lines.
    pub malformed_line_numbers: Vec<u64>,
    /// Line of a truncated last line.
    pub truncated_at_line: Option<u64>,
    /// Frames whose id is not a project message (unknown PGN, 11-bit, remote, FD), or with a profile
    /// frames the profile does not map.
    pub unknown_id_frames: u64,
    /// The profile the frames were read with.
    pub profile: Option<String>,
    /// Periodic messages of the schedule (or the profile) that the trace does not carry.
    pub absent: Vec<String>,
    /// Error frames.
    pub error_frames: u64,
    /// Error frames by most severe condition.
    pub error_frame_kinds: BTreeMap<String, u64>,
    /// Frames of ids beyond [`MAX_IDS`].
    pub untracked_frames: u64,
    /// Bit rate of the load figures, bit/s.
    pub bitrate: u32,
    /// Mean bus load over the span, fraction.
    pub bus_load: Option<f64>,
    /// Peak bus load in one window, fraction.
    pub peak_load: Option<f64>,
    /// Start of the peak window, s after the first frame.
    pub peak_at_s: Option<f64>,
    /// Window of the peak, ms.
    pub window_ms: f64,
    /// Per id, sorted by id.
    pub ids: Vec<IdReport>,
}

#[derive(Debug, Clone)]
struct IdState {
    /// The id on the wire, as candump prints it.
    id: String,
    label: String,
    msg: Option<&'static dbc::MessageDesc>,
    counter: Option<(&'static dbc::SignalDesc, u32)>,
    count: u64,
    first_ns: u64,
    last_ns: u64,
    periods: u64,
    mean_s: f64,
    m2: f64,
    max_s: f64,
    gap_s: Option<f64>,
    gaps: u64,
    first_gaps: Vec<Gap>,
    last_counter: Option<i64>,
    alive_errors: u64,
    checksum_errors: u64,
    invalid: u64,
    last_invalid: Option<DecodeError>,
    backwards: u64,
}

/// Collects statistics record by record.
#[derive(Debug, Clone)]
pub struct StatsCollector {
    opts: StatsOptions,
    ids: HashMap<u32, IdState>,
    frames: u64,
    first_ns: Option<u64>,
    last_ns: u64,
    bits: u64,
    counted_frames: u64,
    window: u64,
    window_bits: u64,
    peak_bits: u64,
    peak_window: u64,
    unknown: u64,
    error_frames: u64,
    error_kinds: BTreeMap<String, u64>,
    untracked: u64,
}

/// A key that keeps 11-bit, 29-bit and error ids apart.
fn id_key(frame: &firmware_bridge::CanFrame) -> u32 {
    match (frame.kind(), frame.id()) {
        (FrameKind::Error, _) => u32::MAX,
        (_, CanId::Extended(id)) => id | 0x8000_0000,
        (_, CanId::Standard(id)) => u32::from(id),
    }
}

/// The id as candump prints it.
fn id_text(frame: &firmware_bridge::CanFrame) -> String {
    match frame.id() {
        CanId::Extended(id) => format!("{id:08X}"),
        CanId::Standard(id) => format!("{id:03X}"),
    }
}

impl StatsCollector {
    /// A collector with `opts`.
    pub fn new(opts: StatsOptions) -> Self {
        Self {
            opts,
            ids: HashMap::new(),
            frames: 0,
            first_ns: None,
            last_ns: 0,
            bits: 0,
            counted_frames: 0,
            window: 0,
            window_bits: 0,
            peak_bits: 0,
            peak_window: 0,
            unknown: 0,
            error_frames: 0,
            error_kinds: BTreeMap::new(),
            untracked: 0,
        }
    }

    fn window_ns(&self) -> u64 {
        let w = self.opts.window_s * 1e9;
        if w.is_finite() && w >= 1.0 {
            w as u64
        } else {
            100_000_000
        }
    }

    /// The state of a new id: `frame` is the project's frame (translated when there is a profile,
    /// `None` when the profile does not map `wire`).
    fn new_state(
        &self,
        rec: &TraceRecord,
        wire: &firmware_bridge::CanFrame,
        frame: Option<&firmware_bridge::CanFrame>,
    ) -> IdState {
        let known = frame.and_then(signals::message_of);
        let label = match (known, wire.kind(), wire.id()) {
            (Some((_, m)), _, _) => {
                match self.opts.profile.as_ref().and_then(|p| p.route_of(m.name)) {
                    Some((_, wire_name)) if wire_name != m.name => {
                        format!("{} ({wire_name})", m.name)
                    }
                    _ => m.name.to_string(),
                }
            }
            (None, _, _) if frame.is_none() => "not in profile".to_string(),
            (None, FrameKind::Remote, _) => "remote".to_string(),
            (None, FrameKind::Fd { .. }, _) => "CAN FD".to_string(),
            (None, _, CanId::Standard(_)) => "11-bit".to_string(),
            (None, _, CanId::Extended(_)) => "unknown".to_string(),
        };
        let msg = known.map(|(_, m)| m);
        let counter = msg.and_then(|m| {
            m.signals
                .iter()
                .find(|s| s.name == "AliveCounter" || s.name == "SequenceCounter")
                .map(|s| (s, u32::from(s.len)))
        });
        let gap_s = self.opts.gap_s.or_else(|| {
            msg.and_then(|m| self.opts.nominal_period_s(m))
                .map(|p| 3.0 * p)
        });
        IdState {
            id: id_text(wire),
            label,
            msg,
            counter,
            count: 0,
            first_ns: rec.timestamp_ns,
            last_ns: rec.timestamp_ns,
            periods: 0,
            mean_s: 0.0,
            m2: 0.0,
            max_s: 0.0,
            gap_s,
            gaps: 0,
            first_gaps: Vec::new(),
            last_counter: None,
            alive_errors: 0,
            checksum_errors: 0,
            invalid: 0,
            last_invalid: None,
            backwards: 0,
        }
    }

    /// Adds one record.
    pub fn add(&mut self, rec: &TraceRecord) {
        self.frames += 1;
        let first = *self.first_ns.get_or_insert(rec.timestamp_ns);
        self.last_ns = self.last_ns.max(rec.timestamp_ns);
        let frame = &rec.frame;

        // Bus load: classic data and remote frames (error and FD frames have no defined length here).
        if let Some(bits) = busload::stuffed_bits(frame) {
            let bits = u64::from(bits);
            self.bits += bits;
            self.counted_frames += 1;
            let w = rec.timestamp_ns.saturating_sub(first) / self.window_ns();
            if w > self.window {
                self.close_window();
                self.window = w;
            }
            self.window_bits += bits;
        }

        if frame.is_error() {
            self.error_frames += 1;
            let kind = BusFault::from_error_frame(frame)
                .map_or_else(|| "unknown".to_string(), |f| format!("{f:?}"));
            *self.error_kinds.entry(kind).or_insert(0) += 1;
            return;
        }
        let translated = match &self.opts.profile {
            Some(p) => p.from_wire(frame).ok(),
            None => Some(*frame),
        };
        if translated.as_ref().and_then(signals::message_of).is_none() {
            self.unknown += 1;
        }
        // A multiplexed wire id carries several messages: one state per project message.
        let key = translated
            .as_ref()
            .map_or_else(|| id_key(frame) ^ 0x4000_0000, id_key);
        if !self.ids.contains_key(&key) {
            if self.ids.len() >= MAX_IDS {
                self.untracked += 1;
                return;
            }
            let state = self.new_state(rec, frame, translated.as_ref());
            self.ids.insert(key, state);
        }
        let Some(st) = self.ids.get_mut(&key) else {
            return;
        };
        st.count += 1;
        if st.count > 1 {
            if rec.timestamp_ns < st.last_ns {
                st.backwards += 1;
            } else {
                let period_s = (rec.timestamp_ns - st.last_ns) as f64 * 1e-9;
                st.periods += 1;
                let delta = period_s - st.mean_s;
                st.mean_s += delta / st.periods as f64;
                st.m2 += delta * (period_s - st.mean_s);
                st.max_s = st.max_s.max(period_s);
                if st.gap_s.is_some_and(|g| period_s > g) {
                    st.gaps += 1;
                    if st.first_gaps.len() < GAPS_LISTED {
                        st.first_gaps.push(Gap {
                            at_s: rec.timestamp_ns.saturating_sub(first) as f64 * 1e-9,
                            length_ms: period_s * 1e3,
                        });
                    }
                }
                st.last_ns = rec.timestamp_ns;
            }
        }
        let (Some(desc), Some(frame)) = (st.msg, translated.as_ref()) else {
            return;
        };
        let data = frame.data();
        if data.len() != usize::from(desc.dlc) {
            st.invalid += 1;
            st.last_invalid = Message::decode(frame).err();
            return;
        }
        if let Some((sig, bits)) = st.counter
            && let Some(raw) = signals::raw_value(sig, data)
        {
            if let Some(prev) = st.last_counter
                && !messages::is_next_alive(prev as u8, raw as u8, bits)
            {
                st.alive_errors += 1;
            }
            st.last_counter = Some(raw);
        }
        match Message::decode(frame) {
            Ok(_) => {}
            Err(DecodeError::BadChecksum { .. }) => st.checksum_errors += 1,
            Err(e) => {
                st.invalid += 1;
                st.last_invalid = Some(e);
            }
        }
    }

    fn close_window(&mut self) {
        if self.window_bits > self.peak_bits {
            self.peak_bits = self.window_bits;
            self.peak_window = self.window;
        }
        self.window_bits = 0;
    }

    /// The report, with the reader's counts.
    pub fn finish(mut self, read: &ReadSummary) -> StatsReport {
        let window_ns = self.window_ns();
        let bitrate = f64::from(self.opts.bitrate.max(1));
        // A last window shorter than the window length would understate its load: only full windows
        // count, unless the trace is shorter than one window.
        let last_window_full = self
            .first_ns
            .is_some_and(|f| self.last_ns.saturating_sub(f) >= (self.window + 1) * window_ns);
        if last_window_full || self.peak_bits == 0 {
            self.close_window();
        }
        let first = self.first_ns.unwrap_or(0);
        let span_s = self.last_ns.saturating_sub(first) as f64 * 1e-9;
        let bus_load = (self.counted_frames >= 2 && span_s > 0.0).then(|| {
            let per_frame = self.bits as f64 / self.counted_frames as f64;
            per_frame * (self.counted_frames - 1) as f64 / span_s / bitrate
        });
        let window_s = window_ns as f64 * 1e-9;
        let peak_load = (self.peak_bits > 0).then(|| self.peak_bits as f64 / window_s / bitrate);
        let peak_at_s = peak_load.map(|_| self.peak_window as f64 * window_s);

        let seen: Vec<&str> = self
            .ids
            .values()
            .filter_map(|st| st.msg.map(|m| m.name))
            .collect();
        let absent = dbc::MESSAGES
            .iter()
            .filter(|m| self.opts.nominal_period_s(m).is_some() && !seen.contains(&m.name))
            .map(|m| m.name.to_string())
            .collect();
        let mut keyed: Vec<(u32, IdState)> = self.ids.into_iter().collect();
        keyed.sort_by(|(ka, a), (kb, b)| (a.id.len(), &a.id, ka).cmp(&(b.id.len(), &b.id, kb)));
        let opts = &self.opts;
        let ids = keyed
            .into_iter()
            .map(|(_, st)| {
                let id = st.id;
                let span = st.last_ns.saturating_sub(st.first_ns) as f64 * 1e-9;
                let std = (st.periods >= 2).then(|| (st.m2 / (st.periods - 1) as f64).sqrt());
                let is_heartbeat = st
                    .msg
                    .is_some_and(|m| m.pgn == dbc::controller_heartbeat::PGN);
                IdReport {
                    id,
                    message: st.label,
                    count: st.count,
                    rate_hz: (st.periods >= 1 && span > 0.0).then(|| st.periods as f64 / span),
                    nominal_hz: st
                        .msg
                        .and_then(|m| opts.nominal_period_s(m))
                        .map(|p| 1.0 / p),
                    period_mean_ms: (st.periods >= 1).then_some(st.mean_s * 1e3),
                    period_std_ms: std.map(|s| s * 1e3),
                    period_max_ms: (st.periods >= 1).then_some(st.max_s * 1e3),
                    gap_threshold_ms: st.gap_s.map(|g| g * 1e3),
                    gaps: st.gaps,
                    first_gaps: st.first_gaps,
                    alive_errors: st.counter.map(|_| st.alive_errors),
                    checksum_errors: is_heartbeat.then_some(st.checksum_errors),
                    invalid: st.invalid,
                    last_invalid: st.last_invalid.map(|e| e.to_string()),
                    backwards: st.backwards,
                }
            })
            .collect();
        StatsReport {
            frames: self.frames,
            span_s,
            malformed_lines: read.malformed,
            malformed_line_numbers: read.malformed_lines.clone(),
            truncated_at_line: read.truncated_at,
            unknown_id_frames: self.unknown,
            profile: self.opts.profile.as_ref().map(|p| p.origin().to_string()),
            absent,
            error_frames: self.error_frames,
            error_frame_kinds: self.error_kinds,
            untracked_frames: self.untracked,
            bitrate: self.opts.bitrate,
            bus_load,
            peak_load,
            peak_at_s,
            window_ms: window_s * 1e3,
            ids,
        }
    }
}

/// Collects the statistics of a whole trace.
///
/// # Errors
/// As [`input::for_each_record`].
pub fn collect<R: BufRead>(
    input: R,
    opts: StatsOptions,
    read: impl Into<input::ReadOptions>,
    diag: &mut dyn Write,
) -> anyhow::Result<StatsReport> {
    let mut collector = StatsCollector::new(opts);
    let read = input::for_each_record(input, read, diag, |rec| {
        collector.add(&rec);
        Ok(true)
    })?;
    Ok(collector.finish(&read))
}

fn opt(v: Option<f64>, decimals: usize) -> String {
    v.map_or_else(|| "-".to_string(), |v| format!("{v:.decimals$}"))
}

fn opt_count(v: Option<u64>) -> String {
    v.map_or_else(|| "-".to_string(), |v| v.to_string())
}

/// Formats the report as text tables.
pub fn format_report(r: &StatsReport) -> String {
    let mut s = String::new();
    // Writing to a String cannot fail.
    let _ = writeln!(
        s,
        "{} frames over {:.3} s; {} malformed line(s){}; {} unknown-id frame(s); {} error frame(s)",
        r.frames,
        r.span_s,
        r.malformed_lines,
        r.truncated_at_line
            .map_or_else(String::new, |l| format!(", truncated at line {l}")),
        r.unknown_id_frames,
        r.error_frames
    );
    if let Some(p) = &r.profile {
        let _ = writeln!(
            s,
            "read with profile {p}: unknown ids are frames it does not map; rates against its periods"
        );
    }
    if !r.absent.is_empty() {
        let _ = writeln!(s, "periodic messages absent: {}", r.absent.join(", "));
    }
    if !r.malformed_line_numbers.is_empty() {
        let lines: Vec<String> = r
            .malformed_line_numbers
            .iter()
            .map(u64::to_string)
            .collect();
        let _ = writeln!(s, "malformed lines: {}", lines.join(", "));
    }
    for (kind, n) in &r.error_frame_kinds {
        let _ = writeln!(s, "error frames {kind}: {n}");
    }
    if r.untracked_frames > 0 {
        let _ = writeln!(
            s,
            "{} frame(s) of ids beyond the first {MAX_IDS} not itemized",
            r.untracked_frames
        );
    }
    let _ = writeln!(
        s,
        "bus load at {} bit/s (exact stuff bits): mean {}, peak {} ({} ms window at {} s)",
        r.bitrate,
        r.bus_load
            .map_or_else(|| "-".to_string(), |l| format!("{:.1} %", l * 100.0)),
        r.peak_load
            .map_or_else(|| "-".to_string(), |l| format!("{:.1} %", l * 100.0)),
        r.window_ms,
        opt(r.peak_at_s, 3),
    );
    let _ = writeln!(
        s,
        "\n{:<8}  {:<26} {:>8} {:>8} {:>7} {:>9} {:>9} {:>9} {:>5} {:>6} {:>6} {:>7}",
        "id",
        "message",
        "count",
        "rate_hz",
        "nominal",
        "period_ms",
        "jitter_ms",
        "max_ms",
        "gaps",
        "alive",
        "crc",
        "invalid"
    );
    for id in &r.ids {
        let _ = writeln!(
            s,
            "{:<8}  {:<26} {:>8} {:>8} {:>7} {:>9} {:>9} {:>9} {:>5} {:>6} {:>6} {:>7}",
            id.id,
            id.message,
            id.count,
            opt(id.rate_hz, 2),
            opt(id.nominal_hz, 0),
            opt(id.period_mean_ms, 3),
            opt(id.period_std_ms, 3),
            opt(id.period_max_ms, 3),
            id.gaps,
            opt_count(id.alive_errors),
            opt_count(id.checksum_errors),
            id.invalid
        );
    }
    let with_gaps: Vec<&IdReport> = r.ids.iter().filter(|i| i.gaps > 0).collect();
    if !with_gaps.is_empty() {
        let _ = writeln!(s, "\ngaps (period over the threshold):");
        for id in with_gaps {
            let list: Vec<String> = id
                .first_gaps
                .iter()
                .map(|g| format!("{:.1} ms at {:.3} s", g.length_ms, g.at_s))
                .collect();
            let _ = writeln!(
                s,
                "  {} {} (threshold {} ms): {}{}",
                id.id,
                id.message,
                opt(id.gap_threshold_ms, 1),
                list.join(", "),
                if id.gaps as usize > id.first_gaps.len() {
                    format!(", ... ({} in all)", id.gaps)
                } else {
                    String::new()
                }
            );
        }
    }
    for id in r.ids.iter().filter(|i| i.backwards > 0) {
        let _ = writeln!(
            s,
            "  {} {}: {} frame(s) earlier than the previous one",
            id.id, id.message, id.backwards
        );
    }
    for id in r.ids.iter().filter(|i| i.invalid > 0) {
        let _ = writeln!(
            s,
            "  {} {}: {} invalid frame(s), last: {}",
            id.id,
            id.message,
            id.invalid,
            id.last_invalid.as_deref().unwrap_or("?")
        );
    }
    s
}

/// Runs `trace stats`.
///
/// # Errors
/// As [`collect`], and output errors.
pub fn run(args: &StatsArgs) -> anyhow::Result<()> {
    let opts = StatsOptions {
        gap_s: args.gap_ms.map(|ms| ms * 1e-3),
        bitrate: args.bitrate,
        window_s: args.window_ms * 1e-3,
        profile: input::load_profile(args.input.profile.as_deref())?,
    };
    let reader = input::open(&args.input.file)?;
    let report = collect(reader, opts, args.input.wire_options(), &mut io::stderr())
        .with_context(|| format!("reading {}", args.input.file.display()))?;
    let text = if args.json {
        let mut j = serde_json::to_string_pretty(&report).context("formatting JSON")?;
        j.push('\n');
        j
    } else {
        format_report(&report)
    };
    let mut out = io::stdout().lock();
    out.write_all(text.as_bytes())
        .and_then(|()| out.flush())
        .context("writing the report")
}

#[cfg(test)]
mod tests {
    use super::*;
    use firmware_bridge::trace::parse_line;

    fn report(lines: &[String]) -> StatsReport {
        let text = lines.join("\n") + "\n";
        collect(
            text.as_bytes(),
            StatsOptions::default(),
            false,
            &mut io::sink(),
        )
        .unwrap()
    }

    fn heartbeat_line(t_ms: u64, counter: u8, bad_crc: bool) -> String {
        let hb = messages::ControllerHeartbeat {
            mode: messages::RequestedMode::ArmValve,
            alive_counter: counter,
        };
        let frame = hb.to_frame().unwrap();
        let mut data = [0u8; 8];
        data.copy_from_slice(frame.data());
        if bad_crc {
            data[7] ^= 0x01;
        }
        let frame = firmware_bridge::CanFrame::new_extended(0x0CFF_6127, &data).unwrap();
        firmware_bridge::trace::format_line(
            1_700_000_000_000_000_000 + t_ms * 1_000_000,
            "vcan0",
            &frame,
            None,
        )
    }

    #[test]
    fn counts_alive_checksum_and_gap_errors() {
        // 20 Hz heartbeats: counter skips 3 (one alive error), one bad CRC, one 200 ms gap.
        let lines = vec![
            heartbeat_line(0, 0, false),
            heartbeat_line(50, 1, false),
            heartbeat_line(100, 2, false),
            heartbeat_line(150, 4, false),
            heartbeat_line(200, 5, true),
            heartbeat_line(400, 6, false),
        ];
        let r = report(&lines);
        let hb = &r.ids[0];
        assert_eq!(hb.message, "ControllerHeartbeat");
        assert_eq!(hb.count, 6);
        assert_eq!(hb.alive_errors, Some(1));
        assert_eq!(hb.checksum_errors, Some(1));
        assert_eq!(hb.gaps, 1);
        assert!((hb.first_gaps[0].length_ms - 200.0).abs() < 1e-6);
        assert!((hb.first_gaps[0].at_s - 0.4).abs() < 1e-9);
        assert!((hb.period_max_ms.unwrap() - 200.0).abs() < 1e-6);
        assert_eq!(hb.nominal_hz, Some(20.0));
    }

    #[test]
    fn unknown_and_error_frames_are_counted() {
        let lines = vec![
            "(1.000000) can0 18FEF100#0011223344556677".to_string(),
            "(1.001000) can0 20000040#0000000000000000".to_string(),
            "(1.002000) can0 123#00".to_string(),
        ];
        let r = report(&lines);
        assert_eq!(r.unknown_id_frames, 2);
        assert_eq!(r.error_frames, 1);
        assert_eq!(r.error_frame_kinds.get("BusOff"), Some(&1));
        assert_eq!(r.ids.len(), 2);
    }

    #[test]
    fn load_of_a_steady_stream_matches_busload() {
        let frame = firmware_bridge::CanFrame::new_extended(0x0CFF_5080, &[0x55; 8]).unwrap();
        let bits = f64::from(busload::stuffed_bits(&frame).unwrap());
        let lines: Vec<String> = (0..1000u64)
            .map(|n| firmware_bridge::trace::format_line(n * 1_000_000, "vcan0", &frame, None))
            .collect();
        let r = report(&lines);
        let expected = bits * 1000.0 / 500_000.0;
        assert!((r.bus_load.unwrap() - expected).abs() < 1e-9);
        assert!((r.peak_load.unwrap() - expected).abs() < 1e-9);
        let recs = lines.iter().map(|l| {
            let r = parse_line(l).unwrap();
            (r.timestamp_ns, r.frame)
        });
        let measured = busload::measured_load(recs, 500_000).unwrap();
        assert!((r.bus_load.unwrap() - measured).abs() < 1e-12);
    }
}
