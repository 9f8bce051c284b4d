//! Self-suspending jobs and the sensor buses (I2C): a job that runs a *script* on one of its board's sensor buses
//! hands the script to the bus's engine and suspends until the script ends (the engine: docs/i2c.md;
//! docs/analysis.md, "Self-suspending publishers and the sensor buses").
//!
//! * **The bus** serves one script at a time, start to end, the most urgent waiting one first (the submitting
//!   task's priority; equal priorities counted as higher): non-preemptive fixed priority, analysed with the CAN
//!   bus's machinery ([`can::response_times_into`]: one "frame" per script, its bus time). A script's release
//!   jitter is its submitting job's response; its blocking the longest lower-priority script. Its siblings (the
//!   other scripts of its RTIC task) are left out: they run one after the other, never while it is pending.
//! * **A job of several scripts** (`scripts`) submits each when the one before it has ended and its settle (the
//!   job's own wait, `settle_us`) has passed: each script is submitted within its job's response, so each keeps
//!   the job's response as its jitter.
//! * **The suspending job** is analysed suspension-oblivious for itself: its CPU plus, per script, its bus
//!   response (from submission), its settle and one more blocking per resumption (after the settle, after the
//!   script: a lower-priority critical section may start while it is suspended), all as if executed; or, where
//!   lower and within its period, by its CPU segments (its suspensions and settles plus, per segment, its CPU and
//!   the interference of its CPU's own window). The jobs of the same RTIC task (`job_of`) run one after the
//!   other, so for them the suspension is execution too.
//! * **Every other task** sees a suspending job as its CPU alone, released with jitter = its response minus its
//!   CPU (Chen, Nelissen, Huang et al., "Many suspensions, many problems", Real-Time Systems 55, 2019, §5;
//!   Bletsas et al., "Errata for three papers (2004-05) on fixed-priority scheduling with self-suspensions",
//!   LITES 5(1), 2018): the sound form of the jitter-based charge (jitter = the suspension alone is not).
//! * **The engine's interrupt** is a row per script at the engine's priority (`<bus>_engine[<task>]`, or
//!   `<bus>_engine[<task>#<n>]` for a job of several; added when the model is validated), released by the
//!   submitting job, costing the engine's charge by its parts ([`SensorBus::script_charge`]): the script's events
//!   times the per-event figure with interrupt entry and exit, the per-script part once (its end and its client's
//!   wake), and the condition wait once per START condition (an operation's start, a repeated START). The master
//!   holds SCL low while an event waits for the engine, so a script's bus time holds its events' time on the CPU:
//!   the lower of each event's own worst response (by what it carries: plain, with the wait, or the ending one)
//!   added per event, and the script as one job at the engine's priority over its whole bus time (the wire as
//!   execution, a blocking per event, each higher job counted once per window: suspension-oblivious). The app's
//!   tasks that are the engine's handlers ([`EngineModel::handlers`]) have no row of their own: the engine rows are
//!   their charge.
//!
//! The jitters feed the bus responses, which feed the jobs' responses, which are the jitters: iterated from zero
//! to a fixed point ([`MAX_ROUNDS`]), or the affected jobs are unbounded with the reason. The rounds are
//! [`suspension_analysis::analyse`], which the chip's check runs too; this module validates the model's buses and
//! scripts, says what the rounds read of the board, and keeps what they find for the report.

use std::collections::BTreeSet;
use std::fmt;

use serde::{Deserialize, Serialize};

use crate::analysis::{self, Bound, Unbounded};
use crate::board::{self, TaskTiming};
use crate::board_analysis;
use crate::busy_window::{AnalysisError, Counter, Limits, Response, Share};
use crate::can::{self, MessageTiming};
use crate::model::{BoardModel, OverheadTimes, TaskKind, TaskSpec};
use crate::suspension_analysis::{
    self, Budget, Engine, Failure, OnBus, ScriptJob, SuspendingBoard, Work,
};
use crate::time::Time;

/// Bit times one byte takes on an I2C bus: eight data bits and the acknowledge.
pub const BITS_PER_BYTE: u64 = 9;
/// Bit times a script's bytes form adds per (repeated) START: the START's hold and the STOP's set-up (or the
/// repeated START's), each within one bit time at 100 and 400 kHz (I2C-bus specification UM10204, table 10).
pub const BITS_PER_START: u64 = 2;
/// Rounds of the holistic iteration (jitters → bus responses → responses) before the affected jobs are declared
/// unbounded.
pub const MAX_ROUNDS: usize = 1000;

/// One sensor bus of a board, as the model and timing files state it.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SensorBusModel {
    /// Name (`i2c1`), which a script's `bus` names.
    pub name: String,
    /// SCL bits per second (400 000 for Fast mode).
    pub bitrate: u32,
    /// The engine's interrupt (I2Cx_EV and I2Cx_ER).
    pub engine: EngineModel,
}

/// The bus engine's interrupt.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct EngineModel {
    /// Its RTIC/NVIC logical priority.
    pub priority: u32,
    /// One event's execution, µs, interrupt entry and exit excluded (the board's overheads add them).
    pub per_event_us: f64,
    /// Whether `per_event_us` is an estimate or the machine code's bound; the report says which.
    pub per_event_from: PerEventFrom,
    /// Where the figure comes from.
    pub source: String,
    /// The per-script part, charged once per script: a script's end (its result stored, the next script
    /// started) and its client's wake, inside the event that ends it. Absent: 0 (the per-event figure covers it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub per_script: Option<EnginePart>,
    /// The condition wait (the handler's wait for the block's previous STOP or START to clear), charged once per
    /// START condition of a script — an operation's start and a repeated START, the events that take it (the
    /// script's `starts`) — and not in `per_event_us`. Absent: the per-event figure holds whatever wait there is.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub condition_wait: Option<EnginePart>,
    /// The app's tasks that are this engine's interrupt handlers (`I2C1_EV`, `I2C1_ER`): declared by the RTIC
    /// app at the engine's `priority`, they need no timing-file row and are charged only through the
    /// `<bus>_engine[<task>]` rows, one per script (docs/analysis.md, "Self-suspending publishers and the sensor
    /// buses").
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub handlers: Vec<String>,
}

