//! The actuator dynamics the dig model steps ([`ActuatorDynamics`]), implemented by the recurrent
//! networks of [`crate::actuator::ActuatorModel`].

use super::Result;
use crate::actuator::{ActuatorModel, ActuatorState};

/// Actuator dynamics of the dig model: cylinder velocities at the next step from this step's commands
/// and cylinder forces (Fig. 14's "actuator model"). The recurrent networks implement it; the
/// model-discrepancy workflow wraps it with named physical effects (dead band, delay, lag, ...).
pub trait ActuatorDynamics: Send + Sync {
    /// Per-dig state (delay lines, previous velocities): created per dig, stepped in place.
    type State: Clone + Send;

    /// The step period, s (the dig model steps Autodig at this period too).
    fn dt_s(&self) -> f64;

    /// A state for a machine at rest under neutral commands.
    ///
    /// # Errors
    /// Implementation-defined; [`DigModelError::Actuator`](super::DigModelError::Actuator) for the networks.
    fn initial_state(&self) -> Result<Self::State>;

    /// Advances one period with commands `[boom, stick, bucket]` in `[-1, 1]` and cylinder forces (N,
    /// Eq. A20 sign), returning the cylinder velocities at the next step, m/s. Must not allocate.
    ///
    /// # Errors
    /// Implementation-defined; non-finite inputs must be errors, not NaN outputs.
    fn step(
        &self,
        state: &mut Self::State,
        command: [f64; 3],
        force_n: [f64; 3],
    ) -> Result<[f64; 3]>;
}

impl ActuatorDynamics for ActuatorModel {
    type State = ActuatorState;

    fn dt_s(&self) -> f64 {
        ActuatorModel::dt_s(self)
    }

    fn initial_state(&self) -> Result<ActuatorState> {
        // The dig model's forces are statics (no pressure dynamics): no force-rate input.
        Ok(ActuatorModel::initial_state(self, [0.0; 3], [0.0; 3])?.with_static_forces())
    }

    #[inline]
    fn step(
        &self,
        state: &mut ActuatorState,
        command: [f64; 3],
        force_n: [f64; 3],
    ) -> Result<[f64; 3]> {
        Ok(ActuatorModel::step(self, state, command, force_n)?) // Eq. 4
    }
}
