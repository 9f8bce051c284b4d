//! One board's analysis, the one both the report ([`crate::analysis`]) and the on-chip admission check
//! ([`crate::admission`]) run: the board's jobs sorted by priority with their SRP blockings, release jitters
//! inherited through release chains iterated to a fixed point, each job's response by the busy-window analysis
//! ([`board::response_time_at_level`]).
//!
//! `no_std` and allocation-free: the caller owns the storage — the chip fixed-capacity arrays indexed by bytes, the
//! host vectors of any length — and says through [`Jobs`] what the analysis reads of each job and through
//! [`JobBounds`] where each job's bound goes. Both are generic parameters, so each caller gets the loop compiled
//! for its own storage.
//!
//! Two closed forms spare the chip fixed points, each giving the numbers the fixed point gives or a bound only a
//! deadline check reads; a caller that keeps whole [`Response`] records ([`JobBounds::WHOLE_RECORDS`], the report)
//! gets every job's fixed point instead.

use core::ops::Range;

use crate::board::{self, TaskTiming};
use crate::busy_window::{
    linear_bound, AnalysisError, Counter, Limits, LinearTerms, Load, Response, Share, UTIL_ONE,
};
use crate::time::Time;

/// Rounds of the release-jitter iteration before the released jobs are declared unbounded
/// ([`Unbound::NoConvergence`]).
pub const MAX_JITTER_ROUNDS: usize = 100;

/// What the analysis reads of a board's jobs besides their [`TaskTiming`]s, per sorted position (most urgent
/// first, ties in the caller's order).
pub trait Jobs {
    /// How job `p` is released by another job; `None`: by none.
    fn release(&self, p: usize) -> Option<Release>;
    /// Where job `p`'s priority level ends (one past its last job).
    fn level_end(&self, p: usize) -> usize;
    /// `Some(deadline)` when nothing reads job `p`'s bound but a check against this deadline, so that a
    /// closed-form bound that meets it may settle the job without a fixed point; `None`: its bound is read.
    fn verdict_only(&self, p: usize) -> Option<Time>;
}

/// A job released by the completion of another.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Release {
    /// The sorted position of the job whose completion releases it.
    pub by: usize,
    /// The sorted position of a second job whose response adds to its release jitter: a transmit job's transmit
    /// interrupt, in one of whose jobs the mailbox abort its frames cause is asked, within that job's response
    /// after the pend (docs/analysis.md, "The sound transmit path: the design"). `None`: no second one.
    pub also: Option<usize>,
    /// Its release jitter of its own, to which the releasers' responses are added.
    pub own_jitter: Time,
}

/// Why a released job has no bound although its own analysis may have found one.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Unbound {
    /// Its releaser has no bound, so its release jitter has none.
    Releaser,
    /// Its inherited release jitter is beyond the 64-bit nanosecond range.
    Overflow,
    /// The inherited release jitters still changed after [`MAX_JITTER_ROUNDS`] rounds.
    NoConvergence,
}

/// Where the analysis puts each job's bound (by sorted position), and where it reads bounds back: a releaser's
/// response for the jobs it releases, a more urgent job's first window as a start hint.
pub trait JobBounds {
    /// Whether the caller keeps whole [`Response`] records: then every job gets its fixed point (the closed forms
    /// give the response and the first window, not the rest of the record).
    const WHOLE_RECORDS: bool;
    /// Job `p`'s fixed point, or why there is none.
    fn put(&mut self, p: usize, result: Result<Response, AnalysisError>);
    /// Job `p`'s closed-form bound (never called with [`JobBounds::WHOLE_RECORDS`]): its response `wcrt` and
    /// first window, or a first window of zero for a bound only the deadline check reads.
    fn put_closed_form(&mut self, p: usize, wcrt: Time, first_window: Time);
    /// Job `p` (a released job) has no bound.
    fn put_unbound(&mut self, p: usize, why: Unbound);
    /// Job `p`'s worst-case response, `None` while it has no bound.
    fn wcrt(&self, p: usize) -> Option<Time>;
    /// Job `p`'s first window when it has a bound (a start hint for the levels below).
    fn first_window(&self, p: usize) -> Option<Time>;
}

/// How the fixed points' iterations are limited.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum IterationBudget {
    /// [`Limits::iterations`] per job; a job beyond it is unbounded ([`AnalysisError::IterationLimit`]).
    PerJob,
    /// [`Limits::iterations`] for the whole board (the admission check's bounded cost); beyond it the analysis
    /// stops with [`OutOfIterations`].
    Board,
}

