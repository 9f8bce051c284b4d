//! DiWheelDrive's sensor groups as RTIC resources: one per bus, so publishers at different levels
//! block each other only for the bus they share.
//!
//! The groups themselves (drivers, conversions, which topic reads what) are amiro-sensors'; this
//! module only binds them to this board's buses and keeps a group that failed its identity check
//! from being read again (its topics then publish nothing, and the fault is counted).
use amiro_can::Topic;
use amiro_sensors::drivers::floor::FloorSensors;
use amiro_sensors::drivers::suite::{self, InertialSensors, SensorGroup};
use amiro_sensors::motion::DriveController;

use crate::platform::{AccelSpi, CompassI2c, FloorI2c, GyroSpi};

pub use amiro_sensors::drivers::suite::Samples;

/// A sensor group and whether it came up.
pub struct Group<G> {
    group: G,
    ready: bool,
    faults: u32,
}

impl<G: SensorGroup> Group<G> {
    /// Checks and configures the group's devices.
    pub fn new(mut group: G) -> Self {
        let ready = group.init().is_ok();
        Self {
            group,
            ready,
            faults: 0,
        }
    }

    /// Whether every device of the group answered its identity check.
    pub fn is_ready(&self) -> bool {
        self.ready
    }

    /// Bus or device faults since boot (failed identity checks count once).
    pub fn faults(&self) -> u32 {
        self.faults + u32::from(!self.ready)
    }

    /// One sample of `topic`: its frames, or none when the group is missing or the read failed.
    // One copy for the four publisher tasks that call it (they are generic over their locks).
    #[inline(never)]
    pub fn sample(&mut self, topic: Topic, now_us: u64) -> Samples {
        if !self.ready {
            return Samples::new();
        }
        match self.group.sample(topic, now_us) {
            Ok(samples) => samples,
            Err(_) => {
                self.faults = self.faults.saturating_add(1);
                Samples::new()
            }
        }
    }
}

/// Gyroscope and accelerometer on SPI1.
pub type Imu = Group<InertialSensors<GyroSpi, AccelSpi>>;
/// Magnetometer on I2C1.
pub type Compass = Group<suite::Compass<CompassI2c>>;
/// Floor sensors behind the PCA9544A on I2C2.
pub type Floor = Group<FloorSensors<FloorI2c>>;

/// The odometry and velocity topics come from the drive controller, not from a bus.
#[inline(never)]
pub fn sample_drive(drive: &DriveController, topic: Topic) -> Samples {
    let mut samples = Samples::new();
    if let Some(data) = drive.sample(topic) {
        let _ = samples.push(data);
    }
    samples
}
