//! The traced QEMU image's own bounds (issue 33, "the traced image bounded as well"): the tasks whose QEMU build
//! runs code the release image has not (the timing file's `trace.qemu.other_code`: the bxCAN register model, the
//! virtual mailboxes' candump printer, the simulated system signals, DiWheelDrive's motor plant, LightRing's
//! TLC5947 chain) bounded in the image the scenarios ran, with the board's bounds file and the QEMU-only
//! statements of `schedule-analysis/models/<board>.qemu.bounds.json` (loops, waits and calls of the QEMU build
//! alone, each with its reason). The release analysis never reads that file, so the release images' bounds and
//! the `wcet --write` fixed point do not depend on it.
//!
//! The bench holds those tasks' QEMU jobs to these bounds (`bench::machine::rows_against`): nothing generated is
//! kept, the bounds are computed from the ELF that just ran, once per image, and only for those tasks.
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use machine_code::{BoundsFile, Image};

use crate::revision::Build;

/// The QEMU-only statements of `board`'s traced QEMU build.
pub fn bounds_path(root: &Path, board: &str) -> PathBuf {
    root.join("schedule-analysis")
        .join("models")
        .join(format!("{board}.qemu.bounds.json"))
}

/// The board's bounds file with its QEMU-only statements added (either may be absent).
pub fn bounds_of(root: &Path, board: &str) -> Result<BoundsFile> {
    let release = root
        .join("schedule-analysis")
        .join("models")
        .join(format!("{board}.bounds.json"));
    let file = if release.exists() {
        BoundsFile::read(&release)?
    } else {
        BoundsFile::default()
    };
    let qemu = bounds_path(root, board);
    if !qemu.exists() {
        return Ok(file);
    }
    let extra = BoundsFile::read(&qemu)?;
    file.with(&extra)
        .with_context(|| format!("{} added to {}", qemu.display(), release.display()))
}

/// One task's bound in the QEMU image.
#[derive(Debug, Clone, serde::Serialize)]
pub struct QemuTaskBound {
    pub task: String,
    /// The function bounded (the handler, or the dispatcher the task is polled from).
    pub function: Option<String>,
    pub cycles: u64,
    /// The longest path's instructions: what a QEMU job is held to.
    pub instructions: u64,
    pub loops: Vec<machine_code::LoopInfo>,
    pub declined: Option<String>,
}

/// The bounds of `tasks` in the QEMU image `elf` of `build`.
#[derive(Debug, Clone, serde::Serialize)]
pub struct QemuBounds {
    pub elf: PathBuf,
    pub tasks: Vec<QemuTaskBound>,
    /// The QEMU file's statements with no place in this image (another board revision's, or stale).
    pub missing: Vec<String>,
    /// Wall-clock time the bounding took (noisy on a shared machine), s.
    pub seconds: f64,
}

