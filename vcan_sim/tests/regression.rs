//! Regression guard for performance work: fixed scripted runs (a dig into the bench with spill, a lift,
//! a swing, a dump in the air, a drive) must end in the same state as the simulator did before the
//! optimisations of the hot paths (hydraulics, linkage, soil contact, spill deposits, sensors, frames).
//!
//! The reference values were recorded with the code before those optimisations (commit 5cd7051 plus the
//! bench `--case` option). Print the current values with
//! `REGRESSION_PRINT=1 cargo test -p vcan_sim --test regression -- --nocapture`.

// Test helpers panic on setup failure by design (clippy only exempts `#[test]` bodies).
#![allow(clippy::unwrap_used)]

use firmware_bridge::messages::{
    AuxValveCommand, ControllerHeartbeat, Message, RequestedMode, Valve,
};
use firmware_bridge::transport::{InProcessBus, VirtualClock};
use vcan_sim::SimConfig;
use vcan_sim::embedded::EmbeddedMachine;
use vcan_sim::plant::Plant;
use vcan_sim::sensors::SensorReadings;

/// Relative tolerance on each recorded quantity (absolute floor [`ABS_FLOOR`] in its unit). The
/// hydraulic solvers stop at 10 Pa steps, so rounding-level changes upstream can move a pressure by a
/// few Pa; positions and masses are far tighter than this.
const REL_TOLERANCE: f64 = 1e-6;
/// Absolute floor for quantities near zero (m, rad, Pa, kg, N: all far below anything physical).
const ABS_FLOOR: f64 = 1e-6;

/// The command script: `(seconds, [boom, stick, bucket, swing, left track, right track])`.
const SCRIPT: [(f64, [f64; 6]); 7] = [
    (1.5, [-1.0, 0.0, 0.0, 0.0, 0.0, 0.0]), // boom down into the bench top
    (4.0, [-0.15, 0.8, 0.25, 0.0, 0.0, 0.0]), // drag: stick in, slow curl; fills and spills
    (2.0, [0.8, 0.0, 1.0, 0.0, 0.0, 0.0]),  // capture: curl and lift
    (2.0, [0.3, 0.0, 0.0, 0.6, 0.0, 0.0]),  // swing toward the spoil side
    (2.5, [0.0, -0.5, -1.0, 0.0, 0.0, 0.0]), // dump in the air
    (1.0, [0.0, 0.0, 0.0, 0.0, 0.6, 0.4]),  // drive, turning
    (0.5, [0.0; 6]),                        // settle
];

/// Hidden effects for the second run (every code path of the hydraulic and sensor effects).
const EFFECTS: [&str; 9] = [
    "valve_deadband=0.05",
    "hydraulic_lag=0.05",
    "flow_sharing=0.3",
    "coulomb_friction=2000",
    "viscous_friction=1e5",
    "internal_leakage=2e-12",
    "pressure_sensor_offset=1e5",
    "resolver_offset=0.01",
    "soil_cohesion=5000",
];

/// The named quantities compared at the end of a run.
fn summary(plant: &Plant, last: &SensorReadings) -> Vec<(&'static str, f64)> {
    let s = plant.true_state();
    let ledger = plant.mass_ledger();
    let terrain = &plant.world.terrain;
    let mut out = vec![
        ("time_s", s.time_s),
        ("boom_rad", s.angles_rad[0]),
        ("stick_rad", s.angles_rad[1]),
        ("bucket_rad", s.angles_rad[2]),
        ("swing_rad", s.angles_rad[3]),
        ("ext_boom_m", s.extensions_m[0]),
        ("ext_stick_m", s.extensions_m[1]),
        ("ext_bucket_m", s.extensions_m[2]),
        ("head_boom_pa", s.head_pa[0]),
        ("head_stick_pa", s.head_pa[1]),
        ("head_bucket_pa", s.head_pa[2]),
        ("rod_boom_pa", s.rod_pa[0]),
        ("rod_stick_pa", s.rod_pa[1]),
        ("rod_bucket_pa", s.rod_pa[2]),
        ("pump1_pa", s.pump_pa[0]),
        ("pump2_pa", s.pump_pa[1]),
        ("pose_x_m", s.pose[0]),
        ("pose_y_m", s.pose[1]),
        ("heading_rad", s.pose[2]),
        ("tip_x_m", s.tip_world[0]),
        ("tip_y_m", s.tip_world[1]),
        ("tip_z_m", s.tip_world[2]),
        ("payload_kg", s.payload_kg),
        ("removed_kg", ledger.removed_kg),
        ("spilled_kg", ledger.spilled_kg),
        ("deposited_m3", ledger.deposited_m3),
        ("terrain_above_0_m3", terrain.volume_above(0.0)),
        ("terrain_above_1_m3", terrain.volume_above(1.0)),
    ];
    let sensed = [
        ("sensed_boom_rad", last.angles_rad[0]),
        ("sensed_stick_rad", last.angles_rad[1]),
        ("sensed_head_boom_pa", last.head_pa[0]),
        ("sensed_pump2_pa", last.pump_pa[1]),
        ("sensed_left_odometry_m", last.odometry_m[0]),
    ];
    out.extend(sensed);
    out
}

