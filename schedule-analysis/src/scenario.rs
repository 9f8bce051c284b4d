//! The project's default model, built from three sources so that none of them can drift from the others:
//!
//! 1. each board's **RTIC app**, read with [`crate::rtic_source`]: which tasks exist, their priorities, hardware
//!    bindings and shared resources (for a board without an app yet, its timing file declares them);
//! 2. each board's **timing file** (`models/<board>.timing.json`): execution-time budgets per task and per
//!    published topic, critical-section lengths, overheads, arrivals;
//! 3. a **scenario** (`models/<name>.scenario.json`): which topics run at which period and CAN priority, the
//!    operator's commands, deadlines and jitter budgets.
//!
//! A topic published at CAN priority P becomes a job of the board's publisher task for P (`publish_high` …), with
//! its own period and budget, woken by the monotonic's timer interrupt (a job of its own), and a message with
//! identifier `0x400 | P << 8 | topic` whose DLC and frames per sample come from `amiro_can::TOPICS`.
//! Every task the app declares must have a budget and every budget must name a declared task, or the build fails.

use std::collections::{BTreeMap, BTreeSet};
use std::fmt;
use std::path::{Path, PathBuf};

use amiro_can::{CanId, Kind, Priority, Topic, TopicInfo};
use serde::Deserialize;

use crate::can;
use crate::model::{
    BoardModel, CanModel, FrameCostSpec, MessageModel, Model, Overheads, TaskKind, TaskModel,
    GLOBAL_CRITICAL_SECTION,
};
use crate::rtic_source::{self, RticApp, RticTaskKind};
use crate::time::Time;

/// Where the default models live, relative to the workspace root.
pub const MODELS_DIR: &str = "schedule-analysis/models";
/// The scenario `cargo xtask analyze` uses when none is named.
pub const DEFAULT_SCENARIO: &str = "thesis-demo";

/// A board's timing file.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Timing {
    /// Board name (the firmware folder: `diwheeldrive`, `powermgmt`, `lightring`).
    pub board: String,
    /// Free text.
    #[serde(default)]
    pub note: Option<String>,
    /// The RTIC app to read; `null` while the board has none (tasks are then declared here).
    #[serde(default)]
    pub app: Option<AppSource>,
    /// Interrupt and dispatcher overheads.
    #[serde(default)]
    pub overheads: Overheads,
    /// What the firmware's task trace costs per job (a start and an end record), when the analysed
    /// build has it: added to every `hardware` and `software` job as interrupt entry and exit are.
    #[serde(default)]
    pub trace: Option<TraceCost>,
    /// The monotonic's timer interrupt, which wakes every timer-released task.
    #[serde(default)]
    pub monotonic: Option<Monotonic>,
    /// Publisher task per CAN priority (`urgent` … `low`); defaults to `publish_<level>`.
    #[serde(default = "default_publishers")]
    pub publishers: BTreeMap<String, String>,
    /// The task that acts on received commands (the end of a command's path).
    #[serde(default)]
    pub command_handler: Option<String>,
    /// The task that moves queued frames into the CAN controller.
    #[serde(default)]
    pub can_tx_task: Option<String>,
    /// Critical sections of `idle`, µs.
    #[serde(default)]
    pub idle_critical_sections_us: BTreeMap<String, f64>,
    /// Budgets per task (not the publisher tasks: their jobs are the topics).
    #[serde(default)]
    pub tasks: BTreeMap<String, TimingTask>,
    /// Budgets per published topic (one job of the publisher task per sample).
    #[serde(default)]
    pub topics: BTreeMap<String, TopicTiming>,
}

fn default_publishers() -> BTreeMap<String, String> {
    Priority::ALL
        .iter()
        .map(|p| (p.name().to_string(), format!("publish_{}", p.name())))
        .collect()
}

/// The cost of the firmware's task trace (`amiro_firmware::tracing`, cargo feature `feature`).
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TraceCost {
    /// The cargo feature that compiles the trace in (the analysed build has it).
    pub feature: String,
    /// One job's start and end records, µs.
    pub per_job_us: f64,
    /// Where the figure comes from.
    #[serde(default)]
    pub note: Option<String>,
    /// The traced QEMU build.
    #[serde(default)]
    pub qemu: Option<QemuBuild>,
}

/// How the traced QEMU build differs from the chip's (`Firmware::Qemu`).
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct QemuBuild {
    /// The trace's cost per job in QEMU, µs (measured: deterministic under `-icount`).
    pub per_job_us: f64,
    /// Every budget of the board times this (≥ 1: QEMU is never assumed faster than the chip).
    #[serde(default = "one")]
    pub budget_scale: f64,
    /// What pends the transmit task in QEMU (absent: the robot's arrival, one job per frame).
    #[serde(default)]
    pub transmit: Option<QemuTransmit>,
    /// Where the figures come from.
    #[serde(default)]
    pub note: Option<String>,
}

/// The transmit task of a QEMU build whose only frames are its publisher's samples.
///
/// QEMU's virtual mailboxes put a frame on the bus the moment it is offered: no transmit-complete
/// interrupt paces the transmit task. It runs when a publisher pends it after queueing a sample's
/// frames, and again at once while frames remain after three (`amiro_firmware::qemu::CanTxPort`):
/// ⌈frames / 3⌉ jobs per sample. So the task becomes one job per publisher job of the scenario
/// (`can_tx[topic]`, released by it) and one for the samples commands request (the task itself):
/// the command handler (`requests_from`) handles at most one command per its period, a request
/// wakes the publisher, and requests not yet served for one topic are one release — so in any
/// window at most one more per requestable topic than the handler's rate allows (the extra release
/// jitter of one period per topic).
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct QemuTransmit {
    /// The command handler whose commands request one-shot samples.
    pub requests_from: String,
    /// What the virtual mailbox costs per frame in QEMU, µs (it prints the frame's candump line),
    /// added to the transmit task's budget for each frame a job sends.
    #[serde(default)]
    pub frame_us: f64,
    /// Why this holds for the board.
    #[serde(default)]
    pub note: Option<String>,
}

/// The `frame-acked` records one job of the transmit task writes at most on the chip: one per
/// mailbox whose transmission completed (bxCAN has three).
pub const ACKS_PER_TRANSMIT_JOB: u64 = 3;

/// The frames one transmit job takes from the queue in QEMU (three virtual mailboxes).
pub const QEMU_FRAMES_PER_TRANSMIT_JOB: u64 = 3;

fn one() -> f64 {
    1.0
}

