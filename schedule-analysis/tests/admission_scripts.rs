//! The on-chip admission check with sensor-bus scripts against the report (`sensor_bus::analyse`): timing files
//! that state sensor buses and scripts (publisher topics' and a fixed task's, jobs of one and of several scripts,
//! settles, the engine's charge by its parts) lower into the chip's tables, and for random publisher sets the
//! check admits exactly what `cargo xtask analyze --check` finds schedulable, naming the WCRTs the report finds;
//! and the hand-worked answers of `tests/sensor_buses.rs` come out of the chip's check.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use proptest::prelude::*;
use schedule_analysis::admission::{
    self, BoardTable, BusRow, Culprit, Refusal, RobotTable, ScriptRow, Sender, Stream, TaskId,
    TaskRow, TopicRow, NO_DEADLINE, NO_RELEASER, SHARE_AT_RUNTIME,
};
use schedule_analysis::admission_host::{self, OwnedRobot};
use schedule_analysis::analysis::{analyse, Analysis, Options};
use schedule_analysis::can::FrameCost;
use schedule_analysis::model::FrameCostSpec;
use schedule_analysis::scenario;
use schedule_analysis::time::Time;
use serde_json::json;

mod common;

const LEVELS: [&str; 4] = ["urgent", "high", "medium", "low"];

/// A script entry of a timing file.
fn script(bus: &str, bytes: u32, starts: u32, settle_us: Option<f64>) -> serde_json::Value {
    let mut s = json!({
        "bus": bus, "bytes": bytes, "starts": starts, "source": "test",
        "stretch_us": 20.0, "stretch_source": "test"
    });
    if let Some(us) = settle_us {
        s["settle_us"] = json!(us);
        s["settle_source"] = json!("test");
    }
    s
}

/// Two buses at the engine's priority 5 (below the CAN interrupts, at the command handler's): `i2c1` charged per event alone, `i2c2` by its parts.
fn buses() -> serde_json::Value {
    json!([
        { "name": "i2c1", "bitrate": 400000,
          "engine": { "priority": 5, "per_event_us": 3.0, "per_event_from": "estimate", "source": "test" } },
        { "name": "i2c2", "bitrate": 100000,
          "engine": { "priority": 5, "per_event_us": 2.0, "per_event_from": "estimate", "source": "test",
                      "per_script": { "us": 4.0, "from": "estimate", "source": "test" },
                      "condition_wait": { "us": 5.0, "from": "estimate", "source": "test" } } }
    ])
}

/// A workspace whose DiWheelDrive publishes its floor, gyroscope and magnetometers with scripts on two buses
/// (the floor's two scripts with a settle), and whose PowerManagement's `power_monitor` (a fixed task) and
/// proximity ring run scripts.
fn workspace() -> &'static PathBuf {
    static ROOT: OnceLock<PathBuf> = OnceLock::new();
    ROOT.get_or_init(|| {
        // One workspace for every test of this binary, replaced by each run.
        let root = common::scratch_workspace_at(
            Path::new(env!("CARGO_TARGET_TMPDIR")).join("admission-scripts"),
            None,
        );
        let models = root.join(scenario::MODELS_DIR);
        let edit = |file: &Path, f: &dyn Fn(&mut serde_json::Value)| {
            let mut timing: serde_json::Value =
                serde_json::from_str(&std::fs::read_to_string(file).unwrap()).unwrap();
            f(&mut timing);
            std::fs::write(file, timing.to_string()).unwrap();
        };
        edit(&models.join("diwheeldrive.timing.json"), &|t| {
            t["sensor_buses"] = buses();
            t["topics"]["floor-proximity"]["scripts"] =
                json!([script("i2c2", 2, 1, None), script("i2c2", 3, 1, Some(66.0))]);
            t["topics"]["gyroscope"]["script"] = script("i2c1", 3, 1, None);
            t["topics"]["magnetometer-x"]["script"] = script("i2c1", 2, 1, None);
            t["topics"]["magnetometer-y"]["script"] = script("i2c2", 2, 1, None);
        });
        edit(&models.join("powermgmt.timing.json"), &|t| {
            t["sensor_buses"] = buses();
            t["tasks"]["power_monitor"]["scripts"] = json!([
                script("i2c1", 3, 1, None),
                script("i2c1", 3, 1, Some(66.0)),
                script("i2c2", 2, 1, Some(66.0))
            ]);
            t["topics"]["proximity-ring"]["scripts"] =
                json!([script("i2c1", 4, 2, None), script("i2c2", 4, 1, None)]);
        });
        root
    })
}

