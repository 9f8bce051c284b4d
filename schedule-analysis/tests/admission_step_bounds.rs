//! The figures the boards' bounds files state for the admission step's loops (schedule-analysis/models/
//! <board>.bounds.json, docs/analysis.md "The admission step's bound"), held against the tables the boards carry:
//! a table that outgrows them (more fixed tasks, or release chains that take more rounds) fails here, so the
//! statements cannot silently become false.

use std::path::{Path, PathBuf};

use schedule_analysis::admission::{DECISION_ITERATIONS, NO_RELEASER};
use schedule_analysis::admission_host::{self, OwnedRobot};
use schedule_analysis::board_analysis::MAX_JITTER_ROUNDS;
use schedule_analysis::model::FrameCostSpec;
use schedule_analysis::scenario;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map(Path::to_path_buf)
        .expect("workspace root")
}

/// The table of a robot of each revision the images are built for.
fn tables() -> Vec<(String, OwnedRobot)> {
    let root = root();
    [None, Some("1-1"), Some("1-2")]
        .into_iter()
        .map(|revision| {
            let files = scenario::timing_files_for(&root, revision);
            let robot = admission_host::lower(
                &root,
                &files,
                schedule_analysis::can::DEFAULT_BITRATE,
                FrameCostSpec::Exact,
            )
            .unwrap_or_else(|e| panic!("{e}"));
            (revision.unwrap_or("default").to_string(), robot)
        })
        .collect()
}

#[test]
fn the_tables_are_within_the_capacities_the_bounds_files_state() {
    for (revision, robot) in tables() {
        assert_eq!(robot.max_tasks(), 43, "{revision}: MAX_TASKS");
        assert_eq!(robot.max_publishers(), 13, "{revision}: MAX_PUBLISHERS");
        assert_eq!(robot.boards.len(), 3, "{revision}: the robot's boards");
        for board in &robot.boards {
            let at = format!("{revision} {}", board.name);
            assert!(board.name.len() <= 12, "{at}: folder names up to 12 bytes");
            assert!(board.tasks.len() <= 17, "{at}: 17 fixed tasks at most");
            assert!(board.topics.len() <= 9, "{at}: 9 topics at most");
            assert!(board.sections.len() <= 23, "{at}: 23 sections at most");
            // The shipped images do not link the sensor-bus rounds (admission/board/suspension.rs, feature
            // `sensor-buses`) and the bounds files state none of their loops: a board that states sensor buses or
            // scripts must state them first (docs/analysis.md, "The chip's check with scripts").
            assert!(
                board.buses.is_empty()
                    && board.task_scripts.is_empty()
                    && board.topics.iter().all(|t| t.scripts.is_empty()),
                "{at}: no sensor buses and no scripts (the bounds files state no loop of the rounds)"
            );
            for topic in &board.topics {
                assert!(
                    topic.sections.len() <= 6,
                    "{at} {}: 6 sections at most",
                    topic.name
                );
            }
        }
    }
}

/// The rounds one board analysis of the tables may take (`board_analysis::analyse`): one pass when every job that
/// another releases is less urgent than its releaser (a fixed task's releaser by the table, a publisher job's —
/// released by its timer job — by the monotonic's priority above every publisher level, a topic's transmit job's —
/// released by its publisher job — by the transmit interrupt's priority below every publisher level), the first
/// pass then settling the inherited jitters; else up to `MAX_JITTER_ROUNDS`.
fn rounds_needed(robot: &OwnedRobot) -> usize {
    let mut rounds = 1;
    for board in &robot.boards {
        for task in &board.tasks {
            let releaser = board.tasks.get(usize::from(task.released_by));
            if task.released_by != NO_RELEASER
                && releaser.is_none_or(|r| r.priority <= task.priority)
            {
                rounds = MAX_JITTER_ROUNDS;
            }
        }
        if let Some(monotonic) = board.monotonic {
            if board
                .levels
                .iter()
                .flatten()
                .any(|&level| level >= monotonic.priority)
            {
                rounds = MAX_JITTER_ROUNDS;
            }
        }
        let transmit = board.can_tx.and_then(|i| board.tasks.get(usize::from(i)));
        if let Some(tx) = transmit.filter(|_| board.topics.iter().any(|t| t.transmit > 0)) {
            if board
                .levels
                .iter()
                .flatten()
                .any(|&level| level <= tx.priority)
            {
                rounds = MAX_JITTER_ROUNDS;
            }
        }
    }
    rounds
}

/// The board analysis's stated totals per step (every bounds file's `totals` of `Pass::run`'s loops in
/// board_analysis.rs and of the fixed points in `board::response_time_in`) cover the rounds the tables need: 3
/// boards × rounds × `MAX_TASKS` jobs, each fixed point up to `DECISION_ITERATIONS` + 1 calls.
#[test]
fn the_bounds_files_state_the_release_rounds_the_tables_need() {
    let rounds = tables()
        .iter()
        .map(|(_, robot)| rounds_needed(robot))
        .max()
        .unwrap_or(1);
    // The files state the totals for MAX_JITTER_ROUNDS, which a table whose transmit interrupt is charged by its parts
    // needs (its rows released by the command handler, the admission task, the publisher jobs: every board's since
    // DiWheelDrive's `can_tx` is used, 2026-12-06), and the check below holds them to what today's tables need.
    assert!((1..=MAX_JITTER_ROUNDS).contains(&rounds), "{rounds}");
    let (boards, jobs) = (3, 43);
    for board in ["diwheeldrive", "lightring", "powermgmt"] {
        let path = root()
            .join(scenario::MODELS_DIR)
            .join(format!("{board}.bounds.json"));
        let file: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&path).expect("bounds file"))
                .expect("parses");
        let totals = file["totals"].as_array().expect("totals");
        let stated = |function: &str, file: &str| -> Vec<u64> {
            totals
                .iter()
                .filter(|t| t["function"] == function && t["file"] == file)
                .map(|t| t["passes"].as_u64().expect("passes"))
                .collect()
        };
        let passes = stated(
            "schedule_analysis::admission::board::run_view",
            "schedule-analysis/src/board_analysis.rs",
        );
        let fixed_points = stated(
            "schedule_analysis::board::response_time_in",
            "schedule-analysis/src/busy_window.rs",
        );
        // Pass::run's loops, enter_level's level sum and its in-pass releases (over the same jobs).
        assert_eq!((passes.len(), fixed_points.len()), (3, 2), "{board}");
        let per_job = boards * rounds as u64 * jobs;
        for p in passes {
            assert!(
                p >= per_job,
                "{board}: {p} passes stated, the tables need {per_job}"
            );
        }
        let iterations = per_job * (DECISION_ITERATIONS + 1);
        for p in fixed_points {
            assert!(
                p >= iterations,
                "{board}: {p} fixed-point iterations stated, the tables need {iterations}"
            );
        }
    }
}
