//! The command queues: the frames the CAN receive interrupt takes off the bus, on their way to the
//! command handler, and the commands the handler passes on to the admission task. A bounded
//! lock-free ring for one producer (the receive interrupt; the handler) and one consumer (the
//! command handler's task; the admission task, below it), and the consumer's wake.
//!
//! Why not `rtic-sync`'s channel: its `try_send` was 443 cycles of every received frame on the
//! F103 (the execution-time bound: a check of its senders' wait queue, a critical section for the
//! closed flag, one for the free list's pop, one for the ready queue's push, and the receiver's
//! waker woken under a fourth), more than the whole stated budget of the receive interrupt. Here a
//! frame is three word stores and an index store, and the interrupt wakes the handler once per job,
//! after its drain ([`Producer::wake`]), not once per frame. The same holds for the handler's
//! queue to the admission task: its `try_send` was 1 224 cycles of the handler's longest job on
//! DiWheelDrive (`tasks::route_to_admission`).
//!
//! The indices are two free-running counters: `written`, stored only by the producer, and `read`,
//! stored only by the consumer. Each is one word, loaded and stored whole on the core (relaxed
//! atomics), so neither side needs a critical section for the ring. One core only
//! ([`FrameQueue::new`]'s contract): the two sides interleave only where an interrupt preempts,
//! so compiler fences order a slot's copy against the index that publishes or frees it.
//!
//! Why that is correct:
//! * **The producer writes only free slots.** It writes slot `written mod N` only while
//!   `written − read < N`, that is while the consumer has freed it, and publishes it by moving
//!   `written` past it after the copy (a release fence before the store).
//! * **The consumer reads only published slots.** It reads slot `read mod N` only while
//!   `read ≠ written` (an acquire fence after the load), and frees it by moving `read` past it
//!   after its copy (a release fence before the store). A producer that preempts the consumer
//!   between its copy and that store sees the ring one frame fuller than it is: at worst a frame
//!   turned away (and counted by the caller) while one was being taken, never a slot overwritten
//!   while it is read.
//! * **A full ring turns the frame away** ([`Producer::push`] returns `false`): the receive
//!   interrupt counts it (`health::count_rx_dropped`), nothing is overwritten, nothing waits.
//! * **No frame waits unseen.** The consumer parks in three steps: it finds the ring empty,
//!   stores its waker (in a section the producer cannot enter: interrupts off on the chips), and
//!   looks again. The producer pushes, then takes the stored waker (in such a section) and wakes
//!   it. A push before the consumer stored its waker is found by its second look; a push after it
//!   finds the waker. A waker is taken once: the consumer stores it again each time it parks.
//!
//! * **One frame set aside.** Beside the ring the queue holds one frame the producer sets aside
//!   while the ring is full ([`Producer::set_aside`]: the command handler's request that the
//!   admission task answers with a busy verdict), a ring of one with a flag for its index: written
//!   only while the flag is clear, published by setting it after the copy; read only while it is
//!   set, freed by clearing it after the copy. The same wake reaches the consumer, which looks
//!   for it before each of its waits and again after storing its waker
//!   ([`Consumer::watch`]).
//!
//! The host tests below run these steps in the orders an interrupt can put them in.
use core::cell::UnsafeCell;
use core::future::Future;
use core::pin::Pin;
use core::sync::atomic::{compiler_fence, AtomicBool, AtomicU32, Ordering};
use core::task::{Context, Poll, Waker};

use crate::can::RxFrame;

/// One received frame as the ring holds it: three words (the identifier and the length, then the
/// payload's two halves), so a slot is written and read by whole words, never a byte copy.
type Slot = [u32; 3];

/// A frame as three words.
fn pack(frame: &RxFrame) -> Slot {
    let [d0, d1, d2, d3, d4, d5, d6, d7] = frame.data;
    [
        u32::from(frame.id) | u32::from(frame.len) << 16,
        u32::from_le_bytes([d0, d1, d2, d3]),
        u32::from_le_bytes([d4, d5, d6, d7]),
    ]
}

/// The frame three words hold.
fn unpack([head, low, high]: Slot) -> RxFrame {
    let [d0, d1, d2, d3] = low.to_le_bytes();
    let [d4, d5, d6, d7] = high.to_le_bytes();
    RxFrame {
        id: head as u16,
        len: (head >> 16) as u8,
        data: [d0, d1, d2, d3, d4, d5, d6, d7],
    }
}

