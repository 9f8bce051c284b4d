//! The robot link: what a board's QEMU build and `cargo xtask robot`'s host exchange every quantum
//! over the board's semihosting files (docs/qemu.md, "The whole robot"). Both sides encode and
//! decode the messages here ([`Up`], [`Down`]), so they cannot drift apart.

/// The exchange period in virtual µs: a multiple of the 10 µs tick below the shortest frame (44 bit
/// times from start of frame to completion at 1 Mbit/s).
pub const QUANTUM_US: u64 = 40;
/// Board → host, [`Up`]: `u64` now, `u8` new frames, `u8` lines driven, `u8` abort requests, `u8`
/// flags ([`UP_WHEELS`]), `u32` µs the board sleeps from now, three 28-byte records (`u64` queued at, `u16` id,
/// `u8` length, `u8` mailbox, 8 data bytes, `u64` released at), `u64` the boundary it reports at,
/// `u8` frames the board completed itself under a grant (7 reserved). Those frames follow the
/// report, [`DONE_LEN`] bytes each ([`Done`]), then the wheels if [`UP_WHEELS`].
pub const UP_LEN: usize = 16 + MAILBOXES * RECORD_LEN + 8 + 8;
/// A frame the board completed itself ([`Done`]): a 28-byte record as in [`Up`], then `u64` its
/// completion.
pub const DONE_LEN: usize = RECORD_LEN + 8;
/// The most frames a board completes itself between two reports ([`Down::free_until_us`]): a
/// board whose record is full reports.
pub const MAX_DONE: usize = 8;
/// Host → board, [`Down`]: `u64` completion time, `u8` flags, `u8` mailbox, `u16` id, `u8` length,
/// `u8` aborted mailboxes, `u8` the mailboxes the host holds a frame of the board's in, 1 reserved,
/// 8 data bytes, `u64` time of the next exchange, `u64` the grant's end, `u64` when the bus is idle.
pub const DOWN_LEN: usize = 48;
/// A board's transmit mailboxes (bxCAN's three).
pub const MAILBOXES: usize = 3;
const RECORD_LEN: usize = 28;
/// Where [`Up::at_us`] lies in the message (the done count after it).
const AT: usize = 16 + MAILBOXES * RECORD_LEN;

/// Up: this board pulls SYS_SYNC_N low.
pub const DRIVES_SYNC_LOW: u8 = 1;
/// Up: this board drives SYS_PD_N low.
pub const DRIVES_PD_LOW: u8 = 2;
/// Up flag: the board's wheel ticks follow this report (`world_link::Wheels`, `WHEELS_LEN`
/// bytes): the DiWheelDrive in a run with a world (docs/world.md).
pub const UP_WHEELS: u8 = 1;
/// Down: a frame completes in this quantum.
pub const DOWN_FRAME: u8 = 1;
/// Down: the frame is this board's own (its mailbox is free at the completion time).
pub const DOWN_OWN: u8 = 2;
/// Down: SYS_PD_N reads low.
pub const DOWN_PD_LOW: u8 = 4;
/// Down: SYS_SYNC_N reads low.
pub const DOWN_SYNC_LOW: u8 = 8;
/// Down: the run is over.
pub const DOWN_END: u8 = 16;
/// Down: run ahead to `next_us`, but report at the first boundary after the board puts a frame
/// into a mailbox, asks for an abort or changes a line it drives (the host sends the one board
/// with work ahead this way while everything else is quiet; docs/qemu.md, "Lookahead").
pub const DOWN_EARLY: u8 = 32;
/// Down: the world's readings for this board follow the answer (`world_link::Readings`,
/// `READINGS_LEN` bytes); its simulators take them before the drivers next read.
pub const DOWN_READINGS: u8 = 64;
/// Down: restart the board (a system reset through SCB AIRCR's SYSRESETREQ, in the same QEMU, which
/// keeps the code it has translated): a live run's warm-up ends with it, so code the boards ran
/// then costs no translation once the wall clock runs (docs/qemu.md, "Live"). The board boots as
/// from power-on and makes its first exchange at its first boundary.
pub const DOWN_RESTART: u8 = 128;

/// Whether a board's software ever sees a frame with identifier `id` that another node sent: the
/// boards' bxCAN receive filter passes only command frames (bit 10, C/S, clear;
/// `amiro_firmware::bxcan::passes_filter`, whose test holds the two equal). The host relies on it
/// to leave a sleeping board out of an exchange while sensor frames go over the bus (docs/qemu.md,
/// "Lookahead"): such a board is only brought to a boundary for a frame that passes, for its own
/// frame's completion, an abort, a line level or the end of the run.
pub const fn reaches_software(id: u16) -> bool {
    id & 0x400 == 0
}

