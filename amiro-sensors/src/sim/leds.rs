//! Simulated TLC5947 LED drivers, alone or chained: one shift register of 288 bits per part,
//! latched at the end of each transfer.

use core::convert::Infallible;

use embedded_hal::spi::{ErrorType, Operation, SpiDevice};

use crate::drivers::tlc5947::{CHANNELS, FRAME_BYTES, MAX_VALUE};

/// `CHIPS` simulated TLC5947 in a chain on one `SpiDevice`, chip select wired to every XLAT.
///
/// Bytes shift through the chain's `36 × CHIPS`-byte register (the oldest falls out of the last
/// part, as on the parts); when the transaction ends the select line rises, XLAT latches, and
/// [`SimLedChain::outputs`] shows the new values: the last `288 × CHIPS` bits shifted in, the first
/// of them on the last part's OUT23, the last on part 0's OUT0 (chain channel 0).
#[derive(Debug, Clone)]
pub struct SimLedChain<const CHIPS: usize> {
    shift: [[u8; FRAME_BYTES]; CHIPS],
    latches: u32,
    outputs: [[u16; CHANNELS]; CHIPS],
}

/// One simulated TLC5947 (LightRing 1-0).
pub type SimLedDriver = SimLedChain<1>;

impl<const CHIPS: usize> SimLedChain<CHIPS> {
    /// Every output at 0, nothing latched yet.
    pub const fn new() -> Self {
        Self {
            shift: [[0; FRAME_BYTES]; CHIPS],
            latches: 0,
            outputs: [[0; CHANNELS]; CHIPS],
        }
    }

    /// The latched value of chain channel `out` (0..24 × `CHIPS`).
    pub fn output(&self, out: usize) -> Option<u16> {
        self.outputs.as_flattened().get(out).copied()
    }

    /// All latched values, chain channel 0 (part 0's OUT0) first.
    pub fn outputs(&self) -> &[u16] {
        self.outputs.as_flattened()
    }

    /// Latch pulses so far.
    pub const fn latches(&self) -> u32 {
        self.latches
    }

    fn shift_in(&mut self, byte: u8) {
        let register = self.shift.as_flattened_mut();
        register.copy_within(1.., 0);
        if let Some(last) = register.last_mut() {
            *last = byte;
        }
    }

    fn latch(&mut self) {
        let top = CHANNELS * CHIPS - 1;
        let outputs = self.outputs.as_flattened_mut();
        // Byte triple t holds chain channels top − 2t then top − 2t − 1, 12 bits each, MSB first.
        for (t, triple) in self.shift.as_flattened().chunks_exact(3).enumerate() {
            if let [b0, b1, b2] = *triple {
                let high = (u16::from(b0) << 4 | u16::from(b1) >> 4) & MAX_VALUE;
                let low = (u16::from(b1 & 0x0F) << 8 | u16::from(b2)) & MAX_VALUE;
                let channel = top - 2 * t;
                if let Some(slot) = outputs.get_mut(channel) {
                    *slot = high;
                }
                if let Some(slot) = outputs.get_mut(channel.wrapping_sub(1)) {
                    *slot = low;
                }
            }
        }
        self.latches = self.latches.wrapping_add(1);
    }
}

impl<const CHIPS: usize> Default for SimLedChain<CHIPS> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const CHIPS: usize> ErrorType for SimLedChain<CHIPS> {
    type Error = Infallible;
}

impl<const CHIPS: usize> SpiDevice for SimLedChain<CHIPS> {
    fn transaction(&mut self, operations: &mut [Operation<'_, u8>]) -> Result<(), Infallible> {
        for operation in operations {
            match operation {
                Operation::Write(bytes) => bytes.iter().for_each(|&b| self.shift_in(b)),
                Operation::Transfer(read, write) => {
                    // The parts' SOUT is not wired back on the ring; reads see zeros.
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
