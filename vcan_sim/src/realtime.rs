//! The simulator in real time on a SocketCAN interface (tokio), with the optional JSON-lines state log
//! and the range-sensor scan socket (docs/scan-protocol.md).
//!
//! Every sensor period of the gateway (10 ms of simulated time, the DBC's `JointAngles` cycle;
//! `10 ms / time_scale` of wall time; real time by default, faster with `--time-scale` when the
//! controller runs at the same scale) the loop steps the physics as many 1 ms steps as the elapsed
//! (scaled) monotonic time requires, sends the frames due, and handles received frames and scan
//! requests in between. Shutdown is passed in and `select!`ed on.
//!
//! A scan never holds the loop: the loop takes the sensor's pose and a copy of the terrain when the
//! request comes, the rays are cast on tokio's blocking pool (a scan is seconds of CPU in a TCG VM),
//! and the loop adds the range noise and answers when they are back. The reply's JSON is written on
//! the blocking pool too. A scan that held the loop would stop the sensor frames for as long, and the
//! controller would rightly stop the machine on stale data.
//!
//! After a late wake-up it catches up at most [`MAX_CATCH_UP_STEPS`] steps; when the host held the
//! simulator off for longer, simulated time slips behind wall time instead (counted in
//! [`RunSummary::overruns`] and [`RunSummary::slipped_s`]). A host stall holds the controller off too
//! (a loaded machine, a VM without enough CPU): replaying the whole stall in one burst would let the
//! gateway's watchdog see a heartbeat gap that no controller caused, and send frames that no real
//! machine would send. A stall of the controller alone still trips the watchdog, as on the machine.

use std::future::Future;
use std::io::Write;
use std::path::PathBuf;
use std::time::Duration;

use tokio::time::Instant;

use firmware_bridge::profile::Profile;
use firmware_bridge::transport::{Bus, ProfileBus, SocketCanBus, TimeScale};
use tokio::io::{AsyncBufReadExt, AsyncWriteExt, BufReader};
use tokio::net::TcpListener;
use tokio::sync::{mpsc, oneshot};

use crate::node::MachineNode;
use crate::plant::PHYSICS_DT_S;
use crate::sensors::{Scan, ScanCast, ScanRequest};
use crate::{Result, SimError};

/// Options of a real-time run.
#[derive(Debug, Clone, Default)]
pub struct RealtimeOptions {
    /// CAN interface (`vcan0`, `can0`).
    pub iface: String,
    /// JSON-lines log of the true state at every resolver sample (every 10 ms of simulated time, in
    /// catch-up steps too): the k-th `JointAngles` frame carries line k's sample.
    pub state_log: Option<PathBuf>,
    /// `HOST:PORT` for the scan socket (loopback TCP, JSON lines).
    pub scan_socket: Option<String>,
    /// Simulated seconds per wall second (the controller must run at the same scale).
    pub time_scale: TimeScale,
}

/// What a run did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RunSummary {
    /// Simulated time (s).
    pub simulated_s: f64,
    /// Frames received.
    pub frames_received: u64,
    /// Frames sent.
    pub frames_sent: u64,
    /// Send failures.
    pub send_errors: u64,
    /// Wake-ups later than [`MAX_CATCH_UP_STEPS`] physics steps, where simulated time slipped.
    pub overruns: u64,
    /// Wall time not simulated because of those overruns, s.
    pub slipped_s: f64,
    /// The longest late wake-up, s (wall time since the step that was due).
    pub max_lag_s: f64,
}

/// Physics steps (1 ms) caught up after a late wake-up at most: 30 ms, three loop periods, a third of
/// the gateway's 100 ms watchdog. Longer stalls slip simulated time (module docs).
pub const MAX_CATCH_UP_STEPS: u64 = 30;

/// How far the wire can run ahead of simulated time when a frame leaves: the catch-up
/// ([`MAX_CATCH_UP_STEPS`] physics steps) and one loop period of `loop_steps` steps, ns.
fn claim_lag_margin_ns(loop_steps: u64) -> i64 {
    let steps = i64::try_from(MAX_CATCH_UP_STEPS + loop_steps).unwrap_or(i64::MAX);
    steps.saturating_mul((PHYSICS_DT_S * 1e9).round() as i64)
}

