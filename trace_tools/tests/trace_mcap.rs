//! `trace convert --to mcap`: the file reads back with the `mcap` crate (and with the Python `mcap`
//! reader and Foxglove's protobuf schema classes from PyPI when they are installed), one channel per
//! message, JSON messages matching their JSON schemas, the Foxglove view with its well-known schemas,
//! zstd chunks with chunk and message indexes, within a bound of the zstd-compressed candump log.

#![allow(clippy::unwrap_used)] // helpers outside #[test] functions fail loudly on purpose

use std::collections::HashMap;
use std::io::BufReader;
use std::path::Path;
use std::process::Command;

use trace_tools::convert;
use trace_tools::synth::{self, SynthConfig};

/// 5 s of the schedule (`synth::frames_in(5.0)`, checked by `the_fixture_is_five_seconds`).
const FRAMES: u64 = 5960;

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

fn convert_fixture(dir: &Path) -> (std::path::PathBuf, convert::ConvertSummary) {
    let log = dir.join("dig.log");
    write_fixture(&log);
    let out = dir.join("dig.mcap");
    let reader = BufReader::new(std::fs::File::open(&log).unwrap());
    let file = std::io::BufWriter::new(std::fs::File::create(&out).unwrap());
    let machine = planner::machine::MachineConfig::default_machine().unwrap();
    let summary = convert::to_mcap(reader, file, &machine, false, &mut std::io::sink()).unwrap();
    assert_eq!(summary.read.records, FRAMES + 2);
    assert_eq!(summary.written, FRAMES);
    // Per joint-angle frame (500) the frames and the signals, the machine's scene, log lines.
    assert!(summary.view_written > 1000, "{summary:?}");
    (out, summary)
}

/// The topics of the Foxglove view and their schema names (crate::view).
const VIEW: [(&str, &str, &str); 4] = [
    ("/tf", "foxglove.FrameTransforms", "protobuf"),
    ("/scene", "foxglove.SceneUpdate", "protobuf"),
    ("/log", "foxglove.Log", "protobuf"),
    ("/signals", "excavator.Signals", "jsonschema"),
];

