//! The on-chip admission check against the report: on the project's own boards (lowered from the apps and timing
//! files), for random publisher sets, the admission decision equals `cargo xtask analyze --check`'s verdict on
//! the same configuration, so it never admits a set the report calls unschedulable.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use proptest::prelude::*;
use schedule_analysis::admission::{self, Culprit, Refusal};
use schedule_analysis::admission_host::{self, OwnedRobot};
use schedule_analysis::analysis::{analyse, Options};
use schedule_analysis::busy_window::Share;
use schedule_analysis::model::FrameCostSpec;
use schedule_analysis::scenario;
use schedule_analysis::time::Time;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map(Path::to_path_buf)
        .expect("workspace root")
}

fn robot() -> &'static OwnedRobot {
    static ROBOT: OnceLock<OwnedRobot> = OnceLock::new();
    ROBOT.get_or_init(|| {
        let root = root();
        admission_host::lower_robot(&root).unwrap_or_else(|e| panic!("{e}"))
    })
}

const LEVELS: [&str; 4] = ["urgent", "high", "medium", "low"];

/// LightRing's transmit interrupt charged by its parts (its `can_tx` bound used, every other held bound held
/// back): the report adds a `can_tx[<topic>]` job per publisher job, and the check builds the same jobs.
fn by_parts() -> scenario::Held<'static> {
    static ROWS: OnceLock<Vec<String>> = OnceLock::new();
    scenario::Held::Only {
        board: "lightring",
        rows: ROWS.get_or_init(|| vec!["can_tx".to_string()]),
    }
}

/// The table lowered from the model with LightRing's transmit interrupt charged by its parts.
fn robot_by_parts() -> &'static OwnedRobot {
    static ROBOT: OnceLock<OwnedRobot> = OnceLock::new();
    ROBOT.get_or_init(|| {
        let root = root();
        admission_host::lower_held(
            &root,
            &scenario::timing_files(&root),
            schedule_analysis::can::DEFAULT_BITRATE,
            FrameCostSpec::Exact,
            by_parts(),
        )
        .unwrap_or_else(|e| panic!("{e}"))
    })
}

/// The report's `--check` verdict for the scenario `json` (written to a temporary file named after `case`), and the
/// notes the report prints with it.
fn report_of(json: &serde_json::Value, case: &str) -> (bool, Vec<String>) {
    let (ok, notes, _) = report_held(json, case, scenario::Held::Kept);
    (ok, notes)
}

/// [`report_of`] on the model built with `held`, with the board tasks' names.
fn report_held(
    json: &serde_json::Value,
    case: &str,
    held: scenario::Held<'_>,
) -> (bool, Vec<String>, Vec<String>) {
    let root = root();
    let path = std::env::temp_dir().join(format!(
        "admission-{}-{case}.scenario.json",
        std::process::id()
    ));
    std::fs::write(&path, json.to_string()).expect("temp scenario");
    let built = scenario::build_held(&root, &path, &scenario::timing_files(&root), held);
    let _ = std::fs::remove_file(&path);
    let built = built.unwrap_or_else(|e| panic!("{e}"));
    let names = built
        .model
        .boards
        .iter()
        .flat_map(|b| {
            b.tasks
                .iter()
                .map(move |t| format!("{}/{}", b.name, t.name))
        })
        .collect();
    let system = built.model.validate().expect("valid");
    let ok = analyse(
        &system,
        &Options {
            frame_cost: FrameCostSpec::Exact,
            horizon: None,
        },
    )
    .all_ok();
    (ok, built.warnings, names)
}

/// The report's `--check` verdict for a scenario with these publishers and commands.
fn report_verdict(
    publishers: &[(String, &str, u64)],
    commands: &[(&str, &str, u64, u64)],
    case: u64,
) -> bool {
    report_verdict_held(publishers, commands, case, scenario::Held::Kept).0
}

/// [`report_verdict`] on the model built with `held`, with the board tasks' names (`<board>/<task>`).
fn report_verdict_held(
    publishers: &[(String, &str, u64)],
    commands: &[(&str, &str, u64, u64)],
    case: u64,
    held: scenario::Held<'_>,
) -> (bool, Vec<String>) {
    let json = serde_json::json!({
        "name": "admission-property",
        "publishers": publishers.iter().map(|(t, l, p)| serde_json::json!({
            "topic": t, "priority": l, "period_us": p })).collect::<Vec<_>>(),
        "commands": commands.iter().map(|(t, l, p, j)| serde_json::json!({
            "topic": t, "priority": l, "period_us": p, "jitter_us": j })).collect::<Vec<_>>(),
    });
    let (ok, _, names) = report_held(&json, &format!("prop-{case}"), held);
    (ok, names)
}

