//! DiWheelDrive's sensor groups as RTIC resources: one per bus, so publishers at different levels
//! block each other only for the bus they share.
//!
//! The groups themselves (drivers, conversions, which topic reads what) are amiro-sensors'; this
//! module only binds them to this board's buses (per revision: 1-1's SPI1 gyroscope and
//! accelerometer and I2C1 magnetometer, or 1-2's BNO055 on I2C1; both revisions publish the same
//! topics in the same units) and keeps a group that failed its identity check
//! from being read again (its topics then publish nothing, and the fault is counted).
//!
//! With the feature `scripted-i2c` (revision 1-1 only; not in the shipped image until the analysis
//! takes the sensor buses, docs/i2c.md "What step (c) wires") the I2C groups — the compass on I2C1,
//! the floor on I2C2 — sample by script instead: I2C scripts built from the drivers' register
//! maps and decoded by them (amiro-sensors' `drivers::scripted`) that the bus runs while the
//! publisher suspends
//! (`amiro_firmware::scripted::sample_on_bus`, a client slot per publisher task), the group's lock
//! held only to record and decode, never across the bus. The SPI groups stay as they are.
use amiro_can::{SensorData, Topic, Velocity};
#[cfg(not(feature = "scripted-i2c"))]
use amiro_sensors::drivers::floor::FloorSensors;
use amiro_sensors::drivers::suite::{self, SensorGroup};
use amiro_sensors::motion::{DriveController, Pose};

use crate::platform::FloorI2c;
#[cfg(feature = "rev-1-1")]
use crate::platform::{AccelSpi, CompassI2c, GyroSpi};
#[cfg(feature = "rev-1-2")]
use crate::platform::{ImuDelay, ImuI2c};

/// The sensor buses the platform's `init` hands to [`groups`] (revision 1-1).
#[cfg(feature = "rev-1-1")]
pub struct SensorBuses {
    /// The L3G4200D's SPI device.
    pub gyro_spi: GyroSpi,
    /// The LIS331DLH's SPI device.
    pub accel_spi: AccelSpi,
    /// The HMC5883L's bus.
    pub compass_i2c: CompassI2c,
    /// The PCA9544A and floor sensors' bus.
    pub floor_i2c: FloorI2c,
}

/// The sensor buses the platform's `init` hands to [`groups`] (revision 1-2).
#[cfg(feature = "rev-1-2")]
pub struct SensorBuses {
    /// The BNO055's bus (I2C1), its reset already pulsed.
    pub imu_i2c: ImuI2c,
    /// Its mode-switch waits.
    pub imu_delay: ImuDelay,
    /// The PCA9544A and floor sensors' bus.
    pub floor_i2c: FloorI2c,
}

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

impl<G> Group<G> {
    /// A group already brought up (`supervised`: the blocking build's [`Group::new`], or the
    /// scripted build's boot by its scripts); `index` names it in the health report.
    pub fn from_booted(supervised: suite::Supervised<G>, index: usize) -> Self {
        let group = Self { supervised, index };
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
}

impl<G: SensorGroup> Group<G> {
    /// Checks and configures the group's devices; `index` names the group in the health report.
    pub fn new(group: G, index: usize) -> Self {
        Self::from_booted(suite::Supervised::new(group), index)
    }

    /// One sample of `topic`: its frames, or none when the group is missing or the read failed.
    /// A group that is missing is initialised again when its back-off has passed, one device per
    /// sample (`SensorGroup::init_step`), so a sensor that was slow at boot or recovered joins
    /// later (each step's transfers count against its sample, never the whole group's set-up).
    // One copy for the four publisher tasks that call it (they are generic over their locks).
    #[inline(never)]
    pub fn sample(&mut self, topic: Topic, now_us: u64) -> Samples {
        let samples = self.supervised.sample(topic, now_us);
        self.report();
        samples
    }
}

/// Floor sensors behind the PCA9544A on I2C2 (both revisions).
#[cfg(not(feature = "scripted-i2c"))]
pub type Floor = Group<FloorSensors<FloorI2c>>;

#[cfg(feature = "rev-1-1")]
mod revision {
    use super::Group;
    use crate::platform::{AccelSpi, GyroSpi};
    use amiro_sensors::drivers::suite::InertialSensors;
    #[cfg(not(feature = "scripted-i2c"))]
    use {super::suite, crate::platform::CompassI2c};

