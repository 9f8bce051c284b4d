//! The sensor groups' scripted path (`drivers::scripted`): the scripts each group builds from its
//! drivers' register maps, run by the simulated buses (`SimBus::answer`) and decoded by the
//! drivers' decode functions, give the samples the blocking path gives on identical simulated
//! devices — fault counting, back-off and the stepwise set-up included — and each script carries
//! the datasheet's transaction, worked byte by byte in the tests.

use amiro_can::Topic;
use amiro_sensors::drivers::bq27500::{self, BatteryStatus, Bq27500, StatusRead};
use amiro_sensors::drivers::floor::FloorSensors;
use amiro_sensors::drivers::pca9544a::{Channel, Pca9544a};
use amiro_sensors::drivers::ring::{RingBus, WIRING};
use amiro_sensors::drivers::scripted::{
    gauge_outcome, gauge_script, sample_on, GaugeIdentity, Next, RingRead, ScriptBus, ScriptResult,
    ScriptedSensors, SensorSetUp, GAUGE_SETTLE_US,
};
use amiro_sensors::drivers::suite::{Compass, ImuSensors, SensorGroup, Supervised};
use amiro_sensors::drivers::vcnl4020::{self, Config, Vcnl4020};
use amiro_sensors::drivers::Error;
use amiro_sensors::drivers::{bno055, hmc5883l, pca9544a};
use amiro_sensors::script::{Script, Symbol};
use amiro_sensors::sim::*;
use embedded_hal::i2c::ErrorKind;

/// A simulated bus that keeps every script it ran.
struct Recorder<T> {
    bus: SimBus<T>,
    scripts: Vec<Script>,
    bus_time_ns: u64,
}

impl<T: I2cTarget> Recorder<T> {
    fn new(bus: SimBus<T>) -> Self {
        Self {
            bus,
            scripts: Vec::new(),
            bus_time_ns: 0,
        }
    }
}

impl<T: I2cTarget> ScriptBus for Recorder<T> {
    fn run(&mut self, script: &Script) -> ScriptResult {
        self.scripts.push(*script);
        let answer = self.bus.answer(script);
        self.bus_time_ns += answer.bus_time_ns();
        answer.result
    }
}

/// What a boot did, in order: the scripts a simulated bus ran and the waits between them.
#[derive(Debug, Clone, PartialEq)]
enum Event {
    Script(Script),
    Wait(u32),
}

/// A simulated bus and a delay that share one timeline of [`Event`]s.
#[derive(Clone)]
struct Timeline<T> {
    bus: std::rc::Rc<std::cell::RefCell<SimBus<T>>>,
    events: std::rc::Rc<std::cell::RefCell<Vec<Event>>>,
}

impl<T: I2cTarget> Timeline<T> {
    fn new(bus: SimBus<T>) -> Self {
        Self {
            bus: std::rc::Rc::new(std::cell::RefCell::new(bus)),
            events: Default::default(),
        }
    }

    fn events(&self) -> Vec<Event> {
        self.events.borrow().clone()
    }

    fn scripts(&self) -> Vec<Script> {
        self.events()
            .into_iter()
            .filter_map(|e| match e {
                Event::Script(s) => Some(s),
                Event::Wait(_) => None,
            })
            .collect()
    }
}

impl<T: I2cTarget> ScriptBus for Timeline<T> {
    fn run(&mut self, script: &Script) -> ScriptResult {
        self.events.borrow_mut().push(Event::Script(*script));
        self.bus.borrow_mut().answer(script).result
    }
}

impl<T> embedded_hal::delay::DelayNs for Timeline<T> {
    fn delay_ns(&mut self, ns: u32) {
        if ns > 0 {
            self.events.borrow_mut().push(Event::Wait(ns / 1_000));
        }
    }
}

/// One sample of `topic` at `now` on both paths: the frames, the fault count, readiness, the last
/// error and the retry time must be the same. Returns the frames' count.
fn same_sample<G, R, B>(
    blocking: &mut Supervised<G>,
    scripted: &mut Supervised<R>,
    bus: &mut B,
    topic: Topic,
    now: u64,
) -> usize
where
    G: SensorGroup,
    R: ScriptedSensors,
    B: ScriptBus,
{
    let expected = blocking.sample(topic, now);
    let got = sample_on(scripted, bus, topic, now);
    assert_eq!(got, expected, "{topic:?} at {now} µs");
    let s = scripted;
    assert_eq!(
        (s.is_ready(), s.faults(), s.last_error(), s.retry_at_us()),
        (
            blocking.is_ready(),
            blocking.faults(),
            blocking.last_error(),
            blocking.retry_at_us()
        ),
        "policy after {topic:?} at {now} µs"
    );
    expected.len()
}

/// A script of `ops`: `(address, written, read)`.
fn script(ops: &[(u8, &[u8], usize)]) -> Script {
    let mut script = Script::new();
    for &(address, written, read) in ops {
        match (written.is_empty(), read) {
            (true, n) => script.read(address, n).unwrap(),
            (false, 0) => script.write(address, written).unwrap(),
            (false, n) => script.write_read(address, written, n).unwrap(),
        };
    }
    script
}

/// Each script's SCL periods.
fn periods(scripts: &[Script]) -> Vec<u32> {
    scripts.iter().map(Script::scl_periods).collect()
}

/// Samples `topics` in turn every `period` µs from `start` to `end` on both paths; how many
/// samples published frames and how many did not.
#[allow(clippy::too_many_arguments)]
fn run_both<G, R, B>(
    blocking: &mut Supervised<G>,
    scripted: &mut Supervised<R>,
    bus: &mut B,
    topics: &[Topic],
    start: u64,
    end: u64,
    period: u64,
) -> (u32, u32)
where
    G: SensorGroup,
    R: ScriptedSensors,
    B: ScriptBus,
{
    let (mut published, mut empty) = (0, 0);
    let mut now = start;
    let mut k = 0;
    while now < end {
        let topic = topics[k % topics.len()];
        if same_sample(blocking, scripted, bus, topic, now) > 0 {
            published += 1;
        } else {
            empty += 1;
        }
        now += period;
        k += 1;
    }
    (published, empty)
}

const MAGNETOMETER: [Topic; 3] = [
    Topic::MagnetometerX,
    Topic::MagnetometerY,
    Topic::MagnetometerZ,
];

