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
//! Each frame stays in a fixed slot from when it is queued until it leaves; what moves is a small
//! array of slot numbers kept in the order the frames will leave, the next one last. So `pop` in
//! the transmit interrupt is O(1), and `push` and `requeue` read at most `N` frames' identifiers
//! in one pass and move at most `N - 1` one-byte slot numbers (evicting or not), never a frame.

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
///
/// `N` is at most 256 (a slot number is one byte); a larger `N` does not compile.
#[derive(Clone)]
pub struct TxQueue<const N: usize> {
    /// The frames, each in its slot from `push` until it leaves; a free slot's contents are stale.
    slots: [Frame; N],
    /// A permutation of the slot numbers `0..N`. `order[..len]` are the queued frames' slots in
    /// reverse leaving order: identifiers descending, and among equal identifiers the newest first,
    /// so the next frame to send is `order[len - 1]`. `order[len..]` are the free slots.
    order: [u8; N],
    /// Frames queued (at most `N`).
    len: usize,
    counters: TxCounters,
}

impl<const N: usize> Default for TxQueue<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> core::fmt::Debug for TxQueue<N> {
    /// The queued frames in leaving order and the counters (a free slot's stale frame is left out).
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("TxQueue")
            .field("frames", &DebugFrames(self))
            .field("counters", &self.counters)
            .finish()
    }
}

/// The queued frames of a [`TxQueue`], for its `Debug`.
struct DebugFrames<'a, const N: usize>(&'a TxQueue<N>);

impl<const N: usize> core::fmt::Debug for DebugFrames<'_, N> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_list().entries(self.0.iter()).finish()
    }
}

/// Where a frame goes among the queued ones, from one pass over them.
enum Place {
    /// A queued frame (this slot) is an older sample of the same thing.
    Same(usize),
    /// No such frame: `above` queued frames have a greater identifier (they leave after it) and
    /// `through` have a greater or equal one.
    Between { above: usize, through: usize },
}

/// Which queued frames of the same identifier a newer frame is a newer sample of, worked out once
/// from the newer frame (the policy in the module's documentation).
#[derive(Clone, Copy)]
enum Replaces {
    /// A command (C/S = 0): none, each command matters.
    Nothing,
    /// A sensor topic of one frame per sample: the queued frame with its identifier.
    SameId,
    /// A sensor topic whose sample spans several frames: the one with the same first data byte
    /// (the frame's index, such as the proximity ring's sensor number).
    SameIndex(Option<u8>),
}

impl Replaces {
    fn of(newer: &Frame) -> Replaces {
        let id = newer.id();
        if id.kind() != Kind::Sensor {
            return Replaces::Nothing;
        }
        let multi_frame = Topic::from_byte(id.topic_byte())
            .map(|topic| topic.frames_per_sample() > 1)
            .unwrap_or(false);
        if multi_frame {
            Replaces::SameIndex(newer.data().first().copied())
        } else {
            Replaces::SameId
        }
    }

    /// Whether `queued`, which has the newer frame's identifier, is an older sample of it.
    fn matches(self, queued: &Frame) -> bool {
        match self {
            Replaces::Nothing => false,
            Replaces::SameId => true,
            Replaces::SameIndex(index) => queued.data().first().copied() == index,
        }
    }
}

impl<const N: usize> TxQueue<N> {
    /// A slot number is one byte.
    const FITS: () = assert!(N <= 256, "a TxQueue holds at most 256 frames");

    /// Every slot free, in slot order.
    const FREE: [u8; N] = {
        let mut order = [0u8; N];
        let mut slot = 0;
        while slot < N {
            // N <= 256 (FITS), so the slot number fits in a byte.
            order[slot] = slot as u8;
            slot += 1;
        }
        order
    };

