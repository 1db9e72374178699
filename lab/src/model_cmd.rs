//! `excavator-ctl model`: the planner's dig model (thesis ch. 4) against the simulator.
//!
//! - `generate-data`: digs in the simulator (`vcan_sim::plant::Plant` in-process, virtual time) with
//!   Autodig closing the loop on the sensor readings, from varied starts (bench geometry, cohesion,
//!   start distance and bucket angle, hardness index), each written as a `candump -L` trace with the
//!   frames the gateway and the controller exchange (sensors, valve commands, heartbeat and
//!   `ControllerStatus`), so `model train` reads the same thing as a trace recorded by `run` or `demo`.
//! - `train`: actuator training digs from traces (Eq. A20 forces, moment-arm velocities), the recurrent
//!   networks of `planner::actuator` with a held-out split, and the error per cylinder.
//! - `compare`: the simulator and the dig model from the same starts over the same sections (thesis
//!   Figs. 34-41): trajectory, time, energy and swept volume errors, and an SVG of the trajectories.
//! - `table2`: thesis Table 2 with the dig model (force factor 1, 2, 3).
//! - `fig52`: thesis Fig. 52 with the dig model ([`crate::model_fig52`]).
//!
//! The simulation harness ([`DigSetup`], [`run_sim_dig`], [`compare_dig`]) is public so the
//! integration tests and the discrepancy workflow can reuse it.

use std::fs::File;
use std::io::{BufReader, BufWriter, Write as _};
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use clap::{Args, Subcommand};
use firmware_bridge::messages::{
    Activity, AutodigStageCode, AuxValveCommand, ControllerHeartbeat, ControllerStatus, Message,
    RequestedMode, Valve,
};
use firmware_bridge::trace::{Direction, ReadMode, TraceReader, TraceWriter};
use planner::actuator::{ActuatorDig, ActuatorModel, ActuatorSample, FreeRunLoss, TrainConfig};
use planner::autodig::{Autodig, AutodigInputs, AutodigMaps, EndReason, Stage};
use planner::dig_model::{DigModel, DigModelConfig, DigPrediction, DigSite, DigStart};
use planner::kinematics::{BucketPose, Joint, JointAngles, Kinematics};
use planner::terrain::{SectionProfile, SweptVolume};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use vcan_sim::SimConfig;
use vcan_sim::soil_contact::World;

/// Control period, s.
const PERIOD_S: f64 = 0.01;
/// Physics steps per control period.
const PHYSICS_PER_PERIOD: usize = 10;
/// Neutral time recorded before and after each dig, s.
const IDLE_S: f64 = 0.3;
/// A simulated dig that has not ended by then is stopped, s.
const SIM_MAX_DIG_S: f64 = 20.0;
/// Section along the digging plane: start, end and step, m.
const SECTION_R: (f64, f64, f64) = (0.5, 12.0, 0.05);
/// Cylinder speeds above this are sensor glitches (pump flow over the smallest area is far lower), m/s.
const MAX_CYLINDER_SPEED_M_PER_S: f64 = 1.5;
/// The thesis's Table 2: force factor, time (s), volume (m^3), energy (kJ).
pub const THESIS_TABLE2: [(f64, f64, f64, f64); 3] = [
    (1.0, 5.5, 2.2, 113.0),
    (2.0, 8.1, 2.5, 234.0),
    (3.0, 7.8, 2.1, 253.0),
];

/// `excavator-ctl model ...`
#[derive(Debug, Subcommand)]
pub enum ModelCommand {
    /// Train the actuator networks (thesis 4.2) from candump traces.
    Train(TrainArgs),
    /// Free-running error of an actuator model on the held-out test digs of `train`'s split.
    Evaluate(EvaluateArgs),
    /// Run Autodig digs in the simulator from varied starts and write their traces.
    GenerateData(GenerateArgs),
    /// Compare the dig model with the simulator from the same starts (thesis Figs. 34-41).
    Compare(CompareArgs),
    /// Thesis Table 2 with the dig model: force factor 1, 2, 3.
    Table2(Table2Args),
    /// Thesis Fig. 52 with the dig model: hardness index 1 and 5 in a soft and a hard soil.
    Fig52(crate::model_fig52::Fig52Args),
    /// Cross-validate the soil models (thesis 4.3.5) on a `demo` session's `soil_samples.json`.
    SoilCv(crate::soil_cv::SoilCvArgs),
}

/// Which measured signal the training and evaluation cylinder velocities come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum VelocitySource {
    /// Moment arm times the sampled joint rate (`JointRates`). When a cylinder stalls deep in the soil
    /// the simulator's rate can be a phantom (docs/simulator.md, Known issues).
    #[default]
    Rates,
    /// Moment arm times the slope of the resolver angles (`JointAngles`): a least-squares line over
    /// `2 ANGLE_SLOPE_HALF_WINDOW + 1` samples, i.e. the velocity that integrates to the positions
    /// the dig model predicts.
    Angles,
}

/// Which cylinder forces the networks are trained and evaluated with.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum ForceSource {
    /// From the measured head and rod pressures (Eq. A20).
    #[default]
    Measured,
    /// What the dig model feeds the networks: the statics `F = (G - J^T f) / r` (Eqs. A2, A4, A7,
    /// A19, clamped to the port relief) with the model's soil force `f` (`DigModel::soil_force_at`,
    /// the nominal soil with the dig's cohesion) at the trace's pose and cylinder velocities, over the
    /// pre-dig section lowered to the sensed tip path, and the payload of the sensed swept volume.
    /// Needs `model generate-data`'s `setups.json` next to the traces (the pre-dig section and soil).
    Statics,
    /// Training only: every dig twice, once with the measured and once with the statics forces (same
    /// target velocities), so the networks learn what both force signals share and stay usable with
    /// the dig model's statics. Evaluation with `mixed` uses the measured forces.
    Mixed,
}

/// Arguments of `model train`.
#[derive(Debug, Args)]
pub struct TrainArgs {
    /// candump -L traces (from `model generate-data`, `run --trace` or a real machine).
    #[arg(long, required = true, num_args = 1..)]
    pub trace: Vec<PathBuf>,
    /// Where to write the model (`actuator.json`).
    #[arg(long)]
    pub out: PathBuf,
    /// Seed of the split and the initial weights.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Hidden units per network (thesis: five).
    #[arg(long, default_value_t = 5)]
    pub hidden: usize,
    /// Command delay in 10 ms steps (default: the machine file's transport delay).
    #[arg(long)]
    pub delay: Option<usize>,
    /// Free-running (BPTT) epochs.
    #[arg(long, default_value_t = 400)]
    pub epochs: usize,
    /// Fig. 17's inputs only (the boom also sees the bucket command); by default every network also
    /// sees the command and force of the cylinder sharing its flow (the shared, power-limited pump and
    /// the crossover), which the simulator traces show matters.
    #[arg(long)]
    pub thesis_inputs: bool,
    /// Also feed every network the orifice-law drive (Eq. 1) of its own and its partner's cylinder:
    /// the command times the square root of the pressure drop left at the valve for the load.
    #[arg(long, conflicts_with = "thesis_inputs")]
    pub orifice_inputs: bool,
    /// Train the free run and stop early on the mean absolute error (the reported measure) instead of
    /// the mean squared error.
    #[arg(long)]
    pub abs_loss: bool,
    /// Standard deviation of a per-dig force offset added in the free-running phase, in units of each
    /// force input's standard deviation (robustness to the dig model's static forces); 0: none.
    #[arg(long, default_value_t = 0.0)]
    pub force_noise: f64,
    /// Teacher-forcing epochs before the free-running phase.
    #[arg(long, default_value_t = 300)]
    pub teacher_epochs: usize,
    /// Digs per Adam step (mini-batches reshuffled every epoch, both phases); 0: the whole training set
    /// per step (one update per epoch, as the shipped networks were trained before 22 November).
    #[arg(long, default_value_t = 0)]
    pub batch_digs: usize,
    /// Also feed every network the rate of change of its own cylinder force over the last step (Eq. 2:
    /// the chamber pressure changes with the difference between valve flow and displacement, so it
    /// shows a load being taken up or let go).
    #[arg(long, conflicts_with_all = ["thesis_inputs", "orifice_inputs", "third_inputs"])]
    pub force_rate: bool,
    /// With `--force-rate`: probability with which a training dig's force rate is zeroed for one step
    /// of the optimiser, so the networks also learn the quasi-static case the dig model uses them in.
    #[arg(long, default_value_t = 0.0, requires = "force_rate")]
    pub force_rate_dropout: f64,
    /// Feed the networks the delayed commands through a first-order lag with the machine file's spool
    /// time constant (`lag_time_constant_s`): an estimate of the spool positions the valves meter with,
    /// instead of the delayed commands themselves.
    #[arg(long)]
    pub spool_lag: bool,
    /// Also feed every network the command and force of the third cylinder, so each sees all three
    /// valves and loads (the boom's crossover flow comes from the stick's pump).
    #[arg(long, conflicts_with_all = ["thesis_inputs", "orifice_inputs"])]
    pub third_inputs: bool,
    /// The target velocity signal (see [`VelocitySource`]).
    #[arg(long, value_enum, default_value_t = VelocitySource::Rates)]
    pub velocity: VelocitySource,
    /// The force inputs (see [`ForceSource`]).
    #[arg(long, value_enum, default_value_t = ForceSource::Measured)]
    pub forces: ForceSource,
    /// Learning-rate schedule: the step size of both phases falls along a half cosine to this
    /// fraction of its starting value (1: constant).
    #[arg(long, default_value_t = 1.0)]
    pub final_rate: f64,
    /// Trainings per network from different initial weights and batch orders; the one with the lowest
    /// validation loss is kept (the split and the test digs stay the seed's).
    #[arg(long, default_value_t = 1)]
    pub restarts: usize,
    /// Free-running epochs without a validation improvement before stopping.
    #[arg(long, default_value_t = 60)]
    pub patience: usize,
    /// Machine file (default: the built-in config/machine.toml).
    #[arg(long, value_name = "FILE")]
    pub machine: Option<PathBuf>,
}

/// Which digs of `train`'s split `model evaluate` runs on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum EvalSplit {
    /// The held-out test digs (the reported figure).
    Test,
    /// The validation digs (early stopping; the split to choose between trainings on).
    Validation,
    /// The training digs.
    Train,
}

/// Arguments of `model evaluate`.
#[derive(Debug, Args)]
pub struct EvaluateArgs {
    /// candump -L traces, in the order given to `model train`.
    #[arg(long, required = true, num_args = 1..)]
    pub trace: Vec<PathBuf>,
    /// Actuator model (default: the shipped config/nominal_actuator.json).
    #[arg(long, value_name = "FILE")]
    pub model: Option<PathBuf>,
    /// Seed of `train`'s split (the test digs are the ones `train --seed` held out).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Evaluate on every dig instead of the held-out test digs.
    #[arg(long)]
    pub all: bool,
    /// Which digs of the seed's split to evaluate on (ignored with `--all`).
    #[arg(long, value_enum, default_value_t = EvalSplit::Test)]
    pub split: EvalSplit,
    /// Hold the force-rate input at zero, as the dig model does with its quasi-static forces
    /// (with `--forces statics`: the networks as the dig model runs them).
    #[arg(long)]
    pub zero_rate: bool,
    /// The target velocity signal (see [`VelocitySource`]).
    #[arg(long, value_enum, default_value_t = VelocitySource::Rates)]
    pub velocity: VelocitySource,
    /// The force inputs (see [`ForceSource`]).
    #[arg(long, value_enum, default_value_t = ForceSource::Measured)]
    pub forces: ForceSource,
    /// Also split the error by samples where the rate and the resolver angles disagree (the
    /// simulator's phantom rate of a stalled cylinder) and report it against both targets.
    #[arg(long)]
    pub breakdown: bool,
    /// Also write every evaluated step as CSV (dig, time, Autodig stage, commands, forces, chamber and
    /// pump pressures, both velocity signals, the free-running prediction) for diagnosis.
    #[arg(long, value_name = "FILE")]
    pub dump: Option<PathBuf>,
    /// Machine file (default: the built-in config/machine.toml).
    #[arg(long, value_name = "FILE")]
    pub machine: Option<PathBuf>,
}

/// Arguments of `model generate-data`.
#[derive(Debug, Args)]
pub struct GenerateArgs {
    /// Output folder (one `dig_NNN.log` per dig and `setups.json`).
    #[arg(long)]
    pub out: PathBuf,
    /// Number of digs.
    #[arg(long, default_value_t = 60)]
    pub digs: usize,
    /// Seed of the starts, terrain and sensor noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Print every dig's statistics.
    #[arg(long)]
    pub verbose: bool,
}

