//! Execution-time bounds from the machine code: per function a control-flow graph, its natural
//! loops bounded (counted loops found, the rest stated in a [`BoundsFile`]), calls composed bottom
//! up, and the longest path on the graph with each loop collapsed ([`path`]); cycles from the
//! [`Chip`]'s model. docs/analysis.md ("Execution-time bounds from the machine code") states the
//! model, its sources and why the bound is safe.
//!
//! A path that ends in a trap (`UDF`) or in a call of a function that cannot return (a panic, the
//! fault handler's halt) does not complete the job: the board halts and the watchdog resets it
//! (docs/faults.md). The bound is of the jobs that complete.
mod analysis;
pub mod bounds;
pub mod cfg;
pub mod chip;
pub mod counted;
pub mod critical;
pub mod length;
mod masking;
pub mod path;
pub mod polled;
pub mod stored;
pub mod topics;
pub mod values;

use serde::Serialize;

use crate::{Error, Image};
use analysis::{Analysis, Summary};
use bounds::BoundsFile;
use chip::Chip;
pub use critical::{task_sections, topic_sections, Ceiling, CeilingBound, TaskSections};
#[cfg(test)]
use path::{Cost, LoopCount};

/// One loop on the way, and where its bound came from.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct LoopInfo {
    /// The function it is in (demangled, without hash).
    pub function: String,
    /// Its header's source file and line (the line table's), when the image has them.
    pub file: Option<String>,
    pub line: Option<u32>,
    /// The most times its header runs per entry (for a wait: 1, the wait is stated apart).
    pub bound: u64,
    /// Where the bound came from: `counted: …`, `bounds file: <reason>`, `wait: <source>`.
    pub source: String,
}

/// A function's bound.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Bound {
    /// Cycles of the longest path (machine code: core and memory system).
    pub cycles: u64,
    /// The most instructions any path runs.
    pub instructions: u64,
    /// Stated peripheral waits on the longest path, nanoseconds (apart from the cycles).
    pub bus_wait_ns: u64,
    /// The loops of the function and everything it calls, with their bounds.
    pub loops: Vec<LoopInfo>,
    /// What one preemption inside an exclusive-access sequence (`LDREX` … `STREX`) adds: one more
    /// iteration of the longest retry loop it may be in (cycles, instructions). Not in `cycles`:
    /// [`bound_tasks`] charges it to every handler, which is what preempts.
    pub retry_cycles: u64,
    pub retry_instructions: u64,
    /// Why there is no bound (then the figures are 0 and mean nothing).
    pub declined: Option<String>,
}

impl Bound {
    /// The stated waits in µs.
    pub fn bus_wait_us(&self) -> f64 {
        self.bus_wait_ns as f64 / 1000.0
    }

    /// Cycles and waits as µs at `chip`'s clock.
    pub fn us(&self, chip: Chip) -> f64 {
        (chip.cycles_to_ns(self.cycles) + self.bus_wait_ns) as f64 / 1000.0
    }
}

/// Where a task starts.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum TaskEntry {
    /// A function, by demangled name or symbol.
    Symbol(String),
    /// The handler of a vector-table entry (the word index: 16 + IRQ number for an interrupt).
    Vector(usize),
    /// One software task's part of the dispatcher that polls it: the dispatcher's own code and
    /// the task's poll, the polls of `others` (the other tasks of its priority, RTIC names) left
    /// out ([`polled`]).
    Polled {
        dispatcher: String,
        task: String,
        others: Vec<String>,
    },
}

impl TaskEntry {
    /// The address the task's code starts at in `image`: its function's, or its vector's handler.
    pub(crate) fn start(&self, image: &Image) -> Result<u64, Error> {
        match self {
            TaskEntry::Symbol(s) | TaskEntry::Polled { dispatcher: s, .. } => {
                image.function_named(s).map(|f| f.start)
            }
            TaskEntry::Vector(i) => image
                .vectors
                .iter()
                .find(|(k, _)| k == i)
                .map(|&(_, at)| at)
                .ok_or_else(|| Error::Other(format!("no handler at vector {i}"))),
        }
    }
}

/// A task to bound.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Task {
    pub name: String,
    pub entry: TaskEntry,
    /// An exception handler: its entry and exit (and lazy FPU stacking on the M4F) are added.
    pub handler: bool,
}

