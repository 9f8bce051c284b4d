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
                // Reading SR then writing CR1 clears MODF; the fault cleared MSTR and SPE
                // (RM0008 §25.3.10): both are set again.
                self.set_register(CR1, self.register(CR1) | CR1_MSTR | CR1_SPE);
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
        self.wait_tx_empty()?;
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

// The transmit-only path and the device that uses it. Appended below the bus's own code, whose
// loops the boards' bounds files name by line (docs/analysis.md): DiWheelDrive's motion sensors
// keep the full-duplex exchange above, byte for byte as before.

use core::convert::Infallible;

use embedded_hal::digital::OutputPin;
use embedded_hal::spi::{Operation, SpiDevice};

/// CR1 DFF: 16-bit frames.
const CR1_DFF: u32 = 1 << 11;

impl<R: Registers> Master<R> {
    /// Waits for TXE (the transmit buffer free), or with `until_idle` for BSY clear (the last bit
    /// gone). An overrun is no error here: a transmit-only stream leaves every received byte
    /// unread, so OVR sets from its second byte on ([`Master::send`] clears it at the end).
    /// Inlined into the frame loop (no call and return a frame); the bounds file states its wait
    /// where it lands (LightRing: in the latch task's dispatcher): either flag comes within one
    /// frame time.
    #[inline(always)]
    fn wait_send(&self, until_idle: bool) -> Result<(), Error> {
        for _ in 0..POLLS {
            let sr = self.register(SR);
            if sr & SR_MODF != 0 {
                self.set_register(CR1, self.register(CR1) | CR1_MSTR | CR1_SPE);
                return Err(Error::ModeFault);
            }
            let done = if until_idle {
                sr & SR_BSY == 0
            } else {
                sr & SR_TXE != 0
            };
            if done {
                return Ok(());
            }
        }
        Err(Error::Timeout)
    }

    /// Shifts `words` out and returns when the last bit has left (BSY clear), reading nothing:
    /// RM0008 §25.3.5's transmit-only sequence (each frame written when TXE shows the buffer free,
    /// so the frames go back to back), then §25.3.8's end of a transfer (TXE, then BSY clear), then
    /// the received frame and the overrun the unread ones set are cleared (DR read, then SR,
    /// §25.3.10) so the next exchange starts clean. An even number of bytes goes as 16-bit frames
    /// (CR1 DFF; MSB first, so the same bits leave in the same order), half the frames to poll;
    /// the frame format is switched with the block off, as §25.5.1 asks of DFF, and back to 8 bits
    /// at the end; an odd number goes as bytes. One flag wait per frame (TXE, within one frame time
    /// of the previous write) where the full-duplex [`SpiBus::write`] takes two a byte (TXE and
    /// RXNE) and leaves the bus idle between bytes while it reads each one back. Called with the bus
    /// idle (every transfer of [`Device`] ends with BSY clear).
    pub fn send(&mut self, words: &[u8]) -> Result<(), Error> {
        let wide = words.len().is_multiple_of(2);
        if wide {
            self.frame_format(CR1_DFF);
        }
        let sent = self.shift_out(words, wide);
        if wide {
            self.frame_format(0);
        }
        sent
    }

    /// Sets the frame format (`dff`: [`CR1_DFF`] for 16 bits, 0 for 8) with the block off.
    fn frame_format(&self, dff: u32) {
        let cr1 = self.register(CR1) & !(CR1_SPE | CR1_DFF);
        self.set_register(CR1, cr1);
        self.set_register(CR1, cr1 | dff);
        self.set_register(CR1, cr1 | dff | CR1_SPE);
    }

    fn shift_out(&self, words: &[u8], wide: bool) -> Result<(), Error> {
        if wide {
            // Counted by frame (not `chunks_exact`, whose step of two the execution-time analysis
            // does not count): the loop's bound is found in each image's machine code.
            for frame in 0..words.len() / 2 {
                if let (Some(&high), Some(&low)) = (words.get(2 * frame), words.get(2 * frame + 1))
                {
                    self.wait_send(false)?;
                    self.set_register(DR, u32::from(high) << 8 | u32::from(low));
                }
            }
        } else {
            for &word in words {
                self.wait_send(false)?;
                self.set_register(DR, u32::from(word));
            }
        }
        self.wait_send(false)?;
        self.wait_send(true)?;
        let _ = self.register(DR);
        let _ = self.register(SR);
        Ok(())
    }
}

