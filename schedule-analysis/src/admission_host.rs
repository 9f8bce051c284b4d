//! The host side of the on-chip admission check ([`crate::admission`]): lowers the boards' task models — built
//! from the same RTIC apps and timing files `cargo xtask analyze` reads, through [`scenario::build`], so a drift
//! between app and timing file fails here as it fails there — to the compact [`RobotTable`], emits it as Rust
//! source for a board's `build.rs`, turns scenario entries into [`Stream`]s, and measures the check's cost.
//!
//! A board's build script (with `schedule-analysis` as a build-dependency):
//!
//! ```text
//! let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
//! let robot = admission_host::lower_robot(&root)      // `lower` with every timing file, 1 Mbit/s, exact frames
//!     .unwrap_or_else(|e| panic!("{e}"));          // drift between app and timing file: the build fails
//! std::fs::write(out_dir.join("admission_table.rs"), robot.to_rust_source("schedule_analysis"))?;
//! ```
//!
//! and the firmware `include!`s it: `ROBOT`, `MAX_TASKS`, `MAX_PUBLISHERS` and `BOARD_<NAME>` (the board's index).

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use amiro_can::{CanId, Kind, Priority, Topic};

use crate::admission::{
    self, BoardTable, BusRow, MonotonicRow, RobotTable, RowTime, ScriptRow, SectionRow, Sender,
    Stream, TaskRow, TopicRow, TopicSection, INTERRUPTS_DISABLED, LEVELS, MAX_BUSES, NO_DEADLINE,
    NO_RELEASER,
};
use crate::can::{self, FrameCost};
use crate::model::{
    BoardModel, FrameCostSpec, Model, OverheadTimes, TaskKind, TaskModel, GLOBAL_CRITICAL_SECTION,
};
use crate::scenario::{self, Arrival, BuildError, Timing};
use crate::time::Time;

/// Period of every publisher in the scenarios the lowering builds (only the budgets are read from them).
const PROBE_PERIOD_US: f64 = 1_000_000.0;

/// A topic row with owned sections.
#[derive(Debug, Clone, PartialEq)]
pub struct OwnedTopic {
    /// Topic name (amiro-can's).
    pub name: String,
    /// Protocol topic byte.
    pub topic: u8,
    /// Cost with overheads.
    pub cost: RowTime,
    /// Best case.
    pub bcet: RowTime,
    /// Critical sections.
    pub sections: Vec<TopicSection>,
    /// The scripts one sample runs, in order.
    pub scripts: Vec<ScriptRow>,
    /// The transmit interrupt's job per sample, with overheads (0: none; [`TopicRow::transmit`]).
    pub transmit: RowTime,
}

/// One board's table, owned.
#[derive(Debug, Clone, PartialEq)]
pub struct OwnedBoard {
    /// Board name.
    pub name: String,
    /// Task names, for messages (parallel to `tasks`).
    pub task_names: Vec<String>,
    /// Fixed tasks.
    pub tasks: Vec<TaskRow>,
    /// Their and idle's critical sections.
    pub sections: Vec<SectionRow>,
    /// The longest of `sections` blocking each priority up to the board's highest job priority.
    pub blocking: Vec<RowTime>,
    /// Publishable topics.
    pub topics: Vec<OwnedTopic>,
    /// Publisher task priority per level.
    pub levels: [Option<u8>; LEVELS],
    /// Timer job.
    pub monotonic: Option<MonotonicRow>,
    /// Transmit task index.
    pub can_tx: Option<u16>,
    /// Command handler index.
    pub command_handler: Option<u16>,
    /// Its sensor buses.
    pub buses: Vec<BusRow>,
    /// The fixed tasks with scripts (index in `tasks`) and their scripts.
    pub task_scripts: Vec<(u8, Vec<ScriptRow>)>,
    /// Per level, its publisher task's number (levels of one task share it).
    pub publisher_tasks: [u8; LEVELS],
}

impl OwnedBoard {
    /// The shortest data length of its topics' frames (0 without topics): [`BoardTable::shortest_dlc`].
    pub fn shortest_dlc(&self) -> u8 {
        self.topics
            .iter()
            .filter_map(|t| amiro_can::Topic::from_byte(t.topic).map(|topic| topic.dlc()))
            .min()
            .unwrap_or(0)
    }
}

/// The whole robot's table, owned.
#[derive(Debug, Clone, PartialEq)]
pub struct OwnedRobot {
    /// Boards in timing-file order.
    pub boards: Vec<OwnedBoard>,
    /// Bits per second.
    pub bitrate: u32,
    /// Frame-cost model.
    pub frame_cost: FrameCost,
    /// The files it was made from (for the generated source's header).
    pub sources: Vec<String>,
}

/// A table with sensor buses or scripts lowered for a build that does not link the check's sensor-bus rounds
/// (`schedule-analysis`'s feature `sensor-buses`, which a board's `scripted-i2c` enables): its check would refuse
/// every request, so the build fails instead.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SensorBusesNotLinked {
    /// The first board whose table states a sensor bus or a script.
    pub board: String,
}

impl std::fmt::Display for SensorBusesNotLinked {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{}'s admission table states sensor buses or scripts, and this build does not link the check's \
             sensor-bus rounds (enable the board's `scripted-i2c`, i.e. `schedule-analysis/sensor-buses`)",
            self.board
        )
    }
}

impl std::error::Error for SensorBusesNotLinked {}

fn read_timing(root: &Path, path: &Path) -> Result<Timing, BuildError> {
    let file = path
        .strip_prefix(root)
        .unwrap_or(path)
        .display()
        .to_string();
    let text = std::fs::read_to_string(path).map_err(|e| BuildError {
        file: file.clone(),
        path: String::new(),
        problem: format!("cannot read: {e}"),
    })?;
    serde_json::from_str(&text).map_err(|e| BuildError {
        file,
        path: String::new(),
        problem: e.to_string(),
    })
}

