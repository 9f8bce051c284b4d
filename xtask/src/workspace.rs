//! The workspace and its builds, for every command: where the workspace and its target directory are, running
//! cargo and other tools, building the boards' images (for the chip and for QEMU), and QEMU itself. Below every
//! other module of xtask (they call it; it calls none of them but the board, revision and ELF tables).
use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{bail, Context, Result};

use crate::boards::Board;
use crate::{elf, revision};

/// The workspace root (the parent of this crate's folder).
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_default()
}

pub fn target_dir(root: &Path) -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| root.join("target"))
}

/// Where QEMU builds go, apart from the real-hardware builds.
pub fn qemu_target_dir(root: &Path) -> PathBuf {
    target_dir(root).join("qemu")
}

/// Builds each image in its own cargo invocation (chip features must never unify), keeps a copy of
/// its ELF per revision (`target/firmware/`) and inspects it.
pub fn build_boards(
    root: &Path,
    builds: &[revision::Build],
    bare_chip: bool,
) -> Result<Vec<elf::SizeReport>> {
    ensure_toolchain(root)?;
    let mut reports = Vec::new();
    for build in builds {
        let board = build.board;
        build.select_models();
        let mut args = vec!["build".to_string(), "--release".into(), "--quiet".into()];
        args.extend(build.feature_args(if bare_chip { &["bare-chip"] } else { &[] }));
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        cargo(&root.join(board.name), &args)
            .with_context(|| format!("building {} {}", board.name, build.revision.name))?;
        let kept = kept_elf(root, build, bare_chip);
        if let Some(dir) = kept.parent() {
            std::fs::create_dir_all(dir)?;
        }
        std::fs::copy(firmware_elf(root, board), &kept)
            .with_context(|| format!("keeping {}", kept.display()))?;
        let mut report = elf::inspect(board, &kept, !bare_chip)?;
        report.revision = build.revision.name.to_string();
        reports.push(report);
    }
    Ok(reports)
}

/// Where cargo leaves a board's release ELF.
pub fn firmware_elf(root: &Path, board: &Board) -> PathBuf {
    target_dir(root)
        .join(board.target)
        .join("release")
        .join(board.name)
}

/// Where the boards' trials (a feature the shipped image does not enable, e.g. `scripted-i2c`) are built for the
/// chip, apart from the shipped images: CI's check step lints and builds them here, and `cargo xtask wcet
/// --features` and the bounds gate build (cargo finds them current after CI's build) and bound them from here.
pub fn trial_target_dir(root: &Path) -> PathBuf {
    target_dir(root).join("scripted-i2c")
}

/// Builds `build`'s release image with the trial's `extra` features in [`trial_target_dir`] (the same cargo
/// arguments as CI's check step, so a build there is current) and keeps it as
/// `target/firmware/<stem>+<feature>….elf` ([`trial_elf`]).
pub fn build_trial(root: &Path, build: &revision::Build, extra: &[&str]) -> Result<PathBuf> {
    ensure_toolchain(root)?;
    let board = build.board;
    build.select_models();
    let dir = trial_target_dir(root);
    let dir = dir.to_string_lossy().into_owned();
    let mut args = vec!["build".to_string(), "--quiet".into(), "--release".into()];
    args.extend(build.feature_args(extra));
    args.extend(["--target-dir".to_string(), dir.clone()]);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    cargo(&root.join(board.name), &args)
        .with_context(|| format!("building {} with {}", build.stem(), extra.join(",")))?;
    let kept = trial_elf(root, build, extra);
    if let Some(parent) = kept.parent() {
        std::fs::create_dir_all(parent)?;
    }
    std::fs::copy(
        PathBuf::from(dir)
            .join(board.target)
            .join("release")
            .join(board.name),
        &kept,
    )
    .with_context(|| format!("keeping {}", kept.display()))?;
    Ok(kept)
}

/// Where [`build_trial`] keeps a trial's image: `target/firmware/powermgmt-1-2+scripted-i2c.elf`.
pub fn trial_elf(root: &Path, build: &revision::Build, extra: &[&str]) -> PathBuf {
    let stem = std::iter::once(build.stem())
        .chain(extra.iter().map(|f| f.to_string()))
        .collect::<Vec<_>>()
        .join("+");
    target_dir(root)
        .join("firmware")
        .join(format!("{stem}.elf"))
}

