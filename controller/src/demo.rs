//! `excavator-ctl demo`: the embedded default. The simulator (`vcan_sim::embedded`) runs in-process on
//! an in-process CAN bus in virtual time, the [`ControllerNode`] runs a full autonomous session against
//! it (a fixed action plan until the dig planner lands: digs across swing angles, a cleanup, a track
//! back, repeated until `--digs`), and the session is written to `--out DIR` (docs/demo-output.md):
//!
//! - `trace.log`: `candump -L` of every frame on the bus (firmware_bridge's `Recorder`), flushed as the
//!   session runs and closed at the end and on Ctrl-C;
//! - `scans/scan_NNNN.json`: the range scans the controller used (docs/scan-protocol.md format);
//! - `summary.json`, `summary.md`: per dig weight, time, energy, swept volume (thesis 6.1) and totals;
//! - `trajectories.svg`, `terrain_before.svg`, `terrain_after.svg`, `dig_stats.svg` ([`crate::plots`]).
//!
//! One thread alternates the simulator (10 ms, ten 1 kHz physics steps) and the controller step, as in
//! the closed-loop tests; the run is deterministic for a seed.

use std::io::IsTerminal as _;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::Context as _;
use clap::Args;
use firmware_bridge::trace::{Direction, Recorder};
use firmware_bridge::transport::{InProcessBus, VirtualClock};
use planner::autodig::AutodigMaps;
use planner::cleanup::CleanupPlan;
use serde::{Deserialize, Serialize};
use vcan_sim::SimConfig;
use vcan_sim::embedded::EmbeddedMachine;
use vcan_sim::sensors::ScanRequest;

use crate::cycle::{Action, ActionKind, Phase, StartPose};
use crate::node::{ControllerConfig, ControllerNode};

/// The control period of the session, s.
pub const PERIOD_S: f64 = 0.01;
/// Flush the trace every this many control steps (5 s of virtual time), so the recorder's queue never
/// fills however fast virtual time runs.
const FLUSH_EVERY_STEPS: u64 = 500;
/// Virtual-time budget per dig, s: a session that takes longer stops (a stuck plan).
const SIM_BUDGET_PER_DIG_S: f64 = 120.0;

/// Arguments of `excavator-ctl demo`.
#[derive(Debug, Clone, Args)]
pub struct DemoArgs {
    /// Number of digs (dig and cleanup actions) in the session.
    #[arg(long, default_value_t = 10, value_name = "N")]
    pub digs: u32,
    /// Seed of the simulator (sensor noise, random boulders); default: the bench file's.
    #[arg(long, value_name = "N")]
    pub seed: Option<u64>,
    /// Machine file (default: the built-in config/machine.toml).
    #[arg(long, value_name = "FILE")]
    pub machine: Option<PathBuf>,
    /// Bench scenario file (default: the built-in config/bench.toml).
    #[arg(long, value_name = "FILE")]
    pub bench: Option<PathBuf>,
    /// A hidden effect of the simulator, NAME=VALUE (repeatable; `excavator-sim --list-effects`).
    #[arg(long = "effect", value_name = "NAME=VALUE")]
    pub effects: Vec<String>,
    /// Output folder.
    #[arg(long, default_value = "out/demo", value_name = "DIR")]
    pub out: PathBuf,
    /// Controller config (TOML, docs/controller.md); its plan replaces the demo plan.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Autodig maps (default: the built-in config/autodig_maps.toml).
    #[arg(long, value_name = "FILE")]
    pub maps: Option<PathBuf>,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
}

impl DemoArgs {
    /// The defaults of the command line with `out` as the output folder.
    pub fn new(out: PathBuf) -> Self {
        Self {
            digs: 10,
            seed: None,
            machine: None,
            bench: None,
            effects: Vec::new(),
            out,
            config: None,
            maps: None,
            quiet: true,
        }
    }
}

