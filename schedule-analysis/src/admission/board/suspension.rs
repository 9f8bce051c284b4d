//! A board whose running jobs run scripts on its sensor buses: the host's `sensor_bus::analyse` on the check's
//! fixed-capacity arrays (docs/analysis.md, "Self-suspending publishers and the sensor buses", "What the chip's
//! check does with scripts"). From zero jitters and event responses, rounds of: each script's response on its bus
//! (non-preemptive fixed priority, [`can::response_time`], without its siblings), the board once per view
//! ([`board_analysis::analyse`]: a view per RTIC task with a suspending job, where its jobs cost their suspensions
//! and one blocking per resumption, every job of every other such task its CPU with jitter `R − C`; and the
//! default view), each bus's engine events on the CPU ([`crate::board::response_time`]); until nothing changes.
//! Every iteration counts against the board's [`SCRIPT_ITERATIONS`] ([`Refusal::Budget`] beyond).

use super::*;

/// A running job's script: its job's and its engine row's sorted positions and its row.
#[derive(Debug, Clone, Copy)]
struct ScriptJob {
    job: u8,
    engine: u8,
    row: ScriptRow,
}

const NO_SCRIPT: ScriptJob = ScriptJob {
    job: 0,
    engine: 0,
    row: ScriptRow {
        bus: 0,
        bus_time: 0,
        events: 0,
        starts: 0,
        settle: 0,
    },
};

/// An engine event's worst responses on the CPU, by what it carries: plain, with the condition wait, the ending one.
type Events = [Time; 3];

/// The running scripts (most urgent job first, each job's in its order) and each job's view.
struct Scripts<const N: usize> {
    list: [ScriptJob; N],
    len: usize,
    /// Per sorted job: 0 (the default view) or `v` for the `v`th RTIC task with a script.
    view: [u8; N],
    views: u8,
}

/// The RTIC task a job belongs to: a fixed task is its own, a publisher job its level's publisher task; timer jobs
/// and engine rows run no script (`None`).
fn group_of<const M: usize>(input: &BoardInput<'_, M>, what: Source) -> Option<u16> {
    match what {
        Source::Fixed(row) => Some(u16::from(row)),
        Source::Publisher { stream, .. } => {
            let level = input.streams.get(usize::from(stream))?.sender?.level;
            let task = input.table.publisher_tasks.get(usize::from(level))?;
            Some(0x100 | u16::from(*task))
        }
        Source::Timer { .. } | Source::Engine { .. } => None,
    }
}

impl<const N: usize> Scripts<N> {
    fn collect<const M: usize>(
        input: &BoardInput<'_, M>,
        set: &BoardSet<N>,
    ) -> Result<Self, Refusal> {
        let mut out = Scripts {
            list: [NO_SCRIPT; N],
            len: 0,
            view: [0; N],
            views: 0,
        };
        let mut groups = [0u16; N];
        let len = set.jobs.len;
        for (p, &what) in set.sources.iter().enumerate().take(len) {
            let scripts = input.scripts_of(what);
            let Some(group) = group_of(input, what).filter(|_| !scripts.is_empty()) else {
                continue;
            };
            let known = groups
                .iter()
                .take(usize::from(out.views))
                .any(|&g| g == group);
            if !known {
                *groups
                    .get_mut(usize::from(out.views))
                    .ok_or(Refusal::Capacity)? = group;
                out.views += 1;
            }
            let original = set.jobs.metas.get(p).map_or(NO_JOB, |m| m.original);
            for (k, row) in scripts.iter().enumerate() {
                let engine = set
                    .jobs
                    .at(original.saturating_add(1).saturating_add(k as u8));
                *out.list.get_mut(out.len).ok_or(Refusal::Capacity)? = ScriptJob {
                    job: p as u8,
                    engine,
                    row: *row,
                };
                out.len += 1;
            }
        }
        for (p, &what) in set.sources.iter().enumerate().take(len) {
            let Some(group) = group_of(input, what) else {
                continue;
            };
            if let (Some(at), Some(slot)) = (
                groups
                    .iter()
                    .take(usize::from(out.views))
                    .position(|&g| g == group),
                out.view.get_mut(p),
            ) {
                *slot = at as u8 + 1;
            }
        }
        Ok(out)
    }

