//! The model file: boards with their tasks, the CAN bus with its messages (JSON, times in microseconds), and its
//! validation into the [`System`] the analysis runs on. Every error names the field it is about.
//!
//! The format is documented field by field in docs/analysis.md; the smallest accepted file is `{}`.

use std::collections::{BTreeMap, BTreeSet, HashMap, HashSet};
use std::fmt;

use serde::{Deserialize, Deserializer, Serialize, Serializer};

use crate::can::{self, FrameCost};
use crate::time::Time;

/// The resource name that stands for "interrupts disabled" (a `critical_section::with` or `interrupt::free`):
/// its ceiling is above every priority, so it blocks every task.
pub const GLOBAL_CRITICAL_SECTION: &str = "critical_section";

/// A whole model file.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Model {
    /// A label for reports (the scenario name when built from a scenario).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// The boards and their tasks.
    #[serde(default)]
    pub boards: Vec<BoardModel>,
    /// The CAN bus, if the model has one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub can: Option<CanModel>,
}

/// One board (one processor).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct BoardModel {
    /// Board name, used in `sender` references (`"diwheeldrive/can_tx"`).
    pub name: String,
    /// Where the task list came from (informational; set by the scenario builder).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source: Option<String>,
    /// Interrupt and dispatcher overheads, added to tasks by their `kind`.
    #[serde(default, skip_serializing_if = "Overheads::is_zero")]
    pub overheads: Overheads,
    /// Critical sections of the background (`idle`, priority 0) per resource, in µs.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub idle_critical_sections_us: BTreeMap<String, f64>,
    /// The task that moves queued frames into the CAN controller; its response time is added to the queuing
    /// jitter of every message sent from this board. It has no deadline of its own, nor have its jobs (tasks whose
    /// `job_of` names it; `deadline_us` is refused for them): the analysis requires only that they are bounded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub can_tx_task: Option<String>,
    /// Static resource ceilings (RTIC computes them from every task that *may* lock a resource, including tasks
    /// with no jobs in this model): a resource's ceiling is the larger of this and its users' priorities.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub ceilings: BTreeMap<String, u32>,
    /// The tasks (jobs) to analyse.
    #[serde(default)]
    pub tasks: Vec<TaskModel>,
    /// The board's sensor buses (I2C), each with its engine's interrupt, where a task's `script` runs
    /// ([`crate::sensor_bus`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub sensor_buses: Vec<crate::sensor_bus::SensorBusModel>,
}

/// Per-board overheads in µs (all default to 0).
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Overheads {
    /// Exception entry (stacking, vector fetch, RTIC prologue): added to every `hardware` and `software` job.
    #[serde(default)]
    pub isr_entry_us: f64,
    /// Exception return (unstacking, RTIC epilogue): added to every `hardware` and `software` job.
    #[serde(default)]
    pub isr_exit_us: f64,
    /// The RTIC dispatcher (executor poll of an async task): added to every `software` job.
    #[serde(default)]
    pub dispatcher_us: f64,
}

impl Overheads {
    fn is_zero(&self) -> bool {
        *self == Overheads::default()
    }
}

/// How a task is activated, which decides the overheads added to it.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum TaskKind {
    /// No overheads added: `wcet_us` is everything (imported task sets).
    #[default]
    Plain,
    /// An interrupt handler (RTIC `binds = ...`): entry and exit added.
    Hardware,
    /// An RTIC software task run by a dispatcher interrupt: entry, exit and dispatcher added.
    Software,
}