/// DiWheelDrive 1-1's HMC5883L: boot, 300 samples (the identity check every 256 reads among
/// them), a bus that stops acknowledging for 12 s (three failures, then retries after 1, 2, 4,
/// 8 s), and the repair.
#[test]
fn the_compass_as_scripts_samples_as_the_blocking_path_through_a_fault() {
    let mut blocking = Supervised::new(Compass::new(SimCompassBus::new()));
    let mut bus = Recorder::new(SimCompassBus::new());
    let mut scripted = Supervised::boot(Compass::scripted(), &mut bus, &mut NoDelay);
    assert!(scripted.is_ready());
    let (published, empty) = run_both(
        &mut blocking,
        &mut scripted,
        &mut bus,
        &MAGNETOMETER,
        1_000,
        6_001_000,
        20_000,
    );
    assert_eq!((published, empty), (300, 0));
    blocking.group_mut().magnetometer.bus_mut().set_nack(true);
    bus.bus.set_nack(true);
    let (_, empty) = run_both(
        &mut blocking,
        &mut scripted,
        &mut bus,
        &MAGNETOMETER,
        6_001_000,
        18_001_000,
        20_000,
    );
    assert_eq!(empty, 600);
    // Three failed samples, then set-ups that fail 1, 2 and 4 s later (the next is due after 8).
    assert_eq!(scripted.faults(), 3 + 3);
    blocking.group_mut().magnetometer.bus_mut().set_nack(false);
    bus.bus.set_nack(false);
    let (published, _) = run_both(
        &mut blocking,
        &mut scripted,
        &mut bus,
        &MAGNETOMETER,
        18_001_000,
        28_001_000,
        20_000,
    );
    assert!(published > 0 && scripted.is_ready());
    // The devices saw the same traffic: the same registers and the same measurement count.
    let device = blocking.group_mut().magnetometer.bus_mut().magnetometer();
    assert_eq!(device.samples(), bus.bus.magnetometer().samples());
    assert_eq!(device.registers(), bus.bus.magnetometer().registers());
}

/// The HMC5883L's scripts are its datasheet's transactions (HMC5883L datasheet, "Operational
/// Examples" and Table 2, the register list): the identity read of registers 10..12, the three
/// configuration writes with their read-back, and a sample as the six data registers from 3 on
/// (X, Z, Y MSB first) — 84 SCL periods, 210 µs at 400 kHz.
#[test]
fn the_compass_scripts_are_the_datasheet_transactions() {
    let mut bus = Recorder::new(SimCompassBus::new());
    let mut scripted = Supervised::boot(Compass::scripted(), &mut bus, &mut NoDelay);
    assert_eq!(
        bus.scripts,
        [
            script(&[(0x1E, &[0x0A], 3)]),
            script(&[
                (0x1E, &[0x00, 0x74], 0),
                (0x1E, &[0x01, 0xA0], 0),
                (0x1E, &[0x02, 0x00], 0),
                (0x1E, &[0x00], 3),
            ]),
        ]
    );
    assert_eq!(periods(&bus.scripts), [57, 144]);
    bus.scripts.clear();
    bus.bus_time_ns = 0;
    sample_on(&mut scripted, &mut bus, Topic::MagnetometerX, 1_000);
    let sample = script(&[(0x1E, &[hmc5883l::reg::DATA_X_MSB], 6)]);
    assert_eq!(bus.scripts, [sample]);
    let wire: Vec<Symbol> = sample.wire().collect();
    assert_eq!(
        wire[..4],
        [
            Symbol::Start,
            Symbol::Address {
                address: 0x1E,
                read: false
            },
            Symbol::Written(0x03),
            Symbol::RepeatedStart
        ]
    );
    assert_eq!(sample.scl_periods(), 84);
    assert_eq!(bus.bus_time_ns, 210_000);
    // Every 256th read checks the identity first, in the same script.
    scripted.group_mut().set_reuse_window_us(0);
    for n in 2..=256u64 {
        bus.scripts.clear();
        sample_on(&mut scripted, &mut bus, Topic::MagnetometerX, n * 1_000);
    }
    assert_eq!(
        bus.scripts,
        [script(&[(0x1E, &[0x0A], 3), (0x1E, &[0x03], 6)])]
    );
    assert_eq!(periods(&bus.scripts), [141]);
}

/// A reading of all zeros (a dead bus's pattern) on the split path: the identity is read in a
/// second script, and the zeros are published because the part still answers "H43".
#[test]
fn a_compass_pattern_calls_for_an_identity_script() {
    let field = Some([0, 0, 0]);
    let mut blocking = Supervised::new(Compass::new(SimCompassBus::new()));
    let mut bus = Recorder::new(SimCompassBus::new());
    let mut scripted = Supervised::boot(Compass::scripted(), &mut bus, &mut NoDelay);
    blocking
        .group_mut()
        .magnetometer
        .bus_mut()
        .magnetometer_mut()
        .set_field(field);
    bus.bus.magnetometer_mut().set_field(field);
    bus.scripts.clear();
    assert_eq!(
        same_sample(
            &mut blocking,
            &mut scripted,
            &mut bus,
            Topic::MagnetometerY,
            1_000
        ),
        1
    );
    assert_eq!(
        bus.scripts,
        [script(&[(0x1E, &[0x03], 6)]), script(&[(0x1E, &[0x0A], 3)])]
    );
}

const FLOOR: [Topic; 1] = [Topic::FloorProximity];

/// DiWheelDrive's floor (PCA9544A and four VCNL4020 on I2C2): 300 rounds (the identity check of
/// all four among them), the bus gone for 12 s, and the set-up again one sensor per sample.
#[test]
fn the_floor_as_scripts_samples_as_the_blocking_path_through_a_fault() {
    let mut blocking = Supervised::new(FloorSensors::new(SimFloorBus::new()));
    let mut bus = Recorder::new(SimFloorBus::new());
    let mut scripted = Supervised::boot(FloorSensors::scripted(), &mut bus, &mut NoDelay);
    let (published, _) = run_both(
        &mut blocking,
        &mut scripted,
        &mut bus,
        &FLOOR,
        1_000,
        3_001_000,
        10_000,
    );
    assert_eq!(published, 300);
    blocking.group_mut().mux_mut().bus_mut().set_nack(true);
    bus.bus.set_nack(true);
    let (_, empty) = run_both(
        &mut blocking,
        &mut scripted,
        &mut bus,
        &FLOOR,
        3_001_000,
        15_001_000,
        10_000,
    );
    assert_eq!(empty, 1200);
    blocking.group_mut().mux_mut().bus_mut().set_nack(false);
    bus.bus.set_nack(false);
    bus.scripts.clear();
    // The set-up is four steps, one sensor each and alone in its release; the release after the
    // fourth publishes.
    let (published, empty) = run_both(
        &mut blocking,
        &mut scripted,
        &mut bus,
        &FLOOR,
        15_001_000,
        25_001_000,
        10_000,
    );
    assert!(published > 0 && scripted.is_ready());
    assert!(empty > 3);
    for (k, channel) in (0..4).zip(Channel::ALL) {
        let sensor = blocking
            .group_mut()
            .mux_mut()
            .bus_mut()
            .proximity()
            .sensor(k);
        let twin = bus.bus.proximity().sensor(k);
        assert_eq!(
            sensor.unwrap().samples(),
            twin.unwrap().samples(),
            "{channel:?}"
        );
        assert!(twin.unwrap().is_configured_for_amiro());
    }
    assert_muxed_rules(&bus.scripts);
}

/// Every script that reaches a VCNL4020 selects its channel first, in the same script, and no
/// script ends with a select; a bq27500 transfer is a script of its own.
fn assert_muxed_rules(scripts: &[Script]) {
    for script in scripts {
        let ops = script.operations();
        let first_sensor = ops.iter().position(|op| op.address == vcnl4020::ADDRESS);
        let first_select = ops.iter().position(|op| op.address == 0x77);
        if let Some(sensor) = first_sensor {
            assert!(first_select.is_some_and(|s| s < sensor), "{ops:?}");
        }
        assert!(ops.last().is_some_and(|op| op.address != 0x77), "{ops:?}");
        if ops.iter().any(|op| op.address == bq27500::ADDRESS) {
            assert_eq!(ops.len(), 1, "{ops:?}");
        }
    }
}

