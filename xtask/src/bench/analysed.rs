//! The analysis a capture is held to: the scenario of what it shows (each topic at the level and period seen,
//! one-shots as the boards decide them), analysed for the measured build under the received frames of the run
//! (a QEMU run's stimulus, a capture's receive runs), beside the board's own admission decision on the same set
//! (docs/bench.md, "One model with the board's admission").
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{anyhow, Context, Result};
use schedule_analysis::analysis::{analyse, Analysis, Options};
use schedule_analysis::scenario;

use super::capture::Capture;
use super::{seen_publishers, us, LEVELS};
use crate::boards::Board;

/// The scenario the bench analyses for what a capture shows: each topic at the level and period it was seen
/// at; a topic sampled once (no period to measure) is a one-shot, analysed as the boards decide one (a sample
/// every `ONE_SHOT_INTERVAL_MS` at its level).
pub(super) fn seen_scenario(
    seen: &[(amiro_can::Topic, u8, Option<u64>, usize)],
) -> serde_json::Value {
    let (mut publishers, mut one_shots) = (Vec::new(), Vec::new());
    for (topic, level, period, _) in seen {
        let priority = LEVELS[usize::from(*level)];
        match period {
            Some(period) => publishers.push(serde_json::json!({
                "topic": topic.name(), "priority": priority, "period_us": period,
            })),
            None => one_shots.push(serde_json::json!({
                "topic": topic.name(), "priority": priority,
            })),
        }
    }
    serde_json::json!({
        "name": "the publishers the capture shows",
        "description": "written by cargo xtask bench",
        "publishers": publishers,
        "one_shots": one_shots,
    })
}

/// The analysis of the scenario at `path` for the firmware build `firmware`, from `timings`; `received_gap_us`:
/// the run's received frames no closer than this (a QEMU stimulus), else a full-rate bus.
pub(super) fn analyse_scenario(
    root: &Path,
    path: &Path,
    timings: &[PathBuf],
    firmware: scenario::Firmware,
    received_gap_us: Option<f64>,
) -> Result<Analysis> {
    let built = scenario::build_for_run(root, path, timings, firmware, received_gap_us)
        .map_err(|e| anyhow!("{e}"))
        .with_context(|| format!("building the analysis model from {}", path.display()))?;
    let frame_cost = built.frame_cost;
    let system = built
        .model
        .validate()
        .map_err(|e| anyhow!("{}: {e}", path.display()))?;
    Ok(analyse(
        &system,
        &Options {
            frame_cost,
            horizon: None,
        },
    ))
}

/// The analysis for what the capture shows (or for `scenario`).
pub(super) fn analysis_for(
    root: &Path,
    board: &Board,
    capture: &Capture,
    scenario_name: Option<&str>,
    qemu: bool,
    received_gap_us: Option<f64>,
) -> Result<(Analysis, String, bool)> {
    let path = match scenario_name {
        Some(name) => scenario::find_scenario(root, name),
        None => {
            let dir = crate::workspace::target_dir(root).join("bench");
            std::fs::create_dir_all(&dir)?;
            // One file per call: measurements run side by side (tests, the live view).
            static CALLS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
            let call = CALLS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            let name = format!("bench-{}-{}-{call}", board.name, std::process::id());
            let path = dir.join(format!("{name}.scenario.json"));
            let json = seen_scenario(&seen_publishers(capture));
            std::fs::write(&path, serde_json::to_string_pretty(&json)?)?;
            path
        }
    };
    // The measured build has the task trace: so has the analysed one.
    let firmware = if qemu {
        scenario::Firmware::Qemu
    } else {
        scenario::Firmware::Traced
    };
    let timings = scenario::timing_files(root);
    // The run's received frames as they came: the receive interrupt no more often than that.
    let analysis = analyse_scenario(root, &path, &timings, firmware, received_gap_us)?;
    // The board's own admission decides on the production build at a full-rate bus: whether it admits the set. A
    // run whose board accepted a request with a warning (accept-and-warn) runs a set the board itself found
    // breaking a bound, whatever the set the capture shows (which holds only this board's publishers, not the
    // other boards' streams the board's view kept) would give.
    let warned_here = capture
        .warned
        .iter()
        .any(|t| seen_publishers(capture).iter().any(|p| p.0 == *t));
    let admitted = !warned_here
        && analyse_scenario(root, &path, &timings, scenario::Firmware::Production, None)?.all_ok();
    let mut label = match scenario_name {
        Some(name) => format!("scenario {name}"),
        None => "the publishers the capture shows, at the periods and levels seen".to_string(),
    };
    match (capture.received_gap_us, received_gap_us) {
        (Some(gap), _) => {
            let _ = write!(
                label,
                "; received frames as the run's stimulus replays them (at least {gap} µs apart)"
            );
        }
        (None, Some(gap)) => {
            let _ = write!(
                label,
                "; received frames as the capture shows them (the receive interrupt's runs at least {gap} µs apart)"
            );
        }
        (None, None) => label.push_str("; a command flood at full bus rate"),
    }
    if warned_here {
        label.push_str(
            "; the board accepted a topic of this set with a warning (accept-and-warn): it promises nothing for it",
        );
    }
    Ok((analysis, label, admitted))
}

