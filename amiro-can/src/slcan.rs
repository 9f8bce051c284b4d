//! A frame in SLCAN (the Lawicel ASCII protocol of USB-CAN adapters): `tIIILDD…` (standard data),
//! `TIIIIIIIILDD…` (extended), `rIIIL`/`RIIIIIIIIL` (remote), optionally followed by a 4-hex-digit
//! adapter timestamp in milliseconds (after `Z1`), ended by `\r`. The one encoder and decoder of a
//! frame's SLCAN text: the operator's `slcan:` bus (the host side of an adapter) and the robot
//! host's emulated adapter (`cargo xtask robot --slcan`) both use them. The command set around the
//! frames (`O`, `C`, `S8`, answers `\r`, `z`, BEL) is each side's own.
//!
//! `no_std`, allocation-free; malformed text is a [`SlcanError`].

use crate::candump::{hex_value, Cursor, FrameId, RawFrame};

/// The longest frame message: `T`, 8 identifier digits, the length, 16 data digits, 4 timestamp
/// digits, `\r`.
pub const MAX_FRAME_MESSAGE: usize = 1 + 8 + 1 + 16 + 4 + 1;

/// Why a message is not an SLCAN frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SlcanError {
    /// The first byte is none of `t`, `T`, `r`, `R`.
    NotAFrame,
    /// The identifier digits are missing or not hex.
    BadIdentifier,
    /// A standard identifier above `7FF` or an extended one above `1FFFFFFF`.
    IdentifierOutOfRange,
    /// The length is not one digit 0..=8.
    BadLength,
    /// The data digits are missing or not hex.
    BadData,
    /// What follows the data is neither nothing nor a 4-hex-digit timestamp.
    BadTimestamp,
}

impl core::fmt::Display for SlcanError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            Self::NotAFrame => "not an SLCAN frame (t, T, r or R)",
            Self::BadIdentifier => "bad identifier digits",
            Self::IdentifierOutOfRange => "identifier out of range",
            Self::BadLength => "bad length digit (0..8)",
            Self::BadData => "bad data digits",
            Self::BadTimestamp => "bad text after the data (a timestamp is 4 hex digits)",
        })
    }
}

/// Decodes a frame message (without its `\r`): the frame and its adapter timestamp, if it has one.
pub fn decode_frame(message: &[u8]) -> Result<(RawFrame, Option<u16>), SlcanError> {
    let (id_digits, remote) = match message.first() {
        Some(b't') => (3, false),
        Some(b'r') => (3, true),
        Some(b'T') => (8, false),
        Some(b'R') => (8, true),
        _ => return Err(SlcanError::NotAFrame),
    };
    let id_value = hex_number(message.get(1..1 + id_digits)).ok_or(SlcanError::BadIdentifier)?;
    let id = if id_digits == 3 {
        FrameId::Standard(id_value as u16)
    } else {
        FrameId::Extended(id_value)
    };
    let len = match message.get(1 + id_digits) {
        Some(d @ b'0'..=b'8') => d - b'0',
        _ => return Err(SlcanError::BadLength),
    };
    let body = &message[2 + id_digits..];
    let data_digits = if remote { 0 } else { 2 * usize::from(len) };
    let data_text = body.get(..data_digits).ok_or(SlcanError::BadData)?;
    let mut data = [0u8; 8];
    for (slot, pair) in data.iter_mut().zip(data_text.chunks_exact(2)) {
        *slot = hex_number(Some(pair)).ok_or(SlcanError::BadData)? as u8;
    }
    let timestamp = match &body[data_digits..] {
        [] => None,
        digits @ [_, _, _, _] => {
            Some(hex_number(Some(digits)).ok_or(SlcanError::BadTimestamp)? as u16)
        }
        _ => return Err(SlcanError::BadTimestamp),
    };
    let frame = if remote {
        RawFrame::remote_frame(id, len)
    } else {
        RawFrame::data_frame(id, &data[..usize::from(len)])
    };
    Ok((frame.ok_or(SlcanError::IdentifierOutOfRange)?, timestamp))
}

/// Encodes a frame message, `\r` included, with an adapter timestamp (ms, taken modulo 60 000 as
/// adapters count) if given; returns its length in `out`.
pub fn encode_frame(
    frame: &RawFrame,
    timestamp_ms: Option<u16>,
    out: &mut [u8; MAX_FRAME_MESSAGE],
) -> usize {
    let mut cursor = Cursor::new(out);
    let (data_letter, remote_letter, digits) = match frame.id() {
        FrameId::Standard(_) => (b't', b'r', 3),
        FrameId::Extended(_) => (b'T', b'R', 8),
    };
    cursor.byte(if frame.is_remote() {
        remote_letter
    } else {
        data_letter
    });
    cursor.hex(frame.id().raw(), digits);
    cursor.byte(b'0' + frame.len());
    for &b in frame.data() {
        cursor.hex(u32::from(b), 2);
    }
    if let Some(ms) = timestamp_ms {
        cursor.hex(u32::from(ms % 60_000), 4);
    }
    cursor.byte(b'\r');
    cursor.at
}

