//! PowerManagement's `scripted-i2c` trial fed to the analysis (docs/i2c.md, "PowerManagement with
//! `scripted-i2c`"): its two sensor buses, the proximity ring's scripts and the power monitor's (the
//! only reader of the gauges: the power-status sample takes its latest round, no script), stated as
//! a timing file would state them, in a scratch copy of the
//! workspace's timing files (the shipped image does not run them, so the real file does not state
//! them yet). The statements are checked against the scripts the board's jobs put on the wire; the
//! copy lowers into the chip's admission table with the figures stated; and the report of the
//! thesis demo (the ring every 62.5 ms) is printed with the engine charged per script, for the trial as
//! built and for the owner-task design (not built).

use std::path::PathBuf;

mod common;
use common::{copy_dir, repository, wire_counts};

use amiro_firmware::i2c_engine::{deadline_us, events};
use amiro_sensors::drivers::bq27500::StatusRead;
use amiro_sensors::drivers::pca9544a::{self, Channel};
use amiro_sensors::drivers::ring::{RingBus, WIRING};
use amiro_sensors::drivers::scripted::{
    gauge_script, RingRead, ScriptBus, SensorSetUp, GAUGE_SETTLE_US,
};
use amiro_sensors::drivers::vcnl4020::Config;
use amiro_sensors::script::Script;
use amiro_sensors::sim::SimPowerBus;
use schedule_analysis::admission_host;
use schedule_analysis::analysis::{analyse, Options};
use schedule_analysis::model::FrameCostSpec;
use schedule_analysis::scenario;
use serde_json::json;

/// A ring bus's read as the timing file states it: per VCNL4020 the PCA9544A's select (an
/// address, a control byte) and the proximity result's read (write the register, repeated START,
/// read two): 4 × (2 + 5) bytes, 4 × (1 + 2) STARTs, 4 × (4 + 7) events.
const RING_BYTES: u32 = 28;
const RING_STARTS: u32 = 12;
const RING_EVENTS: u32 = 44;
/// A gauge's standard command: write the command, repeated START, read two: 5 bytes, 2 STARTs,
/// 7 events; ten of them a status read.
const GAUGE_BYTES: u32 = 5;
const GAUGE_STARTS: u32 = 2;
const GAUGE_EVENTS: u32 = 7;
const GAUGE_SCRIPTS: usize = 10;
/// A gauge script's deadline: 120 µs on the wire + 7 events × 200 µs (`i2c_engine::deadline_us`).
const GAUGE_DEADLINE_US: u32 = 1_520;
/// The power monitor's job with the trial, its CPU, an estimate: the charger's regulation (its
/// 23.5 µs VSYS conversion) and one gauge script's submission and decoding, two polls (the ring's
/// release of two scripts, three polls, is stated at 320 µs below).
const MONITOR_JOB_US: f64 = 200.0;
/// The CPU of one poll of a release that runs scripts (a script's submission, or its result's
/// decoding and the next script's submission): the first statement's 320 µs for the ring's
/// release of two scripts, three polls, an estimate from the QEMU runs.
const POLL_US: f64 = 320.0 / 3.0;
/// After a script's deadline, until its bus is free again: the watch's response at priority 5 and
/// the bus clear (`i2c::BusClear`: 140 µs of stated waits and its code, about 4 130 cycles at
/// 168 MHz as `i2c::Master::recover`'s bound), µs: an estimate.
const RECOVERY_US: u32 = 300;
const DEADLINE_SOURCE: &str = "i2c_engine::deadline_us (the script's wire time + 200 µs an event: the bus's watch ends it with Failure::Stretched) + 300 µs, the watch's response and the bus clear (an estimate)";

/// The engine's parts on the F405 at 168 MHz, tools/engine-bound's bounds (README.md), µs.
const PER_EVENT_US: f64 = 6.02;
const PER_SCRIPT_US: f64 = 9.11;
const CONDITION_WAIT_US: f64 = 8.93;

/// The bq27500's clock stretching, µs: within a packet addressed to it up to 4 ms, and a wake
/// from SLEEP at the beginning of traffic (5 ms, the family's only stated figure for it).
const GAUGE_STRETCH_US: f64 = 4_000.0;
const GAUGE_WAKE_US: f64 = 5_000.0;
const STRETCH_SOURCE: &str = "TI's bq27xxx data sheets, 'I2C Clock Stretching' (docs/analysis.md, PowerManagement's I2C waits): within a packet addressed to the gauge up to 4 ms; at the beginning of traffic as it wakes from SLEEP 5 ms (the bq27520-G4's figure; the bq27500's SLUS785 states none); the PCA9544A and the VCNL4020 state no stretching";

