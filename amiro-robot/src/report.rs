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

/// How many of an identifier's latest frames [`Traffic`] keeps to put them in order of release.
pub const WINDOW: usize = 256;

/// The bus report's figures kept as a run goes, in a bounded space: per identifier its counts, its
/// longest frame, its worst response and its bursts folded so far, and its latest [`WINDOW`]
/// frames in order of release. A live run has no end: it keeps this, not every frame
/// ([`analyse`] on the whole), and its closing report comes from here.
///
/// Frames complete in order (the bus gives them so), but a frame released early can complete after
/// later ones of its identifier (another node's, a babbling controller's); bursts are folded in
/// order of release, so a frame is folded only once [`WINDOW`] later ones of its identifier have
/// come. The report is then [`analyse`]'s, unless a frame comes released before one already folded
/// ([`Traffic::out_of_order`] counts those: folded where they come, they can merge or split a
/// burst).
#[derive(Debug, Clone)]
pub struct Traffic {
    streams: BTreeMap<u16, Stream>,
    out_of_order: usize,
    /// Frames of one identifier kept unfolded ([`WINDOW`]; [`analyse`]'s: all of them).
    window: usize,
}

impl Default for Traffic {
    fn default() -> Self {
        Self {
            streams: BTreeMap::new(),
            out_of_order: 0,
            window: WINDOW,
        }
    }
}

/// One identifier's running figures.
#[derive(Debug, Default, Clone)]
struct Stream {
    node: usize,
    frames: usize,
    dlc: u8,
    observed_us: u64,
    /// The latest frames not yet folded, (released, completed), in order of release.
    window: std::collections::VecDeque<(u64, u64)>,
    /// The release of the last frame folded.
    folded_to: Option<u64>,
    /// The burst being folded: its first release, frames, last completion.
    burst: Option<(u64, u32, u64)>,
    /// The largest burst closed, the shortest time between two bursts' starts.
    per_activation: u32,
    period_us: Option<u64>,
}

impl Stream {
    fn fold(&mut self, (q, end): (u64, u64)) {
        self.folded_to = Some(self.folded_to.map_or(q, |f| f.max(q)));
        match &mut self.burst {
            Some((_, n, busy_until)) if q <= *busy_until => {
                *n += 1;
                *busy_until = (*busy_until).max(end);
            }
            burst => {
                if let Some((first, n, _)) = *burst {
                    self.per_activation = self.per_activation.max(n);
                    let gap = q.saturating_sub(first);
                    self.period_us = Some(self.period_us.map_or(gap, |p| p.min(gap)));
                }
                *burst = Some((q, 1, end));
            }
        }
    }

    /// Its line with every frame folded (on a copy: the run goes on).
    fn line(&self, id: u16, duration_us: u64) -> Line {
        let mut s = self.clone();
        while let Some(f) = s.window.pop_front() {
            s.fold(f);
        }
        let last = s.burst.map_or(1, |b| b.1);
        Line {
            id,
            node: s.node,
            frames: s.frames,
            dlc: s.dlc,
            per_activation: s.per_activation.max(last),
            period_us: s.period_us.unwrap_or(duration_us.max(1)),
            observed_us: s.observed_us,
            bound_us: Err(String::new()),
        }
    }
}

impl Traffic {
    /// Takes a frame that went over the bus (in order of completion).
    pub fn push(&mut self, t: &Transfer) {
        let window = self.window;
        let s = self.streams.entry(t.frame.id).or_insert_with(|| Stream {
            node: t.node,
            window: std::collections::VecDeque::with_capacity(window.min(WINDOW) + 1),
            ..Stream::default()
        });
        s.frames += 1;
        s.dlc = s.dlc.max(t.frame.len);
        s.observed_us = s.observed_us.max(t.end - t.released_at);
        let f = (t.released_at, t.end);
        if s.folded_to.is_some_and(|to| f.0 < to) {
            self.out_of_order += 1;
            s.fold(f);
            return;
        }
        let at = s.window.partition_point(|&w| w <= f);
        s.window.insert(at, f);
        if s.window.len() > window {
            if let Some(oldest) = s.window.pop_front() {
                s.fold(oldest);
            }
        }
    }

    /// Forgets every frame (a live run's warm-up: the report covers the live run).
    pub fn clear(&mut self) {
        *self = Self {
            window: self.window,
            ..Self::default()
        };
    }

    /// Frames that came released before one already folded (see [`Traffic`]).
    pub fn out_of_order(&self) -> usize {
        self.out_of_order
    }

