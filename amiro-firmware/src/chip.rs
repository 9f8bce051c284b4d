//! The chip-family differences the runtime needs, and the clock-tree reset every board runs first.
//!
//! Register addresses from RM0008 (F1) and RM0090 (F4). Only what differs between the families is
//! here; the bxCAN block, the IWDG and the core peripherals sit at the same place on both.

/// RCC base address.
#[cfg(feature = "f1")]
const RCC: usize = 0x4002_1000;
#[cfg(feature = "f4")]
const RCC: usize = 0x4002_3800;
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
/// RCC_APB2RSTR / RCC_APB2ENR offsets (SPI1 is bit 12 in both, on both families).
#[cfg(feature = "f1")]
const RCC_APB2RSTR: usize = 0x0C;
#[cfg(feature = "f4")]
const RCC_APB2RSTR: usize = 0x24;
#[cfg(feature = "f1")]
const RCC_APB2ENR: usize = 0x18;
#[cfg(feature = "f4")]
const RCC_APB2ENR: usize = 0x44;
const APB2_SPI1: u32 = 1 << 12;

/// The RCC block of this chip, for the clock-tree routines.
fn rcc() -> crate::bxcan::Mmio {
    // SAFETY: the RCC block of this chip family; the clock routines run from `init` only, before
    // anything else uses the RCC (the `Registers` accesses are volatile single-register ones).
    unsafe { crate::bxcan::Mmio::new(RCC) }
}

pub use crate::clock_tree::{ClockFault, CLOCK_POLLS};

/// The flash interface's base address (FLASH_ACR at offset 0 on both families).
#[cfg(feature = "f1")]
const FLASH_IF: usize = 0x4002_2000;
#[cfg(feature = "f4")]
const FLASH_IF: usize = 0x4002_3C00;

fn flash_interface() -> crate::bxcan::Mmio {
    // SAFETY: the flash interface of this chip family; only `clock_plan` writes its ACR, from
    // `init`, before anything else runs.
    unsafe { crate::bxcan::Mmio::new(FLASH_IF) }
}

/// Where SYSCLK comes from after [`clock_plan`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ClockSource {
    /// The PLL from the 8 MHz crystal: the board's design clock.
    Crystal,
    /// The PLL from the internal RC oscillator (the crystal did not start): the design clock
    /// (F4) or 64 MHz (F1), less precise.
    InternalPll,
    /// The internal RC oscillator without the PLL (the PLL did not lock): slow and imprecise,
    /// but the board runs, reports, and its CAN keeps 1 Mbit/s.
    Internal,
    /// The clock-tree reset did not complete, but SYSCLK still runs from the crystal's locked PLL
    /// as AMiRo-BLT set it up (its design clock): the board keeps it without touching the PLL.
    AsLeft,
}

impl ClockSource {
    /// The source in words, for the log.
    pub const fn as_str(self) -> &'static str {
        match self {
            ClockSource::Crystal => "PLL from the crystal",
            ClockSource::InternalPll => "PLL from the internal oscillator",
            ClockSource::Internal => "internal oscillator without PLL",
            ClockSource::AsLeft => "the clock AMiRo-BLT left",
        }
    }
}

/// The clock a board runs at after [`clock_plan`], and what its buses, timers and CAN get.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ClockPlan {
    /// Where SYSCLK comes from.
    pub source: ClockSource,
    /// SYSCLK = HCLK.
    pub sysclk_hz: u32,
    /// PCLK1 (APB1: CAN, I2C, TIM2..TIM5).
    pub pclk1_hz: u32,
    /// PCLK2 (APB2: SPI1, ADC).
    pub pclk2_hz: u32,
    /// The APB1 timer clock (2 × PCLK1 when APB1 is divided, else PCLK1).
    pub timer_hz: u32,
    /// CAN bit timing for 1 Mbit/s from this PCLK1.
    pub can_btr: u32,
}

impl ClockPlan {
    const fn new(
        source: ClockSource,
        sysclk_hz: u32,
        pclk1_hz: u32,
        pclk2_hz: u32,
        btr: u32,
    ) -> Self {
        Self {
            source,
            sysclk_hz,
            pclk1_hz,
            pclk2_hz,
            timer_hz: if pclk1_hz == sysclk_hz {
                pclk1_hz
            } else {
                2 * pclk1_hz
            },
            can_btr: btr,
        }
    }
}