/// The demo plan: five digs across the bench (swing 0, +-10, +-20 degrees), a cleanup of the face's
/// toe, and a track back of 1.3 m (the thesis's typical distance, 6.2), repeated.
pub fn demo_plan() -> Vec<Action> {
    let dig = |swing_deg: f64| Action::Dig {
        swing_rad: swing_deg.to_radians(),
        start: StartPose::Tip {
            x_m: 7.5,
            z_m: 2.4,
            bucket_abs_rad: (-55.0_f64).to_radians(),
        },
    };
    vec![
        dig(0.0),
        dig(10.0),
        dig(-10.0),
        dig(20.0),
        dig(-20.0),
        Action::Cleanup {
            swing_rad: 0.0,
            start: StartPose::Tip {
                x_m: 4.6,
                z_m: 2.2,
                bucket_abs_rad: (-150.0_f64).to_radians(),
            },
            plan: CleanupPlan {
                start_radius_m: 4.6,
                min_radius_m: 3.2,
            },
        },
        Action::TrackBack { distance_m: 1.3 },
    ]
}

/// A point of a tip trajectory in the digging plane (base frame), m.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TipPoint {
    /// Distance from the swing axis, m.
    pub x_m: f64,
    /// Height above the ground plane, m.
    pub z_m: f64,
}

/// One dig (or cleanup) of the session, as written to `summary.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DigRecord {
    /// Dig number, from 0.
    pub index: u32,
    /// `dig` or `cleanup`.
    pub action: ActionKind,
    /// Swing angle of the digging plane, degrees.
    pub swing_deg: f64,
    /// The start pose of the action (tip pose or joints; degrees).
    pub start_pose: Option<StartPose>,
    /// Weight of the material from the static estimate after Capture, N (thesis 6.1).
    pub weight_n: Option<f64>,
    /// The simulator's true payload at the end of the dig, kg (for comparison with `weight_n`).
    pub true_payload_kg: f64,
    /// From the start of Boom-Down (or of the cleanup) to the end of Capture, s.
    pub time_s: f64,
    /// Time the tip was below the pre-dig terrain, s.
    pub ground_contact_time_s: f64,
    /// Integral of |cylinder force x displacement|, kJ (thesis 6.1).
    pub energy_kj: f64,
    /// Volume swept over the cutting edge (3.2), m^3.
    pub swept_volume_m3: f64,
    /// Why Autodig ended (`Debug` of the planner's end reason).
    pub end_reason: Option<String>,
    /// Whether the perception enhancements were active.
    pub perception: bool,
    /// The tip trajectory during the dig, base frame.
    #[serde(skip)]
    pub trajectory: Vec<TipPoint>,
    /// The true terrain along the digging plane before the dig, `(r, z)` in the base frame.
    #[serde(skip)]
    pub section: Vec<TipPoint>,
}

/// Totals of the session.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Totals {
    /// Digs completed (dig and cleanup actions).
    pub digs: usize,
    /// Dig actions.
    pub dig_actions: usize,
    /// Cleanup actions.
    pub cleanup_actions: usize,
    /// Track-back actions started.
    pub track_backs: usize,
    /// Sum of the weights, N.
    pub weight_n: f64,
    /// Mean weight per dig, N.
    pub mean_weight_n: f64,
    /// Mean time per dig, s.
    pub mean_time_s: f64,
    /// Mean energy per dig, kJ.
    pub mean_energy_kj: f64,
    /// Sum of the energies, kJ.
    pub energy_kj: f64,
    /// Sum of the swept volumes, m^3.
    pub swept_volume_m3: f64,
    /// Range scans taken.
    pub scans: usize,
    /// Virtual time of the session, s.
    pub sim_time_s: f64,
    /// Wall time of the session, s.
    pub wall_time_s: f64,
    /// Frames written to the trace.
    pub trace_frames: u64,
    /// Frames the trace recorder dropped (0 expected).
    pub trace_dropped: u64,
    /// Whether the plan finished (false: stopped by Ctrl-C or the time budget).
    pub finished: bool,
    /// The last fault of the safety layer, if any (`Display` text).
    pub last_fault: Option<String>,
}