/// The report's `--check` verdict for publishers and one-shots (`one_shots` of a scenario file), and its notes.
fn report_verdict_with_one_shots(
    publishers: &[(&str, &str, u64)],
    one_shots: &[(&str, &str)],
    case: &str,
) -> (bool, Vec<String>) {
    let json = serde_json::json!({
        "name": "admission-one-shots",
        "publishers": publishers.iter().map(|(t, l, p)| serde_json::json!({
            "topic": t, "priority": l, "period_us": p })).collect::<Vec<_>>(),
        "one_shots": one_shots.iter().map(|(t, l)| serde_json::json!({
            "topic": t, "priority": l })).collect::<Vec<_>>(),
    });
    report_of(&json, &format!("once-{case}"))
}

/// A one-shot is decided on the boards as a sample every `ONE_SHOT_INTERVAL_MS` at its level; the report's
/// `one_shots` analyse the same configuration, and say so. Every publishable topic at every level, one-shot beside
/// the thesis example (magnetometer-x at medium every 900 µs) and odometry at low every 10 ms.
#[test]
fn one_shots_are_decided_as_the_report_analyses_them() {
    let robot = robot();
    let interval = Time::from_us(u64::from(amiro_can::ONE_SHOT_INTERVAL_MS) * 1000);
    let running = [
        ("magnetometer-x", "medium", 900u64),
        ("odometry", "low", 10_000),
    ];
    let streams = publisher_streams(running.iter().copied());
    let mut refused = 0;
    for topic in publishable() {
        if running.iter().any(|(t, _, _)| *t == topic) {
            continue;
        }
        for level in LEVELS {
            let request = robot
                .publisher_stream(&topic, level, interval, None)
                .expect("one-shot stream");
            let decision = robot
                .with_table(|table| admission::admit::<48, 32>(table, &streams, &request, false));
            let (report, notes) = report_verdict_with_one_shots(
                &running,
                &[(&topic, level)],
                &format!("{topic}-{level}"),
            );
            assert_eq!(
                decision.admitted(),
                report,
                "one-shot {topic} at {level}: the check says {:?}, the report {report}",
                decision.refusal
            );
            assert!(
                notes
                    .iter()
                    .any(|n| n.contains(&format!("one-shot {topic} at {level}"))
                        && n.contains(&format!("every {} µs", interval.as_ns() / 1000))),
                "the report does not say how it analysed the one-shot: {notes:?}"
            );
            refused += usize::from(!report);
        }
    }
    // Beside the thesis example the bus has room for some one-shots and not for others.
    assert!(refused > 0, "no one-shot refused: the test shows nothing");
}

/// The table's streams of these publishers (topic, level, period in µs).
fn publisher_streams<'a>(
    publishers: impl Iterator<Item = (&'a str, &'a str, u64)>,
) -> Vec<admission::Stream> {
    publishers
        .map(|(t, l, p)| {
            robot()
                .publisher_stream(t, l, Time::from_us(p), None)
                .expect("stream")
        })
        .collect()
}

fn publishable() -> Vec<String> {
    robot()
        .boards
        .iter()
        .flat_map(|b| b.topics.iter().map(|t| t.name.clone()))
        .collect()
}

fn admitted(
    publishers: &[(String, &str, u64)],
    commands: &[(&str, &str, u64, u64)],
) -> admission::Decision {
    admitted_on(robot(), publishers, commands)
}

/// [`admitted`] on `robot`'s table.
fn admitted_on(
    robot: &OwnedRobot,
    publishers: &[(String, &str, u64)],
    commands: &[(&str, &str, u64, u64)],
) -> admission::Decision {
    let mut streams: Vec<admission::Stream> = publishers
        .iter()
        .map(|(t, l, p)| {
            robot
                .publisher_stream(t, l, Time::from_us(*p), None)
                .expect("stream")
        })
        .collect();
    for (t, l, p, j) in commands {
        streams.push(
            robot
                .command_stream(t, l, Time::from_us(*p), Time::from_us(*j), None)
                .expect("command"),
        );
    }
    let request = streams.pop().expect("a request");
    robot.with_table(|table| admission::admit::<48, 32>(table, &streams, &request, false))
}