/// One device alone on a [`Master`]'s bus with its chip select `cs` (LightRing's TLC5947 chain,
/// XLAT as the select: its rising edge at the end of a write latches). [`SpiDevice::write`] is the
/// transmit-only [`Master::send`] between the select's fall and rise, one loop over the bytes;
/// other transactions run each operation on the full-duplex bus, as embedded-hal-bus'
/// `ExclusiveDevice` does. A pin whose writes cannot fail (`Infallible`, as every stm32 HAL pin).
pub struct Device<R, CS> {
    bus: Master<R>,
    cs: CS,
}

impl<R: Registers, CS: OutputPin<Error = Infallible>> Device<R, CS> {
    /// The device on `bus`, its select `cs` released (high).
    pub fn new(bus: Master<R>, mut cs: CS) -> Self {
        let Ok(()) = cs.set_high();
        Self { bus, cs }
    }

    /// Gives the bus and the select back.
    pub fn release(self) -> (Master<R>, CS) {
        (self.bus, self.cs)
    }
}

/// What a [`Device`]'s transaction can fail with: the bus's error, or a delay operation (the
/// device has no delay source: refused, not skipped).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DeviceError {
    /// The bus failed ([`Error`]).
    Bus(Error),
    /// An `Operation::DelayNs` was asked for.
    NoDelay,
}

impl From<Error> for DeviceError {
    fn from(error: Error) -> Self {
        DeviceError::Bus(error)
    }
}

impl embedded_hal::spi::Error for DeviceError {
    fn kind(&self) -> ErrorKind {
        match self {
            DeviceError::Bus(error) => error.kind(),
            DeviceError::NoDelay => ErrorKind::Other,
        }
    }
}

impl<R, CS> ErrorType for Device<R, CS> {
    type Error = DeviceError;
}

impl<R: Registers, CS: OutputPin<Error = Infallible>> SpiDevice for Device<R, CS> {
    fn transaction(&mut self, operations: &mut [Operation<'_, u8>]) -> Result<(), DeviceError> {
        let Ok(()) = self.cs.set_low();
        let mut result = Ok(());
        for operation in operations.iter_mut() {
            result = match operation {
                Operation::Read(words) => self.bus.read(words).map_err(DeviceError::Bus),
                Operation::Write(words) => self.bus.write(words).map_err(DeviceError::Bus),
                Operation::Transfer(read, write) => {
                    self.bus.transfer(read, write).map_err(DeviceError::Bus)
                }
                Operation::TransferInPlace(words) => {
                    self.bus.transfer_in_place(words).map_err(DeviceError::Bus)
                }
                Operation::DelayNs(_) => Err(DeviceError::NoDelay),
            };
            if result.is_err() {
                break;
            }
        }
        let flushed = self.bus.flush().map_err(DeviceError::Bus);
        let Ok(()) = self.cs.set_high();
        result.and(flushed)
    }

    fn write(&mut self, buf: &[u8]) -> Result<(), DeviceError> {
        let Ok(()) = self.cs.set_low();
        let sent = self.bus.send(buf);
        let Ok(()) = self.cs.set_high();
        Ok(sent?)
    }
}

// The exchange's wait for a free transmit buffer, apart from its wait for the answer. Appended
// (as the transmit-only path above) so that the loops the bounds files name keep their lines.

impl<R: Registers> Master<R> {
    /// [`Master::wait`] for TXE, before [`Master::exchange`] writes its byte: the same checks in a
    /// loop of its own, so that the bounds files state its wait apart from the answer's (RXNE).
    /// The transmit buffer hands its byte to the shift register as the byte starts (RM0008
    /// §25.3.5), and an exchange writes only after the previous one's answer came in (RXNE: its
    /// byte shifted out whole) or with the bus idle (a transaction ends with BSY clear, `flush`;
    /// the block starts with its buffer empty), so TXE is set when this is called and its first
    /// read finds it, where the answer's wait takes a byte time.
    fn wait_tx_empty(&self) -> Result<(), Error> {
        for _ in 0..POLLS {
            let sr = self.register(SR);
            if sr & SR_MODF != 0 {
                self.set_register(CR1, self.register(CR1) | CR1_MSTR | CR1_SPE);
                return Err(Error::ModeFault);
            }
            if sr & SR_OVR != 0 {
                let _ = self.register(DR);
                let _ = self.register(SR);
                return Err(Error::Overrun);
            }
            if sr & SR_TXE != 0 {
                return Ok(());
            }
        }
        Err(Error::Timeout)
    }
}
