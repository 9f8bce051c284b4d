//! `cargo xtask wcet --write`: the machine code's bounds of each image written into its generated bounds file
//! (`schedule-analysis/models/<board>[-<rev>].wcet.json`, [`schedule_analysis::bounds`]), under the rows the
//! analysis reads: the RTIC tasks of the board's timing file, `publisher[<topic>]` per topic, and the overheads.
//!
//! How the machine code's rows map onto them (docs/analysis.md, "Budgets from the machine code"):
//! - a hardware task's row is the bound of the handler of the interrupt it binds;
//! - a software task's row is the bound of its part of the dispatcher of its priority (with LTO the task bodies
//!   are inlined into it): the dispatcher's own code and the task's poll, the other tasks' polls left out by the
//!   DWARF inlined subroutines that name them (`machine_code::TaskEntry::Polled`); where the machine code does
//!   not tell the task's part, the whole dispatcher's bound (one poll of every task of that priority, sound and
//!   pessimistic);
//! - `publisher[<topic>]` is the largest bound of the publisher tasks (a topic may be published at any level),
//!   declined if any of them is: of one release of the topic's group where the bounds file states the release
//!   loop per topic (`topics`, `machine_code::TopicBound`), else of the task's whole job; its critical sections
//!   are the publisher tasks' (any job of the task may hold them);
//! - a task or topic whose timing-file entry states `script` or `scripts` suspends on them: its row is one release,
//!   `schedule_analysis::bounds::release_polls` times one poll's bound (a topic's: the publisher tasks' whole
//!   bound), the poll kept as the row's `release` ([`as_release`]; docs/analysis.md, "A suspending release: the sum
//!   of its polls"), or declined where the task's polls cannot be found;
//! - `monotonic` is the bound of the monotonic's interrupt (the task the input bounds file adds);
//! - `exception_entry` and `exception_exit` are the core's (the TRM's 12 and 10 cycles, the entry with lazy FPU
//!   stacking on the M4F), with the flash accesses' wait states (the vector read and the handler's first fetch on
//!   entry, the interrupted code's refetch on return): counted once more on top of every handler's bound, which
//!   includes the TRM's figures already;
//! - `dispatcher` is not written: each software task's bound already contains its dispatcher's code, and the
//!   timing file's stated figure, counted on top, is pessimism, not a gap.
//!
//! The bounds feed the admission tables compiled into the images (read-only data), so writing them can change
//! the images; the gate hashes the executable sections only, and `--write` rebuilds and repeats until the files
//! it writes are the files it finds (a fixed point), or fails.
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use anyhow::{bail, ensure, Context, Result};
use machine_code::Chip;
use schedule_analysis::bounds::{self, BoundsFile, CeilingSection, CeilingSections, TaskBound};
use schedule_analysis::rtic_source::{RticApp, RticTaskKind};

use crate::machine::dispatcher_of;
use crate::revision::Build;
use crate::wcet_gate;

/// How often `--write` builds and bounds before it gives up on a fixed point.
const ROUNDS: usize = 3;

/// Builds the images of `plan`, bounds them and writes their bounds files; repeats (rebuilding with the files
/// just written) until no file changes.
pub fn write(
    root: &Path,
    plan: &[Build],
    wait_states: Option<u32>,
    input: Option<&Path>,
) -> Result<()> {
    for round in 1..=ROUNDS {
        crate::workspace::build_boards(root, plan, false)?;
        let mut changed = Vec::new();
        for build in plan {
            let file = generate(root, build, wait_states, input)?;
            let path = wcet_gate::bounds_path(root, build);
            let text = file.to_json();
            if std::fs::read_to_string(&path).ok().as_deref() != Some(text.as_str()) {
                std::fs::write(&path, &text)
                    .with_context(|| format!("writing {}", path.display()))?;
                changed.push(
                    path.strip_prefix(root)
                        .unwrap_or(&path)
                        .display()
                        .to_string(),
                );
            }
        }
        if changed.is_empty() {
            // What CI's gate will find: each file matches its image as just rebuilt.
            for build in plan {
                let elf = crate::workspace::kept_elf(root, build, false);
                ensure!(
                    wcet_gate::check_one(root, build, &elf)? == wcet_gate::Gate::Current,
                    "{}: no bounds file after writing it",
                    build.stem()
                );
            }
            println!(
                "bounds files: current with the images built from them (round {round}: rebuilt, nothing changed)"
            );
            return Ok(());
        }
        println!(
            "bounds files: wrote {} (round {round}); rebuilding with them",
            changed.join(", ")
        );
    }
    bail!(
        "the bounds files did not settle in {ROUNDS} rounds: each image built with them has other code than the \
         one bounded (docs/analysis.md, \"Budgets from the machine code\")"
    )
}

/// The names a board's timing file gives budgets: its tasks, its topics, its publisher tasks.
#[derive(Debug, Default)]
pub struct Budgets {
    pub tasks: Vec<String>,
    pub topics: Vec<String>,
    pub publishers: BTreeSet<String>,
    /// Per task its stated budget and its deadline (or period), µs, where the file gives them.
    pub stated: BTreeMap<String, (f64, f64)>,
    /// Per task or topic that suspends on scripts (its `script` or `scripts`), whether each script has a settle
    /// before it, in the job's order: its rows are a release's polls ([`as_release`]). Keyed `tasks.<name>` and
    /// `topics.<name>`, as the timing file places them.
    pub scripts: BTreeMap<String, Vec<bool>>,
}

/// The scripts one job of a timing file states, through the analysis's own reading
/// ([`schedule_analysis::sensor_bus::job_scripts`]: both `script` and `scripts`, or an empty list, is refused
/// as the analysis refuses it): per script whether the job waits before it (`settle_us` above 0), in the job's
/// order. Empty without either.
fn scripts_of(
    script: Option<&schedule_analysis::sensor_bus::ScriptModel>,
    scripts: Option<&[schedule_analysis::sensor_bus::ScriptModel]>,
    field: &str,
) -> Result<Vec<bool>> {
    let list = schedule_analysis::sensor_bus::job_scripts(script, scripts, field)
        .map_err(|(at, e)| anyhow::anyhow!("{at}: {e}"))?;
    Ok(list
        .into_iter()
        .map(|(_, s)| s.settle_us.is_some_and(|v| v > 0.0))
        .collect())
}

/// Reads the timing file of `build`'s board at its robot revision.
fn budgets_of(root: &Path, build: &Build) -> Result<Budgets> {
    let wanted = format!("{}.timing.json", build.board.name);
    let path = schedule_analysis::scenario::timing_files_for(root, Some(build.robot()))
        .into_iter()
        .find(|p| p.file_name().and_then(|n| n.to_str()) == Some(wanted.as_str()))
        .with_context(|| format!("no {wanted} for a {} robot", build.robot()))?;
    let text =
        std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    let json: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("{}", path.display()))?;
    let keys = |field: &str| -> Vec<String> {
        json.get(field)
            .and_then(|v| v.as_object())
            .map(|o| o.keys().cloned().collect())
            .unwrap_or_default()
    };
    let publishers = json
        .get("publishers")
        .and_then(|v| v.as_object())
        .map(|o| {
            o.values()
                .filter_map(|v| v.as_str().map(str::to_string))
                .collect()
        })
        .unwrap_or_default();
    let stated = json
        .get("tasks")
        .and_then(|v| v.as_object())
        .map(|tasks| {
            tasks
                .iter()
                .filter_map(|(name, t)| {
                    let wcet = t.get("wcet_us")?.as_f64()?;
                    let arrival = t
                        .get("arrival")
                        .and_then(|a| a.as_object())
                        .and_then(|a| a.values().find_map(|v| v.as_f64()));
                    let deadline = t.get("deadline_us").and_then(|d| d.as_f64()).or(arrival)?;
                    Some((name.clone(), (wcet, deadline)))
                })
                .collect()
        })
        .unwrap_or_default();
    let typed: schedule_analysis::scenario::Timing =
        serde_json::from_str(&text).with_context(|| format!("{}", path.display()))?;
    let mut scripts = BTreeMap::new();
    let jobs = typed
        .tasks
        .iter()
        .map(|(name, t)| {
            (
                format!("tasks.{name}"),
                t.script.as_ref(),
                t.scripts.as_deref(),
            )
        })
        .chain(typed.topics.iter().map(|(name, t)| {
            (
                format!("topics.{name}"),
                t.script.as_ref(),
                t.scripts.as_deref(),
            )
        }));
    for (field, script, list) in jobs {
        let settles =
            scripts_of(script, list, &field).with_context(|| format!("{}", path.display()))?;
        if !settles.is_empty() {
            scripts.insert(field, settles);
        }
    }
    Ok(Budgets {
        tasks: keys("tasks"),
        topics: keys("topics"),
        publishers,
        stated,
        scripts,
    })
}

