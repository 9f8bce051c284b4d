//! Trace events: binary round trip, the text line format, the buffer's overflow accounting, and
//! the helpers that turn handler and queue results into events.

use amiro_can::{Board, CanId, DecodeError, Frame, Topic};
use amiro_sensors::handler::SensorDataHandler;
use amiro_sensors::trace::{
    RejectReason, StopReason, TraceBuffer, TraceDecodeError, TraceEvent, TraceKind, ENCODED_LEN,
};
use amiro_sensors::tx_queue::PushOutcome;
use proptest::prelude::*;

fn arb_topic() -> impl Strategy<Value = Topic> {
    prop::sample::select(Topic::ALL.to_vec())
}

fn arb_kind() -> impl Strategy<Value = TraceKind> {
    let id = any::<u16>();
    let reason = (0..DecodeError::KINDS.len()).prop_map(|i| RejectReason::from_index(i).unwrap());
    let stop = prop::sample::select(vec![
        StopReason::DeadMan,
        StopReason::Shutdown,
        StopReason::Fault,
    ]);
    prop_oneof![
        id.prop_map(|id| TraceKind::CommandAccepted { id }),
        (id, reason).prop_map(|(id, reason)| TraceKind::CommandRejected { id, reason }),
        id.prop_map(|id| TraceKind::CommandIgnored { id }),
        (arb_topic(), any::<u64>())
            .prop_map(|(topic, release_us)| TraceKind::SampleTaken { topic, release_us }),
        id.prop_map(|id| TraceKind::FrameQueued { id }),
        id.prop_map(|id| TraceKind::FrameReplaced { id }),
        id.prop_map(|id| TraceKind::FrameSent { id }),
        (arb_topic(), any::<u32>(), any::<u32>()).prop_map(|(topic, missed, late_us)| {
            TraceKind::DeadlineMissed {
                topic,
                missed,
                late_us,
            }
        }),
        id.prop_map(|id| TraceKind::QueueOverflow { id }),
        stop.prop_map(|reason| TraceKind::MotorsStopped { reason }),
        any::<u32>().prop_map(|count| TraceKind::EventsLost { count }),
        (any::<u8>(), any::<[u8; 3]>()).prop_map(|(led, rgb)| TraceKind::LedSet { led, rgb }),
        any::<u8>().prop_map(|changed| TraceKind::LedsLatched { changed }),
        any::<[u8; 3]>().prop_map(|[state, tec, rec]| TraceKind::CanBusState { state, tec, rec }),
    ]
}

proptest! {
    #[test]
    fn encode_decode_round_trip(at_us in any::<u64>(), kind in arb_kind()) {
        let event = TraceEvent::new(at_us, kind);
        let record = event.encode();
        prop_assert_eq!(record.len(), ENCODED_LEN);
        prop_assert_eq!(record[0], kind.tag());
        prop_assert_eq!(TraceEvent::decode(&record), Ok(event));
    }

    #[test]
    fn decoding_garbage_never_panics(bytes in prop::collection::vec(any::<u8>(), 0..40)) {
        if let Ok(event) = TraceEvent::decode(&bytes) {
            // Whatever decodes re-encodes to the same bytes.
            let again = event.encode();
            prop_assert_eq!(again.as_slice(), bytes.as_slice());
        }
    }

    #[test]
    fn text_lines_are_single_lines(at_us in any::<u64>(), kind in arb_kind()) {
        let line = TraceEvent::new(at_us, kind).to_string();
        let prefix = format!("({}.{:06}) trace {}", at_us / 1_000_000, at_us % 1_000_000, kind.name());
        prop_assert!(line.starts_with(&prefix), "{}", line);
        prop_assert!(!line.contains('\n'));
    }
}

