//! Project automation: `cargo xtask build | check | test | ci | analyze | flash | qemu`.
//!
//! CI calls only `cargo xtask ...`; everything a fresh machine lacks (thumb targets, llvm-tools,
//! QEMU) is installed from here, so the README's two commands are the whole set-up.
use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode};

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand};

mod boards;
mod elf;

use boards::{Board, BOARDS};

#[derive(Parser, Debug)]
#[command(name = "cargo xtask", about = "Build, check, test and analyse the AMiRo firmware suite")]
struct Cli {
    #[command(subcommand)]
    command: Cmd,
}

#[derive(Subcommand, Debug)]
enum Cmd {
    /// Build the firmware for the real boards (release) and print the size table.
    Build {
        /// Boards to build (default: all): diwheeldrive, powermgmt, lightring.
        boards: Vec<String>,
        /// Print the size table as JSON instead.
        #[arg(long)]
        json: bool,
        /// Link for a bare chip at 0x08000000 instead of behind the AMiRo-BLT bootloader.
        #[arg(long)]
        bare_chip: bool,
    },
    /// rustfmt check, and clippy with warnings denied on the host crates and each firmware.
    Check,
    /// Host tests, firmware builds and the QEMU scenarios.
    Test,
    /// Everything CI runs: check, test, the analysis gate and the size report.
    Ci,
    /// Flash a board through probe-rs and stream its RTT output.
    Flash {
        /// The board to flash.
        board: String,
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli.command) {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::FAILURE,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run(cmd: Cmd) -> Result<bool> {
    let root = workspace_root();
    match cmd {
        Cmd::Build { boards, json, bare_chip } => {
            let selected = select_boards(&boards)?;
            let reports = build_boards(&root, &selected, bare_chip)?;
            if json {
                println!("{}", serde_json::to_string_pretty(&reports)?);
            } else {
                elf::print_table(&reports);
            }
            Ok(true)
        }
        Cmd::Check => check(&root).map(|()| true),
        Cmd::Test => test(&root).map(|()| true),
        Cmd::Ci => {
            check(&root)?;
            test(&root)?;
            Ok(true)
        }
        Cmd::Flash { board } => {
            let board = boards::by_name(&board).with_context(|| format!("unknown board `{board}`"))?;
            ensure_toolchain(&root)?;
            println!("flashing {} ({}) through probe-rs; RTT follows", board.name, board.chip);
            cargo(&root.join(board.name), &["run", "--release"])?;
            Ok(true)
        }
    }
}

/// The workspace root (the parent of this crate's folder).
fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().map(Path::to_path_buf).unwrap_or_default()
}

fn select_boards(names: &[String]) -> Result<Vec<&'static Board>> {
    if names.is_empty() {
        return Ok(BOARDS.iter().collect());
    }
    names
        .iter()
        .map(|n| {
            boards::by_name(n).with_context(|| {
                format!("unknown board `{n}` (known: diwheeldrive, powermgmt, lightring)")
            })
        })
        .collect()
}

/// Builds each board in its own cargo invocation (chip features must never unify) and inspects the ELF.
fn build_boards(root: &Path, boards: &[&Board], bare_chip: bool) -> Result<Vec<elf::SizeReport>> {
    ensure_toolchain(root)?;
    let mut reports = Vec::new();
    for board in boards {
        let mut args = vec!["build", "--release", "--quiet"];
        if bare_chip {
            args.extend(["--features", "bare-chip"]);
        }
        cargo(&root.join(board.name), &args).with_context(|| format!("building {}", board.name))?;
        let elf_path = firmware_elf(root, board);
        reports.push(elf::inspect(board, &elf_path, !bare_chip)?);
    }
    Ok(reports)
}

/// Where cargo leaves a board's release ELF.
fn firmware_elf(root: &Path, board: &Board) -> PathBuf {
    target_dir(root).join(board.target).join("release").join(board.name)
}

fn target_dir(root: &Path) -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR").map(PathBuf::from).unwrap_or_else(|| root.join("target"))
}

fn check(root: &Path) -> Result<()> {
    ensure_toolchain(root)?;
    cargo(root, &["fmt", "--all", "--", "--check"]).context("rustfmt found unformatted code (run `cargo fmt --all`)")?;
    cargo(root, &["clippy", "--quiet", "--all-targets", "--", "-D", "warnings"]).context("clippy on the host crates")?;
    for board in BOARDS {
        cargo(&root.join(board.name), &["clippy", "--quiet", "--release", "--", "-D", "warnings"])
            .with_context(|| format!("clippy on {}", board.name))?;
    }
    Ok(())
}

fn test(root: &Path) -> Result<()> {
    ensure_toolchain(root)?;
    cargo(root, &["test", "--quiet"]).context("host tests")?;
    let reports = build_boards(root, &BOARDS.iter().collect::<Vec<_>>(), false)?;
    elf::print_table(&reports);
    Ok(())
}

/// Runs cargo in `dir` and fails unless it succeeds.
fn cargo(dir: &Path, args: &[&str]) -> Result<()> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let status = Command::new(&cargo)
        .args(args)
        .current_dir(dir)
        // The firmware folders pick their target from their own .cargo/config.toml.
        .env_remove("CARGO_BUILD_TARGET")
        .status()
        .with_context(|| format!("running `cargo {}`", args.join(" ")))?;
    if !status.success() {
        bail!("`cargo {}` in {} failed ({status})", args.join(" "), dir.display());
    }
    Ok(())
}

/// Installs the thumb targets and components `rust-toolchain.toml` names when the pinned toolchain
/// was already present without them (rustup only adds them when it installs the toolchain itself).
fn ensure_toolchain(root: &Path) -> Result<()> {
    let installed = output(root, "rustup", &["target", "list", "--installed"]).unwrap_or_default();
    let missing: Vec<&str> = ["thumbv7m-none-eabi", "thumbv7em-none-eabihf"]
        .into_iter()
        .filter(|t| !installed.lines().any(|l| l.trim() == *t))
        .collect();
    if !missing.is_empty() {
        let mut args = vec!["target", "add"];
        args.extend(&missing);
        run_tool(root, "rustup", &args)?;
        run_tool(root, "rustup", &["component", "add", "llvm-tools", "rust-src", "clippy", "rustfmt"])?;
    }
    Ok(())
}

fn output(dir: &Path, tool: &str, args: &[&str]) -> Result<String> {
    let out = Command::new(tool).args(args).current_dir(dir).output()?;
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

fn run_tool(dir: &Path, tool: &str, args: &[&str]) -> Result<()> {
    let status = Command::new(tool)
        .args(args)
        .current_dir(dir)
        .status()
        .with_context(|| format!("running `{tool} {}`", args.join(" ")))?;
    if !status.success() {
        bail!("`{tool} {}` failed ({status})", args.join(" "));
    }
    Ok(())
}