fn robot() -> &'static OwnedRobot {
    static ROBOT: OnceLock<OwnedRobot> = OnceLock::new();
    ROBOT.get_or_init(|| admission_host::lower_robot(workspace()).unwrap_or_else(|e| panic!("{e}")))
}

/// The report for these publishers (topic, level, period in µs) on the scripted workspace.
fn report(publishers: &[(String, &str, u64)], case: u64) -> Analysis {
    let root = workspace();
    let path = std::env::temp_dir().join(format!(
        "admission-scripts-{}-{case}.scenario.json",
        std::process::id()
    ));
    let json = json!({
        "name": "admission-scripts",
        "publishers": publishers.iter().map(|(t, l, p)| json!({
            "topic": t, "priority": l, "period_us": p })).collect::<Vec<_>>(),
    });
    std::fs::write(&path, json.to_string()).expect("temp scenario");
    let built = scenario::build(root, &path, &scenario::timing_files(root));
    let _ = std::fs::remove_file(&path);
    let built = built.unwrap_or_else(|e| panic!("{e}"));
    analyse(
        &built.model.validate().expect("valid"),
        &Options {
            frame_cost: FrameCostSpec::Exact,
            horizon: None,
        },
    )
}

/// The report's task that the check names (`None` for a frame or a path, which the report names otherwise).
fn reported_wcrt(analysis: &Analysis, culprit: Culprit) -> Option<Option<Time>> {
    let Culprit::Task { board, task } = culprit else {
        return None;
    };
    let robot = robot();
    let table = robot.boards.get(usize::from(board))?;
    let topic_name = |t: u8| {
        table
            .topics
            .iter()
            .find(|o| o.topic == t)
            .map(|o| o.name.clone())
    };
    let name = match task {
        TaskId::Fixed(i) => table.task_names.get(usize::from(i))?.clone(),
        TaskId::Publisher(t) | TaskId::Timer(t) => {
            let topic = topic_name(t)?;
            let report_board = analysis.boards.iter().find(|b| b.name == table.name)?;
            // The topic's publisher job: `<publisher>[<topic>]`, not its timer job, engine or transmit rows.
            let job = report_board
                .tasks
                .iter()
                .find(|r| {
                    r.name.ends_with(&format!("[{topic}]"))
                        && !r.name.starts_with("monotonic[")
                        && !r.name.starts_with("can_tx[")
                        && !r.name.contains("_engine[")
                })?
                .name
                .clone();
            if matches!(task, TaskId::Timer(_)) {
                format!("monotonic[{job}]")
            } else {
                job
            }
        }
    };
    let report_board = analysis.boards.iter().find(|b| b.name == table.name)?;
    Some(report_board.tasks.iter().find(|r| r.name == name)?.wcrt())
}

fn publishable() -> Vec<String> {
    robot()
        .boards
        .iter()
        .flat_map(|b| b.topics.iter().map(|t| t.name.clone()))
        .collect()
}

#[test]
fn the_scripts_lower_into_the_table() {
    let robot = robot();
    let dwd = robot
        .boards
        .iter()
        .find(|b| b.name == "diwheeldrive")
        .expect("dwd");
    assert_eq!(dwd.buses.len(), 2);
    // i2c2: 2 µs per event with the board's entry and exit, 4 µs per script, 5 µs per START.
    assert_eq!(
        (
            dwd.buses[1].per_script,
            dwd.buses[1].condition_wait,
            dwd.buses[1].engine_priority
        ),
        (4_000, 5_000, 5)
    );
    let floor = dwd
        .topics
        .iter()
        .find(|t| t.name == "floor-proximity")
        .expect("floor");
    assert_eq!(floor.scripts.len(), 2);
    // 3 bytes and one START at 100 kHz: (9 × 3 + 2) × 10 µs on the wire, 20 µs stretch; 2 × 3 + 2 events.
    assert_eq!(
        floor.scripts[1],
        ScriptRow {
            bus: 1,
            bus_time: 290_000 + 20_000,
            events: 8,
            starts: 1,
            settle: 66_000
        }
    );
    let power = robot
        .boards
        .iter()
        .find(|b| b.name == "powermgmt")
        .expect("powermgmt");
    let monitor = power
        .task_names
        .iter()
        .position(|n| n == "power_monitor")
        .expect("power_monitor");
    assert_eq!(power.task_scripts.len(), 1);
    assert_eq!(usize::from(power.task_scripts[0].0), monitor);
    assert_eq!(power.task_scripts[0].1.len(), 3);
    // DiWheelDrive's four levels are four RTIC tasks, LightRing's one.
    assert_eq!(dwd.publisher_tasks, [0, 1, 2, 3]);
    let ring = robot
        .boards
        .iter()
        .find(|b| b.name == "lightring")
        .expect("lightring");
    assert_eq!(ring.publisher_tasks, [0, 0, 0, 0]);
    let source = robot.to_rust_source("schedule_analysis");
    syn::parse_file(&source).unwrap_or_else(|e| panic!("generated source does not parse: {e}"));
    assert!(source
        .contains("ScriptRow { bus: 1, bus_time: 310000, events: 8, starts: 1, settle: 66000 }"));
}

