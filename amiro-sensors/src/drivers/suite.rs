//! Each board's sensors bundled behind one call: `sample(topic, now_us)` reads what the topic needs
//! and returns the amiro-can [`SensorData`] frames of one sample.
//!
//! A sample may be several frames (the proximity ring is eight), so `sample` returns [`Samples`], a
//! fixed-capacity vector: no heap, and the caller encodes each element. Groups are split along what
//! the firmware locks separately: on DiWheelDrive the SPI motion sensors ([`InertialSensors`]), the
//! I2C1 magnetometer ([`Compass`]) and the I2C2 floor sensors ([`FloorSensors`]) are independent
//! resources that publishers at different priorities can sample without blocking each other;
//! [`DiWheelDriveSensors`] holds all three for a firmware that does not care. PowerManagement's
//! ring and fuel gauges share both buses, so they are one group, [`PowerManagementSensors`].
//!
//! Errors lose their bus type here ([`BusFault`] keeps the embedded-hal error kind) and gain the
//! device that failed, so one [`SampleError`] type serves every board.

use core::fmt;

use amiro_can::{Axis as CanAxis, LedCommand, PowerStatus, SensorData, Topic};
use embedded_hal::delay::DelayNs;
use embedded_hal::i2c::{self, I2c};
use embedded_hal::spi::{self, SpiDevice};

use super::bno055::{self, Bno055};
use super::bq27500::{BatteryStatus, Bq27500, PowerSummary};
use super::floor::{FloorSensors, GroupError};
use super::hmc5883l::{Hmc5883l, MagneticField};
use super::l3g4200d::{AngularRate, L3g4200d};
use super::lis331dlh::{Acceleration, Lis331dlh};
use super::ring::{ProximityRing, RING_SENSORS};
use super::tlc5947::LedRing;
use super::{Axis, Error, IdentitySchedule};

/// Most frames one sample yields (the proximity ring's eight).
pub const MAX_SAMPLES: usize = 8;

/// The frames of one sample.
pub type Samples = heapless::Vec<SensorData, MAX_SAMPLES>;

/// DiWheelDrive's sensor topics, grouped as its devices serve them: the inertial pair
/// (`..2`), the magnetometer's three axes (`2..5`; a BNO055 serves all five, `..5`), then the floor
/// sensors. Each group's topic list is a slice of this one.
pub(crate) static DIWHEELDRIVE_TOPICS: [Topic; 6] = [
    Topic::Gyroscope,
    Topic::Accelerometer,
    Topic::MagnetometerX,
    Topic::MagnetometerY,
    Topic::MagnetometerZ,
    Topic::FloorProximity,
];

/// A bus error with its type erased to the embedded-hal error kind.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BusFault {
    /// An I2C transfer failed.
    I2c(i2c::ErrorKind),
    /// An SPI transfer failed.
    Spi(spi::ErrorKind),
}

/// The device a [`SampleError`] is about.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Device {
    /// L3G4200D.
    Gyroscope,
    /// LIS331DLH.
    Accelerometer,
    /// HMC5883L.
    Magnetometer,
    /// BNO055 (DiWheelDrive 1-2's gyroscope, accelerometer and magnetometer in one part).
    Imu,
    /// Floor sensor by protocol index (0 front-right .. 3 front-left), or its mux.
    FloorSensor(u8),
    /// Ring sensor by protocol index 0..=7, or its mux.
    RingSensor(u8),
    /// A bq27500 fuel gauge.
    FuelGauge(Battery),
    /// The LightRing's TLC5947.
    LedDriver,
}

/// Which of PowerManagement's two batteries.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Battery {
    /// Battery A, "front", gauge on I2C2.
    Front,
    /// Battery B, "rear", gauge on I2C1.
    Rear,
}

/// Why a sample could not be taken.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SampleError {
    /// A device failed.
    Device {
        /// Which one.
        device: Device,
        /// What went wrong.
        error: Error<BusFault>,
    },
    /// The topic is not one this group samples (another group's, another board's, or an actuator).
    NotServed(Topic),
}

impl fmt::Display for SampleError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SampleError::Device { device, error } => write!(f, "{device:?}: {error}"),
            SampleError::NotServed(topic) => write!(f, "topic {topic} is not sampled here"),
        }
    }
}

fn spi_error<E: spi::Error>(device: Device) -> impl Fn(Error<E>) -> SampleError {
    move |error| SampleError::Device {
        device,
        error: error.map_bus(|e| BusFault::Spi(e.kind())),
    }
}

pub(crate) fn i2c_error<E: i2c::Error>(device: Device) -> impl Fn(Error<E>) -> SampleError {
    move |error| SampleError::Device {
        device,
        error: error.map_bus(|e| BusFault::I2c(e.kind())),
    }
}

pub(crate) fn one(data: SensorData) -> Samples {
    let mut samples = Samples::new();
    // Capacity is MAX_SAMPLES ≥ 1, so the push cannot fail.
    let _ = samples.push(data);
    samples
}

/// A set of devices that can be sampled by topic.
pub trait SensorGroup {
    /// The topics [`sample`](Self::sample) serves.
    fn topics(&self) -> &'static [Topic];

    /// Checks identities and configures every device of the group.
    fn init(&mut self) -> Result<(), SampleError>;

    /// One step of a re-initialisation at `now_us` (the retry of a missing group, inside its bus
    /// lock and inside a publisher's release): at most one device's set-up, so a release that
    /// recovers a group costs one bounded step (and no sample), never the whole group's set-up. A
    /// group with more steps to go returns [`InitStep::Pending`] and is called again at that
    /// time (`now_us` for the next release; later where a part needs a wait between steps, so no
    /// wait happens inside the lock). Default: [`init`] at once, for a group of one device.
    ///
    /// [`init`]: Self::init
    fn init_step(&mut self, now_us: u64) -> InitStep {
        let _ = now_us;
        match self.init() {
            Ok(()) => InitStep::Done,
            Err(error) => InitStep::Failed(error),
        }
    }

    /// How many parts [`Supervised`] watches apart (1 or [`SUPERVISED_PARTS`]): each part has its
    /// own failures in a row, readiness and back-off, so a dead part takes out only the topics it
    /// serves and its retries set up only itself. Default: the group is one part.
    fn parts(&self) -> usize {
        1
    }

    /// The part (0, or 1 where [`parts`](Self::parts) is 2) that serves `topic`. Default: 0.
    fn part_of(&self, topic: Topic) -> usize {
        let _ = topic;
        0
    }

