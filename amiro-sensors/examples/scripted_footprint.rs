//! What the sensor groups' scripted path costs, printed (not asserted): the size of each group's
//! scripted state and of the job a publisher keeps while its scripts run, and per sample the
//! scripts and their SCL periods (`Script::scl_periods`, nine per byte and one per START,
//! repeated START and STOP) on the simulated devices.
//!
//! `cargo run -p amiro-sensors --example scripted_footprint`

use core::mem::size_of;

use amiro_can::Topic;
use amiro_sensors::drivers::bq27500::StatusRead;
use amiro_sensors::drivers::floor::FloorSensors;
use amiro_sensors::drivers::pca9544a::{self, Channel};
use amiro_sensors::drivers::scripted::{
    gauge_script, CompassStage, FloorStage, GaugeIdentity, ImuStage, Job, Next, RingRead,
    ScriptBus, ScriptResult, ScriptedSensors, Scripts, SensorSetUp,
};
use amiro_sensors::drivers::suite::{Compass, ImuSensors, Supervised};
use amiro_sensors::drivers::vcnl4020::Config;
use amiro_sensors::script::Script;
use amiro_sensors::sim::{I2cTarget, NoDelay, SimBus, SimCompassBus, SimFloorBus, SimImuBus};

/// A simulated bus that counts the scripts it runs and their SCL periods.
struct Counting<T> {
    bus: SimBus<T>,
    scripts: usize,
    periods: u32,
}

impl<T: I2cTarget> Counting<T> {
    fn new(bus: SimBus<T>) -> Self {
        Self {
            bus,
            scripts: 0,
            periods: 0,
        }
    }

    fn take(&mut self) -> (usize, u32) {
        let counts = (self.scripts, self.periods);
        self.scripts = 0;
        self.periods = 0;
        counts
    }
}

impl<T: I2cTarget> ScriptBus for Counting<T> {
    fn run(&mut self, script: &Script) -> ScriptResult {
        self.scripts += 1;
        self.periods += script.scl_periods();
        self.bus.answer(script).result
    }
}

/// One publisher's sample run to its end: its scripts and their periods.
fn sample<G: ScriptedSensors, T: I2cTarget>(
    group: &mut Supervised<G>,
    bus: &mut Counting<T>,
    topic: Topic,
    now_us: u64,
) -> (usize, u32) {
    let mut job = Job::new();
    let mut next = group.begin_scripted(&mut job, topic, now_us);
    for _ in 0..G::MAX_SCRIPTS {
        match next {
            Next::Done(_) => break,
            Next::Run { script, .. } => {
                let result = bus.run(&script);
                next = group.resume_scripted(&mut job, topic, now_us, &result);
            }
        }
    }
    bus.take()
}

fn line(group: &str, what: &str, (scripts, periods): (usize, u32)) {
    let us = f64::from(periods) * 2.5;
    println!("{group:<26} {what:<44} {scripts:>2} script(s) {periods:>4} SCL periods {us:>7.1} µs");
}

