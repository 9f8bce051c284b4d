//! One board's part of the check: its jobs (the table's fixed tasks; per stream it sends its publisher, timer and, by
//! parts, transmit job) in byte-indexed fixed-capacity arrays, their SRP blockings from the table, then
//! [`board_analysis::analyse`] and what the rest of the check reads of it (a [`Summary`]).

use super::*;

#[cfg(feature = "sensor-buses")]
mod suspension;

/// What the analysis keeps of one job besides its [`TaskTiming`].
#[derive(Debug, Clone, Copy)]
struct JobMeta {
    id: TaskId,
    deadline: Time,
    own_jitter: Time,
    /// The releaser ([`NO_JOB`]: none): its original index (table order: fixed tasks, then per stream its timer
    /// job and its job) as built, its sorted position once [`JobIndex::index`] has run.
    released_by: u8,
    /// This job's original index.
    original: u8,
    /// Where its priority level ends (a sorted position).
    level_end: u8,
    /// What reads its bound.
    check: Check,
}

/// What reads a job's bound besides the rounds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Check {
    /// Its bound is read (by the jobs it releases, the bus, the end-to-end paths) and checked against its deadline.
    Read,
    /// Nothing reads its bound but its deadline check: a fixed task that releases no job and is neither the
    /// transmit interrupt nor the command handler (whose bounds the bus and the end-to-end paths read).
    VerdictOnly,
    /// No deadline, only an unbounded one is a violation: an engine row (its analysed response places its
    /// interference and is no completion: its job's deadline covers the engine's work, docs/analysis.md), and the
    /// transmit interrupt's own row (a late job loses no completion; its response, which the bus reads, is every
    /// message's queuing jitter: docs/analysis.md, "The transmit interrupt keeps no deadline").
    Unchecked,
    /// As [`Check::Unchecked`], a job of the transmit interrupt that another job releases (the report's
    /// `can_tx[<topic>]` and `can_tx[<task>]`): the transmit interrupt is its second releaser
    /// ([`board_analysis::Release::also`]: the abort its frames cause is asked in one of the interrupt's jobs; the
    /// sound transmit path, as the report's `analysis::sort_tasks`).
    Transmit,
}

impl Check {
    /// Whether a job's bound is checked against its deadline (not only for being bounded).
    fn deadline_checked(self) -> bool {
        !matches!(self, Check::Unchecked | Check::Transmit)
    }
}

/// The working arrays' placeholder (every entry the analysis reads is written first): all zero bytes, so that a
/// `const` array of it is cleared in one go rather than copied from flash.
const EMPTY_META: JobMeta = JobMeta {
    id: TaskId::Fixed(0),
    deadline: Time::ZERO,
    own_jitter: Time::ZERO,
    released_by: 0,
    original: 0,
    level_end: 0,
    check: Check::Read,
};

const EMPTY_TIMING: TaskTiming = TaskTiming {
    priority: 0,
    wcet: Time::ZERO,
    period: Time::ZERO,
    jitter: Time::ZERO,
};

/// What a job of a board's analysis is made of (indices are bytes: the working sets are below [`NO_JOB`]).
#[derive(Debug, Clone, Copy)]
enum Source {
    /// A fixed task: its row in the board's `tasks`.
    Fixed(u8),
    /// The timer job of the stream at this [`View`] position.
    Timer { stream: u8 },
    /// The publisher job of the stream at this [`View`] position: its topic row, and its timer job's original
    /// index ([`NO_JOB`]: none).
    Publisher { stream: u8, topic: u8, timer: u8 },
    /// The engine row of script `script` of the job at original index `job` (its charge on the CPU); built only
    /// with the sensor-bus rounds.
    #[cfg_attr(not(feature = "sensor-buses"), allow(dead_code))]
    Engine { job: u8, script: u8 },
    /// The transmit interrupt's job per sample of the stream at this [`View`] position (the report's
    /// `can_tx[<topic>]`, built only where the topic row has a `transmit` cost): its topic row, and its publisher
    /// job's original index (its releaser).
    Transmit {
        stream: u8,
        topic: u8,
        publisher: u8,
    },
}

/// What one board's analysis reads: the board (index `b` of the robot's table), the configuration and the limits.
pub(super) struct BoardInput<'a, const M: usize> {
    bit_time: Time,
    b: usize,
    table: &'a BoardTable<'a>,
    streams: &'a View<'a, M>,
    limits: &'a Limits,
}