#[test]
fn the_stated_scripts_are_the_ones_the_jobs_put_on_the_wire() {
    for bus in [RingBus::I2c1, RingBus::I2c2] {
        let channels: Vec<Channel> = WIRING
            .iter()
            .filter(|(on, _)| *on == bus)
            .map(|&(_, channel)| channel)
            .collect();
        let read = RingRead::new(pca9544a::AMIRO_ADDRESS, &channels);
        let script = read.script().expect("a script").expect("it builds");
        assert_eq!(wire_counts(&script), (RING_BYTES, RING_STARTS));
        assert_eq!(events(&script), RING_EVENTS);
        // The analysis's wire time (9 bit times a byte, 2 a START) covers the script's SCL periods.
        assert!(9 * RING_BYTES + 2 * RING_STARTS >= script.scl_periods());
    }
    // A status read's ten standard commands, each a script of its own after the bus-free time.
    let read = StatusRead::new();
    let transfer = read.next_transfer().expect("a first transfer");
    let script = gauge_script(transfer).expect("it builds");
    assert_eq!(wire_counts(&script), (GAUGE_BYTES, GAUGE_STARTS));
    assert_eq!(events(&script), GAUGE_EVENTS);
    assert_eq!(deadline_us(&script), GAUGE_DEADLINE_US);
    assert_eq!(StatusRead::MAX_TRANSFERS, GAUGE_SCRIPTS + 3);
    assert_eq!(GAUGE_SETTLE_US, 66);
    // The HMC5883L's sample (write 1, read 6) raises the 11 events counted on the register model.
    let mut compass = Script::new();
    compass
        .write_read(0x1E, &[0x03], 6)
        .expect("the compass's sample");
    assert_eq!(events(&compass), 11);
}

/// A script of the ring's job as the timing file states it: its bytes, STARTs and events as the
/// script puts them on the wire, the gauge's wake as its stretch (traffic not addressed to the
/// gauge may wake it), and its deadline.
fn ring_job_script(bus: &str, script: &Script, source: &str) -> serde_json::Value {
    let (bytes, starts) = wire_counts(script);
    json!({
        "bus": bus, "bytes": bytes, "starts": starts, "events": events(script),
        "source": source,
        "stretch_us": GAUGE_WAKE_US, "stretch_source": STRETCH_SOURCE,
        "deadline_us": f64::from(deadline_us(script) + RECOVERY_US),
        "deadline_source": DEADLINE_SOURCE
    })
}

/// The ring's release: each bus's worst job ([`worst_ring_job`]), the rear bus's, then the
/// front's.
fn ring_release() -> Vec<serde_json::Value> {
    let mut scripts = Vec::new();
    for (bus, name) in [(RingBus::I2c1, "i2c1"), (RingBus::I2c2, "i2c2")] {
        let job = worst_ring_job(bus);
        let reads = job.len() - 1;
        for (k, script) in job.iter().enumerate() {
            let source = if k < reads {
                "a missing sensor's set-up (SensorSetUp: identity, then each register written and read back)"
            } else {
                "a ring bus's read (RingRead: four VCNL4020 behind the PCA9544A)"
            };
            scripts.push(ring_job_script(name, script, source));
        }
    }
    scripts
}

/// One transfer of a gauge's status read: a script after the bus-free time, which may wake the
/// gauge (its job comes 50 ms after the gauge's last packet).
fn gauge_script_on(bus: &str) -> serde_json::Value {
    json!({
        "bus": bus, "bytes": GAUGE_BYTES, "starts": GAUGE_STARTS, "events": GAUGE_EVENTS,
        "source": "a bq27500 standard command (StatusRead's transfer as gauge_script)",
        "stretch_us": GAUGE_STRETCH_US + GAUGE_WAKE_US,
        "stretch_source": STRETCH_SOURCE,
        "deadline_us": f64::from(GAUGE_DEADLINE_US + RECOVERY_US),
        "deadline_source": DEADLINE_SOURCE,
        "settle_us": f64::from(GAUGE_SETTLE_US),
        "settle_source": "the bq27500's 66 µs of bus-free time between packets (bq27500::BUS_FREE_NS)"
    })
}

