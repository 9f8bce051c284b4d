//! The sensor groups' bus work as [`Script`]s: each group builds the next script of a job from
//! its drivers' register maps (the `ops` of [`super::hmc5883l`], [`super::vcnl4020`],
//! [`super::bno055`], [`super::pca9544a::select_op`]) and decodes what came back with the same
//! decode functions the blocking drivers call (docs/i2c.md, "The sensor groups' scripts").
//!
//! A *job* is a sample of one topic, or a step of a group's set-up: one or more scripts, each
//! built once the one before it is decoded (an identity that must match before a write, a dead
//! bus's pattern that calls for an identity read, a mode switch the part needs time for). Where
//! the job stands between its scripts is a small value of the group's ([`ScriptedSensors::Stage`])
//! kept by the job's owner ([`Job`]), not by the group: two publishers whose samples of one group
//! overlap each keep theirs, and each decodes into the group as the group is when its script
//! ends.
//!
//! The groups' fault policy is [`Supervised`]'s, the same code on both paths: whether a sample
//! is skipped, takes a set-up step first, or is read ([`Supervised::begin_scripted`]); a step's
//! or a sample's end counted, backed off and retried ([`Supervised::resume_scripted`]). A script
//! that fails (or comes back short) is a typed failure of the device its operation addressed,
//! never a panic: the blocking path's `Error::Bus` with the embedded-hal kind a blocking bus
//! reports for the same event ([`failure_kind`]).
//!
//! At boot, before the engine takes the block, a group is set up by the same scripts run
//! operation by operation on the polled master ([`OnI2c`], [`Supervised::boot`]).

use amiro_can::{SensorData, Topic};
use embedded_hal::delay::DelayNs;
use embedded_hal::i2c::{self, ErrorKind, I2c, NoAcknowledgeSource};

use super::floor::{FloorSensor, FloorSensors, GroupError};
use super::hmc5883l::{self, MagneticField};
use super::pca9544a::{self, Channel};
use super::suite::{
    floor_error, i2c_error, imu_frame, magnetometer_axis, one, Compass, Device, Gate, ImuRead,
    ImuReinit, ImuSensors, InitStep, SampleError, Samples, Supervised, DIWHEELDRIVE_TOPICS,
};
use super::{bno055, bq27500, is_bus_pattern, vcnl4020, Error};
use crate::script::{At, BuildError, Failure, Readings, Script, ScriptError, MAX_READ_BYTES};

/// What a script came back with.
pub type ScriptResult = Result<Readings, ScriptError>;

/// A bus that runs a script to its end at once: the simulated buses
/// ([`crate::sim::SimBus::answer`]), the polled master at boot ([`OnI2c`]).
pub trait ScriptBus {
    /// Runs `script`: its readings, or the failed operation's error.
    fn run(&mut self, script: &Script) -> ScriptResult;
}

/// A script run operation by operation on a blocking embedded-hal bus (the polled master at
/// boot, before the engine takes the block): each operation one `write`, `read` or `write_read`,
/// the first that fails ending the script with its failure ([`kind_failure`]).
#[derive(Debug)]
pub struct OnI2c<I>(pub I);

impl<I: I2c> ScriptBus for OnI2c<I> {
    fn run(&mut self, script: &Script) -> ScriptResult {
        let mut readings = Readings::for_script(script);
        let mut written = script.written();
        for (index, op) in script.operations().iter().enumerate() {
            let (bytes, rest) = written.split_at(usize::from(op.write).min(written.len()));
            written = rest;
            let mut read = [0u8; MAX_READ_BYTES];
            let read = read.get_mut(..usize::from(op.read)).unwrap_or(&mut []);
            let result = match (bytes.is_empty(), read.is_empty()) {
                (false, true) => self.0.write(op.address, bytes),
                (true, false) => self.0.read(op.address, read),
                _ => self.0.write_read(op.address, bytes, read),
            };
            if let Err(error) = result {
                return Err(ScriptError {
                    operation: index as u8,
                    failure: kind_failure(i2c::Error::kind(&error)),
                });
            }
            for &byte in read.iter() {
                readings.push(byte);
            }
        }
        Ok(readings)
    }
}

/// The engine failure a blocking bus's error kind stands for ([`failure_kind`]'s inverse; a kind
/// the engine has no failure for, a polled master's timeout among them, is
/// [`Failure::UnexpectedEvent`]).
pub const fn kind_failure(kind: ErrorKind) -> Failure {
    match kind {
        ErrorKind::NoAcknowledge(NoAcknowledgeSource::Data) => Failure::NackData,
        ErrorKind::NoAcknowledge(_) => Failure::NackAddress,
        ErrorKind::Bus => Failure::Bus,
        ErrorKind::ArbitrationLoss => Failure::ArbitrationLoss,
        ErrorKind::Overrun => Failure::Overrun,
        _ => Failure::UnexpectedEvent,
    }
}

/// The embedded-hal error kind of an engine failure, as a blocking bus reports the same event.
pub const fn failure_kind(failure: Failure) -> ErrorKind {
    match failure {
        Failure::NackAddress => ErrorKind::NoAcknowledge(NoAcknowledgeSource::Address),
        Failure::NackData => ErrorKind::NoAcknowledge(NoAcknowledgeSource::Data),
        Failure::Bus => ErrorKind::Bus,
        Failure::ArbitrationLoss => ErrorKind::ArbitrationLoss,
        Failure::Overrun => ErrorKind::Overrun,
        // A script ended at its deadline is a polled master's timeout: `Other`.
        Failure::UnexpectedEvent | Failure::Busy | Failure::Stretched => ErrorKind::Other,
    }
}

/// What a script that did not end within its client's timeout stands for (the block was reset):
/// its first operation failed, with the kind a polled master's timeout has
/// ([`ErrorKind::Other`]).
pub const fn timed_out() -> ScriptResult {
    Err(ScriptError {
        operation: 0,
        failure: Failure::UnexpectedEvent,
    })
}

/// The bus of a group whose transfers are scripts: the group holds no bus, the job's owner runs
/// its scripts (`Compass<Scripts>`, `FloorSensors<Scripts>`, `ImuSensors<Scripts, D>`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Scripts;

