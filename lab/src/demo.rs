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
//!   `--config` file's plan, on `config/bench.toml` (the library default of [`DemoArgs::new`]).
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
//!   pressures, 4.3.4) for `excavator-ctl model soil-cv` ([`crate::session::SoilSamplesFile`]).
//!
//! One thread alternates the simulator (10 ms, ten 1 kHz physics steps) and the controller step, as in
//! the closed-loop tests; the run is deterministic for a seed.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::Context as _;
use clap::Args;
use firmware_bridge::profile::Profile;
use firmware_bridge::trace::{Direction, Recorder};
use firmware_bridge::transport::{TraceClock, TraceTimeBase};
use planner::autodig::AutodigMaps;
use planner::cleanup::CleanupPlan;
use serde::{Deserialize, Serialize};
use vcan_sim::SimConfig;
use vcan_sim::embedded::EmbeddedMachine;

use planner::kinematics::{JointAngles, MachinePose};
use planner::plan::{HardnessRegression, PlannerConfig, TerrainMapper};
use planner::terrain::TerrainGrid;
use vcan_sim::scenario::{Scenario, SoilContactIntegration};

use controller::cycle::{Action, ActionKind, DigStats, Phase, StartPose};
use controller::node::{ControllerConfig, ControllerNode};
use controller::planned::{PlannedSession, Strategy, median_joints};
use controller::session::{NoObserver, PlannedDig, SessionDriver, SessionEvent, SessionObserver};

pub use crate::harness::PERIOD_S;
use crate::harness::{Harness, SimScans};

/// The extended-operation bench (thesis ch. 6), the default bench of the planned and predefined
/// strategies.
pub use vcan_sim::scenario::EXTENDED_BENCH_TOML;

/// Carry and dump height of the bucket tip on the planned and predefined strategies, m.
pub const EXTENDED_CARRY_TIP_Z_M: f64 = 4.0;
/// Joint tolerance of the moves to the dig on the planned and predefined strategies, rad.
pub const EXTENDED_JOINT_TOLERANCE_RAD: f64 = 0.06;
/// ... or boom angle, degrees, whichever comes first.
pub const EXTENDED_CARRY_BOOM_DEG: f64 = 55.0;

/// Which action source drives the session (`--strategy`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum DemoStrategy {
    /// The perception-based dig planner (5.1), default bench `config/bench_extended.toml`.
    #[default]
    Planned,
    /// The predefined excavation sequence (6.2), default bench `config/bench_extended.toml`.
    Predefined,
    /// The fixed demo plan or the `--config` file's plan, default bench `config/bench.toml`.
    Fixed,
}

impl DemoStrategy {
    /// The planned session's strategy, `None` for the fixed plan.
    #[must_use]
    pub fn session(self) -> Option<Strategy> {
        match self {
            Self::Planned => Some(Strategy::Planned),
            Self::Predefined => Some(Strategy::Predefined),
            Self::Fixed => None,
        }
    }

