//! The QEMU build's timers: SysTick ticking every [`TICK_US`] µs drives two timer queues.
//!
//! - The apps' ([`AppTimer`], behind `mono::QemuClock`): every task's delay and timeout. Its
//!   earliest deadline is known ([`next_deadline_us`]), so a robot run can tell the host how long
//!   the board will sleep.
//! - The platform's own (rtic-monotonics' `SystickBackend` queue): the robot exchange and the
//!   stimulus replay wait in it, so their waits never hide the apps' next deadline.
use core::cell::Cell;

use critical_section::Mutex;
use rtic_monotonics::systick::{SystClkSource, SystickBackend, SYST};
use rtic_time::timer_queue::{TimerQueue, TimerQueueBackend};

use super::TICK_US;

/// The apps' timer queue over SysTick's tick count.
pub struct AppTimer;

static APP_QUEUE: TimerQueue<AppTimer> = TimerQueue::new();
/// The tick of the apps' earliest deadline (`u64::MAX`: none queued).
static NEXT_TICK: Mutex<Cell<u64>> = Mutex::new(Cell::new(u64::MAX));

impl TimerQueueBackend for AppTimer {
    type Ticks = u64;

    fn now() -> u64 {
        SystickBackend::now()
    }

    fn set_compare(at: u64) {
        critical_section::with(|cs| NEXT_TICK.borrow(cs).set(at));
    }

    fn clear_compare_flag() {}

    fn pend_interrupt() {
        cortex_m::peripheral::SCB::set_pendst();
    }

    fn on_interrupt() {}

    fn enable_timer() {}

    fn disable_timer() {
        critical_section::with(|cs| NEXT_TICK.borrow(cs).set(u64::MAX));
    }

    fn timer_queue() -> &'static TimerQueue<Self> {
        &APP_QUEUE
    }
}

/// Starts SysTick at one tick per [`TICK_US`] and both queues.
pub(super) fn start(syst: SYST, core_clock_hz: u32) {
    SystickBackend::_start(
        syst,
        core_clock_hz,
        (1_000_000 / TICK_US) as u32,
        SystClkSource::Core,
    );
    APP_QUEUE.initialize(AppTimer);
}

/// The apps' earliest deadline in µs (`u64::MAX`: none). A queue whose head changed pends SysTick,
/// which updates it, so it is current unless SysTick is pending.
pub(super) fn next_deadline_us() -> u64 {
    critical_section::with(|cs| NEXT_TICK.borrow(cs).get()).saturating_mul(TICK_US)
}

#[no_mangle]
#[allow(non_snake_case)]
unsafe extern "C" fn SysTick() {
    // SAFETY: called only from the SysTick exception, which drives both queues.
    unsafe {
        SystickBackend::timer_queue().on_monotonic_interrupt();
        APP_QUEUE.on_monotonic_interrupt();
    }
}
