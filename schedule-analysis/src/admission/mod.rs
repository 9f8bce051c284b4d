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
//! The analysis is the report's own: per board, publisher jobs and their timer jobs are added to the fixed tasks
//! and their SRP blockings worked out from the table, then [`board_analysis::analyse`] (release jitters to a fixed
//! point, each transmit job with the transmit interrupt as its second releaser); then [`bus_analysis::analyse_each`]
//! with every message's sender's bounds (the sound transmit path, docs/analysis.md). The verdict is "no task and no
//! frame misses its deadline", which is `cargo xtask analyze --check`'s verdict for the same configuration without
//! jitter budgets (a property test checks that they agree).
//!
//! A board whose running jobs run sensor-bus scripts (the table's [`BusRow`]s and [`ScriptRow`]s) is analysed as
//! `sensor_bus::analyse` analyses it: its jobs' engine rows, rounds of the scripts' bus responses, one board analysis
//! per view and the engine events, to a fixed point within [`SCRIPT_ITERATIONS`] (docs/analysis.md, "The chip's
//! check with scripts").
//!
//! Its parts: this module (the table, the request and the verdict, one decision and the cache's refresh steps),
//! `board` (a board's jobs into [`board_analysis::analyse`]; `board::suspension`, the sensor-bus rounds), `bus`
//! (the streams into [`bus_analysis::analyse_each`]) and `cache` (what is kept of a board's analysis between
//! decisions).

use crate::board::TaskTiming;
use crate::board_analysis;
use crate::bus_analysis;
use crate::busy_window::{AnalysisError, Counter, Limits, Response, Share};
use crate::can::{self, FrameCost, MessageTiming};
use crate::time::Time;

mod board;
mod bus;
mod cache;

use board::{analyse_board, board_input};
use bus::analyse_bus;
use cache::Summary;
pub use cache::{Cache, MAX_BOARDS};

/// CAN priority levels of the protocol: urgent, high, medium, low (index 0 is the most urgent).
pub const LEVELS: usize = 4;
/// Rounds of the per-board release-jitter iteration (as the host analysis).
/// Fixed-point iterations one board's analysis may take, and the bus's (all its messages together)
/// ([`Refusal::Budget`] beyond): what bounds a decision's cost on the chip, which analyses one board and the bus. A configuration loaded close to 100 % can need a hundred thousand iterations (a
/// search found one: 217 ms of a board's CPU for one decision, docs/analysis.md); the requests the scenarios and
/// the thesis make take at most a few hundred (1 000 since 2026-12-06: docs/analysis.md, "Held per revision").
pub const DECISION_ITERATIONS: u64 = 1_000;
/// [`DECISION_ITERATIONS`] for a board whose running jobs run sensor-bus scripts: its rounds (each scripts' bus
/// responses, the board once per view, the engine events) to their fixed point, each round counted as one beside
/// its fixed points' iterations. The rounds of the sets `tests/admission_scripts.rs` decides take 40 to 2 500.
pub const SCRIPT_ITERATIONS: u64 = 4_000;
/// The longest period the period search tries (the protocol's 32-bit microsecond span, ≈ 71.6 min).
pub const MAX_PERIOD: Time = Time::from_ns(4_294_967_295_000);

/// A time in a table row: whole nanoseconds below [`NO_DEADLINE`] (about 4.29 s). Rows are 32-bit so that the
/// table a board carries in flash stays small; the lowering (`admission_host::lower`) refuses a model with a
/// longer time, so the build of a board fails instead of the table being wrong.
pub type RowTime = u32;
/// In [`TaskRow::deadline`]: no deadline of its own (the period). Never a row value.
pub const NO_DEADLINE: RowTime = u32::MAX;
/// In [`TaskRow::released_by`]: released by no task.
pub const NO_RELEASER: u8 = u8::MAX;
/// In a section's ceiling: a global critical section (interrupts disabled), the core's `u32::MAX`.
pub const INTERRUPTS_DISABLED: u8 = u8::MAX;

/// A row time as a [`Time`].
pub const fn row_time(ns: RowTime) -> Time {
    Time::from_ns(ns as u64)
}

/// A row ceiling as the core's ceiling ([`INTERRUPTS_DISABLED`] is `u32::MAX`).
pub const fn row_ceiling(ceiling: u8) -> u32 {
    if ceiling == INTERRUPTS_DISABLED {
        u32::MAX
    } else {
        ceiling as u32
    }
}

