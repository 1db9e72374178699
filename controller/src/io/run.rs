//! The real-time loop: `excavator-ctl run` over SocketCAN (or any [`Bus`]).
//!
//! Tokio drives I/O and time only; the control itself is [`ControllerNode::step`]. One task
//! `select!`s between
//!
//! - the shutdown signal (Ctrl-C or SIGTERM, passed in as a future),
//! - a 10 ms interval tick: the frames received since the last tick go through `step`, and its output
//!   is sent in order, and systemd's watchdog is fed ([`crate::io::sd_notify`]: `READY=1`, `WATCHDOG=1`),
//! - receiving: frames are queued for the next tick; error frames (`transport::Error::Fault`) go to
//!   [`ControllerNode::on_bus_fault`] at once. A frame's session time is its arrival: the time it
//!   was read less the time it waited in the socket since the kernel stamped it ([`MAX_RX_WAIT_S`]),
//!   so a loop that reads late does not make old sensor data look fresh.
//!
//! - with `--scan-addr`, the results of the range-scan task ([`crate::io::scan_client`]): after a tick in
//!   which the work cycle asked for a scan ([`ControllerNode::take_scan_request`]) the loop asks the
//!   task, which never blocks the loop; a terrain map goes to [`ControllerNode::provide_terrain`], a
//!   failure is logged with its reason and Autodig digs on its plain angle rules.
//!
//! A [`LoopMonitor`] checks the loop rate once per second (steps, the longest gap between ticks) and the
//! receive load. Under a receive overload (more than [`OVERLOAD_FRAMES_PER_S`] frames/s, or frames
//! dropped from the inbox) it logs a verdict, `loop rate kept` or `safe state`, so an overload never
//! passes silently; when the loop rate is lost during an overload it stops motion itself
//! ([`BusFault::Overflow`], fault code 9 in `ControllerStatus`).
//!
//! Whatever ends the loop (the signal, the end of the plan, an I/O error), the last frames sent are
//! [`ControllerNode::shutdown`]'s: neutral commands for all six valves and a `Disarm` heartbeat. The
//! caller closes the trace recorder afterwards so the buffered tail reaches the file.

use std::future::Future;
use std::time::Duration;

use anyhow::Context as _;
use firmware_bridge::transport::{self, Bus, BusFault, TimeScale, TimestampedFrame};
use tokio::time::MissedTickBehavior;

use crate::io::operator::OperatorPort;
use crate::io::scan_client::ScanClientConfig;
#[cfg(doc)]
use crate::io::scan_client::ScanService;
use crate::session::driver::{PlanOutcome, ScanSource, SessionDriver, SessionEvent};
use crate::step::node::ControllerNode;

/// Frames queued between two ticks before further ones are dropped (a full 10 ms of the bus at
/// 500 kbit/s is under 40 frames).
pub const MAX_INBOX: usize = 1024;
/// The loop monitor's window, s.
pub const MONITOR_WINDOW_S: f64 = 1.0;
/// Received frames per second above which the bus counts as overloaded: over three times the full
/// schedule of docs/protocol.md (1190 frames/s).
pub const OVERLOAD_FRAMES_PER_S: f64 = 4000.0;
/// ... or frames per second that are not the gateway's (ignored or rejected) above this: foreign
/// traffic near the rate of the whole schedule. On the machine's bus there is none; a flooding node
/// counts here even when the receiving host is too slow to take 4000 frames/s (measured in the TCG
/// VM: 1500-9000 frames/s of `cangen -g 0` reached the controller).
pub const OVERLOAD_FOREIGN_PER_S: f64 = 1000.0;
/// The loop rate counts as kept while a window has at least this fraction of its steps ...
pub const MIN_STEP_FRACTION: f64 = 0.8;
/// ... and no gap between two ticks longer than this, s (the gateway's watchdog is 0.1 s; scheduling
/// jitter in a TCG VM reaches 0.03 s).
pub const MAX_TICK_GAP_S: f64 = 0.08;

/// Why the loop ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StopReason {
    /// The shutdown signal.
    Signal,
    /// The plan is complete.
    Finished,
}