/// The floor's scripts, worked from the datasheets: the PCA9544A's channel selection is one
/// write of its control register (0x04 | channel) to 0x77, a transaction of its own (START,
/// address, byte, STOP: 1 + 9 + 9 + 1 = 20 SCL periods); a VCNL4020 result is a write of its
/// register (#7, 0x87, proximity high byte) and a two-byte read after a repeated START (1 + 9 +
/// 9 + 1 + 9 + 18 + 1 = 48). A round is four of each, one script: 4 × 68 = 272 periods, 680 µs
/// at 400 kHz. The identity check every 256 rounds is its own script before the round:
/// PRODUCT_ID (register #1, 0x81, one byte: 39 periods) behind each select, 4 × 59 = 236. A
/// sensor's set-up is six scripts, each behind its select: PRODUCT_ID (59), then each of the five
/// registers written (1 + 9 + 18 + 1 = 29) and read back (39): 20 + 29 + 39 = 88.
#[test]
fn the_floor_scripts_are_the_datasheet_transactions() {
    let mut bus = Recorder::new(SimFloorBus::new());
    let mut scripted = Supervised::boot(FloorSensors::scripted(), &mut bus, &mut NoDelay);
    assert!(scripted.is_ready());
    assert_muxed_rules(&bus.scripts);
    let set_up = |channel: u8| {
        let mut scripts = vec![script(&[(0x77, &[channel], 0), (0x13, &[0x81], 1)])];
        for (register, value) in [
            (0x80, 0x00),
            (0x82, 0x06),
            (0x83, 20),
            (0x84, 0x15),
            (0x80, 0x07),
        ] {
            scripts.push(script(&[
                (0x77, &[channel], 0),
                (0x13, &[register, value], 0),
                (0x13, &[register], 1),
            ]));
        }
        scripts
    };
    let boot: Vec<Script> = (4..8).flat_map(set_up).collect();
    assert_eq!(bus.scripts, boot);
    assert_eq!(periods(&bus.scripts[..6]), [59, 88, 88, 88, 88, 88]);
    bus.scripts.clear();
    bus.bus_time_ns = 0;
    sample_on(&mut scripted, &mut bus, Topic::FloorProximity, 1_000);
    let round = script(&[
        (0x77, &[0x04], 0),
        (0x13, &[0x87], 2),
        (0x77, &[0x05], 0),
        (0x13, &[0x87], 2),
        (0x77, &[0x06], 0),
        (0x13, &[0x87], 2),
        (0x77, &[0x07], 0),
        (0x13, &[0x87], 2),
    ]);
    assert_eq!(bus.scripts, [round]);
    assert_eq!(round.scl_periods(), 272);
    assert_eq!(bus.bus_time_ns, 680_000);
    // Rounds 2..=255 are the same script; the 256th checks the identities first.
    for n in 2..=256u64 {
        bus.scripts.clear();
        sample_on(&mut scripted, &mut bus, Topic::FloorProximity, n * 10_000);
    }
    let identities = script(&[
        (0x77, &[0x04], 0),
        (0x13, &[0x81], 1),
        (0x77, &[0x05], 0),
        (0x13, &[0x81], 1),
        (0x77, &[0x06], 0),
        (0x13, &[0x81], 1),
        (0x77, &[0x07], 0),
        (0x13, &[0x81], 1),
    ]);
    assert_eq!(bus.scripts, [identities, round]);
    assert_eq!(periods(&bus.scripts), [236, 272]);
    assert_muxed_rules(&bus.scripts);
}

const IMU_TOPICS: [Topic; 5] = [
    Topic::Gyroscope,
    Topic::Accelerometer,
    Topic::MagnetometerX,
    Topic::MagnetometerY,
    Topic::MagnetometerZ,
];

/// DiWheelDrive 1-2's BNO055: 500 samples of its five topics, the part gone for 12 s (absent:
/// no acknowledge), then back: the set-up's six steps with the mode switches' 19 ms and 7 ms
/// between them, as the blocking path waits them.
#[test]
fn the_bno055_as_scripts_samples_as_the_blocking_path_through_a_fault() {
    let mut blocking = Supervised::new(ImuSensors::new(SimImuBus::new(), NoDelay));
    let mut bus = Recorder::new(SimImuBus::new());
    let mut scripted = Supervised::boot(ImuSensors::scripted(NoDelay), &mut bus, &mut NoDelay);
    let (published, _) = run_both(
        &mut blocking,
        &mut scripted,
        &mut bus,
        &IMU_TOPICS,
        1_000,
        5_001_000,
        10_000,
    );
    assert_eq!(published, 500);
    for fault in [Bno055Fault::Absent, Bno055Fault::StuckLow] {
        blocking
            .group_mut()
            .imu
            .bus_mut()
            .imu_mut()
            .set_fault(fault);
        bus.bus.imu_mut().set_fault(fault);
        let (_, empty) = run_both(
            &mut blocking,
            &mut scripted,
            &mut bus,
            &IMU_TOPICS,
            5_001_000,
            17_001_000,
            10_000,
        );
        assert_eq!(empty, 1200, "{fault:?}");
        blocking
            .group_mut()
            .imu
            .bus_mut()
            .imu_mut()
            .set_fault(Bno055Fault::None);
        bus.bus.imu_mut().set_fault(Bno055Fault::None);
        let (published, _) = run_both(
            &mut blocking,
            &mut scripted,
            &mut bus,
            &IMU_TOPICS,
            17_001_000,
            27_001_000,
            1_000,
        );
        assert!(published > 0 && scripted.is_ready(), "{fault:?}");
    }
    let device = blocking.group_mut().imu.bus_mut().imu();
    assert_eq!(device.samples(), bus.bus.imu().samples());
    assert_eq!(device.mode_switches(), bus.bus.imu().mode_switches());
}