/// One task's bound, as `cargo xtask wcet` prints it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TaskBound {
    pub task: String,
    /// The function bounded.
    pub function: Option<String>,
    pub cycles: u64,
    pub us: f64,
    pub instructions: u64,
    pub bus_wait_us: f64,
    pub loops: Vec<LoopInfo>,
    /// Included in `cycles` and `instructions` of a handler: one retry iteration of the longest
    /// exclusive-access loop of any task it may preempt (each preemption can cost the preempted job
    /// one).
    pub preemption_retry_cycles: u64,
    pub declined: Option<String>,
    /// Where the bounds file charges the task per activation ([`bounds::PerActivation`]): that
    /// charge, beside the job's bound above.
    pub per_activation: Option<ActivationBound>,
    /// Where the bounds file charges the task by its parts ([`bounds::PerFrame`]): the fixed part per
    /// job, the pass and completion per frame, the requeue per abort, beside the job's bound above.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub per_frame: Option<FrameBound>,
    /// Where the bounds file states the task's release loop per topic ([`bounds::PerTopic`]): the
    /// bound of one topic group's job each, beside the job's bound above.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub topics: Vec<TopicBound>,
}

/// The bound of one job of a publisher task that serves one release of a topic group's topic
/// ([`topics`]): the release loop one pass in total, the other groups' sample functions not called,
/// the group's own waits; a handler's entry, exit and preemption retry added as to the job's bound.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TopicBound {
    /// The group's name and topics.
    pub group: String,
    pub topics: Vec<String>,
    pub cycles: u64,
    pub us: f64,
    pub instructions: u64,
    pub bus_wait_us: f64,
    /// The loops on the way, with their bounds (the waits with the group's sources).
    pub loops: Vec<LoopInfo>,
    /// Why there is no bound (then the figures are 0 and mean nothing).
    pub declined: Option<String>,
}

/// A task's charge per activation ([`bounds::PerActivation`]): its bound with the stated loop at its
/// passes per activation, everything else as in the job's bound (a handler's entry and exit and the
/// preemption retry included alike).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ActivationBound {
    /// The loop, `function at file:line`.
    pub at: String,
    /// Its header's runs per activation.
    pub passes: u64,
    pub cycles: u64,
    pub us: f64,
    pub instructions: u64,
    pub bus_wait_us: f64,
    /// Why a job that serves k activations costs at most k charges (the bounds file's).
    pub reason: String,
    /// Why there is no charge (the loop is not on the task's path, or the bound declined).
    pub declined: Option<String>,
}

/// One part of a [`FrameBound`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct Part {
    pub cycles: u64,
    pub us: f64,
    pub instructions: u64,
}

impl Part {
    fn of(chip: Chip, cycles: u64, instructions: u64) -> Part {
        Part {
            cycles,
            us: chip.cycles_to_ns(cycles) as f64 / 1000.0,
            instructions,
        }
    }
}

/// A transmit interrupt's parts ([`bounds::PerFrame`]), each from the machine code. With the
/// transmit loop's header at 1 and 2 runs and the completion or the requeue function left out
/// (`T(p, X)`, the handler's entry, exit and preemption retry added to the fixed part alone):
/// `fixed` = T(1, {completion}) — the code around both loops, the completion scan's passes that
/// collect nothing, the transmit loop's last pass (the queue empty, or every mailbox taken and at
/// most one abort requested); `pass` = T(2, {completion}) − T(1, {completion}), the longest pass that
/// fills a mailbox; `sent` = (T(1, {requeue}) − T(1, {completion})) / completions, what collecting a
/// completion adds to a scan pass; `abort` = (T(1, {}) − T(1, {requeue})) / completions, what an
/// aborted frame's requeue adds to that. A loop of bound N costs (N − 1) times its longest iteration
/// plus its longest way out ([`path`]), so each difference is exact, and the divisions are checked:
/// the requeue's difference must be `completions` times the completion function's own (its bound
/// with and without the requeue), or the parts are declined. A job that fills q mailboxes and
/// collects s sent and a aborted completions costs at most fixed + q·pass + s·sent + a·(sent + abort).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FrameBound {
    /// The transmit loop, `function at file:line`.
    pub at: String,
    pub completion: String,
    pub completions: u64,
    pub requeue: String,
    /// Once per job.
    pub fixed: Part,
    /// Per frame put in a mailbox.
    pub pass: Part,
    /// Per completion collected.
    pub sent: Part,
    /// Per aborted frame, beyond its completion.
    pub abort: Part,
    /// One frame's: `pass` + `sent`.
    pub per_frame: Part,
    /// Why a job costs at most its parts (the bounds file's).
    pub reason: String,
    /// Why there are no parts (then the figures are 0 and mean nothing).
    pub declined: Option<String>,
}

