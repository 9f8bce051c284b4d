//! The bus report of a robot run: per message, the worst response observed on the simulated bus
//! (released into its node's transmit queue → completed) beside the Davis et al. (2007) bound
//! schedule-analysis computes for the same traffic.
//!
//! "The same traffic" is read off the run: each identifier is one stream, its frame length the
//! longest seen (worst-case stuffing, the analysis's `exact` cost), its frames per activation the
//! largest burst (frames released while an earlier one of the burst was still on its way), its period the shortest time
//! between two bursts (a single burst: the run's length). Frames are counted from the moment they
//! entered their node's transmit queue (a board's driver gives one frame of an identifier a mailbox
//! at a time, so a sample's later frames wait there), as the analysis counts from queuing, with no
//! queuing jitter. Error frames are outside the analysis: a run with a fault episode is reported,
//! not checked.
use std::collections::BTreeMap;

use schedule_analysis::busy_window::{AnalysisError, Counter, Limits};
use schedule_analysis::can::{self, FrameCost, MessageTiming};
use schedule_analysis::time::Time;

use crate::{Transfer, NODES};

/// One message stream of the run.
#[derive(Debug, Clone, PartialEq)]
pub struct Line {
    /// Identifier.
    pub id: u16,
    /// Its sender.
    pub node: usize,
    /// Frames seen.
    pub frames: usize,
    /// Longest data length seen.
    pub dlc: u8,
    /// Frames per activation (the largest burst).
    pub per_activation: u32,
    /// Shortest time between two activations (µs).
    pub period_us: u64,
    /// Worst observed response, released → completed (µs).
    pub observed_us: u64,
    /// The analysis's bound (µs), or why there is none.
    pub bound_us: Result<u64, String>,
}

impl Line {
    /// Whether the observation exceeds the bound (or there is no bound).
    pub fn exceeds(&self) -> bool {
        self.bound_us
            .as_ref()
            .map_or(true, |&b| self.observed_us > b)
    }
}

/// The report of `transfers` from a run of `duration_us`.
pub fn analyse(transfers: &[Transfer], duration_us: u64) -> Vec<Line> {
    let mut streams: BTreeMap<u16, Vec<&Transfer>> = BTreeMap::new();
    for t in transfers {
        streams.entry(t.frame.id).or_default().push(t);
    }
    let mut lines: Vec<Line> = streams
        .iter()
        .map(|(&id, frames)| {
            let mut queued: Vec<(u64, u64)> =
                frames.iter().map(|t| (t.released_at, t.end)).collect();
            queued.sort_unstable();
            // (first queued, frames, last completion)
            let mut bursts: Vec<(u64, u32, u64)> = Vec::new();
            for &(q, end) in &queued {
                match bursts.last_mut() {
                    Some((_, n, busy_until)) if q <= *busy_until => {
                        *n += 1;
                        *busy_until = (*busy_until).max(end);
                    }
                    _ => bursts.push((q, 1, end)),
                }
            }
            let period_us = bursts
                .windows(2)
                .map(|w| w[1].0 - w[0].0)
                .min()
                .unwrap_or(duration_us.max(1));
            Line {
                id,
                node: frames[0].node,
                frames: frames.len(),
                dlc: frames.iter().map(|t| t.frame.len).max().unwrap_or(0),
                per_activation: bursts.iter().map(|b| b.1).max().unwrap_or(1),
                period_us,
                observed_us: frames
                    .iter()
                    .map(|t| t.end - t.released_at)
                    .max()
                    .unwrap_or(0),
                bound_us: Err(String::new()),
            }
        })
        .collect();
    // Highest priority first, as the analysis wants them.
    let bit = can::bit_time(can::DEFAULT_BITRATE);
    let timings: Vec<MessageTiming> = lines
        .iter()
        .map(|l| MessageTiming {
            key: can::arbitration_key(u32::from(l.id), false),
            frame_time: can::frame_time(FrameCost::Exact, l.dlc, false, bit),
            frames: l.per_activation,
            period: Time::from_us(l.period_us),
            jitter: Time::ZERO,
        })
        .collect();
    let n = timings.len();
    let mut blocking = vec![Time::ZERO; n];
    can::blockings(&timings, &mut blocking);
    let mut scratch = vec![Counter::default(); n];
    let mut out = vec![Err(AnalysisError::NoSuchIndex); n];
    can::response_times(
        &timings,
        &blocking,
        bit,
        &Limits::default(),
        &mut scratch,
        &mut out,
    );
    for (line, result) in lines.iter_mut().zip(out) {
        line.bound_us = result
            .map(|r| r.wcrt.as_ns().div_ceil(1_000))
            .map_err(|e| format!("{e:?}"));
    }
    lines
}

