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
    /// The flash did not take the wait states the faster clock needs.
    FlashLatency,
    /// The PLL did not lock.
    PllNotReady,
    /// SYSCLK did not switch to the PLL.
    SwitchToPll,
}

impl ClockFault {
    /// The fault in words, for the log.
    pub const fn as_str(self) -> &'static str {
        match self {
            ClockFault::HsiNotReady => "the internal oscillator never got ready",
            ClockFault::SwitchToHsi => "SYSCLK did not switch to the internal oscillator",
            ClockFault::PllStillRunning => "the PLL did not stop",
            ClockFault::HseNotReady => "the crystal did not start",
            ClockFault::FlashLatency => "the flash did not take its wait states",
            ClockFault::PllNotReady => "the PLL did not lock",
            ClockFault::SwitchToPll => "SYSCLK did not switch to the PLL",
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

/// Whether the tree is in the state [`to_reset_state`] leads to, whatever its ready flags said:
/// SYSCLK from the internal oscillator and the PLL off. A tree whose reset step failed but that
/// reads so (an RCC that never reports HSIRDY, as in QEMU) can still try the crystal and the PLL;
/// one that does not (SYSCLK still on the PLL) must not touch the PLL.
pub fn in_reset_state(rcc: &impl Registers, cfgr: usize) -> bool {
    rcc.read(cfgr) & CFGR_SWS == 0 && rcc.read(RCC_CR) & (CR_PLLON | CR_PLLRDY) == 0
}

/// Whether SYSCLK runs from a locked PLL with the crystal ready (as AMiRo-BLT hands over): a tree
/// whose reset failed can still be used as it is when this holds.
pub fn running_on_crystal_pll(rcc: &impl Registers, cfgr: usize) -> bool {
    let cr = rcc.read(RCC_CR);
    rcc.read(cfgr) & CFGR_SWS == 0b10 << 2 && cr & CR_PLLRDY != 0 && cr & CR_HSERDY != 0
}

/// Starts the crystal oscillator and waits (bounded) for it to report ready.
pub fn start_crystal(rcc: &impl Registers) -> Result<(), ClockFault> {
    modify(rcc, RCC_CR, |r| r | CR_HSEON);
    poll(
        || rcc.read(RCC_CR) & CR_HSERDY != 0,
        ClockFault::HseNotReady,
    )
}

/// What [`start_pll`] writes: the PLL's source and factors, the bus prescalers and the flash wait
/// states of the faster clock. Each is a (mask, value) pair over one register.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PllSetup {
    /// The offset of the RCC register that holds the PLL's source and factors (F1: CFGR 0x04,
    /// F4: PLLCFGR 0x04).
    pub pll_register: usize,
    /// The PLL source and factor bits in it, and their value.
    pub pll: (u32, u32),
    /// The AHB/APB prescaler bits in RCC_CFGR, and their value.
    pub prescalers: (u32, u32),
    /// The offset of FLASH_ACR in the flash interface's block (0 on both families).
    pub flash_acr: usize,
    /// The latency bits in FLASH_ACR, and the value the PLL's SYSCLK needs.
    pub latency: (u32, u32),
}

fn set_field(rcc: &impl Registers, offset: usize, (mask, value): (u32, u32)) {
    modify(rcc, offset, |r| r & !mask | value & mask);
}

/// Starts the PLL and makes it SYSCLK, every wait bounded. Runs from the reset state
/// ([`to_reset_state`], and [`start_crystal`] first when the PLL runs from the crystal).
///
/// On a fault the clock tree is left on the internal oscillator with the PLL off and the bus
/// prescalers at 1 (so every bus runs at the oscillator's frequency, which the caller's fallback
/// plan assumes); the higher flash latency stays, which is safe at any slower clock.
pub fn start_pll(
    rcc: &impl Registers,
    flash: &impl Registers,
    cfgr: usize,
    setup: &PllSetup,
) -> Result<(), ClockFault> {
    let result = try_start_pll(rcc, flash, cfgr, setup);
    if result.is_err() {
        modify(rcc, cfgr, |r| r & !CFGR_SW);
        set_field(rcc, cfgr, (setup.prescalers.0, 0));
        modify(rcc, RCC_CR, |r| r & !CR_PLLON);
        // Bounded as every other wait; if SYSCLK did not even come back the first fault is
        // still the one to report.
        let _ = poll(|| rcc.read(cfgr) & CFGR_SWS == 0, ClockFault::SwitchToHsi);
    }
    result
}

fn try_start_pll(
    rcc: &impl Registers,
    flash: &impl Registers,
    cfgr: usize,
    setup: &PllSetup,
) -> Result<(), ClockFault> {
    // The PLL's factors can only be written while it is off.
    if rcc.read(RCC_CR) & (CR_PLLON | CR_PLLRDY) != 0 {
        return Err(ClockFault::PllStillRunning);
    }
    set_field(rcc, setup.pll_register, setup.pll);
    // Slow buses first, then the wait states, then the fast clock.
    set_field(rcc, cfgr, setup.prescalers);
    set_field(flash, setup.flash_acr, setup.latency);
    let (mask, value) = setup.latency;
    poll(
        || flash.read(setup.flash_acr) & mask == value & mask,
        ClockFault::FlashLatency,
    )?;
    modify(rcc, RCC_CR, |r| r | CR_PLLON);
    poll(
        || rcc.read(RCC_CR) & CR_PLLRDY != 0,
        ClockFault::PllNotReady,
    )?;
    modify(rcc, cfgr, |r| r & !CFGR_SW | 0b10);
    poll(
        || rcc.read(cfgr) & CFGR_SWS == 0b10 << 2,
        ClockFault::SwitchToPll,
    )
}
