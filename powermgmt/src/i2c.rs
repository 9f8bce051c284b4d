//! A polled I2C master for the F405's two I2C blocks, at register level, where every wait is
//! bounded: a sensor that stops answering costs one NACK, a stuck bus one timeout, never a hang.
//!
//! stm32f4xx-hal's blocking I2C polls its status flags without a bound (a bus held low would stall
//! the publisher that holds it until the watchdog resets the board), so this board drives the
//! peripheral itself (RM0090 §27.3.3, master mode, polling). Time is measured on the DWT cycle
//! counter, which `board::init` starts. After a timeout or a bus error the block is reset and set
//! up again, so the next transfer starts clean.
use embedded_hal::i2c::{ErrorKind, ErrorType, I2c, NoAcknowledgeSource, Operation};
use stm32f4xx_hal::pac::i2c1::RegisterBlock;

/// APB1 clock the timing is computed from (MHz).
const PCLK1_MHZ: u16 = 42;
/// Fast mode, duty 2:1: 42 MHz / (3 × 35) = 400 kHz.
const CCR_FAST_400K: u16 = (1 << 15) | 35;
/// Maximum rise time in fast mode (300 ns) in PCLK1 cycles, plus one.
const TRISE_FAST: u16 = PCLK1_MHZ * 300 / 1000 + 1;
/// How long one flag may take: a byte at 400 kHz takes 22.5 µs; 200 µs means the bus is stuck.
pub const FLAG_TIMEOUT_US: u32 = 200;
const TIMEOUT_CYCLES: u32 = FLAG_TIMEOUT_US * 168;

const CR1_PE: u16 = 1 << 0;
const CR1_START: u16 = 1 << 8;
const CR1_STOP: u16 = 1 << 9;
const CR1_ACK: u16 = 1 << 10;
const CR1_SWRST: u16 = 1 << 15;
const SR1_SB: u16 = 1 << 0;
const SR1_ADDR: u16 = 1 << 1;
const SR1_BTF: u16 = 1 << 2;
const SR1_RXNE: u16 = 1 << 6;
const SR1_TXE: u16 = 1 << 7;
const SR1_BERR: u16 = 1 << 8;
const SR1_ARLO: u16 = 1 << 9;
const SR1_AF: u16 = 1 << 10;
const SR1_OVR: u16 = 1 << 11;
const SR1_ERRORS: u16 = SR1_BERR | SR1_ARLO | SR1_AF | SR1_OVR;
const SR2_BUSY: u16 = 1 << 1;

/// What went wrong on the bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Error {
    /// Nobody acknowledged the address or a data byte.
    NoAcknowledge(NoAcknowledgeSource),
    /// Misplaced START/STOP.
    Bus,
    /// Another master won the bus.
    ArbitrationLoss,
    /// Data lost.
    Overrun,
    /// A flag did not come within [`FLAG_TIMEOUT_US`] (bus stuck or device stretching for ever).
    Timeout,
}

impl embedded_hal::i2c::Error for Error {
    fn kind(&self) -> ErrorKind {
        match *self {
            Error::NoAcknowledge(source) => ErrorKind::NoAcknowledge(source),
            Error::Bus => ErrorKind::Bus,
            Error::ArbitrationLoss => ErrorKind::ArbitrationLoss,
            Error::Overrun => ErrorKind::Overrun,
            Error::Timeout => ErrorKind::Other,
        }
    }
}

/// One I2C block (I2C1 or I2C2) as a bounded polled master at 400 kHz.
pub struct Master {
    block: *const RegisterBlock,
}

// SAFETY: the block is owned by this value alone (see `Master::new`); moving it to the task that
// owns the bus moves that ownership.
unsafe impl Send for Master {}

fn cycles() -> u32 {
    cortex_m::peripheral::DWT::cycle_count()
}

impl Master {
    /// Takes the block at `regs` (its clock on, its pins in open-drain AF4) and sets it up.
    ///
    /// # Safety
    /// `regs` must be I2C1 or I2C2 and owned by this value alone.
    pub unsafe fn new(regs: *const RegisterBlock) -> Self {
        // SAFETY: the caller hands over exclusive use of a valid I2C block.
        let master = Self { block: regs };
        master.setup();
        master
    }

    fn regs(&self) -> &RegisterBlock {
        // SAFETY: `new`'s caller handed over a valid block that lives for the whole program.
        unsafe { &*self.block }
    }

    fn setup(&self) {
        let r = self.regs();
        // SAFETY (all writes): documented bit patterns of RM0090's I2C registers.
        r.cr1().write(|w| unsafe { w.bits(CR1_SWRST) });
        r.cr1().write(|w| unsafe { w.bits(0) });
        r.cr2().write(|w| unsafe { w.bits(PCLK1_MHZ) });
        r.ccr().write(|w| unsafe { w.bits(CCR_FAST_400K) });
        r.trise().write(|w| unsafe { w.bits(TRISE_FAST) });
        r.cr1().write(|w| unsafe { w.bits(CR1_PE) });
    }

    fn sr1(&self) -> u16 {
        self.regs().sr1().read().bits()
    }

    fn set_cr1(&self, set: u16, clear: u16) {
        // SAFETY: read-modify-write of control bits of this block.
        self.regs()
            .cr1()
            .modify(|r, w| unsafe { w.bits((r.bits() | set) & !clear) });
    }