/// Runs the script on the default machine and bench (seed 1) with the given effects, reading the
/// sensors every 10 ms as the node does, and returns the summary.
fn scripted_run(effects: &[&str]) -> Vec<(&'static str, f64)> {
    let cfg = SimConfig::load(None, None, Some(1), effects).unwrap();
    let mut plant = cfg.build().unwrap();
    let mut last = SensorReadings::default();
    let mut step = 0u64;
    for (seconds, commands) in SCRIPT {
        for _ in 0..(seconds * 1000.0).round() as u64 {
            if step.is_multiple_of(10) {
                last = plant.read_sensors();
            }
            plant.step(commands);
            step += 1;
        }
    }
    summary(&plant, &last)
}

fn check(name: &str, got: &[(&'static str, f64)], expected: &[(&str, f64)]) {
    if std::env::var_os("REGRESSION_PRINT").is_some() {
        println!("const {name}: [(&str, f64); {}] = [", got.len());
        for (k, v) in got {
            println!("    (\"{k}\", {v:?}),");
        }
        println!("];");
    }
    assert_eq!(got.len(), expected.len(), "{name}: number of quantities");
    let mut failures = Vec::new();
    for ((k, v), (ek, ev)) in got.iter().zip(expected) {
        assert_eq!(k, ek, "{name}: quantity order");
        let tol = REL_TOLERANCE * ev.abs() + ABS_FLOOR;
        if (v - ev).abs() > tol || !v.is_finite() {
            failures.push(format!("{k}: {v:?} vs recorded {ev:?} (tolerance {tol:e})"));
        }
    }
    assert!(failures.is_empty(), "{name}:\n{}", failures.join("\n"));
}

#[test]
fn scripted_dig_ends_in_the_recorded_state() {
    let got = scripted_run(&[]);
    // The script really digs, spills and dumps.
    let value = |k: &str| got.iter().find(|(n, _)| *n == k).map(|(_, v)| *v);
    assert!(value("removed_kg").unwrap() > 500.0, "{got:?}");
    assert!(value("deposited_m3").unwrap() > 0.0, "{got:?}");
    check("NOMINAL", &got, &NOMINAL);
}

#[test]
fn scripted_dig_with_hidden_effects_ends_in_the_recorded_state() {
    check("WITH_EFFECTS", &scripted_run(&EFFECTS), &WITH_EFFECTS);
}

fn heartbeat(alive: u8) -> firmware_bridge::CanFrame {
    ControllerHeartbeat {
        mode: RequestedMode::ArmValve,
        alive_counter: alive % 16,
    }
    .to_frame()
    .unwrap()
}

fn command(valve: Valve, u: f64) -> firmware_bridge::CanFrame {
    Message::AuxValveCommand(AuxValveCommand::from_fraction(valve, u).unwrap())
        .encode()
        .unwrap()
}

/// The embedded machine (gateway, plant, sensor frames) under a scripted controller: it sends as many
/// frames as before, with the same decoded angles and pressures (sums over the run, within a few
/// quanta of the signal encoding).
#[test]
fn scripted_embedded_run_sends_the_recorded_frames() {
    let clock = VirtualClock::new();
    let bus = InProcessBus::with_virtual_clock("sim0", clock.clone());
    let controller = bus.attach();
    let cfg = SimConfig::load::<&str>(None, None, Some(5), &[]).unwrap();
    let mut machine = EmbeddedMachine::new(cfg.build().unwrap(), bus.attach(), Some(clock));
    let (mut count, mut boom_sum, mut pump_sum) = (0u64, 0.0, 0.0);
    for k in 0..300u32 {
        controller.send(heartbeat(k as u8)).unwrap();
        let u = if k < 150 { 0.6 } else { -0.4 };
        controller.send(command(Valve::Boom, u)).unwrap();
        controller.send(command(Valve::Stick, -u)).unwrap();
        machine.advance(0.01);
        while let Some(f) = controller.try_recv() {
            count += 1;
            match Message::decode(&f.frame).map(|d| d.message) {
                Ok(Message::JointAngles(a)) => boom_sum += a.boom_rad,
                Ok(Message::PumpPressures(p)) => pump_sum += p.pump1_pa + p.pump2_pa,
                _ => {}
            }
        }
    }
    let s = machine.plant().true_state();
    if std::env::var_os("REGRESSION_PRINT").is_some() {
        println!(
            "const EMBEDDED: (u64, f64, f64, f64, f64) = ({count}, {boom_sum:?}, {pump_sum:?}, {:?}, {:?});",
            s.angles_rad[0], s.angles_rad[1]
        );
    }
    let (frames, boom, pumps, boom_end, stick_end) = EMBEDDED;
    assert_eq!(count, frames);
    assert!((boom_sum - boom).abs() < 1e-3, "{boom_sum} vs {boom}");
    assert!(
        (pump_sum - pumps).abs() < 1e-6 * pumps + 1e5,
        "{pump_sum} vs {pumps}"
    );
    assert!((s.angles_rad[0] - boom_end).abs() < 1e-6);
    assert!((s.angles_rad[1] - stick_end).abs() < 1e-6);
}

const EMBEDDED: (u64, f64, f64, f64, f64) = (
    1920,
    226.8432999999999,
    6018687000.0,
    0.5844107168435657,
    -1.242342918535866,
);

const NOMINAL: [(&str, f64); 33] = [
    ("time_s", 13.499999999997957),
    ("boom_rad", 0.8391406923290096),
    ("stick_rad", -1.4619303457531876),
    ("bucket_rad", 0.6929985544736388),
    ("swing_rad", 1.3109514239004567),
    ("ext_boom_m", 1.1937111086237397),
    ("ext_stick_m", 0.6305000521145624),
    ("ext_bucket_m", 0.0),
    ("head_boom_pa", 24526400.00397652),
    ("head_stick_pa", 426757.5415669837),
    ("head_bucket_pa", 300000.0),
    ("rod_boom_pa", 15313302.515173698),
    ("rod_stick_pa", 6630199.308901336),
    ("rod_bucket_pa", 34741838.02596605),
    ("pump1_pa", 4680503.9608303225),
    ("pump2_pa", 4680312.405727303),
    ("pose_x_m", 0.6553006774104974),
    ("pose_y_m", -0.03607360981167157),
    ("heading_rad", -0.10989510896870328),
    ("tip_x_m", 3.4957021744217003),
    ("tip_y_m", 7.292782593423789),
    ("tip_z_m", 4.654842128142055),
    ("payload_kg", 0.0),
    ("removed_kg", 1923.0438728243723),
    ("spilled_kg", 1923.0438728243726),
    ("deposited_m3", 1.131202278131983),
    ("terrain_above_0_m3", 179.99999999999966),
    ("terrain_above_1_m3", 84.28879772186806),
    ("sensed_boom_rad", 0.8390874909734457),
    ("sensed_stick_rad", -1.4615001956580445),
    ("sensed_head_boom_pa", 24383902.9011907),
    ("sensed_pump2_pa", 4674417.103257719),
    ("sensed_left_odometry_m", 0.784),
];
const WITH_EFFECTS: [(&str, f64); 33] = [
    ("time_s", 13.499999999997957),
    ("boom_rad", 0.9548013155119359),
    ("stick_rad", -1.9799420532584309),
    ("bucket_rad", 0.6896517670854811),
    ("swing_rad", 1.1759991699596581),
    ("ext_boom_m", 1.2392973518161736),
    ("ext_stick_m", 1.0621555497715267),
    ("ext_bucket_m", 0.001419286132383056),
    ("head_boom_pa", 15415813.371251853),
    ("head_stick_pa", 298977.43164159986),
    ("head_bucket_pa", 12225098.504883002),
    ("rod_boom_pa", 3682014.827079237),
    ("rod_stick_pa", 5106074.173253173),
    ("rod_bucket_pa", 26963273.35209132),
    ("pump1_pa", 4680663.162245611),
    ("pump2_pa", 4680377.7232004935),
    ("pose_x_m", 0.5749323097323733),
    ("pose_y_m", -0.030849235745391997),
    ("heading_rad", -0.10711944346150397),
    ("tip_x_m", 3.6610901027602543),
    ("tip_y_m", 5.592680644585669),
    ("tip_z_m", 3.67960471697603),
    ("payload_kg", 0.0),
    ("removed_kg", 24.51440494110521),
    ("spilled_kg", 24.51440494110521),
    ("deposited_m3", 0.014420238200650122),
    ("terrain_above_0_m3", 180.00000000000014),
    ("terrain_above_1_m3", 84.98557976179927),
    ("sensed_boom_rad", 0.9644904203830968),
    ("sensed_stick_rad", -1.9696313316451635),
    ("sensed_head_boom_pa", 15482353.624389892),
    ("sensed_pump2_pa", 4774486.939987544),
    ("sensed_left_odometry_m", 0.7000000000000001),
];
