//! The AMiRo task-trace record format, version [`VERSION`]: what a board writes on its trace channel
//! (RTT channel 1 on the robot, `# T` lines in QEMU) and what `cargo xtask bench` and
//! `cargo xtask trace` read. One implementation serves both sides: the firmware calls
//! [`Record::encode`], the host feeds whatever bytes it got into a [`Reader`].
//!
//! # Wire format
//!
//! Every record is one COBS-encoded body followed by a `0x00` delimiter, so a reader that starts in
//! the middle of the stream, or meets garbage, drops bytes up to the next `0x00` and is back in
//! step (bounded: a body is at most [`MAX_BODY`] bytes). The body, before COBS:
//!
//! ```text
//! byte 0        version << 5 | kind        (version 1; kind 0..=31, see `Kind`)
//! bytes 1..9    timestamp, u64 little-endian: cycles of the board's trace clock since boot
//! bytes 9..n-1  payload, its length fixed by the kind
//! byte n-1      check: c = 0xA5; for every byte b before it: c = rotate_left(c, 1) ^ b
//! ```
//!
//! A body whose version, kind, length or check byte does not fit is counted and skipped; nothing
//! in a damaged stream makes the reader fail or panic. The trace clock is the DWT cycle counter
//! widened to 64 bits on the robot and SysTick's count in QEMU; its rate is in the [`Kind::Hello`]
//! record a board writes at boot (the reader is also told the rate, for a capture that starts late).
//!
//! | kind | name | payload |
//! |---:|---|---|
//! | 0 | `hello` | trace clock rate in Hz, `u32` (written at boot; again if the clock plan changes) |
//! | 1 | `task-start` | task `u8` (index in the app's source order) |
//! | 2 | `task-end` | task `u8`, next release in `u32` µs from now (`u32::MAX`: waits for a message or ends) |
//! | 3 | `event` | one 18-byte `amiro_sensors::trace` record (handler events: sample taken with its release, frame queued, frame in a mailbox, …) |
//! | 4 | `frame-acked` | identifier `u16`: the frame's transmission completed (acknowledged on the bus) |
//! | 5 | `lost` | records lost `u32` (the channel was full), written when there is room again |
//!
//! Task numbers are the app's tasks in source order, below 32, with one exception: [`PLATFORM_CLOCK_TASK`]
//! (254) is the QEMU platform clock's interrupt (SysTick in a single-board run), not an app task. Its busy
//! ticks (a queue checked: a deadline due, a head changed) are stamped cheaply, outside this stream: two raw
//! trace-clock readings per tick in the
//! run's host file `clock.bin` ([`clock_run`]), which the reader turns into a `task-start`/`task-end` pair of
//! this task so it can take the interrupt out of the job it interrupts. A robot never writes it.
#![cfg_attr(not(test), no_std)]
#![deny(missing_docs)]

pub mod robot_link;
pub mod stimulus;
pub mod world_link;

/// The record format's version (in every record's first byte).
pub const VERSION: u8 = 1;

/// Size of a handler-event record carried in [`Kind::Event`] (`amiro_sensors::trace::ENCODED_LEN`).
pub const EVENT_LEN: usize = 18;

/// Longest body: kind, timestamp, the largest payload, check.
pub const MAX_BODY: usize = 1 + 8 + EVENT_LEN + 1;

/// The task number of the QEMU platform clock's interrupt (`amiro_firmware::qemu::timer`'s SysTick in a
/// single-board run): each busy tick is a `task-start`/`task-end` pair with this number (read from
/// [`clock_run`]'s stamps), so the host sees it as a pre-empting run of its own, not as part of the job it
/// interrupts. No app task has it (app tasks are numbered below 32; 255 is the firmware's "no task").
pub const PLATFORM_CLOCK_TASK: u8 = 254;

/// The QEMU platform clock's stamps (`clock.bin` of a single-board run): per busy SysTick tick its start and end
/// on the trace clock, two `u64` little-endian, 16 bytes, in the order the activations ended. Written raw (no
/// COBS, no check: a host file, not a link) because the interrupt runs often and an encoded pair of records cost
/// it about 1 000 instructions. A reader makes each pair a `task-start`/`task-end` of [`PLATFORM_CLOCK_TASK`].
pub mod clock_run {
    /// Bytes per activation.
    pub const LEN: usize = 16;

