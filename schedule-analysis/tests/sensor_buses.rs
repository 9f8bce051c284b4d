//! The sensor buses in the model and timing files: what is accepted (a script's engine row, its figures, the
//! report's section and the topic's end-to-end figure), what is refused with which typed error, and that a file
//! without scripts is analysed as before.

use schedule_analysis::analysis::{self, Options};
use schedule_analysis::board::{self, TaskTiming};
use schedule_analysis::busy_window::{Counter, Limits};
use schedule_analysis::model::{BoardModel, FrameCostSpec, Model, OverheadTimes};
use schedule_analysis::report::{self, Format, Report};
use schedule_analysis::scenario;
use schedule_analysis::sensor_bus::{self, SensorBusError};
use schedule_analysis::time::Time;
use serde_json::json;

mod common;
mod sim;

/// A board with a publisher job that runs a 6-byte script (one START) on `i2c1` at 400 kHz, a lower task, and
/// the engine at priority 7 with 2 µs per event (1 µs entry and exit).
fn board_json() -> serde_json::Value {
    json!({
        "name": "b",
        "overheads": { "isr_entry_us": 0.5, "isr_exit_us": 0.5 },
        "sensor_buses": [{
            "name": "i2c1", "bitrate": 400000,
            "engine": { "priority": 7, "per_event_us": 2.0, "per_event_from": "estimate",
                        "source": "a guess until the machine code bounds the handler" }
        }],
        "tasks": [
            { "name": "publish[floor]", "priority": 3, "wcet_us": 50.0, "period_us": 10000.0,
              "job_of": "publish",
              "script": { "bus": "i2c1", "bytes": 6, "source": "address + register, address + 4 data bytes",
                          "stretch_us": 10.0, "stretch_source": "the device's datasheet" } },
            { "name": "background", "priority": 1, "wcet_us": 100.0, "period_us": 1000.0 }
        ]
    })
}

fn board(value: serde_json::Value) -> BoardModel {
    serde_json::from_value(value).expect("a board")
}

/// The script: 9 × 6 + 2 = 56 bit times of 2.5 µs = 140 µs on the wire, 2 × 6 + 2 = 14 events; its engine row
/// costs 14 × (2 + 1) = 42 µs. An event's response at priority 7 (nothing above, nothing blocking): 3 µs, so the
/// bus time is 140 + 10 + 14 × 3 = 192 µs, alone on the bus: the suspension. The job: 50 + 192 + the engine's
/// 42 µs (its row, released by the job, above it) = 284 µs.
#[test]
fn a_script_adds_its_engine_row_and_its_suspension() {
    let model = Model {
        name: None,
        boards: vec![board(board_json())],
        can: None,
    };
    let system = model.validate().expect("valid");
    let b = &system.boards[0];
    assert_eq!(b.tasks.len(), 3);
    let row = &b.tasks[2];
    assert_eq!(row.name, "i2c1_engine[publish[floor]]");
    assert_eq!((row.priority, row.wcet), (7, Time::from_us(42)));
    assert_eq!(row.released_by, Some(0));
    let script = &b.sensor_buses.scripts[0];
    assert_eq!(
        (script.wire, script.events, script.stretch),
        (Time::from_us(140), 14, Time::from_us(10))
    );

    let result = analysis::analyse_board(b, &Limits::default());
    let bus = &result.sensor_buses[0];
    assert_eq!(bus.event_response, Some(Time::from_us(3)));
    assert_eq!(bus.scripts[0].bus_time, Time::from_us(192));
    assert_eq!(bus.scripts[0].suspension, Some(Time::from_us(192)));
    assert_eq!(result.tasks[0].wcrt(), Some(Time::from_us(284)));
    // The engine row inherits the job's whole response as its jitter.
    assert_eq!(result.tasks[2].jitter, Time::from_us(284));
    // The lower task sees the job's 50 µs with jitter 284 − 50 and the engine's 42 µs with jitter 284:
    // R = 100 + ⌈(R + 234)/10000⌉·50 + ⌈(R + 284)/10000⌉·42 = 192.
    assert_eq!(result.tasks[1].wcrt(), Some(Time::from_us(192)));

    let analysis = analysis::analyse(
        &system,
        &Options {
            frame_cost: FrameCostSpec::Exact,
            horizon: None,
        },
    );
    let report = Report::build(&system, "t".into(), Vec::new(), Vec::new(), None);
    let text = report::render(&report, Format::Table);
    assert!(text.contains("Sensor bus i2c1 — 400 kbit/s"), "{text}");
    assert!(text.contains("estimate: a guess until"), "{text}");
    assert_eq!(analysis.boards[0].sensor_buses, result.sensor_buses);
    let json = report::render(&report, Format::Json);
    assert!(json.contains("\"per_event_from\": \"estimate\""), "{json}");
}

fn refusal(value: serde_json::Value) -> (String, SensorBusError) {
    let b = board(value);
    sensor_bus::validate_board(&b, &OverheadTimes::default(), &mut Vec::new()).expect_err("refused")
}

