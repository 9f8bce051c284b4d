//! The `slcan:` bus: USB-serial CAN adapters speaking the SLCAN (Lawicel) ASCII protocol.
//!
//! The protocol is line-based: every command and every received frame ends in `\r`; an adapter answers a command
//! with `\r` (done), `z\r`/`Z\r` (frame queued for transmission) or a BEL byte (refused). We open the channel the way
//! `slcand -o -c -s8` does: `C` (close whatever an earlier program left open), `S8` (1 Mbit/s, the AMiRo bus
//! rate everywhere), `O` (open); and close it with `C` when done, so the adapter stops buffering frames nobody reads.
//! Frames can arrive while we wait for an answer; they are queued, never dropped.

use std::collections::VecDeque;
use std::fs::{File, OpenOptions};
use std::io::{ErrorKind, Read, Write};
use std::os::fd::AsFd;
use std::os::unix::fs::OpenOptionsExt;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use nix::fcntl::{Flock, FlockArg};
use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
use nix::sys::termios::{self, BaudRate, ControlFlags, SetArg};

use super::{interrupted, Bus, Reception};
use crate::frame::{LoggedFrame, RawFrame, Timestamp};

/// How long an adapter may take to answer a command; real ones answer in well under a millisecond.
const REPLY_TIMEOUT: Duration = Duration::from_secs(1);
/// The bitrate command for 1 Mbit/s, the AMiRo bus rate.
const BITRATE_1MBIT: &str = "S8";
/// Interface name shown for frames received through an adapter.
const INTERFACE: &str = "slcan";

const BELL: u8 = 0x07;
const CR: u8 = b'\r';
/// The longest message an adapter can mean: `T` + 8 id digits + length + 16 data digits + 4 timestamp digits is
/// 30 bytes. Anything longer without a terminator is garbage (a wrong baud rate, a device that is not an adapter)
/// and is dropped, so an adapter that never sends `\r` cannot grow our memory.
pub const MAX_MESSAGE_LEN: usize = 64;

/// One message from the adapter, without its terminator.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum AdapterMessage {
    /// `\r` alone: the last command was carried out.
    Done,
    /// BEL: the last command was refused.
    Refused,
    /// `z` or `Z`: a frame was queued for transmission.
    Queued,
    /// A received frame.
    Frame(RawFrame),
    /// Anything else (version strings, status flags, a garbled frame).
    Other(String),
    /// More than [`MAX_MESSAGE_LEN`] bytes without a terminator; `bytes` of them were dropped.
    Garbage {
        /// How many bytes were dropped.
        bytes: usize,
    },
}

/// The SLCAN text of a frame to transmit, including the final `\r`: `t205401840302\r` for 205#01840302
/// (`amiro_can::slcan`'s encoder, which the robot host's emulated adapter uses too).
pub fn frame_command(frame: &RawFrame) -> String {
    let mut text = [0u8; amiro_can::slcan::MAX_FRAME_MESSAGE];
    let n = amiro_can::slcan::encode_frame(frame, None, &mut text);
    String::from_utf8_lossy(&text[..n]).into_owned()
}

/// Reads one adapter message (terminator removed). A received frame may carry a 4-digit adapter timestamp
/// (after `Z1`), which we ignore: the host stamps frames itself.
pub fn parse_message(message: &[u8]) -> AdapterMessage {
    let Ok(text) = std::str::from_utf8(message) else {
        return AdapterMessage::Other(String::from_utf8_lossy(message).into_owned());
    };
    match text {
        "" => return AdapterMessage::Done,
        "z" | "Z" => return AdapterMessage::Queued,
        _ => {}
    }
    amiro_can::slcan::decode_frame(message).map_or_else(
        |_| AdapterMessage::Other(text.to_string()),
        |(frame, _)| AdapterMessage::Frame(frame),
    )
}

/// What waiting on the adapter produced.
enum Wait {
    Message(AdapterMessage),
    TimedOut,
    Interrupted,
}