/// A kept analysis is found again: after a request replaced a running stream of its board (which a board keeps in
/// that stream's place), and after a request that moves the analysis horizon (a period above 60 ms), the next
/// decision analyses only its own board — and decides as the check without a cache does.
#[test]
fn a_decision_redoes_only_its_own_board() {
    let robot = robot();
    let mut running = publisher_streams(
        [("odometry", "low", 10_000), ("gyroscope", "medium", 5_000)].into_iter(),
    );
    let mut cache = admission::Cache::<32>::new();
    robot.with_table(|t| admission::refresh::<48, 32>(t, &running, &mut cache));
    let mut decide =
        |running: &mut Vec<admission::Stream>, topic: &str, level: &str, period_us: u64| {
            let request = robot
                .publisher_stream(topic, level, Time::from_us(period_us), None)
                .expect("stream");
            let plain =
                robot.with_table(|t| admission::admit::<48, 32>(t, running, &request, false));
            let cached = robot.with_table(|t| {
                admission::admit_cached::<48, 32>(t, running, &request, &mut cache, false)
            });
            assert_eq!(plain.refusal, cached.refusal, "{topic}");
            assert!(cached.admitted(), "{topic}: {:?}", cached.refusal);
            // Carried out as a board does (`Admission::upsert`): in the place of the stream it replaces.
            match running.iter().position(|s| {
                s.sender.map(|x| (x.board, x.topic)) == request.sender.map(|x| (x.board, x.topic))
            }) {
                Some(i) => running[i] = request,
                None => running.push(request),
            }
            (plain.boards, cached.boards)
        };
    // Odometry replaced in place on DiWheelDrive: its own board only.
    assert_eq!(decide(&mut running, "odometry", "low", 5_000), (3, 1));
    // A PowerManagement request next: DiWheelDrive's analysis of the replaced set holds.
    assert_eq!(
        decide(&mut running, "proximity-ring", "low", 60_000),
        (3, 1)
    );
    // The power status every 500 ms moves the horizon from 60 s to 500 s: no kept window reaches either.
    assert_eq!(decide(&mut running, "power-status", "low", 500_000), (3, 1));
    assert_eq!(decide(&mut running, "gyroscope", "medium", 4_000), (3, 1));
}

#[test]
fn preparation_steps_leave_a_decision_its_own_board_and_the_same_verdict() {
    let robot = robot();
    let running = publisher_streams(
        [
            ("odometry", "urgent", 800),
            ("gyroscope", "high", 1_000),
            // Schedulable (8 ms was until PowerManagement's transmit interrupt was charged by its parts: its ring
            // job and frames then miss at 8 ms).
            ("proximity-ring", "low", 10_000),
        ]
        .into_iter(),
    );
    // Nothing kept yet (as after boot without `prepare`, or when a request moves the horizon past what the kept
    // windows allow): every board but the request's own is analysed first, one per step, each once.
    let mut cache = admission::Cache::<32>::new();
    let power = robot
        .boards
        .iter()
        .position(|b| b.name == "powermgmt")
        .expect("powermgmt");
    for (topic, period_us) in [("power-status", 90_000_000), ("power-status", 5_000)] {
        let request = robot
            .publisher_stream(topic, "low", Time::from_us(period_us), None)
            .expect("stream");
        let mut prepared = Vec::new();
        let mut from = 0;
        while let Some((board, iterations)) = robot.with_table(|t| {
            admission::refresh_one::<48, 32>(t, &running, Some(&request), &mut cache, from)
        }) {
            assert!(iterations <= admission::DECISION_ITERATIONS);
            assert!(
                !prepared.contains(&board) && board != power,
                "{prepared:?} then {board}"
            );
            prepared.push(board);
            from = board + 1;
        }
        if period_us == 90_000_000 {
            assert_eq!(
                prepared.len(),
                robot.boards.len() - 1,
                "every other board, once"
            );
        }
        let cached = robot.with_table(|t| {
            admission::admit_cached::<48, 32>(t, &running, &request, &mut cache, false)
        });
        let plain = robot.with_table(|t| admission::admit::<48, 32>(t, &running, &request, false));
        assert_eq!(cached.refusal, plain.refusal, "{period_us} µs");
        assert_eq!(cached.floor, plain.floor, "{period_us} µs");
        assert_eq!(cached.boards, 1, "{period_us} µs: prepared {prepared:?}");
    }
}