/// One fixed task of a board (not a publisher job), overheads included; times are [`RowTime`]s.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TaskRow {
    /// Worst-case execution time with entry/exit/dispatcher overheads.
    pub cost: RowTime,
    /// Period or minimum inter-arrival time (ignored when `own_frame`).
    pub period: RowTime,
    /// Deadline from the release event; [`NO_DEADLINE`]: the period (ignored when `bounded_only`).
    pub deadline: RowTime,
    /// Release jitter of its own.
    pub jitter: RowTime,
    /// RTIC priority (below 255).
    pub priority: u8,
    /// Index (in the board's `tasks`) of the task whose completion releases this one; [`NO_RELEASER`]: none.
    pub released_by: u8,
    /// Activated once per frame this board sends: its period is the best-case time of the shortest frame the board's
    /// publishers send (the shortest frame on the bus when it sends nothing).
    pub own_frame: bool,
    /// No deadline of its own: only its bound is checked (an unbounded one is refused). The transmit interrupt
    /// ([`BoardTable::can_tx`]) and its jobs per job of a task that queues frames: a late job loses no completion,
    /// and the transmit interrupt's response is every frame's queuing jitter (docs/analysis.md, "The transmit
    /// interrupt keeps no deadline").
    pub bounded_only: bool,
    /// Its share of the CPU, [`row_share`]`(cost, period)`, worked out when the table is built so that a decision
    /// divides only for its streams' jobs; [`SHARE_AT_RUNTIME`]: worked out by the check (an `own_frame` task, whose
    /// period depends on the streams, or a zero period).
    pub share: u32,
}

/// The longest of `sections` that blocks a job of priority `p` under SRP (`board::srp_blocking`): a section of a
/// lower-priority holder on a resource whose ceiling reaches `p` (0 when none does). [`BoardTable::blocking`] holds
/// it per priority.
pub fn fixed_blocking(sections: &[SectionRow], p: u32) -> RowTime {
    let mut longest = 0;
    for cs in sections {
        if u32::from(cs.holder_priority) < p && row_ceiling(cs.ceiling) >= p {
            longest = longest.max(cs.length);
        }
    }
    longest
}

/// In [`TaskRow::share`]: the check works the share out itself.
pub const SHARE_AT_RUNTIME: u32 = u32::MAX;

/// A fixed task's share of the CPU for [`TaskRow::share`]: [`Share::of`]'s utilisation (the table builder's; the
/// check would work out the same), or [`SHARE_AT_RUNTIME`] for a zero period (an overload the check must see).
pub fn row_share(cost: RowTime, period: RowTime) -> u32 {
    if period == 0 && cost > 0 {
        return SHARE_AT_RUNTIME;
    }
    u32::try_from(Share::of(row_time(cost), row_time(period)).utilisation())
        .unwrap_or(SHARE_AT_RUNTIME)
}

/// A critical section of a fixed task (or of `idle`, holder priority 0), its ceiling resolved: the core's
/// [`crate::board::CriticalSection`] in a compact row.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SectionRow {
    /// Longest time held.
    pub length: RowTime,
    /// Priority of the task that locks (0 for `idle`).
    pub holder_priority: u8,
    /// Ceiling of the locked resource ([`INTERRUPTS_DISABLED`]: a global critical section).
    pub ceiling: u8,
}

/// A critical section of a publisher job: its holder is the publisher task of the requested level.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TopicSection {
    /// Longest time held.
    pub length: RowTime,
    /// The resource's static ceiling ([`INTERRUPTS_DISABLED`]: interrupts disabled); the effective ceiling is at
    /// least the holder's priority.
    pub ceiling: u8,
}

/// A topic this board can publish: one job of the level's publisher task per sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TopicRow<'a> {
    /// Protocol topic byte.
    pub topic: u8,
    /// Worst-case execution time of one sample, software-task overheads included.
    pub cost: RowTime,
    /// Best-case execution time (the earliest its frames can be queued).
    pub bcet: RowTime,
    /// Its critical sections.
    pub sections: &'a [TopicSection],
    /// The scripts one sample runs on the board's sensor buses, in the sample's order (empty: none).
    pub scripts: &'a [ScriptRow],
    /// Where the board's transmit interrupt is charged by its parts (docs/analysis.md, "The transmit interrupt's
    /// parts"): the cost of its job per sample of this topic (`can_tx[<topic>]`: fixed + the topic's frames per
    /// sample × (fixed + per frame + abort), hardware-task overheads included), which the publisher job releases
    /// with [`crate::can::transmit_abort_latency`] as its own jitter. 0: no such job (the transmit interrupt charged
    /// as a whole).
    pub transmit: RowTime,
}

/// Most sensor buses a board's table may state (the check's per-bus working arrays).
pub const MAX_BUSES: usize = 4;

