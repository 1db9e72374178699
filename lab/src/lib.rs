//! `lab`: the in-process lab over the controller and the simulated machine.
//!
//! # Layout
//!
//! - [`autodig_maps_svg`]: the Autodig map figures of docs/autodig.md (Figs. 10-11).
//! - [`demo`]: `excavator-ctl demo`, a whole autonomous session against the embedded simulator in
//!   virtual time, and the session folder it writes (trace, scans, summary, plots).
//! - [`experiment`]: the thesis's reproductions in closed loop (Tables 1-5, Figs. 52, 53, 60).
//! - [`model_cmd`]: the dig model's commands: train and evaluate the actuator networks, generate
//!   simulator data, compare the dig model with the simulator, Table 2 with the dig model.
//! - [`model_fig52`]: thesis Fig. 52 with the dig model.
//! - [`soil_cv`]: cross-validation of the soil models on a session's soil samples (4.3.5).
//! - [`plots`]: the SVG figures of sessions and experiments.
//!
//! # Data flow
//!
//! ```text
//! vcan_sim::EmbeddedMachine <--in-process bus, virtual clock--> controller::ControllerNode
//!        |  (truth: terrain, payload)                                |  (estimate, digs)
//!        +----------------------> session records, summaries, plots <+
//! ```

pub mod autodig_maps_svg;
pub mod demo;
pub mod experiment;
pub mod model_cmd;
pub mod model_fig52;
pub mod plots;
pub mod soil_cv;