#[test]
fn the_table_lowers_and_emits_rust() {
    let robot = robot();
    assert_eq!(
        robot.boards.first().map(|b| b.name.as_str()),
        Some("diwheeldrive")
    );
    let dwd = &robot.boards[0];
    assert_eq!(
        dwd.topics.len(),
        9,
        "DiWheelDrive's eight sensor topics and its diagnostics"
    );
    assert!(dwd.levels.iter().all(Option::is_some));
    assert!(dwd.monotonic.is_some() && dwd.can_tx.is_some() && dwd.command_handler.is_some());
    let source = robot.to_rust_source("schedule_analysis");
    syn::parse_file(&source)
        .unwrap_or_else(|e| panic!("generated source does not parse: {e}\n{source}"));
    assert!(source.contains("pub static ROBOT: schedule_analysis::admission::RobotTable<'static>"));
    assert!(source.contains("pub const BOARD_DIWHEELDRIVE: u8 = 0;"));
    // Every fixed task's share, worked out when the table is built, is the one the check would work out itself.
    let mut precomputed = 0;
    for board in &robot.boards {
        for row in &board.tasks {
            if row.own_frame || row.share == admission::SHARE_AT_RUNTIME {
                assert!(row.own_frame || row.period == 0, "{}: {row:?}", board.name);
                continue;
            }
            let exact = Share::of(
                admission::row_time(row.cost),
                admission::row_time(row.period),
            );
            assert_eq!(
                u64::from(row.share),
                exact.utilisation(),
                "{}: {row:?}",
                board.name
            );
            precomputed += 1;
        }
    }
    assert!(precomputed > 20, "{precomputed}");
    // And so is every priority's blocking by the fixed tasks' sections, for every priority a job of the board has.
    for board in &robot.boards {
        for (p, &b) in board.blocking.iter().enumerate() {
            assert_eq!(
                b,
                admission::fixed_blocking(&board.sections, p as u32),
                "{} at {p}",
                board.name
            );
        }
        let highest = board
            .tasks
            .iter()
            .map(|t| t.priority)
            .chain(board.levels.iter().flatten().copied())
            .chain(board.monotonic.map(|m| m.priority));
        for p in highest {
            assert!(
                usize::from(p) < board.blocking.len(),
                "{}: priority {p}",
                board.name
            );
        }
        assert!(board.blocking.iter().any(|&b| b > 0), "{}", board.name);
    }
    // A zero period is an overload the check must see for itself: no share in the table for it.
    assert_eq!(admission::row_share(5, 0), admission::SHARE_AT_RUNTIME);
    assert_eq!(admission::row_share(0, 0), 0);
}

/// The scenario at `path` as built from the shipped timing files, and the report's analysis of it (exact frames).
fn shipped_report(
    root: &std::path::Path,
    path: &std::path::Path,
) -> (scenario::Built, schedule_analysis::analysis::Analysis) {
    let built = scenario::build(root, path, &scenario::timing_files(root)).expect("builds");
    let report = analyse(
        &built.model.validate().expect("valid"),
        &Options {
            frame_cost: FrameCostSpec::Exact,
            horizon: None,
        },
    );
    (built, report)
}

