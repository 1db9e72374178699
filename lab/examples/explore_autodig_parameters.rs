//! One dig per Autodig setting of a small grid (rho2, hardness index, start tip) against the simulator
//! in virtual time: whether it reached Weigh, when, the payload, swept volume and last fault.
//!
//! `cargo run -p lab --release --example explore_autodig_parameters`

#![allow(clippy::unwrap_used)] // A diagnostic: a bad variable or start should stop it loudly.

#[path = "../tests/common/mod.rs"]
mod common;

use common::{Loop, default_sim, one_dig};
use controller::step::cycle::{Action, Phase, StartPose};

fn main() {
    for (rho2, hardness, x, z) in [
        (-180.0, 3.0, 7.0, 2.8),
        (-200.0, 3.0, 7.0, 2.8),
        (-200.0, 5.0, 7.0, 2.8),
        (-200.0, 3.0, 6.0, 2.6),
        (-200.0, 5.0, 6.0, 2.6),
        (-200.0, 5.0, 6.5, 2.4),
    ] {
        let mut c = one_dig();
        c.autodig.rho2_rad = f64::to_radians(rho2);
        c.autodig.hardness_index = hardness;
        c.cycle.actions = vec![Action::Dig {
            swing_rad: 0.0,
            start: StartPose::Tip {
                x_m: x,
                z_m: z,
                bucket_abs_rad: (-90.0_f64).to_radians(),
            },
        }];
        let mut l = Loop::new(default_sim(), c);
        let ok = l.run_until(60.0, |l| l.phase() == Phase::Weigh);
        let t = l.machine().plant().true_state();
        println!(
            "rho2 {rho2} h {hardness} start ({x},{z}): weigh {ok} at {:.2}, payload {:.0} kg, swept {:?}, fault {:?}",
            l.time_s(),
            t.payload_kg,
            l.node().cycle().swept_volume_m3(),
            l.node().last_fault()
        );
    }
}
