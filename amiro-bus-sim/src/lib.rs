//! A model of the robot's CAN bus at bit-time resolution, for `cargo xtask robot`: every board's
//! transmit mailboxes, arbitration by identifier, each frame on the bus for its real length (bit
//! stuffing computed from its bits, CRC included), acknowledgement, error frames and
//! retransmission, error counters, boards unplugged and plugged back, and a babbling controller
//! (a "babbling idiot" that keeps one frame pending and sends it back to back).
//!
//! Time is in bit times, which at the robot's 1 Mbit/s are microseconds. The model is driven from
//! outside: the caller puts frames into a node's mailboxes with the time they were queued
//! ([`Bus::queue`]), then asks for everything that *starts* on the bus before a time
//! ([`Bus::run_until`]). A frame cannot complete sooner than [`MIN_FRAME_BITS`] after its start
//! of frame, so a caller that has queued every frame queued before `t` learns from `run_until(t)`
//! every frame that completes before `t + MIN_FRAME_BITS`: the lock-step of the emulated robot
//! rests on that look-ahead (docs/qemu.md).
//!
//! What the model leaves out, on purpose: remote and extended frames (the robot's protocol has
//! none), overload frames, and the receive FIFOs, which live beside each board's interrupt handler
//! (only the board knows when it empties its FIFO).
#![deny(missing_docs)]

/// The frame layout's bit counts are the CAN protocol crate's (`amiro_can::timing`, which the
/// schedule analysis counts with too): the stuffable bits of a standard frame without data, the
/// never-stuffed tail up to the end of frame, the interframe space.
pub use amiro_can::timing::{
    INTERMISSION_BITS, STUFFABLE_BITS_STANDARD as STUFFABLE_BITS, TAIL_BITS,
};
/// The shortest frame from start of frame to its completion (end of frame): no data, no stuff bit.
pub const MIN_FRAME_BITS: u32 = STUFFABLE_BITS + TAIL_BITS;
/// An error flag (active or passive).
pub const ERROR_FLAG_BITS: u32 = 6;
/// The error delimiter.
pub const ERROR_DELIMITER_BITS: u32 = 8;
/// The extra recessive bits an error-passive transmitter waits after its own transmission.
pub const SUSPEND_TRANSMISSION_BITS: u32 = 8;
/// Recessive bits a bus-off controller waits for before it rejoins (bxCAN's automatic bus-off
/// management: 128 occurrences of 11 recessive bits; the model counts them as consecutive).
pub const BUS_OFF_RECOVERY_BITS: u64 = 128 * 11;
/// Transmit mailboxes per controller (bxCAN's three).
pub const MAILBOXES: usize = 3;
/// The `mailbox` a babbling controller's frames are reported from ([`Bus::babble`]): none of
/// its three, which the board's software fills, but the fault itself.
pub const BABBLE_MAILBOX: usize = MAILBOXES;

/// A standard data frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Frame {
    /// 11-bit identifier.
    pub id: u16,
    /// Data length, 0..=8.
    pub len: u8,
    /// Payload (the first `len` bytes count).
    pub data: [u8; 8],
}

impl Frame {
    /// A frame, or `None` for an identifier beyond 11 bits or more than 8 bytes.
    pub fn new(id: u16, payload: &[u8]) -> Option<Self> {
        if id > 0x7FF || payload.len() > 8 {
            return None;
        }
        let mut data = [0; 8];
        data[..payload.len()].copy_from_slice(payload);
        Some(Self {
            id,
            len: payload.len() as u8,
            data,
        })
    }

    /// The payload bytes.
    pub fn payload(&self) -> &[u8] {
        &self.data[..usize::from(self.len.min(8))]
    }
}

/// CRC-15 and the stuff-bit count, the CAN protocol crate's (one place: the QEMU platform's
/// local completion of its own frames counts with them too).
pub use amiro_can::timing::{crc15, stuff_bit_count};

/// Bits of `frame` on the bus from start of frame to the end of its end-of-frame field (its
/// completion), stuff bits included, interframe space not (`amiro_can::timing::frame_bits`).
pub fn frame_bits(frame: &Frame) -> u32 {
    amiro_can::timing::frame_bits(frame.id, frame.payload())
}

/// A node on the bus (its index in the order nodes were added).
pub type NodeId = usize;

