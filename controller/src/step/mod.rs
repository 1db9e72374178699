//! The control step: synchronous, clock-agnostic, frames in and frames out, no I/O. The estimator turns
//! the gateway's frames into the machine state, the safety layer judges it and owns the handshake
//! with the gateway, the work cycle decides the command, and the node combines the three into one
//! step (the same code in the simulator, the tests and the real-time loop).

pub mod cycle;
pub mod estimate;
pub mod log_throttle;
pub mod node;
pub mod plausibility;
pub mod safety;