/// A ring of `N` received frames (a power of two) and its consumer's waker.
pub struct FrameQueue<const N: usize> {
    /// Frames written, ever (wrapping): stored by the producer only.
    written: AtomicU32,
    /// Frames read, ever (wrapping): stored by the consumer only.
    read: AtomicU32,
    slots: UnsafeCell<[Slot; N]>,
    /// Whether `aside` holds a frame: set by the producer only, cleared by the consumer only.
    aside_full: AtomicBool,
    /// The frame set aside ([`Producer::set_aside`]).
    aside: UnsafeCell<Slot>,
    /// The parked consumer's waker: stored and taken only with the other side kept out
    /// ([`exclusive`]).
    waker: UnsafeCell<Option<Waker>>,
}

// SAFETY: a slot is written only by the one producer while it is free and read only by the one
// consumer while it is published, never both at once (the module's argument, on the one core
// `FrameQueue::new` requires); the waker is touched only in `exclusive` sections; the rest is
// atomics.
unsafe impl<const N: usize> Sync for FrameQueue<N> {}

/// Runs `f` with the other side of the queue kept out: interrupts off on the chips. On the host,
/// where the tests run one step at a time on one thread, `f` alone.
fn exclusive<R>(f: impl FnOnce() -> R) -> R {
    #[cfg(target_os = "none")]
    return critical_section::with(|_| f());
    #[cfg(not(target_os = "none"))]
    f()
}

impl<const N: usize> FrameQueue<N> {
    /// An empty queue of `N` frames.
    ///
    /// # Safety
    /// The queue is used on one core only: its producer and its consumer run on the same core
    /// (interrupt handlers and tasks), never in parallel — its orderings are compiler fences.
    pub const unsafe fn new() -> Self {
        // A power of two up to 2³¹ divides 2³²: the wrapping indices stay in step with the slots.
        assert!(N.is_power_of_two() && N <= 1 << 31);
        Self {
            written: AtomicU32::new(0),
            read: AtomicU32::new(0),
            slots: UnsafeCell::new([[0; 3]; N]),
            aside_full: AtomicBool::new(false),
            aside: UnsafeCell::new([0; 3]),
            waker: UnsafeCell::new(None),
        }
    }

    /// The queue's two ends.
    ///
    /// # Safety
    /// Called once per queue: the ring has one producer and one consumer (the module's argument).
    pub unsafe fn split(&self) -> (Producer<'_, N>, Consumer<'_, N>) {
        (Producer { queue: self }, Consumer { queue: self })
    }

    /// Slot `at` (masked below `N`), without a reference to the whole array.
    fn slot(&self, at: u32) -> *mut Slot {
        self.slots
            .get()
            .cast::<Slot>()
            .wrapping_add(at as usize & (N - 1))
    }
}

/// The receive interrupt's end of a [`FrameQueue`].
pub struct Producer<'q, const N: usize> {
    queue: &'q FrameQueue<N>,
}

impl<const N: usize> Producer<'_, N> {
    /// Queues `frame`; `false` (the frame turned away, for the caller to count) when the ring is
    /// full. Does not wake the consumer: [`Producer::wake`] does, once per drain.
    #[inline(always)]
    pub fn push(&mut self, frame: &RxFrame) -> bool {
        let q = self.queue;
        let written = q.written.load(Ordering::Relaxed);
        let read = q.read.load(Ordering::Relaxed);
        // The consumer's copy of the slot `read` frees came before its store (one core).
        compiler_fence(Ordering::Acquire);
        if written.wrapping_sub(read) >= N as u32 {
            return false;
        }
        // SAFETY: free (`written − read < N`): the consumer reads no slot at or past `written`;
        // `slot` masks the index below `N`.
        unsafe { *q.slot(written) = pack(frame) };
        compiler_fence(Ordering::Release);
        q.written.store(written.wrapping_add(1), Ordering::Relaxed);
        true
    }

    /// Sets `frame` aside beside the ring (one frame: the module's *One frame set aside*); `false`
    /// when one is still there, not yet taken. Does not wake the consumer: [`Producer::wake`] does.
    #[inline(always)]
    pub fn set_aside(&mut self, frame: &RxFrame) -> bool {
        let q = self.queue;
        if q.aside_full.load(Ordering::Relaxed) {
            return false;
        }
        // The consumer's copy of the frame it took came before its clear (one core).
        compiler_fence(Ordering::Acquire);
        // SAFETY: clear: the consumer does not read `aside` until the flag is set again below.
        unsafe { *q.aside.get() = pack(frame) };
        compiler_fence(Ordering::Release);
        q.aside_full.store(true, Ordering::Relaxed);
        true
    }

    /// Wakes the consumer if it is parked (its waker is taken: it stores it again when it parks
    /// next). Called after the frames are pushed.
    #[inline(always)]
    pub fn wake(&mut self) {
        let q = self.queue;
        // SAFETY: the waker is touched only in `exclusive` sections.
        if let Some(waker) = exclusive(|| unsafe { (*q.waker.get()).take() }) {
            waker.wake();
        }
    }
}