/// A frame waiting in a mailbox.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Pending {
    /// The frame.
    pub frame: Frame,
    /// When the node put it into the mailbox.
    pub queued_at: u64,
    /// Attempts that ended in an error frame so far.
    pub failed_attempts: u32,
}

/// A controller's fault-confinement state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ErrorState {
    /// Both counters below 128.
    Active,
    /// A counter at 128 or above: passive error flags, suspended transmission.
    Passive,
    /// Transmit counter beyond 255: off the bus until it has seen the recovery sequence.
    BusOff,
}

#[derive(Debug, Clone)]
struct Node {
    plugged: bool,
    mailboxes: [Option<Pending>; MAILBOXES],
    tec: u32,
    rec: u32,
    /// Not before this time may the node start a frame (suspend transmission, bus-off recovery).
    hold_until: u64,
    bus_off: bool,
    babble: Option<Babble>,
}

/// A babbling controller's frame: pending from `pending_since` (its start, then each completion)
/// until the fault ends.
#[derive(Debug, Clone, Copy)]
struct Babble {
    frame: Frame,
    pending_since: u64,
    until: u64,
}

impl Node {
    fn state(&self) -> ErrorState {
        if self.bus_off {
            ErrorState::BusOff
        } else if self.tec >= 128 || self.rec >= 128 {
            ErrorState::Passive
        } else {
            ErrorState::Active
        }
    }

    /// The node's lowest-identifier frame, as bxCAN picks among its mailboxes (identifier
    /// priority; the lower mailbox on a tie), with its mailbox.
    fn most_urgent(&self, ready_by: u64) -> Option<(usize, Pending)> {
        self.mailboxes
            .iter()
            .enumerate()
            .filter_map(|(k, m)| m.map(|p| (k, p)))
            .filter(|(_, p)| p.queued_at <= ready_by)
            .chain(
                self.babble
                    .filter(|b| b.pending_since <= ready_by && ready_by < b.until)
                    .map(|b| {
                        let pending = Pending {
                            frame: b.frame,
                            queued_at: b.pending_since,
                            failed_attempts: 0,
                        };
                        (BABBLE_MAILBOX, pending)
                    }),
            )
            .min_by_key(|(k, p)| (p.frame.id, *k))
    }

    /// When the node next has a frame to offer, the bus being idle from `idle_from`.
    fn earliest_ready(&self, idle_from: u64) -> Option<u64> {
        let babble = self.babble.and_then(|b| {
            let ready = b.pending_since.max(self.hold_until).max(idle_from);
            (ready < b.until).then_some(ready)
        });
        self.mailboxes
            .iter()
            .flatten()
            .map(|p| p.queued_at.max(self.hold_until).max(idle_from))
            .chain(babble)
            .min()
    }
}

/// Why a transmission ended in an error frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ErrorKind {
    /// The transmitter read back a bit other than it sent (an injected fault).
    Bit,
    /// Nobody acknowledged the frame (no other node on the bus).
    Ack,
}

/// What happened on the bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Event {
    /// A frame was transmitted and acknowledged.
    Sent {
        /// The transmitter.
        node: NodeId,
        /// Its mailbox, free again from `end` on.
        mailbox: usize,
        /// The frame.
        frame: Frame,
        /// When it was queued.
        queued_at: u64,
        /// Its start of frame.
        start: u64,
        /// Its completion (end of the end-of-frame field): the receivers take it here.
        end: u64,
        /// The nodes that received it (bit `n` for node `n`).
        receivers: u32,
    },
    /// A transmission ended in an error frame; the frame stays in its mailbox and tries again.
    ErrorFrame {
        /// The transmitter.
        node: NodeId,
        /// Its mailbox.
        mailbox: usize,
        /// The frame.
        frame: Frame,
        /// Its start of frame.
        start: u64,
        /// The bit time at which the error was detected.
        at: u64,
        /// What went wrong.
        kind: ErrorKind,
        /// When the bus is free again (error flag, delimiter, intermission).
        idle_at: u64,
    },
    /// A node's fault-confinement state changed.
    StateChange {
        /// The node.
        node: NodeId,
        /// When.
        at: u64,
        /// The new state.
        state: ErrorState,
    },
}

