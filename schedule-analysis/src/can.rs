//! Response times of the frames on the CAN bus: non-preemptive fixed priority by identifier, after Davis, Burns,
//! Bril and Lukkien, "Controller Area Network (CAN) schedulability analysis: refuted, revisited and revised"
//! (Real-Time Systems 35(3), 2007), with the frame-cost models the project uses.
//!
//! Frame length of a data frame with `s` data bytes, in bits (counted by `amiro_can::timing`, the one place the
//! frame layout's bit counts live; the bus model counts with it too):
//!
//! * stuffable part `g + 8s`: `g = 34` for an 11-bit identifier (SOF 1, identifier 11, RTR 1, IDE 1, r0 1,
//!   DLC 4, CRC 15), `g = 54` for a 29-bit one (SOF 1, base 11, SRR 1, IDE 1, extension 18, RTR 1, r1 1, r0 1,
//!   DLC 4, CRC 15);
//! * never stuffed, 13 bits: CRC delimiter 1, ACK slot 1, ACK delimiter 1, EOF 7, **interframe space 3**;
//! * at most `⌊(g + 8s − 1)/4⌋` stuff bits (after the first five equal bits, one per four further bits in the
//!   worst pattern).
//!
//! So `C = (g + 8s + 13 + ⌊(g + 8s − 1)/4⌋)·τ`, which is `(55 + 10s)·τ` for standard identifiers and
//! `(80 + 10s)·τ` for extended ones. The interframe space is inside the 13 bits; adding it again would count it
//! twice.

use crate::board::{LevelLoads, Results};
use crate::busy_window::{
    self, Activations, AnalysisError, Counter, Discipline, Limits, Load, Response, Subject,
};
use crate::time::Time;

pub use amiro_can::timing::{frame_bits_best, frame_bits_worst};

/// The fields the thesis lists (SOF, ID, RTR, IDE, RES, DLC, 64 data bits, CRC, DELIM, ACK, DELIM, EOF) add up to
/// 108 bits.
pub const THESIS_LISTED_BITS: u32 = 108;
/// The thesis multiplies 109 bits (not the 108 its fields add up to) by five attempts to get 545 µs; the `thesis`
/// model keeps 109 so that it reproduces the published figure (and stays the larger of the two, i.e. safe).
pub const THESIS_FRAME_BITS: u32 = 109;
/// Transmission attempts the thesis allows per frame.
pub const THESIS_ATTEMPTS: u32 = 5;
/// The default bit rate of every AMiRo board.
pub const DEFAULT_BITRATE: u32 = 1_000_000;

/// How long a frame occupies the bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameCost {
    /// The thesis's figure: 109 bit times × 5 attempts for every frame, whatever its length (545 µs at 1 Mbit/s).
    Thesis,
    /// Worst-case bit stuffing after Davis et al. 2007, interframe space included.
    Exact,
    /// The same fixed time for every frame.
    Fixed(Time),
}

/// One bit time at `bitrate` bits per second, rounded up to the nanosecond (0 for a zero bit rate).
pub fn bit_time(bitrate: u32) -> Time {
    if bitrate == 0 {
        return Time::ZERO;
    }
    let ns = 1_000_000_000u64;
    let b = u64::from(bitrate);
    Time::from_ns(ns.div_ceil(b))
}

/// Time one frame occupies the bus under `cost`, at bit time `bit`.
pub fn frame_time(cost: FrameCost, dlc: u8, extended: bool, bit: Time) -> Time {
    match cost {
        FrameCost::Thesis => bit.times(u64::from(THESIS_FRAME_BITS * THESIS_ATTEMPTS)),
        FrameCost::Exact => bit.times(u64::from(frame_bits_worst(dlc, extended))),
        FrameCost::Fixed(t) => t,
    }
}

/// Best-case time of one frame: no stuff bits, one attempt (a fixed cost stays fixed).
pub fn frame_time_best(cost: FrameCost, dlc: u8, extended: bool, bit: Time) -> Time {
    match cost {
        FrameCost::Fixed(t) => t,
        FrameCost::Thesis | FrameCost::Exact => {
            bit.times(u64::from(frame_bits_best(dlc, extended)))
        }
    }
}

