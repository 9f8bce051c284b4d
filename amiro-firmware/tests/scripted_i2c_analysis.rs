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
const COMPASS_EVENTS: u32 = 11;
/// The floor's sample as the timing file states it: per VCNL4020 the PCA9544A's select (an
/// address, a control byte) and the proximity result's read (write the register, repeated START,
/// read two): 4 × (2 + 5) bytes, 4 × (1 + 2) STARTs.
const FLOOR_BYTES: u32 = 28;
const FLOOR_STARTS: u32 = 12;
const FLOOR_EVENTS: u32 = 44;

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
fn scripted_workspace() -> PathBuf {
    let real = repository();
    let root = std::env::temp_dir().join(format!("scripted-i2c-analysis-{}", std::process::id()));
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
    for topic in ["magnetometer-x", "magnetometer-y", "magnetometer-z"] {
        timing["topics"][topic]["script"] = script(
            "i2c1",
            COMPASS_BYTES,
            COMPASS_STARTS,
            COMPASS_EVENTS,
            "the HMC5883L's sample script (Compass<Scripts>)",
        );
    }
    timing["topics"]["floor-proximity"]["script"] = script(
        "i2c2",
        FLOOR_BYTES,
        FLOOR_STARTS,
        FLOOR_EVENTS,
        "the floor round's script (FloorSensors<Scripts>)",
    );
    std::fs::write(&file, timing.to_string()).unwrap();
    root
}

#[test]
fn the_trial_lowers_into_the_admission_table_and_the_report_charges_its_engine() {
    let root = scripted_workspace();
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
    // 9 bytes and 2 STARTs at 400 kHz: (9 × 9 + 2 × 2) × 2.5 µs, no stretch; 11 events.
    let compass = scripts("magnetometer-x");
    assert_eq!(compass.len(), 1);
    assert_eq!(
        (
            compass[0].bus,
            compass[0].bus_time,
            compass[0].events,
            compass[0].starts
        ),
        (0, 212_500, 11, 2)
    );
    // 28 bytes and 12 STARTs: (9 × 28 + 2 × 12) × 2.5 µs; 44 events.
    let floor = scripts("floor-proximity");
    assert_eq!(
        (
            floor[0].bus,
            floor[0].bus_time,
            floor[0].events,
            floor[0].starts
        ),
        (1, 690_000, 44, 12)
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
        .find(|t| t.name == "i2c1_engine[publish_medium[magnetometer-x]]")
        .unwrap_or_else(|| {
            panic!(
                "no engine row: {:?}",
                board.tasks.iter().map(|t| &t.name).collect::<Vec<_>>()
            )
        });
    // At the engine's priority, released with the job: 11 events × (3.53 µs and the board's
    // interrupt entry and exit, 0.39 µs) + 8.34 µs + 2 STARTs × 10.72 µs = 72.90 µs a script.
    assert_eq!(engine.priority, 5);
    assert_eq!(engine.period, Time::from_us(900));
    assert_eq!(engine.wcet, Time::from_ns(72_900));
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
    let demo_file = root
        .join(scenario::MODELS_DIR)
        .join("thesis-demo.scenario.json");
    let demo = scenario::build(&root, &demo_file, &scenario::timing_files(&root))
        .unwrap_or_else(|e| panic!("{e}"));
    let demo = analyse(
        &demo.model.validate().expect("valid"),
        &Options {
            frame_cost: FrameCostSpec::Exact,
            horizon: None,
        },
    );
    let dwd = demo
        .boards
        .iter()
        .find(|b| b.name == "diwheeldrive")
        .expect("DiWheelDrive in the demo");
    assert!(dwd.tasks.iter().all(|t| !t.name.contains("_engine[")));
    assert!(dwd.sensor_buses.iter().all(|b| b.scripts.is_empty()));
    println!(
        "thesis-demo: DiWheelDrive every task schedulable: {}; utilisation {:.3}",
        dwd.tasks.iter().all(|t| t.schedulable()),
        dwd.utilisation
    );
    let _ = std::fs::remove_dir_all(&root);
}
