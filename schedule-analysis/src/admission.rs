//! Admission control on the chip: before a board starts (or re-prioritises) a publisher it checks, with the same
//! core analysis `cargo xtask analyze` runs, that every task of every board still meets its deadline and every
//! frame its bus deadline. `no_std`, allocation-free, bounded: all working sets are fixed-capacity arrays on the
//! stack (`N` tasks per board, `M` streams on the bus) and the cost is counted in fixed-point iterations.
//!
//! Inputs:
//! * a [`RobotTable`]: every board's task model lowered to `const` rows (fixed tasks with their overheads and
//!   release chains, SRP critical sections with resolved ceilings, per-topic publisher budgets, the publisher task
//!   priority per CAN priority level, the monotonic's timer job), the bit time and the frame-cost model. The host
//!   builds it from the same app sources and timing files as the report (`admission_host::lower`) and can emit it
//!   as Rust source for a board's `build.rs`;
//! * the whole robot's running streams on the bus ([`Stream`]: sender board, topic, CAN priority level,
//!   period, frames per sample, DLC), the same every board keeps from the commands it hears;
//! * the request: one stream to add, or to replace the stream of the same sender and topic.
//!
//! The analysis is the report's, step by step: per board, publisher jobs and their timer jobs are added to the
//! fixed tasks, SRP blockings computed, release jitters iterated to a fixed point (at most 100 rounds) with
//! [`board::response_times`]; then every message's queuing jitter from its sender's response variation and the
//! board's transmit interrupt, and [`can::response_times`]. The verdict is "no task and no frame misses its
//! deadline", which is `cargo xtask analyze --check`'s verdict for the same configuration without jitter budgets
//! (a property test checks that they agree).

use crate::board::{self, CriticalSection, TaskTiming};
use crate::busy_window::{AnalysisError, Counter, Limits, Response};
use crate::can::{self, FrameCost, MessageTiming};
use crate::time::Time;

/// CAN priority levels of the protocol: urgent, high, medium, low (index 0 is the most urgent).
pub const LEVELS: usize = 4;
/// Rounds of the per-board release-jitter iteration (as the host analysis).
const MAX_JITTER_ROUNDS: usize = 100;
/// The longest period the period search tries (the protocol's 32-bit microsecond span, ≈ 71.6 min).
pub const MAX_PERIOD: Time = Time::from_ns(4_294_967_295_000);

/// One fixed task of a board (not a publisher job), overheads included.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TaskRow {
    /// RTIC priority.
    pub priority: u32,
    /// Worst-case execution time with entry/exit/dispatcher overheads.
    pub cost: Time,
    /// Best-case execution time (its best-case response).
    pub bcet: Time,
    /// Period or minimum inter-arrival time (ignored when `own_frame`).
    pub period: Time,
    /// Deadline from the release event; `None`: the period.
    pub deadline: Option<Time>,
    /// Release jitter of its own.
    pub jitter: Time,
    /// Index (in the board's `tasks`) of the task whose completion releases this one.
    pub released_by: Option<u16>,
    /// Activated once per frame this board sends: its period is the best-case time of the shortest frame the board's
    /// publishers send (the shortest frame on the bus when it sends nothing).
    pub own_frame: bool,
}

/// A critical section of a fixed task (or of `idle`, holder priority 0), its ceiling resolved: the core's
/// [`CriticalSection`].
pub type SectionRow = CriticalSection;

/// A critical section of a publisher job: its holder is the publisher task of the requested level.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TopicSection {
    /// The resource's static ceiling (`u32::MAX`: interrupts disabled); the effective ceiling is at least the
    /// holder's priority.
    pub ceiling: u32,
    /// Longest time held.
    pub length: Time,
}

/// A topic this board can publish: one job of the level's publisher task per sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TopicRow<'a> {
    /// Protocol topic byte.
    pub topic: u8,
    /// Worst-case execution time of one sample, software-task overheads included.
    pub cost: Time,
    /// Best-case execution time (the earliest its frames can be queued).
    pub bcet: Time,
    /// Its critical sections.
    pub sections: &'a [TopicSection],
}

/// The monotonic's timer interrupt, one job per timer-released publisher job.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MonotonicRow {
    /// Its priority.
    pub priority: u32,
    /// Cost of one timer interrupt, entry and exit included.
    pub cost: Time,
    /// Release jitter (one tick).
    pub jitter: Time,
}

