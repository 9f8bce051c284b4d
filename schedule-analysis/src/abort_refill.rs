//! The charged model of a frame that needs a mailbox abort (docs/analysis.md, *Why the bounds are safe*, "A frame
//! that needs an abort"): a host-side switch beside the model the verdict, `--check` and the boards' admission run.
//! Their model charges a sent frame one transmit-interrupt response between its queuing and its arbitration; a
//! frame whose board's three mailboxes hold less urgent frames, the least urgent on the bus, waits for that frame
//! to end and for a second transmit response before it is in arbitration, and the transmit job that asks the abort
//! runs within the transmit interrupt's response after its pend. This module analyses the whole system with both
//! charged ([`analyse`]) and says what that breaks ([`AbortRefill`], the report's line after the VERDICT). The
//! transmit-path simulator (tests/simulation.rs) beats the uncharged model and holds to this one, and the known
//! answers (tests/known_answers.rs) work both by hand; the boards still admit on the uncharged one (a known
//! soundness gap, docs/analysis.md).
//!
//! The chip's check has none of this (its image has no room to spare and its decisions stay those of the shipped
//! sets): the charge is applied to the model's own jitters, so the core analyses run unchanged.

use serde::Serialize;

use crate::analysis::{self, Analysis, Options};
use crate::can::{self, FrameCost};
use crate::model::System;
use crate::time::Time;

/// Rounds of the transmit interrupt's response before the charged model gives up on a fixed point. Each round
/// analyses the whole system once; the response only grows round to round, and on the shipped sets it settles
/// within a few.
pub const MAX_ROUNDS: usize = 64;

/// What a sent frame's queuing jitter adds for the mailbox abort it may need: the job that asks for the abort
/// (within the transmit interrupt's response `tx`) leaves the least urgent frame on the bus; the abort takes effect
/// only as that frame ends (at most the longest frame a board sends — eight data bytes, standard identifier — under
/// `cost`, after the ask), and the frame is in the freed mailbox, in arbitration, only when the job that completion
/// pends has run (`tx` again). So `tx` + the longest own frame on top of the one `tx` every sent frame is charged.
/// Zero for a board without a transmit interrupt (`tx` zero: its frames are in arbitration when queued).
pub fn refill_delay(tx: Time, cost: FrameCost, bit: Time) -> Time {
    if tx.is_zero() {
        return Time::ZERO;
    }
    tx.plus(can::frame_time(cost, 8, false, bit))
}

/// `system` with the charge for transmit responses `tx` (per board, zero where it has no transmit interrupt): each
/// transmit job a job queuing frames releases (not the transmit interrupt itself) takes `tx` into its own release
/// jitter (the abort its frames cause is asked in a job of the transmit interrupt, within its response after the
/// pend: `can::transmit_abort_latency` counts from that ask), and each message a task other than the transmit
/// interrupt sends takes [`refill_delay`] into its own queuing jitter.
fn charged(system: &System, tx: &[Time], cost: FrameCost) -> System {
    let mut out = system.clone();
    for (b, board) in out.boards.iter_mut().enumerate() {
        let Some(&r) = tx.get(b) else { continue };
        let can_tx = board.can_tx_task;
        let transmit: Vec<bool> = (0..board.tasks.len())
            .map(|i| board.is_transmit(i) && can_tx != Some(i))
            .collect();
        for (task, is_job) in board.tasks.iter_mut().zip(transmit) {
            if is_job && task.released_by.is_some() {
                task.jitter = task.jitter.plus(r);
            }
        }
    }
    if let Some(bus) = out.bus.as_mut() {
        let bit = bus.bit_time;
        for m in &mut bus.messages {
            let Some(s) = m.sender else { continue };
            let on_board = system.boards.get(s.board);
            if on_board.and_then(|b| b.can_tx_task) == Some(s.task) {
                continue;
            }
            if let Some(&r) = tx.get(s.board) {
                m.jitter = m.jitter.plus(refill_delay(r, cost, bit));
            }
        }
    }
    out
}

