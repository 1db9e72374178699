//! `excavator-ctl demo`: the embedded default. The simulator (`vcan_sim::embedded`) runs in-process on
//! an in-process CAN bus in virtual time, the [`ControllerNode`] runs a full autonomous session against
//! it, and the session is written to `--out DIR` (docs/demo-output.md). The action source is
//! `--strategy`:
//!
//! - `planned` (default; thesis 5.1, ch. 6): a [`PlannedSession`] keeps the terrain map current from
//!   the scans, plans (coarse + refined dig location, cleanup and tracking plans, Fig. 42) whenever
//!   the work cycle waits, estimates the soil and sets Autodig's hardness index online (5.2), on the
//!   extended-operation bench (`config/bench_extended.toml`: machine on the bench top, the face
//!   receding toward it, tracking back);
//! - `predefined` (6.2): fixed start joints (the median of the planner's), swing stepped across the
//!   regions, cleanups from the far reach, 1.3 m backups; same bench;
//! - `fixed`: the fixed demo plan (digs across swing angles, a cleanup, a track back, repeated) or the
//!   `--config` file's plan, on `config/bench.toml` ([`DemoArgs::fixed`] for library callers that
//!   want it; [`DemoArgs::defaults`] is the command line's default session).
//!
//! Outputs:
//!
//! - `trace.log`: `candump -L` of every frame on the bus (firmware_bridge's `Recorder`), stamped with
//!   the virtual time from the fixed epoch (`firmware_bridge::transport::VIRTUAL_EPOCH_UNIX_NS`),
//!   flushed as the session runs and closed at the end and on Ctrl-C;
//! - `scans/scan_NNNN.json`: the range scans the controller used (docs/scan-protocol.md format);
//! - `summary.json`, `summary.md`: per dig weight, time, energy, swept volume (thesis 6.1) and totals;
//! - `trajectories.svg`, `terrain_before.svg`, `terrain_after.svg`, `dig_stats.svg` ([`crate::plots`]);
//! - planned and predefined: `bench_after_NNN.svg` (Fig. 55), `dig_sequence.svg` (Fig. 56), and
//!   `soil_samples.json`: per dig the soil estimator's samples (`Gamma` and the tip force from the
//!   pressures, 4.3.4) for `excavator-ctl model soil-cv` ([`onboard::record::SoilSamplesFile`]).
//!
//! One thread alternates the simulator (10 ms, ten 1 kHz physics steps) and the controller step, as in
//! the closed-loop tests; the run is deterministic for a seed.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::Context as _;
use clap::Args;
use firmware_bridge::trace::{Direction, Recorder};
use firmware_bridge::transport::TraceClock;
use planner::autodig::AutodigMaps;
use planner::cleanup::CleanupPlan;
use vcan_sim::SimConfig;
use vcan_sim::embedded::EmbeddedMachine;

use planner::kinematics::JointAngles;
use planner::plan::PlannerConfig;
use planner::terrain::TerrainGrid;
use vcan_sim::scenario::{Scenario, SoilContactIntegration};

use controller::ControllerConfig;
use controller::session::driver::{NoObserver, SessionDriver, SessionEvent, SessionObserver};
use controller::session::planned::{PlannedSession, median_joints};
use controller::session::snapshot::Strategy;
use controller::step::cycle::{Action, ActionKind, StartPose};
use controller::step::node::ControllerNode;

pub use onboard::record::{BenchSnapshot, DigRecord, SessionRecords, TipPoint, Truth};
pub use onboard::setup::{
    EXTENDED_CARRY_BOOM_DEG, EXTENDED_CARRY_TIP_Z_M, EXTENDED_JOINT_TOLERANCE_RAD, load_profile,
};
pub use onboard::summary::{
    DemoStrategy, DemoSummary, FileRecord, PlanningStats, SessionEnd, SessionPlots, SessionStats,
    Totals, session_summary, summary_markdown, tables_markdown, trace_time_base,
    write_soil_samples,
};

pub use crate::harness::PERIOD_S;
use crate::harness::{Harness, SimScans};

/// The extended-operation bench (thesis ch. 6), the default bench of the planned and predefined
/// strategies.
pub use vcan_sim::scenario::EXTENDED_BENCH_TOML;

/// Control steps between updates of the progress line (0.5 s of session time).
const PROGRESS_EVERY_STEPS: u64 = 50;