/// One sensor bus of a board (docs/analysis.md, "Self-suspending publishers and the sensor buses"): its engine's
/// interrupt priority and charge by its parts; a script's charge is `events · per_event + per_script + starts ·
/// condition_wait`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BusRow {
    /// The engine interrupt's RTIC priority.
    pub engine_priority: u8,
    /// One engine event on the CPU, interrupt entry and exit included.
    pub per_event: RowTime,
    /// Charged once per script (0 where the engine does not state it).
    pub per_script: RowTime,
    /// Charged once per START condition of a script (0 where the engine does not state it).
    pub condition_wait: RowTime,
}

impl BusRow {
    /// Its engine as the sensor buses' rounds read it ([`crate::suspension_analysis`]), with the SRP `blocking`
    /// at its priority.
    pub fn engine(&self, blocking: Time) -> crate::suspension_analysis::Engine {
        crate::suspension_analysis::Engine {
            priority: u32::from(self.engine_priority),
            per_event: row_time(self.per_event),
            per_script: row_time(self.per_script),
            condition_wait: row_time(self.condition_wait),
            blocking,
        }
    }
}

/// One script a job runs on a sensor bus: the host turned its bytes into time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ScriptRow {
    /// Index into the board's `buses`.
    pub bus: u8,
    /// Its time on the wire plus the devices' stretch allowance (the chip adds its events' responses).
    pub bus_time: RowTime,
    /// Engine events one script raises.
    pub events: u16,
    /// Its START conditions (the events that take the condition wait).
    pub starts: u16,
    /// The job's own wait before it submits the script (suspension, not bus time).
    pub settle: RowTime,
}

/// A fixed task's scripts: its index in the board's `tasks` and its job's scripts in order.
pub type TaskScripts<'a> = (u8, &'a [ScriptRow]);

/// The monotonic's timer interrupt, one job per timer-released publisher job.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MonotonicRow {
    /// Its priority.
    pub priority: u8,
    /// Cost of one timer interrupt, entry and exit included.
    pub cost: RowTime,
    /// Release jitter (one tick).
    pub jitter: RowTime,
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
    /// Per priority (the index), the longest of `sections` that blocks a job of that priority
    /// ([`fixed_blocking`]), worked out when the table is built; a priority beyond it is worked out by the check.
    pub blocking: &'a [RowTime],
    /// The topics it can publish, with their budgets.
    pub topics: &'a [TopicRow<'a>],
    /// The shortest data length of `topics`' frames (0 without topics), worked out when the table is built: every
    /// frame the board sends is of one of them, so its shortest own frame ([`crate::can::own_frame_time`]).
    pub shortest_dlc: u8,
    /// RTIC priority of the publisher task per CAN priority level (urgent, high, medium, low); `None`: none.
    pub levels: [Option<u8>; LEVELS],
    /// The monotonic's timer job, when publishers are timer-released.
    pub monotonic: Option<MonotonicRow>,
    /// Index of the transmit interrupt task (its WCRT is queuing jitter for every frame the board sends). It has
    /// no deadline of its own: the check refuses it only unbounded (docs/analysis.md, "The transmit interrupt keeps
    /// no deadline").
    pub can_tx: Option<u16>,
    /// Index of the command handler (the end of a command's path).
    pub command_handler: Option<u16>,
    /// The sensor buses its scripts run on (empty: none).
    pub buses: &'a [BusRow],
    /// The fixed tasks that run scripts, with their scripts (empty: none).
    pub task_scripts: &'a [TaskScripts<'a>],
    /// Per CAN level, which RTIC task publishes it (levels of one publisher task share a number): the jobs of one
    /// RTIC task run one after the other, so a script's siblings and a suspending task's view follow it.
    pub publisher_tasks: [u8; LEVELS],
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
    /// A board's analysis, or the bus's, needed more than [`DECISION_ITERATIONS`] fixed-point iterations (a board
    /// with scripts: [`SCRIPT_ITERATIONS`], its rounds counted): refused
    /// without a verdict on
    /// its deadlines (the check's cost stays bounded; refusing never breaks a deadline). Below the hard floor.
    Budget,
}