/// A frame a board put into one of its mailboxes since its last report.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Queued {
    /// When it entered the mailbox (the board's virtual µs).
    pub at_us: u64,
    /// When it entered the board's transmit queue, before it waited for a mailbox (the driver gives
    /// one frame of an identifier a mailbox at a time): where its response starts.
    pub released_us: u64,
    /// Standard identifier.
    pub id: u16,
    /// Data length (0..=8).
    pub len: u8,
    /// The mailbox (0..3).
    pub mailbox: u8,
    /// Data, `len` bytes of it used.
    pub data: [u8; 8],
}

impl Queued {
    /// The data bytes in use.
    pub fn payload(&self) -> &[u8] {
        &self.data[..usize::from(self.len.min(8))]
    }
}

/// A board's report at the end of a quantum.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Up {
    /// The board's virtual time, µs.
    pub now_us: u64,
    /// The system lines it drives ([`DRIVES_SYNC_LOW`], [`DRIVES_PD_LOW`]).
    pub drives: u8,
    /// Bit `k`: abort mailbox `k`'s frame (bxCAN's ABRQ: the driver displaces its least urgent
    /// frame for a more urgent one when all three mailboxes are full).
    pub aborts: u8,
    /// How long it will do nothing, µs from now (0: it has work; `u32::MAX`: no deadline).
    pub sleeps_us: u32,
    /// [`UP_WHEELS`]: what follows the report.
    pub flags: u8,
    /// The boundary this report is for (the board's virtual µs, a multiple of [`QUANTUM_US`]):
    /// the one the host sent it to, or an earlier one after [`DOWN_EARLY`].
    pub at_us: u64,
    /// Frames it queued since its last report: the first `count` of `frames`.
    pub count: u8,
    /// The frames.
    pub frames: [Queued; MAILBOXES],
    /// How many frames it completed itself under a grant since its last report (at most
    /// [`MAX_DONE`]): as many [`Done`] records follow the report, in the order they started.
    pub done: u8,
}

/// A frame a board completed itself while granted the bus ([`Down::free_until_us`]): it started
/// before the grant's end, so nothing else could compete with it; the host puts it through its
/// bus model at its queueing time and checks the completion.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Done {
    /// The frame, its mailbox and its queueing and release times.
    pub frame: Queued,
    /// Its completion (end of frame) as the board computed it, the board's virtual µs.
    pub completed_us: u64,
}

impl Done {
    /// The record's bytes.
    pub fn encode(&self) -> [u8; DONE_LEN] {
        let mut m = [0u8; DONE_LEN];
        encode_record(&self.frame, &mut m[..RECORD_LEN]);
        m[RECORD_LEN..].copy_from_slice(&self.completed_us.to_le_bytes());
        m
    }

    /// The record in `m` (a length above 8 is read as 8).
    pub fn decode(m: &[u8; DONE_LEN]) -> Done {
        Done {
            frame: decode_record(&m[..RECORD_LEN]),
            completed_us: le_u64(&m[RECORD_LEN..]),
        }
    }
}

fn encode_record(q: &Queued, r: &mut [u8]) {
    r[..8].copy_from_slice(&q.at_us.to_le_bytes());
    r[8..10].copy_from_slice(&q.id.to_le_bytes());
    r[10] = q.len.min(8);
    r[11] = q.mailbox;
    r[12..20].copy_from_slice(&q.data);
    r[20..28].copy_from_slice(&q.released_us.to_le_bytes());
}

fn decode_record(r: &[u8]) -> Queued {
    let mut data = [0u8; 8];
    data.copy_from_slice(&r[12..20]);
    Queued {
        at_us: le_u64(&r[..8]),
        released_us: le_u64(&r[20..28]),
        id: u16::from_le_bytes([r[8], r[9]]),
        len: r[10].min(8),
        mailbox: r[11],
        data,
    }
}

impl Up {
    /// The frames queued since the last report.
    pub fn queued(&self) -> &[Queued] {
        &self.frames[..usize::from(self.count).min(MAILBOXES)]
    }

    /// Adds a queued frame (`false`: already three).
    pub fn push(&mut self, frame: Queued) -> bool {
        let Some(slot) = self.frames.get_mut(usize::from(self.count)) else {
            return false;
        };
        *slot = frame;
        self.count += 1;
        true
    }

