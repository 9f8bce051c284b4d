//! A polled 400 kHz I2C master at register level for the I2C blocks of both chips (the F103's and
//! the F405's are the same IP, RM0008 §26 / RM0090 §27, master mode, polling), where every wait is
//! bounded: a sensor that stops answering costs one NACK, a stuck bus one timeout, never a hang.
//!
//! The HALs' blocking I2C drivers poll their flags without a bound (stm32f4xx-hal) or against the
//! DWT cycle counter only (stm32f1xx-hal's `BlockingI2c`, which spins for ever where the counter
//! does not run, as in QEMU). Here each wait ends after [`FLAG_TIMEOUT_US`] on the cycle counter
//! (which the board starts) or after as many polls as that is cycles, whichever comes first. After
//! a timeout or a bus error the bus is cleared ([`crate::i2c_clear`]: a device left driving SDA low
//! mid-byte is clocked free, then a STOP) and the block reset and set up again, so the next transfer
//! starts clean.
use embedded_hal::i2c::{ErrorType, I2c, NoAcknowledgeSource, Operation};

use crate::i2c_clear::{clear_bus, ClearPins};

/// I2C1's base address on both chips.
pub const I2C1: usize = 0x4000_5400;
/// I2C2's base address on both chips.
pub const I2C2: usize = 0x4000_5800;
/// How long one flag may take: a byte at 400 kHz takes 22.5 µs; 200 µs means the bus is stuck.
pub const FLAG_TIMEOUT_US: u32 = 200;

const CR1: usize = 0x00;
const CR2: usize = 0x04;
const DR: usize = 0x10;
const SR1_REG: usize = 0x14;
const SR2_REG: usize = 0x18;
const CCR: usize = 0x1C;
const TRISE: usize = 0x20;

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

pub use crate::i2c_fault::Error;

/// One I2C block (I2C1 or I2C2) as a bounded polled master at 400 kHz.
pub struct Master {
    base: usize,
    /// APB1 in MHz (the block's FREQ field and its timing).
    pclk1_mhz: u32,
    /// [`FLAG_TIMEOUT_US`] in core cycles (and the poll bound).
    timeout_cycles: u32,
    /// SCL and SDA, for the bus clear.
    pins: Pins,
}

fn cycles() -> u32 {
    cortex_m::peripheral::DWT::cycle_count()
}

/// CCR for 400 kHz in fast mode, duty 2:1, from a `pclk1_mhz` of 2 to 50: ⌈10·p / 12⌉, as
/// ⌊(5·p + 5)·171 / 1024⌋.
const fn fast_mode_ccr(pclk1_mhz: u32) -> u32 {
    ((5 * pclk1_mhz + 5) * 171) >> 10
}

/// 300 ns in cycles of a `pclk1_mhz` of 2 to 50: ⌊300·p / 1000⌋, as ⌊77·p / 256⌋.
const fn rise_cycles(pclk1_mhz: u32) -> u32 {
    (77 * pclk1_mhz) >> 8
}

// The two forms above equal their divisions for every APB1 clock `new` allows (checked as the crate
// compiles).
const _: () = {
    let mut p = 2;
    while p <= 50 {
        assert!(fast_mode_ccr(p) == (p * 10).div_ceil(12));
        assert!(rise_cycles(p) == p * 300 / 1000);
        p += 1;
    }
};

impl Master {
    /// Takes the block at `base` ([`I2C1`] or [`I2C2`]; its clock on, its `pins` in open-drain
    /// alternate function), clears its bus (a device may hold SDA since a reset mid-transfer) and
    /// sets it up for 400 kHz from a `pclk1_hz` APB1, with its timeouts counted in cycles of a
    /// `sysclk_hz` core clock.
    ///
    /// # Safety
    /// `base` must be I2C1 or I2C2 and owned by this value alone.
    pub unsafe fn new(base: usize, pins: Pins, pclk1_hz: u32, sysclk_hz: u32) -> Self {
        let master = Self {
            base,
            pclk1_mhz: (pclk1_hz / 1_000_000).clamp(2, 50),
            timeout_cycles: FLAG_TIMEOUT_US.saturating_mul(sysclk_hz / 1_000_000),
            pins,
        };
        // A bus still held is the first transfer's fault, reported there.
        let _ = master.recover();
        master
    }