#[test]
fn refusals_are_typed_and_name_the_field() {
    let mut v = board_json();
    v["tasks"][0]["script"]["bus"] = json!("i2c9");
    assert_eq!(
        refusal(v),
        (
            "tasks[0].script.bus".into(),
            SensorBusError::UnknownBus("i2c9".into())
        )
    );
    let mut v = board_json();
    v["sensor_buses"][0]["engine"]["per_event_us"] = json!(0.0);
    assert_eq!(
        refusal(v),
        (
            "sensor_buses[0].engine.per_event_us".into(),
            SensorBusError::NotPositive("0".into())
        )
    );
    let mut v = board_json();
    v["sensor_buses"][0]["bitrate"] = json!(0);
    assert_eq!(refusal(v).0, "sensor_buses[0].bitrate");
    let mut v = board_json();
    v["tasks"][0]["script"]["bytes"] = json!(0);
    assert_eq!(
        refusal(v),
        (
            "tasks[0].script.bytes".into(),
            SensorBusError::NotPositive("0".into())
        )
    );
    let mut v = board_json();
    v["tasks"][0]["script"]["bus_time_us"] = json!(-3.0);
    assert_eq!(
        refusal(v),
        ("tasks[0].script".into(), SensorBusError::OneFigure)
    );
    let mut v = board_json();
    v["tasks"][0]["script"]["stretch_us"] = json!(-1.0);
    assert_eq!(
        refusal(v),
        (
            "tasks[0].script.stretch_us".into(),
            SensorBusError::Negative("-1".into())
        )
    );
    let mut v = board_json();
    v["tasks"][0]["script"]["stretch_source"] = json!(" ");
    assert_eq!(refusal(v).1, SensorBusError::NoSource);
    let mut v = board_json();
    v["tasks"][0]["script"]
        .as_object_mut()
        .unwrap()
        .remove("bytes");
    v["tasks"][0]["script"]["bus_time_us"] = json!(120.0);
    assert_eq!(
        refusal(v),
        ("tasks[0].script.events".into(), SensorBusError::NoEvents)
    );
    let mut v = board_json();
    v["sensor_buses"][0]["engine"]["per_event_from"] = json!("guess");
    assert!(serde_json::from_value::<BoardModel>(v).is_err());
    // An unknown field, in the model file as in a timing file.
    let mut v = board_json();
    v["tasks"][0]["script"]["speed"] = json!(1);
    let text = json!({ "boards": [v] }).to_string();
    let error = Model::from_json(&text).expect_err("unknown field");
    assert!(error.path.contains("script"), "{error}");
    assert!(error.problem.contains("unknown field `speed`"), "{error}");
    // And the model's error names the board.
    let mut v = board_json();
    v["tasks"][0]["script"]["bus"] = json!("i2c9");
    let model = Model {
        name: None,
        boards: vec![board(v)],
        can: None,
    };
    let error = model.validate().expect_err("unknown bus");
    assert_eq!(error.path, "boards[0].tasks[0].script.bus");
}

/// A model whose suspending job cannot be bounded on the bus says why, for it and for what it interferes with.
#[test]
fn an_overloaded_bus_leaves_its_jobs_unbounded_with_the_reason() {
    let mut v = board_json();
    // 60 000 bytes at 400 kHz: 1.35 s of bus time every 10 ms.
    v["tasks"][0]["script"]["bytes"] = json!(60_000);
    let model = Model {
        name: None,
        boards: vec![board(v)],
        can: None,
    };
    let system = model.validate().expect("valid");
    let result = analysis::analyse_board(&system.boards[0], &Limits::default());
    let why = result.tasks[0].bound.as_ref().expect_err("unbounded");
    assert!(why.to_string().contains("its script on `i2c1`"), "{why}");
    assert!(result.tasks[1].wcrt().is_none());
    assert!(result.tasks[2].wcrt().is_none(), "released by it");
    assert!(result.sensor_buses[0].scripts[0].bound.is_err());
}