/// F103: 72 MHz from the 8 MHz crystal (PLL ×9), APB1 and APB2 at 36 MHz.
#[cfg(feature = "f1")]
mod family {
    use super::{ClockPlan, ClockSource};
    use crate::clock_tree::PllSetup;

    pub const CFGR: usize = 0x04;
    /// 36 MHz APB1: 18 MHz quanta, 1 + 14 + 3 tq, sample point 83 % (the original firmware's).
    pub const CRYSTAL: ClockPlan = ClockPlan::new(
        ClockSource::Crystal,
        72_000_000,
        36_000_000,
        36_000_000,
        0x012D_0001,
    );
    /// HSI/2 × 16 = 64 MHz; 32 MHz APB1: 16 MHz quanta, 1 + 13 + 2 tq, sample point 87.5 %.
    pub const INTERNAL_PLL: ClockPlan = ClockPlan::new(
        ClockSource::InternalPll,
        64_000_000,
        32_000_000,
        32_000_000,
        0x001C_0001,
    );
    /// AMiRo-BLT's clock, which is the design clock.
    pub const AS_LEFT: ClockPlan = ClockPlan {
        source: ClockSource::AsLeft,
        ..CRYSTAL
    };
    /// HSI at 8 MHz on every bus: 8 tq of 125 ns, 1 + 5 + 2, sample point 75 %.
    pub const INTERNAL: ClockPlan = ClockPlan::new(
        ClockSource::Internal,
        8_000_000,
        8_000_000,
        8_000_000,
        0x0014_0000,
    );

    /// CFGR: PLLSRC (16), PLLXTPRE (17), PLLMUL (21:18); HPRE (7:4), PPRE1 (10:8), PPRE2 (13:11)
    /// with both APBs divided by 2; FLASH_ACR LATENCY (2:0) two wait states above 48 MHz.
    pub const fn pll(from_crystal: bool) -> PllSetup {
        PllSetup {
            pll_register: CFGR,
            pll: (
                0x003F_0000,
                if from_crystal {
                    1 << 16 | 0b0111 << 18
                } else {
                    0b1110 << 18
                },
            ),
            prescalers: (0x3FF0, 0b100 << 8 | 0b100 << 11),
            flash_acr: 0,
            latency: (0b111, 2),
        }
    }
}

/// F405: 168 MHz from either oscillator (PLL to 1 MHz, ×336, /2; 48 MHz on Q), APB1 42 MHz,
/// APB2 84 MHz.
#[cfg(feature = "f4")]
mod family {
    use super::{ClockPlan, ClockSource};
    use crate::clock_tree::PllSetup;

    pub const CFGR: usize = 0x08;
    /// 42 MHz APB1: 21 MHz quanta, 1 + 16 + 4 tq, sample point 81 % (the original firmware's).
    pub const CRYSTAL: ClockPlan = ClockPlan::new(
        ClockSource::Crystal,
        168_000_000,
        42_000_000,
        84_000_000,
        0x013F_0001,
    );
    /// The same frequencies from the 16 MHz HSI.
    pub const INTERNAL_PLL: ClockPlan = ClockPlan {
        source: ClockSource::InternalPll,
        ..CRYSTAL
    };
    /// AMiRo-BLT's clock, which is the design clock.
    pub const AS_LEFT: ClockPlan = ClockPlan {
        source: ClockSource::AsLeft,
        ..CRYSTAL
    };
    /// HSI at 16 MHz on every bus: 16 tq of 62.5 ns, 1 + 13 + 2, sample point 87.5 %.
    pub const INTERNAL: ClockPlan = ClockPlan::new(
        ClockSource::Internal,
        16_000_000,
        16_000_000,
        16_000_000,
        0x001C_0000,
    );

    /// PLLCFGR: PLLM (5:0), PLLN (14:6), PLLP (17:16), PLLSRC (22), PLLQ (27:24); CFGR: HPRE
    /// (7:4), PPRE1 (12:10) /4, PPRE2 (15:13) /2; FLASH_ACR: five wait states (168 MHz at 3.3 V),
    /// prefetch, instruction and data caches.
    pub const fn pll(from_crystal: bool) -> PllSetup {
        let m = if from_crystal { 8 } else { 16 };
        PllSetup {
            pll_register: 0x04,
            pll: (
                0x0F43_7FFF,
                m | 336 << 6 | (from_crystal as u32) << 22 | 7 << 24,
            ),
            prescalers: (0xFCF0, 0b101 << 10 | 0b100 << 13),
            flash_acr: 0,
            latency: (0x707, 0x705),
        }
    }
}

