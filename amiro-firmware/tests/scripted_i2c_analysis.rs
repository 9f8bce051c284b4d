//! DiWheelDrive 1-1's `scripted-i2c` trial fed to the analysis (docs/i2c.md): its two sensor
//! buses and the compass's and the floor's sample scripts, stated as a timing file would state
//! them, in a scratch copy of the workspace's timing files (the shipped 1-1 image does not run
//! them, so the real files do not state them yet). The statements are checked against the scripts
//! the groups put on the wire; the copy lowers into the chip's admission table with the figures
//! stated; and the report charges the engine per script.

use std::path::PathBuf;

mod common;
use common::{copy_dir, repository, wire_counts};

use amiro_can::Topic;
use amiro_firmware::i2c_engine::events;
use amiro_sensors::drivers::floor::FloorSensors;
use amiro_sensors::drivers::scripted::{Job, Next, ScriptBus, ScriptedSensors, Scripts};
use amiro_sensors::drivers::suite::{Compass, Supervised};
use amiro_sensors::script::Script;
use amiro_sensors::sim::{NoDelay, SimCompassBus, SimFloorBus};
use schedule_analysis::admission_host;
use schedule_analysis::analysis::{analyse, Options};
use schedule_analysis::model::FrameCostSpec;
use schedule_analysis::scenario;
use schedule_analysis::time::Time;
use serde_json::json;

/// The HMC5883L's sample as the timing file states it: write the register pointer, a repeated
/// START, read six (an address byte for each direction): 9 bytes, 2 STARTs, and the engine's 11
/// interrupts (counted on the register model: `i2c_tests`, `dwd_sample_scripts_raise_the_stated_events`).
const COMPASS_BYTES: u32 = 9;
const COMPASS_STARTS: u32 = 2;

/// The floor's sample as the timing file states it: per VCNL4020 the PCA9544A's select (an
/// address, a control byte) and the proximity result's read (write the register, repeated START,
/// read two): 4 × (2 + 5) bytes, 4 × (1 + 2) STARTs.
const FLOOR_BYTES: u32 = 28;
const FLOOR_STARTS: u32 = 12;

/// The engine's parts on the F103, tools/engine-bound's bounds (README.md), µs, rounded up: an event
/// without a script's end and the calls after it (I2Cx_EV's 254 cycles, the larger of the two
/// handlers': I2Cx_ER's are 234); a script's end, the next script's look-up and its client's wake
/// (600 cycles); per START, the condition wait's code and its caller's (368 cycles) and its stated
/// 5.6 µs.
const PER_EVENT_US: f64 = 3.53;
const PER_SCRIPT_US: f64 = 8.34;
const CONDITION_WAIT_US: f64 = 10.72;

/// The scripts of one sample of `topic` on a bus that answers at once.
fn sample_scripts<G: ScriptedSensors>(
    group: &mut Supervised<G>,
    bus: &mut impl ScriptBus,
    topic: Topic,
    now_us: u64,
) -> Vec<Script> {
    let mut job = Job::new();
    let mut next = group.begin_scripted(&mut job, topic, now_us);
    let mut scripts = Vec::new();
    for _ in 0..G::MAX_SCRIPTS {
        match next {
            Next::Done(_) => break,
            Next::Run { script, .. } => {
                let result = bus.run(&script);
                scripts.push(script);
                next = group.resume_scripted(&mut job, topic, now_us, &result);
            }
        }
    }
    scripts
}

#[test]
fn the_stated_scripts_are_the_ones_the_groups_put_on_the_wire() {
    let mut bus = SimCompassBus::new();
    let mut compass = Supervised::boot(Compass::<Scripts>::scripted(), &mut bus, &mut NoDelay);
    assert!(compass.is_ready());
    let scripts = sample_scripts(&mut compass, &mut bus, Topic::MagnetometerX, 1_000);
    assert_eq!(scripts.len(), 1);
    assert_eq!(wire_counts(&scripts[0]), (COMPASS_BYTES, COMPASS_STARTS));
    // The analysis's wire time (9 bit times a byte, 2 a START) covers the script's SCL periods.
    assert!(9 * COMPASS_BYTES + 2 * COMPASS_STARTS >= scripts[0].scl_periods());

    let mut bus = SimFloorBus::new();
    let mut floor = Supervised::boot(FloorSensors::<Scripts>::scripted(), &mut bus, &mut NoDelay);
    assert!(floor.is_ready());
    let scripts = sample_scripts(&mut floor, &mut bus, Topic::FloorProximity, 1_000);
    assert_eq!(scripts.len(), 1);
    assert_eq!(wire_counts(&scripts[0]), (FLOOR_BYTES, FLOOR_STARTS));
    assert!(9 * FLOOR_BYTES + 2 * FLOOR_STARTS >= scripts[0].scl_periods());
}

