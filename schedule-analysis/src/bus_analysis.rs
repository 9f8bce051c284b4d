//! The bus's analysis, the one both the report ([`crate::analysis`]) and the on-chip admission check
//! ([`crate::admission`]) run, on the sound transmit path (docs/analysis.md, "The sound transmit path: the design"):
//! every message's queuing jitter from its sender's response variation and its board's transmit interrupt, each
//! board's frames charged the intervals in which a queued frame of it is not covered, then non-preemptive
//! fixed-priority response times by arbitration (Davis, Burns, Bril & Lukkien 2007). [`analyse`] is the host's form,
//! [`analyse_each`] the chip's (the same bounds).
//!
//! `no_std` and allocation-free: the caller owns the working memory (the chip fixed-capacity arrays, the host
//! vectors) and sorts the messages by arbitration itself (the chip by an insertion sort of bytes, the host by the
//! standard library's stable sort), and each puts the responses where it keeps them ([`Results`]).

use crate::board::Results;
use crate::busy_window::{Counter, Limits};
use crate::can::{self, FrameCost, MessageTiming};
use crate::time::Time;

/// What a message's sender contributes to its queuing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sender {
    /// No sending task in the analysis (a command stream): its own queuing jitter only.
    Outside,
    /// The sending job's worst and best response, and its board's transmit interrupt's worst response (zero
    /// without one).
    Bounded {
        /// The sending job's worst-case response.
        worst: Time,
        /// Its best case: the earliest its frames are queued after its activation.
        best: Time,
        /// The transmit interrupt's worst-case response.
        tx: Time,
    },
    /// The sending job, or its board's transmit interrupt, has no bound: neither has the message.
    Unbounded,
}

/// One message stream as the bus analysis reads it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Message {
    /// Identifier.
    pub id: u32,
    /// 29-bit identifier.
    pub extended: bool,
    /// Data bytes per frame.
    pub dlc: u8,
    /// Frames queued together per activation.
    pub frames: u32,
    /// Period or minimum inter-arrival time.
    pub period: Time,
    /// Queuing jitter of its own.
    pub jitter: Time,
    /// Its sender.
    pub sender: Sender,
}

impl Message {
    /// Its timing on the bus and the earliest its frames are queued after the sender's activation (`None` when the
    /// sender has no bound). The queuing jitter is its own plus, for a sent message, the sender's response
    /// variation and the transmit interrupt's response.
    pub fn timing(&self, cost: FrameCost, bit: Time) -> (MessageTiming, Option<Time>) {
        let (jitter, offset) = match self.sender {
            Sender::Outside => (self.jitter, Some(Time::ZERO)),
            Sender::Bounded { worst, best, tx } => {
                (self.jitter.plus(worst.minus(best)).plus(tx), Some(best))
            }
            Sender::Unbounded => (self.jitter, None),
        };
        let timing = MessageTiming {
            key: can::arbitration_key(self.id, self.extended),
            frame_time: can::frame_time(cost, self.dlc, self.extended, bit),
            frames: self.frames,
            period: self.period,
            jitter,
        };
        (timing, offset)
    }
}

/// The bus analysis's working memory, one entry per message in arbitration order.
pub struct BusWork<'a, I> {
    /// The messages' indices sorted by [`can::arbitration_key`] (equal keys in index order).
    pub order: &'a [I],
    /// Each message's timing (queuing jitter included).
    pub timings: &'a mut [MessageTiming],
    /// The earliest its frames are queued after its sender's activation; `None`: the sender has no bound.
    pub offsets: &'a mut [Option<Time>],
    /// Its blocking: the longest lower-priority frame.
    pub blockings: &'a mut [Time],
    /// The busy-window analysis's working memory.
    pub scratch: &'a mut [Counter],
}

/// The greatest identifier of the frames the boards send outside the model's messages: a verdict's two pages and a
/// diagnostics sample's six go on the diagnostics topics (0x1A–0x1C) at any of the four levels, eight bytes each, so
/// the least urgent is 0x400 | 3 << 8 | 0x1C (docs/protocol.md). A message below it may be blocked by one.
pub const LEAST_URGENT_PAGE: u32 = 0x71C;

/// A bus with no message sent through a transmit interrupt, as [`analyse`] reads it: the blockings, then every
/// message's fixed point by [`can::response_times_into`] (each started from the next more urgent identifier's
/// windows: the host's form; the same bounds as [`analyse_each`]'s one by one).
fn analyse_hinted<I, R>(
    message: impl Fn(usize) -> Option<Message>,
    work: BusWork<'_, I>,
    cost: FrameCost,
    bit: Time,
    limits: &Limits,
    out: &mut R,
) where
    I: Copy + Into<usize>,
    R: Results + ?Sized,
{
    let n = work.order.len();
    fill(&message, work.order, work.timings, work.offsets, cost, bit);
    let timings = work.timings.get(..n).unwrap_or(&[]);
    can::blockings(timings, work.blockings);
    can::response_times_into(
        timings,
        work.blockings.get(..n).unwrap_or(&[]),
        bit,
        limits,
        work.scratch,
        out,
    );
}

