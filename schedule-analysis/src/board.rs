//! Response times of the tasks on one board: fixed-priority preemptive scheduling as RTIC does it, with Stack
//! Resource Policy blocking, release jitter, sporadic arrivals and deadlines beyond the period.
//!
//! RTIC semantics the analysis relies on: a higher number is more urgent; a task preempts only when its priority
//! exceeds the running priority (the NVIC does not preempt at equal priority, and a `lock` raises BASEPRI to the
//! resource ceiling); tasks of equal priority therefore run one after the other, in any order. Counting
//! equal-priority tasks like higher-priority ones bounds every such order (FIFO, RTIC's poll order).

use crate::busy_window::{
    self, Activations, AnalysisError, Counter, Discipline, Limits, Load, Response, Subject,
};
use crate::time::Time;

/// The timing of one task (one kind of job) as the scheduler sees it, overheads already included.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TaskTiming {
    /// RTIC priority: higher is more urgent.
    pub priority: u32,
    /// Worst-case execution time of one job, overheads included.
    pub wcet: Time,
    /// Period, or minimum inter-arrival time of a sporadic task.
    pub period: Time,
    /// Release jitter.
    pub jitter: Time,
}

impl Activations for TaskTiming {
    fn activation_cost(&self) -> Time {
        self.wcet
    }
    fn period(&self) -> Time {
        self.period
    }
    fn jitter(&self) -> Time {
        self.jitter
    }
}

/// One critical section as SRP sees it: who holds the lock, the ceiling of the resource, and for how long.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CriticalSection {
    /// Priority of the task that locks (0 for `idle`).
    pub holder_priority: u32,
    /// Ceiling of the locked resource: the highest priority of any task that uses it
    /// (`u32::MAX` for a global critical section with interrupts disabled).
    pub ceiling: u32,
    /// Longest time the lock is held.
    pub length: Time,
}

/// The ceiling of a resource: the highest priority among the tasks that use it (0 when nobody does).
pub fn resource_ceiling(user_priorities: impl IntoIterator<Item = u32>) -> u32 {
    user_priorities.into_iter().max().unwrap_or(0)
}

/// SRP blocking of a task at `priority`: the longest critical section of a lower-priority task on a resource whose
/// ceiling is at least `priority`. Under SRP a job is blocked at most once, before it starts.
pub fn srp_blocking(priority: u32, sections: &[CriticalSection]) -> Time {
    sections
        .iter()
        .filter(|cs| cs.holder_priority < priority && cs.ceiling >= priority)
        .fold(Time::ZERO, |longest, cs| longest.max_of(cs.length))
}

/// Worst-case response time of `tasks[index]` under blocking `blocking`.
///
/// `tasks` must be ordered by descending priority (checked on the part the analysis reads); `scratch` should be at
/// least as long as `tasks` (see [`busy_window::response_time`]).
pub fn response_time(
    tasks: &[TaskTiming],
    index: usize,
    blocking: Time,
    limits: &Limits,
    scratch: &mut [Counter],
) -> Result<Response, AnalysisError> {
    response_time_from(tasks, index, blocking, Time::ZERO, None, limits, scratch)
}

/// Every task's worst-case response time: `out[i]` for `tasks[i]` (ordered by descending priority), under
/// `blockings[i]`. Gives the same results as [`response_time`] one by one, faster: each priority level's load is
/// summed once, and each task's iteration starts from the first window of a task one priority level up when that
/// is provably below its own (Sjödin and Hansson's start value: a lower task's interferers include the higher one
/// and all of its interferers).
pub fn response_times(
    tasks: &[TaskTiming],
    blockings: &[Time],
    limits: &Limits,
    scratch: &mut [Counter],
    out: &mut [Result<Response, AnalysisError>],
) {
    response_times_into(tasks, blockings, limits, scratch, out);
}

