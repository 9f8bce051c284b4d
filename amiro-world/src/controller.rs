//! The controller protocol: an operator-side program (any language) runs in lock-step with the
//! emulated robot over its stdin and stdout.
//!
//! - The host writes every frame on the bus to the program's stdin as a `candump -l` line with
//!   its virtual time: `(12.345678) can0 41F#0304`.
//! - Every controller period (10 ms by default) it writes `(T) tick` and waits until the program
//!   writes a line `ok`. Every `ID#DATA` line (can-utils' `cansend` form: three hex digits, up to
//!   eight bytes of hex) the program wrote before that `ok` is a frame it sends on the bus at T.
//!   Blank lines are ignored; anything else is an error naming the line.
//! - A program that exits, closes its stdout, stops answering for longer than the timeout (wall
//!   clock), or writes a malformed line ends the run with a [`ControllerError`] that says which.
//!
//! The program's stderr is the host's: that is where a behaviour prints what it thinks.

use std::io::{BufRead, BufReader, BufWriter, Write};
use std::process::{Child, ChildStdin, Command, ExitStatus, Stdio};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::thread;
use std::time::Duration;

/// The default controller period, µs.
pub const DEFAULT_PERIOD_US: u64 = 10_000;
/// How long the host waits for `ok` by default (wall clock): a behaviour doing real work in
/// Python answers in well under a millisecond, a loaded CI machine can stall it for seconds.
pub const DEFAULT_TIMEOUT: Duration = Duration::from_secs(10);

/// A classic CAN frame with an 11-bit identifier.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Frame {
    /// Standard identifier (≤ 0x7FF).
    pub id: u16,
    /// Data length (0..=8).
    pub len: u8,
    /// Data, `len` bytes used.
    pub data: [u8; 8],
}

impl Frame {
    /// A frame; `None` if the identifier is beyond 11 bits or the data beyond 8 bytes.
    pub fn new(id: u16, data: &[u8]) -> Option<Frame> {
        if id > 0x7FF || data.len() > 8 {
            return None;
        }
        let mut bytes = [0u8; 8];
        bytes[..data.len()].copy_from_slice(data);
        Some(Frame {
            id,
            len: data.len() as u8,
            data: bytes,
        })
    }

    /// The data bytes in use.
    pub fn payload(&self) -> &[u8] {
        &self.data[..usize::from(self.len.min(8))]
    }

    /// `ID#DATA`, as can-utils writes it.
    pub fn to_cansend(&self) -> String {
        let data: String = self.payload().iter().map(|b| format!("{b:02X}")).collect();
        format!("{:03X}#{data}", self.id)
    }

    /// Reads `ID#DATA`.
    pub fn parse(line: &str) -> Result<Frame, LineProblem> {
        let (id, data) = line.split_once('#').ok_or(LineProblem::NotAFrame)?;
        if id.is_empty() || id.len() > 3 || !id.bytes().all(|b| b.is_ascii_hexdigit()) {
            return Err(LineProblem::BadIdentifier);
        }
        let id = u16::from_str_radix(id, 16).map_err(|_| LineProblem::BadIdentifier)?;
        if id > 0x7FF {
            return Err(LineProblem::BadIdentifier);
        }
        if data.len() % 2 != 0 || !data.bytes().all(|b| b.is_ascii_hexdigit()) {
            return Err(LineProblem::BadData);
        }
        if data.len() > 16 {
            return Err(LineProblem::TooLong {
                bytes: data.len() / 2,
            });
        }
        let bytes: Vec<u8> = (0..data.len())
            .step_by(2)
            .filter_map(|i| u8::from_str_radix(&data[i..i + 2], 16).ok())
            .collect();
        Frame::new(id, &bytes).ok_or(LineProblem::BadData)
    }
}

/// Virtual time as `candump -l` writes it: seconds with six decimals.
pub fn timestamp(t_us: u64) -> String {
    format!("({})", amiro_can::candump::Timestamp::from_micros(t_us))
}

