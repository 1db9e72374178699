//! `excavator-ctl experiment`: the thesis's results reproduced in closed loop against the simulator
//! (in-process, virtual time), each printed next to the thesis's numbers and checked against its
//! statements ([`crate::thesis`]). Table 2 and Fig. 52 also print the dig model's results
//! ([`crate::model::table2`], [`crate::model::fig52`]), since the thesis made both with its dig model.
//!
//! - **Table 1** (3.2): initial stick angles -87, -70, -50 degrees (the stick's joint angle by
//!   default, or to the horizontal: [`StickAngleReading`]), plain Autodig (fixed
//!   beta, gamma) against Autodig with the perception enhancements (swept volume ends Dig, the terrain
//!   ends Capture), `--runs` digs each with different simulator seeds.
//! - **Table 2** (4.4): the soil force scaled by 1, 2 and 3. The simulator has no force multiplier; its
//!   force is the FEE `F = d^2 w gamma g N_w + c w d N_c + V_s gamma g N_q` (Eq. 17), linear in the
//!   cohesion `c` and the density `gamma`, so both are scaled by the factor in the scenario. That
//!   scales the FEE force exactly and the bearing resistance nearly (it has a constant term); as a side
//!   effect the payload is heavier by the factor too (the thesis's model had no payload weight).
//! - **Fig. 52** (5.2): soft and hard soil, hardness index 1 and 5.
//!
//! Table 2 and Fig. 52 start every dig from the same pose on the default bench; Table 1 starts on level
//! material at the tracks' level (see [`table1_with`]). Each run is one dig action.
//!
//! Also: `extended` (6.1-6.2, Tables 3-5, Fig. 60), `hardness-fit` (Fig. 53), `extended-dig-check`,
//! `scoreboard` (every statement of the thesis about Tables 1, 2 and Fig. 52, with its verdict),
//! `results` (the generated page docs/results.md, laid out by [`crate::results`]) and `shift` (a long
//! planned session under injected faults, [`crate::shift`]).

use std::path::PathBuf;

use anyhow::Context as _;
use clap::{Args, Subcommand};
use planner::autodig::AutodigMaps;
use vcan_sim::SimConfig;
use vcan_sim::scenario::SoilContactIntegration;

pub use crate::demo::SoilContact;

use controller::ControllerConfig;
use controller::step::cycle::{Action, Phase, StartPose};
use onboard::record::TipPoint;

use crate::harness::Harness;

use crate::model::fig52::ModelSoils;
use crate::model::start::ModelStartArgs;
use crate::thesis::{
    Fig52Checks, LB_TO_KG, THESIS_TABLE1, THESIS_TABLE2, table2_checks, thesis_verdict,
    write_checks,
};

/// Arguments of `excavator-ctl experiment`.
#[derive(Debug, Clone, Args)]
pub struct ExperimentArgs {
    /// The reproduction to run.
    #[command(subcommand)]
    pub which: Which,
}

/// Which reproduction.
#[derive(Debug, Clone, Subcommand)]
pub enum Which {
    /// Thesis Table 1: perception enhancements across initial stick angles, in the simulator.
    Table1(Table1Args),
    /// Thesis Table 2: soil force x1, x2, x3, in the simulator and in the dig model.
    Table2(Table2Args),
    /// Thesis Fig. 52: hardness index 1 and 5 in soft and hard soil, in the simulator and in the dig
    /// model.
    Fig52(Fig52Args),
    /// Thesis 6.1-6.2, Tables 3-5, Fig. 60: a planned session and the predefined sequence on the
    /// extended-operation bench, compared.
    Extended(ExtendedArgs),
    /// Thesis 5.2, Fig. 53: the hardness regression fitted by simulation over many soils and
    /// terrains with the dig model.
    HardnessFit(OutArgs),
    /// The simulator and the dig model from the same starts on the extended bench (tip depth, swept
    /// volume, soil force), with and without Boom-Down in the simulator.
    ExtendedDigCheck,
    /// Every statement of the thesis about Table 1, Table 2 and Fig. 52, in the simulator and the dig
    /// model, and whether it holds here: one table (`scoreboard.md` in the output folder).
    Scoreboard(ScoreboardArgs),
    /// The results page: the scoreboard, Tables 1 and 2, Fig. 52, the extended run over several seeds
    /// and the dig model's speed, each with the command that made it (docs/results.md).
    Results(ResultsArgs),
    /// A long shift of the planned session under injected faults (sensor dropouts, garbage and
    /// flood frames, bus-off, gateway faults, e-stops, controller restarts) against a fault-free
    /// shift: unsafe outputs, actions, every fault detected and recovered, memory; fails when a
    /// target is missed.
    Shift(crate::shift::ShiftArgs),
}

/// The output folder of a reproduction.
#[derive(Debug, Clone, Args)]
pub struct OutArgs {
    /// Output folder for the figures, sessions and tables.
    #[arg(long, default_value = "out/experiment", value_name = "DIR")]
    pub out: PathBuf,
}

/// The simulator's runs of Table 1, Table 2 and Fig. 52.
#[derive(Debug, Clone, Args)]
pub struct SimArgs {
    /// Digs per configuration (seeds 1..=N).
    #[arg(long, default_value_t = 5, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    pub runs: u64,
    /// Autodig maps (default: the built-in config/autodig_maps.toml).
    #[arg(long, value_name = "FILE")]
    pub maps: Option<PathBuf>,
    /// How the simulator integrates the soil's force (`implicit`, the default plant, or `held`, plant
    /// version `held-1` with its contact chatter; docs/simulator.md).
    #[arg(long, value_enum, default_value_t = SoilContact::Implicit)]
    pub soil_contact: SoilContact,
}

/// Table 1's options.
#[derive(Debug, Clone, Copy, Args)]
pub struct Table1Options {
    /// How the thesis's initial stick angles (-87, -70, -50 deg) are read.
    #[arg(long, value_enum, default_value_t = StickAngleReading::Joint)]
    pub stick_angle: StickAngleReading,
}

/// Table 2's options in the simulator.
#[derive(Debug, Clone, Copy, Args)]
pub struct Table2Options {
    /// The soil of force factor 1 is the default bench's soil with cohesion and density scaled by
    /// this.
    #[arg(long, default_value_t = TABLE2_BASE_SCALE, value_name = "F")]
    pub base_scale: f64,
    /// How the factor makes the soil harder.
    #[arg(long, value_enum, default_value_t = Table2Scaling::Soil)]
    pub scaling: Table2Scaling,
}

/// Fig. 52's soils in the simulator.
#[derive(Debug, Clone, Copy, Args)]
pub struct Fig52Soils {
    /// Cohesion of the soft soil in the simulator, kPa.
    #[arg(long, value_name = "KPA", default_value_t = FIG52_SOILS[0].1 / 1e3)]
    pub soft_cohesion_kpa: f64,
    /// Cohesion of the hard soil in the simulator, kPa.
    #[arg(long, value_name = "KPA", default_value_t = FIG52_SOILS[1].1 / 1e3)]
    pub hard_cohesion_kpa: f64,
}

impl Fig52Soils {
    /// `(name, cohesion Pa)` of the soft and the hard soil, as [`fig52_with`] takes them.
    #[must_use]
    pub fn pa(&self) -> [(&'static str, f64); 2] {
        [
            ("soft", self.soft_cohesion_kpa * 1e3),
            ("hard", self.hard_cohesion_kpa * 1e3),
        ]
    }
}

/// Arguments of `experiment table1`.
#[derive(Debug, Clone, Args)]
pub struct Table1Args {
    /// The simulator's runs.
    #[command(flatten)]
    pub sim: SimArgs,
    /// Table 1's options.
    #[command(flatten)]
    pub table1: Table1Options,
    /// The output folder (`table1.svg`).
    #[command(flatten)]
    pub out: OutArgs,
}

/// Arguments of `experiment table2`.
#[derive(Debug, Clone, Args)]
pub struct Table2Args {
    /// The simulator's runs.
    #[command(flatten)]
    pub sim: SimArgs,
    /// Table 2's options in the simulator.
    #[command(flatten)]
    pub table2: Table2Options,
    /// The dig model and its start.
    #[command(flatten)]
    pub model: ModelStartArgs,
    /// The output folder (`fig39.svg`, `fig39_model.svg`).
    #[command(flatten)]
    pub out: OutArgs,
}

/// Arguments of `experiment fig52`.
#[derive(Debug, Clone, Args)]
pub struct Fig52Args {
    /// The simulator's runs.
    #[command(flatten)]
    pub sim: SimArgs,
    /// The simulator's soils.
    #[command(flatten)]
    pub soils: Fig52Soils,
    /// The dig model and its start.
    #[command(flatten)]
    pub model: ModelStartArgs,
    /// The dig model's soils.
    #[command(flatten)]
    pub model_soils: ModelSoils,
    /// The output folder (`fig52.svg`, `fig52_model.svg`).
    #[command(flatten)]
    pub out: OutArgs,
}

/// Arguments of `experiment scoreboard`: those of Fig. 52 (the simulator's runs, both soils, the dig
/// model and its start; the output folder for `scoreboard.md`) and Table 1's and Table 2's options.
#[derive(Debug, Clone, Args)]
pub struct ScoreboardArgs {
    /// Fig. 52's arguments.
    #[command(flatten)]
    pub fig52: Fig52Args,
    /// Table 1's options.
    #[command(flatten)]
    pub table1: Table1Options,
    /// Table 2's options in the simulator.
    #[command(flatten)]
    pub table2: Table2Options,
}

/// Arguments of `experiment extended`.
#[derive(Debug, Clone, Args)]
pub struct ExtendedArgs {
    /// Digs per strategy.
    #[arg(long, default_value_t = 100, value_name = "N", value_parser = clap::value_parser!(u32).range(1..))]
    pub digs: u32,
    /// The simulator's seed (default: the bench file's).
    #[arg(long, value_name = "N")]
    pub seed: Option<u64>,
    /// Planner settings (default: the built-in config/planner.toml).
    #[arg(long, value_name = "FILE")]
    pub planner: Option<PathBuf>,
    /// The output folder (`extended/`: both sessions, `fig60.svg`, `comparison.md`).
    #[command(flatten)]
    pub out: OutArgs,
}

/// Arguments of `experiment results`.
#[derive(Debug, Clone, Args)]
pub struct ResultsArgs {
    /// The page to write.
    #[arg(long, default_value = "docs/results.md", value_name = "FILE")]
    pub out: PathBuf,
    /// Digs per configuration of Tables 1, 2 and Fig. 52 in the simulator (seeds 1..=N).
    #[arg(long, default_value_t = 3, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    pub runs: u64,
    /// Digs per strategy of the extended run.
    #[arg(long, default_value_t = 30, value_name = "N", value_parser = clap::value_parser!(u32).range(1..))]
    pub digs: u32,
    /// Seeds of the extended run (1..=N), of which the page gives each, the median and the worst.
    #[arg(long, default_value_t = 3, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    pub seeds: u64,
    /// Where the extended run's sessions are written.
    #[arg(long, default_value = "out/experiment/results", value_name = "DIR")]
    pub sessions: PathBuf,
}

/// How Table 1's initial stick angles are read.
///
/// The thesis does not say. `joint` is the default: the stick's joint angle relative to the boom, as
/// its resolver reads it and as Appendix A writes the joint angles (q3 in `S23`). Read to the
/// horizontal, -87 deg is already at the near-vertical beta at which plain Autodig ends its Dig, yet the
/// thesis's plain dig from there took 6.58 s and brought 1880 kg. docs/autodig.md, "Table 1", gives the
/// figures of both readings.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum StickAngleReading {
    /// Relative to the boom (the joint angle): the tip 7.6, 8.3 and 8.9 m out.
    Joint,
    /// To the horizontal: the tip 6.4, 7.3 and 8.4 m out.
    Absolute,
}