/// The report as a table.
pub fn render(lines: &[Line]) -> String {
    let mut text = String::from(
        "bus report: observed worst response (released → completed) against the Davis analysis of the same traffic\n\
         id   sender        frames  dlc  burst  period µs  observed µs  bound µs\n",
    );
    for l in lines {
        let bound = match &l.bound_us {
            Ok(b) => b.to_string(),
            Err(e) => format!("none ({e})"),
        };
        text.push_str(&format!(
            "{:03X}  {:<12}  {:>6}  {:>3}  {:>5}  {:>9}  {:>11}  {:>8}{}\n",
            l.id,
            NODES[l.node],
            l.frames,
            l.dlc,
            l.per_activation,
            l.period_us,
            l.observed_us,
            bound,
            if l.exceeds() { "  EXCEEDED" } else { "" }
        ));
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;
    use amiro_bus_sim::Frame;

    fn transfer(node: usize, id: u16, len: usize, queued_at: u64, end: u64) -> Transfer {
        Transfer {
            node,
            mailbox: 0,
            frame: Frame::new(id, &[0x55; 8][..len]).unwrap(),
            queued_at,
            released_at: queued_at,
            start: end - 50,
            end,
        }
    }

    #[test]
    fn streams_bursts_periods_and_bounds() {
        // 0x100 every 1000 µs, one frame; 0x200 every 5000 µs, bursts of two; each observed
        // responds within its bound, which for 0x100 is its own frame plus the longest lower one.
        let mut t = Vec::new();
        for k in 0..10 {
            t.push(transfer(0, 0x100, 2, k * 1000, k * 1000 + 60));
        }
        for k in 0..2 {
            t.push(transfer(1, 0x200, 8, k * 5000 + 10, k * 5000 + 200));
            t.push(transfer(1, 0x200, 8, k * 5000 + 11, k * 5000 + 330));
        }
        let lines = analyse(&t, 10_000);
        assert_eq!(lines.len(), 2);
        assert_eq!(
            (lines[0].id, lines[0].per_activation, lines[0].period_us),
            (0x100, 1, 1000)
        );
        assert_eq!(
            (lines[1].id, lines[1].per_activation, lines[1].period_us),
            (0x200, 2, 5000)
        );
        let bit = can::bit_time(can::DEFAULT_BITRATE);
        let own = can::frame_time(FrameCost::Exact, 2, false, bit).as_ns() / 1000;
        let lower = can::frame_time(FrameCost::Exact, 8, false, bit).as_ns() / 1000;
        assert_eq!(lines[0].bound_us, Ok(own + lower));
        assert!(!lines[0].exceeds() && !lines[1].exceeds());
        // A burst counts from its release, not from the mailbox: the driver gives an identifier one
        // mailbox at a time, so a sample's second frame enters its mailbox as the first completes.
        let mut later = transfer(1, 0x200, 8, 5_205, 5_335);
        later.released_at = 5_011;
        let mut u = t.clone();
        u[13] = later;
        let lines = analyse(&u, 10_000);
        assert_eq!((lines[1].per_activation, lines[1].period_us), (2, 5000));
        assert_eq!(lines[1].observed_us, 5_335 - 5_011);
        // A frame that waited far longer than any bound is flagged.
        t.push(transfer(0, 0x100, 2, 20_000, 25_000));
        let lines = analyse(&t, 30_000);
        assert!(lines[0].exceeds());
        assert!(render(&lines).contains("EXCEEDED"));
    }
}