/// What a job needs next.
#[derive(Debug, Clone, PartialEq)]
pub enum Next<T> {
    /// Run `script`, `settle_us` after the previous script at the earliest, and hand its result
    /// back.
    Run {
        /// The job's next bus work.
        script: Script,
        /// A part's settling time before it (µs; 0 mostly).
        settle_us: u32,
    },
    /// The job is done: its result.
    Done(T),
}

/// A sensor group whose jobs are scripts it builds and decodes itself.
pub trait ScriptedSensors {
    /// Where a job stands between two of its scripts (kept by the job's owner).
    type Stage: Copy + Default + core::fmt::Debug;
    /// Scripts one sample takes at most, a set-up step before it included.
    const MAX_SCRIPTS: usize;
    /// Steps of a whole set-up ([`Supervised::boot`]).
    const SET_UP_STEPS: usize;

    /// The topics the group serves.
    fn topics(&self) -> &'static [Topic];

    /// A whole set-up begins (the boot's): the step counters start again.
    fn begin_set_up(&mut self);

    /// One step of the set-up at `now_us` begun (as `SensorGroup::init_step`).
    fn begin_set_up_step(&mut self, stage: &mut Self::Stage, now_us: u64) -> Next<InitStep>;

    /// The step's last script's `result` in: the next script, or the step's end.
    fn resume_set_up_step(
        &mut self,
        stage: &mut Self::Stage,
        now_us: u64,
        result: &ScriptResult,
    ) -> Next<InitStep>;

    /// A sample of `topic` at `now_us` begun (as `SensorGroup::sample`).
    fn begin_sample(
        &mut self,
        stage: &mut Self::Stage,
        topic: Topic,
        now_us: u64,
    ) -> Next<Result<Samples, SampleError>>;

    /// The sample's last script's `result` in: the next script, or the sample.
    fn resume_sample(
        &mut self,
        stage: &mut Self::Stage,
        topic: Topic,
        now_us: u64,
        result: &ScriptResult,
    ) -> Next<Result<Samples, SampleError>>;
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    Idle,
    SetUpStep,
    Sample,
}

/// One publisher's sample of a supervised group while its scripts run: kept by the publisher,
/// a few bytes ([`ScriptedSensors::Stage`] and the phase).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Job<S> {
    phase: Phase,
    stage: S,
}

impl<S: Default> Default for Job<S> {
    fn default() -> Self {
        Self::new()
    }
}

impl<S: Default> Job<S> {
    /// A job not begun.
    pub fn new() -> Self {
        Self {
            phase: Phase::Idle,
            stage: S::default(),
        }
    }
}

impl<S> Job<S> {
    /// Whether a script of the job is out (its result not handed back yet).
    pub const fn under_way(&self) -> bool {
        !matches!(self.phase, Phase::Idle)
    }
}

fn carry<T, U>(next: Next<T>, done: impl FnOnce(T) -> Next<U>) -> Next<U> {
    match next {
        Next::Run { script, settle_us } => Next::Run { script, settle_us },
        Next::Done(value) => done(value),
    }
}

impl<G: ScriptedSensors> Supervised<G> {
    /// A publisher's sample of `topic` at `now_us` begun in `job` (which the publisher keeps
    /// until the sample is done): the first script, or the frames at once (a reading reused, a
    /// group in its back-off).
    pub fn begin_scripted(
        &mut self,
        job: &mut Job<G::Stage>,
        topic: Topic,
        now_us: u64,
    ) -> Next<Samples> {
        *job = Job::new();
        match self.gate(self.group().topics().contains(&topic), now_us) {
            Gate::Skip => Next::Done(Samples::new()),
            Gate::SetUpStep => {
                job.phase = Phase::SetUpStep;
                let next = self.group_mut().begin_set_up_step(&mut job.stage, now_us);
                self.after_step(job, now_us, next)
            }
            Gate::Sample => self.start_sample(job, topic, now_us),
        }
    }

    /// The same sample with its last script's `result`: the next script, or the frames (none
    /// when a device failed: counted as on the blocking path). A job not under way has none.
    pub fn resume_scripted(
        &mut self,
        job: &mut Job<G::Stage>,
        topic: Topic,
        now_us: u64,
        result: &ScriptResult,
    ) -> Next<Samples> {
        match job.phase {
            Phase::Idle => Next::Done(Samples::new()),
            Phase::SetUpStep => {
                let next = self
                    .group_mut()
                    .resume_set_up_step(&mut job.stage, now_us, result);
                self.after_step(job, now_us, next)
            }
            Phase::Sample => {
                let next = self
                    .group_mut()
                    .resume_sample(&mut job.stage, topic, now_us, result);
                self.after_sample(job, now_us, next)
            }
        }
    }

    /// A set-up step's scripts, then nothing: a release takes a step or a sample, never both (as
    /// on the blocking path, [`Supervised::sample`]).
    fn after_step(
        &mut self,
        job: &mut Job<G::Stage>,
        now_us: u64,
        next: Next<InitStep>,
    ) -> Next<Samples> {
        carry(next, |step| {
            self.stepped(step, now_us);
            job.phase = Phase::Idle;
            Next::Done(Samples::new())
        })
    }

    fn start_sample(
        &mut self,
        job: &mut Job<G::Stage>,
        topic: Topic,
        now_us: u64,
    ) -> Next<Samples> {
        job.phase = Phase::Sample;
        job.stage = G::Stage::default();
        let next = self.group_mut().begin_sample(&mut job.stage, topic, now_us);
        self.after_sample(job, now_us, next)
    }

    fn after_sample(
        &mut self,
        job: &mut Job<G::Stage>,
        now_us: u64,
        next: Next<Result<Samples, SampleError>>,
    ) -> Next<Samples> {
        carry(next, |result| {
            job.phase = Phase::Idle;
            Next::Done(self.sampled(result, now_us))
        })
    }

