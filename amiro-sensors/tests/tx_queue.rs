//! The transmit queue: bus order, replacement of stale samples, overflow policy, mailbox
//! displacement — and a property test against a plainly written model of the policy.

use amiro_can::{CanId, Frame, Kind, Priority, SensorData, Topic};
use amiro_sensors::tx_queue::{PushOutcome, TxQueue};
use proptest::prelude::*;

fn frame(raw: u16, data: &[u8]) -> Frame {
    Frame::new(CanId::try_from(raw).unwrap(), data).unwrap()
}

fn ids<const N: usize>(queue: &TxQueue<N>) -> Vec<u16> {
    queue.iter().map(|f| f.id().raw()).collect()
}

fn drain<const N: usize>(queue: &mut TxQueue<N>) -> Vec<Frame> {
    std::iter::from_fn(|| queue.pop()).collect()
}

#[test]
fn lowest_identifier_leaves_first_and_equal_identifiers_in_order() {
    let mut q = TxQueue::<8>::new();
    let ring = |sensor: u8, mm: u16| SensorData::ProximityRing { sensor, mm }.encode(Priority::Low);
    q.push(frame(0x708, &[1]));
    q.push(ring(0, 100));
    q.push(frame(0x605, &[1]));
    q.push(ring(1, 200));
    q.push(frame(0x405, &[1]));
    q.push(ring(2, 300));
    assert_eq!(q.peek().map(|f| f.id().raw()), Some(0x405));
    let order: Vec<(u16, u8)> = drain(&mut q)
        .iter()
        .map(|f| (f.id().raw(), f.data()[0]))
        .collect();
    assert_eq!(
        order,
        [
            (0x405, 1),
            (0x605, 1),
            (0x708, 1),
            (0x71F, 0),
            (0x71F, 1),
            (0x71F, 2)
        ]
    );
    assert!(q.is_empty());
    assert_eq!(q.counters().popped, 6);
}

/// The queue's entries sort by the identifier in their top bits, whatever the index byte and the
/// slot below it: the smallest and the largest identifiers, frames with and without data, a
/// capacity that is no power of two, every insertion place and both ends of an eviction.
#[test]
fn identifiers_at_both_ends_and_every_place_of_a_five_frame_queue() {
    let cmd = |id: u8, n: u8| frame(CanId::new(Kind::Command, Priority::Urgent, id).raw(), &[n]);
    let mut q = TxQueue::<5>::new();
    // Command identifiers: never replaced, so equal ones queue in order.
    let low = cmd(0, 0);
    assert_eq!(low.id().raw(), 0x000);
    assert_eq!(q.push(frame(0x7FF, &[])), PushOutcome::Queued);
    assert_eq!(q.push(low), PushOutcome::Queued);
    assert_eq!(q.push(frame(0x0FF, &[9])), PushOutcome::Queued);
    assert_eq!(q.push(cmd(0, 1)), PushOutcome::Queued);
    assert_eq!(q.push(frame(0x0FF, &[8])), PushOutcome::Queued);
    assert_eq!(ids(&q), [0x000, 0x000, 0x0FF, 0x0FF, 0x7FF]);
    // Full: the newest 0x0FF leaves after the older one, before 0x7FF, which is evicted.
    let last = frame(0x0FF, &[7]);
    assert_eq!(
        q.push(last),
        PushOutcome::DroppedOther {
            dropped: frame(0x7FF, &[])
        }
    );
    // Full: a frame that would leave last (an equal identifier queued after the others) is refused.
    let refused = frame(0x0FF, &[6]);
    assert_eq!(
        q.push(refused),
        PushOutcome::DroppedNew { dropped: refused }
    );
    // A requeued 0x0FF goes ahead of its equals, and the newest of them leaves the full queue.
    let back = frame(0x0FF, &[5]);
    assert_eq!(q.requeue(back), PushOutcome::DroppedOther { dropped: last });
    let order: Vec<(u16, Vec<u8>)> = drain(&mut q)
        .iter()
        .map(|f| (f.id().raw(), f.data().to_vec()))
        .collect();
    assert_eq!(
        order,
        [
            (0x000, vec![0]),
            (0x000, vec![1]),
            (0x0FF, vec![5]),
            (0x0FF, vec![9]),
            (0x0FF, vec![8]),
        ]
    );
    assert_eq!(q.counters().dropped, 3);
    assert_eq!(q.counters().requeued, 1);
}