/// One task, or one kind of job of an RTIC task (a publisher task serves several topics, one job each).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TaskModel {
    /// Name, unique on the board.
    pub name: String,
    /// RTIC priority: a higher number is more urgent.
    pub priority: u32,
    /// Worst-case execution time of one job, µs.
    pub wcet_us: f64,
    /// Period, or minimum inter-arrival time when `sporadic`, µs.
    pub period_us: f64,
    /// Deadline from the activation, µs; defaults to the period and may exceed it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub deadline_us: Option<f64>,
    /// Release jitter, µs (default 0).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub jitter_us: f64,
    /// Longest critical section per shared resource, µs. Which tasks name a resource decides its ceiling.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub critical_sections_us: BTreeMap<String, f64>,
    /// Blocking to use instead of the SRP blocking computed from the critical sections, µs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub blocking_us: Option<f64>,
    /// Best-case execution time, µs (default 0); the best case of a topic's delivery starts here.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bcet_us: Option<f64>,
    /// Which overheads apply (default `plain`: none).
    #[serde(default, skip_serializing_if = "is_plain")]
    pub kind: TaskKind,
    /// The task whose completion releases this one (same board); its worst response is added to the jitter.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub released_by: Option<String>,
    /// The period is a minimum inter-arrival time (informational: the analysis is the same).
    #[serde(default, skip_serializing_if = "is_false")]
    pub sporadic: bool,
    /// The RTIC task this is a job of (informational, for grouping in reports; the jobs of one task run one
    /// after the other, which the self-suspension analysis reads).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub job_of: Option<String>,
    /// The script each job runs on one of the board's sensor buses, suspending until it ends
    /// ([`crate::sensor_bus`]); `wcet_us` is then the job's CPU alone.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub script: Option<crate::sensor_bus::ScriptModel>,
    /// A job of several scripts, in the order the job runs them (each submitted when the one before it ends and
    /// its `settle_us` has passed); instead of `script`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scripts: Option<Vec<crate::sensor_bus::ScriptModel>>,
}

/// The CAN bus.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CanModel {
    /// Bits per second (default 1 000 000).
    #[serde(default = "default_bitrate")]
    pub bitrate: u32,
    /// Frame-cost model: `"thesis"`, `"exact"` (default) or a number of µs per frame.
    #[serde(default)]
    pub frame_cost: FrameCostSpec,
    /// The message streams.
    #[serde(default)]
    pub messages: Vec<MessageModel>,
}

fn default_bitrate() -> u32 {
    can::DEFAULT_BITRATE
}

/// One message stream (one topic, one identifier).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct MessageModel {
    /// Name, unique on the bus (the topic).
    pub name: String,
    /// Identifier (11 bits, or 29 with `extended`).
    pub id: u32,
    /// Data bytes per frame, 0..=8.
    pub dlc: u8,
    /// Period or minimum inter-arrival time, µs.
    pub period_us: f64,
    /// Deadline, µs, measured from the sender's activation when `sender` is set, else from queuing; defaults to
    /// the period.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub deadline_us: Option<f64>,
    /// Queuing jitter of its own, µs (default 0); a sender's response variation is added to it.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub jitter_us: f64,
    /// `"board/task"` that queues the message: its response variation becomes queuing jitter.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sender: Option<String>,
    /// `"board/task"` that handles the frame on arrival (commands): the end-to-end time includes its response.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub receiver: Option<String>,
    /// Frames queued per activation (default 1; 8 for a proximity-ring sample).
    #[serde(default = "one", skip_serializing_if = "is_one")]
    pub frames: u32,
    /// 29-bit identifier (default false).
    #[serde(default, skip_serializing_if = "is_false")]
    pub extended: bool,
    /// End-to-end jitter budget, µs: the delivery jitter may not exceed it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub jitter_budget_us: Option<f64>,
    /// End-to-end deadline, µs (sender activation to receiver completion); defaults to `deadline_us`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub e2e_deadline_us: Option<f64>,
}

fn one() -> u32 {
    1
}
fn is_one(n: &u32) -> bool {
    *n == 1
}
fn is_zero(x: &f64) -> bool {
    *x == 0.0
}
fn is_false(b: &bool) -> bool {
    !*b
}
fn is_plain(k: &TaskKind) -> bool {
    *k == TaskKind::Plain
}

