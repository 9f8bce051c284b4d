//! The DiWheelDrive's four floor sensors: VCNL4020s behind the PCA9544A (0x77) on I2C2, read as
//! one group.
//!
//! Channel map (amiro-boards.md §4a, from the Apps floor app and the 1.x constants, which agree):
//! channel 0 front-right, 1 right-wheel, 2 left-wheel, 3 front-left. The 1.x index is the channel
//! number, and the protocol's four floor values (sensor 1..4) are in that order.

use embedded_hal::i2c::I2c;

use super::pca9544a::{Channel, Pca9544a};
use super::vcnl4020::{Config, Reading, Vcnl4020};
use super::{Error, IdentitySchedule};

/// Where a floor sensor sits; the discriminant is its index in the protocol's frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum FloorSensor {
    /// Front right (mux channel 0).
    FrontRight = 0,
    /// Beside the right wheel (mux channel 1).
    RightWheel = 1,
    /// Beside the left wheel (mux channel 2).
    LeftWheel = 2,
    /// Front left (mux channel 3).
    FrontLeft = 3,
}

impl FloorSensor {
    /// All four in protocol order.
    pub const ALL: [FloorSensor; 4] = [
        FloorSensor::FrontRight,
        FloorSensor::RightWheel,
        FloorSensor::LeftWheel,
        FloorSensor::FrontLeft,
    ];

    /// The mux channel it is wired to.
    pub const fn channel(self) -> Channel {
        match self {
            FloorSensor::FrontRight => Channel::Ch0,
            FloorSensor::RightWheel => Channel::Ch1,
            FloorSensor::LeftWheel => Channel::Ch2,
            FloorSensor::FrontLeft => Channel::Ch3,
        }
    }
}

/// An error from one sensor of a group, with the sensor's index.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GroupError<E> {
    /// Index of the sensor that failed (protocol order).
    pub sensor: u8,
    /// What went wrong.
    pub error: Error<E>,
}

/// The four floor sensors and their mux.
#[derive(Debug, Clone)]
pub struct FloorSensors<I2C> {
    mux: Pca9544a<I2C>,
    config: Config,
    identity: IdentitySchedule,
    /// The sensor (protocol index) the next step of a stepwise set-up configures
    /// ([`init_next`](Self::init_next)).
    next_to_init: u8,
}

impl<I2C> FloorSensors<I2C> {
    /// The group on `i2c` with the mux at 0x77 and the original firmware's VCNL4020 settings.
    pub const fn new(i2c: I2C) -> Self {
        Self::with_config(i2c, Config::AMIRO)
    }

    /// The group with other VCNL4020 settings.
    pub const fn with_config(i2c: I2C, config: Config) -> Self {
        Self {
            mux: Pca9544a::new(i2c),
            config,
            identity: IdentitySchedule { samples: 0 },
            next_to_init: 0,
        }
    }

    /// The VCNL4020 settings the set-up writes.
    pub const fn config(&self) -> &Config {
        &self.config
    }

    /// The mux's address.
    pub const fn mux_address(&self) -> u8 {
        self.mux.address()
    }

    /// Sets the sensor the next set-up step configures.
    pub(crate) fn set_next_to_set_up(&mut self, sensor: u8) {
        self.next_to_init = sensor;
    }

    /// Counts one sample; true every [`super::IDENTITY_CHECK_EVERY`] samples.
    pub(crate) fn identity_check_due(&mut self) -> bool {
        self.identity.due()
    }

    /// The sensor (protocol index and part) the next set-up step configures, or `None` with the
    /// set-up started again at the first (the index is out of range only if the field were
    /// corrupted). Both paths' stepwise set-up begins a step here.
    pub(crate) fn sensor_to_set_up(&mut self) -> Option<(u8, FloorSensor)> {
        let index = self.next_to_init;
        let sensor = FloorSensor::ALL.get(usize::from(index)).copied();
        if sensor.is_none() {
            self.next_to_init = 0;
        }
        sensor.map(|sensor| (index, sensor))
    }

