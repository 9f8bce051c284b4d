//! One board's task model, step by step: which tasks it declares ([`super::declared`]), the roles the timing
//! file names checked against them, the declared tasks with their budgets, the publisher jobs of the scenario's
//! topics, the timer jobs that release both, idle's critical sections, and the firmware build's overheads.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use amiro_can::{Priority, Topic};

use super::declared::{declared_tasks, Declared};
use super::plan::Planned;
use super::{
    fail, qemu, Arrival, BuildError, Built, Firmware, Measured, Monotonic, Scenario, Timing,
    ACKS_PER_TRANSMIT_JOB,
};
use crate::can;
use crate::model::{BoardModel, Overheads, TaskKind, TaskModel, GLOBAL_CRITICAL_SECTION};
use crate::time::Time;

/// Where each board's end of a message's path is: the publisher job that sends a topic, the task that acts on
/// a board's commands.
#[derive(Default)]
pub(super) struct Ends {
    /// `board/publisher[topic]` per published topic.
    pub(super) senders: BTreeMap<Topic, String>,
    /// `board/handler` per board with a command handler.
    pub(super) receivers: BTreeMap<String, String>,
}

/// Every board of the timing files, with the scenario's topics it owns, into `built.model.boards`; `received`: the
/// run's received frames no closer than this ([`super::build_for_run`]).
#[allow(clippy::too_many_arguments)]
pub(super) fn build_boards(
    root: &Path,
    timings: &[(String, Timing)],
    sensors: &[Planned],
    scenario: &Scenario,
    bit: Time,
    firmware: Firmware,
    received: Option<Time>,
    held: super::bounded::Held<'_>,
    built: &mut Built,
) -> Result<Ends, BuildError> {
    let mut ends = Ends::default();
    for (file, timing) in timings {
        let mine: Vec<&Planned> = sensors
            .iter()
            .filter(|p| super::board_folder(p.info.board) == timing.board)
            .collect();
        // The transmit-complete interrupt cannot come faster than the shortest frame this board can send: every
        // topic it can publish (its timing file's `topics`), not only the set's streams, since a decided one-shot
        // or a stopped stream's queued frames still go out after they left the set.
        let own_frame = can::own_frame_time(
            bit,
            timing
                .topics
                .keys()
                .filter_map(|name| amiro_can::Topic::from_name(name))
                .map(|topic| topic.dlc())
                .chain(mine.iter().map(|p| p.info.dlc)),
        );
        // A run whose received frames are known (a QEMU stimulus) receives them no closer than they come.
        let bus_frame = can::shortest_frame_time(bit);
        let arrivals = Arrivals {
            bus_frame: received.map_or(bus_frame, |gap| gap.max(bus_frame)),
            own_frame,
            bit,
        };
        let board = build_board(
            root, file, timing, &mine, scenario, arrivals, firmware, held, built,
        )?;
        for p in &mine {
            let publisher = timing
                .publishers
                .get(p.priority.name())
                .cloned()
                .unwrap_or_default();
            ends.senders.insert(
                p.info.topic,
                format!("{}/{}[{}]", timing.board, publisher, p.info.name),
            );
        }
        if let Some(handler) = &timing.command_handler {
            ends.receivers
                .insert(timing.board.clone(), format!("{}/{handler}", timing.board));
        }
        built.model.boards.push(board);
    }
    Ok(ends)
}

/// QEMU's stimulus replay ([`super::QemuReplay`]) as a task: one job per received frame.
fn replay_task(
    root: &Path,
    file: &str,
    timing: &Timing,
    replay: &super::QemuReplay,
    arrivals: Arrivals,
) -> Result<TaskModel, BuildError> {
    super::plan::check_positive(file, "trace.qemu.replay.per_frame_us", replay.per_frame_us)?;
    Ok(TaskModel {
        name: replay.task.clone(),
        priority: qemu::replay_priority(root, file, timing, replay)?,
        wcet_us: replay.per_frame_us,
        period_us: arrivals.bus_frame.as_us_f64(),
        deadline_us: None,
        jitter_us: 0.0,
        critical_sections_us: BTreeMap::new(),
        blocking_us: None,
        bcet_us: None,
        // Its entry, exit and trace records as every job's; the dispatch and the monotonic interrupt
        // that wake it are in `per_frame_us` (one wake-up per frame, nothing else shares it).
        kind: TaskKind::Hardware,
        released_by: None,
        sporadic: true,
        job_of: None,
        script: None,
        scripts: None,
    })
}

/// The inter-arrival times of the bus-driven arrivals ([`Arrival::BusFrame`], [`Arrival::OwnFrame`]).
#[derive(Clone, Copy)]
struct Arrivals {
    /// The shortest frame on the bus.
    bus_frame: Time,
    /// The shortest frame this board sends.
    own_frame: Time,
    /// One bit time on the bus.
    bit: Time,
}