/// The frame-cost model as the model file and the command line spell it.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub enum FrameCostSpec {
    /// 545 µs per frame at 1 Mbit/s (109 bit times × 5 attempts).
    Thesis,
    /// Worst-case stuffing, Davis et al. 2007.
    #[default]
    Exact,
    /// A fixed number of µs per frame.
    Micros(f64),
}

impl FrameCostSpec {
    /// The core's frame cost.
    pub fn cost(self) -> FrameCost {
        match self {
            FrameCostSpec::Thesis => FrameCost::Thesis,
            FrameCostSpec::Exact => FrameCost::Exact,
            FrameCostSpec::Micros(us) => FrameCost::Fixed(Time::from_us_up(us)),
        }
    }

    /// `thesis`, `exact` or `fixed 100 µs`.
    pub fn label(self) -> String {
        match self {
            FrameCostSpec::Thesis => "thesis".into(),
            FrameCostSpec::Exact => "exact".into(),
            FrameCostSpec::Micros(us) => format!("fixed {} µs", Time::from_us_up(us)),
        }
    }

    /// Parses `thesis`, `exact` or a number of µs (the command-line form).
    pub fn parse(text: &str) -> Result<FrameCostSpec, String> {
        match text.trim() {
            "thesis" => Ok(FrameCostSpec::Thesis),
            "exact" => Ok(FrameCostSpec::Exact),
            other => match other.trim_end_matches("us").trim_end_matches("µs").trim().parse::<f64>() {
                Ok(us) if us.is_finite() && us > 0.0 && us <= Time::LIMIT_US => Ok(FrameCostSpec::Micros(us)),
                _ => Err(format!(
                    "unknown frame cost `{text}`: expected \"thesis\", \"exact\" or a positive number of microseconds"
                )),
            },
        }
    }
}

impl Serialize for FrameCostSpec {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        match self {
            FrameCostSpec::Thesis => serializer.serialize_str("thesis"),
            FrameCostSpec::Exact => serializer.serialize_str("exact"),
            FrameCostSpec::Micros(us) => serializer.serialize_f64(*us),
        }
    }
}

impl<'de> Deserialize<'de> for FrameCostSpec {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct Visitor;
        impl serde::de::Visitor<'_> for Visitor {
            type Value = FrameCostSpec;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("\"thesis\", \"exact\" or a positive number of microseconds")
            }
            fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<FrameCostSpec, E> {
                match v {
                    "thesis" => Ok(FrameCostSpec::Thesis),
                    "exact" => Ok(FrameCostSpec::Exact),
                    _ => Err(E::invalid_value(serde::de::Unexpected::Str(v), &self)),
                }
            }
            fn visit_f64<E: serde::de::Error>(self, v: f64) -> Result<FrameCostSpec, E> {
                if v.is_finite() && v > 0.0 {
                    Ok(FrameCostSpec::Micros(v))
                } else {
                    Err(E::invalid_value(serde::de::Unexpected::Float(v), &self))
                }
            }
            fn visit_u64<E: serde::de::Error>(self, v: u64) -> Result<FrameCostSpec, E> {
                self.visit_f64(v as f64)
            }
            fn visit_i64<E: serde::de::Error>(self, v: i64) -> Result<FrameCostSpec, E> {
                self.visit_f64(v as f64)
            }
        }
        deserializer.deserialize_any(Visitor)
    }
}

/// A model that cannot be used, with the field it is about (`boards[0].tasks[2].period_us`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ModelError {
    /// Path of the field in the file.
    pub path: String,
    /// What is wrong with it.
    pub problem: String,
}

impl fmt::Display for ModelError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.path.is_empty() || self.path == "." {
            f.write_str(&self.problem)
        } else {
            write!(f, "`{}`: {}", self.path, self.problem)
        }
    }
}

impl std::error::Error for ModelError {}

fn error(path: impl Into<String>, problem: impl Into<String>) -> ModelError {
    ModelError {
        path: path.into(),
        problem: problem.into(),
    }
}

