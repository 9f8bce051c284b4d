//! The figures the boards' bounds files state for the admission step's loops (schedule-analysis/models/
//! <board>.bounds.json, docs/analysis.md "The admission step's bound"), held against the tables the boards carry:
//! a table that outgrows them fails here, so the statements cannot silently become false.

use std::path::{Path, PathBuf};

use schedule_analysis::admission::NO_RELEASER;
use schedule_analysis::admission_host::{self, OwnedRobot};
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
        assert_eq!(robot.max_tasks(), 32, "{revision}: MAX_TASKS");
        assert_eq!(robot.max_publishers(), 13, "{revision}: MAX_PUBLISHERS");
        assert_eq!(robot.boards.len(), 3, "{revision}: the robot's boards");
        for board in &robot.boards {
            let at = format!("{revision} {}", board.name);
            assert!(board.name.len() <= 12, "{at}: folder names up to 12 bytes");
            assert!(board.tasks.len() <= 14, "{at}: 14 fixed tasks at most");
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

/// Every job that another releases is less urgent than its releaser: a fixed task's releaser by the table, a
/// publisher job's (released by its timer job) by the monotonic's priority above every publisher level. Then the
/// board analysis settles the inherited jitters in one pass (`board_analysis::analyse`): what lets the bounds files
/// count one pass over a board's jobs per analysis.
#[test]
fn every_releaser_is_more_urgent_than_what_it_releases() {
    for (revision, robot) in tables() {
        for board in &robot.boards {
            let at = format!("{revision} {}", board.name);
            for (i, task) in board.tasks.iter().enumerate() {
                if task.released_by == NO_RELEASER {
                    continue;
                }
                let releaser = board
                    .tasks
                    .get(usize::from(task.released_by))
                    .unwrap_or_else(|| panic!("{at}: task {i}'s releaser is not a task"));
                assert!(
                    releaser.priority > task.priority,
                    "{at}: {} (priority {}) is released by {} (priority {})",
                    board.task_names[i],
                    task.priority,
                    board.task_names[usize::from(task.released_by)],
                    releaser.priority
                );
            }
            if let Some(monotonic) = board.monotonic {
                for level in board.levels.iter().flatten() {
                    assert!(
                        monotonic.priority > *level,
                        "{at}: a publisher level at {level} is not below the timer job's {}",
                        monotonic.priority
                    );
                }
            }
        }
    }
}
