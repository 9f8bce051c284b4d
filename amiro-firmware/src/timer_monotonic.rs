//! The microsecond monotonic of every board on the real chips: one general-purpose timer (TIM2–TIM5,
//! the same registers at the same offsets on the F103 and the F405) counting 16 bits, extended to
//! 64 bits by a half-period counter (rtic-time's race-free scheme: the compare on channel 1 at
//! `0x8000` ends the lower half of a period, the update at the wrap ends the upper half); channel 2
//! is the timer queue's compare. A board picks its timer with `timer_monotonic!`:
//! DiWheelDrive TIM5 (TIM2–TIM4 drive its motors and count its encoders), LightRing TIM3,
//! PowerManagement TIM2. The timer claims no pin: its channels only compare, their outputs stay off.
//!
//! Why not rtic-monotonics' STM32 backends: they leave ARR at its reset value (`0xFFFF` on a chip,
//! `0` in QEMU's timer model, which then never runs), and they panic on an update that does not
//! alternate with the half-period compare ("Monotonic must have missed an interrupt!"). Here an
//! event that goes missing — on a chip only if the monotonic's interrupt is held off for half a
//! period (32.8 ms at 1 MHz), in QEMU always, as its timer model has no compare channels — is
//! counted, reported once on the log (by the watchdog task, [`HalfPeriods::take_report`]), and the
//! time goes on from the events that did come ([`advance`]); a fault is reported, not turned into a
//! reset loop.
//!
//! The event accounting and the register sequences are plain functions over
//! [`crate::bxcan::Registers`], tested on the host against a model timer
//! (`tests/timer_monotonic.rs`); the chip glue is the macro.
use core::sync::atomic::{AtomicU32, Ordering};

use crate::bxcan::Registers;

/// Monotonic tick rate: one tick per microsecond.
pub const TICK_HZ: u32 = 1_000_000;

const CR1: usize = 0x00;
const DIER: usize = 0x0C;
const SR: usize = 0x10;
const EGR: usize = 0x14;
const CNT: usize = 0x24;
const PSC: usize = 0x28;
const ARR: usize = 0x2C;
const CCR1: usize = 0x34;
const CCR2: usize = 0x38;
const CR1_CEN: u32 = 1 << 0;
const DIER_UIE: u32 = 1 << 0;
const DIER_CC1IE: u32 = 1 << 1;
const DIER_CC2IE: u32 = 1 << 2;
const SR_UIF: u32 = 1 << 0;
const SR_CC1IF: u32 = 1 << 1;
const SR_CC2IF: u32 = 1 << 2;
const EGR_UG: u32 = 1 << 0;
/// Where channel 1 marks the half period.
const HALF_PERIOD: u32 = 0x8000;

/// The half periods counted so far, and the events that went missing. `repr(C)`: the count is the
/// first word, where `cargo xtask smoke` reads it out of the emulated RAM.
#[repr(C)]
pub struct HalfPeriods {
    count: AtomicU32,
    missed: AtomicU32,
    /// The first event that went missing, until reported ([`HalfPeriods::take_report`]): 0 none,
    /// 1 a half-period compare, 2 an update.
    unreported: AtomicU32,
}

impl HalfPeriods {
    /// None yet.
    pub const fn new() -> Self {
        Self {
            count: AtomicU32::new(0),
            missed: AtomicU32::new(0),
            unreported: AtomicU32::new(0),
        }
    }

    /// Half periods since the start (even: the counter is in the lower half of its period).
    pub fn count(&self) -> u32 {
        self.count.load(Ordering::Relaxed)
    }

    /// Timer events that went missing since the start.
    pub fn missed(&self) -> u32 {
        self.missed.load(Ordering::Relaxed)
    }

    /// The first event that went missing, once: reported by a task (the watchdog's, through
    /// `mono::Clock::take_fault_report`), not by the timer's interrupt, which only counts it.
    pub fn take_report(&self) -> Option<Missed> {
        match self.unreported.swap(0, Ordering::Relaxed) {
            1 => Some(Missed::HalfPeriodCompare),
            2 => Some(Missed::Update),
            _ => None,
        }
    }
}

impl Default for HalfPeriods {
    fn default() -> Self {
        Self::new()
    }
}

/// Which event of a period did not come.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Missed {
    /// The half-period compare (channel 1) before an update.
    HalfPeriodCompare,
    /// The update (the wrap) before a half-period compare.
    Update,
}

impl Missed {
    /// The log line that reports it.
    pub const fn report(self) -> &'static str {
        match self {
            Missed::HalfPeriodCompare => {
                "monotonic: a half-period compare event went missing; time goes on from the updates"
            }
            Missed::Update => {
                "monotonic: an update event went missing; time goes on from the half-period compares"
            }
        }
    }
}

