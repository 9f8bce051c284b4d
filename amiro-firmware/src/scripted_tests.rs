//! A scripted sample end to end on the host: the group's lock taken only to begin and to finish,
//! the publisher suspended while the interrupt-driven bus (over the register-level model) or the
//! QEMU build's simulated bus runs the script, the client's timeout ending a stuck script, and the
//! failures reaching the group.
use core::cell::{Cell, RefCell};
use core::future::{poll_fn, Future};
use core::pin::pin;
use core::task::{Context, Poll};

use amiro_can::{Axis, SensorData, Topic};
use amiro_sensors::drivers::floor::FloorSensors;
use amiro_sensors::drivers::scripted::{ScriptBus, ScriptedSensors};
use amiro_sensors::drivers::suite::{Compass, ImuSensors, Samples, SensorGroup, Supervised};
use amiro_sensors::drivers::{bno055, hmc5883l, pca9544a, vcnl4020};
use amiro_sensors::script::{Failure, Readings, Script, ScriptError};
use amiro_sensors::sim::{Bno055Fault, NoDelay, SimCompassBus, SimFloorBus, SimImuBus};
use embedded_hal::i2c::I2c;

use crate::i2c_bus::I2cBus;
use crate::i2c_engine::CR1_START;
use crate::i2c_model::{Access, Device, Model};
use crate::i2c_sim::{SimBus, SimPort};
use crate::scripted::{
    sample_on_bus, script_timeout_us, BusFault, Deadline, I2cPort, ScriptPort, ScriptedGroup, Step,
};
use crate::test_waker;

thread_local! {
    static NOW_US: Cell<u64> = const { Cell::new(0) };
}

/// Moves [`TestClock`] to `us` (this test's thread only).
pub(crate) fn set_now(us: u64) {
    NOW_US.with(|now| now.set(us));
}

/// The monotonic as the tests move it (here and in `i2c_tests`' runs under the bus's watch).
pub(crate) struct TestClock;

impl Deadline for TestClock {
    fn now_us() -> u64 {
        NOW_US.with(Cell::get)
    }

    fn delay_until_us(at_us: u64) -> impl Future<Output = ()> {
        poll_fn(move |_| {
            if Self::now_us() >= at_us {
                Poll::Ready(())
            } else {
                Poll::Pending
            }
        })
    }

    async fn timeout_at_us<F: Future>(at_us: u64, future: F) -> Option<F::Output> {
        let mut future = pin!(future);
        poll_fn(|cx| match future.as_mut().poll(cx) {
            Poll::Ready(output) => Poll::Ready(Some(output)),
            Poll::Pending if Self::now_us() >= at_us => Poll::Ready(None),
            Poll::Pending => Poll::Pending,
        })
        .await
    }
}

/// An RTIC resource's lock as the tests see it: how often it was taken, and never twice at once.
struct Lock<T> {
    value: RefCell<T>,
    taken: Cell<usize>,
}

impl<T> Lock<T> {
    fn new(value: T) -> Self {
        Self {
            value: RefCell::new(value),
            taken: Cell::new(0),
        }
    }

    /// Another task's lock of the same group (it would block if the sample held the lock).
    fn other_task(&self) -> std::cell::RefMut<'_, T> {
        self.value
            .try_borrow_mut()
            .expect("the group's lock is held across the bus")
    }
}

impl<T> rtic_core::Mutex for &Lock<T> {
    type T = T;

    fn lock<R>(&mut self, f: impl FnOnce(&mut T) -> R) -> R {
        self.taken.set(self.taken.get() + 1);
        f(&mut self.value.borrow_mut())
    }
}

/// A magnetometer group that samples by script: with `check_identity` its sample first reads
/// the HMC5883L's identification registers (three bytes from IDENTIFICATION_A, "H43") and reads
/// the data only if they match; the data script is the register block (six bytes from
/// DATA_X_MSB, X Z Y big-endian; the datasheet's register list), decoded to the X axis. The
/// job (which script a sample is at) is the publisher's.
#[derive(Default)]
struct Magnetometer {
    /// Serve the frames without the bus (a reading reused).
    reuse: Option<i32>,
    check_identity: bool,
    /// Never done: every outcome asks for one more script.
    endless: bool,
    outcomes: Vec<Result<Readings, BusFault>>,
}

#[derive(Default, Clone, Copy, PartialEq, Eq, Debug)]
enum Stage {
    #[default]
    Idle,
    Identity,
    Data,
}