fn main() {
    println!("sizes (host build; the chips' are no larger):");
    let sizes = [
        (
            "Supervised<Compass<Scripts>>",
            size_of::<Supervised<Compass<Scripts>>>(),
        ),
        ("Job<CompassStage>", size_of::<Job<CompassStage>>()),
        (
            "Supervised<FloorSensors<Scripts>>",
            size_of::<Supervised<FloorSensors<Scripts>>>(),
        ),
        ("Job<FloorStage>", size_of::<Job<FloorStage>>()),
        (
            "Supervised<ImuSensors<Scripts, NoDelay>>",
            size_of::<Supervised<ImuSensors<Scripts, NoDelay>>>(),
        ),
        ("Job<ImuStage>", size_of::<Job<ImuStage>>()),
        ("RingRead (one PowerManagement bus)", size_of::<RingRead>()),
        ("SensorSetUp (one VCNL4020)", size_of::<SensorSetUp>()),
        ("StatusRead (a bq27500's)", size_of::<StatusRead>()),
        ("GaugeIdentity", size_of::<GaugeIdentity>()),
        ("Script (one, by value)", size_of::<Script>()),
    ];
    for (name, size) in sizes {
        println!("  {name:<42} {size:>5} B");
    }
    println!();
    println!("scripts per sample (SCL periods at 400 kHz, without clock stretching):");

    let mut bus = Counting::new(SimCompassBus::new());
    let mut compass = Supervised::boot(Compass::new(Scripts), &mut bus, &mut NoDelay);
    line("Compass (HMC5883L)", "boot set-up", bus.take());
    line(
        "Compass (HMC5883L)",
        "sample (a fresh reading)",
        sample(&mut compass, &mut bus, Topic::MagnetometerX, 1_000),
    );
    line(
        "Compass (HMC5883L)",
        "sample of another axis within 33.3 ms",
        sample(&mut compass, &mut bus, Topic::MagnetometerY, 2_000),
    );
    compass.group_mut().set_reuse_window_us(0);
    // The largest of the next 256 samples: the one that checks the identity.
    let checked = (3..=258u64)
        .map(|n| sample(&mut compass, &mut bus, Topic::MagnetometerX, n * 1_000))
        .max_by_key(|&(_, periods)| periods)
        .unwrap_or_default();
    line(
        "Compass (HMC5883L)",
        "sample with the identity check (1 in 256)",
        checked,
    );

    let mut bus = Counting::new(SimFloorBus::new());
    let mut floor = Supervised::boot(FloorSensors::new(Scripts), &mut bus, &mut NoDelay);
    line(
        "Floor (PCA9544A, 4 VCNL)",
        "boot set-up (4 sensors)",
        bus.take(),
    );
    line(
        "Floor (PCA9544A, 4 VCNL)",
        "round",
        sample(&mut floor, &mut bus, Topic::FloorProximity, 1_000),
    );
    let checked = (2..=257u64)
        .map(|n| sample(&mut floor, &mut bus, Topic::FloorProximity, n * 10_000))
        .max_by_key(|&(_, periods)| periods)
        .unwrap_or_default();
    line(
        "Floor (PCA9544A, 4 VCNL)",
        "round with the identity check (1 in 256)",
        checked,
    );

    let mut bus = Counting::new(SimImuBus::new());
    let mut imu = Supervised::boot(ImuSensors::new(Scripts, NoDelay), &mut bus, &mut NoDelay);
    line(
        "ImuSensors (BNO055)",
        "boot set-up (19 ms and 7 ms between)",
        bus.take(),
    );
    for (topic, what) in [
        (Topic::Gyroscope, "gyroscope sample"),
        (
            Topic::MagnetometerX,
            "magnetometer sample (a fresh reading)",
        ),
    ] {
        line(
            "ImuSensors (BNO055)",
            what,
            sample(&mut imu, &mut bus, topic, 1_000),
        );
    }

    let mut bus = Counting::new(SimFloorBus::new());
    let mut set_up = SensorSetUp::new(pca9544a::AMIRO_ADDRESS, Channel::Ch0, Config::AMIRO);
    loop {
        let script = set_up.script().expect("a set-up script fits");
        if set_up.complete(&bus.run(&script)).is_some() {
            break;
        }
    }
    line("PowerManagement bus", "a ring sensor's set-up", bus.take());
    for channel in [Channel::Ch1, Channel::Ch2, Channel::Ch3] {
        let mut set_up = SensorSetUp::new(pca9544a::AMIRO_ADDRESS, channel, Config::AMIRO);
        while let Ok(script) = set_up.script() {
            if set_up.complete(&bus.run(&script)).is_some() {
                break;
            }
        }
    }
    bus.take();
    let mut ring = RingRead::new(pca9544a::AMIRO_ADDRESS, &Channel::ALL);
    while let Some(Ok(script)) = ring.script() {
        ring.complete(&bus.run(&script));
    }
    line(
        "PowerManagement bus",
        "ring round (four sensors)",
        bus.take(),
    );
    let mut read = StatusRead::new();
    let mut gauge = (0, 0);
    while let Some(transfer) = read.next_transfer() {
        let script = gauge_script(transfer).expect("a gauge script fits");
        gauge.0 += 1;
        gauge.1 += script.scl_periods();
        // The status read's words as a gauge that answers (a dead line's pattern would add the
        // identity check's three scripts).
        if read.complete::<()>(Ok(0x1234)).is_some() {
            break;
        }
    }
    line(
        "PowerManagement bus",
        "gauge status read (66 µs before each)",
        gauge,
    );
    let mut identity = GaugeIdentity::new();
    let mut check = (0, 0);
    while let Some(transfer) = identity.next_transfer() {
        let script = gauge_script(transfer).expect("a gauge script fits");
        check.0 += 1;
        check.1 += script.scl_periods();
        if identity.complete::<()>(Ok(0x0500)).is_some() {
            break;
        }
    }
    line(
        "PowerManagement bus",
        "gauge identity (66 µs before each)",
        check,
    );
}