/// The timing file's form: DiWheelDrive's floor-proximity topic with a script on a stated bus, published at
/// medium. The job gets the script, the analysis its engine row, and the topic's end to end grows by at least the
/// suspension; the on-chip admission table carries the script; a script on a
/// bus the timing file does not state is refused naming the timing file's field.
#[test]
fn a_timing_file_topic_states_its_script() {
    let root = common::scratch_workspace("sensor-buses", None);
    let models = root.join(scenario::MODELS_DIR);
    let scenario_path = models.join("floor.scenario.json");
    std::fs::write(
        &scenario_path,
        json!({
            "name": "floor",
            "publishers": [{ "topic": "floor-proximity", "priority": "medium", "period_us": 100000 }]
        })
        .to_string(),
    )
    .unwrap();
    let analyse = |root: &std::path::Path| {
        let built = scenario::build(root, &scenario_path, &scenario::timing_files(root))?;
        let system = built.model.validate().expect("valid");
        Ok::<_, scenario::BuildError>(analysis::analyse(
            &system,
            &Options {
                frame_cost: FrameCostSpec::Exact,
                horizon: None,
            },
        ))
    };
    let before = analyse(&root).expect("builds");

    let timing_path = models.join("diwheeldrive.timing.json");
    let original: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&timing_path).unwrap()).unwrap();
    let mut timing = original.clone();
    timing["sensor_buses"] = json!([{
        "name": "i2c2", "bitrate": 400000,
        "engine": { "priority": 7, "per_event_us": 3.0, "per_event_from": "estimate", "source": "test" }
    }]);
    timing["topics"]["floor-proximity"]["script"] = json!({
        "bus": "i2c2", "bytes": 28, "starts": 8, "source": "four channel selects and four reads",
        "stretch_us": 0.0, "stretch_source": "the PCA9544A and VCNL4020 do not stretch (test)"
    });
    std::fs::write(&timing_path, timing.to_string()).unwrap();
    let after = analyse(&root).expect("builds");
    let dwd = after
        .boards
        .iter()
        .find(|b| b.name == "diwheeldrive")
        .unwrap();
    assert!(dwd
        .tasks
        .iter()
        .any(|t| t.name == "i2c2_engine[publish_medium[floor-proximity]]"));
    let suspension = dwd.sensor_buses[0].scripts[0].suspension.expect("bounded");
    // 9 × 28 + 2 × 8 = 268 bit times of 2.5 µs on the wire, and 72 events' responses.
    assert!(suspension >= Time::from_us(670), "{suspension}");
    let worst = |a: &analysis::Analysis| {
        a.topics
            .iter()
            .find(|t| t.name == "floor-proximity")
            .and_then(|t| t.worst)
            .expect("bounded")
    };
    assert!(
        worst(&after) >= worst(&before).plus(suspension),
        "{} {} {}",
        worst(&after),
        worst(&before),
        suspension
    );

    // The on-chip admission table carries the script: its bus and the topic's row (tests/admission_scripts.rs
    // decides with it as the report does). 268 bit times of 2.5 µs on the wire; 2 × 28 + 2 × 8 events.
    let lowered = schedule_analysis::admission_host::lower_robot(&root).expect("lowers");
    let dwd_table = lowered
        .boards
        .iter()
        .find(|b| b.name == "diwheeldrive")
        .expect("diwheeldrive");
    assert_eq!(dwd_table.buses.len(), 1);
    let floor = dwd_table
        .topics
        .iter()
        .find(|t| t.name == "floor-proximity")
        .expect("floor");
    assert_eq!(
        floor.scripts,
        [schedule_analysis::admission::ScriptRow {
            bus: 0,
            bus_time: 670_000,
            events: 72,
            starts: 8,
            settle: 0
        }]
    );

    timing["topics"]["floor-proximity"]["script"]["bus"] = json!("i2c1");
    std::fs::write(&timing_path, timing.to_string()).unwrap();
    let error = analyse(&root).expect_err("refused");
    assert_eq!(error.path, "topics.floor-proximity.script.bus");
    assert!(error.file.ends_with("diwheeldrive.timing.json"), "{error}");
    assert!(error.problem.contains("no sensor bus `i2c1`"), "{error}");

    // The engine's parts as the timing file states them: a part without its source, a negative wait.
    timing["topics"]["floor-proximity"]["script"]["bus"] = json!("i2c2");
    timing["sensor_buses"][0]["engine"]["per_script"] =
        json!({ "us": 12.74, "from": "bound", "source": "" });
    std::fs::write(&timing_path, timing.to_string()).unwrap();
    let error = analyse(&root).expect_err("refused");
    assert_eq!(error.path, "sensor_buses[0].engine.per_script.source");
    assert!(error.file.ends_with("diwheeldrive.timing.json"), "{error}");
    timing["sensor_buses"][0]["engine"]["per_script"]["source"] = json!("tools/engine-bound");
    timing["sensor_buses"][0]["engine"]["condition_wait"] =
        json!({ "us": -5.6, "from": "estimate", "source": "CONDITION_WAIT_NS" });
    std::fs::write(&timing_path, timing.to_string()).unwrap();
    let error = analyse(&root).expect_err("refused");
    assert_eq!(error.path, "sensor_buses[0].engine.condition_wait.us");
    assert!(error.problem.contains("≥ 0, got -5.6"), "{error}");
    // Stated right, the parts are taken: the engine row grows by 12.74 µs per script and 8 STARTs × 5.6 µs.
    timing["sensor_buses"][0]["engine"]["condition_wait"]["us"] = json!(5.6);
    std::fs::write(&timing_path, timing.to_string()).unwrap();
    let parts = analyse(&root).expect("builds");
    let row = |a: &analysis::Analysis| {
        a.boards
            .iter()
            .find(|b| b.name == "diwheeldrive")
            .and_then(|b| {
                b.tasks
                    .iter()
                    .find(|t| t.name == "i2c2_engine[publish_medium[floor-proximity]]")
            })
            .map(|t| t.wcet)
            .expect("the engine row")
    };
    assert_eq!(
        row(&parts),
        row(&after).plus(Time::from_ns(12_740 + 8 * 5_600))
    );
    let _ = std::fs::remove_dir_all(&root);
}

/// The sensitivity search moves a script's engine row with its job: the row runs once per sample.
#[test]
fn the_engine_row_moves_with_its_publisher() {
    let text = json!({
        "boards": [board_json()],
        "can": { "messages": [ { "name": "floor", "id": 1544, "dlc": 8, "period_us": 10000,
                                 "sender": "b/publish[floor]" } ] }
    })
    .to_string();
    let system = Model::from_json(&text).unwrap().validate().unwrap();
    let publishers = schedule_analysis::sensitivity::publishers(&system);
    let tasks: Vec<usize> = publishers[0].tasks.iter().map(|t| t.task).collect();
    assert_eq!(tasks, vec![0, 2]);
    let moved =
        schedule_analysis::sensitivity::with_period(&system, &publishers[0], Time::from_us(5000));
    assert_eq!(moved.boards[0].tasks[2].period, Time::from_us(5000));
}