    /// The group's boot set-up (as `Supervised::new`'s) as scripts on `bus`: each step's scripts
    /// in turn, a part's settling time and the wait between two steps (the BNO055's mode
    /// switches) on `delay`. A step still asking for a script after [`ScriptedSensors::MAX_SCRIPTS`]
    /// is handed a timeout (a failure); a set-up still pending after
    /// [`ScriptedSensors::SET_UP_STEPS`] goes on stepwise at the first samples.
    pub fn boot(mut group: G, bus: &mut impl ScriptBus, delay: &mut impl DelayNs) -> Self {
        group.begin_set_up();
        let mut now_us = 0;
        for _ in 0..G::SET_UP_STEPS {
            let mut stage = G::Stage::default();
            let mut next = group.begin_set_up_step(&mut stage, now_us);
            // One more pass than scripts: the last hands the step a timeout, which every group
            // ends its step on.
            for scripts in 0..=G::MAX_SCRIPTS {
                let Next::Run { script, settle_us } = next else {
                    break;
                };
                let result = if scripts < G::MAX_SCRIPTS {
                    delay.delay_us(settle_us);
                    bus.run(&script)
                } else {
                    timed_out()
                };
                next = group.resume_set_up_step(&mut stage, now_us, &result);
            }
            match next {
                Next::Done(InitStep::Done) => return Self::set_up(group, Ok(())),
                Next::Done(InitStep::Failed(error)) => return Self::set_up(group, Err(error)),
                Next::Done(InitStep::Pending { next_us }) => {
                    delay.delay_us(
                        u32::try_from(next_us.saturating_sub(now_us)).unwrap_or(u32::MAX),
                    );
                    now_us = next_us;
                }
                // A step that did not end: the set-up goes on stepwise at the first samples.
                Next::Run { .. } => break,
            }
        }
        Self::set_up_pending(group, now_us)
    }
}

/// A sample of `topic` at `now_us` run to its end on a bus that answers at once (the
/// simulators, the host tests): no settling waits. At most [`ScriptedSensors::MAX_SCRIPTS`]
/// scripts; a sample that asks for more publishes nothing (as `amiro_firmware`'s
/// `sample_on_bus`).
pub fn sample_on<G: ScriptedSensors>(
    group: &mut Supervised<G>,
    bus: &mut impl ScriptBus,
    topic: Topic,
    now_us: u64,
) -> Samples {
    let mut job = Job::new();
    let mut next = group.begin_scripted(&mut job, topic, now_us);
    for _ in 0..G::MAX_SCRIPTS {
        match next {
            Next::Done(samples) => return samples,
            Next::Run { script, .. } => {
                let result = bus.run(&script);
                next = group.resume_scripted(&mut job, topic, now_us, &result);
            }
        }
    }
    match next {
        Next::Done(samples) => samples,
        Next::Run { .. } => Samples::new(),
    }
}

/// A script built by `ops`; a shape past a script's capacity (a driver's constant that a host
/// test finds) is the bus fault a blocking bus reports for a transfer it cannot make.
fn build(
    ops: impl FnOnce(&mut Script) -> Result<(), BuildError>,
) -> Result<Script, Error<ErrorKind>> {
    build_with(ops).map(|(script, ())| script)
}

/// [`build`] for a sequence that answers where its reads land ([`At`]).
fn build_with<R>(
    ops: impl FnOnce(&mut Script) -> Result<R, BuildError>,
) -> Result<(Script, R), Error<ErrorKind>> {
    let mut script = Script::new();
    let reads = ops(&mut script).map_err(|_| Error::Bus(ErrorKind::Other))?;
    Ok((script, reads))
}

/// The bytes of the read at `at` (a short one is a bus fault).
fn bytes<const N: usize>(readings: &Readings, at: At<N>) -> Result<[u8; N], Error<ErrorKind>> {
    at.of(readings).ok_or(Error::Bus(ErrorKind::Other))
}

/// The bytes operation `op` read, as a register block of `N` (a short one is a bus fault).
fn block<const N: usize>(readings: &Readings, op: usize) -> Result<[u8; N], Error<ErrorKind>> {
    readings
        .of(op)
        .try_into()
        .map_err(|_| Error::Bus(ErrorKind::Other))
}

/// A failed script's error as the blocking driver's.
fn bus_error(error: &ScriptError) -> Error<ErrorKind> {
    Error::Bus(failure_kind(error.failure))
}

/// The readings, or the failed script's error.
fn readings(result: &ScriptResult) -> Result<&Readings, Error<ErrorKind>> {
    result.as_ref().map_err(bus_error)
}

/// The next script of a job at `stage`, or the failure `fail` makes of a build error.
fn run_or<S, T>(
    stage: &mut S,
    at: S,
    script: Result<Script, Error<ErrorKind>>,
    settle_us: u32,
    fail: impl FnOnce(Error<ErrorKind>) -> T,
) -> Next<T> {
    match script {
        Ok(script) => {
            *stage = at;
            Next::Run { script, settle_us }
        }
        Err(error) => Next::Done(fail(error)),
    }
}

// DiWheelDrive 1-1's HMC5883L on I2C1.

/// Where a [`Compass`] job stands.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum CompassStage {
    /// Not begun.
    #[default]
    Begun,
    /// The set-up's identity read is out.
    SetUpIdentity,
    /// The set-up's writes and their read-back are out.
    SetUpWrites {
        /// Where the read-back lands.
        readback: At<3>,
    },
    /// The sample's data read is out, after the identity read when `checked`.
    Data {
        /// The periodic identity check is the script's first operation.
        checked: bool,
    },
    /// The data read six bytes of a dead bus's pattern (`raw`): the identity read is out.
    PatternIdentity {
        /// The data as read.
        raw: [i16; 3],
    },
}

impl Compass<Scripts> {
    /// The HMC5883L at the AMiRo's gain, its transfers made as scripts. Does no I/O.
    pub const fn scripted() -> Self {
        Self::new(Scripts)
    }

    fn finish(
        &mut self,
        axis: super::Axis,
        raw: Result<[i16; 3], Error<ErrorKind>>,
        now_us: u64,
    ) -> Result<Samples, SampleError> {
        let gain = self.magnetometer().gain();
        let read = raw.and_then(|raw| MagneticField::from_raw(raw, gain));
        let field = self.keep(read.map_err(i2c_error(Device::Magnetometer)), now_us)?;
        Ok(self.deliver(axis, field))
    }
}

fn compass_step_failed(error: Error<ErrorKind>) -> InitStep {
    InitStep::Failed(i2c_error(Device::Magnetometer)(error))
}

impl ScriptedSensors for Compass<Scripts> {
    type Stage = CompassStage;
    /// A set-up step (the identity, the writes) and a sample whose data is a dead bus's pattern
    /// (the data, the identity).
    const MAX_SCRIPTS: usize = 4;
    const SET_UP_STEPS: usize = 1;