/// Flush the trace every this many control steps (5 s of virtual time), so the recorder's queue never
/// fills however fast virtual time runs.
const FLUSH_EVERY_STEPS: u64 = 500;
/// Virtual-time budget per dig, s: a session that takes longer stops (a stuck plan).
const SIM_BUDGET_PER_DIG_S: f64 = 120.0;
/// What stamps a demo trace: the virtual clock, written from its fixed epoch.
const TRACE_CLOCK: TraceClock = TraceClock::Virtual;

/// Arguments of `excavator-ctl demo`.
#[derive(Debug, Clone, PartialEq, Args)]
pub struct DemoArgs {
    /// Number of digs (dig and cleanup actions) in the session.
    #[arg(long, default_value_t = 10, value_name = "N", value_parser = clap::value_parser!(u32).range(1..))]
    pub digs: u32,
    /// Seed of the simulator (sensor noise, random boulders); default: the bench file's.
    #[arg(long, value_name = "N")]
    pub seed: Option<u64>,
    /// Machine file (default: the built-in config/machine.toml): the controller's, and the
    /// simulated machine's unless `--plant-machine` is given.
    #[arg(long, value_name = "FILE")]
    pub machine: Option<PathBuf>,
    /// Machine file of the simulated machine only (the plant: bores, masses, relief, ... and its
    /// `[effects]` table); the controller keeps `--machine` (default: the built-in one). Makes
    /// "measured" sessions of a machine that differs from its file.
    #[arg(long, value_name = "FILE")]
    pub plant_machine: Option<PathBuf>,
    /// Bench scenario file (default: the built-in config/bench_extended.toml for the planned and
    /// predefined strategies, config/bench.toml for the fixed plan).
    #[arg(long, value_name = "FILE")]
    pub bench: Option<PathBuf>,
    /// A hidden effect of the simulator, NAME=VALUE (repeatable; see --list-effects).
    #[arg(long = "effect", value_name = "NAME=VALUE")]
    pub effects: Vec<String>,
    /// Print the simulator's hidden effects (name, unit, range, description) and exit: the
    /// catalogue of `excavator-sim --list-effects`.
    #[arg(long)]
    pub list_effects: bool,
    /// How the simulator integrates the soil's force (default: the bench file's `soil_contact`,
    /// `implicit` when absent; docs/simulator.md, "Soil contact integration").
    #[arg(long, value_enum, value_name = "HOW")]
    pub soil_contact: Option<SoilContact>,
    /// Output folder.
    #[arg(long, default_value = "out/demo", value_name = "DIR")]
    pub out: PathBuf,
    /// Controller config (TOML, docs/controller.md); its plan replaces the demo plan.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Autodig maps (default: the built-in config/autodig_maps.toml).
    #[arg(long, value_name = "FILE")]
    pub maps: Option<PathBuf>,
    /// No progress bar, no log below warnings (unless RUST_LOG asks), and no line saying where the
    /// files went.
    #[arg(long)]
    pub quiet: bool,
    /// Replace the session in `--out` (a folder holding another session is refused without it; a
    /// folder holding no session is never deleted).
    #[arg(long)]
    pub force: bool,
    /// The action source: the dig planner, the predefined sequence of 6.2, or the fixed plan.
    #[arg(long, value_enum, default_value_t = DemoStrategy::Planned)]
    pub strategy: DemoStrategy,
    /// Planner settings (default: the built-in config/planner.toml); the floor is the bench's.
    #[arg(long, value_name = "FILE")]
    pub planner: Option<PathBuf>,
    /// Hardness regression (default: the built-in config/hardness_regression.toml).
    #[arg(long, value_name = "FILE")]
    pub hardness: Option<PathBuf>,
    /// Predefined strategy: the `summary.json` of a planned run whose dig starts' median are the
    /// fixed start joints (6.2's "virtual expert"); default: the median of the planner's best digs
    /// over the regions of the first map.
    #[arg(long, value_name = "FILE")]
    pub predefined_from: Option<PathBuf>,
    /// Plot the bench after this many digs (Fig. 55; repeatable; the end of the session always).
    #[arg(long = "bench-after", value_name = "N", default_values_t = [12u32])]
    pub bench_after: Vec<u32>,
    /// Predefined strategy: plain Autodig (3.1, Dig ending on the fixed beta and Capture on the
    /// fixed gamma) instead of Autodig with the perception enhancements (3.2).
    #[arg(long)]
    pub predefined_plain: bool,
    /// Machine profile (TOML naming a gateway's DBC and the mapping, docs/machine-profile.md): the
    /// controller and the simulated gateway speak that gateway's messages, at its rates, on the
    /// in-process bus, and the trace records them. Default: the project's protocol (excavator.dbc).
    #[arg(long, value_name = "FILE")]
    pub profile: Option<PathBuf>,
    /// Predefined strategy: the fixed start joints (library callers; overrides `predefined_from`).
    #[arg(skip)]
    pub predefined_joints: Option<JointAngles>,
}