/// Each board's transmit-interrupt response in `analysis` (zero where it has none); `None` when one has no bound.
fn transmit_responses(system: &System, analysis: &Analysis) -> Option<Vec<Time>> {
    system
        .boards
        .iter()
        .zip(&analysis.boards)
        .map(|(board, result)| match board.can_tx_task {
            None => Some(Time::ZERO),
            Some(t) => result.tasks.get(t).and_then(|r| r.wcrt()),
        })
        .collect()
}

/// The whole system analysed under `options` with a frame's abort refill charged: the transmit interrupt's response
/// a fixed point of the rounds (each a whole [`analysis::analyse`] with the charge of the previous round's
/// responses, from none), the last round's analysis returned. Where a board's transmit interrupt loses its bound the
/// round that lost it is returned (its frames then have none). `None`: no fixed point within [`MAX_ROUNDS`].
pub fn analyse(system: &System, options: &Options) -> Option<Analysis> {
    let cost = options.frame_cost.cost();
    let mut tx = vec![Time::ZERO; system.boards.len()];
    for _ in 0..MAX_ROUNDS {
        let analysis = analysis::analyse(&charged(system, &tx, cost), options);
        match transmit_responses(system, &analysis) {
            Some(found) if found != tx => tx = found,
            _ => return Some(analysis),
        }
    }
    None
}

/// The verdict with the abort refill charged, for the report's line after the VERDICT (and `abort_refill` in its
/// JSON form).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AbortRefill {
    /// Every deadline and jitter budget met with the charge.
    pub schedulable: bool,
    /// What fails, each with its figure against its limit (`topic/gyroscope jitter 1002.95 of 1000 µs`); with no
    /// fixed point of the transmit responses, that.
    pub breaks: Vec<String>,
}

impl AbortRefill {
    /// `system` analysed with the charge under `options` ([`analyse`]).
    pub fn of(system: &System, options: &Options) -> AbortRefill {
        match analyse(system, options) {
            Some(a) => AbortRefill {
                schedulable: a.all_ok(),
                breaks: a.failure_figures(),
            },
            None => AbortRefill {
                schedulable: false,
                breaks: vec![format!(
                    "no fixed point of the transmit interrupts' responses within {MAX_ROUNDS} rounds"
                )],
            },
        }
    }

    /// The report's line: what the verdict is with the charge, and that the boards still admit without it.
    pub fn line(&self) -> String {
        let head = "With a frame's abort refill charged (docs/analysis.md, \"A frame that needs an abort\")";
        let gap = "the VERDICT above and the boards' admission are on the uncharged model, a known soundness gap";
        if self.schedulable {
            format!("{head}: schedulable too ({gap})")
        } else {
            format!(
                "{head}: NOT schedulable — {} ({gap})",
                self.breaks.join(", ")
            )
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_refill_is_a_second_transmit_response_and_the_longest_frame() {
        let bit = can::bit_time(1_000_000);
        assert_eq!(
            refill_delay(Time::from_us(30), FrameCost::Exact, bit),
            Time::from_us(165)
        );
        assert_eq!(refill_delay(Time::ZERO, FrameCost::Exact, bit), Time::ZERO);
    }

    #[test]
    fn the_line_names_what_breaks_and_the_gap() {
        let broken = AbortRefill {
            schedulable: false,
            breaks: vec!["topic/a jitter 1002.95 of 1000 µs".into()],
        };
        assert_eq!(
            broken.line(),
            "With a frame's abort refill charged (docs/analysis.md, \"A frame that needs an abort\"): NOT \
             schedulable — topic/a jitter 1002.95 of 1000 µs (the VERDICT above and the boards' admission are on \
             the uncharged model, a known soundness gap)"
        );
        let fine = AbortRefill {
            schedulable: true,
            breaks: Vec::new(),
        };
        assert!(
            fine.line().contains(": schedulable too ("),
            "{}",
            fine.line()
        );
    }
}