    /// Checks and configures `part` alone (boot). Default: [`init`](Self::init), for a group
    /// of one part.
    fn init_part(&mut self, part: usize) -> Result<(), SampleError> {
        let _ = part;
        self.init()
    }

    /// One step of `part`'s re-initialisation, as [`init_step`](Self::init_step) is the whole
    /// group's. Default: [`init_step`](Self::init_step), for a group of one part.
    fn init_part_step(&mut self, part: usize, now_us: u64) -> InitStep {
        let _ = part;
        self.init_step(now_us)
    }

    /// Reads one sample of `topic`, taken at `now_us` (groups that reuse a recent reading use it).
    fn sample(&mut self, topic: Topic, now_us: u64) -> Result<Samples, SampleError>;

    /// Whether this group serves `topic`.
    fn serves(&self, topic: Topic) -> bool {
        self.topics().contains(&topic)
    }
}

/// Where a stepwise (re-)initialisation stands ([`SensorGroup::init_step`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InitStep {
    /// The group is configured and may be sampled.
    Done,
    /// A step was taken; call again at `next_us` (µs) for the next.
    Pending {
        /// When the next step may run.
        next_us: u64,
    },
    /// A step failed.
    Failed(SampleError),
}

/// The steps of one part of [`InertialSensors`] in a stepwise set-up, one SPI access each: its
/// identity checked, its configuration written, then read back.
pub const INERTIAL_PART_SET_UP_STEPS: u8 = 3;

/// The steps of [`InertialSensors`]' whole stepwise set-up ([`SensorGroup::init_step`]): the
/// gyroscope's, then the accelerometer's.
pub const INERTIAL_SET_UP_STEPS: u8 = 2 * INERTIAL_PART_SET_UP_STEPS;

/// DiWheelDrive 1-1's gyroscope and accelerometer (SPI1, each with its own chip select).
#[derive(Debug)]
pub struct InertialSensors<G, A> {
    /// The L3G4200D.
    pub gyroscope: L3g4200d<G>,
    /// The LIS331DLH.
    pub accelerometer: Lis331dlh<A>,
    /// Each part's own periodic identity check, counted over its own topic's samples: the
    /// gyroscope's, then the accelerometer's.
    identity: [IdentitySchedule; 2],
    /// Each part's next set-up step ([`INERTIAL_PART_SET_UP_STEPS`]): the gyroscope's, then the
    /// accelerometer's.
    next_step: [u8; 2],
    /// Whether a whole-group stepwise set-up ([`SensorGroup::init_step`]) is at the
    /// accelerometer.
    whole_at_accelerometer: bool,
}

impl<G: SpiDevice, A: SpiDevice> InertialSensors<G, A> {
    /// The two parts at the protocol's ranges (±500 dps, ±8 g). Does no I/O.
    pub const fn new(gyroscope: G, accelerometer: A) -> Self {
        Self {
            gyroscope: L3g4200d::new(gyroscope),
            accelerometer: Lis331dlh::new(accelerometer),
            identity: [IdentitySchedule { samples: 0 }; 2],
            next_step: [0; 2],
            whole_at_accelerometer: false,
        }
    }

    /// One gyroscope reading in the finer unit (millidegrees per second).
    pub fn read_gyroscope(&mut self) -> Result<AngularRate, SampleError> {
        self.gyroscope.read().map_err(spi_error(Device::Gyroscope))
    }

    /// One accelerometer reading in the finer unit (micro-g).
    pub fn read_accelerometer(&mut self) -> Result<Acceleration, SampleError> {
        self.accelerometer
            .read()
            .map_err(spi_error(Device::Accelerometer))
    }
}

impl<G: SpiDevice, A: SpiDevice> SensorGroup for InertialSensors<G, A> {
    fn topics(&self) -> &'static [Topic] {
        &DIWHEELDRIVE_TOPICS[..2]
    }

    fn init(&mut self) -> Result<(), SampleError> {
        self.whole_at_accelerometer = false;
        self.init_part(0)?;
        self.init_part(1)
    }

    /// Supervised apart: part 0 the gyroscope, part 1 the accelerometer.
    fn parts(&self) -> usize {
        2
    }

    fn part_of(&self, topic: Topic) -> usize {
        usize::from(topic == Topic::Accelerometer)
    }

    fn init_part(&mut self, part: usize) -> Result<(), SampleError> {
        let accelerometer = part != 0;
        self.next_step[usize::from(accelerometer)] = 0;
        if accelerometer {
            self.accelerometer
                .init()
                .map_err(spi_error(Device::Accelerometer))
        } else {
            self.gyroscope.init().map_err(spi_error(Device::Gyroscope))
        }
    }

    /// Six steps of one SPI access each: the gyroscope's three
    /// ([`init_part_step`](SensorGroup::init_part_step)), then the accelerometer's.
    fn init_step(&mut self, now_us: u64) -> InitStep {
        let accelerometer = self.whole_at_accelerometer;
        match self.init_part_step(usize::from(accelerometer), now_us) {
            InitStep::Done if !accelerometer => {
                self.whole_at_accelerometer = true;
                InitStep::Pending { next_us: now_us }
            }
            InitStep::Pending { next_us } => InitStep::Pending { next_us },
            done_or_failed => {
                self.whole_at_accelerometer = false;
                done_or_failed
            }
        }
    }

    /// Three steps of one SPI access each for one part: its identity checked, its configuration
    /// written, read back. A release takes a step or a sample, so it makes at most two accesses.
    fn init_part_step(&mut self, part: usize, now_us: u64) -> InitStep {
        let accelerometer = part != 0;
        let index = usize::from(accelerometer);
        let step = self.next_step[index];
        let result = if accelerometer {
            let error = spi_error(Device::Accelerometer);
            match step {
                0 => self.accelerometer.check_identity().map_err(error),
                1 => self.accelerometer.write_configuration().map_err(error),
                _ => self.accelerometer.verify_configuration().map_err(error),
            }
        } else {
            let error = spi_error(Device::Gyroscope);
            match step {
                0 => self.gyroscope.check_identity().map_err(error),
                1 => self.gyroscope.write_configuration().map_err(error),
                _ => self.gyroscope.verify_configuration().map_err(error),
            }
        };
        match result {
            Ok(()) if step + 1 < INERTIAL_PART_SET_UP_STEPS => {
                self.next_step[index] = step + 1;
                InitStep::Pending { next_us: now_us }
            }
            Ok(()) => {
                self.next_step[index] = 0;
                InitStep::Done
            }
            Err(error) => {
                self.next_step[index] = 0;
                InitStep::Failed(error)
            }
        }
    }

    /// A topic's sample reads its own part; every [`IDENTITY_CHECK_EVERY`](super::IDENTITY_CHECK_EVERY)
    /// of its samples checks that part's identity first (and then not again on a reading that
    /// looks like a stuck line): at most two SPI accesses a sample.
    fn sample(&mut self, topic: Topic, _now_us: u64) -> Result<Samples, SampleError> {
        match topic {
            Topic::Gyroscope => {
                let rate = if self.identity[0].due() {
                    self.gyroscope.read_after_identity_check()
                } else {
                    self.gyroscope.read()
                };
                let rate = rate.map_err(spi_error(Device::Gyroscope))?;
                Ok(one(SensorData::Gyroscope(rate.degrees_per_s())))
            }
            Topic::Accelerometer => {
                let acceleration = if self.identity[1].due() {
                    self.accelerometer.read_after_identity_check()
                } else {
                    self.accelerometer.read()
                };
                let acceleration = acceleration.map_err(spi_error(Device::Accelerometer))?;
                Ok(one(SensorData::Accelerometer(acceleration.milli_g())))
            }
            other => Err(SampleError::NotServed(other)),
        }
    }
}

