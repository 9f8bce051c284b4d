//! The sound transmit path's verdict (docs/analysis.md, *Why the bounds are safe*, "The sound transmit path: the
//! design"), a host-side line beside the model the verdict, `--check` and the boards' admission run. Their model
//! charges a sent frame one transmit-interrupt response between its queuing and its arbitration; the sound one
//! charges each board's frames the intervals in which a queued frame of it is covered by no more urgent pending frame
//! of its board (`bus_analysis::analyse_sound`, the shared core the chip can run too), blocks every message by at
//! least a page outside the model, and gives each transmit job its transmit interrupt as a second releaser
//! (`board_analysis::Release::also`) for the aborts it asks after its pend. This module analyses the whole system so ([`analyse`]) and says what that breaks
//! ([`AbortRefill`], the report's line after the VERDICT). The transmit-path simulator (tests/simulation.rs) beats the
//! uncharged model and holds to this one; the boards still admit on the uncharged one (a known soundness gap,
//! docs/analysis.md).

use serde::Serialize;

use crate::analysis::{self, Analysis, Options, TransmitPath};
use crate::model::System;

/// The whole system analysed under `options` on the sound transmit path: the bus by
/// [`crate::bus_analysis::analyse_sound`], each transmit job with its board's transmit-interrupt response as a
/// second releaser ([`crate::board_analysis::Release::also`]), whose fixed point the board's release-jitter rounds
/// reach.
pub fn analyse(system: &System, options: &Options) -> Analysis {
    analysis::analyse_on(system, options, TransmitPath::Sound)
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
        let a = analyse(system, options);
        AbortRefill {
            schedulable: a.all_ok(),
            breaks: a.failure_figures(),
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