impl DemoArgs {
    /// `excavator-ctl demo`'s arguments with nothing given but `--out`: the session a user runs
    /// (the planned strategy on the extended-operation bench, 10 digs, the bench file's seed, the
    /// progress bar on). The values are clap's own defaults, parsed from that command line, so this
    /// cannot drift from the CLI; calibration, evaluation and every library caller that stands for
    /// a user's session start here and change only what they say.
    #[must_use]
    pub fn defaults(out: PathBuf) -> Self {
        /// `demo`'s options alone, as the CLI flattens them.
        #[derive(clap::Parser)]
        #[command(name = "demo")]
        struct Demo {
            #[command(flatten)]
            args: DemoArgs,
        }
        // No option is given, so only a broken default could fail to parse; `defaults_are_the_cli_s`
        // parses the same line.
        let mut args = <Demo as clap::Parser>::try_parse_from(["demo"])
            .expect("demo's defaults parse")
            .args;
        args.out = out;
        args
    }

    /// The fixed demo plan on config/bench.toml ([`demo_plan`], `--strategy fixed`), quiet: for
    /// tests and experiments that want the same short plan whatever the planner does. Not a user's
    /// session: that is [`Self::defaults`].
    #[must_use]
    pub fn fixed(out: PathBuf) -> Self {
        Self {
            strategy: DemoStrategy::Fixed,
            quiet: true,
            ..Self::defaults(out)
        }
    }
}

/// The demo plan: five digs across the bench (swing 0, +-10, +-20 degrees), a cleanup of the face's
/// toe, and a track back of 1.3 m (the thesis's typical distance, 6.2), repeated.
pub fn demo_plan() -> Vec<Action> {
    let dig = Action::bench_dig;
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

/// `--soil-contact`: [`vcan_sim::scenario::SoilContactIntegration`] on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum SoilContact {
    /// The force of each 5 ms contact update held until the next (plant version `held-1`).
    Held,
    /// The force as a function of the tip velocity at every 1 ms step, taken implicitly (the
    /// default plant).
    Implicit,
}

impl From<SoilContact> for SoilContactIntegration {
    fn from(c: SoilContact) -> Self {
        match c {
            SoilContact::Held => SoilContactIntegration::Held,
            SoilContact::Implicit => SoilContactIntegration::Implicit,
        }
    }
}

/// Runs `excavator-ctl demo`: the session on a blocking thread, Ctrl-C stops it cleanly (neutral
/// valves, a disarmed gateway, the trace flushed and closed, the outputs written).
///
/// # Errors
/// Bad arguments or files, simulator or controller construction errors, I/O errors writing the outputs.
pub async fn run(args: DemoArgs) -> anyhow::Result<()> {
    run_observed(args, Box::new(NoObserver)).await
}

/// As [`run`], with `observer` watching every control step (the live view).
///
/// # Errors
/// As [`run`].
pub async fn run_observed(
    args: DemoArgs,
    mut observer: Box<dyn SessionObserver + Send>,
) -> anyhow::Result<()> {
    if args.list_effects {
        print!("{}", vcan_sim::effects::registry_table());
        return Ok(());
    }
    onboard::folder::prepare(&args.out, args.force)?;
    let out = args.out.clone();
    let quiet = args.quiet;
    let stop = Arc::new(AtomicBool::new(false));
    let stop_on_signal = Arc::clone(&stop);
    let signal = tokio::spawn(async move {
        if tokio::signal::ctrl_c().await.is_ok() {
            stop_on_signal.store(true, Ordering::SeqCst);
        }
    });
    let session_stop = Arc::clone(&stop);
    let summary = tokio::task::spawn_blocking(move || {
        run_session_observed(&args, &session_stop, observer.as_mut())
    })
    .await
    .context("demo session thread")??;
    signal.abort();
    print!("{}", summary_markdown(&summary));
    if !quiet {
        eprintln!(
            "excavator-ctl demo: the session's files are in {}",
            out.display()
        );
    }
    Ok(())
}