/// One HMC5883L reading serves all three magnetometer topics.
///
/// The three axes are separate topics (one i32 each), usually published together. A reading is
/// kept and handed out once per axis: the first axis sampled reads the part, the other two take
/// the same reading if they come less than [`Compass::reuse_window_us`] later (default one output period of
/// the part, 33.3 ms at 30 Hz — a fresh read in that window could only return the same data). An
/// axis sampled twice always triggers a new read, so a single running topic never repeats itself.
#[derive(Debug, Clone)]
pub struct Compass<I2C> {
    /// The HMC5883L.
    pub magnetometer: Hmc5883l<I2C>,
    reuse_window_us: u64,
    last: Option<(MagneticField, u64)>,
    delivered: [bool; 3],
    identity: IdentitySchedule,
}

/// One output period of the HMC5883L at the AMiRo's 30 Hz, in µs.
pub const MAGNETOMETER_PERIOD_US: u64 = 33_333;

impl<I2C> Compass<I2C> {
    /// The magnetometer at the AMiRo's gain. Does no I/O.
    pub const fn new(i2c: I2C) -> Self {
        Self {
            magnetometer: Hmc5883l::new(i2c),
            reuse_window_us: MAGNETOMETER_PERIOD_US,
            last: None,
            delivered: [false; 3],
            identity: IdentitySchedule { samples: 0 },
        }
    }

    /// How long a reading may serve the other axes.
    pub const fn reuse_window_us(&self) -> u64 {
        self.reuse_window_us
    }

    /// Sets how long a reading may serve the other axes (0: every sample reads the part).
    pub fn set_reuse_window_us(&mut self, window_us: u64) {
        self.reuse_window_us = window_us;
    }
}

impl<I2C: I2c> Compass<I2C> {
    /// Reads all three axes now (bypassing the reuse) and returns them as three frames, X, Y, Z.
    pub fn sample_all(&mut self, now_us: u64) -> Result<Samples, SampleError> {
        let field = self.read_fresh(now_us)?;
        self.delivered = [true; 3];
        let mut samples = Samples::new();
        for (axis, can_axis) in Axis::ALL.into_iter().zip(CanAxis::ALL) {
            let _ = samples.push(SensorData::Magnetometer {
                axis: can_axis,
                nanotesla: field.axis(axis),
            });
        }
        Ok(samples)
    }

    fn read_fresh(&mut self, now_us: u64) -> Result<MagneticField, SampleError> {
        let checked = if self.identity.due() {
            self.magnetometer.check_identity()
        } else {
            Ok(())
        };
        let read = checked.and_then(|()| self.magnetometer.read());
        self.keep(read.map_err(i2c_error(Device::Magnetometer)), now_us)
    }
}

impl<I2C> Compass<I2C> {
    /// The reading kept, if it may serve `axis` at `now_us` without the bus (not yet delivered
    /// for that axis, within the reuse window).
    pub(crate) fn reusable(&self, axis: Axis, now_us: u64) -> Option<MagneticField> {
        let already_sent = self.delivered.get(axis.index()).copied().unwrap_or(true);
        match self.last {
            Some((field, at))
                if !already_sent && now_us >= at && now_us - at < self.reuse_window_us =>
            {
                Some(field)
            }
            _ => None,
        }
    }

    /// A fresh read's outcome at `now_us`: a field kept for the other axes, a failure forgets
    /// the last one.
    pub(crate) fn keep(
        &mut self,
        read: Result<MagneticField, SampleError>,
        now_us: u64,
    ) -> Result<MagneticField, SampleError> {
        match read {
            Ok(field) => {
                self.last = Some((field, now_us));
                self.delivered = [false; 3];
                Ok(field)
            }
            Err(error) => {
                self.last = None;
                Err(error)
            }
        }
    }

    /// `field`'s frame of `axis`, the axis marked delivered.
    pub(crate) fn deliver(&mut self, axis: Axis, field: MagneticField) -> Samples {
        if let Some(flag) = self.delivered.get_mut(axis.index()) {
            *flag = true;
        }
        one(SensorData::Magnetometer {
            axis: can_axis(axis),
            nanotesla: field.axis(axis),
        })
    }

    /// Counts a fresh read; whether it checks the identity first.
    pub(crate) fn identity_due(&mut self) -> bool {
        self.identity.due()
    }

    /// The magnetometer (its gain).
    pub(crate) fn magnetometer(&self) -> &Hmc5883l<I2C> {
        &self.magnetometer
    }

    /// The set-up forgets the kept reading.
    pub(crate) fn forget(&mut self) {
        self.last = None;
    }
}

/// The axis of a magnetometer topic.
pub(crate) fn magnetometer_axis(topic: Topic) -> Result<Axis, SampleError> {
    match topic {
        Topic::MagnetometerX => Ok(Axis::X),
        Topic::MagnetometerY => Ok(Axis::Y),
        Topic::MagnetometerZ => Ok(Axis::Z),
        other => Err(SampleError::NotServed(other)),
    }
}

/// The protocol's axis of a sensor axis.
fn can_axis(axis: Axis) -> CanAxis {
    match axis {
        Axis::X => CanAxis::X,
        Axis::Y => CanAxis::Y,
        Axis::Z => CanAxis::Z,
    }
}