    fn read(&self, offset: usize) -> u16 {
        // SAFETY: `new`'s contract: a register of the I2C block this value owns.
        unsafe { core::ptr::read_volatile((self.base + offset) as *const u32) as u16 }
    }

    fn write(&self, offset: usize, value: u16) {
        // SAFETY: as in `read`; documented bit patterns of the I2C registers.
        unsafe { core::ptr::write_volatile((self.base + offset) as *mut u32, u32::from(value)) }
    }

    fn setup(&self) {
        // Fast mode, duty 2:1: SCL = PCLK1 / (3 × CCR), rounded so it never exceeds 400 kHz;
        // TRISE: the 300 ns rise time in PCLK1 cycles, plus one. `pclk1_mhz` is 2 to 50 (`new`
        // clamps it), where the multiply-shift forms are exact (checked as the crate compiles) and need no
        // division; CCR is at least 2 (the block's minimum in fast mode is 1).
        let ccr = fast_mode_ccr(self.pclk1_mhz) as u16;
        let trise = (rise_cycles(self.pclk1_mhz) + 1) as u16;
        self.write(CR1, CR1_SWRST);
        self.write(CR1, 0);
        self.write(CR2, self.pclk1_mhz as u16);
        self.write(CCR, (1 << 15) | ccr);
        self.write(TRISE, trise);
        self.write(CR1, CR1_PE);
    }

    fn sr1(&self) -> u16 {
        self.read(SR1_REG)
    }

    fn set_cr1(&self, set: u16, clear: u16) {
        self.write(CR1, (self.read(CR1) | set) & !clear);
    }

