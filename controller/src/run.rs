//! The real-time loop: `excavator-ctl run` over SocketCAN (or any [`Bus`]).
//!
//! Tokio drives I/O and time only; the control itself is [`ControllerNode::step`]. One task
//! `select!`s between
//!
//! - the shutdown signal (Ctrl-C or SIGTERM, passed in as a future),
//! - a 10 ms interval tick: the frames received since the last tick go through `step`, and its output
//!   is sent in order,
//! - receiving: frames are queued for the next tick; error frames (`transport::Error::Fault`) go to
//!   [`ControllerNode::on_bus_fault`] at once.
//!
//! Whatever ends the loop (the signal, the end of the plan, an I/O error), the last frames sent are
//! [`ControllerNode::shutdown`]'s: neutral commands for all six valves and a `Disarm` heartbeat. The
//! caller closes the trace recorder afterwards so the buffered tail reaches the file.

use std::future::Future;
use std::path::PathBuf;
use std::time::Duration;

use anyhow::Context as _;
use firmware_bridge::trace::Recorder;
use firmware_bridge::transport::{self, Bus, SocketCanBus, TimestampedFrame};
use planner::autodig::AutodigMaps;
use planner::machine::MachineConfig;
use tokio::time::MissedTickBehavior;

use crate::node::{ControllerConfig, ControllerNode};

/// The control period (100 Hz).
pub const CONTROL_PERIOD: Duration = Duration::from_millis(10);
/// Frames queued between two ticks before further ones are dropped (a full 10 ms of the bus at
/// 500 kbit/s is under 40 frames).
pub const MAX_INBOX: usize = 1024;

/// Options of `excavator-ctl run`.
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// CAN interface (`can0`, `vcan0`).
    pub iface: String,
    /// Decode and log, never transmit.
    pub listen_only: bool,
    /// Machine file (default: the built-in `config/machine.toml`).
    pub machine: Option<PathBuf>,
    /// Autodig maps (default: the built-in `config/autodig_maps.toml`).
    pub maps: Option<PathBuf>,
    /// Controller config (safety, cycle plan, Autodig, cleanup) as TOML.
    pub config: Option<PathBuf>,
    /// Record a candump log of everything sent and received.
    pub trace: Option<PathBuf>,
    /// Stop after this many digs.
    pub digs: Option<u32>,
    /// Address of the range-scan service.
    pub scan_addr: Option<String>,
}

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
}

/// Builds the node from the options' files.
///
/// # Errors
/// Unreadable or invalid files, or an inconsistent configuration.
pub fn build_node(opts: &RunOptions) -> anyhow::Result<ControllerNode> {
    let machine = match &opts.machine {
        Some(p) => MachineConfig::from_toml_file(p)
            .with_context(|| format!("machine file {}", p.display()))?,
        None => MachineConfig::default_machine().context("built-in machine")?,
    };
    let maps = match &opts.maps {
        Some(p) => {
            let text = std::fs::read_to_string(p)
                .with_context(|| format!("reading Autodig maps {}", p.display()))?;
            AutodigMaps::from_toml_str(&text)
                .with_context(|| format!("Autodig maps {}", p.display()))?
        }
        None => AutodigMaps::builtin().context("built-in Autodig maps")?,
    };
    let mut config = match &opts.config {
        Some(p) => {
            let text = std::fs::read_to_string(p)
                .with_context(|| format!("reading controller config {}", p.display()))?;
            ControllerConfig::from_toml_str(&text)
                .with_context(|| format!("controller config {}", p.display()))?
        }
        None => ControllerConfig::default(),
    };
    config.safety.listen_only |= opts.listen_only;
    if let Some(n) = opts.digs {
        config.cycle.max_digs = Some(n);
    }
    if opts.scan_addr.is_some() {
        // docs/scan-protocol.md has not landed; dig on the plain angle rules until it does.
        tracing::warn!(
            "--scan-addr: the scan protocol is not implemented yet; digging without scans"
        );
    }
    config.cycle.scan = false;
    ControllerNode::new(&machine, maps, config).context("controller configuration")
}

fn now_s<B: Bus>(bus: &B) -> f64 {
    bus.now_ns() as f64 * 1e-9
}