/// Decides `publishers` (the last is the request) on the scripted workspace, and compares with the report: the
/// same verdict, and a refusal's WCRT is the report's for that task. `None` when the check ran out of its
/// iteration budget (a refusal without a verdict, which breaks no deadline).
fn agree(publishers: &[(String, &str, u64)], case: u64) -> Result<Option<bool>, String> {
    let robot = robot();
    let mut streams: Vec<Stream> = publishers
        .iter()
        .map(|(t, l, p)| {
            robot
                .publisher_stream(t, l, Time::from_us(*p), None)
                .expect("stream")
        })
        .collect();
    let request = streams.pop().expect("a request");
    let decision = robot.with_table(|t| admission::admit::<48, 32>(t, &streams, &request, false));
    let analysis = report(publishers, case);
    if decision.refusal == Some(Refusal::Budget) {
        return Ok(None);
    }
    if decision.admitted() != analysis.all_ok() {
        return Err(format!(
            "{publishers:?}: the check says {:?}, the report {:?}",
            decision.refusal,
            analysis.failure_figures()
        ));
    }
    if let Some(Refusal::Deadline(v)) = decision.refusal {
        if let Some(reported) = reported_wcrt(&analysis, v.culprit) {
            if reported != v.wcrt {
                return Err(format!(
                    "{publishers:?}: the check names {:?} at {:?}, the report {reported:?}",
                    v.culprit, v.wcrt
                ));
            }
        }
    }
    Ok(Some(decision.admitted()))
}

/// Some sets by hand: each scripted topic alone, siblings at one level, a fixed task's scripts beside a topic's.
#[test]
fn chosen_sets_agree_with_the_report() {
    let sets: [&[(&str, &str, u64)]; 6] = [
        &[("floor-proximity", "medium", 20_000)],
        &[
            ("gyroscope", "high", 50_000),
            ("magnetometer-x", "high", 20_000),
        ],
        &[
            ("magnetometer-y", "urgent", 30_000),
            ("floor-proximity", "low", 100_000),
        ],
        &[("proximity-ring", "low", 100_000)],
        &[
            ("proximity-ring", "urgent", 50_000),
            ("power-status", "low", 500_000),
        ],
        // Overloaded: the bus cannot carry the gyroscope's script every 40 µs. (Every 100 µs, with DiWheelDrive
        // 1-1's bounds of 2026-12-05, and every 80 µs since its transmit jobs are rows (2026-12-06), the check's
        // fixed point runs out of its iteration budget first: a refusal all the same, but one without a deadline
        // verdict to hold against the report's.)
        &[("gyroscope", "urgent", 40)],
    ];
    let mut verdicts = Vec::new();
    for (case, set) in sets.iter().enumerate() {
        let owned: Vec<(String, &str, u64)> = set
            .iter()
            .map(|(t, l, p)| (t.to_string(), *l, *p))
            .collect();
        let verdict = agree(&owned, 9_000 + case as u64).unwrap_or_else(|e| panic!("{e}"));
        verdicts.push(verdict);
    }
    assert_eq!(verdicts.last(), Some(&Some(false)), "{verdicts:?}");
    assert!(
        verdicts.iter().filter(|v| **v == Some(true)).count() >= 3,
        "{verdicts:?}"
    );
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, .. ProptestConfig::default() })]

    /// Random publisher sets over every publishable topic (the scripted ones among them), periods log-uniform from
    /// 1 ms to 1 s: the check admits exactly what the report finds schedulable.
    #[test]
    fn admission_with_scripts_equals_the_report(
        picks in proptest::collection::vec((any::<prop::sample::Index>(), 0usize..4, 0u32..1000), 1..6),
        case in any::<u64>(),
    ) {
        let topics = publishable();
        let mut publishers: Vec<(String, &str, u64)> = Vec::new();
        for (index, level, scale) in picks {
            let topic = index.get(&topics).clone();
            if publishers.iter().any(|(t, _, _)| *t == topic) {
                continue;
            }
            let period = (1000.0 * 1000f64.powf(f64::from(scale) / 1000.0)).round() as u64;
            publishers.push((topic, LEVELS[level], period));
        }
        if let Err(e) = agree(&publishers, case) {
            prop_assert!(false, "{}", e);
        }
    }
}

