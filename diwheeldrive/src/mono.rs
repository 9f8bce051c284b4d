//! DiWheelDrive's microsecond monotonic on the real chip: TIM5, through the runtime's
//! half-period timer backend (`amiro_firmware::timer_monotonic`).
//!
//! rtic-monotonics offers TIM3 on this chip, but on DiWheelDrive TIM3 and TIM4 count the wheel
//! encoders and TIM2 drives the motors, so the monotonic lives on TIM5 — the timer the original
//! firmware also used for its OS tick. The runtime's `TimerClock` turns it into the `Clock` the
//! tasks use (the QEMU build uses the runtime's SysTick).
use stm32f1xx_hal::pac::{self, Interrupt};

/// TIM5's registers (RM0008 §2.3: the same general-purpose block as TIM2–TIM4).
const TIM5_BASE: usize = 0x4000_0C00;

amiro_firmware::timer_monotonic!(Tim5Backend, TIM5_BASE, Interrupt::TIM5, TIM5);

/// Turns TIM5's clock on and starts it from a `timer_clock_hz` input, its interrupt at `priority`.
pub fn start(rcc: &pac::rcc::RegisterBlock, timer_clock_hz: u32, priority: u8) {
    rcc.apb1enr().modify(|_, w| w.tim5en().set_bit());
    rcc.apb1rstr().modify(|_, w| w.tim5rst().set_bit());
    rcc.apb1rstr().modify(|_, w| w.tim5rst().clear_bit());
    Tim5Backend::start(timer_clock_hz, priority);
}

/// The board's clock: TIM5 ticks are microseconds.
pub type Clock = amiro_firmware::mono::TimerClock<Tim5Backend, 1>;
