//! The default plant's behaviour fingerprint for [`vcan_sim::PLANT_VERSION`].
//!
//! A scripted dig on the default bench (`config/bench.toml`, default machine, no effects): lower the
//! boom into the bench, pull the stick in with the bucket curling, then curl and lift out. The joint
//! angles and the bucket's content every 0.5 s are pinned below. A change to the physics that moves
//! them beyond the tolerances (a few mrad, a few kg: far above rounding, well below what changes a
//! calibration) fails this test: bump `PLANT_VERSION`, pin the new fingerprint this test prints, and
//! run `excavator-ctl calibrate --install` so the shipped artefacts are fitted on the new plant
//! (`calibration/tests/shipped.rs` checks their recorded plant version).
//!
//! `cargo test -p vcan_sim --test plant_version -- --nocapture` prints the fingerprint.

// Test helpers panic on setup failure by design (clippy only exempts `#[test]` bodies).
#![allow(clippy::unwrap_used)]

use planner::machine::MachineConfig;
use vcan_sim::effects::EffectSet;
use vcan_sim::plant::Plant;
use vcan_sim::scenario::{Scenario, SoilContactIntegration};

/// One sample of the fingerprint: time (s), `[boom, stick, bucket]` angles (rad), bucket content (kg).
type Sample = (f64, [f64; 3], f64);

/// The scripted valve commands `[boom, stick, bucket, swing, left, right]` at time `t_s`.
fn script(t_s: f64) -> [f64; 6] {
    match t_s {
        t if t < 1.5 => [-0.6, 0.3, 0.0, 0.0, 0.0, 0.0],
        t if t < 4.5 => [-0.1, 0.8, 0.3, 0.0, 0.0, 0.0],
        t if t < 6.5 => [0.7, 0.2, 0.8, 0.0, 0.0, 0.0],
        _ => [0.0; 6],
    }
}

/// Runs the script on the default plant (with `contact` instead of its soil contact integration) for
/// 7.5 s and samples it every 0.5 s.
fn fingerprint(contact: Option<SoilContactIntegration>) -> Vec<Sample> {
    let mut scenario = Scenario::default_bench().unwrap();
    if let Some(c) = contact {
        scenario.soil_contact = c;
    }
    let mut plant = Plant::new(
        &MachineConfig::default_machine().unwrap(),
        &scenario,
        EffectSet::nominal(),
    )
    .unwrap();
    let mut samples = Vec::new();
    for step in 1..=7500 {
        let t_s = f64::from(step) * 1e-3;
        plant.step(script(t_s));
        if step % 500 == 0 {
            let s = plant.true_state();
            samples.push((
                t_s,
                [s.angles_rad[0], s.angles_rad[1], s.angles_rad[2]],
                s.payload_kg,
            ));
        }
    }
    samples
}

/// The fingerprint of [`vcan_sim::PLANT_VERSION`].
const PINNED: &[Sample] = &[
    (0.5, [0.6176, -1.3110, -1.0468], 0.0),
    (1.0, [0.5129, -1.3456, -1.0681], 222.2),
    (1.5, [0.5130, -1.3481, -1.0643], 222.2),
    (2.0, [0.5184, -1.3843, -1.0151], 222.2),
    (2.5, [0.5217, -1.3974, -0.9940], 222.2),
    (3.0, [0.4949, -1.4801, -1.0476], 937.4),
    (3.5, [0.4677, -1.6100, -1.0539], 2354.4),
    (4.0, [0.4385, -1.6903, -0.9983], 2550.0),
    (4.5, [0.4218, -1.7004, -1.0022], 2550.0),
    (5.0, [0.4444, -1.7117, -1.0499], 2550.0),
    (5.5, [0.5670, -1.7652, -1.6459], 2550.0),
    (6.0, [0.5157, -1.8283, -2.2430], 2550.0),
    (6.5, [0.6076, -1.8713, -2.4607], 2550.0),
    (7.0, [0.6404, -1.8922, -2.4607], 2550.0),
    (7.5, [0.6205, -1.8919, -2.4607], 2550.0),
];

/// Angle tolerance, rad.
const ANGLE_TOLERANCE_RAD: f64 = 0.005;
/// Content tolerance: the larger of this many kg and [`CONTENT_TOLERANCE_FRACTION`] of the content.
const CONTENT_TOLERANCE_KG: f64 = 10.0;
/// Content tolerance as a fraction of the content.
const CONTENT_TOLERANCE_FRACTION: f64 = 0.02;

/// The first sample where `now` departs from [`PINNED`] beyond the tolerances, as a message.
fn departure(now: &[Sample]) -> Option<String> {
    if now.len() != PINNED.len() {
        return Some(format!("{} samples, pinned {}", now.len(), PINNED.len()));
    }
    now.iter().zip(PINNED).find_map(|(got, want)| {
        let content_tolerance = CONTENT_TOLERANCE_KG.max(CONTENT_TOLERANCE_FRACTION * want.2);
        let moved = (0..3).any(|k| (got.1[k] - want.1[k]).abs() > ANGLE_TOLERANCE_RAD)
            || (got.2 - want.2).abs() > content_tolerance;
        moved.then(|| {
            format!(
                "at {} s {:?} rad and {} kg, pinned {:?} rad and {} kg",
                got.0, got.1, got.2, want.1, want.2
            )
        })
    })
}

#[test]
fn the_default_plant_behaves_as_its_version_pinned() {
    let now = fingerprint(None);
    let printed: Vec<String> = now
        .iter()
        .map(|(t, q, m)| {
            format!(
                "    ({t:.1}, [{:.4}, {:.4}, {:.4}], {m:.1}),",
                q[0], q[1], q[2]
            )
        })
        .collect();
    println!(
        "fingerprint of this build's default plant:\n{}",
        printed.join("\n")
    );
    assert!(
        now.iter().any(|s| s.2 > 100.0),
        "the script no longer digs: {now:?}"
    );
    if let Some(d) = departure(&now) {
        panic!(
            "the default plant no longer behaves as plant version {} pinned it: {d}. Bump \
             vcan_sim::PLANT_VERSION, pin the fingerprint printed above, and run `excavator-ctl \
             calibrate --install config`.",
            vcan_sim::PLANT_VERSION
        );
    }
}

/// The fingerprint is sensitive to a change that matters to the calibrations: the other soil
/// contact integration departs from it.
#[test]
fn the_other_soil_contact_departs_from_the_fingerprint() {
    let default = Scenario::default_bench().unwrap().soil_contact;
    let other = match default {
        SoilContactIntegration::Held => SoilContactIntegration::Implicit,
        SoilContactIntegration::Implicit => SoilContactIntegration::Held,
    };
    let d = departure(&fingerprint(Some(other)));
    println!("{other:?}: {d:?}");
    assert!(d.is_some(), "{other:?} behaves as the default plant");
}
