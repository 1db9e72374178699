//! The runtime DBC codec (`firmware_bridge::wire_dbc`) on the example gateway's DBC (Motorola and
//! Intel, signed, unsigned and float signals, 11-bit ids, multiplexed messages) and the project's own:
//! encode-decode round trips, arbitrary payloads never panic, and `cantools` (PyPI) encodes the same
//! values to the same bytes and decodes our bytes to the same values.
//!
//! The `cantools` test skips with a printed line when `cantools` is missing, or fails when
//! `EXCAVATOR_REQUIRE_TOOLS=1`.

mod common;

use std::io::Write;
use std::process::{Command, Stdio};

use firmware_bridge::wire_dbc::{Mux, ValueKind, WireDbc, WireMessage};
use proptest::prelude::*;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

const OTHER_DBC: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../examples/other_gateway.dbc");
const PROJECT_DBC: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../gateway_core/excavator.dbc");

fn load(path: &str) -> WireDbc {
    let text = std::fs::read_to_string(path).expect("the DBC is in the repository");
    WireDbc::parse(&text).unwrap_or_else(|e| panic!("{path}: {e}"))
}

/// Both DBCs' messages.
fn all_messages() -> Vec<WireMessage> {
    let mut out = load(OTHER_DBC).messages;
    out.extend(load(PROJECT_DBC).messages);
    out
}

/// The multiplexor values a frame of `msg` can carry (`None` for a plain message).
fn mux_choices(msg: &WireMessage) -> Vec<Option<u64>> {
    match msg.multiplexor {
        Some(_) if msg.mux_values().is_empty() => vec![Some(0), Some(5)],
        Some(_) => msg.mux_values().into_iter().map(Some).collect(),
        None => vec![None],
    }
}

/// Random raw bits for every signal present with `mux`; finite floats only (a NaN's bits do not
/// compare through a physical value).
fn random_bits(msg: &WireMessage, mux: Option<u64>, rng: &mut impl RngExt) -> Vec<(usize, u64)> {
    msg.signals
        .iter()
        .enumerate()
        .filter(|(_, s)| match s.mux {
            Mux::Plain => true,
            Mux::Multiplexor => false,
            Mux::Multiplexed(v) => Some(v) == mux,
        })
        .map(|(i, s)| {
            let bits = match s.kind {
                ValueKind::Float32 => u64::from((rng.random_range(-1.0e6f32..1.0e6)).to_bits()),
                ValueKind::Float64 => rng.random_range(-1.0e12f64..1.0e12).to_bits(),
                _ => s.bits_of_integer(rng.random::<u64>().into()),
            };
            (i, bits)
        })
        .collect()
}

#[test]
fn the_example_dbc_has_what_real_dbcs_contain() {
    let dbc = load(OTHER_DBC);
    let signals = || dbc.messages.iter().flat_map(|m| &m.signals);
    assert!(dbc.messages.iter().all(|m| !m.id.is_extended()));
    assert!(signals().any(|s| s.byte_order == firmware_bridge::wire_dbc::ByteOrder::Motorola));
    assert!(signals().any(|s| s.kind == ValueKind::Float32));
    assert!(signals().any(|s| s.kind == ValueKind::Signed));
    assert!(
        dbc.messages
            .iter()
            .filter(|m| m.multiplexor.is_some())
            .count()
            >= 2
    );
    assert!(signals().filter(|s| !s.value_table.is_empty()).count() >= 5);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn encoded_bits_decode_to_the_same_bits(seed in any::<u64>(), pick in any::<prop::sample::Index>()) {
        let messages = all_messages();
        let msg = pick.get(&messages);
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        for mux in mux_choices(msg) {
            let bits = random_bits(msg, mux, &mut rng);
            let data = msg.encode_bits(mux, &bits, 0xFF).expect("raw bits always fit");
            let decoded = msg.decode(&data).expect("our own payload decodes");
            prop_assert_eq!(decoded.len(), bits.len() + usize::from(mux.is_some()));
            for (index, want) in &bits {
                let got = decoded.iter().find(|v| v.index == *index).expect("signal decoded");
                prop_assert_eq!(got.bits, *want, "{}.{}", msg.name, msg.signals[*index].name);
                // And through the physical value: bits -> physical -> bits is the identity.
                let sig = &msg.signals[*index];
                prop_assert_eq!(sig.bits_of(got.physical, false).expect("fits"), *want);
            }
        }
    }

    #[test]
    fn arbitrary_payloads_never_panic(data in prop::collection::vec(any::<u8>(), 0..=8), pick in any::<prop::sample::Index>()) {
        let messages = all_messages();
        let msg = pick.get(&messages);
        match msg.decode(&data) {
            Ok(values) => for v in values {
                prop_assert!(v.index < msg.signals.len());
            },
            Err(e) => prop_assert!(!e.to_string().is_empty()),
        }
    }
}

