//! A classic CAN data frame with an AMiRo identifier, independent of any driver.

use core::fmt;

use crate::error::DecodeError;
use crate::id::CanId;

/// A data frame: identifier and 0..=8 data bytes. The length is validated on construction, so
/// [`Frame::data`] never panics.
///
/// Aligned to 4 bytes (its size stays 12): the firmware copies frames between its queues and the
/// mailboxes, and a word-aligned copy is three loads and stores on the chip where one of 2-byte
/// alignment is a call of `memcpy`, which copies byte by byte.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(align(4))]
pub struct Frame {
    id: CanId,
    len: u8,
    data: [u8; 8],
}

impl Frame {
    /// A frame with these data bytes; more than 8 bytes is [`DecodeError::FrameTooLong`].
    pub fn new(id: CanId, data: &[u8]) -> Result<Frame, DecodeError> {
        let mut bytes = [0u8; 8];
        match bytes.get_mut(..data.len()) {
            Some(prefix) => {
                prefix.copy_from_slice(data);
                // data.len() <= 8 here, so the cast is exact.
                Ok(Frame {
                    id,
                    len: data.len() as u8,
                    data: bytes,
                })
            }
            None => Err(DecodeError::FrameTooLong { len: data.len() }),
        }
    }

    /// A frame without data bytes (DLC 0); `const`, so a fixed-size store of frames can be
    /// initialised at compile time.
    pub const fn empty(id: CanId) -> Frame {
        Frame {
            id,
            len: 0,
            data: [0; 8],
        }
    }

    /// A frame from an 8-byte buffer of which the first `len` bytes are used; `len` above 8 is an error.
    pub fn from_parts(id: CanId, len: u8, data: [u8; 8]) -> Result<Frame, DecodeError> {
        if len <= 8 {
            Ok(Frame { id, len, data })
        } else {
            Err(DecodeError::FrameTooLong {
                len: usize::from(len),
            })
        }
    }

    /// For encoders in this crate that build `len <= 8` by construction; clamps instead of failing.
    pub(crate) const fn from_valid(id: CanId, len: u8, data: [u8; 8]) -> Frame {
        let len = if len > 8 { 8 } else { len };
        Frame { id, len, data }
    }

    /// The identifier.
    pub const fn id(&self) -> CanId {
        self.id
    }

    /// The data length code (0..=8).
    pub const fn dlc(&self) -> u8 {
        self.len
    }

    /// The data bytes (`dlc()` of them).
    pub fn data(&self) -> &[u8] {
        // len <= 8 is an invariant of every constructor; the fallback is never taken.
        self.data.get(..usize::from(self.len)).unwrap_or(&self.data)
    }

    /// The whole 8-byte data buffer: the first `dlc()` bytes are [`Frame::data`], the rest as the
    /// frame was built (zeros, unless [`Frame::from_parts`] was given others). For a CAN controller's
    /// mailbox, which sends the first DLC bytes of its 8: a copy of fixed size, whatever the length.
    pub const fn data_buffer(&self) -> [u8; 8] {
        self.data
    }

    /// Decodes this frame; see [`crate::decode`].
    pub fn decode(&self) -> Result<crate::Message, DecodeError> {
        crate::decode(self.id.raw(), self.data())
    }
}

impl fmt::Display for Frame {
    /// can-utils `cansend` form: `205#01840302`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}#", self.id)?;
        for byte in self.data() {
            write!(f, "{byte:02X}")?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::id::{Kind, Priority};

    #[test]
    fn lengths() {
        let id = CanId::new(Kind::Command, Priority::Medium, 0x05);
        for len in 0..=8usize {
            let bytes = [0xAAu8; 8];
            let frame = Frame::new(id, &bytes[..len]).unwrap();
            assert_eq!(frame.data(), &bytes[..len]);
            assert_eq!(usize::from(frame.dlc()), len);
        }
        assert_eq!(
            Frame::new(id, &[0; 9]),
            Err(DecodeError::FrameTooLong { len: 9 })
        );
        assert_eq!(
            Frame::from_parts(id, 9, [0; 8]),
            Err(DecodeError::FrameTooLong { len: 9 })
        );
    }

    #[test]
    fn display_is_cansend_form() {
        let id = CanId::new(Kind::Command, Priority::Medium, 0x05);
        let frame = Frame::new(id, &[0x01, 0x84, 0x03, 0x02]).unwrap();
        assert_eq!(std::format!("{frame}"), "205#01840302");
        let empty = Frame::new(CanId::try_from(0x7FF).unwrap(), &[]).unwrap();
        assert_eq!(std::format!("{empty}"), "7FF#");
        assert_eq!(Frame::empty(CanId::try_from(0x7FF).unwrap()), empty);
        assert_eq!(core::mem::size_of::<Frame>(), 12);
        assert_eq!(core::mem::align_of::<Frame>(), 4);
        let frame = Frame::new(CanId::try_from(0x605).unwrap(), &[1, 2, 3]).unwrap();
        assert_eq!(frame.data_buffer(), [1, 2, 3, 0, 0, 0, 0, 0]);
    }
}