/// A fault to inject: the first transmission that matches gets a bit error.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BitFault {
    /// Only a frame with this identifier (any if `None`).
    pub id: Option<u16>,
    /// Only a transmission starting at or after this time.
    pub not_before: u64,
    /// The bit (counted from start of frame, stuff bits included) the transmitter reads wrong;
    /// clamped into the frame's stuffed part.
    pub at_bit: u32,
}

/// Why a frame could not be queued.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum QueueError {
    /// No such node or mailbox.
    NoSuchMailbox,
    /// The mailbox still holds a frame.
    Occupied,
}

/// The bus and every controller on it.
#[derive(Debug, Clone, Default)]
pub struct Bus {
    nodes: Vec<Node>,
    /// The bus is idle from here on (after the last frame's intermission).
    idle_from: u64,
    faults: Vec<BitFault>,
}

impl Bus {
    /// An empty bus.
    pub fn new() -> Self {
        Self::default()
    }

    /// Connects a new controller (plugged in, error-active, empty mailboxes).
    pub fn add_node(&mut self) -> NodeId {
        self.nodes.push(Node {
            plugged: true,
            mailboxes: [None; MAILBOXES],
            tec: 0,
            rec: 0,
            hold_until: 0,
            bus_off: false,
            babble: None,
        });
        self.nodes.len() - 1
    }

    /// Puts `frame` into `node`'s `mailbox`, queued at `at`.
    pub fn queue(
        &mut self,
        node: NodeId,
        mailbox: usize,
        frame: Frame,
        at: u64,
    ) -> Result<(), QueueError> {
        let slot = self
            .nodes
            .get_mut(node)
            .and_then(|n| n.mailboxes.get_mut(mailbox))
            .ok_or(QueueError::NoSuchMailbox)?;
        if slot.is_some() {
            return Err(QueueError::Occupied);
        }
        *slot = Some(Pending {
            frame,
            queued_at: at,
            failed_attempts: 0,
        });
        Ok(())
    }

    /// Aborts the frame in `node`'s `mailbox` (bxCAN's ABRQ) and returns it, if it is still there: a
    /// frame whose transmission started (in a [`Bus::run_until`] so far) has left its mailbox, and a
    /// frame retried after an error frame is aborted between two attempts.
    pub fn abort(&mut self, node: NodeId, mailbox: usize) -> Option<Pending> {
        self.nodes
            .get_mut(node)
            .and_then(|n| n.mailboxes.get_mut(mailbox))
            .and_then(Option::take)
    }

    /// Empties `node`'s mailboxes (a controller reset): what they held is returned.
    pub fn reset_node(&mut self, node: NodeId, at: u64) -> Vec<Pending> {
        let Some(n) = self.nodes.get_mut(node) else {
            return Vec::new();
        };
        let held = n.mailboxes.iter_mut().filter_map(Option::take).collect();
        n.tec = 0;
        n.rec = 0;
        n.bus_off = false;
        n.hold_until = at;
        held
    }

    /// Unplugs `node` (`false`) or plugs it back in (`true`). An unplugged node neither sends nor
    /// receives; its mailboxes keep their frames for when it is back.
    pub fn set_plugged(&mut self, node: NodeId, plugged: bool, at: u64) {
        if let Some(n) = self.nodes.get_mut(node) {
            n.plugged = plugged;
            if plugged {
                // It synchronises on the bus before it may send: at least one intermission.
                n.hold_until = n.hold_until.max(at + u64::from(INTERMISSION_BITS));
            }
        }
    }

    /// Whether `node` is plugged in.
    pub fn plugged(&self, node: NodeId) -> bool {
        self.nodes.get(node).is_some_and(|n| n.plugged)
    }

    /// Makes `node`'s controller babble from `from` until `until` (exclusive; `u64::MAX`: for
    /// good): a fault that keeps `frame` pending beside its mailboxes and, each time it completes,
    /// pending again at once, so the node offers it at every arbitration and sends it back to
    /// back whenever it wins. It arbitrates as any frame of the node does: a lower identifier on
    /// the bus (or in the node's own mailboxes) still wins, a higher one waits until the fault
    /// ends. Its transmissions are reported with [`BABBLE_MAILBOX`]. A later call replaces the
    /// fault.
    pub fn babble(&mut self, node: NodeId, frame: Frame, from: u64, until: u64) {
        if let Some(n) = self.nodes.get_mut(node) {
            n.babble = Some(Babble {
                frame,
                pending_since: from,
                until,
            });
        }
    }