pub(super) fn board_input<'a, const M: usize>(
    robot: &RobotTable<'_>,
    b: usize,
    table: &'a BoardTable<'a>,
    streams: &'a View<'a, M>,
    limits: &'a Limits,
) -> BoardInput<'a, M> {
    BoardInput {
        bit_time: robot.bit_time,
        b,
        table,
        streams,
        limits,
    }
}

impl<'a, const M: usize> BoardInput<'a, M> {
    /// The streams this board sends, with their [`View`] positions.
    fn mine(&self) -> impl Iterator<Item = (usize, &'a Stream)> + '_ {
        let b = self.b;
        self.streams
            .iter()
            .filter(move |(_, s)| s.sender.is_some_and(|x| usize::from(x.board) == b))
    }

    /// The RTIC priority of the publisher task of `level`.
    fn level_priority(&self, level: u8) -> Option<u8> {
        self.table.levels.get(usize::from(level)).copied().flatten()
    }

    /// The scripts a job runs (empty for a timer job, an engine row and a job without scripts). Out of line: the
    /// bounds files key its loop by it whatever calls it.
    #[inline(never)]
    fn scripts_of(&self, what: Source) -> &'a [ScriptRow] {
        let table = self.table;
        match what {
            Source::Fixed(row) => table
                .task_scripts
                .iter()
                .find(|(task, _)| *task == row)
                .map_or(&[], |(_, list)| *list),
            Source::Publisher { topic, .. } => table
                .topics
                .get(usize::from(topic))
                .map_or(&[], |t| t.scripts),
            Source::Timer { .. } | Source::Engine { .. } | Source::Transmit { .. } => &[],
        }
    }

    /// The shortest frame this board can send (its transmit-complete interrupt's minimum inter-arrival time): of every
    /// topic of its table (the table's `shortest_dlc`), not only the running streams: a decided one-shot's or a
    /// stopped stream's queued frames still go out after they left the set.
    fn own_frame(&self) -> Time {
        // Worked out when the table was built (`admission_host`), so the check walks no rows for it.
        let dlc = self.table.shortest_dlc;
        can::own_frame_time(self.bit_time, core::iter::once(dlc))
    }
}

/// A board's jobs in original order (table order: the fixed tasks, then per stream its timer job and its job):
/// each one's priority and what it is made of.
struct Originals<const N: usize> {
    priority: [u8; N],
    source: [Source; N],
    count: usize,
}

impl<const N: usize> Originals<N> {
    /// The board's jobs in original order.
    #[inline(never)]
    fn of<const M: usize>(input: &BoardInput<'_, M>) -> Result<Self, Refusal> {
        let mut originals = Originals {
            priority: [0; N],
            source: [Source::Fixed(0); N],
            count: 0,
        };
        originals.collect(input)?;
        Ok(originals)
    }

    fn add(&mut self, priority: u8, what: Source) -> Result<u8, Refusal> {
        let original = u8::try_from(self.count)
            .ok()
            .filter(|&o| o != NO_JOB)
            .ok_or(Refusal::Capacity)?;
        *self.priority.get_mut(self.count).ok_or(Refusal::Capacity)? = priority;
        *self.source.get_mut(self.count).ok_or(Refusal::Capacity)? = what;
        self.count += 1;
        Ok(original)
    }

    fn urgency(&self, original: u8) -> u8 {
        self.priority
            .get(usize::from(original))
            .copied()
            .unwrap_or(0)
    }