    /// Ends the set-up step of sensor `index`, which `passed` or failed: true once the fourth is
    /// configured. After the fourth or a failure the next set-up starts at the first sensor.
    /// Both paths' stepwise set-up ends a step here.
    pub(crate) fn end_set_up_step(&mut self, index: u8, passed: bool) -> bool {
        let last = usize::from(index) + 1 >= FloorSensor::ALL.len();
        self.next_to_init = if passed && !last { index + 1 } else { 0 };
        passed && last
    }
}

impl<I2C: I2c> FloorSensors<I2C> {
    /// Checks and configures all four sensors (channel 0 first).
    pub fn init(&mut self) -> Result<(), GroupError<I2C::Error>> {
        self.next_to_init = 0;
        let config = self.config;
        for sensor in FloorSensor::ALL {
            self.with_sensor(sensor, |vcnl| vcnl.init(&config))?;
        }
        Ok(())
    }

    /// One step of a stepwise set-up: checks and configures the next sensor only (channel 0
    /// first), so a set-up costs one sensor's transfers per call, never the group's. `Ok(true)`
    /// once the fourth is configured (the next call starts again at the first); a failure also
    /// starts the next set-up at the first sensor.
    pub fn init_next(&mut self) -> Result<bool, GroupError<I2C::Error>> {
        let Some((index, sensor)) = self.sensor_to_set_up() else {
            return Ok(false);
        };
        let config = self.config;
        let result = self.with_sensor(sensor, |vcnl| vcnl.init(&config));
        let done = self.end_set_up_step(index, result.is_ok());
        result.map(|()| done)
    }

    /// Reads every sensor's PRODUCT_ID through its mux channel (a mux that does not switch, or a
    /// sensor that is gone, fails here).
    pub fn check_identities(&mut self) -> Result<(), GroupError<I2C::Error>> {
        for sensor in FloorSensor::ALL {
            self.with_sensor(sensor, |vcnl| vcnl.check_identity())?;
        }
        Ok(())
    }

    /// The four proximity counts in protocol order (front-right, right-wheel, left-wheel,
    /// front-left).
    pub fn read_proximity(&mut self) -> Result<[u16; 4], GroupError<I2C::Error>> {
        let mut counts = [0u16; 4];
        for (out, sensor) in counts.iter_mut().zip(FloorSensor::ALL) {
            *out = self.with_sensor(sensor, |vcnl| vcnl.read_proximity())?;
        }
        Ok(counts)
    }

    /// Proximity and ambient light of all four, in protocol order.
    pub fn read(&mut self) -> Result<[Reading; 4], GroupError<I2C::Error>> {
        let mut readings = [Reading::default(); 4];
        for (out, sensor) in readings.iter_mut().zip(FloorSensor::ALL) {
            *out = self.with_sensor(sensor, |vcnl| vcnl.read())?;
        }
        Ok(readings)
    }

    /// The mux, e.g. to reach the other devices on the bus through [`Pca9544a::bus_mut`].
    pub fn mux_mut(&mut self) -> &mut Pca9544a<I2C> {
        &mut self.mux
    }

    /// Gives the bus back.
    pub fn release(self) -> I2C {
        self.mux.release()
    }

    fn with_sensor<T>(
        &mut self,
        sensor: FloorSensor,
        f: impl FnOnce(
            &mut Vcnl4020<super::pca9544a::MuxedBus<'_, I2C>>,
        ) -> Result<T, Error<I2C::Error>>,
    ) -> Result<T, GroupError<I2C::Error>> {
        let index = sensor as u8;
        let tag = |error| GroupError {
            sensor: index,
            error,
        };
        let bus = self.mux.select(sensor.channel()).map_err(tag)?;
        f(&mut Vcnl4020::new(bus)).map_err(tag)
    }
}
