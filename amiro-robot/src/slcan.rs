//! `cargo xtask robot --slcan`: the robot's bus behind a pseudo-terminal that speaks SLCAN (the
//! Lawicel ASCII protocol of USB-CAN adapters), so `amiro console --bus slcan:/dev/pts/N`,
//! python-can and `slcand` talk to the emulated robot as to a real one through an adapter.
//!
//! The adapter is the bus's fourth node (the operator's): frames the client sends (`tIIILDD…`) are
//! queued on the bus at the current virtual time; every frame a board completes is sent to the
//! client (`tIIILDD…[TTTT]`) while the channel is open. Extended and remote frames are refused
//! (BEL): the robot's bus carries neither. Output the client does not read is dropped, never
//! buffered without bound, and whole messages at a time: a message the terminal takes only in part
//! keeps its rest in a small backlog, written first at the next chance, so the client never reads a
//! frame cut short (python-can's parser failed on one, `int('t')`, when a busy machine held the
//! client up; issue 34). The run says how many it dropped.
use std::fs::File;
use std::io::{Read, Write};
use std::os::fd::{AsRawFd, FromRawFd};

use amiro_bus_sim::Frame;
use anyhow::{bail, Result};

const BELL: &[u8] = b"\x07";
/// Longest command worth reading (`T` + 8 + 1 + 16 digits + slack); longer without `\r` is garbage.
const MAX_COMMAND: usize = 64;
/// The most output held back for a client that reads slowly (some 2 000 frames); a message that
/// would go beyond it is dropped whole.
const MAX_BACKLOG: usize = 1 << 16;

/// The pseudo-terminal and the adapter's state.
pub struct Slcan {
    master: File,
    /// Kept open so the terminal stays usable while no client has it open.
    _slave: File,
    path: String,
    partial: Vec<u8>,
    open: bool,
    timestamps: bool,
    /// What the terminal has not taken yet (whole messages, the first possibly begun).
    backlog: Vec<u8>,
    /// Messages to the client dropped whole because the backlog was full.
    dropped: u64,
}

impl Slcan {
    /// Opens a pseudo-terminal in raw mode.
    pub fn new() -> Result<Self> {
        let (mut master, mut slave) = (0, 0);
        // SAFETY: openpty writes two descriptors and, with a buffer, the slave's name.
        let mut name = [0 as libc::c_char; 128];
        let ok = unsafe {
            libc::openpty(
                &mut master,
                &mut slave,
                name.as_mut_ptr(),
                std::ptr::null(),
                std::ptr::null(),
            )
        };
        if ok != 0 {
            bail!("openpty: {}", std::io::Error::last_os_error());
        }
        // SAFETY: descriptors openpty just returned, owned from here on.
        let (master, slave) = unsafe { (File::from_raw_fd(master), File::from_raw_fd(slave)) };
        // SAFETY: termios of a terminal we own, made raw (no echo, no line discipline).
        unsafe {
            let mut t: libc::termios = std::mem::zeroed();
            if libc::tcgetattr(slave.as_raw_fd(), &mut t) == 0 {
                libc::cfmakeraw(&mut t);
                libc::tcsetattr(slave.as_raw_fd(), libc::TCSANOW, &t);
            }
        }
        crate::board::set_nonblocking(master.as_raw_fd());
        // SAFETY: `name` is NUL-terminated by openpty.
        let path = unsafe { std::ffi::CStr::from_ptr(name.as_ptr()) }
            .to_string_lossy()
            .into_owned();
        Ok(Self {
            master,
            _slave: slave,
            path,
            partial: Vec::new(),
            open: false,
            timestamps: false,
            backlog: Vec::new(),
            dropped: 0,
        })
    }

    /// The terminal's path (`/dev/pts/N`).
    pub fn path(&self) -> &str {
        &self.path
    }

    fn reply(&mut self, bytes: &[u8]) {
        // A client that does not read loses its answers, whole, not our memory.
        if self.backlog.len() + bytes.len() > MAX_BACKLOG {
            self.dropped += 1;
            return;
        }
        self.backlog.extend_from_slice(bytes);
        self.flush();
    }

