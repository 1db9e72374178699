//! The HIL scenarios over the in-process bus in virtual time (no vcan, no VM): the same plan, the same
//! analysis of the recorded bus, the same faults as the vcan tests (`dig_cycle.rs`, `faults.rs`), so a
//! machine without vcan or qemu still covers the logic. Deterministic for the seed.

#![allow(clippy::unwrap_used)]

use controller::io::run::LoopMonitor;
use firmware_bridge::messages::{
    Activity, AutodigStageCode, AuxValveCommand, GatewayFaults, GatewayMode, Message, Valve,
};
use firmware_bridge::{CanFrame, CanId};
use hil_tests::analysis::{
    activity_sequence, compare_angles, controller_statuses, count_cycles, gateway_statuses,
    heartbeats, joint_angles,
};
use hil_tests::inprocess::{PERIOD_S, Session};
use hil_tests::plan::{PLAN_CLEANUPS, PLAN_DIGS, plan_config};
use vcan_sim::scenario::SoilContactIntegration;

const SEED: u64 = 1;
/// Simulation time allowed for the whole plan, s.
const PLAN_LIMIT_S: f64 = 900.0;
/// The gateway's heartbeat watchdog, s, plus one physics step.
const WATCHDOG_S: f64 = 0.100 + 0.001 + 1e-9;
/// Most a joint may move in the second second after the valves went neutral, rad.
const REST_MOTION_RAD: f64 = 0.005;

/// True while Autodig is in the soil (Pre-Dig or Dig).
fn digging(s: &Session) -> bool {
    matches!(
        s.node().stage(),
        Some(planner::autodig::Stage::PreDig | planner::autodig::Stage::Dig)
    )
}

#[test]
fn three_dig_cycles_and_a_cleanup_complete() {
    let mut s = Session::new(plan_config(), SEED);
    let finished = s.run_until(PLAN_LIMIT_S, |s| s.node().finished());
    let statuses = controller_statuses(&s.record);
    let seq = activity_sequence(&statuses);
    let cycles = count_cycles(&seq);
    let mut fault = 0;
    for (t, st) in &statuses {
        if st.fault_reason != fault {
            fault = st.fault_reason;
            eprintln!("{t:.2} s: fault code {fault} during {:?}", st.activity);
        }
    }
    eprintln!(
        "plan: finished {finished} after {:.1} s simulated; cycles {cycles:?}; scans {}; digs {:?}",
        s.time_s(),
        s.scans,
        s.node()
            .statistics()
            .iter()
            .map(|d| (d.action, d.time_s, d.end_reason))
            .collect::<Vec<_>>()
    );
    assert!(
        finished,
        "plan not finished; last fault {:?}; sequence {seq:?}",
        s.node().last_fault()
    );
    assert!(cycles.digs >= PLAN_DIGS, "{cycles:?} in {seq:?}");
    assert!(cycles.cleanups >= PLAN_CLEANUPS, "{cycles:?} in {seq:?}");
    assert_eq!(cycles.returns_home, 1, "{seq:?}");
    assert_eq!(s.node().statistics().len(), PLAN_DIGS + PLAN_CLEANUPS);
    assert!(
        s.node()
            .statistics()
            .iter()
            .any(|d| d.action == controller::step::cycle::ActionKind::Cleanup)
    );
    assert!(s.scans >= 4, "each dig asked for a scan");
    // After the plan the gateway is disarmed.
    s.run_until(1.0, |_| false);
    assert_eq!(s.machine().node().gateway().mode(), GatewayMode::Disarmed);
}

#[test]
fn decoded_angles_match_the_state_log() {
    let mut s = Session::new(plan_config(), SEED);
    // Long enough to cover swinging and digging.
    s.run_until(40.0, |_| false);
    let decoded = joint_angles(&s.record);
    let cmp = compare_angles(&decoded, &s.truth, 0.0, 10.0, 0.0);
    eprintln!(
        "compared {} (burst {}), offsets {:?}, max error {:?} rad",
        cmp.compared, cmp.burst, cmp.offsets_s, cmp.max_error_rad
    );
    assert!(cmp.compared > 3500, "{}", cmp.compared);
    assert!(
        cmp.outside.is_empty(),
        "{} samples outside; first {:?}",
        cmp.outside.len(),
        cmp.outside.first()
    );
    for o in &cmp.offsets_s {
        // The truth is logged at the end of the period in which the frame was sent.
        assert!(o.abs() <= PERIOD_S + 1e-9, "offset {o}");
    }
}

