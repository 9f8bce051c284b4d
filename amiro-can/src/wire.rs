//! Little-endian byte helpers shared by the encoders and decoders; none of them can panic.

use crate::error::DecodeError;
use crate::frame::Frame;
use crate::id::{CanId, Kind};
use crate::topic::Topic;

/// A frame from a buffer whose used length the caller chose (always 0..=8 in this crate).
pub(crate) const fn frame(id: CanId, len: u8, data: [u8; 8]) -> Frame {
    Frame::from_valid(id, len, data)
}

/// The DLC of `data` for error reports; a slice longer than 255 bytes reports 255.
pub(crate) fn dlc(data: &[u8]) -> u8 {
    u8::try_from(data.len()).unwrap_or(u8::MAX)
}

/// The data as exactly `N` bytes, or the too-short / too-long error for `topic`.
pub(crate) fn exact<const N: usize>(
    topic: Topic,
    frame: Kind,
    data: &[u8],
) -> Result<[u8; N], DecodeError> {
    // N is a topic's DLC, at most 8, so the cast is exact.
    let expected = N as u8;
    <[u8; N]>::try_from(data).map_err(|_| {
        if data.len() < N {
            DecodeError::DlcTooShort {
                topic,
                frame,
                dlc: dlc(data),
                expected,
            }
        } else {
            DecodeError::DlcTooLong {
                topic,
                frame,
                dlc: dlc(data),
                expected,
            }
        }
    })
}

/// Two i32 little-endian, as used by velocity and motor command.
pub(crate) fn two_i32(a: i32, b: i32) -> [u8; 8] {
    let [a0, a1, a2, a3] = a.to_le_bytes();
    let [b0, b1, b2, b3] = b.to_le_bytes();
    [a0, a1, a2, a3, b0, b1, b2, b3]
}

/// The inverse of [`two_i32`].
pub(crate) fn split_two_i32(bytes: [u8; 8]) -> (i32, i32) {
    let [a0, a1, a2, a3, b0, b1, b2, b3] = bytes;
    (
        i32::from_le_bytes([a0, a1, a2, a3]),
        i32::from_le_bytes([b0, b1, b2, b3]),
    )
}