    /// The fixed tasks, then per stream of the board its timer job, its publisher job (with its engine rows) and,
    /// where the transmit interrupt is charged by its parts, the transmit job the publisher job releases.
    fn collect<const M: usize>(&mut self, input: &BoardInput<'_, M>) -> Result<(), Refusal> {
        let table = input.table;
        for (i, t) in table.tasks.iter().enumerate() {
            let row = u8::try_from(i).map_err(|_| Refusal::Capacity)?;
            self.add(t.priority, Source::Fixed(row))?;
        }
        // The fixed tasks' engine rows after every fixed task: a fixed task's original index stays its row's,
        // which the table's `released_by`, `can_tx` and `command_handler` name.
        for &(row, _) in table.task_scripts {
            self.engines(input, Source::Fixed(row), row)?;
        }
        for (m, s) in input.mine() {
            let Some(sender) = s.sender else { continue };
            let priority = input
                .level_priority(sender.level)
                .ok_or(Refusal::Capacity)?;
            let topic = table
                .topics
                .iter()
                .position(|t| t.topic == sender.topic)
                .and_then(|t| u8::try_from(t).ok())
                .ok_or(Refusal::Capacity)?;
            let stream = u8::try_from(m).map_err(|_| Refusal::Capacity)?;
            let timer = match table.monotonic {
                Some(mono) => self.add(mono.priority, Source::Timer { stream })?,
                None => NO_JOB,
            };
            let what = Source::Publisher {
                stream,
                topic,
                timer,
            };
            let job = self.add(priority, what)?;
            self.engines(input, what, job)?;
            let charged = table
                .topics
                .get(usize::from(topic))
                .is_some_and(|t| t.transmit > 0);
            if let (true, Some(tx)) = (charged, table.can_tx) {
                let tx = table.tasks.get(usize::from(tx)).ok_or(Refusal::Capacity)?;
                let transmit = Source::Transmit {
                    stream,
                    topic,
                    publisher: job,
                };
                self.add(tx.priority, transmit)?;
            }
        }
        Ok(())
    }

    /// The engine rows of job `job`'s scripts (`Source::Engine { job, script }`, one per script in its order).
    fn engines<const M: usize>(
        &mut self,
        input: &BoardInput<'_, M>,
        what: Source,
        job: u8,
    ) -> Result<(), Refusal> {
        // A build without the sensor-bus rounds has no engine rows: a table with scripts is not its table (the
        // lowering refuses it for such a build).
        if cfg!(not(feature = "sensor-buses")) {
            return match input.scripts_of(what) {
                [] => Ok(()),
                _ => Err(Refusal::Capacity),
            };
        }
        for (k, script) in input.scripts_of(what).iter().enumerate() {
            let bus = input
                .table
                .buses
                .get(usize::from(script.bus))
                .ok_or(Refusal::Capacity)?;
            let script = u8::try_from(k).map_err(|_| Refusal::Capacity)?;
            self.add(bus.engine_priority, Source::Engine { job, script })?;
        }
        Ok(())
    }

    /// The originals sorted by priority (most urgent first, ties in original order: a stable sort of bytes).
    fn sorted(&self) -> [u8; N] {
        let mut order = [0u8; N];
        for (i, slot) in order.iter_mut().enumerate().take(self.count) {
            *slot = i as u8;
        }
        insertion_sort(order.get_mut(..self.count).unwrap_or(&mut []), |a, b| {
            self.urgency(a) < self.urgency(b)
        });
        order
    }
}

/// A fixed task's deadline at `period`: its row's, else its period.
#[inline(always)]
fn fixed_deadline(t: &TaskRow, period: Time) -> Time {
    if t.deadline == NO_DEADLINE {
        period
    } else {
        row_time(t.deadline)
    }
}

/// The period of a fixed task or a stream's job.
fn period_of<const M: usize>(
    input: &BoardInput<'_, M>,
    what: Source,
    own_frame: Time,
) -> Result<Time, Refusal> {
    match what {
        Source::Fixed(row) => {
            let t = input
                .table
                .tasks
                .get(usize::from(row))
                .ok_or(Refusal::Capacity)?;
            Ok(if t.own_frame {
                own_frame
            } else {
                row_time(t.period)
            })
        }
        Source::Timer { stream }
        | Source::Publisher { stream, .. }
        | Source::Transmit { stream, .. } => input
            .streams
            .get(usize::from(stream))
            .map(|s| s.period)
            .ok_or(Refusal::Capacity),
        Source::Engine { .. } => Err(Refusal::Capacity),
    }
}

