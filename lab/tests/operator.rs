//! Operator control ([`controller::io::operator`]) against the simulated machine in virtual time: what
//! each command does to the valve commands on the bus.

#![allow(clippy::unwrap_used)]

mod common;

use common::{Loop, PERIOD_S, default_sim, has_all_neutral, has_motion, heartbeat_mode};
use controller::ControllerConfig;
use controller::io::operator::{Command, apply};
use controller::step::cycle::Phase;
use firmware_bridge::messages::RequestedMode;

/// The default plan's first two digs.
fn two_digs() -> ControllerConfig {
    let mut c = ControllerConfig::default();
    c.cycle.actions.truncate(2);
    c.cycle.repeat = false;
    c.cycle.max_digs = Some(2);
    c
}

/// A loop in the middle of its first dig (Autodig, valves moving).
fn digging() -> Loop {
    let mut l = Loop::new(default_sim(), two_digs());
    assert!(l.run_until(120.0, |l| l.phase() == Phase::Autodig));
    let moving = (0..50).any(|_| has_motion(&l.step()));
    assert!(moving, "no motion in Autodig");
    l
}

fn operator(l: &mut Loop, cmd: Command) {
    let now = l.time_s();
    apply(l.node_mut(), cmd, "test", now);
}

/// Steps for `s` seconds; true if any step commanded motion.
fn any_motion(l: &mut Loop, s: f64) -> bool {
    let steps = (s / PERIOD_S).round() as usize;
    (0..steps).any(|_| has_motion(&l.step()))
}

#[test]
fn estop_sends_neutral_valves_and_disarm_in_the_next_period_and_holds_until_reset() {
    let mut l = digging();
    operator(&mut l, Command::Estop);
    let out = l.step();
    assert!(has_all_neutral(&out), "{out:?}");
    assert!(!has_motion(&out));
    let hb = heartbeat_mode(&out);
    assert!(
        matches!(hb, Some(RequestedMode::Disarm | RequestedMode::EStop)),
        "{hb:?}"
    );
    // Held: well past the re-arm hold of an ordinary fault.
    assert!(!any_motion(&mut l, 5.0), "motion during the e-stop");
    assert!(l.node().fault().is_some());
    operator(&mut l, Command::Reset);
    assert!(any_motion(&mut l, 10.0), "no motion after the reset");
}

#[test]
fn pause_ends_the_current_action_then_starts_nothing_until_resume() {
    let mut l = digging();
    operator(&mut l, Command::Pause);
    // The dig runs to its end (weighed, dumped) and the cycle holds in Idle.
    assert!(l.run_until(120.0, |l| l.phase() == Phase::Idle));
    assert_eq!(l.node().statistics().len(), 1);
    assert!(!any_motion(&mut l, 5.0), "motion while paused");
    assert_eq!(l.phase(), Phase::Idle);
    assert!(l.node().safety().motion().is_none(), "armed while paused");
    operator(&mut l, Command::Resume);
    assert!(any_motion(&mut l, 20.0), "no motion after resume");
    assert_ne!(l.phase(), Phase::Idle);
}

#[test]
fn stop_ends_the_session_after_the_current_action() {
    let mut l = digging();
    operator(&mut l, Command::Stop);
    assert!(l.run_until(180.0, |l| l.node().finished()));
    assert_eq!(l.node().statistics().len(), 1, "a second dig started");
    let status = apply(l.node_mut(), Command::Status, "test", 0.0);
    assert!(status.stopping && status.digs == 1, "{status:?}");
}
