//! The sensor buses' rounds, the one implementation both the report ([`crate::sensor_bus`]) and the on-chip check
//! ([`crate::admission`]) run for a board whose jobs suspend on its sensor buses (docs/analysis.md,
//! "Self-suspending publishers and the sensor buses").
//!
//! From zero jitters, rounds of:
//!
//! 1. each script's response on its bus (non-preemptive fixed priority, [`can::response_time`], without its
//!    siblings, the other scripts of its RTIC task), its jitter its job's own-view response: its suspension;
//! 2. the board once per *view* (the caller's [`SuspendingBoard::analyse_view`], the board analysis): one view per
//!    RTIC task with a suspending job, where its jobs cost their suspensions, settles and one blocking per
//!    resumption (suspension-oblivious), every job of every other such task its CPU with jitter `R − C` and every
//!    default-view job released by a default-view job the jitter the default view found for it, and the default
//!    view;
//! 3. after the default view's analysis, each bus's engine events on the CPU and each script as one job at the
//!    engine's priority ([`board::response_time`]): a script's bus time is the lower of its wire time plus its
//!    events' own responses and the script as one job;
//! 4. the suspending tasks' jobs' own-view responses as the next jitters;
//!
//! until no response and no bus time changes. A script, an engine event or a suspending task's job without a
//! bound, or rounds run out: every job not above every suspending job and every engine, or in a suspending RTIC
//! task, and every job released by one of those, has no bound ([`SuspendingBoard::unbound`]).
//!
//! `no_std` and allocation-free: the caller owns the storage ([`Work`]: fixed arrays on the chip, vectors on the
//! host) and says through [`SuspendingBoard`] what the rounds read of its jobs and scripts and where the results
//! go; the report keeps each script's bus response and each bus's event response through the same trait.

use crate::board::{self, TaskTiming};
use crate::board_analysis::{OutOfIterations, Outcome};
use crate::busy_window::{AnalysisError, Counter, Limits, Response, Share};
use crate::can::{self, MessageTiming};
use crate::time::Time;

/// A bus's engine as the rounds read it: its priority, its charge's parts and the SRP blocking at its priority.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Engine {
    /// The engine interrupt's priority.
    pub priority: u32,
    /// One event's cost on the CPU, the interrupt's entry and exit included.
    pub per_event: Time,
    /// The per-script part (a script's end and its client's wake), 0 where not stated.
    pub per_script: Time,
    /// The condition wait, charged once per START condition, 0 where not stated.
    pub condition_wait: Time,
    /// The SRP blocking of a job at the engine's priority (once per resumption of an event).
    pub blocking: Time,
}

impl Engine {
    /// The engine's charge for one script of `events` events and `starts` START conditions: each event's cost,
    /// the per-script part once and the condition wait once per START (the engine row's cost).
    pub fn charge(&self, events: u32, starts: u32) -> Time {
        self.per_event
            .times(u64::from(events))
            .plus(self.per_script)
            .plus(self.condition_wait.times(u64::from(starts)))
    }

    /// Each kind of event's cost: plain, with the condition wait, the ending one (per-script part and wait).
    pub fn costs(&self) -> Events {
        Events {
            plain: self.per_event,
            waiting: self.per_event.plus(self.condition_wait),
            ending: self
                .per_event
                .plus(self.per_script)
                .plus(self.condition_wait),
        }
    }
}

/// A figure per kind of engine event (their costs, or their worst responses on the CPU).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Events {
    /// An event with the per-event part alone.
    pub plain: Time,
    /// An event that takes the condition wait.
    pub waiting: Time,
    /// The event that ends a script: the per-script part and the condition wait.
    pub ending: Time,
}

impl Events {
    /// What a script's `events` hold SCL on the CPU: its ending event, one that takes the condition wait per
    /// further START (as many as its other events allow), the rest plain. The ending event is charged the wait as
    /// well, so whichever event takes which wait, each event is charged at least its cost.
    pub fn held(&self, events: u32, starts: u32) -> Time {
        let Some(others) = events.checked_sub(1) else {
            return Time::ZERO;
        };
        let waiting = starts.min(others);
        self.ending
            .plus(self.waiting.times(u64::from(waiting)))
            .plus(self.plain.times(u64::from(others - waiting)))
    }
}