    /// Waits until `flag` is set in SR1, an error flag appears, or the timeout passes.
    fn wait(&self, flag: u16, nack: NoAcknowledgeSource) -> Result<(), Error> {
        let start = cycles();
        // Also bounded in polls: each takes several core cycles, so on a chip whose cycle counter
        // runs the cycle timeout comes first; on one where it does not (QEMU has no DWT), this
        // bound still ends the wait.
        for _ in 0..self.timeout_cycles {
            let sr1 = self.sr1();
            if sr1 & SR1_ERRORS != 0 {
                // Writing 0 to the rc_w0 error bits clears them.
                self.write(SR1_REG, !SR1_ERRORS);
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
            if cycles().wrapping_sub(start) > self.timeout_cycles {
                return Err(Error::Timeout);
            }
        }
        Err(Error::Timeout)
    }

    /// Waits (bounded, in cycles and in polls as [`Master::wait`]) until the bus is free.
    fn wait_idle(&self) -> Result<(), Error> {
        let start = cycles();
        for _ in 0..self.timeout_cycles {
            if self.read(SR2_REG) & SR2_BUSY == 0 && self.read(CR1) & CR1_STOP == 0 {
                return Ok(());
            }
            if cycles().wrapping_sub(start) > self.timeout_cycles {
                return Err(Error::Timeout);
            }
        }
        Err(Error::Timeout)
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
        self.write(DR, byte);
        self.wait(SR1_ADDR, NoAcknowledgeSource::Address)
    }

    fn clear_addr(&self) {
        // Reading SR1 then SR2 clears ADDR.
        let _ = self.sr1();
        let _ = self.read(SR2_REG);
    }

    /// Sends `bytes`, one at a time as the data register empties (the address phase done). Not
    /// inlined: its loop runs once per byte of the slice it is given, and the execution-time
    /// analysis bounds it per call by the length its caller passes (`per_element` in the boards'
    /// bounds files), which every register access of the drivers fixes.
    #[inline(never)]
    fn send(&self, bytes: &[u8]) -> Result<(), Error> {
        for &byte in bytes {
            self.wait(SR1_TXE, NoAcknowledgeSource::Data)?;
            self.write(DR, u16::from(byte));
        }
        Ok(())
    }

    /// Receives `buffer`, byte by byte (the address phase done); where `stop_at_last`, the last byte
    /// is not acknowledged and the STOP is requested before it arrives (the reference manuals'
    /// polling sequence for a transfer of more than one byte). Not inlined, as [`Master::send`].
    #[inline(never)]
    fn receive(&self, buffer: &mut [u8], stop_at_last: bool) -> Result<(), Error> {
        let last = buffer.len().wrapping_sub(1);
        for (n, byte) in buffer.iter_mut().enumerate() {
            if stop_at_last && n == last {
                self.set_cr1(CR1_STOP, CR1_ACK);
            }
            self.wait(SR1_RXNE, NoAcknowledgeSource::Data)?;
            *byte = self.read(DR) as u8;
        }
        Ok(())
    }

    /// The address phase of a read of `total` bytes: START, the address, ADDR cleared; a read of
    /// one byte is not acknowledged and has its STOP requested here.
    fn read_address(&self, address: u8, total: usize) -> Result<(), Error> {
        self.address(address, true, total > 1)?;
        self.clear_addr();
        if total == 1 {
            self.set_cr1(CR1_STOP, 0);
        }
        Ok(())
    }

    fn write_group(&self, address: u8, group: &[Operation<'_>]) -> Result<(), Error> {
        self.address(address, false, false)?;
        self.clear_addr();
        for operation in group {
            if let Operation::Write(bytes) = operation {
                self.send(bytes)?;
            }
        }
        self.wait(SR1_BTF, NoAcknowledgeSource::Data)
    }

    /// Reads every byte of the read operations in `group`; the last byte is not acknowledged and
    /// the STOP is requested before it arrives.
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
        self.read_address(address, total)?;
        // The last byte of the transfer is the last of the last read operation that has any.
        let last = group
            .iter()
            .rposition(|o| matches!(o, Operation::Read(b) if !b.is_empty()));
        for (k, operation) in group.iter_mut().enumerate() {
            if let Operation::Read(buffer) = operation {
                self.receive(buffer, total > 1 && Some(k) == last)?;
            }
        }
        Ok(())
    }

    /// A register read (one byte written, then `read`, after a repeated START), the transfer every
    /// `write_read` of the AMiRo drivers makes; `target` is the device's address (high byte) and
    /// the register's (low byte), so the length of `read` is an argument in a register (r3), which
    /// the call's machine code fixes.
    ///
    /// Once the read's address is acknowledged, the master acknowledges every byte itself, so no
    /// error of the receive is a missing acknowledge (AF is set only while the master transmits:
    /// the master receiver and the error conditions, RM0008 §26.3.3-4, RM0090 §27.3.3-4): it clears
    /// the bus and resets the block at once ([`Master::recover`]), as [`Master::finish`] does with
    /// every other error. Finishing it apart keeps the wait for a released bus (after a missing
    /// acknowledge only) off the path that waited for every flag, where the bound would charge it.
    #[inline(never)]
    fn read_register(&mut self, target: u16, read: &mut [u8]) -> Result<(), Error> {
        let [address, register] = target.to_be_bytes();
        let addressed = self.wait_idle().and_then(|()| {
            self.address(address, false, false)?;
            self.clear_addr();
            self.send(&[register])?;
            self.wait(SR1_BTF, NoAcknowledgeSource::Data)?;
            if read.is_empty() {
                self.set_cr1(CR1_STOP, 0);
                return Ok(());
            }
            self.read_address(address, read.len())
        });
        if addressed.is_err() || read.is_empty() {
            return self.finish(addressed);
        }
        let received = self.receive(read, read.len() > 1);
        if received.is_err() {
            return self.recover().and(received);
        }
        received
    }

    /// After a transfer: on a missing acknowledge the bus is released (the block stays usable),
    /// after any other error (or a STOP that does not free the bus) the bus is cleared and the
    /// block set up again ([`Master::recover`]; [`Error::BusStuck`] where the clear fails).
    fn finish(&mut self, result: Result<(), Error>) -> Result<(), Error> {
        match result {
            Ok(()) => {}
            Err(Error::NoAcknowledge(_)) => {
                self.set_cr1(CR1_STOP, 0);
                if self.wait_released().is_err() {
                    return self.recover().and(result);
                }
            }
            Err(_) => return self.recover().and(result),
        }
        result
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
        self.finish(result)
    }

    // The drivers' transfers, each with its slice's length in an argument register (r3) rather
    // than in an operation list in memory: the execution-time analysis bounds their byte loops
    // per call (docs/analysis.md, "The bounds file").

    fn read(&mut self, address: u8, read: &mut [u8]) -> Result<(), Self::Error> {
        let result = self.wait_idle().and_then(|()| {
            if read.is_empty() {
                return Ok(());
            }
            self.read_address(address, read.len())?;
            self.receive(read, read.len() > 1)
        });
        self.finish(result)
    }

    fn write(&mut self, address: u8, write: &[u8]) -> Result<(), Self::Error> {
        let result = self.wait_idle().and_then(|()| {
            self.address(address, false, false)?;
            self.clear_addr();
            self.send(write)?;
            self.wait(SR1_BTF, NoAcknowledgeSource::Data)?;
            self.set_cr1(CR1_STOP, 0);
            Ok(())
        });
        self.finish(result)
    }

    /// A one-byte write then a read is a register read ([`Master::read_register`]); any other a
    /// transaction. Inlined, so a call whose write is one byte calls `read_register` alone.
    #[inline(always)]
    fn write_read(
        &mut self,
        address: u8,
        write: &[u8],
        read: &mut [u8],
    ) -> Result<(), Self::Error> {
        match write {
            [register] => self.read_register(u16::from_be_bytes([address, *register]), read),
            _ => self.transaction(
                address,
                &mut [Operation::Write(write), Operation::Read(read)],
            ),
        }
    }
}

// Appended below the driver's own code, whose wait loops the boards' bounds files name by line.

impl Master {
    /// Waits (bounded as [`Master::wait_idle`]) until the STOP requested after a missing
    /// acknowledge has freed the bus. A loop of its own, not `wait_idle`'s: this wait follows a
    /// STOP and begins no transfer, so the bounds files state it apart from the wait before a
    /// START (which a device waking on the START may stretch). Not inlined, so it keeps its name.
    #[inline(never)]
    fn wait_released(&self) -> Result<(), Error> {
        let start = cycles();
        // The STOP bit first (it clears when the STOP is on the bus), then BUSY: the same
        // condition as `wait_idle`'s, read in the other order, so the linker does not fold the
        // two functions into one.
        for _ in 0..self.timeout_cycles {
            if self.read(CR1) & CR1_STOP == 0 && self.read(SR2_REG) & SR2_BUSY == 0 {
                return Ok(());
            }
            if cycles().wrapping_sub(start) > self.timeout_cycles {
                return Err(Error::Timeout);
            }
        }
        Err(Error::Timeout)
    }
}

// The bus clear's chip side, below the waits the bounds files name by line.

/// GPIOB's base address (RM0008 §3.3, RM0090 §2.3): the port of both I2C blocks' pins on every
/// AMiRo board.
#[cfg(feature = "f1")]
pub const GPIOB: usize = 0x4001_0C00;
/// GPIOB's base address (RM0008 §3.3, RM0090 §2.3): the port of both I2C blocks' pins on every
/// AMiRo board.
#[cfg(feature = "f4")]
pub const GPIOB: usize = 0x4002_0400;

// A GPIO port's input data and bit set/reset registers (RM0008 §9.2, RM0090 §8.4).
#[cfg(feature = "f1")]
const GPIO_IDR: usize = 0x08;
#[cfg(feature = "f1")]
const GPIO_BSRR: usize = 0x10;
#[cfg(feature = "f4")]
const GPIO_IDR: usize = 0x10;
#[cfg(feature = "f4")]
const GPIO_BSRR: usize = 0x18;

/// Half an SCL period at 400 kHz, as a fraction of [`FLAG_TIMEOUT_US`]: 200 µs / 1.25 µs.
const HALF_PERIODS_PER_TIMEOUT: u32 = 160;

/// An I2C block's SCL and SDA: two pins of one GPIO port, which the board puts in open-drain
/// alternate function and the bus clear turns into open-drain outputs for its pulses, and back.
#[derive(Debug, Clone, Copy)]
pub struct Pins {
    port: usize,
    scl: u8,
    sda: u8,
}

impl Pins {
    /// SCL on pin `scl` and SDA on pin `sda` of the GPIO port at `port` ([`GPIOB`]).
    ///
    /// # Safety
    /// `port` must be a GPIO port's base address and the two pins (0 to 15) the I2C block's, in
    /// open-drain alternate function, reconfigured by nothing else once the master has them.
    pub const unsafe fn new(port: usize, scl: u8, sda: u8) -> Self {
        Self { port, scl, sda }
    }

