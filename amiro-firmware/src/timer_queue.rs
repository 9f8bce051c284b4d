//! The timer queue behind every board's monotonic (and the QEMU build's stand-in): the waits of the
//! async tasks in a fixed array of slots, one per wait, kept in the order of their instants as a
//! list of slot indices, so that the timer's interrupt serves an expiry with one look at the
//! list's head and no critical section.
//!
//! Why not rtic-time's `TimerQueue`: each pass of its interrupt loop takes a critical section,
//! reads the 64-bit time under another, clones the waiter's waker and pops a linked list whose
//! links live in the waiting futures; a pass that finds the head not yet due sets the compare and
//! reads the time again, and may go round once more. The analysis charged every expiry three such
//! passes (docs/analysis.md, "The monotonic"), which the task sets had no room for. Here:
//!
//! - A task's [`Delay`] claims a free slot on its first pending poll, writes the slot's instant and
//!   its waker and links the slot into the list at its place (after the slots of equal instants),
//!   all in one critical section (a walk of at most the waits ahead of it, as rtic-time's insert
//!   walks under its own), and pends the timer's interrupt only if the slot became the head.
//! - The interrupt ([`TimerQueue::on_interrupt`], at the highest priority, so nothing that touches
//!   the queue runs while it does) reads the time once, pops and wakes the due heads (one pass
//!   each), sets the compare for the first head not due (or turns it off), and pends itself if the
//!   time passed that compare while it set it (rtic-time's `continue`): that expiry's own
//!   interrupt then wakes it.
//! - A slot holds the low 32 bits of its instant (compared wrapping: exact while every armed slot
//!   is less than 2^31 ticks from the time, as each is armed at most [`STEP`] ahead and the
//!   interrupt runs at least every 32.8 ms, on the timers' own period events); a wait further away
//!   is armed [`STEP`] ahead and arms again when woken.
//! - Dropping a [`Delay`] (a timeout whose future finished first) unlinks and frees its slot (each
//!   listed slot keeps its predecessor as well as its successor: no walk to it); a
//!   forgotten one only keeps its slot. A slot is no pointer into a future: nothing dangles.
//!
//! The queue holds [`CAPACITY`] waits; a board's async tasks wait one at a time each, so a full
//! queue means more tasks than slots: a [`Delay`] that finds no slot asks its task to be polled
//! again (it waits busy, it does not end early). The backend ([`Backend`]) is the chip's timer (`timer_monotonic`) or the QEMU build's
//! SysTick (`qemu::timer`).
use core::cell::UnsafeCell;
use core::future::Future;
use core::marker::PhantomData;
use core::pin::Pin;
use core::task::{Context, Poll, Waker};

/// Waits the queue holds at once (one bit each in the masks): the boards' async tasks that wait on
/// the clock are 6 to 9, and a slot costs 13 bytes of RAM (QEMU's LightRing image has little).
pub const CAPACITY: usize = 16;

/// Every slot's bit.
const ALL: u32 = u32::MAX >> (32 - CAPACITY);

/// Furthest ahead a slot is armed, in ticks: a wait further away is armed this far ahead and arms
/// again when woken (the slots' 32-bit instants compare exactly within 2^31 ticks).
pub const STEP: u64 = 1 << 30;

/// The timer under a [`TimerQueue`]: its time in ticks, its compare, its interrupt.
pub trait Backend: Sized + 'static {
    /// Time in ticks, from any context.
    fn now() -> u64;
    /// Time in ticks, read in the timer's interrupt (where it may be cheaper: nothing that changes
    /// the time's upper part pre-empts it).
    fn now_in_interrupt() -> u64 {
        Self::now()
    }
    /// Sets the compare for tick `at` (its interrupt on), the time being `now`; called only in the
    /// timer's interrupt. `true` if the time had reached `at` when the compare was set (its match
    /// may be gone by: the interrupt pends itself).
    fn set_compare(at: u64, now: u64) -> bool;
    /// Turns the compare's interrupt off (nothing waits); called only in the timer's interrupt.
    fn disable_compare();
    /// Pends the timer's interrupt.
    fn pend_interrupt();
    /// The queue this backend drives.
    fn queue() -> &'static TimerQueue<Self>;
    /// A fault of the timer to log once (a task calls it: `mono::Clock::take_fault_report`).
    fn take_fault_report() -> Option<&'static str> {
        None
    }
}

/// No compare set: nothing waits (no compare is ever set for tick 0: an armed instant is after the
/// time it was armed at). Zero, so that the queue's initial state is all zeros (in `.bss`, not a
/// flash image of `.data`).
const NONE: u64 = 0;

struct State {
    /// Slots a [`Delay`] owns.
    claimed: u32,
    /// Slots in the list (claimed, instant and waker written).
    armed: u32,
    /// The list's first slot plus one (0: empty).
    head: u8,
    /// Each listed slot's successor plus one (0: the last).
    link: [u8; CAPACITY],
    /// Each listed slot's predecessor plus one, but the head's (left as it was when the interrupt
    /// popped the slot before it), so that a slot leaves the list without a walk to it.
    prev: [u8; CAPACITY],
    /// Low 32 bits of each listed slot's instant.
    at: [u32; CAPACITY],
    /// Each listed slot's waker (taken when the interrupt wakes it).
    waker: [Option<Waker>; CAPACITY],
    /// The instant the compare is set for ([`NONE`]: off).
    compare: u64,
}