/// The power monitor's job: one transfer of its round (`sensors::scripted::BatteryRound`), on the
/// front bus (I2C2) or the rear (I2C1), the round alternating. The file states a script on each
/// bus: each bus then sees at most one of the monitor's scripts a period, as it does, and the
/// monitor's own job is charged both (one in fact: pessimistic, the file cannot say "either").
fn monitor_job() -> serde_json::Value {
    json!([gauge_script_on("i2c2"), gauge_script_on("i2c1")])
}

/// The workspace's apps and timing files, PowerManagement's file stating the trial's buses and
/// scripts (its app read with `scripted-i2c`: the re-arm tasks are in it).
fn scripted_workspace(test: &str) -> PathBuf {
    scripted_workspace_as(test, Design::Trial)
}

/// Which statement of the trial the scratch copy makes.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Design {
    /// The trial as built: the ring's publisher runs each bus's worst job, the power monitor one
    /// gauge transfer every 50 ms.
    Trial,
    /// The owner task the review planned (not built): `power_monitor` every 62.5 ms runs both
    /// buses' worst ring jobs and one gauge transfer a bus; the ring's publisher and the power
    /// status publish its latest readings, no script.
    Owner,
    /// As `Owner`, without the set-up scripts (the review's model, unsound: for comparison).
    OwnerReadOnly,
    /// As `Owner`, a sensor's set-up spread over the owner's jobs, one of its scripts a job (as
    /// DiWheelDrive's stepwise set-up, not built for PowerManagement): per bus the longest set-up
    /// script, the read and the gauge transfer.
    OwnerStepwise,
    /// As `Owner`, the gauge's wake charged once a bus and job (its first script) instead of on
    /// every script: a figure for the decision, not a stated fact.
    OwnerWakeOnce,
}

/// The owner's period (µs).
const OWNER_PERIOD_US: u32 = 62_500;