/// What is wrong with a line the program wrote.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum LineProblem {
    /// Neither `ok` nor `ID#DATA`.
    #[error("neither `ok` nor `ID#DATA`")]
    NotAFrame,
    /// The identifier is not 1–3 hex digits up to 7FF.
    #[error("the identifier is not 1-3 hex digits up to 7FF")]
    BadIdentifier,
    /// The data is not whole hex bytes.
    #[error("the data is not whole hex bytes")]
    BadData,
    /// More than 8 data bytes.
    #[error("{bytes} data bytes, at most 8")]
    TooLong {
        /// Bytes given.
        bytes: usize,
    },
}

/// Why a controller run ended.
#[derive(Debug, thiserror::Error)]
pub enum ControllerError {
    /// The program could not be started.
    #[error("controller `{program}` could not be started: {error}")]
    Spawn {
        /// The command line.
        program: String,
        /// Why.
        error: std::io::Error,
    },
    /// The program exited or closed its stdout.
    #[error("controller `{program}` ended at {} s of virtual time ({})", seconds(*at_us), describe(status))]
    Exited {
        /// The command line.
        program: String,
        /// Virtual time, µs.
        at_us: u64,
        /// Its exit status, if it has exited (`None`: it closed its stdout but still runs).
        status: Option<ExitStatus>,
    },
    /// No `ok` within the timeout.
    #[error("controller `{program}` did not answer the tick at {} s within {:?} (wall clock)", seconds(*at_us), waited)]
    Timeout {
        /// The command line.
        program: String,
        /// The tick's virtual time, µs.
        at_us: u64,
        /// How long the host waited.
        waited: Duration,
    },
    /// A line that is neither `ok` nor `ID#DATA`.
    #[error("controller `{program}` wrote {line:?} at {} s: {problem}", seconds(*at_us))]
    Malformed {
        /// The command line.
        program: String,
        /// Virtual time of the tick it answered, µs.
        at_us: u64,
        /// The line.
        line: String,
        /// What is wrong with it.
        problem: LineProblem,
    },
}

fn seconds(t_us: u64) -> String {
    amiro_can::candump::Timestamp::from_micros(t_us).to_string()
}

fn describe(status: &Option<ExitStatus>) -> String {
    match status {
        Some(s) => format!("exit status: {s}"),
        None => "it closed its stdout".to_string(),
    }
}

/// A running controller.
pub struct Controller {
    program: String,
    child: Child,
    stdin: Option<BufWriter<ChildStdin>>,
    lines: Receiver<String>,
    timeout: Duration,
}