/// The BNO055's sample script is one sensor's six data bytes (the datasheet's register map,
/// e.g. GYR_DATA_X_LSB 0x14 .. 0x19, little-endian X, Y, Z) and OPR_MODE (0x3D), one script
/// of two register reads: 123 SCL periods, 307.5 µs at 400 kHz.
#[test]
fn the_bno055_scripts_are_the_datasheet_transactions() {
    let mut bus = Timeline::new(SimImuBus::new());
    let mut waits = bus.clone();
    let mut scripted = Supervised::boot(ImuSensors::scripted(NoDelay), &mut bus, &mut waits);
    assert!(scripted.is_ready());
    // The boot set-up (BNO055 datasheet, register map page 0 and 1), six steps: page 0
    // (PAGE_ID 0x07) written and the identities (0x00, four bytes) read; ST_RESULT (0x36) read,
    // then configuration mode (OPR_MODE 0x3D = 0x00) written; the part's 19 ms into
    // configuration mode; power mode (PWR_MODE 0x3E), units (UNIT_SEL 0x3B = 0x01) and page 1
    // written; the configuration burst from ACC_CONFIG (0x08: 0x0E, 0x0F, 0x22, 0x00) and its
    // read-back; page 0 and the units' read-back, then AMG mode (OPR_MODE = 0x07); 7 ms into it;
    // OPR_MODE read.
    // SCL periods: a two-byte write 29; a register read of n bytes 30 + 9n; the burst 56.
    assert_eq!(
        bus.events(),
        [
            Event::Script(script(&[(0x28, &[0x07, 0], 0), (0x28, &[0x00], 4)])),
            Event::Script(script(&[(0x28, &[0x36], 1)])),
            Event::Script(script(&[(0x28, &[0x3D, 0x00], 0)])),
            Event::Wait(19_000),
            Event::Script(script(&[
                (0x28, &[0x3E, 0x00], 0),
                (0x28, &[0x3B, 0x01], 0),
                (0x28, &[0x07, 1], 0),
            ])),
            Event::Script(script(&[
                (0x28, &[0x08, 0x0E, 0x0F, 0x22, 0x00], 0),
                (0x28, &[0x08], 4),
            ])),
            Event::Script(script(&[(0x28, &[0x07, 0], 0), (0x28, &[0x3B], 1)])),
            Event::Script(script(&[(0x28, &[0x3D, 0x07], 0)])),
            Event::Wait(7_000),
            Event::Script(script(&[(0x28, &[0x3D], 1)])),
        ]
    );
    let scripts: Vec<Script> = bus.scripts();
    assert_eq!(
        periods(&scripts),
        [29 + 66, 39, 29, 3 * 29, 56 + 66, 29 + 39, 29, 39]
    );
    let mut bus = Recorder::new(SimImuBus::new());
    bus.scripts.clear();
    bus.bus_time_ns = 0;
    sample_on(&mut scripted, &mut bus, Topic::Gyroscope, 1_000);
    let sample = script(&[
        (0x28, &[bno055::reg::GYR_DATA_X_LSB], 6),
        (0x28, &[bno055::reg::OPR_MODE], 1),
    ]);
    assert_eq!(bus.scripts, [sample]);
    assert_eq!(sample.scl_periods(), 123);
    assert_eq!(bus.bus_time_ns, 307_500);
}

#[test]
fn a_failed_operation_is_the_work_s_error_at_that_transfer() {
    use amiro_sensors::drivers::scripted::Job;
    use amiro_sensors::drivers::suite::{Device, SampleError};
    let mut scripted = Supervised::boot(
        FloorSensors::scripted(),
        &mut SimFloorBus::new(),
        &mut NoDelay,
    );
    let mut job = Job::new();
    let Next::Run { script: round, .. } =
        scripted.begin_scripted(&mut job, Topic::FloorProximity, 1_000)
    else {
        panic!("a round needs a script");
    };
    assert_eq!(round.operations().len(), 8);
    // Sensor 2's read (operation 5) is not acknowledged.
    let failed = Err(amiro_sensors::script::ScriptError {
        operation: 5,
        failure: amiro_sensors::script::Failure::NackAddress,
    });
    let next = scripted.resume_scripted(&mut job, Topic::FloorProximity, 1_000, &failed);
    assert_eq!(next, Next::Done(Default::default()));
    assert_eq!(scripted.faults(), 1);
    assert!(matches!(
        scripted.last_error(),
        Some(SampleError::Device {
            device: Device::FloorSensor(2),
            ..
        })
    ));
}

/// Two publishers' samples of one group overlap (each keeps its own `Job`): the magnetometer's X
/// and Y samples both need the bus and their scripts run one after the other; each publishes its
/// own script's reading, decoded when its script ends, and the group keeps the reading decoded
/// last (X's), which a Z sample in the window then reuses without the bus.
#[test]
fn overlapping_jobs_each_publish_their_own_reading() {
    use amiro_sensors::drivers::scripted::Job;
    let mut bus = SimCompassBus::new();
    let mut group = Supervised::boot(Compass::scripted(), &mut bus, &mut NoDelay);
    let (mut x, mut y) = (Job::new(), Job::new());
    let Next::Run {
        script: x_script, ..
    } = group.begin_scripted(&mut x, Topic::MagnetometerX, 5_000)
    else {
        panic!("X needs the bus");
    };
    let Next::Run {
        script: y_script, ..
    } = group.begin_scripted(&mut y, Topic::MagnetometerY, 5_000)
    else {
        panic!("Y needs the bus");
    };
    assert_eq!(x_script, y_script);
    let x_result = bus.answer(&x_script).result;
    let y_result = bus.answer(&y_script).result;
    let Next::Done(y_frames) =
        group.resume_scripted(&mut y, Topic::MagnetometerY, 5_000, &y_result)
    else {
        panic!("Y has its readings");
    };
    let Next::Done(x_frames) =
        group.resume_scripted(&mut x, Topic::MagnetometerX, 5_000, &x_result)
    else {
        panic!("X has its readings");
    };
    // The same part read twice by the blocking driver: X's reading first, Y's second.
    let mut twin = Supervised::new(Compass::new(SimCompassBus::new()));
    let first = twin.group_mut().magnetometer.read().unwrap();
    let second = twin.group_mut().magnetometer.read().unwrap();
    let frame = |axis, nanotesla| amiro_can::SensorData::Magnetometer { axis, nanotesla };
    assert_eq!(
        x_frames.as_slice(),
        [frame(amiro_can::Axis::X, first.nanotesla[0])]
    );
    assert_eq!(
        y_frames.as_slice(),
        [frame(amiro_can::Axis::Y, second.nanotesla[1])]
    );
    let mut z = Job::new();
    let reused = group.begin_scripted(&mut z, Topic::MagnetometerZ, 6_000);
    let expected = [frame(amiro_can::Axis::Z, first.nanotesla[2])];
    assert_eq!(reused, Next::Done(expected.iter().copied().collect()));
    assert!(!x.under_way() && !y.under_way() && !z.under_way());
}

/// The floor bus with the VCNL4020 behind one channel gone (its address not acknowledged while
/// the mux connects that channel): the blocking and the scripted path see the same device fail.
#[derive(Debug, Clone)]
struct DeadChannel {
    floor: SimMuxedProximity,
    dead: Option<u8>,
}

impl I2cTarget for DeadChannel {
    fn acknowledges(&self, address: u8) -> bool {
        let gone = address == vcnl4020::ADDRESS
            && self
                .dead
                .is_some_and(|k| self.floor.control() == pca9544a::ENABLE | k);
        !gone && self.floor.acknowledges(address)
    }
    fn start(&mut self, address: u8, read: bool) {
        self.floor.start(address, read);
    }
    fn write_byte(&mut self, address: u8, byte: u8) {
        self.floor.write_byte(address, byte);
    }
    fn read_byte(&mut self, address: u8) -> u8 {
        self.floor.read_byte(address)
    }
}