/// An open SLCAN adapter.
pub struct Slcan {
    path: PathBuf,
    /// The serial port, locked (`flock`) so that no other `amiro` opens the same device by another name.
    port: Flock<File>,
    /// Whether Ctrl-C ends a wait for frames (false when a relay thread, not the user, is waiting).
    interruptible: bool,
    /// Bytes received but not yet ending in a terminator (at most `MAX_MESSAGE_LEN`).
    partial: Vec<u8>,
    /// Bytes dropped from the current over-long line, reported once its end (or the next message) is seen.
    dropped: usize,
    /// Complete messages read but not yet handed out.
    messages: VecDeque<AdapterMessage>,
    /// Frames that arrived while we were waiting for a command's answer.
    received: VecDeque<RawFrame>,
    channel_open: bool,
}

impl Slcan {
    /// Opens the serial device, configures it raw (and at `baud`, if given), and opens the CAN channel.
    pub fn open(path: &Path, baud: Option<u32>) -> Result<Self> {
        let port = OpenOptions::new()
            .read(true)
            .write(true)
            // The adapter must not become our controlling terminal (a hang-up would kill us).
            .custom_flags(nix::libc::O_NOCTTY)
            .open(path)
            .with_context(|| format!("cannot open {}", path.display()))?;
        let port = Flock::lock(port, FlockArg::LockExclusiveNonblock).map_err(|(_, errno)| {
            anyhow::anyhow!(
                "{} is in use by another amiro that is not sharing it ({errno}); close that program, or start \
                 it again so it shares the adapter",
                path.display()
            )
        })?;
        configure_port(&port, baud)
            .with_context(|| format!("cannot configure {}", path.display()))?;
        let mut adapter = Self {
            path: path.to_path_buf(),
            port,
            interruptible: true,
            partial: Vec::new(),
            dropped: 0,
            messages: VecDeque::new(),
            received: VecDeque::new(),
            channel_open: false,
        };
        // An earlier program may have left the channel open; refusing this `C` just means it was closed.
        adapter.command("C", "close the CAN channel", true)?;
        adapter.command(BITRATE_1MBIT, "set the bitrate to 1 Mbit/s", false)?;
        adapter.command("O", "open the CAN channel", false)?;
        adapter.channel_open = true;
        Ok(adapter)
    }

    /// Makes waits for frames ignore Ctrl-C: the relay thread that serves other processes is stopped by its owner,
    /// not by the signal.
    pub fn set_interruptible(&mut self, interruptible: bool) {
        self.interruptible = interruptible;
    }

    /// The serial device.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Sends a command and waits for its answer; frames that arrive meanwhile are kept.
    fn command(&mut self, command: &str, meaning: &str, refusal_is_fine: bool) -> Result<()> {
        self.write(&format!("{command}\r"))?;
        match self.await_answer()? {
            Some(true) => Ok(()),
            Some(false) if refusal_is_fine => Ok(()),
            Some(false) => bail!("the adapter refused {command:?} ({meaning})"),
            None => bail!(
                "no answer to {command:?} ({meaning}) within {} ms: is {} an SLCAN adapter?",
                REPLY_TIMEOUT.as_millis(),
                self.path.display()
            ),
        }
    }

    /// Waits for done/queued (`Some(true)`), refused (`Some(false)`) or nothing (`None`).
    fn await_answer(&mut self) -> Result<Option<bool>> {
        let deadline = Instant::now() + REPLY_TIMEOUT;
        loop {
            match self.next_message(Some(deadline), false)? {
                Wait::Message(AdapterMessage::Done | AdapterMessage::Queued) => {
                    return Ok(Some(true))
                }
                Wait::Message(AdapterMessage::Refused) => return Ok(Some(false)),
                Wait::Message(AdapterMessage::Frame(frame)) => self.received.push_back(frame),
                Wait::Message(AdapterMessage::Other(text)) => warn_unknown(&text),
                Wait::Message(AdapterMessage::Garbage { bytes }) => warn_garbage(bytes),
                Wait::TimedOut => return Ok(None),
                // Only an interruptible wait reports Ctrl-C, and this one is not.
                Wait::Interrupted => return Ok(None),
            }
        }
    }

    fn write(&mut self, text: &str) -> Result<()> {
        self.port
            .write_all(text.as_bytes())
            .and_then(|()| self.port.flush())
            .with_context(|| format!("cannot write to {}", self.path.display()))
    }