/// A requeued command (never replaced) goes ahead of every queued frame of its identifier and
/// behind every smaller identifier, at each length of the queue, and the slots it frees and takes
/// keep the rest in order.
#[test]
fn a_requeued_frame_goes_ahead_of_its_equals_at_every_length() {
    let cmd = |n: u8| frame(0x205, &[n]);
    for queued in 0..8u8 {
        let mut q = TxQueue::<8>::new();
        q.push(frame(0x100, &[0xAA]));
        for n in 0..queued {
            q.push(cmd(n));
        }
        q.push(frame(0x300, &[0xBB]));
        let requeued = q.requeue(cmd(0xEE));
        assert!(
            requeued.is_queued(),
            "{queued} commands queued: {requeued:?}"
        );
        let order: Vec<(u16, u8)> = drain(&mut q)
            .iter()
            .map(|f| (f.id().raw(), f.data()[0]))
            .collect();
        // Whatever a full queue lost is the end of the whole order: a push that would leave last
        // is refused, a requeue evicts the frame that leaves last.
        let mut expected = vec![(0x100, 0xAA), (0x205, 0xEE)];
        expected.extend((0..queued).map(|n| (0x205, n)));
        expected.push((0x300, 0xBB));
        expected.truncate(8);
        assert_eq!(order, expected, "{queued} commands queued");
    }
}

#[test]
fn a_newer_sample_replaces_the_queued_one_in_its_place() {
    let mut q = TxQueue::<8>::new();
    q.push(frame(0x605, &[1, 0, 0, 0]));
    q.push(frame(0x608, &[1, 0, 0, 0, 0, 0]));
    let newer = frame(0x605, &[2, 0, 0, 0]);
    assert_eq!(
        q.push(newer),
        PushOutcome::Replaced {
            older: frame(0x605, &[1, 0, 0, 0])
        }
    );
    assert_eq!(q.len(), 2);
    assert_eq!(q.pop(), Some(newer));
    assert_eq!(q.counters().replaced, 1);
    assert_eq!(q.counters().dropped, 0);
}

#[test]
fn the_proximity_ring_replaces_per_sensor_index() {
    let mut q = TxQueue::<16>::new();
    let ring =
        |sensor: u8, mm: u16| SensorData::ProximityRing { sensor, mm }.encode(Priority::High);
    for sensor in 0..8 {
        assert_eq!(q.push(ring(sensor, 100)), PushOutcome::Queued);
    }
    for sensor in 0..8 {
        assert!(matches!(
            q.push(ring(sensor, 200)),
            PushOutcome::Replaced { .. }
        ));
    }
    assert_eq!(q.len(), 8);
    let sent: Vec<SensorData> = drain(&mut q)
        .iter()
        .map(|f| match f.decode().unwrap() {
            amiro_can::Message::Sample { data, .. } => data,
            other => panic!("{other:?}"),
        })
        .collect();
    let expected: Vec<SensorData> = (0..8)
        .map(|sensor| SensorData::ProximityRing { sensor, mm: 200 })
        .collect();
    assert_eq!(
        sent, expected,
        "one frame per sensor, newest value, in sensor order"
    );
}

