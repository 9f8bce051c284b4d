//! The command handler's job, hardware-free: one poll takes at most one command from the frame queue
//! the CAN receive interrupt fills, each no earlier than the previous one's start plus the rate limit's
//! interval (`tasks::serve_commands`, `docs/analysis.md`, "The command handler"). The board side is a
//! [`JobClock`]: the monotonic's time and its rate-limit wait (`timer_queue::Expiry`) and the trace's
//! marks; the host tests run it over a timer queue on a test backend.
use core::future::Future;
use core::pin::Pin;
use core::task::{Context, Poll};

use crate::can::RxFrame;
use crate::rx_queue::Consumer;

/// What the command handler's job needs of the board: time, the rate limit's wait, the trace.
pub trait JobClock {
    /// Microseconds since the monotonic started.
    fn now_us() -> u64;
    /// The rate limit's wait (`mono::Clock::Expiry`: it frees its timer slot as it completes).
    type Expiry: Future<Output = ()> + Unpin;
    /// [`JobClock::Expiry`] until `at_us`.
    fn expiry_at_us(at_us: u64) -> Self::Expiry;
    /// Whether `expiry` holds its timer slot (armed, not completed: `timer_queue::Expiry::holds_slot`).
    fn armed(expiry: &Self::Expiry) -> bool;
    /// The trace's mark where the task stops (`tracing::suspend`: its next release and the time
    /// read, if known); the number it returns is [`JobClock::resume`]'s.
    fn suspend(release: Option<(u64, u64)>) -> u8;
    /// The trace's mark where the stopped task runs again.
    fn resume(task: u8);
}

/// The command handler's future (`tasks::serve_commands`), polled through one function the compiler
/// keeps apart, with no loop: a poll is a job, and takes at most one command. Its longest way is the one
/// the machine-code bound charges, so each part is on it once: the time read against the rate limit's
/// instant, the frame queue's look (and the park that finds it empty), the command's handling, and the
/// rate limit's timer armed for the next instant (the previous command's wait dropped, its slot freed
/// without a walk). When that instant has come already (a job that ran past it, or one that came
/// during the arming), the task asks to be polled again: the next command is a job of its own.
///
/// A wake before the instant (a frame came) looks at the rate limit's wait again and goes back to
/// sleep: the armed timer's interrupt wakes the task at the instant. The look is what keeps a wait
/// that found the timer queue full (`timer_queue`: it asks to be polled again, holding no slot) from
/// being left unarmed, the task asleep for good: each poll of it tries the queue again.
pub struct ServeCommands<'c, C: JobClock, const N: usize, H> {
    frames: &'c mut Consumer<'static, N>,
    interval_us: u64,
    handle: H,
    /// The rate limit's wait: polled when it is armed and at each wake before its instant; a slot
    /// it holds is freed when the next arming replaces it.
    limit: C::Expiry,
    /// The rate limit's instant while it is ahead (`None` once it has passed, or before the first
    /// command).
    not_before_us: Option<u64>,
    /// The task the trace stopped at the wait in progress ([`JobClock::suspend`]), `None` while a
    /// command is handled.
    stopped: Option<u8>,
}

impl<'c, C: JobClock, const N: usize, H: FnMut(RxFrame) + Unpin> ServeCommands<'c, C, N, H> {
    /// The job over the frame queue's consumer `frames`, each command handed to `handle`, at most
    /// one per `interval_us`.
    pub fn new(frames: &'c mut Consumer<'static, N>, interval_us: u64, handle: H) -> Self {
        Self {
            frames,
            interval_us,
            handle,
            limit: C::expiry_at_us(0),
            not_before_us: None,
            stopped: None,
        }
    }
}