    /// The message's bytes.
    pub fn encode(&self) -> [u8; UP_LEN] {
        let mut m = [0u8; UP_LEN];
        m[..8].copy_from_slice(&self.now_us.to_le_bytes());
        m[8] = self.count.min(MAILBOXES as u8);
        m[9] = self.drives;
        m[10] = self.aborts;
        m[11] = self.flags;
        m[12..16].copy_from_slice(&self.sleeps_us.to_le_bytes());
        for (k, q) in self.queued().iter().enumerate() {
            encode_record(q, &mut m[16 + RECORD_LEN * k..16 + RECORD_LEN * (k + 1)]);
        }
        m[AT..AT + 8].copy_from_slice(&self.at_us.to_le_bytes());
        m[AT + 8] = self.done.min(MAX_DONE as u8);
        m
    }

    /// The message in `m` (a count above three is read as three, a length above 8 as 8, more
    /// completed frames than [`MAX_DONE`] as [`MAX_DONE`]).
    pub fn decode(m: &[u8; UP_LEN]) -> Up {
        let mut up = Up {
            now_us: le_u64(&m[..8]),
            drives: m[9],
            aborts: m[10],
            flags: m[11],
            sleeps_us: u32::from_le_bytes([m[12], m[13], m[14], m[15]]),
            at_us: le_u64(&m[AT..AT + 8]),
            count: m[8].min(MAILBOXES as u8),
            frames: [Queued::default(); MAILBOXES],
            done: m[AT + 8].min(MAX_DONE as u8),
        };
        for (k, q) in up.frames.iter_mut().enumerate().take(usize::from(up.count)) {
            *q = decode_record(&m[16 + RECORD_LEN * k..16 + RECORD_LEN * (k + 1)]);
        }
        up
    }

    /// The bytes of [`Done`] records that follow this report.
    pub fn done_len(&self) -> usize {
        usize::from(self.done.min(MAX_DONE as u8)) * DONE_LEN
    }
}

/// The host's answer to a report.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Down {
    /// [`DOWN_FRAME`], [`DOWN_OWN`], [`DOWN_PD_LOW`], [`DOWN_SYNC_LOW`], [`DOWN_END`].
    pub flags: u8,
    /// With [`DOWN_FRAME`]: when the frame completes (the board's virtual µs).
    pub at_us: u64,
    /// With [`DOWN_OWN`]: the mailbox it left.
    pub mailbox: u8,
    /// With [`DOWN_FRAME`]: the frame's identifier, length and data.
    pub id: u16,
    /// Its length (0..=8).
    pub len: u8,
    /// Its data, `len` bytes of it used.
    pub data: [u8; 8],
    /// Bit `k`: mailbox `k`'s frame was aborted before its transmission started (it is free now,
    /// and the board's transmit interrupt hands the frame back). An abort that comes too late is
    /// not answered: the frame completes as it would have.
    pub aborted: u8,
    /// The board's virtual time of the next exchange (0: one quantum on). A sleeping board may be
    /// sent several quanta on (it does nothing before its deadline but on a frame or a line level,
    /// which come only through an exchange), and its answer may come late: the host keeps a board
    /// that sleeps past the next boundary waiting in its read until it is needed, then answers with
    /// the boundary it must run to (it runs there idle and reports again, then gets what is due).
    pub next_us: u64,
    /// With [`DOWN_EARLY`], a grant of the bus (0: none; the board's virtual µs): no other node
    /// can have a frame pending before this time, so a sensor frame (one no board's software
    /// hears, [`reaches_software`]) the board queues and whose transmission starts before it is
    /// arbitrated and completed by the board itself, exactly as the host's bus model would: it
    /// reports it later as a [`Done`] record instead of at the next boundary (docs/qemu.md,
    /// "Lookahead").
    pub free_until_us: u64,
    /// With a grant: when the bus is idle (after the frame in progress and its intermission, or
    /// the board's own hold), the board's virtual µs.
    pub idle_from_us: u64,
    /// With a grant: bit `k`, the host's bus model holds a frame of the board's in mailbox `k`
    /// (one the board handed over that has not started).
    pub held: u8,
}

