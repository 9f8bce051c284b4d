//! The analysis rests on the generated bounds files: a bound (plus its stated bus waits) is the budget wherever
//! one exists, the stated estimate is kept where the bound was declined or is absent, the bounded critical
//! sections are the blocking terms, the report says how many budgets are bounded, and a file for another image
//! is refused naming its field.

use std::path::{Path, PathBuf};

use schedule_analysis::bounds::GENERATED_PREFIX;
use schedule_analysis::report::{self, Format, Report};
use schedule_analysis::scenario::{self, BudgetFrom};

mod common;

/// A workspace of its own with `bounds`, when given, as DiWheelDrive 1-1's bounds file.
fn workspace_with(name: &str, bounds: Option<serde_json::Value>) -> PathBuf {
    let root = common::scratch_workspace(&format!("machine-bounds-{name}"), bounds.as_ref());
    // The 900 µs set's frames at 1 500 µs: a set that passes on its stated budgets.
    common::passing_magnetometer_set(&root);
    root
}

/// Bounds for DiWheelDrive 1-1: `can_rx` bounded below its estimate with a bounded global critical section,
/// magnetometer-x's sample bounded with stated I2C waits, the admission task declined.
fn dwd_bounds() -> serde_json::Value {
    serde_json::json!({
        "generated": format!("{GENERATED_PREFIX} from target/firmware/diwheeldrive-1-1.elf; do not edit"),
        "board": "diwheeldrive", "revision": "1-1", "chip": "stm32f103",
        "clock_hz": 72_000_000, "wait_states": 2,
        "image": { "code_sha256": "ab".repeat(32), "code_bytes": 41_000 },
        "tasks": [
            { "task": "can_rx", "cycles": 216, "us": 3.0, "instructions": 150, "bus_wait_us": 0.0,
              "declined": null,
              "critical_sections": { "critical_section": { "cycles": 18, "us": 0.25, "declined": null } } },
            { "task": "publisher[magnetometer-x]", "cycles": 7200, "us": 100.0, "instructions": 4000,
              "bus_wait_us": 150.0, "declined": null },
            { "task": "admit_requests", "cycles": null, "us": null, "instructions": null,
              "declined": "loop in schedule_analysis::busy_window::fixed_point (busy_window.rs:300) has no bound" }
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

fn task<'a>(built: &'a scenario::Built, name: &str) -> &'a schedule_analysis::model::TaskModel {
    built
        .model
        .boards
        .iter()
        .find(|b| b.name == "diwheeldrive")
        .unwrap()
        .tasks
        .iter()
        .find(|t| t.name == name)
        .unwrap()
}

/// The report's source line that starts with `start`.
fn source<'a>(built: &'a scenario::Built, start: &str) -> &'a str {
    built
        .sources
        .iter()
        .find(|s| s.starts_with(start))
        .unwrap_or_else(|| panic!("no source line {start:?} in {:?}", built.sources))
}

