//! The whole system at once, as the report shows it: every board (overheads, SRP ceilings, release chains), then
//! the bus (sender response variation as queuing jitter), then every topic end to end with its jitter budget.
//!
//! The analysis itself is the core's, the one the boards' admission check runs: [`board_analysis::analyse`] per
//! board (release jitters iterated to a fixed point, every job's whole busy-window record kept) and
//! [`bus_analysis::analyse`] for the bus, which depends on the boards but never the other way round, so it runs
//! once afterwards. This module adds what only the host needs: names, resource ceilings from who uses what,
//! overheads, why a bound is missing, utilisations and the end-to-end paths.

use std::collections::{BinaryHeap, HashMap};
use std::fmt;

use crate::board::{self, CriticalSection, TaskTiming};
use crate::board_analysis;
use crate::bus_analysis;
use crate::busy_window::{AnalysisError, Counter, Limits, Response, Share};
use crate::can::{self, MessageTiming};
use crate::model::{
    BoardSystem, BusSystem, FrameCostSpec, System, TaskKind, TaskRef, GLOBAL_CRITICAL_SECTION,
};
use crate::time::Time;

/// Why a response time is unbounded.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Unbounded {
    /// The core analysis found no bound (overload, or beyond the horizon).
    Analysis(AnalysisError),
    /// The task that releases this one is unbounded, so its release jitter is.
    Releaser(String),
    /// The task that sends this message (or its transmit path) is unbounded.
    Sender(String),
    /// Inherited release jitters kept growing.
    NoConvergence,
    /// A script on a sensor bus has no bound, so the job that awaits it has none
    /// ([`crate::sensor_bus`]): the bus, and why.
    SensorBus(String, String),
    /// A self-suspending job of at least this priority has no bound, so its interference has none.
    Suspending(String),
}

impl fmt::Display for Unbounded {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Unbounded::Analysis(AnalysisError::Overload) => f.write_str("utilisation above 100 %"),
            Unbounded::Analysis(AnalysisError::BeyondHorizon) => {
                f.write_str("busy window beyond the horizon")
            }
            Unbounded::Analysis(AnalysisError::Overflow) => {
                f.write_str("times beyond the 64-bit nanosecond range")
            }
            Unbounded::Analysis(AnalysisError::IterationLimit) => {
                f.write_str("fixed point beyond the iteration limit")
            }
            Unbounded::Analysis(e) => write!(f, "{e}"),
            Unbounded::Releaser(name) => write!(f, "released by unbounded `{name}`"),
            Unbounded::Sender(name) => write!(f, "sent by unbounded `{name}`"),
            Unbounded::NoConvergence => f.write_str("inherited jitter does not converge"),
            Unbounded::SensorBus(bus, why) => write!(f, "its script on `{bus}`: {why}"),
            Unbounded::Suspending(name) => write!(f, "self-suspending `{name}` unbounded"),
        }
    }
}

/// A response bound, or why there is none.
pub type Bound = Result<Response, Unbounded>;

/// Settings of one analysis run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Options {
    /// Frame-cost model for the bus.
    pub frame_cost: FrameCostSpec,
    /// Busy windows longer than this are unbounded; `None` picks max(60 s, 1000 × the longest period).
    pub horizon: Option<Time>,
}

/// Everything the analysis found for one frame-cost model.
#[derive(Debug, Clone, PartialEq)]
pub struct Analysis {
    /// Model label.
    pub name: Option<String>,
    /// Frame-cost model used on the bus.
    pub frame_cost: FrameCostSpec,
    /// Per board.
    pub boards: Vec<BoardResult>,
    /// The bus.
    pub bus: Option<BusResult>,
    /// Per message, end to end.
    pub topics: Vec<TopicResult>,
}

/// One board's results.
#[derive(Debug, Clone, PartialEq)]
pub struct BoardResult {
    /// Board name.
    pub name: String,
    /// CPU utilisation Σ C/T, overheads included.
    pub utilisation: f64,
    /// Tasks in model order.
    pub tasks: Vec<TaskResult>,
    /// The board's sensor buses and their scripts ([`crate::sensor_bus`]); empty without scripts.
    pub sensor_buses: Vec<crate::sensor_bus::SensorBusResult>,
}

/// One task's results.
#[derive(Debug, Clone, PartialEq)]
pub struct TaskResult {
    /// Task name.
    pub name: String,
    /// RTIC task it is a job of.
    pub job_of: Option<String>,
    /// Priority.
    pub priority: u32,
    /// Overhead class.
    pub kind: TaskKind,
    /// Sporadic (minimum inter-arrival time).
    pub sporadic: bool,
    /// Period.
    pub period: Time,
    /// Deadline.
    pub deadline: Time,
    /// Execution time with overheads.
    pub wcet: Time,
    /// The overheads in `wcet`.
    pub overhead: Time,
    /// Best-case response time (best-case execution, no interference).
    pub bcrt: Time,
    /// Blocking used.
    pub blocking: Time,
    /// Release jitter used (own plus inherited).
    pub jitter: Time,
    /// The bound.
    pub bound: Bound,
    /// Its WCRT is checked against its deadline: all but a script's engine row, whose analysed response (its
    /// job's whole response as jitter, then its own window) places its interference and is not its completion:
    /// the engine does a script's work while the job is suspended on it, so the job's own check covers it; and
    /// but the board's transmit task (`can_tx_task`) and its jobs (`can_tx[…]`), which have no deadline of their
    /// own: a late job loses no completion, and the transmit task's response is every message's queuing jitter
    /// (docs/analysis.md, "The transmit interrupt keeps no deadline"). Every row must still be bounded.
    pub deadline_checked: bool,
}