/// Counters of one run.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LoopStats {
    /// Control steps run.
    pub steps: u64,
    /// Frames sent.
    pub sent: u64,
    /// Frames received.
    pub received: u64,
    /// Frames dropped because the inbox was full.
    pub dropped: u64,
    /// Ticks that ran late (more than one period after the previous one).
    pub late_ticks: u64,
    /// Longest gap between two ticks, microseconds.
    pub max_tick_gap_us: u64,
    /// Monitor windows with a receive overload in which the loop kept its rate.
    pub overload_rate_kept: u64,
    /// Monitor windows with a receive overload that ended in (or found) a safe state.
    pub overload_safe_state: u64,
    /// Range scans turned into terrain maps.
    pub scans_ok: u64,
    /// Range scans that failed (the dig then used the plain angle rules).
    pub scans_failed: u64,
}

/// One [`MONITOR_WINDOW_S`] window of the loop monitor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoadReport {
    /// Length of the window, s.
    pub window_s: f64,
    /// Control steps per second.
    pub steps_per_s: f64,
    /// Longest gap between two ticks, s.
    pub max_gap_s: f64,
    /// Received frames per second.
    pub frames_per_s: f64,
    /// Received frames per second that were not the gateway's (ignored or rejected by the node).
    pub foreign_per_s: f64,
    /// Frames dropped because the inbox was full.
    pub dropped: u64,
}

impl LoadReport {
    /// More than [`OVERLOAD_FRAMES_PER_S`] received, more than [`OVERLOAD_FOREIGN_PER_S`] of them
    /// foreign, or frames dropped.
    pub fn overloaded(&self) -> bool {
        self.frames_per_s > OVERLOAD_FRAMES_PER_S
            || self.foreign_per_s > OVERLOAD_FOREIGN_PER_S
            || self.dropped > 0
    }

    /// At least [`MIN_STEP_FRACTION`] of the steps, and no gap over [`MAX_TICK_GAP_S`].
    pub fn rate_kept(&self, period: Duration) -> bool {
        let expected = 1.0 / period.as_secs_f64();
        self.steps_per_s >= MIN_STEP_FRACTION * expected && self.max_gap_s <= MAX_TICK_GAP_S
    }
}

/// Counts steps, tick gaps, received and dropped frames per window (pure; the loop feeds it with the
/// bus clock).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoopMonitor {
    start_s: Option<f64>,
    last_tick_s: Option<f64>,
    steps: u64,
    received: u64,
    foreign: u64,
    dropped: u64,
    max_gap_s: f64,
}

impl Default for LoopMonitor {
    fn default() -> Self {
        Self::new()
    }
}

impl LoopMonitor {
    /// A monitor whose first window starts at the first tick.
    pub fn new() -> Self {
        Self {
            start_s: None,
            last_tick_s: None,
            steps: 0,
            received: 0,
            foreign: 0,
            dropped: 0,
            max_gap_s: 0.0,
        }
    }

    /// A frame was received.
    pub fn on_received(&mut self) {
        self.received += 1;
    }

    /// `n` received frames were not the gateway's (counted by the node as ignored or rejected).
    pub fn on_foreign(&mut self, n: u64) {
        self.foreign += n;
    }

    /// A frame was dropped (inbox full).
    pub fn on_dropped(&mut self) {
        self.dropped += 1;
    }

    /// A tick at `now_s`; returns the report of the window it closes, if any.
    pub fn on_tick(&mut self, now_s: f64) -> Option<LoadReport> {
        if let Some(last) = self.last_tick_s {
            self.max_gap_s = self.max_gap_s.max(now_s - last);
        }
        self.last_tick_s = Some(now_s);
        self.steps += 1;
        let start = *self.start_s.get_or_insert(now_s);
        let window_s = now_s - start;
        if window_s < MONITOR_WINDOW_S {
            return None;
        }
        // The closing tick belongs to the next window too (as its first).
        let report = LoadReport {
            window_s,
            steps_per_s: (self.steps - 1) as f64 / window_s,
            max_gap_s: self.max_gap_s,
            frames_per_s: self.received as f64 / window_s,
            foreign_per_s: self.foreign as f64 / window_s,
            dropped: self.dropped,
        };
        *self = Self {
            start_s: Some(now_s),
            last_tick_s: Some(now_s),
            steps: 1,
            ..Self::new()
        };
        Some(report)
    }
}