/// What a session produced (`summary.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DemoSummary {
    /// The simulator's seed.
    pub seed: u64,
    /// The hidden effects given on the command line.
    pub effects: Vec<String>,
    /// Per dig.
    pub digs: Vec<DigRecord>,
    /// Totals.
    pub totals: Totals,
}

/// Runs `excavator-ctl demo`: the session on a blocking thread, Ctrl-C stops it cleanly (neutral
/// valves, a disarmed gateway, the trace flushed and closed, the outputs written).
///
/// # Errors
/// Bad arguments or files, simulator or controller construction errors, I/O errors writing the outputs.
pub async fn run(args: DemoArgs) -> anyhow::Result<()> {
    let stop = Arc::new(AtomicBool::new(false));
    let stop_on_signal = Arc::clone(&stop);
    let signal = tokio::spawn(async move {
        if tokio::signal::ctrl_c().await.is_ok() {
            stop_on_signal.store(true, Ordering::SeqCst);
        }
    });
    let session_stop = Arc::clone(&stop);
    let summary = tokio::task::spawn_blocking(move || run_session(&args, &session_stop))
        .await
        .context("demo session thread")??;
    signal.abort();
    print!("{}", summary_markdown(&summary));
    Ok(())
}

/// Builds the simulator and the controller of a session.
///
/// # Errors
/// File, simulator and controller construction errors.
pub fn setup(args: &DemoArgs) -> anyhow::Result<(SimConfig, ControllerConfig, AutodigMaps)> {
    let effects: Vec<&str> = args.effects.iter().map(String::as_str).collect();
    let sim = SimConfig::load(
        args.machine.as_deref(),
        args.bench.as_deref(),
        args.seed,
        &effects,
    )
    .context("simulator configuration")?;
    let mut config = match &args.config {
        Some(p) => {
            let text = std::fs::read_to_string(p)
                .with_context(|| format!("reading the controller config {}", p.display()))?;
            ControllerConfig::from_toml_str(&text)
                .with_context(|| format!("controller config {}", p.display()))?
        }
        None => {
            let mut c = ControllerConfig::default();
            c.cycle.actions = demo_plan();
            c
        }
    };
    config.cycle.repeat = true;
    config.cycle.max_digs = Some(args.digs);
    let maps = match &args.maps {
        Some(p) => {
            let text = std::fs::read_to_string(p)
                .with_context(|| format!("reading the Autodig maps {}", p.display()))?;
            AutodigMaps::from_toml_str(&text)
                .with_context(|| format!("Autodig maps {}", p.display()))?
        }
        None => AutodigMaps::builtin().context("built-in Autodig maps")?,
    };
    Ok((sim, config, maps))
}

/// The scan for the next dig: the default fan, turned toward the action's digging plane (the scan is
/// requested where the last dump left the machine; the sensor turns with the swing).
pub fn scan_request(node: &ControllerNode) -> ScanRequest {
    let mut request = ScanRequest::default();
    let target = match node.action() {
        Some(Action::Dig { swing_rad, .. } | Action::Cleanup { swing_rad, .. }) => *swing_rad,
        _ => return request,
    };
    let offset = planner::kinematics::wrap_angle(target - node.state().swing_rad);
    if offset.is_finite() {
        request.azimuth_min_rad += offset;
        request.azimuth_max_rad += offset;
    }
    request
}

/// The true terrain along the digging plane (base frame `(r, z)`, r from 1 to 12 m).
fn true_section(machine: &EmbeddedMachine, swing_rad: f64) -> Vec<TipPoint> {
    let plant = machine.plant();
    let pose = plant.pose();
    (0..=220)
        .filter_map(|k| {
            let r = 1.0 + 0.05 * f64::from(k);
            let [x, y, _] = pose.world_from_base(swing_rad, r, 0.0);
            plant
                .world
                .terrain
                .height_at(x, y)
                .ok()
                .map(|z| TipPoint { x_m: r, z_m: z })
        })
        .collect()
}