/// What one analysis of a configuration found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Evaluation {
    /// `None`: everything meets its deadline.
    pub refusal: Option<Refusal>,
    /// The first violation below the hard floor (see [`Decision::floor`]); `None` when there is none.
    pub floor: Option<Refusal>,
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
    /// The first violation that no policy may accept (the hard floor, docs/analysis.md): a task or message left
    /// without a bound, a fixed task of a board (CAN receive and transmit, command handling, the admission task,
    /// the watchdog, the shutdown path, …) missing its deadline, a command's end-to-end path, a capacity or zero
    /// period refusal. `None` when every violation is a bounded deadline miss of a publisher (its job, its timer
    /// job or its frames), which accept-and-warn may start with a warning.
    pub floor: Option<Refusal>,
    /// On refusal, what would be accepted (searched only when asked for).
    pub suggestion: Suggestion,
    /// Fixed-point iterations of the whole decision, searches included.
    pub iterations: u64,
    /// Whole-robot analyses run (1 without a search).
    pub evaluations: u32,
    /// Board analyses the check ran (the searches not counted): with a [`Cache`], the boards whose kept analysis
    /// did not hold — the request's board, and any other whose streams changed since its analysis was kept;
    /// without one, every board.
    pub boards: u32,
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
    let found = evaluate_into::<N, M>(robot, streams, None, &mut iterations, None);
    Evaluation {
        refusal: found.first,
        floor: found.floor,
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
    let found = check_with::<N, M>(robot, streams, request, &mut iterations);
    let refusal = found.first;
    let mut suggestion = Suggestion::default();
    if refusal.is_some() && suggest && request.sender.is_some() && !request.period.is_zero() {
        suggestion.shortest_period =
            shortest_period::<N, M>(robot, streams, request, &mut iterations, &mut evaluations);
        suggestion.level =
            level_needed::<N, M>(robot, streams, request, &mut iterations, &mut evaluations);
    }
    Decision {
        refusal,
        floor: found.floor,
        suggestion,
        iterations,
        evaluations,
        boards: found.boards,
    }
}

/// [`admit`] without the suggestion search, reusing the analyses of boards whose streams did not change since the
/// last decision that used `cache` (the on-chip check: one cache per board, kept across commands). The decision
/// is the one [`admit`] takes on the same inputs. The request's board's new analysis is kept when the request is
/// admitted, or with `carried_out_anyway` (accept-and-warn: the board starts it although it is refused).
pub fn admit_cached<const N: usize, const M: usize>(
    robot: &RobotTable<'_>,
    streams: &[Stream],
    request: &Stream,
    cache: &mut Cache<M>,
    carried_out_anyway: bool,
) -> Decision {
    let mut iterations = 0u64;
    let found = if request.period.is_zero() {
        Found::refused(Refusal::ZeroPeriod)
    } else {
        evaluate_into::<N, M>(
            robot,
            streams,
            Some(request),
            &mut iterations,
            Some((cache, carried_out_anyway)),
        )
    };
    Decision {
        refusal: found.first,
        floor: found.floor,
        suggestion: Suggestion::default(),
        iterations,
        evaluations: 1,
        boards: found.boards,
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
) -> Found {
    if request.period.is_zero() {
        return Found::refused(Refusal::ZeroPeriod);
    }
    evaluate_into::<N, M>(robot, streams, Some(request), iterations, None)
}

/// What one analysis found: the first violation (table order, then the bus) and the first below the hard floor.
#[derive(Debug, Clone, Copy, Default)]
struct Found {
    first: Option<Refusal>,
    floor: Option<Refusal>,
    /// Board analyses run.
    boards: u32,
}

impl Found {
    /// A refusal that no policy may accept (capacity, zero period).
    fn refused(refusal: Refusal) -> Found {
        Found {
            first: Some(refusal),
            floor: Some(refusal),
            boards: 0,
        }
    }

    /// Notes a violation; `floor` says whether it is below the hard floor.
    fn note(&mut self, refusal: Refusal, floor: bool) {
        if self.first.is_none() {
            self.first = Some(refusal);
        }
        if floor && self.floor.is_none() {
            self.floor = Some(refusal);
        }
    }
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
        check_with::<N, M>(robot, streams, &candidate, iterations)
            .first
            .is_none()
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
        if check_with::<N, M>(robot, streams, &candidate, iterations)
            .first
            .is_none()
        {
            return Some(level);
        }
    }
    None
}

/// "No bound" in the working arrays (a response of `u64::MAX` ns cannot occur: it is far beyond any horizon).
const NONE: u64 = u64::MAX;
/// In a [`View`]'s index: the request.
const REQUEST: u8 = u8::MAX;
/// In a job's `released_by`: released by no job.
const NO_JOB: u8 = u8::MAX;

fn bound(ns: u64) -> Option<Time> {
    (ns != NONE).then_some(Time::from_ns(ns))
}

/// The configuration analysed, without copying a stream: the running streams in their order, the request in the
/// place of the stream of its source or, without one, last (indices into `running`, [`REQUEST`] for the request).
struct View<'s, const M: usize> {
    running: &'s [Stream],
    request: Option<&'s Stream>,
    index: [u8; M],
    len: usize,
}

