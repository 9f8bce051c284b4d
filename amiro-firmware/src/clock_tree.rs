//! The clock-tree steps every board runs first, over the RCC's registers (the F1 and F4 RCC share
//! the CR bits and the CFGR switch fields; only CFGR's offset differs, so the caller passes it).
//!
//! Every wait is bounded ([`CLOCK_POLLS`] reads): a crystal that never starts or a PLL that never
//! stops costs a logged fault and the internal oscillator, never a hung boot. Host-tested against a
//! model RCC (`tests/clock_tree.rs`); `chip` applies it to the chip's RCC.
use crate::bxcan::Registers;

const RCC_CR: usize = 0x00;
const CR_HSION: u32 = 1 << 0;
const CR_HSIRDY: u32 = 1 << 1;
const CR_HSEON: u32 = 1 << 16;
const CR_HSERDY: u32 = 1 << 17;
const CR_PLLON: u32 = 1 << 24;
const CR_PLLRDY: u32 = 1 << 25;
const CFGR_SW: u32 = 0b11;
const CFGR_SWS: u32 = 0b11 << 2;

/// How many times a clock flag is polled before the step is declared failed. HSI and PLL flags
/// settle within microseconds; the crystal within a few milliseconds (ST's HSE_STARTUP_TIMEOUT is
/// 100 ms, far more than this many reads take at 8 MHz).
pub const CLOCK_POLLS: u32 = 200_000;

/// A clock step that did not complete in [`CLOCK_POLLS`] reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ClockFault {
    /// The internal oscillator never reported ready.
    HsiNotReady,
    /// SYSCLK did not switch to the internal oscillator.
    SwitchToHsi,
    /// The PLL did not stop.
    PllStillRunning,
    /// The 8 MHz crystal did not start.
    HseNotReady,
}

impl ClockFault {
    /// The fault in words, for the log.
    pub const fn as_str(self) -> &'static str {
        match self {
            ClockFault::HsiNotReady => "the internal oscillator never got ready",
            ClockFault::SwitchToHsi => "SYSCLK did not switch to the internal oscillator",
            ClockFault::PllStillRunning => "the PLL did not stop",
            ClockFault::HseNotReady => "the crystal did not start",
        }
    }
}

fn modify(rcc: &impl Registers, offset: usize, f: impl FnOnce(u32) -> u32) {
    rcc.write(offset, f(rcc.read(offset)));
}

fn poll(done: impl Fn() -> bool, fault: ClockFault) -> Result<(), ClockFault> {
    if (0..CLOCK_POLLS).any(|_| done()) {
        Ok(())
    } else {
        Err(fault)
    }
}

/// Switches the clock tree back to the internal oscillator with the PLL off (`cfgr`: the offset
/// of RCC_CFGR, 0x04 on the F1, 0x08 on the F4).
///
/// AMiRo-BLT hands over with the PLL already driving SYSCLK; the PLL cannot be reconfigured while
/// it is the system clock, so every board starts from the reset state before its HAL sets the
/// clocks up.
pub fn to_reset_state(rcc: &impl Registers, cfgr: usize) -> Result<(), ClockFault> {
    modify(rcc, RCC_CR, |r| r | CR_HSION);
    poll(
        || rcc.read(RCC_CR) & CR_HSIRDY != 0,
        ClockFault::HsiNotReady,
    )?;
    modify(rcc, cfgr, |r| r & !CFGR_SW);
    poll(|| rcc.read(cfgr) & CFGR_SWS == 0, ClockFault::SwitchToHsi)?;
    modify(rcc, RCC_CR, |r| r & !CR_PLLON);
    poll(
        || rcc.read(RCC_CR) & CR_PLLRDY == 0,
        ClockFault::PllStillRunning,
    )
}

/// Starts the crystal oscillator and waits (bounded) for it to report ready.
pub fn start_crystal(rcc: &impl Registers) -> Result<(), ClockFault> {
    modify(rcc, RCC_CR, |r| r | CR_HSEON);
    poll(
        || rcc.read(RCC_CR) & CR_HSERDY != 0,
        ClockFault::HseNotReady,
    )
}