/// Arguments of `model compare`.
#[derive(Debug, Args)]
pub struct CompareArgs {
    /// Number of digs.
    #[arg(long, default_value_t = 8)]
    pub digs: usize,
    /// Seed of the starts (different from the training data's by default).
    #[arg(long, default_value_t = 1001)]
    pub seed: u64,
    /// Actuator model (default: the shipped config/nominal_actuator.json).
    #[arg(long, value_name = "FILE")]
    pub model: Option<PathBuf>,
    /// Output folder for `compare.svg` and `compare.json`.
    #[arg(long, default_value = "model-compare")]
    pub out: PathBuf,
    /// Factor on the soil's force on the bucket in both the simulator and the dig model (thesis
    /// Table 2's force factor), to compare them in harder soil than the default bench's.
    #[arg(long, default_value_t = 1.0)]
    pub force_factor: f64,
    /// Print both trajectories every 0.2 s.
    #[arg(long)]
    pub verbose: bool,
}

/// The dig model and its start on the default bench (`model table2` and `model fig52`).
#[derive(Debug, Clone, Args)]
pub struct ModelStartArgs {
    /// Actuator model (default: the shipped config/nominal_actuator.json).
    #[arg(long, value_name = "FILE")]
    pub model: Option<PathBuf>,
    /// Start distance of the tip from the swing axis, m.
    #[arg(long, default_value_t = 7.8)]
    pub start_r: f64,
    /// Start bucket angle to the horizontal, degrees.
    #[arg(long, default_value_t = -55.0)]
    pub start_bucket_deg: f64,
    /// Start depth of the tip below the surface, m.
    #[arg(long, default_value_t = 0.02)]
    pub start_depth: f64,
}

impl Default for ModelStartArgs {
    /// The command-line defaults.
    fn default() -> Self {
        Self {
            model: None,
            start_r: 7.8,
            start_bucket_deg: -55.0,
            start_depth: 0.02,
        }
    }
}

impl ModelStartArgs {
    /// The dig model (the shipped one or `--model`'s actuator networks).
    ///
    /// # Errors
    /// Reading or parsing `--model`.
    pub fn load_model(&self) -> anyhow::Result<DigModel> {
        load_model(self.model.as_deref())
    }

    /// The start on `site`.
    ///
    /// # Errors
    /// `start_r` outside the site's section.
    pub fn start(&self, site: &DigSite) -> anyhow::Result<DigStart> {
        tip_start(site, self.start_r, self.start_depth, self.start_bucket_deg)
    }

    /// "tip D m deep at r = R m on the default bench, bucket B deg", for report headers.
    #[must_use]
    pub fn describe(&self) -> String {
        format!(
            "tip {:.2} m deep at r = {:.2} m on the default bench, bucket {:.0} deg",
            self.start_depth, self.start_r, self.start_bucket_deg
        )
    }
}

/// Arguments of `model table2`.
#[derive(Debug, Args)]
pub struct Table2Args {
    /// The model and its start.
    #[command(flatten)]
    pub start: ModelStartArgs,
    /// Also write the three predicted tip paths over the bench section (thesis Fig. 39) to
    /// `DIR/fig39_model.svg`.
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
}

/// Runs a `model` subcommand.
///
/// # Errors
/// Any failure, with its cause chain.
pub fn run(cmd: ModelCommand) -> anyhow::Result<()> {
    match cmd {
        ModelCommand::Train(a) => train(&a),
        ModelCommand::Evaluate(a) => evaluate(&a),
        ModelCommand::GenerateData(a) => generate(&a),
        ModelCommand::Compare(a) => compare(&a),
        ModelCommand::Table2(a) => table2(&a),
        ModelCommand::Fig52(a) => crate::model_fig52::run(&a),
        ModelCommand::SoilCv(a) => crate::soil_cv::run(&a),
    }
}

// ---------------------------------------------------------------------------------------------------
// Simulation harness
// ---------------------------------------------------------------------------------------------------

/// A small deterministic generator (SplitMix64) for the dig setups.
#[derive(Debug, Clone)]
struct SplitMix(u64);

impl SplitMix {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * ((self.next_u64() >> 11) as f64 / (1u64 << 53) as f64)
    }
}

/// One simulated dig: the bench, the soil and the start (Autodig starts in Pre-Dig there).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DigSetup {
    /// Dig number.
    pub index: usize,
    /// Simulator seed (sensor noise).
    pub seed: u64,
    /// Toe of the bench face, m from the machine.
    pub face_x_m: f64,
    /// Face angle, degrees.
    pub face_slope_deg: f64,
    /// Bench height, m.
    pub bench_height_m: f64,
    /// Soil cohesion, Pa.
    pub cohesion_pa: f64,
    /// Autodig hardness index.
    pub hardness_index: f64,
    /// Depth of the tip below the surface at the start, m.
    pub start_depth_m: f64,
    /// Start joint angles, rad.
    pub start: JointAngles,
    /// Factor on the soil's force on the bucket (thesis Table 2; the simulator's
    /// `soil_force_factor`, the dig model's force factor). 1 in files written before it existed.
    #[serde(default = "unit_factor")]
    pub soil_force_factor: f64,
}

fn unit_factor() -> f64 {
    1.0
}

/// The simulator configuration of a setup (default machine and bench, changed as the setup says).
///
/// # Errors
/// Loading the built-in files.
pub fn sim_config(setup: &DigSetup) -> anyhow::Result<SimConfig> {
    let mut cfg = SimConfig::load::<&str>(None, None, Some(setup.seed), &[])?;
    let s = &mut cfg.scenario;
    s.bench.face_x_m = setup.face_x_m;
    s.bench.face_slope_deg = setup.face_slope_deg;
    s.bench.height_m = setup.bench_height_m;
    s.soil.cohesion_pa = setup.cohesion_pa;
    s.start.boom_deg = setup.start.boom_rad.to_degrees();
    s.start.stick_deg = setup.start.stick_rad.to_degrees();
    s.start.bucket_deg = setup.start.bucket_rad.to_degrees();
    s.start.swing_deg = 0.0;
    if setup.soil_force_factor != 1.0 {
        s.soil_force_factor = Some(setup.soil_force_factor);
    }
    Ok(cfg)
}

fn section_of(world: &World, cfg: &SimConfig) -> anyhow::Result<SectionProfile> {
    let pose = planner::kinematics::MachinePose {
        x_m: cfg.scenario.start.x_m,
        y_m: cfg.scenario.start.y_m,
        heading_rad: cfg.scenario.start.heading_deg.to_radians(),
    };
    Ok(world
        .terrain
        .section(&pose, 0.0, SECTION_R.0, SECTION_R.1, SECTION_R.2)?)
}

/// `n` setups drawn from `seed`. With `vary` the bench, cohesion and hardness index vary too
/// (training data); without, the default bench and soil and hardness 3 (comparison with the
/// nominal model), varying only the start.
///
/// # Errors
/// Loading the built-in files, or no reachable start found.
pub fn random_setups(n: usize, seed: u64, vary: bool) -> anyhow::Result<Vec<DigSetup>> {
    let base = SimConfig::load::<&str>(None, None, Some(seed), &[])?;
    let kin = Kinematics::new(&base.machine)?;
    let mut rng = SplitMix(seed ^ 0x05EE_DD16);
    let mut out = Vec::with_capacity(n);
    for index in 0..n {
        let mut found = None;
        for _ in 0..200 {
            let mut setup = DigSetup {
                index,
                seed: seed.wrapping_mul(1000).wrapping_add(index as u64),
                face_x_m: base.scenario.bench.face_x_m,
                face_slope_deg: base.scenario.bench.face_slope_deg,
                bench_height_m: base.scenario.bench.height_m,
                cohesion_pa: base.scenario.soil.cohesion_pa,
                hardness_index: 3.0,
                start_depth_m: rng.uniform(0.0, 0.05),
                start: JointAngles::default(),
                soil_force_factor: 1.0,
            };
            if vary {
                setup.face_x_m = rng.uniform(2.5, 4.0);
                setup.face_slope_deg = rng.uniform(30.0, 60.0);
                setup.bench_height_m = rng.uniform(1.2, 2.5);
                setup.cohesion_pa = rng.uniform(3e3, 16e3);
                setup.hardness_index = rng.uniform(1.0, 5.0);
            }
            let r = rng.uniform(setup.face_x_m + 0.8, 8.6);
            let bucket_abs = rng.uniform(-65.0_f64, -45.0).to_radians();
            let mut cfg = sim_config(&setup)?;
            cfg.scenario.start.boom_deg = 40.0;
            let world = World::from_scenario(&cfg.scenario)?;
            let profile = section_of(&world, &cfg)?;
            let z = profile.height_at(r)? - setup.start_depth_m;
            let Ok(q) = kin.inverse(&BucketPose {
                x_m: r,
                z_m: z,
                bucket_abs_rad: bucket_abs,
            }) else {
                continue;
            };
            // The stick out (thesis Table 1: -87 to -50 deg): Dig brings it in to beta.
            if q.stick_abs_rad().to_degrees() > -25.0 || q.stick_abs_rad().to_degrees() < -70.0 {
                continue;
            }
            setup.start = q;
            found = Some(setup);
            break;
        }
        match found {
            Some(s) => out.push(s),
            None => bail!("no reachable start found for dig {index}"),
        }
    }
    Ok(out)
}

/// One 10 ms sample of a simulated dig (from the sensor readings, as the controller sees them).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SimSample {
    /// Time since the start of Autodig, s.
    pub time_s: f64,
    /// Tip `x` from the sensed angles, m.
    pub tip_x_m: f64,
    /// Tip `z`, m.
    pub tip_z_m: f64,
    /// Bucket angle to the horizontal, rad.
    pub bucket_abs_rad: f64,
    /// Autodig command.
    pub command: [f64; 3],
    /// Cylinder forces from the measured pressures (Eq. A20), N.
    pub force_n: [f64; 3],
    /// Head pressures, Pa.
    pub head_pa: [f64; 3],
    /// Rod pressures, Pa.
    pub rod_pa: [f64; 3],
    /// Sensed joint angles `[boom, stick, bucket]`, rad.
    pub joint_rad: [f64; 3],
    /// Autodig's stage for this command.
    pub stage: Stage,
    /// True soil force on the bucket `[F_x, F_z]` (the simulator's contact model), N.
    pub soil_force_n: [f64; 2],
    /// True cylinder velocities, m/s.
    pub velocity_m_per_s: [f64; 3],
    /// Swept volume so far (perception), m^3.
    pub swept_volume_m3: f64,
    /// Model soil force `[F_x, F_z]` at this pose and motion over the simulator's current terrain
    /// (open loop; only with `diagnose`), N.
    pub model_soil_force_n: Option<[f64; 2]>,
    /// Static cylinder forces at the true pose with the true soil force and bucket content
    /// (`tau = G - J^T f`, `F = tau / r`, Eqs. A2, A4, A7, A19; only with `diagnose`), N: what the
    /// model's statics make of the simulator's load, against the measured `force_n`.
    pub static_force_n: Option<[f64; 3]>,
}

/// A simulated dig and its statistics (measured like the controller's `DigStats`).
#[derive(Debug, Clone, PartialEq)]
pub struct SimDig {
    /// The setup.
    pub setup: DigSetup,
    /// The pre-dig section along the digging plane (true terrain).
    pub profile: SectionProfile,
    /// Samples from the start of Autodig.
    pub samples: Vec<SimSample>,
    /// Dig time, s.
    pub time_s: f64,
    /// `sum |F dL|` from the measured pressures (Eq. A20) and sensed angles, J.
    pub energy_j: f64,
    /// Swept volume over the pre-dig section along the sensed tip path, m^3.
    pub swept_volume_m3: f64,
    /// Bank volume in the bucket at the end (the simulator's ledger), m^3.
    pub bucket_volume_m3: f64,
    /// Autodig's end reason (`None`: stopped at the time limit).
    pub end: Option<EndReason>,
    /// True joint angles when Autodig started (the machine may settle during the idle time before).
    pub start_joints: JointAngles,
}

fn stage_code(stage: Stage) -> AutodigStageCode {
    match stage {
        Stage::BoomDown => AutodigStageCode::BoomDown,
        Stage::PreDig => AutodigStageCode::PreDig,
        Stage::Dig => AutodigStageCode::Dig,
        Stage::Capture => AutodigStageCode::Capture,
        Stage::Done => AutodigStageCode::Done,
    }
}

struct Recorder<'a> {
    writer: Option<&'a mut TraceWriter<BufWriter<File>>>,
}

impl Recorder<'_> {
    fn emit(&mut self, t_s: f64, msg: Message, dir: Direction) -> anyhow::Result<()> {
        if let Some(w) = self.writer.as_deref_mut() {
            let frame = msg.encode()?;
            w.write((t_s * 1e9).round() as u64, &frame, dir)?;
        }
        Ok(())
    }
}

/// Runs one dig in the simulator: neutral for 0.3 s, Autodig from Pre-Dig on the sensor readings
/// (with the perception enhancements over the true pre-dig section), neutral for 0.3 s; records the
/// frames into `trace` if given.
///
/// # Errors
/// Building the plant, Autodig errors, encoding or writing frames.
pub fn run_sim_dig(
    setup: &DigSetup,
    trace: Option<&mut TraceWriter<BufWriter<File>>>,
) -> anyhow::Result<SimDig> {
    run_sim_dig_diagnosed(setup, trace, None)
}

