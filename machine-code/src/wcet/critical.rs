//! Critical sections from the machine code: every priority raise a task's code can make (its
//! handler or dispatcher, and every function it calls), each bounded from the raise to its restore
//! with the cycle model and loop bounds of the task bounds (`wcet::analysis`), and per task the
//! longest section at each ceiling: what the task can block others for (SRP's blocking term).
//!
//! The raises and restores, as RTIC 2 and `critical-section` (cortex-m, single core) compile:
//!
//! * a lock of a resource whose ceiling is below the top priority: `MRS rS, BASEPRI` … `MSR
//!   BASEPRI_MAX, rC` (rC holding the ceiling's hardware value, a constant the machine code sets) …
//!   `MSR BASEPRI, rS`. The ceiling is the raise's constant read back to RTIC's logical priority
//!   (`(2^bits − hw >> (8 − bits))`, 4 priority bits on both chips).
//! * interrupts off (`critical_section::with`, a lock at the top priority): `MRS rS, PRIMASK`;
//!   `CPSID i` … `MSR PRIMASK, rS` (or `CPSIE i`). An `MSR PRIMASK` of a register that may hold a
//!   constant with bit 0 set is a raise too.
//!
//! A write in an `IT` block may not execute: the raise's constant is joined with the value before it
//! (it must be the register's on every path), a raise under a condition is counted, and a restore
//! under one declines its section (`wcet::masking`).
//!
//! Raises of one kind nest (a lock inside a lock): a section runs from its raise to the restore
//! that brings its kind's nesting back to where it was, through every inner section; the inner
//! ones are sections of their own too. A section must end in the function that raised it (every
//! RTIC lock and `critical_section::with` is one closure call): one that reaches a return first is
//! declined, named, and so is one with a loop without a bound or a call the bound cannot resolve.
//! A raise of a value the machine code does not fix, or a function whose graph cannot be built,
//! makes the task's list incomplete. The functions a task reaches: its calls, a call through a
//! register resolved as the bound resolves it, else every function whose address the image stores
//! (a superset); not a function that cannot return (a panic halts the board).
//!
//! `wcet::masking` reads the instructions and builds a section's part of the graph.
use std::collections::{BTreeMap, BTreeSet};

use serde::Serialize;

use super::analysis::{Analysis, Summary};
use super::bounds::BoundsFile;
use super::cfg::{Block, Call, Cfg};
use super::chip::Chip;
use super::length::{self, NO_ARGS};
use super::masking::{effect, region, value_before, Effect, Kind, Masks};
use super::stored;
use super::{Task, TaskEntry};
use crate::decode::Insn;
use crate::image::Function;
use crate::{Error, Image};

/// Priority bits of the NVIC on both chips (STM32F103: PM0056 §4.4.7; STM32F405: PM0214 §4.3.7).
pub const NVIC_PRIO_BITS: u8 = 4;

/// What a section masks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Ceiling {
    /// BASEPRI raised to `hardware`: every interrupt of RTIC priority `priority` or below waits.
    Basepri { hardware: u8, priority: u8 },
    /// PRIMASK set: every interrupt waits.
    InterruptsOff,
}

impl Ceiling {
    /// The ceiling of a BASEPRI value, as RTIC's logical priority; `None` for 0 (no masking) or a
    /// value no logical priority maps to.
    pub fn of_basepri(hardware: u8) -> Option<Ceiling> {
        let shift = 8 - NVIC_PRIO_BITS;
        let level = hardware >> shift;
        if level == 0 || hardware & ((1 << shift) - 1) != 0 {
            return None;
        }
        Some(Ceiling::Basepri {
            hardware,
            priority: (1u8 << NVIC_PRIO_BITS) - level,
        })
    }

    /// The logical priority, `None` for interrupts off (above every priority).
    pub fn priority(self) -> Option<u8> {
        match self {
            Ceiling::Basepri { priority, .. } => Some(priority),
            Ceiling::InterruptsOff => None,
        }
    }
}

impl std::fmt::Display for Ceiling {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Ceiling::Basepri { hardware, priority } => {
                write!(f, "priority {priority} (BASEPRI {hardware:#04x})")
            }
            Ceiling::InterruptsOff => write!(f, "interrupts off"),
        }
    }
}

