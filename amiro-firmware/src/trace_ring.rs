//! The trace ring's hardware-free core: slots a writer reserves under a short critical section
//! and fills outside it, and one drain that takes them out oldest first without any critical
//! section (`tracing` on the robot).
//!
//! A writer's record is two steps: [`Ring::reserve`] under its critical section (a few
//! instructions: the ring's next free slot, or the record counted as lost when all `N` are
//! reserved), then [`Claim::fill`] outside it (the copy, then the slot's *complete* flag set). The
//! drain's is one: [`Ring::take`] copies the oldest slot out once it is complete and frees it.
//!
//! The indices are two free-running counters: `reserved`, written only by [`Ring::reserve`] (its
//! callers exclude each other by a critical section), and `released`, written only by the drain.
//! Each is one word, read and written whole on the core (relaxed atomics), so the drain needs no
//! critical section, and a writer only reads `released`.
//!
//! One core only ([`Ring::new`]'s contract): the writers and the drain interleave only where an
//! interrupt preempts, like a signal handler and the code it interrupts, so compiler fences order a
//! slot's copy against its flag and the drain's read against its release (no `DMB`: the core
//! itself sees its own accesses in program order).
//!
//! Why that is correct (one core; writers are interrupt handlers of any priority, or thread mode;
//! the drain is one task at the lowest priority, and the slots' only reader):
//! * **One writer per slot.** `reserve` hands out the slot `reserved mod N` and counts it in one
//!   step under the critical section, and only the drain's `take` frees it, after reading it. So
//!   between its reservation and its release a slot belongs to the one [`Claim`] (not `Clone`,
//!   consumed by `fill`); a writer that preempts another mid-copy reserves the next slot, never
//!   the same one.
//! * **The drain reads only complete slots.** `fill` sets the flag after the copy (a release
//!   fence before it), and `take` reads the slot only after seeing the flag set (an acquire fence
//!   after it). A slot
//!   reserved but not yet complete — its writer preempted mid-copy, maybe by writers that completed
//!   later slots — stops the drain there: it takes nothing and tries again on its next job, so
//!   records leave in the order they were reserved (the order of their stamps, which the firmware
//!   takes under the reservation's critical section).
//! * **No slot is written while the drain reads it.** The drain reads the slot `released mod N`,
//!   which stays counted (`reserved − released`) until the drain moves `released` past it, after
//!   its copy and after clearing the flag (a release fence before it). A writer that reads the old `released`
//!   sees the ring one slot fuller than it is: at worst a record counted as lost while the drain
//!   was freeing a slot, never a slot handed out twice.
//! * **Loss is counted, never silent.** A reservation that finds all `N` slots reserved (complete
//!   or not) counts the record in `lost`; the drain reports what it has not reported yet
//!   ([`Ring::take_lost`]) before the next record it writes, and counts back what its channel had
//!   no room for ([`Ring::count_lost`]).
//!
//! The drain also widens the writers' raw 32-bit stamps to 64 bits ([`Widen`]): it takes the
//! records in the order of their stamps, so a stamp below the one before is a wrap.
//!
//! The host tests below run these steps in the orders an interrupt can put them in.
use core::cell::UnsafeCell;
use core::sync::atomic::{compiler_fence, AtomicBool, AtomicU32, AtomicUsize, Ordering};

/// A ring of `N` records (a power of two) of type `T`.
pub struct Ring<T, const N: usize> {
    /// Slots handed out, ever (wrapping): written by `reserve` only.
    reserved: AtomicUsize,
    /// Slots the drain has taken out, ever (wrapping): written by the drain only.
    released: AtomicUsize,
    /// Records turned away, ever (wrapping): written by `reserve` only.
    lost: AtomicU32,
    /// Of those, the ones the drain has reported (wrapping): written by the drain only.
    reported: AtomicU32,
    records: UnsafeCell<[T; N]>,
    complete: [AtomicBool; N],
}

// SAFETY: a slot is written only by the holder of its `Claim` and read only by the drain, never
// both at once (the module's argument, on the one core `Ring::new` requires); everything else is
// atomics.
unsafe impl<T: Send, const N: usize> Sync for Ring<T, N> {}

/// The right to fill one reserved slot, once ([`Claim::fill`]).
#[must_use = "a reserved slot that is never filled stops the drain"]
pub struct Claim<'r, T, const N: usize> {
    ring: &'r Ring<T, N>,
    at: usize,
}