impl Timing {
    /// The timing with every execution budget, critical section and overhead times `factor`.
    fn scaled(&self, factor: f64) -> Timing {
        let mut t = self.clone();
        let f = factor.max(1.0);
        t.overheads.isr_entry_us *= f;
        t.overheads.isr_exit_us *= f;
        t.overheads.dispatcher_us *= f;
        if let Some(m) = &mut t.monotonic {
            m.timer_isr_us *= f;
        }
        for v in t.idle_critical_sections_us.values_mut() {
            *v *= f;
        }
        for task in t.tasks.values_mut() {
            task.wcet_us = task.wcet_us.map(|w| w * f);
            task.bcet_us = task.bcet_us.map(|w| w * f);
            for v in task.critical_sections_us.values_mut() {
                *v *= f;
            }
            if let Some(m) = &mut task.measured {
                m.wcet_us *= f;
            }
        }
        for topic in t.topics.values_mut() {
            topic.wcet_us *= f;
            topic.bcet_us = topic.bcet_us.map(|w| w * f);
            for v in topic.critical_sections_us.values_mut() {
                *v *= f;
            }
            if let Some(m) = &mut topic.measured {
                m.wcet_us *= f;
            }
        }
        t
    }
}

/// A budget measured on a bench (`cargo xtask bench --calibrate`), kept beside the estimate.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Measured {
    /// The budget the analysis uses: the largest execution time seen times `margin`, µs.
    pub wcet_us: f64,
    /// The largest execution time seen, µs.
    pub max_us: f64,
    /// The margin `wcet_us` adds to `max_us`.
    pub margin: f64,
    /// Jobs measured.
    pub jobs: u64,
    /// The capture it came from.
    pub origin: String,
    /// `robot` (the real chip) or `qemu` (the emulator: not the chip's times).
    pub build: String,
}

/// Where a board's app is.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct AppSource {
    /// The file with `#[rtic::app]`, relative to the workspace root.
    pub source: String,
    /// A stand-in app description used while `source` is still a skeleton without any budgeted task.
    #[serde(default)]
    pub fallback: Option<String>,
    /// Cargo features the analysed build has (for `#[cfg(feature = ..)]` on tasks); none = the real board.
    #[serde(default)]
    pub features: Vec<String>,
}

/// The monotonic's timer interrupt.
#[derive(Debug, Clone, Copy, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Monotonic {
    /// Its RTIC/NVIC logical priority.
    pub priority: u32,
    /// Execution time of one timer interrupt (timer queue, waking one task), µs, entry/exit overheads excluded.
    pub timer_isr_us: f64,
    /// Tick length, µs: a wake-up comes up to one tick late.
    #[serde(default)]
    pub tick_us: f64,
}

/// How often a task is activated.
#[derive(Debug, Clone, Copy, Deserialize, PartialEq)]
#[serde(rename_all = "snake_case")]
pub enum Arrival {
    /// At most once per frame on the bus: the shortest frame (47 bit times) apart.
    BusFrame,
    /// At most once per frame this board sends: the shortest of its frames apart (its transmit-complete
    /// interrupt); the shortest frame on the bus when it sends nothing.
    OwnFrame,
    /// Periodically, µs.
    PeriodicUs(f64),
    /// At most once per this many µs.
    SporadicUs(f64),
}

/// Budgets of one task.
#[derive(Debug, Clone, Deserialize, PartialEq, Default)]
#[serde(deny_unknown_fields)]
pub struct TimingTask {
    /// Priority — only for a board without an app (an app's priorities come from its source).
    #[serde(default)]
    pub priority: Option<u32>,
    /// Interrupt the task is bound to — only without an app; a task without one is a software task.
    #[serde(default)]
    pub binds: Option<String>,
    /// Shared resources — only without an app; defaults to the keys of `critical_sections_us`.
    #[serde(default)]
    pub shared: Option<Vec<String>>,
    /// Worst-case execution time, µs.
    #[serde(default)]
    pub wcet_us: Option<f64>,
    /// Best-case execution time, µs.
    #[serde(default)]
    pub bcet_us: Option<f64>,
    /// Activation pattern.
    #[serde(default)]
    pub arrival: Option<Arrival>,
    /// `"timer"` (woken by the monotonic) or the task that releases it.
    #[serde(default)]
    pub released_by: Option<String>,
    /// Release jitter of its own, µs.
    #[serde(default)]
    pub jitter_us: f64,
    /// Deadline, µs (default: the period).
    #[serde(default)]
    pub deadline_us: Option<f64>,
    /// Longest critical section per resource, µs.
    #[serde(default)]
    pub critical_sections_us: BTreeMap<String, f64>,
    /// Free text: where the budget comes from.
    #[serde(default)]
    pub note: Option<String>,
    /// A measured budget; when present the analysis uses it instead of `wcet_us` (the estimate).
    #[serde(default)]
    pub measured: Option<Measured>,
}

/// Budgets of one published topic: one job of the publisher task per sample.
#[derive(Debug, Clone, Deserialize, PartialEq, Default)]
#[serde(deny_unknown_fields)]
pub struct TopicTiming {
    /// Worst-case execution time of one sample (read, encode, queue every frame), µs.
    pub wcet_us: f64,
    /// Best-case execution time, µs (the earliest the frame can be queued).
    #[serde(default)]
    pub bcet_us: Option<f64>,
    /// Longest critical section per resource, µs.
    #[serde(default)]
    pub critical_sections_us: BTreeMap<String, f64>,
    /// Free text.
    #[serde(default)]
    pub note: Option<String>,
    /// A measured budget; when present the analysis uses it instead of `wcet_us` (the estimate).
    #[serde(default)]
    pub measured: Option<Measured>,
}

/// A scenario: what runs on the robot.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    /// Name.
    pub name: String,
    /// Free text.
    #[serde(default)]
    pub description: Option<String>,
    /// Bus bit rate (default 1 Mbit/s).
    #[serde(default = "default_bitrate")]
    pub bitrate: u32,
    /// Frame-cost model that decides the verdict (default exact).
    #[serde(default)]
    pub frame_cost: FrameCostSpec,
    /// Running sensor publishers.
    #[serde(default)]
    pub publishers: Vec<ScenarioPublisher>,
    /// Commands the operator sends.
    #[serde(default)]
    pub commands: Vec<ScenarioCommand>,
    /// One-shot requests (`once`) the operator sends: each analysed as a sample of its topic at its priority every
    /// [`amiro_can::ONE_SHOT_INTERVAL_MS`] (how often a board takes one at most), in place of the topic's publisher —
    /// what the boards' admission check decides a one-shot as.
    #[serde(default)]
    pub one_shots: Vec<ScenarioOneShot>,
}

