//! `cargo xtask admission-search`: the search for the admission check's costliest step run again per robot revision
//! (amiro-firmware/examples/admission_search.rs, release build, the seeds docs/qemu.md documents), its winner compared
//! with the stored log of scenario `admission-search` on today's tables, and with `--write` the costlier of the two
//! stored. The search, the replay, the log's format and the rule that picks are
//! `amiro_firmware::admission_search`'s; this only runs them and prints what the budget rule needs.
use std::path::Path;
use std::process::Command as Process;

use anyhow::{bail, Context, Result};
use clap::Args;

use amiro_firmware::admission_search::{self, keep, Keep, StoredLog};

/// `cargo xtask admission-search`'s arguments.
#[derive(Args, Debug)]
pub struct SearchArgs {
    /// The robot revision whose tables are searched: 1-1, 1-2 or all (default).
    #[arg(long, value_name = "1-1|1-2|all")]
    revision: Option<String>,
    /// Store the new winner in place of the stored log when its costliest step takes strictly more iterations on
    /// today's tables (else the stored log stays as it is).
    #[arg(long)]
    write: bool,
    /// Rounds per seed (docs/qemu.md's searches: 20 000).
    #[arg(long, default_value_t = 20_000)]
    rounds: usize,
}

/// One revision's search: its seed and its scenario's stored log.
struct Target {
    revision: &'static str,
    seed: u64,
    log: &'static str,
}

/// The searches docs/qemu.md documents (policy changes on both).
const TARGETS: [Target; 2] = [
    Target {
        revision: "1-1",
        seed: 44,
        log: "diwheeldrive/qemu/admission-search.log",
    },
    Target {
        revision: "1-2",
        seed: 38,
        log: "diwheeldrive/qemu/rev-1-2/admission-search.log",
    },
];