/// Sends `frames`; a full transmit queue is reported to the node as a bus fault (the bus is likely
/// off), any other error ends the loop.
async fn send_all<B: Bus>(
    bus: &B,
    node: &mut ControllerNode,
    frames: &[firmware_bridge::CanFrame],
    stats: &mut LoopStats,
) -> anyhow::Result<()> {
    for f in frames {
        match bus.send(*f).await {
            Ok(()) => stats.sent += 1,
            Err(transport::Error::TxQueueFull { .. }) => {
                node.on_bus_fault(now_s(bus), transport::BusFault::TxTimeout);
            }
            Err(e) => {
                return Err(e).with_context(|| format!("sending on {}", bus.interface()));
            }
        }
    }
    Ok(())
}

/// Runs `node` on `bus` until `shutdown` resolves, the plan finishes or an I/O error occurs; then sends
/// the shutdown frames (neutral valves, disarm).
///
/// # Errors
/// A receive or send error of the bus (after the shutdown frames were attempted).
pub async fn run_loop<B: Bus>(
    bus: &B,
    node: &mut ControllerNode,
    period: Duration,
    shutdown: impl Future<Output = ()>,
) -> anyhow::Result<(StopReason, LoopStats)> {
    let mut stats = LoopStats::default();
    let mut interval = tokio::time::interval(period);
    interval.set_missed_tick_behavior(MissedTickBehavior::Skip);
    let mut inbox: Vec<TimestampedFrame> = Vec::with_capacity(MAX_INBOX);
    let mut last_tick: Option<tokio::time::Instant> = None;
    let mut last_report_s = f64::NEG_INFINITY;
    tokio::pin!(shutdown);
    let result: anyhow::Result<StopReason> = loop {
        tokio::select! {
            biased;
            () = &mut shutdown => break Ok(StopReason::Signal),
            tick = interval.tick() => {
                if last_tick.is_some_and(|t| tick.duration_since(t) > period + period / 2) {
                    stats.late_ticks += 1;
                }
                last_tick = Some(tick);
                let now = now_s(bus);
                let out = node.step(now, &inbox);
                inbox.clear();
                stats.steps += 1;
                if let Err(e) = send_all(bus, node, &out, &mut stats).await {
                    break Err(e);
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
                    tracing::trace!(frame = ?tf.frame, "received");
                    if inbox.len() < MAX_INBOX {
                        inbox.push(tf);
                    } else {
                        stats.dropped += 1;
                    }
                }
                Err(transport::Error::Fault(fault)) => node.on_bus_fault(now_s(bus), fault),
                Err(e) => {
                    break Err(anyhow::Error::new(e).context(format!("receiving on {}", bus.interface())));
                }
            },
        }
    };
    let out = node.shutdown(now_s(bus));
    for f in &out {
        if let Err(e) = bus.send(*f).await {
            tracing::error!(error = %e, "could not send a shutdown frame");
        }
    }
    stats.sent += out.len() as u64;
    result.map(|r| (r, stats))
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

/// `excavator-ctl run`: opens the interface, runs the loop until Ctrl-C/SIGTERM or the end of the
/// plan, and closes the trace.
///
/// # Errors
/// Configuration, interface or bus errors, and trace file errors.
pub async fn run(opts: RunOptions) -> anyhow::Result<()> {
    let mut node = build_node(&opts)?;
    let mut bus = SocketCanBus::open(&opts.iface)
        .with_context(|| format!("opening CAN interface {}", opts.iface))?;
    let recorder = match &opts.trace {
        Some(p) => {
            let r = Recorder::create(p, &opts.iface)
                .with_context(|| format!("creating trace {}", p.display()))?;
            bus.set_recorder(r.clone());
            Some(r)
        }
        None => None,
    };
    tracing::info!(
        iface = %opts.iface,
        listen_only = node.safety().config().listen_only,
        "excavator-ctl running; Ctrl-C stops (valves neutral, disarm)"
    );
    let result = run_loop(&bus, &mut node, CONTROL_PERIOD, shutdown_signal()).await;
    if let Some(r) = recorder {
        let closed = r.close().context("closing the trace");
        if let Ok(stats) = &closed {
            tracing::info!(?stats, "trace closed");
        }
        closed?;
    }
    let (reason, stats) = result?;
    tracing::info!(?reason, ?stats, digs = node.statistics().len(), "stopped");
    for d in node.statistics() {
        tracing::info!(
            dig = d.index,
            action = ?d.action,
            weight_n = ?d.weight_n,
            time_s = d.time_s,
            energy_kj = d.energy_kj(),
            swept_m3 = d.swept_volume_m3,
            "dig"
        );
    }
    Ok(())
}