/// How Table 2's force factor is applied in the simulator.
///
/// `soil` is the default: with `force` (the thesis's procedure, closer to it on paper) the time no
/// longer rises from x1 to x2 (3 seeds: 3.94 / 3.93 / 3.39 s, 2.73 / 1.39 / 0.83 m^3, 226 / 262 / 188
/// kJ, against 3.94 / 4.59 / 3.79 s, 2.73 / 1.10 / 0.86 m^3, 226 / 296 / 284 kJ with `soil`): the
/// heavier content of the `soil` scaling is part of what slows its x2 dig (docs/autodig.md).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Table2Scaling {
    /// The soil's force on the bucket times the factor, the soil itself unchanged (thesis 4.4: "the
    /// force output of the analytical model was multiplied by the force factor";
    /// `vcan_sim::scenario::Scenario::soil_force_factor`).
    Force,
    /// Cohesion and density times the factor (Eq. 17 is linear in both, so the cutting force scales
    /// alike, but the bucket's content weighs the factor times more, 5100 kg/m^3 at x3).
    Soil,
}

impl SimArgs {
    /// The Autodig maps of `--maps`, or the built-in ones.
    ///
    /// # Errors
    /// The file cannot be read or is not a valid maps file.
    pub fn autodig_maps(&self) -> anyhow::Result<AutodigMaps> {
        Ok(match &self.maps {
            Some(path) => {
                let text = std::fs::read_to_string(path)
                    .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
                AutodigMaps::from_toml_str(&text)
                    .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?
            }
            None => AutodigMaps::builtin()?,
        })
    }
}

/// The outcome of one dig.
#[derive(Clone, PartialEq)]
pub struct DigOutcome {
    /// The simulator's bucket content after Capture, kg.
    pub payload_kg: f64,
    /// The static weight estimate, N.
    pub weight_n: Option<f64>,
    /// Boom-Down start to the end of Capture, s.
    pub time_s: f64,
    /// Energy (thesis 6.1), kJ.
    pub energy_kj: f64,
    /// Volume swept over the edge against the pre-dig scan, m^3.
    pub swept_volume_m3: f64,
    /// Whether the dig completed (weighed) in time.
    pub completed: bool,
    /// The bucket tip during Autodig (the controller's forward kinematics of the sensed angles, base
    /// frame).
    pub path: Vec<TipPoint>,
    /// The true terrain along the digging plane before the dig (base frame).
    pub section: Vec<TipPoint>,
}

/// The figures, and the number of points of the path and section (a test's failure message prints the
/// rows).
impl std::fmt::Debug for DigOutcome {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DigOutcome")
            .field("payload_kg", &self.payload_kg)
            .field("weight_n", &self.weight_n)
            .field("time_s", &self.time_s)
            .field("energy_kj", &self.energy_kj)
            .field("swept_volume_m3", &self.swept_volume_m3)
            .field("completed", &self.completed)
            .field("path_points", &self.path.len())
            .field("section_points", &self.section.len())
            .finish()
    }
}

/// A dig start with the stick at `stick_abs_deg` (to the horizontal), the bucket opened to -55 deg and
/// the tip 0.25 m above the default bench's top (the boom angle solves the height).
pub fn start_with_stick_angle(stick_abs_deg: f64) -> StartPose {
    start_with_stick_angle_over(stick_abs_deg, DEFAULT_BENCH_TOP_Z_M)
}

/// The default bench's top, world z, m (`config/bench.toml`: `height_m`).
const DEFAULT_BENCH_TOP_Z_M: f64 = 2.0;

/// A dig start with the stick at `stick_abs_deg`, the bucket opened to -55 deg and the tip 0.25 m
/// above a terrain top at `top_z_m` (world z; the machine stands on z = 0).
pub fn start_with_stick_angle_over(stick_abs_deg: f64, top_z_m: f64) -> StartPose {
    // Default machine: boom foot (0.2, 2.0) m, boom 5.7 m, stick 2.9 m, bucket 1.5 m.
    let (stick, bucket) = (stick_abs_deg.to_radians(), (-55.0_f64).to_radians());
    let sin_boom =
        ((top_z_m + 0.25 - 2.0 - 2.9 * stick.sin() - 1.5 * bucket.sin()) / 5.7).clamp(-1.0, 1.0);
    let boom = sin_boom.asin();
    StartPose::Joints {
        boom_rad: boom,
        stick_rad: stick - boom,
        bucket_rad: bucket - stick,
    }
}

/// A dig start with the stick's joint angle (relative to the boom) at `stick_rel_deg`, the bucket
/// opened to -55 deg to the horizontal and the tip 0.25 m above a terrain top at `top_z_m` (world z;
/// the machine stands on z = 0).
///
/// The boom angle b solves the tip height (Eq. A3's forward kinematics of the default machine):
/// `5.7 sin b + 2.9 sin(b + q3) = C` is `R sin(b + phi) = C` with `R cos phi = 5.7 + 2.9 cos q3`,
/// `R sin phi = 2.9 sin q3`; of its two solutions the one with the boom lower (the tip out in front).
pub fn start_with_stick_joint_angle_over(stick_rel_deg: f64, top_z_m: f64) -> StartPose {
    // Default machine: boom foot (0.2, 2.0) m, boom 5.7 m, stick 2.9 m, bucket 1.5 m.
    let (q3, bucket) = (stick_rel_deg.to_radians(), (-55.0_f64).to_radians());
    let c = top_z_m + 0.25 - 2.0 - 1.5 * bucket.sin();
    let (a, b) = (5.7 + 2.9 * q3.cos(), 2.9 * q3.sin());
    let boom = (c / a.hypot(b)).clamp(-1.0, 1.0).asin() - b.atan2(a);
    StartPose::Joints {
        boom_rad: boom,
        stick_rad: q3,
        bucket_rad: bucket - boom - q3,
    }
}

/// Table 1's start for `stick_deg` read as `reading`, over level material at the tracks' level.
#[must_use]
pub fn table1_start(stick_deg: f64, reading: StickAngleReading) -> StartPose {
    match reading {
        StickAngleReading::Joint => start_with_stick_joint_angle_over(stick_deg, 0.0),
        StickAngleReading::Absolute => start_with_stick_angle_over(stick_deg, 0.0),
    }
}

/// Runs one dig from `start` on `sim` with `config` (its plan replaced by that one dig).
///
/// # Errors
/// Simulator or controller construction errors.
pub fn run_dig(
    sim: &SimConfig,
    mut config: ControllerConfig,
    maps: AutodigMaps,
    start: StartPose,
) -> anyhow::Result<DigOutcome> {
    config.cycle.actions = vec![Action::Dig {
        swing_rad: 0.0,
        start,
    }];
    config.cycle.repeat = false;
    config.cycle.max_digs = Some(1);
    let mut h = Harness::new(sim, maps, config)?;
    let mut payload_kg = 0.0;
    let mut weighed = false;
    let section = crate::demo::true_section(&h.machine, 0.0);
    let mut path = Vec::new();
    let running = |h: &Harness| {
        h.node()
            .is_some_and(|n| n.statistics().is_empty() && !n.finished())
    };
    while h.time_s() < 90.0 && running(&h) {
        h.step()?;
        h.answer_scan_request();
        let Some((node, machine)) = h.parts_mut() else {
            break;
        };
        if node.cycle().phase() == Phase::Autodig {
            let tip = node.state().tip;
            path.push(TipPoint {
                x_m: tip.x_m,
                z_m: tip.z_m,
            });
        }
        if !weighed && node.cycle().phase() == Phase::Weigh {
            weighed = true;
            payload_kg = machine.plant().true_state().payload_kg;
        }
    }
    let Some(node) = h.node() else {
        anyhow::bail!("the controller is gone");
    };
    if node.statistics().is_empty() {
        tracing::warn!(
            phase = ?node.cycle().phase(),
            fault = ?node.last_fault(),
            "experiment dig did not complete"
        );
    }
    Ok(match node.statistics().first() {
        Some(d) => DigOutcome {
            payload_kg,
            weight_n: d.weight_n,
            time_s: d.time_s,
            energy_kj: d.energy_kj(),
            swept_volume_m3: d.swept_volume_m3,
            completed: true,
            path,
            section,
        },
        None => DigOutcome {
            payload_kg,
            weight_n: None,
            time_s: f64::NAN,
            energy_kj: f64::NAN,
            swept_volume_m3: f64::NAN,
            completed: false,
            path,
            section,
        },
    })
}

/// Means of several digs.
#[derive(Debug, Clone, PartialEq)]
pub struct Mean {
    /// Payload, kg.
    pub payload_kg: f64,
    /// Time, s.
    pub time_s: f64,
    /// Energy, kJ.
    pub energy_kj: f64,
    /// Swept volume, m^3.
    pub swept_volume_m3: f64,
    /// Digs that completed, of the runs.
    pub completed: usize,
    /// The first run's dig (seed 1), for the trajectory plots.
    pub first: Option<DigOutcome>,
}

