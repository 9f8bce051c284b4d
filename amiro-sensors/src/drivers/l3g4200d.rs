//! STMicroelectronics L3G4200D three-axis gyroscope on 4-wire SPI (DiWheelDrive 1-1, SPI1, CS PC14).
//!
//! Set-up is the original firmware's: CTRL_REG1 0x1F (100 Hz output, 25 Hz bandwidth, normal mode,
//! X/Y/Z on), CTRL_REG3 0x08 (data-ready on INT2), CTRL_REG4 0x10 (±500 dps), CTRL_REG2 and
//! CTRL_REG5 at their reset value 0. The five control registers are written in one
//! auto-increment burst and read back, so a part that did not take the range cannot report in the
//! wrong unit. At ±500 dps one digit is 17.5 mdps (datasheet, "So" sensitivity).

use embedded_hal::spi::SpiDevice;

use super::{div_round_i32, saturate_i16, st_spi, Error};

/// Register addresses (datasheet register map).
pub mod reg {
    /// Device identification, reads [`super::WHO_AM_I_VALUE`].
    pub const WHO_AM_I: u8 = 0x0F;
    /// Output data rate, bandwidth, power mode, axis enables.
    pub const CTRL_REG1: u8 = 0x20;
    /// High-pass filter set-up.
    pub const CTRL_REG2: u8 = 0x21;
    /// Interrupt pin routing.
    pub const CTRL_REG3: u8 = 0x22;
    /// Block data update, endianness, full scale, self-test, SPI mode.
    pub const CTRL_REG4: u8 = 0x23;
    /// Reboot, FIFO, high-pass and output selection.
    pub const CTRL_REG5: u8 = 0x24;
    /// Temperature, one signed byte.
    pub const OUT_TEMP: u8 = 0x26;
    /// Data-ready and overrun flags.
    pub const STATUS_REG: u8 = 0x27;
    /// First of six output bytes: X low, X high, Y low, Y high, Z low, Z high (two's complement).
    pub const OUT_X_L: u8 = 0x28;
}

/// What WHO_AM_I reads on an L3G4200D.
pub const WHO_AM_I_VALUE: u8 = 0xD3;

/// CTRL_REG1 in operation: ODR 100 Hz, cut-off 25 Hz (DR=00, BW=01), PD=1, Z/Y/X enabled.
pub const CTRL_REG1_RUN: u8 = 0x1F;
/// CTRL_REG1 asleep: powered with all axes off (the datasheet's sleep mode, fast wake-up).
pub const CTRL_REG1_SLEEP: u8 = 0x18;
/// CTRL_REG3: data-ready on INT2 (the board routes INT2 to PB13).
pub const CTRL_REG3_DRDY_INT2: u8 = 0x08;

/// Full-scale range, CTRL_REG4 FS bits.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Range {
    /// ±250 dps, 8.75 mdps/digit.
    Dps250,
    /// ±500 dps, 17.5 mdps/digit (the AMiRo setting).
    #[default]
    Dps500,
    /// ±2000 dps, 70 mdps/digit.
    Dps2000,
}

impl Range {
    /// CTRL_REG4 value for this range (BDU off, little-endian, no self-test, 4-wire SPI).
    pub const fn ctrl_reg4(self) -> u8 {
        match self {
            Range::Dps250 => 0x00,
            Range::Dps500 => 0x10,
            Range::Dps2000 => 0x20,
        }
    }

    /// Sensitivity in micro-degrees per second per digit.
    pub const fn micro_dps_per_digit(self) -> i32 {
        match self {
            Range::Dps250 => 8_750,
            Range::Dps500 => 17_500,
            Range::Dps2000 => 70_000,
        }
    }
}

/// One angular-rate reading.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct AngularRate {
    /// X, Y, Z in millidegrees per second.
    pub millidegrees_per_s: [i32; 3],
}

impl AngularRate {
    /// Converts raw output digits at `range` to millidegrees per second.
    ///
    /// Every sensitivity is a whole number of 250 µdps (8 750, 17 500, 70 000), so `raw × s / 1000`
    /// rounded is `raw × (s / 250) / 4` rounded, the same value in 32 bits (|raw × s / 250| <
    /// 2^24): no 64-bit division on the chip.
    pub const fn from_raw(raw: [i16; 3], range: Range) -> Self {
        let k = range.micro_dps_per_digit() / 250;
        Self {
            millidegrees_per_s: [
                div_round_i32(raw[0] as i32 * k, 4),
                div_round_i32(raw[1] as i32 * k, 4),
                div_round_i32(raw[2] as i32 * k, 4),
            ],
        }
    }

    /// X, Y, Z in whole degrees per second, rounded to nearest: the protocol's unit.
    pub const fn degrees_per_s(&self) -> [i16; 3] {
        let m = self.millidegrees_per_s;
        [
            saturate_i16(div_round_i32(m[0], 1000) as i64),
            saturate_i16(div_round_i32(m[1], 1000) as i64),
            saturate_i16(div_round_i32(m[2], 1000) as i64),
        ]
    }
}

/// The gyroscope on its SPI device (the `SpiDevice` owns the chip select).
#[derive(Debug)]
pub struct L3g4200d<SPI> {
    spi: SPI,
    range: Range,
}

impl<SPI: SpiDevice> L3g4200d<SPI> {
    /// A driver at the AMiRo's ±500 dps. Does no I/O; call [`init`](Self::init).
    pub const fn new(spi: SPI) -> Self {
        Self::with_range(spi, Range::Dps500)
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
        st_spi::configure(&mut self.spi, reg::CTRL_REG1, config, |_| 0xFF)
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
        st_spi::verify(&mut self.spi, reg::CTRL_REG1, config, |_| 0xFF)
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
            CTRL_REG3_DRDY_INT2,
            self.range.ctrl_reg4(),
            0x00,
        ]
    }

    /// Reads the six output bytes in one burst: raw X, Y, Z digits.
    pub fn read_raw(&mut self) -> Result<[i16; 3], Error<SPI::Error>> {
        st_spi::read_xyz(&mut self.spi, reg::OUT_X_L, reg::WHO_AM_I, WHO_AM_I_VALUE)
    }

    /// Reads and converts one angular-rate sample.
    pub fn read(&mut self) -> Result<AngularRate, Error<SPI::Error>> {
        Ok(AngularRate::from_raw(self.read_raw()?, self.range))
    }

    /// Checks WHO_AM_I, then reads and converts one sample: the periodic identity check and the
    /// reading in one, whose bytes need no second identity check when they look like a stuck
    /// line (the part answered an access before; `st_spi::read_xyz_identified`).
    pub fn read_after_identity_check(&mut self) -> Result<AngularRate, Error<SPI::Error>> {
        self.check_identity()?;
        let raw = st_spi::read_xyz_identified(&mut self.spi, reg::OUT_X_L)?;
        Ok(AngularRate::from_raw(raw, self.range))
    }

    /// Puts the part into sleep mode (axes off, powered), as the original firmware did on
    /// shutdown.
    pub fn sleep(&mut self) -> Result<(), Error<SPI::Error>> {
        st_spi::write(&mut self.spi, reg::CTRL_REG1, [CTRL_REG1_SLEEP])?;
        Ok(())
    }

    /// Wakes the part from [`sleep`](Self::sleep).
    pub fn wake(&mut self) -> Result<(), Error<SPI::Error>> {
        st_spi::write(&mut self.spi, reg::CTRL_REG1, [CTRL_REG1_RUN])?;
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
