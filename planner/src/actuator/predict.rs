//! Prediction: the model, its per-dig state and its allocation-free step (Eq. 4), free-running
//! simulation of recorded digs and the error measure of Figs. 19-21.

use super::dig::{clamp_command, resample};
use super::network::{IN_VELOCITY, Network};
use super::{ActuatorDig, ActuatorError, MAX_DELAY_STEPS, MAX_HIDDEN};
use crate::kinematics::Joint;
use serde::{Deserialize, Serialize};

/// Prediction error of one cylinder over a set of digs (free-running, as in Figs. 19-21).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CylinderError {
    /// The cylinder.
    pub joint: Joint,
    /// Mean absolute velocity error, m/s.
    pub mae_m_per_s: f64,
    /// Root-mean-square velocity error, m/s.
    pub rms_m_per_s: f64,
    /// Peak measured speed over the digs, m/s.
    pub peak_m_per_s: f64,
    /// Mean absolute error as a percentage of the peak speed (thesis: 5-8 %).
    pub mae_percent_of_peak: f64,
}

/// Free-running prediction errors over a set of digs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EvaluationReport {
    /// Digs evaluated.
    pub digs: usize,
    /// Predicted steps per cylinder.
    pub steps: usize,
    /// Errors `[boom, stick, bucket]`.
    pub cylinders: [CylinderError; 3],
}

/// One step of a free-running prediction of a recorded dig ([`ActuatorModel::simulate`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PredictedStep {
    /// Time, s.
    pub time_s: f64,
    /// Predicted cylinder velocities `[boom, stick, bucket]`, m/s.
    pub predicted_m_per_s: [f64; 3],
    /// Measured (resampled) cylinder velocities, m/s.
    pub measured_m_per_s: [f64; 3],
}

/// Summary of the training, kept with the model (and in its file).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainingSummary {
    /// Seed used.
    pub seed: u64,
    /// Digs trained on, validated on and tested on.
    pub digs: [usize; 3],
    /// Held-out test error, percent of peak speed, `[boom, stick, bucket]`.
    pub test_mae_percent_of_peak: [f64; 3],
    /// The command that made the model and the plant version of its data.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub origin: Option<crate::origin::ArtefactOrigin>,
}

/// The trained actuator model: three recurrent networks (Fig. 17). Immutable and `Send + Sync`.
#[derive(Debug, Clone, PartialEq)]
pub struct ActuatorModel {
    pub(super) dt_s: f64,
    pub(super) delay_steps: usize,
    /// Spool lag time constant, s, and its per-step gain `1 - exp(-dt / tau)` (1: no lag).
    pub(super) command_lag_s: f64,
    pub(super) lag_gain: f64,
    pub(super) networks: [Network; 3],
    pub(super) training: Option<TrainingSummary>,
}

/// Per-dig prediction state: the command delay line and the previous velocities. Fixed size, `Copy`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ActuatorState {
    pub(super) velocity_m_per_s: [f64; 3],
    pub(super) delay_steps: usize,
    pub(super) head: usize,
    pub(super) commands: [[f64; 3]; MAX_DELAY_STEPS],
    /// The lagged delayed commands (spool estimate), the networks' command inputs.
    pub(super) spool: [f64; 3],
    /// The forces of the last step, N (the force-rate input); `None` before the first step.
    pub(super) force_n: Option<[f64; 3]>,
    /// The forces are quasi-static (the dig model's statics, which carry no pressure dynamics): the
    /// force-rate input is held at zero ([`ActuatorState::with_static_forces`]).
    pub(super) static_forces: bool,
}

impl ActuatorState {
    /// The same state for quasi-static force inputs (the dig model's statics, Eqs. A2-A19): the
    /// networks' force-rate input (Eq. 2, [`TrainConfig::force_rate_input`](super::TrainConfig::force_rate_input)) is held at zero, since a
    /// static force has no compressibility transient to report. No effect on networks without it.
    #[must_use]
    pub fn with_static_forces(mut self) -> Self {
        self.static_forces = true;
        self
    }

    /// Velocities `[boom, stick, bucket]` predicted by the last step (or the initial ones), m/s.
    #[must_use]
    pub fn velocity_m_per_s(&self) -> [f64; 3] {
        self.velocity_m_per_s
    }

    /// Pushes this step's command and returns the one issued `delay_steps` steps ago (Fig. 17).
    #[inline]
    fn push_command(&mut self, command: [f64; 3]) -> [f64; 3] {
        if self.delay_steps == 0 {
            return command;
        }
        let head = self.head % self.delay_steps.min(MAX_DELAY_STEPS);
        let slot = &mut self.commands[head];
        let delayed = *slot;
        *slot = command;
        self.head = (head + 1) % self.delay_steps;
        delayed
    }
}