    /// One activation's stamps as written.
    #[inline(always)]
    pub fn encode(start: u64, end: u64) -> [u8; LEN] {
        let mut out = [0u8; LEN];
        let (a, b) = out.split_at_mut(8);
        a.copy_from_slice(&start.to_le_bytes());
        b.copy_from_slice(&end.to_le_bytes());
        out
    }

    /// The activations in `bytes` (a trailing part of one is ignored): (start, end) cycles.
    pub fn decode(bytes: &[u8]) -> impl Iterator<Item = (u64, u64)> + '_ {
        bytes.chunks_exact(LEN).map(|c| {
            let mut start = [0u8; 8];
            let mut end = [0u8; 8];
            start.copy_from_slice(&c[..8]);
            end.copy_from_slice(&c[8..]);
            (u64::from_le_bytes(start), u64::from_le_bytes(end))
        })
    }

    #[cfg(test)]
    mod tests {
        #[test]
        fn round_trip_and_a_cut_tail() {
            let mut bytes = super::encode(5, 1_000_000_007).to_vec();
            bytes.extend_from_slice(&super::encode(u64::MAX - 1, u64::MAX));
            bytes.extend_from_slice(&[1, 2, 3]);
            let runs: Vec<_> = super::decode(&bytes).collect();
            assert_eq!(runs, [(5, 1_000_000_007), (u64::MAX - 1, u64::MAX)]);
        }
    }
}

/// Longest record on the wire: COBS adds one byte per 254, plus the delimiter.
pub const MAX_WIRE: usize = MAX_BODY + 2;

const CHECK_SEED: u8 = 0xA5;

/// What a record says.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// The board started: its trace clock's rate.
    Hello {
        /// Trace clock rate, Hz.
        clock_hz: u32,
    },
    /// A task (or a bound interrupt) started running: an interrupt's entry, or an async task's
    /// resumption.
    TaskStart {
        /// Index of the task in the app's source order.
        task: u8,
    },
    /// A task stopped running: an interrupt's return, or an async task's suspension.
    TaskEnd {
        /// Index of the task in the app's source order.
        task: u8,
        /// When it is due again, µs from now (a timer wait); `u32::MAX` for a wait on a message.
        next_release_in_us: u32,
    },
    /// A handler event (`amiro_sensors::trace` record), stamped here with the trace clock too.
    Event {
        /// The 18-byte record.
        record: [u8; EVENT_LEN],
    },
    /// A frame's transmission completed: it was acknowledged on the bus.
    FrameAcked {
        /// Its identifier.
        id: u16,
    },
    /// Records lost because the channel was full.
    Lost {
        /// How many.
        count: u32,
    },
}

impl Kind {
    /// The kind number (low five bits of the first body byte).
    pub const fn number(&self) -> u8 {
        match self {
            Kind::Hello { .. } => 0,
            Kind::TaskStart { .. } => 1,
            Kind::TaskEnd { .. } => 2,
            Kind::Event { .. } => 3,
            Kind::FrameAcked { .. } => 4,
            Kind::Lost { .. } => 5,
        }
    }

    /// Payload length of kind `number`, if there is such a kind.
    pub const fn payload_len(number: u8) -> Option<usize> {
        match number {
            0 => Some(4),
            1 => Some(1),
            2 => Some(5),
            3 => Some(EVENT_LEN),
            4 => Some(2),
            5 => Some(4),
            _ => None,
        }
    }
}

/// One record: when (trace clock cycles since boot) and what.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Record {
    /// Trace clock cycles since boot.
    pub cycles: u64,
    /// What happened.
    pub kind: Kind,
}

/// A record on the wire: COBS-encoded body and its `0x00` delimiter.
#[derive(Clone, Copy, Debug)]
pub struct Wire {
    bytes: [u8; MAX_WIRE],
    len: usize,
}

