//! How far each publisher could be pushed: the shortest period (1 µs resolution) that keeps the whole system
//! schedulable and inside its jitter budgets, and what fails first below it.
//!
//! A publisher is a sending task with everything that shares its period (the timer job that releases it, the rows
//! its job releases — a script's engine row, a transmit row per sample —, the messages it sends), or a message without a modelled sender (operator commands). Its period is found by
//! binary search; deadlines that default to the period move with it. When the set already fails, the search goes
//! the other way: the shortest longer period (up to 1024 × the current one) that would pass. Schedulability is monotone in the period for
//! every term of the analysis except deadlines that move along, so the search reports a period it has verified, not
//! necessarily the very smallest one in exotic sets.

use crate::analysis::{analyse, Options};
use crate::model::{System, TaskRef};
use crate::time::Time;

/// One publisher and what was found.
#[derive(Debug, Clone, PartialEq)]
pub struct PublisherSensitivity {
    /// `board/task` or the message name.
    pub name: String,
    /// Messages it sends.
    pub messages: Vec<String>,
    /// Its period now.
    pub period: Time,
    /// The set fails at the current period (then `shortest` is the shortest *longer* period that passes).
    pub fails_now: bool,
    /// The shortest verified period; `None` when no period up to 1024 × the current one passes.
    pub shortest: Option<Time>,
    /// What fails just below `shortest` (or at the longest period tried when none passes).
    pub limited_by: Vec<String>,
}

/// The sensitivity of a whole system.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Sensitivity {
    /// One entry per publisher.
    pub publishers: Vec<PublisherSensitivity>,
    /// Why the search was skipped, if it was.
    pub skipped: Option<String>,
}

/// The tasks and messages whose periods move together.
#[derive(Debug, Clone, PartialEq)]
pub struct Publisher {
    /// Label.
    pub name: String,
    /// Tasks whose period moves.
    pub tasks: Vec<TaskRef>,
    /// Messages (indices on the bus) whose period moves.
    pub messages: Vec<usize>,
    /// The current period.
    pub period: Time,
}

/// The publishers of a system.
pub fn publishers(system: &System) -> Vec<Publisher> {
    let Some(bus) = &system.bus else {
        return Vec::new();
    };
    let mut out: Vec<Publisher> = Vec::new();
    for (m, message) in bus.messages.iter().enumerate() {
        match message.sender {
            None => out.push(Publisher {
                name: message.name.clone(),
                tasks: Vec::new(),
                messages: vec![m],
                period: message.period,
            }),
            Some(sender) => {
                if let Some(existing) = out.iter_mut().find(|p| p.tasks.first() == Some(&sender)) {
                    existing.messages.push(m);
                    continue;
                }
                let Some(board) = system.boards.get(sender.board) else {
                    continue;
                };
                let Some(task) = board.tasks.get(sender.task) else {
                    continue;
                };
                // The release chain at the same period is the same publisher (the timer job that wakes it).
                let mut tasks = vec![sender];
                let mut at = task.released_by;
                while let Some(r) = at {
                    match board.tasks.get(r) {
                        Some(releaser)
                            if releaser.period == task.period
                                && !tasks.iter().any(|t| t.task == r) =>
                        {
                            tasks.push(TaskRef {
                                board: sender.board,
                                task: r,
                            });
                            at = releaser.released_by;
                        }
                        _ => break,
                    }
                }
                // So are the rows its job releases at its period (a script's engine row, a transmit row per
                // sample): they run once per sample.
                for (r, released) in board.tasks.iter().enumerate() {
                    if released.released_by == Some(sender.task)
                        && released.period == task.period
                        && !tasks.iter().any(|t| t.task == r)
                    {
                        tasks.push(TaskRef {
                            board: sender.board,
                            task: r,
                        });
                    }
                }
                out.push(Publisher {
                    name: format!("{}/{}", board.name, task.name),
                    tasks,
                    messages: vec![m],
                    period: task.period,
                });
            }
        }
    }
    out
}

/// The system with one publisher moved to `period`.
pub fn with_period(system: &System, publisher: &Publisher, period: Time) -> System {
    let mut moved = system.clone();
    for r in &publisher.tasks {
        if let Some(task) = moved
            .boards
            .get_mut(r.board)
            .and_then(|b| b.tasks.get_mut(r.task))
        {
            task.period = period;
            if task.deadline_follows_period {
                task.deadline = period;
            }
        }
    }
    if let Some(bus) = moved.bus.as_mut() {
        for &m in &publisher.messages {
            if let Some(message) = bus.messages.get_mut(m) {
                message.period = period;
                if message.deadline_follows_period {
                    message.deadline = period;
                }
            }
        }
    }
    moved
}

/// Searches the shortest period of every publisher (skipped above `max_publishers`, as each costs about twenty
/// analyses of the whole system).
pub fn sensitivity(system: &System, options: &Options, max_publishers: usize) -> Sensitivity {
    let all = publishers(system);
    if all.len() > max_publishers {
        return Sensitivity {
            publishers: Vec::new(),
            skipped: Some(format!(
                "{} publishers (more than {max_publishers}): sensitivity search skipped",
                all.len()
            )),
        };
    }
    let bus = system.bus.as_ref();
    let publishers = all
        .iter()
        .map(|p| {
            let messages = p
                .messages
                .iter()
                .filter_map(|&m| bus.and_then(|b| b.messages.get(m)).map(|m| m.name.clone()))
                .collect();
            let failures_at =
                |period: Time| analyse(&with_period(system, p, period), options).failures();
            let step = Time::from_us(1);
            let now = failures_at(p.period);
            let fails_now = !now.is_empty();
            // Bracket the boundary: [lo fails, hi passes].
            let (mut lo, mut hi, mut below) = if fails_now {
                // Look for a longer period that passes, doubling up to 1024 × the current one.
                let mut lo = p.period;
                let mut below = now.clone();
                let mut found = None;
                for _ in 0..10 {
                    let candidate = lo.times(2);
                    let failing = failures_at(candidate);
                    if failing.is_empty() {
                        found = Some(candidate);
                        break;
                    }
                    lo = candidate;
                    below = failing;
                }
                match found {
                    Some(hi) => (lo, hi, below),
                    None => {
                        return PublisherSensitivity {
                            name: p.name.clone(),
                            messages,
                            period: p.period,
                            fails_now,
                            shortest: None,
                            limited_by: below,
                        }
                    }
                }
            } else {
                let lo = step.min(p.period);
                let below = failures_at(lo);
                if below.is_empty() {
                    (lo, lo, below)
                } else {
                    (lo, p.period, below)
                }
            };
            while hi.minus(lo) > step {
                let mid = Time::from_us((lo.as_ns() + hi.as_ns()) / 2 / 1000).max_of(lo.plus(step));
                if mid >= hi {
                    break;
                }
                let failing = failures_at(mid);
                if failing.is_empty() {
                    hi = mid;
                } else {
                    lo = mid;
                    below = failing;
                }
            }
            PublisherSensitivity {
                name: p.name.clone(),
                messages,
                period: p.period,
                fails_now,
                shortest: Some(hi),
                limited_by: below,
            }
        })
        .collect();
    Sensitivity {
        publishers,
        skipped: None,
    }
}