impl ActuatorModel {
    /// Model period, s: one [`step`](Self::step) advances this much time.
    #[must_use]
    pub fn dt_s(&self) -> f64 {
        self.dt_s
    }

    /// Command delay in steps.
    #[must_use]
    pub fn delay_steps(&self) -> usize {
        self.delay_steps
    }

    /// Spool lag time constant, s (0: the networks see the delayed command itself).
    #[must_use]
    pub fn command_lag_s(&self) -> f64 {
        self.command_lag_s
    }

    /// Hidden units per network.
    #[must_use]
    pub fn hidden_units(&self) -> usize {
        self.networks[0].hidden
    }

    /// The training summary stored with the model, if it came from [`train`](super::train()).
    #[must_use]
    pub fn training_summary(&self) -> Option<&TrainingSummary> {
        self.training.as_ref()
    }

    /// The model with its origin recorded in the training summary (a model without a summary, not
    /// made by [`train`](super::train()), gets none).
    #[must_use]
    pub fn with_origin(mut self, origin: crate::origin::ArtefactOrigin) -> Self {
        if let Some(t) = self.training.as_mut() {
            t.origin = Some(origin);
        }
        self
    }

    /// A fresh state: the machine moving at `velocity_m_per_s` with `command` issued for the whole
    /// delay line (use zeros for a machine at rest under neutral commands).
    ///
    /// # Errors
    /// [`ActuatorError::NonFiniteInput`] for NaN or infinite values.
    pub fn initial_state(
        &self,
        velocity_m_per_s: [f64; 3],
        command: [f64; 3],
    ) -> Result<ActuatorState, ActuatorError> {
        if velocity_m_per_s.iter().any(|v| !v.is_finite()) {
            return Err(ActuatorError::NonFiniteInput {
                what: "velocity_m_per_s",
            });
        }
        if command.iter().any(|v| !v.is_finite()) {
            return Err(ActuatorError::NonFiniteInput { what: "command" });
        }
        let mut velocity = velocity_m_per_s;
        for (v, net) in velocity.iter_mut().zip(&self.networks) {
            let limit = net.output_limit * net.velocity_scale;
            *v = v.clamp(-limit, limit);
        }
        let command = clamp_command(command);
        Ok(ActuatorState {
            velocity_m_per_s: velocity,
            delay_steps: self.delay_steps,
            head: 0,
            commands: [command; MAX_DELAY_STEPS],
            spool: command,
            force_n: None,
            static_forces: false,
        })
    }

    /// Advances one period: takes this step's commands `[boom, stick, bucket]` (fractions in `[-1, 1]`,
    /// clamped) and cylinder forces (N), and returns the cylinder velocities at the next step (m/s),
    /// also kept in `state` (Eq. 4). Allocation-free.
    ///
    /// # Errors
    /// [`ActuatorError::NonFiniteInput`] for NaN or infinite inputs (the state is left unchanged);
    /// [`ActuatorError::StateMismatch`] for a state made by a model with another delay.
    #[inline]
    pub fn step(
        &self,
        state: &mut ActuatorState,
        command: [f64; 3],
        force_n: [f64; 3],
    ) -> Result<[f64; 3], ActuatorError> {
        if command.iter().any(|v| !v.is_finite()) {
            return Err(ActuatorError::NonFiniteInput { what: "command" });
        }
        if force_n.iter().any(|v| !v.is_finite()) {
            return Err(ActuatorError::NonFiniteInput { what: "force_n" });
        }
        if state.delay_steps != self.delay_steps {
            return Err(ActuatorError::StateMismatch {
                state_delay: state.delay_steps,
                model_delay: self.delay_steps,
            });
        }
        let delayed = state.push_command(clamp_command(command));
        let gain = self.lag_gain;
        for (s, u) in state.spool.iter_mut().zip(delayed) {
            *s += gain * (u - *s);
        }
        let delayed = state.spool;
        let previous_force = if state.static_forces {
            force_n
        } else {
            state.force_n.unwrap_or(force_n)
        };
        state.force_n = Some(force_n);
        let mut hidden = [0.0; MAX_HIDDEN];
        let mut velocity = [0.0; 3];
        for (j, net) in self.networks.iter().enumerate() {
            let raw = net.raw_inputs(
                j,
                &delayed,
                &force_n,
                &previous_force,
                state.velocity_m_per_s[j],
            );
            let x = net.normalise(&raw);
            let y = net.forward(&net.params, &x, &mut hidden);
            // A non-finite y can only come from overflowing weights; hold the previous speed then.
            let y = if y.is_finite() {
                y.clamp(-net.output_limit, net.output_limit)
            } else {
                x[IN_VELOCITY]
            };
            velocity[j] = y * net.velocity_scale;
        }
        state.velocity_m_per_s = velocity;
        Ok(velocity)
    }