/// Where [`response_times_into`] puts each task's result, and where it reads the start hints back from.
pub trait Results {
    /// Stores task `i`'s result.
    fn put(&mut self, i: usize, result: Result<Response, AnalysisError>);
    /// Element `k`'s start hints, if it has a bound: its [`Response::first_window`] and
    /// [`Response::busy_window`].
    fn windows(&self, k: usize) -> Option<(Time, Time)>;
    /// Fixed-point iterations the next element may still take, when the caller budgets the whole set (the
    /// admission check); `None`: [`Limits::iterations`] per element.
    fn iterations_left(&self) -> Option<u64> {
        None
    }
}

impl Results for [Result<Response, AnalysisError>] {
    fn put(&mut self, i: usize, result: Result<Response, AnalysisError>) {
        if let Some(slot) = self.get_mut(i) {
            *slot = result;
        }
    }
    fn windows(&self, k: usize) -> Option<(Time, Time)> {
        let r = self.get(k)?.as_ref().ok()?;
        Some((r.first_window, r.busy_window))
    }
}

/// [`response_times`] into any [`Results`]: a caller short of memory (the on-chip admission check) keeps only
/// the numbers it needs per task instead of a whole [`Response`].
#[inline(never)]
pub fn response_times_into<R: Results + ?Sized>(
    tasks: &[TaskTiming],
    blockings: &[Time],
    limits: &Limits,
    scratch: &mut [Counter],
    out: &mut R,
) {
    let mut level_start = 0;
    let mut level_end = 0;
    let mut previous_level = 0..0;
    let mut levels = LevelLoads::default();
    // The set's order checked once (not once per task, which made a large set's set-up quadratic): a task's
    // prefix up to the end of its level is ordered exactly when the first out-of-order pair lies beyond it.
    let first_unsorted = tasks
        .windows(2)
        .position(|pair| pair[0].priority < pair[1].priority);
    for (i, task) in tasks.iter().enumerate() {
        if i > 0
            && tasks
                .get(i - 1)
                .is_some_and(|t| t.priority != task.priority)
        {
            previous_level = level_start..i;
            level_start = i;
        }
        if i >= level_end {
            level_end = i + 1;
            while tasks
                .get(level_end)
                .is_some_and(|t| t.priority == task.priority)
            {
                level_end += 1;
            }
        }
        let blocking = blockings.get(i).copied().unwrap_or(Time::ZERO);
        // f_i(w) ≥ f_k(w) − B_k + B_i + C_i, so w_i ≥ w_k whenever B_k ≤ B_i + C_i.
        let hint = previous_level
            .clone()
            .filter_map(|k| {
                let (first, _) = out.windows(k)?;
                (blockings.get(k).copied().unwrap_or(Time::ZERO) <= blocking.plus(task.wcet))
                    .then_some(first)
            })
            .max()
            .unwrap_or(Time::ZERO);
        let load = levels.at(tasks, i, |a, b| a.priority == b.priority);
        let result = if first_unsorted.is_some_and(|k| k < level_end) {
            Err(AnalysisError::NotSorted)
        } else {
            response_time_in(
                tasks, i, level_end, blocking, hint, load, None, limits, scratch,
            )
        };
        out.put(i, result);
    }
}

/// The load of each member's interferers in a set ordered by level (every member of its own or a more urgent
/// level but itself), summing each level once as the walk enters it.
#[derive(Default)]
pub(crate) struct LevelLoads {
    level_end: usize,
    prefix: Load,
}

impl LevelLoads {
    /// The interferers' load of `set[i]`; `i` must not decrease between calls.
    pub(crate) fn at<A: Activations>(
        &mut self,
        set: &[A],
        i: usize,
        same_level: impl Fn(&A, &A) -> bool,
    ) -> Load {
        let Some(me) = set.get(i) else {
            return Load::default();
        };
        if i >= self.level_end {
            let mut end = i;
            while let Some(other) = set.get(end).filter(|other| same_level(other, me)) {
                self.prefix = self.prefix.plus(Load::of(other));
                end += 1;
            }
            self.level_end = end;
        }
        self.prefix.minus(Load::of(me))
    }
}