#[test]
fn the_thesis_example_is_refused_by_both_and_the_starvation_request_refused() {
    // The thesis's worked example, magnetometer-x at medium every 900 µs: on the sound transmit path its frames take
    // 1 115.3 µs (2026-12-05) against their 900 µs deadline (the period), so the report and the chip refuse it alike (the
    // scenario `thesis-magnetometer-900us` keeps it as a checked refusal). At 6 000 µs both admit it on 1-1 (the
    // models folder's budgets), whose publisher rows are the machine code's since 2026-12-06: the polled HMC5883L
    // makes a magnetometer-x job 1 353.4 µs (3 103.9 µs before its reads' transaction caps and one bus clear a
    // release), and the shortest period alone 2 710 µs (5 216 µs before; 1 200 µs was admitted before the machine
    // code's rows).
    let magnetometer = [("magnetometer-x".to_string(), "medium", 900)];
    assert!(!report_verdict(&magnetometer, &[], 1_000_001));
    let d = admitted(&magnetometer, &[]);
    // On 1-1 the job alone overloads DiWheelDrive (188.3 % of its CPU): the check names one of its tasks, unbounded
    // (the admission task, the first in table order the report finds unbounded too).
    match d.refusal {
        Some(Refusal::Deadline(v)) => {
            assert!(
                matches!(v.culprit, Culprit::Task { board: 0, .. }),
                "{:?}",
                v.culprit
            );
            assert!(v.wcrt.is_none_or(|w| w > v.deadline), "{v:?}");
        }
        other => panic!("{other:?}"),
    }
    let slower = [("magnetometer-x".to_string(), "medium", 7_000)];
    assert!(report_verdict(&slower, &[], 1_000_002));
    let d = admitted(&slower, &[]);
    assert!(d.admitted(), "{d:?}");
    assert!(d.iterations > 0 && d.evaluations == 1);

    // Issue 11: accelerometer every 1 µs at urgent priority starved every other publisher.
    let robot = robot();
    let running = [robot
        // Every 3 ms (2 ms until DiWheelDrive's transmit jobs became rows, 2026-12-06: beside it no accelerometer
        // period at urgent passes, in the report as on the chip, and the gyroscope alone needs 1 519 µs).
        .publisher_stream("gyroscope", "high", Time::from_us(3000), None)
        .expect("gyroscope")];
    let request = robot
        .publisher_stream("accelerometer", "urgent", Time::from_us(1), None)
        .expect("accelerometer");
    let d = robot.with_table(|t| admission::admit::<48, 32>(t, &running, &request, true));
    match d.refusal {
        Some(Refusal::Deadline(v)) => {
            assert!(matches!(
                v.culprit,
                Culprit::Task { board: 0, .. } | Culprit::Frame { .. }
            ));
            assert!(v.wcrt.is_none_or(|w| w > v.deadline));
        }
        other => panic!("{other:?}"),
    }
    // What would be accepted: the shortest period at urgent passes, 1 µs less does not (or is not expressible).
    let shortest = d.suggestion.shortest_period.expect("a period passes");
    let mut at = request;
    at.period = shortest;
    assert!(robot
        .with_table(|t| admission::admit::<48, 32>(t, &running, &at, false))
        .admitted());
    at.period = shortest.minus(Time::from_us(1));
    assert!(!robot
        .with_table(|t| admission::admit::<48, 32>(t, &running, &at, false))
        .admitted());
}