#[test]
fn a_bound_is_the_budget_wherever_one_exists() {
    let root = workspace_with("bounded", Some(dwd_bounds()));
    let stated = build(&workspace_with("stated", None)).unwrap();
    let built = build(&root).unwrap();
    // Bounded: the bound, plus its bus waits; its bounded critical section.
    assert_eq!(task(&built, "can_rx").wcet_us, 3.0);
    assert_eq!(
        task(&built, "can_rx").critical_sections_us["critical_section"],
        0.25
    );
    assert_eq!(
        task(&built, "publish_medium[magnetometer-x]").wcet_us,
        250.0
    );
    // Declined or absent: the stated estimate.
    assert_eq!(
        task(&built, "admit_requests").wcet_us,
        task(&stated, "admit_requests").wcet_us
    );
    // Absent from this file: the timing file's stated 9 µs (the shipped generated file, which the workspace
    // without one keeps, bounds `can_tx` by its parts since 2026-12-06).
    assert_eq!(task(&built, "can_tx").wcet_us, 9.0);
    assert_ne!(
        task(&built, "can_rx").wcet_us,
        task(&stated, "can_rx").wcet_us
    );
    // Where each came from.
    assert!(matches!(
        built.budget_from("diwheeldrive", "publish_medium[magnetometer-x]"),
        Some(BudgetFrom::Bound { bus_wait_us, .. }) if *bus_wait_us == 150.0
    ));
    match built.budget_from("diwheeldrive", "admit_requests") {
        Some(BudgetFrom::Stated { why }) => {
            assert!(why.starts_with("bound declined: loop in"), "{why}")
        }
        other => panic!("{other:?}"),
    }
    assert_eq!(
        built
            .budget_from("diwheeldrive", "can_tx")
            .map(BudgetFrom::label),
        Some("stated")
    );
    // The report's line per board.
    let line = source(&built, "diwheeldrive: budgets: ");
    assert!(
        line.starts_with(
            "diwheeldrive: budgets: 2 bounded from the machine code (F103, 72 MHz, 2 wait states; schedule-analysis/models/diwheeldrive-1-1.wcet.json), 17 stated ("
        ),
        "{line}"
    );
    assert!(line.contains("admit_requests"), "{line}");
    // Each stated budget's reason on a line of its own.
    let admit = source(&built, "diwheeldrive: stated budget of admit_requests: ");
    assert!(
        admit.starts_with("diwheeldrive: stated budget of admit_requests: bound declined"),
        "{admit}"
    );
    assert!(
        line.ends_with("each bounded publisher[…] row is one publisher job's bound (its dispatcher's poll of every task of its priority, serving every topic due at its levels), taken for each topic's sample alone"),
        "{line}"
    );
    // The admission step: the declined bound beside the stated budget, and which one is used.
    let admission = source(&built, "diwheeldrive: admission reserves");
    assert!(
        admission.contains("the bound from its iteration caps is not used (bound declined")
            && admission.contains("the analysis uses the stated budget"),
        "{admission}"
    );
    // The JSON report carries per task where its budget came from.
    let system = built.model.validate().unwrap();
    let report = Report::build(
        &system,
        "t".into(),
        built.sources.clone(),
        built.warnings.clone(),
        None,
    )
    .with_budget_sources(&built);
    let json: serde_json::Value =
        serde_json::from_str(&report::render(&report, Format::Json)).unwrap();
    let from = |name: &str| {
        json["tasks"]
            .as_array()
            .unwrap()
            .iter()
            .find(|t| t["board"] == "diwheeldrive" && t["name"] == name)
            .map(|t| t["budget_from"].clone())
            .unwrap()
    };
    assert_eq!(from("can_rx"), "bound");
    assert_eq!(from("publish_medium[magnetometer-x]"), "bound");
    assert_eq!(from("admit_requests"), "stated");
    assert_eq!(from("monotonic[handle_commands]"), "stated");
    for dir in [
        root,
        std::env::temp_dir().join(format!("machine-bounds-stated-{}", std::process::id())),
    ] {
        let _ = std::fs::remove_dir_all(dir);
    }
}

#[test]
fn a_bounded_admission_step_is_used_and_said_so() {
    let mut b = dwd_bounds();
    b["tasks"][2] = serde_json::json!({
        "task": "admit_requests", "cycles": 720_000, "us": 10_000.0, "instructions": 480_000, "declined": null
    });
    let root = workspace_with("admission", Some(b));
    let built = build(&root).unwrap();
    assert_eq!(task(&built, "admit_requests").wcet_us, 10_000.0);
    let admission = source(&built, "diwheeldrive: admission reserves");
    assert!(
        admission.contains("one step's bound from the machine code (its iteration caps): 10000 µs")
            && admission.contains("beside it the stated budget 15300 µs")
            && admission.contains("the analysis uses the bound"),
        "{admission}"
    );
    let _ = std::fs::remove_dir_all(root);
}

#[test]
fn a_bounds_file_for_another_image_or_malformed_is_refused_naming_the_field() {
    let mut other = dwd_bounds();
    other["revision"] = "1-2".into();
    let root = workspace_with("other", Some(other));
    let e = build(&root).unwrap_err();
    assert_eq!(e.path, "revision", "{e}");
    assert!(e.to_string().contains("diwheeldrive-1-1.wcet.json"), "{e}");
    let _ = std::fs::remove_dir_all(root);

    let mut bad = dwd_bounds();
    bad["tasks"][1]["us"] = 1.0.into();
    let root = workspace_with("bad", Some(bad));
    let e = build(&root).unwrap_err();
    assert_eq!(e.path, "tasks[1].us", "{e}");
    let _ = std::fs::remove_dir_all(root);
}

#[test]
fn the_bound_that_breaks_a_set_is_named() {
    // magnetometer-x's sample bounded at 700 µs: its 900 µs period cannot hold it beside the rest.
    let mut b = dwd_bounds();
    b["tasks"][1]["cycles"] = 50_400.into();
    b["tasks"][1]["us"] = 700.0.into();
    let root = workspace_with("breaks", Some(b));
    let built = build(&root).unwrap();
    let lines = scenario::breaking_bounds(&built, built.frame_cost);
    assert_eq!(lines.len(), 1, "{lines:?}");
    assert!(
        lines[0].starts_with(
            "the bound of diwheeldrive/publisher[magnetometer-x] (bound 850 µs from the machine code, stated 300 µs) breaks the set"
        ),
        "{lines:?}"
    );
    // A set that passes names nothing.
    let fine = build(&workspace_with("fine", Some(dwd_bounds()))).unwrap();
    assert!(scenario::breaking_bounds(&fine, fine.frame_cost).is_empty());
    for name in ["breaks", "fine"] {
        let _ = std::fs::remove_dir_all(
            std::env::temp_dir().join(format!("machine-bounds-{name}-{}", std::process::id())),
        );
    }
}
