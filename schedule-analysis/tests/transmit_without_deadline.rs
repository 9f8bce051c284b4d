//! The transmit interrupt keeps no deadline of its own (docs/analysis.md, "The transmit interrupt keeps no
//! deadline"): the host analysis and the boards' admission table check only that its busy window closes, and its
//! response is the queuing jitter of every frame its board sends. PowerManagement's `can_tx` (its bound used on the
//! shipped files), past two of its own frames on thesis-demo, passes on both with that response as its frames'
//! jitter; with LightRing's `can_tx` bound used (as on the shipped files), its diagnostics keep its latch's
//! deadline on both; a `can_tx` whose window never closes is refused by both.

use std::path::{Path, PathBuf};

use schedule_analysis::admission::{self, Culprit, Refusal, TaskId};
use schedule_analysis::admission_host;
use schedule_analysis::analysis::{analyse, Analysis, Options};
use schedule_analysis::can;
use schedule_analysis::model::FrameCostSpec;
use schedule_analysis::scenario;
use schedule_analysis::time::Time;

mod common;

thread_local! {
    /// A workspace of this test's own in place of the real one (each test runs on a thread of its own).
    static ROOT: std::cell::RefCell<Option<PathBuf>> = const { std::cell::RefCell::new(None) };
}

fn root() -> PathBuf {
    ROOT.with(|r| r.borrow().clone())
        .unwrap_or_else(common::workspace)
}

/// A workspace whose DiWheelDrive bounds files have no `can_tx` row, so that its timing file's stated budget is
/// the analysis's (the shipped files bound it by its parts since 2026-12-06).
fn without_dwd_can_tx_bound() -> PathBuf {
    let root = common::scratch_workspace("transmit-no-deadline-stated", None);
    for revision in ["1-1", "1-2"] {
        let path = root
            .join(scenario::MODELS_DIR)
            .join(format!("diwheeldrive-{revision}.wcet.json"));
        let mut json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&path).expect("bounds file"))
                .expect("parses");
        json["tasks"]
            .as_array_mut()
            .expect("tasks")
            .retain(|t| t["task"] != "can_tx");
        std::fs::write(&path, json.to_string()).expect("bounds file");
    }
    root
}

/// A folder of its own for this test's files.
fn scratch(case: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!(
        "transmit-no-deadline-{}-{case}",
        std::process::id()
    ));
    std::fs::create_dir_all(&dir).expect("temp folder");
    dir
}

/// thesis-demo with LightRing's diagnostics published at low priority every `period_us` (its last publisher, the
/// request the chip decides).
fn with_diagnostics(case: &str, period_us: u64) -> PathBuf {
    let root = root();
    let path = scenario::find_scenario(&root, "thesis-demo");
    let mut json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path).expect("scenario")).expect("parses");
    json["publishers"].as_array_mut().expect("publishers").push(
        serde_json::json!({ "topic": "lightring-diagnostics", "priority": "low",
            "period_us": period_us }),
    );
    let out = scratch(case).join("thesis-demo-lightring-diagnostics.scenario.json");
    std::fs::write(&out, json.to_string()).expect("temp scenario");
    out
}

/// The shipped timing files, `edit` applied to each, written to a folder of their own (the apps and the bounds
/// files are still read from the workspace).
fn timing_files(case: &str, edit: impl Fn(&mut serde_json::Value)) -> Vec<PathBuf> {
    let dir = scratch(case);
    scenario::timing_files(&root())
        .iter()
        .map(|path| {
            let text = std::fs::read_to_string(path).expect("timing file");
            let mut json: serde_json::Value = serde_json::from_str(&text).expect("parses");
            edit(&mut json);
            let out = dir.join(path.file_name().expect("a file name"));
            std::fs::write(&out, json.to_string()).expect("temp timing file");
            out
        })
        .collect()
}

/// LightRing's `can_tx` bound used (the bounds file holds it: *Held bounds*), every other held bound held back.
fn lightring_by_parts() -> scenario::Held<'static> {
    static ROWS: std::sync::OnceLock<Vec<String>> = std::sync::OnceLock::new();
    scenario::Held::Only {
        board: "lightring",
        rows: ROWS.get_or_init(|| vec!["can_tx".to_string()]),
    }
}

fn host(scenario_path: &Path, files: &[PathBuf]) -> Analysis {
    host_held(scenario_path, files, scenario::Held::Kept)
}

fn host_held(scenario_path: &Path, files: &[PathBuf], held: scenario::Held<'_>) -> Analysis {
    let built =
        scenario::build_held(&root(), scenario_path, files, held).unwrap_or_else(|e| panic!("{e}"));
    analyse(
        &built.model.validate().expect("valid"),
        &Options {
            frame_cost: FrameCostSpec::Exact,
            horizon: None,
        },
    )
}