/// The table's compact rows hold what the boards need; a model outside them fails the lowering (and so the
/// board's build) with the file and field, instead of a wrong table.
struct Rows<'f> {
    file: &'f str,
}

impl Rows<'_> {
    fn fail(&self, field: &str, problem: String) -> BuildError {
        BuildError {
            file: self.file.to_string(),
            path: field.to_string(),
            problem,
        }
    }

    /// A time as a [`RowTime`]: whole nanoseconds below [`NO_DEADLINE`] (about 4.29 s).
    fn time(&self, field: &str, time: Time) -> Result<RowTime, BuildError> {
        u32::try_from(time.as_ns())
            .ok()
            .filter(|&ns| ns != NO_DEADLINE)
            .ok_or_else(|| {
                self.fail(
                    field,
                    format!(
                        "{} ns does not fit the on-chip admission table's 32-bit rows (at most {} ns, about 4.29 s)",
                        time.as_ns(),
                        NO_DEADLINE - 1
                    ),
                )
            })
    }

    /// An RTIC priority (or a resolved ceiling) as a row byte: below 255 ([`INTERRUPTS_DISABLED`]).
    fn priority(&self, field: &str, priority: u32) -> Result<u8, BuildError> {
        u8::try_from(priority)
            .ok()
            .filter(|&p| p != INTERRUPTS_DISABLED)
            .ok_or_else(|| {
                self.fail(
                    field,
                    format!(
                        "priority {priority} does not fit the on-chip admission table (below 255)"
                    ),
                )
            })
    }

    /// A resolved ceiling: `u32::MAX` (a global critical section) is [`INTERRUPTS_DISABLED`].
    fn ceiling(&self, field: &str, ceiling: u32) -> Result<u8, BuildError> {
        if ceiling == u32::MAX {
            Ok(INTERRUPTS_DISABLED)
        } else {
            self.priority(field, ceiling)
        }
    }
}

fn build_with(
    root: &Path,
    timing_paths: &[PathBuf],
    label: &str,
    publishers: &[(String, &str)],
    held: scenario::Held<'_>,
) -> Result<Model, BuildError> {
    // Unique per call: two lowerings in one process (threads of a test run) must not share the file.
    static CALLS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let call = CALLS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let path = std::env::temp_dir().join(format!(
        "schedule-analysis-lower-{}-{call}-{label}.scenario.json",
        std::process::id()
    ));
    let json = serde_json::json!({
        "name": format!("admission-table-{label}"),
        "publishers": publishers.iter().map(|(topic, level)| serde_json::json!({
            "topic": topic, "priority": level, "period_us": PROBE_PERIOD_US,
        })).collect::<Vec<_>>(),
    });
    std::fs::write(&path, json.to_string()).map_err(|e| BuildError {
        file: path.display().to_string(),
        path: String::new(),
        problem: e.to_string(),
    })?;
    let built = scenario::build_held(root, &path, timing_paths, held);
    let _ = std::fs::remove_file(&path);
    Ok(built?.model)
}

fn overhead_times(o: &crate::model::Overheads) -> OverheadTimes {
    OverheadTimes {
        isr_entry: Time::from_us_up(o.isr_entry_us),
        isr_exit: Time::from_us_up(o.isr_exit_us),
        dispatcher: Time::from_us_up(o.dispatcher_us),
    }
}

/// The table the boards carry: every board's timing file under `root` ([`scenario::timing_files`]) lowered for
/// the bus at [`crate::can::DEFAULT_BITRATE`] under the exact frame cost — what a board's build script
/// generates, and what the host tools (the operator's check, the scenarios, the examples) compare with.
pub fn lower_robot(root: &Path) -> Result<OwnedRobot, BuildError> {
    lower_robot_from(root, &scenario::timing_files(root))
}

/// [`lower_robot`] for a robot of board revision `revision` (its timing files: [`scenario::timing_files_for`]),
/// whatever `AMIRO_REVISION` says.
pub fn lower_robot_for(root: &Path, revision: Option<&str>) -> Result<OwnedRobot, BuildError> {
    lower_robot_from(root, &scenario::timing_files_for(root, revision))
}

fn lower_robot_from(root: &Path, timing_paths: &[PathBuf]) -> Result<OwnedRobot, BuildError> {
    lower(
        root,
        timing_paths,
        crate::can::DEFAULT_BITRATE,
        FrameCostSpec::Exact,
    )
}

/// Lowers every board of the timing files to the admission table, for the bus at `bitrate` under `frame_cost`.
/// Fails exactly where `cargo xtask analyze` fails on the same files (an app task without a budget, a budget
/// for a task the app does not declare, …).
///
/// The steps: read the timing files; build every board without publishers (the fixed tasks); per board, resolve
/// the resource ceilings (`Lowering::new`), lower the fixed tasks and critical sections
/// (`Lowering::task_rows`, `Lowering::idle_rows`), then, per CAN level with a publisher task, build the board
/// with every publishable topic at that level and lower its publisher jobs and timer job
/// (`Lowering::publisher_rows`).
pub fn lower(
    root: &Path,
    timing_paths: &[PathBuf],
    bitrate: u32,
    frame_cost: FrameCostSpec,
) -> Result<OwnedRobot, BuildError> {
    lower_held(
        root,
        timing_paths,
        bitrate,
        frame_cost,
        scenario::Held::Kept,
    )
}

