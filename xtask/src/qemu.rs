//! Runs a firmware's QEMU build in deterministic virtual time against a stimulus log.
//!
//! The stimulus is a `candump -l` log whose timestamps count from the start of the run. It is
//! converted into fixed 20-byte records (`u64` µs, `u16` ID, `u8` length, `u8` flags, 8 data bytes)
//! after a 16-byte header (`AMSTIM1\0`, `u64` duration in µs) that the firmware reads through
//! semihosting. The firmware prints every frame it would put on the bus in the same log format,
//! stamped with virtual time, and its trace events as lines starting with `#`.
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};

/// `-icount shift=3`: one instruction per 8 virtual nanoseconds (125 MIPS, within 2× of a 72 MHz
/// F103), deterministic; the QEMU build's SysTick ticks every 10 µs so its interrupt costs little.
pub const ICOUNT_SHIFT: u32 = 3;

/// The pseudo-identifier of a SYS_PD_N shutdown request in a stimulus.
pub const SIGNAL_SYS_PD_N: u32 = u32::MAX;

/// One timed frame of a stimulus.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TimedFrame {
    /// Microseconds from the start of the run.
    pub at_us: u64,
    /// Identifier (11-bit, or larger for an extended frame the board must ignore).
    pub id: u32,
    /// Payload (up to 8 bytes; longer payloads are kept to test the board's rejection).
    pub data: Vec<u8>,
}

/// Parses a `candump -l` line: `(seconds.micros) iface ID#DATA`. Blank lines and `#` comments give `None`.
pub fn parse_log_line(line: &str) -> Result<Option<TimedFrame>> {
    let line = line.trim();
    if line.is_empty() || line.starts_with('#') {
        return Ok(None);
    }
    let rest = line
        .strip_prefix('(')
        .with_context(|| format!("`{line}`: expected `(seconds.micros)`"))?;
    let (stamp, rest) = rest
        .split_once(')')
        .with_context(|| format!("`{line}`: unclosed timestamp"))?;
    let (secs, micros) = stamp
        .split_once('.')
        .with_context(|| format!("`{line}`: timestamp needs a fraction"))?;
    let secs: u64 = secs
        .trim()
        .parse()
        .with_context(|| format!("`{line}`: bad seconds"))?;
    if micros.len() != 6 {
        bail!("`{line}`: the fraction must have six digits (microseconds)");
    }
    let micros: u64 = micros
        .parse()
        .with_context(|| format!("`{line}`: bad microseconds"))?;
    let mut fields = rest.split_whitespace();
    let iface = fields
        .next()
        .with_context(|| format!("`{line}`: missing interface"))?;
    let frame = fields
        .next()
        .with_context(|| format!("`{line}`: missing frame"))?;
    let at_us = secs
        .checked_mul(1_000_000)
        .and_then(|us| us.checked_add(micros))
        .with_context(|| format!("`{line}`: timestamp beyond u64 microseconds"))?;
    // Not a frame: a system signal for the board (`(t) signal SYS_PD_N`), stimulus only.
    if iface == "signal" {
        if frame != "SYS_PD_N" {
            bail!("`{line}`: the only signal is SYS_PD_N (a shutdown request)");
        }
        return Ok(Some(TimedFrame {
            at_us,
            id: SIGNAL_SYS_PD_N,
            data: Vec::new(),
        }));
    }
    let (id, data) = frame
        .split_once('#')
        .with_context(|| format!("`{line}`: frame needs `ID#DATA`"))?;
    let id = u32::from_str_radix(id, 16).with_context(|| format!("`{line}`: bad ID"))?;
    if !data.is_ascii() {
        bail!("`{line}`: identifier and data must be hex digits");
    }
    if data.len() % 2 != 0 {
        bail!("`{line}`: odd number of hex digits in data");
    }
    let data = (0..data.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&data[i..i + 2], 16))
        .collect::<Result<Vec<u8>, _>>()
        .with_context(|| format!("`{line}`: bad data"))?;
    if data.len() > 8 {
        bail!("`{line}`: a CAN frame carries at most 8 bytes");
    }
    Ok(Some(TimedFrame { at_us, id, data }))
}