#[test]
fn killed_controller_gateway_neutralises_within_100_ms() {
    // The chatter-free soil contact: with the `held` one a bucket stalled deep in the soil creeps
    // after the valves close (the contact chatter of `vcan_sim/tests/soil_chatter.rs`), which would
    // hide whether the machine comes to rest once the gateway neutralised its valves.
    let mut s = Session::with_soil_contact(plan_config(), SEED, SoilContactIntegration::Implicit);
    assert!(s.run_until(120.0, digging), "never reached Autodig's Dig");
    // Let it dig a little so the valves are open.
    s.run_until(0.3, |_| false);
    assert!(
        s.machine()
            .node()
            .valve_commands()
            .iter()
            .any(|u| *u != 0.0),
        "the gateway drives nothing mid-dig"
    );
    s.kill_controller();
    let last_hb = heartbeats(&s.record).last().unwrap().0;
    let mut neutral_at = None;
    while s.time_s() < last_hb + 0.5 {
        s.advance_machine(0.001);
        if neutral_at.is_none()
            && s.machine()
                .node()
                .valve_commands()
                .iter()
                .all(|u| *u == 0.0)
        {
            neutral_at = Some(s.time_s());
        }
    }
    let neutral_at = neutral_at.expect("the gateway never neutralised the valves");
    let delay = neutral_at - last_hb;
    eprintln!(
        "valves neutral {:.1} ms after the last heartbeat",
        delay * 1e3
    );
    assert!(delay <= WATCHDOG_S, "{delay} s");
    let gw = s.machine().node().gateway();
    assert_eq!(gw.mode(), GatewayMode::Faulted);
    assert!(gw.faults().contains(GatewayFaults::WATCHDOG_TIMEOUT));
    // The status frames say so, and the machine comes to rest.
    let last = gateway_statuses(&s.record).last().unwrap().1;
    assert_eq!(last.mode, GatewayMode::Faulted);
    // Spool delay and lag let the joints coast for a few hundred ms; then they hold. (The state's
    // rates are not used: at rest in the soil the simulator reports a creep rate while the angles
    // stay put.)
    s.advance_machine(1.0);
    let a0 = s.machine().plant().true_state().angles_rad;
    s.advance_machine(1.0);
    let a1 = s.machine().plant().true_state().angles_rad;
    let moved = (0..4).map(|j| (a1[j] - a0[j]).abs()).fold(0.0, f64::max);
    assert!(moved < REST_MOTION_RAD, "still moving: {a0:?} -> {a1:?}");
}

/// The malformed and spoofed frames of the fault test: wrong DLC, unknown PGN, a valve command from a
/// foreign source address, and (built later) a replayed heartbeat.
pub fn spoofed_frames() -> Vec<CanFrame> {
    let ext = |id: u32, data: &[u8]| CanFrame::new_data(CanId::Extended(id), data).unwrap();
    vec![
        // Boom valve command from the controller's address with 3 data bytes: rejected (DLC).
        ext(0x0CFE_3027, &[0xFA, 0xFF, 0x31]),
        // Unknown PGN 0xFEAA from a foreign node: unexpected.
        ext(0x18FE_AA99, &[1, 2, 3, 4, 5, 6, 7, 8]),
        // Boom extend 100 % from source address 0x99: rejected (wrong source).
        Message::AuxValveCommand(AuxValveCommand::from_fraction(Valve::Boom, 1.0).unwrap())
            .encode()
            .map(|f| ext(f.id().raw() & !0xFF | 0x99, f.data()))
            .unwrap(),
    ]
}

