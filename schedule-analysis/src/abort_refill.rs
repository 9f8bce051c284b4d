//! The sound transmit path's verdict (docs/analysis.md, *Why the bounds are safe*, "The sound transmit path: the
//! design"), a host-side line beside the model the verdict, `--check` and the boards' admission run. Their model
//! charges a sent frame one transmit-interrupt response between its queuing and its arbitration; the sound one
//! charges each board's frames the intervals in which a queued frame of it is covered by no more urgent pending frame
//! of its board (`bus_analysis::analyse_sound`, the shared core the chip can run too), blocks every message by at
//! least a page outside the model, and gives each transmit job a transmit response of release jitter for the aborts
//! it asks after its pend. This module analyses the whole system so ([`analyse`]) and says what that breaks
//! ([`AbortRefill`], the report's line after the VERDICT). The transmit-path simulator (tests/simulation.rs) beats the
//! uncharged model and holds to this one; the boards still admit on the uncharged one (a known soundness gap,
//! docs/analysis.md).

use serde::Serialize;

use crate::analysis::{self, Analysis, Options, TransmitPath};
use crate::model::System;
use crate::time::Time;

/// Rounds of the transmit interrupt's response before the charged model gives up on a fixed point. Each round
/// analyses the whole system once; the response only grows round to round, and on the shipped sets it settles
/// within a few.
pub const MAX_ROUNDS: usize = 64;

/// `system` with the transmit jobs' charge for transmit responses `tx` (per board, zero where it has no transmit
/// interrupt): each transmit job a job queuing frames releases (not the transmit interrupt itself) takes `tx` into
/// its own release jitter (the abort its frames cause is asked in a job of the transmit interrupt, within its
/// response after the pend: `can::transmit_abort_latency` counts from that ask). The frames' charge is the bus
/// analysis's ([`TransmitPath::Sound`]).
fn charged(system: &System, tx: &[Time]) -> System {
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

/// The whole system analysed under `options` on the sound transmit path: the transmit interrupt's response a fixed
/// point of the rounds (each a whole [`analysis::analyse_on`] with the transmit jobs' charge of the previous round's
/// responses, from none), the last round's analysis returned. Where a board's transmit interrupt loses its bound the
/// round that lost it is returned (its frames then have none). `None`: no fixed point within [`MAX_ROUNDS`].
pub fn analyse(system: &System, options: &Options) -> Option<Analysis> {
    let mut tx = vec![Time::ZERO; system.boards.len()];
    for _ in 0..MAX_ROUNDS {
        let analysis = analysis::analyse_on(&charged(system, &tx), options, TransmitPath::Sound);
        match transmit_responses(system, &analysis) {
            Some(found) if found != tx => tx = found,
            _ => return Some(analysis),
        }
    }
    None
}

/// The verdict on the sound transmit path, for the report's line after the VERDICT (and `abort_refill` in its JSON
/// form).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AbortRefill {
    /// Every deadline and jitter budget met with the charge.
    pub schedulable: bool,
    /// What fails, each with its figure against its limit (`topic/gyroscope jitter 1002.95 of 1000 µs`); with no
    /// fixed point of the transmit responses, that.
    pub breaks: Vec<String>,
}

impl AbortRefill {
    /// `system` analysed on the sound transmit path under `options` ([`analyse`]).
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

    /// The report's line: what the verdict is on the sound transmit path, and that the boards still admit without it.
    pub fn line(&self) -> String {
        let head = "On the sound transmit path (docs/analysis.md, \"The sound transmit path: the design\")";
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
    fn the_line_names_what_breaks_and_the_gap() {
        let broken = AbortRefill {
            schedulable: false,
            breaks: vec!["topic/a jitter 1002.95 of 1000 µs".into()],
        };
        assert_eq!(
            broken.line(),
            "On the sound transmit path (docs/analysis.md, \"The sound transmit path: the design\"): NOT \
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