impl TaskResult {
    /// Worst-case response time, if bounded.
    pub fn wcrt(&self) -> Option<Time> {
        self.bound.as_ref().ok().map(|r| r.wcrt)
    }
    /// Bounded and, when its deadline is checked, within it.
    pub fn schedulable(&self) -> bool {
        self.wcrt()
            .is_some_and(|r| !self.deadline_checked || r <= self.deadline)
    }
    /// Deadline minus WCRT, µs (negative when missed); `None` when unbounded or its deadline is not checked.
    pub fn slack_us(&self) -> Option<f64> {
        self.wcrt()
            .filter(|_| self.deadline_checked)
            .map(|r| signed_us(self.deadline, r))
    }
}

/// The bus's results.
#[derive(Debug, Clone, PartialEq)]
pub struct BusResult {
    /// Bits per second.
    pub bitrate: u32,
    /// Bus utilisation Σ frames·C/T.
    pub utilisation: f64,
    /// Messages in model order.
    pub messages: Vec<MessageResult>,
}

/// One message's results.
#[derive(Debug, Clone, PartialEq)]
pub struct MessageResult {
    /// Message name.
    pub name: String,
    /// Identifier.
    pub id: u32,
    /// 29-bit identifier.
    pub extended: bool,
    /// Data bytes.
    pub dlc: u8,
    /// Frames per activation.
    pub frames: u32,
    /// Period.
    pub period: Time,
    /// Deadline.
    pub deadline: Time,
    /// Worst time of one frame.
    pub frame_time: Time,
    /// Best time of one frame.
    pub frame_time_best: Time,
    /// Blocking by one lower-priority frame.
    pub blocking: Time,
    /// Queuing jitter used (own, sender variation, transmit path).
    pub jitter: Time,
    /// Where queuing can start at the earliest after the activation (the sender's best response).
    pub offset: Time,
    /// The sender (`board/task`).
    pub sender: Option<String>,
    /// The bus part of the bound (from the earliest queuing instant).
    pub bound: Bound,
    /// Best-case delivery after the activation.
    pub bcrt: Time,
}

impl MessageResult {
    /// Worst-case delivery after the activation (the sender's activation when linked).
    pub fn wcrt(&self) -> Option<Time> {
        // A sum that does not fit is no bound (never a saturated one).
        self.bound
            .as_ref()
            .ok()
            .and_then(|r| self.offset.checked_plus(r.wcrt))
    }
    /// Bounded and within its deadline.
    pub fn schedulable(&self) -> bool {
        self.wcrt().is_some_and(|r| r <= self.deadline)
    }
    /// Deadline minus WCRT, µs.
    pub fn slack_us(&self) -> Option<f64> {
        self.wcrt().map(|r| signed_us(self.deadline, r))
    }
}

/// A topic end to end: sender activation, bus, receiver.
#[derive(Debug, Clone, PartialEq)]
pub struct TopicResult {
    /// The message name.
    pub name: String,
    /// Sender `board/task`.
    pub sender: Option<String>,
    /// Receiver `board/task`.
    pub receiver: Option<String>,
    /// Period.
    pub period: Time,
    /// Best case.
    pub best: Time,
    /// Worst case, if bounded.
    pub worst: Option<Time>,
    /// End-to-end deadline.
    pub deadline: Time,
    /// Jitter budget.
    pub jitter_budget: Option<Time>,
}

impl TopicResult {
    /// Worst minus best.
    pub fn jitter(&self) -> Option<Time> {
        self.worst.map(|w| w.minus(self.best))
    }
    /// Deadline minus worst, µs.
    pub fn slack_us(&self) -> Option<f64> {
        self.worst.map(|w| signed_us(self.deadline, w))
    }
    /// Budget minus jitter, µs.
    pub fn budget_left_us(&self) -> Option<f64> {
        match (self.jitter_budget, self.jitter()) {
            (Some(budget), Some(jitter)) => Some(signed_us(budget, jitter)),
            _ => None,
        }
    }
    /// The worst case meets the deadline.
    pub fn deadline_met(&self) -> bool {
        self.worst.is_some_and(|w| w <= self.deadline)
    }
    /// The jitter stays within the budget (or there is none).
    pub fn budget_met(&self) -> bool {
        match self.jitter_budget {
            None => self.worst.is_some(),
            Some(budget) => self.jitter().is_some_and(|j| j <= budget),
        }
    }
    /// Both.
    pub fn ok(&self) -> bool {
        self.deadline_met() && self.budget_met()
    }
}