    fn topics(&self) -> &'static [Topic] {
        DIWHEELDRIVE_TOPICS.get(2..5).unwrap_or(&[])
    }

    fn begin_set_up(&mut self) {}

    fn begin_set_up_step(&mut self, stage: &mut CompassStage, _now_us: u64) -> Next<InitStep> {
        self.forget();
        let script = build(hmc5883l::ops::identity);
        run_or(
            stage,
            CompassStage::SetUpIdentity,
            script,
            0,
            compass_step_failed,
        )
    }

    fn resume_set_up_step(
        &mut self,
        stage: &mut CompassStage,
        _now_us: u64,
        result: &ScriptResult,
    ) -> Next<InitStep> {
        let gain = self.magnetometer().gain();
        let checked = readings(result).and_then(|r| match *stage {
            CompassStage::SetUpIdentity => block(r, 0).and_then(hmc5883l::identity),
            CompassStage::SetUpWrites { readback } => bytes(r, readback).and_then(|readback| {
                hmc5883l::check_set_up(hmc5883l::set_up_values(gain), readback)
            }),
            _ => Err(Error::Bus(ErrorKind::Other)),
        });
        match (checked, *stage) {
            (Err(error), _) => Next::Done(compass_step_failed(error)),
            (Ok(()), CompassStage::SetUpIdentity) => {
                match build_with(|s| hmc5883l::ops::set_up(s, gain)) {
                    Ok((script, readback)) => {
                        *stage = CompassStage::SetUpWrites { readback };
                        Next::Run {
                            script,
                            settle_us: 0,
                        }
                    }
                    Err(error) => Next::Done(compass_step_failed(error)),
                }
            }
            (Ok(()), _) => Next::Done(InitStep::Done),
        }
    }

    fn begin_sample(
        &mut self,
        stage: &mut CompassStage,
        topic: Topic,
        now_us: u64,
    ) -> Next<Result<Samples, SampleError>> {
        let axis = match magnetometer_axis(topic) {
            Ok(axis) => axis,
            Err(error) => return Next::Done(Err(error)),
        };
        if let Some(field) = self.reusable(axis, now_us) {
            return Next::Done(Ok(self.deliver(axis, field)));
        }
        let checked = self.identity_due();
        let script = build(|s| {
            if checked {
                hmc5883l::ops::identity(s)?;
            }
            hmc5883l::ops::data(s)
        });
        match script {
            Ok(script) => {
                *stage = CompassStage::Data { checked };
                Next::Run {
                    script,
                    settle_us: 0,
                }
            }
            Err(error) => Next::Done(self.finish(axis, Err(error), now_us)),
        }
    }

    fn resume_sample(
        &mut self,
        stage: &mut CompassStage,
        topic: Topic,
        now_us: u64,
        result: &ScriptResult,
    ) -> Next<Result<Samples, SampleError>> {
        let axis = match magnetometer_axis(topic) {
            Ok(axis) => axis,
            Err(error) => return Next::Done(Err(error)),
        };
        let raw = readings(result).and_then(|r| match *stage {
            CompassStage::Data { checked } => {
                if checked {
                    block(r, 0).and_then(hmc5883l::identity)?;
                }
                block(r, usize::from(checked)).map(Ok)
            }
            CompassStage::PatternIdentity { raw } => {
                block(r, 0).and_then(hmc5883l::identity).map(|()| Err(raw))
            }
            _ => Err(Error::Bus(ErrorKind::Other)),
        });
        // `Ok(Ok(bytes))`: data to decode; `Ok(Err(raw))`: a pattern's data, its identity good.
        let raw = match raw {
            Ok(Ok(bytes)) if is_bus_pattern(&bytes) => {
                let pattern = CompassStage::PatternIdentity {
                    raw: hmc5883l::raw_field(bytes),
                };
                match build(hmc5883l::ops::identity) {
                    Ok(script) => {
                        *stage = pattern;
                        return Next::Run {
                            script,
                            settle_us: 0,
                        };
                    }
                    Err(error) => Err(error),
                }
            }
            Ok(Ok(bytes)) => Ok(hmc5883l::raw_field(bytes)),
            Ok(Err(raw)) => Ok(raw),
            Err(error) => Err(error),
        };
        Next::Done(self.finish(axis, raw, now_us))
    }
}

// DiWheelDrive's floor on I2C2: the PCA9544A and four VCNL4020s.

/// Sensors of the floor (and the ring's buses): a select and one transfer each per script.
const FLOOR_SENSORS: usize = FloorSensor::ALL.len();

/// Where a [`FloorSensors`] job stands.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum FloorStage {
    /// Not begun.
    #[default]
    Begun,
    /// A set-up step of `sensor` is under way.
    SetUp {
        /// The sensor (protocol index).
        sensor: u8,
        /// Its set-up.
        set_up: SensorSetUp,
    },
    /// The identity reads of the sensors in `sensors` (a bit per sensor) are out: all four for
    /// the periodic check before a round, or after a round the sensors whose count was a dead
    /// bus's pattern, with the round's `counts`.
    Identities {
        /// The sensors checked, bit k for sensor k.
        sensors: u8,
        /// The round's counts, once it was read.
        counts: Option<[u16; FLOOR_SENSORS]>,
    },
    /// The round's reads are out.
    Round,
}

/// Every floor sensor, a bit each.
const ALL_FLOOR_SENSORS: u8 = (1 << FLOOR_SENSORS) - 1;

/// The sensors of `mask` in order.
fn floor_sensors_of(mask: u8) -> impl Iterator<Item = u8> {
    (0..FLOOR_SENSORS as u8).filter(move |k| mask & (1 << k) != 0)
}

impl FloorStage {
    /// The sensor operation `op` of the stage's script addresses (each sensor's operations
    /// follow its select).
    fn sensor_of(self, op: u8) -> u8 {
        let pair = usize::from(op / 2);
        match self {
            FloorStage::SetUp { sensor, .. } => sensor,
            FloorStage::Identities { sensors, .. } => {
                floor_sensors_of(sensors).nth(pair).unwrap_or(0)
            }
            FloorStage::Round | FloorStage::Begun => pair as u8,
        }
    }
}