    /// Writes as much of the backlog as the terminal takes now (never blocks).
    fn flush(&mut self) {
        while !self.backlog.is_empty() {
            match self.master.write(&self.backlog) {
                Ok(0) | Err(_) => break,
                Ok(n) => {
                    self.backlog.drain(..n);
                }
            }
        }
    }

    /// Messages to the client dropped so far because it did not read them in time.
    pub fn dropped(&self) -> u64 {
        self.dropped
    }

    /// Reads what the client sent and answers it; returns the frames to put on the bus.
    pub fn poll(&mut self) -> Vec<Frame> {
        self.flush();
        let mut frames = Vec::new();
        let mut chunk = [0u8; 512];
        while let Ok(n) = self.master.read(&mut chunk) {
            if n == 0 {
                break;
            }
            for &b in &chunk[..n] {
                if b == b'\r' || b == b'\n' {
                    let command = std::mem::take(&mut self.partial);
                    if b == b'\r' || !command.is_empty() {
                        if let Some(frame) = self.command(&command) {
                            frames.push(frame);
                        }
                    }
                } else if self.partial.len() < MAX_COMMAND {
                    self.partial.push(b);
                } else {
                    self.partial.clear();
                }
            }
        }
        frames
    }

    fn command(&mut self, command: &[u8]) -> Option<Frame> {
        let Some((&verb, rest)) = command.split_first() else {
            self.reply(b"\r");
            return None;
        };
        match verb {
            b'O' | b'L' => {
                self.open = true;
                self.reply(b"\r");
            }
            b'C' => {
                self.open = false;
                self.reply(b"\r");
            }
            b'S' | b's' | b'M' | b'm' | b'X' | b'W' | b'Q' => self.reply(b"\r"),
            b'Z' => {
                self.timestamps = rest.first() == Some(&b'1');
                self.reply(b"\r");
            }
            b'V' => self.reply(b"V1013\r"),
            b'v' => self.reply(b"vAMiRo\r"),
            b'N' => self.reply(b"NA123\r"),
            b'F' => self.reply(b"F00\r"),
            b't' if self.open => match parse_frame(command) {
                Some(frame) => {
                    self.reply(b"z\r");
                    return Some(frame);
                }
                None => self.reply(BELL),
            },
            _ => self.reply(BELL),
        }
        None
    }

    /// Hands a frame that completed on the bus at `end_us` to the client, if its channel is open.
    pub fn deliver(&mut self, end_us: u64, frame: &Frame) {
        if !self.open {
            return;
        }
        use amiro_can::candump::{FrameId, RawFrame};
        use amiro_can::slcan::{encode_frame, MAX_FRAME_MESSAGE};
        // The bus model's frames are standard data frames of at most 8 bytes.
        let Some(raw) = RawFrame::data_frame(FrameId::Standard(frame.id), frame.payload()) else {
            return;
        };
        let mut text = [0u8; MAX_FRAME_MESSAGE];
        let stamp = self.timestamps.then_some(((end_us / 1000) % 60_000) as u16);
        let n = encode_frame(&raw, stamp, &mut text);
        self.reply(&text[..n]);
    }
}

