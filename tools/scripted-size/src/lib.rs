//! Each DiWheelDrive I2C group's scripted sample (`Supervised::begin_scripted` and
//! `resume_scripted`, what `amiro_firmware::scripted::sample_on_bus` calls under the group's
//! lock) behind a `#[no_mangle]` wrapper, so that the static library holds that code and what it
//! reaches, and nothing else: its size is the scripted path's code (run.sh).
#![no_std]

use amiro_can::Topic;
use amiro_sensors::drivers::floor::FloorSensors;
use amiro_sensors::drivers::scripted::{
    CompassStage, FloorStage, ImuStage, Job, Next, ScriptResult, Scripts,
};
use amiro_sensors::drivers::suite::{Compass, ImuSensors, Samples, Supervised};

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

scripted_sample!(compass_begin, compass_resume, Compass<Scripts>, CompassStage);
scripted_sample!(floor_begin, floor_resume, FloorSensors<Scripts>, FloorStage);
scripted_sample!(imu_begin, imu_resume, ImuSensors<Scripts, NoWait>, ImuStage);