impl Down {
    /// The message's bytes.
    pub fn encode(&self) -> [u8; DOWN_LEN] {
        let mut m = [0u8; DOWN_LEN];
        m[..8].copy_from_slice(&self.at_us.to_le_bytes());
        m[8] = self.flags;
        m[9] = self.mailbox;
        m[10..12].copy_from_slice(&self.id.to_le_bytes());
        m[12] = self.len.min(8);
        m[13] = self.aborted;
        m[14] = self.held;
        m[16..24].copy_from_slice(&self.data);
        m[24..32].copy_from_slice(&self.next_us.to_le_bytes());
        m[32..40].copy_from_slice(&self.free_until_us.to_le_bytes());
        m[40..48].copy_from_slice(&self.idle_from_us.to_le_bytes());
        m
    }

    /// The message in `m` (a length above 8 is read as 8).
    pub fn decode(m: &[u8; DOWN_LEN]) -> Down {
        let mut data = [0u8; 8];
        data.copy_from_slice(&m[16..24]);
        Down {
            flags: m[8],
            at_us: le_u64(&m[..8]),
            mailbox: m[9],
            id: u16::from_le_bytes([m[10], m[11]]),
            len: m[12].min(8),
            data,
            aborted: m[13],
            next_us: le_u64(&m[24..32]),
            held: m[14],
            free_until_us: le_u64(&m[32..40]),
            idle_from_us: le_u64(&m[40..48]),
        }
    }
}

pub(crate) fn le_u64(bytes: &[u8]) -> u64 {
    let mut b = [0u8; 8];
    b.copy_from_slice(&bytes[..8]);
    u64::from_le_bytes(b)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_report_survives_the_link() {
        let mut up = Up {
            now_us: 123_456_789,
            drives: DRIVES_SYNC_LOW | DRIVES_PD_LOW,
            aborts: 0b100,
            sleeps_us: u32::MAX,
            flags: UP_WHEELS,
            at_us: 123_456_760,
            done: 5,
            ..Up::default()
        };
        for k in 0..MAILBOXES as u8 {
            assert!(up.push(Queued {
                at_us: 1_000 + u64::from(k),
                released_us: 900 + u64::from(k),
                id: 0x61F - u16::from(k),
                len: 2 + k,
                mailbox: 2 - k,
                data: [k; 8],
            }));
        }
        assert!(!up.push(Queued::default()), "three at most");
        let bytes = up.encode();
        assert_eq!(Up::decode(&bytes), up);
        // The layout both sides read: count, lines, aborts, then the records.
        assert_eq!(&bytes[8..11], &[3, 3, 0b100]);
        assert_eq!(&bytes[16 + 8..16 + 12], &[0x1F, 0x06, 2, 2]);
        assert_eq!(up.queued()[1].payload(), &[1, 1, 1]);
        assert_eq!(&bytes[AT..AT + 8], &123_456_760u64.to_le_bytes());
        assert_eq!(bytes[AT + 8], 5);
        assert_eq!(up.done_len(), 5 * DONE_LEN);
    }

    #[test]
    fn a_completed_frame_survives_the_link() {
        let done = Done {
            frame: Queued {
                at_us: 40_123,
                released_us: 40_100,
                id: 0x605,
                len: 4,
                mailbox: 2,
                data: [9, 8, 7, 6, 0, 0, 0, 0],
            },
            completed_us: 40_201,
        };
        let bytes = done.encode();
        assert_eq!(Done::decode(&bytes), done);
        assert_eq!(&bytes[RECORD_LEN..], &40_201u64.to_le_bytes());
        assert_eq!(&bytes[8..12], &[0x05, 0x06, 4, 2]);
    }

    #[test]
    fn an_answer_survives_the_link() {
        let down = Down {
            flags: DOWN_FRAME | DOWN_OWN | DOWN_SYNC_LOW | DOWN_EARLY | DOWN_READINGS,
            at_us: 987_654,
            mailbox: 1,
            id: 0x605,
            len: 4,
            data: [1, 2, 3, 4, 0, 0, 0, 0],
            aborted: 0b011,
            next_us: 1_000_040,
            held: 0b101,
            free_until_us: 1_900_000,
            idle_from_us: 1_000_013,
        };
        assert_eq!(Down::decode(&down.encode()), down);
    }

    #[test]
    fn garbage_decodes_within_bounds() {
        let up = Up::decode(&[0xFF; UP_LEN]);
        assert_eq!(up.queued().len(), MAILBOXES);
        assert!(up.queued().iter().all(|q| q.payload().len() == 8));
        assert_eq!(Down::decode(&[0xFF; DOWN_LEN]).len, 8);
        assert_eq!(Up::decode(&[0xFF; UP_LEN]).done_len(), MAX_DONE * DONE_LEN);
        assert_eq!(Done::decode(&[0xFF; DONE_LEN]).frame.payload().len(), 8);
    }
}