/// The scripts of the group's worst job: a release takes a set-up step or its sample, never both
/// (`Supervised::after_step`), and a set-up step (the compass's two scripts, 201 SCL periods; one
/// floor sensor's six, 499) is longer than a sample (the compass's 84 periods, 141 with the
/// identity check every 256th; the floor's round 272). Found as the trial runs it: the group
/// booted without its parts, the parts back, a release after the retry.
fn set_up_step_scripts<G: ScriptedSensors, B: ScriptBus>(
    group: G,
    mut bus: B,
    nack: impl Fn(&mut B, bool),
    topic: Topic,
) -> Vec<Script> {
    nack(&mut bus, true);
    let mut group = Supervised::boot(group, &mut bus, &mut NoDelay);
    assert!(!group.is_ready());
    nack(&mut bus, false);
    sample_scripts(&mut group, &mut bus, topic, 60_000_000)
}

fn compass_set_up() -> Vec<Script> {
    set_up_step_scripts(
        Compass::<Scripts>::scripted(),
        SimCompassBus::new(),
        |b, on| b.set_nack(on),
        Topic::MagnetometerX,
    )
}

fn floor_set_up() -> Vec<Script> {
    set_up_step_scripts(
        FloorSensors::<Scripts>::scripted(),
        SimFloorBus::new(),
        |b, on| b.set_nack(on),
        Topic::FloorProximity,
    )
}

/// The soundness gap of the first statement (2026-12-05): each topic stated its sample's script,
/// but a release may run a set-up step instead, whose scripts are more and longer. Each topic's
/// stated scripts in the copy are its group's set-up step's, with the bytes, STARTs and events
/// they put on the wire.
#[test]
fn the_stated_jobs_are_the_set_up_steps() {
    let compass = compass_set_up();
    assert_eq!(compass.len(), 2);
    assert_eq!(
        compass.iter().map(Script::scl_periods).sum::<u32>(),
        57 + 144
    );
    let floor = floor_set_up();
    assert_eq!(floor.len(), 6);
    assert_eq!(floor.iter().map(Script::scl_periods).sum::<u32>(), 499);
    let root = scripted_workspace("jobs");
    let robot = admission_host::lower_robot(&root).unwrap_or_else(|e| panic!("{e}"));
    let dwd = robot
        .boards
        .iter()
        .find(|b| b.name == "diwheeldrive")
        .expect("DiWheelDrive");
    for (topic, job, bus) in [
        ("magnetometer-x", &compass, 0),
        ("floor-proximity", &floor, 1),
    ] {
        let stated = &dwd
            .topics
            .iter()
            .find(|t| t.name == topic)
            .expect("the topic")
            .scripts;
        assert_eq!(stated.len(), job.len(), "{topic}");
        for (lowered, script) in stated.iter().zip(job) {
            let (bytes, starts) = wire_counts(script);
            assert_eq!(usize::from(lowered.bus), bus);
            assert_eq!(u32::from(lowered.events), events(script));
            assert_eq!(u32::from(lowered.starts), starts);
            assert_eq!(
                u64::from(lowered.bus_time),
                u64::from(9 * bytes + 2 * starts) * 2_500
            );
        }
    }
    let _ = std::fs::remove_dir_all(&root);
}

/// A script statement of the timing file.
fn script(bus: &str, bytes: u32, starts: u32, events: u32, source: &str) -> serde_json::Value {
    json!({
        "bus": bus, "bytes": bytes, "starts": starts, "events": events, "source": source,
        "stretch_us": 0.0,
        "stretch_source": "the HMC5883L, the PCA9544A and the VCNL4020 state no clock stretching (docs/analysis.md, the I2C waits)"
    })
}

