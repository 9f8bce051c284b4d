//! The bounds a board's bounds file holds back (`held`): kept in structured form in the generated file, read
//! back (an older file without them still loads), and used by the report's second run, which says what the
//! verdict would be on every bound without changing the verdict (docs/analysis.md, "The verdict on the bounds").

use std::path::PathBuf;

use schedule_analysis::analysis::{analyse, Options};
use schedule_analysis::bounds::{BoundsFile, Problem, GENERATED_PREFIX};
use schedule_analysis::report::{self, Format, Report};
use schedule_analysis::scenario::{self, BudgetFrom};

mod common;

/// A workspace of its own with `bounds` as DiWheelDrive 1-1's bounds file.
fn workspace_with(name: &str, bounds: &serde_json::Value) -> PathBuf {
    let root = common::scratch_workspace(&format!("held-bounds-{name}"), Some(bounds));
    // The 900 µs set's frames at 1 500 µs: a set that passes on its stated budgets.
    common::passing_magnetometer_set(&root);
    root
}

/// DiWheelDrive 1-1's bounds: `can_tx` held at 5 400 cycles (75 µs at 72 MHz) against its stated 9 µs, with a
/// held section at interrupts off; `can_status` held at 5 µs against its stated 4 µs; `can_rx` bounded (not held).
fn held_file(can_tx_held: serde_json::Value) -> serde_json::Value {
    serde_json::json!({
        "generated": format!("{GENERATED_PREFIX} from target/firmware/diwheeldrive-1-1.elf; do not edit"),
        "board": "diwheeldrive", "revision": "1-1", "chip": "stm32f103",
        "clock_hz": 72_000_000, "wait_states": 2,
        "image": { "code_sha256": "ab".repeat(32), "code_bytes": 41_000 },
        "tasks": [
            { "task": "can_rx", "cycles": 216, "us": 3.0, "instructions": 150, "bus_wait_us": 0.0,
              "declined": null },
            { "task": "can_tx", "cycles": null, "us": null, "instructions": null,
              "declined": "can_tx: bounded from the machine code at 5400 cycles, held back as its budget: loose",
              "held": can_tx_held },
            { "task": "can_status", "cycles": null, "us": null, "instructions": null,
              "declined": "can_status: bounded from the machine code at 360 cycles, held back as its budget: a test",
              "held": { "cycles": 360, "us": 5.0, "instructions": 100, "reason": "a test" } }
        ]
    })
}

fn can_tx_held() -> serde_json::Value {
    serde_json::json!({
        "cycles": 5400, "us": 75.0, "instructions": 2000, "bus_wait_us": 0.0,
        "reason": "loose: every requeue at its worst",
        "sections": { "incomplete": null, "ceilings": [
            { "ceiling": null, "at": "can_tx at src/tx.rs:10", "cycles": 144, "us": 2.0, "bus_wait_us": 0.0,
              "declined": null }
        ] }
    })
}

fn parse(v: &serde_json::Value) -> Result<BoundsFile, schedule_analysis::bounds::BoundsError> {
    BoundsFile::from_json("t.wcet.json", &v.to_string())
}

#[test]
fn a_held_bound_is_read_back_used_only_on_request_and_an_older_file_still_loads() {
    let file = parse(&held_file(can_tx_held())).unwrap();
    assert_eq!(file.held_rows(), 2);
    let held = file.task("can_tx").unwrap().held.as_ref().unwrap();
    assert_eq!(
        (held.cycles, held.us, held.budget_us()),
        (Some(5400), Some(75.0), Some(75.0))
    );
    // Written and read back unchanged.
    assert_eq!(BoundsFile::from_json("t", &file.to_json()).unwrap(), file);
    // As written, the row is declined; used, it is the bound, its sections the held ones, `held` kept.
    assert_eq!(file.task("can_tx").unwrap().budget_us(), None);
    let used = file.with_held_used(|_| true);
    let tx = used.task("can_tx").unwrap();
    assert_eq!((tx.budget_us(), tx.declined.as_deref()), (Some(75.0), None));
    assert_eq!(tx.sections.as_ref().unwrap().ceilings[0].us, Some(2.0));
    assert!(tx.held.is_some());
    assert_eq!(used.task("can_rx"), file.task("can_rx"));
    // A file without the field (an older writer's) loads, nothing held.
    let mut old = held_file(can_tx_held());
    for row in old["tasks"].as_array_mut().unwrap() {
        row.as_object_mut().unwrap().remove("held");
    }
    assert_eq!(parse(&old).unwrap().held_rows(), 0);
}