fn signed_us(a: Time, b: Time) -> f64 {
    (a.as_ns() as f64 - b.as_ns() as f64) / 1000.0
}

impl Analysis {
    /// Everything bounded, every deadline and every jitter budget met.
    pub fn all_ok(&self) -> bool {
        self.failures().is_empty()
    }

    /// What fails, as `board/task`, `bus/message`, `topic/name (deadline|jitter budget)`.
    pub fn failures(&self) -> Vec<String> {
        self.failing()
            .into_iter()
            .map(|f| format!("{}{}", f.what, f.suffix))
            .collect()
    }

    /// [`Analysis::failures`] with each one's figure against its limit: `diwheeldrive/can_tx WCRT 515.6 of
    /// 158 µs`, `bus/m unbounded`, `topic/gyroscope jitter 1057.4 of 1000 µs`, `topic/t end to end 2100 of
    /// 2000 µs`; the same failures in the same order.
    pub fn failure_figures(&self) -> Vec<String> {
        self.failing().into_iter().map(|f| f.figure()).collect()
    }

    /// Every failure once, in the report's order: tasks, messages, topics (deadline, then jitter budget).
    fn failing(&self) -> Vec<Failure> {
        let failure = |what: String, suffix, quantity, value, limit| Failure {
            what,
            suffix,
            quantity,
            value,
            limit,
        };
        let mut out = Vec::new();
        for b in &self.boards {
            for t in b.tasks.iter().filter(|t| !t.schedulable()) {
                let what = format!("{}/{}", b.name, t.name);
                out.push(failure(what, "", "WCRT", t.wcrt(), t.deadline));
            }
        }
        if let Some(bus) = &self.bus {
            for m in bus.messages.iter().filter(|m| !m.schedulable()) {
                let what = format!("bus/{}", m.name);
                out.push(failure(what, "", "WCRT", m.wcrt(), m.deadline));
            }
        }
        for topic in &self.topics {
            let what = format!("topic/{}", topic.name);
            if !topic.deadline_met() {
                let suffix = " (end-to-end deadline)";
                out.push(failure(
                    what.clone(),
                    suffix,
                    "end to end",
                    topic.worst,
                    topic.deadline,
                ));
            }
            if let Some(budget) = topic.jitter_budget.filter(|_| !topic.budget_met()) {
                let suffix = " (jitter budget)";
                out.push(failure(what, suffix, "jitter", topic.jitter(), budget));
            }
        }
        out
    }
}

/// One failure of an analysis: what fails, and its figure against its limit.
struct Failure {
    /// `board/task`, `bus/message` or `topic/name`.
    what: String,
    /// Which limit a topic breaks, as [`Analysis::failures`] names it (` (jitter budget)`), or empty.
    suffix: &'static str,
    /// `WCRT`, `end to end`, `jitter`.
    quantity: &'static str,
    value: Option<Time>,
    limit: Time,
}

impl Failure {
    fn figure(&self) -> String {
        match self.value {
            Some(v) => format!("{} {} {v} of {} µs", self.what, self.quantity, self.limit),
            None => format!("{} unbounded", self.what),
        }
    }
}

/// Analyses the whole system under `options`, on the sound transmit path (docs/analysis.md, "The sound transmit
/// path: the design"): the bus by [`bus_analysis::analyse`], each transmit job with its board's transmit-interrupt
/// response as a second releaser ([`board_analysis::Release::also`]).
pub fn analyse(system: &System, options: &Options) -> Analysis {
    analyse_with_progress(system, options, &mut |_| {})
}

/// [`analyse`], telling `progress` what it starts (one line per board and one for the bus), so that a front end
/// can show a large model's progress.
pub fn analyse_with_progress(
    system: &System,
    options: &Options,
    progress: &mut dyn FnMut(&str),
) -> Analysis {
    let limits = Limits {
        horizon: options.horizon.unwrap_or_else(|| default_horizon(system)),
        ..Limits::default()
    };
    let boards: Vec<BoardResult> = system
        .boards
        .iter()
        .map(|b| {
            progress(&format!("board {} ({} tasks)", b.name, b.tasks.len()));
            analyse_board(b, &limits)
        })
        .collect();
    let bus = system.bus.as_ref().map(|bus| {
        progress(&format!(
            "CAN bus, {} ({} messages)",
            options.frame_cost.label(),
            bus.messages.len()
        ));
        analyse_bus(system, bus, &boards, options.frame_cost, &limits)
    });
    let topics = match (&system.bus, &bus) {
        (Some(spec), Some(result)) => topics(system, spec, result, &boards),
        _ => Vec::new(),
    };
    Analysis {
        name: system.name.clone(),
        frame_cost: options.frame_cost,
        boards,
        bus,
        topics,
    }
}

fn default_horizon(system: &System) -> Time {
    let longest = system
        .boards
        .iter()
        .flat_map(|b| b.tasks.iter().map(|t| t.period.max_of(t.deadline)))
        .chain(
            system
                .bus
                .iter()
                .flat_map(|bus| bus.messages.iter().map(|m| m.period.max_of(m.deadline))),
        )
        .max()
        .unwrap_or(Time::ZERO);
    longest.times(1000).max_of(Time::from_us(60_000_000))
}

