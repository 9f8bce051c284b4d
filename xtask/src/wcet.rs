//! `cargo xtask wcet`: every task of the boards' release images bounded ([`crate::machine`]) and
//! printed, one function of any ELF (`--elf`), with `--write` each image's generated bounds file
//! ([`crate::wcet_write`]), with `--qemu` the traced QEMU images' own bounds ([`crate::wcet_qemu`]).
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use machine_code::stack::short;
use machine_code::{BoundsFile, Chip, Image};

use crate::machine::bound_build;

/// Arguments of `cargo xtask wcet`.
#[derive(clap::Args, Debug)]
pub struct WcetArgs {
    /// Boards whose built release images to bound per task (default: all; build them first with
    /// `cargo xtask build --revision …`).
    #[arg(conflicts_with = "elf")]
    pub boards: Vec<String>,
    /// The robot revision of the images: 1-2, 1-1, or all. Default: each board's newest.
    #[arg(long, value_name = "1-2|1-1|all", conflicts_with = "elf")]
    pub revision: Option<String>,
    /// Any ELF: bound one function of it (with `--function` and `--chip`).
    #[arg(long, value_name = "FILE", requires_all = ["function", "chip"])]
    pub elf: Option<PathBuf>,
    /// The function to bound: its demangled name without hash, or its symbol.
    #[arg(long, value_name = "SYMBOL")]
    pub function: Option<String>,
    /// The chip the ELF runs on.
    #[arg(long, value_name = "stm32f103|stm32f405")]
    pub chip: Option<String>,
    /// Flash wait states (default: the chip's at its board clock: F103 2, F405 5).
    #[arg(long, value_name = "N")]
    pub wait_states: Option<u32>,
    /// A bounds file (JSON; docs/analysis.md) for the loops and calls the machine code cannot
    /// bound (default with a board: schedule-analysis/models/BOARD.bounds.json).
    #[arg(long, value_name = "FILE")]
    pub bounds: Option<PathBuf>,
    /// A trial's features (`scripted-i2c`): build each board's image with them as well (in
    /// `target/scripted-i2c`, as CI's check step does; kept as `target/firmware/<stem>+<feature>.elf`) and bound
    /// its tasks, the trial's own among them. Printed only: no generated file is written for a trial.
    #[arg(long, value_name = "FEATURE,…", value_delimiter = ',', conflicts_with_all = ["elf", "write", "qemu"])]
    pub features: Vec<String>,
    /// Print JSON.
    #[arg(long)]
    pub json: bool,
    /// Build the images, bound them and write each image's generated bounds file
    /// (`schedule-analysis/models/<board>[-<rev>].wcet.json`), repeating until the images built from
    /// the files are the images bounded (default: every revision).
    #[arg(long, conflicts_with = "elf")]
    pub write: bool,
    /// Bound the tasks that run a simulated device in QEMU (the timing file's `trace.qemu.other_code`) in the
    /// traced QEMU image the scenarios built (`target/qemu/firmware/<board>-<rev>`), with the board's bounds file
    /// and its QEMU-only statements (`schedule-analysis/models/<board>.qemu.bounds.json`).
    #[arg(long, conflicts_with_all = ["elf", "write"])]
    pub qemu: bool,
}

/// `cargo xtask wcet`: one function of any ELF (`--elf`), else every task of the boards' images.
pub fn wcet(root: &Path, args: &WcetArgs) -> Result<bool> {
    if args.elf.is_none() {
        return wcet_boards(root, args);
    }
    wcet_function(args)
}

