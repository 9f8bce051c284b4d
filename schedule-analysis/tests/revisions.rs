//! Board revisions: a revision's own timing files replace the models folder's namesakes, and every shipped
//! scenario is checked on a robot of each revision: schedulable, or failing exactly as its `expected_failures` for
//! that revision say (since 2026-12-06 thesis-demo on a 1-2 robot, whose DiWheelDrive polls its BNO055 inside the
//! publisher's job, and the thesis's magnetometer-x every 900 µs on both: docs/analysis.md, "Held per revision").

use std::path::PathBuf;

use schedule_analysis::analysis::{analyse, Options};
use schedule_analysis::scenario::{self, build};

mod common;

fn root() -> PathBuf {
    common::workspace()
}

#[test]
fn revision_1_2_replaces_every_boards_timing() {
    let root = root();
    let base = scenario::timing_files_for(&root, None);
    let rev = scenario::timing_files_for(&root, Some("1-2"));
    assert_eq!(base.len(), rev.len());
    for (b, r) in base.iter().zip(&rev) {
        let name = b.file_name().and_then(|n| n.to_str()).unwrap_or("");
        if [
            "diwheeldrive.timing.json",
            "lightring.timing.json",
            "powermgmt.timing.json",
        ]
        .contains(&name)
        {
            assert!(r.ends_with(format!("models/rev-1-2/{name}")), "{r:?}");
        } else {
            assert_eq!(b, r);
        }
    }
    // A revision without files of its own is the models folder.
    assert_eq!(scenario::timing_files_for(&root, Some("1-1")), base);
}

#[test]
fn every_scenario_is_schedulable_or_refused_as_expected_on_both_revisions() {
    let root = root();
    let names = scenario::scenario_names(&root).expect("models folder");
    assert!(!names.is_empty());
    for revision in [None, Some("1-2")] {
        let files = scenario::timing_files_for(&root, revision);
        for name in &names {
            let built = build(&root, &scenario::find_scenario(&root, name), &files)
                .unwrap_or_else(|e| panic!("{name} ({revision:?}): {e}"));
            let system = built.model.validate().expect("validates");
            let analysis = analyse(
                &system,
                &Options {
                    frame_cost: built.frame_cost,
                    horizon: None,
                },
            );
            // Schedulable, or failing exactly as the scenario expects (a checked refusal).
            assert_eq!(
                analysis.failures(),
                built.expected_failures,
                "{name} on revision {revision:?}"
            );
        }
    }
}

/// PowerManagement's two images (one per robot revision: their admission tables differ, so does their
/// machine code, so each has its own bounds file) are of one board: their timing files agree but for
/// the note and the `rev-*` feature that names the image.
#[test]
fn the_two_powermanagement_timing_files_describe_one_board() {
    let read = |path: &str| -> serde_json::Value {
        let text = std::fs::read_to_string(root().join(path)).expect("timing file");
        serde_json::from_str(&text).expect("json")
    };
    let mut old = read("schedule-analysis/models/powermgmt.timing.json");
    let mut new = read("schedule-analysis/models/rev-1-2/powermgmt.timing.json");
    assert_eq!(old["app"]["features"], serde_json::json!(["rev-1-1"]));
    assert_eq!(new["app"]["features"], serde_json::json!(["rev-1-2"]));
    for file in [&mut old, &mut new] {
        let object = file.as_object_mut().expect("an object");
        object.remove("note");
        object["app"]
            .as_object_mut()
            .expect("app")
            .remove("features");
    }
    assert_eq!(old, new);
}