/// Where a built image of `build` is kept (the cargo output is overwritten by the next revision's
/// build): `target/firmware/<board>-<revision>.elf`.
pub fn kept_elf(root: &Path, build: &revision::Build, bare_chip: bool) -> PathBuf {
    target_dir(root).join("firmware").join(format!(
        "{}{}.elf",
        build.stem(),
        if bare_chip { "-bare" } else { "" }
    ))
}

/// Builds a board revision's QEMU variant (its own target dir: the features differ from the robot
/// build) and keeps its ELF apart from the other revision's (`target/qemu/firmware/`).
pub fn build_qemu(root: &Path, build: &revision::Build) -> Result<PathBuf> {
    build_qemu_with(root, build, &[])
}

/// [`build_qemu`] with the board's `extra` features as well (a trial the shipped image does not
/// enable, e.g. DiWheelDrive 1-1's `scripted-i2c`); kept beside it under its own name.
pub fn build_qemu_with(root: &Path, build: &revision::Build, extra: &[&str]) -> Result<PathBuf> {
    let board = build.board;
    let dir = qemu_target_dir(root);
    let cargo_bin = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    build.select_models();
    let mut args = vec!["build".to_string(), "--release".into(), "--quiet".into()];
    // With the task trace: the bench measures the scenario runs (docs/bench.md).
    let mut features = vec!["qemu", "task-trace"];
    features.extend_from_slice(extra);
    args.extend(build.feature_args(&features));
    let mut command = Command::new(cargo_bin);
    command
        .args(&args)
        .current_dir(root.join(board.name))
        .env("CARGO_TARGET_DIR", &dir);
    firmware_paths(&mut command, root);
    let status = command
        .status()
        .with_context(|| format!("building the QEMU variant of {}", board.name))?;
    if !status.success() {
        bail!(
            "building the QEMU variant of {} failed ({status})",
            board.name
        );
    }
    let stem = std::iter::once(build.stem())
        .chain(extra.iter().map(|f| f.to_string()))
        .collect::<Vec<_>>()
        .join("+");
    let kept = dir.join("firmware").join(stem);
    std::fs::create_dir_all(dir.join("firmware"))?;
    std::fs::copy(
        dir.join(board.target).join("release").join(board.name),
        &kept,
    )
    .with_context(|| format!("keeping {}", kept.display()))?;
    Ok(kept)
}

/// Installs QEMU where the machine lacks it and we may (root with apt-get); otherwise says how.
pub fn ensure_qemu() -> Result<()> {
    if runs("qemu-system-arm", &["--version"]) {
        return Ok(());
    }
    apt_install(&["qemu-system-arm"], "qemu-system-arm is missing")
}

/// Whether `program` starts and exits successfully with `args` (standard input closed): how a tool is found.
pub fn runs(program: &str, args: &[&str]) -> bool {
    Command::new(program)
        .args(args)
        .stdin(std::process::Stdio::null())
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false)
}

/// Installs the Debian `packages` where we may (root with apt-get, as CI runs); otherwise fails with `missing`
/// and the command that installs them.
pub fn apt_install(packages: &[&str], missing: &str) -> Result<()> {
    let is_root = output(Path::new("."), "id", &["-u"])
        .map(|u| u.trim() == "0")
        .unwrap_or(false);
    if is_root {
        run_tool(Path::new("."), "apt-get", &["update", "-qq"])?;
        let mut args = vec!["install", "-y", "-qq"];
        args.extend_from_slice(packages);
        return run_tool(Path::new("."), "apt-get", &args);
    }
    let them = if packages.len() > 1 { "them" } else { "it" };
    bail!(
        "{missing}: install {them} (Debian/Ubuntu: sudo apt-get install {})",
        packages.join(" ")
    )
}