impl<I2C: I2c> SensorGroup for Compass<I2C> {
    fn topics(&self) -> &'static [Topic] {
        &DIWHEELDRIVE_TOPICS[2..5]
    }

    fn init(&mut self) -> Result<(), SampleError> {
        self.last = None;
        self.magnetometer
            .init()
            .map_err(i2c_error(Device::Magnetometer))
    }

    fn sample(&mut self, topic: Topic, now_us: u64) -> Result<Samples, SampleError> {
        let axis = magnetometer_axis(topic)?;
        let field = match self.reusable(axis, now_us) {
            Some(field) => field,
            None => self.read_fresh(now_us)?,
        };
        Ok(self.deliver(axis, field))
    }
}

impl<I2C: I2c> SensorGroup for FloorSensors<I2C> {
    fn topics(&self) -> &'static [Topic] {
        &[Topic::FloorProximity]
    }

    fn init(&mut self) -> Result<(), SampleError> {
        FloorSensors::init(self).map_err(floor_error)
    }

    /// One sensor per step ([`FloorSensors::init_next`]), channel 0 first.
    fn init_step(&mut self, now_us: u64) -> InitStep {
        match self.init_next() {
            Ok(true) => InitStep::Done,
            Ok(false) => InitStep::Pending { next_us: now_us },
            Err(error) => InitStep::Failed(floor_error(error)),
        }
    }

    fn sample(&mut self, topic: Topic, _now_us: u64) -> Result<Samples, SampleError> {
        if topic == Topic::FloorProximity && self.identity_check_due() {
            self.check_identities().map_err(floor_error)?;
        }
        match topic {
            Topic::FloorProximity => Ok(one(SensorData::FloorProximity(
                self.read_proximity().map_err(floor_error)?,
            ))),
            other => Err(SampleError::NotServed(other)),
        }
    }
}

pub(crate) fn floor_error<E: i2c::Error>(e: GroupError<E>) -> SampleError {
    i2c_error(Device::FloorSensor(e.sensor))(e.error)
}

/// DiWheelDrive 1-2's BNO055 on I2C1: gyroscope, accelerometer and the three magnetometer topics.
///
/// Each topic reads its own sensor's six bytes in one burst and then OPR_MODE
/// ([`Bno055::read_verified`]: about 310 µs at 400 kHz, the same on every sample, so the
/// analysis sees no execution-time jitter from a periodic check, and a part that reset or died is
/// caught on the sample it happens); the three magnetometer axes share one reading as [`Compass`]
/// does (the part's magnetometer runs at 30 Hz, so a reading serves the other axes for
/// [`MAGNETOMETER_PERIOD_US`]). `delay` paces the part's mode switches in `init` (26 ms of busy
/// waiting, at boot only); a re-initialisation runs in steps (`init_step`), the waits between
/// them outside the bus lock.
#[derive(Debug, Clone)]
pub struct ImuSensors<I2C, D> {
    /// The BNO055.
    pub imu: Bno055<I2C>,
    delay: D,
    reuse_window_us: u64,
    last_field: Option<([i32; 3], u64)>,
    delivered: [bool; 3],
    reinit: ImuReinit,
}

/// Where a stepwise re-initialisation of the BNO055 stands ([`ImuSensors`]'s `init_step`): the
/// next of [`Bno055::init`]'s six steps.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum ImuReinit {
    /// No re-initialisation under way: the next step selects page 0 and checks the identities.
    Idle,
    /// Identified: check the self-test and request configuration mode.
    Identified,
    /// Configuration mode requested: the power mode, the units and page 1 once the part is there.
    EnteringConfig,
    /// On page 1: the sensors' configuration written and read back.
    OnPage1,
    /// Configured: page 0, the units read back, AMG mode requested.
    Configured,
    /// AMG mode requested: check it once the part is there.
    EnteringAmg,
}

impl ImuReinit {
    /// The state after this state's step passed and the part's mode-switch time to wait before
    /// it (ms; 0: the next release), or `None` once the set-up is done.
    const fn after_step(self) -> Option<(ImuReinit, u32)> {
        match self {
            ImuReinit::Idle => Some((ImuReinit::Identified, 0)),
            ImuReinit::Identified => {
                Some((ImuReinit::EnteringConfig, bno055::OPERATING_TO_CONFIG_MS))
            }
            ImuReinit::EnteringConfig => Some((ImuReinit::OnPage1, 0)),
            ImuReinit::OnPage1 => Some((ImuReinit::Configured, 0)),
            ImuReinit::Configured => Some((ImuReinit::EnteringAmg, bno055::CONFIG_TO_OPERATING_MS)),
            ImuReinit::EnteringAmg => None,
        }
    }
}

impl<I2C, D> ImuSensors<I2C, D> {
    /// The BNO055 on `i2c`. Does no I/O.
    pub const fn new(i2c: I2C, delay: D) -> Self {
        Self {
            imu: Bno055::new(i2c),
            delay,
            reuse_window_us: MAGNETOMETER_PERIOD_US,
            last_field: None,
            delivered: [false; 3],
            reinit: ImuReinit::Idle,
        }
    }
}

impl<I2C: I2c, D: DelayNs> ImuSensors<I2C, D> {
    /// Waits (at most `timeout_ms`) for the part to answer after the board released its reset.
    pub fn wait_for_boot(&mut self, timeout_ms: u32) -> Result<(), SampleError> {
        self.imu
            .wait_for_boot(&mut self.delay, timeout_ms)
            .map_err(i2c_error(Device::Imu))
    }

    fn read(&mut self, first: u8) -> Result<[i16; 3], SampleError> {
        self.imu
            .read_verified(first)
            .map_err(i2c_error(Device::Imu))
    }
}

/// What a sample of one of [`ImuSensors`]' topics reads: one sensor's register block.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum ImuRead {
    /// The gyroscope's or the accelerometer's block: one frame of its own.
    Block(ImuBlock),
    /// The magnetometer's block, for one axis (a reading serves the three).
    Field(Axis),
}

/// A block whose read is one frame: the gyroscope's or the accelerometer's.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum ImuBlock {
    /// The gyroscope's block.
    Gyroscope,
    /// The accelerometer's block.
    Accelerometer,
}

impl ImuRead {
    /// The read of `topic`.
    pub(crate) fn of(topic: Topic) -> Result<Self, SampleError> {
        match topic {
            Topic::Gyroscope => Ok(ImuRead::Block(ImuBlock::Gyroscope)),
            Topic::Accelerometer => Ok(ImuRead::Block(ImuBlock::Accelerometer)),
            other => magnetometer_axis(other).map(ImuRead::Field),
        }
    }

