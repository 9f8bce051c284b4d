//! Runs a firmware's QEMU build in deterministic virtual time against a stimulus log.
//!
//! The stimulus is a `candump -l` log whose timestamps count from the start of the run. It is
//! converted into `amiro_trace::stimulus`'s records (fixed 20 bytes after a 16-byte header) that
//! the firmware reads through semihosting with the same crate's decoder. The firmware prints every frame it would put on the bus in the same log format,
//! stamped with virtual time, and its trace events as lines starting with `#`.
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{bail, ensure, Context, Result};

pub use amiro_robot::log::{
    duration_of, encode_stimulus, parse_duration, parse_log_line, read_stimulus, split_output,
    with_event_lines, TimedFrame, ICOUNT_SHIFT, SIGNAL_SYS_PD_N,
};

/// The shortest time between two received frames a stimulus replays (records after its duration are not
/// replayed, a SYS_PD_N record is no frame), µs; the whole duration (at least 1 µs) when it has fewer than two.
/// An encoded stimulus that is cut or has no header is an error.
pub fn received_gap_us(encoded: &[u8]) -> Result<u64> {
    use amiro_trace::stimulus::{decode, Event};
    let (duration, records) = decode(encoded).map_err(|e| anyhow::anyhow!("stimulus: {e}"))?;
    let mut times = Vec::new();
    for record in records {
        let record = record.map_err(|e| anyhow::anyhow!("stimulus: {e}"))?;
        if matches!(record.event, Event::Frame { .. }) && record.at_us <= duration {
            times.push(record.at_us);
        }
    }
    times.sort_unstable();
    Ok(times
        .windows(2)
        .map(|w| w[1] - w[0])
        .min()
        .unwrap_or(duration.max(1)))
}

/// How many single-board QEMU runs go at once: one per core (each run is one emulator thread; the runs are in
/// virtual time, so their outputs do not depend on it), or `AMIRO_QEMU_JOBS` (1: one after the other).
pub fn parallel_runs() -> usize {
    std::env::var("AMIRO_QEMU_JOBS")
        .ok()
        .and_then(|n| n.trim().parse::<usize>().ok())
        .filter(|&n| n > 0)
        .unwrap_or_else(|| {
            std::thread::available_parallelism()
                .map(|n| n.get())
                .unwrap_or(1)
        })
}

/// `run(item)` for every item, at most [`parallel_runs`] at a time; the results in the items' order (the
/// caller checks and prints them in that order, as if they had run one after the other).
pub fn run_each<I: Sync, T: Send>(items: &[I], run: impl Fn(&I) -> T + Sync) -> Result<Vec<T>> {
    run_on(parallel_runs(), items, run)
}

/// [`run_each`] on at most `workers` threads.
fn run_on<I: Sync, T: Send>(
    workers: usize,
    items: &[I],
    run: impl Fn(&I) -> T + Sync,
) -> Result<Vec<T>> {
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::sync::Mutex;
    let workers = workers.min(items.len());
    if workers <= 1 {
        return Ok(items.iter().map(run).collect());
    }
    let next = AtomicUsize::new(0);
    let results: Vec<Mutex<Option<T>>> = items.iter().map(|_| Mutex::new(None)).collect();
    std::thread::scope(|scope| {
        for _ in 0..workers {
            scope.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                let Some(item) = items.get(i) else { break };
                let result = run(item);
                *results[i].lock().unwrap_or_else(|e| e.into_inner()) = Some(result);
            });
        }
    });
    // Every slot is filled (a worker takes each index once; a panic in `run` ends the scope with it); a run
    // without a result would be a check left out, so it is an error, never a shorter list.
    let results: Vec<T> = results
        .into_iter()
        .filter_map(|slot| slot.into_inner().unwrap_or_else(|e| e.into_inner()))
        .collect();
    ensure!(
        results.len() == items.len(),
        "{} of {} QEMU runs gave no result",
        items.len() - results.len(),
        items.len()
    );
    Ok(results)
}