#[test]
fn a_full_queue_drops_the_frame_that_would_leave_last() {
    let mut q = TxQueue::<3>::new();
    q.push(frame(0x601, &[]));
    q.push(frame(0x702, &[]));
    q.push(frame(0x505, &[]));
    // More urgent than the last in line: the 0x702 goes.
    let outcome = q.push(frame(0x608, &[]));
    assert_eq!(
        outcome,
        PushOutcome::DroppedOther {
            dropped: frame(0x702, &[])
        }
    );
    assert!(outcome.is_queued());
    assert_eq!(outcome.dropped(), Some(&frame(0x702, &[])));
    assert_eq!(ids(&q), [0x505, 0x601, 0x608]);
    // Less urgent than everything: the new frame itself goes.
    let outcome = q.push(frame(0x709, &[]));
    assert_eq!(
        outcome,
        PushOutcome::DroppedNew {
            dropped: frame(0x709, &[])
        }
    );
    assert!(!outcome.is_queued());
    // Commands (C/S = 0) beat every sample in arbitration: two of them push two samples out.
    let cmd = CanId::new(Kind::Command, Priority::Medium, 0x08).raw();
    assert!(matches!(
        q.push(frame(cmd, &[0])),
        PushOutcome::DroppedOther { .. }
    ));
    q.push(frame(0x101, &[0]));
    assert_eq!(ids(&q), [0x101, cmd, 0x505]);
    // A newer sample replaces even in a full queue: nothing is lost.
    assert!(matches!(
        q.push(frame(0x505, &[9])),
        PushOutcome::Replaced { .. }
    ));
    // A second command with an equal identifier is a new frame, not a replacement.
    assert_eq!(
        q.push(frame(cmd, &[1])),
        PushOutcome::DroppedOther {
            dropped: frame(0x505, &[9])
        }
    );
    assert_eq!(ids(&q), [0x101, cmd, cmd]);
    // Equal to the last in line: the newest of equals would leave last, so the new frame goes.
    assert_eq!(
        q.push(frame(cmd, &[2])),
        PushOutcome::DroppedNew {
            dropped: frame(cmd, &[2])
        }
    );
    assert_eq!(
        drain(&mut q),
        [frame(0x101, &[0]), frame(cmd, &[0]), frame(cmd, &[1])]
    );
    assert_eq!(q.counters().dropped, 6);
    assert_eq!(q.counters().high_water, 3);
    assert_eq!(q.counters().pushed, 10);
}

#[test]
fn a_displaced_mailbox_frame_goes_back_ahead_of_its_equals() {
    let mut q = TxQueue::<4>::new();
    let cmd = CanId::new(Kind::Command, Priority::Low, 0x01).raw();
    q.push(frame(cmd, &[2]));
    q.push(frame(0x605, &[0; 4]));
    // The frame with data [1] was queued before [2] and sat in a mailbox until displaced.
    assert_eq!(q.requeue(frame(cmd, &[1])), PushOutcome::Queued);
    assert_eq!(q.pop(), Some(frame(cmd, &[1])));
    assert_eq!(q.pop(), Some(frame(cmd, &[2])));
    // A displaced sample whose newer value is already queued is discarded.
    assert_eq!(
        q.requeue(frame(0x605, &[7; 4])),
        PushOutcome::Replaced {
            older: frame(0x605, &[7; 4])
        }
    );
    assert_eq!(q.pop(), Some(frame(0x605, &[0; 4])));
    assert_eq!(q.counters().requeued, 2);
}

#[test]
fn pop_if_higher_priority_than_a_pending_mailbox_frame() {
    let mut q = TxQueue::<4>::new();
    let pending = CanId::try_from(0x605).unwrap();
    assert_eq!(q.pop_if_higher_priority_than(pending), None);
    q.push(frame(0x605, &[]));
    assert_eq!(
        q.pop_if_higher_priority_than(pending),
        None,
        "equal identifiers do not swap"
    );
    q.push(frame(0x604, &[]));
    assert_eq!(
        q.pop_if_higher_priority_than(pending),
        Some(frame(0x604, &[]))
    );
    assert_eq!(q.len(), 1);
    assert_eq!(q.capacity(), 4);
    q.clear();
    assert!(q.is_empty());
}

#[test]
fn sixteen_frames_and_a_handler_fit_well_under_one_kib() {
    let total = core::mem::size_of::<TxQueue<16>>()
        + core::mem::size_of::<amiro_sensors::handler::SensorDataHandler>();
    assert!(total < 700, "handler + 16-frame queue take {total} bytes");
}

// ----- property test against a model -----

/// The policy written as plainly as possible: a list of (frame, sequence number), the frame to
/// leave next is the smallest (identifier, sequence), the one to drop the largest.
#[derive(Default)]
struct Model {
    frames: Vec<(Frame, i64)>,
    next_seq: i64,
    first_seq: i64,
    capacity: usize,
}

