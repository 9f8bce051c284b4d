//! The monotonic's interrupt charged per expiry (the generated row's figures a charge per activation, the job's
//! bound beside them, docs/analysis.md "Held bounds"): where the row is bounded, its charge is the budget of
//! every timer job (`monotonic[<task>]`), in the report's analysis and in the table the boards' admission checks
//! carry alike — one analysis for both.

use std::path::{Path, PathBuf};

use schedule_analysis::admission_host::{self, OwnedRobot};
use schedule_analysis::model::FrameCostSpec;
use schedule_analysis::scenario::{self, BudgetFrom};

/// DiWheelDrive 1-1's charge per expiry and its job as `cargo xtask wcet` bounded them with rtic-time's timer queue
/// (1 174 and 5 990 cycles; the figures only need to be a bounded row's).
const CHARGE_US: f64 = 16.306;

mod common;

/// The charge's reason, as the generated row carries it.
const PER_ACTIVATION: &str =
    "TIM5 at cortex-m-0.7.10/src/register/primask.rs:48 at 3 passes: a job that serves k expiries costs at most k charges";

/// A workspace of its own: the boards' apps (linked) and a copy of the models folder, DiWheelDrive 1-1's generated
/// file with its `monotonic` row bounded per expiry when `charged`, held back (stated budget, named with why, as the
/// repository had it until 2026-12-04) otherwise: both rows written here, whatever the repository's row is.
fn workspace_with(name: &str, charged: bool) -> PathBuf {
    let root = common::scratch_workspace(&format!("monotonic-bounds-{name}"), None);
    let models = root.join(scenario::MODELS_DIR);
    let path = models.join("diwheeldrive-1-1.wcet.json");
    let mut file: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    let rows = file["tasks"].as_array_mut().unwrap();
    let row = rows
        .iter_mut()
        .find(|r| r["task"] == "monotonic")
        .expect("a monotonic row");
    let job = serde_json::json!({ "cycles": 5990, "us": 83.195, "instructions": 1826, "per_activation": PER_ACTIVATION });
    *row = if charged {
        serde_json::json!({
            "task": "monotonic", "cycles": 1174, "us": CHARGE_US, "instructions": 354, "bus_wait_us": 0.0,
            "declined": null, "job": job
        })
    } else {
        let reason = "charged per expiry: 1 174 cycles. The stated 3 µs (`timer_isr_us`) is below what the code can take.";
        serde_json::json!({
            "task": "monotonic", "cycles": null, "us": null, "instructions": null, "bus_wait_us": 0.0,
            "declined": format!("monotonic: bounded from the machine code at 1174 cycles ({CHARGE_US} µs, 354 instructions, bus waits 0 µs) per activation, held back as its budget: {reason}"),
            "held": { "cycles": 1174, "us": CHARGE_US, "instructions": 354, "bus_wait_us": 0.0, "reason": reason,
                      "sections": { "incomplete": null, "ceilings": [] }, "job": job }
        })
    };
    std::fs::write(&path, file.to_string()).unwrap();
    root
}

fn built(root: &Path) -> scenario::Built {
    scenario::build(
        root,
        &scenario::find_scenario(root, "thesis-demo"),
        &scenario::timing_files_for(root, Some("1-1")),
    )
    .unwrap_or_else(|e| panic!("{e}"))
}

fn table(root: &Path) -> OwnedRobot {
    admission_host::lower(
        root,
        &scenario::timing_files_for(root, Some("1-1")),
        schedule_analysis::can::DEFAULT_BITRATE,
        FrameCostSpec::Exact,
    )
    .unwrap_or_else(|e| panic!("{e}"))
}

fn timer_jobs(built: &scenario::Built) -> Vec<(String, f64)> {
    built
        .model
        .boards
        .iter()
        .find(|b| b.name == "diwheeldrive")
        .unwrap()
        .tasks
        .iter()
        .filter(|t| t.name.starts_with("monotonic["))
        .map(|t| (t.name.clone(), t.wcet_us))
        .collect()
}

#[test]
fn the_charge_per_expiry_is_every_timer_jobs_budget_in_the_report_and_on_the_chip() {
    let (held, charged) = (
        workspace_with("held", false),
        workspace_with("charged", true),
    );
    let (before, after) = (built(&held), built(&charged));
    // Held: the stated figure, named with why.
    match before.budget_from("diwheeldrive", "monotonic[handle_commands]") {
        Some(BudgetFrom::Stated { why }) => assert!(why.contains("held back"), "{why}"),
        other => panic!("{other:?}"),
    }
    // The report says so, on a line of its own: the stated figure is below what the code can take.
    let line = before
        .sources
        .iter()
        .find(|s| {
            s.starts_with("diwheeldrive: stated overhead of monotonic: bound declined: monotonic: ")
        })
        .expect("the held overhead's line");
    assert!(line.contains("below what the code can take"), "{line}");
    assert!(!after
        .sources
        .iter()
        .any(|s| s.starts_with("diwheeldrive: stated overhead of monotonic")));
    // Charged: every timer job has the charge in place of the stated 3 µs, not the job's 83.2 µs.
    let (stated, bounded) = (timer_jobs(&before), timer_jobs(&after));
    assert_eq!(stated.len(), 6, "{stated:?}");
    for ((name, s), (same, b)) in stated.iter().zip(&bounded) {
        assert_eq!(name, same);
        assert!(
            (b - s - (CHARGE_US - 3.0)).abs() < 1e-9,
            "{name}: {s} µs stated, {b} µs bounded"
        );
        assert!(matches!(
            after.budget_from("diwheeldrive", name),
            Some(BudgetFrom::Bound { us, .. }) if *us == CHARGE_US
        ));
    }
    // The admission table the board carries, lowered from the same files: the same charge, to the ns.
    // The fixed tasks' timer jobs are rows of their own; the publishers' share the board's timer row.
    let cost = |robot: &OwnedRobot, name: &str| {
        let board = robot
            .boards
            .iter()
            .find(|b| b.name == "diwheeldrive")
            .unwrap();
        let i = board.task_names.iter().position(|n| n == name)?;
        Some(board.tasks[i].cost)
    };
    let (stated_table, bounded_table) = (table(&held), table(&charged));
    let mut fixed = 0;
    for (name, _) in &stated {
        if let (Some(s), Some(b)) = (cost(&stated_table, name), cost(&bounded_table, name)) {
            assert_eq!(b - s, 13_306, "{name}: the row's cost in ns");
            fixed += 1;
        }
    }
    assert_eq!(
        fixed, 4,
        "handle_commands, admit_requests, motor_control, watchdog"
    );
    let monotonic = |robot: &OwnedRobot| {
        robot
            .boards
            .iter()
            .find(|b| b.name == "diwheeldrive")
            .unwrap()
            .monotonic
            .expect("the publishers' timer row")
            .cost
    };
    assert_eq!(monotonic(&bounded_table) - monotonic(&stated_table), 13_306);
    for root in [held, charged] {
        let _ = std::fs::remove_dir_all(root);
    }
}
