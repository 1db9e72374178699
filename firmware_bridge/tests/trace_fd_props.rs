//! Property tests of the trace writer and reader: every frame the candump format can carry, CAN FD
//! frames with any flags nibble included, is written and read back unchanged; CAN FD flags beyond the
//! nibble are refused by the writer, never silently cut.

use firmware_bridge::frame::{CANFD_LENGTHS, CanFrame, CanId};
use firmware_bridge::trace::{
    Direction, FormatError, ReadMode, TraceReader, TraceWriter, WriteError,
};
use proptest::prelude::*;

fn id() -> impl Strategy<Value = CanId> {
    prop_oneof![
        (0u16..=0x7FF).prop_map(CanId::Standard),
        (0u32..=0x1FFF_FFFF).prop_map(CanId::Extended),
    ]
}

fn fd_payload() -> impl Strategy<Value = Vec<u8>> {
    proptest::sample::select(CANFD_LENGTHS.to_vec())
        .prop_flat_map(|len| proptest::collection::vec(any::<u8>(), len))
}

fn direction() -> impl Strategy<Value = Direction> {
    prop_oneof![Just(Direction::Receive), Just(Direction::Transmit)]
}

proptest! {
    #[test]
    fn fd_frames_round_trip_through_a_trace(
        frames in proptest::collection::vec(
            (id(), fd_payload(), 0u8..=0x0F, any::<u64>(), direction()),
            1..20,
        ),
    ) {
        let mut writer = TraceWriter::new(Vec::new(), "can0", true);
        let mut expected = Vec::new();
        for (id, data, flags, timestamp_ns, dir) in frames {
            let frame = CanFrame::new_fd(id, &data, flags).expect("valid FD length");
            writer.write(timestamp_ns, &frame, dir).expect("representable");
            expected.push((timestamp_ns / 1000 * 1000, frame, dir));
        }
        let text = writer.into_inner();
        let records: Vec<_> = TraceReader::new(&text[..], ReadMode::Stop)
            .collect::<Result<_, _>>()
            .expect("written traces read back");
        prop_assert_eq!(records.len(), expected.len());
        for (rec, (timestamp_ns, frame, dir)) in records.iter().zip(expected) {
            prop_assert_eq!(rec.frame, frame);
            prop_assert_eq!(rec.direction, Some(dir));
            prop_assert_eq!(rec.timestamp_ns, timestamp_ns);
            prop_assert_eq!(rec.interface.as_str(), "can0");
        }
    }

    #[test]
    fn fd_flags_beyond_the_nibble_are_refused(
        id in id(), data in fd_payload(), flags in 0x10u8..=0xFF,
    ) {
        let frame = CanFrame::new_fd(id, &data, flags).expect("valid FD length");
        let mut writer = TraceWriter::new(Vec::new(), "can0", false);
        let refused = matches!(
            writer.write(0, &frame, Direction::Receive),
            Err(WriteError::Unrepresentable(FormatError::FdFlags { flags: f })) if f == flags
        );
        prop_assert!(refused);
        prop_assert!(writer.into_inner().is_empty());
    }
}