/// A one-shot request: a sensor topic's sample at a priority, asked for again and again.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ScenarioOneShot {
    /// Topic name as `amiro_can` spells it.
    pub topic: String,
    /// CAN priority.
    pub priority: String,
}

fn default_bitrate() -> u32 {
    can::DEFAULT_BITRATE
}

/// A sensor topic being published.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ScenarioPublisher {
    /// Topic name as `amiro_can` spells it (`gyroscope`, `proximity-ring`).
    pub topic: String,
    /// CAN priority: `urgent`, `high`, `medium` (or `normal`), `low`.
    pub priority: String,
    /// Sample period, µs.
    pub period_us: f64,
    /// Deadline from the sample's due time to its last frame on the bus, µs (default: the period).
    #[serde(default)]
    pub deadline_us: Option<f64>,
    /// Budget for the delivery jitter, µs.
    #[serde(default)]
    pub jitter_budget_us: Option<f64>,
}

/// A command stream from the operator.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ScenarioCommand {
    /// Actuator topic (`motor`, `led-3`).
    pub topic: String,
    /// CAN priority.
    pub priority: String,
    /// Shortest time between two commands, µs.
    pub period_us: f64,
    /// The operator's queuing jitter, µs.
    #[serde(default)]
    pub jitter_us: f64,
    /// Deadline from sending to the board having acted, µs (default: the period).
    #[serde(default)]
    pub deadline_us: Option<f64>,
    /// Budget for the jitter, µs.
    #[serde(default)]
    pub jitter_budget_us: Option<f64>,
}

/// The built model and how it was made.
#[derive(Debug, Clone, PartialEq)]
pub struct Built {
    /// The analysable model.
    pub model: Model,
    /// The scenario's frame-cost model.
    pub frame_cost: FrameCostSpec,
    /// Where each board's task list came from.
    pub sources: Vec<String>,
    /// Things the reader should know (fallbacks, assumed lengths).
    pub warnings: Vec<String>,
}

/// A file that cannot be used, with the field it is about.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BuildError {
    /// The file, relative to the workspace root.
    pub file: String,
    /// The field (`tasks.can_rx.wcet_us`), empty for the whole file.
    pub path: String,
    /// What is wrong.
    pub problem: String,
}

impl fmt::Display for BuildError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.path.is_empty() {
            write!(f, "{}: {}", self.file, self.problem)
        } else {
            write!(f, "{}: `{}`: {}", self.file, self.path, self.problem)
        }
    }
}

impl std::error::Error for BuildError {}

fn fail(file: &str, path: impl Into<String>, problem: impl Into<String>) -> BuildError {
    BuildError {
        file: file.to_string(),
        path: path.into(),
        problem: problem.into(),
    }
}

/// The firmware folder of an `amiro_can` board.
pub fn board_folder(board: amiro_can::Board) -> &'static str {
    match board {
        amiro_can::Board::DiWheelDrive => "diwheeldrive",
        amiro_can::Board::PowerManagement => "powermgmt",
        amiro_can::Board::LightRing => "lightring",
    }
}

fn display(root: &Path, path: &Path) -> String {
    path.strip_prefix(root)
        .unwrap_or(path)
        .display()
        .to_string()
}

fn read_json<T: for<'de> Deserialize<'de>>(root: &Path, path: &Path) -> Result<T, BuildError> {
    let file = display(root, path);
    let text =
        std::fs::read_to_string(path).map_err(|e| fail(&file, "", format!("cannot read: {e}")))?;
    let mut de = serde_json::Deserializer::from_str(&text);
    let value: T = serde_path_to_error::deserialize(&mut de).map_err(|e| {
        let path = e.path().to_string();
        fail(
            &file,
            if path == "." { String::new() } else { path },
            e.into_inner().to_string(),
        )
    })?;
    de.end().map_err(|e| fail(&file, "", e.to_string()))?;
    Ok(value)
}

/// Finds a scenario by path, or by name in the models folder (`thesis-demo` → `models/thesis-demo.scenario.json`).
pub fn find_scenario(root: &Path, name_or_path: &str) -> PathBuf {
    let direct = PathBuf::from(name_or_path);
    if direct.extension().is_some() || direct.components().count() > 1 {
        if direct.is_absolute() {
            return direct;
        }
        let in_cwd = std::env::current_dir()
            .map(|d| d.join(&direct))
            .unwrap_or_else(|_| direct.clone());
        return if in_cwd.exists() {
            in_cwd
        } else {
            root.join(direct)
        };
    }
    root.join(MODELS_DIR)
        .join(format!("{name_or_path}.scenario.json"))
}

/// The environment variable naming the board revision of the robot analysed (`1-2`, `1-1`): the timing
/// files in `models/rev-<revision>/` replace the models folder's files of the same name (DiWheelDrive 1-2's
/// BNO055 budgets). Unset, or a revision without its own files: the models folder's files alone (the
/// revision they describe is each file's `note`). `cargo xtask` sets it per build and analysis; the boards'
/// build script sets it from the board's revision feature.
pub const REVISION_ENV: &str = "AMIRO_REVISION";

/// The timing files in the models folder, in the order of `amiro_can::Board::ALL`, then by name, for the
/// revision [`REVISION_ENV`] names (see [`timing_files_for`]).
pub fn timing_files(root: &Path) -> Vec<PathBuf> {
    let revision = std::env::var(REVISION_ENV).ok();
    timing_files_for(root, revision.as_deref().filter(|r| !r.is_empty()))
}

/// The timing files of a robot of board revision `revision`: the models folder's, each replaced by its
/// namesake in `models/rev-<revision>/` where that exists; in the order of [`timing_files`].
pub fn timing_files_for(root: &Path, revision: Option<&str>) -> Vec<PathBuf> {
    let mut files = base_timing_files(root);
    if let Some(revision) = revision {
        let dir = root.join(MODELS_DIR).join(format!("rev-{revision}"));
        for file in &mut files {
            if let Some(name) = file.file_name() {
                let own = dir.join(name);
                if own.is_file() {
                    *file = own;
                }
            }
        }
    }
    files
}

fn base_timing_files(root: &Path) -> Vec<PathBuf> {
    let dir = root.join(MODELS_DIR);
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .map(|entries| {
            entries
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| {
                    p.file_name()
                        .and_then(|n| n.to_str())
                        .is_some_and(|n| n.ends_with(".timing.json"))
                })
                .collect()
        })
        .unwrap_or_default();
    let rank = |p: &PathBuf| {
        let name = p.file_name().and_then(|n| n.to_str()).unwrap_or("");
        let board = name.trim_end_matches(".timing.json");
        let position = amiro_can::Board::ALL
            .iter()
            .position(|b| board_folder(*b) == board)
            .unwrap_or(usize::MAX);
        (position, name.to_string())
    };
    files.sort_by_key(rank);
    files
}