fn register_read(register: u8, count: usize) -> Script {
    let mut script = Script::new();
    script
        .write_read(hmc5883l::ADDRESS, &[register], count)
        .unwrap();
    script
}

fn x_frame(nanotesla: i32) -> Samples {
    let mut frames = Samples::new();
    let _ = frames.push(SensorData::Magnetometer {
        axis: Axis::X,
        nanotesla,
    });
    frames
}

fn run(job: &mut Stage, stage: Stage) -> Step {
    *job = stage;
    let script = match stage {
        Stage::Identity => register_read(hmc5883l::reg::IDENTIFICATION_A, 3),
        _ => register_read(hmc5883l::reg::DATA_X_MSB, 6),
    };
    Step::Run {
        script,
        settle_us: 0,
    }
}

impl ScriptedGroup for Magnetometer {
    type Job = Stage;
    const MAX_ROUNDS: usize = 3;

    fn new_job() -> Stage {
        Stage::Idle
    }

    fn begin(&mut self, job: &mut Stage, topic: Topic, _now_us: u64) -> Step {
        assert_eq!(topic, Topic::MagnetometerX);
        match self.reuse {
            Some(nanotesla) => Step::Done(x_frame(nanotesla)),
            None if self.check_identity => run(job, Stage::Identity),
            None => run(job, Stage::Data),
        }
    }

    fn resume(
        &mut self,
        job: &mut Stage,
        _topic: Topic,
        _now_us: u64,
        outcome: Result<Readings, BusFault>,
    ) -> Step {
        self.outcomes.push(outcome);
        match (*job, outcome) {
            _ if self.endless => run(job, Stage::Data),
            (Stage::Identity, Ok(readings)) if readings.of(0) == hmc5883l::IDENTITY => {
                run(job, Stage::Data)
            }
            (Stage::Data, Ok(readings)) => {
                let bytes = readings.of(0);
                Step::Done(x_frame(i32::from(i16::from_be_bytes([bytes[0], bytes[1]]))))
            }
            _ => Step::Done(Samples::new()),
        }
    }
}

/// The publisher's sample of `topic` through `port`, the group behind its lock.
async fn sample_of<G: ScriptedGroup>(
    group: &Lock<G>,
    port: &mut impl ScriptPort,
    topic: Topic,
    taken_us: u64,
) -> Samples {
    let mut lock = group;
    sample_on_bus(&mut lock, port, topic, taken_us).await
}

fn pump<const N: usize>(bus: &I2cBus<Model, N>) {
    for _ in 0..10_000 {
        let (ev, er) = bus.with_block(|m| m.pending());
        if er {
            bus.on_error();
        } else if ev {
            bus.on_event();
        } else if !bus.with_block(|m| m.advance()) {
            return;
        }
    }
    panic!("the bus did not settle");
}

fn x_of(frames: &Samples) -> Option<i32> {
    match frames.as_slice() {
        [SensorData::Magnetometer {
            axis: Axis::X,
            nanotesla,
        }] => Some(*nanotesla),
        _ => None,
    }
}

#[test]
fn a_sample_suspends_while_the_bus_runs_its_script_and_holds_no_group_lock() {
    set_now(1_000);
    let bus = I2cBus::new(Model::new(vec![Device::new(hmc5883l::ADDRESS)]), [3, 1]);
    let group = Lock::new(Magnetometer::default());
    let mut port = I2cPort::<TestClock, _, 2>::new(&bus, bus.client(0).unwrap(), 100);
    let (wakes, waker) = test_waker::counting();
    let mut cx = Context::from_waker(&waker);
    let mut sample = pin!(sample_of(&group, &mut port, Topic::MagnetometerX, 1_000));
    // Begun: the script is on the bus, the publisher suspended, the group's lock released.
    assert!(sample.as_mut().poll(&mut cx).is_pending());
    assert_eq!(group.taken.get(), 1);
    assert!(group.other_task().outcomes.is_empty());
    // The engine asked the block for the START (the bus model has not moved yet).
    assert!(bus.with_block(|m| m.access.contains(&Access::Cr1 {
        set: CR1_START,
        clear: 0
    })));
    // The block's interrupts carry the script through and wake the publisher once.
    pump(&bus);
    assert_eq!(wakes.count(), 1);
    let Poll::Ready(frames) = sample.as_mut().poll(&mut cx) else {
        panic!("not resumed");
    };
    // The sample begun, and resumed with its script's outcome.
    assert_eq!(group.taken.get(), 2);
    // Device::new's registers hold `register ^ address`: DATA_X_MSB and the next.
    let msb = hmc5883l::reg::DATA_X_MSB ^ hmc5883l::ADDRESS;
    let lsb = (hmc5883l::reg::DATA_X_MSB + 1) ^ hmc5883l::ADDRESS;
    assert_eq!(
        x_of(&frames),
        Some(i32::from(i16::from_be_bytes([msb, lsb])))
    );
    assert!(bus.with_block(|m| m.violations.is_empty()));
}