/// Sends `frames`; a full transmit queue is reported to the node as a bus fault (the bus is likely
/// off), any other error ends the loop.
async fn send_all<B: Bus>(
    bus: &B,
    node: &mut ControllerNode,
    frames: &[firmware_bridge::CanFrame],
    stats: &mut LoopStats,
    now_s: f64,
) -> anyhow::Result<()> {
    for f in frames {
        match bus.send(*f).await {
            Ok(()) => stats.sent += 1,
            Err(transport::Error::TxQueueFull { .. }) => {
                node.on_bus_fault(now_s, transport::BusFault::TxTimeout);
            }
            Err(e) => {
                return Err(e).with_context(|| format!("sending on {}", bus.interface()));
            }
        }
    }
    Ok(())
}

/// The scan client for `node`'s cycle: `addr`, the cycle's grid, and the cycle's `scan_timeout_s`
/// (a later answer would no longer be used).
pub fn scan_client_config(node: &ControllerNode, addr: &str) -> ScanClientConfig {
    let cycle = node.cycle().config();
    ScanClientConfig {
        addr: addr.to_owned(),
        timeout: Duration::from_secs_f64(cycle.scan_timeout_s.clamp(0.01, 3600.0)),
        request: firmware_bridge::scan::ScanRequest::default(),
        grid: cycle.scan_grid,
    }
}

/// Runs `node` on `bus` until `shutdown` resolves, the plan finishes or an I/O error occurs; then sends
/// the shutdown frames (neutral valves, disarm). Without a session driver (nobody answers scan
/// requests or plans); see [`run_session_loop`].
///
/// # Errors
/// A receive or send error of the bus (after the shutdown frames were attempted).
pub async fn run_loop<B: Bus>(
    bus: &B,
    node: &mut ControllerNode,
    period: Duration,
    shutdown: impl Future<Output = ()>,
) -> anyhow::Result<(StopReason, LoopStats)> {
    run_session_loop(
        bus,
        node,
        period,
        TimeScale::REAL_TIME,
        shutdown,
        None,
        None,
    )
    .await
}

/// What is called after every control step with the step's session events (the lab writes the
/// session folder from them). An error ends the loop.
pub type StepObserver<'a> =
    dyn FnMut(&ControllerNode, &SessionDriver, &[SessionEvent]) -> anyhow::Result<()> + 'a;

/// The session around the node in [`run_session_loop`]: the driver (planning detached, module
/// docs), its scan source and the observer of its events.
pub struct LoopSession<'a> {
    /// The session driver.
    pub driver: &'a mut SessionDriver,
    /// Where its scans come from ([`ScanService`] over the network).
    pub scans: &'a mut dyn ScanSource,
    /// Called after every step.
    pub observer: &'a mut StepObserver<'a>,
}

impl std::fmt::Debug for LoopSession<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LoopSession")
            .field("driver", &self.driver)
            .finish_non_exhaustive()
    }
}

/// Logs the monitor's verdict on an overloaded window and stops motion when the loop rate is lost.
fn judge_load(
    report: &LoadReport,
    period: Duration,
    node: &mut ControllerNode,
    now_s: f64,
    stats: &mut LoopStats,
) {
    let rate_kept = report.rate_kept(period);
    if !report.overloaded() {
        if !rate_kept {
            tracing::warn!(
                steps_per_s = report.steps_per_s,
                max_gap_ms = report.max_gap_s * 1e3,
                "control loop late (no bus overload)"
            );
        }
        return;
    }
    if !rate_kept && node.safety().motion().is_some() {
        node.on_bus_fault(now_s, BusFault::Overflow);
    }
    let motion = match (node.safety().motion(), node.fault()) {
        (Some(mode), _) => format!("moving ({mode:?} mode)"),
        (None, Some(fault)) => format!("stopped: {fault}"),
        (None, None) => "stopped (not armed)".to_owned(),
    };
    let verdict = if rate_kept {
        stats.overload_rate_kept += 1;
        "loop rate kept"
    } else {
        stats.overload_safe_state += 1;
        "safe state"
    };
    tracing::warn!(
        verdict,
        frames_per_s = report.frames_per_s.round(),
        foreign_per_s = report.foreign_per_s.round(),
        dropped = report.dropped,
        steps_per_s = report.steps_per_s,
        max_gap_ms = report.max_gap_s * 1e3,
        %motion,
        "bus overload{}",
        if rate_kept { "" } else { ": loop rate lost, valves neutral" }
    );
}