/// What the scenario puts on one board.
struct Planned {
    info: &'static TopicInfo,
    priority: Priority,
    index: usize,
}

/// Builds the model of `scenario` from the timing files (and the apps they point to).
pub fn build(
    root: &Path,
    scenario_path: &Path,
    timing_paths: &[PathBuf],
) -> Result<Built, BuildError> {
    build_for(root, scenario_path, timing_paths, Firmware::Production)
}

/// Which firmware build a model describes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Firmware {
    /// The production build (no task trace): what the report and the admission table cover.
    Production,
    /// The build with the task trace, on the chip: each timing file's `trace.per_job_us` is added
    /// to every job (`cargo xtask bench` on a capture).
    Traced,
    /// The traced QEMU build: every budget times the timing file's `trace.qemu.budget_scale` (the
    /// emulator runs at 125 MIPS, slower than the F405 and faster than the F103) and its measured
    /// `trace.qemu.per_job_us` per job (the QEMU scenarios' bounds, `cargo xtask bench --qemu`).
    Qemu,
}

/// [`build`] for the firmware build `firmware`.
pub fn build_for(
    root: &Path,
    scenario_path: &Path,
    timing_paths: &[PathBuf],
    firmware: Firmware,
) -> Result<Built, BuildError> {
    let scenario_file = display(root, scenario_path);
    let scenario: Scenario = read_json(root, scenario_path)?;
    let (scenario, one_shot_notes) = one_shots_as_publishers(scenario, &scenario_file)?;
    if scenario.bitrate == 0 {
        return Err(fail(&scenario_file, "bitrate", "must be greater than 0"));
    }
    let bit = can::bit_time(scenario.bitrate);

    let mut timings = Vec::new();
    for path in timing_paths {
        let timing: Timing = read_json(root, path)?;
        let file = display(root, path);
        if timings
            .iter()
            .any(|(_, t): &(String, Timing)| t.board == timing.board)
        {
            return Err(fail(
                &file,
                "board",
                format!("a second timing file for board `{}`", timing.board),
            ));
        }
        timings.push((file, timing));
    }

    // The scenario's topics, checked against the protocol's topic table.
    let mut sensors: Vec<Planned> = Vec::new();
    let mut seen = BTreeSet::new();
    for (i, p) in scenario.publishers.iter().enumerate() {
        let (info, priority) = topic_and_priority(
            &scenario_file,
            &format!("publishers[{i}]"),
            &p.topic,
            &p.priority,
        )?;
        if !info.is_sensor {
            return Err(fail(
                &scenario_file,
                format!("publishers[{i}].topic"),
                format!("`{}` is an actuator: list it under `commands`", p.topic),
            ));
        }
        if !seen.insert(info.topic) {
            return Err(fail(
                &scenario_file,
                format!("publishers[{i}].topic"),
                format!("`{}` is published twice", p.topic),
            ));
        }
        check_positive(
            &scenario_file,
            &format!("publishers[{i}].period_us"),
            p.period_us,
        )?;
        sensors.push(Planned {
            info,
            priority,
            index: i,
        });
    }
    let mut commands: Vec<Planned> = Vec::new();
    for (i, c) in scenario.commands.iter().enumerate() {
        let (info, priority) = topic_and_priority(
            &scenario_file,
            &format!("commands[{i}]"),
            &c.topic,
            &c.priority,
        )?;
        if info.is_sensor {
            return Err(fail(
                &scenario_file,
                format!("commands[{i}].topic"),
                format!("`{}` is a sensor: list it under `publishers`", c.topic),
            ));
        }
        if !seen.insert(info.topic) {
            return Err(fail(
                &scenario_file,
                format!("commands[{i}].topic"),
                format!("`{}` is listed twice", c.topic),
            ));
        }
        check_positive(
            &scenario_file,
            &format!("commands[{i}].period_us"),
            c.period_us,
        )?;
        commands.push(Planned {
            info,
            priority,
            index: i,
        });
    }
    for planned in sensors.iter().chain(&commands) {
        let board = board_folder(planned.info.board);
        if !timings.iter().any(|(_, t)| t.board == board) {
            return Err(fail(
                &scenario_file,
                "",
                format!(
                    "topic `{}` lives on board `{board}`, which has no timing file in {MODELS_DIR}",
                    planned.info.name
                ),
            ));
        }
    }

    let mut built = Built {
        model: Model {
            name: Some(scenario.name.clone()),
            boards: Vec::new(),
            can: None,
        },
        frame_cost: scenario.frame_cost,
        sources: Vec::new(),
        warnings: one_shot_notes,
    };
    let mut senders: BTreeMap<Topic, String> = BTreeMap::new();
    let mut receivers: BTreeMap<String, String> = BTreeMap::new();
    for (file, timing) in &timings {
        let mine: Vec<&Planned> = sensors
            .iter()
            .filter(|p| board_folder(p.info.board) == timing.board)
            .collect();
        // The transmit-complete interrupt cannot come faster than the shortest frame this board sends.
        let own_frame = mine
            .iter()
            .map(|p| bit.times(u64::from(can::frame_bits_best(p.info.dlc, false))))
            .min()
            .unwrap_or_else(|| can::shortest_frame_time(bit));
        let board = build_board(
            root,
            file,
            timing,
            &mine,
            &scenario,
            can::shortest_frame_time(bit),
            own_frame,
            firmware,
            &mut built,
        )?;
        for p in &mine {
            let publisher = timing
                .publishers
                .get(p.priority.name())
                .cloned()
                .unwrap_or_default();
            senders.insert(
                p.info.topic,
                format!("{}/{}[{}]", timing.board, publisher, p.info.name),
            );
        }
        if let Some(handler) = &timing.command_handler {
            receivers.insert(timing.board.clone(), format!("{}/{handler}", timing.board));
        }
        built.model.boards.push(board);
    }

    let mut messages = Vec::new();
    for p in &sensors {
        let Some(entry) = scenario.publishers.get(p.index) else {
            continue;
        };
        messages.push(MessageModel {
            name: p.info.name.to_string(),
            id: u32::from(CanId::new(Kind::Sensor, p.priority, p.info.topic.byte()).raw()),
            dlc: p.info.dlc,
            period_us: entry.period_us,
            deadline_us: entry.deadline_us,
            jitter_us: 0.0,
            sender: senders.get(&p.info.topic).cloned(),
            receiver: None,
            frames: u32::from(p.info.frames_per_sample.max(1)),
            extended: false,
            jitter_budget_us: entry.jitter_budget_us,
            e2e_deadline_us: None,
        });
    }
    for p in &commands {
        let Some(entry) = scenario.commands.get(p.index) else {
            continue;
        };
        let board = board_folder(p.info.board);
        let receiver = receivers.get(board).cloned();
        if receiver.is_none() {
            built.warnings.push(format!(
                "command `{}`: board `{board}` names no command_handler, so its path ends on the bus",
                p.info.name
            ));
        }
        messages.push(MessageModel {
            name: p.info.name.to_string(),
            id: u32::from(CanId::new(Kind::Command, p.priority, p.info.topic.byte()).raw()),
            dlc: p.info.dlc,
            period_us: entry.period_us,
            deadline_us: entry.deadline_us,
            jitter_us: entry.jitter_us,
            sender: None,
            receiver,
            frames: 1,
            extended: false,
            jitter_budget_us: entry.jitter_budget_us,
            e2e_deadline_us: None,
        });
    }
    built.model.can = Some(CanModel {
        bitrate: scenario.bitrate,
        frame_cost: scenario.frame_cost,
        messages,
    });
    Ok(built)
}