/// Analyses one board on its own: the model's tasks with their overheads, SRP blockings and release chains, by
/// [`board_analysis::analyse`] (the analysis the boards' admission check runs), every task's whole record kept.
/// Each transmit job takes its board's transmit-interrupt response into its release jitter beside its releaser's
/// ([`board_analysis::Release::also`]).
pub fn analyse_board(board: &BoardSystem, limits: &Limits) -> BoardResult {
    let costs: Vec<Time> = board
        .tasks
        .iter()
        .map(|t| t.wcet.plus(board.overheads.for_kind(t.kind)))
        .collect();
    let blocking = task_blockings(board);
    // A board without scripts is analysed exactly as before the sensor buses existed.
    let (bounds, jitter, sensor_buses) = if board.sensor_buses.scripts.is_empty() {
        let (bounds, jitter) = task_bounds(board, &costs, &blocking, limits);
        (bounds, jitter, Vec::new())
    } else {
        crate::sensor_bus::analyse(board, &costs, &blocking, limits)
    };
    let utilisation = board
        .tasks
        .iter()
        .zip(&costs)
        .map(|(t, c)| c.as_ns() as f64 / t.period.as_ns().max(1) as f64)
        .sum();
    let tasks = board
        .tasks
        .iter()
        .enumerate()
        .map(|(i, t)| TaskResult {
            name: t.name.clone(),
            job_of: t.job_of.clone(),
            priority: t.priority,
            kind: t.kind,
            sporadic: t.sporadic,
            period: t.period,
            deadline: t.deadline,
            wcet: costs.get(i).copied().unwrap_or(t.wcet),
            overhead: board.overheads.for_kind(t.kind),
            bcrt: t.bcet,
            blocking: blocking.get(i).copied().unwrap_or(Time::ZERO),
            jitter: jitter.get(i).copied().unwrap_or(t.jitter),
            deadline_checked: !board.is_transmit(i)
                && !board.sensor_buses.scripts.iter().any(|s| s.engine_row == i),
            bound: bounds
                .get(i)
                .cloned()
                .unwrap_or(Err(Unbounded::NoConvergence)),
        })
        .collect();
    BoardResult {
        name: board.name.clone(),
        utilisation,
        tasks,
        sensor_buses,
    }
}

/// Each task's blocking (model order): its own from the model, or SRP's from the critical sections, with the
/// ceilings resolved from who uses what ("interrupts disabled" is above everyone).
fn task_blockings(board: &BoardSystem) -> Vec<Time> {
    let sections = critical_sections(board);
    let srp = srp_blockings(
        &board.tasks.iter().map(|t| t.priority).collect::<Vec<_>>(),
        &sections,
    );
    board
        .tasks
        .iter()
        .zip(&srp)
        .map(|(t, computed)| t.blocking.unwrap_or(*computed))
        .collect()
}

/// Every critical section of the board (its tasks' and idle's) with its resource's ceiling resolved.
pub(crate) fn critical_sections(board: &BoardSystem) -> Vec<CriticalSection> {
    // A sorted vector, not a hash map: the per-call set-up dominates small boards (docs/analysis.md, benchmark).
    let mut ceilings: Vec<(&str, u32)> = board
        .static_ceilings
        .iter()
        .map(|(r, c)| (r.as_str(), *c))
        .chain(board.tasks.iter().flat_map(|t| {
            t.sections
                .iter()
                .map(move |(r, _)| (r.as_str(), t.priority))
        }))
        .collect();
    ceilings.sort_unstable();
    let ceiling_of = |resource: &str| -> u32 {
        if resource == GLOBAL_CRITICAL_SECTION {
            return u32::MAX;
        }
        // The last entry of the resource's run holds its largest value.
        let end = ceilings.partition_point(|(r, _)| *r <= resource);
        match end.checked_sub(1).and_then(|i| ceilings.get(i)) {
            Some((r, c)) if *r == resource => *c,
            _ => 0,
        }
    };
    let held = board
        .tasks
        .iter()
        .flat_map(|t| t.sections.iter().map(move |s| (t.priority, s)))
        .chain(board.idle_sections.iter().map(|s| (0, s)));
    held.map(|(holder_priority, (resource, length))| CriticalSection {
        holder_priority,
        ceiling: ceiling_of(resource),
        length: *length,
    })
    .collect()
}

/// A board's tasks as [`board_analysis`] reads them: in priority order (highest first, ties in model order).
pub(crate) struct SortedTasks {
    /// Model index per sorted position.
    pub(crate) order: Vec<usize>,
    /// Per sorted position: how it is released (the releaser at `usize::MAX` when the model names none that
    /// exists), and where its level ends.
    pub(crate) release: Vec<Option<board_analysis::Release>>,
    level_end: Vec<usize>,
}