/// The HMC5883L of the model, its identification registers answering "H43".
fn identified_magnetometer() -> Device {
    let mut device = Device::new(hmc5883l::ADDRESS);
    let at = usize::from(hmc5883l::reg::IDENTIFICATION_A);
    device.registers[at..at + 3].copy_from_slice(&hmc5883l::IDENTITY);
    device
}

#[test]
fn two_levels_sample_one_group_at_once_each_with_its_own_job_in_the_bus_order() {
    set_now(0);
    let bus = I2cBus::new(Model::new(vec![identified_magnetometer()]), [3, 1]);
    let group = Lock::new(Magnetometer {
        check_identity: true,
        ..Magnetometer::default()
    });
    let mut urgent = I2cPort::<TestClock, _, 2>::new(&bus, bus.client(0).unwrap(), 100);
    let mut low = I2cPort::<TestClock, _, 2>::new(&bus, bus.client(1).unwrap(), 100);
    let (urgent_wakes, urgent_waker) = test_waker::counting();
    let (low_wakes, low_waker) = test_waker::counting();
    let mut cx_urgent = Context::from_waker(&urgent_waker);
    let mut cx_low = Context::from_waker(&low_waker);
    let mut first = pin!(sample_of(&group, &mut urgent, Topic::MagnetometerX, 0));
    let mut second = pin!(sample_of(&group, &mut low, Topic::MagnetometerX, 0));
    // Both levels begin their samples: the urgent one's identity script runs, the low one's
    // waits in the bus's queue; neither holds the group.
    assert!(first.as_mut().poll(&mut cx_urgent).is_pending());
    assert!(second.as_mut().poll(&mut cx_low).is_pending());
    assert_eq!(group.taken.get(), 2);
    // The urgent identity script ends (its publisher woken), then the low one runs: the bus is
    // not pre-empted by the urgent level's next script, which is not submitted yet.
    pump(&bus);
    assert_eq!((urgent_wakes.count(), low_wakes.count()), (1, 1));
    // Each level's identity matched: both data scripts are submitted; the urgent one runs first.
    assert!(second.as_mut().poll(&mut cx_low).is_pending());
    assert!(first.as_mut().poll(&mut cx_urgent).is_pending());
    pump(&bus);
    let Poll::Ready(urgent_frames) = first.as_mut().poll(&mut cx_urgent) else {
        panic!("the urgent sample did not end after its two scripts");
    };
    let Poll::Ready(low_frames) = second.as_mut().poll(&mut cx_low) else {
        panic!("the low sample did not end after its two scripts");
    };
    assert!(x_of(&urgent_frames).is_some());
    assert_eq!(x_of(&urgent_frames), x_of(&low_frames));
    // On the wire: identity (urgent), identity (low), data (urgent), data (low).
    let lengths: Vec<usize> = group
        .other_task()
        .outcomes
        .iter()
        .map(|o| o.as_ref().map_or(0, |r| r.all().len()))
        .collect();
    assert_eq!(lengths, [3, 3, 6, 6]);
    assert!(bus.with_block(|m| m.violations.is_empty()));
}

#[test]
fn a_wrong_identity_ends_the_job_after_its_first_round() {
    let bus = I2cBus::new(Model::new(vec![Device::new(hmc5883l::ADDRESS)]), [1]);
    let group = Lock::new(Magnetometer {
        check_identity: true,
        ..Magnetometer::default()
    });
    let mut port = I2cPort::<TestClock, _, 1>::new(&bus, bus.client(0).unwrap(), 100);
    let (_, waker) = test_waker::counting();
    let mut cx = Context::from_waker(&waker);
    let mut sample = pin!(sample_of(&group, &mut port, Topic::MagnetometerX, 0));
    assert!(sample.as_mut().poll(&mut cx).is_pending());
    pump(&bus);
    assert_eq!(sample.as_mut().poll(&mut cx), Poll::Ready(Samples::new()));
    assert_eq!(group.other_task().outcomes.len(), 1);
}