/// The parts of `task` charged per frame ([`FrameBound`]); `extra` is the handler's entry, exit and
/// preemption retry (cycles, instructions), added to the fixed part.
fn frame_bound(
    image: &Image,
    chip: Chip,
    bounds: &BoundsFile,
    task: &Task,
    charge: &bounds::PerFrame,
    job: &Bound,
    extra: (u64, u64),
) -> FrameBound {
    let at = format!("{} at {}:{}", charge.function, charge.file, charge.line);
    let on_path = job.loops.iter().any(|l| {
        l.function == charge.function
            && l.line == Some(charge.line)
            && l.file
                .as_deref()
                .is_some_and(|f| bounds::same_file(f, &charge.file))
    });
    let parts = || -> Result<[(u64, u64); 4], String> {
        if let Some(d) = &job.declined {
            return Err(format!("the job's bound is declined: {d}"));
        }
        if !on_path {
            return Err(format!("the loop {at} is not on the task's path"));
        }
        for name in [&charge.completion, &charge.requeue] {
            image
                .function_named(name)
                .map_err(|e| format!("{name}: {e} (inlined? the parts need it as a function)"))?;
        }
        let at_passes = |passes: u64, left_out: &[&String]| -> Result<(u64, u64), String> {
            let stated = bounds.at_passes(charge, passes);
            let excluded: Vec<String> = left_out.iter().map(|s| s.to_string()).collect();
            let mut again =
                Analysis::excluding(image, chip, &stated, &excluded).without_call_contexts();
            let (_, b) = bound_task(&mut again, image, task);
            match b.declined {
                Some(d) => Err(d),
                None => Ok((b.cycles, b.instructions)),
            }
        };
        let function = |left_out: &[&String]| -> Result<(u64, u64), String> {
            let f = image
                .function_named(&charge.completion)
                .map_err(|e| e.to_string())?;
            let excluded: Vec<String> = left_out.iter().map(|s| s.to_string()).collect();
            let mut again =
                Analysis::excluding(image, chip, bounds, &excluded).without_call_contexts();
            match again.summary(f.start) {
                Ok(outcome) => {
                    let b = to_bound(outcome);
                    match b.declined {
                        Some(d) => Err(d),
                        None => Ok((b.cycles, b.instructions)),
                    }
                }
                Err(e) => Err(e.to_string()),
            }
        };
        let none = at_passes(1, &[&charge.completion])?;
        let two = at_passes(2, &[&charge.completion])?;
        let sent = at_passes(1, &[&charge.requeue])?;
        let all = at_passes(1, &[])?;
        let (whole, without) = (function(&[])?, function(&[&charge.requeue])?);
        let n = charge.completions;
        let requeue_own = whole.0.checked_sub(without.0).filter(|&d| d > 0);
        let requeue_in_task = all.0.checked_sub(sent.0);
        match (requeue_own, requeue_in_task) {
            (Some(own), Some(in_task)) if in_task == n * own => {}
            _ => {
                return Err(format!(
                    "the requeue ({}) adds {} cycles to the task and {} to {}: not {n} times \
                     its own, so {} is not called once per pass of a loop of {n} passes",
                    charge.requeue,
                    all.0 as i128 - sent.0 as i128,
                    whole.0 as i128 - without.0 as i128,
                    charge.completion,
                    charge.completion
                ))
            }
        }
        if two.0 < none.0 || sent.0 < none.0 {
            return Err("a part came out negative".into());
        }
        Ok([
            (none.0 + extra.0, none.1 + extra.1),
            (two.0 - none.0, two.1.saturating_sub(none.1)),
            (
                (sent.0 - none.0).div_ceil(n),
                sent.1.saturating_sub(none.1).div_ceil(n),
            ),
            (
                (all.0 - sent.0) / n,
                all.1.saturating_sub(sent.1).div_ceil(n),
            ),
        ])
    };
    let (parts, declined) = match parts() {
        Ok(p) => (p, None),
        Err(e) => ([(0, 0); 4], Some(e)),
    };
    let part = |(c, i): (u64, u64)| Part::of(chip, c, i);
    FrameBound {
        at,
        completion: charge.completion.clone(),
        completions: charge.completions,
        requeue: charge.requeue.clone(),
        fixed: part(parts[0]),
        pass: part(parts[1]),
        sent: part(parts[2]),
        abort: part(parts[3]),
        per_frame: part((parts[1].0 + parts[2].0, parts[1].1 + parts[2].1)),
        reason: charge.reason.clone(),
        declined,
    }
}

