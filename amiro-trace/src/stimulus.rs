//! The single-board QEMU stimulus: what `cargo xtask qemu` (and the bench, the scenarios) hand a
//! board's QEMU build to replay on its bus, and what the build reads back through semihosting
//! (`stimulus.bin`). Both sides encode and decode the records here, beside [`crate::robot_link`]'s
//! exchange of a robot run, so they cannot drift apart.
//!
//! ```text
//! header  16 bytes   "AMSTIM1\0", u64 duration in µs (little-endian)
//! record  20 bytes   u64 µs from the start of the run, u16 identifier, u8 length, u8 flags,
//!                    8 data bytes (the first `length` used)
//! ```
//!
//! Flags: bit 0 marks a frame the protocol cannot carry (an extended identifier; its identifier reads
//! `0xFFFF`, which the boards' decoder rejects as it must), bit 1 a SYS_PD_N shutdown request (no
//! frame). Records come in time order; those after the duration are not replayed.

use crate::robot_link::le_u64;

/// The header's first eight bytes.
pub const MAGIC: [u8; 8] = *b"AMSTIM1\0";
/// The header's size.
pub const HEADER_LEN: usize = 16;
/// A record's size.
pub const RECORD_LEN: usize = 20;
/// The identifier a record carries for a frame with an extended identifier.
pub const UNCARRIED_ID: u16 = 0xFFFF;

const FLAG_UNCARRIED: u8 = 1;
const FLAG_SHUTDOWN: u8 = 2;

/// What happens at a record's time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Event {
    /// A frame arrives in the board's receive FIFO.
    Frame {
        /// Standard identifier, or [`UNCARRIED_ID`] for a frame with an extended one.
        id: u16,
        /// Data length (0..=8).
        len: u8,
        /// Data, `len` bytes of it used.
        data: [u8; 8],
    },
    /// SYS_PD_N falls (a shutdown request from outside the board).
    ShutdownRequest,
}

impl Event {
    /// A frame from its identifier (an extended one, above `0x7FF`, becomes [`UNCARRIED_ID`]) and
    /// its data bytes, of which a record holds the first 8 (a classic frame carries no more).
    pub fn frame(id: u32, bytes: &[u8]) -> Self {
        let len = bytes.len().min(8);
        let mut data = [0; 8];
        data[..len].copy_from_slice(&bytes[..len]);
        Event::Frame {
            id: u16::try_from(id)
                .ok()
                .filter(|&id| id <= 0x7FF)
                .unwrap_or(UNCARRIED_ID),
            len: len as u8,
            data,
        }
    }
}

/// One record: an event and when it happens.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Record {
    /// Microseconds of virtual time from the start of the run.
    pub at_us: u64,
    /// What happens.
    pub event: Event,
}

/// Why bytes are not a stimulus.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StimulusError {
    /// Fewer than [`HEADER_LEN`] bytes, or no `AMSTIM1` magic.
    NoHeader,
    /// The records are not a whole number of [`RECORD_LEN`]-byte records (`bytes` of them).
    CutRecord {
        /// The bytes after the header.
        bytes: usize,
    },
    /// A record's data length is above 8.
    BadLength(u8),
    /// A record's flags name nothing this version knows (or both a frame and a signal).
    BadFlags(u8),
}

impl core::fmt::Display for StimulusError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::NoHeader => f.write_str("no AMSTIM1 header"),
            Self::CutRecord { bytes } => {
                write!(
                    f,
                    "{bytes} bytes of records: not whole {RECORD_LEN}-byte records"
                )
            }
            Self::BadLength(len) => write!(f, "a record of {len} data bytes (at most 8)"),
            Self::BadFlags(flags) => write!(f, "a record with unknown flags {flags:#04x}"),
        }
    }
}

/// The header of a stimulus that runs for `duration_us`.
pub fn encode_header(duration_us: u64) -> [u8; HEADER_LEN] {
    let mut out = [0; HEADER_LEN];
    out[..8].copy_from_slice(&MAGIC);
    out[8..].copy_from_slice(&duration_us.to_le_bytes());
    out
}

/// The run's duration in µs from a header.
pub fn decode_header(bytes: &[u8; HEADER_LEN]) -> Result<u64, StimulusError> {
    if bytes[..8] != MAGIC {
        return Err(StimulusError::NoHeader);
    }
    Ok(le_u64(&bytes[8..]))
}

impl Record {
    /// The record's bytes.
    pub fn encode(&self) -> [u8; RECORD_LEN] {
        let mut out = [0; RECORD_LEN];
        out[..8].copy_from_slice(&self.at_us.to_le_bytes());
        let (id, len, flags, data) = match self.event {
            Event::Frame { id, len, data } => {
                let flags = if id == UNCARRIED_ID {
                    FLAG_UNCARRIED
                } else {
                    0
                };
                (id, len.min(8), flags, data)
            }
            Event::ShutdownRequest => (UNCARRIED_ID, 0, FLAG_SHUTDOWN, [0; 8]),
        };
        out[8..10].copy_from_slice(&id.to_le_bytes());
        out[10] = len;
        out[11] = flags;
        out[12..].copy_from_slice(&data);
        out
    }

