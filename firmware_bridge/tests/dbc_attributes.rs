//! `excavator.dbc` carries what J1939 tools expect of a DBC, and its value tables are the typed
//! messages' states: `ProtocolType` J1939, every message a J1939 parameter group (`VFrameFormat`)
//! with its period (`GenMsgCycleTime`, the bus-load schedule's rate; 0 for the J1939-81 event
//! messages, which are not on the schedule), and a value table on every signal that has states,
//! naming exactly the states the typed messages decode.

use can_dbc::{AttributeValue, Dbc};
use firmware_bridge::busload::SCHEDULE;
use firmware_bridge::dbc::{self, DBC_TEXT};
use firmware_bridge::messages::{
    Activity, AutodigStageCode, FailSafeMode, GatewayMode, LampFlash, LampStatus, RequestedMode,
    ValveState,
};
use firmware_bridge::wire_dbc::WireDbc;

fn attribute_u64(value: &AttributeValue) -> Option<u64> {
    match value {
        AttributeValue::Uint(v) => Some(*v),
        AttributeValue::Int(v) => u64::try_from(*v).ok(),
        _ => None,
    }
}

#[test]
fn every_message_is_a_j1939_parameter_group_with_its_cycle_time() {
    let parsed = Dbc::try_from(DBC_TEXT).expect("excavator.dbc parses");
    let protocol = parsed
        .attribute_values_database
        .iter()
        .find(|a| a.name == "ProtocolType")
        .map(|a| a.value.clone());
    assert_eq!(protocol, Some(AttributeValue::String("J1939".to_owned())));
    for msg in &parsed.messages {
        let of = |name: &str| {
            parsed
                .attribute_values_message
                .iter()
                .find(|a| a.name == name && a.message_id == msg.id)
                .and_then(|a| attribute_u64(&a.value))
        };
        // VFrameFormat's enum: StandardCAN, ExtendedCAN, reserved, J1939PG.
        assert_eq!(of("VFrameFormat"), Some(3), "{}", msg.name);
        let cycle_ms = of("GenMsgCycleTime").unwrap_or_else(|| panic!("{}", msg.name));
        let desc = dbc::MESSAGES
            .iter()
            .find(|d| d.name == msg.name)
            .expect("generated");
        assert_eq!(u64::from(desc.cycle_time_ms), cycle_ms, "{}", msg.name);
        let scheduled = SCHEDULE.iter().find(|e| e.message == msg.name);
        if cycle_ms == 0 {
            // An event message (J1939-81 network management): never on the schedule.
            assert_eq!(scheduled, None, "{}", msg.name);
            assert!(
                [
                    firmware_bridge::address_claim::ADDRESS_CLAIMED_PGN,
                    firmware_bridge::address_claim::REQUEST_PGN
                ]
                .contains(&desc.pgn),
                "{} has cycle time 0",
                msg.name
            );
            continue;
        }
        let scheduled = scheduled.unwrap_or_else(|| panic!("{} not scheduled", msg.name));
        assert!(
            (scheduled.rate_hz * cycle_ms as f64 - 1000.0).abs() < 1e-9,
            "{}: {} Hz against {cycle_ms} ms",
            msg.name,
            scheduled.rate_hz
        );
    }
}

/// The value table of `message.signal` restricted to the signal's range (ISO 11783 tables also
/// name the reserved codes `Error` and `NotAvailable`, which the range excludes).
fn states(dbc: &WireDbc, message: &str, signal: &str) -> Vec<(i64, String)> {
    let sig = dbc
        .message(message)
        .and_then(|m| m.signal(signal))
        .unwrap_or_else(|| panic!("{message}.{signal} in the DBC"));
    assert!(
        !sig.value_table.is_empty(),
        "{message}.{signal} has no value table"
    );
    sig.value_table
        .iter()
        .filter(|(raw, _)| (sig.min..=sig.max).contains(&(*raw as f64 * sig.factor + sig.offset)))
        .cloned()
        .collect()
}