fn scripted_workspace_as(test: &str, design: Design) -> PathBuf {
    let real = repository();
    let root = std::env::temp_dir().join(format!(
        "pm-scripted-analysis-{}-{test}",
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&root);
    std::fs::create_dir_all(&root).unwrap();
    for board in ["diwheeldrive", "powermgmt", "lightring"] {
        std::os::unix::fs::symlink(real.join(board), root.join(board)).unwrap();
    }
    let models = root.join(scenario::MODELS_DIR);
    copy_dir(&real.join(scenario::MODELS_DIR), &models);
    let file = models.join("powermgmt.timing.json");
    let mut timing: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&file).unwrap()).unwrap();
    assert_eq!(timing["app"]["features"], json!([]));
    timing["app"]["features"] = json!(["scripted-i2c"]);
    let engine = json!({
        "priority": 5,
        "per_event_us": PER_EVENT_US, "per_event_from": "bound",
        "source": "tools/engine-bound: I2Cx_EV without Inner::end, settle and wake, F405",
        "per_script": { "us": PER_SCRIPT_US, "from": "bound", "source": "tools/engine-bound: Inner::end + wake, F405" },
        "condition_wait": { "us": CONDITION_WAIT_US, "from": "bound", "source": "tools/engine-bound: I2cBus::settle, its code and the stated wait (i2c_engine::CONDITION_WAIT_NS), F405" }
    });
    timing["sensor_buses"] = json!([
        { "name": "i2c1", "bitrate": 400000, "engine": engine },
        { "name": "i2c2", "bitrate": 400000, "engine": engine },
    ]);
    // The CPU of a release, its polls together: estimates from the QEMU runs (the largest
    // publisher job 11 701 instructions, about 105 µs at 1.5 cycles an instruction; a release of k
    // scripts is k + 1 polls, most of them a script's submission and decoding).
    // The ring: the rear bus's read, then the front's; no bus lock held across either.
    let ring = &mut timing["topics"]["proximity-ring"];
    let release = ring_release();
    ring["wcet_us"] = json!(POLL_US * (release.len() + 1) as f64);
    ring["bcet_us"] = json!(100.0);
    ring["scripts"] = json!(release);
    ring["critical_sections_us"]["rear_bus"] = json!(20.0);
    ring["critical_sections_us"]["front_bus"] = json!(20.0);
    // Power status: the power monitor's latest round and the charge lines, no script: the timing
    // file's own statement (CPU only) stands.
    assert!(timing["topics"]["power-status"].get("scripts").is_none());
    assert!(timing["topics"]["power-status"]["critical_sections_us"]
        .get("rear_bus")
        .is_none());
    let monitor = &mut timing["tasks"]["power_monitor"];
    monitor["wcet_us"] = json!(MONITOR_JOB_US);
    monitor["scripts"] = monitor_job();
    monitor["critical_sections_us"]["rear_bus"] = json!(20.0);
    monitor["critical_sections_us"]["front_bus"] = json!(20.0);
    if design != Design::Trial {
        // Each bus: its worst ring job, then one gauge transfer; the rear bus, then the front.
        let release = ring_release();
        let (rear, front) = release.split_at(release.len() / 2);
        let per_bus = |job: &[serde_json::Value], gauge: serde_json::Value| {
            let mut job = job.to_vec();
            if design == Design::OwnerReadOnly {
                job.drain(..job.len() - 1);
            }
            if design == Design::OwnerStepwise {
                // The set-up's second script is its longest (a register written and read back).
                job.drain(..1);
                job.drain(1..job.len() - 1);
            }
            job.push(gauge);
            if design == Design::OwnerWakeOnce {
                for later in job.iter_mut().skip(1) {
                    let wake = if later.get("settle_us").is_some() {
                        GAUGE_STRETCH_US
                    } else {
                        0.0
                    };
                    later["stretch_us"] = json!(wake);
                }
            }
            job
        };
        let mut scripts = per_bus(rear, gauge_script_on("i2c1"));
        scripts.extend(per_bus(front, gauge_script_on("i2c2")));
        monitor["wcet_us"] = json!(MONITOR_JOB_US + POLL_US * (scripts.len() + 1) as f64);
        monitor["scripts"] = json!(scripts);
        monitor["arrival"] = json!({ "periodic_us": OWNER_PERIOD_US });
        // The ring's publisher takes the owner's latest counts under each bus's lock: eight
        // frames encoded and pushed, as the power status's sample (64.4 µs bounded) with its
        // eight frames: an estimate.
        let ring = &mut timing["topics"]["proximity-ring"];
        ring.as_object_mut().unwrap().remove("scripts");
        ring["wcet_us"] = json!(150.0);
        ring["bcet_us"] = json!(50.0);
        ring["critical_sections_us"]["rear_bus"] = json!(2.0);
        ring["critical_sections_us"]["front_bus"] = json!(2.0);
    }
    for task in ["rearm_rear", "rearm_front"] {
        timing["tasks"][task] = json!({
            "wcet_us": 5.0, "bcet_us": 1.0,
            "arrival": { "sporadic_us": 250 },
            "released_by": "timer",
            "note": "A look at a stalled repeated START (I2cBus::rearm, 127 cycles, tools/engine-bound) and the monotonic's wait around it, at most one per STRETCH_REARM_US = 250 µs: an estimate"
        });
    }
    std::fs::write(&file, timing.to_string()).unwrap();
    // The shipped image's bound of `power_monitor` (a transfer's flags polled) is not the trial's
    // job (its transfer a script the engine carries): declined in the copy, so the statement
    // above is the budget, as the held publisher rows' are.
    let wcet = models.join("powermgmt.wcet.json");
    let mut bounds: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&wcet).unwrap()).unwrap();
    let monitor = bounds["tasks"]
        .as_array_mut()
        .unwrap()
        .iter_mut()
        .find(|t| t["task"] == "power_monitor")
        .expect("power_monitor's bound");
    for field in ["cycles", "us", "instructions"] {
        monitor[field] = serde_json::Value::Null;
    }
    monitor["declined"] =
        json!("the shipped image's polled transfer, not the scripted-i2c trial's job");
    monitor.as_object_mut().unwrap().remove("sections");
    std::fs::write(&wcet, bounds.to_string()).unwrap();
    root
}

/// The ring's worst job on one bus (`sensors::scripted::sample_ring`): a missing sensor whose retry
/// passed set up first (at most one a job and bus: `SensorSetUp`'s six scripts, its identity and
/// each set-up register written and read back), then the read of the sensors that answer (one
/// script, every sensor answering).
fn worst_ring_job(bus: RingBus) -> Vec<Script> {
    let channels: Vec<Channel> = WIRING
        .iter()
        .filter(|(on, _)| *on == bus)
        .map(|&(_, channel)| channel)
        .collect();
    let mut sim = SimPowerBus::new(0, true);
    let mut set_up = SensorSetUp::new(pca9544a::AMIRO_ADDRESS, channels[0], Config::AMIRO);
    let mut scripts = Vec::new();
    loop {
        let script = set_up.script().expect("it builds");
        scripts.push(script);
        if let Some(done) = set_up.complete(&sim.run(&script)) {
            assert!(done.is_ok(), "the simulated sensor sets up");
            break;
        }
    }
    let read = RingRead::new(pca9544a::AMIRO_ADDRESS, &channels);
    scripts.push(read.script().expect("a script").expect("it builds"));
    scripts
}