/// A running script as the rounds read it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ScriptJob {
    /// Its job's sorted position.
    pub job: usize,
    /// Its engine row's sorted position.
    pub engine: usize,
    /// Its bus (index of [`SuspendingBoard::engine`]).
    pub bus: usize,
    /// Its wire time and the devices' stretch (the rounds add its events' time on the CPU).
    pub wire: Time,
    /// Engine events it raises.
    pub events: u32,
    /// Its START conditions (the events that take the condition wait).
    pub starts: u32,
    /// Its job's own wait before it submits it (suspension, not bus time).
    pub settle: Time,
}

/// One script's response on its bus, as a round found it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OnBus {
    /// Its response from its nominal submission (its jitter included).
    pub result: Result<Response, AnalysisError>,
    /// Its bus time used.
    pub bus_time: Time,
    /// Its jitter used (its job's own-view response).
    pub jitter: Time,
    /// Its blocking by the longest lower-priority script.
    pub blocking: Time,
}

/// What left a job without a bound.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Failure {
    /// Script `script` has no bound on its bus.
    Script {
        /// The script (index of [`SuspendingBoard::script`]).
        script: usize,
        /// Why.
        why: AnalysisError,
    },
    /// An engine event of bus `bus` has no bound on the CPU (every script on it fails).
    Event {
        /// The bus.
        bus: usize,
        /// Why.
        why: AnalysisError,
    },
    /// Job `job` of a suspending RTIC task has no bound in its own view, or a default-view job's releaser has no
    /// bound in the default view while a suspending task's view needs its jitter (the caller's bound says why).
    Job {
        /// Its sorted position.
        job: usize,
    },
    /// The rounds ran out ([`Budget::Rounds`]): every script's job fails.
    Rounds,
}

/// How the rounds' work is limited.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Budget {
    /// At most this many rounds; each fixed point has [`Limits::iterations`] of its own (the report).
    Rounds(usize),
    /// [`Limits::iterations`] for the whole board, one per round counted besides the fixed points' (the chip):
    /// beyond it the rounds stop with [`OutOfIterations`].
    Board,
}

/// What the rounds read of a board with scripts and where their results go, per sorted position of its jobs
/// (most urgent first).
pub trait SuspendingBoard {
    /// How many running scripts, in their jobs' sorted order (most urgent first; a job's in its order): a bus's
    /// scripts are analysed in that order, which must be by priority (else they have no bound, `NotSorted`).
    fn scripts(&self) -> usize;
    /// Script `k`.
    fn script(&self, k: usize) -> Option<ScriptJob>;
    /// How many buses.
    fn buses(&self) -> usize;
    /// Bus `b`'s engine.
    fn engine(&self, b: usize) -> Option<Engine>;
    /// Job `p`'s view: 0 (the default) or `v` for the `v`th RTIC task with a running script.
    fn view(&self, p: usize) -> usize;
    /// How many RTIC tasks have a running script (the views besides the default).
    fn views(&self) -> usize;
    /// Job `p`'s own release jitter.
    fn own_jitter(&self, p: usize) -> Time;
    /// The job whose completion releases job `p`.
    fn released_by(&self, p: usize) -> Option<usize>;
    /// Analyses the board's jobs (the first [`Work::jobs`] of `timings`, `shares` and `unreleased`, the caller's
    /// whole arrays: each jitter its own or, for a job `unreleased` marks, the view's; jitters found by release
    /// chains left in place) under `limits`: every job's bound into the caller's storage, read back through
    /// [`SuspendingBoard::keep`]. `cut` is [`Work::own`]: for a default-view job whose release the view cut, the
    /// jitter the view set, on which a second releaser ([`crate::board_analysis::Release::also`], a transmit job's
    /// transmit interrupt) adds its response (the analysis overwrites `timings`' jitters with what it inherits).
    fn analyse_view(
        &mut self,
        timings: &mut [TaskTiming],
        shares: &[Share],
        unreleased: &[bool],
        cut: &[Time],
        limits: &Limits,
    ) -> Result<Outcome, OutOfIterations>;
    /// Job `p`'s bound in the view just analysed ([`SuspendingBoard::analyse_view`]), `None` while it has none.
    fn current(&self, p: usize) -> Option<Time>;
    /// Job `p`'s bound in this view by its CPU segments (one instance, its period at least `found.wcrt`): the
    /// caller keeps the lower of it and the view's.
    fn refine(&mut self, p: usize, found: Response);
    /// After view `v`'s analysis (`timings` as it found them): keeps the bounds of the jobs of that view as their
    /// own.
    fn keep(&mut self, v: usize, timings: &[TaskTiming]);
    /// Job `p`'s kept bound (its own view's), `None` while it has none.
    fn kept(&self, p: usize) -> Option<Time>;
    /// Script `k`'s response on its bus in this round (the report keeps it).
    fn on_bus(&mut self, _k: usize, _found: &OnBus) {}
    /// Bus `b`'s plain event response in this round, or why it has none (the report keeps it).
    fn event(&mut self, _b: usize, _plain: Result<Time, AnalysisError>) {}
    /// A failure of the round (each is told; the rounds stop after the step that found it).
    fn fail(&mut self, failure: Failure);
    /// Job `p` has no bound after a failure: released by unbounded job `releaser`, or (`None`) as a job the
    /// rounds move that is not above every suspending job and every engine, or the failing job itself.
    fn unbound(&mut self, p: usize, releaser: Option<usize>);
}

