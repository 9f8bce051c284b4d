//! A scripted sample end to end on the host: the group's lock taken only to begin and to finish,
//! the publisher suspended while the interrupt-driven bus (over the register-level model) or the
//! QEMU build's simulated bus runs the script, the client's timeout ending a stuck script, and the
//! failures reaching the group.
use core::cell::{Cell, RefCell};
use core::future::{poll_fn, Future};
use core::pin::pin;
use core::task::{Context, Poll};

use amiro_can::{Axis, SensorData, Topic};
use amiro_sensors::drivers::suite::Samples;
use amiro_sensors::drivers::{hmc5883l, pca9544a, vcnl4020};
use amiro_sensors::script::{Failure, Readings, Script, ScriptError};
use amiro_sensors::sim::{SimCompassBus, SimFloorBus};
use embedded_hal::i2c::I2c;

use crate::i2c_bus::I2cBus;
use crate::i2c_engine::CR1_START;
use crate::i2c_model::{Access, Device, Model};
use crate::i2c_sim::{HalDevices, SimBus, SimPort};
use crate::scripted::{
    sample_on_bus, script_timeout_us, Begin, BusFault, Deadline, I2cPort, ScriptPort, ScriptedGroup,
};
use crate::test_waker;

thread_local! {
    static NOW_US: Cell<u64> = const { Cell::new(0) };
}

fn set_now(us: u64) {
    NOW_US.with(|now| now.set(us));
}

/// The monotonic as the tests move it.
struct TestClock;

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

/// A magnetometer group that samples by script: the HMC5883L's data register block (six bytes
/// from DATA_X_MSB, X Z Y big-endian; its datasheet's register list) decoded to one axis.
#[derive(Default)]
struct Magnetometer {
    /// Serve the frames without the bus (a reading reused).
    reuse: Option<i32>,
    outcomes: Vec<Result<Readings, BusFault>>,
}

impl ScriptedGroup for Magnetometer {
    fn begin(&mut self, topic: Topic, _now_us: u64) -> Begin {
        if let Some(nanotesla) = self.reuse {
            let mut frames = Samples::new();
            let _ = frames.push(SensorData::Magnetometer {
                axis: Axis::X,
                nanotesla,
            });
            return Begin::Frames(frames);
        }
        assert_eq!(topic, Topic::MagnetometerX);
        let mut script = Script::new();
        script
            .write_read(hmc5883l::ADDRESS, &[hmc5883l::reg::DATA_X_MSB], 6)
            .unwrap();
        Begin::Script(script)
    }

    fn finish(
        &mut self,
        _topic: Topic,
        _now_us: u64,
        outcome: Result<Readings, BusFault>,
    ) -> Samples {
        self.outcomes.push(outcome);
        let mut frames = Samples::new();
        if let Ok(readings) = outcome {
            let bytes = readings.of(0);
            let x = i16::from_be_bytes([bytes[0], bytes[1]]);
            let _ = frames.push(SensorData::Magnetometer {
                axis: Axis::X,
                nanotesla: i32::from(x),
            });
        }
        frames
    }
}

/// The publisher's sample of `topic` through `port`, the group behind its lock.
async fn sample_of(
    group: &Lock<Magnetometer>,
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
    let bus = SimBus::new(HalDevices(SimCompassBus::new()));
    let group = Lock::new(Magnetometer::default());
    let mut port = SimPort::<TestClock, _>::new(&bus, 100);
    let (_, waker) = test_waker::counting();
    let mut cx = Context::from_waker(&waker);
    let mut sample = pin!(sample_of(&group, &mut port, Topic::MagnetometerX, 10_000));
    assert!(sample.as_mut().poll(&mut cx).is_pending());
    // 84 SCL periods at 400 kHz: 210 µs.
    set_now(10_209);
    assert!(sample.as_mut().poll(&mut cx).is_pending());
    assert_eq!(bus.with_devices(|d| d.0.target.samples()), 0);
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
    assert_eq!(bus.with_devices(|d| d.0.target.samples()), 1);
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
    let bus = SimBus::new(HalDevices(SimFloorBus::new()));
    let script = floor_sensor_script(4);
    // The select: START, address, control byte, STOP (20 SCL periods); the register read:
    // START, address, register, repeated START, address, two bytes, STOP (48): 68, 170 µs.
    assert_eq!(script.scl_periods(), 68);
    let mut first = SimPort::<TestClock, _>::new(&bus, 200);
    let mut second = SimPort::<TestClock, _>::new(&bus, 200);
    let mut third = SimPort::<TestClock, _>::new(&bus, 100);
    let (_, waker) = test_waker::counting();
    let mut cx = Context::from_waker(&waker);
    let mut a = pin!(first.run(script));
    let mut b = pin!(second.run(floor_sensor_script(5)));
    let mut c = pin!(third.run(floor_sensor_script(6)));
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
    let bus = SimBus::new(HalDevices(devices));
    let mut port = SimPort::<TestClock, _>::new(&bus, 200);
    let (_, waker) = test_waker::counting();
    let mut cx = Context::from_waker(&waker);
    {
        let mut run = pin!(port.run(floor_sensor_script(4)));
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
    bus.with_devices(|d| d.0.set_nack(false));
    let mut again = pin!(port.run(floor_sensor_script(4)));
    assert!(again.as_mut().poll(&mut cx).is_pending());
    set_now(340);
    assert!(matches!(again.as_mut().poll(&mut cx), Poll::Ready(Ok(_))));
}