/// One part of the engine's charge beside the per-event one (docs/analysis.md, "Self-suspending publishers and the
/// sensor buses"): its figure, whether an estimate or the machine code's bound, and its source.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct EnginePart {
    /// Its time, µs (≥ 0).
    pub us: f64,
    /// Whether `us` is an estimate or the machine code's bound.
    pub from: PerEventFrom,
    /// Where the figure comes from.
    pub source: String,
}

/// Where an engine's per-event figure comes from.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum PerEventFrom {
    /// A stated estimate (until the machine code bounds the engine's handler).
    Estimate,
    /// The machine code's bound of the handler.
    Bound,
}

impl PerEventFrom {
    /// As the report says it.
    pub fn label(self) -> &'static str {
        match self {
            PerEventFrom::Estimate => "estimate",
            PerEventFrom::Bound => "machine-code bound",
        }
    }
}

/// The script one job runs on a sensor bus: its bytes on the wire or its bus time, and the devices' stretches.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ScriptModel {
    /// The bus (a `sensor_buses` name of the board).
    pub bus: String,
    /// Bytes on the wire, address bytes included (each [`BITS_PER_BYTE`] bit times); or `bus_time_us`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bytes: Option<u32>,
    /// Its START conditions: an operation's start and each repeated START (with `bytes` default 1; each adds
    /// [`BITS_PER_START`] bit times). On an engine with a `condition_wait`, the events that take the wait; a script
    /// given by `bus_time_us` then states them (its wire time is the stated one), and otherwise it cannot.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub starts: Option<u32>,
    /// The script's time on the wire, µs; or `bytes`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bus_time_us: Option<f64>,
    /// Where `bytes` or `bus_time_us` comes from.
    pub source: String,
    /// The devices' stated clock-stretch allowance for the whole script, µs (0 for devices that never stretch).
    pub stretch_us: f64,
    /// Where the stretch allowance comes from (the devices' datasheets).
    pub stretch_source: String,
    /// Engine interrupts one script raises; with `bytes` it defaults to two per byte and two per START (every
    /// byte raises at most one TXE or RXNE and one BTF, every operation one SB and its end).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub events: Option<u32>,
    /// The job's own wait before it submits this script, µs (a device's bus-free time since the job's previous
    /// script on it: the bq27500's 66 µs); the bus is free for other clients meanwhile. Absent: none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub settle_us: Option<f64>,
    /// Where `settle_us` comes from (required with it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub settle_source: Option<String>,
    /// The time from the script's start by which its bus has ended it and is free again, µs: the
    /// script's deadline (the firmware's watch ends a script still on the bus then, wire time and an
    /// allowance per flag, `Failure::Stretched`), the watch's response and the bus clear after it.
    /// The stretch charged is then at most this less the wire time (docs/i2c.md, "A script's
    /// deadline"). Absent: the stated stretch in full.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub deadline_us: Option<f64>,
    /// Where `deadline_us` comes from (required with it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub deadline_source: Option<String>,
}

/// A board's validated sensor buses and the scripts its tasks run on them.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct BoardBuses {
    /// The buses in model order.
    pub buses: Vec<SensorBus>,
    /// One per task with a script, in task order.
    pub scripts: Vec<Script>,
}

/// A validated sensor bus.
#[derive(Debug, Clone, PartialEq)]
pub struct SensorBus {
    /// Name.
    pub name: String,
    /// SCL bits per second.
    pub bitrate: u32,
    /// One bit time, rounded up.
    pub bit_time: Time,
    /// The engine interrupt's priority.
    pub engine_priority: u32,
    /// One engine event's cost on the CPU: the per-event figure plus interrupt entry and exit.
    pub per_event: Time,
    /// Where the per-event figure comes from.
    pub per_event_from: PerEventFrom,
    /// Its source.
    pub source: String,
    /// The per-script part (a script's end and its client's wake), charged once per script, if stated.
    pub per_script: Option<Part>,
    /// The condition wait, charged once per START condition of a script, if stated as a part of its own (then a
    /// script counts its STARTs).
    pub condition_wait: Option<Part>,
}

/// A validated part of the engine's charge.
#[derive(Debug, Clone, PartialEq)]
pub struct Part {
    /// Its time, rounded up.
    pub time: Time,
    /// Whether it is an estimate or the machine code's bound.
    pub from: PerEventFrom,
    /// Its source.
    pub source: String,
}

/// A part's time, 0 if not stated.
fn part_time(part: Option<&Part>) -> Time {
    part.map_or(Time::ZERO, |p| p.time)
}

impl SensorBus {
    /// The engine's charge for one script ([`Engine::charge`]): `events × per_event` (each with the interrupt's
    /// entry and exit), plus the per-script part once, plus the condition wait once per START condition.
    pub fn script_charge(&self, script: &Script) -> Time {
        self.engine(Time::ZERO).charge(script.events, script.starts)
    }

    /// Its engine as the rounds read it ([`suspension_analysis`]), with the SRP `blocking` at its priority.
    pub fn engine(&self, blocking: Time) -> Engine {
        Engine {
            priority: self.engine_priority,
            per_event: self.per_event,
            per_script: part_time(self.per_script.as_ref()),
            condition_wait: part_time(self.condition_wait.as_ref()),
            blocking,
        }
    }
}