/// [`lower`] from the model [`scenario::build_held`] builds with `held`: the table of a model that uses bounds the
/// bounds files hold back (what the boards would carry were those bounds used), for the tests that compare the
/// check with the report on it.
pub fn lower_held(
    root: &Path,
    timing_paths: &[PathBuf],
    bitrate: u32,
    frame_cost: FrameCostSpec,
    held: scenario::Held<'_>,
) -> Result<OwnedRobot, BuildError> {
    let mut timings = Vec::new();
    for path in timing_paths {
        let timing = read_timing(root, path)?;
        timings.push(timing);
    }
    let base = build_with(root, timing_paths, "base", &[], held)?;
    let mut boards = Vec::new();
    for ((timing, board), path) in timings.iter().zip(&base.boards).zip(timing_paths) {
        let file = relative(root, path);
        let lowering = Lowering::new(Rows { file: &file }, timing, board)?;
        let (mut sections, tasks) = lowering.task_rows()?;
        sections.extend(lowering.idle_rows()?);
        let buses = lowering.bus_rows()?;
        let task_scripts = lowering.task_script_rows()?;
        let publishers = lowering.publisher_rows(root, timing_paths, held)?;
        // Every priority a job of the board can have: its tasks', its publisher levels' and its monotonic's.
        let highest = tasks
            .iter()
            .map(|t| t.priority)
            .chain(publishers.levels.iter().flatten().copied())
            .chain(publishers.monotonic.map(|m| m.priority))
            .chain(buses.iter().map(|b| b.engine_priority))
            .max()
            .unwrap_or(0);
        let blocking = (0..=u32::from(highest))
            .map(|p| admission::fixed_blocking(&sections, p))
            .collect();
        boards.push(OwnedBoard {
            name: timing.board.clone(),
            task_names: board.tasks.iter().map(|t| t.name.clone()).collect(),
            tasks,
            sections,
            blocking,
            topics: publishers.topics,
            levels: publishers.levels,
            monotonic: publishers.monotonic,
            can_tx: timing
                .can_tx_task
                .as_deref()
                .and_then(|n| lowering.index_of(n)),
            command_handler: timing
                .command_handler
                .as_deref()
                .and_then(|n| lowering.index_of(n)),
            buses,
            task_scripts,
            publisher_tasks: publisher_tasks(timing),
        });
    }
    Ok(OwnedRobot {
        boards,
        bitrate,
        frame_cost: frame_cost.cost(),
        sources: timing_paths.iter().map(|p| relative(root, p)).collect(),
    })
}

/// Per CAN level, a number for its publisher task: levels published by one RTIC task share it (LightRing's one
/// `publish`), so that the check groups their jobs as the analysis groups them (`job_of`).
fn publisher_tasks(timing: &Timing) -> [u8; LEVELS] {
    let mut names: Vec<&str> = Vec::new();
    let mut out = [0u8; LEVELS];
    for (slot, level) in out.iter_mut().zip(Priority::ALL.iter()) {
        let Some(name) = timing.publishers.get(level.name()) else {
            continue;
        };
        let at = names
            .iter()
            .position(|n| *n == name.as_str())
            .unwrap_or_else(|| {
                names.push(name.as_str());
                names.len() - 1
            });
        *slot = at as u8;
    }
    out
}

/// `path` relative to `root`, as the messages and the generated source name files.
fn relative(root: &Path, path: &Path) -> String {
    path.strip_prefix(root)
        .unwrap_or(path)
        .display()
        .to_string()
}

/// One board's lowering: its fixed-task model (built without publishers), timing file, overheads and resolved
/// ceilings.
struct Lowering<'a> {
    rows: Rows<'a>,
    timing: &'a Timing,
    board: &'a BoardModel,
    overheads: OverheadTimes,
    /// Ceilings as the analysis computes them: the static ones, raised by every user's priority.
    ceilings: BTreeMap<&'a str, u32>,
    /// The board's sensor buses, validated by the analysis with the board's overheads (once for every job's
    /// scripts).
    buses: Vec<crate::sensor_bus::SensorBus>,
}

/// What the publisher jobs lower to.
struct PublisherRows {
    topics: Vec<OwnedTopic>,
    levels: [Option<u8>; LEVELS],
    monotonic: Option<MonotonicRow>,
}

impl<'a> Lowering<'a> {
    fn new(rows: Rows<'a>, timing: &'a Timing, board: &'a BoardModel) -> Result<Self, BuildError> {
        let mut ceilings: BTreeMap<&str, u32> = board
            .ceilings
            .iter()
            .map(|(r, c)| (r.as_str(), *c))
            .collect();
        for t in &board.tasks {
            for r in t.critical_sections_us.keys() {
                let c = ceilings.entry(r.as_str()).or_insert(0);
                *c = (*c).max(t.priority);
            }
        }
        let overheads = overhead_times(&board.overheads);
        let buses = crate::sensor_bus::validate_buses(&board.sensor_buses, &overheads)
            .map_err(|(field, e)| rows.fail(&field, e.to_string()))?;
        Ok(Lowering {
            rows,
            timing,
            board,
            overheads,
            ceilings,
            buses,
        })
    }

    /// A task's index in the board's fixed tasks.
    fn index_of(&self, name: &str) -> Option<u16> {
        self.board
            .tasks
            .iter()
            .position(|t| t.name == name)
            .map(|i| i as u16)
    }

    /// A resource's resolved ceiling (`u32::MAX` for the global critical section).
    fn ceiling_of(&self, r: &str) -> u32 {
        if r == GLOBAL_CRITICAL_SECTION {
            u32::MAX
        } else {
            self.ceilings.get(r).copied().unwrap_or(0)
        }
    }