#[test]
fn a_sample_whose_scripts_run_out_publishes_nothing() {
    set_now(0);
    let bus = SimBus::new(SimCompassBus::new());
    let group = Lock::new(Magnetometer {
        endless: true,
        ..Magnetometer::default()
    });
    let mut port = SimPort::<TestClock, _>::new(&bus, 100);
    let (_, waker) = test_waker::counting();
    let mut cx = Context::from_waker(&waker);
    let mut sample = pin!(sample_of(&group, &mut port, Topic::MagnetometerX, 0));
    let mut polls = 0;
    let frames = loop {
        if let Poll::Ready(frames) = sample.as_mut().poll(&mut cx) {
            break frames;
        }
        polls += 1;
        assert!(polls <= 10, "the sample did not end");
        set_now(NOW_US.with(Cell::get) + 210);
    };
    assert!(frames.is_empty());
    // Magnetometer::MAX_ROUNDS scripts, then no more.
    assert_eq!(polls, Magnetometer::MAX_ROUNDS);
    assert_eq!(group.other_task().outcomes.len(), Magnetometer::MAX_ROUNDS);
}

#[test]
fn frames_ready_without_the_bus_do_not_suspend() {
    let bus = I2cBus::new(Model::new(vec![Device::new(hmc5883l::ADDRESS)]), [1]);
    let group = Lock::new(Magnetometer {
        reuse: Some(-7),
        ..Magnetometer::default()
    });
    let mut port = I2cPort::<TestClock, _, 1>::new(&bus, bus.client(0).unwrap(), 100);
    let (_, waker) = test_waker::counting();
    let mut sample = pin!(sample_of(&group, &mut port, Topic::MagnetometerX, 0));
    let Poll::Ready(frames) = sample.as_mut().poll(&mut Context::from_waker(&waker)) else {
        panic!("a reused reading suspended");
    };
    assert_eq!(x_of(&frames), Some(-7));
    assert_eq!(group.taken.get(), 1);
    assert!(bus.with_block(|m| m.wire.is_empty()));
}

#[test]
fn a_stuck_script_is_ended_by_the_client_timeout_and_the_group_sees_it() {
    set_now(5_000);
    let mut model = Model::new(vec![Device::new(hmc5883l::ADDRESS)]);
    // The device holds SCL low after the third byte on the wire, for ever.
    model.hold_at = Some(3);
    let bus = I2cBus::new(model, [2, 1]);
    let group = Lock::new(Magnetometer::default());
    let allowance_us = 300;
    let mut port = I2cPort::<TestClock, _, 2>::new(&bus, bus.client(0).unwrap(), allowance_us);
    let (_, waker) = test_waker::counting();
    let mut cx = Context::from_waker(&waker);
    let mut sample = pin!(sample_of(&group, &mut port, Topic::MagnetometerX, 5_000));
    assert!(sample.as_mut().poll(&mut cx).is_pending());
    pump(&bus);
    let mut script = Script::new();
    script
        .write_read(hmc5883l::ADDRESS, &[hmc5883l::reg::DATA_X_MSB], 6)
        .unwrap();
    // 84 SCL periods at 400 kHz (210 µs) and the allowance.
    let timeout = script_timeout_us(&script, allowance_us);
    assert_eq!(timeout, 210 + 300);
    set_now(5_000 + timeout - 1);
    assert!(sample.as_mut().poll(&mut cx).is_pending());
    set_now(5_000 + timeout);
    let Poll::Ready(frames) = sample.as_mut().poll(&mut cx) else {
        panic!("the timeout did not end the script");
    };
    assert!(frames.is_empty());
    assert_eq!(group.other_task().outcomes, [Err(BusFault::Timeout)]);
    // The transfer dropped: the script aborted, the block reset.
    assert_eq!(
        bus.with_block(|m| m.access.last().cloned()),
        Some(Access::Reset)
    );
    // The bus serves the next client once the device lets go.
    bus.with_block(|m| m.release());
    let mut next = I2cPort::<TestClock, _, 2>::new(&bus, bus.client(1).unwrap(), allowance_us);
    let mut again = pin!(sample_of(&group, &mut next, Topic::MagnetometerX, 6_000));
    assert!(again.as_mut().poll(&mut cx).is_pending());
    pump(&bus);
    let Poll::Ready(frames) = again.as_mut().poll(&mut cx) else {
        panic!("the next client was not served");
    };
    assert!(x_of(&frames).is_some());
}