type ScanJob = (ScanRequest, oneshot::Sender<Scan>);

/// Serves scan requests: one JSON object per line in, one JSON line out.
async fn serve_scans(listener: TcpListener, jobs: mpsc::Sender<ScanJob>) {
    loop {
        let Ok((stream, _)) = listener.accept().await else {
            continue;
        };
        let jobs = jobs.clone();
        tokio::spawn(async move {
            let (read, mut write) = stream.into_split();
            let mut lines = BufReader::new(read).lines();
            while let Ok(Some(line)) = lines.next_line().await {
                let reply = match serde_json::from_str::<ScanRequest>(&line) {
                    Ok(request) => {
                        let (tx, rx) = oneshot::channel();
                        if jobs.send((request, tx)).await.is_err() {
                            break;
                        }
                        match rx.await {
                            // About 10,000 points: off the runtime's one thread, which runs the loop.
                            Ok(scan) => tokio::task::spawn_blocking(move || {
                                serde_json::to_string(&scan)
                                    .unwrap_or_else(|e| error_json(&e.to_string()))
                            })
                            .await
                            .unwrap_or_else(|e| error_json(&e.to_string())),
                            Err(_) => break,
                        }
                    }
                    Err(e) => error_json(&format!("bad request: {e}")),
                };
                if write.write_all(reply.as_bytes()).await.is_err()
                    || write.write_all(b"\n").await.is_err()
                {
                    break;
                }
            }
        });
    }
}

fn error_json(message: &str) -> String {
    serde_json::json!({ "error": message }).to_string()
}

/// Runs the node on a SocketCAN interface until `shutdown` completes.
///
/// # Errors
/// [`SimError::Bus`] if the interface cannot be opened, [`SimError::Io`] for the state log or the
/// scan socket.
pub async fn run(
    node: MachineNode,
    options: RealtimeOptions,
    shutdown: impl Future<Output = ()>,
) -> Result<RunSummary> {
    let bus = SocketCanBus::open(&options.iface)
        .map_err(|e| SimError::Bus(format!("{}: {e}", options.iface)))?;
    run_on(&bus, node, options, shutdown).await
}

/// As [`run`], speaking `profile`'s wire protocol on the interface: the gateway sees the project's
/// messages, the bus (and any trace of it) carries the profile's (`docs/machine-profile.md`).
///
/// # Errors
/// As [`run`].
pub async fn run_with_profile(
    node: MachineNode,
    options: RealtimeOptions,
    profile: std::sync::Arc<Profile>,
    shutdown: impl Future<Output = ()>,
) -> Result<RunSummary> {
    let bus = SocketCanBus::open(&options.iface)
        .map_err(|e| SimError::Bus(format!("{}: {e}", options.iface)))?;
    let bus = ProfileBus::new(bus, profile);
    let summary = run_on(&bus, node, options, shutdown).await;
    bus.log_stats();
    summary
}