#[test]
fn the_1_2_budgets_put_every_motion_topic_on_the_imu_lock() {
    let path = root().join("schedule-analysis/models/rev-1-2/diwheeldrive.timing.json");
    let text = std::fs::read_to_string(path).expect("1-2 timing file");
    let json: serde_json::Value = serde_json::from_str(&text).expect("json");
    for topic in [
        "gyroscope",
        "accelerometer",
        "magnetometer-x",
        "magnetometer-y",
        "magnetometer-z",
    ] {
        let cs = &json["topics"][topic]["critical_sections_us"];
        // Two transfers: six data bytes and OPR_MODE (about 310 µs on the wire).
        assert!(cs["imu"].as_f64().is_some_and(|us| us >= 310.0), "{topic}");
        assert!(cs.get("compass").is_none(), "{topic}");
    }
}

/// The 1-2 DiWheelDrive model is at least as demanding as the 1-1 model — every task's and topic's
/// WCET and every critical section no shorter, the 1-1 compass lock's sections carried by 1-2's imu
/// lock (whose ceiling is at least both 1-1 locks'), the same tasks, topics and arrivals. Until
/// 2026-12-06 PowerManagement's one image carried a 1-2 robot's table on both robots and relied on
/// this; that was safe for its own requests only, not for its view of the others' (the gap,
/// `amiro-firmware/tests/admission.rs`), and each PowerManagement image now carries its own robot's
/// table (docs/boards.md, "Revisions"). Kept: the 1-2 robot is the more demanding one.
#[test]
fn the_1_2_diwheeldrive_model_dominates_the_1_1_model() {
    let read = |path: &str| -> serde_json::Value {
        let text = std::fs::read_to_string(root().join(path)).expect("timing file");
        serde_json::from_str(&text).expect("json")
    };
    let old = read("schedule-analysis/models/diwheeldrive.timing.json");
    let new = read("schedule-analysis/models/rev-1-2/diwheeldrive.timing.json");
    for section in ["tasks", "topics"] {
        let (Some(old), Some(new)) = (old[section].as_object(), new[section].as_object()) else {
            continue;
        };
        let mut old_names: Vec<_> = old.keys().collect();
        let mut new_names: Vec<_> = new.keys().collect();
        old_names.sort();
        new_names.sort();
        assert_eq!(old_names, new_names, "{section}");
        for (name, o) in old {
            let n = &new[name];
            let wcet = |v: &serde_json::Value| v["wcet_us"].as_f64().unwrap_or(0.0);
            assert!(wcet(n) >= wcet(o), "{section}/{name}: WCET");
            assert_eq!(o["arrival"], n["arrival"], "{section}/{name}: arrival");
            let empty = serde_json::Map::new();
            let old_cs = o["critical_sections_us"].as_object().unwrap_or(&empty);
            let new_cs = n["critical_sections_us"].as_object().unwrap_or(&empty);
            for (lock, us) in old_cs {
                let lock = if lock == "compass" {
                    "imu"
                } else {
                    lock.as_str()
                };
                let new_us = new_cs.get(lock).and_then(|v| v.as_f64()).unwrap_or(0.0);
                assert!(
                    new_us >= us.as_f64().unwrap_or(0.0),
                    "{section}/{name}: lock {lock}"
                );
            }
        }
    }
}

