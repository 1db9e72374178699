//! Smoke tests of the vcan harness: a real SocketCAN interface carries frames between two sockets, and
//! can-utils `candump`/`cansend` see and produce the same frames.
//!
//! They need a vcan interface (`EXCAVATOR_VCAN_IFACE`, default `vcan0`), so they are `#[ignore]`d in a
//! plain `cargo test` and run by `scripts/test-all` through `scripts/vcan-vm run` (natively where the
//! kernel has vcan, otherwise inside a throwaway qemu VM). A missing interface is a failure, never a pass.

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::thread;
use std::time::{Duration, Instant};

use socketcan::{CanFrame, CanSocket, EmbeddedFrame, ExtendedId, Frame, Id, Socket, StandardId};

/// How long to wait for a frame or for candump's output; generous because the VM runs under TCG.
const WAIT: Duration = Duration::from_secs(20);

fn open(iface: &str) -> CanSocket {
    let socket = CanSocket::open(iface)
        .unwrap_or_else(|e| panic!("cannot open a SocketCAN socket on {iface}: {e}"));
    socket
        .set_read_timeout(Duration::from_millis(200))
        .expect("set_read_timeout");
    socket
}

fn extended(id: u32, data: &[u8]) -> CanFrame {
    let id = ExtendedId::new(id).expect("29-bit id");
    CanFrame::new(id, data).expect("a classic CAN frame")
}

fn standard(id: u16, data: &[u8]) -> CanFrame {
    let id = StandardId::new(id).expect("11-bit id");
    CanFrame::new(id, data).expect("a classic CAN frame")
}

/// Reads from `socket` until a frame with `id` arrives or `WAIT` passes.
fn receive_id(socket: &CanSocket, id: Id) -> CanFrame {
    let deadline = Instant::now() + WAIT;
    while Instant::now() < deadline {
        match socket.read_frame() {
            Ok(frame) if frame.id() == id => return frame,
            Ok(_) => {}
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) => {}
            Err(e) => panic!("reading from the CAN socket failed: {e}"),
        }
    }
    panic!("no frame with id {id:?} arrived within {WAIT:?}");
}

/// Finds a program on PATH or fails the test, naming the package.
fn require_tool(name: &str) -> String {
    let path = std::env::var_os("PATH").unwrap_or_default();
    for dir in std::env::split_paths(&path) {
        let candidate = dir.join(name);
        if candidate.is_file() {
            return candidate.to_string_lossy().into_owned();
        }
    }
    panic!(
        "{name} (can-utils) is not on PATH: apt-get install can-utils (scripts/vcan-vm setup does)"
    );
}

#[test]
#[ignore = "needs a vcan interface: run through scripts/test-all"]
fn extended_frame_travels_between_two_sockets() {
    let iface = hil_tests::env::vcan_iface();
    let rx = open(&iface);
    let tx = open(&iface);
    let sent = extended(
        0x0CFE_3027,
        &[0x01, 0x02, 0x03, 0x04, 0xA5, 0x5A, 0xFE, 0xFF],
    );
    tx.write_frame(&sent).expect("write_frame");

    let got = receive_id(&rx, sent.id());
    assert!(
        got.is_extended(),
        "the received frame lost its extended (29-bit) id"
    );
    assert_eq!(got.raw_id(), 0x0CFE_3027);
    assert_eq!(got.data(), sent.data());
    assert_eq!(got.dlc(), 8);
}

#[test]
#[ignore = "needs a vcan interface: run through scripts/test-all"]
fn cansend_frame_reaches_a_socket() {
    let iface = hil_tests::env::vcan_iface();
    let cansend = require_tool("cansend");
    let rx = open(&iface);
    let status = Command::new(&cansend)
        .args([iface.as_str(), "18FEF180#1122334455"])
        .status()
        .expect("run cansend");
    assert!(
        status.success(),
        "cansend {iface} 18FEF180#1122334455 failed: {status}"
    );

    let want = Id::Extended(ExtendedId::new(0x18FE_F180).expect("29-bit id"));
    let got = receive_id(&rx, want);
    assert!(got.is_extended());
    assert_eq!(got.data(), &[0x11, 0x22, 0x33, 0x44, 0x55]);
}