impl<'s, const M: usize> View<'s, M> {
    fn new(running: &'s [Stream], request: Option<&'s Stream>) -> Option<Self> {
        let mut view = View {
            running,
            request,
            index: [0; M],
            len: 0,
        };
        let mut placed = false;
        for (i, s) in running.iter().enumerate() {
            // A replaced stream's place is the request's: the order a board keeps its running set in
            // (`Admission::upsert`), so that the analysis kept for the request's board is found again by the
            // next decision instead of being redone for a different order.
            let i = if request.is_some_and(|r| s.same_source(r)) {
                if placed {
                    continue;
                }
                placed = true;
                REQUEST
            } else {
                u8::try_from(i).ok().filter(|&i| i != REQUEST)?
            };
            *view.index.get_mut(view.len)? = i;
            view.len += 1;
        }
        if request.is_some() && !placed {
            *view.index.get_mut(view.len)? = REQUEST;
            view.len += 1;
        }
        Some(view)
    }

    fn get(&self, position: usize) -> Option<&'s Stream> {
        let &i = self.index.get(..self.len)?.get(position)?;
        if i == REQUEST {
            self.request
        } else {
            self.running.get(usize::from(i))
        }
    }

    fn iter(&self) -> impl Iterator<Item = (usize, &'s Stream)> + '_ {
        (0..self.len).filter_map(|m| Some((m, self.get(m)?)))
    }
}

/// Per stream of the configuration (by position in the [`View`]): what the boards' analyses found for the bus.
struct SenderBounds<const M: usize> {
    /// The sending job's WCRT ([`NONE`]: unbounded or not found).
    wcrt: [u64; M],
    /// The sending job's best case.
    bcrt: [u64; M],
    /// The sender's transmit interrupt's WCRT (0 without one).
    tx: [u64; M],
    /// The receiving board's command handler's WCRT (0 without one).
    receiver: [u64; M],
}

fn horizon<const M: usize>(
    robot: &RobotTable<'_>,
    streams: &View<'_, M>,
    known: Option<&mut Time>,
) -> Time {
    // As the host: max(60 s, 1000 × the longest period or deadline of any task or message). The fixed tasks' part
    // is the same for every configuration: a cache keeps it (zero: not yet worked out), so a decision walks only
    // its streams.
    let mut longest = known.as_deref().copied().unwrap_or(Time::ZERO);
    if longest == Time::ZERO {
        for b in robot.boards {
            for t in b.tasks {
                longest = longest.max_of(row_time(t.period));
                if t.deadline != NO_DEADLINE {
                    longest = longest.max_of(row_time(t.deadline));
                }
            }
        }
        if let Some(slot) = known {
            *slot = longest;
        }
    }
    for (_, s) in streams.iter() {
        longest = longest.max_of(s.period).max_of(s.deadline());
    }
    longest.times(1000).max_of(Time::from_us(60_000_000))
}

#[inline(never)]
fn evaluate_into<const N: usize, const M: usize>(
    robot: &RobotTable<'_>,
    running: &[Stream],
    request: Option<&Stream>,
    iterations: &mut u64,
    mut cache: Option<(&mut Cache<M>, bool)>,
) -> Found {
    if robot.boards.len() > usize::from(u8::MAX) || N >= usize::from(NO_JOB) {
        return Found::refused(Refusal::Capacity);
    }
    let Some(streams) = View::<M>::new(running, request) else {
        return Found::refused(Refusal::Capacity);
    };
    let limits = Limits {
        horizon: horizon(
            robot,
            &streams,
            cache.as_mut().map(|(c, _)| &mut c.fixed_longest),
        ),
        iterations: DECISION_ITERATIONS,
    };
    let mut found = Found::default();
    let mut senders = SenderBounds {
        wcrt: [NONE; M],
        bcrt: [0; M],
        tx: [NONE; M],
        receiver: [NONE; M],
    };
    // The request's board: its new analysis replaces the kept one only when the request is carried out.
    let requesting = request.and_then(|r| r.sender).map(|x| usize::from(x.board));
    // The request's board's new analysis (kept only when the request is carried out), or any board's without a
    // cache; with a cache, the other boards are analysed straight into their slots (one summary on the stack).
    let mut fresh = Summary::EMPTY;
    // Whose analysis `fresh` holds.
    let mut fresh_board = None;
    for (b, table) in robot.boards.iter().enumerate() {
        let hit = cache
            .as_ref()
            .and_then(|(c, _)| c.boards.get(b))
            .is_some_and(|summary| summary.holds_for(b, &streams, limits.horizon));
        let mut in_fresh = false;
        if !hit {
            let slot = cache
                .as_mut()
                .filter(|_| requesting != Some(b))
                .and_then(|(c, _)| c.boards.get_mut(b));
            let target = match slot {
                Some(slot) => slot,
                None => {
                    in_fresh = true;
                    fresh_board = Some(b);
                    &mut fresh
                }
            };
            *target = Summary::EMPTY;
            if target.key.fill(b, &streams, limits.horizon).is_none() {
                return Found::refused(Refusal::Capacity);
            }
            // Each board's analysis has its own budget (not what the boards before it left over): its outcome
            // depends on its own inputs only, so a kept analysis is the one a fresh decision would compute.
            if let Err(refusal) = analyse_board::<N, M>(
                &board_input(robot, b, table, &streams, &limits),
                iterations,
                target,
            ) {
                return Found::refused(refusal);
            }
            target.kept = true;
            found.boards += 1;
        }
        let summary = match cache.as_ref().and_then(|(c, _)| c.boards.get(b)) {
            Some(slot) if !in_fresh => slot,
            _ => &fresh,
        };
        summary.note_violations(b, &mut found);
        summary.apply(b, table, &streams, &mut senders);
    }
    if !analyse_bus(
        robot,
        &streams,
        &senders,
        &limits,
        DECISION_ITERATIONS,
        iterations,
        &mut found,
    ) {
        return Found::refused(Refusal::Budget);
    }
    // Kept when the request is carried out: admitted, or refused above the floor under accept-and-warn.
    if let (Some(b), Some((c, keep_refused))) = (requesting, cache) {
        let carried_out = found.first.is_none() || (keep_refused && found.floor.is_none());
        if fresh_board == Some(b) && carried_out {
            if let Some(slot) = c.boards.get_mut(b) {
                *slot = fresh;
            }
        }
    }
    found
}

