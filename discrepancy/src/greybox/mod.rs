//! The grey-box replay model: a physical model of the valves, pumps, cylinders, links and soil with
//! few parameters, driven by the measured inputs of a trace (valve commands, measured pressures and
//! motion, the pre-dig terrain section) and predicting the measured signals sample by sample.
//!
//! The prediction is an equation-error (one-step) replay: every relation is evaluated at the measured
//! state of its own sample, so model errors never accumulate along a dig (the limit of multiple
//! shooting with one-sample windows). Only the spool state is integrated along the record, from the
//! commands alone (it has no measured counterpart). Relations, per 10 ms sample:
//!
//! - spool: dead band, fixed transport delay, first-order lag (Eq. 2's compressibility and the pilot
//!   stage folded into one time constant), integrated at 1 ms from the zero-order-held commands;
//! - cylinder velocity (Eq. 1): meter-in `Q = k_in a(s) sqrt(p_pump - p_inlet)` and meter-out
//!   `Q = k_out a(s) sqrt(p_outlet - p_tank)` orifices with the measured pressures, flow continuity
//!   `Q = A v` (plus cross-piston leakage), the two estimates combined with weights inverse to their
//!   sensitivity to pressure noise;
//! - pump pressure: the open-centre flow balance `Q_pump(p) = Q_bypass(p) + sum Q_meter_in(p) +
//!   Q_relief(p)` with `Q_pump = min(Q_max, W / p)` (thesis 4.2.1, Fig. 15), solved for the gallery
//!   pressure with the measured chamber pressures;
//! - cylinder force (Eq. 3 with Eq. A20): `p_h A_h - p_r A_r = F_gravity(q) + M(q) a + c v + friction`
//!   with the Appendix gravity torques (Eq. A4) over the moment arms (Eqs. A7, A19), only where the
//!   bucket is empty and out of the soil;
//! - soil force on the bucket (Eqs. A20-A23 from the measured pressures) against the modified FEE
//!   (Eqs. 14-18) on the pre-dig section, in the soil stages.
//!
//! Layout (one relation or stage per module, data flowing top to bottom):
//! - `params`: the nominal parameters ([`GreyBoxParams`]) and the candidate magnitudes
//!   ([`Augmentation`]);
//! - `inertia`, `weighing`, `soil`: the links' gravity and inertia at the cylinders, the weighed
//!   payload and the soil relation's terms, which `record` computes once per sample;
//! - `record`: the prepared record ([`PreparedRecord`]): the measured signals and everything no
//!   candidate changes;
//! - `spool`, `hydraulics`: the spool dynamics and the valve, cylinder and pump relations;
//! - `replay`: the predicted signals of a prepared record under an augmentation;
//! - `prefilter`: the velocity signals' moving average, applied to measurement and prediction.

// Per-cylinder and per-signal arrays run in parallel; indexing them by one counter is clearer here
// than zipping four iterators.
#![allow(clippy::needless_range_loop)]

mod hydraulics;
mod inertia;
mod params;
mod prefilter;
mod record;
mod replay;
mod soil;
mod spool;
mod weighing;

pub use crate::signal::{N_SIGNALS, Signal, SignalGroups};
pub use hydraulics::{bypass_constant, steady_velocity};
pub use params::{Augmentation, GreyBoxParams};
pub use prefilter::{VELOCITY_PREFILTER_HALF, prefilter_velocities};
pub use record::{PreparedRecord, WARMUP_SAMPLES, warmed_up};
pub use replay::replay;
pub use soil::SoilTerms;
pub use weighing::PayloadTerms;