impl State {
    const EMPTY: State = State {
        claimed: 0,
        armed: 0,
        head: 0,
        link: [0; CAPACITY],
        prev: [0; CAPACITY],
        at: [0; CAPACITY],
        waker: [const { None }; CAPACITY],
        compare: NONE,
    };

    /// Takes slot `i` out of the list (it is in it): its neighbours' links, no walk.
    fn unlink(&mut self, i: usize) {
        let me = i as u8 + 1;
        let after = self.link[i];
        // The head's predecessor link is not kept (the interrupt pops heads without a store for it),
        // so the head is told by `head`; any other listed slot's `prev` names its predecessor.
        let before = if self.head == me {
            self.head = after;
            0
        } else {
            let before = self.prev[i];
            self.link[usize::from(before.wrapping_sub(1)) % CAPACITY] = after;
            before
        };
        if after != 0 {
            self.prev[usize::from(after - 1) % CAPACITY] = before;
        }
        self.armed &= !(1 << i);
    }

    /// Puts slot `i` (not in the list) into it at instant `at`, after every slot whose instant is
    /// not later. One pass per slot ahead of it; `true` if it became the head.
    fn link_in(&mut self, i: usize, at: u32) -> bool {
        self.at[i] = at;
        let mut before = 0u8;
        let mut cur = self.head;
        while cur != 0 {
            let c = usize::from(cur - 1) % CAPACITY;
            if (at.wrapping_sub(self.at[c]) as i32) < 0 {
                break;
            }
            before = cur;
            cur = self.link[c];
        }
        self.link[i] = cur;
        self.prev[i] = before;
        let me = i as u8 + 1;
        if cur != 0 {
            self.prev[usize::from(cur - 1) % CAPACITY] = me;
        }
        if before == 0 {
            self.head = me;
        } else {
            self.link[usize::from(before - 1) % CAPACITY] = me;
        }
        self.armed |= 1 << i;
        before == 0
    }
}

/// A fixed-capacity timer queue over the backend `B` (module docs).
pub struct TimerQueue<B> {
    state: UnsafeCell<State>,
    _backend: PhantomData<fn() -> B>,
}

// SAFETY: the state is touched by tasks only inside a critical section, and by the timer's
// interrupt (`on_interrupt`), which no code that touches the queue pre-empts.
unsafe impl<B> Sync for TimerQueue<B> {}

impl<B> Default for TimerQueue<B> {
    fn default() -> Self {
        Self::new()
    }
}

impl<B> TimerQueue<B> {
    /// An empty queue.
    pub const fn new() -> Self {
        Self {
            state: UnsafeCell::new(State::EMPTY),
            _backend: PhantomData,
        }
    }

    /// Runs `f` on the state inside a critical section.
    fn with<R>(&self, f: impl FnOnce(&mut State) -> R) -> R {
        // SAFETY: inside the critical section neither a task nor the timer's interrupt can reach
        // the state but through this borrow.
        critical_section::with(|_| f(unsafe { &mut *self.state.get() }))
    }

    /// Waits in the list.
    pub fn waiting(&self) -> u32 {
        self.with(|s| s.armed.count_ones())
    }
}

impl<B: Backend> TimerQueue<B> {
    /// The timer's interrupt: wakes every wait due by now (the list's due heads), sets the compare
    /// for the first one left (or turns it off), and pends itself if the time passed that compare
    /// while it was set.
    ///
    /// # Safety
    ///
    /// Only from the timer's interrupt, which nothing that touches this queue may pre-empt (the
    /// highest priority of the system's queue users; tasks touch it inside critical sections).
    pub unsafe fn on_interrupt(&self) {
        // SAFETY: the caller's: nothing else reaches the state while this runs.
        let s = unsafe { &mut *self.state.get() };
        let now = B::now_in_interrupt();
        loop {
            let head = s.head;
            if head == 0 {
                s.compare = NONE;
                B::disable_compare();
                return;
            }
            let i = usize::from(head - 1) % CAPACITY;
            let to_go = s.at[i].wrapping_sub(now as u32);
            if to_go as i32 > 0 {
                let at = now + u64::from(to_go);
                s.compare = at;
                if B::set_compare(at, now) {
                    B::pend_interrupt();
                }
                return;
            }
            s.head = s.link[i];
            s.armed &= !(1 << i);
            if let Some(waker) = s.waker[i].take() {
                waker.wake();
            }
        }
    }

    /// A future that completes at tick `at` or later.
    pub fn delay_until(&'static self, at: u64) -> Delay<B> {
        Delay {
            at,
            slot: NO_SLOT,
            _backend: PhantomData,
        }
    }

    /// A future that completes at tick `at` or later, once this queue's interrupt has taken its
    /// slot off the list ([`Expiry`]).
    pub fn expiry(&'static self, at: u64) -> Expiry<B> {
        Expiry(self.delay_until(at))
    }

