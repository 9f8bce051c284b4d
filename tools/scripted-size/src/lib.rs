//! Each DiWheelDrive I2C group's scripted sample (`Supervised::begin_scripted` and
//! `resume_scripted`, what `amiro_firmware::scripted::sample_on_bus` calls under the group's
//! lock) and PowerManagement's scripted parts behind `#[no_mangle]` wrappers, so that the static
//! library holds that code and what it reaches, and nothing else: its size is the scripted path's
//! code (run.sh).
#![no_std]

use amiro_can::Topic;
use amiro_sensors::drivers::bq27500::{BatteryStatus, StatusRead};
use amiro_sensors::drivers::floor::FloorSensors;
use amiro_sensors::drivers::scripted::{
    gauge_outcome, gauge_script, CompassStage, FloorStage, GaugeIdentity, ImuStage, Job, Next,
    RingRead, ScriptResult, Scripts, SensorSetUp,
};
use amiro_sensors::drivers::suite::{Compass, ImuSensors, Samples, Supervised};
use amiro_sensors::drivers::Error;
use amiro_sensors::script::Script;
use embedded_hal::i2c::ErrorKind;

#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    loop {}
}

/// The BNO055 group's delay (unused by the scripted path).
pub struct NoWait;

impl embedded_hal::delay::DelayNs for NoWait {
    fn delay_ns(&mut self, _: u32) {}
}

macro_rules! scripted_sample {
    ($begin:ident, $resume:ident, $group:ty, $stage:ty) => {
        /// A sample begun.
        #[no_mangle]
        pub fn $begin(
            group: &mut Supervised<$group>,
            job: &mut Job<$stage>,
            topic: Topic,
            now_us: u64,
        ) -> Next<Samples> {
            group.begin_scripted(job, topic, now_us)
        }

        /// A sample resumed with its script's result.
        #[no_mangle]
        pub fn $resume(
            group: &mut Supervised<$group>,
            job: &mut Job<$stage>,
            topic: Topic,
            now_us: u64,
            result: &ScriptResult,
        ) -> Next<Samples> {
            group.resume_scripted(job, topic, now_us, result)
        }
    };
}

scripted_sample!(
    compass_begin,
    compass_resume,
    Compass<Scripts>,
    CompassStage
);
scripted_sample!(floor_begin, floor_resume, FloorSensors<Scripts>, FloorStage);
scripted_sample!(imu_begin, imu_resume, ImuSensors<Scripts, NoWait>, ImuStage);

// PowerManagement's parts: a ring bus's read, a sensor's set-up, the gauge's status read and
// identity check, each a script at a time.

/// A part's end (`Some` once done) and its next script.
type Stepped<T, S> = (Option<Result<T, Error<ErrorKind>>>, S);
/// A script, or why it could not be built.
type Built = Result<Script, Error<ErrorKind>>;

/// A ring bus's next script.
#[no_mangle]
pub fn ring_script(read: &RingRead) -> Option<Built> {
    read.script()
}

/// A ring bus's script's result in.
#[no_mangle]
pub fn ring_complete(read: &mut RingRead, result: &ScriptResult) -> Option<[Option<u16>; 4]> {
    read.complete(result);
    read.counts()
}

/// A sensor's set-up: its next script and its last script's result.
#[no_mangle]
pub fn set_up_step(set_up: &mut SensorSetUp, result: &ScriptResult) -> Stepped<(), Built> {
    let done = set_up.complete(result);
    (done, set_up.script())
}

/// The gauge's status read: its last script's result in, its next script.
#[no_mangle]
pub fn gauge_status_step(
    read: &mut StatusRead,
    result: &ScriptResult,
) -> Stepped<BatteryStatus, Option<Built>> {
    let Some(transfer) = read.next_transfer() else {
        return (None, None);
    };
    let done = read.complete(gauge_outcome(transfer, result));
    (done, read.next_transfer().map(gauge_script))
}

/// The gauge's identity check: its last script's result in, its next script.
#[no_mangle]
pub fn gauge_identity_step(
    check: &mut GaugeIdentity,
    result: &ScriptResult,
) -> Stepped<(), Option<Built>> {
    let Some(transfer) = check.next_transfer() else {
        return (None, None);
    };
    let done = check.complete(gauge_outcome(transfer, result));
    (done, check.next_transfer().map(gauge_script))
}
