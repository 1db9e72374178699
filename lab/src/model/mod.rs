//! `excavator-ctl model`: the planner's dig model (thesis ch. 4) against the simulator.
//!
//! # Layout
//!
//! - [`sim_dig`]: one Autodig dig in the simulator from a setup (the simulator dig runner), optionally
//!   recorded as a candump trace.
//! - [`training_data`]: actuator training digs read from traces.
//! - [`generate`], [`train`], [`evaluate`]: `generate-data` writes simulator traces, `train` trains the
//!   recurrent actuator networks of `planner::actuator` on them, `evaluate` reports their error.
//! - [`comparison`], [`compare`], [`plots`]: the dig model against the simulator from the same starts
//!   (thesis Figs. 34-41), the `compare` command and its plots.
//! - [`start`]: the dig model, the machine file and the start on the default bench that the commands
//!   share.
//! - [`table2`], [`fig52`]: thesis Table 2 and Fig. 52 with the dig model (printed by `experiment
//!   table2|fig52` next to the simulator's).
//! - [`speed`]: the dig model's real-time factor.
//! - [`soil_cv`]: cross-validation of the soil models on a session's soil samples (4.3.5).
//!
//! The simulation harness ([`sim_dig::DigSetup`], [`sim_dig::run_sim_dig`],
//! [`comparison::compare_dig`]) is public so the integration tests can reuse it.

use clap::Subcommand;

pub mod compare;
pub mod comparison;
pub mod evaluate;
pub mod fig52;
pub mod generate;
pub mod plots;
pub mod sim_dig;
pub mod soil_cv;
pub mod speed;
pub mod start;
pub mod table2;
pub mod train;
pub mod training_data;

/// `excavator-ctl model ...`
#[derive(Debug, Subcommand)]
pub enum ModelCommand {
    /// Train the actuator networks (thesis 4.2) from candump traces.
    Train(train::TrainArgs),
    /// Free-running error of an actuator model on the held-out test digs of `train`'s split.
    Evaluate(evaluate::EvaluateArgs),
    /// Run Autodig digs in the simulator from varied starts and write their traces.
    GenerateData(generate::GenerateArgs),
    /// Compare the dig model with the simulator from the same starts (thesis Figs. 34-41).
    Compare(compare::CompareArgs),
    /// Cross-validate the soil models (thesis 4.3.5) on a `demo` session's `soil_samples.json`.
    SoilCv(soil_cv::SoilCvArgs),
}

/// Runs a `model` subcommand.
///
/// # Errors
/// Any failure, with its cause chain.
pub fn run(cmd: ModelCommand) -> anyhow::Result<()> {
    match cmd {
        ModelCommand::Train(a) => train::run(&a),
        ModelCommand::Evaluate(a) => evaluate::run(&a),
        ModelCommand::GenerateData(a) => generate::run(&a),
        ModelCommand::Compare(a) => compare::run(&a),
        ModelCommand::SoilCv(a) => soil_cv::run(&a),
    }
}