/// A planning step running on tokio's blocking pool.
type PlanTask = tokio::task::JoinHandle<PlanOutcome>;

/// The outcome of the planning step in flight, or never without one (cancel-safe).
async fn planned(task: &mut Option<PlanTask>) -> Result<PlanOutcome, tokio::task::JoinError> {
    match task {
        Some(t) => t.await,
        None => std::future::pending().await,
    }
}

/// [`run_loop`] with a session driver: after every step the driver answers the work cycle's scan
/// requests from its scan source and, when the cycle waits for an action, stages a planning step,
/// which runs on tokio's blocking pool (the planner takes up to ~160 ms; the cycle holds in Idle
/// meanwhile) and whose action is pushed when it is done. Session time runs `time_scale` times as
/// fast as the monotonic clock: the tick is `period / time_scale` of wall time and the node steps at
/// the scaled time (the simulator must run at the same scale).
///
/// With an `operator` port ([`crate::io::operator`]) the operator's requests are applied before each
/// step (never waiting for them).
///
/// # Errors
/// A receive or send error of the bus, a session error or an observer's error (after the shutdown
/// frames were attempted).
pub async fn run_session_loop<B: Bus>(
    bus: &B,
    node: &mut ControllerNode,
    period: Duration,
    time_scale: TimeScale,
    shutdown: impl Future<Output = ()>,
    mut session: Option<LoopSession<'_>>,
    mut operator: Option<&mut OperatorPort>,
) -> anyhow::Result<(StopReason, LoopStats)> {
    let mut stats = LoopStats::default();
    let mut monitor = LoopMonitor::new();
    let mut foreign_seen = 0_u64;
    let wall_period = period.div_f64(time_scale.get());
    let mut interval = tokio::time::interval(wall_period);
    interval.set_missed_tick_behavior(MissedTickBehavior::Skip);
    let mut inbox: Vec<TimestampedFrame> = Vec::with_capacity(MAX_INBOX);
    let mut last_tick: Option<tokio::time::Instant> = None;
    let mut last_report_s = f64::NEG_INFINITY;
    let clock = SessionClock::start(time_scale);
    let mut plan_task: Option<PlanTask> = None;
    let mut notifier = crate::io::sd_notify::LoopNotifier::from_env();
    tokio::pin!(shutdown);
    let result: anyhow::Result<StopReason> = loop {
        tokio::select! {
            biased;
            () = &mut shutdown => break Ok(StopReason::Signal),
            tick = interval.tick() => {
                if let Some(t) = last_tick {
                    let gap = tick.duration_since(t);
                    if gap > wall_period + wall_period / 2 {
                        stats.late_ticks += 1;
                    }
                    stats.max_tick_gap_us =
                        stats.max_tick_gap_us.max(u64::try_from(gap.as_micros()).unwrap_or(u64::MAX));
                }
                last_tick = Some(tick);
                notifier.on_tick(tick.into_std());
                let now = clock.now_s();
                if let Some(report) = monitor.on_tick(now) {
                    judge_load(&report, period, node, now, &mut stats);
                }
                if let Some(op) = operator.as_mut() {
                    op.serve(node, now);
                }
                let out = node.step(now, &inbox);
                inbox.clear();
                let counters = node.counters();
                let foreign = counters.ignored + counters.faulty;
                monitor.on_foreign(foreign.saturating_sub(foreign_seen));
                foreign_seen = foreign;
                stats.steps += 1;
                if let Err(e) = send_all(bus, node, &out, &mut stats, now).await {
                    break Err(e);
                }
                match session.as_mut() {
                    Some(s) => {
                        let events = match s.driver.after_step(node, &mut *s.scans) {
                            Ok(events) => events.to_vec(),
                            Err(e) => break Err(anyhow::Error::new(e).context("session")),
                        };
                        for e in &events {
                            if let SessionEvent::Scanned(_) = e {
                                stats.scans_ok += 1;
                            }
                        }
                        if let Err(e) = (s.observer)(node, s.driver, &events) {
                            break Err(e);
                        }
                        if let Some(job) = s.driver.take_plan_job() {
                            plan_task = Some(tokio::task::spawn_blocking(move || job.run()));
                        }
                    }
                    None => {
                        if node.take_scan_request() {
                            tracing::warn!(
                                "the work cycle asked for a range scan but no scan service is \
                                 configured (--scan-addr): plain angle rules"
                            );
                        }
                    }
                }
                if now - last_report_s >= 1.0 {
                    last_report_s = now;
                    let s = node.status();
                    tracing::info!(
                        phase = ?s.phase,
                        stage = ?s.stage,
                        digs = s.dig_index,
                        safety = ?s.safety,
                        gateway = ?node.state().gateway.map(|g| g.mode),
                        planning = plan_task.is_some(),
                        "status"
                    );
                }
                if node.finished() {
                    break Ok(StopReason::Finished);
                }
            }
            received = bus.recv() => match received {
                Ok(tf) => {
                    stats.received += 1;
                    monitor.on_received();
                    tracing::trace!(frame = ?tf.frame, "received");
                    if inbox.len() < MAX_INBOX {
                        // The node ages sensor data and times faults against the step's `now`, so a
                        // frame carries the session clock's time of its arrival, not the bus's (wall)
                        // clock; the trace keeps the bus's timestamp.
                        inbox.push(TimestampedFrame {
                            timestamp_ns: clock.arrival_ns(bus.now_ns(), tf.timestamp_ns),
                            frame: tf.frame,
                        });
                    } else {
                        stats.dropped += 1;
                        monitor.on_dropped();
                    }
                }
                Err(transport::Error::Fault(fault)) => node.on_bus_fault(clock.now_s(), fault),
                Err(e) => {
                    break Err(anyhow::Error::new(e).context(format!("receiving on {}", bus.interface())));
                }
            },
            outcome = planned(&mut plan_task) => {
                plan_task = None;
                let Some(s) = session.as_mut() else { continue };
                let finished = outcome
                    .context("the planning task failed")
                    .and_then(|o| s.driver.finish_plan(node, o).context("session"));
                if let Err(e) = finished {
                    break Err(e);
                }
            }
        }
    };
    let out = node.shutdown(clock.now_s());
    for f in &out {
        if let Err(e) = bus.send(*f).await {
            tracing::error!(error = %e, "could not send a shutdown frame");
        }
    }
    stats.sent += out.len() as u64;
    // A planning step still out holds the session: bring it back (its action is not run).
    if let (Some(task), Some(s)) = (plan_task, session.as_mut())
        && let Ok(outcome) = task.await
    {
        s.driver.return_session(outcome);
    }
    result.map(|r| (r, stats))
}