/// One board's compact task model.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BoardTable<'a> {
    /// Board name (the firmware folder).
    pub name: &'a str,
    /// The fixed tasks (with the timer jobs of timer-released fixed tasks).
    pub tasks: &'a [TaskRow],
    /// Critical sections of the fixed tasks and of `idle`.
    pub sections: &'a [SectionRow],
    /// The topics it can publish, with their budgets.
    pub topics: &'a [TopicRow<'a>],
    /// RTIC priority of the publisher task per CAN priority level (urgent, high, medium, low); `None`: none.
    pub levels: [Option<u32>; LEVELS],
    /// The monotonic's timer job, when publishers are timer-released.
    pub monotonic: Option<MonotonicRow>,
    /// Index of the transmit interrupt task (its WCRT is queuing jitter for every frame the board sends).
    pub can_tx: Option<u16>,
    /// Index of the command handler (the end of a command's path).
    pub command_handler: Option<u16>,
}

/// Every board of the robot and the bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RobotTable<'a> {
    /// The boards; a [`Sender::board`] indexes this.
    pub boards: &'a [BoardTable<'a>],
    /// One bit time.
    pub bit_time: Time,
    /// Frame-cost model (the report's verdict model).
    pub frame_cost: FrameCost,
}

/// Who queues a stream: a board's publisher of one topic at one level.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Sender {
    /// Index into [`RobotTable::boards`].
    pub board: u8,
    /// Protocol topic byte (a row of that board's `topics`).
    pub topic: u8,
    /// CAN priority level, 0 = urgent … 3 = low.
    pub level: u8,
}

/// One message stream on the bus: a running publisher, or a command stream (no sender).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Stream {
    /// Identifier.
    pub id: u32,
    /// 29-bit identifier.
    pub extended: bool,
    /// Data bytes per frame.
    pub dlc: u8,
    /// Frames per activation (sample).
    pub frames: u32,
    /// Period (minimum inter-arrival time of a command stream).
    pub period: Time,
    /// Deadline from the sender's activation (commands: from queuing); `None`: the period.
    pub deadline: Option<Time>,
    /// Queuing jitter of its own (commands: the sender's; publishers: 0).
    pub jitter: Time,
    /// The publishing board and topic; `None` for a command stream.
    pub sender: Option<Sender>,
    /// Board whose command handler acts on it (commands): its WCRT is part of the end-to-end deadline.
    pub receiver: Option<u8>,
}

impl Stream {
    fn deadline(&self) -> Time {
        self.deadline.unwrap_or(self.period)
    }

    /// Same publisher (board and topic), or the same identifier for a command stream.
    fn same_source(&self, other: &Stream) -> bool {
        match (self.sender, other.sender) {
            (Some(a), Some(b)) => a.board == b.board && a.topic == b.topic,
            (None, None) => self.id == other.id && self.extended == other.extended,
            _ => false,
        }
    }
}

/// A task as the admission check names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TaskId {
    /// A fixed task: index into the board's `tasks`.
    Fixed(u16),
    /// The publisher job of this topic.
    Publisher(u8),
    /// The timer job that releases the publisher job of this topic.
    Timer(u8),
}

/// What misses its deadline.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Culprit {
    /// A task on a board.
    Task {
        /// Board index.
        board: u8,
        /// Which task.
        task: TaskId,
    },
    /// A stream's frames on the bus (from the sender's activation).
    Frame {
        /// Its identifier.
        id: u32,
    },
    /// A command's end-to-end path (bus, then the receiver's handler).
    EndToEnd {
        /// Its identifier.
        id: u32,
    },
}

/// The first deadline that is missed, with the numbers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Violation {
    /// What misses.
    pub culprit: Culprit,
    /// Its worst-case response; `None`: unbounded.
    pub wcrt: Option<Time>,
    /// Its deadline.
    pub deadline: Time,
}

/// Why a request is refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refusal {
    /// A deadline would be missed.
    Deadline(Violation),
    /// The table or the working arrays cannot hold the configuration (capacity `N`/`M`), or the request names a
    /// board, topic or level the table does not have.
    Capacity,
    /// The request's period is zero.
    ZeroPeriod,
}