/// A job of several scripts (`scripts`, in order): one engine row per script, `<bus>_engine[<task>#<n>]`, each at
/// its bus's engine priority and costing that script's events, released by the job; each script's settle is kept.
#[test]
fn a_job_of_several_scripts_has_an_engine_row_per_script() {
    let mut v = board_json();
    v["sensor_buses"].as_array_mut().unwrap().push(json!({
        "name": "i2c2", "bitrate": 100000,
        "engine": { "priority": 6, "per_event_us": 1.0, "per_event_from": "bound", "source": "a test figure" }
    }));
    let script = v["tasks"][0]["script"].take();
    v["tasks"][0].as_object_mut().unwrap().remove("script");
    let mut second = json!({ "bus": "i2c2", "bus_time_us": 300.0, "events": 4, "source": "a test figure",
                             "stretch_us": 0.0, "stretch_source": "never stretches",
                             "settle_us": 66.0, "settle_source": "the bq27500's bus-free time" });
    v["tasks"][0]["scripts"] = json!([script.clone(), second.clone()]);
    let model = Model {
        name: None,
        boards: vec![board(v.clone())],
        can: None,
    };
    let system = model.validate().expect("valid");
    let b = &system.boards[0];
    let rows: Vec<(&str, u32, Time)> = b.tasks[2..]
        .iter()
        .map(|t| (t.name.as_str(), t.priority, t.wcet))
        .collect();
    assert_eq!(
        rows,
        vec![
            ("i2c1_engine[publish[floor]#1]", 7, Time::from_us(42)),
            ("i2c2_engine[publish[floor]#2]", 6, Time::from_us(8)),
        ]
    );
    let s = &b.sensor_buses.scripts;
    assert_eq!(
        s.iter()
            .map(|s| (s.bus, s.position, s.of, s.settle))
            .collect::<Vec<_>>(),
        vec![(0, 0, 2, Time::ZERO), (1, 1, 2, Time::from_us(66))]
    );
    // An i2c2 event (2 µs at priority 6) may wait for i2c1's engine row (42 µs at 7): its response 44 µs, so each
    // event's own response gives the second script 300 + 4 × 44 = 476 µs on the bus; as one job at priority 6 it
    // meets that row once (one instance per 10 ms): 300 + 4 × 2 + 42 = 350 µs, the bound taken. i2c1's events
    // still answer in 3 µs (192 µs as above). The job: 50 + 192 + 350 + its settle 66 + both engine rows (42 + 8,
    // released by the job, above it) = 708 µs.
    let result = analysis::analyse_board(b, &Limits::default());
    assert_eq!(
        result.sensor_buses[1].event_response,
        Some(Time::from_us(44))
    );
    assert_eq!(
        result.sensor_buses[1].scripts[0].bus_time,
        Time::from_us(350)
    );
    assert_eq!(result.tasks[0].wcrt(), Some(Time::from_us(708)));
    assert_eq!(result.sensor_buses[1].scripts[0].task, "publish[floor]#2");
    assert_eq!(result.sensor_buses[1].scripts[0].settle, Time::from_us(66));
    let report = Report::build(&system, "t".into(), Vec::new(), Vec::new(), None);
    let json = report::render(&report, Format::Json);
    assert!(json.contains("\"settle_us\": 66.0"), "{json}");
    let text = report::render(&report, Format::Table);
    assert!(text.contains("settle µs"), "{text}");

    // The form's refusals, each naming its field.
    let mut both = v.clone();
    both["tasks"][0]["script"] = script.clone();
    assert_eq!(
        refusal(both),
        ("tasks[0]".into(), SensorBusError::ScriptAndScripts)
    );
    let mut empty = v.clone();
    empty["tasks"][0]["scripts"] = json!([]);
    assert_eq!(
        refusal(empty),
        ("tasks[0].scripts".into(), SensorBusError::NoScripts)
    );
    let mut alone = v.clone();
    alone["tasks"][0]["scripts"][1]
        .as_object_mut()
        .unwrap()
        .remove("settle_us");
    assert_eq!(
        refusal(alone),
        (
            "tasks[0].scripts[1].settle_source".into(),
            SensorBusError::SettleSourceAlone
        )
    );
    let mut unsourced = v.clone();
    unsourced["tasks"][0]["scripts"][1]
        .as_object_mut()
        .unwrap()
        .remove("settle_source");
    assert_eq!(
        refusal(unsourced),
        (
            "tasks[0].scripts[1].settle_source".into(),
            SensorBusError::NoSource
        )
    );
    second["settle_us"] = json!(-1.0);
    let mut negative = v.clone();
    negative["tasks"][0]["scripts"][1] = second;
    assert_eq!(
        refusal(negative),
        (
            "tasks[0].scripts[1].settle_us".into(),
            SensorBusError::Negative("-1".into())
        )
    );
    let mut unknown = v;
    unknown["tasks"][0]["scripts"][0]["bus"] = json!("i2c3");
    assert_eq!(
        refusal(unknown),
        (
            "tasks[0].scripts[0].bus".into(),
            SensorBusError::UnknownBus("i2c3".into())
        )
    );
}

