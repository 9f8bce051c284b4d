//! The monotonic glue: microseconds over whichever timer a board uses.
//!
//! Tasks and the runtime see time only as [`Clock`]: `now_us`, `delay_until_us`,
//! `timeout_at_us`. [`TimerClock`] provides it over any [`crate::timer_queue`] backend with 64-bit
//! ticks of `TICK_US` microseconds: the boards' half-period timers (`timer_monotonic`: TIM5 on
//! DiWheelDrive, TIM3 on LightRing, TIM2 on PowerManagement) and the SysTick of the QEMU builds.
//!
//! Deadlock freedom: rtic-monotonics keeps its 64-bit tick counters in `portable_atomic::AtomicU64`,
//! which thumbv7 has no instructions for. Its default emulation is a global spin lock; a timer
//! interrupt that pre-empts a task inside `now()` then spins for ever on the lock the task holds
//! (rtic-rs/rtic#1117: the QEMU build deadlocked under load). This crate enables
//! portable-atomic's `unsafe-assume-single-core` (both chips are single-core Cortex-M), which
//! emulates 64-bit atomics by masking interrupts for a few instructions instead: no lock to spin on.
use core::future::Future;
use core::marker::PhantomData;

use crate::timer_queue::Backend;

/// The QEMU build's clock: the apps' timer queue over the platform's SysTick (`qemu::timer`).
#[cfg(feature = "qemu")]
pub type QemuClock = TimerClock<crate::qemu::timer::AppTimer, { crate::qemu::TICK_US }>;

/// Brings the QEMU platform up (`qemu::init`: painted RAM, SysTick, the trace file) and starts the
/// trace clock over its SysTick. Call first thing in the QEMU build's board set-up.
#[cfg(feature = "qemu")]
pub fn start_qemu(syst: cortex_m::peripheral::SYST) {
    crate::qemu::init(syst);
    crate::tracing::start_clock(crate::qemu::CORE_CLOCK_HZ);
}

/// Time as the tasks see it: microseconds since the monotonic started.
pub trait Clock {
    /// Microseconds since the monotonic started.
    fn now_us() -> u64;
    /// Waits until the monotonic reaches `at_us`.
    fn delay_until_us(at_us: u64) -> impl Future<Output = ()>;
    /// A wait until the monotonic reaches `at_us` that frees its timer slot as it completes
    /// (`timer_queue::Expiry`): the command handler's rate limit (`tasks::serve_commands`). Not
    /// traced: its caller says when its task stops and runs again.
    type Expiry: Future<Output = ()> + Unpin;
    /// [`Clock::Expiry`] for `at_us`.
    fn expiry_at_us(at_us: u64) -> Self::Expiry;
    /// Whether `expiry` holds its timer slot (`timer_queue::Expiry::holds_slot`).
    fn expiry_armed(expiry: &Self::Expiry) -> bool;
    /// Runs `future` until it completes or the monotonic reaches `at_us`, whichever is first.
    fn timeout_at_us<F: Future>(at_us: u64, future: F) -> impl Future<Output = Option<F::Output>>;
    /// A fault of the timer to log, once (the timer's interrupt only counts it; the watchdog task
    /// asks).
    fn take_fault_report() -> Option<&'static str>;
}

/// [`Clock`] over the timer queue of `B`, whose ticks are `TICK_US` microseconds.
pub struct TimerClock<B, const TICK_US: u64>(PhantomData<B>);

impl<B, const TICK_US: u64> Clock for TimerClock<B, TICK_US>
where
    B: Backend,
{
    fn now_us() -> u64 {
        B::now().saturating_mul(TICK_US)
    }

    // The waits end the running task's run in the trace, with its next release, and start it
    // again when it resumes (`tracing`). Only the traced build reads the clock for that release
    // (`tracing::suspend_until`): the shipped images' waits read none.
    async fn delay_until_us(at_us: u64) {
        let task = crate::tracing::suspend_until(at_us, Self::now_us);
        B::queue().delay_until(at_us.div_ceil(TICK_US)).await;
        crate::tracing::resume(task);
    }

    fn take_fault_report() -> Option<&'static str> {
        B::take_fault_report()
    }

    type Expiry = crate::timer_queue::Expiry<B>;

    fn expiry_at_us(at_us: u64) -> Self::Expiry {
        B::queue().expiry(at_us.div_ceil(TICK_US))
    }

    #[inline(always)]
    fn expiry_armed(expiry: &Self::Expiry) -> bool {
        expiry.holds_slot()
    }

    async fn timeout_at_us<F: Future>(at_us: u64, future: F) -> Option<F::Output> {
        let task = crate::tracing::suspend_until(at_us, Self::now_us);
        let result = B::queue().timeout_at(at_us.div_ceil(TICK_US), future).await;
        crate::tracing::resume(task);
        result
    }
}
