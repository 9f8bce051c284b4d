//! A board whose running jobs run scripts on its sensor buses: the chip's side of the sensor buses' rounds
//! ([`suspension_analysis::analyse`], the one implementation the report's `sensor_bus::analyse` runs too;
//! docs/analysis.md, "Self-suspending publishers and the sensor buses", "The chip's check with scripts"). It says
//! what the rounds read — the running scripts (most urgent job first), each job's view (one per RTIC task with a
//! running script), the buses' engines with the SRP blocking at their priorities — and runs each view's board
//! analysis in [`run_view`], the one instance both of the check's paths link; it keeps each job's bound from its
//! own view. The rounds' working arrays are the check's fixed-capacity ones; every fixed point and every round
//! counts against [`SCRIPT_ITERATIONS`] ([`Refusal::Budget`] beyond).

use super::*;
use crate::suspension_analysis::{self, Budget, Engine, Failure, ScriptJob, SuspendingBoard, Work};

/// A running job's script: its job's and its engine row's sorted positions and its row.
#[derive(Debug, Clone, Copy)]
struct Running<'a> {
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

/// The running scripts (most urgent job first, each job's in its order) and each job's view.
struct Scripts<'a, const N: usize> {
    list: [Running<'a>; N],
    len: usize,
    /// Per sorted job: 0 (the default view) or `v` for the `v`th RTIC task with a script.
    view: [u8; N],
    views: u8,
}