    /// The next complete message, reading more bytes until `deadline` if needed. Ctrl-C ends the wait only when
    /// `interruptible`: answers to commands are awaited regardless (for at most `REPLY_TIMEOUT`), so that the
    /// closing `C` after a Ctrl-C is still confirmed.
    fn next_message(&mut self, deadline: Option<Instant>, interruptible: bool) -> Result<Wait> {
        loop {
            if let Some(message) = self.messages.pop_front() {
                return Ok(Wait::Message(message));
            }
            if interruptible && interrupted() {
                return Ok(Wait::Interrupted);
            }
            let timeout = match deadline {
                None => PollTimeout::NONE,
                Some(deadline) => {
                    let left = deadline.saturating_duration_since(Instant::now());
                    if left.is_zero() {
                        return Ok(Wait::TimedOut);
                    }
                    // Round up so a sub-millisecond remainder still waits instead of spinning.
                    PollTimeout::try_from(left + Duration::from_micros(999))
                        .unwrap_or(PollTimeout::MAX)
                }
            };
            let mut fds = [PollFd::new(self.port.as_fd(), PollFlags::POLLIN)];
            match poll(&mut fds, timeout) {
                Ok(0) => continue,
                Ok(_) => {}
                Err(nix::errno::Errno::EINTR) => continue,
                Err(error) => return Err(error).context("waiting for the adapter"),
            }
            let mut buffer = [0u8; 256];
            let count = match self.port.read(&mut buffer) {
                Ok(0) => bail!("{} closed (adapter unplugged?)", self.path.display()),
                Ok(count) => count,
                Err(error)
                    if matches!(error.kind(), ErrorKind::Interrupted | ErrorKind::WouldBlock) =>
                {
                    continue
                }
                Err(error) => {
                    return Err(error)
                        .with_context(|| format!("cannot read from {}", self.path.display()))
                }
            };
            self.take_bytes(&buffer[..count]);
        }
    }

    /// Splits incoming bytes into messages at `\r` and BEL.
    fn take_bytes(&mut self, bytes: &[u8]) {
        self.messages
            .extend(split_messages(&mut self.partial, &mut self.dropped, bytes));
    }
}

/// Splits adapter bytes into messages at `\r` and BEL, carrying an unfinished message over in `partial`. A line
/// that grows past [`MAX_MESSAGE_LEN`] is dropped (counted in `dropped`) and reported as one `Garbage` message
/// when it ends (and every 64 KiB while it does not): it is never kept, so memory stays bounded.
pub fn split_messages(
    partial: &mut Vec<u8>,
    dropped: &mut usize,
    bytes: &[u8],
) -> Vec<AdapterMessage> {
    let mut messages = Vec::new();
    let end_garbage = |dropped: &mut usize, messages: &mut Vec<AdapterMessage>| {
        if *dropped > 0 {
            messages.push(AdapterMessage::Garbage { bytes: *dropped });
            *dropped = 0;
        }
    };
    for &byte in bytes {
        match byte {
            CR => {
                if *dropped > 0 {
                    *dropped += partial.len();
                    partial.clear();
                    end_garbage(dropped, &mut messages);
                } else {
                    let message = std::mem::take(partial);
                    messages.push(parse_message(&message));
                }
            }
            BELL => {
                *dropped += partial.len();
                partial.clear();
                end_garbage(dropped, &mut messages);
                messages.push(AdapterMessage::Refused);
            }
            // Some adapters end lines with "\r\n"; the newline carries nothing.
            b'\n' => {}
            other => {
                if partial.len() == MAX_MESSAGE_LEN {
                    *dropped += partial.len();
                    partial.clear();
                }
                partial.push(other);
            }
        }
    }
    // A stream with no terminator at all is reported as it goes (one warning per 64 KiB), not only at its end.
    if *dropped >= 65_536 {
        end_garbage(dropped, &mut messages);
    }
    messages
}

fn warn_garbage(bytes: usize) {
    eprintln!(
        "warning: SLCAN adapter sent {bytes} bytes without a line end (longer than any SLCAN message); dropped. \
         Wrong baud rate, or not an SLCAN adapter?"
    );
}

fn warn_unknown(text: &str) {
    eprintln!(
        "warning: SLCAN adapter sent {text:?}, which is neither an answer nor a frame; ignored"
    );
}