/// A received frame as the ring holds it (three words): a poll result that carries it is copied
/// by words, where an [`RxFrame`] at the result's half-word offset was copied by a `memcpy` call.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Packed(Slot);

impl Packed {
    /// The frame.
    pub fn unpack(self) -> RxFrame {
        unpack(self.0)
    }
}

/// The command handler's end of a [`FrameQueue`].
pub struct Consumer<'q, const N: usize> {
    queue: &'q FrameQueue<N>,
}

impl<'q, const N: usize> Consumer<'q, N> {
    /// The oldest queued frame, if any.
    pub fn try_recv(&mut self) -> Option<RxFrame> {
        self.take().map(unpack)
    }

    /// The oldest queued frame as the ring holds it, if any.
    fn take(&mut self) -> Option<Slot> {
        let q = self.queue;
        let read = q.read.load(Ordering::Relaxed);
        if q.written.load(Ordering::Relaxed) == read {
            return None;
        }
        // The producer's copy came before its store of `written` (one core).
        compiler_fence(Ordering::Acquire);
        // SAFETY: published (`read ≠ written`) and not freed until `read` moves past it: the
        // producer does not write it meanwhile; `slot` masks the index below `N`.
        let slot = unsafe { *q.slot(read) };
        compiler_fence(Ordering::Release);
        q.read.store(read.wrapping_add(1), Ordering::Relaxed);
        Some(slot)
    }

    /// The frame the producer set aside ([`Producer::set_aside`]), if any, taken.
    pub fn take_aside(&mut self) -> Option<RxFrame> {
        self.take_aside_after(|| ())
    }

    /// [`Consumer::take_aside`], with `first` run when there is a frame, before it is taken (while
    /// the producer still finds the frame there: the busy verdicts' window, `admission::BusyWindow`).
    #[inline(always)]
    pub fn take_aside_after(&mut self, first: impl FnOnce()) -> Option<RxFrame> {
        let q = self.queue;
        if !q.aside_full.load(Ordering::Relaxed) {
            return None;
        }
        first();
        // The producer's copy came before its store of the flag (one core); `first`'s stores come
        // before the clear.
        compiler_fence(Ordering::SeqCst);
        // SAFETY: set: the producer does not write `aside` until the flag is cleared below.
        let slot = unsafe { *q.aside.get() };
        compiler_fence(Ordering::Release);
        q.aside_full.store(false, Ordering::Relaxed);
        Some(unpack(slot))
    }

    /// Stores `waker` for the producer's next [`Producer::wake`], for a consumer that waits for
    /// something else as well (the admission task's pacing, which must still hear of a frame set
    /// aside): look for the frame set aside again after this, as [`Consumer::poll_recv`] looks at
    /// the ring again after its park.
    pub fn watch(&mut self, waker: &Waker) {
        self.park(waker);
    }

    /// Stores `waker` for the producer's next [`Producer::wake`] (kept if it already wakes the
    /// same task).
    fn park(&mut self, waker: &Waker) {
        let q = self.queue;
        // SAFETY: the waker is touched only in `exclusive` sections.
        exclusive(|| {
            let slot = unsafe { &mut *q.waker.get() };
            if !slot.as_ref().is_some_and(|w| w.will_wake(waker)) {
                *slot = Some(waker.clone());
            }
        });
    }

