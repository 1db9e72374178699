//! planner: excavator physics and planning after Cannon (CMU 1999).
//!
//! Layout (data flows top to bottom):
//! - `linkage` (private): the implement linkage in plain numbers, cylinder triangles and the bucket
//!   four-bar (Eqs. A5-A19), below both the machine description's geometric checks and the kinematics.
//! - [`machine`]: the machine description (`config/machine.toml`): geometry, cylinders, masses, hydraulics.
//! - [`toml_lines`]: lines and dotted fields of TOML text, for configuration errors naming file, line
//!   and field.
//! - [`config_file`]: configuration files read as untrusted input (regular files, bounded size).
//! - [`effects`]: the catalogue of hidden physical effects (names, units, ranges) that the simulator
//!   applies and the discrepancy workflow identifies.
//! - [`kinematics`]: joint angles <-> cylinder lengths, forward/inverse kinematics, Jacobian, gravity and
//!   tip forces <-> cylinder forces (Appendix, Eqs. A1-A23).
//! - [`terrain`]: the 2.5-D elevation grid, section profiles, cutting, spoil piles and the swept-volume
//!   integrator (thesis 3.2).
//! - [`soil`]: soil-tool force models, analytical (modified FEE, Eqs. 14-19) and empirical (Eq. 21), and
//!   the bucket-terrain intersection geometry Gamma.
//! - [`actuator`]: the recurrent-network actuator model (thesis 4.2, Figs. 17-18, Eq. 4), training and
//!   `actuator.json`.
//! - [`optimize`]: one-dimensional minimisation (Brent's method), for the estimator's line searches and
//!   the discrepancy workflow's fits.
//! - [`estimate`]: soil-tool property estimation, empirical by least squares and analytical by annealing
//!   and Powell's method (Eqs. 22-24), and the thesis's cross-validation (4.3.4-4.3.5).
//! - [`autodig`]: the Autodig state machine and its pressure-to-command maps (thesis 3.1-3.2, Figs. 9-11).
//! - [`cleanup`]: floor-cleanup waypoints and the hand-over to Autodig (thesis 3.3, Fig. 13).
//! - [`dig_model`]: the combined forward dig model (thesis 4.1, Fig. 14): actuator model + soil model +
//!   the shared Autodig step, predicting a dig's trajectory, time, energy and swept volume.
//! - [`plan`]: the dig planner (thesis ch. 5): terrain mapping from scans, coarse and refined dig
//!   location, dig quality, cleanup and tracking plans, action selection, soil hardness index.
//! - [`site`]: the work site as the controller knows it (`site.toml`): work area, target floor,
//!   the machine's start pose, the material's density.
//! - `synthetic` (tests and the `synthetic` feature): synthetic actuator and FEE soil digs with a known
//!   truth, for the tests and the examples (`cargo run -p planner --release --features synthetic
//!   --example actuator_training` or `--example soil_cross_validation`).

pub mod actuator;
pub mod autodig;
pub mod cleanup;
pub mod config_file;
pub mod dig_model;
pub mod effects;
pub mod estimate;
mod input_check;
pub mod kinematics;
mod linkage;
pub mod machine;
pub mod optimize;
pub mod origin;
mod par;
pub mod plan;
pub mod site;
pub mod soil;
#[cfg(any(test, feature = "synthetic"))]
pub mod synthetic;
pub mod terrain;
pub mod toml_lines;
