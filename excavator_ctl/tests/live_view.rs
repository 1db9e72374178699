//! The live view end to end: `excavator-ctl demo --live` serves a session, a Foxglove WebSocket
//! client in Python (`foxglove_client.py`: `websockets` and Foxglove's protobuf schema classes from
//! PyPI, installed by scripts/install-test-tools) subscribes and decodes the machine's frames, the
//! terrain map, the signals, the scene and the log; then the session's trace converts to MCAP that
//! the Python `mcap` reader reads with the same schemas, smaller than the candump log.

#![allow(clippy::unwrap_used)] // helpers outside #[test] functions fail loudly on purpose

use std::io::{BufRead as _, BufReader};
use std::process::{Command, Stdio};
use std::time::Duration;

const CLIENT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/foxglove_client.py");

fn python_has(modules: &str) -> bool {
    let have = Command::new("python3")
        .args(["-c", &format!("import {modules}")])
        .output()
        .is_ok_and(|o| o.status.success());
    if !have {
        assert!(
            std::env::var("EXCAVATOR_REQUIRE_TOOLS").as_deref() != Ok("1"),
            "python3 with {modules} is required (scripts/install-test-tools)"
        );
        println!("skip: python3 without {modules} (scripts/install-test-tools)");
    }
    have
}

#[test]
fn a_foxglove_client_sees_the_live_session_and_its_recording() {
    if !python_has("websockets, foxglove_schemas_protobuf, mcap.reader") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("demo");
    let mut demo = Command::new(env!("CARGO_BIN_EXE_excavator-ctl"))
        .args(["demo", "--digs", "1", "--quiet", "--live", "127.0.0.1:0"])
        .args(["--pace", "5", "--out"])
        .arg(&out)
        .env("RUST_LOG", "info")
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The port (0 picks one) is on stderr; keep reading it so the demo never blocks on the pipe.
    let stderr = demo.stderr.take().unwrap();
    let (url_tx, url_rx) = std::sync::mpsc::channel();
    let reader = std::thread::spawn(move || {
        let mut lines = Vec::new();
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            if let Some(at) = line.find("ws://") {
                let url = line[at..].split_whitespace().next().unwrap().to_owned();
                let _ = url_tx.send(url);
            }
            lines.push(line);
        }
        lines
    });
    let url = url_rx.recv_timeout(Duration::from_secs(60)).unwrap();
    let client = Command::new("python3")
        .args([CLIENT, &url, "60"])
        .output()
        .unwrap();
    let status = demo.wait().unwrap();
    let log = reader.join().unwrap().join("\n");
    assert!(
        client.status.success(),
        "client: {}\ndemo: {log}",
        String::from_utf8_lossy(&client.stderr)
    );
    assert!(status.success(), "demo: {log}");
    let seen: serde_json::Value = serde_json::from_slice(&client.stdout).unwrap();
    let topics = &seen["topics"];
    for (topic, schema) in [
        ("/tf", "foxglove.FrameTransforms"),
        ("/terrain", "foxglove.Grid"),
        ("/scene", "foxglove.SceneUpdate"),
        ("/log", "foxglove.Log"),
        ("/signals", "excavator.Signals"),
    ] {
        assert_eq!(topics[topic]["schemaName"], schema, "{seen}");
        assert!(topics[topic]["count"].as_u64().unwrap() >= 1, "{seen}");
    }
    assert!(topics["/tf"]["count"].as_u64().unwrap() >= 50, "{seen}");
    assert_eq!(
        seen["frames"],
        serde_json::json!(["base", "house", "boom", "stick", "bucket", "tip"])
    );
    // The terrain map after the first scan: the grid of the bench, part of it seen.
    let grid = &seen["grid"];
    assert_eq!(grid["frame_id"], "world");
    assert_eq!(grid["columns"], 360);
    assert!(grid["known"].as_u64().unwrap() > 1000, "{seen}");
    // The signals carry the estimate and the controller's status.
    let signals = &seen["signals"];
    assert!(signals["pressure_pa"]["boom_head"].as_f64().unwrap() > 0.0);
    assert!(signals["activity"].is_string(), "{seen}");
    assert!(signals["safety_state"].is_string(), "{seen}");
    assert!(log.contains("live stream"), "{log}");

    // The recording of the same session, as MCAP with the same schemas.
    let trace = out.join("trace.log");
    let mcap = out.join("trace.mcap");
    let o = Command::new(env!("CARGO_BIN_EXE_excavator-ctl"))
        .args(["trace", "convert"])
        .arg(&trace)
        .args(["--to", "mcap", "--out"])
        .arg(&mcap)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (log_len, mcap_len) = (
        std::fs::metadata(&trace).unwrap().len(),
        std::fs::metadata(&mcap).unwrap().len(),
    );
    println!("candump log {log_len} bytes, MCAP {mcap_len} bytes");
    assert!(mcap_len <= log_len, "MCAP {mcap_len} > candump {log_len}");
    let script = r#"
import json, sys
from collections import Counter
from mcap.reader import make_reader
from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
counts, schemas = Counter(), {}
with open(sys.argv[1], "rb") as f:
    for schema, channel, message in make_reader(f).iter_messages():
        counts[channel.topic] += 1
        schemas[channel.topic] = schema.name
        if schema.name == "foxglove.FrameTransforms":
            m = FrameTransforms()
            m.ParseFromString(message.data)
            assert m.transforms[-1].child_frame_id == "tip"
print(json.dumps({"counts": counts, "schemas": schemas}))
"#;
    let o = Command::new("python3")
        .args(["-c", script])
        .arg(&mcap)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let read: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(read["schemas"]["/tf"], "foxglove.FrameTransforms");
    assert_eq!(read["schemas"]["/signals"], "excavator.Signals");
    assert!(read["counts"]["/tf"].as_u64().unwrap() > 1000, "{read}");
}
