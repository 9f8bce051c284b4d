//! `cargo xtask bench --calibrate`: measured maxima, times a margin, into the board's timing file
//! as `measured` budgets beside the estimates (`wcet_us` stays as it was), with where they came
//! from; `cargo xtask analyze` then uses and names them (schedule_analysis::scenario).
use std::path::Path;

use anyhow::{bail, Context, Result};
use serde_json::{json, Map, Value};

use super::Bench;

/// `value` rounded up to a tenth of a µs (a budget is never rounded down).
fn tenth_up(value: f64) -> f64 {
    (value * 10.0).ceil() / 10.0
}

/// Writes the measured budgets of `bench` into the timing file at `path`; returns how many.
///
/// Tasks: the largest execution time of a run (pre-emptions taken out). Topics: the largest time
/// from a sample taken to its last frame queued (pre-emptions included). Tasks without runs in the
/// capture, and the publisher tasks (their budgets are the topics'), keep what they had.
pub fn write(path: &Path, bench: &Bench, margin: f64) -> Result<usize> {
    if !(margin >= 1.0 && margin.is_finite()) {
        bail!("the margin must be at least 1 (got {margin})");
    }
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut timing: Value =
        serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
    let measured = |max_us: f64, jobs: usize| -> Value {
        json!({
            "wcet_us": tenth_up(max_us * margin),
            "max_us": (max_us * 100.0).round() / 100.0,
            "margin": margin,
            "jobs": jobs,
            "origin": bench.origin,
            "build": bench.build,
        })
    };
    let mut changed = 0;
    if let Some(tasks) = timing.get_mut("tasks").and_then(Value::as_object_mut) {
        for row in &bench.tasks {
            if let Some(entry) = tasks.get_mut(&row.task).and_then(Value::as_object_mut) {
                if row.jobs > 0 {
                    entry.insert("measured".into(), measured(row.exec_max_us, row.jobs));
                    changed += 1;
                }
            }
        }
    }
    let topics = timing
        .as_object_mut()
        .context("a timing file is a JSON object")?
        .entry("topics")
        .or_insert_with(|| Value::Object(Map::new()));
    if let Some(topics) = topics.as_object_mut() {
        for row in &bench.topics {
            if let (Some(entry), Some(work)) = (
                topics.get_mut(&row.topic).and_then(Value::as_object_mut),
                row.work_max_us,
            ) {
                entry.insert("measured".into(), measured(work, row.samples));
                changed += 1;
            }
        }
    }
    std::fs::write(path, serde_json::to_string_pretty(&timing)? + "\n")
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(changed)
}

#[cfg(test)]
mod tests {
    use super::*;
    use schedule_analysis::scenario;

    #[test]
    fn calibration_round_trip_on_a_recorded_capture() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        let bytes =
            std::fs::read(root.join("xtask/tests/data/diwheeldrive-thesis-60ms.trace")).unwrap();
        let capture = super::super::capture::read(&bytes, 72_000_000).unwrap();
        assert_eq!(
            capture.clock_hz, 120_000_000,
            "the boot record sets the clock"
        );
        assert_eq!((capture.reader.damaged, capture.unbalanced), (0, 0));
        let board = crate::boards::by_name("diwheeldrive").unwrap();
        let bench = super::super::measure(&root, board, &capture, "recorded", false, None).unwrap();
        assert!(bench
            .tasks
            .iter()
            .any(|t| t.task == "can_rx" && t.jobs == 1));
        let magnetometer = bench
            .topics
            .iter()
            .find(|t| t.topic == "magnetometer-x")
            .unwrap();
        assert!(magnetometer.samples > 50 && magnetometer.bus_max_us.is_some());

        let original_path = root.join("schedule-analysis/models/diwheeldrive.timing.json");
        let original: scenario::Timing =
            serde_json::from_str(&std::fs::read_to_string(&original_path).unwrap()).unwrap();
        let dir = std::env::temp_dir().join(format!("xtask-calibrate-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("diwheeldrive.timing.json");
        std::fs::copy(&original_path, &path).unwrap();
        assert!(
            write(&path, &bench, 0.9).is_err(),
            "a margin below 1 is refused"
        );
        let changed = write(&path, &bench, 1.25).unwrap();
        let written: scenario::Timing =
            serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();

        // Every measured task and topic got its measurement, beside the unchanged estimate.
        let mut seen = 0;
        for row in &bench.tasks {
            let (Some(now), Some(before)) =
                (written.tasks.get(&row.task), original.tasks.get(&row.task))
            else {
                continue;
            };
            let m = now.measured.as_ref().unwrap();
            assert_eq!(
                now.wcet_us, before.wcet_us,
                "{}: the estimate stays",
                row.task
            );
            assert_eq!(m.wcet_us, tenth_up(row.exec_max_us * 1.25), "{}", row.task);
            assert!(m.wcet_us >= row.exec_max_us * 1.25 && m.build == "robot");
            assert_eq!(m.jobs, row.jobs as u64);
            seen += 1;
        }
        let m = written.topics["magnetometer-x"].measured.as_ref().unwrap();
        assert_eq!(
            m.wcet_us,
            tenth_up(magnetometer.work_max_us.unwrap() * 1.25)
        );
        assert_eq!(written.topics["magnetometer-x"].wcet_us, 300.0);
        assert_eq!(changed, seen + 1);

        // The analysis uses the measured budgets and says which they are.
        let files: Vec<_> = scenario::timing_files(&root)
            .into_iter()
            .map(|p| {
                if p.ends_with("diwheeldrive.timing.json") {
                    path.clone()
                } else {
                    p
                }
            })
            .collect();
        let built = scenario::build(
            &root,
            &scenario::find_scenario(&root, "thesis-magnetometer-900us"),
            &files,
        )
        .unwrap();
        // With a generated bounds file each stated row's own line names its measurement (`diwheeldrive: stated
        // budget of …: …; measured …`), without one the budgets line lists them (`measured for N of them: …`). A
        // row the machine code bounds takes its bound instead: DiWheelDrive 1-1's magnetometer-x since its publisher
        // rows are used (2026-12-06), its bound far above the measurement (the bus waits polled on the CPU).
        assert!(
            built
                .sources
                .iter()
                .any(|s| (s.starts_with("diwheeldrive: stated budget of ")
                    && s.contains("; measured "))
                    || (s.starts_with("diwheeldrive: budgets: ") && s.contains("measured for"))),
            "{:#?}",
            built.sources
        );
        let board_model = built
            .model
            .boards
            .iter()
            .find(|b| b.name == "diwheeldrive")
            .unwrap();
        let job = board_model
            .tasks
            .iter()
            .find(|t| t.name == "publish_medium[magnetometer-x]")
            .unwrap();
        match built.budget_from("diwheeldrive", "publish_medium[magnetometer-x]") {
            Some(scenario::BudgetFrom::Bound { us, .. }) => {
                assert_eq!(job.wcet_us, *us);
                assert!(job.wcet_us > m.wcet_us, "{} {}", job.wcet_us, m.wcet_us);
            }
            // Held or stated: the measurement is its budget.
            _ => assert_eq!(job.wcet_us, m.wcet_us),
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
