//! The transmit task of the traced QEMU build ([`QemuTransmit`]).

use amiro_can::TopicInfo;

use super::{
    board_folder, fail, BuildError, QemuReplay, QemuTransmit, Timing, QEMU_FRAMES_PER_TRANSMIT_JOB,
};
use crate::model::{Overheads, TaskKind, TaskModel};

/// QEMU's transmit task ([`QemuTransmit`]): its own arrival (one job per frame on the bus) becomes
/// ⌈frames / 3⌉ jobs per publisher job of the scenario (`can_tx[topic]`, released by that job) and
/// per sample a command requests (the task itself, at the command handler's rate, released by it,
/// with one period of extra jitter per requestable topic).
pub(super) fn transmit_jobs(
    file: &str,
    timing: &Timing,
    transmit: &QemuTransmit,
    overheads: &Overheads,
    tasks: &mut Vec<TaskModel>,
) -> Result<(), BuildError> {
    let path = "trace.qemu.transmit";
    let tx_name = timing
        .can_tx_task
        .as_deref()
        .ok_or_else(|| fail(file, path, "the file names no `can_tx_task`"))?;
    let handler = tasks
        .iter()
        .find(|t| t.name == transmit.requests_from)
        .cloned()
        .ok_or_else(|| {
            fail(
                file,
                format!("{path}.requests_from"),
                format!("no task `{}`", transmit.requests_from),
            )
        })?;
    let at = tasks
        .iter()
        .position(|t| t.name == tx_name)
        .ok_or_else(|| fail(file, path, format!("no task `{tx_name}`")))?;
    let tx = tasks[at].clone();
    // A job after the first of a burst costs its entry, exit and trace records too (the analysis
    // adds them once per modelled job).
    let per_job = match tx.kind {
        TaskKind::Hardware => overheads.isr_entry_us + overheads.isr_exit_us,
        TaskKind::Software => {
            overheads.isr_entry_us + overheads.isr_exit_us + overheads.dispatcher_us
        }
        TaskKind::Plain => 0.0,
    };
    let burst = |frames: u64| {
        let jobs = frames.div_ceil(QEMU_FRAMES_PER_TRANSMIT_JOB).max(1) as f64;
        jobs * tx.wcet_us + (jobs - 1.0) * per_job + frames as f64 * transmit.frame_us
    };
    // What a command may request: one sample of a topic the board owns.
    let requestable: Vec<&TopicInfo> = amiro_can::TOPICS
        .iter()
        .filter(|i| i.is_sensor && board_folder(i.board) == timing.board)
        .collect();
    let largest = requestable
        .iter()
        .map(|i| u64::from(i.frames_per_sample))
        .max()
        .unwrap_or(1);
    let requests = &mut tasks[at];
    requests.wcet_us = burst(largest);
    requests.period_us = handler.period_us;
    requests.sporadic = true;
    requests.jitter_us = handler.period_us * requestable.len().max(1) as f64;
    requests.released_by = Some(handler.name.clone());
    let publisher_jobs: Vec<(String, f64, u64)> = tasks
        .iter()
        .filter(|t| {
            t.job_of
                .as_ref()
                .is_some_and(|p| timing.publishers.values().any(|v| v == p))
        })
        .filter_map(|t| {
            let topic = t.name.split_once('[')?.1.strip_suffix(']')?;
            let info = amiro_can::TOPICS.iter().find(|i| i.name == topic)?;
            Some((
                t.name.clone(),
                t.period_us,
                u64::from(info.frames_per_sample),
            ))
        })
        .collect();
    for (job, period_us, frames) in publisher_jobs {
        let topic = job
            .split_once('[')
            .map_or("", |(_, t)| t.trim_end_matches(']'));
        tasks.push(TaskModel {
            name: format!("{tx_name}[{topic}]"),
            wcet_us: burst(frames),
            period_us,
            sporadic: false,
            jitter_us: 0.0,
            released_by: Some(job),
            job_of: Some(tx_name.to_string()),
            script: None,
            scripts: None,
            ..tx.clone()
        });
    }
    Ok(())
}

/// The priority of QEMU's stimulus replay task ([`QemuReplay`]): the app read with its features and `qemu`
/// (the task exists only in the QEMU build).
pub(super) fn replay_priority(
    root: &std::path::Path,
    file: &str,
    timing: &Timing,
    replay: &QemuReplay,
) -> Result<u32, BuildError> {
    let path = "trace.qemu.replay.task";
    let app = timing
        .app
        .as_ref()
        .ok_or_else(|| fail(file, path, "the board has no app to read the task from"))?;
    let text = std::fs::read_to_string(root.join(&app.source))
        .map_err(|e| fail(file, path, format!("cannot read {}: {e}", app.source)))?;
    let parsed =
        crate::rtic_source::parse_app(&text).map_err(|e| fail(&app.source, "", e.to_string()))?;
    let mut features: Vec<&str> = app.features.iter().map(String::as_str).collect();
    features.push("qemu");
    parsed
        .with_features(&features)
        .tasks
        .iter()
        .find(|t| t.name == replay.task)
        .map(|t| u32::from(t.priority))
        .ok_or_else(|| {
            fail(
                file,
                path,
                format!(
                    "no task `{}` in {} with the `qemu` feature",
                    replay.task, app.source
                ),
            )
        })
}