    /// Gyroscope and accelerometer on SPI1.
    pub type Imu = Group<InertialSensors<GyroSpi, AccelSpi>>;
    /// Magnetometer on I2C1.
    #[cfg(not(feature = "scripted-i2c"))]
    pub type Compass = Group<suite::Compass<CompassI2c>>;
}

#[cfg(feature = "rev-1-2")]
mod revision {
    use super::{suite, Group};
    use crate::platform::{ImuDelay, ImuI2c};
    use amiro_sensors::drivers::suite::ImuSensors;

    /// The BNO055 on I2C1: gyroscope, accelerometer and magnetometer.
    pub type Imu = Group<ImuSensors<ImuI2c, ImuDelay>>;
    /// Nothing: 1-2's magnetometer is the BNO055's (in `imu`); the slot keeps the app's resources
    /// (and so its analysis model) the same on both revisions.
    pub type Compass = Group<suite::NoSensors>;
    /// How long the BNO055 may take from its reset (IMU_RESET_N released by the board) to answer:
    /// the datasheet's 650 ms and a margin, inside the boot watchdog's 2 s.
    pub const IMU_BOOT_TIMEOUT_MS: u32 = 800;

    /// The BNO055 group: waits for the part's boot, then checks and configures it. A part that
    /// never answered is *missing* (reported, retried with back-off) like any failed group.
    pub fn imu(i2c: ImuI2c, delay: ImuDelay) -> Imu {
        let mut group = ImuSensors::new(i2c, delay);
        // Its failure is the init's failure just after; the group reports that one.
        let _ = group.wait_for_boot(IMU_BOOT_TIMEOUT_MS);
        Imu::new(group, 0)
    }

    /// The empty slot.
    pub fn compass() -> Compass {
        Compass::new(suite::NoSensors, 1)
    }
}

#[cfg(not(feature = "scripted-i2c"))]
pub use revision::Compass;
pub use revision::Imu;
#[cfg(feature = "scripted-i2c")]
pub use scripted_groups::{Compass, Floor, ScriptedSampler};

/// Brings every sensor group up on its bus: the motion sensors (per revision) and the floor.
#[cfg(not(feature = "scripted-i2c"))]
pub fn groups(buses: SensorBuses) -> (Imu, Compass, Floor) {
    #[cfg(feature = "rev-1-1")]
    let (imu, compass, floor_i2c) = (
        Imu::new(
            suite::InertialSensors::new(buses.gyro_spi, buses.accel_spi),
            0,
        ),
        Compass::new(suite::Compass::new(buses.compass_i2c), 1),
        buses.floor_i2c,
    );
    #[cfg(feature = "rev-1-2")]
    let (imu, compass, floor_i2c) = (
        revision::imu(buses.imu_i2c, buses.imu_delay),
        revision::compass(),
        buses.floor_i2c,
    );
    (imu, compass, Floor::new(FloorSensors::new(floor_i2c), 2))
}

/// Brings every sensor group up: the SPI pair as in the blocking build; the compass and the floor
/// set up by their scripts on the boot's bus (`platform::boot_compass`, `platform::boot_floor`: the
/// polled master on the chip, whose block then goes to its engine; the simulated bus in QEMU).
#[cfg(feature = "scripted-i2c")]
pub fn groups(buses: SensorBuses) -> (Imu, Compass, Floor) {
    let imu = Imu::new(
        suite::InertialSensors::new(buses.gyro_spi, buses.accel_spi),
        0,
    );
    let compass = crate::platform::boot_compass(buses.compass_i2c);
    let floor = crate::platform::boot_floor(buses.floor_i2c);
    (
        imu,
        Group::from_booted(compass, 1),
        Group::from_booted(floor, 2),
    )
}

/// Clients of each I2C bus: the four publisher tasks, by slot `0` urgent to `3` low (the bus
/// serves the most urgent waiting script next).
#[cfg(feature = "scripted-i2c")]
pub const CLIENTS: usize = 4;

/// A script's timeout beyond its time on the wire at 400 kHz (`scripted::script_timeout_us`), µs:
/// the other three clients' scripts it may wait behind, each at most a full script's 504 SCL
/// periods (12 operations, 52 bytes: 1.26 ms), and 1 ms for the delays of its own events'
/// interrupts (the engine at priority 5 beside the command handler, under the CAN interrupts). No
/// stretch: the HMC5883L, the PCA9544A and the VCNL4020 state none (docs/analysis.md, the I2C
/// waits), so on the chip a repeated START stretched past the engine's condition wait stalls its
/// script until this timeout ends it (`amiro_firmware::i2c_engine`: this board runs no re-arm
/// task). A stated allowance, not yet the analysis's bus response.
#[cfg(feature = "scripted-i2c")]
pub const TIMEOUT_ALLOWANCE_US: u32 = 3 * 1_260 + 1_000;

#[cfg(feature = "scripted-i2c")]
mod scripted_groups {
    use amiro_can::Topic;
    use amiro_firmware::publisher::SuspendingSampler;
    use amiro_firmware::scripted::{sample_on_bus, BusFault, ScriptPort, ScriptedGroup, Step};
    use amiro_sensors::drivers::floor::FloorSensors;
    use amiro_sensors::drivers::scripted::Scripts;
    use amiro_sensors::drivers::suite::{self, Supervised};
    use amiro_sensors::script::Readings;