    /// Frames taken.
    pub fn frames(&self) -> usize {
        self.streams.values().map(|s| s.frames).sum()
    }

    /// What it holds, in bytes (its size stays bounded however long a run goes).
    pub fn retained_bytes(&self) -> usize {
        self.streams
            .values()
            .map(|s| std::mem::size_of::<(u16, Stream)>() + s.window.capacity() * 16)
            .sum()
    }

    /// The report of the frames taken so far, from a run of `duration_us`: [`analyse`]'s.
    pub fn report(&self, duration_us: u64) -> Vec<Line> {
        let lines = self
            .streams
            .iter()
            .map(|(&id, s)| s.line(id, duration_us))
            .collect();
        bound(lines)
    }
}

/// The report of `transfers` (in order of completion) from a run of `duration_us`: [`Traffic`] with every
/// frame kept until the report, so that each identifier's bursts are folded in order of release.
pub fn analyse(transfers: &[Transfer], duration_us: u64) -> Vec<Line> {
    let mut traffic = Traffic {
        window: usize::MAX,
        ..Traffic::default()
    };
    for t in transfers {
        traffic.push(t);
    }
    traffic.report(duration_us)
}

/// The lines with their Davis bounds.
fn bound(mut lines: Vec<Line>) -> Vec<Line> {
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

    /// Frames as a long run gives them, in order of completion: `0x100` every 900 µs, `0x200` in
    /// bursts of three every 10 ms (each waiting for the one before), and a low `0x300` that
    /// waits behind the bursts, so that it completes after frames released after it.
    fn long_run(ms: u64) -> Vec<Transfer> {
        let mut t = Vec::new();
        for k in 0..ms * 1000 / 900 {
            t.push(transfer(0, 0x100, 6, k * 900, k * 900 + 120));
        }
        for k in 0..ms / 10 {
            let at = k * 10_000 + 30;
            for j in 0..3 {
                let mut f = transfer(1, 0x200, 8, at + j * 131, at + (j + 1) * 131);
                f.released_at = at;
                t.push(f);
            }
            // Released before the burst's second frame, completed after its third.
            let mut late = transfer(2, 0x300, 8, at + 100, at + 4 * 131 + 40);
            late.released_at = at + 100 - 1 - k % 7;
            t.push(late);
            // And one of 0x200's stream from another node, released before but completed last.
            if k % 50 == 0 {
                let mut other = transfer(0, 0x200, 2, at, at + 700);
                other.released_at = at - 5;
                t.push(other);
            }
        }
        t.sort_by_key(|x| x.end);
        t
    }

    #[test]
    fn the_running_report_is_the_report_of_the_whole() {
        for ms in [1, 10, 95, 3_000] {
            let frames = long_run(ms);
            let mut traffic = Traffic::default();
            for f in &frames {
                traffic.push(f);
            }
            assert_eq!(traffic.out_of_order(), 0);
            assert_eq!(traffic.frames(), frames.len());
            let whole = analyse(&frames, ms * 1000);
            assert_eq!(traffic.report(ms * 1000), whole, "{ms} ms");
        }
    }

    #[test]
    fn a_frame_later_than_the_window_is_counted() {
        let mut traffic = Traffic::default();
        let mut frames: Vec<Transfer> = (0..WINDOW as u64 + 2)
            .map(|k| transfer(0, 0x100, 2, 1_000 + k * 1000, 1_000 + k * 1000 + 60))
            .collect();
        // Released before every other one, completed after them all.
        frames.push(transfer(1, 0x100, 2, 10, 900_000));
        for f in &frames {
            traffic.push(f);
        }
        assert_eq!(traffic.out_of_order(), 1);
        assert_eq!(traffic.frames(), frames.len());
        // Its response is still the worst, whatever the bursts.
        assert_eq!(traffic.report(1_000_000)[0].observed_us, 900_000 - 10);
    }

    #[test]
    fn the_running_report_stays_bounded() {
        // An hour of 0x100 every 900 µs in a space that a second of it fills.
        let mut traffic = Traffic::default();
        let mut second = 0;
        for k in 0..4_000_000u64 {
            traffic.push(&transfer(0, 0x100, 6, k * 900, k * 900 + 120));
            if k == 1_111 {
                second = traffic.retained_bytes();
            }
        }
        assert!(second > 0);
        assert_eq!(traffic.retained_bytes(), second);
        assert!(second < 8 * 1024, "{second} B");
    }
}