/// One critical section's bound.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Section {
    /// What it masks; `None` when the raise's value is not a constant of the machine code.
    pub ceiling: Option<Ceiling>,
    /// The function that raises, and where (the raise's source line, else its address).
    pub function: String,
    pub at: String,
    pub cycles: u64,
    pub instructions: u64,
    pub bus_wait_ns: u64,
    /// Why there is no bound (then the figures are 0 and mean nothing).
    pub declined: Option<String>,
}

/// A task's longest section at one ceiling.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CeilingBound {
    pub ceiling: Ceiling,
    /// Cycles from the raise to the restore (its longest path), machine code only.
    pub cycles: u64,
    /// The cycles at the chip's clock plus the stated waits inside, µs (0 when declined).
    pub us: f64,
    pub instructions: u64,
    pub bus_wait_us: f64,
    /// How many sections of the task's code raise to this ceiling.
    pub sections: usize,
    /// The longest one's raise (function, then file:line), or the declined one's.
    pub function: String,
    pub at: String,
    /// Why the ceiling has no bound: a section at it was declined (named).
    pub declined: Option<String>,
}

/// A task's critical sections, per ceiling.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TaskSections {
    pub task: String,
    /// The longest section at each ceiling the task's code raises to (highest first; interrupts
    /// off first of all).
    pub ceilings: Vec<CeilingBound>,
    /// Why the list may miss sections (a call the enumeration cannot follow, a raise of a value
    /// the machine code does not fix): then none of it stands for the task's blocking.
    pub incomplete: Option<String>,
}

/// The sections of every task's code (the tasks as [`super::bound_tasks`] takes them).
pub fn task_sections(
    image: &Image,
    tasks: &[Task],
    chip: Chip,
    bounds: &BoundsFile,
) -> Vec<TaskSections> {
    let mut finder = Finder {
        image,
        chip,
        bounds,
        analysis: Analysis::new(image, chip, bounds),
        per_function: BTreeMap::new(),
    };
    tasks.iter().map(|task| finder.of_task(task)).collect()
}

/// The sections one release of each topic group can hold in a job of `task` (the bounds file's
/// `topics`, docs/analysis.md "One topic's job"): the task's sections as [`task_sections`] finds
/// them in the job a group's topic bound takes (`super::topics`): every call of a function another
/// present group names left out of every function, with the blocks only such a call leads to, and
/// the group's own waits and loops; then every block left with no way to an exit (a raise in a block
/// of its own before such a call). A release of the group's topics runs none of those blocks, so a
/// raise in one of them (a lock the sampler takes around another family's sample function) is no
/// section of the release; the code around the release loop keeps its own. A function called
/// through a register is reached as [`task_sections`] reaches it (a superset). By group name, in
/// the file's order; empty where the file states no topics or none of its groups is in the image.
pub fn topic_sections(
    image: &Image,
    task: &Task,
    chip: Chip,
    bounds: &BoundsFile,
) -> Vec<(String, TaskSections)> {
    let Some(per_topic) = &bounds.topics else {
        return Vec::new();
    };
    let present = per_topic.present(image);
    present
        .iter()
        .map(|&group| {
            let stated = bounds.for_topic_group(per_topic, group);
            let excluded = super::bounds::PerTopic::excluded(group, &present);
            let mut finder = Finder {
                image,
                chip,
                bounds: &stated,
                analysis: Analysis::excluding(image, chip, &stated, &excluded),
                per_function: BTreeMap::new(),
            };
            (group.name.clone(), finder.of_task(task))
        })
        .collect()
}

impl<'a> Finder<'a> {
    /// `task`'s sections: its handler's (or its part of its dispatcher) and every function's it
    /// reaches.
    fn of_task(&mut self, task: &Task) -> TaskSections {
        match (task.entry.start(self.image), &task.entry) {
            (
                Ok(at),
                TaskEntry::Polled {
                    task: own, others, ..
                },
            ) => self.polled_task(&task.name, at, own, others),
            (Ok(at), _) => self.task(&task.name, at),
            (Err(e), _) => TaskSections {
                task: task.name.clone(),
                ceilings: Vec::new(),
                incomplete: Some(e.to_string()),
            },
        }
    }
}

/// The sections of one function's code (not its callees'), and the functions it calls.
#[derive(Debug, Clone)]
struct Found {
    sections: Vec<Section>,
    callees: Vec<u64>,
    /// Why the enumeration cannot go on from here.
    incomplete: Option<String>,
}

