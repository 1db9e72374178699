//! A `demo` trace read by can-utils' `log2asc` (Debian's `can-utils`, installed by
//! scripts/install-test-tools) as one log: the trace's virtual time is stamped from the fixed epoch
//! (docs/demo-output.md), so the tool dates it and writes its header once. With stamps near 1970 it
//! wrote the header again before every frame.

#![allow(clippy::unwrap_used)] // helpers outside #[test] functions fail loudly on purpose

mod common;

use std::path::Path;
use std::process::{Command, Stdio};

use common::have_or_skip;

fn have_log2asc() -> bool {
    // `log2asc -?` prints its usage (and exits non-zero): it runs.
    let runs = Command::new("log2asc")
        .arg("-?")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok();
    have_or_skip(runs, "log2asc (can-utils)")
}

/// Runs `excavator-ctl demo --digs 1` into `out`; returns the session's length, s.
fn demo(out: &Path) -> f64 {
    let status = Command::new(env!("CARGO_BIN_EXE_excavator-ctl"))
        .args(["demo", "--digs", "1", "--quiet", "--out"])
        .arg(out)
        .status()
        .unwrap();
    assert!(status.success(), "demo: {status}");
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["trace_clock"], "virtual");
    summary["totals"]["sim_time_s"].as_f64().unwrap()
}

/// Its header once, dated at the epoch (2000-01-01), then one event per frame with the time since the
/// first frame, in order, spanning the session.
#[test]
fn log2asc_reads_a_demo_trace_as_one_log_dated_at_the_epoch() {
    if !have_log2asc() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("demo");
    let session_s = demo(&out);
    let trace = out.join("trace.log");
    let asc = dir.path().join("trace.asc");
    let status = Command::new("log2asc")
        .arg("-I")
        .arg(&trace)
        .arg("-O")
        .arg(&asc)
        .arg("vcan0")
        .status()
        .unwrap();
    assert!(status.success(), "log2asc: {status}");
    let text = std::fs::read_to_string(&asc).unwrap();
    let headers: Vec<&str> = text.lines().filter(|l| l.starts_with("date ")).collect();
    assert_eq!(headers, ["date Sat Jan  1 00:00:00 2000"]);
    let times: Vec<f64> = text
        .lines()
        .filter_map(|l| l.split_whitespace().next()?.parse::<f64>().ok())
        .collect();
    let frames = std::fs::read_to_string(&trace).unwrap().lines().count();
    assert_eq!(times.len(), frames, "one ASC event per frame");
    assert_eq!(times[0], 0.0);
    assert!(times.windows(2).all(|w| w[0] <= w[1]), "times in order");
    let span_s = times[times.len() - 1];
    assert!(
        span_s > 0.9 * session_s && span_s <= session_s,
        "the ASC log spans {span_s} s of a {session_s} s session"
    );
    println!("log2asc: {frames} frames over {span_s:.2} s, one header: {headers:?}");
}