    /// A record from its bytes.
    pub fn decode(bytes: &[u8; RECORD_LEN]) -> Result<Self, StimulusError> {
        let at_us = le_u64(&bytes[..8]);
        let (len, flags) = (bytes[10], bytes[11]);
        let event = match flags {
            FLAG_SHUTDOWN => Event::ShutdownRequest,
            0 | FLAG_UNCARRIED if len > 8 => return Err(StimulusError::BadLength(len)),
            0 | FLAG_UNCARRIED => {
                let mut data = [0; 8];
                data.copy_from_slice(&bytes[12..]);
                Event::Frame {
                    id: u16::from_le_bytes([bytes[8], bytes[9]]),
                    len,
                    data,
                }
            }
            other => return Err(StimulusError::BadFlags(other)),
        };
        Ok(Self { at_us, event })
    }
}

/// A whole stimulus in memory: its duration and its records in file order (a host reading a file;
/// the firmware reads record by record with [`decode_header`] and [`Record::decode`]).
pub fn decode(bytes: &[u8]) -> Result<(u64, Records<'_>), StimulusError> {
    let (header, records) = bytes
        .split_first_chunk::<HEADER_LEN>()
        .ok_or(StimulusError::NoHeader)?;
    let duration = decode_header(header)?;
    if records.len() % RECORD_LEN != 0 {
        return Err(StimulusError::CutRecord {
            bytes: records.len(),
        });
    }
    Ok((duration, Records(records)))
}

/// The records of a stimulus ([`decode`]).
#[derive(Debug, Clone)]
pub struct Records<'a>(&'a [u8]);

impl Iterator for Records<'_> {
    type Item = Result<Record, StimulusError>;

    fn next(&mut self) -> Option<Self::Item> {
        let (record, rest) = self.0.split_first_chunk::<RECORD_LEN>()?;
        self.0 = rest;
        Some(Record::decode(record))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_round_trip_and_keep_their_layout() {
        let frame = Record {
            at_us: 5,
            event: Event::frame(0x205, &[1, 2]),
        };
        let bytes = frame.encode();
        assert_eq!(
            &bytes[..14],
            &[5, 0, 0, 0, 0, 0, 0, 0, 0x05, 0x02, 2, 0, 1, 2]
        );
        assert_eq!(Record::decode(&bytes), Ok(frame));
        let extended = Record {
            at_us: 6,
            event: Event::frame(0x1234_5678, &[]),
        };
        assert_eq!(&extended.encode()[8..12], &[0xFF, 0xFF, 0, 1]);
        assert_eq!(Record::decode(&extended.encode()), Ok(extended));
        let shutdown = Record {
            at_us: 7,
            event: Event::ShutdownRequest,
        };
        assert_eq!(shutdown.encode()[11], 2);
        assert_eq!(Record::decode(&shutdown.encode()), Ok(shutdown));
        assert_eq!(
            Event::frame(0x205, &[7; 9]),
            Event::Frame {
                id: 0x205,
                len: 8,
                data: [7; 8]
            }
        );
    }

    #[test]
    fn a_whole_stimulus_and_what_is_not_one() {
        let mut bin = encode_header(2_000_000).to_vec();
        bin.extend_from_slice(
            &Record {
                at_us: 10,
                event: Event::frame(0x205, &[1]),
            }
            .encode(),
        );
        let (duration, records) = decode(&bin).unwrap();
        assert_eq!(duration, 2_000_000);
        assert_eq!(records.map(|r| r.unwrap().at_us).collect::<Vec<_>>(), [10]);
        assert_eq!(
            decode(&bin[..bin.len() - 1]).err(),
            Some(StimulusError::CutRecord { bytes: 19 })
        );
        assert_eq!(decode(b"AMSTIM").err(), Some(StimulusError::NoHeader));
        assert_eq!(
            decode(b"AMSTIM2\0\0\0\0\0\0\0\0\0").err(),
            Some(StimulusError::NoHeader)
        );
        let mut record = [0u8; RECORD_LEN];
        record[10] = 9;
        assert_eq!(Record::decode(&record), Err(StimulusError::BadLength(9)));
        record[10] = 0;
        record[11] = 4;
        assert_eq!(Record::decode(&record), Err(StimulusError::BadFlags(4)));
        record[11] = 3;
        assert_eq!(Record::decode(&record), Err(StimulusError::BadFlags(3)));
    }
}