impl Model {
    /// Reads a model from JSON text; syntax and type errors name the field.
    pub fn from_json(text: &str) -> Result<Model, ModelError> {
        let mut de = serde_json::Deserializer::from_str(text);
        let model: Model = serde_path_to_error::deserialize(&mut de).map_err(|e| {
            let path = e.path().to_string();
            let inner = e.into_inner();
            error(path, format!("{inner}"))
        })?;
        de.end().map_err(|e| error("", format!("{e}")))?;
        Ok(model)
    }

    /// The model as pretty JSON (the format [`Model::from_json`] reads).
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).unwrap_or_else(|e| format!("{{\"error\": \"{e}\"}}"))
    }

    /// Checks every field and resolves names and times into the [`System`] the analysis runs on.
    pub fn validate(&self) -> Result<System, ModelError> {
        let mut boards = Vec::with_capacity(self.boards.len());
        let mut board_index = HashMap::new();
        for (b, board) in self.boards.iter().enumerate() {
            let path = format!("boards[{b}]");
            if board.name.trim().is_empty() || board.name.contains('/') {
                return Err(error(
                    format!("{path}.name"),
                    "must be a non-empty name without `/`",
                ));
            }
            if board_index.insert(board.name.as_str(), b).is_some() {
                return Err(error(
                    format!("{path}.name"),
                    format!("board `{}` is defined twice", board.name),
                ));
            }
            boards.push(validate_board(board, &path)?);
        }
        let bus = match &self.can {
            None => None,
            Some(bus) => Some(validate_bus(bus, &boards, &board_index)?),
        };
        Ok(System {
            name: self.name.clone(),
            boards,
            bus,
        })
    }
}

/// Most tasks one board may have: larger sets are refused instead of analysed for minutes (the benchmark covers
/// up to this size; docs/analysis.md).
pub const MAX_TASKS_PER_BOARD: usize = 10_000;
/// Most message streams on the bus, for the same reason.
pub const MAX_MESSAGES: usize = 10_000;

fn in_range(value: f64, path: &str) -> Result<(), ModelError> {
    if value > Time::LIMIT_US {
        Err(error(
            path,
            format!(
                "{value} µs is beyond the longest time the analysis represents exactly \
                 ({} µs, about 11.6 days)",
                Time::LIMIT_US
            ),
        ))
    } else {
        Ok(())
    }
}

fn non_negative(value: f64, path: &str) -> Result<(), ModelError> {
    if value.is_finite() && value >= 0.0 {
        in_range(value, path)
    } else {
        Err(error(
            path,
            format!("must be a finite number ≥ 0, got {value}"),
        ))
    }
}

fn positive(value: f64, path: &str) -> Result<(), ModelError> {
    if value.is_finite() && value > 0.0 {
        in_range(value, path)
    } else {
        Err(error(
            path,
            format!("must be a finite number > 0, got {value}"),
        ))
    }
}

