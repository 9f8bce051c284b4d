//! Known answers for the transmit interrupt charged by its parts (docs/analysis.md, "The transmit interrupt's
//! parts"): where DiWheelDrive's `can_tx` row carries parts, the model has one frame's job at the own-frame rate,
//! a job per job of each task that queues frames (released by it: the fixed part and, per frame, an abort with its
//! own job), and the fills of the three mailboxes once per window; a task that shares the transmit queue but whose
//! frames the timing file does not state is refused.

use std::path::{Path, PathBuf};

use schedule_analysis::bounds::GENERATED_PREFIX;
use schedule_analysis::model::TaskModel;
use schedule_analysis::scenario;

mod common;

/// DiWheelDrive 1-1's bounds with `can_tx` charged by its parts when `parts`: fixed 30 µs (2 160 cycles), per frame
/// 16 µs (1 152), per abort 34 µs (2 448); one frame's job 46 µs.
fn bounds(parts: bool) -> serde_json::Value {
    let mut job = serde_json::json!({
        "cycles": 13_968, "us": 194.0, "instructions": 4490,
        "per_activation": "USB_HP_CAN_TX at amiro-sensors/src/tx_queue.rs:372 by its parts: a job costs at most its parts"
    });
    if parts {
        job["parts"] = serde_json::json!({
            "fixed_cycles": 2160, "fixed_us": 30.0, "per_frame_cycles": 1152, "per_frame_us": 16.0,
            "abort_cycles": 2448, "abort_us": 34.0
        });
    }
    serde_json::json!({
        "generated": format!("{GENERATED_PREFIX} from target/firmware/diwheeldrive-1-1.elf; do not edit"),
        "board": "diwheeldrive", "revision": "1-1", "chip": "stm32f103",
        "clock_hz": 72_000_000, "wait_states": 2,
        "image": { "code_sha256": "ab".repeat(32), "code_bytes": 41_000 },
        "tasks": [
            { "task": "can_tx", "cycles": 3312, "us": 46.0, "instructions": 1189, "bus_wait_us": 0.0,
              "declined": null, "job": job }
        ]
    })
}

fn build(root: &Path) -> Result<scenario::Built, scenario::BuildError> {
    scenario::build(
        root,
        &scenario::find_scenario(root, "thesis-magnetometer-900us"),
        &scenario::timing_files_for(root, Some("1-1")),
    )
}

fn dwd(built: &scenario::Built) -> &[TaskModel] {
    &built
        .model
        .boards
        .iter()
        .find(|b| b.name == "diwheeldrive")
        .unwrap()
        .tasks
}

fn find<'a>(tasks: &'a [TaskModel], name: &str) -> Option<&'a TaskModel> {
    tasks.iter().find(|t| t.name == name)
}

fn workspace(tag: &str, parts: bool) -> PathBuf {
    common::scratch_workspace(&format!("transmit-parts-{tag}"), Some(&bounds(parts)))
}