/// The shortest time between two frames' ends on the bus: a standard frame without data and without stuff bits
/// (47 bits). A receive (or transmit-complete) interrupt cannot fire more often than this.
pub fn shortest_frame_time(bit: Time) -> Time {
    bit.times(u64::from(frame_bits_best(0, false)))
}

/// The release jitter of a transmit-interrupt job that a job queuing frames releases, where the transmit interrupt
/// is charged by its parts (docs/analysis.md, "The transmit interrupt's parts"): the aborts its frames may cause
/// come after the pend, requested in the job the pend starts or in the job that collects the abort under way (one
/// at a time, at most one per mailbox), each completing at once or, its frame on the bus, with that frame: three of
/// the longest frames (eight data bytes, extended identifier not counted: the boards send standard ones). The host
/// analysis (`scenario`) and the on-chip admission check both take it from here.
pub fn transmit_abort_latency(bit: Time) -> Time {
    frame_time(FrameCost::Exact, 8, false, bit).times(3)
}

/// The shortest frame a board sends, from the data lengths of the frames it sends (standard identifiers, no stuff
/// bits): its transmit-complete interrupt's minimum inter-arrival time; [`shortest_frame_time`] when it sends none.
/// The host analysis (`scenario`) and the on-chip admission check both take it from here.
pub fn own_frame_time(bit: Time, dlcs: impl Iterator<Item = u8>) -> Time {
    dlcs.map(|dlc| bit.times(u64::from(frame_bits_best(dlc, false))))
        .min()
        .unwrap_or_else(|| shortest_frame_time(bit))
}

/// The order in which identifiers win arbitration, as one number (lower wins): the 11 base bits, then the
/// SRR/IDE bits (a standard frame beats an extended one with the same base), then the 18 extension bits.
pub fn arbitration_key(id: u32, extended: bool) -> u32 {
    if extended {
        let base = (id >> 18) & 0x7FF;
        (base << 19) | (1 << 18) | (id & 0x3_FFFF)
    } else {
        (id & 0x7FF) << 19
    }
}

/// One message stream on the bus as the analysis sees it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MessageTiming {
    /// [`arbitration_key`] of its identifier: lower wins.
    pub key: u32,
    /// Time of one frame on the bus.
    pub frame_time: Time,
    /// Frames queued together per activation (8 per proximity-ring sample).
    pub frames: u32,
    /// Period or minimum inter-arrival time.
    pub period: Time,
    /// Queuing jitter.
    pub jitter: Time,
}

impl Activations for MessageTiming {
    fn activation_cost(&self) -> Time {
        self.frame_time.times(u64::from(self.frames.max(1)))
    }
    fn period(&self) -> Time {
        self.period
    }
    fn jitter(&self) -> Time {
        self.jitter
    }
}

/// Blocking of `messages[index]`: the longest single frame of lower priority, which may have just started.
pub fn blocking(messages: &[MessageTiming], index: usize) -> Time {
    let Some(me) = messages.get(index) else {
        return Time::ZERO;
    };
    messages
        .iter()
        .filter(|m| m.key > me.key)
        .fold(Time::ZERO, |longest, m| longest.max_of(m.frame_time))
}

/// [`blocking`] for every message at once (`out[i]` for `messages[i]`, ordered by ascending key) in one pass from
/// the least urgent end.
pub fn blockings(messages: &[MessageTiming], out: &mut [Time]) {
    let mut longest_below = Time::ZERO;
    let mut i = messages.len();
    while i > 0 {
        // The group of equal keys ending at i - 1 is blocked by everything after it.
        let key = messages.get(i - 1).map_or(0, |m| m.key);
        let mut start = i - 1;
        while start > 0 && messages.get(start - 1).is_some_and(|m| m.key == key) {
            start -= 1;
        }
        let mut group_longest = Time::ZERO;
        for k in start..i {
            if let Some(slot) = out.get_mut(k) {
                *slot = longest_below;
            }
            group_longest =
                group_longest.max_of(messages.get(k).map_or(Time::ZERO, |m| m.frame_time));
        }
        longest_below = longest_below.max_of(group_longest);
        i = start;
    }
}