    /// Ends `node`'s babbling from `at` on (a frame already started still completes).
    pub fn stop_babbling(&mut self, node: NodeId, at: u64) {
        if let Some(b) = self.nodes.get_mut(node).and_then(|n| n.babble.as_mut()) {
            b.until = b.until.min(at);
        }
    }

    /// Whether `node`'s controller will still babble at or after `at`.
    pub fn babbling(&self, node: NodeId, at: u64) -> bool {
        self.nodes
            .get(node)
            .and_then(|n| n.babble)
            .is_some_and(|b| b.until > at)
    }

    /// Arranges a bit error (see [`BitFault`]).
    pub fn inject(&mut self, fault: BitFault) {
        self.faults.push(fault);
    }

    /// `node`'s error counters (transmit, receive).
    pub fn error_counters(&self, node: NodeId) -> (u32, u32) {
        self.nodes.get(node).map_or((0, 0), |n| (n.tec, n.rec))
    }

    /// `node`'s fault-confinement state.
    pub fn error_state(&self, node: NodeId) -> ErrorState {
        self.nodes.get(node).map_or(ErrorState::Active, Node::state)
    }

    /// What `node`'s mailboxes hold.
    pub fn mailboxes(&self, node: NodeId) -> [Option<Pending>; MAILBOXES] {
        self.nodes
            .get(node)
            .map_or([None; MAILBOXES], |n| n.mailboxes)
    }

    /// When the bus is idle again after everything run so far.
    pub fn idle_from(&self) -> u64 {
        self.idle_from
    }

    /// When `node` could start a frame on the bus from here on, if nothing else competed (the bus
    /// idle after everything run so far, and the node's own hold); `None` when a frame of it
    /// might not go through as computed from its bits alone: it is unplugged, not error-active or
    /// babbling, no other node is on the bus to acknowledge it, or a bit error is still to be
    /// injected. The host grants a board the bus with it (docs/qemu.md, "Lookahead").
    pub fn alone_from(&self, node: NodeId) -> Option<u64> {
        let n = self.nodes.get(node)?;
        let acknowledged = self
            .nodes
            .iter()
            .enumerate()
            .any(|(k, other)| k != node && self.on_bus(other));
        let clean = self.on_bus(n)
            && n.state() == ErrorState::Active
            && n.babble.is_none()
            && acknowledged
            && self.faults.is_empty();
        clean.then_some(self.idle_from.max(n.hold_until))
    }

    fn on_bus(&self, n: &Node) -> bool {
        n.plugged && !n.bus_off
    }

    /// Runs every transmission whose start of frame lies before `t` and returns what happened, in
    /// order. Frames queued later than a start do not take part in its arbitration.
    pub fn run_until(&mut self, t: u64) -> Vec<Event> {
        let mut events = Vec::new();
        loop {
            let start = self
                .nodes
                .iter()
                .filter(|n| n.plugged)
                .filter_map(|n| n.earliest_ready(self.idle_from))
                .min();
            let Some(start) = start else { break };
            if start >= t {
                break;
            }
            self.recover_bus_off(start, &mut events);
            // Arbitration: every node on the bus and allowed to send offers its most urgent ready
            // frame; the lowest identifier wins bit by bit (a tie between two nodes, which the
            // protocol rules out, goes to the lower node index).
            let winner = self
                .nodes
                .iter()
                .enumerate()
                .filter(|(_, n)| self.on_bus(n) && n.hold_until <= start)
                .filter_map(|(k, n)| n.most_urgent(start).map(|(m, p)| (p.frame.id, k, m, p)))
                .min_by_key(|&(id, k, ..)| (id, k));
            // Every ready frame's node is on the bus by now; nothing to send is only defensive.
            let Some((_, node, mailbox, pending)) = winner else {
                break;
            };
            self.transmit(start, node, mailbox, pending, &mut events);
        }
        events
    }

