//! The register protocol STMicroelectronics' motion sensors share on 4-wire SPI (L3G4200D,
//! LIS331DLH): one command byte, then data, all inside one chip-select assertion.
//!
//! Command byte: bit 7 = read (1) / write (0), bit 6 = auto-increment the register address after
//! every byte (needed for multi-byte access), bits 5..0 = register address.

use embedded_hal::spi::{Operation, SpiDevice};

/// Command bit 7: read.
pub(crate) const READ: u8 = 0x80;
/// Command bit 6: advance the register address after each byte.
pub(crate) const AUTO_INCREMENT: u8 = 0x40;
/// Register addresses are six bits.
pub(crate) const ADDRESS_MASK: u8 = 0x3F;

/// The command byte for an access of `len` bytes starting at `register`.
pub(crate) const fn command(register: u8, read: bool, len: usize) -> u8 {
    let mut byte = register & ADDRESS_MASK;
    if read {
        byte |= READ;
    }
    if len > 1 {
        byte |= AUTO_INCREMENT;
    }
    byte
}

/// Reads `buffer.len()` consecutive registers starting at `register`.
pub(crate) fn read<S: SpiDevice>(
    spi: &mut S,
    register: u8,
    buffer: &mut [u8],
) -> Result<(), S::Error> {
    let cmd = [command(register, true, buffer.len())];
    spi.transaction(&mut [Operation::Write(&cmd), Operation::Read(buffer)])
}

/// Writes `data` to consecutive registers starting at `register`.
pub(crate) fn write<S: SpiDevice>(spi: &mut S, register: u8, data: &[u8]) -> Result<(), S::Error> {
    let cmd = [command(register, false, data.len())];
    spi.transaction(&mut [Operation::Write(&cmd), Operation::Write(data)])
}