/// [`run_sim_dig`], and with `diagnose` the model's soil force at every sample's true pose and cylinder
/// velocities over the simulator's current (cut) terrain and true bucket content (open loop: is the
/// soil force in the model the simulator's?).
///
/// # Errors
/// As [`run_sim_dig`].
pub fn run_sim_dig_diagnosed(
    setup: &DigSetup,
    trace: Option<&mut TraceWriter<BufWriter<File>>>,
    diagnose: Option<&DigModel>,
) -> anyhow::Result<SimDig> {
    let cfg = sim_config(setup)?;
    let mut plant = cfg.build()?;
    let kin = Kinematics::new(&cfg.machine)?;
    let profile = section_of(&plant.world, &cfg)?;
    let mut swept = SweptVolume::new(profile.clone(), cfg.machine.bucket.width_m)?;
    let mut ad_cfg = DigModelConfig::nominal()?.autodig;
    ad_cfg.relief_pressure_pa = [cfg.machine.hydraulics.relief_pressure_pa; 3];
    ad_cfg.perception.bucket_capacity_m3 = cfg.machine.bucket.capacity_m3;
    ad_cfg.hardness_index = setup.hardness_index;
    let mut autodig = Autodig::starting_in(ad_cfg, AutodigMaps::builtin()?, Stage::PreDig)?;
    let cyl = &cfg.machine.cylinders;
    let areas = [&cyl.boom, &cyl.stick, &cyl.bucket].map(|c| (c.head_area_m2(), c.rod_area_m2()));
    let strokes = Joint::ALL.map(|j| kin.stroke(j));
    let dig_index = u16::try_from(setup.index % 60_000).unwrap_or(0);

    let mut rec = Recorder { writer: trace };
    let idle_steps = (IDLE_S / PERIOD_S).round() as usize;
    let max_dig_steps = (SIM_MAX_DIG_S / PERIOD_S).round() as usize;
    let mut samples = Vec::with_capacity(max_dig_steps);
    let mut energy_j = 0.0;
    let mut last_len: Option<[f64; 3]> = None;
    let mut dig_start_s = None;
    let mut dig_time_s = 0.0;
    let mut end = None;
    let mut post = 0usize;
    let mut command = [0.0; 3];
    let mut stage = Stage::PreDig;
    let mut alive = 0u8;
    let mut start_joints = setup.start;
    for step in 0usize.. {
        let t = plant.time_s();
        let r = plant.read_sensors();
        // The gateway's sensor frames.
        for msg in vcan_sim::node::sensor_messages(&plant, &r, command) {
            rec.emit(t, msg, Direction::Receive)?;
        }

        // The controller's step.
        let q = JointAngles {
            boom_rad: r.angles_rad[0],
            stick_rad: r.angles_rad[1],
            bucket_rad: r.angles_rad[2],
        };
        let mut activity = Activity::Idle;
        match (dig_start_s, end.is_some() || post > 0) {
            (None, _) if step < idle_steps => command = [0.0; 3],
            (_, false) => {
                if dig_start_s.is_none() {
                    start_joints = plant.joint_angles();
                }
                let t0 = *dig_start_s.get_or_insert(t);
                activity = Activity::Dig;
                let tip = kin.forward(&q);
                let swept_m3 = swept.update(tip.x_m, tip.z_m).ok();
                let depth_m = swept.depth_m(tip.x_m, tip.z_m).ok();
                let mut len = [0.0; 3];
                let mut ext = [0.0; 3];
                let mut force = [0.0; 3];
                for (j, joint) in Joint::ALL.iter().enumerate() {
                    len[j] = kin.cylinder_length(*joint, q.to_vector()[j])?;
                    ext[j] =
                        ((len[j] - strokes[j].0) / (strokes[j].1 - strokes[j].0)).clamp(0.0, 1.0);
                    force[j] = r.head_pa[j] * areas[j].0 - r.rod_pa[j] * areas[j].1; // Eq. A20
                }
                if let Some(prev) = last_len {
                    energy_j += (0..3)
                        .map(|j| (force[j] * (len[j] - prev[j])).abs())
                        .sum::<f64>();
                }
                last_len = Some(len);
                let inputs = AutodigInputs {
                    joint_rad: [q.boom_rad, q.stick_rad, q.bucket_rad],
                    head_pressure_pa: r.head_pa,
                    rod_pressure_pa: r.rod_pa,
                    extension_fraction: ext,
                    swept_volume_m3: swept_m3,
                    bucket_depth_m: depth_m,
                };
                let out = autodig.step(&inputs, t - t0)?;
                stage = out.stage;
                command = out.command;
                let truth = plant.true_state();
                let velocity = [0, 1, 2].map(|i| plant.hydraulics.actuators[i].velocity);
                let static_force_n = diagnose
                    .map(|_| {
                        kin.cylinder_forces_from_tip_force(
                            &plant.joint_angles(),
                            &planner::kinematics::TipForce {
                                fx_n: truth.soil_force_n[0],
                                fz_n: truth.soil_force_n[1],
                                my_nm: 0.0,
                            },
                            plant.contact.content.mass_kg,
                        )
                    })
                    .transpose()?
                    .map(|f| [f[0], f[1], f[2]]);
                let model_soil_force_n = match diagnose {
                    Some(m) => {
                        let now = section_of(&plant.world, &cfg)?;
                        let f = m.soil_force_at(
                            &plant.joint_angles(),
                            velocity,
                            &now,
                            plant.contact.content.volume_m3,
                        )?;
                        // `soil_force_at` is before the force factor; the simulator's is after.
                        let k = setup.soil_force_factor;
                        Some([k * f.fx_n, k * f.fz_n])
                    }
                    None => None,
                };
                samples.push(SimSample {
                    time_s: t - t0,
                    tip_x_m: tip.x_m,
                    tip_z_m: tip.z_m,
                    bucket_abs_rad: tip.bucket_abs_rad,
                    command,
                    force_n: force,
                    head_pa: r.head_pa,
                    rod_pa: r.rod_pa,
                    joint_rad: [q.boom_rad, q.stick_rad, q.bucket_rad],
                    stage: out.stage,
                    soil_force_n: truth.soil_force_n,
                    velocity_m_per_s: velocity,
                    swept_volume_m3: swept.volume_m3(),
                    model_soil_force_n,
                    static_force_n,
                });
                if out.stage == Stage::Done || samples.len() > max_dig_steps {
                    end = out.end_reason;
                    dig_time_s = t - t0;
                    post = 1;
                    command = [0.0; 3];
                }
            }
            (_, true) => {
                command = [0.0; 3];
                post += 1;
            }
        }
        for (i, valve) in Valve::ALL.iter().enumerate() {
            let u = if i < 3 { command[i] } else { 0.0 };
            rec.emit(
                t,
                Message::AuxValveCommand(AuxValveCommand::from_fraction(*valve, u)?),
                Direction::Transmit,
            )?;
        }
        rec.emit(
            t,
            Message::ControllerHeartbeat(ControllerHeartbeat {
                mode: RequestedMode::ArmValve,
                alive_counter: alive,
            }),
            Direction::Transmit,
        )?;
        if step % 5 == 0 {
            rec.emit(
                t,
                Message::ControllerStatus(ControllerStatus {
                    activity,
                    stage: if activity == Activity::Dig {
                        stage_code(stage)
                    } else {
                        AutodigStageCode::None
                    },
                    dig_index,
                    hardness_index: setup.hardness_index.clamp(0.0, 12.5),
                    swept_volume_m3: swept.volume_m3().clamp(0.0, 6.4),
                    fault_reason: 0,
                    alive_counter: alive,
                }),
                Direction::Transmit,
            )?;
        }
        alive = (alive + 1) % 16;
        if post > idle_steps {
            break;
        }
        for _ in 0..PHYSICS_PER_PERIOD {
            plant.step([command[0], command[1], command[2], 0.0, 0.0, 0.0]);
        }
    }
    Ok(SimDig {
        setup: setup.clone(),
        profile,
        samples,
        time_s: dig_time_s,
        energy_j,
        swept_volume_m3: swept.volume_m3(),
        bucket_volume_m3: plant.contact.content.volume_m3,
        end,
        start_joints,
    })
}

/// Model-versus-simulator figures of one dig (thesis Figs. 34, 40, 41).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DigComparison {
    /// Dig number.
    pub index: usize,
    /// RMS distance between the predicted and measured tip paths (symmetric nearest-point), m.
    pub trajectory_rms_m: f64,
    /// Measured and predicted dig time, s.
    pub time_s: [f64; 2],
    /// Measured and predicted energy, kJ.
    pub energy_kj: [f64; 2],
    /// Measured and predicted swept volume, m^3.
    pub volume_m3: [f64; 2],
    /// Relative errors (model - measured) / measured, %: time, energy, volume.
    pub error_percent: [f64; 3],
    /// Measured and predicted end reasons.
    pub end: [String; 2],
    /// Open-loop soil force error: RMS of `|F_model - F_sim|` over the simulated dig's samples in
    /// contact, with the model's soil force at the simulator's true pose, motion, terrain and bucket
    /// content, as a % of the RMS simulated force (`None` without the diagnosis).
    pub soil_force_error_percent: Option<f64>,
    /// Measured and predicted lowest tip elevation, m.
    pub min_tip_z_m: [f64; 2],
}

