//! The documented schedule fits: worst-case bus load at 500 kbit/s under 40 %.

mod common;

use firmware_bridge::busload::{self, BITRATE, SCHEDULE};
use firmware_bridge::dbc;

#[test]
fn schedule_bus_load_at_500_kbit_is_under_40_percent() {
    let worst =
        busload::worst_case_load(SCHEDULE, BITRATE).expect("every scheduled message is in the DBC");
    // Exact stuffing of the sample frames at the scheduled rates (each DBC message once).
    let samples: Vec<_> = common::sample_messages()
        .iter()
        .map(|m| m.encode().expect("encodes"))
        .collect();
    let mut exact_rows = Vec::new();
    for entry in SCHEDULE {
        let desc = busload::descriptor(entry).expect("in DBC");
        let frame = samples
            .iter()
            .find(|f| f.id().raw() & !0xFF == desc.default_id & !0xFF)
            .expect("a sample for every scheduled message");
        exact_rows.push((*frame, entry.rate_hz));
    }
    let exact = busload::exact_load(&exact_rows, BITRATE).expect("classic frames");
    let frames_per_s: f64 = SCHEDULE.iter().map(|e| e.rate_hz).sum();
    println!(
        "bus load at {} kbit/s: {:.1} % worst-case stuffing, {:.1} % with the sample frames' exact stuffing ({frames_per_s} frames/s)",
        BITRATE / 1000,
        worst * 100.0,
        exact * 100.0
    );
    // DM1 is scheduled at its 1 s period; a change is sent at once but at most every 100 ms, so two
    // nodes whose faults flicker send up to 10 frames/s each: the worst case counts that rate.
    let dm1_extra_hz = 1.0 / firmware_bridge::dm1::DM1_MIN_GAP.as_secs_f64()
        - 1.0 / firmware_bridge::dm1::DM1_PERIOD.as_secs_f64();
    let dm1_nodes = SCHEDULE
        .iter()
        .filter(|e| busload::descriptor(e).is_some_and(|d| d.pgn == firmware_bridge::dm1::DM1_PGN))
        .count();
    assert_eq!(dm1_nodes, 2, "DM1 from the controller and the gateway");
    let worst_with_dm1_changes = worst
        + dm1_nodes as f64 * dm1_extra_hz * f64::from(busload::worst_case_bits(true, 8))
            / f64::from(BITRATE);
    println!(
        "with both nodes' DM1 at their change-limited 10 Hz: {:.1} % worst-case stuffing",
        worst_with_dm1_changes * 100.0
    );
    assert!(
        worst_with_dm1_changes < 0.40,
        "worst-case bus load with DM1 changes {:.1} % is not under 40 %",
        worst_with_dm1_changes * 100.0
    );
    assert!(exact <= worst);
    assert!(
        worst < 0.40,
        "worst-case bus load {:.1} % is not under 40 %",
        worst * 100.0
    );
    // Every periodic DBC message is scheduled. The J1939 network-management messages (address claim,
    // request) are sent on events only: at start, on a contest, on request (docs/protocol.md).
    let on_events = [
        firmware_bridge::address_claim::ADDRESS_CLAIMED_PGN,
        firmware_bridge::address_claim::REQUEST_PGN,
    ];
    for desc in dbc::MESSAGES.iter().filter(|d| !on_events.contains(&d.pgn)) {
        assert!(
            SCHEDULE.iter().any(|e| e.message == desc.name),
            "{} has no rate",
            desc.name
        );
    }
}