/// [`response_time`] with a start hint (a value known not to exceed the first window, e.g. a more urgent task's
/// first window, see [`response_times`]) and the interferers' load already summed (`LevelLoads`): the
/// building block of a caller that analyses a set in priority order itself (the admission check, which sets a
/// released task's jitter as soon as its releaser's bound is known).
pub fn response_time_hinted(
    tasks: &[TaskTiming],
    index: usize,
    blocking: Time,
    hint: Time,
    load: Load,
    limits: &Limits,
    scratch: &mut [Counter],
) -> Result<Response, AnalysisError> {
    response_time_from(tasks, index, blocking, hint, Some(load), limits, scratch)
}

fn response_time_from(
    tasks: &[TaskTiming],
    index: usize,
    blocking: Time,
    hint: Time,
    load: Option<Load>,
    limits: &Limits,
    scratch: &mut [Counter],
) -> Result<Response, AnalysisError> {
    let me = *tasks.get(index).ok_or(AnalysisError::NoSuchIndex)?;
    // Everything of equal or higher priority interferes: the prefix up to the end of this priority level.
    let mut end = index + 1;
    while tasks.get(end).is_some_and(|t| t.priority == me.priority) {
        end += 1;
    }
    let sorted = tasks.get(..end).is_some_and(|prefix| {
        prefix
            .windows(2)
            .all(|pair| pair[0].priority >= pair[1].priority)
    }) && tasks
        .get(end)
        .is_none_or(|next| next.priority < me.priority);
    if !sorted {
        return Err(AnalysisError::NotSorted);
    }
    let load = load.unwrap_or_else(|| Load::sum(tasks.get(..end).unwrap_or(&[]), Some(index)));
    response_time_in(
        tasks, index, end, blocking, hint, load, None, limits, scratch,
    )
}

/// [`response_time_hinted`] for a caller that keeps its set ordered itself and knows more: `end` is where
/// `tasks[index]`'s priority level ends and `tasks[..end]` must be ordered by priority (not checked: the
/// admission check builds its jobs sorted), and `own` is the subject's [`Share`](busy_window::Share), worked out
/// once. The same result as [`response_time_hinted`] on such a set, without its per-call ordering scan and
/// division.
#[allow(clippy::too_many_arguments)]
pub fn response_time_at_level(
    tasks: &[TaskTiming],
    index: usize,
    end: usize,
    blocking: Time,
    hint: Time,
    load: Load,
    own: busy_window::Share,
    limits: &Limits,
    scratch: &mut [Counter],
) -> Result<Response, AnalysisError> {
    response_time_in(
        tasks,
        index,
        end,
        blocking,
        hint,
        load,
        Some(own),
        limits,
        scratch,
    )
}

/// The response time of `tasks[index]` whose level ends at `end`, the prefix `tasks[..end]` known to be ordered;
/// `own`: its CPU share when the caller has worked it out.
// Out of line: one instance for every caller (the board analysis and, with `sensor-buses`, the engine events).
#[inline(never)]
#[allow(clippy::too_many_arguments)]
fn response_time_in(
    tasks: &[TaskTiming],
    index: usize,
    end: usize,
    blocking: Time,
    hint: Time,
    load: Load,
    own: Option<busy_window::Share>,
    limits: &Limits,
    scratch: &mut [Counter],
) -> Result<Response, AnalysisError> {
    let me = *tasks.get(index).ok_or(AnalysisError::NoSuchIndex)?;
    let mut subject = Subject::new(me.wcet, 1, me.period, me.jitter, blocking);
    subject.known_first_window = hint;
    subject.known_utilisation = own.map(busy_window::Share::utilisation);
    busy_window::response_time_loaded(
        &subject,
        tasks.get(..end).unwrap_or(&[]),
        Some(index),
        load,
        Discipline::Preemptive,
        limits,
        scratch,
    )
}