/// Distance from `p` to the polyline `line`, m.
fn distance_to_polyline(p: [f64; 2], line: &[[f64; 2]]) -> f64 {
    if line.len() == 1 {
        return (p[0] - line[0][0]).hypot(p[1] - line[0][1]);
    }
    line.windows(2)
        .map(|w| {
            let (a, b) = (w[0], w[1]);
            let d = [b[0] - a[0], b[1] - a[1]];
            let len2 = d[0] * d[0] + d[1] * d[1];
            let t = if len2 > 0.0 {
                (((p[0] - a[0]) * d[0] + (p[1] - a[1]) * d[1]) / len2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            (p[0] - a[0] - t * d[0]).hypot(p[1] - a[1] - t * d[1])
        })
        .fold(f64::INFINITY, f64::min)
}

/// Symmetric RMS distance between two paths, m (each point of one to the other polyline).
#[must_use]
pub fn path_rms_m(a: &[[f64; 2]], b: &[[f64; 2]]) -> f64 {
    if a.is_empty() || b.is_empty() {
        return f64::INFINITY;
    }
    let sq = |from: &[[f64; 2]], to: &[[f64; 2]]| {
        from.iter()
            .map(|p| distance_to_polyline(*p, to).powi(2))
            .sum::<f64>()
            / from.len() as f64
    };
    (0.5 * (sq(a, b) + sq(b, a))).sqrt()
}

fn percent(model: f64, measured: f64) -> f64 {
    if measured.abs() > 1e-12 {
        100.0 * (model - measured) / measured
    } else {
        0.0
    }
}

/// Runs the dig model from the simulator's start (joint angles when Autodig began) over its pre-dig
/// section and compares.
///
/// # Errors
/// The dig model's errors.
pub fn compare_dig(
    model: &DigModel,
    sim: &SimDig,
) -> anyhow::Result<(DigComparison, DigPrediction)> {
    let mut model = model.clone();
    model.set_hardness_index(sim.setup.hardness_index)?;
    model.set_force_factor(sim.setup.soil_force_factor)?;
    let site = DigSite::new(sim.profile.clone(), 0.0)?;
    let pred = model
        .predict(&DigStart::Joints(sim.start_joints), &site)
        .with_context(|| format!("dig model, dig {}", sim.setup.index))?;
    let measured: Vec<[f64; 2]> = sim.samples.iter().map(|s| [s.tip_x_m, s.tip_z_m]).collect();
    let predicted: Vec<[f64; 2]> = pred
        .samples
        .iter()
        .map(|s| [s.tip_x_m, s.tip_z_m])
        .collect();
    let s = &pred.summary;
    let cmp = DigComparison {
        index: sim.setup.index,
        trajectory_rms_m: path_rms_m(&measured, &predicted),
        time_s: [sim.time_s, s.time_s],
        energy_kj: [sim.energy_j * 1e-3, s.energy_kj()],
        volume_m3: [sim.swept_volume_m3, s.swept_volume_m3],
        error_percent: [
            percent(s.time_s, sim.time_s),
            percent(s.energy_j, sim.energy_j),
            percent(s.swept_volume_m3, sim.swept_volume_m3),
        ],
        end: [
            sim.end
                .map_or_else(|| "time limit".to_owned(), |e| format!("{e:?}")),
            format!("{:?}", s.end),
        ],
        soil_force_error_percent: open_loop_soil_error_percent(&sim.samples),
        min_tip_z_m: [
            sim.samples
                .iter()
                .map(|s| s.tip_z_m)
                .fold(f64::INFINITY, f64::min),
            s.min_tip_z_m,
        ],
    };
    Ok((cmp, pred))
}

/// RMS of the open-loop soil force error over the samples with a simulated soil force, as a % of the
/// RMS simulated force (`None` without model forces or contact).
fn open_loop_soil_error_percent(samples: &[SimSample]) -> Option<f64> {
    let (mut err2, mut ref2, mut n) = (0.0, 0.0, 0usize);
    for s in samples {
        let Some(m) = s.model_soil_force_n else {
            continue;
        };
        let f = s.soil_force_n;
        if f[0].hypot(f[1]) < 1.0 && m[0].hypot(m[1]) < 1.0 {
            continue;
        }
        err2 += (m[0] - f[0]).powi(2) + (m[1] - f[1]).powi(2);
        ref2 += f[0] * f[0] + f[1] * f[1];
        n += 1;
    }
    (n > 0 && ref2 > 0.0).then(|| 100.0 * (err2 / ref2).sqrt())
}

/// Mean of the absolute relative errors `[time, energy, volume]`, % and the mean trajectory RMS, m.
#[must_use]
pub fn mean_errors(c: &[DigComparison]) -> ([f64; 3], f64) {
    let n = c.len().max(1) as f64;
    let mut e = [0.0; 3];
    for d in c {
        for (k, v) in d.error_percent.iter().enumerate() {
            e[k] += v.abs() / n;
        }
    }
    (e, c.iter().map(|d| d.trajectory_rms_m).sum::<f64>() / n)
}

// ---------------------------------------------------------------------------------------------------
// generate-data
// ---------------------------------------------------------------------------------------------------

fn generate(a: &GenerateArgs) -> anyhow::Result<()> {
    if a.digs == 0 {
        bail!("--digs must be at least 1");
    }
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let setups = random_setups(a.digs, a.seed, true)?;
    let bar = indicatif::ProgressBar::new(setups.len() as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} digs {elapsed} {msg}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let results: Vec<anyhow::Result<SimDig>> = setups
        .par_iter()
        .map(|s| {
            let path = a.out.join(format!("dig_{:03}.log", s.index));
            let file =
                File::create(&path).with_context(|| format!("creating {}", path.display()))?;
            let mut w = TraceWriter::new(BufWriter::new(file), "vcan0", true);
            let dig = run_sim_dig(s, Some(&mut w))?;
            w.flush()?;
            bar.inc(1);
            Ok(dig)
        })
        .collect();
    bar.finish_and_clear();
    let mut volume = 0.0;
    let mut time = 0.0;
    for r in &results {
        let d = r.as_ref().map_err(|e| anyhow::anyhow!("{e:#}"))?;
        volume += d.swept_volume_m3;
        time += d.time_s;
        if a.verbose {
            let first = d
                .samples
                .first()
                .map_or([0.0; 2], |s| [s.tip_x_m, s.tip_z_m]);
            let min_z = d
                .samples
                .iter()
                .map(|s| s.tip_z_m)
                .fold(f64::INFINITY, f64::min);
            println!(
                "  dig {:>3}: start r {:.2} z {:.2}, lowest z {:.2}, {:.2} s, swept {:.2} m^3, bucket {:.2} m^3, {:.0} kJ, end {:?}",
                d.setup.index,
                first[0],
                first[1],
                min_z,
                d.time_s,
                d.swept_volume_m3,
                d.bucket_volume_m3,
                d.energy_j * 1e-3,
                d.end
            );
        }
    }
    std::fs::write(
        a.out.join("setups.json"),
        serde_json::to_string_pretty(&setups)?,
    )?;
    let n = setups.len() as f64;
    println!(
        "wrote {} dig traces to {} (mean dig {:.2} s, swept {:.2} m^3)",
        setups.len(),
        a.out.display(),
        time / n,
        volume / n
    );
    Ok(())
}

// ---------------------------------------------------------------------------------------------------
// train
// ---------------------------------------------------------------------------------------------------

#[derive(Debug, Clone, Copy)]
struct Tagged {
    sample: TraceSample,
    /// Moment arms at the sample's pose, m.
    arms: [f64; 3],
    /// Sensed joint angles `[boom, stick, bucket]`, rad.
    angles_rad: [f64; 3],
    /// `Some(dig index)` when a ControllerStatus said Dig or Cleanup.
    dig: Option<u16>,
}

/// Half width, in samples, of the least-squares slope that turns the resolver angles into rates
/// ([`VelocitySource::Angles`]): 11 samples at 100 Hz. The resolvers are quantised to 14 bits
/// (3.8e-4 rad) with 2e-4 rad of noise; a one-step difference would carry 0.03 rad/s of noise, the
/// slope over 0.1 s about 0.002 rad/s.
pub const ANGLE_SLOPE_HALF_WINDOW: usize = 5;

/// One training sample of a trace with both velocity signals.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TraceSample {
    /// The sample, its velocities from the sampled joint rates ([`VelocitySource::Rates`]).
    pub sample: ActuatorSample,
    /// Cylinder velocities from the slope of the resolver angles ([`VelocitySource::Angles`]), m/s.
    pub angle_velocity_m_per_s: [f64; 3],
    /// Sensed joint angles `[boom, stick, bucket]`, rad.
    pub angles_rad: [f64; 3],
    /// Measured head-side pressures `[boom, stick, bucket]`, Pa (diagnosis: `evaluate --dump`).
    pub head_pa: [f64; 3],
    /// Measured rod-side pressures `[boom, stick, bucket]`, Pa.
    pub rod_pa: [f64; 3],
    /// Measured pump gallery pressures `[pump 1 (boom, bucket), pump 2 (stick, swing)]`, Pa (0 in
    /// traces without `PumpPressures`).
    pub pump_pa: [f64; 2],
    /// Autodig stage of the latest `ControllerStatus` (0 without one).
    pub stage: u8,
}

/// One dig of a trace with both velocity signals ([`read_training_digs`]).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TraceDig {
    /// Samples in time order.
    pub samples: Vec<TraceSample>,
}

impl TraceDig {
    /// The dig as actuator training data with the velocities from `source`.
    #[must_use]
    pub fn to_actuator_dig(&self, source: VelocitySource) -> ActuatorDig {
        ActuatorDig {
            samples: self
                .samples
                .iter()
                .map(|s| match source {
                    VelocitySource::Rates => s.sample,
                    VelocitySource::Angles => ActuatorSample {
                        velocity_m_per_s: s.angle_velocity_m_per_s,
                        ..s.sample
                    },
                })
                .collect(),
        }
    }
}

/// Least-squares slope of `angles` against `times` over the samples `lo..=hi`, rad/s.
fn angle_slope(tagged: &[Tagged], lo: usize, hi: usize) -> [f64; 3] {
    let window = &tagged[lo..=hi];
    let n = window.len() as f64;
    let t_mean = window.iter().map(|s| s.sample.sample.time_s).sum::<f64>() / n;
    let stt: f64 = window
        .iter()
        .map(|s| (s.sample.sample.time_s - t_mean).powi(2))
        .sum();
    [0, 1, 2].map(|j| {
        if stt <= 0.0 {
            return 0.0;
        }
        let q_mean = window.iter().map(|s| s.angles_rad[j]).sum::<f64>() / n;
        window
            .iter()
            .map(|s| (s.sample.sample.time_s - t_mean) * (s.angles_rad[j] - q_mean))
            .sum::<f64>()
            / stt
    })
}

/// Reads the training digs of one trace: samples at every `JointAngles` frame with the latest
/// commands, pressures (-> Eq. A20 forces) and cylinder velocities through the moment arms, both from
/// the sampled rates and from the slope of the resolver angles ([`TraceSample`]), segmented by
/// `ControllerStatus` (activity Dig or Cleanup, per dig index) or, in traces without it, by command
/// activity (runs of non-neutral commands, split by 1 s of neutral).
///
/// # Errors
/// Opening or reading the file.
pub fn read_training_digs(
    path: &Path,
    kin: &Kinematics,
    areas: [(f64, f64); 3],
) -> anyhow::Result<Vec<TraceDig>> {
    let file = File::open(path).with_context(|| format!("opening {}", path.display()))?;
    let reader = TraceReader::new(BufReader::new(file), ReadMode::Skip);
    let mut command = [0.0; 3];
    let mut head = [0.0; 3];
    let mut rod = [0.0; 3];
    let mut rates: Option<[f64; 3]> = None;
    let mut pump = [0.0; 2];
    let mut pending: Option<(f64, JointAngles)> = None;
    let mut status: Option<(Activity, u16, u8)> = None;
    let mut seen_status = false;
    let mut tagged: Vec<Tagged> = Vec::new();
    let mut flush = |pending: &mut Option<(f64, JointAngles)>,
                     rates: &Option<[f64; 3]>,
                     command: &[f64; 3],
                     head: &[f64; 3],
                     rod: &[f64; 3],
                     pump: &[f64; 2],
                     status: &Option<(Activity, u16, u8)>| {
        if let (Some((t, q)), Some(w)) = (pending.take(), rates)
            && let Ok(arms) = kin.moment_arms(&q)
        {
            let sample = ActuatorSample {
                time_s: t,
                command: *command,
                force_n: [0, 1, 2].map(|j| head[j] * areas[j].0 - rod[j] * areas[j].1), // Eq. A20
                velocity_m_per_s: [0, 1, 2].map(|j| arms[j] * w[j]),
            };
            let dig = match status {
                Some((Activity::Dig | Activity::Cleanup, i, _)) => Some(*i),
                _ => None,
            };
            let angles_rad = [q.boom_rad, q.stick_rad, q.bucket_rad];
            if sample
                .force_n
                .iter()
                .chain(&sample.velocity_m_per_s)
                .chain(&angles_rad)
                .all(|v| v.is_finite())
            {
                tagged.push(Tagged {
                    sample: TraceSample {
                        sample,
                        angle_velocity_m_per_s: [0.0; 3],
                        angles_rad,
                        head_pa: *head,
                        rod_pa: *rod,
                        pump_pa: *pump,
                        stage: status.map_or(0, |s| s.2),
                    },
                    arms: [arms[0], arms[1], arms[2]],
                    angles_rad,
                    dig,
                });
            }
        }
    };
    for record in trace_tools::input::records_until_cut(path, reader) {
        let record = record.with_context(|| format!("reading {}", path.display()))?;
        let Ok(decoded) = Message::decode(&record.frame) else {
            continue;
        };
        let t = record.timestamp_ns as f64 * 1e-9;
        match decoded.message {
            Message::JointAngles(a) => {
                flush(&mut pending, &rates, &command, &head, &rod, &pump, &status);
                pending = Some((
                    t,
                    JointAngles {
                        boom_rad: a.boom_rad,
                        stick_rad: a.stick_rad,
                        bucket_rad: a.bucket_rad,
                    },
                ));
            }
            Message::JointRates(r) => {
                rates = Some([r.boom_rad_per_s, r.stick_rad_per_s, r.bucket_rad_per_s]);
            }
            Message::AuxValveMeasured(m) => {
                let i = usize::from(m.cylinder.number());
                head[i] = m.head_pressure_pa;
                rod[i] = m.rod_pressure_pa;
            }
            Message::AuxValveCommand(c) => {
                let i = usize::from(c.valve.number());
                if i < 3 {
                    command[i] = c.to_fraction();
                }
            }
            Message::ControllerStatus(s) => {
                seen_status = true;
                status = Some((s.activity, s.dig_index, s.stage as u8));
            }
            Message::PumpPressures(p) => pump = [p.pump1_pa, p.pump2_pa],
            _ => {}
        }
    }
    flush(&mut pending, &rates, &command, &head, &rod, &pump, &status);
    // Angle-derived velocities: the slope over the neighbouring samples of the same run (no gap
    // above 50 ms), at the sample's moment arms.
    let run_start: Vec<usize> = {
        let mut start = 0;
        (0..tagged.len())
            .map(|k| {
                if k > 0
                    && tagged[k].sample.sample.time_s - tagged[k - 1].sample.sample.time_s > 0.05
                {
                    start = k;
                }
                start
            })
            .collect()
    };
    let mut run_end = vec![0; tagged.len()];
    for k in (0..tagged.len()).rev() {
        run_end[k] = if k + 1 < tagged.len() && run_start[k + 1] == run_start[k] {
            run_end[k + 1]
        } else {
            k
        };
    }
    for k in 0..tagged.len() {
        let lo = k.saturating_sub(ANGLE_SLOPE_HALF_WINDOW).max(run_start[k]);
        let hi = (k + ANGLE_SLOPE_HALF_WINDOW).min(run_end[k]);
        let w = angle_slope(&tagged, lo, hi);
        let arms = tagged[k].arms;
        tagged[k].sample.angle_velocity_m_per_s = [0, 1, 2].map(|j| arms[j] * w[j]);
    }
    let mut digs = Vec::new();
    let mut current: Vec<TraceSample> = Vec::new();
    let mut current_key: Option<u16> = None;
    let mut neutral_since: Option<f64> = None;
    let finish = |current: &mut Vec<TraceSample>, digs: &mut Vec<TraceDig>| {
        if current.len() >= 50 {
            digs.push(TraceDig {
                samples: std::mem::take(current),
            });
        } else {
            current.clear();
        }
    };
    for s in &tagged {
        let key = if seen_status {
            s.dig
        } else {
            // Command activity: a dig runs while some command is non-neutral, until 1 s of neutral.
            let active = s.sample.sample.command.iter().any(|u| u.abs() > 1e-3);
            if active {
                neutral_since = None;
                Some(0)
            } else {
                let since = *neutral_since.get_or_insert(s.sample.sample.time_s);
                (s.sample.sample.time_s - since < 1.0 && !current.is_empty()).then_some(0)
            }
        };
        if key != current_key {
            finish(&mut current, &mut digs);
            current_key = key;
        }
        if key.is_some() {
            current.push(s.sample);
        }
    }
    finish(&mut current, &mut digs);
    Ok(digs)
}

