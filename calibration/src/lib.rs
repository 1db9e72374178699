//! `excavator-ctl calibrate`: every shipped artefact that is fitted on the simulated plant, rebuilt
//! from the simulator and a seed, with a report of what each came from and how well it fits.
//!
//! The steps, in order (each uses the artefacts of the steps before it):
//! 1. **Sessions**: `excavator-ctl demo`'s default sessions ([`DemoArgs::defaults`]: the planned
//!    strategy on the extended bench, the sessions users run), fresh for this seed: training
//!    sessions, fresh sessions to measure the networks on, and healthy sessions for the grey-box
//!    calibration, each set with seeds of its own.
//! 2. **Actuator networks** (`config/nominal_actuator.json`, thesis 4.2): `model train` with its
//!    defaults (the shipped recipe) on every dig and cleanup of the training sessions, then their
//!    free-running error on the fresh sessions' digs, per session.
//! 3. **Hardness regression** (`config/hardness_regression.toml`, thesis 5.2, Eq. 25, Fig. 53):
//!    `experiment hardness-fit`'s sweep through the dig model with the new networks.
//! 4. **Grey-box nominal model** (`config/nominal_greybox.json`, the discrepancy workflow's starting
//!    model): the machine file's values, calibrated on the healthy sessions as a reference is (the
//!    effects an analysis names on them); a fixed extra delay is folded into the transport delay.
//!
//! Each artefact records its origin (this command with its options and
//! [`vcan_sim::PLANT_VERSION`]); `calibration.md` and `calibration.json` list the artefacts, the
//! data each came from, their error figures and the wall time of every step. `--install DIR` copies
//! the artefacts into a config folder (the repository's `config/`).
//!
//! Not rebuilt: the Autodig maps (`config/autodig_maps.toml`, the thesis's Figs. 10 and 11 as read,
//! shaped by hand) and the dig model's soil and bearing parameters (`config/dig_model.toml`, chosen
//! with `excavator-ctl model compare`; docs/models.md, "The nominal model").

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::time::Instant;

use anyhow::Context as _;
use clap::Args;
use planner::origin::ArtefactOrigin;
use rayon::prelude::*;
use serde::Serialize;

use discrepancy::model::{AugmentedModel, ModelEffect};
use lab::demo::{DemoArgs, run_session};

/// Arguments of `excavator-ctl calibrate`.
#[derive(Debug, Clone, Args)]
pub struct CalibrateArgs {
    /// Output folder: the sessions, the artefacts and the report.
    #[arg(long, default_value = "out/calibration", value_name = "DIR")]
    pub out: PathBuf,
    /// Seed: every session's seed is derived from it.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Training sessions.
    #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u32).range(1..=100))]
    pub sessions: u32,
    /// Digs (dig and cleanup actions) per training session.
    #[arg(long, default_value_t = 100, value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub digs: u32,
    /// Fresh sessions the networks are measured on.
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..=100))]
    pub eval_sessions: u32,
    /// Digs per fresh session (at least 3: `model evaluate` reads no fewer).
    #[arg(long, default_value_t = 12, value_parser = clap::value_parser!(u32).range(3..=1000))]
    pub eval_digs: u32,
    /// Healthy sessions the grey-box model is calibrated on.
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..=100))]
    pub healthy_sessions: u32,
    /// Digs per healthy session.
    #[arg(long, default_value_t = 16, value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub healthy_digs: u32,
    /// A `model train` option on top of its defaults (repeatable; e.g. `--train-option=--restarts
    /// --train-option=1` for a quicker, rougher calibration).
    #[arg(long = "train-option", value_name = "ARG", allow_hyphen_values = true)]
    pub train_options: Vec<String>,
    /// Also copy the artefacts into this config folder (the repository's `config/`).
    #[arg(long, value_name = "DIR")]
    pub install: Option<PathBuf>,
}

impl CalibrateArgs {
    /// The arguments of a calibration into `out` with the defaults.
    #[must_use]
    pub fn new(out: PathBuf) -> Self {
        Self {
            out,
            seed: 1,
            sessions: 4,
            digs: 100,
            eval_sessions: 3,
            eval_digs: 12,
            healthy_sessions: 3,
            healthy_digs: 16,
            train_options: Vec::new(),
            install: None,
        }
    }