/// The timing file's form: a topic's `scripts` on two buses gives its publisher job one engine row per script, a
/// fixed task's `script` its own row;
/// a refusal names the timing file's field (`topics.<topic>.scripts[<k>]…`); the admission table carries the
/// scripts. The buses' engine handlers are app tasks without a row of their own, at the engine's priority (here
/// DiWheelDrive's `can_status`, at 7, stands in for I2C2_EV): a handler at another priority, one the app does not
/// declare, one the file also budgets, or one that locks a resource a task above the engine uses is refused.
#[test]
fn a_timing_file_topic_states_several_scripts_and_the_engine_names_its_handlers() {
    let root = common::scratch_workspace("sensor-buses-several", None);
    let models = root.join(scenario::MODELS_DIR);
    let scenario_path = models.join("floor.scenario.json");
    std::fs::write(
        &scenario_path,
        json!({
            "name": "floor",
            "publishers": [{ "topic": "floor-proximity", "priority": "medium", "period_us": 100000 }]
        })
        .to_string(),
    )
    .unwrap();
    let build = || scenario::build(&root, &scenario_path, &scenario::timing_files(&root));
    let timing_path = models.join("diwheeldrive.timing.json");
    let mut timing: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&timing_path).unwrap()).unwrap();
    let script = |bus: &str| {
        json!({ "bus": bus, "bytes": 7, "starts": 2, "source": "a channel select and one read",
                "stretch_us": 0.0, "stretch_source": "the PCA9544A and VCNL4020 do not stretch (test)" })
    };
    timing["sensor_buses"] = json!([
        { "name": "i2c1", "bitrate": 400000,
          "engine": { "priority": 7, "per_event_us": 3.0, "per_event_from": "estimate", "source": "test" } },
        { "name": "i2c2", "bitrate": 400000,
          "engine": { "priority": 7, "per_event_us": 3.0, "per_event_from": "estimate", "source": "test",
                      "handlers": ["can_status"] } }
    ]);
    timing["topics"]["floor-proximity"]["scripts"] = json!([script("i2c2"), script("i2c1")]);
    timing["tasks"]["watchdog"]["script"] = script("i2c1");
    timing["tasks"]
        .as_object_mut()
        .unwrap()
        .remove("can_status");
    let write = |timing: &serde_json::Value| {
        std::fs::write(&timing_path, timing.to_string()).unwrap();
    };
    write(&timing);
    let built = build().expect("builds");
    // The machine code's row of the handler (DiWheelDrive's generated bounds file bounds `can_status`) is the
    // engine's, not a misnamed budget.
    assert!(
        !built.warnings.iter().any(|w| w.contains("`can_status`")),
        "{:?}",
        built.warnings
    );
    let system = built.model.validate().expect("valid");
    let dwd = system
        .boards
        .iter()
        .find(|b| b.name == "diwheeldrive")
        .unwrap();
    let names: Vec<&str> = dwd.tasks.iter().map(|t| t.name.as_str()).collect();
    assert!(!names.contains(&"can_status"), "{names:?}");
    assert!(names.contains(&"i2c2_engine[publish_medium[floor-proximity]#1]"));
    assert!(names.contains(&"i2c1_engine[publish_medium[floor-proximity]#2]"));
    assert!(names.contains(&"i2c1_engine[watchdog]"));

    // The admission table takes them: the handler has no task row (it is the engine's), the topic's two scripts
    // in order (bus 1, then bus 0), the fixed task's one beside its row.
    let lowered = schedule_analysis::admission_host::lower_robot(&root).expect("lowers");
    let table = &lowered.boards[0];
    assert!(
        !table.task_names.iter().any(|n| n == "can_status"),
        "{:?}",
        table.task_names
    );
    let floor = table
        .topics
        .iter()
        .find(|t| t.name == "floor-proximity")
        .expect("floor");
    assert_eq!(
        floor.scripts.iter().map(|s| s.bus).collect::<Vec<_>>(),
        [1, 0]
    );
    let watchdog = table
        .task_names
        .iter()
        .position(|n| n == "watchdog")
        .expect("watchdog");
    assert_eq!(
        table
            .task_scripts
            .iter()
            .map(|(t, l)| (usize::from(*t), l.len()))
            .collect::<Vec<_>>(),
        [(watchdog, 1)]
    );
    let mut fixed_only = timing.clone();
    fixed_only["tasks"]["watchdog"]["script"]["bus"] = json!("i2c3");
    write(&fixed_only);
    let error = build().expect_err("refused");
    assert_eq!(error.path, "tasks.watchdog.script.bus");

    let mut priority = timing.clone();
    priority["sensor_buses"][1]["engine"]["priority"] = json!(6);
    write(&priority);
    let error = build().expect_err("refused");
    assert_eq!(error.path, "sensor_buses[1].engine.handlers[0]");
    assert_eq!(
        error.problem,
        SensorBusError::HandlerPriority("can_status".into(), 7, 6).to_string()
    );

    let mut unknown = timing.clone();
    unknown["sensor_buses"][1]["engine"]["handlers"] = json!(["I2C2_EV"]);
    write(&unknown);
    let error = build().expect_err("refused");
    assert_eq!(error.path, "sensor_buses[1].engine.handlers[0]");
    assert_eq!(
        error.problem,
        SensorBusError::UnknownHandler("I2C2_EV".into()).to_string()
    );

    let mut locks = timing.clone();
    locks["sensor_buses"][1]["engine"]["priority"] = json!(1);
    // Motor control (priority 1) locks the command the handler leaves it, whose ceiling is the handler's 5.
    locks["sensor_buses"][1]["engine"]["handlers"] = json!(["motor_control"]);
    locks["tasks"]
        .as_object_mut()
        .unwrap()
        .remove("motor_control");
    write(&locks);
    let error = build().expect_err("refused");
    assert_eq!(error.path, "sensor_buses[1].engine.handlers[0]");
    assert_eq!(
        error.problem,
        SensorBusError::HandlerLocksAbove("motor_control".into(), "motor_command".into(), 5)
            .to_string()
    );

    let mut twice = timing.clone();
    twice["sensor_buses"][0]["engine"]["handlers"] = json!(["can_status"]);
    write(&twice);
    let error = build().expect_err("refused");
    assert_eq!(error.path, "sensor_buses[1].engine.handlers[0]");

    let mut budgeted = timing.clone();
    budgeted["tasks"]["can_status"] = json!({ "wcet_us": 4.0, "arrival": { "sporadic_us": 1000 } });
    write(&budgeted);
    let error = build().expect_err("refused");
    assert_eq!(error.path, "tasks.can_status");

    let mut bad = timing;
    bad["topics"]["floor-proximity"]["scripts"][1]["bus"] = json!("i2c3");
    write(&bad);
    let error = build().expect_err("refused");
    assert_eq!(error.path, "topics.floor-proximity.scripts[1].bus");
    assert!(error.file.ends_with("diwheeldrive.timing.json"), "{error}");
    let _ = std::fs::remove_dir_all(&root);
}

/// [`board_json`]'s engine charged by its three parts: 2 µs per event (3 µs with entry and exit), 4 µs per script
/// and a 5 µs condition wait per START, for a 7-byte script with two STARTs (a write, a repeated START, a read).
fn parts_json() -> serde_json::Value {
    let mut v = board_json();
    v["sensor_buses"][0]["engine"]["per_script"] = json!({ "us": 4.0, "from": "bound", "source": "a script's end and its client's wake (test)" });
    v["sensor_buses"][0]["engine"]["condition_wait"] =
        json!({ "us": 5.0, "from": "estimate", "source": "two SCL periods (test)" });
    v["tasks"][0]["script"]["bytes"] = json!(7);
    v["tasks"][0]["script"]["starts"] = json!(2);
    v
}