/// One row of the per-task table.
#[derive(serde::Serialize)]
struct Row<'a> {
    board: &'a str,
    revision: &'a str,
    task: String,
    function: Option<String>,
    cycles: u64,
    us: f64,
    instructions: u64,
    bus_wait_us: f64,
    loops: Vec<machine_code::LoopInfo>,
    preemption_retry_cycles: u64,
    declined: Option<String>,
    /// Where the bounds file charges the task per activation: that charge (the row's figures are the job's).
    per_activation: Option<machine_code::ActivationBound>,
    /// Where the bounds file charges the task by its parts: fixed per job, a pass and a completion per frame,
    /// a requeue per abort (the row's figures are the job's).
    #[serde(skip_serializing_if = "Option::is_none")]
    per_frame: Option<machine_code::FrameBound>,
    /// Where the bounds file states the release loop per topic: one release of each topic group's topics.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    topics: Vec<machine_code::TopicBound>,
    /// The task's longest critical section per ceiling (from the priority raise to its restore).
    critical_sections: Vec<machine_code::CeilingBound>,
    /// Why the sections found may not be all of them (then none stands for the task's blocking).
    critical_sections_incomplete: Option<String>,
}

/// Every task of each board's release image ([`crate::machine::tasks_of`]); with `--write`, the
/// generated bounds file of each image too ([`crate::wcet_write`]).
fn wcet_boards(root: &Path, args: &WcetArgs) -> Result<bool> {
    let boards = crate::boards::select_boards(&args.boards)?;
    // `--write` without `--revision` writes every revision's file.
    let choice = match (&args.revision, args.write) {
        (None, true) => crate::revision::Choice::All,
        (revision, _) => crate::revision::Choice::parse(revision.as_deref())?,
    };
    let plan = crate::revision::plan(&boards, &choice)?;
    if args.qemu {
        return crate::wcet_qemu::print(root, &plan, args.json);
    }
    if args.write {
        crate::wcet_write::write(root, &plan, args.wait_states, args.bounds.as_deref())?;
    }
    let mut rows = Vec::new();
    for build in &plan {
        let board = build.board;
        let found = if args.features.is_empty() {
            bound_build(root, build, args.wait_states, args.bounds.as_deref())?
        } else {
            let extra: Vec<&str> = args.features.iter().map(String::as_str).collect();
            let elf = crate::workspace::build_trial(root, build, &extra)?;
            crate::machine::bound_image(
                root,
                build,
                &extra,
                &elf,
                args.wait_states,
                args.bounds.as_deref(),
            )?
        };
        let chip = found.chip;
        for (t, sections) in found.tasks.into_iter().zip(found.sections) {
            rows.push(Row {
                board: board.name,
                revision: build.revision.name,
                task: t.task,
                function: t.function,
                cycles: t.cycles,
                us: t.us,
                instructions: t.instructions,
                bus_wait_us: t.bus_wait_us,
                loops: t.loops,
                preemption_retry_cycles: t.preemption_retry_cycles,
                declined: t.declined,
                per_activation: t.per_activation,
                per_frame: t.per_frame,
                topics: t.topics,
                critical_sections: sections.ceilings,
                critical_sections_incomplete: sections.incomplete,
            });
        }
        if !args.json {
            println!(
                "{} {}{}: {} at {} MHz, {} flash wait states",
                board.name,
                build.revision.name,
                if args.features.is_empty() {
                    String::new()
                } else {
                    format!(" with {}", args.features.join(","))
                },
                chip.name(),
                chip.clock_hz() / 1_000_000,
                chip.wait_states()
            );
            // An entry another revision's image may need; none in any image fails the CI gate.
            for entry in &found.missing {
                println!(
                    "{} {}: a stated bound with no place in this image: {entry}",
                    board.name, build.revision.name
                );
            }
        }
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
    } else {
        for r in &rows {
            match &r.declined {
                Some(reason) => println!(
                    "{:<13} {:<8} {:<28} DECLINED: {reason}",
                    r.board, r.revision, r.task
                ),
                None => println!(
                    "{:<13} {:<8} {:<28} ≤ {:>7} cycles {:>9.2} µs {:>6} instructions, bus waits {:.2} µs, {} loop(s)",
                    r.board,
                    r.revision,
                    r.task,
                    r.cycles,
                    r.us,
                    r.instructions,
                    r.bus_wait_us,
                    r.loops.len()
                ),
            }
            if let Some(a) = &r.per_activation {
                match &a.declined {
                    Some(reason) => println!(
                        "    per activation ({} at {} passes): DECLINED: {reason}",
                        a.at, a.passes
                    ),
                    None => println!(
                        "    per activation ({} at {} passes): ≤ {} cycles {:.2} µs {} instructions, bus waits {:.2} µs \
                         (a job that serves k ≥ 1 activations: at most k times this; the bounds file's reason)",
                        a.at, a.passes, a.cycles, a.us, a.instructions, a.bus_wait_us
                    ),
                }
            }
            if let Some(f) = &r.per_frame {
                match &f.declined {
                    Some(reason) => println!("    per frame ({}): DECLINED: {reason}", f.at),
                    None => println!(
                        "    per job ≤ {} cycles {:.2} µs {} instructions; per frame ≤ {} cycles {:.2} µs {} instructions \
                         (a pass {} + a completion {}); per abort ≤ {} cycles {:.2} µs {} instructions (the requeue; the \
                         transmit loop {}, {} completions a job)",
                        f.fixed.cycles,
                        f.fixed.us,
                        f.fixed.instructions,
                        f.per_frame.cycles,
                        f.per_frame.us,
                        f.per_frame.instructions,
                        f.pass.cycles,
                        f.sent.cycles,
                        f.abort.cycles,
                        f.abort.us,
                        f.abort.instructions,
                        f.at,
                        f.completions
                    ),
                }
            }
            for g in &r.topics {
                match &g.declined {
                    Some(reason) => println!(
                        "    one release of {} ({}): DECLINED: {reason}",
                        g.group,
                        g.topics.join(", ")
                    ),
                    None => println!(
                        "    one release of {} ({}): ≤ {} cycles {:.2} µs {} instructions, bus waits {:.2} µs",
                        g.group,
                        g.topics.join(", "),
                        g.cycles,
                        g.us,
                        g.instructions,
                        g.bus_wait_us
                    ),
                }
            }
            print_sections(r);
        }
        let bounded = rows.iter().filter(|r| r.declined.is_none()).count();
        println!("{bounded} of {} tasks bounded", rows.len());
        let ceilings: Vec<&machine_code::CeilingBound> =
            rows.iter().flat_map(|r| &r.critical_sections).collect();
        println!(
            "critical sections: {} of {} ceilings bounded ({} tasks' enumeration incomplete)",
            ceilings.iter().filter(|c| c.declined.is_none()).count(),
            ceilings.len(),
            rows.iter()
                .filter(|r| r.critical_sections_incomplete.is_some())
                .count()
        );
    }
    Ok(true)
}

