//! Vishay VCNL4020 proximity and ambient-light sensor on I2C (address 0x13): the DiWheelDrive's four
//! floor sensors and the PowerManagement's eight ring sensors, all behind PCA9544A multiplexers
//! because every part has the same fixed address.
//!
//! Set-up is the original firmware's values, written in the order the datasheet asks for (rates
//! are only writable while self-timed measurement is off): COMMAND 0x00, PROX_RATE 0x06 (125
//! measurements/s), LED_CURRENT 20 (200 mA), AMBIENT_PARAMETER 0x15 (2 ALS measurements/s, 32
//! averaged, auto offset off), then COMMAND 0x07 (self-timed, proximity and ALS on). Each register
//! is written and read back on its own: single-byte transfers are what every VCNL4020 host
//! supports, and set-up runs once.
//!
//! Results are 16-bit big-endian counts: proximity (raw reflected IR, larger = nearer, not a
//! distance — see [`super::proximity`]) and ambient light (0.25 lx per count).

use embedded_hal::i2c::I2c;

use super::{check_register, Error};

/// The part's fixed 7-bit address.
pub const ADDRESS: u8 = 0x13;

/// Register addresses (datasheet register map).
pub mod reg {
    /// Command: enables, on-demand triggers, data-ready flags.
    pub const COMMAND: u8 = 0x80;
    /// Product ID (high nibble) and revision (low nibble).
    pub const PRODUCT_ID: u8 = 0x81;
    /// Proximity measurement rate (bits 2..0).
    pub const PROXIMITY_RATE: u8 = 0x82;
    /// IR LED current in 10 mA steps (bits 5..0; bits 7..6 are a read-only fuse ID).
    pub const LED_CURRENT: u8 = 0x83;
    /// Ambient-light parameters: continuous mode, rate, auto offset, averaging.
    pub const AMBIENT_PARAMETER: u8 = 0x84;
    /// Ambient-light result, high byte then low byte.
    pub const AMBIENT_RESULT: u8 = 0x85;
    /// Proximity result, high byte then low byte.
    pub const PROXIMITY_RESULT: u8 = 0x87;
}

/// What the product-ID register reads (product 2, revision 1).
pub const PRODUCT_ID_VALUE: u8 = 0x21;
/// COMMAND: self-timed measurements with proximity and ambient light enabled.
pub const COMMAND_SELF_TIMED: u8 = 0x07;
/// COMMAND: everything off.
pub const COMMAND_OFF: u8 = 0x00;
/// Millilux per ambient count (datasheet: 0.25 lx/count).
pub const MILLILUX_PER_COUNT: u32 = 250;

/// Register values for set-up.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Config {
    /// PROX_RATE code 0..=7 (1.95 to 250 measurements/s; 6 = 125/s).
    pub proximity_rate: u8,
    /// LED current in 10 mA steps, 0..=20 (20 = 200 mA).
    pub led_current: u8,
    /// AMBIENT_PARAMETER register value.
    pub ambient_parameter: u8,
}

impl Config {
    /// The AMiRo 1.x firmware's values.
    pub const AMIRO: Config = Config {
        proximity_rate: 0x06,
        led_current: 20,
        ambient_parameter: 0x15,
    };
}

impl Default for Config {
    fn default() -> Self {
        Self::AMIRO
    }
}

/// One proximity and ambient-light reading.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Reading {
    /// Proximity counts (reflected IR; grows as an object comes nearer).
    pub proximity: u16,
    /// Ambient-light counts (0.25 lx each).
    pub ambient: u16,
}

impl Reading {
    /// Ambient light in millilux.
    pub const fn ambient_millilux(&self) -> u32 {
        self.ambient as u32 * MILLILUX_PER_COUNT
    }
}

/// One VCNL4020 on an I2C bus (or on a [`super::pca9544a::MuxedBus`] channel).
#[derive(Debug)]
pub struct Vcnl4020<I2C> {
    i2c: I2C,
}

impl<I2C: I2c> Vcnl4020<I2C> {
    /// A driver for the part at [`ADDRESS`]. Does no I/O.
    pub const fn new(i2c: I2C) -> Self {
        Self { i2c }
    }

    /// Checks the product ID, writes and verifies the configuration, then starts self-timed
    /// measurement.
    pub fn init(&mut self, config: &Config) -> Result<(), Error<I2C::Error>> {
        self.check_identity()?;
        let [off, rate, current, ambient, on] = set_up_writes(config);
        self.write_checked(off)?;
        self.write_checked(rate)?;
        self.write_checked(current)?;
        self.write_checked(ambient)?;
        self.write_checked(on)
    }

    /// Reads the product-ID register and compares it with [`PRODUCT_ID_VALUE`].
    pub fn check_identity(&mut self) -> Result<(), Error<I2C::Error>> {
        identity(self.read_register(reg::PRODUCT_ID)?)
    }

    /// The latest proximity result in counts.
    pub fn read_proximity(&mut self) -> Result<u16, Error<I2C::Error>> {
        self.read_result(reg::PROXIMITY_RESULT)
    }

    /// The latest ambient-light result in counts.
    pub fn read_ambient(&mut self) -> Result<u16, Error<I2C::Error>> {
        self.read_result(reg::AMBIENT_RESULT)
    }