impl board_analysis::Jobs for SortedTasks {
    fn release(&self, p: usize) -> Option<board_analysis::Release> {
        self.release.get(p).copied().flatten()
    }
    fn level_end(&self, p: usize) -> usize {
        self.level_end.get(p).copied().unwrap_or(0)
    }
    fn verdict_only(&self, _: usize) -> Option<Time> {
        // The report reads every task's bound.
        None
    }
}

/// Why a task has no bound, as [`board_analysis`] says it (the report names the releaser afterwards).
#[derive(Debug, Clone, Copy)]
enum NoBound {
    Analysis(AnalysisError),
    Inherited(board_analysis::Unbound),
}

/// Per sorted position: the task's whole record, or why it has none.
struct Records(Vec<Result<Response, NoBound>>);

impl board_analysis::JobBounds for Records {
    const WHOLE_RECORDS: bool = true;
    fn put(&mut self, p: usize, result: Result<Response, AnalysisError>) {
        if let Some(slot) = self.0.get_mut(p) {
            *slot = result.map_err(NoBound::Analysis);
        }
    }
    fn put_closed_form(&mut self, p: usize, wcrt: Time, first_window: Time) {
        // Not called for whole records; kept as the one-instance record a closed form stands for.
        self.put(
            p,
            Ok(Response {
                wcrt,
                worst_instance: 0,
                instances: 1,
                busy_window: first_window,
                interference: Time::ZERO,
                first_window,
                iterations: 0,
            }),
        );
    }
    fn put_unbound(&mut self, p: usize, why: board_analysis::Unbound) {
        if let Some(slot) = self.0.get_mut(p) {
            *slot = Err(NoBound::Inherited(why));
        }
    }
    fn wcrt(&self, p: usize) -> Option<Time> {
        self.0.get(p)?.as_ref().ok().map(|r| r.wcrt)
    }
    fn first_window(&self, p: usize) -> Option<Time> {
        self.0.get(p)?.as_ref().ok().map(|r| r.first_window)
    }
}

/// The tasks of [`SortedTasks`] with some releases cut (a view of the sensor buses' rounds sets those jobs'
/// jitters itself). A cut job with a second releaser (a transmit job's transmit interrupt) keeps that one, on the
/// jitter the view set (`cut_jitters`, the rounds' `Work::own` of a default-view job): the view sets what its first
/// releaser adds, never the transmit response.
struct CutReleases<'a> {
    sorted: &'a SortedTasks,
    cut: ViewCut<'a>,
}

/// What a view of the sensor buses' rounds cuts: per sorted position whether it sets the job's jitter itself (its
/// release cut), and for a cut default-view job that jitter (the rounds' `Work::own`).
#[derive(Clone, Copy)]
pub(crate) struct ViewCut<'a> {
    pub(crate) unreleased: &'a [bool],
    pub(crate) jitters: &'a [Time],
}

impl board_analysis::Jobs for CutReleases<'_> {
    fn release(&self, p: usize) -> Option<board_analysis::Release> {
        let release = self.sorted.release(p)?;
        if !self.cut.unreleased.get(p).copied().unwrap_or(false) {
            return Some(release);
        }
        Some(board_analysis::Release {
            by: release.also?,
            also: None,
            own_jitter: self.cut.jitters.get(p).copied().unwrap_or(Time::ZERO),
        })
    }
    fn level_end(&self, p: usize) -> usize {
        self.sorted.level_end(p)
    }
    fn verdict_only(&self, _: usize) -> Option<Time> {
        None
    }
}

/// One view of the sensor buses' rounds ([`crate::suspension_analysis`]): the sorted tasks' `timings` (their
/// jitters as the view sets them, found ones left in place) analysed by [`board_analysis::analyse`], the jobs
/// `cut` marks with their releases cut (a cut transmit job on the jitter `cut` holds for it, its transmit
/// interrupt's response added); every task's bound per sorted position.
pub(crate) fn view_bounds(
    board: &BoardSystem,
    sorted: &SortedTasks,
    timings: &mut [TaskTiming],
    blocking: &[Time],
    shares: &[Share],
    cut: ViewCut<'_>,
    limits: &Limits,
) -> Vec<Bound> {
    let n = timings.len();
    let mut scratch = vec![Counter::default(); n];
    let mut records = Records(vec![
        Err(NoBound::Inherited(
            board_analysis::Unbound::NoConvergence
        ));
        n
    ]);
    let jobs = board_analysis::BoardJobs {
        timings,
        blocking,
        shares,
        scratch: &mut scratch,
    };
    let cut = CutReleases { sorted, cut };
    // Per job, never out of a board's budget.
    let _ = board_analysis::analyse(
        jobs,
        &cut,
        &mut records,
        limits,
        board_analysis::IterationBudget::PerJob,
    );
    let name = |p: usize| {
        sorted
            .order
            .get(p)
            .and_then(|&i| board.tasks.get(i))
            .map_or("?", |t| t.name.as_str())
            .to_string()
    };
    records
        .0
        .iter()
        .enumerate()
        .map(|(p, record)| {
            (*record).map_err(|why| match why {
                NoBound::Inherited(board_analysis::Unbound::Releaser) => {
                    let by = board_analysis::Jobs::release(&cut, p).map_or(usize::MAX, |r| r.by);
                    Unbounded::Releaser(name(by))
                }
                other => no_bound(other),
            })
        })
        .collect()
}