/// A validated script.
#[derive(Debug, Clone, PartialEq)]
pub struct Script {
    /// The submitting task (model index).
    pub task: usize,
    /// The bus (index into [`BoardBuses::buses`]).
    pub bus: usize,
    /// Its time on the wire.
    pub wire: Time,
    /// The devices' stretch allowance.
    pub stretch: Time,
    /// Engine events one script raises.
    pub events: u32,
    /// Its START conditions (operation starts and repeated STARTs): the events that take the engine's condition
    /// wait. From `starts` (with `bytes`, default 1); 0 for a script by `bus_time_us` on an engine without a
    /// stated wait.
    pub starts: u32,
    /// The engine row charged per script (model index of the added task).
    pub engine_row: usize,
    /// Its place in its job's scripts (0: the first; a job of one script has only 0).
    pub position: usize,
    /// How many scripts its job runs.
    pub of: usize,
    /// The job's wait before submitting it (suspension, not bus time).
    pub settle: Time,
}

/// Why a board's sensor buses or a script are refused.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SensorBusError {
    /// A script names a bus the board does not state.
    UnknownBus(String),
    /// Two buses have one name.
    BusTwice(String),
    /// A name that is empty or holds `/`, `[` or `]`.
    BadName(String),
    /// A figure that must be positive is not (the figure as written).
    NotPositive(String),
    /// A figure that must be finite and at least 0 is not.
    Negative(String),
    /// A stated figure without its source.
    NoSource,
    /// A script with neither `bytes` nor `bus_time_us`, or with both.
    OneFigure,
    /// `starts` without `bytes`, on an engine that states no condition wait.
    StartsWithoutBytes,
    /// A script by `bus_time_us` on an engine with a condition wait, without its `starts`.
    NoStarts,
    /// A script given as `bus_time_us` must state its `events`.
    NoEvents,
    /// The engine row's name is already a task's.
    RowTaken(String),
    /// A task or topic states both `script` and `scripts`.
    ScriptAndScripts,
    /// `scripts` is an empty list.
    NoScripts,
    /// `settle_source` without `settle_us`.
    SettleSourceAlone,
    /// An engine handler named twice (on one bus or two).
    HandlerTwice(String),
    /// An engine handler the app does not declare.
    UnknownHandler(String),
    /// An engine handler whose RTIC priority is not its engine's: (handler, its priority, the engine's).
    HandlerPriority(String, u32, u32),
    /// An engine handler that locks a resource a task above the engine also uses: (handler, resource, its
    /// ceiling). Its critical sections would block that task, and the handler has no row that states them.
    HandlerLocksAbove(String, String, u32),
    /// `engine.handlers` on a bus no script names: the handlers' tasks would lose their rows and be charged
    /// nowhere (the bus's name).
    HandlersWithoutScripts(String),
}

impl fmt::Display for SensorBusError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SensorBusError::UnknownBus(bus) => write!(f, "no sensor bus `{bus}` on this board"),
            SensorBusError::BusTwice(bus) => write!(f, "sensor bus `{bus}` is stated twice"),
            SensorBusError::BadName(name) => {
                write!(
                    f,
                    "`{name}`: a bus name must be non-empty, without `/`, `[` or `]`"
                )
            }
            SensorBusError::NotPositive(v) => write!(f, "must be a finite number > 0, got {v}"),
            SensorBusError::Negative(v) => write!(f, "must be a finite number ≥ 0, got {v}"),
            SensorBusError::NoSource => f.write_str("a stated figure needs its source"),
            SensorBusError::OneFigure => {
                f.write_str("a script states exactly one of `bytes` and `bus_time_us`")
            }
            SensorBusError::StartsWithoutBytes => f.write_str(
                "`starts` goes with `bytes`, or with an engine that states its `condition_wait`",
            ),
            SensorBusError::NoStarts => f.write_str(
                "a script given by `bus_time_us` on an engine with a `condition_wait` states its `starts`",
            ),
            SensorBusError::NoEvents => {
                f.write_str("a script given by `bus_time_us` states its engine `events`")
            }
            SensorBusError::RowTaken(name) => {
                write!(f, "the engine row `{name}` is already a task's name")
            }
            SensorBusError::ScriptAndScripts => {
                f.write_str("state either one `script` or the list `scripts`, not both")
            }
            SensorBusError::NoScripts => {
                f.write_str("`scripts` lists at least one script (or leave it out)")
            }
            SensorBusError::SettleSourceAlone => f.write_str("`settle_source` goes with `settle_us`"),
            SensorBusError::HandlersWithoutScripts(bus) => write!(
                f,
                "`{bus}` names engine handlers but no script runs on it: they would be charged nowhere"
            ),
            SensorBusError::HandlerTwice(name) => {
                write!(f, "`{name}` is named as an engine handler twice")
            }
            SensorBusError::UnknownHandler(name) => {
                write!(f, "engine handler `{name}` is not a task of the app")
            }
            SensorBusError::HandlerLocksAbove(name, resource, ceiling) => write!(
                f,
                "engine handler `{name}` locks `{resource}`, whose ceiling {ceiling} is above its engine: its \
                 critical sections would block a task the analysis does not charge them to"
            ),
            SensorBusError::HandlerPriority(name, got, engine) => write!(
                f,
                "engine handler `{name}` runs at RTIC priority {got}, its engine at {engine}: they must be one"
            ),
        }
    }
}

impl std::error::Error for SensorBusError {}

/// A refusal and the field it is about, relative to the board (`tasks[3].script.bus`).
pub type Refusal = (String, SensorBusError);

fn positive(value: f64, field: String) -> Result<(), Refusal> {
    if value.is_finite() && value > 0.0 && value <= Time::LIMIT_US {
        Ok(())
    } else {
        Err((field, SensorBusError::NotPositive(value.to_string())))
    }
}

fn at_least_zero(value: f64, field: String) -> Result<(), Refusal> {
    if value.is_finite() && (0.0..=Time::LIMIT_US).contains(&value) {
        Ok(())
    } else {
        Err((field, SensorBusError::Negative(value.to_string())))
    }
}