fn mean(outcomes: &[DigOutcome]) -> Mean {
    let done: Vec<&DigOutcome> = outcomes.iter().filter(|o| o.completed).collect();
    let n = done.len().max(1) as f64;
    Mean {
        payload_kg: done.iter().map(|o| o.payload_kg).sum::<f64>() / n,
        time_s: done.iter().map(|o| o.time_s).sum::<f64>() / n,
        energy_kj: done.iter().map(|o| o.energy_kj).sum::<f64>() / n,
        swept_volume_m3: done.iter().map(|o| o.swept_volume_m3).sum::<f64>() / n,
        completed: done.len(),
        first: outcomes.first().cloned(),
    }
}

/// One curve of a trajectory plot: its label and the dig behind it (`None`: nothing to draw).
fn curve(label: String, m: &Mean) -> crate::plots::TipCurve {
    let (path, section) = m
        .first
        .as_ref()
        .map(|d| (d.path.clone(), d.section.clone()))
        .unwrap_or_default();
    crate::plots::TipCurve {
        label,
        path,
        section,
    }
}

/// Writes a trajectory figure `name` into `out` and returns the line the report prints about it.
fn write_figure(
    out: &std::path::Path,
    name: &str,
    title: &str,
    panels: &[(String, Vec<crate::plots::TipCurve>)],
) -> anyhow::Result<String> {
    let path = crate::plots::write_tip_paths(out, name, title, panels)?;
    Ok(format!(
        "\nTrajectories (seed 1, the tip from the sensed angles over the true pre-dig section): {}\n",
        path.display()
    ))
}

/// `time | payload` table cells of a mean, or dashes with the count when no dig completed; a count
/// when only some did.
fn time_payload_cells(m: &Mean, runs: u64) -> String {
    let runs = runs.max(1);
    match m.completed {
        0 => format!("- (0/{runs} completed) | -"),
        n if n as u64 == runs => format!("{:.2} s | {:.0} kg", m.time_s, m.payload_kg),
        n => format!("{:.2} s ({n}/{runs}) | {:.0} kg", m.time_s, m.payload_kg),
    }
}

fn runs(
    seeds: u64,
    base: &SimConfig,
    config: &ControllerConfig,
    maps: &AutodigMaps,
    start: StartPose,
) -> anyhow::Result<Mean> {
    let mut outcomes = Vec::new();
    for seed in 1..=seeds.max(1) {
        let mut sim = base.clone();
        sim.scenario.seed = seed;
        outcomes.push(run_dig(&sim, config.clone(), maps.clone(), start)?);
    }
    Ok(mean(&outcomes))
}