/// The rounds' storage, owned by the caller: per sorted job (`jobs` of them) and per script.
pub struct Work<'a> {
    /// The board's jobs as built (most urgent first): their costs and own jitters; one slot more than the jobs
    /// (an engine event takes the place after the jobs at or above the engine for the while). Changed per view;
    /// as built again afterwards but for the jitters.
    pub timings: &'a mut [TaskTiming],
    /// How many jobs.
    pub jobs: usize,
    /// Their SRP blockings.
    pub blocking: &'a [Time],
    /// Their CPU shares (as built; changed per view with the costs).
    pub shares: &'a mut [Share],
    /// Per job: its cost as built.
    pub base: &'a mut [Time],
    /// Per job: its own-view response (a suspending task's job's jitter in the other views); for a default-view
    /// job whose release the view being analysed cut, the jitter the view set (read by a second releaser,
    /// [`SuspendingBoard::analyse_view`]: kept here, not in a copy, for the chip's stack).
    pub own: &'a mut [Time],
    /// Per job: whether a view sets its jitter itself (its release cut); the unbounded ones after a failure.
    pub unreleased: &'a mut [bool],
    /// Per script: its suspension.
    pub suspension: &'a mut [Time],
    /// Per script: its bus time.
    pub bus_times: &'a mut [Time],
    /// Per script: a bus's scripts as its analysis reads them.
    pub subset: &'a mut [MessageTiming],
    /// The busy-window analysis's working memory, at least one more than the jobs.
    pub scratch: &'a mut [Counter],
}

/// The rounds' state and what they have spent.
struct Rounds<'w, 'a, S> {
    board: &'w mut S,
    work: &'w mut Work<'a>,
    limits: &'w Limits,
    budget: Budget,
    spent: u64,
    /// Whether this round's engine events moved a script's bus time.
    moved: bool,
    /// Whether a step failed.
    failed: bool,
    /// The highest priority of a failing job.
    failed_top: u32,
    /// Whether the default view has been analysed.
    viewed: bool,
}