/// A stated part of the engine's charge: its figure (≥ 0) and its source.
fn engine_part(part: Option<&EnginePart>, field: String) -> Result<Option<Part>, Refusal> {
    let Some(part) = part else {
        return Ok(None);
    };
    at_least_zero(part.us, format!("{field}.us"))?;
    sourced(&part.source, format!("{field}.source"))?;
    Ok(Some(Part {
        time: Time::from_us_up(part.us),
        from: part.from,
        source: part.source.clone(),
    }))
}

fn sourced(source: &str, field: String) -> Result<(), Refusal> {
    if source.trim().is_empty() {
        Err((field, SensorBusError::NoSource))
    } else {
        Ok(())
    }
}

/// Checks a board's buses and its tasks' scripts (the tasks validated into `tasks`, model order), and adds each
/// script's engine row to `tasks`.
pub fn validate_board(
    board: &BoardModel,
    overheads: &OverheadTimes,
    tasks: &mut Vec<TaskSpec>,
) -> Result<BoardBuses, Refusal> {
    let buses = validate_buses(&board.sensor_buses, overheads)?;
    let mut scripts = Vec::new();
    let mut rows = Vec::new();
    for (t, task) in board.tasks.iter().enumerate() {
        let job = job_scripts(
            task.script.as_ref(),
            task.scripts.as_deref(),
            &format!("tasks[{t}]"),
        )?;
        let of = job.len();
        for (position, (p, script)) in job.into_iter().enumerate() {
            let checked = validate_script(&buses, script, &p)?;
            let (Some(spec), Some(bus)) = (tasks.get(t), buses.get(checked.bus)) else {
                continue;
            };
            let name = engine_row_name(&bus.name, &spec.name, position, of);
            if board.tasks.iter().any(|o| o.name == name) {
                return Err((p, SensorBusError::RowTaken(name)));
            }
            rows.push(TaskSpec {
                name,
                priority: bus.engine_priority,
                wcet: bus.script_charge(&checked),
                bcet: Time::ZERO,
                period: spec.period,
                deadline: spec.period,
                deadline_follows_period: true,
                jitter: Time::ZERO,
                sections: Vec::new(),
                blocking: None,
                kind: TaskKind::Plain,
                released_by: Some(t),
                sporadic: spec.sporadic,
                job_of: Some(format!("{}_engine", bus.name)),
            });
            scripts.push(Script {
                task: t,
                engine_row: tasks.len() + rows.len() - 1,
                position,
                of,
                ..checked
            });
        }
    }
    tasks.extend(rows);
    Ok(BoardBuses { buses, scripts })
}

/// The engine row charged for a job's script: `<bus>_engine[<task>]` for a job of one script, and
/// `<bus>_engine[<task>#<n>]` (`n` from 1, in the job's order) for each script of a job of several.
pub fn engine_row_name(bus: &str, task: &str, position: usize, of: usize) -> String {
    if of <= 1 {
        format!("{bus}_engine[{task}]")
    } else {
        format!("{bus}_engine[{task}#{}]", position + 1)
    }
}

/// A job's scripts in order, each with its field (`{p}.script`, or `{p}.scripts[k]`): one `script`, or the list
/// `scripts`, or none; never both.
pub fn job_scripts<'a>(
    script: Option<&'a ScriptModel>,
    scripts: Option<&'a [ScriptModel]>,
    p: &str,
) -> Result<Vec<(String, &'a ScriptModel)>, Refusal> {
    match (script, scripts) {
        (Some(_), Some(_)) => Err((p.to_string(), SensorBusError::ScriptAndScripts)),
        (Some(one), None) => Ok(vec![(format!("{p}.script"), one)]),
        (None, Some([])) => Err((format!("{p}.scripts"), SensorBusError::NoScripts)),
        (None, Some(list)) => Ok(list
            .iter()
            .enumerate()
            .map(|(k, s)| (format!("{p}.scripts[{k}]"), s))
            .collect()),
        (None, None) => Ok(Vec::new()),
    }
}

/// Checks a timing file's `sensor_buses` and its topics' scripts (`(field, script, scripts)`, the field as the
/// file spells it: `topics.gyroscope`) before a model is built from it, so that a refusal names the timing file's
/// field.
pub fn check_timing<'a>(
    buses: &[SensorBusModel],
    jobs: impl Iterator<Item = (String, Option<&'a ScriptModel>, Option<&'a [ScriptModel]>)>,
) -> Result<(), Refusal> {
    let models = buses;
    let buses = validate_buses(models, &OverheadTimes::default())?;
    let mut used = BTreeSet::new();
    for (field, script, scripts) in jobs {
        for (p, s) in job_scripts(script, scripts, &field)? {
            used.insert(validate_script(&buses, s, &p)?.bus);
        }
    }
    handlers_need_scripts(models, &used)
}

/// Refuses `engine.handlers` on a bus (index) not in `used`: removed from the tasks, they would be charged by no
/// engine row.
fn handlers_need_scripts(models: &[SensorBusModel], used: &BTreeSet<usize>) -> Result<(), Refusal> {
    match models
        .iter()
        .enumerate()
        .find(|(b, bus)| !bus.engine.handlers.is_empty() && !used.contains(b))
    {
        Some((b, bus)) => Err((
            format!("sensor_buses[{b}].engine.handlers"),
            SensorBusError::HandlersWithoutScripts(bus.name.clone()),
        )),
        None => Ok(()),
    }
}

/// The engine handlers the board's buses name (`(bus index, handler)`), each named once.
pub fn engine_handlers(buses: &[SensorBusModel]) -> Result<Vec<(usize, &str)>, Refusal> {
    let mut out: Vec<(usize, &str)> = Vec::new();
    for (b, bus) in buses.iter().enumerate() {
        for (h, name) in bus.engine.handlers.iter().enumerate() {
            if out.iter().any(|(_, o)| *o == name.as_str()) {
                return Err((
                    format!("sensor_buses[{b}].engine.handlers[{h}]"),
                    SensorBusError::HandlerTwice(name.clone()),
                ));
            }
            out.push((b, name.as_str()));
        }
    }
    Ok(out)
}