/// Runs `elf` on QEMU's `machine` with `stimulus` for `duration_us` of virtual time and returns its
/// output. QEMU emulates neither the STM32 clock tree nor bxCAN, so a QEMU build touches only core
/// peripherals: netduino2 (a Cortex-M3 STM32F205) runs the F103 boards, netduinoplus2 (an
/// STM32F405) the power board.
///
/// Everything the firmware prints is also written to `work/output.log` as it arrives, so a run that
/// overruns its wall-clock guard (a hang) or fails keeps and shows what it did up to then.
pub fn run(
    elf: &Path,
    machine: &str,
    stimulus: &[TimedFrame],
    duration_us: u64,
    work: &Path,
) -> Result<String> {
    std::fs::create_dir_all(work)?;
    if stimulus.is_empty() {
        eprintln!("note: the stimulus has no frames: the board only runs for the duration");
    }
    let late = stimulus.iter().filter(|f| f.at_us > duration_us).count();
    if late > 0 {
        eprintln!("note: {late} stimulus frame(s) come after the run's end ({duration_us} µs) and are not sent");
    }
    std::fs::write(
        work.join("stimulus.bin"),
        encode_stimulus(stimulus, duration_us),
    )?;
    let log_path = work.join("output.log");
    let mut child = Command::new("qemu-system-arm")
        .args([
            "-machine",
            machine,
            "-nographic",
            "-monitor",
            "none",
            "-serial",
            "none",
        ])
        .args(["-semihosting-config", "enable=on,target=native"])
        .args([
            "-icount",
            &format!("shift={ICOUNT_SHIFT},align=off,sleep=off"),
        ])
        .arg("-kernel")
        .arg(elf)
        .current_dir(work)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .context("starting qemu-system-arm (install it: apt-get install qemu-system-arm)")?;
    // Drain the output while QEMU runs (a full pipe would stall the guest) into memory and the log
    // file, and guard the wall clock only: the firmware exits by itself after `duration_us` of
    // virtual time.
    let stdout = child.stdout.take().context("QEMU stdout")?;
    let mut stderr = child.stderr.take().context("QEMU stderr")?;
    let mut log = std::fs::File::create(&log_path)
        .with_context(|| format!("creating {}", log_path.display()))?;
    let out_reader = std::thread::spawn(move || {
        use std::io::{BufRead, Write};
        let mut text = String::new();
        for line in std::io::BufReader::new(stdout).lines() {
            let Ok(line) = line else { break };
            let _ = writeln!(log, "{line}");
            text.push_str(&line);
            text.push('\n');
        }
        text
    });
    let err_reader = std::thread::spawn(move || {
        let mut text = String::new();
        let _ = std::io::Read::read_to_string(&mut stderr, &mut text);
        text
    });
    let limit = Duration::from_secs(120 + duration_us / 50_000);
    let started = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait()? {
            break Some(status);
        }
        if started.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            break None;
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let stdout = out_reader.join().unwrap_or_default();
    let stderr = err_reader.join().unwrap_or_default();
    match status {
        None => bail!(
            "QEMU run did not finish within {limit:?} of wall time (a hang?); its output up to then \
             is in {}; last lines:\n{}{stderr}",
            log_path.display(),
            tail(&stdout, 20)
        ),
        Some(status) if !status.success() => bail!(
            "QEMU run failed ({status}); output in {}; last lines:\n{}{stderr}",
            log_path.display(),
            tail(&stdout, 20)
        ),
        Some(_) => Ok(with_event_lines(&stdout)),
    }
}

/// The last `n` lines of `text`.
fn tail(text: &str, n: usize) -> String {
    let lines: Vec<&str> = text.lines().collect();
    let from = lines.len().saturating_sub(n);
    lines[from..].iter().map(|l| format!("  {l}\n")).collect()
}