/// Reads the digs of `traces` for training or evaluation (cut short at implausible sampled rates).
fn load_trace_digs(
    traces: &[PathBuf],
    machine: &planner::machine::MachineConfig,
    forces: ForceSource,
) -> anyhow::Result<Vec<TraceDig>> {
    let kin = Kinematics::new(machine)?;
    let c = &machine.cylinders;
    let areas = [&c.boom, &c.stick, &c.bucket].map(|c| (c.head_area_m2(), c.rod_area_m2()));
    let mut digs = Vec::new();
    let mut implausible = 0usize;
    let mut setups: std::collections::HashMap<PathBuf, Vec<DigSetup>> =
        std::collections::HashMap::new();
    let mut model = match forces {
        ForceSource::Measured | ForceSource::Mixed => None,
        ForceSource::Statics => Some(DigModel::nominal()?),
    };
    for path in traces {
        let mut trace_digs = read_training_digs(path, &kin, areas)?;
        if let Some(model) = model.as_mut() {
            let setup = trace_setup(path, &mut setups)?;
            for dig in &mut trace_digs {
                replace_with_statics(dig, &setup, model, &kin, machine)?;
            }
        }
        for mut dig in trace_digs {
            // A cylinder faster than the pumps can drive it is a glitch, not hydraulics: keep the
            // dig up to it.
            if let Some(k) = dig.samples.iter().position(|s| {
                s.sample
                    .velocity_m_per_s
                    .iter()
                    .any(|v| v.abs() > MAX_CYLINDER_SPEED_M_PER_S)
            }) {
                implausible += 1;
                dig.samples.truncate(k);
            }
            if dig.samples.len() >= 50 {
                digs.push(dig);
            }
        }
    }
    if implausible > 0 {
        println!(
            "cut {implausible} dig(s) short at a cylinder speed above {MAX_CYLINDER_SPEED_M_PER_S} m/s"
        );
    }
    if digs.len() < 3 {
        bail!(
            "found {} digs in the traces; training needs at least 3",
            digs.len()
        );
    }
    Ok(digs)
}

/// The setup of a `model generate-data` trace (`dig_NNN.log`) from `setups.json` in its folder.
fn trace_setup(
    path: &Path,
    cache: &mut std::collections::HashMap<PathBuf, Vec<DigSetup>>,
) -> anyhow::Result<DigSetup> {
    let dir = path.parent().unwrap_or(Path::new(".")).to_path_buf();
    let index: usize = path
        .file_stem()
        .and_then(|s| s.to_str())
        .and_then(|s| s.strip_prefix("dig_"))
        .and_then(|s| s.parse().ok())
        .with_context(|| {
            format!(
                "--forces statics needs generate-data traces named dig_NNN.log, not {}",
                path.display()
            )
        })?;
    if !cache.contains_key(&dir) {
        let file = dir.join("setups.json");
        let text = std::fs::read_to_string(&file)
            .with_context(|| format!("reading {} (--forces statics)", file.display()))?;
        cache.insert(dir.clone(), serde_json::from_str(&text)?);
    }
    cache
        .get(&dir)
        .and_then(|v| v.iter().find(|s| s.index == index))
        .cloned()
        .with_context(|| format!("no setup {index} in {}/setups.json", dir.display()))
}

/// Replaces the measured forces of `dig` by the ones the dig model would feed the networks at the
/// recorded states ([`ForceSource::Statics`]): the model's soil force for the pose and the sampled
/// cylinder velocities over the pre-dig section lowered to the sensed tip path (the dig model's cut
/// surface), with the payload of the sensed swept volume (perception, 3.2), through the statics
/// `F = (G - J^T f) / r` (Eqs. A2, A4, A7, A19), clamped to the port relief as in the dig model.
fn replace_with_statics(
    dig: &mut TraceDig,
    setup: &DigSetup,
    model: &mut DigModel,
    kin: &Kinematics,
    machine: &planner::machine::MachineConfig,
) -> anyhow::Result<()> {
    let cfg = sim_config(setup)?;
    let world = World::from_scenario(&cfg.scenario)?;
    let profile = section_of(&world, &cfg)?;
    let soil = &cfg.scenario.soil;
    let psi = planner::soil::SoilProperties {
        density_kg_per_m3: soil.density_kg_per_m3,
        failure_angle_rad: soil.failure_angle_deg.to_radians(),
        friction_angle_rad: soil.friction_angle_deg.to_radians(),
        tool_friction_angle_rad: soil.tool_friction_angle_deg.to_radians(),
        cohesion_pa: soil.cohesion_pa,
    };
    model.set_soil(planner::dig_model::SoilModel::Analytical(psi))?;
    let capacity = machine.bucket.capacity_m3;
    let port_relief = STATICS_PORT_RELIEF_FACTOR * machine.hydraulics.relief_pressure_pa;
    let c = &machine.cylinders;
    let areas = [&c.boom, &c.stick, &c.bucket].map(|c| (c.head_area_m2(), c.rod_area_m2()));
    let mut swept = SweptVolume::new(profile.clone(), machine.bucket.width_m)?;
    let (r0, step) = (profile.r_start_m(), profile.step_m());
    let n = ((profile.r_end_m() - r0) / step).round() as usize + 1;
    let mut heights: Vec<f64> = (0..n)
        .map(|k| profile.height_at((r0 + k as f64 * step).min(profile.r_end_m())))
        .collect::<Result<_, _>>()?;
    let mut last_tip: Option<[f64; 2]> = None;
    for s in &mut dig.samples {
        let [b, st, bu] = s.angles_rad;
        let q = JointAngles {
            boom_rad: b,
            stick_rad: st,
            bucket_rad: bu,
        };
        let tip = kin.forward(&q);
        let v_s = swept.update(tip.x_m, tip.z_m)?.min(capacity);
        // The cut surface: the section lowered to the straight path between successive tips.
        if let Some(from) = last_tip {
            let to = [tip.x_m, tip.z_m];
            let dx = to[0] - from[0];
            if dx.abs() > 1e-12 {
                let (lo, hi) = (from[0].min(to[0]), from[0].max(to[0]));
                for (k, h) in heights.iter_mut().enumerate() {
                    let r = r0 + k as f64 * step;
                    if r >= lo && r <= hi {
                        *h = h.min(from[1] + (r - from[0]) / dx * (to[1] - from[1]));
                    }
                }
            }
        }
        last_tip = Some([tip.x_m, tip.z_m]);
        let surface = SectionProfile::new(r0, step, heights.clone())?;
        let f = model.soil_force_at(&q, s.sample.velocity_m_per_s, &surface, v_s)?;
        let forces = kin.cylinder_forces_from_tip_force(&q, &f, v_s * psi.density_kg_per_m3)?;
        for j in 0..3 {
            let f = forces[j];
            if !f.is_finite() {
                bail!(
                    "non-finite statics force in the replay of dig {}",
                    setup.index
                );
            }
            s.sample.force_n[j] = f.clamp(-port_relief * areas[j].1, port_relief * areas[j].0);
        }
    }
    Ok(())
}

/// Port-relief pressure as a multiple of the main relief, as the dig model clamps its statics.
const STATICS_PORT_RELIEF_FACTOR: f64 = 1.08;

/// The digs of `traces` with the velocities from `source` and the forces from `forces`.
fn load_digs(
    traces: &[PathBuf],
    machine: &planner::machine::MachineConfig,
    source: VelocitySource,
    forces: ForceSource,
) -> anyhow::Result<Vec<ActuatorDig>> {
    let mut digs: Vec<ActuatorDig> = load_trace_digs(traces, machine, forces)?
        .iter()
        .map(|d| d.to_actuator_dig(source))
        .collect();
    if forces == ForceSource::Mixed {
        let statics = load_trace_digs(traces, machine, ForceSource::Statics)?;
        digs.extend(statics.iter().map(|d| d.to_actuator_dig(source)));
    }
    Ok(digs)
}

pub(crate) fn load_machine(path: Option<&Path>) -> anyhow::Result<planner::machine::MachineConfig> {
    Ok(match path {
        Some(p) => planner::machine::MachineConfig::from_toml_file(p)?,
        None => planner::machine::MachineConfig::default_machine()?,
    })
}

fn print_errors(report: &planner::actuator::EvaluationReport) {
    println!("  cylinder  MAE [m/s]  peak [m/s]  MAE % of peak");
    for e in &report.cylinders {
        println!(
            "  {:<8}  {:>9.4}  {:>10.3}  {:>8.2} %{}",
            e.joint.to_string(),
            e.mae_m_per_s,
            e.peak_m_per_s,
            e.mae_percent_of_peak,
            if e.mae_percent_of_peak < 5.0 {
                ""
            } else {
                "  (above 5 %)"
            }
        );
    }
}

/// A sample's sampled rate is counted as a phantom (a stalled cylinder's aliased chatter, docs/simulator.md
/// Known issues) when the resolver angles say the cylinder moves slower than this, m/s ...
const PHANTOM_ANGLE_SPEED_M_PER_S: f64 = 0.01;
/// ... while the rate says it moves faster than this, m/s.
const PHANTOM_RATE_SPEED_M_PER_S: f64 = 0.02;

/// The error of `model` on `digs` split by phantom-rate samples ([`PHANTOM_ANGLE_SPEED_M_PER_S`]),
/// against both target signals. Prints one table.
fn print_breakdown(model: &ActuatorModel, digs: &[TraceDig]) -> anyhow::Result<()> {
    // Per cylinder: [all, phantom] x (steps, |e| vs rates, |e| vs angles); peaks of both signals.
    let mut sums = [[(0usize, 0.0_f64, 0.0_f64); 2]; 3];
    let mut peaks = [[0.0_f64; 2]; 3];
    for dig in digs {
        let by_rates = model.simulate(&dig.to_actuator_dig(VelocitySource::Rates))?;
        let by_angles = model.simulate(&dig.to_actuator_dig(VelocitySource::Angles))?;
        for (r, g) in by_rates.iter().zip(&by_angles).skip(1) {
            for j in 0..3 {
                let (rate, angle) = (r.measured_m_per_s[j], g.measured_m_per_s[j]);
                let phantom = angle.abs() < PHANTOM_ANGLE_SPEED_M_PER_S
                    && rate.abs() > PHANTOM_RATE_SPEED_M_PER_S;
                peaks[j][0] = peaks[j][0].max(rate.abs());
                peaks[j][1] = peaks[j][1].max(angle.abs());
                for (class, sum) in sums[j].iter_mut().enumerate() {
                    if class == 0 || phantom {
                        sum.0 += 1;
                        sum.1 += (r.predicted_m_per_s[j] - rate).abs();
                        sum.2 += (g.predicted_m_per_s[j] - angle).abs();
                    }
                }
            }
        }
    }
    println!(
        "error by target signal; phantom samples: resolver speed < {PHANTOM_ANGLE_SPEED_M_PER_S} m/s while the rate says > {PHANTOM_RATE_SPEED_M_PER_S} m/s"
    );
    println!(
        "  cylinder  MAE vs rates  MAE vs angles  phantom samples  their share of |e| vs rates  MAE vs rates without them"
    );
    for (j, joint) in Joint::ALL.iter().enumerate() {
        let [all, ph] = sums[j];
        let pct = |x: f64, peak: f64| if peak > 0.0 { 100.0 * x / peak } else { 0.0 };
        let n = all.0.max(1) as f64;
        let rest_n = (all.0 - ph.0).max(1) as f64;
        println!(
            "  {:<8}  {:>10.2} %  {:>11.2} %  {:>8} ({:>4.1} %)  {:>18.1} %  {:>16.2} %",
            joint.to_string(),
            pct(all.1 / n, peaks[j][0]),
            pct(all.2 / n, peaks[j][1]),
            ph.0,
            100.0 * ph.0 as f64 / n,
            if all.1 > 0.0 {
                100.0 * ph.1 / all.1
            } else {
                0.0
            },
            pct((all.1 - ph.1) / rest_n, peaks[j][0]),
        );
    }
    println!(
        "  (each % of that signal's peak on these digs: rates {:.3} / {:.3} / {:.3} m/s, angles {:.3} / {:.3} / {:.3} m/s)",
        peaks[0][0], peaks[1][0], peaks[2][0], peaks[0][1], peaks[1][1], peaks[2][1]
    );
    Ok(())
}

