//! `excavator-ctl model train`: the recurrent actuator networks of `planner::actuator` (thesis 4.2)
//! trained on the digs of candump traces with a held-out split, and their error per cylinder.

use std::path::PathBuf;

use anyhow::Context as _;
use clap::Args;
use planner::actuator::{FreeRunLoss, TrainConfig};

use super::evaluate::print_errors;
use super::training_data::{ForceSource, VelocitySource, load_digs};

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
    /// The target velocity signal.
    #[arg(long, value_enum, default_value_t = VelocitySource::Rates)]
    pub velocity: VelocitySource,
    /// The force inputs.
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

/// Runs `model train`.
///
/// # Errors
/// Reading the traces or the machine file, training errors, writing the model.
pub fn run(a: &TrainArgs) -> anyhow::Result<()> {
    let machine = planner::machine::MachineConfig::load_or_default(a.machine.as_deref())?;
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