/// One board's jobs, sorted by priority (most urgent first).
pub struct BoardJobs<'a> {
    /// Their timings; each jitter starts as the job's own and ends as the one its bound was found with (own plus
    /// inherited).
    pub timings: &'a mut [TaskTiming],
    /// Their SRP blockings.
    pub blocking: &'a [Time],
    /// Their CPU shares ([`Share::of`] their cost and period; a table may hold them worked out).
    pub shares: &'a [Share],
    /// The busy-window analysis's working memory, at least as long as `timings`.
    pub scratch: &'a mut [Counter],
}

/// What an analysis found besides the bounds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Outcome {
    /// Fixed-point iterations it took.
    pub iterations: u64,
    /// The longest window any of its fixed points or closed forms reached (ns).
    pub reach: u64,
    /// Whether a job was left unbounded by something but an overload (which a longer horizon might change).
    pub beyond: bool,
}

/// The board's analysis ran out of its [`IterationBudget::Board`] budget: no verdict on its deadlines.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OutOfIterations;

/// Analyses one board's `jobs`: every job's bound goes into `bounds`. With release chains, jitters are iterated
/// to a fixed point: a released job inherits its releaser's response. When every releaser is more urgent than what
/// it releases (the boards' timer jobs and interrupts), a job's jitter is set as its level is entered, from its
/// releaser's final bound, so one pass reaches the fixed point the round-by-round iteration reaches (it is
/// unique: the releases form a chain from more to less urgent) and a second confirms it; otherwise jitters change
/// only between rounds. A second releaser ([`Release::also`]: a transmit job's transmit interrupt, at the job's own
/// priority) is read as its level is entered from the round before, so its response, which the job's jitter grows,
/// reaches its fixed point over the rounds (the least one: every round's jitters are at most the fixed point's).
pub fn analyse<J: Jobs, B: JobBounds>(
    jobs: BoardJobs<'_>,
    meta: &J,
    bounds: &mut B,
    limits: &Limits,
    budget: IterationBudget,
) -> Result<Outcome, OutOfIterations> {
    let BoardJobs {
        timings,
        blocking,
        shares,
        scratch,
    } = jobs;
    let len = timings.len();
    // Whether any job is released by another, and whether every releaser is more urgent than what it releases.
    let (mut chained, mut in_pass) = (false, true);
    for (p, timing) in timings.iter().enumerate() {
        if let Some(Release { by: r, .. }) = meta.release(p) {
            chained = true;
            in_pass &= timings
                .get(r)
                .is_some_and(|releaser| releaser.priority > timing.priority);
        }
    }
    let mut pass = Pass {
        meta,
        blocking,
        shares,
        limits,
        budget,
        in_pass,
        outcome: Outcome::default(),
    };
    for _ in 0..MAX_JITTER_ROUNDS {
        pass.run(timings, bounds, scratch)?;
        if !chained || !inherit(timings, meta, bounds) {
            return Ok(pass.outcome);
        }
    }
    for p in 0..len {
        if meta.release(p).is_some() {
            bounds.put_unbound(p, Unbound::NoConvergence);
        }
    }
    Ok(pass.outcome)
}

/// The jitter job `p` inherits from its releasers' current bounds, or why it has none. Out of line: its three
/// callers share one copy (the chip's flash).
#[inline(never)]
fn inherited<J: Jobs, B: JobBounds>(
    meta: &J,
    bounds: &B,
    p: usize,
) -> Option<Result<Time, Unbound>> {
    let release = meta.release(p)?;
    let second = match release.also {
        None => Some(Time::ZERO),
        Some(also) => bounds.wcrt(also),
    };
    Some(match (bounds.wcrt(release.by), second) {
        (Some(r), Some(s)) => release
            .own_jitter
            .checked_plus(r)
            .and_then(|j| j.checked_plus(s))
            .ok_or(Unbound::Overflow),
        _ => Err(Unbound::Releaser),
    })
}

/// After a round: every released job takes its releaser's bound as jitter; whether a jitter changed (another round
/// is needed). A job whose releaser has no bound has none either.
fn inherit<J: Jobs, B: JobBounds>(timings: &mut [TaskTiming], meta: &J, bounds: &mut B) -> bool {
    let mut changed = false;
    for (p, timing) in timings.iter_mut().enumerate() {
        match inherited(meta, bounds, p) {
            Some(Ok(jitter)) if timing.jitter != jitter => {
                timing.jitter = jitter;
                changed = true;
            }
            Some(Err(why)) => bounds.put_unbound(p, why),
            _ => {}
        }
    }
    if !changed {
        close_release_chains(timings.len(), meta, bounds);
    }
    changed
}