    use super::{sample_drive, sample_inertial_spi, DriveSample, Group, Imu, Samples};

    /// A group that samples by script is a [`Group`] too: its frames reported when its sample is
    /// done, as the blocking build's `Group::sample` reports them.
    impl<G> ScriptedGroup for Group<G>
    where
        Supervised<G>: ScriptedGroup,
    {
        type Job = <Supervised<G> as ScriptedGroup>::Job;
        const MAX_ROUNDS: usize = <Supervised<G> as ScriptedGroup>::MAX_ROUNDS;

        fn new_job() -> Self::Job {
            <Supervised<G> as ScriptedGroup>::new_job()
        }

        fn begin(&mut self, job: &mut Self::Job, topic: Topic, now_us: u64) -> Step {
            let step = self.supervised.begin(job, topic, now_us);
            self.reported(step)
        }

        fn resume(
            &mut self,
            job: &mut Self::Job,
            topic: Topic,
            now_us: u64,
            outcome: Result<Readings, BusFault>,
        ) -> Step {
            let step = self.supervised.resume(job, topic, now_us, outcome);
            self.reported(step)
        }
    }

    impl<G> Group<G> {
        /// A step's frames reported when the sample is done.
        fn reported(&self, step: Step) -> Step {
            if let Step::Done(_) = step {
                self.report();
            }
            step
        }
    }

    /// The HMC5883L on I2C1, its transfers made as scripts.
    pub type Compass = Group<suite::Compass<Scripts>>;
    /// The floor sensors behind the PCA9544A on I2C2, their transfers made as scripts.
    pub type Floor = Group<FloorSensors<Scripts>>;

    /// One sample of a magnetometer axis: the HMC5883L's scripts on I2C1 (not inlined, per topic
    /// family, as the blocking build's: the analysis tells a job's topic by the function).
    #[inline(never)]
    async fn sample_compass_scripted(
        compass: &mut impl rtic::Mutex<T = Compass>,
        port: &mut impl ScriptPort,
        topic: Topic,
        taken: u64,
    ) -> Samples {
        sample_on_bus(compass, port, topic, taken).await
    }

    /// One sample of the floor sensors: the round's scripts on I2C2.
    #[inline(never)]
    async fn sample_floor_scripted(
        floor: &mut impl rtic::Mutex<T = Floor>,
        port: &mut impl ScriptPort,
        topic: Topic,
        taken: u64,
    ) -> Samples {
        sample_on_bus(floor, port, topic, taken).await
    }