    /// This calibration as a command line (each artefact's `made_by`).
    #[must_use]
    pub fn command_line(&self) -> String {
        let mut s = format!(
            "excavator-ctl calibrate --seed {} --sessions {} --digs {} --eval-sessions {} \
             --eval-digs {} --healthy-sessions {} --healthy-digs {}",
            self.seed,
            self.sessions,
            self.digs,
            self.eval_sessions,
            self.eval_digs,
            self.healthy_sessions,
            self.healthy_digs
        );
        for o in &self.train_options {
            s.push_str(&format!(" --train-option={o}"));
        }
        s
    }
}

/// The three sets of sessions, each with seeds of its own.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum SessionSet {
    Training,
    Fresh,
    Healthy,
}

impl SessionSet {
    fn name(self) -> &'static str {
        match self {
            Self::Training => "training",
            Self::Fresh => "fresh",
            Self::Healthy => "healthy",
        }
    }

    /// The seed of session `i` of this set for the calibration seed `seed`: disjoint sets of
    /// seeds for disjoint purposes.
    fn seed(self, seed: u64, i: u32) -> u64 {
        let offset = match self {
            Self::Training => 0,
            Self::Fresh => 400,
            Self::Healthy => 700,
        };
        seed.saturating_mul(1000)
            .saturating_add(offset)
            .saturating_add(u64::from(i))
    }
}

/// One generated session.
#[derive(Debug, Clone, Serialize)]
pub struct SessionRecord {
    /// Which set: `training`, `fresh` or `healthy`.
    pub set: &'static str,
    /// Simulator seed.
    pub seed: u64,
    /// Digs asked for.
    pub digs: u32,
    /// The session folder.
    pub dir: PathBuf,
}

impl SessionRecord {
    /// The session's `demo` arguments: `excavator-ctl demo`'s defaults ([`DemoArgs::defaults`],
    /// the session users run) with this seed, dig count and folder, and no progress bar.
    #[must_use]
    pub fn demo_args(&self) -> DemoArgs {
        DemoArgs {
            digs: self.digs,
            seed: Some(self.seed),
            quiet: true,
            ..DemoArgs::defaults(self.dir.clone())
        }
    }
}

/// The free-running error of the networks on one fresh session's digs, percent of peak speed.
#[derive(Debug, Clone, Serialize)]
pub struct NetworkError {
    /// The session's seed.
    pub seed: u64,
    /// Digs evaluated.
    pub digs: usize,
    /// `[boom, stick, bucket]`, percent of peak.
    pub mae_percent_of_peak: [f64; 3],
}

/// The calibration report (`calibration.json`).
#[derive(Debug, Clone, Serialize)]
pub struct CalibrationReport {
    /// The command that made it.
    pub command: String,
    /// The simulator plant version calibrated on.
    pub plant_version: String,
    /// The soil contact integration of that plant.
    pub soil_contact: String,
    /// Every generated session.
    pub sessions: Vec<SessionRecord>,
    /// The networks' held-out test digs (of the training sessions) and their error, percent of peak.
    pub networks_split: [usize; 3],
    /// Test-digs error, percent of peak `[boom, stick, bucket]`.
    pub networks_test_percent: [f64; 3],
    /// Error on each fresh session's digs.
    pub networks_fresh: Vec<NetworkError>,
    /// Median and worst over the fresh sessions, percent of peak `[boom, stick, bucket]`.
    pub networks_fresh_median: [f64; 3],
    /// Worst over the fresh sessions.
    pub networks_fresh_worst: [f64; 3],
    /// The hardness regression: intercept, slope per kN, r^2, cases.
    pub hardness: (f64, f64, f64, usize),
    /// The least-squares line through the hardness sweep's points, with its slope's t statistic (the
    /// regression is that line only where the slope is significant).
    pub hardness_line: planner::plan::hardness::HardnessLine,
    /// The grey-box calibration: the effects named on the healthy sessions.
    pub greybox_calibration: Vec<ModelEffect>,
    /// The grey-box transport delay after folding, s.
    pub greybox_transport_delay_s: f64,
    /// Wall time per step, s: sessions, networks, fresh evaluation, hardness, grey-box.
    pub wall_s: Vec<(String, f64)>,
    /// The artefacts written, relative to the output folder.
    pub artefacts: Vec<String>,
}