/// The shortest time between the starts of two runs of the receive tasks `receivers` in `capture`, µs (the
/// capture's length when fewer than two ran): the received frames as the capture shows them. A run starts after
/// its frame arrived, so two starts can be closer than their frames were: never an overestimate of how close they
/// came, except by a start's latency, which the capture cannot see.
pub(super) fn observed_gap_us(
    capture: &Capture,
    names: &[String],
    receivers: &[String],
) -> Option<f64> {
    let numbers: Vec<u8> = names
        .iter()
        .enumerate()
        .filter(|(_, n)| receivers.contains(n))
        .filter_map(|(i, _)| u8::try_from(i).ok())
        .collect();
    if numbers.is_empty() {
        return None;
    }
    let mut starts: Vec<u64> = capture
        .runs
        .iter()
        .filter(|r| numbers.contains(&r.task))
        .map(|r| r.start_ns)
        .collect();
    starts.sort_unstable();
    let gap = starts
        .windows(2)
        .map(|w| w[1] - w[0])
        .min()
        .unwrap_or(capture.end_ns.max(1_000));
    Some(us(gap))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bench::machine;
    use amiro_can::Topic;

    /// What the QEMU capture of `diwheeldrive/qemu/admission-one-shots.log` on a 1-1 robot shows once the board
    /// admits its one-shots: magnetometer-x every 6 ms at medium (moved from 3 650 µs, beside which the board
    /// refuses the gyroscope one-shot, the floor one-shot and the accelerometer), the accelerometer every 10 ms at
    /// low and one gyroscope sample at low (DiWheelDrive 1-1's machine-code publisher rows and transmit jobs,
    /// 2026-12-06: the magnetometer's shortest period alone 3 572 µs); the test's copy asks for every 7 ms, its
    /// samples scaled.
    /// The thesis one-shots' scenario, written to a folder of `test`'s own: tests run in parallel in one process,
    /// and a shared file was read half-written by one test while another wrote it.
    fn thesis_one_shots(test: &str) -> PathBuf {
        seen_in(test, &SEEN)
    }

    /// The capture's topics: (topic, level, period µs or a one-shot, samples).
    const SEEN: [(Topic, u8, Option<u64>, usize); 3] = [
        (Topic::MagnetometerX, 2, Some(7000), 53),
        (Topic::Accelerometer, 3, Some(10_000), 9),
        (Topic::Gyroscope, 3, None, 1),
    ];

    /// The scenario of `seen`, in a folder of `test`'s own.
    fn seen_in(test: &str, seen: &[(Topic, u8, Option<u64>, usize)]) -> PathBuf {
        // Under the workspace's target folder (not the system's temporary one, which it would litter).
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../target/tmp")
            .join(format!("bench-one-model-{}-{test}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("seen.scenario.json");
        std::fs::write(&path, seen_scenario(seen).to_string()).unwrap();
        path
    }

    /// The shortest gap between the frames of `admission-one-shots.log` (its requests at 10, 50, 100, 150, 200,
    /// 240 and 280 ms), as `qemu::received_gap_us` reads it from the run's stimulus.
    const RECEIVED_GAP_US: f64 = 40_000.0;

    /// The traced QEMU build's analysis of the scenario at `path`, with the run's received gap.
    fn traced(root: &Path, path: &Path, timings: &[PathBuf]) -> Analysis {
        analyse_scenario(
            root,
            path,
            timings,
            scenario::Firmware::Qemu,
            Some(RECEIVED_GAP_US),
        )
        .unwrap()
    }

    #[test]
    fn the_stimulus_of_the_thesis_one_shots_is_read_as_it_is_replayed() {
        let root = crate::workspace::workspace_root();
        let frames =
            crate::qemu::read_stimulus(&root.join("diwheeldrive/qemu/admission-one-shots.log"))
                .unwrap();
        let bin = crate::qemu::encode_stimulus(&frames, 360_000);
        assert_eq!(
            crate::qemu::received_gap_us(&bin).unwrap() as f64,
            RECEIVED_GAP_US
        );
    }

    #[test]
    fn what_the_board_admitted_the_bench_bounds() {
        let root = crate::workspace::workspace_root();
        let path = thesis_one_shots("admitted");
        let timings = scenario::timing_files_for(&root, Some("1-1"));
        // The board's own admission decides on the production model, one request at a time: the gyroscope
        // one-shot beside the 7 ms magnetometer, then the accelerometer beside it, the one-shot not kept in the
        // board's view by then (each admitted alone beside it on the combined tables, 2026-12-06).
        for (name, without) in [
            ("admitted-once", Topic::Accelerometer),
            ("admitted-stream", Topic::Gyroscope),
        ] {
            let seen: Vec<_> = SEEN.into_iter().filter(|s| s.0 != without).collect();
            let decided = seen_in(name, &seen);
            let production = analyse_scenario(
                &root,
                &decided,
                &timings,
                scenario::Firmware::Production,
                None,
            )
            .unwrap();
            assert!(
                production.all_ok(),
                "the board admitted {seen:?}: {:?}",
                production.failures()
            );
        }
        // The bench measures the traced QEMU build: every task of the board must have a bound there too.
        let traced = traced(&root, &path, &timings);
        let board = traced
            .boards
            .iter()
            .find(|b| b.name == "diwheeldrive")
            .unwrap();
        let unbounded: Vec<&str> = board
            .tasks
            .iter()
            .filter(|t| t.wcrt().is_none())
            .map(|t| t.name.as_str())
            .collect();
        assert!(
            unbounded.is_empty(),
            "unbounded in the bench's model: {unbounded:?}"
        );
        // Why it was unbounded before: at a command flood at full bus rate, which the run never had, the traced
        // build's receive interrupt with its trace records alone takes 27 % of the CPU, and the admission task's
        // busy window never closes.
        let flood =
            analyse_scenario(&root, &path, &timings, scenario::Firmware::Qemu, None).unwrap();
        let admission = flood
            .boards
            .iter()
            .find(|b| b.name == "diwheeldrive")
            .and_then(|b| b.tasks.iter().find(|t| t.name == "admit_requests"))
            .unwrap();
        assert!(admission.wcrt().is_none());
    }

    #[test]
    fn a_publisher_run_is_held_to_the_sum_of_its_topics_bounds() {
        let root = crate::workspace::workspace_root();
        let path = thesis_one_shots("publisher-sum");
        let timings = scenario::timing_files_for(&root, Some("1-1"));
        let traced = traced(&root, &path, &timings);
        let board = traced.boards.iter().find(|b| b.name == "diwheeldrive");
        let row = |task: &str, instructions: u64| {
            serde_json::json!({ "task": task, "cycles": instructions, "us": instructions as f64 / 72.0,
                                "instructions": instructions, "declined": null })
        };
        let file = schedule_analysis::bounds::BoundsFile::from_json(
            "t",
            &serde_json::json!({
                "generated": format!("{} for a test", schedule_analysis::bounds::GENERATED_PREFIX),
                "board": "diwheeldrive", "revision": "1-1", "chip": "stm32f103",
                "clock_hz": 72_000_000, "wait_states": 2,
                "image": { "code_sha256": "1".repeat(64), "code_bytes": 4 },
                "tasks": [ row("publisher[accelerometer]", 3000), row("publisher[gyroscope]", 2000),
                           row("publisher[magnetometer-x]", 9000) ]
            })
            .to_string(),
        )
        .unwrap();
        let bounds = scenario::BoardBounds {
            file: "t".into(),
            bounds: Some(file),
            trace: None,
        };
        let rows = machine::rows(
            &bounds,
            &[
                ("publish_low".into(), vec![machine::Job::alone(40.0)]),
                ("publish_medium".into(), vec![machine::Job::alone(80.0)]),
            ],
            board,
            true,
            120_000_000,
        );
        // publish_low serves the accelerometer and the gyroscope one-shot: 3000 + 2000.
        assert_eq!(rows[0].bound, Some(5000));
        assert_eq!(rows[0].observed, 5000);
        assert_eq!(rows[0].verdict, "ok");
        assert_eq!(rows[1].bound, Some(9000));
        assert_eq!(rows[1].observed, 10_000);
        assert_eq!(rows[1].verdict, machine::EXCEEDS);
        // A run that also sampled the magnetometer at low (moved there for a while; the analysis has each topic at
        // one level): publish_low is held to its row as well, once.
        let seen = [
            ("publish_low".to_string(), "magnetometer-x".to_string()),
            ("publish_low".to_string(), "accelerometer".to_string()),
        ];
        let rows = machine::rows_against_seen(
            &bounds,
            &[("publish_low".into(), vec![machine::Job::alone(80.0)])],
            board,
            &seen,
            true,
            120_000_000,
            None,
        );
        assert_eq!(rows[0].bound, Some(14_000));
        assert_eq!(rows[0].verdict, "ok");
    }
}