fn validate_board(board: &BoardModel, path: &str) -> Result<BoardSystem, ModelError> {
    let o = &board.overheads;
    non_negative(o.isr_entry_us, &format!("{path}.overheads.isr_entry_us"))?;
    non_negative(o.isr_exit_us, &format!("{path}.overheads.isr_exit_us"))?;
    non_negative(o.dispatcher_us, &format!("{path}.overheads.dispatcher_us"))?;
    let overheads = OverheadTimes {
        isr_entry: Time::from_us_up(o.isr_entry_us),
        isr_exit: Time::from_us_up(o.isr_exit_us),
        dispatcher: Time::from_us_up(o.dispatcher_us),
    };
    let mut idle_sections = Vec::new();
    for (resource, &length) in &board.idle_critical_sections_us {
        non_negative(
            length,
            &format!("{path}.idle_critical_sections_us.{resource}"),
        )?;
        idle_sections.push((resource.clone(), Time::from_us_up(length)));
    }
    if board.tasks.len() > MAX_TASKS_PER_BOARD {
        return Err(error(
            format!("{path}.tasks"),
            format!(
                "{} tasks: the analysis accepts at most {MAX_TASKS_PER_BOARD} per board",
                board.tasks.len()
            ),
        ));
    }

    let mut names = HashMap::new();
    for (t, task) in board.tasks.iter().enumerate() {
        if task.name.trim().is_empty() || task.name.contains('/') {
            return Err(error(
                format!("{path}.tasks[{t}].name"),
                "must be a non-empty name without `/`",
            ));
        }
        if names.insert(task.name.as_str(), t).is_some() {
            return Err(error(
                format!("{path}.tasks[{t}].name"),
                format!(
                    "task `{}` is defined twice on board `{}`",
                    task.name, board.name
                ),
            ));
        }
    }
    let mut tasks = Vec::with_capacity(board.tasks.len());
    for (t, task) in board.tasks.iter().enumerate() {
        let p = format!("{path}.tasks[{t}]");
        non_negative(task.wcet_us, &format!("{p}.wcet_us"))?;
        positive(task.period_us, &format!("{p}.period_us"))?;
        if let Some(d) = task.deadline_us {
            positive(d, &format!("{p}.deadline_us"))?;
        }
        non_negative(task.jitter_us, &format!("{p}.jitter_us"))?;
        if let Some(b) = task.blocking_us {
            non_negative(b, &format!("{p}.blocking_us"))?;
        }
        if let Some(bcet) = task.bcet_us {
            non_negative(bcet, &format!("{p}.bcet_us"))?;
            if bcet > task.wcet_us {
                return Err(error(
                    format!("{p}.bcet_us"),
                    format!("{bcet} exceeds wcet_us {}", task.wcet_us),
                ));
            }
        }
        let mut sections = Vec::new();
        for (resource, &length) in &task.critical_sections_us {
            let field = format!("{p}.critical_sections_us.{resource}");
            non_negative(length, &field)?;
            if length > task.wcet_us {
                return Err(error(
                    field,
                    format!(
                        "{length} µs is longer than the task's wcet_us {}",
                        task.wcet_us
                    ),
                ));
            }
            sections.push((resource.clone(), Time::from_us_up(length)));
        }
        let released_by = match &task.released_by {
            None => None,
            Some(name) => match names.get(name.as_str()) {
                Some(&r) if r != t => Some(r),
                Some(_) => {
                    return Err(error(
                        format!("{p}.released_by"),
                        "a task cannot release itself",
                    ))
                }
                None => {
                    return Err(error(
                        format!("{p}.released_by"),
                        format!("no task `{name}` on board `{}`", board.name),
                    ))
                }
            },
        };
        let period = Time::from_us_down(task.period_us);
        tasks.push(TaskSpec {
            name: task.name.clone(),
            priority: task.priority,
            wcet: Time::from_us_up(task.wcet_us),
            bcet: Time::from_us_down(task.bcet_us.unwrap_or(0.0)),
            period,
            deadline: task.deadline_us.map_or(period, Time::from_us_down),
            deadline_follows_period: task.deadline_us.is_none(),
            jitter: Time::from_us_up(task.jitter_us),
            sections,
            blocking: task.blocking_us.map(Time::from_us_up),
            kind: task.kind,
            released_by,
            sporadic: task.sporadic,
            job_of: task.job_of.clone(),
        });
    }
    // Release chains must end: a cycle would make the jitters depend on themselves.
    for start in 0..tasks.len() {
        let mut seen = BTreeSet::new();
        let mut at = start;
        while let Some(next) = tasks.get(at).and_then(|t| t.released_by) {
            if !seen.insert(next) || next == start {
                return Err(error(
                    format!("{path}.tasks[{start}].released_by"),
                    "release chain forms a cycle",
                ));
            }
            at = next;
        }
    }
    let sensor_buses = crate::sensor_bus::validate_board(board, &overheads, &mut tasks).map_err(
        |(field, e)| {
            error(
                if field.is_empty() {
                    path.to_string()
                } else {
                    format!("{path}.{field}")
                },
                e.to_string(),
            )
        },
    )?;
    let can_tx_task = match &board.can_tx_task {
        None => None,
        Some(name) => Some(*names.get(name.as_str()).ok_or_else(|| {
            error(
                format!("{path}.can_tx_task"),
                format!("no task `{name}` on board `{}`", board.name),
            )
        })?),
    };
    // The transmit task and its jobs have no deadline of their own (its response is every message's queuing
    // jitter; only their bounds are checked): a deadline given for one would be read as checked and is refused.
    if let Some(tx) = can_tx_task.and_then(|i| board.tasks.get(i)) {
        for (i, t) in board.tasks.iter().enumerate() {
            let transmit = t.name == tx.name || t.job_of.as_deref() == Some(tx.name.as_str());
            if transmit && t.deadline_us.is_some() {
                return Err(error(
                    format!("{path}.tasks[{i}].deadline_us"),
                    "the transmit task (`can_tx_task`) and its jobs have no deadline of their own: its response is \
                     every message's queuing jitter, and only their bounds are checked"
                        .to_string(),
                ));
            }
        }
    }
    Ok(BoardSystem {
        name: board.name.clone(),
        overheads,
        tasks,
        idle_sections,
        can_tx_task,
        static_ceilings: board.ceilings.clone().into_iter().collect(),
        sensor_buses,
    })
}

