//! The controller's time base: the run loop ages sensors and times faults on the monotonic clock
//! (tokio's, paused here), never on the bus's clock, which is the wall clock on a machine and stamps
//! the frames and the trace. A wall-clock step (NTP) of an hour therefore neither raises a false
//! stale-sensor fault while the gateway keeps sending nor hides the stale sensor when it stops.

#![allow(clippy::unwrap_used)]

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use controller::io::run::{LoopSession, run_session_loop};
use controller::io::scan_client::NoScans;
use controller::session::driver::SessionDriver;
use controller::step::safety::Fault;
use controller::{ControllerConfig, ControllerNode};
use firmware_bridge::dbc::CONTROL_PERIOD;
use firmware_bridge::messages::{
    AuxValveMeasured, Cylinder, GatewayFaults, GatewayMode, GatewayStatus, JointAngles, JointRates,
    Message, ValveState,
};
use firmware_bridge::transport::{InProcessBus, InProcessNode, TimeScale, VirtualClock};
use planner::autodig::AutodigMaps;
use planner::machine::MachineConfig;

/// An hour, ns.
const HOUR_NS: u64 = 3_600_000_000_000;
/// Control steps of the test (3 s).
const STEPS: usize = 300;
/// Steps at which the wall clock steps forward by an hour.
const WALL_STEPS: [usize; 2] = [100, 200];
/// Step from which the gateway stops sending its control signals (its status goes on).
const SENSORS_STOP: usize = 200;

/// A gateway that sends the control signals every 10 ms (angles at the start pose, zero rates, the
/// three cylinders' pressures) while `sensors` is set, and its status every 50 ms (Disarmed, the
/// alive counter advancing), until `stop`.
async fn gateway(bus: InProcessNode, sensors: Arc<AtomicBool>, stop: Arc<AtomicBool>) {
    let mut alive = 0_u8;
    let mut k = 0_u32;
    let mut tick = tokio::time::interval(Duration::from_millis(10));
    while !stop.load(Ordering::Relaxed) {
        tick.tick().await;
        let mut out = Vec::new();
        if sensors.load(Ordering::Relaxed) {
            out.push(Message::JointAngles(JointAngles {
                boom_rad: 41_f64.to_radians(),
                stick_rad: (-71_f64).to_radians(),
                bucket_rad: (-60_f64).to_radians(),
                swing_rad: 0.0,
            }));
            out.push(Message::JointRates(JointRates {
                boom_rad_per_s: 0.0,
                stick_rad_per_s: 0.0,
                bucket_rad_per_s: 0.0,
                swing_rad_per_s: 0.0,
            }));
            for cylinder in [Cylinder::Boom, Cylinder::Stick, Cylinder::Bucket] {
                out.push(Message::AuxValveMeasured(AuxValveMeasured {
                    cylinder,
                    flow_percent: 0.0,
                    state: ValveState::Block,
                    head_pressure_pa: 2e6,
                    rod_pressure_pa: 2e6,
                }));
            }
        }
        if k.is_multiple_of(5) {
            alive = (alive + 1) % 16;
            out.push(Message::GatewayStatus(GatewayStatus {
                mode: GatewayMode::Disarmed,
                faults: GatewayFaults::default(),
                alive_counter: alive,
                unexpected_frames: 0,
                rejected_frames: 0,
            }));
        }
        k += 1;
        for m in out {
            bus.send(m.encode().unwrap()).unwrap();
        }
    }
}

#[tokio::test(start_paused = true)]
async fn a_wall_clock_step_neither_hides_a_stale_sensor_nor_raises_a_false_fault() {
    let wall = VirtualClock::new();
    wall.set_ns(1_750_000_000 * 1_000_000_000);
    let bus = InProcessBus::with_virtual_clock("test0", wall.clone());
    let ctl = bus.attach();
    let sensors = Arc::new(AtomicBool::new(true));
    let stop = Arc::new(AtomicBool::new(false));
    let gw = tokio::spawn(gateway(bus.attach(), sensors.clone(), stop.clone()));
    // Not started: the node stays disarmed and only judges the data (`Safety::health`).
    let mut node = ControllerNode::new(
        &MachineConfig::default_machine().unwrap(),
        AutodigMaps::builtin().unwrap(),
        ControllerConfig::default(),
    )
    .unwrap();
    let max_age_s = node.safety().config().sensor_max_age_s;
    let mut driver = SessionDriver::new(None, None, &mut node);
    let mut scans = NoScans::default();
    let mut health: Vec<Result<(), Fault>> = Vec::new();
    let mut observer = |node: &ControllerNode,
                        _: &SessionDriver,
                        _: &[controller::session::driver::SessionEvent]| {
        health.push(node.safety().health());
        let step = health.len();
        if WALL_STEPS.contains(&step) {
            wall.advance_ns(HOUR_NS);
        }
        if step == SENSORS_STOP {
            sensors.store(false, Ordering::Relaxed);
        }
        Ok(())
    };
    let shutdown = tokio::time::sleep(CONTROL_PERIOD * u32::try_from(STEPS).unwrap());
    run_session_loop(
        &ctl,
        &mut node,
        CONTROL_PERIOD,
        TimeScale::REAL_TIME,
        shutdown,
        Some(LoopSession {
            driver: &mut driver,
            scans: &mut scans,
            observer: &mut observer,
        }),
        None,
    )
    .await
    .unwrap();
    stop.store(true, Ordering::Relaxed);
    gw.await.unwrap();

    assert!(health.len() >= STEPS - 1, "{} steps", health.len());
    // Fresh data from the first status on, through the first wall-clock step: no false fault.
    let first_ok = health.iter().position(Result::is_ok).unwrap();
    assert!(first_ok < 10, "healthy only from step {first_ok}");
    for (i, h) in health.iter().enumerate().take(SENSORS_STOP).skip(first_ok) {
        assert!(
            h.is_ok(),
            "step {i}: {h:?} (wall-clock step at {WALL_STEPS:?})"
        );
    }
    // The sensors stop as the wall clock steps again: stale within the age limit plus a period,
    // and stale to the end.
    let limit = SENSORS_STOP + (max_age_s / CONTROL_PERIOD.as_secs_f64()).ceil() as usize + 2;
    let stale_from = health[SENSORS_STOP..]
        .iter()
        .position(|h| matches!(h, Err(Fault::StaleSensor { .. })))
        .map(|p| p + SENSORS_STOP)
        .unwrap_or_else(|| panic!("the stale sensors went unnoticed"));
    assert!(stale_from <= limit, "stale only from step {stale_from}");
    assert!(
        health[stale_from..]
            .iter()
            .all(|h| matches!(h, Err(Fault::StaleSensor { .. }))),
        "{:?}",
        &health[stale_from..]
    );
}