/// The workspace's apps and timing files, DiWheelDrive 1-1's file stating the trial's buses and
/// scripts.
fn scripted_workspace(test: &str) -> PathBuf {
    let real = repository();
    let root = std::env::temp_dir().join(format!(
        "scripted-i2c-analysis-{}-{test}",
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&root);
    std::fs::create_dir_all(&root).unwrap();
    for board in ["diwheeldrive", "powermgmt", "lightring"] {
        std::os::unix::fs::symlink(real.join(board), root.join(board)).unwrap();
    }
    let models = root.join(scenario::MODELS_DIR);
    copy_dir(&real.join(scenario::MODELS_DIR), &models);
    let file = models.join("diwheeldrive.timing.json");
    let mut timing: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&file).unwrap()).unwrap();
    assert_eq!(timing["app"]["features"], json!(["rev-1-1"]));
    let engine = json!({
        "priority": 5,
        "per_event_us": PER_EVENT_US, "per_event_from": "bound",
        "source": "tools/engine-bound: I2Cx_EV (I2Cx_ER's fewer) without Inner::end and I2cBus::after_end, F103",
        "per_script": { "us": PER_SCRIPT_US, "from": "bound", "source": "tools/engine-bound: Inner::end + I2cBus::after_end - I2cBus::after_start, F103" },
        "condition_wait": { "us": CONDITION_WAIT_US, "from": "bound", "source": "tools/engine-bound: I2cBus::after_start without its stall's wake, its code and the stated wait (i2c_engine::CONDITION_WAIT_NS), F103" }
    });
    timing["sensor_buses"] = json!([
        { "name": "i2c1", "bitrate": 400000, "engine": engine },
        { "name": "i2c2", "bitrate": 400000, "engine": engine },
    ]);
    // Each topic's worst job: its group's set-up step (`set_up_step_scripts`).
    let job = |bus: &str, scripts: Vec<Script>, source: &str| {
        scripts
            .iter()
            .map(|s| {
                let (bytes, starts) = wire_counts(s);
                script(bus, bytes, starts, events(s), source)
            })
            .collect::<Vec<_>>()
    };
    for topic in ["magnetometer-x", "magnetometer-y", "magnetometer-z"] {
        timing["topics"][topic]["scripts"] = json!(job(
            "i2c1",
            compass_set_up(),
            "the HMC5883L's set-up step (Compass<Scripts>), longer than its sample"
        ));
    }
    timing["topics"]["floor-proximity"]["scripts"] = json!(job(
        "i2c2",
        floor_set_up(),
        "one floor sensor's set-up step (FloorSensors<Scripts>), longer than the round"
    ));
    std::fs::write(&file, timing.to_string()).unwrap();
    root
}