pub(crate) fn validate_buses(
    models: &[SensorBusModel],
    overheads: &OverheadTimes,
) -> Result<Vec<SensorBus>, Refusal> {
    let mut buses: Vec<SensorBus> = Vec::with_capacity(models.len());
    for (b, bus) in models.iter().enumerate() {
        let p = format!("sensor_buses[{b}]");
        if bus.name.trim().is_empty() || bus.name.contains(['/', '[', ']']) {
            return Err((
                format!("{p}.name"),
                SensorBusError::BadName(bus.name.clone()),
            ));
        }
        if buses.iter().any(|o| o.name == bus.name) {
            return Err((
                format!("{p}.name"),
                SensorBusError::BusTwice(bus.name.clone()),
            ));
        }
        if bus.bitrate == 0 {
            return Err((
                format!("{p}.bitrate"),
                SensorBusError::NotPositive("0".into()),
            ));
        }
        positive(bus.engine.per_event_us, format!("{p}.engine.per_event_us"))?;
        sourced(&bus.engine.source, format!("{p}.engine.source"))?;
        let per_script = engine_part(
            bus.engine.per_script.as_ref(),
            format!("{p}.engine.per_script"),
        )?;
        let condition_wait = engine_part(
            bus.engine.condition_wait.as_ref(),
            format!("{p}.engine.condition_wait"),
        )?;
        buses.push(SensorBus {
            name: bus.name.clone(),
            bitrate: bus.bitrate,
            bit_time: can::bit_time(bus.bitrate),
            engine_priority: bus.engine.priority,
            per_event: Time::from_us_up(bus.engine.per_event_us)
                .plus(overheads.isr_entry)
                .plus(overheads.isr_exit),
            per_event_from: bus.engine.per_event_from,
            source: bus.engine.source.clone(),
            per_script,
            condition_wait,
        });
    }
    Ok(buses)
}

/// A script checked against its board's buses (`task` and `engine_row` still to be filled in).
pub(crate) fn validate_script(
    buses: &[SensorBus],
    script: &ScriptModel,
    p: &str,
) -> Result<Script, Refusal> {
    let (b, bus) = buses
        .iter()
        .enumerate()
        .find(|(_, bus)| bus.name == script.bus)
        .ok_or_else(|| {
            (
                format!("{p}.bus"),
                SensorBusError::UnknownBus(script.bus.clone()),
            )
        })?;
    let (wire, derived_events, starts) = match (script.bytes, script.bus_time_us) {
        (Some(bytes), None) => {
            if bytes == 0 {
                return Err((
                    format!("{p}.bytes"),
                    SensorBusError::NotPositive("0".into()),
                ));
            }
            let starts = script.starts.unwrap_or(1);
            if starts == 0 {
                return Err((
                    format!("{p}.starts"),
                    SensorBusError::NotPositive("0".into()),
                ));
            }
            let (bytes, wide_starts) = (u64::from(bytes), u64::from(starts));
            let bits = BITS_PER_BYTE * bytes + BITS_PER_START * wide_starts;
            let events = u32::try_from(2 * bytes + 2 * wide_starts).unwrap_or(u32::MAX);
            (bus.bit_time.times(bits), Some(events), starts)
        }
        (None, Some(us)) => {
            let starts = match (script.starts, bus.condition_wait.is_some()) {
                (Some(_), false) => {
                    return Err((format!("{p}.starts"), SensorBusError::StartsWithoutBytes))
                }
                (None, true) => return Err((format!("{p}.starts"), SensorBusError::NoStarts)),
                (Some(0), true) => {
                    return Err((
                        format!("{p}.starts"),
                        SensorBusError::NotPositive("0".into()),
                    ))
                }
                (Some(n), true) => n,
                (None, false) => 0,
            };
            positive(us, format!("{p}.bus_time_us"))?;
            (Time::from_us_up(us), None, starts)
        }
        _ => return Err((p.to_string(), SensorBusError::OneFigure)),
    };
    sourced(&script.source, format!("{p}.source"))?;
    if !(script.stretch_us.is_finite()
        && script.stretch_us >= 0.0
        && script.stretch_us <= Time::LIMIT_US)
    {
        return Err((
            format!("{p}.stretch_us"),
            SensorBusError::Negative(script.stretch_us.to_string()),
        ));
    }
    sourced(&script.stretch_source, format!("{p}.stretch_source"))?;
    let settle = match (script.settle_us, &script.settle_source) {
        (None, None) => Time::ZERO,
        (None, Some(_)) => {
            return Err((
                format!("{p}.settle_source"),
                SensorBusError::SettleSourceAlone,
            ))
        }
        (Some(us), source) => {
            if !(us.is_finite() && (0.0..=Time::LIMIT_US).contains(&us)) {
                return Err((
                    format!("{p}.settle_us"),
                    SensorBusError::Negative(us.to_string()),
                ));
            }
            sourced(
                source.as_deref().unwrap_or(""),
                format!("{p}.settle_source"),
            )?;
            Time::from_us_up(us)
        }
    };
    let mut stretch = Time::from_us_up(script.stretch_us);
    if let Some(us) = script.deadline_us {
        positive(us, format!("{p}.deadline_us"))?;
        sourced(
            script.deadline_source.as_deref().unwrap_or(""),
            format!("{p}.deadline_source"),
        )?;
        // Ended by then: no more stretch than the deadline leaves after the wire time.
        let cap = Time::from_us_up(us).minus(wire);
        if cap < stretch {
            stretch = cap;
        }
    }
    let events = match (script.events, derived_events) {
        (Some(0), _) => {
            return Err((
                format!("{p}.events"),
                SensorBusError::NotPositive("0".into()),
            ))
        }
        (Some(e), _) | (None, Some(e)) => e,
        (None, None) => return Err((format!("{p}.events"), SensorBusError::NoEvents)),
    };
    Ok(Script {
        task: usize::MAX,
        bus: b,
        wire,
        stretch,
        events,
        starts,
        engine_row: usize::MAX,
        position: 0,
        of: 1,
        settle,
    })
}