impl<C: JobClock, const N: usize, H: FnMut(RxFrame) + Unpin> Future for ServeCommands<'_, C, N, H> {
    type Output = core::convert::Infallible;

    #[inline(never)]
    fn poll(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<core::convert::Infallible> {
        let this = self.get_mut();
        if let Some(at_us) = this.not_before_us {
            if C::now_us() < at_us {
                // Woken before the instant: the armed timer's interrupt wakes the task at it. A wait
                // that holds no slot (the queue was full) is polled again below, to arm it now.
                if C::armed(&this.limit) {
                    return Poll::Pending;
                }
            } else {
                this.not_before_us = None;
                if let Some(task) = this.stopped.take() {
                    C::resume(task);
                }
            }
        }
        if this.not_before_us.is_none() {
            let task = *this.stopped.get_or_insert_with(|| C::suspend(None));
            let Poll::Ready(frame) = this.frames.poll_recv_packed(cx) else {
                return Poll::Pending;
            };
            this.stopped = None;
            C::resume(task);
            let started = C::now_us();
            (this.handle)(frame.unpack());
            let at_us = started + this.interval_us;
            let now = C::now_us();
            if now >= at_us {
                crate::timer_queue::poll_again(cx.waker());
                return Poll::Pending;
            }
            this.not_before_us = Some(at_us);
            // The trace's next release: the rate limit's instant. The time is read in every build (the
            // QEMU runs' jobs are held to the release image's bound, which must hold their code).
            this.stopped = Some(C::suspend(Some((at_us, now))));
            this.limit = C::expiry_at_us(at_us);
        }
        // The wait's first poll arms the timer, or finds the instant come meanwhile; a later one (woken
        // before the instant, the wait holding no slot) tries the timer queue again. No poll here finds
        // the wait armed, so none runs the look at an armed slot (`timer_queue::Expiry`).
        if Pin::new(&mut this.limit).poll(cx).is_ready() {
            crate::timer_queue::poll_again(cx.waker());
        }
        Poll::Pending
    }
}

#[cfg(test)]
mod tests {
    use std::sync::atomic::{AtomicU64, Ordering};
    use std::sync::Mutex;

    use super::*;
    use crate::rx_queue::FrameQueue;
    use crate::test_waker::counting;
    use crate::timer_queue::{Backend, Expiry, TimerQueue, CAPACITY};

    /// The tests share the one queue below: one at a time.
    static LOCK: Mutex<()> = Mutex::new(());
    static NOW: AtomicU64 = AtomicU64::new(0);
    static QUEUE: TimerQueue<TestTimer> = TimerQueue::new();

    /// A timer in microsecond ticks whose interrupt the test runs by hand.
    struct TestTimer;

