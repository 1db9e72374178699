//! Logs written by the project are read by the real tools: `cantools decode` (PyPI) with
//! `excavator.dbc`, python-can's candump log reader, and can-utils' `log2asc` (Debian).
//!
//! A missing tool skips the test with a printed line, or fails it when `EXCAVATOR_REQUIRE_TOOLS=1`.

mod common;

use std::io::{BufReader, Write};
use std::path::Path;
use std::process::{Command, Stdio};

use firmware_bridge::messages::*;
use firmware_bridge::trace::{Direction, ReadMode, Recorder, TraceReader, TraceRecord};
use firmware_bridge::{CanFrame, CanId, dbc};

const DBC: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../gateway_core/excavator.dbc");
const T0_NS: u64 = 1_700_000_000_000_000_000;

/// The samples plus values swept across every signal's range.
fn varied_messages() -> Vec<Message> {
    let mut out = common::sample_messages();
    for i in 0..60u32 {
        let f = f64::from(i);
        let angle_min = dbc::joint_angles::BOOM_ANGLE.min;
        let angle = |k: u32| f64::from((i * k) % 62833) * 1e-4 + angle_min;
        out.push(Message::JointAngles(JointAngles {
            boom_rad: angle(7919),
            stick_rad: angle(104_729),
            bucket_rad: angle(1299),
            swing_rad: angle(15_485),
        }));
        out.push(Message::JointRates(JointRates {
            boom_rad_per_s: (f - 30.0) * 0.777,
            stick_rad_per_s: (30.0 - f) * 0.0123,
            bucket_rad_per_s: f * 0.5 - 15.0,
            swing_rad_per_s: -0.001 * f,
        }));
        let valve = Valve::from_number((i % 6) as u8).expect("0..6");
        out.push(Message::AuxValveCommand(
            AuxValveCommand::from_fraction(valve, f / 30.0 - 1.0).expect("in range"),
        ));
        out.push(Message::AuxValveMeasured(AuxValveMeasured {
            cylinder: Cylinder::ALL[(i % 3) as usize],
            flow_percent: f * 2.6667,
            state: [ValveState::Block, ValveState::Extend, ValveState::Retract][(i % 3) as usize],
            head_pressure_pa: (f * 1.234e6) % 100e6,
            rod_pressure_pa: f * 0.505e6,
        }));
        out.push(Message::PumpPressures(PumpPressures {
            pump1_pa: f * 1.0e6,
            pump2_pa: 60e6 - f * 0.9e6,
        }));
        out.push(Message::TrackOdometry(TrackOdometry {
            left_m: (f - 30.0) * 1234.5678,
            right_m: f * 0.0001,
        }));
        // Each setpoint on its own signal's grid and range (the joints' ranges differ).
        let on_grid = |sig: &dbc::SignalDesc, k: i64| {
            let steps = sig.raw_max - sig.raw_min + 1;
            let raw = sig.raw_min + (i64::from(i) * k).rem_euclid(steps);
            raw as f64 * sig.factor + sig.offset
        };
        out.push(Message::PositionSetpoint(PositionSetpoint {
            boom_rad: on_grid(&dbc::position_setpoint::BOOM_SETPOINT, 3),
            stick_rad: on_grid(&dbc::position_setpoint::STICK_SETPOINT, 5),
            bucket_rad: on_grid(&dbc::position_setpoint::BUCKET_SETPOINT, 11),
            swing_rad: on_grid(&dbc::position_setpoint::SWING_SETPOINT, 13),
        }));
        out.push(Message::ControllerStatus(ControllerStatus {
            activity: Activity::Dig,
            stage: AutodigStageCode::PreDig,
            dig_index: (i * 37) as u16,
            hardness_index: f64::from((i % 250) as u8) * 0.05,
            swept_volume_m3: f * 0.0001,
            fault_reason: (i % 7) as u8,
            alive_counter: (i % 16) as u8,
        }));
        out.push(Message::ControllerHeartbeat(ControllerHeartbeat {
            mode: [
                RequestedMode::Disarm,
                RequestedMode::ArmValve,
                RequestedMode::ArmPosition,
                RequestedMode::EStop,
                RequestedMode::ResetEStop,
            ][(i % 5) as usize],
            alive_counter: (i % 16) as u8,
        }));
        out.push(Message::GatewayStatus(GatewayStatus {
            mode: [
                GatewayMode::Disarmed,
                GatewayMode::ArmedValve,
                GatewayMode::ArmedPosition,
                GatewayMode::Faulted,
            ][(i % 4) as usize],
            faults: GatewayFaults(((i * 37) % 65536) as u16),
            alive_counter: (i * 5 % 256) as u8,
            unexpected_frames: (i * 1000 % 65536) as u16,
            rejected_frames: i as u16,
        }));
    }
    out
}

