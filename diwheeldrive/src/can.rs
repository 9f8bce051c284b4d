//! The board's CAN port: what the RTIC tasks need from a CAN controller, and its bxCAN adapter.
//!
//! Received frames stay raw (an 11-bit ID and 0–8 bytes) so that the handler sees, counts and
//! rejects malformed frames itself; frames to send are already-validated `amiro_can::Frame`s.

/// A frame as it came off the bus, before any protocol check.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RxFrame {
    /// Standard identifier, or `u16::MAX` for a frame the protocol cannot carry (extended or remote).
    pub id: u16,
    /// Number of valid bytes in `data`.
    pub len: u8,
    /// Payload.
    pub data: [u8; 8],
}

impl RxFrame {
    /// The valid payload bytes.
    pub fn payload(&self) -> &[u8] {
        &self.data[..usize::from(self.len.min(8))]
    }
}

/// What happened to a frame handed to the transmit mailboxes.
#[derive(Debug)]
// QEMU's virtual mailboxes never fill up.
#[cfg_attr(feature = "qemu", allow(dead_code))]
pub enum Transmit {
    /// The frame is in a mailbox.
    Queued,
    /// The frame is in a mailbox and displaced this lower-priority one, which must be queued again.
    Displaced(amiro_can::Frame),
    /// All mailboxes hold frames at least as urgent; try again after a transmit-complete interrupt.
    Busy,
}

/// The transmit half of a CAN controller.
pub trait CanTx {
    /// Offers `frame` to the mailboxes (ID-ordered: a more urgent frame may displace a pending one).
    fn transmit(&mut self, frame: &amiro_can::Frame) -> Transmit;
    /// Acknowledges the transmit-complete interrupt.
    fn clear_interrupt(&mut self);
}

/// The receive half of a CAN controller.
pub trait CanRx {
    /// Takes the next received frame, if any; `Err(())` reports a FIFO overrun (frames were lost).
    fn receive(&mut self) -> Option<Result<RxFrame, ()>>;
}

#[cfg(not(feature = "qemu"))]
mod bxcan_port {
    use super::{CanRx, CanTx, RxFrame, Transmit};
    use bxcan::{Id, Instance, Rx0, Tx};

    impl<I: Instance> CanTx for Tx<I> {
        fn transmit(&mut self, frame: &amiro_can::Frame) -> Transmit {
            let frame: bxcan::Frame = (*frame).into();
            match Tx::transmit(self, &frame) {
                Ok(status) => match status
                    .dequeued_frame()
                    .and_then(|f| amiro_can::Frame::try_from(f).ok())
                {
                    Some(displaced) => Transmit::Displaced(displaced),
                    None => Transmit::Queued,
                },
                Err(_) => Transmit::Busy,
            }
        }

        fn clear_interrupt(&mut self) {
            self.clear_interrupt_flags();
        }
    }

    impl<I: Instance> CanRx for Rx0<I> {
        fn receive(&mut self) -> Option<Result<RxFrame, ()>> {
            match Rx0::receive(self) {
                Ok(frame) => {
                    let mut out = RxFrame {
                        id: u16::MAX,
                        len: 0,
                        data: [0; 8],
                    };
                    if let (Id::Standard(id), Some(data)) = (frame.id(), frame.data()) {
                        out.id = id.as_raw();
                        out.len = data.len() as u8;
                        out.data[..data.len()].copy_from_slice(data);
                    }
                    Some(Ok(out))
                }
                Err(nb::Error::WouldBlock) => None,
                Err(nb::Error::Other(_overrun)) => Some(Err(())),
            }
        }
    }
}