#[test]
fn mcap_reads_back_with_the_mcap_crate() {
    let dir = tempfile::tempdir().unwrap();
    let (path, conv) = convert_fixture(dir.path());
    // Its size against the candump log: mcap_has_chunk_and_message_indexes_and_a_size_bound_...
    let bytes = std::fs::read(&path).unwrap();

    let summary = mcap::Summary::read(&bytes)
        .unwrap()
        .expect("a summary section");
    let stats = summary.stats.as_ref().expect("statistics");
    // Every project frame decoded, the unknown id and the error frame raw, and the view.
    assert_eq!(stats.message_count, FRAMES + 2 + conv.view_written);
    // 20 message channels (the periodic DBC messages, DM1 of both nodes) + /can/raw + the view's 4.
    assert_eq!(summary.channels.len(), 25);
    assert!(
        summary
            .chunk_indexes
            .iter()
            .all(|c| c.compression == "zstd"),
        "chunks not zstd-compressed"
    );

    let mut per_topic: HashMap<String, u64> = HashMap::new();
    let mut last_time = 0;
    for msg in mcap::MessageStream::new(&bytes).unwrap() {
        let msg = msg.unwrap();
        *per_topic.entry(msg.channel.topic.clone()).or_insert(0) += 1;
        assert!(msg.log_time >= 1_700_000_000_000_000_000);
        last_time = last_time.max(msg.log_time);
        if let Some((_, name, encoding)) = VIEW.iter().find(|v| v.0 == msg.channel.topic) {
            let schema = msg.channel.schema.as_ref().expect("a schema");
            assert_eq!(
                (schema.name.as_str(), schema.encoding.as_str()),
                (*name, *encoding)
            );
            if msg.channel.topic == "/tf" {
                use foxglove::Decode as _;
                let tf = foxglove::messages::FrameTransforms::decode(&msg.data[..]).unwrap();
                let children: Vec<&str> = tf
                    .transforms
                    .iter()
                    .map(|t| t.child_frame_id.as_str())
                    .collect();
                assert_eq!(
                    children,
                    ["base", "house", "boom", "stick", "bucket", "tip"]
                );
            }
            continue;
        }
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
    assert_eq!(per_topic["/can/raw"], 2);
    assert_eq!(per_topic["/can/JointAngles"], 500);
    assert_eq!(per_topic["/can/ControllerStatus"], 100);
    assert_eq!(per_topic["/can/GatewayStatus"], 100);
    assert_eq!(per_topic["/tf"], 500);
    assert_eq!(per_topic["/signals"], 500);
    assert_eq!(last_time, 1_700_000_005_000_100_000);
}

#[test]
fn mcap_reads_back_with_the_python_reader() {
    let have = Command::new("python3")
        .args(["-c", "import mcap.reader, foxglove_schemas_protobuf"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !have {
        if std::env::var("EXCAVATOR_REQUIRE_TOOLS").as_deref() == Ok("1") {
            panic!(
                "python3 with mcap and foxglove-schemas-protobuf is required (scripts/install-test-tools)"
            );
        }
        println!(
            "skip: python3 without mcap or foxglove-schemas-protobuf (scripts/install-test-tools)"
        );
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let (path, _) = convert_fixture(dir.path());
    // JSON channels parse; protobuf channels parse with Foxglove's published schema classes.
    let script = r#"
import json, sys
from collections import Counter
from mcap.reader import make_reader
from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
from foxglove_schemas_protobuf.Log_pb2 import Log
types = {"foxglove.FrameTransforms": FrameTransforms, "foxglove.SceneUpdate": SceneUpdate, "foxglove.Log": Log}
counts = Counter()
with open(sys.argv[1], "rb") as f:
    reader = make_reader(f)
    for schema, channel, message in reader.iter_messages():
        if schema.encoding == "protobuf":
            msg = types[schema.name]()
            msg.ParseFromString(message.data)
            if schema.name == "foxglove.FrameTransforms":
                assert [t.child_frame_id for t in msg.transforms][-1] == "tip"
        else:
            assert schema.encoding == "jsonschema", schema.encoding
            json.loads(message.data)
        counts[channel.topic] += 1
print(json.dumps(counts))
"#;
    let o = Command::new("python3")
        .args(["-c", script, path.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let counts: HashMap<String, u64> = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(counts["/can/raw"], 2);
    assert_eq!(counts["/can/JointAngles"], 500);
    assert_eq!(counts["/tf"], 500);
    assert_eq!(counts["/scene"], 1);
}

/// The MCAP file of the fixture may be at most this many times its candump log compressed with
/// zstd (level 3, the `zstd` tool's default); it measured 5.2. It carries more than the log: every
/// frame decoded to JSON, the Foxglove view (the machine's frames and the signals at each
/// joint-angle frame) and, uncompressed as the format has it, a 16-byte message index entry per
/// message. A demo session's trace is within 5 (`excavator_ctl/tests/live_view.rs`; docs/trace-tools.md
/// has the figures of a `demo --digs 10` trace).
const MAX_OVER_ZSTD_CANDUMP: f64 = 6.0;

#[test]
fn mcap_has_chunk_and_message_indexes_and_a_size_bound_against_a_zstd_candump() {
    let dir = tempfile::tempdir().unwrap();
    let (path, _) = convert_fixture(dir.path());
    let bytes = std::fs::read(&path).unwrap();
    let summary = mcap::Summary::read(&bytes)
        .unwrap()
        .expect("a summary section");
    assert!(!summary.chunk_indexes.is_empty(), "no chunk indexes");
    let stats = summary.stats.as_ref().expect("statistics");
    // Each chunk's message indexes name every message of the chunk, by channel.
    let mut indexed = 0;
    for chunk in &summary.chunk_indexes {
        assert_eq!(chunk.compression, "zstd");
        assert!(chunk.compressed_size < chunk.uncompressed_size, "{chunk:?}");
        let indexes = summary.read_message_indexes(&bytes, chunk).unwrap();
        assert!(
            !indexes.is_empty(),
            "chunk at {} has no message index",
            chunk.chunk_start_offset
        );
        for (channel, entries) in &indexes {
            for e in entries {
                assert!((chunk.message_start_time..=chunk.message_end_time).contains(&e.log_time));
            }
            // The first and last entries of a channel find their messages (each seek
            // decompresses the chunk up to the message).
            for e in [entries.first(), entries.last()].into_iter().flatten() {
                let m = summary.seek_message(&bytes, chunk, e).unwrap();
                assert_eq!(m.channel.id, channel.id);
                assert_eq!(m.log_time, e.log_time);
            }
            indexed += entries.len() as u64;
        }
    }
    assert_eq!(
        indexed, stats.message_count,
        "messages outside the message indexes"
    );

    let log = std::fs::read(dir.path().join("dig.log")).unwrap();
    let zstd_log = zstd::encode_all(&log[..], 3).unwrap().len();
    let ratio = bytes.len() as f64 / zstd_log as f64;
    println!(
        "MCAP {} bytes, candump {} bytes, zstd candump {zstd_log} bytes: {ratio:.2}x",
        bytes.len(),
        log.len()
    );
    assert!(
        ratio <= MAX_OVER_ZSTD_CANDUMP,
        "MCAP {} bytes is {ratio:.2}x the zstd candump ({zstd_log} bytes)",
        bytes.len()
    );
}

#[test]
fn the_fixture_is_five_seconds() {
    assert_eq!(FRAMES, synth::frames_in(5.0));
}