/// The artefacts' file names (in the output folder and in a config folder).
pub const ARTEFACTS: [&str; 3] = [
    "nominal_actuator.json",
    "hardness_regression.toml",
    "nominal_greybox.json",
];

/// Runs the calibration, writes the artefacts and the report into `args.out`, and installs them
/// with `--install`.
///
/// # Errors
/// A session, training, fit or I/O error, each naming the step.
pub fn run(args: &CalibrateArgs) -> anyhow::Result<CalibrationReport> {
    let total = Instant::now();
    let out = &args.out;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let made_by = args.command_line();
    let origin = ArtefactOrigin::new(&made_by, Some(vcan_sim::PLANT_VERSION));
    let machine = planner::machine::MachineConfig::default_machine()?;
    let mut wall_s = Vec::new();

    // 1. Sessions.
    let t = Instant::now();
    let mut plans = Vec::new();
    for (set, count, digs) in [
        (SessionSet::Training, args.sessions, args.digs),
        (SessionSet::Fresh, args.eval_sessions, args.eval_digs),
        (
            SessionSet::Healthy,
            args.healthy_sessions,
            args.healthy_digs,
        ),
    ] {
        for i in 0..count {
            let seed = set.seed(args.seed, i);
            plans.push(SessionRecord {
                set: set.name(),
                seed,
                digs,
                dir: out.join("sessions").join(format!("{}_{seed}", set.name())),
            });
        }
    }
    eprintln!(
        "calibrate: {} sessions ({} training x {} digs, {} fresh x {}, {} healthy x {}) on plant {}",
        plans.len(),
        args.sessions,
        args.digs,
        args.eval_sessions,
        args.eval_digs,
        args.healthy_sessions,
        args.healthy_digs,
        vcan_sim::PLANT_VERSION
    );
    plans
        .par_iter()
        .map(|p| {
            run_session(&p.demo_args(), &AtomicBool::new(false))
                .with_context(|| format!("{} session, seed {}", p.set, p.seed))
                .map(drop)
        })
        .collect::<anyhow::Result<Vec<()>>>()?;
    wall_s.push(("sessions".to_owned(), t.elapsed().as_secs_f64()));
    let traces = |set: SessionSet| -> Vec<PathBuf> {
        plans
            .iter()
            .filter(|p| p.set == set.name())
            .map(|p| p.dir.join("trace.log"))
            .collect()
    };

    // 2. Actuator networks.
    let t = Instant::now();
    let actuator_path = out.join(ARTEFACTS[0]);
    let train = lab::model::train::TrainArgs::with_options(
        &traces(SessionSet::Training),
        &actuator_path,
        &args.train_options,
    )?;
    let (networks, split) = lab::model::train::train(&train, Some(vcan_sim::PLANT_VERSION))
        .context("training the actuator networks")?;
    let networks = networks.with_origin(ArtefactOrigin::new(
        format!("{made_by} (model train {})", train.recipe()),
        Some(vcan_sim::PLANT_VERSION),
    ));
    std::fs::write(&actuator_path, networks.to_json()?)
        .with_context(|| format!("writing {}", actuator_path.display()))?;
    wall_s.push(("networks".to_owned(), t.elapsed().as_secs_f64()));

    // The networks on fresh sessions.
    let t = Instant::now();
    let mut fresh = Vec::new();
    for p in plans.iter().filter(|p| p.set == SessionSet::Fresh.name()) {
        let report = lab::model::evaluate::evaluate_traces(
            &[p.dir.join("trace.log")],
            &networks,
            &machine,
            train.velocity,
        )
        .with_context(|| format!("the networks on the fresh session of seed {}", p.seed))?;
        fresh.push(NetworkError {
            seed: p.seed,
            digs: report.digs,
            mae_percent_of_peak: report.cylinders.map(|c| c.mae_percent_of_peak),
        });
    }
    let (fresh_median, fresh_worst) = median_and_worst(&fresh);
    wall_s.push((
        "networks on fresh digs".to_owned(),
        t.elapsed().as_secs_f64(),
    ));

    // 3. Hardness regression with the new networks.
    let t = Instant::now();
    let dig_model = planner::dig_model::DigModel::new(
        &machine,
        networks.clone(),
        planner::autodig::AutodigMaps::builtin()?,
        planner::dig_model::DigModelConfig::nominal()?,
    )?;
    let hardness = lab::experiment::hardness_fit_with(
        &dig_model,
        &out.join("hardness"),
        &made_by,
        Some(origin.clone()),
    )
    .context("the hardness regression")?;
    std::fs::copy(
        out.join("hardness").join(ARTEFACTS[1]),
        out.join(ARTEFACTS[1]),
    )
    .context("copying the hardness regression")?;
    wall_s.push(("hardness regression".to_owned(), t.elapsed().as_secs_f64()));

    // 4. Grey-box nominal model.
    let t = Instant::now();
    let healthy: Vec<PathBuf> = plans
        .iter()
        .filter(|p| p.set == SessionSet::Healthy.name())
        .map(|p| p.dir.clone())
        .collect();
    let (greybox, calibration) = calibrate_greybox(&machine, &healthy, &made_by)?;
    let greybox = greybox.with_origin(origin.clone());
    std::fs::write(out.join(ARTEFACTS[2]), greybox.to_json()?)
        .with_context(|| format!("writing {}", out.join(ARTEFACTS[2]).display()))?;
    wall_s.push(("grey-box calibration".to_owned(), t.elapsed().as_secs_f64()));
    wall_s.push(("total".to_owned(), total.elapsed().as_secs_f64()));

    let training_summary = networks
        .training_summary()
        .context("the trained networks have no training summary")?;
    let report = CalibrationReport {
        command: made_by,
        plant_version: vcan_sim::PLANT_VERSION.to_owned(),
        soil_contact: format!(
            "{:?}",
            vcan_sim::scenario::Scenario::from_toml_str_named(
                vcan_sim::scenario::EXTENDED_BENCH_TOML,
                "config/bench_extended.toml"
            )?
            .soil_contact
        )
        .to_lowercase(),
        sessions: plans,
        networks_split: [
            split.train_digs.len(),
            split.validation_digs.len(),
            split.test_digs.len(),
        ],
        networks_test_percent: training_summary.test_mae_percent_of_peak,
        networks_fresh: fresh,
        networks_fresh_median: fresh_median,
        networks_fresh_worst: fresh_worst,
        hardness: (
            hardness.regression.intercept,
            hardness.regression.slope_per_kn,
            hardness.regression.r_squared,
            hardness.regression.cases,
        ),
        hardness_line: hardness.line,
        greybox_calibration: calibration,
        greybox_transport_delay_s: greybox.params.transport_delay_s,
        wall_s,
        artefacts: ARTEFACTS.iter().map(|a| (*a).to_owned()).collect(),
    };
    std::fs::write(
        out.join("calibration.json"),
        serde_json::to_string_pretty(&report)?,
    )
    .context("writing calibration.json")?;
    std::fs::write(out.join("calibration.md"), report_markdown(&report))
        .context("writing calibration.md")?;
    if let Some(dir) = &args.install {
        install(out, dir)?;
    }
    Ok(report)
}