/// One round over a board's jobs, and what the rounds have found so far.
struct Pass<'a, J> {
    meta: &'a J,
    blocking: &'a [Time],
    shares: &'a [Share],
    limits: &'a Limits,
    budget: IterationBudget,
    /// Whether released jobs take their releasers' bounds as their level is entered.
    in_pass: bool,
    outcome: Outcome,
}

/// The load of every job of the levels entered so far, summed as each level is entered, with its closed-form terms.
#[derive(Default)]
struct Entered {
    prefix: Load,
    linear: LinearTerms,
    /// The least `T − J` of the jobs summed that cost anything: a window no longer than it holds one activation of
    /// each.
    once_gap: u64,
}

/// One job as a pass reaches it: its timing, blocking and share, and its interferers' load.
struct Job {
    at: usize,
    task: TaskTiming,
    blocking: Time,
    own: Share,
    /// The load of every job of its own and the more urgent levels but itself.
    load: Load,
}

impl<J: Jobs> Pass<'_, J> {
    fn run<B: JobBounds>(
        &mut self,
        timings: &mut [TaskTiming],
        bounds: &mut B,
        scratch: &mut [Counter],
    ) -> Result<(), OutOfIterations> {
        let mut entered = Entered {
            once_gap: u64::MAX,
            ..Entered::default()
        };
        let mut level_start = 0;
        let mut previous_level = 0..0;
        for i in 0..timings.len() {
            let Some(priority) = timings.get(i).map(|t| t.priority) else {
                break;
            };
            if i == 0 || timings.get(i - 1).is_some_and(|t| t.priority != priority) {
                previous_level = level_start..i;
                level_start = i;
                self.enter_level(timings, i, bounds, &mut entered);
            }
            let (Some(&task), Some(&blocking)) = (timings.get(i), self.blocking.get(i)) else {
                break;
            };
            let own = self.shares.get(i).copied().unwrap_or_default();
            let job = Job {
                at: i,
                task,
                blocking,
                own,
                load: entered.prefix.minus(own.load(task.jitter)),
            };
            if !B::WHOLE_RECORDS && self.closed_form(&job, &entered, bounds) {
                continue;
            }
            self.fixed_point(timings, &job, previous_level.clone(), bounds, scratch)?;
        }
        Ok(())
    }

    /// Entering the level that starts at `i`: its released jobs take their (more urgent, done) releasers' bounds
    /// when jitters are set in the pass, and its load, with its jitters as they are now, is summed.
    fn enter_level<B: JobBounds>(
        &self,
        timings: &mut [TaskTiming],
        i: usize,
        bounds: &B,
        entered: &mut Entered,
    ) {
        let end = self.meta.level_end(i);
        if self.in_pass {
            for p in i..end {
                if let (Some(Ok(jitter)), Some(timing)) =
                    (inherited(self.meta, bounds, p), timings.get_mut(p))
                {
                    timing.jitter = jitter;
                }
            }
        }
        for (share, timing) in self.shares.iter().zip(timings.iter()).take(end).skip(i) {
            let load = share.load(timing.jitter);
            entered.prefix = entered.prefix.plus(load);
            let (c, t, j) = (
                timing.wcet.as_ns(),
                timing.period.as_ns(),
                timing.jitter.as_ns(),
            );
            entered.linear = entered.linear.plus(LinearTerms::of(load, c, t, j));
            if c > 0 {
                entered.once_gap = entered.once_gap.min(t.saturating_sub(j));
            }
        }
    }

    /// Settles job `i` in closed form when one applies; whether it did.
    ///
    /// Exactly, without a fixed point: when `w = B + C + Σ C_k` (every job of this and the more urgent levels once)
    /// leaves each of them, this one included, its next activation outside the window (`w + J_k ≤ T_k`), the
    /// window's demand is `w` there and at least `w` anywhere below it, so `w` is the least fixed point and the
    /// job's response is `w + J` (one instance) — the fixed point's response and first window. Not when the fixed
    /// point would report an overload, or beyond the horizon.
    ///
    /// An upper bound, for a job only a deadline check reads ([`Jobs::verdict_only`]), when the linear bound meets
    /// its deadline: one instance in its window (`w̄ + J ≤ T`), so its response is at most `w̄ + J`, and the level's
    /// shares rounded up within 100 % (so the fixed point's, rounded down, are no overload).
    fn closed_form<B: JobBounds>(&mut self, job: &Job, entered: &Entered, bounds: &mut B) -> bool {
        let Job {
            at: i,
            task,
            blocking,
            own,
            load,
        } = *job;
        let own_load = own.load(task.jitter);
        let (c, t, j) = (task.wcet.as_ns(), task.period.as_ns(), task.jitter.as_ns());
        let horizon = self.limits.horizon.as_ns();
        let overload = load.utilisation.saturating_add(own.utilisation()) > UTIL_ONE
            || (load.utilisation >= UTIL_ONE && c > 0);
        let once = blocking.as_ns().saturating_add(entered.linear.cost);
        if c > 0
            && t > 0
            && entered.prefix.zero_periods == 0
            && !overload
            && once <= entered.once_gap
            && once <= horizon
        {
            bounds.put_closed_form(
                i,
                Time::from_ns(once.saturating_add(j)),
                Time::from_ns(once),
            );
            self.outcome.reach = self.outcome.reach.max(once);
            return true;
        }
        let Some(deadline) = self.meta.verdict_only(i) else {
            return false;
        };
        let settled = (entered.linear.utilisation <= UTIL_ONE)
            .then(|| {
                let others = entered.linear.minus(LinearTerms::of(own_load, c, t, j));
                linear_bound(c, blocking.as_ns(), others)
            })
            .flatten()
            .map(|w| (w, w.saturating_add(j)))
            .filter(|&(w, r)| r <= t && r <= deadline.as_ns() && w <= horizon);
        let Some((w, r)) = settled else {
            return false;
        };
        // An upper bound, read only by the deadline check: no start hint for the levels below.
        bounds.put_closed_form(i, Time::from_ns(r), Time::ZERO);
        self.outcome.reach = self.outcome.reach.max(w);
        true
    }

    /// Job `i`'s fixed point, started from a more urgent level's first window when that is provably below this
    /// one's (Sjödin and Hansson's start value, as [`board::response_times`]).
    fn fixed_point<B: JobBounds>(
        &mut self,
        timings: &[TaskTiming],
        job: &Job,
        previous_level: Range<usize>,
        bounds: &mut B,
        scratch: &mut [Counter],
    ) -> Result<(), OutOfIterations> {
        let Job {
            at: i,
            task,
            blocking,
            ..
        } = *job;
        // f_i(w) ≥ f_k(w) − B_k + B_i + C_i, so w_i ≥ w_k whenever B_k ≤ B_i + C_i.
        let hint = previous_level
            .filter(|&k| {
                self.blocking
                    .get(k)
                    .is_some_and(|&b| b <= blocking.plus(task.wcet))
            })
            .filter_map(|k| bounds.first_window(k))
            .max()
            .unwrap_or(Time::ZERO);
        let limits = match self.budget {
            IterationBudget::PerJob => *self.limits,
            IterationBudget::Board => Limits {
                iterations: self
                    .limits
                    .iterations
                    .saturating_sub(self.outcome.iterations),
                ..*self.limits
            },
        };
        let result = board::response_time_at_level(
            timings,
            i,
            self.meta.level_end(i),
            blocking,
            hint,
            job.load,
            job.own,
            &limits,
            scratch,
        );
        match result {
            Ok(r) => {
                self.outcome.iterations += r.iterations;
                self.outcome.reach = self.outcome.reach.max(r.busy_window.as_ns());
            }
            Err(AnalysisError::IterationLimit) if self.budget == IterationBudget::Board => {
                return Err(OutOfIterations);
            }
            // Any unbounded response but an overload may depend on the horizon.
            Err(e) => self.outcome.beyond |= e != AnalysisError::Overload,
        }
        bounds.put(i, result);
        Ok(())
    }
}

/// After the last round: a job placed before its releaser in the order read the releaser's bound before the
/// walk took it away, so release chains are followed to their ends, one link more a pass (a chain is at most
/// every job long), until every job released by one without a bound has none either.
fn close_release_chains<J: Jobs, B: JobBounds>(len: usize, meta: &J, bounds: &mut B) {
    for _ in 0..len {
        let mut lost = false;
        for p in 0..len {
            if bounds.wcrt(p).is_none() {
                continue;
            }
            if let Some(Err(why)) = inherited(meta, bounds, p) {
                bounds.put_unbound(p, why);
                lost = true;
            }
        }
        if !lost {
            break;
        }
    }
}
