//! `excavator-ctl trace replay` onto a real vcan interface, checked with can-utils `candump`: every
//! frame arrives, in order, with the recorded spacing within a tolerance, and the `candump -L` and
//! `candump -l` logs decode with `trace decode`. Needs vcan: run through `scripts/vcan-vm run` (see
//! docs/hil.md), which sets `EXCAVATOR_VCAN_IFACE`.

#![allow(clippy::unwrap_used)] // helpers outside #[test] functions fail loudly on purpose

use std::io::BufRead as _;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

use firmware_bridge::trace::parse_line;
use trace_tools::decode::{self, DecodeFilter};
use trace_tools::synth::{self, SynthConfig};

/// The guest of the vcan VM runs under TCG on a shared host: `docs/hil.md` measured 100 Hz gaps of
/// 11.5 ms mean and 30 ms max, and a loaded host stalls the guest for tens of ms. Replay keeps an
/// absolute schedule, so after a stall it catches up: most frames are close to their time, a few are
/// late. The median error is the spacing check, the maximum only bounds stalls.
const MEDIAN_OFFSET_ERROR: Duration = Duration::from_millis(10);
/// Largest offset error allowed (a stall of the guest).
const MAX_OFFSET_ERROR: Duration = Duration::from_millis(250);

fn require_tool(name: &str) -> bool {
    let found = Command::new("sh")
        .args(["-c", &format!("command -v {name}")])
        .output()
        .is_ok_and(|o| o.status.success());
    if !found {
        if std::env::var("EXCAVATOR_REQUIRE_TOOLS").as_deref() == Ok("1") {
            panic!("{name} is required (apt-get install -y can-utils)");
        }
        println!("skip: {name} not found");
    }
    found
}

fn decode_all(path: &Path) -> (u64, String) {
    let input = std::io::BufReader::new(std::fs::File::open(path).unwrap());
    let mut out = Vec::new();
    let summary = decode::decode_stream(
        input,
        DecodeFilter::default(),
        true,
        &mut out,
        &mut std::io::sink(),
        false,
    )
    .unwrap();
    (summary.lines_out, String::from_utf8(out).unwrap())
}

#[test]
#[ignore = "needs a vcan interface: run through scripts/test-all"]
fn replay_onto_vcan_preserves_timing() {
    let iface = std::env::var("EXCAVATOR_VCAN_IFACE")
        .expect("EXCAVATOR_VCAN_IFACE is not set: run through scripts/vcan-vm run");
    if !require_tool("candump") {
        return;
    }
    let dir = tempfile::tempdir_in(std::env::temp_dir()).unwrap();
    // 1.5 s of the full schedule.
    let log = dir.path().join("dig.log");
    let mut f = std::fs::File::create(&log).unwrap();
    synth::write_candump(
        &mut f,
        &SynthConfig {
            frames: 1740,
            ..SynthConfig::default()
        },
    )
    .unwrap();
    let original: Vec<_> = std::fs::read_to_string(&log)
        .unwrap()
        .lines()
        .map(|l| parse_line(l).unwrap())
        .filter(|r| [0x0CFF_5080, 0x0CFF_6127].contains(&r.frame.id().raw()))
        .collect();
    // About 1.5 s of joint angles and heartbeats.
    assert!(
        original.len() > 170,
        "{} frames of the two ids",
        original.len()
    );

    // candump -L on stdout and candump -l into its own file (cwd).
    let mut live = Command::new("candump")
        .args(["-L", &iface])
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let logdir = dir.path().join("candump-l");
    std::fs::create_dir(&logdir).unwrap();
    let mut file_logger = Command::new("candump")
        .args(["-l", &iface])
        .current_dir(&logdir)
        .stdout(Stdio::null())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(500));

    let o = Command::new(env!("CARGO_BIN_EXE_excavator-ctl"))
        .args(["trace", "replay", log.to_str().unwrap(), "--iface", &iface])
        .args(["--id", "0CFF5080", "--id", "0CFF6127"])
        // The heartbeat is a controller frame, withheld by default; this vcan has no gateway.
        .arg("--allow-control-frames")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    std::thread::sleep(Duration::from_millis(500));
    // Both candumps were started by this test; stop them by their pids with SIGINT, so candump -l
    // flushes its file (SIGKILL would leave a truncated last line).
    for pid in [live.id(), file_logger.id()] {
        let _ = Command::new("kill")
            .args(["-INT", &pid.to_string()])
            .status();
    }
    let _ = file_logger.wait();
    let stdout = live.stdout.take().unwrap();
    let _ = live.wait();

    let captured_lines: Vec<String> = std::io::BufReader::new(stdout)
        .lines()
        .map_while(Result::ok)
        .filter(|l| !l.trim().is_empty())
        .collect();
    let captured: Vec<_> = captured_lines
        .iter()
        .map(|l| parse_line(l).unwrap())
        .collect();
    assert_eq!(captured.len(), original.len(), "frames lost or added");
    // Spacing, not the start: a late first send (the process warming up in the slow guest) moves
    // every arrival by the same amount, so offsets are compared after removing their median.
    let (o0, c0) = (original[0].timestamp_ns, captured[0].timestamp_ns);
    let mut shifts: Vec<i128> = Vec::with_capacity(captured.len());
    for (c, o) in captured.iter().zip(&original) {
        assert_eq!(c.frame, o.frame, "frames out of order");
        let want = i128::from(o.timestamp_ns - o0);
        let got = i128::from(c.timestamp_ns) - i128::from(c0);
        shifts.push(got - want);
    }
    let mut sorted = shifts.clone();
    sorted.sort_unstable();
    let common = sorted[sorted.len() / 2];
    let mut errors: Vec<Duration> = shifts
        .iter()
        .map(|d| Duration::from_nanos(u64::try_from((d - common).abs()).unwrap_or(u64::MAX)))
        .collect();
    errors.sort();
    let median = errors[errors.len() / 2];
    let max = errors[errors.len() - 1];
    println!("{}", String::from_utf8_lossy(&o.stderr).trim());
    println!(
        "replay onto {iface}: {} frames, common shift {:.3} ms, spacing error median {:.3} ms, max {:.3} ms",
        captured.len(),
        common as f64 * 1e-6,
        median.as_secs_f64() * 1e3,
        max.as_secs_f64() * 1e3
    );
    assert!(
        median <= MEDIAN_OFFSET_ERROR,
        "median spacing error {median:?}"
    );
    assert!(max <= MAX_OFFSET_ERROR, "max spacing error {max:?}");

    // candump -L output (with the live capture as a file) and the candump -l file both decode.
    let live_log = dir.path().join("live.log");
    std::fs::write(&live_log, captured_lines.join("\n") + "\n").unwrap();
    let (n, text) = decode_all(&live_log);
    assert_eq!(n, original.len() as u64);
    assert!(!text.contains("!!"), "{text}");
    let file_log = std::fs::read_dir(&logdir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "log"))
        .expect("candump -l wrote no log file");
    let (n, text) = decode_all(&file_log);
    assert_eq!(n, original.len() as u64);
    assert!(text.contains("JointAngles(BoomAngle: "), "{text}");
}