/// Runs the rounds to their fixed point (docs/analysis.md, "Self-suspending publishers and the sensor buses"):
/// every job's bound stays in the caller's storage, each from its own view ([`SuspendingBoard::keep`]); the
/// iterations spent, or [`OutOfIterations`] under [`Budget::Board`].
#[inline(never)]
pub fn analyse<S: SuspendingBoard>(
    board: &mut S,
    work: &mut Work<'_>,
    limits: &Limits,
    budget: Budget,
) -> Result<u64, OutOfIterations> {
    let jobs = work.jobs;
    for (slot, t) in work.base.iter_mut().zip(work.timings.iter()).take(jobs) {
        *slot = t.wcet;
    }
    for slot in work.own.iter_mut().take(jobs) {
        *slot = Time::ZERO;
    }
    for k in 0..board.scripts() {
        if let (Some(slot), Some(s)) = (work.bus_times.get_mut(k), board.script(k)) {
            *slot = s.wire;
        }
    }
    let mut rounds = Rounds {
        board,
        work,
        limits,
        budget,
        spent: 0,
        moved: false,
        failed: false,
        failed_top: 0,
        viewed: false,
    };
    let most = match budget {
        Budget::Rounds(n) => n as u64,
        Budget::Board => limits.iterations,
    };
    let mut converged = false;
    for _ in 0..most {
        if budget == Budget::Board {
            rounds.limits()?;
            rounds.spent += 1;
        }
        converged = rounds.round()?;
        if rounds.failed || converged {
            break;
        }
    }
    if !rounds.failed && !converged {
        if budget == Budget::Board {
            return Err(OutOfIterations);
        }
        rounds.fail(Failure::Rounds);
    }
    if rounds.failed {
        if !rounds.viewed {
            // A script without a bound in the first round: the jobs above every suspending job and every engine
            // keep their bounds, which no suspension moves; the default view once finds them.
            rounds.default_view()?;
        }
        rounds.mark_unbounded();
    }
    Ok(rounds.spent)
}

impl<S: SuspendingBoard> Rounds<'_, '_, S> {
    /// The limits of the next fixed point: under [`Budget::Board`], what is left of the board's iterations.
    fn limits(&self) -> Result<Limits, OutOfIterations> {
        match self.budget {
            Budget::Rounds(_) => Ok(*self.limits),
            Budget::Board => {
                let left = self.limits.iterations.saturating_sub(self.spent);
                if left == 0 {
                    return Err(OutOfIterations);
                }
                Ok(Limits {
                    horizon: self.limits.horizon,
                    iterations: left,
                })
            }
        }
    }

    /// A fixed point's outcome counted: out of the board's iterations is [`OutOfIterations`].
    fn count(
        &mut self,
        result: Result<Response, AnalysisError>,
    ) -> Result<Result<Response, AnalysisError>, OutOfIterations> {
        match result {
            Ok(r) => self.spent += r.iterations,
            Err(AnalysisError::IterationLimit) if self.budget == Budget::Board => {
                return Err(OutOfIterations)
            }
            Err(_) => {}
        }
        Ok(result)
    }

    fn priority(&self, p: usize) -> u32 {
        self.work.timings.get(p).map_or(0, |t| t.priority)
    }

    fn fail(&mut self, failure: Failure) {
        let top = match failure {
            Failure::Script { script, .. } => self.board.script(script).map(|s| s.job),
            Failure::Job { job } => Some(job),
            Failure::Event { .. } | Failure::Rounds => None,
        }
        .map_or(0, |p| self.priority(p));
        self.failed_top = self.failed_top.max(top);
        self.failed = true;
        self.board.fail(failure);
    }

    /// The default view alone, its jobs' bounds kept (after a failure before any view).
    fn default_view(&mut self) -> Result<(), OutOfIterations> {
        self.view_jobs(0);
        let limits = self.limits()?;
        let w = &mut *self.work;
        let outcome =
            self.board
                .analyse_view(w.timings, &*w.shares, &*w.unreleased, &*w.own, &limits)?;
        self.spent += outcome.iterations;
        let w = &mut *self.work;
        self.board.keep(0, w.timings);
        Ok(())
    }