/// Session time: the monotonic clock since the loop started, times the time scale, s.
#[derive(Debug, Clone, Copy)]
struct SessionClock {
    start: tokio::time::Instant,
    scale: f64,
}

impl SessionClock {
    fn start(scale: TimeScale) -> Self {
        Self {
            start: tokio::time::Instant::now(),
            scale: scale.get(),
        }
    }

    fn now_s(&self) -> f64 {
        self.start.elapsed().as_secs_f64() * self.scale
    }

    /// [`Self::now_s`] in nanoseconds (a frame's timestamp).
    fn now_ns(&self) -> u64 {
        // Saturating float-to-int cast; session time is non-negative and far below 584 years.
        (self.now_s() * 1e9) as u64
    }

    /// The session time at which a frame stamped `stamp_ns` by the bus arrived, read when the bus
    /// clock showed `bus_now_ns` ([`arrival_ns`]).
    fn arrival_ns(&self, bus_now_ns: u64, stamp_ns: u64) -> u64 {
        arrival_ns(self.now_ns(), self.scale, bus_now_ns, stamp_ns)
    }
}

/// Longest wait in the socket credited to a frame, s: a kernel timestamp further in the past than
/// this (or in the future) is a wall-clock step between the stamp and the read, not a wait. (A loop
/// that really reads this late has missed its period many times over, which its rate check faults.)
pub const MAX_RX_WAIT_S: f64 = 0.25;