#[test]
fn malformed_and_spoofed_frames_are_counted_rejected_and_safe() {
    let mut s = Session::new(plan_config(), SEED);
    assert!(s.run_until(120.0, digging), "never reached Autodig's Dig");
    // Let a status frame report the counters before.
    s.run_until(0.2, |_| false);
    let before = gateway_statuses(&s.record).last().unwrap().1;
    let replay = *heartbeats(&s.record).last().unwrap();
    let replay = Message::ControllerHeartbeat(replay.1).encode().unwrap();
    let mut frames = spoofed_frames();
    frames.push(replay);
    for f in &frames {
        s.inject(*f);
    }
    // The gateway sees them in the next period; the foreign boom command must never be applied.
    for _ in 0..20 {
        s.step();
        assert_ne!(
            s.machine().node().valve_commands()[0],
            1.0,
            "foreign command applied"
        );
    }
    let after = gateway_statuses(&s.record).last().unwrap().1;
    eprintln!("gateway before {before:?}\nafter {after:?}");
    assert!(
        after.unexpected_frames > before.unexpected_frames,
        "unknown PGN not counted"
    );
    assert!(
        after.rejected_frames >= before.rejected_frames + 3,
        "wrong DLC, foreign source and replay: {} -> {}",
        before.rejected_frames,
        after.rejected_frames
    );
    // The controller saw frames it must not ignore (its own address, a protocol message from a
    // stranger) and stopped; it stays stopped until the operator's resume, then re-arms and digs on.
    let fault = s.node().last_fault();
    assert!(fault.is_some(), "the controller ignored the spoofs");
    assert!(
        !s.run_until(10.0, |s| s.node().safety().motion().is_some()),
        "re-armed after {fault:?} without the operator"
    );
    controller::io::operator::apply(
        s.node_mut(),
        controller::io::operator::Command::Resume,
        "test",
        0.0,
    );
    assert!(
        s.run_until(10.0, |s| s.node().safety().motion().is_some()),
        "no re-arm after {fault:?} and the operator's resume"
    );
}

/// A xorshift generator for the flood (deterministic, no dependency).
struct Xorshift(u64);

impl Xorshift {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }

    /// A frame like `cangen`'s: random 11- or 29-bit id, random length and data.
    fn frame(&mut self) -> CanFrame {
        let r = self.next();
        let len = (r % 9) as usize;
        let data = self.next().to_le_bytes();
        let id = if r & 0x100 == 0 {
            CanId::Standard((r >> 16) as u16 & 0x7FF)
        } else {
            CanId::Extended((r >> 16) as u32 & 0x1FFF_FFFF)
        };
        CanFrame::new_data(id, &data[..len]).unwrap()
    }
}

#[test]
fn bus_flood_keeps_the_loop_or_stops_safely() {
    const FLOOD_PER_PERIOD: usize = 2000;
    let mut s = Session::new(plan_config(), SEED);
    assert!(s.run_until(120.0, digging), "never reached Autodig's Dig");
    let mut rng = Xorshift(0x9E37_79B9_7F4A_7C15);
    let mut monitor = LoopMonitor::new();
    let mut reports = Vec::new();
    let steps = (2.0 / PERIOD_S) as usize;
    // The heartbeat rate without the flood, as the baseline.
    let before = heartbeats(&s.record).len();
    for _ in 0..steps {
        s.step();
    }
    let baseline = heartbeats(&s.record).len() - before;
    let heartbeats_before = heartbeats(&s.record).len();
    for _ in 0..steps {
        for _ in 0..FLOOD_PER_PERIOD {
            s.inject(rng.frame());
            monitor.on_received();
        }
        s.step();
        if let Some(r) = monitor.on_tick(s.time_s()) {
            reports.push(r);
        }
    }
    let hb = heartbeats(&s.record).len() - heartbeats_before;
    let report = reports.first().copied().expect("no monitor window closed");
    let moving = s.node().safety().motion().is_some();
    let fault = s.node().fault();
    eprintln!(
        "flood: {report:?}; heartbeats {hb} in {steps} periods; moving {moving}; fault {fault:?}"
    );
    assert!(report.overloaded());
    // The node stepped every period: its heartbeat kept its rate ...
    assert!(
        hb + 1 >= baseline,
        "{hb} heartbeats in {steps} periods, {baseline} without the flood"
    );
    assert!(report.rate_kept(firmware_bridge::dbc::CONTROL_PERIOD));
    // ... and either kept digging or stopped with a named fault: never silently nothing.
    assert!(moving || fault.is_some());
    let statuses = controller_statuses(&s.record);
    let last = statuses.last().unwrap().1;
    if moving {
        assert!(
            matches!(
                last.activity,
                Activity::Dig | Activity::SwingToDump | Activity::Idle
            ),
            "{last:?}"
        );
        assert_ne!(last.stage, AutodigStageCode::None, "{last:?}");
    } else {
        assert_eq!(last.activity, Activity::Faulted, "{last:?}");
        assert_ne!(last.fault_reason, 0);
    }
    // The gateway counted the flood as unexpected traffic and never drove a foreign command.
    let gw = gateway_statuses(&s.record).last().unwrap().1;
    assert!(gw.unexpected_frames > 1000, "{gw:?}");
}
