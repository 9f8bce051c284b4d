//! The chip-family differences the runtime needs, and the clock-tree reset every board runs first.
//!
//! Register addresses from RM0008 (F1) and RM0090 (F4). Only what differs between the families is
//! here; the bxCAN block, the IWDG and the core peripherals sit at the same place on both.

/// RCC base address.
#[cfg(feature = "f1")]
const RCC: usize = 0x4002_1000;
#[cfg(feature = "f4")]
const RCC: usize = 0x4002_3800;
/// RCC_CFGR offset.
#[cfg(feature = "f1")]
const RCC_CFGR: usize = 0x04;
#[cfg(feature = "f4")]
const RCC_CFGR: usize = 0x08;
/// RCC_CSR offset (reset flags).
#[cfg(feature = "f1")]
const RCC_CSR: usize = 0x24;
#[cfg(feature = "f4")]
const RCC_CSR: usize = 0x74;

/// RCC_APB1RSTR / RCC_APB1ENR offsets (CAN1 is bit 25 in both, on both families).
#[cfg(feature = "f1")]
const RCC_APB1RSTR: usize = 0x10;
#[cfg(feature = "f4")]
const RCC_APB1RSTR: usize = 0x20;
#[cfg(feature = "f1")]
const RCC_APB1ENR: usize = 0x1C;
#[cfg(feature = "f4")]
const RCC_APB1ENR: usize = 0x40;
const APB1_CAN1: u32 = 1 << 25;

/// The RCC block of this chip, for the clock-tree routines.
fn rcc() -> crate::bxcan::Mmio {
    // SAFETY: the RCC block of this chip family; the clock routines run from `init` only, before
    // anything else uses the RCC (the `Registers` accesses are volatile single-register ones).
    unsafe { crate::bxcan::Mmio::new(RCC) }
}

pub use crate::clock_tree::{ClockFault, CLOCK_POLLS};

/// Switches the clock tree back to the internal oscillator with the PLL off
/// ([`crate::clock_tree::to_reset_state`] on this chip's RCC). Every wait is bounded.
pub fn clock_tree_to_reset_state() -> Result<(), ClockFault> {
    crate::clock_tree::to_reset_state(&rcc(), RCC_CFGR)
}

/// Starts the crystal oscillator and waits (bounded) for it ([`crate::clock_tree::start_crystal`]
/// on this chip's RCC). A board whose crystal does not start runs from the internal oscillator
/// instead (and logs the fault) rather than hang in its HAL's unbounded wait.
pub fn start_crystal() -> Result<(), ClockFault> {
    crate::clock_tree::start_crystal(&rcc())
}

fn rcc_read(offset: usize) -> u32 {
    // SAFETY: a register of the RCC block of this chip family.
    unsafe { core::ptr::read_volatile((RCC + offset) as *const u32) }
}

fn rcc_modify(offset: usize, f: impl FnOnce(u32) -> u32) {
    let value = f(rcc_read(offset));
    // SAFETY: as in `rcc_read`; called from `init` only, before anything else uses the RCC.
    unsafe { core::ptr::write_volatile((RCC + offset) as *mut u32, value) }
}

/// Why the chip last reset, from the RCC's reset flags (which it then clears, so the next reset
/// reports only its own cause). Read once, first thing in `init`. The QEMU machines emulate no RCC:
/// there it reports nothing.
pub fn take_reset_cause() -> amiro_can::ResetCause {
    use amiro_can::ResetCause;
    if cfg!(feature = "qemu") {
        return ResetCause::NONE;
    }
    let csr = rcc_read(RCC_CSR);
    let mut cause = ResetCause::NONE;
    for (bit, flag) in [
        (31, ResetCause::LOW_POWER),
        (30, ResetCause::WINDOW_WATCHDOG),
        (29, ResetCause::INDEPENDENT_WATCHDOG),
        (28, ResetCause::SOFTWARE),
        (27, ResetCause::POWER_ON),
        (26, ResetCause::PIN),
        (25, ResetCause::BROWN_OUT),
    ] {
        if csr & (1 << bit) != 0 {
            cause = cause.with(flag);
        }
    }
    // RMVF clears the flags.
    rcc_modify(RCC_CSR, |r| r | (1 << 24));
    cause
}

/// Resets CAN1 (nothing of AMiRo-BLT's filters, modes or pending mailboxes survives) and enables its
/// clock. Every board calls it in `init`, before `bxcan::bring_up`.
pub fn reset_and_enable_can1() {
    if cfg!(feature = "qemu") {
        return;
    }
    rcc_modify(RCC_APB1RSTR, |r| r | APB1_CAN1);
    rcc_modify(RCC_APB1RSTR, |r| r & !APB1_CAN1);
    rcc_modify(RCC_APB1ENR, |r| r | APB1_CAN1);
}

/// The clock plan of an F103 board: 72 MHz from the 8 MHz crystal, or 64 MHz from the internal
/// oscillator when the crystal does not start (bounded wait, logged as a fault), with the CAN bit
/// timing that gives 1 Mbit/s from either APB1.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct F1ClockPlan {
    /// Whether the crystal runs.
    pub on_crystal: bool,
    /// SYSCLK = HCLK.
    pub sysclk_hz: u32,
    /// PCLK1 = PCLK2.
    pub pclk_hz: u32,
    /// The APB1 timer clock (2 × PCLK1).
    pub timer_hz: u32,
    /// CAN bit timing for this PCLK1.
    pub can_btr: u32,
}

/// 36 MHz APB1: 18 MHz quanta, 1 + 14 + 3 tq, sample point 83 % (the original firmware's).
pub const F1_CAN_BTR: u32 = 0x012D_0001;
/// 32 MHz APB1: 16 MHz quanta, 1 + 13 + 2 tq, sample point 87.5 %.
pub const F1_CAN_BTR_HSI: u32 = 0x001C_0001;

/// Resets the clock tree, starts the crystal and chooses the F103 clock plan (logging faults).
pub fn f1_clock_plan() -> F1ClockPlan {
    if let Err(fault) = clock_tree_to_reset_state() {
        crate::log!(
            "clock reset: ",
            fault.as_str(),
            " (continuing on the clock AMiRo-BLT left)"
        );
    }
    if start_crystal().is_ok() {
        F1ClockPlan {
            on_crystal: true,
            sysclk_hz: 72_000_000,
            pclk_hz: 36_000_000,
            timer_hz: 72_000_000,
            can_btr: F1_CAN_BTR,
        }
    } else {
        crate::log!("fault: the 8 MHz crystal did not start; running from HSI at 64 MHz");
        crate::tracing::hello(64_000_000);
        F1ClockPlan {
            on_crystal: false,
            sysclk_hz: 64_000_000,
            pclk_hz: 32_000_000,
            timer_hz: 64_000_000,
            can_btr: F1_CAN_BTR_HSI,
        }
    }
}