/// Processor utilisation `Σ C/T` of the tasks.
pub fn utilisation(tasks: &[TaskTiming]) -> f64 {
    tasks
        .iter()
        .filter(|t| !t.period.is_zero())
        .map(|t| t.wcet.as_ns() as f64 / t.period.as_ns() as f64)
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn task(priority: u32, wcet_us: u64, period_us: u64) -> TaskTiming {
        TaskTiming {
            priority,
            wcet: Time::from_us(wcet_us),
            period: Time::from_us(period_us),
            jitter: Time::ZERO,
        }
    }

    #[test]
    fn blocking_takes_the_longest_qualifying_section_only() {
        let sections = [
            // Lower task on a resource whose ceiling reaches priority 3: blocks.
            CriticalSection {
                holder_priority: 1,
                ceiling: 3,
                length: Time::from_us(4),
            },
            // Ceiling below 3: cannot block priority 3.
            CriticalSection {
                holder_priority: 1,
                ceiling: 2,
                length: Time::from_us(9),
            },
            // Holder at the same priority: not blocking (that is interference).
            CriticalSection {
                holder_priority: 3,
                ceiling: 5,
                length: Time::from_us(7),
            },
            // Interrupts disabled in idle: blocks everything.
            CriticalSection {
                holder_priority: 0,
                ceiling: u32::MAX,
                length: Time::from_us(2),
            },
        ];
        assert_eq!(srp_blocking(3, &sections), Time::from_us(4));
        assert_eq!(srp_blocking(5, &sections), Time::from_us(7));
        assert_eq!(srp_blocking(6, &sections), Time::from_us(2));
        assert_eq!(srp_blocking(1, &sections), Time::from_us(2));
    }

    #[test]
    fn unsorted_sets_are_refused() {
        let tasks = [task(1, 1, 10), task(2, 1, 10)];
        assert_eq!(
            response_time(&tasks, 0, Time::ZERO, &Limits::default(), &mut []),
            Err(AnalysisError::NotSorted)
        );
        assert_eq!(
            response_time(&tasks, 5, Time::ZERO, &Limits::default(), &mut []),
            Err(AnalysisError::NoSuchIndex)
        );
    }

    #[test]
    fn response_times_equal_response_time_one_by_one_on_unsorted_sets() {
        // The set's order is checked once per call: every task whose prefix (to the end of its level) is ordered
        // gets its bound, every other task `NotSorted`, as `response_time` gives them one by one.
        let sets = [
            vec![task(3, 1, 10), task(2, 2, 20), task(1, 3, 40)],
            vec![task(3, 1, 10), task(1, 2, 20), task(2, 3, 40)],
            vec![
                task(3, 1, 10),
                task(3, 2, 20),
                task(4, 1, 40),
                task(1, 3, 80),
            ],
            vec![
                task(2, 1, 10),
                task(2, 1, 20),
                task(2, 1, 40),
                task(3, 1, 80),
            ],
            vec![task(1, 1, 10), task(2, 1, 20)],
        ];
        for tasks in sets {
            let n = tasks.len();
            let blockings = [Time::ZERO; 4];
            let mut out = [Err(AnalysisError::NoSuchIndex); 4];
            let mut scratch = [Counter::default(); 4];
            response_times(
                &tasks,
                &blockings,
                &Limits::default(),
                &mut scratch,
                &mut out[..n],
            );
            for (i, got) in out[..n].iter().enumerate() {
                let one = response_time(&tasks, i, Time::ZERO, &Limits::default(), &mut []);
                assert_eq!(
                    got.map(|r| r.wcrt),
                    one.map(|r| r.wcrt),
                    "{tasks:?}, task {i}"
                );
            }
        }
    }

    #[test]
    fn equal_priorities_delay_each_other() {
        let tasks = [task(2, 3, 20), task(2, 4, 20)];
        let a = response_time(&tasks, 0, Time::ZERO, &Limits::default(), &mut []).map(|r| r.wcrt);
        let b = response_time(&tasks, 1, Time::ZERO, &Limits::default(), &mut []).map(|r| r.wcrt);
        assert_eq!(a, Ok(Time::from_us(7)));
        assert_eq!(b, Ok(Time::from_us(7)));
    }

    #[test]
    fn ceiling_is_the_highest_user() {
        assert_eq!(resource_ceiling([1, 5, 3]), 5);
        assert_eq!(resource_ceiling([]), 0);
    }
}