/// The scenario with each one-shot as a publisher of its topic at its priority every
/// [`amiro_can::ONE_SHOT_INTERVAL_MS`], and a note per one-shot saying so. A one-shot of a published topic, of an
/// actuator or listed twice is an error naming its field.
fn one_shots_as_publishers(
    mut scenario: Scenario,
    file: &str,
) -> Result<(Scenario, Vec<String>), BuildError> {
    let mut notes = Vec::new();
    let one_shots = core::mem::take(&mut scenario.one_shots);
    for (i, o) in one_shots.iter().enumerate() {
        let path = format!("one_shots[{i}]");
        let (info, _) = topic_and_priority(file, &path, &o.topic, &o.priority)?;
        if !info.is_sensor {
            return Err(fail(
                file,
                format!("{path}.topic"),
                format!(
                    "`{}` is an actuator: a one-shot asks for a sensor sample",
                    o.topic
                ),
            ));
        }
        let listed = |topic: &str| Topic::from_name(topic).is_some_and(|t| t == info.topic);
        if one_shots[..i].iter().any(|earlier| listed(&earlier.topic)) {
            return Err(fail(
                file,
                format!("{path}.topic"),
                format!("`{}` is listed twice", o.topic),
            ));
        }
        if scenario.publishers.iter().any(|p| listed(&p.topic)) {
            return Err(fail(
                file,
                format!("{path}.topic"),
                format!(
                    "`{}` is also published: a one-shot stops the topic's publisher, list it once",
                    o.topic
                ),
            ));
        }
        let interval_us = u64::from(amiro_can::ONE_SHOT_INTERVAL_MS) * 1000;
        notes.push(format!(
            "one-shot {} at {}: analysed as a sample every {interval_us} µs (how often a board takes a one-shot at most; docs/analysis.md)",
            info.name, o.priority
        ));
        scenario.publishers.push(ScenarioPublisher {
            topic: o.topic.clone(),
            priority: o.priority.clone(),
            period_us: interval_us as f64,
            deadline_us: None,
            jitter_budget_us: None,
        });
    }
    Ok((scenario, notes))
}

fn check_positive(file: &str, path: &str, value: f64) -> Result<(), BuildError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(fail(
            file,
            path,
            format!("must be a number > 0, got {value}"),
        ))
    }
}

fn topic_and_priority(
    file: &str,
    path: &str,
    topic: &str,
    priority: &str,
) -> Result<(&'static TopicInfo, Priority), BuildError> {
    let t = Topic::from_name(topic).ok_or_else(|| {
        let known: Vec<&str> = amiro_can::TOPICS.iter().map(|i| i.name).collect();
        fail(
            file,
            format!("{path}.topic"),
            format!("unknown topic `{topic}` (known: {})", known.join(", ")),
        )
    })?;
    let p = Priority::from_name(priority).ok_or_else(|| {
        fail(
            file,
            format!("{path}.priority"),
            format!("`{priority}` is not urgent, high, medium or low"),
        )
    })?;
    Ok((t.info(), p))
}

/// The declared tasks, `idle`, and every resource's static ceiling.
type Declarations = (Vec<Declared>, Option<Declared>, BTreeMap<String, u32>);

/// A task as declared (by the app or the timing file).
struct Declared {
    name: String,
    priority: u32,
    hardware: bool,
    shared: Vec<String>,
}