impl FloorSensors<Scripts> {
    /// The mux at 0x77 and four VCNL4020s at the original firmware's settings, their transfers
    /// made as scripts. Does no I/O.
    pub const fn scripted() -> Self {
        Self::new(Scripts)
    }

    fn select(&self, script: &mut Script, sensor: FloorSensor) -> Result<(), BuildError> {
        pca9544a::select_op(script, self.mux_address(), sensor.channel())
    }

    fn set_up_of(&self, part: FloorSensor) -> SensorSetUp {
        SensorSetUp::new(self.mux_address(), part.channel(), *self.config())
    }

    /// The round's script: each sensor's proximity behind its select.
    fn round_script(&self) -> Result<Script, Error<ErrorKind>> {
        build(|s| {
            for sensor in FloorSensor::ALL {
                self.select(s, sensor)?;
                vcnl4020::ops::result(s, vcnl4020::reg::PROXIMITY_RESULT)?;
            }
            Ok(())
        })
    }

    /// The identity reads of the sensors of `mask`, each behind its select.
    fn identities_script(&self, mask: u8) -> Result<Script, Error<ErrorKind>> {
        build(|s| {
            for k in floor_sensors_of(mask) {
                if let Some(&sensor) = FloorSensor::ALL.get(usize::from(k)) {
                    self.select(s, sensor)?;
                    vcnl4020::ops::identity(s)?;
                }
            }
            Ok(())
        })
    }

    fn step_failed(&mut self, sensor: u8, error: Error<ErrorKind>) -> InitStep {
        self.end_set_up_step(sensor, false);
        InitStep::Failed(floor_error(GroupError { sensor, error }))
    }
}

fn floor_failed(sensor: u8, error: Error<ErrorKind>) -> Result<Samples, SampleError> {
    Err(floor_error(GroupError { sensor, error }))
}

impl ScriptedSensors for FloorSensors<Scripts> {
    type Stage = FloorStage;
    /// The last sensor's set-up step (its identity and five writes), then a round with the
    /// periodic identity check before it and the identity check of its patterns after it.
    const MAX_SCRIPTS: usize = 6 + 3;
    const SET_UP_STEPS: usize = FLOOR_SENSORS;

    fn topics(&self) -> &'static [Topic] {
        DIWHEELDRIVE_TOPICS.get(5..).unwrap_or(&[])
    }

    fn begin_set_up(&mut self) {
        self.set_next_to_set_up(0);
    }

    fn begin_set_up_step(&mut self, stage: &mut FloorStage, now_us: u64) -> Next<InitStep> {
        let Some((sensor, part)) = self.sensor_to_set_up() else {
            return Next::Done(InitStep::Pending { next_us: now_us });
        };
        let set_up = self.set_up_of(part);
        match set_up.script() {
            Ok(script) => {
                *stage = FloorStage::SetUp { sensor, set_up };
                Next::Run {
                    script,
                    settle_us: 0,
                }
            }
            Err(error) => Next::Done(self.step_failed(sensor, error)),
        }
    }

    fn resume_set_up_step(
        &mut self,
        stage: &mut FloorStage,
        now_us: u64,
        result: &ScriptResult,
    ) -> Next<InitStep> {
        let FloorStage::SetUp { sensor, mut set_up } = *stage else {
            return Next::Done(self.step_failed(0, Error::Bus(ErrorKind::Other)));
        };
        match set_up.complete(result) {
            Some(Err(error)) => Next::Done(self.step_failed(sensor, error)),
            None => match set_up.script() {
                Ok(script) => {
                    *stage = FloorStage::SetUp { sensor, set_up };
                    Next::Run {
                        script,
                        settle_us: 0,
                    }
                }
                Err(error) => Next::Done(self.step_failed(sensor, error)),
            },
            Some(Ok(())) if self.end_set_up_step(sensor, true) => Next::Done(InitStep::Done),
            Some(Ok(())) => Next::Done(InitStep::Pending { next_us: now_us }),
        }
    }

    fn begin_sample(
        &mut self,
        stage: &mut FloorStage,
        topic: Topic,
        _now_us: u64,
    ) -> Next<Result<Samples, SampleError>> {
        if topic != Topic::FloorProximity {
            return Next::Done(Err(SampleError::NotServed(topic)));
        }
        let (at, script) = if self.identity_check_due() {
            let at = FloorStage::Identities {
                sensors: ALL_FLOOR_SENSORS,
                counts: None,
            };
            (at, self.identities_script(ALL_FLOOR_SENSORS))
        } else {
            (FloorStage::Round, self.round_script())
        };
        run_or(stage, at, script, 0, |error| floor_failed(0, error))
    }

    fn resume_sample(
        &mut self,
        stage: &mut FloorStage,
        _topic: Topic,
        _now_us: u64,
        result: &ScriptResult,
    ) -> Next<Result<Samples, SampleError>> {
        let r = match result {
            Ok(r) => r,
            Err(error) => {
                let sensor = stage.sensor_of(error.operation);
                return Next::Done(floor_failed(sensor, bus_error(error)));
            }
        };
        match *stage {
            FloorStage::Identities { sensors, counts } => {
                // In sensor order: the first that fails is the sample's failure, as the
                // blocking driver stops at it.
                for (i, sensor) in floor_sensors_of(sensors).enumerate() {
                    let checked = block::<1>(r, 2 * i + 1).and_then(|[id]| vcnl4020::identity(id));
                    if let Err(error) = checked {
                        return Next::Done(floor_failed(sensor, error));
                    }
                }
                match counts {
                    Some(counts) => Next::Done(Ok(one(SensorData::FloorProximity(counts)))),
                    None => {
                        let script = self.round_script();
                        run_or(stage, FloorStage::Round, script, 0, |error| {
                            floor_failed(0, error)
                        })
                    }
                }
            }
            FloorStage::Round => {
                let mut counts = [0; FLOOR_SENSORS];
                let mut patterns = 0u8;
                for (k, count) in counts.iter_mut().enumerate() {
                    let bytes = match block::<2>(r, 2 * k + 1) {
                        Ok(bytes) => bytes,
                        Err(error) => return Next::Done(floor_failed(k as u8, error)),
                    };
                    *count = vcnl4020::result(bytes);
                    if is_bus_pattern(&bytes) {
                        patterns |= 1 << k;
                    }
                }
                if patterns == 0 {
                    return Next::Done(Ok(one(SensorData::FloorProximity(counts))));
                }
                // As the blocking driver: a count of 0 or 0xFFFF is passed on only after the
                // sensor's PRODUCT_ID still answers.
                let at = FloorStage::Identities {
                    sensors: patterns,
                    counts: Some(counts),
                };
                let script = self.identities_script(patterns);
                run_or(stage, at, script, 0, |error| floor_failed(0, error))
            }
            FloorStage::SetUp { .. } | FloorStage::Begun => {
                Next::Done(floor_failed(0, Error::Bus(ErrorKind::Other)))
            }
        }
    }
}