/// The decisions over a fixed spread of sets: the check decides most of them (its iteration budget refuses few),
/// and both verdicts occur, so the agreement above is not between two constant answers.
#[test]
fn the_check_decides_most_sets_with_scripts() {
    let topics = publishable();
    let (mut decided, mut admitted, mut total) = (0, 0, 0);
    for i in 0..24u64 {
        let mut publishers: Vec<(String, &str, u64)> = Vec::new();
        for k in 0..(1 + i % 4) {
            let topic = topics[((i * 7 + k * 5) % topics.len() as u64) as usize].clone();
            if publishers.iter().any(|(t, _, _)| *t == topic) {
                continue;
            }
            let period = [2_000, 10_000, 50_000, 200_000][((i + k) % 4) as usize];
            publishers.push((topic, LEVELS[((i + 3 * k) % 4) as usize], period));
        }
        total += 1;
        match agree(&publishers, 20_000 + i).unwrap_or_else(|e| panic!("{e}")) {
            Some(true) => {
                decided += 1;
                admitted += 1;
            }
            Some(false) => decided += 1,
            None => {}
        }
    }
    assert!(decided * 4 >= total * 3, "{decided} of {total} decided");
    assert!(
        admitted > 0 && admitted < decided,
        "{admitted} of {decided} admitted"
    );
}

/// `tests/sensor_buses.rs`'s hand-worked board through the chip's check: a job of 50 µs with a 6-byte script on
/// `i2c1` (150 µs on the wire with its stretch, 14 events of 3 µs at the engine's priority 7) responds in
/// 50 + 192 + 42 = 284 µs, the task below it in 192 µs. The chip names those WCRTs at a deadline 1 µs short and
/// admits at the figure itself.
#[test]
fn the_hand_worked_script_through_the_chip() {
    let plain = (
        ScriptRow {
            bus: 0,
            bus_time: 150_000,
            events: 14,
            starts: 1,
            settle: 0,
        },
        BusRow {
            engine_priority: 7,
            per_event: 3_000,
            per_script: 0,
            condition_wait: 0,
        },
    );
    let decide = |job_deadline_us: u32, background_deadline_us: u32| {
        decide_one(plain, job_deadline_us, background_deadline_us)
    };
    assert_eq!(decide(284, 192), None);
    let named = |refusal: Option<Refusal>| match refusal {
        Some(Refusal::Deadline(v)) => (v.culprit, v.wcrt),
        other => panic!("{other:?}"),
    };
    let task = |i| Culprit::Task {
        board: 0,
        task: TaskId::Fixed(i),
    };
    assert_eq!(named(decide(283, 192)), (task(0), Some(Time::from_us(284))));
    assert_eq!(named(decide(284, 191)), (task(1), Some(Time::from_us(192))));
    // `the_engine_charged_by_its_parts`: 7 bytes and two STARTs (167.5 µs on the wire, 10 µs stretch, 18 events),
    // 4 µs per script and a 5 µs condition wait: the engine row 18 × 3 + 4 + 2 × 5 = 68 µs, the bus time
    // 177.5 + 12 + 2 × 8 + 15 × 3 = 250.5 µs, the job 50 + 250.5 + 68 = 368.5 µs.
    let parts = (
        ScriptRow {
            bus: 0,
            bus_time: 177_500,
            events: 18,
            starts: 2,
            settle: 0,
        },
        BusRow {
            per_script: 4_000,
            condition_wait: 5_000,
            ..plain.1
        },
    );
    assert_eq!(
        named(decide_one(parts, 368, 1000)),
        (task(0), Some(Time::from_ns(368_500)))
    );
    assert_eq!(decide_one(parts, 369, 1000), None);
}