    /// One round; whether it reached the fixed point (no response and no bus time changed).
    fn round(&mut self) -> Result<bool, OutOfIterations> {
        // 1. Each script on its bus: its suspension, from its actual submission.
        for k in 0..self.board.scripts() {
            self.on_bus(k)?;
        }
        if self.failed {
            return Ok(false);
        }
        // 2. The board once per view; after the default view's analysis, 3., the engine events.
        self.moved = false;
        for v in 0..=self.board.views() {
            self.view_jobs(v);
            let limits = self.limits()?;
            let w = &mut *self.work;
            let outcome =
                self.board
                    .analyse_view(w.timings, &*w.shares, &*w.unreleased, &*w.own, &limits)?;
            self.spent += outcome.iterations;
            if v != 0 {
                self.segmented(v)?;
            }
            let w = &mut *self.work;
            self.board.keep(v, w.timings);
            self.viewed = true;
            if v == 0 {
                for b in 0..self.board.buses() {
                    self.events(b)?;
                }
            }
        }
        // 4. The suspending tasks' jobs' responses: the next jitters.
        let mut converged = !self.moved;
        for p in 0..self.work.jobs {
            if self.board.view(p) == 0 {
                continue;
            }
            match (self.board.kept(p), self.work.own.get_mut(p)) {
                (Some(r), Some(slot)) => {
                    converged &= *slot == r;
                    *slot = r;
                }
                _ => self.fail(Failure::Job { job: p }),
            }
        }
        Ok(converged)
    }

    /// View `v`'s suspending jobs bounded by their CPU segments as well (docs/analysis.md, "The suspending job by
    /// its segments"): a job that runs `r` resumptions (one after each script, one more after each settle) runs its
    /// CPU `C` in `r + 1` segments, each, from when it is ready, at most the response `W` of one instance of `C`
    /// alone at its place (its blocking, the interference of every job at or above its priority, its siblings at
    /// their suspension-oblivious cost; a segment of `c ≤ C` meets no more: `c + (W − C)`), so its response is at
    /// most its suspensions and settles plus `W + r · (W − C)` (Chen et al. 2019, §5: the suspension neither
    /// executed nor met by the interference of another window). That holds only while the job's previous instance
    /// has ended at its next activation: a bound above its period is not taken. The caller keeps the lower of it and
    /// the view's suspension-oblivious bound, both sound.
    #[inline(never)]
    fn segmented(&mut self, v: usize) -> Result<(), OutOfIterations> {
        for p in 0..self.work.jobs {
            if self.board.view(p) != v {
                continue;
            }
            let (mut suspended, mut resumptions) = (Time::ZERO, 0u64);
            for k in 0..self.board.scripts() {
                let Some(s) = self.board.script(k).filter(|s| s.job == p) else {
                    continue;
                };
                let suspension = self.work.suspension.get(k).copied().unwrap_or(Time::ZERO);
                suspended = suspended.plus(suspension).plus(s.settle);
                resumptions += if s.settle > Time::ZERO { 2 } else { 1 };
            }
            let (Some(me), Some(&cpu)) = (self.work.timings.get(p).copied(), self.work.base.get(p))
            else {
                continue;
            };
            if resumptions == 0 {
                continue;
            }
            // Its jitter: as the view set it where it cut its release, else its own plus its releaser's bound in
            // this view. A releaser without one leaves it none: the view's error stands (not a bound that leaves
            // the inherited jitter out).
            let cut = self.work.unreleased.get(p).copied().unwrap_or(false);
            let jitter = match self.board.released_by(p).filter(|_| !cut) {
                None => me.jitter,
                Some(by) => match self.board.current(by) {
                    Some(r) => self.board.own_jitter(p).plus(r),
                    None => continue,
                },
            };
            // One instance of its CPU alone at its place, from its release (its jitter added once below: one
            // instance's window does not depend on its own jitter).
            if let Some(slot) = self.work.timings.get_mut(p) {
                *slot = TaskTiming {
                    wcet: cpu,
                    period: self.limits.horizon,
                    jitter: Time::ZERO,
                    ..me
                };
            }
            let limits = self.limits()?;
            let jobs = self.work.jobs;
            let result = board::response_time(
                self.work.timings.get(..jobs).unwrap_or(&[]),
                p,
                self.work.blocking.get(p).copied().unwrap_or(Time::ZERO),
                &limits,
                self.work.scratch,
            );
            if let Some(slot) = self.work.timings.get_mut(p) {
                *slot = me;
            }
            let Ok(alone) = self.count(result)? else {
                continue;
            };
            let around = alone.wcrt.minus(cpu);
            let bound = jitter
                .plus(suspended)
                .plus(alone.wcrt)
                .plus(around.times(resumptions));
            if bound <= me.period {
                self.board.refine(
                    p,
                    Response {
                        wcrt: bound,
                        worst_instance: 0,
                        instances: 1,
                        busy_window: bound,
                        interference: around.times(resumptions + 1),
                        first_window: bound,
                        iterations: alone.iterations,
                    },
                );
            }
        }
        Ok(())
    }

