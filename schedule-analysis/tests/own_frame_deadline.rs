//! The transmit interrupt's deadline in own frames (`deadline_own_frames` in the timing files): the host analysis
//! and the boards' admission table take it from the same field, and decide alike on a set whose `can_tx` misses
//! one own frame and meets two.

use std::path::{Path, PathBuf};

use schedule_analysis::admission::{self, Culprit, Refusal, TaskId};
use schedule_analysis::admission_host;
use schedule_analysis::analysis::{analyse, Analysis, Options};
use schedule_analysis::can;
use schedule_analysis::model::FrameCostSpec;
use schedule_analysis::scenario;
use schedule_analysis::time::Time;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map(Path::to_path_buf)
        .expect("workspace root")
}

/// The shipped timing files, LightRing's `can_tx` given `frames` own frames of deadline and the admission task's
/// stated `tx_queue` section (a blocking term of `can_tx`, at priority 0: it adds no load) `extra_us` longer,
/// written to a folder of their own (the apps and bounds files are still read from the workspace). The section
/// blocks `latch_leds` too, whose slack (148.4 µs on 1-0, 2026-12-04) need not cover the extra: its deadline takes
/// the extra as well, so that `can_tx` is the one row the extra decides.
fn timing_files(case: &str, extra_us: f64, frames: u8) -> Vec<PathBuf> {
    let root = root();
    let dir =
        std::env::temp_dir().join(format!("own-frame-deadline-{}-{case}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp folder");
    scenario::timing_files(&root)
        .iter()
        .map(|path| {
            let text = std::fs::read_to_string(path).expect("timing file");
            let mut json: serde_json::Value = serde_json::from_str(&text).expect("parses");
            if json["board"] == "lightring" {
                let tx = &mut json["tasks"]["can_tx"];
                assert_eq!(tx["arrival"], "own_frame");
                assert_eq!(tx["deadline_own_frames"], 2, "the shipped deadline");
                tx["deadline_own_frames"] = serde_json::json!(frames);
                let section =
                    &mut json["tasks"]["admit_requests"]["critical_sections_us"]["tx_queue"];
                let stated = section.as_f64().expect("a stated section");
                *section = serde_json::json!(stated + extra_us);
                let latch = &mut json["tasks"]["latch_leds"]["deadline_us"];
                let deadline = latch.as_f64().expect("a stated deadline");
                *latch = serde_json::json!(deadline + extra_us);
            }
            let out = dir.join(path.file_name().expect("a file name"));
            std::fs::write(&out, json.to_string()).expect("temp timing file");
            out
        })
        .collect()
}

/// A board's shipped timing file.
fn read_timing(board: &str) -> serde_json::Value {
    scenario::timing_files(&root())
        .iter()
        .map(|path| {
            serde_json::from_str::<serde_json::Value>(
                &std::fs::read_to_string(path).expect("timing file"),
            )
            .expect("parses")
        })
        .find(|json| json["board"] == board)
        .expect("the board's timing file")
}

fn host(files: &[PathBuf]) -> Analysis {
    let root = root();
    let path = scenario::find_scenario(&root, "thesis-demo");
    let built = scenario::build(&root, &path, files).unwrap_or_else(|e| panic!("{e}"));
    analyse(
        &built.model.validate().expect("valid"),
        &Options {
            frame_cost: FrameCostSpec::Exact,
            horizon: None,
        },
    )
}

/// LightRing's `can_tx` in the host's report: (WCRT, deadline, blocking).
fn lightring_can_tx(analysis: &Analysis) -> (Time, Time, Time) {
    let board = analysis
        .boards
        .iter()
        .find(|b| b.name == "lightring")
        .expect("lightring");
    let tx = board
        .tasks
        .iter()
        .find(|t| t.name == "can_tx")
        .expect("can_tx");
    (tx.wcrt().expect("bounded"), tx.deadline, tx.blocking)
}

/// The on-chip check's decision on thesis-demo (its last publisher requested beside the others) with these files.
fn on_chip(files: &[PathBuf]) -> (admission::Decision, usize) {
    let root = root();
    let robot = admission_host::lower(&root, files, can::DEFAULT_BITRATE, FrameCostSpec::Exact)
        .unwrap_or_else(|e| panic!("{e}"));
    let lightring = robot
        .boards
        .iter()
        .position(|b| b.name == "lightring")
        .expect("lightring");
    let tx = robot.boards[lightring]
        .task_names
        .iter()
        .position(|n| n == "can_tx")
        .expect("can_tx");
    let row = robot.boards[lightring].tasks[tx];
    // The table carries the frames, not a figure worked out for one set of streams.
    assert!(row.own_frame && row.deadline == admission::NO_DEADLINE);
    let path = scenario::find_scenario(&root, "thesis-demo");
    let sc: scenario::Scenario =
        serde_json::from_str(&std::fs::read_to_string(path).expect("scenario")).expect("parses");
    let mut streams = robot.scenario_streams(&sc).expect("streams");
    let request = streams.pop().expect("request");
    let decision = robot.with_table(|t| admission::admit::<32, 32>(t, &streams, &request, false));
    (decision, lightring)
}

#[test]
fn a_transmit_interrupt_that_misses_one_own_frame_and_meets_two_is_decided_alike() {
    // LightRing can send one topic, its diagnostics (8 bytes): its own frame is 47 + 64 bits, 111 µs, whether or
    // not thesis-demo runs it (a decided one-shot's frames go out after it left the set).
    let own_frame = can::own_frame_time(can::bit_time(can::DEFAULT_BITRATE), [8u8].into_iter());
    assert_eq!(own_frame, Time::from_us(111));
    let (shipped, deadline, blocking) = lightring_can_tx(&host(&timing_files("shipped", 0.0, 2)));
    assert_eq!(deadline, Time::from_us(222), "two own frames");
    assert!(
        shipped < own_frame,
        "the shipped budgets meet even one frame: {shipped:?}"
    );
    // A blocking term that takes the response past one own frame (and not past two: of the interrupts above it
    // only the receive interrupt, every bus frame of 47 µs, and the status interrupt come into a window below 222 µs).
    // The section is raised past the blocking term it has now first (a longer one, the handler's bounded `tx_queue`
    // section, may be the term), so that all of the rest lengthens the response.
    let stated = read_timing("lightring")["tasks"]["admit_requests"]["critical_sections_us"]
        ["tx_queue"]
        .as_f64()
        .expect("a stated section");
    let lift_us = (blocking.as_us_f64() - stated).max(0.0);
    let extra_us = lift_us + (own_frame.as_us_f64() - shipped.as_us_f64()) + 5.0;
    let mut wcrts = Vec::new();
    for frames in [1u8, 2] {
        let files = timing_files(&format!("frames-{frames}"), extra_us, frames);
        let report = host(&files);
        let (wcrt, deadline, _) = lightring_can_tx(&report);
        assert_eq!(deadline, own_frame.times(u64::from(frames)));
        assert!(wcrt > own_frame && wcrt <= own_frame.times(2), "{wcrt:?}");
        let (decision, lightring) = on_chip(&files);
        assert_eq!(
            decision.admitted(),
            report.all_ok(),
            "{frames} frames: {decision:?}"
        );
        if frames == 1 {
            assert!(!report.all_ok());
            match decision.refusal {
                Some(Refusal::Deadline(v)) => {
                    assert!(matches!(
                        v.culprit,
                        Culprit::Task { board, task: TaskId::Fixed(_) } if usize::from(board) == lightring
                    ));
                    assert_eq!(v.deadline, own_frame);
                    // The same response on the chip as on the host (its rows round up to the ns).
                    let on_chip = v.wcrt.expect("bounded");
                    assert!(
                        on_chip.as_ns().abs_diff(wcrt.as_ns()) <= 10,
                        "{on_chip:?} against {wcrt:?}"
                    );
                }
                other => panic!("one own frame: {other:?}"),
            }
        } else {
            assert!(report.all_ok() && decision.admitted(), "{decision:?}");
        }
        wcrts.push(wcrt);
    }
    // The deadline changes no response; the longer section is in it (with one more receive interrupt).
    assert_eq!(wcrts[0], wcrts[1]);
    assert!(wcrts[0].as_us_f64() - shipped.as_us_f64() >= extra_us - lift_us);
}

#[test]
fn a_frame_deadline_needs_an_own_frame_arrival_and_no_deadline_beside_it() {
    let root = root();
    let path = scenario::find_scenario(&root, "thesis-demo");
    for (case, field, value) in [
        ("both", "deadline_us", serde_json::json!(100.0)),
        ("zero", "deadline_own_frames", serde_json::json!(0)),
    ] {
        let files = timing_files(case, 0.0, 2);
        let lightring = files
            .iter()
            .find(|f| f.ends_with("lightring.timing.json"))
            .expect("lightring");
        let mut json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(lightring).expect("read"))
                .expect("parses");
        json["tasks"]["can_tx"][field] = value;
        std::fs::write(lightring, json.to_string()).expect("write");
        let Err(e) = scenario::build(&root, &path, &files) else {
            panic!("{case}: built");
        };
        assert!(
            e.to_string().contains("tasks.can_tx.deadline_own_frames"),
            "{case}: {e}"
        );
    }
}