#[test]
fn the_thesis_example_as_it_reads_in_a_qemu_log() {
    let lines: Vec<String> = [
        TraceEvent::new(0, TraceKind::CommandAccepted { id: 0x205 }),
        TraceEvent::new(
            1_800,
            TraceKind::SampleTaken {
                topic: Topic::MagnetometerX,
                release_us: 1_800,
            },
        ),
        TraceEvent::new(1_812, TraceKind::FrameQueued { id: 0x605 }),
        TraceEvent::new(1_830, TraceKind::FrameSent { id: 0x605 }),
        TraceEvent::new(
            2_500_000,
            TraceKind::CommandRejected {
                id: 0x205,
                reason: DecodeError::BadUnit { unit: 9 }.into(),
            },
        ),
        TraceEvent::new(3_000_001, TraceKind::CommandIgnored { id: 0x21F }),
        TraceEvent::new(
            4_000_000,
            TraceKind::DeadlineMissed {
                topic: Topic::Gyroscope,
                missed: 2,
                late_us: 150,
            },
        ),
        TraceEvent::new(4_000_010, TraceKind::QueueOverflow { id: 0x71F }),
        TraceEvent::new(
            5_000_000,
            TraceKind::MotorsStopped {
                reason: StopReason::DeadMan,
            },
        ),
        TraceEvent::new(6_000_000, TraceKind::EventsLost { count: 3 }),
        TraceEvent::new(6_000_001, TraceKind::FrameReplaced { id: 0x608 }),
    ]
    .iter()
    .map(ToString::to_string)
    .collect();
    assert_eq!(
        lines,
        [
            "(0.000000) trace command-accepted 205",
            "(0.001800) trace sample-taken magnetometer-x release=0.001800",
            "(0.001812) trace frame-queued 605",
            "(0.001830) trace frame-sent 605",
            "(2.500000) trace command-rejected 205 bad-unit",
            "(3.000001) trace command-ignored 21F",
            "(4.000000) trace deadline-missed gyroscope missed=2 late=150us",
            "(4.000010) trace queue-overflow 71F",
            "(5.000000) trace motors-stopped dead-man",
            "(6.000000) trace events-lost count=3",
            "(6.000001) trace frame-replaced 608",
        ]
    );
}

#[test]
fn bad_records_are_refused_with_a_reason() {
    let good = TraceEvent::new(5, TraceKind::FrameSent { id: 0x605 }).encode();
    assert_eq!(
        TraceEvent::decode(&good[..ENCODED_LEN - 1]),
        Err(TraceDecodeError::WrongLength {
            len: ENCODED_LEN - 1
        })
    );
    let mut bad = good;
    bad[0] = 0;
    assert_eq!(
        TraceEvent::decode(&bad),
        Err(TraceDecodeError::UnknownTag { tag: 0 })
    );
    let mut bad = good;
    bad[ENCODED_LEN - 1] = 1;
    assert_eq!(
        TraceEvent::decode(&bad),
        Err(TraceDecodeError::TrailingBytes)
    );

    let mut bad = TraceEvent::new(
        5,
        TraceKind::SampleTaken {
            topic: Topic::Gyroscope,
            release_us: 1,
        },
    )
    .encode();
    bad[9] = 0x03;
    assert_eq!(
        TraceEvent::decode(&bad),
        Err(TraceDecodeError::UnknownTopic { byte: 0x03 })
    );

    let reason = DecodeError::ZeroSampleTime.into();
    let mut bad = TraceEvent::new(5, TraceKind::CommandRejected { id: 1, reason }).encode();
    bad[11] = 200;
    assert_eq!(
        TraceEvent::decode(&bad),
        Err(TraceDecodeError::UnknownRejectReason { index: 200 })
    );

    let mut bad = TraceEvent::new(
        5,
        TraceKind::MotorsStopped {
            reason: StopReason::Fault,
        },
    )
    .encode();
    bad[9] = 7;
    assert_eq!(
        TraceEvent::decode(&bad),
        Err(TraceDecodeError::UnknownStopReason { code: 7 })
    );
    assert!(!TraceDecodeError::TrailingBytes.to_string().is_empty());
}

#[test]
fn every_tag_is_distinct() {
    let kinds = [
        TraceKind::CommandAccepted { id: 0 },
        TraceKind::CommandRejected {
            id: 0,
            reason: DecodeError::ZeroSampleTime.into(),
        },
        TraceKind::CommandIgnored { id: 0 },
        TraceKind::SampleTaken {
            topic: Topic::Gyroscope,
            release_us: 0,
        },
        TraceKind::FrameQueued { id: 0 },
        TraceKind::FrameReplaced { id: 0 },
        TraceKind::FrameSent { id: 0 },
        TraceKind::DeadlineMissed {
            topic: Topic::Gyroscope,
            missed: 0,
            late_us: 0,
        },
        TraceKind::QueueOverflow { id: 0 },
        TraceKind::MotorsStopped {
            reason: StopReason::DeadMan,
        },
        TraceKind::EventsLost { count: 0 },
    ];
    let mut tags: Vec<u8> = kinds.iter().map(TraceKind::tag).collect();
    let mut names: Vec<&str> = kinds.iter().map(TraceKind::name).collect();
    tags.sort_unstable();
    tags.dedup();
    names.sort_unstable();
    names.dedup();
    assert_eq!(tags.len(), kinds.len());
    assert_eq!(names.len(), kinds.len());
}

