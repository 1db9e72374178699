//! Every message type crosses the in-process bus and decodes back, on the synchronous virtual-time
//! path and on the async path, and both nodes' recorders log what they sent and received.

mod common;

use std::io::BufReader;

use firmware_bridge::trace::{Direction, ReadMode, Recorder, TraceReader};
use firmware_bridge::transport::{Bus, InProcessBus, VirtualClock};
use firmware_bridge::{CONTROLLER_ADDRESS, GATEWAY_ADDRESS, Message};

#[test]
fn every_message_crosses_the_virtual_time_bus() {
    let clock = VirtualClock::new();
    let bus = InProcessBus::with_virtual_clock("sim", clock.clone());
    let controller = bus.attach();
    let gateway = bus.attach();
    let samples = common::sample_messages();
    for (n, msg) in samples.iter().enumerate() {
        clock.set_ns(n as u64 * 10_000_000);
        let frame = msg.encode().expect("encodes");
        // Each message goes from its DBC sender to the other node.
        let (tx, rx) = if msg.descriptor().transmitter == "Controller" {
            (&controller, &gateway)
        } else {
            (&gateway, &controller)
        };
        tx.send(frame).expect("sends");
        let got = rx.try_recv().expect("delivered at once without latency");
        assert_eq!(got.timestamp_ns, n as u64 * 10_000_000);
        let decoded = Message::decode(&got.frame).expect("decodes");
        common::assert_same(&decoded.message, msg);
        let expected_sa = if std::ptr::eq(tx, &controller) {
            CONTROLLER_ADDRESS
        } else {
            GATEWAY_ADDRESS
        };
        assert_eq!(decoded.id.source_address(), expected_sa);
        assert!(
            tx.try_recv().is_none(),
            "a node never receives its own frame"
        );
    }
}

#[tokio::test]
async fn every_message_crosses_the_async_bus_and_is_recorded() {
    let dir = tempfile::tempdir().expect("tempdir");
    let bus = InProcessBus::with_wall_clock("vcan0");
    let mut controller = bus.attach();
    let mut gateway = bus.attach();
    let ctl_log = dir.path().join("controller.log");
    let gw_log = dir.path().join("gateway.log");
    let ctl_rec = Recorder::create(&ctl_log, "vcan0").expect("create log");
    let gw_rec = Recorder::create(&gw_log, "vcan0").expect("create log");
    controller.set_recorder(ctl_rec.clone());
    gateway.set_recorder(gw_rec.clone());

    let samples = common::sample_messages();
    let receiver = tokio::spawn(async move {
        let mut got = Vec::new();
        while got.len() < common::sample_messages().len() {
            let f = Bus::recv(&gateway).await.expect("recv");
            got.push(Message::decode(&f.frame).expect("decodes").message);
        }
        got
    });
    for msg in &samples {
        Bus::send(&controller, msg.encode().expect("encodes"))
            .await
            .expect("send");
    }
    let got = tokio::time::timeout(std::time::Duration::from_secs(10), receiver)
        .await
        .expect("in time")
        .expect("task");
    assert_eq!(got.len(), samples.len());
    for (g, s) in got.iter().zip(&samples) {
        common::assert_same(g, s);
    }

    let ctl_stats = ctl_rec.close().expect("close");
    let gw_stats = gw_rec.close().expect("close");
    assert_eq!(
        (ctl_stats.recorded, ctl_stats.dropped),
        (samples.len() as u64, 0)
    );
    assert_eq!(
        (gw_stats.recorded, gw_stats.dropped),
        (samples.len() as u64, 0)
    );
    for (path, direction) in [
        (&ctl_log, Direction::Transmit),
        (&gw_log, Direction::Receive),
    ] {
        let file = BufReader::new(std::fs::File::open(path).expect("open log"));
        let records: Vec<_> = TraceReader::new(file, ReadMode::Stop)
            .map(|r| r.expect("valid line"))
            .collect();
        assert_eq!(records.len(), samples.len());
        for (rec, msg) in records.iter().zip(&samples) {
            assert_eq!(rec.direction, Some(direction));
            common::assert_same(&Message::decode(&rec.frame).expect("decodes").message, msg);
        }
    }
}