/// Each message's timing and queuing offset, in arbitration order (`order`).
fn fill<I: Copy + Into<usize>>(
    message: &impl Fn(usize) -> Option<Message>,
    order: &[I],
    timings: &mut [MessageTiming],
    offsets: &mut [Option<Time>],
    cost: FrameCost,
    bit: Time,
) {
    for ((&i, timing), offset) in order.iter().zip(timings.iter_mut()).zip(offsets.iter_mut()) {
        if let Some(m) = message(i.into()) {
            (*timing, *offset) = m.timing(cost, bit);
        }
    }
}

/// Analyses the bus on the sound transmit path (docs/analysis.md, "The sound transmit path: the design"):
/// `message(i)` is message `i`; `out.put(k, …)` gets the response of the message at arbitration position `k`
/// (`work.order[k]`), from its queuing. Its delivery after the sender's activation is
/// [`delivery`]`(offsets[k], response)`.
///
/// Every message's queuing jitter is its own plus its sender's response variation and its board's transmit
/// response ([`Message::timing`]); the blockings are the longest less urgent frames; then non-preemptive
/// fixed-priority response times by arbitration. For a message a board sends through its transmit interrupt (a
/// [`Sender::Bounded`] sender with a transmit response `tx` above zero) its board's frames each cost `tx` + the
/// longest frame more (the intervals in which a queued frame is not covered by a more urgent pending one of its
/// board: one per own frame at most), and every message below [`LEAST_URGENT_PAGE`] is blocked by at least the
/// longest frame (a page outside the model). The blockings are worked out on the true frame times; each board's
/// messages are analysed with that board's frames raised, every other message on the true ones (boards with equal
/// `tx` are raised together: more, never less). A bus with no such sender (a model file's) has no raised frame and
/// no page floor: the plain analysis, with start hints ([`can::response_times_into`]). [`analyse_each`], the
/// chip's form, gives the same bounds without the hints.
pub fn analyse<I, R>(
    message: impl Fn(usize) -> Option<Message>,
    work: BusWork<'_, I>,
    cost: FrameCost,
    bit: Time,
    limits: &Limits,
    out: &mut R,
) where
    I: Copy + Into<usize>,
    R: Results + ?Sized,
{
    let charged = work.order.iter().any(|&i| {
        message(i.into())
            .is_some_and(|m| matches!(m.sender, Sender::Bounded { tx, .. } if !tx.is_zero()))
    });
    if charged {
        analyse_each(message, work, cost, bit, limits, out);
    } else {
        analyse_hinted(message, work, cost, bit, limits, out);
    }
}

/// [`analyse`]'s bounds, every message by its own fixed point ([`can::response_time`], no start hints from the next
/// more urgent identifier): the on-chip check's form, whose image then needs neither [`can::response_times_into`]
/// nor its level loads. A bus with no message through a transmit interrupt gets the plain analysis's bounds (no
/// raised frames, no page floor).
pub fn analyse_each<I, R>(
    message: impl Fn(usize) -> Option<Message>,
    work: BusWork<'_, I>,
    cost: FrameCost,
    bit: Time,
    limits: &Limits,
    out: &mut R,
) where
    I: Copy + Into<usize>,
    R: Results + ?Sized,
{
    let n = work.order.len();
    // The transmit response of the board sending the message at position `k`, zero for none.
    let charge = |k: usize| match work.order.get(k).and_then(|&i| message(i.into())) {
        Some(Message {
            sender: Sender::Bounded { tx, .. },
            ..
        }) => tx,
        _ => Time::ZERO,
    };
    let charged = (0..n).any(|k| !charge(k).is_zero());
    fill(&message, work.order, work.timings, work.offsets, cost, bit);
    let timings = work.timings.get_mut(..n).unwrap_or(&mut []);
    can::blockings(timings, work.blockings);
    let longest = timings
        .iter()
        .fold(can::frame_time(cost, 8, false, bit), |l, m| {
            l.max_of(m.frame_time)
        });
    let floor = can::arbitration_key(LEAST_URGENT_PAGE, false);
    for (b, m) in work.blockings.iter_mut().zip(timings.iter()) {
        if charged && m.key < floor {
            *b = b.max_of(longest);
        }
    }
    for first in 0..n {
        let tx = charge(first);
        // Each group of equal transmit responses once, at its first message.
        if (0..first).any(|k| charge(k) == tx) {
            continue;
        }
        let gap = if tx.is_zero() {
            Time::ZERO
        } else {
            tx.plus(longest)
        };
        for (k, m) in timings.iter_mut().enumerate() {
            if charge(k) == tx {
                m.frame_time = m.frame_time.plus(gap);
            }
        }
        for k in first..n {
            if charge(k) != tx {
                continue;
            }
            let limits = Limits {
                iterations: out
                    .iterations_left()
                    .map_or(limits.iterations, |left| left.min(limits.iterations)),
                ..*limits
            };
            let blocking = work.blockings.get(k).copied().unwrap_or(Time::ZERO);
            out.put(
                k,
                can::response_time(timings, k, blocking, bit, &limits, work.scratch),
            );
        }
        for (k, m) in timings.iter_mut().enumerate() {
            if charge(k) == tx {
                m.frame_time = m.frame_time.minus(gap);
            }
        }
    }
}

/// A message's delivery after its sender's activation: its queuing offset plus its response on the bus (`None`
/// when either has no bound, or the sum does not fit: never a saturated bound).
pub fn delivery(offset: Option<Time>, response: Option<Time>) -> Option<Time> {
    offset?.checked_plus(response?)
}