/// Reads the app (or its fallback) and returns the declared tasks, idle, every resource's users and a source line.
fn declared_tasks(
    root: &Path,
    file: &str,
    timing: &Timing,
    built: &mut Built,
) -> Result<Declarations, BuildError> {
    let publishers: BTreeSet<&str> = timing.publishers.values().map(String::as_str).collect();
    let Some(app_source) = &timing.app else {
        // No app yet: the timing file declares the tasks.
        let mut tasks = Vec::new();
        for (name, t) in &timing.tasks {
            let priority = t.priority.ok_or_else(|| {
                fail(
                    file,
                    format!("tasks.{name}.priority"),
                    "required while the board has no app (`app` is null)",
                )
            })?;
            let shared = t.shared.clone().unwrap_or_else(|| {
                t.critical_sections_us
                    .keys()
                    .filter(|k| k.as_str() != GLOBAL_CRITICAL_SECTION)
                    .cloned()
                    .collect()
            });
            tasks.push(Declared {
                name: name.clone(),
                priority,
                hardware: t.binds.is_some(),
                shared,
            });
        }
        let mut ceilings = BTreeMap::new();
        for t in &tasks {
            for r in &t.shared {
                let c = ceilings.entry(r.clone()).or_insert(0);
                *c = (*c).max(t.priority);
            }
        }
        built.sources.push(format!(
            "{}: no app yet — {} tasks declared in {file}",
            timing.board,
            tasks.len()
        ));
        return Ok((tasks, None, ceilings));
    };

    let features: Vec<&str> = app_source.features.iter().map(String::as_str).collect();
    let read = |relative: &str| -> Result<RticApp, BuildError> {
        let path = root.join(relative);
        let text = std::fs::read_to_string(&path)
            .map_err(|e| fail(file, "app.source", format!("cannot read {relative}: {e}")))?;
        let app = rtic_source::parse_app(&text).map_err(|e| fail(relative, "", e.to_string()))?;
        Ok(app.with_features(&features))
    };
    let mut used = app_source.source.clone();
    let mut app = read(&app_source.source)?;
    let budgeted = |app: &RticApp| {
        app.tasks
            .iter()
            .any(|t| timing.tasks.contains_key(&t.name) || publishers.contains(t.name.as_str()))
    };
    if !budgeted(&app) {
        match &app_source.fallback {
            Some(fallback) => {
                built.warnings.push(format!(
                    "{}: {} declares none of the budgeted tasks yet (a skeleton?); analysed the fallback app {fallback} \
                     instead — it describes the app the timing file budgets, not the code",
                    timing.board, app_source.source
                ));
                app = read(fallback)?;
                used = fallback.clone();
            }
            None => {
                return Err(fail(
                    file,
                    "app.source",
                    format!(
                        "{} declares none of the tasks this file budgets",
                        app_source.source
                    ),
                ))
            }
        }
    }

    let mut tasks = Vec::new();
    for t in &app.tasks {
        let shared = t
            .shared
            .iter()
            .filter(|r| !app.is_lock_free(r))
            .cloned()
            .collect();
        tasks.push(Declared {
            name: t.name.clone(),
            priority: u32::from(t.priority),
            hardware: matches!(t.kind, RticTaskKind::Hardware { .. }),
            shared,
        });
    }
    let idle = app.idle.as_ref().map(|t| Declared {
        name: t.name.clone(),
        priority: 0,
        hardware: false,
        shared: t
            .shared
            .iter()
            .filter(|r| !app.is_lock_free(r))
            .cloned()
            .collect(),
    });
    let mut ceilings = BTreeMap::new();
    for r in app.shared.iter().filter(|r| !r.lock_free) {
        let users = app
            .tasks
            .iter()
            .filter(|t| t.shared.contains(&r.name))
            .map(|t| u32::from(t.priority));
        ceilings.insert(r.name.clone(), users.max().unwrap_or(0));
    }
    // Drift checks: every declared task budgeted, every budget declared, nothing the source decides overridden.
    for t in &app.tasks {
        if !timing.tasks.contains_key(&t.name) && !publishers.contains(t.name.as_str()) {
            return Err(fail(
                file,
                "tasks",
                format!(
                    "task `{}` ({used}:{}) has no budget here: add `tasks.{}`",
                    t.name, t.line, t.name
                ),
            ));
        }
    }
    for (name, t) in &timing.tasks {
        if app.task(name).is_none() {
            return Err(fail(
                file,
                format!("tasks.{name}"),
                format!("budgets a task {used} does not declare"),
            ));
        }
        for (field, given) in [
            ("priority", t.priority.is_some()),
            ("binds", t.binds.is_some()),
            ("shared", t.shared.is_some()),
        ] {
            if given {
                return Err(fail(
                    file,
                    format!("tasks.{name}.{field}"),
                    format!("comes from {used}, not from the timing file"),
                ));
            }
        }
    }
    built.sources.push(format!(
        "{}: {} tasks read from {used} (#[rtic::app], dispatchers {})",
        timing.board,
        app.tasks.len(),
        if app.dispatchers.is_empty() {
            "none".to_string()
        } else {
            app.dispatchers.join(", ")
        }
    ));
    Ok((tasks, idle, ceilings))
}

