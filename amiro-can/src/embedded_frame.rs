//! Conversions between [`Frame`] and any `embedded_can::Frame` (embedded-can 0.4): SocketCAN, SLCAN and other
//! drivers that implement the trait.
//!
//! [`Frame`] itself implements the trait too, so a driver generic over `embedded_can::Frame` can carry it directly.
//! Remember that `frame.id()` calls the inherent method (a [`CanId`]); the trait's is
//! `embedded_can::Frame::id(&frame)`.

use embedded_can::{Id, StandardId};

use crate::error::DecodeError;
use crate::frame::Frame;
use crate::id::CanId;
use crate::message::{decode, decode_command, Message};
use crate::Command;

impl Frame {
    /// Converts any embedded-can frame; extended identifiers and remote frames are rejected.
    pub fn from_embedded<F: embedded_can::Frame>(frame: &F) -> Result<Frame, DecodeError> {
        if frame.is_remote_frame() {
            return Err(DecodeError::RemoteFrame);
        }
        match frame.id() {
            Id::Standard(id) => Frame::new(CanId::try_from(id.as_raw())?, frame.data()),
            Id::Extended(id) => Err(DecodeError::ExtendedId { id: id.as_raw() }),
        }
    }

    /// Builds the driver's frame type; `None` only if the driver refuses a standard data frame of ≤ 8 bytes.
    pub fn to_embedded<F: embedded_can::Frame>(&self) -> Option<F> {
        F::new(standard_id(self.id()), self.data())
    }
}

fn standard_id(id: CanId) -> StandardId {
    // A CanId is at most 0x7FF: the fallback is unreachable and only keeps this path panic-free.
    StandardId::new(id.raw()).unwrap_or(StandardId::MAX)
}

impl embedded_can::Frame for Frame {
    /// `None` for an extended identifier (not used by the protocol) or more than 8 bytes.
    fn new(id: impl Into<Id>, data: &[u8]) -> Option<Self> {
        match id.into() {
            Id::Standard(id) => Frame::new(CanId::try_from(id.as_raw()).ok()?, data).ok(),
            Id::Extended(_) => None,
        }
    }

    /// Always `None`: the protocol has no remote frames.
    fn new_remote(_id: impl Into<Id>, _dlc: usize) -> Option<Self> {
        None
    }

    fn is_extended(&self) -> bool {
        false
    }

    fn is_remote_frame(&self) -> bool {
        false
    }

    fn id(&self) -> Id {
        Id::Standard(standard_id(Frame::id(self)))
    }

    fn dlc(&self) -> usize {
        usize::from(Frame::dlc(self))
    }

    fn data(&self) -> &[u8] {
        Frame::data(self)
    }
}

/// Decodes a received embedded-can frame (see [`crate::decode`]).
pub fn decode_embedded<F: embedded_can::Frame>(frame: &F) -> Result<Message, DecodeError> {
    let frame = Frame::from_embedded(frame)?;
    decode(frame.id().raw(), frame.data())
}

/// Decodes a received embedded-can frame that must be a command (see [`crate::decode_command`]).
pub fn decode_embedded_command<F: embedded_can::Frame>(frame: &F) -> Result<Command, DecodeError> {
    let frame = Frame::from_embedded(frame)?;
    decode_command(frame.id().raw(), frame.data())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Priority, SensorData};
    use embedded_can::{ExtendedId, Frame as _};

    /// A host driver's frame type, as SocketCAN or SLCAN crates define one.
    #[derive(Debug, Clone, PartialEq)]
    struct HostFrame {
        id: Id,
        remote: bool,
        data: std::vec::Vec<u8>,
    }

    impl embedded_can::Frame for HostFrame {
        fn new(id: impl Into<Id>, data: &[u8]) -> Option<Self> {
            (data.len() <= 8).then(|| HostFrame {
                id: id.into(),
                remote: false,
                data: data.to_vec(),
            })
        }
        fn new_remote(id: impl Into<Id>, dlc: usize) -> Option<Self> {
            (dlc <= 8).then(|| HostFrame {
                id: id.into(),
                remote: true,
                data: std::vec![0; dlc],
            })
        }
        fn is_extended(&self) -> bool {
            matches!(self.id, Id::Extended(_))
        }
        fn is_remote_frame(&self) -> bool {
            self.remote
        }
        fn id(&self) -> Id {
            self.id
        }
        fn dlc(&self) -> usize {
            self.data.len()
        }
        fn data(&self) -> &[u8] {
            if self.remote {
                &[]
            } else {
                &self.data
            }
        }
    }

    #[test]
    fn round_trip_through_a_host_frame() {
        let frame = SensorData::ProximityRing { sensor: 7, mm: 180 }.encode(Priority::Low);
        let host: HostFrame = frame.to_embedded().unwrap();
        assert_eq!(host.id, Id::Standard(StandardId::new(0x71F).unwrap()));
        assert_eq!(Frame::from_embedded(&host), Ok(frame));
        assert_eq!(
            decode_embedded(&host),
            Ok(Message::Sample {
                priority: Priority::Low,
                data: SensorData::ProximityRing { sensor: 7, mm: 180 }
            })
        );
    }

    #[test]
    fn frame_implements_the_trait() {
        let f =
            <Frame as embedded_can::Frame>::new(StandardId::new(0x205).unwrap(), &[1, 0x84, 3, 2])
                .unwrap();
        assert_eq!(
            embedded_can::Frame::id(&f),
            Id::Standard(StandardId::new(0x205).unwrap())
        );
        assert_eq!(embedded_can::Frame::dlc(&f), 4);
        assert!(f.is_standard() && f.is_data_frame());
        assert!(decode_embedded_command(&f).is_ok());
        assert_eq!(
            <Frame as embedded_can::Frame>::new(ExtendedId::new(5).unwrap(), &[]),
            None
        );
        assert_eq!(
            <Frame as embedded_can::Frame>::new(StandardId::ZERO, &[0; 9]),
            None
        );
        assert_eq!(
            <Frame as embedded_can::Frame>::new_remote(StandardId::ZERO, 1),
            None
        );
    }

    #[test]
    fn rejects_extended_and_remote() {
        let ext = HostFrame::new(ExtendedId::new(0x1234_5678).unwrap(), &[]).unwrap();
        assert_eq!(
            decode_embedded(&ext),
            Err(DecodeError::ExtendedId { id: 0x1234_5678 })
        );
        let rtr = HostFrame::new_remote(StandardId::new(0x608).unwrap(), 6).unwrap();
        assert_eq!(decode_embedded(&rtr), Err(DecodeError::RemoteFrame));
    }
}
