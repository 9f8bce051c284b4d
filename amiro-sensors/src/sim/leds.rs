//! Simulated TLC5947 LED driver: a 288-bit shift register latched at the end of each transfer.

use core::convert::Infallible;

use embedded_hal::spi::{ErrorType, Operation, SpiDevice};

use crate::drivers::tlc5947::{CHANNELS, FRAME_BYTES, MAX_VALUE};

/// A simulated TLC5947 on its `SpiDevice`, chip select wired to XLAT.
///
/// Bytes shift through a 36-byte register (the oldest falls out, as on the part); when the
/// transaction ends the select line rises, XLAT latches, and [`SimLedDriver::output`] shows the
/// new values: the last 288 bits shifted in, the first of them on OUT23.
#[derive(Debug, Clone)]
pub struct SimLedDriver {
    shift: [u8; FRAME_BYTES],
    latches: u32,
    outputs: [u16; CHANNELS],
}

impl SimLedDriver {
    /// Every output at 0, nothing latched yet.
    pub const fn new() -> Self {
        Self {
            shift: [0; FRAME_BYTES],
            latches: 0,
            outputs: [0; CHANNELS],
        }
    }

    /// The latched value of OUT`out` (0..=23).
    pub fn output(&self, out: usize) -> Option<u16> {
        self.outputs.get(out).copied()
    }

    /// All latched values, OUT0 first.
    pub const fn outputs(&self) -> &[u16; CHANNELS] {
        &self.outputs
    }

    /// Latch pulses so far.
    pub const fn latches(&self) -> u32 {
        self.latches
    }

    fn shift_in(&mut self, byte: u8) {
        self.shift.copy_within(1.., 0);
        if let Some(last) = self.shift.last_mut() {
            *last = byte;
        }
    }

    fn latch(&mut self) {
        // Byte triple t holds OUT(23 - 2t) then OUT(22 - 2t), 12 bits each, MSB first.
        for (t, triple) in self.shift.chunks_exact(3).enumerate() {
            if let [b0, b1, b2] = *triple {
                let high = (u16::from(b0) << 4 | u16::from(b1) >> 4) & MAX_VALUE;
                let low = (u16::from(b1 & 0x0F) << 8 | u16::from(b2)) & MAX_VALUE;
                let top = CHANNELS - 1 - 2 * t;
                if let Some(slot) = self.outputs.get_mut(top) {
                    *slot = high;
                }
                if let Some(slot) = self.outputs.get_mut(top.wrapping_sub(1)) {
                    *slot = low;
                }
            }
        }
        self.latches = self.latches.wrapping_add(1);
    }
}

impl Default for SimLedDriver {
    fn default() -> Self {
        Self::new()
    }
}

impl ErrorType for SimLedDriver {
    type Error = Infallible;
}

impl SpiDevice for SimLedDriver {
    fn transaction(&mut self, operations: &mut [Operation<'_, u8>]) -> Result<(), Infallible> {
        for operation in operations {
            match operation {
                Operation::Write(bytes) => bytes.iter().for_each(|&b| self.shift_in(b)),
                Operation::Transfer(read, write) => {
                    // The part's SOUT is not wired on the ring; reads see zeros.
                    read.fill(0);
                    write.iter().for_each(|&b| self.shift_in(b));
                }
                Operation::TransferInPlace(buffer) => {
                    for byte in buffer.iter_mut() {
                        self.shift_in(*byte);
                        *byte = 0;
                    }
                }
                Operation::Read(buffer) => {
                    for byte in buffer.iter_mut() {
                        self.shift_in(0);
                        *byte = 0;
                    }
                }
                Operation::DelayNs(_) => {}
            }
        }
        self.latch();
        Ok(())
    }
}