/// Encodes a stimulus for the firmware.
pub fn encode_stimulus(frames: &[TimedFrame], duration_us: u64) -> Vec<u8> {
    let mut out = Vec::with_capacity(16 + 20 * frames.len());
    out.extend_from_slice(b"AMSTIM1\0");
    out.extend_from_slice(&duration_us.to_le_bytes());
    for f in frames {
        out.extend_from_slice(&f.at_us.to_le_bytes());
        // Flags: bit 0 = a frame the protocol cannot carry (extended ID), bit 1 = SYS_PD_N falls.
        let (id, flags) = if f.id == SIGNAL_SYS_PD_N {
            (0xFFFF, 2u8)
        } else if f.id <= 0x7FF {
            (f.id as u16, 0u8)
        } else {
            (0xFFFF, 1u8)
        };
        out.extend_from_slice(&id.to_le_bytes());
        out.push(f.data.len().min(255) as u8);
        out.push(flags);
        let mut data = [0u8; 8];
        let n = f.data.len().min(8);
        data[..n].copy_from_slice(&f.data[..n]);
        out.extend_from_slice(&data);
    }
    out
}

/// The shortest time between two received frames a stimulus replays (records after its duration are not
/// replayed, a SYS_PD_N record is no frame), µs; the whole duration (at least 1 µs) when it has fewer than two.
/// An encoded stimulus that is cut or has no header is an error.
pub fn received_gap_us(encoded: &[u8]) -> Result<u64> {
    let (header, records) = encoded
        .split_at_checked(16)
        .filter(|(h, _)| &h[..8] == b"AMSTIM1\0")
        .context("no AMSTIM1 header")?;
    let mut duration = [0u8; 8];
    duration.copy_from_slice(&header[8..16]);
    let duration = u64::from_le_bytes(duration);
    if records.len() % 20 != 0 {
        bail!(
            "{} bytes of records: not whole 20-byte records",
            records.len()
        );
    }
    let mut times: Vec<u64> = records
        .chunks_exact(20)
        .filter(|r| r[11] & 2 == 0)
        .map(|r| {
            let mut at = [0u8; 8];
            at.copy_from_slice(&r[..8]);
            u64::from_le_bytes(at)
        })
        .filter(|&at| at <= duration)
        .collect();
    times.sort_unstable();
    Ok(times
        .windows(2)
        .map(|w| w[1] - w[0])
        .min()
        .unwrap_or(duration.max(1)))
}

/// Parses a duration like `2s`, `1500ms` or `900us`.
pub fn parse_duration(text: &str) -> Result<u64> {
    let (digits, scale) = if let Some(d) = text.strip_suffix("us") {
        (d, 1)
    } else if let Some(d) = text.strip_suffix("ms") {
        (d, 1_000)
    } else if let Some(d) = text.strip_suffix('s') {
        (d, 1_000_000)
    } else {
        bail!("duration `{text}` needs a unit: us, ms or s")
    };
    let value: u64 = digits
        .parse()
        .with_context(|| format!("bad duration `{text}`"))?;
    value
        .checked_mul(scale)
        .with_context(|| format!("duration `{text}` too long"))
}

/// Reads a stimulus log file.
pub fn read_stimulus(path: &Path) -> Result<Vec<TimedFrame>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut frames = Vec::new();
    for (n, line) in text.lines().enumerate() {
        if let Some(f) =
            parse_log_line(line).with_context(|| format!("{}:{}", path.display(), n + 1))?
        {
            frames.push(f);
        }
    }
    frames.sort_by_key(|f| f.at_us);
    Ok(frames)
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