    /// Runs `future` until it completes (`Some`) or tick `at` comes (`None`), whichever is first.
    pub fn timeout_at<F: Future>(&'static self, at: u64, future: F) -> Timeout<B, F> {
        Timeout {
            future,
            delay: self.delay_until(at),
        }
    }

    /// Arms `slot` (claiming a free one if [`NO_SLOT`]) for `arm_at` with `waker`, in one critical
    /// section (the waker cloned and the one left over dropped outside it, both calls through its
    /// vtable): a slot already listed keeps its instant (it stays listed until the interrupt wakes
    /// it or the wait ends) and takes the new waker. Pends the interrupt
    /// if the slot became the list's head. `Err` if every slot is claimed. Returns the waker left
    /// over, to be dropped outside the section.
    fn arm(&self, slot: &mut u8, arm_at: u64, waker: Waker) -> Result<Option<Waker>, Full> {
        let (spare, pend) = self.with(|s| {
            let i = if *slot != NO_SLOT {
                usize::from(*slot) % CAPACITY
            } else {
                let free = !s.claimed & ALL;
                if free == 0 {
                    return Err(Full(waker));
                }
                let i = free.trailing_zeros() as usize % CAPACITY;
                s.claimed |= 1 << i;
                *slot = i as u8;
                i
            };
            if s.armed & (1 << i) != 0 {
                return Ok((s.waker[i].replace(waker), false));
            }
            let old = s.waker[i].replace(waker);
            Ok((old, s.link_in(i, arm_at as u32)))
        })?;
        if pend {
            B::pend_interrupt();
        }
        Ok(spare)
    }

    /// An [`Expiry`]'s look at its armed `slot`, in one critical section: still listed, it keeps
    /// waiting (`Err`), with `waker` in place of the one it held unless that one wakes the same
    /// task; taken off the list by the interrupt, it is freed without a walk of the list (`Ok`).
    /// Either way the waker left over is returned, to be dropped outside the section.
    fn settle(&self, slot: u8, waker: &Waker) -> Result<Option<Waker>, Option<Waker>> {
        let i = usize::from(slot) % CAPACITY;
        self.with(|s| {
            if s.armed & (1 << i) == 0 {
                s.claimed &= !(1 << i);
                return Ok(s.waker[i].take());
            }
            if s.waker[i].as_ref().is_some_and(|w| w.will_wake(waker)) {
                return Err(None);
            }
            Err(s.waker[i].replace(waker.clone()))
        })
    }

    /// Frees `slot`: no longer armed nor claimed. Returns its waker, to be dropped outside the
    /// section.
    fn release(&self, slot: u8) -> Option<Waker> {
        let i = usize::from(slot) % CAPACITY;
        self.with(|s| {
            if s.armed & (1 << i) != 0 {
                s.unlink(i);
            }
            s.claimed &= !(1 << i);
            s.waker[i].take()
        })
    }
}

/// Every slot was claimed: the waker that was to wait, to be dropped outside the section.
struct Full(Waker);

/// A [`Delay`] that holds no slot: a plain byte, not an `Option<u8>` (one store sets it, one
/// compare tests it: on LightRing the poll's bound 5 cycles less, the drop's 7).
const NO_SLOT: u8 = u8::MAX;

/// The future of [`TimerQueue::delay_until`]: completes at its tick or later. It holds a slot
/// index (`NO_SLOT`: none), no link: it may move, and dropping it frees the slot.
pub struct Delay<B: Backend> {
    at: u64,
    slot: u8,
    _backend: PhantomData<fn() -> B>,
}

impl<B: Backend> Delay<B> {
    fn free(&mut self) {
        if self.slot != NO_SLOT {
            drop(B::queue().release(core::mem::replace(&mut self.slot, NO_SLOT)));
        }
    }
}

impl<B: Backend> Future for Delay<B> {
    type Output = ();

    fn poll(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<()> {
        let this = &mut *self;
        let now = B::now();
        if now >= this.at {
            // The slot, if any, is freed when the future is dropped, right after.
            return Poll::Ready(());
        }
        let arm_at = this.at.min(now.saturating_add(STEP));
        match B::queue().arm(&mut this.slot, arm_at, cx.waker().clone()) {
            Ok(spare) => drop(spare),
            Err(Full(waker)) => {
                drop(waker);
                poll_again(cx.waker());
            }
        }
        Poll::Pending
    }
}

impl<B: Backend> Drop for Delay<B> {
    fn drop(&mut self) {
        self.free();
    }
}

/// The future of [`TimerQueue::expiry`]: a [`Delay`] that, once armed, completes only when the
/// timer's interrupt has taken its slot off the list, and frees the slot then
/// (`TimerQueue::settle`). Its first poll is the [`Delay`]'s (complete at once, without a slot,
/// when the tick has come; else armed: the insertion walk); a later one only looks at its slot, so
/// the poll that ends the wait never runs the arming, which the execution-time bound would charge it
/// wherever one function polls the wait (the command handler's job: the poll that resumes it and
/// the next wait's first). It may complete later than a [`Delay`] by the interrupt's own latency:
/// the time has passed the list's head, so the interrupt is due, and it wakes the task.
///
/// A wait further than [`STEP`] ahead is armed [`STEP`] ahead, as a [`Delay`] is; when that
/// expires, the wait asks its task to be polled again and arms anew in that poll, so that no poll
/// that finds its slot freed arms one. (The command handler, its one user, waits at most one
/// command interval.)
pub struct Expiry<B: Backend>(Delay<B>);

impl<B: Backend> Expiry<B> {
    /// Whether the wait holds a timer slot: armed and not yet completed. One that found the queue
    /// full holds none until a poll finds one free.
    #[inline(always)]
    pub fn holds_slot(&self) -> bool {
        self.0.slot != NO_SLOT
    }
}

impl<B: Backend> Future for Expiry<B> {
    type Output = ();