/// Resets the clock tree and starts the best clock this chip has, every wait bounded
/// ([`crate::clock_tree`]): the PLL from the crystal; from the internal oscillator when the crystal
/// does not start; the internal oscillator alone when the PLL does not lock. Every fault is
/// logged and counted for the diagnostics ([`crate::health::set_clock_fallback`]); the board goes on
/// with the plan's frequencies (bus prescalers, timer clock, CAN bit timing).
pub fn clock_plan() -> ClockPlan {
    use crate::clock_tree;
    let rcc = rcc();
    let plan = 'plan: {
        if let Err(fault) = clock_tree::to_reset_state(&rcc, family::CFGR) {
            crate::log!("clock: reset: ", fault.as_str());
            if clock_tree::running_on_crystal_pll(&rcc, family::CFGR) {
                break 'plan family::AS_LEFT;
            }
            if !clock_tree::in_reset_state(&rcc, family::CFGR) {
                // Neither the reset state nor a running PLL: no frequency can be trusted, so
                // nothing (CAN bit timing, bus dividers) could be set up right. Stop safely; the
                // watchdog hands the board back to AMiRo-BLT.
                crate::log!("clock: the tree is in no known state; stopping");
                crate::fault::halt();
            }
        }
        let crystal = match clock_tree::start_crystal(&rcc) {
            Ok(()) => true,
            Err(fault) => {
                crate::log!("clock: ", fault.as_str());
                false
            }
        };
        match clock_tree::start_pll(
            &rcc,
            &flash_interface(),
            family::CFGR,
            &family::pll(crystal),
        ) {
            Ok(()) if crystal => family::CRYSTAL,
            Ok(()) => family::INTERNAL_PLL,
            Err(fault) => {
                crate::log!("clock: ", fault.as_str());
                family::INTERNAL
            }
        }
    };
    crate::log!("clock: running on ", plan.source.as_str());
    if plan.sysclk_hz != family::CRYSTAL.sysclk_hz {
        crate::tracing::hello(plan.sysclk_hz);
    }
    crate::health::set_clock_fallback(plan.source != ClockSource::Crystal);
    plan
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

/// Resets SPI1 and enables its clock (the runtime's `spi::Master` takes it from there): called
/// from `init` by the boards that drive a device on SPI1.
pub fn reset_and_enable_spi1() {
    rcc_modify(RCC_APB2RSTR, |r| r | APB2_SPI1);
    rcc_modify(RCC_APB2RSTR, |r| r & !APB2_SPI1);
    rcc_modify(RCC_APB2ENR, |r| r | APB2_SPI1);
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

/// GPIOC's input data register.
#[cfg(feature = "f1")]
const GPIOC_IDR: usize = 0x4001_1000 + 0x08;
#[cfg(feature = "f4")]
const GPIOC_IDR: usize = 0x4002_0800 + 0x10;
/// EXTI_PR, the pending register (offset 0x14 of EXTI on both families).
#[cfg(feature = "f1")]
const EXTI_PR: usize = 0x4001_0400 + 0x14;
#[cfg(feature = "f4")]
const EXTI_PR: usize = 0x4001_3C00 + 0x14;

/// Whether pin `PIN` of port C reads low (every board's SYS_PD_N is on port C).
pub fn port_c_reads_low<const PIN: u8>() -> bool {
    const { assert!(PIN < 16) };
    // SAFETY: a volatile read of GPIOC's input data register, which reading never changes.
    let idr = unsafe { core::ptr::read_volatile(GPIOC_IDR as *const u32) };
    idr & (1 << PIN) == 0
}

/// Clears the pending bit of EXTI line `LINE` (writing 1 clears that bit and no other).
pub fn clear_exti_pending<const LINE: u8>() {
    const { assert!(LINE < 16) };
    // SAFETY: a single write of EXTI_PR; its zero bits leave the other lines' pending bits as
    // they are.
    unsafe { core::ptr::write_volatile(EXTI_PR as *mut u32, 1 << LINE) };
}