    /// Free-running prediction of a recorded dig, resampled to the model period: one
    /// [`PredictedStep`] per step, starting from the measured first velocity and with the first command
    /// filling the delay line (as in training).
    ///
    /// # Errors
    /// As [`evaluate`](Self::evaluate).
    pub fn simulate(&self, dig: &ActuatorDig) -> Result<Vec<PredictedStep>, ActuatorError> {
        self.simulate_dig(dig, 0, false)
    }

    fn simulate_dig(
        &self,
        dig: &ActuatorDig,
        index: usize,
        static_forces: bool,
    ) -> Result<Vec<PredictedStep>, ActuatorError> {
        let seq = resample(dig, index, self.dt_s)?;
        let (Some(&v0), Some(&u0)) = (seq.velocity.first(), seq.command.first()) else {
            return Ok(Vec::new());
        };
        let mut state = self.initial_state(v0, u0)?;
        if static_forces {
            state = state.with_static_forces();
        }
        let mut out = Vec::with_capacity(seq.len());
        out.push(PredictedStep {
            time_s: seq.t0,
            predicted_m_per_s: v0,
            measured_m_per_s: v0,
        });
        for k in 0..seq.len().saturating_sub(1) {
            let v = self.step(&mut state, seq.command[k], seq.force[k])?;
            out.push(PredictedStep {
                time_s: seq.t0 + (k + 1) as f64 * self.dt_s,
                predicted_m_per_s: v,
                measured_m_per_s: seq.velocity[k + 1],
            });
        }
        Ok(out)
    }

    /// Free-running error on a set of digs (the thesis's Figs. 19-21 measure).
    ///
    /// # Errors
    /// [`ActuatorError::NonFiniteSample`], [`ActuatorError::TimeNotIncreasing`],
    /// [`ActuatorError::CommandOutOfRange`], [`ActuatorError::DigTooShort`] for bad digs.
    pub fn evaluate(&self, digs: &[ActuatorDig]) -> Result<EvaluationReport, ActuatorError> {
        self.evaluate_with(digs, false)
    }

    /// [`ActuatorModel::evaluate`] with the force-rate input held at zero
    /// ([`ActuatorState::with_static_forces`]), as the dig model runs the networks on its statics.
    ///
    /// # Errors
    /// As [`ActuatorModel::evaluate`].
    pub fn evaluate_static(&self, digs: &[ActuatorDig]) -> Result<EvaluationReport, ActuatorError> {
        self.evaluate_with(digs, true)
    }

    fn evaluate_with(
        &self,
        digs: &[ActuatorDig],
        static_forces: bool,
    ) -> Result<EvaluationReport, ActuatorError> {
        let mut sums = [(0.0_f64, 0.0_f64, 0.0_f64); 3];
        let mut steps = 0usize;
        for (index, dig) in digs.iter().enumerate() {
            for step in self.simulate_dig(dig, index, static_forces)?.iter().skip(1) {
                for (j, sum) in sums.iter_mut().enumerate() {
                    let e = step.predicted_m_per_s[j] - step.measured_m_per_s[j];
                    sum.0 += e.abs();
                    sum.1 += e * e;
                    sum.2 = sum.2.max(step.measured_m_per_s[j].abs());
                }
                steps += 1;
            }
        }
        let n = steps.max(1) as f64;
        let cylinders = Joint::ALL.map(|joint| {
            let (abs, sq, peak) = sums[joint.index()];
            let mae = abs / n;
            CylinderError {
                joint,
                mae_m_per_s: mae,
                rms_m_per_s: (sq / n).sqrt(),
                peak_m_per_s: peak,
                mae_percent_of_peak: if peak > 0.0 { 100.0 * mae / peak } else { 0.0 },
            }
        });
        Ok(EvaluationReport {
            digs: digs.len(),
            steps,
            cylinders,
        })
    }
}

/// Per-step gain of the spool lag, `1 - exp(-dt / tau)`; 1 (no lag) for `tau = 0`.
pub(super) fn lag_gain(dt_s: f64, tau_s: f64) -> f64 {
    if tau_s > 0.0 {
        -(-dt_s / tau_s).exp_m1()
    } else {
        1.0
    }
}