fn resolve_task(
    reference: &str,
    path: String,
    boards: &[BoardSystem],
    board_index: &HashMap<&str, usize>,
) -> Result<TaskRef, ModelError> {
    let Some((board_name, task_name)) = reference.split_once('/') else {
        return Err(error(
            path,
            format!("`{reference}` is not of the form \"board/task\""),
        ));
    };
    let &board = board_index.get(board_name).ok_or_else(|| {
        error(
            path.clone(),
            format!("no board `{board_name}` in the model"),
        )
    })?;
    let task = boards
        .get(board)
        .and_then(|b| b.tasks.iter().position(|t| t.name == task_name))
        .ok_or_else(|| {
            error(
                path,
                format!("no task `{task_name}` on board `{board_name}`"),
            )
        })?;
    Ok(TaskRef { board, task })
}

fn validate_bus(
    bus: &CanModel,
    boards: &[BoardSystem],
    board_index: &HashMap<&str, usize>,
) -> Result<BusSystem, ModelError> {
    if bus.bitrate == 0 {
        return Err(error("can.bitrate", "must be greater than 0"));
    }
    if let FrameCostSpec::Micros(us) = bus.frame_cost {
        positive(us, "can.frame_cost")?;
    }
    if bus.messages.len() > MAX_MESSAGES {
        return Err(error(
            "can.messages",
            format!(
                "{} messages: the analysis accepts at most {MAX_MESSAGES}",
                bus.messages.len()
            ),
        ));
    }
    let mut names = HashSet::new();
    let mut ids: HashMap<u32, usize> = HashMap::new();
    let mut messages = Vec::with_capacity(bus.messages.len());
    for (m, message) in bus.messages.iter().enumerate() {
        let p = format!("can.messages[{m}]");
        if message.name.trim().is_empty() {
            return Err(error(format!("{p}.name"), "must not be empty"));
        }
        if !names.insert(message.name.as_str()) {
            return Err(error(
                format!("{p}.name"),
                format!("message `{}` is defined twice", message.name),
            ));
        }
        let max_id = if message.extended { 0x1FFF_FFFF } else { 0x7FF };
        if message.id > max_id {
            return Err(error(
                format!("{p}.id"),
                format!(
                    "{:#x} does not fit in {} bits",
                    message.id,
                    if message.extended { 29 } else { 11 }
                ),
            ));
        }
        let key = can::arbitration_key(message.id, message.extended);
        if let Some(&other) = ids.get(&key) {
            let other_name = bus.messages.get(other).map_or("?", |o| o.name.as_str());
            return Err(error(
                format!("{p}.id"),
                format!("{:#x} is already used by `{other_name}`: two streams cannot share an identifier", message.id),
            ));
        }
        ids.insert(key, m);
        if message.dlc > 8 {
            return Err(error(
                format!("{p}.dlc"),
                format!("{} is more than 8 data bytes", message.dlc),
            ));
        }
        positive(message.period_us, &format!("{p}.period_us"))?;
        if let Some(d) = message.deadline_us {
            positive(d, &format!("{p}.deadline_us"))?;
        }
        non_negative(message.jitter_us, &format!("{p}.jitter_us"))?;
        if message.frames == 0 {
            return Err(error(format!("{p}.frames"), "must be at least 1"));
        }
        if let Some(b) = message.jitter_budget_us {
            non_negative(b, &format!("{p}.jitter_budget_us"))?;
        }
        if let Some(d) = message.e2e_deadline_us {
            positive(d, &format!("{p}.e2e_deadline_us"))?;
        }
        let sender = match &message.sender {
            None => None,
            Some(s) => Some(resolve_task(s, format!("{p}.sender"), boards, board_index)?),
        };
        let receiver = match &message.receiver {
            None => None,
            Some(r) => Some(resolve_task(
                r,
                format!("{p}.receiver"),
                boards,
                board_index,
            )?),
        };
        let period = Time::from_us_down(message.period_us);
        messages.push(MessageSpec {
            name: message.name.clone(),
            id: message.id,
            extended: message.extended,
            dlc: message.dlc,
            frames: message.frames,
            period,
            deadline: message.deadline_us.map_or(period, Time::from_us_down),
            deadline_follows_period: message.deadline_us.is_none(),
            jitter: Time::from_us_up(message.jitter_us),
            sender,
            receiver,
            jitter_budget: message.jitter_budget_us.map(Time::from_us_down),
            e2e_deadline: message.e2e_deadline_us.map(Time::from_us_down),
        });
    }
    Ok(BusSystem {
        bitrate: bus.bitrate,
        bit_time: can::bit_time(bus.bitrate),
        frame_cost: bus.frame_cost,
        messages,
    })
}