// A VCNL4020 behind a PCA9544A channel (the floor's, the ring's) and PowerManagement's buses.

/// The set-up of one VCNL4020 behind its mux channel, as scripts: its PRODUCT_ID, then each of
/// the five set-up registers (`vcnl4020::set_up_writes`) written and read back, each script
/// behind the channel's select (a write reaches the part only after every check before it
/// passed, as on the blocking path). Six scripts: 59, then 88 SCL periods each.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SensorSetUp {
    mux: u8,
    channel: Channel,
    config: vcnl4020::Config,
    /// 0 the identity, then the set-up writes.
    register: u8,
}

impl Default for SensorSetUp {
    fn default() -> Self {
        Self::new(
            pca9544a::AMIRO_ADDRESS,
            Channel::Ch0,
            vcnl4020::Config::AMIRO,
        )
    }
}

impl SensorSetUp {
    /// The set-up of the sensor behind `channel` of the mux at `mux`, at `config`.
    pub const fn new(mux: u8, channel: Channel, config: vcnl4020::Config) -> Self {
        Self {
            mux,
            channel,
            config,
            register: 0,
        }
    }

    /// The next script.
    pub fn script(&self) -> Result<Script, Error<ErrorKind>> {
        let writes = vcnl4020::set_up_writes(&self.config);
        build(|s| {
            pca9544a::select_op(s, self.mux, self.channel)?;
            match usize::from(self.register).checked_sub(1) {
                None => vcnl4020::ops::identity(s),
                Some(k) => match writes.get(k) {
                    Some(&write) => vcnl4020::ops::set_up_write(s, write).map(|_| ()),
                    None => Err(BuildError::EmptyOperation),
                },
            }
        })
    }

    /// The last script's result in: `None` while scripts remain, then the set-up's outcome.
    pub fn complete(&mut self, result: &ScriptResult) -> Option<Result<(), Error<ErrorKind>>> {
        let writes = vcnl4020::set_up_writes(&self.config);
        let checked = readings(result).and_then(|r| {
            // Behind the select: PRODUCT_ID's read, or a write and its read-back.
            let [read] = block::<1>(r, if self.register == 0 { 1 } else { 2 })?;
            match usize::from(self.register).checked_sub(1) {
                None => vcnl4020::identity(read),
                Some(k) => match writes.get(k) {
                    Some(write) => write.check(read),
                    None => Err(Error::Bus(ErrorKind::Other)),
                },
            }
        });
        match checked {
            Err(error) => Some(Err(error)),
            Ok(()) if usize::from(self.register) >= writes.len() => Some(Ok(())),
            Ok(()) => {
                self.register += 1;
                None
            }
        }
    }
}

/// Sensors on one of PowerManagement's buses.
pub const RING_BUS_SENSORS: usize = 4;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum RingSensor {
    /// Its proximity is to be read.
    Pending,
    /// It read a dead bus's pattern: its PRODUCT_ID is to be read.
    Check(u16),
    /// Its count.
    Read(u16),
    /// It failed (its select, its read, or its identity after a pattern).
    Failed,
}

/// One PowerManagement bus's ring sensors read as scripts (the board's ring read of a bus): each
/// sensor's proximity behind its channel's select, in the bus's order, one script; a sensor that
/// fails yields no count and the others are read all the same, as on the blocking path. A
/// sensor whose count is a dead bus's pattern (0 or 0xFFFF) has its PRODUCT_ID read first, in the
/// next script with the sensors still to read. A failed script (which returns no readings) fails
/// the sensor its operation addressed; the sensors before it in that script are read again in the
/// next (their counts are the later ones, where the blocking path's were read before the
/// failure). At most [`RingRead::MAX_SCRIPTS`] scripts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RingRead {
    mux: u8,
    channels: [Channel; RING_BUS_SENSORS],
    count: u8,
    sensors: [RingSensor; RING_BUS_SENSORS],
}

impl RingRead {
    /// Scripts a read takes at most: each fails one sensor or moves every sensor it reads on
    /// (to its count, or to its identity check).
    pub const MAX_SCRIPTS: usize = 2 * RING_BUS_SENSORS + 1;

    /// A read of the sensors behind `channels` (the first four) of the mux at `mux`.
    pub fn new(mux: u8, channels: &[Channel]) -> Self {
        let mut read = Self {
            mux,
            channels: [Channel::Ch0; RING_BUS_SENSORS],
            count: 0,
            sensors: [RingSensor::Pending; RING_BUS_SENSORS],
        };
        for (slot, &channel) in read.channels.iter_mut().zip(channels) {
            *slot = channel;
            read.count += 1;
        }
        read
    }

