//! The transmit interrupt charged by its parts, where the machine code gives them (the board's bounds file's
//! `per_frame`; docs/analysis.md, "The transmit interrupt's parts"): one job per frame the board sends, and one per
//! job of a task that queues frames.

use std::collections::BTreeSet;

use super::declared::Declared;
use super::{fail, BuildError, Timing};
use crate::bounds::FrameParts;
use crate::model::TaskModel;
use crate::time::Time;

/// The period of the row that charges the fills of the frames still in their mailboxes at a window's end: any
/// period charges it at least once in every window; 1 s, longer than any busy window of the boards' sets.
const CARRY_IN_PERIOD_US: f64 = 1_000_000.0;

/// The resource every task that queues frames shares with the transmit task.
const TX_QUEUE: &str = "tx_queue";

/// Charges the transmit task (`can_tx_task`, already among `tasks` with one frame's job as its budget, at its own
/// frames' rate) by `parts`, and adds a job of it per job of every task that queues frames: `<can_tx>[<topic>]` per
/// publisher job (its topic's frames per sample) and `<can_tx>[<task>]` per job of a task the transmit task's
/// `queued_by` names (at most that many frames), each released by that job, costing the job its pend starts and,
/// per frame queued, an abort that frame may cause (the aborted frame's completion in a job of its own, its
/// requeue, and the pass that had put it in its mailbox). Returns the source line the report prints.
pub(super) fn charge_by_parts(
    file: &str,
    timing: &Timing,
    declared: &[Declared],
    parts: &FrameParts,
    bit: Time,
    tasks: &mut Vec<TaskModel>,
) -> Result<String, BuildError> {
    let tx_name = timing.can_tx_task.as_deref().ok_or_else(|| {
        fail(
            file,
            "can_tx_task",
            "missing: the transmit task's parts need it",
        )
    })?;
    let path = format!("tasks.{tx_name}.queued_by");
    let tx = tasks
        .iter()
        .find(|t| t.name == tx_name)
        .cloned()
        .ok_or_else(|| fail(file, "can_tx_task", format!("no task `{tx_name}`")))?;
    let publishers: BTreeSet<&str> = timing.publishers.values().map(String::as_str).collect();
    let queued_by = timing
        .tasks
        .get(tx_name)
        .and_then(|t| t.queued_by.clone())
        .unwrap_or_default();
    for d in declared {
        let queues = d.shared.iter().any(|r| r == TX_QUEUE);
        if queues
            && d.name != tx_name
            && !publishers.contains(d.name.as_str())
            && !queued_by.contains_key(&d.name)
        {
            return Err(fail(
                file,
                &path,
                format!(
                    "`{}` shares {TX_QUEUE} but the transmit task's `queued_by` does not say how many frames one \
                     of its jobs queues (0 if none)",
                    d.name
                ),
            ));
        }
    }
    for name in queued_by.keys() {
        if !declared.iter().any(|d| &d.name == name) {
            return Err(fail(file, &path, format!("no task `{name}` is declared")));
        }
    }
    // What one frame a job queues may cost beyond its own frame's job (charged when it is sent): the abort it may
    // cause — the aborted frame's completion in a job of its own (the fixed part and a completion), its requeue,
    // and the pass that had put the aborted frame in its mailbox (a pass and a completion are one frame's).
    let per_queued = parts.fixed_us + parts.per_frame_us + parts.abort_us;
    // The aborts a job's frames cause come after it: three of the longest frames after the pend (shared with the
    // on-chip check, which builds these jobs from the same rule).
    let abort_latency = crate::can::transmit_abort_latency(bit).as_us_f64();
    let mut added = Vec::new();
    for t in tasks.iter() {
        let publisher_job = t.job_of.as_deref().is_some_and(|p| publishers.contains(p));
        let (label, frames) = if publisher_job {
            let Some(topic) = t
                .name
                .split_once('[')
                .and_then(|(_, rest)| rest.strip_suffix(']'))
            else {
                continue;
            };
            let Some(info) = amiro_can::TOPICS.iter().find(|i| i.name == topic) else {
                return Err(fail(
                    file,
                    &path,
                    format!("`{}`: no topic `{topic}`", t.name),
                ));
            };
            (topic.to_string(), u32::from(info.frames_per_sample))
        } else {
            match queued_by.get(&t.name) {
                Some(q) if q.frames > 0 => (t.name.clone(), q.frames),
                _ => continue,
            }
        };
        // The jobs that queue frames at the rate the code gives them where it is not the task's period (the
        // admission task's verdicts: its busy ones come up to once per one-shot interval, counted from the send).
        let spaced = queued_by.get(&t.name).and_then(|q| q.at_least_us);
        added.push(TaskModel {
            name: format!("{tx_name}[{label}]"),
            wcet_us: parts.fixed_us + f64::from(frames) * per_queued,
            period_us: spaced.unwrap_or(t.period_us),
            sporadic: t.sporadic || spaced.is_some(),
            deadline_us: None,
            jitter_us: abort_latency,
            bcet_us: None,
            released_by: Some(t.name.clone()),
            job_of: Some(tx_name.to_string()),
            ..tx.clone()
        });
    }
    // The passes that fill a mailbox in a window whose frames complete after it (at most three: the mailboxes),
    // charged to no completion in the window: once per window (any period is charged at least once in any window;
    // a second time only in windows longer than it).
    added.push(TaskModel {
        name: format!("{tx_name}[mailboxes]"),
        wcet_us: 3.0 * parts.per_frame_us,
        period_us: CARRY_IN_PERIOD_US,
        sporadic: true,
        deadline_us: None,
        jitter_us: 0.0,
        bcet_us: None,
        released_by: None,
        job_of: Some(tx_name.to_string()),
        ..tx.clone()
    });
    let names: Vec<String> = added
        .iter()
        .map(|t| format!("{} {:.3} µs", t.name, t.wcet_us))
        .collect();
    let line = format!(
        "{}: `{tx_name}` charged by its parts from the machine code: one job per frame it sends, {:.3} µs (fixed \
         {:.3} µs + per frame {:.3} µs, at its own frames' rate); per job of a task that queues frames, released by \
         it (its release jitter and {abort_latency:.0} µs for the aborts it may cause): fixed + frames × (fixed + per frame \
         + abort {:.3} µs); three fills once per window: {}",
        timing.board,
        tx.wcet_us,
        parts.fixed_us,
        parts.per_frame_us,
        parts.abort_us,
        if names.is_empty() {
            "none".to_string()
        } else {
            names.join(", ")
        }
    );
    tasks.extend(added);
    Ok(line)
}
