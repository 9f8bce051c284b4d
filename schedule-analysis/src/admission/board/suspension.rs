//! A board whose running jobs run scripts on its sensor buses: the host's `sensor_bus::analyse` on the check's
//! fixed-capacity arrays (docs/analysis.md, "Self-suspending publishers and the sensor buses", "The chip's check
//! with scripts"). From zero jitters and event responses, rounds of: each script's response on its bus
//! (non-preemptive fixed priority, [`can::response_time`], without its siblings; its bus time the lower of its
//! events' own responses and the script as one job at the engine's priority), each bus's engine events and each
//! script as one job on the CPU in the default view ([`crate::board::response_time`]), and the board once per view ([`run_view`]: a view
//! per RTIC task with a suspending job, where its jobs cost their suspensions, settles and one blocking per
//! resumption, every job of every other such task its CPU with jitter `R − C`; and the default view); until no
//! response changes. Every fixed point and every round counts against [`SCRIPT_ITERATIONS`] ([`Refusal::Budget`]
//! beyond). The board's job arrays are changed in place per view and set back from `base` for the next.

use super::*;

/// A running job's script: its job's and its engine row's sorted positions and its row.
#[derive(Debug, Clone, Copy)]
struct ScriptJob<'a> {
    job: u8,
    engine: u8,
    row: &'a ScriptRow,
}

const NO_ROW: ScriptRow = ScriptRow {
    bus: 0,
    bus_time: 0,
    events: 0,
    starts: 0,
    settle: 0,
};

/// An engine event's worst responses on the CPU, by what it carries: plain, with the condition wait, the ending one.
type Events = [Time; 3];