/// Bounds one function of `image` with everything it calls.
pub fn bound_function(
    image: &Image,
    symbol: &str,
    chip: Chip,
    bounds: &BoundsFile,
) -> Result<Bound, Error> {
    let f = image.function_named(symbol)?;
    f.instructions()?;
    let mut analysis = Analysis::new(image, chip, bounds);
    let outcome = analysis.summary(f.start)?;
    Ok(to_bound(outcome))
}

fn to_bound(outcome: Result<Summary, String>) -> Bound {
    match outcome {
        Ok(s) => {
            // The loops stated in total per job, each charged its passes of its longest iteration
            // once for the whole job.
            let (time, count) = s.totals.values().fold((s.time, s.count), |(t, c), total| {
                (
                    t.plus(total.time.times(total.passes)),
                    c.plus(total.count.times(total.passes)),
                )
            });
            Bound {
                cycles: time.cycles,
                instructions: count.instructions,
                bus_wait_ns: time.wait_ns,
                loops: s.loops,
                retry_cycles: s.retry_time.cycles,
                retry_instructions: s.retry_count.instructions,
                declined: None,
            }
        }
        Err(reason) => Bound {
            cycles: 0,
            instructions: 0,
            bus_wait_ns: 0,
            loops: Vec::new(),
            retry_cycles: 0,
            retry_instructions: 0,
            declined: Some(reason),
        },
    }
}