/// One sensor bus's results.
#[derive(Debug, Clone, PartialEq)]
pub struct SensorBusResult {
    /// Name.
    pub name: String,
    /// SCL bits per second.
    pub bitrate: u32,
    /// The engine interrupt's priority.
    pub engine_priority: u32,
    /// One event's cost on the CPU (entry and exit included).
    pub per_event: Time,
    /// Where the per-event figure comes from.
    pub per_event_from: PerEventFrom,
    /// Its source.
    pub source: String,
    /// The per-script part, if stated.
    pub per_script: Option<Part>,
    /// The condition wait as a part of its own (once per START condition), if stated.
    pub condition_wait: Option<Part>,
    /// One engine event's worst response on the CPU (what an event may hold SCL low), if bounded: an event with the
    /// per-event part alone.
    pub event_response: Option<Time>,
    /// Σ bus time / period of its scripts.
    pub utilisation: f64,
    /// Its scripts, most urgent first.
    pub scripts: Vec<ScriptResult>,
}

/// One script's results.
#[derive(Debug, Clone, PartialEq)]
pub struct ScriptResult {
    /// The submitting task (`<task>#<n>` for the `n`th script of a job of several).
    pub task: String,
    /// The job's wait before submitting it (suspension of the job, not bus time).
    pub settle: Time,
    /// Its priority (the script's on the bus).
    pub priority: u32,
    /// Time on the wire.
    pub wire: Time,
    /// The devices' stretch allowance.
    pub stretch: Time,
    /// Engine events.
    pub events: u32,
    /// The bus time used: wire + stretch + events × the event response.
    pub bus_time: Time,
    /// Release jitter used (the submitting job's response).
    pub jitter: Time,
    /// Blocking by the longest lower-priority script.
    pub blocking: Time,
    /// The response on the bus from the nominal submission (jitter included).
    pub bound: Bound,
    /// The submitting job's suspension: the bus response from the actual submission (`bound` minus `jitter`).
    pub suspension: Option<Time>,
}

/// The report's side of the rounds ([`suspension_analysis::SuspendingBoard`]): the board's tasks sorted by
/// priority, its scripts and views, and what the rounds found, kept for the report.
struct HostBoard<'b> {
    board: &'b crate::model::BoardSystem,
    sorted: analysis::SortedTasks,
    /// Per sorted position: its SRP blocking.
    blocking: Vec<Time>,
    /// The scripts as the rounds read them, in their jobs' sorted order (most urgent first).
    scripts: Vec<ScriptJob>,
    /// Per script of the rounds: its index in the board's scripts.
    model: Vec<usize>,
    engines: Vec<Engine>,
    /// Per sorted position: its view (0: the default).
    view: Vec<usize>,
    views: usize,
    limits: Limits,
    /// The last view's bounds, per sorted position.
    current: Vec<Bound>,
    /// Each task's bound from its own view and the jitter it was found with, per sorted position.
    kept: Vec<Bound>,
    jitters: Vec<Time>,
    /// Per script: its response on its bus in the last round.
    on_bus: Vec<Option<OnBus>>,
    /// Per bus: its plain event response in the last round (none for a bus no script uses).
    events: Vec<Option<Time>>,
    /// The failing tasks (sorted positions) and why, in the order found.
    failing: Vec<(usize, Unbounded)>,
}

impl HostBoard<'_> {
    fn name(&self, p: usize) -> String {
        self.sorted
            .order
            .get(p)
            .and_then(|&i| self.board.tasks.get(i))
            .map_or("?", |t| t.name.as_str())
            .to_string()
    }

    fn priority(&self, p: usize) -> u32 {
        self.sorted
            .order
            .get(p)
            .and_then(|&i| self.board.tasks.get(i))
            .map_or(0, |t| t.priority)
    }

    fn bus_name(&self, b: usize) -> String {
        self.board
            .sensor_buses
            .buses
            .get(b)
            .map_or("?", |bus| bus.name.as_str())
            .to_string()
    }
}