#[allow(clippy::too_many_arguments)]
fn build_board(
    root: &Path,
    file: &str,
    timing: &Timing,
    topics: &[&Planned],
    scenario: &Scenario,
    arrivals: Arrivals,
    firmware: Firmware,
    held: super::bounded::Held<'_>,
    built: &mut Built,
) -> Result<BoardModel, BuildError> {
    // The machine-code bounds replace the stated budgets (before any QEMU scaling: they are the chip's).
    let (bounded_timing, budgets) =
        super::bounded::apply(root, file, timing, held, &mut built.warnings)?;
    let timing = &bounded_timing;
    let scaled;
    let timing = match (
        firmware,
        timing.trace.as_ref().and_then(|t| t.qemu.as_ref()),
    ) {
        (Firmware::Qemu, Some(q)) if q.budget_scale != 1.0 => {
            scaled = timing.scaled(q.budget_scale, &budgets);
            &scaled
        }
        _ => timing,
    };
    let (declared, idle, mut ceilings) = declared_tasks(root, file, timing, built)?;
    check_roles(file, timing, &declared)?;
    let board = Board {
        file,
        timing,
        declared: &declared,
        publisher_tasks: timing.publishers.values().map(String::as_str).collect(),
    };
    let mut measured: Vec<String> = Vec::new();
    let mut timer_jobs = TimerJobs {
        file,
        monotonic: timing.monotonic,
        jobs: Vec::new(),
    };
    let mut tasks = board.fixed_tasks(arrivals, &mut timer_jobs, &mut measured, built)?;
    board.publisher_jobs(topics, scenario, &mut timer_jobs, &mut measured, &mut tasks)?;
    if firmware != Firmware::Qemu {
        if let Some(parts) = transmit_parts(timing, &budgets) {
            let line = super::transmit::charge_by_parts(
                file,
                timing,
                &declared,
                &parts,
                arrivals.bit,
                &mut tasks,
            )?;
            built.sources.push(line);
        }
    }
    if firmware == Firmware::Qemu {
        if let Some(replay) = timing
            .trace
            .as_ref()
            .and_then(|t| t.qemu.as_ref())
            .and_then(|q| q.replay.as_ref())
        {
            let task = replay_task(root, file, timing, replay, arrivals)?;
            built.sources.push(format!(
                "{}: in QEMU `{}` replays the stimulus: one job of {} µs per received frame (every {:.1} µs at most), \
                 at priority {} (its wake-up and dispatch included)",
                timing.board, task.name, task.wcet_us, task.period_us, task.priority
            ));
            tasks.push(task);
        }
    }
    let idle_sections = idle_sections(file, timing, idle.as_ref())?;

    // Timer jobs first: they are the most urgent and read best at the top of the table.
    let mut all = timer_jobs.jobs;
    all.extend(tasks);
    let source = built.sources.last().cloned();
    let mut budgets = budgets;
    super::bounded::apply_sections(&mut budgets, &mut all, &mut ceilings);
    built
        .sources
        .extend(super::bounded::budgets_lines(&budgets, &measured));
    built.sources.push(super::bounded::blocking_line(&budgets));
    if let Some(line) = admission_line(timing, &measured, &budgets) {
        built.sources.push(line);
    }
    built.budgets.push(budgets);
    let overheads = build_overheads(file, timing, firmware, &mut all, built)?;
    let fixed = timing.tasks.iter().map(|(name, t)| {
        (
            format!("tasks.{name}"),
            t.script.as_ref(),
            t.scripts.as_deref(),
        )
    });
    let jobs = timing.topics.iter().map(|(name, t)| {
        (
            format!("topics.{name}"),
            t.script.as_ref(),
            t.scripts.as_deref(),
        )
    });
    let jobs = fixed.chain(jobs);
    crate::sensor_bus::check_timing(&timing.sensor_buses, jobs)
        .map_err(|(field, e)| fail(file, field, e.to_string()))?;
    Ok(BoardModel {
        name: timing.board.clone(),
        source,
        overheads,
        idle_critical_sections_us: idle_sections,
        can_tx_task: timing.can_tx_task.clone(),
        ceilings,
        tasks: all,
        sensor_buses: timing.sensor_buses.clone(),
    })
}

/// The transmit task's parts, where its row in the bounds file is used (not declined) and charged by its parts.
fn transmit_parts(
    timing: &Timing,
    budgets: &super::bounded::BoardBudgets,
) -> Option<crate::bounds::FrameParts> {
    let name = timing.can_tx_task.as_deref()?;
    let row = budgets.bounds.as_ref()?.task(name)?;
    if row.declined.is_some() {
        return None;
    }
    row.job.as_ref()?.parts.clone()
}

