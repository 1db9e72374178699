//! The live view end to end: `excavator-ctl demo --live` serves a session, a Foxglove WebSocket
//! client in Python (`foxglove_client.py`: `websockets` and Foxglove's protobuf schema classes from
//! PyPI, installed by scripts/install-test-tools) subscribes and decodes the machine's frames, the
//! terrain map, the signals, the scene and the log; then the session's trace converts to MCAP that
//! the Python `mcap` reader reads with the same schemas, smaller than the candump log. The operator
//! page in headless Chromium (`operator_page.py`, over the DevTools protocol) follows the session
//! and its e-stop button stops the machine: neutral valves in the trace.

#![allow(clippy::unwrap_used)] // helpers outside #[test] functions fail loudly on purpose

mod common;

use std::io::{BufRead as _, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::Duration;

use common::have_or_skip;

const CLIENT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/foxglove_client.py");
const BROWSER: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/operator_page.py");

fn python_has(modules: &str) -> bool {
    let have = Command::new("python3")
        .args(["-c", &format!("import {modules}")])
        .output()
        .is_ok_and(|o| o.status.success());
    have_or_skip(have, &format!("python3 with {modules}"))
}

/// A running `excavator-ctl demo --live 127.0.0.1:0` and the addresses it printed.
struct LiveDemo {
    child: Child,
    ws_url: String,
    page_url: String,
    stderr: std::thread::JoinHandle<Vec<String>>,
}

impl LiveDemo {
    /// Starts a demo of `digs` digs paced at `pace` times real time, writing into `out`.
    fn spawn(out: &Path, digs: &str, pace: &str) -> Self {
        let mut child = Command::new(env!("CARGO_BIN_EXE_excavator-ctl"))
            .args(["demo", "--digs", digs, "--quiet", "--live", "127.0.0.1:0"])
            .args(["--pace", pace, "--out"])
            .arg(out)
            .env("RUST_LOG", "info")
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        // The ports (0 picks them) are on stderr; keep reading it so the demo never blocks on the
        // pipe.
        let stderr = child.stderr.take().unwrap();
        let (url_tx, url_rx) = std::sync::mpsc::channel();
        let reader = std::thread::spawn(move || {
            let mut lines = Vec::new();
            for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                for scheme in ["ws://", "http://"] {
                    if let Some(at) = line.find(scheme) {
                        let url = line[at..].split_whitespace().next().unwrap().to_owned();
                        let _ = url_tx.send(url);
                    }
                }
                lines.push(line);
            }
            lines
        });
        let next = || url_rx.recv_timeout(Duration::from_secs(60)).unwrap();
        let (ws_url, page_url) = (next(), next());
        Self {
            child,
            ws_url,
            page_url,
            stderr: reader,
        }
    }

    /// Waits for the demo's end; checks that it and the Python `client` (`name`) succeeded;
    /// returns the JSON the client printed and the demo's log.
    fn report(mut self, name: &str, client: &Output) -> (serde_json::Value, String) {
        let status = self.child.wait().unwrap();
        let log = self.stderr.join().unwrap().join("\n");
        assert!(
            client.status.success(),
            "{name}: {}\ndemo: {log}",
            String::from_utf8_lossy(&client.stderr)
        );
        assert!(status.success(), "demo: {log}");
        (serde_json::from_slice(&client.stdout).unwrap(), log)
    }
}