    fn scripts(&self) -> &[ScriptJob] {
        self.list.get(..self.len).unwrap_or(&[])
    }

    fn view(&self, p: usize) -> u8 {
        self.view.get(p).copied().unwrap_or(0)
    }
}

/// The board's jobs as one view's analysis reads them: a released job whose jitter the view sets itself is not
/// released, and a job whose bound the rounds read is never settled in closed form.
struct ViewJobs<'a, const N: usize> {
    index: &'a JobIndex<N>,
    unreleased: &'a [bool; N],
    scripts: &'a Scripts<N>,
}

impl<const N: usize> board_analysis::Jobs for ViewJobs<'_, N> {
    fn release(&self, p: usize) -> Option<board_analysis::Release> {
        if self.unreleased.get(p).copied().unwrap_or(true) {
            return None;
        }
        self.index.release(p)
    }
    fn level_end(&self, p: usize) -> usize {
        self.index.level_end(p)
    }
    fn verdict_only(&self, p: usize) -> Option<Time> {
        if self.scripts.view(p) != 0 {
            return None;
        }
        self.index.verdict_only(p)
    }
}

/// What a round reads of the one before and the limits it runs in.
struct Round<'a, const N: usize, const M: usize> {
    input: &'a BoardInput<'a, M>,
    set: &'a BoardSet<N>,
    scripts: &'a Scripts<N>,
    blocking: &'a [Time; N],
    shares: &'a [Share; N],
    /// Iterations spent on the board so far.
    spent: u64,
}

