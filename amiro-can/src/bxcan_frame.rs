//! Conversions between [`Frame`] and `bxcan::Frame` (bxcan 0.8), the driver of all three boards' CAN cells.
//!
//! Caution on the receive side: bxcan 0.8 keeps a received frame's raw 4-bit length code, and its own
//! accessors panic on a frame whose code is 9–15 (legal on the wire, meaning 8 bytes). A firmware
//! must not hand such a frame to these conversions; DiWheelDrive therefore reads its receive FIFO at
//! register level (`diwheeldrive/src/can.rs`) and decodes with [`decode_command`] on raw bytes.

use crate::error::DecodeError;
use crate::frame::Frame;
use crate::id::CanId;
use crate::message::{decode, decode_command, Message};
use crate::Command;

impl From<&Frame> for bxcan::Frame {
    fn from(frame: &Frame) -> bxcan::Frame {
        // A CanId is at most 0x7FF and a Frame holds at most 8 bytes, so both fallbacks are unreachable; they
        // exist so this path has no panic in it.
        let id = bxcan::StandardId::new(frame.id().raw()).unwrap_or(bxcan::StandardId::MAX);
        let data = bxcan::Data::new(frame.data()).unwrap_or(bxcan::Data::empty());
        bxcan::Frame::new_data(id, data)
    }
}

impl From<Frame> for bxcan::Frame {
    fn from(frame: Frame) -> bxcan::Frame {
        bxcan::Frame::from(&frame)
    }
}

impl TryFrom<&bxcan::Frame> for Frame {
    type Error = DecodeError;

    /// Extended identifiers and remote frames are not part of the protocol and are rejected.
    fn try_from(frame: &bxcan::Frame) -> Result<Frame, DecodeError> {
        let id = match frame.id() {
            bxcan::Id::Standard(id) => CanId::try_from(id.as_raw())?,
            bxcan::Id::Extended(id) => return Err(DecodeError::ExtendedId { id: id.as_raw() }),
        };
        match frame.data() {
            Some(data) => Frame::new(id, data),
            None => Err(DecodeError::RemoteFrame),
        }
    }
}

impl TryFrom<bxcan::Frame> for Frame {
    type Error = DecodeError;

    fn try_from(frame: bxcan::Frame) -> Result<Frame, DecodeError> {
        Frame::try_from(&frame)
    }
}

/// Decodes a received bxcan frame (see [`crate::decode`]).
pub fn decode_bxcan(frame: &bxcan::Frame) -> Result<Message, DecodeError> {
    let frame = Frame::try_from(frame)?;
    decode(frame.id().raw(), frame.data())
}

/// Decodes a received bxcan frame that must be a command (see [`crate::decode_command`]).
pub fn decode_bxcan_command(frame: &bxcan::Frame) -> Result<Command, DecodeError> {
    let frame = Frame::try_from(frame)?;
    decode_command(frame.id().raw(), frame.data())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Priority, SensorData};

    #[test]
    fn round_trip_through_bxcan() {
        let frame = SensorData::Gyroscope([-4, 30, 5]).encode(Priority::High);
        let bx = bxcan::Frame::from(&frame);
        assert!(bx.is_standard() && bx.is_data_frame());
        assert_eq!(bx.dlc(), 6);
        assert_eq!(Frame::try_from(&bx), Ok(frame));
        assert_eq!(
            decode_bxcan(&bx),
            Ok(Message::Sample {
                priority: Priority::High,
                data: SensorData::Gyroscope([-4, 30, 5])
            })
        );
    }

    #[test]
    fn thesis_example_through_bxcan() {
        let bx = bxcan::Frame::new_data(
            bxcan::StandardId::new(0x205).unwrap(),
            [0x01, 0x84, 0x03, 0x02],
        );
        let command = decode_bxcan_command(&bx).unwrap();
        assert_eq!(bxcan::Frame::from(command.encode()), bx);
    }

    #[test]
    fn rejects_what_the_protocol_does_not_use() {
        let ext = bxcan::Frame::new_data(bxcan::ExtendedId::new(0x205).unwrap(), [1u8]);
        assert_eq!(
            Frame::try_from(&ext),
            Err(DecodeError::ExtendedId { id: 0x205 })
        );
        let rtr = bxcan::Frame::new_remote(bxcan::StandardId::new(0x605).unwrap(), 4);
        assert_eq!(decode_bxcan(&rtr), Err(DecodeError::RemoteFrame));
        let data_frame = bxcan::Frame::new_data(bxcan::StandardId::new(0x608).unwrap(), [0u8; 6]);
        assert_eq!(
            decode_bxcan_command(&data_frame),
            Err(DecodeError::ExpectedCommand {
                topic: crate::Topic::Gyroscope
            })
        );
    }
}