/// A work directory of its own for one `cargo xtask qemu` run (two runs at once never share one).
pub fn fresh_work_dir(root: &Path, board: &str) -> PathBuf {
    let stamp = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos())
        .unwrap_or_default();
    let runs = crate::workspace::qemu_target_dir(root).join("runs");
    prune_runs(&runs, KEEP_RUNS, std::time::Duration::from_secs(3600));
    runs.join(format!("{board}-{}-{stamp}", std::process::id()))
}

/// Run folders kept under `target/qemu/runs` (the newest; older ones go once an hour old).
const KEEP_RUNS: usize = 20;

/// Removes the run folders in `runs` beyond the `keep` newest that are older than `min_age` (a
/// run another process is still writing is younger than that). Errors only leave folders behind.
fn prune_runs(runs: &Path, keep: usize, min_age: std::time::Duration) {
    let Ok(entries) = std::fs::read_dir(runs) else {
        return;
    };
    let mut dirs: Vec<(std::time::SystemTime, PathBuf)> = entries
        .filter_map(Result::ok)
        .filter_map(|e| {
            let modified = e.metadata().ok()?.modified().ok()?;
            e.file_type().ok()?.is_dir().then(|| (modified, e.path()))
        })
        .collect();
    dirs.sort_by_key(|d| std::cmp::Reverse(d.0));
    let now = std::time::SystemTime::now();
    for (modified, dir) in dirs.into_iter().skip(keep) {
        if now.duration_since(modified).is_ok_and(|age| age >= min_age) {
            let _ = std::fs::remove_dir_all(dir);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn side_by_side_runs_come_back_in_their_order() {
        let items: Vec<u64> = (0..23).collect();
        // Later items finish first: the order must come from the items, not from the finishing.
        let run = |&i: &u64| {
            std::thread::sleep(Duration::from_millis(23 - i));
            i * 3
        };
        let expected: Vec<u64> = items.iter().map(|i| i * 3).collect();
        for workers in [1, 2, 4, 64] {
            assert_eq!(
                run_on(workers, &items, run).unwrap(),
                expected,
                "{workers} workers"
            );
        }
        assert!(run_on(2, &[] as &[u64], run).unwrap().is_empty());
    }

    #[test]
    fn the_shortest_gap_between_received_frames() {
        let frame = |at_us, id| TimedFrame {
            at_us,
            id,
            data: vec![],
        };
        let frames = [
            frame(5, 0x205),
            frame(100, 0x205),
            frame(130, 0x9999),          // an extended frame reaches the FIFO too
            frame(131, SIGNAL_SYS_PD_N), // no frame
            frame(2_000_001, 0x205),     // after the run
        ];
        assert_eq!(
            received_gap_us(&encode_stimulus(&frames, 2_000_000)).unwrap(),
            30
        );
        // Fewer than two frames: the whole run.
        assert_eq!(
            received_gap_us(&encode_stimulus(&frames[..1], 200_000)).unwrap(),
            200_000
        );
        let bin = encode_stimulus(&frames, 2_000_000);
        assert!(received_gap_us(&bin[..bin.len() - 1]).is_err());
        assert!(received_gap_us(b"AMSTIM").is_err());
    }

    #[test]
    fn old_runs_beyond_the_newest_are_pruned() {
        let runs = std::env::temp_dir().join(format!("amiro-prune-{}", std::process::id()));
        for k in 0..5 {
            std::fs::create_dir_all(runs.join(format!("run-{k}"))).unwrap();
        }
        // Young runs stay whatever their number.
        prune_runs(&runs, 2, std::time::Duration::from_secs(3600));
        assert_eq!(std::fs::read_dir(&runs).unwrap().count(), 5);
        prune_runs(&runs, 2, std::time::Duration::ZERO);
        assert_eq!(std::fs::read_dir(&runs).unwrap().count(), 2);
        std::fs::remove_dir_all(&runs).unwrap();
    }
}