/// A validated model: names resolved to indices, times in nanoseconds.
#[derive(Debug, Clone, PartialEq)]
pub struct System {
    /// The model's label.
    pub name: Option<String>,
    /// The boards.
    pub boards: Vec<BoardSystem>,
    /// The bus.
    pub bus: Option<BusSystem>,
}

/// Overheads as times.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct OverheadTimes {
    /// Exception entry.
    pub isr_entry: Time,
    /// Exception return.
    pub isr_exit: Time,
    /// Dispatcher / executor poll.
    pub dispatcher: Time,
}

impl OverheadTimes {
    /// What a job of this kind costs on top of its own execution.
    pub fn for_kind(&self, kind: TaskKind) -> Time {
        match kind {
            TaskKind::Plain => Time::ZERO,
            TaskKind::Hardware => self.isr_entry.plus(self.isr_exit),
            TaskKind::Software => self.isr_entry.plus(self.isr_exit).plus(self.dispatcher),
        }
    }
}

/// A validated board.
#[derive(Debug, Clone, PartialEq)]
pub struct BoardSystem {
    /// Name.
    pub name: String,
    /// Overheads.
    pub overheads: OverheadTimes,
    /// Tasks in file order.
    pub tasks: Vec<TaskSpec>,
    /// Critical sections of the background.
    pub idle_sections: Vec<(String, Time)>,
    /// Index of the task that feeds the CAN controller.
    pub can_tx_task: Option<usize>,
    /// Static ceilings given in the model.
    pub static_ceilings: Vec<(String, u32)>,
    /// Its sensor buses and the scripts its tasks run on them (none: the board is analysed as without buses).
    pub sensor_buses: crate::sensor_bus::BoardBuses,
}

