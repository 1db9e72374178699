//! The DBC and the code cannot disagree: the DBC parsed at test time equals the tables generated at
//! build time, and every DBC message has a typed counterpart that round-trips.

mod common;

use std::collections::BTreeSet;

use can_dbc::{Dbc, MessageId, NumericValue, ValueDescription, ValueType};
use firmware_bridge::dbc::MESSAGES;
use firmware_bridge::{CanId, Message};

fn load_dbc() -> Dbc {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../gateway_core/excavator.dbc");
    let text = std::fs::read_to_string(path).expect("read excavator.dbc");
    Dbc::try_from(text.as_str()).expect("parse excavator.dbc")
}

fn num(v: &NumericValue) -> f64 {
    match *v {
        NumericValue::Uint(u) => u as f64,
        NumericValue::Int(i) => i as f64,
        NumericValue::Double(d) => d,
    }
}

#[test]
fn generated_tables_equal_the_dbc() {
    let dbc = load_dbc();
    assert_eq!(dbc.messages.len(), MESSAGES.len());
    for (msg, desc) in dbc.messages.iter().zip(MESSAGES) {
        assert_eq!(msg.name, desc.name);
        assert_eq!(msg.id, MessageId::Extended(desc.default_id), "{}", msg.name);
        assert_eq!(msg.size, u64::from(desc.dlc), "{}", msg.name);
        assert_eq!(msg.signals.len(), desc.signals.len(), "{}", msg.name);
        for (sig, sd) in msg.signals.iter().zip(desc.signals) {
            assert_eq!(sig.name, sd.name);
            assert_eq!(
                sig.start_bit,
                u64::from(sd.start_bit),
                "{}.{}",
                msg.name,
                sig.name
            );
            assert_eq!(sig.size, u64::from(sd.len), "{}.{}", msg.name, sig.name);
            assert_eq!(
                sig.value_type == ValueType::Signed,
                sd.signed,
                "{}.{}",
                msg.name,
                sig.name
            );
            assert_eq!(sig.factor, sd.factor, "{}.{}", msg.name, sig.name);
            assert_eq!(sig.offset, sd.offset, "{}.{}", msg.name, sig.name);
            assert_eq!(num(&sig.min), sd.min, "{}.{}", msg.name, sig.name);
            assert_eq!(num(&sig.max), sd.max, "{}.{}", msg.name, sig.name);
            assert_eq!(sig.unit, sd.unit, "{}.{}", msg.name, sig.name);
        }
    }
}

#[test]
fn every_dbc_message_has_a_typed_counterpart_that_round_trips() {
    let dbc = load_dbc();
    let dbc_ids: BTreeSet<u32> = dbc
        .messages
        .iter()
        .map(|m| m.id.raw() & 0x1FFF_FFFF)
        .collect();
    let mut typed_ids = BTreeSet::new();
    let samples = common::sample_messages()
        .into_iter()
        .map(|m| (m, m.encode().expect("sample encodes")))
        .chain(common::gateway_sourced_samples());
    for (msg, frame) in samples {
        let CanId::Extended(id) = frame.id() else {
            panic!("J1939 frames are extended")
        };
        typed_ids.insert(id);
        let dbc_msg = dbc
            .messages
            .iter()
            .find(|m| m.id.raw() & 0x1FFF_FFFF == id)
            .expect("id in DBC");
        assert_eq!(frame.len() as u64, dbc_msg.size);
        // The signal names the typed message reports are exactly the DBC's.
        let names: Vec<&str> = msg.signal_values().iter().map(|(n, _)| *n).collect();
        let dbc_names: Vec<&str> = dbc_msg.signals.iter().map(|s| s.name.as_str()).collect();
        assert_eq!(names, dbc_names, "{}", dbc_msg.name);
        let decoded = Message::decode(&frame).expect("decodes");
        assert_eq!(
            decoded
                .message
                .encode_from(decoded.id.source_address())
                .expect("re-encodes"),
            frame,
            "{}",
            dbc_msg.name
        );
    }
    assert_eq!(
        typed_ids, dbc_ids,
        "every DBC message must have a typed sample and vice versa"
    );
}

/// The `VAL_` table of `signal` (by name, first message that has one).
fn value_table(dbc: &Dbc, signal: &str) -> Vec<(i64, String)> {
    dbc.value_descriptions
        .iter()
        .find_map(|v| match v {
            ValueDescription::Signal {
                name,
                value_descriptions,
                ..
            } if name == signal => Some(
                value_descriptions
                    .iter()
                    .map(|d| (d.id, d.description.clone()))
                    .collect(),
            ),
            _ => None,
        })
        .unwrap_or_default()
}

#[test]
fn value_tables_name_the_typed_values() {
    use firmware_bridge::messages::{GatewayStatus, RequestedMode};
    let dbc = load_dbc();
    let modes = [
        (RequestedMode::Disarm, "Disarm"),
        (RequestedMode::ArmValve, "ArmValve"),
        (RequestedMode::ArmPosition, "ArmPosition"),
        (RequestedMode::EStop, "EStop"),
        (RequestedMode::ResetEStop, "ResetEStop"),
    ];
    let expected: Vec<(i64, String)> = modes
        .iter()
        .map(|(m, name)| (*m as i64, (*name).to_string()))
        .collect();
    assert_eq!(value_table(&dbc, "RequestedMode"), expected);
    // A saturated frame counter is named, so trace tools show it (docs/protocol.md).
    for signal in ["UnexpectedFrames", "RejectedFrames"] {
        assert_eq!(
            value_table(&dbc, signal),
            [(
                i64::from(GatewayStatus::FRAME_COUNT_SATURATED),
                "Saturated".to_string()
            )],
            "{signal}"
        );
    }
}
