//! `lab`: the in-process lab over the controller and the simulated machine.
//!
//! # Layout
//!
//! - [`autodig_maps_svg`]: the Autodig map figures of docs/autodig.md (Figs. 10-11).
//! - [`console`]: the progress line of `demo` and `run` on stderr, which log lines do not break.
//! - [`demo`]: `excavator-ctl demo`, a whole autonomous session against the embedded simulator in
//!   virtual time, and the session folder it writes (trace, scans, summary, plots).
//! - [`harness`]: the virtual-time harness: the simulated machine and the controller node on one
//!   in-process bus, stepped in lockstep (used by every in-process run and test).
//! - [`keys`]: the operator's keys at `run`'s terminal (space = e-stop), through the control
//!   socket's own path.
//! - [`experiment`]: the thesis's reproductions in closed loop (Tables 1-5, Figs. 52, 53, 60).
//! - [`model`]: the dig model's commands: train and evaluate the actuator networks, generate
//!   simulator data, compare the dig model with the simulator, Table 2 and Fig. 52 with the dig
//!   model, cross-validation of the soil models on a session's soil samples (4.3.5).
//! - [`plots`]: the SVG figures of sessions and experiments.
//! - [`results`]: the layout of the generated results page (docs/results.md).
//! - [`resume`]: a resumable `run`: the records saved with the session driver's checkpoints, the
//!   writer that saves them off the control loop, the trace a resumed session appends to.
//! - [`shift`]: `experiment shift`, a long planned session under injected faults against a
//!   fault-free one: unsafe outputs, actions, detection and recovery of every fault, memory.
//! - [`session_log`]: `run`'s log in its session folder (`run.log`), stamped with the session clock.
//! - [`session`]: the records of a session folder (per-dig records, tip paths, soil samples).
//! - [`thesis`]: the thesis's figures and statements the reproductions are checked against.
//! - [`wire`]: `excavator-ctl run`, the same session on a CAN bus in real time (planned, predefined
//!   or fixed), writing the same session folder.
//!
//! # Data flow
//!
//! ```text
//! vcan_sim::EmbeddedMachine <--in-process bus, virtual clock--> controller::ControllerNode
//!        |  (truth: terrain, payload)                                |  (estimate, digs)
//!        +----------------------> session records, summaries, plots <+
//! ```

pub mod autodig_maps_svg;
pub mod console;
pub mod demo;
pub mod experiment;
pub mod harness;
pub mod keys;
pub mod model;
pub mod plots;
pub mod results;
pub mod resume;
pub mod session;
pub mod session_log;
pub mod shift;
pub mod thesis;
pub mod wire;
