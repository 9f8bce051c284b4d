//! The transmit queue against the implementation it replaced: the queue kept its frames sorted in a
//! `heapless::Vec` and moved them on every insertion (swapped byte by byte on the chip, 13 750 cycles a
//! requeue on the F103); it now keeps them in fixed slots and orders one-byte slot numbers. Its
//! behaviour must not have changed: every operation's result, the leaving order, the counters, after
//! any sequence of operations. The old queue is kept here verbatim (module `old`), only its outcome
//! and counter types taken from the crate so the two compare directly.

use amiro_can::{CanId, Frame, Kind, Priority};
use amiro_sensors::tx_queue::TxQueue;
use proptest::prelude::*;

/// The queue as it was before the slot rewrite (amiro-sensors/src/tx_queue.rs at 5d3ff6e).
mod old {
    use amiro_can::{CanId, Frame, Kind, Topic};
    use amiro_sensors::tx_queue::{PushOutcome, TxCounters};

    /// Swaps `items[i]` and `items[i + 1]` (nothing if either is missing) through two distinct
    /// references, so no `memmove` is linked for it (`slice::swap` allows `i == j` and uses one).
    pub fn swap_with_next<T>(items: &mut [T], i: usize) {
        if let Some([a, b, ..]) = items.get_mut(i..) {
            core::mem::swap(a, b);
        }
    }

    /// A bounded queue of frames waiting for a CAN mailbox, lowest identifier first.
    #[derive(Clone, Debug)]
    pub struct TxQueue<const N: usize> {
        /// Sorted so the next frame to send is last: identifiers descending, and among equal
        /// identifiers the newest first.
        frames: heapless::Vec<Frame, N>,
        counters: TxCounters,
    }

    impl<const N: usize> Default for TxQueue<N> {
        fn default() -> Self {
            Self::new()
        }
    }

    impl<const N: usize> TxQueue<N> {
        /// An empty queue.
        pub const fn new() -> Self {
            Self {
                frames: heapless::Vec::new(),
                counters: TxCounters {
                    pushed: 0,
                    popped: 0,
                    replaced: 0,
                    dropped: 0,
                    requeued: 0,
                    high_water: 0,
                },
            }
        }

        /// Queues a new frame under the overload policy of this module.
        pub fn push(&mut self, frame: Frame) -> PushOutcome {
            self.counters.pushed = self.counters.pushed.saturating_add(1);
            if let Some(queued) = self
                .frames
                .iter_mut()
                .find(|queued| same_sample(queued, &frame))
            {
                let older = core::mem::replace(queued, frame);
                self.counters.replaced = self.counters.replaced.saturating_add(1);
                return PushOutcome::Replaced { older };
            }
            // Newest among equal identifiers: in front of (below) the ones already waiting.
            let raw = frame.id().raw();
            let at = self
                .frames
                .iter()
                .take_while(|queued| queued.id().raw() > raw)
                .count();
            self.insert_or_drop(at, frame, |last_in_line| raw >= last_in_line)
        }

        /// Puts back a frame that a more urgent one displaced from a transmit mailbox (bxcan hands it
        /// back from `transmit`). It was queued before anything now waiting with its identifier, so it
        /// goes ahead of those; if a newer sample of its topic is already queued, it is discarded
        /// instead (counted as replaced).
        pub fn requeue(&mut self, frame: Frame) -> PushOutcome {
            self.counters.requeued = self.counters.requeued.saturating_add(1);
            if self.frames.iter().any(|queued| same_sample(queued, &frame)) {
                self.counters.replaced = self.counters.replaced.saturating_add(1);
                return PushOutcome::Replaced { older: frame };
            }
            let raw = frame.id().raw();
            let at = self
                .frames
                .iter()
                .take_while(|queued| queued.id().raw() >= raw)
                .count();
            self.insert_or_drop(at, frame, |last_in_line| raw > last_in_line)
        }

