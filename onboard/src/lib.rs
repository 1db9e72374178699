//! `onboard`: what runs on the machine. `excavator-ctl run` drives a machine's CAN gateway from the
//! files the machine has (the machine file, the site, the controller config, maps, planner settings,
//! the key and the machine profile), never from a simulator: this crate depends on no simulator and
//! no lab crate (`scripts/check-deps` checks it).
//!
//! # Layout
//!
//! - [`run`]: `excavator-ctl run` and `excavator-ctl ctl`: the session on a CAN bus in real time (or
//!   `--time-scale` times faster), with the action source of `--strategy`, writing the session
//!   folder.
//! - [`setup`]: the controller config, machine, site, maps, planner and profile of a session, which
//!   `run` and the lab's `demo` both build with.
//! - [`folder`]: a session folder is new or empty; another session's is refused (`--force`).
//! - [`options`]: the options a session was started with, kept in its folder for `--resume DIR`.
//! - [`resume`]: a resumable `run`: the records saved with the session driver's checkpoints, the
//!   writer that saves them off the control loop, the trace a resumed session appends to.
//! - [`record`]: the records of a session folder (per-dig records, tip paths, soil samples) kept from
//!   the session driver's events.
//! - [`summary`]: `summary.json` and `summary.md`: totals, the thesis's Tables 3-5, how the session
//!   ended.
//! - [`keys`]: the operator's keys at `run`'s terminal (space = e-stop), through the control
//!   socket's own path.
//! - [`console`]: the progress line of `run` and `demo` on stderr, which log lines do not break.
//! - [`session_log`]: `run`'s log in its session folder (`run.log`), stamped with the session clock.
//!
//! # Data flow
//!
//! ```text
//! machine file, site, config, maps --setup--> ControllerNode + SessionDriver
//! CAN bus <--frames--> controller::io::run::run_session_loop --events--> records --> summary, state file
//! operator (socket, keys) --> OperatorPort --> the loop, before each step
//! ```

pub mod console;
pub mod folder;
pub mod keys;
pub mod options;
pub mod record;
pub mod resume;
pub mod run;
pub mod session_log;
pub mod setup;
pub mod summary;

pub use summary::{DemoStrategy, DemoSummary};