/// Worst-case response time of `messages[index]`: from its nominal queuing instant until its last frame of the
/// activation has been transmitted (queuing jitter included).
///
/// `messages` must be ordered by ascending [`MessageTiming::key`] (highest priority first); equal keys interfere
/// with each other. `blocking` is normally [`blocking`]`(messages, index)`.
pub fn response_time(
    messages: &[MessageTiming],
    index: usize,
    blocking: Time,
    bit: Time,
    limits: &Limits,
    scratch: &mut [Counter],
) -> Result<Response, AnalysisError> {
    response_time_from(
        messages,
        index,
        blocking,
        (Time::ZERO, Time::ZERO),
        None,
        bit,
        limits,
        scratch,
    )
}

/// Every message's worst-case response time, `out[i]` for `messages[i]` (ordered by ascending key) under
/// `blockings[i]`: the same results as [`response_time`] one by one, faster, since each iteration starts from the
/// windows of the next more urgent identifier when those are provably below its own.
pub fn response_times(
    messages: &[MessageTiming],
    blockings: &[Time],
    bit: Time,
    limits: &Limits,
    scratch: &mut [Counter],
    out: &mut [Result<Response, AnalysisError>],
) {
    response_times_into(messages, blockings, bit, limits, scratch, out);
}

/// [`response_times`] into any [`Results`] (the on-chip admission check keeps only the numbers it needs).
#[inline(never)]
pub fn response_times_into<R: Results + ?Sized>(
    messages: &[MessageTiming],
    blockings: &[Time],
    bit: Time,
    limits: &Limits,
    scratch: &mut [Counter],
    out: &mut R,
) {
    let mut level_start = 0;
    let mut previous_level = 0..0;
    let mut levels = LevelLoads::default();
    for (i, message) in messages.iter().enumerate() {
        if i > 0 && messages.get(i - 1).is_some_and(|m| m.key != message.key) {
            previous_level = level_start..i;
            level_start = i;
        }
        let blocking = blockings.get(i).copied().unwrap_or(Time::ZERO);
        let mut hints = (Time::ZERO, Time::ZERO);
        for k in previous_level.clone() {
            let (Some((first_window, busy_window)), Some(other)) =
                (out.windows(k), messages.get(k))
            else {
                continue;
            };
            let blocking_k = blockings.get(k).copied().unwrap_or(Time::ZERO);
            // Queuing window: f_i ≥ f_k − B_k + B_i + A_k; busy period: the same with the own activation A_i.
            if blocking_k <= blocking.plus(other.activation_cost()) {
                hints.0 = hints.0.max_of(first_window);
            }
            if blocking_k <= blocking.plus(message.activation_cost()) {
                hints.1 = hints.1.max_of(busy_window);
            }
        }
        let load = levels.at(messages, i, |a, b| a.key == b.key);
        let limits = Limits {
            iterations: out
                .iterations_left()
                .map_or(limits.iterations, |left| left.min(limits.iterations)),
            ..*limits
        };
        let result = response_time_from(
            messages,
            i,
            blocking,
            hints,
            Some(load),
            bit,
            &limits,
            scratch,
        );
        out.put(i, result);
    }
}

// Out of line: one instance for every caller (the bus analysis and, with `sensor-buses`, a script's bus response).
#[inline(never)]
#[allow(clippy::too_many_arguments)]
fn response_time_from(
    messages: &[MessageTiming],
    index: usize,
    blocking: Time,
    hints: (Time, Time),
    load: Option<Load>,
    bit: Time,
    limits: &Limits,
    scratch: &mut [Counter],
) -> Result<Response, AnalysisError> {
    let me = *messages.get(index).ok_or(AnalysisError::NoSuchIndex)?;
    let mut end = index + 1;
    while messages.get(end).is_some_and(|m| m.key == me.key) {
        end += 1;
    }
    let sorted = messages
        .get(..end)
        .is_some_and(|prefix| prefix.windows(2).all(|pair| pair[0].key <= pair[1].key))
        && messages.get(end).is_none_or(|next| next.key > me.key);
    if !sorted {
        return Err(AnalysisError::NotSorted);
    }
    let mut subject = Subject::new(
        me.frame_time,
        me.frames.max(1),
        me.period,
        me.jitter,
        blocking,
    );
    subject.known_first_window = hints.0;
    subject.known_busy_period = hints.1;
    let interferers = messages.get(..end).unwrap_or(&[]);
    let load = load.unwrap_or_else(|| Load::sum(interferers, Some(index)));
    busy_window::response_time_loaded(
        &subject,
        interferers,
        Some(index),
        load,
        Discipline::NonPreemptive { bit_time: bit },
        limits,
        scratch,
    )
}

