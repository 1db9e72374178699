//! A machine profile's gateway (`MachineNode::with_timing`): the simulated gateway sends at the
//! periods of the example profile's DBC (`examples/other_gateway.toml`: angles every 20 ms, pumps
//! every 40 ms, status and odometry every 100 ms, once its address claim stands) and its heartbeat watchdog is the profile's; the
//! project's timing is the default node's, frame for frame.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use firmware_bridge::CanFrame;
use firmware_bridge::messages::Message;
use firmware_bridge::profile::{GatewayTiming, Profile};
use firmware_bridge::secoc::SessionKey;
use vcan_sim::SimConfig;
use vcan_sim::node::{MachineNode, Schedule};

const EXAMPLE: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../examples/other_gateway.toml"
);

fn plant() -> vcan_sim::plant::Plant {
    SimConfig::load::<&str>(None, None, Some(3), &[])
        .expect("built-in config")
        .build()
        .expect("plant")
}

/// The frames of `node` in `ms` physics steps.
fn run(mut node: MachineNode, ms: u64) -> Vec<CanFrame> {
    let mut out = Vec::new();
    node.run_steps(ms, &mut out);
    out
}

fn count(frames: &[CanFrame], pick: fn(&Message) -> bool) -> usize {
    frames
        .iter()
        .filter(|f| Message::decode(f).is_ok_and(|d| pick(&d.message)))
        .count()
}

#[test]
fn the_gateway_sends_at_the_profiles_periods() {
    let profile = Profile::load(std::path::Path::new(EXAMPLE)).unwrap();
    let mut node = MachineNode::with_timing(plant(), &profile.timing()).unwrap();
    assert_eq!(
        node.schedule(),
        Schedule {
            sensor: 20,
            pump: 40,
            odometry: 100,
            status: 100
        }
    );
    // Past the address claim's 250 ms hold (nothing but the claim before it), then 2 s.
    let mut frames = Vec::new();
    node.run_steps(300, &mut frames);
    frames.clear();
    node.run_steps(2000, &mut frames);
    assert_eq!(
        count(&frames, |m| matches!(m, Message::JointAngles(_))),
        100
    );
    assert_eq!(count(&frames, |m| matches!(m, Message::JointRates(_))), 100);
    assert_eq!(
        count(&frames, |m| matches!(m, Message::AuxValveMeasured(_))),
        300
    );
    assert_eq!(
        count(&frames, |m| matches!(m, Message::PumpPressures(_))),
        50
    );
    assert_eq!(
        count(&frames, |m| matches!(m, Message::TrackOdometry(_))),
        20
    );
    assert_eq!(
        count(&frames, |m| matches!(m, Message::GatewayStatus(_))),
        20
    );
}

#[test]
fn the_projects_timing_is_the_default_node() {
    // The same session nonces on both (each node draws its own from the OS otherwise).
    let canonical = MachineNode::with_timing(plant(), &GatewayTiming::canonical())
        .unwrap()
        .with_security(&SessionKey::PUBLIC, 1);
    assert_eq!(canonical.schedule(), Schedule::default());
    let default = MachineNode::new(plant()).with_security(&SessionKey::PUBLIC, 1);
    assert_eq!(run(canonical, 1000), run(default, 1000));
}