    /// Both pins as open-drain outputs (`gpio`; their output levels set high before, so the
    /// switch drives nothing low) or back in open-drain alternate function.
    fn hand_to_gpio(&self, gpio: bool) {
        self.mode(self.scl, gpio);
        self.mode(self.sda, gpio);
    }

    /// F1: CRL/CRH, four bits a pin; the board's alternate open drain is CNF 0b11, an open-drain
    /// output CNF 0b01 (RM0008 §9.2.1-2): only CNF's high bit changes.
    #[cfg(feature = "f1")]
    fn mode(&self, pin: u8, gpio: bool) {
        let offset = if pin < 8 { 0x00 } else { 0x04 };
        write_bit(self.port + offset, u32::from(pin % 8) * 4 + 3, !gpio);
    }

    /// F4: MODER, two bits a pin: alternate function 0b10, output 0b01 (RM0090 §8.4.1), through
    /// input (0b00) between the two; the board set OTYPER's open drain and the AF number, which
    /// both modes keep.
    #[cfg(feature = "f4")]
    fn mode(&self, pin: u8, gpio: bool) {
        let low = u32::from(pin) * 2;
        let (off, on) = if gpio { (low + 1, low) } else { (low, low + 1) };
        write_bit(self.port, off, false);
        write_bit(self.port, on, true);
    }
}

/// Sets or clears `bit` of the peripheral register at `register` through its bit-band alias
/// (Cortex-M3/M4: PM0056 §2.2.5, PM0214 §2.2.5): one write, no read-modify-write, so the two
/// blocks' masters, whose pins share a configuration register and whose locks may be taken at
/// different priorities, cannot undo each other's change.
fn write_bit(register: usize, bit: u32, set: bool) {
    let alias =
        0x4200_0000 + register.wrapping_sub(0x4000_0000).wrapping_mul(32) + bit as usize * 4;
    // SAFETY: `Pins::new`'s contract: a bit of a pin of the master's own in its GPIO port's
    // configuration register (peripherals below 0x4010_0000 are all in the bit-band region).
    unsafe { core::ptr::write_volatile(alias as *mut u32, u32::from(set)) }
}

/// The pins as [`ClearPins`] for one clear, with half an SCL period in core cycles.
struct Clearing<'a> {
    pins: &'a Pins,
    half_cycles: u32,
}