/// Runs one session and writes its outputs into `args.out`. Stops early when `stop` is set.
///
/// # Errors
/// As [`setup`]; I/O errors creating the folder or writing the outputs; bus errors.
pub fn run_session(args: &DemoArgs, stop: &AtomicBool) -> anyhow::Result<DemoSummary> {
    let wall = std::time::Instant::now();
    let (sim, config, maps) = setup(args)?;
    let out = &args.out;
    let scans_dir = out.join("scans");
    std::fs::create_dir_all(&scans_dir)
        .with_context(|| format!("creating {}", scans_dir.display()))?;
    let plan = config.cycle.actions.clone();
    let clock = VirtualClock::new();
    let bus = InProcessBus::with_virtual_clock("vcan0", clock.clone());
    let ctl = bus.attach();
    let mut machine = EmbeddedMachine::new(
        sim.build().context("building the simulator")?,
        bus.attach(),
        Some(clock.clone()),
    );
    let mut node = ControllerNode::new(&sim.machine, maps, config).context("controller")?;
    let trace_path = out.join("trace.log");
    let recorder = Recorder::create(&trace_path, "vcan0")
        .with_context(|| format!("creating {}", trace_path.display()))?;
    let terrain_before = machine.plant().world.terrain.clone();

    let progress = progress_bar(args);
    let mut records: Vec<DigRecord> = Vec::new();
    let mut current: Option<DigRecord> = None;
    let mut scans = 0usize;
    let mut track_backs = 0usize;
    let mut last_phase = node.cycle().phase();
    let mut inbox = Vec::new();
    let mut steps: u64 = 0;
    let budget_s = SIM_BUDGET_PER_DIG_S * f64::from(args.digs.max(1));
    let mut result: anyhow::Result<()> = Ok(());
    while !node.finished() && clock.now_s() < budget_s && !stop.load(Ordering::Relaxed) {
        machine.advance(PERIOD_S);
        inbox.clear();
        while let Some(f) = ctl.try_recv() {
            recorder.record(f.timestamp_ns, Direction::Receive, &f.frame);
            inbox.push(f);
        }
        let now = clock.now_s();
        let frames = node.step(now, &inbox);
        for f in &frames {
            recorder.record(clock.now_ns(), Direction::Transmit, f);
            if let Err(e) = ctl.send(*f) {
                result = Err(anyhow::anyhow!("in-process bus: {e}"));
            }
        }
        if result.is_err() {
            break;
        }
        if node.take_scan_request() {
            let scan = machine.scan(&scan_request(&node));
            let path = scans_dir.join(format!("scan_{scans:04}.json"));
            std::fs::write(&path, serde_json::to_vec(&scan)?)
                .with_context(|| format!("writing {}", path.display()))?;
            scans += 1;
            match node.cycle().config().scan_grid.terrain(&scan.points) {
                Ok(grid) => node.provide_terrain(grid),
                Err(e) => tracing::warn!(error = %e, "scan not usable"),
            }
        }
        let phase = node.cycle().phase();
        if phase != last_phase {
            if matches!(phase, Phase::Autodig | Phase::Cleanup) && current.is_none() {
                let action = node.action().copied();
                let swing_rad = node.state().swing_rad;
                current = Some(DigRecord {
                    index: u32::try_from(records.len()).unwrap_or(u32::MAX),
                    action: action.map_or(ActionKind::Dig, |a| a.kind()),
                    swing_deg: swing_rad.to_degrees(),
                    start_pose: match action {
                        Some(Action::Dig { start, .. } | Action::Cleanup { start, .. }) => {
                            Some(start)
                        }
                        _ => None,
                    },
                    weight_n: None,
                    true_payload_kg: 0.0,
                    time_s: 0.0,
                    ground_contact_time_s: 0.0,
                    energy_kj: 0.0,
                    swept_volume_m3: 0.0,
                    end_reason: None,
                    perception: false,
                    trajectory: Vec::new(),
                    section: true_section(&machine, swing_rad),
                });
            }
            if phase == Phase::Weigh
                && let Some(c) = &mut current
            {
                c.true_payload_kg = machine.plant().true_state().payload_kg;
            }
            if phase == Phase::TrackBack {
                track_backs += 1;
            }
            last_phase = phase;
        }
        if matches!(phase, Phase::Autodig | Phase::Cleanup)
            && let Some(c) = &mut current
        {
            let tip = node.state().tip;
            c.trajectory.push(TipPoint {
                x_m: tip.x_m,
                z_m: tip.z_m,
            });
        }
        let stats = node.statistics();
        if stats.len() > records.len()
            && let Some(mut c) = current.take()
            && let Some(d) = stats.get(records.len())
        {
            c.index = d.index;
            c.action = d.action;
            c.swing_deg = d.swing_rad.to_degrees();
            c.weight_n = d.weight_n;
            c.time_s = d.time_s;
            c.ground_contact_time_s = d.ground_contact_time_s;
            c.energy_kj = d.energy_kj();
            c.swept_volume_m3 = d.swept_volume_m3;
            c.end_reason = d.end_reason.map(|r| format!("{r:?}"));
            c.perception = d.perception;
            records.push(c);
            if let Some(p) = &progress {
                p.set_position(records.len() as u64);
            }
        }
        steps += 1;
        if steps.is_multiple_of(FLUSH_EVERY_STEPS)
            && let Err(e) = recorder.flush()
        {
            result = Err(anyhow::anyhow!("writing the trace: {e}"));
            break;
        }
    }
    // Whatever stopped the loop: neutral valves and a Disarm heartbeat, then let the gateway act.
    let now = clock.now_s();
    for f in &node.shutdown(now) {
        recorder.record(clock.now_ns(), Direction::Transmit, f);
        let _ = ctl.send(*f);
    }
    machine.advance(2.0 * PERIOD_S);
    while let Some(f) = ctl.try_recv() {
        recorder.record(f.timestamp_ns, Direction::Receive, &f.frame);
    }
    let trace = recorder.close();
    if let Some(p) = &progress {
        p.finish_and_clear();
    }
    result?;
    let trace = trace.with_context(|| format!("closing {}", trace_path.display()))?;

    let n = records.len();
    let mean = |f: &dyn Fn(&DigRecord) -> f64| {
        if n == 0 {
            0.0
        } else {
            records.iter().map(f).sum::<f64>() / n as f64
        }
    };
    let totals = Totals {
        digs: n,
        dig_actions: records
            .iter()
            .filter(|r| r.action == ActionKind::Dig)
            .count(),
        cleanup_actions: records
            .iter()
            .filter(|r| r.action == ActionKind::Cleanup)
            .count(),
        track_backs,
        weight_n: records.iter().filter_map(|r| r.weight_n).sum(),
        mean_weight_n: mean(&|r| r.weight_n.unwrap_or(0.0)),
        mean_time_s: mean(&|r| r.time_s),
        mean_energy_kj: mean(&|r| r.energy_kj),
        energy_kj: records.iter().map(|r| r.energy_kj).sum(),
        swept_volume_m3: records.iter().map(|r| r.swept_volume_m3).sum(),
        scans,
        sim_time_s: clock.now_s(),
        wall_time_s: wall.elapsed().as_secs_f64(),
        trace_frames: trace.recorded,
        trace_dropped: trace.dropped,
        finished: node.finished(),
        last_fault: node.last_fault().map(|f| f.to_string()),
    };
    let summary = DemoSummary {
        seed: sim.scenario.seed,
        effects: args.effects.clone(),
        digs: records,
        totals,
    };
    write_outputs(
        out,
        &summary,
        &terrain_before,
        &machine.plant().world.terrain,
        &plan,
    )?;
    Ok(summary)
}