    /// The block's first register.
    pub(crate) const fn first_register(self) -> u8 {
        match self {
            ImuRead::Block(ImuBlock::Gyroscope) => bno055::reg::GYR_DATA_X_LSB,
            ImuRead::Block(ImuBlock::Accelerometer) => bno055::reg::ACC_DATA_X_LSB,
            ImuRead::Field(_) => bno055::reg::MAG_DATA_X_LSB,
        }
    }
}

/// The frame of a gyroscope or accelerometer block's digits (the magnetometer's reading is kept
/// instead: [`ImuSensors`]).
pub(crate) fn imu_frame(block: ImuBlock, raw: [i16; 3]) -> Samples {
    match block {
        ImuBlock::Gyroscope => one(SensorData::Gyroscope(bno055::degrees_per_s(raw))),
        ImuBlock::Accelerometer => one(SensorData::Accelerometer(raw)),
    }
}

impl<I2C, D> ImuSensors<I2C, D> {
    /// The field kept, if it may serve `axis` at `now_us` without the bus.
    pub(crate) fn reusable_field(&self, axis: Axis, now_us: u64) -> Option<[i32; 3]> {
        let already_sent = self.delivered.get(axis.index()).copied().unwrap_or(true);
        match self.last_field {
            Some((field, at))
                if !already_sent && now_us >= at && now_us - at < self.reuse_window_us =>
            {
                Some(field)
            }
            _ => None,
        }
    }

    /// A fresh magnetometer block's outcome at `now_us`: the field kept for the other axes, or
    /// a failure that forgets the last one.
    pub(crate) fn keep_field(
        &mut self,
        raw: Result<[i16; 3], SampleError>,
        now_us: u64,
    ) -> Result<[i32; 3], SampleError> {
        match raw {
            Ok(raw) => {
                let field = bno055::nanotesla(raw);
                self.last_field = Some((field, now_us));
                self.delivered = [false; 3];
                Ok(field)
            }
            Err(error) => {
                self.last_field = None;
                Err(error)
            }
        }
    }

    /// `field`'s frame of `axis`, the axis marked delivered.
    pub(crate) fn deliver_field(&mut self, axis: Axis, field: [i32; 3]) -> Samples {
        if let Some(flag) = self.delivered.get_mut(axis.index()) {
            *flag = true;
        }
        one(SensorData::Magnetometer {
            axis: can_axis(axis),
            nanotesla: field.get(axis.index()).copied().unwrap_or(0),
        })
    }

    /// Where a stepwise set-up stands; a step forgets the kept field.
    pub(crate) fn begin_set_up_step(&mut self) -> ImuReinit {
        self.last_field = None;
        self.reinit
    }

    /// The step begun at `passed` passed: the next one pending after the part's mode switch, or
    /// the set-up done (both paths' stepwise set-up).
    pub(crate) fn set_up_step_passed(&mut self, passed: ImuReinit, now_us: u64) -> InitStep {
        match passed.after_step() {
            Some((state, wait_ms)) => {
                self.reinit = state;
                InitStep::Pending {
                    next_us: now_us.saturating_add(u64::from(wait_ms) * 1_000),
                }
            }
            None => {
                self.reinit = ImuReinit::Idle;
                InitStep::Done
            }
        }
    }

    /// A set-up step failed: the next set-up starts at `Idle` (both paths).
    pub(crate) fn set_up_step_failed<E: i2c::Error>(&mut self, error: Error<E>) -> InitStep {
        self.reinit = ImuReinit::Idle;
        InitStep::Failed(i2c_error(Device::Imu)(error))
    }

    /// A whole set-up begins (boot).
    pub(crate) fn begin_set_up(&mut self) {
        self.last_field = None;
        self.reinit = ImuReinit::Idle;
    }
}

impl<I2C: I2c, D: DelayNs> SensorGroup for ImuSensors<I2C, D> {
    fn topics(&self) -> &'static [Topic] {
        &DIWHEELDRIVE_TOPICS[..5]
    }

    fn init(&mut self) -> Result<(), SampleError> {
        self.last_field = None;
        self.reinit = ImuReinit::Idle;
        self.imu
            .init(&mut self.delay)
            .map_err(i2c_error(Device::Imu))
    }

    /// The re-initialisation without a busy wait: the six steps of [`Bno055::init`], one a
    /// release, the part's two mode switches (19 ms and 7 ms) waited between calls, outside the
    /// bus lock.
    fn init_step(&mut self, now_us: u64) -> InitStep {
        self.last_field = None;
        let step = self.reinit;
        let result = match step {
            ImuReinit::Idle => self.imu.init_identify(),
            ImuReinit::Identified => self.imu.init_self_test_then_config(),
            ImuReinit::EnteringConfig => self.imu.init_prepare_page_1(),
            ImuReinit::OnPage1 => self.imu.init_write_page_1(),
            ImuReinit::Configured => self.imu.init_start_amg(),
            ImuReinit::EnteringAmg => self.imu.init_check_running(),
        };
        match result {
            Ok(()) => self.set_up_step_passed(step, now_us),
            Err(error) => self.set_up_step_failed(error),
        }
    }

    fn sample(&mut self, topic: Topic, now_us: u64) -> Result<Samples, SampleError> {
        let read = ImuRead::of(topic)?;
        match read {
            ImuRead::Field(axis) => {
                let field = match self.reusable_field(axis, now_us) {
                    Some(field) => field,
                    None => {
                        let raw = self.read(read.first_register());
                        self.keep_field(raw, now_us)?
                    }
                };
                Ok(self.deliver_field(axis, field))
            }
            ImuRead::Block(block) => Ok(imu_frame(block, self.read(read.first_register())?)),
        }
    }
}

/// A group with no devices and no topics: a resource slot a board revision does not fill
/// (DiWheelDrive 1-2's `compass`, whose topics the BNO055 serves).
#[derive(Debug, Clone, Copy, Default)]
pub struct NoSensors;

impl SensorGroup for NoSensors {
    fn topics(&self) -> &'static [Topic] {
        &[]
    }

    fn init(&mut self) -> Result<(), SampleError> {
        Ok(())
    }

    fn sample(&mut self, topic: Topic, _now_us: u64) -> Result<Samples, SampleError> {
        Err(SampleError::NotServed(topic))
    }
}

