//! `excavator-ctl model train`: the recurrent actuator networks of `planner::actuator` (thesis 4.2)
//! trained on the digs of candump traces with a held-out split, and their error per cylinder.

use std::path::PathBuf;

use anyhow::{Context as _, bail};
use clap::Args;
use planner::actuator::{ActuatorModel, FreeRunLoss, TrainConfig, TrainReport};
use planner::origin::ArtefactOrigin;

use super::evaluate::print_errors;
use super::training_data::{ForceSource, VelocitySource, load_digs};

/// The digs the shipped networks were trained on (`config/nominal_actuator.json`): the 403 digs and
/// cleanups of `calibrate`'s four 100-dig default `demo` sessions, split 262 / 60 / 81 (train /
/// validation / test). Below
/// [`RECOMMENDED_MIN_DIGS`] `model train` warns that the data fall short.
pub const SHIPPED_TRAINING_DIGS: usize = 403;

/// The fewest digs `model train` takes without a data-shortfall warning (docs/models.md, "How much
/// data": on fresh planned sessions the recipe's error falls from about 10 / 3 / 9 % of peak with 12
/// digs to 2.9 / 2.2 / 2.9 % with 100).
pub const RECOMMENDED_MIN_DIGS: usize = 100;

/// The networks' inputs (`--inputs`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum InputLayout {
    /// Fig. 17's layout: delayed command, force and previous velocity (the boom also sees the bucket
    /// command).
    Fig17,
    /// Fig. 17 plus the command and force of the cylinder sharing its flow (the shared, power-limited
    /// pump and the crossover).
    Coupled,
    /// Coupled plus the rate of change of the own cylinder force over the last step (Eq. 2: the
    /// chamber pressure changes with the difference between valve flow and displacement, so it shows
    /// a load being taken up or let go). The shipped networks'.
    ForceRate,
    /// Coupled plus the orifice-law drive (Eq. 1) of the own and the partner cylinder: the command
    /// times the square root of the pressure drop left at the valve for the load.
    Orifice,
    /// Coupled plus the command and force of the third cylinder, so each network sees all three.
    Third,
}

/// Arguments of `model train`. The defaults are the recipe of the shipped networks (docs/models.md).
#[derive(Debug, Args)]
pub struct TrainArgs {
    /// candump -L traces (from `model generate-data`, `demo`, `run --trace` or a real machine).
    #[arg(long, required = true, num_args = 1..)]
    pub trace: Vec<PathBuf>,
    /// Where to write the model (`actuator.json`).
    #[arg(long)]
    pub out: PathBuf,
    /// Seed of the split and the initial weights.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Hidden units per network (thesis: five).
    #[arg(long, default_value_t = 12)]
    pub hidden: usize,
    /// Command delay in 10 ms steps (default: the machine file's transport delay).
    #[arg(long)]
    pub delay: Option<usize>,
    /// Free-running (BPTT) epochs.
    #[arg(long, default_value_t = 600)]
    pub epochs: usize,
    /// The networks' inputs.
    #[arg(long, value_enum, default_value_t = InputLayout::ForceRate)]
    pub inputs: InputLayout,
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
    /// per step.
    #[arg(long, default_value_t = 4)]
    pub batch_digs: usize,
    /// With `--inputs force-rate`: probability with which a training dig's force rate is zeroed for one
    /// step of the optimiser, so the networks also learn the quasi-static case the dig model uses them
    /// in.
    #[arg(long, default_value_t = 0.0)]
    pub force_rate_dropout: f64,
    /// Feed the networks the delayed commands themselves instead of through a first-order lag with the
    /// machine file's spool time constant (`lag_time_constant_s`), the estimate of the spool positions
    /// the valves meter with.
    #[arg(long)]
    pub no_spool_lag: bool,
    /// The target velocity signal.
    #[arg(long, value_enum, default_value_t = VelocitySource::Angles)]
    pub velocity: VelocitySource,
    /// The force inputs.
    #[arg(long, value_enum, default_value_t = ForceSource::Measured)]
    pub forces: ForceSource,
    /// Learning-rate schedule: the step size of both phases falls along a half cosine to this
    /// fraction of its starting value (1: constant).
    #[arg(long, default_value_t = 0.05)]
    pub final_rate: f64,
    /// Trainings per network from different initial weights and batch orders; the one with the lowest
    /// validation loss is kept (the split and the test digs stay the seed's).
    #[arg(long, default_value_t = 3)]
    pub restarts: usize,
    /// Free-running epochs without a validation improvement before stopping (at least `--epochs`:
    /// never).
    #[arg(long, default_value_t = 1000)]
    pub patience: usize,
    /// Machine file (default: the built-in config/machine.toml).
    #[arg(long, value_name = "FILE")]
    pub machine: Option<PathBuf>,
}

