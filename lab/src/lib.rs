//! `lab`: the in-process lab over the controller and the simulated machine (`run`, what runs on
//! the machine, is the `onboard` crate's; the lab draws its plots).
//!
//! # Layout
//!
//! - [`campaign`]: the independent jobs of a long command as data, run in-process or on a Dask
//!   cluster and gathered into the same files (docs/campaigns.md).
//! - [`autodig_maps_svg`]: the Autodig map figures of docs/autodig.md (Figs. 10-11).
//! - [`demo`]: `excavator-ctl demo`, a whole autonomous session against the embedded simulator in
//!   virtual time, and the session folder it writes (trace, scans, summary, plots).
//! - [`harness`]: the virtual-time harness: the simulated machine and the controller node on one
//!   in-process bus, stepped in lockstep (used by every in-process run and test).
//! - [`experiment`]: the thesis's reproductions in closed loop (Tables 1-5, Figs. 52, 53, 60).
//! - [`model`]: the dig model's commands: train and evaluate the actuator networks, generate
//!   simulator data, compare the dig model with the simulator, Table 2 and Fig. 52 with the dig
//!   model, cross-validation of the soil models on a session's soil samples (4.3.5).
//! - [`plots`]: the SVG figures of sessions and experiments.
//! - [`results`]: the layout of the generated results page (docs/results.md).
//! - [`shift`]: `experiment shift`, a long planned session under injected faults against a
//!   fault-free one: unsafe outputs, actions, detection and recovery of every fault, memory.
//! - [`thesis`]: the thesis's figures and statements the reproductions are checked against.
//!
//! # Data flow
//!
//! ```text
//! vcan_sim::EmbeddedMachine <--in-process bus, virtual clock--> controller::ControllerNode
//!        |  (truth: terrain, payload)                                |  (estimate, digs)
//!        +----------------------> session records, summaries, plots <+
//! ```

pub mod autodig_maps_svg;
pub mod campaign;
pub mod demo;
pub mod experiment;
pub mod harness;
pub mod model;
pub mod plots;
pub mod results;
pub mod shift;
pub mod thesis;
pub mod trace_samples;