impl<T: Copy, const N: usize> Ring<T, N> {
    /// `N` slots holding `empty`, none reserved.
    ///
    /// # Safety
    /// The ring is used on one core only: its writers and its drain run on the same core (thread
    /// mode and interrupt handlers), never in parallel — its orderings are compiler fences.
    pub const unsafe fn new(empty: T) -> Self {
        assert!(N.is_power_of_two());
        Self {
            reserved: AtomicUsize::new(0),
            released: AtomicUsize::new(0),
            lost: AtomicU32::new(0),
            reported: AtomicU32::new(0),
            records: UnsafeCell::new([empty; N]),
            complete: [const { AtomicBool::new(false) }; N],
        }
    }

    /// Reserves the next slot for one record, or counts the record as lost when every slot is
    /// reserved.
    ///
    /// # Safety
    /// No other call of `reserve` on this ring runs meanwhile: call it under a critical section.
    #[inline(always)]
    pub unsafe fn reserve(&self) -> Option<Claim<'_, T, N>> {
        let reserved = self.reserved.load(Ordering::Relaxed);
        let released = self.released.load(Ordering::Relaxed);
        // The drain's read of the slot `released` frees came before its release (one core).
        compiler_fence(Ordering::Acquire);
        if reserved.wrapping_sub(released) >= N {
            let lost = self.lost.load(Ordering::Relaxed);
            self.lost.store(lost.wrapping_add(1), Ordering::Relaxed);
            return None;
        }
        self.reserved
            .store(reserved.wrapping_add(1), Ordering::Relaxed);
        Some(Claim {
            ring: self,
            at: reserved & (N - 1),
        })
    }

    /// Copies the oldest slot into `out` and frees it, if it is complete; `false` (nothing read)
    /// when the ring is empty or the oldest slot's writer has not finished it.
    ///
    /// # Safety
    /// The caller is the ring's only drain: no other call of `take` or [`Ring::count_lost`] runs
    /// meanwhile.
    pub unsafe fn take(&self, out: &mut T) -> bool {
        let released = self.released.load(Ordering::Relaxed);
        if self.reserved.load(Ordering::Relaxed) == released {
            return false;
        }
        let flag = &self.complete[released & (N - 1)];
        if !flag.load(Ordering::Relaxed) {
            return false;
        }
        // The writer's copy came before its flag (one core).
        compiler_fence(Ordering::Acquire);
        // SAFETY: complete, and counted until `released` moves past it: no writer holds it.
        *out = unsafe { *self.slot(released) };
        flag.store(false, Ordering::Relaxed);
        compiler_fence(Ordering::Release);
        self.released
            .store(released.wrapping_add(1), Ordering::Relaxed);
        true
    }

    /// The records turned away since the last call (now reported).
    ///
    /// # Safety
    /// As [`Ring::take`]: the drain's only.
    pub unsafe fn take_lost(&self) -> u32 {
        let lost = self.lost.load(Ordering::Relaxed);
        let new = lost.wrapping_sub(self.reported.load(Ordering::Relaxed));
        self.reported.store(lost, Ordering::Relaxed);
        new
    }

    /// Counts `count` taken records as lost again (the drain's channel had no room for them):
    /// the next [`Ring::take_lost`] reports them.
    ///
    /// # Safety
    /// As [`Ring::take`]: the drain's only.
    pub unsafe fn count_lost(&self, count: u32) {
        let reported = self.reported.load(Ordering::Relaxed);
        self.reported
            .store(reported.wrapping_sub(count), Ordering::Relaxed);
    }
}

impl<T, const N: usize> Ring<T, N> {
    /// Slot `at` (masked below `N`), without a reference to the whole array.
    fn slot(&self, at: usize) -> *mut T {
        // In bounds (`at` is masked below `N`); no reference to the whole array.
        self.records.get().cast::<T>().wrapping_add(at & (N - 1))
    }
}

impl<T, const N: usize> Claim<'_, T, N> {
    /// Writes the reserved slot (`write` gets it with its previous contents) and marks it
    /// complete. Outside any critical section.
    pub fn fill(self, write: impl FnOnce(&mut T)) {
        let at = self.at & (N - 1);
        // SAFETY: the claim is the slot's only writer, and the drain does not read it before
        // its flag is set (the module's argument); `at` is below `N`.
        write(unsafe { &mut *self.ring.slot(at) });
        compiler_fence(Ordering::Release);
        self.ring.complete[at].store(true, Ordering::Relaxed);
    }
}