    /// Bus-off controllers whose recovery time has passed by `now` rejoin, error-active.
    fn recover_bus_off(&mut self, now: u64, events: &mut Vec<Event>) {
        for (k, n) in self.nodes.iter_mut().enumerate() {
            if n.bus_off && n.hold_until <= now {
                n.bus_off = false;
                n.tec = 0;
                n.rec = 0;
                events.push(Event::StateChange {
                    node: k,
                    at: n.hold_until,
                    state: ErrorState::Active,
                });
            }
        }
    }

    fn transmit(
        &mut self,
        start: u64,
        node: NodeId,
        mailbox: usize,
        pending: Pending,
        events: &mut Vec<Event>,
    ) {
        let frame = pending.frame;
        let length = frame_bits(&frame);
        let stuffed = length - TAIL_BITS;
        let receivers: u32 = self
            .nodes
            .iter()
            .enumerate()
            .filter(|&(k, n)| k != node && self.on_bus(n))
            .fold(0, |mask, (k, _)| mask | 1 << k);
        let fault = self
            .faults
            .iter()
            .position(|f| f.id.is_none_or(|id| id == frame.id) && f.not_before <= start);
        let error = if let Some(f) = fault {
            let fault = self.faults.remove(f);
            Some((ErrorKind::Bit, fault.at_bit.min(stuffed - 1)))
        } else if receivers == 0 {
            // The ACK slot follows the CRC delimiter.
            Some((ErrorKind::Ack, stuffed + 1))
        } else {
            None
        };
        let before = self.state_snapshot();
        match error {
            None => {
                let end = start + u64::from(length);
                self.idle_from = end + u64::from(INTERMISSION_BITS);
                let sender = &mut self.nodes[node];
                match sender.mailboxes.get_mut(mailbox) {
                    Some(slot) => *slot = None,
                    // The babbling frame is pending again the moment it completes.
                    None => {
                        if let Some(b) = sender.babble.as_mut() {
                            b.pending_since = end;
                        }
                    }
                }
                sender.tec = sender.tec.saturating_sub(1);
                if sender.state() == ErrorState::Passive {
                    sender.hold_until = self.idle_from + u64::from(SUSPEND_TRANSMISSION_BITS);
                }
                for (k, n) in self.nodes.iter_mut().enumerate() {
                    if receivers & 1 << k != 0 {
                        n.rec = n.rec.saturating_sub(1);
                    }
                }
                events.push(Event::Sent {
                    node,
                    mailbox,
                    frame,
                    queued_at: pending.queued_at,
                    start,
                    end,
                    receivers,
                });
            }
            Some((kind, bit)) => {
                let at = start + u64::from(bit);
                let idle_at =
                    at + 1 + u64::from(ERROR_FLAG_BITS + ERROR_DELIMITER_BITS + INTERMISSION_BITS);
                self.idle_from = idle_at;
                let passive = self.nodes[node].state() == ErrorState::Passive;
                let sender = &mut self.nodes[node];
                if let Some(p) = sender.mailboxes.get_mut(mailbox).and_then(Option::as_mut) {
                    p.failed_attempts += 1;
                }
                // ISO 11898-1: an error-passive transmitter's ACK error does not count.
                if !(kind == ErrorKind::Ack && passive) {
                    sender.tec += 8;
                }
                if sender.tec > 255 {
                    sender.bus_off = true;
                    sender.hold_until = idle_at + BUS_OFF_RECOVERY_BITS;
                } else if sender.state() == ErrorState::Passive {
                    sender.hold_until = idle_at + u64::from(SUSPEND_TRANSMISSION_BITS);
                }
                for (k, n) in self.nodes.iter_mut().enumerate() {
                    if receivers & 1 << k != 0 && kind == ErrorKind::Bit {
                        n.rec = (n.rec + 1).min(255);
                    }
                }
                events.push(Event::ErrorFrame {
                    node,
                    mailbox,
                    frame,
                    start,
                    at,
                    kind,
                    idle_at,
                });
            }
        }
        let after = self.state_snapshot();
        for (k, (b, a)) in before.iter().zip(&after).enumerate() {
            if b != a {
                events.push(Event::StateChange {
                    node: k,
                    at: self.idle_from,
                    state: *a,
                });
            }
        }
    }

    fn state_snapshot(&self) -> Vec<ErrorState> {
        self.nodes.iter().map(Node::state).collect()
    }
}

#[cfg(test)]
mod tests;