/// Job `original`'s timing and meta, built from what it is made of (`sources`: every job's, by original index).
fn build_job<const M: usize>(
    input: &BoardInput<'_, M>,
    #[cfg_attr(not(feature = "sensor-buses"), allow(unused_variables))] sources: &[Source],
    what: Source,
    priority: u32,
    original: u8,
    own_frame: Time,
) -> Result<(TaskTiming, JobMeta), Refusal> {
    let table = input.table;
    let stream_of = |m: u8| input.streams.get(usize::from(m)).ok_or(Refusal::Capacity);
    let job = |wcet, period, jitter, id, deadline, released_by| {
        (
            TaskTiming {
                priority,
                wcet,
                period,
                jitter,
            },
            JobMeta {
                id,
                deadline,
                own_jitter: jitter,
                released_by,
                original,
                // Set by `JobIndex::index`.
                level_end: 0,
                check: Check::Read,
            },
        )
    };
    Ok(match what {
        Source::Fixed(row) => {
            let t = table.tasks.get(usize::from(row)).ok_or(Refusal::Capacity)?;
            let period = period_of(input, what, own_frame)?;
            let deadline = fixed_deadline(t, period);
            // NO_RELEASER is NO_JOB.
            let id = TaskId::Fixed(u16::from(row));
            let (timing, mut meta) = job(
                row_time(t.cost),
                period,
                row_time(t.jitter),
                id,
                deadline,
                t.released_by,
            );
            if t.bounded_only {
                // The transmit interrupt's row or one of its jobs': checked only for a bound (its deadline, the
                // period, is what a refusal of an unbounded one names); a released job of it takes the interrupt
                // as its second releaser.
                meta.check = if t.released_by != NO_RELEASER && table.can_tx != Some(u16::from(row))
                {
                    Check::Transmit
                } else {
                    Check::Unchecked
                };
            }
            (timing, meta)
        }
        Source::Timer { stream } => {
            let s = stream_of(stream)?;
            let (Some(mono), Some(sender)) = (table.monotonic, s.sender) else {
                return Err(Refusal::Capacity);
            };
            let id = TaskId::Timer(sender.topic);
            job(
                row_time(mono.cost),
                s.period,
                row_time(mono.jitter),
                id,
                s.period,
                NO_JOB,
            )
        }
        Source::Publisher {
            stream,
            topic,
            timer,
        } => {
            let s = stream_of(stream)?;
            let row = table
                .topics
                .get(usize::from(topic))
                .ok_or(Refusal::Capacity)?;
            let id = TaskId::Publisher(row.topic);
            job(
                row_time(row.cost),
                s.period,
                Time::ZERO,
                id,
                s.deadline(),
                timer,
            )
        }
        Source::Transmit {
            stream,
            topic,
            publisher,
        } => {
            // The report's `can_tx[<topic>]`: at the transmit interrupt's priority (its row's, `Originals::collect`),
            // with its sections (the transmit task's, already the table's: nothing to add to the blockings), at the
            // publisher job's period, released by it, with no deadline of its own. Named as the transmit task: left
            // unbounded, it is the transmit interrupt's (below the hard floor).
            let s = stream_of(stream)?;
            let row = table
                .topics
                .get(usize::from(topic))
                .ok_or(Refusal::Capacity)?;
            let tx = table.can_tx.ok_or(Refusal::Capacity)?;
            let (timing, mut meta) = job(
                row_time(row.transmit),
                s.period,
                can::transmit_abort_latency(input.bit_time),
                TaskId::Fixed(tx),
                s.period,
                publisher,
            );
            // A job of the transmit interrupt: checked only for a bound, as its row; released by its publisher job
            // and by the interrupt.
            meta.check = Check::Transmit;
            (timing, meta)
        }
        // A build without the sensor-bus rounds builds no engine row (`Originals::engines`).
        #[cfg(not(feature = "sensor-buses"))]
        Source::Engine { .. } => return Err(Refusal::Capacity),
        #[cfg(feature = "sensor-buses")]
        Source::Engine { job: by, script } => {
            // The engine's charge for the script, at the engine's priority, released by the job with its period;
            // named as its job (an unbounded engine row is its job's violation).
            let job_source = sources
                .get(usize::from(by))
                .copied()
                .ok_or(Refusal::Capacity)?;
            let row = input
                .scripts_of(job_source)
                .get(usize::from(script))
                .ok_or(Refusal::Capacity)?;
            let bus = table
                .buses
                .get(usize::from(row.bus))
                .ok_or(Refusal::Capacity)?;
            let charge = bus
                .engine(Time::ZERO)
                .charge(row.events.into(), row.starts.into());
            let id = match job_source {
                Source::Fixed(r) => TaskId::Fixed(u16::from(r)),
                Source::Publisher { topic, .. } => table
                    .topics
                    .get(usize::from(topic))
                    .map_or(TaskId::Fixed(0), |t| TaskId::Publisher(t.topic)),
                _ => return Err(Refusal::Capacity),
            };
            let period = period_of(input, job_source, own_frame)?;
            // Its job's deadline, which a refusal for an unbounded row names (the row itself has none).
            let deadline = match job_source {
                Source::Fixed(r) => {
                    let t = table.tasks.get(usize::from(r)).ok_or(Refusal::Capacity)?;
                    fixed_deadline(t, period)
                }
                Source::Publisher { stream, .. } => stream_of(stream)?.deadline(),
                _ => return Err(Refusal::Capacity),
            };
            let (timing, mut meta) = job(charge, period, Time::ZERO, id, deadline, by);
            meta.check = Check::Unchecked;
            (timing, meta)
        }
    })
}