fn is_same_sample(a: &Frame, b: &Frame) -> bool {
    if a.id() != b.id() || a.id().kind() != Kind::Sensor {
        return false;
    }
    // A topic whose sample spans several frames (the proximity ring, the diagnostics topics):
    // the same first byte, the frame's index.
    let multi_frame =
        Topic::from_byte(a.id().topic_byte()).is_some_and(|t| t.frames_per_sample() > 1);
    !multi_frame || a.data().first() == b.data().first()
}

impl Model {
    fn add(&mut self, frame: Frame, seq: i64, requeue: bool) -> PushOutcome {
        if let Some(i) = self
            .frames
            .iter()
            .position(|(f, _)| is_same_sample(f, &frame))
        {
            if requeue {
                return PushOutcome::Replaced { older: frame };
            }
            let older = std::mem::replace(&mut self.frames[i].0, frame);
            return PushOutcome::Replaced { older };
        }
        self.frames.push((frame, seq));
        if self.frames.len() <= self.capacity {
            return PushOutcome::Queued;
        }
        let last = (0..self.frames.len())
            .max_by_key(|i| (self.frames[*i].0.id().raw(), self.frames[*i].1))
            .unwrap();
        let (dropped, dropped_seq) = self.frames.remove(last);
        if dropped_seq == seq {
            PushOutcome::DroppedNew { dropped }
        } else {
            PushOutcome::DroppedOther { dropped }
        }
    }

    fn push(&mut self, frame: Frame) -> PushOutcome {
        self.next_seq += 1;
        self.add(frame, self.next_seq, false)
    }

    fn requeue(&mut self, frame: Frame) -> PushOutcome {
        self.first_seq -= 1;
        self.add(frame, self.first_seq, true)
    }

    fn order(&self) -> Vec<Frame> {
        let mut sorted = self.frames.clone();
        sorted.sort_by_key(|(f, seq)| (f.id().raw(), *seq));
        sorted.into_iter().map(|(f, _)| f).collect()
    }

    fn pop(&mut self) -> Option<Frame> {
        let i = (0..self.frames.len())
            .min_by_key(|i| (self.frames[*i].0.id().raw(), self.frames[*i].1))?;
        Some(self.frames.remove(i).0)
    }
}

#[derive(Clone, Debug)]
enum Op {
    Push(Frame),
    Requeue(Frame),
    Pop,
    PopIfHigher(u16),
}

fn arb_frame() -> impl Strategy<Value = Frame> {
    // Few identifiers, so collisions (replacement, FIFO ties) are common: sensor topics, the
    // proximity ring (multi-frame), commands, and an unknown topic byte.
    let ids = prop::sample::select(vec![
        0x605u16, 0x608, 0x41F, 0x71F, 0x205, 0x205, 0x010, 0x7FF, 0x501, 0x000,
    ]);
    (ids, 0u8..3, any::<u8>(), 0usize..=8).prop_map(|(id, index, value, len)| {
        let bytes = [index, value, 0, 0, 0, 0, 0, 0];
        frame(id, &bytes[..len.max(1)])
    })
}

fn arb_op() -> impl Strategy<Value = Op> {
    prop_oneof![
        4 => arb_frame().prop_map(Op::Push),
        1 => arb_frame().prop_map(Op::Requeue),
        2 => Just(Op::Pop),
        1 => (0u16..0x800).prop_map(Op::PopIfHigher),
    ]
}

/// Frames of two multi-frame topics' identifiers (the proximity ring's and a diagnostics topic's)
/// with up to ten indices and frames without a first byte: long runs of one identifier whose
/// frames differ in the index alone, which the searches for an older (push) or newer (requeue)
/// sample walk from where the run starts to where it ends; and a single-frame sensor topic and a
/// command of the identifiers either side, where the runs end.
fn arb_run_frame() -> impl Strategy<Value = Frame> {
    let ids = prop::sample::select(vec![0x71Fu16, 0x71F, 0x71A, 0x71A, 0x720, 0x719, 0x01A]);
    (ids, 0u8..10, any::<u8>(), 0usize..=8).prop_map(|(id, index, value, len)| {
        let bytes = [index, value, 0, 0, 0, 0, 0, 0];
        frame(id, &bytes[..len])
    })
}

