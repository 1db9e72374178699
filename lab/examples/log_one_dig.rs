//! Stage-by-stage log of one dig: angles, pressures (MPa), commands, soil force and payload every
//! 0.1 s of Autodig. `DIG_X`, `DIG_Z`, `DIG_BUCKET` override the start pose, `DIG_FACE_X` the bench
//! face's toe.
//!
//! More variables: `DIG_SWING` (swing of the dig, deg), `DIG_SECOND` (a second dig at that swing),
//! `DIG_Q` (start joints `boom,stick,bucket`, deg), `DIG_H` (hardness index), `DIG_BETA`, `DIG_RHO1`,
//! `DIG_RHO2`, `DIG_RHO3` (deg), `DIG_BD` (Boom-Down command), `DIG_PLAIN` (no perception),
//! `DIG_CLEANUP` (the cleanup of the closed-loop tests, with `DIG_CL_*` for its settings),
//! `DIG_EFFECTS` (hidden effects, `;`-separated), `DIG_MAPS` (maps file), `DIG_QUIET`, `DIG_ALL`
//! (every phase), `DIG_DT` (log period, s).
//!
//! `cargo run -p lab --release --example log_one_dig`

#![allow(clippy::unwrap_used)] // A diagnostic: a bad variable or start should stop it loudly.

#[path = "../tests/common/mod.rs"]
mod common;

use common::{Loop, cleanup_setup, default_sim, floor_extremes, one_dig};
use controller::step::cycle::{Action, Phase, StartPose};