    /// The name in `summary.json`.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::Planned => "planned",
            Self::Predefined => "predefined",
            Self::Fixed => "fixed",
        }
    }
}

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
#[derive(Debug, Clone, Args)]
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
    /// A hidden effect of the simulator, NAME=VALUE (repeatable; `excavator-sim --list-effects`).
    #[arg(long = "effect", value_name = "NAME=VALUE")]
    pub effects: Vec<String>,
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
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
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
    /// The defaults of the command line with `out` as the output folder, except the strategy: the
    /// fixed plan on config/bench.toml (what this constructor gave before the planner was wired, for
    /// library callers); see [`Self::planned`].
    pub fn new(out: PathBuf) -> Self {
        Self {
            digs: 10,
            seed: None,
            machine: None,
            plant_machine: None,
            bench: None,
            effects: Vec::new(),
            soil_contact: None,
            out,
            config: None,
            maps: None,
            quiet: true,
            strategy: DemoStrategy::Fixed,
            planner: None,
            hardness: None,
            predefined_from: None,
            bench_after: vec![12],
            predefined_plain: false,
            predefined_joints: None,
            profile: None,
        }
    }

    /// The command line's defaults: the planned strategy on the extended-operation bench.
    pub fn planned(out: PathBuf) -> Self {
        Self {
            strategy: DemoStrategy::Planned,
            ..Self::new(out)
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

pub use crate::session::TipPoint;

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

pub use crate::session::DigRecord;

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

/// Thesis Tables 3-5 figures of a session (6.1, 6.2).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct SessionStats {
    /// Mean weight of the dig actions (normal digs), N.
    pub dig_mean_weight_n: f64,
    /// Mean time of the dig actions, s.
    pub dig_mean_time_s: f64,
    /// Mean energy of the dig actions, kJ.
    pub dig_mean_energy_kj: f64,
    /// Mean weight of the cleanup actions, N (0 without cleanups).
    pub cleanup_mean_weight_n: f64,
    /// Mean time of the cleanup actions, s.
    pub cleanup_mean_time_s: f64,
    /// Mean energy of the cleanup actions, kJ.
    pub cleanup_mean_energy_kj: f64,
    /// A full bucket's weight: capacity x bank density x g, N (the thesis's 25 000 N).
    pub full_bucket_n: f64,
    /// Share of all buckets (digs and cleanups) over half full (thesis test 3: 0.94).
    pub over_half_full: f64,
    /// Share of all buckets over a third full (thesis test 3: 0.98).
    pub over_third_full: f64,
    /// Eq. 26: mean weight / (12 s + mean time), N/s.
    pub productivity_n_per_s: f64,
    /// Eq. 27: mean energy / mean weight, kJ/N.
    pub energy_per_weight_kj_per_n: f64,
    /// Least-squares slope of the dig actions' weight over the dig number, N per dig (Fig. 60:
    /// the bucket fill must not decay).
    pub dig_weight_slope_n_per_dig: f64,
    /// Mean weight of the dig actions in the first half of the session, N.
    pub dig_mean_weight_first_half_n: f64,
    /// Mean weight of the dig actions in the second half, N.
    pub dig_mean_weight_second_half_n: f64,
}

impl SessionStats {
    /// The statistics of `digs`, with a full bucket of `full_bucket_n`.
    #[must_use]
    pub fn of(digs: &[DigRecord], full_bucket_n: f64) -> Self {
        let mean = |v: &[f64]| {
            if v.is_empty() {
                0.0
            } else {
                v.iter().sum::<f64>() / v.len() as f64
            }
        };
        let pick = |kind: ActionKind, f: fn(&DigRecord) -> f64| -> Vec<f64> {
            digs.iter().filter(|d| d.action == kind).map(f).collect()
        };
        let weight = |d: &DigRecord| d.weight_n.unwrap_or(0.0);
        let share = |k: f64| {
            if digs.is_empty() {
                0.0
            } else {
                digs.iter()
                    .filter(|d| weight(d) > k * full_bucket_n)
                    .count() as f64
                    / digs.len() as f64
            }
        };
        let w_all: Vec<f64> = digs.iter().map(weight).collect();
        let t_all: Vec<f64> = digs.iter().map(|d| d.time_s).collect();
        let e_all: Vec<f64> = digs.iter().map(|d| d.energy_kj).collect();
        let dig_w: Vec<(f64, f64)> = digs
            .iter()
            .filter(|d| d.action == ActionKind::Dig)
            .map(|d| (f64::from(d.index), weight(d)))
            .collect();
        let slope = {
            let n = dig_w.len() as f64;
            let (mx, my) = (
                dig_w.iter().map(|p| p.0).sum::<f64>() / n.max(1.0),
                dig_w.iter().map(|p| p.1).sum::<f64>() / n.max(1.0),
            );
            let sxx: f64 = dig_w.iter().map(|p| (p.0 - mx).powi(2)).sum();
            let sxy: f64 = dig_w.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
            if sxx > 0.0 { sxy / sxx } else { 0.0 }
        };
        let half = digs.len() / 2;
        let halves = |first: bool| -> Vec<f64> {
            digs.iter()
                .enumerate()
                .filter(|(i, d)| d.action == ActionKind::Dig && ((*i < half) == first))
                .map(|(_, d)| weight(d))
                .collect()
        };
        let (mw, mt, me) = (mean(&w_all), mean(&t_all), mean(&e_all));
        Self {
            dig_mean_weight_n: mean(&pick(ActionKind::Dig, weight)),
            dig_mean_time_s: mean(&pick(ActionKind::Dig, |d| d.time_s)),
            dig_mean_energy_kj: mean(&pick(ActionKind::Dig, |d| d.energy_kj)),
            cleanup_mean_weight_n: mean(&pick(ActionKind::Cleanup, weight)),
            cleanup_mean_time_s: mean(&pick(ActionKind::Cleanup, |d| d.time_s)),
            cleanup_mean_energy_kj: mean(&pick(ActionKind::Cleanup, |d| d.energy_kj)),
            full_bucket_n,
            over_half_full: share(0.5),
            over_third_full: share(1.0 / 3.0),
            productivity_n_per_s: mw / (12.0 + mt), // Eq. 26
            energy_per_weight_kj_per_n: if mw > 0.0 { me / mw } else { 0.0 }, // Eq. 27
            dig_weight_slope_n_per_dig: slope,
            dig_mean_weight_first_half_n: mean(&halves(true)),
            dig_mean_weight_second_half_n: mean(&halves(false)),
        }
    }
}

/// Planning-cycle timing of a session (wall clock, this process).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct PlanningStats {
    /// Planning cycles run.
    pub cycles: usize,
    /// Mean wall time per cycle, ms.
    pub mean_ms: f64,
    /// Longest cycle, ms.
    pub max_ms: f64,
}

