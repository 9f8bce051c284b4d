//! STMicroelectronics LIS331DLH three-axis accelerometer on 4-wire SPI (DiWheelDrive 1-1, SPI1,
//! CS PC13).
//!
//! Set-up follows the original firmware except for the range: CTRL_REG1 0x27 (normal mode, 50 Hz,
//! X/Y/Z on), CTRL_REG2 0, CTRL_REG3 0x82 (interrupt active low, INT1 = data ready), CTRL_REG5 0,
//! and CTRL_REG4 0x30 = ±8 g as issue 5 and the thesis's protocol specify (the 1.x firmware used
//! 0x10 = ±4 g). Output is 12 bits left-justified in 16; the datasheet's sensitivity (1 / 2 / 3.9
//! mg per digit at ±2 / ±4 / ±8 g) is per 12-bit digit, i.e. per 16 LSB of the raw register value.

use embedded_hal::spi::SpiDevice;

use super::{div_round_i32, saturate_i16, st_spi, Error};

/// Register addresses (datasheet register map).
pub mod reg {
    /// Device identification, reads [`super::WHO_AM_I_VALUE`].
    pub const WHO_AM_I: u8 = 0x0F;
    /// Power mode, data rate, axis enables.
    pub const CTRL_REG1: u8 = 0x20;
    /// Reboot and high-pass filter.
    pub const CTRL_REG2: u8 = 0x21;
    /// Interrupt pin polarity, drive and sources.
    pub const CTRL_REG3: u8 = 0x22;
    /// Block data update, endianness, full scale, self-test, SPI mode.
    pub const CTRL_REG4: u8 = 0x23;
    /// Sleep-to-wake.
    pub const CTRL_REG5: u8 = 0x24;
    /// Data-ready and overrun flags.
    pub const STATUS_REG: u8 = 0x27;
    /// First of six output bytes: X low, X high, Y low, Y high, Z low, Z high.
    pub const OUT_X_L: u8 = 0x28;
}

/// What WHO_AM_I reads on a LIS331DLH.
pub const WHO_AM_I_VALUE: u8 = 0x32;

/// CTRL_REG1: PM=001 (normal), DR=00 (50 Hz), Z/Y/X enabled.
pub const CTRL_REG1_RUN: u8 = 0x27;
/// CTRL_REG1: PM=000, power-down.
pub const CTRL_REG1_POWER_DOWN: u8 = 0x00;
/// CTRL_REG3: IHL=1 (active low), I1_CFG=10 (data ready on INT1).
pub const CTRL_REG3_DRDY_INT1: u8 = 0x82;

/// Full-scale range, CTRL_REG4 FS bits.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Range {
    /// ±2 g, 1 mg per 12-bit digit.
    G2,
    /// ±4 g, 2 mg per 12-bit digit (the 1.x firmware's setting).
    G4,
    /// ±8 g, 3.9 mg per 12-bit digit (issue 5, the protocol's stated scale).
    #[default]
    G8,
}

impl Range {
    /// CTRL_REG4 value for this range (BDU off, little-endian, no self-test, 4-wire SPI).
    pub const fn ctrl_reg4(self) -> u8 {
        match self {
            Range::G2 => 0x00,
            Range::G4 => 0x10,
            Range::G8 => 0x30,
        }
    }

    /// Sensitivity in micro-g per 12-bit digit (datasheet typical values).
    pub const fn micro_g_per_digit(self) -> i32 {
        match self {
            Range::G2 => 1_000,
            Range::G4 => 2_000,
            Range::G8 => 3_900,
        }
    }
}

/// One acceleration reading.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Acceleration {
    /// X, Y, Z in micro-g.
    pub micro_g: [i32; 3],
}

impl Acceleration {
    /// Converts the raw 16-bit register values (12 bits left-justified) at `range` to micro-g.
    pub const fn from_raw(raw: [i16; 3], range: Range) -> Self {
        let s = range.micro_g_per_digit();
        // Arithmetic shift keeps the sign; the four bits below the 12-bit result carry nothing.
        Self {
            micro_g: [
                (raw[0] >> 4) as i32 * s,
                (raw[1] >> 4) as i32 * s,
                (raw[2] >> 4) as i32 * s,
            ],
        }
    }

    /// X, Y, Z in milli-g, rounded to nearest: the protocol's unit.
    pub const fn milli_g(&self) -> [i16; 3] {
        let u = self.micro_g;
        [
            saturate_i16(div_round_i32(u[0], 1000) as i64),
            saturate_i16(div_round_i32(u[1], 1000) as i64),
            saturate_i16(div_round_i32(u[2], 1000) as i64),
        ]
    }
}