impl Clearing<'_> {
    /// The port's input data register.
    fn idr(&self) -> u32 {
        // SAFETY: `Pins::new`'s contract: the port's input data register.
        unsafe { core::ptr::read_volatile((self.pins.port + GPIO_IDR) as *const u32) }
    }
}

impl ClearPins for Clearing<'_> {
    fn lines(&mut self, scl: bool, sda: bool) {
        // One write of the port's bit set/reset register, which leaves its other pins alone.
        let bit = |pin: u8, high: bool| 1u32 << (pin + if high { 0 } else { 16 });
        let value = bit(self.pins.scl, scl) | bit(self.pins.sda, sda);
        // SAFETY: `Pins::new`'s contract: the GPIO port's BSRR, the two pins' bits.
        unsafe { core::ptr::write_volatile((self.pins.port + GPIO_BSRR) as *mut u32, value) }
    }

    fn half_period(&mut self) {
        half_period(self.half_cycles);
    }

    fn scl_is_high(&mut self) -> bool {
        self.idr() & (1 << self.pins.scl) != 0
    }

    fn sda_is_high(&mut self) -> bool {
        self.idr() & (1 << self.pins.sda) != 0
    }
}

/// Waits `half_cycles` core cycles on the cycle counter, or as many polls where it does not run
/// (as [`Master::wait`]). Not inlined, so it keeps its name for the bounds files.
#[inline(never)]
fn half_period(half_cycles: u32) {
    let start = cycles();
    for _ in 0..half_cycles {
        if cycles().wrapping_sub(start) >= half_cycles {
            return;
        }
    }
}

