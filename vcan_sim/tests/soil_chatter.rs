//! A cylinder stalled with the bucket deep in the bench: the reported joint rate must match the
//! motion, and the cylinder must not chatter (docs/simulator.md, "Soil contact integration").
//!
//! The soil force depends on the direction of the tip velocity (the FEE wedge and the bearing
//! resistances oppose the travel, mobilised by `tanh(speed / 0.01 m/s)`). The default plant
//! (`soil_contact = "implicit"`) evaluates it at every physics step as a function of the tip velocity
//! and solves its gradient jointly for the three cylinders: the stalled cylinders hold still.
//!
//! The `held` plant (plant version `held-1`) computes it from the velocity at the 200 Hz soil update
//! and holds it for the next 5 physics steps. As an explicit load, against the ~1e5 N of a 0.9 m deep
//! edge, it overshoots: within one hold it reverses the cylinder, the next update sees the opposite
//! travel and flips the force, and the cylinders settle into a limit cycle of period 10 physics steps
//! with no net motion. The 100 Hz sensor sampling takes every 10th step, always at the same phase of
//! that cycle, so it reports a steady rate (the bucket at ~ -0.74 rad/s) while the angle does not
//! move. That test is ignored: it documents the known issue of the plant kept to reproduce results
//! made on it.
//!
//! Both plants must let a bucket stalled there come out when the boom lifts it.
//!
//! `cargo test -p vcan_sim --test soil_chatter -- --include-ignored --nocapture` prints the figures.

// Test helpers panic on setup failure by design (clippy only exempts `#[test]` bodies).
#![allow(clippy::unwrap_used)]

use planner::machine::MachineConfig;
use vcan_sim::effects::EffectSet;
use vcan_sim::hydraulics::{BUCKET, STICK};
use vcan_sim::plant::Plant;
use vcan_sim::scenario::{Scenario, SoilContactIntegration};

/// The default bench with the implement at the stalled pose of the planned demo session: stick
/// -1.3135 rad, bucket -0.482 rad, the boom lowered until the tip is ~0.9 m below the bench top.
fn plant_in_the_bench(contact: SoilContactIntegration) -> Plant {
    let mut sc = Scenario::default_bench().unwrap();
    sc.soil_contact = contact;
    sc.start.boom_deg = 28.0;
    sc.start.stick_deg = (-1.3135f64).to_degrees();
    sc.start.bucket_deg = (-0.482f64).to_degrees();
    let p = Plant::new(
        &MachineConfig::default_machine().unwrap(),
        &sc,
        EffectSet::nominal(),
    )
    .unwrap();
    let ts = p.true_state();
    let depth = p.world.height(ts.tip_world[0], ts.tip_world[1]) - ts.tip_world[2];
    assert!((0.8..1.0).contains(&depth), "tip depth {depth} m");
    p
}

#[test]
fn reported_rate_agrees_with_the_motion_of_a_cylinder_stalled_in_the_bench() {
    stalled_cylinder_rates_agree(SoilContactIntegration::default());
}

#[test]
#[ignore = "known issue of the held plant (plant version held-1, kept to reproduce results made on \
            it): the 200 Hz held soil force makes a stalled cylinder chatter with a 10-step period, \
            aliased by the 100 Hz sensor sampling into a steady rate without motion; the default \
            implicit plant passes (previous test)"]
fn reported_rate_agrees_with_the_motion_of_a_cylinder_stalled_in_the_bench_with_held_contact() {
    stalled_cylinder_rates_agree(SoilContactIntegration::Held);
}