#[test]
fn a_refused_address_reaches_the_group_as_the_failed_operation() {
    let mut device = Device::new(hmc5883l::ADDRESS);
    device.nack_address = true;
    let bus = I2cBus::new(Model::new(vec![device]), [1]);
    let group = Lock::new(Magnetometer::default());
    let mut port = I2cPort::<TestClock, _, 1>::new(&bus, bus.client(0).unwrap(), 100);
    let (_, waker) = test_waker::counting();
    let mut cx = Context::from_waker(&waker);
    let mut sample = pin!(sample_of(&group, &mut port, Topic::MagnetometerX, 0));
    assert!(sample.as_mut().poll(&mut cx).is_pending());
    pump(&bus);
    let Poll::Ready(frames) = sample.as_mut().poll(&mut cx) else {
        panic!("not resumed");
    };
    assert!(frames.is_empty());
    assert_eq!(
        group.other_task().outcomes,
        [Err(BusFault::Script(ScriptError {
            operation: 0,
            failure: Failure::NackAddress
        }))]
    );
}

// The QEMU build's simulated bus.

#[test]
fn the_simulated_bus_answers_a_script_after_its_wire_time() {
    set_now(10_000);
    let bus = SimBus::new(SimCompassBus::new());
    let group = Lock::new(Magnetometer::default());
    let mut port = SimPort::<TestClock, _>::new(&bus, 100);
    let (_, waker) = test_waker::counting();
    let mut cx = Context::from_waker(&waker);
    let mut sample = pin!(sample_of(&group, &mut port, Topic::MagnetometerX, 10_000));
    assert!(sample.as_mut().poll(&mut cx).is_pending());
    // 84 SCL periods at 400 kHz: 210 µs.
    set_now(10_209);
    assert!(sample.as_mut().poll(&mut cx).is_pending());
    assert_eq!(bus.with_devices(|d| d.target.samples()), 0);
    set_now(10_210);
    let Poll::Ready(frames) = sample.as_mut().poll(&mut cx) else {
        panic!("not answered at the end of its wire time");
    };
    // The same six bytes the blocking driver's read of the same part gives.
    let mut blocking = SimCompassBus::new();
    let mut block = [0u8; 6];
    blocking
        .write_read(hmc5883l::ADDRESS, &[hmc5883l::reg::DATA_X_MSB], &mut block)
        .unwrap();
    assert_eq!(
        x_of(&frames),
        Some(i32::from(i16::from_be_bytes([block[0], block[1]])))
    );
    assert_eq!(bus.with_devices(|d| d.target.samples()), 1);
}

/// The floor round of one sensor: the mux select, then the proximity result (a one-byte write
/// and a two-byte read, the VCNL4020's register map).
fn floor_sensor_script(channel: u8) -> Script {
    let mut script = Script::new();
    script
        .write(pca9544a::AMIRO_ADDRESS, &[channel])
        .unwrap()
        .write_read(vcnl4020::ADDRESS, &[vcnl4020::reg::PROXIMITY_RESULT], 2)
        .unwrap();
    script
}