/// Worked by hand: 9 × 7 + 2 × 2 = 67 bit times of 2.5 µs = 167.5 µs on the wire, 2 × 7 + 2 × 2 = 18 events. The
/// engine row: 18 × 3 + 4 + 2 × 5 = 68 µs. An event's response at priority 7 (nothing above, nothing blocking) is
/// its cost: 3 µs plain, 8 µs with the wait, 12 µs for the ending event (3 + 4, and the wait, which the ending
/// event is charged as well). The bus time: 167.5 + 10 stretch + 12 + 2 × 8 + 15 × 3 = 250.5 µs, alone on the bus:
/// the suspension. The job: 50 + 250.5 + the engine's 68 = 368.5 µs. With the per-event figure alone (3 µs, the
/// wait inside it) the same script would be charged 18 × 3 = 54 µs: the parts are what move the figures.
#[test]
fn the_engine_charged_by_its_parts() {
    let model = Model {
        name: None,
        boards: vec![board(parts_json())],
        can: None,
    };
    let system = model.validate().expect("valid");
    let b = &system.boards[0];
    let row = &b.tasks[2];
    assert_eq!(row.name, "i2c1_engine[publish[floor]]");
    assert_eq!(row.wcet, Time::from_us(68));
    let script = &b.sensor_buses.scripts[0];
    assert_eq!(
        (script.wire, script.events, script.starts),
        (Time::from_ns(167_500), 18, 2)
    );
    let result = analysis::analyse_board(b, &Limits::default());
    let bus = &result.sensor_buses[0];
    assert_eq!(bus.event_response, Some(Time::from_us(3)));
    assert_eq!(bus.scripts[0].bus_time, Time::from_ns(250_500));
    assert_eq!(bus.scripts[0].suspension, Some(Time::from_ns(250_500)));
    assert_eq!(result.tasks[0].wcrt(), Some(Time::from_ns(368_500)));

    // The report states each part with its source and kind.
    let report = Report::build(&system, "t".into(), Vec::new(), Vec::new(), None);
    let text = report::render(&report, Format::Table);
    assert!(
        text.contains(
            ", 4 µs per script (machine-code bound: a script's end and its client's wake (test)), 5 µs condition \
             wait per START (estimate: two SCL periods (test))"
        ),
        "{text}"
    );
    let json = report::render(&report, Format::Json);
    assert!(json.contains("\"per_script\": {"), "{json}");
    // Without the parts, the report says nothing of them.
    let plain = Model {
        name: None,
        boards: vec![board(board_json())],
        can: None,
    }
    .validate()
    .expect("valid");
    let json = report::render(
        &Report::build(&plain, "t".into(), Vec::new(), Vec::new(), None),
        Format::Json,
    );
    assert!(
        !json.contains("per_script") && !json.contains("condition_wait"),
        "{json}"
    );
}

/// A script by `bus_time_us` counts its STARTs for the condition wait: its `starts` is required on an engine that
/// states the wait and refused on one that does not (it would mean nothing there).
#[test]
fn a_script_by_its_bus_time_states_its_starts_for_the_wait() {
    let by_time = |v: &mut serde_json::Value| {
        let script = v["tasks"][0]["script"].as_object_mut().unwrap();
        script.remove("bytes");
        script.remove("starts");
        script.insert("bus_time_us".into(), json!(120.0));
        script.insert("events".into(), json!(10));
    };
    let mut v = parts_json();
    by_time(&mut v);
    assert_eq!(
        refusal(v.clone()),
        ("tasks[0].script.starts".into(), SensorBusError::NoStarts)
    );
    v["tasks"][0]["script"]["starts"] = json!(3);
    let system = Model {
        name: None,
        boards: vec![board(v)],
        can: None,
    }
    .validate()
    .expect("valid");
    let b = &system.boards[0];
    assert_eq!(b.sensor_buses.scripts[0].starts, 3);
    // 10 × (2 + 1) + 4 + 3 × 5.
    assert_eq!(b.tasks[2].wcet, Time::from_us(49));
    let mut v = board_json();
    by_time(&mut v);
    v["tasks"][0]["script"]["starts"] = json!(3);
    assert_eq!(
        refusal(v),
        (
            "tasks[0].script.starts".into(),
            SensorBusError::StartsWithoutBytes
        )
    );
}

/// The parts as a timing file states them (its `sensor_buses`): a part without its source, a negative figure or
/// an unknown field is refused, naming the field.
#[test]
fn a_timing_files_engine_parts_are_checked() {
    let buses = |engine: serde_json::Value| -> Vec<sensor_bus::SensorBusModel> {
        serde_json::from_value(json!([{ "name": "i2c2", "bitrate": 400000, "engine": engine }]))
            .expect("the timing file's form")
    };
    let engine = || {
        json!({ "priority": 7, "per_event_us": 12.51, "per_event_from": "bound",
                "source": "tools/engine-bound: I2Cx_EV without end and wake",
                "per_script": { "us": 12.74, "from": "bound", "source": "tools/engine-bound: end + wake" },
                "condition_wait": { "us": 5.6, "from": "estimate", "source": "CONDITION_WAIT_NS" } })
    };
    assert_eq!(
        sensor_bus::check_timing(&buses(engine()), std::iter::empty()),
        Ok(())
    );
    let mut e = engine();
    e["per_script"]["source"] = json!("");
    assert_eq!(
        sensor_bus::check_timing(&buses(e), std::iter::empty()),
        Err((
            "sensor_buses[0].engine.per_script.source".into(),
            SensorBusError::NoSource
        ))
    );
    let mut e = engine();
    e["condition_wait"]["us"] = json!(-5.6);
    assert_eq!(
        sensor_bus::check_timing(&buses(e), std::iter::empty()),
        Err((
            "sensor_buses[0].engine.condition_wait.us".into(),
            SensorBusError::Negative("-5.6".into())
        ))
    );
    let mut e = engine();
    e["per_script"].as_object_mut().unwrap().remove("source");
    assert!(serde_json::from_value::<Vec<sensor_bus::SensorBusModel>>(
        json!([{ "name": "i2c2", "bitrate": 400000, "engine": e }])
    )
    .is_err());
    let mut e = engine();
    e["condition_wait"]["at"] = json!(["repeated_start"]);
    assert!(serde_json::from_value::<Vec<sensor_bus::SensorBusModel>>(
        json!([{ "name": "i2c2", "bitrate": 400000, "engine": e }])
    )
    .is_err());
}

