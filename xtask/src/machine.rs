//! The build's checks of the machine code and each image's tasks bounded: thin callers of the
//! `machine-code` crate (the panic check, the stack bound, the execution-time bounds of an image's
//! tasks that `cargo xtask wcet` prints and writes).
use std::path::Path;

use anyhow::{ensure, Context, Result};
use machine_code::stack::short;
use machine_code::{BoundsFile, Chip, Image};

/// No image's admission check can reach a panic: it decides on data from the bus. Prints each
/// image's figures.
pub fn check_panics(reports: &[crate::elf::SizeReport]) -> Result<()> {
    let mut failures = Vec::new();
    for r in reports.iter().filter(|r| r.analysis_symbols > 0) {
        let found = machine_code::callgraph::admission_panics(&r.elf)?;
        println!(
            "{} {}: the admission check ({} functions, {} reachable from them) reaches {} panic path(s)",
            r.board,
            r.revision,
            found.check_functions,
            found.reachable,
            found.paths.len()
        );
        for path in found.paths {
            failures.push(format!("{} {}: {}", r.board, r.revision, path.join(" → ")));
        }
    }
    ensure!(
        failures.is_empty(),
        "the admission check can panic:\n{}",
        failures.join("\n")
    );
    Ok(())
}

/// Every image's static stack bound, and the check that its static RAM and that bound fit the
/// chip's RAM: a stack that cannot overflow into the statics, whatever QEMU's painted stack
/// happened to see.
pub fn check_stacks(root: &Path, reports: &[crate::elf::SizeReport]) -> Result<()> {
    let mut failures = Vec::new();
    for r in reports {
        let source = std::fs::read_to_string(root.join(&r.board).join("src").join("main.rs"))
            .with_context(|| format!("{}'s app source", r.board))?;
        let app = schedule_analysis::rtic_source::parse_app(&source)
            .map_err(|e| anyhow::anyhow!("{}: {e}", r.board))?;
        let mut priorities: Vec<u8> = app
            .tasks
            .iter()
            .map(|t| t.priority)
            .filter(|&p| p > 0)
            .collect();
        priorities.sort_unstable();
        priorities.dedup();
        // Each distinct task priority, the monotonic's timer interrupt, HardFault and NMI.
        let levels = priorities.len() + 3;
        let board =
            crate::boards::by_name(&r.board).with_context(|| format!("no board {}", r.board))?;
        let image = Image::read(&r.elf)?;
        let found = machine_code::stack::bound_in(&image, levels, board.hard_float)
            .with_context(|| format!("{}", r.elf.display()))?;
        let total = r.ram_used + found.bytes;
        let deepest = machine_code::stack::chain_names(&image, &found.thread.chain);
        println!(
            "{} {}: stack ≤ {} B (thread mode {} B, {} nested handlers of {} levels with {}-byte exception frames); static RAM {} B + stack = {} B of {} B; thread mode's deepest: {}",
            r.board,
            r.revision,
            found.bytes,
            found.thread.bytes,
            found.handlers.len(),
            levels,
            found.exception_frame,
            r.ram_used,
            total,
            r.ram_available,
            deepest.iter().map(|n| short(n)).collect::<Vec<_>>().join(" → ")
        );
        if total > r.ram_available {
            failures.push(format!(
                "{} {}: static RAM {} B and a stack bound of {} B exceed the chip's {} B",
                r.board, r.revision, r.ram_used, found.bytes, r.ram_available
            ));
        }
    }
    ensure!(failures.is_empty(), "{}", failures.join("\n"));
    Ok(())
}

/// The chip a board's image runs on, at its board clock's wait states unless overridden.
pub(crate) fn chip_of(board: &crate::boards::Board, wait_states: Option<u32>) -> Result<Chip> {
    let name = if board.chip.starts_with("STM32F103") {
        "stm32f103"
    } else if board.chip.starts_with("STM32F405") {
        "stm32f405"
    } else {
        anyhow::bail!("{}: no cycle model for {}", board.name, board.chip)
    };
    Ok(Chip::parse(name, wait_states)?)
}

