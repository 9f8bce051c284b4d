//! The text the robot and the single-board runner share: `candump -l` lines (the stimulus and the
//! bus log), durations, the single-board stimulus's records, and the boards' console (`# T` trace
//! records, each handler event's text line in front of its record).
use std::path::Path;

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

/// Parses a `candump -l` line `(seconds.micros) iface ID#DATA` (`amiro_can::candump`'s decoder), or
/// a stimulus's `(seconds.micros) signal SYS_PD_N`. Blank lines and `#` comments give `None`.
pub fn parse_log_line(line: &str) -> Result<Option<TimedFrame>> {
    use amiro_can::candump;
    let fail = |e: candump::CandumpError<'_>| anyhow::anyhow!("`{}`: {e}", line.trim());
    let mut fields = line.split_whitespace();
    // Not a frame: a system signal for the board (`(t) signal SYS_PD_N`), stimulus only.
    if let (Some(stamp), Some("signal")) = (fields.next(), fields.next()) {
        if fields.next() != Some("SYS_PD_N") || fields.next().is_some() {
            bail!(
                "`{}`: the only signal is SYS_PD_N (a shutdown request)",
                line.trim()
            );
        }
        return Ok(Some(TimedFrame {
            at_us: micros_of(candump::parse_timestamp(stamp).map_err(fail)?, line)?,
            id: SIGNAL_SYS_PD_N,
            data: Vec::new(),
        }));
    }
    let Some(logged) = candump::parse_log_line(line).map_err(fail)? else {
        return Ok(None);
    };
    if logged.frame.is_remote() {
        bail!(
            "`{}`: a stimulus carries data frames, not remote frames",
            line.trim()
        );
    }
    Ok(Some(TimedFrame {
        at_us: micros_of(logged.timestamp, line)?,
        id: logged.frame.id().raw(),
        data: logged.frame.data().to_vec(),
    }))
}

/// A log line's timestamp in µs; beyond a `u64` count is an error.
pub fn micros_of(stamp: amiro_can::candump::Timestamp, line: &str) -> Result<u64> {
    stamp
        .checked_micros()
        .with_context(|| format!("`{}`: timestamp beyond u64 microseconds", line.trim()))
}

/// Encodes a stimulus for the firmware (`amiro_trace::stimulus`'s header and records).
pub fn encode_stimulus(frames: &[TimedFrame], duration_us: u64) -> Vec<u8> {
    use amiro_trace::stimulus::{encode_header, Event, Record};
    let mut out = encode_header(duration_us).to_vec();
    for f in frames {
        let event = if f.id == SIGNAL_SYS_PD_N {
            Event::ShutdownRequest
        } else {
            Event::frame(f.id, &f.data)
        };
        out.extend_from_slice(
            &Record {
                at_us: f.at_us,
                event,
            }
            .encode(),
        );
    }
    out
}