/// One floor sensor (channel 2, the left wheel's) gone for 5 s and back: the failures name it
/// (`Device::FloorSensor(2)`, from the failed operation's place in the round's script), the
/// group backs off and is set up again sensor by sensor, as on the blocking path.
#[test]
fn a_floor_sensor_gone_is_named_and_recovered_as_on_the_blocking_path() {
    use amiro_sensors::drivers::suite::{Device, SampleError};
    let floor = || {
        SimBus::with(DeadChannel {
            floor: SimMuxedProximity::new(0),
            dead: None,
        })
    };
    let mut blocking = Supervised::new(FloorSensors::new(floor()));
    let mut bus = Recorder::new(floor());
    let mut scripted = Supervised::boot(FloorSensors::scripted(), &mut bus, &mut NoDelay);
    run_both(
        &mut blocking,
        &mut scripted,
        &mut bus,
        &FLOOR,
        0,
        1_000_000,
        10_000,
    );
    blocking.group_mut().mux_mut().bus_mut().target.dead = Some(2);
    bus.bus.target.dead = Some(2);
    let (_, empty) = run_both(
        &mut blocking,
        &mut scripted,
        &mut bus,
        &FLOOR,
        1_000_000,
        6_000_000,
        10_000,
    );
    assert_eq!(empty, 500);
    assert!(matches!(
        scripted.last_error(),
        Some(SampleError::Device {
            device: Device::FloorSensor(2),
            ..
        })
    ));
    blocking.group_mut().mux_mut().bus_mut().target.dead = None;
    bus.bus.target.dead = None;
    let (published, _) = run_both(
        &mut blocking,
        &mut scripted,
        &mut bus,
        &FLOOR,
        6_000_000,
        16_000_000,
        10_000,
    );
    assert!(published > 0 && scripted.is_ready());
}

/// A publisher's way through a sample (`begin_scripted`, then `resume_scripted` per script
/// until the frames): the BNO055's magnetometer X, its first sample and then one within the reuse
/// window that needs no script.
#[test]
fn a_publisher_begins_and_finishes_a_sample_script_by_script() {
    use amiro_sensors::drivers::scripted::Job;
    let mut sim = SimImuBus::new();
    let mut blocking = Supervised::new(ImuSensors::new(SimImuBus::new(), NoDelay));
    let mut group = Supervised::boot(ImuSensors::scripted(NoDelay), &mut sim, &mut NoDelay);
    let mut job = Job::new();
    let mut scripts = 0;
    let mut next = group.begin_scripted(&mut job, Topic::MagnetometerX, 2_000);
    let frames = loop {
        match next {
            Next::Run { script, settle_us } => {
                assert_eq!(settle_us, 0);
                scripts += 1;
                let result = sim.answer(&script).result;
                next = group.resume_scripted(&mut job, Topic::MagnetometerX, 2_000, &result);
            }
            Next::Done(frames) => break frames,
        }
    };
    assert_eq!(scripts, 1);
    assert_eq!(frames, blocking.sample(Topic::MagnetometerX, 2_000));
    let reused = group.begin_scripted(&mut job, Topic::MagnetometerY, 3_000);
    assert_eq!(
        reused,
        Next::Done(blocking.sample(Topic::MagnetometerY, 3_000))
    );
}

/// A floor sensor reading 0 (a dead bus's pattern) in the middle of a round: the blocking driver
/// reads that sensor's PRODUCT_ID before it passes the 0 on, so the round's script is followed by
/// one with the identity read behind the sensor's select (channel 5: write 0x05 to 0x77; write
/// 0x81 to 0x13, read one byte), and the counts the round read are the frame: each sensor read
/// once, as on the blocking path. The frames are the blocking path's.
#[test]
fn a_dead_bus_pattern_mid_round_is_checked_and_the_round_goes_on() {
    let counts = [3000, 0, 5000, 6000];
    let mut blocking = Supervised::new(FloorSensors::new(SimFloorBus::new()));
    let mut bus = Recorder::new(SimFloorBus::new());
    let mut scripted = Supervised::boot(FloorSensors::scripted(), &mut bus, &mut NoDelay);
    for (k, &c) in counts.iter().enumerate() {
        blocking
            .group_mut()
            .mux_mut()
            .bus_mut()
            .proximity_mut()
            .set_proximity(k, Some(c));
        bus.bus.proximity_mut().set_proximity(k, Some(c));
    }
    bus.scripts.clear();
    let frames = same_sample(
        &mut blocking,
        &mut scripted,
        &mut bus,
        Topic::FloorProximity,
        1_000,
    );
    assert_eq!(frames, 1);
    assert_eq!(
        bus.scripts[1],
        script(&[(0x77, &[0x05], 0), (0x13, &[0x81], 1)])
    );
    assert_eq!(bus.scripts.len(), 2);
    assert_eq!(periods(&bus.scripts), [272, 59]);
    assert_muxed_rules(&bus.scripts);
}

/// A later script of a job that fails at its first operation (the bus gone mid-job, or the
/// client's timeout, which fails operation 0): the second script of a round whose sensor 1 read
/// a dead bus's pattern (its select and PRODUCT_ID) names sensor 1, and
/// the group counts one fault, as the blocking path's failed identity read does.
#[test]
fn a_failed_later_script_is_the_sample_s_failure() {
    use amiro_sensors::drivers::scripted::{timed_out, Job};
    use amiro_sensors::drivers::suite::{Device, SampleError};
    let counts = [3000, 0, 5000, 6000];
    let mut bus = SimFloorBus::new();
    let mut scripted = Supervised::boot(FloorSensors::scripted(), &mut bus, &mut NoDelay);
    for (k, &c) in counts.iter().enumerate() {
        bus.proximity_mut().set_proximity(k, Some(c));
    }
    let faults = scripted.faults();
    let mut job = Job::new();
    let Next::Run { script: first, .. } =
        scripted.begin_scripted(&mut job, Topic::FloorProximity, 1_000)
    else {
        panic!("a round needs a script");
    };
    let result = bus.answer(&first).result;
    let Next::Run { script: second, .. } =
        scripted.resume_scripted(&mut job, Topic::FloorProximity, 1_000, &result)
    else {
        panic!("the dead-bus pattern is checked by a second script");
    };
    assert_eq!(second, script(&[(0x77, &[0x05], 0), (0x13, &[0x81], 1)]));
    assert_eq!(
        scripted.resume_scripted(&mut job, Topic::FloorProximity, 1_000, &timed_out()),
        Next::Done(amiro_sensors::drivers::suite::Samples::new())
    );
    assert_eq!(scripted.faults(), faults + 1);
    assert!(matches!(
        scripted.last_error(),
        Some(SampleError::Device {
            device: Device::FloorSensor(1),
            ..
        })
    ));
    assert!(!job.under_way());
}