impl<const N: usize, const M: usize> Round<'_, N, M> {
    /// The limits of the next fixed point: what is left of the board's budget ([`Refusal::Budget`] when nothing).
    fn limits(&self) -> Result<Limits, Refusal> {
        let left = SCRIPT_ITERATIONS.saturating_sub(self.spent);
        if left == 0 {
            return Err(Refusal::Budget);
        }
        Ok(Limits {
            horizon: self.input.limits.horizon,
            iterations: left,
        })
    }

    /// A fixed point's outcome counted; `Ok(None)` when it has no bound (an overload), `Budget` when it ran out.
    fn count(&mut self, result: Result<Response, AnalysisError>) -> Result<Option<Time>, Refusal> {
        match result {
            Ok(r) => {
                self.spent += r.iterations;
                Ok(Some(r.wcrt))
            }
            Err(AnalysisError::IterationLimit) => Err(Refusal::Budget),
            Err(_) => Ok(None),
        }
    }

    fn timing(&self, p: usize) -> TaskTiming {
        self.set.timings.get(p).copied().unwrap_or(EMPTY_TIMING)
    }

    /// What a script's events hold SCL on the CPU: its ending event, one with the condition wait per further
    /// START (as many as its other events allow), the rest plain.
    fn events_of(row: &ScriptRow, events: &Events) -> Time {
        if row.events == 0 {
            return Time::ZERO;
        }
        let others = u64::from(row.events - 1);
        let waiting = u64::from(row.starts).min(others);
        events[2]
            .plus(events[1].times(waiting))
            .plus(events[0].times(others - waiting))
    }

    /// Script `k`'s response on its bus from its nominal submission (`None`: unbounded), among the bus's scripts
    /// that are not its siblings, each with its job's response as jitter.
    #[inline(never)]
    fn on_bus(
        &mut self,
        k: usize,
        response: &[Time; N],
        events: &[Events; MAX_BUSES],
    ) -> Result<Option<Time>, Refusal> {
        let list = self.scripts.scripts();
        let me = list.get(k).ok_or(Refusal::Capacity)?;
        let mut subset = [MessageTiming {
            key: 0,
            frame_time: Time::ZERO,
            frames: 1,
            period: Time::ZERO,
            jitter: Time::ZERO,
        }; N];
        let (mut len, mut at) = (0, 0);
        let my_view = self.scripts.view(usize::from(me.job));
        for (o, s) in list.iter().enumerate() {
            let sibling = o != k && self.scripts.view(usize::from(s.job)) == my_view;
            if s.row.bus != me.row.bus || sibling {
                continue;
            }
            let job = self.timing(usize::from(s.job));
            let bus_events = events
                .get(usize::from(s.row.bus))
                .copied()
                .unwrap_or_default();
            if o == k {
                at = len;
            }
            *subset.get_mut(len).ok_or(Refusal::Capacity)? = MessageTiming {
                // Lower key first: the most urgent submitter; equal priorities share a key and interfere.
                key: u32::MAX - job.priority,
                frame_time: row_time(s.row.bus_time).plus(Self::events_of(&s.row, &bus_events)),
                frames: 1,
                period: job.period,
                jitter: response.get(o).copied().unwrap_or(Time::ZERO),
            };
            len += 1;
        }
        let subset = subset.get(..len).unwrap_or(&[]);
        let blocking = can::blocking(subset, at);
        let mut scratch = const { [Counter::ZERO; N] };
        let limits = self.limits()?;
        // A script submitted at the very instant the engine picks the next one counts as in time (1 ns).
        let result = can::response_time(
            subset,
            at,
            blocking,
            Time::from_ns(1),
            &limits,
            &mut scratch,
        );
        self.count(result)
    }

    /// View `v`'s jobs (costs and jitters; `unreleased` marks the jobs whose jitter the view sets) from the
    /// scripts' suspensions and the suspending tasks' own-view responses.
    fn view_jobs(
        &self,
        v: u8,
        suspension: &[Time; N],
        own: &[Time; N],
        timings: &mut [TaskTiming; N],
        unreleased: &mut [bool; N],
    ) {
        let len = self.set.jobs.len;
        let scripts = self.scripts;
        *timings = self.set.timings;
        *unreleased = [false; N];
        for (s, &suspended) in scripts.scripts().iter().zip(suspension.iter()) {
            let p = usize::from(s.job);
            if scripts.view(p) != v {
                continue;
            }
            // Suspension-oblivious: the suspension, the settle and a blocking per resumption as execution.
            let resumptions = if s.row.settle > 0 { 2 } else { 1 };
            let blocking = self.blocking.get(p).copied().unwrap_or(Time::ZERO);
            if let Some(t) = timings.get_mut(p) {
                t.wcet = t
                    .wcet
                    .plus(suspended)
                    .plus(row_time(s.row.settle))
                    .plus(blocking.times(resumptions));
            }
        }
        for p in 0..len {
            let view = scripts.view(p);
            let (Some(t), Some(cut), Some(meta)) = (
                timings.get_mut(p),
                unreleased.get_mut(p),
                self.set.jobs.metas.get(p),
            ) else {
                continue;
            };
            // Another suspending task's job: its CPU anywhere in its own-view response.
            if view != 0 && view != v {
                t.jitter = own.get(p).copied().unwrap_or(Time::ZERO).minus(t.wcet);
                *cut = true;
            }
            // Released by a suspending task's job: that job's whole own-view response.
            let by = usize::from(meta.released_by);
            if meta.released_by != NO_JOB && scripts.view(by) != 0 {
                t.jitter = meta
                    .own_jitter
                    .plus(own.get(by).copied().unwrap_or(Time::ZERO));
                *cut = true;
            }
        }
    }

    /// The board in view `v`: its jobs' bounds into `next` (only the view's own jobs').
    #[inline(never)]
    fn in_view(
        &mut self,
        timings: &mut [TaskTiming; N],
        unreleased: &[bool; N],
        v: u8,
        next: &mut [u64; N],
    ) -> Result<(), Refusal> {
        let len = self.set.jobs.len;
        let mut shares = *self.shares;
        for ((share, t), base) in shares
            .iter_mut()
            .zip(timings.iter())
            .zip(self.set.timings.iter())
            .take(len)
        {
            if t.wcet != base.wcet {
                *share = Share::of(t.wcet, t.period);
            }
        }
        let mut bounds = JobWcrt {
            wcrt: [NONE; N],
            first_window: [Time::ZERO; N],
        };
        let mut scratch = const { [Counter::ZERO; N] };
        let jobs = board_analysis::BoardJobs {
            timings: timings.get_mut(..len).unwrap_or(&mut []),
            blocking: self.blocking.get(..len).unwrap_or(&[]),
            shares: shares.get(..len).unwrap_or(&[]),
            scratch: &mut scratch,
        };
        let meta = ViewJobs {
            index: &self.set.jobs,
            unreleased,
            scripts: self.scripts,
        };
        let limits = self.limits()?;
        let outcome = board_analysis::analyse(
            jobs,
            &meta,
            &mut bounds,
            &limits,
            board_analysis::IterationBudget::Board,
        )
        .map_err(|_| Refusal::Budget)?;
        self.spent += outcome.iterations;
        for p in 0..len {
            if self.scripts.view(p) == v {
                if let (Some(slot), Some(&w)) = (next.get_mut(p), bounds.wcrt.get(p)) {
                    *slot = w;
                }
            }
        }
        Ok(())
    }

    /// Bus `b`'s engine events on the CPU in the default view (`timings`, before its analysis): each at the
    /// engine's priority, interfered with by every job at or above it but the bus's own engine rows (these very
    /// events, one at a time), blocked as a job of that priority. `None`: unbounded.
    #[inline(never)]
    fn events(&mut self, b: usize, timings: &[TaskTiming; N]) -> Result<Option<Events>, Refusal> {
        let Some(bus) = self.input.table.buses.get(b) else {
            return Ok(Some(Events::default()));
        };
        let engine = u32::from(bus.engine_priority);
        let mut tasks = [EMPTY_TIMING; N];
        let mut len = 0;
        for (p, t) in timings.iter().enumerate().take(self.set.jobs.len) {
            let own_row = self
                .scripts
                .scripts()
                .iter()
                .any(|s| usize::from(s.engine) == p && usize::from(s.row.bus) == b);
            if own_row || t.priority < engine {
                continue;
            }
            *tasks.get_mut(len).ok_or(Refusal::Capacity)? = *t;
            len += 1;
        }
        let blocking = blocking_at(self.input, engine);
        let wait = row_time(bus.condition_wait);
        let costs = [
            row_time(bus.per_event),
            row_time(bus.per_event).plus(wait),
            row_time(bus.per_event)
                .plus(row_time(bus.per_script))
                .plus(wait),
        ];
        let mut out = Events::default();
        for (slot, cost) in out.iter_mut().zip(costs) {
            *tasks.get_mut(len).ok_or(Refusal::Capacity)? = TaskTiming {
                priority: engine,
                wcet: cost,
                period: self.input.limits.horizon,
                jitter: Time::ZERO,
            };
            let mut scratch = const { [Counter::ZERO; N] };
            let limits = self.limits()?;
            let result = crate::board::response_time(
                tasks.get(..=len).unwrap_or(&[]),
                len,
                blocking,
                &limits,
                &mut scratch,
            );
            match self.count(result)? {
                Some(r) => *slot = r,
                None => return Ok(None),
            }
        }
        Ok(Some(out))
    }
}