#[test]
fn simulated_scripts_go_one_after_the_other_and_a_late_one_times_out() {
    set_now(0);
    let bus = SimBus::new(SimFloorBus::new());
    let script = floor_sensor_script(4);
    // The select: START, address, control byte, STOP (20 SCL periods); the register read:
    // START, address, register, repeated START, address, two bytes, STOP (48): 68, 170 µs.
    assert_eq!(script.scl_periods(), 68);
    let mut first = SimPort::<TestClock, _>::new(&bus, 200);
    let mut second = SimPort::<TestClock, _>::new(&bus, 200);
    let mut third = SimPort::<TestClock, _>::new(&bus, 100);
    let (_, waker) = test_waker::counting();
    let mut cx = Context::from_waker(&waker);
    let mut a = pin!(first.run(script, 0));
    let mut b = pin!(second.run(floor_sensor_script(5), 0));
    let mut c = pin!(third.run(floor_sensor_script(6), 0));
    assert!(a.as_mut().poll(&mut cx).is_pending());
    assert!(b.as_mut().poll(&mut cx).is_pending());
    // The third would end at 510 µs, after its own 170 µs and its 100 µs allowance.
    assert!(c.as_mut().poll(&mut cx).is_pending());
    set_now(170);
    let Poll::Ready(Ok(readings)) = a.as_mut().poll(&mut cx) else {
        panic!("the first script did not end at 170 µs");
    };
    assert!(b.as_mut().poll(&mut cx).is_pending());
    set_now(269);
    assert!(c.as_mut().poll(&mut cx).is_pending());
    set_now(270);
    assert_eq!(
        c.as_mut().poll(&mut cx),
        Poll::Ready(Err(BusFault::Timeout))
    );
    set_now(339);
    assert!(b.as_mut().poll(&mut cx).is_pending());
    set_now(340);
    let Poll::Ready(Ok(second_readings)) = b.as_mut().poll(&mut cx) else {
        panic!("the second script did not end after the first");
    };
    // What the blocking path reads from the same sensors.
    let mut blocking = SimFloorBus::new();
    for (channel, readings) in [(4u8, readings), (5, second_readings)] {
        let mut value = [0u8; 2];
        blocking.write(pca9544a::AMIRO_ADDRESS, &[channel]).unwrap();
        blocking
            .write_read(
                vcnl4020::ADDRESS,
                &[vcnl4020::reg::PROXIMITY_RESULT],
                &mut value,
            )
            .unwrap();
        assert_eq!(readings.of(1), value, "channel {channel}");
        assert!(readings.of(0).is_empty());
    }
}

#[test]
fn an_absent_simulated_device_is_a_nack_of_its_operation() {
    set_now(0);
    let mut devices = SimFloorBus::new();
    devices.set_nack(true);
    let bus = SimBus::new(devices);
    let mut port = SimPort::<TestClock, _>::new(&bus, 200);
    let (_, waker) = test_waker::counting();
    let mut cx = Context::from_waker(&waker);
    {
        let mut run = pin!(port.run(floor_sensor_script(4), 0));
        assert!(run.as_mut().poll(&mut cx).is_pending());
        set_now(170);
        assert_eq!(
            run.as_mut().poll(&mut cx),
            Poll::Ready(Err(BusFault::Script(ScriptError {
                operation: 0,
                failure: Failure::NackAddress
            })))
        );
    }
    // The devices come back: the next script reads; the failure was the first operation's.
    bus.with_devices(|d| d.set_nack(false));
    let mut again = pin!(port.run(floor_sensor_script(4), 0));
    assert!(again.as_mut().poll(&mut cx).is_pending());
    set_now(340);
    assert!(matches!(again.as_mut().poll(&mut cx), Poll::Ready(Ok(_))));
}

// A supervised group of amiro-sensors, its scripts built and decoded by the group, through the
// firmware's path.

/// Samples `topics` in turn every `step_us` from `from_us` to `to_us` (or when the last sample
/// ended, if later) through the simulated bus — the publisher polled, the monotonic moved on while
/// it waits, its settling waits included — and on the blocking path beside it; asserts that both
/// publish the same frames and keep the same fault count and readiness. The frames published, the
/// samples that had none, and the longest a sample took on the monotonic.
fn run_both<GB, GR, D>(
    blocking: &mut Supervised<GB>,
    group: &Lock<Supervised<GR>>,
    bus: &SimBus<D>,
    topics: &[Topic],
    (from_us, to_us, step_us): (u64, u64, u64),
) -> (usize, usize, u64)
where
    GB: SensorGroup,
    GR: ScriptedSensors,
    D: ScriptBus,
{
    let (_, waker) = test_waker::counting();
    let mut cx = Context::from_waker(&waker);
    let (mut published, mut empty, mut longest) = (0, 0, 0);
    let mut at = from_us;
    let mut k = 0;
    while at < to_us {
        let topic = topics[k % topics.len()];
        at = at.max(NOW_US.with(Cell::get));
        set_now(at);
        let mut port = SimPort::<TestClock, _>::new(bus, 500);
        let mut sample = pin!(sample_of(group, &mut port, topic, at));
        let mut waited = 0;
        let frames = loop {
            if let Poll::Ready(frames) = sample.as_mut().poll(&mut cx) {
                break frames;
            }
            waited += 1;
            assert!(waited < 1_000, "the sample at {at} µs did not end");
            set_now(NOW_US.with(Cell::get) + 50);
        };
        longest = longest.max(NOW_US.with(Cell::get) - at);
        let expected = blocking.sample(topic, at);
        assert_eq!(frames, expected, "{topic} at {at} µs");
        let scripted = group.other_task();
        assert_eq!(scripted.faults(), blocking.faults(), "faults at {at} µs");
        assert_eq!(
            scripted.is_ready(),
            blocking.is_ready(),
            "readiness at {at} µs"
        );
        if frames.is_empty() {
            empty += 1;
        } else {
            published += frames.len();
        }
        k += 1;
        at += step_us;
    }
    (published, empty, longest)
}