    /// Waits until `flag` is set in SR1, an error flag appears, or the timeout passes.
    fn wait(&self, flag: u16, nack: NoAcknowledgeSource) -> Result<(), Error> {
        let start = cycles();
        loop {
            let sr1 = self.sr1();
            if sr1 & SR1_ERRORS != 0 {
                // SAFETY: writing 0 to the rc_w0 error bits clears them.
                self.regs().sr1().write(|w| unsafe { w.bits(!SR1_ERRORS) });
                return Err(if sr1 & SR1_AF != 0 {
                    Error::NoAcknowledge(nack)
                } else if sr1 & SR1_ARLO != 0 {
                    Error::ArbitrationLoss
                } else if sr1 & SR1_BERR != 0 {
                    Error::Bus
                } else {
                    Error::Overrun
                });
            }
            if sr1 & flag != 0 {
                return Ok(());
            }
            if cycles().wrapping_sub(start) > TIMEOUT_CYCLES {
                return Err(Error::Timeout);
            }
        }
    }

    /// Waits (bounded) until the bus is free.
    fn wait_idle(&self) -> Result<(), Error> {
        let start = cycles();
        while self.regs().sr2().read().bits() & SR2_BUSY != 0
            || self.regs().cr1().read().bits() & CR1_STOP != 0
        {
            if cycles().wrapping_sub(start) > TIMEOUT_CYCLES {
                return Err(Error::Timeout);
            }
        }
        Ok(())
    }

    /// START (or repeated START) and the address byte; the ADDR flag is left set for the caller.
    fn address(&self, address: u8, read: bool, ack: bool) -> Result<(), Error> {
        if ack {
            self.set_cr1(CR1_START | CR1_ACK, 0);
        } else {
            self.set_cr1(CR1_START, CR1_ACK);
        }
        self.wait(SR1_SB, NoAcknowledgeSource::Unknown)?;
        let byte = (u16::from(address) << 1) | u16::from(read);
        // SAFETY: the address byte into the data register.
        self.regs().dr().write(|w| unsafe { w.bits(byte) });
        self.wait(SR1_ADDR, NoAcknowledgeSource::Address)
    }

    fn clear_addr(&self) {
        // Reading SR1 then SR2 clears ADDR.
        let _ = self.sr1();
        let _ = self.regs().sr2().read().bits();
    }

    fn write_group(&self, address: u8, group: &[Operation<'_>]) -> Result<(), Error> {
        self.address(address, false, false)?;
        self.clear_addr();
        for operation in group {
            if let Operation::Write(bytes) = operation {
                for &byte in bytes.iter() {
                    self.wait(SR1_TXE, NoAcknowledgeSource::Data)?;
                    // SAFETY: one data byte.
                    self.regs()
                        .dr()
                        .write(|w| unsafe { w.bits(u16::from(byte)) });
                }
            }
        }
        self.wait(SR1_BTF, NoAcknowledgeSource::Data)
    }

    /// Reads every byte of the read operations in `group`; the last byte is not acknowledged and
    /// the STOP is requested before it arrives (RM0090's polling sequence).
    fn read_group(&self, address: u8, group: &mut [Operation<'_>]) -> Result<(), Error> {
        let total: usize = group
            .iter()
            .map(|o| match o {
                Operation::Read(b) => b.len(),
                Operation::Write(_) => 0,
            })
            .sum();
        if total == 0 {
            return Ok(());
        }
        self.address(address, true, total > 1)?;
        if total == 1 {
            self.clear_addr();
            self.set_cr1(CR1_STOP, 0);
        } else {
            self.clear_addr();
        }
        let mut n = 0;
        for operation in group.iter_mut() {
            if let Operation::Read(buffer) = operation {
                for byte in buffer.iter_mut() {
                    n += 1;
                    if n == total && total > 1 {
                        self.set_cr1(CR1_STOP, CR1_ACK);
                    }
                    self.wait(SR1_RXNE, NoAcknowledgeSource::Data)?;
                    *byte = self.regs().dr().read().bits() as u8;
                }
            }
        }
        Ok(())
    }

    fn run(&mut self, address: u8, operations: &mut [Operation<'_>]) -> Result<(), Error> {
        self.wait_idle()?;
        let mut start = 0;
        while start < operations.len() {
            let read = matches!(operations[start], Operation::Read(_));
            let mut end = start + 1;
            while end < operations.len() && matches!(operations[end], Operation::Read(_)) == read {
                end += 1;
            }
            let last = end == operations.len();
            let group = &mut operations[start..end];
            if read {
                // A read group ends with its own STOP; a read followed by a write is not used by
                // any AMiRo driver and is done as two transactions.
                self.read_group(address, group)?;
                if !last {
                    self.wait_idle()?;
                }
            } else {
                self.write_group(address, group)?;
                if last {
                    self.set_cr1(CR1_STOP, 0);
                }
            }
            start = end;
        }
        Ok(())
    }
}

impl ErrorType for Master {
    type Error = Error;
}

impl I2c for Master {
    fn transaction(
        &mut self,
        address: u8,
        operations: &mut [Operation<'_>],
    ) -> Result<(), Self::Error> {
        let result = self.run(address, operations);
        match result {
            Ok(()) => {}
            Err(Error::NoAcknowledge(_)) => {
                // Release the bus; the block stays usable.
                self.set_cr1(CR1_STOP, 0);
                if self.wait_idle().is_err() {
                    self.setup();
                }
            }
            Err(_) => self.setup(),
        }
        result
    }
}
