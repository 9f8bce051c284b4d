//! A failed transfer ends its release: once an I2C transfer of the compass (HMC5883L) or the floor (PCA9544A and
//! four VCNL4020) has failed, the release — a sample of a ready group, or one set-up step of a missing one —
//! makes no further transfer on that bus.
//!
//! The machine-code bound rests on it: DiWheelDrive's bounds file states the firmware's bus clear
//! (`i2c::Master::recover`, which the polled master runs after each failed transfer) at most once a release
//! (its groups' `calls`; docs/analysis.md, "The bus transaction's cap"). A driver that went on after an error
//! would make that statement false, and this test fails: each transfer of each kind of release is made to
//! fail in turn, and the transfers that release makes are counted.

use amiro_can::Topic;
use amiro_sensors::drivers::floor::FloorSensors;
use amiro_sensors::drivers::suite::{
    Compass, SensorGroup, Supervised, FAILURES_BEFORE_RETRY, RETRY_FIRST_US,
};
use amiro_sensors::drivers::IDENTITY_CHECK_EVERY;
use amiro_sensors::sim::*;
use embedded_hal::i2c::{ErrorType, I2c, Operation};

/// A bus whose `fail_at`-th transfer (counted from its creation, from 1) is not acknowledged, and which
/// fails every transfer while `dead`. Counts the transfers (one per embedded-hal call).
struct Failing<B> {
    bus: B,
    transfers: u32,
    fail_at: Option<u32>,
    dead: bool,
}

impl<B> Failing<B> {
    fn new(bus: B) -> Self {
        Self {
            bus,
            transfers: 0,
            fail_at: None,
            dead: false,
        }
    }
}

impl<B> ErrorType for Failing<B> {
    type Error = NoAcknowledge;
}

impl<B: I2c<Error = NoAcknowledge>> I2c for Failing<B> {
    fn transaction(
        &mut self,
        address: u8,
        operations: &mut [Operation<'_>],
    ) -> Result<(), Self::Error> {
        self.transfers += 1;
        if self.dead || self.fail_at == Some(self.transfers) {
            return Err(NoAcknowledge { address });
        }
        self.bus.transaction(address, operations)
    }
}

/// One group under test: how to make it, reach its bus, and which topic a release samples.
struct Case<G: OnBus> {
    name: &'static str,
    make: fn() -> Supervised<G>,
    bus: fn(&mut Supervised<G>) -> &mut Failing<G::Bus>,
    topic: Topic,
    period_us: u64,
}

/// The groups' bus type, named for [`Case`].
trait OnBus: SensorGroup {
    type Bus;
}

impl<B: I2c<Error = NoAcknowledge>> OnBus for Compass<Failing<B>> {
    type Bus = B;
}

impl<B: I2c<Error = NoAcknowledge>> OnBus for FloorSensors<Failing<B>> {
    type Bus = B;
}

/// The transfers of the release at `now_us`, on `group` as `prepare` leaves it, when the release's `k`-th
/// transfer fails (`None`: none fails).
fn release<G: OnBus>(
    case: &Case<G>,
    prepare: &dyn Fn(&mut Supervised<G>) -> u64,
    k: Option<u32>,
) -> u32 {
    let mut group = (case.make)();
    let now_us = prepare(&mut group);
    let before = (case.bus)(&mut group).transfers;
    (case.bus)(&mut group).fail_at = k.map(|k| before + k);
    group.sample(case.topic, now_us);
    (case.bus)(&mut group).transfers - before
}

/// Every transfer of the release `prepare` leads to, failed in turn: the release stops at it.
fn each_transfer_failed_ends_the_release<G: OnBus>(
    case: &Case<G>,
    what: &str,
    prepare: &dyn Fn(&mut Supervised<G>) -> u64,
) -> u32 {
    let clean = release(case, prepare, None);
    assert!(clean > 0, "{}: {what} makes no transfer", case.name);
    for k in 1..=clean {
        assert_eq!(
            release(case, prepare, Some(k)),
            k,
            "{}: {what}: transfers after the failed transfer {k} of {clean}",
            case.name
        );
    }
    clean
}

/// Samples `count` releases one period apart from `from_us`; returns the next release's time.
fn run<G: SensorGroup>(
    group: &mut Supervised<G>,
    topic: Topic,
    period_us: u64,
    from_us: u64,
    count: u64,
) -> u64 {
    for n in 0..count {
        group.sample(topic, from_us + n * period_us);
    }
    from_us + count * period_us
}

fn check<G: OnBus>(case: &Case<G>) {
    let (topic, period) = (case.topic, case.period_us);
    // A ready group's sample.
    let sample = each_transfer_failed_ends_the_release(case, "a sample", &|group| {
        assert!(group.is_ready());
        run(group, topic, period, 0, 1)
    });
    // The sample that checks the parts' identities as well.
    let checked =
        each_transfer_failed_ends_the_release(case, "the identity check's sample", &|group| {
            run(group, topic, period, 0, u64::from(IDENTITY_CHECK_EVERY) - 1)
        });
    assert!(
        checked > sample,
        "{}: the identity check reads more",
        case.name
    );
    // A missing group's set-up, step by step: each step's transfers, failed in turn.
    let missing = |group: &mut Supervised<G>| {
        let next = run(group, topic, period, 0, 1);
        (case.bus)(group).dead = true;
        let next = run(group, topic, period, next, u64::from(FAILURES_BEFORE_RETRY));
        (case.bus)(group).dead = false;
        assert!(!group.is_ready(), "{}: missing", case.name);
        next - period + RETRY_FIRST_US
    };
    let mut steps = 0;
    loop {
        let prepare = |group: &mut Supervised<G>| {
            let retry = missing(group);
            run(group, topic, period, retry, steps)
        };
        each_transfer_failed_ends_the_release(
            case,
            &format!("set-up step {}", steps + 1),
            &prepare,
        );
        // The step done, is the group back?
        let mut group = (case.make)();
        let next = prepare(&mut group);
        group.sample(topic, next);
        steps += 1;
        if group.is_ready() {
            break;
        }
        assert!(steps < 16, "{}: the set-up never ends", case.name);
    }
}

#[test]
fn a_failed_compass_transfer_ends_its_release() {
    check(&Case {
        name: "compass",
        make: || {
            let mut compass = Compass::new(Failing::new(SimCompassBus::new()));
            compass.set_reuse_window_us(0);
            Supervised::new(compass)
        },
        bus: |group| group.group_mut().magnetometer.bus_mut(),
        topic: Topic::MagnetometerX,
        period_us: 10_000,
    });
}

#[test]
fn a_failed_floor_transfer_ends_its_release() {
    check(&Case {
        name: "floor",
        make: || Supervised::new(FloorSensors::new(Failing::new(SimFloorBus::new()))),
        bus: |group| group.group_mut().mux_mut().bus_mut(),
        topic: Topic::FloorProximity,
        period_us: 20_000,
    });
}