/// The soundness gap of the trial's first statement (2026-12-05): the ring's release was stated as
/// one read a bus, but a release may first set up a missing sensor on each bus. Each bus's scripts
/// in the copy are the worst job's, in order, with the bytes, STARTs and events the scripts put on
/// the wire and the engine serves.
#[test]
fn the_ring_job_states_its_set_up_scripts() {
    let root = scripted_workspace("ring-job");
    let robot = admission_host::lower_robot(&root).unwrap_or_else(|e| panic!("{e}"));
    let pm = robot
        .boards
        .iter()
        .find(|b| b.name == "powermgmt")
        .expect("PowerManagement");
    let ring = pm
        .topics
        .iter()
        .find(|t| t.name == "proximity-ring")
        .expect("the ring")
        .scripts
        .clone();
    let mut stated = ring.iter();
    for (index, bus) in [RingBus::I2c1, RingBus::I2c2].into_iter().enumerate() {
        let job = worst_ring_job(bus);
        assert_eq!(job.len(), 7, "six set-up scripts and the read");
        for script in &job {
            let lowered = stated
                .next()
                .expect("a stated script for each of the job's");
            assert_eq!(usize::from(lowered.bus), index);
            assert_eq!(u32::from(lowered.events), events(script));
            let (bytes, starts) = wire_counts(script);
            assert_eq!(u32::from(lowered.starts), starts);
            // The wire as the analysis counts it (9 bit times a byte, 2 a START, 2.5 µs each)
            // covers the script's SCL periods; the rest of the bus time is the charged stretch.
            let wire_ns = u64::from(9 * bytes + 2 * starts) * 2_500;
            assert!(wire_ns >= script.bus_time_ns(400_000));
            assert!(u64::from(lowered.bus_time) >= wire_ns);
        }
    }
    assert!(stated.next().is_none());
    let _ = std::fs::remove_dir_all(&root);
}

