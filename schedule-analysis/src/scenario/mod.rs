//! The project's default model, built from three sources so that none of them can drift from the others:
//!
//! 1. each board's **RTIC app**, read with [`crate::rtic_source`]: which tasks exist, their priorities, hardware
//!    bindings and shared resources (for a board without an app yet, its timing file declares them);
//! 2. each board's **timing file** (`models/<board>.timing.json`): execution-time budgets per task and per
//!    published topic, critical-section lengths, overheads, arrivals;
//!    Where a board's generated bounds file (`models/<board>[-<revision>].wcet.json`, [`crate::bounds`]) has a
//!    bound for a job, the bound replaces the stated budget (`bounded`);
//! 3. a **scenario** (`models/<name>.scenario.json`): which topics run at which period and CAN priority, the
//!    operator's commands, deadlines and jitter budgets.
//!
//! A topic published at CAN priority P becomes a job of the board's publisher task for P (`publish_high` …), with
//! its own period and budget, woken by the monotonic's timer interrupt (a job of its own), and a message with
//! identifier `0x400 | P << 8 | topic` whose DLC and frames per sample come from `amiro_can::TOPICS`.
//! Every task the app declares must have a budget and every budget must name a declared task, or the build fails.
//!
//! The steps, one module each: `files` (the timing file and scenario formats), `plan` (reading the scenario and
//! planning its topics onto the boards), `bounded` (the machine-code bounds in place of stated budgets), `declared` (the tasks an app or timing file declares), `board` (a
//! board's tasks, publisher and timer jobs, idle, overheads), `qemu` (the traced QEMU build's transmit jobs) and
//! `messages` (the bus's messages).

use std::fmt;
use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::can;
use crate::model::{CanModel, FrameCostSpec, Model};

mod board;
mod bounded;
mod declared;
mod files;
mod messages;
mod on_bounds;
mod plan;
mod qemu;
mod transmit;

pub use bounded::{bounds_file, breaking_bounds, BoardBudgets, BudgetFrom, Held};
pub use files::{
    scaled_cpu, AppSource, Arrival, ExpectedFailures, Measured, Monotonic, QemuBuild, QemuReplay,
    QemuTransmit, Scenario, ScenarioCommand, ScenarioOneShot, ScenarioPublisher, Timing,
    TimingTask, TopicTiming, TraceCost, UnstampedPerPreemption, WorstStep, ACKS_PER_TRANSMIT_JOB,
    QEMU_FRAMES_PER_TRANSMIT_JOB,
};
pub use on_bounds::{on_held_bounds, BoardOnBounds, OnBounds};

/// Where the default models live, relative to the workspace root.
pub const MODELS_DIR: &str = "schedule-analysis/models";
/// The scenario `cargo xtask analyze` uses when none is named.
pub const DEFAULT_SCENARIO: &str = "thesis-demo";
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
    /// Per board, where each budget came from: the machine-code bound of its generated bounds file, or the
    /// timing file's stated budget and why ([`BoardBudgets`]).
    pub budgets: Vec<BoardBudgets>,
    /// The scenario's `expected_failures`: the failures `--check` expects, exactly ([`crate::report::Report::check_passes`]).
    pub expected_failures: Vec<String>,
}

impl Built {
    /// Where the budget of `board`'s job `task` came from, as the JSON report says it: `bound` or `stated`.
    pub fn budget_from(&self, board: &str, task: &str) -> Option<&BudgetFrom> {
        self.budgets.iter().find(|b| b.board == board)?.of_job(task)
    }
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

/// A board's bounds file as the bench reads it: where it is, the file when there is one, and the task trace's
/// cost from the board's timing file (what the traced build's jobs execute beyond the release image's).
#[derive(Debug, Clone)]
pub struct BoardBounds {
    /// The bounds file's path, relative to the workspace root.
    pub file: String,
    /// The file, `None` while it has not been generated.
    pub bounds: Option<crate::bounds::BoundsFile>,
    /// The timing file's `trace`.
    pub trace: Option<TraceCost>,
}

/// The bounds of the board `board` among `timing_paths` (its image's `models/<board>[-<revision>].wcet.json`);
/// `Ok(None)` when no timing file is the board's.
pub fn board_bounds(
    root: &Path,
    timing_paths: &[PathBuf],
    board: &str,
) -> Result<Option<BoardBounds>, BuildError> {
    for (_, timing) in plan::read_timings(root, timing_paths)? {
        if timing.board == board {
            let (file, bounds) = bounds_file(root, &timing)?;
            return Ok(Some(BoardBounds {
                file,
                bounds,
                trace: timing.trace.clone(),
            }));
        }
    }
    Ok(None)
}

/// The tasks of `board` among `timing_paths` that arrive once per frame on the bus (`"arrival": "bus_frame"`: the
/// receive interrupt), whose arrivals [`build_for_run`] takes from a run's received frames.
pub fn bus_frame_tasks(
    root: &Path,
    timing_paths: &[PathBuf],
    board: &str,
) -> Result<Vec<String>, BuildError> {
    Ok(plan::read_timings(root, timing_paths)?
        .into_iter()
        .filter(|(_, t)| t.board == board)
        .flat_map(|(_, t)| {
            t.tasks
                .into_iter()
                .filter(|(_, task)| matches!(task.arrival, Some(Arrival::BusFrame)))
                .map(|(name, _)| name)
        })
        .collect())
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

/// The names of the shipped scenarios (the models folder's `<name>.scenario.json`, as [`find_scenario`] takes
/// them), sorted.
pub fn scenario_names(root: &Path) -> std::io::Result<Vec<String>> {
    let mut names: Vec<String> = std::fs::read_dir(root.join(MODELS_DIR))?
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            e.file_name()
                .to_str()
                .and_then(|n| n.strip_suffix(".scenario.json"))
                .map(str::to_string)
        })
        .collect();
    names.sort();
    Ok(names)
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
    /// emulator runs at 125 MIPS, slower than the F405 and faster than the F103) except a bounded budget's
    /// stated bus waits (wire time, not the CPU's: [`scaled_cpu`]), and the timing file's measured
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
    build_for_run(root, scenario_path, timing_paths, firmware, None)
}