impl Wire {
    /// The bytes to send, delimiter included.
    pub fn as_bytes(&self) -> &[u8] {
        &self.bytes[..self.len]
    }
}

fn check(bytes: &[u8]) -> u8 {
    bytes.iter().fold(CHECK_SEED, |c, &b| c.rotate_left(1) ^ b)
}

/// COBS and the check byte in one pass, straight into the wire buffer (no body buffer: the
/// firmware's flash and cycles).
struct Encoder<'a> {
    out: &'a mut [u8; MAX_WIRE],
    code_at: usize,
    at: usize,
    check: u8,
}

impl Encoder<'_> {
    fn raw(&mut self, b: u8) {
        // Bodies are < 254 bytes: one code byte per zero and one at the start.
        if b == 0 {
            self.out[self.code_at] = (self.at - self.code_at) as u8;
            self.code_at = self.at;
        } else {
            self.out[self.at] = b;
        }
        self.at += 1;
    }

    // Fields of fixed sizes: a loop of K passes per call, which the WCET analysis counts.
    fn put<const K: usize>(&mut self, bytes: &[u8; K]) {
        for &b in bytes {
            self.check = self.check.rotate_left(1) ^ b;
            self.raw(b);
        }
    }

    fn finish(mut self) -> usize {
        let check = self.check;
        self.raw(check);
        self.out[self.code_at] = (self.at - self.code_at) as u8;
        self.out[self.at] = 0;
        self.at + 1
    }
}

impl Record {
    /// The record as it goes on the wire (COBS, then `0x00`).
    pub fn encode(&self) -> Wire {
        let mut wire = Wire {
            bytes: [0; MAX_WIRE],
            len: 0,
        };
        wire.len = self.encode_into(&mut wire.bytes);
        wire
    }

    /// Writes the record as it goes on the wire into `out` and returns its length (one pass: the
    /// firmware calls this on every task start and end).
    pub fn encode_into(&self, out: &mut [u8; MAX_WIRE]) -> usize {
        let mut e = Encoder {
            out,
            code_at: 0,
            at: 1,
            check: CHECK_SEED,
        };
        e.put(&[VERSION << 5 | self.kind.number()]);
        e.put(&self.cycles.to_le_bytes());
        match &self.kind {
            Kind::Hello { clock_hz } => e.put(&clock_hz.to_le_bytes()),
            Kind::TaskStart { task } => e.put(&[*task]),
            Kind::TaskEnd {
                task,
                next_release_in_us,
            } => {
                e.put(&[*task]);
                e.put(&next_release_in_us.to_le_bytes());
            }
            Kind::Event { record } => e.put(record),
            Kind::FrameAcked { id } => e.put(&id.to_le_bytes()),
            Kind::Lost { count } => e.put(&count.to_le_bytes()),
        }
        e.finish()
    }

    /// Reads one body (COBS already undone).
    pub fn from_body(body: &[u8]) -> Result<Record, Damage> {
        let (&last, rest) = body.split_last().ok_or(Damage::Empty)?;
        if rest.len() < 9 {
            return Err(Damage::Short);
        }
        if rest[0] >> 5 != VERSION {
            return Err(Damage::Version(rest[0] >> 5));
        }
        let number = rest[0] & 0x1F;
        let n = Kind::payload_len(number).ok_or(Damage::Kind(number))?;
        if rest.len() != 9 + n {
            return Err(Damage::Length);
        }
        if check(rest) != last {
            return Err(Damage::Check);
        }
        let mut at = [0u8; 8];
        at.copy_from_slice(&rest[1..9]);
        let cycles = u64::from_le_bytes(at);
        let p = &rest[9..];
        let u32_at = |i: usize| u32::from_le_bytes([p[i], p[i + 1], p[i + 2], p[i + 3]]);
        let kind = match number {
            0 => Kind::Hello {
                clock_hz: u32_at(0),
            },
            1 => Kind::TaskStart { task: p[0] },
            2 => Kind::TaskEnd {
                task: p[0],
                next_release_in_us: u32_at(1),
            },
            3 => {
                let mut record = [0u8; EVENT_LEN];
                record.copy_from_slice(p);
                Kind::Event { record }
            }
            4 => Kind::FrameAcked {
                id: u16::from_le_bytes([p[0], p[1]]),
            },
            _ => Kind::Lost { count: u32_at(0) },
        };
        Ok(Record { cycles, kind })
    }
}