/// The on-chip check's decision on a scenario (its last publisher requested beside the others) with these files,
/// and the board's index and its `can_tx` row's.
fn on_chip(
    scenario_path: &Path,
    files: &[PathBuf],
    board: &str,
) -> (admission::Decision, usize, u16) {
    on_chip_held(scenario_path, files, board, scenario::Held::Kept)
}

fn on_chip_held(
    scenario_path: &Path,
    files: &[PathBuf],
    board: &str,
    held: scenario::Held<'_>,
) -> (admission::Decision, usize, u16) {
    let robot = admission_host::lower_held(
        &root(),
        files,
        can::DEFAULT_BITRATE,
        FrameCostSpec::Exact,
        held,
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let b = robot
        .boards
        .iter()
        .position(|x| x.name == board)
        .expect("the board");
    let tx = robot.boards[b].can_tx.expect("a transmit interrupt");
    assert_eq!(robot.boards[b].task_names[usize::from(tx)], "can_tx");
    // The table carries no deadline for it: the check reads `can_tx`.
    assert_eq!(
        robot.boards[b].tasks[usize::from(tx)].deadline,
        admission::NO_DEADLINE
    );
    let sc: scenario::Scenario =
        serde_json::from_str(&std::fs::read_to_string(scenario_path).expect("scenario"))
            .expect("parses");
    let mut streams = robot.scenario_streams(&sc).expect("streams");
    let request = streams.pop().expect("request");
    let decision = robot.with_table(|t| admission::admit::<48, 32>(t, &streams, &request, false));
    (decision, b, tx)
}

#[test]
fn powermanagements_can_tx_past_two_own_frames_passes_as_its_frames_jitter() {
    // PowerManagement's own frame is its ring's (3 bytes, 47 + 24 bits): 71 µs; the deadline it had was two.
    let own_frame = can::own_frame_time(can::bit_time(can::DEFAULT_BITRATE), [3u8].into_iter());
    assert_eq!(own_frame, Time::from_us(71));
    let files = scenario::timing_files(&root());
    // thesis-demo as shipped, the ring's jitter budget with it: PowerManagement holds no bound of `can_tx`.
    let path = scenario::find_scenario(&root(), "thesis-demo");
    let report = host(&path, &files);
    let board = report
        .boards
        .iter()
        .find(|b| b.name == "powermgmt")
        .expect("powermgmt");
    let tx = board
        .tasks
        .iter()
        .find(|t| t.name == "can_tx")
        .expect("can_tx");
    // Charged by its parts from the machine code (PowerManagement holds no bound of it): the ring's transmit job
    // per sample (eight frames, each with the abort it may cause) is in its busy window.
    assert!(
        board
            .tasks
            .iter()
            .any(|t| t.name == "can_tx[proximity-ring]"),
        "a transmit job per sample"
    );
    let wcrt = tx.wcrt().expect("its window closes");
    assert!(wcrt > own_frame.times(2), "{wcrt:?}");
    assert!(!tx.deadline_checked && tx.schedulable() && tx.slack_us().is_none());
    assert!(report.all_ok(), "{:?}", report.failures());
    // Its response is the queuing jitter of each of the board's frames: their own (none), their publisher job's
    // variation, and can_tx's WCRT.
    let bus = report.bus.as_ref().expect("a bus");
    for topic in ["proximity-ring", "power-status"] {
        let message = bus
            .messages
            .iter()
            .find(|m| m.name == topic)
            .expect("the topic's frames");
        let sender = board
            .tasks
            .iter()
            .find(|t| Some(format!("powermgmt/{}", t.name)) == message.sender)
            .expect("the publisher job");
        assert_eq!(message.offset, sender.bcrt, "{topic}");
        let variation = sender.wcrt().expect("bounded").minus(message.offset);
        assert_eq!(message.jitter, variation.plus(wcrt), "{topic}");
    }
    // The chip decides alike: the set's last request admitted.
    let (decision, _, _) = on_chip(&path, &files, "powermgmt");
    assert!(decision.admitted(), "{decision:?}");
}

/// LightRing's diagnostics with its `can_tx` bound used (what its bounds file once held it for): a sample's transmit job
/// (six frames, each with the abort it may cause) takes LightRing's `can_tx` past two own frames (111 µs each), which
/// refuses nothing, and `latch_leds` below it on LightRing 1-0 keeps its 2 ms: since the command handler queues no
/// frames (a busy verdict is the admission task's to send), the transmit interrupt's window holds no verdict of the
/// handler's, and the host and the chip admit the diagnostics at any period. The latch's margin is printed.
#[test]
fn lightrings_diagnostics_keep_its_latch_with_can_tx_used() {
    let own_frame = can::own_frame_time(can::bit_time(can::DEFAULT_BITRATE), [8u8].into_iter());
    assert_eq!(own_frame, Time::from_us(111));
    let files = scenario::timing_files(&root());
    for period_us in [100_000, 1_000_000] {
        let path = with_diagnostics(&format!("diagnostics-{period_us}"), period_us);
        let report = host_held(&path, &files, lightring_by_parts());
        let board = report
            .boards
            .iter()
            .find(|b| b.name == "lightring")
            .expect("lightring");
        let task = |name: &str| {
            board
                .tasks
                .iter()
                .find(|t| t.name == name)
                .unwrap_or_else(|| panic!("{name}"))
        };
        let tx = task("can_tx");
        let wcrt = tx.wcrt().expect("its window closes");
        assert!(
            wcrt > own_frame.times(2) && tx.schedulable(),
            "{period_us} µs: {wcrt:?}"
        );
        assert!(task("can_tx[lightring-diagnostics]").schedulable());
        let latch = task("latch_leds");
        eprintln!(
            "{period_us} µs: can_tx {:.1} µs, latch_leds {:.1} of {:.0} µs",
            wcrt.as_us_f64(),
            latch.wcrt().expect("bounded").as_us_f64(),
            latch.deadline.as_us_f64()
        );
        let failures = report.failures();
        assert!(failures.is_empty(), "{period_us} µs: {failures:?}");
        // On the shipped files as they are (the bound used there too) the latch meets its 2 ms.
        let shipped = host(&path, &files);
        assert!(
            !shipped
                .failures()
                .contains(&"lightring/latch_leds".to_string()),
            "{:?}",
            shipped.failures()
        );
        // The chip decides alike.
        let (decision, _, _) = on_chip_held(&path, &files, "lightring", lightring_by_parts());
        assert!(decision.admitted(), "{period_us} µs: {decision:?}");
    }
}

#[test]
fn a_transmit_interrupt_whose_window_does_not_close_is_refused_by_host_and_chip() {
    // DiWheelDrive's `can_tx` on a stated budget (a workspace whose bounds files lack its row): 80 µs a frame every
    // own frame (its magnetometers' 4 bytes, 79 µs) is more than the CPU, so its busy window never closes.
    let workspace = without_dwd_can_tx_bound();
    ROOT.with(|r| *r.borrow_mut() = Some(workspace));
    let own_frame = can::own_frame_time(can::bit_time(can::DEFAULT_BITRATE), [4u8].into_iter());
    assert_eq!(own_frame, Time::from_us(79));
    let path = scenario::find_scenario(&root(), "thesis-demo");
    for (case, wcet_us, refused) in [("closes", 9.0, false), ("never", 80.0, true)] {
        let files = timing_files(case, |json| {
            if json["board"] == "diwheeldrive" {
                let tx = &mut json["tasks"]["can_tx"];
                assert_eq!(tx["arrival"], "own_frame");
                assert_eq!(tx["wcet_us"], 9.0, "the shipped budget");
                tx["wcet_us"] = serde_json::json!(wcet_us);
            }
        });
        let report = host(&path, &files);
        let tx = report
            .boards
            .iter()
            .find(|b| b.name == "diwheeldrive")
            .and_then(|b| b.tasks.iter().find(|t| t.name == "can_tx"))
            .expect("can_tx");
        assert_eq!(tx.wcrt().is_none(), refused, "{case}");
        assert_eq!(report.all_ok(), !refused, "{case}: {:?}", report.failures());
        let (decision, board, row) = on_chip(&path, &files, "diwheeldrive");
        assert_eq!(decision.admitted(), !refused, "{case}: {decision:?}");
        if refused {
            assert!(report
                .failures()
                .contains(&"diwheeldrive/can_tx".to_string()));
            // Below the hard floor, named as the transmit interrupt, with no bound.
            for refusal in [decision.refusal, decision.floor] {
                match refusal {
                    Some(Refusal::Deadline(v)) => {
                        assert!(
                            matches!(v.culprit, Culprit::Task { board: b, task: TaskId::Fixed(r) }
                                if usize::from(b) == board && r == row),
                            "{v:?}"
                        );
                        assert_eq!(v.wcrt, None);
                    }
                    other => panic!("{case}: {other:?}"),
                }
            }
        }
    }
}

#[test]
fn the_transmit_task_takes_no_deadline() {
    let root = root();
    let path = scenario::find_scenario(&root, "thesis-demo");
    for (case, field, value, named) in [
        (
            "deadline",
            "deadline_us",
            serde_json::json!(1000.0),
            "tasks.can_tx.deadline_us",
        ),
        (
            "frames",
            "deadline_own_frames",
            serde_json::json!(2),
            "deadline_own_frames",
        ),
    ] {
        let files = timing_files(case, |json| {
            if json["board"] == "lightring" {
                json["tasks"]["can_tx"][field] = value.clone();
            }
        });
        let Err(e) = scenario::build(&root, &path, &files) else {
            panic!("{case}: built");
        };
        assert!(e.to_string().contains(named), "{case}: {e}");
    }
}