/// At boot, before the engine takes the block, a group's set-up runs its scripts operation by
/// operation on the blocking bus (`OnI2c`): the same devices' state and readiness as the
/// simulator's own answers give, and a refused operation is the same error in the same place.
#[test]
fn a_script_on_a_blocking_bus_answers_as_the_simulator() {
    use amiro_sensors::drivers::scripted::OnI2c;
    let mut on_i2c = OnI2c(SimFloorBus::new());
    let mut answering = SimFloorBus::new();
    let a = Supervised::boot(FloorSensors::scripted(), &mut on_i2c, &mut NoDelay);
    let b = Supervised::boot(FloorSensors::scripted(), &mut answering, &mut NoDelay);
    assert!(a.is_ready() && b.is_ready());
    for k in 0..4 {
        let (x, y) = (
            on_i2c.0.proximity().sensor(k).unwrap(),
            answering.proximity().sensor(k).unwrap(),
        );
        assert_eq!(x.registers(), y.registers());
        assert!(x.is_configured_for_amiro());
    }
    let round = script(&[(0x77, &[0x04], 0), (0x13, &[0x87], 2), (0x13, &[0x85], 2)]);
    assert_eq!(on_i2c.run(&round), answering.answer(&round).result);
    let refused = script(&[(0x77, &[0x00], 0), (0x13, &[0x87], 2)]);
    assert_eq!(on_i2c.run(&refused), answering.answer(&refused).result);
    assert_eq!(on_i2c.run(&refused).unwrap_err().operation, 1);
}

/// A BNO055 that comes back with a failed self-test: every set-up step 1 reads the identities
/// and ST_RESULT and stops there, on both paths — the scripted one writes neither the page nor
/// the operating mode on the guess that the self-test passed (the part's mode switches and mode
/// stay the blocking path's).
#[test]
fn no_write_reaches_a_part_whose_check_failed() {
    let mut blocking = Supervised::new(ImuSensors::new(SimImuBus::new(), NoDelay));
    let mut bus = Recorder::new(SimImuBus::new());
    let mut scripted = Supervised::boot(ImuSensors::scripted(NoDelay), &mut bus, &mut NoDelay);
    for (fault, from, to) in [
        (Bno055Fault::Absent, 0, 3_000_000),
        (Bno055Fault::SelfTestFailed, 3_000_000, 20_000_000),
    ] {
        blocking
            .group_mut()
            .imu
            .bus_mut()
            .imu_mut()
            .set_fault(fault);
        bus.bus.imu_mut().set_fault(fault);
        run_both(
            &mut blocking,
            &mut scripted,
            &mut bus,
            &IMU_TOPICS,
            from,
            to,
            10_000,
        );
    }
    assert!(!scripted.is_ready());
    assert!(scripted.faults() > 3 + 1);
    let device = blocking.group_mut().imu.bus_mut().imu();
    assert_eq!(device.mode_switches(), bus.bus.imu().mode_switches());
    assert_eq!(device.operating_mode(), bus.bus.imu().operating_mode());
}

/// The board's ring read of one bus on the blocking path: per sensor the select and the
/// proximity result; a sensor that fails yields `None` and the next is read all the same.
fn ring_read<I: embedded_hal::i2c::I2c>(
    mux: &mut Pca9544a<I>,
    channels: &[Channel],
) -> Vec<Option<u16>> {
    channels
        .iter()
        .map(|&channel| {
            mux.select(channel)
                .ok()
                .and_then(|muxed| Vcnl4020::new(muxed).read_proximity().ok())
        })
        .collect()
}

/// The set-up of one ring sensor on the blocking path, as the board makes it.
fn ring_set_up<I: embedded_hal::i2c::I2c>(mux: &mut Pca9544a<I>, channel: Channel) -> bool {
    match mux.select(channel) {
        Ok(muxed) => Vcnl4020::new(muxed).init(&Config::AMIRO).is_ok(),
        Err(_) => false,
    }
}

/// The same read as scripts: [`RingRead`] to its end.
fn ring_read_scripted(bus: &mut impl ScriptBus, channels: &[Channel]) -> Vec<Option<u16>> {
    let mut read = RingRead::new(pca9544a::AMIRO_ADDRESS, channels);
    for _ in 0..RingRead::MAX_SCRIPTS {
        let Some(script) = read.script() else { break };
        read.complete(&bus.run(&script.unwrap()));
    }
    let counts = read.counts().expect("the read ends within its scripts");
    counts[..channels.len()].to_vec()
}

/// The same set-up as scripts: [`SensorSetUp`] to its end.
fn ring_set_up_scripted(bus: &mut impl ScriptBus, channel: Channel) -> bool {
    let mut set_up = SensorSetUp::new(pca9544a::AMIRO_ADDRESS, channel, Config::AMIRO);
    loop {
        let script = set_up.script().unwrap();
        if let Some(done) = set_up.complete(&bus.run(&script)) {
            return done.is_ok();
        }
    }
}

/// A gauge's work as scripts, one transfer each, with the settling time each asks for.
fn gauge_status_scripted(
    bus: &mut impl ScriptBus,
    settles: &mut Vec<u32>,
) -> Option<BatteryStatus> {
    let mut read = StatusRead::new();
    for _ in 0..StatusRead::MAX_TRANSFERS + 1 {
        let transfer = read.next_transfer()?;
        settles.push(GAUGE_SETTLE_US);
        let result = bus.run(&gauge_script(transfer).unwrap());
        if let Some(done) = read.complete(gauge_outcome(transfer, &result)) {
            return done.ok();
        }
    }
    panic!("the status read did not end within its transfers");
}

fn gauge_identity_scripted(bus: &mut impl ScriptBus) -> Result<(), Error<ErrorKind>> {
    let mut check = GaugeIdentity::new();
    while let Some(transfer) = check.next_transfer() {
        let result = bus.run(&gauge_script(transfer).unwrap());
        if let Some(done) = check.complete(gauge_outcome(transfer, &result)) {
            return done;
        }
    }
    panic!("the identity check ended without an answer");
}

/// PowerManagement's I2C1: the ring sensors' set-up and 100 rounds, the gauge's identity check
/// and ten status reads a transfer a script (`StatusRead`, as `BatteryRound` makes them), the bus
/// gone and back: the same values, the same devices' state, on both paths.
#[test]
fn a_power_bus_as_scripts_reads_as_the_blocking_path() {
    let channels: Vec<Channel> = WIRING
        .iter()
        .filter(|(bus, _)| *bus == RingBus::I2c1)
        .map(|&(_, channel)| channel)
        .collect();
    let mut blocking = Pca9544a::new(SimPowerBus::new(0, true));
    let mut bus = Recorder::new(SimPowerBus::new(0, true));
    for &channel in &channels {
        let expected = ring_set_up(&mut blocking, channel);
        let got = ring_set_up_scripted(&mut bus, channel);
        assert!(expected && got);
    }
    let identity = Bq27500::new(blocking.bus_mut(), NoDelay).init();
    assert_eq!(identity, Ok(()));
    assert_eq!(gauge_identity_scripted(&mut bus), Ok(()));
    let mut settles = Vec::new();
    for round in 0..100 {
        let expected = ring_read(&mut blocking, &channels);
        let got = ring_read_scripted(&mut bus, &channels);
        assert_eq!(got, expected, "round {round}");
        if round % 10 == 0 {
            if round == 50 {
                blocking.bus_mut().set_nack(true);
                bus.bus.set_nack(true);
            }
            let expected = Bq27500::new(blocking.bus_mut(), NoDelay).read_status().ok();
            let got = gauge_status_scripted(&mut bus, &mut settles);
            assert_eq!(got, expected, "gauge at round {round}");
            if round == 50 {
                assert_eq!(expected, None);
                assert_eq!(ring_read(&mut blocking, &channels), [None; 4]);
                assert_eq!(ring_read_scripted(&mut bus, &channels), [None; 4]);
                blocking.bus_mut().set_nack(false);
                bus.bus.set_nack(false);
            }
        }
    }
    // Every gauge script waits the gauge's 66 µs of bus-free time first.
    assert!(settles.iter().all(|&s| s == 66));
    assert_eq!(
        blocking.bus_mut().fuel_gauge().samples(),
        bus.bus.fuel_gauge().samples()
    );
    for k in 0..4 {
        assert_eq!(
            blocking.bus_mut().proximity().sensor(k).unwrap().samples(),
            bus.bus.proximity().sensor(k).unwrap().samples()
        );
    }
    assert_muxed_rules(&bus.scripts);
}