/// The SRP blocking of a job of priority `p` on the board: the longest section of a lower-priority holder whose
/// ceiling reaches `p` (the fixed tasks' from the table, the running publisher jobs' from their topics).
#[inline(never)]
fn blocking_at<const M: usize>(input: &BoardInput<'_, M>, p: u32) -> Time {
    let table = input.table;
    let mut longest = usize::try_from(p)
        .ok()
        .and_then(|p| table.blocking.get(p))
        .copied()
        .unwrap_or_else(|| fixed_blocking(table.sections, p));
    for (_, s) in input.mine() {
        let Some(sender) = s.sender else { continue };
        let holder = input.level_priority(sender.level).map_or(0, u32::from);
        if holder >= p {
            continue;
        }
        if let Some(topic) = table.topics.iter().find(|t| t.topic == sender.topic) {
            for cs in topic.sections {
                // The effective ceiling is at least the holder's priority, which is below `p`.
                if row_ceiling(cs.ceiling) >= p {
                    longest = longest.max(cs.length);
                }
            }
        }
    }
    row_time(longest)
}

/// One board's jobs sorted by priority: their timings, and what else the analysis reads of each.
struct BoardSet<const N: usize> {
    timings: [TaskTiming; N],
    jobs: JobIndex<N>,
}

/// What the analysis reads of a board's sorted jobs besides their timings ([`board_analysis::Jobs`]).
struct JobIndex<const N: usize> {
    len: usize,
    metas: [JobMeta; N],
    /// Sorted position of each original index.
    position: [u8; N],
    /// The transmit interrupt's sorted position ([`NO_JOB`]: none), the second releaser of every
    /// [`Check::Transmit`] job.
    tx: u8,
}

impl<const N: usize> BoardSet<N> {
    /// Builds each job once, at its sorted place, in place (a set built and then returned or copied was a copy
    /// of 2.5 KB a board analysis); whether a job runs scripts (it has engine rows). Out of line: its working
    /// arrays are not in the frame of the analysis that follows.
    #[inline(never)]
    fn fill<const M: usize>(&mut self, input: &BoardInput<'_, M>) -> Result<bool, Refusal> {
        let originals = Originals::<N>::of(input)?;
        let order = originals.sorted();
        let own_frame = input.own_frame();
        self.jobs.len = originals.count;
        for ((&original, timing), meta) in order
            .iter()
            .zip(self.timings.iter_mut())
            .zip(self.jobs.metas.iter_mut())
            .take(originals.count)
        {
            let what = originals
                .source
                .get(usize::from(original))
                .copied()
                .ok_or(Refusal::Capacity)?;
            let priority = u32::from(originals.urgency(original));
            (*timing, *meta) = build_job(
                input,
                &originals.source,
                what,
                priority,
                original,
                own_frame,
            )?;
        }
        self.jobs.index(&self.timings, input.table);
        let scripted = originals
            .source
            .iter()
            .take(originals.count)
            .any(|s| matches!(s, Source::Engine { .. }));
        Ok(scripted)
    }

    /// SRP blocking per job: the longest section of a lower-priority holder whose ceiling reaches the job (the
    /// fixed tasks' from the table, the publisher jobs' from their topics). Jobs of one priority share it: worked
    /// out once per level (the jobs are sorted by priority).
    fn blockings<const M: usize>(&self, input: &BoardInput<'_, M>, blocking: &mut [Time; N]) {
        let mut last_level: Option<(u32, Time)> = None;
        for (slot, timing) in blocking
            .iter_mut()
            .zip(self.timings.iter())
            .take(self.jobs.len)
        {
            let p = timing.priority;
            if let Some((_, known)) = last_level.filter(|&(level, _)| level == p) {
                *slot = known;
                continue;
            }
            let longest = blocking_at(input, p);
            *slot = longest;
            last_level = Some((p, *slot));
        }
    }

