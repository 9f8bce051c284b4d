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
//!   script: a lower-priority critical section may start while it is suspended), all as if executed. The jobs of
//!   the same RTIC task (`job_of`) run one after the other, so for them the suspension is execution too.
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
//! to a fixed point ([`MAX_ROUNDS`]), or the affected jobs are unbounded with the reason.

use std::collections::BTreeSet;
use std::fmt;

use serde::{Deserialize, Serialize};

use crate::analysis::{self, Bound, Unbounded};
use crate::board::{self, TaskTiming};
use crate::busy_window::{AnalysisError, Counter, Limits, Response};
use crate::can::{self, MessageTiming};
use crate::model::{BoardModel, OverheadTimes, TaskKind, TaskSpec};
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
    /// The engine's charge for one script: `events × per_event` (each with the interrupt's entry and exit), plus
    /// the per-script part once, plus the condition wait once per START condition.
    pub fn script_charge(&self, script: &Script) -> Time {
        self.per_event
            .times(u64::from(script.events))
            .plus(part_time(self.per_script.as_ref()))
            .plus(part_time(self.condition_wait.as_ref()).times(u64::from(script.starts)))
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
        stretch: Time::from_us_up(script.stretch_us),
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

/// A bus's engine events' worst responses on the CPU, by what the event carries beside the per-event part.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
struct EventResponses {
    /// An event with the per-event part alone.
    plain: Time,
    /// An event that takes the condition wait.
    waiting: Time,
    /// The event that ends a script: the per-script part and, if the engine states one, the condition wait.
    ending: Time,
}

impl EventResponses {
    /// What a script's events hold SCL on the CPU: its ending event, one that takes the condition wait per
    /// further START (as many as its other events allow), the rest plain. The ending event is charged the wait as
    /// well, so whichever event takes which wait, each event is charged at least its cost.
    fn of(&self, script: &Script) -> Time {
        if script.events == 0 {
            return Time::ZERO;
        }
        let others = u64::from(script.events.saturating_sub(1));
        let waiting = u64::from(script.starts).min(others);
        self.ending
            .plus(self.waiting.times(waiting))
            .plus(self.plain.times(others - waiting))
    }
}

/// One script as its bus's analysis found it.
#[derive(Debug, Clone, Copy)]
struct OnBus {
    /// Index into the board's scripts.
    script: usize,
    result: Result<Response, AnalysisError>,
    bus_time: Time,
    jitter: Time,
    blocking: Time,
}

/// What stopped the iteration: the bus or job that has no bound.
enum Failure {
    /// A script has no bound on the bus (`scripts` index), why.
    Script(usize, String),
    /// A bus's engine event has no bound on the CPU.
    Event(usize, String),
    /// A suspending job has no bound: its script index, why.
    Job(usize, Unbounded),
    /// A job of a suspending RTIC task without a script has no bound: its task index, why.
    Task(usize, Unbounded),
    /// The rounds ran out.
    Rounds,
}

/// Analyses a board with scripts: per task its bound and the release jitter it was found with (model order), and
/// the buses' results. `costs` are the tasks' CPU costs with overheads, `blocking` their SRP blockings.
pub(crate) fn analyse(
    board: &crate::model::BoardSystem,
    costs: &[Time],
    blocking: &[Time],
    limits: &Limits,
) -> (Vec<Bound>, Vec<Time>, Vec<SensorBusResult>) {
    let n = board.tasks.len();
    let buses = &board.sensor_buses.buses;
    let scripts = &board.sensor_buses.scripts;
    let cost = |i: usize| costs.get(i).copied().unwrap_or(Time::ZERO);
    let group = |i: usize| {
        board
            .tasks
            .get(i)
            .map(|t| t.job_of.as_deref().unwrap_or(t.name.as_str()))
    };
    let mut script_of: Vec<Option<usize>> = vec![None; n];
    for (k, s) in scripts.iter().enumerate() {
        if let Some(slot) = script_of.get_mut(s.task) {
            *slot = Some(k);
        }
    }
    // The views: one per RTIC task with a suspending job (its jobs see the suspensions as execution), and the
    // default view for every other task (position 0).
    let groups: Vec<&str> = scripts
        .iter()
        .filter_map(|s| group(s.task))
        .collect::<BTreeSet<_>>()
        .into_iter()
        .collect();
    let view_of = |i: usize| {
        group(i)
            .and_then(|g| groups.iter().position(|o| *o == g))
            .map_or(0, |v| v + 1)
    };
    let sections = analysis::critical_sections(board);
    let priorities: Vec<u32> = board.tasks.iter().map(|t| t.priority).collect();

    // The iteration's state: each suspending job's response (its script's jitter), each bus's event response.
    let mut response = vec![Time::ZERO; scripts.len()];
    // Each job of a suspending RTIC task (script or not): its own-view response.
    let mut own = vec![Time::ZERO; n];
    let mut event = vec![EventResponses::default(); buses.len()];
    // Each script's bus time as one job at its engine's priority (`None`: no such bound; the per-event one holds).
    let mut whole: Vec<Option<Time>> = vec![None; scripts.len()];
    let mut bounds: Vec<Bound> = vec![Err(Unbounded::NoConvergence); n];
    let mut jitters: Vec<Time> = board.tasks.iter().map(|t| t.jitter).collect();
    let mut on_bus: Vec<Vec<OnBus>> = vec![Vec::new(); buses.len()];
    let mut failures = vec![Failure::Rounds];
    for _ in 0..MAX_ROUNDS {
        // 1. The buses, with the scripts' jitters and the events' responses as they stand.
        let mut suspension = vec![Time::ZERO; scripts.len()];
        let mut stop: Vec<Failure> = Vec::new();
        for (b, results) in on_bus.iter_mut().enumerate() {
            let bus_event = event.get(b).copied();
            *results = bus_responses(board, scripts, b, &response, bus_event, &whole, limits);
            for s in results.iter() {
                match s.result {
                    Ok(r) => {
                        if let Some(slot) = suspension.get_mut(s.script) {
                            *slot = r.wcrt.minus(s.jitter);
                        }
                    }
                    Err(e) => {
                        let why = Unbounded::Analysis(e).to_string();
                        stop.push(Failure::Script(s.script, why));
                    }
                }
            }
        }
        if !stop.is_empty() {
            failures = stop;
            break;
        }
        // 2. The board, once per view.
        let mut next_bounds = bounds.clone();
        let mut next_jitters = jitters.clone();
        let mut default_view = None;
        for v in 0..=groups.len() {
            let mut view_costs = costs.to_vec();
            let mut view_jitters: Vec<Time> = board.tasks.iter().map(|t| t.jitter).collect();
            let mut releases: Vec<Option<usize>> =
                board.tasks.iter().map(|t| t.released_by).collect();
            for (k, s) in scripts.iter().enumerate() {
                if view_of(s.task) == v {
                    // Suspension-oblivious: each script's suspension and its settle, and the blocking on each
                    // resumption (after the settle's wait and after the script), as execution.
                    let resumptions = if s.settle > Time::ZERO { 2 } else { 1 };
                    if let Some(c) = view_costs.get_mut(s.task) {
                        *c = c
                            .plus(suspension.get(k).copied().unwrap_or(Time::ZERO))
                            .plus(s.settle)
                            .plus(
                                blocking
                                    .get(s.task)
                                    .copied()
                                    .unwrap_or(Time::ZERO)
                                    .times(resumptions),
                            );
                    }
                }
            }
            // Every job of a suspending RTIC task, with a script or not, seen from another view: its CPU,
            // released anywhere up to its own-view response minus its CPU after its activation (a job without a
            // script still waits behind its task's suspended job, so its own response holds that wait).
            for i in (0..n).filter(|&i| view_of(i) != 0 && view_of(i) != v) {
                if let (Some(j), Some(rel)) = (view_jitters.get_mut(i), releases.get_mut(i)) {
                    *j = own.get(i).copied().unwrap_or(Time::ZERO).minus(cost(i));
                    *rel = None;
                }
            }
            // A job released by a job of a suspending RTIC task inherits that job's whole own-view response.
            for (i, t) in board.tasks.iter().enumerate() {
                let Some(r) = t.released_by.filter(|&r| view_of(r) != 0) else {
                    continue;
                };
                if let (Some(j), Some(rel)) = (view_jitters.get_mut(i), releases.get_mut(i)) {
                    *j = t.jitter.plus(own.get(r).copied().unwrap_or(Time::ZERO));
                    *rel = None;
                }
            }
            let (view_bounds, found_jitters) = analysis::task_bounds_in(
                board,
                &view_costs,
                blocking,
                &view_jitters,
                &releases,
                limits,
            );
            for i in (0..n).filter(|&i| view_of(i) == v) {
                if let (Some(slot), Some(bound)) = (next_bounds.get_mut(i), view_bounds.get(i)) {
                    *slot = bound.clone();
                }
                if let (Some(slot), Some(j)) = (next_jitters.get_mut(i), found_jitters.get(i)) {
                    *slot = *j;
                }
            }
            if v == 0 {
                default_view = Some((view_costs, found_jitters));
            }
        }
        bounds = next_bounds;
        jitters = next_jitters;
        // 3. Each bus's engine event on the CPU, in the default view.
        let mut next_event = event.clone();
        let mut next_whole = whole.clone();
        if let Some((view_costs, view_jitters)) = &default_view {
            for (b, bus) in buses.iter().enumerate() {
                // The bus's own engine rows are this handler's events, one at a time: not its interference.
                let own_rows: Vec<usize> = scripts
                    .iter()
                    .filter(|s| s.bus == b)
                    .map(|s| s.engine_row)
                    .collect();
                let others = (0..n).filter(|i| !own_rows.contains(i));
                let tasks: Vec<TaskTiming> = others
                    .map(|i| TaskTiming {
                        priority: priorities.get(i).copied().unwrap_or(0),
                        wcet: view_costs.get(i).copied().unwrap_or(Time::ZERO),
                        period: board.tasks.get(i).map_or(Time::ZERO, |t| t.period),
                        jitter: view_jitters.get(i).copied().unwrap_or(Time::ZERO),
                    })
                    .collect();
                let wait = part_time(bus.condition_wait.as_ref());
                let respond = |extra: Time| {
                    event_response(bus, bus.per_event.plus(extra), &tasks, &sections, limits)
                };
                let responses = respond(Time::ZERO).and_then(|plain| {
                    Ok(EventResponses {
                        plain,
                        waiting: respond(wait)?,
                        ending: respond(part_time(bus.per_script.as_ref()).plus(wait))?,
                    })
                });
                match responses {
                    Ok(r) => {
                        if let Some(slot) = next_event.get_mut(b) {
                            *slot = r;
                        }
                    }
                    Err(e) => stop.push(Failure::Event(b, Unbounded::Analysis(e).to_string())),
                }
                // Each script on the bus as one job: its events' work, its wire time as if executed.
                for (k, s) in scripts.iter().enumerate().filter(|(_, s)| s.bus == b) {
                    if let Some(slot) = next_whole.get_mut(k) {
                        *slot = script_response(bus, s, &tasks, &sections, limits).ok();
                    }
                }
            }
        }
        // 4. The suspending jobs' responses: the scripts' next jitters.
        let mut next_response = response.clone();
        for (k, s) in scripts.iter().enumerate() {
            match bounds.get(s.task) {
                Some(Ok(r)) => {
                    if let Some(slot) = next_response.get_mut(k) {
                        *slot = r.wcrt;
                    }
                }
                Some(Err(why)) => stop.push(Failure::Job(k, why.clone())),
                None => {}
            }
        }
        // The own-view responses of every job of a suspending RTIC task: their jitters in the other views.
        let mut next_own = own.clone();
        for i in (0..n).filter(|&i| view_of(i) != 0) {
            match bounds.get(i) {
                Some(Ok(r)) => {
                    if let Some(slot) = next_own.get_mut(i) {
                        *slot = r.wcrt;
                    }
                }
                Some(Err(why)) => stop.push(Failure::Task(i, why.clone())),
                None => {}
            }
        }
        if !stop.is_empty() {
            failures = stop;
            break;
        }
        if next_response == response
            && next_event == event
            && next_own == own
            && next_whole == whole
        {
            failures = Vec::new();
            break;
        }
        response = next_response;
        event = next_event;
        whole = next_whole;
        own = next_own;
    }
    if !failures.is_empty() {
        mark_unbounded(board, scripts, buses, &failures, &view_of, &mut bounds);
    }
    let results = buses
        .iter()
        .enumerate()
        .map(|(b, bus)| {
            let list = on_bus.get(b).map(Vec::as_slice).unwrap_or(&[]);
            let event_failed = failures
                .iter()
                .any(|f| matches!(f, Failure::Event(e, _) if *e == b));
            let event_response = if event_failed {
                None
            } else {
                event.get(b).map(|e| e.plain)
            };
            bus_result(board, scripts, bus, list, event_response)
        })
        .collect();
    (bounds, jitters, results)
}

/// The scripts on bus `b` analysed as non-preemptive fixed priority: per script (most urgent first) its index,
/// its response, its bus time and its jitter. A script is analysed without its *siblings*, the other scripts of
/// its RTIC task (`job_of`, or the task itself): a job submits its scripts one after the other, each when the one
/// before it has ended, and the task runs one job at a time, so no sibling is waiting or on the bus while a script
/// is pending; a sibling neither interferes with it nor blocks it.
fn bus_responses(
    board: &crate::model::BoardSystem,
    scripts: &[Script],
    b: usize,
    response: &[Time],
    event: Option<EventResponses>,
    whole: &[Option<Time>],
    limits: &Limits,
) -> Vec<OnBus> {
    let priority = |k: usize| {
        scripts
            .get(k)
            .and_then(|s| board.tasks.get(s.task))
            .map_or(0, |t| t.priority)
    };
    let group = |k: usize| {
        scripts
            .get(k)
            .and_then(|s| board.tasks.get(s.task))
            .map(|t| t.job_of.as_deref().unwrap_or(t.name.as_str()))
    };
    let mut order: Vec<usize> = (0..scripts.len())
        .filter(|&k| scripts.get(k).is_some_and(|s| s.bus == b))
        .collect();
    order.sort_by_key(|&k| std::cmp::Reverse(priority(k)));
    let event = event.unwrap_or_default();
    let timing = |k: usize| {
        let s = scripts.get(k)?;
        Some(MessageTiming {
            // Lower key first: the most urgent submitter; equal priorities share a key and interfere.
            key: u32::MAX - priority(k),
            // The tighter of two bounds, both sound: each event's own worst response, and the script as one job.
            frame_time: bus_time(s, &event, whole.get(k).copied().flatten()),
            frames: 1,
            period: board.tasks.get(s.task).map_or(Time::ZERO, |t| t.period),
            jitter: response.get(k).copied().unwrap_or(Time::ZERO),
        })
    };
    order
        .iter()
        .filter_map(|&script| {
            // The script and every script on the bus that is not its sibling, most urgent first.
            let subset: Vec<usize> = order
                .iter()
                .copied()
                .filter(|&o| o == script || group(o) != group(script))
                .collect();
            let timings: Vec<MessageTiming> = subset.iter().filter_map(|&o| timing(o)).collect();
            let at = subset.iter().position(|&o| o == script)?;
            let mut blockings = vec![Time::ZERO; timings.len()];
            can::blockings(&timings, &mut blockings);
            let mut scratch = vec![Counter::default(); timings.len()];
            let mut out = vec![Err(AnalysisError::NoSuchIndex); timings.len()];
            // The engine picks the next script when one ends; a script submitted at that very instant is counted
            // as having been in time (the CAN analysis's bit term, one nanosecond here).
            can::response_times_into(
                &timings,
                &blockings,
                Time::from_ns(1),
                limits,
                &mut scratch,
                out.as_mut_slice(),
            );
            let t = timings.get(at)?;
            Some(OnBus {
                script,
                result: out.get(at).copied()?,
                bus_time: t.frame_time,
                jitter: t.jitter,
                blocking: blockings.get(at).copied().unwrap_or(Time::ZERO),
            })
        })
        .collect()
}

/// A script's bus time, from its first START to its end: its wire time and stretch plus each event's own worst
/// response (`event`), or its bound as one job (`whole`, [`script_response`]) where that is lower.
fn bus_time(script: &Script, event: &EventResponses, whole: Option<Time>) -> Time {
    let per_event = script.wire.plus(script.stretch).plus(event.of(script));
    whole.map_or(per_event, |w| w.min(per_event))
}

/// A script's bus time as one job at its engine's priority (docs/analysis.md, "Self-suspending publishers and the
/// sensor buses"): from its first START to its end the engine runs the script's events' handlers (their work as
/// [`EventResponses::of`] places it: the ending one, one with the condition wait per further START, the rest plain)
/// and is suspended on the wire between them. Suspension-oblivious (Chen et al. 2019, §5), the wire time and the
/// stretch are executed too, and each event, a resumption, may be blocked once by a lower critical section with a
/// ceiling at or above the engine's priority: one busy window at the engine's priority over `tasks` (every other
/// task at or above it, with its jitter), so each higher job is counted once per window, not once per event.
fn script_response(
    bus: &SensorBus,
    script: &Script,
    tasks: &[TaskTiming],
    sections: &[board::CriticalSection],
    limits: &Limits,
) -> Result<Time, AnalysisError> {
    let wait = part_time(bus.condition_wait.as_ref());
    let work = EventResponses {
        plain: bus.per_event,
        waiting: bus.per_event.plus(wait),
        ending: bus
            .per_event
            .plus(part_time(bus.per_script.as_ref()))
            .plus(wait),
    }
    .of(script);
    let cost = script.wire.plus(script.stretch).plus(work);
    engine_response(bus, cost, u64::from(script.events), tasks, sections, limits)
}

/// One engine event's worst response on the CPU: its `cost` at the engine's priority, interfered with by every
/// other task of at least that priority (`tasks`: not the bus's own engine rows, which are these very events),
/// blocked by SRP as a task of that priority. One instance: the block waits for the engine at each event, and the
/// bus runs one script at a time, so the engine's events never overlap.
fn event_response(
    bus: &SensorBus,
    cost: Time,
    tasks: &[TaskTiming],
    sections: &[board::CriticalSection],
    limits: &Limits,
) -> Result<Time, AnalysisError> {
    engine_response(bus, cost, 1, tasks, sections, limits)
}

/// One job of `cost` at the engine's priority, after every task of at least that priority in `tasks`, blocked once
/// per resumption (`resumptions`, each by SRP as a task of that priority); one instance.
fn engine_response(
    bus: &SensorBus,
    cost: Time,
    resumptions: u64,
    tasks: &[TaskTiming],
    sections: &[board::CriticalSection],
    limits: &Limits,
) -> Result<Time, AnalysisError> {
    let mut timings: Vec<TaskTiming> = tasks
        .iter()
        .filter(|t| t.priority >= bus.engine_priority)
        .copied()
        .collect();
    timings.sort_by_key(|t| std::cmp::Reverse(t.priority));
    timings.push(TaskTiming {
        priority: bus.engine_priority,
        wcet: cost,
        period: limits.horizon,
        jitter: Time::ZERO,
    });
    let index = timings.len() - 1;
    let mut scratch = vec![Counter::default(); timings.len()];
    let blocking = board::srp_blocking(bus.engine_priority, sections).times(resumptions);
    board::response_time(&timings, index, blocking, limits, &mut scratch).map(|r| r.wcrt)
}

/// Marks what the failures leave without a bound: the failing suspending jobs, every task at or below their
/// priority, every other task not above every suspending job and every engine (its bound came from a round that
/// did not converge, with jitters and suspensions still growing), and every task released by one of those. Only
/// a task above all of them, in no suspending RTIC task, keeps its bound: nothing the iteration moves reaches it.
fn mark_unbounded(
    board: &crate::model::BoardSystem,
    scripts: &[Script],
    buses: &[SensorBus],
    failures: &[Failure],
    view_of: &dyn Fn(usize) -> usize,
    bounds: &mut [Bound],
) {
    let bus_name = |b: usize| {
        buses
            .get(b)
            .map_or("?", |bus| bus.name.as_str())
            .to_string()
    };
    let failing: Vec<(usize, Unbounded)> = failures
        .iter()
        .flat_map(|failure| match failure {
            Failure::Script(k, why) => scripts
                .get(*k)
                .map(|s| vec![(s.task, Unbounded::SensorBus(bus_name(s.bus), why.clone()))])
                .unwrap_or_default(),
            Failure::Event(b, why) => scripts
                .iter()
                .filter(|s| s.bus == *b)
                .map(|s| {
                    (
                        s.task,
                        Unbounded::SensorBus(bus_name(*b), format!("its engine's event: {why}")),
                    )
                })
                .collect(),
            Failure::Job(k, why) => scripts
                .get(*k)
                .map(|s| vec![(s.task, why.clone())])
                .unwrap_or_default(),
            Failure::Task(i, why) => vec![(*i, why.clone())],
            Failure::Rounds => scripts
                .iter()
                .map(|s| (s.task, Unbounded::NoConvergence))
                .collect(),
        })
        .collect();
    let name = |i: usize| {
        board
            .tasks
            .get(i)
            .map_or("?", |t| t.name.as_str())
            .to_string()
    };
    let mut unbounded = vec![false; board.tasks.len()];
    for (task, why) in &failing {
        if let Some(slot) = bounds.get_mut(*task) {
            *slot = Err(why.clone());
        }
        if let Some(u) = unbounded.get_mut(*task) {
            *u = true;
        }
        let priority = board.tasks.get(*task).map_or(0, |t| t.priority);
        for (i, t) in board.tasks.iter().enumerate() {
            if i != *task && t.priority <= priority {
                if let (Some(slot), Some(u)) = (bounds.get_mut(i), unbounded.get_mut(i)) {
                    if !*u {
                        *slot = Err(Unbounded::Suspending(name(*task)));
                        *u = true;
                    }
                }
            }
        }
    }
    // Every other task not above every suspending job and every engine: its bound is not a fixed point's.
    let top = scripts
        .iter()
        .filter_map(|s| board.tasks.get(s.task).map(|t| t.priority))
        .chain(
            scripts
                .iter()
                .filter_map(|s| buses.get(s.bus).map(|b| b.engine_priority)),
        )
        .chain(
            scripts
                .iter()
                .filter_map(|s| board.tasks.get(s.engine_row).map(|t| t.priority)),
        )
        .max()
        .unwrap_or(0);
    let cause = failing.first().map(|(task, _)| *task);
    for (i, t) in board.tasks.iter().enumerate() {
        if t.priority > top && view_of(i) == 0 {
            continue;
        }
        if let (Some(slot), Some(u)) = (bounds.get_mut(i), unbounded.get_mut(i)) {
            if !*u {
                *slot =
                    Err(cause.map_or(Unbounded::NoConvergence, |c| Unbounded::Suspending(name(c))));
                *u = true;
            }
        }
    }
    // Release chains from an unbounded task are unbounded too.
    let mut changed = true;
    while changed {
        changed = false;
        for (i, t) in board.tasks.iter().enumerate() {
            let Some(r) = t.released_by else {
                continue;
            };
            if unbounded.get(r).copied().unwrap_or(false)
                && !unbounded.get(i).copied().unwrap_or(true)
            {
                if let Some(slot) = bounds.get_mut(i) {
                    *slot = Err(Unbounded::Releaser(name(r)));
                }
                if let Some(u) = unbounded.get_mut(i) {
                    *u = true;
                }
                changed = true;
            }
        }
    }
}

fn bus_result(
    board: &crate::model::BoardSystem,
    scripts: &[Script],
    bus: &SensorBus,
    list: &[OnBus],
    event_response: Option<Time>,
) -> SensorBusResult {
    let mut utilisation = 0.0;
    let scripts_out = list
        .iter()
        .filter_map(|on| {
            let s = scripts.get(on.script)?;
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