    #[inline]
    fn poll(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<()> {
        let delay = &mut self.0;
        if delay.slot != NO_SLOT {
            let spare = match B::queue().settle(delay.slot, cx.waker()) {
                Ok(spare) => spare,
                Err(spare) => {
                    drop(spare);
                    return Poll::Pending;
                }
            };
            drop(spare);
            delay.slot = NO_SLOT;
            if B::now() >= delay.at {
                return Poll::Ready(());
            }
            // Armed a step ahead, short of its tick: the next poll arms again.
            poll_again(cx.waker());
            return Poll::Pending;
        }
        Pin::new(delay).poll(cx)
    }
}

/// No slot for a wait: its task is to be polled again (module docs). Not inlined: its call through
/// the waker's vtable keeps a place of its own in the machine code (the analysis names each such
/// call by its line).
#[inline(never)]
pub(crate) fn poll_again(waker: &Waker) {
    waker.wake_by_ref();
}

/// The future of [`TimerQueue::timeout_at`]: the future's output, or `None` once the tick came.
/// The future first (`repr(C)`): placed after the delay, its move into the timeout was built as two
/// unaligned `memcpy` calls, of the delay's padding and the future together (LightRing's
/// `timeout_at_us` poll bounded at 3 401 cycles, 1 634 with the future first).
#[repr(C)]
pub struct Timeout<B: Backend, F> {
    future: F,
    delay: Delay<B>,
}

impl<B: Backend, F: Future> Future for Timeout<B, F> {
    type Output = Option<F::Output>;

    fn poll(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Self::Output> {
        // SAFETY: `future` is never moved out of the pinned `Timeout`; `delay` is `Unpin`.
        let this = unsafe { self.get_unchecked_mut() };
        // SAFETY: as above: `future` stays where it is until the `Timeout` is dropped.
        let future = unsafe { Pin::new_unchecked(&mut this.future) };
        if let Poll::Ready(output) = future.poll(cx) {
            // The delay's slot is freed when the timeout is dropped, right after.
            return Poll::Ready(Some(output));
        }
        match Pin::new(&mut this.delay).poll(cx) {
            Poll::Ready(()) => Poll::Ready(None),
            Poll::Pending => Poll::Pending,
        }
    }
}

/// The release after a periodic job's: `next` (its release plus the period) while it is ahead of
/// `now` (read as the job ends); once the job has run past it, `now + period`. The releases it
/// overran are skipped rather than run back to back: a wait for a release already past ends at once
/// without suspending, so a task that kept overrunning would never give the processor back, and
/// the tasks beside it at its priority and every task below (the trace drain at 0) would not run.
/// PowerManagement's production image on QEMU's `netduinoplus2` is such a case (`cargo xtask
/// smoke`): there its power monitor's job, whose I2C waits no gauge answers end by their poll
/// bounds (no DWT), outlasts its 50 ms period as the emulated TIM2 counts it; on a chip only a job
/// past its stated bound would. Skipping only lengthens the time between releases, which the
/// schedule analysis allows for (it takes the period as the shortest).
pub const fn next_release(next: u64, now: u64, period: u64) -> u64 {
    if next > now {
        next
    } else {
        now.saturating_add(period)
    }
}

/// A task's poll ended here and the task pended again at once ([`yield_now`]): its next poll
/// resumes after the await. A job split into short stretches, each one poll, ends each stretch
/// with it, so that a future found ready at once does not run the next stretch in the same poll
/// (PowerManagement's bus owners, docs/i2c.md "Session 24 (continued)").
pub struct YieldNow(bool);

/// An await that ends its task's poll and wakes the task at once ([`YieldNow`]). Its wake is the
/// waker's, through `poll_again`.
pub const fn yield_now() -> YieldNow {
    YieldNow(false)
}

impl Future for YieldNow {
    type Output = ();