/// Builds the simulator and the controller of a session. For the planned and predefined strategies
/// the plan starts empty (the session pushes the actions), the estimator starts at the scenario's
/// machine pose and scans are binned on the scenario's grid.
///
/// # Errors
/// File, simulator and controller construction errors.
pub fn setup(args: &DemoArgs) -> anyhow::Result<(SimConfig, ControllerConfig, AutodigMaps)> {
    let effects: Vec<&str> = args.effects.iter().map(String::as_str).collect();
    // With `--plant-machine` the simulator is built from it (its `[effects]` table included); the
    // controller's machine is `--machine`'s ([`controller_machine`]).
    let mut sim = SimConfig::load(
        args.plant_machine.as_deref().or(args.machine.as_deref()),
        args.bench.as_deref(),
        args.seed,
        &effects,
    )
    .with_context(|| match &args.plant_machine {
        Some(p) => format!("simulator configuration (--plant-machine {})", p.display()),
        None => "simulator configuration".to_owned(),
    })?;
    if args.plant_machine.is_some() {
        // The controller's file is checked before anything runs, as the plant's was.
        controller_machine(args, &sim)?;
    }
    if args.bench.is_none() && args.strategy != DemoStrategy::Fixed {
        let scenario =
            Scenario::from_toml_str_named(EXTENDED_BENCH_TOML, "config/bench_extended.toml")
                .context("built-in extended bench")?;
        sim.effects
            .merge(&scenario.effect_set().context("extended bench [effects]")?);
        // The command line's effects win over the bench file's.
        for e in &effects {
            sim.effects.apply_arg(e).context("--effect")?;
        }
        sim.scenario = scenario;
        if let Some(seed) = args.seed {
            sim.scenario.seed = seed;
        }
    }
    if let Some(c) = args.soil_contact {
        sim.scenario.soil_contact = c.into();
    }
    let site = sim.scenario.site();
    let mut config = onboard::setup::controller_config(
        args.strategy,
        args.config.as_deref(),
        &site,
        args.predefined_plain,
    )?;
    if args.strategy == DemoStrategy::Fixed {
        if args.config.is_none() {
            config.cycle.actions = demo_plan();
        }
        config.cycle.repeat = true;
    }
    config.cycle.max_digs = Some(args.digs);
    let maps = onboard::setup::maps(args.maps.as_deref())?;
    Ok((sim, config, maps))
}

/// The controller's machine of a session: the simulator's, unless the simulated machine has a file
/// of its own (`--plant-machine`); then `--machine` (or the built-in file), loaded and checked as
/// the simulator loads a machine file (its `[effects]` table, a simulator setting, is not the
/// controller's and is ignored).
///
/// # Errors
/// Reading or validating the file (errors name the file, line and field).
pub fn controller_machine(
    args: &DemoArgs,
    sim: &SimConfig,
) -> anyhow::Result<planner::machine::MachineConfig> {
    if args.plant_machine.is_none() {
        return Ok(sim.machine.clone());
    }
    let own = SimConfig::load::<&str>(args.machine.as_deref(), None, None, &[])
        .context("the controller's machine (--machine, or the built-in config/machine.toml)")?;
    Ok(own.machine)
}

/// The planner settings of a session: `--planner` or the built-in file, with the desired floor at
/// the bench's floor elevation (world z = base z: the machine stands on the ground plane).
///
/// # Errors
/// Reading or parsing the file.
pub fn planner_config(args: &DemoArgs, sim: &SimConfig) -> anyhow::Result<PlannerConfig> {
    onboard::setup::planner_config(args.planner.as_deref(), &sim.scenario.site())
}

/// The planned session of a run: the planner on the machine, a terrain map on the bench site's
/// work area, the hardness regression (`--hardness` or the built-in one).
///
/// # Errors
/// Files, planner construction.
pub fn build_session(
    args: &DemoArgs,
    sim: &SimConfig,
    strategy: Strategy,
) -> anyhow::Result<PlannedSession> {
    onboard::setup::planned_session(
        &controller_machine(args, sim)?,
        planner_config(args, sim)?,
        &sim.scenario.site(),
        strategy,
        args.hardness.as_deref(),
    )
}