impl Bus for Slcan {
    fn send(&mut self, frame: &RawFrame) -> Result<()> {
        self.write(&frame_command(frame))?;
        match self.await_answer()? {
            Some(true) => Ok(()),
            Some(false) => {
                bail!("the adapter refused to transmit {frame} (transmit queue full or bus off?)")
            }
            None => bail!(
                "the adapter did not confirm {frame} within {} ms",
                REPLY_TIMEOUT.as_millis()
            ),
        }
    }

    fn receive(&mut self, timeout: Option<Duration>) -> Result<Reception> {
        let deadline = timeout.map(|timeout| Instant::now() + timeout);
        loop {
            if let Some(frame) = self.received.pop_front() {
                let logged = LoggedFrame {
                    timestamp: Some(Timestamp::now()),
                    interface: Some(INTERFACE.into()),
                    frame,
                };
                return Ok(Reception::Frame(logged));
            }
            match self.next_message(deadline, self.interruptible)? {
                Wait::Message(AdapterMessage::Frame(frame)) => self.received.push_back(frame),
                // A late answer to an earlier command carries nothing now.
                Wait::Message(AdapterMessage::Done | AdapterMessage::Queued) => {}
                Wait::Message(AdapterMessage::Refused) => {
                    eprintln!("warning: the SLCAN adapter signalled an error (BEL)")
                }
                Wait::Message(AdapterMessage::Other(text)) => warn_unknown(&text),
                Wait::Message(AdapterMessage::Garbage { bytes }) => warn_garbage(bytes),
                Wait::TimedOut => return Ok(Reception::TimedOut),
                Wait::Interrupted => return Ok(Reception::Interrupted),
            }
        }
    }

    fn close(&mut self) -> Result<()> {
        if !self.channel_open {
            return Ok(());
        }
        self.channel_open = false;
        self.command("C", "close the CAN channel", false)
    }
}

impl Drop for Slcan {
    fn drop(&mut self) {
        // Best effort on an error path: the adapter should not keep the channel open for nobody.
        if self.channel_open {
            self.channel_open = false;
            let _ = self.write("C\r");
        }
    }
}

/// Raw mode (no echo, no line editing, no CR/LF translation), receiver on, modem lines ignored.
/// A device that is not a terminal (a FIFO in a test rig) is used as it is.
fn configure_port(port: &File, baud: Option<u32>) -> Result<()> {
    let mut settings = match termios::tcgetattr(port.as_fd()) {
        Ok(settings) => settings,
        Err(nix::errno::Errno::ENOTTY) if baud.is_none() => return Ok(()),
        Err(error) => return Err(error).context("not a serial port"),
    };
    termios::cfmakeraw(&mut settings);
    settings.control_flags |= ControlFlags::CREAD | ControlFlags::CLOCAL;
    if let Some(baud) = baud {
        termios::cfsetspeed(&mut settings, baud_rate(baud)?).context("cannot set the baud rate")?;
    }
    termios::tcsetattr(port.as_fd(), SetArg::TCSANOW, &settings)
        .context("cannot apply serial settings")?;
    // Bytes queued before we took the port belong to someone else's session.
    termios::tcflush(port.as_fd(), termios::FlushArg::TCIFLUSH)
        .context("cannot flush the serial port")?;
    Ok(())
}

