//! `cargo xtask smoke [BOARD…]`: the production images, booted on emulated silicon.
//!
//! Every other QEMU run uses the `qemu` builds (no clock tree, no bxCAN). This one boots the image
//! a robot runs — byte for byte what `cargo xtask flash` writes: the release ELF's load segments
//! with the AMiRo-BLT checksum word filled in — behind a stand-in for AMiRo-BLT at `0x0800_0000`
//! that does what the bootloader's hand-over does (VTOR = application base, MSP from its first
//! word, jump to its reset vector), on the QEMU machine nearest the board's chip: `netduinoplus2`
//! (STM32F405) for PowerManagement, `netduino2` (STM32F205, whose TIM2..TIM5 and SPI1 sit where
//! the F103's do) for DiWheelDrive and LightRing. QEMU emulates neither RCC nor bxCAN nor flash
//! interface nor IWDG nor GPIO on these machines (their registers read as zero), which is what a
//! chip whose clocks never come up looks like: the run shows that the boot's waits on them end
//! and are reported. Before booting, each ELF is scanned for unbounded waits (`machine_code::waits`).
//!
//! The run is steered over QMP (QEMU's JSON monitor) on QEMU's standard input and output: every
//! [`boot::POLL`] the guest is stopped, its program counter read and its RAM saved (`pmemsave`); the
//! RTT log channel is read out of the RAM image at the `_SEGGER_RTT` control block (found by
//! symbol as `cargo xtask bench` finds it on a probe, or by scanning RAM for its ID), the
//! monotonic's half-period counter (`amiro_firmware::timer_monotonic`, every board's) at its
//! symbol. The inputs the boot reads and QEMU has no GPIO for are held at the robot's level
//! ([`environment`]): by the stand-in, or through QEMU's gdbstub ([`gdb`]). It fails when the board halts (a panic or a HardFault parks the CPU in `fault::halt`),
//! when the monotonic's counter stops while QEMU runs, and when the log misses a step of the boot
//! ([`checks::check_log`]).
//!
//! The parts, one file each: the bootloader stand-in's assembler and the flash image
//! ([`standin`]), the robot's environment around the image ([`environment`]), the RTT log read out
//! of a RAM image ([`rtt`]), the log and timer checks ([`checks`]), the QMP client ([`qmp`]), one
//! board's run loop ([`boot`]) and the command below.
//!
//! [`boot::run_board`] takes one board and its ELF, so a caller can run it once per board revision.
use std::path::{Path, PathBuf};

use anyhow::{ensure, Context, Result};

mod boot;
mod checks;
pub mod environment;
mod gdb;
mod qmp;
mod rtt;
mod standin;

use crate::boards::Via;
use boot::run_board;

/// Where the stand-in for AMiRo-BLT goes: where the chip starts.
pub const STANDIN_BASE: u32 = 0x0800_0000;
/// Both chips' SRAM.
pub const RAM_BASE: u32 = 0x2000_0000;

/// `cargo xtask smoke`: boots the production image of each board revision in `builds` in QEMU
/// (built here unless `built` says the caller built them: then their kept ELFs are booted, nothing
/// is rebuilt); fails unless every one passes.
pub fn run(root: &Path, builds: &[crate::revision::Build], built: bool) -> Result<()> {
    crate::workspace::ensure_qemu()?;
    if !built {
        crate::workspace::build_boards(root, builds, false)?;
    }
    let mut failed = Vec::new();
    for build in builds {
        let board = build.board;
        let elf = crate::workspace::kept_elf(root, build, false);
        let name = format!("{} {}", board.name, build.revision.name);
        // Every wait on the boot path and after it bounded: the machine code says so.
        let found = machine_code::waits::scan_elf(&elf)?;
        let (known, new): (Vec<_>, Vec<_>) = found.iter().partition(|w| w.known().is_some());
        println!(
            "waits {}: {} unbounded-looking poll loop(s), {} with a stated bound",
            name,
            found.len(),
            known.len()
        );
        for wait in &known {
            println!(
                "waits {}: bounded by design: {} at {:#x} ({})",
                name,
                wait.function,
                wait.branch,
                wait.lines.first().map(String::as_str).unwrap_or("?")
            );
        }
        for wait in &new {
            println!(
                "waits {}: UNBOUNDED: {} at {:#x}: {}",
                name,
                wait.function,
                wait.branch,
                wait.lines.join(" | ")
            );
        }
        if !new.is_empty() {
            failed.push(name.clone());
        }
        let work = work_dir(root, &build.stem());
        let outcome =
            run_board(board, &elf, &work).with_context(|| format!("smoke run of {name}"))?;
        println!(
            "── {} on {} (production image behind an AMiRo-BLT stand-in) ──",
            name, board.qemu_machine
        );
        for input in board.qemu_inputs {
            println!(
                "  [{}: {} at {:#010x}, through {}]",
                match input.via {
                    Via::StandIn => "stand-in",
                    Via::Watchpoint => "gdbstub",
                },
                input.stands_for,
                input.address,
                input.through
            );
        }
        if let Some(patched) = outcome.patched_loads {
            println!("  [{patched} load(s) of the watched input given the robot's level]");
        }
        for line in outcome.log.lines() {
            println!("  {line}");
        }
        if outcome.failures.is_empty() {
            let timer = board.monotonic_timer;
            println!(
                "  [monotonic: {} at {:#010x} counts 1 MHz of the internal oscillator, 16-bit \
                 period, half-period compare set, interrupts enabled]",
                timer.name, timer.base
            );
            match outcome.handed_over {
                Some(callback) => println!(
                    "smoke {}: ok (handed over to AMiRo-BLT's `{callback}` callback: SYS_PD_N \
                     reads low on {}, where nothing holds it released)",
                    name, board.qemu_machine
                ),
                None => println!(
                    "smoke {}: ok ({} half periods of the monotonic)",
                    name, outcome.half_periods
                ),
            }
        } else {
            for failure in &outcome.failures {
                println!("smoke {name}: FAILED: {failure}");
            }
            println!(
                "  (images, RAM snapshot and QEMU's stderr: {})",
                work.display()
            );
            failed.push(name.clone());
        }
    }
    ensure!(failed.is_empty(), "smoke run failed: {}", failed.join(", "));
    Ok(())
}

fn work_dir(root: &Path, board: &str) -> PathBuf {
    crate::workspace::target_dir(root).join("smoke").join(board)
}