    /// Each job's share of the CPU: a fixed task's from its row (worked out when the table was built), the others'
    /// by one division each (not one per job and level as it is summed).
    fn shares(&self, table: &BoardTable<'_>, shares: &mut [Share; N]) {
        for ((share, timing), meta) in shares
            .iter_mut()
            .zip(self.timings.iter())
            .zip(self.jobs.metas.iter())
            .take(self.jobs.len)
        {
            let known = match meta.id {
                // An engine row is named as its job, a transmit job as the transmit task: a fixed task's share is
                // its own row's (a fixed task's original index is its row; every other job comes after them).
                TaskId::Fixed(row) if u16::from(meta.original) == row => table
                    .tasks
                    .get(usize::from(row))
                    .filter(|t| !t.own_frame && t.share != SHARE_AT_RUNTIME)
                    .map(|t| Share::with_utilisation(u64::from(t.share))),
                _ => None,
            };
            *share = known.unwrap_or_else(|| Share::of(timing.wcet, timing.period));
        }
    }
}

impl<const N: usize> JobIndex<N> {
    /// Positions, releasers as positions, level ends and the jobs only a deadline check reads.
    fn index(&mut self, timings: &[TaskTiming; N], table: &BoardTable<'_>) {
        let len = self.len;
        for (p, meta) in self.metas.iter_mut().enumerate().take(len) {
            if let Some(slot) = self.position.get_mut(usize::from(meta.original)) {
                *slot = p as u8;
            }
            if let (TaskId::Fixed(row), true) = (meta.id, meta.check.deadline_checked()) {
                let row = Some(row);
                if table.can_tx != row && table.command_handler != row {
                    meta.check = Check::VerdictOnly;
                }
            }
        }
        self.tx = table
            .can_tx
            .and_then(|row| u8::try_from(row).ok())
            .map_or(NO_JOB, |row| self.at(row));
        let mut end = len;
        for p in (0..len).rev() {
            if let (Some(t), Some(next)) = (timings.get(p), timings.get(p + 1)) {
                if t.priority != next.priority {
                    end = p + 1;
                }
            }
            let Some(releaser) = self.metas.get(p).map(|m| self.at(m.released_by)) else {
                break;
            };
            if let Some(meta) = self.metas.get_mut(p) {
                meta.level_end = end as u8;
                // NO_JOB stays NO_JOB.
                meta.released_by = releaser;
            }
            if let Some(releasing) = self
                .metas
                .get_mut(usize::from(releaser))
                .filter(|m| m.check == Check::VerdictOnly)
            {
                releasing.check = Check::Read;
            }
        }
    }

    /// A job's second releaser: the transmit interrupt for a [`Check::Transmit`] job.
    fn second(&self, meta: &JobMeta) -> Option<usize> {
        (meta.check == Check::Transmit).then_some(usize::from(self.tx))
    }

    /// The sorted position of the job with this original index ([`NO_JOB`]: none).
    fn at(&self, original: u8) -> u8 {
        self.position
            .get(usize::from(original))
            .copied()
            .unwrap_or(NO_JOB)
    }
}

impl<const N: usize> board_analysis::Jobs for JobIndex<N> {
    fn release(&self, p: usize) -> Option<board_analysis::Release> {
        let meta = self.metas.get(p)?;
        (meta.released_by != NO_JOB).then_some(board_analysis::Release {
            by: usize::from(meta.released_by),
            also: self.second(meta),
            own_jitter: meta.own_jitter,
        })
    }
    fn level_end(&self, p: usize) -> usize {
        self.metas.get(p).map_or(0, |m| usize::from(m.level_end))
    }
    fn verdict_only(&self, p: usize) -> Option<Time> {
        let meta = self.metas.get(p)?;
        (meta.check == Check::VerdictOnly).then_some(meta.deadline)
    }
}

/// A board's bounds as the check keeps them: per sorted job its response ([`NONE`]: unbounded) and first window.
struct JobWcrt<const N: usize> {
    wcrt: [u64; N],
    first_window: [Time; N],
}