/// The tasks of one board's image to bound: its hardware tasks (the handler of the interrupt each
/// binds, named by the task), its dispatchers (`dispatcher <interrupt>`: the interrupt handlers that
/// poll the software tasks of one priority, their bodies inlined into them), each software task
/// (named by the task: its part of its dispatcher, [`machine_code::TaskEntry::Polled`]), and the
/// tasks the bounds file adds (the monotonic's interrupt).
pub fn tasks_of(
    app: &schedule_analysis::rtic_source::RticApp,
    bounds: &BoundsFile,
) -> Vec<machine_code::Task> {
    let mut tasks = Vec::new();
    for task in &app.tasks {
        if let schedule_analysis::rtic_source::RticTaskKind::Hardware { binds } = &task.kind {
            tasks.push(machine_code::Task {
                name: task.name.clone(),
                entry: machine_code::TaskEntry::Symbol(binds.clone()),
                handler: true,
            });
        }
    }
    for dispatcher in &app.dispatchers {
        tasks.push(machine_code::Task {
            name: format!("dispatcher {dispatcher}"),
            entry: machine_code::TaskEntry::Symbol(dispatcher.clone()),
            handler: true,
        });
    }
    // Each software task's job: its part of its dispatcher (the dispatcher's own code and its
    // poll, the other polls of its priority left out).
    let dispatchers = dispatcher_of(app);
    for task in &app.tasks {
        let software = task.kind == schedule_analysis::rtic_source::RticTaskKind::Software;
        let Some(dispatcher) = dispatchers.get(&task.priority).filter(|_| software) else {
            continue;
        };
        let others = app
            .tasks
            .iter()
            .filter(|t| t.kind == task.kind && t.priority == task.priority && t.name != task.name)
            .map(|t| t.name.clone())
            .collect();
        tasks.push(machine_code::Task {
            name: task.name.clone(),
            entry: machine_code::TaskEntry::Polled {
                dispatcher: dispatcher.clone(),
                task: task.name.clone(),
                others,
            },
            handler: true,
        });
    }
    for extra in &bounds.tasks {
        tasks.push(machine_code::Task {
            name: extra.name.clone(),
            entry: machine_code::TaskEntry::Symbol(extra.symbol.clone()),
            handler: extra.handler,
        });
    }
    tasks
}

/// The dispatcher of each software-task priority, as RTIC's code generation assigns them: the priorities of
/// every software task (whatever its `cfg`: RTIC counts them before `cfg` removes any) from the highest down,
/// each taking the last dispatcher not yet taken.
pub fn dispatcher_of(
    app: &schedule_analysis::rtic_source::RticApp,
) -> std::collections::BTreeMap<u8, String> {
    let priorities: std::collections::BTreeSet<u8> = app
        .tasks
        .iter()
        .filter(|t| {
            t.kind == schedule_analysis::rtic_source::RticTaskKind::Software && t.priority > 0
        })
        .map(|t| t.priority)
        .collect();
    let mut available = app.dispatchers.clone();
    priorities
        .iter()
        .rev()
        .filter_map(|&p| available.pop().map(|d| (p, d)))
        .collect()
}

/// One row per task name: a task the bounds file names with several functions, one of which each
/// job runs (the admission step: a decision, `Admission::on_command`, or a refresh step,
/// `Admission::step`), is bounded by the worst of them — declined when any of them is, naming it.
/// The critical sections of a task the bounds file names with several functions, merged as
/// [`worst_per_name`] merges their bounds: per ceiling the longest section (a declined one wins),
/// incomplete when any function's list is.
pub fn sections_per_name(rows: Vec<machine_code::TaskSections>) -> Vec<machine_code::TaskSections> {
    let mut out: Vec<machine_code::TaskSections> = Vec::new();
    for row in rows {
        let Some(kept) = out.iter_mut().find(|k| k.task == row.task) else {
            out.push(row);
            continue;
        };
        if kept.incomplete.is_none() {
            kept.incomplete = row.incomplete;
        }
        for c in row.ceilings {
            match kept.ceilings.iter_mut().find(|k| k.ceiling == c.ceiling) {
                None => kept.ceilings.push(c),
                Some(k) if k.declined.is_some() => {}
                Some(k) => {
                    if c.declined.is_some() || c.us > k.us {
                        *k = c;
                    }
                }
            }
        }
    }
    out
}