impl Controller {
    /// Starts `program` (a command line, split on whitespace: the first word is the program,
    /// the rest its arguments) with piped stdin and stdout.
    pub fn spawn(program: &str, timeout: Duration) -> Result<Controller, ControllerError> {
        let mut words = program.split_whitespace();
        let spawn_error = |error| ControllerError::Spawn {
            program: program.to_string(),
            error,
        };
        let executable = words.next().ok_or_else(|| {
            spawn_error(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                "empty command line",
            ))
        })?;
        let mut command = Command::new(executable);
        command.args(words);
        Controller::spawn_command(program, command, timeout)
    }

    /// Starts a prepared command (its stdin and stdout are replaced by pipes).
    pub fn spawn_command(
        name: &str,
        mut command: Command,
        timeout: Duration,
    ) -> Result<Controller, ControllerError> {
        let mut child = command
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .spawn()
            .map_err(|error| ControllerError::Spawn {
                program: name.to_string(),
                error,
            })?;
        let stdin = child.stdin.take().map(BufWriter::new);
        let stdout = child.stdout.take();
        let (tx, lines) = mpsc::channel();
        // The reader thread ends at the program's end of output (the channel then disconnects).
        if let Some(stdout) = stdout {
            thread::spawn(move || {
                for line in BufReader::new(stdout).lines() {
                    let Ok(line) = line else { break };
                    if tx.send(line).is_err() {
                        break;
                    }
                }
            });
        }
        Ok(Controller {
            program: name.to_string(),
            child,
            stdin,
            lines,
            timeout,
        })
    }

    /// Writes a frame seen on the bus at `t_us`.
    pub fn frame(&mut self, t_us: u64, frame: &Frame) -> Result<(), ControllerError> {
        let line = format!("{} can0 {}\n", timestamp(t_us), frame.to_cansend());
        self.write(t_us, &line)
    }

    /// Writes the tick at `t_us` and returns the frames the program sends before its `ok`.
    pub fn tick(&mut self, t_us: u64) -> Result<Vec<Frame>, ControllerError> {
        self.write(t_us, &format!("{} tick\n", timestamp(t_us)))?;
        if let Some(stdin) = self.stdin.as_mut() {
            if stdin.flush().is_err() {
                return Err(self.exited(t_us));
            }
        }
        let mut frames = Vec::new();
        loop {
            let line = match self.lines.recv_timeout(self.timeout) {
                Ok(line) => line,
                Err(RecvTimeoutError::Timeout) => {
                    return Err(ControllerError::Timeout {
                        program: self.program.clone(),
                        at_us: t_us,
                        waited: self.timeout,
                    })
                }
                Err(RecvTimeoutError::Disconnected) => return Err(self.exited(t_us)),
            };
            let line = line.trim();
            if line == "ok" {
                return Ok(frames);
            }
            if line.is_empty() {
                continue;
            }
            match Frame::parse(line) {
                Ok(frame) => frames.push(frame),
                Err(problem) => {
                    return Err(ControllerError::Malformed {
                        program: self.program.clone(),
                        at_us: t_us,
                        line: line.to_string(),
                        problem,
                    })
                }
            }
        }
    }

    fn write(&mut self, t_us: u64, line: &str) -> Result<(), ControllerError> {
        let Some(stdin) = self.stdin.as_mut() else {
            return Err(self.exited(t_us));
        };
        if stdin.write_all(line.as_bytes()).is_err() {
            return Err(self.exited(t_us));
        }
        Ok(())
    }

    /// The program has gone: with its exit status if it has one (waiting briefly for it, since
    /// the pipe closes a moment before the process is reaped).
    fn exited(&mut self, t_us: u64) -> ControllerError {
        self.stdin = None;
        let mut status = None;
        for _ in 0..50 {
            if let Ok(Some(s)) = self.child.try_wait() {
                status = Some(s);
                break;
            }
            thread::sleep(Duration::from_millis(10));
        }
        ControllerError::Exited {
            program: self.program.clone(),
            at_us: t_us,
            status,
        }
    }

    /// Ends the run: closes the program's stdin (its cue to finish) and waits a moment for it,
    /// then stops it if it is still running.
    pub fn finish(mut self) -> Option<ExitStatus> {
        self.stdin = None;
        for _ in 0..100 {
            if let Ok(Some(s)) = self.child.try_wait() {
                return Some(s);
            }
            thread::sleep(Duration::from_millis(10));
        }
        let _ = self.child.kill();
        self.child.wait().ok()
    }
}

impl Drop for Controller {
    fn drop(&mut self) {
        // A controller never outlives its run.
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_in_the_cansend_form() {
        let f = Frame::parse("41F#0304").unwrap();
        assert_eq!((f.id, f.payload()), (0x41F, &[3u8, 4][..]));
        assert_eq!(f.to_cansend(), "41F#0304");
        assert_eq!(Frame::parse("10#").unwrap().to_cansend(), "010#");
        assert_eq!(Frame::parse("ok?"), Err(LineProblem::NotAFrame));
        assert_eq!(Frame::parse("800#00"), Err(LineProblem::BadIdentifier));
        assert_eq!(Frame::parse("1234#00"), Err(LineProblem::BadIdentifier));
        assert_eq!(Frame::parse("110#0"), Err(LineProblem::BadData));
        assert_eq!(Frame::parse("110#zz"), Err(LineProblem::BadData));
        assert_eq!(
            Frame::parse("110#000102030405060708"),
            Err(LineProblem::TooLong { bytes: 9 })
        );
        assert_eq!(timestamp(12_345_678), "(12.345678)");
    }
}