impl<const N: usize> board_analysis::JobBounds for JobWcrt<N> {
    const WHOLE_RECORDS: bool = false;
    fn put(&mut self, p: usize, result: Result<Response, AnalysisError>) {
        let (w, f) = result.map_or((NONE, Time::ZERO), |r| (r.wcrt.as_ns(), r.first_window));
        self.put_closed_form(p, Time::from_ns(w), f);
    }
    fn put_closed_form(&mut self, p: usize, wcrt: Time, first_window: Time) {
        if let (Some(ws), Some(fs)) = (self.wcrt.get_mut(p), self.first_window.get_mut(p)) {
            *ws = wcrt.as_ns();
            *fs = first_window;
        }
    }
    fn put_unbound(&mut self, p: usize, _: board_analysis::Unbound) {
        if let Some(slot) = self.wcrt.get_mut(p) {
            *slot = NONE;
        }
    }
    fn wcrt(&self, p: usize) -> Option<Time> {
        bound(self.wcrt.get(p).copied().unwrap_or(NONE))
    }
    fn first_window(&self, p: usize) -> Option<Time> {
        let bounded = self.wcrt.get(p).is_some_and(|&w| w != NONE);
        bounded.then(|| self.first_window.get(p).copied())?
    }
}

/// One board's tasks with the configuration's publishers ([`board_analysis::analyse`] under the board's budget of
/// iterations): writes its first violated deadline (in table order), its transmit interrupt's and command
/// handler's bounds and each of its streams' sending job's bound into `summary`.
#[inline(never)]
pub(super) fn analyse_board<const N: usize, const M: usize>(
    input: &BoardInput<'_, M>,
    iterations: &mut u64,
    summary: &mut Summary<M>,
) -> Result<(), Refusal> {
    // Built in place, field by field: cleared in one go each rather than copied from flash (a `const` set is
    // not all zero bytes).
    let mut set = BoardSet {
        timings: const { [EMPTY_TIMING; N] },
        jobs: JobIndex {
            len: 0,
            metas: const { [EMPTY_META; N] },
            position: [NO_JOB; N],
            tx: NO_JOB,
        },
    };
    let scripted = set.fill(input)?;
    let mut blocking = [Time::ZERO; N];
    set.blockings(input, &mut blocking);
    #[cfg_attr(not(feature = "sensor-buses"), allow(unused_mut))]
    let mut shares = [Share::default(); N];
    set.shares(input.table, &mut shares);
    let mut bounds = JobWcrt {
        wcrt: [NONE; N],
        first_window: [Time::ZERO; N],
    };
    #[cfg(not(feature = "sensor-buses"))]
    if scripted {
        // A build without the sensor-bus rounds (a board whose table states no bus): the lowering refuses such a
        // table for it, so this is a table it was not built for.
        return Err(Refusal::Capacity);
    }
    #[cfg(feature = "sensor-buses")]
    if scripted {
        // Jobs that suspend on a sensor bus: the rounds of views, buses and engine events to their fixed point.
        suspension::analyse(
            input,
            &mut set,
            &blocking,
            &mut shares,
            iterations,
            &mut bounds,
        )?;
        // Its windows are not all the board analysis's: kept only for the same horizon.
        summary.beyond = true;
        summary.note_board(input, &set.jobs, &bounds.wcrt);
        return Ok(());
    }
    {
        let outcome = run_view(
            &mut set.timings,
            &set.jobs,
            &blocking,
            &shares,
            input.limits,
            None,
            &mut bounds,
        )?;
        *iterations += outcome.iterations;
        summary.reach = summary.reach.max(outcome.reach);
        summary.beyond |= outcome.beyond;
    }
    summary.note_board(input, &set.jobs, &bounds.wcrt);
    Ok(())
}

/// What a view of the sensor buses' rounds (`suspension`) changes in the board's jobs: per job whether the view
/// sets its jitter itself (its release cut), and its view (0: the default; a job whose bound the rounds read is
/// never settled in closed form); `jitter`: the rounds' `Work::own`, for a cut default-view job the jitter the view
/// set (not a copy of the timings' jitters: the chip's stack).
#[derive(Clone, Copy)]
struct Cut<'a, const N: usize> {
    unreleased: &'a [bool; N],
    view: &'a [u8; N],
    jitter: &'a [Time; N],
}

/// The board's jobs as one analysis reads them: as built, or as a view of the rounds changes them.
struct ViewJobs<'a, const N: usize> {
    index: &'a JobIndex<N>,
    cut: Option<Cut<'a, N>>,
}