    /// Always inlined: at the await, the flag's store (`yield_now`) and its test here are one
    /// function's, so the compiler settles the first poll's way (pending) and the machine code
    /// has no path on from the await in the poll that reached it.
    #[inline(always)]
    fn poll(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<()> {
        if self.0 {
            return Poll::Ready(());
        }
        self.0 = true;
        // Opaque: else the compiler, knowing the executor's waker where it inlines this, passes
        // the vtable's wake entry to `poll_again` as a constant, which the analysis then takes
        // for a waker's data (machine-code wcet/stored.rs).
        poll_again(core::hint::black_box(cx.waker()));
        Poll::Pending
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
    use std::sync::{Mutex, MutexGuard};

    // One model timer per test binary: the tests that use it take `LOCK`.
    static LOCK: Mutex<()> = Mutex::new(());
    static NOW: AtomicU64 = AtomicU64::new(0);
    static COMPARE: AtomicU64 = AtomicU64::new(NONE);
    static PENDS: AtomicUsize = AtomicUsize::new(0);
    // The time moves by this much at each read in the interrupt after the first (a slow interrupt).
    static DRIFT: AtomicU64 = AtomicU64::new(0);
    static READS: AtomicUsize = AtomicUsize::new(0);
    static QUEUE: TimerQueue<Model> = TimerQueue::new();

    struct Model;

    impl Backend for Model {
        fn now() -> u64 {
            NOW.load(Ordering::SeqCst)
        }
        fn now_in_interrupt() -> u64 {
            if READS.fetch_add(1, Ordering::SeqCst) > 0 {
                NOW.fetch_add(DRIFT.load(Ordering::SeqCst), Ordering::SeqCst);
            }
            Self::now()
        }
        fn set_compare(at: u64, _now: u64) -> bool {
            COMPARE.store(at, Ordering::SeqCst);
            Self::now_in_interrupt() >= at
        }
        fn disable_compare() {
            COMPARE.store(NONE, Ordering::SeqCst);
        }
        fn pend_interrupt() {
            PENDS.fetch_add(1, Ordering::SeqCst);
        }
        fn queue() -> &'static TimerQueue<Self> {
            &QUEUE
        }
    }

    /// A clean model timer at `now`, held for the test.
    fn model(now: u64) -> MutexGuard<'static, ()> {
        let guard = LOCK.lock().unwrap_or_else(|e| e.into_inner());
        NOW.store(now, Ordering::SeqCst);
        COMPARE.store(NONE, Ordering::SeqCst);
        PENDS.store(0, Ordering::SeqCst);
        DRIFT.store(0, Ordering::SeqCst);
        assert_eq!(QUEUE.waiting(), 0, "a test left a wait armed");
        guard
    }

    /// Runs the interrupt, as the timer would, and what it pended of itself.
    fn interrupt() {
        READS.store(0, Ordering::SeqCst);
        let pends = PENDS.load(Ordering::SeqCst);
        // SAFETY: the tests are the only users of the queue, one at a time (`LOCK`).
        unsafe { QUEUE.on_interrupt() };
        if PENDS.load(Ordering::SeqCst) > pends {
            PENDS.fetch_sub(1, Ordering::SeqCst);
            interrupt();
        }
    }

    /// A task: counts its wakes.
    use crate::test_waker::{counting as task, Wakes as Task};

    fn poll<F: Future + Unpin>(f: &mut F, waker: &Waker) -> Poll<F::Output> {
        Pin::new(f).poll(&mut Context::from_waker(waker))
    }

    fn wakes(t: &Task) -> usize {
        t.count()
    }

    #[test]
    fn a_periodic_task_that_overruns_its_period_still_waits_before_each_job() {
        // Period 50, each job 70 long (QEMU's power monitor): the release a job ends past is
        // skipped, and the wait for the next one suspends the task every time.
        let _m = model(0);
        let (_t, w) = task();
        let mut next = 0;
        for job in 0..6u64 {
            let mut d = QUEUE.delay_until(next);
            let started = if job == 0 {
                // The first wait is for the task's start: it ends at once.
                assert!(poll(&mut d, &w).is_ready());
                NOW.load(Ordering::SeqCst)
            } else {
                assert!(poll(&mut d, &w).is_pending(), "job {job}: the task waits");
                drop(d);
                NOW.store(next, Ordering::SeqCst);
                next
            };
            next += 50;
            NOW.store(started + 70, Ordering::SeqCst);
            next = next_release(next, NOW.load(Ordering::SeqCst), 50);
            assert_eq!(
                next,
                started + 120,
                "job {job}: a period after the overrun job ended"
            );
        }
        // Jobs on time keep their releases.
        assert_eq!(next_release(150, 149, 50), 150);
        assert_eq!(next_release(150, 150, 50), 200);
    }

    #[test]
    fn a_delay_ends_at_its_tick_not_before() {
        let _m = model(100);
        let (t, w) = task();
        let mut d = QUEUE.delay_until(150);
        assert!(poll(&mut d, &w).is_pending());
        assert_eq!(
            PENDS.load(Ordering::SeqCst),
            1,
            "a new earliest wait pends the interrupt"
        );
        interrupt();
        assert_eq!(COMPARE.load(Ordering::SeqCst), 150);
        NOW.store(149, Ordering::SeqCst);
        interrupt();
        assert_eq!(wakes(&t), 0);
        NOW.store(150, Ordering::SeqCst);
        interrupt();
        assert_eq!(wakes(&t), 1);
        assert_eq!(
            COMPARE.load(Ordering::SeqCst),
            NONE,
            "nothing left: compare off"
        );
        assert!(poll(&mut d, &w).is_ready());
        assert_eq!(QUEUE.waiting(), 0);
    }

    #[test]
    fn a_past_tick_ends_at_once_without_a_slot() {
        let _m = model(500);
        let (_t, w) = task();
        let mut d = QUEUE.delay_until(500);
        assert!(poll(&mut d, &w).is_ready());
        assert_eq!(PENDS.load(Ordering::SeqCst), 0);
        assert_eq!(QUEUE.with(|s| s.claimed), 0);
    }