/// The median start joints of the dig actions of a planned run's `summary.json` (6.2).
///
/// # Errors
/// Reading or parsing the file; no dig with joint angles in it.
pub fn predefined_start_from_summary(path: &Path) -> anyhow::Result<JointAngles> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let summary: DemoSummary =
        serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
    median_joints(&dig_starts(&summary.digs))
        .with_context(|| format!("{}: no dig start with joint angles", path.display()))
}

/// The start joints of the dig actions of a session (planned digs start from joints).
#[must_use]
pub fn dig_starts(digs: &[DigRecord]) -> Vec<JointAngles> {
    digs.iter()
        .filter(|d| d.action == ActionKind::Dig)
        .filter_map(|d| match d.start_pose {
            Some(StartPose::Joints {
                boom_rad,
                stick_rad,
                bucket_rad,
            }) => Some(JointAngles {
                boom_rad,
                stick_rad,
                bucket_rad,
            }),
            _ => None,
        })
        .collect()
}

/// The true terrain along the digging plane (base frame `(r, z)`, r from 1 to 12 m).
pub(crate) fn true_section(machine: &EmbeddedMachine, swing_rad: f64) -> Vec<TipPoint> {
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

/// The simulated world's truth of a dig's record: the embedded machine's terrain and payload.
pub struct SimTruth<'a>(pub &'a EmbeddedMachine);

impl Truth for SimTruth<'_> {
    fn section(&self, swing_rad: f64) -> Vec<TipPoint> {
        true_section(self.0, swing_rad)
    }

    fn payload_kg(&self) -> f64 {
        self.0.plant().true_state().payload_kg
    }
}

/// Runs one session and writes its outputs into `args.out`. Stops early when `stop` is set.
///
/// The virtual-time harness steps the machine and the controller; the controller's session driver
/// plans and follows the digs; this loop adds the simulator's truth to each dig's record.
///
/// # Errors
/// As [`setup`]; I/O errors creating the folder or writing the outputs; bus errors.
pub fn run_session(args: &DemoArgs, stop: &AtomicBool) -> anyhow::Result<DemoSummary> {
    run_session_observed(args, stop, &mut NoObserver)
}