fn evaluate(a: &EvaluateArgs) -> anyhow::Result<()> {
    let machine = load_machine(a.machine.as_deref())?;
    let trace_digs = load_trace_digs(&a.trace, &machine, a.forces)?;
    let text = match &a.model {
        Some(p) => {
            std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?
        }
        None => planner::dig_model::NOMINAL_ACTUATOR_JSON.to_owned(),
    };
    let model = ActuatorModel::from_json(&text)?;
    let chosen: Vec<TraceDig> = if a.all {
        trace_digs
    } else {
        let config = TrainConfig {
            seed: a.seed,
            ..TrainConfig::default()
        };
        let split = planner::actuator::split_digs(trace_digs.len(), &config)?;
        let picked = match a.split {
            EvalSplit::Test => &split.test,
            EvalSplit::Validation => &split.validation,
            EvalSplit::Train => &split.train,
        };
        picked.iter().map(|&i| trace_digs[i].clone()).collect()
    };
    let digs: Vec<ActuatorDig> = chosen
        .iter()
        .map(|d| d.to_actuator_dig(a.velocity))
        .collect();
    let report = if a.zero_rate {
        model.evaluate_static(&digs)?
    } else {
        model.evaluate(&digs)?
    };
    println!(
        "{} digs ({} steps), target: velocities from the {}, free-running (thesis Figs. 19-21: 5-8 %; target < 5 %):",
        report.digs,
        report.steps,
        match a.velocity {
            VelocitySource::Rates => "sampled joint rates",
            VelocitySource::Angles => "resolver angles' slope",
        }
    );
    print_errors(&report);
    if let Some(path) = &a.dump {
        write_dump(path, &model, &chosen, &digs)?;
        println!("wrote {}", path.display());
    }
    if a.breakdown {
        print_breakdown(&model, &chosen)?;
        if a.forces == ForceSource::Statics {
            let measured = load_trace_digs(&a.trace, &machine, ForceSource::Measured)?;
            print_force_gap(&measured, &trace_digs_all(&a.trace, &machine)?, &machine);
        }
    }
    Ok(())
}

/// Writes `evaluate --dump`'s CSV: one row per predicted step, with the trace sample nearest in time.
fn write_dump(
    path: &Path,
    model: &ActuatorModel,
    chosen: &[TraceDig],
    digs: &[ActuatorDig],
) -> anyhow::Result<()> {
    let file = File::create(path).with_context(|| format!("creating {}", path.display()))?;
    let mut out = BufWriter::new(file);
    writeln!(
        out,
        "dig,t,stage,u0,u1,u2,f0,f1,f2,ph0,ph1,ph2,pr0,pr1,pr2,pump1,pump2,vr0,vr1,vr2,va0,va1,va2,vt0,vt1,vt2,vp0,vp1,vp2"
    )?;
    for (d, (trace, dig)) in chosen.iter().zip(digs).enumerate() {
        let steps = model.simulate(dig)?;
        let times: Vec<f64> = trace.samples.iter().map(|s| s.sample.time_s).collect();
        for step in steps.iter().skip(1) {
            let k = times.partition_point(|&t| t < step.time_s);
            let k = if k > 0
                && (k == times.len() || step.time_s - times[k - 1] < times[k] - step.time_s)
            {
                k - 1
            } else {
                k.min(times.len() - 1)
            };
            let s = &trace.samples[k];
            let mut row = vec![d as f64, step.time_s, f64::from(s.stage)];
            row.extend(s.sample.command);
            row.extend(s.sample.force_n);
            row.extend(s.head_pa);
            row.extend(s.rod_pa);
            row.extend(s.pump_pa);
            row.extend(s.sample.velocity_m_per_s);
            row.extend(s.angle_velocity_m_per_s);
            row.extend(step.measured_m_per_s);
            row.extend(step.predicted_m_per_s);
            let text: Vec<String> = row.iter().map(|v| format!("{v:.6e}")).collect();
            writeln!(out, "{}", text.join(","))?;
        }
    }
    out.flush()?;
    Ok(())
}

/// All digs of `traces` with the statics forces (the same digs as [`ForceSource::Measured`] gives).
fn trace_digs_all(
    traces: &[PathBuf],
    machine: &planner::machine::MachineConfig,
) -> anyhow::Result<Vec<TraceDig>> {
    load_trace_digs(traces, machine, ForceSource::Statics)
}

/// How far the dig model's statics forces lie from the measured ones over all samples: mean and
/// mean absolute difference (statics - measured) per cylinder, as head-side pressure, MPa.
fn print_force_gap(
    measured: &[TraceDig],
    statics: &[TraceDig],
    machine: &planner::machine::MachineConfig,
) {
    let c = &machine.cylinders;
    let head = [&c.boom, &c.stick, &c.bucket].map(|c| c.head_area_m2());
    let mut sums = [(0.0_f64, 0.0_f64); 3];
    let mut n = 0usize;
    for (m, s) in measured.iter().zip(statics) {
        for (a, b) in m.samples.iter().zip(&s.samples) {
            for j in 0..3 {
                let d = (b.sample.force_n[j] - a.sample.force_n[j]) / head[j] * 1e-6;
                sums[j].0 += d;
                sums[j].1 += d.abs();
            }
            n += 1;
        }
    }
    let n = n.max(1) as f64;
    println!(
        "statics - measured force over all {} samples, as head pressure [MPa]: mean {:+.2} / {:+.2} / {:+.2}, mean |.| {:.2} / {:.2} / {:.2} (boom / stick / bucket)",
        n,
        sums[0].0 / n,
        sums[1].0 / n,
        sums[2].0 / n,
        sums[0].1 / n,
        sums[1].1 / n,
        sums[2].1 / n
    );
}

fn train(a: &TrainArgs) -> anyhow::Result<()> {
    let machine = load_machine(a.machine.as_deref())?;
    let digs = load_digs(&a.trace, &machine, a.velocity, a.forces)?;
    let config = TrainConfig {
        seed: a.seed,
        hidden_units: a.hidden,
        delay_steps: a.delay.unwrap_or_else(|| {
            (machine.hydraulics.transport_delay_s / 0.01)
                .round()
                .max(0.0) as usize
        }),
        free_run_epochs: a.epochs,
        coupled_inputs: !a.thesis_inputs,
        orifice_inputs: a.orifice_inputs,
        teacher_forcing_epochs: a.teacher_epochs,
        batch_digs: a.batch_digs,
        force_rate_input: a.force_rate,
        force_rate_dropout: a.force_rate_dropout,
        force_noise: a.force_noise,
        third_inputs: a.third_inputs,
        final_rate_fraction: a.final_rate,
        restarts: a.restarts,
        patience: a.patience,
        command_lag_s: if a.spool_lag {
            machine.hydraulics.lag_time_constant_s
        } else {
            0.0
        },
        free_run_loss: if a.abs_loss {
            FreeRunLoss::Absolute
        } else {
            FreeRunLoss::Squared
        },
        ..TrainConfig::default()
    };
    let samples: usize = digs.iter().map(|d| d.samples.len()).sum();
    println!(
        "training on {} digs ({} samples) from {} trace(s), velocities from the {:?}: {} hidden units, delay {} steps, spool lag {} s, seed {}, batches of {} digs, {} inputs",
        digs.len(),
        samples,
        a.trace.len(),
        a.velocity,
        config.hidden_units,
        config.delay_steps,
        config.command_lag_s,
        config.seed,
        config.batch_digs,
        if config.orifice_inputs {
            "coupled + orifice drives"
        } else if config.force_rate_input {
            "coupled + own force rate"
        } else if config.third_inputs {
            "all three cylinders' command and force"
        } else if config.coupled_inputs {
            "coupled (partner command and force)"
        } else {
            "Fig. 17"
        }
    );
    let bar = indicatif::ProgressBar::new(1);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} epochs {elapsed} {msg}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let started = std::time::Instant::now();
    let (model, report) = planner::actuator::train(&digs, &config, |p| {
        bar.set_length(p.total as u64);
        bar.set_position(p.done as u64);
        bar.set_message(format!(
            "{} {:?} loss {:.2e} val {:.2e}",
            p.joint, p.phase, p.train_loss, p.validation_loss
        ));
    })?;
    bar.finish_and_clear();
    std::fs::write(&a.out, model.to_json()?)
        .with_context(|| format!("writing {}", a.out.display()))?;
    println!(
        "trained in {:.1} s; {} train, {} validation, {} test digs; wrote {}",
        started.elapsed().as_secs_f64(),
        report.train_digs.len(),
        report.validation_digs.len(),
        report.test_digs.len(),
        a.out.display()
    );
    println!(
        "free-running epochs {:?}, best validation loss (mean squared, normalised) {:.4e} / {:.4e} / {:.4e}",
        report.free_run_epochs,
        report.validation_loss[0],
        report.validation_loss[1],
        report.validation_loss[2]
    );
    println!("held-out test digs, free-running (thesis Figs. 19-21: 5-8 %; target < 5 %):");
    print_errors(&report.test);
    Ok(())
}

// ---------------------------------------------------------------------------------------------------
// compare
// ---------------------------------------------------------------------------------------------------

fn load_model(path: Option<&Path>) -> anyhow::Result<DigModel> {
    let nominal = DigModel::nominal()?;
    match path {
        None => Ok(nominal),
        Some(p) => {
            let text =
                std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?;
            let actuator =
                ActuatorModel::from_json(&text).with_context(|| format!("{}", p.display()))?;
            Ok(nominal.with_actuator(actuator)?)
        }
    }
}

fn compare(a: &CompareArgs) -> anyhow::Result<()> {
    if a.digs == 0 {
        bail!("--digs must be at least 1");
    }
    if !(a.force_factor.is_finite() && (0.0..=10.0).contains(&a.force_factor)) {
        bail!(
            "--force-factor must be within 0..=10, got {}",
            a.force_factor
        );
    }
    let model = load_model(a.model.as_deref())?;
    let mut setups = random_setups(a.digs, a.seed, false)?;
    for s in &mut setups {
        s.soil_force_factor = a.force_factor;
    }
    let bar = indicatif::ProgressBar::new(setups.len() as u64);
    let runs: Vec<anyhow::Result<(SimDig, DigComparison, DigPrediction)>> = setups
        .par_iter()
        .map(|s| {
            let sim = run_sim_dig_diagnosed(s, None, Some(&model))?;
            let (cmp, pred) = compare_dig(&model, &sim)?;
            bar.inc(1);
            Ok((sim, cmp, pred))
        })
        .collect();
    bar.finish_and_clear();
    let mut rows = Vec::new();
    for r in runs {
        rows.push(r.map_err(|e| anyhow::anyhow!("{e:#}"))?);
    }
    println!(
        "dig model vs simulator, {} digs, soil force x{} (thesis Fig. 41: within 12-15 %; target 15 %)",
        rows.len(),
        a.force_factor
    );
    println!(
        "  dig  traj RMS [m]  time sim/model [s]  energy sim/model [kJ]  volume sim/model [m^3]  err time/energy/volume [%]  lowest z sim/model [m]  soil F open loop [%]  end sim / model"
    );
    for (_, c, _) in &rows {
        println!(
            "  {:>3}  {:>12.3}  {:>7.2} / {:>6.2}  {:>9.1} / {:>8.1}  {:>9.2} / {:>9.2}  {:>+7.1} / {:>+7.1} / {:>+7.1}  {:>9.2} / {:>9.2}  {:>18}  {} / {}",
            c.index,
            c.trajectory_rms_m,
            c.time_s[0],
            c.time_s[1],
            c.energy_kj[0],
            c.energy_kj[1],
            c.volume_m3[0],
            c.volume_m3[1],
            c.error_percent[0],
            c.error_percent[1],
            c.error_percent[2],
            c.min_tip_z_m[0],
            c.min_tip_z_m[1],
            c.soil_force_error_percent
                .map_or_else(|| "-".to_owned(), |e| format!("{e:.1}")),
            c.end[0],
            c.end[1]
        );
    }
    if a.verbose {
        for (sim, c, pred) in &rows {
            println!(
                "  dig {}: t, sim (x z bucket_abs cmd), model (stage x z bucket_abs cmd head MPa)",
                c.index
            );
            for k in (0..sim.samples.len().max(pred.samples.len())).step_by(20) {
                let fmt_sim = sim.samples.get(k).map_or(String::new(), |s| {
                    format!(
                        "{:5.2} {:5.2} {:6.0} {:+.2?} {:.1?} {:.0?} soil {:.0?} model@sim {:.0?}",
                        s.tip_x_m,
                        s.tip_z_m,
                        s.bucket_abs_rad.to_degrees(),
                        s.command,
                        s.head_pa.map(|p| p * 1e-6),
                        s.force_n.map(|f| f * 1e-3),
                        s.soil_force_n.map(|f| f * 1e-3),
                        s.model_soil_force_n.map(|m| m.map(|f| f * 1e-3))
                    )
                });
                let fmt_model = pred.samples.get(k).map_or(String::new(), |s| {
                    format!(
                        "{:?} {:5.2} {:5.2} {:6.0} {:+.2?} {:.1?} {:.0?} soil [{:.0}, {:.0}]",
                        s.stage,
                        s.tip_x_m,
                        s.tip_z_m,
                        s.bucket_abs_rad.to_degrees(),
                        s.command,
                        s.head_pa.map(|p| p * 1e-6),
                        s.force_n.map(|f| f * 1e-3),
                        s.soil_force.fx_n * 1e-3,
                        s.soil_force.fz_n * 1e-3
                    )
                });
                println!(
                    "    {:5.2}  {fmt_sim:<44}  {fmt_model}",
                    k as f64 * PERIOD_S
                );
            }
        }
    }
    let cmps: Vec<DigComparison> = rows.iter().map(|(_, c, _)| c.clone()).collect();
    let (mean, rms) = mean_errors(&cmps);
    println!(
        "  mean |error|: trajectory {:.3} m, time {:.1} %, energy {:.1} %, volume {:.1} %{}",
        rms,
        mean[0],
        mean[1],
        mean[2],
        if mean.iter().all(|e| *e <= 15.0) {
            " (within 15 %)"
        } else {
            " (above 15 % somewhere)"
        }
    );
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    std::fs::write(
        a.out.join("compare.json"),
        serde_json::to_string_pretty(&cmps)?,
    )?;
    let svg = a.out.join("compare.svg");
    plot_compare(&svg, &rows)?;
    for (sim, cmp, pred) in &rows {
        plot_dig_series(
            &a.out.join(format!("dig_{}.svg", cmp.index)),
            sim,
            cmp,
            pred,
        )?;
    }
    println!(
        "wrote {}, dig_N.svg (commands, joint angles, head pressures, soil force, swept volume over time) and compare.json",
        svg.display()
    );
    Ok(())
}