fn progress_bar(args: &DemoArgs) -> Option<indicatif::ProgressBar> {
    if args.quiet || !std::io::stdout().is_terminal() {
        return None;
    }
    let bar = indicatif::ProgressBar::new(u64::from(args.digs));
    if let Ok(style) = indicatif::ProgressStyle::with_template(
        "{spinner} {elapsed_precise} [{bar:30}] {pos}/{len} digs",
    ) {
        bar.set_style(style);
    }
    bar.enable_steady_tick(std::time::Duration::from_millis(200));
    Some(bar)
}

fn write_outputs(
    out: &Path,
    summary: &DemoSummary,
    before: &planner::terrain::TerrainGrid,
    after: &planner::terrain::TerrainGrid,
    plan: &[Action],
) -> anyhow::Result<()> {
    let write = |name: &str, bytes: &[u8]| -> anyhow::Result<()> {
        let p = out.join(name);
        std::fs::write(&p, bytes).with_context(|| format!("writing {}", p.display()))
    };
    write("summary.json", &serde_json::to_vec_pretty(summary)?)?;
    write("summary.md", summary_markdown(summary).as_bytes())?;
    write("plan.json", &serde_json::to_vec_pretty(plan)?)?;
    write(
        "trajectories.svg",
        crate::plots::trajectories_svg(&summary.digs)?.as_bytes(),
    )?;
    write(
        "terrain_before.svg",
        crate::plots::terrain_svg(before, "terrain before the session (elevation, m)")?.as_bytes(),
    )?;
    write(
        "terrain_after.svg",
        crate::plots::terrain_svg(after, "terrain after the session (elevation, m)")?.as_bytes(),
    )?;
    write(
        "dig_stats.svg",
        crate::plots::dig_stats_svg(&summary.digs)?.as_bytes(),
    )?;
    Ok(())
}