/// The half-period count after the events `update` (the wrap) and `half` (the compare at
/// `0x8000`) seen in one interrupt, from `count`, and the first event that went missing. An even
/// count waits for the compare, an odd one for the update; both pending are taken in that order
/// (two half periods). An event that comes where the other was due means the other went missing:
/// the count skips it (two half periods), so the parity keeps telling the counter's half. No loop:
/// the timer's interrupt runs it once per interrupt, and its bound is the longer of two
/// straight-line paths.
pub fn advance(count: u32, update: bool, half: bool) -> (u32, Option<Missed>) {
    let due_is_half = count & 1 == 0;
    let (due, other) = if due_is_half {
        (half, update)
    } else {
        (update, half)
    };
    let step = match (due, other) {
        (false, false) => 0,
        (true, false) => 1,
        // Both in their order, or the other alone: the one due went missing.
        (_, true) => 2,
    };
    let missed = (other && !due).then_some(if due_is_half {
        Missed::HalfPeriodCompare
    } else {
        Missed::Update
    });
    (count.wrapping_add(step), missed)
}

/// Time in ticks from the half periods counted and the counter's 16 bits, as rtic-time's
/// `half_period_counter::calculate_now` (the backend's `now`) computes it, the counter read after
/// the count. An even count
/// means the lower half of a period: the counter's value adds to it as it is; an odd count means
/// the upper half: a counter already wrapped (below `0x8000`) is the next period's. Exact while the
/// counter read is within one half period of the count's.
pub const fn now_from(half_periods: u32, counter: u16) -> u64 {
    let upper = (half_periods as u64) << 15;
    let lower = upper & (1 << 15);
    upper + (lower ^ counter as u64)
}

/// Starts the timer at [`TICK_HZ`] from a `timer_clock_hz` input (its bus clock on, its interrupt
/// not yet unmasked): prescaler, a 16-bit period (ARR written: the chip's reset value, but a
/// 32-bit TIM2/TIM5 on the F405 would otherwise count 32 bits, and QEMU's model starts at 0), the
/// half-period compare, the update and compare-1 interrupts, counter at 1 (so the first event is
/// the compare), flags cleared, then enabled.
pub fn start<R: Registers>(regs: &R, counter: &HalfPeriods, timer_clock_hz: u32) {
    regs.write(CR1, 0);
    let psc = (timer_clock_hz / TICK_HZ).saturating_sub(1).min(0xFFFF);
    regs.write(PSC, psc);
    regs.write(ARR, 0xFFFF);
    regs.write(CCR1, HALF_PERIOD);
    regs.write(DIER, DIER_UIE | DIER_CC1IE);
    regs.write(EGR, EGR_UG);
    regs.write(CNT, 1);
    regs.write(SR, 0);
    counter.count.store(0, Ordering::SeqCst);
    counter.missed.store(0, Ordering::SeqCst);
    regs.write(CR1, CR1_CEN);
}

/// The timer's interrupt: clears the timer-queue compare flag (before the queue is looked at, so a
/// compare that matches while it is sets it again) and takes the update and half-period flags,
/// in one write (the status bits are write-0-to-clear: only those three), and counts them; an
/// event that went missing is counted, and the first one kept for [`HalfPeriods::take_report`].
/// Nothing else writes the counts (a load and a store each, no exclusive access).
pub fn on_interrupt<R: Registers>(regs: &R, counter: &HalfPeriods) {
    let sr = regs.read(SR);
    let taken = sr & (SR_UIF | SR_CC1IF);
    regs.write(SR, !(taken | SR_CC2IF) & 0xFFFF);
    if taken == 0 {
        return;
    }
    let (count, missed) = advance(counter.count(), taken & SR_UIF != 0, taken & SR_CC1IF != 0);
    counter.count.store(count, Ordering::Relaxed);
    if let Some(missed) = missed {
        let before = counter.missed();
        counter
            .missed
            .store(before.wrapping_add(1), Ordering::Relaxed);
        if before == 0 {
            let code = match missed {
                Missed::HalfPeriodCompare => 1,
                Missed::Update => 2,
            };
            counter.unreported.store(code, Ordering::Relaxed);
        }
    }
}

/// Time in ticks read in the timer's own interrupt: the count and the counter without a critical
/// section, as nothing that changes the count (this interrupt, at the highest priority) can run
/// between the two reads there. Elsewhere the backend's `now` reads them with interrupts masked.
pub fn now_in_interrupt<R: Registers>(regs: &R, counter: &HalfPeriods) -> u64 {
    let count = counter.count();
    core::sync::atomic::compiler_fence(Ordering::Acquire);
    now_from(count, self::counter(regs))
}

/// The counter's 16 bits.
pub fn counter<R: Registers>(regs: &R) -> u16 {
    regs.read(CNT) as u16
}