#[test]
fn the_trial_lowers_into_the_admission_table_and_the_report_charges_its_engine() {
    let root = scripted_workspace("report");
    let robot = admission_host::lower_robot(&root).unwrap_or_else(|e| panic!("{e}"));
    let pm = robot
        .boards
        .iter()
        .find(|b| b.name == "powermgmt")
        .expect("PowerManagement");
    assert_eq!(pm.buses.len(), 2);
    for bus in &pm.buses {
        assert_eq!(
            (bus.engine_priority, bus.per_script, bus.condition_wait),
            (5, 9_110, 8_930)
        );
    }
    let topic = |name: &str| {
        pm.topics
            .iter()
            .find(|t| t.name == name)
            .unwrap_or_else(|| panic!("{name}"))
            .scripts
            .clone()
    };
    // Per bus a set-up's six scripts, then the read. The read: 28 bytes and 12 STARTs at 400 kHz,
    // (9 × 28 + 2 × 12) × 2.5 µs = 690 µs, and a gauge's wake (5 ms): 5 690 µs, below its deadline
    // (680 + 44 × 200 + 300 = 9 780 µs). A set-up script's stretch is capped by its deadline: the
    // identity (6 bytes, 3 STARTs, 11 events) 148 + 11 × 200 + 300 = 2 648 µs, each register
    // written and read back (9 bytes, 4 STARTs, 16 events) 220 + 16 × 200 + 300 = 3 720 µs.
    let ring = topic("proximity-ring");
    assert_eq!(ring.len(), 14);
    assert_eq!(
        (
            ring[6].bus,
            ring[6].bus_time,
            ring[6].events,
            ring[6].starts
        ),
        (0, 5_690_000, 44, 12)
    );
    assert_eq!((ring[0].bus_time, ring[0].events), (2_648_000, 11));
    assert_eq!((ring[1].bus_time, ring[1].events), (3_720_000, 16));
    assert_eq!(ring[13].bus, 1);
    // The power-status sample runs no script: the gauges are the power monitor's alone.
    assert!(topic("power-status").is_empty());
    let monitor = pm
        .task_names
        .iter()
        .position(|n| n == "power_monitor")
        .expect("power_monitor");
    let scripts = pm
        .task_scripts
        .iter()
        .find(|(task, _)| usize::from(*task) == monitor)
        .map(|(_, s)| s.clone())
        .expect("power_monitor's scripts");
    // 5 bytes and 2 STARTs: (45 + 4) × 2.5 µs = 122.5 µs, the stretch and the wake (9 ms)
    // capped by its deadline: 120 + 7 × 200 + 300 = 1 820 µs; 66 µs before each; one on each bus.
    assert_eq!(scripts.len(), 2);
    assert_eq!(
        (
            scripts[0].bus,
            scripts[0].bus_time,
            scripts[0].events,
            scripts[0].settle
        ),
        (1, 1_820_000, 7, 66_000)
    );
    assert_eq!((scripts[1].bus_time, scripts[1].bus), (1_820_000, 0));

    // The thesis demo's report with the trial's statements: printed (docs/i2c.md).
    let scenario_file = root
        .join(scenario::MODELS_DIR)
        .join("thesis-demo.scenario.json");
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
        .find(|b| b.name == "powermgmt")
        .expect("PowerManagement in the report");
    let engine = board
        .tasks
        .iter()
        .find(|t| t.name.starts_with("i2c1_engine["))
        .unwrap_or_else(|| {
            panic!(
                "no engine row: {:?}",
                board.tasks.iter().map(|t| &t.name).collect::<Vec<_>>()
            )
        });
    assert_eq!(engine.priority, 5);
    println!("utilisation {:.3}", board.utilisation);
    for task in board.tasks.iter().filter(|t| !t.name.contains("_engine[")) {
        println!("{}: wcet {:?} {:?}", task.name, task.wcet, task.bound);
    }
    for bus in &board.sensor_buses {
        println!(
            "{}: event response {:?}, utilisation {:.3}",
            bus.name, bus.event_response, bus.utilisation
        );
        for s in bus
            .scripts
            .iter()
            .filter(|s| !s.task.contains('#') || s.task.ends_with("#1"))
        {
            println!(
                "  {}: wire {:?} events {} bus time {:?} blocking {:?} suspension {:?} {:?}",
                s.task, s.wire, s.events, s.bus_time, s.blocking, s.suspension, s.bound
            );
        }
    }
    let _ = std::fs::remove_dir_all(&root);
}

/// The owner-task design, stated in the copy (not built): the verdict of the thesis demo with it
/// (docs/i2c.md, "The owner task: the analysis's verdict"), printed.
#[test]
fn the_owner_design_on_the_thesis_demo() {
    for (name, design) in [
        ("owner", Design::Owner),
        ("owner-read-only", Design::OwnerReadOnly),
        ("owner-stepwise", Design::OwnerStepwise),
        ("owner-wake-once", Design::OwnerWakeOnce),
    ] {
        owner_verdict(name, design);
    }
}

fn owner_verdict(name: &str, design: Design) {
    let root = scripted_workspace_as(name, design);
    let scenario_file = root
        .join(scenario::MODELS_DIR)
        .join("thesis-demo.scenario.json");
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
        .find(|b| b.name == "powermgmt")
        .expect("PowerManagement in the report");
    println!("{name}: utilisation {:.3}", board.utilisation);
    for task in board.tasks.iter().filter(|t| {
        [
            "power_monitor",
            "publish_medium[proximity-ring]",
            "publish_low[power-status]",
            "handle_commands",
        ]
        .contains(&t.name.as_str())
    }) {
        println!(
            "{name}: {}: wcet {:?} jitter {:?} {:?}",
            task.name, task.wcet, task.jitter, task.bound
        );
    }
    for bus in &board.sensor_buses {
        let suspension: u64 = bus
            .scripts
            .iter()
            .map(|s| s.suspension.unwrap_or(s.bus_time).as_ns())
            .sum();
        println!(
            "{name}: {}: event response {:?}, utilisation {:.3}, scripts {}, their suspensions {} ns",
            bus.name,
            bus.event_response,
            bus.utilisation,
            bus.scripts.len(),
            suspension
        );
    }
    for topic in analysis.topics.iter().filter(|t| {
        t.sender
            .as_deref()
            .is_some_and(|s| s.starts_with("powermgmt"))
    }) {
        println!("{name}: topic {topic:?}");
    }
    let _ = std::fs::remove_dir_all(&root);
}