#[test]
fn a_held_section_longer_than_its_job_is_cut_to_the_job() {
    // A row bounded per part (a publisher's topic) keeps the sections of the whole task's paths:
    // used, a section longer than the row's own bound is cut to it (a section is part of its job).
    let mut held = can_tx_held();
    held["sections"]["ceilings"][0]["cycles"] = 720_000.into();
    held["sections"]["ceilings"][0]["us"] = 10_000.0.into();
    let used = parse(&held_file(held)).unwrap().with_held_used(|_| true);
    let section = &used
        .task("can_tx")
        .unwrap()
        .sections
        .as_ref()
        .unwrap()
        .ceilings[0];
    assert_eq!((section.cycles, section.us), (Some(5400), Some(75.0)));
    // One within the bound stays as it is.
    let used = parse(&held_file(can_tx_held()))
        .unwrap()
        .with_held_used(|_| true);
    let section = &used
        .task("can_tx")
        .unwrap()
        .sections
        .as_ref()
        .unwrap()
        .ceilings[0];
    assert_eq!((section.cycles, section.us), (Some(144), Some(2.0)));
}

#[test]
fn a_malformed_held_bound_is_refused_naming_its_field() {
    let field = |v: serde_json::Value| parse(&v).unwrap_err();
    // On a row that is not declined.
    let mut v = held_file(can_tx_held());
    v["tasks"][0]["held"] = can_tx_held();
    let e = field(v);
    assert_eq!(
        (e.field.as_str(), &e.problem),
        ("tasks[0].held", &Problem::HeldNotDeclined)
    );
    // µs that are not the cycles at the clock.
    let mut held = can_tx_held();
    held["us"] = serde_json::json!(81.5);
    let e = field(held_file(held));
    assert_eq!(e.field, "tasks[1].held.us");
    assert!(matches!(e.problem, Problem::UsDisagrees { .. }));
    // Part of a bound.
    let mut held = can_tx_held();
    held["instructions"] = serde_json::Value::Null;
    assert_eq!(field(held_file(held)).field, "tasks[1].held.instructions");
    // No reason.
    let mut held = can_tx_held();
    held["reason"] = serde_json::json!(" ");
    assert_eq!(field(held_file(held)).field, "tasks[1].held.reason");
    // A section's ceiling twice.
    let mut held = can_tx_held();
    let first = held["sections"]["ceilings"][0].clone();
    held["sections"]["ceilings"]
        .as_array_mut()
        .unwrap()
        .push(first);
    assert_eq!(
        field(held_file(held)).field,
        "tasks[1].held.sections.ceilings[1].ceiling"
    );
}

