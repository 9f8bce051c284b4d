//! Analysed bounds the QEMU scenarios check against: the schedule analysis, run on the
//! board app's own source and timing file, for the publisher a scenario starts.
use std::path::Path;

use anyhow::{anyhow, Context, Result};
use schedule_analysis::analysis::{analyse, Options};
use schedule_analysis::model::FrameCostSpec;
use schedule_analysis::scenario;

/// Worst-case latency from a publisher's release to its frame in a mailbox, as analysed for
/// `topic` of `board` published alone at CAN priority `level` every `period_us`: the worst-case response
/// time of the publisher's job (the transmit interrupt pre-empts the job the moment it queues the
/// frame, so the frame reaches a mailbox before the job completes). `received_gap_us`: the run's
/// received frames (its stimulus, which QEMU's replay task delivers) no closer than this; `None`: a
/// command flood at full bus rate. `None`: the analysis bounds nothing (the busy window never closes).
pub fn publisher_bound_us(
    root: &Path,
    board: &str,
    (topic, level, period_us): (&str, &str, u64),
    received_gap_us: Option<f64>,
) -> Result<Option<u64>> {
    let dir = crate::workspace::qemu_target_dir(root).join("bounds");
    std::fs::create_dir_all(&dir)?;
    let name = format!("qemu-{board}-{topic}-{level}-{period_us}us");
    let path = dir.join(format!("{name}.scenario.json"));
    let json = serde_json::json!({
        "name": name,
        "description": "written by cargo xtask for a QEMU scenario's bound",
        "publishers": [{
            "topic": topic,
            "priority": level,
            "period_us": period_us,
            // A late sample may not be overtaken; the bound is the job's response either way.
            "deadline_us": 2 * period_us,
        }],
    });
    std::fs::write(&path, serde_json::to_string_pretty(&json)?)?;
    // The QEMU builds have the task trace: the bound is the traced build's.
    let built = scenario::build_for_run(
        root,
        &path,
        &scenario::timing_files(root),
        scenario::Firmware::Qemu,
        received_gap_us,
    )?;
    let system = built.model.validate().map_err(|e| anyhow!("{name}: {e}"))?;
    let analysis = analyse(
        &system,
        &Options {
            frame_cost: FrameCostSpec::default(),
            horizon: None,
        },
    );
    let task = format!("publish_{level}[{topic}]");
    let result = analysis
        .boards
        .iter()
        .filter(|b| b.name == board)
        .flat_map(|b| b.tasks.iter())
        .find(|t| t.name == task)
        .with_context(|| format!("the analysis has no task {task} on {board}"))?;
    Ok(result.wcrt().map(|wcrt| wcrt.as_ns().div_ceil(1_000)))
}
