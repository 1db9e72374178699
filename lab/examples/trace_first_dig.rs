//! The first dig of the default plan (or, with `TRACE_CLEANUP` set, the floor cleanup of the
//! closed-loop tests) against the simulator in virtual time: the joints' limits, then every 0.5 s the
//! phase, Autodig stage, joints, rates, tip, command and safety state.
//!
//! `cargo run -p lab --release --example trace_first_dig`

#![allow(clippy::unwrap_used)] // A diagnostic: a bad variable or start should stop it loudly.

#[path = "../tests/common/mod.rs"]
mod common;

use common::{Loop, cleanup_setup, default_sim, one_dig};

fn main() {
    let mut l = if std::env::var("TRACE_CLEANUP").is_ok() {
        let (sim, config) = cleanup_setup();
        Loop::new(sim, config)
    } else {
        Loop::new(default_sim(), one_dig())
    };
    for j in planner::kinematics::Joint::ALL {
        let k = l.node().estimator().kinematics();
        println!(
            "{j}: limits {:?} stroke range {:?}",
            k.joint_limits(j),
            k.stroke_limited_range(j)
        );
    }
    let mut next = 0.0;
    l.run_until(60.0, |l| {
        if l.time_s() >= next {
            next += 0.5;
            let s = l.node().state();
            println!(
                "{:6.2} {:?} {:?} q=[{:.3} {:.3} {:.3} sw {:.3}] rates={:.3?} tip=({:.2},{:.2}) cmd={:?} safety={:?}",
                l.time_s(),
                l.phase(),
                l.node().stage(),
                s.joints.boom_rad,
                s.joints.stick_rad,
                s.joints.bucket_rad,
                s.swing_rad,
                s.rates_rad_per_s,
                s.tip.x_m,
                s.tip.z_m,
                l.node().last_command(),
                l.node().safety().state()
            );
        }
        l.node().finished()
    });
}