/// [`build_for`] for one run whose received frames are known: `received_gap_us` is the shortest time between two
/// frames the boards receive in it (a QEMU run's stimulus, which is the only source of received frames there), and
/// a task that arrives once per frame on the bus (`"bus_frame"`: the receive interrupt) arrives no more often than
/// that — never more often than the shortest frame on the bus either. `None`: a command flood at full bus rate, as
/// the report assumes.
pub fn build_for_run(
    root: &Path,
    scenario_path: &Path,
    timing_paths: &[PathBuf],
    firmware: Firmware,
    received_gap_us: Option<f64>,
) -> Result<Built, BuildError> {
    build_with(
        root,
        scenario_path,
        timing_paths,
        firmware,
        received_gap_us,
        Held::Kept,
    )
}

/// [`build`] with every bound the bounds files hold back used in place of the stated budget and sections
/// ([`Held::Used`]): the model of the report's second run (docs/analysis.md, "The verdict on the bounds").
pub fn build_on_held_bounds(
    root: &Path,
    scenario_path: &Path,
    timing_paths: &[PathBuf],
) -> Result<Built, BuildError> {
    build_held(root, scenario_path, timing_paths, Held::Used)
}

/// [`build`] with the held bounds used as `held` says.
pub fn build_held(
    root: &Path,
    scenario_path: &Path,
    timing_paths: &[PathBuf],
    held: Held<'_>,
) -> Result<Built, BuildError> {
    build_with(
        root,
        scenario_path,
        timing_paths,
        Firmware::Production,
        None,
        held,
    )
}

fn build_with(
    root: &Path,
    scenario_path: &Path,
    timing_paths: &[PathBuf],
    firmware: Firmware,
    received_gap_us: Option<f64>,
    held: Held<'_>,
) -> Result<Built, BuildError> {
    let scenario_file = display(root, scenario_path);
    let scenario: Scenario = read_json(root, scenario_path)?;
    let (scenario, one_shot_notes) = plan::one_shots_as_publishers(scenario, &scenario_file)?;
    if scenario.bitrate == 0 {
        return Err(fail(&scenario_file, "bitrate", "must be greater than 0"));
    }
    let bit = can::bit_time(scenario.bitrate);
    let timings = plan::read_timings(root, timing_paths)?;
    let plan = plan::plan(&scenario, &scenario_file, &timings)?;

    let mut built = Built {
        model: Model {
            name: Some(scenario.name.clone()),
            boards: Vec::new(),
            can: None,
        },
        frame_cost: scenario.frame_cost,
        sources: Vec::new(),
        warnings: one_shot_notes,
        budgets: Vec::new(),
        expected_failures: Vec::new(),
    };
    let ends = board::build_boards(
        root,
        &timings,
        &plan.sensors,
        &scenario,
        bit,
        firmware,
        received_gap_us.map(crate::time::Time::from_us_down),
        held,
        &mut built,
    )?;
    // The failures expected of the images the boards' bounds files are of (a per-revision list by their revision).
    let revisions: Vec<&str> = built
        .budgets
        .iter()
        .filter_map(|b| b.bounds.as_ref()?.revision.as_deref())
        .collect();
    built.expected_failures = scenario.expected_failures.on(&revisions);
    let messages = messages::messages(&scenario, &plan, &ends, &mut built.warnings);
    built.model.can = Some(CanModel {
        bitrate: scenario.bitrate,
        frame_cost: scenario.frame_cost,
        messages,
    });
    Ok(built)
}