fn stalled_cylinder_rates_agree(contact: SoilContactIntegration) {
    let mut p = plant_in_the_bench(contact);
    // Stick retract 24 %, bucket retract 42 % (the demo's commands), 2 s to settle.
    let cmd = [0.0, -0.24, -0.42, 0.0, 0.0, 0.0];
    for _ in 0..2000 {
        p.step(cmd);
    }
    // Then 3 s: integrate the joint rate as sampled at 100 Hz (every 10th physics step, as the
    // gateway does) and count the velocity sign changes of the cylinders per physics step.
    let q0 = p.sensed_truth().angles_rad;
    let mut integrated = [0.0; 2];
    let mut sign_changes = [0usize; 2];
    let mut last_v = [0.0f64; 2];
    for n in 1..=3000 {
        p.step(cmd);
        for (k, i) in [STICK, BUCKET].into_iter().enumerate() {
            let v = p.hydraulics.actuators[i].velocity;
            if v * last_v[k] < 0.0 {
                sign_changes[k] += 1;
            }
            last_v[k] = v;
        }
        if n % 10 == 0 {
            let rates = p.sensed_truth().rates_rad_per_s;
            integrated[0] += rates[1] * 0.01;
            integrated[1] += rates[2] * 0.01;
        }
    }
    let q1 = p.sensed_truth().angles_rad;
    let moved = [q1[1] - q0[1], q1[2] - q0[2]];
    println!(
        "3 s: stick moved {:+.4} rad, sampled rate integrates to {:+.4} rad, {} sign changes; \
         bucket moved {:+.4} rad, sampled rate integrates to {:+.4} rad, {} sign changes",
        moved[0], integrated[0], sign_changes[0], moved[1], integrated[1], sign_changes[1]
    );
    for k in 0..2 {
        assert!(
            (integrated[k] - moved[k]).abs() <= 0.05 + 0.2 * moved[k].abs(),
            "joint {k}: the sampled rate integrates to {} rad, the joint moved {} rad",
            integrated[k],
            moved[k]
        );
        assert!(
            sign_changes[k] < 30,
            "joint {k}: the velocity changed sign {} times in 3000 steps",
            sign_changes[k]
        );
    }
}

/// Whatever holds a cylinder stopped in the soil must not hold one driven out of it: stalled deep in
/// the bench as above, the boom raised at 60 % lifts the bucket out of the cut (a static hold of the
/// last resistance, and a hold by the soil's full resistance to upward travel, kept it there:
/// docs/simulator.md, "Known issues").
#[test]
fn a_bucket_stalled_in_the_bench_comes_out_when_the_boom_lifts() {
    stalled_bucket_comes_out(SoilContactIntegration::default());
}

#[test]
fn a_bucket_stalled_in_the_bench_comes_out_when_the_boom_lifts_with_held_contact() {
    stalled_bucket_comes_out(SoilContactIntegration::Held);
}

fn stalled_bucket_comes_out(contact: SoilContactIntegration) {
    let mut p = plant_in_the_bench(contact);
    let stall = [0.0, -0.24, -0.42, 0.0, 0.0, 0.0];
    for _ in 0..2000 {
        p.step(stall);
    }
    let (q0, z0) = (p.sensed_truth().angles_rad, p.true_state().tip_world[2]);
    let lift = [0.6, -0.24, -0.42, 0.0, 0.0, 0.0];
    for _ in 0..4000 {
        p.step(lift);
    }
    let (q1, z1) = (p.sensed_truth().angles_rad, p.true_state().tip_world[2]);
    println!(
        "4 s of boom raise: boom {:+.3} rad, tip {:+.3} m",
        q1[0] - q0[0],
        z1 - z0
    );
    // The edge started ~0.9 m under the bench top.
    assert!(z1 - z0 > 1.0, "the tip rose {} m", z1 - z0);
}

/// The soil's force must follow the edge's motion, not ring: driven through the bench from the
/// stalled pose above (the stick pulled in; the boom lowered with the bucket curling), the force of
/// one physics step may differ from the last by more than 200 kN a few times at most.
///
/// The FEE wedge forms ahead of the edge on the side it travels (Fig. 25, Eq. 18). If the whole
/// wedge sat on the side of `sign(vx)`, the force would turn over in a step at `vx = 0`, and an
/// implicit step linearised at its start would overshoot every turn of the travel, ringing at about
/// 100 Hz with swings of several hundred kN. The default plant blends the two sides by the travel's
/// direction and solves a step again where the force at its end misses the linearisation
/// (docs/simulator.md, "Soil contact integration").
#[test]
fn the_soil_force_follows_an_edge_driven_through_the_bench() {
    for (what, cmd) in [
        ("stick pulled in", [0.0, -0.5, 0.0, 0.0, 0.0, 0.0]),
        (
            "boom lowered, bucket curling",
            [-0.3, 0.0, -0.6, 0.0, 0.0, 0.0],
        ),
    ] {
        let mut p = plant_in_the_bench(SoilContactIntegration::default());
        let mut jumps = 0;
        let mut last = p.true_state().soil_force_n;
        for _ in 0..3000 {
            p.step(cmd);
            let f = p.true_state().soil_force_n;
            if (f[0] - last[0]).hypot(f[1] - last[1]) > 2.0e5 {
                jumps += 1;
            }
            last = f;
        }
        println!("{what}: {jumps} steps of 3000 changed the soil force by more than 200 kN");
        assert!(
            jumps < 10,
            "{what}: {jumps} force jumps over 200 kN in 3000 steps"
        );
    }
}
