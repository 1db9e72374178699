//! Helpers shared by the end-to-end tests of `excavator-sim` and `excavator-ctl`.
//!
//! # Layout
//!
//! - [`env`](mod@env): the vcan interface, the built binaries, can-utils: found or a loud failure naming the fix.
//! - [`process`]: child processes that die with the test, signals, logs.
//! - [`plan`]: the HIL work-cycle plan (three digs and a cleanup) as a controller config file.
//! - [`planned`]: the planned session: the bench where a short session digs, cleans up and tracks
//!   back, the simulator serving it, `run --strategy planned` and `demo` on it.
//! - [`analysis`]: what a recorded session shows, computed the same way for a `candump -L` log and an
//!   in-process recording: the `ControllerStatus` activity sequence and the dig cycles in it, gateway
//!   status frames, joint angles, heartbeats.
//! - [`inprocess`]: the same scenarios over the in-process bus in virtual time (`vcan_sim::embedded`
//!   and `controller::step::node`), so a machine without vcan or qemu still covers the logic.
//!
//! The vcan tests themselves live in `tests/*.rs`, `#[ignore]`d in a plain `cargo test` and run by
//! `scripts/test-all` through `scripts/vcan-vm` (natively where the kernel has vcan, otherwise inside a
//! throwaway qemu VM).

pub mod analysis;
pub mod env;
pub mod inprocess;
pub mod plan;
pub mod planned;
pub mod process;