/// What one analysis of a configuration found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Evaluation {
    /// `None`: everything meets its deadline.
    pub refusal: Option<Refusal>,
    /// Fixed-point iterations it took (the measure of its cost).
    pub iterations: u64,
}

/// What would be accepted instead.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Suggestion {
    /// The shortest period (a value the protocol can express) accepted at the requested level.
    pub shortest_period: Option<Time>,
    /// The least urgent level (0 = urgent … 3 = low) accepted at the requested period.
    pub level: Option<u8>,
}

/// The answer to a request.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Decision {
    /// `None`: admitted.
    pub refusal: Option<Refusal>,
    /// On refusal, what would be accepted (searched only when asked for).
    pub suggestion: Suggestion,
    /// Fixed-point iterations of the whole decision, searches included.
    pub iterations: u64,
    /// Whole-robot analyses run (1 without a search).
    pub evaluations: u32,
}

impl Decision {
    /// Whether the request is admitted.
    pub fn admitted(&self) -> bool {
        self.refusal.is_none()
    }
}

/// Analyses the configuration `streams` (every stream on the bus) with working arrays for `N` tasks per board and
/// `M` streams. Allocation-free; the cost is bounded by the capacities and counted.
pub fn evaluate<const N: usize, const M: usize>(
    robot: &RobotTable<'_>,
    streams: &[Stream],
) -> Evaluation {
    let mut iterations = 0u64;
    let refusal = evaluate_into::<N, M>(robot, streams, &mut iterations);
    Evaluation {
        refusal,
        iterations,
    }
}

/// Decides `request` against the running `streams`: the request replaces a running stream of the same publisher
/// (board and topic) or is added. With `suggest`, a refusal also searches the shortest period accepted at the
/// requested level (binary search over protocol-expressible periods) and the least urgent level accepted at the
/// requested period.
pub fn admit<const N: usize, const M: usize>(
    robot: &RobotTable<'_>,
    streams: &[Stream],
    request: &Stream,
    suggest: bool,
) -> Decision {
    let mut iterations = 0u64;
    let mut evaluations = 1u32;
    let refusal = check_with::<N, M>(robot, streams, request, &mut iterations);
    let mut suggestion = Suggestion::default();
    if refusal.is_some() && suggest && request.sender.is_some() && !request.period.is_zero() {
        suggestion.shortest_period =
            shortest_period::<N, M>(robot, streams, request, &mut iterations, &mut evaluations);
        suggestion.level =
            level_needed::<N, M>(robot, streams, request, &mut iterations, &mut evaluations);
    }
    Decision {
        refusal,
        suggestion,
        iterations,
        evaluations,
    }
}

/// The CAN identifier of a sensor stream: `0x400 | level << 8 | topic` (amiro-can's layout for sensor data).
pub const fn sensor_id(level: u8, topic: u8) -> u32 {
    0x400 | ((level as u32 & 0x3) << 8) | topic as u32
}

/// Rounds a period up to one the protocol can express: whole µs up to 65 535 µs, whole ms up to 65 535 ms,
/// whole seconds beyond.
pub fn expressible_period(period: Time) -> Time {
    let ns = period.as_ns();
    let unit = if ns <= 65_535_000 {
        1_000
    } else if ns <= 65_535_000_000 {
        1_000_000
    } else {
        1_000_000_000
    };
    Time::from_ns(ns.div_ceil(unit).saturating_mul(unit))
}

fn check_with<const N: usize, const M: usize>(
    robot: &RobotTable<'_>,
    streams: &[Stream],
    request: &Stream,
    iterations: &mut u64,
) -> Option<Refusal> {
    if request.period.is_zero() {
        return Some(Refusal::ZeroPeriod);
    }
    let mut set = [EMPTY_STREAM; M];
    let mut len = 0;
    for s in streams
        .iter()
        .filter(|s| !s.same_source(request))
        .chain(core::iter::once(request))
    {
        let Some(slot) = set.get_mut(len) else {
            return Some(Refusal::Capacity);
        };
        *slot = *s;
        len += 1;
    }
    evaluate_into::<N, M>(robot, set.get(..len).unwrap_or(&[]), iterations)
}