/// The value of `digits` read as hex; `None` if absent, empty or not all hex.
fn hex_number(digits: Option<&[u8]>) -> Option<u32> {
    let digits = digits.filter(|d| !d.is_empty())?;
    digits.iter().try_fold(0u32, |value, &b| {
        Some(value << 4 | u32::from(hex_value(b)?))
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::candump::parse_compact;

    fn encoded(frame: &str, timestamp: Option<u16>) -> String {
        let mut out = [0u8; MAX_FRAME_MESSAGE];
        let n = encode_frame(&parse_compact(frame).unwrap(), timestamp, &mut out);
        String::from_utf8(out[..n].to_vec()).unwrap()
    }

    #[test]
    fn frames_as_adapters_write_them() {
        // The forms of the Lawicel manual, as python-can's slcan interface and slcand write them.
        assert_eq!(encoded("205#01840302", None), "t205401840302\r");
        assert_eq!(encoded("12345678#AA", None), "T123456781AA\r");
        assert_eq!(encoded("205#R4", None), "r2054\r");
        assert_eq!(encoded("1FFFFFFF#R", None), "R1FFFFFFF0\r");
        assert_eq!(encoded("605#AB", Some(1234)), "t6051AB04D2\r");
        assert_eq!(encoded("605#", Some(60_001)), "t60500001\r");
    }

    #[test]
    fn frames_decode_and_malformed_ones_are_typed_errors() {
        let frame = |text: &str| parse_compact(text).unwrap();
        assert_eq!(
            decode_frame(b"t205401840302"),
            Ok((frame("205#01840302"), None))
        );
        assert_eq!(
            decode_frame(b"t6051AB04D2"),
            Ok((frame("605#AB"), Some(1234)))
        );
        assert_eq!(
            decode_frame(b"T123456781AA"),
            Ok((frame("12345678#AA"), None))
        );
        assert_eq!(decode_frame(b"r2054"), Ok((frame("205#R4"), None)));
        assert_eq!(decode_frame(b"t6050"), Ok((frame("605#"), None)));
        use SlcanError::*;
        assert_eq!(decode_frame(b""), Err(NotAFrame));
        assert_eq!(decode_frame(b"x205"), Err(NotAFrame));
        assert_eq!(decode_frame(b"t20"), Err(BadIdentifier));
        assert_eq!(decode_frame(b"t2G50"), Err(BadIdentifier));
        assert_eq!(decode_frame(b"t8000"), Err(IdentifierOutOfRange));
        assert_eq!(decode_frame(b"T200000000"), Err(IdentifierOutOfRange));
        assert_eq!(decode_frame(b"t2059"), Err(BadLength));
        assert_eq!(decode_frame(b"t205"), Err(BadLength));
        assert_eq!(decode_frame(b"t2052011"), Err(BadData));
        assert_eq!(decode_frame(b"t2051ZZ"), Err(BadData));
        assert_eq!(decode_frame(b"t2054018403 02"), Err(BadData));
        assert_eq!(decode_frame(b"t205101X"), Err(BadTimestamp));
        assert_eq!(decode_frame(b"t20510112345"), Err(BadTimestamp));
    }

    mod properties {
        use super::*;
        use proptest::prelude::*;

        proptest! {
            #[test]
            fn any_bytes_are_a_frame_or_an_error(bytes in proptest::collection::vec(any::<u8>(), 0..40)) {
                let _ = decode_frame(&bytes);
            }

            #[test]
            fn every_frame_survives_its_message(id in 0u32..=0x1FFF_FFFF, extended: bool, bytes in proptest::collection::vec(any::<u8>(), 0..=8), remote: bool, stamp in proptest::option::of(0u16..60_000)) {
                let id = if extended { FrameId::Extended(id) } else { FrameId::Standard((id & 0x7FF) as u16) };
                let frame = if remote { RawFrame::remote_frame(id, bytes.len() as u8) } else { RawFrame::data_frame(id, &bytes) }.unwrap();
                let mut out = [0u8; MAX_FRAME_MESSAGE];
                let n = encode_frame(&frame, stamp, &mut out);
                prop_assert_eq!(out[n - 1], b'\r');
                prop_assert_eq!(decode_frame(&out[..n - 1]), Ok((frame, stamp)));
            }
        }
    }
}