fn plot_compare(
    path: &Path,
    rows: &[(SimDig, DigComparison, DigPrediction)],
) -> anyhow::Result<()> {
    use plotters::prelude::*;
    let err = |e: &dyn std::fmt::Display| anyhow::anyhow!("drawing {}: {e}", path.display());
    let cols = rows.len().clamp(1, 4);
    let nrows = rows.len().div_ceil(cols).max(1);
    let root = SVGBackend::new(path, (360 * cols as u32, 300 * nrows as u32)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let areas = root.split_evenly((nrows, cols));
    for ((sim, cmp, pred), area) in rows.iter().zip(areas.iter()) {
        let xs = sim
            .samples
            .iter()
            .map(|s| s.tip_x_m)
            .chain(pred.samples.iter().map(|s| s.tip_x_m));
        let (mut x0, mut x1) = (f64::INFINITY, f64::NEG_INFINITY);
        for x in xs {
            x0 = x0.min(x);
            x1 = x1.max(x);
        }
        let (x0, x1) = (x0 - 1.0, x1 + 1.0);
        let zs = sim
            .samples
            .iter()
            .map(|s| s.tip_z_m)
            .chain(pred.samples.iter().map(|s| s.tip_z_m));
        let (mut z0, mut z1) = (f64::INFINITY, f64::NEG_INFINITY);
        for z in zs {
            z0 = z0.min(z);
            z1 = z1.max(z);
        }
        let (z0, z1) = (z0.min(0.0) - 0.3, z1 + 0.3);
        let mut chart = ChartBuilder::on(area)
            .caption(
                format!("dig {}: RMS {:.2} m", cmp.index, cmp.trajectory_rms_m),
                ("sans-serif", 14),
            )
            .margin(6)
            .x_label_area_size(26)
            .y_label_area_size(36)
            .build_cartesian_2d(x0..x1, z0..z1)
            .map_err(|e| err(&e))?;
        chart
            .configure_mesh()
            .x_desc("r [m]")
            .y_desc("z [m]")
            .draw()
            .map_err(|e| err(&e))?;
        let n = ((x1 - x0) / 0.05).ceil() as usize;
        let terrain: Vec<(f64, f64)> = (0..=n)
            .filter_map(|k| {
                let r = x0 + k as f64 * 0.05;
                sim.profile.height_at(r).ok().map(|h| (r, h))
            })
            .collect();
        chart
            .draw_series(LineSeries::new(terrain, BLACK.mix(0.5).stroke_width(1)))
            .map_err(|e| err(&e))?
            .label("terrain before")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 14, y)], BLACK.mix(0.5)));
        chart
            .draw_series(LineSeries::new(
                sim.samples.iter().map(|s| (s.tip_x_m, s.tip_z_m)),
                BLUE.stroke_width(2),
            ))
            .map_err(|e| err(&e))?
            .label("simulator")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 14, y)], BLUE));
        chart
            .draw_series(LineSeries::new(
                pred.samples.iter().map(|s| (s.tip_x_m, s.tip_z_m)),
                RED.stroke_width(2),
            ))
            .map_err(|e| err(&e))?
            .label("dig model")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 14, y)], RED));
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::LowerRight)
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .label_font(("sans-serif", 10))
            .draw()
            .map_err(|e| err(&e))?;
    }
    root.present().map_err(|e| err(&e))?;
    Ok(())
}

/// One dig over time, simulator (solid) against the model (dashed), like the thesis's Figs. 35-38:
/// Autodig commands, joint angles, head pressures, soil force magnitude (with the model's force at the
/// simulator's pose, open loop, dotted) and swept volume.
fn plot_dig_series(
    path: &Path,
    sim: &SimDig,
    cmp: &DigComparison,
    pred: &DigPrediction,
) -> anyhow::Result<()> {
    use plotters::prelude::*;
    let err = |e: &dyn std::fmt::Display| anyhow::anyhow!("drawing {}: {e}", path.display());
    type Series = (Vec<(f64, f64)>, RGBColor, bool, &'static str);
    let colors = [RED, BLUE, RGBColor(0, 150, 0)];
    let names = ["boom", "stick", "bucket"];
    let t_end = sim
        .samples
        .last()
        .map_or(0.0, |s| s.time_s)
        .max(pred.samples.last().map_or(0.0, |s| s.time_s))
        .max(0.1);
    let mut panels: Vec<(&str, Vec<Series>)> = Vec::new();
    let per_joint = |sim_of: &dyn Fn(&SimSample) -> [f64; 3],
                     model_of: &dyn Fn(&planner::dig_model::DigSample) -> [f64; 3]|
     -> Vec<Series> {
        let mut v = Vec::new();
        for j in 0..3 {
            v.push((
                sim.samples
                    .iter()
                    .map(|s| (s.time_s, sim_of(s)[j]))
                    .collect(),
                colors[j],
                false,
                names[j],
            ));
            v.push((
                pred.samples
                    .iter()
                    .map(|s| (s.time_s, model_of(s)[j]))
                    .collect(),
                colors[j],
                true,
                names[j],
            ));
        }
        v
    };
    panels.push((
        "Autodig command (Fig. 35)",
        per_joint(&|s| s.command, &|s| s.command),
    ));
    panels.push((
        "joint angle [deg] (Fig. 37)",
        per_joint(&|s| s.joint_rad.map(f64::to_degrees), &|s| {
            s.joint_rad.map(f64::to_degrees)
        }),
    ));
    panels.push((
        "cylinder force [kN] (dotted: statics at the simulator's pose and soil force)",
        {
            let mut v = per_joint(&|s| s.force_n.map(|f| f * 1e-3), &|s| {
                s.force_n.map(|f| f * 1e-3)
            });
            for j in 0..3 {
                v.push((
                    sim.samples
                        .iter()
                        .filter_map(|s| s.static_force_n.map(|f| (s.time_s, f[j] * 1e-3)))
                        .collect(),
                    RGBColor(
                        colors[j].0 / 2 + 128,
                        colors[j].1 / 2 + 128,
                        colors[j].2 / 2 + 128,
                    ),
                    false,
                    "",
                ));
            }
            v
        },
    ));
    panels.push((
        "head pressure [MPa] (Fig. 38)",
        per_joint(&|s| s.head_pa.map(|p| p * 1e-6), &|s| {
            s.head_pa.map(|p| p * 1e-6)
        }),
    ));
    panels.push((
        "soil force [kN]",
        vec![
            (
                sim.samples
                    .iter()
                    .map(|s| (s.time_s, s.soil_force_n[0].hypot(s.soil_force_n[1]) * 1e-3))
                    .collect(),
                BLACK,
                false,
                "simulator",
            ),
            (
                pred.samples
                    .iter()
                    .map(|s| (s.time_s, s.soil_force.fx_n.hypot(s.soil_force.fz_n) * 1e-3))
                    .collect(),
                BLACK,
                true,
                "model",
            ),
            (
                sim.samples
                    .iter()
                    .filter_map(|s| {
                        s.model_soil_force_n
                            .map(|m| (s.time_s, m[0].hypot(m[1]) * 1e-3))
                    })
                    .collect(),
                RGBColor(200, 120, 0),
                false,
                "model at the simulator's pose",
            ),
        ],
    ));
    panels.push((
        "swept volume [m^3]",
        vec![
            (
                sim.samples
                    .iter()
                    .map(|s| (s.time_s, s.swept_volume_m3))
                    .collect(),
                BLACK,
                false,
                "simulator",
            ),
            (
                pred.samples
                    .iter()
                    .map(|s| (s.time_s, s.swept_volume_m3))
                    .collect(),
                BLACK,
                true,
                "model",
            ),
        ],
    ));
    let root = SVGBackend::new(path, (900, 230 * panels.len() as u32 + 30)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let root = root
        .titled(
            &format!(
                "dig {}: simulator (solid) vs dig model (dashed); time {:+.0} %, energy {:+.0} %, volume {:+.0} %",
                cmp.index, cmp.error_percent[0], cmp.error_percent[1], cmp.error_percent[2]
            ),
            ("sans-serif", 16),
        )
        .map_err(|e| err(&e))?;
    let areas = root.split_evenly((panels.len(), 1));
    for ((title, series), area) in panels.iter().zip(areas.iter()) {
        // The 0.5-99.5 % range of the values: the simulator's soil chatter (200 Hz spikes through the
        // statics) would otherwise flatten every other curve.
        let mut ys: Vec<f64> = series
            .iter()
            .flat_map(|(pts, ..)| pts.iter().map(|p| p.1))
            .filter(|y| y.is_finite())
            .collect();
        ys.sort_by(f64::total_cmp);
        let (mut y0, mut y1) = match (ys.first(), ys.last()) {
            (Some(_), Some(_)) => {
                let at = |q: f64| ys[((ys.len() - 1) as f64 * q).round() as usize];
                (at(0.005), at(0.995))
            }
            _ => (0.0, 1.0),
        };
        if y1 <= y0 {
            (y0, y1) = (y0 - 0.5, y0 + 0.5);
        }
        let pad = 0.05 * (y1 - y0).max(1e-3);
        let mut chart = ChartBuilder::on(area)
            .caption(*title, ("sans-serif", 13))
            .margin(5)
            .x_label_area_size(22)
            .y_label_area_size(45)
            .build_cartesian_2d(0.0..t_end, (y0 - pad)..(y1 + pad))
            .map_err(|e| err(&e))?;
        chart
            .configure_mesh()
            .x_desc("t [s]")
            .draw()
            .map_err(|e| err(&e))?;
        for (pts, color, dashed, name) in series {
            let style = color.stroke_width(if *dashed { 1 } else { 2 });
            if *dashed {
                chart
                    .draw_series(DashedLineSeries::new(pts.iter().copied(), 6, 4, style))
                    .map_err(|e| err(&e))?;
            } else {
                let drawn = chart
                    .draw_series(LineSeries::new(pts.iter().copied(), style))
                    .map_err(|e| err(&e))?;
                if !name.is_empty() {
                    drawn
                        .label(*name)
                        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 14, y)], style));
                }
            }
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .label_font(("sans-serif", 10))
            .draw()
            .map_err(|e| err(&e))?;
    }
    root.present().map_err(|e| err(&e))?;
    Ok(())
}

// ---------------------------------------------------------------------------------------------------
// table2
// ---------------------------------------------------------------------------------------------------

/// One row of Table 2 as the dig model predicts it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Table2Row {
    /// Force factor.
    pub force_factor: f64,
    /// Dig time, s.
    pub time_s: f64,
    /// Swept volume, m^3.
    pub volume_m3: f64,
    /// Energy, kJ.
    pub energy_kj: f64,
}

/// The default bench's site (config/bench.toml) as the machine at its start pose sees it.
///
/// # Errors
/// Loading the built-in files.
pub fn default_site() -> anyhow::Result<DigSite> {
    let cfg = SimConfig::load::<&str>(None, None, None, &[])?;
    let world = World::from_scenario(&cfg.scenario)?;
    Ok(DigSite::new(
        section_of(&world, &cfg)?,
        cfg.scenario.bench.floor_elevation_m,
    )?)
}

/// A dig start with the tip `start_depth_m` under the surface of `site` at `start_r` m from the swing
/// axis and the bucket at `start_bucket_deg` to the horizontal (Table 2's and Fig. 52's start).
///
/// # Errors
/// `start_r` outside the site's section.
fn tip_start(
    site: &DigSite,
    start_r: f64,
    start_depth_m: f64,
    start_bucket_deg: f64,
) -> anyhow::Result<DigStart> {
    Ok(DigStart::Pose(BucketPose {
        x_m: start_r,
        z_m: site.profile().height_at(start_r)? - start_depth_m,
        bucket_abs_rad: start_bucket_deg.to_radians(),
    }))
}

