//! The `file:` bus: `candump -l` log files, appended to by `send` and replayed by `monitor`.
//!
//! This is the transport that works on any machine: record on the robot with `candump -l can0`, study the run at a
//! desk with `amiro monitor --bus file:candump.log --realtime`, or prepare frames with `send` and play them back
//! onto a real bus with can-utils' `canplayer`.

use std::fs::{File, OpenOptions};
use std::io::{BufReader, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context, Result};

use super::{interrupted, Bus, Reception};
use crate::frame::{parse_line, text_lines, LoggedFrame, NumberedLine, RawFrame, Timestamp};

/// Interface name written into log lines, so that `canplayer` can map it (`canplayer can0=vcan0 ...`).
const LOG_INTERFACE: &str = "can0";

/// Appends sent frames to a log file.
pub struct LogWriter {
    path: PathBuf,
    file: File,
}

impl LogWriter {
    /// Opens (creating if needed) the log for appending: sending never destroys an earlier recording.
    pub fn open(path: &Path) -> Result<Self> {
        let file = OpenOptions::new()
            .create(true)
            .append(true)
            .open(path)
            .with_context(|| format!("cannot open {} for writing", path.display()))?;
        Ok(Self {
            path: path.to_path_buf(),
            file,
        })
    }
}

impl Bus for LogWriter {
    fn send(&mut self, frame: &RawFrame) -> Result<()> {
        let logged = LoggedFrame {
            timestamp: Some(Timestamp::now()),
            interface: Some(LOG_INTERFACE.into()),
            frame: *frame,
        };
        writeln!(self.file, "{}", logged.to_log_line())
            .and_then(|()| self.file.flush())
            .with_context(|| format!("cannot write to {}", self.path.display()))
    }

    fn receive(&mut self, _timeout: Option<Duration>) -> Result<Reception> {
        anyhow::bail!(
            "{} was opened for sending, not for monitoring",
            self.path.display()
        )
    }
}

/// Reads frames from a log file, optionally at the pace they were recorded.
pub struct LogReader {
    path: PathBuf,
    lines: Box<dyn Iterator<Item = NumberedLine>>,
    realtime: bool,
    /// The first frame's timestamp and the moment it was handed out: the origin of realtime pacing.
    pace_origin: Option<(Timestamp, Instant)>,
    /// A frame read ahead whose time has not come yet (a realtime wait that timed out).
    waiting: Option<LoggedFrame>,
}

impl LogReader {
    /// Opens a log for reading.
    pub fn open(path: &Path, realtime: bool) -> Result<Self> {
        let file = File::open(path).with_context(|| format!("cannot open {}", path.display()))?;
        Ok(Self {
            path: path.to_path_buf(),
            lines: Box::new(text_lines(BufReader::new(file))),
            realtime,
            pace_origin: None,
            waiting: None,
        })
    }

    /// The next frame in the file; lines that are not frames are reported on stderr and skipped.
    fn next_frame(&mut self) -> Result<Option<LoggedFrame>> {
        for line in self.lines.by_ref() {
            let (number, line) =
                line.with_context(|| format!("cannot read {}", self.path.display()))?;
            match line.and_then(|line| parse_line(&line)) {
                Ok(Some(frame)) => return Ok(Some(frame)),
                Ok(None) => {}
                Err(error) => eprintln!("warning: {}:{number}: {error}", self.path.display()),
            }
        }
        Ok(None)
    }

    /// When a frame is due under realtime pacing.
    fn due(&mut self, frame: &LoggedFrame) -> Option<Instant> {
        if !self.realtime {
            return None;
        }
        let timestamp = frame.timestamp?;
        let (first, started) = *self.pace_origin.get_or_insert((timestamp, Instant::now()));
        // A timestamp going backwards (a concatenated log) is played at once rather than waited for.
        let offset = timestamp.as_micros().saturating_sub(first.as_micros());
        Some(started + Duration::from_micros(offset))
    }
}

impl Bus for LogReader {
    fn send(&mut self, _frame: &RawFrame) -> Result<()> {
        anyhow::bail!(
            "{} was opened for monitoring, not for sending",
            self.path.display()
        )
    }

    fn receive(&mut self, timeout: Option<Duration>) -> Result<Reception> {
        let frame = match self.waiting.take() {
            Some(frame) => frame,
            None => match self.next_frame()? {
                Some(frame) => frame,
                None => return Ok(Reception::Ended),
            },
        };
        let Some(due) = self.due(&frame) else {
            return Ok(Reception::Frame(frame));
        };
        let give_up = timeout.map(|timeout| Instant::now() + timeout);
        loop {
            if interrupted() {
                return Ok(Reception::Interrupted);
            }
            let now = Instant::now();
            if now >= due {
                return Ok(Reception::Frame(frame));
            }
            if give_up.is_some_and(|give_up| now >= give_up) {
                self.waiting = Some(frame);
                return Ok(Reception::TimedOut);
            }
            // Short naps keep Ctrl-C and the timeout responsive during long gaps in a recording.
            let next_wake = give_up.map_or(due, |give_up| due.min(give_up));
            std::thread::sleep((next_wake - now).min(Duration::from_millis(50)));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::parse_compact;

    #[test]
    fn sent_frames_are_appended_as_candump_lines_and_read_back() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bus.log");
        std::fs::write(&path, "(1700000000.000000) can0 608#FCFF02000000\n").unwrap();
        let mut writer = LogWriter::open(&path).unwrap();
        writer
            .send(&parse_compact("205#01840302").unwrap())
            .unwrap();
        drop(writer);
        let text = std::fs::read_to_string(&path).unwrap();
        let last = text.lines().last().unwrap();
        assert!(
            last.starts_with('(') && last.ends_with(") can0 205#01840302"),
            "{last}"
        );

        let mut reader = LogReader::open(&path, false).unwrap();
        let mut frames = Vec::new();
        while let Reception::Frame(frame) = reader.receive(None).unwrap() {
            frames.push(frame.frame.to_string());
        }
        assert_eq!(frames, ["608#FCFF02000000", "205#01840302"]);
    }

    #[test]
    fn realtime_replay_keeps_the_recorded_gaps() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("paced.log");
        std::fs::write(&path, "(10.000000) can0 205#00\n(10.200000) can0 205#02\n").unwrap();
        let mut reader = LogReader::open(&path, true).unwrap();
        let start = Instant::now();
        assert!(matches!(reader.receive(None).unwrap(), Reception::Frame(_)));
        // The second frame is 200 ms later: a 50 ms wait times out and keeps it for the next call.
        assert!(matches!(
            reader.receive(Some(Duration::from_millis(50))).unwrap(),
            Reception::TimedOut
        ));
        assert!(matches!(reader.receive(None).unwrap(), Reception::Frame(_)));
        assert!(start.elapsed() >= Duration::from_millis(200));
        assert!(matches!(reader.receive(None).unwrap(), Reception::Ended));
    }
}
