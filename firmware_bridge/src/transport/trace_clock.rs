//! What stamps a trace's frames, and how a reader gets back the session's time from them.
//!
//! A bus on the wall clock (`run`) stamps frames in nanoseconds since the Unix epoch. A simulation's
//! [`super::VirtualClock`] starts at zero; its trace (`demo`) is written at [`VIRTUAL_EPOCH_UNIX_NS`]
//! plus the virtual time ([`TraceClock::trace_ns`]), in integer nanoseconds, so the trace stays
//! byte-for-byte the same for a seed and tools that expect wall-clock stamps (can-utils `log2asc`,
//! python-can, Foxglove) read it as a date. A reader that relates trace times to the session's own
//! times (scans, per-dig records) goes through one [`TraceTimeBase`].

/// The epoch of virtual-clock traces: 2000-01-01T00:00:00Z, nanoseconds since the Unix epoch. A
/// `demo` trace's frame at virtual time `t` is stamped `VIRTUAL_EPOCH_UNIX_NS + t`.
pub const VIRTUAL_EPOCH_UNIX_NS: u64 = 946_684_800 * 1_000_000_000;

/// A trace of unknown clock whose first frame is within this of [`VIRTUAL_EPOCH_UNIX_NS`] is read as
/// virtual time since the epoch, ns (one day: a session's first frame comes within its first step).
const VIRTUAL_FIRST_FRAME_SPAN_NS: u64 = 86_400 * 1_000_000_000;

/// What stamped the frames of a trace (`trace_clock` in a session's `summary.json`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TraceClock {
    /// The kernel's receive timestamp of the socket (`SO_TIMESTAMPNS`, wall clock since the Unix
    /// epoch): the time the frame reached the host, not when the program got to read it.
    Kernel,
    /// The wall clock (since the Unix epoch) when the program read the frame: the socket delivered
    /// no kernel timestamp.
    WallAtRead,
    /// A simulation's virtual clock, written offset by [`VIRTUAL_EPOCH_UNIX_NS`] (`demo`;
    /// docs/demo-output.md).
    Virtual,
}

impl TraceClock {
    /// The name in `summary.json`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Kernel => "kernel",
            Self::WallAtRead => "wall_at_read",
            Self::Virtual => "virtual",
        }
    }

    /// The trace timestamp of a frame this clock stamped `clock_ns`: the virtual clock's time plus
    /// [`VIRTUAL_EPOCH_UNIX_NS`]; a wall-clock stamp as it is.
    pub fn trace_ns(self, clock_ns: u64) -> u64 {
        match self {
            Self::Virtual => VIRTUAL_EPOCH_UNIX_NS.saturating_add(clock_ns),
            Self::Kernel | Self::WallAtRead => clock_ns,
        }
    }
}

/// Session time from a trace's timestamps: the one place that knows how a trace's clock relates to
/// the session's (the time of its scans and per-dig records, zero at the session start).
///
/// The origin follows from the recorded clock (`summary.json`'s `trace_clock`) and the trace's first
/// frame:
///
/// - `virtual`: [`VIRTUAL_EPOCH_UNIX_NS`], exact; a first frame before the epoch is a trace written
///   before virtual traces carried it, stamped in session time itself (origin 0).
/// - `kernel`, `wall_at_read`: the first frame. The session clock of `run` starts with its loop,
///   just before its first frame, and runs at the time scale: session times from a wall-clock trace
///   are those of a real-time session, to within the first frame's delay.
/// - not recorded: a first frame before the epoch is session time (origin 0), one within a day after
///   the epoch virtual time since the epoch, any other the wall clock (origin the first frame).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TraceTimeBase {
    clock: Option<TraceClock>,
    origin_ns: Option<u64>,
}

impl TraceTimeBase {
    /// The time base of a trace stamped by `clock` (`None`: not recorded); its origin is fixed by
    /// the first timestamp converted.
    pub fn new(clock: Option<TraceClock>) -> Self {
        Self {
            clock,
            origin_ns: None,
        }
    }

    /// The clock this base was made for.
    pub fn clock(&self) -> Option<TraceClock> {
        self.clock
    }

    /// The trace timestamp of session time zero, once a timestamp has been converted.
    pub fn origin_ns(&self) -> Option<u64> {
        self.origin_ns
    }

    /// Session time of the frame stamped `timestamp_ns`, ns; the first call fixes the origin, so call
    /// it with the trace's frames in order from the first. A frame stamped before the origin is at 0.
    pub fn session_ns(&mut self, timestamp_ns: u64) -> u64 {
        let origin = *self
            .origin_ns
            .get_or_insert_with(|| origin_ns(self.clock, timestamp_ns));
        timestamp_ns.saturating_sub(origin)
    }