    /// The oldest queued frame, or `Pending` with the task's waker stored: the producer's next
    /// push wakes it.
    pub fn poll_recv(&mut self, cx: &mut Context<'_>) -> Poll<RxFrame> {
        self.poll_recv_packed(cx).map(Packed::unpack)
    }

    /// [`Consumer::poll_recv`] with the frame as the ring holds it, for a poll that passes it on
    /// before it is looked into (the command handler's job, `tasks::serve_commands`).
    pub fn poll_recv_packed(&mut self, cx: &mut Context<'_>) -> Poll<Packed> {
        if let Some(slot) = self.take() {
            return Poll::Ready(Packed(slot));
        }
        self.park(cx.waker());
        // A frame pushed between the first look and the waker's store found no waker to wake.
        match self.take() {
            Some(slot) => Poll::Ready(Packed(slot)),
            None => Poll::Pending,
        }
    }

    /// Waits for the next frame.
    pub fn recv(&mut self) -> Recv<'_, 'q, N> {
        Recv { consumer: self }
    }
}

/// The future [`Consumer::recv`] returns.
pub struct Recv<'c, 'q, const N: usize> {
    consumer: &'c mut Consumer<'q, N>,
}

impl<const N: usize> Future for Recv<'_, '_, N> {
    type Output = RxFrame;

    fn poll(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<RxFrame> {
        self.consumer.poll_recv(cx)
    }
}

/// A [`FrameQueue`] of `N` frames in a static of its own, split into its two ends (for a board's
/// `init`, which runs once: each expansion is one queue, split once).
#[macro_export]
macro_rules! frame_queue {
    ($n:expr) => {{
        // SAFETY: the chips are single-core.
        static QUEUE: $crate::rx_queue::FrameQueue<{ $n }> =
            unsafe { $crate::rx_queue::FrameQueue::new() };
        // SAFETY: this expansion's queue, split here only, and `init` runs once.
        unsafe { QUEUE.split() }
    }};
}

#[cfg(test)]
mod tests {
    use super::*;

    const N: usize = 4;

    /// A waker that counts its wakes.
    use crate::test_waker::{counting as counter, Wakes as Counter};

    fn wakes(counter: &Counter) -> usize {
        counter.count()
    }

    fn queue() -> &'static FrameQueue<N> {
        // SAFETY: each test runs on one thread, its steps one at a time.
        Box::leak(Box::new(unsafe { FrameQueue::new() }))
    }

    fn frame(id: u16) -> RxFrame {
        RxFrame {
            id,
            len: (id % 9) as u8,
            data: [id as u8, 1, 2, 3, 4, 5, 6, (id >> 8) as u8],
        }
    }

    #[test]
    fn a_frame_comes_out_as_it_went_in_every_field_kept() {
        let odd = RxFrame {
            id: u16::MAX,
            len: 0,
            data: [0xff; 8],
        };
        for f in [frame(0), frame(0x7ff), frame(0x123), odd] {
            assert_eq!(unpack(pack(&f)), f);
        }
    }

    #[test]
    fn frames_leave_in_the_order_they_came_and_a_full_ring_turns_the_next_away() {
        // SAFETY: this test's only split.
        let (mut tx, mut rx) = unsafe { queue().split() };
        for id in 1..=N as u16 {
            assert!(tx.push(&frame(id)));
        }
        assert!(!tx.push(&frame(99)), "full: turned away");
        for id in 1..=N as u16 {
            assert_eq!(rx.try_recv(), Some(frame(id)));
        }
        assert_eq!(rx.try_recv(), None);
    }

    #[test]
    fn the_indices_wrap_past_u32_max_without_losing_or_repeating_a_frame() {
        let q = queue();
        q.written.store(u32::MAX - 1, Ordering::Relaxed);
        q.read.store(u32::MAX - 1, Ordering::Relaxed);
        // SAFETY: this test's only split.
        let (mut tx, mut rx) = unsafe { q.split() };
        for round in 0..3u16 {
            for id in 0..N as u16 {
                assert!(tx.push(&frame(round * 10 + id)));
            }
            assert!(!tx.push(&frame(99)));
            for id in 0..N as u16 {
                assert_eq!(rx.try_recv(), Some(frame(round * 10 + id)));
            }
            assert_eq!(rx.try_recv(), None);
        }
    }