    /// The fixed tasks' critical sections and rows, in the board model's order.
    fn task_rows(&self) -> Result<(Vec<SectionRow>, Vec<TaskRow>), BuildError> {
        let rows = &self.rows;
        let mut tasks = Vec::new();
        let mut sections = Vec::new();
        let transmit = self.timing.can_tx_task.as_deref();
        for t in &self.board.tasks {
            let stated = self.timing.tasks.get(&t.name);
            // The transmit interrupt and its jobs (`can_tx[…]`): no deadline of their own, a bound only.
            let bounded_only =
                transmit.is_some_and(|tx| t.name == tx || t.job_of.as_deref() == Some(tx));
            let own_frame = stated.is_some_and(|b| b.arrival == Some(Arrival::OwnFrame));
            let field = |name: &str| format!("tasks.{}.{name}", t.name);
            let released_by = match t.released_by.as_deref().and_then(|n| self.index_of(n)) {
                None => NO_RELEASER,
                Some(i) => u8::try_from(i)
                    .ok()
                    .filter(|&i| i != NO_RELEASER)
                    .ok_or_else(|| {
                        rows.fail(
                            &field("released_by"),
                            "more tasks than the on-chip admission table indexes (255)".to_string(),
                        )
                    })?,
            };
            let mut row = TaskRow {
                priority: rows.priority(&field("priority"), t.priority)?,
                cost: rows.time(
                    &field("wcet_us"),
                    Time::from_us_up(t.wcet_us).plus(self.overheads.for_kind(t.kind)),
                )?,
                period: rows.time(&field("period_us"), Time::from_us_down(t.period_us))?,
                // The transmit task's rows have none (the scenario gives them none): `bounded_only`.
                deadline: match t.deadline_us {
                    Some(d) => rows.time(&field("deadline_us"), Time::from_us_down(d))?,
                    None => NO_DEADLINE,
                },
                jitter: rows.time(&field("jitter_us"), Time::from_us_up(t.jitter_us))?,
                released_by,
                own_frame,
                bounded_only,
                share: admission::SHARE_AT_RUNTIME,
            };
            if !own_frame {
                row.share = admission::row_share(row.cost, row.period);
            }
            tasks.push(row);
            for (r, length) in &t.critical_sections_us {
                let field = field(&format!("critical_sections_us.{r}"));
                sections.push(SectionRow {
                    holder_priority: rows.priority(&field, t.priority)?,
                    ceiling: rows.ceiling(&field, self.ceiling_of(r))?,
                    length: rows.time(&field, Time::from_us_up(*length))?,
                });
            }
        }
        Ok((sections, tasks))
    }

    /// The board's sensor buses as the check's rows (the analysis's validation, the board's overheads).
    fn bus_rows(&self) -> Result<Vec<BusRow>, BuildError> {
        let buses = &self.buses;
        if buses.len() > MAX_BUSES {
            return Err(self.rows.fail(
                "sensor_buses",
                format!("more than the on-chip admission check's {MAX_BUSES} sensor buses"),
            ));
        }
        buses
            .iter()
            .enumerate()
            .map(|(b, bus)| {
                let field = |name: &str| format!("sensor_buses[{b}].engine.{name}");
                let part =
                    |p: &Option<crate::sensor_bus::Part>| p.as_ref().map_or(Time::ZERO, |p| p.time);
                Ok(BusRow {
                    engine_priority: self
                        .rows
                        .priority(&field("priority"), bus.engine_priority)?,
                    per_event: self.rows.time(&field("per_event_us"), bus.per_event)?,
                    per_script: self
                        .rows
                        .time(&field("per_script"), part(&bus.per_script))?,
                    condition_wait: self
                        .rows
                        .time(&field("condition_wait"), part(&bus.condition_wait))?,
                })
            })
            .collect()
    }

    /// A job's scripts (`field`: the task's or topic's) as the check's rows, validated as the analysis does.
    fn script_rows(&self, job: &TaskModel, field: &str) -> Result<Vec<ScriptRow>, BuildError> {
        let fail = |(f, e): crate::sensor_bus::Refusal| self.rows.fail(&f, e.to_string());
        let mut out = Vec::new();
        for (p, script) in
            crate::sensor_bus::job_scripts(job.script.as_ref(), job.scripts.as_deref(), field)
                .map_err(fail)?
        {
            let s = crate::sensor_bus::validate_script(&self.buses, script, &p).map_err(fail)?;
            let count = |n: u32, name: &str| {
                u16::try_from(n).map_err(|_| {
                    self.rows.fail(
                        &format!("{p}.{name}"),
                        format!("{n} does not fit the on-chip admission table (at most 65 535)"),
                    )
                })
            };
            out.push(ScriptRow {
                bus: u8::try_from(s.bus).unwrap_or(u8::MAX),
                bus_time: self
                    .rows
                    .time(&format!("{p}.bus_time_us"), s.wire.plus(s.stretch))?,
                events: count(s.events, "events")?,
                starts: count(s.starts, "starts")?,
                settle: self.rows.time(&format!("{p}.settle_us"), s.settle)?,
            });
        }
        Ok(out)
    }

    /// The fixed tasks that run scripts, with their rows.
    fn task_script_rows(&self) -> Result<Vec<(u8, Vec<ScriptRow>)>, BuildError> {
        let mut out = Vec::new();
        for (i, t) in self.board.tasks.iter().enumerate() {
            let scripts = self.script_rows(t, &format!("tasks.{}", t.name))?;
            if !scripts.is_empty() {
                let i = u8::try_from(i).map_err(|_| {
                    self.rows.fail(
                        &format!("tasks.{}", t.name),
                        "more tasks than the on-chip admission table indexes (255)".to_string(),
                    )
                })?;
                out.push((i, scripts));
            }
        }
        Ok(out)
    }