    #[test]
    fn waits_end_in_the_order_of_their_ticks_and_equal_ticks_together() {
        let _m = model(0);
        let tasks: Vec<_> = (0..4).map(|_| task()).collect();
        let ticks = [300, 100, 200, 100];
        let mut delays: Vec<_> = ticks.iter().map(|&at| QUEUE.delay_until(at)).collect();
        for (d, (_, w)) in delays.iter_mut().zip(&tasks) {
            assert!(poll(d, w).is_pending());
        }
        interrupt();
        assert_eq!(
            COMPARE.load(Ordering::SeqCst),
            100,
            "the compare is the earliest wait"
        );
        let woken = || tasks.iter().map(|(t, _)| wakes(t)).collect::<Vec<_>>();
        NOW.store(100, Ordering::SeqCst);
        interrupt();
        assert_eq!(woken(), [0, 1, 0, 1], "both waits at 100 together");
        assert_eq!(COMPARE.load(Ordering::SeqCst), 200);
        NOW.store(250, Ordering::SeqCst);
        interrupt();
        assert_eq!(woken(), [0, 1, 1, 1]);
        assert_eq!(COMPARE.load(Ordering::SeqCst), 300);
        NOW.store(300, Ordering::SeqCst);
        interrupt();
        assert_eq!(woken(), [1, 1, 1, 1]);
        for (d, (_, w)) in delays.iter_mut().zip(&tasks) {
            assert!(poll(d, w).is_ready());
        }
        assert_eq!(
            QUEUE.with(|s| s.claimed.count_ones()),
            4,
            "claimed until dropped"
        );
        drop(delays);
        assert_eq!(QUEUE.with(|s| s.claimed), 0);
    }

    #[test]
    fn a_dropped_delay_frees_its_slot_and_is_not_woken() {
        let _m = model(0);
        let (t1, w1) = task();
        let (t2, w2) = task();
        let mut first = QUEUE.delay_until(100);
        let mut second = QUEUE.delay_until(200);
        assert!(poll(&mut first, &w1).is_pending());
        assert!(poll(&mut second, &w2).is_pending());
        interrupt();
        drop(first);
        assert_eq!(QUEUE.waiting(), 1);
        NOW.store(100, Ordering::SeqCst);
        interrupt();
        assert_eq!(wakes(&t1), 0, "the dropped wait is not woken");
        assert_eq!(
            COMPARE.load(Ordering::SeqCst),
            200,
            "the compare goes to the wait left"
        );
        NOW.store(200, Ordering::SeqCst);
        interrupt();
        assert_eq!(wakes(&t2), 1);
        drop(second);
        assert_eq!(QUEUE.with(|s| s.claimed), 0);
    }

    #[test]
    fn the_head_the_interrupt_left_leaves_the_list_as_its_head_when_dropped() {
        let _m = model(0);
        let tasks: Vec<_> = (0..3).map(|_| task()).collect();
        let mut delays: Vec<_> = [100, 200, 300]
            .iter()
            .map(|&at| QUEUE.delay_until(at))
            .collect();
        for (d, (_, w)) in delays.iter_mut().zip(&tasks) {
            assert!(poll(d, w).is_pending());
        }
        NOW.store(100, Ordering::SeqCst);
        interrupt();
        let second = delays.remove(1);
        drop(second);
        assert_eq!(
            QUEUE.with(|s| order(s)).len(),
            1,
            "the third alone, as the head"
        );
        interrupt();
        assert_eq!(COMPARE.load(Ordering::SeqCst), 300);
        NOW.store(300, Ordering::SeqCst);
        interrupt();
        let woken: Vec<_> = tasks.iter().map(|(t, _)| wakes(t)).collect();
        assert_eq!(woken, [1, 0, 1]);
        drop(delays);
        assert_eq!(QUEUE.with(|s| s.claimed), 0);
    }

    #[test]
    fn a_timeout_whose_future_finishes_first_frees_its_slot() {
        let _m = model(0);
        let (t, w) = task();
        let mut timeout = Box::pin(QUEUE.timeout_at(100, core::future::pending::<u8>()));
        assert!(timeout
            .as_mut()
            .poll(&mut Context::from_waker(&w))
            .is_pending());
        assert_eq!(QUEUE.waiting(), 1);
        drop(timeout);
        assert_eq!(
            QUEUE.waiting(),
            0,
            "dropped before its tick: the slot is free"
        );
        let mut timeout = Box::pin(QUEUE.timeout_at(100, core::future::ready(7)));
        assert_eq!(
            timeout.as_mut().poll(&mut Context::from_waker(&w)),
            Poll::Ready(Some(7))
        );
        let mut timeout = Box::pin(QUEUE.timeout_at(100, core::future::pending::<u8>()));
        assert!(timeout
            .as_mut()
            .poll(&mut Context::from_waker(&w))
            .is_pending());
        interrupt();
        NOW.store(100, Ordering::SeqCst);
        interrupt();
        assert_eq!(wakes(&t), 1);
        assert_eq!(
            timeout.as_mut().poll(&mut Context::from_waker(&w)),
            Poll::Ready(None)
        );
        drop(timeout);
        assert_eq!(QUEUE.with(|s| s.claimed), 0);
    }