/// Why a task has no bound, but for a releaser's name.
fn no_bound(why: NoBound) -> Unbounded {
    match why {
        NoBound::Analysis(e) => Unbounded::Analysis(e),
        NoBound::Inherited(board_analysis::Unbound::Overflow) => {
            Unbounded::Analysis(AnalysisError::Overflow)
        }
        NoBound::Inherited(board_analysis::Unbound::NoConvergence) => Unbounded::NoConvergence,
        NoBound::Inherited(board_analysis::Unbound::Releaser) => Unbounded::Releaser("?".into()),
    }
}

/// Every task's bound and the release jitter it was found with (own plus inherited), in model order.
fn task_bounds(
    board: &BoardSystem,
    costs: &[Time],
    blocking: &[Time],
    limits: &Limits,
) -> (Vec<Bound>, Vec<Time>) {
    let jitters: Vec<Time> = board.tasks.iter().map(|t| t.jitter).collect();
    let releases: Vec<Option<usize>> = board.tasks.iter().map(|t| t.released_by).collect();
    let sorted = sort_tasks(board, &jitters, &releases);
    task_bounds_in(board, costs, blocking, &jitters, &releases, &sorted, limits)
}

/// [`task_bounds`] with each task's own release jitter and releaser given (model order).
fn task_bounds_in(
    board: &BoardSystem,
    costs: &[Time],
    blocking: &[Time],
    jitters: &[Time],
    releases: &[Option<usize>],
    sorted: &SortedTasks,
    limits: &Limits,
) -> (Vec<Bound>, Vec<Time>) {
    let n = board.tasks.len();
    let mut timings: Vec<TaskTiming> = sorted
        .order
        .iter()
        .map(|&i| TaskTiming {
            priority: board.tasks.get(i).map_or(0, |t| t.priority),
            wcet: costs.get(i).copied().unwrap_or(Time::ZERO),
            period: board.tasks.get(i).map_or(Time::ZERO, |t| t.period),
            jitter: jitters.get(i).copied().unwrap_or(Time::ZERO),
        })
        .collect();
    let sorted_blocking: Vec<Time> = sorted
        .order
        .iter()
        .map(|&i| blocking.get(i).copied().unwrap_or(Time::ZERO))
        .collect();
    let shares: Vec<Share> = timings
        .iter()
        .map(|t| Share::of(t.wcet, t.period))
        .collect();
    let mut scratch = vec![Counter::default(); n];
    let mut records = Records(vec![
        Err(NoBound::Inherited(
            board_analysis::Unbound::NoConvergence
        ));
        n
    ]);
    let jobs = board_analysis::BoardJobs {
        timings: &mut timings,
        blocking: &sorted_blocking,
        shares: &shares,
        scratch: &mut scratch,
    };
    // Per job, never out of a board's budget.
    let _ = board_analysis::analyse(
        jobs,
        sorted,
        &mut records,
        limits,
        board_analysis::IterationBudget::PerJob,
    );
    let mut bounds: Vec<Bound> = vec![Err(Unbounded::NoConvergence); n];
    let mut jitter: Vec<Time> = jitters.to_vec();
    for (p, &i) in sorted.order.iter().enumerate() {
        let (Some(slot), Some(record), Some(j), Some(timing)) = (
            bounds.get_mut(i),
            records.0.get(p),
            jitter.get_mut(i),
            timings.get(p),
        ) else {
            continue;
        };
        *j = timing.jitter;
        *slot = (*record).map_err(|why| match why {
            NoBound::Analysis(e) => Unbounded::Analysis(e),
            NoBound::Inherited(board_analysis::Unbound::Overflow) => {
                Unbounded::Analysis(AnalysisError::Overflow)
            }
            NoBound::Inherited(board_analysis::Unbound::NoConvergence) => Unbounded::NoConvergence,
            NoBound::Inherited(board_analysis::Unbound::Releaser) => {
                let releaser = releases.get(i).copied().flatten();
                let name = releaser
                    .and_then(|r| board.tasks.get(r))
                    .map_or("?", |t| t.name.as_str());
                Unbounded::Releaser(name.to_string())
            }
        });
    }
    (bounds, jitter)
}