    /// Script `k`'s response on its bus among the bus's scripts that are not its siblings (the other scripts of
    /// its RTIC task: a job submits its scripts one after the other and the task runs one job at a time, so no
    /// sibling waits or is on the bus while it is pending), each with its job's own-view response as jitter and
    /// its bus time as the last round found it; its suspension is the response minus its jitter.
    #[inline(never)]
    fn on_bus(&mut self, k: usize) -> Result<(), OutOfIterations> {
        let Some(me) = self.board.script(k) else {
            return Ok(());
        };
        let my_view = self.board.view(me.job);
        let (mut len, mut at) = (0, 0);
        for o in 0..self.board.scripts() {
            let Some(s) = self.board.script(o) else {
                continue;
            };
            let sibling = o != k && self.board.view(s.job) == my_view;
            if s.bus != me.bus || sibling {
                continue;
            }
            let job = self.work.timings.get(s.job).copied();
            let timing = MessageTiming {
                // Lower key first: the most urgent submitter; equal priorities share a key and interfere.
                key: u32::MAX - job.map_or(0, |j| j.priority),
                frame_time: self.work.bus_times.get(o).copied().unwrap_or(s.wire),
                frames: 1,
                period: job.map_or(Time::ZERO, |j| j.period),
                jitter: self.work.own.get(s.job).copied().unwrap_or(Time::ZERO),
            };
            // In key order: the scripts come in their jobs' order, most urgent first.
            let Some(slot) = self.work.subset.get_mut(len) else {
                break;
            };
            *slot = timing;
            if o == k {
                at = len;
            }
            len += 1;
        }
        let limits = self.limits()?;
        let subset = self.work.subset.get(..len).unwrap_or(&[]);
        let blocking = can::blocking(subset, at);
        // A script submitted at the very instant the engine picks the next one counts as in time (1 ns).
        let result = can::response_time(
            subset,
            at,
            blocking,
            Time::from_ns(1),
            &limits,
            self.work.scratch,
        );
        let me_timing = subset.get(at).copied();
        let result = self.count(result)?;
        let found = OnBus {
            result,
            bus_time: me_timing.map_or(Time::ZERO, |m| m.frame_time),
            jitter: me_timing.map_or(Time::ZERO, |m| m.jitter),
            blocking,
        };
        self.board.on_bus(k, &found);
        match result {
            Ok(r) => {
                if let Some(slot) = self.work.suspension.get_mut(k) {
                    *slot = r.wcrt.minus(found.jitter);
                }
            }
            Err(why) => self.fail(Failure::Script { script: k, why }),
        }
        Ok(())
    }

