//! `vcan_sim`: the excavator emulated behind its CAN gateway.
//!
//! Layout (physics is pure; I/O only in `realtime`, `embedded` and the binary):
//!
//! - [`effects`]: the registry of hidden physical effects (`--effect NAME=VALUE`).
//! - [`hydraulics`]: pumps, open-centre valves, relief valves, chambers and cylinders (Eqs. 1-3).
pub mod effects;
pub mod hydraulics;
pub mod linkage;
pub mod plant;
pub mod scenario;
pub mod sensors;
pub mod soil_contact;
