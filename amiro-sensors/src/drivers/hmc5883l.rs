//! Honeywell HMC5883L three-axis magnetometer on I2C (DiWheelDrive 1-1, I2C1, address 0x1E).
//!
//! Set-up is the original firmware's: CRA 0x74 (8-sample average, 30 Hz output, normal
//! measurement), CRB 0xA0 (gain ±4.7 Ga, 390 LSB/Gauss), MODE 0x00 (continuous). Each register is
//! written in its own transfer and the three are read back. The data registers come in the order
//! X, **Z**, Y, big-endian; an axis reads -4096 when the field exceeds the gain's range, which this
//! driver reports as [`Error::Overflow`] instead of a wrong number. Output is in nanotesla
//! (1 Gauss = 100 µT = 100 000 nT), the protocol's magnetometer unit.

use embedded_hal::i2c::I2c;

use super::{check_register, div_round, Axis, Error};

/// The part's fixed 7-bit address.
pub const ADDRESS: u8 = 0x1E;

/// Register addresses (datasheet register map). The pointer auto-increments, wrapping from 0x08
/// back to 0x03 so a host can re-read the six data bytes.
pub mod reg {
    /// Configuration register A: averaging, output rate, measurement mode.
    pub const CONFIG_A: u8 = 0x00;
    /// Configuration register B: gain (bits 7..5).
    pub const CONFIG_B: u8 = 0x01;
    /// Mode register: continuous / single / idle.
    pub const MODE: u8 = 0x02;
    /// First data byte, X MSB; then X LSB, Z MSB, Z LSB, Y MSB, Y LSB.
    pub const DATA_X_MSB: u8 = 0x03;
    /// Status: data-ready and lock flags.
    pub const STATUS: u8 = 0x09;
    /// Identification A, B, C: 'H', '4', '3'.
    pub const IDENTIFICATION_A: u8 = 0x0A;
}

/// The identification registers' contents, "H43".
pub const IDENTITY: [u8; 3] = *b"H43";
/// What an axis reads when its measurement overflowed.
pub const OVERFLOW: i16 = -4096;
/// CRA: MA=11 (8 samples averaged), DO=101 (30 Hz), MS=00 (normal). The 1.x source calls this
/// rate "20 Hz"; the datasheet's table says 30 Hz.
pub const CONFIG_A_AMIRO: u8 = 0x74;
/// MODE: continuous measurement.
pub const MODE_CONTINUOUS: u8 = 0x00;
/// MODE: idle.
pub const MODE_IDLE: u8 = 0x03;

/// Gain setting, CRB bits 7..5 (datasheet gain table).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Gain {
    /// ±0.88 Ga, 1370 LSB/Ga.
    Ga0_88,
    /// ±1.3 Ga, 1090 LSB/Ga (power-on default).
    Ga1_3,
    /// ±1.9 Ga, 820 LSB/Ga.
    Ga1_9,
    /// ±2.5 Ga, 660 LSB/Ga.
    Ga2_5,
    /// ±4.0 Ga, 440 LSB/Ga.
    Ga4_0,
    /// ±4.7 Ga, 390 LSB/Ga (the AMiRo setting, CRB 0xA0).
    #[default]
    Ga4_7,
    /// ±5.6 Ga, 330 LSB/Ga.
    Ga5_6,
    /// ±8.1 Ga, 230 LSB/Ga.
    Ga8_1,
}

impl Gain {
    /// The CRB value for this gain.
    pub const fn config_b(self) -> u8 {
        let bits = match self {
            Gain::Ga0_88 => 0,
            Gain::Ga1_3 => 1,
            Gain::Ga1_9 => 2,
            Gain::Ga2_5 => 3,
            Gain::Ga4_0 => 4,
            Gain::Ga4_7 => 5,
            Gain::Ga5_6 => 6,
            Gain::Ga8_1 => 7,
        };
        bits << 5
    }