        /// Inserts `frame` at `at`; when full, drops whichever of it and the frame that would leave
        /// last goes last (`new_goes_last(id of the frame leaving last)`).
        fn insert_or_drop(
            &mut self,
            at: usize,
            frame: Frame,
            new_goes_last: impl FnOnce(u16) -> bool,
        ) -> PushOutcome {
            let mut outcome = PushOutcome::Queued;
            if self.frames.is_full() {
                let evict = match self.frames.first() {
                    Some(last_in_line) => !new_goes_last(last_in_line.id().raw()),
                    // Only with N = 0: nowhere to put anything.
                    None => false,
                };
                if !evict {
                    self.counters.dropped = self.counters.dropped.saturating_add(1);
                    return PushOutcome::DroppedNew { dropped: frame };
                }
                // The frame leaving last sits at index 0 (the queue is full and `first` was some, so
                // index 0 exists).
                // Shifted by swaps, not `Vec::remove`: no `memmove` is linked into the images for it.
                for i in 1..self.frames.len() {
                    swap_with_next(&mut self.frames, i - 1);
                }
                let Some(dropped) = self.frames.pop() else {
                    return PushOutcome::DroppedNew { dropped: frame };
                };
                self.counters.dropped = self.counters.dropped.saturating_add(1);
                outcome = PushOutcome::DroppedOther { dropped };
            }
            // `at` counted frames before the insertion point; one of them may just have been dropped.
            let at = match outcome {
                PushOutcome::DroppedOther { .. } => at.saturating_sub(1),
                _ => at,
            };
            // `at` ≤ len: it counted queued frames, less the one dropped before it.
            if let Err(frame) = self.frames.push(frame) {
                // Unreachable: room was made above. Report it as a drop rather than lose it silently.
                self.counters.dropped = self.counters.dropped.saturating_add(1);
                return PushOutcome::DroppedNew { dropped: frame };
            }
            // Into its place by swaps, not `Vec::insert` (no `memmove` in the images).
            for i in (at + 1..self.frames.len()).rev() {
                swap_with_next(&mut self.frames, i - 1);
            }
            let len = u16::try_from(self.frames.len()).unwrap_or(u16::MAX);
            self.counters.high_water = self.counters.high_water.max(len);
            outcome
        }

        /// Takes the most urgent frame (lowest identifier, oldest among equals).
        pub fn pop(&mut self) -> Option<Frame> {
            let frame = self.frames.pop()?;
            self.counters.popped = self.counters.popped.saturating_add(1);
            Some(frame)
        }

        /// Takes the most urgent frame only if it beats `id` in arbitration (strictly lower
        /// identifier): the transmit interrupt uses it to decide whether to swap out a pending
        /// mailbox frame with identifier `id`.
        pub fn pop_if_higher_priority_than(&mut self, id: CanId) -> Option<Frame> {
            match self.frames.last() {
                Some(next) if next.id().raw() < id.raw() => self.pop(),
                _ => None,
            }
        }

        /// The frame `pop` would return.
        pub fn peek(&self) -> Option<&Frame> {
            self.frames.last()
        }

        /// Frames waiting.
        pub fn len(&self) -> usize {
            self.frames.len()
        }

        /// True when nothing waits.
        pub fn is_empty(&self) -> bool {
            self.frames.is_empty()
        }

        /// The capacity `N`.
        pub const fn capacity(&self) -> usize {
            N
        }

        /// The waiting frames in the order they will leave.
        pub fn iter(&self) -> impl Iterator<Item = &Frame> {
            self.frames.iter().rev()
        }

        /// Empties the queue (shutdown); the discarded frames are not counted as dropped.
        pub fn clear(&mut self) {
            self.frames.clear();
        }

        /// What the queue has done since boot.
        pub fn counters(&self) -> &TxCounters {
            &self.counters
        }
    }

    /// Whether `newer` is a newer sample of the same thing as `queued`, so it may replace it.
    fn same_sample(queued: &Frame, newer: &Frame) -> bool {
        let id = newer.id();
        if queued.id() != id || id.kind() != Kind::Sensor {
            return false;
        }
        let multi_frame = Topic::from_byte(id.topic_byte())
            .map(|topic| topic.frames_per_sample() > 1)
            .unwrap_or(false);
        // A sample spanning several frames carries the frame's index in its first byte (the proximity
        // ring's sensor number); only the same index is the same thing.
        !multi_frame || queued.data().first() == newer.data().first()
    }
}

fn frame(raw: u16, data: &[u8]) -> Frame {
    Frame::new(CanId::try_from(raw).unwrap(), data).unwrap()
}

#[derive(Clone, Debug)]
enum Op {
    Push(Frame),
    Requeue(Frame),
    Pop,
    PopIfHigher(u16),
    Clear,
}