/// The bounds file of `build`'s kept image.
fn generate(
    root: &Path,
    build: &Build,
    wait_states: Option<u32>,
    input: Option<&Path>,
) -> Result<BoundsFile> {
    let found = crate::machine::bound_build(root, build, wait_states, input)?;
    let elf = crate::workspace::kept_elf(root, build, false);
    let bytes = std::fs::read(&elf).with_context(|| format!("reading {}", elf.display()))?;
    let image = wcet_gate::image_identity(&bytes).with_context(|| elf.display().to_string())?;
    let budgets = budgets_of(root, build)?;
    let features: Vec<&str> = build.revision.feature.into_iter().collect();
    let mut rows = rows_with_groups(
        &found.app.with_features(&features),
        &found.app,
        &budgets,
        &found.tasks,
        &found.sections,
        &found.group_sections,
        &found.topic_sections,
        found.chip,
    );
    hold(&mut rows, &found.held);
    // The workspace's own files by their path in it, not this checkout's.
    let here = format!("{}/", root.display());
    for r in &mut rows {
        if let Some(reason) = &mut r.declined {
            *reason = reason.replace(&here, "");
        }
        if let Some(sections) = &mut r.sections {
            if let Some(reason) = &mut sections.incomplete {
                *reason = reason.replace(&here, "");
            }
            for c in &mut sections.ceilings {
                c.at = c.at.replace(&here, "");
                if let Some(reason) = &mut c.declined {
                    *reason = reason.replace(&here, "");
                }
            }
        }
    }
    let chip = if found.chip.m4() {
        bounds::Chip::Stm32f405
    } else {
        bounds::Chip::Stm32f103
    };
    Ok(BoundsFile {
        generated: format!(
            "{} from target/firmware/{}.elf; do not edit (docs/analysis.md)",
            bounds::GENERATED_PREFIX,
            build.stem()
        ),
        board: build.board.name.to_string(),
        revision: build
            .revision
            .feature
            .and_then(|f| f.strip_prefix("rev-"))
            .map(str::to_string),
        chip,
        clock_hz: found.chip.clock_hz(),
        wait_states: found.chip.wait_states() as u32,
        image,
        tasks: rows,
        idle_critical_sections: BTreeMap::new(),
    })
}

/// `cycles` at `chip`'s clock in µs, rounded up to the file's 0.001 µs.
fn us(cycles: u64, clock_hz: u64) -> f64 {
    ((cycles as f64 * 1e9 / clock_hz as f64).ceil() / 1000.0).max(0.0)
}

/// The rows the bounds file holds back (`held`): declined for the analysis, the bound and why it is not
/// used in the reason, so the report shows both (docs/analysis.md, "Held bounds").
fn hold(rows: &mut [TaskBound], held: &[machine_code::wcet::bounds::HeldBound]) {
    for r in rows.iter_mut() {
        let Some(h) = held.iter().find(|h| h.names(&r.task)) else {
            continue;
        };
        // Its critical sections come from the same paths: held with it, the stated ones stand. The bound, its
        // job and its sections are kept in structured form (`held`), for the report's run on every bound.
        let sections = r.sections.take();
        let figures = match (&r.declined, r.cycles, r.us, r.instructions) {
            (None, Some(cycles), Some(us), Some(instructions)) => Some((cycles, us, instructions)),
            _ => None,
        };
        if figures.is_some() || sections.is_some() {
            r.held = Some(bounds::HeldBound {
                cycles: figures.map(|f| f.0),
                us: figures.map(|f| f.1),
                instructions: figures.map(|f| f.2),
                bus_wait_us: if figures.is_some() {
                    r.bus_wait_us
                } else {
                    0.0
                },
                reason: h.reason.clone(),
                sections,
                job: figures.and(r.job.clone()),
            });
        }
        let bound = match (&r.declined, r.cycles, r.us, r.instructions) {
            (None, Some(cycles), Some(us), Some(instructions)) => {
                let figures = format!(
                    "{cycles} cycles ({us} µs, {instructions} instructions, bus waits {} µs)",
                    r.bus_wait_us
                );
                match r.job.take() {
                    None if r.release.is_some() => {
                        let p = r.release.as_ref().map_or((0, 0), |p| (p.polls, p.poll_cycles));
                        format!(
                            "bounded from the machine code at {figures} per release ({} polls of at most {} cycles)",
                            p.0, p.1
                        )
                    }
                    None => format!("bounded from the machine code at {figures}"),
                    Some(job) if job.parts.is_some() => {
                        let p = job.parts.as_ref().map_or((0, 0, 0), |p| {
                            (p.fixed_cycles, p.per_frame_cycles, p.abort_cycles)
                        });
                        format!(
                            "bounded from the machine code at {figures} per frame sent, by its parts ({}: {} cycles \
                             once per job, {} per frame, {} per abort), its job at {} cycles ({} µs, {} instructions)",
                            job.per_activation
                                .split_once(": ")
                                .map_or(job.per_activation.as_str(), |(at, _)| at),
                            p.0,
                            p.1,
                            p.2,
                            job.cycles,
                            job.us,
                            job.instructions
                        )
                    }
                    // Where and at how many passes; the bounds file holds why.
                    Some(job) => format!(
                        "bounded from the machine code at {figures} per activation ({}), its job at {} cycles \
                         ({} µs, {} instructions)",
                        job.per_activation
                            .split_once(": ")
                            .map_or(job.per_activation.as_str(), |(at, _)| at),
                        job.cycles,
                        job.us,
                        job.instructions
                    ),
                }
            }
            (Some(reason), ..) => format!("declined ({reason}), its critical sections"),
            _ => "its bound".to_string(),
        };
        r.declined = Some(format!(
            "{}: {bound}, held back as its budget: {}",
            r.task, h.reason
        ));
        r.cycles = None;
        r.us = None;
        r.instructions = None;
    }
}

fn declined(task: &str, reason: String) -> TaskBound {
    TaskBound {
        task: task.to_string(),
        cycles: None,
        us: None,
        instructions: None,
        bus_wait_us: 0.0,
        declined: Some(reason),
        critical_sections: BTreeMap::new(),
        sections: None,
        job: None,
        held: None,
        release: None,
    }
}

fn bounded(task: &str, cycles: u64, instructions: u64, bus_wait_us: f64, clock: u64) -> TaskBound {
    TaskBound {
        task: task.to_string(),
        cycles: Some(cycles),
        us: Some(us(cycles, clock)),
        instructions: Some(instructions),
        bus_wait_us,
        declined: None,
        critical_sections: BTreeMap::new(),
        sections: None,
        job: None,
        held: None,
        release: None,
    }
}

/// The row of a task or topic that suspends on its scripts (`settles`: one per script, whether a settle comes
/// before it; `stated_as`: where the timing file states them) as one release: [`bounds::release_polls`] times its
/// one-poll bound `row`, the poll kept as `release` (docs/analysis.md, "A suspending release: the sum of its
/// polls"). Declined where the task's polls cannot be found (`polls_found`: an interrupt handler, thread mode, no
/// task of the image) or the row is a charge per activation; a declined row keeps its reason.
fn as_release(
    row: TaskBound,
    settles: &[bool],
    stated_as: &str,
    polls_found: Result<(), String>,
    clock: u64,
) -> TaskBound {
    let n = settles.len();
    let settled = settles.iter().filter(|s| **s).count();
    let scripts = format!(
        "{n} script{} stated ({stated_as}), {settled} with a settle before it",
        if n == 1 { "" } else { "s" }
    );
    let refuse = |why: String| TaskBound {
        sections: row.sections.clone(),
        ..declined(&row.task, format!("{}: {scripts}, but {why}", row.task))
    };
    if let Err(why) = polls_found {
        return refuse(format!("its polls cannot be found: {why}"));
    }
    if row.job.is_some() {
        return refuse(
            "its row is a charge per activation, which a release of polls cannot be".into(),
        );
    }
    let (Some(cycles), Some(instructions), None) = (row.cycles, row.instructions, &row.declined)
    else {
        return row;
    };
    let polls = bounds::release_polls(settles);
    let reason = format!(
        "{scripts}: at most {polls} polls, each within one poll's bound: 1 takes the release, {} resume it after \
         each script and each settle, {n} a second wake of a script's await may add (its timeout's and its \
         transfer's wakers), 1 the release point's channel may add (its receiver's waker, kept when its wait ends, \
         woken once by the next send)",
        n + settled
    );
    TaskBound {
        release: Some(bounds::ReleaseBound {
            polls,
            poll_cycles: cycles,
            poll_us: us(cycles, clock),
            poll_instructions: instructions,
            poll_bus_wait_us: row.bus_wait_us,
            reason,
        }),
        sections: row.sections.clone(),
        ..bounded(
            &row.task,
            polls * cycles,
            polls * instructions,
            polls as f64 * row.bus_wait_us,
            clock,
        )
    }
}

/// The row `task` from the machine code's bound `found` and its critical sections (named `what` in a reason).
fn from_found(
    task: &str,
    what: &str,
    found: Option<(&machine_code::TaskBound, &machine_code::TaskSections)>,
    clock: u64,
) -> TaskBound {
    match found {
        None => declined(
            task,
            format!("{what}: not bounded (no such handler in the image)"),
        ),
        Some((f, s)) => {
            let mut row = match (&f.declined, &f.per_activation, &f.per_frame) {
                (Some(reason), ..) => declined(task, format!("{what}: {reason}")),
                // Charged by its parts: one frame's job (the fixed part, a pass and a completion) is the
                // budget, the parts and the whole job's bound kept beside it.
                (None, _, Some(parts)) => match &parts.declined {
                    Some(reason) => declined(
                        task,
                        format!("{what}: its parts per frame ({}) are declined: {reason}", parts.at),
                    ),
                    None => TaskBound {
                        job: Some(bounds::JobBound {
                            cycles: f.cycles,
                            us: us(f.cycles, clock),
                            instructions: f.instructions,
                            per_activation: format!(
                                "{} by its parts per job, frame and abort: {}",
                                parts.at, parts.reason
                            ),
                            parts: Some(bounds::FrameParts {
                                fixed_cycles: parts.fixed.cycles,
                                fixed_us: us(parts.fixed.cycles, clock),
                                per_frame_cycles: parts.per_frame.cycles,
                                per_frame_us: us(parts.per_frame.cycles, clock),
                                abort_cycles: parts.abort.cycles,
                                abort_us: us(parts.abort.cycles, clock),
                            }),
                        }),
                        ..bounded(
                            task,
                            parts.fixed.cycles + parts.per_frame.cycles,
                            parts.fixed.instructions + parts.per_frame.instructions,
                            f.bus_wait_us,
                            clock,
                        )
                    },
                },
                (None, None, None) => bounded(task, f.cycles, f.instructions, f.bus_wait_us, clock),
                // Charged per activation: the charge is the budget, the job's bound kept beside it.
                (None, Some(charge), None) => match &charge.declined {
                    Some(reason) => declined(
                        task,
                        format!(
                            "{what}: its charge per activation ({} at {} passes) is declined: {reason}",
                            charge.at, charge.passes
                        ),
                    ),
                    None => TaskBound {
                        job: Some(bounds::JobBound {
                            cycles: f.cycles,
                            us: us(f.cycles, clock),
                            instructions: f.instructions,
                            per_activation: format!(
                                "{} at {} passes: {}",
                                charge.at, charge.passes, charge.reason
                            ),
                            parts: None,
                        }),
                        ..bounded(
                            task,
                            charge.cycles,
                            charge.instructions,
                            charge.bus_wait_us,
                            clock,
                        )
                    },
                },
            };
            row.sections = Some(sections_row(s, clock));
            row
        }
    }
}