    #[test]
    fn against_a_model_every_frame_is_delivered_once_or_turned_away() {
        // SAFETY: this test's only split.
        let (mut tx, mut rx) = unsafe { queue().split() };
        let mut model = std::collections::VecDeque::new();
        // A fixed pseudo-random walk of pushes and pops (xorshift), long enough to wrap often.
        let mut x = 0x2545_f491_u32;
        for step in 0..10_000u32 {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            if !x.is_multiple_of(3) {
                let f = frame(step as u16);
                let queued = tx.push(&f);
                assert_eq!(queued, model.len() < N, "step {step}");
                if queued {
                    model.push_back(f);
                }
            } else {
                assert_eq!(rx.try_recv(), model.pop_front(), "step {step}");
            }
        }
    }

    #[test]
    fn a_consumer_preempted_mid_take_makes_the_producer_see_the_ring_fuller_never_overwrite() {
        let q = queue();
        // SAFETY: this test's only split.
        let (mut tx, mut rx) = unsafe { q.split() };
        for id in 0..N as u16 {
            assert!(tx.push(&frame(id)));
        }
        // The consumer's take up to its copy (try_recv's first half), then the producer preempts.
        let read = q.read.load(Ordering::Relaxed);
        let copy = unsafe { *q.slot(read) };
        assert!(!tx.push(&frame(50)), "the slot being read is not free yet");
        assert_eq!(
            unsafe { *q.slot(read) },
            copy,
            "the slot was not overwritten"
        );
        q.read.store(read.wrapping_add(1), Ordering::Relaxed);
        assert_eq!(unpack(copy), frame(0));
        // Freed now: the next push goes into it, after the other three.
        assert!(tx.push(&frame(51)));
        for id in [1, 2, 3, 51] {
            assert_eq!(rx.try_recv(), Some(frame(id)));
        }
    }

    #[test]
    fn a_frame_set_aside_waits_beside_a_full_ring_once_and_is_taken_once() {
        // SAFETY: this test's only split.
        let (mut tx, mut rx) = unsafe { queue().split() };
        for id in 0..N as u16 {
            assert!(tx.push(&frame(id)));
        }
        assert!(!tx.push(&frame(40)), "the ring is full");
        assert!(tx.set_aside(&frame(41)));
        assert!(
            !tx.set_aside(&frame(42)),
            "one frame aside: the next is turned away"
        );
        // The ring's frames are not disturbed by it, nor it by them.
        assert_eq!(rx.try_recv(), Some(frame(0)));
        assert_eq!(rx.take_aside(), Some(frame(41)));
        assert_eq!(rx.take_aside(), None, "taken once");
        assert!(tx.set_aside(&frame(43)), "free again once taken");
        for id in 1..N as u16 {
            assert_eq!(rx.try_recv(), Some(frame(id)));
        }
        assert_eq!(rx.try_recv(), None);
        assert_eq!(rx.take_aside(), Some(frame(43)));
    }

    #[test]
    fn a_frame_set_aside_reaches_a_consumer_that_watches_or_is_found_by_its_second_look() {
        let (count, waker) = counter();
        // SAFETY: this test's only split.
        let (mut tx, mut rx) = unsafe { queue().split() };
        // Set aside after the consumer's watch: the wake reaches it.
        assert_eq!(rx.take_aside(), None);
        rx.watch(&waker);
        assert!(tx.set_aside(&frame(5)));
        tx.wake();
        assert_eq!(wakes(&count), 1);
        assert_eq!(rx.take_aside(), Some(frame(5)));
        // Set aside between the first look and the watch: no waker to wake, the second look finds it.
        assert_eq!(rx.take_aside(), None);
        assert!(tx.set_aside(&frame(6)));
        tx.wake();
        assert_eq!(wakes(&count), 1);
        rx.watch(&waker);
        assert_eq!(rx.take_aside(), Some(frame(6)));
    }

    #[test]
    fn a_consumer_preempted_mid_take_aside_makes_the_producer_wait_never_overwrite() {
        let q = queue();
        // SAFETY: this test's only split.
        let (mut tx, mut rx) = unsafe { q.split() };
        assert!(tx.set_aside(&frame(8)));
        // The consumer's take up to its copy, then the producer preempts.
        let copy = unsafe { *q.aside.get() };
        assert!(!tx.set_aside(&frame(9)), "not freed yet");
        assert_eq!(unsafe { *q.aside.get() }, copy, "not overwritten");
        q.aside_full.store(false, Ordering::Relaxed);
        assert_eq!(unpack(copy), frame(8));
        assert!(tx.set_aside(&frame(9)));
        assert_eq!(rx.take_aside(), Some(frame(9)));
    }