struct Finder<'a> {
    image: &'a Image,
    chip: Chip,
    bounds: &'a BoundsFile,
    analysis: Analysis<'a>,
    per_function: BTreeMap<u64, Found>,
}

/// Where an address is in the source (`file:line`), else the address.
fn place(image: &Image, at: u64) -> String {
    match image.line(at) {
        Some((file, line)) => format!("{file}:{line}"),
        None => format!("{at:#010x}"),
    }
}

/// Where a raise is named: the nearest line of the project's own code in its block (after it,
/// else before it), the raise being inlined from `cortex-m`; else the raise's own line.
fn raise_place(image: &Image, insns: &[Insn], block: &Block, k: usize) -> String {
    let own = |i: &Insn| {
        image
            .line(i.addr)
            .filter(|(file, _)| !third_party(file))
            .map(|(file, line)| format!("{file}:{line}"))
    };
    insns[k..=block.last]
        .iter()
        .find_map(own)
        .or_else(|| insns[block.first..k].iter().rev().find_map(own))
        .unwrap_or_else(|| place(image, insns[k].addr))
}

/// Whether a source path is a dependency's or the toolchain's, not the project's.
fn third_party(file: &str) -> bool {
    file.contains("/.cargo/registry/")
        || file.contains("/.cargo/git/")
        || file.contains("/rustlib/src/rust/library/")
        || file.starts_with("/rustc/")
}

impl<'a> Finder<'a> {
    /// Every function reachable from `entry`, their sections per ceiling.
    fn task(&mut self, name: &str, entry: u64) -> TaskSections {
        self.task_from(name, entry, None)
    }

    /// One software task's sections: those of its part of the dispatcher at `entry` (the
    /// dispatcher's own code and its poll, [`Analysis::polled_graph`]) and of every function that
    /// part reaches; the whole dispatcher's where the image does not tell its part.
    fn polled_task(
        &mut self,
        name: &str,
        entry: u64,
        task: &str,
        others: &[String],
    ) -> TaskSections {
        let part = match (
            self.image.function_at(entry),
            self.analysis.polled_graph(entry, task, others),
        ) {
            (Some(f), Ok(Some(Ok(graph)))) => match self.work_out_graph(f, self.on_paths(graph)) {
                Ok(found) => found,
                Err(e) => Found {
                    sections: Vec::new(),
                    callees: Vec::new(),
                    incomplete: Some(format!("{}: {e}", f.name)),
                },
            },
            (Some(_), Ok(Some(Err(reason)))) => Found {
                sections: Vec::new(),
                callees: Vec::new(),
                incomplete: Some(reason),
            },
            _ => return self.task(name, entry),
        };
        self.task_from(name, entry, Some(part))
    }

    /// [`Self::task`], the entry's own sections and callees `entry_found` where given.
    fn task_from(&mut self, name: &str, entry: u64, entry_found: Option<Found>) -> TaskSections {
        let mut seen = BTreeSet::from([entry]);
        let mut work = vec![entry];
        let mut sections = Vec::new();
        let mut incomplete = None;
        let mut entry_found = entry_found;
        while let Some(at) = work.pop() {
            let found = match entry_found.take().filter(|_| at == entry) {
                Some(found) => found,
                None => self.function(at),
            };
            sections.extend(found.sections.iter().cloned());
            if incomplete.is_none() {
                incomplete.clone_from(&found.incomplete);
            }
            for &c in &found.callees {
                if seen.insert(c) {
                    work.push(c);
                }
            }
        }
        let mut by_ceiling: BTreeMap<Ceiling, Vec<Section>> = BTreeMap::new();
        for s in sections {
            match s.ceiling {
                Some(c) => by_ceiling.entry(c).or_default().push(s),
                None => {
                    if incomplete.is_none() {
                        incomplete = Some(format!(
                            "the raise in {} at {}: {}",
                            s.function,
                            s.at,
                            s.declined.as_deref().unwrap_or("no ceiling")
                        ));
                    }
                }
            }
        }
        let chip = self.chip;
        let mut ceilings: Vec<CeilingBound> = by_ceiling
            .into_iter()
            .filter_map(|(ceiling, list)| {
                let count = list.len();
                let declined = list.iter().find(|s| s.declined.is_some());
                let key = |s: &&Section| s.cycles + chip.ns_to_cycles(s.bus_wait_ns);
                let s = declined.or_else(|| list.iter().max_by_key(key))?;
                let bounded = s.declined.is_none();
                Some(CeilingBound {
                    ceiling,
                    cycles: s.cycles,
                    us: if bounded {
                        (chip.cycles_to_ns(s.cycles) + s.bus_wait_ns) as f64 / 1000.0
                    } else {
                        0.0
                    },
                    instructions: s.instructions,
                    bus_wait_us: s.bus_wait_ns as f64 / 1000.0,
                    sections: count,
                    function: s.function.clone(),
                    at: s.at.clone(),
                    declined: s
                        .declined
                        .as_ref()
                        .map(|r| format!("the section raised in {} at {}: {r}", s.function, s.at)),
                })
            })
            .collect();
        // Highest ceiling first: interrupts off, then by priority down.
        ceilings
            .sort_by_key(|c| std::cmp::Reverse(c.ceiling.priority().map_or(u16::MAX, u16::from)));
        TaskSections {
            task: name.to_string(),
            ceilings,
            incomplete,
        }
    }