/// The board's tasks in priority order (highest first; ties keep model order), with what the analysis reads of
/// each.
pub(crate) fn sort_tasks(
    board: &BoardSystem,
    jitters: &[Time],
    releases: &[Option<usize>],
) -> SortedTasks {
    let n = board.tasks.len();
    let priority = |i: usize| board.tasks.get(i).map_or(0, |t| t.priority);
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by_key(|&i| std::cmp::Reverse(priority(i)));
    let mut position = vec![usize::MAX; n];
    for (p, &i) in order.iter().enumerate() {
        if let Some(slot) = position.get_mut(i) {
            *slot = p;
        }
    }
    // A transmit job (a released job of the transmit interrupt) has the transmit interrupt as its second
    // releaser: the abort its frames cause is asked in one of its jobs (the sound transmit path).
    let second = |i: usize| match board.can_tx_task {
        Some(tx) if tx != i && board.is_transmit(i) => {
            Some(position.get(tx).copied().unwrap_or(usize::MAX))
        }
        _ => None,
    };
    let release = order
        .iter()
        .map(|&i| {
            let r = releases.get(i).copied().flatten()?;
            Some(board_analysis::Release {
                by: position.get(r).copied().unwrap_or(usize::MAX),
                also: second(i),
                own_jitter: jitters.get(i).copied().unwrap_or(Time::ZERO),
            })
        })
        .collect();
    let mut level_end = vec![n; n];
    let mut end = n;
    for p in (0..n).rev() {
        let here = order.get(p).map(|&i| priority(i));
        let next = order.get(p + 1).map(|&i| priority(i));
        if next.is_some() && here != next {
            end = p + 1;
        }
        if let Some(slot) = level_end.get_mut(p) {
            *slot = end;
        }
    }
    SortedTasks {
        order,
        release,
        level_end,
    }
}

/// [`board::srp_blocking`] for every priority in one sweep (upwards through the priorities, a max-heap of the
/// sections whose holder is below, dropping those whose ceiling the sweep has passed): O((n + s) log s) instead
/// of O(n·s).
fn srp_blockings(priorities: &[u32], sections: &[CriticalSection]) -> Vec<Time> {
    // Small boards: the definition directly, without the sweep's sorting, heap and map.
    if priorities.len().saturating_mul(sections.len()) <= 4096 {
        return priorities
            .iter()
            .map(|&p| board::srp_blocking(p, sections))
            .collect();
    }
    srp_sweep(priorities, sections)
}

fn srp_sweep(priorities: &[u32], sections: &[CriticalSection]) -> Vec<Time> {
    let mut by_holder: Vec<&CriticalSection> = sections.iter().collect();
    by_holder.sort_by_key(|cs| cs.holder_priority);
    let mut levels: Vec<u32> = priorities.to_vec();
    levels.sort_unstable();
    levels.dedup();
    let mut heap: BinaryHeap<(Time, u32)> = BinaryHeap::new();
    let mut next = 0;
    let mut per_level: HashMap<u32, Time> = HashMap::with_capacity(levels.len());
    for &p in &levels {
        while let Some(cs) = by_holder.get(next).filter(|cs| cs.holder_priority < p) {
            heap.push((cs.length, cs.ceiling));
            next += 1;
        }
        // Ceilings below p can never block p or anything above it again.
        while heap.peek().is_some_and(|&(_, ceiling)| ceiling < p) {
            heap.pop();
        }
        per_level.insert(p, heap.peek().map_or(Time::ZERO, |&(length, _)| length));
    }
    priorities
        .iter()
        .map(|p| per_level.get(p).copied().unwrap_or(Time::ZERO))
        .collect()
}

fn task_name(system: &System, r: TaskRef) -> String {
    let board = system.boards.get(r.board);
    format!(
        "{}/{}",
        board.map_or("?", |b| b.name.as_str()),
        board
            .and_then(|b| b.tasks.get(r.task))
            .map_or("?", |t| t.name.as_str())
    )
}

fn task_result(boards: &[BoardResult], r: TaskRef) -> Option<&TaskResult> {
    boards.get(r.board).and_then(|b| b.tasks.get(r.task))
}

/// What the bus analysis reads of message `m`'s sender: its sending task's bounds and its board's transmit
/// interrupt's, or the name of the one that has no bound.
fn sender_of(
    system: &System,
    boards: &[BoardResult],
    m: &crate::model::MessageSpec,
) -> Result<bus_analysis::Sender, String> {
    let Some(s) = m.sender else {
        return Ok(bus_analysis::Sender::Outside);
    };
    // An unbounded sender is named before its transmit interrupt.
    let sender = task_result(boards, s);
    let (worst, best) = sender
        .and_then(|r| r.wcrt().map(|w| (w, r.bcrt)))
        .ok_or_else(|| task_name(system, s))?;
    let tx = system
        .boards
        .get(s.board)
        .and_then(|b| b.can_tx_task)
        .filter(|&t| t != s.task)
        .map(|t| TaskRef {
            board: s.board,
            task: t,
        });
    let tx = match tx {
        None => Time::ZERO,
        Some(t) => task_result(boards, t)
            .and_then(|r| r.wcrt())
            .ok_or_else(|| task_name(system, t))?,
    };
    Ok(bus_analysis::Sender::Bounded { worst, best, tx })
}