    fn involved(&self) -> impl Iterator<Item = (usize, Channel, RingSensor)> + '_ {
        self.channels
            .iter()
            .zip(self.sensors)
            .take(usize::from(self.count))
            .enumerate()
            .filter(|(_, (_, s))| matches!(s, RingSensor::Pending | RingSensor::Check(_)))
            .map(|(k, (&c, s))| (k, c, s))
    }

    /// The next script, or `None` once every sensor has its count or failed.
    pub fn script(&self) -> Option<Result<Script, Error<ErrorKind>>> {
        self.involved().next()?;
        Some(build(|s| {
            for (_, channel, sensor) in self.involved() {
                pca9544a::select_op(s, self.mux, channel)?;
                match sensor {
                    RingSensor::Check(_) => vcnl4020::ops::identity(s)?,
                    _ => vcnl4020::ops::result(s, vcnl4020::reg::PROXIMITY_RESULT)?,
                }
            }
            Ok(())
        }))
    }

    /// The last script's result in.
    pub fn complete(&mut self, result: &ScriptResult) {
        // The sensors the script read, in its order (a copy: the loop below changes them).
        let mut involved = [None; RING_BUS_SENSORS];
        for (slot, (k, _, sensor)) in involved.iter_mut().zip(self.involved()) {
            *slot = Some((k, sensor));
        }
        let involved = involved.into_iter().flatten();
        match result {
            Err(error) => {
                let failed = involved.clone().nth(usize::from(error.operation / 2));
                if let Some(slot) = failed.and_then(|(k, _)| self.sensors.get_mut(k)) {
                    *slot = RingSensor::Failed;
                }
            }
            Ok(r) => {
                for (i, (k, sensor)) in involved.enumerate() {
                    let op = 2 * i + 1;
                    let next = match sensor {
                        RingSensor::Check(count) => match block::<1>(r, op) {
                            Ok([id]) if vcnl4020::identity::<()>(id).is_ok() => {
                                RingSensor::Read(count)
                            }
                            _ => RingSensor::Failed,
                        },
                        _ => match block::<2>(r, op) {
                            Ok(bytes) if is_bus_pattern(&bytes) => {
                                RingSensor::Check(vcnl4020::result(bytes))
                            }
                            Ok(bytes) => RingSensor::Read(vcnl4020::result(bytes)),
                            Err(_) => RingSensor::Failed,
                        },
                    };
                    if let Some(slot) = self.sensors.get_mut(k) {
                        *slot = next;
                    }
                }
            }
        }
    }

    /// Once no script remains: each sensor's count in the order of the channels given, `None`
    /// for one that failed (and past the channels given).
    pub fn counts(&self) -> Option<[Option<u16>; RING_BUS_SENSORS]> {
        if self.involved().next().is_some() {
            return None;
        }
        let mut counts = [None; RING_BUS_SENSORS];
        for (out, sensor) in counts
            .iter_mut()
            .zip(self.sensors)
            .take(usize::from(self.count))
        {
            if let RingSensor::Read(count) = sensor {
                *out = Some(count);
            }
        }
        Some(counts)
    }
}

/// The wait before each of a bq27500's scripts: its bus-free time between packets (a job's first
/// script too: another job's last transfer to the gauge may just have ended).
pub const GAUGE_SETTLE_US: u32 = bq27500::BUS_FREE_NS.div_ceil(1_000);

/// A gauge transfer as a script of its own ([`bq27500::transfer_op`]).
pub fn gauge_script(transfer: bq27500::Transfer) -> Result<Script, Error<ErrorKind>> {
    build(|s| bq27500::transfer_op(s, transfer))
}

/// A gauge script's outcome as the blocking driver's transfer gives it: a read's word, 0 for a
/// write, or the bus fault.
pub fn gauge_outcome(
    transfer: bq27500::Transfer,
    result: &ScriptResult,
) -> Result<u16, Error<ErrorKind>> {
    let r = readings(result)?;
    match transfer {
        bq27500::Transfer::Write { .. } => Ok(0),
        bq27500::Transfer::Read(_) => block(r, 0).map(bq27500::word),
    }
}

/// The gauge's identity check as scripts (`Bq27500::init`'s Control(DEVICE_TYPE)): its three
/// transfers, each a script of its own after [`GAUGE_SETTLE_US`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct GaugeIdentity {
    made: u8,
}

impl GaugeIdentity {
    /// A check not begun.
    pub const fn new() -> Self {
        Self { made: 0 }
    }

    /// The next transfer (`None` after the third).
    pub fn next_transfer(&self) -> Option<bq27500::Transfer> {
        bq27500::control_transfers(bq27500::subcommand::DEVICE_TYPE)
            .get(usize::from(self.made))
            .copied()
    }

    /// The transfer's outcome: `None` while transfers remain, then the check's.
    pub fn complete<E>(&mut self, outcome: Result<u16, Error<E>>) -> Option<Result<(), Error<E>>> {
        let last = usize::from(self.made) + 1 >= bq27500::control_transfers(0).len();
        self.made = self.made.saturating_add(1);
        match outcome {
            Err(error) => Some(Err(error)),
            Ok(found) if last => Some(bq27500::device_type(found)),
            Ok(_) => None,
        }
    }
}

// DiWheelDrive 1-2's BNO055 on I2C1.

/// Where an [`ImuSensors`] job stands.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum ImuStage {
    /// Not begun.
    #[default]
    Begun,
    /// Set-up step 1: page 0 and the identities are out.
    Identity {
        /// Where the four identity bytes land.
        identity: At<4>,
    },
    /// Set-up step 2: the self-test's result is out.
    SelfTest {
        /// Where ST_RESULT lands.
        self_test: At<1>,
    },
    /// Set-up step 2: configuration mode is out.
    EnterConfig,
    /// Set-up step 3: the power mode, the units and page 1 are out.
    PreparePage1,
    /// Set-up step 4: the configuration and its read-back are out.
    WritePage1 {
        /// Where the page-1 configuration's read-back lands.
        readback: At<4>,
    },
    /// Set-up step 5: page 0 and UNIT_SEL's read-back are out.
    Units {
        /// Where UNIT_SEL's read-back lands.
        units: At<1>,
    },
    /// Set-up step 5: AMG mode is out.
    StartAmg,
    /// Set-up step 6: OPR_MODE is out.
    CheckAmg {
        /// Where OPR_MODE lands.
        opr: At<1>,
    },
    /// A sample's block and OPR_MODE are out.
    Sample {
        /// Where the block's six bytes land.
        data: At<6>,
        /// Where OPR_MODE lands.
        opr: At<1>,
    },
}

impl<D> ImuSensors<Scripts, D> {
    /// The BNO055, its transfers made as scripts (`delay` is not used: the mode switches' waits
    /// are the jobs', between scripts, and the supervisor's, between set-up steps).
    pub const fn scripted(delay: D) -> Self {
        Self::new(Scripts, delay)
    }

    fn next_script<R>(
        &mut self,
        stage: &mut ImuStage,
        at: impl FnOnce(R) -> ImuStage,
        ops: impl FnOnce(&mut Script) -> Result<R, BuildError>,
    ) -> Next<InitStep> {
        match build_with(ops) {
            Ok((script, reads)) => {
                *stage = at(reads);
                Next::Run {
                    script,
                    settle_us: 0,
                }
            }
            Err(error) => Next::Done(self.set_up_step_failed(error)),
        }
    }
}