#[test]
fn the_transmit_interrupt_is_charged_per_frame_per_queueing_job_and_once_per_window() {
    let root = workspace("charged", true);
    let built = build(&root).expect("the model builds");
    let tasks = dwd(&built);
    let tx = find(tasks, "can_tx").expect("can_tx");
    // One frame's job, at the board's own frames' rate (magnetometer-x: 4 bytes, 79 bits unstuffed at 1 Mbit/s).
    assert_eq!(tx.wcet_us, 46.0);
    assert_eq!(tx.period_us, 79.0);
    // The command handler queues no frames (its busy verdict is the admission task's to send): no row.
    assert!(find(tasks, "can_tx[handle_commands]").is_none());
    // The admission task's verdict: 2 frames, at its busy verdicts' spacing (the timing file's `at_least_us`, one
    // per one-shot interval counted from the send), more often than the task's stated 240 ms.
    let admission = find(tasks, "can_tx[admit_requests]").expect("the admission's row");
    assert_eq!(admission.wcet_us, 190.0);
    assert_eq!(admission.period_us, 39_936.0);
    assert!(admission.period_us < find(tasks, "admit_requests").unwrap().period_us);
    assert!(admission.sporadic);
    // The publisher job of magnetometer-x: one frame a sample, 30 + 80 = 110 µs, every 900 µs.
    let publisher = find(tasks, "can_tx[magnetometer-x]").expect("the publisher job's row");
    assert_eq!(publisher.wcet_us, 110.0);
    assert_eq!(publisher.period_us, 900.0);
    assert!(publisher
        .released_by
        .as_deref()
        .is_some_and(|r| r.ends_with("[magnetometer-x]")));
    // The fills of the three mailboxes once per window.
    let mailboxes = find(tasks, "can_tx[mailboxes]").expect("the mailboxes' row");
    assert_eq!(mailboxes.wcet_us, 48.0);
    assert_eq!(mailboxes.period_us, 1_000_000.0);
    // shutdown_sequence queues no frames: no row.
    assert!(find(tasks, "can_tx[shutdown_sequence]").is_none());
    assert!(built
        .sources
        .iter()
        .any(|s| s.starts_with("diwheeldrive: `can_tx` charged by its parts")));
}

#[test]
fn a_task_whose_frame_queueing_jobs_are_spaced_gets_a_row_at_that_spacing() {
    // A task that queues two frames in jobs at least 39 936 µs apart (as the command handler's busy verdicts were):
    // the fixed part and per frame an abort with its own job, 30 + 2 × (30 + 16 + 34) = 190 µs, at that spacing;
    // released by the task, its abort latency three 8-byte frames of 135 µs.
    let root = workspace("spaced", true);
    let timing = root
        .join(scenario::MODELS_DIR)
        .join("diwheeldrive.timing.json");
    let text = std::fs::read_to_string(&timing).unwrap();
    let mut json: serde_json::Value = serde_json::from_str(&text).unwrap();
    json["tasks"]["can_tx"]["queued_by"]["handle_commands"] =
        serde_json::json!({ "frames": 2, "at_least_us": 39936 });
    std::fs::write(&timing, json.to_string()).unwrap();
    let built = build(&root).expect("the model builds");
    let tasks = dwd(&built);
    let tx = find(tasks, "can_tx").expect("can_tx");
    let handler = find(tasks, "can_tx[handle_commands]").expect("the handler's row");
    assert_eq!(handler.wcet_us, 190.0);
    assert_eq!(handler.period_us, 39_936.0);
    assert_eq!(handler.jitter_us, 405.0);
    assert_eq!(handler.released_by.as_deref(), Some("handle_commands"));
    assert_eq!(handler.priority, tx.priority);
    assert_eq!(handler.job_of.as_deref(), Some("can_tx"));
}

#[test]
fn a_row_without_parts_adds_no_jobs() {
    let root = workspace("whole", false);
    let built = build(&root).expect("the model builds");
    let tasks = dwd(&built);
    assert_eq!(find(tasks, "can_tx").unwrap().wcet_us, 46.0);
    assert!(!tasks.iter().any(|t| t.name.starts_with("can_tx[")));
}

#[test]
fn a_task_sharing_the_queue_whose_frames_are_not_stated_is_refused() {
    let root = workspace("unstated", true);
    let timing = root
        .join(scenario::MODELS_DIR)
        .join("diwheeldrive.timing.json");
    let text = std::fs::read_to_string(&timing).unwrap();
    let mut json: serde_json::Value = serde_json::from_str(&text).unwrap();
    json["tasks"]["can_tx"]["queued_by"]
        .as_object_mut()
        .unwrap()
        .remove("admit_requests");
    std::fs::write(&timing, json.to_string()).unwrap();
    let err = build(&root).expect_err("refused").to_string();
    assert!(err.contains("tasks.can_tx.queued_by"), "{err}");
    assert!(err.contains("admit_requests"), "{err}");
}