/// A task's critical sections as the file has them.
fn sections_row(s: &machine_code::TaskSections, clock: u64) -> CeilingSections {
    CeilingSections {
        incomplete: s.incomplete.clone(),
        ceilings: s
            .ceilings
            .iter()
            .map(|c| {
                let bounded = c.declined.is_none();
                CeilingSection {
                    ceiling: c.ceiling.priority().map(u32::from),
                    at: format!("{} at {}", c.function, c.at),
                    cycles: bounded.then_some(c.cycles),
                    us: bounded.then(|| us(c.cycles, clock)),
                    bus_wait_us: c.bus_wait_us,
                    declined: c.declined.clone(),
                }
            })
            .collect(),
    }
}

/// The sections of one job of whichever of `rows` runs it: per ceiling the longest, declined where any of them is;
/// `None` when any has none.
fn merged_sections(rows: &[TaskBound]) -> Option<CeilingSections> {
    let mut incomplete = None;
    let mut by_ceiling: BTreeMap<Option<u32>, CeilingSection> = BTreeMap::new();
    for r in rows {
        let s = r.sections.as_ref()?;
        if incomplete.is_none() {
            incomplete.clone_from(&s.incomplete);
        }
        for c in &s.ceilings {
            let keep = match by_ceiling.get(&c.ceiling) {
                None => true,
                Some(old) if old.declined.is_some() => false,
                Some(_) if c.declined.is_some() => true,
                Some(old) => c.length_us() > old.length_us(),
            };
            if keep {
                by_ceiling.insert(c.ceiling, c.clone());
            }
        }
    }
    // Interrupts off first, then by priority down.
    let mut ceilings: Vec<CeilingSection> = by_ceiling.into_values().collect();
    ceilings.sort_by_key(|c| std::cmp::Reverse(c.ceiling.unwrap_or(u32::MAX)));
    Some(CeilingSections {
        incomplete,
        ceilings,
    })
}

/// Why a thread-mode task's row (the admission step, priority 0) is not its bound, with what the machine code
/// bounds of it: the functions of one step the bounds file names under the task's name (`step`: a decision or a
/// refresh step, the worst of them), within the check's iteration caps. The rest of the job — the handler's
/// update, the verdict frames and their trace events, the pacing — runs in the thread-mode executor, which never
/// returns, so no function's bound is the job's, and a part of a job is no budget for it.
fn thread_mode_step(
    task: &str,
    step: &machine_code::TaskBound,
    stated: Option<&(f64, f64)>,
    clock: u64,
) -> String {
    // Each function by its type and name (`Admission<_,_>::on_command`), not its whole path.
    let function = step
        .function
        .as_deref()
        .unwrap_or("?")
        .split(" or ")
        .map(|f| {
            let parts: Vec<&str> = f.split("::").collect();
            parts[parts.len().saturating_sub(2)..].join("::")
        })
        .collect::<Vec<_>>()
        .join(" or ");
    let head = format!(
        "{task}: thread mode (polled by the idle executor, no handler whose bound is a job)"
    );
    let Some(reason) = &step.declined else {
        let bound = us(step.cycles, clock);
        let against = stated.map_or(String::new(), |&(budget, deadline)| {
            format!(
                "; that check alone is {:.0} times the stated {budget} µs{}",
                bound / budget,
                if bound > deadline {
                    format!(" and above the task's {deadline} µs deadline")
                } else {
                    String::new()
                }
            )
        });
        // The admission step's job around its check; any other thread-mode task's poll around its functions.
        let rest = if task == "admit_requests" {
            "the handler's update, the verdict frames and their trace events, the pacing"
        } else {
            "its poll around the named functions"
        };
        return format!(
            "{head}; its step's check ({function}) is bounded from the machine code within its iteration caps at \
             {} cycles ({bound:.0} µs at {} MHz, {} instructions), the rest of its job ({rest}) is not: a part of a \
             job is no budget for it{against}",
            step.cycles,
            clock / 1_000_000,
            step.instructions
        );
    };
    format!("{head}; its step's check ({function}) is declined: {reason}")
}

/// A topic row's critical sections: those one release of `group` may hold. Where the machine code
/// gives the task's sections in the job that group's topic bound takes (`release`: the other groups'
/// functions' calls left out with the blocks only they lead to, the group's own waits;
/// [`crate::machine::topic_sections`]) and their list is complete, those: a release of the group runs
/// none of the blocks left out, so a lock the sampler takes around another family's sample is none of
/// its sections, wherever it is raised. Otherwise from the publisher task's
/// (`whole`, any job of the task) and each topic group's functions' (`groups`, bounded with each group's
/// own waits: [`crate::machine::group_sections`]). Per ceiling of the task, where every section of the task
/// at that ceiling is accounted for by the groups' functions — each function that has one at that ceiling
/// has exactly one, raised in the function itself (a lock the sampler takes inside the group's not-inlined
/// sample function), and the task has no more sections there than those functions (so none of the code
/// around the samples raises to it) — the row has only its own group's there (none, for a group that does
/// not raise to it); at any other ceiling the task's longest stands, whoever's it is. `None` (the task's
/// sections stand whole) where an enumeration is incomplete or the group has no sections found.
fn group_row_sections(
    whole: &machine_code::TaskSections,
    group: &str,
    groups: &crate::machine::GroupSections,
    release: Option<&machine_code::TaskSections>,
    clock: u64,
) -> Option<CeilingSections> {
    if let Some(release) = release.filter(|r| r.incomplete.is_none()) {
        let mut row = sections_row(release, clock);
        row.ceilings
            .sort_by_key(|c| std::cmp::Reverse(c.ceiling.unwrap_or(u32::MAX)));
        return Some(row);
    }
    let own = groups.get(group)?;
    if whole.incomplete.is_some() {
        return None;
    }
    // Every present group's functions, each once.
    let mut functions: BTreeMap<&str, &machine_code::TaskSections> = BTreeMap::new();
    for (f, s) in groups.values().flatten() {
        if s.incomplete.is_some() {
            return None;
        }
        functions.insert(f.as_str(), s);
    }
    let at = |s: &machine_code::TaskSections, c: machine_code::Ceiling| {
        s.ceilings.iter().find(|x| x.ceiling == c).cloned()
    };
    let mut ceilings = Vec::new();
    for c in &whole.ceilings {
        let in_functions: Vec<(&str, machine_code::CeilingBound)> = functions
            .iter()
            .filter_map(|(f, s)| at(s, c.ceiling).map(|x| (*f, x)))
            .collect();
        let separable = in_functions
            .iter()
            .all(|(f, x)| x.sections == 1 && x.function == *f)
            && in_functions.len() == c.sections;
        if !separable {
            ceilings.push(c.clone());
            continue;
        }
        // The group's own at this ceiling: declined where one is, else the longest.
        let key = |x: &machine_code::CeilingBound| (x.declined.is_some(), x.us.to_bits());
        if let Some(best) = own
            .iter()
            .filter_map(|(_, s)| at(s, c.ceiling))
            .max_by_key(key)
        {
            ceilings.push(best);
        }
    }
    let mut row = sections_row(
        &machine_code::TaskSections {
            task: whole.task.clone(),
            ceilings,
            incomplete: None,
        },
        clock,
    );
    row.ceilings
        .sort_by_key(|c| std::cmp::Reverse(c.ceiling.unwrap_or(u32::MAX)));
    Some(row)
}

/// The rows of one image: `built` is the app as built (its `cfg`s applied), `app` as written (for RTIC's
/// dispatcher assignment), `found` the machine code's bounds by task ([`crate::machine::tasks_of`]). The topic
/// rows carry their publisher tasks' whole sections ([`rows_with_groups`] with no topic group's).
#[cfg(test)]
pub fn rows(
    built: &RticApp,
    app: &RticApp,
    budgets: &Budgets,
    found: &[machine_code::TaskBound],
    sections: &[machine_code::TaskSections],
    chip: Chip,
) -> Vec<TaskBound> {
    rows_with_groups(
        built,
        app,
        budgets,
        found,
        sections,
        &crate::machine::GroupSections::new(),
        &crate::machine::TopicSections::new(),
        chip,
    )
}