/// What a session produced (`summary.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DemoSummary {
    /// The action source: `planned`, `predefined` or `fixed`.
    #[serde(default)]
    pub strategy: String,
    /// The bench scenario's name.
    #[serde(default)]
    pub bench: String,
    /// Track-back actions completed.
    #[serde(default)]
    pub backups: usize,
    /// Cleanup actions completed.
    #[serde(default)]
    pub cleanups: usize,
    /// Why the session ended (`dig count reached`, `bench removed: ...`, `nothing left to do`,
    /// `stopped`, `time budget`).
    #[serde(default)]
    pub end: String,
    /// Tables 3-5 figures.
    #[serde(default)]
    pub stats: SessionStats,
    /// Planning-cycle timing (planned strategy).
    #[serde(default)]
    pub planning: PlanningStats,
    /// The predefined sequence's start joints `[boom, stick, bucket]`, degrees (predefined strategy).
    #[serde(default)]
    pub predefined_start_deg: Option<[f64; 3]>,
    /// The simulator's seed.
    pub seed: u64,
    /// The simulator's soil-contact integration, `held` or `implicit` (docs/simulator.md; `held` in
    /// summaries written before it was recorded).
    #[serde(default = "held")]
    pub soil_contact: SoilContactIntegration,
    /// The hidden effects given on the command line.
    pub effects: Vec<String>,
    /// The simulated machine's own file (`--plant-machine`), when it is not the controller's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plant_machine: Option<FileRecord>,
    /// The machine profile both ends spoke on the bus (`--profile`), when not the project's protocol.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub profile: Option<FileRecord>,
    /// What stamped the trace's frames: `virtual` (`demo`: session time since the fixed epoch of
    /// docs/demo-output.md), `kernel` (`run`: the socket's kernel receive timestamps) or
    /// `wall_at_read` (`run` without them); absent in summaries written before it was recorded.
    #[serde(default)]
    pub trace_clock: Option<TraceClock>,
    /// The CAN interface's link when `run` started (bitrate, state, `restart-ms`, listen-only; none
    /// of them for a vcan); absent for `demo`, which has no interface.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub can_link: Option<firmware_bridge::transport::LinkStatus>,
    /// Per dig.
    pub digs: Vec<DigRecord>,
    /// Totals.
    pub totals: Totals,
}

/// A file a session was made with (`summary.json` `plant_machine`, `profile`): which file, and its
/// content's hash, so the session says which plant or which gateway's protocol made it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct FileRecord {
    /// The file as given.
    pub path: String,
    /// SHA-256 of its bytes, lower-case hex.
    pub sha256: String,
}

impl FileRecord {
    /// The record of the file at `path`.
    ///
    /// # Errors
    /// Reading the file.
    pub fn of(path: &Path) -> anyhow::Result<Self> {
        use sha2::Digest as _;
        let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
        let digest = sha2::Sha256::digest(&bytes);
        Ok(Self {
            path: path.display().to_string(),
            sha256: digest.iter().map(|b| format!("{b:02x}")).collect(),
        })
    }
}

impl DemoSummary {
    /// The summary with its wall-clock figures zeroed: `totals.wall_time_s` and the planning cycles'
    /// `planning.mean_ms` and `planning.max_ms` (how long this process took, not what the session
    /// did). Everything else follows from the arguments and the seed: two sessions of one `demo`
    /// command are equal after this (docs/demo-output.md, "Reproducibility").
    #[must_use]
    pub fn without_wall_clock(mut self) -> Self {
        self.totals.wall_time_s = 0.0;
        self.planning.mean_ms = 0.0;
        self.planning.max_ms = 0.0;
        self
    }
}

/// The soil contact of a summary written before it was recorded: the plant was `held` then.
fn held() -> SoilContactIntegration {
    SoilContactIntegration::Held
}

