//! The register adapter under [`crate::i2c_engine`]: one I2C block (I2C1 or I2C2, RM0008 §26.6 /
//! RM0090 §27.6) as volatile reads and writes, and its set-up for 400 kHz (the polled master's,
//! `i2c::Master`, which the boards still use until the engine is wired).
use cortex_m::interrupt::InterruptNumber;
use cortex_m::peripheral::NVIC;

use crate::i2c_bus::I2cBus;
use crate::i2c_engine::{
    Block, Interrupts, CONDITION_WAIT_NS, CR1_PE, CR1_START, CR1_STOP, CR1_SWRST,
};
use crate::scripted::I2cPort;
use crate::timer_monotonic::nvic_priority;

const CR1: usize = 0x00;
const CR2: usize = 0x04;
const DR: usize = 0x10;
const SR1: usize = 0x14;
const SR2: usize = 0x18;
const CCR: usize = 0x1C;
const TRISE: usize = 0x20;

/// One I2C block's registers.
pub struct Registers {
    base: usize,
    /// APB1 in MHz (CR2's FREQ field).
    pclk1_mhz: u16,
    /// CCR and TRISE for 400 kHz at that APB1 clock, worked out when the value is made so that a
    /// reset (on an event's failure path) divides nothing.
    ccr: u16,
    trise: u16,
    /// [`CONDITION_WAIT_NS`] in core cycles.
    condition_cycles: u32,
}

impl Registers {
    /// The block at `base` (`i2c::I2C1` or `i2c::I2C2`) with a `pclk1_hz` APB1, its condition
    /// waits timed in cycles of a `sysclk_hz` core clock. Touches nothing: [`Block::reset`] sets
    /// the block up.
    ///
    /// # Safety
    /// `base` must be I2C1 or I2C2, its clock on and its pins in open-drain alternate function,
    /// and the block used through this value alone. The core's cycle counter should run (DWT
    /// CYCCNT, as for `i2c::Master`); where it does not, a condition wait ends at its poll cap.
    pub const unsafe fn new(base: usize, pclk1_hz: u32, sysclk_hz: u32) -> Self {
        let mhz = pclk1_hz / 1_000_000;
        let mhz = if mhz < 2 {
            2
        } else if mhz > 50 {
            50
        } else {
            mhz
        };
        let mhz = mhz as u16;
        // Fast mode, duty 2:1: SCL = PCLK1 / (3 × CCR), rounded so it never exceeds 400 kHz;
        // TRISE: the 300 ns rise time in PCLK1 cycles, plus one (as `i2c::Master::setup`).
        let ccr = (mhz * 10).div_ceil(12);
        let ccr = if ccr < 1 { 1 } else { ccr };
        Self {
            base,
            pclk1_mhz: mhz,
            ccr: (1 << 15) | ccr,
            trise: mhz * 300 / 1000 + 1,
            condition_cycles: (CONDITION_WAIT_NS as u64 * sysclk_hz as u64 / 1_000_000_000) as u32,
        }
    }

    /// The block's clocks as the board's clock plan set them up at run time (the value was made
    /// at compile time, in a static): APB1 at `pclk1_hz`, the condition waits timed in cycles of
    /// a `sysclk_hz` core clock. Touches nothing: [`Block::reset`] applies it.
    pub fn set_clocks(&mut self, pclk1_hz: u32, sysclk_hz: u32) {
        // SAFETY: `new` touches nothing and keeps `base`; the caller's value already owns it.
        *self = unsafe { Self::new(self.base, pclk1_hz, sysclk_hz) };
    }

    fn read(&self, offset: usize) -> u16 {
        // SAFETY: `new`'s contract: a register of the I2C block this value owns.
        unsafe { core::ptr::read_volatile((self.base + offset) as *const u32) as u16 }
    }

    fn write(&self, offset: usize, value: u16) {
        // SAFETY: as in `read`; documented bit patterns of the I2C registers.
        unsafe { core::ptr::write_volatile((self.base + offset) as *mut u32, u32::from(value)) }
    }
}

impl Block for Registers {
    fn read_sr1(&mut self) -> u16 {
        self.read(SR1)
    }

    fn read_sr2(&mut self) -> u16 {
        self.read(SR2)
    }

    fn read_dr(&mut self) -> u8 {
        self.read(DR) as u8
    }

