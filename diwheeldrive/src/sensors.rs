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

/// A sensor group and whether it came up: amiro-sensors' [`suite::Supervised`] (host-tested),
/// which stops publishing a group whose devices fail (a stuck line, a wrong identity, a NACK),
/// counts every failure and retries with back-off, 1 s → 2 → 4 → 8 s. Its fault count and state go
/// into the board's diagnostics (page 0).
pub struct Group<G> {
    supervised: suite::Supervised<G>,
    /// The group's index in the board's health report.
    index: usize,
}

impl<G: SensorGroup> Group<G> {
    /// Checks and configures the group's devices; `index` names the group in the health report.
    pub fn new(group: G, index: usize) -> Self {
        let group = Self {
            supervised: suite::Supervised::new(group),
            index,
        };
        group.report();
        group
    }

    /// Puts the group's fault count and state into the board's diagnostics.
    fn report(&self) {
        amiro_firmware::health::report_sensor_group(
            self.index,
            self.supervised.faults(),
            !self.supervised.is_ready(),
        );
    }

    /// Whether the group is up: every device answered its identity check and the last samples
    /// worked.
    pub fn is_ready(&self) -> bool {
        self.supervised.is_ready()
    }

    /// One sample of `topic`: its frames, or none when the group is missing or the read failed.
    /// A group that is missing is initialised again when its back-off has passed, so a sensor
    /// that was slow at boot or recovered joins later (the retry's transfers count against that
    /// sample).
    // One copy for the four publisher tasks that call it (they are generic over their locks).
    #[inline(never)]
    pub fn sample(&mut self, topic: Topic, now_us: u64) -> Samples {
        let samples = self.supervised.sample(topic, now_us);
        self.report();
        samples
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