/// As [`run_session`], with `observer` called after every control step and at the end.
///
/// # Errors
/// As [`run_session`].
pub fn run_session_observed(
    args: &DemoArgs,
    stop: &AtomicBool,
    observer: &mut dyn SessionObserver,
) -> anyhow::Result<DemoSummary> {
    let wall = std::time::Instant::now();
    let (sim, mut config, maps) = setup(args)?;
    let profile = load_profile(args.profile.as_deref())?;
    if let Some(p) = &profile {
        config.safety = config.safety.for_gateway(p.timing());
    }
    let out = &args.out;
    let scans_dir = out.join("scans");
    std::fs::create_dir_all(&scans_dir)
        .with_context(|| format!("creating {}", scans_dir.display()))?;
    let session = match args.strategy.session() {
        Some(st) => Some(build_session(args, &sim, st)?),
        None => None,
    };
    let mut predefined_joints = args.predefined_joints;
    if predefined_joints.is_none()
        && args.strategy == DemoStrategy::Predefined
        && let Some(p) = &args.predefined_from
    {
        predefined_joints = Some(predefined_start_from_summary(p)?);
    }
    let full_bucket_n = sim
        .scenario
        .site()
        .full_bucket_n(sim.machine.bucket.capacity_m3);
    // The harness builds the plant and a controller from `sim`; with `--plant-machine` the
    // controller is the one of its own machine file, started before the first step.
    let own_controller = match &args.plant_machine {
        Some(_) => Some(
            ControllerNode::new(
                &controller_machine(args, &sim)?,
                maps.clone(),
                config.clone(),
            )
            .context("controller")?,
        ),
        None => None,
    };
    let options = crate::harness::HarnessOptions {
        profile,
        ..Default::default()
    };
    let mut h = Harness::with_options(&sim, maps, config, &options).context("controller")?;
    if let Some(node) = own_controller {
        h.kill_controller();
        h.start_controller(node);
    }
    let mut driver = match h.node_mut() {
        Some(node) => SessionDriver::new(session, predefined_joints, node),
        None => anyhow::bail!("no controller"),
    };
    let trace_path = out.join("trace.log");
    let recorder = Recorder::create(&trace_path, "vcan0")
        .with_context(|| format!("creating {}", trace_path.display()))?;
    // Virtual time from the fixed epoch (docs/demo-output.md), exact in integer nanoseconds.
    let stamp = |virtual_ns| TRACE_CLOCK.trace_ns(virtual_ns);
    let terrain_before = h.machine.plant().world.terrain.clone();

    let progress = onboard::console::session_bar(Some(args.digs), args.quiet);
    let mut log = SessionRecords::new(scans_dir);
    let budget_s = SIM_BUDGET_PER_DIG_S * f64::from(args.digs.max(1));
    let mut result: anyhow::Result<()> = Ok(());
    let mut snapshots: Vec<BenchSnapshot> = Vec::new();
    // Operator commands in-process (the live view's page): applied between two steps, as `run`
    // applies those of its control socket before a step.
    let mut operator = controller::io::operator::OperatorPort::new();
    observer.operator_control(operator.sender());
    let finished = |h: &Harness| h.node().is_none_or(ControllerNode::finished);
    while !finished(&h) && h.time_s() < budget_s && !stop.load(Ordering::Relaxed) {
        if let Err(e) = h.step() {
            result = Err(anyhow::Error::new(e));
            break;
        }
        // The frames as they were on the bus: a profile's wire frames.
        for f in h.wire_inbox() {
            recorder.record(stamp(f.timestamp_ns), Direction::Receive, &f.frame);
        }
        for f in h.wire_sent() {
            recorder.record(stamp(h.clock.now_ns()), Direction::Transmit, f);
        }
        let time_s = h.time_s();
        let steps = h.steps();
        let Some((node, machine)) = h.parts_mut() else {
            break;
        };
        let events = driver
            .after_step(node, &mut SimScans::new(machine))?
            .to_vec();
        observer.after_step(time_s, node, driver.session(), &events);
        operator.serve(node, time_s);
        if steps.is_multiple_of(PROGRESS_EVERY_STEPS) {
            onboard::console::update(progress.as_ref(), log.records.len(), node, driver.backups());
        }
        for event in &events {
            if let SessionEvent::PhaseChanged { from, to } = event {
                let st = node.state();
                tracing::debug!(
                    time_s,
                    from = ?from,
                    to = ?to,
                    joints_deg = ?[
                        st.joints.boom_rad.to_degrees(),
                        st.joints.stick_rad.to_degrees(),
                        st.joints.bucket_rad.to_degrees(),
                    ],
                    tip = ?(st.tip.x_m, st.tip.z_m),
                    action = ?node.action(),
                    "demo phase"
                );
            }
            let finished = log.on_event(node, &driver, Some(&SimTruth(machine)), event)?;
            if finished
                && driver.session().is_some()
                && args.bench_after.contains(&(log.records.len() as u32))
            {
                let t = machine.plant().true_state();
                snapshots.push(BenchSnapshot {
                    digs: log.records.len(),
                    backups: driver.backups(),
                    terrain: machine.plant().world.terrain.clone(),
                    pose: t.pose,
                });
            }
        }
        if h.steps().is_multiple_of(FLUSH_EVERY_STEPS)
            && let Err(e) = recorder.flush()
        {
            result = Err(anyhow::anyhow!("writing the trace: {e}"));
            break;
        }
    }
    let session_over = driver.end_reason().map(str::to_owned);
    let track_backs = driver.track_backs();
    let backups_done = driver.backups();
    let plan_ms = driver.planning_ms().to_vec();
    let clock = h.clock.clone();
    let end = if stop.load(Ordering::Relaxed) {
        "stopped".to_owned()
    } else if let Some(why) = &session_over {
        why.clone()
    } else if finished(&h) {
        "dig count reached".to_owned()
    } else if clock.now_s() >= budget_s {
        "time budget".to_owned()
    } else {
        "error".to_owned()
    };
    observer.finished(clock.now_s(), &end);
    // Whatever stopped the loop: neutral valves and a Disarm heartbeat, then let the gateway act.
    let now = clock.now_s();
    let shutdown = h.node_mut().map(|n| n.shutdown(now));
    for f in shutdown.iter().flat_map(|o| o.iter()) {
        let _ = h.send_from_controller(std::slice::from_ref(f));
        for w in h.wire_sent() {
            recorder.record(stamp(clock.now_ns()), Direction::Transmit, w);
        }
    }
    h.machine.advance(2.0 * PERIOD_S);
    for f in h.drain_controller_inbox() {
        recorder.record(stamp(f.timestamp_ns), Direction::Receive, &f.frame);
    }
    let trace = recorder.close();
    for link in [h.profile_link(), h.machine.profile_link()]
        .into_iter()
        .flatten()
    {
        link.log_stats();
    }
    if let Some(p) = &progress {
        p.finish_and_clear();
    }
    result?;
    let trace = trace.with_context(|| format!("closing {}", trace_path.display()))?;
    let Some((node, machine)) = h.parts_mut() else {
        anyhow::bail!("the controller is gone");
    };
    let session = driver.session();
    let summary = session_summary(
        log.records,
        SessionEnd {
            command: "demo",
            strategy: args.strategy,
            bench: sim.scenario.name.clone(),
            seed: sim.scenario.seed,
            soil_contact: Some(soil_contact_name(sim.scenario.soil_contact).to_owned()),
            effects: args.effects.clone(),
            full_bucket_n,
            end,
            track_backs,
            backups: backups_done,
            plan_ms: &plan_ms,
            scans: log.scans,
            session_time_s: clock.now_s(),
            wall_time_s: wall.elapsed().as_secs_f64(),
            trace,
            trace_clock: TRACE_CLOCK,
        },
        node,
        session,
    );
    let summary = DemoSummary {
        plant_machine: args
            .plant_machine
            .as_deref()
            .map(FileRecord::of)
            .transpose()?,
        profile: args.profile.as_deref().map(FileRecord::of).transpose()?,
        ..summary
    };
    let plan: Vec<Action> = node.cycle().config().actions.clone();
    let after = machine.plant().world.terrain.clone();
    if let Some(s) = &session {
        write_planner_outputs(out, s, machine.plant().true_state().pose)?;
    }
    if session.is_some() {
        snapshots.push(BenchSnapshot {
            digs: summary.digs.len(),
            backups: backups_done,
            terrain: after.clone(),
            pose: machine.plant().true_state().pose,
        });
    }
    onboard::summary::write_files(out, &summary, &plan)?;
    write_plots(out, &summary, Some((&terrain_before, &after)), &snapshots)?;
    write_soil_samples(out, &log.soil_samples)?;
    Ok(summary)
}