    fn write_dr(&mut self, byte: u8) {
        self.write(DR, u16::from(byte));
    }

    fn modify_cr1(&mut self, set: u16, clear: u16) {
        self.write(CR1, (self.read(CR1) | set) & !clear);
    }

    fn stop_pending(&mut self) -> bool {
        self.read(CR1) & CR1_STOP != 0
    }

    fn start_pending(&mut self) -> bool {
        self.read(CR1) & CR1_START != 0
    }

    fn set_interrupts(&mut self, interrupts: Interrupts) {
        // CR2 holds FREQ and the enables (DMAEN and LAST stay 0: no DMA): written whole, not read.
        self.write(CR2, self.pclk1_mhz | interrupts.bits());
    }

    fn clear_sr1(&mut self, flags: u16) {
        // SR1's error flags are rc_w0: writing 0 clears, writing 1 keeps.
        self.write(SR1, !flags);
    }

    fn cycles(&mut self) -> u32 {
        cortex_m::peripheral::DWT::cycle_count()
    }

    fn condition_cycles(&self) -> u32 {
        self.condition_cycles
    }

    fn reset(&mut self) {
        self.write(CR1, CR1_SWRST);
        self.write(CR1, 0);
        self.write(CR2, self.pclk1_mhz);
        self.write(CCR, self.ccr);
        self.write(TRISE, self.trise);
        self.write(CR1, CR1_PE);
    }
}

/// A board's I2C1 and I2C2 as their engines' buses (the `scripted-i2c` trials' wiring, shared by
/// DiWheelDrive 1-1 and PowerManagement).
pub struct EngineBuses<const SLOTS: usize> {
    /// I2C1's bus.
    pub i2c1: &'static I2cBus<Registers, SLOTS>,
    /// I2C2's bus.
    pub i2c2: &'static I2cBus<Registers, SLOTS>,
}

impl<const SLOTS: usize> EngineBuses<SLOTS> {
    /// Client `CLIENT`'s slots on I2C1 and I2C2, a script's timeout its wire time plus
    /// `allowance_us` on the clock `D`.
    pub const fn ports<const CLIENT: usize, D>(
        &self,
        allowance_us: u32,
    ) -> (
        I2cPort<'static, D, Registers, SLOTS>,
        I2cPort<'static, D, Registers, SLOTS>,
    ) {
        (
            I2cPort::new(self.i2c1, self.i2c1.client_at::<CLIENT>(), allowance_us),
            I2cPort::new(self.i2c2, self.i2c2.client_at::<CLIENT>(), allowance_us),
        )
    }

    /// The clock plan's APB1 (`pclk1_hz`) and core clock (`sysclk_hz`) kept in both blocks'
    /// values for their hand-over (their statics were made with the design plan's). Touches no
    /// register: `init` calls it while the polled masters still own the blocks.
    pub fn set_clocks(&self, pclk1_hz: u32, sysclk_hz: u32) {
        for bus in [self.i2c1, self.i2c2] {
            bus.with_block(|block| block.set_clocks(pclk1_hz, sysclk_hz));
        }
    }

    /// The four interrupts (`interrupts`: each block's event and error interrupt) at RTIC's
    /// logical `priority` ([`nvic_priority`]), unmasked: the blocks raise nothing until a script
    /// turns CR2's enables on. Bound by the board, not as tasks of the app: RTIC sets up the NVIC
    /// of a hardware task even where a `cfg` leaves the task out, which would change the shipped
    /// images (docs/i2c.md, "What step (c) wires").
    pub fn bind_engines<I: InterruptNumber>(
        &self,
        nvic: &mut NVIC,
        interrupts: [I; 4],
        priority: u8,
    ) {
        for irq in interrupts {
            // SAFETY: init runs with interrupts off; the handlers share no RTIC resource (the
            // buses are statics under their own critical sections).
            unsafe {
                nvic.set_priority(irq, nvic_priority(priority));
                NVIC::unmask(irq);
            }
        }
    }
}

/// `bus`'s block taken over from the polled master that set its devices up: set up again
/// ([`Block::reset`], at the clocks [`EngineBuses::set_clocks`] kept), its interrupts off until a
/// script starts.
pub fn hand_over<const SLOTS: usize>(bus: &I2cBus<Registers, SLOTS>) {
    bus.with_block(|block| block.reset());
}