/// The board's jobs with scripts to their fixed point: each job's bound (by sorted position, [`NONE`]: unbounded)
/// into `wcrt`, read from its own view. When a script, an engine event or a suspending job has no bound, that job
/// and every job not above every suspending job and every engine, or in a suspending RTIC task, is unbounded (the
/// host's rule: only those keep a bound that nothing the rounds move reaches).
#[inline(never)]
pub(super) fn analyse<const N: usize, const M: usize>(
    input: &BoardInput<'_, M>,
    set: &BoardSet<N>,
    blocking: &[Time; N],
    shares: &[Share; N],
    iterations: &mut u64,
    wcrt: &mut [u64; N],
) -> Result<(), Refusal> {
    let scripts = Scripts::<N>::collect(input, set)?;
    let mut round = Round {
        input,
        set,
        scripts: &scripts,
        blocking,
        shares,
        spent: 0,
    };
    let len = set.jobs.len;
    // The rounds' state: each script's jitter (its job's response), each suspending task's job's own-view
    // response, each bus's event responses.
    let mut response = [Time::ZERO; N];
    let mut own = [Time::ZERO; N];
    let mut events = [Events::default(); MAX_BUSES];
    let mut failed: Option<u8> = None;
    let mut timings = [EMPTY_TIMING; N];
    let mut unreleased = [false; N];
    let mut converged = false;
    // Each round counts one iteration beside its fixed points' (a round of closed forms still costs), so the
    // rounds end within the budget.
    for _ in 0..SCRIPT_ITERATIONS {
        round.limits()?;
        round.spent += 1;
        // 1. Each script on its bus: its suspension, from its actual submission.
        let mut suspension = [Time::ZERO; N];
        for (k, slot) in suspension.iter_mut().enumerate().take(scripts.len) {
            match round.on_bus(k, &response, &events)? {
                Some(r) => *slot = r.minus(response.get(k).copied().unwrap_or(Time::ZERO)),
                None => {
                    failed = scripts.list.get(k).map(|s| s.job);
                    break;
                }
            }
        }
        if failed.is_some() {
            break;
        }
        // 2. The board once per view; 3. the engine events in the default view's jobs.
        let mut next = [NONE; N];
        let mut next_events = events;
        for v in 0..=scripts.views {
            round.view_jobs(v, &suspension, &own, &mut timings, &mut unreleased);
            if v == 0 {
                for (b, slot) in next_events
                    .iter_mut()
                    .enumerate()
                    .take(input.table.buses.len())
                {
                    let on_bus = scripts
                        .scripts()
                        .iter()
                        .find(|s| usize::from(s.row.bus) == b);
                    let Some(s) = on_bus else { continue };
                    match round.events(b, &timings)? {
                        Some(e) => *slot = e,
                        None => failed = Some(s.job),
                    }
                }
            }
            round.in_view(&mut timings, &unreleased, v, &mut next)?;
        }
        // 4. The suspending tasks' jobs' responses: the next jitters.
        let mut next_response = response;
        let mut next_own = own;
        for (p, (slot, &w)) in next_own.iter_mut().zip(next.iter()).enumerate().take(len) {
            if scripts.view(p) == 0 {
                continue;
            }
            match bound(w) {
                Some(r) => *slot = r,
                None => failed = failed.or(Some(p as u8)),
            }
        }
        for (slot, s) in next_response.iter_mut().zip(scripts.scripts()) {
            *slot = next_own
                .get(usize::from(s.job))
                .copied()
                .unwrap_or(Time::ZERO);
        }
        *wcrt = next;
        converged = next_response == response && next_events == events && next_own == own;
        if failed.is_some() || converged {
            break;
        }
        response = next_response;
        events = next_events;
        own = next_own;
    }
    *iterations += round.spent;
    if let Some(job) = failed {
        unbound_after(set, &scripts, job, wcrt);
    } else if !converged {
        return Err(Refusal::Budget);
    }
    Ok(())
}

/// After a failure of `job`: it, and every job not above every suspending job and every engine or in a suspending
/// RTIC task, has no bound.
fn unbound_after<const N: usize>(
    set: &BoardSet<N>,
    scripts: &Scripts<N>,
    job: u8,
    wcrt: &mut [u64; N],
) {
    let priority = |p: u8| set.timings.get(usize::from(p)).map_or(0, |t| t.priority);
    let top = scripts
        .scripts()
        .iter()
        .map(|s| priority(s.job).max(priority(s.engine)))
        .max()
        .unwrap_or(0);
    for (p, (slot, t)) in wcrt
        .iter_mut()
        .zip(set.timings.iter())
        .enumerate()
        .take(set.jobs.len)
    {
        if p == usize::from(job) || t.priority <= top || scripts.view(p) != 0 {
            *slot = NONE;
        }
    }
}