#[test]
fn the_second_run_names_the_held_bound_that_turns_a_verdict_into_a_miss() {
    let root = workspace_with("verdict", &held_file(can_tx_held()));
    // can_tx held at 75 µs a frame, one per own frame (the magnetometers' 4 bytes, 79 µs): with the receive
    // interrupt above it (a frame every 47 µs) more than the CPU, so its busy window never closes. It has no
    // deadline of its own, only a bound, and that is what the held bound takes away.
    let path = scenario::find_scenario(&root, "thesis-magnetometer-900us");
    let timings = scenario::timing_files_for(&root, Some("1-1"));
    // The first run: can_tx on its stated 9 µs, everything passes.
    let built = scenario::build(&root, &path, &timings).unwrap();
    let system = built.model.validate().unwrap();
    let report = Report::build(
        &system,
        "t".into(),
        Vec::new(),
        Vec::new(),
        Some(built.frame_cost),
    );
    assert!(report.all_ok(), "{:?}", report.primary.failures());
    assert!(matches!(
        built.budget_from("diwheeldrive", "can_tx"),
        Some(BudgetFrom::Stated { .. })
    ));
    // The second run: can_tx at its held 75 µs.
    let on = scenario::on_held_bounds(&root, &path, &timings, built.frame_cost, &report.primary)
        .unwrap()
        .expect("a bound is held");
    assert!(!on.all_ok);
    let dwd = on
        .boards
        .iter()
        .find(|b| b.board == "diwheeldrive")
        .unwrap();
    assert_eq!(dwd.held, ["can_status", "can_tx"]);
    // Alone, can_tx's breaks the set and can_status's does not.
    let alone = |row: &str| dwd.alone.iter().find(|a| a.row == row).unwrap();
    // What it breaks comes with its figure: can_tx's own response, unbounded, first.
    let breaks = &alone("can_tx").breaks;
    assert_eq!(breaks[0], "diwheeldrive/can_tx unbounded", "{breaks:?}");
    assert!(alone("can_status").breaks.is_empty());
    let tx = dwd
        .misses
        .iter()
        .find(|m| m.job == "can_tx")
        .expect("can_tx misses on its bound");
    assert_eq!((tx.held_us, tx.stated_us), (Some(75.0), Some(9.0)));
    assert_eq!(tx.wcrt_us, None, "above 100 % of the CPU");
    // The same analysis, by hand: the model on the held bound, analysed by the one entry point.
    let held = scenario::build_on_held_bounds(&root, &path, &timings).unwrap();
    let by_hand = analyse(
        &held.model.validate().unwrap(),
        &Options {
            frame_cost: built.frame_cost,
            horizon: None,
        },
    );
    let by_hand_tx = by_hand.boards[0]
        .tasks
        .iter()
        .find(|t| t.name == "can_tx")
        .unwrap();
    assert_eq!(by_hand_tx.wcrt(), None);
    // Its job's budget is the first run's with the held bound in place of the stated 9 µs.
    let first_tx = built.model.boards[0]
        .tasks
        .iter()
        .find(|t| t.name == "can_tx")
        .unwrap();
    let held_tx = held.model.boards[0]
        .tasks
        .iter()
        .find(|t| t.name == "can_tx")
        .unwrap();
    assert!((held_tx.wcet_us - (first_tx.wcet_us + 75.0 - 9.0)).abs() < 1e-9);
    // Its held section at interrupts off is a blocking term (stated 1 µs, held 2 µs).
    assert_eq!(
        (
            first_tx.critical_sections_us.get("critical_section"),
            held_tx.critical_sections_us.get("critical_section")
        ),
        (Some(&1.0), Some(&2.0))
    );
    assert!(dwd.utilisation > dwd.stated_utilisation.unwrap());
    // The printed lines: the board's with the count, one per miss with its figures.
    let lines = on.lines();
    assert!(
        lines[0].starts_with("On the machine code's bounds"),
        "{lines:?}"
    );
    assert!(lines[0].ends_with("NOT schedulable"), "{lines:?}");
    let board = lines
        .iter()
        .find(|l| l.starts_with("diwheeldrive (2 held bounds used: can_status, can_tx): "))
        .unwrap_or_else(|| panic!("{lines:?}"));
    assert!(
        board.contains(&format!(" of {} jobs miss; utilisation ", dwd.jobs)),
        "{board}"
    );
    let expected = format!(
        "  can_tx WCRT unbounded ({}), deadline 79 µs (bound 75 µs, stated 9 µs)",
        tx.unbounded.as_deref().expect("why")
    );
    assert!(lines.contains(&expected), "{expected:?} not in {lines:?}");
    let each = "  each held bound alone (the others held): passes: can_status; breaks the set:";
    let at = lines
        .iter()
        .position(|l| l == each)
        .unwrap_or_else(|| panic!("{each:?} not in {lines:?}"));
    // Its failures, at most three listed, then how many more.
    let breaks = &alone("can_tx").breaks;
    let mut listed: Vec<String> = breaks.iter().take(3).cloned().collect();
    if breaks.len() > 3 {
        listed.push(format!("and {} more", breaks.len() - 3));
    }
    assert_eq!(lines[at + 1], format!("    can_tx: {}", listed.join(", ")));
    // In the report, before the verdict, which stays the first run's; and in its JSON.
    let held: usize = on.boards.iter().map(|b| b.held.len()).sum();
    let report = report.with_on_bounds(Some(on));
    assert!(report.all_ok());
    let text = report::render(&report, Format::Table);
    let section = text.find("The verdict on the bounds").expect("the section");
    assert!(section < text.find("VERDICT").unwrap());
    assert!(text.contains(&expected), "{text}");
    // The verdict's own lines say that it rests on held estimates and what the bounds' verdict is.
    let after = &text[text.find("VERDICT: schedulable").expect("the verdict")..];
    let second = after.lines().nth(1).expect("the verdict's second line");
    assert!(
        second.starts_with("On the machine code's bounds: NOT schedulable — diwheeldrive (")
            && second.contains(&format!(
                "rests on {held} stated estimates held where the machine code has a bound"
            )),
        "{second}"
    );
    let json: serde_json::Value =
        serde_json::from_str(&report::render(&report, Format::Json)).unwrap();
    assert_eq!(json["schedulable"], true);
    assert_eq!(json["on_bounds"]["all_ok"], false);
    assert_eq!(json["on_bounds"]["boards"][0]["held"][1], "can_tx");
}

#[test]
fn nothing_held_means_no_second_run() {
    let mut file = held_file(can_tx_held());
    file["tasks"][1] = serde_json::json!({ "task": "can_tx", "cycles": null, "us": null,
        "instructions": null, "declined": "a loop without a bound" });
    file["tasks"].as_array_mut().unwrap().truncate(2);
    let root = workspace_with("none", &file);
    // The other boards' generated files hold bounds too: this test's own robot is DiWheelDrive alone.
    for other in [
        "powermgmt-1-1.wcet.json",
        "powermgmt-1-2.wcet.json",
        "lightring-1-0.wcet.json",
        "lightring-1-2.wcet.json",
    ] {
        let p = root.join(scenario::MODELS_DIR).join(other);
        let mut v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&p).unwrap()).unwrap();
        for row in v["tasks"].as_array_mut().unwrap() {
            row.as_object_mut().unwrap().remove("held");
        }
        std::fs::write(&p, v.to_string()).unwrap();
    }
    let path = scenario::find_scenario(&root, "thesis-magnetometer-900us");
    let timings = scenario::timing_files_for(&root, Some("1-1"));
    let built = scenario::build(&root, &path, &timings).unwrap();
    let stated = analyse(
        &built.model.validate().unwrap(),
        &Options {
            frame_cost: built.frame_cost,
            horizon: None,
        },
    );
    assert_eq!(
        scenario::on_held_bounds(&root, &path, &timings, built.frame_cost, &stated).unwrap(),
        None
    );
}
