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