/// The bus, by [`bus_analysis::analyse`] (the bounds of the boards' admission check's
/// [`bus_analysis::analyse_each`]), with the senders' bounds from `boards`.
fn analyse_bus(
    system: &System,
    bus: &BusSystem,
    boards: &[BoardResult],
    frame_cost: FrameCostSpec,
    limits: &Limits,
) -> BusResult {
    let cost = frame_cost.cost();
    let bit = bus.bit_time;
    let n = bus.messages.len();
    let senders: Vec<Result<bus_analysis::Sender, String>> = bus
        .messages
        .iter()
        .map(|m| sender_of(system, boards, m))
        .collect();
    let message = |i: usize| {
        let m = bus.messages.get(i)?;
        Some(bus_analysis::Message {
            id: m.id,
            extended: m.extended,
            dlc: m.dlc,
            frames: m.frames,
            period: m.period,
            jitter: m.jitter,
            sender: match senders.get(i)? {
                Ok(sender) => *sender,
                Err(_) => bus_analysis::Sender::Unbounded,
            },
        })
    };
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by_key(|&i| {
        bus.messages
            .get(i)
            .map_or(u32::MAX, |m| can::arbitration_key(m.id, m.extended))
    });
    let mut timings = vec![
        MessageTiming {
            key: u32::MAX,
            frame_time: Time::ZERO,
            frames: 1,
            period: Time::ZERO,
            jitter: Time::ZERO,
        };
        n
    ];
    let mut offsets = vec![None; n];
    let mut sorted_blocking = vec![Time::ZERO; n];
    let mut scratch = vec![Counter::default(); n];
    let mut out = vec![Err(AnalysisError::NoSuchIndex); n];
    let work = bus_analysis::BusWork {
        order: &order,
        timings: &mut timings,
        offsets: &mut offsets,
        blockings: &mut sorted_blocking,
        scratch: &mut scratch,
    };
    bus_analysis::analyse(message, work, cost, bit, limits, out.as_mut_slice());
    let mut messages: Vec<MessageResult> = Vec::with_capacity(n);
    let mut position = vec![0; n];
    for (p, &i) in order.iter().enumerate() {
        if let Some(slot) = position.get_mut(i) {
            *slot = p;
        }
    }
    for (i, m) in bus.messages.iter().enumerate() {
        let p = position.get(i).copied().unwrap_or(0);
        let timing = timings.get(p);
        let best = can::frame_time_best(cost, m.dlc, m.extended, bit);
        let off = offsets.get(p).copied().flatten().unwrap_or(Time::ZERO);
        let bound = match senders.get(i) {
            Some(Err(name)) => Err(Unbounded::Sender(name.clone())),
            _ => out
                .get(p)
                .copied()
                .unwrap_or(Err(AnalysisError::NoSuchIndex))
                .map_err(Unbounded::Analysis),
        };
        messages.push(MessageResult {
            name: m.name.clone(),
            id: m.id,
            extended: m.extended,
            dlc: m.dlc,
            frames: m.frames,
            period: m.period,
            deadline: m.deadline,
            frame_time: timing.map_or(Time::ZERO, |t| t.frame_time),
            frame_time_best: best,
            blocking: sorted_blocking.get(p).copied().unwrap_or(Time::ZERO),
            jitter: timing.map_or(m.jitter, |t| t.jitter),
            offset: off,
            sender: m.sender.map(|s| task_name(system, s)),
            bound,
            bcrt: off.plus(best.times(u64::from(m.frames))),
        });
    }
    BusResult {
        bitrate: bus.bitrate,
        utilisation: can::utilisation(&timings),
        messages,
    }
}

fn topics(
    system: &System,
    spec: &BusSystem,
    bus: &BusResult,
    boards: &[BoardResult],
) -> Vec<TopicResult> {
    spec.messages
        .iter()
        .zip(&bus.messages)
        .map(|(m, result)| {
            let receiver = m.receiver.and_then(|r| task_result(boards, r));
            let worst = match (result.wcrt(), m.receiver) {
                (Some(w), None) => Some(w),
                (Some(w), Some(_)) => receiver
                    .and_then(|r| r.wcrt())
                    .and_then(|rw| w.checked_plus(rw)),
                (None, _) => None,
            };
            let best = result.bcrt.plus(receiver.map_or(Time::ZERO, |r| r.bcrt));
            TopicResult {
                name: m.name.clone(),
                sender: m.sender.map(|s| task_name(system, s)),
                receiver: m.receiver.map(|r| task_name(system, r)),
                period: m.period,
                best,
                worst,
                deadline: m.end_to_end_deadline(),
                jitter_budget: m.jitter_budget,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sweep_blocking_matches_the_definition() {
        // A small deterministic generator is enough to cover ties, idle holders and global sections.
        let mut seed = 0x1234_5678u64;
        let mut next = move |n: u64| {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 33) % n
        };
        for _ in 0..200 {
            let priorities: Vec<u32> = (0..1 + next(12)).map(|_| next(8) as u32).collect();
            let sections: Vec<CriticalSection> = (0..next(15))
                .map(|_| CriticalSection {
                    holder_priority: next(8) as u32,
                    ceiling: if next(10) == 0 {
                        u32::MAX
                    } else {
                        next(9) as u32
                    },
                    length: Time::from_ns(next(1000)),
                })
                .collect();
            let swept = srp_sweep(&priorities, &sections);
            assert_eq!(srp_blockings(&priorities, &sections), swept);
            let direct: Vec<Time> = priorities
                .iter()
                .map(|&p| board::srp_blocking(p, &sections))
                .collect();
            assert_eq!(swept, direct);
        }
    }
}
