//! `excavator-ctl run` and the link of its interface over netlink (docs/deployment.md, "The CAN
//! link"): a down interface and a missing one are refused with one line of advice for their kind,
//! and an up vcan is reported honestly (no bitrate, no state) in the log and the session summary.
//! A vcan has no listen-only control mode; that decision is unit-tested on the parsed status
//! (firmware_bridge `transport::link`).
//!
//! They need a kernel with vcan, so they are `#[ignore]`d in a plain `cargo test` and run through
//! `scripts/vcan-vm`.

#![allow(clippy::unwrap_used)]

use std::process::{Command, Output};
use std::time::Duration;

use hil_tests::process::Proc;

/// `excavator-ctl run --listen-only` on `iface`, expected to refuse at once.
fn run_refused(iface: &str) -> (Output, String) {
    let out = Command::new(hil_tests::env::binary("excavator-ctl"))
        .args(["run", "--listen-only", "--iface", iface])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    (out, stderr)
}

/// The `error:` line of `stderr`; panics unless there is exactly one line.
fn one_error_line(stderr: &str) -> &str {
    let lines: Vec<&str> = stderr.lines().filter(|l| !l.trim().is_empty()).collect();
    assert_eq!(lines.len(), 1, "{stderr}");
    assert!(lines[0].starts_with("error: "), "{stderr}");
    lines[0]
}

fn ip(args: &[&str]) {
    let st = Command::new("ip").args(args).status().unwrap();
    assert!(st.success(), "ip {args:?}");
}

/// A second vcan, down, deleted on drop (vcan0 stays up for the other tests).
struct DownVcan(&'static str);

impl DownVcan {
    fn new(name: &'static str) -> Self {
        ip(&["link", "add", "dev", name, "type", "vcan"]);
        ip(&["link", "set", name, "down"]);
        Self(name)
    }
}

impl Drop for DownVcan {
    fn drop(&mut self) {
        let _ = Command::new("ip").args(["link", "del", self.0]).status();
    }
}

#[test]
#[ignore = "needs a kernel with vcan: run through scripts/vcan-vm"]
fn run_refuses_a_down_interface() {
    hil_tests::env::vcan_iface();
    let down = DownVcan::new("vcandown0");
    let (_, stderr) = run_refused(down.0);
    let line = one_error_line(&stderr);
    assert!(
        line.contains("vcandown0 is down") && line.contains("(ip link set vcandown0 up)"),
        "{line}"
    );
}

#[test]
#[ignore = "needs a kernel with vcan: run through scripts/vcan-vm"]
fn run_on_a_missing_interface_advises_for_its_kind() {
    hil_tests::env::vcan_iface();
    let (_, real) = run_refused("can7");
    let line = one_error_line(&real);
    assert!(
        line.contains("\"can7\" not found")
            && line.contains(
                "ip link set can7 type can bitrate 500000 restart-ms 100 && ip link set can7 up"
            )
            && !line.contains("vcan"),
        "{line}"
    );
    let (_, virt) = run_refused("vcan7");
    let line = one_error_line(&virt);
    assert!(
        line.contains("ip link add dev vcan7 type vcan && ip link set up vcan7"),
        "{line}"
    );
}

#[test]
#[ignore = "needs a kernel with vcan: run through scripts/vcan-vm"]
fn run_reports_a_vcan_link_without_a_bitrate_and_monitors_listen_only() {
    let iface = hil_tests::env::vcan_iface();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("session");
    let mut ctl = Proc::spawn(
        "excavator-ctl",
        &hil_tests::env::binary("excavator-ctl"),
        &[
            "run",
            "--listen-only",
            "--iface",
            &iface,
            "--out",
            out.to_str().unwrap(),
        ],
        &dir.path().join("ctl.log"),
    );
    let link = format!(
        "CAN link: {iface} up, bitrate none (virtual interface), state none (virtual interface), \
         restart-ms none (virtual interface), listen-only off"
    );
    assert!(
        ctl.wait_for_log(&link, Duration::from_secs(60)),
        "{}",
        ctl.log_tail(40)
    );
    std::thread::sleep(Duration::from_secs(2));
    ctl.signal("15");
    let status = ctl.wait_timeout(Duration::from_secs(20));
    assert!(status.is_some_and(|s| s.success()), "{}", ctl.log_tail(40));
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let recorded = &summary["can_link"];
    assert_eq!(recorded["iface"], iface.as_str(), "{summary}");
    assert!(recorded["bitrate_bps"].is_null(), "{recorded}");
    assert!(recorded["state"].is_null(), "{recorded}");
    assert_eq!(recorded["up"], true);
    let md = std::fs::read_to_string(out.join("summary.md")).unwrap();
    assert!(
        md.contains(&format!("CAN link at start: {iface} up")),
        "{md}"
    );
    let run_log = std::fs::read_to_string(out.join("run.log")).unwrap();
    assert!(run_log.contains("CAN link: "), "{run_log}");
    // Listen-only: the trace holds no frame this controller sent.
    let trace = std::fs::read_to_string(out.join("trace.log")).unwrap_or_default();
    assert!(!trace.lines().any(|l| l.ends_with(" T")), "{trace}");
}