/// `model train`'s arguments alone, to parse them outside the command line.
#[derive(Debug, clap::Parser)]
struct TrainCommandLine {
    #[command(flatten)]
    train: TrainArgs,
}

impl TrainArgs {
    /// The arguments of a training on `traces` into `out` with the defaults (the shipped recipe) and
    /// `options` (`model train` flags, e.g. `["--restarts", "1"]`).
    ///
    /// # Errors
    /// An option `model train` does not take, or a bad value.
    pub fn with_options(
        traces: &[PathBuf],
        out: &std::path::Path,
        options: &[String],
    ) -> anyhow::Result<Self> {
        use clap::Parser as _;
        let mut line: Vec<std::ffi::OsString> = vec!["train".into(), "--trace".into()];
        line.extend(traces.iter().map(|t| t.as_os_str().to_owned()));
        line.push("--out".into());
        line.push(out.as_os_str().to_owned());
        line.extend(options.iter().map(Into::into));
        Ok(TrainCommandLine::try_parse_from(line)
            .context("model train options")?
            .train)
    }

    /// The training options as `model train` flags, in a fixed order (kept in the model file's
    /// training summary, so a model says how it was made).
    #[must_use]
    pub fn recipe(&self) -> String {
        let mut r = format!(
            "--seed {} --hidden {} --epochs {} --teacher-epochs {} --inputs {} --batch-digs {} \
             --velocity {} --forces {} --final-rate {} --restarts {} --patience {}",
            self.seed,
            self.hidden,
            self.epochs,
            self.teacher_epochs,
            value_name(self.inputs),
            self.batch_digs,
            value_name(self.velocity),
            value_name(self.forces),
            self.final_rate,
            self.restarts,
            self.patience,
        );
        if let Some(d) = self.delay {
            r.push_str(&format!(" --delay {d}"));
        }
        if self.no_spool_lag {
            r.push_str(" --no-spool-lag");
        }
        if self.abs_loss {
            r.push_str(" --abs-loss");
        }
        if self.force_noise != 0.0 {
            r.push_str(&format!(" --force-noise {}", self.force_noise));
        }
        if self.force_rate_dropout != 0.0 {
            r.push_str(&format!(
                " --force-rate-dropout {}",
                self.force_rate_dropout
            ));
        }
        r
    }
}

/// The command-line spelling of a value-enum value.
fn value_name<T: clap::ValueEnum>(v: T) -> String {
    v.to_possible_value()
        .map_or_else(String::new, |p| p.get_name().to_owned())
}

/// The data-shortfall warning for `digs` digs, or `None` when they are enough for the recipe.
#[must_use]
pub fn data_shortfall(digs: usize) -> Option<String> {
    (digs < RECOMMENDED_MIN_DIGS).then(|| {
        format!(
            "warning: {digs} digs is too little data for these networks: the shipped ones were trained \
             on {SHIPPED_TRAINING_DIGS} digs, and below {RECOMMENDED_MIN_DIGS} the free-running \
             error rises (docs/models.md, \"How much data\"). Record about \
             {} more digs (the `trace.log` of `demo --digs N`, `model generate-data`, or `run \
             --trace` on the machine) and train on all of them.",
            RECOMMENDED_MIN_DIGS - digs
        )
    })
}

/// The training configuration of `a`'s options for `machine` (its transport delay and spool lag).
fn train_config(a: &TrainArgs, machine: &planner::machine::MachineConfig) -> TrainConfig {
    TrainConfig {
        seed: a.seed,
        hidden_units: a.hidden,
        delay_steps: a.delay.unwrap_or_else(|| {
            (machine.hydraulics.transport_delay_s / crate::harness::PERIOD_S)
                .round()
                .max(0.0) as usize
        }),
        free_run_epochs: a.epochs,
        coupled_inputs: a.inputs != InputLayout::Fig17,
        orifice_inputs: a.inputs == InputLayout::Orifice,
        teacher_forcing_epochs: a.teacher_epochs,
        batch_digs: a.batch_digs,
        force_rate_input: a.inputs == InputLayout::ForceRate,
        force_rate_dropout: a.force_rate_dropout,
        force_noise: a.force_noise,
        third_inputs: a.inputs == InputLayout::Third,
        final_rate_fraction: a.final_rate,
        restarts: a.restarts,
        patience: a.patience,
        command_lag_s: if a.no_spool_lag {
            0.0
        } else {
            machine.hydraulics.lag_time_constant_s
        },
        free_run_loss: if a.abs_loss {
            FreeRunLoss::Absolute
        } else {
            FreeRunLoss::Squared
        },
        ..TrainConfig::default()
    }
}