/// Bounds `tasks` (RTIC task names) in the traced QEMU image `elf` of `build` (`qemu` and `task-trace` on, as
/// `workspace::build_qemu` builds it), each as `cargo xtask wcet` bounds the release image's: a hardware task
/// by its interrupt's handler, a software task by its part of its dispatcher. A task the app does not have in
/// this build is declined, naming it.
pub fn bound(
    root: &Path,
    build: &Build,
    elf: &Path,
    tasks: &BTreeSet<String>,
) -> Result<QemuBounds> {
    let started = Instant::now();
    let board = build.board;
    let chip = crate::machine::chip_of(board, None)?;
    let bounds = bounds_of(root, board.name)?;
    let source = std::fs::read_to_string(root.join(board.name).join("src").join("main.rs"))
        .with_context(|| format!("{}'s app source", board.name))?;
    let app = schedule_analysis::rtic_source::parse_app(&source)
        .map_err(|e| anyhow::anyhow!("{}: {e}", board.name))?;
    let mut features: Vec<&str> = build.revision.feature.into_iter().collect();
    features.extend(["qemu", "task-trace"]);
    let built = app.with_features(&features);
    let wanted: Vec<machine_code::Task> = crate::machine::tasks_of(&app, &bounds)
        .into_iter()
        .filter(|t| tasks.contains(&t.name))
        .filter(|t| {
            !matches!(t.entry, machine_code::TaskEntry::Polled { .. })
                || built.tasks.iter().any(|b| b.name == t.name)
        })
        .collect();
    let image = Image::read(elf).with_context(|| format!("{}", elf.display()))?;
    let found =
        crate::machine::worst_per_name(machine_code::bound_tasks(&image, &wanted, chip, &bounds));
    let mut by_name: BTreeMap<String, QemuTaskBound> = found
        .into_iter()
        .map(|t| {
            (
                t.task.clone(),
                QemuTaskBound {
                    task: t.task,
                    function: t.function,
                    cycles: t.cycles,
                    instructions: t.instructions,
                    loops: t.loops,
                    declined: t.declined,
                },
            )
        })
        .collect();
    for task in tasks {
        by_name
            .entry(task.clone())
            .or_insert_with(|| QemuTaskBound {
                task: task.clone(),
                function: None,
                cycles: 0,
                instructions: 0,
                loops: Vec::new(),
                declined: Some(format!(
                    "{} has no task {task} in its QEMU build",
                    board.name
                )),
            });
    }
    let missing = match BoundsFile::read(&bounds_path(root, board.name)) {
        Ok(qemu) => qemu.missing_places(&image),
        Err(_) => Vec::new(),
    };
    Ok(QemuBounds {
        elf: elf.to_path_buf(),
        tasks: by_name.into_values().collect(),
        missing,
        seconds: started.elapsed().as_secs_f64(),
    })
}

/// The tasks of `board` (at the models `build.select_models()` chose) that run a simulated device in QEMU.
pub fn other_code_tasks(root: &Path, board: &str) -> Result<BTreeSet<String>> {
    let files = schedule_analysis::scenario::timing_files(root);
    let bounds = schedule_analysis::scenario::board_bounds(root, &files, board)
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    Ok(bounds
        .and_then(|b| b.trace)
        .and_then(|t| t.qemu)
        .map(|q| q.other_code.into_keys().collect())
        .unwrap_or_default())
}

/// `cargo xtask wcet BOARD [--revision R] --qemu`: the other_code tasks of each selected revision's traced QEMU
/// image (`target/qemu/firmware/<stem>`, as the scenarios built it last), one line each.
pub fn print(root: &Path, plan: &[Build], json: bool) -> Result<bool> {
    let mut all = Vec::new();
    for build in plan {
        build.select_models();
        let elf = crate::workspace::qemu_target_dir(root)
            .join("firmware")
            .join(build.stem());
        anyhow::ensure!(
            elf.exists(),
            "{} is not built: cargo xtask scenarios {} (builds the traced QEMU image)",
            elf.display(),
            build.board.name
        );
        let tasks = other_code_tasks(root, build.board.name)?;
        let found = bound(root, build, &elf, &tasks)?;
        if !json {
            println!(
                "{} {}: QEMU image {} ({} tasks bounded in {:.1} s)",
                build.board.name,
                build.revision.name,
                found.elf.strip_prefix(root).unwrap_or(&found.elf).display(),
                found.tasks.len(),
                found.seconds
            );
            for m in &found.missing {
                println!("    a QEMU-only statement with no place in this image: {m}");
            }
            for t in &found.tasks {
                match &t.declined {
                    Some(why) => println!("    {:<16} DECLINED: {why}", t.task),
                    None => println!(
                        "    {:<16} ≤ {:>8} instructions ({} cycles at the F103/F405 model; {} loops)",
                        t.task,
                        t.instructions,
                        t.cycles,
                        t.loops.len()
                    ),
                }
            }
        }
        all.push((build.board.name, build.revision.name, found));
    }
    if json {
        let rows: Vec<_> = all
            .iter()
            .map(|(b, r, f)| serde_json::json!({ "board": b, "revision": r, "bounds": f }))
            .collect();
        println!("{}", serde_json::to_string_pretty(&rows)?);
    }
    Ok(all
        .iter()
        .all(|(_, _, f)| f.tasks.iter().all(|t| t.declined.is_none())))
}
