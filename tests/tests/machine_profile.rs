//! `excavator-sim --profile` and `excavator-ctl run --profile` with the example profile of another
//! gateway (`examples/other_gateway.toml`) as separate processes over a real vcan interface: the HIL
//! plan completes, the bus carries only that gateway's 11-bit frames, and `cantools` decodes the
//! `candump -L` recording with that gateway's DBC to the values the profile translates it to.
//!
//! `#[ignore]`d in a plain `cargo test`: it needs a vcan interface (`EXCAVATOR_VCAN_IFACE`) and the
//! release binaries (`EXCAVATOR_BIN_DIR`); `scripts/test-all` runs it through `scripts/vcan-vm`.

#![allow(clippy::unwrap_used)]

mod common;

use std::path::Path;
use std::process::Command;
use std::time::Duration;

use firmware_bridge::messages::{JointAngles, Message};
use firmware_bridge::profile::Profile;
use hil_tests::analysis::{
    Rec, activity_sequence, controller_statuses, count_cycles, read_candump,
};
use hil_tests::plan::{PLAN_CLEANUPS, PLAN_DIGS};

const PROFILE: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../examples/other_gateway.toml"
);
const PROFILE_DBC: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../examples/other_gateway.dbc");
/// As the plain HIL plan's (`dig_cycle.rs`).
const PLAN_TIMEOUT: Duration = Duration::from_secs(900);
/// candump's marker frame (`common::start_candump`).
const MARKER_ID: u16 = 0x7FF;

#[test]
#[ignore = "needs a vcan interface: run through scripts/test-all"]
fn the_plan_completes_over_another_gateways_protocol() {
    let profile = Profile::load(Path::new(PROFILE)).unwrap();
    let args = ["--profile", PROFILE];
    let mut s = common::Session::start_with("machine_profile", &args, &args);
    let status = s.ctl().wait_timeout(PLAN_TIMEOUT);
    assert!(
        status.is_some(),
        "the plan did not finish within {PLAN_TIMEOUT:?}\n{}",
        s.logs()
    );
    s.stop_sim_and_candump();
    assert!(
        status.unwrap().success(),
        "excavator-ctl failed\n{}",
        s.logs()
    );

    // The wire: the example's 11-bit ids only, each translating to a project message.
    let (wire, _) = read_candump(&s.candump_log);
    let mut canonical = Vec::with_capacity(wire.len());
    for rec in wire
        .iter()
        .filter(|r| r.frame.id() != firmware_bridge::CanId::Standard(MARKER_ID))
    {
        assert!(!rec.frame.is_extended(), "{:?} on the bus", rec.frame);
        let frame = profile
            .from_wire(&rec.frame)
            .unwrap_or_else(|e| panic!("{e}: {:?}", rec.frame));
        canonical.push(Rec {
            t_s: rec.t_s,
            frame,
        });
    }
    let seq = activity_sequence(&controller_statuses(&canonical));
    let cycles = count_cycles(&seq);
    eprintln!("{} wire frames; cycles {cycles:?}", canonical.len());
    assert!(
        cycles.digs >= PLAN_DIGS && cycles.cleanups >= PLAN_CLEANUPS,
        "{cycles:?} in {seq:?}"
    );

    // cantools with the other gateway's DBC: its ArmAngles in degrees are our joint angles.
    let ours: Vec<JointAngles> = canonical
        .iter()
        .filter_map(|r| match Message::decode(&r.frame).map(|d| d.message) {
            Ok(Message::JointAngles(a)) => Some(a),
            _ => None,
        })
        .collect();
    let out = Command::new("python3")
        .args(["-m", "cantools", "decode", "--single-line", PROFILE_DBC])
        .stdin(std::fs::File::open(&s.candump_log).unwrap())
        .output()
        .expect("python3 runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    let theirs: Vec<f64> = text
        .lines()
        .filter_map(|l| {
            l.split_once(":: ArmAngles(")?
                .1
                .split_once("BoomDeg: ")?
                .1
                .split(' ')
                .next()?
                .parse()
                .ok()
        })
        .collect();
    assert_eq!(
        theirs.len(),
        ours.len(),
        "cantools decoded every ArmAngles frame"
    );
    for (deg, a) in theirs.iter().zip(&ours) {
        assert!(
            (deg.to_radians() - a.boom_rad).abs() < 1e-4,
            "{deg} deg vs {} rad",
            a.boom_rad
        );
    }
}