    /// Digits per Gauss.
    pub const fn lsb_per_gauss(self) -> i32 {
        match self {
            Gain::Ga0_88 => 1370,
            Gain::Ga1_3 => 1090,
            Gain::Ga1_9 => 820,
            Gain::Ga2_5 => 660,
            Gain::Ga4_0 => 440,
            Gain::Ga4_7 => 390,
            Gain::Ga5_6 => 330,
            Gain::Ga8_1 => 230,
        }
    }
}

/// Nanotesla per Gauss.
pub const NANOTESLA_PER_GAUSS: i32 = 100_000;

/// One magnetic-field reading.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct MagneticField {
    /// X, Y, Z in nanotesla (note: in X, Y, Z order, not the register order).
    pub nanotesla: [i32; 3],
}

impl MagneticField {
    /// Converts raw X, Y, Z digits at `gain`; -4096 on any axis is an overflow.
    pub fn from_raw<E>(raw: [i16; 3], gain: Gain) -> Result<Self, Error<E>> {
        let mut nanotesla = [0i32; 3];
        for ((out, digits), axis) in nanotesla.iter_mut().zip(raw).zip(Axis::ALL) {
            if digits == OVERFLOW {
                return Err(Error::Overflow { axis });
            }
            *out = div_round(
                i64::from(digits) * i64::from(NANOTESLA_PER_GAUSS),
                i64::from(gain.lsb_per_gauss()),
            ) as i32;
        }
        Ok(Self { nanotesla })
    }

    /// One axis in nanotesla.
    pub const fn axis(&self, axis: Axis) -> i32 {
        self.nanotesla[axis.index()]
    }
}

/// The magnetometer on its I2C bus.
#[derive(Debug, Clone)]
pub struct Hmc5883l<I2C> {
    i2c: I2C,
    gain: Gain,
}

impl<I2C> Hmc5883l<I2C> {
    /// A driver at the AMiRo's gain (±4.7 Ga). Does no I/O; call [`init`](Self::init).
    pub const fn new(i2c: I2C) -> Self {
        Self::with_gain(i2c, Gain::Ga4_7)
    }

    /// A driver at another gain.
    pub const fn with_gain(i2c: I2C, gain: Gain) -> Self {
        Self { i2c, gain }
    }

    /// The configured gain.
    pub const fn gain(&self) -> Gain {
        self.gain
    }
}
impl<I2C: I2c> Hmc5883l<I2C> {
    /// Checks the identification registers, writes CRA, CRB and MODE, and reads them back.
    /// The datasheet notes the first measurement after a gain change still uses the old gain; in
    /// continuous mode that sample is gone long before the first publisher asks (33 ms at 30 Hz).
    pub fn init(&mut self) -> Result<(), Error<I2C::Error>> {
        self.check_identity()?;
        let readback = ops::set_up(&mut crate::script::Blocking(&mut self.i2c), self.gain)?;
        check_set_up(set_up_values(self.gain), readback)
    }

    /// Reads the three identification registers and compares them with "H43".
    pub fn check_identity(&mut self) -> Result<(), Error<I2C::Error>> {
        let mut id = [0u8; 3];
        self.i2c
            .write_read(ADDRESS, &[reg::IDENTIFICATION_A], &mut id)?;
        identity(id)
    }

    /// Reads the six data bytes in one transfer: raw X, Y, Z digits (reordered from X, Z, Y).
    ///
    /// Six bytes of all `0x00` or all `0xFF` (a dead bus, or a part that lost its configuration
    /// and stopped measuring) are passed on only after the identification registers still read
    /// "H43" ([`Error::WrongIdentity`] otherwise).
    pub fn read_raw(&mut self) -> Result<[i16; 3], Error<I2C::Error>> {
        let mut out = [0u8; 6];
        self.i2c.write_read(ADDRESS, &[reg::DATA_X_MSB], &mut out)?;
        if super::is_bus_pattern(&out) {
            self.check_identity()?;
        }
        Ok(raw_field(out))
    }