/// Every sensor of DiWheelDrive 1-1. The fields are public so a firmware can split them into
/// separately locked resources.
#[derive(Debug)]
pub struct DiWheelDriveSensors<G, A, M, F> {
    /// Gyroscope and accelerometer on SPI1.
    pub inertial: InertialSensors<G, A>,
    /// Magnetometer on I2C1.
    pub compass: Compass<M>,
    /// Floor sensors behind the mux on I2C2.
    pub floor: FloorSensors<F>,
    /// The group a stepwise set-up is in: 0 inertial, 1 compass, 2 floor.
    init_part: u8,
}

impl<G: SpiDevice, A: SpiDevice, M: I2c, F: I2c> DiWheelDriveSensors<G, A, M, F> {
    /// The board's sensors on their buses: gyroscope SPI device (CS PC14), accelerometer SPI
    /// device (CS PC13), I2C1, I2C2. Does no I/O.
    pub const fn new(gyroscope: G, accelerometer: A, i2c1: M, i2c2: F) -> Self {
        Self {
            inertial: InertialSensors::new(gyroscope, accelerometer),
            compass: Compass::new(i2c1),
            floor: FloorSensors::new(i2c2),
            init_part: 0,
        }
    }
}

impl<G: SpiDevice, A: SpiDevice, M: I2c, F: I2c> SensorGroup for DiWheelDriveSensors<G, A, M, F> {
    fn topics(&self) -> &'static [Topic] {
        &DIWHEELDRIVE_TOPICS
    }

    fn init(&mut self) -> Result<(), SampleError> {
        self.init_part = 0;
        self.inertial.init()?;
        self.compass.init()?;
        SensorGroup::init(&mut self.floor)
    }

    /// The three groups' steps in turn (inertial, compass, floor), one step per call.
    fn init_step(&mut self, now_us: u64) -> InitStep {
        let (step, last) = match self.init_part {
            0 => (self.inertial.init_step(now_us), false),
            1 => (self.compass.init_step(now_us), false),
            _ => (SensorGroup::init_step(&mut self.floor, now_us), true),
        };
        match step {
            InitStep::Done if last => {
                self.init_part = 0;
                InitStep::Done
            }
            InitStep::Done => {
                self.init_part += 1;
                InitStep::Pending { next_us: now_us }
            }
            InitStep::Pending { next_us } => InitStep::Pending { next_us },
            InitStep::Failed(error) => {
                self.init_part = 0;
                InitStep::Failed(error)
            }
        }
    }

    fn sample(&mut self, topic: Topic, now_us: u64) -> Result<Samples, SampleError> {
        match topic {
            Topic::Gyroscope | Topic::Accelerometer => self.inertial.sample(topic, now_us),
            Topic::MagnetometerX | Topic::MagnetometerY | Topic::MagnetometerZ => {
                self.compass.sample(topic, now_us)
            }
            Topic::FloorProximity => SensorGroup::sample(&mut self.floor, topic, now_us),
            other => Err(SampleError::NotServed(other)),
        }
    }
}

/// PowerManagement's proximity ring and its two fuel gauges, which share I2C1 and I2C2.
#[derive(Debug)]
pub struct PowerManagementSensors<I1, I2, D> {
    /// The eight ring sensors and their muxes (which own the two buses).
    pub ring: ProximityRing<I1, I2>,
    delay: D,
    gauge_faults: [u32; 2],
    /// The next step of a stepwise set-up: ring sensor 0..=7, then the front gauge (8) and the
    /// rear one (9).
    next_to_init: u8,
}

impl<I1: I2c, I2: I2c, D: DelayNs> PowerManagementSensors<I1, I2, D> {
    /// The board's sensors on I2C1 and I2C2; `delay` paces the fuel gauges. Does no I/O.
    pub const fn new(i2c1: I1, i2c2: I2, delay: D) -> Self {
        Self {
            ring: ProximityRing::new(i2c1, i2c2),
            delay,
            gauge_faults: [0; 2],
            next_to_init: 0,
        }
    }

    /// Both batteries' gauge readings, front then rear.
    pub fn read_batteries(
        &mut self,
    ) -> (
        Result<BatteryStatus, SampleError>,
        Result<BatteryStatus, SampleError>,
    ) {
        let front = Bq27500::new(self.ring.i2c2_mut(), &mut self.delay)
            .read_status()
            .map_err(i2c_error(Device::FuelGauge(Battery::Front)));
        let rear = Bq27500::new(self.ring.i2c1_mut(), &mut self.delay)
            .read_status()
            .map_err(i2c_error(Device::FuelGauge(Battery::Rear)));
        (front, rear)
    }

    /// The combined power status. If one gauge fails the other one's reading is used (and the
    /// failure counted, see [`gauge_faults`](Self::gauge_faults)); if both fail, the front error.
    pub fn read_power(&mut self) -> Result<PowerSummary, SampleError> {
        let (front, rear) = self.read_batteries();
        if front.is_err() {
            self.gauge_faults[0] = self.gauge_faults[0].saturating_add(1);
        }
        if rear.is_err() {
            self.gauge_faults[1] = self.gauge_faults[1].saturating_add(1);
        }
        match (front, rear) {
            (Ok(a), Ok(b)) => Ok(PowerSummary::of_pair(&a, &b)),
            (Ok(one), Err(_)) | (Err(_), Ok(one)) => Ok(PowerSummary::of(&one)),
            (Err(e), Err(_)) => Err(e),
        }
    }

    /// Failed gauge reads so far: `[front, rear]`.
    pub const fn gauge_faults(&self) -> [u32; 2] {
        self.gauge_faults
    }
}