    /// View `v`'s jobs in place, from the scripts' suspensions and the suspending tasks' own-view responses:
    /// its own jobs cost their suspensions, settles and a blocking per resumption; every job of every other
    /// suspending task is its CPU with jitter `R − C` and its release cut; every job released by one of them
    /// inherits the releaser's whole own-view response (the larger of it and its `R − C` for a suspending one); in
    /// a suspending task's view every default-view job released by a default-view job takes its releaser's
    /// default-view bound, its release cut (none: a failure); every other job as built.
    fn view_jobs(&mut self, v: usize) {
        let board = &*self.board;
        let w = &mut *self.work;
        let mut orphan = None;
        for p in 0..w.jobs {
            let base = w.base.get(p).copied().unwrap_or(Time::ZERO);
            let mut cost = base;
            if board.view(p) == v {
                let b = w.blocking.get(p).copied().unwrap_or(Time::ZERO);
                for k in 0..board.scripts() {
                    let Some(s) = board.script(k).filter(|s| s.job == p) else {
                        continue;
                    };
                    // Suspension-oblivious: the suspension, the settle and a blocking per resumption (after the
                    // settle's wait and after the script) as execution.
                    let resumptions = if s.settle > Time::ZERO { 2 } else { 1 };
                    cost = cost
                        .plus(w.suspension.get(k).copied().unwrap_or(Time::ZERO))
                        .plus(s.settle)
                        .plus(b.times(resumptions));
                }
            }
            let mut jitter = board.own_jitter(p);
            let mut cut = false;
            // Another suspending task's job: its CPU anywhere in its own-view response.
            let view = board.view(p);
            if view != 0 && view != v {
                jitter = w.own.get(p).copied().unwrap_or(Time::ZERO).minus(base);
                cut = true;
            }
            // Released by a suspending task's job: that job's whole own-view response, or, for another suspending
            // task's job, its `R − C` where larger (its own-view response counts from its activation, so its
            // inherited release with its suspensions: the release alone would leave the suspensions out).
            if let Some(by) = board.released_by(p).filter(|&by| board.view(by) != 0) {
                jitter = jitter.max(
                    board
                        .own_jitter(p)
                        .plus(w.own.get(by).copied().unwrap_or(Time::ZERO)),
                );
                cut = true;
            }
            // In a suspending task's view, a default-view job released by a default-view job: its jitter from the
            // default view (analysed first this round), its release cut. The view's own bound of its releaser may
            // be none (the suspending job's suspensions as execution may overload it) where the default view's is
            // one; without either the job's jitter is not known and the view's jobs at or below it have no bound.
            if v != 0 && view == 0 && !cut {
                if let Some(by) = board.released_by(p).filter(|&by| board.view(by) == 0) {
                    match board.kept(by) {
                        Some(r) => {
                            jitter = board.own_jitter(p).plus(r);
                            cut = true;
                        }
                        None => orphan = orphan.or(Some(p)),
                    }
                }
            }
            if let (Some(t), Some(share)) = (w.timings.get_mut(p), w.shares.get_mut(p)) {
                if cost != t.wcet {
                    t.wcet = cost;
                    *share = Share::of(cost, t.period);
                }
                t.jitter = jitter;
            }
            if let Some(slot) = w.unreleased.get_mut(p) {
                *slot = cut;
            }
            // A default-view job's own-view response is never read: its slot keeps the cut jitter for a second
            // releaser (`SuspendingBoard::analyse_view`).
            if let (true, 0, Some(slot)) = (cut, view, w.own.get_mut(p)) {
                *slot = jitter;
            }
        }
        if let Some(job) = orphan {
            self.fail(Failure::Job { job });
        }
    }