/// Parses a duration like `2s`, `1500ms`, `900us` or `1.5s` into µs (`amiro_can::duration`'s decoder,
/// the operator tool's too).
pub fn parse_duration(text: &str) -> Result<u64> {
    amiro_can::duration::parse(text)
        .map(|(micros, _)| micros)
        .map_err(|e| anyhow::anyhow!("duration: {e}"))
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

/// The run's output with the text line of every handler event (`# (t) trace sample-taken …`) in
/// front of the binary record the board printed for it (`# T …`, kept: the bench reads it).
pub fn with_event_lines(text: &str) -> String {
    let mut out = String::with_capacity(text.len() * 2);
    for line in text.lines() {
        if line.starts_with("# T ") {
            for record in amiro_trace::records(&console_record_bytes(line)) {
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

/// The bytes of the `# T` lines (binary records printed in hex) of a QEMU console, each record
/// followed by its delimiter; other lines are left out.
pub fn console_record_bytes(text: &str) -> Vec<u8> {
    let mut out = Vec::new();
    for line in text.lines() {
        let Some(hex) = line.trim().strip_prefix("# T ") else {
            continue;
        };
        for pair in hex.trim().as_bytes().chunks(2) {
            // A damaged line decodes to whatever it decodes to; the reader rejects the record.
            let byte = std::str::from_utf8(pair)
                .ok()
                .and_then(|p| u8::from_str_radix(p, 16).ok())
                .unwrap_or(0);
            out.push(byte);
        }
        out.push(0);
    }
    out
}

/// Splits a run's output into the bus (frame lines: a plain `candump -l` log) and the rest
/// (trace and log lines).
pub fn split_output(text: &str) -> (String, String) {
    let mut bus = String::new();
    let mut trace = String::new();
    for line in text.lines() {
        let target = if is_frame_line(line) {
            &mut bus
        } else {
            &mut trace
        };
        target.push_str(line);
        target.push('\n');
    }
    (bus, trace)
}

/// Whether an output line is a bus frame (a `candump -l` line): the bus log's lines.
fn is_frame_line(line: &str) -> bool {
    line.starts_with('(')
}

/// Where a run's log files stop growing: each named file rotated at a size, or kept whole (`None`,
/// a run in virtual time: its length bounds it and the scenarios read its files whole).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LogBounds {
    /// `output.log` (every line the run printed).
    pub output: Option<u64>,
    /// `bus.log` (the `candump -l` recording).
    pub bus: Option<u64>,
}

/// A live run's `output.log` is rotated at 64 MiB: the run prints about 530 KB a second with the
/// thesis load (1.9 GB an hour), and a run left at the bench for hours must not fill the disk.
pub const LIVE_OUTPUT_LOG_MAX: u64 = 64 << 20;

/// One log file, whole or rotated: once the next line would take it beyond `rotate_at` bytes it
/// becomes `NAME.1` (replacing the previous one) and a new `NAME` starts, so the newest lines are
/// always in `NAME`, the ones before them in `NAME.1`, and the two together hold at most twice the
/// size. A line (with its newline) goes whole into one file: a single line longer than the size
/// gets a file of its own.
struct LogFile {
    path: std::path::PathBuf,
    out: std::io::BufWriter<std::fs::File>,
    /// Bytes in the current file.
    size: u64,
    rotate_at: Option<u64>,
    /// Bytes written over the run, all files.
    written: u64,
    rotations: u64,
    /// Set at the first rotation, taken once by [`RunFiles::take_rotation_notes`].
    note: Option<String>,
}

impl LogFile {
    fn create(path: std::path::PathBuf, rotate_at: Option<u64>) -> Result<Self> {
        let out = Self::open(&path)?;
        Ok(Self {
            path,
            out,
            size: 0,
            rotate_at,
            written: 0,
            rotations: 0,
            note: None,
        })
    }

    fn open(path: &Path) -> Result<std::io::BufWriter<std::fs::File>> {
        let file =
            std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?;
        Ok(std::io::BufWriter::with_capacity(1 << 16, file))
    }

    /// The previous file's path (`NAME.1`).
    fn previous(&self) -> std::path::PathBuf {
        let mut name = self.path.as_os_str().to_owned();
        name.push(".1");
        name.into()
    }

    /// Writes `line` and its newline, rotating first if it would take the file beyond its size.
    fn line(&mut self, line: &str) -> std::io::Result<()> {
        use std::io::Write;
        let bytes = line.len() as u64 + 1;
        if let Some(max) = self.rotate_at {
            if self.size > 0 && self.size + bytes > max {
                self.rotate(max)?;
            }
        }
        self.out.write_all(line.as_bytes())?;
        self.out.write_all(b"\n")?;
        self.size += bytes;
        self.written += bytes;
        Ok(())
    }

    fn rotate(&mut self, max: u64) -> std::io::Result<()> {
        use std::io::Write;
        self.out.flush()?;
        let previous = self.previous();
        std::fs::rename(&self.path, &previous)?;
        self.out = std::io::BufWriter::with_capacity(1 << 16, std::fs::File::create(&self.path)?);
        self.size = 0;
        self.rotations += 1;
        if self.rotations == 1 {
            let (name, size) = (file_name(&self.path), size_text(max));
            self.note = Some(format!(
                "{name} reached {size}: rotated, its older lines in {} (replaced at every further {size}), the newest in {name}; the two hold at most {}",
                file_name(&previous),
                size_text(2 * max)
            ));
        }
        Ok(())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        std::io::Write::flush(&mut self.out)
    }

    /// What the file took over the run, if it was rotated.
    fn summary(&self) -> Option<String> {
        (self.rotations > 0).then(|| {
            format!(
                "{}: {} written, rotated {} time(s), the newest {} kept (with {})",
                file_name(&self.path),
                size_text(self.written),
                self.rotations,
                size_text(self.size + std::fs::metadata(self.previous()).map_or(0, |m| m.len())),
                file_name(&self.previous())
            )
        })
    }
}

fn file_name(path: &Path) -> String {
    path.file_name().map_or_else(
        || path.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    )
}

/// A size as people read it: `64 MiB`, `1.5 GiB`, `512 B`.
pub fn size_text(bytes: u64) -> String {
    const UNITS: [(&str, u64); 3] = [("GiB", 1 << 30), ("MiB", 1 << 20), ("KiB", 1 << 10)];
    for (unit, scale) in UNITS {
        if bytes >= scale {
            let value = bytes as f64 / scale as f64;
            return if bytes.is_multiple_of(scale) {
                format!("{} {unit}", bytes / scale)
            } else {
                format!("{value:.1} {unit}")
            };
        }
    }
    format!("{bytes} B")
}

/// Parses a size like `64MiB`, `500MB`, `1GiB`, `4096` (bytes): binary units `KiB`, `MiB`, `GiB`,
/// decimal `kB`/`KB`, `MB`, `GB`, `B`; a space before the unit is allowed, a fraction is not.
pub fn parse_size(text: &str) -> Result<u64> {
    let text = text.trim();
    let digits = text
        .find(|c: char| !c.is_ascii_digit())
        .unwrap_or(text.len());
    let (number, unit) = text.split_at(digits);
    let number: u64 = number
        .parse()
        .with_context(|| format!("size `{text}`: a whole number, then a unit (e.g. 64MiB)"))?;
    let scale: u64 = match unit.trim() {
        "" | "B" => 1,
        "KiB" => 1 << 10,
        "MiB" => 1 << 20,
        "GiB" => 1 << 30,
        "kB" | "KB" => 1_000,
        "MB" => 1_000_000,
        "GB" => 1_000_000_000,
        other => bail!("size `{text}`: unknown unit `{other}` (B, KiB, MiB, GiB, kB, MB, GB)"),
    };
    number
        .checked_mul(scale)
        .with_context(|| format!("size `{text}`: too large"))
}

/// A run's `output.log` (every line) and `bus.log` (its frame lines, a plain `candump -l` log),
/// written as the lines come: the same bytes as [`split_output`] of the whole, with nothing kept.
/// Buffered; with a flush period (a live run's), flushed at a line once that long has passed since
/// the last flush, so that a reader following the files lags at most about that much behind a run
/// that prints. With [`LogBounds`] (a live run's), a file is rotated at its size: it and its `.1`
/// hold the newest lines, at most twice the size, never a line split between them.
pub struct RunFiles {
    output: LogFile,
    bus: LogFile,
    flush_every: Option<std::time::Duration>,
    flushed: std::time::Instant,
    /// The first write that failed (a [`crate::Sink`] cannot fail; [`RunFiles::finish`] says it).
    error: Option<std::io::Error>,
}

impl RunFiles {
    /// Creates `output.log` and `bus.log` in `dir`, each rotated at its bound (whole without one).
    pub fn create(
        dir: &Path,
        flush_every: Option<std::time::Duration>,
        bounds: LogBounds,
    ) -> Result<Self> {
        Ok(Self {
            output: LogFile::create(dir.join("output.log"), bounds.output)?,
            bus: LogFile::create(dir.join("bus.log"), bounds.bus)?,
            flush_every,
            flushed: std::time::Instant::now(),
            error: None,
        })
    }

    fn write(&mut self, line: &str) -> std::io::Result<()> {
        self.output.line(line)?;
        if line.contains(['\n', '\r']) {
            // As `split_output` splits the whole (`str::lines` drops a line's trailing `\r`).
            for part in format!("{line}\n").lines().filter(|l| is_frame_line(l)) {
                self.bus.line(part)?;
            }
        } else if is_frame_line(line) {
            self.bus.line(line)?;
        }
        if self
            .flush_every
            .is_some_and(|every| self.flushed.elapsed() >= every)
        {
            self.output.flush()?;
            self.bus.flush()?;
            self.flushed = std::time::Instant::now();
        }
        Ok(())
    }

    /// What a file's first rotation has to say (once per file; `cargo xtask robot` prints it on
    /// stderr): where its older lines are now and how much the two files hold at most.
    pub fn take_rotation_notes(&mut self) -> Vec<String> {
        [self.output.note.take(), self.bus.note.take()]
            .into_iter()
            .flatten()
            .collect()
    }

    /// Per rotated file, what it took over the run and what is kept (for the run's closing lines).
    pub fn rotation_summary(&self) -> Vec<String> {
        [self.output.summary(), self.bus.summary()]
            .into_iter()
            .flatten()
            .collect()
    }

    /// Flushes both files; the first write that failed, if one did.
    pub fn finish(mut self) -> Result<()> {
        if let Some(e) = self.error.take() {
            return Err(e).context("writing the run's output.log and bus.log");
        }
        self.output.flush()?;
        self.bus.flush()?;
        Ok(())
    }
}

impl crate::Sink for RunFiles {
    fn line(&mut self, line: &str) {
        if self.error.is_none() {
            if let Err(e) = self.write(line) {
                // Said at once: the run goes on without its logs, and `finish` returns the error.
                eprintln!(
                    "robot: writing output.log or bus.log failed ({e:#}): the logs stop here"
                );
                self.error = Some(e);
            }
        }
    }
}

/// The `# duration:` header of a stimulus log.
pub fn duration_of(path: &Path) -> Result<u64> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    for line in text.lines() {
        if let Some(d) = line.trim().strip_prefix("# duration:") {
            return parse_duration(d.trim());
        }
    }
    bail!("{} has no `# duration:` header", path.display())
}

#[cfg(test)]
mod tests {
    use super::*;

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
        // A short fraction is a decimal fraction of a second (as python-can reads it).
        assert_eq!(
            parse_log_line("(0.01) can0 205#01").unwrap().unwrap().at_us,
            10_000
        );
        assert!(parse_log_line("205#01").is_err());
        assert!(parse_log_line("(0.000000) can0 205#R").is_err());
        assert!(parse_log_line("(0.000000) signal SYS_SYNC_N").is_err());
        assert_eq!(
            parse_log_line("(0.000002) signal SYS_PD_N")
                .unwrap()
                .unwrap()
                .id,
            SIGNAL_SYS_PD_N
        );
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
                id: SIGNAL_SYS_PD_N,
                data: vec![],
            },
        ];
        let bin = encode_stimulus(&frames, 2_000_000);
        let (duration, records) = amiro_trace::stimulus::decode(&bin).unwrap();
        assert_eq!(duration, 2_000_000);
        let events: Vec<_> = records.map(|r| r.unwrap().event).collect();
        assert_eq!(
            events,
            [
                amiro_trace::stimulus::Event::frame(0x205, &[1, 2]),
                amiro_trace::stimulus::Event::ShutdownRequest
            ]
        );
    }

    #[test]
    fn durations() {
        assert_eq!(parse_duration("2s").unwrap(), 2_000_000);
        assert_eq!(parse_duration("1500ms").unwrap(), 1_500_000);
        assert_eq!(parse_duration("900us").unwrap(), 900);
        assert_eq!(parse_duration("1.5s").unwrap(), 1_500_000);
        assert!(parse_duration("2").is_err());
        assert!(parse_duration("2h").is_err());
    }

    #[test]
    fn run_files_are_the_split_of_the_whole() {
        use crate::Sink;
        let dir =
            std::env::temp_dir().join(format!("amiro-robot-run-files-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let lines = [
            "diwheeldrive: # qemu: start",
            "(0.010082) can0 201#010A0000",
            "bus: # (0.010100) SYS_SYNC_N high (every module released it)",
            "(0.010622) can0 601#0000000000000000\r",
            "powermgmt: odd\r\n(0.011000) can0 605#F0D7FFFF",
            "",
            "(0.012000) can0 708#00",
        ];
        let mut files =
            RunFiles::create(&dir, Some(std::time::Duration::ZERO), LogBounds::default()).unwrap();
        let mut text = String::new();
        for line in lines {
            files.line(line);
            text.push_str(line);
            text.push('\n');
        }
        files.finish().unwrap();
        let output = std::fs::read_to_string(dir.join("output.log")).unwrap();
        let bus = std::fs::read_to_string(dir.join("bus.log")).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
        assert_eq!(output, text);
        assert_eq!(bus, split_output(&text).0);
        assert_eq!(bus.lines().count(), 4);
    }

    /// A long feed like a live run's output: numbered trace lines, frame lines, now and then a
    /// line that holds a newline (a board's line with its frame), lengths from 20 to 200 bytes.
    fn long_feed(lines: usize) -> Vec<String> {
        (0..lines)
            .map(|n| match n % 7 {
                0 => format!("({}.{:06}) can0 605#{:0>12X}", n / 1000, n % 1000, n),
                3 => format!(
                    "powermgmt: # line {n}\n({}.{:06}) can0 61F#{:016X}",
                    n / 1000,
                    n % 1000,
                    n
                ),
                _ => format!("diwheeldrive: # {n} trace {}", "x".repeat(n % 180)),
            })
            .collect()
    }

    /// `NAME.1` then `NAME`, read whole.
    fn kept(dir: &Path, name: &str) -> (String, u64, u64) {
        let older = std::fs::read_to_string(dir.join(format!("{name}.1"))).unwrap_or_default();
        let newest = std::fs::read_to_string(dir.join(name)).unwrap();
        let sizes = (older.len() as u64, newest.len() as u64);
        (older + &newest, sizes.0, sizes.1)
    }

    #[test]
    fn rotated_files_keep_the_newest_lines_whole_within_the_bound() {
        use crate::Sink;
        let dir = std::env::temp_dir().join(format!("amiro-robot-rotation-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let (output_max, bus_max) = (8 * 1024, 3 * 1024);
        let bounds = LogBounds {
            output: Some(output_max),
            bus: Some(bus_max),
        };
        let feed = long_feed(40_000);
        let mut files = RunFiles::create(&dir, Some(std::time::Duration::ZERO), bounds).unwrap();
        let mut whole = String::new();
        let mut notes = Vec::new();
        for (n, line) in feed.iter().enumerate() {
            files.line(line);
            notes.extend(files.take_rotation_notes());
            whole.push_str(line);
            whole.push('\n');
            if n % 997 == 0 {
                // Flushed at every line: what is on disk now stays within the bound.
                for (name, max) in [("output.log", output_max), ("bus.log", bus_max)] {
                    let (_, older, newest) = kept(&dir, name);
                    assert!(
                        older <= max && newest <= max,
                        "{name} at line {n}: {older} + {newest} B"
                    );
                }
            }
        }
        let summary = files.rotation_summary();
        files.finish().unwrap();
        let whole_bus = split_output(&whole).0;
        assert!(
            whole.len() > 100 * output_max as usize,
            "{} B fed",
            whole.len()
        );
        for (name, max, all) in [
            ("output.log", output_max, &whole),
            ("bus.log", bus_max, &whole_bus),
        ] {
            let (text, older, newest) = kept(&dir, name);
            assert!(
                older <= max && newest <= max,
                "{name}: {older} + {newest} B"
            );
            // The newest lines, from a line's start: a suffix of the whole at a line boundary.
            assert!(all.ends_with(&text), "{name} is not the end of the whole");
            let cut = all.len() - text.len();
            assert!(
                cut == 0 || all.as_bytes()[cut - 1] == b'\n',
                "{name} starts mid-line"
            );
            // Nearly the whole bound is used: the older file was full to within a line.
            assert!(older > max - 300, "{name}.1 holds {older} B of {max}");
        }
        // Each file says its first rotation once, and what it took in the end.
        assert_eq!(notes.len(), 2, "{notes:?}");
        assert!(
            notes[0].starts_with("output.log reached 8 KiB"),
            "{}",
            notes[0]
        );
        assert_eq!(summary.len(), 2, "{summary:?}");
        // Without bounds (a run in virtual time) the same feed is kept whole, no `.1`.
        std::fs::remove_dir_all(&dir).unwrap();
        std::fs::create_dir_all(&dir).unwrap();
        let mut files = RunFiles::create(&dir, None, LogBounds::default()).unwrap();
        for line in &feed {
            files.line(line);
        }
        assert!(files.take_rotation_notes().is_empty());
        files.finish().unwrap();
        assert_eq!(
            std::fs::read_to_string(dir.join("output.log")).unwrap(),
            whole
        );
        assert_eq!(
            std::fs::read_to_string(dir.join("bus.log")).unwrap(),
            whole_bus
        );
        assert!(!dir.join("output.log.1").exists() && !dir.join("bus.log.1").exists());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn sizes() {
        assert_eq!(parse_size("64MiB").unwrap(), 64 << 20);
        assert_eq!(parse_size("64 MiB").unwrap(), 64 << 20);
        assert_eq!(parse_size("500MB").unwrap(), 500_000_000);
        assert_eq!(parse_size("1GiB").unwrap(), 1 << 30);
        assert_eq!(parse_size("4096").unwrap(), 4096);
        assert!(parse_size("1.5GiB").is_err());
        assert!(parse_size("64M").is_err());
        assert!(parse_size("MiB").is_err());
        assert!(parse_size("99999999999999GiB").is_err());
        assert_eq!(size_text(64 << 20), "64 MiB");
        assert_eq!(size_text(3 << 29), "1.5 GiB");
        assert_eq!(size_text(512), "512 B");
    }
}