impl<I1: I2c, I2: I2c, D: DelayNs> SensorGroup for PowerManagementSensors<I1, I2, D> {
    fn topics(&self) -> &'static [Topic] {
        &[Topic::ProximityRing, Topic::PowerStatus]
    }

    fn init(&mut self) -> Result<(), SampleError> {
        self.next_to_init = 0;
        self.ring
            .init()
            .map_err(|e| i2c_error::<i2c::ErrorKind>(Device::RingSensor(e.sensor))(e.error))?;
        Bq27500::new(self.ring.i2c2_mut(), &mut self.delay)
            .init()
            .map_err(i2c_error(Device::FuelGauge(Battery::Front)))?;
        Bq27500::new(self.ring.i2c1_mut(), &mut self.delay)
            .init()
            .map_err(i2c_error(Device::FuelGauge(Battery::Rear)))
    }

    /// One device per step: the eight ring sensors by index, then the front gauge, the rear one.
    fn init_step(&mut self, now_us: u64) -> InitStep {
        let step = self.next_to_init;
        let result = match usize::from(step) {
            index @ 0..RING_SENSORS => self
                .ring
                .init_sensor(index)
                .map_err(|e| i2c_error::<i2c::ErrorKind>(Device::RingSensor(e.sensor))(e.error)),
            RING_SENSORS => Bq27500::new(self.ring.i2c2_mut(), &mut self.delay)
                .init()
                .map_err(i2c_error(Device::FuelGauge(Battery::Front))),
            _ => Bq27500::new(self.ring.i2c1_mut(), &mut self.delay)
                .init()
                .map_err(i2c_error(Device::FuelGauge(Battery::Rear))),
        };
        match result {
            Ok(()) if usize::from(step) > RING_SENSORS => {
                self.next_to_init = 0;
                InitStep::Done
            }
            Ok(()) => {
                self.next_to_init = step + 1;
                InitStep::Pending { next_us: now_us }
            }
            Err(error) => {
                self.next_to_init = 0;
                InitStep::Failed(error)
            }
        }
    }

    fn sample(&mut self, topic: Topic, _now_us: u64) -> Result<Samples, SampleError> {
        match topic {
            Topic::ProximityRing => {
                let mm = self.ring.read_mm().map_err(|e| {
                    i2c_error::<i2c::ErrorKind>(Device::RingSensor(e.sensor))(e.error)
                })?;
                let mut samples = Samples::new();
                for (sensor, mm) in (0u8..).zip(mm).take(RING_SENSORS) {
                    let _ = samples.push(SensorData::ProximityRing { sensor, mm });
                }
                Ok(samples)
            }
            Topic::PowerStatus => {
                let power = self.read_power()?;
                Ok(one(SensorData::PowerStatus(PowerStatus {
                    charging: power.charging,
                    state_of_charge: power.state_of_charge,
                    minutes: power.minutes,
                    power_mw: power.power_mw,
                })))
            }
            other => Err(SampleError::NotServed(other)),
        }
    }
}

impl<SPI: SpiDevice, const CHIPS: usize> LedRing<SPI, CHIPS> {
    /// Applies an LED command from the protocol: sets the LED's colour (its whole group on a
    /// 24-LED ring) and latches the whole ring.
    pub fn apply(&mut self, command: &LedCommand) -> Result<(), SampleError> {
        let rgb = command.rgb;
        self.set_led(command.led, rgb.r, rgb.g, rgb.b)
            .and_then(|()| self.flush())
            .map_err(spi_error(Device::LedDriver))
    }
}

/// Consecutive failed samples after which a [`Supervised`] group is treated as missing.
pub const FAILURES_BEFORE_RETRY: u8 = 3;
/// The first wait before a missing group is initialised again (µs).
pub const RETRY_FIRST_US: u64 = 1_000_000;
/// The longest wait between two attempts (µs): the wait doubles after every failed attempt up to
/// this, so a dead part costs one identity check per 8 s instead of one timeout per sample.
pub const RETRY_MAX_US: u64 = 8_000_000;

/// A sensor group with its fault policy: a group that failed stops publishing (its samples are
/// empty, never invented), every failure is counted, and it is initialised again with back-off.
///
/// - At construction the group is initialised; if that fails it is *missing*.
/// - A missing group answers nothing until its retry time; then it is set up again in steps
///   ([`SensorGroup::init_step`]): one step per release, at most one device's set-up, the
///   group answering nothing until the release after its last step, which samples it. A release
///   takes a step or a sample, never both, so it costs the longer of the two, never the whole
///   group's set-up nor a step and a sample together. A failed step doubles the
///   wait, 1 s → 2 → 4 → 8 s, stays at [`RETRY_MAX_US`], and the set-up starts again from its
///   first step at the next retry.
/// - A ready group whose sample fails [`FAILURES_BEFORE_RETRY`] times in a row becomes missing
///   (retry after the current wait, which then doubles). A successful sample resets the wait to
///   [`RETRY_FIRST_US`].
/// - [`faults`](Self::faults) counts every failed sample and every failed (re-)initialisation;
///   a topic the group does not serve is no fault.
/// - A group of two parts ([`SensorGroup::parts`]: the SPI pair, gyroscope and accelerometer)
///   has all of the above per part: each part is initialised, counts its failures in a row,
///   goes missing, backs off and is set up again ([`SensorGroup::init_part_step`]) on its own,
///   so a dead part stops only its own topic and a working part's samples neither keep it in
///   service nor wait for it. [`faults`](Self::faults) and [`last_error`](Self::last_error) are
///   the group's (both parts'); [`is_ready`](Self::is_ready) is false while either part is
///   missing.
#[derive(Debug, Clone)]
pub struct Supervised<G> {
    group: G,
    faults: u32,
    last_error: Option<SampleError>,
    /// Each part's state (a group of one part uses the first; the second stays ready).
    parts: [PartWatch; SUPERVISED_PARTS],
}

/// The most parts a [`Supervised`] group watches apart.
pub const SUPERVISED_PARTS: usize = 2;

/// One part's supervision: whether it is ready, its failures in a row, and its back-off (the
/// wait in 32 bits, at most [`RETRY_MAX_US`]: 16 bytes a part).
#[derive(Debug, Clone, Copy)]
struct PartWatch {
    retry_at_us: u64,
    backoff_us: u32,
    consecutive_failures: u8,
    ready: bool,
}

// The waits fit the part's 32-bit field.
const _: () = assert!(RETRY_FIRST_US <= RETRY_MAX_US && RETRY_MAX_US <= u32::MAX as u64);

impl PartWatch {
    const READY: Self = Self {
        retry_at_us: 0,
        backoff_us: RETRY_FIRST_US as u32,
        consecutive_failures: 0,
        ready: true,
    };
}

impl<G: SensorGroup> Supervised<G> {
    /// Initialises `group` (boot, time 0), each of its parts on its own.
    pub fn new(mut group: G) -> Self {
        let first = group.init_part(0);
        let mut supervised = Self::set_up(group, first);
        if supervised.group.parts() > 1 {
            if let Err(error) = supervised.group.init_part(1) {
                supervised.parts[1].ready = false;
                supervised.missing(1, 0, error);
            }
        }
        supervised
    }

    /// One sample of `topic`: its frames, or none while its part is missing or when it failed.
    pub fn sample(&mut self, topic: Topic, now_us: u64) -> Samples {
        let serves = self.group.serves(topic);
        let part = usize::from(serves && self.group.part_of(topic) != 0);
        match self.gate_part(part, serves, now_us) {
            Gate::Skip => return Samples::new(),
            Gate::SetUpStep => {
                // A release takes a set-up step or a sample, never both: the part's first
                // sample is the release after its last step.
                let step = self.group.init_part_step(part, now_us);
                self.stepped_part(part, step, now_us);
                return Samples::new();
            }
            Gate::Sample => {}
        }
        let result = self.group.sample(topic, now_us);
        self.sampled_part(part, result, now_us)
    }
}