/// An engine row is left out of the deadline check: it carries its job's whole response as jitter, so its analysed
/// response is no completion time (the engine does the script's work while the job is suspended on it, before the
/// job ends; the job's check covers it). [`board_json`]'s job with a 330 µs period: the job 50 + 192 + 2 × 42 =
/// 326 µs meets its deadline; its row's analysed response, 326 + 42 = 368, is above the 330 µs it was checked
/// against, and the set is schedulable (it was not).
#[test]
fn an_engine_row_is_left_out_of_the_deadline_check() {
    let mut v = board_json();
    v["tasks"][0]["period_us"] = json!(330.0);
    let model = Model {
        name: None,
        boards: vec![board(v)],
        can: None,
    };
    let system = model.validate().expect("valid");
    let result = analysis::analyse_board(&system.boards[0], &Limits::default());
    assert_eq!(result.tasks[0].wcrt(), Some(Time::from_us(326)));
    assert!(result.tasks[0].schedulable());
    let row = &result.tasks[2];
    assert_eq!(row.name, "i2c1_engine[publish[floor]]");
    assert_eq!(row.wcrt(), Some(Time::from_us(368)), "{row:?}");
    assert!(!row.deadline_checked && row.schedulable());
    assert!(result.tasks[1].deadline_checked);
    let analysis = analysis::analyse(
        &system,
        &Options {
            frame_cost: FrameCostSpec::Exact,
            horizon: None,
        },
    );
    assert!(analysis.all_ok(), "{:?}", analysis.failures());
    // Nor is it the board's tightest task in the report.
    let report = Report::build(&system, "t".into(), Vec::new(), Vec::new(), None);
    let text = report::render(&report, Format::Table);
    let heading = text
        .lines()
        .find(|l| l.contains("Board b"))
        .expect("the board's heading");
    assert!(heading.contains("tightest: publish[floor]"), "{heading}");
}

/// `engine.handlers` take the handlers' tasks off the board: on a bus no script names, nothing would charge them,
/// so the timing file is refused naming the field; with a script on the bus it is taken.
#[test]
fn engine_handlers_on_a_bus_without_scripts_are_refused() {
    let buses: Vec<sensor_bus::SensorBusModel> = serde_json::from_value(json!([
        { "name": "i2c1", "bitrate": 400000,
          "engine": { "priority": 7, "per_event_us": 2.0, "per_event_from": "estimate", "source": "a guess" } },
        { "name": "i2c2", "bitrate": 400000,
          "engine": { "priority": 7, "per_event_us": 2.0, "per_event_from": "estimate", "source": "a guess",
                      "handlers": ["i2c2_ev", "i2c2_er"] } }
    ]))
    .expect("the timing file's form");
    let script = |bus: &str| -> sensor_bus::ScriptModel {
        serde_json::from_value(
            json!({ "bus": bus, "bytes": 6, "source": "address + 5 bytes",
                                      "stretch_us": 0.0, "stretch_source": "none" }),
        )
        .expect("a script")
    };
    let refused = Err((
        "sensor_buses[1].engine.handlers".into(),
        SensorBusError::HandlersWithoutScripts("i2c2".into()),
    ));
    assert_eq!(
        sensor_bus::check_timing(&buses, std::iter::empty()),
        refused
    );
    let on_i2c1 = script("i2c1");
    assert_eq!(
        sensor_bus::check_timing(
            &buses,
            std::iter::once(("topics.a".to_string(), Some(&on_i2c1), None))
        ),
        refused
    );
    let on_i2c2 = script("i2c2");
    assert_eq!(
        sensor_bus::check_timing(
            &buses,
            std::iter::once(("topics.a".to_string(), Some(&on_i2c2), None))
        ),
        Ok(())
    );
}

/// A board whose timer job `tick` (priority 9, 1 µs every 50 µs, 10 µs release jitter) releases `follow`
/// (priority 8, 20 µs) above the engine (priority 7, 26 µs per event with 1 µs entry and exit), and a publisher job
/// at priority 3 with a one-byte script: `follow`'s releases lie 1 to 11 µs after `tick`'s activation.
fn released_above_the_engine() -> BoardModel {
    board(json!({
        "name": "b",
        "overheads": { "isr_entry_us": 0.5, "isr_exit_us": 0.5 },
        "sensor_buses": [{
            "name": "i2c1", "bitrate": 400000,
            "engine": { "priority": 7, "per_event_us": 26.0, "per_event_from": "estimate",
                        "source": "a figure large enough that two of follow's jobs reach one event" }
        }],
        "tasks": [
            { "name": "tick", "priority": 9, "wcet_us": 1.0, "period_us": 50.0, "jitter_us": 10.0 },
            { "name": "follow", "priority": 8, "wcet_us": 20.0, "period_us": 50.0, "released_by": "tick" },
            { "name": "publish[floor]", "priority": 3, "wcet_us": 50.0, "period_us": 100000.0,
              "job_of": "publish",
              "script": { "bus": "i2c1", "bytes": 1, "source": "one address byte",
                          "stretch_us": 0.0, "stretch_source": "none stated" } }
        ]
    }))
}

