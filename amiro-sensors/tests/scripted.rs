//! The sensor groups' split path (`drivers::scripted`): the same work, its transfers recorded
//! into scripts and run by the simulated buses (`SimBus::answer`), gives the samples the blocking
//! path gives on identical simulated devices — fault counting, back-off and the stepwise set-up
//! included — and each script carries the datasheet's transaction.

use amiro_can::Topic;
use amiro_sensors::drivers::bq27500::{self, BatteryStatus, Bq27500, StatusRead};
use amiro_sensors::drivers::floor::FloorSensors;
use amiro_sensors::drivers::pca9544a::{Channel, Pca9544a};
use amiro_sensors::drivers::ring::{RingBus, WIRING};
use amiro_sensors::drivers::scripted::{
    Next, ReplayBus, Replayed, Replaying, ScriptBus, ScriptResult,
};
use amiro_sensors::drivers::suite::{Compass, ImuSensors, SensorGroup, Supervised};
use amiro_sensors::drivers::vcnl4020::{self, Config, Vcnl4020};
use amiro_sensors::drivers::{bno055, hmc5883l, pca9544a};
use amiro_sensors::script::{Script, Symbol};
use amiro_sensors::sim::*;

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

/// One sample of `topic` at `now` on both paths: the frames, the fault count, readiness, the last
/// error and the retry time must be the same. Returns the frames' count.
fn same_sample<G, R, B>(
    blocking: &mut Supervised<G>,
    scripted: &mut Replayed<Supervised<R>>,
    bus: &mut B,
    topic: Topic,
    now: u64,
) -> usize
where
    G: SensorGroup,
    R: SensorGroup + Clone + Replaying,
    B: ScriptBus,
{
    let expected = blocking.sample(topic, now);
    let got = scripted
        .run(bus, |s| s.sample(topic, now))
        .expect("a job within its rounds");
    assert_eq!(got, expected, "{topic:?} at {now} µs");
    let s = scripted.state();
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
    scripted: &mut Replayed<Supervised<R>>,
    bus: &mut B,
    topics: &[Topic],
    start: u64,
    end: u64,
    period: u64,
) -> (u32, u32)
where
    G: SensorGroup,
    R: SensorGroup + Clone + Replaying,
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
    let mut scripted = Replayed::boot(Compass::new(ReplayBus::compass()), &mut bus).unwrap();
    assert!(scripted.state().is_ready());
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
    assert_eq!(scripted.state().faults(), 3 + 3);
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
    assert!(published > 0 && scripted.state().is_ready());
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
    let mut scripted = Replayed::boot(Compass::new(ReplayBus::compass()), &mut bus).unwrap();
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
    scripted
        .run(&mut bus, |s| s.sample(Topic::MagnetometerX, 1_000))
        .unwrap();
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
    scripted.state_mut().group_mut().set_reuse_window_us(0);
    for n in 2..=256u64 {
        bus.scripts.clear();
        scripted
            .run(&mut bus, |s| s.sample(Topic::MagnetometerX, n * 1_000))
            .unwrap();
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
    let mut scripted = Replayed::boot(Compass::new(ReplayBus::compass()), &mut bus).unwrap();
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
    let mut scripted = Replayed::boot(FloorSensors::new(ReplayBus::muxed()), &mut bus).unwrap();
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
    // The set-up is four steps, one sensor each; the fourth sample after the retry publishes.
    let (published, empty) = run_both(
        &mut blocking,
        &mut scripted,
        &mut bus,
        &FLOOR,
        15_001_000,
        25_001_000,
        10_000,
    );
    assert!(published > 0 && scripted.state().is_ready());
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

/// The floor round's script is PCA9544A's channel selection (its datasheet's "Control
/// register" write: 0x04 | channel) and the VCNL4020's proximity result read (its datasheet's
/// register #7 and #8, high byte first), four times: one script, 8 operations, 272 SCL periods,
/// 680 µs at 400 kHz. The identity check every 256 rounds adds PRODUCT_ID (register #1) behind
/// each select; it and the round are 16 operations, two scripts.
#[test]
fn the_floor_scripts_are_the_datasheet_transactions() {
    let mut bus = Recorder::new(SimFloorBus::new());
    let mut scripted = Replayed::boot(FloorSensors::new(ReplayBus::muxed()), &mut bus).unwrap();
    // The boot set-up: per sensor the select and PRODUCT_ID, then each register written and
    // read back, each write in a script that begins with the select again.
    assert_muxed_rules(&bus.scripts);
    assert_eq!(
        bus.scripts[..3],
        [
            script(&[(0x77, &[0x04], 0), (0x13, &[0x81], 1)]),
            script(&[
                (0x77, &[0x04], 0),
                (0x13, &[0x80, 0x00], 0),
                (0x13, &[0x80], 1)
            ]),
            script(&[
                (0x77, &[0x04], 0),
                (0x13, &[0x82, 0x06], 0),
                (0x13, &[0x82], 1)
            ]),
        ]
    );
    // A sensor's last read-back, the next sensor's select and PRODUCT_ID share a script.
    assert_eq!(bus.scripts.len(), 1 + 4 * 5);
    // Select and PRODUCT_ID 59 periods; each register's select, write and read-back 88 (the
    // last with the next sensor's select and PRODUCT_ID).
    assert_eq!(periods(&bus.scripts[..6]), [59, 88, 88, 88, 88, 88 + 59]);
    bus.scripts.clear();
    bus.bus_time_ns = 0;
    scripted
        .run(&mut bus, |s| s.sample(Topic::FloorProximity, 1_000))
        .unwrap();
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
        scripted
            .run(&mut bus, |s| s.sample(Topic::FloorProximity, n * 10_000))
            .unwrap();
    }
    assert_eq!(bus.scripts.len(), 2);
    let identities: Vec<_> = bus.scripts[0].operations()[..8]
        .iter()
        .map(|op| (op.address, op.write, op.read))
        .collect();
    assert_eq!(identities, [(0x77, 1, 0), (0x13, 1, 1)].repeat(4));
    assert_eq!(bus.scripts[0].operations().len(), 12);
    assert_eq!(periods(&bus.scripts), [372, 136]);
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
/// no acknowledge), then back: the set-up's three steps with the mode switches' 19 ms and 7 ms
/// between them, as the blocking path waits them.
#[test]
fn the_bno055_as_scripts_samples_as_the_blocking_path_through_a_fault() {
    let mut blocking = Supervised::new(ImuSensors::new(SimImuBus::new(), NoDelay));
    let mut bus = Recorder::new(SimImuBus::new());
    let mut scripted =
        Replayed::boot(ImuSensors::new(ReplayBus::imu(), NoDelay), &mut bus).unwrap();
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
        assert!(published > 0 && scripted.state().is_ready(), "{fault:?}");
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
    let mut bus = Recorder::new(SimImuBus::new());
    let mut scripted =
        Replayed::boot(ImuSensors::new(ReplayBus::imu(), NoDelay), &mut bus).unwrap();
    // The boot set-up: the identities and the self-test in one script of reads, page 0 and
    // configuration mode; power mode, units, page 1, the configuration burst and its
    // read-back; page 0 and the units' read-back; AMG mode; its check.
    assert_eq!(
        bus.scripts,
        [
            script(&[(0x28, &[0x00], 4), (0x28, &[0x36], 1)]),
            script(&[(0x28, &[0x07, 0], 0), (0x28, &[0x3D, 0x00], 0)]),
            script(&[
                (0x28, &[0x3E, 0x00], 0),
                (0x28, &[0x3B, 0x01], 0),
                (0x28, &[0x07, 1], 0),
                (0x28, &[0x08, 0x0E, 0x0F, 0x22, 0x00], 0),
                (0x28, &[0x08], 4),
            ]),
            script(&[(0x28, &[0x07, 0], 0), (0x28, &[0x3B], 1)]),
            script(&[(0x28, &[0x3D, 0x07], 0)]),
            script(&[(0x28, &[0x3D], 1)]),
        ]
    );
    assert_eq!(periods(&bus.scripts), [105, 58, 209, 68, 29, 39]);
    // The mode switches' waits come before the script after each OPR_MODE write.
    let mut settles = Vec::new();
    let mut imu = Replayed::new(ImuSensors::new(ReplayBus::imu(), NoDelay));
    let mut twin = SimImuBus::new();
    while let Next::Run(script) = imu.step(|s| s.init()).unwrap() {
        settles.push(imu.settle_us());
        imu.complete(&twin.answer(&script).result);
    }
    assert_eq!(settles, [0, 0, 19_000, 0, 0, 7_000]);
    bus.scripts.clear();
    bus.bus_time_ns = 0;
    scripted
        .run(&mut bus, |s| s.sample(Topic::Gyroscope, 1_000))
        .unwrap();
    let sample = script(&[
        (0x28, &[bno055::reg::GYR_DATA_X_LSB], 6),
        (0x28, &[bno055::reg::OPR_MODE], 1),
    ]);
    assert_eq!(bus.scripts, [sample]);
    assert_eq!(sample.scl_periods(), 123);
    assert_eq!(bus.bus_time_ns, 307_500);
}

/// One PowerManagement bus as the board samples it (powermgmt's `SensorBus`): its mux, the
/// ring sensors on it and its fuel gauge's read under way.
#[derive(Clone)]
struct PowerBus {
    mux: Pca9544a<ReplayBus>,
    read: StatusRead,
}

impl Replaying for PowerBus {
    fn replay_bus(&mut self) -> &mut ReplayBus {
        self.mux.bus_mut()
    }
}

/// The board's ring read of one bus: per sensor the select and the proximity result, a sensor
/// that fails yields `None` and the next is read all the same.
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

/// The set-up of one ring sensor as the board makes it.
fn ring_set_up<I: embedded_hal::i2c::I2c>(mux: &mut Pca9544a<I>, channel: Channel) -> bool {
    match mux.select(channel) {
        Ok(muxed) => Vcnl4020::new(muxed).init(&Config::AMIRO).is_ok(),
        Err(_) => false,
    }
}

/// PowerManagement's I2C1: the ring sensors' set-up and 100 rounds, the gauge's identity check
/// and ten status reads a transfer at a time (`StatusRead::step`, what `BatteryRound` makes),
/// the bus gone and back: the same values, the same devices' state, on both paths.
#[test]
fn a_power_bus_as_scripts_reads_as_the_blocking_path() {
    let channels: Vec<Channel> = WIRING
        .iter()
        .filter(|(bus, _)| *bus == RingBus::I2c1)
        .map(|&(_, channel)| channel)
        .collect();
    let mut blocking = Pca9544a::new(SimPowerBus::new(0, true));
    let mut bus = Recorder::new(SimPowerBus::new(0, true));
    let mut scripted = Replayed::new(PowerBus {
        mux: Pca9544a::new(ReplayBus::muxed()),
        read: StatusRead::new(),
    });
    for &channel in &channels {
        let expected = ring_set_up(&mut blocking, channel);
        let got = scripted
            .run(&mut bus, |s| ring_set_up(&mut s.mux, channel))
            .unwrap();
        assert!(expected && got);
    }
    let identity = Bq27500::new(blocking.bus_mut(), NoDelay).init();
    let scripted_identity = scripted
        .run(&mut bus, |s| Bq27500::new(s.mux.bus_mut(), NoDelay).init())
        .unwrap();
    assert_eq!(identity, Ok(()));
    assert_eq!(scripted_identity.map_err(|e| e.map_bus(|_| ())), Ok(()));
    let gauge_read = |s: &mut PowerBus| -> Option<Option<BatteryStatus>> {
        let mut gauge = Bq27500::new(s.mux.bus_mut(), NoDelay);
        s.read.step(&mut gauge).map(|done| done.ok())
    };
    for round in 0..100 {
        let expected = ring_read(&mut blocking, &channels);
        let got = scripted
            .run(&mut bus, |s| ring_read(&mut s.mux, &channels))
            .unwrap();
        assert_eq!(got, expected, "round {round}");
        if round % 10 == 0 {
            if round == 50 {
                blocking.bus_mut().set_nack(true);
                bus.bus.set_nack(true);
            }
            let expected = Bq27500::new(blocking.bus_mut(), NoDelay).read_status().ok();
            let mut got = None;
            for _ in 0..StatusRead::MAX_TRANSFERS {
                if let Some(done) = scripted.run(&mut bus, gauge_read).unwrap() {
                    got = Some(done);
                    scripted.state_mut().read.restart();
                    break;
                }
            }
            assert_eq!(got, Some(expected), "gauge at round {round}");
            if round == 50 {
                assert_eq!(expected, None);
                assert_eq!(ring_read(&mut blocking, &channels), [None; 4]);
                blocking.bus_mut().set_nack(false);
                bus.bus.set_nack(false);
            }
        }
    }
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

/// A power bus's scripts: the ring round is four selects and proximity reads (PCA9544A
/// "Control register", VCNL4020 registers #7/#8), 272 SCL periods; a gauge's standard command
/// is one write of the command byte and a two-byte read after a repeated START (bq27500
/// datasheet, "I2C interface", standard commands), alone in its script for the gauge's 66 µs of
/// bus-free time: 48 SCL periods, 120 µs. Control(DEVICE_TYPE) is its two one-byte subcommand
/// writes and the read of 0x00, three scripts.
#[test]
fn the_power_bus_scripts_are_the_datasheet_transactions() {
    let mut bus = Recorder::new(SimPowerBus::new(4, false));
    let mut scripted = Replayed::new(PowerBus {
        mux: Pca9544a::new(ReplayBus::muxed()),
        read: StatusRead::new(),
    });
    for channel in Channel::ALL {
        assert!(scripted
            .run(&mut bus, |s| ring_set_up(&mut s.mux, channel))
            .unwrap());
    }
    bus.scripts.clear();
    let channels = [Channel::Ch0, Channel::Ch1, Channel::Ch3, Channel::Ch2];
    let counts = scripted
        .run(&mut bus, |s| ring_read(&mut s.mux, &channels))
        .unwrap();
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
    scripted
        .run(&mut bus, |s| Bq27500::new(s.mux.bus_mut(), NoDelay).init())
        .unwrap()
        .unwrap();
    assert_eq!(
        bus.scripts,
        [
            script(&[(0x55, &[0x00, 0x01], 0)]),
            script(&[(0x55, &[0x01, 0x00], 0)]),
            script(&[(0x55, &[0x00], 2)]),
        ]
    );
    // Each gauge script after the first waits the gauge's 66 µs of bus-free time.
    let mut settles = Vec::new();
    let init = |s: &mut PowerBus| Bq27500::new(s.mux.bus_mut(), NoDelay).init();
    while let Next::Run(script) = scripted.step(init).unwrap() {
        settles.push(scripted.settle_us());
        scripted.complete(&bus.bus.answer(&script).result);
    }
    assert_eq!(settles, [0, 66, 66]);
    bus.scripts.clear();
    bus.bus_time_ns = 0;
    let step = scripted
        .step(|s| {
            let mut gauge = Bq27500::new(s.mux.bus_mut(), NoDelay);
            s.read.step(&mut gauge).is_some()
        })
        .unwrap();
    let temperature = script(&[(0x55, &[bq27500::cmd::TEMPERATURE], 2)]);
    assert_eq!(step, Next::Run(temperature));
    assert_eq!(temperature.scl_periods(), 48);
    assert_eq!(bus.bus.answer(&temperature).bus_time_ns(), 120_000);
}

/// A failed script names its operation, and the work sees the bus error at the transfer that
/// failed (the floor's sensor behind the mux, here the first read), not at the first operation.
#[test]
fn a_failed_operation_is_the_work_s_error_at_that_transfer() {
    let mut scripted = Replayed::new(FloorSensors::new(ReplayBus::muxed()));
    let work = |s: &mut FloorSensors<ReplayBus>| s.read_proximity().map_err(|e| e.sensor);
    let Next::Run(round) = scripted.step(work).unwrap() else {
        panic!("a round needs a script");
    };
    assert_eq!(round.operations().len(), 8);
    // Sensor 2's read (operation 5) is not acknowledged.
    scripted.complete(&Err(amiro_sensors::script::ScriptError {
        operation: 5,
        failure: amiro_sensors::script::Failure::NackAddress,
    }));
    assert_eq!(scripted.step(work).unwrap(), Next::Done(Err(2)));
}

/// Two publishers' jobs on one group overlap (each keeps its own `Job`; the group changes only
/// when a job ends): the magnetometer's X job records its read, the Y job runs and ends first,
/// and the X job then ends on the group as the Y job left it — the Y reading reused within the
/// window, as the blocking path would after a Y sample, the X job's own read unused.
#[test]
fn overlapping_jobs_each_keep_their_log_and_end_on_the_group_as_it_is() {
    use amiro_sensors::drivers::scripted::{step, Job};
    let mut bus = SimCompassBus::new();
    let mut group = Replayed::boot(Compass::new(ReplayBus::compass()), &mut bus)
        .unwrap()
        .state()
        .clone();
    let (mut x, mut y) = (Job::new(), Job::new());
    let sample = |topic| move |s: &mut Supervised<Compass<ReplayBus>>| s.sample(topic, 5_000);
    let Next::Run(x_script) = step(&mut group, &mut x, sample(Topic::MagnetometerX)).unwrap()
    else {
        panic!("X needs the bus");
    };
    let Next::Run(y_script) = step(&mut group, &mut y, sample(Topic::MagnetometerY)).unwrap()
    else {
        panic!("Y needs the bus");
    };
    assert_eq!(x_script, y_script);
    x.complete(&bus.answer(&x_script).result);
    y.complete(&bus.answer(&y_script).result);
    let Next::Done(y_frames) = step(&mut group, &mut y, sample(Topic::MagnetometerY)).unwrap()
    else {
        panic!("Y has its readings");
    };
    let Next::Done(x_frames) = step(&mut group, &mut x, sample(Topic::MagnetometerX)).unwrap()
    else {
        panic!("X has its readings");
    };
    // The blocking path, Y then X: the second reading's field for both.
    let mut blocking = Supervised::new(Compass::new(SimCompassBus::new()));
    // The simulator's first read is X's (unused); the Y job's read is the second.
    blocking.group_mut().magnetometer.read().unwrap();
    assert_eq!(y_frames, blocking.sample(Topic::MagnetometerY, 5_000));
    assert_eq!(x_frames, blocking.sample(Topic::MagnetometerX, 5_000));
    assert_eq!(x.logged() + y.logged(), 0);
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
    let mut scripted = Replayed::boot(FloorSensors::new(ReplayBus::muxed()), &mut bus).unwrap();
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
        scripted.state().last_error(),
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
    assert!(published > 0 && scripted.state().is_ready());
}

/// A publisher's way through a sample (`begin_sample`, then `finish_sample` per script until the
/// frames): the BNO055's magnetometer X, its first sample and then one within the reuse window
/// that needs no script.
#[test]
fn a_publisher_begins_and_finishes_a_sample_script_by_script() {
    use amiro_sensors::drivers::scripted::{begin_sample, finish_sample, Job};
    let mut sim = SimImuBus::new();
    let mut blocking = Supervised::new(ImuSensors::new(SimImuBus::new(), NoDelay));
    let mut group = Replayed::boot(ImuSensors::new(ReplayBus::imu(), NoDelay), &mut sim)
        .unwrap()
        .state()
        .clone();
    let mut job = Job::new();
    let mut scripts = 0;
    let mut next = begin_sample(&mut group, &mut job, Topic::MagnetometerX, 2_000);
    let frames = loop {
        match next {
            Next::Run(script) => {
                scripts += 1;
                let result = sim.answer(&script).result;
                next = finish_sample(&mut group, &mut job, Topic::MagnetometerX, 2_000, &result);
            }
            Next::Done(frames) => break frames,
        }
    };
    assert_eq!(scripts, 1);
    assert_eq!(frames, blocking.sample(Topic::MagnetometerX, 2_000));
    let reused = begin_sample(&mut group, &mut job, Topic::MagnetometerY, 3_000);
    assert_eq!(
        reused,
        Next::Done(blocking.sample(Topic::MagnetometerY, 3_000))
    );
}

/// A floor sensor reading 0 (a dead bus's pattern) in the middle of a round: the round's script
/// ran on the guess that every reading is data, so the replay finds the work wanting that
/// sensor's PRODUCT_ID where the log has the next select. The reads made on the guess are
/// dropped and the next script carries the identity read behind the sensor's select and the rest
/// of the round again (the sensors after it read twice: the cost of a wrong guess). The frames
/// are the blocking path's (the sensors fed fixed counts, as a world feeds them).
#[test]
fn a_dead_bus_pattern_mid_round_is_checked_and_the_round_goes_on() {
    let counts = [3000, 0, 5000, 6000];
    let mut blocking = Supervised::new(FloorSensors::new(SimFloorBus::new()));
    let mut bus = Recorder::new(SimFloorBus::new());
    let mut scripted = Replayed::boot(FloorSensors::new(ReplayBus::muxed()), &mut bus).unwrap();
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
        script(&[
            (0x77, &[0x05], 0),
            (0x13, &[0x81], 1),
            (0x77, &[0x06], 0),
            (0x13, &[0x87], 2),
            (0x77, &[0x07], 0),
            (0x13, &[0x87], 2),
        ])
    );
    assert_eq!(bus.scripts.len(), 2);
    assert_muxed_rules(&bus.scripts);
}

/// A later script of a job that fails at its first operation, the select sent again at its start
/// (the bus gone mid-job, or the client's timeout, which fails operation 0): the work sees that
/// failure at its next transfer and the group counts the fault, as the blocking path's failed
/// read does; the same script is not recorded again.
#[test]
fn a_failed_resent_select_is_the_work_s_failure_not_a_script_to_run_again() {
    let counts = [3000, 0, 5000, 6000];
    let mut bus = SimFloorBus::new();
    let mut scripted = Replayed::boot(FloorSensors::new(ReplayBus::muxed()), &mut bus).unwrap();
    for (k, &c) in counts.iter().enumerate() {
        bus.proximity_mut().set_proximity(k, Some(c));
    }
    let faults = scripted.state().faults();
    let sample =
        |s: &mut Supervised<FloorSensors<ReplayBus>>| s.sample(Topic::FloorProximity, 1_000);
    let Next::Run(first) = scripted.step(sample).unwrap() else {
        panic!("a round needs a script");
    };
    scripted.complete(&bus.answer(&first).result);
    let Next::Run(second) = scripted.step(sample).unwrap() else {
        panic!("the dead-bus pattern is checked by a second script");
    };
    assert_eq!(second.operations().first().map(|o| o.address), Some(0x77));
    scripted.complete(&Err(amiro_sensors::script::ScriptError {
        operation: 0,
        failure: amiro_sensors::script::Failure::NackAddress,
    }));
    assert_eq!(
        scripted.step(sample).unwrap(),
        Next::Done(amiro_sensors::drivers::suite::Samples::new())
    );
    assert_eq!(scripted.state().faults(), faults + 1);
}

/// At boot, before the engine takes the block, a group's set-up runs its scripts operation by
/// operation on the blocking bus (`OnI2c`): the same devices' state and readiness as the
/// simulator's own answers give, and a refused operation is the same error in the same place.
#[test]
fn a_script_on_a_blocking_bus_answers_as_the_simulator() {
    use amiro_sensors::drivers::scripted::OnI2c;
    let mut on_i2c = OnI2c(SimFloorBus::new());
    let mut answering = SimFloorBus::new();
    let a = Replayed::boot(FloorSensors::new(ReplayBus::muxed()), &mut on_i2c).unwrap();
    let b = Replayed::boot(FloorSensors::new(ReplayBus::muxed()), &mut answering).unwrap();
    assert!(a.state().is_ready() && b.state().is_ready());
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
    let mut scripted =
        Replayed::boot(ImuSensors::new(ReplayBus::imu(), NoDelay), &mut bus).unwrap();
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
    assert!(!scripted.state().is_ready());
    assert!(scripted.state().faults() > 3 + 1);
    let device = blocking.group_mut().imu.bus_mut().imu();
    assert_eq!(device.mode_switches(), bus.bus.imu().mode_switches());
    assert_eq!(device.operating_mode(), bus.bus.imu().operating_mode());
}