/// The running scripts (most urgent job first, each job's in its order) and each job's view.
struct Scripts<'a, const N: usize> {
    list: [ScriptJob<'a>; N],
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

impl<'a, const N: usize> Scripts<'a, N> {
    fn collect<const M: usize>(
        input: &BoardInput<'a, M>,
        set: &BoardSet<N>,
        out: &mut Self,
    ) -> Result<(), Refusal> {
        let mut groups = [0u16; N];
        let len = set.jobs.len;
        // What each job is made of, by sorted position (its original index in the board's jobs rebuilt).
        let originals = Originals::<N>::of(input)?;
        let source = |p: usize| {
            let original = set.jobs.metas.get(p).map_or(NO_JOB, |m| m.original);
            originals
                .source
                .get(usize::from(original))
                .copied()
                .unwrap_or(Source::Timer { stream: 0 })
        };
        for p in 0..len {
            let what = source(p);
            let scripts = input.scripts_of(what);
            let Some(group) = group_of(input, what).filter(|_| !scripts.is_empty()) else {
                continue;
            };
            if !groups
                .iter()
                .take(usize::from(out.views))
                .any(|&g| g == group)
            {
                *groups
                    .get_mut(usize::from(out.views))
                    .ok_or(Refusal::Capacity)? = group;
                out.views += 1;
            }
            let original = set.jobs.metas.get(p).map_or(NO_JOB, |m| m.original);
            for (k, row) in scripts.iter().enumerate() {
                // The `k`th script's engine row ([`Originals::engines`]).
                let engine = originals
                    .source
                    .iter()
                    .take(originals.count)
                    .position(|s| matches!(*s, Source::Engine { job, script } if job == original && usize::from(script) == k))
                    .map_or(NO_JOB, |e| set.jobs.at(e as u8));
                *out.list.get_mut(out.len).ok_or(Refusal::Capacity)? = ScriptJob {
                    job: p as u8,
                    engine,
                    row,
                };
                out.len += 1;
            }
        }
        for (p, slot) in out.view.iter_mut().enumerate().take(len) {
            let view = group_of(input, source(p)).and_then(|g| {
                groups
                    .iter()
                    .take(usize::from(out.views))
                    .position(|&o| o == g)
            });
            *slot = view.map_or(0, |v| v as u8 + 1);
        }
        Ok(())
    }

    fn scripts(&self) -> &[ScriptJob<'a>] {
        self.list.get(..self.len).unwrap_or(&[])
    }

    fn view(&self, p: usize) -> u8 {
        self.view.get(p).copied().unwrap_or(0)
    }
}

/// What every step of the rounds reads, and the iterations spent.
struct Round<'r, 'a, const N: usize, const M: usize> {
    input: &'r BoardInput<'a, M>,
    scripts: &'r Scripts<'a, N>,
    /// Each job's cost as built.
    base: &'r [Time; N],
    /// Iterations spent on the board so far.
    spent: u64,
    /// Whether this round's engine events moved a script's bus time (the rounds' state, kept in place).
    moved: bool,
}

impl<const N: usize, const M: usize> Round<'_, '_, N, M> {
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

    /// What a script's events hold SCL on the CPU: its ending event, one with the condition wait per further
    /// START (as many as its other events allow), the rest plain. Out of line: taken for the costs and the responses.
    #[inline(never)]
    fn events_of(row: &ScriptRow, events: &Events) -> Time {
        let Some(others) = row.events.checked_sub(1) else {
            return Time::ZERO;
        };
        let waiting = row.starts.min(others);
        let [plain, wait, end] = *events;
        end.plus(wait.times(u64::from(waiting)))
            .plus(plain.times(u64::from(others - waiting)))
    }

    /// Script `k`'s response on its bus from its nominal submission (`None`: unbounded), among the bus's scripts
    /// that are not its siblings (the other scripts of its RTIC task), each with its job's response as jitter.
    #[inline(never)]
    fn on_bus(
        &mut self,
        k: usize,
        timings: &[TaskTiming; N],
        own: &[Time; N],
        bus_times: &[Time; N],
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
            let p = usize::from(s.job);
            let job = timings.get(p).copied().unwrap_or(EMPTY_TIMING);
            if o == k {
                at = len;
            }
            // Its bus time as the last round's events found it; before any, its wire and stretch alone.
            let bus_time = match bus_times.get(o) {
                Some(&t) if t > Time::ZERO => t,
                _ => row_time(s.row.bus_time),
            };
            *subset.get_mut(len).ok_or(Refusal::Capacity)? = MessageTiming {
                // Lower key first: the most urgent submitter; equal priorities share a key and interfere.
                key: u32::MAX - job.priority,
                frame_time: bus_time,
                frames: 1,
                period: job.period,
                jitter: own.get(p).copied().unwrap_or(Time::ZERO),
            };
            len += 1;
        }
        let subset = subset.get(..len).unwrap_or(&[]);
        let mut scratch = const { [Counter::ZERO; N] };
        let limits = self.limits()?;
        // A script submitted at the very instant the engine picks the next one counts as in time (1 ns).
        let result = can::response_time(
            subset,
            at,
            can::blocking(subset, at),
            Time::from_ns(1),
            &limits,
            &mut scratch,
        );
        self.count(result)
    }

    /// View `v`'s jobs in place (`timings`, `shares`, `unreleased`: the jobs whose jitter the view sets), from the
    /// scripts' suspensions and the suspending tasks' own-view responses; every other job as built.
    #[allow(clippy::too_many_arguments)]
    fn view_jobs(
        &self,
        v: u8,
        set: &mut BoardSet<N>,
        blocking: &[Time; N],
        shares: &mut [Share; N],
        suspension: &[Time; N],
        own: &[Time; N],
        unreleased: &mut [bool; N],
    ) {
        let scripts = self.scripts;
        for (p, (((t, share), cut), meta)) in set
            .timings
            .iter_mut()
            .zip(shares.iter_mut())
            .zip(unreleased.iter_mut())
            .zip(set.jobs.metas.iter())
            .enumerate()
            .take(set.jobs.len)
        {
            let base = self.base.get(p).copied().unwrap_or(Time::ZERO);
            let mut cost = base;
            for (s, &suspended) in scripts.scripts().iter().zip(suspension.iter()) {
                if usize::from(s.job) == p && scripts.view(p) == v {
                    // Suspension-oblivious: the suspension, the settle and a blocking per resumption as execution.
                    let resumptions = if s.row.settle > 0 { 2 } else { 1 };
                    let b = blocking.get(p).copied().unwrap_or(Time::ZERO);
                    cost = cost
                        .plus(suspended)
                        .plus(row_time(s.row.settle))
                        .plus(b.times(resumptions));
                }
            }
            if cost != t.wcet {
                t.wcet = cost;
                *share = Share::of(cost, t.period);
            }
            t.jitter = meta.own_jitter;
            *cut = false;
            // Another suspending task's job: its CPU anywhere in its own-view response.
            let view = scripts.view(p);
            if view != 0 && view != v {
                t.jitter = own.get(p).copied().unwrap_or(Time::ZERO).minus(base);
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

    /// Bus `b`'s engine events on the CPU in the default view's jobs (`timings`, after their analysis, so that a
    /// released job carries the jitter it inherits from its releaser's response, as the host's found jitters do):
    /// each at the engine's priority, interfered with by every job at or above it but the bus's own engine rows
    /// (these very events, one at a time; costed 0 meanwhile), blocked as a job of that priority; the event itself
    /// takes the place after the jobs at or above it for the while. Then each script on the bus as one job the
    /// same way, and its bus time (by script, into `bus_times`) the lower of the two bounds, both sound: its wire
    /// and stretch plus each event's own response, and the script as one job. `false`: an event is unbounded.
    #[inline(never)]
    fn events(
        &mut self,
        b: usize,
        timings: &mut [TaskTiming; N],
        len: usize,
        bus_times: &mut [Time; N],
    ) -> Result<bool, Refusal> {
        let Some(bus) = self.input.table.buses.get(b) else {
            return Ok(true);
        };
        let engine = u32::from(bus.engine_priority);
        for s in self.scripts.scripts() {
            if usize::from(s.row.bus) == b {
                if let Some(t) = timings.get_mut(usize::from(s.engine)) {
                    t.wcet = Time::ZERO;
                }
            }
        }
        let end = timings
            .iter()
            .take(len)
            .position(|t| t.priority < engine)
            .unwrap_or(len);
        let kept = timings.get(end).copied().ok_or(Refusal::Capacity)?;
        let blocking = blocking_at(self.input, engine);
        let wait = row_time(bus.condition_wait);
        let plain = row_time(bus.per_event);
        let costs = [
            plain,
            plain.plus(wait),
            plain.plus(row_time(bus.per_script)).plus(wait),
        ];
        let (mut out, mut bounded) = (Events::default(), true);
        // The three events, then each script on the bus as one job at the engine's priority (the host's
        // `script_response`): its events' work and its wire time as execution, blocked once per event; one call
        // site for both. A script's window without a bound leaves its events' bound.
        let list = self.scripts.scripts();
        for k in 0..costs.len() + list.len() {
            let script = k.checked_sub(costs.len());
            let (cost, resumptions) = match script.map(|i| list.get(i)) {
                None => (costs.get(k).copied().unwrap_or(Time::ZERO), 1),
                Some(Some(s)) if usize::from(s.row.bus) == b => (
                    row_time(s.row.bus_time).plus(Self::events_of(s.row, &costs)),
                    u64::from(s.row.events),
                ),
                Some(_) => continue,
            };
            if let Some(slot) = timings.get_mut(end) {
                *slot = TaskTiming {
                    priority: engine,
                    wcet: cost,
                    period: self.input.limits.horizon,
                    jitter: Time::ZERO,
                };
            }
            let mut scratch = const { [Counter::ZERO; N] };
            let limits = self.limits()?;
            let result = crate::board::response_time(
                timings.get(..=end).unwrap_or(&[]),
                end,
                blocking.times(resumptions),
                &limits,
                &mut scratch,
            );
            let r = self.count(result)?;
            match (script, r) {
                (Some(i), _) => {
                    // The events come first: `out` is complete.
                    let row = list.get(i).map_or(&NO_ROW, |s| s.row);
                    let per_event = row_time(row.bus_time).plus(Self::events_of(row, &out));
                    let bus_time = r.map_or(per_event, |w| w.min(per_event));
                    if let Some(slot) = bus_times.get_mut(i).filter(|slot| **slot != bus_time) {
                        *slot = bus_time;
                        self.moved = true;
                    }
                }
                (None, Some(r)) => {
                    if let Some(slot) = out.get_mut(k) {
                        *slot = r;
                    }
                }
                (None, None) => bounded = false,
            }
        }
        // The jobs as they were.
        if let Some(slot) = timings.get_mut(end) {
            *slot = kept;
        }
        for s in self.scripts.scripts() {
            if let Some(t) = timings.get_mut(usize::from(s.engine)) {
                t.wcet = self
                    .base
                    .get(usize::from(s.engine))
                    .copied()
                    .unwrap_or(Time::ZERO);
            }
        }
        Ok(bounded)
    }
}

/// The board's jobs with scripts to their fixed point: each job's bound (by sorted position, [`NONE`]: unbounded)
/// into `bounds`, read from its own view. When a script, an engine event or a suspending task's job has no
/// bound, that job and every job not above every suspending job and every engine, or in a suspending RTIC task,
/// is unbounded (the host's rule: only a job that nothing the rounds move reaches keeps its bound).
#[inline(never)]
pub(super) fn analyse<const N: usize, const M: usize>(
    input: &BoardInput<'_, M>,
    set: &mut BoardSet<N>,
    blocking: &[Time; N],
    shares: &mut [Share; N],
    iterations: &mut u64,
    bounds: &mut JobWcrt<N>,
) -> Result<(), Refusal> {
    let mut scripts = Scripts {
        list: [ScriptJob {
            job: 0,
            engine: 0,
            row: &NO_ROW,
        }; N],
        len: 0,
        view: [0; N],
        views: 0,
    };
    Scripts::collect(input, set, &mut scripts)?;
    let len = set.jobs.len;
    let mut base = [Time::ZERO; N];
    for (slot, t) in base.iter_mut().zip(set.timings.iter()) {
        *slot = t.wcet;
    }
    let mut round = Round {
        input,
        scripts: &scripts,
        base: &base,
        spent: 0,
        moved: false,
    };
    // The rounds' state: each suspending task's job's own-view response (its scripts' jitter), each bus's event
    // responses; and per job its bound from its own view.
    let mut own = [Time::ZERO; N];
    // Each script's bus time (by script; 0 before the first round's events: its wire and stretch alone).
    let mut bus_times = [Time::ZERO; N];
    let mut wcrt = [NONE; N];
    let mut suspension = [Time::ZERO; N];
    let mut unreleased = [false; N];
    let mut failed: Option<u8> = None;
    let mut converged = false;
    // Each round counts one iteration beside its fixed points' (a round of closed forms still costs), so the
    // rounds end within the budget.
    for _ in 0..SCRIPT_ITERATIONS {
        round.limits()?;
        round.spent += 1;
        // 1. Each script on its bus: its suspension, from its actual submission.
        for (k, (slot, s)) in suspension.iter_mut().zip(scripts.scripts()).enumerate() {
            let jitter = own.get(usize::from(s.job)).copied().unwrap_or(Time::ZERO);
            match round.on_bus(k, &set.timings, &own, &bus_times)? {
                Some(r) => *slot = r.minus(jitter),
                None => failed = failed.or(Some(s.job)),
            }
        }
        if failed.is_some() {
            break;
        }
        // 2. The board once per view; after the default view's analysis, 3., the engine events.
        round.moved = false;
        for v in 0..=scripts.views {
            round.view_jobs(v, set, blocking, shares, &suspension, &own, &mut unreleased);
            let cut = Cut {
                unreleased: &unreleased,
                view: &scripts.view,
            };
            let limits = round.limits()?;
            let outcome = run_view(
                &mut set.timings,
                &set.jobs,
                blocking,
                shares,
                &limits,
                Some(cut),
                bounds,
            )?;
            round.spent += outcome.iterations;
            for (p, (slot, &w)) in wcrt.iter_mut().zip(bounds.wcrt.iter()).enumerate() {
                if scripts.view(p) == v {
                    *slot = w;
                }
            }
            if v == 0 {
                // The default view's jobs as analysed: a released job's jitter is now the one it inherits from
                // its releaser's response (its own plus that response), not its own alone.
                for b in 0..input.table.buses.len() {
                    let on_bus = scripts
                        .scripts()
                        .iter()
                        .find(|s| usize::from(s.row.bus) == b);
                    let Some(s) = on_bus else { continue };
                    if !round.events(b, &mut set.timings, len, &mut bus_times)? {
                        failed = failed.or(Some(s.job));
                    }
                }
            }
        }
        // 4. The suspending tasks' jobs' responses: the next jitters.
        converged = !round.moved;
        for (p, (slot, &w)) in own.iter_mut().zip(wcrt.iter()).enumerate().take(len) {
            if scripts.view(p) == 0 {
                continue;
            }
            match bound(w) {
                Some(r) => {
                    converged &= *slot == r;
                    *slot = r;
                }
                None => failed = failed.or(Some(p as u8)),
            }
        }
        if failed.is_some() || converged {
            break;
        }
    }
    *iterations += round.spent;
    if let Some(job) = failed {
        unbound_after(set, &scripts, job, &mut wcrt);
    } else if !converged {
        return Err(Refusal::Budget);
    }
    bounds.wcrt = wcrt;
    Ok(())
}

/// After a failure of `job`: it, and every job not above every suspending job and every engine or in a suspending
/// RTIC task, has no bound.
fn unbound_after<const N: usize>(
    set: &BoardSet<N>,
    scripts: &Scripts<'_, N>,
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