    #[test]
    fn a_later_wait_does_not_pend_and_an_earlier_one_does() {
        let _m = model(0);
        let (_t, w) = task();
        let mut early = QUEUE.delay_until(100);
        let mut late = QUEUE.delay_until(200);
        let mut earlier = QUEUE.delay_until(50);
        assert!(poll(&mut early, &w).is_pending());
        interrupt();
        let pends = PENDS.load(Ordering::SeqCst);
        assert!(poll(&mut late, &w).is_pending());
        assert_eq!(
            PENDS.load(Ordering::SeqCst),
            pends,
            "after the compare: no interrupt"
        );
        assert!(poll(&mut earlier, &w).is_pending());
        assert_eq!(
            PENDS.load(Ordering::SeqCst),
            pends + 1,
            "before the compare: pended"
        );
        interrupt();
        assert_eq!(COMPARE.load(Ordering::SeqCst), 50);
        assert!(poll(&mut late, &w).is_pending());
        assert_eq!(QUEUE.waiting(), 3, "a poll again keeps the one slot");
        drop((early, late, earlier));
    }

    #[test]
    fn time_that_passes_the_compare_while_it_is_set_pends_the_interrupt() {
        let _m = model(0);
        let (t, w) = task();
        let mut d = QUEUE.delay_until(10);
        assert!(poll(&mut d, &w).is_pending());
        // The interrupt runs at 5 and its second read of the time is 15: past the compare at 10.
        NOW.store(5, Ordering::SeqCst);
        DRIFT.store(10, Ordering::SeqCst);
        READS.store(0, Ordering::SeqCst);
        let pends = PENDS.load(Ordering::SeqCst);
        // SAFETY: the tests are the only users of the queue, one at a time (`LOCK`).
        unsafe { QUEUE.on_interrupt() };
        assert_eq!(wakes(&t), 0);
        assert_eq!(
            PENDS.load(Ordering::SeqCst),
            pends + 1,
            "the interrupt pends itself"
        );
        DRIFT.store(0, Ordering::SeqCst);
        interrupt();
        assert_eq!(wakes(&t), 1);
        drop(d);
    }

    #[test]
    fn the_low_32_bits_compare_across_their_wrap() {
        let start = (1u64 << 32) - 40;
        let _m = model(start);
        let (t, w) = task();
        let mut d = QUEUE.delay_until(start + 100);
        assert!(poll(&mut d, &w).is_pending());
        interrupt();
        assert_eq!(COMPARE.load(Ordering::SeqCst), start + 100);
        NOW.store(start + 99, Ordering::SeqCst);
        interrupt();
        assert_eq!(wakes(&t), 0);
        NOW.store(start + 100, Ordering::SeqCst);
        interrupt();
        assert_eq!(wakes(&t), 1);
        assert!(poll(&mut d, &w).is_ready());
    }

    #[test]
    fn a_wait_further_than_a_step_arms_in_steps() {
        let _m = model(0);
        let (t, w) = task();
        let at = 3 * STEP + 7;
        let mut d = QUEUE.delay_until(at);
        assert!(poll(&mut d, &w).is_pending());
        interrupt();
        assert_eq!(COMPARE.load(Ordering::SeqCst), STEP);
        for step in 1..=3 {
            NOW.store(step * STEP, Ordering::SeqCst);
            interrupt();
            assert_eq!(wakes(&t), step as usize);
            assert!(poll(&mut d, &w).is_pending(), "woken early: arms again");
            interrupt();
        }
        assert_eq!(COMPARE.load(Ordering::SeqCst), at);
        NOW.store(at, Ordering::SeqCst);
        interrupt();
        assert!(poll(&mut d, &w).is_ready());
    }

    #[test]
    fn a_full_queue_makes_a_wait_poll_again_and_a_freed_slot_serves_it() {
        let _m = model(0);
        let (t, w) = task();
        let mut held: Vec<_> = (0..CAPACITY).map(|_| QUEUE.delay_until(1_000)).collect();
        for d in &mut held {
            assert!(poll(d, &w).is_pending());
        }
        let before = wakes(&t);
        let mut extra = QUEUE.delay_until(10);
        assert!(poll(&mut extra, &w).is_pending());
        assert_eq!(wakes(&t), before + 1, "no slot: the task is polled again");
        assert_eq!(QUEUE.waiting(), CAPACITY as u32, "and it holds none");
        held.pop();
        assert!(poll(&mut extra, &w).is_pending());
        assert_eq!(QUEUE.waiting(), CAPACITY as u32);
        drop(held);
        drop(extra);
    }