#[test]
fn the_shipped_scenarios_agree() {
    let root = root();
    for name in ["thesis-demo", "thesis-magnetometer-900us"] {
        let path = scenario::find_scenario(&root, name);
        let text = std::fs::read_to_string(&path).expect("scenario");
        let sc: scenario::Scenario = serde_json::from_str(&text).expect("parses");
        let robot = robot();
        let mut streams = robot.scenario_streams(&sc).expect("streams");
        let request = streams.pop().expect("request");
        let d = robot.with_table(|t| admission::admit::<48, 32>(t, &streams, &request, false));
        let (built, report) = shipped_report(&root, &path);
        // The shipped scenarios have jitter budgets the on-chip check does not know; they pass anyway, but for a
        // checked refusal (the 900 µs set's frames late on the sound transmit path), which the chip refuses too.
        assert_eq!(report.failures(), built.expected_failures, "{name}");
        assert_eq!(
            d.admitted(),
            built.expected_failures.is_empty(),
            "{name}: {d:?}"
        );
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, .. ProptestConfig::default() })]

    #[test]
    fn admission_equals_the_report(
        picks in proptest::collection::vec((any::<prop::sample::Index>(), 0usize..4, 0u32..1000), 1..7),
        command in proptest::option::of((0usize..4, 1_000u64..50_000, 0u64..2_000)),
        case in any::<u64>(),
    ) {
        let topics = publishable();
        let mut publishers: Vec<(String, &str, u64)> = Vec::new();
        for (index, level, scale) in picks {
            let topic = index.get(&topics).clone();
            if publishers.iter().any(|(t, _, _)| *t == topic) {
                continue;
            }
            // Periods log-uniform from 100 µs to 100 ms: both sides of the boundary.
            let period = (100.0 * 1000f64.powf(f64::from(scale) / 1000.0)).round() as u64;
            publishers.push((topic, LEVELS[level], period));
        }
        let commands: Vec<(&str, &str, u64, u64)> = command
            .map(|(level, period, jitter)| vec![("motor", LEVELS[level], period, jitter)])
            .unwrap_or_default();
        let report = report_verdict(&publishers, &commands, case);
        let decision = admitted(&publishers, &commands);
        prop_assert_eq!(decision.admitted(), report, "publishers {:?} commands {:?}: {:?}", publishers, commands, decision);
    }

    /// The same with LightRing's transmit interrupt charged by its parts, a LightRing topic always among the
    /// publishers (the report's `can_tx[<topic>]` jobs, the check's transmit jobs): the check admits exactly
    /// what the report finds schedulable.
    #[test]
    fn admission_equals_the_report_with_the_transmit_interrupt_by_its_parts(
        lightring in (any::<prop::sample::Index>(), 0usize..4, 0u32..1000),
        picks in proptest::collection::vec((any::<prop::sample::Index>(), 0usize..4, 0u32..1000), 0..6),
        command in proptest::option::of((0usize..4, 1_000u64..50_000, 0u64..2_000)),
        case in any::<u64>(),
    ) {
        let robot = robot_by_parts();
        let own: Vec<String> = robot
            .boards
            .iter()
            .filter(|b| b.name == "lightring")
            .flat_map(|b| b.topics.iter().map(|t| t.name.clone()))
            .collect();
        let topics = publishable();
        let mut publishers: Vec<(String, &str, u64)> = Vec::new();
        let period = |scale: u32| (100.0 * 1000f64.powf(f64::from(scale) / 1000.0)).round() as u64;
        for (i, (index, level, scale)) in std::iter::once(lightring).chain(picks).enumerate() {
            let topic = if i == 0 { index.get(&own) } else { index.get(&topics) }.clone();
            if publishers.iter().any(|(t, _, _)| *t == topic) {
                continue;
            }
            publishers.push((topic, LEVELS[level], period(scale)));
        }
        let commands: Vec<(&str, &str, u64, u64)> = command
            .map(|(level, period, jitter)| vec![("motor", LEVELS[level], period, jitter)])
            .unwrap_or_default();
        let (report, names) = report_verdict_held(&publishers, &commands, case, by_parts());
        prop_assert!(
            names.iter().any(|n| n.starts_with("lightring/can_tx[") && !n.ends_with("[mailboxes]")),
            "the report charges no LightRing publisher's frames: {:?}", names
        );
        let decision = admitted_on(robot, &publishers, &commands);
        prop_assert_eq!(decision.admitted(), report, "publishers {:?} commands {:?}: {:?}", publishers, commands, decision);
    }
}