    /// Reads and converts one field sample.
    pub fn read(&mut self) -> Result<MagneticField, Error<I2C::Error>> {
        MagneticField::from_raw(self.read_raw()?, self.gain)
    }

    /// Stops measuring (MODE idle).
    pub fn idle(&mut self) -> Result<(), Error<I2C::Error>> {
        self.i2c.write(ADDRESS, &[reg::MODE, MODE_IDLE])?;
        Ok(())
    }

    /// The bus handle, e.g. for a test to reach a simulator's fault injection.
    pub fn bus_mut(&mut self) -> &mut I2C {
        &mut self.i2c
    }

    /// Gives the bus back.
    pub fn release(self) -> I2C {
        self.i2c
    }
}

fn pack3(bytes: [u8; 3]) -> u32 {
    u32::from_be_bytes([0, bytes[0], bytes[1], bytes[2]])
}

/// CRA, CRB and MODE as the set-up writes them at `gain` (the AMiRo's: 0x74, 0xA0, 0x00).
pub const fn set_up_values(gain: Gain) -> [u8; 3] {
    [CONFIG_A_AMIRO, gain.config_b(), MODE_CONTINUOUS]
}

/// The set-up's read-back of CRA, CRB and MODE checked against `config` on the bits the part
/// lets a host write.
#[inline(always)]
pub fn check_set_up<E>(config: [u8; 3], readback: [u8; 3]) -> Result<(), Error<E>> {
    // CRA bit 7 must stay clear; CRB bits 4..0 and MODE bits 6..2 read back as zero.
    let writable = [0x7F, 0xE0, 0x83];
    for (((register, written), read), mask) in
        (reg::CONFIG_A..).zip(config).zip(readback).zip(writable)
    {
        check_register(register, written, read, mask)?;
    }
    Ok(())
}

/// The identification registers' three bytes: "H43", or [`Error::WrongIdentity`].
pub fn identity<E>(id: [u8; 3]) -> Result<(), Error<E>> {
    if id == IDENTITY {
        Ok(())
    } else {
        Err(Error::WrongIdentity {
            expected: pack3(IDENTITY),
            found: pack3(id),
        })
    }
}

/// The six data registers (X, Z, Y, each MSB first) as raw X, Y, Z digits.
pub const fn raw_field(out: [u8; 6]) -> [i16; 3] {
    let x = i16::from_be_bytes([out[0], out[1]]);
    let z = i16::from_be_bytes([out[2], out[3]]);
    let y = i16::from_be_bytes([out[4], out[5]]);
    [x, y, z]
}

/// The part's transactions as script operations (the same registers the blocking driver above
/// reads and writes, decoded by the same functions).
pub mod ops {
    use super::{reg, set_up_values, Gain, ADDRESS};
    use crate::script::{BuildError, Script, Transfers};

    /// The identification registers: write 0x0A, read 3 ([`super::identity`]).
    pub fn identity(script: &mut Script) -> Result<(), BuildError> {
        script.write_read(ADDRESS, &[reg::IDENTIFICATION_A], 3)?;
        Ok(())
    }

    /// The six data registers: write 0x03, read 6 ([`super::raw_field`]).
    pub fn data(script: &mut Script) -> Result<(), BuildError> {
        script.write_read(ADDRESS, &[reg::DATA_X_MSB], 6)?;
        Ok(())
    }

    /// The set-up's three register writes (one transfer each) and their read-back, read 3 from
    /// CRA ([`super::check_set_up`]): [`super::Hmc5883l::init`]'s and the scripted set-up's.
    #[inline(always)]
    pub fn set_up<T: Transfers>(bus: &mut T, gain: Gain) -> Result<T::Read<3>, T::Error> {
        for (register, value) in (reg::CONFIG_A..).zip(set_up_values(gain)) {
            bus.send(ADDRESS, &[register, value])?;
        }
        bus.fetch::<3>(ADDRESS, &[reg::CONFIG_A])
    }
}