/// Bounds every task: a row each, declined with its reason where no bound can be given (an error
/// of the image is a declined row too, naming the error).
pub fn bound_tasks(
    image: &Image,
    tasks: &[Task],
    chip: Chip,
    bounds: &BoundsFile,
) -> Vec<TaskBound> {
    let mut analysis = Analysis::new(image, chip, bounds);
    let found: Vec<(Option<String>, Bound)> = tasks
        .iter()
        .map(|task| bound_task(&mut analysis, image, task))
        .collect();
    // What one preemption can cost the job it preempts: one retry of the longest exclusive-access
    // loop of any task (charged to the preempting handler).
    let retry_cycles = found.iter().map(|(_, b)| b.retry_cycles).max().unwrap_or(0);
    let retry_instructions = found
        .iter()
        .map(|(_, b)| b.retry_instructions)
        .max()
        .unwrap_or(0);
    // A handler's figures: the bound, its entry and exit, one retry of what it preempts.
    let extras = |task: &Task, bound: &Bound| {
        if task.handler && bound.declined.is_none() {
            (chip.exception_cycles() + retry_cycles, retry_instructions)
        } else {
            (0, 0)
        }
    };
    let us = |cycles: u64, bound: &Bound| {
        if bound.declined.is_some() {
            0.0
        } else {
            (chip.cycles_to_ns(cycles) + bound.bus_wait_ns) as f64 / 1000.0
        }
    };
    tasks
        .iter()
        .zip(found)
        .map(|(task, (function, bound))| {
            let (extra, extra_insns) = extras(task, &bound);
            let per_activation = bounds.per_activation(&task.name).map(|charge| {
                let at = format!("{} at {}:{}", charge.function, charge.file, charge.line);
                let on_path = bound.loops.iter().any(|l| {
                    l.function == charge.function
                        && l.line == Some(charge.line)
                        && l.file
                            .as_deref()
                            .is_some_and(|f| bounds::same_file(f, &charge.file))
                });
                let (cycles, instructions, bus_wait_ns, declined) = if bound.declined.is_some() {
                    (0, 0, 0, Some("the job's bound is declined".to_string()))
                } else if !on_path {
                    (
                        0,
                        0,
                        0,
                        Some(format!("the loop {at} is not on the task's path")),
                    )
                } else {
                    let stated = bounds.at_activation(charge);
                    let mut again = Analysis::new(image, chip, &stated);
                    let (_, b) = bound_task(&mut again, image, task);
                    let (e, ei) = extras(task, &b);
                    (b.cycles + e, b.instructions + ei, b.bus_wait_ns, b.declined)
                };
                ActivationBound {
                    at,
                    passes: charge.passes,
                    cycles,
                    us: if declined.is_some() {
                        0.0
                    } else {
                        (chip.cycles_to_ns(cycles) + bus_wait_ns) as f64 / 1000.0
                    },
                    instructions,
                    bus_wait_us: bus_wait_ns as f64 / 1000.0,
                    reason: charge.reason.clone(),
                    declined,
                }
            });
            let per_frame = bounds.per_frame(&task.name).map(|charge| {
                frame_bound(
                    image,
                    chip,
                    bounds,
                    task,
                    charge,
                    &bound,
                    extras(task, &bound),
                )
            });
            let topics = match &bounds.topics {
                Some(per_topic) if bound.declined.is_none() => {
                    let on_path = bound.loops.iter().any(|l| {
                        l.function == per_topic.function
                            && l.line == Some(per_topic.line)
                            && l.file
                                .as_deref()
                                .is_some_and(|f| bounds::same_file(f, &per_topic.file))
                    });
                    if on_path {
                        let present = per_topic.present(image);
                        present
                            .iter()
                            .map(|&group| {
                                let stated = bounds.for_topic_group(per_topic, group);
                                let excluded = bounds::PerTopic::excluded(group, &present);
                                let mut again =
                                    Analysis::excluding(image, chip, &stated, &excluded);
                                let (_, mut b) = bound_task(&mut again, image, task);
                                if let Some(t) = bounds::PerTopic::shared_topic(group, &present) {
                                    b = to_bound(Err(format!(
                                        "the topic {t} is in two topic groups of this image"
                                    )));
                                }
                                let (e, ei) = extras(task, &b);
                                let cycles = b.cycles + e;
                                TopicBound {
                                    group: group.name.clone(),
                                    topics: group.topics.clone(),
                                    cycles,
                                    us: us(cycles, &b),
                                    instructions: b.instructions + ei,
                                    bus_wait_us: b.bus_wait_us(),
                                    loops: b.loops,
                                    declined: b.declined,
                                }
                            })
                            .collect()
                    } else {
                        Vec::new()
                    }
                }
                _ => Vec::new(),
            };
            let cycles = bound.cycles + extra;
            TaskBound {
                task: task.name.clone(),
                function,
                cycles,
                us: us(cycles, &bound),
                instructions: bound.instructions + extra_insns,
                bus_wait_us: bound.bus_wait_us(),
                preemption_retry_cycles: if extra > 0 { retry_cycles } else { 0 },
                loops: bound.loops,
                declined: bound.declined,
                per_activation,
                per_frame,
                topics,
            }
        })
        .collect()
}

/// One task's bound with `analysis` (its function's name, where its start is found).
fn bound_task(analysis: &mut Analysis<'_>, image: &Image, task: &Task) -> (Option<String>, Bound) {
    match task.entry.start(image) {
        Ok(at) => (
            Some(image.name(at)),
            match match &task.entry {
                TaskEntry::Polled { task, others, .. } => analysis.polled_summary(at, task, others),
                _ => analysis.summary(at),
            } {
                Ok(outcome) => to_bound(outcome),
                Err(e) => to_bound(Err(e.to_string())),
            },
        ),
        Err(e) => (None, to_bound(Err(e.to_string()))),
    }
}

#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_activation;
#[cfg(test)]
mod tests_dead_ends;
#[cfg(test)]
mod tests_polled;
#[cfg(test)]
mod tests_spills;
#[cfg(test)]
mod tests_topics;
#[cfg(test)]
mod tests_transactions;
#[cfg(test)]
mod tests_values;