/// The set on which the check and the report were apart before the check built the transmit jobs (odometry at
/// high every 10 ms, LightRing's diagnostics at urgent every 50 ms) and LightRing's publishers alone: with the
/// transmit interrupt charged by its parts both agree, and the table carries each LightRing topic's transmit job.
#[test]
fn the_transmit_jobs_are_in_the_table_and_decide_as_the_report() {
    let robot = robot_by_parts();
    let lightring = robot
        .boards
        .iter()
        .find(|b| b.name == "lightring")
        .expect("lightring");
    assert!(
        !lightring.topics.is_empty() && lightring.topics.iter().all(|t| t.transmit > 0),
        "{:?}",
        lightring.topics
    );
    // Where the transmit interrupt is used (every board's: LightRing's here, PowerManagement's and DiWheelDrive's as
    // shipped, DiWheelDrive's since 2026-12-06), every topic has a transmit job.
    for board in &robot.boards {
        assert!(board.topics.iter().all(|t| t.transmit > 0), "{board:?}");
    }
    let sets: [&[(&str, &str, u64)]; 3] = [
        &[
            ("odometry", "high", 10_000),
            ("lightring-diagnostics", "urgent", 50_000),
        ],
        &[("lightring-diagnostics", "urgent", 50_000)],
        &[("lightring-diagnostics", "low", 1_000)],
    ];
    for (case, set) in sets.iter().enumerate() {
        let owned: Vec<(String, &str, u64)> = set
            .iter()
            .map(|(t, l, p)| (t.to_string(), *l, *p))
            .collect();
        let (report, names) = report_verdict_held(&owned, &[], 7_000 + case as u64, by_parts());
        assert!(
            names
                .iter()
                .any(|n| n == "lightring/can_tx[lightring-diagnostics]"),
            "{names:?}"
        );
        let decision = admitted_on(robot, &owned, &[]);
        assert_eq!(decision.admitted(), report, "{set:?}: {decision:?}");
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 32, .. ProptestConfig::default() })]

    /// The on-chip check keeps each board's last analysis between decisions: a sequence of requests decided with
    /// the cache gets exactly the decisions (refusal and its reason) of the check without it.
    #[test]
    fn the_cache_changes_no_decision(
        requests in proptest::collection::vec((any::<prop::sample::Index>(), 0usize..4, 0u32..1000, any::<bool>()), 1..24),
    ) {
        let robot = robot();
        let topics = publishable();
        let mut running: Vec<admission::Stream> = Vec::new();
        let mut cache = admission::Cache::<32>::new();
        for (index, level, scale, stop) in requests {
            let topic = index.get(&topics);
            if stop {
                // A stop leaves the set (and changes that board's inputs); sometimes the cache is brought up to date.
                running.retain(|s| robot.publisher_stream(topic, LEVELS[level], Time::from_us(1000), None)
                    .is_some_and(|r| r.sender.map(|x| (x.board, x.topic)) != s.sender.map(|x| (x.board, x.topic))));
                if level % 2 == 0 {
                    robot.with_table(|t| admission::refresh::<48, 32>(t, &running, &mut cache));
                }
                continue;
            }
            let period = (100.0 * 1000f64.powf(f64::from(scale) / 1000.0)).round() as u64;
            let request = robot
                .publisher_stream(topic, LEVELS[level], Time::from_us(period), None)
                .expect("stream");
            let plain = robot.with_table(|t| admission::admit::<48, 32>(t, &running, &request, false));
            let cached = robot.with_table(|t| admission::admit_cached::<48, 32>(t, &running, &request, &mut cache, false));
            prop_assert_eq!(plain.refusal, cached.refusal, "{} at {} µs {}", topic, period, LEVELS[level]);
            prop_assert_eq!(plain.floor, cached.floor, "the hard floor: {} at {} µs {}", topic, period, LEVELS[level]);
            prop_assert!(cached.iterations <= plain.iterations);
            if plain.admitted() {
                running.retain(|s| s.sender.map(|x| (x.board, x.topic)) != request.sender.map(|x| (x.board, x.topic)));
                running.push(request);
            }
        }
    }
}

/// A topic's sections block at every level it runs at: on DiWheelDrive 1-1 (the machine code's publisher rows) the
/// gyroscope's SPI sample holds a lock at priority 4 for 74.75 µs (89.15 µs when found, its SPI waits then at 2 µs a byte), which a publisher job at urgent (priority 4) never
/// raises but one at low does, blocking the magnetometer at medium. The table once kept the urgent job's sections
/// only, and admitted magnetometer-x every 5 300 µs beside a gyroscope one-shot at low (every 40 ms) where the report
/// put 0x605 at 5 344.4 µs (5 358.8 when found with the QEMU scenario admission-one-shots, 2026-12-06). With the
/// transaction caps of the HMC5883L's reads and one bus clear a release (docs/analysis.md, "The bus transaction's
/// cap") and DiWheelDrive's transmit jobs as rows (its `can_tx` used) the pair is taken every 3 700 µs: the
/// magnetometer alone needs 3 572 µs, beside the gyroscope at low 3 818 µs, so without the gyroscope's section it
/// would fit (`report_verdict` searched, 2026-12-06).
#[test]
fn a_topics_sections_block_at_every_level() {
    let set = [
        ("magnetometer-x".to_string(), "medium", 3_700),
        ("gyroscope".to_string(), "low", 40_000),
    ];
    assert!(!report_verdict(&set, &[], 4_242));
    let d = admitted(&set, &[]);
    match d.refusal {
        Some(Refusal::Deadline(v)) => {
            assert_eq!(v.culprit, Culprit::Frame { id: 0x605 });
            assert!(v.wcrt.is_some_and(|w| w > Time::from_us(3_700)), "{v:?}");
        }
        other => panic!("{other:?}"),
    }
    let robot = robot();
    let gyroscope = robot.boards[0]
        .topics
        .iter()
        .find(|t| t.name == "gyroscope")
        .expect("gyroscope");
    assert!(
        gyroscope.sections.iter().any(|s| s.ceiling == 4),
        "{:?}",
        gyroscope.sections
    );
}