    /// What DiWheelDrive samples for a topic, a publisher task's own: each topic locks only the
    /// group it reads; the compass's and the floor's samples suspend the task while their scripts
    /// run on the task's client slots (`compass_port` on I2C1, `floor_port` on I2C2).
    pub struct ScriptedSampler<I, C, F, D, PC, PF> {
        /// The SPI pair.
        pub imu: I,
        /// The compass group.
        pub compass: C,
        /// The floor group.
        pub floor: F,
        /// Motor control's last pose and velocity.
        pub drive: D,
        /// The task's slot on I2C1.
        pub compass_port: PC,
        /// The task's slot on I2C2.
        pub floor_port: PF,
    }

    impl<I, C, F, D, PC, PF> SuspendingSampler for ScriptedSampler<I, C, F, D, PC, PF>
    where
        I: rtic::Mutex<T = Imu>,
        C: rtic::Mutex<T = Compass>,
        F: rtic::Mutex<T = Floor>,
        D: rtic::Mutex<T = DriveSample>,
        PC: ScriptPort,
        PF: ScriptPort,
    {
        async fn sample(&mut self, topic: Topic, taken_us: u64) -> Samples {
            match topic {
                Topic::Gyroscope | Topic::Accelerometer => {
                    sample_inertial_spi(&mut self.imu, topic, taken_us)
                }
                Topic::MagnetometerX | Topic::MagnetometerY | Topic::MagnetometerZ => {
                    sample_compass_scripted(
                        &mut self.compass,
                        &mut self.compass_port,
                        topic,
                        taken_us,
                    )
                    .await
                }
                Topic::FloorProximity => {
                    sample_floor_scripted(&mut self.floor, &mut self.floor_port, topic, taken_us)
                        .await
                }
                Topic::Odometry | Topic::Velocity => sample_drive(&mut self.drive, topic),
                _ => Samples::new(),
            }
        }
    }
}

/// A publisher task's sampler with `scripted-i2c`: the groups behind its locks and its slots on
/// I2C1 and I2C2 (`platform::ports`).
#[cfg(feature = "scripted-i2c")]
pub fn scripted_sampler(
    imu: impl rtic::Mutex<T = Imu>,
    compass: impl rtic::Mutex<T = Compass>,
    floor: impl rtic::Mutex<T = Floor>,
    drive: impl rtic::Mutex<T = DriveSample>,
    (compass_port, floor_port): (crate::platform::CompassPort, crate::platform::FloorPort),
) -> impl amiro_firmware::publisher::SuspendingSampler {
    ScriptedSampler {
        imu,
        compass,
        floor,
        drive,
        compass_port,
        floor_port,
    }
}

/// One word on the groups for the boot log.
pub fn summary(imu: &Imu, compass: &Compass, floor: &Floor) -> &'static str {
    if imu.is_ready() && compass.is_ready() && floor.is_ready() {
        "ready"
    } else {
        "partly missing (their topics answer nothing)"
    }
}

/// What motor control publishes after each step for the odometry and velocity topics: the
/// controller's pose and velocity, copied out so that the controller stays motor control's own (a
/// publisher's lock is a copy of these 32 bytes, not a control step).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DriveSample {
    /// The pose in µm and µrad.
    pub pose: Pose,
    /// The measured body velocity.
    pub velocity: Velocity,
}

impl DriveSample {
    /// The controller's pose and velocity now.
    pub fn of(controller: &DriveController) -> Self {
        Self {
            pose: controller.pose(),
            velocity: controller.velocity(),
        }
    }
}