    /// One function's sections and callees, worked out once.
    fn function(&mut self, at: u64) -> Found {
        if let Some(found) = self.per_function.get(&at) {
            return found.clone();
        }
        let found = match self.image.function_at(at) {
            None => Found {
                sections: Vec::new(),
                callees: Vec::new(),
                incomplete: Some(format!("a call to {at:#010x}, where no function starts")),
            },
            Some(f) => match self.work_out(f) {
                Ok(found) => found,
                Err(e) => Found {
                    sections: Vec::new(),
                    callees: Vec::new(),
                    incomplete: Some(format!("{}: {e}", f.name)),
                },
            },
        };
        self.per_function.insert(at, found.clone());
        found
    }

    fn work_out(&mut self, f: &'a Function) -> Result<Found, Error> {
        let graph = match self.analysis.graph(f)? {
            Ok(g) => g,
            Err(reason) => {
                return Ok(Found {
                    sections: Vec::new(),
                    callees: Vec::new(),
                    incomplete: Some(reason),
                })
            }
        };
        let graph = self.on_paths(graph);
        self.work_out_graph(f, graph)
    }

    /// `graph` as the job's paths take it: where the job leaves calls out (one topic's release), a
    /// block left with no way to an exit ends no path of the job, so a raise in it (a lock the
    /// sampler takes before a left-out sample) is no section of the job: left out with it. A job
    /// that leaves nothing out keeps the graph as built.
    fn on_paths(&self, graph: Cfg) -> Cfg {
        if !self.analysis.leaves_calls_out() {
            return graph;
        }
        graph.on_paths_to_exits().unwrap_or(graph)
    }

