//! The register protocol STMicroelectronics' motion sensors share on 4-wire SPI (L3G4200D,
//! LIS331DLH): one command byte, then data, all inside one chip-select assertion.
//!
//! Command byte: bit 7 = read (1) / write (0), bit 6 = auto-increment the register address after
//! every byte (needed for multi-byte access), bits 5..0 = register address.
//!
//! Every access is one `Operation::TransferInPlace` of the command byte and its data: the same
//! bytes on the wire as a write of the command then a read or write of the data, and one operation
//! of at most [`MAX_DATA`] + 1 bytes for the execution-time bound of the device's transaction, whose
//! machine code cannot tell which kind each of several operations is (docs/analysis.md, the
//! bounds file's SPI statements).

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

/// Most data bytes one access moves: [`read_xyz`]'s six output registers.
pub(crate) const MAX_DATA: usize = 6;

/// One access of `N` data bytes: the command byte, then `data` out (a write) or dummy bytes out and
/// the registers in (a read; `data` holds zeros), in one chip-select assertion; what came in
/// during the data bytes is returned.
fn access<S: SpiDevice, const N: usize>(
    spi: &mut S,
    command: u8,
    data: [u8; N],
) -> Result<[u8; N], S::Error> {
    const { assert!(N >= 1 && N <= MAX_DATA) };
    let mut buffer = [0u8; MAX_DATA + 1];
    // N ≤ MAX_DATA (checked above at compile time): the ranges are in bounds.
    let frame = &mut buffer[..=N];
    frame[0] = command;
    frame[1..].copy_from_slice(&data);
    spi.transaction(&mut [Operation::TransferInPlace(frame)])?;
    let mut answer = [0u8; N];
    answer.copy_from_slice(&frame[1..]);
    Ok(answer)
}

/// Reads `N` consecutive registers starting at `register`.
pub(crate) fn read<S: SpiDevice, const N: usize>(
    spi: &mut S,
    register: u8,
) -> Result<[u8; N], S::Error> {
    access(spi, command(register, true, N), [0; N])
}

/// Writes `data` to consecutive registers starting at `register`.
pub(crate) fn write<S: SpiDevice, const N: usize>(
    spi: &mut S,
    register: u8,
    data: [u8; N],
) -> Result<(), S::Error> {
    access(spi, command(register, false, N), data).map(|_| ())
}

/// Reads the identity register and compares it with `expected`.
pub(crate) fn check_identity<S: SpiDevice>(
    spi: &mut S,
    register: u8,
    expected: u8,
) -> Result<(), Error<S::Error>> {
    let [id] = read::<S, 1>(spi, register)?;
    if id == expected {
        Ok(())
    } else {
        Err(Error::WrongIdentity {
            expected: expected.into(),
            found: id.into(),
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
    write(spi, first, config)?;
    verify(spi, first, config, writable)
}

/// Reads the five control registers from `first` back and compares them with `config` on the
/// bits `writable(register)` gives ([`configure`]'s second half).
pub(crate) fn verify<S: SpiDevice>(
    spi: &mut S,
    first: u8,
    config: [u8; 5],
    writable: impl Fn(u8) -> u8,
) -> Result<(), Error<S::Error>> {
    let readback: [u8; 5] = read(spi, first)?;
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
    let out: [u8; 6] = read(spi, first)?;
    if stuck(&out) {
        check_identity(spi, who_am_i, expected)?;
    }
    Ok(xyz(out))
}

/// Reads the six output bytes from `first` as [`read_xyz`] does, for a part whose identity was
/// checked just before in the same sample: a bus pattern then is a real reading (the line
/// answered the identity an access earlier), so it is not checked again.
pub(crate) fn read_xyz_identified<S: SpiDevice>(
    spi: &mut S,
    first: u8,
) -> Result<[i16; 3], Error<S::Error>> {
    Ok(xyz(read(spi, first)?))
}

/// [`super::is_bus_pattern`] of the six output bytes, over their fixed length: its loop has a count
/// the machine code shows wherever the compiler puts it (the outliner moved the shared function's
/// call, with its length, into a helper with no line for a bounds file to name).
fn stuck(out: &[u8; 6]) -> bool {
    (out[0] == 0x00 || out[0] == 0xFF) && out.iter().all(|&byte| byte == out[0])
}

/// X, Y, Z from the six output bytes, each little-endian `i16`.
fn xyz(out: [u8; 6]) -> [i16; 3] {
    [
        i16::from_le_bytes([out[0], out[1]]),
        i16::from_le_bytes([out[2], out[3]]),
        i16::from_le_bytes([out[4], out[5]]),
    ]
}