pub fn worst_per_name(rows: Vec<machine_code::TaskBound>) -> Vec<machine_code::TaskBound> {
    let mut out: Vec<machine_code::TaskBound> = Vec::new();
    for row in rows {
        let Some(kept) = out.iter_mut().find(|k| k.task == row.task) else {
            out.push(row);
            continue;
        };
        let functions = [kept.function.take(), row.function.clone()]
            .into_iter()
            .flatten()
            .collect::<Vec<_>>()
            .join(" or ");
        if kept.declined.is_none() {
            if let Some(reason) = &row.declined {
                let name = row.function.as_deref().unwrap_or("?");
                kept.declined = Some(format!("{name}: {reason}"));
            } else {
                // The longer in time (cycles and stated waits), and the most instructions of either; the
                // longer charge per activation, declined where either is.
                let instructions = kept.instructions.max(row.instructions);
                let per_activation = match (kept.per_activation.take(), row.per_activation.clone())
                {
                    (Some(a), Some(b)) => Some(
                        if a.declined.is_some() || (b.declined.is_none() && a.us >= b.us) {
                            machine_code::ActivationBound {
                                instructions: a.instructions.max(b.instructions),
                                ..a
                            }
                        } else {
                            machine_code::ActivationBound {
                                instructions: a.instructions.max(b.instructions),
                                ..b
                            }
                        },
                    ),
                    (a, b) => a.or(b),
                };
                let per_frame = match (kept.per_frame.take(), row.per_frame.clone()) {
                    (Some(a), Some(b)) => Some(larger_parts(a, b)),
                    (a, b) => a.or(b),
                };
                if row.us > kept.us {
                    *kept = row;
                }
                kept.instructions = instructions;
                kept.per_activation = per_activation;
                kept.per_frame = per_frame;
            }
        }
        kept.function = Some(functions);
    }
    out
}

/// The larger of two images' parts, part by part (each part bounds its share of every job of either image);
/// declined where either is.
fn larger_parts(
    a: machine_code::FrameBound,
    b: machine_code::FrameBound,
) -> machine_code::FrameBound {
    if a.declined.is_some() {
        return a;
    }
    if b.declined.is_some() {
        return b;
    }
    let max = |x: machine_code::Part, y: machine_code::Part| machine_code::Part {
        cycles: x.cycles.max(y.cycles),
        us: x.us.max(y.us),
        instructions: x.instructions.max(y.instructions),
    };
    let (pass, sent) = (max(a.pass, b.pass), max(a.sent, b.sent));
    machine_code::FrameBound {
        fixed: max(a.fixed, b.fixed),
        abort: max(a.abort, b.abort),
        per_frame: machine_code::Part {
            cycles: pass.cycles + sent.cycles,
            us: pass.us + sent.us,
            instructions: pass.instructions + sent.instructions,
        },
        pass,
        sent,
        ..a
    }
}

/// One image's task bounds, with what they were computed from.
pub struct Bounded {
    pub chip: Chip,
    pub app: schedule_analysis::rtic_source::RticApp,
    pub tasks: Vec<machine_code::TaskBound>,
    /// Each task's critical sections per ceiling, in the order of `tasks`.
    pub sections: Vec<machine_code::TaskSections>,
    /// The bounds file's entries that name no place in this image (`BoundsFile::missing_places`).
    pub missing: Vec<String>,
    /// The tasks whose bound the generated file holds back from the analysis (`BoundsFile::held`).
    pub held: Vec<machine_code::wcet::bounds::HeldBound>,
    /// Per topic group of the image (the bounds file's `topics`), the critical sections of each of
    /// its functions and what they reach, with the group's own waits ([`group_sections`]).
    pub group_sections: GroupSections,
    /// Per task with topic bounds, the sections one release of each of its topic groups can hold
    /// ([`topic_sections`]).
    pub topic_sections: TopicSections,
}

/// Per task's name, per topic group's name, the sections of the task's job as that group's
/// topic bound takes it.
pub type TopicSections = std::collections::BTreeMap<
    String,
    std::collections::BTreeMap<String, machine_code::TaskSections>,
>;

/// The sections of each publisher task's job per topic group (`machine_code::topic_sections`: the
/// calls of the other groups' functions left out with the blocks only they lead to, the group's own
/// waits), for the tasks whose bound has topic bounds (`found`); a task bounded by several entries
/// (by name) has per group the longest of theirs at each ceiling ([`sections_per_name`]).
pub fn topic_sections(
    image: &Image,
    tasks: &[machine_code::Task],
    found: &[machine_code::TaskBound],
    chip: Chip,
    bounds: &BoundsFile,
) -> TopicSections {
    let mut out = TopicSections::new();
    for task in tasks {
        if !found
            .iter()
            .any(|f| f.task == task.name && !f.topics.is_empty())
        {
            continue;
        }
        let per_group = out.entry(task.name.clone()).or_default();
        for (group, sections) in machine_code::topic_sections(image, task, chip, bounds) {
            let merged = match per_group.remove(&group) {
                Some(kept) => sections_per_name(vec![kept, sections]).remove(0),
                None => sections,
            };
            per_group.insert(group, merged);
        }
    }
    out
}