/// The RTIC task a job belongs to: a fixed task is its own, a publisher job its level's publisher task; timer jobs,
/// engine rows and transmit jobs run no script (`None`).
fn group_of<const M: usize>(input: &BoardInput<'_, M>, what: Source) -> Option<u16> {
    match what {
        Source::Fixed(row) => Some(u16::from(row)),
        Source::Publisher { stream, .. } => {
            let level = input.streams.get(usize::from(stream))?.sender?.level;
            let task = input.table.publisher_tasks.get(usize::from(level))?;
            Some(0x100 | u16::from(*task))
        }
        Source::Timer { .. } | Source::Engine { .. } | Source::Transmit { .. } => None,
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
                *out.list.get_mut(out.len).ok_or(Refusal::Capacity)? = Running {
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

    fn scripts(&self) -> &[Running<'a>] {
        self.list.get(..self.len).unwrap_or(&[])
    }

    fn view(&self, p: usize) -> u8 {
        self.view.get(p).copied().unwrap_or(0)
    }
}

/// The chip's side of the rounds ([`suspension_analysis::SuspendingBoard`]): the board's jobs, its running
/// scripts and views, each view's bounds (`bounds`) and each job's own-view bound (`kept`).
struct ChipBoard<'r, 'a, const N: usize, const M: usize> {
    input: &'r BoardInput<'a, M>,
    scripts: &'r Scripts<'a, N>,
    jobs: &'r JobIndex<N>,
    blocking: &'r [Time; N],
    engines: [Engine; MAX_BUSES],
    bounds: &'r mut JobWcrt<N>,
    kept: [u64; N],
}

impl<const N: usize, const M: usize> SuspendingBoard for ChipBoard<'_, '_, N, M> {
    fn scripts(&self) -> usize {
        self.scripts.len
    }
    fn script(&self, k: usize) -> Option<ScriptJob> {
        let s = self.scripts.scripts().get(k)?;
        Some(ScriptJob {
            job: usize::from(s.job),
            engine: usize::from(s.engine),
            bus: usize::from(s.row.bus),
            wire: row_time(s.row.bus_time),
            events: u32::from(s.row.events),
            starts: u32::from(s.row.starts),
            settle: row_time(s.row.settle),
        })
    }
    fn buses(&self) -> usize {
        self.input.table.buses.len().min(MAX_BUSES)
    }
    fn engine(&self, b: usize) -> Option<Engine> {
        self.engines.get(b).copied()
    }
    fn view(&self, p: usize) -> usize {
        usize::from(self.scripts.view(p))
    }
    fn views(&self) -> usize {
        usize::from(self.scripts.views)
    }
    fn own_jitter(&self, p: usize) -> Time {
        self.jobs.metas.get(p).map_or(Time::ZERO, |m| m.own_jitter)
    }
    fn released_by(&self, p: usize) -> Option<usize> {
        let meta = self.jobs.metas.get(p)?;
        (meta.released_by != NO_JOB).then_some(usize::from(meta.released_by))
    }
    fn analyse_view(
        &mut self,
        timings: &mut [TaskTiming],
        shares: &[Share],
        unreleased: &[bool],
        jitter: &[Time],
        limits: &Limits,
    ) -> Result<board_analysis::Outcome, board_analysis::OutOfIterations> {
        // The rounds hand back the check's own arrays (`Work`): of `N` entries each.
        let (Ok(timings), Ok(shares), Ok(unreleased), Ok(jitter)) = (
            <&mut [TaskTiming; N]>::try_from(timings),
            <&[Share; N]>::try_from(shares),
            <&[bool; N]>::try_from(unreleased),
            <&[Time; N]>::try_from(jitter),
        ) else {
            return Err(board_analysis::OutOfIterations);
        };
        let cut = Cut {
            unreleased,
            view: &self.scripts.view,
            jitter,
        };
        run_view(
            timings,
            self.jobs,
            self.blocking,
            shares,
            limits,
            Some(cut),
            self.bounds,
        )
        .map_err(|_| board_analysis::OutOfIterations)
    }
    fn current(&self, p: usize) -> Option<Time> {
        bound(self.bounds.wcrt.get(p).copied().unwrap_or(NONE))
    }
    fn refine(&mut self, p: usize, found: Response) {
        if let Some(slot) = self.bounds.wcrt.get_mut(p) {
            *slot = (*slot).min(found.wcrt.as_ns());
        }
    }
    fn keep(&mut self, v: usize, _: &[TaskTiming]) {
        for (p, (slot, &w)) in self
            .kept
            .iter_mut()
            .zip(self.bounds.wcrt.iter())
            .enumerate()
        {
            if usize::from(self.scripts.view(p)) == v {
                *slot = w;
            }
        }
    }
    fn kept(&self, p: usize) -> Option<Time> {
        bound(self.kept.get(p).copied().unwrap_or(NONE))
    }
    fn fail(&mut self, _: Failure) {
        // The rounds mark what a failure leaves unbounded; the decision is a refusal either way.
    }
    fn unbound(&mut self, p: usize, _: Option<usize>) {
        if let Some(slot) = self.kept.get_mut(p) {
            *slot = NONE;
        }
    }
}

/// The board's jobs with scripts to their fixed point ([`suspension_analysis::analyse`] under the board's
/// [`SCRIPT_ITERATIONS`]): each job's bound (by sorted position, [`NONE`]: unbounded) into `bounds`, read from
/// its own view.
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
        list: [Running {
            job: 0,
            engine: 0,
            row: &NO_ROW,
        }; N],
        len: 0,
        view: [0; N],
        views: 0,
    };
    Scripts::collect(input, set, &mut scripts)?;
    let jobs = set.jobs.len;
    // An engine event takes the place after the jobs at or above its engine for the while.
    if jobs >= N {
        return Err(Refusal::Capacity);
    }
    let mut engines = [Engine::default(); MAX_BUSES];
    for (slot, bus) in engines.iter_mut().zip(input.table.buses.iter()) {
        *slot = bus.engine(blocking_at(input, u32::from(bus.engine_priority)));
    }
    let mut board = ChipBoard {
        input,
        scripts: &scripts,
        jobs: &set.jobs,
        blocking,
        engines,
        bounds,
        kept: [NONE; N],
    };
    let mut base = [Time::ZERO; N];
    let mut own = [Time::ZERO; N];
    let mut unreleased = [false; N];
    let mut suspension = [Time::ZERO; N];
    let mut bus_times = [Time::ZERO; N];
    let mut subset = [MessageTiming {
        key: 0,
        frame_time: Time::ZERO,
        frames: 1,
        period: Time::ZERO,
        jitter: Time::ZERO,
    }; N];
    let mut scratch = const { [Counter::ZERO; N] };
    let mut work = Work {
        timings: &mut set.timings,
        jobs,
        blocking,
        shares,
        base: &mut base,
        own: &mut own,
        unreleased: &mut unreleased,
        suspension: &mut suspension,
        bus_times: &mut bus_times,
        subset: &mut subset,
        scratch: &mut scratch,
    };
    let limits = Limits {
        horizon: input.limits.horizon,
        iterations: SCRIPT_ITERATIONS,
    };
    let spent = suspension_analysis::analyse(&mut board, &mut work, &limits, Budget::Board)
        .map_err(|_| Refusal::Budget)?;
    *iterations += spent;
    let kept = board.kept;
    bounds.wcrt = kept;
    Ok(())
}
