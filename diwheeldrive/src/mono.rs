//! DiWheelDrive's microsecond monotonic on the real chip: TIM5, a 16-bit timer extended to 64 bits.
//!
//! rtic-monotonics offers TIM3 on this chip, but on DiWheelDrive TIM3 and TIM4 count the wheel
//! encoders and TIM2 drives the motors, so the monotonic lives on TIM5 — the timer the original
//! firmware also used for its OS tick. The 16-bit counter is extended to 64 bits with rtic-time's
//! race-free half-period counter (an interrupt at 0x0000 and one at 0x8000). The runtime's
//! `TimerClock` turns it into the `Clock` the tasks use (the QEMU build uses the runtime's SysTick).

use core::sync::atomic::{AtomicU32, Ordering};

use rtic_time::half_period_counter::calculate_now;
use rtic_time::timer_queue::{TimerQueue, TimerQueueBackend};
use stm32f1xx_hal::pac::{self, Interrupt, TIM5};

/// NVIC priority bits implemented on the STM32F1.
const NVIC_PRIO_BITS: u8 = 4;

/// Converts an RTIC logical priority (1 = least urgent) to the NVIC's hardware encoding.
const fn hw_priority(logical: u8) -> u8 {
    ((1 << NVIC_PRIO_BITS) - logical) << (8 - NVIC_PRIO_BITS)
}

/// Monotonic tick rate: one tick per microsecond.
pub const TICK_HZ: u32 = 1_000_000;

static HALF_PERIODS: AtomicU32 = AtomicU32::new(0);
static QUEUE: TimerQueue<Tim5Backend> = TimerQueue::new();

/// The TIM5 backend of the timer queue.
pub struct Tim5Backend;

fn tim5() -> &'static pac::tim2::RegisterBlock {
    // SAFETY: TIM5 is owned by this module from `start` on (the PAC handle is consumed there);
    // its registers are only touched here.
    unsafe { &*TIM5::ptr() }
}

impl Tim5Backend {
    /// Starts TIM5 at [`TICK_HZ`] from a `timer_clock_hz` input clock and unmasks its interrupt at
    /// `priority` (must be the highest priority in the system that masks for long, see module docs).
    pub fn start(_tim5: TIM5, rcc: &pac::rcc::RegisterBlock, timer_clock_hz: u32, priority: u8) {
        rcc.apb1enr().modify(|_, w| w.tim5en().set_bit());
        rcc.apb1rstr().modify(|_, w| w.tim5rst().set_bit());
        rcc.apb1rstr().modify(|_, w| w.tim5rst().clear_bit());
        let t = tim5();
        t.cr1().modify(|_, w| w.cen().clear_bit());
        let psc = (timer_clock_hz / TICK_HZ).saturating_sub(1) as u16;
        t.psc().write(|w| w.psc().set(psc));
        t.arr().write(|w| w.arr().set(0xFFFF));
        // Compare channel 1 marks the half period, channel 2 is the timer-queue compare.
        t.ccr(0).write(|w| w.ccr().set(0x8000));
        t.dier().modify(|_, w| w.uie().set_bit().cc1ie().set_bit());
        t.egr().write(|w| w.ug().set_bit());
        t.cnt().write(|w| w.cnt().set(1));
        t.sr().write(|w| unsafe { w.bits(0) });
        QUEUE.initialize(Tim5Backend);
        HALF_PERIODS.store(0, Ordering::SeqCst);
        t.cr1().modify(|_, w| w.cen().set_bit());
        // SAFETY: only the priority of TIM5 is changed, before any task uses the monotonic.
        unsafe {
            let mut nvic = cortex_m::Peripherals::steal().NVIC;
            nvic.set_priority(Interrupt::TIM5, hw_priority(priority));
            cortex_m::peripheral::NVIC::unmask(Interrupt::TIM5);
        }
    }
}

impl TimerQueueBackend for Tim5Backend {
    type Ticks = u64;

    fn now() -> u64 {
        calculate_now(
            || HALF_PERIODS.load(Ordering::Relaxed),
            || tim5().cnt().read().cnt().bits(),
        )
    }

    fn set_compare(instant: u64) {
        let now = Self::now();
        // A target more than one counter period away (or in the past) fires at the next wrap,
        // where the queue re-arms it.
        let value = if instant.wrapping_sub(now) <= 0xFFFF {
            instant as u16
        } else {
            0
        };
        tim5().ccr(1).write(|w| w.ccr().set(value));
    }

    fn clear_compare_flag() {
        tim5()
            .sr()
            .write(|w| unsafe { w.bits(!0) }.cc2if().clear_bit());
    }

    fn pend_interrupt() {
        cortex_m::peripheral::NVIC::pend(Interrupt::TIM5);
    }

    fn enable_timer() {
        tim5().dier().modify(|_, w| w.cc2ie().set_bit());
    }

    fn disable_timer() {
        tim5().dier().modify(|_, w| w.cc2ie().clear_bit());
    }

    fn on_interrupt() {
        let t = tim5();
        if t.sr().read().uif().bit_is_set() {
            t.sr().write(|w| unsafe { w.bits(!0) }.uif().clear_bit());
            HALF_PERIODS.fetch_add(1, Ordering::Relaxed);
        }
        if t.sr().read().cc1if().bit_is_set() {
            t.sr().write(|w| unsafe { w.bits(!0) }.cc1if().clear_bit());
            HALF_PERIODS.fetch_add(1, Ordering::Relaxed);
        }
    }

    fn timer_queue() -> &'static TimerQueue<Self> {
        &QUEUE
    }
}

#[allow(non_snake_case)]
#[no_mangle]
unsafe extern "C" fn TIM5() {
    // SAFETY: called only from the TIM5 vector, as the timer queue requires.
    unsafe { Tim5Backend::timer_queue().on_monotonic_interrupt() };
}

/// The board's clock: TIM5 ticks are microseconds.
pub type Clock = amiro_firmware::mono::TimerClock<Tim5Backend, 1>;
