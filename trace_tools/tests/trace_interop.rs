//! Interoperability of `trace decode` with the real tools: logs written by can-utils (`asc2log`, the
//! same writer as `candump -l`) and python-can decode to the same values as the project's own logs,
//! 9-digit timestamps decode, and every signal value agrees with `cantools decode` on the same file and
//! DBC. A missing tool skips its test (printing why) unless `EXCAVATOR_REQUIRE_TOOLS=1`.

#![allow(clippy::unwrap_used)] // helpers outside #[test] functions fail loudly on purpose

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use trace_tools::decode::{self, DecodeFilter};
use trace_tools::signals;
use trace_tools::synth::{self, SynthConfig};

fn have(check: &str, hint: &str) -> bool {
    let ok = Command::new("sh")
        .args(["-c", check])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if !ok {
        if std::env::var("EXCAVATOR_REQUIRE_TOOLS").as_deref() == Ok("1") {
            panic!("required tool missing: `{check}` failed ({hint})");
        }
        println!("skip: `{check}` failed ({hint})");
    }
    ok
}

fn fixture(dir: &Path, frames: u64) -> PathBuf {
    let path = dir.join("dig.log");
    let mut f = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
    synth::write_candump(
        &mut f,
        &SynthConfig {
            frames,
            ..SynthConfig::default()
        },
    )
    .unwrap();
    f.flush().unwrap();
    path
}

/// `trace decode` of the log at `path` (all messages, with signal values), as text.
fn decoded_text(path: &Path) -> String {
    let input = std::io::BufReader::new(std::fs::File::open(path).unwrap());
    let mut out = Vec::new();
    decode::decode_stream(
        input,
        DecodeFilter::default(),
        true,
        &mut out,
        &mut std::io::sink(),
        false,
    )
    .unwrap();
    String::from_utf8(out).unwrap()
}

/// The decoded part of each line (after `::`), which does not depend on the time or interface.
fn decoded_bodies(path: &Path) -> Vec<String> {
    decoded_text(path)
        .lines()
        .map(|l| l.split_once(" :: ").unwrap().1.to_string())
        .collect()
}

fn dbc_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../gateway_core/excavator.dbc")
}

#[test]
fn nine_digit_timestamps_decode() {
    let dir = tempfile::tempdir().unwrap();
    let log = fixture(dir.path(), 300);
    let text = std::fs::read_to_string(&log).unwrap();
    // `(s.uuuuuu)` -> `(s.uuuuuu123)`, as candump of newer can-utils and nanosecond loggers write.
    let ns: String = text
        .lines()
        .map(|l| l.replacen(") ", "123) ", 1) + "\n")
        .collect();
    let ns_log = dir.path().join("ns.log");
    std::fs::write(&ns_log, ns).unwrap();
    assert_eq!(decoded_bodies(&log), decoded_bodies(&ns_log));
    let first = decoded_text(&ns_log);
    assert!(first.starts_with("(1700000000.000"), "{first}");
    assert!(
        first
            .lines()
            .next()
            .unwrap()
            .split(')')
            .next()
            .unwrap()
            .ends_with("123")
    );
}

#[test]
fn can_utils_logs_decode() {
    if !have(
        "command -v log2asc && command -v asc2log",
        "apt-get install -y can-utils",
    ) {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let log = fixture(dir.path(), 1160);
    // Our log -> ASC (log2asc) -> a candump log written by can-utils (asc2log, candump -l's format).
    let asc = Command::new("log2asc")
        .args(["-I", log.to_str().unwrap(), "vcan0"])
        .output()
        .unwrap();
    assert!(asc.status.success());
    let asc_path = dir.path().join("dig.asc");
    std::fs::write(&asc_path, &asc.stdout).unwrap();
    let back = Command::new("asc2log")
        .args(["-I", asc_path.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(back.status.success());
    let can_utils_log = dir.path().join("can-utils.log");
    std::fs::write(&can_utils_log, &back.stdout).unwrap();
    let text = String::from_utf8_lossy(&back.stdout);
    assert!(text.lines().next().unwrap().ends_with(" R"), "{text}");
    assert_eq!(decoded_bodies(&can_utils_log), decoded_bodies(&log));
}

#[test]
fn python_can_logs_decode() {
    if !have("python3 -c 'import can'", "pip install python-can") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let log = fixture(dir.path(), 1160);
    let out = dir.path().join("python-can.log");
    let script = r#"
import sys, can
writer = can.CanutilsLogWriter(sys.argv[2], channel="can1")
for msg in can.CanutilsLogReader(sys.argv[1]):
    writer.on_message_received(msg)
writer.stop()
"#;
    let o = Command::new("python3")
        .args(["-c", script, log.to_str().unwrap(), out.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(decoded_bodies(&out), decoded_bodies(&log));
}

/// `Signal: value` pairs of a decoded body `Name(A: 1 unit, B: 'x')`.
fn pairs(body: &str) -> (String, Vec<(String, String)>) {
    let (name, rest) = body.split_once('(').unwrap();
    let inner = rest.trim_end_matches(')');
    let pairs = inner
        .split(", ")
        .map(|p| {
            let (k, v) = p.split_once(": ").unwrap();
            (k.to_string(), v.trim_matches('\'').to_string())
        })
        .collect();
    (name.to_string(), pairs)
}

#[test]
fn values_match_cantools_decode() {
    if !have("python3 -c 'import cantools'", "pip install cantools") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    // 3 s: every message, Autodig stages boom-down and pre-dig.
    let log = fixture(dir.path(), 3480);
    let input = std::fs::File::open(&log).unwrap();
    let o = Command::new("python3")
        .args(["-m", "cantools", "decode", "--single-line"])
        .arg(dbc_path())
        .stdin(input)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let theirs: Vec<String> = String::from_utf8(o.stdout)
        .unwrap()
        .lines()
        .map(|l| l.split_once(" :: ").unwrap().1.to_string())
        .collect();
    let ours = decoded_bodies(&log);
    assert_eq!(theirs.len(), ours.len());
    let mut compared = 0;
    for (t, o) in theirs.iter().zip(&ours) {
        let (tn, tp) = pairs(t);
        let (on, op) = pairs(o);
        assert_eq!(tn, on);
        assert_eq!(tp.len(), op.len(), "{t}\n{o}");
        for ((tk, tv), (ok, ov)) in tp.iter().zip(&op) {
            assert_eq!(tk, ok);
            let number = |v: &str| v.split(' ').next().and_then(|n| n.parse::<f64>().ok());
            match (number(tv), number(ov)) {
                (Some(a), Some(b)) => {
                    assert!(
                        (a - b).abs() <= 1e-9 * a.abs().max(1.0),
                        "{tk}: {tv} vs {ov}"
                    )
                }
                // The DBC attaches value tables to one message; we apply them by signal name.
                (Some(a), None) => {
                    assert_eq!(signals::value_name(tk, a as i64), Some(ov.as_str()), "{tk}")
                }
                _ => assert_eq!(tv, ov, "{tk}"),
            }
            compared += 1;
        }
    }
    assert!(compared > 10_000, "{compared}");
}