impl<D> ScriptedSensors for ImuSensors<Scripts, D> {
    type Stage = ImuStage;
    /// Set-up step 2's or step 5's two scripts (a release takes a step or a sample, never both;
    /// every other step and a sample are one script each).
    const MAX_SCRIPTS: usize = 2;
    const SET_UP_STEPS: usize = 6;

    fn topics(&self) -> &'static [Topic] {
        DIWHEELDRIVE_TOPICS.get(..5).unwrap_or(&[])
    }

    fn begin_set_up(&mut self) {
        ImuSensors::begin_set_up(self);
    }

    fn begin_set_up_step(&mut self, stage: &mut ImuStage, _now_us: u64) -> Next<InitStep> {
        match self.begin_set_up_step() {
            ImuReinit::Idle => self.next_script(
                stage,
                |identity| ImuStage::Identity { identity },
                bno055::ops::identity_on_page_0,
            ),
            ImuReinit::Identified => self.next_script(
                stage,
                |self_test| ImuStage::SelfTest { self_test },
                bno055::ops::self_test_result,
            ),
            ImuReinit::EnteringConfig => self.next_script(
                stage,
                |()| ImuStage::PreparePage1,
                bno055::ops::prepare_page_1,
            ),
            ImuReinit::OnPage1 => self.next_script(
                stage,
                |readback| ImuStage::WritePage1 { readback },
                bno055::ops::write_page_1,
            ),
            ImuReinit::Configured => self.next_script(
                stage,
                |units| ImuStage::Units { units },
                bno055::ops::page_0_units,
            ),
            ImuReinit::EnteringAmg => self.next_script(
                stage,
                |opr| ImuStage::CheckAmg { opr },
                bno055::ops::operating_mode,
            ),
        }
    }

    fn resume_set_up_step(
        &mut self,
        stage: &mut ImuStage,
        now_us: u64,
        result: &ScriptResult,
    ) -> Next<InitStep> {
        let checked = readings(result).and_then(|r| match *stage {
            ImuStage::Identity { identity } => bytes(r, identity).and_then(bno055::identity),
            ImuStage::SelfTest { self_test } => {
                bytes(r, self_test).and_then(|[st]| bno055::self_test(st))
            }
            ImuStage::WritePage1 { readback } => {
                bytes(r, readback).and_then(bno055::check_configuration)
            }
            ImuStage::Units { units } => {
                bytes(r, units).and_then(|[units]| bno055::check_units(units))
            }
            ImuStage::CheckAmg { opr } => {
                bytes(r, opr).and_then(|[opr]| bno055::check_amg_started(opr))
            }
            ImuStage::EnterConfig | ImuStage::PreparePage1 | ImuStage::StartAmg => Ok(()),
            ImuStage::Begun | ImuStage::Sample { .. } => Err(Error::Bus(ErrorKind::Other)),
        });
        if let Err(error) = checked {
            return Next::Done(self.set_up_step_failed(error));
        }
        // The step whose last script this was (steps 2 and 5 go on with their second).
        let passed = match *stage {
            ImuStage::Identity { .. } => ImuReinit::Idle,
            ImuStage::SelfTest { .. } => {
                return self.next_script(
                    stage,
                    |()| ImuStage::EnterConfig,
                    bno055::ops::enter_config,
                )
            }
            ImuStage::EnterConfig => ImuReinit::Identified,
            ImuStage::PreparePage1 => ImuReinit::EnteringConfig,
            ImuStage::WritePage1 { .. } => ImuReinit::OnPage1,
            ImuStage::Units { .. } => {
                return self.next_script(stage, |()| ImuStage::StartAmg, bno055::ops::start_amg)
            }
            ImuStage::StartAmg => ImuReinit::Configured,
            _ => ImuReinit::EnteringAmg,
        };
        Next::Done(self.set_up_step_passed(passed, now_us))
    }

    fn begin_sample(
        &mut self,
        stage: &mut ImuStage,
        topic: Topic,
        now_us: u64,
    ) -> Next<Result<Samples, SampleError>> {
        let read = match ImuRead::of(topic) {
            Ok(read) => read,
            Err(error) => return Next::Done(Err(error)),
        };
        if let ImuRead::Field(axis) = read {
            if let Some(field) = self.reusable_field(axis, now_us) {
                return Next::Done(Ok(self.deliver_field(axis, field)));
            }
        }
        let script = build_with(|s| bno055::ops::verified_block(s, read.first_register()));
        match script {
            Ok((script, (data, opr))) => {
                *stage = ImuStage::Sample { data, opr };
                Next::Run {
                    script,
                    settle_us: 0,
                }
            }
            Err(error) => Next::Done(self.finish(read, Err(error), now_us)),
        }
    }

    fn resume_sample(
        &mut self,
        stage: &mut ImuStage,
        topic: Topic,
        now_us: u64,
        result: &ScriptResult,
    ) -> Next<Result<Samples, SampleError>> {
        let read = match ImuRead::of(topic) {
            Ok(read) => read,
            Err(error) => return Next::Done(Err(error)),
        };
        let ImuStage::Sample { data, opr } = *stage else {
            return Next::Done(self.finish(read, Err(Error::Bus(ErrorKind::Other)), now_us));
        };
        let raw = readings(result).and_then(|r| {
            let block = bytes(r, data)?;
            bytes(r, opr).and_then(|[opr]| bno055::still_running(opr))?;
            Ok(bno055::le3(&block))
        });
        Next::Done(self.finish(read, raw, now_us))
    }
}

impl<D> ImuSensors<Scripts, D> {
    fn finish(
        &mut self,
        read: ImuRead,
        raw: Result<[i16; 3], Error<ErrorKind>>,
        now_us: u64,
    ) -> Result<Samples, SampleError> {
        let raw = raw.map_err(i2c_error(Device::Imu));
        match read {
            ImuRead::Field(axis) => {
                let field = self.keep_field(raw, now_us)?;
                Ok(self.deliver_field(axis, field))
            }
            ImuRead::Block(block) => Ok(imu_frame(block, raw?)),
        }
    }
}