    impl Backend for TestTimer {
        fn now() -> u64 {
            NOW.load(Ordering::SeqCst)
        }
        fn set_compare(at: u64, now: u64) -> bool {
            now >= at
        }
        fn disable_compare() {}
        fn pend_interrupt() {}
        fn queue() -> &'static TimerQueue<Self> {
            &QUEUE
        }
    }

    impl JobClock for TestTimer {
        fn now_us() -> u64 {
            Self::now()
        }
        type Expiry = Expiry<TestTimer>;
        fn expiry_at_us(at_us: u64) -> Self::Expiry {
            QUEUE.expiry(at_us)
        }
        fn armed(expiry: &Self::Expiry) -> bool {
            expiry.holds_slot()
        }
        fn suspend(_: Option<(u64, u64)>) -> u8 {
            0
        }
        fn resume(_: u8) {}
    }

    fn interrupt() {
        // SAFETY: the tests are the queue's only users, one at a time (`LOCK`).
        unsafe { QUEUE.on_interrupt() };
    }

    fn frame(id: u16) -> RxFrame {
        RxFrame {
            id,
            len: 1,
            data: [id as u8, 0, 0, 0, 0, 0, 0, 0],
        }
    }

    const INTERVAL_US: u64 = 1_000;

    #[test]
    fn a_rate_limit_wait_that_found_the_timer_queue_full_arms_at_the_next_wake_before_its_instant()
    {
        let _l = LOCK.lock().unwrap_or_else(|e| e.into_inner());
        NOW.store(10_000, Ordering::SeqCst);
        // SAFETY: this test's queue, split once, used on this thread only.
        let (mut tx, mut rx) = unsafe { Box::leak(Box::new(FrameQueue::<4>::new())).split() };
        let handled = std::cell::RefCell::new(Vec::new());
        let mut job = ServeCommands::<TestTimer, 4, _>::new(&mut rx, INTERVAL_US, |f: RxFrame| {
            handled.borrow_mut().push(f.id)
        });
        let (wakes, waker) = counting();
        let mut cx = Context::from_waker(&waker);
        let mut poll = |job: &mut ServeCommands<'_, TestTimer, 4, _>| {
            assert!(Pin::new(job).poll(&mut cx).is_pending());
        };
        // Every timer slot held by other waits, far ahead.
        let (_other, other_waker) = counting();
        let mut held: Vec<_> = (0..CAPACITY)
            .map(|_| QUEUE.delay_until(1_000_000))
            .collect();
        for d in &mut held {
            assert!(Pin::new(d)
                .poll(&mut Context::from_waker(&other_waker))
                .is_pending());
        }
        assert!(tx.push(&frame(1)));
        poll(&mut job);
        assert_eq!(*handled.borrow(), [1]);
        assert_eq!(
            wakes.count(),
            1,
            "no slot for the rate limit's wait: polled again"
        );
        poll(&mut job);
        assert_eq!(
            QUEUE.waiting(),
            CAPACITY as u32,
            "still no slot: the wait holds none"
        );
        // A slot frees; the task's next wake (a frame came, before the instant) arms the wait.
        held.pop();
        assert!(tx.push(&frame(2)));
        tx.wake();
        poll(&mut job);
        assert_eq!(
            *handled.borrow(),
            [1],
            "before the instant: the frame waits"
        );
        assert_eq!(
            QUEUE.waiting(),
            CAPACITY as u32,
            "the wait armed in the freed slot"
        );
        let before = wakes.count();
        interrupt();
        NOW.store(10_000 + INTERVAL_US, Ordering::SeqCst);
        interrupt();
        assert_eq!(
            wakes.count(),
            before + 1,
            "the timer wakes the task at the instant"
        );
        poll(&mut job);
        assert_eq!(*handled.borrow(), [1, 2]);
        drop(held);
        drop(job);
    }

    #[test]
    fn a_wake_before_the_instant_takes_no_command_and_the_timer_wakes_the_task_at_it() {
        let _l = LOCK.lock().unwrap_or_else(|e| e.into_inner());
        NOW.store(50_000, Ordering::SeqCst);
        // SAFETY: this test's queue, split once, used on this thread only.
        let (mut tx, mut rx) = unsafe { Box::leak(Box::new(FrameQueue::<4>::new())).split() };
        let handled = std::cell::RefCell::new(Vec::new());
        let mut job = ServeCommands::<TestTimer, 4, _>::new(&mut rx, INTERVAL_US, |f: RxFrame| {
            handled
                .borrow_mut()
                .push((f.id, NOW.load(Ordering::SeqCst)))
        });
        let (wakes, waker) = counting();
        let mut cx = Context::from_waker(&waker);
        assert!(
            Pin::new(&mut job).poll(&mut cx).is_pending(),
            "nothing queued"
        );
        assert!(tx.push(&frame(1)) && tx.push(&frame(2)));
        tx.wake();
        assert_eq!(wakes.count(), 1);
        assert!(Pin::new(&mut job).poll(&mut cx).is_pending());
        assert_eq!(*handled.borrow(), [(1, 50_000)], "one command a job");
        assert_eq!(QUEUE.waiting(), 1, "the rate limit's wait armed");
        interrupt();
        NOW.store(50_400, Ordering::SeqCst);
        assert!(Pin::new(&mut job).poll(&mut cx).is_pending());
        assert_eq!(
            handled.borrow().len(),
            1,
            "woken before the instant: no command"
        );
        assert_eq!(QUEUE.waiting(), 1, "one slot, kept");
        NOW.store(51_000, Ordering::SeqCst);
        interrupt();
        assert_eq!(wakes.count(), 2, "the timer's wake at the instant");
        assert!(Pin::new(&mut job).poll(&mut cx).is_pending());
        assert_eq!(*handled.borrow(), [(1, 50_000), (2, 51_000)]);
        drop(job);
        assert_eq!(QUEUE.waiting(), 0);
    }
}
