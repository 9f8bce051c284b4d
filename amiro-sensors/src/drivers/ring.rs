//! The PowerManagement's proximity ring: eight VCNL4020s, four behind a PCA9544A (0x77) on each of
//! I2C1 and I2C2, read as one group and converted to millimetres.
//!
//! Sensor index = the 1.x firmware's index, which the protocol's ring frames carry (amiro-boards.md
//! §5; the 1.x and Apps sources agree on the wiring):
//!
//! | index | position | bus / channel |
//! |---|---|---|
//! | 0 | rear-left (SSW) | I2C1 ch1 |
//! | 1 | left-rear (WSW) | I2C1 ch3 |
//! | 2 | left-front (WNW) | I2C1 ch2 |
//! | 3 | front-left (NNW) | I2C2 ch0 |
//! | 4 | front-right (NNE) | I2C2 ch1 |
//! | 5 | right-front (ENE) | I2C2 ch3 |
//! | 6 | right-rear (ESE) | I2C2 ch2 |
//! | 7 | rear-right (SSE) | I2C1 ch0 |
//!
//! The two buses may be different types, so bus errors are reported as their
//! [`embedded_hal::i2c::ErrorKind`].

use embedded_hal::i2c::{Error as _, ErrorKind, I2c};

use super::floor::GroupError;
use super::pca9544a::{Channel, MuxedBus, Pca9544a};
use super::proximity::ProximityCalibration;
use super::vcnl4020::{Config, Reading, Vcnl4020};
use super::Error;

/// Number of ring sensors.
pub const RING_SENSORS: usize = 8;

/// Which of the PowerManagement's two I2C buses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RingBus {
    /// I2C1 ("rear" bus, PB8/PB9).
    I2c1,
    /// I2C2 ("front" bus, PB10/PB11).
    I2c2,
}

/// Bus and mux channel of ring sensor `index` (see the table in the module documentation).
pub const WIRING: [(RingBus, Channel); RING_SENSORS] = [
    (RingBus::I2c1, Channel::Ch1),
    (RingBus::I2c1, Channel::Ch3),
    (RingBus::I2c1, Channel::Ch2),
    (RingBus::I2c2, Channel::Ch0),
    (RingBus::I2c2, Channel::Ch1),
    (RingBus::I2c2, Channel::Ch3),
    (RingBus::I2c2, Channel::Ch2),
    (RingBus::I2c1, Channel::Ch0),
];

/// The eight ring sensors, their two muxes and their calibrations.
#[derive(Debug)]
pub struct ProximityRing<I1, I2> {
    mux1: Pca9544a<I1>,
    mux2: Pca9544a<I2>,
    config: Config,
    calibration: [ProximityCalibration; RING_SENSORS],
}

impl<I1: I2c, I2: I2c> ProximityRing<I1, I2> {
    /// The ring on I2C1 and I2C2 with muxes at 0x77, the original VCNL4020 settings and the
    /// default (uncalibrated) counts → mm model.
    pub const fn new(i2c1: I1, i2c2: I2) -> Self {
        Self {
            mux1: Pca9544a::new(i2c1),
            mux2: Pca9544a::new(i2c2),
            config: Config::AMIRO,
            calibration: [ProximityCalibration::DEFAULT; RING_SENSORS],
        }
    }

    /// Replaces the VCNL4020 settings used by [`init`](Self::init).
    pub fn set_config(&mut self, config: Config) {
        self.config = config;
    }

    /// Replaces sensor `index`'s calibration.
    pub fn set_calibration(
        &mut self,
        index: usize,
        calibration: ProximityCalibration,
    ) -> Result<(), Error<ErrorKind>> {
        match self.calibration.get_mut(index) {
            Some(slot) => {
                *slot = calibration;
                Ok(())
            }
            None => Err(Error::OutOfRange {
                value: index as u16,
                max: (RING_SENSORS - 1) as u16,
            }),
        }
    }

    /// All eight calibrations, by sensor index.
    pub fn calibration(&self) -> &[ProximityCalibration; RING_SENSORS] {
        &self.calibration
    }