/// One frame for the Python side: message name, physical values by signal name, our bytes.
#[derive(serde::Serialize)]
struct Case {
    message: String,
    values: Vec<(String, f64)>,
    ours: String,
}

const CANTOOLS_SCRIPT: &str = r#"
import json, sys, cantools
db = cantools.database.load_file(sys.argv[1])
out = []
for case in json.load(sys.stdin):
    msg = db.get_message_by_name(case["message"])
    values = dict(case["values"])
    theirs = msg.encode(values, padding=True, strict=False).hex()
    decoded = msg.decode(bytes.fromhex(case["ours"]), decode_choices=False)
    out.append({"encoded": theirs, "decoded": {k: float(v) for k, v in decoded.items()}})
json.dump(out, sys.stdout)
"#;

#[test]
fn cantools_encodes_and_decodes_like_the_runtime_codec() {
    if !common::tool_available(
        "cantools",
        "python3",
        &["-c", "import cantools"],
        "pip install cantools",
    ) {
        return;
    }
    for path in [OTHER_DBC, PROJECT_DBC] {
        let dbc = load(path);
        let mut rng = ChaCha8Rng::seed_from_u64(0x00DB_C0DE);
        let mut cases = Vec::new();
        for msg in &dbc.messages {
            for mux in mux_choices(msg) {
                for _ in 0..40 {
                    let bits = random_bits(msg, mux, &mut rng);
                    let data = msg.encode_bits(mux, &bits, 0xFF).expect("fits");
                    let mut values: Vec<(String, f64)> = bits
                        .iter()
                        .map(|&(i, b)| (msg.signals[i].name.clone(), msg.signals[i].physical(b)))
                        .collect();
                    if let (Some(i), Some(v)) = (msg.multiplexor, mux) {
                        values.push((msg.signals[i].name.clone(), v as f64));
                    }
                    cases.push(Case {
                        message: msg.name.clone(),
                        values,
                        ours: hex(&data),
                    });
                }
            }
        }
        let mut child = Command::new("python3")
            .args(["-c", CANTOOLS_SCRIPT, path])
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .spawn()
            .expect("python3 runs");
        let input = serde_json::to_vec(&cases).expect("serialises");
        child
            .stdin
            .take()
            .expect("piped")
            .write_all(&input)
            .expect("write to python");
        let out = child.wait_with_output().expect("python finishes");
        assert!(out.status.success(), "cantools script failed on {path}");
        let results: Vec<serde_json::Value> =
            serde_json::from_slice(&out.stdout).expect("JSON from the script");
        assert_eq!(results.len(), cases.len());
        for (case, result) in cases.iter().zip(&results) {
            assert_eq!(
                result["encoded"].as_str(),
                Some(case.ours.as_str()),
                "{path}: cantools encodes {} {:?} differently",
                case.message,
                case.values
            );
            for (name, value) in &case.values {
                let theirs = result["decoded"][name]
                    .as_f64()
                    .unwrap_or_else(|| panic!("cantools decoded no {name} in {}", case.message));
                assert!(
                    (theirs - value).abs() <= 1e-9 * (1.0 + value.abs()),
                    "{path}: {}.{name}: cantools {theirs}, ours {value}",
                    case.message
                );
            }
        }
        println!(
            "{path}: {} frames over {} messages encode and decode alike in cantools",
            cases.len(),
            dbc.messages.len()
        );
    }
}

fn hex(data: &[u8]) -> String {
    data.iter().map(|b| format!("{b:02x}")).collect()
}