impl BoardSystem {
    /// Whether task `i` is the transmit interrupt (`can_tx_task`) or one of its jobs (a task whose `job_of` names
    /// it: the `can_tx[…]` rows of a transmit interrupt charged by its parts). Such a row has no deadline of its own:
    /// only its bound is checked, and the transmit task's WCRT is every message's queuing jitter
    /// (docs/analysis.md, "The transmit interrupt keeps no deadline").
    pub fn is_transmit(&self, i: usize) -> bool {
        let Some(tx) = self.can_tx_task else {
            return false;
        };
        i == tx
            || self.tasks.get(tx).is_some_and(|t| {
                self.tasks
                    .get(i)
                    .is_some_and(|job| job.job_of.as_deref() == Some(t.name.as_str()))
            })
    }
}

/// A validated task.
#[derive(Debug, Clone, PartialEq)]
pub struct TaskSpec {
    /// Name.
    pub name: String,
    /// RTIC priority.
    pub priority: u32,
    /// Worst-case execution time without overheads.
    pub wcet: Time,
    /// Best-case execution time.
    pub bcet: Time,
    /// Period or minimum inter-arrival time.
    pub period: Time,
    /// Deadline.
    pub deadline: Time,
    /// The deadline was not given and follows the period (sensitivity moves it along).
    pub deadline_follows_period: bool,
    /// Release jitter of its own.
    pub jitter: Time,
    /// Critical sections: resource and longest length.
    pub sections: Vec<(String, Time)>,
    /// Explicit blocking replacing SRP's.
    pub blocking: Option<Time>,
    /// Overhead class.
    pub kind: TaskKind,
    /// Index of the releasing task.
    pub released_by: Option<usize>,
    /// Sporadic (informational).
    pub sporadic: bool,
    /// RTIC task this is a job of.
    pub job_of: Option<String>,
}

/// A validated bus.
#[derive(Debug, Clone, PartialEq)]
pub struct BusSystem {
    /// Bits per second.
    pub bitrate: u32,
    /// One bit time.
    pub bit_time: Time,
    /// The model file's frame-cost model.
    pub frame_cost: FrameCostSpec,
    /// Messages in file order.
    pub messages: Vec<MessageSpec>,
}

/// A task on a board.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct TaskRef {
    /// Board index.
    pub board: usize,
    /// Task index on that board.
    pub task: usize,
}

/// A validated message.
#[derive(Debug, Clone, PartialEq)]
pub struct MessageSpec {
    /// Name.
    pub name: String,
    /// Identifier.
    pub id: u32,
    /// 29-bit identifier.
    pub extended: bool,
    /// Data bytes per frame.
    pub dlc: u8,
    /// Frames per activation.
    pub frames: u32,
    /// Period.
    pub period: Time,
    /// Deadline.
    pub deadline: Time,
    /// The deadline follows the period.
    pub deadline_follows_period: bool,
    /// Own queuing jitter.
    pub jitter: Time,
    /// Sending task.
    pub sender: Option<TaskRef>,
    /// Receiving task.
    pub receiver: Option<TaskRef>,
    /// End-to-end jitter budget.
    pub jitter_budget: Option<Time>,
    /// End-to-end deadline.
    pub e2e_deadline: Option<Time>,
}

impl MessageSpec {
    /// The deadline of the whole path, sender activation to receiver completion.
    pub fn end_to_end_deadline(&self) -> Time {
        self.e2e_deadline.unwrap_or(self.deadline)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn empty_model_is_valid() {
        let model = Model::from_json("{}").map_err(|e| e.to_string());
        assert_eq!(model.as_ref().map(|m| m.boards.len()), Ok(0));
    }

    #[test]
    fn frame_cost_forms() {
        assert_eq!(FrameCostSpec::parse("thesis"), Ok(FrameCostSpec::Thesis));
        assert_eq!(
            FrameCostSpec::parse("130"),
            Ok(FrameCostSpec::Micros(130.0))
        );
        assert_eq!(
            FrameCostSpec::parse("130us"),
            Ok(FrameCostSpec::Micros(130.0))
        );
        assert!(FrameCostSpec::parse("fast").is_err());
        assert!(FrameCostSpec::parse("-3").is_err());
    }
}
