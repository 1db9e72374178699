//! `trace convert --to mcap`: the file reads back with the `mcap` crate (and with the Python `mcap`
//! reader from PyPI when it is installed), one channel per message, JSON messages matching their JSON
//! schemas.

#![allow(clippy::unwrap_used)] // helpers outside #[test] functions fail loudly on purpose

use std::collections::HashMap;
use std::io::BufReader;
use std::path::Path;
use std::process::Command;

use trace_tools::convert;
use trace_tools::synth::{self, SynthConfig};

const FRAMES: u64 = 5850;

fn write_fixture(path: &Path) {
    let mut f = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    synth::write_candump(
        &mut f,
        &SynthConfig {
            frames: FRAMES,
            ..SynthConfig::default()
        },
    )
    .unwrap();
    // An unknown id and an error frame go to /can/raw only.
    use std::io::Write as _;
    writeln!(f, "(1700000005.000000) vcan0 18FEF100#0011223344556677").unwrap();
    writeln!(f, "(1700000005.000100) vcan0 20000040#0000000000000000").unwrap();
}

fn convert_fixture(dir: &Path) -> std::path::PathBuf {
    let log = dir.join("dig.log");
    write_fixture(&log);
    let out = dir.join("dig.mcap");
    let reader = BufReader::new(std::fs::File::open(&log).unwrap());
    let file = std::io::BufWriter::new(std::fs::File::create(&out).unwrap());
    let summary = convert::to_mcap(reader, file, false, &mut std::io::sink()).unwrap();
    assert_eq!(summary.read.records, FRAMES + 2);
    assert_eq!(summary.written, FRAMES);
    out
}

#[test]
fn mcap_reads_back_with_the_mcap_crate() {
    let dir = tempfile::tempdir().unwrap();
    let path = convert_fixture(dir.path());
    let bytes = std::fs::read(&path).unwrap();

    let summary = mcap::Summary::read(&bytes)
        .unwrap()
        .expect("a summary section");
    let stats = summary.stats.as_ref().expect("statistics");
    assert_eq!(stats.message_count, 2 * FRAMES + 2);
    // 18 message channels + /can/raw.
    assert_eq!(summary.channels.len(), 19);

    let mut per_topic: HashMap<String, u64> = HashMap::new();
    let mut last_time = 0;
    for msg in mcap::MessageStream::new(&bytes).unwrap() {
        let msg = msg.unwrap();
        *per_topic.entry(msg.channel.topic.clone()).or_insert(0) += 1;
        assert!(msg.log_time >= 1_700_000_000_000_000_000);
        last_time = last_time.max(msg.log_time);
        assert_eq!(msg.channel.message_encoding, "json");
        let schema = msg.channel.schema.as_ref().expect("a schema");
        assert_eq!(schema.encoding, "jsonschema");
        let schema: serde_json::Value = serde_json::from_slice(&schema.data).unwrap();
        let value: serde_json::Value = serde_json::from_slice(&msg.data).unwrap();
        // Every field of the message is described by the schema.
        let props = schema["properties"].as_object().unwrap();
        for key in value.as_object().unwrap().keys() {
            assert!(
                props.contains_key(key),
                "{} has {key} outside its schema",
                msg.channel.topic
            );
        }
        if msg.channel.topic == "/can/JointAngles" {
            let boom = value["BoomAngle"].as_f64().unwrap();
            assert!((-3.2..3.2).contains(&boom));
            assert!(value["error"].is_null());
        }
        if msg.channel.topic == "/can/ControllerStatus" {
            assert!(value["AutodigStage_name"].is_string());
        }
    }
    assert_eq!(per_topic["/can/raw"], FRAMES + 2);
    assert_eq!(per_topic["/can/JointAngles"], 500);
    assert_eq!(per_topic["/can/ControllerStatus"], 100);
    assert_eq!(per_topic["/can/GatewayStatus"], 50);
    assert_eq!(last_time, 1_700_000_005_000_100_000);
}

#[test]
fn mcap_reads_back_with_the_python_reader() {
    let have = Command::new("python3")
        .args(["-c", "import mcap.reader"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !have {
        if std::env::var("EXCAVATOR_REQUIRE_TOOLS").as_deref() == Ok("1") {
            panic!("python3 with the mcap package is required (pip install mcap)");
        }
        println!("skip: python3 -c 'import mcap.reader' failed (pip install mcap)");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let path = convert_fixture(dir.path());
    let script = r#"
import json, sys
from collections import Counter
from mcap.reader import make_reader
counts = Counter()
with open(sys.argv[1], "rb") as f:
    reader = make_reader(f)
    for schema, channel, message in reader.iter_messages():
        json.loads(message.data)
        assert schema.encoding == "jsonschema", schema.encoding
        counts[channel.topic] += 1
print(json.dumps(counts))
"#;
    let o = Command::new("python3")
        .args(["-c", script, path.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let counts: HashMap<String, u64> = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(counts["/can/raw"], FRAMES + 2);
    assert_eq!(counts["/can/JointAngles"], 500);
}