#[allow(clippy::too_many_arguments)]
fn build_board(
    root: &Path,
    file: &str,
    timing: &Timing,
    topics: &[&Planned],
    scenario: &Scenario,
    bus_frame: Time,
    own_frame: Time,
    firmware: Firmware,
    built: &mut Built,
) -> Result<BoardModel, BuildError> {
    let scaled;
    let timing = match (
        firmware,
        timing.trace.as_ref().and_then(|t| t.qemu.as_ref()),
    ) {
        (Firmware::Qemu, Some(q)) if q.budget_scale != 1.0 => {
            scaled = timing.scaled(q.budget_scale);
            &scaled
        }
        _ => timing,
    };
    let (declared, idle, ceilings) = declared_tasks(root, file, timing, built)?;
    let mut measured: Vec<String> = Vec::new();
    let find = |name: &str| declared.iter().find(|d| d.name == name);
    for (level, task) in &timing.publishers {
        if Priority::from_name(level).is_none() {
            return Err(fail(
                file,
                format!("publishers.{level}"),
                "not urgent, high, medium or low",
            ));
        }
        if find(task).is_none() {
            return Err(fail(
                file,
                format!("publishers.{level}"),
                format!("no task `{task}` is declared"),
            ));
        }
        // Without an app the timing file declares the publisher tasks too, but never budgets them.
        if let Some(t) = timing.tasks.get(task) {
            if timing.app.is_some()
                || t.wcet_us.is_some()
                || t.arrival.is_some()
                || t.released_by.is_some()
            {
                return Err(fail(
                    file,
                    format!("tasks.{task}"),
                    "a publisher task is budgeted per topic, under `topics` (declare only priority and shared here)",
                ));
            }
        }
    }
    for (field, name) in [
        ("command_handler", &timing.command_handler),
        ("can_tx_task", &timing.can_tx_task),
    ] {
        if let Some(name) = name {
            if find(name).is_none() {
                return Err(fail(file, field, format!("no task `{name}` is declared")));
            }
        }
    }
    let publisher_tasks: BTreeSet<&str> = timing.publishers.values().map(String::as_str).collect();
    let monotonic = timing.monotonic;
    let mut tasks: Vec<TaskModel> = Vec::new();
    let mut timer_jobs: Vec<TaskModel> = Vec::new();
    let mut add_timer_job = |released: &TaskModel, path: &str| -> Result<String, BuildError> {
        let m = monotonic.ok_or_else(|| {
            fail(
                file,
                path,
                "released by the timer, but the file has no `monotonic`",
            )
        })?;
        let name = format!("monotonic[{}]", released.name);
        timer_jobs.push(TaskModel {
            name: name.clone(),
            priority: m.priority,
            wcet_us: m.timer_isr_us,
            period_us: released.period_us,
            deadline_us: None,
            jitter_us: m.tick_us,
            critical_sections_us: BTreeMap::new(),
            blocking_us: None,
            bcet_us: None,
            kind: TaskKind::Hardware,
            released_by: None,
            sporadic: released.sporadic,
            job_of: Some("monotonic".into()),
        });
        Ok(name)
    };

    for d in declared
        .iter()
        .filter(|d| !publisher_tasks.contains(d.name.as_str()))
    {
        let p = format!("tasks.{}", d.name);
        let t = timing.tasks.get(&d.name).cloned().unwrap_or_default();
        let estimate = t.wcet_us.ok_or_else(|| {
            fail(
                file,
                format!("{p}.wcet_us"),
                "missing: every task needs a budget",
            )
        })?;
        let wcet = budget(estimate, t.measured.as_ref(), &d.name, &mut measured);
        let arrival = t.arrival.ok_or_else(|| fail(file, format!("{p}.arrival"), "missing: \"bus_frame\", \"own_frame\", {\"periodic_us\": ..} or {\"sporadic_us\": ..}"))?;
        let (period_us, sporadic) = match arrival {
            Arrival::BusFrame => (bus_frame.as_us_f64(), true),
            Arrival::OwnFrame => (own_frame.as_us_f64(), true),
            Arrival::PeriodicUs(us) => (us, false),
            Arrival::SporadicUs(us) => (us, true),
        };
        check_positive(file, &format!("{p}.arrival"), period_us)?;
        let sections = critical_sections(
            file,
            &p,
            &d.shared,
            &within(&t.critical_sections_us, wcet),
            wcet,
            &d.name,
            built,
        )?;
        let mut task = TaskModel {
            name: d.name.clone(),
            priority: d.priority,
            wcet_us: wcet,
            period_us,
            deadline_us: t.deadline_us,
            jitter_us: t.jitter_us,
            critical_sections_us: sections,
            blocking_us: None,
            bcet_us: t.bcet_us,
            kind: if d.hardware {
                TaskKind::Hardware
            } else {
                TaskKind::Software
            },
            released_by: None,
            sporadic,
            job_of: None,
        };
        task.released_by = match t.released_by.as_deref() {
            None => None,
            Some("timer") => Some(add_timer_job(&task, &format!("{p}.released_by"))?),
            Some(other) if find(other).is_some() && !publisher_tasks.contains(other) => {
                Some(other.to_string())
            }
            Some(other) => {
                return Err(fail(
                    file,
                    format!("{p}.released_by"),
                    format!("`{other}` is neither \"timer\" nor a declared task"),
                ))
            }
        };
        tasks.push(task);
    }

    for planned in topics {
        let level = planned.priority.name();
        let publisher = timing.publishers.get(level).ok_or_else(|| {
            fail(
                file,
                "publishers",
                format!("no publisher task for CAN priority {level}"),
            )
        })?;
        let d = find(publisher).ok_or_else(|| {
            fail(
                file,
                format!("publishers.{level}"),
                format!("no task `{publisher}`"),
            )
        })?;
        let name = planned.info.name;
        let t = timing.topics.get(name).ok_or_else(|| {
            fail(
                file,
                format!("topics.{name}"),
                "missing: the scenario publishes this topic",
            )
        })?;
        let Some(entry) = scenario.publishers.get(planned.index) else {
            continue;
        };
        let p = format!("topics.{name}");
        for resource in t.critical_sections_us.keys() {
            if resource != GLOBAL_CRITICAL_SECTION && !d.shared.contains(resource) {
                return Err(fail(
                    file,
                    format!("{p}.critical_sections_us.{resource}"),
                    format!("`{publisher}` does not use `{resource}`"),
                ));
            }
        }
        let wcet = budget(t.wcet_us, t.measured.as_ref(), name, &mut measured);
        let mut job = TaskModel {
            name: format!("{publisher}[{name}]"),
            priority: d.priority,
            wcet_us: wcet,
            period_us: entry.period_us,
            deadline_us: entry.deadline_us,
            jitter_us: 0.0,
            critical_sections_us: within(&t.critical_sections_us, wcet),
            blocking_us: None,
            bcet_us: t.bcet_us,
            kind: TaskKind::Software,
            released_by: None,
            sporadic: false,
            job_of: Some(publisher.clone()),
        };
        if monotonic.is_some() {
            job.released_by = Some(add_timer_job(&job, &p)?);
        }
        tasks.push(job);
    }

    let mut idle_sections = BTreeMap::new();
    if let Some(idle) = &idle {
        for r in &idle.shared {
            let length = timing.idle_critical_sections_us.get(r).ok_or_else(|| {
                fail(
                    file,
                    format!("idle_critical_sections_us.{r}"),
                    format!("`{}` locks `{r}`: give the longest lock", idle.name),
                )
            })?;
            idle_sections.insert(r.clone(), *length);
        }
    }
    for (r, length) in &timing.idle_critical_sections_us {
        if r == GLOBAL_CRITICAL_SECTION {
            idle_sections.insert(r.clone(), *length);
        } else if !idle.as_ref().is_some_and(|i| i.shared.contains(r)) {
            return Err(fail(
                file,
                format!("idle_critical_sections_us.{r}"),
                "idle does not use this resource",
            ));
        }
    }

    // Timer jobs first: they are the most urgent and read best at the top of the table.
    timer_jobs.extend(tasks);
    let source = built.sources.last().cloned();
    let budgets = timing.tasks.len() + timing.topics.len();
    built.sources.push(if measured.is_empty() {
        format!(
            "{}: budgets are estimates ({budgets}; none measured)",
            timing.board
        )
    } else {
        format!(
            "{}: measured budgets for {} ({} of {budgets}), the rest estimates",
            timing.board,
            measured.join(", "),
            measured.len()
        )
    });
    // The task trace's start and end records, where every job's entry and exit are counted.
    let mut overheads = timing.overheads;
    match (&timing.trace, firmware) {
        (Some(trace), Firmware::Traced) => {
            overheads.isr_entry_us += trace.per_job_us / 2.0;
            overheads.isr_exit_us += trace.per_job_us / 2.0;
            built.sources.push(format!(
                "{}: analysed build has the task trace (feature `{}`, {} µs per job in the overheads)",
                timing.board, trace.feature, trace.per_job_us
            ));
            // The transmit task writes a `frame-acked` record per completed mailbox: one record
            // (half a job's two), up to three per job. (QEMU's mailboxes report no completion.)
            if let Some(tx) = timing
                .can_tx_task
                .as_ref()
                .and_then(|name| timer_jobs.iter_mut().find(|t| &t.name == name))
            {
                let acks = ACKS_PER_TRANSMIT_JOB as f64 * trace.per_job_us / 2.0;
                tx.wcet_us += acks;
                built.sources.push(format!(
                    "{}: `{}` writes up to {ACKS_PER_TRANSMIT_JOB} acknowledgement records per job (+{acks} µs)",
                    timing.board, tx.name
                ));
            }
        }
        (Some(trace), Firmware::Qemu) => {
            let q = trace
                .qemu
                .as_ref()
                .map_or((trace.per_job_us, 1.0), |q| (q.per_job_us, q.budget_scale));
            overheads.isr_entry_us += q.0 / 2.0;
            overheads.isr_exit_us += q.0 / 2.0;
            built.sources.push(format!(
                "{}: analysed build is the traced QEMU build (budgets ×{}, {} µs per job for the trace)",
                timing.board, q.1, q.0
            ));
        }
        (Some(trace), Firmware::Production) => built.sources.push(format!(
            "{}: analysed build is without the task trace (feature `{}` off)",
            timing.board, trace.feature
        )),
        (None, _) => {}
    }
    if firmware == Firmware::Qemu {
        if let Some(transmit) = timing
            .trace
            .as_ref()
            .and_then(|t| t.qemu.as_ref())
            .and_then(|q| q.transmit.as_ref())
        {
            qemu_transmit_jobs(file, timing, transmit, &overheads, &mut timer_jobs)?;
            built.sources.push(format!(
                "{}: in QEMU `{}` is pended by the publisher's samples (⌈frames / 3⌉ jobs each) and \
                 the samples `{}`'s commands request, not by a transmit-complete",
                timing.board,
                timing.can_tx_task.as_deref().unwrap_or("?"),
                transmit.requests_from
            ));
        }
    }
    Ok(BoardModel {
        name: timing.board.clone(),
        source,
        overheads,
        idle_critical_sections_us: idle_sections,
        can_tx_task: timing.can_tx_task.clone(),
        ceilings,
        tasks: timer_jobs,
    })
}