fn named<T: Copy>(
    all: &[T],
    raw: impl Fn(T) -> i64,
    name: impl Fn(T) -> &'static str,
) -> Vec<(i64, String)> {
    all.iter().map(|&v| (raw(v), name(v).to_owned())).collect()
}

#[test]
fn value_tables_are_the_typed_messages_states() {
    let dbc = WireDbc::parse(DBC_TEXT).expect("excavator.dbc parses");
    let valve_state = named(ValveState::ALL, |v| v as i64, ValveState::name);
    let fail_safe = named(FailSafeMode::ALL, |v| v as i64, FailSafeMode::name);
    for valve in [
        "Boom",
        "Stick",
        "Bucket",
        "Swing",
        "LeftTrack",
        "RightTrack",
    ] {
        let msg = format!("AuxValveCommand_{valve}");
        assert_eq!(states(&dbc, &msg, "ValveState"), valve_state, "{msg}");
        assert_eq!(states(&dbc, &msg, "FailSafeMode"), fail_safe, "{msg}");
    }
    for cylinder in ["Boom", "Stick", "Bucket"] {
        let msg = format!("AuxValveMeasured_{cylinder}");
        assert_eq!(states(&dbc, &msg, "ValveState"), valve_state, "{msg}");
    }
    assert_eq!(
        states(&dbc, "GatewayStatus", "Mode"),
        named(GatewayMode::ALL, |v| v as i64, GatewayMode::name)
    );
    assert_eq!(
        states(&dbc, "ControllerHeartbeat", "RequestedMode"),
        named(RequestedMode::ALL, |v| v as i64, RequestedMode::name)
    );
    assert_eq!(
        states(&dbc, "ControllerStatus", "Activity"),
        named(Activity::ALL, |v| v as i64, Activity::name)
    );
    assert_eq!(
        states(&dbc, "ControllerStatus", "AutodigStage"),
        named(AutodigStageCode::ALL, |v| v as i64, AutodigStageCode::name)
    );
    let lamp = named(LampStatus::ALL, |v| v as i64, LampStatus::name);
    let flash = named(LampFlash::ALL, |v| v as i64, LampFlash::name);
    for msg in ["DM1", "DM1_Gateway"] {
        for l in ["Protect", "AmberWarning", "RedStop", "MalfunctionIndicator"] {
            assert_eq!(states(&dbc, msg, &format!("{l}LampStatus")), lamp, "{msg}");
            assert_eq!(states(&dbc, msg, &format!("Flash{l}Lamp")), flash, "{msg}");
        }
        assert_eq!(
            states(&dbc, msg, "OccurrenceCount"),
            [(127, "NotAvailable".to_owned())]
        );
    }
    // The saturating counters name their saturated value.
    for counter in ["UnexpectedFrames", "RejectedFrames"] {
        assert_eq!(
            states(&dbc, "GatewayStatus", counter),
            [(65535, "Saturated".to_owned())]
        );
    }
}

/// docs/protocol.md said "priority 3 for everything" while three messages are priority 6: the
/// priorities are the ones it now lists.
#[test]
fn priorities_are_the_ones_docs_protocol_md_lists() {
    let priority = |m: &&dbc::MessageDesc| m.default_id >> 26;
    let six: Vec<&str> = dbc::MESSAGES
        .iter()
        .filter(|m| priority(m) == 6)
        .map(|m| m.name)
        .collect();
    assert_eq!(
        six,
        [
            "ControllerStatus",
            "AddressClaimed",
            "AddressClaimed_Gateway",
            "DM1",
            "DM1_Gateway",
            "RequestPgn"
        ]
    );
    assert!(
        dbc::MESSAGES
            .iter()
            .all(|m| six.contains(&m.name) || priority(&m) == 3)
    );
    let doc = include_str!("../../docs/protocol.md").replace("\n  ", " ");
    assert!(
        doc.contains("priority 6 (J1939's default for information and network management) for `ControllerStatus`, `AddressClaimed`, `AddressClaimed_Gateway`, `DM1`, `DM1_Gateway` and `RequestPgn`"),
        "docs/protocol.md names the priority-6 messages"
    );
}
