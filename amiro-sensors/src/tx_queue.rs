//! The transmit queue between the publisher tasks and the CAN mailboxes: bounded, ordered by CAN
//! identifier like the bus itself, with a written-down overload policy.
//!
//! Policy (also in `docs/handler.md`):
//! - The frame with the lowest identifier leaves first; frames with equal identifiers leave in the
//!   order they were queued.
//! - A newer sample of a topic replaces the older one still queued (same identifier; for a topic
//!   whose sample spans several frames, such as the proximity ring, also the same index byte). It
//!   takes the older frame's place in the line. Counted as *replaced*.
//! - When the queue is full and nothing can be replaced, the frame that would leave last is
//!   dropped — the highest identifier, possibly the new frame itself. Counted as *dropped*.
//! - Command frames (C/S = 0) are never replaced: each command matters, not just the latest.
//!
//! The frames are kept sorted with the most urgent at the end, so `pop` in the transmit interrupt
//! is O(1); `push` shifts at most `N` frames.

use amiro_can::{CanId, Frame, Kind, Topic};

/// What [`TxQueue::push`] (or [`TxQueue::requeue`]) did with a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PushOutcome {
    /// The frame is queued; nothing else changed.
    Queued,
    /// The frame is queued in place of an older sample of the same topic, which is returned.
    /// After [`TxQueue::requeue`] it is the other way round: a newer sample was already queued,
    /// so the requeued frame is the one returned and discarded.
    Replaced {
        /// The frame that left the queue unsent.
        older: Frame,
    },
    /// The queue was full: the frame is queued and the lowest-priority queued frame was dropped.
    DroppedOther {
        /// The frame that left the queue unsent.
        dropped: Frame,
    },
    /// The queue was full and the frame itself had the lowest priority: it was dropped.
    DroppedNew {
        /// The frame that was refused.
        dropped: Frame,
    },
}

impl PushOutcome {
    /// Whether the pushed frame is now in the queue.
    pub fn is_queued(&self) -> bool {
        !matches!(self, PushOutcome::DroppedNew { .. })
    }

    /// The frame lost to overload, if one was dropped (a replaced frame is not a loss).
    pub fn dropped(&self) -> Option<&Frame> {
        match self {
            PushOutcome::DroppedOther { dropped } | PushOutcome::DroppedNew { dropped } => {
                Some(dropped)
            }
            PushOutcome::Queued | PushOutcome::Replaced { .. } => None,
        }
    }
}

/// What the queue has done since boot. Counters saturate instead of wrapping.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TxCounters {
    /// Frames accepted by `push` (whether queued, replacing, or evicting).
    pub pushed: u32,
    /// Frames handed to the mailboxes by `pop` / `pop_if_higher_priority_than`.
    pub popped: u32,
    /// Older samples overwritten by newer ones of the same topic.
    pub replaced: u32,
    /// Frames dropped because the queue was full.
    pub dropped: u32,
    /// Frames put back after a more urgent frame displaced them from a mailbox.
    pub requeued: u32,
    /// The most frames ever queued at once.
    pub high_water: u16,
}

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

#[cfg(test)]
mod tests {
    use super::*;
    use amiro_can::Priority;

    fn frame(raw: u16, data: &[u8]) -> Frame {
        let id = CanId::try_from(raw).unwrap();
        Frame::new(id, data).unwrap()
    }

    #[test]
    fn sixteen_frames_fit_in_a_small_budget() {
        let size = core::mem::size_of::<TxQueue<16>>();
        // 16 frames of 12 bytes, the length and the counters.
        assert!(size <= 16 * 12 + 8 + 24, "TxQueue<16> is {size} bytes");
    }

    #[test]
    fn zero_capacity_drops_everything() {
        let mut queue = TxQueue::<0>::new();
        let f = frame(0x605, &[1]);
        assert_eq!(queue.push(f), PushOutcome::DroppedNew { dropped: f });
        assert_eq!(queue.counters().dropped, 1);
        assert!(queue.pop().is_none());
    }

    #[test]
    fn commands_are_never_replaced() {
        let mut queue = TxQueue::<4>::new();
        let id = CanId::new(Kind::Command, Priority::High, 0x05).raw();
        assert_eq!(queue.push(frame(id, &[0])), PushOutcome::Queued);
        assert_eq!(queue.push(frame(id, &[0])), PushOutcome::Queued);
        assert_eq!(queue.len(), 2);
    }
}