    /// [`Self::session_ns`] in seconds.
    pub fn session_s(&mut self, timestamp_ns: u64) -> f64 {
        self.session_ns(timestamp_ns) as f64 * 1e-9
    }
}

/// The trace timestamp of session time zero for a trace stamped by `clock` whose first frame is
/// stamped `first_ns` ([`TraceTimeBase`]).
fn origin_ns(clock: Option<TraceClock>, first_ns: u64) -> u64 {
    let before_epoch = first_ns < VIRTUAL_EPOCH_UNIX_NS;
    match clock {
        Some(TraceClock::Virtual) if before_epoch => 0,
        Some(TraceClock::Virtual) => VIRTUAL_EPOCH_UNIX_NS,
        Some(TraceClock::Kernel | TraceClock::WallAtRead) => first_ns,
        None if before_epoch => 0,
        None if first_ns - VIRTUAL_EPOCH_UNIX_NS < VIRTUAL_FIRST_FRAME_SPAN_NS => {
            VIRTUAL_EPOCH_UNIX_NS
        }
        None => first_ns,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 2000-01-01T00:00:00Z: 30 years of 365 days and the 7 leap days of 1972..=1996.
    #[test]
    fn the_epoch_is_the_first_second_of_2000() {
        let days: u64 = 30 * 365 + 7;
        assert_eq!(VIRTUAL_EPOCH_UNIX_NS, days * 86_400 * 1_000_000_000);
    }

    #[test]
    fn virtual_stamps_are_the_epoch_plus_virtual_time_exactly() {
        let t = 123_456_789_012;
        assert_eq!(TraceClock::Virtual.trace_ns(0), VIRTUAL_EPOCH_UNIX_NS);
        assert_eq!(
            TraceClock::Virtual.trace_ns(t),
            VIRTUAL_EPOCH_UNIX_NS + 123_456_789_012
        );
        assert_eq!(TraceClock::Virtual.trace_ns(u64::MAX), u64::MAX);
        assert_eq!(TraceClock::Kernel.trace_ns(t), t);
        assert_eq!(TraceClock::WallAtRead.trace_ns(t), t);
    }

    #[test]
    fn a_virtual_trace_gives_back_the_virtual_time_whatever_its_first_frame() {
        let mut base = TraceTimeBase::new(Some(TraceClock::Virtual));
        // The first frame comes after a few control steps, not at zero.
        let first = TraceClock::Virtual.trace_ns(30_000_000);
        assert_eq!(base.session_ns(first), 30_000_000);
        assert_eq!(base.origin_ns(), Some(VIRTUAL_EPOCH_UNIX_NS));
        let t = 456_789_123_456;
        assert_eq!(base.session_ns(TraceClock::Virtual.trace_ns(t)), t);
        assert!((base.session_s(TraceClock::Virtual.trace_ns(t)) - 456.789_123_456).abs() < 1e-12);
    }

    #[test]
    fn a_virtual_trace_written_before_the_epoch_is_session_time_itself() {
        for clock in [Some(TraceClock::Virtual), None] {
            let mut base = TraceTimeBase::new(clock);
            assert_eq!(base.session_ns(30_000_000), 30_000_000, "{clock:?}");
            assert_eq!(base.session_ns(5_000_000_000), 5_000_000_000, "{clock:?}");
        }
    }

    #[test]
    fn a_wall_clock_trace_starts_its_session_at_the_first_frame() {
        let first = 1_790_000_000_123_000_000;
        for clock in [Some(TraceClock::Kernel), Some(TraceClock::WallAtRead), None] {
            let mut base = TraceTimeBase::new(clock);
            assert_eq!(base.session_ns(first), 0, "{clock:?}");
            assert_eq!(base.session_ns(first + 2_500_000_000), 2_500_000_000);
            // A frame stamped before the first (a wall-clock step) does not go negative.
            assert_eq!(base.session_ns(first - 1), 0);
        }
    }

    #[test]
    fn an_unrecorded_clock_near_the_epoch_is_virtual() {
        let mut base = TraceTimeBase::new(None);
        assert_eq!(
            base.session_ns(TraceClock::Virtual.trace_ns(10_000_000)),
            10_000_000
        );
        let mut late = TraceTimeBase::new(None);
        let first = VIRTUAL_EPOCH_UNIX_NS + VIRTUAL_FIRST_FRAME_SPAN_NS;
        assert_eq!(late.session_ns(first), 0);
    }

    #[test]
    fn the_clock_names_are_those_of_summary_json() {
        for clock in [
            TraceClock::Kernel,
            TraceClock::WallAtRead,
            TraceClock::Virtual,
        ] {
            let json = serde_json::to_string(&clock).expect("serialise");
            assert_eq!(json, format!("\"{}\"", clock.name()));
        }
    }
}