impl Master {
    /// After a timeout or a bus error: the block held in reset (it drives neither line, whatever
    /// state it was in: clearing PE alone waits for the end of a transfer, RM0008 §26.6.1), its
    /// pins handed to GPIO for the bus clear (UM10204 §3.1.16, [`clear_bus`]: up to nine SCL
    /// pulses while SDA is low, each released SCL awaited for at most `i2c_clear::MAX_STRETCH` half
    /// periods as a device may stretch it, then a STOP), the pins given back, the block reset again (with
    /// its pins back on the lines, as the STM32F10x errata's I2C busy-flag entry asks) and set up.
    /// [`Error::BusStuck`] where SDA stays low, or SCL. Not inlined: one copy for every fault path.
    #[inline(never)]
    fn recover(&self) -> Result<(), Error> {
        self.write(CR1, CR1_SWRST);
        let mut pins = Clearing {
            pins: &self.pins,
            half_cycles: self.timeout_cycles / HALF_PERIODS_PER_TIMEOUT,
        };
        // Both output levels high (the alternate function ignores them) before the pins are
        // outputs; the half period after it lets the lines settle, released by the block.
        pins.lines(true, true);
        pins.half_period();
        self.pins.hand_to_gpio(true);
        let cleared = clear_bus(&mut pins);
        self.pins.hand_to_gpio(false);
        self.setup();
        cleared.map(|_| ()).map_err(Error::from)
    }
}

/// The bus clear of a block its interrupt-driven engine runs (`i2c_bus::I2cBus::serve_watch`'s,
/// after a script ended at its deadline, the `scripted-i2c` trials): the clear of
/// [`Master`]'s fault path on the same pins, without the master. Linked only where a board calls
/// it.
pub struct BusClear {
    base: usize,
    pins: Pins,
    half_cycles: u32,
}

impl BusClear {
    /// The clear of the block at `base` ([`I2C1`] or [`I2C2`]) on `pins`, its half SCL periods
    /// timed in cycles of a `sysclk_hz` core clock (the design plan's: a slower clock only makes
    /// them longer).
    ///
    /// # Safety
    /// As [`Pins::new`] and [`Master::new`]: `base` the block whose pins these are, used by this
    /// value only while its bus recovers (the bus starts no script then, and its interrupts are
    /// off).
    pub const unsafe fn new(base: usize, pins: Pins, sysclk_hz: u32) -> Self {
        Self {
            base,
            pins,
            half_cycles: FLAG_TIMEOUT_US * (sysclk_hz / 1_000_000) / HALF_PERIODS_PER_TIMEOUT,
        }
    }

    /// The block held in reset, its pins as GPIO, the bus cleared (up to nine SCL pulses while SDA
    /// is low, then a STOP, each released SCL awaited as a device may stretch it), the pins given
    /// back; the block left in reset for its bus to set it up (`I2cBus::recovered`). `Stuck`
    /// where SDA or SCL stays low.
    pub fn clear(&self) -> Result<(), crate::i2c_clear::Stuck> {
        // SAFETY: `new`'s contract: this block's CR1, the software reset bit.
        unsafe {
            core::ptr::write_volatile((self.base + CR1) as *mut u32, u32::from(CR1_SWRST));
        }
        let mut pins = Clearing {
            pins: &self.pins,
            half_cycles: self.half_cycles,
        };
        pins.lines(true, true);
        pins.half_period();
        self.pins.hand_to_gpio(true);
        let cleared = clear_bus(&mut pins);
        self.pins.hand_to_gpio(false);
        cleared.map(|_| ())
    }
}
