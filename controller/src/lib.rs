//! `controller`: the real-time excavator controller behind `excavator-ctl run`.
//!
//! # Layout
//!
//! The folder follows the parts: the control step, the session around it, and the I/O that drives both.
//!
//! - [`check`]: the parameter checks every part's `validate()` uses ([`check::ParamError`] names the
//!   field and the rule it breaks).
//! - [`config`]: [`ControllerConfig`] (the TOML of `excavator-ctl run --config`) gathering the parts'
//!   configurations, and its loading with errors naming file, line and field.
//! - [`step`]: the synchronous, clock-agnostic control step, frames in, frames out, no I/O:
//!   - [`step::estimate`]: the machine state from the gateway's frames (Appendix A.2): angles, filtered
//!     rates, pressures, cylinder forces (A20), joint torques (A21, A22), tip forces (A23), tip pose,
//!     odometry, the static payload estimate, and per-signal timestamps.
//!   - [`step::safety`]: the safety layer as a pure state machine: arming handshake and heartbeat, stale
//!     data, decode errors, joint limits, e-stop, gateway and bus faults, listen-only.
//!   - [`step::cycle`]: the work cycle: scan, swing to the dig, Autodig with the perception enhancements
//!     or cleanup, weigh, swing to the spoil pile, dump, return; tracking backwards; per-dig statistics.
//!   - [`step::node`]: [`ControllerNode`], the control step combining the three.
//!   - [`step::log_throttle`]: the rate limit of log lines another node can trigger frame by frame.
//! - [`session`]: what runs a session of many actions on a node:
//!   - [`session::driver`]: the session driver: after every control step it answers scan requests, asks
//!     the planner for the next action when the cycle waits for one, and feeds each dig's outcome back
//!     (the loop `demo` and `run` share); after every completed action it takes a checkpoint.
//!   - [`session::planned`]: the dig planner as the work cycle's action source (thesis 5.3, Fig. 42), and
//!     the predefined excavation sequence of 6.2.
//!   - [`session::snapshot`]: the serialized types of a session the driver, the planner and the state
//!     file share: the checkpoint's snapshots, the strategy, the predefined sequence, a dig's prediction.
//!   - [`session::session_state`]: the resumable session: the identity a saved session belongs to, and
//!     its validated loading (`run --resume`).
//!   - [`session::state_file`]: atomic JSON state files (temp, fsync, rename) and loading that names file
//!     and field.
//! - [`io`]: the real-time I/O around the step:
//!   - [`io::run`]: the real-time loop over SocketCAN (tokio drives an interval of
//!     [`CONTROL_PERIOD`](firmware_bridge::dbc::CONTROL_PERIOD) around the node).
//!   - [`io::operator`]: operator control of a running controller over a Unix socket (status, pause,
//!     resume, e-stop, reset, stop), served beside the loop and applied before each step.
//!   - [`io::scan_client`]: the range-scan client of the real-time loop (JSON lines over TCP).
//!   - [`io::sd_notify`]: systemd readiness and watchdog notifications from the loop.
//!
//! `io` uses `session` and `step`, `session` uses `step` (and the driver's observer hook takes the
//! operator socket's sender), the step's parts use `check`, and `config` gathers the parts'
//! configurations; `controller/tests/import_cycles.rs` fails on an import circle of more than two
//! files.
//!
//! # Data flow (one 10 ms step)
//!
//! ```text
//! received frames --decode--> Estimator (+ safety: decode errors, unexpected frames, bus faults)
//!        Estimator --> Safety::observe (staleness, limits, gateway status)
//!        Estimator --> WorkCycle::step (Autodig / cleanup / P-controllers) --> wanted mode + command
//!        Safety::tick (handshake, faults) --> frames: valve commands or a setpoint, then the heartbeat
//! ```

pub mod check;
pub mod config;
pub mod io;
pub mod session;
pub mod step;

pub use config::ControllerConfig;
pub use step::cycle::{Action, CycleConfig, DigStats, WorkCycle};
pub use step::estimate::{Estimator, MachineState};
pub use step::node::{ControllerNode, Outbox};
pub use step::safety::{ArmMode, Fault, Safety, SafetyConfig};

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