/// The 1-2 LightRing model (three TLC5947) demands at least as much of its board in every window as
/// the 1-0 model (on 1-1 robots; until 2026-12-06 PowerManagement's one image relied on it, as
/// above). They differ only in the latch task: one
/// 108-byte latch per 3 ms against one 36-byte latch per 1 ms (docs/boards.md). Every other task and
/// topic is the same; the latch's demand in any window (ceil((w + J) / T) jobs of C plus the
/// dispatch overheads) is at least the 1-0 latch's, its critical sections no shorter.
#[test]
fn the_1_2_lightring_model_dominates_the_1_0_model() {
    let read = |path: &str| -> serde_json::Value {
        let text = std::fs::read_to_string(root().join(path)).expect("timing file");
        serde_json::from_str(&text).expect("json")
    };
    let old = read("schedule-analysis/models/lightring.timing.json");
    let new = read("schedule-analysis/models/rev-1-2/lightring.timing.json");
    assert_eq!(old["overheads"], new["overheads"]);
    assert_eq!(old["topics"], new["topics"]);
    let (Some(old_tasks), Some(new_tasks)) = (old["tasks"].as_object(), new["tasks"].as_object())
    else {
        panic!("tasks");
    };
    let mut old_names: Vec<_> = old_tasks.keys().collect();
    let mut new_names: Vec<_> = new_tasks.keys().collect();
    old_names.sort();
    new_names.sort();
    assert_eq!(old_names, new_names);
    for (name, o) in old_tasks {
        if name != "latch_leds" {
            assert_eq!(o, &new_tasks[name], "{name}");
        }
    }
    let overhead = ["isr_entry_us", "isr_exit_us", "dispatcher_us"]
        .iter()
        .map(|k| old["overheads"][k].as_f64().unwrap_or(0.0))
        .sum::<f64>();
    let latch = |v: &serde_json::Value| {
        let t = &v["tasks"]["latch_leds"];
        let us = |k: &str| t[k].as_f64().unwrap_or(0.0);
        (
            us("wcet_us") + overhead,
            t["arrival"]["sporadic_us"]
                .as_f64()
                .expect("sporadic latch"),
            us("jitter_us"),
        )
    };
    let ((c0, t0, j0), (c2, t2, j2)) = (latch(&old), latch(&new));
    for w in 0..=200_000u32 {
        let w = f64::from(w);
        let demand = |c: f64, t: f64, j: f64| ((w + j) / t).ceil() * c;
        assert!(
            demand(c2, t2, j2) >= demand(c0, t0, j0),
            "window {w} µs: 1-2 latch demand {} < 1-0's {}",
            demand(c2, t2, j2),
            demand(c0, t0, j0)
        );
    }
    let sections = |v: &serde_json::Value| v["tasks"]["latch_leds"]["critical_sections_us"].clone();
    let (old_cs, new_cs) = (sections(&old), sections(&new));
    for (lock, us) in old_cs.as_object().expect("sections") {
        assert!(
            new_cs[lock].as_f64().unwrap_or(0.0) >= us.as_f64().unwrap_or(0.0),
            "{lock}"
        );
    }
}

/// LightRing's latch: its release jitter is derived (docs/analysis.md, "LightRing's latch: its release jitter"),
/// not budgeted: the latch interval plus the command handler's own release jitter, released by the timer (whose
/// response the analysis adds). It holds while the handler is more urgent than the latch and its deadline is at
/// most the interval (that the handler meets it, every scenario's analysis checks).
#[test]
fn the_latch_jitter_is_the_interval_plus_the_handlers_own_jitter() {
    let root = root();
    let path = scenario::find_scenario(&root, "thesis-demo");
    for revision in [None, Some("1-2")] {
        let files = scenario::timing_files_for(&root, revision);
        let file = files
            .iter()
            .find(|p| p.ends_with("lightring.timing.json"))
            .expect("a lightring timing file");
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(file).expect("readable")).expect("JSON");
        let (latch, handler) = (
            &json["tasks"]["latch_leds"],
            &json["tasks"]["handle_commands"],
        );
        let us = |v: &serde_json::Value| v.as_f64().expect("a figure");
        let interval = us(&latch["arrival"]["sporadic_us"]);
        assert_eq!(latch["released_by"], "timer", "{revision:?}");
        assert_eq!(
            us(&latch["jitter_us"]),
            interval + us(&handler["jitter_us"]),
            "{revision:?}"
        );
        assert!(us(&handler["deadline_us"]) <= interval, "{revision:?}");
        let built = build(&root, &path, &files).expect("builds");
        let board = built
            .model
            .boards
            .iter()
            .find(|b| b.name == "lightring")
            .expect("lightring");
        let priority = |name: &str| {
            board
                .tasks
                .iter()
                .find(|t| t.name == name)
                .map(|t| t.priority)
                .expect("the task")
        };
        assert!(
            priority("handle_commands") > priority("latch_leds"),
            "{revision:?}"
        );
    }
}
