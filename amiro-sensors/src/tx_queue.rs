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
//! Each frame stays in a fixed slot from when it is queued until it leaves; what moves is one word
//! per queued frame, its *entry*, kept in an array in the order the frames will leave, the next one
//! last. An entry packs the frame's identifier (the sort key, in its top bits, so entries compare as
//! plain words), the index byte that tells a multi-frame topic's frames apart, and the slot number.
//! So `pop` in the transmit interrupt is O(1); `push` and `requeue` find the frame's place by one
//! binary search over the entries (at most `log2 N + 1` word loads and compares, straight-line
//! code, no frame read), look for another sample of its topic only among the frames of the same
//! identifier (one entry for a topic of one frame per sample, none for a command; for a topic
//! whose sample spans several frames a walk forward from where those frames start, one test an
//! entry), and move at most `N` entries by one place, each carried through a register (one load
//! and one store), never a frame. The walk and the moves index the entries from the array's start
//! (the execution-time bound then places every access in RAM; `position_of_sample`).

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
#[repr(C)]
pub struct TxQueue<const N: usize> {
    /// One entry per slot ([`entry`]); their slot numbers are a permutation of `0..N`.
    /// `entries[..len]` are the queued frames' in reverse leaving order: identifiers descending, and
    /// among equal identifiers the newest first, so the next frame to send is `entries[len - 1]`'s.
    /// `entries[len..]` hold the free slots' numbers (the rest of such an entry is stale).
    /// First, at the queue's own address (`repr(C)`): the searches and moves then index the queue's
    /// address itself, which the execution-time bound places in RAM, with no offset for the
    /// compiler to add to the index first (an address the bound cannot place).
    entries: [u32; N],
    /// The frames, each in its slot from `push` until it leaves; a free slot's contents are stale.
    slots: [Frame; N],
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

/// The bits of an entry ([`TxQueue`]'s `entries`): the identifier plus one from bit 20 (so every
/// queued frame's entry is at least `1 << 20`), the index tag from bit 8 (bit 16 set when the frame
/// has a first data byte, bits 8–15 that byte: the sensor number of a multi-frame topic's frame),
/// the slot number in bits 0–7. Entries in descending order are frames in descending identifier
/// order, whatever their tags and slots.
const KEY_SHIFT: u32 = 20;
const TAG_SHIFT: u32 = 8;
const TAG_MASK: u32 = 0x1FF << TAG_SHIFT;
const SLOT_MASK: u32 = 0xFF;

/// The smallest entry of a frame with identifier `raw` (11 bits: [`CanId`]'s range; the mask only
/// keeps the arithmetic in 32 bits).
fn key_floor(raw: u16) -> u32 {
    (u32::from(raw & 0x7FF) + 1) << KEY_SHIFT
}

/// The index tag of a frame: its first data byte, if it has one (bits 8–16 of an entry).
#[inline(always)]
fn tag(frame: &Frame) -> u32 {
    frame
        .data()
        .first()
        .map_or(0, |&byte| (0x100 | u32::from(byte)) << TAG_SHIFT)
}

/// The slot number of an entry.
fn slot_of(entry: u32) -> usize {
    (entry & SLOT_MASK) as usize
}

/// How many of `entries` (in descending order, at most `N` of them) are at least `floor`: the
/// length of the prefix that is. Binary lifting over the positions, from the largest power of two
/// at most `N` down to 1: one word load and compare per step, `log2 N + 1` steps (5 for 16 frames,
/// 4 for 8), written out as straight-line code: the steps larger than `N` are constants the
/// compiler drops, and no loop is left for the transmit interrupt's bound to charge a taken branch,
/// a pipeline refill and a flash line per step (and a bounds-file entry to state). `N` is at most
/// 256 ([`TxQueue`]).
#[inline(always)]
fn count_at_least<const N: usize>(entries: &[u32], floor: u32) -> usize {
    let mut count = 0;
    // One step: take `STEP` more if the last of them is still at least `floor`.
    macro_rules! step {
        ($step:literal) => {
            if $step <= N
                && entries
                    .get(count + ($step - 1))
                    .is_some_and(|&e| e >= floor)
            {
                count += $step;
            }
        };
    }
    step!(256);
    step!(128);
    step!(64);
    step!(32);
    step!(16);
    step!(8);
    step!(4);
    step!(2);
    step!(1);
    count
}

/// The bits of an entry that say which identifier its frame has (its sort key, [`key_floor`]).
const ID_MASK: u32 = !(TAG_MASK | SLOT_MASK);

/// Where among the queued `entries`, from `from` (where the frames of its identifier start) as far
/// as the first with another identifier, the entry of the frame `sample` (identifier and tag bits)
/// is: `Ok` with its place, or `Err` with where its identifier's frames end (the first entry of
/// another identifier, or the end) when it is not there. A push's search for an older sample
/// among the frames of its identifier, and a requeue's for a newer one, which also learns its
/// place from it. One test per entry: the entry's bits above the slot number, against `sample`'s,
/// are 0 for the frame itself, 1 to 0x1FF for another frame of its identifier (only the tag
/// differs; bits 17–19 are 0 in every entry) and more for another identifier.
///
/// This loop and the two below index `entries` from its start rather than walk a pointer or a
/// subslice: the execution-time bound then knows every access is into the array's memory (RAM),
/// where a stepped pointer, which its analysis stops following after a few passes, is charged a
/// peripheral's bus latency on every load and store (docs/analysis.md, "The cycle model").
#[inline(never)]
fn position_of_sample(entries: &[u32], from: usize, sample: u32) -> Result<usize, usize> {
    let mut at = from;
    if at >= entries.len() {
        return Err(at);
    }
    // Tested at the bottom, one branch back a pass (`at` is below the length in the body).
    loop {
        let Some(&queued) = entries.get(at) else {
            return Err(at);
        };
        let apart = (queued ^ sample) >> TAG_SHIFT;
        if apart.wrapping_sub(1) >= TAG_MASK >> TAG_SHIFT {
            return if apart == 0 { Ok(at) } else { Err(at) };
        }
        at += 1;
        if at >= entries.len() {
            return Err(at);
        }
    }
}

/// Moves every entry of `entries` from `from` on one place up (towards the end) and puts `new` at
/// `from`: the last entry, a free slot's whose number `new` carries, is overwritten. Each carried
/// through a register (a `copy_within` would link `memmove`, whose byte loop the execution-time
/// bound charges).
#[inline(never)]
fn carry_up(entries: &mut [u32], from: usize, new: u32) {
    let mut carried = new;
    let mut at = from;
    if at >= entries.len() {
        return;
    }
    // Tested at the bottom, one branch a pass (`at` is below the length in the body).
    loop {
        if let Some(place) = entries.get_mut(at) {
            carried = core::mem::replace(place, carried);
        }
        at += 1;
        if at >= entries.len() {
            return;
        }
    }
}

/// Moves every entry of `entries` one place down (towards the start) and puts `new` last: the
/// first entry, the evicted frame's whose slot number `new` carries, is overwritten. From the
/// start, each entry taking the next one's value through two views of the same cells (the one a
/// word further on), tested at the bottom as [`carry_up`]: a loop down to the start would have the
/// compiler address the array's start less a word, which the bound cannot place in RAM.
#[inline(never)]
fn carry_down(entries: &mut [u32], new: u32) {
    let cells = core::cell::Cell::from_mut(entries).as_slice_of_cells();
    let next = cells.split_first().map_or(cells, |(_, rest)| rest);
    let mut at = 0;
    if at < next.len() {
        loop {
            if let (Some(place), Some(following)) = (cells.get(at), next.get(at)) {
                place.set(following.get());
            }
            at += 1;
            if at >= next.len() {
                break;
            }
        }
    }
    if let Some(last) = cells.last() {
        last.set(new);
    }
}

/// Which queued frames of the same identifier a newer frame is a newer sample of, worked out once
/// from the newer frame (the policy in the module's documentation).
#[derive(Clone, Copy)]
enum Replaces {
    /// A command (C/S = 0): none, each command matters.
    Nothing,
    /// A sensor topic of one frame per sample: the queued frame with its identifier (at most one
    /// is queued: a second sample always replaced the first).
    SameId,
    /// A sensor topic whose sample spans several frames: the one with the same first data byte
    /// (the frame's index, such as the proximity ring's sensor number): the same entry bits but for
    /// the slot number.
    SameIndex,
}

/// The topic bytes (bit `b` for byte `b`; every topic's byte is below 32) of the topics whose sample
/// spans several frames, worked out from amiro-can's table when compiling: a lookup per frame
/// queued or requeued cost a call into the table.
const MULTI_FRAME_TOPICS: u32 = {
    let mut bits = 0u32;
    let mut byte = 0u8;
    while byte < 32 {
        if let Some(topic) = Topic::from_byte(byte) {
            if topic.frames_per_sample() > 1 {
                bits |= 1 << byte;
            }
        }
        byte += 1;
    }
    bits
};

impl Replaces {
    #[inline(always)]
    fn of(newer: &Frame) -> Replaces {
        let id = newer.id();
        if id.kind() != Kind::Sensor {
            return Replaces::Nothing;
        }
        let multi_frame = MULTI_FRAME_TOPICS
            .checked_shr(u32::from(id.topic_byte()))
            .is_some_and(|bits| bits & 1 != 0);
        if multi_frame {
            Replaces::SameIndex
        } else {
            Replaces::SameId
        }
    }
}

impl<const N: usize> TxQueue<N> {
    /// A slot number is one byte.
    const FITS: () = assert!(N <= 256, "a TxQueue holds at most 256 frames");