/// Per topic group's name, each of its functions in the image with its critical sections.
pub type GroupSections =
    std::collections::BTreeMap<String, Vec<(String, machine_code::TaskSections)>>;

/// The critical sections of every present topic group's functions (the bounds file's `topics`),
/// each function taken as an entry of its own and bounded with its group's waits and loops
/// (`BoundsFile::for_topic_group`, as the group's release bound is): what a release of the group
/// may hold beside the publisher's own code (docs/analysis.md, "One topic's job").
pub fn group_sections(image: &Image, chip: Chip, bounds: &BoundsFile) -> GroupSections {
    let Some(per_topic) = &bounds.topics else {
        return GroupSections::new();
    };
    per_topic
        .present(image)
        .into_iter()
        .map(|group| {
            let stated = bounds.for_topic_group(per_topic, group);
            let functions: Vec<machine_code::Task> = group
                .functions
                .iter()
                .filter(|f| image.function_named(f).is_ok())
                .map(|f| machine_code::Task {
                    name: f.clone(),
                    entry: machine_code::TaskEntry::Symbol(f.clone()),
                    handler: false,
                })
                .collect();
            let found = machine_code::task_sections(image, &functions, chip, &stated);
            let sections = functions
                .iter()
                .map(|f| f.name.clone())
                .zip(found)
                .collect();
            (group.name.clone(), sections)
        })
        .collect()
}

/// Bounds every task of `build`'s kept release image (it must be built) with the board's input
/// bounds file (`bounds`, else `schedule-analysis/models/<board>.bounds.json` if there is one).
pub fn bound_build(
    root: &Path,
    build: &crate::revision::Build,
    wait_states: Option<u32>,
    bounds: Option<&Path>,
) -> Result<Bounded> {
    let elf = crate::workspace::kept_elf(root, build, false);
    bound_image(root, build, &[], &elf, wait_states, bounds)
}

/// [`bound_build`] of the image `elf`, built for `build` with the trial's `extra` features as well (`cargo xtask
/// wcet --features`: the tasks a feature adds to the app, or removes, as that image has them).
pub fn bound_image(
    root: &Path,
    build: &crate::revision::Build,
    extra: &[&str],
    elf: &Path,
    wait_states: Option<u32>,
    bounds: Option<&Path>,
) -> Result<Bounded> {
    let board = build.board;
    ensure!(
        elf.exists(),
        "{} is not built: cargo xtask build {} --revision {}",
        elf.display(),
        board.name,
        build.revision.name
    );
    let chip = chip_of(board, wait_states)?;
    let default_bounds = root
        .join("schedule-analysis")
        .join("models")
        .join(format!("{}.bounds.json", board.name));
    let bounds = match bounds.or(Some(default_bounds.as_path()).filter(|p| p.exists())) {
        Some(path) => BoundsFile::read(path)?,
        None => BoundsFile::default(),
    };
    let source = std::fs::read_to_string(root.join(board.name).join("src").join("main.rs"))
        .with_context(|| format!("{}'s app source", board.name))?;
    let app = schedule_analysis::rtic_source::parse_app(&source)
        .map_err(|e| anyhow::anyhow!("{}: {e}", board.name))?;
    // A software task the image as built leaves out (`#[cfg]`: DiWheelDrive's QEMU-only stimulus) has
    // no part of its dispatcher to bound.
    let features: Vec<&str> = build
        .revision
        .feature
        .into_iter()
        .chain(extra.iter().copied())
        .collect();
    let built = app.with_features(&features);
    let tasks: Vec<machine_code::Task> = tasks_of(&app, &bounds)
        .into_iter()
        .filter(|t| {
            !matches!(t.entry, machine_code::TaskEntry::Polled { .. })
                || built.tasks.iter().any(|b| b.name == t.name)
        })
        .collect();
    let image = Image::read(elf).with_context(|| format!("{}", elf.display()))?;
    let sections = sections_per_name(machine_code::task_sections(&image, &tasks, chip, &bounds));
    let group_sections = group_sections(&image, chip, &bounds);
    let found = machine_code::bound_tasks(&image, &tasks, chip, &bounds);
    let topic_sections = topic_sections(&image, &tasks, &found, chip, &bounds);
    let tasks = worst_per_name(found);
    let missing = bounds.missing_places(&image);
    let held = held_on(&bounds.held, board, build.revision)?;
    Ok(Bounded {
        held,
        chip,
        app,
        tasks,
        sections,
        missing,
        group_sections,
        topic_sections,
    })
}

