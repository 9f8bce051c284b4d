//! What the check keeps of a board's analysis between decisions: [`Cache`], its per-board [`Summary`] and the
//! [`BoardKey`] of the inputs it holds for.

use super::*;

/// Most boards a [`Cache`] keeps (the AMiRo has three; the analyses of further boards are not kept).
pub const MAX_BOARDS: usize = 3;

/// Each board's last analysis, kept between decisions by a board that decides many requests: a board's tasks
/// depend only on its own streams (and the horizon), so a request on one board leaves the other boards' results
/// as they were. A summary is reused only when its inputs are the same — the board's streams in the same order
/// with the same topic, level, size, period and deadline, and the same horizon — so a decision with the cache is
/// the decision without it (a test compares them), at a fraction of the cost.
///
/// Its empty value is all zero bytes (no summary kept), so a board's admission state, a `static` initialised with
/// it, is placed in `.bss` and costs no flash.
#[derive(Debug, Clone)]
pub struct Cache<const M: usize> {
    pub(super) boards: [Summary<M>; MAX_BOARDS],
    /// The longest period or deadline of the robot's fixed tasks (the table's part of the horizon), once worked
    /// out; zero before. A cache belongs to one robot table.
    pub(super) fixed_longest: Time,
}

impl<const M: usize> Cache<M> {
    /// Nothing analysed yet.
    pub const fn new() -> Self {
        Self {
            boards: [Summary::EMPTY; MAX_BOARDS],
            fixed_longest: Time::ZERO,
        }
    }
}

impl<const M: usize> Default for Cache<M> {
    fn default() -> Self {
        Self::new()
    }
}

/// Everything a board's analysis reads from the configuration: the horizon and, per stream the board sends (in
/// order), its topic, level, data bytes, period and deadline.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct BoardKey<const M: usize> {
    pub(super) horizon: Time,
    pub(super) len: u8,
    pub(super) topic: [u8; M],
    pub(super) level: [u8; M],
    pub(super) dlc: [u8; M],
    pub(super) period: [Time; M],
    pub(super) deadline: [u64; M],
}

impl<const M: usize> BoardKey<M> {
    /// No streams, zero horizon: all zero bytes.
    pub(super) const EMPTY: Self = BoardKey {
        horizon: Time::ZERO,
        len: 0,
        topic: [0; M],
        level: [0; M],
        dlc: [0; M],
        period: [Time::ZERO; M],
        deadline: [0; M],
    };

    /// Writes the key of board `b`'s streams in `streams` with `horizon` into `self` (in place: a key is a few
    /// hundred bytes, and built and copied it was one `memcpy` per copy); `None` when the board sends more than `M`.
    pub(super) fn fill(&mut self, b: usize, streams: &View<'_, M>, horizon: Time) -> Option<()> {
        self.horizon = horizon;
        self.len = 0;
        for (_, s) in streams.iter() {
            let Some(sender) = s.sender.filter(|x| usize::from(x.board) == b) else {
                continue;
            };
            let i = usize::from(self.len);
            *self.topic.get_mut(i)? = sender.topic;
            *self.level.get_mut(i)? = sender.level;
            *self.dlc.get_mut(i)? = s.dlc;
            *self.period.get_mut(i)? = s.period;
            *self.deadline.get_mut(i)? = s.deadline.map_or(NONE, Time::as_ns);
            self.len += 1;
        }
        Some(())
    }
}

/// What one board's analysis gives the rest of the check. [`Summary::EMPTY`] is all zero bytes (see [`Cache`]).
#[derive(Debug, Clone, Copy)]
pub(super) struct Summary<const M: usize> {
    /// Whether this is a kept analysis (in a [`Cache`]); the rest is meaningless when not.
    pub(super) kept: bool,
    pub(super) key: BoardKey<M>,
    /// Whether a deadline of the board is violated: the first in table order is `task`'s, with these numbers.
    pub(super) violated: bool,
    pub(super) task: TaskId,
    /// Its WCRT ([`NONE`]: unbounded) and deadline.
    pub(super) violation_wcrt: u64,
    pub(super) violation_deadline: Time,
    /// Whether a violation is below the hard floor (a fixed task missing its deadline, or any job without a
    /// bound): the first in table order, with these numbers.
    pub(super) floor_violated: bool,
    pub(super) floor_task: TaskId,
    pub(super) floor_wcrt: u64,
    pub(super) floor_deadline: Time,
    /// Its transmit interrupt's WCRT (0 without one, [`NONE`] unbounded).
    pub(super) tx: u64,
    /// Its command handler's WCRT (0 without one, [`NONE`] unbounded).
    pub(super) handler: u64,
    /// Per stream the board sends (in the key's order): its publisher job's WCRT (meaningful only when found)
    /// and whether the job was found.
    pub(super) wcrt: [u64; M],
    pub(super) found: [bool; M],
    /// The longest window any of its fixed points reached (ns), and whether one ran beyond the horizon: a kept
    /// analysis holds for another horizon when none did and it reached no further than the new one
    /// ([`Summary::holds_for`]), since the horizon only stops windows that grow past it.
    pub(super) reach: u64,
    pub(super) beyond: bool,
}