/// QEMU's transmit task ([`QemuTransmit`]): its own arrival (one job per frame on the bus) becomes
/// ⌈frames / 3⌉ jobs per publisher job of the scenario (`can_tx[topic]`, released by that job) and
/// per sample a command requests (the task itself, at the command handler's rate, released by it,
/// with one period of extra jitter per requestable topic).
fn qemu_transmit_jobs(
    file: &str,
    timing: &Timing,
    transmit: &QemuTransmit,
    overheads: &Overheads,
    tasks: &mut Vec<TaskModel>,
) -> Result<(), BuildError> {
    let path = "trace.qemu.transmit";
    let tx_name = timing
        .can_tx_task
        .as_deref()
        .ok_or_else(|| fail(file, path, "the file names no `can_tx_task`"))?;
    let handler = tasks
        .iter()
        .find(|t| t.name == transmit.requests_from)
        .cloned()
        .ok_or_else(|| {
            fail(
                file,
                format!("{path}.requests_from"),
                format!("no task `{}`", transmit.requests_from),
            )
        })?;
    let at = tasks
        .iter()
        .position(|t| t.name == tx_name)
        .ok_or_else(|| fail(file, path, format!("no task `{tx_name}`")))?;
    let tx = tasks[at].clone();
    // A job after the first of a burst costs its entry, exit and trace records too (the analysis
    // adds them once per modelled job).
    let per_job = match tx.kind {
        TaskKind::Hardware => overheads.isr_entry_us + overheads.isr_exit_us,
        TaskKind::Software => {
            overheads.isr_entry_us + overheads.isr_exit_us + overheads.dispatcher_us
        }
        TaskKind::Plain => 0.0,
    };
    let burst = |frames: u64| {
        let jobs = frames.div_ceil(QEMU_FRAMES_PER_TRANSMIT_JOB).max(1) as f64;
        jobs * tx.wcet_us + (jobs - 1.0) * per_job + frames as f64 * transmit.frame_us
    };
    // What a command may request: one sample of a topic the board owns.
    let requestable: Vec<&TopicInfo> = amiro_can::TOPICS
        .iter()
        .filter(|i| i.is_sensor && board_folder(i.board) == timing.board)
        .collect();
    let largest = requestable
        .iter()
        .map(|i| u64::from(i.frames_per_sample))
        .max()
        .unwrap_or(1);
    let requests = &mut tasks[at];
    requests.wcet_us = burst(largest);
    requests.period_us = handler.period_us;
    requests.sporadic = true;
    requests.jitter_us = handler.period_us * requestable.len().max(1) as f64;
    requests.released_by = Some(handler.name.clone());
    let publisher_jobs: Vec<(String, f64, u64)> = tasks
        .iter()
        .filter(|t| {
            t.job_of
                .as_ref()
                .is_some_and(|p| timing.publishers.values().any(|v| v == p))
        })
        .filter_map(|t| {
            let topic = t.name.split_once('[')?.1.strip_suffix(']')?;
            let info = amiro_can::TOPICS.iter().find(|i| i.name == topic)?;
            Some((
                t.name.clone(),
                t.period_us,
                u64::from(info.frames_per_sample),
            ))
        })
        .collect();
    for (job, period_us, frames) in publisher_jobs {
        let topic = job
            .split_once('[')
            .map_or("", |(_, t)| t.trim_end_matches(']'));
        tasks.push(TaskModel {
            name: format!("{tx_name}[{topic}]"),
            wcet_us: burst(frames),
            period_us,
            sporadic: false,
            jitter_us: 0.0,
            released_by: Some(job),
            job_of: Some(tx_name.to_string()),
            ..tx.clone()
        });
    }
    Ok(())
}

/// The budget a job gets: the measured one when the timing file has it (noted in `measured`), else
/// the estimate.
fn budget(estimate: f64, m: Option<&Measured>, name: &str, measured: &mut Vec<String>) -> f64 {
    match m {
        Some(m) => {
            measured.push(format!(
                "{name} ({} µs, {}, {})",
                m.wcet_us, m.build, m.origin
            ));
            m.wcet_us
        }
        None => estimate,
    }
}

/// Critical sections no longer than the job: a measured budget below an estimated lock length
/// bounds the lock too.
fn within(sections: &BTreeMap<String, f64>, wcet: f64) -> BTreeMap<String, f64> {
    sections
        .iter()
        .map(|(r, &cs)| (r.clone(), cs.min(wcet)))
        .collect()
}

/// The critical sections of a task: one per shared resource it declares (its length from the timing file, or
/// the whole WCET with a warning), plus the global critical section if budgeted.
fn critical_sections(
    file: &str,
    path: &str,
    shared: &[String],
    given: &BTreeMap<String, f64>,
    wcet: f64,
    task: &str,
    built: &mut Built,
) -> Result<BTreeMap<String, f64>, BuildError> {
    let mut out = BTreeMap::new();
    for (resource, length) in given {
        if resource != GLOBAL_CRITICAL_SECTION && !shared.iter().any(|s| s == resource) {
            return Err(fail(
                file,
                format!("{path}.critical_sections_us.{resource}"),
                format!("`{task}` does not use `{resource}` (not in its `shared` list)"),
            ));
        }
        out.insert(resource.clone(), *length);
    }
    for resource in shared {
        if !given.contains_key(resource) {
            built.warnings.push(format!(
                "{file}: `{path}` gives no critical-section length for `{resource}`; assumed the whole WCET ({wcet} µs)"
            ));
            out.insert(resource.clone(), wcet);
        }
    }
    Ok(out)
}