/// Brings `cache` up to date with the running `streams` (analysing only the boards whose kept analysis does not
/// hold, each once) and returns the iterations it took: [`refresh_one`]'s steps back to back.
pub fn refresh<const N: usize, const M: usize>(
    robot: &RobotTable<'_>,
    streams: &[Stream],
    cache: &mut Cache<M>,
) -> u64 {
    let (mut iterations, mut from) = (0u64, 0);
    while let Some((board, spent)) = refresh_one::<N, M>(robot, streams, None, cache, from) {
        iterations += spent;
        from = board + 1;
    }
    iterations
}

/// One step of bringing `cache` up to date, so that a decision analyses no board but the request's own: the first
/// board from index `from` on (other than `request`'s sender's) whose kept analysis does not hold for the `running`
/// streams with `request` in its place is analysed and kept. Returns that board and the iterations it took (kept
/// only when the analysis completed within its budget); `None` when every such board's analysis holds. The admission
/// task runs it as a paced step of its own before a decision whose request moves the horizon (a long period: every
/// board's key changes), and after a stop (`request` `None`), so that no step analyses more than one board, and a
/// decision its own board and the bus. A decision after these steps is the decision without them: a kept analysis is
/// the one a fresh decision computes for the same key.
pub fn refresh_one<const N: usize, const M: usize>(
    robot: &RobotTable<'_>,
    running: &[Stream],
    request: Option<&Stream>,
    cache: &mut Cache<M>,
    from: usize,
) -> Option<(usize, u64)> {
    let streams = View::<M>::new(running, request)?;
    let limits = Limits {
        horizon: horizon(robot, &streams, Some(&mut cache.fixed_longest)),
        iterations: DECISION_ITERATIONS,
    };
    let requesting = request.and_then(|r| r.sender).map(|x| usize::from(x.board));
    for (b, table) in robot.boards.iter().enumerate().skip(from) {
        if requesting == Some(b) {
            continue;
        }
        let Some(slot) = cache.boards.get_mut(b) else {
            // Boards beyond the cache's are analysed in each decision.
            return None;
        };
        if slot.holds_for(b, &streams, limits.horizon) {
            continue;
        }
        *slot = Summary::EMPTY;
        slot.key.fill(b, &streams, limits.horizon)?;
        let mut iterations = 0;
        let input = board_input(robot, b, table, &streams, &limits);
        if analyse_board::<N, M>(&input, &mut iterations, slot).is_ok() {
            slot.kept = true;
        }
        return Some((b, iterations));
    }
    None
}