/// The thesis's statements about Table 1 (3.2) on its rows `(stick angle, plain, with perception)`,
/// ordered by reach: each statement and whether it holds.
#[must_use]
pub fn table1_checks(rows: &[(f64, Mean, Mean)]) -> [(&'static str, bool); 4] {
    let rising = |f: fn(&Mean) -> f64, strict: bool| {
        rows.windows(2).all(|w| {
            let (a, b) = (f(&w[0].1), f(&w[1].1));
            // Not falling: within 1 % (payloads at the bucket's capacity differ by rounding).
            if strict { b > a } else { b >= 0.99 * a }
        }) && rows.len() > 1
            && f(&rows[rows.len() - 1].1) > f(&rows[0].1)
    };
    let (lo, hi) = rows.iter().fold((f64::INFINITY, 0.0_f64), |(lo, hi), r| {
        (lo.min(r.2.payload_kg), hi.max(r.2.payload_kg))
    });
    let alike: Vec<_> = rows
        .iter()
        .filter(|r| (r.2.payload_kg - r.1.payload_kg).abs() <= 0.05 * r.1.payload_kg)
        .collect();
    [
        (
            "plain: payload grows with reach (fixed beta)",
            rising(|m| m.payload_kg, false),
        ),
        ("plain: time rises with reach", rising(|m| m.time_s, true)),
        (
            "perception: payload consistent across the starts (spread < 10 %)",
            !rows.is_empty() && hi - lo < 0.1 * hi,
        ),
        (
            "perception: faster where the payloads are alike (within 5 %)",
            !alike.is_empty() && alike.iter().all(|r| r.2.time_s < r.1.time_s),
        ),
    ]
}

/// Table 1's terrain: the extended-operation bench (machine on the material it digs, bench top at the
/// tracks' level, z = 0) with the crest of its cut moved out to this x, m, beyond the starts' reach.
pub const TABLE1_CREST_X_M: f64 = 11.0;

/// Table 1 rows: `(stick angle, plain, with perception)`.
///
/// # Errors
/// As [`run_dig`].
pub fn table1(seeds: u64, reading: StickAngleReading) -> anyhow::Result<Vec<(f64, Mean, Mean)>> {
    table1_with(
        seeds,
        &AutodigMaps::builtin()?,
        SoilContactIntegration::default(),
        reading,
    )
}

/// [`table1`] with the given maps.
///
/// The terrain: the thesis does not say where Table 1's 30 digs were dug, only that every perception
/// dig filled the bucket. Its machine worked standing on the material (ch. 6, Fig. 1); on our default
/// bench (a 2 m bench in front of the machine, top at the boom foot's height) the -87 degree start
/// (read to the horizontal) needs the boom 50 degrees up, which leaves the stick 19 degrees of stroke before its cylinder limit
/// (1165 kg with perception, 0.74 m^3 swept). So the digs start over level material at the tracks'
/// level ([`TABLE1_CREST_X_M`]); the -87, -70, -50 degree starts put the tip at 7.6, 8.3 and 8.9 m
/// read as joint angles, 6.4, 7.3 and 8.4 m read to the horizontal ([`StickAngleReading`]).
/// The machine is placed at the start pose (no move to the dig): Table 1 compares Autodig alone.
///
/// # Errors
/// As [`run_dig`].
pub fn table1_with(
    seeds: u64,
    maps: &AutodigMaps,
    contact: SoilContactIntegration,
    reading: StickAngleReading,
) -> anyhow::Result<Vec<(f64, Mean, Mean)>> {
    let mut sim = SimConfig::load::<&str>(None, None, None, &[])?;
    sim.scenario = vcan_sim::scenario::Scenario::from_toml_str_named(
        crate::demo::EXTENDED_BENCH_TOML,
        "config/bench_extended.toml",
    )?;
    sim.scenario.bench.face_x_m = TABLE1_CREST_X_M;
    sim.scenario.soil_contact = contact;
    let mut rows = Vec::new();
    for stick in [-87.0, -70.0, -50.0] {
        let start = table1_start(stick, reading);
        if let StartPose::Joints {
            boom_rad,
            stick_rad,
            bucket_rad,
        } = start
        {
            sim.scenario.start.boom_deg = boom_rad.to_degrees();
            sim.scenario.start.stick_deg = stick_rad.to_degrees();
            sim.scenario.start.bucket_deg = bucket_rad.to_degrees();
        }
        let mut plain = ControllerConfig::default();
        plain.cycle.perception = false;
        let with = ControllerConfig::default();
        rows.push((
            stick,
            runs(seeds, &sim, &plain, maps, start)?,
            runs(seeds, &sim, &with, maps, start)?,
        ));
    }
    Ok(rows)
}

/// Table 2's soil of force factor 1: the default bench's soil with cohesion and density scaled by this.
pub const TABLE2_BASE_SCALE: f64 = 1.0;

/// Table 2 rows: `(force factor, mean)`, perception on, default start, base soil
/// [`TABLE2_BASE_SCALE`].
///
/// # Errors
/// As [`run_dig`].
pub fn table2(seeds: u64) -> anyhow::Result<Vec<(f64, Mean)>> {
    table2_with(
        seeds,
        &AutodigMaps::builtin()?,
        TABLE2_BASE_SCALE,
        Table2Scaling::Soil,
        SoilContactIntegration::default(),
    )
}

/// [`table2`] with the given maps and base soil scale.
///
/// # Errors
/// As [`run_dig`]; a base scale that is not finite and positive.
pub fn table2_with(
    seeds: u64,
    maps: &AutodigMaps,
    base_scale: f64,
    scaling: Table2Scaling,
    contact: SoilContactIntegration,
) -> anyhow::Result<Vec<(f64, Mean)>> {
    anyhow::ensure!(
        base_scale.is_finite() && base_scale > 0.0,
        "--base-scale {base_scale}: must be finite and positive"
    );
    let base = SimConfig::load::<&str>(None, None, None, &[])?;
    let config = ControllerConfig::default();
    let start = default_start();
    let mut rows = Vec::new();
    for k in [1.0, 2.0, 3.0] {
        let mut sim = base.clone();
        sim.scenario.soil_contact = contact;
        match scaling {
            Table2Scaling::Force => {
                scale_soil(&mut sim, base_scale);
                sim.scenario.soil_force_factor = Some(k);
            }
            Table2Scaling::Soil => scale_soil(&mut sim, k * base_scale),
        }
        rows.push((k, runs(seeds, &sim, &config, maps, start)?));
    }
    Ok(rows)
}

fn scale_soil(sim: &mut SimConfig, k: f64) {
    sim.scenario.soil.cohesion_pa *= k;
    sim.scenario.soil.density_kg_per_m3 *= k;
    for r in &mut sim.scenario.soil_regions {
        r.soil.cohesion_pa *= k;
        r.soil.density_kg_per_m3 *= k;
    }
}

fn default_start() -> StartPose {
    match controller::step::cycle::CycleConfig::default()
        .actions
        .first()
    {
        Some(Action::Dig { start, .. }) => *start,
        _ => start_with_stick_angle(-45.0),
    }
}

/// The soft and hard soils of Fig. 52 (cohesion, Pa): the default bench's soil and twice its cohesion.
///
/// The default bench's 5 kPa is the nominal soil of the default (implicit) plant
/// (docs/simulator.md, "Soil contact integration"). The index matters between the default soil and
/// about three times its cohesion; much harder, the Boom-Down contact alone loads all three cylinders
/// to relief and both indices fill a quarter of the bucket. On the implicit plant (seeds 1-3, fill of
/// index 1 / index 5): soft 4 kPa 99 / 95 %, hard 8 kPa 73 / 100 %; soft 5 kPa 98 / 88 %, hard 10
/// kPa 55 / 91 %; soft 6 kPa 96 / 86 %, hard 12 kPa 44 / 76 %.
pub const FIG52_SOILS: [(&str, f64); 2] = [("soft", 5_000.0), ("hard", 10_000.0)];

/// Fig. 52 rows: `(soil, hardness index, mean)`.
///
/// # Errors
/// As [`run_dig`].
pub fn fig52(seeds: u64) -> anyhow::Result<Vec<(&'static str, f64, Mean)>> {
    fig52_with(
        seeds,
        &AutodigMaps::builtin()?,
        SoilContactIntegration::default(),
        FIG52_SOILS,
    )
}

/// [`fig52`] with the given maps, plant and `(name, cohesion Pa)` soils.
///
/// # Errors
/// A cohesion that is not finite and >= 0; as [`run_dig`].
pub fn fig52_with(
    seeds: u64,
    maps: &AutodigMaps,
    contact: SoilContactIntegration,
    soils: [(&'static str, f64); 2],
) -> anyhow::Result<Vec<(&'static str, f64, Mean)>> {
    let base = SimConfig::load::<&str>(None, None, None, &[])?;
    let start = default_start();
    let mut rows = Vec::new();
    for (name, cohesion) in soils {
        anyhow::ensure!(
            cohesion.is_finite() && cohesion >= 0.0,
            "Fig. 52's {name} soil: cohesion {cohesion} Pa must be finite and >= 0"
        );
        let mut sim = base.clone();
        sim.scenario.soil.cohesion_pa = cohesion;
        sim.scenario.soil_contact = contact;
        for index in [1.0, 5.0] {
            let mut config = ControllerConfig::default();
            config.autodig.hardness_index = index;
            rows.push((name, index, runs(seeds, &sim, &config, maps, start)?));
        }
    }
    Ok(rows)
}

/// The full bucket's payload of the default machine at its rated density, kg (Fig. 52's fill).
///
/// # Errors
/// Loading the built-in machine file.
pub fn full_bucket_kg() -> anyhow::Result<f64> {
    Ok(planner::machine::MachineConfig::default_machine()?.rated_payload_kg())
}

/// The thesis's statements about Fig. 52 on the simulator's rows (fill: payload over the full
/// bucket's `full_kg`).
#[must_use]
pub fn fig52_checks(rows: &[(&'static str, f64, Mean)], full_kg: f64) -> Fig52Checks {
    let figures = |soil: &str, index: f64| {
        rows.iter()
            .find(|r| r.0 == soil && r.1 == index)
            .map_or((0.0, 0.0, 0.0), |(_, _, m)| {
                (m.payload_kg / full_kg, m.time_s, m.energy_kj)
            })
    };
    Fig52Checks::from_figures(
        [figures("soft", 1.0), figures("soft", 5.0)],
        [figures("hard", 1.0), figures("hard", 5.0)],
    )
}

/// One line of the scoreboard: the result, one of the thesis's statements about it, and whether it
/// holds here.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Score {
    /// The thesis result and where it was reproduced, e.g. "Table 2 (dig model)".
    pub result: String,
    /// The statement.
    pub statement: String,
    /// Whether it holds.
    pub holds: bool,
}

/// The simulator's rows of Table 1, Table 2 and Fig. 52.
#[derive(Debug, Clone, PartialEq)]
pub struct SimRows {
    /// Table 1: `(stick angle, plain, with perception)`.
    pub table1: Vec<(f64, Mean, Mean)>,
    /// Table 2: `(force factor, mean)`.
    pub table2: Vec<(f64, Mean)>,
    /// Fig. 52: `(soil, hardness index, mean)`.
    pub fig52: Vec<(&'static str, f64, Mean)>,
}

/// Table 1, Table 2 and Fig. 52 in the simulator with `args`' runs, maps, plant, Table 1 reading,
/// Table 2 scaling and Fig. 52 soils.
///
/// # Errors
/// As the reproductions.
pub fn sim_rows(args: &ScoreboardArgs) -> anyhow::Result<SimRows> {
    let f52 = &args.fig52;
    let maps = f52.sim.autodig_maps()?;
    let contact = f52.sim.soil_contact.into();
    let runs = f52.sim.runs;
    Ok(SimRows {
        table1: table1_with(runs, &maps, contact, args.table1.stick_angle)?,
        table2: table2_with(
            runs,
            &maps,
            args.table2.base_scale,
            args.table2.scaling,
            contact,
        )?,
        fig52: fig52_with(runs, &maps, contact, f52.soils.pa())?,
    })
}

/// Every statement of the thesis about Table 1, Table 2 and Fig. 52, checked in the simulator (with
/// `args`' runs, maps, plant, Table 1 reading, Table 2 scaling and Fig. 52 soils) and in the dig model
/// (`args`' model and start, by default the shipped model from Table 2's start, and its Fig. 52
/// soils).
///
/// # Errors
/// As the reproductions.
pub fn scoreboard(args: &ScoreboardArgs) -> anyhow::Result<Vec<Score>> {
    let f52 = &args.fig52;
    scoreboard_of(&sim_rows(args)?, &f52.model, &f52.model_soils)
}

/// The scoreboard of the simulator's `rows` and the dig model from `model` in `model_soils`.
///
/// # Errors
/// The dig model's errors.
pub fn scoreboard_of(
    rows: &SimRows,
    model: &ModelStartArgs,
    model_soils: &ModelSoils,
) -> anyhow::Result<Vec<Score>> {
    let mut scores = Vec::new();
    let mut add = |result: &str, checks: Vec<(String, bool)>| {
        scores.extend(checks.into_iter().map(|(statement, holds)| Score {
            result: result.to_owned(),
            statement,
            holds,
        }));
    };
    let owned = |c: &[(&str, bool)]| c.iter().map(|(s, b)| ((*s).to_owned(), *b)).collect();
    add("Table 1 (simulator)", owned(&table1_checks(&rows.table1)));
    let figures = |m: &Mean| (m.time_s, m.swept_volume_m3, m.energy_kj);
    if let [(_, a), (_, b), (_, c)] = rows.table2.as_slice() {
        add(
            "Table 2 (simulator)",
            owned(&table2_checks([figures(a), figures(b), figures(c)])),
        );
    }
    add(
        "Fig. 52 (simulator)",
        fig52_checks(&rows.fig52, full_bucket_kg()?)
            .statements()
            .to_vec(),
    );
    let dig_model = model.load_model()?;
    let site = crate::model::start::default_site()?;
    let dig_start = model.start(&site)?;
    let model_rows = crate::model::table2::table2_rows(
        &dig_model,
        model.start_r,
        model.start_depth,
        model.start_bucket_deg,
    )?;
    let figures = |r: &crate::model::table2::Table2Row| (r.time_s, r.volume_m3, r.energy_kj);
    if let [a, b, c] = model_rows.as_slice() {
        add(
            "Table 2 (dig model)",
            owned(&table2_checks([figures(a), figures(b), figures(c)])),
        );
    }
    let f52_model = crate::model::fig52::checks(
        &dig_model,
        (model_soils.soft_cohesion_kpa, model_soils.hard_cohesion_kpa),
        &dig_start,
        &site,
    )?;
    add("Fig. 52 (dig model)", f52_model.statements().to_vec());
    Ok(scores)
}

/// The scoreboard as a Markdown table with the count of statements that hold.
#[must_use]
pub fn scoreboard_markdown(scores: &[Score]) -> String {
    use std::fmt::Write as _;
    let mut s = String::from("| result | the thesis's statement | here |\n|---|---|---|\n");
    for sc in scores {
        // Writing into a String cannot fail.
        let _ = writeln!(
            s,
            "| {} | {} | {} |",
            sc.result,
            sc.statement,
            thesis_verdict(sc.holds)
        );
    }
    let _ = writeln!(
        s,
        "\n{} of {} statements hold.",
        scores.iter().filter(|sc| sc.holds).count(),
        scores.len()
    );
    s
}

/// Runs the chosen reproduction and prints its table next to the thesis's numbers.
///
/// # Errors
/// As [`run_dig`].
pub fn run(args: &ExperimentArgs) -> anyhow::Result<()> {
    print!("{}", report(args)?);
    Ok(())
}

/// The printed report of a reproduction (and the figures, sessions and tables it writes).
///
/// # Errors
/// As [`run_dig`].
pub fn report(args: &ExperimentArgs) -> anyhow::Result<String> {
    match &args.which {
        Which::Table1(a) => table1_report(a),
        Which::Table2(a) => table2_report(a),
        Which::Fig52(a) => fig52_report(a),
        Which::Extended(a) => extended_report(a),
        Which::HardnessFit(a) => hardness_fit_report(&a.out),
        Which::ExtendedDigCheck => extended_dig_check_report(),
        Which::Scoreboard(a) => scoreboard_report(a),
        Which::Results(a) => results_report(a),
        Which::Shift(a) => crate::shift::report(a),
    }
}

/// The line that says the simulator runs without its contact chatter, if it does.
fn contact_note(sim: &SimArgs) -> &'static str {
    if sim.soil_contact == SoilContact::Held {
        "Simulator soil contact: held (plant version held-1, with its contact chatter; the shipped \
         calibrations are fitted on the default, implicit plant)\n\n"
    } else {
        ""
    }
}

/// Table 1 in the simulator: the table next to the thesis's and the checks.
#[must_use]
pub fn table1_markdown(
    rows: &[(f64, Mean, Mean)],
    runs: u64,
    reading: StickAngleReading,
) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    // Writing into a String cannot fail.
    let _ = writeln!(
        s,
        "Table 1: Autodig with and without the perception enhancements ({runs} digs each; payload kg, \
         time s; thesis lbs converted to kg; stick angle {})\n",
        match reading {
            StickAngleReading::Joint => "relative to the boom (joint angle)",
            StickAngleReading::Absolute => "to the horizontal",
        }
    );
    let _ = writeln!(
        s,
        "| stick angle | plain: time | plain: payload | perception: time | perception: payload | \
         thesis plain: time, payload | thesis perception: time, payload |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|");
    for ((stick, plain, with), t) in rows.iter().zip(THESIS_TABLE1) {
        let _ = writeln!(
            s,
            "| {stick:.0} deg | {} | {} | {:.2} s, {:.0} kg | {:.2} s, {:.0} kg |",
            time_payload_cells(plain, runs),
            time_payload_cells(with, runs),
            t.1,
            t.2 * LB_TO_KG,
            t.3,
            t.4 * LB_TO_KG
        );
    }
    write_checks(&mut s, table1_checks(rows));
    s
}

fn table1_report(a: &Table1Args) -> anyhow::Result<String> {
    let rows = table1_with(
        a.sim.runs,
        &a.sim.autodig_maps()?,
        a.sim.soil_contact.into(),
        a.table1.stick_angle,
    )?;
    let mut s = contact_note(&a.sim).to_owned();
    s.push_str(&table1_markdown(&rows, a.sim.runs, a.table1.stick_angle));
    let panel = |name: &str, pick: fn(&(f64, Mean, Mean)) -> &Mean| {
        let curves = rows
            .iter()
            .map(|r| curve(format!("stick {:.0} deg", r.0), pick(r)))
            .collect();
        (name.to_string(), curves)
    };
    s.push_str(&write_figure(
        &a.out.out,
        "table1.svg",
        "Table 1: Autodig from three stick angles",
        &[
            panel("plain (fixed beta, gamma)", |r| &r.1),
            panel("with the perception enhancements", |r| &r.2),
        ],
    )?);
    Ok(s)
}

/// Table 2 in the simulator: the table next to the thesis's and the checks.
#[must_use]
pub fn table2_markdown(rows: &[(f64, Mean)], runs: u64, options: &Table2Options) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    // Writing into a String cannot fail.
    let _ = writeln!(
        s,
        "Table 2: soil force x1, x2, x3 ({}, base soil scaled by {}; {runs} digs each)\n",
        match options.scaling {
            Table2Scaling::Force => "the soil's force on the bucket times the factor",
            Table2Scaling::Soil => "cohesion and density times the factor",
        },
        options.base_scale,
    );
    let _ = writeln!(
        s,
        "| factor | time | swept volume | energy | payload | thesis: time, volume, energy |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|");
    for ((k, m), t) in rows.iter().zip(THESIS_TABLE2) {
        let _ = writeln!(
            s,
            "| {k:.1} | {:.2} s | {:.2} m^3 | {:.0} kJ | {:.0} kg | {} s, {} m^3, {} kJ |",
            m.time_s, m.swept_volume_m3, m.energy_kj, m.payload_kg, t.1, t.2, t.3
        );
    }
    let figures = |m: &Mean| (m.time_s, m.swept_volume_m3, m.energy_kj);
    if let [(_, a), (_, b), (_, c)] = rows {
        write_checks(&mut s, table2_checks([figures(a), figures(b), figures(c)]));
    }
    s
}

/// The heading of the simulator's section of a report that has the dig model's too.
const SIM_SECTION: &str = "## Simulator (closed loop, in-process, virtual time)\n\n";
/// The heading of the dig model's section.
const MODEL_SECTION: &str = "\n## Dig model (the planner's, as the thesis made it)\n\n";

fn table2_report(a: &Table2Args) -> anyhow::Result<String> {
    let rows = table2_with(
        a.sim.runs,
        &a.sim.autodig_maps()?,
        a.table2.base_scale,
        a.table2.scaling,
        a.sim.soil_contact.into(),
    )?;
    let mut s = format!("{SIM_SECTION}{}", contact_note(&a.sim));
    s.push_str(&table2_markdown(&rows, a.sim.runs, &a.table2));
    let curves = rows
        .iter()
        .map(|(k, m)| curve(format!("force factor {k:.0}"), m))
        .collect();
    s.push_str(&write_figure(
        &a.out.out,
        "fig39.svg",
        "Fig. 39 / Table 2: the same dig at three soil force levels",
        &[(String::new(), curves)],
    )?);
    s.push_str(MODEL_SECTION);
    s.push_str(&crate::model::table2::report(&a.model, Some(&a.out.out))?);
    Ok(s)
}

/// Fig. 52 in the simulator: the table, the thesis's figure in words and the checks (fill: payload
/// over `full_kg`).
#[must_use]
pub fn fig52_markdown(
    rows: &[(&'static str, f64, Mean)],
    runs: u64,
    soils: &Fig52Soils,
    full_kg: f64,
) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    // Writing into a String cannot fail.
    let _ = writeln!(
        s,
        "Fig. 52: hardness index 1 and 5 in soft (c = {} kPa) and hard (c = {} kPa) soil ({runs} digs each; \
         fill = payload / {full_kg:.0} kg)\n",
        soils.soft_cohesion_kpa, soils.hard_cohesion_kpa
    );
    let _ = writeln!(s, "| soil | index | fill | time | energy | swept volume |");
    let _ = writeln!(s, "|---|---|---|---|---|---|");
    for (soil, index, m) in rows {
        let _ = writeln!(
            s,
            "| {soil} | {index:.0} | {:.0} % | {:.2} s | {:.0} kJ | {:.2} m^3 |",
            100.0 * m.payload_kg / full_kg,
            m.time_s,
            m.energy_kj,
            m.swept_volume_m3
        );
    }
    let _ = writeln!(
        s,
        "\nThesis: soft soil, both indices fill the bucket; the higher index digs too deep, +60 % time \
         and +75 % energy. Hard soil: the low index fills about 50 %, the high index fully. \
         The thesis made the figure with its dig model (the dig model's section)."
    );
    write_checks(&mut s, fig52_checks(rows, full_kg).statements());
    s
}

fn fig52_report(a: &Fig52Args) -> anyhow::Result<String> {
    let soils = a.soils.pa();
    let rows = fig52_with(
        a.sim.runs,
        &a.sim.autodig_maps()?,
        a.sim.soil_contact.into(),
        soils,
    )?;
    let full_kg = full_bucket_kg()?;
    let mut s = format!("{SIM_SECTION}{}", contact_note(&a.sim));
    s.push_str(&fig52_markdown(&rows, a.sim.runs, &a.soils, full_kg));
    let panels: Vec<_> = soils
        .iter()
        .map(|(soil, cohesion)| {
            let curves = rows
                .iter()
                .filter(|r| r.0 == *soil)
                .map(|(_, index, m)| {
                    curve(
                        format!(
                            "index {index:.0}: fill {:.0} %",
                            100.0 * m.payload_kg / full_kg
                        ),
                        m,
                    )
                })
                .collect();
            (
                format!("{soil} soil (c = {:.0} kPa)", cohesion / 1000.0),
                curves,
            )
        })
        .collect();
    s.push_str(&write_figure(
        &a.out.out,
        "fig52.svg",
        "Fig. 52: Autodig's soil hardness index 1 and 5",
        &panels,
    )?);
    s.push_str(MODEL_SECTION);
    s.push_str(&crate::model::fig52::report(
        &a.model,
        &a.model_soils,
        Some(&a.out.out),
    )?);
    Ok(s)
}

fn scoreboard_report(a: &ScoreboardArgs) -> anyhow::Result<String> {
    let table = scoreboard_markdown(&scoreboard(a)?);
    let out = &a.fig52.out.out;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let path = out.join("scoreboard.md");
    std::fs::write(&path, &table).with_context(|| format!("writing {}", path.display()))?;
    Ok(format!(
        "The thesis's statements about Table 1, Table 2 and Fig. 52 ({} runs each in the \
         simulator; the dig model from Table 2's start)\n\n{table}\nWritten to {}\n",
        a.fig52.sim.runs,
        path.display()
    ))
}

/// The two sessions of the extended-operation comparison (6.2).
#[derive(Debug, Clone)]
pub struct ExtendedRuns {
    /// The perception-based dig planner.
    pub planned: crate::demo::DemoSummary,
    /// The predefined excavation sequence, started at the median of the planner's starts.
    pub predefined: crate::demo::DemoSummary,
}

/// Runs a planned session of `digs` on the extended-operation bench, then the predefined sequence
/// with the median of the planner's dig starts (6.2's "virtual expert"), each written to its folder
/// under `out` (docs/demo-output.md), and the Fig. 60 plot (`out/fig60.svg`). Both sessions run with
/// the simulator seed `seed` (`None`: the bench file's).
///
/// # Errors
/// As [`crate::demo::run_session`]; no planned dig to take the median of.
pub fn extended(
    digs: u32,
    seed: Option<u64>,
    out: &std::path::Path,
    planner: Option<&std::path::Path>,
) -> anyhow::Result<ExtendedRuns> {
    use crate::demo::{DemoArgs, DemoStrategy, dig_starts, run_session};
    use anyhow::Context as _;
    let stop = std::sync::atomic::AtomicBool::new(false);
    let mut args = DemoArgs::planned(out.join("planned"));
    args.digs = digs;
    args.seed = seed;
    args.planner = planner.map(std::path::Path::to_path_buf);
    args.bench_after = vec![12, digs / 2];
    let planned = run_session(&args, &stop).context("planned session")?;
    let median = controller::session::planned::median_joints(&dig_starts(&planned.digs))
        .context("the planned session made no dig to take the median start of")?;
    let mut args = DemoArgs::planned(out.join("predefined"));
    args.strategy = DemoStrategy::Predefined;
    args.digs = digs;
    args.seed = seed;
    args.planner = planner.map(std::path::Path::to_path_buf);
    args.bench_after = vec![12, digs / 2];
    args.predefined_joints = Some(median);
    let predefined = run_session(&args, &stop).context("predefined session")?;
    let path = out.join("fig60.svg");
    std::fs::write(
        &path,
        crate::plots::weight_sequence_svg(&planned.digs, &predefined.digs)?,
    )
    .with_context(|| format!("writing {}", path.display()))?;
    Ok(ExtendedRuns {
        planned,
        predefined,
    })
}

/// The comparison of [`extended`] as Tables 3-5 with the targets.
pub fn extended_markdown(runs: &ExtendedRuns) -> String {
    use std::fmt::Write as _;
    let (p, d) = (&runs.planned, &runs.predefined);
    let mut s = String::new();
    // Writing into a String cannot fail.
    let _ = writeln!(
        s,
        "Extended operation on \"{}\" (thesis 6.1-6.2): the dig planner and the predefined sequence\n",
        p.bench
    );
    let _ = writeln!(
        s,
        "Table 3: | strategy | digs | backups | cleanups | weight (N) | time (s) | energy (kJ) | ended |\n|---|---|---|---|---|---|---|---|"
    );
    for r in [p, d] {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {:.0} | {:.1} | {:.0} | {} |",
            r.strategy,
            r.totals.digs,
            r.backups,
            r.cleanups,
            r.totals.mean_weight_n,
            r.totals.mean_time_s,
            r.totals.mean_energy_kj,
            r.end
        );
    }
    let _ = writeln!(
        s,
        "| thesis test 3 | 109 | 6 | | 21300 | 7.6 | 252 | bench removed |\n"
    );
    let _ = writeln!(
        s,
        "Table 4: | strategy | dig actions: weight, time, energy | cleanup actions: weight, time, energy |\n|---|---|---|"
    );
    for r in [p, d] {
        let t = &r.stats;
        let _ = writeln!(
            s,
            "| {} | {:.0} N, {:.1} s, {:.0} kJ | {:.0} N, {:.1} s, {:.0} kJ |",
            r.strategy,
            t.dig_mean_weight_n,
            t.dig_mean_time_s,
            t.dig_mean_energy_kj,
            t.cleanup_mean_weight_n,
            t.cleanup_mean_time_s,
            t.cleanup_mean_energy_kj
        );
    }
    let _ = writeln!(
        s,
        "| thesis test 3 | 21201 N, 5.8 s, 212 kJ | 21590 N, 12.8 s, 366 kJ |\n"
    );
    let _ = writeln!(
        s,
        "Table 5 (per cycle): | strategy | weight (N) | time (s) | energy (kJ) | productivity Eq. 26 (N/s) | energy/weight Eq. 27 (J/N) |\n|---|---|---|---|---|---|"
    );
    for r in [p, d] {
        let _ = writeln!(
            s,
            "| {} | {:.0} | {:.1} | {:.0} | {:.0} | {:.2} |",
            r.strategy,
            r.totals.mean_weight_n,
            r.totals.mean_time_s,
            r.totals.mean_energy_kj,
            r.stats.productivity_n_per_s,
            1e3 * r.stats.energy_per_weight_kj_per_n
        );
    }
    let _ = writeln!(
        s,
        "| thesis planner / predefined | 23992 / 19397 | 7.5 / 6.5 | 272 / 147 | | |\n"
    );
    let gain = if d.stats.dig_mean_weight_n > 0.0 {
        100.0 * (p.stats.dig_mean_weight_n / d.stats.dig_mean_weight_n - 1.0)
    } else {
        f64::NAN
    };
    let ok = |b: bool| if b { "met" } else { "NOT met" };
    let _ = writeln!(
        s,
        "Targets of the extended run (thesis ch. 6):\n\
         - planned: {} digs (>= 100), {} backups (>= 3), no human input: {}\n\
         - buckets over half full: {:.0} % (>= 94 %; thesis test 3: 94 %): {}\n\
         - payload per normal dig, planner over predefined: {:+.0} % (>= +30 %; thesis +42 %): {}\n\
         - bucket fill over the run (Fig. 60, normal digs): planner {:.0} N first half, {:.0} N second half \
         (trend {:+.0} N/dig); predefined {:.0} N, {:.0} N (trend {:+.0} N/dig); planner does not decay: {}",
        p.totals.digs,
        p.backups,
        ok(p.totals.digs >= 100 && p.backups >= 3),
        100.0 * p.stats.over_half_full,
        ok(p.stats.over_half_full >= 0.94),
        gain,
        ok(gain >= 30.0),
        p.stats.dig_mean_weight_first_half_n,
        p.stats.dig_mean_weight_second_half_n,
        p.stats.dig_weight_slope_n_per_dig,
        d.stats.dig_mean_weight_first_half_n,
        d.stats.dig_mean_weight_second_half_n,
        d.stats.dig_weight_slope_n_per_dig,
        ok(p.stats.dig_mean_weight_second_half_n >= 0.9 * p.stats.dig_mean_weight_first_half_n)
    );
    s
}

fn extended_report(args: &ExtendedArgs) -> anyhow::Result<String> {
    let out = args.out.out.join("extended");
    let runs = extended(args.digs, args.seed, &out, args.planner.as_deref())?;
    let text = extended_markdown(&runs);
    let path = out.join("comparison.md");
    std::fs::write(&path, &text).map_err(|e| anyhow::anyhow!("writing {}: {e}", path.display()))?;
    Ok(format!(
        "{text}\nOutputs: {} (planned/, predefined/, fig60.svg, comparison.md)\n",
        out.display()
    ))
}

/// The extended run's headline figures over several seeds (`experiment results`).
#[must_use]
pub fn extended_seed_rows(runs: &[ExtendedRuns]) -> Vec<crate::results::SeedRow> {
    use crate::results::{Better, SeedRow};
    /// The planner's gain over the predefined sequence, %.
    fn gain(planned: f64, predefined: f64) -> f64 {
        if predefined > 0.0 {
            100.0 * (planned / predefined - 1.0)
        } else {
            f64::NAN
        }
    }
    type Figure = (&'static str, Better, usize, fn(&ExtendedRuns) -> f64);
    #[rustfmt::skip] // A table: one figure a line.
    let figures: [Figure; 10] = [
        ("planned: actions (digs and cleanups)", Better::Higher, 0, |r| r.planned.totals.digs as f64),
        ("planned: backups", Better::Higher, 0, |r| r.planned.backups as f64),
        ("planned: cleanups", Better::Neither, 0, |r| r.planned.cleanups as f64),
        ("planned: buckets over half full, % (target >= 94; thesis test 3: 94)", Better::Higher, 0,
            |r| 100.0 * r.planned.stats.over_half_full),
        ("payload per normal dig, planner over predefined, % (target >= +30; thesis +42)", Better::Higher, 0,
            |r| gain(r.planned.stats.dig_mean_weight_n, r.predefined.stats.dig_mean_weight_n)),
        ("weight per cycle, planner over predefined, %", Better::Higher, 0,
            |r| gain(r.planned.totals.mean_weight_n, r.predefined.totals.mean_weight_n)),
        ("planned: productivity, Eq. 26, N/s", Better::Higher, 0, |r| r.planned.stats.productivity_n_per_s),
        ("predefined: productivity, Eq. 26, N/s", Better::Neither, 0, |r| r.predefined.stats.productivity_n_per_s),
        ("planned: energy per weight, Eq. 27, J/N", Better::Lower, 2,
            |r| 1e3 * r.planned.stats.energy_per_weight_kj_per_n),
        ("planned: trend of the normal digs' weight (Fig. 60), N per dig", Better::Higher, 0,
            |r| r.planned.stats.dig_weight_slope_n_per_dig),
    ];
    figures
        .iter()
        .map(|(name, better, decimals, f)| SeedRow {
            name: (*name).to_owned(),
            values: runs.iter().map(f).collect(),
            better: *better,
            decimals: *decimals,
        })
        .collect()
}

/// The results page: the scoreboard, Tables 1 and 2 and Fig. 52 in the simulator and the dig model,
/// the extended run over `args.seeds` seeds and the dig model's speed, each with the command that
/// prints it.
///
/// # Errors
/// As the reproductions and [`extended`].
pub fn results_page(args: &ResultsArgs) -> anyhow::Result<String> {
    use crate::results::{Page, Provenance, seeds_table};
    let runs = args.runs;
    let board = ScoreboardArgs {
        fig52: Fig52Args {
            sim: SimArgs {
                runs,
                maps: None,
                soil_contact: SoilContact::Implicit,
            },
            soils: Fig52Soils {
                soft_cohesion_kpa: FIG52_SOILS[0].1 / 1e3,
                hard_cohesion_kpa: FIG52_SOILS[1].1 / 1e3,
            },
            model: ModelStartArgs::default(),
            model_soils: ModelSoils::default(),
            out: OutArgs {
                out: args.sessions.clone(),
            },
        },
        table1: Table1Options {
            stick_angle: StickAngleReading::Joint,
        },
        table2: Table2Options {
            base_scale: TABLE2_BASE_SCALE,
            scaling: Table2Scaling::Soil,
        },
    };
    let (model, model_soils) = (&board.fig52.model, &board.fig52.model_soils);
    let rows = sim_rows(&board)?;
    let full_kg = full_bucket_kg()?;
    let mut page = Page::new(
        Provenance::now(),
        &format!(
            "The simulator runs in-process in virtual time on the default machine and benches \
             (`config/`), seeds 1..={runs}; the dig model is the shipped one \
             (`config/nominal_actuator.json`). Each section names the command that prints its \
             figures ({} build).",
            if cfg!(debug_assertions) {
                "debug"
            } else {
                "release"
            }
        ),
    );
    let command = |which: &str| format!("excavator-ctl experiment {which} --runs {runs}");
    page.section(
        "The thesis's statements about Table 1, Table 2 and Fig. 52",
        &[command("scoreboard")],
        &scoreboard_markdown(&scoreboard_of(&rows, model, model_soils)?),
    );
    page.section(
        "Table 1 (thesis 3.2): the perception enhancements",
        &[command("table1")],
        &table1_markdown(&rows.table1, runs, board.table1.stick_angle),
    );
    page.section(
        "Table 2 (thesis 4.4): soil force x1, x2, x3",
        &[command("table2")],
        &format!(
            "### Simulator\n\n{}\n### Dig model\n\n{}",
            table2_markdown(&rows.table2, runs, &board.table2),
            crate::model::table2::report(model, None)?
        ),
    );
    page.section(
        "Fig. 52 (thesis 5.2): the soil hardness index",
        &[command("fig52")],
        &format!(
            "### Simulator\n\n{}\n### Dig model\n\n{}",
            fig52_markdown(&rows.fig52, runs, &board.fig52.soils, full_kg),
            crate::model::fig52::report(model, model_soils, None)?
        ),
    );
    let seeds: Vec<u64> = (1..=args.seeds).collect();
    let mut extended_runs = Vec::new();
    for &seed in &seeds {
        let out = args.sessions.join(format!("extended-seed-{seed}"));
        extended_runs.push(
            extended(args.digs, Some(seed), &out, None)
                .with_context(|| format!("extended run, seed {seed}"))?,
        );
    }
    page.section(
        &format!(
            "Extended operation (thesis 6.1-6.2, Tables 3-5, Fig. 60): {} digs per strategy",
            args.digs
        ),
        &seeds
            .iter()
            .map(|seed| format!("excavator-ctl experiment extended --digs {} --seed {seed}", args.digs))
            .collect::<Vec<_>>(),
        &format!(
            "The planned session and the predefined sequence (started at the median of the planned \
             starts) on the extended-operation bench; each command prints its seed's Tables 3-5.\n\n{}",
            seeds_table(&seeds, &extended_seed_rows(&extended_runs))
        ),
    );
    let speed = crate::model::speed::measure(model, 300)?;
    page.section(
        "Dig model speed (thesis 4.1)",
        &["excavator-ctl experiment results".to_owned()],
        &format!(
            "Table 2's x1 dig predicted {} times in this process; the fastest run is one the scheduler \
             did not interrupt (`cargo bench -p planner --bench dig_model` profiles the step).\n\n\
             | figure | value | target |\n|---|---|---|\n\
             | one {:.2} s dig ({} steps), fastest | {:.3} ms = {:.0}x real time | >= 10,000x |\n\
             | same, median run | {:.3} ms = {:.0}x | |\n",
            speed.runs,
            speed.dig_time_s,
            speed.steps,
            speed.fastest_s * 1e3,
            speed.real_time_factor(),
            speed.median_s * 1e3,
            speed.dig_time_s / speed.median_s
        ),
    );
    Ok(page.finish())
}

fn results_report(args: &ResultsArgs) -> anyhow::Result<String> {
    let t0 = std::time::Instant::now();
    let page = results_page(args)?;
    if let Some(dir) = args.out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    std::fs::write(&args.out, &page).with_context(|| format!("writing {}", args.out.display()))?;
    Ok(format!(
        "Wrote {} in {:.0} s (sessions in {})\n",
        args.out.display(),
        t0.elapsed().as_secs_f64(),
        args.sessions.display()
    ))
}

/// Fits the hardness regression of 5.2 by simulation ([`planner::plan::hardness::fit_hardness_regression`]
/// on [`planner::plan::hardness::default_sweep`] with the nominal dig model and the shipped quality
/// settings) and writes `hardness_regression.toml` and `fig53.svg` into `out`.
///
/// # Errors
/// Dig model, sweep or fit errors; I/O.
pub fn hardness_fit(out: &std::path::Path) -> anyhow::Result<planner::plan::hardness::HardnessFit> {
    use anyhow::Context as _;
    let model = planner::dig_model::DigModel::nominal().context("nominal dig model")?;
    hardness_fit_with(&model, out, "excavator-ctl experiment hardness-fit", None)
}

/// As [`hardness_fit`] with the dig model `model` (`source` names it in the file's header); with
/// `origin` the regression records it (`[origin]`, as `excavator-ctl calibrate` writes it).
///
/// # Errors
/// As [`hardness_fit`].
pub fn hardness_fit_with<A: planner::dig_model::ActuatorDynamics + Clone>(
    model: &planner::dig_model::DigModel<A>,
    out: &std::path::Path,
    source: &str,
    origin: Option<planner::origin::ArtefactOrigin>,
) -> anyhow::Result<planner::plan::hardness::HardnessFit> {
    use anyhow::Context as _;
    use planner::plan::hardness::{default_sweep, fit_hardness_regression};
    let sweep = default_sweep()?;
    let planner_cfg = planner::plan::PlannerConfig::nominal()?;
    let mut quality = planner_cfg.quality;
    if quality.v_max_m3 <= 0.0 {
        quality.v_max_m3 = model.config().autodig.perception.bucket_capacity_m3;
    }
    let mut fit = fit_hardness_regression(model, &sweep, &quality)?;
    fit.regression.origin = origin;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let header = format!(
        "Autodig soil hardness index from the average soil force (thesis 5.2, Eq. 25, Fig. 53):\n\
         index = intercept + slope_per_kn x |F(Gamma_typical)| / 1 kN, clamped to [min_index, max_index].\n\
         Fitted by `{source}` (planner::plan::hardness::fit_hardness_regression\n\
         on default_sweep(): {} soils x {} terrains x {} indices, config/planner.toml quality).\n\
         The {}; the line is used where its slope is at least {} standard errors from zero.",
        sweep.soils.len(),
        sweep.terrains.len(),
        sweep.indices.len(),
        hardness_line_note(&fit.line),
        planner::plan::hardness::SLOPE_T_MIN,
    );
    let path = out.join("hardness_regression.toml");
    std::fs::write(&path, fit.regression.to_toml(&header))
        .with_context(|| format!("writing {}", path.display()))?;
    let points: Vec<(f64, f64)> = fit
        .points
        .iter()
        .map(|p| (p.average_force_n / 1e3, p.best_index))
        .collect();
    let path = out.join("fig53.svg");
    std::fs::write(
        &path,
        crate::plots::hardness_fit_svg(
            &points,
            fit.regression.intercept,
            fit.regression.slope_per_kn,
        )?,
    )
    .with_context(|| format!("writing {}", path.display()))?;
    Ok(fit)
}

/// How the hardness sweep's least-squares line became the regression, for the reports.
#[must_use]
pub fn hardness_line_note(line: &planner::plan::hardness::HardnessLine) -> String {
    let fit = format!(
        "least-squares line {:.3} + {:.5} x force/kN, r^2 {:.3}, slope t {:.2}",
        line.intercept, line.slope_per_kn, line.r_squared, line.slope_t
    );
    if line.slope_t.abs() >= planner::plan::hardness::SLOPE_T_MIN {
        fit
    } else {
        format!(
            "{fit}: the slope is not significant (|t| < {}), so the mean optimal index",
            planner::plan::hardness::SLOPE_T_MIN
        )
    }
}

fn hardness_fit_report(out: &std::path::Path) -> anyhow::Result<String> {
    use std::fmt::Write as _;
    let out = out.join("hardness");
    let t0 = std::time::Instant::now();
    let fit = hardness_fit(&out)?;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "Fig. 53: optimal Autodig index per soil and terrain against the average soil force (Eq. 25)\n\n\
         | soil | terrain | average force (kN) | optimal index | quality |\n|---|---|---|---|---|"
    );
    for p in &fit.points {
        let _ = writeln!(
            s,
            "| {} | {} | {:.1}{} | {:.1} | {:.2} |",
            p.soil,
            p.terrain,
            p.average_force_n / 1e3,
            if p.analytical_fallback {
                " (analytical)"
            } else {
                ""
            },
            p.best_index,
            p.best_quality
        );
    }
    let r = &fit.regression;
    let _ = writeln!(
        s,
        "\nindex = {:.3} + {:.5} x force/kN (r^2 {:.3}, {} cases; {}) in {:.1} s; thesis: the index rises with the force.\n\
         Outputs: {} (hardness_regression.toml, fig53.svg)",
        r.intercept,
        r.slope_per_kn,
        r.r_squared,
        r.cases,
        hardness_line_note(&fit.line),
        t0.elapsed().as_secs_f64(),
        out.display()
    );
    Ok(s)
}

/// One start of [`extended_dig_check`]: the simulator and the dig model from the same start on the
/// extended bench (the simulator's true pre-dig section for both).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct DigCheck {
    /// Machine x in the world (the crest of the face is at `4 - machine_x_m` m from the swing axis).
    pub machine_x_m: f64,
    /// The start tip `[r, z, bucket_abs_deg]` on the surface, base frame.
    pub start: [f64; 3],
    /// Where the simulated dig began Pre-Dig (after Boom-Down when `boom_down`), `[r, z]`, m.
    pub sim_predig_start: [f64; 2],
    /// Lowest tip z: simulator, dig model, m.
    pub min_tip_z_m: [f64; 2],
    /// Swept volume: simulator, dig model, m^3.
    pub swept_m3: [f64; 2],
    /// Dig time (Pre-Dig to Done): simulator, dig model, s.
    pub time_s: [f64; 2],
    /// The simulator's bucket content at the end, m^3.
    pub sim_bucket_m3: f64,
    /// Mean soil force magnitude over the Pre-Dig and Dig samples in contact: simulator, and the dig
    /// model's soil model at the simulator's pose, velocities, cut terrain and content (open loop), N.
    pub mean_soil_force_n: [f64; 2],
    /// Mean `(F_x, F_z)` of the same samples: simulator, open-loop model, N.
    pub mean_soil_fxz_n: [[f64; 2]; 2],
    /// End reasons: simulator, dig model.
    pub end: [String; 2],
}

/// Digs from a grid of starts on the extended bench (machine at world x 0, -1.5, -3: crest at 4, 5.5,
/// 7 m) in the simulator and in the nominal dig model from the same start over the simulator's true
/// section: where their tip paths part (the model once predicted the tip 0.5-1.2 m deeper than
/// the simulator took it for starts high on the face). With `boom_down` the simulated dig starts
/// [`controller::session::planned::APPROACH_HEIGHT_M`] above the start with Autodig's Boom-Down, as in a session;
/// the model starts in Pre-Dig on the start as the refined planner evaluates it.
///
/// # Errors
/// Simulator, kinematics, Autodig or dig-model errors.
pub fn extended_dig_check(boom_down: bool) -> anyhow::Result<Vec<DigCheck>> {
    use anyhow::Context as _;
    use planner::autodig::{Autodig, AutodigInputs, Stage};
    use planner::dig_model::{DigModel, DigSite, DigStart};
    use planner::kinematics::{BucketPose, Joint, Kinematics, MachinePose};
    use planner::terrain::SweptVolume;
    use vcan_sim::scenario::Scenario;
    let base = {
        let mut sim = SimConfig::load::<&str>(None, None, Some(1), &[])?;
        sim.scenario = Scenario::from_toml_str_named(
            crate::demo::EXTENDED_BENCH_TOML,
            "config/bench_extended.toml",
        )
        .context("built-in extended bench")?;
        sim
    };
    let kin = Kinematics::new(&base.machine)?;
    let model = DigModel::nominal()?;
    let maps = AutodigMaps::builtin()?;
    let strokes = Joint::ALL.map(|j| kin.stroke(j));
    let mut ad_cfg = model.config().autodig;
    ad_cfg.relief_pressure_pa = [base.machine.hydraulics.relief_pressure_pa; 3];
    ad_cfg.perception.bucket_capacity_m3 = base.machine.bucket.capacity_m3;
    let mut rows = Vec::new();
    for machine_x_m in [0.0, -1.5, -3.0] {
        let crest = 4.0 - machine_x_m;
        let pose = MachinePose {
            x_m: machine_x_m,
            y_m: 0.0,
            heading_rad: 0.0,
        };
        for dr in [-0.8, 0.0, 0.6, 1.2, 1.8] {
            for bucket_abs_deg in [-60.0, -90.0, -120.0] {
                let mut sim = base.clone();
                sim.scenario.start.x_m = machine_x_m;
                let plant0 = sim.build()?;
                let profile = plant0.world.terrain.section(&pose, 0.0, 0.5, 12.0, 0.05)?;
                let r = crest + dr;
                let z = profile.height_at(r)?;
                let start = BucketPose {
                    x_m: r,
                    z_m: z,
                    bucket_abs_rad: f64::to_radians(bucket_abs_deg),
                };
                let Ok(q) = kin.inverse(&start) else {
                    continue;
                };
                if kin.cylinder_lengths(&q).is_err() {
                    continue;
                }
                let site = DigSite::new(profile.clone(), -2.0)?;
                let Ok(pred) = model.predict(&DigStart::Joints(q), &site) else {
                    continue;
                };
                let q_sim = if boom_down {
                    controller::session::planned::approach_joints(
                        &kin,
                        q,
                        controller::session::planned::APPROACH_HEIGHT_M,
                    )
                } else {
                    q
                };
                sim.scenario.start.boom_deg = q_sim.boom_rad.to_degrees();
                sim.scenario.start.stick_deg = q_sim.stick_rad.to_degrees();
                sim.scenario.start.bucket_deg = q_sim.bucket_rad.to_degrees();
                sim.scenario.start.swing_deg = 0.0;
                let mut plant = sim.build()?;
                let mut swept = SweptVolume::new(profile.clone(), base.machine.bucket.width_m)?;
                let mut autodig = Autodig::starting_in(
                    ad_cfg,
                    maps.clone(),
                    if boom_down {
                        Stage::BoomDown
                    } else {
                        Stage::PreDig
                    },
                )?;
                let mut min_z = f64::INFINITY;
                let mut predig_start = None;
                let mut t_predig = 0.0;
                let mut end = None;
                let (mut f_sum, mut fm_sum, mut n_f) = (0.0, 0.0, 0usize);
                let (mut fxz, mut fxz_m) = ([0.0; 2], [0.0; 2]);
                let mut t_done = f64::NAN;
                for step in 0..4000usize {
                    let t = step as f64 * crate::demo::PERIOD_S;
                    let rd = plant.read_sensors();
                    let qn = plant.joint_angles();
                    let tip = kin.forward(&qn);
                    let mut ext = [0.0; 3];
                    for (j, joint) in Joint::ALL.iter().enumerate() {
                        let len = kin.cylinder_length(*joint, qn.to_vector()[j])?;
                        ext[j] =
                            ((len - strokes[j].0) / (strokes[j].1 - strokes[j].0)).clamp(0.0, 1.0);
                    }
                    let in_dig = predig_start.is_some();
                    let inputs = AutodigInputs {
                        joint_rad: [qn.boom_rad, qn.stick_rad, qn.bucket_rad],
                        head_pressure_pa: rd.head_pa,
                        rod_pressure_pa: rd.rod_pa,
                        extension_fraction: ext,
                        swept_volume_m3: if in_dig {
                            swept.update(tip.x_m, tip.z_m).ok()
                        } else {
                            Some(0.0)
                        },
                        bucket_depth_m: swept.depth_m(tip.x_m, tip.z_m).ok(),
                    };
                    let out = autodig.step(&inputs, t)?;
                    if predig_start.is_none() && out.stage != Stage::BoomDown {
                        predig_start = Some([tip.x_m, tip.z_m]);
                        t_predig = t;
                        swept = SweptVolume::new(profile.clone(), base.machine.bucket.width_m)?;
                    }
                    if predig_start.is_some() {
                        min_z = min_z.min(tip.z_m);
                        if matches!(out.stage, Stage::PreDig | Stage::Dig) {
                            let truth = plant.true_state();
                            let fs = truth.soil_force_n;
                            if fs[0].hypot(fs[1]) > 1.0 {
                                let now =
                                    plant.world.terrain.section(&pose, 0.0, 0.5, 12.0, 0.05)?;
                                let v = [0, 1, 2].map(|i| plant.hydraulics.actuators[i].velocity);
                                let fm = model.soil_force_at(
                                    &qn,
                                    v,
                                    &now,
                                    plant.contact.content.volume_m3,
                                )?;
                                f_sum += fs[0].hypot(fs[1]);
                                fm_sum += fm.fx_n.hypot(fm.fz_n);
                                fxz[0] += fs[0];
                                fxz[1] += fs[1];
                                fxz_m[0] += fm.fx_n;
                                fxz_m[1] += fm.fz_n;
                                n_f += 1;
                            }
                        }
                    }
                    let command = out.command;
                    if out.stage == Stage::Done {
                        end = out.end_reason;
                        t_done = t - t_predig;
                        break;
                    }
                    for _ in 0..10 {
                        plant.step([command[0], command[1], command[2], 0.0, 0.0, 0.0]);
                    }
                }
                let n = n_f.max(1) as f64;
                let s = &pred.summary;
                rows.push(DigCheck {
                    machine_x_m,
                    start: [r, z, bucket_abs_deg],
                    sim_predig_start: predig_start.unwrap_or([f64::NAN; 2]),
                    min_tip_z_m: [min_z, s.min_tip_z_m],
                    swept_m3: [swept.volume_m3(), s.swept_volume_m3],
                    time_s: [t_done, s.time_s],
                    sim_bucket_m3: plant.contact.content.volume_m3,
                    mean_soil_force_n: [f_sum / n, fm_sum / n],
                    mean_soil_fxz_n: [[fxz[0] / n, fxz[1] / n], [fxz_m[0] / n, fxz_m[1] / n]],
                    end: [
                        end.map_or_else(|| "none".to_owned(), |e| format!("{e:?}")),
                        format!("{:?}", s.end),
                    ],
                });
            }
        }
    }
    Ok(rows)
}

fn extended_dig_check_report() -> anyhow::Result<String> {
    use std::fmt::Write as _;
    let mut s = String::new();
    for boom_down in [false, true] {
        let rows = extended_dig_check(boom_down)?;
        let _ = writeln!(
            s,
            "\nSimulator vs dig model on the extended bench ({}; model from Pre-Dig on the start)\n",
            if boom_down {
                "simulator: Boom-Down from 0.8 m above"
            } else {
                "simulator: Pre-Dig on the start"
            }
        );
        let _ = writeln!(
            s,
            "| machine x | start r, z, bucket | sim Pre-Dig r, z | min z sim / model | swept sim / model | bucket | time sim / model | |F| sim / model (kN) | Fx, Fz sim | Fx, Fz model | end sim / model |\n|---|---|---|---|---|---|---|---|---|---|---|"
        );
        for r in &rows {
            let _ = writeln!(
                s,
                "| {:.1} | {:.2}, {:.2}, {:.0} | {:.2}, {:.2} | {:.2} / {:.2} | {:.2} / {:.2} | {:.2} | {:.1} / {:.1} | {:.1} / {:.1} | {:.1}, {:.1} | {:.1}, {:.1} | {} / {} |",
                r.machine_x_m,
                r.start[0],
                r.start[1],
                r.start[2],
                r.sim_predig_start[0],
                r.sim_predig_start[1],
                r.min_tip_z_m[0],
                r.min_tip_z_m[1],
                r.swept_m3[0],
                r.swept_m3[1],
                r.sim_bucket_m3,
                r.time_s[0],
                r.time_s[1],
                r.mean_soil_force_n[0] * 1e-3,
                r.mean_soil_force_n[1] * 1e-3,
                r.mean_soil_fxz_n[0][0] * 1e-3,
                r.mean_soil_fxz_n[0][1] * 1e-3,
                r.mean_soil_fxz_n[1][0] * 1e-3,
                r.mean_soil_fxz_n[1][1] * 1e-3,
                r.end[0],
                r.end[1]
            );
        }
    }
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn m(payload_kg: f64, time_s: f64) -> Mean {
        Mean {
            payload_kg,
            time_s,
            energy_kj: 200.0,
            swept_volume_m3: 1.5,
            completed: 1,
            first: None,
        }
    }

    /// The thesis's own Table 1 (lbs to kg) passes every check; ours read to the horizontal fails the
    /// perception consistency only (2111 against 2550 kg).
    #[test]
    fn table1_checks_hold_for_the_thesis_and_tell_an_inconsistent_payload() {
        let thesis = [
            (-87.0, m(1880.0, 6.58), m(2418.0, 7.13)),
            (-70.0, m(2346.0, 10.35), m(2417.0, 7.47)),
            (-50.0, m(2960.0, 13.83), m(2421.0, 8.77)),
        ];
        assert!(table1_checks(&thesis).iter().all(|c| c.1));
        let horizontal = [
            (-87.0, m(1560.0, 4.21), m(2111.0, 4.28)),
            (-70.0, m(2550.0, 4.37), m(2550.0, 4.34)),
            (-50.0, m(2550.0, 5.46), m(2550.0, 3.92)),
        ];
        let c = table1_checks(&horizontal);
        assert_eq!(c.map(|c| c.1), [true, true, false, true], "{c:?}");
        // A perception dig slower than plain with the same payload fails the last check.
        let slow = [
            (-87.0, m(2000.0, 4.0), m(2500.0, 4.0)),
            (-70.0, m(2500.0, 5.0), m(2500.0, 5.5)),
        ];
        assert!(!table1_checks(&slow)[3].1);
    }

    /// The scoreboard lists every statement with its verdict and counts those that hold.
    #[test]
    fn scoreboard_markdown_counts_what_holds() {
        let score = |statement: &str, holds| Score {
            result: "Table 2 (dig model)".to_owned(),
            statement: statement.to_owned(),
            holds,
        };
        let md = scoreboard_markdown(&[score("time rises 1 -> 2", true), score("volume", false)]);
        assert!(
            md.contains("| Table 2 (dig model) | time rises 1 -> 2 | as in the thesis |"),
            "{md}"
        );
        assert!(md.contains("| volume | differs from the thesis |"), "{md}");
        assert!(md.contains("1 of 2 statements hold."), "{md}");
    }

    /// The thesis's Table 2 passes every check; a volume that falls from x1 fails that one.
    #[test]
    fn table2_checks_hold_for_the_thesis() {
        let thesis = THESIS_TABLE2.map(|t| (t.1, t.2, t.3));
        assert!(table2_checks(thesis).iter().all(|c| c.1));
        let ours = [
            (3.92, 2.69, 226.0),
            (4.57, 1.10, 294.0),
            (3.94, 0.84, 276.0),
        ];
        let c = table2_checks(ours);
        assert_eq!(c.map(|c| c.1), [true, true, false, true, false], "{c:?}");
    }
}