/// Runs `model train`.
///
/// # Errors
/// Reading the traces or the machine file, training errors, writing the model.
pub fn run(a: &TrainArgs) -> anyhow::Result<()> {
    train(a, None).map(drop)
}

/// Trains the networks on `a`'s traces, prints the progress and the held-out error, and writes the
/// model to `a.out` with its provenance: the recipe and `plant_version`, the simulator plant version
/// the traces came from (`None`: unknown or a real machine).
///
/// # Errors
/// Invalid options, reading the traces or the machine file, training errors, writing the model.
pub fn train(
    a: &TrainArgs,
    plant_version: Option<&str>,
) -> anyhow::Result<(ActuatorModel, TrainReport)> {
    if a.force_rate_dropout != 0.0 && a.inputs != InputLayout::ForceRate {
        bail!("--force-rate-dropout needs --inputs force-rate");
    }
    if !(0.0..=1.0).contains(&a.force_rate_dropout) {
        bail!(
            "--force-rate-dropout {} is not a probability (0 to 1)",
            a.force_rate_dropout
        );
    }
    let machine = planner::machine::MachineConfig::load_or_default(a.machine.as_deref())?;
    let digs = load_digs(&a.trace, &machine, a.velocity, a.forces)?;
    if let Some(w) = data_shortfall(digs.len()) {
        eprintln!("{w}");
    }
    let config = train_config(a, &machine);
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
    let model = model.with_origin(ArtefactOrigin::new(
        format!("excavator-ctl model train {}", a.recipe()),
        plant_version,
    ));
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
    Ok((model, report))
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    type Cli = TrainCommandLine;

    fn defaults() -> TrainArgs {
        TrainArgs::with_options(
            &[PathBuf::from("t.log")],
            std::path::Path::new("m.json"),
            &[],
        )
        .unwrap()
    }

    /// `model train`'s defaults are the recipe the shipped networks record and were made with.
    #[test]
    fn defaults_are_the_shipped_recipe() {
        let machine = planner::machine::MachineConfig::default_machine().unwrap();
        let config = train_config(&defaults(), &machine);
        let text = planner::dig_model::NOMINAL_ACTUATOR_JSON;
        let shipped = ActuatorModel::from_json(text).unwrap();
        assert_eq!(config.hidden_units, shipped.hidden_units());
        assert_eq!(config.delay_steps, shipped.delay_steps());
        assert_eq!(config.command_lag_s, shipped.command_lag_s());
        assert!(config.coupled_inputs && config.force_rate_input);
        assert!(text.contains("\"force_rate_n_per_s\""));
        let summary = shipped.training_summary().unwrap();
        assert_eq!(summary.digs.iter().sum::<usize>(), SHIPPED_TRAINING_DIGS);
        assert_eq!(config.seed, summary.seed);
    }

    #[test]
    fn recipe_round_trips_through_the_parser() {
        let a = defaults();
        let line = format!("train --trace t.log --out m.json {}", a.recipe());
        let b = Cli::parse_from(line.split_whitespace()).train;
        assert_eq!(a.recipe(), b.recipe());
        let c = Cli::parse_from(
            "train --trace t --out m --inputs fig17 --no-spool-lag --force-noise 0.5 --delay 3"
                .split_whitespace(),
        )
        .train;
        let d =
            Cli::parse_from(format!("train --trace t --out m {}", c.recipe()).split_whitespace())
                .train;
        assert_eq!(c.recipe(), d.recipe());
        assert!(c.recipe().contains("--inputs fig17") && c.recipe().contains("--no-spool-lag"));
    }

    #[test]
    fn few_digs_warn_and_name_the_shortfall() {
        let w = data_shortfall(12).unwrap();
        assert!(w.contains("12 digs") && w.contains("88 more"), "{w}");
        assert!(data_shortfall(RECOMMENDED_MIN_DIGS).is_none());
    }
}