#[test]
fn a_foxglove_client_sees_the_live_session_and_its_recording() {
    if !python_has("websockets, foxglove_schemas_protobuf, mcap.reader") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("demo");
    // Two digs (about 12 s at 5x): long enough for a client that starts slowly on a loaded machine.
    let demo = LiveDemo::spawn(&out, "2", "5");
    let client = Command::new("python3")
        .args([CLIENT, &demo.ws_url, "60"])
        .output()
        .unwrap();
    let (seen, log) = demo.report("client", &client);
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
    let zstd_len = zstd::encode_all(&std::fs::read(&trace).unwrap()[..], 3)
        .unwrap()
        .len() as u64;
    let ratio = mcap_len as f64 / zstd_len as f64;
    println!(
        "candump log {log_len} bytes (zstd -3: {zstd_len}), MCAP {mcap_len} bytes ({ratio:.2}x)"
    );
    assert!(mcap_len <= log_len, "MCAP {mcap_len} > candump {log_len}");
    // With a message index entry (16 bytes, uncompressed) per message: within 5x the zstd'd log.
    assert!(
        ratio <= 5.0,
        "MCAP {mcap_len} is {ratio:.2}x the zstd candump {zstd_len}"
    );
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

/// Where the browser test keeps its screenshot: `EXCAVATOR_TEST_ARTIFACTS`, or `test-artefacts` in
/// the target directory's scratch folder.
fn artefacts_dir() -> PathBuf {
    let dir = std::env::var_os("EXCAVATOR_TEST_ARTIFACTS").map_or_else(
        || PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("test-artefacts"),
        PathBuf::from,
    );
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Whether `chromium` (Debian's package) runs.
fn have_chromium() -> bool {
    let have = Command::new("chromium")
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    have_or_skip(have, "chromium")
}

#[test]
fn the_operator_page_follows_the_session_and_its_estop_stops_the_machine() {
    if !have_chromium() || !python_has("websockets.sync.client") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("demo");
    // A session longer than the browser's whole timeout (a dig takes about 12 s at 2x), so a
    // Chromium that starts slowly on a loaded machine still finds it running; Ctrl-C ends it.
    let demo = LiveDemo::spawn(&out, "20", "2");
    let screenshot = artefacts_dir().join("operator-page.png");
    let browser = Command::new("python3")
        .args([BROWSER, &demo.page_url])
        .arg(&screenshot)
        .arg("90")
        .output()
        .unwrap();
    // Ctrl-C ends the demo cleanly (neutral valves, trace closed, outputs written).
    let pid = demo.child.id().to_string();
    let _ = Command::new("kill").args(["-INT", &pid]).status();
    let (seen, log) = demo.report("browser", &browser);
    println!(
        "operator page: {seen}\nscreenshot: {}",
        screenshot.display()
    );
    assert!(std::fs::metadata(&screenshot).unwrap().len() > 10_000);
    // What the page showed: the state before and after the e-stop, the same as the controller's.
    assert!(seen["before"]["time_s"].as_f64().unwrap() > 1.0, "{seen}");
    assert_eq!(seen["before"]["fault"], serde_json::Value::Null, "{seen}");
    assert_eq!(seen["shown"]["safety"], "Faulted", "{seen}");
    assert_eq!(seen["shown"]["fault"], "emergency stop", "{seen}");
    assert!(seen["shown"]["updates"].as_u64().unwrap() >= 10, "{seen}");
    // The valves by the protocol's names, in % of full flow.
    let valves = seen["shown"]["valves"].as_str().unwrap();
    for name in [
        "Boom",
        "Stick",
        "Bucket",
        "Swing",
        "LeftTrack",
        "RightTrack",
    ] {
        assert!(valves.contains(name), "{valves}");
    }
    assert!(valves.contains(" %"), "{valves}");
    assert!(log.contains("operator e-stop"), "{log}");

    // The trace: the controller moved the machine before the e-stop and, once its status reports
    // the e-stop (fault code 5), commands neutral valves only.
    let text = std::fs::read_to_string(out.join("trace.log")).unwrap();
    let (mut moving_before, mut estop_at, mut neutral_after, mut moving_after) =
        (0_u32, None, 0_u32, 0_u32);
    for line in text.lines() {
        let Ok(rec) = firmware_bridge::trace::parse_line(line) else {
            continue;
        };
        if rec.direction != Some(firmware_bridge::trace::Direction::Transmit) {
            continue;
        }
        let Ok(d) = firmware_bridge::messages::Message::decode(&rec.frame) else {
            continue;
        };
        match d.message {
            firmware_bridge::messages::Message::ControllerStatus(s)
                if s.fault_reason == 5 && estop_at.is_none() =>
            {
                estop_at = Some(rec.timestamp_ns);
            }
            firmware_bridge::messages::Message::AuxValveCommand(c) => {
                let neutral = c == firmware_bridge::messages::AuxValveCommand::neutral(c.valve);
                match (estop_at, neutral) {
                    (None, false) => moving_before += 1,
                    (Some(_), true) => neutral_after += 1,
                    (Some(_), false) => moving_after += 1,
                    (None, true) => {}
                }
            }
            _ => {}
        }
    }
    assert!(estop_at.is_some(), "no e-stop status in the trace");
    assert!(
        moving_before > 0,
        "the machine never moved before the e-stop"
    );
    assert!(
        neutral_after >= 6,
        "no neutral valve commands after the e-stop"
    );
    assert_eq!(moving_after, 0, "valves commanded open after the e-stop");
}

#[test]
fn the_operator_page_keeps_the_sessions_last_state_after_it_ends() {
    if !have_chromium() || !python_has("websockets.sync.client") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("demo");
    // Two digs at 4x (about 15 s): the browser follows it from its start to its end.
    let demo = LiveDemo::spawn(&out, "2", "4");
    let screenshot = artefacts_dir().join("operator-page-finished.png");
    let browser = Command::new("python3")
        .args([BROWSER, &demo.page_url])
        .arg(&screenshot)
        .args(["120", "finish"])
        .output()
        .unwrap();
    let (seen, _) = demo.report("browser", &browser);
    println!(
        "operator page: {seen}\nscreenshot: {}",
        screenshot.display()
    );
    let shown = &seen["shown"];
    assert_eq!(
        shown["over"], "session finished: dig count reached",
        "{seen}"
    );
    assert_eq!(shown["connection"], "stream closed", "{seen}");
    // The last state stays: both digs done (numbered from 1), none in progress.
    assert_eq!(shown["digsDone"], "2", "{seen}");
    assert!(
        shown["lastDig"].as_str().unwrap().starts_with("dig 2 "),
        "{seen}"
    );
    assert_eq!(shown["digs"], "none (between digs)", "{seen}");
    assert_eq!(seen["after"]["session_over"], "dig count reached", "{seen}");
}
