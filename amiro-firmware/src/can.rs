//! The board's CAN port: what the RTIC tasks need from a CAN controller.
//!
//! Received frames stay raw (an 11-bit ID and 0–8 bytes) so that the handler sees, counts and
//! rejects malformed frames itself; frames to send are already-validated `amiro_can::Frame`s.
//! The one implementation for the robot is [`crate::bxcan`] (the same IP on the F103 and the F405);
//! the QEMU build has virtual ports in `crate::qemu`. The transmit interrupt's job over a port and the transmit
//! queue is here too ([`collect_completions`], [`fill_mailboxes`]), hardware-free.

use amiro_sensors::tx_queue::TxQueue;

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

/// What the receive side reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RxEvent {
    /// A frame.
    Frame(RxFrame),
    /// The receive FIFO overflowed at least once since the last report: one or more frames were
    /// lost. The hardware keeps one flag, so counting these events gives a *lower bound* on the
    /// frames lost.
    Overrun,
}

/// What happened to a frame handed to the transmit mailboxes.
///
/// A more urgent frame never waits for the mailboxes to drain: when all three hold less urgent
/// frames, the least urgent one is aborted (without waiting for the abort) and the caller is told
/// `Busy`; the abort completes with a transmit interrupt, where [`CanTx::completed`] hands the
/// aborted frame back for the queue and a mailbox is free for the urgent one.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Transmit {
    /// The frame is in a mailbox.
    Queued,
    /// All mailboxes hold frames at least as urgent; try again after a transmit-complete interrupt.
    Busy,
}

/// What the transmit-complete interrupt found for one mailbox.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Completion {
    /// The frame was acknowledged on the bus.
    Sent(amiro_can::Frame),
    /// The frame's transmission was aborted (displaced by a more urgent one): it must go back into
    /// the transmit queue.
    Aborted(amiro_can::Frame),
}

/// The transmit half of a CAN controller.
pub trait CanTx {
    /// Offers `frame` to the mailboxes (ID-ordered: a more urgent frame may displace a pending one).
    fn transmit(&mut self, frame: &amiro_can::Frame) -> Transmit;
    /// Acknowledges the transmit interrupt and reports every mailbox that completed.
    fn completed(&mut self, on_completion: &mut dyn FnMut(Completion));
}

/// The receive half of a CAN controller.
pub trait CanRx {
    /// Takes the next received frame or overrun report, if any.
    fn receive(&mut self) -> Option<RxEvent>;
}

/// The transmit interrupt's job, its first half: every completion collected, each aborted frame put back into
/// `queue`, `sent` told of each frame sent. `tasks::transmit_pending` runs it and then [`fill_mailboxes`]; they are
/// apart so that the host's tests run the job itself with the controller moving between them, as it runs beside
/// the interrupt (amiro-firmware's `tests/transmit_aborts.rs`).
#[inline(always)]
pub fn collect_completions<const N: usize>(
    port: &mut impl CanTx,
    queue: &mut TxQueue<N>,
    mut sent: impl FnMut(&amiro_can::Frame),
) {
    port.completed(&mut |completion| match completion {
        Completion::Aborted(frame) => {
            let _ = queue.requeue(frame);
        }
        Completion::Sent(frame) => sent(&frame),
    });
}

/// The transmit interrupt's job, its second half: mailboxes filled from the queue's head, most urgent first, until
/// the queue is empty or a frame is refused (`Busy`, where the port may have asked for an abort); `queued` told the
/// identifier of each frame that went into a mailbox.
#[inline(always)]
pub fn fill_mailboxes<const N: usize>(
    port: &mut impl CanTx,
    queue: &mut TxQueue<N>,
    mut queued: impl FnMut(u16),
) {
    // The frame goes to the mailbox from its place in the queue: copied out first, it was a `memcpy` call per
    // pass on the chip. Its identifier is kept for `queued`, which comes after `pop` has freed its slot.
    while let Some(frame) = queue.peek() {
        let id = frame.id().raw();
        match port.transmit(frame) {
            Transmit::Queued => {
                queue.pop();
                queued(id);
            }
            Transmit::Busy => break,
        }
    }
}
