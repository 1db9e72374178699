//! SocketCAN over a real vcan interface. The development containers have no `AF_CAN`, so these tests
//! are ignored by default and run by the harness that provides vcan (the VM):
//! `EXCAVATOR_VCAN_IFACE=vcan0 cargo test -p firmware_bridge --test socketcan_vcan -- --ignored`.

mod common;

use std::time::Duration;

use firmware_bridge::transport::{Bus, IdFilter, SocketCanBus};
use firmware_bridge::{CONTROLLER_ADDRESS, Message};

fn iface() -> String {
    std::env::var("EXCAVATOR_VCAN_IFACE").unwrap_or_else(|_| "vcan0".to_string())
}

#[tokio::test]
#[ignore = "needs a vcan interface (run with --ignored where vcan exists)"]
async fn every_message_crosses_vcan() {
    let iface = iface();
    let tx = SocketCanBus::open(&iface).expect("open vcan for sending");
    // Only frames from the controller's address reach the receiver.
    let rx = SocketCanBus::open_with_filters(
        &iface,
        &[IdFilter::from_source_address(CONTROLLER_ADDRESS)],
    )
    .expect("open vcan for receiving");
    let samples: Vec<Message> = common::sample_messages();
    let controller_frames: Vec<_> = samples
        .iter()
        .map(|m| m.encode_from(CONTROLLER_ADDRESS).expect("encodes"))
        .collect();
    // A gateway-addressed frame first: the filter must drop it.
    let other = samples[0].encode_from(0x80).expect("encodes");
    Bus::send(&tx, other).await.expect("send");
    for frame in &controller_frames {
        Bus::send(&tx, *frame).await.expect("send");
    }
    for (frame, msg) in controller_frames.iter().zip(&samples) {
        let got = tokio::time::timeout(Duration::from_secs(2), Bus::recv(&rx))
            .await
            .expect("frame in time")
            .expect("no bus error");
        assert_eq!(got.frame, *frame);
        let decoded = Message::decode(&got.frame).expect("decodes");
        assert_eq!(decoded.id.source_address(), CONTROLLER_ADDRESS);
        common::assert_same(&decoded.message, msg);
    }
}

#[tokio::test]
#[ignore = "needs a vcan interface (run with --ignored where vcan exists)"]
async fn canplayer_replays_a_project_log() {
    use firmware_bridge::trace::{Direction, Recorder};
    if !common::tool_available(
        "canplayer (can-utils)",
        "sh",
        &["-c", "command -v canplayer"],
        "apt-get install can-utils",
    ) {
        return;
    }
    let iface = iface();
    let dir = tempfile::tempdir().expect("tempdir");
    let log = dir.path().join("replay.log");
    let samples = common::sample_messages();
    let frames: Vec<_> = samples
        .iter()
        .map(|m| m.encode().expect("encodes"))
        .collect();
    let rec = Recorder::create(&log, &iface).expect("create log");
    for (n, f) in frames.iter().enumerate() {
        rec.record(
            1_700_000_000_000_000_000 + n as u64 * 1_000_000,
            Direction::Transmit,
            f,
        );
    }
    rec.close().expect("close log");

    let rx = SocketCanBus::open(&iface).expect("open vcan");
    // Blocking is fine here: the receiving socket buffers the few replayed frames.
    let status = std::process::Command::new("canplayer")
        .args(["-t", "-I"])
        .arg(&log)
        .status()
        .expect("run canplayer");
    assert!(status.success(), "canplayer failed: {status}");
    for (frame, msg) in frames.iter().zip(&samples) {
        let got = tokio::time::timeout(Duration::from_secs(2), Bus::recv(&rx))
            .await
            .expect("replayed frame in time")
            .expect("no bus error");
        assert_eq!(got.frame, *frame);
        common::assert_same(&Message::decode(&got.frame).expect("decodes").message, msg);
    }
}