/// The odometry and velocity topics come from the drive controller, not from a bus: from the
/// sample motor control published after its last step (a copy under the `drive` lock, which motor
/// control and the publishers share at priority 4). The pose's conversion to the odometry's wire
/// units (the heading's reduction to a turn) and the sample's frame are made after the lock. The
/// same values as [`DriveController::sample`] of the controller at that step.
#[inline(never)]
fn sample_drive(drive: &mut impl rtic::Mutex<T = DriveSample>, topic: Topic) -> Samples {
    let data = match topic {
        Topic::Odometry => {
            SensorData::Odometry(DriveController::odometry_of(drive.lock(|d| d.pose)))
        }
        Topic::Velocity => SensorData::Velocity(drive.lock(|d| d.velocity)),
        _ => return Samples::new(),
    };
    // Made here, after the reads: the sample is built where the caller receives it (made before
    // the locks, it was a copy of all eight slots on the way out).
    let mut samples = Samples::new();
    let _ = samples.push(data);
    samples
}

/// One sample of the gyroscope or the accelerometer: 1-1's L3G4200D and LIS331DLH on SPI1. Each
/// topic family's sample is a function of its own, not inlined, named per revision (its devices
/// and their bus waits differ), so the execution-time analysis tells a publisher job's topic by the
/// function it calls (the bounds file's `topics`, docs/analysis.md "One topic's job"): a job of one
/// family calls no other's.
#[cfg(feature = "rev-1-1")]
#[inline(never)]
fn sample_inertial_spi(imu: &mut impl rtic::Mutex<T = Imu>, topic: Topic, taken: u64) -> Samples {
    imu.lock(|d| d.sample(topic, taken))
}

/// One sample of a magnetometer axis: 1-1's HMC5883L on I2C1.
#[cfg(all(feature = "rev-1-1", not(feature = "scripted-i2c")))]
#[inline(never)]
fn sample_compass_hmc5883l(
    compass: &mut impl rtic::Mutex<T = Compass>,
    topic: Topic,
    taken: u64,
) -> Samples {
    compass.lock(|d| d.sample(topic, taken))
}

/// One sample of the gyroscope, the accelerometer or a magnetometer axis: 1-2's BNO055 on I2C1.
#[cfg(feature = "rev-1-2")]
#[inline(never)]
fn sample_imu_bno055(imu: &mut impl rtic::Mutex<T = Imu>, topic: Topic, taken: u64) -> Samples {
    imu.lock(|d| d.sample(topic, taken))
}

/// One sample of the floor sensors (the four VCNL4020 behind the PCA9544A on I2C2).
#[cfg(not(feature = "scripted-i2c"))]
#[inline(never)]
fn sample_floor(floor: &mut impl rtic::Mutex<T = Floor>, topic: Topic, taken: u64) -> Samples {
    floor.lock(|d| d.sample(topic, taken))
}

/// What DiWheelDrive samples for a topic: each topic locks only the device group it reads.
#[cfg(not(feature = "scripted-i2c"))]
pub fn sampler(
    mut imu: impl rtic::Mutex<T = Imu>,
    #[cfg_attr(feature = "rev-1-2", allow(unused_mut))] mut compass: impl rtic::Mutex<T = Compass>,
    mut floor: impl rtic::Mutex<T = Floor>,
    mut drive: impl rtic::Mutex<T = DriveSample>,
) -> impl amiro_firmware::publisher::Sampler {
    // 1-2's magnetometer is the BNO055's: the empty slot is not read.
    #[cfg(feature = "rev-1-2")]
    drop(compass);
    move |topic: Topic, taken: u64| match topic {
        #[cfg(feature = "rev-1-1")]
        Topic::Gyroscope | Topic::Accelerometer => sample_inertial_spi(&mut imu, topic, taken),
        #[cfg(feature = "rev-1-1")]
        Topic::MagnetometerX | Topic::MagnetometerY | Topic::MagnetometerZ => {
            sample_compass_hmc5883l(&mut compass, topic, taken)
        }
        #[cfg(feature = "rev-1-2")]
        Topic::Gyroscope
        | Topic::Accelerometer
        | Topic::MagnetometerX
        | Topic::MagnetometerY
        | Topic::MagnetometerZ => sample_imu_bno055(&mut imu, topic, taken),
        Topic::FloorProximity => sample_floor(&mut floor, topic, taken),
        Topic::Odometry | Topic::Velocity => sample_drive(&mut drive, topic),
        _ => Samples::new(),
    }
}
