//! `excavator-ctl trace ...` end to end: the binary on synthetic traces of the full schedule.

#![allow(clippy::unwrap_used)] // helpers outside #[test] functions fail loudly on purpose

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

use trace_tools::synth::{self, SynthConfig};

/// Frames of the standard fixture: 2 s of the synthetic schedule (`synth::frames_in(2.0)`, checked
/// by `the_fixture_is_two_seconds`).
const FRAMES: u64 = 2384;

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
    // 100 + 100 + 3 x 100 + 50 + 20 + 20 (status) + 20 (session) + 1 (DM1) frames/s over 2 s.
    assert_eq!(out.lines().count(), 2 * 611);
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
    let log = fixture(dir.path(), "dig.log", synth::frames_in(10.0));
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
    let log = fixture(dir.path(), "dig.log", synth::frames_in(12.05));
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
    // Pressures are drawn in MPa, their panel named for the unit.
    assert!(text.contains("JointAngles.BoomAngle") && text.contains("signals [MPa]"));
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

const OTHER_GATEWAY: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../examples/other_gateway.toml"
);

/// The standard fixture as the example gateway's wire frames (what `--profile` records).
fn profile_fixture(dir: &Path, frames: u64) -> PathBuf {
    let profile = firmware_bridge::profile::Profile::load(Path::new(OTHER_GATEWAY)).unwrap();
    let canonical = fixture(dir, "canonical.log", frames);
    let mut out = String::new();
    for line in std::fs::read_to_string(canonical).unwrap().lines() {
        let rec = firmware_bridge::trace::parse_line(line).unwrap();
        // Network management does not cross this (non-J1939) wire bus.
        if let Ok(wire) = profile.to_wire(&rec.frame) {
            out += &firmware_bridge::trace::format_line(rec.timestamp_ns, "vcan0", &wire, None);
            out.push('\n');
        }
    }
    let path = dir.join("wire.log");
    std::fs::write(&path, out).unwrap();
    path
}