/// A standard data frame the client sends (`tIIILDD…`, `amiro_can::slcan`'s decoder); `None` for
/// anything the robot's bus does not carry or the decoder refuses.
fn parse_frame(message: &[u8]) -> Option<Frame> {
    use amiro_can::candump::FrameId;
    let (frame, _) = amiro_can::slcan::decode_frame(message).ok()?;
    match frame.id() {
        FrameId::Standard(id) if !frame.is_remote() => Frame::new(id, frame.data()),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_and_refusals() {
        assert_eq!(parse_frame(b"t2054018403 02"), None);
        assert_eq!(
            parse_frame(b"t205401840302"),
            Frame::new(0x205, &[1, 0x84, 3, 2])
        );
        assert_eq!(parse_frame(b"t6050"), Frame::new(0x605, &[]));
        assert_eq!(parse_frame(b"t8000"), None);
        assert_eq!(parse_frame(b"t20590000000000000000000"), None);
        assert_eq!(parse_frame(b"t2052011"), None);
        assert_eq!(parse_frame(b"r2050"), None);
        assert_eq!(parse_frame(b"T000002050"), None);
    }

    #[test]
    fn a_client_that_reads_late_gets_whole_messages() {
        let mut adapter = Slcan::new().unwrap();
        let mut client = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(adapter.path())
            .unwrap();
        client.write_all(b"O\r").unwrap();
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
        while !adapter.open && std::time::Instant::now() < deadline {
            adapter.poll();
            std::thread::sleep(std::time::Duration::from_millis(2));
        }
        // SAFETY: the client's descriptor, open for the whole test.
        unsafe {
            let fd = std::os::fd::AsRawFd::as_raw_fd(&client);
            libc::fcntl(
                fd,
                libc::F_SETFL,
                libc::fcntl(fd, libc::F_GETFL) | libc::O_NONBLOCK,
            );
        }
        // 10 000 frames of 14 bytes while the client reads nothing: more than the terminal and the
        // backlog hold together.
        let frame = Frame::new(0x605, &[0xAA, 0xBB, 0xCC, 0xDD]).unwrap();
        for k in 0..10_000 {
            adapter.deliver(k, &frame);
        }
        assert!(adapter.dropped() > 0);
        // Then it reads everything (the adapter writing its backlog as it polls).
        let mut got = Vec::new();
        let mut idle = 0;
        while idle < 20 && std::time::Instant::now() < deadline {
            adapter.poll();
            let mut buffer = [0u8; 4096];
            match client.read(&mut buffer) {
                Ok(n) if n > 0 => {
                    got.extend_from_slice(&buffer[..n]);
                    idle = 0;
                }
                _ => {
                    idle += 1;
                    std::thread::sleep(std::time::Duration::from_millis(2));
                }
            }
        }
        // The answer to `O`, then whole frames only.
        assert_eq!(&got[..1], b"\r");
        let frames = &got[1..];
        assert!(!frames.is_empty());
        assert_eq!(frames.len() % 14, 0, "a message cut short");
        assert!(frames.chunks(14).all(|m| m == b"t6054AABBCCDD\r"));
        assert_eq!(frames.len() / 14 + adapter.dropped() as usize, 10_000);
    }

    #[test]
    fn a_client_on_the_terminal() {
        let mut adapter = Slcan::new().unwrap();
        let mut client = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(adapter.path())
            .unwrap();
        // Not open yet: a frame is refused; then the slcand sequence, a frame, an extended frame.
        client
            .write_all(b"t6050\rC\rS8\rO\rt205401840302\rT123456780\r")
            .unwrap();
        // Polled until the terminal has passed everything on both ways (a fixed 50 ms wait failed on a loaded
        // machine): the client's end reads without blocking.
        // SAFETY: the client's descriptor, open for the whole test.
        unsafe {
            let fd = std::os::fd::AsRawFd::as_raw_fd(&client);
            libc::fcntl(
                fd,
                libc::F_SETFL,
                libc::fcntl(fd, libc::F_GETFL) | libc::O_NONBLOCK,
            );
        }
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
        let mut frames = Vec::new();
        let mut got = Vec::new();
        let mut exchange = |adapter: &mut Slcan, frames: &mut Vec<Frame>, until: &[u8]| {
            while !got.ends_with(until) && std::time::Instant::now() < deadline {
                frames.extend(adapter.poll());
                let mut buffer = [0u8; 64];
                if let Ok(n) = client.read(&mut buffer) {
                    got.extend_from_slice(&buffer[..n]);
                }
                std::thread::sleep(std::time::Duration::from_millis(2));
            }
            std::mem::take(&mut got)
        };
        // Refused (not open), C, S8, O, the frame, the extended frame refused.
        let answers = exchange(&mut adapter, &mut frames, b"z\r\x07");
        assert_eq!(&answers[..], b"\x07\r\r\rz\r\x07");
        assert_eq!(frames, vec![Frame::new(0x205, &[1, 0x84, 3, 2]).unwrap()]);
        adapter.deliver(1_234_567, &Frame::new(0x605, &[0xAB]).unwrap());
        let delivered = exchange(&mut adapter, &mut frames, b"t6051AB\r");
        assert_eq!(&delivered[..], b"t6051AB\r");
    }
}
