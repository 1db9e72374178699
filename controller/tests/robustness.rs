//! Nothing panics: arbitrary frames into the node (proptest); and the real-time loop's shutdown
//! sequence over the in-process bus.

#![allow(clippy::unwrap_used)]

mod common;
use common::node;

use controller::step::node::OUTBOX_CAPACITY;
use firmware_bridge::messages::{AuxValveCommand, Message, RequestedMode, Valve};
use firmware_bridge::transport::{InProcessBus, TimestampedFrame};
use firmware_bridge::{CONTROLLER_ADDRESS, CanFrame, CanId};
use proptest::prelude::*;

fn arb_frame() -> impl Strategy<Value = CanFrame> {
    prop_oneof![
        // Extended ids: mostly the protocol's PGNs from the gateway, some from anyone.
        (
            prop::sample::select(vec![
                0xFE20u32, 0xFE21, 0xFE22, 0xFF50, 0xFF51, 0xFF52, 0xFF53, 0xFF54, 0xFE30, 0xFF60,
                0xFF61, 0xFF62
            ]),
            prop::sample::select(vec![0x80u8, 0x80, 0x80, 0x27, 0x33]),
            prop::collection::vec(any::<u8>(), 0..=8),
        )
            .prop_map(|(pgn, sa, data)| {
                CanFrame::new_extended((3 << 26) | (pgn << 8) | u32::from(sa), &data).unwrap()
            }),
        (0u32..0x2000_0000, prop::collection::vec(any::<u8>(), 0..=8))
            .prop_map(|(id, data)| CanFrame::new_extended(id, &data).unwrap()),
        (0u16..0x800, prop::collection::vec(any::<u8>(), 0..=8))
            .prop_map(|(id, data)| CanFrame::new_standard(id, &data).unwrap()),
        (0u32..0x2000_0000, any::<[u8; 8]>()).prop_map(|(c, d)| CanFrame::new_error(c, d).unwrap()),
        (0u32..0x2000_0000, 0u8..=8).prop_map(|(id, n)| CanFrame::new_remote(
            CanId::Extended(id),
            n
        )
        .unwrap()),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn arbitrary_frames_never_panic_and_outputs_stay_valid(
        batches in prop::collection::vec(
            (prop::collection::vec(arb_frame(), 0..12), -1.0e-3f64..0.05),
            1..40,
        )
    ) {
        let mut n = node();
        let mut t = 1.0;
        for (frames, dt) in batches {
            t += dt; // occasionally backwards by a little, never NaN
            let received: Vec<_> = frames
                .into_iter()
                .map(|frame| TimestampedFrame { timestamp_ns: (t * 1e9) as u64, frame })
                .collect();
            let out = n.step(t, &received);
            prop_assert!(out.len() <= OUTBOX_CAPACITY);
            for f in &out {
                let d = Message::decode(f).unwrap();
                prop_assert_eq!(d.id.source_address(), CONTROLLER_ADDRESS);
                if let Message::AuxValveCommand(c) = d.message {
                    // Nothing moves before a gateway confirmed an arm request.
                    if n.safety().motion().is_none() {
                        prop_assert_eq!(c.to_fraction(), 0.0);
                    }
                }
            }
        }
        let out = n.shutdown(t);
        prop_assert!(out.iter().all(|f| Message::decode(f).is_ok()));
    }
}

/// On tokio's paused clock: the 320 ms before the shutdown signal pass in virtual time, so the loop
/// ticks exactly at 0, 10, ..., 320 ms whatever the machine's load (past the 250 ms address claim,
/// before which the node sends nothing but its claim, not even shutdown frames).
#[tokio::test(start_paused = true)]
async fn the_loop_ends_with_neutral_valves_and_a_disarm_heartbeat() {
    let bus = InProcessBus::with_wall_clock("test0");
    let ctl = bus.attach();
    let observer = bus.attach();
    let mut n = node();
    // The gateway's session: without one the node sends no secured frame (the gateway would refuse it).
    let session = firmware_bridge::messages::GatewaySession { session_id: 7 };
    observer
        .send(Message::GatewaySession(session).encode().unwrap())
        .unwrap();
    let shutdown = tokio::time::sleep(std::time::Duration::from_millis(320));
    let (reason, stats) =
        controller::io::run::run_loop(&ctl, &mut n, firmware_bridge::dbc::CONTROL_PERIOD, shutdown)
            .await
            .unwrap();
    assert_eq!(reason, controller::io::run::StopReason::Signal);
    assert!((32..=33).contains(&stats.steps), "{stats:?}");
    let mut frames = Vec::new();
    while let Some(f) = observer.try_recv() {
        frames.push(Message::decode(&f.frame).unwrap().message);
    }
    let n_frames = frames.len();
    assert!(n_frames >= 7);
    let tail = &frames[n_frames - 7..];
    for (m, v) in tail.iter().zip(Valve::ALL) {
        assert_eq!(*m, Message::AuxValveCommand(AuxValveCommand::neutral(v)));
    }
    assert!(matches!(
        tail[6],
        Message::ControllerHeartbeat(hb) if hb.mode == RequestedMode::Disarm
    ));
}
