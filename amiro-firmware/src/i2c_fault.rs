//! The polled I2C master's errors (`i2c::Master`), hardware-free so that the host tests follow a fault
//! from the bus clear ([`crate::i2c_clear`]) through a sensor driver to what the diagnostics count:
//! every failed sample is a sensor fault (`amiro_sensors::drivers::suite::Supervised`, diagnostics
//! page 0), whatever its kind.
use embedded_hal::i2c::{ErrorKind, NoAcknowledgeSource};

use crate::i2c_clear::Stuck;

/// What went wrong on the bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Error {
    /// Nobody acknowledged the address or a data byte.
    NoAcknowledge(NoAcknowledgeSource),
    /// Misplaced START/STOP.
    Bus,
    /// Another master won the bus.
    ArbitrationLoss,
    /// Data lost.
    Overrun,
    /// A flag did not come within the master's flag timeout (`i2c::FLAG_TIMEOUT_US`: bus stuck or
    /// device stretching for ever).
    Timeout,
    /// After a fault, SDA still low when the bus clear's nine pulses were given, or SCL held low
    /// past the clear's wait for it (`i2c_clear::MAX_STRETCH`): a device holds the bus; the next
    /// transfer's wait for a free bus fails and clears it again.
    BusStuck,
}

impl From<Stuck> for Error {
    /// A bus clear that failed ([`crate::i2c_clear::clear_bus`]), as the transfer reports it.
    fn from(_: Stuck) -> Self {
        Error::BusStuck
    }
}

impl embedded_hal::i2c::Error for Error {
    fn kind(&self) -> ErrorKind {
        match *self {
            Error::NoAcknowledge(source) => ErrorKind::NoAcknowledge(source),
            Error::Bus => ErrorKind::Bus,
            Error::ArbitrationLoss => ErrorKind::ArbitrationLoss,
            Error::Overrun => ErrorKind::Overrun,
            Error::Timeout => ErrorKind::Other,
            Error::BusStuck => ErrorKind::Bus,
        }
    }
}

#[cfg(test)]
mod tests {
    use amiro_can::Topic;
    use amiro_sensors::drivers::suite::{
        BusFault, Compass, Device, SampleError, Supervised, FAILURES_BEFORE_RETRY,
    };
    use amiro_sensors::drivers::Error as DriverError;
    use amiro_sensors::sim::SimCompassBus;
    use embedded_hal::i2c::{ErrorType, I2c, Operation};

    use super::*;
    use crate::i2c_clear::{clear_bus, ClearPins};

    /// A bus whose SDA a device holds low for good: the clear after a fault fails.
    struct HeldSda;

    impl ClearPins for HeldSda {
        fn lines(&mut self, _: bool, _: bool) {}
        fn half_period(&mut self) {}
        fn scl_is_high(&mut self) -> bool {
            true
        }
        fn sda_is_high(&mut self) -> bool {
            false
        }
    }

    /// The DiWheelDrive's magnetometer bus as the polled master serves it: the simulated HMC5883L
    /// while the bus is healthy; once it is held, each transfer times out and the master's fault
    /// path clears the bus (`i2c::Master::finish`, `recover`: the clear's result replaces the
    /// transfer's error where it failed).
    struct MasterBus {
        compass: SimCompassBus,
        held: bool,
    }

    impl ErrorType for MasterBus {
        type Error = Error;
    }

    impl I2c for MasterBus {
        fn transaction(
            &mut self,
            address: u8,
            operations: &mut [Operation<'_>],
        ) -> Result<(), Error> {
            if self.held {
                let transfer: Result<(), Error> = Err(Error::Timeout);
                let recovered = clear_bus(&mut HeldSda).map(|_| ()).map_err(Error::from);
                return recovered.and(transfer);
            }
            self.compass
                .transaction(address, operations)
                .map_err(|_| Error::NoAcknowledge(NoAcknowledgeSource::Address))
        }
    }

    #[test]
    fn a_stuck_bus_is_a_bus_error_and_a_counted_sensor_fault() {
        assert_eq!(
            clear_bus(&mut HeldSda).map_err(Error::from),
            Err(Error::BusStuck)
        );
        assert_eq!(
            embedded_hal::i2c::Error::kind(&Error::BusStuck),
            ErrorKind::Bus
        );
        let mut compass = Compass::new(MasterBus {
            compass: SimCompassBus::new(),
            held: false,
        });
        compass.set_reuse_window_us(0);
        let mut group = Supervised::new(compass);
        assert!(group.is_ready());
        assert_eq!(group.sample(Topic::MagnetometerX, 1_000).len(), 1);
        assert_eq!(group.faults(), 0);
        group.group_mut().magnetometer.bus_mut().held = true;
        assert!(group.sample(Topic::MagnetometerX, 40_000).is_empty());
        assert_eq!(group.faults(), 1, "the stuck bus is one sensor fault");
        // Held for good: the next failures in a row take the part out of service (the board's
        // "sensor fault now").
        for k in 2..=FAILURES_BEFORE_RETRY {
            assert!(group.is_ready());
            assert!(group
                .sample(Topic::MagnetometerX, 40_000 * u64::from(k))
                .is_empty());
            assert_eq!(group.faults(), u32::from(k));
        }
        assert!(!group.is_ready());
        assert_eq!(
            group.last_error(),
            Some(SampleError::Device {
                device: Device::Magnetometer,
                error: DriverError::Bus(BusFault::I2c(ErrorKind::Bus)),
            })
        );
    }
}