/// Bus utilisation `Σ frames·C/T`.
pub fn utilisation(messages: &[MessageTiming]) -> f64 {
    messages
        .iter()
        .filter(|m| !m.period.is_zero())
        .map(|m| m.activation_cost().as_ns() as f64 / m.period.as_ns() as f64)
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_lengths_follow_davis() {
        for s in 0..=8u8 {
            assert_eq!(frame_bits_worst(s, false), 55 + 10 * u32::from(s));
            assert_eq!(frame_bits_worst(s, true), 80 + 10 * u32::from(s));
            assert_eq!(frame_bits_best(s, false), 47 + 8 * u32::from(s));
        }
        // An eight-byte frame: 135 bits, 135 µs at 1 Mbit/s, 1.08 ms at 125 kbit/s.
        assert_eq!(
            frame_time(FrameCost::Exact, 8, false, bit_time(1_000_000)),
            Time::from_us(135)
        );
        assert_eq!(
            frame_time(FrameCost::Exact, 8, false, bit_time(125_000)),
            Time::from_us(1080)
        );
        // DLC above 8 is sent as 8 bytes.
        assert_eq!(frame_bits_worst(15, false), frame_bits_worst(8, false));
    }

    #[test]
    fn thesis_figure_is_545_us() {
        assert_eq!(
            frame_time(FrameCost::Thesis, 0, false, bit_time(DEFAULT_BITRATE)),
            Time::from_us(545)
        );
        // What the listed fields really add up to.
        assert_eq!(
            1 + 11 + 1 + 1 + 1 + 4 + 64 + 15 + 1 + 1 + 1 + 7,
            THESIS_LISTED_BITS
        );
        // The listed fields are the unstuffed 8-byte frame without the interframe space.
        assert_eq!(frame_bits_best(8, false) - 3, THESIS_LISTED_BITS);
    }

    #[test]
    fn shortest_frame_is_47_bits() {
        assert_eq!(shortest_frame_time(bit_time(1_000_000)), Time::from_us(47));
    }

    #[test]
    fn standard_beats_extended_with_the_same_base() {
        let std_key = arbitration_key(0x123, false);
        let ext_key = arbitration_key(0x123 << 18, true);
        assert!(std_key < ext_key);
        assert!(arbitration_key(0x122, false) < std_key);
        assert!(arbitration_key((0x122 << 18) | 0x3FFFF, true) < std_key);
    }

    #[test]
    fn blocking_is_the_longest_lower_frame() {
        let m = |key, us| MessageTiming {
            key,
            frame_time: Time::from_us(us),
            frames: 1,
            period: Time::from_us(1000),
            jitter: Time::ZERO,
        };
        let set = [m(1, 100), m(2, 50), m(3, 135), m(4, 80)];
        assert_eq!(blocking(&set, 0), Time::from_us(135));
        assert_eq!(blocking(&set, 2), Time::from_us(80));
        assert_eq!(blocking(&set, 3), Time::ZERO);
        let mut all = [Time::MAX; 4];
        blockings(&set, &mut all);
        assert_eq!(all, [0, 1, 2, 3].map(|i| blocking(&set, i)));
        // Equal keys do not block each other.
        let tied = [m(1, 100), m(2, 50), m(2, 135), m(4, 80)];
        let mut all = [Time::MAX; 4];
        blockings(&tied, &mut all);
        assert_eq!(all, [0, 1, 2, 3].map(|i| blocking(&tied, i)));
        assert_eq!(all[1], Time::from_us(80));
    }
}
