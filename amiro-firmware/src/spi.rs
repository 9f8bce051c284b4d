//! A polled SPI master at register level for the SPI blocks of both chips (the F103's and the
//! F405's SPI1 are the same IP at the same address, RM0008 §25 / RM0090 §28), where every wait is
//! bounded: a byte that does not come back within [`POLLS`] reads of the status register is a
//! [`Error::Timeout`], never a hang.
//!
//! stm32f1xx-hal's SPI waits for TXE, RXNE and BSY without a bound (and panics on a rate above
//! PCLK / 2, which the internal-oscillator clock plan would ask for); on a working chip those flags
//! always come, but "always" is a property of a clocked, enabled block, and a bound makes it one
//! of the code. The block is the master with software slave management; chip selects are the
//! device wrappers' (embedded-hal-bus).
use embedded_hal::spi::{ErrorKind, ErrorType, Mode, Phase, Polarity, SpiBus};

use crate::bxcan::Registers;

/// SPI1's base address on both chips.
pub const SPI1: usize = 0x4001_3000;
/// Status-register reads before a flag counts as lost: a byte at the slowest divider (PCLK / 256)
/// takes 2048 PCLK cycles, and a read of the register takes at least one.
pub const POLLS: u32 = 20_000;

const CR1: usize = 0x00;
const CR2: usize = 0x04;
const SR: usize = 0x08;
const DR: usize = 0x0C;
const CR1_CPHA: u32 = 1 << 0;
const CR1_CPOL: u32 = 1 << 1;
const CR1_MSTR: u32 = 1 << 2;
const CR1_SPE: u32 = 1 << 6;
const CR1_SSI: u32 = 1 << 8;
const CR1_SSM: u32 = 1 << 9;
const SR_RXNE: u32 = 1 << 0;
const SR_TXE: u32 = 1 << 1;
const SR_MODF: u32 = 1 << 5;
const SR_OVR: u32 = 1 << 6;
const SR_BSY: u32 = 1 << 7;

/// What went wrong on the bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Error {
    /// A flag did not come within [`POLLS`] reads (block not clocked or not enabled).
    Timeout,
    /// Another master pulled NSS (cannot happen with software slave management; reported if it
    /// does).
    ModeFault,
    /// A received byte was overwritten before it was read.
    Overrun,
}

impl embedded_hal::spi::Error for Error {
    fn kind(&self) -> ErrorKind {
        match self {
            Error::Timeout => ErrorKind::Other,
            Error::ModeFault => ErrorKind::ModeFault,
            Error::Overrun => ErrorKind::Overrun,
        }
    }
}

/// The baud-rate code (PCLK / 2^(code + 1)) of the fastest rate not above `max_hz`.
pub const fn divider_code(pclk_hz: u32, max_hz: u32) -> u32 {
    let mut code = 0;
    while code < 7 && pclk_hz >> (code + 1) > max_hz {
        code += 1;
    }
    code
}

/// One SPI block as a bounded polled master, 8-bit frames, MSB first, over its registers
/// ([`crate::bxcan::Mmio`] on the chip — the block at [`SPI1`], its clock on, its pins set up —
/// a model in `tests/spi.rs`).
pub struct Master<R> {
    regs: R,
}

impl<R: Registers> Master<R> {
    /// Takes the block as the master in `mode`, at the fastest rate from a `pclk_hz` bus clock
    /// that is not above `max_hz`.
    pub fn new(regs: R, pclk_hz: u32, max_hz: u32, mode: Mode) -> Self {
        let master = Self { regs };
        let mut cr1 = CR1_MSTR | CR1_SSM | CR1_SSI | divider_code(pclk_hz, max_hz) << 3;
        if mode.polarity == Polarity::IdleHigh {
            cr1 |= CR1_CPOL;
        }
        if mode.phase == Phase::CaptureOnSecondTransition {
            cr1 |= CR1_CPHA;
        }
        master.set_register(CR1, 0);
        master.set_register(CR2, 0);
        master.set_register(CR1, cr1);
        master.set_register(CR1, cr1 | CR1_SPE);
        master
    }

    fn register(&self, offset: usize) -> u32 {
        self.regs.read(offset)
    }

    fn set_register(&self, offset: usize, value: u32) {
        self.regs.write(offset, value);
    }

    fn wait(&self, flag: u32) -> Result<(), Error> {
        for _ in 0..POLLS {
            let sr = self.register(SR);
            if sr & SR_MODF != 0 {
                // Reading SR then writing CR1 clears MODF; SPE must be set again.
                self.set_register(CR1, self.register(CR1) | CR1_SPE);
                return Err(Error::ModeFault);
            }
            if sr & SR_OVR != 0 {
                // Reading DR then SR clears OVR.
                let _ = self.register(DR);
                let _ = self.register(SR);
                return Err(Error::Overrun);
            }
            if sr & flag != 0 {
                return Ok(());
            }
        }
        Err(Error::Timeout)
    }

    fn exchange(&self, out: u8) -> Result<u8, Error> {
        self.wait(SR_TXE)?;
        self.set_register(DR, u32::from(out));
        self.wait(SR_RXNE)?;
        Ok(self.register(DR) as u8)
    }
}

impl<R> ErrorType for Master<R> {
    type Error = Error;
}

impl<R: Registers> SpiBus<u8> for Master<R> {
    fn read(&mut self, words: &mut [u8]) -> Result<(), Error> {
        for word in words.iter_mut() {
            *word = self.exchange(0)?;
        }
        Ok(())
    }

    fn write(&mut self, words: &[u8]) -> Result<(), Error> {
        for &word in words {
            self.exchange(word)?;
        }
        Ok(())
    }

    fn transfer(&mut self, read: &mut [u8], write: &[u8]) -> Result<(), Error> {
        for i in 0..read.len().max(write.len()) {
            let byte = self.exchange(write.get(i).copied().unwrap_or(0))?;
            if let Some(slot) = read.get_mut(i) {
                *slot = byte;
            }
        }
        Ok(())
    }

    fn transfer_in_place(&mut self, words: &mut [u8]) -> Result<(), Error> {
        for word in words.iter_mut() {
            *word = self.exchange(*word)?;
        }
        Ok(())
    }

    fn flush(&mut self) -> Result<(), Error> {
        for _ in 0..POLLS {
            if self.register(SR) & SR_BSY == 0 {
                return Ok(());
            }
        }
        Err(Error::Timeout)
    }
}

// Checked at every firmware build: 36 MHz → 9 MHz is /4, → 2.25 MHz is /16; 8 MHz → 9 MHz is /2.
const _: () = {
    assert!(divider_code(36_000_000, 9_000_000) == 1);
    assert!(divider_code(36_000_000, 2_250_000) == 3);
    assert!(divider_code(8_000_000, 9_000_000) == 0);
    assert!(divider_code(8_000_000, 2_250_000) == 1);
    assert!(divider_code(168_000_000, 1) == 7);
};