/// A power bus's scripts, worked from the datasheets: the ring round is four selects (PCA9544A
/// control register, 20 SCL periods each) and proximity reads (VCNL4020 register #7, 0x87, two
/// bytes: 48), 272 SCL periods, in the channels' order; a gauge's standard command is one write
/// of the command byte and a two-byte read after a repeated START (bq27500 datasheet, standard
/// commands): 1 + 9 + 9 + 1 + 9 + 18 + 1 = 48 SCL periods, 120 µs, alone in its script for the
/// gauge's 66 µs of bus-free time. Control(DEVICE_TYPE) is its two one-byte subcommand writes
/// (0x01 to 0x00, 0x00 to 0x01: 29 periods each) and the read of 0x00, three scripts.
#[test]
fn the_power_bus_scripts_are_the_datasheet_transactions() {
    let mut bus = Recorder::new(SimPowerBus::new(4, false));
    for channel in Channel::ALL {
        assert!(ring_set_up_scripted(&mut bus, channel));
    }
    bus.scripts.clear();
    let channels = [Channel::Ch0, Channel::Ch1, Channel::Ch3, Channel::Ch2];
    let counts = ring_read_scripted(&mut bus, &channels);
    assert!(counts.iter().all(Option::is_some));
    let round = script(&[
        (0x77, &[0x04], 0),
        (0x13, &[0x87], 2),
        (0x77, &[0x05], 0),
        (0x13, &[0x87], 2),
        (0x77, &[0x07], 0),
        (0x13, &[0x87], 2),
        (0x77, &[0x06], 0),
        (0x13, &[0x87], 2),
    ]);
    assert_eq!(bus.scripts, [round]);
    assert_eq!(round.scl_periods(), 272);
    bus.scripts.clear();
    assert_eq!(gauge_identity_scripted(&mut bus), Ok(()));
    assert_eq!(
        bus.scripts,
        [
            script(&[(0x55, &[0x00, 0x01], 0)]),
            script(&[(0x55, &[0x01, 0x00], 0)]),
            script(&[(0x55, &[0x00], 2)]),
        ]
    );
    assert_eq!(periods(&bus.scripts), [29, 29, 48]);
    bus.scripts.clear();
    bus.bus_time_ns = 0;
    let read = StatusRead::new();
    let temperature = gauge_script(read.next_transfer().unwrap()).unwrap();
    assert_eq!(
        temperature,
        script(&[(0x55, &[bq27500::cmd::TEMPERATURE], 2)])
    );
    assert_eq!(temperature.scl_periods(), 48);
    assert_eq!(bus.bus.answer(&temperature).bus_time_ns(), 120_000);
    assert_eq!(GAUGE_SETTLE_US, 66);
    // A whole status read: the ten commands in the driver's order, one script each.
    let mut settles = Vec::new();
    assert!(gauge_status_scripted(&mut bus, &mut settles).is_some());
    let commands: Vec<u8> = bus.scripts.iter().map(|s| s.written()[0]).collect();
    assert_eq!(
        commands,
        [0x06, 0x08, 0x0A, 0x10, 0x12, 0x14, 0x16, 0x18, 0x24, 0x2C]
    );
}

/// A ring sensor whose read fails mid-round (its channel's VCNL4020 gone): it yields no count,
/// the others theirs, as on the blocking path; the script that failed (which returns no
/// readings) is followed by one that reads the sensor before it again and the ones after it.
#[test]
fn a_ring_sensor_gone_fails_alone() {
    let channels = [Channel::Ch0, Channel::Ch1, Channel::Ch2, Channel::Ch3];
    let floor = || {
        SimBus::with(DeadChannel {
            floor: SimMuxedProximity::new(0),
            dead: Some(1),
        })
    };
    let mut blocking = Pca9544a::new(floor());
    let mut bus = Recorder::new(floor());
    for channel in [Channel::Ch0, Channel::Ch2, Channel::Ch3] {
        assert!(ring_set_up(&mut blocking, channel));
        assert!(ring_set_up_scripted(&mut bus, channel));
    }
    bus.scripts.clear();
    let expected = ring_read(&mut blocking, &channels);
    assert_eq!(expected[1], None);
    assert!(expected[0].is_some() && expected[2].is_some() && expected[3].is_some());
    let got = ring_read_scripted(&mut bus, &channels);
    assert_eq!(got[1..], expected[1..]);
    // Sensor 0's count of the failed script is lost with it: the next script reads it again,
    // the count the blocking path's next read of it gives.
    assert_eq!(got[0], ring_read(&mut blocking, &[Channel::Ch0])[0]);
    assert_ne!(got[0], expected[0]);
    assert_eq!(bus.scripts.len(), 2);
    assert_eq!(bus.scripts[1].operations().len(), 6);
    assert_muxed_rules(&bus.scripts);
}