fn arb_frame() -> impl Strategy<Value = Frame> {
    // Few identifiers so that ties, replacements and evictions are common: one-frame sensor topics,
    // the proximity ring (several frames per sample, told apart by the first byte), commands of
    // equal and different identifiers, a topic byte no table knows, the extremes 0x000 and 0x7FF;
    // zero-length frames too (no index byte).
    let ids = prop::sample::select(vec![
        0x000u16,
        0x010,
        0x205,
        0x41F,
        0x501,
        0x605,
        0x608,
        0x71F,
        0x7FF,
        CanId::new(Kind::Command, Priority::Low, 0x1F).raw(),
        CanId::new(Kind::Sensor, Priority::Urgent, 0xEE).raw(),
    ]);
    (ids, 0u8..4, any::<u8>(), 0usize..=8).prop_map(|(id, index, value, len)| {
        let bytes = [index, value, 7, 6, 5, 4, 3, 2];
        frame(id, &bytes[..len])
    })
}

fn arb_op() -> impl Strategy<Value = Op> {
    prop_oneof![
        6 => arb_frame().prop_map(Op::Push),
        2 => arb_frame().prop_map(Op::Requeue),
        3 => Just(Op::Pop),
        1 => (0u16..=0x7FF).prop_map(Op::PopIfHigher),
        1 => Just(Op::Clear),
    ]
}

/// Runs `ops` on both queues and compares everything either shows after each step.
fn same_as_old<const N: usize>(ops: &[Op]) -> Result<(), TestCaseError> {
    let mut new = TxQueue::<N>::new();
    let mut old = old::TxQueue::<N>::new();
    for (step, op) in ops.iter().enumerate() {
        match op {
            Op::Push(f) => prop_assert_eq!(new.push(*f), old.push(*f), "step {}: {:?}", step, op),
            Op::Requeue(f) => {
                prop_assert_eq!(new.requeue(*f), old.requeue(*f), "step {}: {:?}", step, op)
            }
            Op::Pop => prop_assert_eq!(new.pop(), old.pop(), "step {}", step),
            Op::PopIfHigher(raw) => {
                let id = CanId::try_from(*raw).unwrap();
                prop_assert_eq!(
                    new.pop_if_higher_priority_than(id),
                    old.pop_if_higher_priority_than(id),
                    "step {}: {:?}",
                    step,
                    op
                );
            }
            Op::Clear => {
                new.clear();
                old.clear();
            }
        }
        let leaving: Vec<Frame> = new.iter().copied().collect();
        let leaving_old: Vec<Frame> = old.iter().copied().collect();
        prop_assert_eq!(&leaving, &leaving_old, "step {}: {:?}", step, op);
        prop_assert_eq!(new.peek(), old.peek());
        prop_assert_eq!(new.len(), old.len());
        prop_assert_eq!(new.capacity(), old.capacity());
        prop_assert_eq!(new.is_empty(), old.is_empty());
        prop_assert_eq!(new.counters(), old.counters(), "step {}: {:?}", step, op);
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(1024))]

    #[test]
    fn behaves_as_the_old_queue_with_room_for_sixteen(ops in prop::collection::vec(arb_op(), 0..300)) {
        same_as_old::<16>(&ops)?;
    }

    #[test]
    fn behaves_as_the_old_queue_with_room_for_eight(ops in prop::collection::vec(arb_op(), 0..200)) {
        same_as_old::<8>(&ops)?;
    }

    #[test]
    fn behaves_as_the_old_queue_with_room_for_three(ops in prop::collection::vec(arb_op(), 0..100)) {
        same_as_old::<3>(&ops)?;
    }

    #[test]
    fn behaves_as_the_old_queue_with_room_for_one_or_none(ops in prop::collection::vec(arb_op(), 0..40)) {
        same_as_old::<1>(&ops)?;
        same_as_old::<0>(&ops)?;
    }
}

/// A full queue of one identifier is the longest pass for `place` and the longest shifts: a frame
/// of a smaller identifier goes to the far end, one of a larger evicts the whole line's last.
#[test]
fn a_full_queue_of_equal_identifiers_behaves_as_before() {
    let mut new = TxQueue::<16>::new();
    let mut old = old::TxQueue::<16>::new();
    let cmd = CanId::new(Kind::Command, Priority::Medium, 0x08).raw();
    for n in 0..16u8 {
        assert_eq!(new.push(frame(cmd, &[n])), old.push(frame(cmd, &[n])));
    }
    for f in [frame(0x000, &[]), frame(cmd, &[99]), frame(0x7FF, &[])] {
        assert_eq!(new.requeue(f), old.requeue(f));
        assert_eq!(new.push(f), old.push(f));
    }
    assert!(new.iter().eq(old.iter()));
    assert_eq!(new.counters(), old.counters());
    assert_eq!(
        std::iter::from_fn(|| new.pop()).collect::<Vec<_>>(),
        std::iter::from_fn(|| old.pop()).collect::<Vec<_>>()
    );
}