/// The grey-box nominal model calibrated on `healthy` sessions: the machine file's values with the
/// Eq. 2 chamber balance, and the effects an analysis of the healthy sessions names (as a reference
/// calibrates the model it is read with, `discrepancy::analysis::load_reference`). A named
/// `transport_delay` is folded into the model's transport delay; other named effects stay in the
/// model's effect list. Returns the model and the effects named.
fn calibrate_greybox(
    machine: &planner::machine::MachineConfig,
    healthy: &[PathBuf],
    made_by: &str,
) -> anyhow::Result<(AugmentedModel, Vec<ModelEffect>)> {
    let mut params = discrepancy::greybox::GreyBoxParams::from_machine(machine);
    params.chamber_balance = true;
    let start = AugmentedModel::new(
        params.clone(),
        Vec::new(),
        "the machine file's values (GreyBoxParams::from_machine) with the Eq. 2 chamber balance"
            .to_owned(),
    );
    let reference = discrepancy::analysis::load_reference(healthy, machine, &start)?
        .context("no healthy sessions")?;
    let calibration = reference.calibration.clone();
    let mut effects = Vec::new();
    for e in &calibration {
        if e.name == discrepancy::Candidate::TransportDelay.name() {
            params.transport_delay_s += e.magnitude;
        } else {
            effects.push(e.clone());
        }
    }
    let named = if calibration.is_empty() {
        "nothing".to_owned()
    } else {
        calibration
            .iter()
            .map(|e| format!("{} = {:.4e} +- {:.1e}", e.name, e.magnitude, e.uncertainty))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let model = AugmentedModel::new(
        params,
        effects,
        format!(
            "nominal grey-box model: the machine file's values (GreyBoxParams::from_machine) with the \
             Eq. 2 chamber balance, calibrated by `{made_by}` on {} healthy default `demo` sessions \
             (planned), which named {named} (a transport delay folded into the model's)",
            healthy.len()
        ),
    );
    model
        .augmentation()
        .context("the calibrated grey-box model")?;
    Ok((model, calibration))
}

/// Per cylinder, the median and the worst (largest) error over sessions (NaN without a session).
fn median_and_worst(errors: &[NetworkError]) -> ([f64; 3], [f64; 3]) {
    let mut median = [f64::NAN; 3];
    let mut worst = [f64::NAN; 3];
    for j in 0..3 {
        let v: Vec<f64> = errors.iter().map(|e| e.mae_percent_of_peak[j]).collect();
        median[j] = lab::results::median(&v);
        worst[j] = v.iter().copied().max_by(f64::total_cmp).unwrap_or(f64::NAN);
    }
    (median, worst)
}

/// `calibration.md`: the artefacts, the data each came from, the error figures and the wall times.
#[must_use]
pub fn report_markdown(r: &CalibrationReport) -> String {
    use std::fmt::Write as _;
    let pct = |v: [f64; 3]| format!("{:.1} / {:.1} / {:.1} %", v[0], v[1], v[2]);
    let seeds = |set: &str| {
        let s: Vec<String> = r
            .sessions
            .iter()
            .filter(|p| p.set == set)
            .map(|p| p.seed.to_string())
            .collect();
        let digs = r
            .sessions
            .iter()
            .find(|p| p.set == set)
            .map_or(0, |p| p.digs);
        format!(
            "{} sessions of {digs} digs, seeds {}",
            s.len(),
            s.join(", ")
        )
    };
    let mut s = String::new();
    let _ = writeln!(s, "# Calibration on plant {}\n", r.plant_version);
    let _ = writeln!(
        s,
        "Made by `{}` on the default plant (soil contact `{}`): `excavator-ctl demo`'s default \
         sessions (planned, extended bench).\n",
        r.command, r.soil_contact
    );
    let _ = writeln!(s, "| artefact | data | figures |\n|---|---|---|");
    let _ = writeln!(
        s,
        "| `nominal_actuator.json` (thesis 4.2) | {}: every dig and cleanup, split {} / {} / {} \
         (train / validation / test) | test digs {}; fresh sessions ({}): median {}, worst {} \
         (boom / stick / bucket, free-running MAE in % of peak speed; target < 5 %) |",
        seeds("training"),
        r.networks_split[0],
        r.networks_split[1],
        r.networks_split[2],
        pct(r.networks_test_percent),
        seeds("fresh"),
        pct(r.networks_fresh_median),
        pct(r.networks_fresh_worst)
    );
    let (a, b, r2, cases) = r.hardness;
    let _ = writeln!(
        s,
        "| `hardness_regression.toml` (5.2, Eq. 25, Fig. 53) | the default sweep through the dig \
         model with these networks | index = {a:.3} + {b:.5} x force/kN, r^2 {r2:.3}, {cases} cases \
         ({}) |",
        lab::experiment::hardness_line_note(&r.hardness_line)
    );
    let named = if r.greybox_calibration.is_empty() {
        "nothing named".to_owned()
    } else {
        r.greybox_calibration
            .iter()
            .map(|e| format!("{} = {:.3e}", e.name, e.magnitude))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let _ = writeln!(
        s,
        "| `nominal_greybox.json` (discrepancy workflow) | {} | {named}; transport delay {:.0} ms |",
        seeds("healthy"),
        r.greybox_transport_delay_s * 1e3
    );
    let _ = writeln!(s, "\nFresh sessions, one row each (% of peak):\n");
    let _ = writeln!(
        s,
        "| seed | digs | boom | stick | bucket |\n|---|---|---|---|---|"
    );
    for e in &r.networks_fresh {
        let _ = writeln!(
            s,
            "| {} | {} | {:.1} | {:.1} | {:.1} |",
            e.seed,
            e.digs,
            e.mae_percent_of_peak[0],
            e.mae_percent_of_peak[1],
            e.mae_percent_of_peak[2]
        );
    }
    let _ = writeln!(s, "\nWall time:\n");
    for (step, secs) in &r.wall_s {
        let _ = writeln!(s, "- {step}: {secs:.0} s");
    }
    let _ = writeln!(
        s,
        "\nNot rebuilt: the Autodig maps (`config/autodig_maps.toml`, the thesis's Figs. 10-11 as \
         read) and the dig model's soil and bearing parameters (`config/dig_model.toml`, chosen with \
         `excavator-ctl model compare`; docs/models.md, \"The nominal model\")."
    );
    s
}

/// The plant version a shipped artefact records, for the check that they match the plant.
///
/// # Errors
/// The artefact does not parse, or records no origin.
pub fn recorded_plant_version(name: &str, text: &str) -> anyhow::Result<Option<String>> {
    let origin = match name {
        "nominal_actuator.json" => planner::actuator::ActuatorModel::from_json(text)?
            .training_summary()
            .and_then(|t| t.origin.clone()),
        "hardness_regression.toml" => {
            planner::plan::HardnessRegression::from_toml_str(text)?.origin
        }
        "nominal_greybox.json" => AugmentedModel::from_json(text)?.origin,
        other => anyhow::bail!("{other} is not a calibrated artefact"),
    };
    Ok(origin.and_then(|o| o.plant_version))
}

/// Installs a calibration's artefacts from `from` (an output folder) into `config`.
///
/// # Errors
/// A missing artefact or I/O.
pub fn install(from: &Path, config: &Path) -> anyhow::Result<()> {
    for a in ARTEFACTS {
        std::fs::copy(from.join(a), config.join(a))
            .with_context(|| format!("installing {a} into {}", config.display()))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `demo`'s options alone, as `excavator-ctl` flattens them.
    #[derive(clap::Parser)]
    #[command(name = "demo")]
    struct Demo {
        #[command(flatten)]
        args: DemoArgs,
    }

    /// Every session `calibrate` makes is `excavator-ctl demo` with its defaults but for the
    /// seed, the digs, the folder and the progress bar: calibrated on the sessions users run, not on
    /// a library default (it was the fixed plan on config/bench.toml).
    #[test]
    fn calibrate_s_sessions_are_demo_s_defaults_but_for_seed_digs_out_and_quiet() {
        use clap::Parser as _;
        let record = SessionRecord {
            set: SessionSet::Healthy.name(),
            seed: SessionSet::Healthy.seed(1, 2),
            digs: 16,
            dir: PathBuf::from("out/calibration/sessions/healthy_1702"),
        };
        let cal = record.demo_args();
        let out = record.dir.to_str().unwrap_or_default();
        let cli = Demo::try_parse_from([
            "demo", "--seed", "1702", "--digs", "16", "--out", out, "--quiet",
        ])
        .map(|d| d.args);
        assert_eq!(cli.as_ref().ok(), Some(&cal));
        assert_eq!(cal.strategy, lab::demo::DemoStrategy::Planned);
        let defaults = Demo::try_parse_from(["demo"]).map(|d| d.args);
        assert_eq!(
            defaults.ok(),
            Some(DemoArgs {
                seed: None,
                digs: 10,
                out: PathBuf::from("out/demo"),
                quiet: false,
                ..cal
            })
        );
    }

    /// Per cylinder, the median over the sessions (the mean of the middle two for an even count)
    /// and the largest; NaN for every cylinder without a session.
    #[test]
    fn the_median_and_the_worst_are_taken_per_cylinder() {
        let e = |seed: u64, mae: [f64; 3]| NetworkError {
            seed,
            digs: 12,
            mae_percent_of_peak: mae,
        };
        let (median, worst) = median_and_worst(&[
            e(1, [1.0, 5.0, 2.0]),
            e(2, [3.0, 1.0, 2.0]),
            e(3, [2.0, 4.0, 9.0]),
            e(4, [8.0, 2.0, 2.0]),
        ]);
        assert_eq!(median, [2.5, 3.0, 2.0]);
        assert_eq!(worst, [8.0, 5.0, 9.0]);
        let (median, worst) = median_and_worst(&[]);
        assert!(median.iter().chain(&worst).all(|v| v.is_nan()));
    }
}