impl SuspendingBoard for HostBoard<'_> {
    fn scripts(&self) -> usize {
        self.scripts.len()
    }
    fn script(&self, k: usize) -> Option<ScriptJob> {
        self.scripts.get(k).copied()
    }
    fn buses(&self) -> usize {
        self.engines.len()
    }
    fn engine(&self, b: usize) -> Option<Engine> {
        self.engines.get(b).copied()
    }
    fn view(&self, p: usize) -> usize {
        self.view.get(p).copied().unwrap_or(0)
    }
    fn views(&self) -> usize {
        self.views
    }
    fn own_jitter(&self, p: usize) -> Time {
        self.sorted
            .order
            .get(p)
            .and_then(|&i| self.board.tasks.get(i))
            .map_or(Time::ZERO, |t| t.jitter)
    }
    fn released_by(&self, p: usize) -> Option<usize> {
        let by = self.sorted.release.get(p).copied().flatten()?.by;
        (by < self.sorted.order.len()).then_some(by)
    }
    fn analyse_view(
        &mut self,
        timings: &mut [TaskTiming],
        shares: &[Share],
        unreleased: &[bool],
        cut: &[Time],
        _: &Limits,
    ) -> Result<board_analysis::Outcome, board_analysis::OutOfIterations> {
        let n = self.sorted.order.len();
        self.current = analysis::view_bounds(
            self.board,
            &self.sorted,
            timings.get_mut(..n).unwrap_or(&mut []),
            &self.blocking,
            shares.get(..n).unwrap_or(&[]),
            analysis::ViewCut {
                unreleased,
                jitters: cut,
            },
            &self.limits,
        );
        Ok(board_analysis::Outcome::default())
    }
    fn current(&self, p: usize) -> Option<Time> {
        self.current.get(p)?.as_ref().ok().map(|r| r.wcrt)
    }
    fn refine(&mut self, p: usize, found: Response) {
        if let Some(slot) = self.current.get_mut(p) {
            if slot.as_ref().map_or(true, |r| found.wcrt < r.wcrt) {
                *slot = Ok(found);
            }
        }
    }
    fn keep(&mut self, v: usize, timings: &[TaskTiming]) {
        for (p, ((kept, jitter), t)) in self
            .kept
            .iter_mut()
            .zip(self.jitters.iter_mut())
            .zip(timings)
            .enumerate()
        {
            if self.view.get(p).copied().unwrap_or(0) == v {
                if let Some(bound) = self.current.get(p) {
                    *kept = bound.clone();
                }
                *jitter = t.jitter;
            }
        }
    }
    fn kept(&self, p: usize) -> Option<Time> {
        self.kept.get(p)?.as_ref().ok().map(|r| r.wcrt)
    }
    fn on_bus(&mut self, k: usize, found: &OnBus) {
        let model = self.model.get(k).copied().unwrap_or(usize::MAX);
        if let Some(slot) = self.on_bus.get_mut(model) {
            *slot = Some(*found);
        }
    }
    fn event(&mut self, b: usize, plain: Result<Time, AnalysisError>) {
        if let Some(slot) = self.events.get_mut(b) {
            *slot = plain.ok();
        }
    }
    fn fail(&mut self, failure: Failure) {
        match failure {
            Failure::Script { script, why } => {
                if let Some(s) = self.scripts.get(script).copied() {
                    let why = Unbounded::SensorBus(
                        self.bus_name(s.bus),
                        Unbounded::Analysis(why).to_string(),
                    );
                    self.failing.push((s.job, why));
                }
            }
            Failure::Event { bus, why } => {
                let why = Unbounded::SensorBus(
                    self.bus_name(bus),
                    format!("its engine's event: {}", Unbounded::Analysis(why)),
                );
                for s in self.scripts.iter().filter(|s| s.bus == bus) {
                    self.failing.push((s.job, why.clone()));
                }
            }
            Failure::Job { job } => {
                let why = match self.kept.get(job) {
                    Some(Err(why)) => why.clone(),
                    _ => Unbounded::NoConvergence,
                };
                self.failing.push((job, why));
            }
            Failure::Rounds => {
                for s in &self.scripts {
                    self.failing.push((s.job, Unbounded::NoConvergence));
                }
            }
        }
    }
    fn unbound(&mut self, p: usize, releaser: Option<usize>) {
        // A failing task says why it failed (the last reason found); a released one names its releaser; every
        // other one names the first failing task at or above its priority, or else the first failing task.
        let why = match (
            self.failing.iter().rev().find(|(task, _)| *task == p),
            releaser,
        ) {
            (Some((_, why)), _) => why.clone(),
            (None, Some(r)) => Unbounded::Releaser(self.name(r)),
            (None, None) => {
                let priority = self.priority(p);
                let cause = self
                    .failing
                    .iter()
                    .find(|(task, _)| self.priority(*task) >= priority)
                    .or(self.failing.first());
                match cause {
                    Some((task, _)) => Unbounded::Suspending(self.name(*task)),
                    None => Unbounded::NoConvergence,
                }
            }
        };
        if let Some(slot) = self.kept.get_mut(p) {
            *slot = Err(why);
        }
    }
}

