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
///
/// A more urgent frame never waits for the mailboxes to drain: when all three hold less urgent
/// frames, the least urgent one is aborted (without waiting for the abort) and the caller is told
/// `Busy`; the abort completes with a transmit interrupt, where [`CanTx::completed`] hands the
/// aborted frame back for the queue and a mailbox is free for the urgent one.
#[derive(Debug)]
// QEMU's virtual mailboxes never fill up.
#[cfg_attr(feature = "qemu", allow(dead_code))]
pub enum Transmit {
    /// The frame is in a mailbox.
    Queued,
    /// All mailboxes hold frames at least as urgent; try again after a transmit-complete interrupt.
    Busy,
}

/// The transmit half of a CAN controller.
pub trait CanTx {
    /// Offers `frame` to the mailboxes (ID-ordered: a more urgent frame may displace a pending one).
    fn transmit(&mut self, frame: &amiro_can::Frame) -> Transmit;
    /// Acknowledges the transmit interrupt; every frame whose mailbox was aborted is handed to
    /// `requeue` (it must go back into the transmit queue).
    fn completed(&mut self, requeue: &mut dyn FnMut(amiro_can::Frame));
}

/// The receive half of a CAN controller.
pub trait CanRx {
    /// Takes the next received frame, if any; `Err(())` reports a FIFO overrun (frames were lost).
    fn receive(&mut self) -> Option<Result<RxFrame, ()>>;
}

#[cfg(not(feature = "qemu"))]
pub use bxcan_port::{Fifo0, Mailboxes};

#[cfg(not(feature = "qemu"))]
mod bxcan_port {
    use super::{CanRx, CanTx, RxFrame, Transmit};

    /// CAN1's three transmit mailboxes, driven at register level.
    ///
    /// bxcan 0.8's `transmit` displaces a less urgent pending frame by aborting it and *waiting* for
    /// the abort, which takes up to a whole frame time when that mailbox is on the bus — far too long
    /// inside a transmit interrupt. This driver requests the abort and returns; the mailbox's
    /// completion interrupt (RQCP with TXOK clear) hands the aborted frame back from `shadow`.
    pub struct Mailboxes {
        shadow: [Option<amiro_can::Frame>; 3],
    }

    impl Mailboxes {
        /// The mailboxes of a controller bxcan has configured and enabled.
        pub const fn new() -> Self {
            Self { shadow: [None; 3] }
        }
    }

    const TSR_TME0: u32 = 1 << 26;
    const fn rqcp(i: usize) -> u32 {
        1 << (8 * i)
    }
    const fn txok(i: usize) -> u32 {
        1 << (8 * i + 1)
    }
    const fn abrq(i: usize) -> u32 {
        1 << (8 * i + 7)
    }

