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

/// A run's `output.log` (every line) and `bus.log` (its frame lines, a plain `candump -l` log),
/// written as the lines come: the same bytes as [`split_output`] of the whole, with nothing kept.
/// Buffered; with a flush period (a live run's), flushed at a line once that long has passed since
/// the last flush, so that a reader following the files lags at most about that much behind a run
/// that prints.
pub struct RunFiles {
    output: std::io::BufWriter<std::fs::File>,
    bus: std::io::BufWriter<std::fs::File>,
    flush_every: Option<std::time::Duration>,
    flushed: std::time::Instant,
    /// The first write that failed (a [`crate::Sink`] cannot fail; [`RunFiles::finish`] says it).
    error: Option<std::io::Error>,
}

impl RunFiles {
    /// Creates `output.log` and `bus.log` in `dir`.
    pub fn create(dir: &Path, flush_every: Option<std::time::Duration>) -> Result<Self> {
        let open = |name: &str| -> Result<_> {
            let path = dir.join(name);
            let file = std::fs::File::create(&path)
                .with_context(|| format!("creating {}", path.display()))?;
            Ok(std::io::BufWriter::with_capacity(1 << 16, file))
        };
        Ok(Self {
            output: open("output.log")?,
            bus: open("bus.log")?,
            flush_every,
            flushed: std::time::Instant::now(),
            error: None,
        })
    }

    fn write(&mut self, line: &str) -> std::io::Result<()> {
        use std::io::Write;
        writeln!(self.output, "{line}")?;
        if line.contains(['\n', '\r']) {
            // As `split_output` splits the whole (`str::lines` drops a line's trailing `\r`).
            for part in format!("{line}\n").lines().filter(|l| is_frame_line(l)) {
                writeln!(self.bus, "{part}")?;
            }
        } else if is_frame_line(line) {
            writeln!(self.bus, "{line}")?;
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

    /// Flushes both files; the first write that failed, if one did.
    pub fn finish(mut self) -> Result<()> {
        use std::io::Write;
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
        let mut files = RunFiles::create(&dir, Some(std::time::Duration::ZERO)).unwrap();
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
}