/// The session-time base of the trace at `trace` (its frames' session time for the scans and
/// per-dig records beside it): the clock recorded in the `summary.json` of its folder, else, without
/// a summary (a session still running or killed, a bare trace), the one its first frame shows
/// ([`TraceTimeBase`]).
///
/// # Errors
/// A `summary.json` beside the trace that cannot be read, or whose `trace_clock` is not a clock.
pub fn trace_time_base(trace: &Path) -> anyhow::Result<TraceTimeBase> {
    #[derive(Deserialize)]
    struct Recorded {
        #[serde(default)]
        trace_clock: Option<TraceClock>,
    }
    let summary = trace
        .parent()
        .unwrap_or_else(|| Path::new("."))
        .join("summary.json");
    let clock = match std::fs::read_to_string(&summary) {
        Ok(text) => {
            serde_json::from_str::<Recorded>(&text)
                .with_context(|| format!("{}: reading trace_clock", summary.display()))?
                .trace_clock
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
        Err(e) => return Err(e).with_context(|| format!("reading {}", summary.display())),
    };
    Ok(TraceTimeBase::new(clock))
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
    let mut config = match &args.config {
        Some(p) => ControllerConfig::from_toml_file(p).context("controller config")?,
        None => {
            let mut c = ControllerConfig::default();
            c.cycle.actions = demo_plan();
            c
        }
    };
    config.cycle.max_digs = Some(args.digs);
    if args.strategy == DemoStrategy::Fixed {
        config.cycle.repeat = true;
    } else {
        config.cycle.actions.clear();
        config.cycle.repeat = false;
        // The spoil is cast beside the tract onto the bench top and piles up there over a long
        // session: carry and dump well above it (the default 2.8 m tip height is 0.8 m over the
        // default bench's top; the uncurling bucket's tip swings down about 1.5 m).
        config.cycle.carry_tip_z_m = config.cycle.carry_tip_z_m.max(EXTENDED_CARRY_TIP_Z_M);
        // The start is approached 0.4 m above the planned tip and Boom-Down lowers it onto the
        // terrain, so a few degrees of implement error only change where Boom-Down starts; the
        // P-controller's minimum command cannot lift a boom that overshot a 0.03 rad tolerance
        // downward (the move timed out 2 degrees short).
        config.cycle.joint.tolerance = config
            .cycle
            .joint
            .tolerance
            .max(EXTENDED_JOINT_TOLERANCE_RAD);
        config.cycle.carry_boom_rad = config
            .cycle
            .carry_boom_rad
            .max(EXTENDED_CARRY_BOOM_DEG.to_radians());
        if args.strategy == DemoStrategy::Predefined {
            // Thesis 6.2: the floor detected once and reused "was not implemented for the
            // predefined excavation sequence": its cleanups detect the floor every time.
            config.cycle.floor_policy = planner::cleanup::FloorPolicy::DetectEveryTime;
            if args.predefined_plain {
                // Plain Autodig (3.1): Dig ends on its fixed beta, Capture on its fixed gamma.
                config.cycle.perception = false;
            }
        }
        let st = &sim.scenario.start;
        config.estimator.initial_pose = MachinePose {
            x_m: st.x_m,
            y_m: st.y_m,
            heading_rad: st.heading_deg.to_radians(),
        };
        let g = &sim.scenario.grid;
        config.cycle.scan_grid.x_min_m = g.x_min_m;
        config.cycle.scan_grid.y_min_m = g.y_min_m;
        config.cycle.scan_grid.cell_m = g.cell_m;
        config.cycle.scan_grid.size_x_m = g.size_x_m;
        config.cycle.scan_grid.size_y_m = g.size_y_m;
    }
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
    let mut cfg = match &args.planner {
        Some(p) => {
            let text = std::fs::read_to_string(p)
                .with_context(|| format!("reading the planner config {}", p.display()))?;
            PlannerConfig::from_toml_str(&text)
                .with_context(|| format!("planner config {}", p.display()))?
        }
        None => PlannerConfig::nominal().context("built-in planner config")?,
    };
    cfg.floor_z_m = sim.scenario.bench.floor_elevation_m;
    Ok(cfg)
}

/// The planned session of a run: the planner on the machine, a terrain map on the scenario's grid,
/// the hardness regression (`--hardness` or the built-in one).
///
/// # Errors
/// Files, planner construction.
pub fn build_session(
    args: &DemoArgs,
    sim: &SimConfig,
    strategy: Strategy,
) -> anyhow::Result<PlannedSession> {
    let cfg = planner_config(args, sim)?;
    let g = &sim.scenario.grid;
    let n = |size: f64| (size / g.cell_m).round().max(1.0) as usize;
    let mapper = TerrainMapper::new(
        g.x_min_m,
        g.y_min_m,
        g.cell_m,
        n(g.size_x_m),
        n(g.size_y_m),
        controller::cycle::ScanGrid::default().max_gap_cells,
    )
    .context("terrain map")?;
    let machine = controller_machine(args, sim)?;
    let mut session =
        PlannedSession::new(&machine, cfg, mapper, strategy).context("planned session")?;
    if let Some(p) = &args.hardness {
        let text = std::fs::read_to_string(p)
            .with_context(|| format!("reading the hardness regression {}", p.display()))?;
        session.set_regression(
            HardnessRegression::from_toml_str(&text)
                .with_context(|| format!("hardness regression {}", p.display()))?,
        );
    }
    Ok(session)
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

/// A dig's record as it begins: the action, the planner's prediction, and with the simulator at hand
/// its truth (the terrain along the digging plane, the map's error against it).
fn begin_record(
    node: &ControllerNode,
    machine: Option<&EmbeddedMachine>,
    session: Option<&PlannedSession>,
    info: &PlannedDig,
    pose: MachinePose,
    done: usize,
) -> DigRecord {
    let action = node.action().copied();
    let swing_rad = node.state().swing_rad;
    let truth = machine.map_or_else(Vec::new, |m| true_section(m, swing_rad));
    let map_error_m = session.and_then(|s| {
        let errs: Vec<f64> = truth
            .iter()
            .filter(|p| (3.0..=10.0).contains(&p.x_m))
            .filter_map(|p| {
                let [x, y, _] = pose.world_from_base(swing_rad, p.x_m, 0.0);
                s.terrain()
                    .height_at(x, y)
                    .ok()
                    .map(|h| (h - p.z_m).powi(2))
            })
            .collect();
        (!errs.is_empty()).then(|| (errs.iter().sum::<f64>() / errs.len() as f64).sqrt())
    });
    let map_bias_at_start_m = match (session, info.start) {
        (Some(s), Some([r_start, ..])) => {
            let errs: Vec<f64> = truth
                .iter()
                .filter(|p| (r_start - 1.5..=r_start + 0.2).contains(&p.x_m))
                .filter_map(|p| {
                    let [x, y, _] = pose.world_from_base(swing_rad, p.x_m, 0.0);
                    s.terrain().height_at(x, y).ok().map(|h| h - p.z_m)
                })
                .collect();
            (!errs.is_empty()).then(|| errs.iter().sum::<f64>() / errs.len() as f64)
        }
        _ => None,
    };
    DigRecord {
        index: u32::try_from(done).unwrap_or(u32::MAX),
        action: action.map_or(ActionKind::Dig, |a| a.kind()),
        swing_deg: swing_rad.to_degrees(),
        start_pose: match action {
            Some(Action::Dig { start, .. } | Action::Cleanup { start, .. }) => Some(start),
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
        quality: info.quality,
        predicted_volume_m3: info.volume_m3,
        predicted_time_s: info.time_s,
        predicted_energy_kj: info.energy_kj,
        predicted_min_tip_z_m: info.min_tip_z_m,
        contact_start: None,
        min_tip_z_m: None,
        hardness_index: Some(node.cycle().hardness_index()),
        pose: Some([pose.x_m, pose.y_m, pose.heading_rad]),
        planned_start: info.start,
        map_error_m,
        map_bias_at_start_m,
        trajectory: Vec::new(),
        section: truth,
    }
}

/// A dig's record at its end: the controller's statistics and the tip path.
fn finish_record(c: &mut DigRecord, d: &DigStats, tip_path: &[(f64, f64)]) {
    c.trajectory = tip_path
        .iter()
        .map(|&(x_m, z_m)| TipPoint { x_m, z_m })
        .collect();
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
    c.min_tip_z_m = c
        .trajectory
        .iter()
        .map(|p| p.z_m)
        .filter(|z| z.is_finite())
        .reduce(f64::min);
    c.contact_start = c.trajectory.iter().find_map(|p| {
        let below = c
            .section
            .iter()
            .min_by(|a, b| (a.x_m - p.x_m).abs().total_cmp(&(b.x_m - p.x_m).abs()))
            .is_some_and(|s| (s.x_m - p.x_m).abs() < 0.05 && p.z_m < s.z_m - 0.02);
        below.then_some([p.x_m, p.z_m])
    });
}

/// The true terrain after some digs (Fig. 55), with the machine's pose then.
#[derive(Debug, Clone)]
pub struct BenchSnapshot {
    /// Digs done.
    pub digs: usize,
    /// Track backs done.
    pub backups: usize,
    /// The simulator's terrain.
    pub terrain: TerrainGrid,
    /// The machine's true world pose `[x, y, heading]`.
    pub pose: [f64; 3],
}

/// The machine profile at `path`, if one is given: checked completely before anything runs.
///
/// # Errors
/// The profile's error, one line naming the file, the line and the quantity.
pub fn load_profile(path: Option<&Path>) -> anyhow::Result<Option<Arc<Profile>>> {
    Ok(path.map(Profile::load).transpose()?.map(Arc::new))
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
    let full_bucket_n = sim.machine.bucket.capacity_m3
        * sim.scenario.soil.density_kg_per_m3
        * planner::machine::GRAVITY_M_PER_S2;
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

    let progress = crate::console::session_bar(Some(args.digs), args.quiet);
    let mut log = SessionRecords::new(scans_dir);
    let budget_s = SIM_BUDGET_PER_DIG_S * f64::from(args.digs.max(1));
    let mut result: anyhow::Result<()> = Ok(());
    let mut snapshots: Vec<BenchSnapshot> = Vec::new();
    // Operator commands in-process (the live view's page): applied between two steps, as `run`
    // applies those of its control socket before a step.
    let mut operator = controller::operator::OperatorPort::new();
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
            crate::console::update(progress.as_ref(), log.records.len(), node, driver.backups());
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
            let finished = log.on_event(node, &driver, Some(machine), event)?;
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
            strategy: args.strategy,
            bench: sim.scenario.name.clone(),
            seed: sim.scenario.seed,
            soil_contact: sim.scenario.soil_contact,
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
    write_outputs(
        out,
        &summary,
        Some((&terrain_before, &after)),
        &plan,
        &snapshots,
    )?;
    write_soil_samples(out, &log.soil_samples)?;
    Ok(summary)
}

/// The planner's outputs of a session: its last cycle (`last_plan.json`), the refined grid of the
/// first planned dig (`refined_grid.svg`, Figs. 47/48) and its map at the end (`map_after.svg`, the
/// machine at world `pose` `[x, y, heading]`).
///
/// # Errors
/// Writing the files.
pub fn write_planner_outputs(out: &Path, s: &PlannedSession, pose: [f64; 3]) -> anyhow::Result<()> {
    // The planner's last cycle (cleanup candidates, tracking limits, regions) and its map.
    if let Some(p) = s.steps().iter().rev().find_map(|st| st.plan.as_ref()) {
        let last = serde_json::json!({
            "coarse": p.coarse,
            "best_dig": p.best_dig,
            "cleanup_track": p.cleanup_track,
            "action": p.action.kind().map(|k| format!("{k:?}")),
        });
        let path = out.join("last_plan.json");
        std::fs::write(&path, serde_json::to_vec_pretty(&last)?)
            .with_context(|| format!("writing {}", path.display()))?;
    }
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

/// The records of a session as it runs, from the session driver's events: the scans written to
/// `scans/`, one [`DigRecord`] per dig and cleanup, and their soil samples. `demo` and `run` keep
/// them alike; `demo` adds the simulator's truth.
#[derive(Debug)]
pub struct SessionRecords {
    scans_dir: PathBuf,
    /// Scans written.
    pub scans: usize,
    /// Finished digs and cleanups.
    pub records: Vec<DigRecord>,
    current: Option<DigRecord>,
    /// Every dig's soil samples (4.3.5), for `soil_samples.json` and `model soil-cv`.
    pub soil_samples: crate::session::SoilSamplesFile,
}

impl SessionRecords {
    /// Records whose scans go to `scans_dir` (created by the caller).
    #[must_use]
    pub fn new(scans_dir: PathBuf) -> Self {
        Self {
            scans_dir,
            scans: 0,
            records: Vec::new(),
            current: None,
            soil_samples: crate::session::SoilSamplesFile::default(),
        }
    }

    /// Takes one event of `driver` for `node`, with the simulator's truth when `machine` is given.
    /// Returns whether a dig or cleanup finished.
    ///
    /// # Errors
    /// Writing a scan.
    pub fn on_event(
        &mut self,
        node: &ControllerNode,
        driver: &SessionDriver,
        machine: Option<&EmbeddedMachine>,
        event: &SessionEvent,
    ) -> anyhow::Result<bool> {
        match event {
            SessionEvent::Scanned(scan) => {
                let path = self.scans_dir.join(format!("scan_{:04}.json", self.scans));
                std::fs::write(&path, serde_json::to_vec(scan)?)
                    .with_context(|| format!("writing {}", path.display()))?;
                self.scans += 1;
            }
            SessionEvent::PhaseChanged { to, .. } => {
                if *to == Phase::Weigh
                    && let (Some(c), Some(m)) = (&mut self.current, machine)
                {
                    c.true_payload_kg = m.plant().true_state().payload_kg;
                }
            }
            SessionEvent::DigStarted { planned, pose } => {
                self.current = Some(begin_record(
                    node,
                    machine,
                    driver.session(),
                    planned,
                    *pose,
                    self.records.len(),
                ));
            }
            SessionEvent::DigFinished {
                index,
                tip_path,
                soil_samples,
            } => {
                let (Some(mut c), Some(d)) = (self.current.take(), node.statistics().get(*index))
                else {
                    return Ok(false);
                };
                finish_record(&mut c, d, tip_path);
                if !soil_samples.is_empty() {
                    self.soil_samples.digs.push(crate::session::SoilDigSamples {
                        index: c.index,
                        samples: soil_samples.clone(),
                    });
                }
                self.records.push(c);
                return Ok(true);
            }
        }
        Ok(false)
    }
}

/// How a session ended and what it was, for [`session_summary`].
#[derive(Debug, Clone)]
pub struct SessionEnd<'a> {
    /// The action source.
    pub strategy: DemoStrategy,
    /// The bench's name.
    pub bench: String,
    /// The simulator's seed.
    pub seed: u64,
    /// The simulator's soil-contact integration.
    pub soil_contact: SoilContactIntegration,
    /// The hidden effects.
    pub effects: Vec<String>,
    /// A full bucket's weight, N.
    pub full_bucket_n: f64,
    /// Why it ended.
    pub end: String,
    /// Track backs begun.
    pub track_backs: usize,
    /// Track backs done.
    pub backups: usize,
    /// Wall time of each planning cycle, ms.
    pub plan_ms: &'a [f64],
    /// Scans taken.
    pub scans: usize,
    /// Session (simulated or scaled) time, s.
    pub session_time_s: f64,
    /// Wall time, s.
    pub wall_time_s: f64,
    /// The trace recorder's counts.
    pub trace: firmware_bridge::trace::RecorderStats,
    /// What stamped the trace.
    pub trace_clock: TraceClock,
}

/// `summary.json` of a session: the records, their totals and Tables 3-5 figures.
#[must_use]
pub fn session_summary(
    records: Vec<DigRecord>,
    end: SessionEnd<'_>,
    node: &ControllerNode,
    session: Option<&PlannedSession>,
) -> DemoSummary {
    let n = records.len();
    let mean = |f: &dyn Fn(&DigRecord) -> f64| {
        if n == 0 {
            0.0
        } else {
            records.iter().map(f).sum::<f64>() / n as f64
        }
    };
    let cleanups = records
        .iter()
        .filter(|r| r.action == ActionKind::Cleanup)
        .count();
    let totals = Totals {
        digs: n,
        dig_actions: records
            .iter()
            .filter(|r| r.action == ActionKind::Dig)
            .count(),
        cleanup_actions: cleanups,
        track_backs: end.track_backs,
        weight_n: records.iter().filter_map(|r| r.weight_n).sum(),
        mean_weight_n: mean(&|r| r.weight_n.unwrap_or(0.0)),
        mean_time_s: mean(&|r| r.time_s),
        mean_energy_kj: mean(&|r| r.energy_kj),
        energy_kj: records.iter().map(|r| r.energy_kj).sum(),
        swept_volume_m3: records.iter().map(|r| r.swept_volume_m3).sum(),
        scans: end.scans,
        sim_time_s: end.session_time_s,
        wall_time_s: end.wall_time_s,
        trace_frames: end.trace.recorded,
        trace_dropped: end.trace.dropped,
        finished: node.finished(),
        last_fault: node.last_fault().map(|f| f.to_string()),
    };
    let plan_ms = end.plan_ms;
    let planning = if plan_ms.is_empty() {
        PlanningStats::default()
    } else {
        PlanningStats {
            cycles: plan_ms.len(),
            mean_ms: plan_ms.iter().sum::<f64>() / plan_ms.len() as f64,
            max_ms: plan_ms.iter().copied().fold(0.0, f64::max),
        }
    };
    DemoSummary {
        strategy: end.strategy.name().to_owned(),
        bench: end.bench,
        backups: end.backups,
        cleanups,
        end: end.end,
        stats: SessionStats::of(&records, end.full_bucket_n),
        planning,
        predefined_start_deg: session.and_then(|s| s.predefined()).map(|p| {
            [
                p.start.boom_rad.to_degrees(),
                p.start.stick_rad.to_degrees(),
                p.start.bucket_rad.to_degrees(),
            ]
        }),
        seed: end.seed,
        soil_contact: end.soil_contact,
        effects: end.effects,
        plant_machine: None,
        profile: None,
        trace_clock: Some(end.trace_clock),
        can_link: None,
        digs: records,
        totals,
    }
}

/// Writes `soil_samples.json`.
///
/// # Errors
/// Writing the file.
pub fn write_soil_samples(
    out: &Path,
    samples: &crate::session::SoilSamplesFile,
) -> anyhow::Result<()> {
    let path = out.join("soil_samples.json");
    std::fs::write(&path, serde_json::to_vec(samples)?)
        .with_context(|| format!("writing {}", path.display()))
}

/// Writes `summary.json`, `summary.md`, `plan.json`, the plots of the digs and, given the terrain
/// before and after (the simulator's truth), its plots, and the bench `snapshots` (Fig. 55) with the
/// dig sequence (Fig. 56).
///
/// # Errors
/// Writing the files.
pub fn write_outputs(
    out: &Path,
    summary: &DemoSummary,
    terrain: Option<(&TerrainGrid, &TerrainGrid)>,
    plan: &[Action],
    snapshots: &[BenchSnapshot],
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
    if let Some(link) = &s.can_link {
        let _ = writeln!(m, "CAN link at start: {link}.\n");
    }
    if !s.strategy.is_empty() && s.strategy != "fixed" {
        m.push_str(&tables_markdown(s));
    }
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

/// Tables 3-5 of the thesis for one session: the run (Table 3), dig against cleanup actions
/// (Table 4), the per-cycle means with Eqs. 26-27 (Table 5), the share of buckets over half full
/// (Fig. 56) and the fill trend (Fig. 60).
pub fn tables_markdown(s: &DemoSummary) -> String {
    use std::fmt::Write as _;
    let mut m = String::new();
    let t = &s.totals;
    let st = &s.stats;
    // Writing into a String cannot fail.
    let _ = writeln!(
        m,
        "Strategy `{}` on \"{}\"; ended: {}.\n",
        s.strategy, s.bench, s.end
    );
    let _ = writeln!(
        m,
        "Table 3 (run): | digs | backups | weight (N) | time (s) | energy (kJ) |\n|---|---|---|---|---|\n| {} | {} | {:.0} | {:.1} | {:.0} |\n\
         | thesis test 3 | 109, 6 | 21300 | 7.6 | 252 |\n",
        t.digs, s.backups, t.mean_weight_n, t.mean_time_s, t.mean_energy_kj
    );
    let _ = writeln!(
        m,
        "Table 4 (actions): | | count | weight (N) | time (s) | energy (kJ) |\n|---|---|---|---|---|\n\
         | dig actions | {} | {:.0} | {:.1} | {:.0} |\n| cleanup actions | {} | {:.0} | {:.1} | {:.0} |\n\
         | thesis digs / cleanups | | 21201 / 21590 | 5.8 / 12.8 | 212 / 366 |\n",
        t.dig_actions,
        st.dig_mean_weight_n,
        st.dig_mean_time_s,
        st.dig_mean_energy_kj,
        s.cleanups,
        st.cleanup_mean_weight_n,
        st.cleanup_mean_time_s,
        st.cleanup_mean_energy_kj
    );
    let _ = writeln!(
        m,
        "Buckets over half full: {:.0} % (over a third: {:.0} %; full bucket {:.0} N; thesis test 3: 94 %, 98 %). \
         Productivity (Eq. 26) {:.0} N/s, energy per weight (Eq. 27) {:.2} J/N. Dig-action weight trend {:+.0} N per dig; \
         first half {:.0} N, second half {:.0} N (Fig. 60).",
        100.0 * st.over_half_full,
        100.0 * st.over_third_full,
        st.full_bucket_n,
        st.productivity_n_per_s,
        1e3 * st.energy_per_weight_kj_per_n,
        st.dig_weight_slope_n_per_dig,
        st.dig_mean_weight_first_half_n,
        st.dig_mean_weight_second_half_n
    );
    if s.planning.cycles > 0 {
        let _ = writeln!(
            m,
            "\nPlanning: {} cycles, mean {:.0} ms, longest {:.0} ms (wall clock, this process).",
            s.planning.cycles, s.planning.mean_ms, s.planning.max_ms
        );
    }
    if let Some(q) = s.predefined_start_deg {
        let _ = writeln!(
            m,
            "\nPredefined start joints (boom, stick, bucket): {:.1}, {:.1}, {:.1} deg.",
            q[0], q[1], q[2]
        );
    }
    m.push('\n');
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The clock comes from the `summary.json` beside the trace; without one, from the first frame;
    /// a summary whose clock is not one is an error naming the file.
    #[test]
    fn the_trace_time_base_follows_the_recorded_clock() {
        let dir = tempfile::tempdir().unwrap();
        let trace = dir.path().join("trace.log");
        let summary = dir.path().join("summary.json");
        let wall_ns = 1_790_000_000_000_000_000;
        let mut bare = trace_time_base(&trace).unwrap();
        assert_eq!(bare.clock(), None);
        assert_eq!(
            bare.session_ns(TRACE_CLOCK.trace_ns(20_000_000)),
            20_000_000
        );

        std::fs::write(&summary, r#"{"seed": 1, "trace_clock": "kernel"}"#).unwrap();
        let mut kernel = trace_time_base(&trace).unwrap();
        assert_eq!(kernel.clock(), Some(TraceClock::Kernel));
        assert_eq!(kernel.session_ns(wall_ns), 0);
        assert_eq!(kernel.session_ns(wall_ns + 7), 7);

        std::fs::write(&summary, r#"{"trace_clock": "virtual"}"#).unwrap();
        let mut virt = trace_time_base(&trace).unwrap();
        assert_eq!(virt.session_ns(TRACE_CLOCK.trace_ns(5)), 5);

        std::fs::write(&summary, r#"{"trace_clock": "sundial"}"#).unwrap();
        let err = format!("{:#}", trace_time_base(&trace).unwrap_err());
        assert!(
            err.contains("summary.json") && err.contains("sundial"),
            "{err}"
        );
    }
}