/// Runs cargo in `dir` and fails unless it succeeds.
pub fn cargo(dir: &Path, args: &[&str]) -> Result<()> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let mut command = Command::new(&cargo);
    command
        .args(args)
        .current_dir(dir)
        // The firmware folders pick their target from their own .cargo/config.toml.
        .env_remove("CARGO_BUILD_TARGET");
    if crate::boards::BOARDS.iter().any(|b| dir.ends_with(b.name)) {
        // A board's folder: its image is the same wherever the workspace is checked out.
        firmware_paths(&mut command, &workspace_root());
    }
    let status = command
        .status()
        .with_context(|| format!("running `cargo {}`", args.join(" ")))?;
    if !status.success() {
        bail!(
            "`cargo {}` in {} failed ({status})",
            args.join(" "),
            dir.display()
        );
    }
    Ok(())
}

/// Makes a firmware build's debug information name its sources by fixed prefixes, not by where this checkout
/// and the cargo home are (`--remap-path-prefix`, added to any flags already set in the environment): the
/// machine code never depended on the checkout path, but the DWARF line rows of inlined code did (the same
/// instruction of `CAN1_TX` at `tx_queue.rs:478` in one checkout, `:476` in another), and the bounds files key
/// their loops by file and line, so a bound found in one checkout was declined in the next. With the prefixes
/// fixed, `cargo xtask wcet` gives the same answer in every checkout and on every machine (docs/analysis.md,
/// "Keys by file and line").
pub fn firmware_paths(command: &mut Command, root: &Path) {
    let mut flags: Vec<String> = match std::env::var("CARGO_ENCODED_RUSTFLAGS") {
        Ok(encoded) if !encoded.is_empty() => encoded.split('\x1f').map(String::from).collect(),
        _ => std::env::var("RUSTFLAGS")
            .map(|f| f.split_whitespace().map(String::from).collect())
            .unwrap_or_default(),
    };
    flags.push(format!(
        "--remap-path-prefix={}={WORKSPACE_PREFIX}",
        root.display()
    ));
    if let Some(home) = cargo_home() {
        flags.push(format!(
            "--remap-path-prefix={}={CARGO_HOME_PREFIX}",
            home.display()
        ));
    }
    command
        .env_remove("RUSTFLAGS")
        .env("CARGO_ENCODED_RUSTFLAGS", flags.join("\x1f"));
}

/// What a firmware image's debug information calls the workspace's root (`firmware_paths`).
pub const WORKSPACE_PREFIX: &str = "/amiro";
/// What it calls the cargo home (the registry's sources under it).
pub const CARGO_HOME_PREFIX: &str = "/cargo";

/// Cargo's home: `CARGO_HOME`, else `~/.cargo`.
fn cargo_home() -> Option<PathBuf> {
    std::env::var_os("CARGO_HOME")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cargo")))
}

/// Installs the thumb targets and components `rust-toolchain.toml` names when the pinned toolchain
/// was already present without them (rustup only adds them when it installs the toolchain itself).
pub fn ensure_toolchain(root: &Path) -> Result<()> {
    let Ok(installed) = output(root, "rustup", &["target", "list", "--installed"]) else {
        // No rustup: the toolchain is managed some other way; cargo reports anything missing.
        return Ok(());
    };
    let missing: Vec<&str> = ["thumbv7m-none-eabi", "thumbv7em-none-eabihf"]
        .into_iter()
        .filter(|t| !installed.lines().any(|l| l.trim() == *t))
        .collect();
    if !missing.is_empty() {
        let mut args = vec!["target", "add"];
        args.extend(&missing);
        run_tool(root, "rustup", &args)?;
    }
    let components =
        output(root, "rustup", &["component", "list", "--installed"]).unwrap_or_default();
    let wanted = ["llvm-tools", "rust-src", "clippy", "rustfmt"];
    let lacking: Vec<&str> = wanted
        .into_iter()
        .filter(|c| !components.lines().any(|l| l.starts_with(c)))
        .collect();
    if !lacking.is_empty() {
        let mut args = vec!["component", "add"];
        args.extend(&lacking);
        run_tool(root, "rustup", &args)?;
    }
    Ok(())
}

pub fn output(dir: &Path, tool: &str, args: &[&str]) -> Result<String> {
    let out = Command::new(tool).args(args).current_dir(dir).output()?;
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

pub fn run_tool(dir: &Path, tool: &str, args: &[&str]) -> Result<()> {
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