/// The bounds file's held statements that hold back on `revision`'s image of `board` (a statement
/// without `revisions` on every image); a statement naming a revision the board has none of is an error.
fn held_on(
    held: &[machine_code::wcet::bounds::HeldBound],
    board: &crate::boards::Board,
    revision: &crate::boards::Revision,
) -> Result<Vec<machine_code::wcet::bounds::HeldBound>> {
    let known: Vec<&str> = board.revisions.iter().map(|r| r.name).collect();
    let mut out = Vec::new();
    for h in held {
        if h.holds_on(revision.name, &known)
            .with_context(|| format!("{}.bounds.json", board.name))?
        {
            out.push(h.clone());
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_board_holds_back_only_what_its_revision_lists() {
        let file = BoundsFile::parse(
            r#"{"held":[{"task":"publisher[*]","revisions":["1-2"],"reason":"polled on 1-2"},
                        {"task":"can_tx","reason":"every image"}]}"#,
        )
        .unwrap();
        let dwd = crate::boards::by_name("diwheeldrive").unwrap();
        let on = |rev: &str| -> Vec<String> {
            let r = dwd.revisions.iter().find(|r| r.name == rev).unwrap();
            held_on(&file.held, dwd, r)
                .unwrap()
                .into_iter()
                .map(|h| h.task)
                .collect()
        };
        assert_eq!(on("1-2"), ["publisher[*]", "can_tx"]);
        assert_eq!(on("1-1"), ["can_tx"]);
        // LightRing's revisions are 1-2 and 1-0: a statement for a 1-1 ring is a typed error naming it.
        let lightring = crate::boards::by_name("lightring").unwrap();
        let ring = BoundsFile::parse(
            r#"{"held":[{"task":"can_tx","revisions":["1-1"],"reason":"loose"}]}"#,
        )
        .unwrap();
        let e = held_on(&ring.held, lightring, lightring.newest()).unwrap_err();
        let unknown = e
            .downcast_ref::<machine_code::wcet::bounds::UnknownRevision>()
            .unwrap();
        assert_eq!(
            (unknown.revision.as_str(), &unknown.known[..]),
            ("1-1", &["1-2".to_string(), "1-0".to_string()][..])
        );
        assert!(
            format!("{e:#}").starts_with("lightring.bounds.json: "),
            "{e:#}"
        );
    }

    fn row(
        task: &str,
        function: &str,
        cycles: u64,
        declined: Option<&str>,
    ) -> machine_code::TaskBound {
        machine_code::TaskBound {
            task: task.into(),
            function: Some(function.into()),
            cycles,
            us: cycles as f64 / 72.0,
            instructions: 1000 - cycles,
            bus_wait_us: 0.0,
            loops: Vec::new(),
            preemption_retry_cycles: 0,
            declined: declined.map(str::to_string),
            per_activation: None,
            per_frame: None,
            topics: Vec::new(),
        }
    }

    #[test]
    fn a_task_of_several_functions_is_bounded_by_the_worst() {
        let rows = worst_per_name(vec![
            row("step", "decide", 720, None),
            row("other", "f", 72, None),
            row("step", "refresh", 144, None),
        ]);
        assert_eq!(rows.len(), 2);
        let step = &rows[0];
        // The longer one's time, the most instructions of either (856 from `refresh`).
        assert_eq!((step.cycles, step.us, step.instructions), (720, 10.0, 856));
        assert_eq!(step.function.as_deref(), Some("decide or refresh"));
        let rows = worst_per_name(vec![
            row("step", "decide", 720, None),
            row("step", "refresh", 0, Some("a loop without a bound")),
        ]);
        assert_eq!(
            rows[0].declined.as_deref(),
            Some("refresh: a loop without a bound")
        );
    }
}