fn arb_run_op() -> impl Strategy<Value = Op> {
    prop_oneof![
        4 => arb_run_frame().prop_map(Op::Push),
        2 => arb_run_frame().prop_map(Op::Requeue),
        2 => Just(Op::Pop),
        1 => (0x700u16..0x720).prop_map(Op::PopIfHigher),
    ]
}

fn run_against_model<const N: usize>(ops: &[Op]) -> Result<(), TestCaseError> {
    let mut queue = TxQueue::<N>::new();
    let mut model = Model {
        capacity: N,
        ..Model::default()
    };
    let (mut replaced, mut dropped) = (0u32, 0u32);
    for op in ops {
        match op {
            Op::Push(f) => {
                let expected = model.push(*f);
                prop_assert_eq!(queue.push(*f), expected);
                replaced += u32::from(matches!(expected, PushOutcome::Replaced { .. }));
                dropped += u32::from(expected.dropped().is_some());
            }
            Op::Requeue(f) => {
                let expected = model.requeue(*f);
                prop_assert_eq!(queue.requeue(*f), expected);
                replaced += u32::from(matches!(expected, PushOutcome::Replaced { .. }));
                dropped += u32::from(expected.dropped().is_some());
            }
            Op::Pop => prop_assert_eq!(queue.pop(), model.pop()),
            Op::PopIfHigher(raw) => {
                let id = CanId::try_from(*raw).unwrap();
                let expected = match model.order().first() {
                    Some(next) if next.id().raw() < *raw => model.pop(),
                    _ => None,
                };
                prop_assert_eq!(queue.pop_if_higher_priority_than(id), expected);
            }
        }
        let order: Vec<Frame> = queue.iter().copied().collect();
        prop_assert_eq!(order, model.order());
        prop_assert_eq!(queue.peek().copied(), model.order().first().copied());
        prop_assert!(queue.len() <= N);
        prop_assert_eq!(queue.counters().replaced, replaced);
        prop_assert_eq!(queue.counters().dropped, dropped);
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn matches_the_model_with_room_for_four(ops in prop::collection::vec(arb_op(), 0..80)) {
        run_against_model::<4>(&ops)?;
    }

    #[test]
    fn matches_the_model_with_room_for_sixteen(ops in prop::collection::vec(arb_op(), 0..200)) {
        run_against_model::<16>(&ops)?;
    }

    // The binary search's steps start at the largest power of two at most N: capacities that are
    // not a power of two (LightRing's 8 is one, the steps 4, 2, 1 for 5 and 7 reach every place).
    #[test]
    fn matches_the_model_with_room_for_five(ops in prop::collection::vec(arb_op(), 0..100)) {
        run_against_model::<5>(&ops)?;
    }

    #[test]
    fn matches_the_model_with_room_for_seven(ops in prop::collection::vec(arb_op(), 0..120)) {
        run_against_model::<7>(&ops)?;
    }

    #[test]
    fn matches_the_model_with_room_for_eight(ops in prop::collection::vec(arb_op(), 0..120)) {
        run_against_model::<8>(&ops)?;
    }

    #[test]
    fn matches_the_model_with_room_for_one(ops in prop::collection::vec(arb_op(), 0..40)) {
        run_against_model::<1>(&ops)?;
    }

    // Long runs of one multi-frame identifier: the walk over a run to an older or newer sample
    // or to its end, with the moves either side of it when the queue is full.
    #[test]
    fn matches_the_model_with_long_runs_of_one_identifier(ops in prop::collection::vec(arb_run_op(), 0..200)) {
        run_against_model::<16>(&ops)?;
    }

    #[test]
    fn matches_the_model_with_long_runs_in_room_for_eight(ops in prop::collection::vec(arb_run_op(), 0..120)) {
        run_against_model::<8>(&ops)?;
    }
}