/// The tasks the timing file gives a role (a publisher per CAN level, the command handler, the transmit task)
/// must be declared, and a publisher task is budgeted per topic, not as a task.
fn check_roles(file: &str, timing: &Timing, declared: &[Declared]) -> Result<(), BuildError> {
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
    Ok(())
}

/// The monotonic's timer interrupt as one job per timer-released task (`monotonic[task]`), in the order the
/// released tasks are built.
struct TimerJobs<'f> {
    file: &'f str,
    monotonic: Option<Monotonic>,
    jobs: Vec<TaskModel>,
}

impl TimerJobs<'_> {
    /// Adds the timer job that releases `released` and returns its name; an error at `path` when the board has
    /// no monotonic.
    fn add(&mut self, released: &TaskModel, path: &str) -> Result<String, BuildError> {
        let m = self.monotonic.ok_or_else(|| {
            fail(
                self.file,
                path,
                "released by the timer, but the file has no `monotonic`",
            )
        })?;
        let name = format!("monotonic[{}]", released.name);
        self.jobs.push(TaskModel {
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
            script: None,
            scripts: None,
        });
        Ok(name)
    }
}

/// What the task-building steps of one board share.
struct Board<'a> {
    file: &'a str,
    timing: &'a Timing,
    declared: &'a [Declared],
    /// The publisher tasks: their jobs are the topics, not tasks of their own.
    publisher_tasks: BTreeSet<&'a str>,
}

impl Board<'_> {
    fn find(&self, name: &str) -> Option<&Declared> {
        self.declared.iter().find(|d| d.name == name)
    }

    /// Every declared task but the publishers, with its budget, arrival, critical sections and releaser.
    fn fixed_tasks(
        &self,
        arrivals: Arrivals,
        timer_jobs: &mut TimerJobs<'_>,
        measured: &mut Vec<String>,
        built: &mut Built,
    ) -> Result<Vec<TaskModel>, BuildError> {
        let (file, timing) = (self.file, self.timing);
        let mut tasks = Vec::new();
        for d in self
            .declared
            .iter()
            .filter(|d| !self.publisher_tasks.contains(d.name.as_str()))
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
            let wcet = budget(estimate, t.measured.as_ref(), &d.name, measured);
            let arrival = t.arrival.ok_or_else(|| fail(file, format!("{p}.arrival"), "missing: \"bus_frame\", \"own_frame\", {\"periodic_us\": ..} or {\"sporadic_us\": ..}"))?;
            let (period_us, sporadic) = match arrival {
                Arrival::BusFrame => (arrivals.bus_frame.as_us_f64(), true),
                Arrival::OwnFrame => (arrivals.own_frame.as_us_f64(), true),
                Arrival::PeriodicUs(us) => (us, false),
                Arrival::SporadicUs(us) => (us, true),
            };
            super::plan::check_positive(file, &format!("{p}.arrival"), period_us)?;
            // The transmit task has no deadline of its own: a late job loses no completion, and its response is
            // charged to every message this board sends as queuing jitter (docs/analysis.md, "The transmit
            // interrupt keeps no deadline"); the analysis checks only that its busy window closes.
            let transmit = timing.can_tx_task.as_deref() == Some(d.name.as_str());
            if transmit && t.deadline_us.is_some() {
                return Err(fail(
                    file,
                    format!("{p}.deadline_us"),
                    "the transmit task (`can_tx_task`) has no deadline of its own: its response is every \
                     message's queuing jitter",
                ));
            }
            let deadline_us = t.deadline_us;
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
                deadline_us,
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
                script: t.script.clone(),
                scripts: t.scripts.clone(),
            };
            task.released_by = match t.released_by.as_deref() {
                None => None,
                Some("timer") => Some(timer_jobs.add(&task, &format!("{p}.released_by"))?),
                Some(other)
                    if self.find(other).is_some() && !self.publisher_tasks.contains(other) =>
                {
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
        Ok(tasks)
    }

    /// One job of the level's publisher task per topic the scenario publishes on this board (`publisher[topic]`),
    /// released by the timer when the board has a monotonic; appended to `tasks`.
    fn publisher_jobs(
        &self,
        topics: &[&Planned],
        scenario: &Scenario,
        timer_jobs: &mut TimerJobs<'_>,
        measured: &mut Vec<String>,
        tasks: &mut Vec<TaskModel>,
    ) -> Result<(), BuildError> {
        let (file, timing) = (self.file, self.timing);
        for planned in topics {
            let level = planned.priority.name();
            let publisher = timing.publishers.get(level).ok_or_else(|| {
                fail(
                    file,
                    "publishers",
                    format!("no publisher task for CAN priority {level}"),
                )
            })?;
            let d = self.find(publisher).ok_or_else(|| {
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
            let wcet = budget(t.wcet_us, t.measured.as_ref(), name, measured);
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
                script: t.script.clone(),
                scripts: t.scripts.clone(),
            };
            if timer_jobs.monotonic.is_some() {
                job.released_by = Some(timer_jobs.add(&job, &p)?);
            }
            tasks.push(job);
        }
        Ok(())
    }
}

/// Idle's critical sections: a length for every resource idle locks, and only for those (plus the global one).
fn idle_sections(
    file: &str,
    timing: &Timing,
    idle: Option<&Declared>,
) -> Result<BTreeMap<String, f64>, BuildError> {
    let mut idle_sections = BTreeMap::new();
    if let Some(idle) = idle {
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
        } else if !idle.is_some_and(|i| i.shared.contains(r)) {
            return Err(fail(
                file,
                format!("idle_critical_sections_us.{r}"),
                "idle does not use this resource",
            ));
        }
    }
    Ok(idle_sections)
}