/// The hand-worked board of `tests/sensor_buses.rs` as chip rows: a job of 50 µs every 10 ms at priority 3 running
/// `script` on a bus with `engine`, and a task of 100 µs every 1 ms at priority 1, with these deadlines.
fn decide_one(
    (script, engine): (ScriptRow, BusRow),
    job_deadline_us: u32,
    background_deadline_us: u32,
) -> Option<Refusal> {
    let tasks = [
        TaskRow {
            cost: 50_000,
            period: 10_000_000,
            deadline: job_deadline_us * 1000,
            jitter: 0,
            priority: 3,
            released_by: NO_RELEASER,
            own_frame: false,
            bounded_only: false,
            share: SHARE_AT_RUNTIME,
        },
        TaskRow {
            cost: 100_000,
            period: 1_000_000,
            deadline: background_deadline_us * 1000,
            priority: 1,
            ..TaskRow {
                cost: 0,
                period: 0,
                deadline: NO_DEADLINE,
                jitter: 0,
                priority: 0,
                released_by: NO_RELEASER,
                own_frame: false,
                bounded_only: false,
                share: SHARE_AT_RUNTIME,
            }
        },
    ];
    let scripts = [script];
    let task_scripts = [(0u8, &scripts[..])];
    let buses = [engine];
    let boards = [BoardTable {
        name: "b",
        tasks: &tasks,
        sections: &[],
        blocking: &[],
        topics: &[],
        shortest_dlc: 0,
        levels: [None; 4],
        monotonic: None,
        can_tx: None,
        command_handler: None,
        buses: &buses,
        task_scripts: &task_scripts,
        publisher_tasks: [0; 4],
    }];
    let robot = RobotTable {
        boards: &boards,
        bit_time: Time::from_ns(1000),
        frame_cost: FrameCost::Exact,
    };
    admission::evaluate::<8, 8>(&robot, &[]).refusal
}

/// A publisher topic's script on the chip: the same hand-worked job as a publisher job of a stream (its period
/// the stream's, its engine row released by it), and a second topic of the same RTIC task whose script is its
/// sibling (never on the bus while the first is pending: no blocking, no interference between them), against one
/// of another task at the same priority, which is not.
#[test]
fn a_topics_script_and_its_siblings_through_the_chip() {
    let scripts = [ScriptRow {
        bus: 0,
        bus_time: 150_000,
        events: 14,
        starts: 1,
        settle: 0,
    }];
    let topics = [
        TopicRow {
            topic: 7,
            cost: 50_000,
            bcet: 0,
            sections: &[],
            scripts: &scripts,
            transmit: 0,
        },
        TopicRow {
            topic: 8,
            cost: 50_000,
            bcet: 0,
            sections: &[],
            scripts: &scripts,
            transmit: 0,
        },
    ];
    let buses = [BusRow {
        engine_priority: 7,
        per_event: 3_000,
        per_script: 0,
        condition_wait: 0,
    }];
    let response = |publisher_tasks: [u8; 4], deadline_us: u64| {
        let boards = [BoardTable {
            name: "b",
            tasks: &[],
            sections: &[],
            blocking: &[],
            topics: &topics,
            shortest_dlc: 1,
            levels: [Some(3), Some(3), None, None],
            monotonic: None,
            can_tx: None,
            command_handler: None,
            buses: &buses,
            task_scripts: &[],
            publisher_tasks,
        }];
        let robot = RobotTable {
            boards: &boards,
            bit_time: Time::from_ns(1),
            frame_cost: FrameCost::Exact,
        };
        let stream = |topic: u8, level: u8| Stream {
            id: admission::sensor_id(level, topic),
            extended: false,
            dlc: 1,
            frames: 1,
            period: Time::from_us(10_000),
            deadline: Some(Time::from_us(deadline_us)),
            jitter: Time::ZERO,
            sender: Some(Sender {
                board: 0,
                topic,
                level,
            }),
            receiver: None,
        };
        admission::evaluate::<8, 8>(&robot, &[stream(7, 0), stream(8, 1)]).refusal
    };
    // Worked by hand: each job is 50 µs of CPU, a script of 150 µs on the wire and 14 events of 3 µs (192 µs on
    // the bus alone), its engine row 42 µs at priority 7. As siblings (one RTIC task) the scripts never meet on
    // the bus (S = 192), but the other job waits out the suspension: 50 + 192 + (50 + 192) + 42 + 42 = 568 µs. As
    // two tasks the other's script may be on the bus first (S = 384) and its CPU runs anywhere in its window:
    // 50 + 384 + 50 + 42 + 42 = 568 µs. The chip names 568 µs at a deadline short of it and admits the set at 569.
    let wcrt = |publisher_tasks, deadline_us| match response(publisher_tasks, deadline_us) {
        Some(Refusal::Deadline(v)) => v.wcrt,
        None => None,
        other => panic!("{other:?}"),
    };
    for publisher_tasks in [[0, 0, 1, 2], [0, 1, 2, 3]] {
        assert_eq!(wcrt(publisher_tasks, 567), Some(Time::from_us(568)));
        // The job at 568 µs; its frame (130 bits of 1 ns) leaves within 569.
        assert_eq!(response(publisher_tasks, 569), None);
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 16, .. ProptestConfig::default() })]

    /// A board with scripts keeps its analysis between decisions as any board does (for the same horizon only): a
    /// sequence of requests on the scripted workspace decided with the cache gets the decisions of the check
    /// without it.
    #[test]
    fn the_cache_changes_no_decision_with_scripts(
        requests in proptest::collection::vec((any::<prop::sample::Index>(), 0usize..4, 0u32..1000), 1..12),
    ) {
        let robot = robot();
        let topics = publishable();
        let mut running: Vec<Stream> = Vec::new();
        let mut cache = admission::Cache::<32>::new();
        for (index, level, scale) in requests {
            let topic = index.get(&topics);
            let period = (1000.0 * 1000f64.powf(f64::from(scale) / 1000.0)).round() as u64;
            let request = robot
                .publisher_stream(topic, LEVELS[level], Time::from_us(period), None)
                .expect("stream");
            let plain = robot.with_table(|t| admission::admit::<48, 32>(t, &running, &request, false));
            let cached = robot.with_table(|t| admission::admit_cached::<48, 32>(t, &running, &request, &mut cache, false));
            prop_assert_eq!(plain.refusal, cached.refusal, "{} at {} µs {}", topic, period, LEVELS[level]);
            prop_assert_eq!(plain.floor, cached.floor);
            if plain.admitted() {
                running.retain(|s| s.sender.map(|x| (x.board, x.topic)) != request.sender.map(|x| (x.board, x.topic)));
                running.push(request);
            }
        }
    }
}