    /// The sections and callees of `graph`, `f`'s graph or a part of it.
    fn work_out_graph(&mut self, f: &'a Function, graph: Cfg) -> Result<Found, Error> {
        let image = self.image;
        let insns = f.instructions()?;
        let mut callees = Vec::new();
        for (index, block) in graph.blocks.iter().enumerate() {
            match block.call {
                Some(Call::Direct { target, .. }) => callees.push(target),
                Some(Call::Indirect { at, .. }) => {
                    if let Some(t) = length::constant_target(image, insns, &graph, index)
                        .filter(|&t| image.function_at(t).is_some())
                    {
                        callees.push(t);
                        continue;
                    }
                    let stated = image.line(at).and_then(|(file, line)| {
                        self.bounds.indirect(&f.name, &file, line).cloned()
                    });
                    match stated {
                        // The stated targets, or those found stored with the stated object;
                        // where they cannot be found, every function whose address the image
                        // stores (below).
                        Some(stated) => match stored::targets(image, &stated, &f.name) {
                            Ok(Ok(targets)) => callees.extend(targets.into_iter().map(|(_, t)| t)),
                            _ => callees.extend(image.address_taken.iter().copied()),
                        },
                        // Not stated: every function whose address the image stores (a call
                        // through a register reaches no other), a superset.
                        None => callees.extend(image.address_taken.iter().copied()),
                    }
                }
                None => {}
            }
        }
        // A call of a function that cannot return (a panic, the fault handler's halt) ends the
        // job: the board halts into its safe state, no task runs after it to be blocked.
        callees.retain(|&c| self.analysis.can_return(c));
        let mut incomplete = None;
        let mut sections = Vec::new();
        let masks = Masks::new(image, insns, &graph);
        // The raises, by instruction (a block copied by node splitting raises once per copy: the
        // longest of them is the section's bound).
        let mut raises: BTreeMap<usize, Vec<(usize, Kind, Option<u8>)>> = BTreeMap::new();
        for (b, block) in graph.blocks.iter().enumerate() {
            let mut known = masks.entry(b);
            for (k, insn) in insns
                .iter()
                .enumerate()
                .take(block.last + 1)
                .skip(block.first)
            {
                match effect(insn, &known) {
                    Some(Effect::Raise(kind, reg)) => {
                        raises.entry(k).or_default().push((b, kind, reg));
                    }
                    // A write of a mask the code does not fix may raise it: a section this list
                    // cannot bound.
                    Some(Effect::Unclear(kind)) if incomplete.is_none() => {
                        incomplete = Some(format!(
                            "{}: the {kind:?} write at {:#010x} is neither a raise nor a restore \
                             of a value an MRS saved",
                            f.name, insn.addr
                        ));
                    }
                    _ => {}
                }
                known.step(image, insn);
            }
        }
        for (k, copies) in raises {
            let mut worst: Option<Section> = None;
            for (b, kind, reg) in copies {
                let s = self.section(f, insns, &graph, &masks, b, k, kind, reg)?;
                worst = Some(match worst {
                    None => s,
                    Some(w) if w.declined.is_some() => w,
                    Some(_) if s.declined.is_some() => s,
                    Some(w) if w.cycles >= s.cycles => w,
                    Some(_) => s,
                });
            }
            sections.extend(worst);
        }
        Ok(Found {
            sections,
            callees,
            incomplete,
        })
    }

    /// The section raised by instruction `k` (in block `b` of `graph`).
    #[allow(clippy::too_many_arguments)]
    fn section(
        &mut self,
        f: &'a Function,
        insns: &[Insn],
        graph: &Cfg,
        masks: &Masks,
        b: usize,
        k: usize,
        kind: Kind,
        reg: Option<u8>,
    ) -> Result<Section, Error> {
        let image = self.image;
        let at = raise_place(image, insns, &graph.blocks[b], k);
        let mut section = Section {
            ceiling: None,
            function: f.name.clone(),
            at,
            cycles: 0,
            instructions: 0,
            bus_wait_ns: 0,
            declined: None,
        };
        let ceiling = match (kind, reg) {
            (Kind::Primask | Kind::Faultmask, _) => Some(Ceiling::InterruptsOff),
            (Kind::Basepri, Some(r)) => match value_before(image, insns, graph, b, k, r) {
                Some(v) => match u8::try_from(v).ok().and_then(Ceiling::of_basepri) {
                    Some(c) => Some(c),
                    None => {
                        section.declined = Some(format!(
                            "raises BASEPRI to {v:#x}, no priority of {NVIC_PRIO_BITS} bits"
                        ));
                        return Ok(section);
                    }
                },
                None => {
                    section.declined = Some(format!(
                        "raises BASEPRI to r{r}, which holds no constant the machine code fixes"
                    ));
                    return Ok(section);
                }
            },
            (Kind::Basepri, None) => None,
        };
        section.ceiling = ceiling;
        let sub = match region(image, insns, graph, masks, b, k, kind) {
            Ok(sub) => sub,
            Err(reason) => {
                section.declined = Some(reason);
                return Ok(section);
            }
        };
        match self
            .analysis
            .bound_graph(f, sub, NO_ARGS, None, &super::values::NO_CONTEXT)?
        {
            Ok(Summary {
                time,
                count,
                totals,
                ..
            }) => {
                // The loops and calls stated in total per job, each charged its count of its longest
                // iteration or call once for the section, as for a job's bound (`to_bound`).
                let (time, count) = totals.values().fold((time, count), |(t, c), total| {
                    (
                        t.plus(total.time.times(total.passes)),
                        c.plus(total.count.times(total.passes)),
                    )
                });
                section.cycles = time.cycles;
                section.instructions = count.instructions;
                section.bus_wait_ns = time.wait_ns;
            }
            Err(reason) => section.declined = Some(reason),
        }
        Ok(section)
    }
}
