//! `excavator-ctl trace ...` end to end: the binary on synthetic traces of the full schedule.

#![allow(clippy::unwrap_used)] // helpers outside #[test] functions fail loudly on purpose

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

use trace_tools::synth::{self, SynthConfig};

/// Frames of the standard fixture: 2 s of the synthetic schedule (1170 frames/s).
const FRAMES: u64 = 2340;

fn exe() -> &'static str {
    env!("CARGO_BIN_EXE_excavator-ctl")
}

fn fixture(dir: &Path, name: &str, frames: u64) -> PathBuf {
    let path = dir.join(name);
    let mut f = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
    let n = synth::write_candump(
        &mut f,
        &SynthConfig {
            frames,
            ..SynthConfig::default()
        },
    )
    .unwrap();
    assert_eq!(n, frames);
    path
}

fn trace(args: &[&str]) -> Output {
    Command::new(exe())
        .arg("trace")
        .args(args)
        .env("RUST_LOG", "warn")
        .output()
        .unwrap()
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn decode_prints_one_line_per_frame() {
    let dir = tempfile::tempdir().unwrap();
    let log = fixture(dir.path(), "dig.log", FRAMES);
    let o = trace(&["decode", log.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = stdout(&o);
    assert_eq!(out.lines().count() as u64, FRAMES);
    assert!(out.lines().all(|l| l.contains(" :: ")));
    assert!(!out.contains("!!"), "a synthetic frame is invalid:\n{out}");
    assert!(out.contains("JointAngles(BoomAngle: "), "{out}");
    assert!(out.contains("rad, StickAngle: "), "{out}");
    assert!(
        out.contains("ControllerStatus(Activity: Dig, AutodigStage: BoomDown"),
        "{out}"
    );
}

#[test]
fn decode_filters() {
    let dir = tempfile::tempdir().unwrap();
    let log = fixture(dir.path(), "dig.log", FRAMES);
    let log = log.to_str().unwrap();
    // 2 s at 100 Hz.
    let o = trace(&["decode", log, "--message", "JointAngles"]);
    assert_eq!(stdout(&o).lines().count(), 200);
    // Two families.
    let o = trace(&[
        "decode",
        log,
        "--message",
        "JointAngles",
        "--message",
        "ControllerStatus",
    ]);
    assert_eq!(stdout(&o).lines().count(), 240);
    // Signal: only that signal is printed.
    let o = trace(&["decode", log, "--signal", "AutodigStage"]);
    let out = stdout(&o);
    assert_eq!(out.lines().count(), 40);
    assert!(
        out.lines()
            .all(|l| l.ends_with("ControllerStatus(AutodigStage: BoomDown)")
                || l.contains("ControllerStatus(AutodigStage: PreDig)"))
    );
    // Source address: gateway frames only.
    let o = trace(&["decode", log, "--source-address", "0x80"]);
    let out = stdout(&o);
    assert!(out.lines().all(|l| l.contains("80#")), "{out}");
    // 100 + 100 + 3 x 100 + 50 + 20 + 10 (status) + 10 (session) frames/s over 2 s.
    assert_eq!(out.lines().count(), 2 * 590);
    // Time window: [0.5, 1.0] s holds 50 or 51 periods of JointAngles.
    let o = trace(&[
        "decode",
        log,
        "--message",
        "JointAngles",
        "--from",
        "0.5",
        "--to",
        "1.0",
    ]);
    let n = stdout(&o).lines().count();
    assert!((50..=51).contains(&n), "{n}");
    // Unknown names fail with a clear message.
    let o = trace(&["decode", log, "--message", "Nope"]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("unknown message \"Nope\""),
        "{}",
        stderr(&o)
    );
}

#[test]
fn decode_reads_stdin() {
    let dir = tempfile::tempdir().unwrap();
    let log = fixture(dir.path(), "dig.log", 500);
    let text = std::fs::read(&log).unwrap();
    let mut child = Command::new(exe())
        .args(["trace", "decode", "-"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    {
        let mut stdin = child.stdin.take().unwrap();
        stdin.write_all(&text).unwrap();
    }
    let o = child.wait_with_output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(stdout(&o).lines().count(), 500);
}

#[test]
fn malformed_lines_are_reported_skipped_or_fatal() {
    let dir = tempfile::tempdir().unwrap();
    let log = fixture(dir.path(), "dig.log", 100);
    let mut lines: Vec<String> = std::fs::read_to_string(&log)
        .unwrap()
        .lines()
        .map(str::to_string)
        .collect();
    lines[9] = "this is not candump".into();
    lines[49] = "(1700000000.1) vcan0 0CFE3027#00".into();
    let bad = dir.path().join("bad.log");
    std::fs::write(&bad, lines.join("\n") + "\n").unwrap();
    let bad = bad.to_str().unwrap();

    let o = trace(&["decode", bad]);
    assert!(o.status.success());
    assert_eq!(stdout(&o).lines().count(), 98);
    let err = stderr(&o);
    assert!(
        err.contains("line 10:") && err.contains("line 50:"),
        "{err}"
    );

    let o = trace(&["decode", bad, "--strict"]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("line 10"), "{}", stderr(&o));
    assert_eq!(stdout(&o).lines().count(), 9);

    let o = trace(&["stats", bad]);
    assert!(o.status.success());
    assert!(
        stdout(&o).contains("malformed lines: 10, 50"),
        "{}",
        stdout(&o)
    );
    assert!(!trace(&["stats", bad, "--strict"]).status.success());
}

#[test]
fn truncated_file_is_read_up_to_the_damage() {
    let dir = tempfile::tempdir().unwrap();
    let log = fixture(dir.path(), "dig.log", 100);
    let text = std::fs::read_to_string(&log).unwrap();
    // Cut inside the timestamp of line 51.
    let cut_at = text.match_indices('\n').nth(49).unwrap().0 + 8;
    let cut = dir.path().join("cut.log");
    std::fs::write(&cut, &text[..cut_at]).unwrap();
    let o = trace(&["decode", cut.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(stdout(&o).lines().count(), 50);
    assert!(stderr(&o).contains("line 51: truncated"), "{}", stderr(&o));
    let o = trace(&["decode", "--strict", cut.to_str().unwrap()]);
    assert!(!o.status.success());
    assert_eq!(stdout(&o).lines().count(), 50);
}

#[test]
fn stats_reports_rates_load_and_injected_faults() {
    let dir = tempfile::tempdir().unwrap();
    let log = fixture(dir.path(), "dig.log", 11_700);
    let text = std::fs::read_to_string(&log).unwrap();
    // Drop 50 ms of JointAngles (a gap), corrupt one heartbeat checksum, add an unknown id and an
    // error frame.
    let mut out = String::new();
    let mut angles = 0;
    let mut heartbeats = 0;
    for line in text.lines() {
        if line.contains(" 0CFF5080#") {
            angles += 1;
            if (300..305).contains(&angles) {
                continue;
            }
        }
        if line.contains(" 0CFF6127#") {
            heartbeats += 1;
            if heartbeats == 7 {
                let (head, data) = line.split_at(line.len() - 2);
                let flipped = if data == "00" { "01" } else { "00" };
                out += head;
                out += flipped;
                out.push('\n');
                continue;
            }
        }
        out += line;
        out.push('\n');
    }
    out += "(1700000010.000000) vcan0 18FEF100#FFFFFFFFFFFFFFFF\n";
    out += "(1700000010.000100) vcan0 20000004#0004000000000000\n";
    let faulty = dir.path().join("faulty.log");
    std::fs::write(&faulty, out).unwrap();

    let o = trace(&["stats", faulty.to_str().unwrap(), "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let r: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    let id = |hex: &str| {
        r["ids"]
            .as_array()
            .unwrap()
            .iter()
            .find(|i| i["id"] == hex)
            .unwrap()
            .clone()
    };
    let angles = id("0CFF5080");
    assert_eq!(angles["message"], "JointAngles");
    assert_eq!(angles["count"], 995);
    assert_eq!(angles["gaps"], 1);
    let gap = angles["first_gaps"][0]["length_ms"].as_f64().unwrap();
    assert!((gap - 60.0).abs() < 0.1, "{gap}");
    assert!((angles["rate_hz"].as_f64().unwrap() - 100.0).abs() < 1.0);
    let jitter = angles["period_std_ms"].as_f64().unwrap();
    assert!(jitter > 0.0 && jitter < 3.0, "{jitter}");
    let hb = id("0CFF6127");
    assert_eq!(hb["checksum_errors"], 1);
    assert_eq!(hb["alive_errors"], 0);
    assert_eq!(id("0CFF5480")["alive_errors"], 0);
    assert_eq!(id("18FF6227")["alive_errors"], 0);
    assert_eq!(r["unknown_id_frames"], 1);
    assert_eq!(r["error_frames"], 1);
    // The schedule with the sample stuffing is about 33 %; the peak is close to it.
    let load = r["bus_load"].as_f64().unwrap();
    assert!((0.25..0.37).contains(&load), "{load}");
    assert!(r["peak_load"].as_f64().unwrap() >= load);

    let o = trace(&["stats", faulty.to_str().unwrap()]);
    let text = stdout(&o);
    assert!(text.contains("bus load at 500000 bit/s"), "{text}");
    assert!(
        text.contains("0CFF5080 JointAngles (threshold 30.0 ms): 60.0 ms at"),
        "{text}"
    );
}

#[test]
fn plot_draws_signals_and_the_dig_preset() {
    let dir = tempfile::tempdir().unwrap();
    // One whole 12 s work cycle.
    let log = fixture(dir.path(), "dig.log", 14_100);
    let svg = dir.path().join("dig.svg");
    let o = trace(&[
        "plot",
        log.to_str().unwrap(),
        "--preset",
        "dig",
        "--out",
        svg.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = std::fs::read_to_string(&svg).unwrap();
    assert!(text.starts_with("<svg"), "{}", &text[..100]);
    for caption in [
        "joint angles",
        "cylinder pressures",
        "valve commands",
        "Autodig stage",
        "bucket-tip path",
        "pre-dig",
        "capture",
    ] {
        assert!(text.contains(caption), "missing {caption}");
    }
    let svg2 = dir.path().join("angles.svg");
    let o = trace(&[
        "plot",
        log.to_str().unwrap(),
        "--signal",
        "BoomAngle",
        "--signal",
        "StickAngle",
        "--signal",
        "Pump1Pressure",
        "--out",
        svg2.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = std::fs::read_to_string(&svg2).unwrap();
    assert!(text.contains("JointAngles.BoomAngle") && text.contains("signals [Pa]"));
    let o = trace(&[
        "plot",
        log.to_str().unwrap(),
        "--out",
        svg2.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
}

#[test]
fn convert_to_csv_is_wide_and_forward_filled() {
    let dir = tempfile::tempdir().unwrap();
    let log = fixture(dir.path(), "dig.log", FRAMES);
    let csv = dir.path().join("dig.csv");
    let o = trace(&[
        "convert",
        log.to_str().unwrap(),
        "--to",
        "csv",
        "--out",
        csv.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(header[0], "timestamp_s");
    assert_eq!(header[1], "t_s");
    assert!(header.contains(&"JointAngles.BoomAngle"));
    assert!(header.contains(&"ControllerStatus.AutodigStage"));
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len() as u64, FRAMES);
    assert!(rows.iter().all(|r| r.len() == header.len()));
    // After the first 10 ms period every 100 Hz signal has a value in every row.
    let boom = header
        .iter()
        .position(|h| *h == "JointAngles.BoomAngle")
        .unwrap();
    assert!(rows[20..].iter().all(|r| !r[boom].is_empty()));

    let csv2 = dir.path().join("step.csv");
    let o = trace(&[
        "convert",
        log.to_str().unwrap(),
        "--to",
        "csv",
        "--rows",
        "step",
        "--step-ms",
        "20",
        "--signal",
        "BoomAngle",
        "--out",
        csv2.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = std::fs::read_to_string(&csv2).unwrap();
    // 2 s at 20 ms: 100 rows (+1 final) and the header.
    let n = text.lines().count();
    assert!((101..=102).contains(&n), "{n}");
}

#[test]
fn diff_finds_where_a_run_departs() {
    let dir = tempfile::tempdir().unwrap();
    let a = fixture(dir.path(), "a.log", FRAMES);
    // B: the same run with the boom angle offset by 0.05 rad from t = 1 s.
    let text = std::fs::read_to_string(&a).unwrap();
    let mut out = String::new();
    for line in text.lines() {
        let rec = firmware_bridge::trace::parse_line(line).unwrap();
        let t = (rec.timestamp_ns - 1_700_000_000_000_000_000) as f64 * 1e-9;
        match firmware_bridge::Message::decode(&rec.frame)
            .unwrap()
            .message
        {
            firmware_bridge::Message::JointAngles(mut ja) if t >= 1.0 => {
                ja.boom_rad += 0.05;
                let f = firmware_bridge::Message::JointAngles(ja).encode().unwrap();
                out += &firmware_bridge::trace::format_line(rec.timestamp_ns, "vcan0", &f, None);
            }
            _ => out += line,
        }
        out.push('\n');
    }
    let b = dir.path().join("b.log");
    std::fs::write(&b, out).unwrap();
    let o = trace(&[
        "diff",
        a.to_str().unwrap(),
        b.to_str().unwrap(),
        "--tol",
        "BoomAngle=0.01",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = stdout(&o);
    assert!(text.contains("first divergence at 1.0"), "{text}");
    assert!(
        text.contains("JointAngles.BoomAngle |A-B| = 0.05"),
        "{text}"
    );
    let o = trace(&["diff", a.to_str().unwrap(), a.to_str().unwrap()]);
    assert!(stdout(&o).contains("no signal diverges"), "{}", stdout(&o));
}

#[test]
fn replay_without_the_interface_says_how_to_create_it() {
    let dir = tempfile::tempdir().unwrap();
    let log = fixture(dir.path(), "dig.log", 10);
    let o = trace(&["replay", log.to_str().unwrap(), "--iface", "nosuchcan0"]);
    assert!(!o.status.success());
    let err = stderr(&o);
    assert!(err.contains("cannot replay onto nosuchcan0"), "{err}");
    // Either the interface is missing, or the kernel has no SocketCAN at all; both say what to do
    // (for a name not starting with vcan: a real interface's set-up, not `type vcan`).
    assert!(
        err.contains("ip link set nosuchcan0 type can bitrate 500000")
            || err.contains("SocketCAN is not available"),
        "{err}"
    );
    let o = trace(&[
        "replay",
        log.to_str().unwrap(),
        "--iface",
        "vcan0",
        "--speed",
        "0",
    ]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("--speed must be a positive number"),
        "{}",
        stderr(&o)
    );
}