/// A 32-bit counter's readings widened to 64 bits, for a reader that sees them in the order they
/// were taken: a reading below the one before means the counter wrapped once in between. The
/// drain widens the writers' raw stamps so (a writer's stamp is one load): it takes the records in
/// the order of their reservations, under which each stamp is read, so consecutive records are in
/// time order and the wrap is seen as long as they are less than one wrap apart — as when the
/// writers widened their own stamps, each against the record stamped before it.
#[derive(Clone, Copy, Debug, Default)]
pub struct Widen {
    /// Wraps seen so far: the high word.
    high: u32,
    /// The latest reading taken in order.
    last: u32,
}

impl Widen {
    /// Nothing read yet: the counter started at zero.
    pub const fn new() -> Self {
        Self { high: 0, last: 0 }
    }

    /// The next reading in order, widened; it becomes the one later readings are compared to.
    pub fn advance(&mut self, raw: u32) -> u64 {
        let wide = self.peek(raw);
        self.high = (wide >> 32) as u32;
        self.last = raw;
        wide
    }

    /// A reading taken after the latest one (and after those still to come through
    /// [`Widen::advance`]), widened without becoming the latest: a stamp read now, written before
    /// records stamped earlier (the drain's `Lost` report).
    pub fn peek(&self, raw: u32) -> u64 {
        let high = self.high.wrapping_add(u32::from(raw < self.last));
        u64::from(high) << 32 | u64::from(raw)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn widening_counts_each_wrap_between_readings_in_order() {
        let mut clock = Widen::new();
        assert_eq!(clock.advance(5), 5);
        assert_eq!(clock.advance(5), 5);
        assert_eq!(clock.advance(u32::MAX), u64::from(u32::MAX));
        assert_eq!(clock.advance(3), 1 << 32 | 3);
        assert_eq!(clock.advance(0x8000_0000), 1 << 32 | 0x8000_0000);
        assert_eq!(clock.advance(1), 2 << 32 | 1);
    }

    #[test]
    fn a_peeked_reading_leaves_the_widening_of_older_ones_alone() {
        let mut clock = Widen::new();
        assert_eq!(clock.advance(u32::MAX - 10), u64::from(u32::MAX - 10));
        // A report stamped after a wrap, written before two records stamped earlier, one on either
        // side of the wrap.
        assert_eq!(clock.peek(20), 1 << 32 | 20);
        assert_eq!(clock.advance(u32::MAX - 5), u64::from(u32::MAX - 5));
        assert_eq!(clock.advance(10), 1 << 32 | 10);
        assert_eq!(clock.advance(30), 1 << 32 | 30);
    }

    const N: usize = 4;

    /// One drain step as `tracing::drain_one` takes it: the oldest complete record, or `None`.
    fn ring() -> Ring<u32, N> {
        // SAFETY: each test runs on one thread, its steps one at a time.
        unsafe { Ring::new(0) }
    }

    fn drain(ring: &Ring<u32, N>) -> Option<u32> {
        let mut out = 0;
        // SAFETY: each test is the ring's only drain.
        unsafe { ring.take(&mut out) }.then_some(out)
    }

    /// A writer's whole record: its reservation (the critical section) and its fill.
    fn push(ring: &Ring<u32, N>, value: u32) -> bool {
        // SAFETY: the tests run one step at a time, as a critical section makes them.
        match unsafe { ring.reserve() } {
            Some(claim) => claim.fill(|s| *s = value),
            None => return false,
        }
        true
    }

    // SAFETY (each `reserve`, `take_lost`, `count_lost` below): one step at a time, one drain.

    #[test]
    fn records_leave_in_the_order_they_were_reserved() {
        let ring = ring();
        for v in 1..=3 {
            assert!(push(&ring, v));
        }
        assert_eq!(drain(&ring), Some(1));
        assert_eq!(drain(&ring), Some(2));
        assert_eq!(drain(&ring), Some(3));
        assert_eq!(drain(&ring), None);
    }

    #[test]
    fn a_writer_preempted_mid_copy_keeps_its_slot_and_the_drain_waits_for_it() {
        let ring = ring();
        // Writer A reserves (under its critical section) and is preempted before its copy.
        let a = unsafe { ring.reserve() }.expect("room");
        // Writer B, at a higher priority, reserves the next slot and completes its record.
        assert!(push(&ring, 20));
        // The drain finds A's slot incomplete: it takes nothing, and not B's record ahead of it.
        assert_eq!(drain(&ring), None);
        // A resumes and finishes its copy, which B's record did not overwrite.
        a.fill(|s| *s = 10);
        assert_eq!(drain(&ring), Some(10));
        assert_eq!(drain(&ring), Some(20));
        assert_eq!(drain(&ring), None);
    }

    #[test]
    fn a_half_written_record_is_never_read_and_a_writer_preempting_the_copy_goes_next() {
        let ring = ring();
        let a = unsafe { ring.reserve() }.expect("room");
        // A writes half its record and is preempted by writer B, then the drain runs.
        a.fill(|s| {
            *s = 0xAAAA_0000;
            assert!(push(&ring, 7));
            assert_eq!(drain(&ring), None);
            *s |= 0x5555;
        });
        assert_eq!(drain(&ring), Some(0xAAAA_5555));
        assert_eq!(drain(&ring), Some(7));
    }

    #[test]
    fn a_full_ring_counts_what_it_turns_away_and_incomplete_slots_count_as_full() {
        let ring = ring();
        // Three complete records and one reserved by a writer that was preempted.
        for v in 1..=3 {
            assert!(push(&ring, v));
        }
        let late = unsafe { ring.reserve() }.expect("the fourth slot");
        // Two preempting writers find every slot reserved: both counted, nothing overwritten.
        assert!(!push(&ring, 98));
        assert!(!push(&ring, 99));
        assert_eq!(unsafe { ring.take_lost() }, 2);
        assert_eq!(unsafe { ring.take_lost() }, 0);
        assert_eq!(drain(&ring), Some(1));
        // The slot just freed is the next writer's (the ring wraps), behind the late one.
        assert!(push(&ring, 5));
        assert_eq!(drain(&ring), Some(2));
        assert_eq!(drain(&ring), Some(3));
        assert_eq!(drain(&ring), None);
        late.fill(|s| *s = 4);
        assert_eq!(drain(&ring), Some(4));
        assert_eq!(drain(&ring), Some(5));
        assert_eq!(drain(&ring), None);
        // Records the channel had no room for are reported again, with any lost since.
        unsafe { ring.count_lost(3) };
        assert!(push(&ring, 6));
        assert_eq!(unsafe { ring.take_lost() }, 3);
        assert_eq!(unsafe { ring.take_lost() }, 0);
    }

    #[test]
    fn a_writer_while_the_drain_copies_out_gets_another_slot() {
        let ring = ring();
        for v in 1..=4 {
            assert!(push(&ring, v));
        }
        // The ring is full: a writer preempting the drain before it moves `released` is turned
        // away (the slot being read is still counted), not given the slot being read.
        assert!(!push(&ring, 9));
        assert_eq!(drain(&ring), Some(1));
        assert!(push(&ring, 5));
        assert_eq!(unsafe { ring.take_lost() }, 1);
        for want in 2..=5 {
            assert_eq!(drain(&ring), Some(want));
        }
        assert_eq!(drain(&ring), None);
    }

    #[test]
    fn the_counters_wrap_and_the_ring_stays_in_order() {
        let ring = ring();
        // Both counters a few steps below their wrap.
        ring.reserved.store(usize::MAX - 5, Ordering::Relaxed);
        ring.released.store(usize::MAX - 5, Ordering::Relaxed);
        ring.lost.store(u32::MAX, Ordering::Relaxed);
        ring.reported.store(u32::MAX, Ordering::Relaxed);
        let mut next_out = 0;
        for v in 0..(10 * N as u32) {
            assert!(push(&ring, v));
            if v % 3 == 2 {
                while let Some(got) = drain(&ring) {
                    assert_eq!(got, next_out);
                    next_out += 1;
                }
            }
        }
        while let Some(got) = drain(&ring) {
            assert_eq!(got, next_out);
            next_out += 1;
        }
        assert_eq!(next_out, 10 * N as u32);
        for _ in 0..(N + 2) {
            push(&ring, 0);
        }
        assert_eq!(unsafe { ring.take_lost() }, 2);
    }
}