    /// Checks and configures all eight sensors, in index order.
    pub fn init(&mut self) -> Result<(), GroupError<ErrorKind>> {
        let config = self.config;
        for index in 0..RING_SENSORS {
            self.with_sensor(index, |vcnl| vcnl.init(&config), |vcnl| vcnl.init(&config))?;
        }
        Ok(())
    }

    /// Checks and configures sensor `index` alone (one step of a stepwise set-up).
    pub fn init_sensor(&mut self, index: usize) -> Result<(), GroupError<ErrorKind>> {
        let config = self.config;
        self.with_sensor(index, |vcnl| vcnl.init(&config), |vcnl| vcnl.init(&config))
    }

    /// Proximity counts of all eight sensors, by index.
    pub fn read_counts(&mut self) -> Result<[u16; RING_SENSORS], GroupError<ErrorKind>> {
        let mut counts = [0u16; RING_SENSORS];
        for (index, out) in counts.iter_mut().enumerate() {
            *out = self.with_sensor(
                index,
                |vcnl| vcnl.read_proximity(),
                |vcnl| vcnl.read_proximity(),
            )?;
        }
        Ok(counts)
    }

    /// Distances in millimetres of all eight sensors, by index (each through its calibration).
    pub fn read_mm(&mut self) -> Result<[u16; RING_SENSORS], GroupError<ErrorKind>> {
        let counts = self.read_counts()?;
        let mut mm = [0u16; RING_SENSORS];
        for ((out, c), cal) in mm.iter_mut().zip(counts).zip(&self.calibration) {
            *out = cal.counts_to_mm(c);
        }
        Ok(mm)
    }

    /// Proximity and ambient light of all eight sensors, by index.
    pub fn read(&mut self) -> Result<[Reading; RING_SENSORS], GroupError<ErrorKind>> {
        let mut readings = [Reading::default(); RING_SENSORS];
        for (index, out) in readings.iter_mut().enumerate() {
            *out = self.with_sensor(index, |vcnl| vcnl.read(), |vcnl| vcnl.read())?;
        }
        Ok(readings)
    }

    /// The I2C1 bus, for the devices beside the mux (the rear fuel gauge, INA219s).
    pub fn i2c1_mut(&mut self) -> &mut I1 {
        self.mux1.bus_mut()
    }

    /// The I2C2 bus, for the devices beside the mux (the front fuel gauge, touch, INA219s).
    pub fn i2c2_mut(&mut self) -> &mut I2 {
        self.mux2.bus_mut()
    }

    /// Gives both buses back.
    pub fn release(self) -> (I1, I2) {
        (self.mux1.release(), self.mux2.release())
    }

    /// Runs `on1` or `on2` (the same operation, typed for each bus) on sensor `index`.
    fn with_sensor<T>(
        &mut self,
        index: usize,
        on1: impl FnOnce(&mut Vcnl4020<MuxedBus<'_, I1>>) -> Result<T, Error<I1::Error>>,
        on2: impl FnOnce(&mut Vcnl4020<MuxedBus<'_, I2>>) -> Result<T, Error<I2::Error>>,
    ) -> Result<T, GroupError<ErrorKind>> {
        let sensor = index as u8;
        let tag = |error| GroupError { sensor, error };
        let Some(&(bus, channel)) = WIRING.get(index) else {
            return Err(tag(Error::OutOfRange {
                value: index as u16,
                max: (RING_SENSORS - 1) as u16,
            }));
        };
        match bus {
            RingBus::I2c1 => {
                let muxed = self
                    .mux1
                    .select(channel)
                    .map_err(|e| tag(e.map_bus(|b| b.kind())))?;
                on1(&mut Vcnl4020::new(muxed)).map_err(|e| tag(e.map_bus(|b| b.kind())))
            }
            RingBus::I2c2 => {
                let muxed = self
                    .mux2
                    .select(channel)
                    .map_err(|e| tag(e.map_bus(|b| b.kind())))?;
                on2(&mut Vcnl4020::new(muxed)).map_err(|e| tag(e.map_bus(|b| b.kind())))
            }
        }
    }
}