/// A task's critical sections, one line per ceiling under its row.
fn print_sections(r: &Row<'_>) {
    for c in &r.critical_sections {
        let many = if c.sections == 1 {
            String::new()
        } else {
            format!(", longest of {}", c.sections)
        };
        match &c.declined {
            Some(reason) => println!("    section at {}: DECLINED: {reason}", c.ceiling),
            None => println!(
                "    section at {}: ≤ {} cycles {:.2} µs {} instructions, bus waits {:.2} µs ({} at {}{many})",
                c.ceiling,
                c.cycles,
                c.us,
                c.instructions,
                c.bus_wait_us,
                short(&c.function),
                c.at
            ),
        }
    }
    if let Some(reason) = &r.critical_sections_incomplete {
        println!("    sections: INCOMPLETE: {reason}");
    }
}

/// `cargo xtask wcet --elf FILE --function SYMBOL --chip CHIP`: one function's bound. `Ok(false)`
/// when it was declined.
fn wcet_function(args: &WcetArgs) -> Result<bool> {
    let (Some(elf), Some(function), Some(chip)) = (&args.elf, &args.function, &args.chip) else {
        anyhow::bail!(
            "cargo xtask wcet --elf FILE needs --function SYMBOL --chip stm32f103|stm32f405"
        );
    };
    let chip = Chip::parse(chip, args.wait_states)?;
    let bounds = match &args.bounds {
        Some(path) => BoundsFile::read(path)?,
        None => BoundsFile::default(),
    };
    let image = Image::read(elf).with_context(|| format!("{}", elf.display()))?;
    let bound = machine_code::bound_function(&image, function, chip, &bounds)
        .with_context(|| format!("{}", elf.display()))?;
    let declined = bound.declined.is_some();
    if args.json {
        let json = serde_json::json!({
            "elf": elf,
            "function": function,
            "chip": chip.name(),
            "clock_hz": chip.clock_hz(),
            "wait_states": chip.wait_states(),
            "cycles": bound.cycles,
            "us": if declined { None } else { Some(bound.us(chip)) },
            "instructions": bound.instructions,
            "bus_wait_us": bound.bus_wait_us(),
            "loops": bound.loops,
            "retry_cycles": bound.retry_cycles,
            "retry_instructions": bound.retry_instructions,
            "declined": bound.declined,
        });
        println!("{}", serde_json::to_string_pretty(&json)?);
    } else {
        match &bound.declined {
            Some(reason) => println!("{function}: DECLINED: {reason}"),
            None => println!(
                "{function}: ≤ {} cycles ({:.2} µs on {} at {} MHz, {} wait states), ≤ {} instructions, stated bus waits {:.2} µs",
                bound.cycles,
                bound.us(chip),
                chip.name(),
                chip.clock_hz() / 1_000_000,
                chip.wait_states(),
                bound.instructions,
                bound.bus_wait_us()
            ),
        }
        for l in &bound.loops {
            println!(
                "  loop in {} at {}:{}: ≤ {} ({})",
                short(&l.function),
                l.file.as_deref().unwrap_or("?"),
                l.line.map_or_else(|| "?".to_string(), |n| n.to_string()),
                l.bound,
                l.source
            );
        }
    }
    Ok(!declined)
}

