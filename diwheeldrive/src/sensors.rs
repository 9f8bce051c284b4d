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

/// How long a group that failed its identity check waits before the next attempt.
pub const RETRY_INIT_US: u64 = 1_000_000;
/// Consecutive failed reads after which a group is treated as missing (and retried as above),
/// so a dead bus costs one timeout per second instead of one per sample.
pub const FAILURES_BEFORE_RETRY: u8 = 3;

/// A sensor group and whether it came up.
pub struct Group<G> {
    group: G,
    ready: bool,
    faults: u32,
    consecutive_failures: u8,
    last_init_us: u64,
}

impl<G: SensorGroup> Group<G> {
    /// Checks and configures the group's devices.
    pub fn new(mut group: G) -> Self {
        let ready = group.init().is_ok();
        Self {
            group,
            ready,
            faults: 0,
            consecutive_failures: 0,
            last_init_us: 0,
        }
    }

    /// Whether every device of the group answered its identity check.
    pub fn is_ready(&self) -> bool {
        self.ready
    }

    /// One sample of `topic`: its frames, or none when the group is missing or the read failed.
    /// A group that did not come up is initialised again, at most once per [`RETRY_INIT_US`], so a
    /// sensor that was slow at boot joins later (the retry's transfers count against that sample).
    // One copy for the four publisher tasks that call it (they are generic over their locks).
    #[inline(never)]
    pub fn sample(&mut self, topic: Topic, now_us: u64) -> Samples {
        if !self.ready {
            if now_us.saturating_sub(self.last_init_us) < RETRY_INIT_US {
                return Samples::new();
            }
            self.last_init_us = now_us;
            self.ready = self.group.init().is_ok();
            if !self.ready {
                return Samples::new();
            }
        }
        match self.group.sample(topic, now_us) {
            Ok(samples) => {
                self.consecutive_failures = 0;
                samples
            }
            Err(_) => {
                self.faults = self.faults.saturating_add(1);
                self.consecutive_failures = self.consecutive_failures.saturating_add(1);
                if self.consecutive_failures >= FAILURES_BEFORE_RETRY {
                    self.ready = false;
                    self.consecutive_failures = 0;
                    self.last_init_us = now_us;
                }
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

/// One word on the groups for the boot log.
pub fn summary(imu: &Imu, compass: &Compass, floor: &Floor) -> &'static str {
    if imu.is_ready() && compass.is_ready() && floor.is_ready() {
        "ready"
    } else {
        "partly missing (their topics answer nothing)"
    }
}

/// The odometry and velocity topics come from the drive controller, not from a bus.
#[inline(never)]
pub fn sample_drive(drive: &DriveController, topic: Topic) -> Samples {
    let mut samples = Samples::new();
    if let Some(data) = drive.sample(topic) {
        let _ = samples.push(data);
    }
    samples
}

/// What DiWheelDrive samples for a topic: each topic locks only the device group it reads.
pub fn sampler(
    mut imu: impl rtic::Mutex<T = Imu>,
    mut compass: impl rtic::Mutex<T = Compass>,
    mut floor: impl rtic::Mutex<T = Floor>,
    mut drive: impl rtic::Mutex<T = DriveController>,
) -> impl amiro_firmware::publisher::Sampler {
    move |topic: Topic, taken: u64| match topic {
        Topic::Gyroscope | Topic::Accelerometer => imu.lock(|d| d.sample(topic, taken)),
        Topic::MagnetometerX | Topic::MagnetometerY | Topic::MagnetometerZ => {
            compass.lock(|d| d.sample(topic, taken))
        }
        Topic::FloorProximity => floor.lock(|d| d.sample(topic, taken)),
        Topic::Odometry | Topic::Velocity => drive.lock(|d| sample_drive(d, topic)),
        _ => Samples::new(),
    }
}