fn main() {
    let mut c = one_dig();
    let env = |k: &str, d: f64| {
        std::env::var(k)
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(d)
    };
    if std::env::var("DIG_X").is_ok() {
        c.cycle.actions = vec![Action::Dig {
            swing_rad: 0.0,
            start: StartPose::Tip {
                x_m: env("DIG_X", 7.0),
                z_m: env("DIG_Z", 2.8),
                bucket_abs_rad: env("DIG_BUCKET", -90.0).to_radians(),
            },
        }];
    }
    if let Ok(sw) = std::env::var("DIG_SWING") {
        let sw: f64 = sw.parse().unwrap();
        if let Some(Action::Dig { swing_rad, .. }) = c.cycle.actions.first_mut() {
            *swing_rad = sw.to_radians();
        }
    }
    if let Ok(sw) = std::env::var("DIG_SECOND") {
        let sw: f64 = sw.parse().unwrap();
        let mut second = c.cycle.actions[0];
        if let Action::Dig { swing_rad, .. } = &mut second {
            *swing_rad = sw.to_radians();
        }
        c.cycle.actions.push(second);
        c.cycle.max_digs = Some(2);
    }
    if std::env::var("DIG_Q").is_ok() {
        // boom, stick, bucket (deg) directly.
        let q: Vec<f64> = std::env::var("DIG_Q")
            .unwrap()
            .split(',')
            .map(|v| v.parse().unwrap())
            .collect();
        c.cycle.actions = vec![Action::Dig {
            swing_rad: 0.0,
            start: StartPose::Joints {
                boom_rad: q[0].to_radians(),
                stick_rad: q[1].to_radians(),
                bucket_rad: q[2].to_radians(),
            },
        }];
    }
    c.autodig.hardness_index = env("DIG_H", c.autodig.hardness_index);
    c.autodig.beta_rad = env("DIG_BETA", c.autodig.beta_rad.to_degrees()).to_radians();
    c.autodig.rho1_rad = env("DIG_RHO1", c.autodig.rho1_rad.to_degrees()).to_radians();
    c.autodig.rho2_rad = env("DIG_RHO2", c.autodig.rho2_rad.to_degrees()).to_radians();
    c.autodig.rho3_rad = env("DIG_RHO3", c.autodig.rho3_rad.to_degrees()).to_radians();
    c.autodig.boom_down_command = env("DIG_BD", c.autodig.boom_down_command);
    c.cycle.perception = std::env::var("DIG_PLAIN").is_err();
    let mut sim = default_sim();
    if std::env::var("DIG_CLEANUP").is_ok() {
        let (s, cc) = cleanup_setup();
        sim = s;
        c.cycle = cc.cycle;
        c.cleanup = cc.cleanup;
        c.cleanup.follow_clearance_m = env("DIG_CL_CLEAR", c.cleanup.follow_clearance_m);
        c.cleanup.follow_settle_s = env("DIG_CL_SETTLE", c.cleanup.follow_settle_s);
        c.cleanup.bucket_abs_rad =
            env("DIG_CL_BUCKET", c.cleanup.bucket_abs_rad.to_degrees()).to_radians();
        c.cleanup.probe_lag_m = env("DIG_CL_LAG", c.cleanup.probe_lag_m);
        c.cleanup.pressure_threshold_pct = env("DIG_CL_PCT", c.cleanup.pressure_threshold_pct);
        c.cleanup.pressure_hold_s = env("DIG_CL_HOLD", c.cleanup.pressure_hold_s);
        if let Some(Action::Cleanup { start, .. }) = c.cycle.actions.first_mut()
            && let StartPose::Tip { bucket_abs_rad, .. } = start
        {
            *bucket_abs_rad = c.cleanup.bucket_abs_rad;
        }
    }
    if let Ok(e) = std::env::var("DIG_EFFECTS") {
        let effects: Vec<&str> = e.split(';').collect();
        sim = vcan_sim::SimConfig::load::<&str>(None, None, Some(1), &effects).unwrap();
    }
    sim.scenario.bench.face_x_m = env("DIG_FACE_X", sim.scenario.bench.face_x_m);
    let maps = match std::env::var("DIG_MAPS") {
        Ok(p) => planner::autodig::AutodigMaps::from_toml_str(&std::fs::read_to_string(p).unwrap())
            .unwrap(),
        Err(_) => planner::autodig::AutodigMaps::builtin().unwrap(),
    };
    let quiet = std::env::var("DIG_QUIET").is_ok();
    let mut l = Loop::with_maps(sim, c, maps);
    let mut next = 0.0;
    l.run_until(60.0, |l| {
        let in_dig = matches!(l.phase(), Phase::Autodig | Phase::Weigh)
            || std::env::var("DIG_ALL").is_ok();
        if in_dig && !quiet && l.time_s() >= next {
            next = l.time_s() + env("DIG_DT", 0.1);
            if std::env::var("DIG_ALL").is_ok() {
                println!(
                    "phase {:?} swing {:.1} deg target action {:?}",
                    l.phase(),
                    l.node().state().swing_rad.to_degrees(),
                    l.node().action().map(|a| a.kind())
                );
            }
            let s = l.node().state();
            let t = l.machine().plant().true_state();
            let q = s.joints;
            let d = |r: f64| r.to_degrees();
            let ground = l.machine().plant().world.height(t.tip_world[0], t.tip_world[1]);
            println!(
                "{:6.2} {:>9} q=[{:6.1} {:6.1} {:6.1}] abs st {:6.1} bk {:6.1} tip=({:5.2},{:5.2}) gnd {:5.2} \
                 head=[{:4.1} {:4.1} {:4.1}] rod=[{:4.1} {:4.1} {:4.1}] ext=[{:.2} {:.2} {:.2}] cmd={:?} F=({:7.0},{:7.0}) pay {:5.0} est {:5.0} sw {:?}",
                l.time_s(),
                format!("{:?}", l.node().stage().map_or("-".into(), |s| format!("{s:?}"))),
                d(q.boom_rad),
                d(q.stick_rad),
                d(q.bucket_rad),
                d(q.boom_rad + q.stick_rad),
                d(q.boom_rad + q.stick_rad + q.bucket_rad),
                t.tip_world[0],
                t.tip_world[2],
                ground,
                s.head_pressure_pa[0] * 1e-6,
                s.head_pressure_pa[1] * 1e-6,
                s.head_pressure_pa[2] * 1e-6,
                s.rod_pressure_pa[0] * 1e-6,
                s.rod_pressure_pa[1] * 1e-6,
                s.rod_pressure_pa[2] * 1e-6,
                s.extension_fraction[0],
                s.extension_fraction[1],
                s.extension_fraction[2],
                match l.node().last_command() {
                    controller::step::cycle::CycleCommand::Valves(v) =>
                        format!("[{:.2} {:.2} {:.2}]", v[0], v[1], v[2]),
                    c => format!("{c:?}"),
                },
                t.soil_force_n[0],
                t.soil_force_n[1],
                t.payload_kg,
                l.node().estimator().payload_estimate_kg().unwrap_or(f64::NAN),
                l.node().cycle().swept_volume_m3(),
            );
        }
        if std::env::var("DIG_SECOND").is_ok() {
            return l.node().statistics().len() >= 2 || l.node().finished();
        }
        l.phase() == Phase::SwingToDump
    });
    let t = l.machine().plant().true_state();
    l.run_until(60.0, |l| !l.node().statistics().is_empty());
    println!(
        "payload {:.0} kg, phase {:?}, last fault {:?}, stats {:?}",
        t.payload_kg,
        l.phase(),
        l.node().last_fault(),
        l.node().statistics()
    );
    if std::env::var("DIG_CLEANUP").is_ok() {
        l.run_until(120.0, |l| l.node().finished());
        let (lowest, highest) = floor_extremes(&l);
        println!(
            "CLEANUP hand_over {:?} floor {:?} lowest {lowest:.3} highest {highest:.3}",
            l.node().statistics().first().and_then(|d| d.hand_over),
            l.node().statistics().first().and_then(|d| d.floor_z_m),
        );
    }
    let d = l.node().statistics().first().copied();
    if let Some(d) = d {
        println!(
            "SUMMARY payload_kg {:.0} time_s {:.2} energy_kj {:.0} swept {:.2} end {:?}",
            t.payload_kg,
            d.time_s,
            d.energy_kj(),
            d.swept_volume_m3,
            d.end_reason
        );
    }
}