/// The run's output with the text line of every handler event (`# (t) trace sample-taken …`) in
/// front of the binary record the board printed for it (`# T …`, kept: the bench reads it).
pub fn with_event_lines(text: &str) -> String {
    let mut out = String::with_capacity(text.len() * 2);
    for line in text.lines() {
        if line.starts_with("# T ") {
            for record in amiro_trace::records(&crate::bench::capture::console_record_bytes(line)) {
                if let amiro_trace::Kind::Event { record } = record.kind {
                    if let Ok(event) = amiro_sensors::trace::TraceEvent::decode(&record) {
                        out.push_str(&format!("# {event}\n"));
                    }
                }
            }
        }
        out.push_str(line);
        out.push('\n');
    }
    out
}

/// The last `n` lines of `text`.
fn tail(text: &str, n: usize) -> String {
    let lines: Vec<&str> = text.lines().collect();
    let from = lines.len().saturating_sub(n);
    lines[from..].iter().map(|l| format!("  {l}\n")).collect()
}

/// Splits a run's output into the bus (frame lines: a plain `candump -l` log) and the rest
/// (trace and log lines).
pub fn split_output(text: &str) -> (String, String) {
    let mut bus = String::new();
    let mut trace = String::new();
    for line in text.lines() {
        let target = if line.starts_with('(') {
            &mut bus
        } else {
            &mut trace
        };
        target.push_str(line);
        target.push('\n');
    }
    (bus, trace)
}

/// A work directory of its own for one `cargo xtask qemu` run (two runs at once never share one).
pub fn fresh_work_dir(root: &Path, board: &str) -> PathBuf {
    let stamp = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos())
        .unwrap_or_default();
    let runs = target_dir(root).join("runs");
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

/// Where QEMU builds go, apart from the real-hardware builds.
pub fn target_dir(root: &Path) -> PathBuf {
    crate::target_dir(root).join("qemu")
}

#[cfg(test)]
mod tests {
    use super::*;

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

    #[test]
    fn parses_candump_lines() {
        let f = parse_log_line("(0.010000) can0 205#01840302")
            .unwrap()
            .unwrap();
        assert_eq!(
            f,
            TimedFrame {
                at_us: 10_000,
                id: 0x205,
                data: vec![1, 0x84, 3, 2]
            }
        );
        assert_eq!(parse_log_line("# comment").unwrap(), None);
        assert_eq!(
            parse_log_line("(1.000001) can0 7FF#")
                .unwrap()
                .unwrap()
                .at_us,
            1_000_001
        );
        assert!(parse_log_line("(0.01) can0 205#01").is_err());
        assert!(parse_log_line("205#01").is_err());
        assert!(parse_log_line("(0.000000) can0 205#0").is_err());
        // Hostile input is an error, never a panic.
        assert!(parse_log_line("(18446744073710.000000) can0 205#01").is_err());
        assert!(parse_log_line("(0.000001) can0 205#é1").is_err());
        assert!(parse_log_line("(0.000001) can0 2é#01").is_err());
    }

    #[test]
    fn encodes_records() {
        let frames = vec![
            TimedFrame {
                at_us: 5,
                id: 0x205,
                data: vec![1, 2],
            },
            TimedFrame {
                at_us: 6,
                id: 0x1234_5678,
                data: vec![],
            },
        ];
        let bin = encode_stimulus(&frames, 2_000_000);
        assert_eq!(bin.len(), 16 + 40);
        assert_eq!(&bin[..8], b"AMSTIM1\0");
        assert_eq!(
            u64::from_le_bytes(bin[8..16].try_into().unwrap()),
            2_000_000
        );
        assert_eq!(
            &bin[16..30],
            &[5, 0, 0, 0, 0, 0, 0, 0, 0x05, 0x02, 2, 0, 1, 2]
        );
        assert_eq!(&bin[44..48], &[0xFF, 0xFF, 0, 1]);
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
    fn durations() {
        assert_eq!(parse_duration("2s").unwrap(), 2_000_000);
        assert_eq!(parse_duration("1500ms").unwrap(), 1_500_000);
        assert_eq!(parse_duration("900us").unwrap(), 900);
        assert!(parse_duration("2").is_err());
    }
}