    /// Every slot free, in slot order.
    const FREE: [u32; N] = {
        let mut entries = [0u32; N];
        let mut slot = 0;
        while slot < N {
            // N <= 256 (FITS), so the slot number fits in a byte.
            entries[slot] = slot as u32;
            slot += 1;
        }
        entries
    };

    /// An empty queue.
    pub const fn new() -> Self {
        #[allow(clippy::let_unit_value)]
        let () = Self::FITS;
        Self {
            entries: Self::FREE,
            slots: [Frame::empty(CanId::new(Kind::Command, amiro_can::Priority::Urgent, 0)); N],
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

    /// The queued frames' entries: from the one leaving last to the next one to leave.
    fn queued(&self) -> &[u32] {
        self.entries.split_at(self.len.min(N)).0
    }
    /// Queues a new frame under the overload policy of this module: the frames with a greater
    /// identifier end at `above` (one binary search) and leave after it, the ones with its identifier
    /// follow, newest first. An older sample is looked for among those (one entry for a topic of one
    /// frame per sample, none for a command) and replaced; otherwise the frame goes in front of
    /// (below) its equals, at `above`.
    #[inline(never)]
    pub fn push(&mut self, frame: Frame) -> PushOutcome {
        self.counters.pushed = self.counters.pushed.saturating_add(1);
        let key = key_floor(frame.id().raw());
        let sample = key | tag(&frame);
        let above = count_at_least::<N>(self.queued(), key + (1 << KEY_SHIFT));
        let older = match Replaces::of(&frame) {
            Replaces::Nothing => None,
            // At most one is queued: the first after `above`, if it has the identifier.
            Replaces::SameId => self
                .queued()
                .get(above)
                .filter(|&&queued| queued & ID_MASK == key)
                .map(|_| above),
            Replaces::SameIndex => position_of_sample(self.queued(), above, sample).ok(),
        };
        match older {
            Some(found) => self.replace_at(found, frame, sample),
            // A full queue's last frame (at 0) leaves after it only with a greater identifier,
            // that is when `above` counted it.
            None => self.insert_or_drop(above, frame, sample, above > 0),
        }
    }

    /// Puts `frame` in the place of the queued frame at `at`, an older sample of it.
    fn replace_at(&mut self, at: usize, frame: Frame, sample: u32) -> PushOutcome {
        let Some(queued) = self.entries.get_mut(at) else {
            // Unreachable: `at` was read. Report it as a drop rather than queue a second sample.
            return self.refuse(frame);
        };
        let slot = *queued & SLOT_MASK;
        *queued = sample | slot;
        let Some(place) = self.slots.get_mut(slot as usize) else {
            // Unreachable: a slot number is below N.
            return self.refuse(frame);
        };
        let older = core::mem::replace(place, frame);
        self.counters.replaced = self.counters.replaced.saturating_add(1);
        PushOutcome::Replaced { older }
    }

    /// Puts back a frame that a more urgent one displaced from a transmit mailbox (bxcan hands it
    /// back from `transmit`). It was queued before anything now waiting with its identifier, so it
    /// goes ahead of those, at `at`: one binary search counts the frames with its identifier or a
    /// greater one, which leave after it. If a newer sample of its topic is already queued (among
    /// the last of those), it is discarded instead (counted as replaced). For a multi-frame topic
    /// the search counts only the greater identifiers, where its identifier's frames start, and
    /// `position_of_sample` walks those forward, as `push`'s does, to the newer sample or to
    /// where they end, `at` (a walk back from `at` would have the compiler address the array's
    /// start less a word, which the execution-time bound cannot place in RAM). Its own body, not
    /// [`Self::push`]'s: the transmit interrupt's bound charges it per aborted frame by its name
    /// (the bounds files' `per_frame` `requeue`), so it is not inlined.
    #[inline(never)]
    pub fn requeue(&mut self, frame: Frame) -> PushOutcome {
        self.counters.requeued = self.counters.requeued.saturating_add(1);
        let key = key_floor(frame.id().raw());
        let sample = key | tag(&frame);
        let replaces = Replaces::of(&frame);
        let floor = match replaces {
            Replaces::SameIndex => key + (1 << KEY_SHIFT),
            Replaces::Nothing | Replaces::SameId => key,
        };
        let counted = count_at_least::<N>(self.queued(), floor);
        let (newer, at) = match replaces {
            Replaces::Nothing => (false, counted),
            // At most one is queued: the last before `at`, if it has the identifier.
            Replaces::SameId => {
                let last = counted
                    .checked_sub(1)
                    .and_then(|last| self.queued().get(last));
                (last.is_some_and(|&queued| queued & ID_MASK == key), counted)
            }
            // Its identifier's frames start at `counted`.
            Replaces::SameIndex => match position_of_sample(self.queued(), counted, sample) {
                Ok(newer) => (true, newer),
                Err(end) => (false, end),
            },
        };
        if newer {
            self.counters.replaced = self.counters.replaced.saturating_add(1);
            return PushOutcome::Replaced { older: frame };
        }
        // A full queue's last frame (at 0) leaves after it if its identifier is at least as
        // great, that is when `at` counted it.
        self.insert_or_drop(at, frame, sample, at > 0)
    }

    /// The frame at `at` in the leaving order (0 leaves last), if queued.
    fn at(&self, at: usize) -> Option<&Frame> {
        if at >= self.len {
            return None;
        }
        let entry = self.entries.get(at)?;
        self.slots.get(slot_of(*entry))
    }

    /// Inserts `frame` (its entry's bits but the slot number: `sample`) at `at` of the entries (`at` queued frames leave after it); when full,
    /// drops whichever of it and the frame that would leave last goes last (the one leaving last
    /// is evicted when `evict`: the caller's count of the frames leaving after it included it,
    /// so no frame is read for it). The entries between move by one place ([`carry_up`],
    /// [`carry_down`]), only one way per call: at most `N - 1` of them.
    fn insert_or_drop(&mut self, at: usize, frame: Frame, sample: u32, evict: bool) -> PushOutcome {
        if self.len < N {
            // The first free slot takes the frame, and the entries from `at` move up by one onto
            // the free entry at `len` (`at` <= len: it counted queued frames).
            let len = self.len;
            let free = self.entries.get(len).copied();
            let (Some(free), Some(moving)) = (free, self.entries.get_mut(..=len)) else {
                // Unreachable: len < N. Report it as a drop rather than lose it silently.
                return self.refuse(frame);
            };
            carry_up(moving, at, sample | (free & SLOT_MASK));
            if let Some(slot) = self.slots.get_mut(slot_of(free)) {
                *slot = frame;
            }
            self.len = len + 1;
            self.note_high_water();
            return PushOutcome::Queued;
        }
        // With N = 0 nothing is queued, so `at` is 0 and nothing is evicted: nowhere to put it.
        if !evict {
            return self.refuse(frame);
        }
        // The frame leaving last, at 0, gives its slot to the new one, whose entry goes to `at - 1`
        // as the ones from 1 to `at - 1` move down by one (`at` >= 1: the frame at 0 leaves after
        // the new one, so `at` counted it).
        let last = self.entries.first().copied();
        let (Some(last), Some(moving)) = (last, self.entries.get_mut(..at)) else {
            // Unreachable: the frame at 0 was just read.
            return self.refuse(frame);
        };
        carry_down(moving, sample | (last & SLOT_MASK));
        let Some(slot) = self.slots.get_mut(slot_of(last)) else {
            // Unreachable: a slot number is below N.
            return self.refuse(frame);
        };
        let dropped = core::mem::replace(slot, frame);
        self.counters.dropped = self.counters.dropped.saturating_add(1);
        // No high-water mark to note: the queue was full before, so it is already `N`.
        PushOutcome::DroppedOther { dropped }
    }

    /// Drops `frame` unqueued, counted: a full queue's frame that would leave last, and the
    /// unreachable arms where an index was already checked. One body for all of them, out of line.
    #[cold]
    #[inline(never)]
    fn refuse(&mut self, frame: Frame) -> PushOutcome {
        self.counters.dropped = self.counters.dropped.saturating_add(1);
        PushOutcome::DroppedNew { dropped: frame }
    }

    fn note_high_water(&mut self) {
        let len = u16::try_from(self.len).unwrap_or(u16::MAX);
        self.counters.high_water = self.counters.high_water.max(len);
    }

    /// Takes the most urgent frame (lowest identifier, oldest among equals).
    ///
    /// The frame is read beside the queue's shortening, not before it: where the caller drops it
    /// (the transmit interrupt, which sent the frame from [`Self::peek`]'s reference), the compiler
    /// drops the read, a call per frame the interrupt's bound charges.
    pub fn pop(&mut self) -> Option<Frame> {
        let next = self.len.checked_sub(1)?;
        let frame = self.at(next).copied();
        self.len = next;
        self.counters.popped = self.counters.popped.saturating_add(1);
        frame
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
        self.entries
            .iter()
            .take(self.len)
            .rev()
            .filter_map(|entry| self.slots.get(slot_of(*entry)))
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
        // 16 frames of 12 bytes, their 16 entries of a word, the length and the counters.
        let limit = 16 * 12 + 16 * 4 + core::mem::size_of::<usize>() + 24;
        assert!(size <= limit, "TxQueue<16> is {size} bytes");
    }

    #[test]
    fn the_multi_frame_mask_is_the_topic_table() {
        for byte in 0..=u8::MAX {
            let from_table = Topic::from_byte(byte).is_some_and(|t| t.frames_per_sample() > 1);
            let from_mask = MULTI_FRAME_TOPICS
                .checked_shr(u32::from(byte))
                .is_some_and(|bits| bits & 1 != 0);
            assert_eq!(from_mask, from_table, "topic byte {byte:#04x}");
        }
        assert_ne!(
            MULTI_FRAME_TOPICS, 0,
            "the proximity ring spans several frames"
        );
    }

    /// The straight-line search against a count, for every capacity's steps (0, 1, powers of two
    /// and between) and every prefix length and floor of descending entries.
    #[test]
    fn the_unrolled_search_counts_the_entries_at_least_the_floor() {
        fn check<const N: usize>() {
            let entries: Vec<u32> = (0..N as u32).rev().map(|i| 2 * i + 10).collect();
            for len in 0..=N {
                let queued = &entries[..len];
                for floor in 0..=(2 * N as u32 + 12) {
                    let counted = queued.iter().filter(|&&e| e >= floor).count();
                    assert_eq!(
                        count_at_least::<N>(queued, floor),
                        counted,
                        "N {N} len {len} floor {floor}"
                    );
                }
            }
        }
        check::<0>();
        check::<1>();
        check::<3>();
        check::<8>();
        check::<16>();
        check::<17>();
        check::<256>();
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