/// An engine event's response counts a released job above the engine with the jitter it inherits from its
/// releaser (its own plus the releaser's response), not its own alone. The simulator: `tick` released 10 µs late
/// runs 10 to 11 µs, `follow` 11 to 31 µs, an event of 27 µs arriving at 11 µs runs 31 to 50, `tick`'s next job
/// (on time) 50 to 51, `follow`'s 51 to 71, the event's last 8 µs 71 to 79: 68 µs. With `follow`'s own jitter (0)
/// the event's window holds one `follow`: 27 + 2 × 1 + 20 = 49 µs, below that; with its inherited 11 µs:
/// 27 + 2 × 1 + 2 × 20 = 69 µs. The script: 11 bit times (27.5 µs) and 4 events of 69 µs, 303.5 µs on the bus by
/// each event's own response; as one job of 27.5 + 4 × 27 = 135.5 µs at priority 7 it meets `tick` 6 times
/// (⌈(261.5 + 10)/50⌉) and `follow` 6 times (⌈(261.5 + 11)/50⌉): 135.5 + 6 + 120 = 261.5 µs, the bound taken
/// (with `follow`'s own jitter it would be 241.5 µs). The job: 50 + 261.5 + its engine row's 108 + 15 of `tick`'s
/// and `follow`'s jobs (15 × 21) = 734.5 µs (`tests/admission_scripts.rs` decides the same from the chip's rows).
#[test]
fn an_event_counts_a_released_jobs_inherited_jitter() {
    let model = Model {
        name: None,
        boards: vec![released_above_the_engine()],
        can: None,
    };
    let system = model.validate().expect("valid");
    let result = analysis::analyse_board(&system.boards[0], &Limits::default());
    assert_eq!(result.tasks[1].jitter, Time::from_us(11));
    let bus = &result.sensor_buses[0];
    assert_eq!(bus.event_response, Some(Time::from_us(69)));
    assert_eq!(bus.scripts[0].bus_time, Time::from_ns(261_500));
    assert_eq!(result.tasks[2].wcrt(), Some(Time::from_ns(734_500)));

    let us = 1000;
    let job = |task, arrival: u64, release: u64, length: u64| sim::Job {
        task,
        arrival: arrival * us,
        release: release * us,
        segments: vec![sim::Segment {
            length: length * us,
            lock: None,
        }],
    };
    let jobs = [
        job(0, 0, 10, 1),
        job(1, 11, 11, 20),
        job(2, 11, 11, 27),
        job(0, 50, 50, 1),
        job(1, 51, 51, 20),
    ];
    let responses = sim::board_run(&[9, 8, 7], &[], &jobs);
    let event = Time::from_ns(responses[2]);
    assert_eq!(event, Time::from_us(68));
    assert!(event <= bus.event_response.expect("bounded"));
    // What the event's window gives with `follow`'s own jitter: below the simulated response.
    let own_jitter = [
        TaskTiming {
            priority: 9,
            wcet: Time::from_us(1),
            period: Time::from_us(50),
            jitter: Time::from_us(10),
        },
        TaskTiming {
            priority: 8,
            wcet: Time::from_us(20),
            period: Time::from_us(50),
            jitter: Time::ZERO,
        },
        TaskTiming {
            priority: 7,
            wcet: Time::from_us(27),
            period: Limits::default().horizon,
            jitter: Time::ZERO,
        },
    ];
    let mut scratch = [Counter::default(); 3];
    let optimistic =
        board::response_time(&own_jitter, 2, Time::ZERO, &Limits::default(), &mut scratch)
            .expect("bounded");
    assert_eq!(optimistic.wcrt, Time::from_us(49));
    assert!(optimistic.wcrt < event);
}

/// A script's deadline bounds its stretch: the bus ends it by `deadline_us` after its start (its
/// deadline, the watch's response and the bus clear), so the stretch charged is at most the
/// deadline less the wire time (140 µs here); a deadline above wire + stretch changes nothing; a
/// deadline without its source is refused.
#[test]
fn a_scripts_deadline_caps_its_stretch() {
    let stretch_of = |stretch: f64, deadline: Option<f64>| {
        let mut v = board_json();
        v["tasks"][0]["script"]["stretch_us"] = json!(stretch);
        if let Some(deadline) = deadline {
            v["tasks"][0]["script"]["deadline_us"] = json!(deadline);
            v["tasks"][0]["script"]["deadline_source"] = json!("the bus's watch (test)");
        }
        let model = Model {
            name: None,
            boards: vec![board(v)],
            can: None,
        };
        let system = model.validate().expect("valid");
        let script = &system.boards[0].sensor_buses.scripts[0];
        assert_eq!(script.wire, Time::from_us(140));
        script.stretch
    };
    assert_eq!(stretch_of(9_000.0, None), Time::from_us(9_000));
    assert_eq!(stretch_of(9_000.0, Some(1_600.0)), Time::from_us(1_460));
    assert_eq!(stretch_of(10.0, Some(1_600.0)), Time::from_us(10));
    // A deadline shorter than the wire leaves no stretch (the script ends with `Stretched`).
    assert_eq!(stretch_of(9_000.0, Some(100.0)), Time::ZERO);
    let mut v = board_json();
    v["tasks"][0]["script"]["deadline_us"] = json!(1_600.0);
    assert_eq!(
        refusal(v),
        (
            "tasks[0].script.deadline_source".into(),
            SensorBusError::NoSource
        )
    );
}