/// The name `summary.json` records for a soil-contact integration.
fn soil_contact_name(c: SoilContactIntegration) -> &'static str {
    match c {
        SoilContactIntegration::Held => "held",
        SoilContactIntegration::Implicit => "implicit",
    }
}

/// The lab's plots of a `run` session folder ([`SessionPlots`]): the planner's figures at the
/// machine's last pose and the bench snapshots, without a simulator's terrain (a bus session has
/// none).
#[derive(Debug, Clone, Copy, Default)]
pub struct Plots;

impl SessionPlots for Plots {
    fn write(
        &self,
        out: &Path,
        summary: &DemoSummary,
        session: Option<&PlannedSession>,
        snapshots: &[BenchSnapshot],
    ) -> anyhow::Result<()> {
        if let (Some(s), Some(last)) = (session, snapshots.last()) {
            write_planner_outputs(out, s, last.pose)?;
        }
        write_plots(out, summary, None, snapshots)
    }
}

/// The planner's outputs of a session: its last cycle (`last_plan.json`), the refined grid of the
/// first planned dig (`refined_grid.svg`, Figs. 47/48) and its map at the end (`map_after.svg`, the
/// machine at world `pose` `[x, y, heading]`).
///
/// # Errors
/// Writing the files.
pub fn write_planner_outputs(out: &Path, s: &PlannedSession, pose: [f64; 3]) -> anyhow::Result<()> {
    onboard::summary::write_last_plan(out, s)?;
    // Figs. 47/48: the refined planner's evaluated grid of the region of the first planned dig.
    if let Some((plan, dig)) = s.steps().iter().find_map(|st| match &st.plan {
        Some(p) => match &p.action {
            planner::plan::ActionChoice::Dig(d) => Some((p, d)),
            _ => None,
        },
        None => None,
    }) && let Some(refined) = plan
        .refined
        .iter()
        .find(|r| r.region.index == dig.region_index)
    {
        let q = s.planner().quality();
        let max_q = q.w_volume * q.xi_max + q.w_time * q.psi_max + q.w_energy * q.zeta_max;
        let path = out.join("refined_grid.svg");
        std::fs::write(
            &path,
            crate::plots::refined_grid_svg(
                refined,
                s.planner().config().floor_z_m,
                max_q,
                &format!(
                    "refined plan of the first planned dig (region {}, thesis Figs. 47/48)",
                    dig.region_index
                ),
            )?,
        )
        .with_context(|| format!("writing {}", path.display()))?;
    }
    let path = out.join("map_after.svg");
    std::fs::write(
        &path,
        crate::plots::bench_svg(
            s.terrain(),
            crate::plots::ElevationScale::spanning([s.terrain()]),
            &crate::plots::MachineTrack::default().at(pose),
            "the planner's terrain map at the end (elevation, m)",
        )?,
    )
    .with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

/// Writes the plots of the digs and, given the terrain before and after (the simulator's truth), its
/// plots, and the bench `snapshots` (Fig. 55) with the dig sequence (Fig. 56).
///
/// # Errors
/// Writing the files.
pub fn write_plots(
    out: &Path,
    summary: &DemoSummary,
    terrain: Option<(&TerrainGrid, &TerrainGrid)>,
    snapshots: &[BenchSnapshot],
) -> anyhow::Result<()> {
    let write = |name: &str, bytes: &[u8]| -> anyhow::Result<()> {
        let p = out.join(name);
        std::fs::write(&p, bytes).with_context(|| format!("writing {}", p.display()))
    };
    write(
        "trajectories.svg",
        crate::plots::trajectories_svg(&summary.digs)?.as_bytes(),
    )?;
    // One colour scale for the maps meant to be compared.
    let scale = crate::plots::ElevationScale::spanning(
        terrain
            .iter()
            .flat_map(|&(b, a)| [b, a])
            .chain(snapshots.iter().map(|s| &s.terrain)),
    );
    let track =
        |n: usize| crate::plots::MachineTrack::of_digs(&summary.digs[..n.min(summary.digs.len())]);
    if let Some((before, after)) = terrain {
        write(
            "terrain_before.svg",
            crate::plots::terrain_svg(before, scale, &track(1), "terrain before the session")?
                .as_bytes(),
        )?;
        write(
            "terrain_after.svg",
            crate::plots::terrain_svg(
                after,
                scale,
                &track(usize::MAX),
                "terrain after the session",
            )?
            .as_bytes(),
        )?;
    }
    write(
        "dig_stats.svg",
        crate::plots::dig_stats_svg(&summary.digs)?.as_bytes(),
    )?;
    if !snapshots.is_empty() {
        for snap in snapshots {
            write(
                &format!("bench_after_{:03}.svg", snap.digs),
                crate::plots::bench_svg(
                    &snap.terrain,
                    scale,
                    &track(snap.digs).at(snap.pose),
                    &format!(
                        "bench after {} digs, {} backups ({})",
                        snap.digs, snap.backups, summary.strategy
                    ),
                )?
                .as_bytes(),
            )?;
        }
        write(
            "dig_sequence.svg",
            crate::plots::dig_sequence_svg(&summary.digs, summary.stats.full_bucket_n)?.as_bytes(),
        )?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The output folder of the fixtures.
    const OUT: &str = "out/x";

    /// `defaults` is `demo`'s command line with nothing given: the planned strategy on the
    /// extended bench, the progress bar on; `fixed` differs in the strategy and the bar only.
    #[test]
    fn defaults_are_the_cli_s() {
        let d = DemoArgs::defaults(PathBuf::from(OUT));
        assert_eq!(d.strategy, DemoStrategy::Planned);
        assert_eq!(d.digs, 10);
        assert_eq!(d.seed, None);
        assert_eq!(d.bench, None);
        assert!(!d.quiet);
        assert_eq!(d.out, PathBuf::from(OUT));
        let f = DemoArgs::fixed(PathBuf::from(OUT));
        assert_eq!(f.strategy, DemoStrategy::Fixed);
        assert!(f.quiet);
        assert_eq!(
            DemoArgs {
                strategy: DemoStrategy::Planned,
                quiet: false,
                ..f
            },
            d
        );
    }
}