/// `rows`, each topic row with the critical sections of one release of its group where
/// `topic_sections` or `groups` tell them apart ([`group_row_sections`]).
#[allow(clippy::too_many_arguments)]
pub fn rows_with_groups(
    built: &RticApp,
    app: &RticApp,
    budgets: &Budgets,
    found: &[machine_code::TaskBound],
    sections: &[machine_code::TaskSections],
    groups: &crate::machine::GroupSections,
    topic_sections: &crate::machine::TopicSections,
    chip: Chip,
) -> Vec<TaskBound> {
    let clock = chip.clock_hz();
    let by_name: BTreeMap<&str, (&machine_code::TaskBound, &machine_code::TaskSections)> = found
        .iter()
        .zip(sections)
        .map(|(t, s)| (t.task.as_str(), (t, s)))
        .collect();
    let dispatchers = dispatcher_of(app);
    // The machine-code row a task's job is bounded by, and what to call it.
    type Found<'f> = (&'f machine_code::TaskBound, &'f machine_code::TaskSections);
    let source = |name: &str| -> Option<(String, Option<Found<'_>>)> {
        let task = built.tasks.iter().find(|t| t.name == name)?;
        match &task.kind {
            RticTaskKind::Hardware { binds } => Some((
                format!("{name} (handler {binds})"),
                by_name.get(name).copied(),
            )),
            RticTaskKind::Software => {
                let d = dispatchers.get(&task.priority)?;
                // Its own part of the dispatcher where the machine code has it, else the whole
                // dispatcher's poll.
                match by_name.get(name) {
                    Some(&own) => Some((
                        format!(
                            "{name} (its part of {d}'s poll, priority {})",
                            task.priority
                        ),
                        Some(own),
                    )),
                    None => {
                        let key = format!("dispatcher {d}");
                        Some((
                            format!("{name} (polled by {d}, priority {})", task.priority),
                            by_name.get(key.as_str()).copied(),
                        ))
                    }
                }
            }
            RticTaskKind::Idle => None,
        }
    };
    // Whether the task's jobs are polls (an async task its dispatcher polls), for a task that suspends.
    let polls_found = |name: &str| -> Result<(), String> {
        let Some(task) = built.tasks.iter().find(|t| t.name == name) else {
            return Err(format!("{name} is no task of the image as built"));
        };
        match &task.kind {
            RticTaskKind::Software if dispatchers.contains_key(&task.priority) => Ok(()),
            RticTaskKind::Software => Err(format!("{name} has no dispatcher at its priority")),
            RticTaskKind::Hardware { binds } => Err(format!(
                "{name} is the handler of {binds}, whose job runs to its end: no await suspends it"
            )),
            RticTaskKind::Idle => Err(format!(
                "{name} runs in thread mode, polled by no dispatcher"
            )),
        }
    };
    let mut out = Vec::new();
    for task in &budgets.tasks {
        let suspends = budgets.scripts.get(&format!("tasks.{task}"));
        let row = match (source(task), by_name.get(task.as_str())) {
            (Some((what, f)), _) => from_found(task, &what, f, clock),
            // Its budget stays stated, but the sections of the functions named for it are sections of its job:
            // blocking terms beside the stated ones (not in place of them: those functions may be only part
            // of the job).
            (None, Some(step)) => TaskBound {
                sections: Some({
                    let mut s = sections_row(step.1, clock);
                    let part = format!(
                        "{task}: thread mode, the sections of the functions the bounds file names for it \
                         ({}), which may be only part of its job",
                        step.0.function.as_deref().unwrap_or("?")
                    );
                    s.incomplete = Some(match s.incomplete {
                        Some(why) => format!("{part}; {why}"),
                        None => part,
                    });
                    s
                }),
                ..declined(
                    task,
                    thread_mode_step(task, step.0, budgets.stated.get(task.as_str()), clock),
                )
            },
            (None, None) => declined(
                task,
                format!("{task}: not an interrupt-driven task of the image as built (thread mode, or not in the app)"),
            ),
        };
        out.push(match suspends {
            Some(settles) => as_release(
                row,
                settles,
                &format!("tasks.{task}"),
                polls_found(task),
                clock,
            ),
            None => row,
        });
    }
    // One sample of a topic: a job of whichever publisher task publishes it.
    let publishers: Vec<TaskBound> = budgets
        .publishers
        .iter()
        .map(|p| match source(p) {
            Some((what, f)) => from_found(p, &what, f, clock),
            None => declined(
                p,
                format!("publisher {p}: not a task of the image as built"),
            ),
        })
        .collect();
    // Where the bounds file states the release loop per topic (`topics`), each publisher task's bound of one
    // release of the topic's group (machine_code::TopicBound) in place of its whole job's.
    let per_topic: Vec<Option<Found<'_>>> = budgets
        .publishers
        .iter()
        .map(|p| source(p).and_then(|(_, f)| f))
        .collect();
    for topic in &budgets.topics {
        let row = bounds::publisher_row(topic);
        // A topic whose sample suspends on scripts: a release is several polls, and a poll that ends one release
        // may take the next and start its sample, so each poll is bounded by its task's whole job (every group's
        // functions), not one group's release.
        if let Some(settles) = budgets.scripts.get(&format!("topics.{topic}")) {
            let poll = match (
                publishers.iter().find_map(|p| p.declined.clone()),
                publishers.is_empty(),
            ) {
                (_, true) => declined(&row, "the timing file names no publisher task".into()),
                (Some(reason), _) => declined(&row, reason),
                (None, false) => {
                    let max =
                        |f: fn(&TaskBound) -> u64| publishers.iter().map(f).max().unwrap_or(0);
                    bounded(
                        &row,
                        max(|p| p.cycles.unwrap_or(0)),
                        max(|p| p.instructions.unwrap_or(0)),
                        publishers.iter().map(|p| p.bus_wait_us).fold(0.0, f64::max),
                        clock,
                    )
                }
            };
            let found = budgets
                .publishers
                .iter()
                .map(|p| polls_found(p))
                .find(Result::is_err)
                .unwrap_or(Ok(()));
            out.push(as_release(
                TaskBound {
                    sections: merged_sections(&publishers),
                    ..poll
                },
                settles,
                &format!("topics.{topic}"),
                found,
                clock,
            ));
            continue;
        }
        let rows: Vec<TaskBound> = publishers
            .iter()
            .zip(&per_topic)
            .map(|(whole, found)| {
                let group = found.and_then(|(f, _)| {
                    f.topics
                        .iter()
                        .find(|g| g.topics.iter().any(|t| t == topic))
                });
                match (group, &whole.declined) {
                    (Some(g), None) => match &g.declined {
                        Some(reason) => declined(
                            &whole.task,
                            format!(
                                "{}: one release of topic group {}: {reason}",
                                whole.task, g.group
                            ),
                        ),
                        None => {
                            bounded(&whole.task, g.cycles, g.instructions, g.bus_wait_us, clock)
                        }
                    },
                    _ => whole.clone(),
                }
            })
            .collect();
        let refused = rows.iter().find_map(|p| p.declined.clone());
        // Each publisher's sections of one release of the topic's group where they tell apart, else its
        // whole task's; then the longest over the publishers, as for the task's.
        let with_group_sections: Vec<TaskBound> = publishers
            .iter()
            .zip(&per_topic)
            .map(|(whole, found)| {
                let own = found.and_then(|(f, s)| {
                    let g = f
                        .topics
                        .iter()
                        .find(|g| g.topics.iter().any(|t| t == topic))?;
                    let release = topic_sections
                        .get(f.task.as_str())
                        .and_then(|per_group| per_group.get(&g.group));
                    group_row_sections(s, &g.group, groups, release, clock)
                });
                TaskBound {
                    sections: own.or_else(|| whole.sections.clone()),
                    ..whole.clone()
                }
            })
            .collect();
        let row_sections = merged_sections(&with_group_sections);
        out.push(match (refused, rows.is_empty()) {
            (_, true) => declined(&row, "the timing file names no publisher task".into()),
            (Some(reason), _) => TaskBound {
                sections: row_sections,
                ..declined(&row, reason)
            },
            (None, false) => {
                let max = |f: fn(&TaskBound) -> u64| rows.iter().map(f).max().unwrap_or(0);
                let cycles = max(|p| p.cycles.unwrap_or(0));
                let instructions = max(|p| p.instructions.unwrap_or(0));
                let wait = rows.iter().map(|p| p.bus_wait_us).fold(0.0, f64::max);
                TaskBound {
                    sections: row_sections,
                    ..bounded(&row, cycles, instructions, wait, clock)
                }
            }
        });
    }
    out.push(from_found(
        "monotonic",
        "the monotonic's interrupt",
        by_name.get("monotonic").copied(),
        clock,
    ));
    // The TRM's figures assume zero-wait-state memory. The entry reads the vector from flash and fetches the
    // handler's first instruction from flash, the return refetches the interrupted code: each flash access its
    // wait states more.
    let exit = machine_code::wcet::chip::EXCEPTION_EXIT;
    let entry = chip.exception_cycles() - exit + 2 * chip.wait_states();
    out.push(bounded("exception_entry", entry, 0, 0.0, clock));
    out.push(bounded(
        "exception_exit",
        exit + chip.wait_states(),
        0,
        0.0,
        clock,
    ));
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use schedule_analysis::rtic_source::parse_app;

    /// Priorities 3 (one task only in the QEMU build), 2 (two tasks) and 1 (the publisher); a hardware task.
    const APP: &str = r#"
#[rtic::app(device = pac, dispatchers = [SPARE, LOW, MID, HIGH])]
mod app {
    #[shared] struct Shared {}
    #[local] struct Local {}
    #[init] fn init(_: init::Context) -> (Shared, Local) { (Shared {}, Local {}) }
    #[task(binds = CAN_RX, priority = 4)] fn can_rx(_: can_rx::Context) {}
    #[cfg(feature = "qemu")]
    #[task(priority = 3)] async fn stimulus(_: stimulus::Context) {}
    #[task(priority = 2)] async fn handle(_: handle::Context) {}
    #[task(priority = 2)] async fn drive(_: drive::Context) {}
    #[task(priority = 1)] async fn publish(_: publish::Context) {}
}
"#;

    fn found(task: &str, cycles: u64, declined: Option<&str>) -> machine_code::TaskBound {
        machine_code::TaskBound {
            task: task.into(),
            function: None,
            cycles,
            us: 0.0,
            instructions: cycles / 2,
            bus_wait_us: 0.5,
            loops: Vec::new(),
            preemption_retry_cycles: 0,
            declined: declined.map(str::to_string),
            per_activation: None,
            per_frame: None,
            topics: Vec::new(),
        }
    }

    /// No sections for each of `machine`, but `with` (task, ceiling, cycles, declined).
    fn sections_of(
        machine: &[machine_code::TaskBound],
        with: &[(&str, machine_code::Ceiling, u64, Option<&str>)],
    ) -> Vec<machine_code::TaskSections> {
        machine
            .iter()
            .map(|t| machine_code::TaskSections {
                task: t.task.clone(),
                ceilings: with
                    .iter()
                    .filter(|(task, ..)| *task == t.task)
                    .map(
                        |&(_, ceiling, cycles, declined)| machine_code::CeilingBound {
                            ceiling,
                            cycles,
                            us: 0.0,
                            instructions: 1,
                            bus_wait_us: 0.0,
                            sections: 1,
                            function: "f".into(),
                            at: "src/f.rs:1".into(),
                            declined: declined.map(str::to_string),
                        },
                    )
                    .collect(),
                incomplete: None,
            })
            .collect()
    }

    #[test]
    fn a_topic_row_takes_its_group_bound_of_one_release_where_the_bounds_file_groups_it() {
        let app = parse_app(APP).unwrap();
        let built = app.with_features(&[]);
        let chip = Chip::parse("stm32f103", None).unwrap();
        let budgets = Budgets {
            tasks: Vec::new(),
            topics: vec!["gyro".into(), "odo".into(), "temp".into()],
            publishers: ["publish".to_string()].into(),
            stated: BTreeMap::new(),
            scripts: BTreeMap::new(),
        };
        let group = |name: &str, topic: &str, cycles: u64, declined: Option<&str>| {
            machine_code::TopicBound {
                group: name.into(),
                topics: vec![topic.into()],
                cycles,
                us: 0.0,
                instructions: cycles / 3,
                bus_wait_us: 25.2,
                loops: Vec::new(),
                declined: declined.map(str::to_string),
            }
        };
        let mut publish = found("dispatcher LOW", 7200, None);
        publish.topics = vec![
            group("imu", "gyro", 720, None),
            group("drive", "odo", 0, Some("the loop in F has no bound")),
        ];
        let machine = [publish];
        let sections = sections_of(&machine, &[]);
        let rows = rows(&built, &app, &budgets, &machine, &sections, chip);
        let row = |n: &str| rows.iter().find(|r| r.task == n).unwrap();
        // Its group's one release: 720 cycles (10 µs at 72 MHz), its instructions and bus waits.
        let gyro = row("publisher[gyro]");
        assert_eq!(
            (gyro.cycles, gyro.us, gyro.instructions, gyro.bus_wait_us),
            (Some(720), Some(10.0), Some(240), 25.2)
        );
        // A group whose bound is declined declines the topic's row, naming the group.
        assert!(row("publisher[odo]")
            .declined
            .as_deref()
            .is_some_and(|r| r.contains("one release of topic group drive")));
        // A topic in no group: the task's whole job.
        assert_eq!(row("publisher[temp]").cycles, Some(7200));
        assert_eq!(row("publisher[temp]").bus_wait_us, 0.5);
    }

    #[test]
    fn a_suspending_release_is_its_polls_times_its_tasks_whole_poll_and_a_task_without_polls_is_declined(
    ) {
        let app = parse_app(APP).unwrap();
        let built = app.with_features(&[]);
        let chip = Chip::parse("stm32f103", None).unwrap();
        // gyro: three scripts, the second after a settle; odo: none (its group's bound, as before); the task
        // `handle` (async, priority 2): one script; `can_rx` (the CAN_RX handler): one script.
        let budgets = Budgets {
            tasks: vec!["handle".into(), "can_rx".into(), "drive".into()],
            topics: vec!["gyro".into(), "odo".into()],
            publishers: ["publish".to_string()].into(),
            stated: BTreeMap::new(),
            scripts: [
                ("topics.gyro".to_string(), vec![false, true, false]),
                ("tasks.handle".to_string(), vec![false]),
                ("tasks.can_rx".to_string(), vec![false]),
            ]
            .into(),
        };
        let group = |name: &str, topic: &str, cycles: u64| machine_code::TopicBound {
            group: name.into(),
            topics: vec![topic.into()],
            cycles,
            us: 0.0,
            instructions: cycles / 3,
            bus_wait_us: 0.0,
            loops: Vec::new(),
            declined: None,
        };
        let mut publish = found("dispatcher LOW", 720, None);
        publish.topics = vec![group("imu", "gyro", 360), group("drive", "odo", 144)];
        let machine = [
            publish,
            found("handle", 1_440, None),
            found("can_rx", 288, None),
            found("drive", 72, None),
        ];
        let sections = sections_of(&machine, &[]);
        let rows = rows(&built, &app, &budgets, &machine, &sections, chip);
        let row = |n: &str| rows.iter().find(|r| r.task == n).unwrap();
        // gyro: 1 + (3 scripts + 1 settle) + 3 + 1 = 9 polls, each at the publisher task's whole poll (720
        // cycles, 10 µs, 360 instructions, 0.5 µs of waits; not its group's 360: a poll may end one release and
        // take the next): 6 480 cycles, 90 µs, 3 240 instructions, 4.5 µs of waits.
        let gyro = row("publisher[gyro]");
        assert_eq!(
            (gyro.cycles, gyro.us, gyro.instructions, gyro.bus_wait_us),
            (Some(6_480), Some(90.0), Some(3_240), 4.5)
        );
        let release = gyro.release.as_ref().unwrap();
        assert_eq!(
            (
                release.polls,
                release.poll_cycles,
                release.poll_us,
                release.poll_instructions
            ),
            (9, 720, 10.0, 360)
        );
        assert!(release
            .reason
            .contains("3 scripts stated (topics.gyro), 1 with a settle"));
        // odo states no script: its group's one release, no release.
        assert_eq!(
            (
                row("publisher[odo]").cycles,
                row("publisher[odo]").release.is_none()
            ),
            (Some(144), true)
        );
        // handle: one script, 1 + 1 + 1 + 1 = 4 polls of 1 440 cycles.
        let handle = row("handle");
        assert_eq!(
            (handle.cycles, handle.instructions),
            (Some(5_760), Some(2_880))
        );
        assert_eq!(handle.release.as_ref().map(|r| r.polls), Some(4));
        // can_rx: a handler runs to its end, so its polls cannot be found: declined, naming why.
        let can_rx = row("can_rx");
        assert_eq!((can_rx.cycles, can_rx.release.is_none()), (None, true));
        assert!(can_rx.declined.as_deref().is_some_and(|r| r.contains(
            "1 script stated (tasks.can_rx), 0 with a settle before it, but its polls cannot be found: can_rx is \
             the handler of CAN_RX"
        )));
        // drive states none: as before.
        assert_eq!(
            (row("drive").cycles, row("drive").release.is_none()),
            (Some(72), true)
        );
        // The file with these rows is valid, and a release whose figures are not its polls' is refused.
        let file = |tasks: Vec<TaskBound>| BoundsFile {
            generated: format!("{} from a test", bounds::GENERATED_PREFIX),
            board: "b".into(),
            revision: None,
            chip: bounds::Chip::Stm32f103,
            clock_hz: 72_000_000,
            wait_states: 2,
            image: bounds::ImageIdentity {
                code_sha256: "0".repeat(64),
                code_bytes: 1,
            },
            tasks,
            idle_critical_sections: BTreeMap::new(),
        };
        let written = file(rows.clone()).to_json();
        assert!(BoundsFile::from_json("b.wcet.json", &written).is_ok());
        let mut wrong = rows.clone();
        if let Some(r) = wrong.iter_mut().find(|r| r.task == "publisher[gyro]") {
            r.release.as_mut().unwrap().polls = 8;
        }
        let refused = BoundsFile::from_json("b.wcet.json", &file(wrong).to_json()).unwrap_err();
        assert!(refused.to_string().contains("release.polls"), "{refused}");
    }

    /// A publisher that is no async task cannot have its polls found: its suspending topic is declined.
    #[test]
    fn a_jobs_scripts_are_read_as_the_analysis_reads_them() {
        let script = |settle: Option<f64>| schedule_analysis::sensor_bus::ScriptModel {
            settle_us: settle,
            settle_source: settle.map(|_| "bq27500 bus-free time".into()),
            ..serde_json::from_value(serde_json::json!({
                "bus": "i2c1", "bytes": 5, "source": "Script::wire",
                "stretch_us": 0.0, "stretch_source": "none"
            }))
            .unwrap()
        };
        let two = [script(None), script(Some(66.0))];
        assert_eq!(
            scripts_of(None, Some(&two), "topics.power-status").unwrap(),
            [false, true]
        );
        assert_eq!(
            scripts_of(Some(&two[1]), None, "tasks.power_monitor").unwrap(),
            [true]
        );
        assert!(scripts_of(None, None, "tasks.watchdog").unwrap().is_empty());
        // Both, or an empty list: refused as the analysis refuses them (a raw reading took `script`).
        let both = scripts_of(Some(&two[0]), Some(&two), "topics.floor").unwrap_err();
        assert!(both.to_string().starts_with("topics.floor"), "{both}");
        assert!(scripts_of(None, Some(&[]), "topics.floor").is_err());
    }

    #[test]
    fn a_suspending_topic_whose_publisher_is_a_handler_is_declined() {
        let app = parse_app(APP).unwrap();
        let built = app.with_features(&[]);
        let chip = Chip::parse("stm32f103", None).unwrap();
        let budgets = Budgets {
            tasks: Vec::new(),
            topics: vec!["gyro".into()],
            publishers: ["can_rx".to_string()].into(),
            stated: BTreeMap::new(),
            scripts: [("topics.gyro".to_string(), vec![false, false])].into(),
        };
        let machine = [found("can_rx", 288, None)];
        let sections = sections_of(&machine, &[]);
        let rows = rows(&built, &app, &budgets, &machine, &sections, chip);
        let gyro = rows.iter().find(|r| r.task == "publisher[gyro]").unwrap();
        assert_eq!(gyro.cycles, None);
        assert!(gyro.declined.as_deref().is_some_and(|r| r.contains(
            "2 scripts stated (topics.gyro), 0 with a settle before it, but its polls cannot be found: can_rx is the \
             handler of CAN_RX"
        )), "{:?}", gyro.declined);
    }

    /// A ceiling's longest section as the machine code reports it: `sections` raises at `ceiling`, the
    /// longest `us` long, raised in `function`.
    fn ceiling(
        ceiling: machine_code::Ceiling,
        us: f64,
        sections: usize,
        function: &str,
    ) -> machine_code::CeilingBound {
        machine_code::CeilingBound {
            ceiling,
            cycles: (us * 72.0) as u64,
            us,
            instructions: 1,
            bus_wait_us: 0.0,
            sections,
            function: function.into(),
            at: format!("{function} at src/f.rs:1"),
            declined: None,
        }
    }

    #[test]
    fn a_topic_row_carries_its_own_groups_sections_where_the_groups_account_for_a_ceiling() {
        let app = parse_app(APP).unwrap();
        let built = app.with_features(&[]);
        let chip = Chip::parse("stm32f103", None).unwrap();
        let budgets = Budgets {
            tasks: Vec::new(),
            topics: vec!["floor".into(), "odo".into()],
            publishers: ["publish".to_string()].into(),
            stated: BTreeMap::new(),
            scripts: BTreeMap::new(),
        };
        let topic = |name: &str, t: &str| machine_code::TopicBound {
            group: name.into(),
            topics: vec![t.into()],
            cycles: 720,
            us: 10.0,
            instructions: 240,
            bus_wait_us: 0.0,
            loops: Vec::new(),
            declined: None,
        };
        let mut publish = found("dispatcher LOW", 7200, None);
        publish.topics = vec![topic("floor", "floor"), topic("drive", "odo")];
        let (p4, p5) = (
            machine_code::Ceiling::Basepri {
                hardware: 0xc0,
                priority: 4,
            },
            machine_code::Ceiling::Basepri {
                hardware: 0xb0,
                priority: 5,
            },
        );
        // The task: at priority 4 two sections (the floor's lock, 9 000 µs with the file's waits, and the
        // drive's), at priority 5 three (the drive's two and the code around the samples, 50 µs).
        let whole = machine_code::TaskSections {
            task: "dispatcher LOW".into(),
            ceilings: vec![
                ceiling(p5, 50.0, 3, "serve"),
                ceiling(p4, 9_000.0, 2, "sample_floor"),
            ],
            incomplete: None,
        };
        let function = |f: &str, ceilings: Vec<machine_code::CeilingBound>| {
            (
                f.to_string(),
                machine_code::TaskSections {
                    task: f.into(),
                    ceilings,
                    incomplete: None,
                },
            )
        };
        let mut groups = crate::machine::GroupSections::new();
        // The floor's lock with the group's own waits: 1 200 µs, raised in its sample function.
        groups.insert(
            "floor".into(),
            vec![function(
                "sample_floor",
                vec![ceiling(p4, 1_200.0, 1, "sample_floor")],
            )],
        );
        groups.insert(
            "drive".into(),
            vec![function(
                "sample_drive",
                vec![
                    ceiling(p5, 20.0, 2, "sample_drive"),
                    ceiling(p4, 30.0, 1, "sample_drive"),
                ],
            )],
        );
        let machine = [publish];
        let rows = rows_with_groups(
            &built,
            &app,
            &budgets,
            &machine,
            std::slice::from_ref(&whole),
            &groups,
            &crate::machine::TopicSections::new(),
            chip,
        );
        let row = |n: &str| rows.iter().find(|r| r.task == n).unwrap();
        let at = |n: &str, p: u32| {
            row(n)
                .sections
                .as_ref()
                .unwrap()
                .ceilings
                .iter()
                .find(|c| c.ceiling == Some(p))
                .map(|c| (c.us, c.at.clone()))
        };
        // Priority 4: both sections are the groups' own, one each in their sample functions: the floor's
        // row has its own (with its waits), the drive's its own, not the floor's 9 000 µs.
        assert_eq!(
            at("publisher[floor]", 4),
            Some((
                Some(1_200.0),
                "sample_floor at sample_floor at src/f.rs:1".into()
            ))
        );
        assert_eq!(at("publisher[odo]", 4).and_then(|c| c.0), Some(30.0));
        // Priority 5: the drive's function raises twice there, so the groups do not account for the
        // ceiling: the task's longest stands on every row.
        assert_eq!(at("publisher[floor]", 5).and_then(|c| c.0), Some(50.0));
        assert_eq!(at("publisher[odo]", 5).and_then(|c| c.0), Some(50.0));
        // A third raise at priority 4 (the code around the samples): no longer accounted for, the task's
        // longest stands on every row.
        let mut more = whole.clone();
        more.ceilings[1].sections = 3;
        let rows = rows_with_groups(
            &built,
            &app,
            &budgets,
            &machine,
            std::slice::from_ref(&more),
            &groups,
            &crate::machine::TopicSections::new(),
            chip,
        );
        let odo = rows.iter().find(|r| r.task == "publisher[odo]").unwrap();
        let p4_us = odo
            .sections
            .as_ref()
            .unwrap()
            .ceilings
            .iter()
            .find(|c| c.ceiling == Some(4));
        assert_eq!(p4_us.and_then(|c| c.us), Some(9_000.0));
        // With the task's sections in the job of the drive's release (the floor's lock left out with
        // the floor's sample: priority 4 the drive's lock alone, priority 5 the code around the
        // samples, no interrupts-off section), the drive's row has those, whoever raises them; the
        // floor's row, without its own, keeps the groups' accounting.
        let mut release = crate::machine::TopicSections::new();
        let drive = machine_code::TaskSections {
            task: "dispatcher LOW".into(),
            ceilings: vec![ceiling(p5, 50.0, 3, "serve"), ceiling(p4, 30.0, 1, "serve")],
            incomplete: None,
        };
        release
            .entry("dispatcher LOW".into())
            .or_default()
            .insert("drive".into(), drive.clone());
        let rows = rows_with_groups(
            &built,
            &app,
            &budgets,
            &machine,
            std::slice::from_ref(&more),
            &groups,
            &release,
            chip,
        );
        let at = |n: &str| {
            rows.iter()
                .find(|r| r.task == n)
                .unwrap()
                .sections
                .as_ref()
                .unwrap()
                .ceilings
                .iter()
                .map(|c| (c.ceiling, c.us))
                .collect::<Vec<_>>()
        };
        assert_eq!(
            at("publisher[odo]"),
            [(Some(5), Some(50.0)), (Some(4), Some(30.0))]
        );
        assert_eq!(
            at("publisher[floor]"),
            [(Some(5), Some(50.0)), (Some(4), Some(9_000.0))]
        );
        // A release list that may miss sections is not used: the task's longest stands.
        let incomplete = machine_code::TaskSections {
            incomplete: Some("a call through a register".into()),
            ..drive
        };
        release
            .entry("dispatcher LOW".into())
            .or_default()
            .insert("drive".into(), incomplete);
        let rows = rows_with_groups(
            &built,
            &app,
            &budgets,
            &machine,
            std::slice::from_ref(&more),
            &groups,
            &release,
            chip,
        );
        let odo = rows.iter().find(|r| r.task == "publisher[odo]").unwrap();
        let p4_us = odo
            .sections
            .as_ref()
            .unwrap()
            .ceilings
            .iter()
            .find(|c| c.ceiling == Some(4));
        assert_eq!(p4_us.and_then(|c| c.us), Some(9_000.0));
        // Without the groups' sections, the task's whole sections, as before.
        let whole_rows = super::rows(
            &built,
            &app,
            &budgets,
            &machine,
            std::slice::from_ref(&whole),
            chip,
        );
        let odo = whole_rows
            .iter()
            .find(|r| r.task == "publisher[odo]")
            .unwrap();
        let p4_us = odo
            .sections
            .as_ref()
            .unwrap()
            .ceilings
            .iter()
            .find(|c| c.ceiling == Some(4));
        assert_eq!(p4_us.and_then(|c| c.us), Some(9_000.0));
    }

    #[test]
    fn rtic_assigns_the_last_dispatchers_to_the_highest_priorities_cfg_or_not() {
        let app = parse_app(APP).unwrap();
        let d = dispatcher_of(&app);
        assert_eq!(d[&3], "HIGH");
        assert_eq!(d[&2], "MID");
        assert_eq!(d[&1], "LOW");
        assert_eq!(d.len(), 3);
    }

    #[test]
    fn tasks_take_their_handlers_or_dispatchers_bound_and_topics_the_publishers() {
        let app = parse_app(APP).unwrap();
        let built = app.with_features(&[]);
        let chip = Chip::parse("stm32f103", None).unwrap();
        let budgets = Budgets {
            tasks: vec![
                "can_rx".into(),
                "handle".into(),
                "drive".into(),
                "admit".into(),
            ],
            topics: vec!["gyro".into()],
            publishers: ["publish".to_string()].into(),
            stated: BTreeMap::new(),
            scripts: BTreeMap::new(),
        };
        let machine = [
            found("can_rx", 720, None),
            found("dispatcher MID", 144, None),
            found("dispatcher LOW", 7200, None),
            found("monotonic", 0, Some("the loop in TIM3 has no bound")),
        ];
        let p3 = machine_code::Ceiling::Basepri {
            hardware: 0xd0,
            priority: 3,
        };
        let sections = sections_of(
            &machine,
            &[
                ("dispatcher LOW", p3, 144, None),
                (
                    "dispatcher LOW",
                    machine_code::Ceiling::InterruptsOff,
                    0,
                    Some("a loop"),
                ),
                ("can_rx", machine_code::Ceiling::InterruptsOff, 72, None),
            ],
        );
        let rows = rows(&built, &app, &budgets, &machine, &sections, chip);
        let row = |n: &str| rows.iter().find(|r| r.task == n).unwrap();
        assert_eq!(row("can_rx").cycles, Some(720));
        assert_eq!(row("can_rx").us, Some(10.0));
        assert_eq!(row("can_rx").bus_wait_us, 0.5);
        // Both priority-2 tasks: the one dispatcher's bound.
        assert_eq!(row("handle").cycles, Some(144));
        assert_eq!(row("drive").instructions, Some(72));
        assert_eq!(row("publisher[gyro]").cycles, Some(7200));
        // Sections ride along with their rows: a topic's are its publisher's, interrupts off first.
        let gyro = row("publisher[gyro]").sections.clone().unwrap();
        assert_eq!(gyro.incomplete, None);
        let ceilings: Vec<(Option<u32>, Option<u64>, bool)> = gyro
            .ceilings
            .iter()
            .map(|c| (c.ceiling, c.cycles, c.declined.is_some()))
            .collect();
        assert_eq!(ceilings, [(None, None, true), (Some(3), Some(144), false)]);
        assert_eq!(gyro.ceilings[1].us, Some(2.0));
        let rx = row("can_rx").sections.clone().unwrap();
        assert_eq!(rx.ceilings[0].us, Some(1.0));
        assert!(row("handle").sections.as_ref().unwrap().ceilings.is_empty());
        // A task with no code of its own in the image has none: its stated sections stand.
        assert_eq!(row("admit").sections, None);
        assert!(row("admit")
            .declined
            .as_deref()
            .unwrap()
            .contains("not an interrupt-driven task"));
        assert!(row("monotonic")
            .declined
            .as_deref()
            .unwrap()
            .contains("TIM3"));
        // The TRM's 12 and 10 cycles, with two flash accesses' 2 wait states (the vector, the handler's first
        // instruction) and one (the interrupted code's).
        assert_eq!(row("exception_entry").cycles, Some(16));
        assert_eq!(row("exception_exit").cycles, Some(12));
        // What the writer writes, the loader reads.
        let file = BoundsFile {
            generated: bounds::GENERATED_PREFIX.into(),
            board: "b".into(),
            revision: None,
            chip: bounds::Chip::Stm32f103,
            clock_hz: chip.clock_hz(),
            wait_states: 2,
            image: schedule_analysis::bounds::ImageIdentity {
                code_sha256: "0".repeat(64),
                code_bytes: 4,
            },
            tasks: rows.clone(),
            idle_critical_sections: BTreeMap::new(),
        };
        assert_eq!(BoundsFile::from_json("t", &file.to_json()).unwrap(), file);
    }

    /// `can_rx` charged per frame: its job 2 160 cycles, a frame's charge 576 (or declined).
    fn charged(declined: Option<&str>) -> machine_code::TaskBound {
        machine_code::TaskBound {
            per_activation: Some(machine_code::ActivationBound {
                at: "RX at src/rx.rs:12".into(),
                passes: 2,
                cycles: 576,
                us: 8.0,
                instructions: 160,
                bus_wait_us: 0.0,
                reason: "a job that drains k frames costs at most k charges".into(),
                declined: declined.map(str::to_string),
            }),
            ..found("can_rx", 2160, None)
        }
    }

    #[test]
    fn a_transmit_task_charged_by_its_parts_has_one_frames_job_as_its_budget() {
        let app = parse_app(APP).unwrap();
        let built = app.with_features(&[]);
        let chip = Chip::parse("stm32f103", None).unwrap();
        let budgets = Budgets {
            tasks: vec!["can_rx".into()],
            ..Budgets::default()
        };
        let part = |cycles: u64, instructions: u64| machine_code::Part {
            cycles,
            us: cycles as f64 / 72.0,
            instructions,
        };
        let parts = |declined: Option<&str>| machine_code::TaskBound {
            per_frame: Some(machine_code::FrameBound {
                at: "TX at src/tx.rs:30".into(),
                completion: "C".into(),
                completions: 3,
                requeue: "Q".into(),
                fixed: part(2160, 800),
                pass: part(1080, 300),
                sent: part(72, 30),
                abort: part(2448, 700),
                per_frame: part(1152, 330),
                reason: "a job costs at most its parts".into(),
                declined: declined.map(str::to_string),
            }),
            ..found("can_rx", 13_968, None)
        };
        let machine = [parts(None)];
        let sections = sections_of(&machine, &[]);
        let written = super::rows(&built, &app, &budgets, &machine, &sections, chip);
        let tx = written.iter().find(|r| r.task == "can_rx").unwrap();
        // One frame's job: the fixed part and a frame's pass and completion, 2 160 + 1 152 = 3 312 cycles, 46 µs at
        // 72 MHz; the job's bound and the parts beside it.
        assert_eq!(
            (tx.cycles, tx.us, tx.instructions),
            (Some(3312), Some(46.0), Some(1130))
        );
        let job = tx.job.as_ref().expect("the job's bound kept");
        assert_eq!((job.cycles, job.us), (13_968, 194.0));
        let p = job.parts.as_ref().expect("the parts kept");
        assert_eq!(
            (
                p.fixed_cycles,
                p.fixed_us,
                p.per_frame_cycles,
                p.per_frame_us,
                p.abort_cycles,
                p.abort_us
            ),
            (2160, 30.0, 1152, 16.0, 2448, 34.0)
        );
        // Declined parts decline the row (the worst job is no frame's budget).
        let machine = [parts(Some("the requeue adds 10 cycles to the task"))];
        let written = super::rows(&built, &app, &budgets, &machine, &sections, chip);
        let tx = written.iter().find(|r| r.task == "can_rx").unwrap();
        assert_eq!(tx.cycles, None);
        assert!(tx.declined.as_deref().unwrap().contains("parts per frame"));
        // Held, the row names the frame's job and the parts; the held bound keeps them for the run on every bound.
        let machine = [parts(None)];
        let mut written = super::rows(&built, &app, &budgets, &machine, &sections, chip);
        let held = machine_code::wcet::bounds::HeldBound {
            task: "can_rx".into(),
            revisions: None,
            reason: "every set fails".into(),
        };
        hold(&mut written, &[held]);
        let tx = written.iter().find(|r| r.task == "can_rx").unwrap();
        let reason = tx.declined.as_deref().unwrap();
        assert!(
            reason.contains("3312 cycles")
                && reason.contains("2160 cycles once per job, 1152 per frame, 2448 per abort"),
            "{reason}"
        );
        let kept = tx.held.as_ref().expect("held");
        assert_eq!(kept.cycles, Some(3312));
        assert_eq!(
            kept.job
                .as_ref()
                .and_then(|j| j.parts.as_ref())
                .map(|p| p.abort_cycles),
            Some(2448)
        );
    }

    #[test]
    fn a_task_charged_per_activation_has_the_charge_as_its_budget_and_keeps_its_job() {
        let app = parse_app(APP).unwrap();
        let built = app.with_features(&[]);
        let chip = Chip::parse("stm32f103", None).unwrap();
        let budgets = Budgets {
            tasks: vec!["can_rx".into()],
            ..Budgets::default()
        };
        let machine = [charged(None)];
        let sections = sections_of(&machine, &[]);
        let written = super::rows(&built, &app, &budgets, &machine, &sections, chip);
        let rx = written.iter().find(|r| r.task == "can_rx").unwrap();
        // 576 cycles at 72 MHz: 8 µs, the budget; the job's 2 160 cycles (30 µs) beside it.
        assert_eq!(
            (rx.cycles, rx.us, rx.instructions),
            (Some(576), Some(8.0), Some(160))
        );
        assert_eq!(rx.budget_us(), Some(8.0));
        let job = rx.job.as_ref().expect("the job's bound kept");
        assert_eq!((job.cycles, job.us, job.instructions), (2160, 30.0, 1080));
        assert_eq!(
            job.per_activation,
            "RX at src/rx.rs:12 at 2 passes: a job that drains k frames costs at most k charges"
        );
        // Written and read back.
        let text = serde_json::to_string(rx).unwrap();
        assert!(text.contains(r#""job":{"cycles":2160"#), "{text}");
        // A declined charge declines the row (the job's bound is no per-frame budget).
        let machine = [charged(Some(
            "the loop RX at src/rx.rs:12 is not on the task's path",
        ))];
        let written = super::rows(&built, &app, &budgets, &machine, &sections, chip);
        let rx = written.iter().find(|r| r.task == "can_rx").unwrap();
        assert_eq!(rx.cycles, None);
        assert!(rx
            .declined
            .as_deref()
            .unwrap()
            .contains("not on the task's path"));
        // Held, the row says both figures and drops the job.
        let machine = [charged(None)];
        let mut written = super::rows(&built, &app, &budgets, &machine, &sections, chip);
        let held = machine_code::wcet::bounds::HeldBound {
            task: "can_rx".into(),
            revisions: None,
            reason: "LightRing's can_tx misses".into(),
        };
        hold(&mut written, &[held]);
        let rx = written.iter().find(|r| r.task == "can_rx").unwrap();
        assert_eq!((rx.cycles, rx.job.as_ref()), (None, None));
        // The charge and the job beside it kept in structured form, written and read back.
        let kept = rx.held.as_ref().expect("the held bound kept");
        assert_eq!(
            (kept.cycles, kept.us, kept.instructions),
            (Some(576), Some(8.0), Some(160))
        );
        assert_eq!(kept.job.as_ref().map(|j| j.cycles), Some(2160));
        assert_eq!(kept.reason, "LightRing's can_tx misses");
        let text = serde_json::to_string(rx).unwrap();
        assert!(text.contains(r#""held":{"cycles":576"#), "{text}");
        assert_eq!(&serde_json::from_str::<TaskBound>(&text).unwrap(), rx);
        let reason = rx.declined.as_deref().unwrap();
        assert!(reason.contains("576 cycles (8 µs"), "{reason}");
        assert!(
            reason.contains("per activation (RX at src/rx.rs:12 at 2 passes), its job"),
            "{reason}"
        );
        assert!(reason.contains("its job at 2160 cycles (30 µs"), "{reason}");
        assert!(reason.ends_with("LightRing's can_tx misses"), "{reason}");
    }

    #[test]
    fn a_software_task_takes_its_own_part_of_the_dispatcher_where_there_is_one() {
        let app = parse_app(APP).unwrap();
        let built = app.with_features(&[]);
        let chip = Chip::parse("stm32f103", None).unwrap();
        let budgets = Budgets {
            tasks: vec!["handle".into(), "drive".into()],
            topics: vec!["gyro".into()],
            publishers: ["publish".to_string()].into(),
            stated: BTreeMap::new(),
            scripts: BTreeMap::new(),
        };
        let machine = [
            found("dispatcher MID", 1440, None),
            found("dispatcher LOW", 7200, None),
            found("handle", 720, None),
            found("publish", 144, None),
        ];
        let sections = sections_of(&machine, &[]);
        let rows = rows(&built, &app, &budgets, &machine, &sections, chip);
        let row = |n: &str| rows.iter().find(|r| r.task == n).unwrap();
        // `handle` has its own part; `drive`, without one, the whole dispatcher's poll.
        assert_eq!(row("handle").cycles, Some(720));
        assert_eq!(row("drive").cycles, Some(1440));
        assert_eq!(row("publisher[gyro]").cycles, Some(144));
    }

    #[test]
    fn each_software_task_is_bounded_by_its_part_of_its_dispatcher() {
        let app = parse_app(APP).unwrap();
        let tasks = crate::machine::tasks_of(&app, &machine_code::BoundsFile::default());
        let entry = |n: &str| {
            tasks
                .iter()
                .find(|t| t.name == n)
                .map(|t| (t.entry.clone(), t.handler))
        };
        assert_eq!(
            entry("handle"),
            Some((
                machine_code::TaskEntry::Polled {
                    dispatcher: "MID".into(),
                    task: "handle".into(),
                    others: vec!["drive".into()],
                },
                true
            ))
        );
        // One task of its priority (`stimulus`, in the QEMU build only): nothing to leave out.
        assert_eq!(
            entry("stimulus"),
            Some((
                machine_code::TaskEntry::Polled {
                    dispatcher: "HIGH".into(),
                    task: "stimulus".into(),
                    others: Vec::new(),
                },
                true
            ))
        );
        assert!(entry("dispatcher LOW").is_some());
        assert!(entry("can_rx").is_some());
    }

    #[test]
    fn a_declined_publisher_declines_every_topic_and_a_missing_dispatcher_is_named() {
        let app = parse_app(APP).unwrap();
        let built = app.with_features(&[]);
        let chip = Chip::parse("stm32f405", None).unwrap();
        let budgets = Budgets {
            tasks: vec!["handle".into()],
            topics: vec!["a".into(), "b".into()],
            publishers: ["publish".to_string()].into(),
            stated: BTreeMap::new(),
            scripts: BTreeMap::new(),
        };
        let machine = [found(
            "dispatcher LOW",
            0,
            Some("irreducible control flow in LOW"),
        )];
        let rows = rows(
            &built,
            &app,
            &budgets,
            &machine,
            &sections_of(&machine, &[]),
            chip,
        );
        for topic in ["publisher[a]", "publisher[b]"] {
            let r = rows.iter().find(|r| r.task == topic).unwrap();
            assert!(
                r.declined.as_deref().unwrap().contains("irreducible"),
                "{r:?}"
            );
        }
        let handle = rows.iter().find(|r| r.task == "handle").unwrap();
        assert!(handle
            .declined
            .as_deref()
            .unwrap()
            .contains("polled by MID"));
        // Lazy FPU stacking on the M4F's entry, and its 5 wait states.
        let entry = rows.iter().find(|r| r.task == "exception_entry").unwrap();
        assert_eq!(entry.cycles, Some(12 + 17 + 2 * 5));
    }

    #[test]
    fn a_held_row_is_declined_with_its_figures_and_without_its_sections() {
        let held: machine_code::BoundsFile = machine_code::BoundsFile::parse(
            r#"{"held":[{"task":"can_tx","reason":"loose: every pass at its worst"},{"task":"publisher[*]","reason":"the bus transfers"}]}"#,
        )
        .unwrap();
        let mut rows = vec![
            bounded("can_tx", 7200, 3600, 0.0, 72_000_000),
            declined("publisher[gyroscope]", "i2c.rs:215".into()),
            bounded("shutdown", 72, 30, 0.0, 72_000_000),
        ];
        rows[0].sections = Some(CeilingSections {
            incomplete: None,
            ceilings: Vec::new(),
        });
        hold(&mut rows, &held.held);
        let reason = rows[0].declined.as_deref().unwrap();
        assert!(
            reason.starts_with(
                "can_tx: bounded from the machine code at 7200 cycles (100 µs, 3600 instructions"
            ) && reason.ends_with("held back as its budget: loose: every pass at its worst"),
            "{reason}"
        );
        assert_eq!(
            (rows[0].cycles, rows[0].us, &rows[0].sections),
            (None, None, &None)
        );
        // Kept in structured form: the bound, its sections, the reason.
        let kept = rows[0].held.as_ref().expect("the held bound kept");
        assert_eq!(
            (kept.cycles, kept.us, kept.instructions, kept.bus_wait_us),
            (Some(7200), Some(100.0), Some(3600), 0.0)
        );
        assert_eq!(kept.reason, "loose: every pass at its worst");
        assert_eq!(kept.sections.as_ref().map(|s| s.ceilings.len()), Some(0));
        // A declined row held without sections has nothing to use: no `held`.
        assert_eq!(rows[1].held, None);
        assert!(rows[1]
            .declined
            .as_deref()
            .unwrap()
            .ends_with("held back as its budget: the bus transfers"));
        // A row the file does not hold keeps its bound.
        assert_eq!((rows[2].cycles, &rows[2].declined), (Some(72), &None));
        assert!(
            machine_code::BoundsFile::parse(r#"{"held":[{"task":"can_tx","reason":" "}]}"#)
                .is_err()
        );
    }

    #[test]
    fn a_thread_mode_task_names_its_steps_bound_and_keeps_its_stated_budget() {
        let app = parse_app(APP).unwrap();
        let built = app.with_features(&[]);
        let chip = Chip::parse("stm32f103", None).unwrap();
        let budgets = Budgets {
            tasks: vec!["admit".into()],
            topics: Vec::new(),
            publishers: BTreeSet::new(),
            stated: [("admit".to_string(), (50.0, 80.0))].into(),
            scripts: BTreeMap::new(),
        };
        let mut step = found("admit", 7200, None);
        step.function = Some("check".into());
        let steps = [step];
        let written = rows(
            &built,
            &app,
            &budgets,
            &steps,
            &sections_of(&steps, &[]),
            chip,
        );
        let admit = written.iter().find(|r| r.task == "admit").unwrap();
        assert_eq!(admit.cycles, None);
        // Its sections go with it, marked as possibly only part of the job's.
        let sections = admit.sections.as_ref().expect("the step's sections");
        assert!(sections
            .incomplete
            .as_deref()
            .is_some_and(|w| w.contains("thread mode") && w.contains("(check)")));
        let reason = admit.declined.as_deref().unwrap();
        assert!(
            reason.contains("its step's check (check) is bounded from the machine code within its iteration caps at 7200 cycles (100 µs at 72 MHz, 3600 instructions)")
                && reason.ends_with("that check alone is 2 times the stated 50 µs and above the task's 80 µs deadline"),
            "{reason}"
        );
        let mut step = found("admit", 0, Some("the loop in check at a.rs:3 has no bound"));
        step.function = Some("check".into());
        let steps = [step];
        let written = rows(
            &built,
            &app,
            &budgets,
            &steps,
            &sections_of(&steps, &[]),
            chip,
        );
        let admit = written.iter().find(|r| r.task == "admit").unwrap();
        assert!(admit.declined.as_deref().unwrap().ends_with(
            "its step's check (check) is declined: the loop in check at a.rs:3 has no bound"
        ));
    }

    #[test]
    fn microseconds_round_up() {
        assert_eq!(us(72, 72_000_000), 1.0);
        assert_eq!(us(1, 72_000_000), 0.014);
        assert_eq!(us(0, 72_000_000), 0.0);
    }
}