/// The source line of the board's on-chip admission task (`admit_requests`, docs/analysis.md "The admission
/// task"): the CPU share its budget reserves, what the budget rests on, and — beside the costliest step measured —
/// the machine-code bound from its iteration caps, saying which of the two the analysis uses.
fn admission_line(
    timing: &Timing,
    measured: &[String],
    budgets: &super::BoardBudgets,
) -> Option<String> {
    let task = timing.tasks.get("admit_requests")?;
    let wcet = task.wcet_us?;
    let period = match task.arrival {
        Some(Arrival::SporadicUs(p)) | Some(Arrival::PeriodicUs(p)) if p > 0.0 => p,
        _ => return None,
    };
    let step = task.worst_step.as_ref().map(|step| {
        format!(
            "the costliest step measured, {} instructions of its own ({} fixed-point iterations; {}), at an assumed {} cycles per instruction and {} MHz = {:.0} µs",
            step.instructions,
            step.iterations,
            step.measured_in,
            step.cycles_per_instruction,
            step.clock_mhz,
            step.on_chip_us(),
        )
    });
    let basis = match budgets.rows.get("admit_requests") {
        Some(super::BudgetFrom::Bound { us, stated_us, .. }) => format!(
            "one step's bound from the machine code (its iteration caps): {us:.0} µs; beside it the stated budget {stated_us:.0} µs{}; the analysis uses the bound",
            step.map(|s| format!(" rests on {s}")).unwrap_or_default()
        ),
        other => {
            let why = match other {
                Some(super::BudgetFrom::Stated { why }) => why.clone(),
                _ => "no bound".to_string(),
            };
            let stated = if measured.iter().any(|m| m.starts_with("admit_requests ")) {
                "a measured budget".to_string()
            } else if let (Some(s), Some(st)) = (&step, &task.worst_step) {
                format!(
                    "one step's budget, an estimate: {s}, the budget {:.0} % above it; not a bench measurement",
                    100.0 * (wcet / st.on_chip_us() - 1.0)
                )
            } else {
                "one step's budget, an estimate (no measured step recorded in the timing file), not a bench measurement"
                    .to_string()
            };
            format!("{stated}; the bound from its iteration caps is not used ({why}): the analysis uses the stated budget")
        }
    };
    Some(format!(
        "{}: admission reserves {:.1} % of the CPU (admit_requests: {:.0} µs per {:.0} µs), {basis}",
        timing.board,
        100.0 * wcet / period,
        wcet,
        period
    ))
}

/// The board's overheads in the firmware build `firmware`: the task trace's start and end records where every
/// job's entry and exit are counted, the transmit task's acknowledgement records on the chip, and QEMU's
/// transmit jobs ([`qemu::transmit_jobs`]) in the traced QEMU build.
fn build_overheads(
    file: &str,
    timing: &Timing,
    firmware: Firmware,
    tasks: &mut Vec<TaskModel>,
    built: &mut Built,
) -> Result<Overheads, BuildError> {
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
                .and_then(|name| tasks.iter_mut().find(|t| &t.name == name))
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
            qemu::transmit_jobs(file, timing, transmit, &overheads, tasks)?;
            built.sources.push(format!(
                "{}: in QEMU `{}` is pended by the publisher's samples (⌈frames / 3⌉ jobs each) and \
                 the samples `{}`'s commands request, not by a transmit-complete",
                timing.board,
                timing.can_tx_task.as_deref().unwrap_or("?"),
                transmit.requests_from
            ));
        }
    }
    Ok(overheads)
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