#[cfg(test)]
mod tests {
    /// A topic group of a board's bounds file may state `TxQueue`'s search for an older sample of a
    /// frame (`position_of_sample`) at one header run, not called in its job: `push` calls it only for
    /// a topic whose sample spans several frames, and a release pushes only its sample's frames. That
    /// holds while every topic of such a group is one frame a sample in amiro-can's table.
    #[test]
    fn single_frame_groups_state_no_sample_search() {
        let models =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../schedule-analysis/models");
        let mut stated = 0;
        for board in ["diwheeldrive", "powermgmt", "lightring"] {
            let path = models.join(format!("{board}.bounds.json"));
            let text = std::fs::read_to_string(&path).expect("the bounds file reads");
            let file: serde_json::Value =
                serde_json::from_str(&text).expect("the bounds file parses");
            let groups = file["topics"]["groups"]
                .as_array()
                .cloned()
                .unwrap_or_default();
            for group in groups {
                let states_it = group["loops"].as_array().is_some_and(|loops| {
                    loops.iter().any(|l| {
                        l["function"] == "amiro_sensors::tx_queue::position_of_sample"
                            && l["bound"] == 1
                    })
                });
                if !states_it {
                    continue;
                }
                stated += 1;
                for topic in group["topics"]
                    .as_array()
                    .expect("a group names its topics")
                {
                    let name = topic.as_str().expect("a topic's name");
                    let topic = amiro_can::Topic::from_name(name)
                        .unwrap_or_else(|| panic!("{board}: no topic {name}"));
                    assert_eq!(
                        topic.frames_per_sample(),
                        1,
                        "{board}: group {} states no sample search, but {name} spans several frames",
                        group["name"]
                    );
                }
            }
        }
        assert!(stated > 0, "no group states it: the test checks nothing");
    }
}