fn shortest_period<const N: usize, const M: usize>(
    robot: &RobotTable<'_>,
    streams: &[Stream],
    request: &Stream,
    iterations: &mut u64,
    evaluations: &mut u32,
) -> Option<Time> {
    let mut at = |period: Time, iterations: &mut u64| {
        *evaluations += 1;
        let mut candidate = *request;
        candidate.period = period;
        check_with::<N, M>(robot, streams, &candidate, iterations).is_none()
    };
    // Double until one passes (lo fails, hi passes), then bisect to 1 µs and round to an expressible value.
    let mut lo = request.period;
    let mut hi = lo;
    loop {
        hi = expressible_period(hi.times(2).min(MAX_PERIOD));
        if at(hi, iterations) {
            break;
        }
        if hi >= MAX_PERIOD {
            return None;
        }
        lo = hi;
    }
    let step = Time::from_us(1);
    while hi.minus(lo) > step {
        let mid = expressible_period(Time::from_ns((lo.as_ns() + hi.as_ns()) / 2));
        if mid >= hi || mid <= lo {
            break;
        }
        if at(mid, iterations) {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    Some(hi)
}

fn level_needed<const N: usize, const M: usize>(
    robot: &RobotTable<'_>,
    streams: &[Stream],
    request: &Stream,
    iterations: &mut u64,
    evaluations: &mut u32,
) -> Option<u8> {
    let sender = request.sender?;
    // From the least urgent level up: the first that passes is the least urgency needed.
    for level in (0..LEVELS as u8).rev() {
        if level == sender.level {
            continue;
        }
        *evaluations += 1;
        let mut candidate = *request;
        candidate.sender = Some(Sender { level, ..sender });
        if !candidate.extended {
            candidate.id = sensor_id(level, sender.topic);
        }
        if check_with::<N, M>(robot, streams, &candidate, iterations).is_none() {
            return Some(level);
        }
    }
    None
}

const EMPTY_STREAM: Stream = Stream {
    id: 0,
    extended: false,
    dlc: 0,
    frames: 1,
    period: Time::ZERO,
    deadline: None,
    jitter: Time::ZERO,
    sender: None,
    receiver: None,
};

/// One task of a board as analysed.
#[derive(Debug, Clone, Copy)]
struct Job {
    id: TaskId,
    priority: u32,
    cost: Time,
    bcet: Time,
    period: Time,
    deadline: Time,
    own_jitter: Time,
    /// Index in the job array of the releaser.
    released_by: Option<usize>,
}

const EMPTY_JOB: Job = Job {
    id: TaskId::Fixed(0),
    priority: 0,
    cost: Time::ZERO,
    bcet: Time::ZERO,
    period: Time::ZERO,
    deadline: Time::ZERO,
    own_jitter: Time::ZERO,
    released_by: None,
};

/// One board's results: per job its bound (`None` when unbounded) and its best case.
struct BoardBounds<const N: usize> {
    jobs: [Job; N],
    wcrt: [Option<Time>; N],
    len: usize,
}

fn horizon(robot: &RobotTable<'_>, streams: &[Stream]) -> Time {
    // As the host: max(60 s, 1000 × the longest period or deadline of any task or message).
    let mut longest = Time::ZERO;
    for b in robot.boards {
        for t in b.tasks {
            longest = longest
                .max_of(t.period)
                .max_of(t.deadline.unwrap_or(t.period));
        }
    }
    for s in streams {
        longest = longest.max_of(s.period).max_of(s.deadline());
    }
    longest.times(1000).max_of(Time::from_us(60_000_000))
}

fn evaluate_into<const N: usize, const M: usize>(
    robot: &RobotTable<'_>,
    streams: &[Stream],
    iterations: &mut u64,
) -> Option<Refusal> {
    if streams.len() > M || robot.boards.len() > usize::from(u8::MAX) {
        return Some(Refusal::Capacity);
    }
    let limits = Limits {
        horizon: horizon(robot, streams),
    };
    let mut first: Option<Refusal> = None;
    // Each board's bounds are needed for the bus; keep the transmit task's and each sender's numbers.
    let mut sender_wcrt = [None::<Time>; M];
    let mut sender_bcrt = [Time::ZERO; M];
    let mut tx_wcrt = [None::<Time>; M];
    let mut receiver_wcrt = [None::<Time>; M];
    for (b, table) in robot.boards.iter().enumerate() {
        let bounds = match analyse_board::<N>(robot, b, table, streams, &limits, iterations) {
            Ok(bounds) => bounds,
            Err(refusal) => return Some(refusal),
        };
        for (j, job) in bounds.jobs.iter().enumerate().take(bounds.len) {
            let wcrt = bounds.wcrt.get(j).copied().flatten();
            if first.is_none() && wcrt.is_none_or(|w| w > job.deadline) {
                first = Some(Refusal::Deadline(Violation {
                    culprit: Culprit::Task {
                        board: b as u8,
                        task: job.id,
                    },
                    wcrt,
                    deadline: job.deadline,
                }));
            }
        }
        let fixed_wcrt = |index: Option<u16>| -> Option<Option<Time>> {
            let index = index?;
            let j = bounds
                .jobs
                .iter()
                .take(bounds.len)
                .position(|job| job.id == TaskId::Fixed(index))?;
            Some(bounds.wcrt.get(j).copied().flatten())
        };
        let tx = fixed_wcrt(table.can_tx);
        let handler = fixed_wcrt(table.command_handler);
        for (m, s) in streams.iter().enumerate() {
            if let Some(sender) = s.sender.filter(|x| usize::from(x.board) == b) {
                let j = bounds
                    .jobs
                    .iter()
                    .take(bounds.len)
                    .position(|job| job.id == TaskId::Publisher(sender.topic));
                if let (Some(j), Some(slot), Some(best), Some(txs)) = (
                    j,
                    sender_wcrt.get_mut(m),
                    sender_bcrt.get_mut(m),
                    tx_wcrt.get_mut(m),
                ) {
                    *slot = bounds.wcrt.get(j).copied().flatten();
                    *best = bounds.jobs.get(j).map_or(Time::ZERO, |job| job.bcet);
                    // No transmit task: nothing to add (`Some(0)`); an unbounded one: no bound (`None`).
                    *txs = match tx {
                        None => Some(Time::ZERO),
                        Some(w) => w,
                    };
                }
            }
            if s.receiver.is_some_and(|r| usize::from(r) == b) {
                if let Some(slot) = receiver_wcrt.get_mut(m) {
                    // A board without a command handler ends the path on the bus.
                    *slot = match handler {
                        None => Some(Time::ZERO),
                        Some(w) => w,
                    };
                }
            }
        }
    }

    // The bus: queuing jitter from the sender's variation and the transmit interrupt, then Davis et al.
    let bit = robot.bit_time;
    let n = streams.len();
    let mut order = [0usize; M];
    for (i, slot) in order.iter_mut().enumerate().take(n) {
        *slot = i;
    }
    let key = |i: usize| {
        streams
            .get(i)
            .map_or(u32::MAX, |s| can::arbitration_key(s.id, s.extended))
    };
    insertion_sort(order.get_mut(..n).unwrap_or(&mut []), |a, b| {
        key(a) > key(b)
    });
    let mut timings = [MessageTiming {
        key: 0,
        frame_time: Time::ZERO,
        frames: 1,
        period: Time::ZERO,
        jitter: Time::ZERO,
    }; M];
    let mut offset = [Time::ZERO; M];
    let mut sender_ok = [true; M];
    for (position, &i) in order.iter().enumerate().take(n) {
        let Some(s) = streams.get(i) else { continue };
        let mut jitter = s.jitter;
        let mut off = Time::ZERO;
        if s.sender.is_some() {
            match (
                sender_wcrt.get(i).copied().flatten(),
                tx_wcrt.get(i).copied().flatten(),
            ) {
                (Some(worst), Some(tx)) => {
                    let best = sender_bcrt.get(i).copied().unwrap_or(Time::ZERO);
                    jitter = jitter.plus(worst.minus(best)).plus(tx);
                    off = best;
                }
                _ => {
                    if let Some(ok) = sender_ok.get_mut(position) {
                        *ok = false;
                    }
                }
            }
        }
        if let (Some(t), Some(o)) = (timings.get_mut(position), offset.get_mut(position)) {
            *t = MessageTiming {
                key: can::arbitration_key(s.id, s.extended),
                frame_time: can::frame_time(robot.frame_cost, s.dlc, s.extended, bit),
                frames: s.frames,
                period: s.period,
                jitter,
            };
            *o = off;
        }
    }
    let timings = timings.get(..n).unwrap_or(&[]);
    let mut blockings = [Time::ZERO; M];
    can::blockings(timings, &mut blockings);
    let mut scratch = [Counter::default(); M];
    let mut out = [Err(AnalysisError::NoSuchIndex); M];
    can::response_times(
        timings,
        blockings.get(..n).unwrap_or(&[]),
        bit,
        &limits,
        &mut scratch,
        out.get_mut(..n).unwrap_or(&mut []),
    );
    for (position, &i) in order.iter().enumerate().take(n) {
        let Some(s) = streams.get(i) else { continue };
        *iterations += out
            .get(position)
            .and_then(|r| r.as_ref().ok())
            .map_or(0, |r: &Response| r.iterations);
        let bus = match (sender_ok.get(position), out.get(position)) {
            (Some(true), Some(Ok(r))) => offset.get(position).and_then(|o| o.checked_plus(r.wcrt)),
            _ => None,
        };
        if first.is_none() && bus.is_none_or(|w| w > s.deadline()) {
            first = Some(Refusal::Deadline(Violation {
                culprit: Culprit::Frame { id: s.id },
                wcrt: bus,
                deadline: s.deadline(),
            }));
        }
        if s.receiver.is_some() {
            let end = match (bus, receiver_wcrt.get(i).copied().flatten()) {
                (Some(w), Some(r)) => w.checked_plus(r),
                _ => None,
            };
            if first.is_none() && end.is_none_or(|w| w > s.deadline()) {
                first = Some(Refusal::Deadline(Violation {
                    culprit: Culprit::EndToEnd { id: s.id },
                    wcrt: end,
                    deadline: s.deadline(),
                }));
            }
        }
    }
    first
}

/// Stable insertion sort (small sets; allocation-free): `after(a, b)` says `a` belongs after `b`.
fn insertion_sort(items: &mut [usize], after: impl Fn(usize, usize) -> bool) {
    for i in 1..items.len() {
        let mut k = i;
        while k > 0 {
            let (Some(&prev), Some(&cur)) = (items.get(k - 1), items.get(k)) else {
                break;
            };
            if !after(prev, cur) {
                break;
            }
            items.swap(k - 1, k);
            k -= 1;
        }
    }
}

fn analyse_board<const N: usize>(
    robot: &RobotTable<'_>,
    b: usize,
    table: &BoardTable<'_>,
    streams: &[Stream],
    limits: &Limits,
    iterations: &mut u64,
) -> Result<BoardBounds<N>, Refusal> {
    let mut jobs = [EMPTY_JOB; N];
    let mut len = 0usize;
    let mut push = |job: Job| -> Result<usize, Refusal> {
        let slot = jobs.get_mut(len).ok_or(Refusal::Capacity)?;
        *slot = job;
        len += 1;
        Ok(len - 1)
    };
    // The shortest frame this board sends (its transmit-complete interrupt's minimum inter-arrival time).
    let mine = || {
        streams
            .iter()
            .filter(|s| s.sender.is_some_and(|x| usize::from(x.board) == b))
    };
    let own_frame = mine()
        .map(|s| {
            robot
                .bit_time
                .times(u64::from(can::frame_bits_best(s.dlc, false)))
        })
        .min()
        .unwrap_or_else(|| can::shortest_frame_time(robot.bit_time));
    for (i, t) in table.tasks.iter().enumerate() {
        let period = if t.own_frame { own_frame } else { t.period };
        push(Job {
            id: TaskId::Fixed(i as u16),
            priority: t.priority,
            cost: t.cost,
            bcet: t.bcet,
            period,
            deadline: t.deadline.unwrap_or(period),
            own_jitter: t.jitter,
            released_by: t.released_by.map(usize::from),
        })?;
    }
    for s in mine() {
        let Some(sender) = s.sender else { continue };
        let priority = table
            .levels
            .get(usize::from(sender.level))
            .copied()
            .flatten()
            .ok_or(Refusal::Capacity)?;
        let topic = table
            .topics
            .iter()
            .find(|t| t.topic == sender.topic)
            .ok_or(Refusal::Capacity)?;
        let timer = match table.monotonic {
            Some(m) => Some(push(Job {
                id: TaskId::Timer(sender.topic),
                priority: m.priority,
                cost: m.cost,
                bcet: Time::ZERO,
                period: s.period,
                deadline: s.period,
                own_jitter: m.jitter,
                released_by: None,
            })?),
            None => None,
        };
        push(Job {
            id: TaskId::Publisher(sender.topic),
            priority,
            cost: topic.cost,
            bcet: topic.bcet,
            period: s.period,
            deadline: s.deadline(),
            own_jitter: Time::ZERO,
            released_by: timer,
        })?;
    }

    // SRP blocking per job: the longest section of a lower-priority holder whose ceiling reaches the job.
    let mut blocking = [Time::ZERO; N];
    for (j, job) in jobs.iter().enumerate().take(len) {
        let p = job.priority;
        let mut longest = board::srp_blocking(p, table.sections);
        for s in mine() {
            let Some(sender) = s.sender else { continue };
            let holder = table
                .levels
                .get(usize::from(sender.level))
                .copied()
                .flatten()
                .unwrap_or(0);
            if holder >= p {
                continue;
            }
            if let Some(topic) = table.topics.iter().find(|t| t.topic == sender.topic) {
                for cs in topic.sections {
                    let section = CriticalSection {
                        holder_priority: holder,
                        ceiling: cs.ceiling.max(holder),
                        length: cs.length,
                    };
                    longest = longest.max_of(board::srp_blocking(p, &[section]));
                }
            }
        }
        if let Some(slot) = blocking.get_mut(j) {
            *slot = longest;
        }
    }

    // Highest priority first, ties in table order (as the host).
    let mut order = [0usize; N];
    for (i, slot) in order.iter_mut().enumerate().take(len) {
        *slot = i;
    }
    let priority = |i: usize| jobs.get(i).map_or(0, |j| j.priority);
    insertion_sort(order.get_mut(..len).unwrap_or(&mut []), |a, b| {
        priority(a) < priority(b)
    });
    let mut jitter = [Time::ZERO; N];
    for (j, job) in jobs.iter().enumerate().take(len) {
        if let Some(slot) = jitter.get_mut(j) {
            *slot = job.own_jitter;
        }
    }
    let mut wcrt = [None::<Time>; N];
    let chained = jobs.iter().take(len).any(|j| j.released_by.is_some());
    let mut settled = false;
    let mut scratch = [Counter::default(); N];
    let mut timings = [TaskTiming {
        priority: 0,
        wcet: Time::ZERO,
        period: Time::ZERO,
        jitter: Time::ZERO,
    }; N];
    let mut sorted_blocking = [Time::ZERO; N];
    let mut out = [Err(AnalysisError::NoSuchIndex); N];
    for _ in 0..MAX_JITTER_ROUNDS {
        for (position, &i) in order.iter().enumerate().take(len) {
            let (Some(job), Some(t), Some(sb)) = (
                jobs.get(i),
                timings.get_mut(position),
                sorted_blocking.get_mut(position),
            ) else {
                continue;
            };
            *t = TaskTiming {
                priority: job.priority,
                wcet: job.cost,
                period: job.period,
                jitter: jitter.get(i).copied().unwrap_or(Time::ZERO),
            };
            *sb = blocking.get(i).copied().unwrap_or(Time::ZERO);
        }
        board::response_times(
            timings.get(..len).unwrap_or(&[]),
            sorted_blocking.get(..len).unwrap_or(&[]),
            limits,
            &mut scratch,
            out.get_mut(..len).unwrap_or(&mut []),
        );
        for (position, &i) in order.iter().enumerate().take(len) {
            let result = out.get(position).copied();
            *iterations += result
                .and_then(|r| r.ok())
                .map_or(0, |r: Response| r.iterations);
            if let Some(slot) = wcrt.get_mut(i) {
                *slot = result.and_then(|r| r.ok()).map(|r| r.wcrt);
            }
        }
        if !chained {
            settled = true;
            break;
        }
        let mut changed = false;
        for i in 0..len {
            let Some(job) = jobs.get(i).copied() else {
                continue;
            };
            let Some(r) = job.released_by else { continue };
            match wcrt.get(r).copied().flatten() {
                Some(releaser) => match job.own_jitter.checked_plus(releaser) {
                    Some(inherited) => {
                        if jitter.get(i) != Some(&inherited) {
                            if let Some(slot) = jitter.get_mut(i) {
                                *slot = inherited;
                            }
                            changed = true;
                        }
                    }
                    None => {
                        if let Some(slot) = wcrt.get_mut(i) {
                            *slot = None;
                        }
                    }
                },
                None => {
                    if let Some(slot) = wcrt.get_mut(i) {
                        *slot = None;
                    }
                }
            }
        }
        if !changed {
            settled = true;
            break;
        }
    }
    if !settled {
        for (i, job) in jobs.iter().enumerate().take(len) {
            if job.released_by.is_some() {
                if let Some(slot) = wcrt.get_mut(i) {
                    *slot = None;
                }
            }
        }
    }
    Ok(BoardBounds { jobs, wcrt, len })
}

#[cfg(test)]
mod tests {
    use super::*;

    const SECTIONS: [TopicSection; 1] = [TopicSection {
        ceiling: 3,
        length: Time::from_us(5),
    }];
    const TOPICS: [TopicRow<'static>; 1] = [TopicRow {
        topic: 7,
        cost: Time::from_us(100),
        bcet: Time::from_us(50),
        sections: &SECTIONS,
    }];
    const TASKS: [TaskRow; 1] = [TaskRow {
        priority: 3,
        cost: Time::from_us(10),
        bcet: Time::from_us(5),
        period: Time::from_us(1000),
        deadline: None,
        jitter: Time::ZERO,
        released_by: None,
        own_frame: false,
    }];
    const BOARDS: [BoardTable<'static>; 1] = [BoardTable {
        name: "test",
        tasks: &TASKS,
        sections: &[],
        topics: &TOPICS,
        levels: [Some(4), Some(3), Some(2), Some(1)],
        monotonic: None,
        can_tx: None,
        command_handler: None,
    }];
    /// The table is `const`-constructible, as a build script's generated source needs.
    static ROBOT: RobotTable<'static> = RobotTable {
        boards: &BOARDS,
        bit_time: Time::from_ns(1000),
        frame_cost: FrameCost::Exact,
    };

    fn request(level: u8, period_us: u64) -> Stream {
        Stream {
            id: sensor_id(level, 7),
            extended: false,
            dlc: 8,
            frames: 1,
            period: Time::from_us(period_us),
            deadline: None,
            jitter: Time::ZERO,
            sender: Some(Sender {
                board: 0,
                topic: 7,
                level,
            }),
            receiver: None,
        }
    }

    #[test]
    fn admits_what_fits_and_refuses_what_does_not_with_a_suggestion() {
        let ok = admit::<8, 8>(&ROBOT, &[], &request(3, 2000), true);
        assert!(ok.admitted(), "{ok:?}");
        assert!(ok.iterations > 0);
        // 100 µs every 90 µs cannot fit; the shortest accepted period at low priority is found.
        let no = admit::<8, 8>(&ROBOT, &[], &request(3, 90), true);
        assert!(!no.admitted());
        let shortest = no.suggestion.shortest_period.expect("some period passes");
        assert!(admit::<8, 8>(&ROBOT, &[], &request(3, shortest.as_ns() / 1000), false).admitted());
        assert!(
            !admit::<8, 8>(&ROBOT, &[], &request(3, shortest.as_ns() / 1000 - 1), false).admitted()
        );
        assert!(no.evaluations > 2);
    }

    #[test]
    fn the_one_microsecond_request_is_refused_by_name() {
        let d = admit::<8, 8>(&ROBOT, &[], &request(0, 1), false);
        match d.refusal {
            Some(Refusal::Deadline(v)) => assert!(v.wcrt.is_none_or(|w| w > v.deadline)),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn capacity_is_a_refusal_not_a_panic() {
        let running = [request(3, 5000)];
        let mut other = request(2, 5000);
        other.sender = Some(Sender {
            board: 0,
            topic: 9,
            level: 2,
        });
        let d = admit::<8, 1>(&ROBOT, &running, &other, false);
        assert_eq!(d.refusal, Some(Refusal::Capacity));
        // Replacing the running publisher of the same topic needs no extra room.
        assert!(admit::<8, 1>(&ROBOT, &running, &request(2, 5000), false).admitted());
    }

    #[test]
    fn expressible_periods() {
        assert_eq!(
            expressible_period(Time::from_ns(899_500)),
            Time::from_us(900)
        );
        assert_eq!(
            expressible_period(Time::from_us(70_001)),
            Time::from_us(71_000)
        );
    }
}