    #[test]
    fn a_parked_consumer_is_woken_by_the_next_push_and_only_once() {
        let (count, waker) = counter();
        let mut cx = Context::from_waker(&waker);
        // SAFETY: this test's only split.
        let (mut tx, mut rx) = unsafe { queue().split() };
        assert_eq!(rx.poll_recv(&mut cx), Poll::Pending);
        tx.wake();
        assert_eq!(
            wakes(&count),
            1,
            "a wake with nothing pushed is spurious but harmless"
        );
        assert_eq!(rx.poll_recv(&mut cx), Poll::Pending);
        assert!(tx.push(&frame(7)));
        tx.wake();
        assert_eq!(wakes(&count), 2);
        tx.wake();
        assert_eq!(wakes(&count), 2, "the waker was taken: no second wake");
        assert_eq!(rx.poll_recv(&mut cx), Poll::Ready(frame(7)));
    }

    #[test]
    fn a_packed_frame_unpacks_to_the_frame_pushed_and_parks_as_the_plain_poll_does() {
        let (count, waker) = counter();
        let mut cx = Context::from_waker(&waker);
        // SAFETY: this test's only split.
        let (mut tx, mut rx) = unsafe { queue().split() };
        assert_eq!(rx.poll_recv_packed(&mut cx), Poll::Pending);
        assert!(tx.push(&frame(0x7ff)));
        tx.wake();
        assert_eq!(wakes(&count), 1, "parked: the push wakes it");
        let Poll::Ready(packed) = rx.poll_recv_packed(&mut cx) else {
            panic!("the pushed frame is there");
        };
        assert_eq!(packed.unpack(), frame(0x7ff));
        assert_eq!(rx.try_recv(), None, "taken once");
    }

    #[test]
    fn a_push_between_the_first_look_and_the_park_is_found_by_the_second_look() {
        let (count, waker) = counter();
        // SAFETY: this test's only split.
        let (mut tx, mut rx) = unsafe { queue().split() };
        // poll_recv step by step: the first look finds nothing …
        assert_eq!(rx.try_recv(), None);
        // … the interrupt pushes and finds no waker to wake …
        assert!(tx.push(&frame(3)));
        tx.wake();
        assert_eq!(wakes(&count), 0);
        // … the consumer parks and looks again: the frame is there, the task does not sleep.
        rx.park(&waker);
        assert_eq!(rx.try_recv(), Some(frame(3)));
    }

    #[test]
    fn a_push_after_the_park_wakes_the_consumer_before_its_second_look() {
        let (count, waker) = counter();
        // SAFETY: this test's only split.
        let (mut tx, mut rx) = unsafe { queue().split() };
        assert_eq!(rx.try_recv(), None);
        rx.park(&waker);
        // The interrupt comes between the park and the second look.
        assert!(tx.push(&frame(4)));
        tx.wake();
        assert_eq!(wakes(&count), 1);
        // The second look takes it; the wake makes one more poll, which finds the ring empty and
        // parks again.
        assert_eq!(rx.try_recv(), Some(frame(4)));
        let mut cx = Context::from_waker(&waker);
        assert_eq!(rx.poll_recv(&mut cx), Poll::Pending);
        assert!(tx.push(&frame(5)));
        tx.wake();
        assert_eq!(wakes(&count), 2);
        assert_eq!(rx.poll_recv(&mut cx), Poll::Ready(frame(5)));
    }

    #[test]
    fn parking_again_with_another_task_s_waker_replaces_the_stored_one() {
        let (first, first_waker) = counter();
        let (second, second_waker) = counter();
        // SAFETY: this test's only split.
        let (mut tx, mut rx) = unsafe { queue().split() };
        rx.park(&first_waker);
        rx.park(&second_waker);
        assert!(tx.push(&frame(1)));
        tx.wake();
        assert_eq!((wakes(&first), wakes(&second)), (0, 1));
    }
}