/// The bits of a control register that read back as written: CTRL_REG2 bit 7 (BOOT) clears
/// itself, every other bit stays.
fn writable(register: u8) -> u8 {
    if register == reg::CTRL_REG2 {
        0x7F
    } else {
        0xFF
    }
}

/// The accelerometer on its SPI device (the `SpiDevice` owns the chip select).
#[derive(Debug)]
pub struct Lis331dlh<SPI> {
    spi: SPI,
    range: Range,
}

impl<SPI: SpiDevice> Lis331dlh<SPI> {
    /// A driver at ±8 g. Does no I/O; call [`init`](Self::init).
    pub const fn new(spi: SPI) -> Self {
        Self::with_range(spi, Range::G8)
    }

    /// A driver at another range.
    pub const fn with_range(spi: SPI, range: Range) -> Self {
        Self { spi, range }
    }

    /// The configured range.
    pub const fn range(&self) -> Range {
        self.range
    }

    /// Checks WHO_AM_I, writes CTRL_REG1..5 in one burst and reads them back.
    pub fn init(&mut self) -> Result<(), Error<SPI::Error>> {
        self.check_identity()?;
        let config = self.control_registers();
        st_spi::configure(&mut self.spi, reg::CTRL_REG1, config, writable)
    }

    /// [`init`](Self::init)'s middle access: writes CTRL_REG1..5 (a stepwise set-up's step, after
    /// [`check_identity`](Self::check_identity); [`verify_configuration`](Self::verify_configuration)
    /// is the next).
    pub fn write_configuration(&mut self) -> Result<(), Error<SPI::Error>> {
        let config = self.control_registers();
        st_spi::write(&mut self.spi, reg::CTRL_REG1, config)?;
        Ok(())
    }

    /// [`init`](Self::init)'s last access: reads CTRL_REG1..5 back and compares them with what
    /// [`write_configuration`](Self::write_configuration) wrote.
    pub fn verify_configuration(&mut self) -> Result<(), Error<SPI::Error>> {
        let config = self.control_registers();
        st_spi::verify(&mut self.spi, reg::CTRL_REG1, config, writable)
    }

    /// Reads WHO_AM_I and compares it with [`WHO_AM_I_VALUE`].
    pub fn check_identity(&mut self) -> Result<(), Error<SPI::Error>> {
        st_spi::check_identity(&mut self.spi, reg::WHO_AM_I, WHO_AM_I_VALUE)
    }

    /// The five control register values [`init`](Self::init) writes.
    pub const fn control_registers(&self) -> [u8; 5] {
        [
            CTRL_REG1_RUN,
            0x00,
            CTRL_REG3_DRDY_INT1,
            self.range.ctrl_reg4(),
            0x00,
        ]
    }

    /// Reads the six output bytes in one burst: raw 16-bit X, Y, Z.
    pub fn read_raw(&mut self) -> Result<[i16; 3], Error<SPI::Error>> {
        st_spi::read_xyz(&mut self.spi, reg::OUT_X_L, reg::WHO_AM_I, WHO_AM_I_VALUE)
    }

    /// Reads and converts one acceleration sample.
    pub fn read(&mut self) -> Result<Acceleration, Error<SPI::Error>> {
        Ok(Acceleration::from_raw(self.read_raw()?, self.range))
    }

    /// Checks WHO_AM_I, then reads and converts one sample: the periodic identity check and the
    /// reading in one, whose bytes need no second identity check when they look like a stuck
    /// line (the part answered an access before; `st_spi::read_xyz_identified`).
    pub fn read_after_identity_check(&mut self) -> Result<Acceleration, Error<SPI::Error>> {
        self.check_identity()?;
        let raw = st_spi::read_xyz_identified(&mut self.spi, reg::OUT_X_L)?;
        Ok(Acceleration::from_raw(raw, self.range))
    }

    /// Powers the part down (CTRL_REG1 PM=000).
    pub fn power_down(&mut self) -> Result<(), Error<SPI::Error>> {
        st_spi::write(&mut self.spi, reg::CTRL_REG1, [CTRL_REG1_POWER_DOWN])?;
        Ok(())
    }

    /// The bus handle, e.g. for a test to reach a simulator's fault injection.
    pub fn bus_mut(&mut self) -> &mut SPI {
        &mut self.spi
    }

    /// Gives the SPI device back.
    pub fn release(self) -> SPI {
        self.spi
    }
}