/// Writes `frames` with the project's recorder (with ` R`/` T` markers) and returns the records.
fn write_trace(path: &Path, frames: &[CanFrame]) -> Vec<TraceRecord> {
    let rec = Recorder::create(path, "vcan0").expect("create trace");
    for (n, frame) in frames.iter().enumerate() {
        let dir = if n % 2 == 0 {
            Direction::Transmit
        } else {
            Direction::Receive
        };
        rec.record(T0_NS + n as u64 * 1_000_123, dir, frame);
    }
    let stats = rec.close().expect("close trace");
    assert_eq!(stats.dropped, 0);
    let file = BufReader::new(std::fs::File::open(path).expect("open trace"));
    TraceReader::new(file, ReadMode::Stop)
        .map(|r| r.expect("own trace parses"))
        .collect()
}

fn run(program: &str, args: &[&str], stdin_path: Option<&Path>) -> String {
    let stdin = match stdin_path {
        Some(p) => Stdio::from(std::fs::File::open(p).expect("open stdin file")),
        None => Stdio::null(),
    };
    let out = Command::new(program)
        .args(args)
        .stdin(stdin)
        .output()
        .expect("run tool");
    assert!(
        out.status.success(),
        "{program} {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).expect("tool output is UTF-8")
}

#[test]
fn cantools_decode_agrees_with_our_decoder() {
    // The controller's frames sealed as on the bus, so the trailer signals are compared too.
    let mut sealer =
        firmware_bridge::secoc::Sealer::new(&firmware_bridge::secoc::SessionKey::PUBLIC);
    sealer.set_session(0x5EC0_0C01);
    if !common::tool_available(
        "cantools",
        "cantools",
        &["--version"],
        "pip install cantools",
    ) {
        return;
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("project.log");
    let messages = varied_messages();
    let frames: Vec<CanFrame> = messages
        .iter()
        .map(|m| sealer.seal(m).expect("encodes"))
        .chain(
            common::gateway_sourced_samples()
                .into_iter()
                .map(|(_, f)| f),
        )
        .collect();
    let records = write_trace(&path, &frames);
    let out = run(
        "cantools",
        &["decode", "--single-line", "--no-decode-choices", DBC],
        Some(&path),
    );
    let lines: Vec<&str> = out.lines().filter(|l| !l.trim().is_empty()).collect();
    assert_eq!(
        lines.len(),
        records.len(),
        "cantools printed one line per frame"
    );

    let mut compared = 0;
    for (line, record) in lines.iter().zip(&records) {
        let decoded = Message::decode(&record.frame).expect("our decoder accepts our frames");
        let (_, body) = line
            .split_once(" :: ")
            .unwrap_or_else(|| panic!("cantools did not decode: {line}"));
        let (name, rest) = body.split_once('(').expect("Name(...)");
        // The DBC message of the frame's id: the gateway's claim and DM1 have their own.
        let dbc_name = dbc::MESSAGES
            [dbc::message_index_by_id(record.frame.id().raw()).expect("a project message")]
        .name;
        assert_eq!(name, dbc_name, "{line}");
        let inner = rest.strip_suffix(')').expect("closing parenthesis");
        let ours = decoded.signal_values();
        let theirs: Vec<(&str, f64)> = inner
            .split(", ")
            .map(|item| {
                let (sig, value) = item.split_once(": ").expect("Signal: value");
                let number = value.split_whitespace().next().expect("a value");
                (
                    sig,
                    number
                        .parse::<f64>()
                        .unwrap_or_else(|_| panic!("number in {item}")),
                )
            })
            .collect();
        assert_eq!(theirs.len(), ours.len(), "{line}");
        for ((sig, their), (our_sig, our)) in theirs.iter().zip(&ours) {
            assert_eq!(sig, our_sig, "{line}");
            // cantools shows the 0.4 %/bit standard flow byte; ours is the fine flow.
            let tol = if *sig == "PortFlowCommand" {
                dbc::aux_valve_command_boom::PORT_FLOW_COMMAND.factor / 2.0 + 1e-9
            } else {
                1e-9 * (1.0 + our.abs())
            };
            assert!(
                (their - our).abs() <= tol,
                "{sig}: cantools {their}, ours {our} in {line}"
            );
            compared += 1;
        }
    }
    println!(
        "cantools decode: {} frames, {compared} signal values agree",
        records.len()
    );
}

/// Frames of every kind the trace format has: project messages plus standard, remote, error and FD.
fn mixed_frames() -> Vec<CanFrame> {
    let mut frames: Vec<CanFrame> = common::sample_messages()
        .iter()
        .map(|m| m.encode().expect("encodes"))
        .collect();
    frames.push(CanFrame::new_standard(0x123, &[0xDE, 0xAD]).expect("frame"));
    frames.push(CanFrame::new_standard(0x7FF, &[]).expect("frame"));
    frames.push(CanFrame::new_remote(CanId::Standard(0x123), 5).expect("frame"));
    frames.push(CanFrame::new_remote(CanId::Extended(0x0CFF_5080), 0).expect("frame"));
    // Bus error (0x80) with a protocol violation (0x08): python-can recognises error frames by 0x80.
    frames.push(CanFrame::new_error(0x88, [0, 0, 0x08, 0, 0, 0, 0, 0]).expect("frame"));
    frames.push(CanFrame::new_fd(CanId::Standard(0x456), &[0x11; 12], 1).expect("frame"));
    frames
}

#[test]
fn python_can_reads_our_log() {
    if !common::tool_available(
        "python-can",
        "python3",
        &["-c", "import can"],
        "pip install python-can",
    ) {
        return;
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("mixed.log");
    let records = write_trace(&path, &mixed_frames());
    let script = "import can, sys\n\
        for m in can.LogReader(sys.argv[1]):\n\
        \x20   print(f'{m.timestamp:.6f} {m.arbitration_id:08X} {int(m.is_extended_id)} {int(m.is_remote_frame)} {int(m.is_error_frame)} {int(m.is_fd)} {m.dlc} {bytes(m.data or b\"\").hex().upper()} {int(m.is_rx)}')\n";
    let path_str = path.to_str().expect("UTF-8 temp path");
    let out = run("python3", &["-c", script, path_str], None);
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(lines.len(), records.len());
    for (line, rec) in lines.iter().zip(&records) {
        let f: Vec<&str> = line.split(' ').collect();
        let ts: f64 = f[0].parse().expect("timestamp");
        assert!((ts - rec.timestamp_ns as f64 * 1e-9).abs() < 2e-6, "{line}");
        let frame = &rec.frame;
        assert_eq!(f[4] == "1", frame.is_error(), "{line}");
        if frame.is_error() {
            continue; // python-can keeps no id or data for error frames
        }
        assert_eq!(
            u32::from_str_radix(f[1], 16).expect("hex id"),
            frame.id().raw(),
            "{line}"
        );
        assert_eq!(f[2] == "1", frame.is_extended(), "{line}");
        assert_eq!(f[3] == "1", frame.is_remote(), "{line}");
        assert_eq!(f[5] == "1", frame.is_fd(), "{line}");
        assert_eq!(f[6].parse::<usize>().expect("dlc"), frame.dlc(), "{line}");
        let hex: String = frame.data().iter().map(|b| format!("{b:02X}")).collect();
        assert_eq!(f.get(7).copied().unwrap_or(""), hex, "{line}");
        assert_eq!(
            f[8] == "1",
            rec.direction == Some(Direction::Receive),
            "{line}"
        );
    }
    println!("python-can read {} frames of every kind", records.len());
}

#[test]
fn log2asc_converts_our_log() {
    if !common::tool_available(
        "log2asc (can-utils)",
        "sh",
        &["-c", "command -v log2asc"],
        "apt-get install can-utils",
    ) {
        return;
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("mixed.log");
    let asc = dir.path().join("mixed.asc");
    let records = write_trace(&path, &mixed_frames());
    let (p, a) = (path.to_str().expect("UTF-8"), asc.to_str().expect("UTF-8"));
    run("log2asc", &["-I", p, "-O", a, "vcan0"], None);
    let text = std::fs::read_to_string(&asc).expect("asc written");
    let events: Vec<&str> = text
        .lines()
        .filter(|l| {
            l.starts_with(' ')
                && l.trim()
                    .split(' ')
                    .next()
                    .is_some_and(|t| t.parse::<f64>().is_ok())
        })
        .collect();
    assert_eq!(
        events.len(),
        records.len(),
        "one ASC event per log line:\n{text}"
    );
    for (line, rec) in events.iter().zip(&records) {
        let frame = &rec.frame;
        if frame.is_error() {
            assert!(line.contains("ErrorFrame"), "{line}");
            continue;
        }
        let id = match frame.id() {
            CanId::Standard(id) => format!("{id:X}"),
            CanId::Extended(id) => format!("{id:X}x"),
        };
        assert!(
            line.split_whitespace().any(|w| w == id),
            "{id} not in {line}"
        );
        if frame.is_fd() {
            assert!(line.contains("CANFD"), "{line}");
            continue;
        }
        let dir = if rec.direction == Some(Direction::Transmit) {
            "Tx"
        } else {
            "Rx"
        };
        assert!(
            line.split_whitespace().any(|w| w == dir),
            "{dir} not in {line}"
        );
        let data: Vec<String> = frame.data().iter().map(|b| format!("{b:02X}")).collect();
        let expected_tail = if frame.is_remote() {
            format!("r {}", frame.dlc())
        } else {
            format!("d {} {}", frame.dlc(), data.join(" "))
                .trim_end()
                .to_string()
        };
        assert!(
            line.trim_end().ends_with(&expected_tail),
            "{expected_tail:?} not at end of {line}"
        );
    }
    let _ = std::io::stdout().flush();
    println!("log2asc converted {} frames of every kind", records.len());
}