/// Runs the searches; `false` when a kept sequence's costliest step falls below the scenario's 90 % of a step's
/// iterations (the scenario would ask for a search).
pub fn run(root: &Path, args: &SearchArgs) -> Result<bool> {
    let targets: Vec<&Target> = match args.revision.as_deref() {
        None | Some("all") => TARGETS.iter().collect(),
        Some(r) => match TARGETS.iter().find(|t| t.revision == r) {
            Some(t) => vec![t],
            None => bail!("--revision {r}: expected 1-1, 1-2 or all"),
        },
    };
    let most = 2 * schedule_analysis::admission::DECISION_ITERATIONS;
    let mut ok = true;
    let mut replays = Vec::new();
    for target in targets {
        let path = root.join(target.log);
        let text = std::fs::read_to_string(&path).with_context(|| target.log.to_string())?;
        let stored = StoredLog::parse(&text).with_context(|| target.log.to_string())?;
        println!(
            "{}: searching seed {} for {} rounds with policy changes (release build of amiro-firmware's example admission_search)",
            target.revision, target.seed, args.rounds
        );
        let found = run_example(root, target, args.rounds)?;
        let robot = schedule_analysis::admission_host::lower_robot_for(root, Some(target.revision))
            .map_err(|e| anyhow::anyhow!("the {} admission table: {e}", target.revision))?;
        let (stored_cost, found_cost) = robot.with_table(|table| {
            (
                admission_search::worst_step(table, &stored.sequence()),
                admission_search::worst_step(table, &found.sequence()),
            )
        });
        println!(
            "  stored {}: {} commands, its costliest step {stored_cost} on today's tables",
            target.log,
            stored.commands.len()
        );
        println!(
            "  found (seed {}): {} commands, its costliest step {found_cost}",
            target.seed,
            found.commands.len()
        );
        let kept_iterations = match keep(stored_cost, found_cost) {
            Keep::Stored => {
                println!("  the stored sequence costs as much or more: it stays");
                stored_cost.iterations
            }
            Keep::Found if args.write => {
                let log = replacement(&found, target.revision, &today(), found_cost, stored_cost);
                std::fs::write(&path, log.render())
                    .with_context(|| format!("writing {}", target.log))?;
                println!(
                    "  the new winner costs more: written to {} (replay it, update the figures in docs/qemu.md)",
                    target.log
                );
                found_cost.iterations
            }
            Keep::Found => {
                println!(
                    "  the new winner costs strictly more: `--write` stores it in {}",
                    target.log
                );
                stored_cost.iterations
            }
        };
        let share = kept_iterations as f64 * 100.0 / most as f64;
        println!(
            "  costliest step kept: {kept_iterations} of a step's {most} iterations ({share:.1} %; scenario admission-search asks for at least 90 %)"
        );
        if kept_iterations * 10 < most * 9 {
            println!("  below 90 %: scenario admission-search fails and asks for a search");
            ok = false;
        }
        match last_replay(root, target) {
            Ok(Some(replay)) => {
                println!(
                    "  its instructions: the last QEMU replay of this very log ({}, run {} UTC; the image of that run) took {} instructions in its costliest activation ({:.1} µs virtual of its own execution); a replay of today's image: `cargo xtask scenarios diwheeldrive --revision {}`",
                    replay.work.display(),
                    replay.when,
                    replay.instructions,
                    replay.own_us,
                    target.revision
                );
                replays.push((target.revision, replay.instructions));
            }
            Ok(None) => println!(
                "  its instructions: replay with `cargo xtask scenarios diwheeldrive --revision {}` (no kept QEMU run of this log)",
                target.revision
            ),
            Err(e) => println!(
                "  its instructions: replay with `cargo xtask scenarios diwheeldrive --revision {}` (the kept QEMU run does not read: {e:#})",
                target.revision
            ),
        }
    }
    println!(
        "the admission task's recorded worst step and budget per step in each timing file (a replay may exceed the record by 2 % at most):"
    );
    for path in crate::scenarios::diwheeldrive::ADMISSION_BUDGETS {
        let (budget, step) = crate::scenarios::diwheeldrive::admission_budget(path)?;
        let on_chip = step.on_chip_us();
        let mut line = format!(
            "  {path}: worst_step {} instructions ({} iterations), ≈ {on_chip:.0} µs at {} MHz and {} cycles per instruction = {:.1} % of admit_requests' {budget} µs",
            step.instructions,
            step.iterations,
            step.clock_mhz,
            step.cycles_per_instruction,
            on_chip * 100.0 / budget
        );
        for (revision, instructions) in &replays {
            let above = (*instructions as f64 / step.instructions as f64 - 1.0) * 100.0;
            line.push_str(&format!(
                "; {revision} replay {above:+.1} % of the record, {:.1} % of the budget",
                step.us_for(*instructions) * 100.0 / budget
            ));
        }
        println!("{line}");
    }
    Ok(ok)
}

/// The log `--write` stores: the search's winner with a header line saying how and when, and what it replaced.
fn replacement(
    found: &StoredLog,
    revision: &str,
    date: &str,
    found_cost: admission_search::Cost,
    stored_cost: admission_search::Cost,
) -> StoredLog {
    let mut log = found.clone();
    log.header.push(format!(
        "Stored by `cargo xtask admission-search --revision {revision} --write` on {date}: {found_cost} on these tables, above the stored sequence's {} iterations.",
        stored_cost.iterations
    ));
    log
}

/// A kept QEMU run of scenario `admission-search` (`cargo xtask scenarios` keeps each run's work directory).
struct Replay {
    work: std::path::PathBuf,
    when: String,
    instructions: u64,
    own_us: f64,
}

/// The last QEMU run of `target`'s scenario if it replayed the stored log as it is now (its `stimulus.bin` the
/// log's encoding): the admission task's costliest activation, read from its task trace as the scenario reads it.
fn last_replay(root: &Path, target: &Target) -> Result<Option<Replay>> {
    let work = crate::workspace::qemu_target_dir(root)
        .join("scenarios")
        .join(format!("diwheeldrive-{}", target.revision))
        .join("admission-search");
    let Ok(sent) = std::fs::read(work.join("stimulus.bin")) else {
        return Ok(None);
    };
    let log = root.join(target.log);
    let frames = crate::qemu::read_stimulus(&log)?;
    if sent != crate::qemu::encode_stimulus(&frames, crate::scenarios::duration_of(&log)?) {
        return Ok(None);
    }
    let output = work.join("output.log");
    let text = std::fs::read_to_string(&output).with_context(|| output.display().to_string())?;
    let when = std::fs::metadata(&output)
        .and_then(|m| m.modified())
        .ok()
        .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
        .map_or_else(
            || "at an unknown time".to_string(),
            |d| timestamp(d.as_secs()),
        );
    let mut out = crate::scenarios::RunOutput::parse(&text)?;
    out.work = Some(work.clone());
    let (own_us, runs) = out.own_execution_us("diwheeldrive", "admit_requests")?;
    if runs == 0 {
        bail!("its task trace shows no run of admit_requests");
    }
    let instructions = crate::scenarios::diwheeldrive::qemu_instructions(own_us);
    Ok(Some(Replay {
        work,
        when,
        instructions,
        own_us,
    }))
}