/// Why a stretch of bytes between two delimiters was not a record.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Damage {
    /// Nothing between two delimiters.
    Empty,
    /// Shorter than a header.
    Short,
    /// Longer than any record (garbage, or records run together after a lost delimiter).
    Long,
    /// Not valid COBS.
    Cobs,
    /// Another format version.
    Version(u8),
    /// A kind number this version does not have.
    Kind(u8),
    /// The payload length does not fit the kind.
    Length,
    /// The check byte does not fit.
    Check,
}

/// What the reader found so far besides records.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ReaderStats {
    /// Records read.
    pub records: u64,
    /// Stretches skipped as damaged (an empty stretch between two delimiters is not counted).
    pub damaged: u64,
    /// Bytes skipped (in damaged stretches).
    pub skipped_bytes: u64,
}

/// A resynchronising stream reader: push bytes in any chunks, take records out. Allocation-free;
/// holds at most one record's worth of bytes.
#[derive(Clone, Debug)]
pub struct Reader {
    buf: [u8; MAX_WIRE],
    len: usize,
    overlong: bool,
    stats: ReaderStats,
}

impl Default for Reader {
    fn default() -> Self {
        Self::new()
    }
}

impl Reader {
    /// A reader at the start of a stream (or anywhere in one: it finds the next record).
    pub const fn new() -> Self {
        Self {
            buf: [0; MAX_WIRE],
            len: 0,
            overlong: false,
            stats: ReaderStats {
                records: 0,
                damaged: 0,
                skipped_bytes: 0,
            },
        }
    }

    /// Counts so far.
    pub fn stats(&self) -> ReaderStats {
        self.stats
    }

    /// Feeds one byte; returns the record it completes, if any.
    pub fn push(&mut self, byte: u8) -> Option<Record> {
        if byte != 0 {
            if self.len < self.buf.len() {
                self.buf[self.len] = byte;
                self.len += 1;
            } else {
                self.overlong = true;
                self.stats.skipped_bytes += 1;
            }
            return None;
        }
        let len = core::mem::replace(&mut self.len, 0);
        let overlong = core::mem::replace(&mut self.overlong, false);
        if len == 0 && !overlong {
            return None;
        }
        let result = if overlong {
            Err(Damage::Long)
        } else {
            decode_cobs(&self.buf[..len]).and_then(|(body, n)| Record::from_body(&body[..n]))
        };
        match result {
            Ok(record) => {
                self.stats.records += 1;
                Some(record)
            }
            Err(_) => {
                self.stats.damaged += 1;
                self.stats.skipped_bytes += len as u64 + 1;
                None
            }
        }
    }
}

/// Undoes COBS on one stretch (without its delimiter).
fn decode_cobs(wire: &[u8]) -> Result<([u8; MAX_WIRE], usize), Damage> {
    let mut out = [0u8; MAX_WIRE];
    let mut n = 0;
    let mut at = 0;
    while at < wire.len() {
        let code = usize::from(wire[at]);
        if code == 0 || at + code > wire.len() {
            return Err(Damage::Cobs);
        }
        for &b in &wire[at + 1..at + code] {
            out[n] = b;
            n += 1;
        }
        at += code;
        if at < wire.len() {
            // A group shorter than 255 stands for a zero (bodies never need 255-byte groups).
            out[n] = 0;
            n += 1;
        }
    }
    if n > MAX_BODY {
        return Err(Damage::Long);
    }
    Ok((out, n))
}

/// Every record in `bytes` (a whole capture), damage skipped.
pub fn records(bytes: &[u8]) -> impl Iterator<Item = Record> + '_ {
    let mut reader = Reader::new();
    bytes.iter().filter_map(move |&b| reader.push(b))
}