impl<const N: usize> board_analysis::Jobs for ViewJobs<'_, N> {
    fn release(&self, p: usize) -> Option<board_analysis::Release> {
        match self.cut {
            // A cut job keeps a second releaser (a transmit job's transmit interrupt), on the jitter the view set:
            // the view sets what its first releaser adds, never the transmit response.
            Some(c) if c.unreleased.get(p).copied().unwrap_or(true) => {
                let meta = self.index.metas.get(p)?;
                Some(board_analysis::Release {
                    by: self.index.second(meta)?,
                    also: None,
                    own_jitter: c.jitter.get(p).copied().unwrap_or(Time::ZERO),
                })
            }
            _ => self.index.release(p),
        }
    }
    fn level_end(&self, p: usize) -> usize {
        self.index.level_end(p)
    }
    fn verdict_only(&self, p: usize) -> Option<Time> {
        if self
            .cut
            .is_some_and(|c| c.view.get(p).copied().unwrap_or(1) != 0)
        {
            return None;
        }
        self.index.verdict_only(p)
    }
}

/// One [`board_analysis::analyse`] of the board's jobs (`timings`, their jitters left as inherited) under the
/// board's budget of iterations (`limits`), every job's bound into `bounds`: the board's analysis, and each view
/// of the sensor buses' rounds (`cut`) — one instance of the analysis linked for both.
#[inline(never)]
fn run_view<const N: usize>(
    timings: &mut [TaskTiming; N],
    jobs: &JobIndex<N>,
    blocking: &[Time; N],
    shares: &[Share; N],
    limits: &Limits,
    cut: Option<Cut<'_, N>>,
    bounds: &mut JobWcrt<N>,
) -> Result<board_analysis::Outcome, Refusal> {
    bounds.wcrt = [NONE; N];
    let mut scratch = const { [Counter::ZERO; N] };
    let len = jobs.len;
    let set = board_analysis::BoardJobs {
        timings: timings.get_mut(..len).unwrap_or(&mut []),
        blocking: blocking.get(..len).unwrap_or(&[]),
        shares: shares.get(..len).unwrap_or(&[]),
        scratch: &mut scratch,
    };
    board_analysis::analyse(
        set,
        &ViewJobs { index: jobs, cut },
        bounds,
        limits,
        board_analysis::IterationBudget::Board,
    )
    .map_err(|_| Refusal::Budget)
}

impl<const M: usize> Summary<M> {
    /// Writes the board's analysis into the summary: its first violation in table order and its first below the
    /// floor (no bound at all, or a fixed task — the board's own machinery — late), its transmit interrupt's and
    /// command handler's bounds and its streams' publisher jobs' bounds.
    fn note_board<const N: usize>(
        &mut self,
        input: &BoardInput<'_, M>,
        set: &JobIndex<N>,
        wcrt: &[u64; N],
    ) {
        let len = set.len;
        for original in 0..len {
            let p = usize::from(set.at(original as u8));
            let (Some(meta), Some(&w)) = (set.metas.get(p), wcrt.get(p)) else {
                continue;
            };
            let missed = w == NONE || (meta.check.deadline_checked() && w > meta.deadline.as_ns());
            if !self.violated && missed {
                self.violated = true;
                self.task = meta.id;
                self.violation_wcrt = w;
                self.violation_deadline = meta.deadline;
            }
            if !self.floor_violated
                && (w == NONE || (missed && matches!(meta.id, TaskId::Fixed(_))))
            {
                self.floor_violated = true;
                self.floor_task = meta.id;
                self.floor_wcrt = w;
                self.floor_deadline = meta.deadline;
            }
        }
        // No such task: nothing to add; an unbounded one: no bound.
        let fixed = |index: Option<u16>| -> u64 {
            index
                .and_then(|i| u8::try_from(i).ok())
                .map(|i| set.at(i))
                .and_then(|p| wcrt.get(usize::from(p)).copied())
                .unwrap_or(0)
        };
        self.tx = fixed(input.table.can_tx);
        self.handler = fixed(input.table.command_handler);
        for (own, (_, s)) in input.mine().enumerate() {
            let Some(sender) = s.sender else { continue };
            // The stream's job: the first of its topic in table order.
            let job = (0..len)
                .map(|original| usize::from(set.at(original as u8)))
                .find(|&p| {
                    set.metas
                        .get(p)
                        .is_some_and(|meta| meta.id == TaskId::Publisher(sender.topic))
                });
            if let (Some(p), Some(w), Some(found)) =
                (job, self.wcrt.get_mut(own), self.found.get_mut(own))
            {
                *w = wcrt.get(p).copied().unwrap_or(NONE);
                *found = true;
            }
        }
    }
}
