//! The build's checks of the machine code and `cargo xtask wcet`: thin callers of the
//! `machine-code` crate (the panic check, the stack bound, the execution-time bounds), printing
//! what it finds.
use std::path::{Path, PathBuf};

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

/// Arguments of `cargo xtask wcet`.
#[derive(clap::Args, Debug)]
pub struct WcetArgs {
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
    /// A bounds file (JSON; docs/analysis.md) for the loops and calls the machine code cannot bound.
    #[arg(long, value_name = "FILE")]
    pub bounds: Option<PathBuf>,
    /// Print JSON.
    #[arg(long)]
    pub json: bool,
}

/// `cargo xtask wcet --elf FILE --function SYMBOL --chip CHIP`: one function's bound. `Ok(false)`
/// when it was declined.
pub fn wcet(args: &WcetArgs) -> Result<bool> {
    let (Some(elf), Some(function), Some(chip)) = (&args.elf, &args.function, &args.chip) else {
        anyhow::bail!(
            "cargo xtask wcet needs --elf FILE --function SYMBOL --chip stm32f103|stm32f405 \
             (the per-board task table is not built yet)"
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