    #[test]
    fn an_expiry_ends_only_once_the_interrupt_took_its_slot_off_and_frees_it_without_its_drop() {
        let _m = model(100);
        let (t, w) = task();
        let mut e = QUEUE.expiry(150);
        assert!(poll(&mut e, &w).is_pending());
        interrupt();
        NOW.store(150, Ordering::SeqCst);
        assert!(
            poll(&mut e, &w).is_pending(),
            "the time has come, but the slot is still listed: the interrupt is due"
        );
        assert_eq!(QUEUE.waiting(), 1);
        interrupt();
        assert_eq!(wakes(&t), 1, "the interrupt wakes it");
        assert!(poll(&mut e, &w).is_ready());
        assert_eq!(
            QUEUE.with(|s| s.claimed),
            0,
            "freed as it completed, before its drop"
        );
        drop(e);
        assert_eq!(QUEUE.with(|s| s.claimed), 0);
    }

    #[test]
    fn an_expiry_whose_tick_has_come_ends_at_once_without_a_slot() {
        let _m = model(500);
        let (_t, w) = task();
        let mut e = QUEUE.expiry(500);
        assert!(poll(&mut e, &w).is_ready());
        assert_eq!(PENDS.load(Ordering::SeqCst), 0);
        assert_eq!(QUEUE.with(|s| s.claimed), 0);
    }

    #[test]
    fn an_expiry_further_than_a_step_asks_to_be_polled_again_and_arms_then() {
        let _m = model(0);
        let (t, w) = task();
        let at = STEP + 7;
        let mut e = QUEUE.expiry(at);
        assert!(poll(&mut e, &w).is_pending());
        interrupt();
        assert_eq!(COMPARE.load(Ordering::SeqCst), STEP);
        NOW.store(STEP, Ordering::SeqCst);
        interrupt();
        assert_eq!(wakes(&t), 1);
        assert!(poll(&mut e, &w).is_pending(), "a step short of its tick");
        assert_eq!(wakes(&t), 2, "it asks to be polled again");
        assert_eq!(QUEUE.waiting(), 0, "and holds no slot until then");
        assert!(poll(&mut e, &w).is_pending());
        interrupt();
        assert_eq!(COMPARE.load(Ordering::SeqCst), at, "armed for its tick");
        NOW.store(at, Ordering::SeqCst);
        interrupt();
        assert!(poll(&mut e, &w).is_ready());
        assert_eq!(QUEUE.with(|s| s.claimed), 0);
    }

    #[test]
    fn an_expiry_dropped_while_it_waits_frees_its_slot_and_is_not_woken() {
        let _m = model(0);
        let (t, w) = task();
        let mut e = QUEUE.expiry(100);
        assert!(poll(&mut e, &w).is_pending());
        interrupt();
        drop(e);
        assert_eq!(QUEUE.with(|s| s.claimed), 0);
        NOW.store(100, Ordering::SeqCst);
        interrupt();
        assert_eq!(wakes(&t), 0);
        assert_eq!(COMPARE.load(Ordering::SeqCst), NONE);
    }

    #[test]
    fn an_expiry_polled_by_another_task_while_it_waits_wakes_that_task() {
        let _m = model(0);
        let (first, w1) = task();
        let (second, w2) = task();
        let mut e = QUEUE.expiry(100);
        assert!(poll(&mut e, &w1).is_pending());
        assert!(poll(&mut e, &w2).is_pending());
        NOW.store(100, Ordering::SeqCst);
        interrupt();
        assert_eq!((wakes(&first), wakes(&second)), (0, 1));
        assert!(poll(&mut e, &w2).is_ready());
    }

    /// The listed slots from the head, each but the head checked against its predecessor link.
    fn order(s: &State) -> Vec<usize> {
        let mut out = Vec::new();
        let mut before = 0u8;
        let mut cur = s.head;
        while cur != 0 {
            let i = usize::from(cur - 1);
            if before != 0 {
                assert_eq!(s.prev[i], before, "slot {i}'s predecessor");
            }
            out.push(i);
            before = cur;
            cur = s.link[i];
        }
        out
    }

    #[test]
    fn the_list_keeps_instant_order_with_equal_instants_in_arrival_order() {
        let mut s = State::EMPTY;
        assert!(s.link_in(4, 300));
        assert!(s.link_in(7, 100), "an earlier instant becomes the head");
        assert!(!s.link_in(2, 200));
        assert!(
            !s.link_in(9, 100),
            "an equal instant goes after the one there"
        );
        assert!(!s.link_in(15, 400));
        assert_eq!(order(&s), [7, 9, 2, 4, 15]);
        assert_eq!(s.armed, 1 << 7 | 1 << 9 | 1 << 2 | 1 << 4 | 1 << 15);
        s.unlink(2);
        assert_eq!(order(&s), [7, 9, 4, 15], "from the middle");
        s.unlink(7);
        assert_eq!(order(&s), [9, 4, 15], "the head");
        s.unlink(15);
        assert_eq!(order(&s), [9, 4], "the last");
        assert_eq!(s.armed, 1 << 9 | 1 << 4);
        s.unlink(9);
        s.unlink(4);
        assert!(order(&s).is_empty());
        assert_eq!((s.head, s.armed), (0, 0));
    }

    #[test]
    fn the_list_orders_across_the_wrap_of_the_32_bits() {
        let mut s = State::EMPTY;
        assert!(s.link_in(0, 5));
        assert!(
            s.link_in(1, u32::MAX - 5),
            "before the wrap: earlier than 5 after it"
        );
        assert_eq!(order(&s), [1, 0]);
    }
}