/// A boot with the parts gone (no acknowledge): the scripted set-up fails as `Supervised::new`'s
/// blocking one does — missing, one fault, the same error, its retry after 1 s — and the groups
/// then sample as the blocking path through the retries and the parts' return.
#[test]
fn a_boot_without_the_parts_is_missing_as_on_the_blocking_path() {
    fn check<G: SensorGroup, R: ScriptedSensors>(blocking: Supervised<G>, scripted: Supervised<R>) {
        assert!(!scripted.is_ready());
        assert_eq!(
            (
                scripted.faults(),
                scripted.last_error(),
                scripted.retry_at_us()
            ),
            (
                blocking.faults(),
                blocking.last_error(),
                blocking.retry_at_us()
            )
        );
        assert_eq!(scripted.faults(), 1);
    }
    let absent = || {
        let mut bus = SimCompassBus::new();
        bus.set_nack(true);
        bus
    };
    let mut bus = Recorder::new(absent());
    let mut scripted = Supervised::boot(Compass::scripted(), &mut bus, &mut NoDelay);
    let mut blocking = Supervised::new(Compass::new(absent()));
    check(Supervised::new(Compass::new(absent())), scripted.clone());
    blocking.group_mut().magnetometer.bus_mut().set_nack(false);
    bus.bus.set_nack(false);
    run_both(
        &mut blocking,
        &mut scripted,
        &mut bus,
        &MAGNETOMETER,
        0,
        3_000_000,
        20_000,
    );
    assert!(scripted.is_ready());

    let absent = || {
        let mut bus = SimFloorBus::new();
        bus.set_nack(true);
        bus
    };
    let mut bus = Recorder::new(absent());
    let mut scripted = Supervised::boot(FloorSensors::scripted(), &mut bus, &mut NoDelay);
    let mut blocking = Supervised::new(FloorSensors::new(absent()));
    check(
        Supervised::new(FloorSensors::new(absent())),
        scripted.clone(),
    );
    blocking.group_mut().mux_mut().bus_mut().set_nack(false);
    bus.bus.set_nack(false);
    run_both(
        &mut blocking,
        &mut scripted,
        &mut bus,
        &FLOOR,
        0,
        3_000_000,
        10_000,
    );
    assert!(scripted.is_ready());

    let absent = || {
        let mut bus = SimImuBus::new();
        bus.imu_mut().set_fault(Bno055Fault::Absent);
        bus
    };
    let mut bus = Recorder::new(absent());
    let mut scripted = Supervised::boot(ImuSensors::scripted(NoDelay), &mut bus, &mut NoDelay);
    let mut blocking = Supervised::new(ImuSensors::new(absent(), NoDelay));
    check(
        Supervised::new(ImuSensors::new(absent(), NoDelay)),
        scripted.clone(),
    );
    blocking
        .group_mut()
        .imu
        .bus_mut()
        .imu_mut()
        .set_fault(Bno055Fault::None);
    bus.bus.imu_mut().set_fault(Bno055Fault::None);
    run_both(
        &mut blocking,
        &mut scripted,
        &mut bus,
        &IMU_TOPICS,
        0,
        3_000_000,
        1_000,
    );
    assert!(scripted.is_ready());
}

mod random_faults {
    //! Random fault patterns, sample by sample, on both paths at once: the frames, the fault
    //! count, readiness, the last error and the retry time stay equal.
    use super::*;
    use proptest::prelude::*;

    /// What the parts do during one sample.
    #[derive(Debug, Clone, Copy)]
    enum Fault {
        /// Working.
        None,
        /// Nothing acknowledges.
        Nack,
        /// Readings of a dead bus's pattern (all zeros) from working parts.
        Pattern,
        /// One floor sensor (by channel) gone; the BNO055's self-test failed; the compass
        /// working.
        One(u8),
    }

    fn fault() -> impl Strategy<Value = Fault> {
        prop_oneof![
            6 => Just(Fault::None),
            2 => Just(Fault::Nack),
            1 => Just(Fault::Pattern),
            1 => (0u8..4).prop_map(Fault::One),
        ]
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(24))]

        #[test]
        fn the_compass(faults in proptest::collection::vec(fault(), 100..300)) {
            let mut blocking = Supervised::new(Compass::new(SimCompassBus::new()));
            let mut bus = SimCompassBus::new();
            let mut scripted = Supervised::boot(Compass::scripted(), &mut bus, &mut NoDelay);
            for (k, fault) in faults.into_iter().enumerate() {
                let field = matches!(fault, Fault::Pattern).then_some([0, 0, 0]);
                let nack = matches!(fault, Fault::Nack);
                for sim in [blocking.group_mut().magnetometer.bus_mut(), &mut bus] {
                    sim.set_nack(nack);
                    sim.magnetometer_mut().set_field(field);
                }
                let topic = MAGNETOMETER[k % 3];
                same_sample(&mut blocking, &mut scripted, &mut bus, topic, k as u64 * 15_000);
            }
        }

        #[test]
        fn the_floor(faults in proptest::collection::vec(fault(), 100..300)) {
            let floor = || {
                SimBus::with(DeadChannel {
                    floor: SimMuxedProximity::new(0),
                    dead: None,
                })
            };
            let mut blocking = Supervised::new(FloorSensors::new(floor()));
            let mut bus = floor();
            let mut scripted = Supervised::boot(FloorSensors::scripted(), &mut bus, &mut NoDelay);
            for (k, fault) in faults.into_iter().enumerate() {
                for sim in [blocking.group_mut().mux_mut().bus_mut(), &mut bus] {
                    sim.set_nack(matches!(fault, Fault::Nack));
                    sim.target.dead = match fault {
                        Fault::One(channel) => Some(channel),
                        _ => None,
                    };
                    let count = matches!(fault, Fault::Pattern).then_some(0);
                    for channel in [1, 3] {
                        sim.target.floor.set_proximity(channel, count);
                    }
                }
                same_sample(
                    &mut blocking,
                    &mut scripted,
                    &mut bus,
                    Topic::FloorProximity,
                    k as u64 * 300_000,
                );
            }
        }

        /// A PowerManagement ring bus (its sensors fed fixed counts, as a world feeds them, so
        /// that a sensor read again in the next script reads the same): the counts of every round
        /// equal the blocking read's.
        #[test]
        fn a_ring_bus(
            faults in proptest::collection::vec(fault(), 50..150),
            counts in proptest::array::uniform4(1u16..5000),
        ) {
            let ring = || {
                SimBus::with(DeadChannel {
                    floor: SimMuxedProximity::new(0),
                    dead: None,
                })
            };
            let channels = [Channel::Ch1, Channel::Ch3, Channel::Ch2, Channel::Ch0];
            let mut blocking = Pca9544a::new(ring());
            let mut bus = ring();
            for channel in channels {
                assert!(ring_set_up(&mut blocking, channel));
                assert!(ring_set_up_scripted(&mut bus, channel));
            }
            for (k, fault) in faults.into_iter().enumerate() {
                for sim in [blocking.bus_mut(), &mut bus] {
                    sim.set_nack(matches!(fault, Fault::Nack));
                    sim.target.dead = match fault {
                        Fault::One(channel) => Some(channel),
                        _ => None,
                    };
                    for (channel, &count) in counts.iter().enumerate() {
                        let pattern = matches!(fault, Fault::Pattern) && channel % 2 == 1;
                        sim.target
                            .floor
                            .set_proximity(channel, Some(if pattern { 0 } else { count }));
                    }
                }
                let expected = ring_read(&mut blocking, &channels);
                prop_assert_eq!(ring_read_scripted(&mut bus, &channels), expected, "round {}", k);
            }
        }

        #[test]
        fn the_bno055(faults in proptest::collection::vec(fault(), 100..300)) {
            let mut blocking = Supervised::new(ImuSensors::new(SimImuBus::new(), NoDelay));
            let mut bus = SimImuBus::new();
            let mut scripted =
                Supervised::boot(ImuSensors::scripted(NoDelay), &mut bus, &mut NoDelay);
            for (k, fault) in faults.into_iter().enumerate() {
                let fault = match fault {
                    Fault::None => Bno055Fault::None,
                    Fault::Nack => Bno055Fault::Absent,
                    Fault::Pattern => Bno055Fault::StuckLow,
                    Fault::One(_) => Bno055Fault::SelfTestFailed,
                };
                blocking.group_mut().imu.bus_mut().imu_mut().set_fault(fault);
                bus.imu_mut().set_fault(fault);
                let topic = IMU_TOPICS[k % IMU_TOPICS.len()];
                same_sample(&mut blocking, &mut scripted, &mut bus, topic, k as u64 * 12_000);
            }
        }
    }
}
