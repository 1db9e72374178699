//! Actuator model: one small recurrent network per cylinder (thesis 4.2.2-4.2.3, Figs. 17-18, Eq. 4).
//!
//! Each of the boom, stick and bucket cylinders has its own network that predicts the cylinder velocity at
//! the next time step from
//!
//! - the command delayed by a fixed number of steps (the fixed controller/pilot delays, Fig. 17),
//! - the cylinder force at the current step ("the forces are assumed to act immediately"),
//! - its own previous velocity (the recurrence that carries the large transient lags, Fig. 18, Eq. 4),
//! - for the boom only, the delayed bucket command (boom and bucket share a pump, 4.2.2).
//!
//! Two wider layouts are options of [`TrainConfig`]: `coupled_inputs` gives every network the delayed
//! command and the force of the cylinder sharing its flow, and `orifice_inputs` adds the orifice-law drive
//! of both cylinders, `u sqrt(1 - F / F_ref)` (Eq. 1: flow through the valve grows with the square root of
//! the pressure drop the load leaves), a product the tanh units cannot form from `u` and `F` alone.
//! With `command_lag_s` the delayed commands also pass a first-order lag (the spool estimate) before they
//! enter the networks: the valve's dead band, bypass and crossover act on the lagged spool, which the
//! networks cannot rebuild from the delayed command and their own velocity.
//!
//! The network is `y = w2 . act(W1 x + b1) + s . x + b2` on normalised inputs `x` and normalised output
//! `y = v / v_scale`. The linear shortcut `s . x` is Eq. 4's `v(t+1) = w_v v(t) + u(t)`: the previous
//! velocity enters linearly (`s_v = w_v`) and the hidden layer supplies the non-linear drive `u(t)`.
//! Five hidden units (Fig. 18) are the default.
//!
//! Training ([`train`]) is backpropagation with Adam: teacher forcing first (every step sees the measured
//! previous velocity), then backpropagation through time on free-running rollouts of whole digs, so the
//! recurrence is trained the way it is used. Early stopping keeps the weights with the lowest free-run
//! error on held-out validation digs; the error reported is on separate held-out test digs, as the thesis
//! did with its ten test digs (mean absolute error as a percentage of the peak velocity, thesis 5-8 %).
//!
//! Prediction ([`ActuatorModel::step`]) is allocation-free: the per-dig state ([`ActuatorState`]) is a
//! fixed-size delay ring buffer plus the previous velocities, and the model is immutable, `Send + Sync`,
//! so many digs can be evaluated in parallel. Models are stored as JSON (`actuator.json`) with a format
//! name and version; normalisation is stored with the weights.
//!
//! Units: commands are fractions of maximum cylinder velocity in `[-1, 1]` (positive = extend), forces are
//!
//! # Layout
//!
//! - `dig`: recorded digs ([`ActuatorDig`]) and their resampling to the model period.
//! - `network`: one cylinder's network, its input slots and its forward and backward passes.
//! - `predict`: the model ([`ActuatorModel`]), its allocation-free step and free-running evaluation.
//! - `file`: the `actuator.json` format.
//! - `train`: training ([`train()`]) and its settings ([`TrainConfig`]).

use crate::kinematics::Joint;

mod dig;
mod file;
mod network;
mod predict;
mod train;

pub use dig::{ActuatorDig, ActuatorSample, MAX_DIG_STEPS};
pub use file::{ACTUATOR_FORMAT, ACTUATOR_FORMAT_VERSION};
pub use network::Activation;
pub use predict::{
    ActuatorModel, ActuatorState, CylinderError, EvaluationReport, PredictedStep, TrainingSummary,
};
pub use train::{
    DigSplit, FreeRunLoss, TrainConfig, TrainPhase, TrainProgress, TrainReport, split_digs, train,
};

/// Largest command delay in steps (the size of the ring buffer in [`ActuatorState`]).
pub const MAX_DELAY_STEPS: usize = 64;
/// Largest number of hidden units per network.
pub const MAX_HIDDEN: usize = 16;

/// Actuator model errors.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ActuatorError {
    /// A step input is NaN or infinite.
    #[error("actuator step input {what} is not finite")]
    NonFiniteInput {
        /// Which input.
        what: &'static str,
    },
    /// The state was made for a model with another delay.
    #[error("actuator state has a {state_delay}-step delay, the model {model_delay}")]
    StateMismatch {
        /// Delay the state was made for.
        state_delay: usize,
        /// Delay of the model.
        model_delay: usize,
    },
    /// A training or evaluation sample is NaN or infinite.
    #[error("dig {dig}, sample {sample}: value not finite")]
    NonFiniteSample {
        /// Dig index.
        dig: usize,
        /// Sample index within the dig.
        sample: usize,
    },
    /// Sample times do not strictly increase.
    #[error("dig {dig}, sample {sample}: time does not increase")]
    TimeNotIncreasing {
        /// Dig index.
        dig: usize,
        /// Sample index within the dig.
        sample: usize,
    },
    /// A command is outside `[-1, 1]`.
    #[error("dig {dig}, sample {sample}: command {value} outside [-1, 1]")]
    CommandOutOfRange {
        /// Dig index.
        dig: usize,
        /// Sample index within the dig.
        sample: usize,
        /// The command.
        value: f64,
    },
    /// A dig is too short to give a step at the model's sample period.
    #[error("dig {dig} spans {steps} steps at the model period, needs at least {needed}")]
    DigTooShort {
        /// Dig index.
        dig: usize,
        /// Steps after resampling.
        steps: usize,
        /// Steps needed.
        needed: usize,
    },
    /// A dig spans more steps than [`MAX_DIG_STEPS`] at the model period (a time stamp far off).
    #[error("dig {dig} spans {steps} steps at the model period, at most {max} allowed")]
    DigTooLong {
        /// Dig index.
        dig: usize,
        /// Steps after resampling.
        steps: usize,
        /// Largest allowed.
        max: usize,
    },
    /// Too few digs for the train/validation/test split.
    #[error("{count} digs given, training needs at least {needed}")]
    NotEnoughDigs {
        /// Digs given.
        count: usize,
        /// Digs needed.
        needed: usize,
    },
    /// The training data do not excite a cylinder (its velocity never varies).
    #[error("{joint} velocity does not vary in the training digs")]
    DegenerateData {
        /// The cylinder.
        joint: Joint,
    },
    /// A configuration field is invalid.
    #[error("actuator config {field}: {reason}")]
    InvalidConfig {
        /// Field name.
        field: &'static str,
        /// What is wrong.
        reason: &'static str,
    },
    /// A model file is malformed (wrong format or version, bad dimensions, non-finite weights).
    #[error("actuator model file: {0}")]
    InvalidModel(String),
    /// Training produced non-finite weights.
    #[error("{joint} network training diverged")]
    Diverged {
        /// The cylinder.
        joint: Joint,
    },
}

#[cfg(test)]
mod tests;