fn baud_rate(baud: u32) -> Result<BaudRate> {
    Ok(match baud {
        9_600 => BaudRate::B9600,
        19_200 => BaudRate::B19200,
        38_400 => BaudRate::B38400,
        57_600 => BaudRate::B57600,
        115_200 => BaudRate::B115200,
        230_400 => BaudRate::B230400,
        460_800 => BaudRate::B460800,
        500_000 => BaudRate::B500000,
        921_600 => BaudRate::B921600,
        1_000_000 => BaudRate::B1000000,
        2_000_000 => BaudRate::B2000000,
        3_000_000 => BaudRate::B3000000,
        other => bail!(
            "unsupported serial baud rate {other}: use 9600, 19200, 38400, 57600, 115200, 230400, 460800, \
             500000, 921600, 1000000, 2000000 or 3000000"
        ),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::parse_compact;

    #[test]
    fn frames_become_slcan_commands() {
        assert_eq!(
            frame_command(&parse_compact("205#01840302").unwrap()),
            "t205401840302\r"
        );
        assert_eq!(frame_command(&parse_compact("605#").unwrap()), "t6050\r");
        assert_eq!(
            frame_command(&parse_compact("1234ABCD#FF").unwrap()),
            "T1234ABCD1FF\r"
        );
        assert_eq!(frame_command(&parse_compact("205#R4").unwrap()), "r2054\r");
        assert_eq!(
            frame_command(&parse_compact("00000205#R").unwrap()),
            "R000002050\r"
        );
    }

    #[test]
    fn adapter_messages_are_recognised() {
        assert_eq!(parse_message(b""), AdapterMessage::Done);
        assert_eq!(parse_message(b"z"), AdapterMessage::Queued);
        assert_eq!(parse_message(b"Z"), AdapterMessage::Queued);
        let expected = parse_compact("608#FCFF02000000").unwrap();
        assert_eq!(
            parse_message(b"t6086FCFF02000000"),
            AdapterMessage::Frame(expected)
        );
        assert_eq!(
            parse_message(b"t6086fcff02000000"),
            AdapterMessage::Frame(expected)
        );
        // With the adapter's own 16-bit timestamp appended.
        assert_eq!(
            parse_message(b"t6086FCFF020000001A2B"),
            AdapterMessage::Frame(expected)
        );
        assert_eq!(
            parse_message(b"r2052"),
            AdapterMessage::Frame(parse_compact("205#R2").unwrap())
        );
        assert_eq!(
            parse_message(b"T1234ABCD1FF"),
            AdapterMessage::Frame(parse_compact("1234ABCD#FF").unwrap())
        );
    }

    #[test]
    fn an_adapter_that_never_ends_a_line_cannot_grow_memory() {
        let (mut partial, mut dropped) = (Vec::new(), 0);
        let mut garbage = 0;
        for _ in 0..1000 {
            for message in split_messages(&mut partial, &mut dropped, &[b'A'; 1000]) {
                match message {
                    AdapterMessage::Garbage { bytes } => garbage += bytes,
                    other => panic!("unexpected {other:?}"),
                }
            }
            assert!(
                partial.len() <= MAX_MESSAGE_LEN,
                "{} bytes kept",
                partial.len()
            );
        }
        // Reported while it goes on, and the rest when the line finally ends; then frames read normally again.
        assert!(garbage >= 900_000, "{garbage}");
        let after = split_messages(&mut partial, &mut dropped, b"\rt6054D8ADFFFF\r");
        let AdapterMessage::Garbage { bytes } = after[0] else {
            panic!("{after:?}")
        };
        assert_eq!(garbage + bytes, 1_000_000);
        assert_eq!(
            after[1],
            AdapterMessage::Frame(parse_compact("605#D8ADFFFF").unwrap())
        );
    }

    #[test]
    fn garbled_frames_are_not_frames() {
        for garbled in [
            &b"t60"[..],
            b"t6089",
            b"t6082FF",
            b"t6082FFFFF",
            b"t8001FF",
            b"tXYZ0",
            b"V1013",
            b"\xff",
        ] {
            assert!(
                matches!(parse_message(garbled), AdapterMessage::Other(_)),
                "{garbled:?}"
            );
        }
    }

    mod properties {
        use super::*;
        use crate::frame::FrameId;
        use proptest::prelude::*;

        proptest! {
            #[test]
            fn every_frame_survives_the_adapter_text(
                standard in any::<bool>(),
                id in 0u32..=0x1FFF_FFFF,
                bytes in proptest::collection::vec(any::<u8>(), 0..=8),
                remote in any::<bool>(),
            ) {
                let id = if standard { FrameId::Standard((id & 0x7FF) as u16) } else { FrameId::Extended(id) };
                let frame = if remote {
                    RawFrame::remote_frame(id, bytes.len() as u8).unwrap()
                } else {
                    RawFrame::data_frame(id, &bytes).unwrap()
                };
                let command = frame_command(&frame);
                let text = command.strip_suffix('\r').unwrap();
                prop_assert_eq!(parse_message(text.as_bytes()), AdapterMessage::Frame(frame));
            }

            #[test]
            fn any_bytes_from_an_adapter_are_handled(bytes in proptest::collection::vec(any::<u8>(), 0..40)) {
                let _ = parse_message(&bytes);
            }
        }
    }
}