impl<const M: usize> Summary<M> {
    /// Whether this kept analysis is the one board `b` would get for `streams` at `horizon` (its key, compared with
    /// the view as it is read: no key is built for a board whose analysis is kept): the same streams in the same
    /// order, and the same horizon or one that stops none of its windows (a request with a long period moves the
    /// horizon, and so the key, of every board).
    pub(super) fn holds_for(&self, b: usize, streams: &View<'_, M>, horizon: Time) -> bool {
        let kept = &self.key;
        let mut n = 0usize;
        for (_, s) in streams.iter() {
            let Some(sender) = s.sender.filter(|x| usize::from(x.board) == b) else {
                continue;
            };
            let same = kept.topic.get(n) == Some(&sender.topic)
                && kept.level.get(n) == Some(&sender.level)
                && kept.dlc.get(n) == Some(&s.dlc)
                && kept.period.get(n) == Some(&s.period)
                && kept.deadline.get(n) == Some(&s.deadline.map_or(NONE, Time::as_ns));
            if !same {
                return false;
            }
            n += 1;
        }
        self.kept
            && usize::from(kept.len) == n
            && (kept.horizon == horizon || (!self.beyond && self.reach <= horizon.as_ns()))
    }

    pub(super) const EMPTY: Self = Summary {
        kept: false,
        key: BoardKey::EMPTY,
        violated: false,
        task: TaskId::Fixed(0),
        violation_wcrt: 0,
        violation_deadline: Time::ZERO,
        floor_violated: false,
        floor_task: TaskId::Fixed(0),
        floor_wcrt: 0,
        floor_deadline: Time::ZERO,
        tx: 0,
        handler: 0,
        wcrt: [0; M],
        found: [false; M],
        reach: 0,
        beyond: false,
    };

    /// Notes the board's (index `b`) first violated deadline and its first below the floor, in table order.
    pub(super) fn note_violations(&self, b: usize, found: &mut Found) {
        let violation = |task, wcrt, deadline| {
            Refusal::Deadline(Violation {
                culprit: Culprit::Task {
                    board: b as u8,
                    task,
                },
                wcrt: bound(wcrt),
                deadline,
            })
        };
        if self.violated {
            found.note(
                violation(self.task, self.violation_wcrt, self.violation_deadline),
                false,
            );
        }
        if self.floor_violated {
            found.note(
                violation(self.floor_task, self.floor_wcrt, self.floor_deadline),
                true,
            );
        }
    }

    /// Writes the board's numbers into the per-stream arrays the bus analysis reads.
    pub(super) fn apply(
        &self,
        b: usize,
        table: &BoardTable<'_>,
        streams: &View<'_, M>,
        senders: &mut SenderBounds<M>,
    ) {
        let mut own = 0usize;
        for (m, s) in streams.iter() {
            if let Some(sender) = s.sender.filter(|x| usize::from(x.board) == b) {
                if self.found.get(own).copied().unwrap_or(false) {
                    let best = table
                        .topics
                        .iter()
                        .find(|t| t.topic == sender.topic)
                        .map_or(0, |t| u64::from(t.bcet));
                    if let (Some(w), Some(bc), Some(t)) = (
                        senders.wcrt.get_mut(m),
                        senders.bcrt.get_mut(m),
                        senders.tx.get_mut(m),
                    ) {
                        *w = self.wcrt.get(own).copied().unwrap_or(NONE);
                        *bc = best;
                        *t = self.tx;
                    }
                }
                own += 1;
            }
            if s.receiver.is_some_and(|r| usize::from(r) == b) {
                if let Some(slot) = senders.receiver.get_mut(m) {
                    *slot = self.handler;
                }
            }
        }
    }
}