/// The readable summary table (`summary.md`, also printed at the end of `demo`).
pub fn summary_markdown(s: &DemoSummary) -> String {
    use std::fmt::Write as _;
    let mut m = String::new();
    let t = &s.totals;
    // Writing into a String cannot fail.
    let _ = writeln!(
        m,
        "# excavator-ctl demo\n\nseed {}, effects [{}]; {} digs ({} dig, {} cleanup), {} track backs, {} scans; \
         {:.1} s simulated in {:.1} s wall{}\n",
        s.seed,
        s.effects.join(", "),
        t.digs,
        t.dig_actions,
        t.cleanup_actions,
        t.track_backs,
        t.scans,
        t.sim_time_s,
        t.wall_time_s,
        if t.finished { "" } else { " (stopped early)" }
    );
    let _ = writeln!(
        m,
        "| # | action | swing (deg) | weight (N) | true payload (kg) | time (s) | energy (kJ) | swept (m^3) | end |"
    );
    let _ = writeln!(m, "|---|---|---|---|---|---|---|---|---|");
    for d in &s.digs {
        let _ = writeln!(
            m,
            "| {} | {:?} | {:.0} | {} | {:.0} | {:.1} | {:.0} | {:.2} | {} |",
            d.index,
            d.action,
            d.swing_deg,
            d.weight_n.map_or("-".to_owned(), |w| format!("{w:.0}")),
            d.true_payload_kg,
            d.time_s,
            d.energy_kj,
            d.swept_volume_m3,
            d.end_reason.as_deref().unwrap_or("-")
        );
    }
    let _ = writeln!(
        m,
        "| mean | | | {:.0} | | {:.1} | {:.0} | | |\n\nThesis Table 3 (tests 1-3, per dig): weight 18917-22654 N, time 6.7-10.2 s, \
         energy 213-252 kJ; Table 4: digs 21201 N, 5.8 s, 212 kJ.",
        t.mean_weight_n, t.mean_time_s, t.mean_energy_kj
    );
    if let Some(f) = &t.last_fault {
        let _ = writeln!(m, "\nLast safety event: {f}.");
    }
    m
}