    /// An empty queue.
    pub const fn new() -> Self {
        #[allow(clippy::let_unit_value)]
        let () = Self::FITS;
        Self {
            slots: [Frame::empty(CanId::new(Kind::Command, amiro_can::Priority::Urgent, 0)); N],
            order: Self::FREE,
            len: 0,
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
        match self.place(&frame) {
            Place::Same(slot) => {
                if let Some(queued) = self.slots.get_mut(slot) {
                    let older = core::mem::replace(queued, frame);
                    self.counters.replaced = self.counters.replaced.saturating_add(1);
                    return PushOutcome::Replaced { older };
                }
                // Unreachable: `place` found the slot among the queued ones. Report it as a drop
                // rather than queue a second sample.
                self.counters.dropped = self.counters.dropped.saturating_add(1);
                PushOutcome::DroppedNew { dropped: frame }
            }
            // Newest among equal identifiers: in front of (below) the ones already waiting.
            Place::Between { above, .. } => {
                let raw = frame.id().raw();
                self.insert_or_drop(above, frame, |last_in_line| raw >= last_in_line)
            }
        }
    }

    /// Puts back a frame that a more urgent one displaced from a transmit mailbox (bxcan hands it
    /// back from `transmit`). It was queued before anything now waiting with its identifier, so it
    /// goes ahead of those; if a newer sample of its topic is already queued, it is discarded
    /// instead (counted as replaced).
    pub fn requeue(&mut self, frame: Frame) -> PushOutcome {
        self.counters.requeued = self.counters.requeued.saturating_add(1);
        match self.place(&frame) {
            Place::Same(_) => {
                self.counters.replaced = self.counters.replaced.saturating_add(1);
                PushOutcome::Replaced { older: frame }
            }
            Place::Between { through, .. } => {
                let raw = frame.id().raw();
                self.insert_or_drop(through, frame, |last_in_line| raw > last_in_line)
            }
        }
    }

    /// One pass over the queued frames from the one leaving last, as far as the first with a
    /// smaller identifier (the order is by identifier, so the frames of `frame`'s identifier are
    /// together): an older sample of `frame`, or where `frame` goes.
    fn place(&self, frame: &Frame) -> Place {
        let raw = frame.id().raw();
        let replaces = Replaces::of(frame);
        let (mut above, mut through) = (0, 0);
        for &slot in self.order.iter().take(self.len) {
            let slot = usize::from(slot);
            let Some(queued) = self.slots.get(slot) else {
                break;
            };
            let id = queued.id().raw();
            if id < raw {
                break;
            }
            if id > raw {
                above += 1;
            } else if replaces.matches(queued) {
                return Place::Same(slot);
            }
            through += 1;
        }
        Place::Between { above, through }
    }

    /// The frame at `at` in `order` (0 leaves last), if queued.
    fn at(&self, at: usize) -> Option<&Frame> {
        if at >= self.len {
            return None;
        }
        let slot = self.order.get(at)?;
        self.slots.get(usize::from(*slot))
    }

    /// Inserts `frame` at `at` of `order` (`at` queued frames leave after it); when full, drops
    /// whichever of it and the frame that would leave last goes last (`new_goes_last(id of the
    /// frame leaving last)`). Slot numbers move by swaps, not `copy_within` (no `memmove` is linked
    /// into the images for it), and only one way per call: at most `N - 1` of them.
    fn insert_or_drop(
        &mut self,
        at: usize,
        frame: Frame,
        new_goes_last: impl FnOnce(u16) -> bool,
    ) -> PushOutcome {
        if self.len < N {
            // The first free slot takes the frame, and its number moves from `len` down to `at`
            // (`at` <= len: it counted queued frames).
            let Some(slot) = self
                .order
                .get(self.len)
                .and_then(|slot| self.slots.get_mut(usize::from(*slot)))
            else {
                // Unreachable: len < N. Report it as a drop rather than lose it silently.
                self.counters.dropped = self.counters.dropped.saturating_add(1);
                return PushOutcome::DroppedNew { dropped: frame };
            };
            *slot = frame;
            for i in (at..self.len).rev() {
                swap_with_next(&mut self.order, i);
            }
            self.len += 1;
            self.note_high_water();
            return PushOutcome::Queued;
        }
        let evict = match self.at(0) {
            Some(last_in_line) => !new_goes_last(last_in_line.id().raw()),
            // Only with N = 0: nowhere to put anything.
            None => false,
        };
        if !evict {
            self.counters.dropped = self.counters.dropped.saturating_add(1);
            return PushOutcome::DroppedNew { dropped: frame };
        }
        // The frame leaving last, at 0, gives its slot to the new one, whose number moves up to
        // `at - 1` (`at` >= 1: the frame at 0 leaves after the new one, so `at` counted it).
        let Some(slot) = self
            .order
            .first()
            .and_then(|slot| self.slots.get_mut(usize::from(*slot)))
        else {
            // Unreachable: the frame at 0 was just read.
            self.counters.dropped = self.counters.dropped.saturating_add(1);
            return PushOutcome::DroppedNew { dropped: frame };
        };
        let dropped = core::mem::replace(slot, frame);
        for i in 1..at {
            swap_with_next(&mut self.order, i - 1);
        }
        self.counters.dropped = self.counters.dropped.saturating_add(1);
        self.note_high_water();
        PushOutcome::DroppedOther { dropped }
    }

    fn note_high_water(&mut self) {
        let len = u16::try_from(self.len).unwrap_or(u16::MAX);
        self.counters.high_water = self.counters.high_water.max(len);
    }

    /// Takes the most urgent frame (lowest identifier, oldest among equals).
    pub fn pop(&mut self) -> Option<Frame> {
        let next = self.len.checked_sub(1)?;
        let frame = *self.at(next)?;
        self.len = next;
        self.counters.popped = self.counters.popped.saturating_add(1);
        Some(frame)
    }

    /// Takes the most urgent frame only if it beats `id` in arbitration (strictly lower
    /// identifier): the transmit interrupt uses it to decide whether to swap out a pending
    /// mailbox frame with identifier `id`.
    pub fn pop_if_higher_priority_than(&mut self, id: CanId) -> Option<Frame> {
        match self.peek() {
            Some(next) if next.id().raw() < id.raw() => self.pop(),
            _ => None,
        }
    }

    /// The frame `pop` would return.
    pub fn peek(&self) -> Option<&Frame> {
        self.at(self.len.checked_sub(1)?)
    }

    /// Frames waiting.
    pub fn len(&self) -> usize {
        self.len
    }

    /// True when nothing waits.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The capacity `N`.
    pub const fn capacity(&self) -> usize {
        N
    }

    /// The waiting frames in the order they will leave.
    pub fn iter(&self) -> impl Iterator<Item = &Frame> {
        self.order
            .iter()
            .take(self.len)
            .rev()
            .filter_map(|slot| self.slots.get(usize::from(*slot)))
    }

    /// Empties the queue (shutdown); the discarded frames are not counted as dropped.
    pub fn clear(&mut self) {
        self.len = 0;
    }

    /// What the queue has done since boot.
    pub fn counters(&self) -> &TxCounters {
        &self.counters
    }
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
        // 16 frames of 12 bytes, their 16 slot numbers, the length and the counters.
        let limit = 16 * 12 + 16 + core::mem::size_of::<usize>() + 24;
        assert!(size <= limit, "TxQueue<16> is {size} bytes");
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