/// As [`run`] on any bus (`options.iface` unused): the in-process bus of the lab's tests.
///
/// # Errors
/// [`SimError::Io`] for the state log or the scan socket.
pub async fn run_on<B: Bus>(
    bus: &B,
    mut node: MachineNode,
    options: RealtimeOptions,
    shutdown: impl Future<Output = ()>,
) -> Result<RunSummary> {
    // A frame leaves at the wake-up that simulates its step, up to the catch-up plus one loop period
    // after that step's simulated time; the gateway stamps its address claim with the step's time, so
    // it holds the claim that much longer to keep 250 ms between the claim and its first other frame
    // on the wire.
    let loop_steps = node.schedule().sensor;
    node.set_claim_hold_margin(claim_lag_margin_ns(loop_steps));
    let mut log = match &options.state_log {
        Some(path) => Some(std::io::BufWriter::new(
            std::fs::File::create(path).map_err(|source| SimError::Io {
                context: format!("creating {}", path.display()),
                source,
            })?,
        )),
        None => None,
    };
    let (scan_tx, mut scan_rx) = mpsc::channel::<ScanJob>(8);
    if let Some(addr) = &options.scan_socket {
        let listener = TcpListener::bind(addr)
            .await
            .map_err(|source| SimError::Io {
                context: format!("binding the scan socket {addr}"),
                source,
            })?;
        tracing::info!(%addr, "scan socket listening");
        tokio::spawn(serve_scans(listener, scan_tx));
    } else {
        drop(scan_tx);
    }
    let mut summary = RunSummary::default();
    let scale = options.time_scale.get();
    let loop_period = Duration::from_secs_f64(loop_steps as f64 * PHYSICS_DT_S);
    let mut interval = tokio::time::interval(loop_period.div_f64(scale));
    // Rays cast on the blocking pool, back to the loop for their noise and the reply.
    let (cast_tx, mut cast_rx) = mpsc::unbounded_channel::<(ScanCast, oneshot::Sender<Scan>)>();
    interval.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    let start = Instant::now();
    let mut steps_done: u64 = 0;
    let mut slipped_steps: u64 = 0;
    let mut out = Vec::with_capacity(64);
    tokio::pin!(shutdown);
    loop {
        tokio::select! {
            _ = &mut shutdown => break,
            received = bus.recv() => match received {
                Ok(f) => {
                    summary.frames_received += 1;
                    node.on_frame(&f.frame);
                }
                Err(e) => tracing::warn!("CAN receive: {e}"),
            },
            Some((request, reply)) = scan_rx.recv() => {
                let pending = node.prepare_scan(&request);
                let cast_tx = cast_tx.clone();
                tokio::task::spawn_blocking(move || {
                    // The loop is gone when the send fails: nobody waits for the scan.
                    let _ = cast_tx.send((pending.cast(), reply));
                });
            }
            Some((cast, reply)) = cast_rx.recv() => {
                let _ = reply.send(node.finish_scan(cast));
            }
            _ = interval.tick() => {
                // Wall-clock physics steps due, minus the time slipped so far.
                let due = ((start.elapsed().as_secs_f64() * scale / PHYSICS_DT_S) as u64).saturating_sub(slipped_steps);
                let behind = due.saturating_sub(steps_done);
                summary.max_lag_s = summary.max_lag_s.max(behind as f64 * PHYSICS_DT_S);
                let n = behind.min(MAX_CATCH_UP_STEPS);
                if behind > MAX_CATCH_UP_STEPS {
                    let slip = behind - MAX_CATCH_UP_STEPS;
                    slipped_steps += slip;
                    summary.overruns += 1;
                    summary.slipped_s = slipped_steps as f64 * PHYSICS_DT_S;
                    if summary.overruns.is_power_of_two() {
                        tracing::warn!(
                            late_ms = behind,
                            overruns = summary.overruns,
                            slipped_s = summary.slipped_s,
                            "the host held the simulator off: simulated time slips behind wall time"
                        );
                    }
                }
                steps_done += n;
                out.clear();
                for _ in 0..n {
                    if let Some(log) = log.as_mut()
                        && node.samples_sensors_next()
                    {
                        write_state(log, &node)?;
                    }
                    node.step(&mut out);
                }
                for frame in out.drain(..) {
                    match bus.send(frame).await {
                        Ok(()) => summary.frames_sent += 1,
                        Err(_) => summary.send_errors += 1,
                    }
                }
            }
        }
    }
    if let Some(mut log) = log {
        log.flush().map_err(|source| SimError::Io {
            context: "flushing the state log".into(),
            source,
        })?;
    }
    summary.simulated_s = node.time_s();
    Ok(summary)
}

/// Writes the true state as one line of the state log.
fn write_state(log: &mut impl Write, node: &MachineNode) -> Result<()> {
    let line = serde_json::to_string(&node.plant().true_state()).map_err(|e| SimError::Io {
        context: "encoding the state log".into(),
        source: std::io::Error::other(e),
    })?;
    writeln!(log, "{line}").map_err(|source| SimError::Io {
        context: "writing the state log".into(),
        source,
    })
}