#[test]
fn the_buffer_keeps_the_oldest_and_marks_the_gap() {
    let mut buffer = TraceBuffer::<4>::new();
    let sent = |i: u64| TraceEvent::new(i, TraceKind::FrameSent { id: i as u16 });
    for i in 0..6 {
        let fitted = buffer.push(sent(i));
        assert_eq!(fitted, i < 4, "event {i}");
    }
    assert_eq!(buffer.lost(), 2);
    assert_eq!(buffer.len(), 4);
    assert_eq!(buffer.pop(), Some(sent(0)));
    // One free slot is not enough for marker + event: still lost.
    assert!(!buffer.push(sent(6)));
    assert_eq!(buffer.pop(), Some(sent(1)));
    assert!(buffer.push(sent(7)));
    let rest: Vec<TraceEvent> = std::iter::from_fn(|| buffer.pop()).collect();
    assert_eq!(
        rest,
        [
            sent(2),
            sent(3),
            TraceEvent::new(7, TraceKind::EventsLost { count: 3 }),
            sent(7),
        ]
    );
    assert_eq!(buffer.lost(), 3);
    assert!(buffer.is_empty());
    // The gap was reported once.
    assert!(buffer.push(sent(8)));
    assert_eq!(buffer.pop(), Some(sent(8)));
    assert_eq!(buffer.pop(), None);
}

#[test]
fn handler_and_queue_results_become_events() {
    let mut handler = SensorDataHandler::new(Board::DiWheelDrive);
    let accepted = handler.on_frame(0, 0x205, &[1]);
    assert_eq!(
        TraceKind::for_command(0x205, &accepted),
        TraceKind::CommandAccepted { id: 0x205 }
    );
    let ignored = handler.on_frame(0, 0x21F, &[0]);
    assert_eq!(
        TraceKind::for_command(0x21F, &ignored),
        TraceKind::CommandIgnored { id: 0x21F }
    );
    let rejected = handler.on_frame(0, 0x205, &[7]);
    assert_eq!(
        TraceKind::for_command(0x205, &rejected),
        TraceKind::CommandRejected {
            id: 0x205,
            reason: DecodeError::BadMode { mode: 7 }.into()
        }
    );

    let f = |raw: u16| Frame::new(CanId::try_from(raw).unwrap(), &[]).unwrap();
    let kinds = |outcome: PushOutcome| TraceKind::for_push(0x605, &outcome).collect::<Vec<_>>();
    assert_eq!(
        kinds(PushOutcome::Queued),
        [TraceKind::FrameQueued { id: 0x605 }]
    );
    assert_eq!(
        kinds(PushOutcome::Replaced { older: f(0x605) }),
        [TraceKind::FrameReplaced { id: 0x605 }]
    );
    assert_eq!(
        kinds(PushOutcome::DroppedOther { dropped: f(0x71F) }),
        [
            TraceKind::FrameQueued { id: 0x605 },
            TraceKind::QueueOverflow { id: 0x71F }
        ]
    );
    assert_eq!(
        kinds(PushOutcome::DroppedNew { dropped: f(0x605) }),
        [TraceKind::QueueOverflow { id: 0x605 }]
    );

    handler.on_frame(0, 0x108, &[1, 1, 0, 0]).unwrap(); // gyroscope every 1 ms, high
    handler.take_due(amiro_can::Priority::High, 0, |_, _| {});
    let releases = handler.take_due_releases(amiro_can::Priority::High, 3_200);
    assert_eq!(
        TraceKind::for_release(&releases[0]),
        Some(TraceKind::DeadlineMissed {
            topic: Topic::Gyroscope,
            missed: 2,
            late_us: 1_200
        })
    );
    let releases = handler.take_due_releases(amiro_can::Priority::High, 4_000);
    assert_eq!(TraceKind::for_release(&releases[0]), None);
}