    /// Bus `b`'s engine events on the CPU in the default view's jobs (after their analysis, so that a released
    /// job carries the jitter it inherits from its releaser): each at the engine's priority, interfered with by
    /// every job at or above it but the bus's own engine rows (these very events, one at a time; costed 0 for the
    /// while), blocked as a job of that priority, the event placed after the jobs at or above it. Then each script
    /// on the bus as one job the same way (its wire time and its events' work as execution, blocked once per
    /// event), and its bus time the lower of the two bounds, both sound. A bus no running script uses is skipped.
    #[inline(never)]
    fn events(&mut self, b: usize) -> Result<(), OutOfIterations> {
        let scripts = self.board.scripts();
        if !(0..scripts).any(|k| self.on(b, k).is_some()) {
            return Ok(());
        }
        let Some(engine) = self.board.engine(b) else {
            return Ok(());
        };
        for k in 0..scripts {
            if let Some(e) = self.on(b, k).map(|s| s.engine) {
                if let Some(t) = self.work.timings.get_mut(e) {
                    t.wcet = Time::ZERO;
                }
            }
        }
        let jobs = self.work.jobs;
        let end = self
            .work
            .timings
            .iter()
            .take(jobs)
            .position(|t| t.priority < engine.priority)
            .unwrap_or(jobs);
        let kept = self.work.timings.get(end).copied();
        let costs = engine.costs();
        let mut out = Events::default();
        let mut unbounded = None;
        // The three events, then each script on the bus as one job: one call site for both. A script's window
        // without a bound leaves its events' bound.
        for k in 0..3 + scripts {
            let script = k.checked_sub(3);
            let on = script.and_then(|i| self.on(b, i));
            let (cost, resumptions) = match (script, on) {
                (None, _) => (
                    [costs.plain, costs.waiting, costs.ending]
                        .get(k)
                        .copied()
                        .unwrap_or(Time::ZERO),
                    1,
                ),
                (Some(_), Some(s)) => (
                    s.wire.plus(costs.held(s.events, s.starts)),
                    u64::from(s.events),
                ),
                (Some(_), None) => continue,
            };
            if let Some(slot) = self.work.timings.get_mut(end) {
                *slot = TaskTiming {
                    priority: engine.priority,
                    wcet: cost,
                    period: self.limits.horizon,
                    jitter: Time::ZERO,
                };
            }
            let limits = self.limits()?;
            let result = board::response_time(
                self.work.timings.get(..=end).unwrap_or(&[]),
                end,
                engine.blocking.times(resumptions),
                &limits,
                self.work.scratch,
            );
            let result = self.count(result)?.map(|r| r.wcrt);
            match (on, result) {
                (Some(s), _) => {
                    // The events come first: `out` is complete.
                    let per_event = s.wire.plus(out.held(s.events, s.starts));
                    let bus_time = result.map_or(per_event, |w| w.min(per_event));
                    let slot = script.and_then(|i| self.work.bus_times.get_mut(i));
                    if let Some(slot) = slot.filter(|slot| **slot != bus_time) {
                        *slot = bus_time;
                        self.moved = true;
                    }
                }
                (None, Ok(r)) => match k {
                    0 => out.plain = r,
                    1 => out.waiting = r,
                    _ => out.ending = r,
                },
                (None, Err(why)) => unbounded = unbounded.or(Some(why)),
            }
        }
        self.board.event(b, unbounded.map_or(Ok(out.plain), Err));
        if let Some(why) = unbounded {
            self.fail(Failure::Event { bus: b, why });
        }
        // The jobs as they were.
        if let (Some(slot), Some(kept)) = (self.work.timings.get_mut(end), kept) {
            *slot = kept;
        }
        for k in 0..scripts {
            let Some(e) = self.on(b, k).map(|s| s.engine) else {
                continue;
            };
            let base = self.work.base.get(e).copied().unwrap_or(Time::ZERO);
            if let Some(t) = self.work.timings.get_mut(e) {
                t.wcet = base;
            }
        }
        Ok(())
    }

    /// Script `k` if it runs on bus `b`.
    fn on(&self, b: usize, k: usize) -> Option<ScriptJob> {
        self.board.script(k).filter(|s| s.bus == b)
    }

    /// After a failure: every job not above every suspending job, every engine and every failing job, or in a
    /// suspending RTIC task, has no bound (its bound came from a round that did not converge), and so has every
    /// job released by one of those.
    fn mark_unbounded(&mut self) {
        let mut top = self.failed_top;
        for k in 0..self.board.scripts() {
            if let Some(s) = self.board.script(k) {
                top = top.max(self.priority(s.job)).max(self.priority(s.engine));
            }
        }
        let jobs = self.work.jobs;
        for p in 0..jobs {
            let lost = self.priority(p) <= top || self.board.view(p) != 0;
            if lost {
                self.board.unbound(p, None);
            }
            if let Some(slot) = self.work.unreleased.get_mut(p) {
                *slot = lost;
            }
        }
        // Release chains from an unbounded job (at most one job more a pass).
        for _ in 0..jobs {
            let mut changed = false;
            for p in 0..jobs {
                let by = self.board.released_by(p);
                let unbounded = |q: usize| self.work.unreleased.get(q).copied().unwrap_or(false);
                let Some(by) = by.filter(|&by| unbounded(by) && !unbounded(p)) else {
                    continue;
                };
                self.board.unbound(p, Some(by));
                if let Some(slot) = self.work.unreleased.get_mut(p) {
                    *slot = true;
                }
                changed = true;
            }
            if !changed {
                break;
            }
        }
    }
}