    /// Idle's critical sections (holder priority 0).
    fn idle_rows(&self) -> Result<Vec<SectionRow>, BuildError> {
        let mut sections = Vec::new();
        for (r, length) in &self.board.idle_critical_sections_us {
            let field = format!("idle.critical_sections_us.{r}");
            sections.push(SectionRow {
                holder_priority: 0,
                ceiling: self.rows.ceiling(&field, self.ceiling_of(r))?,
                length: self.rows.time(&field, Time::from_us_up(*length))?,
            });
        }
        Ok(sections)
    }

    /// The publishable topics: those the timing file budgets and the protocol gives to this board.
    fn publishable(&self) -> Vec<&'static amiro_can::TopicInfo> {
        self.timing
            .topics
            .keys()
            .filter_map(|name| Topic::from_name(name).map(|t| t.info()))
            .filter(|info| {
                info.is_sensor && scenario::board_folder(info.board) == self.timing.board
            })
            .collect()
    }

    /// Per CAN level with a publisher task: the board built with every publishable topic at that level, whose
    /// publisher jobs give the level's priority and (once per topic) the topic's row, and whose timer job gives
    /// the monotonic's row.
    fn publisher_rows(
        &self,
        root: &Path,
        timing_paths: &[PathBuf],
        held: scenario::Held<'_>,
    ) -> Result<PublisherRows, BuildError> {
        let timing = self.timing;
        let owned = self.publishable();
        let mut out = PublisherRows {
            topics: Vec::new(),
            levels: [None; LEVELS],
            monotonic: None,
        };
        for (l, level) in Priority::ALL.iter().enumerate() {
            let Some(publisher) = timing.publishers.get(level.name()) else {
                continue;
            };
            if owned.is_empty() {
                continue;
            }
            let wanted: Vec<(String, &str)> = owned
                .iter()
                .map(|i| (i.name.to_string(), level.name()))
                .collect();
            let model = build_with(
                root,
                timing_paths,
                &format!("{}-{}", timing.board, level.name()),
                &wanted,
                held,
            )?;
            let Some(b) = model.boards.iter().find(|b| b.name == timing.board) else {
                continue;
            };
            for info in &owned {
                let job_name = format!("{publisher}[{}]", info.name);
                let Some(job) = b.tasks.iter().find(|t| t.name == job_name) else {
                    continue;
                };
                if let Some(slot) = out.levels.get_mut(l) {
                    *slot = Some(
                        self.rows
                            .priority(&format!("publishers.{}", level.name()), job.priority)?,
                    );
                }
                match out.topics.iter_mut().find(|t| t.name == info.name) {
                    None => {
                        let mut row = self.topic_row(info, job)?;
                        row.transmit = self.transmit_cost(&b.tasks, job)?;
                        out.topics.push(row);
                    }
                    // The row is the topic's at every level, but a job's sections are those that block: at a more
                    // urgent level a section at the job's own priority raises nothing and is not in its model (a
                    // sample's bus lock at priority 4 in a publisher job at 4), while at a lower level it blocks
                    // every job up to its ceiling. The row keeps each ceiling's longest section of every level, so
                    // the check blocks as the report does whatever level the topic runs at.
                    Some(row) => {
                        for s in self.topic_row(info, job)?.sections {
                            match row.sections.iter_mut().find(|k| k.ceiling == s.ceiling) {
                                Some(k) => k.length = k.length.max(s.length),
                                None => row.sections.push(s),
                            }
                        }
                    }
                }
                if let Some(timer) = b
                    .tasks
                    .iter()
                    .find(|t| t.name == format!("monotonic[{job_name}]"))
                {
                    out.monotonic = Some(self.monotonic_row(timer)?);
                }
            }
        }
        Ok(out)
    }

    /// The cost of the transmit interrupt's job that publisher job `job` releases (the report's
    /// `<can_tx>[<topic>]`, built where the transmit interrupt is charged by its parts), with the hardware-task
    /// overheads; 0 where the report builds none. The check builds that job at the transmit task's priority, at the
    /// publisher's period with that as its deadline, released by the publisher job with
    /// [`crate::can::transmit_abort_latency`] as its own jitter: a row the report builds otherwise fails here.
    fn transmit_cost(&self, tasks: &[TaskModel], job: &TaskModel) -> Result<RowTime, BuildError> {
        let Some(tx_name) = self.timing.can_tx_task.as_deref() else {
            return Ok(0);
        };
        let Some(topic) = job.name.split_once('[').map(|(_, rest)| rest) else {
            return Ok(0);
        };
        let name = format!("{tx_name}[{topic}");
        let Some(row) = tasks.iter().find(|t| t.name == name) else {
            return Ok(0);
        };
        let field = format!("tasks.{name}");
        let tx = self.board.tasks.iter().find(|t| t.name == tx_name);
        let bit = can::bit_time(can::DEFAULT_BITRATE);
        let as_built = row.released_by.as_deref() == Some(job.name.as_str())
            && tx.is_some_and(|tx| tx.priority == row.priority)
            && row.period_us == job.period_us
            && row.deadline_us.is_none()
            && Time::from_us_up(row.jitter_us) == can::transmit_abort_latency(bit);
        if !as_built {
            return Err(self.rows.fail(
                &field,
                format!(
                    "the on-chip check builds this job at `{tx_name}`'s priority, released by `{}` at its period \
                     with three of the longest frames as its jitter; the report built it otherwise",
                    job.name
                ),
            ));
        }
        self.rows.time(
            &field,
            Time::from_us_up(row.wcet_us).plus(self.overheads.for_kind(row.kind)),
        )
    }

    /// A topic's row from its publisher job.
    fn topic_row(
        &self,
        info: &amiro_can::TopicInfo,
        job: &TaskModel,
    ) -> Result<OwnedTopic, BuildError> {
        let rows = &self.rows;
        let field = |name: &str| format!("topics.{}.{name}", info.name);
        let mut topic_sections = Vec::new();
        for (r, length) in &job.critical_sections_us {
            let field = field(&format!("critical_sections_us.{r}"));
            topic_sections.push(TopicSection {
                ceiling: rows.ceiling(&field, self.ceiling_of(r))?,
                length: rows.time(&field, Time::from_us_up(*length))?,
            });
        }
        Ok(OwnedTopic {
            name: info.name.to_string(),
            topic: info.topic.byte(),
            cost: rows.time(
                &field("wcet_us"),
                Time::from_us_up(job.wcet_us).plus(self.overheads.for_kind(TaskKind::Software)),
            )?,
            bcet: rows.time(
                &field("bcet_us"),
                Time::from_us_down(job.bcet_us.unwrap_or(0.0)),
            )?,
            sections: topic_sections,
            scripts: self.script_rows(job, &format!("topics.{}", info.name))?,
            transmit: 0,
        })
    }

    /// The monotonic's row from the timer job that releases a publisher job.
    fn monotonic_row(&self, timer: &TaskModel) -> Result<MonotonicRow, BuildError> {
        let field = format!("tasks.{}", timer.name);
        Ok(MonotonicRow {
            priority: self.rows.priority(&field, timer.priority)?,
            cost: self.rows.time(
                &field,
                Time::from_us_up(timer.wcet_us).plus(self.overheads.for_kind(TaskKind::Hardware)),
            )?,
            jitter: self.rows.time(&field, Time::from_us_up(timer.jitter_us))?,
        })
    }
}