/// Kills the child process when dropped, so a failed assertion does not leak candump.
struct KillOnDrop(Child);

impl Drop for KillOnDrop {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Checks one `candump -L` line: `(seconds.micros) iface ID#DATA`; returns `ID#DATA`.
fn parse_candump_line<'a>(line: &'a str, iface: &str) -> &'a str {
    let rest = line
        .strip_prefix('(')
        .unwrap_or_else(|| panic!("candump line does not start with '(': {line:?}"));
    let (stamp, rest) = rest
        .split_once(") ")
        .unwrap_or_else(|| panic!("no ') ' after the timestamp: {line:?}"));
    let (secs, micros) = stamp
        .split_once('.')
        .unwrap_or_else(|| panic!("timestamp without '.': {line:?}"));
    assert!(
        !secs.is_empty()
            && secs.bytes().all(|b| b.is_ascii_digit())
            && micros.len() == 6
            && micros.bytes().all(|b| b.is_ascii_digit()),
        "timestamp is not seconds.microseconds: {line:?}"
    );
    let mut fields = rest.split_whitespace();
    assert_eq!(fields.next(), Some(iface), "interface field: {line:?}");
    let frame = fields
        .next()
        .unwrap_or_else(|| panic!("no ID#DATA field: {line:?}"));
    assert_eq!(fields.next(), None, "trailing fields: {line:?}");
    frame
}

#[test]
#[ignore = "needs a vcan interface: run through scripts/test-all"]
fn candump_log_format_shows_sent_frames() {
    let iface = hil_tests::env::vcan_iface();
    let candump = require_tool("candump");
    let mut child = Command::new(&candump)
        .args(["-L", iface.as_str()])
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("start candump");
    let stdout = child.stdout.take().expect("candump stdout");
    let _guard = KillOnDrop(child);
    let (lines_tx, lines) = mpsc::channel::<String>();
    thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            if lines_tx.send(line).is_err() {
                break;
            }
        }
    });

    // candump prints nothing until its socket is bound: send a marker frame until it shows up.
    let tx = open(&iface);
    let marker = standard(0x7FF, &[0xC0, 0xDE]);
    let deadline = Instant::now() + WAIT;
    let mut synced = false;
    while !synced && Instant::now() < deadline {
        tx.write_frame(&marker).expect("write marker frame");
        while let Ok(line) = lines.recv_timeout(Duration::from_millis(100)) {
            if parse_candump_line(&line, &iface) == "7FF#C0DE" {
                synced = true;
            }
        }
    }
    assert!(
        synced,
        "candump -L {iface} printed no marker frame within {WAIT:?}"
    );

    let frames = [
        (
            extended(
                0x0CFE_3027,
                &[0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x07, 0x08],
            ),
            "0CFE3027#0102030405060708",
        ),
        (standard(0x123, &[0xDE, 0xAD, 0xBE, 0xEF]), "123#DEADBEEF"),
        (extended(0x18FE_F180, &[]), "18FEF180#"),
    ];
    for (frame, _) in &frames {
        tx.write_frame(frame).expect("write_frame");
    }
    let mut seen = Vec::new();
    let deadline = Instant::now() + WAIT;
    while seen.len() < frames.len() && Instant::now() < deadline {
        if let Ok(line) = lines.recv_timeout(Duration::from_millis(200)) {
            let frame = parse_candump_line(&line, &iface).to_owned();
            if frame != "7FF#C0DE" {
                seen.push(frame);
            }
        }
    }
    let want: Vec<&str> = frames.iter().map(|(_, text)| *text).collect();
    assert_eq!(
        seen, want,
        "candump -L {iface} output differs from the frames sent"
    );
}

#[test]
fn candump_line_parser_accepts_the_log_format() {
    assert_eq!(
        parse_candump_line(
            "(1700000000.123456) vcan0 0CFE3027#0102030405060708",
            "vcan0"
        ),
        "0CFE3027#0102030405060708"
    );
}