    fn can() -> &'static stm32f1xx_hal::pac::can::RegisterBlock {
        // SAFETY: the transmit registers (TSR, mailboxes) are touched only by `Mailboxes`, which the
        // `can_tx` task owns; the receive side uses FIFO registers only.
        unsafe { &*stm32f1xx_hal::pac::CAN::ptr() }
    }

    impl CanTx for Mailboxes {
        fn transmit(&mut self, frame: &amiro_can::Frame) -> Transmit {
            let can = can();
            let tsr = can.tsr().read().bits();
            // Frames with the same identifier must leave in order, but pending mailboxes with equal
            // identifiers go out by mailbox number: wait until an earlier one with this ID has left.
            let same_id_pending = (0..3).any(|i| {
                tsr & (TSR_TME0 << i) == 0
                    && self
                        .shadow
                        .get(i)
                        .copied()
                        .flatten()
                        .is_some_and(|f| f.id() == frame.id())
            });
            if same_id_pending {
                return Transmit::Busy;
            }
            if let Some(free) = (0..3).find(|i| tsr & (TSR_TME0 << i) != 0) {
                let mut data = [0u8; 8];
                data[..frame.data().len()].copy_from_slice(frame.data());
                let mailbox = can.tx(free);
                // SAFETY: raw writes of an empty mailbox: standard ID in bits 31..21, DLC, data;
                // TXRQ last hands it to the controller.
                unsafe {
                    mailbox.tdtr().write(|w| w.bits(u32::from(frame.dlc())));
                    mailbox.tdlr().write(|w| {
                        w.bits(u32::from_le_bytes([data[0], data[1], data[2], data[3]]))
                    });
                    mailbox.tdhr().write(|w| {
                        w.bits(u32::from_le_bytes([data[4], data[5], data[6], data[7]]))
                    });
                    mailbox
                        .tir()
                        .write(|w| w.bits((u32::from(frame.id().raw()) << 21) | 1));
                }
                if let Some(slot) = self.shadow.get_mut(free) {
                    *slot = Some(*frame);
                }
                return Transmit::Queued;
            }
            // All three pending: abort the least urgent one if this frame beats it (and no abort is
            // already under way), without waiting.
            let least = (0..3)
                .filter_map(|i| {
                    self.shadow
                        .get(i)
                        .copied()
                        .flatten()
                        .map(|f| (i, f.id().raw()))
                })
                .max_by_key(|(_, id)| *id);
            if let Some((i, id)) = least {
                if frame.id().raw() < id && tsr & abrq(i) == 0 {
                    // SAFETY: setting ABRQ of one mailbox; the other TSR bits are write-1-to-clear
                    // flags, written as 0 here so nothing else changes.
                    unsafe { can.tsr().write(|w| w.bits(abrq(i))) };
                }
            }
            Transmit::Busy
        }

        fn completed(&mut self, requeue: &mut dyn FnMut(amiro_can::Frame)) {
            let can = can();
            let tsr = can.tsr().read().bits();
            for i in 0..3 {
                if tsr & rqcp(i) == 0 {
                    continue;
                }
                // SAFETY: writing RQCP clears that mailbox's completion flags (TXOK, ALST, TERR).
                unsafe { can.tsr().write(|w| w.bits(rqcp(i))) };
                let shadow = self.shadow.get_mut(i).and_then(Option::take);
                // With automatic retransmission on, a completion without TXOK is an abort.
                if tsr & txok(i) == 0 {
                    if let Some(frame) = shadow {
                        requeue(frame);
                    }
                }
            }
        }
    }

    /// CAN1's receive FIFO 0, read at register level.
    ///
    /// bxcan 0.8 keeps a received frame's raw 4-bit length code, and reading the payload of a frame
    /// whose code is 9–15 (legal on the wire: it means 8 bytes) panics inside bxcan. Any node could
    /// send one, so this reader takes the FIFO registers itself and clamps the length to 8.
    pub struct Fifo0;

    impl CanRx for Fifo0 {
        fn receive(&mut self) -> Option<Result<RxFrame, ()>> {
            // SAFETY: FIFO 0's registers are read and released only here (the `can_rx` task owns
            // this reader); bxcan's transmit half never touches them.
            let can = unsafe { &*stm32f1xx_hal::pac::CAN::ptr() };
            let rf0r = can.rfr(0).read();
            if rf0r.fovr().bit_is_set() {
                // Frames were lost because the FIFO was full: acknowledge and report it.
                can.rfr(0).write(|w| unsafe { w.bits(1 << 4) });
                return Some(Err(()));
            }
            if rf0r.fmp().bits() == 0 {
                return None;
            }
            let mailbox = can.rx(0);
            let rir = mailbox.rir().read();
            let dlc = (mailbox.rdtr().read().dlc().bits() & 0x0F).min(8);
            let low = mailbox.rdlr().read().bits().to_le_bytes();
            let high = mailbox.rdhr().read().bits().to_le_bytes();
            // Release the mailbox (RFOM0) so the next frame moves up.
            can.rfr(0).write(|w| unsafe { w.bits(1 << 5) });
            let mut frame = RxFrame {
                id: u16::MAX,
                len: 0,
                data: [0; 8],
            };
            if rir.ide().bit_is_clear() && rir.rtr().bit_is_clear() {
                frame.id = rir.stid().bits();
                frame.len = dlc;
                frame.data[..4].copy_from_slice(&low);
                frame.data[4..].copy_from_slice(&high);
            }
            Some(Ok(frame))
        }
    }
}
