//! The DM1 table of `gateway_core::dm1` is the one source of each fault's SPN, FMI and lamp: the DBC's
//! value tables of `DM1.SpnLow` / `DM1_Gateway.SpnLow` and the table in docs/protocol.md are checked
//! against it here.

use firmware_bridge::dbc::DBC_TEXT;
use firmware_bridge::dm1::{CONTROLLER_DTCS, DtcSpec, GATEWAY_DTCS, Lamp};
use firmware_bridge::wire_dbc::WireDbc;

const PROTOCOL_MD: &str = include_str!("../../docs/protocol.md");

/// `(SpnLow, name)` of every entry, with 0 `NoActiveFault` first (SpnHigh is 7 for them all).
fn expected_value_table(table: &[DtcSpec]) -> Vec<(i64, String)> {
    let mut out = vec![(0, "NoActiveFault".to_owned())];
    for s in table {
        assert_eq!(
            s.spn >> 16,
            7,
            "{}: the proprietary SPNs have SpnHigh 7",
            s.name
        );
        out.push((i64::from(s.spn & 0xFFFF), s.name.to_owned()));
    }
    out
}

#[test]
fn the_dbc_names_every_dtc_of_each_node() {
    let dbc = WireDbc::parse(DBC_TEXT).expect("excavator.dbc parses");
    for (message, table) in [
        ("DM1", &CONTROLLER_DTCS[..]),
        ("DM1_Gateway", &GATEWAY_DTCS[..]),
    ] {
        let sig = dbc
            .message(message)
            .and_then(|m| m.signal("SpnLow"))
            .unwrap_or_else(|| panic!("{message}.SpnLow in the DBC"));
        let got: Vec<(i64, String)> = sig.value_table.to_vec();
        assert_eq!(got, expected_value_table(table), "{message}.SpnLow");
    }
}

#[test]
fn docs_protocol_md_lists_every_dtc_as_the_code_sends_it() {
    let lamp = |l: Lamp| match l {
        Lamp::RedStop => "red stop",
        Lamp::AmberWarning => "amber warning",
    };
    let mut expected = Vec::new();
    for (i, s) in GATEWAY_DTCS.iter().enumerate() {
        expected.push(format!(
            "| `0x80` | `{}` (fault bit {i}) | {} | {} | {} |",
            s.name,
            s.spn,
            s.fmi,
            lamp(s.lamp)
        ));
    }
    for (i, s) in CONTROLLER_DTCS.iter().enumerate() {
        expected.push(format!(
            "| `0x27` | `{}` (fault code {}) | {} | {} | {} |",
            s.name,
            i + 1,
            s.spn,
            s.fmi,
            lamp(s.lamp)
        ));
    }
    let documented: Vec<&str> = PROTOCOL_MD
        .lines()
        .filter(|l| l.starts_with("| `0x80` | `") || l.starts_with("| `0x27` | `"))
        .collect();
    assert_eq!(documented, expected, "docs/protocol.md's DM1 table");
}

#[test]
fn the_gateway_table_follows_its_fault_bits() {
    use firmware_bridge::messages::GatewayFaults as F;
    let bits = [
        (F::WATCHDOG_TIMEOUT, "WatchdogTimeout"),
        (F::BAD_CHECKSUM, "BadChecksum"),
        (F::BAD_ALIVE_COUNTER, "BadAliveCounter"),
        (F::STALE_COMMAND, "StaleCommand"),
        (F::E_STOP, "EStop"),
        (F::BUS_ERROR, "BusError"),
        (F::JOINT_LIMIT, "JointLimit"),
        (F::SETPOINT_OUT_OF_RANGE, "SetpointOutOfRange"),
        (F::CLOCK_FAULT, "ClockFault"),
        (F::AUTH_FAILURE, "AuthFailure"),
        (F::ADDRESS_LOST, "AddressLost"),
    ];
    assert_eq!(bits.len(), GATEWAY_DTCS.len());
    for (bit, name) in bits {
        let index = bit.trailing_zeros() as usize;
        assert_eq!(GATEWAY_DTCS[index].name, name, "fault bit {index}");
    }
}