/// Runs the example's search on `target`'s tables and reads its winner.
fn run_example(root: &Path, target: &Target, rounds: usize) -> Result<StoredLog> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let seed = target.seed.to_string();
    let rounds = rounds.to_string();
    let args = [
        "run",
        "-q",
        "--release",
        "-p",
        "amiro-firmware",
        "--example",
        "admission_search",
        "--",
        &seed,
        &rounds,
        "policies",
    ];
    let output = Process::new(&cargo)
        .args(args)
        .current_dir(root)
        .env(schedule_analysis::scenario::REVISION_ENV, target.revision)
        .env("CARGO_INCREMENTAL", "0")
        .env_remove("CARGO_BUILD_TARGET")
        .stderr(std::process::Stdio::inherit())
        .output()
        .with_context(|| format!("running `cargo {}`", args.join(" ")))?;
    if !output.status.success() {
        bail!("`cargo {}` failed ({})", args.join(" "), output.status);
    }
    let text = String::from_utf8(output.stdout).context("the example's log is not UTF-8")?;
    StoredLog::parse(&text).context("the example's log")
}

/// Today's date (UTC) as `YYYY-MM-DD`.
fn today() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let (y, m, d) = civil_from_days((secs / 86_400) as i64);
    format!("{y:04}-{m:02}-{d:02}")
}

/// `secs` after the epoch (UTC) as `YYYY-MM-DD HH:MM`.
fn timestamp(secs: u64) -> String {
    let (y, m, d) = civil_from_days((secs / 86_400) as i64);
    let minutes = secs % 86_400 / 60;
    format!(
        "{y:04}-{m:02}-{d:02} {:02}:{:02}",
        minutes / 60,
        minutes % 60
    )
}

/// The proleptic Gregorian date `days` days after 1970-01-01.
fn civil_from_days(days: i64) -> (i64, u32, u32) {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    let y = yoe + era * 400 + i64::from(m <= 2);
    (y, m, d)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dates() {
        assert_eq!(civil_from_days(0), (1970, 1, 1));
        assert_eq!(civil_from_days(20_793), (2026, 12, 6));
        assert_eq!(civil_from_days(11_016), (2000, 2, 29));
    }

    #[test]
    fn a_replacement_round_trips_with_its_header() {
        let root = crate::workspace::workspace_root();
        let text = std::fs::read_to_string(root.join(TARGETS[1].log)).unwrap_or_default();
        let found = StoredLog::parse(&text).unwrap_or_else(|e| panic!("{e}"));
        let cost = |iterations| admission_search::Cost {
            iterations,
            command: 30,
            refresh: false,
        };
        let log = replacement(&found, "1-2", "2026-12-06", cost(1995), cost(1990));
        let back = StoredLog::parse(&log.render()).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(back, log);
        assert_eq!(back.commands, found.commands);
        assert_eq!(back.duration_ms, found.duration_ms);
        assert_eq!(back.header.len(), found.header.len() + 1);
        assert!(back.header.last().is_some_and(|l| l.starts_with(
            "Stored by `cargo xtask admission-search --revision 1-2 --write` on 2026-12-06: 1995 iterations at command 31"
        ) && l.ends_with("above the stored sequence's 1990 iterations.")));
    }

    #[test]
    fn the_targets_logs_parse() {
        let root = crate::workspace::workspace_root();
        for target in &TARGETS {
            let text = std::fs::read_to_string(root.join(target.log)).unwrap_or_default();
            assert!(StoredLog::parse(&text).is_ok(), "{}", target.log);
        }
    }
}