const MAGNETOMETER: [Topic; 3] = [
    Topic::MagnetometerX,
    Topic::MagnetometerY,
    Topic::MagnetometerZ,
];

#[test]
fn the_scripted_compass_through_the_simulated_bus_publishes_as_the_blocking_path() {
    set_now(0);
    let mut blocking = Supervised::new(Compass::new(SimCompassBus::new()));
    let bus = SimBus::new(SimCompassBus::new());
    let booted =
        bus.with_devices(|devices| Supervised::boot(Compass::scripted(), devices, &mut NoDelay));
    let group = Lock::new(booted);
    assert!(group.other_task().is_ready());
    let (published, empty, _) = run_both(
        &mut blocking,
        &group,
        &bus,
        &MAGNETOMETER,
        (1_000, 3_001_000, 10_000),
    );
    assert_eq!((published, empty), (300, 0));
    // The part stops answering for 6 s: failures, then the set-up retried after 1, 2 s.
    blocking.group_mut().magnetometer.bus_mut().set_nack(true);
    bus.with_devices(|d| d.set_nack(true));
    let (_, empty, _) = run_both(
        &mut blocking,
        &group,
        &bus,
        &MAGNETOMETER,
        (3_001_000, 9_001_000, 10_000),
    );
    assert_eq!(empty, 600);
    assert!(group.other_task().faults() >= 3);
    blocking.group_mut().magnetometer.bus_mut().set_nack(false);
    bus.with_devices(|d| d.set_nack(false));
    let (published, _, _) = run_both(
        &mut blocking,
        &group,
        &bus,
        &MAGNETOMETER,
        (9_001_000, 19_001_000, 10_000),
    );
    assert!(published > 0 && group.other_task().is_ready());
    // The devices saw the same traffic.
    let device = blocking.group_mut().magnetometer.bus_mut().magnetometer();
    let (samples, registers) =
        bus.with_devices(|d| (d.magnetometer().samples(), d.magnetometer().registers()));
    assert_eq!((device.samples(), device.registers()), (samples, registers));
}

#[test]
fn a_timed_out_script_is_a_fault_of_the_supervised_group() {
    set_now(0);
    let booted = Supervised::boot(Compass::scripted(), &mut SimCompassBus::new(), &mut NoDelay);
    let group = Lock::new(booted);
    // The chip's bus, its HMC5883L holding SCL low after the third byte of the sample's script.
    let mut model = Model::new(vec![identified_magnetometer()]);
    model.hold_at = Some(3);
    let bus = I2cBus::new(model, [1]);
    let mut port = I2cPort::<TestClock, _, 1>::new(&bus, bus.client(0).unwrap(), 300);
    let (_, waker) = test_waker::counting();
    let mut cx = Context::from_waker(&waker);
    let mut sample = pin!(sample_of(&group, &mut port, Topic::MagnetometerX, 0));
    assert!(sample.as_mut().poll(&mut cx).is_pending());
    pump(&bus);
    assert!(sample.as_mut().poll(&mut cx).is_pending());
    assert_eq!(group.other_task().faults(), 0);
    // 84 SCL periods (210 µs) and the 300 µs allowance: the timeout ends the script.
    set_now(510);
    let Poll::Ready(frames) = sample.as_mut().poll(&mut cx) else {
        panic!("the timeout did not end the sample");
    };
    assert!(frames.is_empty());
    // Counted as one failed sample, as a polled master's timeout was (the group stays up until
    // its third failure in a row, `Supervised`'s rule on either path).
    assert_eq!(group.other_task().faults(), 1);
    assert_eq!(
        bus.with_block(|m| m.access.last().cloned()),
        Some(Access::Reset)
    );
}

