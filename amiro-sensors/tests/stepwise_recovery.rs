//! A missing group is set up again in steps, one device per sample (`SensorGroup::init_step`,
//! `Supervised`): a release that recovers a group costs one device's set-up and no sample (the
//! group's next release samples it), never the whole group's set-up, while the back-off and the
//! reporting stay as they were.

use amiro_can::Topic;
use amiro_sensors::drivers::floor::FloorSensors;
use amiro_sensors::drivers::pca9544a;
use amiro_sensors::drivers::suite::{
    Device, InitStep, PowerManagementSensors, SampleError, SensorGroup, Supervised, RETRY_FIRST_US,
};
use amiro_sensors::drivers::vcnl4020;
use amiro_sensors::drivers::Error;
use amiro_sensors::sim::*;
use embedded_hal::i2c::{ErrorType, I2c, Operation};

/// One VCNL4020's set-up in bus transfers: the mux's channel, PRODUCT_ID, then five registers
/// each written and read back.
const ONE_SENSOR_SET_UP: u32 = 1 + 1 + 5 * 2;

/// The DiWheelDrive's floor bus with one sensor that can stop answering: while `dead` names its
/// mux channel, every transfer to a VCNL4020 behind that channel is not acknowledged. Counts the
/// transfers (one per embedded-hal call).
struct FlakyFloorBus {
    bus: SimFloorBus,
    dead: Option<u8>,
    control: u8,
    transfers: u32,
}

impl FlakyFloorBus {
    fn new() -> Self {
        Self {
            bus: SimFloorBus::new(),
            dead: None,
            control: 0,
            transfers: 0,
        }
    }
}

impl ErrorType for FlakyFloorBus {
    type Error = NoAcknowledge;
}

