//! The bus's part of the check: the configuration's streams, with their senders' bounds, sorted by arbitration
//! into [`bus_analysis::analyse_each`] (the sound transmit path, the report's bounds without its start hints), then
//! each stream's violations.

use super::*;

/// The per-job numbers the analysis keeps of a [`Response`]: the bound (or [`NONE`]), its start hints, and the
/// iterations summed.
struct Bounds<'a> {
    wcrt: &'a mut [u64],
    first: &'a mut [Time],
    busy: &'a mut [Time],
    iterations: &'a mut u64,
    /// Whether a response ran out of its iterations ([`Refusal::Budget`]).
    limited: bool,
    /// Iterations the whole set may take ([`DECISION_ITERATIONS`]), and spent so far.
    budget: u64,
    spent: u64,
}

impl crate::board::Results for Bounds<'_> {
    fn put(&mut self, i: usize, result: Result<Response, AnalysisError>) {
        let (wcrt, first, busy) = match result {
            Ok(r) => {
                *self.iterations += r.iterations;
                self.spent += r.iterations;
                (r.wcrt.as_ns(), r.first_window, r.busy_window)
            }
            Err(e) => {
                self.limited |= e == AnalysisError::IterationLimit;
                (NONE, Time::ZERO, Time::ZERO)
            }
        };
        if let (Some(w), Some(f), Some(b)) = (
            self.wcrt.get_mut(i),
            self.first.get_mut(i),
            self.busy.get_mut(i),
        ) {
            *w = wcrt;
            *f = first;
            *b = busy;
        }
    }
    fn windows(&self, k: usize) -> Option<(Time, Time)> {
        let bounded = self.wcrt.get(k).is_some_and(|&w| w != NONE);
        bounded.then_some((*self.first.get(k)?, *self.busy.get(k)?))
    }
    fn iterations_left(&self) -> Option<u64> {
        Some(self.budget.saturating_sub(self.spent))
    }
}

/// The bus ([`bus_analysis::analyse_each`]) with the senders' bounds the boards' analyses found; `left`: the
/// fixed-point iterations all its messages together may take; `false` when they ran out ([`Refusal::Budget`]).
#[inline(never)]
pub(super) fn analyse_bus<const M: usize>(
    robot: &RobotTable<'_>,
    streams: &View<'_, M>,
    senders: &SenderBounds<M>,
    limits: &Limits,
    left: u64,
    iterations: &mut u64,
    found: &mut Found,
) -> bool {
    let n = streams.len;
    let mut order = [0u8; M];
    for (i, slot) in order.iter_mut().enumerate().take(n) {
        *slot = i as u8;
    }
    let key = |i: u8| {
        streams
            .get(usize::from(i))
            .map_or(u32::MAX, |s| can::arbitration_key(s.id, s.extended))
    };
    let order = order.get_mut(..n).unwrap_or(&mut []);
    insertion_sort(order, |a, b| key(a) > key(b));
    let mut timings = [MessageTiming {
        key: 0,
        frame_time: Time::ZERO,
        frames: 1,
        period: Time::ZERO,
        jitter: Time::ZERO,
    }; M];
    let mut offsets = [None; M];
    let mut blockings = [Time::ZERO; M];
    let mut scratch = const { [Counter::ZERO; M] };
    let mut wcrt = [NONE; M];
    let mut first_window = [Time::ZERO; M];
    let mut busy = [Time::ZERO; M];
    let mut bounds = Bounds {
        wcrt: &mut wcrt,
        first: &mut first_window,
        busy: &mut busy,
        iterations,
        limited: false,
        budget: left,
        spent: 0,
    };
    let work = bus_analysis::BusWork {
        order,
        timings: &mut timings,
        offsets: &mut offsets,
        blockings: &mut blockings,
        scratch: &mut scratch,
    };
    let message = |m: usize| bus_message(streams.get(m)?, senders, m);
    bus_analysis::analyse_each(
        message,
        work,
        robot.frame_cost,
        robot.bit_time,
        limits,
        &mut bounds,
    );
    if bounds.limited {
        return false;
    }
    for (position, &i) in order.iter().enumerate() {
        let m = usize::from(i);
        let Some(s) = streams.get(m) else { continue };
        let response = wcrt.get(position).copied().and_then(bound);
        let bus = bus_analysis::delivery(offsets.get(position).copied().flatten(), response);
        note_stream(
            s,
            bus,
            senders.receiver.get(m).copied().and_then(bound),
            found,
        );
    }
    true
}

/// Stream `m` of the configuration as the bus analysis reads it, with its sender's bounds.
fn bus_message<const M: usize>(
    s: &Stream,
    senders: &SenderBounds<M>,
    m: usize,
) -> Option<bus_analysis::Message> {
    let sender = if s.sender.is_none() {
        bus_analysis::Sender::Outside
    } else {
        let worst = senders.wcrt.get(m).copied().and_then(bound);
        let tx = senders.tx.get(m).copied().and_then(bound);
        match (worst, tx) {
            (Some(worst), Some(tx)) => bus_analysis::Sender::Bounded {
                worst,
                best: Time::from_ns(senders.bcrt.get(m).copied().unwrap_or(0)),
                tx,
            },
            _ => bus_analysis::Sender::Unbounded,
        }
    };
    Some(bus_analysis::Message {
        id: s.id,
        extended: s.extended,
        dlc: s.dlc,
        frames: s.frames,
        period: s.period,
        jitter: s.jitter,
        sender,
    })
}

/// Notes a stream's violations: its frames' delivery `bus` (from the sender's activation) against its deadline
/// and, for a command, its path to the receiver's handler (whose bound is `handler`).
fn note_stream(s: &Stream, bus: Option<Time>, handler: Option<Time>, found: &mut Found) {
    let mut late = |culprit, wcrt: Option<Time>, floor| {
        if wcrt.is_none_or(|w| w > s.deadline()) {
            let deadline = s.deadline();
            let violation = Violation {
                culprit,
                wcrt,
                deadline,
            };
            found.note(Refusal::Deadline(violation), floor);
        }
    };
    // Below the floor: frames without a bound, or a command's (not a publisher's) frames late.
    let floor = bus.is_none() || s.sender.is_none();
    late(Culprit::Frame { id: s.id }, bus, floor);
    if s.receiver.is_some() {
        let end = match (bus, handler) {
            (Some(w), Some(r)) => w.checked_plus(r),
            _ => None,
        };
        // A command's path to its handler: always below the floor.
        late(Culprit::EndToEnd { id: s.id }, end, true);
    }
}