/// A fixed task of a hand-worked board: priority, CPU µs, period µs, its scripts' bus times µs (one bus, engine of
/// no cost), its critical section's length µs on a resource of ceiling 3 (0: none), the task that releases it
/// ([`NO_RELEASER`]: none).
type HandTask = (u8, u32, u32, &'static [u32], u32, u8);

/// The chip's decision on `tasks` (as [`chip_wcrts_us`] reads them), each deadline `expected` µs (0: none), task
/// `short`'s one µs less.
fn chip_decide(tasks: &[HandTask], expected: &[u32], short: Option<usize>) -> Option<Refusal> {
    let rows: Vec<TaskRow> = tasks
        .iter()
        .enumerate()
        .map(|(i, &(priority, cpu, period, _, _, released_by))| TaskRow {
            cost: cpu * 1000,
            period: period * 1000,
            deadline: match expected[i] {
                0 => NO_DEADLINE,
                e => (e - u32::from(short == Some(i))) * 1000,
            },
            jitter: 0,
            priority,
            released_by,
            own_frame: false,
            bounded_only: false,
            share: SHARE_AT_RUNTIME,
        })
        .collect();
    let sections: Vec<admission::SectionRow> = tasks
        .iter()
        .filter(|t| t.4 > 0)
        .map(|&(priority, _, _, _, length, _)| admission::SectionRow {
            length: length * 1000,
            holder_priority: priority,
            ceiling: 3,
        })
        .collect();
    let scripts: Vec<Vec<ScriptRow>> = tasks
        .iter()
        .map(|t| {
            t.3.iter()
                .map(|&us| ScriptRow {
                    bus: 0,
                    bus_time: us * 1000,
                    events: 0,
                    starts: 0,
                    settle: 0,
                })
                .collect()
        })
        .collect();
    let task_scripts: Vec<admission::TaskScripts<'_>> = scripts
        .iter()
        .enumerate()
        .filter(|(_, l)| !l.is_empty())
        .map(|(i, l)| (i as u8, l.as_slice()))
        .collect();
    let buses = [BusRow {
        engine_priority: 10,
        per_event: 0,
        per_script: 0,
        condition_wait: 0,
    }];
    let boards = [BoardTable {
        name: "b",
        tasks: &rows,
        sections: &sections,
        blocking: &[],
        topics: &[],
        shortest_dlc: 0,
        levels: [None; 4],
        monotonic: None,
        can_tx: None,
        command_handler: None,
        buses: &buses,
        task_scripts: &task_scripts,
        publisher_tasks: [0; 4],
    }];
    let robot = RobotTable {
        boards: &boards,
        bit_time: Time::from_ns(1000),
        frame_cost: FrameCost::Exact,
    };
    admission::evaluate::<16, 8>(&robot, &[]).refusal
}

/// The chip's WCRT of each of `tasks` (`tests/known_answers.rs`'s boards as chip rows) with an `expected` figure
/// (0: its period, not read): each such task's deadline one µs short of it in turn, the check names the task and
/// its WCRT; at `expected` it admits the set.
fn chip_wcrts_us(tasks: &[HandTask], expected: &[u32]) -> Vec<Option<u64>> {
    let decide = |short: Option<usize>| chip_decide(tasks, expected, short);
    assert_eq!(decide(None), None, "admitted at the expected WCRTs");
    (0..tasks.len())
        .filter(|&i| expected[i] > 0)
        .map(|i| match decide(Some(i)) {
            Some(Refusal::Deadline(v))
                if v.culprit
                    == Culprit::Task {
                        board: 0,
                        task: TaskId::Fixed(i as u16),
                    } =>
            {
                v.wcrt.map(|w| w.as_ns() / 1000)
            }
            other => panic!("task {i}: {other:?}"),
        })
        .collect()
}

/// `tests/known_answers.rs`'s hand-worked suspension examples through the chip's check: the suspending task seen
/// by the one below as its CPU with jitter `R − C` (8 and 8 µs, where the naive charge says 6), three scripts on
/// one bus to their fixed point round by round (410, 630, 640 µs), and a job blocked again when it resumes (15 µs,
/// where one blocking says 11).
#[test]
fn the_known_answers_through_the_chip() {
    let expected = [8, 8];
    assert_eq!(
        chip_wcrts_us(
            &[
                (2, 2, 10, &[6], 0, NO_RELEASER),
                (1, 4, 100, &[], 0, NO_RELEASER)
            ],
            &expected
        ),
        [Some(8), Some(8)]
    );
    let expected = [410, 630, 640];
    assert_eq!(
        chip_wcrts_us(
            &[
                (3, 10, 1000, &[100], 0, NO_RELEASER),
                (2, 10, 2000, &[200], 0, NO_RELEASER),
                (1, 10, 5000, &[300], 0, NO_RELEASER)
            ],
            &expected
        ),
        [Some(410), Some(630), Some(640)]
    );
    let expected = [15, 0, 0];
    assert_eq!(
        chip_wcrts_us(
            &[
                (3, 2, 100, &[5], 0, NO_RELEASER),
                (1, 4, 100, &[], 4, NO_RELEASER),
                (2, 4, 100, &[], 4, NO_RELEASER)
            ],
            &expected
        ),
        [Some(15)]
    );
    // A fixed task with scripts before a released one: the chip keeps every fixed task at its row's index (its
    // engine rows after all of them), so the release names the task the table names. t0 (3): 10 µs, a 100 µs
    // script: 110; t1 (2): 20 + t0's 10 with jitter 100: 30; t2 (1), released by t1: its jitter 30, then
    // 30 + 10 + 20 in its window: 90 (released by t0's engine row instead it would be 110 + 60 = 170).
    let expected = [110, 30, 90];
    assert_eq!(
        chip_wcrts_us(
            &[
                (3, 10, 1000, &[100], 0, NO_RELEASER),
                (2, 20, 1000, &[], 0, NO_RELEASER),
                (1, 30, 1000, &[], 0, 1)
            ],
            &expected
        ),
        [Some(110), Some(30), Some(90)]
    );
}

/// `tests/sensor_buses.rs`'s `an_event_counts_a_released_jobs_inherited_jitter` as chip rows: `tick` (9, 1 µs
/// every 50 µs, 10 µs jitter) releases `follow` (8, 20 µs) above the engine (7, 27 µs per event); the job (3,
/// 50 µs) runs a one-byte script (27.5 µs on the wire, 4 events). An event counts `follow` with the jitter it
/// inherits from `tick`'s 11 µs response: 69 µs (the simulator reaches 68); the script as one job meets `follow`
/// with that jitter too (261.5 µs on the bus, below the events' 303.5), the job 734.5 µs, as the host finds.
/// With `follow`'s own jitter the event was 49 µs and the job's bound below the host's.
#[test]
fn an_event_counts_a_released_jobs_inherited_jitter_on_the_chip() {
    let decide = |job_deadline: u32| {
        let row =
            |cost_us: u32, period_us: u32, jitter_us: u32, priority: u8, released_by: u8| TaskRow {
                cost: cost_us * 1000,
                period: period_us * 1000,
                deadline: NO_DEADLINE,
                jitter: jitter_us * 1000,
                priority,
                released_by,
                own_frame: false,
                bounded_only: false,
                share: SHARE_AT_RUNTIME,
            };
        let tasks = [
            row(1, 50, 10, 9, NO_RELEASER),
            row(20, 50, 0, 8, 0),
            TaskRow {
                deadline: job_deadline,
                ..row(50, 100_000, 0, 3, NO_RELEASER)
            },
        ];
        let scripts = [ScriptRow {
            bus: 0,
            bus_time: 27_500,
            events: 4,
            starts: 1,
            settle: 0,
        }];
        let task_scripts = [(2u8, &scripts[..])];
        let buses = [BusRow {
            engine_priority: 7,
            per_event: 27_000,
            per_script: 0,
            condition_wait: 0,
        }];
        let boards = [BoardTable {
            name: "b",
            tasks: &tasks,
            sections: &[],
            blocking: &[],
            topics: &[],
            shortest_dlc: 0,
            levels: [None; 4],
            monotonic: None,
            can_tx: None,
            command_handler: None,
            buses: &buses,
            task_scripts: &task_scripts,
            publisher_tasks: [0; 4],
        }];
        let robot = RobotTable {
            boards: &boards,
            bit_time: Time::from_ns(1000),
            frame_cost: FrameCost::Exact,
        };
        admission::evaluate::<8, 8>(&robot, &[]).refusal
    };
    assert_eq!(decide(734_500), None);
    match decide(734_499) {
        Some(Refusal::Deadline(v)) => {
            assert_eq!(
                v.culprit,
                Culprit::Task {
                    board: 0,
                    task: TaskId::Fixed(2),
                }
            );
            assert_eq!(v.wcrt, Some(Time::from_ns(734_500)));
        }
        other => panic!("{other:?}"),
    }
}

/// A build that does not link the check's sensor-bus rounds (a board without `scripted-i2c`) takes no table that
/// states a bus or a script: the lowering refuses it, naming the first such board (the build fails), and takes the
/// shipped timing files' table, which states none.
#[test]
fn a_build_without_the_rounds_takes_no_table_with_buses() {
    assert_eq!(
        robot().check_sensor_buses_linked(false),
        Err(admission_host::SensorBusesNotLinked {
            board: "diwheeldrive".into()
        })
    );
    assert_eq!(robot().check_sensor_buses_linked(true), Ok(()));
    let shipped =
        admission_host::lower_robot(&common::workspace()).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(shipped.check_sensor_buses_linked(false), Ok(()));
}

/// `tests/known_answers.rs`'s `a_suspending_job_whose_releaser_overloads_in_its_view_has_no_bound` through the
/// chip: p (2, CPU 20 µs, a 170 µs script, T 400) released by r (1, 300 µs, T 400), which overloads in p's view.
/// The simulator finds p at 490 µs; the check refuses the set without a bound, at any deadline.
#[test]
fn a_suspending_job_whose_releaser_overloads_through_the_chip() {
    let tasks: [HandTask; 2] = [
        (2, 20, 400, &[170], 0, 1),
        (1, 300, 400, &[], 0, NO_RELEASER),
    ];
    for expected in [[400, 400], [0, 400], [400, 0]] {
        match chip_decide(&tasks, &expected, None) {
            Some(Refusal::Deadline(v)) => assert_eq!(v.wcrt, None, "{expected:?}: {v:?}"),
            other => panic!("{expected:?}: {other:?}"),
        }
    }
}

/// `tests/known_answers.rs`'s `a_job_released_by_a_suspending_job_counts_its_own_suspensions` through the chip:
/// a (3, 10 µs, a 50 µs script) releases b (2, 10 µs, a 300 µs script), l (1, 380 µs) below, T 1000 µs each: b
/// seen by l with its `R − C` of 720 µs as jitter, not its release's 360: 360, 730 and 410 µs.
#[test]
fn a_job_released_by_a_suspending_job_through_the_chip() {
    let expected = [360, 730, 410];
    assert_eq!(
        chip_wcrts_us(
            &[
                (3, 10, 1000, &[50], 0, NO_RELEASER),
                (2, 10, 1000, &[300], 0, 0),
                (1, 380, 1000, &[], 0, NO_RELEASER)
            ],
            &expected
        ),
        [Some(360), Some(730), Some(410)]
    );
}

/// `tests/known_answers.rs`'s `a_job_released_across_a_suspending_one_keeps_its_jitter_in_its_view` through the
/// chip: x (3, 10 µs, T 100) released by r (1, 60 µs, T 100) keeps its 100 µs jitter from the default view in the
/// view of p (2, 20 µs, a 170 µs script, T 400), where r overloads: 110, 100 and 230 µs.
#[test]
fn a_job_released_across_a_suspending_one_through_the_chip() {
    let expected = [110, 100, 230];
    assert_eq!(
        chip_wcrts_us(
            &[
                (3, 10, 100, &[], 0, 1),
                (1, 60, 100, &[], 0, NO_RELEASER),
                (2, 20, 400, &[170], 0, NO_RELEASER)
            ],
            &expected
        ),
        [Some(110), Some(100), Some(230)]
    );
}