#[test]
fn the_trial_lowers_into_the_admission_table_and_the_report_charges_its_engine() {
    let root = scripted_workspace("report");
    let robot = admission_host::lower_robot(&root).unwrap_or_else(|e| panic!("{e}"));
    let dwd = robot
        .boards
        .iter()
        .find(|b| b.name == "diwheeldrive")
        .expect("DiWheelDrive");
    assert_eq!(dwd.buses.len(), 2);
    for bus in &dwd.buses {
        assert_eq!(
            (bus.engine_priority, bus.per_script, bus.condition_wait),
            (5, 8_340, 10_720)
        );
    }
    let scripts = |name: &str| {
        dwd.topics
            .iter()
            .find(|t| t.name == name)
            .unwrap_or_else(|| panic!("{name}"))
            .scripts
            .clone()
    };
    // The compass's set-up step: the identity (6 bytes, 2 STARTs: (9 × 6 + 2 × 2) × 2.5 µs, no
    // stretch; 8 events), then the three configuration writes and their read-back (15 bytes, 5
    // STARTs: 362.5 µs; 23 events).
    let compass = scripts("magnetometer-x");
    assert_eq!(compass.len(), 2);
    assert_eq!(
        (
            compass[0].bus,
            compass[0].bus_time,
            compass[0].events,
            compass[0].starts
        ),
        (0, 145_000, 8, 2)
    );
    assert_eq!(
        (compass[1].bus_time, compass[1].events, compass[1].starts),
        (362_500, 23, 5)
    );
    // One floor sensor's set-up step: its identity behind its select (6 bytes, 3 STARTs: 150 µs;
    // 11 events), then five registers each written and read back.
    let floor = scripts("floor-proximity");
    assert_eq!(floor.len(), 6);
    assert_eq!(
        (
            floor[0].bus,
            floor[0].bus_time,
            floor[0].events,
            floor[0].starts
        ),
        (1, 150_000, 11, 3)
    );

    // The report of the thesis's magnetometer at 900 µs on 1-1: the engine's row per script.
    let scenario_file = root
        .join(scenario::MODELS_DIR)
        .join("thesis-magnetometer-900us.scenario.json");
    let built = scenario::build(&root, &scenario_file, &scenario::timing_files(&root))
        .unwrap_or_else(|e| panic!("{e}"));
    let analysis = analyse(
        &built.model.validate().expect("valid"),
        &Options {
            frame_cost: FrameCostSpec::Exact,
            horizon: None,
        },
    );
    let board = analysis
        .boards
        .iter()
        .find(|b| b.name == "diwheeldrive")
        .expect("DiWheelDrive in the report");
    let engine = board
        .tasks
        .iter()
        .find(|t| t.name == "i2c1_engine[publish_medium[magnetometer-x]#2]")
        .unwrap_or_else(|| {
            panic!(
                "no engine row: {:?}",
                board.tasks.iter().map(|t| &t.name).collect::<Vec<_>>()
            )
        });
    // At the engine's priority, released with the job: the set-up step's second script, 23
    // events × (3.53 µs and the board's interrupt entry and exit, 0.39 µs) + 8.34 µs + 5 STARTs ×
    // 10.72 µs = 152.10 µs (the sample's script alone was 72.90 µs: 11 events, 2 STARTs).
    assert_eq!(engine.priority, 5);
    assert_eq!(engine.period, Time::from_us(900));
    assert_eq!(engine.wcet, Time::from_ns(152_100));
    // Today's verdict (docs/i2c.md): the report prints it; the figures above are what it rests on.
    let job = board
        .tasks
        .iter()
        .find(|t| t.name == "publish_medium[magnetometer-x]")
        .expect("the magnetometer's job");
    println!(
        "publish_medium[magnetometer-x]: {:?}; engine row {:?}; utilisation {:.3}",
        job.bound, engine.bound, board.utilisation
    );
    // What an engine event's response adds up from: the tasks at or above its priority, each
    // with its cost, period and blocking.
    for t in board.tasks.iter().filter(|t| t.priority >= 5) {
        println!(
            "  priority {} {}: wcet {:?} period {:?} blocking {:?}",
            t.priority, t.name, t.wcet, t.period, t.blocking
        );
    }
    for bus in &board.sensor_buses {
        println!(
            "{}: event response {:?}, utilisation {:.3}",
            bus.name, bus.event_response, bus.utilisation
        );
        for s in &bus.scripts {
            println!(
                "  {}: wire {:?} events {} bus time {:?} blocking {:?} suspension {:?} {:?}",
                s.task, s.wire, s.events, s.bus_time, s.blocking, s.suspension, s.bound
            );
        }
    }

    // The thesis demo's set (gyroscope and odometry on DiWheelDrive) samples no I2C topic: the
    // trial's buses carry no script there and add no engine row.
    let demo = common::thesis_demo(&root);
    let dwd = demo
        .boards
        .iter()
        .find(|b| b.name == "diwheeldrive")
        .expect("diwheeldrive in the report");
    assert!(dwd.tasks.iter().all(|t| !t.name.contains("_engine[")));
    assert!(dwd.sensor_buses.iter().all(|b| b.scripts.is_empty()));
    println!(
        "thesis-demo: DiWheelDrive every task schedulable: {}; utilisation {:.3}",
        dwd.tasks.iter().all(|t| t.schedulable()),
        dwd.utilisation
    );
    let _ = std::fs::remove_dir_all(&root);
}