/// `stats` on another gateway's trace listed every frame as an unknown id with no protocol checks;
/// with `--profile` the frames are the project's messages, checked against the profile's periods,
/// and `plot`, `convert` and `diff` read them too.
#[test]
fn every_trace_command_reads_a_profile_trace() {
    let dir = tempfile::tempdir().unwrap();
    let wire = profile_fixture(dir.path(), FRAMES);
    let wire = wire.to_str().unwrap();
    let o = trace(&["stats", wire, "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let plain: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert!(
        plain["unknown_id_frames"].as_u64().unwrap() > 2000,
        "{plain}"
    );

    let o = trace(&["stats", wire, "--profile", OTHER_GATEWAY, "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let r: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(r["unknown_id_frames"], 0, "{r}");
    assert_eq!(r["profile"], OTHER_GATEWAY);
    let ids = r["ids"].as_array().unwrap();
    let by_message = |name: &str| ids.iter().find(|i| i["message"] == name).unwrap().clone();
    let angles = by_message("JointAngles (ArmAngles)");
    // The example gateway's ArmAngles: 11-bit id, every 20 ms (its DBC's GenMsgCycleTime).
    assert_eq!(angles["id"].as_str().unwrap().len(), 3);
    assert_eq!(angles["nominal_hz"], 50.0);
    let heartbeat = by_message("ControllerHeartbeat (Heartbeat)");
    assert_eq!(heartbeat["checksum_errors"], 0);
    assert_eq!(heartbeat["alive_errors"], 0);
    // The six valve commands share one multiplexed wire id and are checked one by one.
    let valve_ids: Vec<_> = ids
        .iter()
        .filter(|i| {
            i["message"]
                .as_str()
                .unwrap()
                .starts_with("AuxValveCommand_")
        })
        .map(|i| i["id"].clone())
        .collect();
    assert_eq!(valve_ids.len(), 6);
    assert!(valve_ids.windows(2).all(|w| w[0] == w[1]), "{valve_ids:?}");

    let csv = dir.path().join("wire.csv");
    let o = trace(&[
        "convert",
        wire,
        "--to",
        "csv",
        "--out",
        csv.to_str().unwrap(),
        "--signal",
        "BoomAngle",
        "--profile",
        OTHER_GATEWAY,
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = std::fs::read_to_string(&csv).unwrap();
    assert!(text.lines().count() > 100, "{text}");
    let svg = dir.path().join("wire.svg");
    let o = trace(&[
        "plot",
        wire,
        "--signal",
        "BoomAngle",
        "--out",
        svg.to_str().unwrap(),
        "--profile",
        OTHER_GATEWAY,
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!stderr(&o).contains("no data"), "{}", stderr(&o));
    // The same scenario on the two gateways does not diverge.
    let canonical = dir.path().join("canonical.log");
    let o = trace(&[
        "diff",
        canonical.to_str().unwrap(),
        wire,
        "--profile-b",
        OTHER_GATEWAY,
        "--signal",
        "BoomAngle",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).contains("no signal diverges"), "{}", stdout(&o));
}

/// Plain `candump vcan0` output was refused as "bad direction marker"; it and the `-t` variants
/// read, with the times they carry.
#[test]
fn candump_screen_output_and_its_timestamp_variants_read() {
    let dir = tempfile::tempdir().unwrap();
    let log = fixture(dir.path(), "dig.log", 1170);
    let recs: Vec<_> = std::fs::read_to_string(&log)
        .unwrap()
        .lines()
        .map(|l| firmware_bridge::trace::parse_line(l).unwrap())
        .collect();
    let screen = |time: &dyn Fn(usize, u64) -> String| -> String {
        let mut s = String::new();
        for (i, r) in recs.iter().enumerate() {
            let id = match r.frame.id() {
                firmware_bridge::frame::CanId::Extended(id) => format!("{id:08X}"),
                firmware_bridge::frame::CanId::Standard(id) => format!("{id:03X}"),
            };
            let data: Vec<String> = r.frame.data().iter().map(|b| format!("{b:02X}")).collect();
            s += &format!(
                "{} vcan0  {id}   [{}]  {}\n",
                time(i, r.timestamp_ns),
                r.frame.len(),
                data.join(" ")
            );
        }
        s
    };
    let t0 = recs[0].timestamp_ns;
    let micros = |ns: u64| format!("{}.{:06}", ns / 1_000_000_000, ns % 1_000_000_000 / 1000);
    type Stamp<'a> = Box<dyn Fn(usize, u64) -> String + 'a>;
    let variants: [(&str, Stamp<'_>, &[&str]); 5] = [
        ("plain", Box::new(|_, _| String::new()), &[]),
        ("ta", Box::new(|_, t| format!(" ({})", micros(t))), &[]),
        (
            "tz",
            Box::new(move |_, t| format!(" ({})", micros(t - t0))),
            &[],
        ),
        (
            "td",
            Box::new(|i, t| format!(" ({})", micros(t - recs[i.saturating_sub(1)].timestamp_ns))),
            &["--delta-timestamps"],
        ),
        (
            "tA",
            // 1700000000 s is 2023-11-14 22:13:20 UTC; the fixture's frames are within a second.
            Box::new(|_, t| {
                let us = t % 1_000_000_000 / 1000;
                format!(
                    " (2023-11-14 22:13:2{}.{us:06})",
                    t / 1_000_000_000 - 1_700_000_000
                )
            }),
            &[],
        ),
    ];
    for (name, time, extra) in &variants {
        let path = dir.path().join(format!("{name}.txt"));
        std::fs::write(&path, screen(time.as_ref())).unwrap();
        let mut args = vec!["stats", path.to_str().unwrap(), "--json", "--strict"];
        args.extend_from_slice(extra);
        let o = trace(&args);
        assert!(o.status.success(), "{name}: {}", stderr(&o));
        let r: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
        assert_eq!(r["frames"], 1170, "{name}");
        assert_eq!(r["unknown_id_frames"], 0, "{name}");
        let span = r["span_s"].as_f64().unwrap();
        if *name == "plain" {
            assert_eq!(span, 0.0);
            assert!(stderr(&o).contains("without a timestamp"), "{}", stderr(&o));
        } else {
            let want = (recs[1169].timestamp_ns - t0) as f64 * 1e-9;
            assert!((span - want).abs() < 1e-5, "{name}: span {span} vs {want}");
        }
    }
}

/// A file of nothing but unparsable lines exited 0; every command now fails naming the file and
/// the first bad line.
#[test]
fn a_trace_without_one_frame_fails_naming_the_file_and_the_first_bad_line() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("junk.log");
    std::fs::write(&bad, "\nnot-a-frame\nneither\n").unwrap();
    let bad = bad.to_str().unwrap();
    let csv = dir.path().join("x.csv");
    let svg = dir.path().join("x.svg");
    for args in [
        vec!["decode", bad],
        vec!["stats", bad],
        vec![
            "convert",
            bad,
            "--to",
            "csv",
            "--out",
            csv.to_str().unwrap(),
        ],
        vec![
            "plot",
            bad,
            "--signal",
            "BoomAngle",
            "--out",
            svg.to_str().unwrap(),
        ],
        vec!["diff", bad, bad],
    ] {
        let o = trace(&args);
        assert!(!o.status.success(), "{args:?}");
        let err = stderr(&o);
        assert!(err.contains(bad), "{args:?}: {err}");
        assert!(
            err.contains("no CAN frame in 3 line(s): line 2 `not-a-frame`: expected"),
            "{args:?}: {err}"
        );
    }
}

/// The docs' example traces in `dir` (`docs/trace-tools.md`): `dig.log`, 24 s of the synthetic
/// schedule; `faulty.log`, the same with 5 `JointAngles` frames removed after 10 s, line 2000
/// damaged and an error frame appended; `sim.log`, the same with the boom angle 0.03 rad higher from
/// t = 6 s.
fn docs_example_traces(dir: &Path) {
    use firmware_bridge::Message;
    let cfg = SynthConfig {
        frames: synth::frames_in(24.0),
        ..SynthConfig::default()
    };
    let mut dig = String::new();
    let mut sim = String::new();
    for (t, frame) in synth::SyntheticTrace::new(cfg.clone()) {
        dig += &firmware_bridge::trace::format_line(t, &cfg.interface, &frame, None);
        dig.push('\n');
        let mut changed = frame;
        if t >= cfg.start_ns + 6_000_000_000
            && let Ok(Message::JointAngles(mut a)) = Message::decode(&frame).map(|d| d.message)
        {
            a.boom_rad += 0.03;
            changed = Message::JointAngles(a).encode().unwrap();
        }
        sim += &firmware_bridge::trace::format_line(t, &cfg.interface, &changed, None);
        sim.push('\n');
    }
    std::fs::write(dir.join("dig.log"), &dig).unwrap();
    std::fs::write(dir.join("sim.log"), &sim).unwrap();
    let mut lines: Vec<String> = Vec::new();
    let mut angles = 0;
    for line in dig.lines() {
        if line.contains(" 0CFF5080#") {
            angles += 1;
            if (1001..=1005).contains(&angles) {
                continue;
            }
        }
        lines.push(line.to_string());
    }
    lines[1999] = lines[1999].replacen('.', "x", 1);
    let stamp = lines.last().unwrap().split_once(' ').unwrap().0.to_string();
    lines.push(format!("{stamp} vcan0 20000004#0004000000000000"));
    std::fs::write(dir.join("faulty.log"), lines.join("\n") + "\n").unwrap();
}

/// One `$ excavator-ctl trace ...` line of a `console` block and the output the docs show for it.
struct DocsSample {
    command: String,
    shown: String,
}

/// The `excavator-ctl trace` samples of `doc` that run without a CAN interface (not `replay`).
fn docs_samples(doc: &str) -> Vec<DocsSample> {
    let mut samples = Vec::new();
    for block in doc.split("```console\n").skip(1) {
        let block = block.split_once("```").unwrap().0;
        let mut current: Option<DocsSample> = None;
        for line in block.lines() {
            if let Some(command) = line.strip_prefix("$ ") {
                samples.extend(current.take());
                current = (command.starts_with("excavator-ctl trace ")
                    && !command.starts_with("excavator-ctl trace replay"))
                .then(|| DocsSample {
                    command: command.to_string(),
                    shown: String::new(),
                });
            } else if let Some(sample) = current.as_mut() {
                sample.shown += line;
                sample.shown.push('\n');
            }
        }
        samples.extend(current);
    }
    samples
}

/// Runs a sample's command line (`excavator-ctl trace ...`, optionally `| head -N`) in `dir`:
/// stderr, then stdout.
fn run_docs_sample(dir: &Path, command: &str) -> String {
    let (command, head) = match command.split_once(" | head -") {
        Some((c, n)) => (c, Some(n.trim().parse::<usize>().unwrap())),
        None => (command, None),
    };
    let args: Vec<&str> = command.split_whitespace().skip(1).collect();
    let o = Command::new(exe())
        .current_dir(dir)
        .args(&args)
        .env("RUST_LOG", "warn")
        .output()
        .unwrap();
    assert!(o.status.success(), "{command}: {}", stderr(&o));
    let out = stdout(&o);
    let out = match head {
        Some(n) => out.lines().take(n).map(|l| format!("{l}\n")).collect(),
        None => out,
    };
    stderr(&o) + &out
}

/// Every `excavator-ctl trace` sample of `docs/trace-tools.md` prints what the page shows, on the
/// traces the page describes. `EXCAVATOR_UPDATE_DOCS=1` writes what the commands print into the page.
#[test]
fn the_trace_tools_page_shows_what_the_commands_print() {
    let page = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/trace-tools.md");
    let doc = std::fs::read_to_string(&page).unwrap();
    let dir = tempfile::tempdir().unwrap();
    docs_example_traces(dir.path());
    let normal = |s: &str| {
        s.lines()
            .map(str::trim_end)
            .collect::<Vec<_>>()
            .join("\n")
            .trim()
            .to_string()
    };
    let samples = docs_samples(&doc);
    assert!(samples.len() >= 7, "{} samples", samples.len());
    let mut updated = doc.clone();
    let mut differing = Vec::new();
    for sample in &samples {
        let printed = run_docs_sample(dir.path(), &sample.command);
        if normal(&printed) != normal(&sample.shown) {
            let shown = format!("$ {}\n{}", sample.command, sample.shown);
            let now = format!("$ {}\n{}\n", sample.command, normal(&printed));
            updated = updated.replacen(&shown, &now, 1);
            differing.push(format!("$ {}\n{printed}", sample.command));
        }
    }
    if std::env::var_os("EXCAVATOR_UPDATE_DOCS").is_some() {
        std::fs::write(&page, updated).unwrap();
        return;
    }
    assert!(
        differing.is_empty(),
        "docs/trace-tools.md differs from what these commands print (EXCAVATOR_UPDATE_DOCS=1 \
         cargo test -p excavator-ctl --test trace_cli writes them):\n{}",
        differing.join("\n")
    );
}

#[test]
fn the_fixture_is_two_seconds() {
    assert_eq!(FRAMES, synth::frames_in(2.0));
}