impl I2c for FlakyFloorBus {
    fn transaction(
        &mut self,
        address: u8,
        operations: &mut [Operation<'_>],
    ) -> Result<(), Self::Error> {
        self.transfers += 1;
        if address == pca9544a::AMIRO_ADDRESS {
            if let Some(Operation::Write([byte, ..])) = operations.first() {
                self.control = *byte;
            }
        }
        let selected = (self.control & pca9544a::ENABLE != 0).then_some(self.control & 0x03);
        if address == vcnl4020::ADDRESS && self.dead.is_some() && self.dead == selected {
            return Err(NoAcknowledge { address });
        }
        self.bus.transaction(address, operations)
    }
}

type Floor = Supervised<FloorSensors<FlakyFloorBus>>;

fn bus(group: &mut Floor) -> &mut FlakyFloorBus {
    group.group_mut().mux_mut().bus_mut()
}

/// One sample of the floor and the bus transfers it made.
fn sample(group: &mut Floor, now_us: u64) -> (usize, u32) {
    let before = bus(group).transfers;
    let frames = group.sample(Topic::FloorProximity, now_us).len();
    (frames, bus(group).transfers - before)
}

#[test]
fn a_floor_sensor_that_nacks_then_comes_back_is_set_up_one_sensor_per_sample() {
    let mut group = Supervised::new(FloorSensors::new(FlakyFloorBus::new()));
    assert!(group.is_ready());
    let (frames, normal) = sample(&mut group, 0);
    assert_eq!(frames, 1);
    // The left-wheel sensor (channel 2) stops answering: three failed samples, then missing.
    bus(&mut group).dead = Some(2);
    for n in 1..=3 {
        assert_eq!(sample(&mut group, n * 10_000).0, 0);
    }
    assert!(!group.is_ready());
    assert_eq!(group.faults(), 3);
    let retry = group.retry_at_us();
    assert_eq!(retry, 30_000 + RETRY_FIRST_US);
    // Before its retry a missing group touches no bus.
    assert_eq!(sample(&mut group, retry - 1), (0, 0));
    // The retry: sensors 0 and 1 set up, one per sample, each costing one sensor's set-up; sensor
    // 2 fails its step (a NACK on PRODUCT_ID: two transfers), which is the attempt's fault.
    assert_eq!(sample(&mut group, retry), (0, ONE_SENSOR_SET_UP));
    assert_eq!(
        group.retry_at_us(),
        retry,
        "the next step at the next sample"
    );
    assert_eq!(group.faults(), 3, "a step that worked is no fault");
    assert_eq!(sample(&mut group, retry + 10_000), (0, ONE_SENSOR_SET_UP));
    assert_eq!(sample(&mut group, retry + 20_000), (0, 2));
    assert_eq!(group.faults(), 4);
    assert!(matches!(
        group.last_error(),
        Some(SampleError::Device {
            device: Device::FloorSensor(2),
            error: Error::Bus(_)
        })
    ));
    assert!(!group.is_ready());
    // The wait doubled, as before.
    let failed_at = retry + 20_000;
    let retry = group.retry_at_us();
    assert_eq!(retry, failed_at + 2 * RETRY_FIRST_US);
    // It answers again. The next attempt starts at the first sensor: four releases, a sensor
    // each and no sample, the group missing (and reported so) until the last; the release after
    // it reads the floor.
    bus(&mut group).dead = None;
    for k in 0..3 {
        assert_eq!(
            sample(&mut group, retry + k * 10_000),
            (0, ONE_SENSOR_SET_UP),
            "step {k}"
        );
        assert!(!group.is_ready());
    }
    assert_eq!(
        sample(&mut group, retry + 30_000),
        (0, ONE_SENSOR_SET_UP),
        "the last step, alone in its release"
    );
    assert!(group.is_ready());
    let (frames, transfers) = sample(&mut group, retry + 35_000);
    assert_eq!(frames, 1);
    assert!(
        transfers <= 2 * normal,
        "{transfers}: a sample (with its identity check), no set-up"
    );
    let sensors = group
        .group_mut()
        .mux_mut()
        .bus_mut()
        .bus
        .proximity()
        .clone();
    for channel in 0..4 {
        assert!(
            sensors
                .sensor(channel)
                .is_some_and(|s| s.is_configured_for_amiro()),
            "sensor {channel}"
        );
    }
    // A good sample resets the back-off: the next loss waits 1 s again.
    bus(&mut group).dead = Some(0);
    let at = retry + 40_000;
    for n in 0..3 {
        assert_eq!(sample(&mut group, at + n * 10_000).0, 0);
    }
    assert_eq!(group.retry_at_us(), at + 20_000 + RETRY_FIRST_US);
}

#[test]
fn every_floor_step_sets_up_one_sensor_and_the_fourth_completes() {
    let mut floor = FloorSensors::new(SimFloorBus::new());
    for step in 0..4 {
        let before = floor.mux_mut().bus_mut().proximity().selections();
        let result = SensorGroup::init_step(&mut floor, 5);
        let after = floor.mux_mut().bus_mut().proximity().selections();
        assert_eq!(after - before, 1, "step {step}: one channel selected");
        assert_eq!(
            result,
            if step == 3 {
                InitStep::Done
            } else {
                InitStep::Pending { next_us: 5 }
            }
        );
        let sensors = floor.mux_mut().bus_mut().proximity().clone();
        for channel in 0..4 {
            assert_eq!(
                sensors
                    .sensor(channel)
                    .is_some_and(|s| s.is_configured_for_amiro()),
                channel <= step,
                "after step {step}, sensor {channel}"
            );
        }
    }
    // Done: the next set-up starts again at the first sensor.
    assert_eq!(
        SensorGroup::init_step(&mut floor, 6),
        InitStep::Pending { next_us: 6 }
    );
}

#[test]
fn power_management_is_set_up_one_device_per_step_ring_then_gauges() {
    let mut group = PowerManagementSensors::new(
        SimPowerBus::new(0, false),
        SimPowerBus::new(4, true),
        NoDelay,
    );
    // Ten devices: eight ring sensors (I2C1 and I2C2 by their wiring), then two gauges.
    let selections = |g: &mut PowerManagementSensors<SimPowerBus, SimPowerBus, NoDelay>| {
        g.ring.i2c1_mut().target.0.selections() + g.ring.i2c2_mut().target.0.selections()
    };
    for step in 0..10u32 {
        let before = selections(&mut group);
        let result = group.init_step(100);
        let selected = selections(&mut group) - before;
        assert_eq!(selected, u32::from(step < 8), "step {step}");
        assert_eq!(
            result,
            if step == 9 {
                InitStep::Done
            } else {
                InitStep::Pending { next_us: 100 }
            },
            "step {step}"
        );
    }
    assert!(group.sample(Topic::ProximityRing, 200).is_ok());
    // I2C2 stops answering: the step of its first device (ring sensor 3) fails; the next set-up
    // starts again at sensor 0.
    group.ring.i2c2_mut().set_nack(true);
    let mut failed = None;
    for step in 0..10 {
        if let InitStep::Failed(error) = group.init_step(300) {
            failed = Some((step, error));
            break;
        }
    }
    assert!(matches!(
        failed,
        Some((
            _,
            SampleError::Device {
                device: Device::RingSensor(3),
                ..
            }
        ))
    ));
    group.ring.i2c2_mut().set_nack(false);
    let before = selections(&mut group);
    assert_eq!(group.init_step(400), InitStep::Pending { next_us: 400 });
    assert_eq!(selections(&mut group) - before, 1);
}