/// Stable insertion sort (small sets; allocation-free): `after(a, b)` says `a` belongs after `b`.
fn insertion_sort(items: &mut [u8], after: impl Fn(u8, u8) -> bool) {
    for i in 1..items.len() {
        let mut k = i;
        while k > 0 {
            // A pair taken by pattern, not `swap(k - 1, k)`: that one keeps a bounds check (a panic path the
            // build's call-graph check found in every image).
            let Some([prev, cur]) = items.get_mut(k - 1..=k) else {
                break;
            };
            if !after(*prev, *cur) {
                break;
            }
            core::mem::swap(prev, cur);
            k -= 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SECTIONS: [TopicSection; 1] = [TopicSection {
        ceiling: 3,
        length: 5_000,
    }];
    const TOPICS: [TopicRow<'static>; 1] = [TopicRow {
        topic: 7,
        cost: 100_000,
        bcet: 50_000,
        sections: &SECTIONS,
        scripts: &[],
        transmit: 0,
    }];
    const TASKS: [TaskRow; 1] = [TaskRow {
        priority: 3,
        cost: 10_000,
        period: 1_000_000,
        deadline: NO_DEADLINE,
        jitter: 0,
        released_by: NO_RELEASER,
        own_frame: false,
        bounded_only: false,
        share: SHARE_AT_RUNTIME,
    }];
    const BOARDS: [BoardTable<'static>; 1] = [BoardTable {
        name: "test",
        tasks: &TASKS,
        sections: &[],
        blocking: &[],
        topics: &TOPICS,
        shortest_dlc: 4,
        levels: [Some(4), Some(3), Some(2), Some(1)],
        monotonic: None,
        can_tx: None,
        command_handler: None,
        buses: &[],
        task_scripts: &[],
        publisher_tasks: [0, 1, 2, 3],
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
    fn the_one_microsecond_request_is_refused_below_the_floor() {
        // Named by its deadline, or — when a fixed point runs out of the check's iterations first, as this table's
        // does — refused for the check's budget; never admitted, and no policy may start it.
        let d = admit::<8, 8>(&ROBOT, &[], &request(0, 1), false);
        match d.refusal {
            Some(Refusal::Deadline(v)) => assert!(v.wcrt.is_none_or(|w| w > v.deadline)),
            Some(Refusal::Budget) => {}
            other => panic!("{other:?}"),
        }
        assert!(d.floor.is_some());
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

    /// A fixed task whose bound nothing reads (no transmit interrupt, no command handler, it releases nothing)
    /// needs no fixed point when the closed-form bound meets its deadline; when the bound does not but the exact
    /// response does, the exact analysis settles it, and the verdict is the exact one either way. A job whose window
    /// holds one activation of each job at or above its level needs none either, exactly.
    #[test]
    fn a_job_nothing_reads_is_settled_in_closed_form_when_its_bound_meets_its_deadline() {
        // Alone, the 10 µs task every 1 ms: its window is its cost, exactly, with no iteration (it took one).
        let alone = evaluate::<8, 8>(&ROBOT, &[]);
        assert_eq!((alone.refusal, alone.iterations), (None, 0));
        // 250 µs every 1 ms below a publisher of 100 µs every 300 µs: 350 µs hold two of the publisher's
        // activations, so the exact response is 250 + 2 × 100 = 450 µs after two iterations; in closed form
        // (250 + 100) / (1 − 1/3) ≈ 525 µs. With its 1 ms deadline the bound settles it (no iteration on the board);
        // with 500 µs the exact analysis does (admitted), and with 400 µs it is refused, naming the exact 450 µs.
        let above = request(0, 300);
        let decide = |deadline_us: u32| {
            let tasks = [TaskRow {
                cost: 250_000,
                deadline: deadline_us * 1000,
                share: SHARE_AT_RUNTIME,
                ..TASKS[0]
            }];
            let boards = [BoardTable {
                tasks: &tasks,
                ..BOARDS[0]
            }];
            let robot = RobotTable {
                boards: &boards,
                ..ROBOT
            };
            evaluate::<8, 8>(&robot, &[above])
        };
        let loose = decide(1000);
        assert_eq!(loose.refusal, None);
        for (deadline_us, refused) in [(500, false), (400, true)] {
            let tight = decide(deadline_us);
            assert!(
                tight.iterations >= loose.iterations + 2,
                "{deadline_us} µs: {tight:?} against {loose:?}"
            );
            match tight.refusal {
                None => assert!(!refused, "{deadline_us} µs"),
                Some(Refusal::Deadline(v)) => {
                    assert!(refused, "{deadline_us} µs");
                    assert_eq!(
                        v.culprit,
                        Culprit::Task {
                            board: 0,
                            task: TaskId::Fixed(0)
                        }
                    );
                    assert_eq!(v.wcrt, Some(Time::from_us(450)));
                }
                other => panic!("{deadline_us} µs: {other:?}"),
            }
        }
    }

    /// The transmit interrupt ([`BoardTable::can_tx`]) keeps no deadline of its own: a row whose busy window
    /// closes passes however long its response, that response is the queuing jitter of the board's frames, and a
    /// row whose window does not close is refused. Worked by hand: the board's one topic has 3-byte frames (the
    /// proximity ring; 47 + 24 = 71 bits, 71 µs at 1 Mbit/s), so the transmit row (55 µs per own frame, priority 5)
    /// is released every 71 µs; above it a 20 µs task every 1 ms at priority 6 and the publisher job (100 µs, best
    /// 50 µs, every 10 ms at priority 9, which nothing delays). The level's busy period: 175 → 285 → 395 → 450 →
    /// 505 → 560 → 560 µs (⌈w/71⌉·55 + 20 + 100), eight jobs, the first the worst: 175 µs, more than two own frames
    /// (142 µs). The frame (8 bytes, 135 µs, alone on the bus) is queued with jitter (100 − 50) + 175 from the
    /// publisher's best 50 µs; on the sound transmit path it costs 135 + G, G = 175 + 135 (the transmit response and
    /// the longest frame), and a page outside the model blocks it (135 µs, its identifier 0x707 below 0x71C):
    /// delivered at worst 50 + 225 + 135 + 445 = 855 µs after the release.
    #[test]
    fn the_transmit_interrupt_is_checked_for_a_bound_and_its_response_is_the_frames_jitter() {
        let own_frame = can::own_frame_time(Time::from_ns(1000), [3u8].into_iter());
        assert_eq!(own_frame, Time::from_us(71));
        // `transmit`: the row is the board's transmit interrupt; `cost`, `above`: its and the task above's cost
        // (ns); `deadline`: the stream's (µs).
        let decide = |transmit: bool, cost: u32, above: u32, deadline: u64| {
            let topic = 0x1F;
            assert_eq!(amiro_can::Topic::from_byte(topic).map(|t| t.dlc()), Some(3));
            let topics = [TopicRow { topic, ..TOPICS[0] }];
            let tasks = [
                TaskRow {
                    priority: 6,
                    cost: above,
                    period: 1_000_000,
                    ..TASKS[0]
                },
                TaskRow {
                    priority: 5,
                    cost,
                    period: 0,
                    own_frame: true,
                    bounded_only: transmit,
                    ..TASKS[0]
                },
            ];
            let boards = [BoardTable {
                tasks: &tasks,
                topics: &topics,
                shortest_dlc: 3,
                levels: [Some(9); LEVELS],
                can_tx: transmit.then_some(1),
                ..BOARDS[0]
            }];
            let robot = RobotTable {
                boards: &boards,
                ..ROBOT
            };
            let mut stream = request(3, 10_000);
            stream.deadline = Some(Time::from_us(deadline));
            if let Some(sender) = stream.sender.as_mut() {
                sender.topic = topic;
            }
            evaluate::<8, 8>(&robot, &[stream])
        };
        // 175 µs, beyond two own frames: admitted, the frames delivered by 855 µs.
        assert_eq!(decide(true, 55_000, 20_000, 855).refusal, None);
        match decide(true, 55_000, 20_000, 854).refusal {
            Some(Refusal::Deadline(v)) => {
                assert!(matches!(v.culprit, Culprit::Frame { .. }), "{v:?}");
                assert_eq!(v.wcrt, Some(Time::from_us(855)));
            }
            other => panic!("the frames at 854 µs: {other:?}"),
        }
        // 80 µs more above it: the first job 255 µs, and the frames 160 µs later (in the jitter and in G).
        assert_eq!(decide(true, 55_000, 100_000, 1015).refusal, None);
        assert!(decide(true, 55_000, 100_000, 1014).refusal.is_some());
        // The same row as any other fixed task has its period for a deadline (one own frame): refused.
        match decide(false, 55_000, 20_000, 410).refusal {
            Some(Refusal::Deadline(v)) => {
                assert_eq!(
                    v.culprit,
                    Culprit::Task {
                        board: 0,
                        task: TaskId::Fixed(1)
                    }
                );
                assert_eq!((v.wcrt, v.deadline), (Some(Time::from_us(175)), own_frame));
            }
            other => panic!("not the transmit interrupt: {other:?}"),
        }
        // 65 µs every 71 µs with 10 % above it: the window never closes, refused below the hard floor.
        let unbounded = decide(true, 65_000, 100_000, 10_000);
        for refusal in [unbounded.refusal, unbounded.floor] {
            match refusal {
                Some(Refusal::Deadline(v)) => {
                    assert_eq!(
                        v.culprit,
                        Culprit::Task {
                            board: 0,
                            task: TaskId::Fixed(1)
                        }
                    );
                    assert_eq!(v.wcrt, None);
                }
                other => panic!("unbounded: {other:?}"),
            }
        }
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