/// Table 2 with `model` from the tip at `start_r` on the default bench.
///
/// # Errors
/// The dig model's errors.
pub fn table2_rows(
    model: &DigModel,
    start_r: f64,
    start_depth_m: f64,
    start_bucket_deg: f64,
) -> anyhow::Result<Vec<Table2Row>> {
    Ok(
        table2_predictions(model, start_r, start_depth_m, start_bucket_deg)?
            .into_iter()
            .map(|(row, _)| row)
            .collect(),
    )
}

/// [`table2_rows`] with each factor's predicted dig.
fn table2_predictions(
    model: &DigModel,
    start_r: f64,
    start_depth_m: f64,
    start_bucket_deg: f64,
) -> anyhow::Result<Vec<(Table2Row, planner::dig_model::DigPrediction)>> {
    let site = default_site()?;
    let start = tip_start(&site, start_r, start_depth_m, start_bucket_deg)?;
    let mut rows = Vec::new();
    for factor in [1.0, 2.0, 3.0] {
        let mut m = model.clone();
        m.set_force_factor(factor)?;
        let p = m.predict(&start, &site)?;
        let s = &p.summary;
        rows.push((
            Table2Row {
                force_factor: factor,
                time_s: s.time_s,
                volume_m3: s.swept_volume_m3,
                energy_kj: s.energy_kj(),
            },
            p,
        ));
    }
    Ok(rows)
}

/// The tip path of a predicted dig, for the tip-path plots.
pub(crate) fn predicted_tip_path(p: &DigPrediction) -> Vec<crate::demo::TipPoint> {
    p.samples
        .iter()
        .map(|s| crate::demo::TipPoint {
            x_m: s.tip_x_m,
            z_m: s.tip_z_m,
        })
        .collect()
}

/// The thesis's statements about Table 2 (4.4) on `(time s, swept volume m^3, energy kJ)` at force
/// factor 1, 2 and 3: each statement and whether it holds.
#[must_use]
pub fn table2_checks(r: [(f64, f64, f64); 3]) -> [(&'static str, bool); 5] {
    [
        ("time rises 1 -> 2", r[1].0 > r[0].0),
        ("time falls 2 -> 3", r[2].0 < r[1].0),
        ("volume rises 1 -> 2", r[1].1 > r[0].1),
        ("volume falls 2 -> 3", r[2].1 < r[1].1),
        (
            "energy rises throughout",
            r[1].2 > r[0].2 && r[2].2 > r[1].2,
        ),
    ]
}

/// How a reproduction's check reads: "as in the thesis" or "differs from the thesis".
pub fn thesis_verdict(ok: bool) -> &'static str {
    if ok {
        "as in the thesis"
    } else {
        "differs from the thesis"
    }
}

/// The section of the default bench as [`TipPoint`]s (every 0.05 m from 1 to 12 m).
pub(crate) fn default_section() -> anyhow::Result<Vec<crate::demo::TipPoint>> {
    let site = default_site()?;
    Ok((0..=220)
        .filter_map(|k| {
            let r = 1.0 + 0.05 * f64::from(k);
            site.profile()
                .height_at(r)
                .ok()
                .map(|z| crate::demo::TipPoint { x_m: r, z_m: z })
        })
        .collect())
}

fn table2(a: &Table2Args) -> anyhow::Result<()> {
    let model = a.start.load_model()?;
    let predicted = table2_predictions(
        &model,
        a.start.start_r,
        a.start.start_depth,
        a.start.start_bucket_deg,
    )?;
    let rows: Vec<Table2Row> = predicted.iter().map(|(r, _)| *r).collect();
    println!("Table 2 with the dig model ({})", a.start.describe());
    println!(
        "  force factor  time [s]  volume [m^3]  energy [kJ]   | thesis: time  volume  energy"
    );
    for (r, t) in rows.iter().zip(THESIS_TABLE2) {
        println!(
            "  {:>12.1}  {:>8.2}  {:>12.2}  {:>11.1}   |        {:>5.1}  {:>6.1}  {:>6.0}",
            r.force_factor, r.time_s, r.volume_m3, r.energy_kj, t.1, t.2, t.3
        );
    }
    let figures = |r: &Table2Row| (r.time_s, r.volume_m3, r.energy_kj);
    for (statement, ok) in table2_checks([figures(&rows[0]), figures(&rows[1]), figures(&rows[2])])
    {
        println!("  {statement}: {}", thesis_verdict(ok));
    }
    if let Some(dir) = &a.out {
        let section = default_section()?;
        let curves = predicted
            .iter()
            .map(|(r, p)| crate::plots::TipCurve {
                label: format!(
                    "force factor {:.0}: {:.2} m^3, {:?}",
                    r.force_factor, r.volume_m3, p.summary.end
                ),
                path: predicted_tip_path(p),
                section: section.clone(),
            })
            .collect();
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        let path = dir.join("fig39_model.svg");
        std::fs::write(
            &path,
            crate::plots::tip_paths_svg(
                "Fig. 39 with the dig model: the same start at three soil force levels",
                &[(String::new(), curves)],
            )?,
        )
        .with_context(|| format!("writing {}", path.display()))?;
        println!("  trajectories: {}", path.display());
    }
    let mut out = std::io::stdout().lock();
    out.flush()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `model table2 --out DIR` draws the three predicted digs, each over the bench section.
    #[test]
    fn table2_writes_the_three_predicted_paths() {
        let dir = tempfile::tempdir().unwrap();
        table2(&Table2Args {
            start: ModelStartArgs::default(),
            out: Some(dir.path().to_path_buf()),
        })
        .unwrap();
        let svg = std::fs::read_to_string(dir.path().join("fig39_model.svg")).unwrap();
        for k in 1..=3 {
            assert!(svg.contains(&format!("force factor {k}:")), "{svg}");
        }
        // Three paths and three dashed sections (a dashed line is drawn as one polyline a dash).
        assert!(svg.matches("<polyline").count() >= 6, "{svg}");
    }

    /// `compare --force-factor` reaches the simulator through the setup; `setups.json` files written
    /// before the field existed load with factor 1.
    #[test]
    fn a_setup_carries_the_soil_force_factor_to_the_simulator() {
        let mut setup = random_setups(1, 7, false).unwrap().remove(0);
        assert_eq!(setup.soil_force_factor, 1.0);
        assert_eq!(sim_config(&setup).unwrap().scenario.soil_force_factor, None);
        setup.soil_force_factor = 2.0;
        assert_eq!(
            sim_config(&setup).unwrap().scenario.soil_force_factor,
            Some(2.0)
        );
        let mut json = serde_json::to_value(&setup).unwrap();
        json.as_object_mut().unwrap().remove("soil_force_factor");
        let old: DigSetup = serde_json::from_value(json).unwrap();
        assert_eq!(old.soil_force_factor, 1.0);
    }

    /// A training trace cut mid-line (a logger stopped on the machine) was an error that lost the
    /// whole file; the digs before the cut are read.
    #[test]
    fn a_training_trace_cut_mid_line_keeps_what_precedes_the_cut() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("dig_000.log");
        let setup = random_setups(1, 3, false).unwrap().remove(0);
        let mut w = TraceWriter::new(BufWriter::new(File::create(&path).unwrap()), "vcan0", true);
        run_sim_dig(&setup, Some(&mut w)).unwrap();
        w.flush().unwrap();
        drop(w);
        let machine = planner::machine::MachineConfig::default_machine().unwrap();
        let kin = Kinematics::new(&machine).unwrap();
        let c = &machine.cylinders;
        let areas = [&c.boom, &c.stick, &c.bucket].map(|c| (c.head_area_m2(), c.rod_area_m2()));
        let count = |digs: &[TraceDig]| digs.iter().map(|d| d.samples.len()).sum::<usize>();
        let whole = count(&read_training_digs(&path, &kin, areas).unwrap());
        assert!(whole > 100, "{whole} samples");
        let text = std::fs::read_to_string(&path).unwrap();
        // Cut two thirds in, inside a line.
        let mut cut_at = text.len() * 2 / 3;
        while text.as_bytes()[cut_at - 1] == b'\n' {
            cut_at += 1;
        }
        std::fs::write(&path, &text[..cut_at]).unwrap();
        let cut = count(&read_training_digs(&path, &kin, areas).unwrap());
        assert!(cut > 0 && cut < whole, "{cut} of {whole} samples");
    }

    fn tagged_at(t: f64, angles_rad: [f64; 3]) -> Tagged {
        Tagged {
            sample: TraceSample {
                sample: ActuatorSample {
                    time_s: t,
                    command: [0.0; 3],
                    force_n: [0.0; 3],
                    velocity_m_per_s: [0.0; 3],
                },
                angle_velocity_m_per_s: [0.0; 3],
                angles_rad,
                head_pa: [0.0; 3],
                rod_pa: [0.0; 3],
                pump_pa: [0.0; 2],
                stage: 0,
            },
            arms: [1.0; 3],
            angles_rad,
            dig: None,
        }
    }

    #[test]
    fn angle_slope_recovers_the_rate_of_quantised_resolver_angles() {
        // Ramps at 0.2, -0.05 and 0 rad/s, quantised to 14 bits like the simulator's resolvers.
        let quantum = std::f64::consts::TAU / 16384.0;
        let rates = [0.2, -0.05, 0.0];
        let tagged: Vec<Tagged> = (0..40)
            .map(|k| {
                let t = k as f64 * 0.01;
                tagged_at(t, rates.map(|w| (0.3 + w * t / quantum).round() * quantum))
            })
            .collect();
        let w = angle_slope(&tagged, 10, 20);
        for j in 0..3 {
            assert!(
                (w[j] - rates[j]).abs() < 0.01,
                "joint {j}: {} against {}",
                w[j],
                rates[j]
            );
        }
        // A single sample has no slope.
        assert_eq!(angle_slope(&tagged, 5, 5), [0.0; 3]);
    }

    #[test]
    fn a_generated_trace_reads_back_with_both_velocities_and_statics_forces() {
        let dir = tempfile::tempdir().unwrap();
        let setups = random_setups(3, 3, true).unwrap();
        let mut paths = Vec::new();
        for setup in &setups {
            let path = dir.path().join(format!("dig_{:03}.log", setup.index));
            let mut w =
                TraceWriter::new(BufWriter::new(File::create(&path).unwrap()), "vcan0", true);
            run_sim_dig(setup, Some(&mut w)).unwrap();
            w.flush().unwrap();
            paths.push(path);
        }
        std::fs::write(
            dir.path().join("setups.json"),
            serde_json::to_string(&setups).unwrap(),
        )
        .unwrap();
        let machine = planner::machine::MachineConfig::default_machine().unwrap();
        let measured = load_trace_digs(&paths, &machine, ForceSource::Measured).unwrap();
        let statics = load_trace_digs(&paths, &machine, ForceSource::Statics).unwrap();
        assert_eq!(measured.len(), 3);
        assert_eq!(statics.len(), 3);
        // The two velocity signals describe the same motion: their means over the dig agree to a
        // small fraction of the peak speed (they differ sample by sample by noise and smoothing).
        for (dig, j) in measured.iter().flat_map(|d| [(d, 0), (d, 1), (d, 2)]) {
            let s = &dig.samples;
            let peak = s
                .iter()
                .map(|x| x.sample.velocity_m_per_s[j].abs())
                .fold(0.0, f64::max);
            let mean_rate = s.iter().map(|x| x.sample.velocity_m_per_s[j]).sum::<f64>();
            let mean_angle = s.iter().map(|x| x.angle_velocity_m_per_s[j]).sum::<f64>();
            let n = s.len() as f64;
            assert!(
                ((mean_rate - mean_angle) / n).abs() < 0.05 * peak,
                "cylinder {j}: mean {} against {} m/s, peak {peak}",
                mean_rate / n,
                mean_angle / n
            );
        }
        // Statics forces: finite, within the port relief, not the measured ones, and the same samples
        // otherwise.
        let relief = STATICS_PORT_RELIEF_FACTOR * machine.hydraulics.relief_pressure_pa;
        let c = &machine.cylinders;
        let head = [&c.boom, &c.stick, &c.bucket].map(|c| c.head_area_m2());
        let mut differs = false;
        let pairs = measured.iter().zip(&statics).flat_map(|(m, s)| {
            assert_eq!(m.samples.len(), s.samples.len());
            m.samples.iter().zip(&s.samples)
        });
        for (m, s) in pairs {
            assert_eq!(m.sample.time_s, s.sample.time_s);
            assert_eq!(m.sample.velocity_m_per_s, s.sample.velocity_m_per_s);
            for ((f, a), fm) in s.sample.force_n.iter().zip(head).zip(m.sample.force_n) {
                assert!(f.is_finite() && *f <= relief * a + 1e-6);
                differs |= (f - fm).abs() > 1.0;
            }
        }
        assert!(differs);
    }
}