#[test]
fn the_scripted_floor_through_the_simulated_bus_publishes_as_the_blocking_path() {
    set_now(0);
    let mut blocking = Supervised::new(FloorSensors::new(SimFloorBus::new()));
    let bus = SimBus::new(SimFloorBus::new());
    let booted = bus
        .with_devices(|devices| Supervised::boot(FloorSensors::scripted(), devices, &mut NoDelay));
    let group = Lock::new(booted);
    let floor = [Topic::FloorProximity];
    let (published, empty, _) = run_both(
        &mut blocking,
        &group,
        &bus,
        &floor,
        (1_000, 3_001_000, 10_000),
    );
    // One frame a round (the four sensors' values), 300 rounds.
    assert_eq!((published, empty), (300, 0));
    blocking.group_mut().mux_mut().bus_mut().set_nack(true);
    bus.with_devices(|d| d.set_nack(true));
    let (_, empty, _) = run_both(
        &mut blocking,
        &group,
        &bus,
        &floor,
        (3_001_000, 9_001_000, 10_000),
    );
    assert_eq!(empty, 600);
    blocking.group_mut().mux_mut().bus_mut().set_nack(false);
    bus.with_devices(|d| d.set_nack(false));
    let (published, _, _) = run_both(
        &mut blocking,
        &group,
        &bus,
        &floor,
        (9_001_000, 19_001_000, 10_000),
    );
    assert!(published > 0 && group.other_task().is_ready());
}

#[test]
fn the_scripted_bno055_through_the_simulated_bus_publishes_as_the_blocking_path() {
    set_now(0);
    let mut blocking = Supervised::new(ImuSensors::new(SimImuBus::new(), NoDelay));
    let bus = SimBus::new(SimImuBus::new());
    let booted = bus.with_devices(|devices| {
        Supervised::boot(ImuSensors::scripted(NoDelay), devices, &mut NoDelay)
    });
    let group = Lock::new(booted);
    let topics = [
        Topic::Gyroscope,
        Topic::Accelerometer,
        Topic::MagnetometerX,
        Topic::MagnetometerY,
        Topic::MagnetometerZ,
    ];
    let (published, _, _) = run_both(
        &mut blocking,
        &group,
        &bus,
        &topics,
        (1_000, 2_001_000, 10_000),
    );
    assert_eq!(published, 200);
    // Gone (no acknowledge), then back: the set-up again, step by step.
    blocking
        .group_mut()
        .imu
        .bus_mut()
        .imu_mut()
        .set_fault(Bno055Fault::Absent);
    bus.with_devices(|d| d.imu_mut().set_fault(Bno055Fault::Absent));
    let (_, empty, _) = run_both(
        &mut blocking,
        &group,
        &bus,
        &topics,
        (2_001_000, 8_001_000, 10_000),
    );
    assert!(empty > 0);
    blocking
        .group_mut()
        .imu
        .bus_mut()
        .imu_mut()
        .set_fault(Bno055Fault::None);
    bus.with_devices(|d| d.imu_mut().set_fault(Bno055Fault::None));
    let start = NOW_US.with(Cell::get);
    let (published, _, longest) = run_both(
        &mut blocking,
        &group,
        &bus,
        &topics,
        (start, start + 10_000_000, 1_000),
    );
    assert!(published > 0 && group.other_task().is_ready());
    // The set-up's mode switches are the supervisor's waits between samples (one step a
    // sample, `SensorGroup::init_step`), not a wait inside one: no sample took a switch's 19 ms.
    assert!(longest < u64::from(bno055::OPERATING_TO_CONFIG_MS) * 1_000);
    let device = blocking.group_mut().imu.bus_mut().imu();
    let (samples, switches) = bus.with_devices(|d| (d.imu().samples(), d.imu().mode_switches()));
    assert_eq!(
        (device.samples(), device.mode_switches()),
        (samples, switches)
    );
}

#[test]
fn a_simulated_script_waits_its_settling_time_first() {
    set_now(1_000);
    let bus = SimBus::new(SimFloorBus::new());
    let mut port = SimPort::<TestClock, _>::new(&bus, 100);
    let (_, waker) = test_waker::counting();
    let mut cx = Context::from_waker(&waker);
    // A part's 66 µs of bus-free time first (the bq27500's, `Job::settle_us`), then the
    // script's 170 µs on the wire: it ends at 1 236 µs, and its timeout counts from its start.
    let mut run = pin!(port.run(floor_sensor_script(4), 66));
    assert!(run.as_mut().poll(&mut cx).is_pending());
    set_now(1_066);
    assert!(run.as_mut().poll(&mut cx).is_pending());
    set_now(1_235);
    assert!(run.as_mut().poll(&mut cx).is_pending());
    set_now(1_236);
    assert!(matches!(run.as_mut().poll(&mut cx), Poll::Ready(Ok(_))));
}