/// What a supervised group's sample begins with ([`Supervised`]'s policy, shared by the
/// blocking path and the scripted one, `drivers::scripted`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Gate {
    /// Nothing: a topic the group does not serve, or a missing group before its retry time.
    Skip,
    /// A step of the set-up first ([`SensorGroup::init_step`]), then the sample if it was the
    /// last ([`Supervised::stepped`]).
    SetUpStep,
    /// The sample.
    Sample,
}

impl<G> Supervised<G> {
    /// The group after its boot set-up ended with `result` (time 0): ready, or missing.
    pub(crate) fn set_up(group: G, result: Result<(), SampleError>) -> Self {
        let mut supervised = Self {
            group,
            faults: 0,
            last_error: None,
            parts: [PartWatch::READY; SUPERVISED_PARTS],
        };
        if let Err(error) = result {
            supervised.parts[0].ready = false;
            supervised.missing(0, 0, error);
        }
        supervised
    }

    /// The group whose boot set-up has steps to go at `next_us` (the first samples from then
    /// take them, one each).
    pub(crate) fn set_up_pending(group: G, next_us: u64) -> Self {
        let mut supervised = Self::set_up(group, Ok(()));
        supervised.parts[0].ready = false;
        supervised.parts[0].retry_at_us = next_us;
        supervised
    }

    /// Whether every part of the group is initialised and its last samples worked (false while
    /// any part is missing: the board's "sensor fault now").
    pub const fn is_ready(&self) -> bool {
        self.parts[0].ready && self.parts[1].ready
    }

    /// Whether `part` ([`SensorGroup::part_of`]; any other than 0 is the second) is initialised
    /// and its last samples worked.
    pub const fn is_part_ready(&self, part: usize) -> bool {
        self.parts[if part == 0 { 0 } else { 1 }].ready
    }

    /// Failed samples and failed (re-)initialisations since boot (saturating).
    pub const fn faults(&self) -> u32 {
        self.faults
    }

    /// The most recent failure, if any.
    pub const fn last_error(&self) -> Option<SampleError> {
        self.last_error
    }

    /// When a missing group is tried next (µs): its missing part's retry, the earlier of the
    /// two where both are missing.
    pub const fn retry_at_us(&self) -> u64 {
        let [first, second] = self.parts;
        if second.ready || (!first.ready && first.retry_at_us <= second.retry_at_us) {
            first.retry_at_us
        } else {
            second.retry_at_us
        }
    }

    /// The group, e.g. for a test to inspect its buses.
    pub fn group_mut(&mut self) -> &mut G {
        &mut self.group
    }

    /// The group.
    pub const fn group(&self) -> &G {
        &self.group
    }

    /// What a sample at `now_us` of a topic the group `serves` (or not) begins with (a group of
    /// one part: the scripted path's).
    pub(crate) fn gate(&self, serves: bool, now_us: u64) -> Gate {
        self.gate_part(0, serves, now_us)
    }

    /// A set-up step of a group of one part ended with `step` ([`Self::stepped_part`]).
    pub(crate) fn stepped(&mut self, step: InitStep, now_us: u64) {
        self.stepped_part(0, step, now_us);
    }

    /// A sample of a group of one part ended with `result` ([`Self::sampled_part`]).
    pub(crate) fn sampled(&mut self, result: Result<Samples, SampleError>, now_us: u64) -> Samples {
        self.sampled_part(0, result, now_us)
    }

    /// What a sample at `now_us` of a topic of `part` the group `serves` (or not) begins with.
    fn gate_part(&self, part: usize, serves: bool, now_us: u64) -> Gate {
        let watch = &self.parts[if part == 0 { 0 } else { 1 }];
        if !serves || (!watch.ready && now_us < watch.retry_at_us) {
            Gate::Skip
        } else if !watch.ready {
            Gate::SetUpStep
        } else {
            Gate::Sample
        }
    }

    /// A set-up step of `part` ended with `step`: the part ready after its last step (its next
    /// release samples it), waiting for its next step, or missing again.
    fn stepped_part(&mut self, part: usize, step: InitStep, now_us: u64) {
        let index = if part == 0 { 0 } else { 1 };
        match step {
            InitStep::Done => {
                self.parts[index].ready = true;
                self.parts[index].consecutive_failures = 0;
            }
            InitStep::Pending { next_us } => {
                // Not a fault: more devices to set up (the next at the next sample), or the
                // group's parts are switching modes; the next step at `next_us` (the back-off is
                // left as it is).
                self.parts[index].retry_at_us = next_us;
            }
            InitStep::Failed(error) => self.missing(index, now_us, error),
        }
    }

    /// A sample of `part` ended with `result`: its frames, or none with the failure counted.
    fn sampled_part(
        &mut self,
        part: usize,
        result: Result<Samples, SampleError>,
        now_us: u64,
    ) -> Samples {
        let index = if part == 0 { 0 } else { 1 };
        match result {
            Ok(samples) => {
                self.parts[index].consecutive_failures = 0;
                self.parts[index].backoff_us = PartWatch::READY.backoff_us;
                samples
            }
            Err(error) => {
                self.faults = self.faults.saturating_add(1);
                self.last_error = Some(error);
                let watch = &mut self.parts[index];
                watch.consecutive_failures = watch.consecutive_failures.saturating_add(1);
                if watch.consecutive_failures >= FAILURES_BEFORE_RETRY {
                    watch.consecutive_failures = 0;
                    self.back_off(index, now_us);
                }
                Samples::new()
            }
        }
    }

    /// A failed (re-)initialisation of `part`: count it, wait, and double the next wait.
    fn missing(&mut self, part: usize, now_us: u64, error: SampleError) {
        self.faults = self.faults.saturating_add(1);
        self.last_error = Some(error);
        self.back_off(part, now_us);
    }

    /// Stop sampling `part` until its retry time, and double its wait after that.
    fn back_off(&mut self, part: usize, now_us: u64) {
        let watch = &mut self.parts[if part == 0 { 0 } else { 1 }];
        watch.ready = false;
        watch.retry_at_us = now_us.saturating_add(u64::from(watch.backoff_us));
        watch.backoff_us = watch.backoff_us.saturating_mul(2).min(RETRY_MAX_US as u32);
    }
}
