//! The register protocol STMicroelectronics' motion sensors share on 4-wire SPI (L3G4200D,
//! LIS331DLH): one command byte, then data, all inside one chip-select assertion.
//!
//! Command byte: bit 7 = read (1) / write (0), bit 6 = auto-increment the register address after
//! every byte (needed for multi-byte access), bits 5..0 = register address.

use embedded_hal::spi::{Operation, SpiDevice};

use super::{check_register, Error};

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

/// Reads the identity register and compares it with `expected`.
pub(crate) fn check_identity<S: SpiDevice>(
    spi: &mut S,
    register: u8,
    expected: u8,
) -> Result<(), Error<S::Error>> {
    let mut id = [0u8];
    read(spi, register, &mut id)?;
    if id[0] == expected {
        Ok(())
    } else {
        Err(Error::WrongIdentity {
            expected: expected.into(),
            found: id[0].into(),
        })
    }
}

/// Writes the five control registers from `first` in one burst and reads them back;
/// `writable(register)` gives the bits of that register that read back as written.
pub(crate) fn configure<S: SpiDevice>(
    spi: &mut S,
    first: u8,
    config: [u8; 5],
    writable: impl Fn(u8) -> u8,
) -> Result<(), Error<S::Error>> {
    write(spi, first, &config)?;
    let mut readback = [0u8; 5];
    read(spi, first, &mut readback)?;
    for ((register, written), read) in (first..).zip(config).zip(readback) {
        check_register(register, written, read, writable(register))?;
    }
    Ok(())
}

/// Reads the six output bytes from `first` in one burst: X, Y, Z as little-endian `i16`.
///
/// Six bytes of all `0x00` or all `0xFF` are what a stuck MISO line returns: then the identity
/// register `who_am_i` is read once more, and only a part that still answers `expected` gets its
/// reading through (a dead line reads its stuck level there too: [`Error::WrongIdentity`]).
pub(crate) fn read_xyz<S: SpiDevice>(
    spi: &mut S,
    first: u8,
    who_am_i: u8,
    expected: u8,
) -> Result<[i16; 3], Error<S::Error>> {
    let mut out = [0u8; 6];
    read(spi, first, &mut out)?;
    if super::is_bus_pattern(&out) {
        check_identity(spi, who_am_i, expected)?;
    }
    Ok([
        i16::from_le_bytes([out[0], out[1]]),
        i16::from_le_bytes([out[2], out[3]]),
        i16::from_le_bytes([out[4], out[5]]),
    ])
}