impl OwnedRobot {
    /// Runs `f` on the borrowed [`RobotTable`] view of this table.
    pub fn with_table<R>(&self, f: impl FnOnce(&RobotTable<'_>) -> R) -> R {
        let topic_rows: Vec<Vec<TopicRow<'_>>> = self
            .boards
            .iter()
            .map(|b| {
                b.topics
                    .iter()
                    .map(|t| TopicRow {
                        topic: t.topic,
                        cost: t.cost,
                        bcet: t.bcet,
                        sections: &t.sections,
                        scripts: &t.scripts,
                        transmit: t.transmit,
                    })
                    .collect()
            })
            .collect();
        let task_scripts: Vec<Vec<admission::TaskScripts<'_>>> = self
            .boards
            .iter()
            .map(|b| {
                b.task_scripts
                    .iter()
                    .map(|(i, list)| (*i, list.as_slice()))
                    .collect()
            })
            .collect();
        let boards: Vec<BoardTable<'_>> = self
            .boards
            .iter()
            .zip(&topic_rows)
            .zip(&task_scripts)
            .map(|((b, topics), task_scripts)| BoardTable {
                name: &b.name,
                tasks: &b.tasks,
                sections: &b.sections,
                blocking: &b.blocking,
                topics,
                shortest_dlc: b.shortest_dlc(),
                levels: b.levels,
                monotonic: b.monotonic,
                can_tx: b.can_tx,
                command_handler: b.command_handler,
                buses: &b.buses,
                task_scripts,
                publisher_tasks: b.publisher_tasks,
            })
            .collect();
        f(&RobotTable {
            boards: &boards,
            bit_time: can::bit_time(self.bitrate),
            frame_cost: self.frame_cost,
        })
    }

    /// The most jobs one board can have: its fixed tasks plus a job and a timer job per publishable topic, an
    /// engine row per script of each, and a transmit job per topic with a `transmit` cost.
    pub fn max_tasks(&self) -> usize {
        self.boards
            .iter()
            .map(|b| {
                let scripts: usize = b.task_scripts.iter().map(|(_, l)| l.len()).sum::<usize>()
                    + b.topics.iter().map(|t| t.scripts.len()).sum::<usize>();
                let transmit = b.topics.iter().filter(|t| t.transmit > 0).count();
                b.tasks.len() + 2 * b.topics.len() + scripts + transmit
            })
            .max()
            .unwrap_or(0)
    }

    /// The protocol's limit of running publishers on the bus: one per publishable sensor topic.
    pub fn max_publishers(&self) -> usize {
        self.boards.iter().map(|b| b.topics.len()).sum()
    }

    /// Index of a board by name.
    pub fn board_index(&self, name: &str) -> Option<u8> {
        self.boards
            .iter()
            .position(|b| b.name == name)
            .map(|i| i as u8)
    }

    /// The stream of `topic` published at `level` every `period` (deadline `None`: the period).
    pub fn publisher_stream(
        &self,
        topic: &str,
        level: &str,
        period: Time,
        deadline: Option<Time>,
    ) -> Option<Stream> {
        let info = Topic::from_name(topic)?.info();
        let priority = Priority::from_name(level)?;
        let l = Priority::ALL.iter().position(|p| *p == priority)? as u8;
        let board = self.board_index(scenario::board_folder(info.board))?;
        Some(Stream {
            id: u32::from(CanId::new(Kind::Sensor, priority, info.topic.byte()).raw()),
            extended: false,
            dlc: info.dlc,
            frames: u32::from(info.frames_per_sample.max(1)),
            period,
            deadline,
            jitter: Time::ZERO,
            sender: Some(Sender {
                board,
                topic: info.topic.byte(),
                level: l,
            }),
            receiver: None,
        })
    }

    /// The stream of operator commands to `topic` at `level`, at least `period` apart.
    pub fn command_stream(
        &self,
        topic: &str,
        level: &str,
        period: Time,
        jitter: Time,
        deadline: Option<Time>,
    ) -> Option<Stream> {
        let info = Topic::from_name(topic)?.info();
        let priority = Priority::from_name(level)?;
        let board = self.board_index(scenario::board_folder(info.board))?;
        let has_handler = self
            .boards
            .get(usize::from(board))
            .is_some_and(|b| b.command_handler.is_some());
        Some(Stream {
            id: u32::from(CanId::new(Kind::Command, priority, info.topic.byte()).raw()),
            extended: false,
            dlc: info.dlc,
            frames: 1,
            period,
            deadline,
            jitter,
            sender: None,
            receiver: has_handler.then_some(board),
        })
    }

    /// The streams of a scenario file's publishers and commands.
    pub fn scenario_streams(&self, scenario: &scenario::Scenario) -> Option<Vec<Stream>> {
        let mut out = Vec::new();
        for p in &scenario.publishers {
            out.push(self.publisher_stream(
                &p.topic,
                &p.priority,
                Time::from_us_down(p.period_us),
                p.deadline_us.map(Time::from_us_down),
            )?);
        }
        for c in &scenario.commands {
            out.push(self.command_stream(
                &c.topic,
                &c.priority,
                Time::from_us_down(c.period_us),
                Time::from_us_up(c.jitter_us),
                c.deadline_us.map(Time::from_us_down),
            )?);
        }
        Some(out)
    }

    /// Whether a build that links the check's sensor-bus rounds or not (`sensor_buses`) can decide this table:
    /// one without them cannot take a board that states a sensor bus or a script.
    pub fn check_sensor_buses_linked(
        &self,
        sensor_buses: bool,
    ) -> Result<(), SensorBusesNotLinked> {
        match self.boards.iter().find(|b| {
            !b.buses.is_empty()
                || !b.task_scripts.is_empty()
                || b.topics.iter().any(|t| !t.scripts.is_empty())
        }) {
            Some(b) if !sensor_buses => Err(SensorBusesNotLinked {
                board: b.name.clone(),
            }),
            _ => Ok(()),
        }
    }

    /// The table as Rust source: `static ROBOT: RobotTable<'static>` and its capacities, with types from
    /// `crate_path` (`schedule_analysis`).
    pub fn to_rust_source(&self, crate_path: &str) -> String {
        let t = |time: Time| format!("{crate_path}::time::Time::from_ns({})", time.as_ns());
        let opt = |v: Option<u16>| v.map_or_else(|| "None".to_string(), |x| format!("Some({x})"));
        let a = format!("{crate_path}::admission");
        let mut s = String::new();
        let _ = writeln!(
            s,
            "// Generated by schedule_analysis::admission_host::lower from {}. Do not edit: the build regenerates it.",
            self.sources.join(", ")
        );
        let _ = writeln!(
            s,
            "/// Most jobs of one board (fixed tasks, publisher and timer jobs)."
        );
        let _ = writeln!(s, "pub const MAX_TASKS: usize = {};", self.max_tasks());
        let _ = writeln!(
            s,
            "/// The protocol's limit of running publishers on the bus."
        );
        let _ = writeln!(
            s,
            "pub const MAX_PUBLISHERS: usize = {};",
            self.max_publishers()
        );
        for (i, b) in self.boards.iter().enumerate() {
            let _ = writeln!(s, "/// Index of board `{}` in `ROBOT.boards`.", b.name);
            let _ = writeln!(
                s,
                "pub const BOARD_{}: u8 = {i};",
                b.name.to_uppercase().replace('-', "_")
            );
        }
        let _ = writeln!(s, "/// The robot's task models and bus, for `{a}::admit`.");
        let _ = writeln!(
            s,
            "pub static ROBOT: {a}::RobotTable<'static> = {a}::RobotTable {{"
        );
        let _ = writeln!(s, "    boards: &[");
        for b in &self.boards {
            let _ = writeln!(s, "        {a}::BoardTable {{");
            let _ = writeln!(s, "            name: {:?},", b.name);
            let _ = writeln!(s, "            tasks: &[");
            for (row, name) in b.tasks.iter().zip(&b.task_names) {
                let _ = writeln!(
                    s,
                    "                // {name}\n                {a}::TaskRow {{ priority: {}, cost: {}, period: {}, deadline: {}, jitter: {}, released_by: {}, own_frame: {}, bounded_only: {}, share: {} }},",
                    row.priority, row.cost, row.period, row.deadline, row.jitter, row.released_by, row.own_frame, row.bounded_only, row.share
                );
            }
            let _ = writeln!(s, "            ],\n            sections: &[");
            for cs in &b.sections {
                let _ = writeln!(
                    s,
                    "                {a}::SectionRow {{ holder_priority: {}, ceiling: {}, length: {} }},",
                    cs.holder_priority, cs.ceiling, cs.length
                );
            }
            let blocking: Vec<String> = b.blocking.iter().map(u32::to_string).collect();
            let _ = writeln!(
                s,
                "            ],\n            blocking: &[{}],\n            topics: &[",
                blocking.join(", ")
            );
            for topic in &b.topics {
                let sections: Vec<String> = topic
                    .sections
                    .iter()
                    .map(|cs| {
                        format!(
                            "{a}::TopicSection {{ ceiling: {}, length: {} }}",
                            cs.ceiling, cs.length
                        )
                    })
                    .collect();
                let _ = writeln!(
                    s,
                    "                // {}\n                {a}::TopicRow {{ topic: {}, cost: {}, bcet: {}, sections: &[{}], scripts: &[{}], transmit: {} }},",
                    topic.name, topic.topic, topic.cost, topic.bcet, sections.join(", "), script_rows(&a, &topic.scripts), topic.transmit
                );
            }
            let _ = writeln!(
                s,
                "            ],\n            shortest_dlc: {},",
                b.shortest_dlc()
            );
            let levels: Vec<String> = b
                .levels
                .iter()
                .map(|l| l.map_or_else(|| "None".to_string(), |p| format!("Some({p})")))
                .collect();
            let _ = writeln!(s, "            levels: [{}],", levels.join(", "));
            let _ = writeln!(
                s,
                "            monotonic: {},",
                b.monotonic.map_or_else(
                    || "None".to_string(),
                    |m| format!(
                        "Some({a}::MonotonicRow {{ priority: {}, cost: {}, jitter: {} }})",
                        m.priority, m.cost, m.jitter
                    )
                )
            );
            let _ = writeln!(s, "            can_tx: {},", opt(b.can_tx));
            let _ = writeln!(
                s,
                "            command_handler: {},",
                opt(b.command_handler)
            );
            let buses: Vec<String> = b
                .buses
                .iter()
                .map(|bus| {
                    format!(
                        "{a}::BusRow {{ engine_priority: {}, per_event: {}, per_script: {}, condition_wait: {} }}",
                        bus.engine_priority, bus.per_event, bus.per_script, bus.condition_wait
                    )
                })
                .collect();
            let _ = writeln!(s, "            buses: &[{}],", buses.join(", "));
            let task_scripts: Vec<String> = b
                .task_scripts
                .iter()
                .map(|(i, list)| format!("({i}, &[{}])", script_rows(&a, list)))
                .collect();
            let _ = writeln!(
                s,
                "            task_scripts: &[{}],",
                task_scripts.join(", ")
            );
            let groups: Vec<String> = b.publisher_tasks.iter().map(u8::to_string).collect();
            let _ = writeln!(s, "            publisher_tasks: [{}],", groups.join(", "));
            let _ = writeln!(s, "        }},");
        }
        let cost = match self.frame_cost {
            FrameCost::Thesis => format!("{crate_path}::can::FrameCost::Thesis"),
            FrameCost::Exact => format!("{crate_path}::can::FrameCost::Exact"),
            FrameCost::Fixed(x) => format!("{crate_path}::can::FrameCost::Fixed({})", t(x)),
        };
        let _ = writeln!(
            s,
            "    ],\n    bit_time: {},\n    frame_cost: {cost},\n}};",
            t(can::bit_time(self.bitrate))
        );
        s
    }

    /// The on-chip check's cost on `board`'s worst configuration we know: every publishable topic of the robot
    /// running (the protocol's limit) at its default period, all at one level; `board`'s last topic requested
    /// at its default period (one analysis), and at 1 µs (refused: the analysis plus both suggestion searches).
    /// The most expensive of the four levels is reported for each.
    pub fn worst_case_cost(&self, board: usize) -> Option<CheckCost> {
        let b = self.boards.get(board)?;
        let last = b.topics.last()?;
        let default_period = |name: &str| {
            Topic::from_name(name)
                .map(|t| Time::from_us(u64::from(t.info().default_period_us.max(1))))
        };
        let mut worst: Option<CheckCost> = None;
        for level in Priority::ALL {
            let mut streams = Vec::new();
            for other in &self.boards {
                for t in &other.topics {
                    streams.push(self.publisher_stream(
                        &t.name,
                        level.name(),
                        default_period(&t.name)?,
                        None,
                    )?);
                }
            }
            let request =
                self.publisher_stream(&last.name, level.name(), default_period(&last.name)?, None)?;
            let mut flood = request;
            flood.period = Time::from_us(1);
            let (plain, searched) = self.with_table(|robot| {
                (
                    admission::admit::<64, 64>(robot, &streams, &request, false),
                    admission::admit::<64, 64>(robot, &streams, &flood, true),
                )
            });
            let cost = CheckCost {
                publishers: streams.len(),
                tasks: b.tasks.len()
                    + 2 * b.topics.len()
                    + b.topics.iter().filter(|t| t.transmit > 0).count(),
                iterations_per_analysis: plain.iterations,
                iterations_with_search: searched.iterations,
                analyses_with_search: searched.evaluations,
            };
            worst = Some(match worst {
                None => cost,
                Some(w) => CheckCost {
                    iterations_per_analysis: w
                        .iterations_per_analysis
                        .max(cost.iterations_per_analysis),
                    iterations_with_search: w
                        .iterations_with_search
                        .max(cost.iterations_with_search),
                    analyses_with_search: w.analyses_with_search.max(cost.analyses_with_search),
                    ..cost
                },
            });
        }
        worst
    }
}

/// Script rows as Rust source (`{a}`: the admission module's path).
fn script_rows(a: &str, scripts: &[ScriptRow]) -> String {
    let rows: Vec<String> = scripts
        .iter()
        .map(|r| {
            format!(
                "{a}::ScriptRow {{ bus: {}, bus_time: {}, events: {}, starts: {}, settle: {} }}",
                r.bus, r.bus_time, r.events, r.starts, r.settle
            )
        })
        .collect();
    rows.join(", ")
}

/// What one on-chip decision costs, in fixed-point iterations.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CheckCost {
    /// Running publishers on the bus in the configuration.
    pub publishers: usize,
    /// The board's jobs at most.
    pub tasks: usize,
    /// Iterations of one whole-robot analysis (a decision without suggestions).
    pub iterations_per_analysis: u64,
    /// Iterations of a refusal with both suggestion searches.
    pub iterations_with_search: u64,
    /// Whole-robot analyses that refusal ran.
    pub analyses_with_search: u32,
}