/// Analyses a board with scripts by the rounds ([`suspension_analysis::analyse`], the one the chip's check runs):
/// per task its bound and the release jitter it was found with (model order), and the buses' results. `costs` are
/// the tasks' CPU costs with overheads, `blocking` their SRP blockings.
pub(crate) fn analyse(
    board: &crate::model::BoardSystem,
    costs: &[Time],
    blocking: &[Time],
    limits: &Limits,
) -> (Vec<Bound>, Vec<Time>, Vec<SensorBusResult>) {
    let n = board.tasks.len();
    let buses = &board.sensor_buses.buses;
    let scripts = &board.sensor_buses.scripts;
    let own_jitters: Vec<Time> = board.tasks.iter().map(|t| t.jitter).collect();
    let releases: Vec<Option<usize>> = board.tasks.iter().map(|t| t.released_by).collect();
    let sorted = analysis::sort_tasks(board, &own_jitters, &releases);
    let mut position = vec![usize::MAX; n];
    for (p, &i) in sorted.order.iter().enumerate() {
        if let Some(slot) = position.get_mut(i) {
            *slot = p;
        }
    }
    let at = |i: usize| position.get(i).copied().unwrap_or(usize::MAX);
    let group = |i: usize| {
        board
            .tasks
            .get(i)
            .map(|t| t.job_of.as_deref().unwrap_or(t.name.as_str()))
    };
    // The views: one per RTIC task with a suspending job (its jobs see the suspensions as execution), and the
    // default view for every other task (0).
    let groups: Vec<&str> = scripts
        .iter()
        .filter_map(|s| group(s.task))
        .collect::<BTreeSet<_>>()
        .into_iter()
        .collect();
    let view: Vec<usize> = sorted
        .order
        .iter()
        .map(|&i| {
            group(i)
                .and_then(|g| groups.iter().position(|o| *o == g))
                .map_or(0, |v| v + 1)
        })
        .collect();
    let sections = analysis::critical_sections(board);
    // The scripts in their jobs' sorted order (a job's in its order): a bus's scripts by priority.
    let mut model: Vec<usize> = (0..scripts.len()).collect();
    model.sort_by_key(|&m| scripts.get(m).map_or(usize::MAX, |s| at(s.task)));
    let mut host = HostBoard {
        board,
        blocking: sorted
            .order
            .iter()
            .map(|&i| blocking.get(i).copied().unwrap_or(Time::ZERO))
            .collect(),
        scripts: model
            .iter()
            .filter_map(|&m| scripts.get(m))
            .map(|s| ScriptJob {
                job: at(s.task),
                engine: at(s.engine_row),
                bus: s.bus,
                wire: s.wire.plus(s.stretch),
                events: s.events,
                starts: s.starts,
                settle: s.settle,
            })
            .collect(),
        model,
        engines: buses
            .iter()
            .map(|bus| bus.engine(board::srp_blocking(bus.engine_priority, &sections)))
            .collect(),
        view,
        views: groups.len(),
        limits: *limits,
        current: Vec::new(),
        kept: vec![Err(Unbounded::NoConvergence); n],
        jitters: sorted
            .order
            .iter()
            .map(|&i| own_jitters.get(i).copied().unwrap_or(Time::ZERO))
            .collect(),
        on_bus: vec![None; scripts.len()],
        events: vec![None; buses.len()],
        failing: Vec::new(),
        sorted,
    };
    let mut timings: Vec<TaskTiming> = host
        .sorted
        .order
        .iter()
        .map(|&i| TaskTiming {
            priority: board.tasks.get(i).map_or(0, |t| t.priority),
            wcet: costs.get(i).copied().unwrap_or(Time::ZERO),
            period: board.tasks.get(i).map_or(Time::ZERO, |t| t.period),
            jitter: own_jitters.get(i).copied().unwrap_or(Time::ZERO),
        })
        .collect();
    // An engine event takes the place after the jobs at or above its engine for the while.
    timings.push(TaskTiming {
        priority: 0,
        wcet: Time::ZERO,
        period: Time::ZERO,
        jitter: Time::ZERO,
    });
    let mut shares: Vec<Share> = timings
        .iter()
        .map(|t| Share::of(t.wcet, t.period))
        .collect();
    let k = scripts.len();
    let (mut base, mut own, mut unreleased) =
        (vec![Time::ZERO; n], vec![Time::ZERO; n], vec![false; n]);
    let (mut suspension, mut bus_times) = (vec![Time::ZERO; k], vec![Time::ZERO; k]);
    let mut subset = vec![
        MessageTiming {
            key: 0,
            frame_time: Time::ZERO,
            frames: 1,
            period: Time::ZERO,
            jitter: Time::ZERO,
        };
        k
    ];
    let mut scratch = vec![Counter::default(); n + 1];
    let sorted_blocking = host.blocking.clone();
    let mut work = Work {
        timings: &mut timings,
        jobs: n,
        blocking: &sorted_blocking,
        shares: &mut shares,
        base: &mut base,
        own: &mut own,
        unreleased: &mut unreleased,
        suspension: &mut suspension,
        bus_times: &mut bus_times,
        subset: &mut subset,
        scratch: &mut scratch,
    };
    // Each fixed point has the limits' iterations of its own: the rounds never run out of a board's budget.
    let _ = suspension_analysis::analyse(&mut host, &mut work, limits, Budget::Rounds(MAX_ROUNDS));
    let mut bounds: Vec<Bound> = vec![Err(Unbounded::NoConvergence); n];
    let mut jitters = own_jitters.clone();
    for (p, &i) in host.sorted.order.iter().enumerate() {
        if let (Some(slot), Some(bound)) = (bounds.get_mut(i), host.kept.get(p)) {
            *slot = bound.clone();
        }
        if let (Some(slot), Some(j)) = (jitters.get_mut(i), host.jitters.get(p)) {
            *slot = *j;
        }
    }
    let results = buses
        .iter()
        .enumerate()
        .map(|(b, bus)| {
            // The bus's scripts, most urgent first (ties in model order).
            let mut list: Vec<(usize, OnBus)> = (0..k)
                .filter(|&s| scripts.get(s).is_some_and(|s| s.bus == b))
                .filter_map(|s| Some((s, host.on_bus.get(s).copied().flatten()?)))
                .collect();
            list.sort_by_key(|&(s, _)| {
                std::cmp::Reverse(
                    scripts
                        .get(s)
                        .and_then(|s| board.tasks.get(s.task))
                        .map_or(0, |t| t.priority),
                )
            });
            bus_result(
                board,
                scripts,
                bus,
                &list,
                host.events.get(b).copied().flatten(),
            )
        })
        .collect();
    (bounds, jitters, results)
}

fn bus_result(
    board: &crate::model::BoardSystem,
    scripts: &[Script],
    bus: &SensorBus,
    list: &[(usize, OnBus)],
    event_response: Option<Time>,
) -> SensorBusResult {
    let mut utilisation = 0.0;
    let scripts_out = list
        .iter()
        .filter_map(|(script, on)| {
            let s = scripts.get(*script)?;
            let task = board.tasks.get(s.task)?;
            utilisation += on.bus_time.as_ns() as f64 / task.period.as_ns().max(1) as f64;
            Some(ScriptResult {
                task: if s.of > 1 {
                    format!("{}#{}", task.name, s.position + 1)
                } else {
                    task.name.clone()
                },
                settle: s.settle,
                priority: task.priority,
                wire: s.wire,
                stretch: s.stretch,
                events: s.events,
                bus_time: on.bus_time,
                jitter: on.jitter,
                blocking: on.blocking,
                bound: on.result.map_err(Unbounded::Analysis),
                suspension: on.result.ok().map(|r| r.wcrt.minus(on.jitter)),
            })
        })
        .collect();
    SensorBusResult {
        name: bus.name.clone(),
        bitrate: bus.bitrate,
        engine_priority: bus.engine_priority,
        per_event: bus.per_event,
        per_event_from: bus.per_event_from,
        source: bus.source.clone(),
        per_script: bus.per_script.clone(),
        condition_wait: bus.condition_wait.clone(),
        event_response,
        utilisation,
        scripts: scripts_out,
    }
}
