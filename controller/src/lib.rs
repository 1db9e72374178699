//! `controller`: the real-time excavator controller behind `excavator-ctl run`.
//!
//! # Layout
//!
//! - [`estimate`]: the machine state from the gateway's frames (Appendix A.2): angles, filtered rates,
//!   pressures, cylinder forces (A20), joint torques (A21, A22), tip forces (A23), tip pose, odometry,
//!   the static payload estimate, and per-signal timestamps.
//! - [`safety`]: the safety layer as a pure state machine: arming handshake and heartbeat, stale data,
//!   decode errors, joint limits, e-stop, gateway and bus faults, listen-only.
//! - [`cycle`]: the work cycle: scan, swing to the dig, Autodig with the perception enhancements or
//!   cleanup, weigh, swing to the spoil pile, dump, return; tracking backwards; per-dig statistics.
//! - [`config`]: [`ControllerConfig`] (the TOML of `excavator-ctl run --config`), its loading with
//!   errors naming file, line and field, and the parameter checks every part's `validate()` uses.
//! - [`log_throttle`]: the rate limit of log lines another node can trigger frame by frame.
//! - [`node`]: [`ControllerNode`], the synchronous, clock-agnostic control step combining the three:
//!   frames in, frames out, no I/O.
//! - [`planned`]: the dig planner as the work cycle's action source (thesis 5.3, Fig. 42), and the
//!   predefined excavation sequence of 6.2.
//! - [`session`]: the session driver: after every control step it answers scan requests, asks the
//!   planner for the next action when the cycle waits for one, and feeds each dig's outcome back
//!   (the loop `demo` and `run` share); after every completed action it takes a checkpoint.
//! - [`session_state`]: the resumable session: the driver's checkpoint, the identity a saved session
//!   belongs to, and its validated loading (`run --resume`).
//! - [`state_file`]: atomic JSON state files (temp, fsync, rename) and loading that names file and
//!   field.
//! - [`operator`]: operator control of a running controller over a Unix socket (status, pause,
//!   resume, e-stop, reset, stop), served beside the loop and applied before each step.
//! - [`run`]: the real-time loop over SocketCAN (tokio drives a 10 ms interval around the node).
//! - [`scan_client`]: the range-scan client of the real-time loop (JSON lines over TCP).
//!
//! # Data flow (one 10 ms step)
//!
//! ```text
//! received frames --decode--> Estimator (+ safety: decode errors, unexpected frames, bus faults)
//!        Estimator --> Safety::observe (staleness, limits, gateway status)
//!        Estimator --> WorkCycle::step (Autodig / cleanup / P-controllers) --> wanted mode + command
//!        Safety::tick (handshake, faults) --> frames: valve commands or a setpoint, then the heartbeat
//! ```

pub mod config;
pub mod cycle;
pub mod estimate;
pub mod log_throttle;
pub mod node;
pub mod operator;
pub mod planned;
pub mod run;
pub mod safety;
pub mod scan_client;
pub mod sd_notify;
pub mod session;
pub mod session_state;
pub mod state_file;

pub use config::ControllerConfig;
pub use cycle::{Action, CycleConfig, DigStats, WorkCycle};
pub use estimate::{Estimator, MachineState};
pub use node::{ControllerNode, Outbox};
pub use safety::{ArmMode, Fault, Safety, SafetyConfig};

/// Errors building the controller.
#[derive(Debug, thiserror::Error)]
pub enum ControllerError {
    /// The machine geometry is inconsistent.
    #[error("machine geometry: {0}")]
    Kinematics(#[from] planner::kinematics::KinematicsError),
    /// The Autodig configuration is invalid.
    #[error("autodig: {0}")]
    Autodig(#[from] planner::autodig::AutodigError),
    /// The cleanup configuration is invalid.
    #[error("cleanup: {0}")]
    Cleanup(#[from] planner::cleanup::CleanupError),
    /// A configuration value is invalid.
    #[error("config {field}: {reason}")]
    Config {
        /// The field.
        field: &'static str,
        /// What is wrong.
        reason: String,
    },
}

/// Result alias of this crate.
pub type Result<T> = std::result::Result<T, ControllerError>;