    /// Both results (two transfers: proximity, then ambient).
    pub fn read(&mut self) -> Result<Reading, Error<I2C::Error>> {
        let proximity = self.read_proximity()?;
        let ambient = self.read_ambient()?;
        Ok(Reading { proximity, ambient })
    }

    /// Stops self-timed measurement (the LED stops pulsing).
    pub fn stop(&mut self) -> Result<(), Error<I2C::Error>> {
        self.i2c.write(ADDRESS, &[reg::COMMAND, COMMAND_OFF])?;
        Ok(())
    }

    /// Gives the bus back.
    pub fn release(self) -> I2C {
        self.i2c
    }

    fn read_register(&mut self, register: u8) -> Result<u8, Error<I2C::Error>> {
        let mut value = [0u8];
        self.i2c.write_read(ADDRESS, &[register], &mut value)?;
        Ok(value[0])
    }

    /// A two-byte result; `0x0000` or `0xFFFF` (a dead line, or a part that reset and stopped
    /// measuring) only after PRODUCT_ID still answers.
    fn read_result(&mut self, high_register: u8) -> Result<u16, Error<I2C::Error>> {
        let mut value = [0u8; 2];
        self.i2c.write_read(ADDRESS, &[high_register], &mut value)?;
        if super::is_bus_pattern(&value) {
            self.check_identity()?;
        }
        Ok(result(value))
    }

    fn write_checked(&mut self, write: SetUpWrite) -> Result<(), Error<I2C::Error>> {
        let [read] = ops::set_up_write(&mut crate::script::Blocking(&mut self.i2c), write)?;
        write.check(read)
    }
}

/// One register of the set-up: written, then read back and compared on its writable bits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SetUpWrite {
    /// The register.
    pub register: u8,
    /// The value written.
    pub value: u8,
    /// The bits that read back as written.
    pub writable: u8,
}

impl SetUpWrite {
    /// The read-back `read` checked against the value written.
    pub fn check<E>(self, read: u8) -> Result<(), Error<E>> {
        check_register(self.register, self.value, read, self.writable)
    }
}

/// The set-up's five register writes in the datasheet's order (rates only while self-timed
/// measurement is off): COMMAND off, PROX_RATE, LED_CURRENT, AMBIENT_PARAMETER, COMMAND on.
pub const fn set_up_writes(config: &Config) -> [SetUpWrite; 5] {
    [
        SetUpWrite {
            register: reg::COMMAND,
            value: COMMAND_OFF,
            writable: 0x07,
        },
        SetUpWrite {
            register: reg::PROXIMITY_RATE,
            value: config.proximity_rate,
            writable: 0x07,
        },
        SetUpWrite {
            register: reg::LED_CURRENT,
            value: config.led_current,
            writable: 0x3F,
        },
        SetUpWrite {
            register: reg::AMBIENT_PARAMETER,
            value: config.ambient_parameter,
            writable: 0xFF,
        },
        // Bits 7..3 of COMMAND are the read-only lock and data-ready flags and the self-clearing
        // on-demand triggers; only the three enables read back as written.
        SetUpWrite {
            register: reg::COMMAND,
            value: COMMAND_SELF_TIMED,
            writable: 0x07,
        },
    ]
}

/// PRODUCT_ID's byte: [`PRODUCT_ID_VALUE`], or [`Error::WrongIdentity`].
pub fn identity<E>(id: u8) -> Result<(), Error<E>> {
    if id == PRODUCT_ID_VALUE {
        Ok(())
    } else {
        Err(Error::WrongIdentity {
            expected: PRODUCT_ID_VALUE.into(),
            found: id.into(),
        })
    }
}

/// A result register pair (high byte first) as counts.
pub const fn result(bytes: [u8; 2]) -> u16 {
    u16::from_be_bytes(bytes)
}

/// The part's transactions as script operations (decoded by the functions above).
pub mod ops {
    use super::{reg, SetUpWrite, ADDRESS};
    use crate::script::{BuildError, Script, Transfers};

    /// PRODUCT_ID: write 0x81, read 1 ([`super::identity`]).
    pub fn identity(script: &mut Script) -> Result<(), BuildError> {
        script.write_read(ADDRESS, &[reg::PRODUCT_ID], 1)?;
        Ok(())
    }

    /// A result pair from `high_register` (the proximity's 0x87, the ambient light's 0x85):
    /// write it, read 2 ([`super::result`]).
    pub fn result(script: &mut Script, high_register: u8) -> Result<(), BuildError> {
        script.write_read(ADDRESS, &[high_register], 2)?;
        Ok(())
    }

    /// A set-up register written, then read back: two operations ([`SetUpWrite::check`]), the
    /// blocking [`super::Vcnl4020::init`]'s and the scripted set-up's.
    #[inline(always)]
    pub fn set_up_write<T: Transfers>(
        bus: &mut T,
        write: SetUpWrite,
    ) -> Result<T::Read<1>, T::Error> {
        bus.send(ADDRESS, &[write.register, write.value])?;
        bus.fetch::<1>(ADDRESS, &[write.register])
    }
}