/// The session time (ns) at which a frame arrived: `session_now_ns` less the time it waited between
/// the bus's stamp (`stamp_ns`, the kernel's receive time where the socket gives one) and its read
/// (`bus_now_ns`, the bus clock read then), in session time at `scale`. A wait that cannot be trusted
/// (the stamp after the read, or more than [`MAX_RX_WAIT_S`] before it: the wall clock stepped
/// between them) is discarded and the frame arrives at its read on the monotonic clock, so a step
/// neither makes a frame younger than its read nor ages it (a false stale sensor).
fn arrival_ns(session_now_ns: u64, scale: f64, bus_now_ns: u64, stamp_ns: u64) -> u64 {
    let Some(wait_ns) = bus_now_ns.checked_sub(stamp_ns) else {
        return session_now_ns;
    };
    let wait_s = wait_ns as f64 * 1e-9;
    if wait_s > MAX_RX_WAIT_S {
        return session_now_ns;
    }
    // Saturating float-to-int cast of a wait of at most MAX_RX_WAIT_S times the scale.
    session_now_ns.saturating_sub((wait_s * scale * 1e9) as u64)
}

/// Ctrl-C or SIGTERM (systemd's stop signal).
pub async fn shutdown_signal() {
    #[cfg(unix)]
    {
        use tokio::signal::unix::{SignalKind, signal};
        match signal(SignalKind::terminate()) {
            Ok(mut term) => {
                tokio::select! {
                    _ = tokio::signal::ctrl_c() => {}
                    _ = term.recv() => {}
                }
            }
            Err(_) => {
                let _ = tokio::signal::ctrl_c().await;
            }
        }
    }
    #[cfg(not(unix))]
    {
        let _ = tokio::signal::ctrl_c().await;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use firmware_bridge::dbc::CONTROL_PERIOD;

    fn window(steps_per_s: f64, max_gap_s: f64, frames_per_s: f64, dropped: u64) -> LoadReport {
        LoadReport {
            window_s: 1.0,
            steps_per_s,
            max_gap_s,
            frames_per_s,
            foreign_per_s: 0.0,
            dropped,
        }
    }

    #[test]
    fn monitor_reports_steps_gaps_and_load_per_window() {
        let mut m = LoopMonitor::new();
        let mut reports = Vec::new();
        let mut t = 0.0;
        for k in 0..250 {
            // One 60 ms stall in the first window.
            t += if k == 50 { 0.06 } else { 0.01 };
            for _ in 0..12 {
                m.on_received();
            }
            if let Some(r) = m.on_tick(t) {
                reports.push(r);
            }
        }
        assert_eq!(reports.len(), 2, "{reports:?}");
        let first = reports[0];
        assert!((first.max_gap_s - 0.06).abs() < 1e-9, "{first:?}");
        assert!(
            first.steps_per_s > 90.0 && first.steps_per_s <= 100.0,
            "{first:?}"
        );
        assert!(first.frames_per_s > 1000.0 && first.frames_per_s < 1300.0);
        assert!(!first.overloaded());
        assert!(first.rate_kept(CONTROL_PERIOD));
        assert!((reports[1].max_gap_s - 0.01).abs() < 1e-9);
    }

    #[test]
    fn a_frame_arrives_when_the_kernel_stamped_it_within_bounds() {
        const NOW_NS: u64 = 50_000_000_000;
        const BUS_NOW_NS: u64 = 1_700_000_000_000_000_000;
        // Waited 20 ms in the socket: 20 ms older, 40 ms of session time at 2x.
        assert_eq!(
            arrival_ns(NOW_NS, 1.0, BUS_NOW_NS, BUS_NOW_NS - 20_000_000),
            NOW_NS - 20_000_000
        );
        assert_eq!(
            arrival_ns(NOW_NS, 2.0, BUS_NOW_NS, BUS_NOW_NS - 20_000_000),
            NOW_NS - 40_000_000
        );
        // Stamped when read: no wait.
        assert_eq!(arrival_ns(NOW_NS, 1.0, BUS_NOW_NS, BUS_NOW_NS), NOW_NS);
        // The wall clock stepped back between stamp and read: never younger than the read.
        assert_eq!(
            arrival_ns(NOW_NS, 1.0, BUS_NOW_NS, BUS_NOW_NS + 3_600_000_000_000),
            NOW_NS
        );
        // ... or forward by an hour: the wait is discarded, it arrived when read.
        assert_eq!(
            arrival_ns(NOW_NS, 1.0, BUS_NOW_NS + 3_600_000_000_000, BUS_NOW_NS),
            NOW_NS
        );
        // Early in the session: not before its start.
        assert_eq!(
            arrival_ns(1_000, 1.0, BUS_NOW_NS, BUS_NOW_NS - 20_000_000),
            0
        );
    }

    /// A sensor frame every 10 ms, read 2 ms after the kernel stamped it, by a loop whose bus
    /// (wall) clock steps by `step_ns` between the stamp and the read of frame 50: the age of each
    /// frame at its read, ns.
    fn ages_across_a_wall_clock_step(step_ns: i64) -> Vec<u64> {
        const START_WALL_NS: i64 = 1_700_000_000_000_000_000;
        const PERIOD_NS: u64 = 10_000_000;
        const WAIT_NS: i64 = 2_000_000;
        let mut offset_ns = 0_i64;
        (0..100_u64)
            .map(|i| {
                let session_read_ns = 1_000_000_000 + i * PERIOD_NS;
                let stamp = START_WALL_NS + (session_read_ns as i64 - WAIT_NS) + offset_ns;
                if i == 50 {
                    offset_ns += step_ns;
                }
                let read = START_WALL_NS + session_read_ns as i64 + offset_ns;
                let arrival = arrival_ns(session_read_ns, 1.0, read as u64, stamp as u64);
                session_read_ns - arrival
            })
            .collect()
    }

    #[test]
    fn a_wall_clock_step_between_stamp_and_read_gives_no_false_stale_sensor() {
        // Forward and back, by more than the stale bound and by an hour.
        for step_ns in [
            300_000_000,
            -300_000_000,
            3_600_000_000_000,
            -3_600_000_000_000,
        ] {
            let ages = ages_across_a_wall_clock_step(step_ns);
            for (i, age) in ages.iter().enumerate() {
                // The stepped frame arrives at its read; every other one 2 ms before it. The old
                // clamp aged the forward-stepped frame by 250 ms: a false StaleSensor.
                let expected = if i == 50 { 0 } else { 2_000_000 };
                assert_eq!(*age, expected, "step {step_ns} ns, frame {i}");
            }
        }
    }

    #[test]
    fn overload_and_rate_verdicts() {
        assert!(window(100.0, 0.012, 50_000.0, 0).overloaded());
        assert!(window(100.0, 0.012, 1200.0, 3).overloaded());
        assert!(!window(100.0, 0.012, 1200.0, 0).overloaded());
        // A flood the host is too slow to receive at 4000 frames/s is still one: most of it foreign.
        let slow_flood = LoadReport {
            foreign_per_s: 1500.0,
            ..window(40.0, 0.09, 2700.0, 0)
        };
        assert!(slow_flood.overloaded() && !slow_flood.rate_kept(CONTROL_PERIOD));
        assert!(window(99.0, 0.03, 0.0, 0).rate_kept(CONTROL_PERIOD));
        assert!(!window(60.0, 0.03, 0.0, 0).rate_kept(CONTROL_PERIOD));
        assert!(!window(99.0, 0.09, 0.0, 0).rate_kept(CONTROL_PERIOD));
    }
}