/// Sets the timer-queue compare (channel 2) for `instant` as seen at `now` (read in this
/// interrupt): a target more than one counter period away fires at the next wrap, where the queue
/// looks again. `true` if the counter, read after the write, had already reached `instant`: its
/// match may be gone by, and the interrupt must look again (the ticks since `now` fit the counter's
/// 16 bits, as the interrupt runs far less than a period).
pub fn set_compare<R: Registers>(regs: &R, instant: u64, now: u64) -> bool {
    let ahead = instant.wrapping_sub(now);
    if ahead > 0xFFFF {
        regs.write(CCR2, 0);
        return false;
    }
    regs.write(CCR2, u32::from(instant as u16));
    let since = counter(regs).wrapping_sub(now as u16);
    u64::from(since) >= ahead
}

/// Turns the timer-queue compare interrupt on or off: one write, the period events' interrupts
/// staying on (nothing else writes DIER after [`start`]).
pub fn set_compare_interrupt<R: Registers>(regs: &R, on: bool) {
    let compare = if on { DIER_CC2IE } else { 0 };
    regs.write(DIER, DIER_UIE | DIER_CC1IE | compare);
}

/// Declares `$backend`, the timer-queue backend of the general-purpose timer at `$base` whose
/// interrupt is `$interrupt` (a PAC `Interrupt` variant whose vector is named `$vector`), with its
/// half-period counter in a static named `HALF_PERIODS`, and binds the vector. The board turns the
/// timer's bus clock on, then calls `$backend::start(timer_clock_hz, priority)`.
#[cfg(target_os = "none")]
#[macro_export]
macro_rules! timer_monotonic {
    ($backend:ident, $base:expr, $interrupt:expr, $vector:ident) => {
        /// The timer-queue backend of this board's monotonic timer.
        pub struct $backend;

        static HALF_PERIODS: $crate::timer_monotonic::HalfPeriods =
            $crate::timer_monotonic::HalfPeriods::new();
        static QUEUE: $crate::timer_queue::TimerQueue<$backend> =
            $crate::timer_queue::TimerQueue::new();

        impl $backend {
            fn regs() -> $crate::bxcan::Mmio {
                // SAFETY: the timer at `$base` belongs to this backend from `start` on; nothing
                // else touches its registers.
                unsafe { $crate::bxcan::Mmio::new($base) }
            }

            /// Starts the timer from a `timer_clock_hz` input (its bus clock already on) and
            /// unmasks its interrupt at RTIC `priority` (the highest in the system).
            pub fn start(timer_clock_hz: u32, priority: u8) {
                $crate::timer_monotonic::start(&Self::regs(), &HALF_PERIODS, timer_clock_hz);
                // SAFETY: only this interrupt's priority changes, before any task uses the clock.
                unsafe {
                    let mut core = $crate::__cortex_m::Peripherals::steal();
                    core.NVIC
                        .set_priority($interrupt, $crate::timer_monotonic::nvic_priority(priority));
                    $crate::__cortex_m::peripheral::NVIC::unmask($interrupt);
                }
            }

            /// Half periods and missed events so far.
            pub fn half_periods() -> &'static $crate::timer_monotonic::HalfPeriods {
                &HALF_PERIODS
            }
        }

        impl $crate::timer_queue::Backend for $backend {
            fn now() -> u64 {
                $crate::__rtic_time::half_period_counter::calculate_now(
                    || HALF_PERIODS.count(),
                    || $crate::timer_monotonic::counter(&Self::regs()),
                )
            }

            fn now_in_interrupt() -> u64 {
                $crate::timer_monotonic::now_in_interrupt(&Self::regs(), &HALF_PERIODS)
            }

            fn set_compare(at: u64, now: u64) -> bool {
                let regs = Self::regs();
                $crate::timer_monotonic::set_compare_interrupt(&regs, true);
                $crate::timer_monotonic::set_compare(&regs, at, now)
            }

            fn disable_compare() {
                $crate::timer_monotonic::set_compare_interrupt(&Self::regs(), false);
            }

            fn pend_interrupt() {
                $crate::__cortex_m::peripheral::NVIC::pend($interrupt);
            }

            fn queue() -> &'static $crate::timer_queue::TimerQueue<Self> {
                &QUEUE
            }

            fn take_fault_report() -> Option<&'static str> {
                HALF_PERIODS
                    .take_report()
                    .map($crate::timer_monotonic::Missed::report)
            }
        }

        #[allow(non_snake_case)]
        #[no_mangle]
        unsafe extern "C" fn $vector() {
            $crate::timer_monotonic::on_interrupt(&$backend::regs(), &HALF_PERIODS);
            // SAFETY: this timer's vector, at the highest priority: nothing that touches the
            // queue pre-empts it.
            unsafe { QUEUE.on_interrupt() };
        }
    };
}

/// The NVIC's encoding of RTIC's logical `priority` (1 = least urgent) on both chips, which
/// implement 4 priority bits.
pub const fn nvic_priority(priority: u8) -> u8 {
    const BITS: u8 = 4;
    ((1 << BITS) - priority) << (8 - BITS)
}
